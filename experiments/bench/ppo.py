"""PPO benchmark: seconds per PPO iteration and environment steps per second on a study, by
batch shape (parallel environments × minibatches).

    python -m experiments.bench.ppo [--study studies/ieee300_pnnl.toml]
        [--shapes 40:32 500:400 2000:32] [--seeds 1 5] [--iterations 3] [--repeats 2]
        [--budget-steps 115e6] [--out benchmarks/cpu/ppo.json]

Each shape ENVS:MINIBATCHES runs the study's PPO (`baselines.ppo.PPOConfig`: Table II of the
PARS study, else RLlib's defaults) with that many environments and minibatches per epoch,
rollout 100 steps and 30 epochs: 40:32 is the default (RLlib's 4 000-step train batch in
minibatches of 125), 500:400 the paper's 500 rollout workers with the same minibatch size.
A timed call is one jitted chunk of `--iterations` iterations (`baselines.ppo_train`, as
`experiments.train_ppo` runs them), `--seeds` K trainings vmapped in one program (as PARS
trains its seeds; `experiments.train_ppo` trains one); the first call includes the compile.
Each row gives the hours that K trainings of `--budget-steps` environment steps each
(default: one 300-bus PARS training, 500 iterations of 2·128·9 rollouts of 100 steps) would
take at the best warm speed.
"""
from __future__ import annotations

import argparse
import dataclasses
import itertools

import jax
import jax.numpy as jnp

from baselines.ppo import PPOConfig, make_ppo
from baselines.ppo_train import host_state, make_chunk
from experiments.bench.timing import timed, write_report
from experiments.common.studyargs import study_from_spec
from jaxgrid.gym import gymnax_env


def shape_config(text: str) -> PPOConfig:
    """'ENVS:MINIBATCHES' -> the default PPOConfig with that many environments and minibatches
    (argparse type: a malformed shape or one PPOConfig refuses is an error of --shapes, before
    anything compiles)."""
    try:
        envs, minibatches = (int(part) for part in text.split(":"))
        return dataclasses.replace(PPOConfig(), envs=envs, minibatches=minibatches)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"{text!r}: want ENVS:MINIBATCHES ({err})") from None


def bench_shape(study, config: PPOConfig, seeds: int, iterations: int, repeats: int,
                budget_steps: float) -> dict:
    """Time `repeats` warm chunks of `iterations` PPO iterations of `config`, `seeds`
    trainings vmapped in one program."""
    adapter, params = gymnax_env(study)
    algo = make_ppo(adapter, params, config)
    chunk = jax.jit(jax.vmap(make_chunk(), in_axes=(None, 0, None)))  # traced once
    keys = jax.random.split(jax.random.PRNGKey(config.seed), seeds)
    state = host_state(jax.vmap(algo.init_state)(keys))
    state, first = timed(lambda: chunk(algo, state, jnp.int32(iterations)))
    warm = []
    for _ in range(repeats):
        state, wall = timed(lambda: chunk(algo, state, jnp.int32(iterations)))
        warm.append(wall / iterations)
    steps_per_s = seeds * config.batch / min(warm)
    row = {"envs": config.envs, "minibatches": config.minibatches, "seeds": seeds,
           "minibatch_size": config.batch // config.minibatches,
           "rollout_steps": config.rollout_steps, "epochs": config.epochs,
           "env_steps_per_iteration": config.batch, "iterations_per_call": iterations,
           "first_call_s": round(first, 2), "s_per_iteration": round(min(warm), 3),
           "warm_s_per_iteration": [round(w, 3) for w in warm],
           "env_steps_per_s": round(steps_per_s, 1),
           "budget_hours": round(seeds * budget_steps / steps_per_s / 3600, 2)}
    print(row, flush=True)
    return row


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--study", default="studies/ieee300_pnnl.toml",
                        help="built-in study name or study file")
    parser.add_argument("--shapes", nargs="*", type=shape_config, default=[PPOConfig()],
                        help="ENVS:MINIBATCHES pairs to time")
    parser.add_argument("--seeds", nargs="*", type=int, default=[1],
                        help="trainings vmapped in one program, each count timed per shape")
    parser.add_argument("--iterations", type=int, default=3, help="PPO iterations per call")
    parser.add_argument("--repeats", type=int, default=2, help="warm calls per shape")
    parser.add_argument("--budget-steps", type=float, default=500 * 2 * 128 * 9 * 100,
                        help="environment steps to project the run time of")
    parser.add_argument("--out", default="benchmarks/cpu/ppo.json")
    args = parser.parse_args(argv)
    study = study_from_spec(args.study)
    rows = []
    for config, seeds in itertools.product(args.shapes, args.seeds):
        rows.append(bench_shape(study, config, seeds, args.iterations, args.repeats,
                                args.budget_steps))
        write_report(args.out, study=args.study, budget_steps=args.budget_steps, runs=rows)


if __name__ == "__main__":
    main()
