"""Mold reduction: how many molds the curved panels of a net need, verified panel by panel.

A doubly curved panel is hot-bent on a mold. On a Weingarten surface both principal
curvatures are constant along one family of curves, so the panels along such a curve can
share a mold, and about ``sqrt(N)`` molds serve ``N`` panels (paper, section 3.5). This
module counts the molds a net really needs at a stated tolerance:

1. Panel model (`fabplan.panels`): every face is a quadratic surface patch with its
   principal curvatures and frame; it is *planar* when a plane, *single curved* when a
   cylinder and otherwise *double curved* fits it within the tolerance.
2. Molds: every mold is the surface ``z = (k1 x^2 + k2 y^2) / 2`` in mold coordinates
   (millimetres): a *plane* (``k1 = k2 = 0``), a *cylinder* (``k2 = 0``; the parabolic
   cylinder, which differs from the circular one of radius ``1 / k1`` by about
   ``k1^3 x^4 / 8`` over a panel) or a *paraboloid*. Each panel type gets molds of its own
   type. A panel is placed on a mold by a rigid motion that takes its principal frame to
   the mold's axes (in one of the four principal placements of
   `fabplan.panels.placement_frames`) and shifts it along the mold axis to even out the
   gap; its deviation is the largest vertical gap between panel and mold, an upper bound of
   the distance. For fixed placement frames that gap is piecewise linear and convex in the
   mold curvatures, so it is computed exactly for every (panel, mold) pair, not estimated.
3. Assignment: a greedy set cover of the panels by candidate molds (the panels' own
   shapes), then rounds of refitting every mold's curvatures to its panels (a small linear
   program minimizing the largest deviation), reassigning panels to their closest mold and
   removing molds whose panels all fit elsewhere. Everything is sorted and deterministic.
4. Verification: every panel is sampled again, densely, placed by its exported 4 x 4
   matrix and measured against its mold; panels found above the tolerance get molds of
   their own; a panel that fits no mold (or exceeds the largest mold size) is reported as
   a failure, never dropped.
5. Weingarten evidence: how close the panels' ``(k1, k2)`` lie to a line
   ``a k1 + b k2 = c`` (and to a conic), against the curvature difference one mold absorbs.

Model coordinates are in the net's units (``units``: ``"m"`` or ``"mm"``); every
fabrication output (mold curvatures, sizes, placements, deviations) is in millimetres.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from ..errors import InputError
from ..io.units import MM_PER_UNIT, check_units
from ..net.mesh import QuadMesh
from ..net.weingarten import weingarten_fit
from .materials import Material
from .panel_classes import CLASSES, DEFAULT_ORDER, PanelClasses, classify_panels
from .panel_meshes import PANEL_MESH_LEVEL, PanelMesh, panel_surface_mesh
from .panels import (
    SURFACE_MODELS,
    check_panels,
    design_panel_samples,
    fit_design_panels,
    fit_panel_surfaces,
    fit_shared_panels,
    panel_samples,
    panel_shapes,
    placement_frames,
    shared_panel_samples,
    surface_model,
    surface_steps,
)

__all__ = [
    "UNITS",
    "TOLERANCE_RANGE_MM",
    "PANEL_TYPES",
    "MOLD_TYPES",
    "MoldSettings",
    "MoldPlan",
    "plan_molds",
    "mold_heights",
    "placement_deviations",
    "closest_mold_points",
    "panel_steps",
    "chord_steps",
    "mold_count_bound",
]

UNITS = MM_PER_UNIT    # the model units a plan takes (`fabplan.io.units`)
"""Millimetres per model unit for each accepted ``units`` name (molds and strips)."""

STEP_ROUNDS = 3
"""Rounds of casting the panels of over-limit steps on closer molds (tolerance halved in
each round)."""

TOLERANCE_RANGE_MM = (0.01, 1000.0)
"""Mold tolerances that mean something: finer than 0.01 mm no mold is made, a gap of a
metre is no mold at all."""

PANEL_TYPES = ("planar", "single_curved", "double_curved")
MOLD_TYPES = ("plane", "cylinder", "paraboloid")
_FREE_DIMS = {"plane": 0, "cylinder": 1, "paraboloid": 2}  # mold curvatures that are fitted


@dataclass
class MoldSettings:
    """What a mold plan is asked for.

    Attributes
    ----------
    tolerance_mm : largest allowed gap between a panel and its mold (mm), > 0.
    units : unit of the net's coordinates (a key of `fabplan.io.units.MM_PER_UNIT`).
    max_mold_size_mm : largest mold side (mm); a panel whose footprint on its mold is
        larger is a failure. None: no limit.
    panel_surface : ``"auto"``, ``"shared"``, ``"local_fit"``, ``"corners"`` or ``"design"``
        (see `fabplan.fabricate.panels`; ``"design"`` needs the design the net lies on).
    cover_level : sample grid steps per fan-triangle side while assigning (60 points on a
        quad at 4).
    verify_level : the same for the verification (364 points on a quad at 12).
    reserve : fraction of the tolerance kept in reserve while assigning, for what lies
        between the assignment samples; the verification uses the full tolerance.
    rounds : cap on the refit / reassign / remove rounds.
    step_fractions : where along every shared edge the step between the two panels' molds
        is measured (fractions of the edge from its first vertex).
    step_limit_mm : largest step allowed between neighbouring panels' molds (mm); None:
        twice the tolerance (two panels each within the tolerance of one surface).
    material : the panels' sheet material (`fabplan.fabricate.materials`), or None. With a
        material every panel is classified flat, cold-bent, roll-bent or molded
        (`fabplan.fabricate.panel_classes`) and only the molded panels' molds are made.
    class_order : the order the classes are tried in (`panel_classes.class_order`).
    """

    tolerance_mm: float = 5.0
    units: str = "m"
    max_mold_size_mm: float | None = None
    panel_surface: str = "auto"
    cover_level: int = 4
    verify_level: int = 12
    reserve: float = 0.01
    rounds: int = 8
    step_fractions: tuple[float, ...] = (0.25, 0.5, 0.75)
    step_limit_mm: float | None = None
    material: Material | None = None
    class_order: tuple[str, ...] = DEFAULT_ORDER

    def check(self) -> None:
        """Refuse impossible settings with a one-line `InputError`."""
        t = self.tolerance_mm
        if not isinstance(t, (int, float)) or not math.isfinite(t) or t <= 0:
            raise InputError(f"the tolerance must be a positive number of millimetres, got {t}")
        low, high = TOLERANCE_RANGE_MM
        if not low <= t <= high:
            raise InputError(f"the tolerance {t:g} mm lies outside {low:g} .. {high:g} mm, the "
                             "range a mold can be made to (is it in the wrong unit?)")
        check_units(self.units)
        s = self.max_mold_size_mm
        if s is not None and not (math.isfinite(s) and s > 0):
            raise InputError(f"the largest mold size must be a positive number of millimetres, got {s}")
        if self.panel_surface not in ("auto", "smooth") + SURFACE_MODELS:   # smooth: local_fit
            raise InputError(f"unknown panel surface {self.panel_surface!r}: use auto, "
                             + ", ".join(SURFACE_MODELS))
        if self.cover_level < 1 or self.verify_level < 1:
            raise InputError("the sample levels must be at least 1")
        limit = self.step_limit_mm
        if limit is not None and not (math.isfinite(limit) and limit > 0):
            raise InputError(f"the step limit must be a positive number of millimetres, got {limit}")
        if self.material is not None and not isinstance(self.material, Material):
            raise InputError(f"the material must be a fabplan Material, got {self.material!r}")

    @property
    def mm_per_unit(self) -> float:
        return UNITS[self.units]

    @property
    def working_tolerance_mm(self) -> float:
        return self.tolerance_mm * (1.0 - self.reserve)


# ----------------------------------------------------------------------------- gaps
def mold_heights(xy: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """Height of the mold surface ``z = (k1 x^2 + k2 y^2) / 2`` at mold-plane points.

    Parameters
    ----------
    xy : (..., s, 2) float, mold coordinates (mm).
    shape : (..., 2) float, ``(k1, k2)`` (1/mm).

    Returns
    -------
    (..., s) float, mm.

    Examples
    --------
    >>> import numpy as np
    >>> mold_heights(np.array([[1000.0, 0.0], [0.0, 500.0]]), np.array([0.001, -0.002]))
    array([ 500., -250.])
    """
    return 0.5 * (shape[..., None, 0] * xy[..., 0] ** 2 + shape[..., None, 1] * xy[..., 1] ** 2)


def placement_deviations(points: np.ndarray, placements: np.ndarray,
                         shapes: np.ndarray) -> np.ndarray:
    """Largest vertical gap between placed panels and their molds.

    Parameters
    ----------
    points : (p, s, 3) float, samples of each panel in model coordinates.
    placements : (p, 4, 4) float, homogeneous matrices taking model coordinates to mold
        coordinates (mm).
    shapes : (p, 2) float, ``(k1, k2)`` of each panel's mold (1/mm).

    Returns
    -------
    (p,) float, mm: ``max |z - (k1 x^2 + k2 y^2) / 2|`` over each panel's placed samples,
    an upper bound of their distance from the mold surface.
    """
    q = np.einsum("pij,psj->psi", placements[:, :3, :3], points) + placements[:, None, :3, 3]
    return np.abs(q[..., 2] - mold_heights(q[..., :2], shapes)).max(axis=1)


def _offset_gap(U: np.ndarray, Z: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deviation and best shift along the mold axis for fixed placement frames.

    U : (..., s, 2) squared mold coordinates ``(x^2, y^2)``; Z : (..., s) heights;
    K : (..., 2) mold curvatures. Returns (deviation, shift), each (...,), mm.
    """
    r = Z - 0.5 * (U[..., 0] * K[..., None, 0] + U[..., 1] * K[..., None, 1])
    hi, lo = r.max(axis=-1), r.min(axis=-1)
    return 0.5 * (hi - lo), 0.5 * (hi + lo)


