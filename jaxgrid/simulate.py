"""Time-domain simulation: events as data, fixed-step Heun (modified Euler) in `lax.scan`.

One rollout is one jit-compiled function of (model, task); `simulate_batch` vmaps it over a
batch of tasks (fault bus, times, impedance, load changes), so tasks with different fault
buses share one compiled step. A rollout whose state becomes non-finite or leaves physical
bounds is frozen at its last good sample and flagged (`Trajectory.diverged`); the rest of a
batch is untouched. Everything is differentiable (discrete logic through `jnp.where`).

Command line: `python -m experiments.simulate`.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jaxgrid import network
from jaxgrid.checks import Range
from jaxgrid.batching import vmap_minor
from jaxgrid.dynamics import (FAMILIES, clip_to_limits, derivatives, exponential_heun,
                              machine_state, motor_jacobian, rosenbrock_heun, solve_network,
                              update_loads)
from jaxgrid.grid import GridModel, GridState


OBSERVE_SWEEPS = 4  # network sweeps of a sample (`observe`): the accuracy reference's


@dataclasses.dataclass(frozen=True)
class FaultEvent:
    """A three-phase bus fault.

    Attributes:
      bus: RAW bus number.  start: s.  duration: s.
      r, x: fault impedance, p.u. on the system base (default a bolted fault, x = 1e-4).
    """

    bus: int
    start: float
    duration: float
    r: float = 0.0
    x: float = 1e-4


@dataclasses.dataclass(frozen=True)
class LoadChange:
    """At `time` (s), shed `fraction` of the initial load at `bus` (every load type there).

    The connected fraction is clipped to [0, 1]: shedding more than what remains sheds
    what remains; a negative fraction reconnects shed load, at most up to the initial load.
    """

    bus: int
    time: float
    fraction: float


DT = Range(1e-4, 0.05, "s")  # simulation steps this integrator is meant for (2-5 ms usual)
POSITIVE = Range(0.0, 1e6, lo_open=True)


@dataclasses.dataclass(frozen=True)
class Bounds:
    """Physical bounds beyond which a rollout counts as diverged.

    Attributes:
      max_speed_dev: largest |Δω|, p.u. (0.2 = 12 Hz at 60 Hz).
      max_voltage: largest slot voltage magnitude, p.u.
    """

    max_speed_dev: float = 0.2
    max_voltage: float = 3.0

    def __post_init__(self):
        POSITIVE.check("max_speed_dev", self.max_speed_dev)
        POSITIVE.check("max_voltage", self.max_voltage)


@struct.dataclass
class Task:
    """One rollout's disturbance, as arrays (a batch has a leading axis on every field).

    Attributes:
      fault_bus: () int bus index (not the RAW number).
      fault_start, fault_end: () s; fault_end <= fault_start means no fault.
      fault_z: () complex fault impedance, p.u.
      load_slot: (k,) int load-slot index per load change.
      load_time: (k,) s.  load_fraction: (k,) fraction of the initial load removed.
    """

    fault_bus: jnp.ndarray
    fault_start: jnp.ndarray
    fault_end: jnp.ndarray
    fault_z: jnp.ndarray
    load_slot: jnp.ndarray
    load_time: jnp.ndarray
    load_fraction: jnp.ndarray


@struct.dataclass
class Trajectory:
    """Sampled results of a rollout (a batch adds a leading axis).

    Attributes:
      t: (n_t,) s.  vm: (n_t, n_bus) p.u.  va: (n_t, n_bus) rad (buses in model order).
      speed_dev: (n_t, n_gen) Δω, p.u.  angle: (n_t, n_gen) rotor angle δ, rad.
      residual: (n_t,) largest network fixed-point residual since the previous sample, p.u.
      load_left: (n_t, n_load) connected fraction of each load slot's initial load.
      load_flags: per load-model group, {flag: (n_t, n_unit)} (e.g. ACMTBLU1 run_a, kcon).
      diverged: () bool.  diverged_at: () s, the end of the first sample whose state was
        non-finite or out of bounds (inf if none was).
      final: GridState at t_end (the frozen state if diverged).
    """

    t: jnp.ndarray
    vm: jnp.ndarray
    va: jnp.ndarray
    speed_dev: jnp.ndarray
    angle: jnp.ndarray
    residual: jnp.ndarray
    load_left: jnp.ndarray
    load_flags: tuple
    diverged: jnp.ndarray
    diverged_at: jnp.ndarray
    final: GridState


def make_task(model: GridModel, fault: FaultEvent | None = None,
              load_changes: Sequence[LoadChange] = ()) -> Task:
    """A Task from events given with RAW bus numbers (checked against the model)."""
    real = np.float64 if model.precision == "float64" else np.float32
    if fault is not None:
        for name in ("start", "duration"):
            if not np.isfinite(getattr(fault, name)) or getattr(fault, name) < 0:
                raise ValueError(f"FaultEvent.{name} = {getattr(fault, name)!r}: must be >= 0 s")
    bus = model.bus_index(fault.bus) if fault else 0
    start = fault.start if fault else 0.0
    end = fault.start + fault.duration if fault else 0.0
    z = complex(fault.r, fault.x) if fault else 1.0
    return Task(
        fault_bus=np.int32(bus), fault_start=real(start), fault_end=real(end),
        fault_z=np.asarray(z, dtype=np.result_type(real, np.complex64)),
        load_slot=np.array([model.load_slot(c.bus) for c in load_changes], dtype=np.int32),
        load_time=np.array([c.time for c in load_changes], dtype=real),
        load_fraction=np.array([c.fraction for c in load_changes], dtype=real))


def stack_tasks(tasks: Sequence[Task]) -> Task:
    """A batch (leading axis) from tasks with the same number of load changes."""
    return jax.tree.map(lambda *a: np.stack(a), *tasks)


def _is_on(t, start, dt):
    """1.0 from `start` on, with event times rounded to the step grid."""
    return (t >= start - 0.5 * dt).astype(t.dtype)


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


def scheduled_shedding(task: Task, x: GridState, t, dt) -> GridState:
    """x with the task's load changes that fall due at the step starting at t applied."""
    due = _is_on(t, task.load_time, dt) * (1.0 - _is_on(t - dt, task.load_time, dt))
    return x.replace(load_left=shed(x.load_left, task.load_slot, task.load_fraction * due))


