"""GridPACK, the simulator the PARS study's code (HADREC) drove, as the reference for jaxgrid.

    python -m experiments.reference.gridpack --raw R --dyr D --faults 4:0.08 15:0.05 \\
        [--fault-start 1.0] [--t-end 10] [--dt 0.005] [--heating stalled|gridpack] \\
        [--buses 4 504 ...] --out DIR [--save-references DIR2]
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

`--heating stalled` (default) runs GridPACK with ACMOTOR_HEAT_STALLED_ONLY=1 (running motors
add no heat, the PSS/E reading; the kit's switch) and jaxgrid with heating "stalled";
`gridpack` runs GridPACK as published and jaxgrid with heating "gridpack"
(`jaxgrid.models.acmotor`). Exit status 0 done, 2 bad input or GridPACK missing.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from jaxgrid.case import Case, CaseError
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.grid import GridModel
from jaxgrid.io.dyr import DyrError, read_dyr
from jaxgrid.io.raw import raw_version, read_raw
from jaxgrid.models.acmotor import Acmtblu1, motor_power
from jaxgrid.models.base import ModelError
from jaxgrid.models.options import CONTACTORS, HEATING, MotorOptions
from jaxgrid.powerflow import PowerFlowOptions, solve
from jaxgrid.simulate import FaultEvent, make_task, simulate_batch, stack_tasks

FAULT_X = 1e-9  # p.u.: GridPACK's faultEvent puts −j1e9 on the faulted bus's diagonal
GRIDPACK_COMMIT = "bea5ce1"  # the kit's source snapshot (../shared/reference/gridpack)
DRIVER = "build/applications/dynamic_simulation_full_y/dsf_obs.x"  # under GRIDPACK_HOME
RAW_TAGS = {23: "networkConfiguration", 33: "networkConfiguration_v33"}  # GridPACK's readers
MOTOR_FIELDS = ("Vmeas", "statusA", "statusB", "P", "Q", "thetaA", "thetaB")  # load watch
LEVELS = (0.9, 0.8)  # p.u.: the comparison's "time below" levels
# Q_LIMITS: GridPACK's power flow enforces generator Q limits only with <qlim>1</qlim>; the
# PNNL/HADREC inputs write <qLimit>True</qLimit>, which it does not read, so the PARS study
# ran without them, and with <qlim>1</qlim> it diverges on HADREC's 300-bus case. Both
# simulators therefore start from a power flow without Q limits here (on the PNNL 39-bus
# case no limit binds).


class GridpackMissing(RuntimeError):
    """The GridPACK driver could not be found or run."""


@dataclasses.dataclass(frozen=True)
class Fault:
    """A bolted bus fault: RAW bus number, start and duration (s)."""

    bus: int
    start: float
    duration: float

    @property
    def end(self) -> float:
        return self.start + self.duration

    @property
    def name(self) -> str:
        return f"bus{self.bus}_{self.duration * 1000:g}ms"


@dataclasses.dataclass(frozen=True)
class Run:
    """Sampled trajectories of one simulator for one fault.

    Attributes:
      t: (n_t,) s.  bus_ids: (n_bus,) RAW numbers.  vm: (n_t, n_bus) p.u.
      motor_bus: (n_motor,) RAW numbers of the ACMTBLU1 motors.
      status_a, status_b: (n_t, n_motor) 1 running, 0 stalled.
      theta_a, theta_b: (n_t, n_motor) winding temperatures, p.u.
      p_motor, q_motor: (n_t, n_motor) power drawn, p.u. on the motor's base (all its
        fractions applied; GridPACK's Pmotor, Qmotor).
    """

    t: np.ndarray
    bus_ids: np.ndarray
    vm: np.ndarray
    motor_bus: np.ndarray
    status_a: np.ndarray
    status_b: np.ndarray
    theta_a: np.ndarray
    theta_b: np.ndarray
    p_motor: np.ndarray
    q_motor: np.ndarray

    def voltage(self, bus: int) -> np.ndarray:
        """(n_t,) p.u. at RAW bus `bus`."""
        return self.vm[:, list(self.bus_ids).index(bus)]

    def until(self, t_end: float) -> Run:
        """The samples at t <= t_end (s)."""
        keep = self.t <= t_end + 1e-9
        return dataclasses.replace(self, **{f.name: getattr(self, f.name)[keep]
                                            for f in dataclasses.fields(self)
                                            if f.name not in ("bus_ids", "motor_bus")})


# --------------------------------------------------------------------------- #
# GridPACK: input, run, output
# --------------------------------------------------------------------------- #

def find_driver(path: str | None = None) -> Path:
    """The dsf_obs.x driver: `path`, else $DSF_OBS, else $GRIDPACK_HOME/DRIVER (default
    /opt/gridpack); GridpackMissing says how to build it."""
    home = os.environ.get("GRIDPACK_HOME", "/opt/gridpack")
    driver = Path(path or os.environ.get("DSF_OBS") or Path(home) / DRIVER)
    if not (driver.is_file() and os.access(driver, os.X_OK)):
        raise GridpackMissing(
            f"GridPACK driver not found at {driver}: build it with "
            "../shared/reference/gridpack/build.sh (about 5 minutes on 2 cores) and set "
            "GRIDPACK_HOME, or give --gridpack PATH/dsf_obs.x")
    if shutil.which("mpirun") is None:
        raise GridpackMissing("mpirun not found (OpenMPI, installed by build.sh)")
    return driver


def fault_branch(case: Case, bus: int, raw_text: str) -> tuple[tuple[int, int], str]:
    """((from, to) RAW numbers, RAW text) of an in-service branch whose from bus is `bus`:
    GridPACK's faultEvent faults the from bus of the branch it names. Where no branch leaves
    `bus`, a line (not a transformer) that ends there is written the other way round in the
    returned text (I and J swapped; its line-end shunts must be zero, so nothing else
    changes)."""
    br, numbers = case.branches, case.buses.number
    for f, t, on in zip(br.from_bus, br.to_bus, br.in_service):
        if on and numbers[f] == bus:
            return (int(numbers[f]), int(numbers[t])), raw_text
    lines = raw_text.splitlines(keepends=True)
    for k in range(len(br.from_bus)):
        f, t = numbers[br.from_bus[k]], numbers[br.to_bus[k]]
        ends_free = br.g_from[k] == br.g_to[k] == br.b_from[k] == br.b_to[k] == 0
        if br.in_service[k] and t == bus and not br.is_transformer[k] and ends_free:
            row = lines[br.line[k] - 1]
            first, second, rest = row.split(",", 2)
            lines[br.line[k] - 1] = f"{second},{first},{rest}"
            return (int(t), int(f)), "".join(lines)
    raise ValueError(f"{case.source}: no in-service branch leaves bus {bus} and no line without "
                     "end shunts ends there (GridPACK's faultEvent faults the from bus of a "
                     "branch)")


def gridpack_xml(raw: str, version: int, dyr: str, branch: tuple[int, int], fault: Fault,
                 t_end: float, dt: float, buses, motors) -> str:
    """GridPACK's input XML: files named relative to the XML, observed bus voltages, the
    ACMTBLU1 motors (bus, load id) in the load watch."""
    if version not in RAW_TAGS:
        raise ValueError(f"{raw}: RAW version {version}: GridPACK reads versions "
                         f"{sorted(RAW_TAGS)}")
    tag = RAW_TAGS[version]
    observe = "".join(f"<observation><type>bus</type><busID>{b}</busID></observation>"
                      for b in buses)
    watch = "".join(f"<load><busID>{b}</busID><loadID>{i}</loadID></load>" for b, i in motors)
    solver = ("<LinearSolver><SolutionTolerance>1.0E-12</SolutionTolerance><ForceSerial>true"
              "</ForceSerial><InitialGuessZero>true</InitialGuessZero><SerialMatrixConstant>"
              "true</SerialMatrixConstant><PETScOptions>-ksp_type preonly -pc_type lu "
              "-pc_factor_mat_solver_type petsc -pc_factor_mat_ordering_type amd</PETScOptions>"
              "</LinearSolver>")
    return f"""<?xml version="1.0" encoding="utf-8"?>
