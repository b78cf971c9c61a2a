"""Algebraic network solution by a precomputed impedance matrix (DESIGN.md, "Simulator numerics").

Everything linear (branches, shunts, constant-admittance loads, machines' Norton admittances)
is folded into one admittance matrix, inverted once in float64 on the host. Current
injections live at *slots*: one per machine (its bus), then one per load bus whose
injection can change (ZIP parts that are not constant Z, load shedding). A slot voltage is
then a matrix-vector product; nonlinear injections are resolved by a fixed number of
fixed-point sweeps warm-started from the previous voltages. The two products that run every
sweep are real 2×2-block products ([Re −Im; Im Re] acting on [Re; Im]): measured 3× faster
than the complex64 product on CPU (`experiments/bench/profile_step.py`, docs/performance.md).

A three-phase fault at bus f with impedance z_f is the rank-one update
Z − Z[:, f] Z[f, :] / (Z[f, f] + z_f); the fault bus is data, so tasks with different
fault buses share one compiled step.
"""
from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class Network:
    """Impedance views, p.u. on the system base.

    Attributes:
      zr_ss: (2·n_slot, 2·n_slot) real block (`real_block`) of Z[slot, slot]: slot
        voltages per unit current injected at a slot.
      zr_bs: (2·n_bus, 2·n_slot) real block of Z[bus, slot]: bus voltages from slot
        injections; its blocks also give the fault rows Z[f, slot].
      z_sb: (n_slot, n_bus) complex Z[slot, bus]: the slot side of a fault column.
      z_bb: (n_bus, n_bus) complex, the whole impedance matrix (fault columns for bus
        voltages).
    """

    zr_ss: jnp.ndarray
    zr_bs: jnp.ndarray
    z_sb: jnp.ndarray
    z_bb: jnp.ndarray

    @property
    def real_dtype(self):
        """float32 or float64: the precision of the time loop."""
        return self.zr_ss.dtype


@struct.dataclass
class Fault:
    """One task's fault as seen by the network; `active` switches it on (0/1 float).

    Attributes:
      col: (n_slot,) Z[slot, f];  row: (n_slot,) Z[f, slot];  col_bus: (n_bus,) Z[bus, f].
      denom: Z[f, f] + z_f, complex scalar.
    """

    col: jnp.ndarray
    row: jnp.ndarray
    col_bus: jnp.ndarray
    denom: jnp.ndarray


def build(y: np.ndarray, slot_bus: np.ndarray, dtype) -> Network:
    """Invert the full admittance matrix y (n_bus, n_bus) in float64 and cut the slot views.

    Buses with an all-zero row (isolated) get a unit diagonal so they carry 0 V.
    """
    y = np.array(y, dtype=np.complex128)
    empty = ~np.any(y != 0, axis=1)
    y[empty, empty] = 1.0
    z = np.linalg.inv(y)
    cast = lambda a: np.asarray(a, dtype=dtype)  # noqa: E731
    real = np.real(np.zeros((), dtype)).dtype
    return Network(zr_ss=real_block(z[np.ix_(slot_bus, slot_bus)]).astype(real),
                   zr_bs=real_block(z[:, slot_bus]).astype(real),
                   z_sb=cast(z[slot_bus, :]), z_bb=cast(z))


def real_block(z: np.ndarray) -> np.ndarray:
    """(2m, 2n) real [[Re z, −Im z], [Im z, Re z]] of a complex (m, n) matrix: the real
    product of `times`."""
    return np.block([[z.real, -z.imag], [z.imag, z.real]])


def times(block, current):
    """Complex product Z·current (m,) from Z's real block (2m, 2n) and current (n,)."""
    m = block.shape[0] // 2
    out = block @ jnp.concatenate([jnp.real(current), jnp.imag(current)])
    return jax.lax.complex(out[:m], out[m:])


def fault_view(net: Network, bus, z_fault) -> Fault:
    """Fault vectors for a fault at bus index `bus` (int, traced) with impedance z_fault (p.u.)."""
    n_bus, n_slot = net.z_bb.shape[0], net.z_sb.shape[0]
    row = jax.lax.complex(net.zr_bs[bus, :n_slot], net.zr_bs[n_bus + bus, :n_slot])
    return Fault(col=net.z_sb[:, bus], row=row, col_bus=net.z_bb[:, bus],
                 denom=net.z_bb[bus, bus] + z_fault)


def slot_voltages(net: Network, fault: Fault, active, current):
    """Slot voltages (n_slot,) for injections `current` (n_slot,), with the fault if active."""
    through_fault = active * (fault.row @ current) / fault.denom
    return times(net.zr_ss, current) - fault.col * through_fault


def bus_voltages(net: Network, fault: Fault, active, current, buses=None):
    """Bus voltages (n_bus,) for slot injections `current` (n_slot,); with `buses` (static
    (k,) bus indices) only those (k,), from their rows of the product alone."""
    through_fault = active * (fault.row @ current) / fault.denom
    if buses is None:
        return times(net.zr_bs, current) - fault.col_bus * through_fault
    rows = np.concatenate([buses, net.z_bb.shape[0] + np.asarray(buses)])
    return times(net.zr_bs[rows], current) - fault.col_bus[buses] * through_fault


def solve(net: Network, fault: Fault, active, source, load_injection: Callable, v_guess,
          sweeps: int):
    """Fixed-point solution of v = Z·[source; load_injection(v_loads)].

    source: (n_source,) machine Norton currents; load_injection maps load-slot voltages
    (n_slot − n_source,) to their injections. `sweeps` (static) >= 1 iterations start from
    v_guess (n_slot,); one where there are no load slots (nothing then depends on v).
    Returns (v (n_slot,), current (n_slot,), residual = max |Δv| of the last sweep, p.u.).
    """
    n_source = source.shape[0]
    if v_guess.shape[0] == n_source:
        sweeps = 1

    def sweep(v):
        current = jnp.concatenate([source, load_injection(v[n_source:])])
        return slot_voltages(net, fault, active, current), current

    v, current = v_guess, None
    for _ in range(sweeps):
        v_prev = v
        v, current = sweep(v)
    return v, current, jnp.max(jnp.abs(v - v_prev), initial=0.0)
