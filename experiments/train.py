"""PARS training of a load-shedding policy on a study (built-in, study file, or RAW + DYR +
task files).

    python -m experiments.train --study ieee39_fidvr|studies/x.toml --out DIR
    python -m experiments.train --raw R1 R2 ... --dyr D --task-config J [--sim-config S] --out DIR

`experiments.train_39bus` and `experiments.train_300bus` are presets (the built-in studies
with the paper's hyper-parameters); every hyper-parameter has a flag. Each iteration draws
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
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from experiments.studyargs import add_study_arguments, study_from_args

# Hyper-parameter defaults of the plain command (the presets give the paper's per case).
DEFAULTS = {"study": None, "policy": "lstm", "hidden": "32,32", "directions": 16, "top": 8,
            "decay": 0.99, "iterations": 200, "task_batch": None}
TASKS_PER_ITERATION = 9  # m when --tasks-per-iteration is not given and the set has as many


# The paper's Table I per system: the 39-bus column for studies up to 100 buses, else the
# 300-bus one (N: the directions its main policy trained with; b = N/2).
PAPER_PRESETS = {"small": {"hidden": "32,32", "decay": 0.99, "directions": 16},
                 "large": {"hidden": "64,64", "decay": 0.996, "directions": 128}}


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
    p.add_argument("--task-batch", type=int, default=defaults["task_batch"],
                   help="tasks whose rollouts run as one batch (default all m); batches run "
                        "one after another and stop once all their episodes are done")
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


def main(argv: list[str] | None = None, defaults: dict = DEFAULTS) -> int:
    args = parser(defaults).parse_args(argv)
    if args.distributed or args.coordinator or args.num_processes:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    try:
        return _train(args)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


class Trainer(NamedTuple):
    """What `build` makes: iteration(state, tasks, data), the policy and its spec, the
    arguments the iteration takes (tasks: PointTask batch, data: the stacked grid models),
    and the environment's configuration (history and episode as trained)."""

    iteration: object
    policy: object
    spec: object
    tasks: object
    data: object
    env_config: object


def device_label(count: int) -> str:
    """'COUNT × KIND' for `count` devices of this backend, e.g. '2 × cpu' (metrics lines)."""
    return f"{count} × {jax.devices()[0].device_kind}"


def build(study, policy_kind: str, hidden: tuple[int, ...], config, history: int | None = None,
          episode: float | None = None, task_set: str = "train", sampling: str | None = None,
          mesh=None, seeds: int | None = None) -> Trainer:
    """PARS on `study`'s task set `task_set`, episodes of `episode` s (default the study's),
    `history` observations stacked and `sampling` (default the study's for `policy_kind`),
    rollouts sharded over `mesh` (default: all devices); `seeds` independent trainings in
    one program (`make_iteration`). The data holds only the set's operating points."""
    from ars.pars import make_iteration
    from ars.policies import Policy, PolicySpec
    from jaxgrid.study import point_episode, stratified_sampler

    history = study.history(policy_kind) if history is None else history
    sampling = sampling or study.definition.training.task_sampling
    overrides = {k: v for k, v in (("history", history), ("episode", episode)) if v is not None}
    env = study.env(**overrides)
    params = study.params
    spec = PolicySpec(policy_kind, env.config.history * env.obs_size, len(env.action_slots),
                      hidden, float(params.action_low), float(params.action_high))
    policy = Policy(spec)
    sample = (stratified_sampler(study.task_set(task_set), study.n_points,
                                 config.tasks_per_iteration)
              if sampling == "stratified" else None)
    iteration = make_iteration(point_episode(env, params), policy, config, sample, mesh, seeds)
    points = study.task_set(task_set).points(study.n_points)
    specs = [dataclasses.replace(s, operating_point=points.index(s.operating_point))
             for s in study.tasks(task_set)]  # indices into the set's points, in order
    data = jax.tree.map(lambda a: a[np.array(points)], study.models)
    return Trainer(iteration, policy, spec, study.batch(specs), data, env.config)


def layout(env_config) -> dict:
    """What a saved policy observes and acts on (checked when it is evaluated)."""
    return {"observed_buses": list(env_config.observed_buses),
            "action_buses": list(env_config.action_buses), "history": env_config.history,
            "include_action_status": env_config.include_action_status}


