"""The documentation: the tutorial's Python blocks run, in order, in one namespace (as
scikit-fem runs its examples); every relative link between the pages reaches a file; the
solvers page stays a concise design page. The site itself is built by ``mkdocs build
--strict`` in .ci/run."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PACKAGE = ROOT / "rffqm_nlp"

#: A fenced block of Python: its body.
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
#: A Markdown link or image target: ``[text](target)``.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
#: Any fenced block, whose links are code, not links.
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def python_blocks(page: Path) -> list[str]:
    """The bodies of the ```python blocks of ``page``, in order."""
    return PYTHON_BLOCK.findall(page.read_text())


def test_tutorial_runs(tmp_path, monkeypatch):
    """Every Python block of docs/tutorial.md, in order, in one namespace, in an empty
    folder; a block that raises fails the test and names itself."""
    blocks = python_blocks(DOCS / "tutorial.md")
    assert len(blocks) >= 10
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "tutorial"}
    for number, block in enumerate(blocks, 1):
        code = compile(block, f"docs/tutorial.md, block {number}", "exec")
        exec(code, namespace)  # noqa: S102 - the tutorial is this repository's own text


def reference_page(target: str) -> bool:
    """Whether ``reference/<dotted path>.md`` is a page the site generates: one per public
    module or package of rffqm_nlp (docs/reference_tools/gen_pages.py)."""
    parts = Path(target).with_suffix("").parts[1:]
    if not parts or parts[0] != "rffqm_nlp" or any(p.startswith("_") for p in parts[1:]):
        return False
    path = ROOT.joinpath(*parts)
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def relative_links(page: Path) -> list[str]:
    """The link targets of ``page`` that are relative paths (no scheme, no bare anchor),
    outside code blocks, without their anchors."""
    text = FENCE.sub("", page.read_text())
    targets = []
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        targets.append(target.split("#", 1)[0])
    return targets


PAGES = sorted(DOCS.rglob("*.md"))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(DOCS)))
def test_relative_links_reach_files(page):
    """A relative link reaches a file inside docs/ (the site holds only those) or a
    generated API page."""
    missing = []
    for target in relative_links(page):
        path = (page.parent / target).resolve()
        inside = path.is_relative_to(DOCS.resolve())
        relative = path.relative_to(DOCS.resolve()).as_posix() if inside else ""
        if not inside or not (path.exists() or reference_page(relative)):
            missing.append(target)
    assert missing == []


def test_solvers_page_is_concise():
    assert len((DOCS / "solvers.md").read_text().splitlines()) <= 300
