"""The PARS training settings of a study, worked out in one place: `train_config(study,
choices)` turns a study and what a user chose (`Choices`, one field per flag of
`experiments.train`; None or "auto": the paper's setting for the study's grid size) into the
`ars.train.TrainConfig`, and `problem(study, choices)` into the study's side
(`jaxgrid.problem.training_problem`). The training commands, the reproduction harness and
the training benchmarks all use them; `train_pars_study` runs one training.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import numpy as np

from ars.pars import ParsConfig
from ars.train import TrainConfig
from experiments.common.curves import pars_curve

TASKS_PER_ITERATION = 9  # m when not chosen and the task set has as many
LARGE_GRID = 100  # buses: larger grids get the paper's 300-bus settings

# The paper's Table I per system: the 39-bus column for studies up to LARGE_GRID buses (the
# defaults of ParsConfig and TrainConfig), else the 300-bus one (N: the directions its main
# policy trained with; b = N/2). The large grids'
# m tasks run one after another on CPUs (task_batch 1: 256 rollouts per batch, and a task's
# batch stops once all its episodes have failed; measured on 2 CPU devices 1.17× faster per
# iteration at θ = 0, 2.4× after the first update).
PAPER_PRESETS = {"small": {"hidden": TrainConfig.hidden, "decay": ParsConfig.decay,
                           "directions": ParsConfig.directions, "task_batch": None},
                 "large": {"hidden": (64, 64), "decay": 0.996, "directions": 128,
                           "task_batch": 1}}

# The study and iterations of each training command (`python -m experiments.NAME`).
COMMANDS = {"train": {"study": None, "iterations": TrainConfig.iterations},
            "train_39bus": {"study": "ieee39_fidvr", "iterations": 200},
            "train_300bus": {"study": "ieee300_fidvr", "iterations": 500}}


@dataclasses.dataclass(frozen=True)
class Choices:
    """What a user chose for a PARS training (`experiments.train`'s flags); None or "auto":
    the paper's setting for the study's grid size (`paper_preset`) or the study's own. The
    other defaults are those of `ars.pars.ParsConfig` and `ars.train.TrainConfig` (read from
    them, written once).

    Attributes:
      policy: "linear" | "fnn" | "lstm".  hidden: layer widths (linear: none).
      obs_clip: ± standard deviations of the normalised inputs, or None (no clip).
      relative_inputs: inputs as their change since the episode's start (not the paper's).
      self_mask: the policy masks its own requests with the study's action mask (not the
        paper's; `ars.train.TrainConfig.self_mask`).
      arming_level: p.u., with self_mask: the policy armed only once an action bus falls
        below it, or None (`ars.train.TrainConfig.arming_level`).
      obs_std_floor: the normaliser's smallest standard deviation, or None (none).
      task_returns: "mean" (the paper's), "zscores", "ranks" or "ranks+mean"
        (`ars.pars.ParsConfig.task_returns`).
      init_policy: a saved PARS policy to start from, or None (θ = 0, the paper's;
        `ars.train.TrainConfig.init_policy`).
      max_request: the most the policy asks per action and step, or None (the study's
        action range, the paper's; `ars.train.TrainConfig.max_request`).
      history: observations stacked (None: the study's for the policy kind).
      directions: N.  top: b (None: N/2).  step_size: α.  noise: ν.  decay: ε.
      tasks_per_iteration: m (None: TASKS_PER_ITERATION, or the whole set if smaller).
      task_batch: tasks per rollout batch, or "auto" (`task_batch`).
      compact_after: "auto" | "check" | "off" | a number of agent steps (`compact_after`).
      compact_chunks: K.  task_set: the study's set to train on (several joined by "+").
      task_sampling: "uniform" | "stratified" (None: the study's).
      shaping: ((EnvParams reward field, value), ...) in place of the study's in training
        only (`shaping`): evaluations, and the study saved with the run, keep the study's.  episode: s (None: the study's).  seed: the first.
      iterations, seeds, checkpoint_every, out, resume: as `ars.train.TrainConfig`.
    """

    policy: str = TrainConfig.policy
    hidden: tuple[int, ...] | None = None
    obs_clip: float | None = TrainConfig.obs_clip
    relative_inputs: bool = TrainConfig.relative_inputs
    self_mask: bool = TrainConfig.self_mask
    arming_level: float | None = TrainConfig.arming_level
    obs_std_floor: float | None = ParsConfig.obs_std_floor
    task_returns: str = ParsConfig.task_returns
    init_policy: str | None = TrainConfig.init_policy
    max_request: float | None = TrainConfig.max_request
    history: int | None = None
    directions: int | None = None
    top: int | None = None
    step_size: float = ParsConfig.step_size
    noise: float = ParsConfig.noise
    decay: float | None = None
    tasks_per_iteration: int | None = None
    task_batch: int | str = "auto"
    compact_after: str = "auto"
    compact_chunks: int = ParsConfig.compact_chunks
    task_set: str = "train"
    task_sampling: str | None = None
    shaping: tuple[tuple[str, float], ...] = ()
    episode: float | None = None
    seed: int = ParsConfig.seed
    iterations: int = TrainConfig.iterations
    seeds: int | None = TrainConfig.seeds
    checkpoint_every: int = TrainConfig.checkpoint_every
    out: str = TrainConfig.out
    resume: bool = TrainConfig.resume


def train_config(study, choices: Choices = Choices()) -> TrainConfig:
    """The `ars.train.TrainConfig` of `choices` on `study`: the paper's widths, N, ε and task
    batch for the grid's size where not chosen, b = N/2, m from the task set."""
    preset = paper_preset(study)
    directions = choices.directions or preset["directions"]
    pars = ParsConfig(directions=directions, top=choices.top or max(1, directions // 2),
                      step_size=choices.step_size, noise=choices.noise,
                      decay=choices.decay or preset["decay"],
                      tasks_per_iteration=tasks_per_iteration(study, choices),
                      task_batch=task_batch(choices.task_batch, preset["task_batch"]),
                      compact_after=compact_after(choices.compact_after, study,
                                                  choices.task_set, choices.episode),
                      compact_chunks=choices.compact_chunks,
                      obs_std_floor=choices.obs_std_floor,
                      task_returns=choices.task_returns, seed=choices.seed)
    hidden = choices.hidden if choices.hidden is not None else (
        () if choices.policy == "linear" else preset["hidden"])
    return TrainConfig(policy=choices.policy, hidden=tuple(hidden), obs_clip=choices.obs_clip,
                       relative_inputs=choices.relative_inputs, self_mask=choices.self_mask,
                       arming_level=choices.arming_level, init_policy=choices.init_policy,
                       max_request=choices.max_request,
                       pars=pars, iterations=choices.iterations, seeds=choices.seeds,
                       checkpoint_every=choices.checkpoint_every, out=choices.out,
                       resume=choices.resume)


def problem(study, choices: Choices = Choices()):
    """The study's side of the training: `jaxgrid.problem.training_problem` of the chosen
    policy kind, history, episode, task set and sampling; UVLS the reference of c_beat."""
    from baselines.uvls import uvls_policy
    from jaxgrid.problem import training_problem

    return training_problem(study, choices.policy, choices.history, choices.episode,
                            choices.task_set, choices.task_sampling, dict(choices.shaping),
                            reference=uvls_policy)


SHAPING_FIELDS = ("c_voltage", "c_shed", "c_invalid", "c_normal", "c_prefault",
                  "unstable_penalty", "c_quiet", "c_beat", "beat_scale")


def shaping(items) -> tuple[tuple[str, float], ...]:
    """`Choices.shaping` of --shaping FIELD=VALUE items (reward weights of
    `jaxgrid.env.EnvParams`, in their ranges, and c_quiet, c_beat (against UVLS) and
    beat_scale, `jaxgrid.problem.training_problem`'s); ValueError naming the flag and the
    item (beat_scale without c_beat is one)."""
    from jaxgrid.env import check_params
    from jaxgrid.problem import SHAPING_TERMS

    pairs = []
    for item in items:
        field, _, value = item.partition("=")
        if field not in SHAPING_FIELDS:
            raise ValueError(f"--shaping {item!r}: FIELD=VALUE with FIELD one of "
                             f"{', '.join(SHAPING_FIELDS)}")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"--shaping {item!r}: VALUE must be a number") from None
        if field in SHAPING_TERMS:
            SHAPING_TERMS[field].check(f"--shaping {field}", number)
        else:
            check_params({field: number}, key=lambda f: f"--shaping {f}")
        pairs.append((field, number))
    fields = [f for f, _ in pairs]
    if len(set(fields)) < len(fields):
        raise ValueError(f"--shaping {' '.join(items)}: a field given twice")
    if "beat_scale" in fields and "c_beat" not in fields:
        raise ValueError(f"--shaping {' '.join(items)}: beat_scale scales c_beat's bonus; give "
                         "c_beat=B with it")
    return tuple(pairs)


def widths(hidden: str) -> tuple[int, ...]:
    """Layer widths of a --hidden value, e.g. "32,32" -> (32, 32); "" -> ()."""
    return tuple(int(h) for h in str(hidden).split(",") if h.strip())


def paper_preset(study) -> dict:
    """The `PAPER_PRESETS` entry for `study`'s grid size."""
    n_buses = len(study.points[0].case.buses.number)
    return PAPER_PRESETS["large" if n_buses > LARGE_GRID else "small"]


def task_batch(setting: int | str, preset: int | None) -> int | None:
    """`ParsConfig.task_batch` of a --task-batch setting: a number as given; 'auto' is all m
    tasks in one batch (None) on a GPU, which has batch width to spare, and `preset`
    elsewhere (one task per batch on the large grids, so a task's batch stops once its
    episodes have failed). One H100, the look-alike 300-bus: 0.34 s per iteration all in
    one batch, 0.84 s one task per batch (benchmarks/h100/ab.json)."""
    if setting != "auto":
        return setting
    return None if jax.default_backend() == "gpu" else preset


def compact_after(setting: str, study, task_set: str = "train",
                  episode: float | None = None) -> int | None:
    """`ParsConfig.compact_after` of a --compact-after setting: 'check' is the task set's
    last recovery check step (`jaxgrid.problem.recovery_check_step`), 'auto' is 'check' on
    grids of the paper's large preset (`paper_preset`: more than LARGE_GRID buses) and 'off'
    on smaller ones; None for 'off' or a step not inside the episode (`episode` s, default
    the study's)."""
    from jaxgrid.problem import recovery_check_step

    if setting == "auto":
        setting = "check" if paper_preset(study) is PAPER_PRESETS["large"] else "off"
    if setting == "off":
        return None
    if setting == "check":
        step = recovery_check_step(study, task_set)
    elif setting.isdigit() and int(setting) >= 1:
        step = int(setting)
    else:
        raise ValueError(f"--compact-after {setting!r}: allowed 'auto', 'check', 'off' or a "
                         "number of agent steps >= 1")
    n_steps = study.env(**{"episode": episode} if episode else {}).config.n_steps
    return step if step < n_steps else None


def tasks_per_iteration(study, choices: Choices) -> int:
    """m: as chosen, by default TASKS_PER_ITERATION or the whole task set if it is smaller;
    ValueError naming the flag when uniform sampling asks for more than the set has."""
    available = len(study.tasks(choices.task_set))
    m = choices.tasks_per_iteration or min(TASKS_PER_ITERATION, available)
    if choices.task_sampling == "uniform" and m > available:
        raise ValueError(f"--tasks-per-iteration {m}: the task set {choices.task_set!r} of "
                         f"study {study.name!r} has {available} tasks; pass "
                         f"--tasks-per-iteration {available} or fewer, or another --task-set")
    return m


def train_pars_study(study, choices: Choices = Choices()):
    """`ars.train.train` of `train_config(study, choices)` on `problem(study, choices)`, then,
    on process 0, learning_curve.png and a summary line; returns `train`'s TrainResult."""
    from ars.train import train

    config = train_config(study, choices)
    result = train(config, problem(study, choices))
    if jax.process_index() == 0:
        out, log = Path(config.out), result.metrics
        pars_curve(log, out / "learning_curve.png", study.name)
        print(f"{out}: {log[-1]['iteration']} iterations, last mean reward "
              f"{np.mean(log[-1]['reward_mean']):.1f}, policy in {out / 'policy'}")
    return result
