"""Milling against the design: the design's heights on the simulation grid, its closest
points and normals for the tool paths, and the net's own distance from it.

A net laid out on a design (or optimized near it) lies off the design by what its
optimization allowed. Milling is meant to make the design: the simulation measures the cut
against the design's heights (`design_heights`), the planner puts the passes' nodes on the
design (`design_frames`), and the net's distance from the design is reported on its own
(`NetDistance`). Every length here is in millimetres; the design's coordinates are scaled
by ``mm_per_unit`` like the net's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...design.topology import edge_corners
from .mill_simulation import HeightTarget

__all__ = ["design_heights", "design_frames", "NetDistance", "net_distance_from_design",
           "mesh_faceting_mm"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _raster_triangles(corners: np.ndarray, target: HeightTarget, near: np.ndarray,
                      chunk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the grid's vertical lines cross the triangles `corners` (frame coordinates).

    Of several crossings on one line (a design folding over itself seen from the mill
    direction) the one nearest to `near` is kept.

    Parameters
    ----------
    corners : (t, 3, 3) float, triangle corners in the mill frame (mm).
    target : the grid (its ``x``, ``y``; cells where ``target.z`` is NaN are not sought).
    near : (ny * nx,) float, heights the crossing kept should be nearest to.
    chunk : (triangle, cell) pairs examined at once (memory).

    Returns
    -------
    z : (ny * nx,) float, height of the crossing (NaN: none).
    triangle : (ny * nx,) int, the triangle crossed (-1: none).
    bary : (ny * nx, 3) float, barycentric coordinates of the crossing in it.
    """
    nx, step = len(target.x), target.step
    ny = len(target.y)
    part = np.isfinite(target.z).ravel()
    z = np.full(ny * nx, np.nan)
    gap = np.full(ny * nx, np.inf)
    triangle = np.full(ny * nx, -1)
    bary = np.zeros((ny * nx, 3))
    xy = corners[:, :, :2]
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    lo, hi = xy.min(axis=1), xy.max(axis=1)
    i0 = np.maximum(np.ceil((lo[:, 0] - target.x[0]) / step - 1e-9), 0).astype(np.int64)
    i1 = np.minimum(np.floor((hi[:, 0] - target.x[0]) / step + 1e-9), nx - 1).astype(np.int64)
    j0 = np.maximum(np.ceil((lo[:, 1] - target.y[0]) / step - 1e-9), 0).astype(np.int64)
    j1 = np.minimum(np.floor((hi[:, 1] - target.y[0]) / step + 1e-9), ny - 1).astype(np.int64)
    # edge-on triangles are crossed by no vertical line
    seen = np.flatnonzero((i1 >= i0) & (j1 >= j0)
                          & (np.abs(area) > 1e-12 * max(float(np.abs(area).max()), 1e-300)))
    width = i1[seen] - i0[seen] + 1
    counts = width * (j1[seen] - j0[seen] + 1)
    bounds = np.searchsorted(np.cumsum(counts), np.arange(chunk, counts.sum() + chunk, chunk))
    start = 0
    for stop in np.unique(np.r_[bounds, len(seen)]):
        if stop <= start:
            continue
        who, cnt, w = seen[start:stop], counts[start:stop], width[start:stop]
        start = stop
        t = np.repeat(np.arange(len(who)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ci = i0[who][t] + local % w[t]
        cj = j0[who][t] + local // w[t]
        cell = cj * nx + ci
        tri = who[t]
        dx, dy = target.x[ci] - xy[tri, 0, 0], target.y[cj] - xy[tri, 0, 1]
        b1 = (dx * e2[tri, 1] - dy * e2[tri, 0]) / area[tri]
        b2 = (e1[tri, 0] * dy - e1[tri, 1] * dx) / area[tri]
        b0 = 1 - b1 - b2
        tol = -1e-9
        inside = (b0 >= tol) & (b1 >= tol) & (b2 >= tol) & part[cell]
        cell, tri = cell[inside], tri[inside]
        b = np.column_stack([b0[inside], b1[inside], b2[inside]])
        height = np.einsum("mk,mk->m", b, corners[tri, :, 2])
        off = np.abs(height - near[cell])
        # per cell the crossing nearest `near`: sorted by cell, then by gap
        order = np.lexsort((off, cell))
        first = order[np.r_[True, cell[order][1:] != cell[order][:-1]]]
        better = off[first] < gap[cell[first]]
        first = first[better]
        where = cell[first]
        z[where], gap[where], triangle[where], bary[where] = height[first], off[first], tri[first], b[first]
    return z, triangle, bary


def _exact_heights(parametric: Any, uv: np.ndarray, gx: np.ndarray, gy: np.ndarray,
                   target: HeightTarget, mm_per_unit: float,
                   iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Heights where the vertical lines at (gx, gy) cross the exact surface: Newton on the
    two frame coordinates ``(x, y)(u, v) = (gx, gy)`` from `uv`.

    Returns
    -------
    z : (m,) float, heights (mm); converged : (m,) bool, within 1e-7 mm of the line.
    """
    (u0, u1), (v0, v1) = parametric.domain
    R, origin, s = target.rotation, target.origin, mm_per_unit

    def inside(w: np.ndarray) -> np.ndarray:
        u = (u0 + np.mod(w[:, 0] - u0, u1 - u0) if parametric.periodic_u
             else np.clip(w[:, 0], u0, u1))
        return np.column_stack([u, np.clip(w[:, 1], v0, v1)])

    for _ in range(iterations):
        fu, fv = parametric.derivatives(uv[:, 0], uv[:, 1])[:2]
        p = (parametric.points(uv[:, 0], uv[:, 1]) * s - origin) @ R.T
        ru, rv = s * fu @ R.T, s * fv @ R.T
        fx, fy = p[:, 0] - gx, p[:, 1] - gy
        det = ru[:, 0] * rv[:, 1] - ru[:, 1] * rv[:, 0]
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        du = (rv[:, 1] * fx - rv[:, 0] * fy) / det
        dv = (ru[:, 0] * fy - ru[:, 1] * fx) / det
        uv = inside(uv - np.column_stack([du, dv]))
    p = (parametric.points(uv[:, 0], uv[:, 1]) * s - origin) @ R.T
    converged = np.hypot(p[:, 0] - gx, p[:, 1] - gy) <= 1e-7 * max(1.0, float(np.abs(p).max()))
    return p[:, 2], converged


def design_heights(design: Any, target: HeightTarget, mm_per_unit: float, *,
                   chunk: int = 1_000_000) -> np.ndarray:
    """The design's heights on the grid of a height map: where each vertical line of the
    mill frame crosses the design.

    On a mesh design the crossing with its triangles; on a design with an exact surface
    (a built-in or NURBS design) the crossing with that surface, found by Newton from the
    triangles'. Where the design folds over itself seen from the mill direction, the
    crossing nearest to the target's own height is kept.

    Parameters
    ----------
    design : a `fabplan.design.DesignSurface` (``vertices`` (n, 3), ``triangles`` (t, 3)
        in model units, ``exact``, ``parametric``, ``triangle_uv``).
    target : the net's height map (`fabplan.fabricate.milling.mill_simulation.height_target`):
        its grid, frame and part; the design is sought where ``target.z`` is finite.
    mm_per_unit : millimetres per model unit.
    chunk : (triangle, grid point) pairs examined at once.

    Returns
    -------
    (ny, nx) float, design heights in the mill frame (mm); NaN off the part and where the
    design does not reach.

    Examples
    --------
    >>> from fabplan.design.parametric import paraboloid
    >>> from fabplan.fabricate.milling.mill_simulation import height_target
    >>> design = paraboloid(radius_x=50.0, radius_y=50.0, width=10.0, depth=10.0).triangulate(20)
    >>> x, y = np.meshgrid(np.linspace(-8, 8, 5), np.linspace(-8, 8, 5))
    >>> net = np.column_stack([x.ravel(), y.ravel(), (x * x + y * y).ravel() / 100 + 0.1])
    >>> from matplotlib.tri import Triangulation
    >>> target = height_target(net, Triangulation(net[:, 0], net[:, 1]).triangles,
    ...                        np.array([0.0, 0, 1]), step_mm=1.0)
    >>> z = design_heights(design, target, 1.0)
    >>> gx, gy = np.meshgrid(target.x, target.y)
    >>> exact = (gx * gx + gy * gy) / 100 - target.origin[2]
    >>> bool(np.nanmax(np.abs(z - exact)) < 1e-9), bool(np.isfinite(z).sum() == 17 * 17)
    (True, True)
    """
    corners = target.to_frame(np.asarray(design.vertices, dtype=np.float64) * mm_per_unit)[
        np.asarray(design.triangles)]
    near = target.z.ravel()
    z, triangle, bary = _raster_triangles(corners, target, near, chunk)
    if getattr(design, "exact", False):
        found = np.flatnonzero(triangle >= 0)
        if found.size:
            uv = np.einsum("mk,mkj->mj", bary[found], design.triangle_uv(triangle[found]))
            nx = len(target.x)
            exact, converged = _exact_heights(design.parametric, uv, target.x[found % nx],
                                              target.y[found // nx], target, mm_per_unit)
            z[found] = np.where(converged, exact, z[found])
    return z.reshape(target.z.shape)


def mesh_faceting_mm(vertices: np.ndarray, triangles: np.ndarray, mm_per_unit: float) -> float:
    """How far a triangle mesh's flat faces stand off a smooth surface through its
    vertices, about (mm): over its inner edges, the curvature ``kappa`` the turn of the
    two triangles' normals makes over the distance of their centroids, and the sagitta
    ``kappa L^2 / 6`` of the longer edges ``L`` of an equilateral triangle on it; the 99th
    percentile, which leaves out a few creases meant as such.

    Examples
    --------
    >>> from fabplan.design.parametric import paraboloid
    >>> mesh = paraboloid(radius_x=300.0, radius_y=300.0, width=50.0, depth=50.0).triangulate(60)
    >>> X, T = mesh.vertices, mesh.triangles
    >>> L = np.linalg.norm(X[T[:, 1]] - X[T[:, 0]], axis=1).mean()
    >>> ratio = mesh_faceting_mm(X, T, 1.0) / (L * L / (8 * 300))
    >>> bool(0.5 < ratio < 3)
    True
    """
    X = np.asarray(vertices, dtype=np.float64) * mm_per_unit
    T = np.asarray(triangles)
    corner, other = edge_corners(T, len(X))      # the two corners of every inner edge
    if corner.size == 0:
        return 0.0
    normal = np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    centroid = X[T].mean(axis=1)
    a, b = corner // 3, other // 3
    turn = np.arccos(np.clip(np.abs(np.sum(normal[a] * normal[b], axis=1)), 0.0, 1.0))
    kappa = turn / np.maximum(np.linalg.norm(centroid[a] - centroid[b], axis=1), 1e-300)
    length = np.linalg.norm(X[T[:, [1, 2, 0]].ravel()[corner]] - X[T.ravel()[corner]], axis=1)
    return float(np.percentile(kappa * length * length / 6, 99))


def design_frames(design: Any, points_mm: np.ndarray, mm_per_unit: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The design's closest points to `points_mm` and its unit normals there.

    Parameters
    ----------
    design : a `fabplan.design.DesignSurface` in model units.
    points_mm : (m, 3) float, points (mm).
    mm_per_unit : millimetres per model unit.

    Returns
    -------
    foot : (m, 3) float, closest points of the design (mm; on the exact surface of a
        built-in or NURBS design).
    normal : (m, 3) float, unit normals there (the exact surface's; on a mesh the vertex
        normals interpolated), oriented along the face normals of the design.

    Examples
    --------
    >>> from fabplan.design.parametric import paraboloid
    >>> design = paraboloid(radius_x=50.0, radius_y=50.0, width=10.0, depth=10.0).triangulate(20)
    >>> foot, normal = design_frames(design, np.array([[0.0, 0.0, 3.0]]), 1.0)
    >>> (foot.round(6) + 0.0).tolist(), (normal.round(6) + 0.0).tolist()
    ([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    """
    import igl

    X = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3) / mm_per_unit
    foot, face_normal, tri = design.reference.closest_points(X)
    if getattr(design, "exact", False):
        corners = design.vertices[design.triangles[tri]]
        bary = igl.barycentric_coordinates(foot, corners[:, 0].copy(), corners[:, 1].copy(),
                                           corners[:, 2].copy())
        uv = design.parametric.closest_parameters(X, np.einsum("mk,mkj->mj", bary,
                                                               design.triangle_uv(tri)))
        fu, fv = design.parametric.derivatives(uv[:, 0], uv[:, 1])[:2]
        foot = design.parametric.points(uv[:, 0], uv[:, 1])
        normal = _unit(np.cross(fu, fv))
    else:
        corners = design.vertices[design.triangles[tri]]
        bary = igl.barycentric_coordinates(foot, corners[:, 0].copy(), corners[:, 1].copy(),
                                           corners[:, 2].copy())
        vertex_normals = igl.per_vertex_normals(design.vertices, design.triangles)
        normal = _unit(np.einsum("mk,mkj->mj", bary, vertex_normals[design.triangles[tri]]))
    normal = np.where((np.sum(normal * face_normal, axis=1) < 0)[:, None], -normal, normal)
    return foot * mm_per_unit, normal


@dataclass
class NetDistance:
    """How far the net is from the design it was made for (mm).

    Attributes
    ----------
    vertex_max_mm, vertex_mean_mm : largest and mean distance of the net's vertices from
        the design (closest points).
    above_max_mm, below_max_mm : the net's surface (the spline through its vertices the
        simulation measures without a design) above and below the design along the mill
        direction, the largest on the simulation grid (None without a simulation).
    cells : grid points where both are known.
    part_cells : grid points of the part (where the net's surface is known).
    """

    vertex_max_mm: float
    vertex_mean_mm: float
    above_max_mm: float | None = None
    below_max_mm: float | None = None
    cells: int = 0
    part_cells: int = 0

    @property
    def coverage(self) -> float | None:
        """Share of the part the design reaches on the grid (None without a grid)."""
        return self.cells / self.part_cells if self.part_cells else None

    def to_json(self) -> dict:
        return {"units": "mm", "vertex_max_mm": self.vertex_max_mm,
                "vertex_mean_mm": self.vertex_mean_mm,
                "surface_above_design_max_mm": self.above_max_mm,
                "surface_below_design_max_mm": self.below_max_mm,
                "measured_cells": self.cells, "part_cells": self.part_cells,
                "design_covers_part": self.coverage}


def net_distance_from_design(design: Any, vertices_mm: np.ndarray, mm_per_unit: float,
                             net_heights: np.ndarray | None = None,
                             heights: np.ndarray | None = None) -> NetDistance:
    """The net's distance from the design: its vertices' closest-point distances and, on a
    simulation grid, its surface's heights above and below the design's.

    Parameters
    ----------
    design : a `fabplan.design.DesignSurface` in model units.
    vertices_mm : (n, 3) float, the net's vertices (mm).
    mm_per_unit : millimetres per model unit.
    net_heights, heights : (ny, nx) float, the net's and the design's heights on one grid
        (mm, NaN where unknown), or None.
    """
    X = np.asarray(vertices_mm, dtype=np.float64) / mm_per_unit
    distance = design.distances(X) * mm_per_unit
    result = NetDistance(vertex_max_mm=float(distance.max()), vertex_mean_mm=float(distance.mean()))
    if net_heights is not None and heights is not None:
        result.part_cells = int(np.isfinite(net_heights).sum())
        gap = net_heights - heights
        known = np.isfinite(gap)
        if known.any():
            result.above_max_mm = float(max(np.max(gap[known]), 0.0))
            result.below_max_mm = float(max(-np.min(gap[known]), 0.0))
            result.cells = int(known.sum())
    return result
