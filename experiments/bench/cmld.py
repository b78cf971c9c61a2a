"""WECC composite loads (CMLDBLU2) on the original study's files: FIDVR figures and speed.

    python -m experiments.bench.cmld [--out benchmarks/cpu/cmld.json] [--skip-2000]

1. IEEE 300 (`IEEE300Bus_modified_noHVDC_v2.raw` + `IEEE300_dyn_cmld_zone1.dyr`, strict,
   dt 2 ms as the study's InterPSS configuration, 10 s): a flat run (largest |ΔV| over all
   buses, over the composite load buses, and where it is largest) and the training faults of
   the LSTM moreActionBuses task file (fault buses of `faultBusCandidates`, 0.08 s at 1.0 s):
   per fault, how many of the 46 action buses (`Bus<N>_loadBus`) are below
   `minVoltRecoveryLevel` `maxVoltRecoveryTime` after clearing.
2. The `baseCases/` operating points: compile, 10-s flat run, largest |ΔV|, diverged.
3. Speed: seconds per Heun step of the same 300-bus case with the composite loads and with
   static loads only (`IEEE300_dyn_v2.dyr`, the same machines), batch of BATCH fault tasks,
   best of ROUNDS alternating warm calls (compile timed apart); the ratio. `--speed-only`
   runs this section alone (into --out).
4. ACTIVSg2000 (`ACTIVSg2000.RAW` + `ACTIVSg2000_dyn_cmld_zone3_v1.dyr`, strict; dt 5 ms
   as its task configuration): compile time, a 1-s flat run (largest |ΔV|), seconds per
   simulated second. Its fault runs and the A/C-motor file: `experiments.bench.texas`.
Writes JSON to --out and prints the figures.
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from experiments.bench.inputs import SHARED
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.records import DyrData
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks

IEEE300 = SHARED / "ieee300"
TASK_FILE = IEEE300 / ("IEEE300_RL_loadShedding_zone1_continuous_LSTM_new_lessfaultbuses_"
                       "moreActionBuses_multipfcases.json")
DT_300, DT_2000 = 0.002, 0.005  # s: IEEE300_dyn_config.json, Texas2000_dyn_config.json
T_END, FAULT_START, FAULT_DURATION = 10.0, 1.0, 0.08  # s
SAMPLE = 0.1  # s between trajectory samples
BATCH = 8  # fault tasks per timed call of the speed comparison
TIMING_T = 1.0  # s simulated per timed call
ROUNDS = 10  # alternating timed calls per model


def _compile(raw: Path, dyr: Path | DyrData):
    """(model, compile seconds), strict; RAW warnings (tap control not modelled) and
    InitWarnings are kept in model.notes."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        case = read_raw(raw)
        start = time.perf_counter()
        data = dyr if isinstance(dyr, DyrData) else read_dyr(dyr)
        model = compile_model(case, data, CompileOptions())
    return model, time.perf_counter() - start


def _drift(model, vm_flat) -> dict:
    """Largest |ΔV| of a flat run's samples vm_flat (n_t, n_bus): overall, where, at the
    composite loads' internal buses and without the worst bus."""
    drift = np.abs(vm_flat - np.abs(np.asarray(model.v0))).max(axis=0)
    internal = [k for k, n in enumerate(model.bus_names) if "_" in n]
    worst = int(drift.argmax())
    return {"max_dv": float(drift.max()), "max_dv_bus": model.bus_names[worst],
            "max_dv_composite_buses": float(drift[internal].max()) if internal else None,
            "max_dv_without_worst_bus": float(np.delete(drift, worst).max())}


def _flat(model, t_end: float, dt: float) -> dict:
    """`_drift` of a flat run of t_end s, and whether it diverged."""
    traj = simulate_batch(model, stack_tasks([make_task(model, None)]), t_end, dt,
                          decimation=int(round(SAMPLE / dt)))
    return {**_drift(model, np.asarray(traj.vm)[0]),
            "diverged": bool(np.asarray(traj.diverged)[0])}


def ieee300_faults(model) -> dict:
    """Flat run and the task file's training faults, 10 s at 2 ms."""
    config = json.loads(TASK_FILE.read_text())
    level, delay = config["minVoltRecoveryLevel"], config["maxVoltRecoveryTime"]
    action = [model.bus_index_by_name(n) for n in config["actionScopeAry"]]
    faults = [model.bus_number_by_name(n) for n in config["faultBusCandidates"]]
    tasks = [make_task(model, None)] + [
        make_task(model, FaultEvent(b, FAULT_START, FAULT_DURATION)) for b in faults]
    start = time.perf_counter()
    traj = simulate_batch(model, stack_tasks(tasks), T_END, DT_300,
                          decimation=int(round(SAMPLE / DT_300)))
    vm = np.asarray(traj.vm)
    wall = time.perf_counter() - start
    t = np.asarray(traj.t).reshape(-1, vm.shape[1])[0]  # the same sample times for every task
    k = int(np.argmin(np.abs(t - (FAULT_START + FAULT_DURATION + delay))))
    after = vm[:, k][:, action]
    return {
        "wall_s_compile_and_run": wall, "flat": _drift(model, vm[0]),
        "recovery_level": level, "seconds_after_clearing": delay, "sample_t": float(t[k]),
        "faults": [{"bus": b, "duration": FAULT_DURATION,
                    "load_buses_below": int((after[i + 1] < level).sum()),
                    "lowest_load_bus_v": float(after[i + 1].min()),
                    "diverged": bool(np.asarray(traj.diverged)[i + 1])}
                   for i, b in enumerate(faults)],
    }


