"""Coherent sphere orientation: every Meusnier sphere lies on the same side of the surface.

With ``2a`` the signed normal curvature of a star's sphere, the condition is
``2a_s = sigma * tau_s^2`` with one slack variable ``tau_s`` per star and ``sigma = +-1``
the side taken by most spheres of the initial net (section 4.2, coherent alignment).
"""

from __future__ import annotations

import numpy as np

from .base import Constraint

__all__ = ["CoherentOrientation"]


class CoherentOrientation(Constraint):
    """Keep all sphere centres on one side: ``2 a_s - sigma tau_s^2 = 0``."""

    name = "orientation"

    def declare(self, state):
        return {"sphere": (len(state.stars), 5), "side-slack": (len(state.stars),)}

    def initialize(self, state):
        a = state.blocks.view(state.x, "sphere")[:, 0]
        self.sigma = 1.0 if np.median(a) >= 0 else -1.0
        state.blocks.view(state.x, "side-slack")[:] = np.sqrt(np.maximum(self.sigma * 2 * a, 0))

    def columns(self, state):
        return np.column_stack([state.blocks.index("sphere")[:, 0],
                                state.blocks.index("side-slack")])

    def evaluate(self, state):
        a = state.blocks.view(state.x, "sphere")[:, 0]
        tau = state.blocks.view(state.x, "side-slack")
        J = np.column_stack([np.full(len(a), 2.0), -2 * self.sigma * tau])
        return 2 * a - self.sigma * tau**2, J
