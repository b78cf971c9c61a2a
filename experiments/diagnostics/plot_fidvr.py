"""Draw fault-induced delayed voltage recovery on a study (built-in, file or RAW + DYR).

    python -m experiments.diagnostics.plot_fidvr --study ieee39_fidvr --fault-bus 4 \
        --fault-duration 0.08 [--point 0] --out fidvr.png

The motor-data readings (`MotorOptions`) are the study's compile settings ([compile.motors]
of a study file).

Top: the observed bus voltages against the recovery envelope (0.7 / 0.8 / 0.9 / 0.95 p.u.
from 0 / 0.33 / 0.5 / 1.5 s after clearing). Bottom: the A/C motor population, weighted by
motor MVA, running / stalled / off (thermal or UV trip, contactor open). No control.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from experiments.common.studyargs import add_study_arguments, study_from_args
from jaxgrid.study import write_study
from jaxgrid.models.acmotor import Acmtblu1, motor_status
from jaxgrid.recovery import envelope
from jaxgrid.simulate import FaultEvent, simulate


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m experiments.diagnostics.plot_fidvr",
                                description=__doc__.split("\n")[0])
    add_study_arguments(p, "ieee39_fidvr")
    p.add_argument("--point", type=int, default=0, help="operating point index (default 0)")
    p.add_argument("--fault-bus", type=int, required=True, help="RAW number of the faulted bus")
    p.add_argument("--fault-start", type=float, default=1.0, help="s (default 1.0)")
    p.add_argument("--fault-duration", type=float, default=0.08, help="s (default 0.08)")
    p.add_argument("--t-end", type=float, default=10.0, help="s (default 10)")
    p.add_argument("--out", default="fidvr.png", help="PNG file")
    return p


def motor_shares(model, traj):
    """(running, stalled, off) shares of all ACMTBLU1 motors, weighted by motor MVA: (3, n_t),
    or (3, batch, n_t) for a batch trajectory."""
    totals = np.zeros((3, *np.shape(traj.t)))
    weight = 0.0
    for group, flags in zip(model.loads, traj.load_flags):
        if group.model is not Acmtblu1:
            continue
        p = {k: np.asarray(v) for k, v in group.params.items()}
        shares = motor_status(p, {k: np.asarray(v) for k, v in flags.items()})
        totals += np.stack([(s * p["sm"]).sum(axis=-1) for s in shares])
        weight += float(p["sm"].sum())
    return totals / max(weight, 1e-12)


def draw(name: str, observed_buses, model, t: np.ndarray, vm: np.ndarray, shares: np.ndarray,
         fault: FaultEvent, path: str) -> None:
    """Write the two-panel FIDVR figure of study `name` to `path`: voltages vm (n_t, n_bus)
    p.u. at the observed buses (RAW numbers) at times t (n_t,) s, and motor shares (3, n_t)
    from `motor_shares`."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cleared = fault.start + fault.duration
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 7), sharex=True,
                                      gridspec_kw={"height_ratios": [2, 1]})
    for bus in observed_buses:
        top.plot(t, vm[:, model.bus_index(bus)], lw=1, label=f"bus {bus}")
    fine = np.linspace(0, t[-1], 2000)
    top.step(fine, envelope(fine - cleared), "k--", where="post", lw=1.5,
             label="recovery envelope")
    top.set_ylabel("voltage (p.u.)")
    top.set_ylim(0, 1.15)
    top.set_title(f"{name}: {fault.duration * 1000:.0f} ms fault at bus {fault.bus}, "
                  "no control")
    top.legend(ncol=4, fontsize=7, loc="lower right")
    top.grid(alpha=0.3)
    bottom.stackplot(t, *shares, labels=["running", "stalled", "off"],
                     colors=["tab:green", "tab:red", "tab:gray"], alpha=0.8)
    bottom.set_ylabel("A/C motors (share of MVA)")
    bottom.set_xlabel("time (s)")
    bottom.set_ylim(0, 1)
    bottom.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        study = study_from_args(args)
        if not 0 <= args.point < study.n_points:
            raise ValueError(f"--point {args.point}: the study has {study.n_points} operating "
                             f"points (0 to {study.n_points - 1})")
        model = study.point(args.point)
        fault = FaultEvent(args.fault_bus, args.fault_start, args.fault_duration)
        solver = study.config.solver.fine()
        traj = simulate(model, args.t_end, solver, fault=fault,
                        decimation=max(1, int(round(0.01 / solver.dt))))
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    t, vm, shares = np.asarray(traj.t), np.asarray(traj.vm), motor_shares(model, traj)
    draw(f"{study.name} {study.points[args.point].label}", study.config.observed_buses, model,
         t, vm, shares, fault, args.out)
    write_study(study, Path(args.out).with_suffix(".study.toml"))
    judged = fault.start + fault.duration + 4.0
    k = min(int(np.searchsorted(t, judged - 1e-6)), len(t) - 1)
    when = "4 s after clearing" if t[k] >= judged - 1e-6 else f"at the end ({t[k]:.2f} s)"
    observed = vm[k, [model.bus_index(b) for b in study.config.observed_buses]]
    running, stalled, off = shares
    print(f"{args.out}: lowest observed voltage {when} {observed.min():.3f} p.u.; "
          f"motors at the end: {running[-1]:.0%} running, {stalled[-1]:.0%} stalled, "
          f"{off[-1]:.0%} off" + (" (DIVERGED)" if bool(traj.diverged) else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
