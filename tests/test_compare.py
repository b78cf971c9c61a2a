"""The task-by-task comparison of evaluate results: which tasks need shedding, who wins."""
import json

import pytest

from experiments.compare import compare, load


def _result(tmp_path, name, rows):
    tasks = [{"fault_bus": bus, "fault_duration": 0.1, "operating_point": 1.0,
              "reward": reward, "shed_mw": shed, "recovered": ok}
             for bus, (reward, shed, ok) in rows.items()]
    summary = {"n_tasks": len(tasks), "n_recovered": sum(t["recovered"] for t in tasks),
               "mean_reward": sum(t["reward"] for t in tasks) / len(tasks),
               "total_shed_mw": sum(t["shed_mw"] for t in tasks)}
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps({"controller": name, "tasks": tasks, "summary": summary}))
    return load(str(path))


def test_counts_wins_on_the_tasks_the_reference_does_not_recover(tmp_path):
    none = _result(tmp_path, "none", {1: (-10, 0, True), 2: (-900, 0, False),
                                      3: (-800, 0, False)})
    uvls = _result(tmp_path, "uvls", {1: (-10, 0, True), 2: (-500, 90, False),
                                      3: (-100, 50, True)})
    policy = _result(tmp_path, "policy", {1: (-30, 20, True), 2: (-200, 80, True),
                                          3: (-150, 60, True)})
    report = compare([none, uvls, policy])
    assert report["need_shedding"] == 2
    (pair,) = [p for p in report["pairs"] if p["controller"] == "policy"]
    assert pair["against"] == "uvls"
    assert (pair["higher_reward_on"], pair["recovered"], pair["against_recovered"]) == (1, 2, 1)
    assert pair["sheds_where_not_needed"] == 1


def test_refuses_results_on_other_tasks(tmp_path):
    none = _result(tmp_path, "none", {1: (-10, 0, True)})
    other = _result(tmp_path, "uvls", {2: (-10, 0, True)})
    with pytest.raises(ValueError, match="other tasks"):
        compare([none, other])


def test_a_published_policy_is_set_against_its_training_log(tmp_path):
    """Tasks with a logged reward ("log_reward", experiments.evaluate of rlgc:FILE) are listed
    beside it, printed and drawn; tasks the log lacks are left out."""
    from experiments.compare import main

    rows = {4: (-700.0, 250.0, True), 15: (-1200.0, 400.0, False), 2: (-5.0, 0.0, True)}
    tasks = [{"fault_bus": bus, "fault_duration": 0.05, "operating_point": "base",
              "fault_start": 1.0, "reward": reward, "shed_mw": shed, "recovered": ok,
              "log_reward": {4: -247.5, 15: -238.1}.get(bus)}
             for bus, (reward, shed, ok) in rows.items()]
    path = tmp_path / "rlgc.json"
    path.write_text(json.dumps({
        "study": "ieee39_pnnl_gp", "controller": "rlgc:v5/policy_plus500.npz", "tasks": tasks,
        "log": {"path": "v5/log.txt", "iteration": 500},
        "summary": {"n_tasks": 3, "n_recovered": 2, "mean_reward": -635.0,
                    "total_shed_mw": 650.0}}))
    main([str(path), "--out", str(tmp_path / "out.json"), "--plot", str(tmp_path / "figs")])
    report = json.loads((tmp_path / "out.json").read_text())
    entry = report["against_log"]["rlgc:v5/policy_plus500.npz"]
    assert entry["log"]["iteration"] == 500
    assert [(t["fault_bus"], t["reward"], t["log_reward"], t["recovered"])
            for t in entry["tasks"]] == [(4, -700.0, -247.5, True), (15, -1200.0, -238.1, False)]
    assert (tmp_path / "figs" / "v5_policy_plus500_log.png").stat().st_size > 10_000
