"""Constant intersection angle between the osculating tangents of the two families.

The residual of a star is ``cos(t1, t2) - C`` with ``t1, t2`` the tangents of Lemma 2.12
and ``C`` either a prescribed cosine or one global variable shared by all stars (an
isogonal net of free angle).
"""

from __future__ import annotations

import numpy as np

from ...net.geometry import osculating_tangents
from .base import Constraint

__all__ = ["ConstantAngle", "star_angle_cosines", "inverse_square_jacobian_times"]


def inverse_square_jacobian_times(w: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``d(w / |w|^2)/dw`` (symmetric) applied to ``q``: ``(q - 2 w (w.q) / |w|^2) / |w|^2``."""
    ww = np.sum(w * w, axis=1, keepdims=True)
    return (q - 2 * w * np.sum(w * q, axis=1, keepdims=True) / ww) / ww


class ConstantAngle(Constraint):
    """``cos angle(t1, t2) = C`` at every star.

    Parameters
    ----------
    cosine : the prescribed cosine, or None for a free common angle (global variable).
    """

    name = "angle"

    def __init__(self, cosine: float | None = None):
        self.cosine = cosine

    def declare(self, state):
        return {} if self.cosine is not None else {"cosine": (1,)}

    def initialize(self, state):
        if self.cosine is None:
            t1, t2 = osculating_tangents(state.X, state.stars)
            c = np.sum(t1 * t2, axis=1) / np.linalg.norm(t1, axis=1) / np.linalg.norm(t2, axis=1)
            state.blocks.view(state.x, "cosine")[:] = np.median(c)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars].reshape(-1, 15)
        if self.cosine is None:
            C = np.broadcast_to(state.blocks.index("cosine"), (len(V), 1))
            return np.concatenate([V, C], axis=1)
        return V

    def evaluate(self, state):
        cos, J = star_angle_cosines(state)
        if self.cosine is None:
            C = state.blocks.view(state.x, "cosine")[0]
            return cos - C, np.concatenate([J, -np.ones((len(J), 1))], axis=1)
        return cos - self.cosine, J


def star_angle_cosines(state) -> tuple[np.ndarray, np.ndarray]:
    """Cosine of the angle between the osculating tangents at every star (s,), and its
    derivatives (s, 15) by the star's vertex coordinates ``[v, v1, v2, v3, v4]``."""
    P = state.X[state.stars]
    v = P[:, 0]
    w1, w2, w3, w4 = (P[:, i] - v for i in range(1, 5))
    t1, t2 = osculating_tangents(state.X, state.stars)
    l1, l2 = np.linalg.norm(t1, axis=1, keepdims=True), np.linalg.norm(t2, axis=1, keepdims=True)
    u1, u2 = t1 / l1, t2 / l2
    cos = np.sum(u1 * u2, axis=1, keepdims=True)
    q1 = (u2 - cos * u1) / l1          # d cos / d t1
    q2 = (u1 - cos * u2) / l2          # d cos / d t2
    g1 = inverse_square_jacobian_times(w1, q1)
    g3 = inverse_square_jacobian_times(w3, q1)
    g2 = inverse_square_jacobian_times(w2, q2)
    g4 = inverse_square_jacobian_times(w4, q2)
    # t1 = g(v1 - v) - g(v3 - v), t2 = g(v2 - v) - g(v4 - v)
    J = np.concatenate([-g1 + g3 - g2 + g4, g1, g2, -g3, -g4], axis=1)
    return cos[:, 0], J
