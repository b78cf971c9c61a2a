"""How accurate is a study's time step? Candidate (step, sweeps) pairs against a float64,
small-step, many-sweep reference over the study's training tasks, without control.

    python -m experiments.diagnostics.step_accuracy --study ieee39_fidvr [--dts 0.002 0.005 0.01]
        [--sweeps 2] [--coarse-dts 0 0.01] [--fine-window 1.0] [--coarse-sweeps K]
        [--motor-step rosenbrock] [--reference-dt 0.001] [--reference-sweeps 4]
        [--reference-precision float64] [--tasks train] [--episode S]
        [--out benchmarks/cpu/step_accuracy.json]

A candidate is a (step, sweeps, coarse step) triple: the coarse step
(`jaxgrid.steppers.Solver.coarse_dt`, 0 for none) is used outside the fault window,
`--fine-window` s after clearing, with `--coarse-sweeps` network sweeps (default: the
candidate's); `--motor-step` sets how the candidates integrate the load models' motors
(`Solver.motor_step`; the reference always steps them exponentially).

For each candidate it reports, over every task and agent step (0.1 s samples of the observed
bus voltages, float32 time loop as in training): the 99th-percentile and largest |ΔV|
(p.u.) against the reference, the largest |ΔV| at the recovery check (the first sample
after clearing + recovery_time), how many recovery verdicts differ from the reference's,
and the wall time of the warm run with its ratio to the study's own step. The step the
study should use is the fastest candidate with p99 |ΔV| <= 1e-3 p.u. (`ACCURACY_P99`), no
changed verdict and at most 5e-3 p.u. at the recovery check (`ACCURACY_AT_CHECK`: the
verdict compares that voltage with 0.95 p.u., so a larger error there can flip verdicts of
tasks this set does not hold), and no diverged episode under random shedding; the command
names it.

Uncontrolled runs never shed, and shedding can make a step unstable that is stable without
it (measured on the PNNL 300-bus study: docs/studies.md, "The motors' step"). So each
candidate that passes the accuracy rule also runs `--stress-rollouts` episodes (default 64;
0: none) of random shedding on the training task with the longest fault
(`shedding_stress`), and is recommended only if none of them diverges.
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from baselines.controllers import no_control
from experiments.common.studyargs import add_study_arguments, study_from_args, summarised_notes
from jaxgrid.episode import play
from jaxgrid.problem import play_specs
from jaxgrid.steppers import MOTOR_STEPS, Solver
from jaxgrid.study import Study, rebuild

ACCURACY_P99 = 1e-3  # p.u.: the largest p99 |ΔV| a study's default step may have
ACCURACY_AT_CHECK = 5e-3  # p.u.: its largest |ΔV| at the recovery check
STRESS_SHARE = 0.15  # share of the action buses that shed at each agent step under stress


def run(study: Study, solver: Solver, episode: float, tasks: str, timed: bool = True):
    """(vm (n_task, n_steps, n_observed), recovered (n_task,), warm wall time s) without
    control, the grid integrated by `solver`; with `timed` False the episodes run once (no
    warm run) and the time is None."""
    env = study.env(solver=solver, episode=episode)
    apply, params, carry = no_control(env)
    specs = study.tasks(tasks)
    _, out = play_specs(study, env, apply, params, specs, carry, trace=True)  # compiles
    if not timed:
        return out["vm"], out["recovered"], None
    start = time.perf_counter()
    _, out = play_specs(study, env, apply, params, specs, carry, trace=True)
    return out["vm"], out["recovered"], time.perf_counter() - start


def stress_task(study: Study):
    """The training task with the longest fault (the first such) at operating point 0."""
    specs = [s for s in study.tasks("train") if s.operating_point == 0]
    return max(specs, key=lambda s: s.fault_duration)


def shedding_stress(study: Study, env, rollouts: int, seed: int = 0) -> dict:
    """Random open-loop shedding on `stress_task`: at every agent step each action bus sheds,
    with probability STRESS_SHARE, a uniform draw from the action range (a perturbed policy
    at its worst: most of the action buses' load is gone well before the episode ends).
    Returns {"diverged": episodes of `rollouts` flagged diverged (`Health.diverged`),
    "shed_share": mean shed power over the action buses' initial load}."""
    grid, params = study.point(0), study.params
    task = jax.tree.map(lambda a: a[0], study.batch([stress_task(study)]).task)
    low, high = float(params.action_low), float(params.action_high)
    shape = (rollouts, env.config.n_steps, len(env.action_slots))
    draw, share = jax.random.split(jax.random.PRNGKey(seed))
    tables = jnp.where(jax.random.uniform(share, shape) < STRESS_SHARE,
                       jax.random.uniform(draw, shape, minval=low, maxval=high), high)

    def replay(table, obs, k, inputs):  # a controller: the table's row for agent step k
        return table[k], k + 1

    def episodes(tables, grid, task, params):
        return jax.vmap(lambda table: play(env, replay, table, task, params, grid,
                                           jnp.zeros((), jnp.int32)))(tables)

    with jax.enable_x64(env.precision == "float64"):
        out = jax.jit(episodes)(tables, grid, task, params)
    p0 = float(np.sum(np.asarray(grid.load_p0)[env.action_slots]))
    return {"diverged": int(np.sum(out["diverged"])),
            "shed_share": float(np.mean(out["shed_pu"])) / p0}


def check_index(study: Study, tasks: str, agent_dt: float, n_steps: int) -> np.ndarray:
    """(n_task,) index of the first agent-step sample at or after the recovery check."""
    specs = study.tasks(tasks)
    cleared = np.array([s.fault_start + s.fault_duration for s in specs])
    at = cleared + float(study.params.recovery_time)
    return np.minimum(np.ceil(at / agent_dt - 1e-9).astype(int) - 1, n_steps - 1)


def accuracy(study: Study, dts, sweeps, reference_dt: float, reference_sweeps: int,
             tasks: str = "train", episode: float | None = None, coarse_dts=(0.0,),
             fine_window: float = 1.0, coarse_sweeps: int | None = None,
             motor_step: str = "exponential", reference_precision: str = "float64",
             stress_rollouts: int = 64) -> dict:
    """The report of the module docstring as a dict; a coarse step of 0 means none."""
    episode = episode or study.config.episode
    with summarised_notes():
        reference = rebuild(study, precision=reference_precision)
        candidate_study = rebuild(study, precision="float32")
    vm_ref, ok_ref, _ = run(reference, Solver(reference_dt, sweeps=reference_sweeps), episode,
                            tasks, timed=False)
    check = check_index(study, tasks, study.config.agent_dt, vm_ref.shape[1])
    rows = []
    for n_sweeps in sweeps:
        for dt, coarse in itertools.product(dts, coarse_dts):
            if coarse and coarse <= dt:
                continue
            solver = Solver(dt, coarse or None, fine_window, n_sweeps, coarse_sweeps, motor_step)
            vm, ok, wall = run(candidate_study, solver, episode, tasks)
            error = np.abs(vm - vm_ref)
            at_check = error[np.arange(len(check)), check]
            row = {"dt_s": dt, "sweeps": n_sweeps, "coarse_dt_s": coarse or None,
                   "p99_dv_pu": float(np.percentile(error, 99)),
                   "max_dv_pu": float(error.max()),
                   "max_dv_at_check_pu": float(at_check.max()),
                   "changed_verdicts": int(np.sum(ok != ok_ref)), "wall_s": wall,
                   "diverged_under_shedding": None, "stress_shed_share": None}
            if stress_rollouts and accurate(row):
                env = candidate_study.env(solver=solver, episode=episode)
                stress = shedding_stress(candidate_study, env, stress_rollouts)
                row["diverged_under_shedding"] = stress["diverged"]
                row["stress_shed_share"] = stress["shed_share"]
            rows.append(row)
    own_solver = study.config.solver
    own = [r for r in rows if r["dt_s"] == own_solver.dt and r["sweeps"] == own_solver.sweeps
           and r["coarse_dt_s"] == own_solver.coarse_dt]
    for row in rows:
        row["time_ratio_to_study_step"] = row["wall_s"] / own[0]["wall_s"] if own else None
    good = [r for r in rows if accurate(r) and not r["diverged_under_shedding"]]
    best = min(good, key=lambda r: r["wall_s"]) if good else None
    return {"study": study.name, "tasks": tasks, "n_tasks": len(ok_ref), "episode_s": episode,
            "reference": {"dt_s": reference_dt, "sweeps": reference_sweeps,
                          "precision": reference_precision, "recovered": int(ok_ref.sum())},
            "study_step": {"dt_s": own_solver.dt, "sweeps": own_solver.sweeps,
                           "coarse_dt_s": own_solver.coarse_dt},
            "fine_window_s": fine_window, "coarse_sweeps": coarse_sweeps,
            "motor_step": motor_step,
            "stress": {"rollouts": stress_rollouts, "share": STRESS_SHARE,
                       "task": str(stress_task(study))},
            "candidates": rows,
            "recommended": best and {k: best[k] for k in ("dt_s", "sweeps", "coarse_dt_s")}}


def accurate(row: dict) -> bool:
    """The accuracy rule of the module docstring (without the shedding stress)."""
    return (row["p99_dv_pu"] <= ACCURACY_P99 and row["changed_verdicts"] == 0
            and row["max_dv_at_check_pu"] <= ACCURACY_AT_CHECK)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.diagnostics.step_accuracy",
                                description=__doc__.split("\n")[0])
    add_study_arguments(p, "ieee39_fidvr")
    p.add_argument("--dts", nargs="+", type=float, default=[0.002, 0.005, 0.01],
                   help="candidate steps, s")
    p.add_argument("--sweeps", nargs="+", type=int, default=[2], help="candidate sweeps")
    p.add_argument("--coarse-dts", nargs="+", type=float, default=[0.0],
                   help="candidate steps outside the fault window, s (0: none)")
    p.add_argument("--fine-window", type=float, default=1.0,
                   help="s after clearing at the fine step (with a coarse step)")
    p.add_argument("--coarse-sweeps", type=int, help="network sweeps at the coarse step")
    p.add_argument("--motor-step", choices=MOTOR_STEPS, default="exponential",
                   help="how the candidates integrate the load models' motors")
    p.add_argument("--reference-dt", type=float, default=0.001, help="s (default 1 ms)")
    p.add_argument("--reference-sweeps", type=int, default=4)
    p.add_argument("--reference-precision", choices=("float64", "float32"), default="float64")
    p.add_argument("--tasks", default="train", help="the study's task set")
    p.add_argument("--episode", type=float, help="s (default: the study's)")
    p.add_argument("--stress-rollouts", type=int, default=64,
                   help="random-shedding episodes per accurate candidate (0: none)")
    p.add_argument("--out", default="benchmarks/cpu/step_accuracy.json")
    args = p.parse_args(argv)
    try:
        study = study_from_args(args)
        report = accuracy(study, args.dts, args.sweeps, args.reference_dt,
                          args.reference_sweeps, args.tasks, args.episode, args.coarse_dts,
                          args.fine_window, args.coarse_sweeps, args.motor_step,
                          args.reference_precision, args.stress_rollouts)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for row in report["candidates"]:
        coarse = f" ({row['coarse_dt_s'] * 1000:g} ms outside)" if row["coarse_dt_s"] else ""
        print(f"dt {row['dt_s'] * 1000:g} ms{coarse}, {row['sweeps']} sweeps: p99 |dV| "
              f"{row['p99_dv_pu']:.2e}, max {row['max_dv_pu']:.2e}, at the check "
              f"{row['max_dv_at_check_pu']:.2e} p.u.; {row['changed_verdicts']} changed "
              f"verdicts of {report['n_tasks']}; {row['wall_s']:.2f} s{stressed(row)}")
    print(f"{report['study']}: recommended {report['recommended']} (p99 |dV| <= "
          f"{ACCURACY_P99:g} p.u., <= {ACCURACY_AT_CHECK:g} p.u. at the check, no changed "
          "verdict, none diverged under shedding)")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


def stressed(row: dict) -> str:
    """The shedding-stress part of a candidate's line ('' if it did not run)."""
    if row["diverged_under_shedding"] is None:
        return ""
    return (f"; under random shedding ({row['stress_shed_share']:.0%} of the action buses' "
            f"load) {row['diverged_under_shedding']} diverged")


if __name__ == "__main__":
    sys.exit(main())
