"""The command-line flags that choose a study, shared by every command.

    --study NAME|FILE                       a built-in study or a study TOML file
    --raw R1 [R2 ...] --dyr D [--task-config J] [--sim-config S]   a study from files
    --load-levels L1 [L2 ...]               operating points of a built-in study
    --study FILE --raw R1 [R2 ...]          a study file's settings at these operating points
"""
from __future__ import annotations

import argparse

from jaxgrid import cases
from jaxgrid.study import Study, builtin, from_files, load_study, read_study


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
    parser.set_defaults(default_study=default)


def study_from_args(args: argparse.Namespace, fallback: str | None = None) -> Study:
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
    return load_study(name)
