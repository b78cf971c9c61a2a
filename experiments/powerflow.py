"""Command line for the AC power flow (`jaxgrid.powerflow.solve`) on a RAW file or a built-in case.

    python -m experiments.powerflow (--raw FILE | --case NAME) [--flat] [--no-q-limits]
        [--tol TOL] [--out pf.json]

Prints convergence, iterations, the largest mismatch (p.u.) and the voltage extremes; `--out`
writes `PowerFlowResult.to_json()`. Exit status 0 solved, 1 not converged, 2 bad input.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from jaxgrid import cases
from jaxgrid.case import CaseError
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import PowerFlowError, PowerFlowOptions, solve


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.powerflow", description=__doc__.split("\n")[0])
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--raw", help="PSS/E RAW file (v23, v30-v35)")
    source.add_argument("--case", help="built-in case name (see jaxgrid.cases.names())")
    parser.add_argument("--flat", action="store_true", help="flat start instead of stored voltages")
    parser.add_argument("--no-q-limits", action="store_true", help="do not switch PV buses to PQ")
    parser.add_argument("--tol", type=float, default=PowerFlowOptions.tol, help="mismatch tolerance, p.u.")
    parser.add_argument("--out", help="write the solution as JSON here")
    args = parser.parse_args(argv)

    try:
        case = read_raw(args.raw) if args.raw else cases.load(args.case)
        if isinstance(case, cases.StudyCase):
            case = case.case  # the study's network
    except (CaseError, ValueError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    options = PowerFlowOptions(tol=args.tol, flat_start=args.flat,
                               enforce_q_limits=not args.no_q_limits)
    start = time.perf_counter()
    try:
        result = solve(case, options)
    except PowerFlowError as error:
        print(f"converged: False\n{error}", file=sys.stderr)
        return 1
    seconds = time.perf_counter() - start
    live = result.vm > 0
    print(f"case: {case.name} ({case.n_bus} buses)")
    print(f"converged: {result.converged}")
    print(f"iterations: {result.iterations}")
    print(f"max mismatch: {result.max_mismatch:.3e} p.u.")
    print(f"voltage: min {result.vm[live].min():.4f} p.u. at bus {case.buses.number[live][np.argmin(result.vm[live])]},"
          f" max {result.vm[live].max():.4f} p.u. at bus {case.buses.number[live][np.argmax(result.vm[live])]}")
    print(f"PV buses switched to PQ: {len(result.switched_to_pq)}")
    print(f"wall time: {seconds:.3f} s (includes JIT compilation)")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result.to_json()))
        print(f"written: {args.out}")
    return 0



if __name__ == "__main__":
    sys.exit(main())
