"""The bars, triangles and hinges of the N4B5 bar-and-hinge model of an N x M pattern
(Filipov et al., Int. J. Solids Struct. 2017, s.3): four nodes and five bars per panel.

Nodes are the pattern's vertices: vertex (i, j) (1-based) is node (i-1)(M+1) + (j-1), the
row-major order of an (N+1, M+1) array. Bars, in this order:

* the horizontal edges (i, j) -> (i, j+1), (N+1) M of them, row-major;
* the vertical edges (i, j) -> (i+1, j), N (M+1), row-major;
* one diagonal per panel, N M, row-major: the shorter of a-d and b-c (the panel bends
  along its shorter diagonal, Filipov et al. 2017 s.3.2), a-d when they are equal.

The diagonal cuts each panel into two triangles (the constant-strain membrane elements).
Hinges, each (a, b, p, q) with its axis from node a to node b and the wing nodes p (right of
the axis, seen from +z in the flat pattern) and q (left of it):

* one bending hinge per panel on its diagonal, N M;
* one fold hinge per interior crease: the interior horizontal edges (N-1) M, then the
  interior vertical ones N (M-1), row-major; a wing is the third node of the triangle that
  holds the crease in that panel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    """The index tables of the N4B5 model of N x M panels.

    * ``bars`` (n_bars, 2): node pairs, in the order of the module's docstring;
    * ``triangles`` (2 N M, 3): node triples, counter-clockwise in the flat pattern;
    * ``triangle_bars`` (2 N M, 3): the bars of each triangle's sides 0-1, 1-2 and 2-0;
    * ``hinges`` (n_hinges, 4): (a, b, p, q), bending hinges first, then fold hinges;
    * ``creases`` (n_folds, 2, 2): the 1-based vertices (i, j) at both ends of each fold
      hinge's crease, in the order of the fold hinges.
    """

    N: int
    M: int
    bars: np.ndarray
    triangles: np.ndarray
    triangle_bars: np.ndarray
    hinges: np.ndarray
    creases: np.ndarray

    @property
    def nodes(self) -> int:
        """Number of nodes, (N+1)(M+1)."""
        return (self.N + 1) * (self.M + 1)

    @property
    def bending(self) -> slice:
        """The bending hinges among :attr:`hinges`."""
        return slice(0, self.N * self.M)

    @property
    def folds(self) -> slice:
        """The fold hinges among :attr:`hinges`."""
        return slice(self.N * self.M, len(self.hinges))


def build_frame(X: np.ndarray) -> Frame:
    """The :class:`Frame` of a pattern from its flat positions ``X`` (N+1, M+1, 3), which
    choose each panel's diagonal (the shorter one)."""
    N, M = X.shape[0] - 1, X.shape[1] - 1
    node = np.arange((N + 1) * (M + 1)).reshape(N + 1, M + 1)
    a, b, c, d = node[:-1, :-1], node[1:, :-1], node[:-1, 1:], node[1:, 1:]
    horizontal = np.stack([node[:, :-1], node[:, 1:]], -1).reshape(-1, 2)
    vertical = np.stack([node[:-1], node[1:]], -1).reshape(-1, 2)
    ad = (np.linalg.norm(X[1:, 1:] - X[:-1, :-1], axis=-1)
          <= np.linalg.norm(X[:-1, 1:] - X[1:, :-1], axis=-1))
    diagonal = np.where(ad[..., None], np.stack([a, d], -1), np.stack([c, b], -1))
    bars = np.concatenate([horizontal, vertical, diagonal.reshape(-1, 2)])
    # the two triangles of each panel, counter-clockwise: (a, c, d), (a, d, b) when the
    # diagonal is a-d; (a, c, b), (c, d, b) when it is c-b
    first = np.where(ad[..., None], np.stack([a, c, d], -1), np.stack([a, c, b], -1))
    second = np.where(ad[..., None], np.stack([a, d, b], -1), np.stack([c, d, b], -1))
    triangles = np.stack([first, second], axis=2).reshape(-1, 3)
    return Frame(N, M, bars, triangles, _triangle_bars(triangles, bars),
                 _hinges(node, ad, diagonal), _creases(N, M))


def _triangle_bars(triangles: np.ndarray, bars: np.ndarray) -> np.ndarray:
    """The bar index of each triangle side (0-1, 1-2, 2-0), (n_triangles, 3)."""
    n = int(bars.max()) + 1
    key = np.minimum(bars[:, 0], bars[:, 1]) * n + np.maximum(bars[:, 0], bars[:, 1])
    order = np.argsort(key)
    sides = np.stack([triangles, np.roll(triangles, -1, axis=1)], -1)
    wanted = np.minimum(sides[..., 0], sides[..., 1]) * n + np.maximum(sides[..., 0],
                                                                       sides[..., 1])
    return order[np.searchsorted(key[order], wanted)]


def _hinges(node: np.ndarray, ad: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
    """The hinge table (a, b, p, q): bending hinges, then fold hinges (module docstring)."""
    a, b, c, d = node[:-1, :-1], node[1:, :-1], node[:-1, 1:], node[1:, 1:]
    # diagonal a -> d has c on its right and b on its left; c -> b has d right, a left
    bend = np.concatenate([diagonal, np.where(ad[..., None], np.stack([c, b], -1),
                                              np.stack([d, a], -1))], axis=-1)
    # wings of a crease in the panel below a horizontal edge (its top edge b-d) and in the
    # panel above (its bottom edge a-c); right of a vertical edge (left side a-b) and left
    # of it (right side c-d): the third node of the triangle holding that side
    top_wing = np.where(ad, a, c)            # triangle (a, d, b) or (c, d, b)
    bottom_wing = np.where(ad, d, b)         # triangle (a, c, d) or (a, c, b)
    left_side_wing = np.where(ad, d, c)      # triangle (a, d, b) or (a, c, b)
    right_side_wing = np.where(ad, a, b)     # triangle (a, c, d) or (c, d, b)
    horizontal = np.stack([node[1:-1, :-1], node[1:-1, 1:], top_wing[:-1],
                           bottom_wing[1:]], -1).reshape(-1, 4)
    vertical = np.stack([node[:-1, 1:-1], node[1:, 1:-1], left_side_wing[:, 1:],
                         right_side_wing[:, :-1]], -1).reshape(-1, 4)
    return np.concatenate([bend.reshape(-1, 4), horizontal, vertical])


def _creases(N: int, M: int) -> np.ndarray:
    """The 1-based end vertices (i, j) of the interior creases, (n_folds, 2, 2), in the
    order of the fold hinges."""
    i, j = np.meshgrid(np.arange(2, N + 1), np.arange(1, M + 1), indexing="ij")
    horizontal = np.stack([np.stack([i, j], -1), np.stack([i, j + 1], -1)], -2)
    i, j = np.meshgrid(np.arange(1, N + 1), np.arange(2, M + 1), indexing="ij")
    vertical = np.stack([np.stack([i, j], -1), np.stack([i + 1, j], -1)], -2)
    return np.concatenate([horizontal.reshape(-1, 2, 2), vertical.reshape(-1, 2, 2)])
