"""Evaluate a load-shedding controller on a study's task set, at every operating point.

    python -m experiments.evaluate --study ieee39_fidvr|FILE.toml \
        --controller none|uvls|mpc|policy:PATH|ppo:PATH|rlgc:FILE \
        --tasks train|test|NAME|FILE.json --out results.json [--plot DIR]
    python -m experiments.evaluate --raw R1 R2 --dyr D --task-config J ... (a study from files)

`--tasks` names a task set of the study, or a PNNL task JSON whose fault candidates, crossed
with the study's operating points, make the set. Writes {"study", "controller", "points",
"tasks": [{"fault_bus", "fault_duration", "fault_start", "operating_point" (label), "point"
(index), "reward", "shed_mw", "recovered"}], "summary": {"n_tasks", "n_recovered",
"mean_reward", "total_shed_mw"}} and the resolved study beside it (OUT.study.toml). With
--plot, draws for the lowest-reward tasks (--plot-count) the observed bus voltages against
the recovery envelope and the total load shed against time. All operating points run in one
compiled, vmapped call. The controllers are `baselines.controllers`'; a saved policy (PARS:
policy:PATH, PPO: ppo:PATH, a folder written by `experiments.train` or
`experiments.train_ppo`) must observe and act on the study's buses; a published network
(rlgc:FILE, `baselines.rlgc`) picks its own buses from the study's observation. Where a
published file has a training log beside it, each task of the first operating point that
the log has gains "log_reward" (null for the others), and the result "log" {"path",
"iteration"}: `experiments.compare` sets them side by side.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from baselines.controllers import check_layout, controller, saved_policy
from baselines.rlgc import training_log
from experiments.studyargs import add_study_arguments, study_from_args
from jaxgrid.recovery import envelope
from jaxgrid.rollouts import rollout_specs
from jaxgrid.study import Study, bus_number, write_study
from jaxgrid.tasks import TaskSet


def task_specs(study: Study, tasks: str):
    """The specs of `tasks`: a task set of the study, or a PNNL task JSON's fault candidates
    at every operating point."""
    if not tasks.endswith(".json"):
        return study.tasks(tasks)
    from jaxgrid.io.pnnl import read_task_config

    config = read_task_config(tasks)
    buses = tuple(bus_number(n, study.buses, config.source, "faultBusCandidates")
                  for n in config.fault_buses)
    return TaskSet(buses, config.fault_durations, config.fault_starts).specs(study.n_points)


def controlled_env(study: Study, control: str):
    """(env, policy_apply, params, carry) of controller `control` on the study: the env
    stacks as many observations as a saved policy was trained with, whose layout is
    checked."""
    saved = saved_policy(control)
    history = int(saved[2].get("history", 1)) if saved else None  # as the policy was trained
    env = study.env(**({"history": history} if history else {}))
    if saved:
        check_layout(control, saved[2], study, env)
    return (env, *controller(control, env, saved))


def evaluate(study: Study, control: str, tasks="test", plot_dir=None,
             plot_count: int = 3) -> dict:
    """The results dict of the module docstring (and figures in plot_dir). `tasks`: a task
    set name, a PNNL task JSON, or a list of TaskSpec."""
    env, apply, policy_params, carry = controlled_env(study, control)
    log = training_log(control.removeprefix("rlgc:")) if control.startswith("rlgc:") else None
    for k, point in enumerate(study.points):
        unchecked = env.unchecked_buses(study.params, study.point(k))
        if unchecked:
            print(f"{study.name} {point.label}: observed buses {list(unchecked)} sit below the "
                  "recovery level before any fault; the recovery check leaves them out")
    chosen = tasks if isinstance(tasks, list) else task_specs(study, tasks)
    specs, out = rollout_specs(study, env, apply, policy_params, chosen, carry,
                               trace=plot_dir is not None)
    rows = [{"fault_bus": s.fault_bus, "fault_duration": s.fault_duration,
             "fault_start": s.fault_start, "operating_point": study.points[s.operating_point]
             .label, "point": s.operating_point, "reward": float(out["reward"][k]),
             "shed_mw": float(out["shed_pu"][k]) * study.base_mva,
             "recovered": bool(out["recovered"][k])} for k, s in enumerate(specs)]
    if plot_dir is not None:
        for k in np.argsort(out["reward"], kind="stable")[:plot_count]:
            _plot(Path(plot_dir), specs[k], study, env, out, int(k), control)
    rewards = [r["reward"] for r in rows]
    result = {"study": study.name, "controller": control,
              "points": [p.label for p in study.points], "tasks": rows,
              "summary": {"n_tasks": len(rows),
                          "n_recovered": sum(r["recovered"] for r in rows),
                          "mean_reward": float(np.mean(rewards)),
                          "total_shed_mw": float(sum(r["shed_mw"] for r in rows))}}
    if log is not None:
        for row in rows:
            row["log_reward"] = log.reward(row["fault_bus"], row["fault_duration"],
                                           row["fault_start"]) if row["point"] == 0 else None
        result["log"] = {"path": log.path, "iteration": log.iteration}
    return result


def _plot(folder: Path, spec, study: Study, env, out, k, control: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    steps = out["vm"].shape[1]
    t = (np.arange(steps) + 1) * env.config.agent_dt
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for j, bus in enumerate(env.config.observed_buses):
        top.plot(t, out["vm"][k, :, j], lw=0.8, label=f"bus {bus}" if j < 8 else None)
    cleared = spec.fault_start + spec.fault_duration if spec.fault_duration > 0 else 0.0
    fine = np.linspace(0, t[-1], 1000)
    top.step(fine, envelope(fine - cleared), "k--", where="post", label="envelope")
    top.set_ylabel("voltage (p.u.)")
    label = study.points[spec.operating_point].label
    top.set_title(f"{study.name} {label}, {control}: fault at bus {spec.fault_bus}, "
                  f"{spec.fault_duration * 1000:.0f} ms; reward {out['reward'][k]:.1f}")
    top.legend(fontsize=7, ncol=3)
    bottom.step(t, np.cumsum(out["shed_step_pu"][k]) * study.base_mva, where="post")
    bottom.set_ylabel("load shed (MW)")
    bottom.set_xlabel("time (s)")
    fig.tight_layout()
    controller_name = control.replace(":", "_").replace("/", "_")
    name = (f"{study.name}_{label}_{controller_name}_bus{spec.fault_bus}_"
            f"{int(round(spec.fault_duration * 1000))}ms.png")
    fig.savefig(folder / name, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.evaluate",
                                description=__doc__.split("\n")[0])
    add_study_arguments(p, "ieee39_fidvr")
    p.add_argument("--controller", default="none",
                   help="none | uvls | mpc[:horizon=1,every=2,...] | policy:PATH (PARS) | "
                        "ppo:PATH (PPO) | rlgc:FILE.npz (a network the PARS study published)")
    p.add_argument("--tasks", default="test", help="task set name, or a PNNL task JSON")
    p.add_argument("--out", default="results/evaluate.json")
    p.add_argument("--plot", help="folder for figures of the lowest-reward tasks")
    p.add_argument("--plot-count", type=int, default=3)
    args = p.parse_args(argv)
    try:
        study = study_from_args(args)
        result = evaluate(study, args.controller, args.tasks, args.plot, args.plot_count)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    write_study(study, out.with_suffix(".study.toml"))
    s = result["summary"]
    print(f"{args.out}: {s['n_recovered']}/{s['n_tasks']} recovered, mean reward "
          f"{s['mean_reward']:.1f}, total shed {s['total_shed_mw']:.0f} MW")
    return 0


if __name__ == "__main__":
    sys.exit(main())
