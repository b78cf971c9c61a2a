"""The evaluation command on the 39-bus study: JSON layout, counts, figures, task files."""
from __future__ import annotations

import json

import pytest

from experiments.common.evaluation import evaluate
from experiments.evaluate import main


@pytest.fixture(scope="module")
def study(ieee39):
    return ieee39


@pytest.fixture(scope="module")
def uncontrolled(study):
    return evaluate(study, "none", "test")


def test_uncontrolled_test_set_fails_some_tasks_and_not_others(uncontrolled):
    summary = uncontrolled["summary"]
    print(f"\nno control on the 120 test tasks: {summary}")
    assert summary["n_tasks"] == 120
    assert 0 < summary["n_recovered"] < 120
    assert summary["total_shed_mw"] == 0.0
    failed = [t for t in uncontrolled["tasks"] if not t["recovered"]]
    assert all(t["reward"] <= -1000.0 for t in failed), "a failed task earns -M"
    # the longer the fault at a bus, the worse: no 0.02 s fault fails where 0.1 s recovers
    by_bus = {}
    for t in uncontrolled["tasks"]:
        by_bus.setdefault(t["fault_bus"], {})[t["fault_duration"]] = t["recovered"]
    for bus, outcome in by_bus.items():
        assert outcome[0.02] >= outcome[0.1], f"bus {bus}: short fault fails, long recovers"


@pytest.fixture(scope="module")
def relays(study):
    return evaluate(study, "uvls", "test")


def test_uvls_sheds_on_the_failing_tasks_only(uncontrolled, relays):
    pairs = list(zip(uncontrolled["tasks"], relays["tasks"]))
    failing = [(a, b) for a, b in pairs if not a["recovered"]]
    shed_on = sum(b["shed_mw"] > 0 for _, b in failing)
    print(f"\nUVLS on the 120 test tasks: {relays['summary']}; sheds on {shed_on} of the "
          f"{len(failing)} tasks that fail without control, recovers "
          f"{sum(b['recovered'] for _, b in failing)} of them")
    assert shed_on >= 0.9 * len(failing)
    assert all(b["shed_mw"] == 0 for a, b in pairs if a["recovered"]), "UVLS shed needlessly"
    assert relays["summary"]["mean_reward"] > uncontrolled["summary"]["mean_reward"]


def test_cli_writes_the_documented_json_figures_and_study(tmp_path):
    out = tmp_path / "results.json"
    assert main(["--study", "ieee39_fidvr", "--controller", "none", "--tasks", "train",
                 "--out", str(out), "--plot", str(tmp_path / "figs"), "--plot-count", "2"]) == 0
    data = json.loads(out.read_text())
    assert set(data) == {"study", "controller", "points", "tasks", "summary"}
    assert set(data["tasks"][0]) == {"fault_bus", "fault_duration", "fault_start",
                                     "operating_point", "point", "reward", "shed_mw",
                                     "recovered"}
    assert set(data["summary"]) == {"n_tasks", "n_recovered", "mean_reward", "total_shed_mw"}
    assert data["summary"]["n_tasks"] == 9 and data["points"] == ["load100"]
    assert len(list((tmp_path / "figs").glob("*.png"))) == 2
    again = tmp_path / "again.json"
    assert main(["--study", str(out.with_suffix(".study.toml")), "--tasks", "train",
                 "--out", str(again)]) == 0, "the saved study reproduces the run"
    # the plotting run traces its episodes (a full scan), this one stops them when done
    # (a while loop): the same episodes, compiled apart, so float32 rounding differs over
    # 5000 steps (1.3e-5 relative seen); 1e-4 stays far below the step's own error (p99
    # |ΔV| 2e-4 p.u. against the float64 reference), where a flipped stall would not
    for a, b in zip(json.loads(again.read_text())["tasks"], data["tasks"]):
        assert a.pop("reward") == pytest.approx(b.pop("reward"), rel=1e-4) and a == b
    assert main(["--controller", "ppo", "--out", str(out)]) == 2
    assert main(["--tasks", "holdout", "--out", str(out)]) == 2


def test_a_pnnl_task_file_crossed_with_the_operating_points(shared_cases, tmp_path):
    """--tasks FILE.json: the file's fault candidates at every operating point of the study."""
    out = tmp_path / "file.json"
    task = shared_cases / "ieee39/IEEE39_RL_loadShedding_3motor_continuous_reducedActionRange_" \
                          "gp.json"
    assert main(["--study", "ieee39_fidvr", "--load-levels", "0.9", "1.1", "--tasks",
                 str(task), "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["points"] == ["load90", "load110"]
    assert data["summary"]["n_tasks"] == 2 * 3 * 3, "2 points x buses 4, 15, 21 x 3 durations"
    assert {(t["point"], t["fault_bus"]) for t in data["tasks"]} == {
        (p, b) for p in (0, 1) for b in (4, 15, 21)}
