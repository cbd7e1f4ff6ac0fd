"""The unclad strip cut in the parameter plane (steps 1 and 2 of `fabplan.layout.trim`):
the net's vertices in the plane (`net_in_plane`), the design less the net's faces (by sheet
where a seam makes the plane hold several, `_unclad_by_sheet`), and that region cut into
pieces by the net's lines extended straight until they leave it (`pieces_in_plane`)."""

from __future__ import annotations

import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..design.mesh_surface import DesignSurface
from ..net.mesh import QuadMesh
from .extraction import transition_maps
from .parameter_chart import ParameterChart

__all__ = ["net_in_plane", "pieces_in_plane"]


def net_in_plane(mesh: QuadMesh, chart: ParameterChart, design: DesignSurface, h: float,
                touch: float, *, onto_boundary: bool
                ) -> tuple[np.ndarray, float, float, np.ndarray]:
    """The net's vertices in the parameter plane, snap-rounded, and which stand on the
    design boundary (`fabplan.layout.trim.trim_to_design`); with `onto_boundary` (a net
    that left the design) those are moved onto it.

    Returns
    -------
    p_net : (n, 2) float, the vertices' parameters, rounded to `grid`.
    cell : area of a full panel in the plane.
    grid : the snap-rounding grid of every overlay.
    touching : (n,) bool, vertices within `touch` (panel sizes) of the boundary.
    """
    p_net = chart.parameters_of(mesh.vertices)
    # a full panel in the plane: about one unit square of the lattice
    cell = float(np.median(np.abs(chart.param_area))) * h * h / float(np.median(design.face_areas))
    cell = cell if np.isfinite(cell) and cell > 0 else 1.0
    # every overlay is snap-rounded to this grid (a ten-millionth of a panel), so that a
    # vertex on a boundary segment to rounding is noded there
    grid = 1e-7 * cell ** 0.5
    p_net = np.round(p_net / grid) * grid
    boundary = chart.boundary_lines
    # a vertex on the boundary (to `touch` of a panel: gliding, or added on it)
    # ends its lines there; a line continued from it would run along the boundary. It is
    # joined to the boundary by the shortest way instead, which parts the slivers beside it
    points = shapely.points(p_net)
    touching = shapely.distance(points, boundary) <= touch * cell ** 0.5
    if onto_boundary and touching.any():
        # a net that left the design: its vertices that near the boundary stand on it in
        # the plane, so that no strip a few millimetres wide is cut beside them
        foot = shapely.get_coordinates(
            shapely.shortest_line(points[touching], boundary)).reshape(-1, 2, 2)[:, 1]
        p_net[touching] = np.round(foot / grid) * grid
    return p_net, cell, grid, touching


def pieces_in_plane(mesh: QuadMesh, cuts: list, chart: ParameterChart, p_net: np.ndarray,
                    touching: np.ndarray, by_sheet: bool, cell: float, grid: float,
                    min_panel: float, h: float) -> tuple:
    """The unclad strip of the plane cut into pieces by the net's lines (steps 1 and 2 of
    `fabplan.layout.trim`).

    Returns
    -------
    pieces, rays : (k,) object arrays of shapely geometry, the pieces and the rays that
        cut them.
    patch : (k,) bool, pieces of holes (not on the design boundary).
    sheets : None, or with `by_sheet` ``(rest, rest_triangle, rest_region, piece_region)``
        (`_unclad_by_sheet`, and the region (k,) each piece was cut from).
    """
    boundary = chart.boundary_lines
    faces = _face_polygons(mesh, p_net, transition_maps([(sign, (jp, js)) for sign, jp, js in cuts]))
    if by_sheet:
        # across a seam the plane holds several sheets of the design: each triangle loses
        # only the net faces on its own sheet
        rest, rest_triangle, rest_region, regions = _unclad_by_sheet(
            chart, faces, mesh, h, grid, 1e-6 * cell)
    else:
        net = shapely.union_all(_polygonal(shapely.make_valid(faces)), grid_size=grid)
        domain = shapely.union_all(_polygonal([shapely.set_precision(
            _through_gliding_vertices(chart.domain, p_net[touching & mesh.is_boundary_vertex],
                                      grid), grid)]), grid_size=grid)
        regions = [shapely.union_all(_polygonal([shapely.difference(domain, net, grid_size=grid)]),
                                     grid_size=grid)]
    # regions of different sheets may overlap in the plane: each is cut on its own
    cut = [_cut_region(unclad, mesh, p_net, boundary, touching, cell, grid, min_panel)
           for unclad in regions]
    pieces = np.concatenate([c[0] for c in cut] + [np.zeros(0, dtype=object)])
    rays = np.concatenate([c[1] for c in cut] + [np.zeros(0, dtype=object)])
    patch = np.concatenate([c[2] for c in cut] + [np.zeros(0, bool)])
    sheets = None
    if by_sheet:
        piece_region = np.repeat(np.arange(len(cut)), [len(c[0]) for c in cut])
        sheets = (rest, rest_triangle, rest_region, piece_region)
    return pieces, rays, patch, sheets


