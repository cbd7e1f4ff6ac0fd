"""Quads on the integer points of a parametrization, cleaned and with small holes closed.

The integer points are located triangle by triangle (barycentric test, vectorized over
candidate points) and become vertices; unit squares whose corners and centre exist
become quads, oriented with the surface. Quads that fold or stretch (near singularities
and seams) are dropped, the largest piece is kept, pinched vertices are separated, and
small interior holes are closed by a fan of quads around a new, irregular vertex. A quad
whose corners lie on the design may still span a corner of its boundary (a door's) or
line up three corners along it: such quads are no panels (`sound_quads`), and the
trimming cuts their place as boundary panels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..net.index_rows import unique_rows
from ..net.mesh import QuadMesh
from .off_design import MIN_OFF_PANELS, degenerate_faces, faces_off_design

if TYPE_CHECKING:
    from .settings import LayoutSettings

__all__ = ["extract_quads", "fill_boundary_cells", "sound_quads", "transition_maps"]


@dataclass
class _Points:
    key: np.ndarray        # (p, 2) int
    position: np.ndarray   # (p, 3) float
    triangle: np.ndarray   # (p,) int


def _lattice_points(P2: np.ndarray, X3: np.ndarray, shift: float) -> _Points:
    """Points ``(i + shift, j + shift)`` (i, j integers) inside each parameter triangle.

    Parameters
    ----------
    P2 : (t, 3, 2) float, parameters of the triangle corners (orientation-preserving
        triangles only).
    X3 : (t, 3, 3) float, positions of the corners.
    """
    lo = np.ceil(P2.min(axis=1) - shift - 1e-9).astype(np.int64)
    hi = np.floor(P2.max(axis=1) - shift + 1e-9).astype(np.int64)
    nx, ny = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = nx * ny
    tri = np.repeat(np.arange(len(P2)), count)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    i = lo[tri, 0] + local // np.maximum(ny[tri], 1)
    j = lo[tri, 1] + local % np.maximum(ny[tri], 1)
    q = np.stack([i, j], axis=1) + shift
    a, b, c = P2[tri, 0], P2[tri, 1], P2[tri, 2]
    v0, v1, v2 = b - a, c - a, q - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    l1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
    l2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    l0 = 1 - l1 - l2
    inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
    bary = np.stack([l0, l1, l2], axis=1)[inside]
    tri = tri[inside]
    pos = np.einsum("pk,pkj->pj", bary, X3[tri])
    return _Points(np.stack([i, j], axis=1)[inside], pos, tri)


class _KeyTable:
    """Lookup of points by integer key, several points per key told apart by position."""

    def __init__(self, key: np.ndarray, position: np.ndarray, ids: np.ndarray):
        self.base = key.min(axis=0) - 4 if len(key) else np.zeros(2, np.int64)
        self.width = int(np.ptp(key[:, 1])) + 9 if len(key) else 1
        code = self._code(key)
        order = np.argsort(code, kind="stable")
        self.code, self.position, self.ids = code[order], position[order], ids[order]
        starts = np.searchsorted(self.code, self.code, side="left")
        ends = np.searchsorted(self.code, self.code, side="right")
        self.multiplicity = int((ends - starts).max()) if len(code) else 0

    def _code(self, key):
        k = key - self.base
        return k[:, 0] * self.width + k[:, 1]

    def find(self, key: np.ndarray, near: np.ndarray, radius: float) -> np.ndarray:
        """(m,) int, id of the point with `key` nearest to `near` within `radius`, or -1."""
        k = key - self.base
        valid = (k[:, 1] >= 0) & (k[:, 1] < self.width)
        code = k[:, 0] * self.width + k[:, 1]
        start = np.searchsorted(self.code, code, side="left")
        end = np.searchsorted(self.code, code, side="right")
        best = np.full(len(key), -1)
        best_d = np.full(len(key), radius)
        for m in range(self.multiplicity):
            at = start + m
            ok = valid & (at < end)
            d = np.full(len(key), np.inf)
            d[ok] = np.linalg.norm(self.position[at[ok]] - near[ok], axis=1)
            better = d < best_d
            best[better] = self.ids[at[better]]
            best_d[better] = d[better]
        return best


def extract_quads(P2: np.ndarray, X3: np.ndarray, normals: np.ndarray, panel_size: float,
                  transitions: list, settings: LayoutSettings) -> tuple:
    """Quads on the integer points of a parametrization.

    Parameters
    ----------
    P2 : (t, 3, 2) float, ``(phi, psi)`` at the corners of every triangle (cut mesh).
    X3 : (t, 3, 3) float, corner positions.
    normals : (t, 3) float, unit triangle normals.
    panel_size : target edge length (model units).
    transitions : list of (sign, (2,) offset): the parameters ``q`` on one side of a cut
        or seam are ``sign * p + offset`` of those ``p`` on the other (a translation by an
        integer vector across a loop cut, a half turn ``c - p`` across a seam).
    settings : edge bounds of accepted quads.

    Returns
    -------
    vertices : (n, 3) float, on the triangles.
    quads : (q, 4) int, counter-clockwise about the surface normal.
    keys : (n, 2) int, integer parameters of every vertex (one of them for a vertex on a
        cut).
    """
    h = panel_size
    e0, e1 = P2[:, 1] - P2[:, 0], P2[:, 2] - P2[:, 0]
    area = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
    # triangles the map folds over or squeezes are not trusted
    X = X3
    area3 = 0.5 * np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    good = area > 1e-3 * area3 / h**2
    keep = np.flatnonzero(good)
    nodes = _lattice_points(P2[keep], X3[keep], 0.0)
    centres = _lattice_points(P2[keep], X3[keep], 0.5)
    if len(nodes.key) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64)
    vertices, first, entries, keys = _distinct_vertices(nodes, h)
    normal_of = normals[keep][nodes.triangle[first]]
    table = _KeyTable(entries[:, :2], vertices[entries[:, 2]], entries[:, 2])
    centre_table = _KeyTable(np.floor(centres.key).astype(np.int64), centres.position,
                             np.arange(len(centres.key)))
    base, v0 = entries[:, :2], entries[:, 2]
    steps = np.array([[1, 0], [1, 1], [0, 1]])
    maps = [(sign, np.round(shift).astype(np.int64))
            for sign, shift in transition_maps(transitions)]
    corners = [v0]
    reach = 2.5 * h
    for step in steps:
        found = np.full(len(base), -1)
        for sign, shift in maps:
            miss = found < 0
            found[miss] = table.find(sign * (base[miss] + step) + shift, vertices[v0[miss]], reach)
        corners.append(found)
    quads = np.stack(corners, axis=1)
    ok = (quads >= 0).all(axis=1)
    quads = quads[ok]
    # the unit square's centre must lie on the surface, near the corners' centroid
    centroid = vertices[quads].mean(axis=1)
    found = np.full(len(quads), -1)
    for sign, shift in maps:
        miss = found < 0
        # the centre p + 1/2 maps to sign (p + 1/2) + shift, whose key is its floor
        key = sign * base[ok][miss] + shift - (1 if sign < 0 else 0)
        found[miss] = centre_table.find(key, centroid[miss], 0.5 * h)
    quads = quads[found >= 0]
    quads = quads[np.all(np.diff(np.sort(quads, axis=1), axis=1) > 0, axis=1)]
    Q = vertices[quads]
    edge = np.linalg.norm(Q - np.roll(Q, -1, axis=1), axis=2)
    fold = np.sum(np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]) * normal_of[quads].sum(axis=1),
                  axis=1) <= 0
    good = (edge.min(axis=1) >= settings.min_edge * h) & (edge.max(axis=1) <= settings.max_edge * h)
    quads = quads[good & ~fold]
    quads = unique_rows(quads) if len(quads) else quads
    # the same quad found from both sides of a cut
    _, first_q = unique_rows(np.sort(quads, axis=1), return_index=True)
    return vertices, quads[np.sort(first_q)], keys


def _distinct_vertices(nodes: _Points, h: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One vertex per distinct lattice point of `nodes` (points on shared edges and on
    the cuts coincide, to a millionth of the panel size `h`): vertices (n, 3), the first
    node (n,) int of each, the distinct rows ``(key, vertex)`` (e, 3) int, and keys (n, 2)
    int, one lattice key of each vertex."""
    tree = cKDTree(nodes.position)
    pairs = tree.query_pairs(1e-6 * h, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                          shape=(len(nodes.key),) * 2)
    _, vertex_of = csgraph.connected_components(graph, directed=False)
    first = np.full(vertex_of.max() + 1, len(vertex_of))
    np.minimum.at(first, vertex_of, np.arange(len(vertex_of)))
    vertices = nodes.position[first]
    entries = unique_rows(np.c_[nodes.key, vertex_of])
    keys = np.zeros((len(vertices), 2), np.int64)
    keys[entries[::-1, 2]] = entries[::-1, :2]
    return vertices, first, entries, keys


