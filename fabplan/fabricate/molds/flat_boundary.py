"""Flat boundary panels: beside a net's flat panels, boundary panels cut from flat stock.

A boundary panel (`fabplan.layout.trim`) borders the net along some of its sides. Where
the net's panels across those sides are flat (on the plan's plane molds), the boundary
panel is flat too when one plane holds its net sides: the plane through two sides
meeting at a net vertex (the V between two tips of a zigzag net boundary), the plane of
the one face it continues (one pane with it), or the plane fitted to longer runs of sides
where they are that flat. It then meets each face beside it without a step, with a kink
only.

Two flat panels meet without a step only along the line where their planes cross. A
side they share that runs from a point of both planes (a tip of the net) to the design
boundary is therefore put on that line: its end slides along the design boundary to
where the line passes it (`fabplan.layout.trim.slide_splits`), the boundary's points
between going over from one panel to the other. This is the joint a facade engineer
draws between two flat panes, and it is found again from the panels' outlines: the
outlines as made are written to ``NET.boundary.obj``, and `flat_boundary_panels` on them
leaves them as they are.

A panel whose net sides no plane holds within the step limit (or beside curved panels)
is left to `fabplan.fabricate.molds.boundary_molds`, which fits it to the flat panels beside it
as to any other neighbour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...layout.boundary_panels import BoundaryPanels, slide_splits
from .boundary_sides import BoundarySides, boundary_sides
from .mold_plan import MoldPlan
from .mold_shapes import MOLD_TYPES, chord_steps

__all__ = ["FlatBoundary", "boundary_planes", "flat_boundary_panels", "plane_placements"]


@dataclass(frozen=True)
class FlatBoundary:
    """The flat boundary panels of a net.

    Attributes
    ----------
    panels : the `BoundaryPanels` as made: the sides two flat panels share slid onto the
        lines where their planes cross.
    flat : (p,) bool, the panels cut flat (slivers cut with a flat full panel included).
    placement : (p, 4, 4) float, model -> mold coordinates (mm) of each flat panel on a
        plane mold (its plane ``z = 0``); zero for the others.
    mold : (p,) int, the plane mold of the net's plan each flat panel is cut from; -1 for
        the others.
    slid : (k,) int, the points of ``panels.vertices`` moved onto such a line.
    """

    panels: BoundaryPanels
    flat: np.ndarray
    placement: np.ndarray
    mold: np.ndarray
    slid: np.ndarray

    @property
    def count(self) -> int:
        """Flat boundary panels made as panels of their own (slivers not counted)."""
        return int(np.sum(self.flat & ~np.asarray(self.panels.extension, bool)))


def plane_placements(normals: np.ndarray, points: np.ndarray, mm: float) -> np.ndarray:
    """Placements of a plane mold (``z = 0`` in mold coordinates) on planes.

    Parameters
    ----------
    normals : (p, 3) float, unit normals of the planes.
    points : (p, 3) float, a point of each plane (model units).
    mm : millimetres per model unit.

    Returns
    -------
    (p, 4, 4) float, model -> mold coordinates (mm): the rows of the rotation block are mm
    times two directions in the plane and the normal.

    Examples
    --------
    >>> import numpy as np
    >>> M = plane_placements(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 2.0]]), 1000.0)
    >>> float((M[0] @ [5.0, 1.0, 2.0, 1.0])[2])
    0.0
    """
    n = np.asarray(normals, float)
    # a direction in each plane: the axis least along the normal, made square to it
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    e1 = axis - np.sum(axis * n, axis=1)[:, None] * n
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(n, e1)
    R = np.stack([e1, e2, n], axis=1)
    M = np.zeros((len(n), 4, 4))
    M[:, :3, :3] = mm * R
    M[:, :3, 3] = -mm * np.einsum("pij,pj->pi", R, points)
    M[:, 3, 3] = 1.0
    return M


def boundary_planes(plan: MoldPlan, panels: BoundaryPanels, sides: BoundarySides,
                    step_limit_mm: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The boundary panels that can be flat, and their planes (see the module's text).

    Parameters
    ----------
    plan : the net's `MoldPlan`.
    panels : its `BoundaryPanels`.
    sides : their `BoundarySides`.
    step_limit_mm : the step allowed between a flat panel and a net face beside it (mm).

    Returns
    -------
    flat : (p,) bool.
    placement : (p, 4, 4) float, on a plane mold (zero where not flat).
    mold : (p,) int, the plan's plane mold (-1 where not flat).
    """
    p = panels.count
    mm = plan.settings.mm_per_unit
    flat = np.zeros(p, bool)
    placement = np.zeros((p, 4, 4))
    mold = np.full(p, -1, np.int64)
    plane_mold = np.asarray(plan.mold_type)[plan.mold] == MOLD_TYPES.index("plane")   # (f,)
    net = np.flatnonzero(sides.face >= 0)
    if not p or not net.size:
        return flat, placement, mold
    X = panels.vertices
    owner = sides.panel[net]
    face = sides.face[net]
    count = np.bincount(owner, minlength=p)
    on_plane = np.bincount(owner, plane_mold[face], minlength=p) == count
    # the plane through each panel's net sides: the smallest direction of their ends' spread
    ends = np.r_[sides.start[net], sides.end[net]]
    who = np.r_[owner, owner]
    weight = np.maximum(np.bincount(who, minlength=p), 1)
    centre = np.stack([np.bincount(who, X[ends, k], minlength=p) for k in range(3)], 1) / weight[:, None]
    d = X[ends] - centre[who]
    cov = np.zeros((p, 3, 3))
    np.add.at(cov, who, d[:, :, None] * d[:, None, :])
    value, vector = np.linalg.eigh(cov)
    normal = vector[:, :, 0]
    first = np.full(p, -1)
    first[owner[::-1]] = face[::-1]
    along = plan.placement[np.maximum(first, 0), 2, :3] / mm       # the face's mold normal
    normal = np.where((np.sum(normal * along, axis=1) < 0)[:, None], -normal, normal)
    placement = plane_placements(normal, centre, mm)
    # sides on one line (one side, or several in a row) leave the plane open: the panel
    # continues the face beside it, one pane with it (a panel beside it continuing the
    # same face, a sliver, then lies in its plane too)
    span = np.sqrt(np.maximum(value[:, 2], 0.0))
    open_ = np.sqrt(np.maximum(value[:, 1], 0.0)) <= 1e-6 * np.maximum(span, 1e-300)
    placement[open_] = plan.placement[np.maximum(first, 0)][open_]
    candidate = (count > 0) & on_plane
    # flat where every net side meets its face within the step limit
    chords = np.stack([X[sides.start[net]], X[sides.end[net]]], axis=1)
    M = np.stack([placement[owner], plan.placement[face]], axis=1)
    K = np.zeros((len(net), 2, 2))
    K[:, 1] = plan.mold_shape[plan.mold[face]]
    step = chord_steps(chords, M, K, mm, fractions=np.linspace(0.0, 1.0, 5))[0]
    worst = np.zeros(p)
    np.maximum.at(worst, owner, step)
    flat = candidate & (worst <= step_limit_mm)
    mold[flat] = plan.mold[first[flat]]
    # a sliver is cut with the full panel it continues: flat where that panel is
    continues = np.asarray(panels.neighbour_face, np.int64)
    sliver = np.asarray(panels.extension, bool) & (continues >= 0)
    sliver &= plane_mold[np.maximum(continues, 0)]
    placement[sliver] = plan.placement[continues[sliver]]
    mold[sliver] = plan.mold[continues[sliver]]
    flat |= sliver
    placement[~flat] = 0.0
    return flat, placement, mold


