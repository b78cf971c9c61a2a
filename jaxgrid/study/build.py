"""Building a study: its source's defaults with the overrides laid over them into the
`StudyDefinition`, then each operating point's power flow, compile, and the compiled points
stacked into one `GridModel` pytree with a leading operating-point axis.

    builtin("ieee39_fidvr", load_levels=(0.9, 1.0))     # a built-in study
    from_files(["a.raw", "b.raw"], "x.dyr", "task.json", "sim.json")
    rebuild(study, precision="float64")                 # the same study compiled otherwise
"""
from __future__ import annotations

import contextlib
import dataclasses
import warnings
from collections import Counter
from pathlib import Path

import jax
import numpy as np

from jaxgrid.checks import InputError, renamed_errors
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.env import EnvConfig, EnvParams, check_params
from jaxgrid.grid import GridModel
from jaxgrid.powerflow import solve
from jaxgrid.study.definition import (CompileSettings, GridSource, OperatingPoint, Study,
                                      StudyDefinition, StudyWarning, TrainingSettings)
from jaxgrid.study.names import BusTable
from jaxgrid.study.sources import SourceDefaults, builtin_source, file_source, pnnl_checks
from jaxgrid.tasks import TaskSet


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
    precision="float64" (a reference model for accuracy checks)."""
    d = study.definition

    def fields(value) -> dict:
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}

    return build(d.grid, name=d.name, compile=dataclasses.replace(d.compile, **compile_changes),
                 env=d.env.values(), params=fields(d.params),
                 tasks={k: fields(v) for k, v in d.tasks.items()}, training=fields(d.training))


def read_source(grid: GridSource, label: str = "study") -> SourceDefaults:
    """The operating points and defaults of `grid` (a built-in's bad name is reported as
    "LABEL: grid.builtin")."""
    if grid.builtin:
        with renamed_errors(lambda key: f"{label}: {key}"):
            return builtin_source(grid)
    if grid.raw and grid.dyr:
        return file_source(grid)
    raise InputError(f"{label}: grid", None, ": a study needs builtin = NAME, or raw = [files] "
                     "and dyr = FILE")


def build(grid: GridSource, name: str | None = None,
          compile: CompileSettings = CompileSettings(), env: dict | None = None,
          params: dict | None = None, tasks: dict | None = None,
          training: dict | None = None, origin: str | None = None) -> Study:
    """The study of `grid` with overrides of the source's env, params, task sets and
    training settings.

    env, params, training: {field: value}; tasks: {set name: {TaskSet field: value}} (a new
    name adds a set, fault buses and durations then required). A bad value raises an
    InputError naming it as written: "ORIGIN: env.dt" for an override (origin: the study
    file; "study" for none), the PNNL file and key for a value read from one. With an origin,
    an error from the files its grid names (RAW, DYR, JSON) or from compiling them gets
    "ORIGIN: [grid] " in front. Everything is checked before the first operating point
    compiles.
    """
    label = origin or "study"
    with _from_grid(origin):
        source = read_source(grid, label)
    definition = _definition(source, grid, name, compile, env or {}, params or {}, tasks or {},
                             training or {}, label)
    with _from_grid(origin):
        flows = [solve(p.case) for p in source.points]
        models = [compile_model(p.case, source.dyr, _compile_options(definition), pf=flow)
                  for p, flow in zip(source.points, flows)]
        stacked = stack_models(models, [p.source for p in source.points])
    notes = list(source.notes)
    if source.pnnl_task:
        notes.extend(pnnl_checks(source.pnnl_task, definition.env, source.buses, models[0],
                                 source.points[0].case.base_mva))
    if notes:
        warnings.warn(notes_summary(definition.name, notes), StudyWarning, stacklevel=2)
    points = tuple(OperatingPoint(label=p.label, source=p.source, case=p.case, power_flow=flow,
                                  notes=m.notes)
                   for p, flow, m in zip(source.points, flows, models))
    return Study(definition=definition, points=points, models=stacked, buses=source.buses,
                 notes=tuple(notes))


def notes_summary(study: str, notes: list[str]) -> str:
    """One line on a study's notes ("SOURCE: text"): how many, from which files, and where
    they are (Study.notes)."""
    sources = Counter(Path(n.split(": ", 1)[0]).name for n in notes)
    return (f"study {study!r}: {len(notes)} note(s) in Study.notes ("
            + ", ".join(f"{count} on {source}" for source, count in sources.items()) + ")")


@contextlib.contextmanager
def _from_grid(origin: str | None):
    """With a study file as origin, a ValueError from inside that does not name it gets
    "ORIGIN: [grid] " in front: it comes from the files [grid] names or their compiling."""
    try:
        yield
    except ValueError as err:
        if origin is None or origin in str(err):
            raise
        raise ValueError(f"{origin}: [grid] {err}") from err


@dataclasses.dataclass(frozen=True)
class _Names:
    """The fields of one section ("env", "tasks.train") as the user wrote them.

    Attributes:
      label: the study file ("study" for the API).  section: the section.
      given: the overrides ({field: value}).  written: {"section.field": "FILE: key"} of
        the values a PNNL file gave.
    """

    label: str
    section: str
    given: dict
    written: dict

    def source(self, field: str) -> str | None:
        """Where the value of `field` ("history.lstm" counts as "history") was written: the
        override's "LABEL: section.field", a PNNL "FILE: key"; None for a default."""
        if field.split(".")[0] in self.given:
            return f"{self.label}: {self.section}.{field}"
        return self.written.get(f"{self.section}.{field}")

    def __call__(self, key: str) -> str:
        """`key` ("fault_starts[2]") as written; a default as where it would be set."""
        field, bracket, index = key.partition("[")
        return (self.source(field) or f"{self.label}: {self.section}.{field}") + bracket + index


