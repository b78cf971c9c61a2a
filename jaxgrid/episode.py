"""The episode loop of `jaxgrid.env.LoadSheddingEnv`: a controller acting every agent step.

    out = play_tasks(env, controller, controller_params, tasks, params, grid, carry)  # vmapped
    out = play(env, controller, controller_params, task, params, grid, carry)        # one task

Every controller (a trained policy, the UVLS relays, the MPC) is called the same way:

    controller(controller_params, obs, carry, inputs: ControlInputs) -> (action, carry)

with obs (history·n_obs,), action (n_action,) and `inputs` the state before the action, the
grid model, the reward values and the agent step index; a policy ignores `inputs`, the MPC
(`baselines.mpc.Mpc`) plans from them. A controller whose attribute `plans` is true (the
MPC) runs in a `lax.scan` over every agent step, so its step index is not batched when
episodes are vmapped (a `lax.cond` on it stays a branch); every other controller runs in a
`lax.while_loop` that stops once the episode (vmapped: every episode of the batch) is done.
An episode can also run in parts, `result(run(..., run(..., start(...), k), n))`, between
which a trainer regroups the episodes still running (`jaxgrid.population`). The loop state is an
`EpisodeLoop`; after `done` the reward stops and the controller's state is held (gymnax's
`rollout` validity mask).
"""
from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

from jaxgrid.batching import vmap_minor
from jaxgrid.env import EnvParams, EnvState, LoadSheddingEnv, mask_passes
from jaxgrid.grid import GridModel
from jaxgrid.simulate import Task


@struct.dataclass
class ControlInputs:
    """What the episode gives a controller besides the observation.

    Attributes:
      state: the episode's state before the action.  grid: the operating point's model.
      params: the reward values.  step: () int32 agent step index; in a planner's scan it is
        not batched when episodes are vmapped (a `lax.cond` on it stays a branch).
    """

    state: EnvState
    grid: GridModel
    params: EnvParams
    step: jnp.ndarray


@struct.dataclass
class EpisodeLoop:
    """The state of an episode between agent steps.

    Attributes:
      step: () int32 agent steps the loop has taken (held steps after `done` included).
      obs: (history·n_obs,) the controller's next observation.
      env_state: the environment's state (`EnvState`).
      policy_carry: the controller's state (its dtypes kept throughout).
      reward: () total reward so far.  shed_pu: () load shed so far, p.u. of the system base.
      failed: () bool the episode ended by failing recovery or diverging (`terminated`).
    """

    step: jnp.ndarray
    obs: jnp.ndarray
    env_state: EnvState
    policy_carry: object
    reward: jnp.ndarray
    shed_pu: jnp.ndarray
    failed: jnp.ndarray


def start(env: LoadSheddingEnv, task: Task, params: EnvParams, grid: GridModel,
          policy_carry=None) -> EpisodeLoop:
    """The loop of an episode of `task` before its first agent step (`env.reset`)."""
    obs, state = env.reset(None, task, params, grid)
    zero = jnp.zeros((), obs.dtype)
    return EpisodeLoop(step=jnp.zeros((), jnp.int32), obs=obs, env_state=state,
                       policy_carry=policy_carry, reward=zero, shed_pu=zero,
                       failed=jnp.zeros((), bool))


def run(env: LoadSheddingEnv, controller, controller_params, params: EnvParams,
        grid: GridModel, loop: EpisodeLoop, until) -> EpisodeLoop:
    """`loop` continued until agent step `until` (int) or until it is done, in a
    `while_loop`; vmapped, until every episode of the batch is. Splitting an episode into
    runs does not change it."""
    step = _step(env, controller, controller_params, params, grid, False)
    return jax.lax.while_loop(lambda lp: (lp.step < until) & ~done(lp),
                              lambda lp: step(lp, lp.step)[0], loop)


def done(loop: EpisodeLoop):
    """() bool: the episode of `loop` has ended."""
    return loop.env_state.done


@functools.lru_cache(maxsize=8)
def idle_controller(n_action: int) -> Callable:
    """A controller (`play`'s signature) that never sheds at n_action buses; one function per
    size, so a compiled play of it is reused."""
    return lambda params, obs, carry, inputs: (jnp.zeros(n_action), carry)


ARMING_LEVELS = (0.0, 2.0)  # p.u., open bounds of an arming level
ARMING_LATE = (0.0, 60.0)  # s after clearing, open bounds of a late arming


def _check_open(value, bounds, name: str, unit: str) -> None:
    low, high = bounds
    if value is not None and not (isinstance(value, (int, float)) and not isinstance(value, bool)
                                  and low < value < high):
        raise ValueError(f"{name} = {value!r}: allowed {low:g} < {unit} < {high:g}")


def check_arming_level(level, name: str = "--arming-level") -> None:
    """ValueError naming `name` unless `level` is None or a number in the open range
    ARMING_LEVELS (p.u.)."""
    _check_open(level, ARMING_LEVELS, name, "p.u.")


def check_arming_late(late, level, name: str = "--arming-late") -> None:
    """ValueError naming `name` unless `late` is None, or a number in the open range
    ARMING_LATE (s) beside an arming `level` (without one the policy is always armed)."""
    _check_open(late, ARMING_LATE, name, "s")
    if late is not None and level is None:
        raise ValueError(f"{name} = {late!r}: needs an arming level (--arming-level), "
                         "which it adds a second way to arm to")


