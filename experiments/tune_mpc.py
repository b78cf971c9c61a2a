"""Choose the MPC's options by measurement: candidate option strings on the tasks of a study's
set that fail without shedding.

    python -m experiments.tune_mpc --study ieee39_fidvr --tasks test --count 8 \
        --candidates "" "width=0" "every=2" "horizon=2" --out runs/tune_mpc.json

Each candidate (`baselines.mpc` options, "" for the defaults) runs on the same `--count`
tasks (evenly spread over those that fail with no control); per candidate it writes the
mean reward, the tasks recovered, the MW shed and the wall time of the evaluation
(compilation included), and prints them as one table.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from baselines.controllers import no_control
from baselines.mpc import mpc_controller, parse_options
from experiments.bench.timing import write_report
from experiments.common.studyargs import add_study_arguments, study_from_args
from jaxgrid.problem import play_specs


def failing_tasks(study, env, tasks: str, count: int):
    """Up to `count` specs of the set `tasks` that fail without shedding, evenly spread,
    the same number at every operating point."""
    apply, policy_params, carry = no_control(env)
    specs, out = play_specs(study, env, apply, policy_params, study.tasks(tasks), carry)
    by_point = {}
    for spec, recovered in zip(specs, out["recovered"]):
        if not recovered:
            by_point.setdefault(spec.operating_point, []).append(spec)
    per_point = max(1, count // max(1, len(by_point)))
    size = min([per_point] + [len(g) for g in by_point.values()])
    return [s for g in by_point.values() for s in g[::max(1, len(g) // size)][:size]]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m experiments.tune_mpc",
                                description=__doc__.split("\n")[0])
    add_study_arguments(p, "ieee39_fidvr")
    p.add_argument("--tasks", default="test")
    p.add_argument("--count", type=int, default=8)
    p.add_argument("--candidates", nargs="+", default=["", "width=0", "every=2", "horizon=2"])
    p.add_argument("--out", default="runs/tune_mpc.json")
    args = p.parse_args(argv)
    study = study_from_args(args)
    env = study.env()
    specs = failing_tasks(study, env, args.tasks, args.count)
    rows = []
    for text in args.candidates:
        start = time.perf_counter()
        planner, mpc, plan = mpc_controller(env, parse_options(text))
        _, out = play_specs(study, env, planner, mpc, specs, plan)
        rows.append({"options": text or "defaults", "mean_reward": float(np.mean(out["reward"])),
                     "recovered": int(np.sum(out["recovered"])), "tasks": len(specs),
                     "shed_mw": float(np.sum(out["shed_pu"])) * study.base_mva,
                     "wall_s": round(time.perf_counter() - start, 1)})
        print(rows[-1], flush=True)
    write_report(args.out, study=study.name, task_set=args.tasks,
                 task_list=[[s.fault_bus, s.fault_duration, s.operating_point] for s in specs],
                 candidates=rows)


if __name__ == "__main__":
    main()
