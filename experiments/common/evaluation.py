"""A controller evaluated on a study's tasks, as `experiments.evaluate` writes it:
`evaluate` (every task's reward, MW shed and verdict, a published policy's training log
beside them, figures of the lowest-reward tasks; the controller from
`baselines.controllers.load`) and `default_out` (where a result goes without --out). The
reproduction harness uses them too.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from baselines.controllers import load
from baselines.rlgc import training_log
from jaxgrid.recovery import envelope
from jaxgrid.problem import play_specs
from jaxgrid.study import Study
from jaxgrid.study.sources import fault_set


def task_specs(study: Study, tasks: str):
    """The specs of `tasks`: a task set of the study, or a PNNL task JSON's fault candidates
    at every operating point."""
    if not tasks.endswith(".json"):
        return study.tasks(tasks)
    from jaxgrid.study.pnnl import read_task_config

    return fault_set(read_task_config(tasks), study.buses).specs(study.n_points)


def evaluate(study: Study, control: str, tasks="test", plot_dir=None,
             plot_count: int = 3, own_mask: bool = True,
             arming_level: float | None = None, arming_late: float | None = None) -> dict:
    """The results dict of the module docstring (and figures in plot_dir). `tasks`: a task
    set name, a PNNL task JSON, or a list of TaskSpec. own_mask: a saved policy trained under
    an action mask the study lacks masks its own requests; arming_level (p.u.) and
    arming_late (s): a saved policy's own, in place of its policy.json's
    (`baselines.controllers.load`)."""
    controller = load(control, study, own_mask, arming_level, arming_late)
    env = controller.env
    log = training_log(control.removeprefix("rlgc:")) if control.startswith("rlgc:") else None
    for k, point in enumerate(study.points):
        unchecked = env.unchecked_buses(study.params, study.point(k))
        if unchecked:
            print(f"{study.name} {point.label}: observed buses {list(unchecked)} sit below the "
                  "recovery level before any fault; the recovery check leaves them out")
    chosen = tasks if isinstance(tasks, list) else task_specs(study, tasks)
    specs, out = play_specs(study, env, controller.apply, controller.params, chosen,
                            controller.carry, trace=plot_dir is not None)
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
              **({"own_mask": controller.own_mask} if controller.own_mask else {}),
              **({"arming_level": controller.arming_level}
                 if controller.arming_level is not None else {}),
              **({"arming_late": controller.arming_late}
                 if controller.arming_late is not None else {}),
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
    name = file_stem(study.name, label, control, f"bus{spec.fault_bus}",
                     f"{int(round(spec.fault_duration * 1000))}ms")
    fig.savefig(folder / f"{name}.png", dpi=110)
    plt.close(fig)


def file_stem(*parts: str) -> str:
    """The parts joined by "_", every run of characters other than letters, digits, "." and
    "-" (":", "/", "=", ...) made one "_"."""
    return re.sub(r"[^\w.-]+", "_", "_".join(parts))


def default_out(study: Study, control: str, tasks: str) -> Path:
    """Where an evaluation is written without --out: runs/evaluate/STUDY_CONTROLLER_TASKS.json
    (under runs/, as trainings; results/ holds the committed reports)."""
    task_set = Path(tasks).stem if tasks.endswith(".json") else tasks
    return Path("runs") / "evaluate" / f"{file_stem(study.name, control, task_set)}.json"
