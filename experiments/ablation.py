"""Ablations of PARS trainings: each row a study and training flags, trained at several seeds
and scored per kind of task against UVLS on several task sets.

    python -m experiments.ablation results/pnnl39/ablation.toml [--only paper mask ...]
        [--no-train]

The file (TOML; paths relative to it):

    out = "ablation"                      # runs, evaluations, ablation.json, ABLATION.md
    seeds = 3                             # per row, vmapped in one program (--seeds)
    iterations = 500
    task_sets = ["test", "generalisation"]   # each row's study's sets to score on
    [subsets.generalisation_unseen]       # optional: a set's tasks at some operating points,
    of = "generalisation"                 # scored from that set's evaluations (no new runs)
    points = [1, 2, 3]
    why = "the load levels no row trains on"
    [[rows]]
    name = "paper"
    study = "../../studies/ieee39_pnnl.toml"
    flags = []                            # experiments.train flags (after --seeds/--iterations)
    why = "the paper's settings"          # one line for the table
    [[rows]]
    name = "published LSTM v5"
    study = "../../studies/ieee39_pnnl.toml"
    controller = "rlgc:../../../shared/reference/rlgc-policies/.../policy_plus500.npz"
    why = "a network the study published, evaluated as is"

A row with a `controller` (an `experiments.evaluate` spec; a path after its prefix relative to
the file) trains nothing: that controller is scored as one seed; a list of specs
(`controller = ["policy:runs/a/seed0", "policy:runs/b/seed0"]`) is scored as that many seeds,
e.g. the seeds of a training made elsewhere, or before a change to the simulator. A row's
`arming_level = 0.8` (p.u.) scores its saved policies, trained with --self-mask, armed only
once an action bus falls below that level (`experiments.evaluate --arming-level`);
`arming_late = 3.0` (s) arms them as well while a bus of the recovery check is below the
recovery level that long after clearing (`--arming-late`). Each row's
seeds train as one program in a run folder named by the study and the training
(`experiments.reproduce.runs.Runs`: a finished row is reused, an interrupted one resumes);
every seed's final policy, no control and UVLS are evaluated on each task set in the row's
own study (its environment binds every controller alike; evaluations are cached), and scored
per kind of task (`experiments.common.scores`). `--no-train` tabulates the rows already
trained. Writes OUT/ablation.json (every seed's record, for the rows the file names) and
OUT/ABLATION.md (one table per task set: per row the mean over seeds and the range).
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

from ars.checkpoint import metrics_rows
from experiments.common.pars_command import parser as train_parser
from experiments.common.scores import LOSS_KINDS, scores, targets_met
from experiments.common.training import Choices, shaping
from experiments.reproduce.runs import FULL, Runs
from jaxgrid.episode import check_arming_late, check_arming_level

SPEC_KEYS = {"out", "seeds", "iterations", "task_sets", "rows", "subsets"}
ROW_KEYS = {"name", "study", "flags", "why", "controller", "arming_level", "arming_late"}
SUBSET_KEYS = {"of", "points", "why"}


@dataclasses.dataclass(frozen=True)
class Row:
    """One configuration: name, study file (absolute), experiments.train flags, why; or
    fixed controller specs (paths absolute), one per seed, evaluated instead of a training;
    arming_level: p.u., the saved policies' arming level when scored, or None (theirs);
    arming_late: s, their late arming (`jaxgrid.episode.masked`), or None (theirs)."""

    name: str
    study: str
    flags: tuple[str, ...]
    why: str
    controllers: tuple[str, ...] = ()
    arming_level: float | None = None
    arming_late: float | None = None


@dataclasses.dataclass(frozen=True)
class Subset:
    """The tasks of task set `of` at operating points `points` (indices of the study's
    points), scored from `of`'s evaluations."""

    name: str
    of: str
    points: tuple[int, ...]
    why: str


@dataclasses.dataclass(frozen=True)
class Spec:
    """An ablation file's contents (module docstring), paths absolute."""

    path: Path
    out: Path
    seeds: int
    iterations: int
    task_sets: tuple[str, ...]
    rows: tuple[Row, ...]
    subsets: tuple[Subset, ...] = ()


