"""Simulation benchmark: batched 10 s fault rollouts vs batch size and device count, vs ANDES.

    python -m experiments.bench.sim [--cases ieee39 npcc] [--batch-sizes 1 4 16 64 256 1024]
                                    [--devices 1 2] [--out benchmarks/cpu/sim.json]

Cases: `ieee39` is the PNNL 39-bus file (../shared/cases, motor loads left out), `npcc` the
140-bus NPCC case that ANDES ships, `ieee300` the PNNL 300-bus file; `ieee39_fidvr` and
`ieee300_fidvr` are the built-in study cases with their A/C motors and a load slot per
action bus, run at the case's step (2 ms / 5 ms). Each task is a 0.1 s bolted fault at
1.0 s on a different bus, 10 s, sampled every 0.1 s (the load-shedding control step). For each batch size and device count the batch axis is
sharded over a 1-D mesh of CPU devices (NamedSharding); the first call (compile + run) and
the best warm call are timed. ANDES runs the same case and fault in the same process.

The file cases are compiled with no load slots (`CompileOptions(load_buses=())`): these are
pure fault rollouts, as ANDES runs them. A load-shedding environment adds one slot per
controlled load bus (as the study cases have), and the network solve grows with the square
of the slot count.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from pathlib import Path

import jax
import numpy as np

from experiments.reference.andes_files import run_andes, write_psse_dyr
from experiments.bench.inputs import SHARED
from experiments.bench.timing import sharded_timings, write_report
from experiments.common.studyargs import study_from_spec
from jaxgrid import network
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks
from jaxgrid.steppers import Solver, heun_step

T_END, DT, SAMPLE = 10.0, 0.005, 0.1  # s
LOAD_BUSES = ()  # no controllable loads in the file cases: see the module docstring
STUDY_CASES = ("ieee39_fidvr", "ieee300_fidvr")


def _andes_cases() -> Path:
    import andes
    return Path(andes.__file__).parent / "cases"


CASES = {  # name: (raw, dyr, models dropped for both simulators)
    "ieee39": (lambda: SHARED / "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw",
               lambda: SHARED / "ieee39/IEEE39bus_3AC.dyr", ("USRLOD",)),
    "npcc": (lambda: _andes_cases() / "npcc/npcc.raw",
             lambda: _andes_cases() / "npcc/npcc_full.dyr", ()),
    "ieee300": (lambda: SHARED / "ieee300/IEEE300Bus_modified_noHVDC_v2.raw",
                lambda: SHARED / "ieee300/IEEE300_genrou_exdc1_tgov1_zone1ac.dyr", ("USRLOD",)),
}


def step_compile_seconds(model, solver: Solver) -> float:
    """Seconds to lower and compile one Heun step of `model` (no run)."""
    task = make_task(model, FaultEvent(model.bus_numbers[0], 1.0, 0.1))
    fault = network.fault_view(model.network, task.fault_bus, task.fault_z)
    step = jax.jit(heun_step, static_argnames=("solver",))
    start = time.perf_counter()
    step.lower(model, model.initial, np.float32(0.0), solver=solver, task=task,
               fault=fault).compile()
    return time.perf_counter() - start


def load_case(name: str):
    """(model, solver, (raw, dyr) files for ANDES or None) of a benchmark case."""
    if name in STUDY_CASES:
        study = study_from_spec(name)
        return study.point(0), study.config.solver.fine(), None
    raw_fn, dyr_fn, drop = CASES[name]
    folder = tempfile.mkdtemp()
    dyr = write_psse_dyr(str(dyr_fn()), os.path.join(folder, f"{name}.dyr"), drop)
    raw = str(raw_fn())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = compile_model(read_raw(raw), read_dyr(dyr),
                              CompileOptions(strict=False, load_buses=LOAD_BUSES))
    return model, Solver(dt=DT), (raw, dyr)


def bench_case(name: str, batch_sizes, device_counts, repeats: int, with_andes: bool) -> dict:
    start = time.perf_counter()
    model, solver, files = load_case(name)
    dt = solver.dt
    decimation = int(round(SAMPLE / dt))
    result = {"case": name, "n_bus": model.n_bus, "n_gen": model.n_gen,
              "n_slot": len(model.slot_bus), "n_motor": sum(len(g.index) for g in model.loads),
              "dt_s": dt, "model_compile_s": round(time.perf_counter() - start, 3),
              "step_compile_s": round(step_compile_seconds(model, solver), 3), "runs": []}
    # fault buses: the machines' buses excluded, cycling over the rest
    candidates = [b for b in model.bus_numbers if b > 0 and b not in model.gen_bus]
    faults = [make_task(model, FaultEvent(candidates[k % len(candidates)], 1.0, 0.1))
              for k in range(max(batch_sizes))]
    for n_dev, batch, out, first, warm in sharded_timings(
            batch_sizes, device_counts, repeats, lambda batch: stack_tasks(faults[:batch]),
            lambda tasks: simulate_batch(model, tasks, T_END, solver, decimation)):
        row = {"devices": n_dev, "batch": batch, "first_call_s": round(first, 3),
               "warm_s": round(warm, 4), "rollouts_per_s": round(batch / warm, 2),
               "sim_s_per_wall_s": round(batch * T_END / warm, 1),
               "diverged": int(np.sum(np.asarray(out.diverged)))}
        print(name, row, flush=True)
        result["runs"].append(row)
    if with_andes and files:
        try:
            ref = run_andes(*files, T_END, candidates[0], 1.0, 0.1, tstep=dt)
        except Exception as err:  # ANDES reads PSS/E v33 layouts only; report, go on
            result["andes_error"] = f"{type(err).__name__}: {err}"
            print(name, "ANDES could not run:", result["andes_error"], flush=True)
            return result
        best = max(r["rollouts_per_s"] for r in result["runs"])
        result["andes_tds_s"] = round(ref.wall_s, 3)
        result["best_rollouts_per_s"] = best
        result["ratio_to_andes"] = round(best * ref.wall_s, 1)
        single = [r for r in result["runs"] if r["batch"] == 1 and r["devices"] == 1]
        if single:
            result["ratio_one_at_a_time_to_andes"] = round(single[0]["rollouts_per_s"] * ref.wall_s, 1)
        print(name, {k: v for k, v in result.items() if k != "runs"}, flush=True)
    return result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="*", default=["ieee39", "npcc"],
                        choices=list(CASES) + list(STUDY_CASES))
    parser.add_argument("--batch-sizes", nargs="*", type=int, default=[1, 4, 16, 64, 256, 1024])
    parser.add_argument("--devices", nargs="*", type=int, default=[1, 2])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--no-andes", action="store_true", help="skip the ANDES comparison")
    parser.add_argument("--out", default="benchmarks/cpu/sim.json")
    args = parser.parse_args(argv)
    write_report(args.out, t_end_s=T_END, sample_every_s=SAMPLE,
                 cases=[bench_case(c, args.batch_sizes, args.devices, args.repeats,
                                   not args.no_andes) for c in args.cases])


if __name__ == "__main__":
    main()
