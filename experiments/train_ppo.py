"""PPO training of a load-shedding policy on a study: the PPO baseline of the PNNL PARS study
(`baselines.ppo`: rejax's PPO with RLlib's value clip and KL term, Table II defaults).

    python -m experiments.train_ppo --study ieee39_fidvr|studies/x.toml --env-steps N \
        --envs K --out DIR [--resume]

Every flag is one field of `baselines.ppo_train.PPOTrainConfig` or of its
`baselines.ppo.PPOConfig` (`FLAGS`), and `baselines.ppo_train.train_ppo` runs the training:
jitted chunks of --eval-every iterations of --envs × --rollout-steps transitions each, an
evaluation, a metrics line and a checkpoint after each chunk. Output folder DIR:
  study.toml      the resolved study (`--resume` without --study reads it back)
  config.json     the resolved hyper-parameters and run information
  metrics.jsonl   one line per chunk: iteration, env_steps, wall_s, device, wall_total_s,
                  reward_mean (deterministic policy, every training task), n_recovered,
                  reward_train (episodes ended during the collection) and episodes_train
                  (`baselines.ppo_train` says more)
  checkpoints/    orbax checkpoints of the whole rejax train state, every chunk (last 3 kept)
  policy/         the trained policy (experiments.evaluate --controller ppo:DIR/policy)
  learning_curve.png
`--resume` continues from the last checkpoint; `--env-steps` is the run's total (rounded up
to whole iterations). A resumed run must use the hyper-parameters it was started with.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from experiments.studyargs import add_study_arguments, study_from_args

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


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return _train(args)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


def config_from_args(args):
    """The `baselines.ppo_train.PPOTrainConfig` of the flags (one field each)."""
    from baselines.ppo import PPOConfig
    from baselines.ppo_train import PPOTrainConfig

    values = {field: getattr(args, flag) for flag, field in FLAGS.items()}
    values["hidden"] = tuple(int(h) for h in str(args.hidden).split(",") if h.strip())
    return PPOTrainConfig(ppo=PPOConfig(**values), env_steps=args.env_steps,
                          eval_every=args.eval_every, task_set=args.task_set,
                          history=args.history, episode=args.episode, out=args.out,
                          resume=args.resume)


def _train(args) -> int:
    """`train_study` of the flags' config on the flags' study."""
    config = config_from_args(args)
    saved_study = Path(config.out) / "study.toml"
    study = study_from_args(args, str(saved_study) if config.resume and saved_study.is_file()
                            else None)
    train_study(study, config)
    return 0


def train_study(study, config):
    """`baselines.ppo_train.train_ppo` of `config` (a `PPOTrainConfig`) on `study`, then
    learning_curve.png and a summary line; returns `train_ppo`'s PPOTrainResult."""
    from baselines.ppo_train import train_ppo

    result = train_ppo(config, study)
    out, log, done = Path(config.out), result.metrics, config.iterations
    _learning_curve(log, out / "learning_curve.png", study.name,
                    len(study.tasks(config.task_set)))
    print(f"{out}: {done} iterations ({done * config.ppo.batch} env steps), deterministic "
          f"policy mean reward {log[-1]['reward_mean']:.1f}, policy in {out / 'policy'}")
    return result


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
