"""Reproduce the PARS paper's figures and tables with one command, the paper's values beside.

    python -m experiments.reproduce --study ieee39_fidvr|FILE.toml --out results/repro39 \
        [--only fig6a,fig8,...] [--quick] [--iterations N] [--seeds K] [--ppo-seeds K]
        [--directions N] [--policy DIR/policy] [--ppo-policy DIR/policy]
        [--gpu-timing BENCH.json] [--skip-baselines mpc,ppo] [--ppo-flags "--envs 500 ..."]
        [--ppo-env-steps STEPS]
    python -m experiments.reproduce --study studies/ieee39_pnnl.toml --out results/pnnl39
    python -m experiments.reproduce --study studies/ieee300_pnnl.toml --out results/pnnl300
    make reproduce

Experiments (`experiments.reproduce.figures`): fig6a (linear / FNN / LSTM learning curves, mean ±
std over seeds), fig6b (LSTM, N = 8/16/32/64), fig7 (speed-up over devices and processes),
fig8 (39-bus case study, PARS vs UVLS), fig9 (LSTM, N = 32/64/128), fig10_11 (PARS vs PPO over
wall time and environment steps), fig12 (per-task reward differences PARS − UVLS / MPC /
PPO on the test set), tab3 (decision time), fig13 (300-bus case study, all four
controllers), generalisation (not in the paper: the policy against UVLS on the study's
"generalisation" task set, operating points it never trained on; skipped for a study without
one). Every experiment runs on the given study at the paper's settings (500 iterations, 5
seeds, N = 16 on the 39-bus and 128 on the 300-bus, b = N/2, the study's history per policy
kind and task sampling); the paper's values are for the case the report names. Seeds of one
configuration train as one vmapped program.

Output folder: OUT/<id>.png and OUT/<id>.json (numbers, settings, wall time of this
invocation, the trainings' wall time summed over all invocations and the devices they ran on)
per experiment, OUT/REPORT.md (every figure; our numbers beside the paper's; OUT/NOTES.md, the
hand-written explanations, at its end), OUT/policy/ (the
best seed of the finished main LSTM training, `experiments.evaluate --controller
policy:OUT/policy`), OUT/runs/ (the
trainings and evaluations, named by a hash of their inputs: reused when finished, resumed
when interrupted, recomputed when an input changes). `--quick` runs everything with tiny
settings (2 iterations, 1.5-s episodes, a few test tasks) as a check of the pipeline.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

from experiments.reproduce.figures import EXPERIMENTS, PAPER, NotApplicable
from experiments.reproduce.runs import BASELINES_SKIPPABLE, FULL, QUICK, Runs


def run(study: str, out: str | Path, only=None, quick: bool = False, **overrides) -> dict:
    """Run the experiments `only` (default all) into `out`; write REPORT.md. `overrides`:
    fields of `runs.Settings`. Returns {id: result}."""
    unknown = sorted(set(only or ()) - set(EXPERIMENTS))
    if unknown:
        raise ValueError(f"--only {','.join(unknown)}: unknown; the experiments are "
                         f"{', '.join(EXPERIMENTS)}")
    settings = dataclasses.replace(QUICK if quick else FULL, **overrides)
    wrong = sorted(set(settings.skip_baselines) - set(BASELINES_SKIPPABLE))
    if wrong:
        raise ValueError(f"--skip-baselines {','.join(wrong)}: unknown; it takes "
                         f"{', '.join(BASELINES_SKIPPABLE)} (UVLS is always in)")
    if settings.ppo_env_steps is not None and settings.ppo_env_steps < 1:
        raise ValueError(f"--ppo-env-steps {settings.ppo_env_steps}: must be at least 1 "
                         "(environment steps per PPO training)")
    runs = Runs(study, out, settings)
    results = {}
    for name, experiment in EXPERIMENTS.items():
        if only and name not in only:
            continue
        print(f"--- {name}: {PAPER[name]['title']}", flush=True)
        runs.trainings.clear()
        start = time.perf_counter()
        try:
            result = experiment(runs, runs.out / f"{name}.png")
        except NotApplicable as why:
            print(f"--- {name}: skipped: {why}", flush=True)
            continue
        wall_s = time.perf_counter() - start
        training_s, trained_on = runs.training_time()
        result.update(id=name, figure=f"{name}.png", wall_s=round(wall_s, 1),
                      training_s=round(training_s, 1), trained_on=trained_on,
                      study=runs.study.name, quick=quick)
        (runs.out / f"{name}.json").write_text(json.dumps(result, indent=1))
        results[name] = result
    policy = runs.export_policy()
    if policy is not None:
        print(f"policy: {policy}", flush=True)
    write_report(runs.out, dataclasses.replace(settings, directions=runs.directions), quick,
                 runs.study.name)
    return results


def write_report(out: Path, settings, quick: bool, study: str | None = None) -> None:
    """REPORT.md from every OUT/<id>.json there (this run's and earlier ones), and OUT/NOTES.md
    at its end when there is one: what was measured to explain the numbers, written by hand,
    kept across runs. `study`: the study the main training ran on (what OUT/policy is
    compared with)."""
    lines = ["# PARS paper reproduction", "",
             f"Settings of the last invocation: "
             f"{'--quick (a pipeline check, not results)' if quick else 'full'}; "
             f"{json.dumps(dataclasses.asdict(settings))}.", "",
             "Each experiment ran on the study named under it, in its own last invocation "
             "(an experiment left out of the last one keeps its earlier figure and numbers); "
             "the paper's values are for the paper's case and settings, given beside ours.", ""]
    if (out / "policy" / "policy.json").is_file():
        lines += [_policy_line(out / "policy", study), ""]
    for name in EXPERIMENTS:
        path = out / f"{name}.json"
        if not path.is_file():
            continue
        result, paper = json.loads(path.read_text()), PAPER[name]
        lines += [f"## {name}: {paper['title']}", "", f"![{name}]({result['figure']})", "",
                  f"- ours: {result['study']}, {result['settings']}; {_times(result)}"
                  + (" (--quick)" if result.get("quick") else ""),
                  f"- paper: {paper['case']}, {paper['settings']}", "",
                  "| quantity | ours | paper |", "| --- | --- | --- |"]
        keys = list(result["numbers"]) + [k for k in paper["values"]
                                          if k not in result["numbers"]]
        for key in keys:
            lines.append(f"| {key} | {_cell(result['numbers'].get(key))} | "
                         f"{_cell(paper['values'].get(key))} |")
        lines.append("")
    notes = out / "NOTES.md"
    if notes.is_file():
        lines += [notes.read_text().rstrip(), ""]
    (out / "REPORT.md").write_text("\n".join(lines))


def _policy_line(folder: Path, study: str | None) -> str:
    """What OUT/policy holds: the best seed of the main LSTM training on `study`, a policy of
    another study (committed on purpose, `Runs.export_policy`), or, when its policy.json
    says the training stopped short, the iteration it is from."""
    info = json.loads((folder / "policy.json").read_text())
    use = f"(`python -m experiments.evaluate --controller policy:{folder} ...`)"
    if study is not None and info.get("study", study) != study:
        return (f"`policy/` holds a policy trained on the study `{info['study']}` (task set "
                f"`{info.get('task_set')}`), not this report's main training: the notes say "
                f"why {use}.")
    done, total = info.get("iteration"), info.get("iterations")
    if done is not None and total is not None and done < total:
        return (f"`policy/` holds the main LSTM training's policy after iteration {done} of "
                f"{total}: that training is unfinished {use}.")
    return f"The best seed of the main LSTM training is in `policy/` {use}."


def _times(result: dict) -> str:
    """Wall time of the experiment's last invocation, and its trainings' over all of theirs
    (a resumed or reused training ran mostly in earlier invocations)."""
    text = f"{result['wall_s']} s in its last invocation"
    if result.get("training_s"):
        text += (f"; its trainings took {result['training_s']} s in all, on "
                 + ", ".join(result.get("trained_on") or ["unrecorded devices"]))
    return text


def _cell(value) -> str:
    return "" if value is None else str(value)


def _names(text: str) -> tuple[str, ...]:
    """'a, b,' -> ('a', 'b')."""
    return tuple(s.strip() for s in text.split(",") if s.strip())


def _directions(text: str) -> tuple[int, ...]:
    """'32, 128' -> (32, 128): direction counts N >= 2 (argparse names the flag otherwise)."""
    try:
        values = tuple(int(n) for n in _names(text))
    except ValueError:
        values = ()
    if not values or min(values) < 2:
        raise argparse.ArgumentTypeError(f"{text!r}: give comma-separated direction counts "
                                         "N >= 2")
    return values


# experiments.train_ppo flags the harness sets itself (per training), refused in --ppo-flags
PPO_FLAGS_SET_HERE = ("--study", "--raw", "--dyr", "--task-config", "--sim-config",
                      "--load-levels", "--env-steps", "--seed", "--out", "--resume")


def _ppo_flags(text: str) -> tuple[str, ...]:
    """'--envs 500 --minibatches 400' -> its words, once `experiments.train_ppo` accepts them
    as a configuration (argparse names --ppo-flags otherwise)."""
    from experiments.common.ppo_training import config_from_args, parser

    words, train_ppo = tuple(shlex.split(text)), parser()
    train_ppo.allow_abbrev = False  # '--env-s' must not slip in as --env-steps
    args, unknown = train_ppo.parse_known_args(words)
    refused = [w for w in words if w.split("=")[0] in PPO_FLAGS_SET_HERE]
    if unknown or refused:
        raise argparse.ArgumentTypeError(
            f"{text!r}: {unknown or refused} not allowed (experiments.train_ppo's flags, "
            f"less those the harness sets: {', '.join(PPO_FLAGS_SET_HERE)})")
    try:
        config_from_args(args)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"{text!r}: {err}") from None
    return words


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.reproduce",
                                description=__doc__.split("\n")[0])
    p.add_argument("--study", default="ieee39_fidvr", help="built-in study name or study TOML")
    p.add_argument("--out", default="results/reproduce", help="output folder")
    p.add_argument("--only", help=f"comma-separated subset of {','.join(EXPERIMENTS)}")
    p.add_argument("--quick", action="store_true", help="tiny settings: a pipeline check")
    p.add_argument("--iterations", type=int, help="PARS iterations per training")
    p.add_argument("--seeds", type=int, help="PARS seeds per configuration")
    p.add_argument("--ppo-seeds", type=int, help="PPO trainings for fig10_11 (the best one "
                                                  "is fig12's and fig13's)")
    p.add_argument("--ppo-env-steps", type=int, help="environment steps per PPO training "
                   "(default: as many as one PARS training, fig11's comparison)")
    p.add_argument("--directions", type=int, help="N of the main policy (default: the "
                                                   "paper's, 16 or 128 by grid size)")
    p.add_argument("--sweep", type=_directions, help="comma-separated N of fig6b (default "
                   f"{','.join(map(str, FULL.sweep))})")
    p.add_argument("--sweep-large", type=_directions, help="comma-separated N of fig9 (default "
                   f"{','.join(map(str, FULL.sweep_large))}; the main policy's N reuses the "
                   "main training)")
    p.add_argument("--policy", help="a trained PARS policy folder for fig8, fig12, fig13 "
                                    "(default: train one)")
    p.add_argument("--ppo-policy", help="a trained PPO policy folder for fig12, fig13 "
                                        "(default: train one)")
    p.add_argument("--gpu-timing", help="an experiments.bench.train JSON measured on a GPU "
                                        "machine: fig7 adds its iteration time")
    p.add_argument("--skip-baselines", help="comma-separated baselines to leave out of "
                   "fig10_11, fig12, tab3 and fig13: mpc, ppo (for a machine that cannot "
                   "afford them; the report says so)")
    p.add_argument("--ppo-flags", type=_ppo_flags, help="experiments.train_ppo flags for the "
                   "PPO trainings, e.g. '--envs 500 --minibatches 400' (default: Table II with "
                   "RLlib's defaults, 40 environments)")
    args = p.parse_args(argv)
    overrides = {k: v for k, v in (("iterations", args.iterations), ("seeds", args.seeds),
                                   ("ppo_seeds", args.ppo_seeds), ("ppo_flags", args.ppo_flags),
                                   ("ppo_env_steps", args.ppo_env_steps),
                                   ("directions", args.directions), ("policy", args.policy),
                                   ("ppo_policy", args.ppo_policy),
                                   ("sweep", args.sweep), ("sweep_large", args.sweep_large),
                                   ("gpu_timing", args.gpu_timing)) if v is not None}
    if args.skip_baselines:
        overrides["skip_baselines"] = _names(args.skip_baselines)
    only = _names(args.only) if args.only else None
    try:
        run(args.study, args.out, only, args.quick, **overrides)
    except (ValueError, KeyError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{Path(args.out) / 'REPORT.md'}")
    return 0

