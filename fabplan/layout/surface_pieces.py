"""The pieces cut in the parameter plane mapped to the surface (step 3 of
`fabplan.layout.trim`): corners at net vertices are those vertices, the others go through
the design's triangles (`fabplan.layout.parameter_chart`), points on the design boundary
onto its curve and points on a side of the net onto that side's straight edge; pieces that
map across a seam or clad the design twice are left out (`pieces_on_surface`)."""

from __future__ import annotations

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..net.mesh import QuadMesh
from .coverage import share_under_net
from .parameter_chart import ParameterChart
from .soundness import flipped_panels

__all__ = ["pieces_on_surface"]


def pieces_on_surface(pieces: np.ndarray, rays: np.ndarray, patch: np.ndarray,
                      sheets: tuple | None, mesh: QuadMesh, p_net: np.ndarray,
                      chart: ParameterChart, touching: np.ndarray, tol: float, h: float
                      ) -> tuple:
    """The pieces of the plane mapped to the surface (`_to_surface`, step 3 of
    `fabplan.layout.trim`), less those that map across a seam or clad the design twice.

    Returns
    -------
    vertices, polygons, on_boundary, corner, on_side : as `_to_surface` gives them.
    triangles, owner : the pieces' triangles (m, 3) int and the piece (m,) of each.
    patch : (k',) bool, `patch` of the pieces kept.
    """
    design, boundary = chart.design, chart.boundary_lines
    vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
        pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
    # a piece over a seam of the parametrization, where the plane holds several sheets
    # of the design, may map to points of different sheets: its sides then stretch far
    # beyond their length in the plane (about a panel per unit). Such pieces are left
    # out and their area counted as unclad
    sane = _sane_on_surface(pieces, vertices, polygons, h)
    if not sane.all():
        pieces = pieces[sane]
        if sheets is not None:
            sheets = (*sheets[:3], sheets[3][sane])
        vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
            pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
    patch = patch[sane]
    triangles, owner = _triangles_on_surface(pieces, ring_ids)
    # near a singular point the plane's sheets overlap, and a "hole" there may lie under
    # net faces on the surface: such a patch would clad the design twice. Cut by sheet,
    # any piece may: along a seam a face whose corners lie on both sides is folded in the
    # plane and leaves part of the triangles under it unclad there
    by_sheet = sheets is not None
    double = (patch | by_sheet) & \
        (share_under_net(vertices, triangles, owner, len(pieces), mesh, h) > 0.5)
    if by_sheet:
        # a piece of a hole at a singular point, where the sheets meet, may map across
        # the fold there: it faces against the design and overlaps its neighbours
        double[flipped_panels(vertices, polygons, design, 1e-3 * h * h)] = True
    if double.any():
        pieces, patch = pieces[~double], patch[~double]
        if sheets is not None:
            sheets = (*sheets[:3], sheets[3][~double])
        vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
            pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
        triangles, owner = _triangles_on_surface(pieces, ring_ids)
    return vertices, polygons, on_boundary, corner, on_side, triangles, owner, patch


