"""PPO training of a load-shedding policy on a study: the PPO baseline of the PNNL PARS study
(`baselines.ppo`: rejax's PPO with RLlib's value clip and KL term, Table II defaults).

    python -m experiments.train_ppo --study ieee39_fidvr|studies/x.toml --env-steps N \
        --envs K --out DIR [--resume]

Every hyper-parameter of `baselines.ppo.PPOConfig` has a flag. Each iteration collects
--envs × --rollout-steps transitions (environments reset to a training task drawn uniformly
over the study's operating points and faults) and runs --epochs passes over them. The
iterations run in jitted chunks of --eval-every; after each chunk the host writes:
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
  study.toml      the resolved study (`--resume` without --study reads it back)
  config.json     the resolved hyper-parameters and run information
and at the end:
  policy/         the trained policy (experiments.evaluate --controller ppo:DIR/policy)
  learning_curve.png
`--resume` continues from the last checkpoint; `--env-steps` is the run's total (rounded up
to whole iterations). A resumed run must use the hyper-parameters it was started with.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from experiments.studyargs import add_study_arguments, study_from_args
from ars.train import device_label

# flag -> PPOConfig field (one-to-one; the defaults are PPOConfig's)
FLAGS = {"envs": "envs", "rollout_steps": "rollout_steps", "epochs": "epochs",
         "minibatches": "minibatches", "lr": "learning_rate", "clip": "clip",
         "entropy": "entropy", "kl_coef": "kl_coef", "vf_clip": "vf_clip", "vf_coef": "vf_coef",
         "hidden": "hidden", "activation": "activation", "gamma": "gamma",
         "gae_lambda": "gae_lambda", "normalize_actions": "normalize_actions", "seed": "seed"}


def parser() -> argparse.ArgumentParser:
    from baselines.ppo import PPOConfig

    d = PPOConfig()
    p = argparse.ArgumentParser(prog="python -m experiments.train_ppo",
                                description="PPO training (the PARS study's baseline)")
    add_study_arguments(p, None)
    p.add_argument("--env-steps", type=int, default=1_000_000,
                   help="total environment (agent) steps of the run")
    p.add_argument("--envs", type=int, default=d.envs, help="parallel environments")
    p.add_argument("--rollout-steps", type=int, default=d.rollout_steps,
                   help="agent steps per environment per iteration")
    p.add_argument("--epochs", type=int, default=d.epochs, help="passes per iteration")
    p.add_argument("--minibatches", type=int, default=d.minibatches, help="per epoch")
    p.add_argument("--lr", type=float, default=d.learning_rate, help="Adam learning rate")
    p.add_argument("--clip", type=float, default=d.clip, help="surrogate clip ε")
    p.add_argument("--entropy", type=float, default=d.entropy, help="entropy coefficient")
    p.add_argument("--kl-coef", type=float, default=d.kl_coef, help="KL coefficient (fixed)")
    p.add_argument("--vf-clip", type=float, default=d.vf_clip,
                   help="value clip, reward units")
    p.add_argument("--vf-coef", type=float, default=d.vf_coef, help="value loss coefficient")
    p.add_argument("--hidden", default=",".join(map(str, d.hidden)),
                   help="layer widths, e.g. 64,64")
    p.add_argument("--activation", default=d.activation, help="flax.linen activation")
    p.add_argument("--gamma", type=float, default=d.gamma, help="discount γ")
    p.add_argument("--gae-lambda", type=float, default=d.gae_lambda, help="GAE λ")
    p.add_argument("--no-normalize-actions", dest="normalize_actions", action="store_false",
                   help="the policy acts in the env's action range, not in [-1, 1]")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--eval-every", type=int, default=10,
                   help="iterations per chunk (one metrics line, evaluation, checkpoint)")
    p.add_argument("--task-set", default="train", help="the study's task set to train on")
    p.add_argument("--history", type=int, help="observations stacked (default: the study's)")
    p.add_argument("--episode", type=float, help="episode length, s (default: the study's)")
    p.add_argument("--out", default="runs/ppo", help="output folder")
    p.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return _train(args)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


def config_from_args(args):
    """The PPOConfig of the flags."""
    from baselines.ppo import PPOConfig

    values = {field: getattr(args, flag) for flag, field in FLAGS.items()}
    values["hidden"] = tuple(int(h) for h in str(args.hidden).split(",") if h.strip())
    return PPOConfig(**values)


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


def _train(args) -> int:
    from tqdm import tqdm

    from ars import checkpoint
    from baselines.ppo import gymnax_env, make_ppo, ppo_policy, save_policy
    from jaxgrid.rollouts import layout, rollout_specs
    from jaxgrid.study import write_study

    config = config_from_args(args)
    if args.env_steps < 1 or args.eval_every < 1:
        raise ValueError("--env-steps and --eval-every must be >= 1")
    total = math.ceil(args.env_steps / config.batch)  # iterations
    out = Path(args.out)
    saved_study = out / "study.toml"
    study = study_from_args(args, str(saved_study) if args.resume and saved_study.is_file()
                            else None)
    out.mkdir(parents=True, exist_ok=True)
    mgr = checkpoint.manager(out / "checkpoints", 1)
    if not args.resume and mgr.latest_step() is not None:
        raise ValueError(f"{out} already holds a run (checkpoint at iteration "
                         f"{mgr.latest_step()}): pass --resume to continue it, or another --out")
    if args.resume and (mgr.latest_step() or 0) > total:
        raise ValueError(f"--resume: the checkpoint in {out} is at iteration "
                         f"{mgr.latest_step()}, past --env-steps {args.env_steps} "
                         f"({total} iterations of {config.batch})")
    overrides = {k: v for k, v in (("history", args.history), ("episode", args.episode))
                 if v is not None}
    env = study.env(**overrides)
    adapter, params = gymnax_env(study, args.task_set, config.normalize_actions, env)
    algo = make_ppo(adapter, params, config)
    run_info = {"study": study.name, "points": [p.label for p in study.points],
                "task_set": args.task_set, "layout": layout(env.config),
                "history": env.config.history, "episode": env.config.episode,
                "config": dataclasses.asdict(config)}
    state, log = host_state(algo.init_state(jax.random.PRNGKey(config.seed))), []
    if args.resume:
        restored = checkpoint.restore_latest(mgr, packed(state))
        if restored is None:
            raise ValueError(f"--resume: no checkpoint in {out / 'checkpoints'}")
        state, meta = unpacked(state, restored[0]), restored[1]
        now = json.loads(json.dumps(run_info["config"]))  # tuples as the JSON lists
        changed = {k: (v, now[k]) for k, v in meta["config"].items() if now[k] != v}
        if changed or meta["task_set"] != args.task_set:
            raise ValueError(f"--resume: the run in {out} was started with other settings "
                             f"(saved, now): {changed or {'task_set': meta['task_set']}}")
        log = meta["metrics"]
    (out / "config.json").write_text(json.dumps({**run_info, "env_steps": args.env_steps,
                                                 "iterations": total}, indent=1))
    write_study(study, saved_study)
    metrics_path = out / "metrics.jsonl"
    metrics_path.write_text("".join(json.dumps(m) + "\n" for m in log))

    chunk = make_chunk()
    specs = study.tasks(args.task_set)
    done = log[-1]["iteration"] if log else 0
    wall_total = log[-1]["wall_total_s"] if log else 0.0
    device = device_label(1)
    bar = tqdm(total=total, initial=done, unit="it")
    while done < total:
        n = min(args.eval_every, total - done)
        start = time.perf_counter()
        state = jax.block_until_ready(chunk(algo, state, jnp.int32(n)))
        wall = time.perf_counter() - start
        done, wall_total = done + n, wall_total + wall
        apply, policy_params, carry = ppo_policy(state, algo)
        _, evaluation = rollout_specs(study, env, apply, policy_params, specs, carry)
        ended = int(np.sum(state.env_state.returns_count))
        row = {"iteration": done, "env_steps": done * config.batch, "wall_s": round(wall, 3),
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
        checkpoint.save(mgr, packed(state), {"metrics": log, "iteration": done, **run_info},
                        force=True, step=done)
    bar.close()
    save_policy(out / "policy", algo, state, run_info)
    _learning_curve(log, out / "learning_curve.png", study.name, len(specs))
    print(f"{out}: {done} iterations ({done * config.batch} env steps), deterministic policy "
          f"mean reward {log[-1]['reward_mean']:.1f}, policy in {out / 'policy'}")
    return 0


def _learning_curve(log: list[dict], path: Path, study: str, n_tasks: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from experiments.train import save_curve

    steps = np.array([m["env_steps"] for m in log])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(steps, [m["reward_mean"] for m in log], "o-", ms=3,
            label=f"deterministic policy, mean over the {n_tasks} training tasks")
    train = [(s, m["reward_train"]) for s, m in zip(steps, log) if m["reward_train"] is not None]
    if train:
        ax.plot(*zip(*train), alpha=0.6, label="episodes ended during collection")
    save_curve(fig, ax, path, "environment steps", f"PPO on {study}")


if __name__ == "__main__":
    sys.exit(main())
