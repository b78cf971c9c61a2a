"""Where one integration step's time goes: XLA kernel count and time per component.

    python -m experiments.bench.profile_step [--studies ieee39_fidvr ieee300_fidvr] [--batch 64]
        [--calls 20] [--out benchmarks/cpu/profile_step.json]

For a batch of the study's training tasks at its first operating point, during the fault,
on one CPU device:
- kernels: the top-level instructions of the compiled, batched Heun step, with the batch as
  every array's last axis as the simulator holds it (`jaxgrid.batching.batch_last`), i.e.
  what the CPU runs one after another, by kind, how many of its fusions hold complex numbers,
  transposes, gathers or scatters, and its sine, cosine, power and atan2 instructions
  (`scalar_math`: XLA:CPU evaluates them element by element, at 1.5–14 ns each, and copies
  one into every fusion that reads it; `jaxgrid.vecmath` replaces them in the step);
- time (µs per rollout-step, best of `--calls` calls of 50 steps each) of the whole step,
  of the network solution alone (one `solve_network`; a step makes two), and within it of
  one evaluation of the load slots' injections (`load_injection`, once per sweep) and of one
  slot-impedance product (`network.times`, once per sweep), of one Euler
  stage (network + device models + state update), of the load models' discrete update
  (`update_loads`, once a step), of one limit clip (`clip_to_limits`, two a step) and of the
  divergence check (`within_bounds`, once an agent step: not part of the step's share), so
  the device models' share is stage − network (`experiments.bench.profiling`).
"""
from __future__ import annotations

import argparse

import jax.numpy as jnp

from experiments.bench.profiling import profile_model
from experiments.bench.timing import write_report
from experiments.common.studyargs import study_from_spec


def profile(name: str, batch: int, calls: int) -> dict:
    """`profile_model` of a study's first operating point on its training tasks."""
    study = study_from_spec(name)
    specs = [s for s in study.tasks("train") if s.operating_point == 0]
    tasks = study.batch([specs[k % len(specs)] for k in range(batch)]).task
    result = {"study": name, **profile_model(study.point(0), study.config.solver.fine(), tasks,
                                                   calls)}
    print(name, result, flush=True)
    return result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--studies", nargs="*", default=["ieee39_fidvr", "ieee300_fidvr"])
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--calls", type=int, default=10)
    parser.add_argument("--out", default="benchmarks/cpu/profile_step.json")
    args = parser.parse_args(argv)
    jnp.zeros(())  # backend up before timing
    write_report(args.out, profiles=[profile(s, args.batch, args.calls) for s in args.studies])


if __name__ == "__main__":
    main()
