"""IPOPT's Hessians of the design NLP's Lagrangian (its ``hess_lag`` option): the exact one
assembled around the few global variables (:func:`lagrangian_hessian`) and the damped
Gauss-Newton approximation (:func:`gauss_newton_hessian`)."""

from __future__ import annotations

import casadi as ca

from ...transcription.nlp import NLP


def lagrangian_hessian(nlp: NLP) -> ca.Function:
    """IPOPT's ``hess_lag`` for an NLP with ``parts``: the Hessian of
    L = lam_f f + lam_g' g assembled around its few dense rows and columns.

    Omega enters every crease and the rigid alignment every lattice point, so the Hessian
    has dense rows; CasADi's star colouring of the whole Hessian grows like their degree
    squared and dominated the build of large patterns. Here only the local block is
    coloured; the global rows are the Jacobian of grad_global L (8 rows), which builds
    several times faster (docs/decisions/ipopt.md).
    """
    local, glob = nlp.parts

    def hessian(lam_f, lam_g):
        L = lam_f * nlp.objective + ca.dot(lam_g, nlp.g)
        grad = ca.gradient(L, glob)
        cross = ca.jacobian(grad, local)
        return ca.blockcat([[ca.hessian(L, local)[0], cross.T],
                            [cross, ca.jacobian(grad, glob)]])

    return _hess_lag(nlp, hessian)


def gauss_newton_hessian(nlp: NLP, damping: float = 0.0) -> ca.Function:
    """IPOPT's ``hess_lag`` for the damped Gauss-Newton approximation
    lam_f (J' J + damping D), J the Jacobian of the residuals, D = ``nlp.damping_weights``
    (:func:`rffqm_nlp.design.transcription.damping_weights`).

    The constraints' curvature is dropped, so the matrix is positive semidefinite and IPOPT
    factorises the KKT system once per iteration (with the exact Hessian it first tries
    without a perturbation, finds the wrong inertia and factorises again). Most variables
    of the simultaneous NLP do not enter the loss, so J' J alone leaves them without any
    curvature: undamped, the sphere cap took huge steps and did not recover feasibility
    (docs/decisions/ipopt.md).
    """
    J = ca.jacobian(nlp.residuals, nlp.x)
    JtJ = ca.mtimes(J.T, J)
    if damping > 0:
        JtJ = JtJ + ca.diag(ca.DM(damping * nlp.damping_weights))
    return _hess_lag(nlp, lambda lam_f, lam_g: lam_f * JtJ)


def _hess_lag(nlp: NLP, hessian) -> ca.Function:
    """The Function IPOPT's CasADi interface takes as ``hess_lag``: (x, p, lam_f, lam_g) ->
    the upper triangle of ``hessian(lam_f, lam_g)``."""
    lam_f, lam_g, p = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", nlp.g.numel()), ca.MX.sym("p", 0)
    return ca.Function("nlp_hess_l", [nlp.x, p, lam_f, lam_g],
                       [ca.triu(hessian(lam_f, lam_g))],
                       ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
