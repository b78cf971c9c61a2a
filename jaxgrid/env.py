"""The FIDVR load-shedding environment of the PNNL PARS study, functional and jittable.

    env = study.env()                         # or LoadSheddingEnv(model, EnvConfig(...))
    grid = study.point(0)                     # the grid model of one operating point (data)
    obs, state = env.reset(key, task, params, grid)
    obs, state, reward, done, info = env.step(state, action, params, grid)

The episode loop (a controller acting every agent step, vmapped over tasks) is
`jaxgrid.episode`.

Every agent step (0.1 s) the action sheds, per action bus, a fraction of its initial load
(in [-0.2, 0], negative sheds, clipped to what remains within `shed_limit`; requests up to
`action_deadband` are dropped); the grid then runs for one agent step of simulation steps.
The observation is the voltage magnitude at the observed buses and (unless
`include_action_status` is off) the remaining load fraction at the action buses, optionally
the last k of them stacked: one per agent step, or one every `obs_interval` seconds within
it.
The reward per step is

    c1·Σ_i ΔV_i − c2·Σ_j ΔP_j − c3·n_invalid − c_normal·n_normal − c_pre·n_prefault,

ΔV_i = min(V_i − V_env(t), 0) against the recovery envelope (`jaxgrid.recovery`), ΔP_j the
load shed this step in p.u. of the system base, n_normal the requests at action buses in normal
operation (`jaxgrid.recovery.normal_operation`, the paper's second kind of invalid action);
with `action_mask = "hadrec"` such requests (and every request of the first 0.15 s after
clearing) are dropped before they shed anything, for every controller alike; an episode that still has a voltage of the
recovery-check set below the recovery level after the recovery time (or diverges) earns −M
and ends (`terminated`); reaching the episode length ends it too (`truncated`). Each term
is a named function below. `EnvConfig` is structure (static), `EnvParams` values (traced),
and the grid model (`GridModel`, one operating point) is an argument of every call, never a
constant of the compiled step: one compilation serves every operating point of a grid.
"""
from __future__ import annotations

import copy
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jaxgrid import network
from jaxgrid.case import VOLTAGE
from jaxgrid.checks import InputError, Range, check_int, check_listed
from jaxgrid.grid import GridModel, GridState
from jaxgrid.recovery import (MASK_HOLD, envelope, mask_allows, normal_operation,
                             supervision_allows)
from jaxgrid.simulate import Bounds, Health, Task, advance, bus_voltage_sets, initial_health
from jaxgrid.steppers import Solver, clip_closed, shed


@struct.dataclass
class EnvParams:
    """Reward and action values of the task (defaults: the study's 39-bus task).

    Attributes:
      c_voltage: c1, weight of the envelope deviation (p.u. of voltage).
      c_shed: c2, weight of the load shed per step (p.u. of the system base).
      c_invalid: c3, penalty per shedding request at an empty action bus.
      c_normal: penalty per shedding request at an action bus in normal operation (after
        clearing, its voltage at or above 0.8/0.9/0.95 p.u.: `jaxgrid.recovery`); 0 leaves
        the term out (RLGC's environment); the PNNL studies set it to c3, as the paper's
        invalid action is also one "when the system is within normal operation".
      c_prefault: penalty per shedding request before the fault.
      unstable_penalty: M, the reward of the step that fails recovery or diverges.
      recovery_level: p.u. voltage the recovery-check set must reach ...
      recovery_time: ... this many seconds after clearing.
      action_low, action_high: the action range (fraction of the initial load per step).
    """

    c_voltage: float = 260.0
    c_shed: float = 150.0
    c_invalid: float = 3.0
    c_normal: float = 0.0
    c_prefault: float = 100.0
    unstable_penalty: float = 1000.0
    recovery_level: float = 0.95
    recovery_time: float = 4.0
    action_low: float = -0.2
    action_high: float = 0.0


