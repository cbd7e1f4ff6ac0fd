"""Closeness to a reference surface: point-to-plane distance to each vertex's footpoint.

Footpoints and their normals are recomputed at the start of every iteration, so the
linear residual ``n_k . (v_k - p_k)`` lets the net glide along the surface (section 4.2).
Where a vertex has left the surface over its boundary, its footpoint lies on the
boundary and the offset has a part along the surface too: a second row pulls that part
back (it is zero, with a zero Jacobian row, while the footpoint is inside).

As a hard constraint the distance may be held within a band ``|n . (v - p)| <= tol``
instead of at zero: ``n . (v - p) = tol sin(s)`` with one auxiliary variable per vertex.
A net that must be an S-net exactly gains the freedom to leave a curved design by up
to the tolerance (near-umbilics, boundaries), where at zero it could only slide.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["Closeness", "BoundaryGliding", "closest_points_on_polylines"]


class Closeness(Constraint):
    """Vertices on a `fabplan.reference.ReferenceSurface`.

    Parameters
    ----------
    reference : surface in model units, with ``closest_points`` (a `ReferenceSurface`).
    vertices : (k,) int, the vertices it applies to (default: all).
    hard : False: a soft pull that fades out with the other soft terms ("closeness");
        True: a constraint that must hold at convergence, so the net glides on the
        surface ("surface").
    tolerance : with `hard`, the distance allowed off the surface (model units).
    """

    name = "closeness"
    hard = False

    def __init__(self, reference, vertices: np.ndarray | None = None, *, hard: bool = False,
                 tolerance: float = 0.0):
        self.reference = reference
        self.vertices = vertices
        if hard:
            self.hard = True
            self.name = "surface"
        if not tolerance >= 0:
            raise ValueError(f"the distance tolerance must be >= 0, got {tolerance}")
        if tolerance > 0 and not hard:
            raise ValueError("a distance tolerance applies to the hard constraint only")
        self.tolerance = float(tolerance)

    def declare(self, state):
        return {f"{self.name}-band": (len(self._ids(state)),)} if self.tolerance > 0 else {}

    def _ids(self, state):
        return np.arange(state.mesh.vertex_count) if self.vertices is None else self.vertices

    def prepare(self, state):
        model = state.X[self._ids(state)] * state.length_scale + state.origin
        foot, normal, triangle = state.footpoints(self.reference, self.vertices)
        self._foot = (foot - state.origin) / state.length_scale
        self._normal = normal
        # beyond the boundary: the direction from the footpoint along the surface
        d = model - foot
        along = d - np.sum(d * normal, axis=1, keepdims=True) * normal
        length = np.linalg.norm(along, axis=1, keepdims=True)
        outside = (length > 1e-9 * state.length_scale) & \
            self.reference.on_boundary(foot, triangle)[:, None]
        self._outward = np.where(outside, along / np.where(outside, length, 1.0), 0.0)

    def distances(self, state) -> np.ndarray:
        """(k,) float, distance of each vertex from its footpoint (normalized units), as
        found by the last `prepare`."""
        return np.linalg.norm(state.X[self._ids(state)] - self._foot, axis=1)

    def columns(self, state):
        ids = state.blocks.index("vertices")[self._ids(state)]
        if self.tolerance > 0:
            ids = np.concatenate([ids, state.blocks.index(f"{self.name}-band")[:, None]], axis=1)
        return np.repeat(ids, 2, axis=0)

    def evaluate(self, state):
        d = state.X[self._ids(state)] - self._foot
        rows = np.stack([self._normal, self._outward], axis=1)          # (k, 2, 3)
        r = np.einsum("kij,kj->ki", rows, d)
        if self.tolerance <= 0:
            return r.ravel(), rows.reshape(-1, 3)
        band = state.blocks.view(state.x, f"{self.name}-band")
        tol = self.tolerance / state.length_scale
        r[:, 0] -= tol * np.sin(band)
        slack = np.zeros((len(band), 2, 1))
        slack[:, 0, 0] = -tol * np.cos(band)
        return r.ravel(), np.concatenate([rows, slack], axis=2).reshape(-1, 4)


def closest_points_on_polylines(points: np.ndarray, curves: list
                                ) -> tuple[np.ndarray, np.ndarray]:
    """Closest points on a set of polylines and the unit tangents there.

    Parameters
    ----------
    points : (m, 3) float
    curves : list of (k, 3) float, closed polylines (the last vertex joins the first).

    Returns
    -------
    foot : (m, 3) float
    tangent : (m, 3) float, unit direction of the segment holding each footpoint.
    """
    a = np.concatenate([c for c in curves])
    b = np.concatenate([np.roll(c, -1, axis=0) for c in curves])
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    foot = np.empty_like(points)
    seg = np.empty(len(points), dtype=np.int64)
    for lo in range(0, len(points), 256):  # blocks bound the (points x segments) memory
        P = points[lo:lo + 256, None, :]
        t = np.clip(np.sum((P - a) * ab, axis=2) / length2, 0.0, 1.0)
        Q = a + t[..., None] * ab
        best = np.argmin(np.sum((Q - P) ** 2, axis=2), axis=1)
        foot[lo:lo + 256] = Q[np.arange(len(best)), best]
        seg[lo:lo + 256] = best
    return foot, ab[seg] / np.sqrt(length2[seg])[:, None]


class BoundaryGliding(Constraint):
    """Boundary vertices of the net on the boundary curves of the design surface.

    Two rows per vertex: the offset from its footpoint on the nearest boundary curve,
    measured across the curve (the vertex may slide along it). Footpoints are updated
    every iteration.

    Parameters
    ----------
    curves : list of (k, 3) float, closed boundary polylines of the design surface.
    vertices : (b,) int, the net's boundary vertices.
    """

    name = "boundary"

    def __init__(self, curves: list, vertices: np.ndarray):
        self.curves = [np.asarray(c, dtype=np.float64) for c in curves]
        self.vertices = np.asarray(vertices, dtype=np.int64)

    def prepare(self, state):
        model = state.X[self.vertices] * state.length_scale + state.origin
        foot, tangent = closest_points_on_polylines(model, self.curves)
        # two directions across the curve
        helper = np.where(np.abs(tangent[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        u = np.cross(tangent, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        self._across = np.stack([u, np.cross(tangent, u)], axis=1)        # (b, 2, 3)
        self._foot = (foot - state.origin) / state.length_scale

    def columns(self, state):
        return np.repeat(state.blocks.index("vertices")[self.vertices], 2, axis=0)

    def evaluate(self, state):
        d = state.X[self.vertices] - self._foot
        r = np.einsum("bkj,bj->bk", self._across, d).ravel()
        return r, self._across.reshape(-1, 3)