<Configuration>
  <Powerflow>
    <{tag}>{raw}</{tag}>
    <maxIteration>20</maxIteration><tolerance>1.0e-8</tolerance><qlim>0</qlim>
    <LinearSolver><SolutionTolerance>1.0E-11</SolutionTolerance><PETScOptions>-ksp_type
      richardson -pc_type lu -pc_factor_mat_solver_type petsc -ksp_max_it 1</PETScOptions>
    </LinearSolver>
    <UseNonLinear>false</UseNonLinear><UseNewton>false</UseNewton>
  </Powerflow>
  <Dynamic_simulation>
    <generatorParameters>{dyr}</generatorParameters>
    <simulationTime>{t_end:g}</simulationTime>
    <timeStep>{dt:g}</timeStep>
    <Events><faultEvent><beginFault>{fault.start:g}</beginFault><endFault>{fault.end:g}</endFault>
      <faultBranch>{branch[0]} {branch[1]}</faultBranch><timeStep>{dt:g}</timeStep></faultEvent>
    </Events>
    <observations>{observe}</observations>
    <suppressWatchFiles>false</suppressWatchFiles>
    <loadWatch>{watch}</loadWatch>
    <loadWatchFrequency>1</loadWatchFrequency>
    <loadWatchFileName>motor_watch.csv</loadWatchFileName>
    {solver}
  </Dynamic_simulation>
