"""PPO training of a load-shedding policy on a study: the PPO baseline of the PNNL PARS study
(`baselines.ppo`: rejax's PPO with RLlib's value clip and KL term, Table II defaults).

    python -m experiments.train_ppo --study ieee39_fidvr|studies/x.toml --env-steps N \
        --envs K --out DIR [--resume]

Every flag is one field of `baselines.ppo_train.PPOTrainConfig` or of its
`baselines.ppo.PPOConfig` (`experiments.common.ppo_training.FLAGS`), and
`baselines.ppo_train.train_ppo` runs the training:
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

import sys
from pathlib import Path

from experiments.common.ppo_training import config_from_args, parser, train_ppo_study
from experiments.common.studyargs import study_from_args


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return _train(args)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


def _train(args) -> int:
    """`train_ppo_study` of the flags' config on the flags' study."""
    config = config_from_args(args)
    saved_study = Path(config.out) / "study.toml"
    study = study_from_args(args, str(saved_study) if config.resume and saved_study.is_file()
                            else None)
    train_ppo_study(study, config)
    return 0


if __name__ == "__main__":
    sys.exit(main())
