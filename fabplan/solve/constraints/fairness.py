"""Fairness: second differences along both families, along the boundary, and the
umbrella operator at irregular vertices (section 4.3.2). Linear in the vertices."""

from __future__ import annotations

import numpy as np

from ...net.fairness import line_turns
from .base import Constraint

__all__ = ["Fairness", "DisplacementFairness", "fairness_stencils"]


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
    """Soft smoothing term; the solver fades its weight out as the solve converges.

    With `turn_start_deg` and `turn_full_deg`, the rows of the lines' second differences at
    the stars also get a weight that stays where a line turns: `held` (rows,) is 0 where
    the line turns by at most `turn_start_deg`, rising smoothly to 1 at `turn_full_deg`
    and beyond, taken from the turns (`fabplan.net.fairness.line_turns`) at the start of
    every iteration. The solver adds it, with a weight of its own that fades slowly
    (`SolverSettings.turning_fairness_weight`), to the fading one: where a line starts to
    double back it keeps being pulled straight however far the solve has gone, while
    lines that turn less are left to the constraints. The turns are left in
    ``state.data["line_turns"]`` for the solver's test of an iterate.
    """

    name = "fairness"
    hard = False

    def __init__(self, turn_start_deg: float | None = None, turn_full_deg: float | None = None):
        self.turning = turn_start_deg is not None and turn_full_deg is not None
        if self.turning:
            assert turn_start_deg is not None and turn_full_deg is not None
            if not 0.0 <= turn_start_deg < turn_full_deg:
                raise ValueError(f"the turns must satisfy 0 <= start < full, got {turn_start_deg}, "
                                 f"{turn_full_deg}")
            self._start = float(np.radians(turn_start_deg))
            self._span = float(np.radians(turn_full_deg - turn_start_deg))

    def prepare(self, state):
        if not self.turning or len(state.stars) == 0 or not hasattr(self, "_jac"):
            return      # (before `columns`, the solver's first look at the families)
        turn, _ = line_turns(state.X, state.stars)               # (s, 2)
        state.data["line_turns"] = turn
        # the first rows are the stars' second differences, family 0 then 1
        # (`fairness_stencils`), three rows (x, y, z) each
        held = np.zeros(len(self._jac))
        weight = np.clip((turn.T.ravel() - self._start) / self._span, 0.0, 1.0) ** 2
        held[:3 * len(weight)] = np.repeat(weight, 3)
        self.held = held

    def columns(self, state):
        self._verts, coef = fairness_stencils(state.mesh, state.stars)
        self._jac = np.repeat(coef, 3, axis=0)           # rows: stencil-major, then x, y, z
        V = state.blocks.index("vertices")[self._verts]  # (m, k, 3)
        return V.transpose(0, 2, 1).reshape(-1, self._verts.shape[1])

    def evaluate(self, state):
        r = np.einsum("mk,mkj->mj", self._jac[::3], state.X[self._verts]).ravel()
        return r, self._jac



class DisplacementFairness(Constraint):
    """Soft fairness of the move from an anchor net: the second differences of the
    displacement (the `Fairness` stencils) and, `membrane` times, its differences along
    every edge; 3 rows (x, y, z) per stencil and per edge.

    An editor sets `anchor` to the last solved net and `weight` at the start of a drag,
    and fades `weight` itself (the solver's fade of the soft terms runs over all drags):
    the first steps of the solve then move the net as a thin plate that follows the
    handles, instead of the smallest move that meets the constraints, which stays near
    the handles and bends the faces around them into a spike. The second differences
    keep the faces around a handle pulled off the surface as they were (a membrane alone
    would make a cone there); the edge differences keep the move from growing away from
    the handles, which second differences alone allow (a move linear across the net
    costs them nothing). Before an anchor is set the rows are 0.
    """

    name = "displacement-fairness"
    hard = False
    weight: float | None = 0.0

    def __init__(self, membrane: float = 0.3) -> None:
        self.membrane = float(membrane)
        self.anchor: np.ndarray | None = None     # (n, 3) float, normalized positions

    def columns(self, state):
        verts, coef = fairness_stencils(state.mesh, state.stars)
        k = verts.shape[1]
        edges = state.mesh.edges
        # edge rows padded to the stencils' width with their first vertex, coefficient 0
        self._verts = np.concatenate([verts, np.pad(edges, ((0, 0), (0, k - 2)), mode="edge")])
        edge_coef = np.zeros((len(edges), k))
        edge_coef[:, :2] = self.membrane * np.array([1.0, -1.0])
        self._jac = np.repeat(np.concatenate([coef, edge_coef]), 3, axis=0)
        V = state.blocks.index("vertices")[self._verts]  # (m, k, 3)
        return V.transpose(0, 2, 1).reshape(-1, k)

    def evaluate(self, state):
        if self.anchor is None:
            return np.zeros(len(self._jac)), self._jac
        move = state.X - self.anchor
        return np.einsum("mk,mkj->mj", self._jac[::3], move[self._verts]).ravel(), self._jac
