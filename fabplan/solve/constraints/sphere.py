"""The S-net condition: the five vertices of every regular star lie on a sphere (Def. 2.14).

Each star carries a generalized sphere ``a|x - o|^2 + b.(x - o) + c = 0`` (a plane when
``a = 0``) in coordinates centred at the star's own origin ``o``, the centre vertex at the
start of the iteration. With the normalization ``|b|^2 - 4ac = 1`` the residual at a point
is its signed distance to the sphere to first order, ``2a`` is the signed normal
curvature, and ``b`` is the unit sphere normal at ``o``; it is kept pointing against the
discrete normal, so the sign of ``a`` tells on which side the sphere lies.
"""

from __future__ import annotations

import numpy as np

from ...net.geometry import fit_star_spheres, star_normals
from .base import Constraint

__all__ = ["SphereCondition", "SphereNormalization", "rebase_spheres"]


def rebase_spheres(coef: np.ndarray, old_origin: np.ndarray, new_origin: np.ndarray) -> None:
    """Re-express sphere coefficients ``(s, 5)`` about new origins, in place."""
    d = new_origin - old_origin
    a, b = coef[:, 0], coef[:, 1:4]
    coef[:, 4] += a * np.sum(d * d, axis=1) + np.sum(b * d, axis=1)
    coef[:, 1:4] += 2 * a[:, None] * d


class SphereCondition(Constraint):
    """``f_s(v_i) = 0`` for the five vertices of each star: 5 rows per star."""

    name = "sphere"

    def declare(self, state):
        return {"sphere": (len(state.stars), 5)}

    def initialize(self, state):
        X = state.X
        fit = fit_star_spheres(X, state.stars)
        coef = fit.coefficients.copy()
        bad = ~np.isfinite(coef).all(axis=1)
        # a star too degenerate to fit starts as its tangent plane
        coef[bad] = np.c_[np.zeros(bad.sum()), -np.nan_to_num(star_normals(X, state.stars)[bad]),
                          np.zeros(bad.sum())]
        state.blocks.view(state.x, "sphere")[:] = coef
        state.data["sphere_origin"] = X[state.stars[:, 0]].copy()

    def prepare(self, state):
        coef = state.blocks.view(state.x, "sphere")
        new = state.X[state.stars[:, 0]].copy()
        rebase_spheres(coef, state.data["sphere_origin"], new)
        state.data["sphere_origin"] = new
        # keep b against the discrete normal (the representation's orientation)
        n = star_normals(state.X, state.stars)
        flip = np.sum(coef[:, 1:4] * n, axis=1) > 0
        coef[flip] *= -1

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars]       # (s, 5, 3)
        S = state.blocks.index("sphere")                      # (s, 5)
        S = np.broadcast_to(S[:, None, :], (len(S), 5, 5))
        return np.concatenate([V, S], axis=2).reshape(-1, 8)

    def evaluate(self, state):
        coef = state.blocks.view(state.x, "sphere")
        a, b = coef[:, 0:1], coef[:, None, 1:4]
        P = state.X[state.stars] - state.data["sphere_origin"][:, None, :]   # (s, 5, 3)
        pp = np.sum(P * P, axis=2)
        r = a * pp + np.sum(P * b, axis=2) + coef[:, 4:5]
        J = np.concatenate([2 * a[..., None] * P + b, pp[..., None], P,
                            np.ones_like(pp)[..., None]], axis=2)
        return r.ravel(), J.reshape(-1, 8)


class SphereNormalization(Constraint):
    """``|b|^2 - 4ac = 1`` per star, so residuals are distances and ``2a`` a curvature."""

    name = "sphere-normalization"

    def declare(self, state):
        return {"sphere": (len(state.stars), 5)}

    def columns(self, state):
        return state.blocks.index("sphere")

    def evaluate(self, state):
        coef = state.blocks.view(state.x, "sphere")
        a, b, c = coef[:, 0], coef[:, 1:4], coef[:, 4]
        r = np.sum(b * b, axis=1) - 4 * a * c - 1
        J = np.column_stack([-4 * c, 2 * b, -4 * a])
        return r, J
