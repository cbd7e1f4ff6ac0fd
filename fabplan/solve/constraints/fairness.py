"""Fairness: second differences along both families, along the boundary, and the
umbrella operator at irregular vertices (section 4.3.2). Linear in the vertices."""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["Fairness", "fairness_stencils"]


def fairness_stencils(mesh, stars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex rows and coefficient rows of every fairness stencil.

    Returns
    -------
    verts : (m, k) int, stencil vertices; short stencils are padded with their first vertex.
    coef : (m, k) float, coefficients (0 on padding).
    """
    second = [stars[:, [1, 0, 3]], stars[:, [2, 0, 4]], mesh.boundary_triples]
    irregular = mesh.irregular_vertices
    deg = np.zeros(0, dtype=np.int64)
    if irregular.size:
        indptr, nbrs = mesh.neighbours(irregular)
        deg = np.diff(indptr)
    k = max(3, int(deg.max()) + 1 if deg.size else 3)
    verts = [np.pad(r, ((0, 0), (0, k - 3)), mode="edge") for r in second]
    coef = [np.tile(np.r_[1.0, -2.0, 1.0, np.zeros(k - 3)], (len(r), 1)) for r in second]
    if irregular.size:
        umbrella = np.repeat(irregular[:, None], k, axis=1)
        weights = np.zeros((len(irregular), k))
        owner = np.repeat(np.arange(len(irregular)), deg)
        slot = np.arange(len(nbrs)) - np.repeat(indptr[:-1], deg) + 1
        umbrella[owner, slot] = nbrs
        weights[owner, slot] = 1.0
        weights[:, 0] = -deg
        verts.append(umbrella)
        coef.append(weights)
    return np.concatenate(verts), np.concatenate(coef)


class Fairness(Constraint):
    """Soft smoothing term; the solver fades its weight out as the solve converges."""

    name = "fairness"
    hard = False

    def columns(self, state):
        self._verts, coef = fairness_stencils(state.mesh, state.stars)
        self._jac = np.repeat(coef, 3, axis=0)           # rows: stencil-major, then x, y, z
        V = state.blocks.index("vertices")[self._verts]  # (m, k, 3)
        return V.transpose(0, 2, 1).reshape(-1, self._verts.shape[1])

    def evaluate(self, state):
        r = np.einsum("mk,mkj->mj", self._jac[::3], state.X[self._verts]).ravel()
        return r, self._jac
