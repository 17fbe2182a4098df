"""One design's solve: the task of every run (:func:`solve_design`), on a Dask worker or in
this process, with one thread in every BLAS and OpenMP pool (:func:`one_thread`)."""

from __future__ import annotations

import functools
import socket
import time
from collections.abc import Mapping
from contextlib import AbstractContextManager
from typing import Any

from threadpoolctl import OpenBLASController, register, threadpool_limits

from ..design import from_config as problem_from_config
from ..design.results import SolveStats
from ..errors import InfeasibleDesign, SolverFailed, one_line
from .outcomes import state_values


def solve_design(payload: Mapping[str, Any]) -> dict[str, Any]:
    """Solve one design: the task of every run, on a Dask worker or in this process.

    ``payload`` is :meth:`Design.payload`. Returns {"row": outcome columns, "result":
    DesignResult.to_dict() or None}. Never raises an :class:`Exception`: an infeasible
    design gives status "infeasible", a solver failure "failed" (with IPOPT's status), any
    other exception "error" with its type and message as the reason.

    The solve runs with one thread in every BLAS and OpenMP pool (:func:`one_thread`):
    wherever a design runs it then gives the same numbers, and workers sharing a machine do
    not oversubscribe it.
    """
    t0 = time.perf_counter()
    config = payload["config"]
    row: dict[str, Any] = {"worker": _worker_name(), "host": socket.gethostname()}
    result = None
    try:
        problem, options = problem_from_config(config, trust=bool(payload.get("trust")))
        with one_thread():
            result = problem.solve(options)
    except InfeasibleDesign as exc:
        row.update(status="infeasible", solver_status="Infeasible_Problem_Detected",
                   reason=one_line(exc))
    except SolverFailed as exc:
        row.update(status="failed", solver_status=exc.status, reason=one_line(exc),
                   **_stat_columns(exc.stats))
    except Exception as exc:  # a task turns every failure into a row
        row.update(status="error", solver_status="",
                   reason=f"{type(exc).__name__}: {one_line(exc)}")
    else:
        multistart = result.stats.multistart or {}
        row.update(status="solved", solver_status=result.stats.status, reason="",
                   **result.fit.to_dict(), **state_values(result),
                   **_stat_columns(result.stats),
                   start=multistart.get("chosen", 0))
    row["time"] = time.perf_counter() - t0
    return {"row": row, "result": None if result is None else result.to_dict()}


def _stat_columns(stats: SolveStats | None) -> dict[str, Any]:
    if stats is None:
        return {}
    return {"iterations": stats.iterations, "build_time": stats.build_time,
            "solve_time": stats.solve_time}


def one_thread() -> AbstractContextManager:
    """Limit every BLAS and OpenMP thread pool of this process to one thread (threadpoolctl),
    CasADi's own OpenBLAS under MUMPS included: threadpoolctl does not know that library by
    name, so it is registered here, and IPOPT's plugin is loaded first (``has_nlpsol`` loads
    it, silently when it already is) so that the library is found.

    The thread count of that OpenBLAS changes IPOPT's path in the last digits (iterations
    and fit, docs/decisions/large-patterns.md), so without the limit a serial run would not
    reproduce a cluster run's table.
    """
    import casadi

    _register_casadi_openblas()
    casadi.has_nlpsol("ipopt")
    return threadpool_limits(limits=1)


@functools.cache
def _register_casadi_openblas() -> None:
    class CasadiOpenBLAS(OpenBLASController):
        """The OpenBLAS that CasADi ships for its MUMPS (libcasadi-tp-openblas)."""

        filename_prefixes = ("libcasadi-tp-openblas",)

    register(CasadiOpenBLAS)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "in-process"
