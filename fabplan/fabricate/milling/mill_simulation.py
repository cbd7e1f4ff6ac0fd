"""A height-map milling simulation that checks tool paths, independent of how they were made.

The target is a height field ``z = f(x, y)`` over a regular grid in a *mill frame* whose
z-axis points to the tool side. A cutter (flat end, ball end or toroidal, with its body
up to a length) is swept through the cutter locations of each pass: between two locations
it moves as a 5-axis machine reading the CL file does, tip along the straight line and axis
turning in the plane of the two axes. The cut surface at a grid point is the lowest point
where the vertical line through it enters the swept cutter, found exactly for each pose
(lines against cylinders and spheres in closed form) and minimized over the continuous
motion: first over poses half a grid step apart, then by golden-section search between
the neighbours of the best one.

What is left is measured against the target: the *scallop* is the largest height of the
cut above the target between two neighbouring passes (inside the strip their contact
paths bound), the *gouge* the largest depth of the cut below the target anywhere on the
part. Units are millimetres.

A conical flank mill is a truncated cone: the entry is the lower crossing of the vertical
line with the cone's quadric within the slab of its length, or the tip's end face.

The same simulation runs the conventional finishing path: a ball-end cutter of the same
diameter normal to the surface, through the same contact points (`ball_end_path`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...errors import CannotMakeError, InputError

__all__ = [
    "Cutter",
    "HeightTarget",
    "SimulationSettings",
    "SimulationResult",
    "mill_frame",
    "simulation_cells",
    "MAX_SIMULATION_CELLS",
    "height_target",
    "entry_heights",
    "ball_end_path",
    "simulate_milling",
    "measure_cut",
]

_GOLDEN = (np.sqrt(5.0) - 1) / 2

#: the largest simulation grid `height_target` makes (cells): about 4 GB and 17 minutes
#: (`fabplan.io.resources.SIMULATION_MEMORY`)
MAX_SIMULATION_CELLS = 4_000_000


@dataclass(frozen=True)
class Cutter:
    """The cutting solid.

    Attributes
    ----------
    kind : ``"flat"`` (cylinder, sharp or with a corner radius), ``"ball"`` or ``"cone"``
        (a truncated cone of revolution widening from the tip).
    radius_mm : cutter radius (cone: the radius of its tip, 0 for a sharp cone).
    length_mm : length of the body above the tip along the axis.
    corner_mm : corner radius of a toroidal cutter (``"flat"`` only).
    angle_deg : half angle of a cone, between its axis and its flank.
    """

    kind: str
    radius_mm: float
    length_mm: float
    corner_mm: float = 0.0
    angle_deg: float = 0.0

    @property
    def widest_radius_mm(self) -> float:
        """Largest distance of the cutter's surface from its axis."""
        if self.kind == "cone":
            return self.radius_mm + self.length_mm * float(np.tan(np.radians(self.angle_deg)))
        return self.radius_mm


@dataclass
class HeightTarget:
    """A target surface as heights on a grid of the mill frame.

    Attributes
    ----------
    x : (nx,) float, y : (ny,) float, grid coordinates (mm).
    z : (ny, nx) float, target heights, NaN off the part.
    rotation : (3, 3) float, model-to-frame rotation (rows: frame axes in model coords).
    origin : (3,) float, frame origin in model coordinates (mm).
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray

    @property
    def step(self) -> float:
        return float(self.x[1] - self.x[0])

    def to_frame(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) model points (mm) in frame coordinates."""
        return (points - self.origin) @ self.rotation.T

    def vectors_to_frame(self, vectors: np.ndarray) -> np.ndarray:
        return vectors @ self.rotation.T


