"""The training command: a run killed with SIGKILL resumes from its last checkpoint, loses
at most --checkpoint-every iterations, and ends where an uninterrupted run ends; two
processes joined by `jax.distributed` on loopback end where one process does; the saved
policy and study load into the evaluation command, and a training can start from it; the
PNNL 300-bus GridPACK files train from their own files. Tiny settings (linear policy, 1
direction, 1 task, 0.5 s episodes) keep it to a few compiles."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from ars import checkpoint
from ars.pars import ParsConfig, init_state
from conftest import REPO
from experiments.common.evaluation import evaluate
from experiments.common.pars_command import run
from jaxgrid.study import read_study

TINY = ["--policy", "linear", "--history", "1", "--directions", "1", "--top", "1",
        "--tasks-per-iteration", "1", "--episode", "0.5", "--checkpoint-every", "3",
        "--seed", "7"]


def _lines(path):
    return path.read_text().splitlines() if path.exists() else []


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    out = tmp_path_factory.mktemp("straight")
    assert run(TINY + ["--iterations", "12", "--out", str(out)], "train_39bus") == 0
    return out


# The killed run hangs before its 8th iteration, so the kill lands at the same point
# however fast the machine is (a run that reached 12 first would leave nothing to resume).
HANG_BEFORE_ITERATION_8 = """
import sys, time
import ars.train
import experiments.common.pars_command as command
make_trainer = ars.train.make_trainer
def hanging_trainer(*args, **kwargs):
    trainer = make_trainer(*args, **kwargs)
    def hang_after_7(state, tasks, data):
        if int(state.iteration) >= 7:
            time.sleep(3600)
        return trainer.iteration(state, tasks, data)
    return trainer._replace(iteration=hang_after_7)
