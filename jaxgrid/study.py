"""A load-shedding study as one value: operating points, buses, reward, steps and task sets.

    study = load_study("ieee39_fidvr")                  # built-in, load levels as points
    study = load_study("studies/ieee39_pnnl.toml")      # the project's study file
    study = from_files(["a.raw", "b.raw"], "x.dyr", "task.json", "sim.json")
    env, grid = study.env(), study.point(0)
    write_study(study, "run/study.toml")                # a run folder alone reproduces it

A `Study` holds its `StudyDefinition` (everything that rebuilds it, serialisable to TOML),
the operating points (solved cases of one grid) and their compiled models stacked into
one `GridModel` pytree with a leading operating-point axis (`models`). That pytree is data:
it is passed to compiled functions as an argument (`jaxgrid.rollouts.at_point` selects a
point inside jit), so one compilation serves every operating point of the grid.

Built three ways:
  built-in: `jaxgrid.cases` FIDVR study cases ("ieee39_fidvr", "ieee300_fidvr") at one or
    more load levels; buses, step, reward values and task sets are the case's.
  from files: RAW files (the operating points; one grid, so bus, branch, load and machine
    structure must agree), one DYR, optionally a PNNL task JSON (buses, reward, history,
    training faults: `jaxgrid.io.pnnl`) and a PNNL simulation JSON (step, episode length).
  study file (TOML, `read_study`): names the built-in or the files (paths relative to the
    file, RAW paths may be glob patterns) and overrides any field of the definition:

        name = "ieee39_pnnl"
        [grid]      builtin, load_levels | raw, dyr, task_config, sim_config
        [compile]   strict, precision, sweeps, [compile.motors], [compile.loads]
        [env]       jaxgrid.env.EnvConfig fields (observed_buses, action_buses, dt, agent_dt,
                    episode, history, include_action_status, recovery_buses, [env.bounds])
        [params]    jaxgrid.env.EnvParams fields (reward weights, action range, recovery)
        [tasks.NAME] jaxgrid.tasks.TaskSet fields (fault_buses, fault_durations,
                    fault_starts, operating_points, fault_r, fault_x)
        [training]  TrainingSettings fields (history = {lstm = 1, ...}, task_sampling)

`write_study` writes the resolved definition, every field explicit and paths absolute;
reading it back gives the identical definition.
"""
from __future__ import annotations

import contextlib
import dataclasses
import glob
import re
import tomllib
import warnings
from pathlib import Path

import jax
import numpy as np
import tomli_w

from jaxgrid import cases
from jaxgrid.case import Case
from jaxgrid.checks import InputError, Range, check_each
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.env import EnvConfig, EnvParams, LoadSheddingEnv, check_params
from jaxgrid.grid import GridModel
from jaxgrid.io import pnnl
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.models.acmotor import MotorOptions
from jaxgrid.models.cmld import COMPOSITE_LOADS, CompositeOptions
from jaxgrid.models.cmld_init import internal_buses
from jaxgrid.models.loads import LoadSplit
from jaxgrid.powerflow import bus_loads
from jaxgrid.simulate import Bounds
from jaxgrid.tasks import PointTask, TaskSet, TaskSpec, task_batch


class StudyWarning(UserWarning):
    """A study input that is read but changes nothing, or a check that does not match."""


@dataclasses.dataclass(frozen=True)
class GridSource:
    """Where the operating points come from: a built-in case or files (absolute paths).

    Attributes:
      builtin: a `jaxgrid.cases` FIDVR study case name, or None.
      load_levels: the built-in's operating points (factor on loads and dispatch).
      raw: RAW files, one per operating point.  dyr: the DYR file.
      task_config, sim_config: PNNL task and simulation JSON files, or None.
    """

    builtin: str | None = None
    load_levels: tuple[float, ...] = (1.0,)
    raw: tuple[str, ...] = ()
    dyr: str | None = None
    task_config: str | None = None
    sim_config: str | None = None

    def __post_init__(self):
        if not self.load_levels:
            raise InputError("load_levels", None, " is empty: give at least one load level")
        check_each("load_levels", self.load_levels, LOAD_LEVEL)


