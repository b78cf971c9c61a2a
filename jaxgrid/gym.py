"""The FIDVR load-shedding environment (`jaxgrid.env`) behind the Gym APIs, one adapter with
two faces:

- gymnax's (`LoadSheddingGymnax`, functional and jittable, every episode one task drawn from
  the params: what rejax's PPO trains on, `baselines.ppo`; `gymnax_env(study)` makes it);
- Gymnasium's (`LoadSheddingGymEnv`, stateful, one episode at a time on the host, for agents
  written against Gymnasium >= 1.0: `reset(seed, options) -> (obs, info)`,
  `step(action) -> (obs, reward, terminated, truncated, info)`), whose reset and step are
  the gymnax adapter's, jitted. Importing this module registers the built-in studies and a
  generic id:

    import gymnasium
    import jaxgrid.gym  # registers the ids below
    env = gymnasium.make("jaxgrid/IEEE39-FIDVR-v0")          # or "jaxgrid/IEEE300-FIDVR-v0"
    env = gymnasium.make("jaxgrid/FIDVR-v0", study="studies/ieee39_pnnl.toml")  # any study
    env = gymnasium.make("jaxgrid.gym:jaxgrid/IEEE39-FIDVR-v0")  # imports jaxgrid.gym itself

Keyword arguments of `gymnasium.make` go to the constructor, e.g.
`gymnasium.make("jaxgrid/FIDVR-v0", study=builtin("ieee39_fidvr", (0.9, 1.0, 1.1)),
config={"episode": 6.0})`.

Every Gymnasium `reset` draws one task (operating point and fault) from the constructor's
`tasks` (default: the study's training set) with the env's seeded `np_random`, or takes
`options={"task": FaultEvent | None, "point": int}`. One episode is one task; the
observation, action, reward, `terminated` (recovery failed or the simulation diverged) and
`truncated` (episode length reached) are those of `LoadSheddingEnv` (see its module docstring
and the PNNL PARS study: Huang et al., "Accelerated deep reinforcement learning based load
shedding for emergency voltage control", 2022). The host side converts to NumPy and Python
types. For batched training stay with `jaxgrid.episode.play_tasks` or the gymnax face: the
Gymnasium one runs one episode at a time.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from gymnax.environments import environment, spaces as gymnax_spaces
from gymnasium import spaces

from jaxgrid.env import EnvParams, EnvState, LoadSheddingEnv
from jaxgrid.grid import GridModel
from jaxgrid.problem import at_point
from jaxgrid.simulate import FaultEvent, Task, make_task
from jaxgrid.study import Study, load_study
from jaxgrid.tasks import PointTask, TaskSpec

# --------------------------------------------------------------------------- #
# The gymnax face
# --------------------------------------------------------------------------- #


@struct.dataclass
class GymnaxParams:
    """Values of the adapter (traced; the grid models are data, not constants).

    Attributes:
      env: reward and action values.  models: the study's grid models, every array leaf
        with a leading (n_points,) axis.  tasks: (n_tasks,) the tasks `reset` draws from.
      max_steps_in_episode: agent steps per episode (static).
    """

    env: EnvParams
    models: GridModel
    tasks: PointTask
    max_steps_in_episode: int = struct.field(pytree_node=False, default=100)


@struct.dataclass
class GymnaxState:
    """One episode of the adapter.

    Attributes:
      inner: the `LoadSheddingEnv` state.  point: () int32 its operating point.
      time: () int32 agent steps taken (gymnax's field).
      episode_return: () reward summed so far in this episode.
      returns_sum, returns_count: () sum and number of the returns of the episodes that
        ended since the counters were last zeroed (training statistics; `step` keeps them
        across the automatic reset).
    """

    inner: EnvState
    point: jnp.ndarray
    time: jnp.ndarray
    episode_return: jnp.ndarray
    returns_sum: jnp.ndarray
    returns_count: jnp.ndarray


class LoadSheddingGymnax(environment.Environment):
    """`LoadSheddingEnv` behind the gymnax API, one task per episode.

    `reset_env` draws a task uniformly from `params.tasks` (operating point and fault, as
    PARS's uniform sampling) and resets (`reset_task`); `step_env` steps with the grid model
    of that task's operating point; gymnax's `step` resets automatically when an episode ends.

    Spaces: observation (history·n_obs,) as `LoadSheddingEnv` (`observation_bounds`); action
    (n_action,) in [-1, 1] mapped linearly onto [action_low, action_high] (fraction of the
    initial load shed per step) with `normalize_actions`, else in [action_low, action_high]
    itself. The bounds are Python floats fixed at construction (rejax's policy keeps them as
    static attributes), so the adapter's params must carry the same action range.
    """

    def __init__(self, env: LoadSheddingEnv, action_low: float, action_high: float,
                 normalize_actions: bool = True):
        self.env = env
        self.low, self.high = float(action_low), float(action_high)
        self.normalize_actions = bool(normalize_actions)
        self.n_action = len(env.action_slots)
        self.n_obs = env.config.history * env.obs_size

    def env_action(self, action):
        """The env's action (fraction of the initial load) of a policy action."""
        if not self.normalize_actions:
            return action
        return self.low + (jnp.clip(action, -1.0, 1.0) + 1.0) * (0.5 * (self.high - self.low))

    def draw_task(self, key, params: GymnaxParams) -> PointTask:
        """One task of `params.tasks`, uniformly."""
        n_tasks = jax.tree.leaves(params.tasks)[0].shape[0]
        k = jax.random.randint(key, (), 0, n_tasks)
        return jax.tree.map(lambda a: a[k], params.tasks)

    def reset_env(self, key, params: GymnaxParams):
        task = self.draw_task(key, params)
        return self.reset_task(task.task, task.point, params)

    def reset_task(self, task: Task, point, params: GymnaxParams):
        """(obs, state) of an episode of `task` at operating point `point` (() int)."""
        obs, inner = self.env.reset(None, task, params.env, at_point(params.models, point))
        zero = jnp.zeros((), jnp.float32)
        state = GymnaxState(inner=inner, point=jnp.asarray(point, jnp.int32),
                            time=jnp.zeros((), jnp.int32), episode_return=zero,
                            returns_sum=zero, returns_count=jnp.zeros((), jnp.int32))
        return obs, state

    def step_env(self, key, state: GymnaxState, action, params: GymnaxParams):
        del key
        grid = at_point(params.models, state.point)
        obs, inner, reward, done, info = self.env.step(state.inner, self.env_action(action),
                                                       params.env, grid)
        state = state.replace(inner=inner, time=state.time + 1,
                              episode_return=state.episode_return + reward)
        return obs, state, reward, done, info

    def step(self, key, state: GymnaxState, action, params: GymnaxParams | None = None):
        """gymnax's step (automatic reset) keeping the return statistics across the reset."""
        obs, new, reward, done, info = super().step(key, state, action, params)
        finished = state.episode_return + reward
        new = new.replace(returns_sum=state.returns_sum + jnp.where(done, finished, 0.0),
                          returns_count=state.returns_count + done.astype(jnp.int32))
        return obs, new, reward, done, info

    def observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) (history·n_obs,) float32: the voltage magnitude at the observed buses
        in [0, bounds.max_voltage] p.u. (a rollout leaving that bound is declared diverged
        and frozen), then the connected load fraction at the action buses in [0, 1];
        stacked oldest first when history > 1."""
        n_observed, one = len(self.env.observed), self.env.obs_size
        high = np.concatenate([np.full(n_observed, self.env.config.bounds.max_voltage,
                                       np.float32), np.ones(one - n_observed, np.float32)])
        history = self.env.config.history
        return np.zeros(history * one, np.float32), np.tile(high, history)

    def action_bounds(self) -> tuple[float, float]:
        """(low, high) of a policy's action."""
        return (-1.0, 1.0) if self.normalize_actions else (self.low, self.high)

    def observation_space(self, params: GymnaxParams):
        return gymnax_spaces.Box(*self.observation_bounds(), (self.n_obs,), jnp.float32)

    def action_space(self, params: GymnaxParams | None = None):
        return gymnax_spaces.Box(*self.action_bounds(), (self.n_action,), jnp.float32)

    @property
    def name(self) -> str:
        return "LoadShedding"

    @property
    def default_params(self):
        """None: the params hold the study's models and tasks (`gymnax_env` makes them)."""
        return None


def gymnax_env(study: Study, task_set: str = "train", normalize_actions: bool = True,
               env: LoadSheddingEnv | None = None):
    """(LoadSheddingGymnax, GymnaxParams) of `study`'s task set (every operating point ×
    fault), with `env` (default `study.env()`, e.g. `study.env(episode=6.0)`)."""
    env = env or study.env()
    params = study.params
    adapter = LoadSheddingGymnax(env, float(params.action_low), float(params.action_high),
                                 normalize_actions)
    values = GymnaxParams(env=params, models=study.models,
                          tasks=study.batch(study.tasks(task_set)),
                          max_steps_in_episode=env.config.n_steps)
    return adapter, values


# --------------------------------------------------------------------------- #
# The Gymnasium face
# --------------------------------------------------------------------------- #

# Registered ids -> the study they wrap (None: the `study` keyword names it).
ENV_IDS = {"jaxgrid/IEEE39-FIDVR-v0": "ieee39_fidvr", "jaxgrid/IEEE300-FIDVR-v0": "ieee300_fidvr",
           "jaxgrid/FIDVR-v0": None}


class LoadSheddingGymEnv(gymnasium.Env):
    """One FIDVR load-shedding episode at a time behind the Gymnasium API.

    Args:
      study: a `Study`, or a built-in study name or study file (`jaxgrid.study.load_study`).
      tasks: tasks `reset` draws from, each a `TaskSpec` (operating point and fault), a
        `FaultEvent` or None (no fault; both at operating point 0); default the study's
        training set.
      config: overrides of the study's `EnvConfig` fields, e.g. {"episode": 6.0} (s),
        {"history": 3}.
      params: reward and action values (`EnvParams`), default the study's.

    Spaces (float32):
      observation: (history·(n_observed + n_action),) as the gymnax face's
        (`LoadSheddingGymnax.observation_bounds`).
      action: (n_action,) fraction of each action bus's initial load to shed this step, in
        [params.action_low, params.action_high] (negative sheds); values outside are clipped.

    `info` of `step`: "terminated", "truncated", "diverged" (bool), "shed_pu" (load shed this
    step, p.u. system base), "time" (s after the step). `info` of `reset`: "task" (the
    FaultEvent or None of the episode), "point" (its operating point), "time" (0.0).
    Stepping after the episode ended goes
    on simulating; call `reset`.
    """

    metadata = {"render_modes": []}

    def __init__(self, study: Study | str = "ieee39_fidvr",
                 tasks: Sequence[TaskSpec | FaultEvent | None] | None = None,
                 config: Mapping[str, Any] | None = None, params: EnvParams | None = None):
        if study is None:
            raise ValueError("jaxgrid/FIDVR-v0 needs study=NAME|FILE|Study")
        self.study = study if isinstance(study, Study) else load_study(str(study))
        self.env = self.study.env(**dict(config or {}))
        self.params = params if params is not None else self.study.params
        self.tasks = tuple(self.study.tasks("train") if tasks is None else
                           (_spec(t, k) for k, t in enumerate(tasks)))
        if not self.tasks:
            raise ValueError("tasks = []: give at least one TaskSpec, FaultEvent or None")
        self._template = self.study.point(0)  # host arrays: bus numbering for make_task
        for spec in self.tasks:
            self._point(spec.operating_point)
        self._x64 = self.env.precision == "float64"
        # the gymnax face in the env's own action range; its tasks are drawn here
        self.adapter = LoadSheddingGymnax(self.env, float(self.params.action_low),
                                          float(self.params.action_high),
                                          normalize_actions=False)
        with jax.enable_x64(self._x64):
            self._values = jax.device_put(GymnaxParams(
                env=self.params, models=self.study.models, tasks=None,
                max_steps_in_episode=self.env.config.n_steps))
        self.observation_space = spaces.Box(*self.adapter.observation_bounds(),
                                            dtype=np.float32)
        low, high = self.adapter.action_bounds()
        self.action_space = spaces.Box(np.float32(low), np.float32(high),
                                       shape=(self.adapter.n_action,), dtype=np.float32)
        self._reset_fn = jax.jit(self.adapter.reset_task)
        self._step_fn = jax.jit(self.adapter.step_env)
        self._state = None

    def _point(self, point) -> int:
        if isinstance(point, bool) or not isinstance(point, (int, np.integer)) or not (
                0 <= point < self.study.n_points):
            raise ValueError(f"operating point {point!r}: the study has {self.study.n_points} "
                             f"(0 to {self.study.n_points - 1})")
        return int(point)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """(obs (n_obs,) float32, info) of a new episode; see the class docstring."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"task", "point"})
        if unknown:
            raise ValueError(f"reset options {unknown}: allowed 'task' (FaultEvent or None) "
                             "and 'point' (operating point index)")
        if "task" in options or "point" in options:
            fault = options.get("task")
            if fault is not None and not isinstance(fault, FaultEvent):
                raise ValueError(f"options['task'] = {fault!r} ({type(fault).__name__}): must "
                                 "be a FaultEvent or None")
            point = self._point(options.get("point", 0))
        else:
            spec = self.tasks[int(self.np_random.integers(len(self.tasks)))]
            fault, point = spec.event(), spec.operating_point
        with jax.enable_x64(self._x64):
            obs, self._state = self._reset_fn(make_task(self._template, fault), point,
                                              self._values)
        return np.asarray(obs, np.float32), {"task": fault, "point": point, "time": 0.0}

    def step(self, action):
        """(obs, reward, terminated, truncated, info) after one agent step (agent_dt s)."""
        if self._state is None:
            raise RuntimeError("step before reset: call reset() first")
        action = np.asarray(action, np.float32)
        if action.shape != self.action_space.shape:
            raise ValueError(f"action shape {action.shape}: expected {self.action_space.shape} "
                             "(one value per action bus)")
        with jax.enable_x64(self._x64):
            obs, self._state, reward, _, info = self._step_fn(None, self._state,
                                                              jnp.asarray(action), self._values)
        info = {key: value.item() for key, value in jax.device_get(info).items()}
        info["time"] = round(int(self._state.inner.step) * self.env.config.agent_dt, 9)
        return (np.asarray(obs, np.float32), float(reward), bool(info["terminated"]),
                bool(info["truncated"]), info)


def _spec(task, k: int) -> TaskSpec:
    """A TaskSpec from a constructor task (FaultEvent or None: at operating point 0)."""
    if isinstance(task, TaskSpec):
        return task
    if task is None:
        return TaskSpec(0, 0.0)
    if isinstance(task, FaultEvent):
        return TaskSpec(task.bus, task.duration, task.start, 0, task.r, task.x)
    raise ValueError(f"tasks[{k}] = {task!r} ({type(task).__name__}): must be a TaskSpec, a "
                     "FaultEvent or None")


def _register() -> None:
    for env_id, study in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=f"{__name__}:LoadSheddingGymEnv",
                               kwargs={"study": study})


_register()

__all__ = ["ENV_IDS", "GymnaxParams", "GymnaxState", "LoadSheddingGymEnv", "LoadSheddingGymnax",
           "gymnax_env"]
