"""A PARS training run: `init_state`, then the jit-compiled iteration (`ars.iteration`: the
PARS strategy `ars.pars.Pars` composed with the problem's `evaluate`) in a Python loop that
logs metrics, checkpoints, resumes and saves policies (the shape of google/brax's
`agents/ars/train.py`, with the loop on the host so that it can checkpoint).

Any environment works: `train` takes a `Problem`, what the environment side supplies (for
a grid study, `jaxgrid.problem.training_problem`). Output folder `TrainConfig.out`:
  metrics.jsonl   one line per iteration: iteration, reward_mean, reward_max, wall_s, rollouts
                  (cumulative), env_steps (cumulative agent steps, where the episodes report
                  "steps"), device ("COUNT × KIND")
  checkpoints/    orbax checkpoints every checkpoint_every iterations and at the end
  policy/         the trained policy (`ars.checkpoint.save_policy`)
  policies/NNNNN/ the policy after iteration NNNNN, at every checkpoint
and what `Problem.save` writes; each policy.json records the "iteration" it is from and the
run's "iterations". With `seeds`, the metrics hold per-seed lists of reward_mean,
reward_max and env_steps (rollouts counts one seed's) and each policy folder holds seed0/ ...
Every process of a multi-process run computes the same replicated state; process 0 writes
the files (orbax coordinates the checkpoints itself).
"""
from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import jax
import numpy as np

from ars import checkpoint
from ars.iteration import TrainState, default_mesh, make_iteration
from ars.normalizer import initial_carry, normalized_policy
from ars.pars import Pars, ParsConfig, init_state
from ars.policies import Policy, PolicySpec


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """A training run. Each field is one flag of `experiments.train` (errors name the flags).

    Attributes:
      policy: the policy kind, "linear" | "fnn" | "lstm".  hidden: layer widths.
      pars: the iteration's hyper-parameters (its seed is the first seed).
      iterations: the run's total (when resuming: continue up to it).
      seeds: K independent trainings (seeds pars.seed ... pars.seed + K − 1) vmapped into
        one program, or None for one training without a seed axis.
      checkpoint_every: iterations between checkpoints (and saved policies).
      out: the output folder.  resume: continue from the last checkpoint in `out`.
      obs_clip: the policy's inputs clipped to ±obs_clip standard deviations, or None
        (`ars.policies.PolicySpec.obs_clip`).
      relative_inputs: the policy reads its inputs as their change since the episode's
        start (`ars.policies.PolicySpec.relative_inputs`; the paper's: False).
      self_mask: the policy masks its own requests with the problem's action mask, in
        training and wherever it runs (`Problem.evaluator`; the paper's: False).
      arming_level: with self_mask, the policy asks nothing until an action bus has been
        observed below this level (p.u.) after clearing, then is armed for the episode
        (`Problem.evaluator`), or None (not the paper's: it has no mask).
      init_policy: a saved PARS policy folder to start from instead of θ = 0 and empty
        statistics (`ars.checkpoint.warm_start`: fine-tuning), or None (the paper's). A
        resumed run continues from its checkpoint.
      max_request: the most the policy asks to shed per action and step, in the action's
        units (a fraction of a bus's initial load): its output range becomes
        [−max_request, action_high], inside the problem's range, which the environment still
        applies to every controller; None: the problem's range (the paper's: 0.2).
    """

    policy: str = "lstm"
    hidden: tuple[int, ...] = (32, 32)
    pars: ParsConfig = ParsConfig()
    iterations: int = 200
    seeds: int | None = None
    checkpoint_every: int = 10
    out: str = "runs/study"
    resume: bool = False
    obs_clip: float | None = None
    relative_inputs: bool = False
    self_mask: bool = False
    arming_level: float | None = None
    init_policy: str | None = None
    max_request: float | None = None

    def __post_init__(self):
        if self.iterations < 1 or self.checkpoint_every < 1 or (self.seeds or 1) < 1:
            raise ValueError("--iterations, --checkpoint-every and --seeds must be >= 1")
        if self.obs_clip is not None and not self.obs_clip > 0:
            raise ValueError(f"--obs-clip {self.obs_clip}: allowed > 0 (or leave it out)")
        if self.arming_level is not None:
            if not self.self_mask:
                raise ValueError("--arming-level: needs --self-mask (it arms the policy's own "
                                 "mask)")


