"""The runs behind `experiments.reproduce`, each cached in the output folder by its inputs.

A run's folder (or file) under OUT/runs/ is named by what it is and a hash of everything it
depends on: the study (its TOML text) and the run's settings. A finished run is reused; a
training run that was interrupted resumes from its last checkpoint; a changed input gives a
new name, so nothing stale is ever read back. PARS and PPO trainings are library calls
(`experiments.common.training.train_pars_study` and `experiments.common.ppo_training
.train_ppo_study`), named by their `ars.train.TrainConfig` and
`baselines.ppo_train.PPOTrainConfig`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ars.checkpoint import metrics_rows
from ars.pars import init_state
from ars.train import make_trainer
from experiments.reproduce.claims import best_ppo_seed
from experiments.common.studyargs import study_from_spec
from experiments.common.curves import SMOOTHING, smoothed
from experiments.common.training import (Choices, paper_preset, problem, train_config,
                                         train_pars_study)
from jaxgrid.problem import play_specs
from jaxgrid.study import Study, write_study

REPO = Path(__file__).resolve().parents[2]


@dataclasses.dataclass(frozen=True)
class Settings:
    """How large the experiments are (FULL: the paper's settings; QUICK: a pipeline check).

    Attributes:
      iterations: PARS iterations per training (the paper: 500).  seeds: PARS seeds per
        configuration.
      directions: N of the study's main policy (fig6a, fig7, fig8, fig10_11, fig12, tab3,
        fig13, generalisation), None for the paper's (`experiments.common.training.paper_preset`:
        16 on the 39-bus, 128 on the 300-bus).  sweep: N of fig6b.  sweep_large: N of fig9.
      tasks_per_iteration: m.  episode: s, None for the study's (the study written to
        OUT/study.toml carries it, so every run uses it).
      test_tasks: test faults per (operating point, duration) kept, None for all; durations
        kept: test_durations (None for all); both apply to the generalisation set too.
      ppo_seeds: PPO trainings (the best one is fig12's and fig13's).  ppo_env_steps: per
        PPO training, None for as many as one PARS training could take (iterations × 2N·m
        episodes × agent steps; failed episodes stop early, so PARS takes fewer).
      ppo_flags: extra `experiments.train_ppo` flags of the PPO trainings (`--ppo-flags`).
      mpc: MPC options (`baselines.mpc.parse_options`).
      timing_iterations: iterations timed per device count (fig7).  processes: fig7's
        `jax.distributed` process count (0: none).
      latency_calls: calls timed per controller (tab3).  window: moving-average window, its.
      policy, ppo_policy: an already trained PARS / PPO policy folder for the case studies,
        fig12 and tab3's evaluations in place of training one (None: train).
      gpu_timing: an `experiments.bench.train` JSON measured on a GPU machine; fig7 adds its
        1-device iteration time for this study and N = directions (None: none).
      skip_baselines: of "mpc", "ppo": baselines left out of fig10_11 (skipped without PPO),
        fig12, tab3 and fig13, for a machine that cannot afford them (on the PNNL 300-bus
        system a PPO training at the paper's budget, or the MPC on the 170 test tasks, takes
        many CPU hours). UVLS is always in.
    """

    iterations: int = 500
    seeds: int = 5
    directions: int | None = None
    sweep: tuple[int, ...] = (8, 16, 32, 64)
    sweep_large: tuple[int, ...] = (32, 64, 128)
    tasks_per_iteration: int = 9
    episode: float | None = None
    test_tasks: int | None = None
    test_durations: int | None = None
    ppo_seeds: int = 5
    ppo_env_steps: int | None = None
    ppo_flags: tuple[str, ...] = ()
    mpc: str = ""
    timing_iterations: int = 5
    processes: int = 2
    latency_calls: int = 200
    window: int = SMOOTHING
    policy: str | None = None
    ppo_policy: str | None = None
    gpu_timing: str | None = None
    skip_baselines: tuple[str, ...] = ()


BASELINES_SKIPPABLE = ("mpc", "ppo")
FULL = Settings()
QUICK = Settings(iterations=2, seeds=2, directions=2, sweep=(2, 4), sweep_large=(2, 4),
                 tasks_per_iteration=1, episode=1.5, test_tasks=2, test_durations=1,
                 ppo_seeds=1, ppo_env_steps=32,
                 ppo_flags=("--envs", "2", "--rollout-steps", "16", "--minibatches", "2",
                            "--epochs", "1", "--eval-every", "1"),
                 mpc="horizon=0.2,iterations=1,dt=0.02", timing_iterations=1, processes=0,
                 latency_calls=3, window=1)


def _hash(value) -> str:
    return hashlib.sha1(json.dumps(value, sort_keys=True).encode()).hexdigest()[:10]


def study_key(study: Study, text: str) -> str:
    """Hash of a study's resolved TOML `text` with each input file's absolute path replaced by
    a hash of the file's content, so that a run folder's name (and a committed checkpoint)
    does not depend on where the checkout and the case files lie."""
    grid = study.definition.grid
    for path in sorted({*grid.raw, *filter(None, (grid.dyr, grid.task_config,
                                                  grid.sim_config))}, key=len, reverse=True):
        text = text.replace(path, hashlib.sha1(Path(path).read_bytes()).hexdigest())
    return _hash(text)


# Lines that every resolved study TOML gained with a new setting at its default (the study
# unchanged): runs made before a line came keep the names that the text without it gives.
ADDED_AT_DEFAULT = ("shed_limit = 1.0\n",)  # [env] shed_limit (078c57a), 1.0: no limit


def study_keys(study: Study, text: str) -> tuple[str, ...]:
    """The study's key (`study_key`), then the keys it had before the `ADDED_AT_DEFAULT`
    lines of `text` were written."""
    keys = [study_key(study, text)]
    for line in ADDED_AT_DEFAULT:
        if line in text:
            text = text.replace(line, "", 1)
            keys.append(study_key(study, text))
    return tuple(keys)


def _holds_a_run(folder: Path) -> bool:
    """Whether a run folder holds more than its inputs.json."""
    return folder.is_dir() and any(f.name != "inputs.json" for f in folder.iterdir())


class Runs:
    """The study of a reproduction and its cached runs under `out`/runs."""

    def __init__(self, study_spec: str, out: str | Path, settings: Settings):
        self.out = Path(out)
        self.settings = settings
        self.study = _sized(study_from_spec(study_spec), settings)
        self.out.mkdir(parents=True, exist_ok=True)
        self.study_file = self.out / "study.toml"
        write_study(self.study, self.study_file)
        self.study_key, *self.earlier_keys = study_keys(self.study, self.study_file.read_text())
        self.preset = paper_preset(self.study)
        self.directions = settings.directions or self.preset["directions"]
        self.trainings: set[Path] = set()  # PARS / PPO run folders used since last cleared
        self.main_policy_evaluated = False  # an experiment here evaluated the trained one

    def folder(self, kind: str, inputs: dict, training: bool = False) -> Path:
        """OUT/runs/KIND-HASH for `inputs` (with the study), and its inputs.json. A `training`
        is found by an earlier key of the study too (`study_keys`) where the key's own folder
        holds none; evaluations are named by the key alone, so they are made with today's
        code beside UVLS's."""
        keys = (self.study_key, *self.earlier_keys) if training else (self.study_key,)
        named = [self.out / "runs" / f"{kind}-{_hash([key, inputs])}" for key in keys]
        folder = next((f for f in named if _holds_a_run(f)), named[0])
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "inputs.json").write_text(json.dumps(inputs, indent=1))
        return folder

    # --- PARS ------------------------------------------------------------------------------
    def pars_choices(self, policy: str, directions: int) -> Choices:
        """The `Choices` of a PARS training of `policy` with N = directions, the paper's other
        settings for the grid's size (`experiments.common.training.train_config`: b = N/2,
        the preset's widths, decay and task batch, the large grid regrouped after the
        recovery check), the study's history for the policy kind and its task sampling,
        `settings.seeds` seeds in one program."""
        s = self.settings
        return Choices(policy=policy, directions=directions,
                       tasks_per_iteration=s.tasks_per_iteration, iterations=s.iterations,
                       seeds=s.seeds, history=self.study.history(policy),
                       task_sampling=self.study.definition.training.task_sampling)

    def pars_folder(self, policy: str, directions: int) -> Path:
        """The run folder of that PARS training (made, not trained), named by its config."""
        return self.choices_folder(f"pars_{policy}_N{directions}",
                                   self.pars_choices(policy, directions))

    def choices_folder(self, kind: str, choices: Choices) -> Path:
        """OUT/runs/KIND-HASH of the PARS training of `choices` (made, not trained), named by
        its `ars.train.TrainConfig`, history, sampling and training-only shaping."""
        config = train_config(self.study, choices)
        inputs = {k: v for k, v in dataclasses.asdict(config).items()
                  if k not in ("out", "resume")}
        for speed_only in ("compact_after", "compact_chunks"):  # folders named as before them
            inputs["pars"].pop(speed_only)
        if inputs["pars"]["obs_std_floor"] is None:  # named as before it
            inputs["pars"].pop("obs_std_floor")
        if inputs["pars"]["task_returns"] == "mean":  # the paper's: named as before it
            inputs["pars"].pop("task_returns")
        if inputs["obs_clip"] is None:  # named as before it
            inputs.pop("obs_clip")
        for flag in ("relative_inputs", "self_mask", "arming_level", "init_policy",
                     "max_request"):
            if inputs[flag] is False or inputs[flag] is None:  # named as before it
                inputs.pop(flag)
        inputs["pars"]["task_batch"] = self.preset["task_batch"]  # the same on a GPU
        named = {"config": inputs, "history": choices.history,
                 "sampling": choices.task_sampling}
        if choices.task_set != "train":
            named["task_set"] = choices.task_set
        if choices.shaping:
            named["shaping"] = dict(choices.shaping)
        return self.folder(kind, named, training=True)

    def pars_finished(self, folder: Path) -> bool:
        rows = metrics_rows(folder / "metrics.jsonl")
        return bool(rows) and rows[-1]["iteration"] >= self.settings.iterations and (
            folder / "policy").is_dir()

    def pars(self, policy: str, directions: int) -> Path:
        """A finished PARS training (`pars_choices`,
        `experiments.common.training.train_pars_study`); its folder. An interrupted one
        resumes from its last checkpoint."""
        return self.trained(self.pars_folder(policy, directions),
                            self.pars_choices(policy, directions))

    def trained(self, folder: Path, choices: Choices) -> Path:
        """`folder` (`choices_folder`) holding the finished training of `choices`, trained or
        resumed from its last checkpoint unless it is finished."""
        self.trainings.add(folder)
        rows = metrics_rows(folder / "metrics.jsonl")
        if rows and rows[-1]["iteration"] >= choices.iterations and (folder / "policy").is_dir():
            return folder
        resume = any((folder / "checkpoints").glob("[0-9]*"))
        train_pars_study(self.study, dataclasses.replace(choices, out=str(folder),
                                                         resume=resume))
        return folder

    def training_time(self) -> tuple[float, list[str]]:
        """(wall s, devices) of the trainings in `trainings`, from their metrics over every
        invocation they ran in: the s summed (first iterations include compilation), the
        devices ('COUNT × KIND') listed, 'unrecorded devices' for lines that predate them."""
        rows = [r for folder in self.trainings for r in metrics_rows(folder / "metrics.jsonl")]
        return (sum(r["wall_s"] for r in rows),
                sorted({r.get("device", "unrecorded devices") for r in rows}))

    def pars_curves(self, folder: Path) -> dict:
        """Per-seed learning curves of a PARS run: iteration (n,), reward (seeds, n) (mean over
        the iteration's perturbed rollouts), wall_s (n,) cumulative, device (n,) where each
        iteration ran ('COUNT × KIND'), episodes (n,) per seed, env_steps (seeds, n)
        cumulative agent steps simulated."""
        rows = metrics_rows(folder / "metrics.jsonl")
        return {"iteration": np.array([r["iteration"] for r in rows]),
                "reward": np.array([r["reward_mean"] for r in rows], float).reshape(
                    len(rows), -1).T,
                "wall_s": np.cumsum([r["wall_s"] for r in rows]),
                "device": np.array([r.get("device", "unrecorded devices") for r in rows]),
                "episodes": np.array([r["rollouts"] for r in rows]),
                "env_steps": np.array([r["env_steps"] for r in rows], float).reshape(
                    len(rows), -1).T}

    def best_seed_folder(self, folder: Path) -> Path:
        """The policy folder of the seed whose smoothed final training reward is highest."""
        curves = self.pars_curves(folder)
        window = min(self.settings.window, curves["reward"].shape[1])
        final = smoothed(curves["reward"], window)[:, -1]
        return folder / "policy" / f"seed{int(np.argmax(final))}"

    def best_seed(self, folder: Path) -> str:
        """controller spec of `best_seed_folder`."""
        return f"policy:{self.best_seed_folder(folder)}"

    def main_policy(self) -> str:
        """The PARS controller of the case studies, fig12, tab3 and generalisation: the given
        policy, or the best seed of the LSTM training with N = directions."""
        if self.settings.policy:
            return f"policy:{self.settings.policy}"
        self.main_policy_evaluated = True
        return self.best_seed(self.pars("lstm", self.directions))

    def export_policy(self) -> Path | None:
        """Copy the best seed of the finished main LSTM training to OUT/policy (loadable by
        `experiments.evaluate --controller policy:OUT/policy`); None if it is not trained, if
        a policy was given (`settings.policy`: the experiments used that one, so OUT/policy
        is left as it is, e.g. when a redraw passes `--policy OUT/policy`), if OUT/policy
        exists and no experiment here evaluated the trained one (a training-curve redraw such
        as `--only fig6b` keeps the policy that the report's evaluations were measured with),
        or if OUT/policy is a policy of another study (one committed on purpose: an ablation's
        best configuration)."""
        target = self.out / "policy"
        existing = target / "policy.json"
        if self.settings.policy or (existing.is_file() and (
                not self.main_policy_evaluated
                or json.loads(existing.read_text()).get("study") != self.study.name)):
            return None
        folder = self.pars_folder("lstm", self.directions)
        if not self.pars_finished(folder):
            return None
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(self.best_seed_folder(folder), target)
        return target

    # --- PPO -------------------------------------------------------------------------------
    def ppo(self, seed: int, env_steps: int) -> Path:
        """A finished PPO training (`experiments.common.ppo_training.train_ppo_study`, the study's Table II
        defaults with `settings.ppo_flags`) of `env_steps` environment steps; its folder,
        named by its `baselines.ppo_train.PPOTrainConfig`. An interrupted one resumes."""
        from experiments.common.ppo_training import config_from_args, parser
        from experiments.common.ppo_training import train_ppo_study

        flagged = config_from_args(parser().parse_args(list(self.settings.ppo_flags)))
        config = dataclasses.replace(flagged, env_steps=env_steps,
                                     ppo=dataclasses.replace(flagged.ppo, seed=seed))
        inputs = {k: v for k, v in dataclasses.asdict(config).items()
                  if k not in ("out", "resume")}
        folder = self.folder(f"ppo_seed{seed}", {"config": inputs}, training=True)
        self.trainings.add(folder)
        if (folder / "policy").is_dir():
            return folder
        resume = any((folder / "checkpoints").glob("[0-9]*"))
        train_ppo_study(self.study, dataclasses.replace(config, out=str(folder), resume=resume))
        return folder

    def best_ppo(self, env_steps: int) -> str:
        """controller spec of the best of the `ppo_seeds` PPO trainings (`best_ppo_seed`)."""
        folders = [self.ppo(seed, env_steps) for seed in range(self.settings.ppo_seeds)]
        best = best_ppo_seed([metrics_rows(f / "metrics.jsonl") for f in folders])
        return f"ppo:{folders[best] / 'policy'}"

    # --- evaluations -----------------------------------------------------------------------
    def evaluation(self, control: str, tasks: str = "test", arming_level: float | None = None,
                   arming_late: float | None = None) -> dict:
        """`experiments.evaluate` of `control` on a task set (a saved self-masked policy with
        `arming_level`, p.u., and `arming_late`, s, if given), cached."""
        from experiments.common.evaluation import evaluate

        arming = {k: v for k, v in (("arming_level", arming_level), ("arming_late", arming_late))
                  if v is not None}  # named as before when neither is given
        path = self.folder("eval", {**self._controller_inputs(control), "tasks": tasks, **arming})
        path = path / "result.json"
        if path.is_file():
            return json.loads(path.read_text())
        result = evaluate(self.study, self._spec(control), tasks, arming_level=arming_level,
                          arming_late=arming_late)
        path.write_text(json.dumps(result, indent=1))
        return result

    def trace(self, control: str, fault_bus: int, duration: float) -> dict:
        """One episode of `control` on a fault at `fault_bus` lasting `duration` s at the first
        operating point, cached: t (s), vm (steps, observed buses) p.u., shed_mw cumulative,
        reward, recovered, observed (bus numbers)."""
        from baselines.controllers import load
        from jaxgrid.tasks import TaskSpec

        path = self.folder("trace", {**self._controller_inputs(control), "bus": fault_bus,
                                     "duration": duration})
        path = path / "trace.json"
        if path.is_file():
            return json.loads(path.read_text())
        controller = load(self._spec(control), self.study)
        env = controller.env
        task = TaskSpec(fault_bus, duration, self.study.task_set("test").fault_starts[0])
        _, out = play_specs(self.study, env, controller.apply, controller.params, [task],
                            controller.carry, trace=True)
        steps = out["vm"].shape[1]
        result = {"t": ((np.arange(steps) + 1) * env.config.agent_dt).tolist(),
                  "vm": out["vm"][0].tolist(),
                  "shed_mw": (np.cumsum(out["shed_step_pu"][0]) * self.study.base_mva).tolist(),
                  "reward": float(out["reward"][0]), "recovered": bool(out["recovered"][0]),
                  "observed": list(env.config.observed_buses), "fault_start": task.fault_start}
        path.write_text(json.dumps(result))
        return result

    def _spec(self, control: str) -> str:
        """The controller spec `experiments.evaluate` takes: "mpc" with the settings' options."""
        return f"mpc:{self.settings.mpc}" if control == "mpc" and self.settings.mpc else control

    def _controller_inputs(self, control: str) -> dict:
        """What a cached result of `control` depends on besides the study."""
        return {"controller": _identity(control),
                "mpc": self.settings.mpc if control == "mpc" else None}

    # --- timing ----------------------------------------------------------------------------
    def iteration_seconds(self, devices: int) -> float:
        """Median seconds of one iteration of the main LSTM training (`pars_choices` with
        N = directions, one seed) on a mesh of the first `devices` CPU devices of this
        process, after its compile."""
        import jax
        from jax.sharding import Mesh

        choices = dataclasses.replace(self.pars_choices("lstm", self.directions), seeds=None)
        config = train_config(self.study, choices)
        mesh = Mesh(np.array(jax.devices()[:devices]), ("batch",))
        grid = problem(self.study, choices)
        trainer = make_trainer(grid, config, mesh)
        state = init_state(trainer.policy, config.pars)
        state, _ = jax.block_until_ready(trainer.iteration(state, grid.tasks, grid.data))
        times = []
        for _ in range(self.settings.timing_iterations):
            start = time.perf_counter()
            state, _ = jax.block_until_ready(trainer.iteration(state, grid.tasks, grid.data))
            times.append(time.perf_counter() - start)
        return float(np.median(times))

    def gpu_row(self) -> tuple[str, dict]:
        """(label, run row) of this study's LSTM iteration with N = directions on one device,
        from the `settings.gpu_timing` benchmark JSON (its case named by the study's name or
        file), a row regrouped as the training is (`compact_after`) first; the row's
        `s_per_iteration` is the best of its warm calls."""
        path = Path(self.settings.gpu_timing)
        report = json.loads(path.read_text())
        regrouped = train_config(self.study, self.pars_choices(
            "lstm", self.directions)).pars.compact_after
        rows = sorted((r for case in report["cases"]
                       if self.study.name in (case["case"], Path(case["case"]).stem)
                       for r in case["runs"]
                       if r["directions"] == self.directions and r["devices"] == 1),
                      key=lambda r: r.get("compact_after") != regrouped)
        if report.get("backend") != "gpu" or not rows:
            raise ValueError(f"{path}: no GPU row for study {self.study.name!r} with N = "
                             f"{self.directions} on 1 device (backend "
                             f"{report.get('backend')!r})")
        return f"1 {report['device_kind']} ({path.name})", rows[0]

    def process_seconds(self, processes: int) -> float:
        """Median seconds per iteration of the same training as `iteration_seconds` run as
        `processes` processes of one CPU device each, joined by `jax.distributed` on loopback
        (`experiments.train --coordinator`); the first iteration (compile) is left out.
        Fresh processes are needed here, not a library call: each process of the cluster
        must call `jax.distributed.initialize` before anything touches JAX, and this
        process has long since used it (with its own device count)."""
        s = self.settings
        folder = self.folder("processes", {"processes": processes, "settings": [
            self.directions, s.tasks_per_iteration, s.episode, s.timing_iterations]})
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        env = dict(os.environ, PYTHONPATH=str(REPO),
                   XLA_FLAGS="--xla_force_host_platform_device_count=1")
        flags = ["--study", str(self.study_file), "--policy", "lstm",
                 "--hidden", self.preset["hidden"], "--directions", str(self.directions),
                 "--top", str(max(1, self.directions // 2)),
                 "--tasks-per-iteration", str(s.tasks_per_iteration),
                 "--iterations", str(s.timing_iterations + 1), "--checkpoint-every", "1000",
                 "--out", str(folder / "run"), "--coordinator", f"127.0.0.1:{port}",
                 "--num-processes", str(processes)]
        shutil.rmtree(folder / "run", ignore_errors=True)  # a timing starts afresh
        procs = [subprocess.Popen([sys.executable, "-m", "experiments.train", *flags,
                                   "--process-id", str(i)], cwd=REPO, env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                 for i in range(processes)]
        logs = [proc.communicate(timeout=3600)[0] for proc in procs]
        for i, (proc, log) in enumerate(zip(procs, logs)):
            if proc.returncode:
                raise RuntimeError(f"process {i} of {processes} failed:\n{log[-2000:]}")
        return float(np.median([r["wall_s"] for r in metrics_rows(folder / "run" / "metrics.jsonl")
                                [1:]]))


def convergence_iteration(iterations: np.ndarray, reward: np.ndarray, window: int,
                          tolerance: float = 0.02) -> int | None:
    """The study's rule: the first iteration from which the `window`-iteration moving
    average of `reward` (n,) stays within `tolerance` (relative) of its final value, for at
    least `window` averages to the run's end; None for a run shorter than two windows (too
    short to tell) or one that settles only in its last window (still changing)."""
    if len(reward) < 2 * window:
        return None
    average = smoothed(np.asarray(reward, float), window)
    inside = np.abs(average - average[-1]) <= tolerance * abs(average[-1])
    outside = np.flatnonzero(~inside)
    first = 0 if outside.size == 0 else int(outside[-1]) + 1
    return int(iterations[window - 1 + first]) if len(average) - first >= window else None


def _sized(study: Study, settings: Settings) -> Study:
    """The study with the settings' episode length and test and generalisation set sizes."""
    definition = study.definition
    env = (definition.env if settings.episode is None
           else dataclasses.replace(definition.env, episode=settings.episode))
    tasks = dict(definition.tasks)
    for name in ("test", "generalisation"):
        if name in tasks:
            kept = tasks[name]
            tasks[name] = dataclasses.replace(
                kept, fault_buses=kept.fault_buses[:settings.test_tasks],
                fault_durations=kept.fault_durations[:settings.test_durations])
    return dataclasses.replace(study, definition=dataclasses.replace(
        definition, env=env, tasks=tasks))


def _identity(control: str) -> str:
    """A controller spec with a policy path (a folder, or an rlgc file) replaced by the
    policy's content hash, so an evaluation is recomputed when the policy changes."""
    kind, _, path = control.partition(":")
    if kind not in ("policy", "ppo", "rlgc"):
        return control
    digest = hashlib.sha1()
    for file in [Path(path)] if kind == "rlgc" else sorted(Path(path).glob("**/*")):
        if file.is_file():
            digest.update(file.read_bytes())
    return f"{kind}:{digest.hexdigest()[:10]}"

