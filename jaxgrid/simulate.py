"""Time-domain simulation: events as data, fixed-step Heun (modified Euler) in `lax.scan`.

One rollout is one jit-compiled function of (model, task); `simulate_batch` vmaps it over a
batch of tasks (fault bus, times, impedance, load changes), so tasks with different fault
buses share one compiled step. How a step is taken is the `jaxgrid.steppers.Solver` value
(step, sweeps, motor step, coarse step outside the fault window); `advance` runs a span
(a sample here, an agent step in `jaxgrid.env`) of steps. A rollout whose state becomes
non-finite or leaves physical bounds is frozen at its last good sample and flagged
(`Trajectory.diverged`); the rest of a batch is untouched. Everything is differentiable
(discrete logic through `jnp.where`).

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
from jaxgrid.batching import vmap_minor
from jaxgrid.checks import Range
from jaxgrid.dynamics import FAMILIES, machine_state, solve_network
from jaxgrid.grid import GridModel, GridState
from jaxgrid.steppers import Solver, fault_active, heun_step, motor_jacobian


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


def within_bounds(x: GridState, bounds: Bounds):
    """() bool: every state finite, speeds and voltages inside `bounds`."""
    finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in jax.tree.leaves(x)]))
    return (finite & jnp.all(jnp.abs(machine_state(x, "dw")) <= bounds.max_speed_dev)
            & jnp.all(jnp.abs(x.v) <= bounds.max_voltage))


def observe(model: GridModel, x: GridState, t, solver: Solver, task: Task,
            fault: network.Fault, buses=None):
    """(vm (n_bus,), va (n_bus,), Δω (n_gen,), δ (n_gen,), load_left, load_flags) at time t;
    with `buses` (static (k,) bus indices) vm and va of those buses only, (k,).

    The network is solved with at least `OBSERVE_SWEEPS` sweeps: a sample that falls on a
    fault's start or clearing sees the new topology from the warm start of the step before,
    which one or two sweeps leave far from converged (this costs one solution per sample).
    """
    v = bus_voltage_sets(model, x, t, solver, task, fault, buses)[0]
    return (jnp.abs(v), jnp.angle(v), machine_state(x, "dw"), machine_state(x, "delta"),
            x.load_left, x.load_flags)


def bus_voltage_sets(model: GridModel, x: GridState, t, solver: Solver, task: Task,
                     fault: network.Fault, *bus_sets):
    """Complex bus voltages at time t, one array per static index set of `bus_sets` ((k,)
    bus indices, or None for all buses), from one network solution (as `observe`); each set's
    rows of the product are computed apart, so adding a set leaves the others' rounding."""
    active = fault_active(task, t, solver.dt)
    _, current, _, _ = solve_network(model, x, fault, active,
                                     max(solver.sweeps, OBSERVE_SWEEPS))
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


def integrate(model: GridModel, x: GridState, residual, t0, n, solver: Solver, task: Task,
              fault: network.Fault, jacobian=None):
    """n Heun steps of solver.dt from time t0 (s, traced); (state, largest residual so far).

    n static: a `lax.scan` (differentiable); n traced (e.g. 0 or a whole span, chosen per
    rollout: `advance`'s coarse step): a `lax.while_loop`, forward mode only. With
    solver.motor_step "rosenbrock" the motors' Jacobian is evaluated once, at x (or given,
    `jaxgrid.steppers.motor_jacobian`), and held for the n steps (`heun_step`).
    """
    if jacobian is None and solver.implicit:
        jacobian = motor_jacobian(model, x)

    def step(j, carry):
        x, residual = carry
        new, r = heun_step(model, x, t0 + j * solver.dt, solver, task, fault, jacobian)
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


def advance(model: GridModel, x: GridState, health: Health, t0, span: float, solver: Solver,
            task: Task, fault: network.Fault, bounds: Bounds, done=None):
    """(state, health) `span` s (static, a whole number of steps) after x at t0 (s).

    Without solver.coarse_dt: span/dt steps of dt. With it: those steps if the span
    overlaps the fault window (`Solver.in_fault_window`), else span/coarse_dt steps of
    coarse_dt with coarse_sweeps network sweeps; one of the two loops runs, both holding the
    motors' Jacobian at x, evaluated once. There a finished rollout (`done`, () bool) takes
    no steps: vmapped, the two step loops run as long as their longest member, and a rollout
    frozen inside the fault window would otherwise keep the fine loop running for the whole
    batch. Divergence is checked once, after the span (an agent step or an output sample),
    not at every step (`checked`).
    """
    if solver.coarse_dt is None:
        n = solver.steps(span)
        new, residual = integrate(model, x, health.residual, t0, n, solver, task, fault)
        t_end = (t0 + n * solver.dt).astype(model.network.real_dtype)
        return checked(x, new, health, residual, t_end, bounds)
    window = solver.in_fault_window(t0, span, task)
    running = True if done is None else ~done
    fine, slow = window & running, ~window & running
    coarse = solver.coarse()
    jacobian = motor_jacobian(model, x) if solver.implicit else None
    new, residual = integrate(model, x, health.residual, t0,
                              jnp.where(fine, solver.steps(span), 0), solver, task, fault,
                              jacobian)
    new, residual = integrate(model, new, residual, t0, jnp.where(slow, coarse.steps(span), 0),
                              coarse, task, fault, jacobian)
    return checked(x, new, health, residual, t0 + span, bounds)