LOAD_LEVEL = Range(0.0, 10.0, "(factor on loads and dispatch)", lo_open=True)


FILE_SWEEPS = 2  # network sweeps of a study from files (its step's accuracy is not measured)


@dataclasses.dataclass(frozen=True)
class CompileSettings:
    """How every operating point is compiled (`jaxgrid.compile.CompileOptions`; the action
    buses become the load slots). sweeps None: the source's (a built-in study's measured
    value, `FILE_SWEEPS` for files); a built study's definition holds the value used."""

    strict: bool = True
    precision: str = "float32"
    sweeps: int | None = None
    motors: MotorOptions = MotorOptions()
    loads: LoadSplit = LoadSplit()
    composite: CompositeOptions = CompositeOptions()


POLICY_KINDS = ("linear", "fnn", "lstm")
# The PARS study's inputs per policy kind: 10 stacked observations for linear and FNN
# policies, the current one for the LSTM (it remembers the rest); built-in studies train so.
PAPER_HISTORY = {"linear": 10, "fnn": 10, "lstm": 1}
TASK_SAMPLINGS = ("uniform", "stratified")


@dataclasses.dataclass(frozen=True)
class TrainingSettings:
    """How the study's policies train where the study fixes it (`experiments.train` takes
    these as its flag defaults).

    Attributes:
      history: {policy kind: observations stacked}; a kind not named stacks env.history.
      task_sampling: "uniform" (m distinct tasks) or "stratified" (`jaxgrid.rollouts.stratified_sampler`).
    """

    history: dict = dataclasses.field(default_factory=dict)
    task_sampling: str = "uniform"

    def __post_init__(self):
        bad = {k: v for k, v in self.history.items()
               if k not in POLICY_KINDS or isinstance(v, bool) or not isinstance(v, int)
               or v < 1}
        if bad:
            raise ValueError(f"training.history {bad}: keys from {list(POLICY_KINDS)}, values "
                             "ints >= 1")
        if self.task_sampling not in TASK_SAMPLINGS:
            raise ValueError(f"training.task_sampling = {self.task_sampling!r}: allowed "
                             f"{list(TASK_SAMPLINGS)}")


@dataclasses.dataclass(frozen=True)
class StudyDefinition:
    """Everything that rebuilds a study (what `write_study` saves).

    Attributes:
      name: the study's name.  grid: its sources.  compile: compile settings.
      env: the environment's structure.  params: reward and action values.
      tasks: named task sets ("train", "test", ...).  training: TrainingSettings.
    """

    name: str
    grid: GridSource
    compile: CompileSettings
    env: EnvConfig
    params: EnvParams
    tasks: dict
    training: TrainingSettings = TrainingSettings()


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """One solved case of the study's grid.

    Attributes:
      label: short name ("load100", a RAW file's stem).  source: where it came from.
      case: the network.  notes: what the compiler reported for it (load report, ...).
    """

    label: str
    source: str
    case: Case
    notes: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class BusTable:
    """The buses a study file can name, before compiling: the RAW buses and the composite
    loads' internal buses (`jaxgrid.models.cmld_init.internal_buses`).

    Attributes:
      source: the case.  number: {lower-case name: bus number} ("bus504",
        "bus20_loadbus").  zone, base_kv, loaded: per bus number (loaded: an in-service
        RAW load, the composite loads' load buses).
    """

    source: str
    number: dict
    zone: dict
    base_kv: dict
    loaded: dict