def transition_maps(transitions: list) -> list[tuple[int, np.ndarray]]:
    """The maps ``p -> sign p + shift`` (shifts (2,) float) between the sides of the cuts
    and seams of `transitions`, ``(sign, shift)`` each, the identity first: a loop cut
    open shifts by its jump both ways, a seam turns a half turn about its centre."""
    maps = [(1, np.zeros(2))]
    for sign, shift in transitions:
        shift = np.asarray(shift, dtype=np.float64)
        maps += [(1, shift), (1, -shift)] if sign > 0 else [(-1, shift)]
    return maps


def clean_quads(vertices: np.ndarray, quads: np.ndarray, *, min_piece: int = 12
                ) -> tuple[np.ndarray, np.ndarray]:
    """Edge-connected pieces of at least `min_piece` quads (and the largest in any case:
    where the directions have seams, the lattice comes in pieces that together clad the
    design), no edge used twice in one direction or by three faces, no pinched vertex.

    Returns
    -------
    used : (n,) bool, the vertices still in use.
    quads : (q, 4) int, the kept quads, numbered over the used vertices.
    """
    for _ in range(50):
        if len(quads) == 0:
            break
        n = len(vertices)
        a, b = quads.ravel(), np.roll(quads, -1, axis=1).ravel()
        face = np.repeat(np.arange(len(quads)), 4)
        und = np.minimum(a, b) * n + np.maximum(a, b)
        _, inv, cnt = np.unique(und, return_inverse=True, return_counts=True)
        dkey = a * n + b
        order = np.argsort(dkey, kind="stable")
        skey = dkey[order]
        dup = np.zeros(len(dkey), bool)
        dup[order[1:][skey[1:] == skey[:-1]]] = True
        bad = np.zeros(len(quads), bool)
        bad[face[(cnt[inv] > 2) | dup]] = True
        pos = np.clip(np.searchsorted(skey, b * n + a), 0, len(skey) - 1)
        twin = np.where(skey[pos] == b * n + a, order[pos], -1)
        # pinched vertices: more than one outgoing boundary half-edge
        pinch = np.bincount(a[twin < 0], minlength=n) > 1
        if pinch.any():
            # drop the faces at pinched vertices that have the fewest neighbours
            neighbours = np.bincount(face[twin >= 0], minlength=len(quads))
            at_pinch = np.zeros(len(quads), bool)
            at_pinch[face[pinch[a]]] = True
            bad |= at_pinch & (neighbours == neighbours[at_pinch].min())
        inner = twin >= 0
        adj = sp.coo_matrix((np.ones(int(inner.sum())), (face[inner], face[twin[inner]])),
                            shape=(len(quads),) * 2)
        ncomp, label = csgraph.connected_components(adj, directed=False)
        if ncomp > 1:
            size = np.bincount(label)
            small = (size < min_piece) & (np.arange(ncomp) != np.argmax(size))
            bad |= small[label]
        if not bad.any():
            break
        quads = quads[~bad]
    used = np.zeros(len(vertices), bool)
    used[quads.ravel()] = True
    remap = np.cumsum(used) - 1
    return used, remap[quads]