def _through_gliding_vertices(domain, points: np.ndarray, grid: float):
    """The `domain` with its outline moved onto the net's vertices `points` (k, 2) that lie
    within two `grid` steps of it (vertices gliding on the design boundary, a fraction of
    the grid off it to rounding). Whether the overlays' snap-rounding would node such a
    vertex on the outline depends on where the grid falls: the strip beside it would be
    parted there in metres and run on through a neck in millimetres. On the outline, it is
    parted at every scale; farther vertices are joined to it by `_connectors`."""
    if len(points) == 0:
        return domain
    return shapely.make_valid(shapely.snap(domain, shapely.multipoints(points), 2 * grid))


def _polygonal(geometries) -> np.ndarray:
    """The polygons among the parts of `geometries` (a degenerate face made valid may
    leave lines and points, which no overlay with areas accepts)."""
    parts = shapely.get_parts(np.asarray(geometries, dtype=object))
    return parts[shapely.get_type_id(parts) == 3]


def _areas_only(geometries: np.ndarray) -> np.ndarray:
    """The geometries with the lines and points that snap-rounding leaves beside their
    areas dropped (a collection of both is no input to a further overlay).

    Examples
    --------
    >>> mixed = shapely.GeometryCollection([shapely.box(0, 0, 1, 1),
    ...                                     shapely.LineString([(2, 0), (3, 0)])])
    >>> [g.geom_type for g in _areas_only(np.array([mixed, shapely.box(0, 0, 1, 1)]))]
    ['Polygon', 'Polygon']
    """
    out = np.asarray(geometries, dtype=object).copy()
    for k in np.flatnonzero(shapely.get_type_id(out) == 7):       # collections only
        out[k] = shapely.union_all(_polygonal([out[k]]))
    return out


def _face_polygons(mesh: QuadMesh, p: np.ndarray, maps: list) -> np.ndarray:
    """The net's faces in the parameter plane. Across a cut a face's corners are taken to
    the side of its first corner, and every face also enters in its images under the
    cuts' maps, so that it covers the plane on both sides of the cut."""
    sizes, idx, ptr = mesh.face_sizes, mesh.face_indices, mesh.face_indptr
    face = mesh.corner_faces
    corner_p = p[idx]
    if len(maps) > 1:
        anchor = p[idx[ptr[face]]]
        images = np.stack([sign * corner_p + shift for sign, shift in maps])   # (m, c, 2)
        pick = np.argmin(np.linalg.norm(images - anchor[None], axis=2), axis=0)
        corner_p = images[pick, np.arange(len(idx))]
    # a closed ring per face: its corners and the first again
    closing = np.insert(corner_p, ptr[1:], corner_p[ptr[:-1]], axis=0)
    ring_of = np.repeat(np.arange(len(sizes)), sizes + 1)
    out = [shapely.polygons(shapely.linearrings(closing, indices=ring_of))]
    out += [shapely.polygons(shapely.linearrings(sign * closing + shift, indices=ring_of))
            for sign, shift in maps[1:]]
    return np.concatenate(out)


