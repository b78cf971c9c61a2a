"""Benchmarks, one command each: `python -m experiments.bench.<name>`.

`make bench` writes their JSON reports to benchmarks/cpu/; the GPU records are kept beside
it in benchmarks/h100/ and benchmarks/h200/. `timing` holds what they share: the timer, the
device sweep and the report writer.

Importing the package asks XLA for two host CPU devices, so that a benchmark can shard its
batch over 1 and 2 devices, and turns off the commands' compilation cache
(`experiments.XLA_CACHE`) here and in the commands a benchmark starts, so that first calls
compile; this runs before any benchmark module imports JAX.
"""
import os

from experiments import XLA_CACHE

os.environ["JAXGRID_XLA_CACHE"] = "0"
if os.environ.get("JAX_COMPILATION_CACHE_DIR") == str(XLA_CACHE):
    del os.environ["JAX_COMPILATION_CACHE_DIR"]
os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                           + " --xla_force_host_platform_device_count=2").strip()
