"""A barrier against collapsing edges.

A star whose edge has shrunk to a point lies on a sphere trivially (four points always
do), so an S-net solve can slide into such degenerate "solutions". Every edge must keep
at least a fraction of its starting length; the residual is one-sided, zero (with a zero
Jacobian row) while the edge is long enough, so it only acts where a collapse begins.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["EdgeCollapseBarrier", "EdgeLengthRange"]


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


class EdgeLengthRange(Constraint):
    """``lo <= L_e <= hi`` for every edge e, as equalities with slack variables:
    ``L_e / lo - 1 = s_e^2`` and ``1 - L_e / hi = t_e^2``.

    The one-sided `EdgeCollapseBarrier` switches rows on and off as edges cross the
    bound, and Gauss-Newton chatters where many edges sit on it (a layout whose lines
    converge near a near-umbilic); the slack keeps every row smooth, at two variables per
    edge, so it is used where the edges' range is part of the requirement (layouts).

    Parameters
    ----------
    minimum, maximum : allowed edge lengths in model units; an edge starting shorter
        than `minimum` keeps its start length as its bound.
    name : family name.
    """

    name = "edge-length"

    def __init__(self, minimum: float, maximum: float, *, name: str = "edge-length"):
        if not 0 < minimum < maximum:
            raise ValueError(f"edge length range needs 0 < minimum < maximum, got "
                             f"{minimum}, {maximum}")
        self.minimum, self.maximum = float(minimum), float(maximum)
        self.name = name

    def declare(self, state):
        return {f"{self.name}-slack": (len(state.mesh.edges), 2)}

    def initialize(self, state):
        self._edges = state.mesh.edges
        length = self._lengths(state)
        self._lo = np.minimum(self.minimum / state.length_scale, length)
        self._hi = np.full(len(length), self.maximum / state.length_scale)
        # slacks start where they satisfy the rows (zero for an edge outside the range)
        slack = np.stack([np.sqrt(np.maximum(length / self._lo - 1.0, 0.0)),
                          np.sqrt(np.maximum(1.0 - length / self._hi, 0.0))], axis=1)
        state.layout.view(state.x, f"{self.name}-slack")[:] = slack

    def _lengths(self, state):
        X = state.X
        return np.linalg.norm(X[self._edges[:, 0]] - X[self._edges[:, 1]], axis=1)

    def columns(self, state):
        V = state.layout.index("vertices")[self._edges].reshape(-1, 6)       # (e, 6)
        S = state.layout.index(f"{self.name}-slack")                        # (e, 2)
        return np.stack([np.c_[V, S[:, 0]], np.c_[V, S[:, 1]]], axis=1).reshape(-1, 7)

    def evaluate(self, state):
        X = state.X
        d = X[self._edges[:, 0]] - X[self._edges[:, 1]]
        length = np.maximum(np.linalg.norm(d, axis=1), 1e-15)
        s = state.layout.view(state.x, f"{self.name}-slack")
        unit = d / length[:, None]
        r = np.stack([length / self._lo - 1.0 - s[:, 0] ** 2,
                      1.0 - length / self._hi - s[:, 1] ** 2], axis=1)
        g_lo, g_hi = unit / self._lo[:, None], -unit / self._hi[:, None]
        J = np.stack([np.c_[g_lo, -g_lo, -2 * s[:, 0]], np.c_[g_hi, -g_hi, -2 * s[:, 1]]],
                     axis=1)
        return r.ravel(), J.reshape(-1, 7)
