"""The synthetic Texas grid ACTIVSg2000 from its files as written.

    python -m experiments.bench.texas [--out benchmarks/cpu/texas.json] [--t-end 5]
        [--fault-bus 7186] [--fault-duration 0.1] [--skip-acmotor]

1. `ACTIVSg2000.RAW` + `ACTIVSg2000_dyn_cmld_zone3_v1.dyr`, strict: compile seconds, the build
   notes counted by kind, a 1-s flat run (largest |ΔV| over all buses and where), then a
   bolted fault at the study's candidate bus 7186 (`Texas2000_RL_loadShedding_zone3.json`),
   0.1 s from 1.0 s, at dt 5 ms (`Texas2000_dyn_config.json`): the first call (trace and
   compile) and a warm call in seconds, milliseconds per step, divergence, and the composite
   load buses (`Bus<N>_loadBus`) below 0.9 p.u. 5 s after clearing (`--t-end` 6.1).
2. `ACTIVSg2000_dyn_acmotor_zone3_v1.dyr`: how many of its ACMTBLU1 and machine records each
   RAW has, then the same runs with `texas2000_hr_4375_v30_mod.raw`, the RAW whose buses
   17xxx carry its zone-3 motors, lenient (the records naming what that RAW lacks dropped).
Writes JSON to --out and prints the figures.
"""
from __future__ import annotations

import argparse
import collections
import time
import warnings

import jax
import numpy as np

from experiments.bench.inputs import SHARED
from experiments.bench.timing import write_report
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.simulate import FaultEvent, simulate

FOLDER = SHARED / "activsg2000"
CMLD, ACMOTOR = "ACTIVSg2000_dyn_cmld_zone3_v1.dyr", "ACTIVSg2000_dyn_acmotor_zone3_v1.dyr"
RAW, MOD_RAW = "ACTIVSg2000.RAW", "texas2000_hr_4375_v30_mod.raw"
DT = 0.005  # s: Texas2000_dyn_config.json simuTimeStepSec
FLAT_T = 1.0  # s
FAULT_START = 1.0  # s
SAMPLE = 0.1  # s between trajectory samples
RECOVERED = 0.9  # p.u.: the task file's minVoltRecoveryLevel


def note_kinds(notes) -> dict[str, int]:
    """The build notes counted by what they say (the text after the device's name)."""
    kinds = collections.Counter()
    for note in notes:
        if note.startswith("load report: "):
            kinds["load report"] += 1
        else:
            kinds[note.split(": ")[-1].split(" (")[0][:80]] += 1
    return dict(kinds.most_common())


def runs(model, fault_bus: int, duration: float, t_end: float) -> dict:
    """The flat run and the fault run of `model` (module docstring)."""
    v0 = np.abs(np.asarray(model.v0))
    flat = simulate(model, FLAT_T, DT, decimation=round(SAMPLE / DT))
    drift = np.abs(np.asarray(flat.vm) - v0)
    worst = int(np.argmax(drift.max(axis=0)))
    fault = FaultEvent(fault_bus, FAULT_START, duration)
    calls = []
    for _ in range(2):
        start = time.perf_counter()
        traj = simulate(model, t_end, DT, fault=fault, decimation=round(SAMPLE / DT))
        jax.block_until_ready(traj.vm)
        calls.append(time.perf_counter() - start)
    t, vm = np.asarray(traj.t), np.asarray(traj.vm)
    after = int(np.argmin(np.abs(t - (FAULT_START + duration + 5.0))))
    load_buses = [k for k, name in enumerate(model.bus_names) if name.endswith("_loadBus")]
    return {"flat_drift_pu": float(drift.max()), "flat_drift_bus": model.bus_numbers[worst],
            "fault_first_call_s": calls[0], "fault_warm_s": calls[1],
            "ms_per_step": 1e3 * calls[1] / round(t_end / DT),
            "diverged": bool(traj.diverged), "sampled_at_s": float(t[after]),
            "load_buses": len(load_buses),
            "load_buses_below": int(np.sum(vm[after, load_buses] < RECOVERED)),
            "min_v_at_sample": float(vm[after].min())}


def compiled(raw: str, dyr: str, strict: bool) -> tuple:
    """(model, compile seconds, warnings' texts)."""
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = compile_model(read_raw(FOLDER / raw), read_dyr(FOLDER / dyr),
                              CompileOptions(strict=strict))
    return model, time.perf_counter() - start, [str(w.message)[:300] for w in caught]


def record_matches(dyr: str) -> dict:
    """How many of `dyr`'s ACMTBLU1 and machine-side records each RAW has."""
    data = read_dyr(FOLDER / dyr)
    out = {}
    for raw in (RAW, MOD_RAW):
        case = read_raw(FOLDER / raw)
        number = case.buses.number
        loads = {(int(number[b]), str(i).strip()) for b, i in
                 zip(case.loads.bus, case.loads.load_id)}
        gens = {(int(number[b]), str(i).strip()) for b, i in
                zip(case.generators.bus, case.generators.gen_id)}
        motors = [r for r in data.records if r.record_type == "USRLOD"]
        others = [r for r in data.records if r.record_type != "USRLOD"]
        out[raw] = {"motor_records": len(motors), "others": len(others),
                    "motors_with_a_load": sum((r.bus, r.device_id.strip()) in loads
                                              for r in motors),
                    "others_with_a_generator": sum((r.bus, r.device_id.strip()) in gens
                                                   for r in others)}
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="benchmarks/cpu/texas.json")
    parser.add_argument("--t-end", type=float, default=6.1, help="s, fault run")
    parser.add_argument("--fault-bus", type=int, default=7186)
    parser.add_argument("--fault-duration", type=float, default=0.1, help="s")
    parser.add_argument("--skip-acmotor", action="store_true")
    args = parser.parse_args(argv)
    out = {}
    cases = [("cmld", RAW, CMLD, True)] + ([] if args.skip_acmotor else
                                           [("acmotor", MOD_RAW, ACMOTOR, False)])
    for key, raw, dyr, strict in cases:
        model, seconds, caught = compiled(raw, dyr, strict)
        entry = {"raw": raw, "dyr": dyr, "strict": strict, "compile_s": seconds,
                 "n_bus": model.n_bus, "n_gen": model.n_gen,
                 "devices": {family: {g.model.name: len(g.labels) for g in getattr(model, family)}
                             for family in ("exciters", "governors", "stabilizers", "loads")},
                 "notes": note_kinds(model.notes), "warnings": caught}
        if key == "acmotor":
            entry["record_matches"] = record_matches(dyr)
        entry |= runs(model, args.fault_bus, args.fault_duration, args.t_end)
        out[key] = entry
        print(f"{key}: {raw} + {dyr} ({'strict' if strict else 'lenient'}): compile "
              f"{seconds:.1f} s, {model.n_bus} buses, {model.n_gen} machines; flat 1 s: "
              f"{entry['flat_drift_pu']:.2e} p.u. (bus {entry['flat_drift_bus']}); fault at "
              f"{args.fault_bus}: first call {entry['fault_first_call_s']:.1f} s, "
              f"{entry['ms_per_step']:.2f} ms/step, diverged {entry['diverged']}, "
              f"{entry['load_buses_below']} of {entry['load_buses']} load buses below "
              f"{RECOVERED} p.u. at {entry['sampled_at_s']:.1f} s")
    write_report(args.out, **out)


if __name__ == "__main__":
    main()
