"""Study files: a study read from TOML (`read_study`) and its resolved definition written
back (`write_study`); `load_study` takes a built-in study's name or a study file.

The file format is in the module docstring of `jaxgrid.study`. Values are checked against
the annotated field types of the definition's dataclasses; errors name the file, key and
value.
"""
from __future__ import annotations

import dataclasses
import glob
import re
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from jaxgrid import cases
from jaxgrid.checks import InputError, check_int, renamed_errors
from jaxgrid.env import EnvConfig, EnvParams
from jaxgrid.models.acmotor import MotorOptions
from jaxgrid.models.cmld import CompositeOptions
from jaxgrid.models.loads import LoadSplit
from jaxgrid.simulate import Bounds
from jaxgrid.steppers import SWEEPS, Solver
from jaxgrid.study.build import build, builtin
from jaxgrid.study.definition import (CompileSettings, GridSource, Study, StudyDefinition,
                                      TrainingSettings)
from jaxgrid.tasks import TaskSet


def load_study(spec: str) -> Study:
    """A built-in study by name, or a study TOML file."""
    if spec in cases.names():
        return builtin(spec)
    if spec.endswith(".toml") or Path(spec).is_file():
        return read_study(spec)
    studies = [n for n in cases.names() if n.endswith("_fidvr")]
    raise ValueError(f"study {spec!r}: neither a built-in study ({', '.join(studies)}) nor a "
                     "study file (.toml)")


_SECTIONS = {"name", "base", "grid", "compile", "env", "params", "tasks", "training"}


def read_study(path: str | Path, raw=None) -> Study:
    """A study from its TOML file (format: `jaxgrid.study`); errors name the file, key and
    value. `raw`: RAW files (one per operating point) in place of the file's grid.raw: its
    settings (buses, reward, steps, history, fault sets) at other operating points of its
    grid (and not its grid.base_load_levels), every task set at all of them (a set's operating_points index the file's points),
    so a policy trained on the study runs there (`--study FILE --raw R ...`)."""
    path = Path(path)
    data = _file_tables(path)
    grid = dict(data.get("grid", {}))
    if raw is not None:
        if "builtin" in grid:
            raise ValueError(f"{path}: grid.builtin = {grid['builtin']!r}: a built-in's operating "
                             "points are load levels (--load-levels), not RAW files")
        grid["raw"] = [str(Path(r).resolve()) for r in raw]
        grid.pop("base_load_levels", None)  # levels of the file's base case, not of these
    elif "raw" in grid:
        grid["raw"] = [str(p) for file, r in grid["raw"] for p in _paths(file.parent, r, file)]
    source = _typed(GridSource, grid, path, "grid")
    compile_table = dict(_table(data.get("compile", {}), path, "compile"))
    sweeps = compile_table.pop("sweeps", None)
    compile_settings = _typed(CompileSettings, compile_table, path, "compile")
    env = _fields(_ENV_TYPES, data.get("env", {}), path, "env")
    if sweeps is not None:  # the solver's: study files write it in [compile]
        with renamed_errors(lambda field: f"{path}: compile.{field}"):
            env["sweeps"] = check_int("sweeps", sweeps, SWEEPS)
    params = _fields(EnvParams, data.get("params", {}), path, "params")
    tasks = {name: _fields(TaskSet, values, path, f"tasks.{name}")
             for name, values in _table(data.get("tasks", {}), path, "tasks").items()}
    if raw is not None:  # sources leave operating_points unset: only the file's could index
        tasks = {name: {**values, "operating_points": None} for name, values in tasks.items()}
    training = _fields(TrainingSettings, data.get("training", {}), path, "training")
    name = data.get("name")
    if name is not None and not isinstance(name, str):
        raise ValueError(f"{path}: name = {name!r}: must be a string")
    return build(source, name=name, compile=compile_settings, env=env, params=params,
                 tasks=tasks, training=training, origin=str(path))


