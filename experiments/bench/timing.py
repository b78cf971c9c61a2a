"""What the benchmarks share: wall-clock timing of a JAX call, a sweep over device counts
and batch sizes, and the JSON report that says what machine and JAX measured it."""
from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    """Call `fn()` and wait for its arrays: (its output, wall seconds)."""
    start = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - start


def sharded_timings(batch_sizes, device_counts, repeats: int, make_tasks, run):
    """Time `run(tasks)` with `make_tasks(batch)` sharded over a 1-D mesh of the first n
    devices, for every device count n and every batch size n divides.

    Yields (n, batch, output of the first call, first-call s, best of `repeats` warm calls s).
    """
    for n_dev in device_counts:
        sharding = NamedSharding(Mesh(np.array(jax.devices()[:n_dev]), ("batch",)),
                                 PartitionSpec("batch"))
        for batch in batch_sizes:
            if batch % n_dev:
                continue
            tasks = jax.device_put(make_tasks(batch), sharding)
            out, first = timed(lambda: run(tasks))
            warm = min(timed(lambda: run(tasks))[1] for _ in range(repeats))
            yield n_dev, batch, out, first, warm


def write_report(path: str, **fields) -> None:
    """Write the benchmark JSON: machine, JAX version, backend, device kind and count, then
    `fields`; say where it went."""
    report = {"machine": platform.processor() or platform.machine(), "jax": jax.__version__,
              "backend": jax.default_backend(), "device_kind": jax.devices()[0].device_kind,
              "devices": len(jax.devices()), **fields}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(report, indent=2))
    print(f"wrote {path}")
