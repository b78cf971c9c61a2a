"""How the grid takes a step: the solver value and the steppers.

`Solver` is the simulator's one value of numerical settings (static, hashable): the step,
the network sweeps, how the motors are integrated, and the coarse step outside a fault
window. `heun_step` is one step of it: the task's events, then Heun's modified Euler (the
original simulator's integrator) on `Integrated` states (`jaxgrid.grid`), with every stiff
induction-motor state advanced by an exponential (`exponential_heun`) or a linearly implicit
(`rosenbrock_heun`) form of the same step. The right-hand side is `jaxgrid.dynamics`'; the
loops over steps and agent steps are `jaxgrid.simulate`'s.
"""
from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from jaxgrid import network
from jaxgrid.checks import InputError, Range, check_int
from jaxgrid.dynamics import clip_to_limits, derivatives, update_loads
from jaxgrid.grid import GridModel, GridState, Integrated
from jaxgrid.models.base import LoadPorts
from jaxgrid.vecmath import sincos

DT = Range(1e-4, 0.05, "s")  # simulation steps this integrator is meant for (2-5 ms usual)
SWEEPS = Range(1, 100, "network sweeps")
FINE_WINDOW = Range(0.0, 3600.0, "s after clearing")
MOTOR_STEPS = ("exponential", "rosenbrock")  # Solver.motor_step
ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)  # ROS2's γ: L-stable, second order for any J
PHI_SERIES_BELOW = 0.5  # |λ·dt| below which φ1, φ2 come from their Taylor series


@dataclasses.dataclass(frozen=True)
class Solver:
    """How a grid is integrated (static: one compilation per value).

    Attributes:
      dt: step, s (inside the fault window when coarse_dt is set).
      coarse_dt: step outside the fault window, s; None: dt throughout. A span (an agent
        step) that overlaps [fault start, clearing + fine_window) runs at dt, every other
        one at coarse_dt (the steady state before the fault and the slow recovery after
        it). Its accuracy is measured like dt's (`experiments.diagnostics.step_accuracy`).
      fine_window: s after clearing that the step stays dt (used with coarse_dt).
      sweeps: network fixed-point sweeps per solution at dt (a grid without load slots
        takes one: nothing in it depends on the voltages, `jaxgrid.network.solve`).
      coarse_sweeps: network sweeps per solution at coarse_dt (None: sweeps).
      motor_step: how the load models' motors are integrated (`MOTOR_STEPS`; None:
        "exponential", left out of a written study so that run folders named by earlier
        studies keep their names): "exponential" (`exponential_heun`: E' and ψk exactly,
        the speed by Heun) or "rosenbrock" (`rosenbrock_heun`: each motor's E', ψk and speed
        together, linearly implicit, stable for their electromechanical mode).

    InputError naming the field of a value outside its range.
    """

    dt: float = 0.005
    coarse_dt: float | None = None
    fine_window: float = 1.0
    sweeps: int = 2
    coarse_sweeps: int | None = None
    motor_step: str | None = None

    def __post_init__(self):
        DT.check("dt", self.dt)
        if self.coarse_dt is not None:
            coarse = Range(self.dt, DT.hi, "s (dt up to the largest step)")
            reason = coarse.problem(self.coarse_dt)
            if reason:
                raise InputError("coarse_dt", self.coarse_dt, reason, related=("dt",))
        FINE_WINDOW.check("fine_window", self.fine_window)  # unused values checked too
        check_int("sweeps", self.sweeps, SWEEPS)
        if self.coarse_sweeps is not None:
            check_int("coarse_sweeps", self.coarse_sweeps, SWEEPS)
        if self.motor_step is not None and self.motor_step not in MOTOR_STEPS:
            raise InputError("motor_step", self.motor_step, f"must be one of {MOTOR_STEPS}")

    @property
    def implicit(self) -> bool:
        """The motors step linearly implicitly (motor_step "rosenbrock")."""
        return self.motor_step == "rosenbrock"

    def fine(self) -> Solver:
        """This solver at dt throughout (coarse_dt None): a simulation's, sampled at dt."""
        return dataclasses.replace(self, coarse_dt=None, coarse_sweeps=None)

    def coarse(self) -> Solver:
        """The solver outside the fault window: coarse_dt with coarse_sweeps (or sweeps)."""
        return dataclasses.replace(self, dt=self.coarse_dt, sweeps=self.coarse_sweeps or
                                   self.sweeps, coarse_dt=None, coarse_sweeps=None)

    def in_fault_window(self, t, span: float, task):
        """() bool: the span of `span` s that starts at t (s) overlaps [fault start,
        clearing + fine_window), so it runs at dt rather than coarse_dt."""
        return ((t + span - 0.5 * self.dt > task.fault_start)
                & (t < task.fault_end + self.fine_window))

    def steps(self, span: float) -> int:
        """Steps of dt in `span` s."""
        return int(round(span / self.dt))


# --------------------------------------------------------------------------- #
# Events within a step
# --------------------------------------------------------------------------- #

def _is_on(t, start, dt):
    """1.0 from `start` on, with event times rounded to the step grid."""
    return (t >= start - 0.5 * dt).astype(t.dtype)


def fault_active(task, t, dt):
    """1.0 while the task's fault is on at time t (s), else 0.0."""
    return _is_on(t, task.fault_start, dt) * (1.0 - _is_on(t, task.fault_end, dt))


