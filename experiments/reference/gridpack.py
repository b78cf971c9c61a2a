"""GridPACK, the simulator the PARS study's code (HADREC) drove, as the reference for jaxgrid.

    python -m experiments.reference.gridpack --raw R --dyr D --faults 4:0.08 15:0.05 \\
        [--fault-start 1.0] [--t-end 10] [--dt 0.005] [--heating stalled|gridpack] \\
        [--buses 4 504 ...] [--motors 504 ...] [--motor-cons NAME=VALUE ...] \\
        [--add-records "504, 'CIM6BL', 1, ... /" ...] [--cmld-source FILE:BUS --cmld-at BUS:ID]
        [--cmld-cons NAME=VALUE ...] [--motorw gridpack|wecc] [--composite NAME=VALUE ...]
        --out DIR [--save-references DIR2]
    python -m experiments.reference.gridpack --study FILE --tasks train --out DIR
        (the study's faults at each operating point, jaxgrid with the study's models)
    python -m experiments.reference.gridpack --references tests/references/gridpack/*.npz --out DIR

For every fault it writes GridPACK's XML input (the RAW and DYR copied beside it; the fault is
GridPACK's `faultEvent` on a branch from the faulted bus, which adds −j1e9 p.u. to that bus's
diagonal for the fault's duration), runs GridPACK's full-Y dynamic simulator through the
`dsf_obs.x` driver of ../shared/reference/gridpack (found with --gridpack, DSF_OBS or
GRIDPACK_HOME; one MPI process), reads its CSV, runs jaxgrid on the same files and faults (one
batch, `FAULT_X`) and compares them (`compare`): per bus the RMS and largest |ΔV| after
clearing and the time below 0.9 and 0.8 p.u. in each, per A/C motor the stall, part-B restart
and thermal-trip times. Writes DIR/comparison.json and DIR/comparison.png (the worst case's
voltages) and prints a table. --save-references keeps GridPACK's trajectories as compressed
npz files with the command that made them (`save_reference`); --references compares jaxgrid
against such files without GridPACK (what the tests do).

--motors keeps only some ACMTBLU1 motors, --motor-cons changes their CONs and --add-records
adds DYR records (another motor model, e.g. CIM6BL) in place of the ACMTBLU1 of their bus
and load id, in both simulators' files (model-level checks; `gridpack_dyr.MotorEdit`).
--exciter-source FILE:BUS puts that file's exciter at BUS in place of every exciter.
--cmld-source FILE:BUS --cmld-at BUS:ID places the composite load of another DYR at BUS (a
CMLDBLU1 record, replacing the ACMTBLU1 of BUS and ID), --cmld-cons changes every composite
load's CONs. A composite load needs GridPACK with `gridpack_patches/cmld.patch` (README
there); its internal buses are compared under jaxgrid's numbers and its motor D with the A/C
motors. --motorw wecc runs GridPACK's MOTORW (motors A-C) with the patch's switches that make
it the WECC description's motor (`gridpack_files.MOTORW`); --composite sets jaxgrid's
`CompositeOptions` (e.g. v_floor=0 extra_var=none, GridPACK's readings).

`--heating stalled` (default) runs GridPACK with ACMOTOR_HEAT_STALLED_ONLY=1 (running motors
add no heat, the PSS/E reading; the kit's switch) and jaxgrid with heating "stalled";
`gridpack` runs GridPACK as published and jaxgrid with heating "gridpack"
(`jaxgrid.models.acmotor`). Exit status 0 done, 2 bad input or GridPACK missing.
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
from pathlib import Path

from experiments.reference.comparison import against, plot, worst
from experiments.reference.gridpack_dyr import (MotorEdit, composite_buses, edited_dyr,
                                                motor_buses)
from experiments.reference.gridpack_files import (DRIVER, MOTORW, Fault, GridpackMissing,
                                                  Setup, find_driver, load_reference,
                                                  run_gridpack, save_reference)
from jaxgrid.case import CaseError
from jaxgrid.io.dyr import DyrError
from jaxgrid.io.raw import read_raw
from jaxgrid.models.base import ModelError
from jaxgrid.models.options import CONTACTORS, HEATING, MotorOptions

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m experiments.reference.gridpack",
                                description=__doc__.split("\n")[0])
    p.add_argument("--raw", help="PSS/E RAW file, v23 or v33 (GridPACK's readers)")
    p.add_argument("--dyr", help="PSS/E DYR file")
    p.add_argument("--study", help="a study file: its tasks (--tasks) on its own files, "
                                   "jaxgrid with the study's compiled model")
    p.add_argument("--tasks", default="train", help="the study's task set (default train)")
    p.add_argument("--faults", nargs="+", default=[], metavar="BUS:DURATION",
                   help="faults, e.g. 4:0.08 (bus number : duration in s)")
    p.add_argument("--fault-start", type=float, default=1.0, help="s (default 1.0)")
    p.add_argument("--t-end", type=float, default=10.0, help="s (default 10)")
    p.add_argument("--dt", type=float, default=0.005, help="step of both simulators, s")
    p.add_argument("--heating", choices=HEATING, default="stalled",
                   help="A/C motor heating in both simulators (module docstring)")
    p.add_argument("--contactor", choices=CONTACTORS, default="memory",
                   help="jaxgrid's A/C motor contactor rule (GridPACK's is 'gridpack')")
    p.add_argument("--motors", nargs="+", type=int, default=[],
                   help="keep only the ACMTBLU1 motors at these buses (the others' loads "
                        "stay static)")
    p.add_argument("--motor-cons", nargs="+", default=[], metavar="NAME=VALUE",
                   help="set ACMTBLU1 CONs of the kept motors, e.g. fuvr=0.3 ttr1=0.05")
    p.add_argument("--add-records", nargs="+", default=[], metavar="RECORD",
                   help="DYR records to add, e.g. \"504, 'CIM6BL', 1, 1, 0.01, ...\"; each "
                        "replaces the ACMTBLU1 of its bus and load id")
    p.add_argument("--cmld-source", default="", metavar="FILE:BUS",
                   help="a composite load (CMLDBLU1/2 record) of another DYR, for --cmld-at")
    p.add_argument("--cmld-at", nargs="+", default=[], metavar="BUS:ID",
                   help="place --cmld-source's composite load there, as CMLDBLU1")
    p.add_argument("--cmld-cons", nargs="+", default=[], metavar="NAME=VALUE",
                   help="set CONs of every composite load, e.g. fel=0 fb=0 vtr1a=0")
    p.add_argument("--exciter-source", default="", metavar="FILE:BUS",
                   help="replace every exciter by that file's exciter at BUS (GridPACK's "
                        "ESST1A aborts on its own 300-bus case)")
    p.add_argument("--motorw", choices=MOTORW, default="gridpack",
                   help="GridPACK's composite motors A-C as published or with the WECC "
                        "switches of gridpack_patches/cmld.patch")
    p.add_argument("--composite", nargs="+", default=[], metavar="NAME=VALUE",
                   help="jaxgrid's CompositeOptions, e.g. v_floor=0 extra_var=none")
    p.add_argument("--stiff-below", type=float, default=MotorOptions().stiff_below,
                   help="jaxgrid's induction-motor stiff_below, s (0: keep every cage, as "
                        "GridPACK)")
    p.add_argument("--buses", nargs="+", type=int,
                   help="buses to compare (default: the fault buses and the motor buses)")
    p.add_argument("--references", nargs="+", default=[],
                   help="compare jaxgrid against saved references instead of running GridPACK")
    p.add_argument("--gridpack", help="path of dsf_obs.x (default: $DSF_OBS or "
                                      "$GRIDPACK_HOME/" + DRIVER + ")")
    p.add_argument("--save-references", help="folder for GridPACK's trajectories as npz")
    p.add_argument("--name", default="", help="tag in the saved references' file names")
    p.add_argument("--out", required=True, help="output folder")
    return p


def _fault(text: str, start: float) -> Fault:
    bus, _, duration = text.partition(":")
    try:
        return Fault(int(bus), start, float(duration))
    except ValueError:
        raise ValueError(f"--faults {text!r}: expected BUS:DURATION, e.g. 4:0.08") from None


def _pairs(texts, flag: str, number: bool = True) -> tuple:
    """((name, value), ...) of NAME=VALUE texts; values float unless number is False."""
    out = []
    for text in texts:
        name, _, value = text.partition("=")
        try:
            out.append((name.strip().lower(), float(value) if number else value.strip()))
        except ValueError:
            raise ValueError(f"{flag} {text!r}: expected NAME=VALUE") from None
    return tuple(out)


def _edit(args) -> MotorEdit:
    return MotorEdit(tuple(args.motors), _pairs(args.motor_cons, "--motor-cons"),
                     tuple(args.add_records), args.cmld_source, tuple(args.cmld_at),
                     _pairs(args.cmld_cons, "--cmld-cons"), args.exciter_source)


def _composite(args) -> tuple:
    """jaxgrid's CompositeOptions changes: numbers as floats, words as given."""
    pairs = []
    for name, value in _pairs(args.composite, "--composite", number=False):
        try:
            pairs.append((name, float(value)))
        except ValueError:
            pairs.append((name, value))
    return tuple(pairs)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    out = Path(args.out)
    command = "python -m experiments.reference.gridpack " + shlex.join(
        sys.argv[1:] if argv is None else argv)
    try:
        with tempfile.TemporaryDirectory(prefix="gridpack-") as tmp:
            models: dict = {}
            if args.references:
                groups = _saved(args.references)
            elif args.study:
                groups, models = _study_runs(args, command, Path(tmp))
            else:
                groups = _gridpack_runs(args, command, Path(tmp))
            results, runs = [], []
            for k, (setup, cases) in enumerate(groups.items()):
                rows = against(setup, [(f, ref) for f, ref, _ in cases], Path(tmp) / f"j{k}",
                               models.get(setup))
                results += [dict(row, setup=setup.to_json(), reference=source)
                            for (row, _), (_, _, source) in zip(rows, cases)]
                runs += [(fault, ref, ours) for (_, ours), (fault, ref, _) in zip(rows, cases)]
    except (GridpackMissing, CaseError, DyrError, ModelError, ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    (out / "comparison.json").write_text(json.dumps(results, indent=1))
    worst_case = max(range(len(results)), key=lambda k: worst(results[k])[0])
    plot(out / "comparison.png", *runs[worst_case])
    _print_table(results)
    return 0


def _saved(paths) -> dict:
    """{Setup: [(fault, GridPACK Run, file)]} of saved references."""
    groups: dict = {}
    for path in paths:
        run, fault, setup = load_reference(path)
        groups.setdefault(setup, []).append((fault, run, str(path)))
    return groups


def _gridpack_runs(args, command: str, tmp: Path) -> dict:
    """{Setup: [(fault, GridPACK Run, where it was saved or "gridpack")]} of --faults."""
    if not (args.raw and args.dyr and args.faults):
        raise ValueError("give --raw, --dyr and --faults (or --study FILE, or --references "
                         "FILES)")
    setup = Setup(args.raw, args.dyr, args.t_end, args.dt, args.heating, _edit(args),
                  args.contactor, args.stiff_below, args.motorw, _composite(args))
    faults = [_fault(text, args.fault_start) for text in args.faults]
    return {setup: _run_all(args, setup, faults, command, tmp)}


def _study_runs(args, command: str, tmp: Path) -> tuple[dict, dict]:
    """({Setup: cases}, {Setup: the study's model of that point}) of the study's --tasks;
    faults of zero duration are left out (GridPACK's driver needs a fault)."""
    from jaxgrid.study import read_study

    study = read_study(args.study)
    grid, cfg = study.definition.grid, study.config
    if not grid.raw or grid.dyr is None:
        raise ValueError(f"--study {args.study}: a study from RAW and DYR files is needed")
    groups, models = {}, {}
    for k, raw in enumerate(grid.raw):
        faults = [Fault(t.fault_bus, t.fault_start, t.fault_duration)
                  for t in study.tasks(args.tasks)
                  if t.operating_point == k and t.fault_duration > 0]
        if faults:
            setup = Setup(raw, grid.dyr, cfg.episode, cfg.dt,
                          study.definition.compile.motors.heating)
            groups[setup] = _run_all(args, setup, faults, command, tmp / f"point{k}")
            models[setup] = study.point(k)
    return groups, models


def _run_all(args, setup: Setup, faults: list[Fault], command: str, tmp: Path) -> list:
    """[(fault, GridPACK Run, where it was saved or "gridpack")] of `faults` on `setup`."""
    driver = find_driver(args.gridpack)
    dyr = edited_dyr(setup.dyr, setup.edit, tmp / "edited.dyr")
    composites = composite_buses(read_raw(setup.raw), dyr)
    watched = {*motor_buses(dyr, setup.edit), *(c.bus for c in composites),
               *(c.low for c in composites), *(c.load for c in composites)}
    cases = []
    for fault in faults:
        buses = args.buses or sorted({fault.bus, *watched})
        ref = run_gridpack(driver, setup, dyr, fault, buses, tmp / fault.name)
        source = "gridpack"
        if args.save_references:
            tag = f"_{args.name}" if args.name else ""
            path = Path(args.save_references) / (f"{Path(setup.raw).stem}{tag}_{fault.name}_"
                                                  f"{setup.heating}.npz")
            save_reference(path, ref, fault, setup, command)
            source = str(path)
        cases.append((fault, ref, source))
    return cases


def _print_table(results: list[dict]) -> None:
    print(f"{'fault':>16} {'bus':>5} {'rms':>7} {'max':>7} {'<0.9 GridPACK':>13} "
          f"{'<0.9 jaxgrid':>12}")
    for r in results:
        f = r["fault"]
        for bus, row in r["buses"].items():
            below = row["below_0.9"]
            print(f"{f['bus']:>6}:{f['duration']:<9g} {bus:>5} {row['rms']:7.4f} "
                  f"{row['max_abs']:7.4f} {below[0]:13.3f} {below[1]:12.3f}")
    if results:
        rms, gap = max(worst(r)[0] for r in results), max(worst(r)[1] for r in results)
        print(f"worst RMS {rms:.4f} p.u., worst time-below-0.9 difference {gap:.3f} s "
              f"over {len(results)} fault(s)")


if __name__ == "__main__":
    sys.exit(main())
