"""The solution methods of a design problem, one folder each: Levenberg-Marquardt on the
marching manifold (:mod:`.levenberg_marquardt`), IPOPT (:mod:`.ipopt`), both a
``solve(nlp, x, run, ...) -> Outcome`` on the shared :class:`.context.Run`; and the
closed-form alternating perturbation (:mod:`.closed_form`), a design without an optimiser
that a solve may start from (``SolveOptions.start``)."""
