"""The PPO training command's flags (one per field of `baselines.ppo_train.PPOTrainConfig`
or of its `baselines.ppo.PPOConfig`, `FLAGS`), the configuration they give, and the training
of a study with its learning curve: `experiments.train_ppo` and the reproduction harness
(`experiments.reproduce`) share them."""
from __future__ import annotations

import argparse
from pathlib import Path

from experiments.common.curves import ppo_curve
from experiments.common.studyargs import add_study_arguments
from experiments.common.training import widths

# flag -> PPOConfig field (one-to-one; the defaults are PPOConfig's)
FLAGS = {"envs": "envs", "rollout_steps": "rollout_steps", "epochs": "epochs",
         "minibatches": "minibatches", "lr": "learning_rate", "clip": "clip",
         "entropy": "entropy", "kl_coef": "kl_coef", "vf_clip": "vf_clip", "vf_coef": "vf_coef",
         "hidden": "hidden", "activation": "activation", "gamma": "gamma",
         "gae_lambda": "gae_lambda", "normalize_actions": "normalize_actions", "seed": "seed"}


def parser() -> argparse.ArgumentParser:
    from baselines.ppo_train import PPOTrainConfig

    run = PPOTrainConfig()
    d = run.ppo
    p = argparse.ArgumentParser(prog="python -m experiments.train_ppo",
                                description="PPO training (the PARS study's baseline)")
    add_study_arguments(p, None)
    p.add_argument("--env-steps", type=int, default=run.env_steps,
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
    p.add_argument("--eval-every", type=int, default=run.eval_every,
                   help="iterations per chunk (one metrics line, evaluation, checkpoint)")
    p.add_argument("--task-set", default=run.task_set, help="the study's task set to train on")
    p.add_argument("--history", type=int, help="observations stacked (default: the study's)")
    p.add_argument("--episode", type=float, help="episode length, s (default: the study's)")
    p.add_argument("--out", default=run.out, help="output folder")
    p.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    return p


def config_from_args(args):
    """The `baselines.ppo_train.PPOTrainConfig` of the flags (one field each)."""
    from baselines.ppo import PPOConfig
    from baselines.ppo_train import PPOTrainConfig

    values = {field: getattr(args, flag) for flag, field in FLAGS.items()}
    values["hidden"] = widths(args.hidden)
    return PPOTrainConfig(ppo=PPOConfig(**values), env_steps=args.env_steps,
                          eval_every=args.eval_every, task_set=args.task_set,
                          history=args.history, episode=args.episode, out=args.out,
                          resume=args.resume)


def train_ppo_study(study, config):
    """`baselines.ppo_train.train_ppo` of `config` (a `PPOTrainConfig`) on `study`, then
    learning_curve.png and a summary line; returns `train_ppo`'s PPOTrainResult."""
    from baselines.ppo_train import train_ppo

    result = train_ppo(config, study)
    out, log, done = Path(config.out), result.metrics, config.iterations
    ppo_curve(log, out / "learning_curve.png", study.name, len(study.tasks(config.task_set)))
    print(f"{out}: {done} iterations ({done * config.ppo.batch} env steps), deterministic "
          f"policy mean reward {log[-1]['reward_mean']:.1f}, policy in {out / 'policy'}")
    return result
