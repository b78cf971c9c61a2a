"""Evaluate a load-shedding controller on a study case's task set.

    python -m experiments.evaluate --case ieee39_fidvr --controller none|uvls|policy:PATH \
        --tasks train|test --out results.json [--plot DIR] [--operating-points 0.9 1.0 1.1]

Writes {"case", "controller", "tasks": [{"fault_bus", "fault_duration", "operating_point",
"reward", "shed_mw", "recovered"}], "summary": {"n_tasks", "n_recovered", "mean_reward",
"total_shed_mw"}}. With --plot, draws for the lowest-reward tasks (--plot-count) the observed
bus voltages against the recovery envelope and the total load shed against time.
Every operating point is its own compiled model; all its tasks run in one vmapped call.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid import cases
from jaxgrid.env import LoadSheddingEnv, study_params
from jaxgrid.recovery import envelope
from jaxgrid.tasks import study_task_set, task_batch


def no_control(env: LoadSheddingEnv):
    """(policy_apply, params, carry) of a controller that never sheds."""
    n = len(env.action_slots)
    return (lambda params, obs, carry: (jnp.zeros(n), carry)), None, None


def saved_policy(control: str):
    """(Policy, (θ, mean, std), info) of a "policy:PATH" controller, read once; else None."""
    if not control.startswith("policy:"):
        return None
    from ars.checkpoint import load_policy
    return load_policy(control.removeprefix("policy:"))


def controller(spec: str, env: LoadSheddingEnv, saved=None):
    """(policy_apply, params, carry) for "none", "uvls" or "policy:PATH" (`saved`: that
    policy as `saved_policy` returns it, read from PATH if not given)."""
    if spec == "none":
        return no_control(env)
    if spec == "uvls":
        from baselines.uvls import uvls_policy
        return uvls_policy(env)
    if spec.startswith("policy:"):
        from ars.pars import initial_carry, normalized_policy
        policy, params, _ = saved or saved_policy(spec)
        if policy.spec.obs_size != env.config.history * env.obs_size:
            raise ValueError(f"{spec}: the policy observes {policy.spec.obs_size} values, this "
                             f"environment gives {env.config.history * env.obs_size}")
        return normalized_policy(policy), params, initial_carry(policy)
    raise ValueError(f"--controller {spec!r}: allowed none, uvls or policy:PATH")


def evaluate(case: str, control: str, tasks: str, operating_points=(1.0,), plot_dir=None,
             plot_count: int = 3) -> dict:
    """The results dict of the module docstring (and figures in plot_dir)."""
    specs = study_task_set(case, tasks, operating_points)
    saved = saved_policy(control)
    history = int(saved[2].get("history", 1)) if saved else 1  # as the policy was trained
    rows, figures = [], []
    for point in operating_points:
        study = cases.load(case, load_level=point)
        env = LoadSheddingEnv.for_study(study, history=history)
        params = study_params(case)
        unchecked = env.unchecked_buses(params)
        if unchecked:
            print(f"{study.name}: observed buses {list(unchecked)} sit below the recovery level "
                  "before any fault; the recovery check leaves them out")
        chosen = [s for s in specs if s.operating_point == point]
        apply, policy_params, carry = controller(control, env, saved)
        run = jax.jit(env.rollout, static_argnums=0, static_argnames="trace")
        out = run(apply, policy_params, task_batch(env.model, chosen), params, carry,
                  trace=plot_dir is not None)
        out = jax.tree.map(np.asarray, out)
        base_mva = study.case.base_mva
        for k, spec in enumerate(chosen):
            rows.append({"fault_bus": spec.fault_bus, "fault_duration": spec.fault_duration,
                         "operating_point": point, "reward": float(out["reward"][k]),
                         "shed_mw": float(out["shed_pu"][k]) * base_mva,
                         "recovered": bool(out["recovered"][k])})
            if plot_dir is not None:
                figures.append((float(out["reward"][k]), spec, study, env, out, k))
    if plot_dir is not None:
        for _, spec, study, env, out, k in sorted(figures, key=lambda f: f[0])[:plot_count]:
            _plot(Path(plot_dir), spec, study, env, out, k, control)
    rewards = [r["reward"] for r in rows]
    return {"case": case, "controller": control, "tasks": rows,
            "summary": {"n_tasks": len(rows), "n_recovered": sum(r["recovered"] for r in rows),
                        "mean_reward": float(np.mean(rewards)),
                        "total_shed_mw": float(sum(r["shed_mw"] for r in rows))}}


def _plot(folder: Path, spec, study, env, out, k, control: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    steps = out["vm"].shape[1]
    t = (np.arange(steps) + 1) * env.config.agent_dt
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for j, bus in enumerate(study.observed_buses):
        top.plot(t, out["vm"][k, :, j], lw=0.8, label=f"bus {bus}" if j < 8 else None)
    cleared = spec.fault_start + spec.fault_duration if spec.fault_duration > 0 else 0.0
    fine = np.linspace(0, t[-1], 1000)
    top.step(fine, envelope(fine - cleared), "k--", where="post", label="envelope")
    top.set_ylabel("voltage (p.u.)")
    top.set_title(f"{study.name}, {control}: fault at bus {spec.fault_bus}, "
                  f"{spec.fault_duration * 1000:.0f} ms; reward {out['reward'][k]:.1f}")
    top.legend(fontsize=7, ncol=3)
    bottom.step(t, np.cumsum(out["shed_step_pu"][k]) * study.case.base_mva, where="post")
    bottom.set_ylabel("load shed (MW)")
    bottom.set_xlabel("time (s)")
    fig.tight_layout()
    name = f"{study.name}_{control.replace(':', '_').replace('/', '_')}_bus{spec.fault_bus}_" \
           f"{int(round(spec.fault_duration * 1000))}ms.png"
    fig.savefig(folder / name, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.evaluate",
                                description=__doc__.split("\n")[0])
    p.add_argument("--case", default="ieee39_fidvr", choices=["ieee39_fidvr", "ieee300_fidvr"])
    p.add_argument("--controller", default="none", help="none | uvls | policy:PATH")
    p.add_argument("--tasks", default="test", choices=["train", "test"])
    p.add_argument("--operating-points", nargs="*", type=float, default=[1.0])
    p.add_argument("--out", default="results/evaluate.json")
    p.add_argument("--plot", help="folder for figures of the lowest-reward tasks")
    p.add_argument("--plot-count", type=int, default=3)
    args = p.parse_args(argv)
    try:
        result = evaluate(args.case, args.controller, args.tasks, tuple(args.operating_points),
                          args.plot, args.plot_count)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    s = result["summary"]
    print(f"{args.out}: {s['n_recovered']}/{s['n_tasks']} recovered, mean reward "
          f"{s['mean_reward']:.1f}, total shed {s['total_shed_mw']:.0f} MW")
    return 0


if __name__ == "__main__":
    sys.exit(main())
