"""The folders are the layers (docs/architecture.md): no import circle, at most two imports
that run back up a floor (each explained where it stands), and small modules."""

from __future__ import annotations

import ast
from pathlib import Path

import rffqm_nlp as rq

PACKAGE = Path(rq.__file__).parent
#: The floors, lowest first: a module may import from its own floor and those below.
FLOORS = ["ground", "model", "targets", "contact", "design", "mechanics", "io", "make", "show",
          "sweeps", "cli"]
GROUND = {"errors", "files", "memory", "ipopt_options", "_version"}
#: Imports that run back up a floor: (importer, imported), each with a comment where it is.
UPWARD = {("design.results", "show.view")}
#: Longest library module (lines).
MAX_LINES = 600


def modules() -> dict[str, Path]:
    """Every module of the package by its dotted name below rffqm_nlp; a subpackage's
    __init__ by the subpackage's name (the package's own __init__, the public API that
    gathers every floor, is left out)."""
    found = {}
    for p in PACKAGE.rglob("*.py"):
        parts = p.relative_to(PACKAGE).with_suffix("").parts
        if p.name == "__init__.py":
            parts = parts[:-1]
        if parts:
            found[".".join(parts)] = p
    return found


def floor(name: str) -> int:
    top = name.split(".")[0]
    return 0 if top in GROUND else FLOORS.index(top)


def type_hint_blocks(tree: ast.Module) -> set[int]:
    """ids of the nodes under ``if TYPE_CHECKING:``: imports for type hints only, which never
    run (a module may name the type of what calls it)."""
    return {id(inner) for node in ast.walk(tree)
            if isinstance(node, ast.If) and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING"
            for stmt in node.body for inner in ast.walk(stmt)}


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in it (functions included), but
    for type hints only."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    tree = ast.parse(path.read_text())
    hints = type_hint_blocks(tree)
    for node in ast.walk(tree):
        if id(node) in hints:
            continue
        if not isinstance(node, ast.ImportFrom) or not node.level:
            continue
        base = package[:len(package) - node.level + 1] + (node.module.split(".")
                                                        if node.module else [])
        for alias in node.names:
            for candidate in (".".join(base + [alias.name]), ".".join(base)):
                if candidate in known:
                    found.add(candidate)
                    break
    return found - {name}


def graph() -> dict[str, set[str]]:
    mods = modules()
    return {name: imports(name, path, set(mods)) for name, path in mods.items()}


def circles(edges: dict[str, set[str]]) -> set[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: set[frozenset[str]] = set()

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in edges[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = set()
            while True:
                member = stack.pop()
                component.add(member)
                if member == node:
                    break
            if len(component) > 1:
                found.add(frozenset(component))

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return found


def test_no_import_circle():
    """No circle but through the imports up a floor (each made on use, in a function)."""
    edges = {a: {b for b in targets if (a, b) not in UPWARD} for a, targets in graph().items()}
    assert circles(edges) == set()
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == {
        frozenset("abc")}                                  # the check itself finds one


def test_imports_run_down_the_floors():
    upward = {(a, b) for a, targets in graph().items() for b in targets
              if floor(b) > floor(a)}
    assert upward == UPWARD and len(UPWARD) <= 2


def test_modules_are_small():
    lines = {name: len(path.read_text().splitlines()) for name, path in modules().items()}
    assert {name for name, count in lines.items() if count > MAX_LINES} == set()
