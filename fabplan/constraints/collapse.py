"""A barrier against collapsing edges.

A star whose edge has shrunk to a point lies on a sphere trivially (four points always
do), so an S-net solve can slide into such degenerate "solutions". Every edge must keep
at least a fraction of its starting length; the residual is one-sided, zero (with a zero
Jacobian row) while the edge is long enough, so it only acts where a collapse begins.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["EdgeCollapseBarrier"]


class EdgeCollapseBarrier(Constraint):
    """``L_e >= b_e`` for every edge e (a one-sided hard constraint), with the bound
    ``b_e = max(fraction * L_e(start), minimum)``, never above the start length.

    Parameters
    ----------
    fraction : smallest allowed length of an edge relative to its length at the start.
    minimum : smallest allowed length in model units (e.g. half the panel size of a
        layout), or None.
    name : family name (two barriers in one solve need two names).
    """

    name = "edge-collapse"

    def __init__(self, fraction: float = 0.25, minimum: float | None = None, *,
                 name: str = "edge-collapse"):
        self.fraction = float(fraction)
        self.minimum = minimum
        self.name = name

    def columns(self, state):
        self._edges = state.mesh.edges
        X = state.X
        start = np.maximum(np.linalg.norm(X[self._edges[:, 0]] - X[self._edges[:, 1]], axis=1),
                           1e-12)
        bound = self.fraction * start
        if self.minimum is not None:
            bound = np.minimum(np.maximum(bound, self.minimum / state.length_scale), start)
        self._bound = bound
        V = state.layout.index("vertices")[self._edges]       # (e, 2, 3)
        return V.reshape(-1, 6)

    def evaluate(self, state):
        X = state.X
        d = X[self._edges[:, 0]] - X[self._edges[:, 1]]
        length = np.maximum(np.linalg.norm(d, axis=1), 1e-15)
        r = 1.0 - length / self._bound          # in units of the bound
        active = r > 0
        g = d / (length * self._bound)[:, None] * active[:, None]   # d(L/b)/da
        return np.where(active, r, 0.0), np.concatenate([-g, g], axis=1)
