"""Shared test setup: two CPU devices for sharding tests, compiles made cheap and shared,
paths to reference data.

XLA compiles take most of the suite's time (measured: 60 % of the CPU time of the heaviest
files), so the tests compile with XLA's backend optimisation level 0 (LLVM unoptimised: a
third less CPU time on test_ars, a fifth on test_gridpack_reference's six-second runs; the
arithmetic is the same IEEE arithmetic) and with XLA:CPU's loop emitters in place of its
newer fusion emitters (`--xla_cpu_use_fusion_emitters=false`: test_ars 15-16 s instead of
25-26 s, test_reproduce with test_step_accuracy 179 s instead of 243 s, measured alternately
in one run; XLA:CPU's older code generator for fused loops, whose results agree to float
rounding: the suite passes with either), each unless XLA_FLAGS sets it; `make bench` and the
experiments run with XLA's defaults. They share one persistent compilation cache per run: a
program compiled by one test file, one pytest-xdist worker or one process a test starts is
loaded, not compiled again, by the others (a fresh folder, removed at the end; set
JAX_COMPILATION_CACHE_DIR to keep one across runs). These environment variables must be set
before JAX is imported anywhere, hence at the top here; the processes the tests start
inherit them.
"""
import atexit
import os
import shutil
import tarfile
import tempfile

_flags = [flag for flag in os.environ.get("XLA_FLAGS", "").split()
          if not flag.startswith("--xla_force_host_platform_device_count")]
for _name, _value in (("--xla_backend_optimization_level", "0"),
                      ("--xla_cpu_use_fusion_emitters", "false")):
    if not any(flag.startswith(_name) for flag in _flags):
        _flags.append(f"{_name}={_value}")
os.environ["XLA_FLAGS"] = " ".join(_flags + ["--xla_force_host_platform_device_count=2"])
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:  # set here: workers and processes inherit
    os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxgrid-tests-xla-")
    atexit.register(shutil.rmtree, os.environ["JAX_COMPILATION_CACHE_DIR"], True)
# every program, not only those compiling for over 1 s (JAX's default): the processes the
# tests start compile the same small ones (measured: 10 % less CPU time on test_train's
# multi-process and resume tests, none more on a one-process file)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# resolved, as the readers and study files report input paths: a test that matches an error
# message against a case path then holds where ../shared is a symbolic link
SHARED_CASES = (REPO.parent / "shared" / "cases").resolve()


def raw_v33(buses: str, loads: str = "", generators: str = "", branches: str = "", *,
            rev: int = 33, two_terminal_dc: str = "", facts: str = "") -> str:
    """A PSS/E v33 RAW text from record blocks (each block: newline-terminated lines)."""
    return (
        f"0, 100.00, {rev}, 0, 1, 60.00 / jaxgrid input-error test\n"
        "HAND WRITTEN TEST CASE\n"
        "FOR ERROR MESSAGES\n"
        f"{buses}0 / END OF BUS DATA, BEGIN LOAD DATA\n"
        f"{loads}0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA\n"
        "0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA\n"
        f"{generators}0 / END OF GENERATOR DATA, BEGIN BRANCH DATA\n"
        f"{branches}0 / END OF BRANCH DATA, BEGIN TRANSFORMER DATA\n"
        "0 / END OF TRANSFORMER DATA, BEGIN AREA DATA\n"
        "0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA\n"
        f"{two_terminal_dc}0 / END OF TWO-TERMINAL DC DATA, BEGIN VSC DC LINE DATA\n"
        "0 / END OF VSC DC LINE DATA, BEGIN IMPEDANCE CORRECTION DATA\n"
        "0 / END OF IMPEDANCE CORRECTION DATA, BEGIN MULTI-TERMINAL DC DATA\n"
        "0 / END OF MULTI-TERMINAL DC DATA, BEGIN MULTI-SECTION LINE DATA\n"
        "0 / END OF MULTI-SECTION LINE DATA, BEGIN ZONE DATA\n"
        "0 / END OF ZONE DATA, BEGIN INTER-AREA TRANSFER DATA\n"
        "0 / END OF INTER-AREA TRANSFER DATA, BEGIN OWNER DATA\n"
        "0 / END OF OWNER DATA, BEGIN FACTS DEVICE DATA\n"
        f"{facts}0 / END OF FACTS DEVICE DATA, BEGIN SWITCHED SHUNT DATA\n"
        "0 / END OF SWITCHED SHUNT DATA, BEGIN GNE DATA\n"
        "0 / END OF GNE DATA, BEGIN INDUCTION MACHINE DATA\n"
        "0 / END OF INDUCTION MACHINE DATA\n"
        "Q\n"
    )


