"""Parametric design surfaces by name.

A shape described by a few parameters keeps its function, so the layout can take its
principal directions from the exact fundamental forms instead of estimating them, and
distances to it are measured to the exact surface. `ParametricSurface.triangulate` gives
the `DesignSurface` a layout runs on.

Built-in parametric surfaces (`SURFACES`, looked up with `make_surface` or a spec string
``"name:key=value,key=value"`` with `surface_from_spec`):

=========================  =============================================================
``hyperbolic-paraboloid``  ``z = rise (x / width) (y / depth)`` on a rectangle (K < 0)
``paraboloid``             ``z = x^2 / (2 radius_x) + y^2 / (2 radius_y)``; equal radii
                           put an umbilic at the apex
``torus``                  a patch of a torus of radii ``major``, ``minor``
``revolution``             a tower: a profile ``r(z)`` swept about the z-axis; with
                           ``aspect != 1`` elliptic floors, with ``twist_deg`` floors
                           turning with the height
``tower-facade``           one face of a twisted tower, z up: a vertical hyperbolic
                           paraboloid bent in plan and elevation
``height-field``           ``z = f(x, y)`` from a grid of heights (bicubic spline)
``bspline``                a tensor-product B-spline patch from a grid of control points
=========================  =============================================================
"""


from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import InputError
from ..io.inputs import check_input_file, check_text
from ..io.parameters import surface_parameter
from .mesh_surface import DesignSurface

__all__ = [
    "ParametricSurface",
    "SURFACES",
    "make_surface",
    "surface_parameters",
    "surface_from_spec",
    "describe_surface_parameters",
    "spec_of_surface",
    "hyperbolic_paraboloid",
    "paraboloid",
    "torus_patch",
    "revolution",
    "tower_facade",
    "height_field",
    "bspline_patch",
]