@dataclasses.dataclass(frozen=True)
class Study:
    """A load-shedding study (module docstring).

    Attributes:
      definition: what rebuilds it.  points: the operating points.
      models: the compiled points stacked, every array leaf with a leading (n_points,) axis.
      buses: the names study files can use for its buses (`bus_number`).
      notes: what the readers and checks reported (unused keys, count mismatches, ...).
    """

    definition: StudyDefinition
    points: tuple[OperatingPoint, ...]
    models: GridModel
    buses: BusTable
    notes: tuple[str, ...]

    @property
    def name(self) -> str:
        return self.definition.name

    @property
    def config(self) -> EnvConfig:
        return self.definition.env

    @property
    def params(self) -> EnvParams:
        return self.definition.params

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def base_mva(self) -> float:
        return self.points[0].case.base_mva

    def point(self, index: int) -> GridModel:
        """The compiled model of operating point `index` (host arrays)."""
        return jax.tree.map(lambda a: a[index], self.models)

    def history(self, policy_kind: str) -> int:
        """Observations a `policy_kind` policy stacks in this study's training."""
        return self.definition.training.history.get(policy_kind, self.config.history)

    def env(self, **config) -> LoadSheddingEnv:
        """The environment; `config` overrides EnvConfig fields, e.g. episode=6.0 (s)."""
        return LoadSheddingEnv(self.point(0), dataclasses.replace(self.config, **config))

    def task_set(self, name: str) -> TaskSet:
        """The named task set; ValueError listing the study's sets."""
        if name not in self.definition.tasks:
            raise ValueError(f"study {self.name!r} has no task set {name!r}; it has "
                             f"{', '.join(sorted(self.definition.tasks)) or 'none'}")
        return self.definition.tasks[name]

    def tasks(self, name: str) -> list[TaskSpec]:
        """The specs of the named task set (every operating point × fault × duration)."""
        return self.task_set(name).specs(self.n_points)

    def batch(self, specs) -> PointTask:
        """Stacked PointTask of specs (any operating points of this study)."""
        return task_batch(self.point(0), specs)


# --------------------------------------------------------------------------- #
# Building
# --------------------------------------------------------------------------- #

def load_study(spec: str) -> Study:
    """A built-in study by name, or a study TOML file."""
    if spec in cases.names():
        return builtin(spec)
    if spec.endswith(".toml") or Path(spec).is_file():
        return read_study(spec)
    studies = [n for n in cases.names() if n.endswith("_fidvr")]
    raise ValueError(f"study {spec!r}: neither a built-in study ({', '.join(studies)}) nor a "
                     "study file (.toml)")


def builtin(case: str, load_levels=(1.0,), **overrides) -> Study:
    """The built-in FIDVR study `case` at `load_levels` (operating points); `overrides` as
    `build` (name, compile, env, params, tasks)."""
    return build(GridSource(builtin=case, load_levels=tuple(float(x) for x in load_levels)),
                 **overrides)


def from_files(raw, dyr, task_config=None, sim_config=None, **overrides) -> Study:
    """A study from RAW files (operating points), a DYR and PNNL JSON files."""
    raw = [raw] if isinstance(raw, (str, Path)) else list(raw)
    return build(GridSource(raw=tuple(str(Path(r).resolve()) for r in raw),
                            dyr=str(Path(dyr).resolve()),
                            task_config=task_config and str(Path(task_config).resolve()),
                            sim_config=sim_config and str(Path(sim_config).resolve())),
                 **overrides)


def rebuild(study: Study, **compile_changes) -> Study:
    """`study` built again from its definition with CompileSettings fields changed, e.g.
    precision="float64", sweeps=4 (a reference model for accuracy checks)."""
    d = study.definition

    def fields(value) -> dict:
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}

    return build(d.grid, name=d.name, compile=dataclasses.replace(d.compile, **compile_changes),
                 env=fields(d.env), params=fields(d.params),
                 tasks={k: fields(v) for k, v in d.tasks.items()}, training=fields(d.training))


@contextlib.contextmanager
def _named(name):
    """Re-raise an InputError from inside under the key as the user wrote it, name(key)."""
    try:
        yield
    except InputError as err:
        raise err.renamed(name(err.key)) from None


