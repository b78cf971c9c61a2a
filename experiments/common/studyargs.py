"""The command-line flags that choose a study, shared by every command, and how the notes of
building one are shown.

    --study NAME|FILE                       a built-in study or a study TOML file
    --raw R1 [R2 ...] --dyr D [--task-config J] [--sim-config S]   a study from files
    --load-levels L1 [L2 ...]               operating points of a built-in study
    --study FILE --raw R1 [R2 ...]          a study file's settings at these operating points
    --verbose                               every note of building the study, in full

Building a study warns what its readers skipped (RawWarning: records not modelled),
approximated or found odd (ModelWarning, InitWarning: a device not at rest at t = 0) and
what its input files hold that changes nothing (StudyWarning, the notes in `Study.notes`).
`summarised_notes` prints them as one line per kind, with counts, instead of one
(multi-line) warning each; `--verbose` prints every one, and the study's and each operating
point's notes.
"""
from __future__ import annotations

import argparse
import contextlib
import re
import sys
import warnings
from collections import Counter

import jaxgrid.study as jaxgrid_study
from jaxgrid import cases
from jaxgrid.study import Study, builtin, from_files, read_study

LINE_WIDTH = 120  # characters of a summary line
# A message's leading "FILE: " or "FILE:LINE: " (the same note of many files is one kind).
_SOURCE = re.compile(r"^(\S+\.(raw|dyr|json|toml|m))(:\d+)?: ", re.IGNORECASE)


def add_study_arguments(parser: argparse.ArgumentParser, default: str | None) -> None:
    """The study flags above; `default` is the study used when none is given."""
    group = parser.add_argument_group("study")
    group.add_argument("--study", default=None,
                       help=f"built-in study name or study TOML file (default: {default})")
    group.add_argument("--raw", nargs="+", help="RAW files, one per operating point (with "
                       "--study FILE: that study's settings at these points)")
    group.add_argument("--dyr", help="DYR file (with --raw)")
    group.add_argument("--task-config", help="PNNL task JSON (with --raw)")
    group.add_argument("--sim-config", help="PNNL simulation JSON (with --raw)")
    group.add_argument("--load-levels", nargs="+", type=float,
                       help="operating points of a built-in study (factor on every load)")
    group.add_argument("--verbose", action="store_true",
                       help="print every note of building the study in full (default: one "
                            "line per kind)")
    parser.set_defaults(default_study=default)


def study_from_args(args: argparse.Namespace, fallback: str | None = None) -> Study:
    """The study the flags name (`_chosen_study`), its notes summarised on stderr
    (`summarised_notes`; with --verbose every one in full)."""
    verbose = getattr(args, "verbose", False)
    with summarised_notes(verbose):
        study = _chosen_study(args, fallback)
    if verbose:
        notes = [*study.notes, *(f"{p.label}: {n}" for p in study.points for n in p.notes)]
        print("\n".join(notes), file=sys.stderr)
    return study


def study_from_spec(spec: str) -> Study:
    """`jaxgrid.study.load_study(spec)` (a built-in name or a study file) for a command: the
    notes of building it summarised on stderr (`summarised_notes`)."""
    with summarised_notes():
        return jaxgrid_study.load_study(spec)


@contextlib.contextmanager
def summarised_notes(verbose: bool = False):
    """Warnings raised inside printed on stderr at the end: one line per kind (category)
    with its count and its most frequent message, shortened (`warnings_summary`); verbose:
    every one in full."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield
        finally:
            lines = ([f"{w.category.__name__}: {w.message}" for w in caught] if verbose
                     else warnings_summary(caught))
            if lines:
                print("\n".join(lines), file=sys.stderr, flush=True)


def warnings_summary(caught: list[warnings.WarningMessage]) -> list[str]:
    """A header and one line per warning category: "  RawWarning x13 (13 files): records
    not modelled, skipped: ..."; the same message of different files counts as one."""
    if not caught:
        return []
    kinds: dict[str, Counter] = {}
    files: dict[str, set] = {}
    for w in caught:
        text = str(w.message)
        source = _SOURCE.match(text)
        kind = w.category.__name__
        kinds.setdefault(kind, Counter())[text[source.end():] if source else text] += 1
        files.setdefault(kind, set()).update([source.group(1)] if source else [])
    lines = [f"{len(caught)} note(s) while building the study, one line per kind "
             "(--verbose prints them in full):"]
    for kind, texts in kinds.items():
        text, _ = texts.most_common(1)[0]
        where = f" ({len(files[kind])} files)" if len(files[kind]) > 1 else ""
        others = f" [+{len(texts) - 1} other message(s)]" if len(texts) > 1 else ""
        head = f"  {kind} x{sum(texts.values())}{where}: "
        room = LINE_WIDTH - len(head) - len(others)
        lines.append(head + (text if len(text) <= room else text[:room - 3] + "...") + others)
    return lines


def _chosen_study(args: argparse.Namespace, fallback: str | None) -> Study:
    """The study the flags name; `fallback` (e.g. a run folder's study.toml) before the
    parser's default when neither --study nor --raw is given."""
    if args.raw and args.study:
        if args.dyr or args.task_config or args.sim_config or args.load_levels:
            raise ValueError("--study with --raw takes the study's settings at the RAW files' "
                             "operating points: drop --dyr, --task-config, --sim-config and "
                             "--load-levels")
        if args.study in cases.names():
            raise ValueError(f"--raw with the built-in {args.study!r}: its operating points are "
                             "load levels (--load-levels), not RAW files")
        return read_study(args.study, raw=args.raw)
    if args.raw:
        if args.load_levels:
            raise ValueError("--raw builds a study from files: drop --load-levels")
        if not args.dyr:
            raise ValueError("--raw needs --dyr")
        return from_files(args.raw, args.dyr, args.task_config, args.sim_config)
    if args.dyr or args.task_config or args.sim_config:
        raise ValueError("--dyr, --task-config and --sim-config go with --raw")
    name = args.study or fallback or args.default_study
    if name is None:
        raise ValueError("no study: give --study NAME|FILE or --raw ... --dyr ...")
    if args.load_levels:
        if name not in cases.names():
            raise ValueError(f"--load-levels sets the operating points of a built-in study; "
                             f"{name!r} is not one (a study file lists its RAW files)")
        return builtin(name, args.load_levels)
    return jaxgrid_study.load_study(name)
