"""Generated meshes: exact S-nets on surfaces of revolution, and grids on height fields.

Both are starting points and ground truth for tests and benchmarks: a rotational S-net is
an S-net by construction (to rounding), at any size, so a solver run on a perturbed copy has
a known solution nearby; a height-field grid is a plain quad grid with a prescribed angle
between its families in plan view.

Rotational S-nets
-----------------
On a surface of revolution ``p(s, phi) = (r(s) cos phi, r(s) sin phi, z(s))`` put vertex
``(i, j)`` at ``phi = (i + j) d / 2`` and on the parallel of meridian level ``l = j - i``,
at a curve parameter ``s_l`` that increases with ``l``. The two mesh families run
diagonally to meridians and parallels. Each star is mirror-symmetric in the meridian plane
through its centre (the reflection swaps ``(i + 1, j)`` with ``(i, j - 1)`` and
``(i - 1, j)`` with ``(i, j + 1)``), and a sphere through ``v``, ``(i + 1, j)`` and
``(i, j + 1)`` whose centre lies on that plane also passes through their mirror images: the
five vertices lie exactly on a sphere, whatever the increasing sequence ``s_l``.

The levels are spaced evenly in the conformal meridian coordinate
``u(s) = int |p'(s)| / r(s) ds``, so the faces are close to rhombi of equal shape, and the
families meet at nearly ``angle_deg`` everywhere (loxodromes of a conformal map meet at a
constant angle). With ``isogonal=True`` the levels are instead found one after the other so
that the discrete intersection angle (between the osculating-circle tangents, Lemma 2.12)
is exactly ``angle_deg`` at every star. On the sphere profile every star's Meusnier sphere
is the sphere itself, so ``rotational_snet(..., profile="sphere", isogonal=True)`` is an
exact linear Weingarten S-net (isogonal, constant radius) of any size, if a degenerate one.
`rotational_weingarten_snet` builds the meridian itself, level by level, so that every star
has one prescribed angle and one prescribed Meusnier radius: exact linear Weingarten S-nets
of revolution that are not spheres, with positive or negative Gaussian curvature.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import partial
from typing import Callable

import numpy as np
from scipy.optimize import brentq, fsolve

from ..errors import InputError
from .geometry import circumcircle_tangent
from .mesh import QuadMesh

__all__ = ["Profile", "PROFILES", "rotational_snet", "rotational_weingarten_snet",
           "height_field_grid"]


@dataclass(frozen=True)
class Profile:
    """A meridian curve ``s -> (r(s), z(s))`` of a surface of revolution about the z-axis.

    Attributes
    ----------
    name : the name `rotational_snet` accepts.
    radius : vectorized ``r(s)``, distance from the axis, positive on `domain`.
    height : vectorized ``z(s)``, increasing ``s`` should move upwards or outwards so that
        the generated faces have normals pointing away from the axis.
    domain : open interval of valid ``s``.
    centre : ``s`` of the middle meridian level of a generated grid.
    summary : the surface in one line, with the sign of its Gaussian curvature.
    """

    name: str
    radius: Callable[[np.ndarray], np.ndarray]
    height: Callable[[np.ndarray], np.ndarray]
    domain: tuple[float, float]
    centre: float
    summary: str = ""

    def points(self, s: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """(..., 3) float, points ``p(s, phi)`` for broadcastable ``s`` and ``phi``."""
        s, phi = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(phi, dtype=np.float64))
        r = self.radius(s)
        return np.stack([r * np.cos(phi), r * np.sin(phi), self.height(s) + 0 * s], axis=-1)

    def conformal_table(self, samples: int = 1 << 17) -> tuple[np.ndarray, np.ndarray]:
        """Sampled ``(s, u(s))``, with ``u`` the conformal meridian coordinate, 0 at `centre`.

        ``u`` is integrated along the polyline of the samples; its accuracy only affects how
        evenly the levels are spaced, never whether the result is an S-net.
        """
        lo, hi = self.domain
        s = np.linspace(lo, hi, samples)
        r, z = self.radius(s), self.height(s) + 0 * s
        mid_r = self.radius((s[1:] + s[:-1]) / 2)
        du = np.hypot(np.diff(r), np.diff(z)) / mid_r
        u = np.concatenate([[0.0], np.cumsum(du)])
        return s, u - np.interp(self.centre, s, u)


PROFILES: dict[str, Profile] = {p.name: p for p in [
    Profile("sphere", np.sin, lambda s: -np.cos(s), (1e-6, math.pi - 1e-6), math.pi / 2,
            "unit sphere, s the polar angle from the south pole, centred on the equator (K > 0)"),
    Profile("paraboloid", lambda s: s, lambda s: s * s / 2, (1e-4, 40.0), 2.0,
            "z = r^2 / 2, centred on the parallel r = 2 (K > 0)"),
    Profile("catenoid", np.cosh, lambda s: s, (-10.0, 10.0), 0.0,
            "r = cosh z, centred on the neck (minimal, K < 0)"),
    Profile("hyperboloid", lambda s: np.sqrt(1 + s * s), lambda s: s, (-100.0, 100.0), 0.0,
            "one-sheeted hyperboloid r^2 - z^2 = 1, centred on the neck (K < 0)"),
]}


def _meridian_star(pa: np.ndarray, pb: np.ndarray, pc: np.ndarray, half_step: float) -> tuple:
    """Points ``v, v1, v2, v3, v4`` of a star centred at ``phi = 0`` on meridian point ``pb``.

    ``pa, pb, pc`` are ``(..., 2)`` meridian points ``(r, z)`` of the levels before, at and
    after the centre; the neighbours lie at ``phi = +-half_step``.
    """
    def point(p, phi):
        return np.stack([p[..., 0] * np.cos(phi), p[..., 0] * np.sin(phi), p[..., 1]], axis=-1)

    return (point(pb, 0.0), point(pa, half_step), point(pc, half_step), point(pc, -half_step),
            point(pa, -half_step))


def _star_cosine(v, v1, v2, v3, v4):
    """Cosine of the discrete intersection angle (between the osculating-circle tangents)."""
    t1 = circumcircle_tangent(v, v1, v3)
    t2 = circumcircle_tangent(v, v2, v4)
    return np.sum(t1 * t2, axis=-1) / np.linalg.norm(t1, axis=-1) / np.linalg.norm(t2, axis=-1)


def _star_curvature(v, v1, v2, v3, v4):
    """Curvature ``1 / radius`` of the sphere of a star mirror-symmetric in the plane y = 0.

    Its centre lies on that plane, equidistant from ``v, v1, v2`` (a 2 x 2 linear system).
    """
    rows = 2 * np.stack([(v1 - v)[..., [0, 2]], (v2 - v)[..., [0, 2]]], axis=-2)
    rhs = np.stack([np.sum(v1 * v1 - v * v, axis=-1), np.sum(v2 * v2 - v * v, axis=-1)], axis=-1)
    centre = np.linalg.solve(rows, rhs[..., None])[..., 0]
    return 1 / np.hypot(centre[..., 0] - v[..., 0], centre[..., 1] - v[..., 2])


def _level_cosine(profile: Profile, s_prev, s_mid, s_next, half_step: float):
    """Cosine of the discrete intersection angle of a star centred on level ``s_mid``."""
    def rz(s):
        s = np.asarray(s, dtype=np.float64)
        return np.stack([profile.radius(s), profile.height(s) + 0 * s], axis=-1)

    return _star_cosine(*_meridian_star(rz(s_prev), rz(s_mid), rz(s_next), half_step))


def _solve_level(f: Callable[[float], float], base: float, guess: float) -> float:
    """Root of ``f`` between ``base`` and ``base + 2 (guess - base)``, where it is expected."""
    step = guess - base
    lo, hi = base + 0.5 * step, base + 1.5 * step
    for _ in range(8):
        if f(lo) * f(hi) <= 0:
            return brentq(f, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps)
        lo, hi = base + (lo - base) / 2, base + 2 * (hi - base)
    raise InputError("rotational_snet: no meridian level gives the requested constant angle; "
                     "use a smaller span_deg or isogonal=False")


def _isogonal_levels(profile: Profile, levels: np.ndarray, half_step: float,
                     cosine: float) -> np.ndarray:
    """Meridian levels with the discrete angle ``arccos(cosine)`` at every interior level.

    Starts from three levels around the middle (the outer one solved for the angle) and
    marches outwards, each new level solving one scalar equation. The march is sequential by
    nature: it runs once per generated mesh, over levels (not vertices).
    """
    s = levels.copy()
    c = (len(s) - 1) // 2

    def solve_up(at):
        s[at + 1] = _solve_level(
            lambda x: float(_level_cosine(profile, s[at - 1], s[at], x, half_step)) - cosine,
            s[at], s[at] + (levels[at + 1] - levels[at]) * (s[at] - s[at - 1])
            / (levels[at] - levels[at - 1]))

    def solve_down(at):
        s[at - 1] = _solve_level(
            lambda x: float(_level_cosine(profile, x, s[at], s[at + 1], half_step)) - cosine,
            s[at], s[at] - (levels[at] - levels[at - 1]) * (s[at + 1] - s[at])
            / (levels[at + 1] - levels[at]))

    for level in range(c, len(s) - 1):
        solve_up(level)
    for level in range(c, 0, -1):
        solve_down(level)
    return s


def _levels_and_half_step(name: str, m: int, k: int, span_deg: float,
                          step: float | None) -> tuple[int, float]:
    """Number of levels of an (m, k) diagonal net and half its longitude step (radians)."""
    n_levels = m + k - 1
    d = 2 * math.radians(span_deg) / (n_levels - 1) if step is None else float(step)
    half = d / 2
    if not 0 < half * (n_levels - 1) < 2 * math.pi:
        raise InputError(f"{name}: the grid would cover {math.degrees(half * (n_levels - 1)):.4g}"
                         " degrees of longitude; it must be positive and below 360 (reduce step or "
                         "span_deg)")
    return n_levels, half


def rotational_snet(m: int, k: int, *, profile: str | Profile = "catenoid",
                    step: float | None = None, span_deg: float = 90.0, angle_deg: float = 90.0,
                    isogonal: bool = False, scale: float = 1.0) -> QuadMesh:
    """An exact S-net of ``m x k`` vertices on a surface of revolution.

    Parameters
    ----------
    m, k : vertices along the two families (both at least 2); ``(m - 2)(k - 2)`` stars.
    profile : a name from `PROFILES` (``"sphere"``, ``"paraboloid"``: positive Gaussian
        curvature; ``"catenoid"``, ``"hyperboloid"``: negative), or a `Profile`.
    step : angular increment ``d`` in radians between vertices ``(i, j)`` and
        ``(i + 1, j + 1)``; an edge spans ``d / 2`` in longitude. Default: the grid spans
        `span_deg` of longitude, ``d = 2 radians(span_deg) / (m + k - 2)``.
    span_deg : longitude covered by the grid when `step` is not given (degrees, below 360).
    angle_deg : intersection angle of the two families, in degrees: the limit angle of the
        conformal spacing, or the exact discrete angle when `isogonal` is set. It fixes the
        ratio of the meridian step (in the conformal coordinate) to the longitude step,
        ``tan(angle_deg / 2)``; the grid reaches ``+-tan(angle_deg / 2) * span / 2`` in the
        conformal meridian coordinate around the profile's centre.
    isogonal : solve the meridian levels so that every star has the same discrete angle.
    scale : factor applied to all coordinates (the profiles have unit size).

    Returns
    -------
    QuadMesh with ``m * k`` vertices ``(i, j)`` at row ``i * k + j``, faces from
    `QuadMesh.grid` (counter-clockwise in ``(i, j)``, normals pointing away from the axis),
    symmetric about the xz-plane.

    Raises
    ------
    InputError
        For fewer than 2 vertices along a family, a longitude span of 360 degrees or more,
        an angle outside (0, 180), or a grid reaching beyond the profile's domain.

    Examples
    --------
    >>> from fabplan.net.generate import rotational_snet
    >>> from fabplan.net.geometry import fit_star_spheres
    >>> net = rotational_snet(12, 9, profile="catenoid")
    >>> net.vertex_count, len(net.faces), len(net.stars)
    (108, 88, 70)
    >>> bool(fit_star_spheres(net.vertices, net.stars).residual.max() < 1e-12)
    True
    """
    if isinstance(profile, str):
        if profile not in PROFILES:
            raise InputError(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
        profile = PROFILES[profile]
    if m < 2 or k < 2:
        raise InputError(f"rotational_snet needs at least 2 x 2 vertices, got {m} x {k}")
    if not 0.0 < angle_deg < 180.0:
        raise InputError(f"angle_deg must lie strictly between 0 and 180, got {angle_deg}")
    n_levels, half = _levels_and_half_step("rotational_snet", m, k, span_deg, step)
    aspect = math.tan(math.radians(angle_deg) / 2)
    level = np.arange(n_levels) - (n_levels - 1) / 2
    s_table, u_table = profile.conformal_table()
    u = level * aspect * half
    if u[0] < u_table[0] or u[-1] > u_table[-1]:
        raise InputError(f"rotational_snet: the grid leaves the domain {profile.domain} of profile "
                         f"{profile.name!r}; reduce span_deg, step or angle_deg")
    s = np.interp(u, u_table, s_table)
    if isogonal and n_levels >= 3:
        s = _isogonal_levels(profile, s, half, math.cos(math.radians(angle_deg)))
        if s[0] <= profile.domain[0] or s[-1] >= profile.domain[1]:
            raise InputError(f"rotational_snet: the isogonal levels leave the domain {profile.domain} "
                             f"of profile {profile.name!r}; reduce span_deg, step or angle_deg")
    i, j = np.meshgrid(np.arange(m), np.arange(k), indexing="ij")
    phi = (i + j - (m + k - 2) / 2) * half
    points = scale * profile.points(s[j - i + m - 1], phi)
    return QuadMesh.grid(points, name=f"rotational-{profile.name}-{m}x{k}")


def _solve_point(f: Callable[[np.ndarray], np.ndarray], guess: np.ndarray) -> np.ndarray:
    """Root of a map of the meridian plane near `guess`; InputError when none is found."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # fsolve warns at its precision floor
        x = fsolve(f, guess, xtol=1e-14)
    # the conditions lose digits like 1 / step^2: 1e-8 still tells a root from a failure
    if not (np.all(np.isfinite(x)) and np.max(np.abs(f(x))) < 1e-8 and x[0] > 0):
        raise InputError("rotational_weingarten_snet: the profile cannot be continued (it would "
                         "reach the axis or fold); use a smaller span_deg or another radius")
    return x