class Problem(Protocol):
    """What `train` needs from the environment side.

    Attributes:
      tasks: pytree of the training tasks, leading axis n_tasks.
      data: pytree the episodes read (passed to the compiled iteration, not closed over).
      obs_size: length of the policy's input.  action_size: length of its output.
      action_low, action_high: the action range.
      sampler: sampler(m) -> sample(key) -> (m,) task indices, or None (m distinct tasks
        drawn uniformly).
      network: network(fun) -> fun, how a per-example policy network `fun(θ, obs, carry)`
        runs inside the problem's episodes (e.g. `jaxgrid.batching.batch_major`; the
        identity where nothing is needed).
      info: JSON-able run information, saved with every checkpoint and policy.
    """

    tasks: Any
    data: Any
    obs_size: int
    action_size: int
    action_low: float
    action_high: float
    sampler: Callable | None
    network: Callable
    info: dict

    def evaluator(self, apply: Callable, carry, mesh, *, self_mask: bool,
                  arming_level: float | None, task_batch: int | None,
                  compact_after: int | None, compact_chunks: int) -> Callable:
        """evaluate(thetas (P, size), shared, tasks (m, ...), data) -> dict of (P, m, ...)
        episode results ("reward", "policy_carry", optionally "steps"): each θ's episodes
        run the controller `apply(params, obs, carry, inputs)` with params (θ, *shared) and
        `carry` at the start, the P vectors split over `mesh` and batched as the problem
        sees fit (`ars.iteration.make_iteration`; `ParsConfig` says what the batching fields
        ask for); self_mask: the controller first drops the requests the problem's action
        mask would (`TrainConfig.self_mask`), and with arming_level every one until an
        action bus falls below that level (`TrainConfig.arming_level`)."""

    def save(self, folder: Path) -> None:
        """Write what rebuilds the environment into the run folder (process 0, at start)."""


class Trainer(NamedTuple):
    """The compiled iteration of a problem (`make_trainer`): iteration(state, tasks, data)
    -> (state, metrics), the policy and its spec."""

    iteration: Callable
    policy: Policy
    spec: PolicySpec


def policy_range(problem: Problem, max_request: float | None) -> tuple[float, float]:
    """(low, high) of the policy's outputs: the problem's action range, or with
    `max_request` [−max_request, high] (`TrainConfig.max_request`); ValueError outside it."""
    low, high = float(problem.action_low), float(problem.action_high)
    if max_request is None:
        return low, high
    if not -high < max_request <= -low:
        raise ValueError(f"--max-request {max_request}: allowed in ({-high + 0.0:g}, "
                         f"{-low:g}], the problem's action range")
    return -float(max_request), high


def make_trainer(problem: Problem, config: TrainConfig, mesh=None) -> Trainer:
    """The policy of `config` on the problem's sizes and its PARS iteration, the problem's
    episodes sharded over `mesh` (default: all devices)."""
    spec = PolicySpec(config.policy, problem.obs_size, problem.action_size, config.hidden,
                      *policy_range(problem, config.max_request), config.obs_clip,
                      config.relative_inputs)
    policy, pars, mesh = Policy(spec), config.pars, mesh or default_mesh()
    evaluate = problem.evaluator(normalized_policy(policy, problem.network),
                                 initial_carry(policy), mesh, self_mask=config.self_mask,
                                 arming_level=config.arming_level,
                                 task_batch=pars.task_batch,
                                 compact_after=pars.compact_after,
                                 compact_chunks=pars.compact_chunks)
    sample = (problem.sampler(pars.tasks_per_iteration)
              if problem.sampler is not None else None)
    iteration = make_iteration(Pars(pars), evaluate, pars.tasks_per_iteration, sample, mesh,
                               config.seeds, pars.task_returns)
    return Trainer(iteration, policy, spec)


class TrainResult(NamedTuple):
    """What `train` returns: the final TrainState and the metrics lines of the whole run."""

    state: TrainState
    metrics: list


def device_label(count: int) -> str:
    """'COUNT × KIND' for `count` devices of this backend, e.g. '2 × cpu' (metrics lines)."""
    return f"{count} × {jax.devices()[0].device_kind}"


