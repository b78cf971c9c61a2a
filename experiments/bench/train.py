"""Training benchmark: seconds per PARS iteration and rollouts per second, by study and
device count.

    python -m experiments.bench.train [--studies ieee39_fidvr ieee300_fidvr FILE.toml]
        [--devices 1 2] [--directions N ...] [--task-batch M] [--repeats 2]
        [--out benchmarks/cpu/train.json]

Each built-in study runs with the defaults of its training command (LSTM; 39-bus N = 16,
b = 8; 300-bus N = 128, b = 64; m = 9 tasks, 10 s episodes), so an iteration is 2·N·m
rollouts: 288 (39-bus) and 2304 (300-bus); a study file runs with those of
`experiments.train` for its grid's size (`experiments.train.paper_preset`: the PNNL 300-bus
file gets the 300-bus ones). The rollout batch is sharded over a 1-D mesh of
the first `d` CPU devices (or of GPUs, where the backend has them). `--directions` sweeps
the batch: N directions make 2·N·m rollouts per iteration (b = N/2). The first call
(compile + run) and the best of `--repeats` later calls are timed. `--compact-after` sweeps
the episodes' regrouping (`experiments.train --compact-after`; 'auto' as the training
command).
"""
from __future__ import annotations

import argparse
import itertools
import time

import jax
import numpy as np
from jax.sharding import Mesh

from ars.pars import ParsConfig, init_state
from ars.train import TrainConfig, make_trainer
from experiments.bench.timing import timed, write_report
from experiments.train import PRESETS, compact_after, paper_preset
from jaxgrid.rollouts import training_problem
from jaxgrid.study import load_study

DEFAULTS = {p["study"]: p for p in PRESETS.values() if p["study"]}
PLAIN = PRESETS["train"]
TASKS_PER_ITERATION = 9
EPISODE = 10.0  # s


def bench_case(case: str, device_counts, repeats: int, task_batch: int | None = None,
               directions=(None,), compact_settings=("auto",)) -> dict:
    """Time a `case` iteration for every direction count N in `directions` (None: the
    training command's; b = N/2 as in both training commands), every --compact-after setting
    in `compact_settings` and every device count."""
    study = load_study(case)
    defaults = DEFAULTS.get(case) or {**PLAIN, **paper_preset(study)}
    hidden = tuple(int(h) for h in defaults["hidden"].split(","))
    task_batch = task_batch or defaults["task_batch"]
    result = {"case": case, "policy": defaults["policy"], "hidden": list(hidden),
              "tasks_per_iteration": TASKS_PER_ITERATION, "task_batch": task_batch, "runs": []}
    for n_dir, setting in itertools.product(directions, compact_settings):
        n_dir = n_dir or defaults["directions"]
        config = ParsConfig(directions=n_dir, top=max(1, n_dir * defaults["top"]
                                                      // defaults["directions"]),
                            decay=defaults["decay"], tasks_per_iteration=TASKS_PER_ITERATION,
                            task_batch=task_batch,
                            compact_after=compact_after(setting, study, episode=EPISODE))
        rollouts = 2 * config.directions * config.tasks_per_iteration
        for n_dev in device_counts:
            mesh = Mesh(np.array(jax.devices()[:n_dev]), ("batch",))
            start = time.perf_counter()
            problem = training_problem(study, defaults["policy"], 1, EPISODE)
            trainer = make_trainer(problem, TrainConfig(defaults["policy"], hidden, config),
                                   mesh)
            build_s = time.perf_counter() - start
            state = init_state(trainer.policy, config)
            data = jax.device_put((problem.tasks, problem.data))

            def step():
                return trainer.iteration(state, *data)

            (state, _), first = timed(step)
            warm = []
            for _ in range(repeats):
                (state, metrics), wall = timed(step)
                warm.append(wall)
            row = {"directions": config.directions, "top": config.top,
                   "compact_after": config.compact_after,
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
    parser.add_argument("--studies", nargs="*", default=list(DEFAULTS),
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
    parser.add_argument("--out", default="benchmarks/cpu/train.json")
    args = parser.parse_args(argv)
    if max(args.devices) > len(jax.devices()):
        parser.error(f"--devices {max(args.devices)}: only {len(jax.devices())} available")
    write_report(args.out, episode_s=EPISODE,
                 cases=[bench_case(c, args.devices, args.repeats, args.task_batch,
                                   args.directions, args.compact_after)
                        for c in args.studies])


if __name__ == "__main__":
    main()