def rotational_weingarten_snet(m: int, k: int, *, radius: float = 1.5, angle_deg: float = 80.0,
                               step: float | None = None, span_deg: float = 90.0,
                               scale: float = 1.0) -> QuadMesh:
    """An exact linear Weingarten S-net of revolution: isogonal, with one Meusnier radius.

    The layout is that of `rotational_snet`, but the meridian curve is not given: it is
    built level by level, each new meridian point ``(r, z)`` solving the two conditions at
    the star before it: the discrete intersection angle is `angle_deg` and the Meusnier
    sphere has radius `radius`. The middle level is the parallel ``r = 1, z = 0``, where the
    meridian is vertical and the profile symmetric. In the smooth limit the net's normal
    curvature ``k_parallel cos^2(a / 2) + k_meridian sin^2(a / 2)`` is ``1 / radius`` (a
    linear Weingarten surface; the families are symmetric about the parallels). At the
    middle parallel ``k_parallel = 1``, so the surface is barrel-shaped (positive Gaussian
    curvature) for ``radius < 1 / cos^2(angle_deg / 2)`` and has a neck (negative) for a
    larger radius; ``radius = 1`` gives the unit sphere.

    Parameters
    ----------
    m, k : vertices along the two families (both at least 3).
    radius : the Meusnier radius shared by all stars (before `scale`).
    angle_deg : the intersection angle of every star, in (0, 180) degrees.
    step, span_deg : as in `rotational_snet`.
    scale : factor applied to all coordinates.

    Returns
    -------
    QuadMesh with ``m * k`` vertices ``(i, j)`` at row ``i * k + j``, faces counter-clockwise
    in ``(i, j)`` (normals pointing away from the axis).

    Raises
    ------
    InputError
        For bad sizes, angle or radius, or when the profile cannot be continued over the
        requested span.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import rotational_weingarten_snet
    >>> from fabplan.net.geometry import fit_star_spheres, intersection_angles
    >>> net = rotational_weingarten_snet(10, 10, radius=3.0, angle_deg=80.0)
    >>> fit = fit_star_spheres(net.vertices, net.stars)
    >>> bool(fit.residual.max() < 1e-12), bool(np.allclose(fit.radius, 3.0, rtol=1e-12))
    (True, True)
    >>> angles = np.degrees(intersection_angles(net.vertices, net.stars))
    >>> bool(np.allclose(np.minimum(angles, 180 - angles), 80.0, atol=1e-9))
    True
    """
    if m < 3 or k < 3:
        raise InputError(f"rotational_weingarten_snet needs at least 3 x 3 vertices, got {m} x {k}")
    if not 0.0 < angle_deg < 180.0:
        raise InputError(f"angle_deg must lie strictly between 0 and 180, got {angle_deg}")
    if not (radius > 0 and math.isfinite(radius)):
        raise InputError(f"radius must be a positive length, got {radius}")
    n_levels, half = _levels_and_half_step("rotational_weingarten_snet", m, k, span_deg, step)
    cosine, curvature = math.cos(math.radians(angle_deg)), 1 / radius

    def conditions(pa: np.ndarray, pb: np.ndarray, pc: np.ndarray) -> np.ndarray:
        star = _meridian_star(pa, pb, pc, half)
        return np.array([_star_cosine(*star) - cosine, (_star_curvature(*star) - curvature) * radius])

    P = np.full((n_levels, 2), np.nan)
    c = (n_levels - 1) // 2
    P[c] = (1.0, 0.0)
    # the middle star's neighbours are mirror images in z = 0: solve for (r, dz)
    r1, dz = _solve_point(lambda x: conditions(x * [1, -1], P[c], x),
                          np.array([1.0, math.tan(math.radians(angle_deg) / 2) * half]))
    P[c - 1], P[c + 1] = (r1, -dz), (r1, dz)
    # A second-order recurrence, solved level by level (once per mesh, over levels).
    for at in range(c + 1, n_levels - 1):
        P[at + 1] = _solve_point(partial(conditions, P[at - 1], P[at]), 2 * P[at] - P[at - 1])
    for at in range(c - 1, 0, -1):
        P[at - 1] = _solve_point(partial(conditions, pb=P[at], pc=P[at + 1]), 2 * P[at] - P[at + 1])
    i, j = np.meshgrid(np.arange(m), np.arange(k), indexing="ij")
    phi = (i + j - (m + k - 2) / 2) * half
    rz = P[j - i + m - 1]
    points = scale * np.stack([rz[..., 0] * np.cos(phi), rz[..., 0] * np.sin(phi), rz[..., 1]], axis=-1)
    return QuadMesh.grid(points, name=f"rotational-weingarten-{m}x{k}")


