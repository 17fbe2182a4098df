"""Small crease patterns and the edge kinds the FOLD and export tests expect of them."""

from __future__ import annotations

from collections import Counter

import numpy as np

import rffqm_nlp as rq
from rffqm_nlp.model import lengths
from rffqm_nlp.model import marching

OMEGA = 1.3
#: Names of the patterns of :func:`make_pattern`.
PATTERNS = ("miura", "perturbed")


def make_pattern(name: str) -> rq.Pattern:
    """A 4 x 5 Miura-ori ("miura") or a 6 x 6 one with perturbed angles and LP lengths."""
    if name == "miura":
        return marching.march(rq.miura_boundary(4, 5))
    bd = rq.perturb_angles(rq.miura_boundary(6, 6), 0.01 * np.pi, seed=1)
    return marching.march(lengths.side_length_lp(bd))


def expected_kinds(pat: rq.Pattern, omega: float = OMEGA) -> Counter:
    """M/V/B counts from the signs of marching.fold_angles (boundary edges known by place)."""
    gh, gv = marching.fold_angles(pat, omega)
    creases = np.concatenate([gh[1:-1].ravel(), gv[:, 1:-1].ravel()])
    return Counter({"V": int(np.sum(creases > 0)), "M": int(np.sum(creases < 0)),
                    "B": 2 * (pat.N + pat.M)})


def n_edges(pat: rq.Pattern) -> int:
    """Edge count of the pattern: horizontal then vertical edges."""
    return (pat.N + 1) * pat.M + pat.N * (pat.M + 1)