def train(config: TrainConfig, problem: Problem, mesh=None) -> TrainResult:
    """Train (or resume) the run of `config` on `problem` (module docstring); ValueError
    if `out` holds a run and resume is off, or resume finds no fitting checkpoint."""
    from tqdm import tqdm

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    mgr = checkpoint.manager(out / "checkpoints", config.checkpoint_every)
    if not config.resume and mgr.latest_step() is not None:
        raise ValueError(f"{out} already holds a run (checkpoint at iteration "
                         f"{mgr.latest_step()}): pass --resume to continue it, or another --out")
    if config.resume and (mgr.latest_step() or 0) > config.iterations:
        raise ValueError(f"--resume: the checkpoint in {out} is at iteration "
                         f"{mgr.latest_step()}, past --iterations {config.iterations}")
    trainer = make_trainer(problem, config, mesh)
    run_info = {**problem.info, "config": dataclasses.asdict(config.pars),
                "seeds": config.seeds, "iterations": config.iterations,
                **({"self_mask": True} if config.self_mask else {}),  # policy.json as before
                **({"arming_level": config.arming_level} if config.arming_level is not None
                   else {}),
                **({"init_policy": config.init_policy} if config.init_policy else {}),
                **({"max_request": config.max_request} if config.max_request is not None
                   else {})}
    state, log = init_state(trainer.policy, config.pars, config.seeds), []
    if config.init_policy and not config.resume:
        state = checkpoint.warm_start(state, config.init_policy, trainer.spec)
    if config.resume:
        restored = checkpoint.restore_latest(mgr, state)
        if restored is None:
            raise ValueError(f"--resume: no checkpoint in {out / 'checkpoints'}")
        state, meta = restored
        log = meta["metrics"]
        for flag, value, unsaved in (("seeds", config.seeds, None),
                                     ("obs_clip", config.obs_clip, None),
                                     ("relative_inputs", config.relative_inputs, False),
                                     ("self_mask", config.self_mask, False),
                                     ("arming_level", config.arming_level, None),
                                     ("max_request", config.max_request, None)):
            if meta.get(flag, unsaved) != value:  # unsaved: a run from before the flag
                raise ValueError(f"--resume: the run in {out} has --{flag.replace('_', '-')} "
                                 f"{meta.get(flag)}, not {value}")
    primary = jax.process_index() == 0
    metrics_path = out / "metrics.jsonl"
    if primary:
        problem.save(out)
        metrics_path.write_text("".join(json.dumps(m) + "\n" for m in log))
    done = int(np.max(state.iteration))
    rollouts = log[-1]["rollouts"] if log else 0
    env_steps = np.array(log[-1].get("env_steps", 0) if log else 0, np.int64)  # per seed, wide
    device = device_label(jax.device_count())
    bar = tqdm(total=config.iterations, initial=done, unit="it", disable=not primary)
    try:  # closing the bar ends its line, so an error starts on a new one
        while done < config.iterations:
            start = time.perf_counter()
            state, metrics = trainer.iteration(state, problem.tasks, problem.data)
            metrics = jax.device_get(metrics)
            wall = time.perf_counter() - start
            done, rollouts = done + 1, rollouts + int(np.ravel(metrics["rollouts"])[0])
            row = {"iteration": done, "reward_mean": np.asarray(metrics["reward_mean"]).tolist(),
                   "reward_max": np.asarray(metrics["reward_max"]).tolist(),
                   "wall_s": round(wall, 3), "rollouts": rollouts}
            if "env_steps" in metrics:
                env_steps = env_steps + np.asarray(metrics["env_steps"], np.int64)
                row["env_steps"] = env_steps.tolist()
            row["device"] = device
            log.append(row)
            if primary:
                with open(metrics_path, "a") as metrics_file:
                    metrics_file.write(json.dumps(row) + "\n")
            bar.set_postfix(mean=f"{np.mean(row['reward_mean']):.1f}",
                            best=f"{np.max(row['reward_max']):.1f}", s_per_it=f"{wall:.2f}")
            bar.update(1)
            last = done == config.iterations
            checkpoint.save(mgr, state, {"metrics": log, **run_info, "obs_clip": config.obs_clip,
                                         "relative_inputs": config.relative_inputs},
                            force=last, step=done)
            if primary and (done % config.checkpoint_every == 0 or last):
                save_policies(out / "policies" / f"{done:05d}", trainer.spec, state,
                              {**run_info, "iteration": done}, config.seeds)
    finally:
        bar.close()
    if primary:
        save_policies(out / "policy", trainer.spec, state, {**run_info, "iteration": done},
                      config.seeds)
    return TrainResult(state, log)


def save_policies(folder: Path, spec: PolicySpec, state: TrainState, run_info: dict,
                  seeds: int | None) -> None:
    """The policy in `folder`, or with seeds each seed's in folder/seedI."""
    if seeds is None:
        checkpoint.save_policy(folder, spec, state, run_info)
        return
    for i in range(seeds):
        checkpoint.save_policy(folder / f"seed{i}", spec, jax.tree.map(lambda a: a[i], state),
                               {**run_info, "seed": run_info["config"]["seed"] + i})