</Configuration>
"""


def run_gridpack(driver: Path, raw: str, dyr: str, fault: Fault, t_end: float, dt: float,
                 buses, heating: str, workdir: Path) -> Run:
    """GridPACK's trajectories of `fault` (GridpackMissing if it fails)."""
    case = read_raw(raw)
    motors = [(r.bus, r.device_id) for r in read_dyr(dyr).by_model("ACMTBLU1")]
    workdir.mkdir(parents=True, exist_ok=True)
    branch, raw_text = fault_branch(case, fault.bus, Path(raw).read_text(errors="replace"))
    (workdir / "case.raw").write_text(raw_text)
    # GridPACK's DYR parser loses the first record of a file that starts with a UTF-8 byte
    # order mark (the PNNL 39-bus DYR does; its bus-30 GENSAL is repeated, perhaps for this)
    (workdir / "case.dyr").write_text(Path(dyr).read_text(encoding="utf-8-sig"))
    version = raw_version(raw)
    (workdir / "input.xml").write_text(gridpack_xml("case.raw", version, "case.dyr", branch, fault,
                                                    t_end, dt, buses, motors))
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    forward = []
    env.pop("ACMOTOR_HEAT_STALLED_ONLY", None)
    if heating == "stalled":
        env["ACMOTOR_HEAT_STALLED_ONLY"] = "1"
        forward = ["-x", "ACMOTOR_HEAT_STALLED_ONLY"]
    command = ["mpirun", "-np", "1", *forward, str(driver), "input.xml", "obs.csv"]
    done = subprocess.run(command, cwd=workdir, env=env, capture_output=True, text=True,
                          timeout=1800)
    (workdir / "gridpack.log").write_text(done.stdout + done.stderr)
    if done.returncode != 0 or not (workdir / "obs.csv").exists():
        tail = "\n".join((done.stdout + done.stderr).splitlines()[-15:])
        raise GridpackMissing(f"GridPACK failed on {workdir / 'input.xml'} "
                              f"(log {workdir / 'gridpack.log'}):\n{tail}")
    return read_gridpack_csv(workdir / "obs.csv", workdir / "motor_watch.csv", dt)


