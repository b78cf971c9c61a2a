"""The grid's differential-algebraic right-hand side: one network solution, then all devices.

Order of one evaluation (spec §0 initialisation order, run forwards):
machine EMFs -> Norton sources -> network (with fault, static loads and load models, all
scaled by the connected fraction) -> machine currents (`Signals`) -> one loop over the
device families: governors (Pm) -> stabilizers (VOTHSG) -> exciters (EFD) -> machine and
load-model derivatives.
Once per accepted step `update_loads` advances the load models' discrete logic.
"""
from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp

from jaxgrid import network
from jaxgrid.grid import GridModel, GridState
from jaxgrid.models import loads
from jaxgrid.models.base import LoadPorts, Signals
from jaxgrid.vecmath import sincos

ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)  # ROS2's γ: L-stable, second order for any J
PHI_SERIES_BELOW = 0.5  # |λ·dt| below which φ1, φ2 come from their Taylor series
# GridModel/GridState fields, in the order of GridState.integrated()
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


def solve_network(model: GridModel, x: GridState, fault: network.Fault, active,
                  sweeps: int | None = None):
    """Slot voltages (n_slot,), slot injections (n_slot,), residual, and EMFs (n_gen,), by
    `sweeps` fixed-point sweeps (static; default the model's) from x.v."""
    emf = machine_emf(model, x)
    v, current, residual = network.solve(model.network, fault, active, emf * model.y_norton,
                                         partial(load_injection, model, x), x.v,
                                         sweeps or model.sweeps)
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


def derivatives(model: GridModel, x: GridState, fault: network.Fault, active):
    """Time derivatives of every integrated state.

    One loop over the families in `CAUSAL_ORDER`: each group reads its ports from the
    signals (`DeviceModel.ports`), and its output (EFD, Pm) is written back before the
    next family reads them.

    Args:
      x: current state; fault/active: the task's fault and whether it is on (0/1).
    Returns:
      (dx, v, residual): dx a tuple (machines, exciters, governors, loads, stabilizers) of
      {state: rate}
      dicts mirroring x.integrated(); v (n_slot,) the slot voltages; residual the network
      fixed-point residual.
    """
    v, _, residual, emf = solve_network(model, x, fault, active)
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
    return tuple(tuple(rates[family]) for family in FAMILIES), v, residual


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
    states mirrors x.integrated()."""

    def clip(groups, values):
        out = []
        for g, xs in zip(groups, values):
            xs = dict(xs)
            for name, (lo, hi) in g.model.limits(g.params).items():
                xs[name] = jnp.clip(xs[name], lo, hi)
            out.append(xs)
        return tuple(out)

    return tuple(clip(getattr(model, family), values)
                 for family, values in zip(FAMILIES, states))


def axpy(a, dx, x):
    """x + a·dx over matching state trees."""
    return jax.tree.map(lambda d, s: s + a * d, dx, x)


def stiff_rates(model: GridModel, x: GridState) -> tuple:
    """Per load group, {(real state, imaginary state): λ (n,) complex, 1/s} of its stiff
    complex states (`LoadModel.stiff_rates`), at the state x."""
    return tuple(g.model.stiff_rates(g.params, xs, zs)
                 for g, xs, zs in zip(model.loads, x.loads, x.load_flags))


def phi_functions(z):
    """(φ1, φ2) = ((e^z − 1)/z, (e^z − 1 − z)/z²) of complex z, elementwise; Taylor series
    (through z⁶) below |z| = PHI_SERIES_BELOW, where the quotients lose digits."""
    small = jnp.abs(z) < PHI_SERIES_BELOW
    zs = jnp.where(small, 1.0, z)
    sin, cos = sincos(jnp.imag(zs))
    exp = jnp.exp(jnp.real(zs)) * jax.lax.complex(cos, sin)
    # φ_k(z) = Σ_n z^n / (n + k)!, in Horner form
    series1, series2 = 1 / math.factorial(7), 1 / math.factorial(8)
    for n in range(6, -1, -1):
        series1 = 1 / math.factorial(n + 1) + z * series1
        series2 = 1 / math.factorial(n + 2) + z * series2
    return (jnp.where(small, series1, (exp - 1) / zs),
            jnp.where(small, series2, (exp - 1 - zs) / (zs * zs)))


def _stiff_pairs(rates) -> list[tuple[int, tuple[str, str]]]:
    """(load group, (real state, imaginary state)) of every stiff pair, in `rates` order."""
    return [(g, names) for g, lams in enumerate(rates) for names in lams]


def _gather(states, pairs):
    """(n_stiff,) complex: every stiff pair's value, concatenated in `pairs` order."""
    return jnp.concatenate([states[3][g][re] + 1j * states[3][g][im] for g, (re, im) in pairs])


