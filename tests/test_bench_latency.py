"""The decision-latency benchmark runs every controller of a study and writes its JSON, with
one timed call per controller and the MPC of the reproduction's --quick settings (a 0.2-s
horizon, one iteration). The figures themselves are measurements, not asserted: only that
each is recorded."""
import json

from experiments.bench.latency import main
from experiments.reproduce.runs import QUICK


def test_every_controller_is_timed_on_its_own_observation(tmp_path):
    out = tmp_path / "latency.json"
    main(["--studies", "ieee39_fidvr", "--batch", "2", "--calls", "1", "--out", str(out),
          "--mpc", QUICK.mpc, "--mpc-batch", "2"])
    (study,) = json.loads(out.read_text())["studies"]
    rows = {r["controller"]: r for r in study["controllers"]}
    mpc = rows.pop(f"mpc({QUICK.mpc})")
    assert mpc["batch"] == 2 and mpc["one_task_ms"] > 0 and mpc["per_decision_in_batch_us"] > 0
    assert set(rows) == {"pars_linear", "pars_fnn_32x32", "pars_lstm_32x32", "uvls"}
    # 8 observed voltages + 3 load fractions, 10 stacked for linear / FNN, 1 for LSTM / UVLS
    assert [rows[k]["obs_size"] for k in sorted(rows)] == [110, 110, 11, 11]
    assert all(r["one_task_ms"] > 0 and r["per_decision_in_batch_us"] > 0 for r in rows.values())
