"""PARS training of a load-shedding policy on a built-in FIDVR study case.

`experiments.train_39bus` and `experiments.train_300bus` call `main` with the study's
defaults; every hyper-parameter has a flag. Output folder DIR:
  metrics.jsonl   one line per iteration: iteration, reward_mean, reward_max, wall_s, rollouts
  checkpoints/    orbax checkpoints every --checkpoint-every iterations and at the end
  policy/         the trained policy (experiments.evaluate --controller policy:DIR/policy)
  policies/NNNNN/ the policy after iteration NNNNN, at every checkpoint (all kept: the last
                  is not always the one that generalises best to the test tasks)
  learning_curve.png
`--resume` continues from the last checkpoint; `--iterations` is the run's total.
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

import jax
import numpy as np


def parser(case: str, defaults: dict) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"python -m experiments.train_{case.split('_')[0][4:]}bus",
                                description=f"PARS training on {case}")
    p.add_argument("--policy", default=defaults["policy"], choices=["linear", "fnn", "lstm"])
    p.add_argument("--hidden", default=defaults["hidden"], help="layer widths, e.g. 32,32")
    p.add_argument("--history", type=int, help="observations stacked (default: 1 for lstm, "
                                               "10 for linear and fnn, as the study)")
    p.add_argument("--directions", type=int, default=defaults["directions"], help="N")
    p.add_argument("--top", type=int, default=defaults["top"], help="b")
    p.add_argument("--step-size", type=float, default=1.0, help="α")
    p.add_argument("--noise", type=float, default=2.0, help="ν")
    p.add_argument("--decay", type=float, default=defaults["decay"], help="ε")
    p.add_argument("--tasks-per-iteration", type=int, default=9, help="m")
    p.add_argument("--iterations", type=int, default=defaults["iterations"],
                   help="total iterations of the run (with --resume: continue up to it)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episode", type=float, default=10.0, help="episode length, s")
    p.add_argument("--load-level", type=float, default=1.0, help="operating point")
    p.add_argument("--out", default=f"runs/{case}", help="output folder")
    p.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    p.add_argument("--checkpoint-every", type=int, default=10, help="K iterations")
    p.add_argument("--distributed", action="store_true",
                   help="multi-host: join a jax.distributed cluster; without the next three "
                        "flags the cluster environment (Slurm, Open MPI, TPU) supplies them")
    p.add_argument("--coordinator", help="multi-host: coordinator address HOST:PORT")
    p.add_argument("--num-processes", type=int, help="multi-host: number of processes")
    p.add_argument("--process-id", type=int, help="multi-host: this process's index")
    return p


def main(case: str, defaults: dict, argv: list[str] | None = None) -> int:
    args = parser(case, defaults).parse_args(argv)
    if args.distributed or args.coordinator or args.num_processes:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    try:
        return _train(case, args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


def build(case: str, policy_kind: str, hidden: tuple[int, ...], history: int,
          config, episode: float = 10.0, load_level: float = 1.0, mesh=None):
    """(iteration, Policy, PolicySpec) for PARS on a built-in study case.

    `iteration(state) -> (state, metrics)` is `ars.pars.make_iteration` over the case's
    training tasks, episodes of `episode` s, rollouts sharded over `mesh` (default: all
    devices).
    """
    from ars.pars import make_iteration
    from ars.policies import Policy, PolicySpec
    from jaxgrid import cases
    from jaxgrid.env import LoadSheddingEnv, study_params
    from jaxgrid.tasks import study_task_set, task_batch

    env = LoadSheddingEnv.for_study(cases.load(case, load_level=load_level), history=history,
                                    episode=episode)
    params = study_params(case)
    spec = PolicySpec(policy_kind, history * env.obs_size, len(env.action_slots), hidden,
                      float(params.action_low), float(params.action_high))
    policy = Policy(spec)
    tasks = task_batch(env.model, study_task_set(case, "train"))
    iteration = make_iteration(
        lambda apply, pp, task, carry: env.episode(apply, pp, task, params, carry),
        policy, config, tasks, mesh)
    return iteration, policy, spec


def _train(case: str, args) -> int:
    from tqdm import tqdm

    from ars import checkpoint
    from ars.pars import ParsConfig, init_state

    hidden = tuple(int(h) for h in str(args.hidden).split(",") if h.strip())
    history = args.history or (1 if args.policy == "lstm" else 10)
    config = ParsConfig(directions=args.directions, top=args.top, step_size=args.step_size,
                        noise=args.noise, decay=args.decay,
                        tasks_per_iteration=args.tasks_per_iteration, seed=args.seed)
    if args.iterations < 1 or args.checkpoint_every < 1:
        raise ValueError("--iterations and --checkpoint-every must be >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mgr = checkpoint.manager(out / "checkpoints", args.checkpoint_every)
    if not args.resume and mgr.latest_step() is not None:
        raise ValueError(f"{out} already holds a run (checkpoint at iteration "
                         f"{mgr.latest_step()}): pass --resume to continue it, or another --out")
    if args.resume and (mgr.latest_step() or 0) > args.iterations:
        raise ValueError(f"--resume: the checkpoint in {out} is at iteration "
                         f"{mgr.latest_step()}, past --iterations {args.iterations}")
    iteration, policy, spec = build(case, args.policy, hidden, history, config, args.episode,
                                    args.load_level)
    run_info = {"case": case, "load_level": args.load_level, "history": history,
                "episode": args.episode, "config": dataclasses.asdict(config)}
    state, log = init_state(policy, config), []
    if args.resume:
        restored = checkpoint.restore_latest(mgr, state)
        if restored is None:
            raise ValueError(f"--resume: no checkpoint in {out / 'checkpoints'}")
        state, meta = restored
        log = meta["metrics"]
    # every process computes the same replicated state; the first one writes the files
    # (orbax coordinates the checkpoints itself)
    primary = jax.process_index() == 0
    metrics_path = out / "metrics.jsonl"
    if primary:
        metrics_path.write_text("".join(json.dumps(m) + "\n" for m in log))
    done = int(state.iteration)
    rollouts = log[-1]["rollouts"] if log else 0
    bar = tqdm(total=args.iterations, initial=done, unit="it", disable=not primary)
    while done < args.iterations:
        start = time.perf_counter()
        state, metrics = iteration(state)
        metrics = jax.device_get(metrics)
        wall = time.perf_counter() - start
        done, rollouts = done + 1, rollouts + int(metrics["rollouts"])
        row = {"iteration": done, "reward_mean": float(metrics["reward_mean"]),
               "reward_max": float(metrics["reward_max"]), "wall_s": round(wall, 3),
               "rollouts": rollouts}
        log.append(row)
        if primary:
            with open(metrics_path, "a") as metrics_file:
                metrics_file.write(json.dumps(row) + "\n")
        bar.set_postfix(mean=f"{row['reward_mean']:.1f}", best=f"{row['reward_max']:.1f}",
                        s_per_it=f"{wall:.2f}")
        bar.update(1)
        last = done == args.iterations
        checkpoint.save(mgr, state, {"metrics": log, **run_info}, force=last)
        if primary and (done % args.checkpoint_every == 0 or last):
            checkpoint.save_policy(out / "policies" / f"{done:05d}", spec, state, run_info)
    bar.close()
    if primary:
        checkpoint.save_policy(out / "policy", spec, state, run_info)
        _learning_curve(log, out / "learning_curve.png", case)
        print(f"{out}: {done} iterations, last mean reward {log[-1]['reward_mean']:.1f}, "
              f"policy in {out / 'policy'}")
    return 0


def _learning_curve(log: list[dict], path: Path, case: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    it = np.array([m["iteration"] for m in log])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(it, [m["reward_mean"] for m in log], label="mean over perturbed rollouts")
    ax.plot(it, [m["reward_max"] for m in log], alpha=0.6, label="best direction")
    ax.set_xlabel("iteration")
    ax.set_ylabel("reward per episode")
    ax.set_title(f"PARS on {case}")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