def _unclad_by_sheet(chart: ParameterChart, faces: np.ndarray, mesh: QuadMesh, h: float,
                     grid: float, min_area: float) -> tuple:
    """The unclad region ``D - N`` of a chart whose parameter triangles overlap (a seam):
    every design triangle minus the net faces on its own sheet, united.

    A face lies on the sheet of the triangles it overlaps in the plane that lie under it
    on the surface: their centroid within the face's radius (its corners' largest
    distance from its centroid) and half a panel `h` of its centroid. On another sheet
    the triangle lies a few panels away, but where the sheets meet (at a singular point)
    the face lies on all of them.

    Parameters
    ----------
    chart : the layout's `ParameterChart`.
    faces : (f * k,) Polygons, the net's f faces in the plane and their images under the
        cuts' maps (`_face_polygons`): row i is face ``i % f``.
    mesh : the net.
    h : panel size (model units).
    grid : the overlays' snap-rounding grid.
    min_area : regions of no more area (in the plane) are left out.

    Returns
    -------
    rest : (u,) Polygons, what is left of the design triangles.
    rest_triangle : (u,) int, the design triangle of each.
    rest_region : (u,) int, the region of each (-1: one left out).
    regions : list of polygonal geometries, the unclad region in parts that hang
        together on the surface (each on one sheet; two may overlap in the plane).
    """
    parts, part, tri = _faces_on_own_sheet(chart, faces, mesh, h)
    # most triangles lie inside one face of their sheet: nothing of them is left
    covered = np.zeros(len(chart.P), bool)
    covered[tri[shapely.covers(parts[part], chart.triangles[tri])]] = True
    part, tri = part[~covered[tri]], tri[~covered[tri]]
    # each triangle loses its faces one rank at a time: a loop over the few faces a
    # triangle meets, not over the triangles
    order = np.lexsort((part, tri))
    part, tri = part[order], tri[order]
    first = np.r_[True, tri[1:] != tri[:-1]]
    rank = np.arange(len(tri)) - np.maximum.accumulate(np.where(first, np.arange(len(tri)), 0))
    usable = np.flatnonzero(chart.usable & ~covered)
    rest = np.full(len(chart.P), None, dtype=object)
    rest[usable] = chart.triangles[usable]
    for k in range(int(rank.max(initial=-1)) + 1):
        at = rank == k
        rest[tri[at]] = _areas_only(shapely.difference(rest[tri[at]], parts[part[at]],
                                                       grid_size=grid))
    left = usable[~shapely.is_empty(rest[usable])]
    rest, at = shapely.get_parts(rest[left], return_index=True)
    polygon = shapely.get_type_id(rest) == 3
    rest, left = rest[polygon], left[at[polygon]]
    region, regions, number = _sheet_regions(chart, rest, left, grid, min_area)
    return rest, left, number[region], regions


