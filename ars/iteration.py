"""One training iteration as the composition of a search strategy and a problem (the model of
RobertTLange/evosax's `ask`/`tell`), jit-compiled:

    thetas  = strategy.ask(state, key)                        # (P, size) parameter vectors
    tasks   = m tasks drawn (the same for every θ)
    out     = evaluate(thetas, (mean, std), tasks, data)      # the problem: (P, m) episodes
    returns = the mean over the tasks, non-finite ones replaced by the lowest finite one (or
              the mean of each task's z-scores or centred ranks: `returns_of`)
    state   = strategy.tell(state, key, thetas, returns)
    then the observation statistics of every episode merged in (ARS V2's normaliser).

The problem's `evaluate` owns how its episodes are batched and sharded over the devices of
the mesh (a grid's: `jaxgrid.population.evaluator`); the strategy owns the search (PARS:
`ars.pars.Pars`; any other is a new file, e.g. `ars.es.PlainEs`). The tasks and whatever
else the episodes read (`data`, e.g. the grid models) are arguments of the compiled
iteration, not constants: new tasks or data of the same shapes reuse the compilation.
Nothing here knows about grids.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ars import normalizer
from ars.normalizer import RunningStats
from ars.policies import Policy


@struct.dataclass
class TrainState:
    """Everything an iteration changes (what a checkpoint holds).

    Attributes:
      theta: (size,) policy parameters: the strategy's current solution.
      stats: observation RunningStats.  key: PRNG key.  iteration: () int.
      step_size: α now.  noise: ν now (the strategy's step and spread).
    """

    theta: jnp.ndarray
    stats: RunningStats
    key: jnp.ndarray
    iteration: jnp.ndarray
    step_size: jnp.ndarray
    noise: jnp.ndarray


class Strategy(Protocol):
    """A search over flat parameter vectors (evosax's `ask`/`tell`). Its state is the
    `TrainState`: a strategy reads and writes theta, step_size and noise, the iteration
    keeps the rest (key, iteration, stats).

    Attributes:
      population: P, the vectors of one `ask` (static).
    """

    population: int

    def ask(self, state: TrainState, key) -> jnp.ndarray:
        """(P, size) parameter vectors to evaluate."""

    def tell(self, state: TrainState, key, thetas, returns) -> TrainState:
        """The state after the returns (P,) of `thetas`, asked with `key` (a strategy may
        redraw from `key` what `ask` drew rather than keep it)."""


def initial_state(policy: Policy, step_size: float, noise: float, seed: int,
                  obs_std_floor: float | None = None, seeds: int | None = None) -> TrainState:
    """θ = 0, empty statistics (with `obs_std_floor`), the seed's key, α = step_size and
    ν = noise. With `seeds`, the states of seeds seed, seed + 1, ... stacked on a leading
    axis (for `make_iteration(..., seeds=...)`)."""

    def one(key):
        return TrainState(theta=policy.initial_theta(),
                          stats=RunningStats.empty(policy.spec.obs_size, obs_std_floor),
                          key=key, iteration=jnp.zeros((), jnp.int32),
                          step_size=jnp.asarray(step_size, jnp.float32),
                          noise=jnp.asarray(noise, jnp.float32))

    if seeds is not None:
        return jax.vmap(lambda s: one(jax.random.PRNGKey(s)))(jnp.arange(seed, seed + seeds))
    return one(jax.random.PRNGKey(seed))


def clean_returns(returns):
    """Non-finite returns replaced by the lowest finite one (0 if none is finite): a
    diverged episode can never rank first."""
    finite = jnp.isfinite(returns)
    floor = jnp.min(jnp.where(finite, returns, jnp.inf))
    floor = jnp.where(jnp.isfinite(floor), floor, 0.0)
    return jnp.where(finite, returns, floor)


TASK_RETURNS = ("mean", "ranks", "ranks+mean", "zscores")


def centred_ranks(values):
    """(P, k) ranks of each column's P values in [−0.5, 0.5], equal values sharing their mean
    rank; non-finite values rank lowest."""
    values = jnp.where(jnp.isfinite(values), values, -jnp.inf)
    below = (values[None, :, :] < values[:, None, :]).sum(1)  # (P, k): how many below
    equal = (values[None, :, :] == values[:, None, :]).sum(1)  # itself included
    return (below + 0.5 * (equal - 1)) / max(values.shape[0] - 1, 1) - 0.5


def returns_of(rewards, how: str = "mean"):
    """(P,) returns of the (P, m) episode rewards of P vectors on the same m tasks.

    "mean": the mean over the tasks (the paper's), so a task weighs by its rewards' spread:
    one whose episodes fail or recover by the perturbation (a spread of thousands) outweighs
    one where they differ by the load shed (tens). "zscores": the mean over the tasks of each
    task's rewards less their mean over the P, divided by their standard deviation (a task on
    which all P are equal adds 0): every task's spread weighs alike, and within a task a
    failure still costs what it costs against the others. "ranks": the mean over the tasks
    of each task's centred ranks in [−0.5, 0.5] among the P (the fitness shaping of Salimans
    et al. 2017, per task), equal rewards sharing their mean rank: every task weighs alike
    and only the order counts. "ranks+mean": "ranks" plus the centred rank of the mean
    reward among the P, so that the order by the paper's return (where one failed task
    outweighs less shedding on several) weighs as much as every task's order together.
    Non-finite rewards count as the lowest finite one (ranks: rank lowest). ValueError for
    another `how`.
    """
    if how == "mean":
        return clean_returns(rewards.mean(axis=1))
    if how == "zscores":
        rewards = clean_returns(rewards)
        spread = rewards.std(axis=0)
        scaled = (rewards - rewards.mean(axis=0)) / jnp.where(spread > 0, spread, 1.0)
        return scaled.mean(axis=1)
    if how not in ("ranks", "ranks+mean"):
        raise ValueError(f"task_returns = {how!r}: allowed {', '.join(TASK_RETURNS)}")
    per_task = centred_ranks(rewards).mean(axis=1)
    if how == "ranks":
        return per_task
    return per_task + centred_ranks(rewards.mean(axis=1, keepdims=True))[:, 0]


def default_mesh() -> Mesh:
    """A 1-D mesh (axis "batch") over every device."""
    return Mesh(np.array(jax.devices()), ("batch",))


def make_iteration(strategy: Strategy, evaluate: Callable, tasks_per_iteration: int,
                   sample=None, mesh: Mesh | None = None, seeds: int | None = None,
                   task_returns: str = "mean"):
    """`iteration(state, tasks, data) -> (state, metrics)`, jit-compiled (`iteration.compiled`).

    evaluate(thetas (P, size), (mean, std), tasks (m, ...), data) -> dict of (P, m, ...)
    episode results: "reward", "policy_carry" (`ars.normalizer.normalized_policy`'s final
    carry) and optionally "steps" (the problem's `evaluator`). tasks: pytree with a leading
    axis of n_tasks; sample(key) -> (m,) int task indices (default: m distinct tasks
    uniformly). State and metrics are replicated over `mesh` (default all devices). With
    `seeds`, the state (from `initial_state(..., seeds=...)`) and the metrics have a leading seed
    axis: independent trainings of one configuration vmapped into one program, sharing the
    tasks and data. The strategy is told `returns_of(rewards, task_returns)`.
    Metrics: reward_mean, reward_max (over the P mean rewards), rollouts (P·m) and, where
    the episodes report steps, env_steps. ValueError if the P vectors do not split over the
    mesh's devices (the problem's evaluate splits them).
    """
    m = tasks_per_iteration
    mesh = mesh or default_mesh()
    if strategy.population % mesh.size:
        raise ValueError(f"{strategy.population} parameter vectors (the strategy's "
                         f"population) do not split over {mesh.size} devices")

    def iteration(state: TrainState, tasks, data):
        n_tasks = int(jax.tree.leaves(tasks)[0].shape[0])
        key, k_ask, k_task = jax.random.split(state.key, 3)
        thetas = strategy.ask(state, k_ask)
        chosen = (sample(k_task) if sample is not None
                  else jax.random.choice(k_task, n_tasks, (m,), replace=False))
        picked = jax.tree.map(lambda a: a[chosen], tasks)
        out = evaluate(thetas, (state.stats.mean, state.stats.std), picked, data)
        returns = returns_of(out["reward"])
        new = strategy.tell(state, k_ask, thetas, returns_of(out["reward"], task_returns))
        _, (count, total, total_sq) = out["policy_carry"]
        stats = normalizer.merge(state.stats, count.sum(), total.sum((0, 1)),
                                 total_sq.sum((0, 1)))
        new = new.replace(stats=stats, key=key, iteration=state.iteration + 1)
        metrics = {"reward_mean": returns.mean(), "reward_max": returns.max(),
                   "rollouts": jnp.asarray(strategy.population * m)}
        if "steps" in out:  # environment steps simulated: failed episodes stop early
            metrics["env_steps"] = out["steps"].sum()
        return new, metrics

    replicated = NamedSharding(mesh, PartitionSpec())
    step = jax.vmap(iteration, in_axes=(0, None, None)) if seeds is not None else iteration
    compiled = jax.jit(step, in_shardings=replicated, out_shardings=replicated)

    def run(state: TrainState, tasks, data=None):
        n_tasks = int(jax.tree.leaves(tasks)[0].shape[0])
        if sample is None and m > n_tasks:
            raise ValueError(f"tasks_per_iteration = {m}: only {n_tasks} tasks available "
                             "(lower ParsConfig.tasks_per_iteration, or pass more tasks)")
        # fresh inputs live on one device or the host: place them as the compiled function
        # returns the state, so the first and later calls share one compilation
        return compiled(*jax.device_put((state, tasks, data), replicated))

    run.compiled = compiled
    return run
