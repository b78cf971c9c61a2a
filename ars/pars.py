"""The PARS search strategy (PNNL PARS study, Algorithm 1; ARS V2-t of Mania et al. 2018) as
`ask`/`tell` (`ars.iteration.Strategy`), and its training's hyper-parameters.

  ask:  sample N directions δ ~ N(0, I) over the flat policy vector θ and propose the 2N
        vectors θ + ν·δ, then θ − ν·δ (the problem evaluates each on the same m tasks, so
        r+ − r− measures the perturbation alone: `ars.iteration`);
  tell: keep the top b directions by max(r+, r−) of the returns averaged over the tasks and
        step θ += α / (b·σ_b) Σ_top (r+ − r−)·δ, σ_b the std of the 2b selected returns (1 if
        0); then α ← ε·α, ν ← ε·ν.

`tell` redraws δ from the key `ask` drew it from (the same bits), so nothing of the population
is stored between the two. The observation statistics are the iteration's, not the
strategy's (`ars.iteration.make_iteration`).
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ars.iteration import TASK_RETURNS, TrainState, initial_state
from ars.policies import Policy


@dataclasses.dataclass(frozen=True)
class ParsConfig:
    """Hyper-parameters of a PARS training (defaults: the study's 39-bus run), one record:
    the strategy's (N, b, α, ν, ε), the iteration's (m, seed, normaliser floor) and how the
    problem batches its rollouts (task_batch, compact_after, compact_chunks: the problem's
    `evaluator`, e.g. `jaxgrid.population.evaluator`). Saved with every run as "config".

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
        `resume`, `done` and `result` (`jaxgrid.problem.PointEpisode`). Results are equal
        to float rounding, as for `task_batch`.
      compact_chunks: see `compact_after`.
      obs_std_floor: the normaliser's smallest standard deviation of a varying input, in the
        input's units (`ars.normalizer.RunningStats.floor`; None: none, as the paper).
      task_returns: how a vector's m episode rewards become the return the top-b selection
        and the step read (`ars.iteration.returns_of`): "mean" (the paper's), or the mean
        of each task's "zscores" or centred "ranks" (every task weighs alike; not the
        paper's), or "ranks+mean" (those ranks plus the centred rank of the mean reward).
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
    task_returns: str = "mean"
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
            "task_returns": (self.task_returns in TASK_RETURNS, ", ".join(TASK_RETURNS)),
        }
        for name, (ok, allowed) in checks.items():
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r}: allowed {allowed}")


def init_state(policy: Policy, config: ParsConfig, seeds: int | None = None) -> TrainState:
    """The state a PARS training starts from (`ars.iteration.initial_state` at the config's
    α, ν, seed and normaliser floor); with `seeds`, seeds config.seed, config.seed + 1, ...
    stacked on a leading axis."""
    return initial_state(policy, config.step_size, config.noise, config.seed,
                         config.obs_std_floor, seeds)


@dataclasses.dataclass(frozen=True)
class Pars:
    """PARS as a strategy (module docstring): N = config.directions, b = config.top,
    ε = config.decay; α and ν are the state's step_size and noise."""

    config: ParsConfig

    @property
    def population(self) -> int:
        """2N: the + vectors, then the − ones."""
        return 2 * self.config.directions

    def _directions(self, state: TrainState, key):
        return jax.random.normal(key, (self.config.directions, state.theta.shape[0]))

    def ask(self, state: TrainState, key):
        """(2N, size): θ + ν·δ for each direction, then θ − ν·δ."""
        delta = self._directions(state, key)
        return jnp.concatenate([state.theta + state.noise * delta,
                                state.theta - state.noise * delta])

    def tell(self, state: TrainState, key, thetas, returns) -> TrainState:
        """θ after the returns (2N,) of `ask(state, key)`'s vectors; α and ν decayed."""
        del thetas  # δ is redrawn from `key`: the + and − returns say all else
        n = self.config.directions
        theta, _ = ars_update(state.theta, self._directions(state, key), returns[:n],
                              returns[n:], self.config.top, state.step_size)
        return state.replace(theta=theta, step_size=state.step_size * self.config.decay,
                             noise=state.noise * self.config.decay)


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
