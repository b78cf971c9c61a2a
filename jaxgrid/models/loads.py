"""Static loads for dynamic simulation: the power-flow load re-split into a ZIP model.

At the power-flow voltage V0 each bus's load S0 (its own ZIP data evaluated at |V0|) is
re-split into constant-admittance, constant-current and constant-power fractions
(`LoadSplit`; default all constant admittance, the convention of the original study's
simulator and of PSS/E's CONL default for dynamics). The admittance part is folded into
the network matrix; the current and power parts, and any change of the load (load
shedding), enter as voltage-dependent current injections. Below `pq_break` (p.u.) the
constant-power part turns into a constant admittance, as PSS/E's PQBRAK does, so that a
fault never asks a collapsed bus for full power.
"""
from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from jaxgrid.checks import Range

FRACTION = Range(0.0, 1.0, "of the bus's load")  # LoadSplit's p_z ... q_p
PQ_BREAK = Range(0.0, 1.0, "p.u.", lo_open=True)  # LoadSplit.pq_break

@dataclasses.dataclass(frozen=True)
class LoadSplit:
    """Fractions of each bus's power-flow load held as constant Z, I and P during dynamics.

    Attributes:
      p_z, p_i, p_p: active-power fractions (sum to 1).
      q_z, q_i, q_p: reactive-power fractions (sum to 1).
      pq_break: voltage (p.u.) below which constant power becomes constant admittance.
    """

    p_z: float = 1.0
    p_i: float = 0.0
    p_p: float = 0.0
    q_z: float = 1.0
    q_i: float = 0.0
    q_p: float = 0.0
    pq_break: float = 0.7

    def __post_init__(self):
        """InputError naming the field of a value outside its range; ValueError for
        fractions that do not sum to 1."""
        for name in ("p_z", "p_i", "p_p", "q_z", "q_i", "q_p"):
            FRACTION.check(name, getattr(self, name))
        for axis in ("p", "q"):
            total = sum(getattr(self, f"{axis}_{k}") for k in "zip")
            if abs(total - 1.0) > 1e-9:
                raise ValueError(f"LoadSplit: {axis}_z + {axis}_i + {axis}_p = {total:g}, must be 1")
        PQ_BREAK.check("pq_break", self.pq_break)

    @property
    def has_injections(self) -> bool:
        """True if any load part is not constant admittance."""
        return self.p_z < 1.0 or self.q_z < 1.0


def split_bus_loads(s0: np.ndarray, v0: np.ndarray, split: LoadSplit):
    """Per-bus (y_z, s_i, s_p) from the load s0 (n_bus,) complex p.u. drawn at v0 (n_bus,) complex.

    y_z: admittance (p.u.) of the constant-Z part; s_i: power of the constant-current part
    at |v0|; s_p: constant power. All complex (n_bus,).
    """
    vm2 = np.maximum(np.abs(v0), 1e-6) ** 2
    part = lambda fp, fq: fp * s0.real + 1j * fq * s0.imag  # noqa: E731
    return (np.conj(part(split.p_z, split.q_z)) / vm2, part(split.p_i, split.q_i),
            part(split.p_p, split.q_p))


def injection(v, scale, y_z, s_i, s_p, vm0, pq_break):
    """Current injected into the network by loads at their buses, complex (n,) p.u.

    The constant-Z part sits in the network matrix at its initial value, so a scale below 1
    injects (1 − scale)·y_z·v back; the I and P parts are drawn (injection negative) and
    scaled by `scale` (n,), the fraction of the initial load still connected.
    v: bus voltages (n,); vm0: power-flow voltage magnitudes (n,).
    """
    vm = jnp.maximum(jnp.abs(v), 1e-6)
    unit = v / vm
    i_current = jnp.conj(s_i / vm0) * unit
    low = vm < pq_break
    i_power = jnp.where(low, jnp.conj(s_p) * v / pq_break ** 2,
                        jnp.conj(s_p / jnp.where(low, 1.0, v)))
    return (1.0 - scale) * y_z * v - scale * (i_current + i_power)