def flat_boundary_panels(plan: MoldPlan, panels: BoundaryPanels, *,
                         step_limit_mm: float | None = None, reach: float = 0.1) -> FlatBoundary:
    """The flat boundary panels of a net, and the panels with the sides two flat panels
    share slid onto the lines where their planes cross (see the module's text).

    Parameters
    ----------
    plan : the net's `MoldPlan`.
    panels : its `BoundaryPanels` (as cut, or as read from ``NET.boundary.obj``).
    step_limit_mm : the step allowed between neighbouring panels (mm); None: the plan's.
    reach : how far the line of two planes may pass from the design boundary for the side
        on it to end there (`fabplan.layout.trim.slide_splits`), in the net's mean edge
        lengths.

    Returns
    -------
    FlatBoundary
    """
    limit = float(plan.step_limit_mm if step_limit_mm is None else step_limit_mm)
    size = plan.mesh.mean_edge_length
    sides = boundary_sides(panels, plan.mesh)
    flat, placement, mold = boundary_planes(plan, panels, sides, limit)
    # the planes are the net's: sliding the panels' splits leaves them, and panels slid
    # once (as written to NET.boundary.obj) slide no further
    r, origin, direction = _crossing_lines(plan, panels, sides, flat, placement)
    panels, moved = slide_splits(panels, r, origin, direction, reach=reach * size)
    slid = r[moved]
    return FlatBoundary(panels=panels, flat=flat, placement=placement, mold=mold, slid=slid)


def _crossing_lines(plan: MoldPlan, panels: BoundaryPanels, sides: BoundarySides,
                    flat: np.ndarray, placement: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sides two flat panels share from a point of both planes (a tip of the net) to
    the design boundary: their ends there (k,) int, and the lines where the two planes
    cross, through a point (k, 3) along a direction (k, 3)."""
    mm = plan.settings.mm_per_unit
    both = (sides.across >= 0) & (sides.panel < sides.across)
    both &= flat[sides.panel] & flat[np.maximum(sides.across, 0)]
    on = panels.on_design_boundary
    n = panels.net_vertex_count
    start, end = sides.start, sides.end
    rim_end = on[end] & ~on[start] & (end >= n)
    rim_start = on[start] & ~on[end] & (start >= n)
    which = np.flatnonzero(both & (rim_end ^ rim_start))
    r = np.where(rim_end[which], end[which], start[which])
    tip = np.where(rim_end[which], start[which], end[which])
    a, b = sides.panel[which], sides.across[which]
    na, nb = placement[a, 2, :3] / mm, placement[b, 2, :3] / mm
    ha, hb = -placement[a, 2, 3] / mm, -placement[b, 2, 3] / mm
    X = panels.vertices[tip]
    direction = np.cross(na, nb)
    sine = np.linalg.norm(direction, axis=1)
    # the tip must be a point of both planes (to the plan's tolerance), and the planes
    # must cross (parallel planes meet nowhere, or everywhere)
    ra = ha - np.sum(X * na, axis=1)
    rb = hb - np.sum(X * nb, axis=1)
    ok = (np.maximum(np.abs(ra), np.abs(rb)) <= plan.settings.tolerance_mm / mm)
    ok &= sine > np.sin(np.radians(0.5))
    # the line's point nearest the tip: tip + alpha na + beta nb on both planes
    g = np.sum(na * nb, axis=1)
    det = np.maximum(1.0 - g * g, 1e-300)
    alpha, beta = (ra - g * rb) / det, (rb - g * ra) / det
    origin = X + alpha[:, None] * na + beta[:, None] * nb
    return r[ok], origin[ok], direction[ok]
