"""Model-predictive load shedding by gradients through the simulator: the MPC baseline of the
PNNL PARS study (which used trajectory-sensitivity MPC, 63.31 s per decision).

At a decision step the controller takes the episode's current simulator state, predicts the
next `horizon` seconds of the study's reward for a shedding plan u (H agent steps × action
buses, fractions of the initial load in [0, −action_low]), and improves the plan by
`iterations` projected Adam steps on ∇u of the predicted return (`jax.grad` through
`LoadSheddingEnv.step`, optax). It applies the plan's first action, shifts the plan by one
step as the next decision's warm start, and decides again `every` agent steps. Everything
is one jittable controller of `jaxgrid.episode` that plans from the episode's state (its
`plans = True`: the episode loop is a scan), so a test set is one compiled, vmapped program:

    planner, params, carry = mpc_controller(env, MpcOptions(horizon=1.0))
    out = jaxgrid.episode.play_tasks(env, planner, params, tasks, env_params, grid, carry)

The prediction model (choices, documented where they differ from the plant):
  * Gradient surrogate: stall, stall jump and restart of the motors are switches with zero
    gradient. The prediction model gives them the gradient of a sigmoid of width `width`
    (p.u. of voltage) and `timer_width` (s) (`jaxgrid.models.acmotor`); the predicted
    trajectory stays bitwise the plant's, only the gradient changes (0 widths: exact).
  * Recovery penalty: a step that fails the recovery check earns −M, whose gradient is 0.
    The planner's objective keeps the value −M but takes the gradient of the step's shaped
    reward (envelope deviation and shedding cost) on that step (straight-through).
  * What it knows: before the fault starts the prediction runs without it (no clairvoyance);
    from the fault's start on it knows the fault, its impedance and its clearing time (set
    by protection).
  * `dt`: the prediction may step coarser than the plant (0: the plant's step). It steps
    at one fixed step: a plant's coarse step outside the fault window
    (`jaxgrid.steppers.Solver.coarse_dt`) is not used, since its per-agent-step choice has
    no reverse-mode gradient.
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jaxgrid.checks import Range
from jaxgrid.env import EnvParams, EnvState, LoadSheddingEnv
from jaxgrid.episode import ControlInputs
from jaxgrid.grid import GridModel

# Each option's allowed values, with its meaning: the one table `parse_options` checks.
OPTION_RANGES = {
    "horizon": Range(0.0, 30.0, "s: the prediction horizon (whole agent steps, at least "
                     "`every`)", lo_open=True),
    "every": Range(1, 1000, "agent steps per decision"),
    "iterations": Range(1, 10000, "Adam steps per decision"),
    "learning_rate": Range(0.0, 1.0, "Adam step, fraction of the initial load"),
    "width": Range(0.0, 1.0, "p.u.: the stall/restart surrogate's width in voltage (0: "
                   "exact gradient)"),
    "timer_width": Range(0.0, 10.0, "s: the stall/restart surrogate's width in timer time"),
    "dt": Range(0.0, 1.0, "s: the prediction step (0: the plant's)"),
}


@dataclasses.dataclass(frozen=True)
class MpcOptions:
    """MPC settings (module docstring). Defaults from `experiments.tune_mpc` on 8 of the 39-bus
    built-in study's test tasks that fail without shedding (from horizon 1 s, every 2,
    width 0.02: every = 1 recovered 6 of 8 against 4, width = 0 5 of 8, horizon 2 s 5 of 8)."""

    horizon: float = 1.0
    every: int = 1
    iterations: int = 10
    learning_rate: float = 0.05
    width: float = 0.0
    timer_width: float = 0.02
    dt: float = 0.01

    def __post_init__(self):
        for name, allowed in OPTION_RANGES.items():
            allowed.check(f"MPC option {name}", getattr(self, name))


def parse_options(text: str) -> MpcOptions:
    """MpcOptions from "horizon=2,iterations=20" (empty: the defaults); ValueError names the
    option and its allowed range."""
    values = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, _, raw = item.partition("=")
        if name not in OPTION_RANGES or not raw:
            raise ValueError(f"MPC option {item!r}: write name=value with name one of "
                             f"{', '.join(OPTION_RANGES)}")
        kind = int if isinstance(getattr(MpcOptions, name), int) else float
        try:
            values[name] = kind(raw)
        except ValueError as err:
            raise ValueError(f"MPC option {name} = {raw!r}: not a{'n int' if kind is int else ' number'}"
                             ) from err
    return MpcOptions(**values)


@struct.dataclass
class MpcParams:
    """The MPC's traced settings (vmap over them freely): learning_rate, width (p.u.),
    timer_width (s), all ()."""

    learning_rate: jax.Array
    width: jax.Array
    timer_width: jax.Array


def surrogate_model(grid: GridModel, width, timer_width) -> GridModel:
    """`grid` with the motors' stall/restart gradient surrogate set (jittable)."""

    def group(g):
        params = {k: (jnp.full_like(v, width) if k.endswith("stall_surrogate_v") else
                      jnp.full_like(v, timer_width) if k.endswith("stall_surrogate_t") else v)
                  for k, v in g.params.items()}
        return g.replace(params=params)

    return grid.replace(loads=tuple(group(g) for g in grid.loads))


