"""The solution methods of a design problem: Levenberg-Marquardt on the marching manifold
(:mod:`.levenberg_marquardt`); IPOPT runs from :mod:`rffqm_nlp.design.problem`."""
