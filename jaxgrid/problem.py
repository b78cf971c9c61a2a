"""A study as a training problem, and its episodes at the study's operating points.

`at_point` picks an operating point of the stacked models inside jit; `PointEpisode` is the
episode a trainer runs per parameter vector and task; `stratified_sampler` draws tasks as the
PNNL PARS study does; `training_problem` bundles what `ars.train.train` needs from a study
(`GridProblem`: its tasks, the models, the sizes, and its `evaluator`, which runs a
population of policies on them batched and sharded: `jaxgrid.population`); `play_specs`
runs a controller on any tasks of a study in one compiled call (evaluation);
`recovery_check_step` is where a trainer regroups the episodes still running. Nothing here
imports `ars`: the trainer's types are met by their fields.
"""
from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrid import episode, population
from jaxgrid.batching import batch_major
from jaxgrid.checks import Range
from jaxgrid.env import EnvConfig, EnvParams, LoadSheddingEnv
from jaxgrid.grid import GridModel
from jaxgrid.study import Study, write_study
from jaxgrid.tasks import PointTask, TaskSet


def at_point(models: GridModel, point) -> GridModel:
    """The model of operating point `point` (traced int) from stacked `models`, inside jit.

    With one operating point the index is static, so nothing is gathered.
    """
    if jax.tree.leaves(models)[0].shape[0] == 1:
        return jax.tree.map(lambda a: a[0], models)
    return jax.tree.map(lambda a: a[point], models)


@dataclasses.dataclass(frozen=True)
class PointEpisode:
    """`jaxgrid.episode.play` at the task's operating point of stacked `models` (for
    `jaxgrid.population`): `episode(policy_apply, policy_params, task: PointTask,
    policy_carry, models) -> dict`, or in two runs, `result(resume(..., begin(..., steps)))`,
    between which the episodes still running are regrouped
    (`ars.pars.ParsConfig.compact_after`)."""

    env: LoadSheddingEnv
    params: EnvParams

    def __call__(self, policy_apply, policy_params, task: PointTask, policy_carry, models):
        return episode.play(self.env, policy_apply, policy_params, task.task, self.params,
                            at_point(models, task.point), policy_carry)

    def begin(self, policy_apply, policy_params, task: PointTask, policy_carry, models,
              steps: int) -> episode.EpisodeLoop:
        """The episode's loop after `steps` agent steps (or when done, if sooner)."""
        grid = at_point(models, task.point)
        loop = episode.start(self.env, task.task, self.params, grid, policy_carry)
        return episode.run(self.env, policy_apply, policy_params, self.params, grid, loop,
                           steps)

    def resume(self, policy_apply, policy_params, task: PointTask, models,
               loop: episode.EpisodeLoop) -> episode.EpisodeLoop:
        """`loop` (from `begin`) run to the episode's end."""
        return episode.run(self.env, policy_apply, policy_params, self.params,
                           at_point(models, task.point), loop, self.env.config.n_steps)

    done = staticmethod(episode.done)
    result = staticmethod(episode.result)


def play_specs(study: Study, env: LoadSheddingEnv, policy_apply, policy_params, specs,
               policy_carry=None, trace: bool = False, params: EnvParams | None = None):
    """Every task of `specs` in one compiled call: a vmap over their operating points (models
    batched; none for one point) of `jaxgrid.episode.play_tasks` over each point's tasks (one
    model shared), rewarded with `params` (default the study's).

    Every operating point of `specs` must have the same number of tasks (task sets do).
    Returns (specs in the order of the results, `play`'s dict with a leading axis).
    """
    points = sorted({s.operating_point for s in specs})
    groups = [[s for s in specs if s.operating_point == p] for p in points]
    if len({len(g) for g in groups}) != 1:
        raise ValueError("play_specs: every operating point needs the same number of tasks")
    ordered = [s for g in groups for s in g]
    shape = (len(points), len(groups[0]))
    tasks = jax.tree.map(lambda a: a.reshape(shape + a.shape[1:]), study.batch(ordered).task)
    models = jax.tree.map(lambda a: a[np.array(points)], study.models)
    params = study.params if params is None else params
    with jax.enable_x64(env.precision == "float64"):
        out = _points_play(env, policy_apply, trace)(models, tasks, params, policy_params,
                                                     policy_carry)
    out = jax.tree.map(lambda a: np.asarray(a).reshape((len(ordered),) + a.shape[2:]), out)
    return ordered, out