def build(grid: GridSource, name: str | None = None,
          compile: CompileSettings = CompileSettings(), env: dict | None = None,
          params: dict | None = None, tasks: dict | None = None,
          training: dict | None = None, origin: str = "study") -> Study:
    """The study of `grid` with overrides of the source's env, params, task sets and
    training settings.

    env, params, training: {field: value}; tasks: {set name: {TaskSet field: value}} (a new
    name adds a set, fault buses and durations then required). A bad value raises an
    InputError naming it as written: "ORIGIN: env.dt" for an override (origin: the study
    file), the PNNL file and key for a value read from one.
    """
    notes: list[str] = []
    if grid.builtin:
        with _named(lambda key: f"{origin}: {key}"):
            points, dyr, defaults = _builtin_points(grid)
    elif grid.raw:
        points, dyr, defaults = _file_points(grid, notes)
    else:
        raise ValueError("a study needs [grid] builtin = NAME, or raw = [files] and dyr = FILE")
    written = defaults.get("written", {})

    def key_of(section: str, given: dict | None):
        """name(key) of a field of `section` ("env", "tasks.train"); `given`: the overrides."""
        def name(key: str) -> str:
            field, bracket, index = key.partition("[")
            where = written.get(f"{section}.{field}")
            if field in (given or {}) or where is None:
                where = f"{origin}: {section}.{field}"
            return where + bracket + index
        return name

    env_values = {**defaults["env"], **(env or {})}
    for key in ("observed_buses", "action_buses"):
        if key not in env_values:
            raise ValueError(f"{origin}: no {key}: give a task_config or [env] {key}")
    env_values["action_buses"] = tuple(env_values["action_buses"])
    env_key = key_of("env", env)
    with _named(env_key):
        config = EnvConfig(**env_values)
    buses = defaults.get("buses") or bus_table(points[0][2], dyr)
    for b in config.action_buses:
        if not buses.loaded.get(b, False):
            raise InputError(env_key("action_buses"), list(config.action_buses),
                             f"bus {b} " + ("carries no load" if b in buses.loaded
                                            else "is not in the case"))
    param_values = {**defaults["params"], **(params or {})}
    check_params(param_values, key_of("params", params))
    compile = dataclasses.replace(compile, sweeps=compile.sweeps or defaults["sweeps"])
    options = CompileOptions(strict=compile.strict, loads=compile.loads,
                             load_buses=env_values["action_buses"], motors=compile.motors,
                             composite=compile.composite, precision=compile.precision,
                             sweeps=compile.sweeps)
    models = [compile_model(c, dyr, options) for _, _, c in points]
    stacked = stack_models(models, [source for _, source, _ in points])
    for key in ("observed_buses", "recovery_buses"):
        _check_buses(getattr(config, key) or (), models[0], env_key(key))
    task_sets = {}
    for set_name in sorted(set(defaults["tasks"]) | set(tasks or {})):
        given = (tasks or {}).get(set_name, {})
        values = {**defaults["tasks"].get(set_name, {}), **given}
        missing = {"fault_buses", "fault_durations"} - set(values)
        if missing:
            raise ValueError(f"{origin}: tasks.{set_name} needs {sorted(missing)}")
        task_key = key_of(f"tasks.{set_name}", given)
        with _named(task_key):
            task_sets[set_name] = TaskSet(**values)
        _check_buses(task_sets[set_name].fault_buses, models[0], task_key("fault_buses"))
        for i, start in enumerate(task_sets[set_name].fault_starts):
            if start >= config.episode:
                raise InputError(task_key(f"fault_starts[{i}]"), start, "the fault must start "
                                 f"inside the episode (episode = {config.episode:g} s)")
        task_sets[set_name].points(len(points))
    definition = StudyDefinition(
        name=name or defaults["name"], grid=grid, compile=compile, env=config,
        params=EnvParams(**param_values), tasks=task_sets,
        training=TrainingSettings(**{**defaults.get("training", {}), **(training or {})}))
    if defaults.get("pnnl_task"):
        notes.extend(_pnnl_checks(defaults["pnnl_task"], config, buses, models[0],
                                  points[0][2].base_mva))
    if notes:
        warnings.warn(f"study {definition.name!r}: {len(notes)} note(s), in Study.notes: "
                      + "; ".join(notes), StudyWarning, stacklevel=2)
    ops = tuple(OperatingPoint(label, source, c, m.notes)
                for (label, source, c), m in zip(points, models))
    return Study(definition=definition, points=ops, models=stacked, buses=buses,
                 notes=tuple(notes))


