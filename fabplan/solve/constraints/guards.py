"""Guards against folding: face normals within a cone around the reference surface's
normal, and the two families of every star kept apart.

A net can meet its sphere conditions exactly while some of its quads turn over (a fold)
or the lines of a star run together. Both guards are inequalities written as smooth
equalities with one auxiliary angle per row, as `EdgeLengthRange` does for edge lengths:
``g(x) = m + r sin(s)`` holds ``g`` in ``[m - r, m + r]`` without switching rows on and off.
"""

from __future__ import annotations

import numpy as np

from .angle import star_angle_cosines
from .base import Constraint

__all__ = ["NormalCone", "StarAngleRange"]


def _slack_start(value: np.ndarray, centre: float, half: float) -> np.ndarray:
    """The auxiliary angle of a value, just inside the range (at sin(s) = +-1 the angle's
    derivative vanishes and Gauss-Newton could not move it off the bound again)."""
    return np.arcsin(np.clip((value - centre) / half, -0.999, 0.999))


class NormalCone(Constraint):
    """``n_f . m_f >= cos(max_angle)`` for every quad f: its normal ``n_f`` (the cross
    product of its diagonals, normalized) within `max_angle_deg` of the reference normal
    ``m_f`` at its centre.

    Parameters
    ----------
    reference : surface with ``closest_points`` (model units), e.g. a `ReferenceSurface`.
    max_angle_deg : half-angle of the cone.
    """

    name = "normal-cone"

    def __init__(self, reference, max_angle_deg: float = 75.0):
        if not 0.0 < max_angle_deg < 180.0:
            raise ValueError(f"the cone's half-angle must lie in (0, 180) degrees, got {max_angle_deg}")
        self.reference = reference
        low = float(np.cos(np.radians(max_angle_deg)))
        self._centre, self._half = 0.5 * (1.0 + low), 0.5 * (1.0 - low)
        self._sign = 1.0

    def declare(self, state):
        return {f"{self.name}-angle": (len(state.mesh.quads),)}

    def _normals(self, state) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        Q = state.X[state.mesh.quads]
        d1, d2 = Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]
        n = np.cross(d1, d2)
        return n, np.linalg.norm(n, axis=1), d1, d2

    def prepare(self, state):
        centres = state.X[state.mesh.quads].mean(axis=1) * state.length_scale + state.origin
        _, self._reference_normals, _ = self.reference.closest_points(centres)

    def initialize(self, state):
        self.prepare(state)
        n, length, _, _ = self._normals(state)
        agree = np.sum(n * self._reference_normals, axis=1) / np.maximum(length, 1e-300)
        # the reference's orientation is a convention: take the one most quads agree with
        self._sign = -1.0 if np.sum(np.sign(agree)) < 0 else 1.0
        state.blocks.view(state.x, f"{self.name}-angle")[:] = _slack_start(
            self._sign * agree, self._centre, self._half)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.mesh.quads].reshape(-1, 12)
        return np.c_[V, state.blocks.index(f"{self.name}-angle")]

    def evaluate(self, state):
        n, length, d1, d2 = self._normals(state)
        length = np.maximum(length, 1e-15)[:, None]
        u = n / length
        m = self._sign * self._reference_normals
        cosine = np.sum(u * m, axis=1, keepdims=True)
        q = (m - cosine * u) / length            # d cosine / d n
        g1, g2 = np.cross(d2, q), np.cross(q, d1)   # d cosine / d d1, d d2
        s = state.blocks.view(state.x, f"{self.name}-angle")
        r = (cosine[:, 0] - self._centre) / self._half - np.sin(s)
        J = np.concatenate([-g1, -g2, g1, g2], axis=1) / self._half
        return r, np.c_[J, -np.cos(s)]


class StarAngleRange(Constraint):
    """The intersection angle of every star within ``[min_angle, 180 - min_angle]``:
    ``cos(t1, t2) = cos(min_angle) sin(s)``, with ``t1, t2`` the osculating tangents.

    Parameters
    ----------
    min_angle_deg : smallest angle between the families at a star.
    """

    name = "star-angle-range"

    def __init__(self, min_angle_deg: float = 15.0):
        if not 0.0 < min_angle_deg < 90.0:
            raise ValueError(f"the smallest star angle must lie in (0, 90) degrees, got {min_angle_deg}")
        self._half = float(np.cos(np.radians(min_angle_deg)))

    def declare(self, state):
        return {f"{self.name}-angle": (len(state.stars),)}

    def initialize(self, state):
        cosine, _ = star_angle_cosines(state)
        state.blocks.view(state.x, f"{self.name}-angle")[:] = _slack_start(cosine, 0.0, self._half)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars].reshape(-1, 15)
        return np.c_[V, state.blocks.index(f"{self.name}-angle")]

    def evaluate(self, state):
        cosine, J = star_angle_cosines(state)
        s = state.blocks.view(state.x, f"{self.name}-angle")
        return cosine / self._half - np.sin(s), np.c_[J / self._half, -np.cos(s)]
