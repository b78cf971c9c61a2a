"""PARS training of a load-shedding policy on a study (built-in, study file, or RAW + DYR +
task files).

    python -m experiments.train --study ieee39_fidvr|studies/x.toml --out DIR
    python -m experiments.train --raw R1 R2 ... --dyr D --task-config J [--sim-config S] --out DIR

`experiments.train_39bus` and `experiments.train_300bus` are presets (`PRESETS`: the built-in
studies with the paper's hyper-parameters); every hyper-parameter has a flag, mapped one to
one onto `ars.train.TrainConfig` (the training loop) or `jaxgrid.rollouts.training_problem`
(--history, --episode, --task-set, --task-sampling: the study's side). Each iteration draws
m tasks of the study's training set across its operating points, uniformly or stratified
(`--task-sampling`); all operating points share one compiled iteration. Output folder DIR:
  study.toml      the resolved study (`--resume` without --study reads it back)
  metrics.jsonl   one line per iteration: iteration, reward_mean, reward_max, wall_s, rollouts,
                  env_steps (agent steps simulated, cumulative: failed episodes stop early),
                  device (the devices it ran on, "COUNT × KIND": a run resumed elsewhere says so)
  checkpoints/    orbax checkpoints every --checkpoint-every iterations and at the end
  policy/         the trained policy (experiments.evaluate --controller policy:DIR/policy)
  policies/NNNNN/ the policy after iteration NNNNN, at every checkpoint (all kept: the last
                  is not always the one that generalises best to the test tasks)
  learning_curve.png
`--resume` continues from the last checkpoint; `--iterations` is the run's total.
`--seeds K` trains K seeds of the configuration as one vmapped program (a leading seed axis
on the training state): metrics.jsonl then holds per-seed lists of reward_mean and
reward_max and env_steps (rollouts counts one seed's), and each policy folder holds seed0/ ...
seedK-1/. The study's [training] settings give the defaults of --history (per policy kind)
and --task-sampling; episodes run only at the operating points of the task set.
Multi-host: --coordinator HOST:PORT --num-processes P --process-id I, or --distributed alone
where `jax.distributed.initialize` can read them from the cluster environment; it is called
before anything else touches JAX. Process 0 writes the files.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
import numpy as np

from experiments.studyargs import add_study_arguments, study_from_args

TASKS_PER_ITERATION = 9  # m when --tasks-per-iteration is not given and the set has as many

# The paper's Table I per system: the 39-bus column for studies up to 100 buses, else the
# 300-bus one (N: the directions its main policy trained with; b = N/2).
PAPER_PRESETS = {"small": {"hidden": "32,32", "decay": 0.99, "directions": 16, "top": 8,
                           "task_batch": None},
                 "large": {"hidden": "64,64", "decay": 0.996, "directions": 128, "top": 64,
                           "task_batch": 1}}

# Hyper-parameter defaults per command (`python -m experiments.NAME`). The large grids' m
# tasks run one after another (task_batch 1: 256 rollouts per batch, and a task's batch
# stops once all its episodes have failed; measured on 2 CPU devices 1.17× faster per
# iteration at θ = 0, 2.4× after the first update).
PLAIN = {"study": None, "policy": "lstm", **PAPER_PRESETS["small"], "iterations": 200}
PRESETS = {"train": PLAIN,
           "train_39bus": {**PLAIN, "study": "ieee39_fidvr"},
           "train_300bus": {**PLAIN, **PAPER_PRESETS["large"], "study": "ieee300_fidvr",
                            "iterations": 500}}


def paper_preset(study) -> dict:
    """The `PAPER_PRESETS` entry for `study`'s grid size."""
    n_buses = len(study.points[0].case.buses.number)
    return PAPER_PRESETS["large" if n_buses > 100 else "small"]