def fault_active(task: Task, t, dt):
    """1.0 while the fault is on at time t, else 0.0."""
    return _is_on(t, task.fault_start, dt) * (1.0 - _is_on(t, task.fault_end, dt))


def heun_step(model: GridModel, x: GridState, t, dt: float, task: Task, fault: network.Fault,
              jacobian=None):
    """One modified-Euler (Heun) step from t to t + dt; returns (state, network residual).

    Stiff induction-motor states are advanced by the exponential form of the same step
    (`jaxgrid.dynamics.exponential_heun`), or, with model.motor_step "rosenbrock", each
    motor's states together by a linearly implicit step (`jaxgrid.dynamics.rosenbrock_heun`)
    with `jacobian` (`jaxgrid.dynamics.motor_jacobian`, e.g. held from an earlier state;
    None: evaluated at x).
    Scheduled load changes apply at the start of the step; the load models' discrete logic
    advances after the corrector from the corrector's network voltages.
    """
    x = scheduled_shedding(task, x, t, dt)

    def rates(states, v, time):
        return derivatives(model, x.with_integrated(states, v), fault,
                           fault_active(task, time, dt))

    if model.motor_step == "rosenbrock":
        predict, correct = rosenbrock_heun(model, x, dt, jacobian)
    else:
        predict, correct = exponential_heun(model, x, dt)
    s0 = x.integrated()
    k1, v1, r1 = rates(s0, x.v, t)
    predicted = clip_to_limits(model, predict(s0, k1))
    k2, v2, r2 = rates(predicted, v1, t + dt)
    new = clip_to_limits(model, correct(s0, predicted, k1, k2))
    return update_loads(model, x.with_integrated(new, v2), x.v, dt), jnp.maximum(r1, r2)


def within_bounds(x: GridState, bounds: Bounds):
    """() bool: every state finite, speeds and voltages inside `bounds`."""
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in jax.tree.leaves(x)]))
    return (finite & jnp.all(jnp.abs(machine_state(x, "dw")) <= bounds.max_speed_dev)
            & jnp.all(jnp.abs(x.v) <= bounds.max_voltage))