def seconds_per_step(models: dict, dt: float, batch: int = BATCH) -> dict:
    """Per model: first call s and best warm s per Heun step, `batch` fault tasks over
    TIMING_T s; the models' calls alternate ROUNDS times, so load from other processes on
    the machine hits them alike, and the fastest call of each counts."""
    calls = {}
    for name, model in models.items():
        buses = [b for b in model.bus_numbers if b in set(model.gen_bus)]
        tasks = stack_tasks([make_task(model, FaultEvent(buses[k % len(buses)], 0.1, 0.05))
                             for k in range(batch)])
        calls[name] = (model, tasks)
    n_steps = int(round(TIMING_T / dt))

    def call(name):
        model, tasks = calls[name]
        start = time.perf_counter()
        np.asarray(simulate_batch(model, tasks, TIMING_T, dt, decimation=n_steps).vm)
        return time.perf_counter() - start

    out = {name: {"first_call_s": call(name), "n_slot": len(calls[name][0].slot_bus),
                  "s_per_step": np.inf} for name in calls}
    for _ in range(ROUNDS):
        for name in calls:
            out[name]["s_per_step"] = min(out[name]["s_per_step"], call(name) / n_steps)
    return out


def activsg2000(data: DyrData) -> dict:
    """Compile time, and a 1-s flat run's drift and cost of the 2000-bus case."""
    big, compile_s = _compile(SHARED / "activsg2000/ACTIVSg2000.RAW", data)
    start = time.perf_counter()
    flat = _flat(big, 1.0, DT_2000)
    first = time.perf_counter() - start
    start = time.perf_counter()
    _flat(big, 1.0, DT_2000)
    return {"compile_s": compile_s, "n_bus": big.n_bus, "n_slot": len(big.slot_bus),
            "n_composite": len(big.loads[-1].index), "dt": DT_2000, "first_1s_run_s": first,
            "s_per_simulated_s": time.perf_counter() - start, **flat}, big


def speed(model, batch: int = BATCH) -> dict:
    """Section 3: `model` (the 300-bus composite case) against the same case with static
    loads (IEEE300_dyn_v2.dyr)."""
    static, _ = _compile(IEEE300 / "IEEE300Bus_modified_noHVDC_v2.raw",
                         IEEE300 / "IEEE300_dyn_v2.dyr")
    timing = seconds_per_step({"composite": model, "static": static}, DT_300, batch)
    timing["ratio"] = timing["composite"]["s_per_step"] / timing["static"]["s_per_step"]
    print(f"speed (batch {batch}, best of {ROUNDS} alternating calls): composite "
          f"{timing['composite']['s_per_step'] * 1e3:.3f} ms/step, "
          f"static {timing['static']['s_per_step'] * 1e3:.3f} ms/step, ratio {timing['ratio']:.2f}")
    return dict(timing, batch=batch, dt=DT_300)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="benchmarks/cpu/cmld.json")
    parser.add_argument("--skip-2000", action="store_true", help="leave out ACTIVSg2000")
    parser.add_argument("--speed-only", action="store_true",
                        help="only the composite-vs-static cost per step (section 3)")
    parser.add_argument("--batch", type=int, default=BATCH, help="tasks per timed call")
    args = parser.parse_args(argv)
    out: dict = {}

    model, compile_s = _compile(IEEE300 / "IEEE300Bus_modified_noHVDC_v2.raw",
                                IEEE300 / "IEEE300_dyn_cmld_zone1.dyr")
    if args.speed_only:
        out["speed_ieee300"] = speed(model, args.batch)
        Path(args.out).write_text(json.dumps(out, indent=2))
        return out
    out["ieee300"] = {"compile_s": compile_s, "n_bus": model.n_bus, **ieee300_faults(model)}
    r = out["ieee300"]
    print(f"ieee300 CMLD: compile {compile_s:.1f} s, {model.n_bus} buses; flat 10 s: max |dV| "
          f"{r['flat']['max_dv']:.2e} at {r['flat']['max_dv_bus']}, composite buses "
          f"{r['flat']['max_dv_composite_buses']:.2e}, "
          f"others {r['flat']['max_dv_without_worst_bus']:.2e}")
    for f in r["faults"]:
        print(f"  fault bus {f['bus']} {f['duration']} s: {f['load_buses_below']} of 46 load buses "
              f"< {r['recovery_level']} p.u. {r['seconds_after_clearing']} s after clearing "
              f"(lowest {f['lowest_load_bus_v']:.3f}, diverged {f['diverged']})")

    out["base_cases"] = {}
    for raw in sorted((IEEE300 / "baseCases").glob("*.raw")):
        m, c = _compile(raw, IEEE300 / "IEEE300_dyn_cmld_zone1.dyr")
        out["base_cases"][raw.name] = {"compile_s": c, **_flat(m, T_END, DT_300)}
        b = out["base_cases"][raw.name]
        print(f"  {raw.name}: compile {c:.1f} s, flat 10 s max |dV| {b['max_dv']:.2e} at "
              f"{b['max_dv_bus']}, composite buses {b['max_dv_composite_buses']:.2e}, "
              f"diverged {b['diverged']}")

    out["speed_ieee300"] = speed(model, args.batch)

    if not args.skip_2000:
        out["activsg2000"], _ = activsg2000(
            read_dyr(SHARED / "activsg2000/ACTIVSg2000_dyn_cmld_zone3_v1.dyr"))
        a = out["activsg2000"]
        print(f"activsg2000: compile {a['compile_s']:.1f} s, {a['n_bus']} buses, "
              f"{a['n_composite']} CMLD; 1-s flat run: max |dV| {a['max_dv']:.2e} at "
              f"{a['max_dv_bus']} (composite buses {a['max_dv_composite_buses']:.2e}, "
              f"diverged {a['diverged']}), first call {a['first_1s_run_s']:.1f} s, "
              f"{a['s_per_simulated_s']:.2f} s per simulated s (warm)")

    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
