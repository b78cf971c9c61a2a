"""Building a study: its source's defaults with the overrides laid over them into the
`StudyDefinition`, then each operating point's power flow, compile, and the compiled points
stacked into one `GridModel` pytree with a leading operating-point axis.

    builtin("ieee39_fidvr", load_levels=(0.9, 1.0))     # a built-in study
    from_files(["a.raw", "b.raw"], "x.dyr", "task.json", "sim.json")
    rebuild(study, precision="float64", sweeps=4)       # the same study compiled otherwise
"""
from __future__ import annotations

import contextlib
import dataclasses
import warnings
from pathlib import Path

import jax
import numpy as np

from jaxgrid.checks import InputError
from jaxgrid.compile import CompileOptions, compile_model
from jaxgrid.env import EnvConfig, EnvParams, check_params
from jaxgrid.grid import GridModel
from jaxgrid.powerflow import solve
from jaxgrid.study.definition import (CompileSettings, GridSource, OperatingPoint, Study,
                                      StudyDefinition, StudyWarning, TrainingSettings)
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
    precision="float64", sweeps=4 (a reference model for accuracy checks)."""
    d = study.definition

    def fields(value) -> dict:
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}

    return build(d.grid, name=d.name, compile=dataclasses.replace(d.compile, **compile_changes),
                 env=fields(d.env), params=fields(d.params),
                 tasks={k: fields(v) for k, v in d.tasks.items()}, training=fields(d.training))


@contextlib.contextmanager
def renamed_errors(name):
    """Re-raise an InputError from inside under the key as the user wrote it, name(key)."""
    try:
        yield
    except InputError as err:
        raise err.renamed(name(err.key)) from None


def read_source(grid: GridSource, origin: str = "study") -> SourceDefaults:
    """The operating points and defaults of `grid` (a built-in's bad name is reported as
    "ORIGIN: grid.builtin")."""
    if grid.builtin:
        with renamed_errors(lambda key: f"{origin}: {key}"):
            return builtin_source(grid)
    if grid.raw:
        return file_source(grid)
    raise ValueError("a study needs [grid] builtin = NAME, or raw = [files] and dyr = FILE")


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
    source = read_source(grid, origin)
    notes = list(source.notes)

    def key_of(section: str, given: dict | None):
        """name(key) of a field of `section` ("env", "tasks.train"); `given`: the overrides."""
        def name(key: str) -> str:
            field, bracket, index = key.partition("[")
            where = source.written.get(f"{section}.{field}")
            if field in (given or {}) or where is None:
                where = f"{origin}: {section}.{field}"
            return where + bracket + index
        return name

    env_values = {**source.env, **(env or {})}
    for key in ("observed_buses", "action_buses"):
        if key not in env_values:
            raise ValueError(f"{origin}: no {key}: give a task_config or [env] {key}")
    env_values["action_buses"] = tuple(env_values["action_buses"])
    env_key = key_of("env", env)
    with renamed_errors(env_key):
        config = EnvConfig(**env_values)
    buses = source.buses
    for b in config.action_buses:
        if not buses.loaded.get(b, False):
            raise InputError(env_key("action_buses"), list(config.action_buses),
                             f"bus {b} " + ("carries no load" if b in buses.loaded
                                            else "is not in the case"))
    param_values = {**source.params, **(params or {})}
    check_params(param_values, key_of("params", params))
    compile = dataclasses.replace(compile, sweeps=compile.sweeps or source.sweeps)
    options = CompileOptions(strict=compile.strict, loads=compile.loads,
                             load_buses=env_values["action_buses"], motors=compile.motors,
                             composite=compile.composite, precision=compile.precision,
                             sweeps=compile.sweeps, machine_base=compile.machine_base)
    flows = [solve(p.case) for p in source.points]
    models = [compile_model(p.case, source.dyr, options, pf=flow)
              for p, flow in zip(source.points, flows)]
    stacked = stack_models(models, [p.source for p in source.points])
    for key in ("observed_buses", "recovery_buses"):
        _check_buses(getattr(config, key) or (), models[0], env_key(key))
    task_sets = {}
    for set_name in sorted(set(source.tasks) | set(tasks or {})):
        given = (tasks or {}).get(set_name, {})
        values = {**source.tasks.get(set_name, {}), **given}
        missing = {"fault_buses", "fault_durations"} - set(values)
        if missing:
            raise ValueError(f"{origin}: tasks.{set_name} needs {sorted(missing)}")
        task_key = key_of(f"tasks.{set_name}", given)
        with renamed_errors(task_key):
            task_sets[set_name] = TaskSet(**values)
        _check_buses(task_sets[set_name].fault_buses, models[0], task_key("fault_buses"))
        for i, start in enumerate(task_sets[set_name].fault_starts):
            if start >= config.episode:
                raise InputError(task_key(f"fault_starts[{i}]"), start, "the fault must start "
                                 f"inside the episode (episode = {config.episode:g} s)")
        task_sets[set_name].points(len(source.points))
    definition = StudyDefinition(
        name=name or source.name, grid=grid, compile=compile, env=config,
        params=EnvParams(**param_values), tasks=task_sets,
        training=TrainingSettings(**{**source.training, **(training or {})}))
    if source.pnnl_task:
        notes.extend(pnnl_checks(source.pnnl_task, config, buses, models[0],
                                 source.points[0].case.base_mva))
    if notes:
        warnings.warn(f"study {definition.name!r}: {len(notes)} note(s), in Study.notes: "
                      + "; ".join(notes), StudyWarning, stacklevel=2)
    points = tuple(OperatingPoint(label=p.label, source=p.source, case=p.case, power_flow=flow,
                                  notes=m.notes)
                   for p, flow, m in zip(source.points, flows, models))
    return Study(definition=definition, points=points, models=stacked, buses=buses,
                 notes=tuple(notes))


def _check_buses(buses, model: GridModel, key: str) -> None:
    missing = [b for b in buses if b not in model.bus_numbers]
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