@functools.lru_cache(maxsize=32)
def _points_play(env: LoadSheddingEnv, policy_apply, trace: bool):
    """jit of `jaxgrid.episode.play_tasks` vmapped over operating points (models and tasks
    batched), one per (env, policy, trace), so repeated calls reuse the compilation. One
    operating point is played without the vmap: under it every primitive of the episode
    would be traced through JAX's batching as well (measured: about half an evaluation's
    tracing, docs/performance.md)."""

    def play(grid, task, params, policy_params, policy_carry):
        return episode.play_tasks(env, policy_apply, policy_params, task, params, grid,
                                  policy_carry, trace)

    def run(models, tasks, params, policy_params, policy_carry):
        if jax.tree.leaves(tasks)[0].shape[0] == 1:
            one = play(*jax.tree.map(lambda a: a[0], (models, tasks)), params, policy_params,
                       policy_carry)
            return jax.tree.map(lambda a: a[None], one)
        return jax.vmap(play, in_axes=(0, 0, None, None, None))(
            models, tasks, params, policy_params, policy_carry)

    return jax.jit(run)


def recovery_check_step(study: Study, task_set: str = "train") -> int:
    """The agent step by which every task of `task_set` has had its first recovery check
    (the first step that ends more than `recovery_time` s after clearing): an episode that
    fails it has stopped by then (`ars.pars.ParsConfig.compact_after`)."""
    last_clearing = max(s.fault_start + s.fault_duration for s in study.tasks(task_set))
    agent_dt = study.env().config.agent_dt
    return int(np.floor((last_clearing + float(study.params.recovery_time)) / agent_dt)) + 1