def parser(defaults: dict) -> argparse.ArgumentParser:
    study = defaults["study"]
    p = argparse.ArgumentParser(prog="python -m experiments.train",
                                description=f"PARS training on {study or 'a study'}")
    add_study_arguments(p, study)
    p.add_argument("--policy", default=defaults["policy"], choices=["linear", "fnn", "lstm"])
    p.add_argument("--hidden", default=defaults["hidden"], help="layer widths, e.g. 32,32")
    p.add_argument("--obs-clip", type=float,
                   help="clip the policy's normalised inputs to ± this many standard "
                        "deviations (default: no clip, as the paper)")
    p.add_argument("--history", type=int,
                   help="observations stacked (default: the study's for the policy kind, "
                        "[training] history; the PNNL study files give 10 for linear and FNN, "
                        "1 for LSTM policies)")
    p.add_argument("--directions", type=int, default=defaults["directions"], help="N")
    p.add_argument("--top", type=int, default=defaults["top"], help="b")
    p.add_argument("--step-size", type=float, default=1.0, help="α")
    p.add_argument("--noise", type=float, default=2.0, help="ν")
    p.add_argument("--decay", type=float, default=defaults["decay"], help="ε")
    p.add_argument("--tasks-per-iteration", type=int,
                   help=f"m (default {TASKS_PER_ITERATION}, or every task of the set if it "
                        "has fewer)")
    p.add_argument("--task-batch", type=int_or_auto, default="auto",
                   help="tasks whose rollouts run as one batch, or 'auto' (default: all m on "
                        f"a GPU, else {defaults['task_batch'] or 'all m'}); batches run one "
                        "after another and stop once all their episodes are done")
    p.set_defaults(preset_task_batch=defaults["task_batch"])
    p.add_argument("--compact-after", default="auto",
                   help="agent steps after which the episodes still running in a batch "
                        "continue regrouped, so episodes that ended stop costing: 'check' "
                        "(the step of the task set's last recovery check, after which failed "
                        "episodes have stopped), a number, 'off', or 'auto' (default: 'check' "
                        "on grids of more than 100 buses, else 'off': measured faster on the "
                        "PNNL 300-bus on CPUs and a GPU, slower on the 39-bus)")
    p.add_argument("--compact-chunks", type=int, default=4,
                   help="the episodes still running continue in chunks of 1/K of a batch, "
                        "as many as they fill")
    p.add_argument("--task-set", default="train", help="the study's task set to train on")
    p.add_argument("--task-sampling", choices=["uniform", "stratified"],
                   help="m distinct tasks uniformly, or k buses × k' durations as the paper "
                        "(default: the study's [training] task_sampling)")
    p.add_argument("--iterations", type=int, default=defaults["iterations"],
                   help="total iterations of the run (with --resume: continue up to it)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", type=int,
                   help="K independent trainings (seeds --seed ... --seed + K − 1) vmapped "
                        "into one compiled program; metrics per seed, policies in seedI/")
    p.add_argument("--episode", type=float, help="episode length, s (default: the study's)")
    p.add_argument("--out", default=f"runs/{study or 'study'}", help="output folder")
    p.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    p.add_argument("--checkpoint-every", type=int, default=10, help="K iterations")
    p.add_argument("--distributed", action="store_true",
                   help="multi-host: join a jax.distributed cluster; without the next three "
                        "flags the cluster environment (Slurm, Open MPI, TPU) supplies them")
    p.add_argument("--coordinator", help="multi-host: coordinator address HOST:PORT")
    p.add_argument("--num-processes", type=int, help="multi-host: number of processes")
    p.add_argument("--process-id", type=int, help="multi-host: this process's index")
    return p


def main(argv: list[str] | None = None, defaults: dict = PRESETS["train"]) -> int:
    args = parser(defaults).parse_args(argv)
    if args.distributed or args.coordinator or args.num_processes:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    try:
        return _train(args)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


def _train(args) -> int:
    """`train_study` with the flags mapped one to one onto `ars.train.TrainConfig` and
    `jaxgrid.rollouts.training_problem`."""
    from ars.pars import ParsConfig
    from ars.train import TrainConfig

    saved_study = Path(args.out) / "study.toml"
    study = study_from_args(args, str(saved_study) if args.resume and saved_study.is_file()
                            else None)
    pars = ParsConfig(directions=args.directions, top=args.top, step_size=args.step_size,
                      noise=args.noise, decay=args.decay,
                      tasks_per_iteration=tasks_per_iteration(args, study),
                      task_batch=task_batch(args.task_batch, args.preset_task_batch),
                      compact_after=compact_after(args.compact_after, study, args.task_set,
                                                  args.episode),
                      compact_chunks=args.compact_chunks, seed=args.seed)
    config = TrainConfig(policy=args.policy, hidden=widths(args.hidden),
                         obs_clip=args.obs_clip, pars=pars, iterations=args.iterations,
                         seeds=args.seeds, checkpoint_every=args.checkpoint_every, out=args.out,
                         resume=args.resume)
    train_study(study, config, args.history, args.episode, args.task_set, args.task_sampling)
    return 0


def train_study(study, config, history: int | None = None, episode: float | None = None,
                task_set: str = "train", sampling: str | None = None):
    """`ars.train.train` of `config` (an `ars.train.TrainConfig`) on the study's
    `jaxgrid.rollouts.training_problem` (the other arguments are its), then, on process 0,
    learning_curve.png and a summary line; returns `train`'s TrainResult."""
    from ars.train import train
    from jaxgrid.rollouts import training_problem

    result = train(config, training_problem(study, config.policy, history, episode, task_set,
                                            sampling))
    if jax.process_index() == 0:
        out, log = Path(config.out), result.metrics
        _learning_curve(log, out / "learning_curve.png", study.name)
        print(f"{out}: {log[-1]['iteration']} iterations, last mean reward "
              f"{np.mean(log[-1]['reward_mean']):.1f}, policy in {out / 'policy'}")
    return result


