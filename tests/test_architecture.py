"""The layering of the library packages, read from their source with `ast` (nothing imported).

- No import circle among the modules of `jaxgrid/`, `ars/` and `baselines/`, counting the
  imports inside functions too.
- No command-line code in them (`def main`, `if __name__ == "__main__"`, argparse): commands
  live in `experiments/`.
- `ars/` imports nothing from `jaxgrid/`.
"""
from __future__ import annotations

import ast
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("jaxgrid", "ars", "baselines")


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
