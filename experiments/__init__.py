"""Command-line experiments (`python -m experiments.<name>`) and benchmarks
(`python -m experiments.bench.<name>`).

Every command keeps XLA's compiled programs in a persistent cache, `XLA_CACHE`
(~/.cache/jaxgrid/xla, at most `XLA_CACHE_BYTES`, the least recently used evicted): a second
training, resume or evaluation of the same study and settings loads its large programs instead
of compiling them (the PNNL 39-bus test-set evaluation of the committed policy: 15.9 s cold,
9.4 s warm, 2-core machine; docs/performance.md). JAX_COMPILATION_CACHE_DIR chooses another
folder (JAX's settings as they are, no size limit unless JAX_COMPILATION_CACHE_MAX_SIZE says
so); JAXGRID_XLA_CACHE=0 turns the cache off. The benchmarks do not use it (they time
compiles), nor does a process that imported JAX before this package (JAX reads the setting on
import).
"""
import os
from pathlib import Path

XLA_CACHE = Path.home() / ".cache" / "jaxgrid" / "xla"
XLA_CACHE_BYTES = 2 * 1024 ** 3

# the size limit only with this folder: JAX's limited cache keeps access-time files that a
# folder written without the limit lacks, and its eviction fails on such entries
if (os.environ.get("JAXGRID_XLA_CACHE", "1") != "0"
        and "JAX_COMPILATION_CACHE_DIR" not in os.environ):
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(XLA_CACHE)
    os.environ.setdefault("JAX_COMPILATION_CACHE_MAX_SIZE", str(XLA_CACHE_BYTES))
