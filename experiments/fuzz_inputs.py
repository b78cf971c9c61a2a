"""Fuzz every reader and study value with Hypothesis: a clear error or a valid, finite result.

    python -m experiments.fuzz_inputs --examples 500 --out fuzz.json

Each input kind mutates one reference input of ../shared/cases (read in place, mutants are
written to a temporary folder): the PNNL 39-bus RAW files (v30, v33) field by field or line
by line, its DYR token by token, its task and simulation JSON key by key, and a study TOML
over the built-in 39-bus study, one value per mutant. Every mutant ends in one of

  valid           read (or built) with only finite values;
  clear error     a ValueError (CaseError, DyrError, ModelError, InputError, ...) whose
                  message names the mutated file;
  unclear error   any other exception, or an error that does not say where;
  silent garbage  accepted with a non-finite value in what was built.

The command prints and writes the counts per kind (with the first unclear or garbage cases);
tests/test_fuzz_inputs.py asserts the property on a bounded, derandomized run.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import warnings
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

SHARED_CASES = Path(__file__).resolve().parents[2] / "shared" / "cases"
IEEE39 = SHARED_CASES / "ieee39"
RAW_FILES = {"raw_v30": IEEE39 / "IEEE39bus_multiloads_xfmr4_smallX_v30.raw",
             "raw_v33": IEEE39 / "IEEE39bus_multiloads_xfmr4_smallX_slackmvachange_v33.raw"}
DYR_FILE = IEEE39 / "IEEE39bus_3AC.dyr"
TASK_FILE = IEEE39 / "IEEE39_RL_loadShedding_3motor_continuous.json"
SIM_FILE = IEEE39 / "IEEE39_dyn_config.json"
OUTCOMES = ("valid", "clear error", "unclear error", "silent garbage")
SLOW_KINDS = {"study_toml": 10}  # examples divided by this (each valid mutant compiles)

# What a new user might type into a numeric field.
TEXT_VALUES = st.one_of(
    st.sampled_from(["0", "-1", "1e300", "-1e300", "1e20", "1e400", "nan", "inf", "-inf",
                     "1e-300", "abc", "", "''", "99999999999", "0.0", "-0.5", "2.5"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr))
JSON_VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, 1e20, 10 ** 20, 1e-12, 1000, "x",
                     [], None, True, [math.nan], [-1.0], [1e300], [0.1, 0.1], {},
                     [[0.0, -0.2]], [[-0.2, 0.0], [-0.5, 0.0]], ["Bus4", "Bus4"]]),
    st.floats(allow_nan=True, allow_infinity=True))
TOML_VALUES = st.sampled_from(
    ["nan", "inf", "-inf", "0", "0.0", "-1.0", "1e-12", "1e20", "100000000000000000", "[]",
     "[nan]", "[4, 4]", "[4]", "[7, 8]", '"text"', "true", "[0.1]", "[-0.1]", "0.5", "2.0",
     "[20.0]", "-0.3", '"ieee39"'])
TOML_KEYS = (
    [("env", k) for k in ("dt", "agent_dt", "episode", "history", "observed_buses",
                          "action_buses", "recovery_buses")]
    + [("params", k) for k in ("c_voltage", "c_shed", "c_invalid", "c_prefault",
                               "unstable_penalty", "recovery_level", "recovery_time",
                               "action_low", "action_high")]
    + [("tasks.test", k) for k in ("fault_buses", "fault_durations", "fault_starts",
                                   "fault_r", "fault_x")]
    + [("grid", "load_levels"), ("grid", "builtin"), ("compile", "sweeps")])


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


def classify(build: Callable[[], object], where: str) -> tuple[str, str]:
    """(outcome, detail) of build(): see the module docstring; `where` is the file a clear
    error names."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            built = build()
    except ValueError as err:
        return ("clear error" if where in str(err) else "unclear error"), str(err)[:300]
    except Exception as err:  # noqa: BLE001 - the point is to see any that escape
        return "unclear error", f"{type(err).__name__}: {str(err)[:300]}"
    bad = non_finite(built)
    return ("silent garbage", f"non-finite value at {bad}") if bad else ("valid", "")


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


