"""The README and docs/ cannot drift from the code: every command they show is checked.

Fenced shell blocks of README.md and docs/*.md, and the Makefile's recipes, are read command
by command. A `python -m MODULE ARGS` must name a module that imports and whose argument
parser accepts ARGS: the module runs as `python -m` would run it, and its first
`ArgumentParser.parse_args` call stops it once the arguments are parsed, so nothing is
computed. All modules are checked in one subprocess, which imports jax once. A `make TARGET`
must be a Makefile target. A repository path a command reads (studies/, results/,
benchmarks/, runs/, ...) must exist, unless an earlier command of the same file writes it
(`--out`, `--plot`). The imports of fenced Python blocks must resolve, every `python -m
MODULE` named in the prose must import, and relative links must reach a file and heading.
"""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MAKEFILE = ROOT / "Makefile"
PROJECT_PACKAGES = {"jaxgrid", "ars", "baselines", "experiments"}
SHELL_LANGUAGES = {"", "bash", "sh", "shell", "console"}
SEPARATORS = {";", "&", "&&", "|", "||"}
OUTPUT_FLAGS = {"--out", "--plot"}
# first path components of repository paths a command may read (runs/: written by commands)
REPO_ROOTS = {"studies", "results", "benchmarks", "notebooks", "tests", "runs", "docs",
              "jaxgrid", "ars", "baselines", "experiments"}
SHARED = ROOT.parent / "shared"
README_MAX_LINES = 200


@dataclass(frozen=True)
class Check:
    """One thing a document shows. kind: "command" (module, args), "import" (module,
    names), "module" (module only) or "make" (targets in args); reads: repository paths
    the command reads that no earlier command of the file writes."""
    source: str
    line: int
    kind: str
    module: str = ""
    args: tuple[str, ...] = ()
    reads: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        return f"{self.source}:{self.line}: {self.kind} {self.module} {' '.join(self.args)}"


def fenced_blocks(text: str):
    """(language, first line number, lines) of every fenced code block of a Markdown text."""
    blocks, language, start, body = [], None, 0, []
    for number, line in enumerate(text.splitlines(), 1):
        fence = re.match(r"\s*```(\w*)", line)
        if fence and language is None:
            language, start, body = fence[1], number + 1, []
        elif fence:
            blocks.append((language, start, body))
            language = None
        elif language is not None:
            body.append(line)
    return blocks


def logical_lines(numbered_lines):
    """(line number, text) pairs with backslash continuations joined."""
    joined, first, parts = [], None, []
    for number, line in numbered_lines:
        first = first or number
        parts.append(line.strip().removesuffix("\\"))
        if not line.rstrip().endswith("\\"):
            joined.append((first, " ".join(parts)))
            first, parts = None, []
    return joined


def commands(line: str):
    """The simple commands of one shell line, without leading VAR=value assignments."""
    tokens = shlex.split(line, comments=True)
    segment = []
    for token in [*tokens, ";"]:
        if token in SEPARATORS:
            while segment and re.match(r"^\w+=", segment[0]):
                segment.pop(0)
            if segment:
                yield segment
            segment = []
        else:
            segment.append(token)


def path_arguments(args) -> tuple[list[str], list[str]]:
    """(paths read, paths written) among a command's arguments."""
    reads, writes, previous = [], [], None
    for arg in args:
        flag, _, value = arg.partition("=") if arg.startswith("--") else ("", "", arg)
        if flag in OUTPUT_FLAGS:
            writes.append(value)
        elif previous in OUTPUT_FLAGS:
            writes.append(arg)
        elif "/" in value and not value.startswith("-"):
            path = re.sub(r"^\w+:", "", value)  # a controller spec, e.g. policy:DIR
            if path.split("/")[0] in REPO_ROOTS or path.startswith("../shared/"):
                reads.append(path)
        previous = arg
    return reads, writes


def shell_checks(source: str, numbered_lines, written: list[str]):
    """Checks of the commands in (line number, text) pairs; `written` collects outputs."""
    for number, line in numbered_lines:
        for tokens in commands(line):
            if tokens[0] == "make":
                yield Check(source, number, "make", args=tuple(tokens[1:]))
            elif Path(tokens[0]).name.startswith("python") and tokens[1:2] == ["-m"]:
                reads, writes = path_arguments(tokens[3:])
                unwritten = tuple(p for p in reads if not any(
                    p == w or p.startswith(w.rstrip("/") + "/") for w in written))
                written.extend(writes)
                yield Check(source, number, "command", tokens[2], tuple(tokens[3:]), unwritten)


def python_checks(source: str, start: int, lines: list[str]):
    for number, line in enumerate(lines, start):
        found = re.match(r"\s*from ([\w.]+) import (.+)", line)
        if found:
            names = [n.split(" as ")[0].strip(" ()") for n in found[2].split(",")]
            yield Check(source, number, "import", found[1], tuple(n for n in names if n))
        elif found := re.match(r"\s*import ([\w.]+)", line):
            yield Check(source, number, "import", found[1])


def document_checks(path: Path):
    source, text, written = path.relative_to(ROOT).as_posix(), path.read_text(), []
    for language, start, lines in fenced_blocks(text):
        if language in SHELL_LANGUAGES:
            yield from shell_checks(source, logical_lines(enumerate(lines, start)),
                                    written)
        elif language == "python":
            yield from python_checks(source, start, lines)
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    for module in sorted(set(re.findall(r"python -m ([\w.]*\w)", prose))):
        yield Check(source, 0, "module", module)


