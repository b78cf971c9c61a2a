"""`experiments.reproduce --quick`: every experiment (generalisation included, on the built-in
39-bus study at two load levels, trained at one) writes its figure and numbers, REPORT.md
names each beside the paper's values, the best LSTM policy is exported and evaluates, a
second run reuses every finished run and reports its trainings' time, fig7's GPU timing file,
the environment steps actually simulated, and the convergence rule and the side claims on
inputs whose answer is known by hand."""
from __future__ import annotations

import argparse
import dataclasses
import json
import re
import shutil
from types import SimpleNamespace

import jax
import numpy as np
import pytest

from experiments.reproduce import claims
from experiments.reproduce.figures import EXPERIMENTS, PAPER
from experiments.reproduce.runs import (QUICK, Runs, _hash, convergence_iteration, study_key,
                                        study_keys)
from experiments.reproduce.harness import _ppo_flags, main, run, write_report

# The built-in 39-bus study at two load levels: trained and tested at the first, the second
# the generalisation set's (quick settings keep 2 fault buses and 1 duration of each set).
LEVELS_STUDY = """name = "ieee39_levels"
[grid]
builtin = "ieee39_fidvr"
load_levels = [1.0, 0.9]
[tasks.train]
operating_points = [0]
[tasks.test]
operating_points = [0]
[tasks.generalisation]
fault_buses = [3, 4]
fault_durations = [0.08]
operating_points = [1]
"""


@pytest.fixture(scope="module")
def study_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("study") / "ieee39_levels.toml"
    path.write_text(LEVELS_STUDY)
    return path


# The smallest settings: --quick, with fig6b's and fig9's sweeps of the main training's N
# alone, so that nothing trains for them (their curves are fig6a's code with other N), and the
# MPC left out (its gradient programs were a quarter of this run's compile and trace time; its
# episodes are tests/test_mpc.py's, its latency row tests/test_bench_latency.py's, and fig12's
# MPC numbers are checked below on evaluations written by hand)
SWEEP = (QUICK.directions,)
SMOKE_SKIPS = ("mpc",)


@pytest.fixture(scope="module")
def quick(tmp_path_factory, study_file):
    """The one end-to-end run of every experiment (the suite's smoke run of the harness)."""
    out = tmp_path_factory.mktemp("reproduce")
    sweeps = ",".join(map(str, SWEEP))
    assert main(["--quick", "--study", str(study_file), "--out", str(out), "--sweep", sweeps,
                 "--sweep-large", sweeps, "--skip-baselines", ",".join(SMOKE_SKIPS)]) == 0
    return out


def test_every_experiment_writes_its_figure_numbers_and_report_entry(quick):
    report = (quick / "REPORT.md").read_text()
    for name in EXPERIMENTS:
        assert (quick / f"{name}.png").stat().st_size > 10_000, f"{name}: no figure"
        result = json.loads((quick / f"{name}.json").read_text())
        assert result["numbers"], f"{name}: no numbers"
        assert f"## {name}: {PAPER[name]['title']}" in report
        assert f"![{name}]({name}.png)" in report
    fig8 = json.loads((quick / "fig8.json").read_text())["numbers"]
    assert set(fig8) >= {"reward, PARS", "reward, UVLS"}
    assert "| reward, UVLS |" in report and "-2367.21" in report, "the paper's value beside"
    fig6a = json.loads((quick / "fig6a.json").read_text())["numbers"]
    assert all(np.isfinite(fig6a[f"best average reward, {k}"]) for k in ("linear", "fnn",
                                                                          "lstm"))
    rows = [json.loads(line) for line in next((quick / "runs").glob("pars_lstm_N2-*"))
            .joinpath("metrics.jsonl").read_text().splitlines()]
    assert len(rows[-1]["reward_mean"]) == 2, "2 seeds trained in one program"
    assert rows[-1]["reward_mean"][0] != rows[-1]["reward_mean"][1]
    fig7 = json.loads((quick / "fig7.json").read_text())["numbers"]
    assert fig7["speed-up, 2 cpu device(s)"] > 0, "1 and 2 devices timed"
    fig10 = json.loads((quick / "fig10_11.json").read_text())["numbers"]
    assert np.isfinite(fig10["final training reward, PPO"]), "a PPO episode ended"
    fig12 = json.loads((quick / "fig12.json").read_text())["numbers"]
    for key in ("PARS − UVLS more than M on", "PARS − PPO less than M/2 on", "PPO fails on"):
        assert key in fig12 and f"| {key} |" in report, key
    assert "left out: MPC" in report
    fig13 = json.loads((quick / "fig13.json").read_text())["numbers"]
    assert set(fig13["sheds the least"].split(", ")) <= {"PARS", "PPO", "UVLS"}
    assert all(isinstance(fig13[f"buses not recovered, {k}"], int) for k in ("PARS", "UVLS"))
    tab3 = json.loads((quick / "tab3.json").read_text())["numbers"]
    assert {"pars_linear", "pars_fnn", "pars_lstm"} <= {k.split(",")[0] for k in tab3}, \
        "fig6a's trained networks timed"