def _builtin_points(grid: GridSource):
    studies = [n for n in cases.names() if n.endswith("_fidvr")]
    if grid.builtin not in studies:
        what = "a network without dynamic data" if grid.builtin in cases.names() else \
            "not a built-in case"
        raise InputError("grid.builtin", grid.builtin, f"{what}; study cases: "
                         + ", ".join(studies))
    made = [cases.load(grid.builtin, load_level=level) for level in grid.load_levels]
    first = made[0]
    points = [(f"load{100 * s.load_level:g}", f"jaxgrid.cases.{grid.builtin}"
               f"(load_level={s.load_level:g})", s.case) for s in made]
    defaults = {
        "name": grid.builtin,
        "env": {"observed_buses": first.observed_buses, "action_buses": first.action_buses,
                "dt": first.dt},
        "params": dict(first.reward), "sweeps": first.sweeps,
        "training": {"history": dict(PAPER_HISTORY)},
        "tasks": {k: {"fault_buses": tuple(b), "fault_durations": tuple(d)}
                  for k, (b, d) in first.task_sets.items()}}
    # machine data and MBASE are those of level 1 at every level: one DYR serves all points
    return points, first.dyr, defaults


def _file_points(grid: GridSource, notes: list[str]):
    if not grid.dyr:
        raise ValueError("study: [grid] raw needs dyr = FILE")
    points, stems = [], {}
    for path in grid.raw:
        stem = Path(path).stem
        stems[stem] = stems.get(stem, 0) + 1
        label = stem if stems[stem] == 1 else f"{stem}#{stems[stem]}"
        points.append((label, path, read_raw(path)))
    _, first_path, first = points[0]
    for _, path, case in points[1:]:
        difference = structure_difference(first, case)
        if difference:
            raise ValueError(f"{path} and {first_path} are not one grid: {difference}")
    defaults = {"name": Path(grid.task_config or grid.raw[0]).stem, "env": {}, "params": {},
                "tasks": {}, "sweeps": FILE_SWEEPS, "written": {}}
    dyr = read_dyr(grid.dyr)
    if grid.task_config:
        buses = bus_table(points[0][2], dyr)
        task = pnnl.read_task_config(grid.task_config)
        notes.extend(f"{task.source}: {n}" for n in task.notes)
        notes.extend(f"{task.source}: key {k!r} is not understood and was not used"
                     for k in task.unknown)
        action = _scope(task.action_scope, task.action, buses, task.source, "actionScopeAry")
        observed = _scope(task.observation_scope, task.observed, buses, task.source,
                          "observationScopeAry", min_kv=task.observed_min_kv)
        if task.observation_scope == "Zone":
            observed = observed + tuple(b for b in action if b not in observed)
        fault_buses = tuple(bus_number(n, buses, task.source, "faultBusCandidates")
                            for n in task.fault_buses)
        defaults.update(name=task.name, params=dict(task.params), pnnl_task=task, buses=buses,
                        env={"observed_buses": observed, "action_buses": action,
                             "agent_dt": task.agent_dt, "history": task.history,
                             "include_action_status": task.include_action_status},
                        tasks={"train": {"fault_buses": fault_buses,
                                         "fault_starts": task.fault_starts,
                                         "fault_durations": task.fault_durations}})
        defaults["written"].update({field: f"{task.source}: {key}" for field, key in (
            ("env.observed_buses", "observationScopeAry"), ("env.action_buses", "actionScopeAry"),
            ("env.agent_dt", "envStepTimeInSec"), ("env.history", "historyObservationSize"),
            ("tasks.train.fault_buses", "faultBusCandidates"),
            ("tasks.train.fault_starts", "faultStartTimeCandidates"),
            ("tasks.train.fault_durations", "faultDurationCandidates"))})
    if grid.sim_config:
        sim = pnnl.read_sim_config(grid.sim_config)
        notes.extend(f"{sim.source}: {n}" for n in sim.notes)
        notes.extend(f"{sim.source}: key {k!r} is not understood and was not used"
                     for k in sim.unknown)
        defaults["env"].update(dt=sim.dt, episode=sim.t_end)
        defaults["written"].update({"env.dt": f"{sim.source}: simuTimeStepSec",
                                    "env.episode": f"{sim.source}: totalSimuTimeSec"})
        if sim.fault_r is not None and "train" in defaults["tasks"]:
            defaults["tasks"]["train"].update(fault_r=sim.fault_r, fault_x=sim.fault_x)
    return points, dyr, defaults


