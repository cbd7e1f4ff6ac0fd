"""Planar quads: the four vertices of every quad lie on one plane (section 3.6).

Each quad carries a plane ``n.x + d = 0`` with ``|n| = 1``; S-nets with planar faces are
the characteristic conjugate nets, paneled with flat glass. A study that asks for flat
panels within a tolerance holds every other net type to it with `PlanarityBound`: each
corner within the tolerance of its quad's plane, an inequality like `DeviationBound`.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint
from .guards import slack_start

__all__ = ["PlanarFaces", "PlaneNormalization", "PlanarityBound"]


def best_fit_planes(P: np.ndarray) -> np.ndarray:
    """(q, 4) float, the plane ``(n, d)`` (``|n| = 1``) of least squares through each
    quad's corners `P` (q, 4, 3)."""
    centre = P.mean(axis=1)
    _, _, vt = np.linalg.svd(P - centre[:, None, :])
    n = vt[:, -1, :]
    return np.c_[n, -np.sum(n * centre, axis=1)]


class PlanarFaces(Constraint):
    """``n_f . v + d_f = 0`` for the four vertices of every quad: 4 rows per quad."""

    name = "planar-faces"

    def declare(self, state):
        return {"face-plane": (len(state.mesh.quads), 4)}

    def initialize(self, state):
        state.blocks.view(state.x, "face-plane")[:] = best_fit_planes(state.X[state.mesh.quads])

    def columns(self, state):
        V = state.blocks.index("vertices")[state.mesh.quads]            # (q, 4, 3)
        F = state.blocks.index("face-plane")                            # (q, 4)
        F = np.broadcast_to(F[:, None, :], (len(F), 4, 4))
        return np.concatenate([V, F], axis=2).reshape(-1, 7)

    def evaluate(self, state):
        plane = state.blocks.view(state.x, "face-plane")
        n, d = plane[:, None, :3], plane[:, None, 3:]
        P = state.X[state.mesh.quads]
        r = np.sum(P * n, axis=2) + d[..., 0]
        J = np.concatenate([np.broadcast_to(n, P.shape), P, np.ones_like(P[..., :1])], axis=2)
        return r.ravel(), J.reshape(-1, 7)


class PlaneNormalization(Constraint):
    """``|n_f|^2 = 1`` per quad, so the plane residuals are distances."""

    name = "plane-normalization"

    def declare(self, state):
        return {"face-plane": (len(state.mesh.quads), 4)}

    def columns(self, state):
        return state.blocks.index("face-plane")[:, :3]

    def evaluate(self, state):
        n = state.blocks.view(state.x, "face-plane")[:, :3]
        return np.sum(n * n, axis=1) - 1, 2 * n


class PlanarityBound(PlanarFaces):
    """Every quad's corners within `limit` (model units) of its plane: ``n_f . v + d_f =
    limit sin(s)`` with one auxiliary angle per corner, so that inside the band the net is
    free. `PlanarFaces` with a band: solved with `PlaneNormalization` (the plane residuals
    are then distances).

    Parameters
    ----------
    limit : the largest distance of a corner from its quad's plane (model units, > 0).
    """

    name = "planarity-bound"

    def __init__(self, limit: float):
        if not (np.isfinite(limit) and limit > 0):
            raise ValueError(f"the planarity limit must be a positive length, got {limit}")
        self.limit = float(limit)

    def declare(self, state):
        return {**super().declare(state), "planarity-band": (len(state.mesh.quads), 4)}

    def initialize(self, state):
        super().initialize(state)
        r, _ = super().evaluate(state)
        state.blocks.view(state.x, "planarity-band")[:] = slack_start(
            r.reshape(-1, 4), 0.0, self.limit / state.length_scale)

    def columns(self, state):
        band = state.blocks.index("planarity-band").reshape(-1, 1)
        return np.concatenate([super().columns(state), band], axis=1)

    def evaluate(self, state):
        r, J = super().evaluate(state)
        s = state.blocks.view(state.x, "planarity-band").ravel()
        limit = self.limit / state.length_scale
        return r - limit * np.sin(s), np.concatenate([J, -limit * np.cos(s)[:, None]], axis=1)