# The allowed EnvParams values. The reward is maximised and every weight and penalty enters it
# with its sign fixed in `step` (c1·ΣΔV with ΔV <= 0, −c2, −c3, −c_pre, −M), so all are >= 0.
PARAM_RANGES = {
    "c_voltage": Range(0.0, 1e9, "per p.u. of voltage deviation"),
    "c_shed": Range(0.0, 1e9, "per p.u. of load shed"),
    "c_invalid": Range(0.0, 1e9, "per request"),
    "c_normal": Range(0.0, 1e9, "per request"),
    "c_prefault": Range(0.0, 1e9, "per request"),
    "unstable_penalty": Range(0.0, 1e12, "(the reward -M of a failed episode)"),
    "recovery_level": VOLTAGE,
    "recovery_time": Range(0.0, 3600.0, "s"),
    "action_low": Range(-1.0, 0.0, "of the initial load per step"),
    "action_high": Range(-1.0, 0.0, "of the initial load per step"),
}


def check_params(values: dict, key=lambda field: field) -> None:
    """InputError for an EnvParams value (given as {field: value}) outside PARAM_RANGES or an
    action range with low > high; `key(field)` names the field as the user wrote it."""
    for field, value in values.items():
        PARAM_RANGES[field].check(key(field), value)
    low, high = (values.get(f, getattr(EnvParams, f)) for f in ("action_low", "action_high"))
    if low > high:
        raise InputError(key("action_low"), low, f"must be <= action_high = {high}")


