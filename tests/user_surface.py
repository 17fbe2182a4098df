"""A user's surface for the ``python = "user_surface:wavy_sheet"`` target tests."""

import casadi as ca


def wavy_sheet(u, v):
    """A gently waved sheet, written with CasADi-compatible math."""
    return u, v, 0.3 * ca.sin(u) * ca.cos(v)


def flat_pair(u, v):
    """Returns two components only: a wrong surface for the error tests."""
    return u, v