def fill_holes(vertices: np.ndarray, faces: list, design: DesignSurface, panel_size: float,
                max_edges: int, *, poles: np.ndarray | None = None,
                max_pole_edges: int = 64) -> tuple[np.ndarray, list, int, int]:
    """Close the interior holes of a layout (around singularities of the field).

    Holes bounded by 4 or 6 edges become one or two quads; larger ones a fan of quads
    (and one triangle when odd) around a new vertex on the surface. Holes more than
    `max_edges` long stay open, except around one of the `poles` (points the field turns
    a whole turn around, where the net's spirals close in: up to `max_pole_edges`; the
    fan's centre, the surface point nearest to the hole's centroid, becomes one
    many-valent vertex); loops near the design boundary are the layout's own boundary and
    are not touched.

    Returns
    -------
    vertices, faces : the closed layout.
    filled, left_open : counts of interior holes.
    """
    from ..solve.constraints.closeness import closest_points_on_polylines

    mesh = QuadMesh(vertices, faces)
    loops = [np.asarray(loop, dtype=np.int64) for loop in igl.boundary_loop_all(mesh.triangles())]
    curves = design.boundary_curves()
    be = mesh.boundary_edges
    forward = set(zip(be[:, 0].tolist(), be[:, 1].tolist(), strict=True))
    new_faces, new_vertices = list(faces), [vertices]
    count = len(vertices)
    filled = left_open = 0
    for loop in loops:
        if curves:
            foot, _ = closest_points_on_polylines(vertices[loop], curves)
            if np.linalg.norm(foot - vertices[loop], axis=1).min() < panel_size:
                continue
        elif len(loops) == 1:
            continue
        m = len(loop)
        limit = max_edges
        if poles is not None and len(poles):
            centre = vertices[loop].mean(axis=0)
            radius = np.linalg.norm(vertices[loop] - centre, axis=1).min()
            if np.linalg.norm(poles - centre, axis=1).min() < radius:
                limit = max_pole_edges
        if m > limit:
            left_open += 1
            continue
        if (int(loop[0]), int(loop[1])) in forward:
            loop = loop[::-1]      # new faces run against the hole's boundary half-edges
        if m == 4:
            new_faces.append(loop)
        elif m == 6:
            new_faces += [loop[[0, 1, 2, 3]], loop[[3, 4, 5, 0]]]
        else:
            centre, _, _ = design.reference.closest_points(vertices[loop].mean(axis=0)[None])
            new_vertices.append(centre)
            new_faces += [np.array([count, loop[k], loop[k + 1], loop[(k + 2) % m]])
                          for k in range(0, m - 1, 2)]
            if m % 2:
                new_faces.append(np.array([count, loop[m - 1], loop[0]]))
            count += 1
        filled += 1
    return np.concatenate(new_vertices), new_faces, filled, left_open


