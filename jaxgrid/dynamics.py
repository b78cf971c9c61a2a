"""The grid's differential-algebraic right-hand side: one network solution, then all devices.

Order of one evaluation (spec §0 initialisation order, run forwards):
machine EMFs -> Norton sources -> network (with fault, loads) -> machine currents ->
exciters (EFD) -> governors (Pm) -> machine derivatives.
"""
from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxgrid import network
from jaxgrid.grid import GridModel, GridState
from jaxgrid.models import loads
from jaxgrid.models.base import ExciterInputs


def _index(group):
    return jnp.asarray(group.machine)


def machine_state(x: GridState, name: str):
    """(n_gen,) one state of every machine in model order, e.g. "dw" (p.u.) or "delta" (rad)."""
    return jnp.concatenate([xs[name] for xs in x.machines])


def machine_emf(model: GridModel, x: GridState):
    """(n_gen,) complex internal EMFs, network frame, p.u."""
    return jnp.concatenate([g.model.emf(g.params, xs) for g, xs in zip(model.machines, x.machines)])


def solve_network(model: GridModel, x: GridState, fault: network.Fault, active, load_scale):
    """Slot voltages (n_slot,), slot injections (n_slot,), residual, and EMFs (n_gen,)."""
    emf = machine_emf(model, x)
    inject = partial(loads.injection, scale=load_scale, y_z=model.load_y, s_i=model.load_s_i,
                     s_p=model.load_s_p, vm0=model.load_vm0, pq_break=model.pq_break)
    v, current, residual = network.solve(model.network, fault, active, emf * model.y_norton,
                                         inject, x.v, model.sweeps)
    return v, current, residual, emf


def derivatives(model: GridModel, x: GridState, fault: network.Fault, active, load_scale):
    """Time derivatives of every device state.

    Args:
      x: current state; fault/active: the task's fault and whether it is on (0/1);
      load_scale: (n_load,) fraction of each load slot's initial load still connected.
    Returns:
      (dx, v, residual): dx a tuple (machines, exciters, governors) of {state: rate} dicts
      mirroring x; v (n_slot,) the slot voltages; residual the network fixed-point residual.
    """
    v, _, residual, emf = solve_network(model, x, fault, active, load_scale)
    vt = v[:model.n_gen]
    current = (emf - vt) / model.z_source
    dw = machine_state(x, "dw")
    xadifd = jnp.concatenate([g.model.field_current(g.params, xs, current[_index(g)])
                              for g, xs in zip(model.machines, x.machines)])
    efd = jnp.asarray(model.efd0)
    d_exciters = []
    for g, xs in zip(model.exciters, x.exciters):
        k = _index(g)
        inputs = ExciterInputs(ec=jnp.abs(vt[k]), vt=vt[k], it=current[k], xadifd=xadifd[k],
                               dw=dw[k])
        out, dx = g.model.dynamics(g.params, xs, inputs)
        efd = efd.at[k].set(out)
        d_exciters.append(dx)
    pm = jnp.asarray(model.pm0)
    d_governors = []
    for g, xs in zip(model.governors, x.governors):
        k = _index(g)
        out, dx = g.model.dynamics(g.params, xs, dw[k])
        pm = pm.at[k].set(out)
        d_governors.append(dx)
    d_machines = tuple(
        g.model.derivative(g.params, xs, current[_index(g)], efd[_index(g)], pm[_index(g)],
                           model.omega_b)
        for g, xs in zip(model.machines, x.machines))
    return (d_machines, tuple(d_exciters), tuple(d_governors)), v, residual


def device_states(x: GridState):
    """The integrated part of a state: (machines, exciters, governors)."""
    return (x.machines, x.exciters, x.governors)


def clip_to_limits(model: GridModel, states):
    """Clip non-windup states to their limits after an update (cannot overshoot by a step)."""
    machines, exciters, governors = states

    def clip(groups, values):
        out = []
        for g, xs in zip(groups, values):
            xs = dict(xs)
            for name, (lo, hi) in g.model.limits(g.params).items():
                xs[name] = jnp.clip(xs[name], lo, hi)
            out.append(xs)
        return tuple(out)

    return machines, clip(model.exciters, exciters), clip(model.governors, governors)


def axpy(a, dx, x):
    """x + a·dx over matching state trees."""
    return jax.tree.map(lambda d, s: s + a * d, dx, x)
