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
    # task 3: both recover, the policy sheds more (60 against 50 MW) and earns less
    assert pair["not_higher_on"] == {"tie": 0, "both_recover": 1, "both_fail": 0,
                                     "it_fails": 0, "it_recovers": 0}


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


def _evaluated(controller, rows):
    """An evaluate result (`experiments.common.evaluation.evaluate`) of bus: (reward, MW,
    recovered) rows at one operating point."""
    return {"controller": controller, "tasks": [
        {"fault_bus": bus, "fault_duration": 0.1, "fault_start": 1.0, "point": 0,
         "reward": reward, "shed_mw": mw, "recovered": ok} for bus, (reward, mw, ok) in rows.items()]}


def test_scores_per_kind_of_task_by_hand():
    """Buses 1-2 need no shedding (no control recovers them), 3-5 do. The policy sheds 0.5 MW
    on bus 1 (nothing: below 1 MW) and 30 MW on bus 2; beats UVLS on 3 and 4, ties on 5."""
    from experiments.common.scores import scores, targets_met

    none = _evaluated("none", {1: (0, 0, True), 2: (-5, 0, True), 3: (-900, 0, False),
                               4: (-800, 0, False), 5: (-1000, 0, False)})
    uvls = _evaluated("uvls", {1: (0, 0, True), 2: (-5, 0, True), 3: (-600, 90, False),
                               4: (-300, 60, True), 5: (-1000, 0, False)})
    policy = _evaluated("policy", {1: (-1, 0.5, True), 2: (-50, 30, True),
                                   3: (-200, 120, True), 4: (-100, 30, True),
                                   5: (-1000, 0, False)})
    record = scores(none, uvls, policy)
    assert record == {"n_tasks": 5, "need": 3, "wins": 2, "recovered": 2, "uvls_recovered": 1,
                      "mw_need": 50.0, "losses": {"tie": 1, "both_recover": 0, "both_fail": 0,
                                                  "it_fails": 0, "it_recovers": 0},
                      "ok": 2, "sheds_on": 1, "mw_ok": 15.25, "mean_reward": -270.2}
    assert targets_met(record) == {"wins": False, "recovers": True, "quiet": False}
    with pytest.raises(ValueError, match="ran different tasks"):
        scores(none, uvls, _evaluated("other", {1: (0, 0, True)}))


def test_losses_by_what_each_recovered():
    """Each kind of a lost task once, by hand, and a win that is not counted."""
    from experiments.common.scores import losses

    task = lambda reward, ok: {"reward": reward, "recovered": ok}  # noqa: E731
    other = {1: task(-100, False), 2: task(-100, True), 3: task(-900, False),
             4: task(-100, True), 5: task(-11000, False), 6: task(-500, True)}
    mine = {1: task(-100, False), 2: task(-200, True), 3: task(-950, False),
            4: task(-10500, False), 5: task(-11200, True), 6: task(-300, True)}
    assert losses(other, mine, mine.keys()) == {
        "tie": 1, "both_recover": 1, "both_fail": 1, "it_fails": 1, "it_recovers": 1}
    assert losses(other, mine, [6]) == dict.fromkeys(
        ("tie", "both_recover", "both_fail", "it_fails", "it_recovers"), 0)


