"""A population of policies evaluated on a batch of tasks: how a trainer's problem runs its
episodes (the `evaluate` of `ars.iteration.make_iteration`, built by `evaluator`).

- The P parameter vectors are split over a 1-D device mesh by `jax.shard_map`: each device
  runs its share on its own, so a loop that stops once its batch is done waits for the
  device's own episodes, with no cross-device reduction per step.
- On a device, a vmap over its vectors of a vmap over the m tasks: a task's data (its grid
  model) is shared by its episodes and each vector by its m episodes, so the policy runs as
  batched products over the tasks. Both vmaps keep the batch as every array's last axis
  (`jaxgrid.batching.vmap_minor`; the vectors the minor one, so XLA:CPU's loops run over
  them), and the policy network runs batch-first (`jaxgrid.batching.batch_major`, which the
  problem wraps it in: `jaxgrid.problem.GridProblem.network`) with the vectors
  kept batch-first, so each vector's weights are read in place.
- With `task_batch`, the tasks run in batches of that many, one batch after another; with
  `compact_after`, a batch's episodes still running after that many agent steps continue
  regrouped in smaller chunks (`_regrouped`), so episodes that ended stop costing.

The episode is any function `episode(apply, params, task, carry, data) -> dict` (for
`compact_after` also `begin`, `resume`, `done` and `result`: `jaxgrid.problem.PointEpisode`);
nothing here knows about grids or imports `ars`.
"""
from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxgrid.batching import vmap_minor

_thetas = functools.partial(vmap_minor, first=True)  # the vectors stay batch-first
_lanes = functools.partial(vmap_minor, first=(True, False, False))
PHASES = ("begin", "resume", "done", "result")  # what a regrouped episode offers


def evaluator(episode, apply: Callable, carry, mesh: Mesh, task_batch: int | None = None,
              compact_after: int | None = None, compact_chunks: int = 4) -> Callable:
    """evaluate(thetas (P, size), shared, tasks (m, ...), data) -> the episodes' dict with
    leading axes (P, m): `episode(apply, (θ, *shared), task, carry, data)` for every vector
    and task (module docstring), P (a multiple of the mesh's devices) split over `mesh`
    (1-D). task_batch, compact_after, compact_chunks: `ars.pars.ParsConfig`'s fields of those
    names. ValueError for an episode that cannot be regrouped."""
    if compact_after is not None and not all(hasattr(episode, f) for f in PHASES):
        raise ValueError(f"compact_after = {compact_after}: the episode must run in two parts "
                         f"({', '.join(PHASES)}; e.g. jaxgrid.problem.PointEpisode), or set "
                         "compact_after None")
    (axis,) = mesh.axis_names
    spread = NamedSharding(mesh, PartitionSpec(axis))

    def rollouts(thetas, tasks, shared, data):  # one device's share of the vectors
        def per_batch(batch):  # (c, ...) tasks -> (P/devices, c, ...) episode results
            if compact_after is not None:
                return _regrouped(episode, apply, thetas, batch, shared, carry, data,
                                  compact_after, compact_chunks)
            return _thetas(lambda theta: vmap_minor(
                lambda task: episode(apply, (theta, *shared), task, carry, data))(batch))(
                    thetas)

        m = int(jax.tree.leaves(tasks)[0].shape[0])
        return _in_batches(per_batch, tasks, task_batch or m)

    local = jax.shard_map(rollouts, mesh=mesh, in_specs=(PartitionSpec(axis),) +
                          (PartitionSpec(),) * 3, out_specs=PartitionSpec(axis),
                          check_vma=False)

    def evaluate(thetas, shared, tasks, data):
        return local(jax.lax.with_sharding_constraint(thetas, spread), tasks, shared, data)

    return evaluate


def _in_batches(run, tasks, size: int):
    """run(batch of c tasks) -> (n_θ, c, ...) results, over the m tasks (leading axis) in
    batches of `size`, one after another; returns (n_θ, m, ...)."""
    m = int(jax.tree.leaves(tasks)[0].shape[0])
    n_full = m // size
    head = jax.tree.map(lambda a: a[:n_full * size].reshape((n_full, size) + a.shape[1:]), tasks)
    out = jax.lax.map(run, head)  # (n_full, n_θ, size, ...)
    out = jax.tree.map(lambda a: jnp.moveaxis(a, 0, 1).reshape(
        (a.shape[1], n_full * size) + a.shape[3:]), out)
    if n_full * size < m:
        tail = run(jax.tree.map(lambda a: a[n_full * size:], tasks))
        out = jax.tree.map(lambda a, b: jnp.concatenate([a, b], axis=1), out, tail)
    return out


def _regrouped(episode, apply, thetas, batch, shared, carry, data, compact_after: int,
               compact_chunks: int):
    """The (n_θ, c, ...) results of every θ of `thetas` (n_θ, size) on every task of `batch`
    (c tasks): all n_θ·c episodes run `compact_after` agent steps together
    (`episode.begin`), then those still running are regrouped, running first, and continue
    to their end (`episode.resume`) in chunks of ⌈n_θ·c / compact_chunks⌉, as many as they
    fill."""
    n_theta, c = thetas.shape[0], int(jax.tree.leaves(batch)[0].shape[0])
    lanes = n_theta * c
    size = -(-lanes // compact_chunks)
    loops = _thetas(lambda theta: vmap_minor(lambda task: episode.begin(
        apply, (theta, *shared), task, carry, data, compact_after))(batch))(thetas)
    loops = jax.tree.map(lambda a: a.reshape((lanes,) + a.shape[2:]), loops)
    running = ~jax.vmap(episode.done)(loops)
    order = jnp.argsort(~running, stable=True)  # lane = θ index · c + task index

    def chunk(k, loops):
        lane = order[jnp.minimum(k * size + jnp.arange(size), lanes - 1)]
        # one task: shared by the chunk (its data is not gathered per rollout)
        tasks = jax.tree.map(lambda a: a[0] if c == 1 else a[lane % c], batch)
        part = _lanes(lambda theta, task, loop: episode.resume(
            apply, (theta, *shared), task, data, loop), (0, None if c == 1 else 0, 0))(
                thetas[lane // c], tasks, jax.tree.map(lambda a: a[lane], loops))
        return jax.tree.map(lambda a, b: a.at[lane].set(b), loops, part)

    loops = jax.lax.fori_loop(0, (running.sum() + size - 1) // size, chunk, loops)
    out = jax.vmap(episode.result)(loops)
    return jax.tree.map(lambda a: a.reshape((n_theta, c) + a.shape[1:]), out)