# ----------------------------------------------------------------------------- steps
def closest_mold_points(q: np.ndarray, shape: np.ndarray, iterations: int = 8) -> np.ndarray:
    """Closest points of molds ``z = (k1 x^2 + k2 y^2) / 2`` to points in mold coordinates.

    Newton's method on ``(x, y)`` from the point's own ``(x, y)``; a mold over a panel is
    nearly flat (``k r`` small), so a few steps reach machine precision.

    Parameters
    ----------
    q : (..., 3) float, mm; shape : (..., 2) float, ``(k1, k2)`` (1/mm).

    Returns
    -------
    (..., 3) float, mm.

    Examples
    --------
    >>> import numpy as np
    >>> closest_mold_points(np.array([0.0, 0.0, 7.0]), np.array([0.0, 0.0]))
    array([0., 0., 0.])
    """
    k1, k2 = shape[..., 0], shape[..., 1]
    x, y = q[..., 0].copy(), q[..., 1].copy()
    for _ in range(iterations):
        r = 0.5 * (k1 * x * x + k2 * y * y) - q[..., 2]
        gx, gy = x - q[..., 0] + r * k1 * x, y - q[..., 1] + r * k2 * y
        hxx = 1 + (k1 * x) ** 2 + r * k1
        hyy = 1 + (k2 * y) ** 2 + r * k2
        hxy = k1 * x * k2 * y
        det = hxx * hyy - hxy * hxy
        x, y = x - (hyy * gx - hxy * gy) / det, y - (hxx * gy - hxy * gx) / det
    return np.stack([x, y, 0.5 * (k1 * x * x + k2 * y * y)], axis=-1)