ars.train.make_trainer = hanging_trainer
sys.exit(command.run(sys.argv[1:], "train_39bus"))
"""


def test_sigkill_mid_training_resumes_and_matches_an_uninterrupted_run(tmp_path, straight):
    out = tmp_path / "killed"
    metrics = out / "metrics.jsonl"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-c", HANG_BEFORE_ITERATION_8, *TINY,
                             "--iterations", "1000", "--out", str(out)], cwd=REPO, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while len(_lines(metrics)) < 7 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert len(_lines(metrics)) == 7, "the run did not get going"
    kept = [int(p.name) for p in (out / "checkpoints").iterdir() if p.name.isdigit()]
    assert max(kept) == 6, f"killed after 7 iterations, last checkpoint {max(kept)}"
    assert run(TINY + ["--iterations", "12", "--resume", "--out", str(out)], "train_39bus") == 0
    rows = [json.loads(line) for line in _lines(metrics)]
    assert [r["iteration"] for r in rows] == list(range(1, 13)), "one line per iteration"
    assert max(int(p.name) for p in (out / "checkpoints").iterdir() if p.name.isdigit()) == 12
    a = np.load(out / "policy" / "policy.npz")
    b = np.load(straight / "policy" / "policy.npz")
    np.testing.assert_array_equal(a["theta"], b["theta"])
    np.testing.assert_allclose(a["mean"], b["mean"], rtol=1e-6)


def _train_on_two_processes(out, *args):
    """Run the 39-bus command as 2 processes of 1 CPU device each, joined on loopback."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = dict(os.environ, PYTHONPATH=str(REPO),  # tests/conftest.py's flags, one device
               XLA_FLAGS=os.environ["XLA_FLAGS"].replace("device_count=2", "device_count=1"))
    procs = [subprocess.Popen(
        [sys.executable, "-m", "experiments.train_39bus", *TINY, *args, "--out", str(out),
         "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id", str(i)],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        for i in range(2)]
    logs = [proc.communicate(timeout=600)[0] for proc in procs]
    for i, (proc, log) in enumerate(zip(procs, logs)):
        assert proc.returncode == 0, f"process {i} failed:\n{log[-2000:]}"


def test_two_processes_on_loopback_match_one_process(tmp_path, straight):
    """2 processes x 1 device against 1 process x 2 devices (the same mesh size, so the same
    arithmetic): a fresh start, then a resume from a checkpoint, to 12 iterations."""
    out = tmp_path / "two"
    _train_on_two_processes(out, "--iterations", "6")
    _train_on_two_processes(out, "--iterations", "12", "--resume")
    rows = [json.loads(line) for line in _lines(out / "metrics.jsonl")]
    assert [r["iteration"] for r in rows] == list(range(1, 13)), "one writer, one line each"
    one = [json.loads(line) for line in _lines(straight / "metrics.jsonl")]
    assert [r["reward_mean"] for r in rows] == [r["reward_mean"] for r in one]
    a = np.load(out / "policy" / "policy.npz")
    b = np.load(straight / "policy" / "policy.npz")
    for name in ("theta", "mean", "std"):
        np.testing.assert_array_equal(a[name], b[name])


def test_saved_policy_evaluates_and_runs_refuse_the_wrong_folder(straight, tmp_path, capsys,
                                                                ieee39):
    study = read_study(straight / "study.toml")
    assert study.definition == ieee39.definition, "the run's study is saved"
    result = evaluate(study, f"policy:{straight / 'policy'}", "train")
    assert result["summary"]["n_tasks"] == 9
    assert (straight / "learning_curve.png").is_file()
    kept = sorted(p.name for p in (straight / "policies").iterdir())
    assert kept == ["00003", "00006", "00009", "00012"], "a policy at every checkpoint"
    last, final = (np.load(straight / d / "policy.npz") for d in ("policies/00012", "policy"))
    np.testing.assert_array_equal(last["theta"], final["theta"])
    assert run(TINY + ["--resume", "--out", str(tmp_path)], "train_39bus") == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert run(TINY + ["--resume", "--iterations", "6", "--out", str(straight)], "train_39bus") == 2
    assert "past --iterations 6" in capsys.readouterr().err
    assert run(TINY + ["--resume", "--obs-clip", "5", "--out", str(straight)], "train_39bus") == 2
    assert "has --obs-clip None, not 5.0" in capsys.readouterr().err
    assert run(TINY + ["--resume", "--relative-inputs", "--out", str(straight)],
               "train_39bus") == 2
    assert "has --relative-inputs False, not True" in capsys.readouterr().err
    assert run(TINY + ["--resume", "--max-request", "0.1", "--out", str(straight)],
               "train_39bus") == 2
    assert "has --max-request None, not 0.1" in capsys.readouterr().err
    assert run(TINY + ["--self-mask", "--out", str(tmp_path)], "train_39bus") == 2
    assert ("--self-mask: study 'ieee39_fidvr' has no action mask ([env] action_mask)"
            in capsys.readouterr().err)
    assert run(TINY + ["--arming-level", "0.85", "--out", str(tmp_path)], "train_39bus") == 2
    assert "--arming-level: needs --self-mask" in capsys.readouterr().err
    assert run(TINY + ["--obs-clip", "0", "--out", str(tmp_path)], "train_39bus") == 2
    assert "--obs-clip 0.0: allowed > 0" in capsys.readouterr().err
    before = (straight / "metrics.jsonl").read_text()
    assert run(TINY + ["--out", str(straight)], "train_39bus") == 2
    assert "pass --resume" in capsys.readouterr().err
    assert (straight / "metrics.jsonl").read_text() == before, "a fresh run loses nothing"


def test_a_training_starts_from_a_saved_policy_with_its_statistics(straight, tmp_path, capsys):
    """--init-policy: the state starts at the saved θ and statistics, weighted by the
    observations its run had seen (policy.npz's count, or for a policy saved without one,
    its run's env_steps at that iteration), on every seed; the run records where it started
    (a fine-tune also its --max-request and --task-returns), and a policy of another shape
    is refused by name."""
    source = straight / "policies" / "00006"
    policy, (theta, mean, std), info = checkpoint.load_policy(source)
    steps = [json.loads(line)["env_steps"] for line in _lines(straight / "metrics.jsonl")]
    legacy = tmp_path / "runs" / "policy"  # saved before the count was kept
    legacy.mkdir(parents=True)
    (legacy / "policy.json").write_text((source / "policy.json").read_text())
    np.savez(legacy / "policy.npz", theta=theta, mean=mean, std=std)
    (tmp_path / "runs" / "metrics.jsonl").write_text((straight / "metrics.jsonl").read_text())
    for folder in (source, legacy):
        state = checkpoint.warm_start(init_state(policy, ParsConfig(), seeds=2), folder,
                                      policy.spec)
        np.testing.assert_array_equal(state.theta, np.stack([theta, theta]))
        assert state.stats.count.tolist() == [steps[5]] * 2, "the run's observations at 6"
        for seed in range(2):
            np.testing.assert_allclose(state.stats.replace(
                count=state.stats.count[seed], m2=state.stats.m2[seed]).std, std, rtol=1e-6)
        np.testing.assert_array_equal(state.stats.mean, np.stack([mean, mean]))
    out = tmp_path / "tuned"  # under a smaller output range (--max-request): θ carries over
    assert run(TINY + ["--init-policy", str(source), "--max-request", "0.1", "--iterations", "1",
                       "--task-returns", "ranks", "--out", str(out)], "train_39bus") == 0
    tuned = json.loads((out / "policy" / "policy.json").read_text())
    assert (tuned["init_policy"], tuned["max_request"]) == (str(source), 0.1)
    assert tuned["config"]["task_returns"] == "ranks"
    assert (tuned["spec"]["action_low"], tuned["spec"]["action_high"]) == (-0.1, 0.0)
    assert run(TINY + ["--max-request", "0.3", "--out", str(tmp_path / "wide")],
               "train_39bus") == 2
    assert "--max-request 0.3: allowed in (0, 0.2]" in capsys.readouterr().err
    assert run(TINY + ["--history", "2", "--init-policy", str(source), "--iterations", "1",
                       "--out", str(tmp_path / "other")], "train_39bus") == 2
    assert f"--init-policy {source}: its policy is PolicySpec(" in capsys.readouterr().err


def test_a_self_masked_armed_training_saves_its_arming(tmp_path, capsys):
    """--self-mask --arming-level on a study with an action mask trains (a level outside
    0-2 p.u. is refused first), and the policy and checkpoint keep the level: a resume with
    another is refused."""
    study = tmp_path / "masked.toml"
    study.write_text('[grid]\nbuiltin = "ieee39_fidvr"\n[env]\naction_mask = "hadrec"\n')
    armed = TINY + ["--study", str(study), "--self-mask", "--out", str(tmp_path / "run")]
    assert run(armed + ["--arming-level", "2"], "train") == 2
    assert "--arming-level = 2.0: allowed 0 < p.u. < 2" in capsys.readouterr().err
    assert run(armed + ["--arming-level", "0.8", "--iterations", "1"], "train") == 0
    info = json.loads((tmp_path / "run" / "policy" / "policy.json").read_text())
    assert (info["action_mask"], info["self_mask"], info["arming_level"]) == ("hadrec", True, 0.8)
    assert run(armed + ["--arming-level", "0.7", "--iterations", "2", "--resume"], "train") == 2
    assert "has --arming-level 0.8, not 0.7" in capsys.readouterr().err


def test_the_300_bus_gridpack_files_train_from_their_own_files(shared_cases, tmp_path):
    """The PNNL GridPACK pair with its LSTM multi-operating-point training file (zone-1
    observation scope, 34 action buses, 8 fault buses), a few stratified iterations, then a
    resume that reads the run folder's study.toml alone."""
    folder = shared_cases / "ieee300"
    args = ["--raw", str(folder / "IEEE300Bus_modified_noHVDC_v23_reduce3bigloads.raw"),
            "--dyr", str(folder / "IEEE300_genrou_exdc1_tgov1_zone1ac.dyr"),
            "--task-config",
            str(folder / "IEEE300_RL_loadShedding_zone1_continuous_LSTM_multipfcases_training_"
                         "gp.json"),
            "--hidden", "8,8", "--directions", "2", "--top", "1", "--tasks-per-iteration", "2",
            "--task-sampling", "stratified", "--episode", "0.3", "--checkpoint-every", "2",
            "--out", str(tmp_path)]
    assert run(args + ["--iterations", "2"], "train") == 0
    assert run(["--resume", "--iterations", "3", "--hidden", "8,8", "--directions", "2",
                 "--top", "1", "--tasks-per-iteration", "2", "--task-sampling", "stratified",
                 "--episode", "0.3", "--checkpoint-every", "2", "--out", str(tmp_path)],
               "train") == 0
    rows = [json.loads(line) for line in _lines(tmp_path / "metrics.jsonl")]
    assert [r["rollouts"] for r in rows] == [8, 16, 24]
    assert all(np.isfinite(r["reward_mean"]) for r in rows)
    saved = json.loads((tmp_path / "policy" / "policy.json").read_text())
    assert saved["spec"]["kind"] == "lstm" and saved["study"] == \
        "IEEE300_FIDVR_LoadShedding_Continuous_Action"
    assert len(saved["layout"]["observed_buses"]) == 142 == saved["spec"]["obs_size"] - 34


def test_tasks_per_iteration_fits_the_set_or_names_the_flag():
    """By default m is 9 or the whole set if smaller; asking for more than the set has names
    --tasks-per-iteration."""
    from types import SimpleNamespace

    from experiments.common.training import Choices, tasks_per_iteration

    study = SimpleNamespace(name="two_raws", tasks=lambda name: [None] * 6)

    def args(m=None, sampling="uniform"):
        return Choices(tasks_per_iteration=m, task_set="train", task_sampling=sampling)

    assert tasks_per_iteration(study, args()) == 6
    assert tasks_per_iteration(study, args(4)) == 4
    with pytest.raises(ValueError, match=r"--tasks-per-iteration 9: the task set 'train' of "
                                         r"study 'two_raws' has 6 tasks; pass "
                                         r"--tasks-per-iteration 6 or fewer"):
        tasks_per_iteration(study, args(9))


def test_shaping_and_joined_task_sets_change_the_training_only(capsys, ieee39):
    """--task-set train+test trains on both sets' tasks; --shaping sets reward weights of the
    training episodes while the study (what evaluations and the saved study use) keeps its
    own; bad items name the flag."""
    from experiments.common.training import shaping
    from jaxgrid.problem import training_problem

    study = ieee39
    weights = shaping(["c_normal=30", "c_shed=200"])
    assert weights == (("c_normal", 30.0), ("c_shed", 200.0))
    problem = training_problem(study, "lstm", task_set="train+test", shaping=dict(weights))
    assert problem.tasks.point.shape == (len(study.tasks("train")) + len(study.tasks("test")),)
    assert (problem.episode.params.c_normal, problem.episode.params.c_shed) == (30.0, 200.0)
    assert study.params.c_normal == 0.0 and problem.info["shaping"] == dict(weights)
    with pytest.raises(ValueError, match=r"stratified sampling draws from one task set"):
        training_problem(study, "lstm", task_set="train+test", sampling="stratified")
    for items, message in ((["c_volt=1"], r"--shaping 'c_volt=1': FIELD=VALUE with FIELD one "
                                          r"of c_voltage, c_shed"),
                           (["c_normal=-1"], r"--shaping c_normal = -1.0: must lie in"),
                           (["c_normal=x"], r"VALUE must be a number"),
                           (["c_shed=1", "c_shed=2"], r"a field given twice")):
        with pytest.raises(ValueError, match=message):
            shaping(items)
    assert run(["--shaping", "c_volt=1", "--iterations", "1", "--out", "unused"],
               "train_39bus") == 2
    assert "--shaping 'c_volt=1'" in capsys.readouterr().err


def test_c_quiet_charges_shedding_on_the_tasks_that_recover_without_control(monkeypatch,
                                                                             ieee39):
    """--shaping c_quiet=C labels each training task by one uncontrolled episode (the
    zero-duration faults recover, bus 4's 0.08-s fault, the study's FIDVR case, does not)
    and charges C per p.u. shed on the quiet ones, in training only: the evaluator's rewards
    (population's, stubbed here) lose C·shed_pu where the task is quiet, nothing elsewhere;
    the episodes' own reward weights stay the study's; a negative C names the flag."""
    from experiments.common.training import shaping
    from jaxgrid import population
    from jaxgrid.problem import training_problem

    problem = training_problem(ieee39, "lstm", shaping=dict(shaping(["c_quiet=500"])))
    specs = ieee39.tasks("train")
    quiet = dict(zip([(s.fault_bus, s.fault_duration) for s in specs], problem.tasks.quiet))
    assert all(quiet[bus, 0.0] for bus in (4, 15, 21)) and not quiet[4, 0.08]
    assert problem.episode.params == ieee39.params and problem.quiet_charge == 500.0
    reward = np.array([[-10.0, -20.0, -30.0], [-1.0, -2.0, -3.0]])  # (P, m)
    shed = np.array([[0.5, 0.5, 0.0], [0.1, 0.0, 0.2]])
    monkeypatch.setattr(population, "evaluator", lambda *a, **k: (
        lambda thetas, shared, tasks, data: {"reward": reward, "shed_pu": shed}))
    tasks = problem.tasks.replace(quiet=np.array([True, False, True]))
    out = problem.evaluator(None, None, None)(None, None, tasks, None)
    np.testing.assert_allclose(out["reward"], [[-260.0, -20.0, -30.0], [-51.0, -2.0, -103.0]])
    with pytest.raises(ValueError, match=r"--shaping c_quiet = -1.0: must lie in"):
        shaping(["c_quiet=-1"])


def test_c_beat_rewards_beating_uvls_on_each_training_task(monkeypatch, ieee39):
    """--shaping c_beat=B beat_scale=S labels each training task with the reward UVLS earns
    on it (the evaluation's, `experiments.common.evaluation.evaluate`) and adds
    B·tanh((r − r_UVLS)/S) to each training episode's reward r, beside c_quiet's charge;
    without a reference controller, with S <= 0 or S without B, it names what is wrong."""
    from experiments.common.evaluation import evaluate
    from experiments.common.training import Choices, problem, shaping
    from jaxgrid import population
    from jaxgrid.problem import training_problem

    weights = shaping(["c_beat=200", "beat_scale=50", "c_quiet=100"])
    trained = problem(ieee39, dataclasses.replace(Choices(), shaping=weights))
    assert (trained.beat_bonus, trained.beat_scale, trained.quiet_charge) == (200, 50, 100)
    uvls = {(t["fault_bus"], t["fault_duration"]): t["reward"]
            for t in evaluate(ieee39, "uvls", "train")["tasks"]}
    labels = dict(zip([(s.fault_bus, s.fault_duration) for s in ieee39.tasks("train")],
                      trained.tasks.reference_reward))
    assert labels.keys() == uvls.keys()
    for task, reward in uvls.items():  # float32 episodes, the same program
        assert labels[task] == pytest.approx(reward, rel=1e-5, abs=1e-3), task
    assert min(uvls.values()) < -100 < max(uvls.values()), "failing and recovering tasks"

    reward = np.array([[-10.0, -200.0], [-60.0, -2.0]], np.float32)  # (P, m), as episodes'
    shed = np.array([[0.5, 0.0], [0.1, 0.2]], np.float32)
    monkeypatch.setattr(population, "evaluator", lambda *a, **k: (
        lambda thetas, shared, tasks, data: {"reward": reward, "shed_pu": shed}))
    tasks = trained.tasks.replace(quiet=np.array([True, False]),
                                  reference_reward=np.array([-60.0, -100.0]))
    out = trained.evaluator(None, None, None)(None, None, tasks, None)
    bonus = 200 * np.tanh((reward - [-60.0, -100.0]) / 50)
    np.testing.assert_allclose(out["reward"], reward - 100 * shed * [1, 0] + bonus, rtol=1e-5)
    assert out["reward"][1, 0] == pytest.approx(-70.0), "a tie: no bonus, c_quiet's charge"
    with pytest.raises(ValueError, match=r"c_beat: a reference controller is needed"):
        training_problem(ieee39, "lstm", shaping={"c_beat": 1.0})
    with pytest.raises(ValueError, match=r"--shaping beat_scale = 0.0: must lie in \(0, "):
        shaping(["beat_scale=0"])
    with pytest.raises(ValueError, match=r"beat_scale scales c_beat's bonus; give c_beat=B"):
        shaping(["c_quiet=100", "beat_scale=50"])


def test_task_batch_auto_is_every_task_on_a_gpu_and_the_preset_elsewhere(monkeypatch, capsys):
    """--task-batch 'auto' (the default) is the command's preset on CPUs (one task per batch
    for the 300-bus command) and all m tasks in one batch (None) on a GPU; a number is kept;
    anything else names the flag."""
    import jax

    from experiments.common.pars_command import parser
    from experiments.common.training import PAPER_PRESETS, task_batch

    args = parser("train_300bus").parse_args([])
    assert args.task_batch == "auto"
    assert task_batch(args.task_batch, PAPER_PRESETS["large"]["task_batch"]) == 1
    assert task_batch(3, 1) == 3
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert task_batch("auto", 1) is None
    assert task_batch(3, 1) == 3
    with pytest.raises(SystemExit):
        parser("train").parse_args(["--task-batch", "some"])
    assert "--task-batch: invalid int_or_auto value: 'some'" in capsys.readouterr().err


def test_compact_after_is_the_last_recovery_check_or_names_the_flag():
    """--compact-after 'check' is the agent step of the task set's last recovery check (the
    last fault cleared at 1.08 s, checked more than 5 s later: step 61 of 0.1 s); 'auto' is
    'check' on a grid of more than 100 buses only; a step not inside the episode is off; a bad
    value names the flag and what it allows."""
    from types import SimpleNamespace

    from experiments.common.training import compact_after

    specs = [SimpleNamespace(fault_start=1.0, fault_duration=d) for d in (0.0, 0.08, 0.05)]
    def grid(n_buses):
        return SimpleNamespace(
            tasks=lambda name: specs, params=SimpleNamespace(recovery_time=5.0),
            points=[SimpleNamespace(case=SimpleNamespace(buses=SimpleNamespace(
                number=np.arange(n_buses))))],
            env=lambda episode=10.0: SimpleNamespace(config=SimpleNamespace(
                agent_dt=0.1, n_steps=round(episode / 0.1))))

    study = grid(300)
    assert compact_after("check", study) == 61
    assert compact_after("auto", study) == 61
    assert compact_after("auto", grid(39)) is None
    assert compact_after("check", grid(39)) == 61
    assert compact_after("30", study) == 30
    assert compact_after("check", study, episode=6.0) is None
    with pytest.raises(ValueError, match=r"--compact-after 'soon': allowed 'auto', 'check', "
                                         r"'off' or a number of agent steps >= 1"):
        compact_after("soon", study)


def test_a_training_error_starts_on_a_new_line(tmp_path, capsys, monkeypatch):
    """An error in an iteration closes the progress bar first, so the message has its own
    line."""
    import ars.train

    make_trainer = ars.train.make_trainer

    def failing_trainer(*args, **kwargs):
        def fail(state, tasks, data):
            raise ValueError("broken iteration")
        return make_trainer(*args, **kwargs)._replace(iteration=fail)

    monkeypatch.setattr(ars.train, "make_trainer", failing_trainer)
    assert run(TINY + ["--iterations", "2", "--out", str(tmp_path)], "train_39bus") == 2
    err = capsys.readouterr().err
    assert "\nerror: broken iteration" in err, err
