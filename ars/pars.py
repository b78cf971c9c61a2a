"""The PARS iteration (PNNL PARS study, Algorithm 1; ARS V2-t of Mania et al. 2018).

One jit-compiled function does a whole iteration:
  1. sample N directions δ ~ N(0, I) over the flat policy vector θ;
  2. build the 2N vectors θ ± ν·δ and pick m tasks (the same for every direction and sign,
     so r+ − r− measures the perturbation alone), uniformly or by a given sampler;
  3. roll out all 2N·m (θ, task) pairs as a vmap over the 2N vectors (split over a 1-D
     device mesh by `jax.shard_map`: each device runs its share of the vectors on its own,
     so a loop that stops once its batch is done waits for the device's own rollouts, with
     no cross-device reduction per step) of a vmap over the m tasks: a task's data (its
     grid model) is shared by its 2N rollouts and each vector by its m rollouts, so the policy
     runs as 2N batched products over the tasks; observations normalised by the frozen
     running stats. Both vmaps are passed in (`Vmaps`, default `jax.vmap`); a grid passes
     `jaxgrid.batching.vmap_minor`, which keeps the batch as every array's last axis (the
     2N vectors the minor one, so XLA:CPU's loops run over them), with the policy network
     run batch-first (`batch_major`, θ kept batch-first) so each direction's weights are
     read in place. With `task_batch`, the tasks run in batches of that many, one batch
     after another; with `compact_after`, a batch's episodes still running after that many
     agent steps continue regrouped in smaller chunks (`_regrouped`);
  4. average the returns per ± direction, keep the top b directions by max(r+, r−);
  5. θ += α / (b·σ_b) Σ_top (r+ − r−)·δ, σ_b the std of the 2b selected returns (1 if 0);
  6. α ← ε·α, ν ← ε·ν; merge the observation statistics of every rollout.
A non-finite return is replaced by the lowest finite return of the iteration, so it can
never rank first. The tasks and whatever else the episode needs (`data`, e.g. the grid
models) are arguments of the compiled iteration, not constants: new tasks or data of the
same shapes reuse the compilation. Nothing here knows about grids.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ars import normalizer
from ars.normalizer import RunningStats
from ars.policies import Policy


@dataclasses.dataclass(frozen=True)
class ParsConfig:
    """Hyper-parameters (defaults: the study's 39-bus run).

    Attributes:
      directions: N.  top: b (<= N).  step_size: α.  noise: ν.  decay: ε in (0, 1].
      tasks_per_iteration: m, tasks drawn (without replacement) per iteration.
      task_batch: tasks whose 2N rollouts run as one batch (None: all m). Batches run one
        after another, and a batch stops once all its episodes are done (episodes that fail
        early stop costing), at the price of smaller batches. Results are equal to float
        rounding (batches of other sizes compile apart; a borderline episode can flip).
      compact_after: agent steps after which a batch's episodes still running continue
        regrouped (None: never). All of a device's episodes of a task batch run this many
        steps together; those still running then run to their end in chunks of
        1/`compact_chunks` of them, as many chunks as they fill, so episodes that ended
        (e.g. failed a recovery check) stop costing. The episode must offer `begin`,
        `resume`, `done` and `result` (`jaxgrid.rollouts.PointEpisode`). Results are equal
        to float rounding, as for `task_batch`.
      compact_chunks: see `compact_after`.
      obs_std_floor: the normaliser's smallest standard deviation of a varying input, in the
        input's units (`ars.normalizer.RunningStats.floor`; None: none, as the paper).
      seed: PRNG seed.
    """

    directions: int = 16
    top: int = 8
    step_size: float = 1.0
    noise: float = 2.0
    decay: float = 0.99
    tasks_per_iteration: int = 9
    task_batch: int | None = None
    compact_after: int | None = None
    compact_chunks: int = 4
    obs_std_floor: float | None = None
    seed: int = 0

    def __post_init__(self):
        checks = {
            "directions": (self.directions >= 1, ">= 1"),
            "top": (1 <= self.top <= self.directions, f"in [1, directions = {self.directions}]"),
            "step_size": (self.step_size > 0, "> 0"),
            "noise": (self.noise > 0, "> 0"),
            "decay": (0 < self.decay <= 1, "in (0, 1]"),
            "tasks_per_iteration": (self.tasks_per_iteration >= 1, ">= 1"),
            "task_batch": (self.task_batch is None
                           or 1 <= self.task_batch <= self.tasks_per_iteration,
                           f"None or in [1, tasks_per_iteration = {self.tasks_per_iteration}]"),
            "compact_after": (self.compact_after is None or self.compact_after >= 1,
                              "None or >= 1"),
            "compact_chunks": (self.compact_chunks >= 1, ">= 1"),
            "obs_std_floor": (self.obs_std_floor is None or self.obs_std_floor > 0,
                              "None or > 0"),
        }
        for name, (ok, allowed) in checks.items():
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r}: allowed {allowed}")


def _unchanged(fun: Callable) -> Callable:
    return fun


@dataclasses.dataclass(frozen=True)
class Vmaps:
    """How an iteration batches its rollouts: `jax.vmap`-like transforms (default `jax.vmap`).

    Attributes:
      thetas: `thetas(fun)(thetas)`, `fun` batched over the (2N, size) perturbed vectors.
      tasks: `tasks(fun)(tasks)`, `fun` batched over a batch of tasks (leading axis).
      network: applied to the policy network `apply(θ, obs, carry)` before the vmaps meet
        it (e.g. `jaxgrid.batching.batch_major`); default unchanged.
      lanes: `lanes(fun, in_axes)(thetas, tasks, loops)`, `fun` batched over the three
        (one θ, task (or one shared, in_axes None) and episode loop per rollout:
        `ParsConfig.compact_after`'s chunks).
    """

    thetas: Callable = jax.vmap
    tasks: Callable = jax.vmap
    network: Callable = _unchanged
    lanes: Callable = jax.vmap


@struct.dataclass
class TrainState:
    """Everything an iteration changes.

    Attributes:
      theta: (size,) policy parameters.  stats: observation RunningStats.
      key: PRNG key.  iteration: () int.  step_size: α now.  noise: ν now.
    """

    theta: jnp.ndarray
    stats: RunningStats
    key: jnp.ndarray
    iteration: jnp.ndarray
    step_size: jnp.ndarray
    noise: jnp.ndarray


def init_state(policy: Policy, config: ParsConfig, seeds: int | None = None) -> TrainState:
    """θ = 0, empty statistics, the seed's key, α and ν at their initial values. With
    `seeds`, the states of seeds config.seed, config.seed + 1, ... stacked on a leading axis
    (for `make_iteration(..., seeds=...)`)."""
    if seeds is not None:
        return jax.vmap(lambda seed: _init(policy, config, jax.random.PRNGKey(seed)))(
            jnp.arange(config.seed, config.seed + seeds))
    return _init(policy, config, jax.random.PRNGKey(config.seed))


def _init(policy: Policy, config: ParsConfig, key) -> TrainState:
    return TrainState(theta=policy.initial_theta(),
                      stats=RunningStats.empty(policy.spec.obs_size, config.obs_std_floor),
                      key=key,
                      iteration=jnp.zeros((), jnp.int32),
                      step_size=jnp.asarray(config.step_size, jnp.float32),
                      noise=jnp.asarray(config.noise, jnp.float32))


def normalized_policy(policy: Policy, network: Callable = _unchanged):
    """policy_apply(params, obs, carry, inputs) with params = (θ, mean, std) that normalises
    the observation and accumulates its sums (count, Σx, Σx²) in the carry; `inputs`, what
    else the episode gives its controllers (e.g. `jaxgrid.episode.ControlInputs`), is unused.
    The network runs as `network(policy.apply)` (`Vmaps.network`)."""
    net = network(policy.apply)

    def apply(params, obs, carry, inputs):
        theta, mean, std = params
        net_carry, (count, total, total_sq) = carry
        action, net_carry = net(theta, (obs - mean) / std, net_carry)
        c, s, s2 = normalizer.sums(obs)
        return action, (net_carry, (count + c, total + s, total_sq + s2))

    return apply


def initial_carry(policy: Policy):
    """The carry `normalized_policy` starts an episode with."""
    n = policy.spec.obs_size
    return policy.initial_carry(), (jnp.zeros(()), jnp.zeros(n), jnp.zeros(n))


def ars_update(theta, delta, r_plus, r_minus, top: int, step_size):
    """θ + α/(b·σ_b) Σ_top (r+ − r−)·δ over the b directions with the largest max(r+, r−).

    delta: (N, size); r_plus, r_minus: (N,). Returns (θ, indices of the top directions).
    """
    best = jnp.argsort(-jnp.maximum(r_plus, r_minus))[:top]
    selected = jnp.concatenate([r_plus[best], r_minus[best]])
    sigma = jnp.std(selected)
    sigma = jnp.where(sigma > 0, sigma, 1.0)
    step = step_size / (top * sigma) * ((r_plus[best] - r_minus[best]) @ delta[best])
    return theta + step, best


def clean_returns(returns):
    """Non-finite returns replaced by the lowest finite one (0 if none is finite)."""
    finite = jnp.isfinite(returns)
    floor = jnp.min(jnp.where(finite, returns, jnp.inf))
    floor = jnp.where(jnp.isfinite(floor), floor, 0.0)
    return jnp.where(finite, returns, floor)


def _in_batches(run, tasks, size: int):
    """run(batch of c tasks) -> (2N, c, ...) results, over the m tasks (leading axis) in
    batches of `size`, one after another; returns (2N, m, ...)."""
    m = int(jax.tree.leaves(tasks)[0].shape[0])
    n_full = m // size
    head = jax.tree.map(lambda a: a[:n_full * size].reshape((n_full, size) + a.shape[1:]), tasks)
    out = jax.lax.map(run, head)  # (n_full, 2N, size, ...)
    out = jax.tree.map(lambda a: jnp.moveaxis(a, 0, 1).reshape(
        (a.shape[1], n_full * size) + a.shape[3:]), out)
    if n_full * size < m:
        tail = run(jax.tree.map(lambda a: a[n_full * size:], tasks))
        out = jax.tree.map(lambda a, b: jnp.concatenate([a, b], axis=1), out, tail)
    return out


def _regrouped(episode, apply, thetas, batch, stats, carry0, data, config: ParsConfig,
               vmaps: Vmaps):
    """The (n_θ, c, ...) results of every θ of `thetas` (n_θ, size) on every task of `batch`
    (c tasks): all n_θ·c episodes run `config.compact_after` agent steps together
    (`episode.begin`), then those still running are regrouped, running first, and continue
    to their end (`episode.resume`) in chunks of ⌈n_θ·c / compact_chunks⌉, as many as they
    fill."""
    mean, std = stats
    n_theta, c = thetas.shape[0], int(jax.tree.leaves(batch)[0].shape[0])
    lanes = n_theta * c
    size = -(-lanes // config.compact_chunks)
    loops = vmaps.thetas(lambda theta: vmaps.tasks(lambda task: episode.begin(
        apply, (theta, mean, std), task, carry0, data, config.compact_after))(batch))(thetas)
    loops = jax.tree.map(lambda a: a.reshape((lanes,) + a.shape[2:]), loops)
    running = ~jax.vmap(episode.done)(loops)
    order = jnp.argsort(~running, stable=True)  # lane = θ index · c + task index

    def chunk(k, loops):
        lane = order[jnp.minimum(k * size + jnp.arange(size), lanes - 1)]
        # one task: shared by the chunk (its data is not gathered per rollout)
        tasks = jax.tree.map(lambda a: a[0] if c == 1 else a[lane % c], batch)
        part = vmaps.lanes(lambda theta, task, loop: episode.resume(
            apply, (theta, mean, std), task, data, loop), (0, None if c == 1 else 0, 0))(
                thetas[lane // c], tasks, jax.tree.map(lambda a: a[lane], loops))
        return jax.tree.map(lambda a, b: a.at[lane].set(b), loops, part)

    loops = jax.lax.fori_loop(0, (running.sum() + size - 1) // size, chunk, loops)
    out = jax.vmap(episode.result)(loops)
    return jax.tree.map(lambda a: a.reshape((n_theta, c) + a.shape[1:]), out)


def make_iteration(episode, policy: Policy, config: ParsConfig, sample=None,
                   mesh: Mesh | None = None, seeds: int | None = None,
                   vmaps: Vmaps = Vmaps()):
    """`iteration(state, tasks, data) -> (state, metrics)`, jit-compiled (`iteration.compiled`).

    episode(policy_apply, policy_params, task, policy_carry, data) -> dict with "reward" ()
    and "policy_carry" (the final carry); tasks: pytree with a leading axis of n_tasks;
    data: any pytree the episode reads (passed through unchanged). sample(key) -> (m,) int
    task indices (default: m distinct tasks uniformly). The 2N perturbed vectors are sharded
    over `mesh` (1-D, axis "batch"; default all devices). With `seeds`, the state (from
    `init_state(..., seeds)`) and the metrics have a leading seed axis: independent trainings
    of one configuration vmapped into one program, sharing the tasks and data. `vmaps`:
    how the rollouts are batched.
    """
    m = config.tasks_per_iteration
    mesh = mesh or Mesh(np.array(jax.devices()), ("batch",))
    n_dir = config.directions
    if (2 * n_dir) % mesh.size:
        raise ValueError(f"2·directions = {2 * n_dir} perturbed policies do not split over "
                         f"{mesh.size} devices")
    phases = ("begin", "resume", "done", "result")
    if config.compact_after is not None and not all(hasattr(episode, f) for f in phases):
        raise ValueError(f"compact_after = {config.compact_after}: the episode must run in "
                         f"two parts ({', '.join(phases)}; e.g. jaxgrid.rollouts."
                         "PointEpisode), or set compact_after None")
    spread = NamedSharding(mesh, PartitionSpec("batch"))
    apply = normalized_policy(policy, vmaps.network)
    carry0 = initial_carry(policy)

    def iteration(state: TrainState, tasks, data):
        n_tasks = int(jax.tree.leaves(tasks)[0].shape[0])
        key, k_dir, k_task = jax.random.split(state.key, 3)
        delta = jax.random.normal(k_dir, (n_dir, policy.size))
        thetas = jax.lax.with_sharding_constraint(
            jnp.concatenate([state.theta + state.noise * delta,
                             state.theta - state.noise * delta]), spread)
        chosen = (sample(k_task) if sample is not None
                  else jax.random.choice(k_task, n_tasks, (m,), replace=False))
        picked = jax.tree.map(lambda a: a[chosen], tasks)
        mean, std = state.stats.mean, state.stats.std

        def rollouts(thetas, picked, mean, std, data):  # one device's share of the thetas
            def per_batch(batch):  # (c, ...) tasks -> (2N/devices, c, ...) episode results
                if config.compact_after is not None:
                    return _regrouped(episode, apply, thetas, batch, (mean, std), carry0,
                                      data, config, vmaps)
                return vmaps.thetas(lambda theta: vmaps.tasks(
                    lambda task: episode(apply, (theta, mean, std), task, carry0, data))(
                        batch))(thetas)

            return _in_batches(per_batch, picked, config.task_batch or m)

        local = jax.shard_map(rollouts, mesh=mesh, in_specs=(PartitionSpec("batch"),) +
                              (PartitionSpec(),) * 4, out_specs=PartitionSpec("batch"),
                              check_vma=False)
        out = local(thetas, picked, mean, std, data)  # (2N, m, ...)
        returns = clean_returns(out["reward"].mean(axis=1))
        r_plus, r_minus = returns[:n_dir], returns[n_dir:]
        theta, _ = ars_update(state.theta, delta, r_plus, r_minus, config.top, state.step_size)
        _, (count, total, total_sq) = out["policy_carry"]
        stats = normalizer.merge(state.stats, count.sum(), total.sum((0, 1)),
                                 total_sq.sum((0, 1)))
        new = TrainState(theta=theta, stats=stats, key=key, iteration=state.iteration + 1,
                         step_size=state.step_size * config.decay,
                         noise=state.noise * config.decay)
        metrics = {"reward_mean": returns.mean(), "reward_max": returns.max(),
                   "rollouts": jnp.asarray(2 * n_dir * m)}
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
