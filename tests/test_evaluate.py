"""The evaluation command on the 39-bus study case: JSON layout, counts, figures."""
from __future__ import annotations

import json

import pytest

from experiments.evaluate import evaluate, main


@pytest.fixture(scope="module")
def uncontrolled():
    return evaluate("ieee39_fidvr", "none", "test")


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
def relays():
    return evaluate("ieee39_fidvr", "uvls", "test")


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


def test_cli_writes_the_documented_json_and_figures(tmp_path):
    out = tmp_path / "results.json"
    assert main(["--case", "ieee39_fidvr", "--controller", "none", "--tasks", "train",
                 "--out", str(out), "--plot", str(tmp_path / "figs"), "--plot-count", "2"]) == 0
    data = json.loads(out.read_text())
    assert set(data) == {"case", "controller", "tasks", "summary"}
    assert set(data["tasks"][0]) == {"fault_bus", "fault_duration", "operating_point", "reward",
                                     "shed_mw", "recovered"}
    assert set(data["summary"]) == {"n_tasks", "n_recovered", "mean_reward", "total_shed_mw"}
    assert data["summary"]["n_tasks"] == 9
    assert len(list((tmp_path / "figs").glob("*.png"))) == 2
    assert main(["--controller", "ppo", "--out", str(out)]) == 2