def bus_table(case: Case, dyr) -> BusTable:
    """The BusTable of `case` with the composite loads of `dyr`."""
    numbers = [int(n) for n in case.buses.number]
    names = {f"bus{n}": n for n in numbers}
    zone = dict(zip(numbers, (int(z) for z in case.buses.zone)))
    kv = dict(zip(numbers, (float(v) for v in case.buses.base_kv)))
    loaded = dict(zip(numbers, (bool(x) for x in np.abs(sum(bus_loads(case))) > 0)))
    composite = [r for r in dyr.records if r.model in COMPOSITE_LOADS]
    for record, ((low, low_name), (load, load_name)) in zip(
            composite, internal_buses(case, composite)):
        for number, name, base_kv in ((low, low_name, 0.0), (load, load_name, kv[record.bus])):
            names[name.lower()], zone[number], kv[number] = number, zone[record.bus], base_kv
            loaded[number] = number == load
    return BusTable(case.source, names, zone, kv, loaded)


def bus_number(name, buses: BusTable, source: str, key: str) -> int:
    """The number of a PNNL bus reference ("Bus504", "bus20001", "Bus20_loadBus", 504)."""
    text = str(name).strip()
    number = buses.number.get(text.lower())
    if number is not None:
        return number
    if re.fullmatch(r"bus-?\d+_\w+", text, re.IGNORECASE):
        raise ValueError(f"{source}: {key}: {name!r}: the case {buses.source} has no such "
                         "internal bus (no composite load record there in the DYR)")
    match = re.fullmatch(r"(?:bus)?(-?\d+)", text, re.IGNORECASE)
    if not match:
        raise ValueError(f"{source}: {key}: {name!r} is not a bus reference ('Bus<number>' "
                         "or a composite load's 'Bus<number>_loadBus')")
    if int(match.group(1)) in buses.zone:
        return int(match.group(1))
    raise ValueError(f"{source}: {key}: {name!r}: the case {buses.source} has no bus "
                     f"{match.group(1)}")


def _scope(kind: str, entries, buses: BusTable, source: str, key: str, min_kv: float = 0.0):
    """Bus numbers of a "Bus" scope (the names) or a "Zone" scope (observations: the zones'
    buses above min_kv; actions: the zones' buses with a load)."""
    if kind == "Bus":
        return tuple(bus_number(n, buses, source, key) for n in entries)
    zones = []
    for z in entries:
        if not str(z).strip().isdigit() or int(z) not in set(buses.zone.values()):
            raise ValueError(f"{source}: {key}: zone {z!r} is not a zone of {buses.source}")
        zones.append(int(z))
    keep = (lambda b: buses.loaded[b]) if key == "actionScopeAry" else \
        (lambda b: buses.base_kv[b] > min_kv)
    return tuple(b for b, z in buses.zone.items() if z in zones and keep(b))


def _check_buses(buses, model: GridModel, key: str) -> None:
    missing = [b for b in buses if b not in model.bus_numbers]
    if missing:
        raise InputError(key, None, f": buses {missing} are not in the case")