def _json_mutant(data: dict):
    """Strategy of (description, text): one key (top level or in a nested object) set to a
    value from JSON_VALUES, or removed."""
    keys = [(k,) for k in data] + [(k, n) for k, v in data.items() if isinstance(v, dict)
                                   for n in v]

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

    return st.tuples(st.sampled_from(keys), JSON_VALUES, st.booleans()).map(change)


def _toml_mutant():
    """Strategy of (description, text): the built-in 39-bus study with one value changed."""
    def text(key_value):
        (section, key), value = key_value
        tables = {"grid": {"builtin": '"ieee39_fidvr"'},
                  "tasks.test": {"fault_buses": "[4]", "fault_durations": "[0.1]"}}
        tables.setdefault(section, {})[key] = value
        body = "".join(f"[{name}]\n" + "".join(f"{k} = {v}\n" for k, v in table.items())
                       for name, table in tables.items())
        return f"{section}.{key} = {value}", body

    return st.tuples(st.sampled_from(TOML_KEYS), TOML_VALUES).map(text)


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


def _read_task(path: Path):
    from jaxgrid.io.pnnl import read_task_config
    return read_task_config(path)


def _read_sim(path: Path):
    from jaxgrid.io.pnnl import read_sim_config
    return read_sim_config(path)


def _read_study(path: Path):
    from jaxgrid.study import read_study
    study = read_study(path)
    return {"definition": study.definition, "models": study.models}


def kinds() -> dict:
    """{kind: (strategy of (description, text), file suffix, reader)}."""
    out = {name: (_lines_mutant(path.read_text().splitlines()), ".raw", _read_raw)
           for name, path in RAW_FILES.items() if path.is_file()}
    out["dyr"] = (_tokens_mutant(DYR_FILE.read_text()), ".dyr", _read_dyr)
    out["task_json"] = (_json_mutant(json.loads(TASK_FILE.read_text())), ".json", _read_task)
    out["sim_json"] = (_json_mutant(json.loads(SIM_FILE.read_text())), ".json", _read_sim)
    out["study_toml"] = (_toml_mutant(), ".toml", _read_study)
    return out


def run_kind(kind: str, examples: int, record: Callable[[str, str, str], None]) -> None:
    """Run `examples` derandomized mutants of `kind`; record(outcome, description, detail)."""
    strategy, suffix, reader = kinds()[kind]

    @settings(max_examples=examples, derandomize=True, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def one(mutant):
        description, text = mutant
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / f"mutant_{kind}{suffix}"
            path.write_text(text)
            outcome, detail = classify(lambda: reader(path), path.name)
        record(outcome, description, detail)

    one()


def examples_for(kind: str, examples: int) -> int:
    """Examples of a kind: `examples`, fewer for the kinds whose valid mutants compile."""
    return max(3, examples // SLOW_KINDS.get(kind, 1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.fuzz_inputs",
                                description=__doc__.split("\n")[0])
    p.add_argument("--examples", type=int, default=300,
                   help="mutants per input kind (the study TOML gets a tenth: each compiles)")
    p.add_argument("--kinds", default=None, help="comma-separated kinds (default: all)")
    p.add_argument("--out", help="JSON file for the counts and the unclear/garbage cases")
    args = p.parse_args(argv)
    chosen = args.kinds.split(",") if args.kinds else list(kinds())
    report = {}
    for kind in chosen:
        counts, cases = Counter(), []

        def record(outcome, description, detail):
            counts[outcome] += 1
            if outcome in ("unclear error", "silent garbage") and len(cases) < 20:
                cases.append({"outcome": outcome, "mutant": description, "detail": detail})

        run_kind(kind, examples_for(kind, args.examples), record)
        report[kind] = {"counts": {o: counts[o] for o in OUTCOMES}, "cases": cases}
        print(f"{kind:11s} " + "  ".join(f"{o}: {counts[o]}" for o in OUTCOMES), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