def _train(args) -> int:
    from tqdm import tqdm

    from ars import checkpoint
    from ars.pars import ParsConfig, init_state
    from jaxgrid.study import write_study

    hidden = tuple(int(h) for h in str(args.hidden).split(",") if h.strip())
    if args.iterations < 1 or args.checkpoint_every < 1 or (args.seeds or 1) < 1:
        raise ValueError("--iterations, --checkpoint-every and --seeds must be >= 1")
    out = Path(args.out)
    saved_study = out / "study.toml"
    study = study_from_args(args, str(saved_study) if args.resume and saved_study.is_file()
                            else None)
    config = ParsConfig(directions=args.directions, top=args.top, step_size=args.step_size,
                        noise=args.noise, decay=args.decay,
                        tasks_per_iteration=tasks_per_iteration(args, study),
                        task_batch=args.task_batch, seed=args.seed)
    out.mkdir(parents=True, exist_ok=True)
    mgr = checkpoint.manager(out / "checkpoints", args.checkpoint_every)
    if not args.resume and mgr.latest_step() is not None:
        raise ValueError(f"{out} already holds a run (checkpoint at iteration "
                         f"{mgr.latest_step()}): pass --resume to continue it, or another --out")
    if args.resume and (mgr.latest_step() or 0) > args.iterations:
        raise ValueError(f"--resume: the checkpoint in {out} is at iteration "
                         f"{mgr.latest_step()}, past --iterations {args.iterations}")
    trainer = build(study, args.policy, hidden, config, args.history, args.episode,
                    args.task_set, args.task_sampling, seeds=args.seeds)
    env_config = trainer.env_config
    run_info = {"study": study.name, "points": [p.label for p in study.points],
                "task_set": args.task_set,
                "task_sampling": args.task_sampling or study.definition.training.task_sampling,
                "layout": layout(env_config), "history": env_config.history,
                "episode": env_config.episode, "config": dataclasses.asdict(config),
                "seeds": args.seeds}
    state, log = init_state(trainer.policy, config, args.seeds), []
    if args.resume:
        restored = checkpoint.restore_latest(mgr, state)
        if restored is None:
            raise ValueError(f"--resume: no checkpoint in {out / 'checkpoints'}")
        state, meta = restored
        log = meta["metrics"]
        if meta.get("seeds") != args.seeds:
            raise ValueError(f"--resume: the run in {out} has --seeds {meta.get('seeds')}, "
                             f"not {args.seeds}")
    # every process computes the same replicated state; the first one writes the files
    # (orbax coordinates the checkpoints itself)
    primary = jax.process_index() == 0
    metrics_path = out / "metrics.jsonl"
    if primary:
        write_study(study, saved_study)
        metrics_path.write_text("".join(json.dumps(m) + "\n" for m in log))
    done = int(np.max(state.iteration))
    rollouts = log[-1]["rollouts"] if log else 0
    env_steps = np.array(log[-1]["env_steps"] if log else 0, np.int64)  # per seed, wide
    device = device_label(jax.device_count())
    bar = tqdm(total=args.iterations, initial=done, unit="it", disable=not primary)
    try:  # closing the bar ends its line, so an error starts on a new one
        while done < args.iterations:
            start = time.perf_counter()
            state, metrics = trainer.iteration(state, trainer.tasks, trainer.data)
            metrics = jax.device_get(metrics)
            wall = time.perf_counter() - start
            done, rollouts = done + 1, rollouts + int(np.ravel(metrics["rollouts"])[0])
            env_steps = env_steps + np.asarray(metrics["env_steps"], np.int64)
            row = {"iteration": done, "reward_mean": np.asarray(metrics["reward_mean"]).tolist(),
                   "reward_max": np.asarray(metrics["reward_max"]).tolist(),
                   "wall_s": round(wall, 3), "rollouts": rollouts,
                   "env_steps": env_steps.tolist(), "device": device}
            log.append(row)
            if primary:
                with open(metrics_path, "a") as metrics_file:
                    metrics_file.write(json.dumps(row) + "\n")
            bar.set_postfix(mean=f"{np.mean(row['reward_mean']):.1f}",
                            best=f"{np.max(row['reward_max']):.1f}", s_per_it=f"{wall:.2f}")
            bar.update(1)
            last = done == args.iterations
            checkpoint.save(mgr, state, {"metrics": log, **run_info}, force=last, step=done)
            if primary and (done % args.checkpoint_every == 0 or last):
                _save_policies(out / "policies" / f"{done:05d}", trainer.spec, state, run_info,
                               args.seeds)
    finally:
        bar.close()
    if primary:
        _save_policies(out / "policy", trainer.spec, state, run_info, args.seeds)
        _learning_curve(log, out / "learning_curve.png", study.name)
        print(f"{out}: {done} iterations, last mean reward "
              f"{np.mean(log[-1]['reward_mean']):.1f}, policy in {out / 'policy'}")
    return 0


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


def _save_policies(folder: Path, spec, state, run_info: dict, seeds: int | None) -> None:
    """The policy in `folder`, or with seeds each seed's in folder/seedI."""
    from ars import checkpoint

    if seeds is None:
        checkpoint.save_policy(folder, spec, state, run_info)
        return
    for i in range(seeds):
        checkpoint.save_policy(folder / f"seed{i}", spec, jax.tree.map(lambda a: a[i], state),
                               {**run_info, "seed": run_info["config"]["seed"] + i})


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
