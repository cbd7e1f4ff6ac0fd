"""A limit on the distance to the reference surface, held inside the solve.

``|n_k . (v_k - p_k)| <= D`` at every vertex, with ``p_k`` its footpoint on the reference
and ``n_k`` the normal there (recomputed every iteration, as for `Closeness`): the band
form of `Closeness` with one auxiliary angle per vertex, ``n . (v - p) = D sin(s)``. It is
an inequality, not a pull: inside the band the net is free, and the limit does not fade.
"""

from __future__ import annotations

import numpy as np

from .closeness import Closeness
from .guards import slack_start

__all__ = ["DeviationBound"]


class DeviationBound(Closeness):
    """Every vertex within `limit` (model units) of the reference surface.

    Parameters
    ----------
    reference : surface in model units, with ``closest_points`` (a `ReferenceSurface`).
    limit : the largest distance allowed (model units, > 0). It may be changed between
        runs of a solver (a continuation tightening it).
    vertices : (k,) int, the vertices it applies to (default: all).
    """

    name = "deviation"

    def __init__(self, reference, limit: float, vertices: np.ndarray | None = None):
        if not (np.isfinite(limit) and limit > 0):
            raise ValueError(f"the deviation limit must be a positive length, got {limit}")
        super().__init__(reference, vertices, hard=True, tolerance=limit)
        self.name = "deviation"

    @property
    def limit(self) -> float:
        return self.tolerance

    @limit.setter
    def limit(self, value: float) -> None:
        self.tolerance = float(value)

    def initialize(self, state):
        self.prepare(state)
        offset = np.sum((state.X[self._ids(state)] - self._foot) * self._normal, axis=1)
        state.blocks.view(state.x, f"{self.name}-band")[:] = slack_start(
            offset, 0.0, self.tolerance / state.length_scale)