def test_training_counts_the_environment_steps_it_simulated(quick):
    """metrics.jsonl's env_steps: per seed, cumulative, at most 15 agent steps (1.5 s) per
    rollout; fig11's PARS steps are their mean over the seeds, and fig10's PARS wall time is
    the program's over its seeds (PPO's is per seed)."""
    rows = [json.loads(line) for line in next((quick / "runs").glob("pars_lstm_N2-*"))
            .joinpath("metrics.jsonl").read_text().splitlines()]
    steps = np.array([r["env_steps"] for r in rows])  # (iterations, seeds)
    assert steps.shape == (QUICK.iterations, QUICK.seeds) and np.all(np.diff(steps, axis=0) > 0)
    assert np.all(steps[-1] <= rows[-1]["rollouts"] * 15)
    fig10 = json.loads((quick / "fig10_11.json").read_text())["numbers"]
    assert fig10["environment steps, PARS (mean over seeds)"] == int(steps[-1].mean())
    program_s = sum(r["wall_s"] for r in rows)
    assert fig10["wall s in all, PARS"] == pytest.approx(program_s / QUICK.seeds, abs=0.051)


def test_generalisation_and_the_exported_policy(quick, study_file, tmp_path):
    """The main policy against UVLS at the untrained load level, and OUT/policy evaluating
    with `experiments.evaluate` on the study file."""
    from experiments.evaluate import main as evaluate

    result = json.loads((quick / "generalisation.json").read_text())
    numbers = result["numbers"]
    assert numbers["tasks"] == 2 and numbers["operating points"] == 1
    assert numbers["PARS better than UVLS on"].endswith(" %")
    assert "PARS better than UVLS at load90" in numbers
    out = tmp_path / "policy.json"
    assert evaluate(["--study", str(study_file), "--controller", f"policy:{quick / 'policy'}",
                     "--tasks", "generalisation", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["summary"]["n_tasks"] == 2
    info = json.loads((quick / "policy" / "policy.json").read_text())
    assert (info["iteration"], info["iterations"]) == (QUICK.iterations, QUICK.iterations)
    assert "The best seed of the main LSTM training is in `policy/`" in (
        quick / "REPORT.md").read_text()


def test_a_given_policy_is_kept_and_otherwise_the_trained_one_is_exported(quick, tmp_path):
    """With --policy the experiments use the given policy, so OUT/policy is not replaced by
    the main training's best seed (a redraw passing `--policy OUT/policy` keeps it); nor is
    it when no experiment evaluated the trained policy (a training-curve redraw); when one
    did, the finished training's best seed is copied there."""
    out = tmp_path / "out"
    shutil.copytree(quick, out)
    info_path = out / "policy" / "policy.json"
    info_path.write_text(json.dumps({**json.loads(info_path.read_text()), "given": True}))
    given = Runs(str(out / "study.toml"), out,
                 dataclasses.replace(QUICK, policy=str(out / "policy")))
    assert given.export_policy() is None
    assert json.loads(info_path.read_text())["given"]
    curves_only = Runs(str(out / "study.toml"), out, QUICK)
    assert curves_only.export_policy() is None
    assert json.loads(info_path.read_text())["given"]
    evaluating = Runs(str(out / "study.toml"), out, QUICK)
    evaluating.main_policy()
    assert evaluating.export_policy() == out / "policy"
    assert "given" not in json.loads(info_path.read_text())


def test_a_policy_of_another_study_is_kept_and_named_in_the_report(quick, tmp_path):
    """OUT/policy trained on another study (an ablation's best configuration, committed on
    purpose) is not replaced by the main training's best seed, even when an experiment
    evaluated that one, and the report says what it is."""
    out = tmp_path / "out"
    shutil.copytree(quick, out)
    info_path = out / "policy" / "policy.json"
    info_path.write_text(json.dumps({**json.loads(info_path.read_text()),
                                     "study": "elsewhere", "task_set": "train_levels"}))
    evaluating = Runs(str(out / "study.toml"), out, QUICK)
    evaluating.main_policy()
    assert evaluating.export_policy() is None
    assert json.loads(info_path.read_text())["study"] == "elsewhere"
    write_report(out, QUICK, quick=True, study=evaluating.study.name)
    report = (out / "REPORT.md").read_text()
    assert ("`policy/` holds a policy trained on the study `elsewhere` (task set "
            "`train_levels`), not this report's main training") in report


def test_the_report_says_when_its_policy_is_from_an_unfinished_training(quick, tmp_path):
    """A policy copied from a checkpoint of a training that stopped short (its policy.json:
    iteration < iterations) is named as such at the top of the report."""
    out = tmp_path / "out"
    shutil.copytree(quick, out)
    info_path = out / "policy" / "policy.json"
    info_path.write_text(json.dumps({**json.loads(info_path.read_text()), "iteration": 120,
                                     "iterations": 500}))
    write_report(out, QUICK, quick=True)
    report = (out / "REPORT.md").read_text()
    assert "policy after iteration 120 of 500: that training is unfinished" in report
    assert "The best seed" not in report


def test_a_second_run_reuses_the_finished_runs(quick):
    trained = sorted((quick / "runs").glob("*/metrics.jsonl"))
    before = {p: p.stat().st_mtime_ns for p in trained}
    folders = sorted(p.name for p in (quick / "runs").iterdir())
    run(str(quick / "study.toml"), quick, ["fig6b", "fig8", "fig12"], quick=True, sweep=SWEEP,
        skip_baselines=SMOKE_SKIPS)
    assert sorted(p.name for p in (quick / "runs").iterdir()) == folders, "nothing new ran"
    assert {p: p.stat().st_mtime_ns for p in trained} == before, "no training touched"
    fig6b = json.loads((quick / "fig6b.json").read_text())
    walls = [json.loads(line)["wall_s"] for n in SWEEP
             for line in next((quick / "runs").glob(f"pars_lstm_N{n}-*"))
             .joinpath("metrics.jsonl").read_text().splitlines()]
    assert fig6b["training_s"] == pytest.approx(sum(walls), abs=0.05), \
        "the reused trainings' time, from their metrics"
    assert fig6b["trained_on"] == [f"{jax.device_count()} × cpu"], "from the metrics lines"
    assert (f"its trainings took {fig6b['training_s']} s in all, on {jax.device_count()} × cpu"
            in (quick / "REPORT.md").read_text())


def test_a_sweep_given_on_the_command_line_reuses_the_main_training(quick, tmp_path, capsys):
    """--sweep-large N with the main policy's N: fig9 is that training's curve, nothing new
    trains; a count below 2 is refused with the flag named."""
    out = tmp_path / "out"
    shutil.copytree(quick, out)
    folders = sorted(p.name for p in (out / "runs").iterdir())
    assert main(["--quick", "--study", str(out / "study.toml"), "--out", str(out),
                 "--only", "fig9", "--sweep-large", str(QUICK.directions)]) == 0
    assert sorted(p.name for p in (out / "runs").iterdir()) == folders, "nothing new ran"
    fig9 = json.loads((out / "fig9.json").read_text())
    assert f"N = [{QUICK.directions}]" in fig9["settings"]
    with pytest.raises(SystemExit):
        main(["--quick", "--out", str(out), "--only", "fig9", "--sweep-large", "1,64"])
    assert "argument --sweep-large: '1,64'" in capsys.readouterr().err


def test_ppo_flags_are_train_ppo_flags_the_harness_does_not_set_itself(capsys):
    """--ppo-flags: words of experiments.train_ppo's flags that make a valid PPO
    configuration; the ones the harness sets per training, unknown ones (abbreviations too)
    and a configuration PPOConfig refuses are errors of the flag, before anything runs."""
    assert _ppo_flags("--envs 500 --minibatches 400") == ("--envs", "500", "--minibatches", "400")
    for flags, why in [("--seed 3", "['--seed'] not allowed"),
                       ("--env-s 9", "['--env-s', '9'] not allowed"),
                       ("--envs 500 --minibatches 32", "a divisor of envs·rollout_steps")]:
        with pytest.raises(SystemExit):
            main(["--quick", "--ppo-flags", flags])
        assert f"argument --ppo-flags: '{flags}': " in capsys.readouterr().err
        with pytest.raises(argparse.ArgumentTypeError, match=re.escape(why)):
            _ppo_flags(flags)


def test_baselines_left_out_are_not_run_and_the_report_says_so(quick, tmp_path, capsys):
    """--skip-baselines mpc,ppo: fig12 and fig13 compare PARS with UVLS alone, from the cached
    runs, fig10_11 is skipped, the paper's MPC and PPO values stay beside empty cells; NOTES.md
    ends the report."""
    out = tmp_path / "out"
    shutil.copytree(quick, out)
    (out / "NOTES.md").write_text("## Notes\n\nMeasured: why.\n")
    results = run(str(out / "study.toml"), out, ["fig10_11", "fig12", "fig13"], quick=True,
                  skip_baselines=("mpc", "ppo"))
    assert set(results) == {"fig12", "fig13"}, "fig10_11 needs PPO"
    fig12 = results["fig12"]["numbers"]
    assert "PARS better than UVLS on" in fig12 and "UVLS fails on" in fig12
    assert not [k for k in fig12 if "MPC" in k or "PPO" in k]
    fig13 = results["fig13"]["numbers"]
    assert {k.split(", ")[1] for k in fig13 if k.startswith("reward, ")} == {"PARS", "UVLS"}
    report = (out / "REPORT.md").read_text()
    assert "left out: MPC, PPO" in report
    assert report.endswith("## Notes\n\nMeasured: why.\n"), "the hand-written notes at its end"
    assert "| PARS better than PPO on |  | 95.29 % |" in report, "the paper's value, ours empty"
    assert main(["--quick", "--study", str(out / "study.toml"), "--out", str(out),
                 "--only", "fig12", "--skip-baselines", "mpc,uvls"]) == 2
    assert "--skip-baselines uvls: unknown; it takes mpc, ppo" in capsys.readouterr().err


def test_gpu_timing_is_read_from_a_gpu_benchmark_and_refused_from_a_cpu_one(tmp_path):
    """Which row of a benchmark file fig7 takes (this study, by name or file, N = directions,
    one device, regrouped as the training is: not on the 39-bus). The rows carry no timing:
    no speed is measured or judged here."""
    wanted = {"directions": QUICK.directions, "devices": 1, "compact_after": None,
              "row": "wanted"}
    others = [{**wanted, "directions": 64, "row": "other N"},
              {**wanted, "devices": 2, "row": "2 devices"},
              {**wanted, "compact_after": 61, "row": "regrouped"}]
    bench = {"backend": "gpu", "device_kind": "Example GPU",
             "cases": [{"case": "ieee300_fidvr", "runs": [{**wanted, "row": "other study"}]},
                       {"case": "studies/ieee39_fidvr.toml", "runs": [*others, wanted]}]}
    path = tmp_path / "train.json"
    path.write_text(json.dumps(bench))
    runs = Runs("ieee39_fidvr", tmp_path, dataclasses.replace(QUICK, gpu_timing=str(path)))
    label, row = runs.gpu_row()
    assert label == "1 Example GPU (train.json)"
    assert row["row"] == "wanted"
    path.write_text(json.dumps({**bench, "backend": "cpu"}))
    with pytest.raises(ValueError, match="no GPU row for study 'ieee39_fidvr' with N = 2"):
        runs.gpu_row()


def test_unknown_experiments_and_a_ppo_budget_below_one_step_are_named(tmp_path, capsys):
    assert main(["--quick", "--only", "fig6a,fig99", "--out", str(tmp_path)]) == 2
    assert "fig99" in capsys.readouterr().err
    assert main(["--quick", "--ppo-env-steps", "0", "--out", str(tmp_path)]) == 2
    assert "--ppo-env-steps 0: must be at least 1" in capsys.readouterr().err


def test_convergence_rule_on_curves_known_by_hand():
    iterations = np.arange(1, 101)
    # -100 for 40 iterations, then -10: the 5-iteration average is within 2 % of -10 from
    # the window that holds only the new value, ending at iteration 45
    step = np.where(iterations <= 40, -100.0, -10.0)
    assert convergence_iteration(iterations, step, 5) == 45
    # a ramp to -100 comes within 2 % (2) of its final value at -102, iteration 98
    ramp = -200.0 + iterations.astype(float)
    assert convergence_iteration(iterations, ramp, 1) == 98
    # with a 10-iteration window it is still rising at its end: its average comes within 2 %
    # of its final -104.5 from iteration 98 on, 3 averages, fewer than a window
    assert convergence_iteration(iterations, ramp, 10) is None, "settles in its last window"
    assert convergence_iteration(iterations[:9], step[:9], 5) is None, "under two windows"


def _result(controller: str, rows: list[tuple]) -> dict:
    """An evaluate result of tasks (fault bus, reward, recovered) at point "p0", 0.1 s."""
    return {"controller": controller, "tasks": [
        {"fault_bus": bus, "fault_duration": 0.1, "fault_start": 1.0, "operating_point": "p0",
         "reward": reward, "recovered": recovered} for bus, reward, recovered in rows]}


def test_side_claims_on_results_whose_answers_are_known_by_hand():
    pars = _result("pars", [(1, -100.0, True), (2, -300.0, True), (3, -500.0, True),
                            (4, -20000.0, False)])
    uvls = _result("uvls", [(1, -15000.0, False), (2, -200.0, True), (3, -500.0, True),
                            (4, -19000.0, False)])
    ppo = _result("ppo", [(2, -6000.0, True), (1, -100.0, True), (3, -400.0, True),
                          (4, -30000.0, False)])  # another order: paired by task
    none = _result("none", [(1, -16000.0, False), (2, -100.0, True), (3, -900.0, False),
                            (4, -25000.0, False)])
    # PARS − UVLS: 14900, −100, 0, −1000
    assert claims.difference_shares(pars, uvls, more_than=10000) == {
        "better": "25.00 %", "at least as good": "50.00 %", "more than": "25.00 %"}
    # PARS − PPO: 0, 5700, −100, 10000
    assert claims.difference_shares(pars, ppo, less_than=5000)["less than"] == "50.00 %"
    assert claims.failures(ppo) == "1 of 4" and claims.failures(uvls) == "2 of 4"
    wins = claims.shedding_wins(none, pars, uvls)  # buses 1, 3, 4 need shedding
    assert wins["better on tasks that need shedding"] == "1 of 3"
    assert wins["not better on"] == ["bus 3, 0.1 s, p0: -500.0 vs -500.0",
                                     "bus 4, 0.1 s, p0: -20000.0 vs -19000.0"]
    with pytest.raises(ValueError, match="different tasks"):
        claims.paired_rewards(pars, _result("short", [(1, 0.0, True)]))


def test_fig12_compares_pars_with_each_baseline_on_evaluations_written_by_hand(tmp_path):
    """fig12 from evaluate results, the MPC among the baselines (the smoke run leaves it out):
    per baseline the shares, the failures and the mean reward, and PARS − MPC."""
    from experiments.reproduce.figures import fig12

    results = {"policy:p": _result("pars", [(1, -100.0, True), (2, -300.0, True)]),
               "uvls": _result("uvls", [(1, -15000.0, False), (2, -200.0, True)]),
               "mpc": _result("mpc", [(1, -400.0, True), (2, -400.0, True)])}
    for result in results.values():
        result["summary"] = {"mean_reward": np.mean([t["reward"] for t in result["tasks"]])}
    runs = SimpleNamespace(
        main_policy=lambda: "policy:p", evaluation=results.__getitem__,
        settings=dataclasses.replace(QUICK, skip_baselines=("ppo",)),
        study=SimpleNamespace(name="by hand", params=SimpleNamespace(unstable_penalty=-1e4)))
    result = fig12(runs, tmp_path / "fig12.png")
    numbers = result["numbers"]
    # means: PARS −200, UVLS −7600, MPC −400; PARS − UVLS: 14900 (> M = 10000), −100
    assert numbers["mean reward, PARS − MPC"] == 200.0
    assert numbers["PARS better than MPC on"] == "100.00 %"
    assert numbers["PARS − UVLS more than M on"] == "50.00 %"
    assert (numbers["UVLS fails on"], numbers["MPC fails on"]) == ("1 of 2", "0 of 2")
    assert "left out: PPO" in result["settings"]
    assert (tmp_path / "fig12.png").stat().st_size > 10_000


def test_buses_not_recovered_and_the_best_ppo_seed():
    trace = {"recovered": False, "observed": [10, 11, 12, 13],
             "vm": [[1.0, 0.96, 0.90, 1.0], [0.5, 0.5, 0.5, 0.5], [0.94, 0.97, 0.80, 0.93]]}
    # bus 12 sat below 0.95 before the fault: not checked; 10 and 13 end below it
    assert claims.buses_not_recovered(trace, 0.95) == [10, 13]
    assert claims.buses_not_recovered({**trace, "recovered": True}, 0.95) == []
    rows = [[{"reward_mean": -50.0}, {"reward_mean": -900.0}],
            [{"reward_mean": -800.0}, {"reward_mean": -300.0}], []]
    assert claims.best_ppo_seed(rows) == 1, "the last line counts; an empty run never wins"


def test_a_run_folder_name_does_not_depend_on_where_the_files_lie(tmp_path):
    """The study key hashes the input files' content, not their paths: the same files in two
    places give one key (so a committed checkpoint resumes from any checkout); a changed
    file gives another."""
    from jaxgrid.study.definition import GridSource

    def key(folder, raw_text):
        folder.mkdir(exist_ok=True)
        raw, dyr = folder / "case.raw", folder / "case.dyr"
        raw.write_text(raw_text)
        dyr.write_text("dynamics")
        grid = GridSource(raw=(str(raw),), dyr=str(dyr))
        text = f'[grid]\nraw = ["{raw}"]\ndyr = "{dyr}"\n'
        return study_key(SimpleNamespace(definition=SimpleNamespace(grid=grid)), text)

    here = key(tmp_path / "a", "network")
    assert key(tmp_path / "b", "network") == here
    assert key(tmp_path / "c", "network, changed") != here


def test_runs_made_before_a_setting_was_written_at_its_default_keep_their_folders(study_file,
                                                                                 tmp_path):
    """A study's resolved TOML gained `shed_limit = 1.0` (its default, no limit) after runs
    were named by the text without it: such a training is found by that earlier key while
    the key's own folder holds no run, a training under the key itself is preferred, and an
    evaluation is named by the key alone."""
    plain = SimpleNamespace(definition=SimpleNamespace(grid=SimpleNamespace(
        raw=(), dyr=None, task_config=None, sim_config=None)))
    written, before = "[env]\nshed_limit = 1.0\nx = 2\n", "[env]\nx = 2\n"
    assert study_keys(plain, written) == (study_key(plain, written), study_key(plain, before))
    limited = "[env]\nshed_limit = 0.6\n"
    assert study_keys(plain, limited) == (study_key(plain, limited),)

    runs = Runs(str(study_file), tmp_path, QUICK)
    assert "shed_limit = 1.0\n" in runs.study_file.read_text()
    inputs = {"config": {"seed": 0}}
    earlier = tmp_path / "runs" / f"pars-{_hash([runs.earlier_keys[0], inputs])}"
    earlier.mkdir(parents=True)
    (earlier / "metrics.jsonl").write_text("")
    assert runs.folder("pars", inputs, training=True) == earlier
    now = tmp_path / "runs" / f"pars-{_hash([runs.study_key, inputs])}"
    assert runs.folder("pars", inputs) == now
    (now / "metrics.jsonl").write_text("")
    assert runs.folder("pars", inputs, training=True) == now


def test_a_gpu_trains_every_task_in_one_batch_in_the_cpu_runs_folder(study_file, tmp_path,
                                                                      monkeypatch):
    """On a GPU a PARS training runs all m tasks in one batch, whatever the preset's task
    batch (a speed setting); its run folder keeps the CPU run's name, so either resumes the
    other's checkpoint."""
    from experiments.common.training import PAPER_PRESETS, train_config

    monkeypatch.setitem(PAPER_PRESETS, "small", {**PAPER_PRESETS["small"], "task_batch": 1})
    runs = Runs(str(study_file), tmp_path, QUICK)
    on_cpu = runs.pars_folder("lstm", 2)

    def task_batch():
        return train_config(runs.study, runs.pars_choices("lstm", 2)).pars.task_batch

    assert task_batch() == 1
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert task_batch() is None
    assert runs.pars_folder("lstm", 2) == on_cpu


def test_seconds_per_iteration_are_given_per_device(tmp_path):
    """A training that ran on a GPU and was resumed on CPUs reports the median seconds per
    iteration on each, so neither device's compile nor the other's speed skews the figure."""
    from experiments.reproduce.figures import _curves

    curves = {"iteration": np.arange(1, 7), "reward": np.array([[-5.0, -4, -3, -2, -2, -2]]),
              "wall_s": np.cumsum([80.0, 1, 1, 90, 7, 8]),
              "device": np.array(["1 × NVIDIA H200"] * 3 + ["2 × cpu"] * 3)}
    runs = SimpleNamespace(settings=SimpleNamespace(window=2, seeds=1), pars=lambda *_: None,
                           pars_curves=lambda _: curves, study=SimpleNamespace(name="grid"))
    numbers = _curves(runs, [("lstm", 32, "N=32")], "LSTM", tmp_path / "curves.png")
    assert numbers["s per iteration (1 seed in one program, median, 1 × NVIDIA H200), N=32"] == 1
    assert numbers["s per iteration (1 seed in one program, median, 2 × cpu), N=32"] == 8
