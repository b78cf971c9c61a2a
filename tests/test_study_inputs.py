"""Bad study input by class, and the notes of building a study as commands show them.

- Every list setting (a study file's, a PNNL task file's once resolved, the API's; the task
  file's own lists: tests/test_study.py) that repeats an entry or is empty where that means
  nothing is refused, naming it: a repeated fault bus would
  double its tasks' weight in sampling, an empty observed-bus list make a policy without
  inputs.
- Every error from a study file names the file and the table ("study.toml: env.bounds.
  max_speed_dev = ...", "study.toml: [compile.loads] ..."), and a cross-check names where
  the other value was written.
- Settings the study would not read (files with a built-in, load levels with RAW files) are
  refused.
All of these fail before anything compiles. `experiments.common.studyargs.warnings_summary` turns the
warnings of a build into one line per kind.
"""
from __future__ import annotations

import json
import re
import warnings

import pytest

from experiments.common.studyargs import warnings_summary
from jaxgrid.study.pnnl import read_task_config
from jaxgrid.io.raw import RawWarning
from jaxgrid.study import StudyWarning, builtin, from_files, read_study

BASE = "ieee39/IEEE39bus_multiloads_xfmr4_smallX_v30.raw"
DYR = "ieee39/IEEE39bus_3AC.dyr"
TASK = "ieee39/IEEE39_RL_loadShedding_3motor_continuous.json"
# A study file over the built-in 39-bus study, every list setting given: {table: {key: TOML}}
STUDY = {"grid": {"builtin": '"ieee39_fidvr"', "load_levels": "[1.0]"},
         "env": {"observed_buses": "[4, 504, 7]", "action_buses": "[504, 507]",
                 "recovery_buses": "[4, 504]"},
         "tasks.test": {"fault_buses": "[4, 15]", "fault_durations": "[0.05, 0.1]",
                        "fault_starts": "[1.0]", "operating_points": "[0]"}}


def task_file(shared_cases, tmp_path, key: str, value):
    """The PNNL 39-bus task JSON with key = value, written to tmp_path/task.json."""
    data = json.loads((shared_cases / TASK).read_text())
    path = tmp_path / "task.json"
    path.write_text(json.dumps({**data, key: value}))
    return path


def study_file(tmp_path, table: str, key: str, value: str):
    """STUDY with table.key = value, written to tmp_path/study.toml."""
    tables = {t: dict(v) for t, v in STUDY.items()}
    tables.setdefault(table, {})[key] = value
    path = tmp_path / "study.toml"
    path.write_text("".join(f"[{t}]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items())
                            for t, keys in tables.items()))
    return path


@pytest.mark.parametrize("table, key, value, entry", [
    ("grid", "load_levels", "[1.0, 1.0]", "1.0"),
    ("env", "observed_buses", "[4, 504, 4]", "4"),
    ("env", "action_buses", "[504, 504]", "504"),
    ("env", "recovery_buses", "[4, 4]", "4"),
    ("tasks.test", "fault_buses", "[4, 15, 4]", "4"),
    ("tasks.test", "fault_durations", "[0.05, 0.05]", "0.05"),
    ("tasks.test", "fault_starts", "[1.0, 1.0]", "1.0"),
    ("tasks.test", "operating_points", "[0, 0]", "0"),
])
def test_a_study_list_that_repeats_an_entry_is_refused(tmp_path, table, key, value, entry):
    path = study_file(tmp_path, table, key, value)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: {table}.{key} = \[.*\]: "
                                         rf"{re.escape(entry)} is listed more than once$"):
        read_study(path)


@pytest.mark.parametrize("table, key", [
    ("grid", "load_levels"), ("env", "observed_buses"), ("env", "action_buses"),
    ("env", "recovery_buses"), ("tasks.test", "fault_buses"), ("tasks.test", "fault_durations"),
    ("tasks.test", "fault_starts"), ("tasks.test", "operating_points"),
])
def test_a_study_list_that_is_empty_is_refused(tmp_path, table, key):
    path = study_file(tmp_path, table, key, "[]")
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: {table}.{key} is empty: "
                                         "give at least one"):
        read_study(path)


@pytest.mark.parametrize("table, key, value, message", [
    ("env.bounds", "max_speed_dev", "-1.0",
     r"env.bounds.max_speed_dev = -1.0: must lie in \(0, 1e\+06\]"),
    ("env", "fine_window", "nan", r"env.fine_window = nan: must be finite"),  # unused, checked
    ("compile", "precision", '"half"', r"compile.precision = 'half': must be one of"),
    ("compile", "sweeps", "0", r"compile.sweeps = 0: must lie in \[1, 100\]"),
    ("compile.loads", "p_z", "0.5", r"\[compile.loads\] LoadSplit: p_z \+ p_i \+ p_p = 0.5"),
    ("compile.motors", "vx_rule", '"x"', r"\[compile.motors\] vx_rule = 'x': allowed"),
    ("compile.motors", "stiff_below", "inf", r"compile.motors.stiff_below = inf: must be finite"),
    ("training", "history", "{lstm = 0}", r"training.history.lstm = 0: must lie in \[1, 1000\]"),
    ("training", "history", "{ppo = 1}", r"training.history.ppo = 1: 'ppo' is not a policy"),
    ("training", "task_sampling", '"all"', r"training.task_sampling = 'all': must be one of"),
    ("tasks.test", "operating_points", "[3]",
     r"tasks.test.operating_points = \[3\]: the study has 1 operating point"),
    ("env", "recovery_buses", "[504, 7, 8]", r"env.recovery_buses = \[504, 7, 8\]: buses \[8\] "
     r"are not observed buses \(observed_buses: .*study.toml: env.observed_buses\)"),
    ("env", "dt", "0.003", r"env.agent_dt = 0.1: must be a whole number \(>= 1\) of simulation "
     r"steps dt = 0.003 s \(dt: .*study.toml: env.dt\)"),
    ("grid", "raw", "0.0", r"grid.raw = 0.0: must be a path, a pattern or a list of them"),
    ("grid", "dyr", f'"{DYR}"', r"grid.dyr = .*: no such file"),
    ("grid", "load_levels", "[0.1]", r"\[grid\] ieee39_fidvr: load_level = 0.1"),
])
def test_every_study_file_error_names_the_file_and_the_table(tmp_path, table, key, value,
                                                              message):
    path = study_file(tmp_path, table, key, value)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: {message}"):
        read_study(path)