def _to_surface(pieces: np.ndarray, mesh: QuadMesh, p_net: np.ndarray, chart: ParameterChart,
                boundary, rays: np.ndarray, tol: float, touching: np.ndarray,
                sheets: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
                ) -> tuple:
    """The pieces as polygons on the surface: corners at net vertices are those vertices,
    the others are mapped through the chart (shared points once; points within `tol` of
    the design boundary are first put on it, so that they land on its curve). Net
    vertices marked `touching` (n,) bool lie on the boundary as far as corners go.

    Returns
    -------
    vertices (m, 3), polygons (list of int arrays), on_boundary (m,) bool, corner (m,) bool,
    the id of every point of every piece's ring (list of int arrays, repeats kept), and
    on_side (m,) bool, the points put on a boundary side of the net
    (`_net_side_points`).
    """
    n = mesh.vertex_count
    if len(pieces) == 0:
        return (mesh.vertices.copy(), [], np.zeros(n, bool), np.ones(n, bool), [],
                np.zeros(n, bool))
    rings = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    points = np.concatenate(rings)
    # a point is a net vertex when the parameters agree to the grid
    d, nearest = cKDTree(p_net).query(points)
    is_net = d <= tol
    other = np.flatnonzero(~is_net)
    ids = np.where(is_net, nearest, -1)
    new_p = np.zeros((0, 2))
    first = np.zeros(0, np.int64)
    if other.size:
        # the overlays are snap-rounded: equal points are equal coordinates
        _, first, inverse = np.unique(points[other], axis=0, return_index=True, return_inverse=True)
        ids[other] = n + inverse.ravel()
        new_p = points[other[first]]
    new_points = shapely.points(new_p)
    on_boundary = np.zeros(n + len(new_p), bool)
    on_boundary[n:] = shapely.distance(new_points, boundary) <= tol
    exact = new_p.copy()
    if on_boundary[n:].any():
        at = on_boundary[n:]
        exact[at] = shapely.get_coordinates(
            shapely.line_interpolate_point(boundary, shapely.line_locate_point(boundary, new_points[at])))
    # where the plane holds several sheets of the design, a point belongs to the sheet of
    # the net vertices of its panel
    sizes = np.array([len(r) for r in rings])
    piece = np.repeat(np.arange(len(rings)), sizes)
    anchor = _sheet_anchors(pieces, piece, is_net, mesh.vertices[nearest], sheets, chart)
    near = anchor[piece[other[first]]] if other.size else np.zeros((0, 3))
    # over a seam a point on one sheet's boundary may be inside another sheet's triangle
    # only, to rounding: the triangles within `tol` are candidates too
    reach = tol if sheets is not None else 0.0
    vertices = np.vstack([mesh.vertices, chart.to_surface(exact, near, reach=reach)])
    # a point on a side of the net in the plane is on that side on the surface too: the
    # straight edge between its two vertices, not the chart's curve under it (which
    # leaves a sliver between the panel and the face, over or beside it)
    # (points on the design boundary stay on its curve)
    at, chord = _net_side_points(new_p, p_net, mesh, tol)
    inside = ~on_boundary[n + at]
    at, chord = at[inside], chord[inside]
    vertices[n + at] = chord
    on_side = np.zeros(len(vertices), bool)
    on_side[n + at] = True
    on_ray = np.zeros(len(vertices), bool)
    if len(rays) and len(new_p):
        on_ray[n:] = shapely.distance(new_points, shapely.union_all(rays)) <= tol
    ring_ids = np.split(ids, np.cumsum(sizes)[:-1])
    polygons = ring_ids
    # drop repeated consecutive ids (two points of one ring mapped to one net vertex)
    polygons = [q[np.r_[True, q[1:] != q[:-1]] & ~((np.arange(len(q)) == len(q) - 1) & (q == q[0]))]
                for q in polygons]
    corner = _corner_points(polygons, on_boundary, touching, on_ray)
    return vertices, polygons, on_boundary, corner, ring_ids, on_side


def _sheet_anchors(pieces: np.ndarray, piece: np.ndarray, is_net: np.ndarray,
                   nearest: np.ndarray,
                   sheets: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
                   chart: ParameterChart) -> np.ndarray:
    """(p, 3) float, a point on the sheet of the design each of the `pieces` (p,) maps
    to, where the plane holds several: the centroid of the net vertices in its ring (its
    ring's points `piece` (r,) int, `is_net` (r,) bool, and `nearest` (r, 3) the net
    vertex nearest each), NaN where it has none; with `sheets`, that of the design
    triangles it was cut from (`_piece_anchors`)."""
    weight = is_net.astype(np.float64)
    count = np.bincount(piece, weight, minlength=len(pieces))
    anchor = np.stack([np.bincount(piece, weight * nearest[:, k], minlength=len(pieces))
                       for k in range(3)], axis=1) / np.maximum(count, 1)[:, None]
    # a panel without a net vertex has no sheet to prefer (NaN); the others keep theirs
    anchor[count == 0] = np.nan
    if sheets is not None:
        # where the plane holds several sheets, the piece is on that of the design
        # triangles it was cut from (the net vertices in its ring may be another's)
        anchor = _piece_anchors(pieces, *sheets, chart, anchor)
    return anchor


def _corner_points(polygons: list, on_boundary: np.ndarray, touching: np.ndarray,
                   on_ray: np.ndarray) -> np.ndarray:
    """(m,) bool, the panels' corners: the net's vertices, points off the design
    boundary, ends of the rays (`on_ray` (m,) bool) and where an outline meets or leaves
    the boundary (`on_boundary` (m,) bool; the net's vertices by `touching` (n,) bool)."""
    n = len(touching)
    # a corner is off the boundary, ends a line, or is where the outline meets or leaves
    # the boundary; the points between follow the boundary curve
    ring = np.concatenate(polygons)
    before = np.concatenate([np.roll(q, 1) for q in polygons])
    after = np.concatenate([np.roll(q, -1) for q in polygons])
    ob = on_boundary.copy()
    ob[:n] = touching
    corner = np.zeros(len(on_ray), bool)
    corner[ring[(ring < n) | ~ob[ring] | ~ob[before] | ~ob[after] | on_ray[ring]]] = True
    return corner


