"""Fuzz every reader and study value with Hypothesis: a clear error or a valid result.

    python -m experiments.diagnostics.fuzz_inputs --examples 500 --seed 0 --out fuzz.json

Each input kind mutates one reference input of ../shared/cases (read in place, mutants are
written to a temporary folder): the PNNL 39-bus RAW files (v30, v33) field by field or line
by line, its DYR token by token, its task and simulation JSON key by key (each mutant then
builds the study of the base case with the other file as given), and two study TOMLs, over
the built-in 39-bus study and over the PNNL files, one key of any table set (every field of
every table of a study definition). List-valued settings are also mutated as a class: one
entry repeated (a bus name in another spelling) or the list emptied. Every mutant ends in one of

  valid           read (or built) with only finite values, no list setting that repeats an
                  entry or is empty where that means nothing (`repeated_or_empty`), and no
                  setting that the study ignores (`ignored_setting`);
  clear error     a ValueError (CaseError, DyrError, ModelError, InputError, ...) whose
                  message names the mutated file, and for a study TOML one of its tables
                  ("study.toml: env.bounds.max_speed_dev = -1.0: ...");
  unclear error   any other exception, or an error that does not say where;
  silent garbage  accepted with a non-finite value, a repeated or empty list, or a setting
                  that changes nothing;
  hang            no outcome within HANG_SECONDS.

The command prints and writes the counts per kind (with the first unclear, garbage and hang
cases); tests/test_fuzz_inputs.py asserts the property on a bounded, derandomized run.
`--seed` fixes the mutants of a campaign (the same seed, the same mutants).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import re
import signal
import sys
import tempfile
import threading
import warnings
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

SHARED_CASES = Path(__file__).resolve().parents[3] / "shared" / "cases"
IEEE39 = SHARED_CASES / "ieee39"
RAW_FILES = {"raw_v30": IEEE39 / "IEEE39bus_multiloads_xfmr4_smallX_v30.raw",
             "raw_v33": IEEE39 / "IEEE39bus_multiloads_xfmr4_smallX_slackmvachange_v33.raw"}
BASE_RAW = RAW_FILES["raw_v30"]
DYR_FILE = IEEE39 / "IEEE39bus_3AC.dyr"
TASK_FILE = IEEE39 / "IEEE39_RL_loadShedding_3motor_continuous.json"
SIM_FILE = IEEE39 / "IEEE39_dyn_config.json"
OUTCOMES = ("valid", "clear error", "unclear error", "silent garbage", "hang")
FAILURES = ("unclear error", "silent garbage", "hang")
HANG_SECONDS = 120
# kinds whose mutants build a study (0.2-0.3 s each once compiled): examples divided by this
SLOW_KINDS = {"task_json": 3, "sim_json": 3, "study_toml": 3, "study_toml_files": 3}

# What a new user might type into a numeric field.
TEXT_VALUES = st.one_of(
    st.sampled_from(["0", "-1", "1e300", "-1e300", "1e20", "1e400", "nan", "inf", "-inf",
                     "1e-300", "abc", "", "''", "99999999999", "0.0", "-0.5", "2.5"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr))
JSON_VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, 1e20, 10 ** 20, 1e-12, 1000, "x",
                     [], None, True, [math.nan], [-1.0], [1e300], [0.1, 0.1], {},
                     [[0.0, -0.2]], [[-0.2, 0.0], [-0.5, 0.0]], ["Bus4", "Bus4"],
                     ["Bus4", "bus4"], ["Bus4", 4], ["1", "01"]]),
    st.floats(allow_nan=True, allow_infinity=True))
TOML_VALUES = (
    "nan", "inf", "-inf", "0", "0.0", "-1.0", "1e-12", "1e20", "100000000000000000", "[]",
    "[nan]", "[4, 4]", "[4]", "[7, 8]", '"text"', "true", "[0.1]", "[-0.1]", "0.5", "2.0",
    "[20.0]", "-0.3", '"ieee39"', "[0, 0]", "[1.0, 1.0]", "{}", '{lstm = 0}')
# The tables of a study file that a clear error names ("study.toml: env.dt = ...",
# "study.toml: [compile.motors] ...").
STUDY_TABLES = ("name", "grid", "compile", "env", "params", "tasks", "training")
# Study TOMLs as {table: {key: TOML literal}}, every list a valid one (its class mutants
# repeat its first entry or empty it).
BUILTIN_STUDY = {
    "": {"name": '"fuzz39"'},
    "grid": {"builtin": '"ieee39_fidvr"', "load_levels": "[1.0]"},
    "compile": {"sweeps": "1"},
    "env": {"observed_buses": "[4, 504, 7, 507]", "action_buses": "[504, 507, 518]",
            "recovery_buses": "[4, 504]", "agent_dt": "0.1", "episode": "10.0"},
    "env.bounds": {"max_speed_dev": "0.2"},
    "params": {"action_low": "-0.2"},
    "tasks.test": {"fault_buses": "[4, 15]", "fault_durations": "[0.05, 0.1]",
                   "fault_starts": "[1.0]", "operating_points": "[0]"},
    "training": {"history": "{linear = 10, lstm = 1}", "task_sampling": '"uniform"'},
}
FILES_STUDY = {
    "grid": {"raw": f'["{BASE_RAW}"]', "dyr": f'"{DYR_FILE}"', "task_config": f'"{TASK_FILE}"',
             "sim_config": f'"{SIM_FILE}"'},
    "compile": {"sweeps": "1"},
    "tasks.test": {"fault_buses": "[4, 15]", "fault_durations": "[0.05]",
                   "operating_points": "[0]"},
}
# More values of one key: RAW lists naming one file twice, directly or through a pattern.
FILES_VALUES = {("grid", "raw"): (f'["{BASE_RAW}", "{BASE_RAW}"]',
                                  f'["{BASE_RAW}", "{IEEE39}/*smallX_v30.raw"]',
                                  f'"{BASE_RAW}"', f'["{IEEE39}/nothing*.raw"]')}
# Settings whose entries may repeat or be empty (everything else is checked by class).
MAY_REPEAT = {"action_p_mw"}     # PnnlTask: one MW value per action bus
MAY_BE_EMPTY = {"raw",           # a built-in study's grid has no RAW files
                "base_load_levels"}  # nor scaled points; a study from files need not
NOT_SETTINGS = {"notes", "unknown", "counts", "source"}


# --------------------------------------------------------------------------- #
# The property
# --------------------------------------------------------------------------- #

def non_finite(value, path: str = "") -> str | None:
    """The path of the first non-finite float in a nest of dataclasses, dicts, sequences and
    arrays, or None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = enumerate(value)
    elif isinstance(value, (float, np.floating, np.complexfloating)) or (
            isinstance(value, np.ndarray) and np.issubdtype(value.dtype, np.inexact)):
        return None if np.all(np.isfinite(value)) else path
    else:
        return None
    for key, item in items:
        found = non_finite(item, f"{path}.{key}")
        if found is not None:
            return found
    return None