def fill_boundary_cells(vertices: np.ndarray, quads: np.ndarray, keys: np.ndarray,
                        design: DesignSurface, panel_size: float, *, passes: int = 2,
                        min_edge: float = 0.25, max_edge: float = 2.2,
                        snap: float = 0.4) -> tuple:
    """Close the staircase along the design boundary with quads whose outer corners lie
    on the boundary curve.

    Only lattice cells with all four corners on the surface become quads, so a layout
    ends up to one panel short of the design boundary, in steps. Here every missing
    cell next to the layout that has three corners (a notch of the staircase) or two
    corners along one edge gets its missing corners predicted (parallelograms, or one
    more step outwards), and where such a corner falls outside the surface it is moved
    to the nearest point of the boundary curve. The new quads must keep their edges
    between `min_edge` and `max_edge` panel sizes and face the way the surface does.

    Parameters
    ----------
    vertices : (n, 3) float; quads : (q, 4) int, corners ``(i, j), (i+1, j), (i+1, j+1),
        (i, j+1)`` of their lattice cell; keys : (n, 2) int, lattice keys of the vertices.
    design : the surface, with its boundary curves.
    panel_size : target edge length.
    passes : rounds (a convex corner of the boundary is closed in the second).
    snap : a predicted corner moves at most this many panel sizes to the boundary curve
        (farther, the quad would be too far from a parallelogram to make a good star).

    Returns
    -------
    vertices (n', 3), quads (q', 4), keys (n', 2), and the number of quads added.
    """
    from ..solve.constraints.closeness import closest_points_on_polylines

    curves = design.boundary_curves()
    h = panel_size
    added = 0
    if not curves or len(quads) == 0:
        return vertices, quads, keys, added
    corner = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    for _ in range(passes):
        table = _KeyTable(keys, vertices, np.arange(len(keys)))
        cells = unique_rows((keys[:, None, :] - corner[None]).reshape(-1, 2))
        done = unique_rows(keys[quads[:, 0]])
        cells = cells[~_rows_in(cells, done)]
        ids = np.stack([_lookup(table, cells + c) for c in corner], axis=1)   # (c, 4), -1 missing
        present = ids >= 0
        count = present.sum(axis=1)
        predicted_key, predicted_pos = [], []
        # notches: the missing corner completes the parallelogram of the other three
        notch = np.flatnonzero(count == 3)
        if notch.size:
            miss = np.argmin(present[notch], axis=1)
            a, o, b = (ids[notch, (miss + k) % 4] for k in (1, 2, 3))
            predicted_key.append(cells[notch] + corner[miss])
            predicted_pos.append(vertices[a] + vertices[b] - vertices[o])
        # edge cells: two corners along one cell edge, the cell beyond them missing
        for side in range(4):
            p, q = side, (side + 1) % 4
            rows = np.flatnonzero((count == 2) & present[:, p] & present[:, q])
            if rows.size == 0:
                continue
            inward = corner[p] - corner[(p + 3) % 4]     # from the missing side to p
            for k, m in ((p, (p + 3) % 4), (q, (q + 1) % 4)):
                inner = _lookup(table, cells[rows] + corner[k] + inward)
                ok = inner >= 0
                v = ids[rows[ok], k]
                predicted_key.append(cells[rows[ok]] + corner[m])
                predicted_pos.append(2 * vertices[v] - vertices[inner[ok]])
        if not predicted_key:
            break
        pk, inverse = unique_rows(np.concatenate(predicted_key), return_inverse=True)
        inverse = inverse.ravel()
        pos = np.zeros((len(pk), 3))
        np.add.at(pos, inverse, np.concatenate(predicted_pos))
        pos /= np.bincount(inverse, minlength=len(pk))[:, None]
        # a corner is new only where it falls off the surface: its closest point on the
        # surface is then on the boundary curve, where it goes
        on_surface, _, _ = design.reference.closest_points(pos)
        foot, _ = closest_points_on_polylines(pos, curves)
        outside = np.linalg.norm(on_surface - foot, axis=1) <= 1e-6 * h
        outside &= np.linalg.norm(foot - pos, axis=1) <= snap * h
        if not outside.any():
            break
        new_keys, new_pos = pk[outside], foot[outside]
        base = len(vertices)
        vertices = np.vstack([vertices, new_pos])
        keys = np.vstack([keys, new_keys])
        table = _KeyTable(keys, vertices, np.arange(len(keys)))
        ids = np.stack([_lookup(table, cells + c) for c in corner], axis=1)
        full = (ids >= 0).all(axis=1) & (ids >= base).any(axis=1)
        candidate = ids[full]
        Q = vertices[candidate]
        edge = np.linalg.norm(Q - np.roll(Q, -1, axis=1), axis=2)
        centre, _, tri = design.reference.closest_points(Q.mean(axis=1))
        facing = np.sum(np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1])
                        * design.face_normals[tri], axis=1) > 0
        good = (edge.min(axis=1) >= min_edge * h) & (edge.max(axis=1) <= max_edge * h) & facing
        # a corner snapped onto the boundary curve may line up with its neighbours there, or
        # the quad may span a corner of the boundary (a door's): neither is a panel
        good[good] = sound_quads(design, vertices, candidate[good], h)
        if not good.any():
            vertices, keys = vertices[:base], keys[:base]
            break
        quads = np.vstack([quads, candidate[good]])
        added += int(good.sum())
        used, quads = clean_quads(vertices, quads)
        vertices, keys = vertices[used], keys[used]
    return vertices, quads, keys, added


