"""Guards against folding and crumpling: face normals within a cone around the reference
surface's normal, the two families of every star kept apart, every quad convex.

A net can meet its sphere conditions exactly while some of its quads turn over (a fold)
or the lines of a star run together. Both guards are inequalities written as smooth
equalities with one auxiliary angle per row, as `EdgeLengthRange` does for edge lengths:
``g(x) = m + r sin(s)`` holds ``g`` in ``[m - r, m + r]`` without switching rows on and off.
"""

from __future__ import annotations

import numpy as np

from .angle import star_angle_cosines
from .base import Constraint

__all__ = ["NormalCone", "StarAngleRange", "ConvexQuads", "slack_start"]


def slack_start(value: np.ndarray, centre: float, half: float) -> np.ndarray:
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
        state.blocks.view(state.x, f"{self.name}-angle")[:] = slack_start(
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
        state.blocks.view(state.x, f"{self.name}-angle")[:] = slack_start(cosine, 0.0, self._half)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars].reshape(-1, 15)
        return np.c_[V, state.blocks.index(f"{self.name}-angle")]

    def evaluate(self, state):
        cosine, J = star_angle_cosines(state)
        s = state.blocks.view(state.x, f"{self.name}-angle")
        return cosine / self._half - np.sin(s), np.c_[J / self._half, -np.cos(s)]


class ConvexQuads(Constraint):
    """Every quad convex: at each corner the boundary turns the way the quad runs, by a
    turn whose sine is at least `min_sine`. With ``a, b`` the edges into and out of the
    corner and ``N = d1 x d2`` the cross product of the quad's diagonals (its normal),
    ``sin(turn) = (a x b) . N / (|a| |b| |N|)`` is held in ``[min_sine, 1]``:
    ``sin(turn) = c + h sin(s)`` with one auxiliary angle per corner. A dart turns
    backwards at its reflex corner (a negative sine); the lower bound also keeps every
    corner's angle within ``[asin(min_sine), 180 - asin(min_sine)]`` degrees.

    Parameters
    ----------
    min_angle_deg : the smallest turn (and inner angle) of a corner, in (0, 90) degrees.
    """

    name = "convex-quads"

    def __init__(self, min_angle_deg: float = 5.0):
        if not 0.0 < min_angle_deg < 90.0:
            raise ValueError(f"the smallest corner angle must lie in (0, 90) degrees, got "
                             f"{min_angle_deg}")
        low = float(np.sin(np.radians(min_angle_deg)))
        self._centre, self._half = 0.5 * (1.0 + low), 0.5 * (1.0 - low)

    def declare(self, state):
        return {f"{self.name}-angle": (len(state.mesh.quads), 4)}

    def _sines(self, state) -> tuple[np.ndarray, np.ndarray]:
        """(q, 4) sines of the corner turns and (q, 4, 12) their derivatives by the quad's
        corner coordinates (corner-major)."""
        Q = state.X[state.mesh.quads]                      # (q, 4, 3)
        d1, d2 = Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]
        N = np.cross(d1, d2)
        n_len = np.maximum(np.linalg.norm(N, axis=1), 1e-300)[:, None]
        a = Q - np.roll(Q, 1, axis=1)                      # into corner i
        b = np.roll(Q, -1, axis=1) - Q                     # out of corner i
        a_len = np.maximum(np.linalg.norm(a, axis=2), 1e-300)[..., None]
        b_len = np.maximum(np.linalg.norm(b, axis=2), 1e-300)[..., None]
        u = np.cross(a, b)                                 # (q, 4, 3)
        Nq = N[:, None, :]
        scale = a_len * b_len * n_len[:, None, :]
        t = np.sum(u * Nq, axis=2, keepdims=True) / scale   # (q, 4, 1)
        grad_a = np.cross(b, Nq) / scale - t * a / a_len**2
        grad_b = np.cross(Nq, a) / scale - t * b / b_len**2
        d1q, d2q = d1[:, None, :], d2[:, None, :]
        grad_d1 = np.cross(d2q, u) / scale - t * np.cross(d2q, Nq) / n_len[:, None, :] ** 2
        grad_d2 = np.cross(u, d1q) / scale - t * np.cross(Nq, d1q) / n_len[:, None, :] ** 2
        J = np.zeros(Q.shape[:2] + (4, 3))                 # (q, corner, vertex, xyz)
        i = np.arange(4)
        # a = p_i - p_(i-1), b = p_(i+1) - p_i
        J[:, i, i] += grad_a - grad_b
        J[:, i, (i - 1) % 4] -= grad_a
        J[:, i, (i + 1) % 4] += grad_b
        # d1 = p_2 - p_0, d2 = p_3 - p_1
        J[:, :, 2] += grad_d1
        J[:, :, 0] -= grad_d1
        J[:, :, 3] += grad_d2
        J[:, :, 1] -= grad_d2
        return t[..., 0], J.reshape(len(Q), 4, 12)

    def initialize(self, state):
        sine, _ = self._sines(state)
        state.blocks.view(state.x, f"{self.name}-angle")[:] = slack_start(
            sine, self._centre, self._half)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.mesh.quads].reshape(-1, 1, 12)
        V = np.broadcast_to(V, (len(V), 4, 12))
        slack = state.blocks.index(f"{self.name}-angle")[..., None]
        return np.concatenate([V, slack], axis=2).reshape(-1, 13)

    def evaluate(self, state):
        sine, J = self._sines(state)
        s = state.blocks.view(state.x, f"{self.name}-angle")
        r = (sine - self._centre) / self._half - np.sin(s)
        J = np.concatenate([J / self._half, -np.cos(s)[..., None]], axis=2)
        return r.ravel(), J.reshape(-1, 13)