def repeated_or_empty(value, path: str = "") -> str | None:
    """Where a list setting in a nest of dataclasses and dicts repeats an entry or is empty
    (MAY_REPEAT, MAY_BE_EMPTY and NOT_SETTINGS excepted), or None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        for key, item in value.items():
            found = None if key in NOT_SETTINGS else repeated_or_empty(item, f"{path}.{key}")
            if found:
                return found
        return None
    if not isinstance(value, (list, tuple)):
        return None
    name = path.rpartition(".")[2]
    if not value:
        return None if name in MAY_BE_EMPTY else f"{path} is empty"
    scalars = all(isinstance(v, (int, float, str)) for v in value)
    if scalars and name not in MAY_REPEAT and len(set(value)) < len(value):
        return f"{path} = {list(value)} repeats an entry"
    return None


def ignored_setting(definition) -> str | None:
    """A [grid] setting the study's source does not read (None if every one is read)."""
    grid = definition.grid
    if grid.builtin and (grid.raw or grid.base_load_levels or grid.dyr or grid.task_config
                         or grid.sim_config):
        return "grid.builtin with files: the files are not read"
    if grid.raw and tuple(grid.load_levels) != (1.0,):
        return f"grid.load_levels = {list(grid.load_levels)} with RAW files: not used"
    return None


