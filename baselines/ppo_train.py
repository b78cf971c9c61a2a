"""A PPO training run of the PARS study's baseline (`baselines.ppo`) on a study: the rejax
iterations in jitted chunks, with evaluation, metrics, checkpoints and resume on the host.

    result = train_ppo(PPOTrainConfig(env_steps=2_000_000, out="runs/ppo39"), study)

Each iteration collects envs × rollout_steps transitions (environments reset to a training
task drawn uniformly over the study's operating points and faults) and runs `epochs` passes
over them. The iterations run in jitted chunks of `eval_every`; after each chunk the host
writes, in the output folder `PPOTrainConfig.out`:
  metrics.jsonl   one line per chunk: iteration, env_steps, wall_s (training time of the
                  chunk, s, as PARS's per-iteration wall_s; the first includes compilation),
                  device (one device: "1 × KIND"),
                  wall_total_s (cumulative), reward_mean (mean return of the deterministic
                  policy over every task of the training set, all operating points: the
                  figure PARS's reward_mean estimates, PARS averaging its perturbed rollouts
                  on m drawn tasks), n_recovered (of those tasks), reward_train (mean return
                  of the episodes that ended during the chunk's collection, stochastic
                  policy; null if none ended) and episodes_train
  checkpoints/    orbax checkpoints of the whole rejax train state, every chunk (last 3 kept)
at the start:
  study.toml      the resolved study
  config.json     the resolved hyper-parameters and run information
and at the end:
  policy/         the trained policy (`baselines.ppo.load_policy`)
`resume` continues from the last checkpoint; `env_steps` is the run's total (rounded up to
whole iterations). A resumed run must use the hyper-parameters it was started with.
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ars import checkpoint
from ars.train import device_label
from baselines.ppo import PPOConfig, make_ppo, ppo_policy, save_policy
from jaxgrid.gym import gymnax_env
from jaxgrid.problem import play_specs, run_info
from jaxgrid.study import Study, write_study


@dataclasses.dataclass(frozen=True)
class PPOTrainConfig:
    """A PPO training run. Each field is one flag of `experiments.train_ppo` (errors name the
    flags; `ppo`'s fields are one flag each too).

    Attributes:
      ppo: the hyper-parameters.  env_steps: the run's total environment (agent) steps,
        rounded up to whole iterations (when resuming: continue up to it).
      eval_every: iterations per chunk (one metrics line, evaluation, checkpoint).
      task_set: the study's task set to train on.
      history: observations stacked, None for the study's.  episode: episode length, s,
        None for the study's.
      out: the output folder.  resume: continue from the last checkpoint in `out`.
    """

    ppo: PPOConfig = PPOConfig()
    env_steps: int = 1_000_000
    eval_every: int = 10
    task_set: str = "train"
    history: int | None = None
    episode: float | None = None
    out: str = "runs/ppo"
    resume: bool = False

    def __post_init__(self):
        if self.env_steps < 1 or self.eval_every < 1:
            raise ValueError("--env-steps and --eval-every must be >= 1")

    @property
    def iterations(self) -> int:
        """The run's total iterations: env_steps rounded up to whole iterations."""
        return math.ceil(self.env_steps / self.ppo.batch)


class PPOTrainResult(NamedTuple):
    """What `train_ppo` returns: the final rejax train state (host arrays) and the metrics
    lines of the whole run."""

    state: Any
    metrics: list


def make_chunk():
    """chunk(algo, state, n) -> state: n (traced) PPO iterations in one compiled call, the
    collection's return counters zeroed first."""

    def chunk(algo, state, n):
        env_state = state.env_state
        env_state = env_state.replace(returns_sum=jnp.zeros_like(env_state.returns_sum),
                                      returns_count=jnp.zeros_like(env_state.returns_count))
        state = state.replace(env_state=env_state)
        return jax.lax.fori_loop(0, n, lambda _, s: algo.train_iteration(s), state)

    return jax.jit(chunk)


def host_state(state):
    """The train state as host NumPy arrays of their canonical dtypes (no weak types), the
    form a restored checkpoint has, so a resumed run compiles and computes as a straight one."""
    return jax.device_get(jax.tree.map(jnp.asarray, state))


def packed(state) -> list:
    """The non-empty array leaves of `state`, in tree order: what a checkpoint holds (orbax
    cannot save zero-size arrays, and the env state has some, e.g. an empty task field)."""
    return [leaf for leaf in jax.tree.leaves(state) if np.size(leaf)]


def unpacked(template, leaves: list):
    """`template` with its non-empty leaves replaced by `leaves` (as `packed` lists them)."""
    it = iter(leaves)
    return jax.tree.map(lambda leaf: next(it) if np.size(leaf) else leaf, template)


def train_ppo(config: PPOTrainConfig, study: Study) -> PPOTrainResult:
    """Train (or resume) the run of `config` on `study` (module docstring); ValueError if
    `out` holds a run and resume is off, or resume finds no fitting checkpoint."""
    from tqdm import tqdm

    ppo, total, out = config.ppo, config.iterations, Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    mgr = checkpoint.manager(out / "checkpoints", 1)
    if not config.resume and mgr.latest_step() is not None:
        raise ValueError(f"{out} already holds a run (checkpoint at iteration "
                         f"{mgr.latest_step()}): pass --resume to continue it, or another --out")
    if config.resume and (mgr.latest_step() or 0) > total:
        raise ValueError(f"--resume: the checkpoint in {out} is at iteration "
                         f"{mgr.latest_step()}, past --env-steps {config.env_steps} "
                         f"({total} iterations of {ppo.batch})")
    overrides = {k: v for k, v in (("history", config.history), ("episode", config.episode))
                 if v is not None}
    env = study.env(**overrides)
    adapter, params = gymnax_env(study, config.task_set, ppo.normalize_actions, env)
    algo = make_ppo(adapter, params, ppo)
    info = {**run_info(study, env.config, config.task_set), "config": dataclasses.asdict(ppo)}
    # compiled: run eagerly, each operation of the networks' and the env's start compiles alone
    state, log = host_state(jax.jit(algo.init_state)(jax.random.PRNGKey(ppo.seed))), []
    if config.resume:
        restored = checkpoint.restore_latest(mgr, packed(state))
        if restored is None:
            raise ValueError(f"--resume: no checkpoint in {out / 'checkpoints'}")
        state, meta = unpacked(state, restored[0]), restored[1]
        now = json.loads(json.dumps(info["config"]))  # tuples as the JSON lists
        changed = {k: (v, now[k]) for k, v in meta["config"].items() if now[k] != v}
        if changed or meta["task_set"] != config.task_set:
            raise ValueError(f"--resume: the run in {out} was started with other settings "
                             f"(saved, now): {changed or {'task_set': meta['task_set']}}")
        log = meta["metrics"]
    (out / "config.json").write_text(json.dumps({**info, "env_steps": config.env_steps,
                                                 "iterations": total}, indent=1))
    write_study(study, out / "study.toml")
    metrics_path = out / "metrics.jsonl"
    metrics_path.write_text("".join(json.dumps(m) + "\n" for m in log))

    chunk = make_chunk()
    specs = study.tasks(config.task_set)
    done = log[-1]["iteration"] if log else 0
    wall_total = log[-1]["wall_total_s"] if log else 0.0
    device = device_label(1)
    bar = tqdm(total=total, initial=done, unit="it")
    while done < total:
        n = min(config.eval_every, total - done)
        start = time.perf_counter()
        state = jax.block_until_ready(chunk(algo, state, jnp.int32(n)))
        wall = time.perf_counter() - start
        done, wall_total = done + n, wall_total + wall
        apply, policy_params, carry = ppo_policy(state, algo)
        _, evaluation = play_specs(study, env, apply, policy_params, specs, carry)
        ended = int(np.sum(state.env_state.returns_count))
        row = {"iteration": done, "env_steps": done * ppo.batch, "wall_s": round(wall, 3),
               "device": device,
               "wall_total_s": round(wall_total, 3),
               "reward_mean": float(np.mean(evaluation["reward"])),
               "n_recovered": int(np.sum(evaluation["recovered"])),
               "reward_train": (float(np.sum(state.env_state.returns_sum)) / ended
                                if ended else None),
               "episodes_train": ended}
        log.append(row)
        with open(metrics_path, "a") as metrics_file:
            metrics_file.write(json.dumps(row) + "\n")
        bar.set_postfix(eval=f"{row['reward_mean']:.1f}", s_per_chunk=f"{wall:.2f}")
        bar.update(n)
        state = host_state(state)
        checkpoint.save(mgr, packed(state), {"metrics": log, "iteration": done, **info},
                        force=True, step=done)
    bar.close()
    save_policy(out / "policy", algo, state, info)
    return PPOTrainResult(state, log)
