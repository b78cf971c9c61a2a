"""Scale figure: the 2000-bus synthetic Texas grid (ACTIVSg2000) with A/C motor loads.

    python -m experiments.bench.scale [--batch-sizes 1 4 16 64] [--t-end 1.5]
        [--out benchmarks/cpu/scale.json]

`ACTIVSg2000.RAW` + `ACTIVSg2000_dyn_acmotor_zone3_v1.dyr` from ../shared/cases, compiled
strictly (every model of the file is supported; its 98 generators without a dynamic record
are negative loads, noted). The DYR's 1125 ACMTBLU1
records name buses 10000 + N (the zone-3 loads behind transformers, as the PNNL 300-bus
edit puts them on 20000 + N), which ACTIVSg2000.RAW does not have: each goes onto bus N's
load with the same ID, without the transformer (`motors_on_raw_buses`; a speed figure,
not a study), and records with no such load are dropped and counted. At dt = 5 ms (the case's
Texas2000_dyn_config.json, 2 network sweeps as every study from files), batches of faults
(0.08 s at 1.0 s, cycling over the buses without a machine) run `--t-end` seconds; the
figure is wall seconds per simulated second for the whole batch and per rollout (best of 2
warm calls, compile timed apart), and `profile_step`'s split of one step into network,
device models and the rest, at the largest batch.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

from experiments.bench.inputs import SHARED
from experiments.bench.timing import timed, write_report
from experiments.bench.profiling import profile_model
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.records import DyrData
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks
from jaxgrid.steppers import Solver

RAW = SHARED / "activsg2000/ACTIVSg2000.RAW"
DYR = SHARED / "activsg2000/ACTIVSg2000_dyn_acmotor_zone3_v1.dyr"
DT = 0.005  # s: Texas2000_dyn_config.json simuTimeStepSec
SOLVER = Solver(dt=DT, sweeps=2)  # 2 network sweeps, as every study from files
FAULT_START, FAULT_DURATION, SAMPLE = 1.0, 0.08, 0.1  # s


MOTOR_BUS_OFFSET = 10000  # the DYR's motor bus = this + the RAW load bus


def motors_on_raw_buses(data: DyrData, case) -> tuple[DyrData, dict]:
    """`data` with each load-model record on bus 10000 + N moved to bus N where N has a load
    of that ID; records with neither bus are dropped. Returns (data, counts)."""
    loads = {(int(case.buses.number[b]), str(i).strip()) for b, i in
             zip(case.loads.bus, case.loads.load_id)}
    kept, counts = [], {"moved": 0, "dropped": 0}
    for r in data.records:
        key = (r.bus - MOTOR_BUS_OFFSET, r.device_id.strip())
        if r.record_type != "USRLOD" or (r.bus, r.device_id.strip()) in loads:
            kept.append(r)
        elif key in loads:
            kept.append(dataclasses.replace(r, bus=key[0]))
            counts["moved"] += 1
        else:
            counts["dropped"] += 1
    return dataclasses.replace(data, records=tuple(kept)), counts


def texas_model():
    """(model, compile s, details: motor records moved / dropped)."""
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = read_raw(RAW)
        data, motors = motors_on_raw_buses(read_dyr(DYR), case)
        model = compile_model(case, data, CompileOptions())
    return model, time.perf_counter() - start, {"motor_records": motors}


def fault_tasks(model, batch: int):
    machines = set(model.gen_bus)
    buses = [b for b in model.bus_numbers if b > 0 and b not in machines]
    return stack_tasks([make_task(model, FaultEvent(buses[k * 7 % len(buses)], FAULT_START,
                                                    FAULT_DURATION)) for k in range(batch)])


def bench(batch_sizes, t_end: float) -> dict:
    model, compile_s, details = texas_model()
    result = {"case": "ACTIVSg2000 + ACTIVSg2000_dyn_acmotor_zone3_v1.dyr",
              "n_bus": model.n_bus, "n_gen": model.n_gen, "n_slot": len(model.slot_bus),
              "n_motor": sum(len(g.index) for g in model.loads), "dt_s": DT,
              "sweeps": SOLVER.sweeps, "compile_s": round(compile_s, 2), **details,
              "runs": []}
    print({k: v for k, v in result.items() if k != "runs"}, flush=True)
    decimation = int(round(SAMPLE / DT))
    for batch in batch_sizes:
        tasks = fault_tasks(model, batch)

        def run():
            return simulate_batch(model, tasks, t_end, SOLVER, decimation=decimation).vm

        vm, first = timed(run)
        warm = min(timed(run)[1] for _ in range(2))
        row = {"batch": batch, "first_call_s": round(first, 2),
               "s_per_simulated_s": round(warm / t_end, 3),
               "s_per_simulated_s_per_rollout": round(warm / t_end / batch, 4),
               "finite": bool(np.all(np.isfinite(np.asarray(vm))))}
        print(row, flush=True)
        result["runs"].append(row)
    best = min(result["runs"], key=lambda r: r["s_per_simulated_s_per_rollout"])
    result["best_batch"] = best["batch"]
    result["profile"] = profile_model(model, SOLVER, fault_tasks(model, max(batch_sizes)),
                                      calls=2)
    print(result["profile"], flush=True)
    return result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--batch-sizes", nargs="*", type=int, default=[1, 4, 16, 64])
    parser.add_argument("--t-end", type=float, default=1.5, help="s simulated per call")
    parser.add_argument("--out", default="benchmarks/cpu/scale.json")
    args = parser.parse_args(argv)
    write_report(args.out, **bench(args.batch_sizes, args.t_end))


if __name__ == "__main__":
    main()
