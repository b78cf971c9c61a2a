"""The commands' persistent compilation cache (`experiments.XLA_CACHE`): on by default under
the home folder with a size limit, a folder the user set kept as JAX's settings have it, off
with JAXGRID_XLA_CACHE=0 and in the benchmarks and the commands they start; a compile lands
in it. Checked in fresh processes (JAX reads the settings when it is imported)."""
import json
import os
import subprocess
import sys

from conftest import REPO

SHOW = ("import json, os; import experiments; first = dict(os.environ); "
        "import experiments.bench; print(json.dumps([first.get(k) for k in KEYS] + "
        "[os.environ.get(k) for k in KEYS]))")
KEYS = ("JAX_COMPILATION_CACHE_DIR", "JAX_COMPILATION_CACHE_MAX_SIZE", "JAXGRID_XLA_CACHE")


def _settings(tmp_path, **env):
    """(after `import experiments`, after `import experiments.bench`): the three variables."""
    base = {k: v for k, v in os.environ.items() if k not in KEYS}
    out = subprocess.run([sys.executable, "-c", f"KEYS = {KEYS!r}; {SHOW}"], cwd=REPO,
                         env={**base, "HOME": str(tmp_path), "PYTHONPATH": str(REPO), **env},
                         capture_output=True, text=True, check=True).stdout
    values = json.loads(out)
    return tuple(values[:3]), tuple(values[3:])


def test_commands_cache_compiles_under_home_and_benchmarks_do_not(tmp_path):
    command, bench = _settings(tmp_path)
    assert command == (str(tmp_path / ".cache" / "jaxgrid" / "xla"), str(2 * 1024 ** 3), None)
    assert bench == (None, str(2 * 1024 ** 3), "0"), "a benchmark and what it starts compile"
    mine = str(tmp_path / "mine")
    assert _settings(tmp_path, JAX_COMPILATION_CACHE_DIR=mine)[0] == (mine, None, None), \
        "the user's folder kept, no size limit added (JAX's eviction fails on entries written "\
        "without one)"
    assert _settings(tmp_path, JAXGRID_XLA_CACHE="0")[0] == (None, None, "0")


def test_a_command_s_compile_lands_in_the_cache(tmp_path):
    """A program compiled after `import experiments` is written to the cache folder, size
    limit and all (JAX's limited cache needs the `filelock` package; without it JAX turns
    the cache off without a word)."""
    base = {k: v for k, v in os.environ.items() if k not in KEYS}
    subprocess.run([sys.executable, "-c", "import experiments, jax; "
                    "jax.jit(lambda x: x + 1)(1.0).block_until_ready()"], cwd=REPO,
                   env={**base, "HOME": str(tmp_path), "PYTHONPATH": str(REPO),
                        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"}, check=True)
    assert list((tmp_path / ".cache" / "jaxgrid" / "xla").glob("jit_*-cache"))