def test_settings_the_study_would_not_read_are_refused(shared_cases, tmp_path):
    """A built-in with files, load levels with RAW files, one RAW file twice (directly or
    through a pattern): each an error naming grid.KEY."""
    raw = shared_cases / BASE
    for grid, message in [
            (f'builtin = "ieee39_fidvr"\ndyr = "{shared_cases / DYR}"',
             r"grid.builtin = 'ieee39_fidvr': a built-in study reads no files: leave out dyr"),
            (f'raw = ["{raw}"]\ndyr = "{shared_cases / DYR}"\nload_levels = [0.9]',
             r"grid.load_levels = \[0.9\]: set a built-in study's operating points"),
            (f'raw = ["{raw}", "{raw.parent}/*smallX_v30.raw"]\ndyr = "{shared_cases / DYR}"',
             rf"grid.raw = .*: {re.escape(str(raw))} is listed more than once")]:
        path = tmp_path / "study.toml"
        path.write_text(f"[grid]\n{grid}\n")
        with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: {message}"):
            read_study(path)


@pytest.mark.parametrize("key, value, message", [
    ("faultBusCandidates", ["Bus4", 4], r"faultBusCandidates = \[4, 4\]: 4 is listed more than "
                                        "once"),
    ("actionBusesPValue", [86.0, 32.2], r"actionBusesPValue = \[86.0, 32.2\]: must give one value "
                                        r"per action bus \(3\)"),
])
def test_a_task_json_list_is_checked_again_once_its_buses_are_resolved(shared_cases, tmp_path,
                                                                       key, value, message):
    """"Bus4" and 4 are one bus: refused once resolved, named by the file's key."""
    path = task_file(shared_cases, tmp_path, key, value)
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: {message}"):
        from_files(shared_cases / BASE, shared_cases / DYR, path)


def test_the_api_checks_lists_too():
    with pytest.raises(ValueError, match=r"^study: tasks.test.fault_buses = \[4, 4\]: 4 is "
                                         "listed more than once"):
        builtin("ieee39_fidvr", tasks={"test": {"fault_buses": (4, 4)}})


def _warning(category, message) -> warnings.WarningMessage:
    return warnings.WarningMessage(message, category, "x.py", 1)


def test_notes_of_a_build_are_one_line_per_kind():
    """13 RAW files with the same skipped records and a study's notes: a header and two
    lines, each at most 120 characters, counting files and other messages."""
    caught = [_warning(RawWarning, f"/data/case{k}.raw: records not modelled, skipped: "
                                   "transformer tap control x5") for k in range(13)]
    caught += [_warning(StudyWarning, "study 'x': 13 note(s) in Study.notes (3 on t.json, 10 "
                                      "on s.json)"),
               _warning(UserWarning, "a " * 100), _warning(UserWarning, "b")]
    lines = warnings_summary(caught)
    assert lines[0].startswith("16 note(s) while building the study") and "--verbose" in lines[0]
    assert lines[1:3] == [
        "  RawWarning x13 (13 files): records not modelled, skipped: transformer tap control x5",
        "  StudyWarning x1: study 'x': 13 note(s) in Study.notes (3 on t.json, 10 on s.json)"]
    assert lines[3].startswith("  UserWarning x2: a a ") and lines[3].endswith(
        "a... [+1 other message(s)]") and len(lines[3]) == 120
    assert len(lines) == 4
    assert warnings_summary([]) == []


def test_a_task_json_as_evaluation_tasks_names_its_repeats(shared_cases, tmp_path):
    """`experiments.evaluate --tasks FILE.json`: the file's faults alone (`fault_set`)."""
    from jaxgrid.io.dyr import read_dyr
    from jaxgrid.io.raw import read_raw
    from jaxgrid.study.names import bus_table
    from jaxgrid.study.sources import fault_set

    path = task_file(shared_cases, tmp_path, "faultBusCandidates", ["Bus4", "Bus15", 4])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RawWarning)
        buses = bus_table(read_raw(shared_cases / BASE), read_dyr(shared_cases / DYR))
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: faultBusCandidates = "
                                         r"\[4, 15, 4\]: 4 is listed more than once"):
        fault_set(read_task_config(path), buses)


@pytest.mark.parametrize("verbose", [False, True])
def test_commands_print_the_notes_of_a_build_summarised_or_in_full(capsys, verbose):
    """`summarised_notes` (what every command wraps a study build in): on stderr, after the
    block, the summary or (--verbose) every message."""
    from experiments.common.studyargs import summarised_notes

    with summarised_notes(verbose):
        for k in range(3):
            warnings.warn(f"/data/case{k}.raw: records not modelled, skipped: facts x1",
                          RawWarning)
    err = capsys.readouterr().err.splitlines()
    if verbose:
        assert err == [f"RawWarning: /data/case{k}.raw: records not modelled, skipped: facts x1"
                       for k in range(3)]
    else:
        assert err[1:] == ["  RawWarning x3 (3 files): records not modelled, skipped: facts x1"]
