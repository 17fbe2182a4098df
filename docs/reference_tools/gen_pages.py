"""Writes the API reference pages at build time (mkdocs-gen-files): one page per module of
the package, found by walking rffqm_nlp/, so modules that move between folders need no edit
here. reference/SUMMARY.md is the reference's nav (mkdocs-literate-nav)."""

from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "rffqm_nlp"


def module_names() -> list[tuple[str, ...]]:
    """Dotted names of the public modules and packages, as tuples, packages first."""
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(part.startswith("_") for part in parts):
            continue
        names.append(parts)
    return sorted(names)


nav = mkdocs_gen_files.Nav()
for parts in module_names():
    page = Path(*parts).with_suffix(".md")
    nav[parts[1:] or parts] = page.as_posix()
    with mkdocs_gen_files.open(Path("reference", page), "w") as out:
        out.write(f"::: {'.'.join(parts)}\n")

with mkdocs_gen_files.open("reference/SUMMARY.md", "w") as out:
    out.writelines(nav.build_literate_nav())
