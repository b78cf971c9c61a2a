"""Gymnasium adapter for the FIDVR load-shedding environment (`jaxgrid.env`).

`LoadSheddingGymEnv` wraps the functional `LoadSheddingEnv` in the stateful `gymnasium.Env`
API (Gymnasium >= 1.0: `reset(seed, options) -> (obs, info)`,
`step(action) -> (obs, reward, terminated, truncated, info)`), for agents written against
Gymnasium. Importing this module registers the built-in studies and a generic id:

    import gymnasium
    import jaxgrid.gym  # registers the ids below
    env = gymnasium.make("jaxgrid/IEEE39-FIDVR-v0")          # or "jaxgrid/IEEE300-FIDVR-v0"
    env = gymnasium.make("jaxgrid/FIDVR-v0", study="studies/ieee39_pnnl.toml")  # any study
    env = gymnasium.make("jaxgrid.gym:jaxgrid/IEEE39-FIDVR-v0")  # imports jaxgrid.gym itself

Keyword arguments of `gymnasium.make` go to the constructor, e.g.
`gymnasium.make("jaxgrid/FIDVR-v0", study=builtin("ieee39_fidvr", (0.9, 1.0, 1.1)),
config={"episode": 6.0})`.

Every `reset` draws one task (operating point and fault) from the constructor's `tasks`
(default: the study's training set) with the env's seeded `np_random`, or takes
`options={"task": FaultEvent | None, "point": int}`. One episode is one task; the
observation, action, reward, `terminated` (recovery failed or the simulation diverged) and
`truncated` (episode length reached) are those of `LoadSheddingEnv` (see its module docstring
and the PNNL PARS study: Huang et al., "Accelerated deep reinforcement learning based load
shedding for emergency voltage control", 2022). `reset` and `step` are jitted once per
instance; the host side converts to NumPy and Python types. For batched training stay with
`jaxgrid.episode.play_tasks`: this adapter runs one episode at a time.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces

from jaxgrid.env import EnvParams
from jaxgrid.simulate import FaultEvent, make_task
from jaxgrid.study import Study, load_study
from jaxgrid.tasks import TaskSpec

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
      observation: (history·(n_observed + n_action),) the voltage magnitude at the observed
        buses, in [0, bounds.max_voltage] p.u. (a rollout leaving that bound is declared
        diverged and frozen), then the connected load fraction at the action buses, in [0, 1];
        stacked oldest first when history > 1.
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
        self._grids = [jax.device_put(self.study.point(k)) for k in range(self.study.n_points)]
        for spec in self.tasks:
            self._point(spec.operating_point)
        self._x64 = self.env.precision == "float64"

        cfg, n_observed = self.env.config, len(self.env.observed)
        n_action = len(self.env.action_slots)
        one_low = np.zeros(self.env.obs_size, np.float32)
        one_high = np.concatenate([np.full(n_observed, cfg.bounds.max_voltage, np.float32),
                                   np.ones(self.env.obs_size - n_observed, np.float32)])
        self.observation_space = spaces.Box(np.tile(one_low, cfg.history),
                                            np.tile(one_high, cfg.history), dtype=np.float32)
        self.action_space = spaces.Box(np.float32(self.params.action_low),
                                       np.float32(self.params.action_high), shape=(n_action,),
                                       dtype=np.float32)

        env = self.env
        self._reset_fn = jax.jit(lambda task, params, grid: env.reset(None, task, params, grid))
        self._step_fn = jax.jit(env.step)
        self._state = self._grid = None

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
        self._grid = self._grids[point]
        with jax.enable_x64(self._x64):
            obs, self._state = self._reset_fn(make_task(self._template, fault),
                                              self.params, self._grid)
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
            obs, self._state, reward, _, info = self._step_fn(self._state, jnp.asarray(action),
                                                              self.params, self._grid)
        info = {key: value.item() for key, value in jax.device_get(info).items()}
        info["time"] = round(int(self._state.step) * self.env.config.agent_dt, 9)
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

__all__ = ["ENV_IDS", "LoadSheddingGymEnv"]