def read_gridpack_csv(observations: Path, motor_watch: Path, dt: float) -> Run:
    """The driver's CSV (a row of t = (k + 1)·dt holds step k's network solution, labelled
    t_k here; the first row is the state before the first step) and its motor watch file."""
    rows = list(csv.reader(observations.open()))
    head = [h.strip() for h in rows[0]]
    data = np.array([[float(x) for x in r] for r in rows[2:]])
    t = np.round(data[:, 0] - dt, 9)
    volts = [k for k, h in enumerate(head) if h.startswith("V_")]
    watch: dict[float, dict[tuple[int, str], float]] = {}
    if motor_watch.exists():
        for line in motor_watch.read_text().splitlines()[1:]:
            fields = [x.strip() for x in line.split(",")]
            record, k = {}, 1
            while k + len(MOTOR_FIELDS) < len(fields):
                bus = int(fields[k])
                for j, name in enumerate(MOTOR_FIELDS):
                    record[(bus, name)] = float(fields[k + 1 + j])
                k += len(MOTOR_FIELDS) + 1
            watch[round(float(fields[0]), 6)] = record
    motor_bus = sorted({b for rec in watch.values() for b, _ in rec})
    first = next(iter(watch.values()), {})

    def series(name):
        out = np.full((len(t), len(motor_bus)), np.nan)
        for i, tk in enumerate(t):
            rec = watch.get(round(float(tk), 6), first if tk < dt / 2 else {})
            out[i] = [rec.get((b, name), np.nan) for b in motor_bus]
        return out

    return Run(t=t, bus_ids=np.array([int(head[k][2:]) for k in volts]), vm=data[:, volts],
               motor_bus=np.array(motor_bus, dtype=int), status_a=series("statusA"),
               status_b=series("statusB"), theta_a=series("thetaA"), theta_b=series("thetaB"),
               p_motor=series("P"), q_motor=series("Q"))


# --------------------------------------------------------------------------- #
# Model-level variants: the same files with some A/C motors kept and CONs changed
# --------------------------------------------------------------------------- #

@dataclasses.dataclass(frozen=True)
class MotorEdit:
    """ACMTBLU1 records to keep (RAW bus numbers; empty: all) and CONs to set on them
    ({name: value}, names as in `jaxgrid.models.acmotor.Acmtblu1.cons`); a dropped motor's
    load stays a static load."""

    keep: tuple[int, ...] = ()
    cons: tuple[tuple[str, float], ...] = ()

    @property
    def empty(self) -> bool:
        return not (self.keep or self.cons)


def edited_dyr(dyr: str, edit: MotorEdit, out: Path) -> str:
    """`dyr` with `edit` applied, written to `out` (returned); `dyr` itself when empty."""
    if edit.empty:
        return dyr
    names = [c.name for c in Acmtblu1.cons]
    unknown = [n for n, _ in edit.cons if n not in names]
    if unknown:
        raise ValueError(f"--motor-cons {unknown}: ACMTBLU1 CONs are {', '.join(names)}")
    lines = Path(dyr).read_text(encoding="utf-8-sig").splitlines()
    records = read_dyr(dyr).by_model("ACMTBLU1")
    missing = sorted(set(edit.keep) - {r.bus for r in records})
    if missing:
        raise ValueError(f"--motors {missing}: {dyr} has no ACMTBLU1 record there")
    drop, kept = set(), []
    for r in records:
        end = next(k for k in range(r.line - 1, len(lines)) if "/" in lines[k])
        drop.update(range(r.line - 1, end + 1))
        if not edit.keep or r.bus in edit.keep:
            cons = list(r.cons)
            for name, value in edit.cons:
                cons[names.index(name)] = value
            values = ", ".join(f"{v:g}" for v in (*r.header, *r.icons, *cons))
            kept.append(f"{r.bus}, 'USRLOD', {r.device_id}, 'ACMTBLU1', {values} /")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join([x for k, x in enumerate(lines) if k not in drop] + kept) + "\n")
    return str(out)


