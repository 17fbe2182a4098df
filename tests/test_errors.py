"""The one message sanitizer (errors.safe_text): what rffqm_nlp says is one line, shows no
character that acts on a terminal, and cuts long words and long messages (issue 41)."""

from __future__ import annotations

import unicodedata

from hypothesis import given, settings
from hypothesis import strategies as st

import rffqm_nlp as rq
from rffqm_nlp.errors import MAX_MESSAGE, MAX_WORD, one_line, safe_text


def unsafe(text: str) -> list[str]:
    """The characters of ``text`` that a terminal acts on or that reorder text."""
    return [c for c in text if unicodedata.category(c) in ("Cc", "Cf", "Cs", "Zl", "Zp")]


@settings(max_examples=300, derandomize=True, deadline=None)
@given(st.text(alphabet=st.characters(exclude_categories=()), max_size=3000))
def test_safe_text_is_one_safe_bounded_line(text):
    shown = safe_text(text)
    assert not unsafe(shown)
    assert "\n" not in shown and "\r" not in shown
    assert len(shown) <= MAX_MESSAGE
    assert all(len(word) <= MAX_WORD + 30 for word in shown.split())


def test_control_characters_are_escaped_not_dropped():
    assert safe_text("a\x1b[31mb\x00c\x9bd\u202ee") == "a\\x1b[31mb\\x00c\\x9bd\\u202ee"
    assert safe_text("two\nlines\t and  spaces\u2028") == "two lines and spaces"
    assert safe_text("bidi\u061c zero\u200b lone\udcff") == "bidi\\u061c zero\\u200b lone\\udcff"


def test_a_long_path_keeps_its_start_and_its_file_name():
    path = "/home/me/" + "deep/" * 100 + "design.toml"
    shown = safe_text(f"no such design file: {path}")
    assert shown.startswith("no such design file: /home/me/deep/")
    assert shown.endswith("/design.toml") and f"({len(path)} characters)" in shown


def test_a_long_message_says_how_long_it_was():
    text = "word " * 1000
    shown = safe_text(text)
    assert shown.endswith(f"(cut, {len(text.strip())} characters)")


def test_every_library_error_is_sanitized_and_keeps_its_fields():
    exc = rq.MarchingError("first", (2, 3), detail="\x1b]0;title\x07")
    assert exc.check == "first" and exc.panel == (2, 3)
    assert not unsafe(str(exc)) and "\\x1b]0;title\\x07" in str(exc)
    for error in (rq.InputError, rq.SurfaceError, rq.InfeasibleDesign):
        assert str(error("line one\nline two\x07")) == "line one line two\\x07"
    assert rq.SolverFailed("x\x1b", status="s").status == "s"


def test_one_line_sanitizes_foreign_exceptions_too():
    assert one_line(ValueError("bad\x1b[2J\nvalue")) == "bad\\x1b[2J value"
    assert one_line(KeyError()) == "KeyError"