def stored_mismatch(case):
    """Per-bus complex power mismatch (n_bus,) of the voltages stored in a RAW file, p.u.:
    how far the original tool's solution is from satisfying our reading of the data."""
    import numpy as np

    from jaxgrid.powerflow import admittance_matrix, bus_loads

    v = case.buses.vm * np.exp(1j * case.buses.va)
    s_power, s_current, s_impedance = bus_loads(case)
    gen = case.generators
    s_gen = np.zeros(case.n_bus, complex)
    np.add.at(s_gen, gen.bus[gen.in_service], (gen.pg + 1j * gen.qg)[gen.in_service])
    return (v * np.conj(admittance_matrix(case) @ v) - s_gen + s_power
            + s_current * case.buses.vm + s_impedance * case.buses.vm ** 2)


def andes_cases_dir() -> Path:
    """Folder of the PSS/E test files bundled with the andes package (a test dependency)."""
    import importlib.util

    spec = importlib.util.find_spec("andes")
    assert spec is not None and spec.origin, "andes is a test dependency: pip install -e '.[test]'"
    return Path(spec.origin).parent / "cases"


@pytest.fixture(scope="session")
def ieee39():
    """The built-in `ieee39_fidvr` study, built once per session (per xdist worker) and shared
    by the files that read it: a `Study` is immutable (frozen dataclasses, host arrays)."""
    from jaxgrid.study import builtin

    return builtin("ieee39_fidvr")


@pytest.fixture(scope="session")
def shared_cases() -> Path:
    """../shared/cases, the PNNL reference inputs (read in place, never copied)."""
    assert SHARED_CASES.is_dir(), f"reference cases not found at {SHARED_CASES}"
    return SHARED_CASES


GRIDPACK_TARBALL = SHARED_CASES.parent / "reference" / "gridpack" / "gridpack-src.tar.gz"
DATA_SETS = "src/applications/data_sets"


@pytest.fixture(scope="session")
def gridpack_data() -> Path:
    """GridPACK's data sets (`src/applications/data_sets` of its source tree): under
    $GRIDPACK_SRC or $GRIDPACK_HOME/gridpack (default /opt/gridpack/gridpack), else unpacked
    once per test process from ../shared/reference/gridpack/gridpack-src.tar.gz into a
    temporary folder (its data-set files, 9.5 MB); an error, not a skip, when neither is
    there (the tests need ../shared, as for the PNNL cases)."""
    roots = [os.environ.get("GRIDPACK_SRC"),
             str(Path(os.environ.get("GRIDPACK_HOME", "/opt/gridpack")) / "gridpack")]
    for root in filter(None, roots):
        folder = Path(root) / DATA_SETS
        if folder.is_dir():
            return folder
    target = Path(tempfile.mkdtemp(prefix="jaxgrid-tests-gridpack-"))
    atexit.register(shutil.rmtree, target, True)
    with tarfile.open(GRIDPACK_TARBALL) as tar:
        members = [m for m in tar.getmembers() if f"/{DATA_SETS}/" in f"/{m.name}"]
        tar.extractall(target, members=members, filter="data")
    (top,) = {m.name.split(f"/{DATA_SETS}/")[0] for m in members if m.isfile()}
    return target / top / DATA_SETS


# The files that take longest (measured with --durations), longest first: `make test` hands
# whole files to its two workers in collection order (--dist loadfile
# --no-loadscope-reorder), so these start first and no long file starts last.
LONGEST_FIRST = ("test_reproduce.py", "test_train.py", "test_study.py", "test_cmld.py",
                 "test_env.py", "test_mpc.py", "test_simulate.py", "test_ppo.py",
                 "test_step_accuracy.py", "test_gridpack_reference.py", "test_notebook.py")


def pytest_collection_modifyitems(items):
    """Items of the LONGEST_FIRST files first, in that order; the rest as collected."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
