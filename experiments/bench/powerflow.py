"""Power-flow benchmark: compile and solve times per case, written as JSON.

    python -m experiments.bench.powerflow [--raw FILE ...] [--out benchmarks/cpu/powerflow.json]

Without --raw it times the built-in cases and, when ../shared/cases is beside
the repository, the PNNL 2000-bus ACTIVSg2000 file. The first solve includes
JIT compilation of the residual and Jacobian program; the next ones reuse it (same bus
count); each Newton step is a SciPy sparse LU solve.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
import warnings
from pathlib import Path

import jax

from jaxgrid import cases
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import PowerFlowOptions, solve

DEFAULT_RAW = Path(__file__).resolve().parents[3] / "shared/cases/activsg2000/ACTIVSg2000.RAW"


def time_case(case, repeats: int) -> dict:
    """Seconds for the first (compiling) solve and the best of `repeats` warm solves."""
    start = time.perf_counter()
    first = solve(case)
    first_s = time.perf_counter() - start
    warm = []
    for _ in range(repeats):
        start = time.perf_counter()
        solve(case)
        warm.append(time.perf_counter() - start)
    flat = solve(case, PowerFlowOptions(flat_start=True))
    return {"case": case.name, "n_bus": case.n_bus, "iterations": first.iterations,
            "iterations_flat_start": flat.iterations,
            "pv_to_pq": len(first.switched_to_pq), "first_solve_s": round(first_s, 4),
            "warm_solve_s": round(min(warm), 4),
            "compile_s_estimate": round(first_s - min(warm), 4)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--raw", nargs="*", default=None, help="RAW files to time")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="benchmarks/cpu/powerflow.json")
    args = parser.parse_args(argv)
    targets = [cases.load(name) for name in ("ieee39", "ieee300")]
    raws = args.raw if args.raw is not None else ([DEFAULT_RAW] if DEFAULT_RAW.is_file() else [])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        targets += [read_raw(path) for path in raws]
    rows = []
    for case in targets:
        rows.append(time_case(case, args.repeats))
        print(json.dumps(rows[-1]))
    report = {"benchmark": "powerflow", "device": str(jax.devices()[0]),
              "platform": platform.platform(), "jax": jax.__version__, "results": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=2))
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
