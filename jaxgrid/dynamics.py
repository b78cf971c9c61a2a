"""The grid's differential-algebraic right-hand side: one network solution, then all devices.

Order of one evaluation (spec §0 initialisation order, run forwards):
machine EMFs -> Norton sources -> network (with fault, static loads and load models, all
scaled by the connected fraction) -> machine currents (`Signals`) -> one loop over the
device families: governors (Pm) -> stabilizers (VOTHSG) -> exciters (EFD) -> machine and
load-model derivatives. Once per accepted step `update_loads` advances the load models'
discrete logic. How a step is taken from these rates is `jaxgrid.steppers`'.
"""
from __future__ import annotations

from functools import partial

import jax.numpy as jnp

from jaxgrid import network
from jaxgrid.grid import GridModel, GridState, Integrated
from jaxgrid.models import loads
from jaxgrid.models.base import Signals

# GridModel/GridState fields, in the order of `Integrated` (GridState.integrated())
FAMILIES = ("machines", "exciters", "governors", "loads", "stabilizers")
# Evaluation order: each family reads what the earlier ones wrote (governors Pm, read by a
# stabilizer of accelerating power and by the machines; stabilizers VOTHSG, read by the
# exciters; exciters EFD, read by the machines)
CAUSAL_ORDER = ("governors", "stabilizers", "exciters", "machines", "loads")


def _index(group):
    return jnp.asarray(group.index)


def machine_state(x: GridState, name: str):
    """(n_gen,) one state of every machine in model order, e.g. "dw" (p.u.) or "delta" (rad)."""
    return jnp.concatenate([xs[name] for xs in x.machines])


def machine_emf(model: GridModel, x: GridState):
    """(n_gen,) complex internal EMFs, network frame, p.u."""
    return jnp.concatenate([g.model.emf(g.params, xs) for g, xs in zip(model.machines, x.machines)])


def load_injection(model: GridModel, x: GridState, v_load):
    """(n_load,) current injected at the load slots at voltages v_load (n_load,), p.u.

    Static ZIP parts plus, per load model, its Norton correction y_norton·V − left·I(V)
    (the Norton admittance itself sits in the network matrix; `LoadModel.shed_current`),
    and any current a model injects at a second slot (`LoadModel.upstream_injection`).
    """
    left = x.load_left
    total = loads.injection(v_load, left, model.load_y, model.load_s_i, model.load_s_p,
                            model.load_vm0, model.pq_break)
    for g, xs, zs in zip(model.loads, x.loads, x.load_flags):
        k = _index(g)
        v = v_load[k]
        drawn = g.model.shed_current(g.params, xs, zs, v, left[k])
        total = total.at[k].add(g.params["y_norton"] * v - drawn)
        upstream = g.model.upstream_injection(g.params, xs, zs, v, left[k])
        if upstream is not None:
            total = total.at[g.params["upstream_slot"]].add(upstream)
    return total


def solve_network(model: GridModel, x: GridState, fault: network.Fault, active, sweeps: int):
    """Slot voltages (n_slot,), slot injections (n_slot,), residual, and EMFs (n_gen,), by
    `sweeps` fixed-point sweeps (static) from x.v."""
    emf = machine_emf(model, x)
    v, current, residual = network.solve(model.network, fault, active, emf * model.y_norton,
                                         partial(load_injection, model, x), x.v, sweeps)
    return v, current, residual, emf


def machine_signals(model: GridModel, x: GridState, v, emf) -> Signals:
    """The model-wide `Signals` at slot voltages v (n_slot,) and EMFs emf (n_gen,): the
    machines' currents and speeds, EFD0 and Pm0 (until exciters and governors set them),
    VOTHSG 0 (until stabilizers set it)."""
    vt = v[:model.n_gen]
    current = (emf - vt) / model.z_source
    # (n_gen,) rotor-frame currents, concatenated on purpose: the concatenation is stored,
    # so the sin/cos inside are computed once; kept per group, XLA copies them into every
    # kernel that reads them (`profile_step`, 39-bus: 8 sin/cos this way, 38 per group,
    # when they were XLA's own)
    i_dq = jnp.concatenate([g.model.to_rotor(xs, current[_index(g)])
                            for g, xs in zip(model.machines, x.machines)])
    dw = machine_state(x, "dw")
    xadifd = jnp.concatenate([g.model.field_current(g.params, xs, i_dq[_index(g)])
                              for g, xs in zip(model.machines, x.machines)])
    return Signals(vt=vt, current=current, i_dq=i_dq, xadifd=xadifd, dw=dw,
                   efd=jnp.asarray(model.efd0), pm=jnp.asarray(model.pm0),
                   vothsg=jnp.zeros_like(dw), v_load=v[model.n_gen:], omega_b=model.omega_b)


def derivatives(model: GridModel, x: GridState, fault: network.Fault, active, sweeps: int):
    """Time derivatives of every integrated state, the network solved by `sweeps` sweeps.

    One loop over the families in `CAUSAL_ORDER`: each group reads its ports from the
    signals (`DeviceModel.ports`), and its output (EFD, Pm) is written back before the
    next family reads them.

    Args:
      x: current state; fault/active: the task's fault and whether it is on (0/1).
    Returns:
      (dx, v, residual): dx the `Integrated` {state: rate} dicts mirroring x.integrated();
      v (n_slot,) the slot voltages; residual the network fixed-point residual.
    """
    v, _, residual, emf = solve_network(model, x, fault, active, sweeps)
    signals = machine_signals(model, x, v, emf)
    rates = {}
    for family in CAUSAL_ORDER:
        groups = getattr(model, family)
        flags = x.load_flags if family == "loads" else ({},) * len(groups)
        rates[family] = []
        for g, xs, zs in zip(groups, getattr(x, family), flags):
            k = _index(g)
            out, dx = g.model.rates(g.params, xs, g.model.ports(signals, k, zs))
            if g.model.output is not None:
                driven = getattr(signals, g.model.output).at[k].set(out)
                signals = signals._replace(**{g.model.output: driven})
            rates[family].append(dx)
    return Integrated(*(tuple(rates[family]) for family in FAMILIES)), v, residual


def update_loads(model: GridModel, x: GridState, v_old, dt: float) -> GridState:
    """x with the load models' flags advanced after an accepted step of dt seconds.

    x.v is the step's network solution, v_old (n_slot,) the previous one.
    """
    n = model.n_gen
    flags = tuple(g.model.update(g.params, xs, zs, x.v[n:][_index(g)], v_old[n:][_index(g)],
                                 dt)
                  for g, xs, zs in zip(model.loads, x.loads, x.load_flags))
    return x.replace(load_flags=flags)


def clip_to_limits(model: GridModel, states):
    """Clip non-windup states to their limits after an update (cannot overshoot by a step);
    states (`Integrated`) mirrors x.integrated()."""

    def clip(groups, values):
        out = []
        for g, xs in zip(groups, values):
            xs = dict(xs)
            for name, (lo, hi) in g.model.limits(g.params).items():
                xs[name] = jnp.clip(xs[name], lo, hi)
            out.append(xs)
        return tuple(out)

    return Integrated(*(clip(getattr(model, family), values)
                        for family, values in zip(FAMILIES, states)))
