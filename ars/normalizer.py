"""Running mean and standard deviation of observations (ARS V2, Mania et al. 2018), and the
policy that normalises its inputs by them (`normalized_policy`).

Frozen during an iteration; afterwards the statistics of all its rollouts are merged in
(Chan et al.'s parallel update), as Algorithm 1 of the PARS study does.
"""
from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
from flax import struct

from ars.policies import Policy

STD_FLOOR = 1e-6  # below it a feature is treated as constant (scale 1)


@struct.dataclass
class RunningStats:
    """Statistics of observations seen so far.

    Attributes:
      count: () number of observations.  mean: (n_obs,).  m2: (n_obs,) sum of squared
      deviations from the mean.
      floor: the smallest standard deviation a varying feature is scaled by, in the
        observation's units (None: none, as the paper's Algorithm 1). A feature that hardly
        moves in training (a bus far from the training faults) would otherwise be scaled up
        by 1/std and drive the policy far outside its trained range on a fault near it.
    """

    count: jnp.ndarray
    mean: jnp.ndarray
    m2: jnp.ndarray
    floor: float | None = struct.field(pytree_node=False, default=None)

    @classmethod
    def empty(cls, n_obs: int, floor: float | None = None) -> RunningStats:
        return cls(jnp.zeros(()), jnp.zeros(n_obs), jnp.zeros(n_obs), floor)

    @property
    def std(self):
        """(n_obs,) standard deviation (at least `floor`), 1 where (nearly) constant or
        nothing seen yet."""
        var = self.m2 / jnp.maximum(self.count, 1.0)
        std = jnp.sqrt(var)
        if self.floor is not None:
            std = jnp.where(std > STD_FLOOR, jnp.maximum(std, self.floor), std)
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
    return stats.replace(count=n, mean=stats.mean + delta * share,
                         m2=stats.m2 + batch_m2 + delta ** 2 * stats.count * share)



def normalized_policy(policy: Policy, network: Callable = lambda fun: fun):
    """policy_apply(params, obs, carry, inputs) with params = (θ, mean, std) that normalises
    the policy's input and accumulates its sums (count, Σx, Σx²) in the carry; `inputs`, what
    else the episode gives its controllers (e.g. `jaxgrid.episode.ControlInputs`), is unused.
    The input is the observation, or with `spec.relative_inputs` the observation less the
    episode's first one (held in the carry beside the network's). The network runs as
    `network(policy.apply)`: the problem's wrap of a per-example network
    (`ars.train.Problem.network`; default as it is)."""
    net = network(policy.apply)
    relative = policy.spec.relative_inputs

    def apply(params, obs, carry, inputs):
        theta, mean, std = params
        net_carry, (count, total, total_sq) = carry
        x = obs
        if relative:
            net_carry, first = net_carry
            first = jnp.where(count > 0, first, obs)  # nothing summed yet: the first call
            x = obs - first
        action, net_carry = net(theta, (x - mean) / std, net_carry)
        if relative:
            net_carry = (net_carry, first)
        c, s, s2 = sums(x)
        return action, (net_carry, (count + c, total + s, total_sq + s2))

    return apply


def initial_carry(policy: Policy):
    """The carry `normalized_policy` starts an episode with."""
    n = policy.spec.obs_size
    net_carry = policy.initial_carry()
    if policy.spec.relative_inputs:
        net_carry = (net_carry, jnp.zeros(n))
    return net_carry, (jnp.zeros(()), jnp.zeros(n), jnp.zeros(n))
