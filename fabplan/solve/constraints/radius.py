"""Common Meusnier sphere radius: every star's normal curvature ``2a`` equals one value.

The value is either prescribed (a signed curvature in normalized units; zero gives
planar stars, the A-net condition) or one global variable shared by all stars.
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["ConstantCurvature"]


class ConstantCurvature(Constraint):
    """``2 a_s = K`` for every star ``s``.

    Parameters
    ----------
    curvature : prescribed signed normal curvature in normalized units, or None for a
        free common value (global variable ``curvature``).
    """

    name = "radius"

    def __init__(self, curvature: float | None = None):
        self.curvature = curvature

    def declare(self, state):
        blocks = {"sphere": (len(state.stars), 5)}
        if self.curvature is None:
            blocks["curvature"] = (1,)
        return blocks

    def initialize(self, state):
        if self.curvature is None:
            a = state.blocks.view(state.x, "sphere")[:, 0]
            state.blocks.view(state.x, "curvature")[:] = np.median(2 * a)

    def columns(self, state):
        A = state.blocks.index("sphere")[:, :1]
        if self.curvature is None:
            K = np.broadcast_to(state.blocks.index("curvature"), (len(A), 1))
            return np.concatenate([A, K], axis=1)
        return A

    def evaluate(self, state):
        a = state.blocks.view(state.x, "sphere")[:, 0]
        if self.curvature is None:
            K = state.blocks.view(state.x, "curvature")[0]
            return 2 * a - K, np.tile([2.0, -1.0], (len(a), 1))
        return 2 * a - self.curvature, np.full((len(a), 1), 2.0)
