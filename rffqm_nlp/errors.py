"""Named errors: every failure a user can cause says what went wrong and what to change."""

from __future__ import annotations

import unicodedata
from typing import Any


#: Longest word (a run without spaces, e.g. a path) a message shows whole; a longer one
#: keeps its start and its end (a path's file name) around its length.
MAX_WORD = 120
#: Longest message: a longer one is cut and says how long it was.
MAX_MESSAGE = 1000
#: Unicode categories a message never shows as they are: controls (C0, C1, DEL: they can
#: move the cursor, recolour or clear a terminal), format characters (bidirectional and
#: zero-width marks, which reorder or hide text) and lone surrogates (from undecodable
#: file names, which a terminal cannot print).
_UNSAFE = ("Cc", "Cf", "Cs")


def safe_text(text: str) -> str:
    """``text`` fit for a user's terminal or a log line: on one line (runs of whitespace as
    one space), unsafe characters (:data:`_UNSAFE`) escaped as Python writes them (``\\x1b``),
    every word longer than :data:`MAX_WORD` cut in its middle, the whole cut at
    :data:`MAX_MESSAGE` characters. The one sanitizer of everything rffqm_nlp says: every
    :class:`RffqmError` message goes through it."""
    text = "".join(_escape(c) if unicodedata.category(c) in _UNSAFE and not c.isspace()
                   else c for c in str(text))
    words = [_cut_word(word) for word in text.split()]
    text = " ".join(words)
    if len(text) > MAX_MESSAGE:
        text = f"{text[:MAX_MESSAGE - 40]} ... (cut, {len(text)} characters)"
    return text


def _escape(char: str) -> str:
    code = ord(char)
    return (f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000
            else f"\\U{code:08x}")


def _cut_word(word: str) -> str:
    if len(word) <= MAX_WORD:
        return word
    keep = (MAX_WORD - 30) // 2
    return f"{word[:keep]}...({len(word)} characters)...{word[-keep:]}"


class RffqmError(Exception):
    """Base class of every error raised on purpose by rffqm_nlp; its message is made safe
    for a terminal by :func:`safe_text`."""

    def __init__(self, message: Any = "", *args: Any):
        super().__init__(safe_text(message), *args)


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` through :func:`safe_text` (one line, no control characters,
    long words cut); the name of its type when it has no message."""
    return safe_text(str(exc)) or type(exc).__name__


class InputError(RffqmError, ValueError):
    """Invalid input data (shape, value, option); the message names the offending item."""


class BoundaryDataError(InputError):
    """Invalid boundary data (eq:inputMarching) at one boundary vertex or side.

    ``vertex`` is the 1-based (i, j) of the vertex (or None for a side length),
    ``value`` the offending value.
    """

    def __init__(self, message: str, vertex: tuple[int, int] | None = None, value: Any = None):
        super().__init__(message)
        self.vertex = vertex
        self.value = value


class SurfaceError(InputError):
    """Invalid target surface: bad parameters, empty domain, a callable of the wrong shape."""


class MarchingError(RffqmError, ValueError):
    """No RFFQM pattern exists for the boundary data: a marching check failed.

    ``check`` is one of "first" (eq:firstCheck), "second" (eq:secondCheck) or "final"
    (eq:finalCheck); ``panel`` is the 1-based (i, j) of the first failing panel in
    marching order.
    """

    _WHAT = {
        "first": "2*pi - (alpha_a + alpha_b + alpha_c) is not in (0, pi) (eq:firstCheck)",
        "second": "|mu_abc| = 1, so no (beta_d, sigma_d) exists (eq:secondCheck)",
        "final": "a side length l_cd or l_bd is not positive (eq:finalCheck)",
    }

    def __init__(self, check: str, panel: tuple[int, int], detail: str = ""):
        if check not in self._WHAT:
            raise ValueError(f"unknown check {check!r}")
        self.check = check
        self.panel = (int(panel[0]), int(panel[1]))
        msg = f"{check} check failed at panel {self.panel}: {self._WHAT[check]}"
        if detail:
            msg += f"; {detail}"
        msg += ". Change the boundary angles or side lengths (or use lengths from side_length_lp)."
        super().__init__(msg)


class InfeasibleDesign(RffqmError):
    """The requested design has no solution (empty LP feasible set, unreachable constraints)."""


class SolverFailed(RffqmError):
    """IPOPT (or another solver) did not succeed; carries its status and the last iterate.

    ``stats`` is the design solve's :class:`~rffqm_nlp.design.results.SolveStats` (None for the
    other solves, e.g. the side-length NLP, whose message says the status and iterations).
    ``best_iterate`` is the feasible point with the smallest objective the solver visited
    (for the simultaneous design NLP, an iterate's boundary data re-marched; None when it
    visited none or does not report iterates); it can warm-start a new solve.
    """

    def __init__(
        self, message: str, status: str = "", stats: Any = None,
        last_iterate: Any = None, best_iterate: Any = None,
    ):
        super().__init__(message)
        self.status = status
        self.stats = stats
        self.last_iterate = last_iterate
        self.best_iterate = best_iterate


def raise_for_ipopt(status: str, iterations: int, what: str, infeasible_hint: str,
                    failed_hint: str, stats: Any = None,
                    last_iterate: Any = None, best_iterate: Any = None) -> None:
    """Raise the named error for an unsuccessful IPOPT solve of ``what``.

    IPOPT's "Infeasible_Problem_Detected" becomes :class:`InfeasibleDesign`; every other
    status :class:`SolverFailed` carrying it, the solver statistics, the last iterate and the
    best feasible one.
    """
    if status == "Infeasible_Problem_Detected":
        raise InfeasibleDesign(f"IPOPT status {status} in {what}: the constraints cannot all "
                               f"hold; {infeasible_hint}")
    raise SolverFailed(f"IPOPT did not solve {what}: status {status} after {iterations} "
                       f"iterations; {failed_hint}", status=status, stats=stats,
                       last_iterate=last_iterate, best_iterate=best_iterate)
