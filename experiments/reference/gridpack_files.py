"""GridPACK's side of the reference: its XML input, the run of its `dsf_obs.x` driver, its CSV
output and the reference files kept in the repository (`save_reference`, `load_reference`);
the DYR side (model-level variants, GridPACK's DYR, composite-load buses) is
`experiments.reference.gridpack_dyr`. The driver is the one of ../shared/reference/gridpack
(found with --gridpack, DSF_OBS or GRIDPACK_HOME; one MPI process), with this project's
patches applied for composite loads (`gridpack_patches/`, README there); the command is
`experiments.reference.gridpack`.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

from experiments.reference.gridpack_dyr import MotorEdit, composite_buses, gridpack_dyr
from experiments.reference.gridpack_raw import raw33
from jaxgrid.case import Case
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import raw_version, read_raw
from jaxgrid.models.options import MotorOptions

FAULT_X = 1e-9  # p.u.: GridPACK's faultEvent puts −j1e9 on the faulted bus's diagonal
GRIDPACK_COMMIT = "bea5ce1"  # the kit's source snapshot (../shared/reference/gridpack)
DRIVER = "build/applications/dynamic_simulation_full_y/dsf_obs.x"  # under GRIDPACK_HOME
RAW_TAGS = {23: "networkConfiguration", 33: "networkConfiguration_v33"}  # GridPACK's readers
MOTOR_FIELDS = ("Vmeas", "statusA", "statusB", "P", "Q", "thetaA", "thetaB")  # load watch
PATCHES = "experiments/reference/gridpack_patches"  # this project's patches (README there)
PATCH_MARK = b"jaxgrid cmld.patch 1"  # in a driver built with gridpack_patches/cmld.patch
# MOTORW, GridPACK's motors A-C of a composite load: "gridpack" runs it as published,
# "wecc" with the patch's switches that make it the WECC description's motor (README there)
MOTORW = {"gridpack": (), "wecc": ("MOTORW_SWING_TORQUE", "MOTORW_LOAD_TORQUE_RATIO",
                                   "MOTORW_NOMINAL_FREQ")}
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


def run_gridpack(driver: Path, setup: Setup, dyr: str, fault: Fault, buses,
                 workdir: Path) -> Run:
    """GridPACK's trajectories of `fault` on `setup`'s RAW and `dyr` (GridpackMissing if it
    fails). `buses` and the Run's bus numbers are jaxgrid's, composite loads' internal buses
    included (`gridpack_dyr.composite_buses`); each composite load's motor D is watched
    with the A/C motors, under its load-bus number."""
    workdir.mkdir(parents=True, exist_ok=True)
    raw, version = setup.raw, raw_version(setup.raw)
    if version not in RAW_TAGS:  # e.g. the PNNL 300-bus v30: written as v33
        raw, version = str(workdir / "case_v33.raw"), 33
        Path(raw).write_text(raw33(read_raw(setup.raw)))
    case = read_raw(raw)
    composites = composite_buses(case, dyr)
    if composites:
        require_cmld_patch(driver)
    to_gridpack = {c.load: c.gridpack_load for c in composites}
    to_gridpack.update({c.low: c.gridpack_low for c in composites})
    motors = [(r.bus, r.device_id) for r in read_dyr(dyr).by_model("ACMTBLU1")]
    motors += [(c.gridpack_load, "D") for c in composites if c.fmd > 0]
    branch, raw_text = fault_branch(case, fault.bus, Path(raw).read_text(errors="replace"))
    (workdir / "case.raw").write_text(raw_text)
    gridpack_dyr(dyr, workdir / "case.dyr")
    observed = [to_gridpack.get(b, b) for b in buses]
    (workdir / "input.xml").write_text(gridpack_xml(
        "case.raw", version, "case.dyr", branch, fault, setup.t_end, setup.dt,
        observed, motors))
    switches = (("ACMOTOR_HEAT_STALLED_ONLY",) if setup.heating == "stalled" else ()) \
        + MOTORW[setup.motorw]
    env = {k: v for k, v in os.environ.items() if k not in SWITCHES}
    env.update({name: "1" for name in switches}, OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    forward = [a for name in switches for a in ("-x", name)]
    command = ["mpirun", "-np", "1", *forward, str(driver), "input.xml", "obs.csv"]
    done = subprocess.run(command, cwd=workdir, env=env, capture_output=True, text=True,
                          timeout=1800)
    (workdir / "gridpack.log").write_text(done.stdout + done.stderr)
    if done.returncode != 0 or not (workdir / "obs.csv").exists():
        tail = "\n".join((done.stdout + done.stderr).splitlines()[-15:])
        raise GridpackMissing(f"GridPACK failed on {workdir / 'input.xml'} "
                              f"(log {workdir / 'gridpack.log'}):\n{tail}")
    run = read_gridpack_csv(workdir / "obs.csv", workdir / "motor_watch.csv", setup.dt)
    to_ours = {g: b for b, g in to_gridpack.items()}
    return dataclasses.replace(
        run, bus_ids=np.array([to_ours.get(int(b), int(b)) for b in run.bus_ids]),
        motor_bus=np.array([to_ours.get(int(b), int(b)) for b in run.motor_bus], dtype=int))


def require_cmld_patch(driver: Path) -> None:
    """GridpackMissing unless `driver` was built with this project's composite-load patch."""
    if PATCH_MARK not in Path(driver).read_bytes():
        raise GridpackMissing(
            f"{driver} lacks {PATCHES}/cmld.patch, which GridPACK's composite load needs "
            f"(as published it does not start at rest): apply it with {PATCHES}/apply.sh")


def read_gridpack_csv(observations: Path, motor_watch: Path, dt: float) -> Run:
    """The driver's CSV (a row of t = (k + 1)·dt holds step k's network solution, labelled
    t_k here; the first row is the state before the first step) and its motor watch file
    (the A/C motors' lines; a composite's MOTORW lines, patched in, are left out)."""
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
                if float(fields[k + 2]) >= 0:  # statusA -1: a composite's induction motor
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
# References kept in the repository
# --------------------------------------------------------------------------- #

SWITCHES = ("ACMOTOR_HEAT_STALLED_ONLY",) + MOTORW["wecc"]  # GridPACK's switches, all


@dataclasses.dataclass(frozen=True)
class Setup:
    """What both simulators run, besides the fault: files (paths as given), horizon and step
    (s), A/C motor heating (both) and edit, jaxgrid's contactor rule (GridPACK has its own)
    and `MotorOptions.stiff_below` (s; GridPACK integrates every cage), GridPACK's MOTORW
    reading (`MOTORW`) and jaxgrid's `CompositeOptions` changes ((name, value) pairs)."""

    raw: str
    dyr: str
    t_end: float = 10.0
    dt: float = 0.005
    heating: str = "stalled"
    edit: MotorEdit = MotorEdit()
    contactor: str = "memory"
    stiff_below: float = MotorOptions().stiff_below
    motorw: str = "gridpack"
    composite: tuple[tuple[str, object], ...] = ()

    def __post_init__(self):
        if self.motorw not in MOTORW:
            raise ValueError(f"motorw = {self.motorw!r}: allowed {', '.join(MOTORW)}")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> Setup:
        return cls(**dict(d, edit=MotorEdit.from_json(d.get("edit") or {}),
                          composite=tuple(tuple(c) for c in d.get("composite", ()))))


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
