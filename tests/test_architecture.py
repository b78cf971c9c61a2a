"""The layering of the library packages, read from their source with `ast` (nothing imported).

- No import circle among the modules of `jaxgrid/`, `ars/` and `baselines/`, counting the
  imports inside functions too.
- No command-line code in them (`def main`, `if __name__ == "__main__"`, argparse): commands
  live in `experiments/`.
- `ars/` imports nothing from `jaxgrid/`.
- The readers (`jaxgrid.io`) stand on the floor of what they build and return: the case
  tables (`jaxgrid.case`), the DYR record types (`jaxgrid.records`) and the shared
  input-check helpers (`jaxgrid.checks`), which themselves import nothing higher. Settings,
  models, simulation and studies sit above them; a reader of study settings (the PNNL JSON)
  belongs to `jaxgrid.study`.
- Nothing `jaxgrid.models` imports, directly or through other modules, is a reader: the
  models know the DYR record type, not the parser.
"""
from __future__ import annotations

import ast
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("jaxgrid", "ars", "baselines")
READER_FLOOR = ("jaxgrid.case", "jaxgrid.checks", "jaxgrid.records")


def module_name(path: Path) -> str:
    """`jaxgrid/io/raw.py` -> `jaxgrid.io.raw`; a package's `__init__.py` -> the package."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def library_modules() -> dict[str, ast.Module]:
    """Every module of the library packages: name -> parsed source."""
    return {module_name(p): ast.parse(p.read_text(), str(p))
            for package in LIBRARY for p in sorted((ROOT / package).rglob("*.py"))}


def imported_modules(name: str, tree: ast.Module, known: set[str]) -> set[str]:
    """The library modules `name` imports anywhere in its source: `from P import x` counts
    as `P.x` where that is a module, else as `P`."""
    package = name if (ROOT / name.replace(".", "/")).is_dir() else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.update(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                         for a in node.names)
    return {m for m in found if m in known and m != name}


def import_graph() -> dict[str, set[str]]:
    """Library module -> the library modules it imports."""
    modules = library_modules()
    return {name: imported_modules(name, tree, set(modules)) for name, tree in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle as a list of modules (first == last), or None (depth-first search)."""
    state: dict[str, str] = {}  # "open" while on the current path, "done" after

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = "open"
        path = path + [node]
        for succ in sorted(graph[node]):
            if state.get(succ) == "open":
                return path[path.index(succ):] + [succ]
            if succ not in state and (cycle := visit(succ, path)):
                return cycle
        state[node] = "done"
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start, [])):
            return cycle
    return None


def in_package(module: str, package: str) -> bool:
    """Whether `module` is `package` or one of its modules."""
    return module == package or module.startswith(package + ".")


def reachable(graph: dict[str, set[str]], starts) -> set[str]:
    """The modules `starts` import directly or through others, `starts` included."""
    seen, todo = set(), list(starts)
    while todo:
        if (module := todo.pop()) not in seen:
            seen.add(module)
            todo.extend(graph[module])
    return seen


def imports_out_of(graph: dict[str, set[str]], modules, allowed) -> list[str]:
    """"A -> B" for each import B of a module A of `modules` that `allowed(B)` rejects."""
    return sorted(f"{a} -> {b}" for a in modules for b in graph[a] if not allowed(b))


def on_reader_floor(module: str) -> bool:
    """A reader, or a module readers may import (see the module docstring)."""
    return in_package(module, "jaxgrid.io") or module in READER_FLOOR


def reader_breaks(graph: dict[str, set[str]]) -> list[str]:
    """Imports that leave the reader floor, made by a reader or by a floor module."""
    return imports_out_of(graph, [m for m in graph if on_reader_floor(m)], on_reader_floor)


def model_breaks(graph: dict[str, set[str]]) -> list[str]:
    """Imports of a reader by a module that `jaxgrid.models` reaches."""
    models = reachable(graph, [m for m in graph if in_package(m, "jaxgrid.models")])
    return imports_out_of(graph, models, lambda m: not in_package(m, "jaxgrid.io"))