def _file_tables(path: Path, seen: tuple[Path, ...] = ()) -> dict:
    """The tables of a study file with its grid paths absolute, laid over those of the file
    its `base` names (a path relative to it, read the same way): a table merges key by key
    into the base's, any other value replaces the base's."""
    path = path.resolve()
    if path in seen:
        raise ValueError(f"{seen[-1]}: base = {str(path)!r}: a study file cannot be its own "
                         f"base (chain: {' -> '.join(map(str, (*seen, path)))})")
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ValueError(f"{path}: cannot read a study file: {err}") from None
    unknown = sorted(set(data) - _SECTIONS)
    if unknown:
        raise ValueError(f"{path}: unknown keys {unknown}; allowed: {sorted(_SECTIONS)}")
    folder = path.parent
    grid = dict(_table(data.get("grid", {}), path, "grid"))
    for key in ("dyr", "task_config", "sim_config"):
        if key in grid:
            grid[key] = str(_path(folder, grid[key], path, f"grid.{key}"))
    if "raw" in grid:
        raws = [grid["raw"]] if isinstance(grid["raw"], str) else grid["raw"]
        if not isinstance(raws, list):
            raise ValueError(f"{path}: grid.raw = {raws!r}: must be a path, a pattern or a "
                             "list of them")
        grid["raw"] = [(path, r) for r in raws]  # expanded by `read_study` unless replaced
    if "grid" in data:
        data["grid"] = grid
    base = data.pop("base", None)
    if base is None:
        return data
    return _merged(_file_tables(_path(folder, base, path, "base"), (*seen, path)), data)


def _merged(base: dict, over: dict) -> dict:
    """`over` laid over `base`: tables (dicts) merged key by key, other values replaced."""
    out = dict(base)
    for key, value in over.items():
        both = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merged(out[key], value) if both else value
    return out


def write_study(study: Study | StudyDefinition, path: str | Path) -> None:
    """Write the resolved definition as TOML (every field explicit, paths absolute)."""
    definition = study.definition if isinstance(study, Study) else study
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(tomli_w.dumps(_as_written(_plain(definition))))


def _as_written(tables: dict) -> dict:
    """The definition's tables as study files have always held them: the environment's
    solver's fields in [env] where the solver stands, but its sweeps in [compile] after
    precision, and [grid] base_load_levels only where there are some (the written text, and
    so the names of run folders, unchanged)."""
    solver = tables["env"]["solver"]
    env = {}
    for key, value in tables["env"].items():
        env.update({k: v for k, v in solver.items() if k != "sweeps"} if key == "solver"
                   else {key: value})
    compile_table = {}
    for key, value in tables["compile"].items():
        compile_table[key] = value
        if key == "precision":
            compile_table["sweeps"] = solver["sweeps"]
    grid = {k: v for k, v in tables["grid"].items() if k != "base_load_levels" or v}
    return {**tables, "grid": grid, "compile": compile_table, "env": env}


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
    """{field: value} checked against the fields of dataclass `cls` (or {field: annotation})
    and their types."""
    values = _table(values, path, key)
    types = cls if isinstance(cls, dict) else {f.name: f.type for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - set(types))
    if unknown:
        raise ValueError(f"{path}: [{key}] unknown keys {unknown}; allowed: {sorted(types)}")
    return {name: _coerce(v, types[name], path, f"{key}.{name}")
            for name, v in values.items()}


# The keys of [env]: EnvConfig's fields, its solver's in its place (sweeps in [compile])
_ENV_TYPES = {name: kind for f in dataclasses.fields(EnvConfig) for name, kind in (
    [(g.name, g.type) for g in dataclasses.fields(Solver) if g.name != "sweeps"]
    if f.name == "solver" else [(f.name, f.type)])}


def _typed(cls, values, path, key):
    """cls(**values) checked (`_fields`); its own errors name the file and table:
    "PATH: key.field = value: ..." (an InputError) or "PATH: [key] ..." (any other)."""
    fields = _fields(cls, values, path, key)
    try:
        return cls(**fields)
    except InputError as err:
        raise err.renamed(lambda field: f"{path}: {key}.{field}") from None
    except ValueError as err:
        raise ValueError(f"{path}: [{key}] {err}") from None


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