def _definition(source: SourceDefaults, grid: GridSource, name: str | None,
                compile: CompileSettings, env: dict, params: dict, tasks: dict,
                training: dict, label: str) -> StudyDefinition:
    """The StudyDefinition of `source` with the overrides, every value checked (InputError
    naming it as written, `_Names`)."""
    env_values = {"sweeps": source.sweeps, **source.env, **env}
    for key in ("observed_buses", "action_buses"):
        if key not in env_values:
            raise InputError(f"{label}: env.{key}", None, f" is not set: give a task_config or "
                             f"[env] {key}")
    env_values["action_buses"] = tuple(env_values["action_buses"])
    env_names = _Names(label, "env", env, source.written)
    with renamed_errors(env_names, env_names.source):
        config = EnvConfig.of(env_values)
    buses = source.buses
    for b in config.action_buses:
        if not buses.loaded.get(b, False):
            raise InputError(env_names("action_buses"), list(config.action_buses),
                             f"bus {b} " + ("carries no load" if b in buses.loaded
                                            else "is not in the case"))
    for key in ("observed_buses", "recovery_buses"):
        _check_buses(getattr(config, key) or (), buses, env_names(key))
    param_values = {**source.params, **params}
    check_params(param_values, _Names(label, "params", params, source.written))
    task_sets, episode = {}, env_names.source("episode")
    for set_name in sorted(set(source.tasks) | set(tasks)):
        given = tasks.get(set_name, {})
        values = {**source.tasks.get(set_name, {}), **given}
        missing = {"fault_buses", "fault_durations"} - set(values)
        if missing:
            raise InputError(f"{label}: tasks.{set_name}", None, f" needs {sorted(missing)}")
        task_names = _Names(label, f"tasks.{set_name}", given, source.written)
        with renamed_errors(task_names, task_names.source):
            task_sets[set_name] = TaskSet(**values)
            task_sets[set_name].points(len(source.points))
        _check_buses(task_sets[set_name].fault_buses, buses, task_names("fault_buses"))
        for i, start in enumerate(task_sets[set_name].fault_starts):
            if start >= config.episode:
                raise InputError(task_names(f"fault_starts[{i}]"), start, "the fault must start "
                                 f"inside the episode (episode = {config.episode:g} s"
                                 + (f"; episode: {episode})" if episode else ")"))
    training_names = _Names(label, "training", training, source.written)
    with renamed_errors(training_names, training_names.source):
        settings = TrainingSettings(**{**source.training, **training})
    return StudyDefinition(
        name=name or source.name, grid=grid, compile=compile, env=config, params=EnvParams(**param_values), tasks=task_sets, training=settings)


def _compile_options(definition: StudyDefinition) -> CompileOptions:
    """The CompileOptions of a definition (its action buses get the load slots)."""
    c = definition.compile
    return CompileOptions(strict=c.strict, loads=c.loads, load_buses=definition.env.action_buses,
                          motors=c.motors, composite=c.composite, precision=c.precision,
                          machine_base=c.machine_base)


def _check_buses(numbers, buses: BusTable, key: str) -> None:
    """InputError naming `key` for bus numbers the study's grid does not have."""
    missing = [b for b in numbers if b not in buses.numbers]
    if missing:
        raise InputError(key, None, f": buses {missing} are not in the case")


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
