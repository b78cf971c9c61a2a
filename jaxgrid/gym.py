"""Gymnasium adapter for the FIDVR load-shedding environment (`jaxgrid.env`).

`LoadSheddingGymEnv` wraps the functional `LoadSheddingEnv` in the stateful `gymnasium.Env`
API (Gymnasium >= 1.0: `reset(seed, options) -> (obs, info)`,
`step(action) -> (obs, reward, terminated, truncated, info)`), for agents written against
Gymnasium. Importing this module registers the study's two tasks:

    import gymnasium
    import jaxgrid.gym  # registers the ids below
    env = gymnasium.make("jaxgrid/IEEE39-FIDVR-v0")          # or "jaxgrid/IEEE300-FIDVR-v0"
    env = gymnasium.make("jaxgrid.gym:jaxgrid/IEEE39-FIDVR-v0")  # imports jaxgrid.gym itself

Keyword arguments of `gymnasium.make` go to the constructor, e.g.
`gymnasium.make("jaxgrid/IEEE39-FIDVR-v0", load_level=1.2, config={"episode": 6.0})`.

Every `reset` draws one task from the constructor's `tasks` (default: the study's training
faults, `jaxgrid.tasks.study_task_set(case, "train")`) with the env's seeded
`np_random`, or takes `options={"task": FaultEvent | None}`. One episode is one task; the
observation, action, reward, `terminated` (recovery failed or the simulation diverged) and
`truncated` (episode length reached) are those of `LoadSheddingEnv` (see its module docstring
and the PNNL PARS study: Huang et al., "Accelerated deep reinforcement learning based load
shedding for emergency voltage control", 2022). `reset` and `step` are jitted once per
instance; the host side converts to NumPy and Python types. For batched training stay with
`LoadSheddingEnv.rollout`: this adapter runs one episode at a time.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces

from jaxgrid import cases
from jaxgrid.env import EnvParams, LoadSheddingEnv, study_params
from jaxgrid.simulate import FaultEvent, make_task

# Registered ids -> the built-in study case they wrap.
ENV_IDS = {"jaxgrid/IEEE39-FIDVR-v0": "ieee39_fidvr", "jaxgrid/IEEE300-FIDVR-v0": "ieee300_fidvr"}


def training_faults(case: str) -> list[FaultEvent | None]:
    """The study's training faults of a built-in case (None: the no-fault task)."""
    from jaxgrid.tasks import study_task_set

    try:
        specs = study_task_set(case, "train")
    except ValueError as err:
        raise ValueError(f"{err}; pass tasks=[FaultEvent | None, ...]") from None
    return [spec.event() for spec in specs]


class LoadSheddingGymEnv(gymnasium.Env):
    """One FIDVR load-shedding episode at a time behind the Gymnasium API.

    Args:
      case: built-in study case, "ieee39_fidvr" or "ieee300_fidvr".
      load_level: operating point of the case (factor on every load and dispatch).
      tasks: faults `reset` draws from, each a `FaultEvent` or None (no fault); default the
        study's training faults of the case (`training_faults`).
      config: overrides of `EnvConfig.for_study` fields, e.g. {"episode": 6.0} (s),
        {"history": 3}.
      params: reward and action values (`EnvParams`), default the study's for the case
        (`jaxgrid.env.study_params`).

    Spaces (float32):
      observation: (history·(n_observed + n_action),) the voltage magnitude at the observed
        buses, in [0, bounds.max_voltage] p.u. (a rollout leaving that bound is declared
        diverged and frozen), then the connected load fraction at the action buses, in [0, 1];
        stacked oldest first when history > 1.
      action: (n_action,) fraction of each action bus's initial load to shed this step, in
        [params.action_low, params.action_high] (negative sheds); values outside are clipped.

    `info` of `step`: "terminated", "truncated", "diverged" (bool), "shed_pu" (load shed this
    step, p.u. system base), "time" (s after the step). `info` of `reset`: "task" (the
    FaultEvent or None of the episode), "time" (0.0). Stepping after the episode ended goes
    on simulating; call `reset`.
    """

    metadata = {"render_modes": []}

    def __init__(self, case: str = "ieee39_fidvr", load_level: float = 1.0,
                 tasks: Sequence[FaultEvent | None] | None = None,
                 config: Mapping[str, Any] | None = None, params: EnvParams | None = None):
        self.study = cases.load(case, load_level=load_level)
        self.env = LoadSheddingEnv.for_study(self.study, **dict(config or {}))
        self.params = params if params is not None else study_params(case)
        self.tasks = tuple(training_faults(case) if tasks is None else tasks)
        if not self.tasks:
            raise ValueError("tasks = []: give at least one FaultEvent or None")
        for k, fault in enumerate(self.tasks):
            if fault is not None and not isinstance(fault, FaultEvent):
                raise ValueError(f"tasks[{k}] = {fault!r} ({type(fault).__name__}): must be a "
                                 "FaultEvent or None")
        self._task_arrays = [make_task(self.env.model, f) for f in self.tasks]
        self._x64 = self.env.model.precision == "float64"

        cfg, n_observed = self.env.config, len(self.env.observed)
        one_low = np.zeros(self.env.obs_size, np.float32)
        one_high = np.concatenate([np.full(n_observed, cfg.bounds.max_voltage, np.float32),
                                   np.ones(len(self.env.action_slots), np.float32)])
        self.observation_space = spaces.Box(np.tile(one_low, cfg.history),
                                            np.tile(one_high, cfg.history), dtype=np.float32)
        n_action = len(self.env.action_slots)
        self.action_space = spaces.Box(np.float32(self.params.action_low),
                                       np.float32(self.params.action_high), shape=(n_action,),
                                       dtype=np.float32)

        env = self.env
        self._reset_fn = jax.jit(lambda task, params: env.reset(None, task, params))
        self._step_fn = jax.jit(env.step)
        self._state = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """(obs (n_obs,) float32, info) of a new episode; see the class docstring."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"task"})
        if unknown:
            raise ValueError(f"reset options {unknown}: allowed 'task' (FaultEvent or None)")
        if "task" in options:
            fault = options["task"]
            if fault is not None and not isinstance(fault, FaultEvent):
                raise ValueError(f"options['task'] = {fault!r} ({type(fault).__name__}): must "
                                 "be a FaultEvent or None")
            task = make_task(self.env.model, fault)
        else:
            k = int(self.np_random.integers(len(self.tasks)))
            fault, task = self.tasks[k], self._task_arrays[k]
        with jax.enable_x64(self._x64):
            obs, self._state = self._reset_fn(task, self.params)
        return np.asarray(obs, np.float32), {"task": fault, "time": 0.0}

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
                                                              self.params)
        info = {key: value.item() for key, value in jax.device_get(info).items()}
        info["time"] = round(int(self._state.step) * self.env.config.agent_dt, 9)
        return (np.asarray(obs, np.float32), float(reward), bool(info["terminated"]),
                bool(info["truncated"]), info)


def _register() -> None:
    for env_id, case in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=f"{__name__}:LoadSheddingGymEnv",
                               kwargs={"case": case})


_register()

__all__ = ["ENV_IDS", "LoadSheddingGymEnv", "training_faults"]