def clip_closed(x, low, high):
    """jnp.clip(x, low, high) whose gradient is 1 on the closed range [low, high] (jnp.clip's
    is ½ or 0 at a bound, which hides the gradient of shedding from "no shedding")."""
    return jnp.where((x >= low) & (x <= high), x, jnp.clip(x, low, high))


def shed(load_left, slot, fraction):
    """Connected fractions (n_load,) after shedding `fraction` (k,) at load slots `slot` (k,).

    Clipped to [0, 1] per slot (spec acmtblu1 §9): a request beyond what remains sheds
    what remains.
    """
    return clip_closed(load_left - jnp.zeros_like(load_left).at[slot].add(fraction), 0.0, 1.0)


def scheduled_shedding(task, x: GridState, t, dt) -> GridState:
    """x with the task's load changes that fall due at the step starting at t applied."""
    due = _is_on(t, task.load_time, dt) * (1.0 - _is_on(t - dt, task.load_time, dt))
    return x.replace(load_left=shed(x.load_left, task.load_slot, task.load_fraction * due))


# --------------------------------------------------------------------------- #
# One step
# --------------------------------------------------------------------------- #

def heun_step(model: GridModel, x: GridState, t, solver: Solver, task, fault: network.Fault,
              jacobian=None):
    """One modified-Euler (Heun) step of solver.dt from t (s); returns (state, network
    residual).

    Stiff induction-motor states are advanced by the exponential form of the same step
    (`exponential_heun`), or, with solver.motor_step "rosenbrock", each motor's states
    together by a linearly implicit step (`rosenbrock_heun`) with `jacobian`
    (`motor_jacobian`, e.g. held from an earlier state; None: evaluated at x).
    Scheduled load changes apply at the start of the step; the load models' discrete logic
    advances after the corrector from the corrector's network voltages.
    """
    dt = solver.dt
    x = scheduled_shedding(task, x, t, dt)

    def rates(states, v, time):
        return derivatives(model, x.with_integrated(states, v), fault,
                           fault_active(task, time, dt), solver.sweeps)

    if solver.implicit:
        predict, correct = rosenbrock_heun(model, x, dt, jacobian)
    else:
        predict, correct = exponential_heun(model, x, dt)
    s0 = x.integrated()
    k1, v1, r1 = rates(s0, x.v, t)
    predicted = clip_to_limits(model, predict(s0, k1))
    k2, v2, r2 = rates(predicted, v1, t + dt)
    new = clip_to_limits(model, correct(s0, predicted, k1, k2))
    return update_loads(model, x.with_integrated(new, v2), x.v, dt), jnp.maximum(r1, r2)


def axpy(a, dx, x):
    """x + a·dx over matching state trees."""
    return jax.tree.map(lambda d, s: s + a * d, dx, x)


# --------------------------------------------------------------------------- #
# Stiff motor states: the exponential step
# --------------------------------------------------------------------------- #

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


def _gather(states: Integrated, pairs):
    """(n_stiff,) complex: every stiff pair's value, concatenated in `pairs` order."""
    return jnp.concatenate([states.loads[g][re] + 1j * states.loads[g][im]
                            for g, (re, im) in pairs])


def _scatter(states: Integrated, pairs, values) -> Integrated:
    """`states` with the stiff pairs set to the parts of `values` (n_stiff,) complex."""
    loads = [dict(xs) for xs in states.loads]
    offset = 0
    for g, (re, im) in pairs:
        n = loads[g][re].shape[0]
        part = values[offset:offset + n]
        loads[g][re], loads[g][im] = jnp.real(part), jnp.imag(part)
        offset += n
    return states._replace(loads=tuple(loads))


def exponential_heun(model: GridModel, x: GridState, dt: float, implicit=frozenset()):
    """(predict, correct) of one step from x: Heun's Euler predictor and trapezoidal
    corrector, with every stiff pair (`stiff_rates`, λ frozen at x) advanced by the
    exponential Runge-Kutta pair of the same order (ETD2RK, Cox & Matthews 2002):

        predicted = s0 + dt·φ1(λdt)·k1
        new       = predicted + dt·φ2(λdt)·(k2 − k1 − λ·(predicted − s0)),

    which integrates the part λ·s exactly and is Heun's method where λ = 0. Every pair of
    every group is handled as one concatenated array (one set of kernels, not one per pair).
    predict(s0, k1) -> predicted; correct(s0, predicted, k1, k2) -> new (`Integrated`).
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


# --------------------------------------------------------------------------- #
# Stiff motor blocks: the linearly implicit step
# --------------------------------------------------------------------------- #

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
        ports = LoadPorts(v=v_load[jnp.asarray(group.index)], flags=x.load_flags[g])
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
        return solve([dt * r for r in _gather_blocks(k1.loads, blocks)])

    def predict(s0, k1):
        out = predict_rest(s0, k1)
        start, k_1 = _gather_blocks(s0.loads, blocks), first_stage(k1)
        return out._replace(loads=_scatter_blocks(out.loads, blocks,
                                                  [s + a for s, a in zip(start, k_1)]))

    def correct(s0, predicted, k1, k2):
        out = correct_rest(s0, predicted, k1, k2)
        start, k_1 = _gather_blocks(s0.loads, blocks), first_stage(k1)
        k_2 = solve([dt * r - 2.0 * a for r, a in zip(_gather_blocks(k2.loads, blocks), k_1)])
        return out._replace(loads=_scatter_blocks(out.loads, blocks, [
            s + 1.5 * a + 0.5 * b for s, a, b in zip(start, k_1, k_2)]))

    return predict, correct
