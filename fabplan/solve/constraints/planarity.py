"""Planar quads: the four vertices of every quad lie on one plane (section 3.6).

Each quad carries a plane ``n.x + d = 0`` with ``|n| = 1``; S-nets with planar faces are
the characteristic conjugate nets, paneled with flat glass.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["PlanarFaces", "PlaneNormalization"]


class PlanarFaces(Constraint):
    """``n_f . v + d_f = 0`` for the four vertices of every quad: 4 rows per quad."""

    name = "planar-faces"

    def declare(self, state):
        return {"face-plane": (len(state.mesh.quads), 4)}

    def initialize(self, state):
        P = state.X[state.mesh.quads]
        centre = P.mean(axis=1)
        _, _, vt = np.linalg.svd(P - centre[:, None, :])
        n = vt[:, -1, :]
        state.blocks.view(state.x, "face-plane")[:] = np.c_[n, -np.sum(n * centre, axis=1)]

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
