"""Fairness: second differences along both families, along the boundary, and the
umbrella operator at irregular vertices (section 4.3.2). Linear in the vertices."""

from __future__ import annotations

import numpy as np

from ...net.fairness import line_turns
from .base import Constraint

__all__ = ["Fairness", "TurningFairness", "fairness_stencils"]


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


class TurningFairness(Constraint):
    """Fairness that stays where lines turn: the second differences of both lines at every
    star, each weighted by how far its line turns past `start_deg` (0 up to it, rising
    smoothly to 1 at `full_deg` and beyond), the weights taken from the turns at the start
    of every iteration (`fabplan.net.fairness.line_turns`; left in ``state.data`` as
    ``"line_turns"`` for the solver's test of an iterate).

    A soft family that does not fade: where a line starts to double back it keeps being
    pulled straight however far the solve has gone, while on lines that turn less it has
    no weight and leaves the constraints to converge.
    """

    name = "turning-fairness"
    hard = False
    fades = False

    def __init__(self, start_deg: float = 45.0, full_deg: float = 90.0):
        if not 0.0 <= start_deg < full_deg:
            raise ValueError(f"the turns must satisfy 0 <= start < full, got {start_deg}, {full_deg}")
        self._start, self._span = np.radians(start_deg), np.radians(full_deg - start_deg)

    def columns(self, state):
        self._verts = np.concatenate([state.stars[:, [1, 0, 3]], state.stars[:, [2, 0, 4]]])
        V = state.blocks.index("vertices")[self._verts]          # (m, 3, 3)
        return V.transpose(0, 2, 1).reshape(-1, 3)

    def prepare(self, state):
        turn, _ = line_turns(state.X, state.stars)              # (s, 2)
        state.data["line_turns"] = turn
        weight = np.clip((turn.T.ravel() - self._start) / self._span, 0.0, 1.0) ** 2
        self._weight = np.repeat(weight, 3)                       # a row per coordinate

    def evaluate(self, state):
        P = state.X[self._verts]
        r = (P[:, 0] - 2 * P[:, 1] + P[:, 2]).ravel() * self._weight
        return r, self._weight[:, None] * np.array([1.0, -2.0, 1.0])