def read_spec(path: str | Path) -> Spec:
    """The ablation file; ValueError naming the file and key of a bad entry."""
    path = Path(path).resolve()
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ValueError(f"{path}: cannot read an ablation file: {err}") from None
    unknown = sorted(set(data) - SPEC_KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown keys {unknown}; allowed: {sorted(SPEC_KEYS)}")
    for key, kind in (("out", str), ("seeds", int), ("iterations", int), ("task_sets", list),
                      ("rows", list)):
        if not isinstance(data.get(key), kind) or isinstance(data.get(key), bool):
            raise ValueError(f"{path}: {key} = {data.get(key)!r}: must be a {kind.__name__}")
    if data["seeds"] < 1 or data["iterations"] < 1 or not data["task_sets"] or not data["rows"]:
        raise ValueError(f"{path}: seeds and iterations must be >= 1, task_sets and rows "
                         "not empty")
    rows = []
    for i, row in enumerate(data["rows"]):
        where = f"{path}: rows[{i}]"
        if not isinstance(row, dict) or set(row) - ROW_KEYS or not {"name", "study"} <= set(row):
            raise ValueError(f"{where}: a table of {sorted(ROW_KEYS)} with name and study")
        study = (path.parent / row["study"]).resolve()
        if not study.is_file():
            raise ValueError(f"{where}.study = {row['study']!r}: no such file ({study})")
        flags = row.get("flags", [])
        if not all(isinstance(f, str) for f in flags):
            raise ValueError(f"{where}.flags = {flags!r}: must be a list of strings")
        controller = row.get("controller")
        listed = [controller] if isinstance(controller, str) else controller
        if controller is not None and (flags or not isinstance(listed, list) or not listed
                                       or not all(isinstance(c, str) for c in listed)):
            raise ValueError(f"{where}.controller = {controller!r}: a controller spec string "
                             "or a non-empty list of them (one per seed), in a row without "
                             "flags")
        level, late = row.get("arming_level"), row.get("arming_late")
        check_arming_level(level, f"{where}.arming_level")
        check_arming_late(late, level, f"{where}.arming_late")
        rows.append(Row(row["name"], str(study), tuple(flags), row.get("why", ""),
                        tuple(_beside(path, c) for c in listed or ()), level, late))
    names = [r.name for r in rows]
    if len(set(names)) < len(names):
        raise ValueError(f"{path}: rows: a name used twice in {names}")
    return Spec(path, (path.parent / data["out"]).resolve(), data["seeds"], data["iterations"],
                tuple(data["task_sets"]), tuple(rows), _subsets(path, data.get("subsets", {})))


def _beside(path: Path, controller: str) -> str:
    """A controller spec with its file (after policy:, ppo: or rlgc:) made absolute,
    relative to the ablation file `path`."""
    kind, sep, target = controller.partition(":")
    if sep and kind in ("policy", "ppo", "rlgc"):
        return f"{kind}:{(path.parent / target).resolve()}"
    return controller


def _subsets(path: Path, data) -> tuple[Subset, ...]:
    """The file's [subsets.NAME] tables; ValueError naming the file and key of a bad one."""
    if not isinstance(data, dict):
        raise ValueError(f"{path}: subsets: must be tables [subsets.NAME]")
    subsets = []
    for name, entry in data.items():
        entry = entry if isinstance(entry, dict) else {}
        points = entry.get("points")
        valid = (not set(entry) - SUBSET_KEYS and isinstance(entry.get("of"), str)
                 and isinstance(points, list) and points
                 and all(isinstance(i, int) and i >= 0 for i in points))
        if not valid:
            raise ValueError(f"{path}: subsets.{name}: a table of {sorted(SUBSET_KEYS)}: `of` "
                             "a task set, `points` a non-empty list of operating-point "
                             "indices >= 0")
        subsets.append(Subset(name, entry["of"], tuple(points), entry.get("why", "")))
    return tuple(subsets)


def choices(spec: Spec, row: Row) -> Choices:
    """The row's training: its flags after the file's --seeds and --iterations."""
    flags = ["--seeds", str(spec.seeds), "--iterations", str(spec.iterations), *row.flags]
    try:
        args = train_parser("train").parse_args(flags)
    except SystemExit:
        raise ValueError(f"{spec.path}: row {row.name!r}: bad flags {list(row.flags)}") from None
    names = {f.name for f in dataclasses.fields(Choices)}
    chosen = {k: v for k, v in vars(args).items() if k in names}
    return Choices(**{**chosen, "shaping": shaping(args.shaping)})


def run_row(spec: Spec, row: Row, train: bool, studies: dict) -> dict | None:
    """{task set: {"seeds": [scores per seed], "uvls": scores of UVLS}} of the row, training it
    first if `train`; None if it is not trained (and `train` is off). `studies` caches a
    `Runs` per study file."""
    if row.study not in studies:
        studies[row.study] = Runs(row.study, spec.out / Path(row.study).stem, FULL)
    runs = studies[row.study]
    folder = None
    if row.controllers:
        controllers = list(row.controllers)
    else:
        chosen = choices(spec, row)
        folder = runs.choices_folder(f"pars_{row.name}", chosen)
        finished = metrics_rows(folder / "metrics.jsonl")
        if not train and not (finished and finished[-1]["iteration"] >= chosen.iterations):
            return None
        runs.trained(folder, chosen)
        controllers = [f"policy:{folder / 'policy' / f'seed{i}'}" for i in range(spec.seeds)]
    record = {"folder": str(folder.relative_to(spec.out)) if folder else None}
    evaluation = functools.cache(runs.evaluation)  # a subset reads its set's result once
    scored = [(name, name, None) for name in spec.task_sets]
    scored += [(s.name, s.of, s.points) for s in spec.subsets]
    for name, task_set, points in scored:
        none, uvls = (at_points(evaluation(c, task_set), points) for c in ("none", "uvls"))
        record[name] = {
            "uvls": scores(none, uvls, uvls),
            "seeds": [scores(none, uvls, at_points(
                evaluation(c, task_set, row.arming_level, row.arming_late), points))
                for c in controllers]}
    return record


def at_points(result: dict, points: tuple[int, ...] | None) -> dict:
    """An evaluation `result` restricted to the tasks at operating points `points` (None:
    all); ValueError if it ran none there."""
    if points is None:
        return result
    tasks = [t for t in result["tasks"] if t["point"] in points]
    if not tasks:
        raise ValueError(f"{result['controller']}: no task at operating points {list(points)}")
    return {**result, "tasks": tasks}


def table(spec: Spec, results: dict) -> str:
    """ABLATION.md: one table per task set, a row per configuration (mean over seeds, then
    the range), the targets each seed meets."""
    lines = [f"# Ablation ({spec.path.name}): {spec.seeds} seeds per row, "
             f"{spec.iterations} iterations", "",
             "Per task set: *need* = tasks no control fails, *ok* = tasks it recovers. "
             "wins: reward above UVLS's on need tasks; rec.: need tasks recovered (UVLS's in "
             "brackets); sheds on: ok tasks with >= 1 MW shed; MW: shed per task of the kind; "
             "lost: the need tasks not won, as ties / both recover / both fail / only UVLS "
             "recovers / only it recovers (mean over seeds; blank for a row scored before "
             "they were counted). "
             "Mean over seeds, range in brackets (a row of one seed: its one value); "
             "targets: seeds meeting all three "
             "(wins >= 95 %, rec. >= UVLS, sheds on <= 5 % of ok).", ""]
    headings = {name: name for name in spec.task_sets}
    for subset in spec.subsets:
        why = f": {subset.why}" if subset.why else ""
        headings[subset.name] = (f"{subset.name} ({subset.of} at points "
                                 f"{', '.join(map(str, subset.points))}{why})")
    for task_set, heading in headings.items():
        first = next((r[task_set] for r in results.values() if r and task_set in r), None)
        if first is None:
            continue
        uv = first["uvls"]
        lines += [f"## {heading}: {uv['n_tasks']} tasks, {uv['need']} need shedding "
                  f"(UVLS recovers {uv['uvls_recovered']}), {uv['ok']} need none", "",
                  "| row | wins (% of need) | rec. | MW need | lost | sheds on (% of ok) | MW ok | "
                  "mean reward | targets | why |", "| --- " * 10 + "|"]
        for row in spec.rows:
            record = results.get(row.name)
            if not record or task_set not in record:
                missing = "not scored (rerun with --no-train)" if record else "not trained"
                lines.append(f"| {row.name} | {missing} | | | | | | | | {row.why} |")
                continue
            seeds = record[task_set]["seeds"]
            cell = lambda key, scale=1.0, fmt="{:.1f}": _cell(  # noqa: E731
                [s[key] * scale for s in seeds], fmt)
            need, ok = seeds[0]["need"], seeds[0]["ok"]
            met = sum(all(targets_met(s).values()) for s in seeds)
            lines.append(
                f"| {row.name} | {cell('wins', 100 / max(need, 1))} | "
                f"{cell('recovered', fmt='{:.1f}')} ({seeds[0]['uvls_recovered']}) | "
                f"{cell('mw_need', fmt='{:.0f}')} | {_lost(seeds)} | "
                f"{cell('sheds_on', 100 / max(ok, 1))} | "
                f"{cell('mw_ok', fmt='{:.0f}')} | {cell('mean_reward', fmt='{:.0f}')} | "
                f"{met}/{len(seeds)} | {row.why} |")
        lines.append("")
    return "\n".join(lines)


def rows_of_spec(spec: Spec, results: dict, results_path: Path) -> dict:
    """`results` (ablation.json's records by row name) without the records of rows no longer
    in the file (renamed or removed), saying which it drops: ablation.json mirrors the file's
    rows, as ABLATION.md does. A dropped row's runs and evaluations stay on disk."""
    stale = sorted(set(results) - {row.name for row in spec.rows})
    if stale:
        print(f"{results_path}: dropping the records of rows no longer in {spec.path}: "
              f"{', '.join(stale)}")
    return {name: record for name, record in results.items() if name not in stale}


def _lost(seeds: list[dict]) -> str:
    """The seeds' mean count of each kind of lost task (`scores.LOSS_KINDS`), or "" for
    records scored before the kinds were counted."""
    if any("losses" not in s for s in seeds):
        return ""
    fmt = "{:.0f}" if len(seeds) == 1 else "{:.1f}"
    return " / ".join(fmt.format(np.mean([s["losses"][kind] for s in seeds]))
                      for kind in LOSS_KINDS)


def _cell(values: list[float], fmt: str) -> str:
    low, high = min(values), max(values)
    if len(values) == 1:
        return fmt.format(low)
    return f"{fmt.format(np.mean(values))} [{fmt.format(low)}, {fmt.format(high)}]"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.ablation",
                                description=__doc__.split("\n")[0])
    p.add_argument("spec", help="the ablation file (TOML)")
    p.add_argument("--only", nargs="+", help="rows to run (default: all, in order)")
    p.add_argument("--no-train", action="store_true",
                   help="tabulate the rows already trained; train nothing")
    args = p.parse_args(argv)
    try:
        spec = read_spec(args.spec)
        unknown = sorted(set(args.only or ()) - {r.name for r in spec.rows})
        if unknown:
            raise ValueError(f"--only {unknown}: not rows of {spec.path}")
        spec.out.mkdir(parents=True, exist_ok=True)
        results_path = spec.out / "ablation.json"
        results = json.loads(results_path.read_text()) if results_path.is_file() else {}
        results = rows_of_spec(spec, results, results_path)
        studies: dict = {}
        for row in spec.rows:
            if args.only and row.name not in args.only:
                continue
            record = run_row(spec, row, not args.no_train, studies)
            if record:
                results[row.name] = {**record, "study": row.study, "flags": list(row.flags)}
                results_path.write_text(json.dumps(results, indent=1))
                (spec.out / "ABLATION.md").write_text(table(spec, results))
        (spec.out / "ABLATION.md").write_text(table(spec, results))
        print(f"{spec.out / 'ABLATION.md'}: {len(results)} of {len(spec.rows)} rows")
    except (ValueError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