def garbage(built) -> str | None:
    """Why an accepted result is garbage, or None. `built`: what a reader returns; a dict
    with "settings" ({name: dataclass}) has them checked by class too."""
    bad = non_finite(built)
    if bad:
        return f"non-finite value at {bad}"
    if not isinstance(built, dict) or "settings" not in built:
        return None
    definition = built["settings"].get("definition")
    return (repeated_or_empty(built["settings"])
            or (ignored_setting(definition) if definition is not None else None))


class Hang(BaseException):
    """A mutant that ran past HANG_SECONDS (BaseException: no reader catches it)."""


@contextlib.contextmanager
def time_limit(seconds: int):
    """Hang raised after `seconds` (main thread only; elsewhere no limit)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise Hang(f"no outcome in {seconds} s")

    previous = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def classify(build: Callable[[], object], names_where: Callable[[str], bool]) -> tuple[str,
                                                                                      str]:
    """(outcome, detail) of build(): see the module docstring; names_where(message): whether
    an error message says where the problem is."""
    try:
        with warnings.catch_warnings(), time_limit(HANG_SECONDS):
            warnings.simplefilter("ignore")
            built = build()
    except Hang as err:
        return "hang", str(err)
    except ValueError as err:
        return ("clear error" if names_where(str(err)) else "unclear error"), str(err)[:300]
    except Exception as err:  # noqa: BLE001 - the point is to see any that escape
        return "unclear error", f"{type(err).__name__}: {str(err)[:300]}"
    bad = garbage(built)
    return ("silent garbage", bad) if bad else ("valid", "")


def names_file(name: str) -> Callable[[str], bool]:
    """An error names the file `name`."""
    return lambda message: name in message


def names_file_and_table(name: str) -> Callable[[str], bool]:
    """An error names the study file `name` and one of its tables (STUDY_TABLES)."""
    pattern = re.compile(rf"{re.escape(name)}: \[?({'|'.join(STUDY_TABLES)})\b")
    return lambda message: bool(pattern.search(message))


# --------------------------------------------------------------------------- #
# Input kinds: a strategy of mutants and how to read one
# --------------------------------------------------------------------------- #

def _lines_mutant(lines: list[str]):
    """Strategy of (description, text) for a line-based file: a field changed, a line
    repeated, dropped, or the file cut."""
    index = st.integers(0, len(lines) - 1)

    def field(k_i_value):
        k, i, value = k_i_value
        fields = lines[k].split(",")
        i = i % len(fields)
        fields[i] = value
        return f"line {k + 1} field {i + 1} = {value!r}", lines[:k] + [",".join(fields)] + \
            lines[k + 1:]

    return st.one_of(
        st.tuples(index, st.integers(0, 30), TEXT_VALUES).map(field),
        index.map(lambda k: (f"line {k + 1} repeated", lines[:k + 1] + lines[k:])),
        index.map(lambda k: (f"line {k + 1} dropped", lines[:k] + lines[k + 1:])),
        index.map(lambda k: (f"cut after line {k}", lines[:k])),
    ).map(lambda d_l: (d_l[0], "\n".join(d_l[1]) + "\n"))


def _tokens_mutant(text: str):
    """Strategy of (description, text) for the DYR: one blank-separated token replaced, or
    one record repeated."""
    tokens = text.split(" ")
    numeric = [k for k, t in enumerate(tokens) if t.strip() and t.strip()[0] in "0123456789-."]
    records = [r for r in text.split("/") if r.strip()]

    def token(k_value):
        k, value = k_value
        return f"token {k} = {value!r}", " ".join(tokens[:k] + [value] + tokens[k + 1:])

    return st.one_of(
        st.tuples(st.sampled_from(numeric), TEXT_VALUES).map(token),
        st.integers(0, len(records) - 1).map(
            lambda k: (f"record {k + 1} repeated", text + records[k].strip() + " /\n")))


def _respelled(entry):
    """The same entry as a user might write it again: "Bus4" -> "bus4", else unchanged."""
    return entry.lower() if isinstance(entry, str) and re.fullmatch(r"Bus\d+", entry) else entry


def _json_mutant(data: dict):
    """Strategy of (description, text): one key (top level or in a nested object) set to a
    value from JSON_VALUES, or removed; or one list-valued key with its first entry repeated
    (respelled) or emptied."""
    keys = [(k,) for k in data] + [(k, n) for k, v in data.items() if isinstance(v, dict)
                                   for n in v]
    lists = [k for k, v in data.items() if isinstance(v, list) and v]

    def change(key_value):
        key, value, remove = key_value
        out = json.loads(json.dumps(data))
        holder = out if len(key) == 1 else out[key[0]]
        if remove:
            holder.pop(key[-1])
        else:
            holder[key[-1]] = value
        what = ".".join(key)
        return (f"{what} removed" if remove else f"{what} = {value!r}"), json.dumps(out)

    def relist(key_empty):
        key, empty = key_empty
        entries = data[key]
        changed = [] if empty else entries + [_respelled(entries[0])]
        return f"{key} = {changed!r}", json.dumps({**data, key: changed})

    return st.one_of(st.tuples(st.sampled_from(keys), JSON_VALUES, st.booleans()).map(change),
                     st.tuples(st.sampled_from(lists), st.booleans()).map(relist))


def study_keys() -> list[tuple[str, str]]:
    """(table, key) of every field of a study file: [grid], [compile] and its option tables,
    [env] and [env.bounds], [params], a [tasks.test] set, [training], and the name."""
    from jaxgrid.env import EnvConfig, EnvParams
    from jaxgrid.study.definition import CompileSettings, GridSource, TrainingSettings
    from jaxgrid.tasks import TaskSet

    tables = {"grid": GridSource, "compile": CompileSettings, "env": EnvConfig,
              "params": EnvParams, "tasks.test": TaskSet, "training": TrainingSettings}
    keys = [("", "name")]
    for table, cls in tables.items():
        for f in dataclasses.fields(cls):
            if dataclasses.is_dataclass(f.default):  # an option table: [compile.motors], ...
                keys += [(f"{table}.{f.name}", g.name) for g in dataclasses.fields(f.default)]
            else:
                keys.append((table, f.name))
    return keys


def _list_class(literal: str | None) -> tuple[str, ...]:
    """The class mutants of a TOML list literal: emptied, and its first entry repeated."""
    if not literal or not literal.startswith("[") or literal == "[]":
        return ()
    inner = literal[1:-1]
    return "[]", f"[{inner}, {inner.split(',')[0].strip()}]"


def _toml_text(tables: dict) -> str:
    top = "".join(f"{k} = {v}\n" for k, v in tables.get("", {}).items())
    return top + "".join(f"[{name}]\n" + "".join(f"{k} = {v}\n" for k, v in table.items())
                         for name, table in tables.items() if name)


def _toml_mutant(base: dict, extra: dict):
    """Strategy of (description, text): the study `base` ({table: {key: literal}}) with one
    key of study_keys() set to a value of TOML_VALUES, `extra` or the key's list class."""
    def values(key):
        table, name = key
        return st.tuples(st.just(key), st.sampled_from(
            TOML_VALUES + extra.get(key, ()) + _list_class(base.get(table, {}).get(name))))

    def text(key_value):
        (table, name), value = key_value
        tables = {t: dict(v) for t, v in base.items()}
        tables.setdefault(table, {})[name] = value
        return f"{table or '(top)'}.{name} = {value}", _toml_text(tables)

    return st.sampled_from(study_keys()).flatmap(values).map(text)