# --------------------------------------------------------------------------- #
# jaxgrid on the same inputs
# --------------------------------------------------------------------------- #

def jaxgrid_model(raw: str, dyr: str, heating: str, contactor: str = "memory") -> GridModel:
    """The compiled model of the files with the default options but the A/C motors'
    `heating` and `contactor` rules, from a power flow without generator Q limits, as
    GridPACK's (`Q_LIMITS`)."""
    options = CompileOptions(motors=MotorOptions(heating=heating, contactor=contactor))
    case = read_raw(raw)
    pf = solve(case, PowerFlowOptions(enforce_q_limits=False))
    return compile_model(case, read_dyr(dyr), options, pf)


def run_jaxgrid(model: GridModel, faults: list[Fault], t_end: float, dt: float,
                buses, decimation: int = 1) -> list[Run]:
    """jaxgrid's trajectories of `faults` (one vmapped batch), sampled every `decimation`
    steps of dt s."""
    tasks = stack_tasks([make_task(model, FaultEvent(f.bus, f.start, f.duration, 0.0, FAULT_X))
                         for f in faults])
    traj = simulate_batch(model, tasks, t_end, dt, decimation)
    columns = [model.bus_numbers.index(b) for b in buses]
    groups = [(g, k) for g in model.loads if g.model.name == "ACMTBLU1"
              for k in range(len(g.index))]
    motor_bus = np.array([model.bus_numbers[model.load_bus[g.index[k]]] for g, k in groups])
    runs = []
    vm_all = np.asarray(traj.vm)
    for i in range(len(faults)):
        flags = []
        for g, k in groups:
            z = {name: np.asarray(a)[i][:, k]
                 for name, a in traj.load_flags[model.loads.index(g)].items()}
            p = {name: np.asarray(a)[k] if np.ndim(a) else np.asarray(a)
                 for name, a in g.params.items()}
            s = motor_power(p, z, vm_all[i][:, model.load_bus[g.index[k]]], np)
            flags.append(dict(z, p_motor=s.real, q_motor=s.imag))

        def stack(name):
            return np.stack([f[name] for f in flags], axis=1) if flags else np.zeros(
                (traj.t.shape[-1], 0))

        runs.append(Run(t=np.asarray(traj.t)[i], bus_ids=np.asarray(buses),
                        vm=np.asarray(traj.vm)[i][:, columns], motor_bus=motor_bus,
                        status_a=stack("run_a"), status_b=stack("run_b"),
                        theta_a=stack("theta_a"), theta_b=stack("theta_b"),
                        p_motor=stack("p_motor"), q_motor=stack("q_motor")))
    return runs


# --------------------------------------------------------------------------- #
# Comparison
# --------------------------------------------------------------------------- #

def time_below(t: np.ndarray, v: np.ndarray, level: float, after: float) -> float:
    """Seconds (sample count × step) that v (n_t,) spends below `level` p.u. from `after` s."""
    keep = t >= after - 1e-9
    return float(np.sum(v[keep] < level) * (t[1] - t[0]))


def _events(t, flag, falling: bool) -> list[float]:
    """Times (s) at which a 0/1 flag (n_t,) falls (running -> stalled) or rises."""
    flag = np.nan_to_num(flag, nan=1.0) > 0.5
    change = flag[:-1] & ~flag[1:] if falling else ~flag[:-1] & flag[1:]
    return [round(float(x), 4) for x in t[1:][change]]


def _trip_start(t, theta, status, th1t) -> float | None:
    """First time (s) a stalled part's temperature exceeds Th1t (thermal tripping starts)."""
    hot = (theta > th1t) & (np.nan_to_num(status, nan=1.0) < 0.5)
    return round(float(t[np.argmax(hot)]), 4) if hot.any() else None