def observe(model: GridModel, x: GridState, t, dt: float, task: Task, fault: network.Fault,
            buses=None):
    """(vm (n_bus,), va (n_bus,), Δω (n_gen,), δ (n_gen,), load_left, load_flags) at time t;
    with `buses` (static (k,) bus indices) vm and va of those buses only, (k,).

    The network is solved with at least `OBSERVE_SWEEPS` sweeps: a sample that falls on a
    fault's start or clearing sees the new topology from the warm start of the step before,
    which one or two sweeps leave far from converged (this costs one solution per sample).
    """
    v = bus_voltage_sets(model, x, t, dt, task, fault, buses)[0]
    return (jnp.abs(v), jnp.angle(v), machine_state(x, "dw"), machine_state(x, "delta"),
            x.load_left, x.load_flags)


def bus_voltage_sets(model: GridModel, x: GridState, t, dt: float, task: Task,
                     fault: network.Fault, *bus_sets):
    """Complex bus voltages at time t, one array per static index set of `bus_sets` ((k,)
    bus indices, or None for all buses), from one network solution (as `observe`); each set's
    rows of the product are computed apart, so adding a set leaves the others' rounding."""
    active = fault_active(task, t, dt)
    _, current, _, _ = solve_network(model, x, fault, active, max(model.sweeps, OBSERVE_SWEEPS))
    return tuple(network.bus_voltages(model.network, fault, active, current, buses)
                 for buses in bus_sets)


@struct.dataclass
class Health:
    """Divergence bookkeeping carried through a rollout.

    Attributes:
      diverged: () bool.  diverged_at: () s, inf while healthy.
      residual: () largest network fixed-point residual since it was last reset, p.u.
    """

    diverged: jnp.ndarray
    diverged_at: jnp.ndarray
    residual: jnp.ndarray


def healthy(real) -> Health:
    """A Health record of a rollout that has not diverged."""
    return Health(jnp.zeros((), bool), jnp.asarray(jnp.inf, real), jnp.zeros((), real))


def parameters_valid(model: GridModel):
    """() bool: every float array of the model finite and every device CON inside its range.

    compile_model checks both; this catches values changed through the API afterwards
    (a NaN or negative H would otherwise make a machine an infinite bus).
    """
    ok = [jnp.all(jnp.isfinite(a)) for a in jax.tree.leaves(model)
          if jnp.issubdtype(jnp.asarray(a).dtype, jnp.inexact)]
    for family in FAMILIES:
        for g in getattr(model, family):
            for con in g.model.cons:
                v = g.params[con.name]
                ok.append(jnp.all(con.admits(v)))
    return jnp.all(jnp.stack(ok))


def initial_health(model: GridModel) -> Health:
    """Health at t = 0: diverged at 0 s when the model's parameters are not valid."""
    real = model.network.real_dtype
    bad = ~parameters_valid(model)
    return healthy(real).replace(diverged=bad, diverged_at=jnp.where(bad, 0.0, jnp.inf)
                                 .astype(real))


def integrate(model: GridModel, x: GridState, residual, t0, n, dt: float, task: Task,
              fault: network.Fault, jacobian=None):
    """n Heun steps of dt seconds from time t0 (s, traced); (state, largest residual so far).

    n static: a `lax.scan` (differentiable); n traced (e.g. 0 or a whole agent step, chosen
    per rollout: `LoadSheddingEnv`'s coarse step): a `lax.while_loop`, forward mode only.
    With model.motor_step "rosenbrock" the motors' Jacobian is evaluated once, at x (or
    given, `jaxgrid.dynamics.motor_jacobian`), and held for the n steps (`heun_step`).
    """
    if jacobian is None and model.motor_step == "rosenbrock":
        jacobian = motor_jacobian(model, x)

    def step(j, carry):
        x, residual = carry
        new, r = heun_step(model, x, t0 + j * dt, dt, task, fault, jacobian)
        return new, jnp.maximum(residual, r)

    return jax.lax.fori_loop(0, n, step, (x, residual))