def test_ablation_file_rows_and_table(tmp_path):
    """An ablation file's rows become training choices (the file's seeds and iterations, the
    row's flags after them); bad entries name the file and key; the table shows each row's
    mean and range over seeds and how many seeds meet the targets; ablation.json drops the
    records of rows no longer in the file."""
    from experiments.ablation import (Subset, at_points, choices, read_spec, rows_of_spec,
                                      table)

    study = tmp_path / "study.toml"
    study.write_text('[grid]\nbuiltin = "ieee39_fidvr"\n')
    spec_file = tmp_path / "ablation.toml"
    spec_file.write_text(
        'out = "out"\nseeds = 2\niterations = 7\ntask_sets = ["test"]\n'
        '[subsets.unseen]\nof = "test"\npoints = [2, 3]\nwhy = "not trained on"\n'
        '[[rows]]\nname = "paper"\nstudy = "study.toml"\n'
        '[[rows]]\nname = "shaped"\nstudy = "study.toml"\n'
        'flags = ["--shaping", "c_normal=30", "--iterations", "9"]\nwhy = "charge"\n'
        '[[rows]]\nname = "fixed"\nstudy = "study.toml"\ncontroller = "rlgc:nets/v5.npz"\n'
        '[[rows]]\nname = "elsewhere"\nstudy = "study.toml"\n'
        'controller = ["policy:runs/seed0", "uvls"]\narming_level = 0.85\narming_late = 3.0\n')
    spec = read_spec(spec_file)
    assert spec.out == tmp_path / "out"
    assert [r.name for r in spec.rows] == ["paper", "shaped", "fixed", "elsewhere"]
    assert spec.rows[2].controllers == (f"rlgc:{tmp_path / 'nets' / 'v5.npz'}",)  # beside it
    assert spec.rows[3].controllers == (f"policy:{tmp_path / 'runs' / 'seed0'}", "uvls")
    assert spec.rows[0].controllers == ()
    assert [r.arming_level for r in spec.rows] == [None, None, None, 0.85]
    assert [r.arming_late for r in spec.rows] == [None, None, None, 3.0]
    paper, shaped = (choices(spec, row) for row in spec.rows[:2])
    assert (paper.seeds, paper.iterations, paper.shaping) == (2, 7, ())
    assert (shaped.iterations, shaped.shaping) == (9, (("c_normal", 30.0),))
    record = {"n_tasks": 5, "need": 3, "wins": 3, "recovered": 2, "uvls_recovered": 1,
              "mw_need": 50.0, "ok": 2, "sheds_on": 0, "mw_ok": 0.0, "mean_reward": -100.0,
              "losses": {"tie": 0, "both_recover": 0, "both_fail": 0, "it_fails": 0,
                         "it_recovers": 0}}
    worse = {**record, "wins": 1, "sheds_on": 1, "mean_reward": -300.0,
             "losses": {**record["losses"], "both_recover": 1, "it_fails": 1}}
    assert spec.subsets == (Subset("unseen", "test", (2, 3), "not trained on"),)
    text = table(spec, {"paper": {"test": {"uvls": record, "seeds": [record, worse]}}})
    assert "## test: 5 tasks, 3 need shedding (UVLS recovers 1), 2 need none" in text
    assert "## unseen" not in text  # no row scored on it yet
    text = table(spec, {"paper": {"test": {"uvls": record, "seeds": [record, worse]}},
                        "shaped": {"test": {"uvls": record, "seeds": [record, worse]},
                                   "unseen": {"uvls": record, "seeds": [worse, worse]}}})
    assert "| paper | not scored (rerun with --no-train) |" in text
    text = table(spec, {"paper": {"test": {"uvls": record, "seeds": [record, worse]},
                                  "unseen": {"uvls": record, "seeds": [worse, worse]}}})
    assert ("## unseen (test at points 2, 3: not trained on): 5 tasks, 3 need shedding"
            in text)
    assert "| paper | 33.3 [33.3, 33.3] |" in text
    tasks = _evaluated("none", {1: (0, 0, True), 2: (-5, 0, True)})["tasks"]
    at_two = at_points({"controller": "none", "tasks": [tasks[0], {**tasks[1], "point": 2}]},
                       (2, 3))
    assert [t["fault_bus"] for t in at_two["tasks"]] == [2]
    with pytest.raises(ValueError, match=r"none: no task at operating points \[5\]"):
        at_points(at_two, (5,))
    assert ("| paper | 66.7 [33.3, 100.0] | 2.0 [2.0, 2.0] (1) | 50 [50, 50] | "
            "0.0 / 0.5 / 0.0 / 0.5 / 0.0 |") in text
    assert "| 1/2 |" in text and "| shaped | not trained |" in text
    renamed = {"paper": {"folder": None}, "paper, seeds 0-1": {"folder": None}}
    assert list(rows_of_spec(spec, renamed, tmp_path / "ablation.json")) == ["paper"]
    for body, message in (('out = "o"\nseeds = 0\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml"}]\n', r"must be >= 1"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "none.toml"}]\n',
                           r"rows\[0\].study = 'none.toml': no such file"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml"}]\n'
                           '[subsets.u]\nof = "t"\npoints = []\n',
                           r"subsets.u: a table of .*non-empty list"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml"}, '
                           '{name = "a", study = "study.toml"}]\n', r"a name used twice"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml", controller = "uvls", '
                           'flags = ["--seeds", "2"]}]\n', r"rows\[0\].controller = 'uvls'"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml", controller = []}]\n',
                           r"rows\[0\].controller = \[\]: .*non-empty list"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml", arming_level = 2}]\n',
                           r"rows\[0\].arming_level = 2: allowed 0 < p.u. < 2"),
                          ('out = "o"\nseeds = 1\niterations = 1\ntask_sets = ["t"]\n'
                           'rows = [{name = "a", study = "study.toml", arming_late = 3.0}]\n',
                           r"rows\[0\].arming_late = 3.0: needs an arming level")):
        spec_file.write_text(body)
        with pytest.raises(ValueError, match=message):
            read_spec(spec_file)