def masked(apply, mask: str, env: LoadSheddingEnv, arming_level: float | None = None,
           arming_late: float | None = None) -> Callable:
    """The controller `apply` (this module's signature) with its actions at the action buses
    that `mask` does not let shed (`jaxgrid.env.mask_passes` on the episode's state: the bus
    voltages at the request and the time since clearing) set to 0 (no request): a policy
    that masks its own requests, as a relay's arming logic does (`jaxgrid.problem.
    GridProblem.evaluator`'s self_mask, `baselines.controllers.load`). With `arming_level`
    (p.u.) it requests nothing at all until an action bus has been observed below that level
    at least the mask's hold after clearing (`EnvState.lowest_action_vm`), and stays armed
    for the episode: a far fault that only dips the voltages leaves it alone. With
    `arming_late` (s) it is armed as well while, that long or longer after clearing, a bus
    of the recovery check is below the recovery level (`EnvParams.recovery_level`): a slow
    sag that never dips an action bus below `arming_level` but would fail the check.
    ValueError outside `ARMING_LEVELS`, `ARMING_LATE` (`check_arming_late`)."""
    check_arming_level(arming_level)
    check_arming_late(arming_late, arming_level)
    agent_dt, n_observed = env.config.agent_dt, len(env.observed)

    def apply_masked(params, obs, carry, inputs: ControlInputs):
        action, carry = apply(params, obs, carry, inputs)
        state = inputs.state
        t = state.step.astype(inputs.grid.network.real_dtype) * agent_dt
        passes = mask_passes(mask, state, t, inputs.params)
        if arming_level is not None:
            armed = state.lowest_action_vm < arming_level
            if arming_late is not None:
                vm = state.history[-1, :n_observed]  # the newest observation's voltages
                armed |= (t - state.task.fault_end >= arming_late) & jnp.any(
                    state.recovery_check & (vm < inputs.params.recovery_level))
            passes &= armed
        return jnp.where(passes, action, jnp.zeros_like(action)), carry

    return apply_masked


def result(loop: EpisodeLoop) -> dict:
    """`play`'s dict (without the trace) from a finished episode loop."""
    state = loop.env_state
    return {"reward": loop.reward, "shed_pu": loop.shed_pu, "recovered": ~loop.failed,
            "steps": state.step, "diverged": state.health.diverged,
            "policy_carry": loop.policy_carry}


def play(env: LoadSheddingEnv, controller, controller_params, task: Task, params: EnvParams,
         grid: GridModel, policy_carry=None, trace: bool = False) -> dict:
    """One whole episode (un-batched; `play_tasks` vmaps it over tasks).

    `policy_carry` is the controller's initial state (None for feed-forward policies); it
    keeps its dtypes (a saved float32 policy runs in a float64 study). Without `trace`
    (static) and for a controller that does not plan, a `while_loop` (`run`) stops at
    `done`; otherwise a `scan` runs every agent step. Returns {"reward", "shed_pu",
    "recovered", "steps" (agent steps taken), "diverged", "policy_carry" (final)}; with
    `trace` also per agent step "vm" (n_steps, n_observed) p.u. and "shed_step_pu"
    (n_steps,), frozen after the episode ends.
    """
    loop = start(env, task, params, grid, policy_carry)
    n_steps = env.config.n_steps
    if not (trace or getattr(controller, "plans", False)):
        return result(run(env, controller, controller_params, params, grid, loop, n_steps))
    # a scan: per-step outputs, and an unbatched step index for a planner
    step = _step(env, controller, controller_params, params, grid, trace)
    loop, per_step = jax.lax.scan(step, loop, jnp.arange(n_steps))
    out = result(loop)
    if trace:
        out["vm"], out["shed_step_pu"] = per_step
    return out


def play_tasks(env: LoadSheddingEnv, controller, controller_params, tasks: Task,
               params: EnvParams, grid: GridModel, policy_carry=None,
               trace: bool = False) -> dict:
    """`play` vmapped over a batch of tasks (leading axis) at one operating point `grid`; the
    controller is shared. Every entry of the returned dict gains a leading axis."""
    return vmap_minor(lambda task: play(env, controller, controller_params, task, params, grid,
                                        policy_carry, trace))(tasks)


def _step(env: LoadSheddingEnv, controller, controller_params, params: EnvParams,
          grid: GridModel, trace: bool):
    """step(loop, k) -> (loop, (vm (n_observed,), shed p.u.) if `trace` else None): one agent
    step k of the controller's episode (held once done)."""
    n_observed = len(env.observed)

    def step(loop: EpisodeLoop, k):
        state = loop.env_state
        live = ~state.done
        inputs = ControlInputs(state, grid, params, k)
        action, carry = controller(controller_params, loop.obs, loop.policy_carry, inputs)
        # the controller's state keeps its dtype (a float32 policy in a float64 simulation)
        carry = jax.tree.map(lambda a, b: jnp.where(live, a, b).astype(b.dtype),
                             carry, loop.policy_carry)
        obs, new, reward, _, info = env.step(state, action, params, grid)
        new = jax.tree.map(lambda a, b: jnp.where(live, a, b), new, state)
        shed_now = jnp.where(live, info["shed_pu"], 0.0)
        loop = EpisodeLoop(step=loop.step + 1, obs=obs, env_state=new, policy_carry=carry,
                           reward=loop.reward + jnp.where(live, reward, 0.0),
                           shed_pu=loop.shed_pu + shed_now,
                           failed=loop.failed | (live & info["terminated"]))
        return loop, ((new.history[-1, :n_observed], shed_now) if trace else None)

    return step