def _row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(m,) float, the dot products of the rows of (m, 3) arrays: ``np.sum(a * b, axis=1)``,
    whose terms numpy adds in this order (the same numbers), without its reduction over
    rows of three, which takes five times as long.

    Examples
    --------
    >>> a = np.array([[1e16, 1.0, -1e16], [0.1, 0.2, 0.3]])
    >>> bool(np.array_equal(_row_dot(a, np.ones((2, 3))), np.sum(a, axis=1)))
    True
    """
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


@dataclass(frozen=True)
class ParametricSurface:
    """A surface ``(u, v) -> xyz`` on a rectangular domain.

    Attributes
    ----------
    name : label used in messages and file headers.
    function : vectorized ``f(u, v) -> (..., 3)`` for broadcastable float arrays.
    domain : ``((u0, u1), (v0, v1))``.
    parameters : the values the surface was built from (reported with results).
    periodic_u : the surface closes up in ``u`` (``f(u0, v) == f(u1, v)``), as a tower
        swept through 360 degrees.

    Examples
    --------
    >>> from fabplan.design.parametric import hyperbolic_paraboloid
    >>> s = hyperbolic_paraboloid(width=2.0, depth=2.0, rise=1.0)
    >>> s.points(np.array([2.0]), np.array([2.0])).tolist()
    [[2.0, 2.0, 1.0]]
    >>> k1, k2, e1, e2, n = s.principal_frames(np.array([0.0]), np.array([0.0]))
    >>> float(k1[0]), float(k2[0])   # z = x y / 4: principal curvatures +-1/4 at the origin
    (0.25, -0.25)
    """

    name: str
    function: Callable[[np.ndarray, np.ndarray], np.ndarray]
    domain: tuple
    parameters: dict = field(default_factory=dict)
    periodic_u: bool = False

    def points(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(..., 3) float, points of the surface at broadcastable parameters."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        return np.asarray(self.function(u, v), dtype=np.float64).reshape(u.shape + (3,))

    def _steps(self) -> tuple[float, float]:
        (u0, u1), (v0, v1) = self.domain
        return 1e-4 * (u1 - u0), 1e-4 * (v1 - v0)

    def derivatives(self, u: np.ndarray, v: np.ndarray) -> tuple:
        """First and second partial derivatives by central differences of the exact function.

        Returns
        -------
        fu, fv, fuu, fuv, fvv : (m, 3) float each, for (m,) parameters.
        """
        u, v = np.asarray(u, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
        du, dv = self._steps()
        f = self.points
        p = f(u, v)
        pu, mu = f(u + du, v), f(u - du, v)
        pv, mv = f(u, v + dv), f(u, v - dv)
        fu, fv = (pu - mu) / (2 * du), (pv - mv) / (2 * dv)
        fuu, fvv = (pu - 2 * p + mu) / du**2, (pv - 2 * p + mv) / dv**2
        fuv = (f(u + du, v + dv) - f(u + du, v - dv) - f(u - du, v + dv)
               + f(u - du, v - dv)) / (4 * du * dv)
        return fu, fv, fuu, fuv, fvv

    def principal_frames(self, u: np.ndarray, v: np.ndarray) -> tuple:
        """Principal curvatures and directions from the fundamental forms.

        Returns
        -------
        k1, k2 : (m,) float, k1 >= k2, signed with respect to ``n`` (1/model units).
        e1, e2 : (m, 3) float, unit principal directions of k1 and k2, ``e2 = n x e1``.
        n : (m, 3) float, unit normal ``fu x fv / |fu x fv|``.
        """
        fu, fv, fuu, fuv, fvv = self.derivatives(u, v)
        n = np.cross(fu, fv)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        E, F, G = (np.sum(a * b, axis=1) for a, b in ((fu, fu), (fu, fv), (fv, fv)))
        e, f, g = (np.sum(a * n, axis=1) for a in (fuu, fuv, fvv))
        # shape operator W = I^-1 II in the (u, v) basis, eigen-decomposed in closed form
        det = E * G - F * F
        a = (G * e - F * f) / det
        b = (G * f - F * g) / det
        c = (E * f - F * e) / det
        d = (E * g - F * f) / det
        half_trace, disc = (a + d) / 2, np.sqrt(np.maximum(((a - d) / 2) ** 2 + b * c, 0.0))
        k1, k2 = half_trace + disc, half_trace - disc
        # eigenvector of k1: (b, k1 - a) or (k1 - d, c), whichever is longer
        x1 = np.stack([b, k1 - a], axis=1)
        x2 = np.stack([k1 - d, c], axis=1)
        x = np.where((np.sum(x1 * x1, axis=1) >= np.sum(x2 * x2, axis=1))[:, None], x1, x2)
        e1 = x[:, :1] * fu + x[:, 1:] * fv
        length = np.linalg.norm(e1, axis=1, keepdims=True)
        umbilic = length[:, 0] < 1e-300
        e1[umbilic] = fu[umbilic]
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e1 -= np.sum(e1 * n, axis=1, keepdims=True) * n
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        return k1, k2, e1, np.cross(n, e1), n

    def closest_parameters(self, points: np.ndarray, start: np.ndarray, *,
                           iterations: int = 8) -> np.ndarray:
        """(m, 2) float, parameters of the surface points closest to `points`: Gauss-Newton
        on ``|f(u, v) - p|^2`` from `start` (m, 2), kept in the domain (``u`` wraps where
        the surface is periodic).

        Examples
        --------
        >>> from fabplan.design.parametric import paraboloid
        >>> s = paraboloid(radius_x=2.0, radius_y=2.0)
        >>> uv = s.closest_parameters(np.array([[1.0, 0.0, 1.0]]), np.array([[0.5, 0.1]]))
        >>> np.round(s.points(uv[:, 0], uv[:, 1]), 4).tolist()   # x^3 + 4 x = 8 on z = x^2 / 4
        [[1.3647, 0.0, 0.4656]]
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        uv = np.array(start, dtype=np.float64).reshape(-1, 2)
        (u0, u1), (v0, v1) = self.domain
        du, dv = self._steps()

        def inside(w):
            u = u0 + np.mod(w[:, 0] - u0, u1 - u0) if self.periodic_u else np.clip(w[:, 0], u0, u1)
            return np.stack([u, np.clip(w[:, 1], v0, v1)], axis=1)

        uv = inside(uv)
        # the surface's points at uv, kept as uv moves (not evaluated again)
        at = self.points(uv[:, 0], uv[:, 1])
        best = _row_dot(at - P, at - P)
        # a point that no trial of an iteration brings closer stays where it is: the next
        # iteration would try the same steps from the same place. Only the others (`live`)
        # are computed, each as in a step of all of them
        live = np.arange(len(P))
        for _ in range(iterations):
            if live.size == 0:
                break
            settled = live.size < len(P)
            Pl, uvl, atl, bestl = P[live], uv[live], at[live], best[live]
            u, v = uvl[:, 0], uvl[:, 1]
            fu = (self.points(u + du, v) - self.points(u - du, v)) / (2 * du)
            fv = (self.points(u, v + dv) - self.points(u, v - dv)) / (2 * dv)
            r = atl - Pl
            a, b, c = _row_dot(fu, fu), _row_dot(fu, fv), _row_dot(fv, fv)
            gu, gv = _row_dot(fu, r), _row_dot(fv, r)
            det = np.maximum(a * c - b * b, 1e-300)
            step = np.stack([(c * gu - b * gv) / det, (a * gv - b * gu) / det], axis=1)
            moves = np.zeros(live.size, bool)
            # a step that does not bring the point closer is halved, up to three times
            for _ in range(4):
                trial = inside(uvl - step)
                moved = self.points(trial[:, 0], trial[:, 1])
                distance = _row_dot(moved - Pl, moved - Pl)
                better = distance < bestl
                column = better[:, None]
                uvl = np.where(column, trial, uvl)
                bestl = np.where(better, distance, bestl)
                atl = np.where(column, moved, atl)
                moves |= better
                # (a settled point is never brought closer: with one, they never all are)
                if better.all() and not settled:
                    break
                step = np.where(column, step, 0.5 * step)
            uv[live], at[live], best[live] = uvl, atl, bestl
            live = live[moves]
        return uv

    def triangulate(self, resolution: int | tuple[int, int] = 100) -> "DesignSurface":
        """A triangle mesh of the surface on a regular grid of the parameter domain.

        Parameters
        ----------
        resolution : grid cells along u and v (one number for both); each cell is split
            into two triangles, alternating diagonals.

        Returns
        -------
        DesignSurface with ``uv`` (n, 2) and this surface attached.
        """
        pair = np.full(2, resolution) if np.isscalar(resolution) else np.asarray(resolution)
        nu, nv = (int(n) for n in pair)
        if nu < 1 or nv < 1:
            raise InputError(f"{self.name}: the triangulation needs at least 1 x 1 cells")
        (u0, u1), (v0, v1) = self.domain
        columns = nu if self.periodic_u else nu + 1
        u = np.linspace(u0, u1, nu + 1)[:columns]
        v = np.linspace(v0, v1, nv + 1)
        U, V = np.meshgrid(u, v, indexing="ij")
        idx = np.arange(columns * (nv + 1)).reshape(columns, nv + 1)
        if self.periodic_u:
            idx = np.concatenate([idx, idx[:1]], axis=0)
        a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
        flip = ((np.arange(nu)[:, None] + np.arange(nv)[None, :]) % 2 == 1)
        t1 = np.where(flip[..., None], np.stack([a, b, d], -1), np.stack([a, b, c], -1))
        t2 = np.where(flip[..., None], np.stack([b, c, d], -1), np.stack([a, c, d], -1))
        triangles = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)])
        uv = np.stack([U.ravel(), V.ravel()], axis=1)
        return DesignSurface(self.points(U, V).reshape(-1, 3), triangles, name=self.name, uv=uv,
                             parametric=self)

    def resolution_for(self, triangles: int) -> tuple[int, int]:
        """Grid cells (nu, nv) giving about `triangles` triangles of near-square shape."""
        (u0, u1), (v0, v1) = self.domain
        um, vm = (u0 + u1) / 2, (v0 + v1) / 2
        su = np.linalg.norm(np.diff(self.points(np.linspace(u0, u1, 65), vm), axis=0), axis=1).sum()
        sv = np.linalg.norm(np.diff(self.points(um, np.linspace(v0, v1, 65)), axis=0), axis=1).sum()
        cells = max(triangles / 2, 1.0)
        nu = max(2, round(math.sqrt(cells * su / sv)))
        return nu, max(2, round(cells / nu))


