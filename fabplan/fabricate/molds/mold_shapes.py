"""Molds and what is measured on them: the settings of a mold plan, a mold's heights, the
closest points of a mold, the steps between neighbouring panels' molds.

Every mold is the surface ``z = (k1 x^2 + k2 y^2) / 2`` in mold coordinates (millimetres):
a *plane* (``k1 = k2 = 0``), a *cylinder* (``k2 = 0``) or a *paraboloid*. A panel lies on
its mold by a 4 x 4 placement (model units to millimetres). The plan that assigns panels to
molds is `fabplan.fabricate.molds.mold_assignment.plan_molds`; its record
`fabplan.fabricate.molds.mold_plan.MoldPlan`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...io.units import MM_PER_UNIT, check_units
from ...net.mesh import QuadMesh
from .materials import Material
from .panel_classes import DEFAULT_ORDER
from .panels import SURFACE_MODELS

__all__ = [
    "UNITS",
    "TOLERANCE_RANGE_MM",
    "PANEL_TYPES",
    "MOLD_TYPES",
    "MoldSettings",
    "mold_heights",
    "placement_deviations",
    "closest_mold_points",
    "panel_steps",
    "chord_steps",
    "mold_count_bound",
]

UNITS = MM_PER_UNIT    # the model units a plan takes (`fabplan.io.units`)
"""Millimetres per model unit for each accepted ``units`` name (molds and strips)."""

TOLERANCE_RANGE_MM = (0.01, 1000.0)
"""Mold tolerances that mean something: finer than 0.01 mm no mold is made, a gap of a
metre is no mold at all."""

PANEL_TYPES = ("planar", "single_curved", "double_curved")
MOLD_TYPES = ("plane", "cylinder", "paraboloid")


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
