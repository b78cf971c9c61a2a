"""Seconds per PARS iteration of a real training run, this tree against earlier commits, in
one run of the benchmark.

    python -m experiments.bench.iterations [--iterations 22] [--baselines 641791a:3 ...]
        [--variants STUDY.toml ...] [--devices 2] [--out benchmarks/cpu/iterations.json]
        [-- TRAIN ARGS]

Each side runs `experiments.train` (default arguments: the PNNL 300-bus command of
docs/performance.md, LSTM, N = 128, b = 64, one task per batch) as a fresh process on
`--devices` CPU devices, one side after the other: a baseline `COMMIT:K` runs K iterations
in a temporary git worktree (with `../shared` linked beside it, since study files name their
inputs relative to the checkout), this tree `--iterations`. Each side runs its own study
file and defaults. The figures are the iterations' `wall_s` from the run's metrics.jsonl:
the first (with its compile), the median of iterations 2-3 (early: most perturbed policies
fail and their episodes stop at the recovery check) and of the last three (after about 20
updates, more episodes run their whole length), and each early median's ratio to this
tree's. `--variants` runs this tree once more per study file given (e.g. the same study
with another `[env]` step), with the same arguments but `--study`, after the plain run.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from ars.checkpoint import metrics_rows
from experiments.bench.timing import write_report

ROOT = Path(__file__).resolve().parents[2]
TRAIN_ARGS = ["--study", "studies/ieee300_pnnl.toml", "--policy", "lstm", "--hidden", "64,64",
              "--directions", "128", "--top", "64", "--decay", "0.996", "--task-batch", "1"]


def run_training(tree: Path, iterations: int, devices: int, train_args, out: Path) -> list:
    """Per-iteration wall times (s) of `experiments.train` run in `tree` for `iterations`."""
    env = {**os.environ, "PYTHONPATH": str(tree),
           "XLA_FLAGS": f"--xla_force_host_platform_device_count={devices}"}
    subprocess.run([sys.executable, "-m", "experiments.train", *train_args,
                    "--iterations", str(iterations), "--out", str(out)],
                   cwd=tree, env=env, check=True, stdout=subprocess.DEVNULL)
    rows = metrics_rows(next(out.rglob("metrics.jsonl")))
    return [row["wall_s"] for row in sorted(rows, key=lambda r: r["iteration"])]


def with_study(train_args: list, study: str) -> list:
    """`train_args` with its `--study` value (or a new one) set to `study`."""
    if "--study" not in train_args:
        return [*train_args, "--study", study]
    k = train_args.index("--study") + 1
    return [*train_args[:k], study, *train_args[k + 1:]]


def summary(name: str, walls: list) -> dict:
    late = walls[-3:] if len(walls) >= 6 else []
    return {"code": name, "iterations": len(walls), "wall_s": walls, "first_s": walls[0],
            "early_median_s": statistics.median(walls[1:3]),
            "late_median_s": statistics.median(late) if late else None}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1:] if "--" in argv else TRAIN_ARGS
    p = argparse.ArgumentParser(prog="python -m experiments.bench.iterations",
                                description=__doc__.split("\n")[0])
    p.add_argument("--iterations", type=int, default=22)
    p.add_argument("--baselines", nargs="*", default=["641791a:3"],
                   help="COMMIT:ITERATIONS, each run in a git worktree")
    p.add_argument("--variants", nargs="*", default=[],
                   help="study files this tree also runs, with the same arguments")
    p.add_argument("--devices", type=int, default=2)
    p.add_argument("--out", default="benchmarks/cpu/iterations.json")
    args = p.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        os.symlink(ROOT.parent / "shared", Path(tmp) / "shared")
        for spec in args.baselines:
            commit, iterations = spec.split(":")
            tree = Path(tmp) / commit
            subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=ROOT,
                           check=True, capture_output=True)
            try:
                walls = run_training(tree, int(iterations), args.devices, extra,
                                     Path(tmp) / f"run-{commit}")
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                               check=True)
            rows.append(summary(commit, walls))
            print(rows[-1], flush=True)
        for k, variant in enumerate([None, *args.variants]):
            train_args = extra if variant is None else with_study(extra, variant)
            walls = run_training(ROOT, args.iterations, args.devices, train_args,
                                 Path(tmp) / f"run-this-{k}")
            rows.append(summary("this" if variant is None else f"this:{variant}", walls))
            print(rows[-1], flush=True)
    this = rows[len(args.baselines)]
    for row in rows:
        row["early_ratio_to_this"] = row["early_median_s"] / this["early_median_s"]
        if row["late_median_s"] and this["late_median_s"]:
            row["late_ratio_to_this"] = row["late_median_s"] / this["late_median_s"]
    write_report(args.out, train_args=extra, variants=args.variants, cpu_devices=args.devices,
                 runs=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
