"""Three-stage under-voltage load-shedding (UVLS) relays: the rule-based baseline of the
PNNL PARS study (Huang et al., "Accelerated deep reinforcement learning based load shedding
for emergency voltage control", 2022), as a batched policy of `jaxgrid.env.LoadSheddingEnv`.

Every action bus has one relay with three stages. A stage picks up while the bus voltage is
below its level and trips when it has stayed below for its delay; it then sheds its fraction
of the bus's initial load, once (latched). The study's settings:

    stage 1: V < 0.70 p.u. for 0.33 s    sheds 20 %
    stage 2: V < 0.80 p.u. for 0.50 s    sheds 20 %
    stage 3: V < 0.90 p.u. for 1.50 s    sheds 20 %

A relay is a relay: it acts whenever the voltage is low, before, during or after a fault.

    policy_apply, policy_params, carry = uvls_policy(env)
    out = jaxgrid.episode.play_tasks(env, policy_apply, policy_params, tasks, EnvParams(), grid,
                                  carry)

Time granularity. The relays run at the control step `env.config.agent_dt` (0.1 s in the
study), on the voltage of the newest observation. Each low observation counts as one
control step of low voltage, so a stage trips on the n-th consecutive low observation with

    n = max(1, ceil(delay / agent_dt − 1e-4)),

i.e. the first n with n·agent_dt >= delay − 1e-4·agent_dt (the tolerance absorbs the
float32 error of the division): 0.33 s trips on the 4th low observation, 0.5 s on the 5th,
1.5 s on the 15th. An observation at or above the level resets that stage's count.

Carried remainder. The env sheds at most `-EnvParams.action_low` (0.2) of a bus's initial
load per control step and clips each request to what remains. When stages trip together
(or one stage's fraction exceeds that limit) the relay asks for at most `step_limit` per
step and carries the rest over to the next steps, so every tripped stage sheds its full
fraction eventually; a remainder larger than the load left at the bus is dropped, so the
relay never asks an empty bus (the env's invalid-request penalty is never charged).
"""
from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jaxgrid.env import EnvParams, LoadSheddingEnv

DELAY_TOLERANCE = 1e-4  # of a control step: delays this close to a whole step count as it
DUST = 1e-6  # a remainder owed below this (float rounding of a difference) is dropped


@dataclasses.dataclass(frozen=True)
class ParamInfo:
    """Meaning, unit, default and allowed range of one `UvlsParams` field."""

    name: str
    info: str
    unit: str
    default: tuple[float, ...] | float
    low: float
    high: float
    low_open: bool = False

    @property
    def allowed(self) -> str:
        return (f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}"
                f"{')' if math.isinf(self.high) else ']'}")

    def contains(self, value: np.ndarray) -> np.ndarray:
        above = value > self.low if self.low_open else value >= self.low
        return np.isfinite(value) & above & (value <= self.high)


# The one place that both `check_params` and the `UvlsParams` docstring read.
PARAMETERS = (
    ParamInfo("levels", "pick-up voltage per stage: the stage counts while V < level",
              "p.u.", (0.70, 0.80, 0.90), 0.0, 1.5, low_open=True),
    ParamInfo("delays", "time per stage the voltage must stay below its level",
              "s", (0.33, 0.50, 1.50), 0.0, math.inf),
    ParamInfo("fractions", "load shed per stage when it trips (their sum at most 1)",
              "fraction of the initial load", (0.20, 0.20, 0.20), 0.0, 1.0),
    ParamInfo("step_limit", "most load requested per bus and control step; set it to "
              "-EnvParams.action_low", "fraction of the initial load", -EnvParams().action_low,
              0.0, 1.0, low_open=True),
)
_INFO = {p.name: p for p in PARAMETERS}


def _default(name):
    return dataclasses.field(default_factory=lambda: np.asarray(_INFO[name].default, np.float64))


@struct.dataclass
class UvlsParams:  # docstring built from PARAMETERS just below
    levels: jax.Array = _default("levels")
    delays: jax.Array = _default("delays")
    fractions: jax.Array = _default("fractions")
    step_limit: jax.Array = _default("step_limit")


UvlsParams.__doc__ = (
    "Relay settings (traced values: vmap over them freely), the study's by default.\n\n"
    "Attributes:\n"
    + "".join(f"  {p.name}: {'(n_stage,)' if isinstance(p.default, tuple) else '()'} {p.info}, "
              f"[{p.unit}], allowed {p.allowed}, default {p.default}.\n" for p in PARAMETERS)
    + "\nNot checked on construction (jax rebuilds it from tracers); `check_params` is.")


@struct.dataclass
class UvlsState:
    """The relays' memory, one row per action bus (the policy carry).

    Attributes:
      low_steps: (n_action, n_stage) int32 consecutive observations below each stage's level.
      tripped: (n_action, n_stage) bool latched trips.
      owed: (n_action,) fraction of the initial load tripped but not yet requested.
    """

    low_steps: jax.Array
    tripped: jax.Array
    owed: jax.Array


