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
        V = state.blocks.index("vertices")[self._edges]       # (e, 2, 3)
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
    """``lo <= L_e <= hi`` for every edge e, as one smooth equality with an auxiliary
    angle per edge: ``L_e = m + r sin(s_e)`` (m, r: centre and half-width of the range).

    The one-sided `EdgeCollapseBarrier` switches rows on and off as edges cross the
    bound, and Gauss-Newton chatters where many edges sit on it (a layout whose lines
    converge near a near-umbilic); here every row stays smooth, at one variable per edge,
    so it is used where the edges' range is part of the requirement (layouts).

    Parameters
    ----------
    minimum, maximum : allowed edge lengths in model units. An edge that starts shorter
        than `minimum` gets its start length as its lower bound (it may not shrink); one
        that starts longer than `maximum` is pulled into the range.
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
        return {f"{self.name}-angle": (len(state.mesh.edges),)}

    def initialize(self, state):
        self._edges = state.mesh.edges
        X = state.X
        length = np.linalg.norm(X[self._edges[:, 0]] - X[self._edges[:, 1]], axis=1)
        lo = np.minimum(self.minimum / state.length_scale, length)
        hi = np.full(len(length), self.maximum / state.length_scale)
        self._centre, self._half = 0.5 * (hi + lo), 0.5 * (hi - lo)
        # an edge on a bound starts just inside it: at sin(s) = +-1 the angle's derivative
        # vanishes and Gauss-Newton could not move it off the bound again
        where = np.clip((length - self._centre) / self._half, -0.999, 0.999)
        state.blocks.view(state.x, f"{self.name}-angle")[:] = np.arcsin(where)

    def columns(self, state):
        V = state.blocks.index("vertices")[self._edges].reshape(-1, 6)       # (e, 6)
        return np.c_[V, state.blocks.index(f"{self.name}-angle")]

    def evaluate(self, state):
        X = state.X
        d = X[self._edges[:, 0]] - X[self._edges[:, 1]]
        length = np.maximum(np.linalg.norm(d, axis=1), 1e-15)
        s = state.blocks.view(state.x, f"{self.name}-angle")
        r = (length - self._centre) / self._half - np.sin(s)          # in half-widths
        g = d / (length * self._half)[:, None]
        return r, np.c_[g, -g, -np.cos(s)]
