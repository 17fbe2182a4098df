"""NumPy or CasADi: the one dispatch for formulas written once for both.

The vertex formulas (vertex.py), the target surfaces (surfaces.py) and the discrete shape
measures (shape.py) are each written once and evaluated on NumPy arrays (and Python numbers)
or on CasADi SX/MX symbols and DM matrices. :func:`math_for` returns the namespace of math
functions for its arguments, CasADi's as soon as one argument is a CasADi object:

    m = math_for(u, v)
    x = m.sqrt(u * u + v * v) * m.cos(v)

Both namespaces have the same names: ``sin, cos, tan, atan, atan2, sqrt, exp, log, sinh,
cosh, tanh, fabs, where, pi``; ``where(cond, a, b)`` is ``numpy.where`` or ``casadi.if_else``.
Users reach :func:`math_for` as ``rffqm_nlp.surfaces.mathlib``.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np

#: A value the formulas written once for both take and return: a Python or NumPy number, a
#: NumPy array, or a CasADi SX/MX symbol or DM matrix.
Scalar = Any
#: The CasADi matrix types: symbols (SX, MX) and numeric matrices (DM).
CASADI_TYPES = (ca.SX, ca.MX, ca.DM)

NUMPY = SimpleNamespace(sin=np.sin, cos=np.cos, tan=np.tan, atan=np.arctan, atan2=np.arctan2,
                        sqrt=np.sqrt, exp=np.exp, log=np.log, sinh=np.sinh, cosh=np.cosh,
                        tanh=np.tanh, fabs=np.abs, where=np.where, pi=math.pi)

CASADI = SimpleNamespace(sin=ca.sin, cos=ca.cos, tan=ca.tan, atan=ca.atan, atan2=ca.atan2,
                         sqrt=ca.sqrt, exp=ca.exp, log=ca.log, sinh=ca.sinh, cosh=ca.cosh,
                         tanh=ca.tanh, fabs=ca.fabs, where=ca.if_else, pi=math.pi)


def is_casadi(*args: Any) -> bool:
    """Whether any argument is a CasADi SX, MX or DM matrix."""
    return any(isinstance(a, CASADI_TYPES) for a in args)


def math_for(*args: Any) -> SimpleNamespace:
    """The math namespace for ``args``: :data:`CASADI` if any is a CasADi object, else
    :data:`NUMPY` (NumPy arrays, Python and NumPy numbers)."""
    return CASADI if is_casadi(*args) else NUMPY