def stratified_sampler(task_set: TaskSet, n_points: int, m: int):
    """sample(key) -> (m,) indices into `task_set.specs(n_points)`: as the PARS study, k_b
    distinct fault buses × k_d distinct durations (k_b·k_d = m, k_d as large as the set
    allows), each pair at a uniformly drawn operating point and start."""
    n_p, n_s = len(task_set.points(n_points)), len(task_set.fault_starts)
    n_b, n_d = len(task_set.fault_buses), len(task_set.fault_durations)
    k_d = next((k for k in range(min(n_d, m), 0, -1) if m % k == 0 and m // k <= n_b), None)
    if k_d is None:
        raise ValueError(f"stratified sampling: m = {m} tasks are not k fault buses × k' "
                         f"durations of this set ({n_b} buses, {n_d} durations)")
    k_b = m // k_d

    def sample(key):
        k_bus, k_dur, k_point, k_start = jax.random.split(key, 4)
        bus = jax.random.choice(k_bus, n_b, (k_b,), replace=False)
        duration = jax.random.choice(k_dur, n_d, (k_d,), replace=False)
        bus, duration = (a.reshape(-1) for a in jnp.meshgrid(bus, duration, indexing="ij"))
        point = jax.random.randint(k_point, (m,), 0, n_p)
        start = jax.random.randint(k_start, (m,), 0, n_s)
        return ((point * n_s + start) * n_b + bus) * n_d + duration

    return sample


def layout(env_config: EnvConfig) -> dict:
    """What a saved policy observes and acts on (checked when it is evaluated); obs_interval
    only where set, so the layouts of policies saved before it existed still match."""
    interval = {} if env_config.obs_interval is None else {
        "obs_interval": env_config.obs_interval}
    return {"observed_buses": list(env_config.observed_buses),
            "action_buses": list(env_config.action_buses), "history": env_config.history,
            "include_action_status": env_config.include_action_status, **interval}


def run_info(study: Study, env_config: EnvConfig, task_set: str) -> dict:
    """What a training saves with its checkpoints and policies about the study it ran on
    (PARS and PPO alike): the study, its points, the task set, the layout, the action mask
    (a policy loaded under another warns), the history and the episode length (s)."""
    return {"study": study.name, "points": [p.label for p in study.points],
            "task_set": task_set, "layout": layout(env_config),
            "action_mask": env_config.action_mask, "history": env_config.history,
            "episode": env_config.episode}


# c_quiet, c_beat and beat_scale of `training_problem`'s shaping (not EnvParams fields: the
# environment cannot know whether a task would recover without control, or what another
# controller earns on it; the training problem can)
QUIET_CHARGE = Range(0.0, 1e9, "per p.u. of load shed on a task that recovers without control")
BEAT_BONUS = Range(0.0, 1e9, "reward units, the most an episode gains or loses against UVLS")
BEAT_SCALE = Range(0.0, 1e9, "reward units", lo_open=True)
SHAPING_TERMS = {"c_quiet": QUIET_CHARGE, "c_beat": BEAT_BONUS, "beat_scale": BEAT_SCALE}
DEFAULT_BEAT_SCALE = 100.0  # reward units: the 300-bus policy's narrow losses to UVLS, 8-237


@dataclasses.dataclass(frozen=True)
class GridProblem:
    """A study's task set as a training problem (the fields of `ars.train.Problem`).

    Attributes:
      study: the study.  env: its environment as trained (history, episode).
      episode: `PointEpisode`.  tasks: PointTask batch, each point an index into `data`.
      data: the task set's operating points' models, stacked (n_points, ...).
      obs_size: stacked observation length.  action_size: action buses.
      action_low, action_high: the action range, p.u.
      sampler: m -> `stratified_sampler`, or None (uniform).
      info: the run information saved with checkpoints and policies (study, points, task
        set, task sampling, layout, history, episode).
      quiet_charge: c_quiet (`training_problem`), per p.u. of load shed on a task that
        recovers without control (`tasks.quiet`); 0: none.
      beat_bonus, beat_scale: c_beat and beat_scale (`training_problem`): each episode's
        reward r gains beat_bonus·tanh((r − r_ref)/beat_scale), r_ref the reference
        controller's reward on its task (`tasks.reference_reward`); beat_bonus 0: none.
    """

    network = staticmethod(batch_major)  # a policy network runs batch-first in the episodes

    study: Study
    env: LoadSheddingEnv
    episode: Callable
    tasks: PointTask
    data: GridModel
    obs_size: int
    action_size: int
    action_low: float
    action_high: float
    sampler: Callable | None
    info: dict
    quiet_charge: float = 0.0
    beat_bonus: float = 0.0
    beat_scale: float = DEFAULT_BEAT_SCALE

    def evaluator(self, apply, carry, mesh, self_mask: bool = False,
                  arming_level: float | None = None, **batching) -> Callable:
        """The problem's `evaluate` of a population of `apply` (`jaxgrid.population.evaluator`
        of `PointEpisode`; batching: task_batch, compact_after, compact_chunks), each
        episode's reward less quiet_charge·(its load shed, p.u.) on the quiet tasks, plus
        the beat bonus against the reference controller (class docstring).
        self_mask: `apply` masks its own requests with the study's action mask
        (`jaxgrid.episode.masked`), so a request the mask would drop is never made (nor
        charged c_normal or c_prefault); ValueError on a study without one. arming_level
        (p.u., with self_mask): `apply` asks nothing until an action bus falls below it."""
        if self_mask:
            mask = self.env.config.action_mask
            if mask == "none":
                raise ValueError(f"--self-mask: study {self.study.name!r} has no action mask "
                                 "([env] action_mask) for the policy to mask its requests with")
            apply = episode.masked(apply, mask, self.env, arming_level)
        evaluate = population.evaluator(self.episode, apply, carry, mesh, **batching)
        if not (self.quiet_charge or self.beat_bonus):
            return evaluate

        def shaped(thetas, shared, tasks: PointTask, data):
            out = evaluate(thetas, shared, tasks, data)  # (P, m) per episode
            reward = out["reward"]
            if self.quiet_charge:
                reward = reward - self.quiet_charge * out["shed_pu"] * tasks.quiet
            if self.beat_bonus:
                margin = (out["reward"] - tasks.reference_reward) / self.beat_scale
                reward = reward + self.beat_bonus * jnp.tanh(margin)
            return {**out, "reward": reward.astype(out["reward"].dtype)}

        return shaped

    def save(self, folder: Path) -> None:
        """The resolved study as folder/study.toml (a run folder alone reproduces it)."""
        write_study(self.study, Path(folder) / "study.toml")


def training_problem(study: Study, policy_kind: str, history: int | None = None,
                     episode: float | None = None, task_set: str = "train",
                     sampling: str | None = None, shaping: dict | None = None,
                     reference: Callable | None = None) -> GridProblem:
    """The task set `task_set` of `study` (or several joined by "+", `Study.tasks`) for a
    `policy_kind` policy: episodes of `episode` s (default the study's), `history`
    observations stacked (default the study's for the kind), tasks drawn by `sampling`
    ("uniform" | "stratified" (one set only), default the study's), rewarded with the study's
    `EnvParams` but for the fields of `shaping` ({field: value}: reward weights for training
    only; evaluations keep the study's). shaping's "c_quiet" (`QUIET_CHARGE`) charges, on
    top, each p.u. of load shed on a task that recovers without control (`quiet_tasks`, run
    once here): a label only a trainer has, so it shapes training and enters no
    evaluation. Its "c_beat" (`BEAT_BONUS`) adds to each training episode's reward r
    c_beat·tanh((r − r_ref)/beat_scale) (`BEAT_SCALE`, default `DEFAULT_BEAT_SCALE`), r_ref
    the reward of `reference` (env -> (apply, params, carry), e.g. `baselines.uvls.
    uvls_policy`) on its task under the training's weights (`reference_rewards`, run once
    here): the training then values beating that controller on a task, however narrowly,
    beside the reward itself. The data holds only the set's operating points."""
    history = study.history(policy_kind) if history is None else history
    sampling = sampling or study.definition.training.task_sampling
    overrides = {k: v for k, v in (("history", history), ("episode", episode)) if v is not None}
    env = study.env(**overrides)
    weights = dict(shaping or {})
    terms = {name: allowed.check(name, weights.pop(name))
             for name, allowed in SHAPING_TERMS.items() if name in weights}
    quiet_charge, beat_bonus = terms.get("c_quiet", 0.0), terms.get("c_beat", 0.0)
    if beat_bonus and reference is None:
        raise ValueError("c_beat: a reference controller is needed (training_problem's "
                         "reference)")
    params = dataclasses.replace(study.params, **weights)
    if sampling == "stratified" and "+" in task_set:
        raise ValueError(f"--task-set {task_set}: stratified sampling draws from one task set")
    chosen = study.tasks(task_set)
    points = sorted({s.operating_point for s in chosen})
    specs = [dataclasses.replace(s, operating_point=points.index(s.operating_point))
             for s in chosen]  # indices into the set's points, in order
    info = {**run_info(study, env.config, task_set), "task_sampling": sampling,
            **({"shaping": dict(shaping)} if shaping else {})}
    tasks = study.batch(specs)
    if quiet_charge:
        quiet = quiet_tasks(study, env, chosen)
        print(f"c_quiet = {quiet_charge:g}: {int(quiet.sum())} of {len(quiet)} training tasks "
              "recover without control")
        tasks = tasks.replace(quiet=quiet)
    if beat_bonus:
        earned = reference_rewards(study, env, params, reference(env), chosen)
        print(f"c_beat = {beat_bonus:g}: the reference earns {earned.mean():.1f} per training "
              "task on average")
        tasks = tasks.replace(reference_reward=earned.astype(np.dtype(env.precision)))
    return GridProblem(
        study, env, PointEpisode(env, params), tasks,
        jax.tree.map(lambda a: a[np.array(points)], study.models),
        env.config.history * env.obs_size, len(env.action_slots), float(params.action_low),
        float(params.action_high),
        (functools.partial(stratified_sampler, study.task_set(task_set), study.n_points)
         if sampling == "stratified" else None), info, quiet_charge, beat_bonus,
        terms.get("beat_scale", DEFAULT_BEAT_SCALE))


def quiet_tasks(study: Study, env: LoadSheddingEnv, specs) -> np.ndarray:
    """(len(specs),) bool: each task of `specs` recovers in `env` with no shedding (one
    uncontrolled episode each)."""
    idle = (episode.idle_controller(len(env.action_slots)), None, None)
    return _per_task(study, env, idle, specs, "recovered").astype(bool)


def reference_rewards(study: Study, env: LoadSheddingEnv, params: EnvParams, controller,
                      specs) -> np.ndarray:
    """(len(specs),) the reward `controller` ((apply, params, carry)) earns on each task of
    `specs` in `env`, rewarded with `params` (one episode each)."""
    return _per_task(study, env, controller, specs, "reward", params)


def _per_task(study: Study, env: LoadSheddingEnv, controller, specs, key: str,
              params=None) -> np.ndarray:
    """`play_specs`'s result `key` of `controller` ((apply, params, carry)) on each task of
    `specs`, in their order (one call per operating point: their task counts may differ)."""
    apply, policy_params, carry = controller
    played = {}
    for point in sorted({s.operating_point for s in specs}):
        ordered, out = play_specs(study, env, apply, policy_params,
                                  [s for s in specs if s.operating_point == point], carry,
                                  params=params)
        played.update(zip(ordered, out[key]))
    return np.array([played[s] for s in specs])