def compare(ref: Run, ours: Run, fault: Fault, th1t: dict[int, float]) -> dict:
    """Per bus {rms, max_abs (p.u., after clearing), below_0.9/0.8 (s, ref and ours)}; per
    motor bus the RMS of its P and Q after clearing (p.u. motor base) and the stall,
    restart and thermal-trip times (s) in both; ours is interpolated onto ref's samples."""
    after = ref.t >= fault.end - 1e-9
    buses = {}
    for b in ref.bus_ids:
        if b not in ours.bus_ids:
            continue
        v_ref = ref.voltage(int(b))
        v_ours = np.interp(ref.t, ours.t, ours.voltage(int(b)))
        diff = (v_ours - v_ref)[after]
        row = {"rms": float(np.sqrt(np.mean(diff ** 2))), "max_abs": float(np.max(np.abs(diff)))}
        for level in LEVELS:
            row[f"below_{level}"] = [time_below(ref.t, v_ref, level, fault.end),
                                     time_below(ref.t, v_ours, level, fault.end)]
        buses[int(b)] = row
    motors = {}
    for m, b in enumerate(ref.motor_bus):
        if b not in ours.motor_bus:
            continue
        n = list(ours.motor_bus).index(b)
        sides = [(ref, m), (ours, n)]
        power = {}
        for axis in ("p", "q"):
            ref_s = getattr(ref, f"{axis}_motor")[:, m]
            ours_s = np.interp(ref.t, ours.t, getattr(ours, f"{axis}_motor")[:, n])
            power[f"{axis}_rms"] = float(np.sqrt(np.nanmean((ours_s - ref_s)[after] ** 2)))
        motors[int(b)] = {
            **power,
            "stall": [_events(r.t, r.status_a[:, k], True)[:1] for r, k in sides],
            "restart": [_events(r.t, r.status_b[:, k], False) for r, k in sides],
            "trip_a": [_trip_start(r.t, r.theta_a[:, k], r.status_a[:, k], th1t[int(b)])
                       for r, k in sides]}
    return {"fault": dataclasses.asdict(fault), "buses": buses, "motors": motors}


def worst(result: dict) -> tuple[float, float]:
    """(largest RMS, largest |time below 0.9 difference|) over the buses of a comparison."""
    rows = result["buses"].values()
    return (max(r["rms"] for r in rows),
            max(abs(r["below_0.9"][1] - r["below_0.9"][0]) for r in rows))


# --------------------------------------------------------------------------- #
# References kept in the repository
# --------------------------------------------------------------------------- #

@dataclasses.dataclass(frozen=True)
class Setup:
    """What both simulators run, besides the fault: files (paths as given), horizon and step
    (s), A/C motor heating (both) and edit, and jaxgrid's contactor rule (GridPACK has
    its own)."""

    raw: str
    dyr: str
    t_end: float = 10.0
    dt: float = 0.005
    heating: str = "stalled"
    edit: MotorEdit = MotorEdit()
    contactor: str = "memory"

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Setup:
        edit = d.get("edit") or {}
        return cls(**dict(d, edit=MotorEdit(tuple(edit.get("keep", ())),
                                            tuple(tuple(c) for c in edit.get("cons", ())))))


def save_reference(path: Path, run: Run, fault: Fault, setup: Setup, command: str,
                   every: int = 2) -> None:
    """GridPACK's `run` as a compressed npz (float32, every `every`-th sample) with what made
    it: setup, fault, command and GridPACK's source commit."""
    meta = dict(setup=setup.to_json(), fault=dataclasses.asdict(fault), command=command,
                gridpack=GRIDPACK_COMMIT)
    arrays = {f.name: getattr(run, f.name) for f in dataclasses.fields(Run)}
    for name in ("vm", "theta_a", "theta_b", "p_motor", "q_motor"):
        arrays[name] = arrays[name][::every].astype(np.float32)
    arrays["t"] = arrays["t"][::every]
    for name in ("status_a", "status_b"):
        arrays[name] = np.nan_to_num(arrays[name][::every], nan=1.0).astype(np.int8)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, meta=json.dumps(meta), **arrays)


