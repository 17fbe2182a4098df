"""Named errors: every failure a user can cause says what went wrong and what to change."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .results import SolveStats


class RffqmError(Exception):
    """Base class of every error raised on purpose by rffqm_nlp."""


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (runs of whitespace as one space); the name of its
    type when it has no message."""
    return " ".join(str(exc).split()) or type(exc).__name__


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

    ``stats`` is the design solve's :class:`~rffqm_nlp.results.SolveStats` (None for the
    other solves, e.g. the side-length NLP, whose message says the status and iterations).
    ``best_iterate`` is the feasible point with the smallest objective the solver visited
    (for the simultaneous design NLP, an iterate's boundary data re-marched; None when it
    visited none or does not report iterates); it can warm-start a new solve.
    """

    def __init__(
        self, message: str, status: str = "", stats: "SolveStats | None" = None,
        last_iterate: Any = None, best_iterate: Any = None,
    ):
        super().__init__(message)
        self.status = status
        self.stats = stats
        self.last_iterate = last_iterate
        self.best_iterate = best_iterate


def raise_for_ipopt(status: str, iterations: int, what: str, infeasible_hint: str,
                    failed_hint: str, stats: "SolveStats | None" = None,
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
