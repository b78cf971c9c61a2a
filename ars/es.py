"""Plain evolution strategies as a search strategy (`ars.iteration.Strategy`): OpenAI-ES
without its optimiser (Salimans, Ho, Chen, Sidor & Sutskever 2017, "Evolution strategies as a
scalable alternative to reinforcement learning", Algorithm 2 with mirrored sampling and
centred ranks), the second strategy beside PARS (`ars.pars.Pars`):

  ask:  θ + ν·ε_i, then θ − ν·ε_i, for `pairs` draws ε_i ~ N(0, I);
  tell: θ += α/(P·ν) Σ_i (u_i+ − u_i−)·ε_i, u the returns' centred ranks in [−0.5, 0.5]
        (P = 2·pairs). α and ν stay as they are.
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ars.iteration import TrainState


@dataclasses.dataclass(frozen=True)
class PlainEs:
    """Plain ES of `pairs` mirrored pairs (module docstring); α, ν: the state's step_size,
    noise."""

    pairs: int

    @property
    def population(self) -> int:
        return 2 * self.pairs

    def _draws(self, state: TrainState, key):
        return jax.random.normal(key, (self.pairs, state.theta.shape[0]))

    def ask(self, state: TrainState, key):
        eps = self._draws(state, key)
        return jnp.concatenate([state.theta + state.noise * eps, state.theta - state.noise * eps])

    def tell(self, state: TrainState, key, thetas, returns) -> TrainState:
        ranks = jnp.argsort(jnp.argsort(returns)) / (self.population - 1) - 0.5
        gradient = (ranks[:self.pairs] - ranks[self.pairs:]) @ self._draws(state, key)
        return state.replace(theta=state.theta + state.step_size / (self.population * state.noise)
                             * gradient)