def hyperbolic_paraboloid(width: float = 10.0, depth: float = 10.0,
                          rise: float = 3.0) -> ParametricSurface:
    """The saddle ``z = rise (x / width) (y / depth)`` over ``[-width, width] x [-depth, depth]``.

    Its Gaussian curvature is negative everywhere: no umbilics.
    """
    _positive(width=width, depth=depth)
    return ParametricSurface(
        "hyperbolic-paraboloid",
        lambda u, v: np.stack([u, v, rise * (u / width) * (v / depth)], axis=-1),
        ((-width, width), (-depth, depth)), dict(width=width, depth=depth, rise=rise))


def paraboloid(radius_x: float = 10.0, radius_y: float = 10.0, width: float = 6.0,
               depth: float = 6.0) -> ParametricSurface:
    """The dome ``z = x^2 / (2 radius_x) + y^2 / (2 radius_y)`` over ``[-width, width] x [-depth, depth]``.

    ``radius_x, radius_y`` are the principal radii at the apex (signed); equal radii make
    the apex an umbilic (the principal directions turn once around it).
    """
    _positive(width=width, depth=depth)
    if radius_x == 0 or radius_y == 0:
        raise InputError("paraboloid: the radii must be non-zero")
    return ParametricSurface(
        "paraboloid",
        lambda u, v: np.stack([u, v, u * u / (2 * radius_x) + v * v / (2 * radius_y)], axis=-1),
        ((-width, width), (-depth, depth)),
        dict(radius_x=radius_x, radius_y=radius_y, width=width, depth=depth))


