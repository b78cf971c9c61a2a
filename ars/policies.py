"""Policies of the PARS study as Flax modules over one flat parameter vector θ.

Kinds: "linear" (one dense layer), "fnn" (tanh hidden layers, e.g. [32, 32]) and "lstm"
(an LSTM of hidden[0] units followed by tanh dense layers hidden[1:]). The output is
squashed into the action range [low, high] as high + (low − high)·max(tanh(u), 0): u <= 0
means `high` (no shedding when high = 0), so θ = 0, where ARS starts, is "no control".
`Policy.apply(θ, obs, carry)` unflattens θ (`jax.flatten_util.ravel_pytree`) for the
forward pass; perturbations act on θ directly.
"""
from __future__ import annotations

import dataclasses

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

KINDS = ("linear", "fnn", "lstm")


@dataclasses.dataclass(frozen=True)
class PolicySpec:
    """Architecture (static).

    Attributes:
      kind: "linear" | "fnn" | "lstm".  obs_size, action_size: vector lengths.
      hidden: layer widths (fnn: all tanh layers; lstm: LSTM units, then tanh layers).
      action_low, action_high: the action range.
      obs_clip: the (normalised) inputs are clipped to [−obs_clip, obs_clip] before the
        network, or None: not clipped, as the paper's Algorithm 1. A clip keeps inputs far
        outside what training saw (a bus that hardly moved under the training faults has a
        tiny std) from driving the policy out of its trained range.
      relative_inputs: the network reads each input as its change since the episode's
        first observation (`ars.normalizer.normalized_policy`), not as it is (the paper's):
        before a fault every operating point then looks alike to it.
    """

    kind: str
    obs_size: int
    action_size: int
    hidden: tuple[int, ...] = (32, 32)
    action_low: float = -0.2
    action_high: float = 0.0
    obs_clip: float | None = None
    relative_inputs: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"policy kind {self.kind!r}: allowed {', '.join(KINDS)}")
        if self.kind != "linear" and (not self.hidden or min(self.hidden) < 1):
            raise ValueError(f"hidden = {self.hidden!r}: {self.kind} needs widths >= 1")
        if not self.action_low < self.action_high:
            raise ValueError(f"action range [{self.action_low}, {self.action_high}] is empty")
        if self.obs_clip is not None and not self.obs_clip > 0:
            raise ValueError(f"obs_clip = {self.obs_clip!r}: allowed None or > 0")


class _Network(nn.Module):
    spec: PolicySpec

    @nn.compact
    def __call__(self, obs, carry):
        spec, x, layers = self.spec, obs, ()
        if spec.obs_clip is not None:
            x = jnp.clip(x, -spec.obs_clip, spec.obs_clip)
        if spec.kind == "fnn":
            layers = spec.hidden
        if spec.kind == "lstm":
            carry, x = nn.OptimizedLSTMCell(spec.hidden[0])(carry, x)
            layers = spec.hidden[1:]
        for width in layers:
            x = jnp.tanh(nn.Dense(width)(x))
        u = nn.Dense(spec.action_size)(x)
        squash = jnp.maximum(jnp.tanh(u), 0.0)
        return spec.action_high + (spec.action_low - spec.action_high) * squash, carry


class Policy:
    """A policy of `spec` over a flat θ (size `size`)."""

    def __init__(self, spec: PolicySpec):
        self.spec = spec
        self.network = _Network(spec)
        # the network's parameter shapes alone (θ starts at 0, not at the initialiser's draw):
        # traced, not run (run eagerly, each operation of the draw was compiled on its own)
        shapes = jax.eval_shape(self.network.init, jax.random.PRNGKey(0),
                                jnp.zeros(spec.obs_size), self.initial_carry())
        flat, self._unravel = ravel_pytree(jax.tree.map(
            lambda s: np.zeros(s.shape, s.dtype), shapes))
        self.size = int(flat.shape[0])

    def initial_carry(self):
        """Recurrent state at the start of an episode: LSTM (c, h) zeros, else ()."""
        if self.spec.kind == "lstm":
            width = self.spec.hidden[0]
            return (jnp.zeros(width), jnp.zeros(width))
        return ()

    def initial_theta(self):
        """θ = 0 (ARS starts there): no control."""
        return jnp.zeros(self.size)

    def apply(self, theta, obs, carry):
        """(action (action_size,), carry) for one observation (obs_size,)."""
        return self.network.apply(self._unravel(theta), obs, carry)
