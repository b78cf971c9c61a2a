"""Where a study's operating points and defaults come from: one `SourceDefaults` per source.

`builtin_source(grid)`: a `jaxgrid.cases` FIDVR `StudyCase` per load level.
`file_source(grid)`: RAW files (one grid; the first also at `grid.base_load_levels`), a DYR,
and optionally a PNNL task JSON and a PNNL simulation JSON (`jaxgrid.study.pnnl`), whose bus
references are resolved here (`jaxgrid.study.names`). Each turns its source-specific input into `SourceDefaults` at this
one place; `jaxgrid.study.build` lays the overrides over them into the `StudyDefinition`.
`fault_set(task, buses)`: a PNNL task file's fault candidates alone, as a `TaskSet`.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from jaxgrid import cases
from jaxgrid.case import Case, at_load_level
from jaxgrid.checks import InputError, renamed_errors
from jaxgrid.env import EnvConfig
from jaxgrid.grid import GridModel
from jaxgrid.io.dyr import read_dyr
from jaxgrid.io.raw import read_raw
from jaxgrid.powerflow import with_reactive_room
from jaxgrid.records import DyrData
from jaxgrid.study import pnnl
from jaxgrid.study.definition import PAPER_HISTORY, GridSource
from jaxgrid.study.names import BusTable, bus_number, bus_scope, bus_table
from jaxgrid.tasks import TaskSet

FILE_SWEEPS = 2  # network sweeps of a study from files (its step's accuracy is not measured)
# TaskSet field -> the PNNL task key of the training faults
FAULT_KEYS = {"fault_buses": "faultBusCandidates", "fault_starts": "faultStartTimeCandidates",
              "fault_durations": "faultDurationCandidates"}


@dataclasses.dataclass(frozen=True)
class SourcePoint:
    """An operating point as its source gives it, before the power flow and compile.

    Attributes:
      label: short name ("load100", a RAW file's stem).  source: where it came from.
      case: the network.
    """

    label: str
    source: str
    case: Case


@dataclasses.dataclass(frozen=True)
class SourceDefaults:
    """What a grid source gives a study: its operating points and the defaults of its
    definition, which the study's overrides replace field by field.

    Attributes:
      name: the study's default name.  points: the operating points (one grid).
      dyr: the dynamic data of every point.  buses: the names the study can use.
      sweeps: the solver's network sweeps unless the study sets them (`EnvConfig.solver`).
      env, params, training: {EnvConfig | EnvParams | TrainingSettings field: value}.
      tasks: {set name: {TaskSet field: value}}.
      written: {"section.field": "FILE: key"} of the values read from a file (messages).
      pnnl_task: the PNNL task whose own counts are checked after compiling, or None.
      notes: what the readers reported (keys read but unused, unknown keys).
    """

    name: str
    points: tuple[SourcePoint, ...]
    dyr: DyrData
    buses: BusTable
    sweeps: int
    env: dict
    params: dict = dataclasses.field(default_factory=dict)
    training: dict = dataclasses.field(default_factory=dict)
    tasks: dict = dataclasses.field(default_factory=dict)
    written: dict = dataclasses.field(default_factory=dict)
    pnnl_task: pnnl.PnnlTask | None = None
    notes: tuple[str, ...] = ()


def builtin_source(grid: GridSource) -> SourceDefaults:
    """The built-in FIDVR study `grid.builtin` at `grid.load_levels`; InputError
    "grid.builtin" if it is not one."""
    studies = [n for n in cases.names() if n.endswith("_fidvr")]
    if grid.builtin not in studies:
        what = "a network without dynamic data" if grid.builtin in cases.names() else \
            "not a built-in case"
        raise InputError("grid.builtin", grid.builtin, f"{what}; study cases: "
                         + ", ".join(studies))
    made = [cases.load(grid.builtin, load_level=level) for level in grid.load_levels]
    first = made[0]
    points = tuple(SourcePoint(f"load{100 * s.load_level:g}", f"jaxgrid.cases.{grid.builtin}"
                               f"(load_level={s.load_level:g})", s.case) for s in made)
    # machine data and MBASE are those of level 1 at every level: one DYR serves all points
    return SourceDefaults(
        name=grid.builtin, points=points, dyr=first.dyr,
        buses=bus_table(points[0].case, first.dyr), sweeps=first.sweeps,
        env={"observed_buses": first.observed_buses, "action_buses": first.action_buses,
             "dt": first.dt},
        params=dict(first.reward), training={"history": dict(PAPER_HISTORY)},
        tasks={k: {"fault_buses": tuple(b), "fault_durations": tuple(d)}
               for k, (b, d) in first.task_sets.items()})


def file_source(grid: GridSource) -> SourceDefaults:
    """The study of `grid.raw` (one grid; the first RAW file again at each of
    `grid.base_load_levels`, after them, its units' reactive limits widened to what the
    level needs: `jaxgrid.powerflow.with_reactive_room`), `grid.dyr` and the PNNL JSON files
    named."""
    points, stems = [], {}
    for path in grid.raw:
        stem = Path(path).stem
        stems[stem] = stems.get(stem, 0) + 1
        label = stem if stems[stem] == 1 else f"{stem}#{stems[stem]}"
        points.append(SourcePoint(label, path, read_raw(path)))
    first = points[0]
    for point in points[1:]:
        difference = structure_difference(first.case, point.case)
        if difference:
            raise ValueError(f"{point.source} and {first.source} are not one grid: {difference}")
    for level in grid.base_load_levels:
        label = f"{first.label}_load{100 * level:g}"
        source = f"{first.source} (loads and dispatch x {level:g})"
        case = with_reactive_room(at_load_level(first.case, level, label, source))
        points.append(SourcePoint(label, source, case))
    dyr = read_dyr(grid.dyr)
    source = SourceDefaults(name=Path(grid.task_config or grid.raw[0]).stem,
                            points=tuple(points), dyr=dyr, buses=bus_table(first.case, dyr),
                            sweeps=FILE_SWEEPS, env={})
    if grid.task_config:
        source = _with_task(source, pnnl.read_task_config(grid.task_config))
    if grid.sim_config:
        source = _with_sim(source, pnnl.read_sim_config(grid.sim_config))
    return source


def _read_notes(read: pnnl.PnnlTask | pnnl.PnnlSimConfig) -> tuple[str, ...]:
    """A PNNL file's notes and unknown keys as study notes."""
    return (tuple(f"{read.source}: {n}" for n in read.notes)
            + tuple(f"{read.source}: key {k!r} is not understood and was not used"
                    for k in read.unknown))


def _with_task(source: SourceDefaults, task: pnnl.PnnlTask) -> SourceDefaults:
    """`source` with the buses, reward, history and training faults of a PNNL task."""
    buses = source.buses
    action = bus_scope(task.action_scope, task.action, buses, task.source, "actionScopeAry")
    observed = bus_scope(task.observation_scope, task.observed, buses, task.source,
                         "observationScopeAry", min_kv=task.observed_min_kv)
    if task.observation_scope == "Zone":
        observed = observed + tuple(b for b in action if b not in observed)
    if task.action_p_mw is not None and len(task.action_p_mw) != len(action):
        raise InputError(f"{task.source}: actionBusesPValue", list(task.action_p_mw),
                         f"must give one value per action bus ({len(action)})")
    written = {field: f"{task.source}: {key}" for field, key in (
        ("env.observed_buses", "observationScopeAry"), ("env.action_buses", "actionScopeAry"),
        ("env.agent_dt", "envStepTimeInSec"), ("env.history", "historyObservationSize"),
        *((f"tasks.train.{field}", key) for field, key in FAULT_KEYS.items()))}
    return dataclasses.replace(
        source, name=task.name, params=dict(task.params), pnnl_task=task,
        env={"observed_buses": observed, "action_buses": action, "agent_dt": task.agent_dt,
             "history": task.history, "include_action_status": task.include_action_status},
        tasks={"train": {"fault_buses": _fault_buses(task, buses),
                         "fault_starts": task.fault_starts,
                         "fault_durations": task.fault_durations}},
        written={**source.written, **written}, notes=source.notes + _read_notes(task))


def fault_set(task: pnnl.PnnlTask, buses: BusTable) -> TaskSet:
    """The fault candidates of a PNNL task file as a TaskSet at every operating point, its
    bus names resolved against `buses`; errors name the file and key."""
    with renamed_errors(lambda field: f"{task.source}: {FAULT_KEYS.get(field, field)}"):
        return TaskSet(_fault_buses(task, buses), task.fault_durations, task.fault_starts)


def _fault_buses(task: pnnl.PnnlTask, buses: BusTable) -> tuple[int, ...]:
    """The bus numbers of a PNNL task file's faultBusCandidates."""
    return tuple(bus_number(n, buses, task.source, FAULT_KEYS["fault_buses"])
                 for n in task.fault_buses)


def _with_sim(source: SourceDefaults, sim: pnnl.PnnlSimConfig) -> SourceDefaults:
    """`source` with the step, episode length and fault impedance of a PNNL simulation."""
    tasks = source.tasks
    if sim.fault_r is not None and "train" in tasks:
        tasks = {**tasks, "train": {**tasks["train"], "fault_r": sim.fault_r,
                                    "fault_x": sim.fault_x}}
    return dataclasses.replace(
        source, env={**source.env, "dt": sim.dt, "episode": sim.t_end}, tasks=tasks,
        written={**source.written, "env.dt": f"{sim.source}: simuTimeStepSec",
                 "env.episode": f"{sim.source}: totalSimuTimeSec"},
        notes=source.notes + _read_notes(sim))


def pnnl_checks(task: pnnl.PnnlTask, config: EnvConfig, buses: BusTable, model: GridModel,
                base_mva: float) -> list[str]:
    """Notes where the resolved buses or loads differ from the PNNL task file's own counts
    (base_mva: the case's, MVA)."""
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