def checked(x: GridState, new: GridState, health: Health, residual, t_end, bounds: Bounds):
    """(state, health) after integrating from x to new: a new state that is non-finite or
    outside `bounds` is discarded, the rollout stays frozen at x (its last good checked
    state) and is flagged diverged at t_end (s)."""
    bad = ~within_bounds(new, bounds) & ~health.diverged
    keep = health.diverged | bad
    x = jax.tree.map(lambda old, nw: jnp.where(keep, old, nw), x, new)
    return x, Health(health.diverged | bad, jnp.where(bad, t_end, health.diverged_at),
                     jnp.where(keep, health.residual, residual))


def advance(model: GridModel, x: GridState, health: Health, t0, n: int, dt: float,
            task: Task, fault: network.Fault, bounds: Bounds):
    """n Heun steps (static) from time t0 (s); (state, health) after them.

    Divergence is checked once, after the n steps (an agent step or an output sample), not
    at every step (`checked`).
    """
    new, residual = integrate(model, x, health.residual, t0, n, dt, task, fault)
    t_end = (t0 + n * dt).astype(model.network.real_dtype)
    return checked(x, new, health, residual, t_end, bounds)


@partial(jax.jit, static_argnames=("n_samples", "decimation", "dt", "bounds"))
def rollout(model: GridModel, task: Task, n_samples: int, decimation: int, dt: float,
            bounds: Bounds = Bounds()) -> Trajectory:
    """Simulate n_samples × decimation steps of dt seconds; sample every `decimation` steps."""
    fault = network.fault_view(model.network, task.fault_bus, task.fault_z)
    real = model.network.real_dtype

    def sample(carry, k):
        x, h = carry
        n0 = k * decimation
        x, h = advance(model, x, h.replace(residual=jnp.zeros((), real)), n0.astype(real) * dt,
                       decimation, dt, task, fault, bounds)
        t = (n0 + decimation).astype(real) * dt
        return (x, h), observe(model, x, t, dt, task, fault) + (h.residual,)

    x0 = model.initial
    first = observe(model, x0, jnp.zeros((), real), dt, task, fault) + (jnp.zeros((), real),)
    (x, health), samples = jax.lax.scan(sample, (x0, initial_health(model)),
                                        jnp.arange(n_samples))
    vm, va, speed, angle, left, flags, residual = jax.tree.map(
        lambda f, s: jnp.concatenate([f[None], s]), first, samples)
    t = jnp.arange(n_samples + 1, dtype=real) * (decimation * dt)
    return Trajectory(t=t, vm=vm, va=va, speed_dev=speed, angle=angle, residual=residual,
                      load_left=left, load_flags=flags, diverged=health.diverged,
                      diverged_at=health.diverged_at, final=x)


def _samples(t_end: float, dt: float, decimation: int) -> int:
    if DT.problem(dt):
        raise ValueError(f"dt = {dt!r} s: allowed range is {DT} (2-5 ms is usual)")
    if not isinstance(decimation, int) or decimation < 1:
        raise ValueError(f"decimation = {decimation!r}: must be an int >= 1")
    Range(0.0, 3600.0, "s", lo_open=True).check("t_end", t_end)
    return max(1, int(round(t_end / (dt * decimation))))


def simulate(model: GridModel, t_end: float, dt: float = 0.005,
             fault: FaultEvent | None = None, load_changes: Sequence[LoadChange] = (),
             decimation: int = 1, bounds: Bounds = Bounds()) -> Trajectory:
    """One rollout of `t_end` seconds (rounded to whole samples) with the given events."""
    task = make_task(model, fault, load_changes)
    return simulate_batch(model, task, t_end, dt, decimation, bounds, batched=False)


def simulate_batch(model: GridModel, tasks: Task, t_end: float, dt: float = 0.005,
                   decimation: int = 1, bounds: Bounds = Bounds(), batched: bool = True):
    """Rollouts of a batch of tasks (leading axis on every Task field), vmapped."""
    n = _samples(t_end, dt, decimation)
    run = partial(rollout, n_samples=n, decimation=decimation, dt=float(dt), bounds=bounds)
    with jax.enable_x64(model.precision == "float64"):
        return vmap_minor(run, in_axes=(None, 0))(model, tasks) if batched else run(model, tasks)
