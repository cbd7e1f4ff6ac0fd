"""Prescribed levels: vertices on level sets of a function given on the reference surface
(the paper's second layout mode, section 2.1.11: one family prescribed, e.g. floor levels).
"""

from __future__ import annotations

import igl
import numpy as np

from .base import Constraint

__all__ = ["FamilyLevels"]


class FamilyLevels(Constraint):
    """Vertices on prescribed level sets of a function on the reference surface (hard).

    One row per vertex: the distance from the level set through its footpoint, measured
    along the function's gradient, ``g^ . (x - p) + (f(p) - level) / |g|``; footpoints are
    updated every iteration (the function is linear on each reference triangle).

    Parameters
    ----------
    reference : `fabplan.reference.ReferenceSurface`, in model units.
    value : (n_reference,) float, the function on the reference vertices.
    vertices : (k,) int, net vertices held on levels.
    levels : (k,) float, their levels.
    """

    name = "levels"
    hard = True

    def __init__(self, reference, value: np.ndarray, vertices: np.ndarray, levels: np.ndarray):
        self.reference = reference
        self.value = np.asarray(value, dtype=np.float64)
        self.vertices = np.asarray(vertices, dtype=np.int64)
        self.levels = np.asarray(levels, dtype=np.float64)
        g = igl.grad(reference.vertices, reference.triangles) @ self.value
        t = len(reference.triangles)
        self.gradient = np.stack([g[:t], g[t:2 * t], g[2 * t:]], axis=1)   # per triangle

    def prepare(self, state):
        model = state.X[self.vertices] * state.length_scale + state.origin
        foot, _, tri = self.reference.closest_points(model)
        V, T = self.reference.vertices, self.reference.triangles[tri]
        bary = igl.barycentric_coordinates(foot, V[T[:, 0]], V[T[:, 1]], V[T[:, 2]])
        at_foot = np.sum(bary * self.value[T], axis=1)
        g = self.gradient[tri]
        norm = np.maximum(np.linalg.norm(g, axis=1), 1e-300)
        self._direction = g / norm[:, None]
        self._offset = (at_foot - self.levels) / norm / state.length_scale
        self._foot = (foot - state.origin) / state.length_scale

    def columns(self, state):
        return state.blocks.index("vertices")[self.vertices]

    def evaluate(self, state):
        d = state.X[self.vertices] - self._foot
        return np.sum(d * self._direction, axis=1) + self._offset, self._direction