def torus_patch(major: float = 10.0, minor: float = 4.0, u_deg: tuple = (-45.0, 45.0),
                v_deg: tuple = (-60.0, 60.0)) -> ParametricSurface:
    """A patch of the torus of radii ``major > minor``: ``u`` around the axis, ``v`` around
    the tube (0 on the outer equator), both in degrees. No umbilics."""
    _positive(major=major, minor=minor)
    if minor >= major:
        raise InputError("torus: the minor radius must be smaller than the major radius")

    def f(u, v):
        r = major + minor * np.cos(v)
        return np.stack([r * np.cos(u), r * np.sin(u), minor * np.sin(v)], axis=-1)

    return ParametricSurface("torus", f, (tuple(np.radians(u_deg)), tuple(np.radians(v_deg))),
                             dict(major=major, minor=minor, u_deg=list(u_deg), v_deg=list(v_deg)))


def revolution(profile=None, *, height: float = 40.0, radius: float = 8.0, waist: float = 0.7,
               sweep_deg: float = 360.0, aspect: float = 1.0,
               twist_deg: float = 0.0) -> ParametricSurface:
    """A tower: a profile ``r(z)`` swept about the z-axis.

    Parameters
    ----------
    profile : (k, 2) float, points ``(r, z)`` with increasing z (interpolated by a cubic
        spline), or a vectorized callable ``r(z)`` on ``[0, height]``. Default: a hyperbolic
        waist, ``r(z) = radius sqrt(waist^2 + (1 - waist^2) (2 z / height - 1)^2)``.
    height, radius, waist : the default profile (model units; waist as a fraction).
    sweep_deg : angle swept about the axis; 360 closes the tower (periodic in u).
    aspect : y/x ratio of the floor sections (1: circles, a surface of revolution).
    twist_deg : rotation of the floor sections from bottom to top.

    Returns
    -------
    ParametricSurface with u the angle about the axis (radians) and v the height z.
    """
    described: dict[str, object]
    if profile is None:
        _positive(height=height, radius=radius, waist=waist)

        def r_of_z(z):
            t = 2 * z / height - 1
            return radius * np.sqrt(waist**2 + (1 - waist**2) * t * t)
        z0, z1 = 0.0, height
        described = dict(height=height, radius=radius, waist=waist)
    elif callable(profile):
        r_of_z, z0, z1, described = profile, 0.0, height, dict(height=height, profile="callable")
    else:
        from scipy.interpolate import CubicSpline

        pts = np.asarray(profile, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or np.any(np.diff(pts[:, 1]) <= 0):
            raise InputError("revolution: the profile must be (r, z) points with increasing z")
        if np.any(pts[:, 0] <= 0):
            raise InputError("revolution: the profile radii must be positive")
        r_of_z = CubicSpline(pts[:, 1], pts[:, 0]) if len(pts) > 2 else \
            (lambda z: np.interp(z, pts[:, 1], pts[:, 0]))
        z0, z1, described = pts[0, 1], pts[-1, 1], dict(profile=pts.tolist())
    if not 0 < sweep_deg <= 360 or aspect <= 0:
        raise InputError("revolution: sweep_deg must lie in (0, 360] and aspect be positive")
    twist = math.radians(twist_deg) / (z1 - z0)

    def f(u, v):
        r = r_of_z(v)
        x, y = r * np.cos(u), aspect * r * np.sin(u)
        if twist:
            turn = twist * (v - z0)
            c, s = np.cos(turn), np.sin(turn)
            x, y = c * x - s * y, s * x + c * y
        # untwisted, the turn is by cos 0 = 1 and sin 0 = 0: the same points, without the
        # two sines and cosines that are most of the cost of the closest points
        return np.stack([x, y, v + 0 * u], axis=-1)

    periodic = sweep_deg == 360
    half = math.radians(sweep_deg) / 2
    domain = ((0.0, 2 * math.pi) if periodic else (-half, half), (z0, z1))
    return ParametricSurface("revolution", f, domain,
                             dict(described, sweep_deg=sweep_deg, aspect=aspect,
                                  twist_deg=twist_deg), periodic_u=periodic)


def tower_facade(width: float = 12.0, height: float = 24.0, twist: float = 4.0,
                 plan: float = 0.03, vertical: float = 0.0) -> ParametricSurface:
    """One face of a twisted tower, standing upright (z up).

    ``y = twist (2 x / width) (z / height) + plan x^2 + vertical z^2`` over ``|x| <= width/2``,
    ``0 <= z <= height``: `twist` is the depth by which the face turns from bottom to top
    (a vertical hyperbolic paraboloid whose floor lines are straight), `plan` and
    `vertical` bend it in plan and in elevation (1/model units).
    """
    _positive(width=width, height=height)
    return ParametricSurface(
        "tower-facade",
        lambda u, v: np.stack([u, twist * (2 * u / width) * (v / height) + plan * u * u
                               + vertical * v * v, v], axis=-1),
        ((-width / 2, width / 2), (0.0, height)),
        dict(width=width, height=height, twist=twist, plan=plan, vertical=vertical))


def height_field(heights, *, width: float = 20.0, depth: float = 20.0) -> ParametricSurface:
    """A freeform height field ``z = f(x, y)`` over ``[-width/2, width/2] x
    [-depth/2, depth/2]`` (full sizes; the rows of a grid run along x).

    Parameters
    ----------
    heights : (m, k) float grid of heights over ``[-width/2, width/2] x [-depth/2, depth/2]``
        (interpolated by a bicubic spline, m, k >= 4; row i at x, column j at y), or a
        vectorized callable ``f(x, y)``.
    """
    _positive(width=width, depth=depth)
    if callable(heights):
        func, described = heights, "callable"
    else:
        from scipy.interpolate import RectBivariateSpline

        z = np.asarray(heights, dtype=np.float64)
        if z.ndim != 2 or min(z.shape) < 4 or not np.isfinite(z).all():
            raise InputError("height-field: heights must be a finite grid of at least 4 x 4")
        spline = RectBivariateSpline(np.linspace(-width / 2, width / 2, z.shape[0]),
                                     np.linspace(-depth / 2, depth / 2, z.shape[1]), z)

        def func(x, y):
            return spline.ev(x, y)
        described = z.tolist()
    return ParametricSurface(
        "height-field", lambda u, v: np.stack([u, v, func(u, v) + 0 * u], axis=-1),
        ((-width / 2, width / 2), (-depth / 2, depth / 2)),
        dict(width=width, depth=depth, heights=described))


def bspline_patch(control_points, degree: int = 3) -> ParametricSurface:
    """A tensor-product B-spline patch (clamped, uniform knots) on ``[0, 1]^2``.

    Parameters
    ----------
    control_points : (m, k, 3) float, with m, k > degree.
    degree : polynomial degree in both directions.
    """
    from scipy.interpolate import BSpline

    P = np.asarray(control_points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3 or min(P.shape[:2]) <= degree or not np.isfinite(P).all():
        raise InputError(f"bspline: control points must be a finite (m, k, 3) grid with "
                         f"m, k > degree {degree}")

    def knots(count):
        inner = np.linspace(0.0, 1.0, count - degree + 1)
        return np.r_[np.zeros(degree), inner, np.ones(degree)]

    ku, kv = knots(P.shape[0]), knots(P.shape[1])
    eye_u, eye_v = np.eye(P.shape[0]), np.eye(P.shape[1])

    def f(u, v):
        shape = u.shape
        bu = BSpline(ku, eye_u, degree)(np.clip(u.ravel(), 0.0, 1.0))   # (N, m)
        bv = BSpline(kv, eye_v, degree)(np.clip(v.ravel(), 0.0, 1.0))   # (N, k)
        return np.einsum("ni,nj,ijc->nc", bu, bv, P).reshape(shape + (3,))

    return ParametricSurface("bspline", f, ((0.0, 1.0), (0.0, 1.0)),
                             dict(control_points=P.tolist(), degree=degree))


def _positive(**values) -> None:
    for key, value in values.items():
        if not (value > 0 and math.isfinite(value)):
            raise InputError(f"{key} must be a positive number, got {value}")


SURFACES: dict[str, Callable[..., ParametricSurface]] = {
    "hyperbolic-paraboloid": hyperbolic_paraboloid,
    "paraboloid": paraboloid,
    "torus": torus_patch,
    "revolution": revolution,
    "tower-facade": tower_facade,
    "height-field": height_field,
    "bspline": bspline_patch,
}


REQUIRED = object()   # marks a surface parameter without a default

# the parameters that name a text file in a surface spec (see `surface_from_spec`)
FILE_PARAMETERS = {"heights": "FILE of a height grid", "control_points": "FILE of x y z rows",
                   "profile": "FILE of r z rows"}


def surface_parameters(name: str) -> dict:
    """The parameters of a built-in surface: name -> default (`REQUIRED` where none).

    Examples
    --------
    >>> surface_parameters("paraboloid")
    {'radius_x': 10.0, 'radius_y': 10.0, 'width': 6.0, 'depth': 6.0}
    >>> surface_parameters("height-field")["heights"] is REQUIRED
    True
    """
    import inspect

    return {p.name: (REQUIRED if p.default is inspect.Parameter.empty else p.default)
            for p in inspect.signature(SURFACES[name]).parameters.values()}


def describe_surface_parameters(name: str) -> str:
    """``key=default`` for every parameter of a built-in surface, for messages and help.

    Examples
    --------
    >>> describe_surface_parameters("torus")
    'major=10, minor=4, u_deg=-45..45, v_deg=-60..60'
    """
    def shown(key, value):
        if key in FILE_PARAMETERS:
            return FILE_PARAMETERS[key] + ("" if value is REQUIRED else " (optional)")
        if isinstance(value, tuple):
            return "..".join(f"{v:g}" for v in value)
        return "?" if value is REQUIRED else f"{value:g}"

    return ", ".join(f"{k}={shown(k, v)}" for k, v in surface_parameters(name).items())


def make_surface(name: str, **parameters) -> ParametricSurface:
    """A built-in parametric surface by name (see `SURFACES`) with keyword parameters."""
    if name not in SURFACES:
        raise InputError(f"unknown surface {name!r}; known: {', '.join(SURFACES)}")
    known = surface_parameters(name)
    unknown = [k for k in parameters if k not in known]
    missing = [k for k, v in known.items() if v is REQUIRED and k not in parameters]
    if unknown or missing:
        what = (f"has no parameter {unknown[0]!r}" if unknown else f"needs {missing[0]}="
                f"{FILE_PARAMETERS.get(missing[0], 'VALUE')}")
        raise InputError(f"surface {name!r} {what}; its parameters: "
                         f"{describe_surface_parameters(name)}")
    return SURFACES[name](**{k: _checked(name, k, v) for k, v in parameters.items()})


def _checked(surface: str, key: str, value: object) -> object:
    """A surface parameter checked against its range (`fabplan.io.parameters`): a number
    as a float (an int for a count), a ``LO..HI`` angle range as a pair; a parameter
    without a range (a file's grid, a callable) as it is."""
    parameter = surface_parameter(surface, key)
    if parameter is None:
        return value
    where = f"{surface}: "
    if key not in ("u_deg", "v_deg"):
        return parameter.check(value, where=where)
    if not (isinstance(value, (tuple, list)) and len(value) == 2):
        raise InputError(f"{where}{key} must be a range LO..HI of two angles, got {value!r}")
    low, high = (parameter.check(v, where=where) for v in value)
    if not low < high:
        raise InputError(f"{where}{key} {low:g}..{high:g}: the first angle must be the smaller")
    return (low, high)


def surface_from_spec(spec: str) -> ParametricSurface:
    """A built-in surface from ``"name"`` or ``"name:key=value,key=value"``.

    Values are numbers; ``heights=FILE`` (height-field), ``control_points=FILE``
    (bspline, rows ``x y z`` with the grid shape in a ``# shape m k`` comment or m*k rows
    of a square grid) and ``profile=FILE`` (revolution, rows ``r z``) read text files.

    Examples
    --------
    >>> s = surface_from_spec("hyperbolic-paraboloid:width=5,rise=2")
    >>> s.name, s.parameters["width"], s.parameters["rise"]
    ('hyperbolic-paraboloid', 5.0, 2.0)
    """
    name, _, rest = spec.partition(":")
    parameters: dict = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise InputError(f"surface spec {spec!r}: expected key=value, got {item!r}")
        key = key.strip()
        if key in FILE_PARAMETERS:
            parameters[key] = _read_grid_file(value.strip(), key)
        elif key in ("u_deg", "v_deg"):
            parts = value.split("..")
            if len(parts) != 2:
                raise InputError(f"surface spec {spec!r}: {key} is LO..HI degrees")
            parameters[key] = tuple(parts)     # the numbers are read by `make_surface`
        elif surface_parameter(name, key) is not None or _unknown_parameter(name, key):
            # read and checked by `make_surface`, which names a parameter the surface
            # does not have before reading its value
            parameters[key] = value
        else:
            try:
                parameters[key] = float(value)
            except ValueError:
                raise InputError(f"surface spec {spec!r}: {key} must be a number, got "
                                 f"{value!r}") from None
    return make_surface(name, **parameters)


def _unknown_parameter(surface: str, key: str) -> bool:
    """Whether `key` is no parameter of built-in surface `surface` (an unknown surface
    has none)."""
    return surface not in SURFACES or key not in surface_parameters(surface)


def spec_of_surface(surface: ParametricSurface) -> str | None:
    """The ``"name:key=value,..."`` spec that `surface_from_spec` makes `surface` from again,
    or None where a parameter came from a file (its values are not kept as text).

    Examples
    --------
    >>> spec_of_surface(surface_from_spec("hyperbolic-paraboloid:width=5,rise=2"))
    'hyperbolic-paraboloid:width=5.0,depth=10.0,rise=2.0'
    """
    if surface.name not in SURFACES:      # a NURBS surface, say: made from its file
        return None
    items = []
    for key, value in surface.parameters.items():
        if key in FILE_PARAMETERS:
            return None
        if key in ("u_deg", "v_deg"):
            items.append(f"{key}={float(value[0])!r}..{float(value[1])!r}")
        else:
            items.append(f"{key}={float(value)!r}")
    return surface.name + (":" + ",".join(items) if items else "")


def _read_grid_file(path: str, key: str) -> np.ndarray:
    what = f"a text file of numbers for the surface parameter {key}"
    # a folder, a FIFO, a device or an unreadable file (/proc/self/mem) named as such
    text = check_text(check_input_file(path, what), key)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")      # numpy warns of a file of comments only
            data = np.loadtxt(text.splitlines(), ndmin=2)
    except (ValueError, UserWarning):
        raise InputError(f"{path}: not {what}") from None
    if data.size == 0:
        raise InputError(f"{path}: holds no numbers (the surface parameter {key})")
    if key == "control_points":
        shape = [line.split()[2:] for line in text.splitlines() if line.startswith("# shape")]
        if shape:
            try:
                m, k = (int(s) for s in shape[0])
            except ValueError:
                m = k = -1
        else:
            m = k = int(round(math.sqrt(len(data))))
        if data.shape[1] != 3 or m < 1 or k < 1 or m * k != len(data):
            raise InputError(f"{path}: control points must be m*k rows 'x y z' "
                             "(give '# shape m k' for a non-square grid)")
        return data.reshape(m, k, 3)
    return data
