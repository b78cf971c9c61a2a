"""Training speed of this code against an earlier commit, measured in the same run.

    python -m experiments.bench.speedup [--baseline cae8d39] [--studies ieee39_fidvr
        ieee300_fidvr] [--devices 1 2] [--rounds 2] [--repeats 2]
        [--out benchmarks/cpu/speedup.json]

The baseline commit is checked out in a temporary git worktree; its training benchmark
(`experiments.bench_train` before the benchmarks moved to `experiments/bench/`) and this
tree's `experiments.bench.train` run one after the other, as fresh processes, alternating
`--rounds` times per (study, device count), so the machine's drift (±25 % here between runs)
falls on both. Each side runs its own defaults for the built-in study (step size, sweeps)
with the same work per iteration (the training command's N, b, m = 9 tasks, 10 s episodes;
see `experiments.bench.train`). The figure is the best s/iteration of each side and their
ratio baseline / this.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from experiments.bench.timing import write_report

ROOT = Path(__file__).resolve().parents[2]
BASELINE = "cae8d39"  # the code before the performance issue (15)


def bench_train_row(tree: Path, study: str, devices: int, repeats: int, out: Path) -> dict:
    """One run of the training benchmark of the tree at `tree` in a fresh process: its case
    (runs, each with rollouts_per_iteration).

    Commits before the benchmarks moved to `experiments/bench/` name it
    `experiments.bench_train`; those before the studies-as-data change name a built-in study
    `--cases`."""
    module = "experiments.bench.train" if (tree / "experiments/bench/train.py").is_file() \
        else "experiments.bench_train"
    source = tree / (module.replace(".", "/") + ".py")
    flag = "--studies" if "--studies" in source.read_text() else "--cases"
    subprocess.run([sys.executable, "-m", module, flag, study,
                    "--devices", str(devices), "--repeats", str(repeats), "--out", str(out)],
                   cwd=tree, check=True, env={**os.environ, "PYTHONPATH": str(tree)})
    return json.loads(out.read_text())["cases"][0]


def speedup(baseline: str, studies, device_counts, rounds: int, repeats: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / f"baseline-{baseline}"
        subprocess.run(["git", "worktree", "add", "--detach", str(old), baseline], cwd=ROOT,
                       check=True, capture_output=True)
        try:
            for study in studies:
                for devices in device_counts:
                    times = {"baseline": [], "this": []}
                    for _ in range(rounds):
                        for side, tree in (("baseline", old), ("this", ROOT)):
                            case = bench_train_row(tree, study, devices, repeats,
                                                   Path(tmp) / "run.json")
                            times[side].append(case["runs"][0]["s_per_iteration"])
                    rollouts = case["runs"][0]["rollouts_per_iteration"]  # this tree's row
                    best = {side: min(t) for side, t in times.items()}
                    rows.append({"study": study, "devices": devices,
                                 "s_per_iteration": best, "all_s_per_iteration": times,
                                 "rollouts_per_s": {s: round(rollouts / t, 1)
                                                    for s, t in best.items()},
                                 "speedup": round(best["baseline"] / best["this"], 2)})
                    print(rows[-1], flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT,
                           check=False, capture_output=True)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", default=BASELINE, help="commit to compare with")
    parser.add_argument("--studies", nargs="*", default=["ieee39_fidvr", "ieee300_fidvr"])
    parser.add_argument("--devices", nargs="*", type=int, default=[1, 2])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=2, help="warm iterations per run")
    parser.add_argument("--out", default="benchmarks/cpu/speedup.json")
    args = parser.parse_args(argv)
    write_report(args.out, baseline=args.baseline,
                 rows=speedup(args.baseline, args.studies, args.devices, args.rounds,
                                      args.repeats))


if __name__ == "__main__":
    main()
