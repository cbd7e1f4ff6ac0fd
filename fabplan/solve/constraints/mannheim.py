"""S*-nets (section 2.3): nets of oriented tangent planes, given as contact elements.

Every vertex carries a unit normal; its tangent plane passes through the vertex. The five
oriented planes of a star touch one oriented sphere, the Mannheim sphere, with centre
``m`` and signed radius ``rho``: ``n_i . (m - v_i) = rho``. The normal at a star centre
is held orthogonal to both osculating tangents (Def. 2.13), so the planes stay tangent to
the surface the contact points describe. Angles of S*-nets are measured between the cone
rulings of Eq. 5, not between the contact curves.
"""

from __future__ import annotations

import numpy as np

from ...net.geometry import (
    fit_mannheim_spheres,
    osculating_tangents,
    ruling_directions,
    vertex_contact_normals,
)
from .angle import inverse_square_jacobian_times
from .base import Constraint

__all__ = [
    "ContactNormals",
    "NormalNormalization",
    "MannheimTangency",
    "ConstantMannheimRadius",
    "RulingAngle",
]


def _skew(v: np.ndarray) -> np.ndarray:
    """(m, 3, 3) cross-product matrices: ``_skew(a) @ b == a x b``."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1),
                     np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


class ContactNormals(Constraint):
    """``n_v . t1 = 0`` and ``n_v . t2 = 0`` at every star centre (2 rows per star).

    Owns the ``normals`` block and initializes it from the mesh (section 4.3).
    """

    name = "contact-normals"

    def declare(self, state):
        return {"normals": (state.mesh.vertex_count, 3)}

    def initialize(self, state):
        N = state.mesh.normals if state.mesh.normals is not None else \
            vertex_contact_normals(state.mesh, state.X, state.stars)
        state.blocks.view(state.x, "normals")[:] = N

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars].reshape(-1, 15)
        N = state.blocks.index("normals")[state.stars[:, 0]]
        row = np.concatenate([V, N], axis=1)
        return np.repeat(row, 2, axis=0)

    def evaluate(self, state):
        P = state.X[state.stars]
        n = state.blocks.view(state.x, "normals")[state.stars[:, 0]]
        t1, t2 = osculating_tangents(state.X, state.stars)
        w = [P[:, i] - P[:, 0] for i in range(1, 5)]
        # t1 = g(w1) - g(w3), t2 = g(w2) - g(w4) with g(w) = w / |w|^2
        g = [inverse_square_jacobian_times(wi, n) for wi in w]
        zero = np.zeros_like(n)
        J1 = np.concatenate([-g[0] + g[2], g[0], zero, -g[2], zero, t1], axis=1)
        J2 = np.concatenate([-g[1] + g[3], zero, g[1], zero, -g[3], t2], axis=1)
        r = np.stack([np.sum(n * t1, axis=1), np.sum(n * t2, axis=1)], axis=1).ravel()
        return r, np.stack([J1, J2], axis=1).reshape(-1, 18)


class NormalNormalization(Constraint):
    """``|n_v|^2 = 1`` for every vertex."""

    name = "normal-normalization"

    def declare(self, state):
        return {"normals": (state.mesh.vertex_count, 3)}

    def columns(self, state):
        return state.blocks.index("normals")

    def evaluate(self, state):
        n = state.blocks.view(state.x, "normals")
        return np.sum(n * n, axis=1) - 1, 2 * n


class MannheimTangency(Constraint):
    """``n_i . (m_s - v_i) - rho_s = 0`` for the five planes of each star (5 rows per star)."""

    name = "mannheim"

    def declare(self, state):
        return {"normals": (state.mesh.vertex_count, 3), "mannheim": (len(state.stars), 4)}

    def initialize(self, state):
        N = state.blocks.view(state.x, "normals")
        fit = fit_mannheim_spheres(state.X, N, state.stars)
        state.blocks.view(state.x, "mannheim")[:] = np.c_[fit.centre, fit.radius]

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars]            # (s, 5, 3)
        N = state.blocks.index("normals")[state.stars]             # (s, 5, 3)
        M = state.blocks.index("mannheim")                         # (s, 4)
        M = np.broadcast_to(M[:, None, :], (len(M), 5, 4))
        return np.concatenate([V, N, M], axis=2).reshape(-1, 10)

    def evaluate(self, state):
        sphere = state.blocks.view(state.x, "mannheim")
        m, rho = sphere[:, None, :3], sphere[:, None, 3]
        V = state.X[state.stars]
        N = state.blocks.view(state.x, "normals")[state.stars]
        d = m - V
        r = np.sum(N * d, axis=2) - rho
        J = np.concatenate([-N, d, N, -np.ones_like(r)[..., None]], axis=2)
        return r.ravel(), J.reshape(-1, 10)


class ConstantMannheimRadius(Constraint):
    """``rho_s = R`` for every star: prescribed (0 gives a dual A-net) or a free common value.

    Parameters
    ----------
    radius : prescribed signed Mannheim radius in normalized units, or None (free).
    """

    name = "mannheim-radius"

    def __init__(self, radius: float | None = None):
        self.radius = radius

    def declare(self, state):
        blocks = {"mannheim": (len(state.stars), 4)}
        if self.radius is None:
            blocks["mannheim-common"] = (1,)
        return blocks

    def initialize(self, state):
        if self.radius is None:
            rho = state.blocks.view(state.x, "mannheim")[:, 3]
            state.blocks.view(state.x, "mannheim-common")[:] = np.median(rho)

    def columns(self, state):
        R = state.blocks.index("mannheim")[:, 3:]
        if self.radius is None:
            C = np.broadcast_to(state.blocks.index("mannheim-common"), (len(R), 1))
            return np.concatenate([R, C], axis=1)
        return R

    def evaluate(self, state):
        rho = state.blocks.view(state.x, "mannheim")[:, 3]
        if self.radius is None:
            common = state.blocks.view(state.x, "mannheim-common")[0]
            return rho - common, np.tile([1.0, -1.0], (len(rho), 1))
        return rho - self.radius, np.ones((len(rho), 1))


def _ruling_jacobians(p, q1, q3, n, n1, n3):
    """Ruling ``r = a (n x n3) + b (n1 x n)`` of Eq. 5 and its (s, 3, 3) derivatives with
    respect to p, q1, q3, n, n1, n3 (``a = (q1 - p).n1``, ``b = (q3 - p).n3``)."""
    a = np.sum((q1 - p) * n1, axis=1)[:, None, None]
    b = np.sum((q3 - p) * n3, axis=1)[:, None, None]
    c3, c1 = np.cross(n, n3), np.cross(n1, n)
    outer = np.einsum
    d_q1 = outer("si,sj->sij", c3, n1)
    d_q3 = outer("si,sj->sij", c1, n3)
    d_p = -d_q1 - d_q3
    d_n = -a * _skew(n3) + b * _skew(n1)
    d_n1 = outer("si,sj->sij", c3, q1 - p) - b * _skew(n)
    d_n3 = a * _skew(n) + outer("si,sj->sij", c1, q3 - p)
    return d_p, d_q1, d_q3, d_n, d_n1, d_n3


class RulingAngle(Constraint):
    """Angle between the two cone rulings of Eq. 5 at every star.

    Parameters
    ----------
    cosine : prescribed cosine, 0 for orthogonal S*-nets, or None (a free common angle).
        The rulings are lines, so a non-zero cosine is matched in absolute value.
    """

    name = "ruling-angle"

    def __init__(self, cosine: float | None = None):
        self.cosine = cosine

    def declare(self, state):
        blocks = {"normals": (state.mesh.vertex_count, 3)}
        if self.cosine is None:
            blocks["ruling-cosine"] = (1,)
        return blocks

    def initialize(self, state):
        if self.cosine is None:
            N = state.blocks.view(state.x, "normals")
            r1, r2 = ruling_directions(state.X, N, state.stars)
            c = np.abs(np.sum(r1 * r2, axis=1)) / np.linalg.norm(r1, axis=1) / np.linalg.norm(r2, axis=1)
            state.blocks.view(state.x, "ruling-cosine")[:] = np.median(c)

    def columns(self, state):
        V = state.blocks.index("vertices")[state.stars].reshape(-1, 15)
        N = state.blocks.index("normals")[state.stars].reshape(-1, 15)
        cols = np.concatenate([V, N], axis=1)
        if self.cosine is None:
            C = np.broadcast_to(state.blocks.index("ruling-cosine"), (len(V), 1))
            cols = np.concatenate([cols, C], axis=1)
        return cols

    def evaluate(self, state):
        P = state.X[state.stars]
        N = state.blocks.view(state.x, "normals")[state.stars]
        r1, r2 = ruling_directions(state.X, state.blocks.view(state.x, "normals"), state.stars)
        l1 = np.linalg.norm(r1, axis=1, keepdims=True)
        l2 = np.linalg.norm(r2, axis=1, keepdims=True)
        u1, u2 = r1 / l1, r2 / l2
        cos = np.sum(u1 * u2, axis=1, keepdims=True)
        g1 = (u2 - cos * u1) / l1          # d cos / d r1
        g2 = (u1 - cos * u2) / l2          # d cos / d r2
        s = len(P)
        JV, JN = np.zeros((s, 5, 3)), np.zeros((s, 5, 3))
        # family 1 uses the star centre (0) with neighbours 1 and 3, family 2 with 2 and 4
        for g, (i, j) in ((g1, (1, 3)), (g2, (2, 4))):
            d_p, d_q1, d_q3, d_n, d_n1, d_n3 = _ruling_jacobians(
                P[:, 0], P[:, i], P[:, j], N[:, 0], N[:, i], N[:, j])
            for k, D in ((0, d_p), (i, d_q1), (j, d_q3)):
                JV[:, k] += np.einsum("sij,si->sj", D, g)
            for k, D in ((0, d_n), (i, d_n1), (j, d_n3)):
                JN[:, k] += np.einsum("sij,si->sj", D, g)
        J = np.concatenate([JV.reshape(s, 15), JN.reshape(s, 15)], axis=1)
        c = cos[:, 0]
        if self.cosine is None or self.cosine != 0:
            # lines: match |cos| (sign chosen by the current configuration)
            sign = np.where(c < 0, -1.0, 1.0)
            c, J = c * sign, J * sign[:, None]
        if self.cosine is None:
            C = state.blocks.view(state.x, "ruling-cosine")[0]
            return c - C, np.concatenate([J, -np.ones((s, 1))], axis=1)
        return c - self.cosine, J