def sound_quads(design: DesignSurface, vertices: np.ndarray, quads: np.ndarray,
                panel_size: float) -> np.ndarray:
    """(q,) bool, the quads (q, 4) int into `vertices` (n, 3) that are panels: wholly on
    the design (none of their area over a hole or past the boundary, `faces_off_design`)
    and without three corners in a line (`degenerate_faces`)."""
    if len(quads) == 0:
        return np.zeros(0, bool)
    off = faces_off_design(design, vertices, quads, panel_size)
    return (off.area <= MIN_OFF_PANELS * panel_size ** 2) & ~degenerate_faces(vertices, quads)


def _lookup(table: _KeyTable, key: np.ndarray) -> np.ndarray:
    """(m,) int, the vertex with each key (the first when a key repeats), or -1."""
    k = key - table.base
    valid = (k[:, 1] >= 0) & (k[:, 1] < table.width) & (k[:, 0] >= 0)
    code = k[:, 0] * table.width + k[:, 1]
    at = np.clip(np.searchsorted(table.code, code), 0, len(table.code) - 1)
    hit = valid & (table.code[at] == code)
    return np.where(hit, table.ids[at], -1)


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(m,) bool, which rows of `rows` (m, 2) int appear in `table` (t, 2) int."""
    if len(table) == 0:
        return np.zeros(len(rows), bool)
    lo = np.minimum(rows.min(axis=0), table.min(axis=0))
    width = int(max(rows[:, 1].max(), table[:, 1].max()) - lo[1]) + 1
    code = (rows[:, 0] - lo[0]) * width + (rows[:, 1] - lo[1])
    known = (table[:, 0] - lo[0]) * width + (table[:, 1] - lo[1])
    return np.isin(code, known)