def _pnnl_checks(task: pnnl.PnnlTask, config: EnvConfig, buses: BusTable, model: GridModel,
                 base_mva: float):
    """Notes where the resolved buses or loads differ from the file's own counts."""
    notes = []
    zones = {int(z) for z in task.observed} if task.observation_scope == "Zone" else None
    if zones is not None:
        zone_of, kv_of = buses.zone, buses.base_kv
        inside = [b for b in config.observed_buses if zone_of[b] in zones]
        found = {"ObservationSelfZoneVoltNum": len(inside),
                 "ObservationSelfZoneLowVoltNum": sum(kv_of[b] <= task.observed_min_kv
                                                      for b in inside),
                 "ObservationOtherZoneVoltNum": len(config.observed_buses) - len(inside),
                 "actionLoadSelfZoneNum": sum(zone_of[b] in zones for b in config.action_buses),
                 "actionLoadOtherZoneNum": sum(zone_of[b] not in zones
                                               for b in config.action_buses)}
        notes += [f"{task.source}: {k} = {v}, but the case gives {found[k]}"
                  for k, v in task.counts.items() if found[k] != v]
    if task.action_p_mw is not None:
        slots = [model.load_slot(b) for b in config.action_buses]
        mw = np.asarray(model.load_p0)[slots] * base_mva
        notes += [f"{task.source}: actionBusesPValue: bus {b} {want:g} MW, the case has "
                  f"{have:.2f} MW" for b, want, have in zip(config.action_buses,
                                                             task.action_p_mw, mw)
                  if abs(have - want) > 0.01 * abs(want)]
    return notes


def structure_difference(a: Case, b: Case) -> str | None:
    """The first difference in bus, branch, load or machine structure of two cases, or None."""
    tables = (
        ("buses", lambda c: [int(n) for n in c.buses.number]),
        ("branches (from, to, circuit)", lambda c: list(zip(
            c.buses.number[c.branches.from_bus].tolist(), c.buses.number[c.branches.to_bus]
            .tolist(), c.branches.ckt))),
        ("branch status", lambda c: c.branches.in_service.tolist()),
        ("loads (bus, id, status)", lambda c: list(zip(
            c.buses.number[c.loads.bus].tolist(), c.loads.load_id,
            c.loads.in_service.tolist()))),
        ("machines (bus, id, status)", lambda c: list(zip(
            c.buses.number[c.generators.bus].tolist(), c.generators.gen_id,
            c.generators.in_service.tolist()))),
    )
    for what, rows in tables:
        left, right = rows(a), rows(b)
        if left != right:
            if len(left) != len(right):
                return f"{what}: {len(left)} against {len(right)}"
            k = next(i for i, (x, y) in enumerate(zip(left, right)) if x != y)
            return f"{what}: entry {k + 1} is {left[k]} against {right[k]}"
    return None


def stack_models(models: list[GridModel], sources: list[str]) -> GridModel:
    """One GridModel whose array leaves gain a leading operating-point axis.

    The compiler's notes stay with each point; everything static must agree (one grid).
    """
    plain = [dataclasses.replace(m, notes=()) for m in models]
    first = jax.tree.structure(plain[0])
    for model, source in zip(plain[1:], sources[1:]):
        if jax.tree.structure(model) != first:
            raise ValueError(f"{source} and {sources[0]} compile to different structures "
                             "(device models, units or load slots differ)")
    return jax.tree.map(lambda *a: np.stack(a), *plain)


# --------------------------------------------------------------------------- #
# Study files
# --------------------------------------------------------------------------- #

_SECTIONS = {"name", "grid", "compile", "env", "params", "tasks", "training"}