def command_line_code(tree: ast.Module) -> list[str]:
    """What makes a module a command: `def main`, `if __name__ == "__main__"`, argparse."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "main":
            found.append(f"def main (line {node.lineno})")
        elif (isinstance(node, ast.Compare) and isinstance(node.left, ast.Name)
              and node.left.id == "__name__"):
            found.append(f"if __name__ == ... (line {node.lineno})")
        elif isinstance(node, (ast.Import, ast.ImportFrom)) and "argparse" in (
                [a.name for a in node.names] + [getattr(node, "module", None)]):
            found.append(f"import argparse (line {node.lineno})")
    return found


def test_find_cycle_finds_a_circle_and_accepts_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_layer_rules_catch_the_old_io_knot():
    old = {"jaxgrid.io.pnnl": {"jaxgrid.checks", "jaxgrid.env"}, "jaxgrid.checks": set(),
           "jaxgrid.env": {"jaxgrid.models.base"}, "jaxgrid.models.base": {"jaxgrid.io.dyr"},
           "jaxgrid.io.dyr": set()}
    assert reader_breaks(old) == ["jaxgrid.io.pnnl -> jaxgrid.env"]
    assert model_breaks(old) == ["jaxgrid.models.base -> jaxgrid.io.dyr"]


def test_the_graph_sees_imports_inside_functions_and_from_package_imports():
    graph = import_graph()
    assert "jaxgrid.case" in graph["jaxgrid.powerflow"]
    assert "jaxgrid.network" in graph["jaxgrid.simulate"], "`from jaxgrid import network`"


def test_no_import_circle_in_the_library():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])


def test_no_command_line_code_in_the_library():
    found = {name: where for name, tree in library_modules().items()
             if (where := command_line_code(tree))}
    assert not found, f"command-line code belongs in experiments/: {found}"


def test_ars_imports_nothing_from_jaxgrid():
    graph = import_graph()
    found = {name: sorted(m for m in deps if m.split(".")[0] == "jaxgrid")
             for name, deps in graph.items() if name.split(".")[0] == "ars"}
    found = {name: deps for name, deps in found.items() if deps}
    assert not found, f"ars/ must not know grids: {found}"


def test_readers_import_only_the_case_and_record_types():
    found = reader_breaks(import_graph())
    assert not found, ("jaxgrid.io may import only jaxgrid.io, " + ", ".join(READER_FLOOR)
                       + "; found: " + "; ".join(found))


def test_models_do_not_import_the_readers():
    found = model_breaks(import_graph())
    assert not found, "jaxgrid.models must not import jaxgrid.io; found: " + "; ".join(found)


COMMANDS_TOP_LEVEL = 12  # files at experiments/'s top: the commands a user runs first


def experiment_modules() -> dict[str, ast.Module]:
    """Every module under experiments/: name -> parsed source."""
    return {module_name(p): ast.parse(p.read_text(), str(p))
            for p in sorted((ROOT / "experiments").rglob("*.py"))}


def is_command(tree: ast.Module) -> bool:
    """A command module: it has `def main` or `if __name__ == "__main__"` (argparse alone,
    as in the flags the commands share, does not make one)."""
    return any(not found.startswith("import argparse") for found in command_line_code(tree))


def test_no_module_imports_a_command():
    """What two commands share lives in a module that is not a command (experiments/common,
    the *_files and profiling helpers), so a command's flags and output stay its own. A
    package's __main__.py is the entry of its command and may import it."""
    modules = experiment_modules()
    commands = {name for name, tree in modules.items() if is_command(tree)}
    known = set(modules)
    found = {name: sorted(imported_modules(name, tree, known) & commands)
             for name, tree in modules.items() if not name.endswith("__main__")}
    found = {name: deps for name, deps in found.items() if deps}
    assert not found, f"modules importing a command module: {found}"
    assert {"experiments.train", "experiments.evaluate"} <= commands


def test_the_top_of_experiments_holds_the_commands_a_user_runs_first():
    top = sorted(p.name for p in (ROOT / "experiments").glob("*.py"))
    assert len(top) <= COMMANDS_TOP_LEVEL, f"experiments/ top level: {top}"