def makefile_recipes() -> list[tuple[int, str]]:
    """(line number, recipe line) of the Makefile, continuations joined, variables expanded."""
    lines = MAKEFILE.read_text().splitlines()
    joined = logical_lines((n, line) for n, line in enumerate(lines, 1) if line.startswith("\t"))
    expand = {"$(PY)": "python", "$(PYTHON)": "python3", "$(VENV)": ".venv"}
    return [(n, re.sub(r"\$\(\w+\)", lambda m: expand.get(m[0], m[0]), t)) for n, t in joined]


def makefile_targets() -> set[str]:
    return set(re.findall(r"^([\w.-]+):", MAKEFILE.read_text(), flags=re.M))


CHECKS = [c for path in DOCS for c in document_checks(path)] + list(
    shell_checks("Makefile", makefile_recipes(), []))


def params(kinds):
    return [pytest.param(c, id=c.key[:120]) for c in CHECKS if c.kind in kinds]


CHECKER = r'''
import argparse, contextlib, importlib, importlib.util, io, json, runpy, sys, warnings

PROJECT = set(sys.argv[1].split(","))

class Parsed(Exception):
    """Raised once a command's arguments are parsed: nothing after runs."""

parse_args = argparse.ArgumentParser.parse_args

def parse_and_stop(self, args=None, namespace=None):
    parse_args(self, args, namespace)
    raise Parsed

argparse.ArgumentParser.parse_args = parse_and_stop

def importable(module):
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:
        return False

def check(job):
    module = job["module"]
    if not importable(module):
        return f"no module named {module}"
    if job["kind"] == "import":
        imported = importlib.import_module(module)
        missing = [n for n in job["args"] if not hasattr(imported, n)
                   and not importable(f"{module}.{n}")]
        return f"{module} has no {', '.join(missing)}" if missing else None
    if job["kind"] == "module" or module.split(".")[0] not in PROJECT:
        return None
    sys.argv, err = [module, *job["args"]], io.StringIO()
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            runpy.run_module(module, run_name="__main__", alter_sys=True)
    except Parsed:
        return None
    except SystemExit as stop:
        if stop.code in (0, None) and {"-h", "--help"} & set(job["args"]):
            return None
        return f"its argument parser refused {job['args']}: {err.getvalue().strip()[-600:]}"
    return "it ran to the end without parsing its arguments"

warnings.simplefilter("ignore")
results = []
for job in json.load(sys.stdin):
    try:
        results.append(check(job))
    except BaseException as error:
        results.append(f"{type(error).__name__}: {error}")
print(json.dumps(results), file=sys.__stdout__)
'''


@pytest.fixture(scope="module")
def module_results() -> dict[str, str | None]:
    """Error (or None) per check key of every module check, from one subprocess."""
    jobs = [c for c in CHECKS if c.kind in ("command", "import", "module")]
    env = {**os.environ, "JAX_PLATFORMS": "cpu",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-c", CHECKER, ",".join(sorted(PROJECT_PACKAGES))], cwd=ROOT, env=env,
        input=json.dumps([{"kind": c.kind, "module": c.module, "args": list(c.args)}
                          for c in jobs]),
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"the checker failed: {done.stderr[-2000:]}"
    return dict(zip([c.key for c in jobs], json.loads(done.stdout.splitlines()[-1])))


@pytest.mark.parametrize("check", params({"command", "import", "module"}))
def test_module_commands_parse(check: Check, module_results):
    assert module_results[check.key] is None, f"{check.key}: {module_results[check.key]}"
    missing = [p for p in check.reads if not p.startswith("../shared/") or SHARED.is_dir()
               if not (ROOT / p).exists()]
    assert not missing, f"{check.key}: these paths do not exist: {missing}"


@pytest.mark.parametrize("check", params({"make"}))
def test_make_targets_exist(check: Check):
    unknown = sorted(set(check.args) - makefile_targets())
    assert not unknown, f"{check.key}: the Makefile has no target {unknown}"


def test_quick_start_shows_the_makefile_commands():
    """The README's quick start is make install / run / test, with the test and run recipes
    written out exactly as the Makefile runs them."""
    readme = (ROOT / "README.md").read_text()
    quick = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    assert re.findall(r"^make (\w+)", quick, flags=re.M)[:3] == ["install", "run", "test"], \
        "the quick start's first three commands must be make install, make run, make test"
    recipes = dict(re.findall(r"^(\w+):.*\n\t(.+)", MAKEFILE.read_text(), flags=re.M))
    for target in ("run", "test"):
        command = recipes[target].replace("$(PY)", ".venv/bin/python")
        assert command in quick, f"the quick start must show `make {target}` as: {command}"


def test_readme_is_a_guide():
    lines = len((ROOT / "README.md").read_text().splitlines())
    assert lines <= README_MAX_LINES, \
        f"README.md has {lines} lines; keep it under {README_MAX_LINES}, details go to docs/"
    linked = set(re.findall(r"\]\((docs/[\w.-]+\.md)", (ROOT / "README.md").read_text()))
    unlinked = sorted({p.relative_to(ROOT).as_posix() for p in DOCS[1:]} - linked)
    assert not unlinked, f"README.md does not link {unlinked}"


def heading_anchors(path: Path) -> set[str]:
    """GitHub's anchors of a Markdown file's headings."""
    headings = re.findall(r"^#+ (.+)$", re.sub(r"```.*?```", "", path.read_text(), flags=re.S),
                          flags=re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in headings}


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_reach_files_and_headings(doc: Path):
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
        if re.match(r"\w+://", target):
            continue
        file, _, anchor = target.partition("#")
        path = (doc.parent / file).resolve() if file else doc
        if not path.exists() or anchor and path.suffix == ".md" \
                and anchor not in heading_anchors(path):
            broken.append(target)
    assert not broken, f"{doc.name}: broken links {broken}"
