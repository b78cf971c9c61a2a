"""PARS training of a load-shedding policy on a study (built-in, study file, or RAW + DYR +
task files).

    python -m experiments.train --study ieee39_fidvr|studies/x.toml --out DIR
    python -m experiments.train --raw R1 R2 ... --dyr D --task-config J [--sim-config S] --out DIR

`experiments.train_39bus` and `experiments.train_300bus` are the same command on the
built-in studies (`experiments.common.training.COMMANDS`). Every hyper-parameter has a flag,
one field each of `experiments.common.training.Choices`; where one is not given, the paper's
setting for the study's grid size applies (Table I: the 39-bus column up to 100 buses, the
300-bus one above), and `training.train_config` / `training.problem` turn them into
`ars.train.TrainConfig` (the training loop) and `jaxgrid.problem.training_problem` (the
study's side: --history, --episode, --task-set, --task-sampling). Each iteration draws
m tasks of the study's training set across its operating points, uniformly or stratified
(`--task-sampling`); all operating points share one compiled iteration. Output folder DIR:
  study.toml      the resolved study (`--resume` without --study reads it back)
  metrics.jsonl   one line per iteration: iteration, reward_mean, reward_max, wall_s, rollouts,
                  env_steps (agent steps simulated, cumulative: failed episodes stop early),
                  device (the devices it ran on, "COUNT × KIND": a run resumed elsewhere says so)
  checkpoints/    orbax checkpoints every --checkpoint-every iterations and at the end
  policy/         the trained policy (experiments.evaluate --controller policy:DIR/policy)
  policies/NNNNN/ the policy after iteration NNNNN, at every checkpoint (all kept: the last
                  is not always the one that generalises best to the test tasks)
  learning_curve.png
`--resume` continues from the last checkpoint; `--iterations` is the run's total.
`--seeds K` trains K seeds of the configuration as one vmapped program (a leading seed axis
on the training state): metrics.jsonl then holds per-seed lists of reward_mean and
reward_max and env_steps (rollouts counts one seed's), and each policy folder holds seed0/ ...
seedK-1/. The study's [training] settings give the defaults of --history (per policy kind)
and --task-sampling; episodes run only at the operating points of the task set.
Multi-host: --coordinator HOST:PORT --num-processes P --process-id I, or --distributed alone
where `jax.distributed.initialize` can read them from the cluster environment; it is called
before anything else touches JAX. Process 0 writes the files.
"""
import sys

from experiments.common.pars_command import run


def main(argv: list[str] | None = None) -> int:
    return run(argv, "train")


if __name__ == "__main__":
    sys.exit(main())