def check_params(params: UvlsParams) -> UvlsParams:
    """`params` with NumPy float leaves, or ValueError naming the field, value and range."""
    values = {}
    for p in PARAMETERS:
        raw = getattr(params, p.name)
        try:
            value = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise ValueError(f"UvlsParams.{p.name} = {raw!r} ({type(raw).__name__}): must be "
                             f"numbers in {p.allowed} [{p.unit}]") from err
        shape = "(n_stage,)" if isinstance(p.default, tuple) else "()"
        if value.ndim != (1 if isinstance(p.default, tuple) else 0) or (value.ndim and
                                                                       value.size == 0):
            raise ValueError(f"UvlsParams.{p.name} = {raw!r}: shape {value.shape}, "
                             f"allowed {shape}")
        bad = ~p.contains(value)
        if np.any(bad):
            raise ValueError(f"UvlsParams.{p.name} = {value.tolist()}: must lie in "
                             f"{p.allowed} [{p.unit}] ({p.info})")
        values[p.name] = value
    sizes = {name: values[name].size for name in ("levels", "delays", "fractions")}
    if len(set(sizes.values())) != 1:
        raise ValueError(f"UvlsParams stage counts differ: {sizes}; levels, delays and "
                         "fractions need one entry per stage")
    if values["fractions"].sum() > 1.0 + 1e-9:
        raise ValueError(f"UvlsParams.fractions = {values['fractions'].tolist()}: sum "
                         f"{values['fractions'].sum():g} must lie in [0, 1] (fraction of the "
                         "bus's initial load)")
    return UvlsParams(**values)


def voltage_index(env: LoadSheddingEnv) -> tuple[int, ...]:
    """Position of each action bus's voltage in one observation (static, host side)."""
    observed = tuple(env.config.observed_buses)
    missing = [b for b in env.config.action_buses if b not in observed]
    if missing:
        raise ValueError(f"UVLS relays read the voltage of the action buses from the "
                         f"observation, but action buses {missing} are not among "
                         f"observed_buses {observed}; add them to EnvConfig.observed_buses")
    return tuple(observed.index(b) for b in env.config.action_buses)


def relay_step(params: UvlsParams, state: UvlsState, vm, left, agent_dt: float):
    """One control step of the relays.

    Args:
      params: settings.  state: memory.  vm: (n_action,) bus voltages, p.u.
      left: (n_action,) remaining load fraction.  agent_dt: control step, s (static).
    Returns:
      (request (n_action,) fraction of the initial load to shed now, >= 0; new state).
    """
    low = vm[:, None] < params.levels
    low_steps = jnp.where(low, state.low_steps + 1, 0)
    needed = jnp.maximum(jnp.ceil(params.delays / agent_dt - DELAY_TOLERANCE), 1.0)
    trips = low & (low_steps >= needed) & ~state.tripped
    owed = state.owed + jnp.sum(jnp.where(trips, params.fractions, 0.0), axis=-1)
    request = jnp.clip(jnp.minimum(owed, params.step_limit), 0.0, left)
    owed = jnp.clip(owed - request, 0.0, left - request)  # what cannot be shed is dropped
    owed = jnp.where(owed > DUST, owed, 0.0)
    return request, UvlsState(low_steps=low_steps, tripped=state.tripped | trips, owed=owed)


def uvls_policy(env: LoadSheddingEnv, params: UvlsParams | None = None):
    """UVLS relays at every action bus of `env`, as a controller for `jaxgrid.episode`.

    Args:
      env: the environment (reads `config.observed_buses`, `action_buses`, `agent_dt`,
        `history`).  params: relay settings (default: the study's), checked here.
    Returns:
      (policy_apply(params, obs, carry, inputs) -> (action (n_action,), carry),
      policy_params, initial_carry): the action is −request (the env's sign: negative
      sheds; `inputs` unused); the carry is a `UvlsState` of zeros, shared by all tasks of
      a rollout.
    Raises:
      ValueError: an action bus is not observed, or a setting is out of range.
    """
    index = voltage_index(env)
    n_action, n_observed = len(env.config.action_buses), len(env.config.observed_buses)
    newest = (env.config.history - 1) * env.obs_size  # start of the newest observation
    v_at = np.array([newest + i for i in index])
    if not env.config.include_action_status:
        raise ValueError("UVLS reads the connected load fraction from the observation: the "
                         "study must have include_action_status = true")
    left_at = np.arange(n_action) + newest + n_observed
    agent_dt = float(env.config.agent_dt)
    real = np.dtype(np.float64 if env.precision == "float64" else np.float32)
    checked = check_params(UvlsParams() if params is None else params)
    policy_params = jax.tree.map(lambda a: np.asarray(a, real), checked)
    n_stage = checked.levels.size
    carry = UvlsState(low_steps=np.zeros((n_action, n_stage), np.int32),
                      tripped=np.zeros((n_action, n_stage), bool),
                      owed=np.zeros(n_action, real))

    def policy_apply(params: UvlsParams, obs, carry: UvlsState, inputs):
        request, carry = relay_step(params, carry, obs[v_at], obs[left_at], agent_dt)
        return -request, carry

    return policy_apply, policy_params, carry
