"""Exact NURBS design surfaces: rational, general knot vectors, any degree, trimmed.

A `NurbsSurface` is a `ParametricSurface` whose points and first and second derivatives
come from the B-spline basis (The NURBS Book, algorithms A2.2/A2.3, vectorized over
many parameters) and the quotient rule for the rational form (A4.4), so principal
curvatures and directions are exact as for the built-in surfaces, and the distance to
the design is measured to the surface itself by a Newton closest-point projection.

A trimmed face keeps its trims as loops in the parameter domain: the triangulation a
layout runs on covers only the region they bound, so the layout's boundary is the trim.

Knot vectors are in the standard form of ``n + p + 2`` knots for ``n + 1`` control
points of degree ``p`` (Rhino stores ``n + p``, without one superfluous knot at each
end: `fabplan.io.rhino_read` adds them).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import InputError
from ..net.index_rows import unique_rows
from .mesh_surface import DesignSurface
from .parametric import ParametricSurface

__all__ = [
    "NurbsSurface",
    "ClosestPoints",
    "basis_function_derivatives",
    "find_spans",
    "triangulate_trimmed",
    "trims_to_parameters",
]


def find_spans(knots: np.ndarray, degree: int, count: int, t: np.ndarray) -> np.ndarray:
    """(m,) int, the knot span ``i`` with ``knots[i] <= t < knots[i + 1]`` of each
    parameter, kept in ``degree .. count - 1`` (the last span holds the domain's end).

    Parameters
    ----------
    knots : (count + degree + 1,) float, non-decreasing.
    degree : polynomial degree p.
    count : number of control points (n + 1).
    t : (m,) float parameters in the domain ``[knots[p], knots[count]]``.
    """
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, degree, count - 1)


def basis_function_derivatives(knots: np.ndarray, degree: int, span: np.ndarray, t: np.ndarray,
                               order: int) -> np.ndarray:
    """Non-zero B-spline basis functions and their derivatives (NURBS Book A2.3), for
    many parameters at once.

    Parameters
    ----------
    knots : (n + p + 2,) float knot vector.
    degree : p.
    span : (m,) int, spans of `t` (`find_spans`).
    t : (m,) float parameters.
    order : highest derivative wanted (0, 1, 2, ...).

    Returns
    -------
    (m, order + 1, p + 1) float: ``[:, k, r]`` is the k-th derivative of basis function
    ``N[span - p + r]`` at `t` (zero for k > p).

    Examples
    --------
    >>> k = np.array([0, 0, 0, 1, 1, 1.0])          # quadratic Bernstein basis
    >>> d = basis_function_derivatives(k, 2, np.array([2]), np.array([0.5]), 2)
    >>> d[0].tolist()
    [[0.25, 0.5, 0.25], [-1.0, 0.0, 1.0], [2.0, -4.0, 2.0]]
    """
    p = degree
    t = np.asarray(t, dtype=np.float64)
    m = len(t)
    # ndu[:, j, r] for r >= j: basis functions of degree r; below the diagonal: knot differences
    ndu = np.zeros((m, p + 1, p + 1))
    ndu[:, 0, 0] = 1.0
    left = np.zeros((m, p + 1))
    right = np.zeros((m, p + 1))
    for j in range(1, p + 1):
        left[:, j] = t - knots[span + 1 - j]
        right[:, j] = knots[span + j] - t
        saved = np.zeros(m)
        for r in range(j):
            ndu[:, j, r] = right[:, r + 1] + left[:, j - r]
            temp = ndu[:, r, j - 1] / ndu[:, j, r]
            ndu[:, r, j] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        ndu[:, j, j] = saved
    ders = np.zeros((m, order + 1, p + 1))
    ders[:, 0, :] = ndu[:, :, p]
    for r in range(p + 1):
        a = np.zeros((2, m, p + 1))
        a[0, :, 0] = 1.0
        s1, s2 = 0, 1
        for k in range(1, min(order, p) + 1):
            d = np.zeros(m)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, :, 0] = a[s1, :, 0] / ndu[:, pk + 1, rk]
                d = a[s2, :, 0] * ndu[:, rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, :, j] = (a[s1, :, j] - a[s1, :, j - 1]) / ndu[:, pk + 1, rk + j]
                d = d + a[s2, :, j] * ndu[:, rk + j, pk]
            if r <= pk:
                a[s2, :, k] = -a[s1, :, k - 1] / ndu[:, pk + 1, r]
                d = d + a[s2, :, k] * ndu[:, r, pk]
            ders[:, k, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, min(order, p) + 1):
        ders[:, k, :] *= factor
        factor *= p - k
    return ders


@dataclass
class ClosestPoints:
    """Closest points on a NURBS surface (`NurbsSurface.closest_points`).

    Attributes
    ----------
    uv : (m, 2) float, parameters of the closest points.
    points : (m, 3) float, the closest points (model units).
    distances : (m,) float, distance of each query point from its closest point.
    converged : (m,) bool, the first-order condition holds: the offset is normal to the
        surface (its cosine to both tangents below the tolerance, with a floor of 1e-13 of
        the surface's size for the tangential part of points on it), where at an edge of
        the domain a tangent the offset leans out along does not count.
    iterations : Newton iterations taken.
    """

    uv: np.ndarray
    points: np.ndarray
    distances: np.ndarray
    converged: np.ndarray
    iterations: int

    def to_json(self) -> dict:
        return {"points": int(len(self.uv)), "converged": int(self.converged.sum()),
                "iterations": self.iterations,
                "max_distance": float(self.distances.max()) if len(self.distances) else 0.0}


class NurbsSurface(ParametricSurface):
    """A tensor-product NURBS surface with exact derivatives.

    Parameters
    ----------
    control_points : (nu, nv, 3) float, Euclidean control points (model units).
    weights : (nu, nv) float, positive; None for a non-rational surface (all 1).
    knots_u, knots_v : (nu + degree_u + 1,), (nv + degree_v + 1,) float, non-decreasing
        knot vectors (any multiplicities, clamped or not).
    degree_u, degree_v : polynomial degrees (>= 1).
    name : label for messages.
    trims : list of (k, 2) float closed polygons in the parameter domain, the outer loop
        first, then holes; None for the whole domain.
    periodic_u : the surface closes up in u (a seam to wrap across).

    Examples
    --------
    A quarter cylinder of radius 2 as a rational quadratic: its curvatures are 1/2 and 0.

    >>> w = np.sqrt(0.5)
    >>> P = np.array([[[2, 0, 0], [2, 0, 1]], [[2, 2, 0], [2, 2, 1]], [[0, 2, 0], [0, 2, 1]]], float)
    >>> W = np.array([[1, 1], [w, w], [1, 1]])
    >>> s = NurbsSurface(P, W, [0, 0, 0, 1, 1, 1], [0, 0, 1, 1], 2, 1)
    >>> k1, k2, *_ = s.principal_frames(np.array([0.3]), np.array([0.5]))
    >>> sorted(np.round(np.abs([k1[0], k2[0]]), 12).tolist())
    [0.0, 0.5]
    >>> round(float(np.linalg.norm(s.points(0.3, 0.5)[:2])), 12)
    2.0
    """

    def __init__(self, control_points: npt.ArrayLike, weights: npt.ArrayLike | None,
                 knots_u: npt.ArrayLike, knots_v: npt.ArrayLike, degree_u: int, degree_v: int, *,
                 name: str = "nurbs", trims: list[np.ndarray] | None = None,
                 periodic_u: bool = False) -> None:
        P = np.asarray(control_points, dtype=np.float64)
        if P.ndim != 3 or P.shape[2] != 3:
            raise InputError(f"{name}: control points must be an (nu, nv, 3) grid, got shape {P.shape}")
        W = np.ones(P.shape[:2]) if weights is None else np.asarray(weights, dtype=np.float64)
        ku, kv = (np.asarray(k, dtype=np.float64).ravel() for k in (knots_u, knots_v))
        p, q = int(degree_u), int(degree_v)
        if W.shape != P.shape[:2]:
            raise InputError(f"{name}: {W.shape} weights for {P.shape[:2]} control points")
        if not (np.isfinite(P).all() and np.isfinite(W).all() and (W > 0).all()):
            raise InputError(f"{name}: control points must be finite and weights positive")
        for what, knots, degree, count in (("u", ku, p, P.shape[0]), ("v", kv, q, P.shape[1])):
            if degree < 1 or count <= degree:
                raise InputError(f"{name}: degree {degree} in {what} needs more than {degree} "
                                 f"control points, has {count}")
            if len(knots) != count + degree + 1 or np.any(np.diff(knots) < 0) \
                    or not np.isfinite(knots).all():
                raise InputError(f"{name}: the {what} knot vector must be {count + degree + 1} "
                                 f"non-decreasing numbers, got {len(knots)}")
            if not knots[count] > knots[degree]:
                raise InputError(f"{name}: the {what} knot vector spans an empty domain")
        self.control_points, self.weights = P, W
        self.knots_u, self.knots_v = ku, kv
        self.degree_u, self.degree_v = p, q
        self.rational = bool(np.ptp(W) > 0)
        # homogeneous control points (w x, w y, w z, w): the B-spline the rational one divides
        self._homogeneous = np.concatenate([P * W[..., None], W[..., None]], axis=2)
        self.trims = None if trims is None else [np.asarray(t, dtype=np.float64) for t in trims]
        domain = ((float(ku[p]), float(ku[P.shape[0]])), (float(kv[q]), float(kv[P.shape[1]])))
        parameters = {"degree": [p, q], "control_points": list(P.shape[:2]),
                      "rational": self.rational, "knots_u": ku.tolist(), "knots_v": kv.tolist(),
                      "trimmed": self.trims is not None}
        super().__init__(name, self._function, domain, parameters, periodic_u)
        self._own_domain: tuple | None = None       # set on an `extended` copy

    def extended(self, domain: tuple) -> "NurbsSurface":
        """The surface continued on a wider parameter `domain` ``((u0, u1), (v0, v1))``,
        as a design continued past its edges needs (`fabplan.layout.margin`).

        Past its own domain a point is the second-order expansion about the nearest
        point of the domain, with the normal parts of the second derivatives only: the
        continuation meets the surface with its tangent plane and normal curvatures, and
        keeps the edge's parameter speed. (The end spans' polynomials would continue it
        too, but a rational patch's weight may vanish close past its edge, and a
        cubic's turns soon fold the continuation.) Its second derivatives are those at
        the edge. The trims, which bound the design, are not carried."""
        wider = copy.copy(self)
        # the domain and the function are fields of the frozen base class
        object.__setattr__(wider, "domain", tuple(tuple(map(float, d)) for d in domain))
        object.__setattr__(wider, "function", wider._function)
        wider.trims = None
        wider._own_domain = self._own_domain or self.domain
        return wider

    # ------------------------------------------------------------------ evaluation
    def _function(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self.evaluate(np.ravel(u), np.ravel(v), order=0)[0].reshape(np.shape(u) + (3,))

    def evaluate(self, u: npt.ArrayLike, v: npt.ArrayLike, *, order: int = 2) -> list[np.ndarray]:
        """Points and partial derivatives up to `order` (0, 1 or 2).

        Parameters
        ----------
        u, v : (m,) float parameters (clipped to the domain; an `extended` surface is
            continued past its own).

        Returns
        -------
        ``[S]``, ``[S, Su, Sv]`` or ``[S, Su, Sv, Suu, Suv, Svv]``, each (m, 3) float.
        """
        if self._own_domain is None:
            return self._evaluate(u, v, order)
        (u0, u1), (v0, v1) = self.domain
        u = np.clip(np.asarray(u, dtype=np.float64).ravel(), u0, u1)
        v = np.clip(np.asarray(v, dtype=np.float64).ravel(), v0, v1)
        (a0, a1), (b0, b1) = self._own_domain
        at_u, at_v = np.clip(u, a0, a1), np.clip(v, b0, b1)
        du, dv = (u - at_u)[:, None], (v - at_v)[:, None]
        if not (du.any() or dv.any()):
            return self._evaluate(at_u, at_v, order)
        S, Su, Sv, Suu, Suv, Svv = self._evaluate(at_u, at_v, 2)
        # the second derivatives' normal parts only (the second fundamental form): the
        # continuation bends as the surface does across its edge, at the edge's speed
        n = np.cross(Su, Sv)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        L, M, N = (np.sum(D * n, axis=1, keepdims=True) * n for D in (Suu, Suv, Svv))
        P = S + du * Su + dv * Sv + 0.5 * (du * du * L + 2.0 * du * dv * M + dv * dv * N)
        first = [P, Su + du * L + dv * M, Sv + du * M + dv * N]
        return [P] if order == 0 else first if order == 1 else first + [L, M, N]

    def _evaluate(self, u: npt.ArrayLike, v: npt.ArrayLike, order: int) -> list[np.ndarray]:
        """`evaluate` on the surface's own domain (the parameters clipped to it)."""
        (u0, u1), (v0, v1) = self._own_domain or self.domain
        u = np.clip(np.asarray(u, dtype=np.float64).ravel(), u0, u1)
        v = np.clip(np.asarray(v, dtype=np.float64).ravel(), v0, v1)
        p, q = self.degree_u, self.degree_v
        nu, nv = self.control_points.shape[:2]
        su = find_spans(self.knots_u, p, nu, u)
        sv = find_spans(self.knots_v, q, nv, v)
        Nu = basis_function_derivatives(self.knots_u, p, su, u, order)   # (m, order+1, p+1)
        Nv = basis_function_derivatives(self.knots_v, q, sv, v, order)
        iu = su[:, None] - p + np.arange(p + 1)
        iv = sv[:, None] - q + np.arange(q + 1)
        Pw = self._homogeneous[iu[:, :, None], iv[:, None, :]]             # (m, p+1, q+1, 4)

        # all mixed derivatives of the homogeneous surface at once, as two batched products:
        # H[:, k, l] = d^(k+l) / du^k dv^l of (w x, w y, w z, w)
        T = np.matmul(Nv[:, None], Pw)                                      # (m, p+1, order+1, 4)
        m, o = len(u), order + 1
        H = np.matmul(Nu, T.reshape(m, p + 1, 4 * o)).reshape(m, o, o, 4)
        w = H[:, 0, 0, 3:]
        S = H[:, 0, 0, :3] / w
        if order == 0:
            return [S]
        au, av = H[:, 1, 0], H[:, 0, 1]
        Su = (au[:, :3] - au[:, 3:] * S) / w
        Sv = (av[:, :3] - av[:, 3:] * S) / w
        if order == 1:
            return [S, Su, Sv]
        auu, auv, avv = H[:, 2, 0], H[:, 1, 1], H[:, 0, 2]
        Suu = (auu[:, :3] - 2 * au[:, 3:] * Su - auu[:, 3:] * S) / w
        Suv = (auv[:, :3] - au[:, 3:] * Sv - av[:, 3:] * Su - auv[:, 3:] * S) / w
        Svv = (avv[:, :3] - 2 * av[:, 3:] * Sv - avv[:, 3:] * S) / w
        return [S, Su, Sv, Suu, Suv, Svv]

    def derivatives(self, u: np.ndarray, v: np.ndarray) -> tuple:
        """Exact first and second partial derivatives from the NURBS basis.

        Returns
        -------
        fu, fv, fuu, fuv, fvv : (m, 3) float each, for (m,) parameters.
        """
        return tuple(self.evaluate(u, v, order=2)[1:])

    # ------------------------------------------------------------------ closest points
    def _inside(self, uv: np.ndarray) -> np.ndarray:
        (u0, u1), (v0, v1) = self.domain
        u = u0 + np.mod(uv[:, 0] - u0, u1 - u0) if self.periodic_u else np.clip(uv[:, 0], u0, u1)
        return np.stack([u, np.clip(uv[:, 1], v0, v1)], axis=1)

    def sample_parameters(self, per_span: int = 4, minimum: int = 24) -> tuple[np.ndarray, np.ndarray]:
        """Parameter values for a seed grid: `per_span` per knot span, at least `minimum`
        per direction. Returns (a,), (b,) float."""
        out = []
        for knots, degree, count in ((self.knots_u, self.degree_u, self.control_points.shape[0]),
                                     (self.knots_v, self.degree_v, self.control_points.shape[1])):
            inner = np.unique(knots[degree:count + 1])
            steps = np.arange(per_span) / per_span
            fine = np.r_[(inner[:-1, None] + np.diff(inner)[:, None] * steps).ravel(), inner[-1]]
            if len(fine) < minimum:
                fine = np.unique(np.r_[fine, np.linspace(inner[0], inner[-1], minimum)])
            out.append(fine)
        return out[0], out[1]

    def seed_parameters(self, points: np.ndarray) -> np.ndarray:
        """(m, 2) float, parameters of the nearest point of a sampled grid on the surface,
        a start for `closest_parameters`."""
        from scipy.spatial import cKDTree

        a, b = self.sample_parameters()
        U, V = np.meshgrid(a, b, indexing="ij")
        grid = np.stack([U.ravel(), V.ravel()], axis=1)
        _, nearest = cKDTree(self.points(grid[:, 0], grid[:, 1])).query(points)
        return grid[nearest]

    def closest_points(self, points: npt.ArrayLike, start: npt.ArrayLike | None = None, *,
                       iterations: int = 30, tolerance: float = 1e-8) -> ClosestPoints:
        """Closest points on the (untrimmed) surface by Newton's method on
        ``|S(u, v) - p|^2 / 2`` with its exact Hessian.

        Parameters
        ----------
        points : (m, 3) float query points.
        start : (m, 2) float start parameters; None: the nearest point of a sampled grid.
        iterations : Newton iteration cap.
        tolerance : the cosine between the offset and each tangent that counts as normal.

        Returns
        -------
        `ClosestPoints`. A step that does not bring a point closer is halved (up to 8
        times), or replaced by a Gauss-Newton step where the Hessian is not positive
        definite; parameters stay in the domain (u wraps where the surface is periodic).
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        uv = self.seed_parameters(P) if start is None else \
            self._inside(np.array(start, dtype=np.float64).reshape(-1, 2))
        active = np.ones(len(P), bool)
        extent = float(np.ptp(self.control_points.reshape(-1, 3), axis=0).max())
        tiny = (1e-15 * extent) ** 2
        best = np.sum((self.points(uv[:, 0], uv[:, 1]) - P) ** 2, axis=1)
        done = 0
        for done in range(1, iterations + 1):
            idx = np.flatnonzero(active)
            if not len(idx):
                done -= 1
                break
            S, Su, Sv, Suu, Suv, Svv = self.evaluate(uv[idx, 0], uv[idx, 1], order=2)
            r = S - P[idx]
            gu, gv = np.sum(Su * r, axis=1), np.sum(Sv * r, axis=1)
            a, b, c = np.sum(Su * Su, axis=1), np.sum(Su * Sv, axis=1), np.sum(Sv * Sv, axis=1)
            ha, hb, hc = a + np.sum(Suu * r, axis=1), b + np.sum(Suv * r, axis=1), \
                c + np.sum(Svv * r, axis=1)
            det = ha * hc - hb * hb
            newton = (det > 1e-12 * a * c) & (ha > 0)
            ha, hb, hc = np.where(newton, ha, a), np.where(newton, hb, b), np.where(newton, hc, c)
            det = np.maximum(ha * hc - hb * hb, 1e-300)
            step = np.stack([(hc * gu - hb * gv) / det, (ha * gv - hb * gu) / det], axis=1)
            # at the domain's edge, a parameter whose descent leads out stays there and the
            # other one is solved for alone
            pin_u, pin_v = self._outward(uv[idx], gu, gv)
            # a point that already meets a tenth of the tolerance stops here
            allowed = 0.1 * tolerance * np.linalg.norm(r, axis=1) + 1e-14 * extent
            met = (((np.abs(gu) <= allowed * np.sqrt(a)) | pin_u)
                   & ((np.abs(gv) <= allowed * np.sqrt(c)) | pin_v))
            active[idx[met]] = False
            step[pin_u] = np.stack([np.zeros(pin_u.sum()), gv[pin_u] / hc[pin_u]], axis=1)
            step[pin_v] = np.stack([gu[pin_v] / ha[pin_v], np.zeros(pin_v.sum())], axis=1)
            step[(pin_u & pin_v) | met] = 0.0
            moved = np.zeros(len(idx), bool)
            # a full Newton step shorter than a tenth of the distance is taken as it is:
            # there the squared distance no longer resolves the last steps (rounding), and
            # Newton's method converges quadratically
            short = newton & (np.linalg.norm(step[:, :1] * Su + step[:, 1:] * Sv, axis=1)
                              <= 0.1 * np.sqrt(best[idx]))
            for attempt in range(9):
                trial = self._inside(uv[idx] - step)
                d2 = np.sum((self.points(trial[:, 0], trial[:, 1]) - P[idx]) ** 2, axis=1)
                better = ((d2 <= best[idx] * (1 + 1e-12) + tiny) | (short & (attempt == 0))) & ~moved
                uv[idx[better]], best[idx[better]] = trial[better], d2[better]
                moved |= better
                if moved.all():
                    break
                step[~moved] *= 0.5
            # stop a point when its step no longer moves it (measured on the surface)
            shift = np.linalg.norm(step[:, :1] * Su + step[:, 1:] * Sv, axis=1)
            scale = np.sqrt(best[idx]) + 1e-9 * np.sqrt(np.maximum(a, c))
            active[idx[(shift <= 1e-10 * scale) | ~moved]] = False
        foot, Su, Sv = self.evaluate(uv[:, 0], uv[:, 1], order=1)
        offset = foot - P
        distance = np.linalg.norm(offset, axis=1)
        converged = self._stationary(uv, offset, Su, Sv, tolerance)
        return ClosestPoints(uv, foot, distance, converged, done)

    def _outward(self, uv: np.ndarray, gu: np.ndarray, gv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(m,) bool twice: the parameter sits at an edge of the domain and the descent
        direction ``-g`` of the squared distance leads out of it."""
        (u0, u1), (v0, v1) = self.domain
        pin_u = ((uv[:, 0] <= u0) & (gu > 0)) | ((uv[:, 0] >= u1) & (gu < 0))
        pin_v = ((uv[:, 1] <= v0) & (gv > 0)) | ((uv[:, 1] >= v1) & (gv < 0))
        return pin_u & (not self.periodic_u), pin_v

    def _stationary(self, uv: np.ndarray, offset: np.ndarray, Su: np.ndarray, Sv: np.ndarray,
                    tolerance: float) -> np.ndarray:
        """(m,) bool, the first-order condition of a closest point, with the gradient
        component that points out of the domain at its edge set aside."""
        gu, gv = np.sum(Su * offset, axis=1), np.sum(Sv * offset, axis=1)
        pin_u, pin_v = self._outward(uv, gu, gv)
        gu, gv = np.where(pin_u, 0.0, gu), np.where(pin_v, 0.0, gv)
        # the tangential part of the offset: against the distance (a cosine), with a floor
        # at the rounding of the coordinates for points on the surface
        r = np.linalg.norm(offset, axis=1)
        extent = float(np.ptp(self.control_points.reshape(-1, 3), axis=0).max())
        allowed = tolerance * r + 1e-13 * extent
        return (np.abs(gu) <= allowed * np.linalg.norm(Su, axis=1)) & \
            (np.abs(gv) <= allowed * np.linalg.norm(Sv, axis=1))

    def closest_parameters(self, points: np.ndarray, start: np.ndarray, *,
                           iterations: int = 30) -> np.ndarray:
        """(m, 2) float, parameters of the surface points closest to `points` (Newton from
        `start`, see `closest_points`)."""
        return self.closest_points(points, start, iterations=iterations).uv

    # ------------------------------------------------------------------ triangulation
    def triangulate(self, resolution: int | tuple[int, int] = 100) -> DesignSurface:
        """A triangle mesh of the surface: a regular grid of the domain, or for a trimmed
        face the grid cells clipped to its trims (`triangulate_trimmed`)."""
        if self.trims is None:
            return super().triangulate(resolution)
        pair = np.full(2, resolution) if np.isscalar(resolution) else np.asarray(resolution)
        uv, triangles = triangulate_trimmed(self.trims, self.domain, (int(pair[0]), int(pair[1])))
        return DesignSurface(self.points(uv[:, 0], uv[:, 1]), triangles, name=self.name, uv=uv,
                             parametric=self)

    def resolution_for(self, triangles: int) -> tuple[int, int]:
        """Grid cells (nu, nv) giving about `triangles` triangles of near-square shape
        inside the trims."""
        nu, nv = super().resolution_for(triangles)
        if self.trims is None:
            return nu, nv
        (u0, u1), (v0, v1) = self.domain
        share = max(float(_trim_region(self.trims).area) / ((u1 - u0) * (v1 - v0)), 1e-3)
        grow = min(1.0 / np.sqrt(share), 20.0)   # the cells outside the trims are dropped
        return max(2, round(nu * grow)), max(2, round(nv * grow))

    def __reduce__(self):   # a plain constructor call: the bound evaluation is rebuilt
        return (_rebuild_nurbs, (self.control_points, self.weights, self.knots_u, self.knots_v,
                                 self.degree_u, self.degree_v, self.name, self.trims,
                                 self.periodic_u))

    def __repr__(self) -> str:
        nu, nv = self.control_points.shape[:2]
        return (f"NurbsSurface({self.name!r}, degree {self.degree_u}x{self.degree_v}, "
                f"{nu}x{nv} control points, {'rational' if self.rational else 'non-rational'}"
                f"{', trimmed' if self.trims is not None else ''})")


def _rebuild_nurbs(P, W, ku, kv, p, q, name, trims, periodic_u) -> NurbsSurface:
    return NurbsSurface(P, W, ku, kv, p, q, name=name, trims=trims, periodic_u=periodic_u)


def trims_to_parameters(surface: NurbsSurface, loops: list[np.ndarray], *,
                        whole: float = 0.999) -> list[np.ndarray] | None:
    """The trim loops of a face, given as 3D polylines on it, in its parameter domain.

    Parameters
    ----------
    surface : the face's (untrimmed) surface.
    loops : list of (k, 3) float closed polylines on the surface (model units), the outer
        loop first.
    whole : an outer loop bounding at least this share of the domain, with no holes,
        trims nothing (a surface turned into a polysurface keeps its whole domain).

    Returns
    -------
    list of (k, 2) float loops, or None when the face is the whole surface.

    Raises
    ------
    InputError
        When a loop does not lie on the surface (its points farther from it than a
        thousandth of the surface's size), or the loops bound no area.
    """
    import shapely

    extent = float(np.ptp(surface.control_points.reshape(-1, 3), axis=0).max())
    out = []
    for k, loop in enumerate(loops):
        found = surface.closest_points(loop)
        if found.distances.max() > 1e-3 * extent:
            raise InputError(f"{surface.name}: trim loop {k} lies up to {found.distances.max():.3g} "
                             "off its surface (a trim on a closed surface's seam is not supported)")
        out.append(found.uv)
    (u0, u1), (v0, v1) = surface.domain
    region = _trim_region(out)
    if region.is_empty or not region.area > 0:
        raise InputError(f"{surface.name}: the trims bound no area of the surface")
    if len(out) == 1 and shapely.Polygon(out[0]).area >= whole * (u1 - u0) * (v1 - v0):
        return None
    return out


def _trim_region(trims: list[np.ndarray]):
    """The region the trim loops bound (outer loop minus the holes), as a shapely polygon."""
    import shapely

    outer = shapely.Polygon(trims[0])
    holes = [shapely.Polygon(t) for t in trims[1:]]
    region = shapely.make_valid(outer)
    for hole in holes:
        region = shapely.difference(region, shapely.make_valid(hole))
    return region


def triangulate_trimmed(trims: list[np.ndarray], domain: tuple,
                        resolution: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Triangles covering the region bounded by trim loops in a parameter domain.

    The domain is cut into ``nu x nv`` grid cells; every cell is clipped to the region
    and the pieces are split by a constrained Delaunay triangulation. Neighbouring pieces
    meet at the same points (grid nodes and the trims' crossings of the grid lines), so
    the triangles form one conforming mesh whose boundary follows the trims.

    Parameters
    ----------
    trims : list of (k, 2) float closed polygons: the outer loop, then holes.
    domain : ``((u0, u1), (v0, v1))``.
    resolution : grid cells (nu, nv).

    Returns
    -------
    uv : (n, 2) float, parameters of the vertices.
    triangles : (t, 3) int.

    Examples
    --------
    >>> square = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    >>> uv, tri = triangulate_trimmed([square * 2], ((0, 4), (0, 4)), (4, 4))
    >>> len(uv), len(tri)      # a quarter of the domain: 2 x 2 cells, 3 x 3 nodes
    (9, 8)
    """
    import shapely

    (u0, u1), (v0, v1) = domain
    nu, nv = resolution
    region = _trim_region(trims)
    if region.is_empty or not region.area > 0:
        raise InputError("the trims of the face bound no area in its parameter domain")
    a, b = np.linspace(u0, u1, nu + 1), np.linspace(v0, v1, nv + 1)
    cell_u, cell_v = (c.ravel() for c in np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij"))
    cells = shapely.box(a[cell_u], b[cell_v], a[cell_u + 1], b[cell_v + 1])
    # cells crossed by or inside the region, clipped to it
    keep = shapely.intersects(cells, region)
    pieces = shapely.get_parts(shapely.intersection(cells[keep], region))
    pieces = pieces[(shapely.get_type_id(pieces) == 3) & (shapely.area(pieces) > 0)]
    triangles = shapely.get_parts(shapely.constrained_delaunay_triangles(pieces))
    triangles = triangles[shapely.get_type_id(triangles) == 3]
    corners = shapely.get_coordinates(shapely.get_exterior_ring(triangles)).reshape(-1, 4, 2)[:, :3]
    # weld the corners that pieces share (computed separately, equal up to rounding)
    span = max(u1 - u0, v1 - v0)
    key = np.round(corners.reshape(-1, 2) / (1e-9 * span)).astype(np.int64)
    _, first, inverse = unique_rows(key, return_index=True, return_inverse=True)
    uv = corners.reshape(-1, 2)[first]
    tri = inverse.ravel().reshape(-1, 3)
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
    return uv, tri