def known_task(state: EnvState, agent_dt: float) -> EnvState:
    """`state` with the fault hidden until it has started (the prediction's knowledge)."""
    task = state.task
    t = state.step * agent_dt
    hidden = t < task.fault_start
    return state.replace(task=task.replace(
        fault_end=jnp.where(hidden, task.fault_start, task.fault_end)))


def feasible(env: LoadSheddingEnv, state: EnvState, shed):
    """`shed` (n_action,) limited to the load left to shed at each action bus
    (`LoadSheddingEnv.sheddable`; none where nothing is, so no request is invalid)."""
    left = env.sheddable(state.grid.load_left[env.action_slots])
    return jnp.where(left > 0, jnp.minimum(shed, left), 0.0)


def horizon_return(env: LoadSheddingEnv, plan, state: EnvState, params: EnvParams,
                   grid: GridModel):
    """Predicted return of shedding `plan` (H, n_action) (fractions shed per agent step,
    >= 0) from `state`: the sum of the rewards until the episode ends or the horizon does.
    Its gradient follows the shaped reward on a failing step (module docstring)."""

    def step(carry, shed_now):
        state, total, live = carry
        _, new, reward, done, info = env.step(state, -feasible(env, state, shed_now), params,
                                              grid)
        shaped = info["shaped_reward"]
        reward = reward + info["terminated"] * (shaped - jax.lax.stop_gradient(shaped))
        return (new, total + live * reward, live & ~done), None

    zero = jnp.zeros((), plan.dtype)
    (_, total, _), _ = jax.lax.scan(step, (state, zero, ~state.done), plan)
    return total


def decide(env: LoadSheddingEnv, iterations: int, plan, state: EnvState, params: EnvParams,
           grid: GridModel, mpc: MpcParams):
    """(best plan (H, n_action), its predicted return, first predicted return): `iterations`
    projected Adam ascent steps from `plan` on `horizon_return`, keeping the best plan seen.
    """
    high = -params.action_low
    value_and_grad = jax.value_and_grad(horizon_return, argnums=1)
    optimizer = optax.adam(mpc.learning_rate)

    def improve(carry, _):
        plan, opt_state, best_plan, best = carry
        value, grad = value_and_grad(env, plan, state, params, grid)
        better = value > best
        best_plan, best = jnp.where(better, plan, best_plan), jnp.where(better, value, best)
        updates, opt_state = optimizer.update(-grad, opt_state)
        plan = jnp.clip(plan + updates, 0.0, high)
        return (plan, opt_state, best_plan, best), value

    start = (plan, optimizer.init(plan), plan, jnp.full((), -jnp.inf, plan.dtype))
    (_, _, best_plan, best), values = jax.lax.scan(improve, start, None, length=iterations)
    return best_plan, best, values[0]


class Mpc:
    """The receding-horizon controller (module docstring) for `jaxgrid.episode`.

    Carry: the current plan (H, n_action); controller params: `MpcParams`. `plans`: the
    episode runs it in a scan, so the step index of its `lax.cond` is not batched.
    """

    plans = True

    def __init__(self, env: LoadSheddingEnv, options: MpcOptions):
        cfg = env.config
        self.options = options
        # one fixed step (a scan: the gradient needs reverse mode, which a step chosen per
        # agent step, coarse_dt's while loop, does not have)
        self.prediction = env.with_config(dt=options.dt or cfg.dt, coarse_dt=None)
        self.agent_dt = cfg.agent_dt
        self.steps = int(round(options.horizon / cfg.agent_dt))
        if self.steps < options.every:
            raise ValueError(f"MPC horizon = {options.horizon} s is {self.steps} agent steps "
                             f"of {cfg.agent_dt} s: it must cover every = {options.every}")

    def plan(self, plan, inputs: ControlInputs, mpc: MpcParams):
        """The plan after one decision from the episode's state."""
        grid = surrogate_model(inputs.grid, mpc.width, mpc.timer_width)
        state = known_task(inputs.state, self.agent_dt)
        return decide(self.prediction, self.options.iterations, plan, state, inputs.params,
                      grid, mpc)[0]

    def __call__(self, mpc: MpcParams, obs, plan, inputs: ControlInputs):
        del obs  # the MPC reads the simulator state
        plan = jax.lax.cond(inputs.step % self.options.every == 0,
                            lambda p: self.plan(p, inputs, mpc), lambda p: p, plan)
        action = -feasible(self.prediction, inputs.state, plan[0])
        shifted = jnp.concatenate([plan[1:], jnp.zeros_like(plan[:1])])
        return action, shifted


def mpc_controller(env: LoadSheddingEnv, options: MpcOptions | None = None):
    """(planner, MpcParams, initial plan of zeros (H, n_action)) for
    `jaxgrid.episode.play_tasks` and `experiments.evaluate --controller mpc:...`."""
    options = options or MpcOptions()
    planner = Mpc(env, options)
    real = np.float64 if env.precision == "float64" else np.float32
    params = MpcParams(*(np.asarray(getattr(options, k), real)
                         for k in ("learning_rate", "width", "timer_width")))
    carry = np.zeros((planner.steps, len(env.action_slots)), real)
    return planner, params, carry
