"""Inverse design (the paper's section "Discussion on the inverse problem", PAPER_NOTES s.8).

:class:`DesignProblem` states the problem declaratively: a target surface, a 2N x 2M
pattern whose coarse lattice r(i, j) = y^{(2i)(2j)} should match the target lattice, the
Miura mountain-valley assignment held fixed, the inline manufacturability constraints and the
loss. :meth:`DesignProblem.solve` transcribes it (:mod:`rffqm_nlp.transcription`), solves one
IPOPT NLP with exact derivatives (or, with ``solver="levenberg-marquardt"``, first marches
the design's least squares with :mod:`rffqm_nlp.reduced`), re-marches the answer with the
independent NumPy model and returns a :class:`~rffqm_nlp.results.DesignResult`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import casadi as ca
import numpy as np

from . import numpy_model, reduced, shape, surfaces, transcription
from .boundary import LAYOUTS, BoundaryData, miura_boundary
from .errors import (InfeasibleDesign, InputError, MarchingError, SolverFailed,
                     raise_for_ipopt)
from .files import read_toml
from .results import DesignResult

PI = np.pi
DEFAULT_WEIGHTS = {"position": 1.0, "forms": 0.1, "regularization": 0.1, "smoothness": 0.0}
TRANSCRIPTIONS = ("sequential", "simultaneous")
SOLVERS = ("ipopt", "levenberg-marquardt")
HESSIANS = ("gauss-newton", "exact", "limited-memory")
GROUPS = ("angles", "lengths", "omega")
#: IPOPT options that a DesignProblem field (or solve's ``verbose``) sets, and that field.
IPOPT_FIELDS = {"max_iter": "max_iter", "tol": "tol", "max_wall_time": "time_limit",
                "hessian_approximation": "hessian", "print_level": "solve(verbose=...)"}
#: Largest sequential pattern (panels) whose NLP is expanded to SX; see DesignProblem._expand.
SX_MAX_PANELS = 144
#: IPOPT's barrier from a cold start. The loss is O(0.1) against hundreds of log-barrier
#: terms, so IPOPT's default (monotone from mu = 0.1) first solves a different problem
#: (angles near pi/2, sides ~8x the spacing): the simultaneous transcription loses
#: feasibility there and never recovers, the sequential one needs 1.5-3x the iterations.
#: Measured at 8 x 8 and 20 x 20 on the bundled targets: "adaptive" is fastest for the
#: simultaneous NLP (20-36 iterations); for the sequential one it is also fast but found a
#: worse local minimum of the 8 x 8 sphere cap, which mu_init = 1e-3 does not.
COLD_BARRIER = {"sequential": {"ipopt.mu_init": 1e-3},
                "simultaneous": {"ipopt.mu_strategy": "adaptive"}}
#: Most iterations of the damped Gauss-Newton Hessian before the exact one takes over (see
#: DesignProblem._phases). The 20 x 20 sphere cap reaches 0.9% after 23-26.
GAUSS_NEWTON_ITERATIONS = 30
#: IPOPT statuses after which the exact Hessian does not take over from Gauss-Newton (nor
#: does it after stop_rms is reached)
FINAL_STATUSES = ("Solve_Succeeded", "Maximum_WallTime_Exceeded")


@dataclass(frozen=True)
class Start:
    """The Miura start and the target lattice placed to match it."""

    boundary: BoundaryData
    omega: float
    target_points: np.ndarray
    spacing: float
    rotation: np.ndarray
    translation: np.ndarray


@dataclass(frozen=True)
class DesignProblem:
    """Which RFFQM pattern, perturbed from a Miura-ori, folds into ``target``?

    Parameters (all with defaults chosen so designs are manufacturable):

    * ``panels``: (2N, 2M) panels, both even; the coarse lattice is (N+1) x (M+1);
    * ``layout``, ``alpha0``, ``omega0``: the starting Miura-ori (PAPER_NOTES s.6); its side
      lengths are chosen so that its coarse lattice at ``omega0`` has the target lattice's
      mean spacings. The default layout "zigzag_i" (zig-zag along the target's u) needed
      15-90 iterations on the bundled targets at 20 x 20 panels where "zigzag_j" needed
      190-1000+ (studies/inverse_examples.py);
    * ``min_angle``: every sector angle in [min_angle, pi - min_angle] (this also keeps the
      first check, eq:firstCheck, away from its limits);
    * ``mu_margin``: |mu_abc| of every panel stays on its starting side of 1 by this margin
      (second check, eq:secondCheck, so sigma_d never flips), and the multiplier of every
      boundary vertex that vanishes where its sigma leaves MV(alpha, beta) keeps its sign,
      at least this large (:func:`rffqm_nlp.vertex.mv_multiplier`): the MV pattern of the
      Miura is held at every crease;
    * ``min_length``: every side >= min_length times the mean side (replaces the LP);
    * ``omega_bounds``: bounds of the fold parameter;
    * ``fix``: groups held at their start, among "angles", "lengths", "omega";
    * ``weights``: loss weights, "forms" (the paper's fundamental-form loss) and "position"
      (lattice positions after a rigid alignment that is part of the NLP), see
      :func:`rffqm_nlp.transcription.loss_residuals`; "regularization" (Tikhonov, towards
      the Miura start) and "smoothness" (second differences of the boundary perturbation
      along each edge, :func:`rffqm_nlp.transcription.smoothness_residuals`; default 0);
      missing keys count as 0;
    * ``continuation``: multipliers of the regularization weight for successive solves, each
      warm-started from the last (e.g. (10, 1): first stay close to the Miura, then let the
      fit improve; the default is one solve);
    * ``transcription``: "simultaneous" (the default: all pattern and kinematic quantities
      as variables, the marching equations as sparse equality constraints) or "sequential"
      (the marching graph as a function of the boundary data). Both state the same NLP; on
      the bundled targets at 8-16 panels a side, both layouts, the simultaneous one solved
      18 of 18 (the sequential one 16), 1.5-6.8x faster
      (studies/results/compare_transcriptions.md), and it converges at 40 x 40;
      ``hessian``: "exact" (the default), "gauss-newton" or "limited-memory" (L-BFGS).
      "gauss-newton" is J^T J of the residuals plus ``damping`` times a diagonal
      Levenberg-Marquardt term (:func:`rffqm_nlp.transcription.gauss_newton_hessian`),
      for at most :data:`GAUSS_NEWTON_ITERATIONS` iterations, after which the exact
      Hessian takes over from the last iterate and its multipliers unless ``stop_rms`` was
      reached or IPOPT converged (:meth:`_phases`). It factorises the KKT system once per
      iteration instead of about twice: to stop_rms 0.9%, the bundled targets (whose files
      choose it) took 0.7-1.9 s at 20 x 20 panels against 2.6-4.2 s with the exact
      Hessian, 3.5-7.7 s at 40 x 40 against 19-32 s, and 42-85 s at 100 x 100 for two of
      them (studies/results/solve_cost.md). The 100 x 100 sphere cap did not reach 0.9%
      with it (its objective fell from 5.0 to 0.15 in 21 iterations, then rose, its
      iterates violating the marching equations by 0.01-0.02) where the exact Hessian
      takes 392 s, so the exact Hessian stays IPOPT's default;
    * ``solver``: "ipopt" (the default) or "levenberg-marquardt": Levenberg-Marquardt on
      the marching manifold (:mod:`rffqm_nlp.reduced`, simultaneous transcription only).
      Its variables are the boundary data, omega and the alignment; every iterate is
      re-marched, so every iterate is an admissible design, and the inequalities enter
      each step linearised (a small QP). It stops at ``stop_rms``; when it no longer
      lowers the loss by 0.01% a step, IPOPT (with ``hessian``) finishes from its point.
      The bundled target files choose it: to their 0.9%, the three targets took 8, 2 and 2
      iterations and 0.4-0.7 s at 20 x 20 panels, and the sphere cap 6 iterations and
      39 s at 100 x 100, where IPOPT took 392 s (studies/results/solve_cost.md);
    * ``damping``: weight of the Levenberg-Marquardt term of "gauss-newton" (default 0.03;
      without it the 20 x 20 sphere cap had not reached 0.9% after 380 iterations, with
      0.02-0.04 it took 23-26, the hyperboloid and the quarter vase 4-5), and the first
      damping of solver "levenberg-marquardt" (then adapted every step; must be > 0);
    * ``max_iter``, ``tol``, ``time_limit`` (seconds): IPOPT's limits;
    * ``stop_rms``: stop as soon as the aligned coarse lattice is within this RMS distance of
      the target lattice (a fraction of the target's diameter) with every constraint holding
      (status "Fit_Reached"); None (the default) runs IPOPT to its tolerance. With the
      simultaneous transcription the designs judged are the iterates' boundary data
      re-marched (see :class:`_IterationLog`): with the exact Hessian the bundled 20 x 20
      targets stop after 22, 11 and 11 iterations instead of 40, 36 and 31;
    * ``barrier_init``: IPOPT's initial barrier parameter with small bound pushes (default
      None: :data:`COLD_BARRIER` from a cold start, 1e-6 from a warm start);
    * ``ipopt_options``: further IPOPT options by name (e.g. {"bound_mult_init_val": 0.01},
      or "output_file" with "file_print_level"), applied last; checked against IPOPT when
      the problem is made. Options that a field above sets (:data:`IPOPT_FIELDS`) are
      refused. Which start options pay off depends on the target and size
      (studies/results/ipopt_start.md), so the defaults stay IPOPT's.
    """

    target: surfaces.Surface
    panels: tuple[int, int] = (20, 20)
    layout: str = "zigzag_i"
    alpha0: float = 1.1
    omega0: float = 2.0
    min_angle: float = 0.15
    mu_margin: float = 0.02
    min_length: float = 0.2
    omega_bounds: tuple[float, float] = (0.05, PI - 0.05)
    fix: tuple[str, ...] = ()
    weights: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_WEIGHTS))
    continuation: tuple[float, ...] = (1.0,)
    transcription: str = "simultaneous"
    solver: str = "ipopt"
    hessian: str = "exact"
    damping: float = 0.03
    max_iter: int = 1000
    tol: float = 1e-6
    time_limit: float | None = None
    stop_rms: float | None = None
    barrier_init: float | None = None
    ipopt_options: dict[str, str | int | float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.target, surfaces.Surface):
            raise InputError("target must be a surface from rq.surfaces (get, Custom, load), "
                             f"got {type(self.target).__name__}")
        panels = tuple(int(p) for p in self.panels)
        if len(panels) != 2 or any(p < 4 or p % 2 for p in panels):
            raise InputError(f"panels must be two even numbers >= 4 (2N, 2M), got {self.panels}")
        object.__setattr__(self, "panels", panels)
        object.__setattr__(self, "fix", tuple(self.fix))
        object.__setattr__(self, "continuation", tuple(float(c) for c in self.continuation))
        if not self.continuation or any(not c > 0 for c in self.continuation):
            raise InputError(f"continuation needs positive multipliers, got {self.continuation}")
        object.__setattr__(self, "omega_bounds", tuple(float(w) for w in self.omega_bounds))
        object.__setattr__(self, "weights", {**dict.fromkeys(DEFAULT_WEIGHTS, 0.0),
                                             **{k: float(v) for k, v in self.weights.items()}})
        _choice("layout", self.layout, LAYOUTS)
        _choice("transcription", self.transcription, TRANSCRIPTIONS)
        _choice("hessian", self.hessian, HESSIANS)
        _choice("solver", self.solver, SOLVERS)
        if self.solver == "levenberg-marquardt" and self.transcription != "simultaneous":
            raise InputError("solver='levenberg-marquardt' marches the simultaneous NLP's "
                             "design; use transcription='simultaneous'")
        for name in self.fix:
            _choice("fix", name, GROUPS)
        unknown = set(self.weights) - set(DEFAULT_WEIGHTS)
        if unknown or any(w < 0 for w in self.weights.values()) or not any(self.weights.values()):
            raise InputError(f"weights take non-negative values for {sorted(DEFAULT_WEIGHTS)}, "
                             f"not all zero; got {self.weights}")
        if not 0 < self.alpha0 < PI / 2:
            raise InputError(f"alpha0 must be an acute angle in (0, pi/2), got {self.alpha0}")
        if not 0 <= self.min_angle < PI / 4:
            raise InputError(f"min_angle must lie in [0, pi/4), got {self.min_angle}")
        if not 0 <= self.mu_margin < 1:
            raise InputError(f"mu_margin must lie in [0, 1), got {self.mu_margin}")
        if not 0 <= self.min_length:
            raise InputError(f"min_length must be >= 0, got {self.min_length}")
        lo, hi = self.omega_bounds
        if not -PI <= lo < hi <= PI or not lo <= self.omega0 <= hi:
            raise InputError(f"need -pi <= omega_bounds[0] <= omega0 <= omega_bounds[1] <= pi, "
                             f"got omega0 = {self.omega0}, omega_bounds = {self.omega_bounds}")
        if self.stop_rms is not None and not self.stop_rms > 0:
            raise InputError(f"stop_rms must be a positive fraction of the diameter or None, "
                             f"got {self.stop_rms}")
        if self.barrier_init is not None and not self.barrier_init > 0:
            raise InputError(f"barrier_init must be positive or None, got {self.barrier_init}")
        if not 0 <= self.damping < np.inf:
            raise InputError(f"damping must be a finite number >= 0, got {self.damping}")
        if self.solver == "levenberg-marquardt" and not self.damping > 0:
            raise InputError("solver='levenberg-marquardt' starts from damping, which must be "
                             f"positive; got {self.damping}")
        if self.max_iter < 1 or not self.tol > 0:
            raise InputError("max_iter must be >= 1 and tol > 0")
        object.__setattr__(self, "ipopt_options", _ipopt_options(self.ipopt_options))

    @property
    def N(self) -> int:
        """Coarse lattice rows (the pattern has 2N panel rows)."""
        return self.panels[0] // 2

    @property
    def M(self) -> int:
        """Coarse lattice columns (the pattern has 2M panel columns)."""
        return self.panels[1] // 2

    # ------------------------------------------------------------------ start
    def start(self) -> Start:
        """The starting Miura and the target lattice.

        The target lattice spans the target's whole domain; the Miura's vertical and
        horizontal sides are scaled so that its coarse lattice at omega0 has the same mean
        neighbour distances along i and along j; both are then aligned (Kabsch).
        """
        N, M = self.N, self.M
        unit = miura_boundary(2 * N, 2 * M, 1.0, 1.0, self.alpha0, self.layout)
        coarse = numpy_model.fold(numpy_model.march(unit), self.omega0)[::2, ::2]
        target_points = self.target.lattice(N, M)
        s_i, s_j = surfaces.mean_neighbour_distances(coarse)
        t_i, t_j = surfaces.mean_neighbour_distances(target_points)
        bd = unit.with_lengths(np.concatenate([unit.l_left * t_i / s_i,
                                               unit.l_bottom * t_j / s_j]))
        coarse = numpy_model.fold(numpy_model.march(bd), self.omega0)[::2, ::2]
        R, t, _ = shape.kabsch(coarse, target_points)
        return Start(boundary=bd, omega=self.omega0, target_points=target_points,
                     spacing=0.5 * (t_i + t_j), rotation=R, translation=t)

    def transcribe(self, start: Start | None = None, weights: dict[str, float] | None = None,
                   initial: DesignResult | None = None) -> transcription.NLP:
        """The NLP of this problem in the chosen transcription.

        ``weights`` override the problem's; ``initial`` (a result of a problem of the same
        size, in either transcription) replaces the Miura as the initial guess, while the
        Miura stays the Tikhonov reference and fixes the mountain-valley pattern.
        """
        start = start or self.start()
        guess = start
        if initial is not None:
            if initial.boundary.N != 2 * self.N or initial.boundary.M != 2 * self.M:
                raise InputError(f"the initial guess has {initial.boundary.N} x "
                                 f"{initial.boundary.M} panels, the problem {self.panels}")
            guess = Start(boundary=initial.boundary, omega=initial.omega,
                          target_points=start.target_points, spacing=start.spacing,
                          rotation=initial.rotation, translation=initial.translation)
        setup = transcription.Setup(
            boundary=guess.boundary, omega=guess.omega, rotation=guess.rotation,
            translation=guess.translation, target=start.target_points, spacing=start.spacing,
            weights=weights or self.weights, min_angle=self.min_angle,
            min_length=self.min_length, mu_margin=self.mu_margin,
            omega_bounds=self.omega_bounds, fixed=self.fix, reference=start.boundary,
            reference_omega=start.omega)
        return getattr(transcription, self.transcription)(setup)

    # ------------------------------------------------------------------ solve
    def solve(self, callback: Callable[[dict], None] | None = None,
              warm_start: DesignResult | None = None, verbose: bool = False,
              multistart: int = 1, seed: int = 0) -> DesignResult:
        """Solve the design with IPOPT; see the module docstring.

        ``callback`` receives {"iter", "objective", "inf_pr", "elapsed"} every iteration
        ("elapsed": seconds since the solve started).
        ``warm_start``: a result of a problem of the same size to start from instead of the
        Miura (the Miura stays the Tikhonov reference and the mountain-valley pattern).
        ``multistart`` > 1: solve from that many starting Miuras (the first the problem's own,
        the others with alpha0 and omega0 perturbed, seeded by ``seed``) and keep the
        successful result with the smallest fit["rms"]; see :func:`_multistart`.
        Raises :class:`InfeasibleDesign` when IPOPT finds the constraints infeasible,
        :class:`SolverFailed` (with IPOPT's status, the last iterate and the best feasible
        one) otherwise.
        """
        if multistart != 1:
            return _multistart(self, multistart, seed, callback, warm_start, verbose)
        if self.min_length >= 1:
            raise InfeasibleDesign(
                f"min_length = {self.min_length} asks every side to be at least the mean side, "
                "which only equal sides satisfy; choose min_length < 1 (default 0.2)")
        t0 = time.perf_counter()
        start = self.start()
        x = None
        history: dict[str, list] = {"iter": [], "objective": [], "inf_pr": [], "elapsed": []}
        iterations, t_build = 0, 0.0
        counts = {"gauss_newton_iterations": 0, "marched_iterations": 0}
        for stage, factor in enumerate(self.continuation):
            weights = dict(self.weights, regularization=factor * self.weights["regularization"])
            t1 = time.perf_counter()
            nlp = self.transcribe(start, weights, warm_start if x is None else None)
            if x is None:
                x = nlp.x0
            t_build += time.perf_counter() - t1
            sol, log, best = None, None, None
            phases = self._phases(iterations)
            march = None
            if self.solver == "levenberg-marquardt":
                march = self._march(nlp, start, x, history, callback, iterations, t0)
            if march is not None and march.status != "Inadmissible_Start":
                iterations += march.iterations
                counts["marched_iterations"] += march.iterations
                x, best, objective = march.x, march.x, march.objective
                status, success = march.status, march.status == "Fit_Reached"
                if status == "Stalled" and iterations >= self.max_iter:
                    status = "Maximum_Iterations_Exceeded"
                phases = self._phases(iterations) if status == "Stalled" else []
            multipliers: dict[str, Any] = {}
            for hessian, max_iter in phases:
                t1 = time.perf_counter()
                solver, log = self._solver(
                    nlp, start, history, callback, verbose, hessian=hessian,
                    max_iter=max_iter, elapsed=t1 - t0, best=log if multipliers else None,
                    warm=(warm_start is not None or stage > 0 or bool(multipliers)
                          or best is not None),
                    multipliers=bool(multipliers))
                t_build += time.perf_counter() - t1
                sol = solver(x0=x, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg,
                             **multipliers)
                stats = dict(solver.stats())
                status = "Fit_Reached" if log.reached else stats["return_status"]
                success = log.reached or bool(stats["success"])
                x = log.reached_x if log.reached else sol["x"].full().ravel()
                objective = log.reached_objective if log.reached else float(sol["f"])
                best = log.best if log.best is not None else best
                iterations += int(stats["iter_count"])
                if hessian == "gauss-newton":
                    counts["gauss_newton_iterations"] += int(stats["iter_count"])
                if log.reached or status in FINAL_STATUSES:
                    break
                multipliers = {"lam_g0": sol["lam_g"], "lam_x0": sol["lam_x"]}
            solve_stats = {"status": status, "success": success,
                           "iterations": iterations, "build_time": t_build,
                           "solve_time": time.perf_counter() - t0 - t_build,
                           "objective": objective, "history": history,
                           "transcription": self.transcription, "hessian": self.hessian,
                           "solver": self.solver, **counts}
            if not success or status == "Fit_Reached":
                break
        if not success:
            if sol is None:
                raise SolverFailed(
                    f"the marched Levenberg-Marquardt solve did not finish the design: status "
                    f"{status} after {iterations} iterations; raise max_iter or time_limit",
                    status=status, stats=solve_stats, last_iterate=x, best_iterate=best)
            raise_for_ipopt(
                status, iterations, "the design",
                f"{_violation_report(nlp, sol)}; relax min_length, min_angle or mu_margin",
                "raise max_iter or time_limit, or relax tol", solve_stats, x, best)
        return self._result(nlp, start, x, solve_stats)

    def _phases(self, done: int) -> list[tuple[str, int]]:
        """(Hessian, iteration limit) of each IPOPT run of one solve stage, ``done``
        iterations having been spent by earlier stages.

        With ``hessian = "gauss-newton"`` the damped Gauss-Newton runs first, for at most
        :data:`GAUSS_NEWTON_ITERATIONS`; unless it reaches stop_rms or converges, the exact
        Hessian takes over from its last iterate and multipliers. On its own it converges
        only linearly: to IPOPT's tolerance the 20 x 20 sphere cap had not converged after
        800 iterations, and the hyperboloid's and quarter vase's last iterates failed the
        re-march check (folded states 6-8e-8 off the NumPy re-march, where 1e-8 is allowed).
        """
        left = self.max_iter - done
        if self.hessian != "gauss-newton":
            return [(self.hessian, left)]
        first = min(GAUSS_NEWTON_ITERATIONS, left)
        return [("gauss-newton", first)] + ([("exact", left - first)] if left > first else [])

    def _march(self, nlp: transcription.NLP, start: Start, x: np.ndarray, history: dict,
               callback, done: int, t0: float) -> reduced.Outcome:
        """The Levenberg-Marquardt run on the marching manifold (:mod:`rffqm_nlp.reduced`)
        from x, ``done`` iterations having been spent, recording every step in ``history``."""

        def record(objective: float, violation: float) -> None:
            entry = {"iter": len(history["iter"]), "objective": objective,
                     "inf_pr": violation, "elapsed": time.perf_counter() - t0}
            for key, value in entry.items():
                history[key].append(value)
            if callback is not None:
                callback(entry)

        deadline = None if self.time_limit is None else t0 + float(self.time_limit)
        return reduced.levenberg_marquardt(
            nlp, x, self.damping, self.max_iter - done, deadline=deadline,
            stop=self._fit_reached(nlp, start), callback=record)

    def _solver(self, nlp: transcription.NLP, start: Start, history: dict, callback,
                verbose: bool, hessian: str, max_iter: int, elapsed: float = 0.0,
                warm: bool = False, multipliers: bool = False, best=None):
        f = nlp.objective
        opts: dict[str, Any] = {
            "ipopt.max_iter": max_iter, "ipopt.tol": self.tol,
            "ipopt.constr_viol_tol": 1e-9, "ipopt.print_level": 5 if verbose else 0,
            "print_time": verbose, "ipopt.sb": "yes", "expand": self._expand()}
        if self.time_limit is not None:
            opts["ipopt.max_wall_time"] = max(float(self.time_limit) - elapsed, 1e-3)
        if warm or self.barrier_init is not None:
            # near an optimum a small barrier keeps IPOPT from wandering off
            mu_init = 1e-6 if self.barrier_init is None else self.barrier_init
            opts.update({"ipopt.mu_init": mu_init, "ipopt.bound_push": 1e-9,
                         "ipopt.bound_frac": 1e-9})
        else:
            opts.update(COLD_BARRIER[self.transcription])
        if multipliers:
            opts["ipopt.warm_start_init_point"] = "yes"
        opts.update({f"ipopt.{name}": value for name, value in self.ipopt_options.items()})
        if hessian == "limited-memory":
            opts["ipopt.hessian_approximation"] = "limited-memory"
        elif hessian == "gauss-newton":
            opts["hess_lag"] = transcription.gauss_newton_hessian(nlp, self.damping)
        elif nlp.parts is not None:
            opts["hess_lag"] = transcription.lagrangian_hessian(nlp)
        log = _IterationLog(nlp, history, callback, self._fit_reached(nlp, start), best,
                            t0=time.perf_counter() - elapsed)
        opts["iteration_callback"] = log
        solver = ca.nlpsol("design", "ipopt", {"x": nlp.x, "f": f, "g": nlp.g}, opts)
        solver._iteration_log = log  # keep the callback alive as long as the solver
        return solver, log

    def _expand(self) -> bool:
        """Expand the NLP to SX (fast evaluation, costly derivative build) or keep MX.

        The sequential NLP is dense: its SX Hessian took 2-5 s to build at 8 x 8 panels and
        19-31 s (3.4 GB) at 16 x 16 to 20 x 20, while the MX Hessian builds in 0.4-4 s but
        costs 0.1-0.4 s per evaluation against 0.01-0.1 s. Measured on the bundled targets,
        SX was faster in total up to 12 x 12 panels (:data:`SX_MAX_PANELS`), MX from 16 x 16
        on. The simultaneous NLP's time goes to MUMPS, not to evaluations, and its SX
        Hessian build grows with the pattern (3.3 s at 20 x 20, 15 s at 40 x 40, most of
        the 282 s build at 100 x 100), so it stays MX: build + solve of the sphere cap took
        0.50 s against 0.62 s at 8 x 8, 1.5 s against 2.2 s at 12 x 12 and 6.5 s against
        9.5 s at 20 x 20.
        """
        return (self.transcription == "sequential"
                and self.panels[0] * self.panels[1] <= SX_MAX_PANELS)

    def _fit_reached(self, nlp: transcription.NLP, start: Start):
        """For ``stop_rms``: does the aligned coarse lattice at x fit the target well enough?"""
        if self.stop_rms is None:
            return None
        limit = self.stop_rms * self.target.diameter()

        def reached(x: np.ndarray) -> bool:
            Y = np.stack([c.full() for c in nlp.folded(x)], axis=-1)
            return shape.kabsch(Y[::2, ::2], start.target_points)[2] <= limit

        return reached

    def _result(self, nlp: transcription.NLP, start: Start, x: np.ndarray,
                stats: dict) -> DesignResult:
        """Re-march the solution with the NumPy model, check it, measure the fit."""
        vec, omega = (np.asarray(v.full()).ravel() for v in nlp.unpack(x))
        omega = float(omega[0])
        bd = BoundaryData.from_vector(vec, start.boundary.sigma, 2 * self.N, 2 * self.M)
        try:
            pattern = numpy_model.march(bd)
        except MarchingError as exc:
            raise SolverFailed(f"the solution fails re-marching with the NumPy model: {exc}",
                               status="remarch_failed", stats=stats, last_iterate=x) from exc
        Y = numpy_model.fold(pattern, omega)
        Y_graph = np.stack([c.full() for c in nlp.folded(x)], axis=-1)
        scale = np.abs(Y).max()
        if np.abs(Y - Y_graph).max() > 1e-8 * scale:
            raise SolverFailed("the NumPy re-march disagrees with the CasADi graph by "
                               f"{np.abs(Y - Y_graph).max():.3g}", status="remarch_mismatch",
                               stats=stats, last_iterate=x)
        self._check_constraints(pattern, stats, x)
        R, t, rms = shape.kabsch(Y[::2, ::2], start.target_points)
        folded = Y @ R.T + t
        fit = design_fit(folded[::2, ::2], start.target_points, self.target)
        fit.update(min_side_over_mean=float(pattern.side_lengths.min()
                                            / pattern.side_lengths.mean()),
                   min_sector_angle=float(pattern.sector_angles.min()))
        return DesignResult(boundary=bd, omega=omega, pattern=pattern, folded=folded,
                            target_points=start.target_points, rotation=R, translation=t,
                            fit=fit, stats=stats, problem=self.to_config(), x=x)

    def _check_constraints(self, pattern, stats: dict, x: np.ndarray) -> None:
        tol = 1e-6
        sides = pattern.side_lengths
        worst_angle = float(np.min(np.concatenate([pattern.alpha.ravel(), pattern.beta.ravel(),
                                                   PI - pattern.alpha.ravel(),
                                                   PI - pattern.beta.ravel()])))
        problems = []
        if worst_angle < self.min_angle - tol:
            problems.append(f"a sector angle of {worst_angle:.6g} < min_angle")
        if sides.min() < self.min_length * sides.mean() * (1 - tol):
            problems.append(f"a side of {sides.min() / sides.mean():.6g} x mean < min_length")
        if problems:
            raise SolverFailed("the solution violates its constraints on re-marching: "
                               + "; ".join(problems), status="constraint_violation",
                               stats=stats, last_iterate=x)

    # ------------------------------------------------------------------ configuration
    def to_config(self) -> dict[str, Any]:
        """The problem as a TOML-ready dict: {"target": ..., "design": ...}."""
        design = {name: getattr(self, name) for name in self.__dataclass_fields__
                  if name != "target"}
        design["weights"] = dict(self.weights)
        design["panels"] = list(self.panels)
        design["omega_bounds"] = list(self.omega_bounds)
        design["fix"] = list(self.fix)
        design["continuation"] = list(self.continuation)
        design["ipopt_options"] = dict(self.ipopt_options)
        if design["time_limit"] is None:
            design.pop("time_limit")
        return {"target": self.target.to_config(), "design": design}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> "DesignProblem":
        """A problem from {"target": {...}, "design": {...}} (the tables of a target file)."""
        if "target" not in config:
            raise InputError("a design needs a [target] table")
        design = dict(config.get("design", {}))
        known = set(cls.__dataclass_fields__) - {"target"}
        unknown = set(design) - known
        if unknown:
            raise InputError(f"unknown [design] keys {sorted(unknown)}; known: {sorted(known)}")
        return cls(target=surfaces.from_config(config["target"]), **design)

    @classmethod
    def load(cls, path: str | Path) -> "DesignProblem":
        """A problem from a TOML file with [target] and [design] tables."""
        return cls.from_config(read_toml(path, "design file"))


def design_fit(coarse: np.ndarray, target_points: np.ndarray,
               target: surfaces.Surface) -> dict[str, float]:
    """Fit measures of an aligned coarse lattice, relative to the target's diameter.

    ``rms``: RMS distance to the target lattice (corresponding points); ``rms_surface`` and
    ``hausdorff``: RMS and largest distance to the target surface; ``plane_rms``: RMS
    distance of the target lattice to its best-fitting plane, the fit a flat sheet reaches.
    """
    diameter = target.diameter()
    rms = float(np.sqrt(np.mean(np.sum((coarse - target_points) ** 2, axis=-1))))
    pts = target_points.reshape(-1, 3)
    plane = np.linalg.svd(pts - pts.mean(0), compute_uv=False)[-1] / np.sqrt(len(pts))
    surface = shape.relative_fit(coarse, target)
    return {"rms": rms / diameter, "rms_surface": surface["rms"],
            "hausdorff": surface["hausdorff"], "plane_rms": float(plane / diameter)}


def _ipopt_options(options: dict) -> dict[str, str | int | float]:
    """``options`` with any "ipopt." prefix dropped, checked by building a small IPOPT
    solver with them (CasADi rejects unknown names, IPOPT values of the wrong type or out
    of range)."""
    if not isinstance(options, dict):
        raise InputError(f"ipopt_options must be a dict of IPOPT options, got {options!r}")
    out: dict[str, str | int | float] = {}
    for key, value in options.items():
        name = str(key).removeprefix("ipopt.")
        if name in IPOPT_FIELDS:
            raise InputError(f"ipopt_options: set {name} through DesignProblem's "
                             f"{IPOPT_FIELDS[name]}, not ipopt_options")
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise InputError(f"ipopt_options: {name} = {value!r} must be a number or a string "
                             "(IPOPT's yes/no options take 'yes' or 'no')")
        out[name] = value
    if out:
        x = ca.MX.sym("x")
        try:
            ca.nlpsol("ipopt_options", "ipopt", {"x": x, "f": x * x},
                      {**{f"ipopt.{k}": v for k, v in out.items()}, "ipopt.sb": "yes",
                       "ipopt.print_level": 0, "print_time": False})
        except RuntimeError as exc:
            reason = str(exc).strip().splitlines()[-1].split(": ", 1)[-1]
            if reason.startswith("Invalid options"):
                reason += " It printed which and why above."
            raise InputError(f"IPOPT rejects ipopt_options {out}: {reason}") from None
    return out


def _choice(name: str, value: str, options: tuple[str, ...]) -> None:
    if value not in options:
        raise InputError(f"{name} must be one of {options}, got {value!r}")


def _violation_report(nlp: transcription.NLP, sol) -> str:
    g = sol["g"].full().ravel()
    viol = np.maximum(nlp.lbg - g, g - nlp.ubg)
    return f"largest constraint violation {viol.max():.3g} at constraint {int(viol.argmax())}"


class _IterationLog(ca.Callback):
    """IPOPT iteration callback: records objective and constraint violation per iteration,
    keeps the best admissible design met on the way (``best``) and asks IPOPT to stop once
    ``stop(x)`` holds at one (``reached_x``).

    An iterate is admissible when it satisfies every constraint and bound. Where it does not
    and the NLP can project it (``nlp.project``: the simultaneous transcription re-marches
    the iterate's boundary data), the projected point is judged instead, with its own
    objective: the simultaneous NLP meets its marching equations only near the optimum, but
    its earlier iterates' designs are often admissible and good (the 20 x 20 sphere cap:
    1.29% RMS/diameter after 15 of 40 iterations, 0.75% after 25).
    """

    #: constraint violation below which an iterate counts as feasible for ``stop``
    FEASIBLE = 1e-9

    def __init__(self, nlp: transcription.NLP, history: dict, callback, stop=None,
                 previous: "_IterationLog | None" = None, t0: float | None = None):
        ca.Callback.__init__(self)
        self._stop = stop
        self.reached = False
        self.reached_x: np.ndarray | None = None
        self.reached_objective = np.nan
        # the best admissible iterate so far, of this run or of an earlier run on the same NLP
        self.best: np.ndarray | None = None if previous is None else previous.best
        self._best_objective = np.inf if previous is None else previous._best_objective
        self._nx, self._ng = nlp.x.numel(), nlp.g.numel()
        self._lbg, self._ubg = nlp.lbg, nlp.ubg
        self._lbx, self._ubx = nlp.lbx, nlp.ubx
        self._project = nlp.project
        if nlp.project is not None:
            self._fg = ca.Function("fg", [nlp.x], [nlp.objective, nlp.g])
        self._history = history
        self._callback = callback
        self._t0 = time.perf_counter() if t0 is None else t0  # "elapsed" counts from t0
        self.construct("iteration_log", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = ca.nlpsol_out(i)
        if n in ("f",):
            return ca.Sparsity.dense(1)
        if n in ("x", "lam_x"):
            return ca.Sparsity.dense(self._nx)
        if n in ("g", "lam_g"):
            return ca.Sparsity.dense(self._ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        g = np.asarray(arg[ca.nlpsol_out().index("g")]).ravel()
        viol = self._violation(g)
        entry = {"iter": len(self._history["iter"]),
                 "objective": float(arg[ca.nlpsol_out().index("f")]),
                 "inf_pr": viol, "elapsed": time.perf_counter() - self._t0}
        for key, value in entry.items():
            self._history[key].append(value)
        if self._callback is not None:
            self._callback(entry)
        x = np.asarray(arg[ca.nlpsol_out().index("x")]).ravel()
        objective = entry["objective"]
        if viol > self.FEASIBLE and self._project is not None:
            x = self._project(x)
            if x is None:
                return [int(self.reached)]
            f, g = self._fg(x)
            objective, viol = float(f), self._violation(g.full().ravel(), x)
        if viol <= self.FEASIBLE:
            if objective < self._best_objective:
                self.best, self._best_objective = x.copy(), objective
            if self._stop is not None and self._stop(x):
                self.reached, self.reached_x, self.reached_objective = True, x.copy(), objective
        return [int(self.reached)]

    def _violation(self, g: np.ndarray, x: np.ndarray | None = None) -> float:
        """Largest violation of the constraints at g (and of the bounds at x, if given)."""
        parts = [[0.0], self._lbg - g, g - self._ubg]
        if x is not None:
            parts += [self._lbx - x, x - self._ubx]
        return float(np.max(np.concatenate(parts)))


# ---------------------------------------------------------------------- multistart
#: Half-widths (radians) of the uniform perturbations of alpha0 and omega0 of the starts
#: 1, 2, ... of a multistart; the perturbed values are clipped into their valid ranges.
MULTISTART_SPREAD = {"alpha0": 0.3, "omega0": 0.6}


def multistart_starts(problem: DesignProblem, starts: int, seed: int) -> list[tuple[float, float]]:
    """(alpha0, omega0) of each start of a multistart: the problem's own first, then
    ``starts - 1`` seeded uniform perturbations by :data:`MULTISTART_SPREAD`, clipped to
    alpha0 in [min_angle + 0.05, pi/2 - 0.05] and omega0 inside ``omega_bounds`` (5% of
    their width away from each end)."""
    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or starts < 1:
        raise InputError(f"multistart must be a whole number of starts >= 1, got {starts!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a whole number >= 0, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    lo, hi = problem.omega_bounds
    margin = 0.05 * (hi - lo)
    alpha = np.clip(problem.alpha0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["alpha0"],
                    problem.min_angle + 0.05, PI / 2 - 0.05)
    omega = np.clip(problem.omega0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["omega0"],
                    lo + margin, hi - margin)
    return [(problem.alpha0, problem.omega0)] + [(float(a), float(w)) for a, w in zip(alpha, omega)]


def _multistart(problem: DesignProblem, starts: int, seed: int,
                callback: Callable[[dict], None] | None, warm_start: DesignResult | None,
                verbose: bool) -> DesignResult:
    """Solve ``problem`` from each start of :func:`multistart_starts`; keep the best.

    A start that ends in :class:`InfeasibleDesign` or :class:`SolverFailed` is recorded and
    skipped; the result is the successful start with the smallest fit["rms"], with the
    problem as asked (``result.problem``) and ``result.stats["multistart"]`` = {"starts",
    "seed", "chosen" (index of the kept start), "time" (all starts, s), "runs": one entry
    per start with alpha0, omega0, status, rms (None when it failed), iterations, time and
    reason}. When every start fails, raises :class:`InfeasibleDesign` if all were
    infeasible, else :class:`SolverFailed` with the status of the first failed solve.
    """
    if warm_start is not None:
        raise InputError("multistart and warm_start exclude each other: a warm start replaces "
                         "the starting Miuras that multistart varies")
    t0 = time.perf_counter()
    runs: list[dict[str, Any]] = []
    errors: list[InfeasibleDesign | SolverFailed] = []
    best: tuple[int, DesignResult] | None = None
    for k, (alpha0, omega0) in enumerate(multistart_starts(problem, starts, seed)):
        t1 = time.perf_counter()
        run: dict[str, Any] = {"start": k, "alpha0": alpha0, "omega0": omega0}
        try:
            res = replace(problem, alpha0=alpha0, omega0=omega0).solve(callback=callback,
                                                                         verbose=verbose)
        except (InfeasibleDesign, SolverFailed) as exc:
            errors.append(exc)
            run.update(status=getattr(exc, "status", "") or "Infeasible_Problem_Detected",
                       rms=None, iterations=None, reason=" ".join(str(exc).split()))
        else:
            run.update(status=res.stats["status"], rms=res.fit["rms"],
                       iterations=res.stats["iterations"], reason="")
            if best is None or res.fit["rms"] < best[1].fit["rms"]:
                best = (k, res)
        run["time"] = time.perf_counter() - t1
        runs.append(run)
    if best is None:
        statuses = ", ".join(sorted({r["status"] for r in runs}))
        message = (f"all {starts} starts of the multistart failed ({statuses}); the problem's "
                   f"own start: {errors[0]}")
        failed = [e for e in errors if isinstance(e, SolverFailed)]
        if not failed:
            raise InfeasibleDesign(message) from errors[0]
        raise SolverFailed(message, status=failed[0].status, stats=failed[0].stats,
                           last_iterate=failed[0].last_iterate,
                           best_iterate=failed[0].best_iterate) from failed[0]
    chosen, res = best
    stats = dict(res.stats, multistart={"starts": starts, "seed": seed, "chosen": chosen,
                                        "time": time.perf_counter() - t0, "runs": runs})
    return replace(res, stats=stats, problem=problem.to_config())