def _read_raw(path: Path):
    from jaxgrid.io.raw import read_raw
    return read_raw(path)


def _read_dyr(path: Path):
    """The DYR's records read by every supported model (CON ranges checked)."""
    from jaxgrid.compile import GOVERNORS, LOAD_MODELS, MACHINES
    from jaxgrid.io.dyr import read_dyr
    from jaxgrid.models.exciters import EXCITERS

    dyr = read_dyr(path)
    registry = {**MACHINES, **EXCITERS, **GOVERNORS, **LOAD_MODELS}
    return {name: registry[name].read(dyr.by_model(name)) for name in dyr.counts()
            if name in registry}


def _built(study, **settings) -> dict:
    return {"settings": {**settings, "definition": study.definition}, "models": study.models}


def _read_task(path: Path):
    """The task JSON read, then the base case's study built with it."""
    from jaxgrid.study.pnnl import read_task_config
    from jaxgrid.study import from_files

    task = read_task_config(path)
    return _built(from_files(BASE_RAW, DYR_FILE, path, SIM_FILE), task=task)


def _read_sim(path: Path):
    """The simulation JSON read, then the base case's study built with it."""
    from jaxgrid.study.pnnl import read_sim_config
    from jaxgrid.study import from_files

    sim = read_sim_config(path)
    return _built(from_files(BASE_RAW, DYR_FILE, TASK_FILE, path), sim=sim)


