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
