"""Closeness to a reference surface: point-to-plane distance to each vertex's footpoint.

Footpoints and their normals are recomputed at the start of every iteration, so the
linear residual ``n_k . (v_k - p_k)`` lets the net glide along the surface (section 4.2).
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["Closeness"]


class Closeness(Constraint):
    """Soft term pulling the vertices onto a `fabplan.reference.ReferenceSurface`.

    Parameters
    ----------
    reference : surface in model units, with ``closest_points`` (a `ReferenceSurface`).
    vertices : (k,) int, the vertices it applies to (default: all).
    """

    name = "closeness"
    hard = False

    def __init__(self, reference, vertices: np.ndarray | None = None):
        self.reference = reference
        self.vertices = vertices

    def _ids(self, state):
        return np.arange(state.mesh.vertex_count) if self.vertices is None else self.vertices

    def prepare(self, state):
        model = state.X[self._ids(state)] * state.length_scale + state.origin
        foot, normal, _ = self.reference.closest_points(model)
        self._foot = (foot - state.origin) / state.length_scale
        self._normal = normal

    def columns(self, state):
        return state.layout.index("vertices")[self._ids(state)]

    def evaluate(self, state):
        d = state.X[self._ids(state)] - self._foot
        return np.sum(d * self._normal, axis=1), self._normal