def mill_frame(up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose rows are frame axes, the third one `up` (unit).

    Examples
    --------
    >>> R = mill_frame(np.array([0.0, 0.0, 1.0]))
    >>> bool(np.allclose(R, np.eye(3)))
    True
    """
    up = np.asarray(up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    helper = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 1.0, 0])
    ex = helper - up * (helper @ up)
    ex /= np.linalg.norm(ex)
    return np.stack([ex, np.cross(up, ex), up])


def simulation_cells(points_mm: np.ndarray, triangles: np.ndarray, step_mm: float) -> float:
    """The cells of the simulation grid of a surface at `step_mm`, estimated before the
    passes are planned: the grid over the bounding box of the points seen along their
    triangles' mean normal (the mill direction `height_target` takes is the passes' mean
    tool-side normal, close to it).

    Parameters
    ----------
    points_mm : (n, 3) float, the net's vertices (mm).
    triangles : (t, 3) int, a triangulation of them.
    step_mm : grid spacing.

    Returns
    -------
    float, the estimated cell count (may be huge).

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [100, 0, 0], [100, 50, 0], [0, 50, 0]])
    >>> simulation_cells(P, np.array([[0, 1, 2], [0, 2, 3]]), 1.0)
    5151.0
    """
    a, b, c = (points_mm[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a).sum(axis=0)
    length = np.linalg.norm(normal)
    up = normal / length if length > 0 else np.array([0.0, 0.0, 1.0])
    P = points_mm @ mill_frame(up).T
    extent = P[:, :2].max(axis=0) - P[:, :2].min(axis=0)
    return float(np.prod(np.ceil(extent / step_mm) + 1))


def height_target(points_mm: np.ndarray, triangles: np.ndarray, up: np.ndarray, *,
                  step_mm: float, max_cells: int = MAX_SIMULATION_CELLS,
                  samples: np.ndarray | None = None) -> HeightTarget:
    """The target height map of a surface sampled by points (a net's vertices).

    Heights are the samples' best-fit sphere plus a thin-plate spline with a quadratic
    polynomial part through what departs from it (exact on spheres and on quadratic
    height fields, smooth between samples); the part is where the projected triangles
    lie. The sphere carries the curvature out to the part's edges, where a spline alone,
    with samples on one side only, runs off a curved surface by a fraction of a
    millimetre (0.04 mm between the last vertices of a sphere of radius 360 mm sampled
    every 15 mm).

    Parameters
    ----------
    points_mm : (n, 3) float, samples of the surface (mm).
    triangles : (t, 3) int, a triangulation of the samples (for the part's outline).
    up : (3,) float, the mill direction (towards the tool).
    step_mm : grid spacing.
    max_cells : refuse grids larger than this.
    samples : (n,) bool, the points that sample the surface (default: all); the others
        only outline the part (a net's vertices in no star, which no sphere binds).

    Raises
    ------
    InputError
        When the surface folds over itself seen from `up` (not a height field), or the
        grid would exceed `max_cells`.
    """
    from matplotlib.tri import Triangulation
    from scipy.interpolate import RBFInterpolator

    rotation = mill_frame(up)
    origin = points_mm.mean(axis=0)
    P = (points_mm - origin) @ rotation.T
    e1, e2 = P[triangles[:, 1], :2] - P[triangles[:, 0], :2], P[triangles[:, 2], :2] - P[triangles[:, 0], :2]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    if np.any(area * np.sign(np.median(area)) <= 0):
        raise CannotMakeError("the surface is not a height field seen from the mill direction: "
                              "some faces are seen edge-on or from behind (undercut)")
    lo, hi = P[:, :2].min(axis=0), P[:, :2].max(axis=0)
    cells = np.prod(np.ceil((hi - lo) / step_mm) + 1)
    if cells > max_cells:
        fits = float(np.sqrt(np.prod(hi - lo) / max_cells)) * 1.05
        raise CannotMakeError(f"the simulation grid at {step_mm:g} mm would have {cells:.3g} "
                              f"cells (limit {max_cells}): use a coarser simulation step "
                              f"(--sim-step {fits:.3g} or more), or --no-simulation")
    x = np.arange(lo[0], hi[0] + step_mm / 2, step_mm)
    y = np.arange(lo[1], hi[1] + step_mm / 2, step_mm)
    gx, gy = np.meshgrid(x, y)
    tri = Triangulation(P[:, 0], P[:, 1], triangles)
    inside = np.asarray(tri.get_trifinder()(gx, gy)) >= 0
    query = np.column_stack([gx[inside], gy[inside]])
    if samples is not None:
        P = P[samples]
    base = _sphere_heights(P, np.vstack([P[:, :2], query]))
    neighbours = None if len(P) <= 3000 else 60
    spline = RBFInterpolator(P[:, :2], P[:, 2] - base[:len(P)], kernel="thin_plate_spline",
                             degree=2, neighbors=neighbours)
    z = np.full(gx.shape, np.nan)
    z[inside] = base[len(P):] + (np.concatenate([spline(chunk) for chunk in np.array_split(
        query, max(1, len(query) // 20000))]) if len(query) else 0.0)
    return HeightTarget(x=x, y=y, z=z, rotation=rotation, origin=origin)


def _sphere_heights(P: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(m,) float, heights at `xy` (m, 2) of the least-squares sphere of the points `P`
    (n, 3), on the points' side of its equator; zero everywhere when the sphere does not
    span every `xy` (a nearly flat or a steep part), so that the spline alone remains."""
    A = np.column_stack([2 * P, np.ones(len(P))])
    solution, *_ = np.linalg.lstsq(A, np.sum(P * P, axis=1), rcond=None)
    centre, radius2 = solution[:3], solution[3] + solution[:3] @ solution[:3]
    under = radius2 - np.sum((xy - centre[:2]) ** 2, axis=1)
    extent = np.ptp(P[:, :2], axis=0).max()
    if not np.isfinite(radius2) or radius2 > (1e4 * extent) ** 2 or np.any(under <= 0):
        return np.zeros(len(xy))
    side = 1.0 if np.median(P[:, 2] - centre[2]) >= 0 else -1.0
    heights = centre[2] + side * np.sqrt(under)
    # a part past the sphere's equator, or one the sphere fits badly, keeps the spline alone
    if np.abs(heights[:len(P)] - P[:, 2]).max() > 0.1 * extent:
        return np.zeros(len(xy))
    return heights


def _cylinder_entry(dx, dy, tz, axis, radius, length):
    """Height where the vertical line at offset (dx, dy) from the tip enters the cylinder
    of `radius` standing on the tip along `axis` up to `length` (inf: misses)."""
    ax, ay, az = axis[..., 0], axis[..., 1], axis[..., 2]
    wa = dx * ax + dy * ay
    slab_lo = -wa / az
    slab_hi = (length - wa) / az
    A = 1 - az * az
    B = -2 * wa * az
    C = dx * dx + dy * dy - wa * wa - radius * radius
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = B * B - 4 * A * C
        root = np.sqrt(np.maximum(disc, 0))
        vertical = A < 1e-12
        z1 = np.where(vertical, np.where(C <= 0, -np.inf, np.inf), (-B - root) / (2 * A))
        z2 = np.where(vertical, np.where(C <= 0, np.inf, -np.inf), (-B + root) / (2 * A))
        z1 = np.where(~vertical & (disc < 0), np.inf, z1)
        z2 = np.where(~vertical & (disc < 0), -np.inf, z2)
    lo = np.maximum(z1, slab_lo)
    hi = np.minimum(z2, slab_hi)
    return np.where(lo <= hi, tz + lo, np.inf)


def _cone_entry(dx, dy, tz, axis, tip_radius, angle, length):
    """Height where the vertical line at offset (dx, dy) from the tip enters the truncated
    cone standing on the tip along `axis`: radius ``tip_radius + h tan(angle)`` at height
    h in ``[0, length]`` (inf: misses). The solid is convex: the entry is the lower end of
    the slab interval where it lies inside the cone, or the lower crossing of the flank."""
    ax, ay, az = axis[..., 0], axis[..., 1], axis[..., 2]
    tan2 = np.tan(angle) ** 2
    apex = tip_radius / np.tan(angle)     # axial distance from the apex to the tip
    wa = dx * ax + dy * ay                # axial coordinate w.a = wa + az z (z from the tip)
    rho2 = dx * dx + dy * dy
    slab_lo = -wa / az
    slab_hi = (length - wa) / az

    def inside(z):
        h = wa + az * z
        return rho2 + z * z - h * h - tan2 * (h + apex) ** 2

    # inside(z) = A z^2 + B z + C
    A = 1 - az * az - tan2 * az * az
    B = -2 * wa * az - 2 * tan2 * (wa + apex) * az
    C = rho2 - wa * wa - tan2 * (wa + apex) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = B * B - 4 * A * C
        root = np.sqrt(np.maximum(disc, 0))
        flat = np.abs(A) < 1e-12
        r1 = np.where(flat, -C / np.where(B == 0, 1.0, B), (-B - root) / (2 * np.where(flat, 1.0, A)))
        r2 = np.where(flat, np.inf, (-B + root) / (2 * np.where(flat, 1.0, A)))
    candidates = [np.where(inside(slab_lo) <= 1e-12 * np.maximum(rho2, 1.0), slab_lo, np.inf)]
    for r in (r1, r2):
        ok = (disc >= 0) & np.isfinite(r) & (r >= slab_lo) & (r <= slab_hi)
        candidates.append(np.where(ok, r, np.inf))
    lowest = np.minimum.reduce(candidates)
    return np.where(np.isfinite(lowest), tz + lowest, np.inf)


def _sphere_entry(dx, dy, cz, radius):
    rho2 = dx * dx + dy * dy
    return np.where(rho2 <= radius * radius, cz - np.sqrt(np.maximum(radius * radius - rho2, 0)),
                    np.inf)


def entry_heights(cutter: Cutter, tip: np.ndarray, axis: np.ndarray, x: np.ndarray,
                  y: np.ndarray) -> np.ndarray:
    """Lowest height where the vertical lines at (x, y) enter the cutter.

    Parameters
    ----------
    cutter : the cutter.
    tip : (..., 3) float, centre of the cutter's end (flat) or lowest point on the axis (ball).
    axis : (..., 3) float, unit axes pointing up (positive z).
    x, y : (...) float, broadcastable with ``tip[..., 0]``.

    Returns
    -------
    (...) float, heights (inf where the line misses the cutter).

    Examples
    --------
    >>> c = Cutter("flat", 5.0, 20.0)
    >>> entry_heights(c, np.array([0.0, 0, 1]), np.array([0.0, 0, 1]), np.array([3.0, 6.0]),
    ...               np.array([0.0, 0.0])).tolist()
    [1.0, inf]
    >>> b = Cutter("ball", 5.0, 20.0)
    >>> float(entry_heights(b, np.array([0.0, 0, 0]), np.array([0.0, 0, 1]), np.array(3.0),
    ...                     np.array(4.0)))
    5.0
    >>> k = Cutter("cone", 2.0, 10.0, angle_deg=45.0)
    >>> entry_heights(k, np.zeros(3), np.array([0.0, 0, 1]), np.array([1.0, 5.0, 13.0]),
    ...               np.zeros(3)).round(12).tolist()
    [0.0, 3.0, inf]
    """
    dx, dy, tz = x - tip[..., 0], y - tip[..., 1], tip[..., 2]
    r = cutter.radius_mm
    if cutter.kind == "cone":
        return _cone_entry(dx, dy, tz, axis, r, np.radians(cutter.angle_deg), cutter.length_mm)
    if cutter.kind == "ball":
        centre_dx, centre_dy = dx - r * axis[..., 0], dy - r * axis[..., 1]
        cz = tz + r * axis[..., 2]
        return np.minimum(_sphere_entry(centre_dx, centre_dy, cz, r),
                          _cylinder_entry(centre_dx, centre_dy, cz, axis, r, cutter.length_mm - r))
    c = cutter.corner_mm
    body = _cylinder_entry(dx, dy, tz, axis, r, cutter.length_mm)
    if c == 0:
        return body
    # toroidal: the flat core of radius r - c and a ring of spheres along the corner circle
    core = _cylinder_entry(dx, dy, tz, axis, r - c, cutter.length_mm)
    ring = _torus_ring_entry(dx, dy, tz, axis, r - c, c)
    shell = _cylinder_entry(dx - c * axis[..., 0], dy - c * axis[..., 1], tz + c * axis[..., 2],
                            axis, r, cutter.length_mm - c)
    return np.minimum(np.minimum(core, ring), shell)


def _torus_ring_entry(dx, dy, tz, axis, spine, corner, samples: int = 24, rounds: int = 24):
    """Lowest entry into the ring of spheres of radius `corner` along the spine circle
    (radius `spine`, centre ``tip + corner axis``): coarse angles, then golden section."""
    a = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    helper = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    u = helper - a * np.sum(helper * a, axis=-1, keepdims=True)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(a, u)
    cz = tz + corner * a[..., 2]
    cx, cy = -corner * a[..., 0], -corner * a[..., 1]   # centre offset in (dx, dy) terms

    def at(theta):
        px = cx + spine * (np.cos(theta) * u[..., 0] + np.sin(theta) * v[..., 0])
        py = cy + spine * (np.cos(theta) * u[..., 1] + np.sin(theta) * v[..., 1])
        pz = cz + spine * (np.cos(theta) * u[..., 2] + np.sin(theta) * v[..., 2])
        return _sphere_entry(dx - px, dy - py, pz, corner)

    angles = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    values = np.stack([at(t) for t in angles], axis=-1)
    best = np.argmin(values, axis=-1)
    width = 2 * np.pi / samples
    lo = angles[best] - width
    hi = angles[best] + width
    for _ in range(rounds):
        m1 = hi - _GOLDEN * (hi - lo)
        m2 = lo + _GOLDEN * (hi - lo)
        left = at(m1) <= at(m2)
        hi = np.where(left, m2, hi)
        lo = np.where(left, lo, m1)
    return np.minimum(values.min(axis=-1), at((lo + hi) / 2))


def ball_end_path(contact: np.ndarray, normal: np.ndarray, radius_mm: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The conventional finishing pose: a ball end touching at the contact, axis normal.

    Returns
    -------
    tip : (k, 3) float, lowest point of the ball on its axis (``contact``: the ball's
        centre is ``contact + r n``); axis : (k, 3) float, the normals.
    """
    return contact.copy(), normal / np.linalg.norm(normal, axis=1, keepdims=True)


@dataclass
class SimulationSettings:
    """Resolution of the simulation.

    Attributes
    ----------
    step_mm : grid spacing of the height map.
    pose_spacing_mm : largest tip distance between the poses evaluated on the grid before
        the golden-section search refines the motion between them.
    golden_rounds : golden-section iterations (each shrinks the interval by 0.618).
    gouge_tolerance_mm : depth below the target that counts as a gouge.
    end_trim_mm : the scallop between passes is measured this far from the passes' ends
        and more (the gouge everywhere).
    chunk : grid-pose pairs evaluated at once (memory).
    body_mm : length of the cutter body swept above its cutting edge; material higher up
        is a matter of the collision check of the holder, not of the cut.
    """

    step_mm: float = 0.5
    pose_spacing_mm: float = 2.0
    golden_rounds: int = 28
    gouge_tolerance_mm: float = 0.005
    end_trim_mm: float = 5.0
    body_mm: float = 10.0
    chunk: int = 4_000_000


@dataclass
class SimulationResult:
    """What the simulated cut leaves.

    Attributes
    ----------
    cut : (ny, nx) float, height of the cut surface (inf where no pass reached).
    left : (ny, nx) float, cut minus target (NaN off the part or not reached).
    between : (ny, nx) bool, grid points in a strip between two neighbouring passes.
    max_scallop_mm : largest ``left`` between passes.
    scallop_by_strip_mm : (passes - 1,) float, largest ``left`` in each strip.
    max_gouge_mm : largest depth below the target (0 when none).
    gouge_cells : grid points deeper than the gouge tolerance.
    seconds : time taken.
    strip : (ny, nx) int, the strip between passes of each grid point (its index, the
        passes in order), -1 outside the strips (None: not kept).
    """

    cut: np.ndarray
    left: np.ndarray
    between: np.ndarray
    max_scallop_mm: float
    scallop_by_strip_mm: np.ndarray
    max_gouge_mm: float
    gouge_cells: int
    seconds: float
    strip: np.ndarray | None = None

    def record(self) -> dict:
        return {"max_scallop_mm": self.max_scallop_mm,
                "scallop_by_strip_mm": self.scallop_by_strip_mm.tolist(),
                "max_gouge_mm": self.max_gouge_mm, "gouge_cells": self.gouge_cells,
                "measured_cells": int(np.isfinite(self.left).sum()),
                "cells_between_passes": int(self.between.sum()),
                "seconds": self.seconds}


def _densify(tip: np.ndarray, axis: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Poses on the straight moves between CL points, at most `spacing` apart."""
    step = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    parts = np.maximum(1, np.ceil(step / spacing)).astype(np.int64)
    seg = np.repeat(np.arange(len(step)), parts)
    frac = (np.arange(parts.sum()) - np.repeat(np.cumsum(parts) - parts, parts)) / np.repeat(parts, parts)
    param = np.r_[seg + frac, len(tip) - 1.0]
    return _pose_at(tip, axis, param)


def _pose_at(tip: np.ndarray, axis: np.ndarray, param: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose at fractional CL index `param`: tip linear, axis normalized linear."""
    i = np.clip(np.floor(param).astype(np.int64), 0, len(tip) - 2)
    f = (param - i)[..., None]
    t = tip[i] * (1 - f) + tip[i + 1] * f
    a = axis[i] * (1 - f) + axis[i + 1] * f
    return t, a / np.linalg.norm(a, axis=-1, keepdims=True)


def _end_face_hits(cutter: Cutter, tip: np.ndarray, axis: np.ndarray, x: np.ndarray,
                   y: np.ndarray) -> np.ndarray:
    """(k,) bool, the vertical lines at (x, y) cross the flat end face of the cutter
    (none for a ball end): the cutting edge passes a cell where this changes."""
    if cutter.kind == "ball":
        return np.zeros(len(x), bool)
    dx, dy = x - tip[:, 0], y - tip[:, 1]
    rise = (dx * axis[:, 0] + dy * axis[:, 1]) / axis[:, 2]
    return dx * dx + dy * dy + rise * rise <= cutter.radius_mm**2


def _golden_minimum(function, lo: np.ndarray, hi: np.ndarray, rounds: int) -> np.ndarray:
    """Smallest value `function` takes at the golden-section points of [lo, hi] (arrays),
    the interval shrinking towards the smaller value for `rounds` rounds."""
    m1 = hi - _GOLDEN * (hi - lo)
    m2 = lo + _GOLDEN * (hi - lo)
    f1, f2 = function(m1), function(m2)
    smallest = np.minimum(f1, f2)
    for _ in range(rounds):
        # keep the interior point of the smaller value; one new evaluation per round
        left = f1 <= f2
        hi = np.where(left, m2, hi)
        lo = np.where(left, lo, m1)
        keep_p, keep_f = np.where(left, m1, m2), np.where(left, f1, f2)
        new_p = np.where(left, hi - _GOLDEN * (hi - lo), lo + _GOLDEN * (hi - lo))
        new_f = function(new_p)
        smallest = np.minimum(smallest, new_f)
        m1, f1 = np.where(left, new_p, keep_p), np.where(left, new_f, keep_f)
        m2, f2 = np.where(left, keep_p, new_p), np.where(left, keep_f, new_f)
    return smallest


def _sweep_pass(target: HeightTarget, cutter: Cutter, tip: np.ndarray, axis: np.ndarray,
                settings: SimulationSettings) -> np.ndarray:
    """(ny, nx) lowest cut of one pass (inf where it does not reach)."""
    ny, nx = target.z.shape
    step = target.step
    x0, y0 = target.x[0], target.y[0]
    poses, pose_axes = _densify(tip, axis, settings.pose_spacing_mm)
    # the param of each dense pose, to refine between neighbours on the CL polyline
    seg = np.linalg.norm(np.diff(tip, axis=0), axis=1)
    parts = np.maximum(1, np.ceil(seg / settings.pose_spacing_mm)).astype(np.int64)
    frac = (np.arange(parts.sum()) - np.repeat(np.cumsum(parts) - parts, parts)) / np.repeat(parts, parts)
    param = np.r_[np.repeat(np.arange(len(seg)), parts) + frac, len(tip) - 1.0]
    reach = cutter.widest_radius_mm + cutter.length_mm * np.linalg.norm(pose_axes[:, :2], axis=1).max() + step
    half = int(np.ceil(reach / step))
    offsets = np.arange(-half, half + 1)
    oy, ox = np.meshgrid(offsets, offsets, indexing="ij")
    disk = oy**2 + ox**2 <= half**2
    oy, ox = oy[disk], ox[disk]
    best = np.full(ny * nx, np.inf)
    best_pose = np.full(ny * nx, -1)
    first_pose = np.full(ny * nx, len(poses))
    last_pose = np.full(ny * nx, -1)
    per = max(1, settings.chunk // len(ox))
    for start in range(0, len(poses), per):
        t, a = poses[start:start + per], pose_axes[start:start + per]
        cx = np.rint((t[:, 0] - x0) / step).astype(np.int64)
        cy = np.rint((t[:, 1] - y0) / step).astype(np.int64)
        gx = cx[:, None] + ox[None, :]
        gy = cy[:, None] + oy[None, :]
        ok = (gx >= 0) & (gx < nx) & (gy >= 0) & (gy < ny)
        k, m = np.nonzero(ok)
        cell = gy[k, m] * nx + gx[k, m]
        z = entry_heights(cutter, t[k], a[k], target.x[gx[k, m]], target.y[gy[k, m]])
        hit = np.isfinite(z)
        cell, z, k = cell[hit], z[hit], k[hit] + start
        np.minimum.at(best, cell, z)
        won = z == best[cell]
        best_pose[cell[won]] = k[won]
        face = _end_face_hits(cutter, t[k - start], a[k - start], target.x[cell % nx],
                              target.y[cell // nx])
        np.minimum.at(first_pose, cell[face], k[face])
        np.maximum.at(last_pose, cell[face], k[face])
    # golden-section search on the continuous motion about the best pose, and about the
    # first and last poses whose end face lies over the cell: the cutting edge crosses it
    # there, and that narrow dip may lie between two coarse poses that both miss it
    reached = np.flatnonzero(best_pose >= 0)
    px = target.x[reached % nx]
    py = target.y[reached // nx]

    def height(p):
        t, a = _pose_at(tip, axis, p)
        return entry_heights(cutter, t, a, px, py)

    refined = best[reached]
    for j in (best_pose[reached], first_pose[reached], last_pose[reached]):
        lo = param[np.maximum(j - 1, 0)]
        hi = param[np.minimum(j + 1, len(param) - 1)]
        refined = np.minimum(refined, _golden_minimum(height, lo, hi, settings.golden_rounds))
    best[reached] = refined
    return best.reshape(ny, nx)


def _strip_masks(target: HeightTarget, contacts: list, end_trim_mm: float) -> list:
    """Grid masks of the strips between neighbouring passes' contact paths.

    A strip is the polygon the two paths bound, less the cells whose closest point on
    either path is one of its ends: beyond the end of the shorter pass only one pass
    cuts, which leaves no scallop between passes but an unfinished corner; cells whose
    closest path point lies within `end_trim_mm` of an end, where the cutter starts and
    stops, are left out too. Only the cells in a strip's bounding box are tested (a
    strip is a narrow band: testing every cell of a large part against every strip took
    minutes, in calls that hold the interpreter, so progress stalled).
    """
    from matplotlib.path import Path as PolygonPath
    from scipy.spatial import cKDTree

    ny, nx = target.z.shape
    dense = [_densify(c, np.tile([0.0, 0.0, 1.0], (len(c), 1)), target.step)[0][:, :2]
             for c in contacts]
    trees = [cKDTree(path) for path in dense]
    trim = int(np.ceil(end_trim_mm / target.step))
    masks = []
    for i, (a, b) in enumerate(zip(contacts[:-1], contacts[1:], strict=False)):
        same_way = np.dot(a[-1, :2] - a[0, :2], b[-1, :2] - b[0, :2]) > 0
        ring = np.vstack([a[:, :2], (b[::-1] if same_way else b)[:, :2]])
        lo = np.searchsorted(target.x, ring[:, 0].min()), np.searchsorted(target.y, ring[:, 1].min())
        hi = (np.searchsorted(target.x, ring[:, 0].max(), side="right"),
              np.searchsorted(target.y, ring[:, 1].max(), side="right"))
        gx, gy = np.meshgrid(target.x[lo[0]:hi[0]], target.y[lo[1]:hi[1]])
        points = np.column_stack([gx.ravel(), gy.ravel()])
        inside = PolygonPath(ring).contains_points(points)
        for k in (i, i + 1):
            _, nearest = trees[k].query(points[inside])
            keep = (nearest > trim) & (nearest < len(dense[k]) - 1 - trim)
            inside[np.flatnonzero(inside)[~keep]] = False
        mask = np.zeros((ny, nx), bool)
        mask[lo[1]:hi[1], lo[0]:hi[0]] = inside.reshape(gx.shape)
        masks.append(mask)
    return masks


def simulate_milling(target: HeightTarget, cutter: Cutter, tip: np.ndarray, axis: np.ndarray,
                     contact: np.ndarray, pass_id: np.ndarray,
                     settings: SimulationSettings | None = None) -> SimulationResult:
    """Sweep `cutter` through the passes and measure scallop and gouge.

    Parameters
    ----------
    target : the height map (`height_target`).
    cutter : the cutter.
    tip, axis : (k, 3) float, cutter locations and unit axes in model coordinates (mm).
    contact : (k, 3) float, contact points (model, mm): only their paths are used, to
        outline the strips between neighbouring passes where the scallop is measured.
    pass_id : (k,) int, pass of each location, passes in order across the part.
    settings : resolution.

    Returns
    -------
    SimulationResult
    """
    started = time.perf_counter()
    settings = settings or SimulationSettings()
    T = target.to_frame(tip)
    A = target.vectors_to_frame(axis)
    C = target.to_frame(contact)
    if np.any(A[:, 2] <= 0.05):
        raise InputError("a tool axis points away from the mill direction (more than 87 deg "
                         "from it): the part cannot be reached from this side")
    cut = np.full(target.z.shape, np.inf)
    contacts = []
    for p in np.unique(pass_id):
        sel = pass_id == p
        if sel.sum() < 2:
            continue
        cut = np.minimum(cut, _sweep_pass(target, cutter, T[sel], A[sel], settings))
        contacts.append(C[sel])
    strip = np.full(target.z.shape, -1)
    for number, mask in enumerate(_strip_masks(target, contacts, settings.end_trim_mm)):
        strip[mask & (strip < 0)] = number
    return measure_cut(cut, target.z, strip, max(len(contacts) - 1, 0),
                       settings.gouge_tolerance_mm, seconds=time.perf_counter() - started)


def measure_cut(cut: np.ndarray, z: np.ndarray, strip: np.ndarray, strips: int,
                gouge_tolerance_mm: float, *, seconds: float = 0.0) -> SimulationResult:
    """What a cut leaves against a target: scallop between passes and gouge.

    Parameters
    ----------
    cut : (ny, nx) float, height of the cut (mm; inf where no pass reached).
    z : (ny, nx) float, target heights on the same grid (mm; NaN off the part).
    strip : (ny, nx) int, the strip between passes of each grid point, -1 outside.
    strips : number of strips (passes - 1).
    gouge_tolerance_mm : depth below the target that counts as a gouge.
    seconds : time to record.

    Returns
    -------
    SimulationResult

    Examples
    --------
    >>> cut = np.array([[1.0, 1.2, np.inf]])
    >>> r = measure_cut(cut, np.array([[1.01, 1.0, 1.0]]), np.array([[-1, 0, 0]]), 1, 0.005)
    >>> round(r.max_gouge_mm, 6), round(r.max_scallop_mm, 6), r.gouge_cells
    (0.01, 0.2, 1)
    """
    part = np.isfinite(z)
    reached = part & np.isfinite(cut)
    left = np.where(reached, cut - np.where(part, z, 0.0), np.nan)
    between = (strip >= 0) & reached
    by_strip = []
    for number in range(strips):
        inside = between & (strip == number)
        by_strip.append(float(np.max(left[inside])) if inside.any() else np.nan)
    depth = -np.nanmin(left) if reached.any() else 0.0
    with np.errstate(invalid="ignore"):
        scallop = float(np.nanmax(by_strip)) if np.isfinite(by_strip).any() else float("nan")
    return SimulationResult(
        cut=cut, left=left, between=between,
        max_scallop_mm=scallop,
        scallop_by_strip_mm=np.array(by_strip),
        max_gouge_mm=float(max(depth, 0.0)),
        gouge_cells=int(np.sum(left[reached] < -gouge_tolerance_mm)),
        seconds=seconds, strip=strip)