def _read_study(path: Path):
    from jaxgrid.study import read_study
    return _built(read_study(path))


def kinds() -> dict:
    """{kind: (strategy of (description, text), file suffix, reader, names_where(file))}."""
    out = {name: (_lines_mutant(path.read_text().splitlines()), ".raw", _read_raw, names_file)
           for name, path in RAW_FILES.items() if path.is_file()}
    out["dyr"] = (_tokens_mutant(DYR_FILE.read_text()), ".dyr", _read_dyr, names_file)
    out["task_json"] = (_json_mutant(json.loads(TASK_FILE.read_text())), ".json", _read_task,
                        names_file)
    out["sim_json"] = (_json_mutant(json.loads(SIM_FILE.read_text())), ".json", _read_sim,
                       names_file)
    out["study_toml"] = (_toml_mutant(BUILTIN_STUDY, {}), ".toml", _read_study,
                         names_file_and_table)
    out["study_toml_files"] = (_toml_mutant(FILES_STUDY, FILES_VALUES), ".toml", _read_study,
                               names_file_and_table)
    return out


def run_kind(kind: str, examples: int, record: Callable[[str, str, str], None],
             fixed_seed: int | None = None) -> None:
    """Run `examples` mutants of `kind`; record(outcome, description, detail). fixed_seed:
    the campaign's seed (None: derandomized by the test's own digest)."""
    strategy, suffix, reader, names_where = kinds()[kind]

    @settings(max_examples=examples, derandomize=fixed_seed is None, deadline=None,
              database=None, suppress_health_check=list(HealthCheck))
    @given(strategy)
    def one(mutant):
        description, text = mutant
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / f"mutant_{kind}{suffix}"
            path.write_text(text)
            outcome, detail = classify(lambda: reader(path), names_where(path.name))
        record(outcome, description, detail)

    (one if fixed_seed is None else seed(fixed_seed)(one))()


def examples_for(kind: str, examples: int) -> int:
    """Examples of a kind: `examples`, fewer for the kinds whose mutants build a study."""
    return max(3, examples // SLOW_KINDS.get(kind, 1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.diagnostics.fuzz_inputs",
                                description=__doc__.split("\n")[0])
    p.add_argument("--examples", type=int, default=300,
                   help="mutants per input kind (a third for the kinds that build a study)")
    p.add_argument("--seed", type=int, default=0, help="the campaign's seed")
    p.add_argument("--kinds", default=None, help="comma-separated kinds (default: all)")
    p.add_argument("--out", help="JSON file for the counts and the unclear/garbage cases")
    args = p.parse_args(argv)
    chosen = args.kinds.split(",") if args.kinds else list(kinds())
    report = {}
    for kind in chosen:
        counts, cases = Counter(), []

        def record(outcome, description, detail):
            counts[outcome] += 1
            if outcome in FAILURES and len(cases) < 50:
                cases.append({"outcome": outcome, "mutant": description, "detail": detail})

        run_kind(kind, examples_for(kind, args.examples), record, args.seed)
        report[kind] = {"counts": {o: counts[o] for o in OUTCOMES}, "cases": cases}
        print(f"{kind:16s} " + "  ".join(f"{o}: {counts[o]}" for o in OUTCOMES), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