def load_reference(path: str | Path) -> tuple[Run, Fault, Setup]:
    """(GridPACK's Run, fault, setup) of a file written by `save_reference`."""
    with np.load(path) as f:
        meta = json.loads(str(f["meta"]))
        run = Run(**{k: np.asarray(f[k], dtype=float) for k in
                     (fl.name for fl in dataclasses.fields(Run))})
    run = dataclasses.replace(run, bus_ids=run.bus_ids.astype(int),
                              motor_bus=run.motor_bus.astype(int))
    return run, Fault(**meta["fault"]), Setup.from_json(meta["setup"])


def motor_th1t(model: GridModel) -> dict[int, float]:
    """Th1t (p.u.) of each ACMTBLU1 motor by RAW bus number."""
    return {model.bus_numbers[model.load_bus[slot]]: float(np.asarray(g.params["th1t"])[k])
            for g in model.loads if g.model.name == "ACMTBLU1" for k, slot in enumerate(g.index)}


def against(setup: Setup, cases: list[tuple[Fault, Run]], workdir: Path,
            model: GridModel | None = None, t_end: float | None = None) -> list[dict]:
    """[(`compare` dict, jaxgrid's Run)] of jaxgrid (one batch of the faults, sampled as the
    references) against each reference Run, up to t_end (s; default the setup's); jaxgrid's
    model compiled from the setup's files with the default options, unless given."""
    if model is None:
        dyr = edited_dyr(setup.dyr, setup.edit, workdir / "edited.dyr")
        model = jaxgrid_model(setup.raw, dyr, setup.heating, setup.contactor)
    t_end = setup.t_end if t_end is None else t_end
    cases = [(fault, ref.until(t_end)) for fault, ref in cases]
    buses = sorted({int(b) for _, ref in cases for b in ref.bus_ids} & set(model.bus_numbers))
    step = cases[0][1].t[1] - cases[0][1].t[0]
    ours = run_jaxgrid(model, [fault for fault, _ in cases], t_end, setup.dt, buses,
                       max(1, round(step / setup.dt)))
    th1t = motor_th1t(model)
    return [(compare(ref, run, fault, th1t), run) for (fault, ref), run in zip(cases, ours)]


# --------------------------------------------------------------------------- #
# Command
# --------------------------------------------------------------------------- #

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


def _edit(args) -> MotorEdit:
    cons = []
    for text in args.motor_cons:
        name, _, value = text.partition("=")
        try:
            cons.append((name.strip().lower(), float(value)))
        except ValueError:
            raise ValueError(f"--motor-cons {text!r}: expected NAME=VALUE") from None
    return MotorEdit(tuple(args.motors), tuple(cons))


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


def plot(path: Path, fault: Fault, ref: Run, ours: Run) -> None:
    """Bus voltages of both simulators for one fault (GridPACK solid, jaxgrid dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k, bus in enumerate(ref.bus_ids):
        if bus in ours.bus_ids:
            color = f"C{k % 10}"
            ax.plot(ref.t, ref.voltage(int(bus)), color=color, label=f"bus {bus} GridPACK")
            ax.plot(ours.t, ours.voltage(int(bus)), color=color, ls="--",
                    label=f"bus {bus} jaxgrid")
    ax.axhline(0.9, color="grey", lw=0.6)
    ax.set(xlabel="t (s)", ylabel="|V| (p.u.)", ylim=(0.0, 1.15),
           title=f"bolted fault at bus {fault.bus}, {fault.start:g}-{fault.end:g} s")
    ax.legend(ncol=2, fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


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
                  args.contactor)
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
    motors = sorted({r.bus for r in read_dyr(dyr).by_model("ACMTBLU1")})
    cases = []
    for fault in faults:
        buses = args.buses or sorted({fault.bus, *motors})
        ref = run_gridpack(driver, setup.raw, dyr, fault, setup.t_end, setup.dt, buses,
                           setup.heating, tmp / fault.name)
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