def _scatter(states, pairs, values):
    """`states` with the stiff pairs set to the parts of `values` (n_stiff,) complex."""
    machines, exciters, governors, loads, *rest = states
    loads = [dict(xs) for xs in loads]
    offset = 0
    for g, (re, im) in pairs:
        n = loads[g][re].shape[0]
        part = values[offset:offset + n]
        loads[g][re], loads[g][im] = jnp.real(part), jnp.imag(part)
        offset += n
    return machines, exciters, governors, tuple(loads), *rest


def exponential_heun(model: GridModel, x: GridState, dt: float, implicit=frozenset()):
    """(predict, correct) of one step from x: Heun's Euler predictor and trapezoidal
    corrector, with every stiff pair (`stiff_rates`, λ frozen at x) advanced by the
    exponential Runge-Kutta pair of the same order (ETD2RK, Cox & Matthews 2002):

        predicted = s0 + dt·φ1(λdt)·k1
        new       = predicted + dt·φ2(λdt)·(k2 − k1 − λ·(predicted − s0)),

    which integrates the part λ·s exactly and is Heun's method where λ = 0. Every pair of
    every group is handled as one concatenated array (one set of kernels, not one per pair).
    predict(s0, k1) -> predicted; correct(s0, predicted, k1, k2) -> new (state trees).
    The load groups in `implicit` (indices) are left to Heun (`rosenbrock_heun` takes them).
    """
    rates = stiff_rates(model, x)
    pairs = [(g, names) for g, names in _stiff_pairs(rates) if g not in implicit]

    def euler(s0, k1):
        return axpy(dt, k1, s0)

    def heun(s0, predicted, k1, k2):
        return axpy(0.5 * dt, k2, axpy(0.5 * dt, k1, s0))

    if not pairs:
        return euler, heun
    lam = jnp.concatenate([rates[g][names] for g, names in pairs])
    phi1, phi2 = phi_functions(lam * dt)

    def predict(s0, k1):
        return _scatter(euler(s0, k1), pairs,
                        _gather(s0, pairs) + dt * phi1 * _gather(k1, pairs))

    def correct(s0, predicted, k1, k2):
        p0 = _gather(predicted, pairs)
        step = _gather(k2, pairs) - _gather(k1, pairs) - lam * (p0 - _gather(s0, pairs))
        return _scatter(heun(s0, predicted, k1, k2), pairs, p0 + dt * phi2 * step)

    return predict, correct


def _implicit_blocks(model: GridModel) -> list[tuple[int, tuple[str, ...]]]:
    """(load group, state names) of every implicit block (`LoadModel.implicit_blocks`)."""
    return [(g, names) for g, group in enumerate(model.loads)
            for names in group.model.implicit_blocks()]


def _gather_blocks(loads, blocks) -> list:
    """[(n_blocked,) per block position]: the blocks' states, concatenated in `blocks` order."""
    return [jnp.concatenate([loads[g][names[i]] for g, names in blocks])
            for i in range(len(blocks[0][1]))]


def _scatter_blocks(loads, blocks, columns) -> tuple:
    """`loads` (x.loads' structure) with the blocks' states set from `columns`."""
    loads = [dict(xs) for xs in loads]
    offset = 0
    for g, names in blocks:
        n = loads[g][names[0]].shape[0]
        for name, column in zip(names, columns):
            loads[g][name] = column[offset:offset + n]
        offset += n
    return tuple(loads)


def block_jacobian(model: GridModel, x: GridState, blocks) -> list[list]:
    """J[i][j] (n_blocked,): ∂(rate of a block's state i)/∂(its state j) at x and the fixed
    slot voltages x.v, every block of `blocks` concatenated. One forward-mode pass per block
    position: its tangent seeds position j of every block of a group at once, which the
    blocks' independence (`LoadModel.implicit_blocks`) allows."""
    v_load = x.v[model.n_gen:]
    size = len(blocks[0][1])
    columns = {}
    for g in sorted({g for g, _ in blocks}):
        group, xs = model.loads[g], x.loads[g]
        ports = LoadPorts(v=v_load[_index(group)], flags=x.load_flags[g])
        seeds = {name: jnp.zeros((size,) + a.shape, a.dtype) for name, a in xs.items()}
        for names in group.model.implicit_blocks():
            for j, name in enumerate(names):
                seeds[name] = seeds[name].at[j].set(1.0)

        def column(seed, group=group, xs=xs, ports=ports):
            return jax.jvp(lambda s: group.model.rates(group.params, s, ports)[1], (xs,),
                           (seed,))[1]

        columns[g] = jax.vmap(column)(seeds)
    return [[jnp.concatenate([columns[g][names[i]][j] for g, names in blocks])
             for j in range(size)] for i in range(size)]


