"""A limit on the distance to the reference surface, held inside the solve.

``|v_k - p_k| <= D`` at every vertex, ``p_k`` its closest point on the reference
(recomputed every iteration, as for `Closeness`): in the band form of the guards, the
signed distance ``delta_k = sign(n_k . (v_k - p_k)) |v_k - p_k|`` (``n_k`` the reference's
normal at ``p_k``) is ``D sin(s_k)``, with one auxiliary angle per vertex. It is an
inequality, not a pull: inside the band the net is free, and the limit does not fade.

The closest points are on the reference's triangles. Where the reference triangulates an
exact surface (a built-in or NURBS design), the limit is met on that surface: the band is
held narrower by how far the triangles lie from it (`ReferenceSurface.held_distance`).

The gradient of the distance is the unit offset ``(v - p) / |v - p|`` (the closest point
moves, but only along the surface): it turns continuously where the closest point passes
from one triangle to the next or over the surface's boundary, where a point-to-plane
distance would jump from one triangle's normal to the next.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint
from .guards import slack_start

__all__ = ["DeviationBound"]


class DeviationBound(Constraint):
    """Every vertex within `limit` (model units) of the reference surface.

    Parameters
    ----------
    reference : surface in model units, with ``closest_points`` (a `ReferenceSurface`).
    limit : the largest distance allowed (model units, > 0), to the exact surface where
        the reference has one. It may be changed between runs of a solver (a
        continuation tightening it).
    vertices : (k,) int, the vertices held to it; None (default): every vertex. A vertex
        in no star (a zigzag tip) is placed after the solve, or lies past the design's
        edge where the net is continued, and is left out.
    """

    name = "deviation"

    def __init__(self, reference, limit: float, vertices: np.ndarray | None = None):
        if not (np.isfinite(limit) and limit > 0):
            raise ValueError(f"the deviation limit must be a positive length, got {limit}")
        self.reference = reference
        self.limit = float(limit)
        self.vertices = None if vertices is None else np.asarray(vertices, np.int64)

    def _held(self, state) -> np.ndarray:
        """(k,) int, the vertices held to the limit (every vertex made once, not per
        iteration)."""
        if self.vertices is None:
            self.vertices = np.arange(state.mesh.vertex_count)
        return self.vertices

    @property
    def held_limit(self) -> float:
        """The largest distance to the reference's triangles that keeps a vertex within
        `limit` of the surface they stand for (model units)."""
        held = getattr(self.reference, "held_distance", None)
        return self.limit if held is None else held(self.limit)

    def declare(self, state):
        return {f"{self.name}-band": (len(self._held(state)),)}

    def prepare(self, state):
        foot, self._normal, _ = state.footpoints(self.reference, self._held(state))
        self._foot = (foot - state.origin) / state.length_scale

    def distances(self, state) -> np.ndarray:
        """(k,) float, distance of each vertex held from its closest point (normalized
        units), as found by the last `prepare`."""
        return np.linalg.norm(state.X[self._held(state)] - self._foot, axis=1)

    def _signed(self, state) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (k,) and their gradients (k, 3), normalized units."""
        d = state.X[self._held(state)] - self._foot
        length = np.linalg.norm(d, axis=1)
        side = np.where(np.sum(d * self._normal, axis=1) < 0, -1.0, 1.0)
        # on the surface the offset has no direction: the surface normal is its limit
        on = length <= 1e-12
        gradient = np.where(on[:, None], self._normal,
                            side[:, None] * d / np.where(on, 1.0, length)[:, None])
        return side * length, gradient

    def initialize(self, state):
        self.prepare(state)
        signed, _ = self._signed(state)
        state.blocks.view(state.x, f"{self.name}-band")[:] = slack_start(
            signed, 0.0, self.held_limit / state.length_scale)

    def columns(self, state):
        return np.c_[state.blocks.index("vertices")[self._held(state)],
                     state.blocks.index(f"{self.name}-band")]

    def evaluate(self, state):
        signed, gradient = self._signed(state)
        s = state.blocks.view(state.x, f"{self.name}-band")
        limit = self.held_limit / state.length_scale
        return signed - limit * np.sin(s), np.c_[gradient, -limit * np.cos(s)]