@partial(jax.jit, static_argnames=("n_samples", "decimation", "solver", "bounds"))
def trajectory(model: GridModel, task: Task, n_samples: int, decimation: int, solver: Solver,
               bounds: Bounds = Bounds()) -> Trajectory:
    """Simulate n_samples × decimation steps of solver.dt; sample every `decimation` steps."""
    fault = network.fault_view(model.network, task.fault_bus, task.fault_z)
    real = model.network.real_dtype
    dt = solver.dt

    def sample(carry, k):
        x, h = carry
        n0 = k * decimation
        x, h = advance(model, x, h.replace(residual=jnp.zeros((), real)), n0.astype(real) * dt,
                       decimation * dt, solver, task, fault, bounds)
        t = (n0 + decimation).astype(real) * dt
        return (x, h), observe(model, x, t, solver, task, fault) + (h.residual,)

    x0 = model.initial
    first = observe(model, x0, jnp.zeros((), real), solver, task, fault) + (jnp.zeros((), real),)
    (x, health), samples = jax.lax.scan(sample, (x0, initial_health(model)),
                                        jnp.arange(n_samples))
    vm, va, speed, angle, left, flags, residual = jax.tree.map(
        lambda f, s: jnp.concatenate([f[None], s]), first, samples)
    t = jnp.arange(n_samples + 1, dtype=real) * (decimation * dt)
    return Trajectory(t=t, vm=vm, va=va, speed_dev=speed, angle=angle, residual=residual,
                      load_left=left, load_flags=flags, diverged=health.diverged,
                      diverged_at=health.diverged_at, final=x)


def _solver(solver: Solver | float) -> Solver:
    """`solver`, or Solver(dt=solver) for a step alone (s); ValueError for a coarse step,
    which only an environment's agent steps use (`jaxgrid.env`)."""
    solver = solver if isinstance(solver, Solver) else Solver(dt=float(solver))
    if solver.coarse_dt is not None:
        raise ValueError(f"coarse_dt = {solver.coarse_dt}: a simulation samples at dt "
                         "throughout; the coarse step is an environment's (its agent steps)")
    return solver


def _samples(t_end: float, solver: Solver, decimation: int) -> int:
    if not isinstance(decimation, int) or decimation < 1:
        raise ValueError(f"decimation = {decimation!r}: must be an int >= 1")
    Range(0.0, 3600.0, "s", lo_open=True).check("t_end", t_end)
    return max(1, int(round(t_end / (solver.dt * decimation))))


def simulate(model: GridModel, t_end: float, solver: Solver | float = Solver(),
             fault: FaultEvent | None = None, load_changes: Sequence[LoadChange] = (),
             decimation: int = 1, bounds: Bounds = Bounds()) -> Trajectory:
    """One rollout of `t_end` seconds (rounded to whole samples) with the given events, by
    `solver` (or its step dt alone, s)."""
    task = make_task(model, fault, load_changes)
    return simulate_batch(model, task, t_end, solver, decimation, bounds, batched=False)


def simulate_batch(model: GridModel, tasks: Task, t_end: float,
                   solver: Solver | float = Solver(), decimation: int = 1,
                   bounds: Bounds = Bounds(), batched: bool = True):
    """Rollouts of a batch of tasks (leading axis on every Task field), vmapped, by `solver`
    (or its step dt alone, s)."""
    solver = _solver(solver)
    n = _samples(t_end, solver, decimation)
    with jax.enable_x64(model.precision == "float64"):
        return _rollouts(model, tasks, n, decimation, solver, bounds, batched)


@partial(jax.jit, static_argnums=(2, 3, 4, 5, 6))
def _rollouts(model: GridModel, tasks: Task, n_samples: int, decimation: int, solver: Solver,
              bounds: Bounds, batched: bool) -> Trajectory:
    """`trajectory` of each task (vmapped if `batched`) as one compiled program: evaluated
    eagerly, its steps outside the `lax.scan` would each be dispatched, and compiled per
    shape, on their own (measured: about 890 small XLA compiles of the GridPACK reference
    tests, 17 of their 40 s)."""
    run = partial(trajectory, n_samples=n_samples, decimation=decimation, solver=solver,
                  bounds=bounds)
    return vmap_minor(run, in_axes=(None, 0))(model, tasks) if batched else run(model, tasks)