SOLVER_FIELDS = tuple(f.name for f in dataclasses.fields(Solver))  # EnvConfig.of, replace
AGENT_DT = Range(0.0, 60.0, "s", lo_open=True)
EPISODE = Range(0.0, 3600.0, "s", lo_open=True)
HISTORY = Range(1, 1000, "observations")
OBS_INTERVAL = Range(0.0, 60.0, "s", lo_open=True)
ACTION_DEADBAND = Range(0.0, 1.0, "of the initial load per step")
SHED_LIMIT = Range(0.0, 1.0, "of the initial load per episode", lo_open=True)
ACTION_MASKS = ("none", "hadrec", "undervoltage")  # EnvConfig.action_mask


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Structure of the task (static).

    Attributes:
      observed_buses, action_buses: RAW bus numbers.
      solver: how the grid is integrated (`jaxgrid.steppers.Solver`: step, sweeps, motor
        step, coarse step outside the fault window); the simulator's, held here so that the
        environment's agent steps are whole numbers of its steps. A study file writes its
        fields in [env] (sweeps in [compile]); `replace` takes them as EnvConfig's.
      agent_dt: control step, s (a whole number of solver.dt and of solver.coarse_dt).
      episode: length, s.
      history: number of last observations stacked (1: just the current one).
      obs_interval: s between the stacked observations, a whole fraction of agent_dt and a
        whole number of the solver's steps; each agent step then appends agent_dt/obs_interval
        observations, the last at its end (HADREC's GridPACK environment samples every
        0.02 s). None: one per agent step, at its end.
      include_action_status: the observation ends with the connected load fraction at the
        action buses (PNNL includeActionStatusInObservations).
      action_deadband: a request to shed at most this fraction of a bus's initial load is
        dropped: not applied and not penalised (HADREC's GridPACK environment: 0.01). 0:
        every request counts.
      shed_limit: the most of each action bus's initial load an episode may shed (fraction):
        a request is clipped to what remains above 1 − shed_limit, and one at a bus with
        nothing left within the limit counts as an invalid request (the paper's "load ...
        already shed to zero"). [choice]; default 1.0, the paper's (a bus may be shed to
        zero); 0.6 gives every controller the three UVLS stages' authority (each 20 %).
      action_mask: "none" (every request is applied: the paper's Java environment, RLGC) or
        "hadrec" (its authors' GridPACK environment: a request at an action bus in normal
        operation, or in the first 0.15 s after clearing, is dropped: `jaxgrid.recovery.
        mask_allows` on the bus voltage at the request) or "undervoltage" (not the study's:
        a request at an action bus at or above the recovery level after clearing is dropped,
        `jaxgrid.recovery.supervision_allows`). [choice]; default "none", the paper's. The
        mask is the environment's, so it binds every controller alike.
      recovery_buses: the observed buses the recovery check covers (None: all of them).
      bounds: divergence bounds of the simulation.
    """

    observed_buses: tuple[int, ...]
    action_buses: tuple[int, ...]
    solver: Solver = Solver(dt=0.002)
    agent_dt: float = 0.1
    episode: float = 10.0
    history: int = 1
    obs_interval: float | None = None
    include_action_status: bool = True
    action_deadband: float = 0.0
    shed_limit: float = 1.0
    action_mask: str = "none"
    recovery_buses: tuple[int, ...] | None = None
    bounds: Bounds = Bounds()

    def __post_init__(self):
        """InputError naming the field (as `key`) of a value outside its range."""
        AGENT_DT.check("agent_dt", self.agent_dt)
        steps = {"dt": self.solver.dt}
        if self.solver.coarse_dt is not None:
            steps["coarse_dt"] = self.solver.coarse_dt
        spans = {"agent_dt": self.agent_dt}
        if self.obs_interval is not None:
            OBS_INTERVAL.check("obs_interval", self.obs_interval)
            _check_whole("agent_dt", self.agent_dt, "observation intervals", "obs_interval",
                         self.obs_interval)
            spans["obs_interval"] = self.obs_interval
        for span, length in spans.items():
            for name, dt in steps.items():
                _check_whole(span, length, "simulation steps", name, dt)
        check_int("history", self.history, HISTORY)
        ACTION_DEADBAND.check("action_deadband", self.action_deadband)
        SHED_LIMIT.check("shed_limit", self.shed_limit)
        if self.action_mask not in ACTION_MASKS:
            raise InputError("action_mask", self.action_mask, f"must be one of {ACTION_MASKS}")
        if EPISODE.check("episode", self.episode) < self.agent_dt:
            raise InputError("episode", self.episode, f"must be >= agent_dt = {self.agent_dt} s",
                             related=("agent_dt",))
        check_listed("observed_buses", self.observed_buses, "bus (the policy's inputs)")
        check_listed("action_buses", self.action_buses, "bus (the policy's outputs)")
        if self.recovery_buses is not None:
            check_listed("recovery_buses", self.recovery_buses, "bus, or leave it out to "
                         "check every observed bus")
            outside = sorted(set(self.recovery_buses) - set(self.observed_buses))
            if outside:
                raise InputError("recovery_buses", list(self.recovery_buses), f"buses {outside} "
                                 "are not observed buses", related=("observed_buses",))

    @classmethod
    def of(cls, values: dict) -> EnvConfig:
        """The config of {field: value} naming EnvConfig's fields and the solver's
        (`SOLVER_FIELDS`, as a study file's [env] table and its [compile] sweeps), the
        solver's others EnvConfig's default solver's; checked."""
        solver = {k: values[k] for k in SOLVER_FIELDS if k in values}
        return cls(solver=dataclasses.replace(cls.solver, **solver),
                   **{k: v for k, v in values.items() if k not in solver})

    def values(self) -> dict:
        """{field: value} of EnvConfig's fields and the solver's (what `of` takes)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        solver = fields.pop("solver")
        return {**fields, **{k: getattr(solver, k) for k in SOLVER_FIELDS}}

    def replace(self, **changes) -> EnvConfig:
        """This config with fields of EnvConfig or of its solver changed, checked."""
        solver = {k: changes.pop(k) for k in SOLVER_FIELDS if k in changes}
        if solver:
            changes["solver"] = dataclasses.replace(self.solver, **solver)
        return dataclasses.replace(self, **changes)

    @property
    def dt(self) -> float:
        """The simulation step, s (solver.dt: the fault window's, with a coarse step)."""
        return self.solver.dt

    @property
    def n_steps(self) -> int:
        """Agent steps per episode."""
        return int(round(self.episode / self.agent_dt))

    @property
    def samples_per_step(self) -> int:
        """Observations appended to the history per agent step."""
        return 1 if self.obs_interval is None else int(round(self.agent_dt / self.obs_interval))


def _check_whole(name: str, span: float, what: str, unit_name: str, unit: float) -> None:
    """InputError naming `name` unless `span` (s) is a whole number (>= 1) of `what`, the
    field `unit_name` = `unit` (s)."""
    ratio = span / unit
    if not (abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1):
        raise InputError(name, span, f"must be a whole number (>= 1) of {what} {unit_name} = "
                         f"{unit} s", related=(unit_name,))


@struct.dataclass
class EnvState:
    """One episode's state.

    Attributes:
      grid: the simulator state.  health: divergence flags of the simulation.
      task: the episode's disturbance.  step: () int agent steps taken.
      history: (history, n_obs) the last observations, newest last.
      recovery_check: (n_observed,) bool buses that must recover (at or above the recovery
        level before the fault).
      action_vm: (n_action,) p.u. voltage at the action buses at the newest observation (what
        the normal-operation test of the next request reads).
      lowest_action_vm: () p.u. the lowest voltage at an action bus observed at least
        `MASK_HOLD` after clearing (inf until then): what a policy's arming level reads
        (`jaxgrid.episode.masked`).
      done: () bool.
    """

    grid: GridState
    health: Health
    task: Task
    step: jnp.ndarray
    history: jnp.ndarray
    recovery_check: jnp.ndarray
    action_vm: jnp.ndarray
    lowest_action_vm: jnp.ndarray
    done: jnp.ndarray


# --------------------------------------------------------------------------- #
# Reward terms (each checked by hand in tests/test_env.py)
# --------------------------------------------------------------------------- #

def envelope_deviation(vm, t_after_clearing):
    """Σ_i min(V_i − V_env, 0) (p.u., <= 0) of voltages vm (n,) at t_after_clearing (s).

    Zero before clearing (no envelope applies).
    """
    level = envelope(t_after_clearing, jnp)
    return jnp.where(jnp.isnan(level), 0.0, jnp.sum(jnp.minimum(vm - level, 0.0)))


def shed_power(amount, p0):
    """Σ_j load shed this step, p.u. system base: fractions amount (n,) of initial loads p0."""
    return jnp.sum(amount * p0)


def invalid_requests(request, left_before):
    """Number of action buses asked to shed (request > 0) with nothing left there."""
    return jnp.sum((request > 0) & (left_before <= 0))


def normal_requests(request, action_vm, t_after_clearing):
    """Number of action buses asked to shed while in normal operation (`jaxgrid.recovery`),
    their voltages action_vm (n,) p.u. at t_after_clearing (s)."""
    return jnp.sum((request > 0) & normal_operation(action_vm, t_after_clearing, jnp))


def prefault_requests(request, t, fault_start):
    """Number of action buses asked to shed before the fault (t < fault_start, s)."""
    return jnp.sum(request > 0) * (t < fault_start)


def mask_passes(mask: str, state: EnvState, t, params: EnvParams):
    """(n_action,) bool: the action buses whose requests `mask` ("hadrec" or
    "undervoltage", `EnvConfig.action_mask`) lets through at agent time t (s) from `state`
    (its bus voltages at the request, `state.action_vm`, p.u., and its task's clearing
    time)."""
    after = t - state.task.fault_end
    if mask == "hadrec":
        return mask_allows(state.action_vm, after, jnp)
    if mask == "undervoltage":
        return supervision_allows(state.action_vm, after, params.recovery_level, jnp)
    raise ValueError(f"action_mask {mask!r}: the masks are {ACTION_MASKS[1:]}")


def recovery_failed(vm, check, t_after_clearing, params: EnvParams):
    """() bool: after the recovery time, a checked voltage is still below the level."""
    late = t_after_clearing > params.recovery_time
    return late & jnp.any(check & (vm < params.recovery_level))


# --------------------------------------------------------------------------- #
# The environment
# --------------------------------------------------------------------------- #

class LoadSheddingEnv:
    """Structure (bus indices, step counts); `reset`/`step` are pure and take the grid model of
    the operating point as an argument (episodes: `jaxgrid.episode`).

    `model` gives the structure only (bus numbering, load slots, precision): any operating
    point of the same grid does, and its arrays are not kept.
    """

    def __init__(self, model: GridModel, config: EnvConfig):
        self.config = config
        self.precision = model.precision
        self.observed = np.array([model.bus_index(b) for b in config.observed_buses])
        self.action_slots = np.array([model.load_slot(b) for b in config.action_buses])
        self.action_buses = np.array([model.bus_index(b) for b in config.action_buses])
        checked = set(config.observed_buses if config.recovery_buses is None
                      else config.recovery_buses)
        self.recovery_mask = np.array([b in checked for b in config.observed_buses])

    def unchecked_buses(self, params: EnvParams, grid: GridModel) -> tuple[int, ...]:
        """Observed buses below the recovery level before any fault at this operating point:
        shedding cannot recover them, so the recovery check leaves them out (they still
        count in the reward)."""
        vm = np.abs(np.asarray(grid.v0))[self.observed]
        low = vm < float(params.recovery_level)
        return tuple(int(b) for b, is_low in zip(self.config.observed_buses, low) if is_low)

    def with_config(self, **changes) -> LoadSheddingEnv:
        """The same environment with `EnvConfig` or solver fields changed (e.g. dt, episode),
        checked (`EnvConfig.replace`)."""
        env = copy.copy(self)
        env.config = self.config.replace(**changes)
        return env

    @property
    def obs_size(self) -> int:
        """Length of one observation (before stacking)."""
        return len(self.observed) + len(self.action_slots) * self.config.include_action_status

    def _observe(self, grid: GridModel, x: GridState, t, task: Task, fault):
        """(vm (n_observed,), observation (n_obs,), action_vm (n_action,)) at t (s), p.u."""
        vm, action_vm = (jnp.abs(v) for v in bus_voltage_sets(
            grid, x, t, self.config.solver, task, fault, self.observed, self.action_buses))
        if not self.config.include_action_status:
            return vm, vm, action_vm
        return vm, jnp.concatenate([vm, x.load_left[self.action_slots]]), action_vm

    @staticmethod
    def _fault(grid: GridModel, task: Task):
        return network.fault_view(grid.network, task.fault_bus, task.fault_z)

    def reset(self, key, task: Task, params: EnvParams, grid: GridModel):
        """(obs (history·n_obs,), state) at t = 0; `key` is unused (the grid is deterministic)."""
        del key
        x = grid.initial
        real = grid.network.real_dtype
        vm, obs, action_vm = self._observe(grid, x, jnp.zeros((), real), task,
                                           self._fault(grid, task))
        history = jnp.tile(obs, (self.config.history, 1))
        check = (vm >= params.recovery_level) & self.recovery_mask
        state = EnvState(grid=x, health=initial_health(grid), task=task,
                         step=jnp.zeros((), jnp.int32), history=history,
                         recovery_check=check, action_vm=action_vm,
                         lowest_action_vm=jnp.full((), jnp.inf, real), done=jnp.zeros((), bool))
        return history.reshape(-1), state

    def _advance(self, grid: GridModel, x: GridState, health: Health, t, task: Task, fault,
                 done):
        """(grid state, health) one agent step after x at t (s), by the config's solver
        (`jaxgrid.simulate.advance`: with a coarse step, a finished episode (`done`, () bool)
        takes no steps)."""
        cfg = self.config
        return advance(grid, x, health, t, cfg.agent_dt, cfg.solver, task, fault, cfg.bounds,
                       done)

    def _advance_observed(self, grid: GridModel, x: GridState, health: Health, t, task: Task,
                          fault, done):
        """(grid state, health, vm (n_observed,) and action_vm (n_action,) at the step's end,
        observations (samples_per_step, n_obs)) one agent step after x at t (s): `_advance`
        and an observation at its end, or, with obs_interval, one `_advance` of obs_interval
        and an observation after each."""
        cfg = self.config
        if cfg.obs_interval is None:
            x, health = self._advance(grid, x, health, t, task, fault, done)
            vm, obs, action_vm = self._observe(grid, x, t + cfg.agent_dt, task, fault)
            return x, health, vm, action_vm, obs[None]
        interval = self.with_config(agent_dt=cfg.obs_interval, obs_interval=None)

        def sample(carry, k):
            x, health = carry
            start = t + k * cfg.obs_interval
            x, health = interval._advance(grid, x, health, start, task, fault, done)
            return (x, health), interval._observe(grid, x, start + cfg.obs_interval, task,
                                                  fault)

        (x, health), (vm, obs, action_vm) = jax.lax.scan(sample, (x, health),
                                                         jnp.arange(cfg.samples_per_step))
        return x, health, vm[-1], action_vm[-1], obs

    def sheddable(self, load_left):
        """(n_action,) fraction of each action bus's initial load still sheddable: what is
        left of it (load_left, (n_action,)) above 1 − `EnvConfig.shed_limit`."""
        limit = self.config.shed_limit
        return load_left if limit == 1.0 else jnp.maximum(load_left - (1.0 - limit), 0.0)

    def step(self, state: EnvState, action, params: EnvParams, grid: GridModel):
        """(obs, state, reward, done, info) after one agent step with `action` (n_action,)."""
        cfg, task = self.config, state.task
        real = grid.network.real_dtype
        t = state.step.astype(real) * cfg.agent_dt
        request = -clip_closed(action, params.action_low, params.action_high)  # >= 0
        if cfg.action_deadband > 0:
            request = jnp.where(request > cfg.action_deadband, request, 0.0)
        left = self.sheddable(state.grid.load_left[self.action_slots])
        penalties = (params.c_invalid * invalid_requests(request, left)
                     + params.c_normal * normal_requests(request, state.action_vm,
                                                         t - task.fault_end)
                     + params.c_prefault * prefault_requests(request, t, task.fault_start))
        if cfg.action_mask != "none":
            request = jnp.where(mask_passes(cfg.action_mask, state, t, params), request, 0.0)
        amount = jnp.minimum(request, left)
        x = state.grid.replace(load_left=shed(state.grid.load_left, self.action_slots, amount))
        fault = self._fault(grid, task)
        x, health, vm, action_vm, observed = self._advance_observed(grid, x, state.health, t,
                                                                    task, fault, state.done)
        t_next = t + cfg.agent_dt
        after = t_next - task.fault_end
        lowest = jnp.where(after >= MASK_HOLD, jnp.minimum(state.lowest_action_vm,
                                                           jnp.min(action_vm)),
                           state.lowest_action_vm)
        failed = recovery_failed(vm, state.recovery_check, after, params) | health.diverged
        shed_pu = shed_power(amount, grid.load_p0[self.action_slots])
        shaped = (params.c_voltage * envelope_deviation(vm, after) - params.c_shed * shed_pu
                  - penalties)
        reward = jnp.where(failed, -params.unstable_penalty, shaped)
        truncated = state.step + 1 >= cfg.n_steps
        done = failed | truncated
        history = jnp.concatenate([state.history, observed])[-cfg.history:]
        new = EnvState(grid=x, health=health, task=task, step=state.step + 1,
                       history=history, recovery_check=state.recovery_check,
                       action_vm=action_vm, lowest_action_vm=lowest, done=done)
        info = {"terminated": failed, "truncated": truncated & ~failed,
                "shed_pu": shed_pu, "shaped_reward": shaped,
                "diverged": health.diverged}
        return history.reshape(-1), new, reward, done, info

    def state_after(self, task: Task, params: EnvParams, grid: GridModel, steps: int):
        """The state after `steps` agent steps (an int, or a traced integer: one program for
        any count) without shedding, from reset."""
        _, state = self.reset(None, task, params, grid)
        zero = jnp.zeros(len(self.action_slots), grid.load_p0.dtype)
        return jax.lax.fori_loop(0, steps, lambda _, s: self.step(s, zero, params, grid)[1],
                                 state)