def read_study(path: str | Path) -> Study:
    """A study from its TOML file (module docstring); errors name the file, key and value."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ValueError(f"{path}: cannot read a study file: {err}") from None
    unknown = sorted(set(data) - _SECTIONS)
    if unknown:
        raise ValueError(f"{path}: unknown keys {unknown}; allowed: {sorted(_SECTIONS)}")
    base = path.parent
    grid = dict(_table(data.get("grid", {}), path, "grid"))
    for key in ("dyr", "task_config", "sim_config"):
        if key in grid:
            grid[key] = str(_path(base, grid[key], path, f"grid.{key}"))
    if "raw" in grid:
        raws = [grid["raw"]] if isinstance(grid["raw"], str) else grid["raw"]
        grid["raw"] = [str(p) for r in raws for p in _paths(base, r, path)]
    with _named(lambda key: f"{path}: grid.{key}"):
        source = _typed(GridSource, grid, path, "grid")
    compile_settings = _typed(CompileSettings, data.get("compile", {}), path, "compile")
    env = _fields(EnvConfig, data.get("env", {}), path, "env")
    params = _fields(EnvParams, data.get("params", {}), path, "params")
    tasks = {name: _fields(TaskSet, values, path, f"tasks.{name}")
             for name, values in _table(data.get("tasks", {}), path, "tasks").items()}
    training = _fields(TrainingSettings, data.get("training", {}), path, "training")
    name = data.get("name")
    if name is not None and not isinstance(name, str):
        raise ValueError(f"{path}: name = {name!r}: must be a string")
    return build(source, name=name, compile=compile_settings, env=env, params=params,
                 tasks=tasks, training=training, origin=str(path))


def write_study(study: Study | StudyDefinition, path: str | Path) -> None:
    """Write the resolved definition as TOML (every field explicit, paths absolute)."""
    definition = study.definition if isinstance(study, Study) else study
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(tomli_w.dumps(_plain(definition)))


def _plain(value):
    """Dataclasses and tuples as TOML-able dicts and lists; None fields left out."""
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if getattr(value, f.name) is not None}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _table(value, path, key) -> dict:
    if not isinstance(value, dict):
        raise ValueError(f"{path}: {key} = {value!r}: must be a table")
    return value


_NESTED = {"MotorOptions": MotorOptions, "LoadSplit": LoadSplit, "Bounds": Bounds,
           "CompositeOptions": CompositeOptions}


def _fields(cls, values, path, key) -> dict:
    """{field: value} checked against the fields of dataclass `cls` and their types."""
    values = _table(values, path, key)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise ValueError(f"{path}: [{key}] unknown keys {unknown}; allowed: {sorted(fields)}")
    return {name: _coerce(v, fields[name].type, path, f"{key}.{name}")
            for name, v in values.items()}


def _typed(cls, values, path, key):
    return cls(**_fields(cls, values, path, key))


def _coerce(value, annotation: str, path, key):
    """value as the annotated type (str annotations: float, int, bool, str, tuple[X, ...],
    the nested option dataclasses, and `X | None`)."""
    base = annotation.removesuffix(" | None")
    kind = "a table of ints" if base == "dict" else re.sub(
        r"tuple\[(\w+), \.\.\.\]", r"a list of \1", base)
    bad = ValueError(f"{path}: {key} = {value!r}: must be {kind}")
    if base in _NESTED:
        return _typed(_NESTED[base], value, path, key)
    if base == "dict":  # a table of ints (training.history)
        if not isinstance(value, dict):
            raise bad
        return {k: _coerce(v, "int", path, f"{key}.{k}") for k, v in value.items()}
    if base.startswith("tuple["):
        if not isinstance(value, list):
            raise bad
        item = base[len("tuple["):].split(",")[0]
        return tuple(_coerce(v, item, path, key) for v in value)
    if base == "bool":
        if not isinstance(value, bool):
            raise bad
        return value
    if base in ("int", "float"):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                base == "int" and not isinstance(value, int)):
            raise bad
        return float(value) if base == "float" else value
    if base == "str":
        if not isinstance(value, str):
            raise bad
        return value
    raise ValueError(f"{path}: {key}: no reader for type {annotation}")


def _path(base: Path, value, path, key) -> Path:
    if not isinstance(value, str):
        raise ValueError(f"{path}: {key} = {value!r}: must be a path")
    out = (base / value).resolve()
    if not out.is_file():
        raise ValueError(f"{path}: {key} = {value!r}: no such file ({out})")
    return out


def _paths(base: Path, pattern, path) -> list[Path]:
    """RAW files of one entry of grid.raw: a path or a glob pattern (sorted)."""
    if not isinstance(pattern, str):
        raise ValueError(f"{path}: grid.raw entry {pattern!r}: must be a path or pattern")
    if not glob.has_magic(pattern):
        return [_path(base, pattern, path, "grid.raw")]
    found = sorted(Path(p).resolve() for p in glob.glob(str(base / pattern)))
    if not found:
        raise ValueError(f"{path}: grid.raw pattern {pattern!r} matches no file")
    return found