def _faces_on_own_sheet(chart: ParameterChart, faces: np.ndarray, mesh: QuadMesh, h: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The net's faces in the plane (`faces`, as `_unclad_by_sheet` takes them) as
    polygons, `parts` (g,), and the pairs of a part (c,) int and a design triangle (c,)
    int it overlaps in the plane that lies under its face on the surface (its own sheet,
    `_unclad_by_sheet`)."""
    f = len(mesh.face_sizes)
    valid = shapely.make_valid(faces)
    parts, row = shapely.get_parts(valid, return_index=True)
    polygon = shapely.get_type_id(parts) == 3
    parts, face = parts[polygon], row[polygon] % f
    sizes, idx, ptr = mesh.face_sizes, mesh.face_indices, mesh.face_indptr
    centre3 = np.stack([np.add.reduceat(mesh.vertices[idx, k], ptr[:-1]) for k in range(3)],
                       axis=1) / sizes[:, None]
    corner_face = mesh.corner_faces
    radius = np.zeros(f)
    np.maximum.at(radius, corner_face, np.linalg.norm(mesh.vertices[idx] - centre3[corner_face], axis=1))
    part, tri = chart.tree.query(parts, predicate="intersects")
    keep = chart.usable[tri]
    part, tri = part[keep], tri[keep]
    design = chart.design
    gap = np.linalg.norm(design.vertices[design.triangles[tri]].mean(axis=1) - centre3[face[part]],
                         axis=1)
    own = gap <= radius[face[part]] + 0.5 * h
    return parts, part[own], tri[own]


def _sheet_regions(chart: ParameterChart, rest: np.ndarray, left: np.ndarray, grid: float,
                   min_area: float) -> tuple[np.ndarray, list, np.ndarray]:
    """The unclad parts `rest` (u,) of the design triangles `left` (u,) int grouped into
    regions that hang together on the surface: the region (u,) int of each part, the
    regions larger than `min_area` united (list of polygonal geometries), and (r,) int
    the number of each region among those (-1: left out)."""
    # parts hang together where their triangles share a corner on the design and they
    # meet in the plane; parts of other sheets over them in the plane share no corner
    a, b = shapely.STRtree(rest).query(rest, predicate="intersects")
    T = chart.design.triangles
    linked = (T[left[a]][:, :, None] == T[left[b]][:, None, :]).any(axis=(1, 2))
    graph = coo_matrix((np.ones(int(linked.sum())), (a[linked], b[linked])),
                       shape=(len(rest), len(rest)))
    count, region = connected_components(graph, directed=False)
    # regions of rounding size are no panels (as the specks among the pieces)
    large = np.flatnonzero(np.bincount(region, shapely.area(rest), minlength=count) > min_area)
    regions = [shapely.union_all(_polygonal([shapely.union_all(rest[region == k], grid_size=grid)]),
                                 grid_size=grid) for k in large]
    number = np.full(count, -1)
    number[large] = np.arange(len(large))
    return region, regions, number


def _cut_region(unclad, mesh: QuadMesh, p_net: np.ndarray, boundary, touching: np.ndarray,
                cell: float, grid: float, min_panel: float) -> tuple:
    """One unclad region cut into pieces by the net's lines extended into it.

    Returns
    -------
    pieces : (p,) Polygons, counter-clockwise.
    rays : (r,) LineStrings, the lines that cut it (`_clipped_rays`, `_connectors`).
    patch : (p,) bool, pieces of parts of the region that do not reach the design
        boundary (holes inside the net).
    """
    tol = 4 * grid
    rays = np.concatenate([
        _clipped_rays(mesh, p_net, unclad, ~touching, grid),
        _connectors(p_net[touching & mesh.is_boundary_vertex], boundary, unclad, grid)])
    pieces = _split_large(_split(unclad, rays, grid), 1.5 * cell, grid)
    # specks of rounding size are no panels (their area stays in the uncovered share)
    pieces = shapely.orient_polygons(
        _merge_small(pieces[shapely.area(pieces) > 1e-6 * cell], min_panel * cell))
    # unclad regions that do not reach the design boundary are holes inside the net
    regions = shapely.get_parts(unclad)
    inner = regions[shapely.distance(regions, boundary) > tol]
    patch = np.zeros(len(pieces), bool)
    if len(pieces) and len(inner):
        hit, _ = shapely.STRtree(inner).query(shapely.point_on_surface(pieces), predicate="within")
        patch[hit] = True
    return pieces, rays, patch


def _clipped_rays(mesh: QuadMesh, p: np.ndarray, unclad, free: np.ndarray, grid: float
                  ) -> np.ndarray:
    """The net's lines that end on its boundary, continued straight in the parameter
    plane from their last vertex through the unclad strip, up to where they leave it.

    A boundary vertex with one face continues both its edges, one with two faces its
    interior edge; with three or more faces every line through it goes on in the net.
    Only vertices marked `free` (n,) bool (off the design boundary) start rays. The
    overlays are snap-rounded to `grid`.

    Returns
    -------
    (r,) array of LineStrings.
    """
    faces_at = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    boundary = mesh.is_boundary_vertex & free
    starts, throughs = [], []
    idx, nxt, prv = mesh.face_indices, mesh.corner_next_vertices, mesh.corner_previous_vertices
    lone = boundary[idx] & (faces_at[idx] == 1)
    starts += [idx[lone], idx[lone]]
    throughs += [nxt[lone], prv[lone]]
    e = mesh.interior_edges
    for a, b in ((e[:, 0], e[:, 1]), (e[:, 1], e[:, 0])):
        ok = boundary[a] & (faces_at[a] == 2)
        starts.append(a[ok])
        throughs.append(b[ok])
    start, through = np.concatenate(starts), np.concatenate(throughs)
    if start.size == 0 or unclad.is_empty:
        return np.zeros(0, dtype=object)
    direction = p[start] - p[through]
    length = np.linalg.norm(direction, axis=1)
    ok = length > 0
    start, direction, length = start[ok], direction[ok], length[ok]
    # long enough to cross any strip the net leaves (a few panels)
    reach = 6.0 * float(np.median(length))
    end = p[start] + direction / length[:, None] * reach
    lines = shapely.linestrings(np.stack([p[start], end], axis=1))
    inside = shapely.intersection(lines, unclad, grid_size=grid)
    rays = [_first_piece(line, o, grid) for line, o in zip(inside, p[start], strict=True)]
    return np.array([r for r in rays if r is not None], dtype=object)


def _connectors(points: np.ndarray, boundary, unclad, grid: float) -> np.ndarray:
    """(r,) LineStrings, the shortest segments from `points` (k, 2) near the boundary to
    it, where they run through the unclad region (a hair longer, to be noded)."""
    if len(points) == 0 or unclad.is_empty:
        return np.zeros(0, dtype=object)
    lines = shapely.shortest_line(shapely.points(points), boundary)
    ends = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    step = ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(step, axis=1)
    ok = length > 2 * grid
    ends, step, length = ends[ok], step[ok], length[ok]
    ends[:, 1] += 10 * grid * step / length[:, None]
    segments = shapely.linestrings(ends)
    return segments[shapely.within(shapely.line_interpolate_point(segments, 0.5, normalized=True),
                                   unclad)]


def _first_piece(line, origin: np.ndarray, grid: float):
    """The part of a clipped ray that starts at `origin` (2,), as a straight segment a
    few grid steps longer (so that it crosses the boundary it ends on and is noded
    there), or None."""
    parts = shapely.get_parts(line)
    parts = parts[shapely.get_type_id(parts) == 1]
    if len(parts) == 0:
        return None
    d = shapely.distance(parts, shapely.points(origin))
    best = int(np.argmin(d))
    if d[best] > 2 * grid or shapely.length(parts[best]) < 10 * grid:
        return None
    end = np.asarray(parts[best].coords)[-1]
    step = end - origin
    return shapely.linestrings([origin, end + 10 * grid * step / np.linalg.norm(step)])


def _split(unclad, rays: np.ndarray, grid: float) -> np.ndarray:
    """The pieces the rays cut the unclad region into (polygons; noded on `grid`)."""
    if unclad.is_empty:
        return np.zeros(0, dtype=object)
    lines = [shapely.boundary(unclad)] + list(rays)
    noded = shapely.union_all(np.array(lines, dtype=object), grid_size=grid)
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
    if len(faces) == 0:
        return faces
    inside = shapely.contains(unclad, shapely.point_on_surface(faces))
    pieces = faces[inside & (shapely.area(faces) > 0)]
    return pieces


def _split_large(pieces: np.ndarray, max_area: float, grid: float) -> np.ndarray:
    """Pieces above `max_area` (where the net stops more than a panel short of the
    boundary) cut further by the lattice lines ``phi = k``, ``psi = k`` that cross them:
    the lines the net would have there."""
    big = shapely.area(pieces) > max_area
    if not big.any():
        return pieces
    out = [pieces[~big]]
    for piece in pieces[big]:
        x0, y0, x1, y1 = piece.bounds
        xs = np.arange(np.ceil(x0), np.floor(x1) + 1)
        ys = np.arange(np.ceil(y0), np.floor(y1) + 1)
        lines = [shapely.linestrings([[x, y0 - 1], [x, y1 + 1]]) for x in xs] + \
            [shapely.linestrings([[x0 - 1, y], [x1 + 1, y]]) for y in ys]
        out.append(_split(piece, np.array(lines, dtype=object), grid) if lines else np.array([piece]))
    return np.concatenate(out)


def _merge_small(pieces: np.ndarray, min_area: float) -> np.ndarray:
    """Pieces below `min_area` joined to the neighbour they share the longest side with
    (the smallest first, one at a time); one without a neighbour stays."""
    pieces = np.asarray(pieces, dtype=object)
    stuck: set[int] = set()
    while len(pieces) > 1:
        area = shapely.area(pieces)
        small = [i for i in np.argsort(area) if area[i] < min_area and i not in stuck]
        if not small:
            break
        i = int(small[0])
        shared = shapely.length(shapely.intersection(shapely.boundary(pieces[i]),
                                                     shapely.boundary(pieces)))
        shared[i] = 0.0
        j = int(np.argmax(shared))
        union = shapely.union(pieces[j], pieces[i]) if shared[j] > 0 else None
        if union is None or union.geom_type != "Polygon":
            stuck.add(i)
            continue
        pieces[j] = union
        pieces = np.delete(pieces, i)
        stuck = {k - (k > i) for k in stuck}
    return pieces
