"""The PARS training commands' flags, one per `experiments.common.training.Choices` field,
and their run: `experiments.train`, `experiments.train_39bus` and `experiments.train_300bus`
differ only in their study and iterations (`training.COMMANDS`)."""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import jax

from ars.iteration import TASK_RETURNS
from ars.policies import KINDS
from experiments.common.studyargs import add_study_arguments, study_from_args
from experiments.common.training import (COMMANDS, PAPER_PRESETS, TASKS_PER_ITERATION, Choices,
                                         shaping, train_pars_study, widths)

SMALL, LARGE = PAPER_PRESETS["small"], PAPER_PRESETS["large"]


def parser(command: str) -> argparse.ArgumentParser:
    """The flags of training command `command` (a `COMMANDS` key)."""
    defaults = COMMANDS[command]
    study = defaults["study"]
    p = argparse.ArgumentParser(prog=f"python -m experiments.{command}",
                                description=f"PARS training on {study or 'a study'}")
    add_study_arguments(p, study)
    paper = "(default: the paper's for the grid's size, {} up to 100 buses, else {})".format
    p.add_argument("--policy", default=Choices.policy, choices=list(KINDS))
    p.add_argument("--hidden", type=widths,
                   help="layer widths, e.g. 32,32 " + paper(_csv(SMALL["hidden"]),
                                                            _csv(LARGE["hidden"]))
                   + "; a linear policy has none")
    p.add_argument("--obs-clip", type=float,
                   help="clip the policy's normalised inputs to ± this many standard "
                        "deviations (default: no clip, as the paper)")
    p.add_argument("--relative-inputs", action="store_true",
                   help="the policy reads each input as its change since the episode's first "
                        "observation, so every operating point looks alike before a fault "
                        "(default: as it is, the paper's)")
    p.add_argument("--self-mask", action="store_true",
                   help="the policy masks its own requests with the study's action mask, in "
                        "training and wherever it runs, so it never asks to shed where the "
                        "mask would drop it (and is never charged for it); needs a study with "
                        "[env] action_mask (default: its requests go to the environment as "
                        "they are, the paper's)")
    p.add_argument("--arming-level", type=float,
                   help="with --self-mask, the policy asks to shed nothing until one of its "
                        "action buses has been observed below this level (p.u.) from 0.15 s "
                        "after clearing, then is armed for the episode, so a far fault that "
                        "only dips the voltages is left alone, as a relay's pickup does "
                        "(default: none, armed throughout)")
    p.add_argument("--obs-std-floor", type=float,
                   help="the observation normaliser's smallest standard deviation of a "
                        "varying input, in its units (p.u. for voltages; default: none, as "
                        "the paper): an input that hardly moves in training is scaled by at "
                        "most 1/FLOOR")
    p.add_argument("--task-returns", choices=TASK_RETURNS, default=Choices.task_returns,
                   help="a perturbed policy's return: the mean of its m tasks' rewards (the "
                        "paper's), or the mean over the tasks of its rewards' z-scores "
                        "(zscores) or centred ranks (ranks) among the 2N on each task, so "
                        "that a task whose episodes fail or recover by the perturbation "
                        "weighs no more than one where they differ by the load shed; "
                        "ranks+mean adds the centred rank of the mean reward")
    p.add_argument("--init-policy", metavar="DIR",
                   help="start from this saved PARS policy (its θ and observation statistics) "
                        "instead of θ = 0: fine-tuning a trained policy under other settings "
                        "(its kind, sizes and input options must be this training's; pass "
                        "--step-size and --noise where it left off, e.g. α·ε^iterations; "
                        "default: none, the paper's)")
    p.add_argument("--max-request", type=float,
                   help="the most the policy asks to shed per action bus and agent step, as a "
                        "fraction of the bus's initial load (its outputs span [-MAX, 0]); the "
                        "study's action range still binds every controller alike (default: "
                        "that range, the paper's 0.2)")
    p.add_argument("--history", type=int,
                   help="observations stacked (default: the study's for the policy kind, "
                        "[training] history; the PNNL study files give 10 for linear and FNN, "
                        "1 for LSTM policies)")
    p.add_argument("--directions", type=int,
                   help="N " + paper(SMALL["directions"], LARGE["directions"]))
    p.add_argument("--top", type=int, help="b (default: N/2, as the paper)")
    p.add_argument("--step-size", type=float, default=Choices.step_size, help="α")
    p.add_argument("--noise", type=float, default=Choices.noise, help="ν")
    p.add_argument("--decay", type=float, help="ε " + paper(SMALL["decay"], LARGE["decay"]))
    p.add_argument("--tasks-per-iteration", type=int,
                   help=f"m (default {TASKS_PER_ITERATION}, or every task of the set if it "
                        "has fewer)")
    p.add_argument("--task-batch", type=int_or_auto, default=Choices.task_batch,
                   help="tasks whose rollouts run as one batch, or 'auto' (default: all m on "
                        "a GPU, else one on grids of more than 100 buses and all m on "
                        "smaller ones); batches run one after another and stop once all "
                        "their episodes are done")
    p.add_argument("--compact-after", default=Choices.compact_after,
                   help="agent steps after which the episodes still running in a batch "
                        "continue regrouped, so episodes that ended stop costing: 'check' "
                        "(the step of the task set's last recovery check, after which failed "
                        "episodes have stopped), a number, 'off', or 'auto' (default: 'check' "
                        "on grids of more than 100 buses, else 'off': measured faster on the "
                        "PNNL 300-bus on CPUs and a GPU, slower on the 39-bus)")
    p.add_argument("--compact-chunks", type=int, default=Choices.compact_chunks,
                   help="the episodes still running continue in chunks of 1/K of a batch, "
                        "as many as they fill")
    p.add_argument("--task-set", default=Choices.task_set,
                   help="the study's task set to train on, or several joined by '+' "
                        "(uniform sampling), e.g. train+train_extra")
    p.add_argument("--task-sampling", choices=["uniform", "stratified"],
                   help="m distinct tasks uniformly, or k buses × k' durations as the paper "
                        "(default: the study's [training] task_sampling)")
    p.add_argument("--shaping", nargs="+", default=(), metavar="FIELD=VALUE",
                   help="reward weights used in training only, e.g. c_normal=30 (fields of "
                        "the study's [params]: c_voltage, c_shed, c_invalid, c_normal, "
                        "c_prefault, unstable_penalty; c_quiet, a charge per p.u. shed "
                        "on a training task that recovers without control; c_beat, a bonus "
                        "c_beat·tanh((r - r_UVLS)/beat_scale) per training episode, "
                        "beat_scale default 100); evaluations keep the study's")
    p.add_argument("--iterations", type=int, default=defaults["iterations"],
                   help="total iterations of the run (with --resume: continue up to it)")
    p.add_argument("--seed", type=int, default=Choices.seed)
    p.add_argument("--seeds", type=int,
                   help="K independent trainings (seeds --seed ... --seed + K − 1) vmapped "
                        "into one compiled program; metrics per seed, policies in seedI/")
    p.add_argument("--episode", type=float, help="episode length, s (default: the study's)")
    p.add_argument("--out", default=f"runs/{study or 'study'}", help="output folder")
    p.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    p.add_argument("--checkpoint-every", type=int, default=Choices.checkpoint_every,
                   help="K iterations")
    p.add_argument("--distributed", action="store_true",
                   help="multi-host: join a jax.distributed cluster; without the next three "
                        "flags the cluster environment (Slurm, Open MPI, TPU) supplies them")
    p.add_argument("--coordinator", help="multi-host: coordinator address HOST:PORT")
    p.add_argument("--num-processes", type=int, help="multi-host: number of processes")
    p.add_argument("--process-id", type=int, help="multi-host: this process's index")
    return p


def run(argv: list[str] | None, command: str) -> int:
    """Training command `command` with the flags `argv`: `train_pars_study` of their `Choices`
    on their study (a resumed run's own study.toml without --study); 2 and the error on
    stderr for bad input."""
    args = parser(command).parse_args(argv)
    if args.distributed or args.coordinator or args.num_processes:
        jax.distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    try:
        saved_study = Path(args.out) / "study.toml"
        study = study_from_args(args, str(saved_study) if args.resume and saved_study.is_file()
                                else None)
        names = {f.name for f in dataclasses.fields(Choices)}
        chosen = {k: v for k, v in vars(args).items() if k in names}
        train_pars_study(study, Choices(**{**chosen, "shaping": shaping(args.shaping)}))
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


def int_or_auto(value: str) -> int | str:
    """A flag's value: 'auto' or a whole number."""
    return value if value == "auto" else int(value)


def _csv(values) -> str:
    return ",".join(map(str, values))
