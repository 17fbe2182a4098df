"""The folders are the layers (docs/architecture.md): no import circle, at most two imports
that run back up a floor (each explained where it stands), and small modules."""

from __future__ import annotations

import ast
from pathlib import Path

import rffqm_nlp as rq

PACKAGE = Path(rq.__file__).parent
#: The floors, lowest first: a module may import from its own floor and those below.
FLOORS = ["ground", "model", "targets", "contact", "design", "io", "show", "sweeps", "cli"]
GROUND = {"errors", "files", "memory", "ipopt_options", "_version"}
#: Imports that run back up a floor: (importer, imported), each with a comment where it is.
UPWARD = {("design.results", "show.view")}
#: Longest library module (lines).
MAX_LINES = 600
#: Modules still over MAX_LINES, to be split (issue "The house in rooms"); none may join.
OVERSIZE = {"design.solvers.levenberg_marquardt", "design.transcription", "design.problem",
            "design.results", "contact.collisions", "sweeps", "targets.surfaces",
            "targets.meshes", "model.marching", "cli", "files"}


def modules() -> dict[str, Path]:
    """Every module of the package by its dotted name below rffqm_nlp (no __init__)."""
    return {".".join(p.relative_to(PACKAGE).with_suffix("").parts): p
            for p in PACKAGE.rglob("*.py") if p.name != "__init__.py"}


def floor(name: str) -> int:
    top = name.split(".")[0]
    return 0 if top in GROUND else FLOORS.index(top)


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in it (functions included)."""
    package = name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
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


#: Import circles still to break (issue "The house in rooms"); none may join.
CIRCLES = {frozenset({"targets.surfaces", "targets.meshes"})}


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
    assert circles(edges) <= CIRCLES
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == {
        frozenset("abc")}                                  # the check itself finds one


def test_imports_run_down_the_floors():
    upward = {(a, b) for a, targets in graph().items() for b in targets
              if floor(b) > floor(a)}
    assert upward == UPWARD and len(UPWARD) <= 2


def test_modules_are_small():
    lines = {name: len(path.read_text().splitlines()) for name, path in modules().items()}
    over = {name for name, count in lines.items() if count > MAX_LINES}
    assert over <= OVERSIZE, over - OVERSIZE
