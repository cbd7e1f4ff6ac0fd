"""Patches for the small gaps the trimming leaves, cut in the plane tangent to each gap.

Around a singular point of the direction field the layout's parameter plane holds
several sheets of the design, and a piece cut there may be left out (it would fold or
overlap its neighbours, `fabplan.layout.trim`): a few panels' area of the design stays
unclad. Such a gap is small, and at the scale of a few panels the surface around it is
nearly flat, so it is cut in its own tangent plane instead of the parametrization's: the
design's triangles around the gap, less the cladding over them, seen along the plane's
normal, is the patch. Its corners are the cladding's own points where it borders the
cladding, and points of the design elsewhere (on its boundary curve where the gap
reaches it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface

__all__ = ["GapPatches", "gap_patches", "outline_triangles", "unclad_components",
           "MAX_GAP_PANELS"]

#: gaps up to this many full panels of area are patched (in pieces of about a panel); a
#: larger one is where the layout failed, and is reported rather than filled
MAX_GAP_PANELS = 6.0

#: smaller gaps are the measure's noise between panels that meet (full panels of area)
MIN_GAP_PANELS = 0.01

#: a gap is cut in its tangent plane only where every design triangle around it faces
#: within this angle of the plane's normal (degrees)
MAX_TILT_DEG = 60.0


@dataclass
class GapPatches:
    """Patches closing gaps, to append to a cladding of `count` points.

    Attributes
    ----------
    points : (m, 3) float, the new points (on the design), numbered from `count` on.
    on_boundary : (m,) bool, new points on the design's boundary curve.
    polygons : list of (k,) int arrays, each patch's outline (counter-clockwise about the
        design's normal) into the cladding's points followed by `points`.
    triangles : (t, 3) int, the patches cut into triangles (same numbering); owner :
        (t,) int, the patch of each.
    """

    points: np.ndarray
    on_boundary: np.ndarray
    polygons: list
    triangles: np.ndarray
    owner: np.ndarray

    @property
    def count(self) -> int:
        return len(self.polygons)


def unclad_components(design: DesignSurface, clad: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The unclad parts of the design, as components of triangles sharing edges.

    Parameters
    ----------
    clad : (4 t,) bool, which of the design's samples are clad (four per triangle in the
        triangle order, `fabplan.layout.coverage.design_samples`).

    Returns
    -------
    triangles : (u,) int, the design triangles with an unclad sample.
    label : (u,) int, the component of each.
    open_samples : (u, 4) bool, which of their samples are unclad.
    area : (c,) float, the unclad area of each component (model units squared).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from ..design.topology import triangle_pairs

    open_ = ~np.asarray(clad, bool).reshape(-1, 4)
    unclad = np.flatnonzero(open_.any(axis=1))
    if len(unclad) == 0:
        return unclad, np.zeros(0, np.int64), np.zeros((0, 4), bool), np.zeros(0)
    f, g, _ = triangle_pairs(design.triangles, len(design.vertices))
    hit: np.ndarray = np.asarray(open_.any(axis=1))
    both = hit[f] & hit[g]
    local = np.full(len(design.triangles), -1)
    local[unclad] = np.arange(len(unclad))
    graph = coo_matrix((np.ones(int(both.sum())), (local[f[both]], local[g[both]])),
                       shape=(len(unclad), len(unclad)))
    _, label = connected_components(graph, directed=False)
    area = np.bincount(label, (design.face_areas[unclad, None] / 4 * open_[unclad]).sum(axis=1))
    return unclad, label, open_[unclad], area


def gap_patches(design: DesignSurface, points: np.ndarray, triangles: np.ndarray,
                clad: np.ndarray, h: float, *, max_panels: float = MAX_GAP_PANELS,
                rings: int = 2) -> GapPatches:
    """Patches for the gaps of up to `max_panels` full panels of area.

    Parameters
    ----------
    design : the design surface.
    points : (n, 3) float, the cladding's points (the net's vertices and the boundary
        panels' points); triangles : (c, 3) int, the cladding cut into triangles.
    clad : (4 t,) bool, the design's samples the cladding covers.
    h : the panel size.
    rings : the gap's triangles grown by this many rings of design triangles are cut.

    Returns
    -------
    GapPatches. A gap is left as it is when the design bends too much around it
    (`MAX_TILT_DEG`), or when the unclad area reaches the edge of the region cut (it goes
    on beyond).
    """
    unclad, label, _, area = unclad_components(design, clad)
    design_boundary = _boundary_edge_keys(design.triangles, len(design.vertices))
    new_points: list = []
    new_boundary: list = []
    polygons: list = []
    pieces: list = []
    grid = 1e-7 * h
    count = len(points)
    for gap in np.flatnonzero((area >= MIN_GAP_PANELS * h * h) & (area <= max_panels * h * h)):
        made: tuple | None = None
        # until the region holds the gap: a few rings, then up to two panels around it
        # (a gap may run on as a slit between two pieces of the cladding)
        panel_rings = int(np.ceil(h / design.mean_edge_length))
        for grown in sorted({rings, 2 * rings, 4 * rings, panel_rings, 2 * panel_rings}):
            made = _patch_gap(design, points, triangles, unclad[label == gap], h, grown, grid,
                              design_boundary)
            if made is not None:
                break
        if not made:
            continue
        cut, lifted, on_edge = made
        for piece, ids in cut:
            # new points are numbered -1, -2, ... within the gap (shared by its pieces)
            polygons.append(np.where(ids < 0, count - ids - 1, ids))
            pieces.append(piece)
        count += len(lifted)
        new_points.append(lifted)
        new_boundary.append(on_edge)
    if not polygons:
        return GapPatches(np.zeros((0, 3)), np.zeros(0, bool), [], np.zeros((0, 3), np.int64),
                          np.zeros(0, np.int64))
    tris, owner = _triangulated(pieces, polygons)
    # two points of a ring snapped to one point of the cladding are one corner
    polygons = [q[q != np.roll(q, 1)] for q in polygons]
    return GapPatches(np.concatenate(new_points), np.concatenate(new_boundary), polygons,
                      tris, owner)


def _patch_gap(design: DesignSurface, points: np.ndarray, triangles: np.ndarray,
               gap: np.ndarray, h: float, rings: int, grid: float,
               design_boundary: np.ndarray) -> tuple | None:
    """The patches of one gap (its design triangles `gap`, grown by `rings` rings):
    (pieces, lifted, on_edge) with pieces a list of (piece in the plane, (k,) int ids of
    its ring points: into `points`, or -1 - j for the gap's new point j), lifted (m, 3)
    the new points on the design and on_edge (m,) bool those on the design boundary; an
    empty tuple where the gap is not cut here, None where it reaches beyond the grown
    region. A patch larger than `SPLIT_ABOVE` panels is cut into pieces of about a panel
    (`_split_piece`)."""
    T, V = design.triangles, design.vertices
    region = np.zeros(len(T), bool)
    region[gap] = True
    for _ in range(rings):
        region |= np.isin(T, T[region]).any(axis=1)
    region = np.flatnonzero(region)
    normal = np.sum(design.face_normals[region] * design.face_areas[region, None], axis=0)
    normal /= np.linalg.norm(normal)
    if np.min(design.face_normals[region] @ normal) < np.cos(np.radians(MAX_TILT_DEG)):
        return ()
    e1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    axes = np.stack([e1, np.cross(normal, e1)])
    centre = V[T[region]].reshape(-1, 3).mean(axis=0)

    def flat(X: np.ndarray) -> np.ndarray:
        return np.round((X - centre) @ axes.T / grid) * grid

    design_2d = shapely.union_all(shapely.polygons(flat(V[T[region]])), grid_size=grid)
    # the cladding over the region: its triangles near it
    reach = np.max(np.linalg.norm(V[T[region]].reshape(-1, 3) - centre, axis=1)) + h
    C = points[triangles]
    near = np.linalg.norm(C.mean(axis=1) - centre, axis=1) <= reach
    clad_2d = shapely.union_all(shapely.polygons(flat(C[near])), grid_size=grid)
    rest = shapely.difference(design_2d, clad_2d, grid_size=grid)
    # seams thinner than `SEAM_PANELS` between pieces of the cladding (where a panel cut
    # in the parameter plane meets a face along a slightly different line) are no part
    # of a gap: they would join it to the region's edge
    seam = SEAM_PANELS * h
    rest = shapely.set_precision(
        shapely.buffer(shapely.buffer(rest, -seam, join_style="mitre"), seam, join_style="mitre"),
        grid)
    # where the region's edge is not the design's, the gap must not reach it
    edge = _region_edges(T, region, design_boundary, len(V))
    inner = shapely.union_all(shapely.linestrings(flat(V[edge[0]])))
    outer = shapely.union_all(shapely.linestrings(flat(V[edge[1]]))) if len(edge[1]) else None
    gap_2d = shapely.union_all(shapely.polygons(flat(V[T[gap]])), grid_size=grid)
    tree = cKDTree(flat(points[np.unique(triangles[near])]))
    ids_near = np.unique(triangles[near])
    cut: list = []
    fresh: dict = {}                # a new point's plane coordinates (on the grid) -> j
    for whole in shapely.get_parts(rest):
        if not isinstance(whole, shapely.Polygon) or \
                whole.area < 0.01 * h * h or shapely.intersection(whole, gap_2d).area < 1e-3 * h * h:
            continue
        if shapely.distance(whole.exterior, inner) <= 4 * grid:
            return None                               # the gap goes on beyond the region
        simple = _cut_through_holes(whole, grid) if whole.interiors else [whole]
        for piece in (p for part in simple for p in _split_piece(part, h, grid)):
            ring = np.asarray(piece.exterior.coords)[:-1]
            distance, at = tree.query(ring)
            ids = np.where(distance <= 8 * grid, ids_near[at], -1)
            for m in np.flatnonzero(ids < 0):
                key = tuple(np.round(ring[m] / grid).astype(np.int64).tolist())
                ids[m] = -1 - fresh.setdefault(key, len(fresh))
            cut.append((piece, ids))
    if not cut:
        return ()
    plane = np.array(list(fresh), dtype=float).reshape(-1, 2) * grid
    lifted = _lift(design, region, flat(V[T[region]]), plane) if len(plane) else np.zeros((0, 3))
    on_edge = np.zeros(len(plane), bool) if outer is None or not len(plane) else \
        shapely.distance(shapely.points(plane), outer) <= 4 * grid
    return cut, lifted, on_edge


#: unclad seams up to twice this wide (full panels) between pieces of the cladding are
#: not part of a gap
SEAM_PANELS = 0.005

#: patches larger than this many full panels of area are cut into pieces of about one
SPLIT_ABOVE = 1.5


def _split_piece(piece, h: float, grid: float) -> list:
    """`piece` (a polygon in the plane) oriented counter-clockwise, cut by lines along
    its principal axes into pieces of about a panel when it is larger than
    `SPLIT_ABOVE` panels."""
    orient = getattr(shapely, "orient_polygons", None) or shapely.geometry.polygon.orient
    if piece.area <= SPLIT_ABOVE * h * h:
        return [orient(piece)]
    ring = np.asarray(piece.exterior.coords)[:-1]
    centre = ring.mean(axis=0)
    axes = np.linalg.svd(ring - centre)[2]
    lines = []
    for axis, other in (axes, axes[::-1]):
        along = (ring - centre) @ axis
        reach = float(np.abs((ring - centre) @ other).max()) + h
        cuts = max(int(round((along.max() - along.min()) / h)), 1)
        for t in along.min() + (along.max() - along.min()) * np.arange(1, cuts) / cuts:
            a, b = centre + t * axis - reach * other, centre + t * axis + reach * other
            lines.append(shapely.linestrings([a, b]))
    if not lines:
        return [orient(piece)]
    noded = shapely.union_all([piece.exterior, *lines], grid_size=grid)
    parts = [p for p in shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
             if shapely.contains(piece, shapely.point_on_surface(p)) and p.area > 1e-6 * h * h]
    return [orient(p) for p in parts] or [orient(piece)]


def _cut_through_holes(polygon, grid: float) -> list:
    """The polygon with holes (a gap around an island of cladding) cut into polygons
    without: a line across it through a point of every hole, noded on `grid`."""
    x0, _, x1, _ = polygon.bounds
    lines = [shapely.linestrings([[x0 - 1, y], [x1 + 1, y]]) for y in
             (shapely.point_on_surface(shapely.Polygon(hole)).y for hole in polygon.interiors)]
    noded = shapely.union_all([polygon.exterior, *polygon.interiors, *lines], grid_size=grid)
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
    inside = shapely.contains(polygon, shapely.point_on_surface(faces)) & (shapely.area(faces) > 0)
    return [f for f in faces[inside] if not f.interiors]


def _boundary_edge_keys(T: np.ndarray, n: int) -> np.ndarray:
    """The design's boundary edges (used by one triangle), as sorted keys ``a n + b``,
    a < b, of `n` vertices."""
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    return keys[counts == 1]


def _region_edges(T: np.ndarray, region: np.ndarray, boundary_keys: np.ndarray, n: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The edges around the region (triangles `region` of `T`, `n` vertices): (i, 2) int
    that lie inside the design, (j, 2) int on its boundary (`boundary_keys`)."""
    e = np.sort(np.concatenate([T[region][:, [0, 1]], T[region][:, [1, 2]],
                                T[region][:, [2, 0]]]), axis=1)
    keys, first, counts = np.unique(e[:, 0] * n + e[:, 1], return_index=True, return_counts=True)
    rim = e[first[counts == 1]]
    on = np.isin(keys[counts == 1], boundary_keys)
    return rim[~on], rim[on]


def _lift(design: DesignSurface, region: np.ndarray, flat_triangles: np.ndarray,
          ring: np.ndarray) -> np.ndarray:
    """(k, 3) the design's points under the plane points `ring` (k, 2): barycentric in
    the region's triangle that holds each (through the exact surface's parameters for a
    built-in design)."""
    A, B, Cc = flat_triangles[:, 0], flat_triangles[:, 1], flat_triangles[:, 2]
    d1, d2 = B - A, Cc - A
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    r = ring[:, None, :] - A[None]
    b1 = (r[..., 0] * d2[:, 1] - r[..., 1] * d2[:, 0]) / det
    b2 = (d1[:, 0] * r[..., 1] - d1[:, 1] * r[..., 0]) / det
    bary = np.stack([1 - b1 - b2, b1, b2], axis=-1)            # (k, r, 3)
    best = np.argmax(bary.min(axis=-1), axis=1)                 # the triangle most inside
    w = np.clip(bary[np.arange(len(ring)), best], 0.0, 1.0)
    w /= w.sum(axis=1, keepdims=True)
    tri = region[best]
    if design.parametric is not None and design.uv is not None:
        uv = np.einsum("kc,kcj->kj", w, design.triangle_uv(tri))
        return design.parametric.points(uv[:, 0], uv[:, 1])
    return np.einsum("kc,kcj->kj", w, design.vertices[design.triangles[tri]])


def _triangulated(pieces: list, polygons: list) -> tuple[np.ndarray, np.ndarray]:
    """The pieces cut into triangles in their plane (`outline_triangles`) and the piece
    of each."""
    tris = [outline_triangles(piece, ids) for piece, ids in zip(pieces, polygons, strict=True)]
    owner = np.repeat(np.arange(len(tris)), [len(t) for t in tris])
    return np.concatenate(tris).astype(np.int64), owner.astype(np.int64)


def outline_triangles(outline, ids: np.ndarray) -> np.ndarray:
    """(t, 3) int, the simple polygon `outline` (in a plane) cut into triangles by
    constrained Delaunay (a concave outline stays whole), corners numbered as its ring's
    points are by `ids` (k,) (the ring without its closing point)."""
    ring = np.asarray(outline.exterior.coords)[:-1]
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(outline))
    corners = shapely.get_coordinates(shapely.get_exterior_ring(parts)).reshape(-1, 4, 2)[:, :3]
    _, at = cKDTree(ring).query(corners.reshape(-1, 2))
    t = np.asarray(ids)[at].reshape(-1, 3)
    return t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