def lu_solver(a: list[list]):
    """solve(b) -> y with a·y = b, for a batch of small dense systems: a[i][j] and b[i] are
    (n,) arrays (one system per element), eliminated in place without pivoting, which
    the linearly implicit step's matrices I − γ·dt·J allow (their E' blocks are scaled
    rotations with a diagonal above 1)."""
    size = len(a)
    a = [list(row) for row in a]
    for p in range(size):
        for i in range(p + 1, size):
            a[i][p] = a[i][p] / a[p][p]
            for j in range(p + 1, size):
                a[i][j] = a[i][j] - a[i][p] * a[p][j]

    def solve(b):
        y = list(b)
        for i in range(size):
            for j in range(i):
                y[i] = y[i] - a[i][j] * y[j]
        for i in reversed(range(size)):
            for j in range(i + 1, size):
                y[i] = y[i] - a[i][j] * y[j]
            y[i] = y[i] / a[i][i]
        return y

    return solve


def motor_jacobian(model: GridModel, x: GridState):
    """`block_jacobian` of every implicit block of the model at x, None when it has none:
    what `rosenbrock_heun` takes as its `jacobian`."""
    blocks = _implicit_blocks(model)
    return block_jacobian(model, x, blocks) if blocks else None


def rosenbrock_heun(model: GridModel, x: GridState, dt: float, jacobian=None):
    """(predict, correct) of one step from x, as `exponential_heun`, with every implicit
    block (`LoadModel.implicit_blocks`: a motor's E', ψk and speed) advanced by the
    two-stage linearly implicit Rosenbrock method ROS2 (Verwer, Spee, Blom & Hundsdorfer
    1999), with W = I − γ·dt·J and J the block's Jacobian (`block_jacobian`, at x by default):

        W·K1 = dt·k1,   predicted = s0 + K1,
        W·K2 = dt·k2 − 2·K1,   new = s0 + 1.5·K1 + 0.5·K2.

    k1 and k2 are the step's two rate evaluations (at s0 and at the predictor, each with
    its own network solution), so the step costs what Heun's does plus two block solves and
    the Jacobian (5 forward-mode passes of the load models' rates, held: below). ROS2 is second
    order for any J (a W-method) and L-stable with the exact one; with J = 0 it is Heun.
    It stays stable for the motors' electromechanical mode (E' against ω, about
    −27 ± 85j 1/s at the PNNL 300-bus operating point, faster at high voltage), which the
    exponential step leaves to Heun. Every other state takes `exponential_heun`'s step.

    `jacobian` (`motor_jacobian`) may come from an earlier state: a W-method stays second
    order with any J, so `jaxgrid.simulate.integrate` evaluates it once per call (the
    environment once per agent step) and holds it for that call's steps. None: J at x.
    """
    blocks = _implicit_blocks(model)
    predict_rest, correct_rest = exponential_heun(model, x, dt, {g for g, _ in blocks})
    if not blocks:
        return predict_rest, correct_rest
    jacobian = block_jacobian(model, x, blocks) if jacobian is None else jacobian
    solve = lu_solver([[float(i == j) - ROS2_GAMMA * dt * jij for j, jij in enumerate(row)]
                       for i, row in enumerate(jacobian)])

    def first_stage(k1):
        return solve([dt * r for r in _gather_blocks(k1[3], blocks)])

    def predict(s0, k1):
        out = predict_rest(s0, k1)
        start, k_1 = _gather_blocks(s0[3], blocks), first_stage(k1)
        return (*out[:3], _scatter_blocks(out[3], blocks,
                                          [s + a for s, a in zip(start, k_1)]), *out[4:])

    def correct(s0, predicted, k1, k2):
        out = correct_rest(s0, predicted, k1, k2)
        start, k_1 = _gather_blocks(s0[3], blocks), first_stage(k1)
        k_2 = solve([dt * r - 2.0 * a for r, a in zip(_gather_blocks(k2[3], blocks), k_1)])
        return (*out[:3], _scatter_blocks(out[3], blocks, [s + 1.5 * a + 0.5 * b
                                                           for s, a, b in zip(start, k_1, k_2)]),
                *out[4:])

    return predict, correct