def _net_side_points(points: np.ndarray, p_net: np.ndarray, mesh: QuadMesh, tol: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The points (m, 2) of the plane within `tol` of a boundary edge of the net (its
    vertices at `p_net` (n, 2)), not at its ends: (k,) int which, and (k, 3) float, where
    they lie on the edge's straight side in space (at the same share of its length)."""
    edges = mesh.boundary_edges
    if len(points) == 0 or len(edges) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    A, B = p_net[edges[:, 0]], p_net[edges[:, 1]]
    tree = shapely.STRtree(shapely.linestrings(np.stack([A, B], axis=1)))
    point, edge = tree.query(shapely.points(points), predicate="dwithin", distance=tol)
    d = B[edge] - A[edge]
    share = np.sum((points[point] - A[edge]) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-300)
    length = np.sqrt(np.sum(d * d, axis=1))
    inner = (share * length > tol) & ((1 - share) * length > tol)
    point, edge, share = point[inner], edge[inner], share[inner]
    point, first = np.unique(point, return_index=True)
    edge, share = edge[first], share[first]
    X = mesh.vertices
    return point, (1 - share)[:, None] * X[edges[edge, 0]] + share[:, None] * X[edges[edge, 1]]


def _piece_anchors(pieces: np.ndarray, rest: np.ndarray, rest_triangle: np.ndarray,
                   rest_region: np.ndarray, piece_region: np.ndarray, chart: ParameterChart,
                   default: np.ndarray) -> np.ndarray:
    """(p, 3) float, a point of the surface on each piece's sheet: the centroid on the
    surface of the design triangle with the largest unclad part (`rest` (u,) Polygons of
    the triangles `rest_triangle` (u,) int in regions `rest_region` (u,) int,
    `_unclad_by_sheet`) in the piece and its region (`piece_region` (p,) int); the row
    of `default` (p, 3) for a piece that holds none."""
    anchor = default.copy()
    if len(rest) == 0 or len(pieces) == 0:
        return anchor
    piece, part = shapely.STRtree(shapely.point_on_surface(rest)).query(pieces, predicate="covers")
    same = rest_region[part] == piece_region[piece]
    piece, part = piece[same], part[same]
    if len(piece) == 0:
        return anchor
    share = shapely.area(rest[part])
    best = np.lexsort((-share, piece))
    best = best[np.r_[True, piece[best][1:] != piece[best][:-1]]]
    design = chart.design
    anchor[piece[best]] = design.vertices[design.triangles[rest_triangle[part[best]]]].mean(axis=1)
    return anchor


def _triangles_on_surface(pieces: np.ndarray, ring_ids: list) -> tuple[np.ndarray, np.ndarray]:
    """The pieces triangulated in the plane (constrained Delaunay: concave outlines stay
    whole) with corners numbered as their ring points (`ring_ids`); (t, 3) int and the
    piece of each (t,)."""
    if len(pieces) == 0:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    rings = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(pieces), return_index=True)
    corners = shapely.get_coordinates(shapely.get_exterior_ring(parts[0])).reshape(-1, 4, 2)[:, :3]
    owner = parts[1]
    # a corner is a point of its piece's ring: numbered as that point is
    points = np.concatenate(rings)
    piece_of = np.repeat(np.arange(len(rings)), [len(r) for r in rings])
    ids = np.concatenate(ring_ids)
    tree = cKDTree(np.c_[points, piece_of * 1e6])
    _, at = tree.query(np.c_[corners.reshape(-1, 2), np.repeat(owner, 3) * 1e6])
    triangles = ids[at].reshape(-1, 3)
    keep = (triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2]) & \
        (triangles[:, 0] != triangles[:, 2])
    return triangles[keep], owner[keep]


def _sane_on_surface(pieces: np.ndarray, vertices: np.ndarray, polygons: list, h: float
                     ) -> np.ndarray:
    """(p,) bool, pieces whose sides on the surface are at most three times their length
    in the plane times the panel size `h` (plus a tenth of a panel)."""
    if not polygons:
        return np.zeros(0, bool)
    plane = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    ok = np.ones(len(polygons), bool)
    for k, (q, r) in enumerate(zip(polygons, plane, strict=True)):
        if len(q) != len(r):      # a ring with points merged into one net vertex
            r = r[:len(q)] if len(r) > len(q) else r
        side3 = np.linalg.norm(vertices[q] - vertices[np.roll(q, -1)], axis=1).sum()
        side2 = np.linalg.norm(r - np.roll(r, -1, axis=0), axis=1).sum()
        ok[k] = side3 <= 3 * h * side2 + 0.1 * h
    return ok