def _mold_normals(c: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """(..., 3) unit normals of molds at their points c (..., 3), mold coordinates."""
    n = np.stack([-shape[..., 0] * c[..., 0], -shape[..., 1] * c[..., 1], np.ones_like(c[..., 0])], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def panel_steps(mesh: QuadMesh, placement: np.ndarray, shape: np.ndarray, mm: float, *,
                fractions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The step and the kink between the molds of the two panels of every interior edge.

    At points of the edge's chord (`fractions` of the way from its first vertex) the point
    is put on panel A's mold (its closest point there, through A's placement) and measured
    against panel B's mold (the distance to B's closest point); and the other way round.
    This is the step a fabricator sees between the two finished panels (`chord_steps`).

    Parameters
    ----------
    mesh : the net; placement : (p, 4, 4) model -> mold coordinates (mm) of every panel;
    shape : (p, 2) ``(k1, k2)`` of every panel's mold (1/mm); mm : millimetres per unit.
    fractions : (t,) float, default ``(0.25, 0.5, 0.75)``.

    Returns
    -------
    step : (i,) float, mm, the largest over the points and both directions, for the edges
        in the order of ``mesh.interior_edge_faces``.
    kink : (i,) float, degrees, the largest angle between the two molds' normals there.
    """
    pairs, edges = mesh.interior_edge_faces, mesh.interior_edges
    if len(pairs) == 0:
        return np.zeros(0), np.zeros(0)
    X = mesh.vertices
    return chord_steps(X[edges], placement[pairs], shape[pairs], mm, fractions=fractions)


def chord_steps(chords: np.ndarray, placement: np.ndarray, shape: np.ndarray, mm: float, *,
                fractions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The step and the kink between two molds along the chords of their shared sides.

    Parameters
    ----------
    chords : (i, 2, 3) float, the two ends of every shared side (model units).
    placement : (i, 2, 4, 4) float, model -> mold coordinates (mm) of the two panels.
    shape : (i, 2, 2) float, ``(k1, k2)`` of their molds (1/mm).
    mm : millimetres per model unit.
    fractions : (t,) float, where along the chords (default ``(0.25, 0.5, 0.75)``).

    Returns
    -------
    step : (i,) float, mm: the chord's points put on the first mold (their closest points
        there) and measured against the second, and the other way round; the largest.
    kink : (i,) float, degrees, the largest angle between the two molds' normals there.

    Examples
    --------
    >>> import numpy as np
    >>> flat = np.eye(4) * np.array([1000.0, 1000.0, 1000.0, 1.0])
    >>> up = flat.copy()
    >>> up[2, 3] = -2.0                              # the second mold 2 mm lower
    >>> step, kink = chord_steps(np.array([[[0.0, 0, 0], [1.0, 0, 0]]]),
    ...                          np.array([[flat, up]]), np.zeros((1, 2, 2)), 1000.0)
    >>> np.round(step, 9), np.round(kink, 9)
    (array([2.]), array([0.]))
    """
    if len(chords) == 0:
        return np.zeros(0), np.zeros(0)
    t = np.array([0.25, 0.5, 0.75]) if fractions is None else np.asarray(fractions, float)
    P = (1 - t[None, :, None]) * chords[:, :1] + t[None, :, None] * chords[:, 1:]   # (i, t, 3)
    step = np.zeros(len(chords))
    kink = np.zeros(len(chords))
    for a, b in ((0, 1), (1, 0)):
        A, B = placement[:, a], placement[:, b]
        qa = np.einsum("eij,etj->eti", A[:, :3, :3], P) + A[:, None, :3, 3]
        ca = closest_mold_points(qa, shape[:, a, None, :])
        # back to model coordinates (A's block is mm times a rotation), then into B's mold
        Ra = A[:, :3, :3] / mm
        pa = np.einsum("eji,etj->eti", Ra, ca - A[:, None, :3, 3]) / mm
        qb = np.einsum("eij,etj->eti", B[:, :3, :3], pa) + B[:, None, :3, 3]
        cb = closest_mold_points(qb, shape[:, b, None, :])
        step = np.maximum(step, np.linalg.norm(qb - cb, axis=2).max(axis=1))
        na = np.einsum("eji,etj->eti", Ra, _mold_normals(ca, shape[:, a, None, :]))
        nb = np.einsum("eji,etj->eti", B[:, :3, :3] / mm, _mold_normals(cb, shape[:, b, None, :]))
        cos = np.abs(np.sum(na * nb, axis=2)).min(axis=1)
        kink = np.maximum(kink, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return step, kink


def mold_count_bound(curvature: np.ndarray, reach: float) -> tuple[float, int]:
    """The fewest molds any plan can use, by the length of the panels' curvature set.

    The panels' ``(k1, k2)`` (1/mm) are spread along their principal axis over a length
    ``L`` (the largest minus the smallest projection); one mold absorbs panels within
    `reach` of its own curvatures, an interval ``2 reach`` long, so at least
    ``ceil(L / (2 reach))`` molds are needed (a cloud that fills an area needs more).

    Returns
    -------
    (L, bound): length in 1/mm and molds.

    Examples
    --------
    >>> import numpy as np
    >>> mold_count_bound(np.array([[0.0, 1.0], [3.0, 1.0], [1.0, 1.0]]), 0.5)
    (3.0, 3)
    """
    k = np.asarray(curvature, float)
    k = k[np.all(np.isfinite(k), axis=1)]
    if len(k) < 2 or not (reach > 0) or not math.isfinite(reach):
        return 0.0, 1
    c = k - k.mean(axis=0)
    axis = np.linalg.svd(c, full_matrices=False)[2][0]
    proj = c @ axis
    length = float(proj.max() - proj.min())
    return length, max(1, math.ceil(length / (2.0 * reach) - 1e-9))


# ----------------------------------------------------------------------------- the panels
@dataclass
class _Panels:
    """Panel data for the assignment (internal): samples in the four placement frames."""

    shapes: np.ndarray      # (p, 4, 2) panel curvatures in each frame (1/mm)
    U: np.ndarray           # (p, 4, s, 2) squared mold x, y of the samples (mm^2)
    Z: np.ndarray           # (p, 4, s) mold z of the samples (mm)
    reach: np.ndarray       # (p,) curvature distance beyond which molds are not tried (1/mm)


def _frame_coordinates(points: np.ndarray, point: np.ndarray, frames: np.ndarray,
                       mm: float) -> np.ndarray:
    """(p, v, s, 3) mold coordinates (mm) of samples (p, s, 3) in frames (p, v, 3, 3)."""
    d = points - point[:, None, :]
    return mm * np.einsum("pvij,psj->pvsi", frames, d)


def _panel_data(points: np.ndarray, point: np.ndarray, frames: np.ndarray, shapes: np.ndarray,
                mm: float, tolerance: float) -> _Panels:
    """Samples (p, s, 3) of panels with apex points (p, 3) in their placement frames
    (p, 4, 3, 3), their shapes there (p, 4, 2) and their reach at the tolerance (mm)."""
    Q = _frame_coordinates(points, point, frames, mm)
    U, Z = Q[..., :2] ** 2, Q[..., 2]
    width = np.minimum(np.ptp(Q[:, 0, :, 0], axis=1), np.ptp(Q[:, 0, :, 1], axis=1))
    # A shift along the mold axis leaves a gap of about dk w^2 / 16 for a curvature error dk
    # across a width w; molds four times farther than the tolerance allows are not tried
    # (a generous cut: it can only cost a mold, never accept a panel that does not fit).
    reach = 64.0 * tolerance / np.maximum(width, 1e-9) ** 2
    return _Panels(shapes=shapes, U=U, Z=Z, reach=reach)


def _cylinder_fits(U: np.ndarray, Z: np.ndarray, k1: np.ndarray,
                   iterations: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Best ``K1`` of a cylinder mold ``(K1, 0)`` for each panel (frame F0), by golden
    section on the convex gap. Returns (K1, deviation), each (p,)."""
    span = 2.0 * np.abs(k1) + 1e-9
    lo, hi = k1 - span, k1 + span
    g = (math.sqrt(5) - 1) / 2

    def gap(K1: np.ndarray) -> np.ndarray:
        return _offset_gap(U, Z, np.stack([K1, np.zeros_like(K1)], -1))[0]

    for _ in range(iterations):
        a, b = hi - g * (hi - lo), lo + g * (hi - lo)
        left = gap(a) < gap(b)
        hi, lo = np.where(left, b, hi), np.where(left, lo, a)
    K1 = 0.5 * (lo + hi)
    return K1, gap(K1)


# ----------------------------------------------------------------------------- gaps and cover
#: Panels per block of `_gap_matrix`'s arithmetic.
_GAP_ROWS = 32


def _gap_matrix(data: _Panels, molds: np.ndarray, chunk: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Exact gaps of every panel on every mold, in the best of the four placements.

    Molds are taken in blocks of nearby curvatures; a block is only evaluated for the
    panels whose shape in a placement lies within their reach (see `_panel_data`) of the
    block's bounding box: farther pairs are left at infinity (treated as not fitting).

    Returns
    -------
    deviation : (p, m) float, mm, inf where not evaluated.
    variant : (p, m) int, the placement frame that gives it.
    """
    p = len(data.shapes)
    m = len(molds)
    deviation = np.full((p, m), np.inf)
    variant = np.zeros((p, m), np.int64)
    order = np.lexsort((molds[:, 1], molds[:, 0]))
    for start in range(0, m, chunk):
        cols = order[start:start + chunk]
        K = molds[cols]
        lo, hi = K.min(axis=0), K.max(axis=0)
        for v in range(4):
            shape = data.shapes[:, v]
            gap = np.maximum(np.maximum(lo - shape, shape - hi), 0.0).max(axis=1)
            rows = np.flatnonzero(gap <= data.reach)
            if rows.size == 0:
                continue
            dev = np.empty((rows.size, len(cols)))                  # (rows, chunk)
            # rows in blocks: the (rows, samples, chunk) temporaries stay in the cache
            for b in range(0, rows.size, _GAP_ROWS):
                U, Z = data.U[rows[b:b + _GAP_ROWS], v], data.Z[rows[b:b + _GAP_ROWS], v]
                r = Z[..., None] - 0.5 * (U[..., 0, None] * K[:, 0] + U[..., 1, None] * K[:, 1])
                dev[b:b + _GAP_ROWS] = 0.5 * (r.max(axis=1) - r.min(axis=1))
            block = deviation[np.ix_(rows, cols)]
            better = dev < block
            deviation[np.ix_(rows, cols)] = np.where(better, dev, block)
            variant[np.ix_(rows, cols)] = np.where(better, v, variant[np.ix_(rows, cols)])
    return deviation, variant


def _greedy_cover(fits: np.ndarray) -> np.ndarray:
    """Columns of `fits` (p, c) bool chosen greedily, the one covering most uncovered rows
    first (lowest index on ties), until every coverable row is covered.

    The uncovered rows of every column are counted once and then less the rows each
    choice covers (integers: no product of the whole matrix per choice)."""
    uncovered = np.any(fits, axis=1)
    count = fits.sum(axis=0, dtype=np.int64)
    chosen: list[int] = []
    while uncovered.any():
        best = int(np.argmax(count))
        chosen.append(best)
        covered = uncovered & fits[:, best]
        count -= fits[covered].sum(axis=0, dtype=np.int64)
        uncovered &= ~covered
    return np.array(chosen, dtype=np.int64)


def _refit_molds(U: np.ndarray, Z: np.ndarray, owner: np.ndarray, K: np.ndarray, free: int,
                 reach: np.ndarray) -> np.ndarray:
    """Mold curvatures minimizing the largest gap of each mold's panels (fixed frames, each
    panel with its own shift along the mold axis), for several molds at once.

    Each mold is a linear program in (K, shifts, gap) over the samples that are highest or
    lowest for some curvature near its `K` (within its `reach`), with samples found
    violating the result added until none does (cutting planes): a few small programs
    instead of one over all samples. The programs of all molds are independent blocks of
    one program whose cost is the sum of their gaps, so one solve serves every mold (the
    solver's fixed cost per call is most of a small program's time); a mold leaves it once
    its samples settle.

    Parameters
    ----------
    U : (q, s, 2) float, Z : (q, s) float, the squared mold x, y (mm^2) and mold z (mm) of
        the samples of all molds' panels in their frames, each mold's panels together.
    owner : (q,) int, the mold of each panel, nondecreasing.
    K : (g, 2) float, the molds' start curvatures (1/mm).
    free : how many curvatures are fitted (0: none, 1: ``k1``, 2: both).
    reach : (g,) float, the curvature distance of each mold's panels (1/mm).

    Returns
    -------
    (g, 2) float, the fitted curvatures (1/mm); a mold whose program fails keeps its
    last fit.
    """
    best = np.array(K, dtype=np.float64)
    if free == 0 or len(best) == 0:
        return best
    g = len(best)
    size = np.bincount(owner, minlength=g)
    first = np.cumsum(size) - size
    local = np.arange(len(owner)) - first[owner]
    scale = np.full(g, -np.inf)
    np.maximum.at(scale, owner, U.max(axis=(1, 2)))
    scale = np.maximum(scale, 1e-12)
    steps = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], float) * 0.25
    steps[:, free:] = 0.0
    active = np.zeros(Z.shape, bool)
    for d in steps:
        _mark_extremes(active, U, Z, best[owner] + d * reach[owner, None])
    open_ = np.ones(g, bool)
    for _ in range(20):
        rows = open_[owner]
        p, j = np.nonzero(active & rows[:, None])
        # columns of each open mold's block: its curvatures, its panels' shifts, its gap
        width = np.where(open_, free + size + 1, 0)
        column = np.cumsum(width) - width
        b = owner[p]
        A = _refit_constraints(U[p, j, :free] / scale[b, None], column[b],
                               column[b] + free + local[p], column[b] + free + size[b],
                               int(width.sum()))
        cost = np.zeros(int(width.sum()))
        cost[(column + free + size)[open_]] = 1.0
        lower = np.full(len(cost), -np.inf)
        lower[(column + free + size)[open_]] = 0.0
        z = Z[p, j]
        res = linprog(cost, A_ub=A, b_ub=np.concatenate([-z, z]),
                      bounds=np.column_stack([lower, np.full(len(cost), np.inf)]),
                      method="highs")
        if res.status != 0:
            if g == 1:
                return best
            # the joint program may run into numerical trouble where the blocks' scales
            # differ; each open mold is then fitted on its own, from where it stands
            for m in np.flatnonzero(open_):
                mine = owner == m
                best[m] = _refit_molds(U[mine], Z[mine], np.zeros(int(mine.sum()), np.int64),
                                       best[m:m + 1], free, reach[m:m + 1])[0]
            return best
        which = np.flatnonzero(open_)
        best[which, :free] = res.x[column[which, None] + np.arange(free)] / scale[which, None]
        before = np.bincount(owner, weights=active.sum(axis=1), minlength=g)
        marked = np.flatnonzero(rows)
        sub = active[marked]
        _mark_extremes(sub, U[marked], Z[marked], best[owner[marked]])
        active[marked] = sub
        after = np.bincount(owner, weights=active.sum(axis=1), minlength=g)
        open_ &= after > before
        if not open_.any():
            break
    return best


def _refit_constraints(u: np.ndarray, k_column: np.ndarray, c_column: np.ndarray,
                       t_column: np.ndarray, columns: int) -> sp.csr_matrix:
    """The constraint matrix of `_refit_molds`'s linear program, (2 m, columns) CSR.

    For every active sample (m, with its scaled squared coordinates `u` (m, free)) the rows
    of ``z - u.k/2 - c <= t`` and ``-(z - u.k/2 - c) <= t``, ``k`` its mold's curvatures
    (columns ``k_column + 0 .. free - 1``), ``c`` its panel's shift (column `c_column`) and
    ``t`` its mold's gap (column `t_column`); zeros of ``u/2`` left out.
    """
    m, free = u.shape
    half = 0.5 * u
    row, col = np.nonzero(half)
    rows = np.arange(m)
    minus = -np.ones(m)
    k = k_column[row] + col
    row_all = np.concatenate([row, rows, rows, row + m, rows + m, rows + m])
    col_all = np.concatenate([k, c_column, t_column, k, c_column, t_column])
    data = np.concatenate([-half[row, col], minus, minus, half[row, col], -minus, minus])
    return sp.csr_matrix((data, (row_all, col_all)), shape=(2 * m, columns))


def _mark_extremes(active: np.ndarray, U: np.ndarray, Z: np.ndarray, K: np.ndarray) -> None:
    """Mark in `active` (q, s) each panel's highest and lowest sample above its mold, `K`
    (q, 2) per panel (1/mm)."""
    r = Z - 0.5 * (U[..., 0] * K[:, 0, None] + U[..., 1] * K[:, 1, None])
    rows = np.arange(len(Z))
    active[rows, r.argmax(axis=1)] = True
    active[rows, r.argmin(axis=1)] = True


def _thin_candidates(K: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Indices of candidate molds, one per grid cell of their own scale.

    A candidate from a panel of reach ``r`` (see `_panel_data`) falls in a cell of side
    about ``r / 64`` (a power of two, so cells of different scales nest): moving a mold
    that far changes its gaps by about a sixteenth of the tolerance, so candidates closer
    than that cover nearly the same panels. The first candidate of every cell is kept.
    """
    cell = 2.0 ** np.floor(np.log2(np.maximum(reach, 1e-300) / 64.0))
    key = np.column_stack([np.log2(cell), np.floor(K / cell[:, None])])
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


@dataclass
class _Stage:
    """The molds of one type and the assignment of that type's panels (internal)."""

    molds: np.ndarray       # (m, 2) 1/mm
    mold: np.ndarray        # (n,) mold index of each panel
    variant: np.ndarray     # (n,) placement frame of each panel


def _assign(data: _Panels, candidates: np.ndarray, free: int, tolerance: float,
            rounds: int) -> _Stage:
    """Cover the panels by molds, then refit, reassign and remove molds until stable.

    ``candidates`` (c, 2): one candidate mold per panel (its own shape), thinned here by
    `_thin_candidates`, or the only mold of a plane.
    """
    n = len(data.shapes)
    if n == 0:
        return _Stage(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(candidates) == n:
        candidates = candidates[_thin_candidates(candidates[:, :max(free, 1)], data.reach)]
    dev, _ = _gap_matrix(data, candidates)
    fits = dev <= tolerance
    molds = candidates[_greedy_cover(fits)]
    # a panel that no candidate fits gets a mold of its own shape (refitted below)
    alone = np.flatnonzero(~fits.any(axis=1))
    if alone.size:
        own = data.shapes[alone, 0].copy()
        own[:, free:] = 0.0
        molds = np.concatenate([molds, own])
    mold = np.full(n, -1)
    state: tuple[int, bytes] | None = None
    # (mold, members, placements) already refitted: a refit is a fixpoint
    refitted: set[tuple[bytes, bytes, bytes]] = set()
    for _ in range(max(rounds, 1)):
        dev, var = _gap_matrix(data, molds)
        rows = np.arange(n)
        # every panel to its closest mold; a panel stays unless another fits strictly better
        best = np.argmin(dev, axis=1)
        stay = (mold >= 0) & (dev[rows, np.maximum(mold, 0)] <= dev[rows, best])
        mold = np.where(stay, mold, best)
        mold, molds, dev, var = _remove_molds(mold, molds, dev, var, tolerance)
        variant, deviation = var[rows, mold], dev[rows, mold]
        groups = [np.flatnonzero(mold == j) for j in range(len(molds))]
        keys = [(molds[j].tobytes(), m.tobytes(), variant[m].tobytes())
                for j, m in enumerate(groups)]
        todo = [j for j in range(len(molds)) if keys[j] not in refitted]
        if todo:
            members = np.concatenate([groups[j] for j in todo])
            owner = np.repeat(np.arange(len(todo)), [groups[j].size for j in todo])
            U, Z = data.U[members, variant[members]], data.Z[members, variant[members]]
            reach = np.array([np.median(data.reach[groups[j]]) for j in todo])
            new = _refit_molds(U, Z, owner, molds[todo], free, reach)
            gap = np.zeros(len(todo))
            np.maximum.at(gap, owner, _offset_gap(U, Z, new[owner])[0])
            worst = np.zeros(len(todo))
            np.maximum.at(worst, owner, deviation[members])
            for i, j in enumerate(todo):
                if gap[i] <= worst[i]:
                    molds[j] = new[i]
                refitted.add((molds[j].tobytes(), keys[j][1], keys[j][2]))
        settled = (len(molds), mold.tobytes())
        if settled == state:
            break
        state = settled
    _, var = _gap_matrix(data, molds)
    return _Stage(molds=molds, mold=mold, variant=var[np.arange(n), mold])


def _remove_molds(mold: np.ndarray, molds: np.ndarray, dev: np.ndarray, var: np.ndarray,
                  tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop molds (fewest panels first) whose panels all fit another remaining mold, moving
    each of them to its closest remaining mold."""
    alive = np.ones(len(molds), bool)
    fits = dev <= tolerance
    counts = np.bincount(mold, minlength=len(molds))
    for j in np.lexsort((np.arange(len(molds)), counts)):
        members = np.flatnonzero(mold == j)
        others = alive.copy()
        others[j] = False
        if members.size and not np.all((fits[members] & others).any(axis=1)):
            continue
        if members.size:
            d = np.where(others, dev[members], np.inf)
            mold[members] = np.argmin(d, axis=1)
        alive[j] = False
    renumber = np.cumsum(alive) - 1
    return renumber[mold], molds[alive].copy(), dev[:, alive], var[:, alive]


# ----------------------------------------------------------------------------- the plan
@dataclass
class MoldPlan:
    """The molds of a net and every panel's placement on its mold, as measured.

    Attributes
    ----------
    mesh : the net (`fabplan.mesh.QuadMesh`).
    settings : the `MoldSettings` used.
    panel_surface : the panel surface model used (``"shared"``, ``"local_fit"``,
        ``"corners"`` or ``"design"``).
    panel_type : (p,) int, index into `PANEL_TYPES`.
    curvature : (p, 2) float, signed principal curvatures ``k1 >= k2`` of every panel
        with respect to its face normal (1/mm).
    mold_type : (m,) int, index into `MOLD_TYPES`.
    mold_shape : (m, 2) float, ``(k1, k2)`` of every mold (1/mm).
    panel_shape : (p, 2) float, every panel's own ``(k1, k2)`` in its placement frame on its
        mold (1/mm): what its mold's curvatures approximate.
    mold : (p,) int, the mold of every panel.
    placement : (p, 4, 4) float, model coordinates -> mold coordinates (mm); the upper
        left block is ``mm_per_unit`` times a rotation.
    deviation_mm : (p,) float, largest gap between the densely sampled panel and its
        mold, measured through `placement`.
    footprint_mm : (p, 2) float, ``2 max |x|``, ``2 max |y|`` of the placed panel.
    problem : list of str or None per panel: why it does not fit, if it does not.
    weingarten : `weingarten_fit` of the panel curvatures (1/mm).
    reassigned : (k,) int, panels the dense verification found above the tolerance on their
        first mold, classified again and moved to new molds.
    step_mm : (i,) float, the step between the molds of the two panels of every interior
        edge (`panel_steps`), in the order of ``mesh.interior_edge_faces``.
    kink_deg : (i,) float, the largest angle between those two molds' normals there.
    surface_step_mm : (i,) float, how far the two panels' surfaces themselves differ along
        every interior edge (`fabplan.fabricate.panels.surface_steps`): the part of a step
        no mold can close.
    recast_for_steps : (k,) int, panels at edges whose first molds stepped apart by more
        than twice the tolerance, cast again on molds that fit them closer.
    classes : with a material (`MoldSettings.material`), every panel's class
        (`fabplan.fabricate.panel_classes.PanelClasses`); None without one (every curved
        panel is molded). The molds are planned for every curved panel either way: a
        cold-bent, roll-bent or flat panel keeps its mold as the surface its neighbours'
        steps and the boundary panels are measured against, but only the molds of molded
        panels are made (`mold_made`).
    surface : the panel surfaces as triangle meshes (`fabplan.fabricate.panel_meshes`,
        `PANEL_MESH_LEVEL`), corners on the net's vertices: what the IFC export writes
        and `panel_area` measures; None for a plan made without them.
    seconds : run time.
    """

    mesh: QuadMesh
    settings: MoldSettings
    panel_surface: str
    panel_type: np.ndarray
    curvature: np.ndarray
    mold_type: np.ndarray
    mold_shape: np.ndarray
    panel_shape: np.ndarray
    mold: np.ndarray
    placement: np.ndarray
    deviation_mm: np.ndarray
    footprint_mm: np.ndarray
    problem: list[str | None]
    weingarten: dict
    reassigned: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    step_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kink_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    surface_step_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    recast_for_steps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    classes: PanelClasses | None = None
    surface: PanelMesh | None = None
    seconds: float = 0.0
    stage_seconds: dict[str, float] = field(default_factory=dict)

    # ------------------------------------------------------------------ derived numbers
    @property
    def panel_count(self) -> int:
        return len(self.mold)

    @property
    def mold_count(self) -> int:
        return len(self.mold_shape)

    @property
    def mold_made(self) -> np.ndarray:
        """(m,) bool, the molds that are made: the curved molds (a plane is no mold) that a
        molded panel sits on; without a material every curved mold."""
        made = np.asarray(self.mold_type) > 0
        if self.classes is not None:
            made &= np.bincount(self.mold[self.classes.molded], minlength=self.mold_count) > 0
        return made

    @property
    def made_mold_count(self) -> int:
        """The molds made (`mold_made`)."""
        return int(self.mold_made.sum())

    @property
    def molds_saved(self) -> int:
        """The curved molds that every curved panel molded would need and the material's
        classes do not: cold-bent, roll-bent and flat panels need none."""
        return int(np.sum(np.asarray(self.mold_type) > 0)) - self.made_mold_count

    @property
    def failures(self) -> np.ndarray:
        """(k,) int, faces that do not fit their mold."""
        return np.array([i for i, p in enumerate(self.problem) if p], dtype=np.int64)

    @property
    def step_limit_mm(self) -> float:
        """Largest step allowed between neighbouring panels (`MoldSettings.step_limit_mm`)."""
        s = self.settings
        return 2.0 * s.tolerance_mm if s.step_limit_mm is None else float(s.step_limit_mm)

    @property
    def steps_over(self) -> np.ndarray:
        """(k,) int, interior edges (rows of ``mesh.interior_edge_faces``) whose step
        exceeds `step_limit_mm`."""
        return np.flatnonzero(self.step_mm > self.step_limit_mm)

    @property
    def max_step_mm(self) -> float:
        return float(self.step_mm.max()) if self.step_mm.size else 0.0

    @property
    def fits_all(self) -> bool:
        """Every panel fits its mold and no step between neighbours exceeds the limit."""
        return self.failures.size == 0 and self.steps_over.size == 0

    def mold_count_bound(self) -> tuple[float, int]:
        """`mold_count_bound` of the curved panels' curvatures, each in the form a mold takes
        it (turned over when its mean curvature is negative: ``(-k2, -k1)``), at the median
        panel's reach; ``(0.0, 0)`` when every panel is flat."""
        curved = np.asarray(self.panel_type) > 0
        if not curved.any():
            return 0.0, 0
        k = self.curvature[curved]
        turned = np.where((k.sum(axis=1) < 0)[:, None], -k[:, ::-1], k)
        return mold_count_bound(turned, self.curvature_reach(0.5))

    @property
    def panel_area(self) -> np.ndarray | None:
        """(p,) float, every panel's area on its triangulated surface (`surface`; model
        units squared), or None without it."""
        return None if self.surface is None else self.surface.areas()

    @property
    def panels_per_mold(self) -> np.ndarray:
        """(m,) int"""
        return np.bincount(self.mold, minlength=self.mold_count)

    def mold_extent_mm(self) -> np.ndarray:
        """(m, 2) float, the rectangle centred on each mold's apex that holds its panels."""
        ext = np.zeros((self.mold_count, 2))
        np.maximum.at(ext, self.mold, self.footprint_mm)
        return ext

    def mold_deviation_mm(self) -> np.ndarray:
        """(m,) float, the largest deviation of a mold's panels."""
        dev = np.zeros(self.mold_count)
        np.maximum.at(dev, self.mold, self.deviation_mm)
        return dev

    def panel_width_mm(self, quantile: float = 0.5) -> float:
        """A quantile of the panels' widths (the smaller side of their footprints), mm."""
        return float(np.quantile(np.min(self.footprint_mm, axis=1), quantile))

    def curvature_reach(self, quantile: float = 0.5) -> float:
        """Curvature difference (1/mm) one mold absorbs for a panel of the given width
        quantile: a pure shift leaves a gap of ``dk w^2 / 16`` over a panel of width ``w``,
        so larger panels (higher quantiles) absorb less."""
        w = self.panel_width_mm(quantile)
        return 16.0 * self.settings.tolerance_mm / w**2 if w > 0 else math.inf

    def record(self) -> dict:
        """The JSON record (``molds.json``; schema in ``docs/molds-schema.md``)."""
        mm = self.settings.mm_per_unit
        types, counts = np.unique(self.panel_type, return_counts=True)
        per = self.panels_per_mold
        ext, mdev = self.mold_extent_mm(), self.mold_deviation_mm()
        made = self.mold_made
        molds = []
        for j in range(self.mold_count):
            k1, k2 = (float(v) for v in self.mold_shape[j])
            molds.append({
                "id": j,
                "type": MOLD_TYPES[self.mold_type[j]],
                "k1": k1,
                "k2": k2,
                "radius1_mm": 1.0 / k1 if k1 else None,
                "radius2_mm": 1.0 / k2 if k2 else None,
                "size_mm": [float(ext[j, 0]), float(ext[j, 1])],
                "panel_count": int(per[j]),
                "max_deviation_mm": float(mdev[j]),
                "made": bool(made[j]),
            })
        area = self.panel_area
        panels = []
        for i in range(self.panel_count):
            panels.append({
                **({} if area is None else {"area": float(area[i])}),
                "face": i,
                "mold": int(self.mold[i]),
                "type": PANEL_TYPES[self.panel_type[i]],
                "k1": float(self.curvature[i, 0]),
                "k2": float(self.curvature[i, 1]),
                "placement": self.placement[i].tolist(),
                "deviation_mm": float(self.deviation_mm[i]),
                "footprint_mm": [float(v) for v in self.footprint_mm[i]],
                "fits": self.problem[i] is None,
                "problem": self.problem[i],
                **({} if self.classes is None else
                   {"class": CLASSES[self.classes.panel_class[i]]}),
            })
        n = self.panel_count
        length, bound = self.mold_count_bound()
        return {
            "schema": "fabplan-molds/2",
            "net": str(getattr(self.mesh, "name", "")),
            "units": self.settings.units,
            "mm_per_unit": mm,
            "tolerance_mm": float(self.settings.tolerance_mm),
            "max_mold_size_mm": self.settings.max_mold_size_mm,
            "panel_surface": self.panel_surface,
            "panel_count": n,
            "mold_count": self.mold_count,
            "curved_mold_count": int(np.sum(self.mold_type > 0)),
            "molds_per_sqrt_panels": self.mold_count / math.sqrt(n),
            "panel_types": {t: int(counts[types == i].sum()) for i, t in enumerate(PANEL_TYPES)},
            "mold_types": {t: int(np.sum(self.mold_type == i)) for i, t in enumerate(MOLD_TYPES)},
            "panels_per_mold": {"min": int(per.min()), "median": float(np.median(per)),
                                "mean": float(per.mean()), "max": int(per.max())},
            "max_deviation_mm": float(self.deviation_mm.max()),
            **({} if area is None else {"panel_area": {
                "total": float(area.sum()), "units": f"{self.settings.units}^2",
                "surface": f"the panel surfaces triangulated, {PANEL_MESH_LEVEL} steps per side "
                           "of every fan triangle (as the IFC export writes them)"}}),
            "panel_steps": self._steps_record(),
            "mold_count_bound": {"curvature_set_length_per_mm": length,
                                 "mold_reach_per_mm": self.curvature_reach(0.5),
                                 "molds": bound},
            "fits_all": self.fits_all,
            "failures": self.failures.tolist(),
            "reassigned_by_verification": self.reassigned.tolist(),
            "recast_for_steps": self.recast_for_steps.tolist(),
            "weingarten": self.weingarten,
            "molds_made": self.made_mold_count,
            "molds_saved_by_material": self.molds_saved,
            "panel_classes": None if self.classes is None else self.classes.record(mm),
            "curvature_reach_per_mm": {"median_panel": self.curvature_reach(0.5),
                                       "large_panels": self.curvature_reach(0.9)},
            "seconds": self.seconds,
            "molds": molds,
            "panels": panels,
        }

    def _steps_record(self) -> dict:
        pairs, edges = self.mesh.interior_edge_faces, self.mesh.interior_edges
        over = self.steps_over
        over = over[np.argsort(-self.step_mm[over], kind="stable")]
        return {
            "limit_mm": self.step_limit_mm,
            "edge_count": int(len(self.step_mm)),
            "max_mm": self.max_step_mm,
            "median_mm": float(np.median(self.step_mm)) if self.step_mm.size else 0.0,
            "max_kink_deg": float(self.kink_deg.max()) if self.kink_deg.size else 0.0,
            "panel_surfaces_max_mm": (float(self.surface_step_mm.max())
                                      if self.surface_step_mm.size else 0.0),
            "fractions": [float(v) for v in self.settings.step_fractions],
            "over_limit": [{"faces": [int(a), int(b)], "vertices": [int(u), int(v)],
                            "step_mm": float(d), "panel_surfaces_mm": float(g)}
                           for (a, b), (u, v), d, g in zip(
                               pairs[over].tolist(), edges[over].tolist(),
                               self.step_mm[over].tolist(), self.surface_step_mm[over].tolist(),
                               strict=True)],
        }

    def panels_csv(self) -> str:
        """``panels.csv``: one row per panel (placement flattened row by row)."""
        head = ["face", "mold", "type", "k1_per_mm", "k2_per_mm", "deviation_mm",
                "footprint_x_mm", "footprint_y_mm", "fits"]
        head += [f"m{r}{c}" for r in range(4) for c in range(4)]
        if self.classes is not None:
            head += ["class", "class_figure", "class_limit", "class_unit"]
            value, limit, unit = self.classes.figure()
        lines = [",".join(head)]
        for i in range(self.panel_count):
            row = [str(i), str(int(self.mold[i])), PANEL_TYPES[self.panel_type[i]],
                   f"{self.curvature[i, 0]:.9g}", f"{self.curvature[i, 1]:.9g}",
                   f"{self.deviation_mm[i]:.4f}", f"{self.footprint_mm[i, 0]:.1f}",
                   f"{self.footprint_mm[i, 1]:.1f}", "yes" if self.problem[i] is None else "no"]
            row += [f"{v:.12g}" for v in self.placement[i].ravel()]
            if self.classes is not None:
                row += [CLASSES[self.classes.panel_class[i]], f"{value[i]:.6g}",
                        f"{limit[i]:.6g}", unit[i]]
            lines.append(",".join(row))
        return "\n".join(lines) + "\n"

    def summary(self) -> str:
        """A few lines for the terminal."""
        r = self.record()
        t = r["panel_types"]
        w = self.weingarten
        lines = [
            f"{r['panel_count']} panels ({t['planar']} planar, {t['single_curved']} single curved, "
            f"{t['double_curved']} double curved) at {r['tolerance_mm']:g} mm",
            f"{r['mold_count']} molds ({r['mold_types']['plane']} plane, "
            f"{r['mold_types']['cylinder']} cylinder, {r['mold_types']['paraboloid']} paraboloid)"
            + (" with every curved panel molded" if self.classes is not None else "")
            + f"; M / sqrt(N) = {r['molds_per_sqrt_panels']:.2f}",
            f"largest deviation {r['max_deviation_mm']:.3f} mm; "
            + ("every panel fits its mold" if self.failures.size == 0 else
               f"{len(r['failures'])} panels do not fit (faces {r['failures'][:10]})"),
            f"largest step between neighbouring panels' molds {self.max_step_mm:.3f} mm "
            f"(limit {self.step_limit_mm:g} mm, {self.steps_over.size} shared edges over it); "
            f"the curvature set's length over one mold's reach suggests about "
            f"{r['mold_count_bound']['molds']} molds (an estimate, not a bound)",
        ]
        if self.classes is not None:
            c = self.classes.counts
            lines.append(f"{self.classes.material.label}: {c['flat']} flat, {c['cold_bent']} "
                         f"cold-bent, {c['roll_bent']} roll-bent, {c['molded']} molded panels: "
                         f"{self.made_mold_count} molds to make, {self.molds_saved} saved by "
                         "the material")
        if w.get("thickness") is not None:
            lines.append(f"Weingarten residual: rms {w['line_residual_rms'] * 1000:.4g} 1/m from the "
                         f"line a k1 + b k2 = c, {w['thickness']:.3f} of the curvature spread")
        return "\n".join(lines)


def plan_molds(mesh: QuadMesh, settings: MoldSettings | None = None, *, design: Any = None,
               **options: Any) -> MoldPlan:
    """Find few molds that fit every panel of a net, and verify every panel on its mold.

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh` (faces of any size).
    settings : `MoldSettings`; or give its fields as keyword options
        (``plan_molds(mesh, tolerance_mm=5, units="m")``).
    design : the `fabplan.design.DesignSurface` the net lies on, when it was laid out on one
        and held there: with an exact surface (a built-in or NURBS design) the panels are
        its patches (panel surface ``design``, `fabplan.fabricate.panels`).

    Returns
    -------
    MoldPlan

    Raises
    ------
    InputError
        For impossible settings, a net without faces or with a degenerate face.
    """
    start = time.perf_counter()
    if settings is None:
        settings = MoldSettings(**options)
    elif options:
        raise InputError("give either settings or keyword options, not both")
    settings.check()
    check_panels(mesh)
    mm = settings.mm_per_unit
    tol = settings.tolerance_mm
    work = settings.working_tolerance_mm
    clock: dict[str, float] = {}

    model = surface_model(mesh, tol / mm, settings.panel_surface, design)

    def samples(level: int) -> np.ndarray:
        if model == "design":
            return design_panel_samples(mesh, surfaces, design, level)
        if model == "shared":
            return shared_panel_samples(mesh, local, level)
        return panel_samples(mesh, surfaces, level)

    # the points the quadrics of the design and shared models are fitted to serve the
    # assignment too
    if model == "design":
        surfaces, points = fit_design_panels(mesh, design, settings.cover_level)
    elif model == "shared":
        local = fit_panel_surfaces(mesh, "local_fit")
        surfaces, points = fit_shared_panels(mesh, local, settings.cover_level)
    else:
        surfaces = fit_panel_surfaces(mesh, model)
        points = panel_samples(mesh, surfaces, settings.cover_level)
    shapes = panel_shapes(surfaces)
    frames, kk = placement_frames(shapes)
    kk = kk / mm
    data = _panel_data(points, shapes.point, frames, kk, mm, work)
    clock["panel model"] = time.perf_counter() - start

    panel_type, cylinder = _classify(data, work)
    # the dense samples verify the molds below; with a material they decide every panel's
    # class first (the classes do not change the molds' assignment: the molds the curved
    # panels would need are planned in full, and only those of molded panels are made)
    dense = samples(settings.verify_level)
    classes = None if settings.material is None else classify_panels(
        mesh, dense, shapes.normal, settings.material, tol, mm, settings.class_order)
    clock["classification"] = time.perf_counter() - start - sum(clock.values())
    mold, variant, mold_shape, mold_type = _assign_by_type(data, panel_type, cylinder, work,
                                                           settings.rounds)
    clock["assignment"] = time.perf_counter() - start - sum(clock.values())

    # verification on dense samples; a panel found above the tolerance is classified again
    # on them (it may be more curved than the assignment samples showed) and gets a new mold
    placement, deviation = _place(dense, shapes.point, frames, variant, mold_shape[mold], mm)
    over = np.flatnonzero(deviation > tol)

    def recast(faces: np.ndarray, tolerance: float) -> None:
        """Classify `faces` again on the dense samples (at the working tolerance) and give
        them new molds of their own at `tolerance` (mm)."""
        nonlocal mold, mold_shape, mold_type, placement
        data = _panel_data(dense[faces], shapes.point[faces], frames[faces], kk[faces], mm,
                           tolerance)
        dense_type, cylinder = _classify(data, work)
        panel_type[faces] = np.maximum(panel_type[faces], dense_type)
        new = _assign_by_type(data, panel_type[faces], cylinder, tolerance, settings.rounds)
        mold[faces] = new[0] + len(mold_shape)
        variant[faces] = new[1]
        mold, mold_shape, mold_type = _drop_empty(mold, np.concatenate([mold_shape, new[2]]),
                                                  np.concatenate([mold_type, new[3]]))
        placement, _ = _place(dense, shapes.point, frames, variant, mold_shape[mold], mm)

    if over.size:
        recast(over, work)
    # neighbours whose molds step apart by more than twice the tolerance: the panels of those
    # edges are cast on molds of their own that fit them closer, halving the gap each round
    # (a step is at most the two gaps plus what the panel surfaces differ by: where these
    # alone take up the limit, closer molds cannot help and would only add molds)
    fractions = np.asarray(settings.step_fractions, float)
    step, kink = panel_steps(mesh, placement, mold_shape[mold], mm, fractions=fractions)
    # pieces of one surface share their edges; the other panels' surfaces may differ there
    surface_step = (np.zeros(len(mesh.interior_edge_faces)) if model in ("design", "shared")
                    else surface_steps(mesh, surfaces, fractions) * mm)
    step_limit = 2.0 * tol if settings.step_limit_mm is None else float(settings.step_limit_mm)
    closable = surface_step + 2.0 * work * 0.5**STEP_ROUNDS <= step_limit
    stepped = np.zeros(0, np.int64)
    for k in range(1, STEP_ROUNDS + 1):
        faces = np.unique(mesh.interior_edge_faces[(step > step_limit) & closable])
        if faces.size == 0:
            break
        stepped = np.union1d(stepped, faces)
        recast(faces, work * 0.5**k)
        step, kink = panel_steps(mesh, placement, mold_shape[mold], mm, fractions=fractions)
    # a panel classified single curved on the assignment samples but cast on a doubly
    # curved mold (`_merge_curved_molds`) was never checked against a cylinder on the
    # dense ones: classify it there
    moved = np.flatnonzero((panel_type == 1) & (mold_type[mold] != 1))
    if moved.size:
        data = _panel_data(dense[moved], shapes.point[moved], frames[moved], kk[moved], mm, work)
        panel_type[moved] = np.maximum(panel_type[moved], _classify(data, work)[0])
    clock["steps"] = time.perf_counter() - start - sum(clock.values())
    q = np.einsum("pij,psj->psi", placement[:, :3, :3], dense) + placement[:, None, :3, 3]
    footprint = 2.0 * np.abs(q[..., :2]).max(axis=1)
    deviation = placement_deviations(dense, placement, mold_shape[mold])
    clock["verification"] = time.perf_counter() - start - sum(clock.values())

    n = len(panel_type)
    problem: list[str | None] = [None] * n
    for i in np.flatnonzero(deviation > tol):
        problem[i] = f"deviates {deviation[i]:.3f} mm from its mold (tolerance {tol:g} mm)"
    if settings.max_mold_size_mm is not None:
        limit = settings.max_mold_size_mm
        for i in np.flatnonzero(footprint.max(axis=1) > limit):
            problem[i] = (f"needs a mold of {footprint[i, 0]:.0f} x {footprint[i, 1]:.0f} mm, "
                          f"larger than the largest mold ({limit:g} mm)")
    curvature = np.column_stack([shapes.k1, shapes.k2]) / mm
    weingarten = weingarten_fit(curvature[:, 0], curvature[:, 1])
    # the panels as triangle meshes: the assignment's samples when they are at that level
    surface = panel_surface_mesh(mesh, points if settings.cover_level == PANEL_MESH_LEVEL
                                 else samples(PANEL_MESH_LEVEL), PANEL_MESH_LEVEL)
    clock["panel meshes"] = time.perf_counter() - start - sum(clock.values())
    return MoldPlan(mesh=mesh, settings=settings, panel_surface=model, panel_type=panel_type,
                    curvature=curvature, mold_type=mold_type, mold_shape=mold_shape,
                    panel_shape=kk[np.arange(n), variant], mold=mold,
                    placement=placement, deviation_mm=deviation, footprint_mm=footprint,
                    problem=problem, weingarten=weingarten, reassigned=over,
                    step_mm=step, kink_deg=kink, surface_step_mm=surface_step,
                    recast_for_steps=stepped, classes=classes, surface=surface,
                    seconds=time.perf_counter() - start, stage_seconds=clock)


def _classify(data: _Panels, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Panel types (indices into `PANEL_TYPES`): planar when the plane, else single curved
    when the best cylinder mold fits within `tolerance` (mm), else double curved; and the
    best cylinder curvature of every panel (1/mm)."""
    plane = _offset_gap(data.U[:, 0], data.Z[:, 0], np.zeros(2))[0]
    cylinder, cylinder_gap = _cylinder_fits(data.U[:, 0], data.Z[:, 0], data.shapes[:, 0, 0])
    return np.where(plane <= tolerance, 0, np.where(cylinder_gap <= tolerance, 1, 2)), cylinder


def _assign_by_type(data: _Panels, panel_type: np.ndarray, cylinder: np.ndarray,
                    tolerance: float, rounds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Molds for panels, each type on molds of its own type (plane, cylinder, paraboloid).

    Returns mold (p,) int, variant (p,) int, mold shapes (m, 2), mold types (m,) int.
    """
    n = len(panel_type)
    mold = np.zeros(n, np.int64)
    variant = np.zeros(n, np.int64)
    shapes, types = [np.zeros((0, 2))], [np.zeros(0, np.int64)]
    count = 0
    for t, kind in enumerate(MOLD_TYPES):
        idx = np.flatnonzero(panel_type == t)
        if idx.size == 0:
            continue
        sub = _subset(data, idx)
        if kind == "plane":
            candidates = np.zeros((1, 2))
        elif kind == "cylinder":
            candidates = np.column_stack([cylinder[idx], np.zeros(idx.size)])
        else:
            candidates = sub.shapes[:, 0]
        order = np.lexsort((candidates[:, 1], candidates[:, 0]))
        stage = _assign(sub, candidates[order], _FREE_DIMS[kind], tolerance, rounds)
        mold[idx] = stage.mold + count
        variant[idx] = stage.variant
        shapes.append(stage.molds)
        types.append(np.full(len(stage.molds), t))
        count += len(stage.molds)
    return _merge_curved_molds(data, mold, variant, np.concatenate(shapes),
                               np.concatenate(types), tolerance)


def _merge_curved_molds(data: _Panels, mold: np.ndarray, variant: np.ndarray,
                        shapes: np.ndarray, types: np.ndarray, tolerance: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop the cylinder or paraboloid molds whose panels all fit the other curved molds.

    A single curved panel may sit on a doubly curved mold (and a doubly curved one on a
    cylinder, within the tolerance). Without this, a looser tolerance that lets a few
    panels pass as single curved would give them a cylinder mold of their own beside the
    paraboloid mold that already fits them: more molds at a looser tolerance.
    """
    curved = np.flatnonzero(types[mold] > 0)
    kept = np.flatnonzero(types > 0)
    if len(np.unique(types[kept])) < 2:
        return mold, variant, shapes, types
    local = np.full(len(shapes), -1)
    local[kept] = np.arange(len(kept))
    dev, var = _gap_matrix(_subset(data, curved), shapes[kept])
    members = local[mold[curved]]
    # a panel's own mold fits it on the assignment samples, whatever the gap matrix's
    # reach cut says
    dev[np.arange(len(curved)), members] = np.minimum(dev[np.arange(len(curved)), members],
                                                      tolerance)
    tagged = np.column_stack([shapes[kept], kept])         # which molds survive
    members, tagged, dev, var = _remove_molds(members, tagged, dev, var, tolerance)
    survivors = tagged[:, 2].astype(np.int64)
    if len(survivors) == len(kept):
        return mold, variant, shapes, types
    moved = survivors[members] != mold[curved]
    variant = variant.copy()
    variant[curved[moved]] = var[np.flatnonzero(moved), members[moved]]
    mold = mold.copy()
    mold[curved] = survivors[members]
    mold, shapes, types = _drop_empty(mold, shapes, types)
    return mold, variant, shapes, types


def _subset(data: _Panels, idx: np.ndarray) -> _Panels:
    return _Panels(shapes=data.shapes[idx], U=data.U[idx], Z=data.Z[idx], reach=data.reach[idx])


def _drop_empty(mold: np.ndarray, mold_shape: np.ndarray,
                mold_type: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    used = np.bincount(mold, minlength=len(mold_shape)) > 0
    renumber = np.cumsum(used) - 1
    return renumber[mold], mold_shape[used], mold_type[used]


def _place(points: np.ndarray, point: np.ndarray, frames: np.ndarray, variant: np.ndarray,
           shape: np.ndarray, mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Placement matrices (frame of the chosen variant, shift evening out the gap) and the
    resulting deviations, for samples (p, s, 3) and mold shapes (p, 2)."""
    R = frames[np.arange(len(variant)), variant]                     # (p, 3, 3)
    Q = mm * np.einsum("pij,psj->psi", R, points - point[:, None, :])
    dev, shift = _offset_gap(Q[..., :2] ** 2, Q[..., 2], shape)
    placement = np.zeros((len(variant), 4, 4))
    placement[:, :3, :3] = mm * R
    placement[:, :3, 3] = -mm * np.einsum("pij,pj->pi", R, point)
    placement[:, 2, 3] -= shift
    placement[:, 3, 3] = 1.0
    return placement, dev
