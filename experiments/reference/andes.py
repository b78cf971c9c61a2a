"""The errors of this project's simulator against ANDES for one case and bus fault:

    python -m experiments.reference.andes --raw R --dyr D --fault-bus B [--drop IEEEST ST2CUT]

prints the largest and RMS voltage error, speed and relative angle errors
(`experiments.reference.andes_files`).
"""
from __future__ import annotations

import argparse
import os
import tempfile

from experiments.reference.andes_files import run_andes, trajectory_errors, write_psse_dyr
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import PowerFlowOptions, solve
from jaxgrid.simulate import FaultEvent, simulate


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="errors against ANDES for one bus fault")
    parser.add_argument("--raw", required=True)
    parser.add_argument("--dyr", required=True)
    parser.add_argument("--fault-bus", type=int, required=True)
    parser.add_argument("--fault-start", type=float, default=1.0)
    parser.add_argument("--fault-duration", type=float, default=0.1)
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--dt", type=float, default=0.005)
    parser.add_argument("--drop", nargs="*", default=(), help="models removed for both tools")
    args = parser.parse_args(argv)
    dyr = write_psse_dyr(args.dyr, os.path.join(tempfile.mkdtemp(), "case.dyr"), tuple(args.drop))
    ref = run_andes(args.raw, dyr, args.t_end, args.fault_bus, args.fault_start,
                    args.fault_duration, tstep=args.dt)
    case = read_raw(args.raw)  # ANDES's power flow does not enforce Q limits; match it
    model = compile_model(case, read_dyr(dyr), CompileOptions(strict=False),
                          pf=solve(case, PowerFlowOptions(enforce_q_limits=False)))
    fault = FaultEvent(args.fault_bus, args.fault_start, args.fault_duration)
    traj = simulate(model, args.t_end, args.dt, fault=fault)
    errors = trajectory_errors(model, traj, ref, (fault.start, fault.start + fault.duration))
    print(f"{args.raw}: {errors}, ANDES TDS {ref.wall_s:.2f} s, diverged {bool(traj.diverged)}")


if __name__ == "__main__":
    main()