def int_or_auto(value: str) -> int | str:
    """A flag's value: 'auto' or a whole number."""
    return value if value == "auto" else int(value)


def task_batch(setting: int | str, preset: int | None) -> int | None:
    """`ParsConfig.task_batch` of a --task-batch setting: a number as given; 'auto' is all m
    tasks in one batch (None) on a GPU, which has batch width to spare, and `preset`
    elsewhere (one task per batch on the large grids, so a task's batch stops once its
    episodes have failed). One H100, the look-alike 300-bus: 0.34 s per iteration all in
    one batch, 0.84 s one task per batch (benchmarks/h100/ab.json)."""
    if setting != "auto":
        return setting
    return None if jax.default_backend() == "gpu" else preset


def compact_after(setting: str, study, task_set: str = "train",
                  episode: float | None = None) -> int | None:
    """`ParsConfig.compact_after` of a --compact-after setting: 'check' is the task set's
    last recovery check step (`jaxgrid.rollouts.recovery_check_step`), 'auto' is 'check' on
    grids of the paper's large preset (`paper_preset`: more than 100 buses) and 'off' on
    smaller ones; None for 'off' or a step not inside the episode (`episode` s, default the
    study's)."""
    from jaxgrid.rollouts import recovery_check_step

    if setting == "auto":
        setting = "check" if paper_preset(study) is PAPER_PRESETS["large"] else "off"
    if setting == "off":
        return None
    if setting == "check":
        step = recovery_check_step(study, task_set)
    elif setting.isdigit() and int(setting) >= 1:
        step = int(setting)
    else:
        raise ValueError(f"--compact-after {setting!r}: allowed 'auto', 'check', 'off' or a "
                         "number of agent steps >= 1")
    n_steps = study.env(**{"episode": episode} if episode else {}).config.n_steps
    return step if step < n_steps else None


def widths(hidden: str) -> tuple[int, ...]:
    """Layer widths of a --hidden value, e.g. "32,32" -> (32, 32); "" -> ()."""
    return tuple(int(h) for h in str(hidden).split(",") if h.strip())


def tasks_per_iteration(args, study) -> int:
    """m: --tasks-per-iteration, by default TASKS_PER_ITERATION or the whole task set if it is
    smaller; ValueError naming the flag when uniform sampling asks for more than the set has."""
    available = len(study.tasks(args.task_set))
    m = args.tasks_per_iteration or min(TASKS_PER_ITERATION, available)
    if args.task_sampling == "uniform" and m > available:
        raise ValueError(f"--tasks-per-iteration {m}: the task set {args.task_set!r} of study "
                         f"{study.name!r} has {available} tasks; pass --tasks-per-iteration "
                         f"{available} or fewer, or another --task-set")
    return m


SMOOTHING = 20  # iterations: the tasks drawn change from one iteration to the next


def smoothed(values: np.ndarray, window: int = SMOOTHING) -> np.ndarray:
    """Trailing moving average along the last axis (..., n) -> (..., n − window + 1)."""
    kernel = np.ones(window) / window
    return np.apply_along_axis(lambda v: np.convolve(v, kernel, "valid"), -1, values)


def _learning_curve(log: list[dict], path: Path, study: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    it = np.array([m["iteration"] for m in log])
    mean = np.array([m["reward_mean"] for m in log], float).reshape(len(log), -1).mean(1)
    best = np.array([m["reward_max"] for m in log], float).reshape(len(log), -1).mean(1)
    seeds = np.size(log[0]["reward_mean"])
    over = f", mean of {seeds} seeds" if seeds > 1 else ""
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(it, mean, label="mean over perturbed rollouts" + over)
    ax.plot(it, best, alpha=0.6, label="best direction" + over)
    if len(log) > SMOOTHING:
        ax.plot(it[SMOOTHING - 1:], smoothed(mean), "k", lw=1.5,
                label=f"mean, {SMOOTHING}-iteration average")
    save_curve(fig, ax, path, "iteration", f"PARS on {study}")


def save_curve(fig, ax, path: Path, xlabel: str, title: str) -> None:
    """Label, title, legend and grid a learning curve (reward per episode) and save it."""
    import matplotlib.pyplot as plt

    ax.set_xlabel(xlabel)
    ax.set_ylabel("reward per episode")
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
