"""Environment benchmark: batched agent steps per second of FIDVR studies.

    python -m experiments.bench.env [--studies ieee39_fidvr ieee300_fidvr FILE.toml]
        [--batch-sizes 1 16 128 512] [--devices 1 2] [--out benchmarks/cpu/env.json]

Each rollout is a whole 10 s episode (100 agent steps of 0.1 s) of `jaxgrid.episode.play_tasks`
with a controller that never sheds, on training-set faults cycled over the batch; the batch
axis is sharded over a 1-D mesh of CPU devices. Agent steps per second = batch × 100 / the
best warm wall time.
"""
from __future__ import annotations

import argparse
import functools

import jax

from baselines.controllers import no_control
from experiments.bench.timing import sharded_timings, write_report
from experiments.common.studyargs import study_from_spec
from jaxgrid.episode import play_tasks


def bench_case(name: str, batch_sizes, device_counts, repeats: int) -> dict:
    """Rollouts of the study's training tasks at its first operating point (name: a built-in
    study or a study file)."""
    study = study_from_spec(name)
    env, grid = study.env(), study.point(0)
    specs = [s for s in study.tasks("train") if s.operating_point == 0]
    apply, params, carry = no_control(env)
    run = jax.jit(functools.partial(play_tasks, env), static_argnums=0)
    result = {"case": name, "dt_s": env.config.dt, "agent_steps": env.config.n_steps,
              "runs": []}
    for n_dev, batch, _, first, warm in sharded_timings(
            batch_sizes, device_counts, repeats,
            lambda batch: study.batch([specs[k % len(specs)] for k in range(batch)]).task,
            lambda tasks: run(apply, params, tasks, study.params, grid, carry)):
        row = {"devices": n_dev, "batch": batch, "first_call_s": round(first, 3),
               "warm_s": round(warm, 4),
               "agent_steps_per_s": round(batch * env.config.n_steps / warm, 1),
               "episodes_per_s": round(batch / warm, 2)}
        print(name, row, flush=True)
        result["runs"].append(row)
    return result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--studies", nargs="*", default=["ieee39_fidvr", "ieee300_fidvr"],
                        help="built-in study names or study files")
    parser.add_argument("--batch-sizes", nargs="*", type=int, default=[1, 16, 128, 512])
    parser.add_argument("--devices", nargs="*", type=int, default=[1, 2])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--out", default="benchmarks/cpu/env.json")
    args = parser.parse_args(argv)
    write_report(args.out, cases=[bench_case(c, args.batch_sizes, args.devices, args.repeats)
                                  for c in args.studies])


if __name__ == "__main__":
    main()
