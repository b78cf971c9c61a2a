"""Command line for one time-domain rollout (`jaxgrid.simulate.simulate`) of a RAW + DYR pair.

    python -m experiments.simulate --raw R --dyr D [--fault-bus B ...] --t-end T --dt DT
        --out run.npz

Writes the trajectory as .npz (`write_npz`). Exit status 0 written, 2 bad input.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from jaxgrid.case import CaseError
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.grid import GridModel
from jaxgrid.io.dyr import DyrError, read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.models.acmotor import MotorOptions
from jaxgrid.models.base import ModelError
from jaxgrid.simulate import FaultEvent, Trajectory, simulate


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m experiments.simulate", description=__doc__.split("\n")[0])
    p.add_argument("--raw", required=True, help="PSS/E RAW file (v23, v30-v35)")
    p.add_argument("--dyr", required=True, help="PSS/E DYR file")
    p.add_argument("--fault-bus", type=int, help="RAW number of the faulted bus (none: flat run)")
    p.add_argument("--fault-start", type=float, default=1.0, help="s (default 1.0)")
    p.add_argument("--fault-duration", type=float, default=0.1, help="s (default 0.1)")
    p.add_argument("--fault-r", type=float, default=0.0, help="p.u. system base (default 0)")
    p.add_argument("--fault-x", type=float, default=1e-4, help="p.u. system base (default 1e-4)")
    p.add_argument("--t-end", type=float, default=10.0, help="s (default 10)")
    p.add_argument("--dt", type=float, default=0.005, help="integration step, s (default 0.005)")
    p.add_argument("--decimation", type=int, default=1, help="steps per output sample")
    p.add_argument("--lenient", action="store_true",
                   help="drop unsupported dynamic models (with a warning) instead of failing")
    p.add_argument("--float64", action="store_true", help="run the time loop in float64")
    p.add_argument("--motor-share", default="gridpack",
                   help="load an ACMTBLU1 motor represents: gridpack (default: CON(36), else "
                        "0.43 of its load record, as the PARS study's GridPACK), "
                        "psse_load_record (the whole record), interpss_bus_total or fraction:X")
    p.add_argument("--motor-heating", default="stalled", choices=["stalled", "gridpack"],
                   help="which ACMTBLU1 parts heat: stalled (default, PSS/E and WECC) or "
                        "gridpack (GridPACK as published: running part A too)")
    p.add_argument("--vx-rule", default="reference_running1",
                   choices=["reference_running1", "spec_running2"],
                   help="ACMTBLU1 stall-jump voltage rule (default: the original study's)")
    p.add_argument("--machine-base", default="gridpack", choices=["gridpack", "raw"],
                   help="MBASE of a GENSAL/GENROU the power flow loads beyond it: gridpack "
                        "(default: 1.2 × its loading, as the PARS study's GridPACK) or raw")
    p.add_argument("--out", required=True, help="output .npz")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        case = read_raw(args.raw)
        options = CompileOptions(strict=not args.lenient,
                                 motors=MotorOptions(share_mode=args.motor_share,
                                                     vx_rule=args.vx_rule,
                                                     heating=args.motor_heating),
                                 precision="float64" if args.float64 else "float32",
                                 machine_base=args.machine_base)
        model = compile_model(case, read_dyr(args.dyr), options)
        for note in model.notes:
            if note.startswith("load report: "):
                print(note)
        fault = None if args.fault_bus is None else FaultEvent(
            args.fault_bus, args.fault_start, args.fault_duration, args.fault_r, args.fault_x)
        traj = simulate(model, args.t_end, args.dt, fault=fault, decimation=args.decimation)
    except (CaseError, DyrError, ModelError, ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    write_npz(args.out, model, traj)
    status = f"DIVERGED at t = {float(traj.diverged_at):.3f} s" if traj.diverged else "ok"
    print(f"{args.out}: {len(traj.t)} samples, {model.n_bus} buses, {model.n_gen} machines, {status}")
    return 0


def write_npz(path: str, model: GridModel, traj: Trajectory) -> None:
    """The CLI's arrays; buses in RAW order without three-winding star buses."""
    keep = np.asarray(model.bus_numbers) > 0
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez(path, t=np.asarray(traj.t), bus_ids=np.asarray(model.bus_numbers)[keep],
             vm=np.asarray(traj.vm)[:, keep], va=np.asarray(traj.va)[:, keep],
             gen_bus=np.asarray(model.gen_bus), gen_id=np.asarray(model.gen_id),
             gen_speed=1.0 + np.asarray(traj.speed_dev), gen_angle=np.asarray(traj.angle),
             diverged=np.asarray(traj.diverged))


if __name__ == "__main__":
    sys.exit(main())
