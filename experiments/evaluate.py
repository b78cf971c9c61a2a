"""Evaluate a load-shedding controller on a study's task set, at every operating point.

    python -m experiments.evaluate --study ieee39_fidvr|FILE.toml \
        --controller none|uvls|mpc|policy:PATH|ppo:PATH|rlgc:FILE \
        --tasks train|test|NAME|FILE.json [--out FILE.json] [--plot DIR]
    python -m experiments.evaluate --raw R1 R2 --dyr D --task-config J ... (a study from files)

`--tasks` names a task set of the study, or a PNNL task JSON whose fault candidates, crossed
with the study's operating points, make the set. Writes {"study", "controller", "points",
"tasks": [{"fault_bus", "fault_duration", "fault_start", "operating_point" (label), "point"
(index), "reward", "shed_mw", "recovered"}], "summary": {"n_tasks", "n_recovered",
"mean_reward", "total_shed_mw"}} and the resolved study beside it (OUT.study.toml); OUT is
runs/evaluate/STUDY_CONTROLLER_TASKS.json unless --out names it. With --plot, draws for the
lowest-reward tasks (--plot-count) the observed bus voltages against the recovery envelope and the total load shed against time. All operating points run in one
compiled, vmapped call. The controllers are `baselines.controllers`'; a saved policy (PARS:
policy:PATH, PPO: ppo:PATH, a folder written by `experiments.train` or
`experiments.train_ppo`) must observe and act on the study's buses; a published network
(rlgc:FILE, `baselines.rlgc`) picks its own buses from the study's observation. A saved
policy trained under an action mask the study lacks, or trained with --self-mask, masks its
own requests as in training (the result then holds "own_mask"; --no-own-mask: unmasked); one
trained under a mask is armed at the level its policy.json gives or at --arming-level's (the
result then holds "arming_level"), and late as its policy.json or --arming-late says. Where a
published file has a training log beside it, each task of the first operating point that
the log has gains "log_reward" (null for the others), and the result "log" {"path",
"iteration"}: `experiments.compare` sets them side by side. The work is
`experiments.common.evaluation`'s.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from experiments.common.evaluation import default_out, evaluate
from experiments.common.studyargs import add_study_arguments, study_from_args
from jaxgrid.study import write_study


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.evaluate",
                                description=__doc__.split("\n")[0])
    add_study_arguments(p, "ieee39_fidvr")
    p.add_argument("--controller", default="none",
                   help="none | uvls | mpc[:horizon=1,every=2,...] | policy:PATH (PARS) | "
                        "ppo:PATH (PPO) | rlgc:FILE.npz (a network the PARS study published)")
    p.add_argument("--tasks", default="test", help="task set name, or a PNNL task JSON")
    p.add_argument("--out", help="result JSON (default: runs/evaluate/STUDY_CONTROLLER_TASKS"
                                 ".json)")
    p.add_argument("--plot", help="folder for figures of the lowest-reward tasks")
    p.add_argument("--plot-count", type=int, default=3)
    p.add_argument("--no-own-mask", dest="own_mask", action="store_false",
                   help="a saved policy trained under an action mask this study lacks, or "
                        "with --self-mask, asks unmasked (default: it masks its own requests "
                        "as in training)")
    p.add_argument("--arming-level", type=float,
                   help="p.u.: a saved policy trained under an action mask asks to shed "
                        "nothing until an action bus has fallen below this level after "
                        "clearing, in place of its policy.json's (default: that, if any)")
    p.add_argument("--arming-late", type=float,
                   help="s: with an arming level, the policy is armed as well while, this "
                        "long or longer after clearing, a bus of the recovery check is below "
                        "the recovery level, in place of its policy.json's (default: that, "
                        "if any)")
    args = p.parse_args(argv)
    try:
        study = study_from_args(args)
        result = evaluate(study, args.controller, args.tasks, args.plot, args.plot_count,
                          args.own_mask, args.arming_level, args.arming_late)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else default_out(study, args.controller, args.tasks)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    write_study(study, out.with_suffix(".study.toml"))
    s = result["summary"]
    print(f"{out}: {s['n_recovered']}/{s['n_tasks']} recovered, mean reward "
          f"{s['mean_reward']:.1f}, total shed {s['total_shed_mw']:.0f} MW")
    return 0


if __name__ == "__main__":
    sys.exit(main())
