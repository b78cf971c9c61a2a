"""Training benchmark: seconds per PARS iteration and rollouts per second, by study and
device count.

    python -m experiments.bench.train [--studies ieee39_fidvr ieee300_fidvr FILE.toml]
        [--devices 1 2] [--directions N ...] [--task-batch M] [--repeats 2] [--plain-vmap]
        [--out benchmarks/cpu/train.json]

Each built-in study runs with the defaults of its training command (LSTM; 39-bus N = 16,
b = 8; 300-bus N = 128, b = 64; m = 9 tasks, 10 s episodes), so an iteration is 2·N·m
rollouts: 288 (39-bus) and 2304 (300-bus); a study file runs with those of
`experiments.train` for its grid's size (`experiments.common.training.train_config`: the
PNNL 300-bus file gets the 300-bus ones). The rollout batch is sharded over a 1-D mesh of
the first `d` CPU devices (or of GPUs, where the backend has them). `--directions` sweeps
the batch: N directions make 2·N·m rollouts per iteration (b = N/2). The first call
(compile + run) and the best of `--repeats` later calls are timed. `--compact-after` sweeps
the episodes' regrouping (`experiments.train --compact-after`; 'auto' as the training
command). `--plain-vmap` batches with `jax.vmap` (`jaxgrid.batching.refuse`), as a JAX
release outside `jaxgrid.batching.KNOWN_JAX` does: what the batch-last path is worth.
"""
from __future__ import annotations

import argparse
import itertools
import time

import jax
import numpy as np
from jax.sharding import Mesh

from ars.pars import init_state
from ars.train import make_trainer
from experiments.bench.timing import timed, write_report
from experiments.common.studyargs import study_from_spec
from experiments.common.training import COMMANDS, Choices, problem, train_config
from jaxgrid import batching

BUILT_IN = [c["study"] for c in COMMANDS.values() if c["study"]]
TASKS_PER_ITERATION = 9
EPISODE = 10.0  # s


def bench_case(case: str, device_counts, repeats: int, task_batch: int | None = None,
               directions=(None,), compact_settings=("auto",)) -> dict:
    """Time a `case` iteration for every direction count N in `directions` (None: the
    training command's; b = N/2), every --compact-after setting in `compact_settings` and
    every device count."""
    study = study_from_spec(case)
    result = {"case": case, "tasks_per_iteration": TASKS_PER_ITERATION, "runs": []}
    for n_dir, setting in itertools.product(directions, compact_settings):
        choices = Choices(directions=n_dir, tasks_per_iteration=TASKS_PER_ITERATION,
                          task_batch=task_batch or "auto", compact_after=setting, history=1,
                          episode=EPISODE)
        config = train_config(study, choices)
        result.update(policy=config.policy, hidden=list(config.hidden),
                      task_batch=config.pars.task_batch)
        rollouts = 2 * config.pars.directions * config.pars.tasks_per_iteration
        for n_dev in device_counts:
            mesh = Mesh(np.array(jax.devices()[:n_dev]), ("batch",))
            start = time.perf_counter()
            grid = problem(study, choices)
            trainer = make_trainer(grid, config, mesh)
            build_s = time.perf_counter() - start
            state = init_state(trainer.policy, config.pars)
            data = jax.device_put((grid.tasks, grid.data))

            def step():
                return trainer.iteration(state, *data)

            (state, _), first = timed(step)
            warm = []
            for _ in range(repeats):
                (state, metrics), wall = timed(step)
                warm.append(wall)
            row = {"directions": config.pars.directions, "top": config.pars.top,
                   "compact_after": config.pars.compact_after,
                   "rollouts_per_iteration": rollouts, "devices": n_dev,
                   "build_s": round(build_s, 2), "first_call_s": round(first, 2),
                   "s_per_iteration": round(min(warm), 3),
                   "warm_s": [round(w, 3) for w in warm],
                   "rollouts_per_s": round(rollouts / min(warm), 1),
                   "reward_mean_last": round(float(metrics["reward_mean"]), 1)}
            print(case, row, flush=True)
            result["runs"].append(row)
    return result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--studies", nargs="*", default=BUILT_IN,
                        help="built-in study names or study files")
    parser.add_argument("--devices", nargs="*", type=int, default=[1, 2])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--task-batch", type=int,
                        help="tasks per rollout batch (default: the training command's)")
    parser.add_argument("--directions", nargs="*", type=int, default=[None],
                        help="direction counts N to sweep, top b = N/2 (default: the "
                             "training command's)")
    parser.add_argument("--compact-after", nargs="*", default=["auto"],
                        help="--compact-after settings of experiments.train to sweep")
    parser.add_argument("--plain-vmap", action="store_true",
                        help="batch with jax.vmap, as a JAX outside the tested range does")
    parser.add_argument("--out", default="benchmarks/cpu/train.json")
    args = parser.parse_args(argv)
    if max(args.devices) > len(jax.devices()):
        parser.error(f"--devices {max(args.devices)}: only {len(jax.devices())} available")
    if args.plain_vmap:
        batching.refuse("--plain-vmap")
    write_report(args.out, episode_s=EPISODE, vmap="plain" if args.plain_vmap else "minor",
                 cases=[bench_case(c, args.devices, args.repeats, args.task_batch,
                                   args.directions, args.compact_after)
                        for c in args.studies])


if __name__ == "__main__":
    main()
