"""Running mean and standard deviation of observations (ARS V2, Mania et al. 2018).

Frozen during an iteration; afterwards the statistics of all its rollouts are merged in
(Chan et al.'s parallel update), as Algorithm 1 of the PARS study does.
"""
from __future__ import annotations

import jax.numpy as jnp
from flax import struct

STD_FLOOR = 1e-6  # below it a feature is treated as constant (scale 1)


@struct.dataclass
class RunningStats:
    """Statistics of observations seen so far.

    Attributes:
      count: () number of observations.  mean: (n_obs,).  m2: (n_obs,) sum of squared
      deviations from the mean.
    """

    count: jnp.ndarray
    mean: jnp.ndarray
    m2: jnp.ndarray

    @classmethod
    def empty(cls, n_obs: int) -> RunningStats:
        return cls(jnp.zeros(()), jnp.zeros(n_obs), jnp.zeros(n_obs))

    @property
    def std(self):
        """(n_obs,) standard deviation, 1 where (nearly) constant or nothing seen yet."""
        var = self.m2 / jnp.maximum(self.count, 1.0)
        std = jnp.sqrt(var)
        return jnp.where(std > STD_FLOOR, std, 1.0)


def sums(obs):
    """(count, Σx, Σx²) of one observation (n_obs,): what a rollout accumulates."""
    return jnp.ones(()), obs, obs * obs


def merge(stats: RunningStats, count, total, total_sq) -> RunningStats:
    """Stats with a batch given by its sums merged in (parallel variance update)."""
    count = jnp.asarray(count, stats.mean.dtype)
    batch_mean = total / jnp.maximum(count, 1.0)
    batch_m2 = jnp.maximum(total_sq - count * batch_mean ** 2, 0.0)
    n = stats.count + count
    delta = batch_mean - stats.mean
    share = count / jnp.maximum(n, 1.0)
    return RunningStats(count=n, mean=stats.mean + delta * share,
                        m2=stats.m2 + batch_m2 + delta ** 2 * stats.count * share)