def height_field_grid(m: int, k: int, f: Callable[[np.ndarray, np.ndarray], np.ndarray], *,
                      spacing: float = 1.0, angle_deg: float = 90.0,
                      rotation_deg: float = 0.0) -> QuadMesh:
    """A grid of straight lines in the xy-plane lifted onto the graph ``z = f(x, y)``.

    Parameters
    ----------
    m, k : vertices along the two families (both at least 2).
    f : vectorized height function of ``(m, k)`` float arrays ``x, y`` (model units).
    spacing : distance between neighbouring vertices in plan view (model units).
    angle_deg : angle in plan view between the lines of the two families, in (0, 180).
    rotation_deg : direction of the first family (along ``i``) from the x-axis, counter-
        clockwise; the second family (along ``j``) runs at ``rotation_deg + angle_deg``.

    Returns
    -------
    QuadMesh with ``m * k`` vertices ``(i, j)`` at row ``i * k + j``, centred on the origin in
    plan view, faces counter-clockwise seen from above (normals with positive z).

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import height_field_grid
    >>> grid = height_field_grid(4, 3, lambda x, y: 0.1 * x * y, angle_deg=60.0)
    >>> grid.vertex_count, len(grid.faces), grid.stars.shape
    (12, 6, (2, 5))
    >>> e1 = grid.vertices[3, :2] - grid.vertices[0, :2]  # (0, 0) -> (1, 0)
    >>> e2 = grid.vertices[1, :2] - grid.vertices[0, :2]  # (0, 0) -> (0, 1)
    >>> round(float(np.degrees(np.arccos(e1 @ e2))), 9)
    60.0
    """
    if m < 2 or k < 2:
        raise InputError(f"height_field_grid needs at least 2 x 2 vertices, got {m} x {k}")
    if not 0.0 < angle_deg < 180.0:
        raise InputError(f"angle_deg must lie strictly between 0 and 180, got {angle_deg}")
    if not spacing > 0:
        raise InputError(f"spacing must be a positive length, got {spacing}")
    a1 = math.radians(rotation_deg)
    a2 = a1 + math.radians(angle_deg)
    d1 = spacing * np.array([math.cos(a1), math.sin(a1)])
    d2 = spacing * np.array([math.cos(a2), math.sin(a2)])
    i, j = np.meshgrid(np.arange(m) - (m - 1) / 2, np.arange(k) - (k - 1) / 2, indexing="ij")
    xy = i[..., None] * d1 + j[..., None] * d2
    x, y = xy[..., 0], xy[..., 1]
    z = np.broadcast_to(np.asarray(f(x, y), dtype=np.float64), x.shape)
    return QuadMesh.grid(np.stack([x, y, z], axis=-1), name=f"height-field-{m}x{k}")
