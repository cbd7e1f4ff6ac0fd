"""The lines of the lamellas and their development: a net's parameter polylines, their node
normals, a polyline's lamella unrolled into the plane, and runs of nodes on one circle.

A lamella is the developable strip of height ``h`` that stands orthogonally on the surface
along a parameter line (paper, section 3.3). Its development preserves the normal
curvature of the line, so on an S-net whose Meusnier spheres share one radius ``r`` every
lamella unrolls to a piece of one circular annulus, and on an A-net to a straight strip.

Discrete lamella and its development
------------------------------------
At every node ``x_i`` of a polyline the lamella contains the node normal ``n_i``: its
ruling there is the normal, so the lamellas of the two families share that line at a
crossing and their slits interlock. Near ``x_i`` the lamella consists of the planar pieces
spanned by ``(x_{i-1} - x_i, n_i)`` and ``(n_i, x_{i+1} - x_i)``; unrolled, each keeps its
angles, so the developed polyline has the 3D edge lengths and turns at ``x_i`` by

    ``asin(n_i . (x_{i-1} - x_i) / |x_{i-1} - x_i|) + asin(n_i . (x_{i+1} - x_i) / |x_{i+1} - x_i|)``

towards the top (the side ``n_i`` points to). When the neighbours lie on a sphere of radius
``r`` touching the surface at ``x_i`` (the Meusnier sphere of an S-net star) each term is
``asin(l / 2r)``: the developed nodes lie on a circle of radius ``r``, exactly. On an A-net
the star is planar, both terms vanish and the strip unrolls straight. A node that is no
star centre (on the boundary) has no Meusnier sphere; its strip continues the normal
curvature of its neighbours there, and `Strip.lean_deg` reports how far that makes the
lamella lean from the node normal.

A lamella made of flat panels (the plane through each edge and the mean of its end
normals) cannot contain the normals at both ends of an edge when the normals twist about
the edge; `Strip.twist_deg_per_m` and `Strip.off_orthogonal_deg` measure that. Its
development is not the one above when the strips twist: on the bundled ``wein99`` net
(9 degrees of twist per bay) its unrolled radius varies node by node from -1.4 to +3.4 %
of r, so fabplan unrolls the bent lamella, whose radius is exact, and reports the twist.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...net.geometry import circumcircle_tangent, face_normals, fit_star_spheres, star_normals
from ...net.mesh import Polylines, QuadMesh

__all__ = [
    "ArcRun",
    "strip_polylines",
    "node_normals",
    "unroll_polylines",
    "fit_arc_runs",
]


# ---------------------------------------------------------------------- polylines and normals
def strip_polylines(mesh: QuadMesh, *, join_boundary: bool = True) -> Polylines:
    """The parameter polylines that carry lamellas: both families, quads only.

    Parameters
    ----------
    mesh : the net.
    join_boundary : join two polylines of the same family that both end at one boundary
        vertex and are the only ones of that family ending there. On a staircase boundary
        (valence-4 corners with three faces) a parameter line continues straight through
        the corner along the boundary edge, so the lamella does too.

    Returns
    -------
    Polylines with families 0 and 1 only; closed loops are kept closed.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.mesh import QuadMesh
    >>> u, v = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    >>> lines = strip_polylines(QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1)))
    >>> len(lines), sorted(len(p) for p in lines.vertices)
    (7, [3, 3, 3, 3, 4, 4, 4])
    """
    lines = mesh.polylines
    keep = np.flatnonzero(lines.family >= 0)
    verts = [np.asarray(lines.vertices[i], dtype=np.int64) for i in keep]
    family = lines.family[keep].astype(np.int64)
    closed = lines.closed[keep].astype(bool)
    if not join_boundary or not verts:
        return Polylines(vertices=verts, family=family, closed=closed)
    boundary = mesh.is_boundary_vertex
    # ends of open polylines at boundary vertices: (vertex, family) -> polyline ends
    ends: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for p, (v, fam, loop) in enumerate(zip(verts, family, closed, strict=True)):
        if loop or len(v) < 2:
            continue
        for side, vertex in ((0, v[0]), (1, v[-1])):
            if boundary[vertex]:
                ends.setdefault((int(vertex), int(fam)), []).append((p, side))
    # union-find over polylines joined at such vertices, then walk each chain once
    link: dict[tuple[int, int], tuple[int, int]] = {}
    for pair in ends.values():
        if len(pair) == 2 and pair[0][0] != pair[1][0]:
            link[pair[0]] = pair[1]
            link[pair[1]] = pair[0]
    used = np.zeros(len(verts), bool)
    out_v, out_f, out_c = [], [], []
    for p in range(len(verts)):
        if used[p] or ((p, 0) in link and (p, 1) in link):
            continue  # start chains at a polyline with a free end
        chain: list[np.ndarray] = []
        side = 0
        q, entry = p, (0 if (p, 0) not in link else 1)
        while True:
            used[q] = True
            part = verts[q] if entry == 0 else verts[q][::-1]
            chain.append(part if not chain else part[1:])
            side = 1 - entry
            if (q, side) not in link:
                break
            q, entry = link[(q, side)]
            if used[q]:
                break
        out_v.append(np.concatenate(chain))
        out_f.append(family[p])
        out_c.append(closed[p])
    for loop in np.flatnonzero(~used):  # chains that close up on themselves: keep as they were
        out_v.append(verts[loop])
        out_f.append(family[loop])
        out_c.append(closed[loop])
    return Polylines(vertices=out_v, family=np.array(out_f, np.int64), closed=np.array(out_c, bool))


def _polyline_neighbours(n: int, lines: Polylines) -> np.ndarray:
    """(n, 2, 2) int: previous and next vertex along the polyline of each family through
    each vertex, -1 where there is none (closed loops wrap around)."""
    nb = np.full((n, 2, 2), -1, dtype=np.int64)
    for v, f, loop in zip(lines.vertices, lines.family, lines.closed, strict=True):
        v = np.asarray(v)
        if f not in (0, 1) or len(v) < 2:
            continue
        prev = np.r_[v[-1] if loop else -1, v[:-1]]
        nxt = np.r_[v[1:], v[0] if loop else -1]
        nb[v, f, 0] = prev
        nb[v, f, 1] = nxt
    return nb


def node_normals(mesh: QuadMesh, polylines: Polylines | None = None) -> np.ndarray:
    """Unit surface normals at all vertices, from the net's discrete geometry.

    At a star centre the S-net normal (Def. 2.13). At any other vertex with at least three
    neighbours along the polylines through it (boundary vertices, vertices next to an
    irregular one) the normal of the sphere through the vertex and those neighbours (a
    plane when they are coplanar): the vertex is treated as a star with the missing
    neighbours left out, so a constant-radius net's boundary strips keep their radius.
    Where only two neighbours exist (a corner), the normal is orthogonal to the end
    tangents of both polylines (tangents of the circles through their first three nodes);
    the mean face normal, oriented as the Meusnier spheres nearby, is the last resort.

    Parameters
    ----------
    mesh : the net.
    polylines : the polylines whose neighbours count (default `strip_polylines`).

    Returns
    -------
    (n, 3) float, oriented like the faces.
    """
    X = mesh.vertices
    lines = strip_polylines(mesh) if polylines is None else polylines
    N = _sphere_normals(mesh)
    nb = _polyline_neighbours(len(X), lines)
    count = (nb >= 0).reshape(len(X), 4).sum(axis=1)
    todo = np.flatnonzero((mesh.star_of_vertex < 0) & (count >= 3)
                          & (nb[:, 0] >= 0).any(axis=1) & (nb[:, 1] >= 0).any(axis=1))
    if todo.size:
        # pseudo stars [v, a_prev, b_prev, a_next, b_next], a missing neighbour replaced by
        # the other one of its family (a repeated point leaves the sphere through the rest)
        q = nb[todo]
        for f in (0, 1):
            q[:, f, 0] = np.where(q[:, f, 0] >= 0, q[:, f, 0], q[:, f, 1])
            q[:, f, 1] = np.where(q[:, f, 1] >= 0, q[:, f, 1], q[:, f, 0])
        stars = np.column_stack([todo, q[:, 0, 0], q[:, 1, 0], q[:, 0, 1], q[:, 1, 1]])
        spheres = fit_star_spheres(X, stars, normals=N[todo])
        n = _unit(-spheres.coefficients[:, 1:4])
        good = np.isfinite(n).all(axis=1)
        N[todo[good]] = n[good]
    rest = np.flatnonzero((mesh.star_of_vertex < 0) & (count == 2))
    if rest.size:
        T = np.full((2, len(X), 3), np.nan)
        for v, f, loop in zip(lines.vertices, lines.family, lines.closed, strict=True):
            v = np.asarray(v)
            if len(v) < 3 or f not in (0, 1) or loop:
                continue
            T[f, v[0]] = circumcircle_tangent(X[v[0]], X[v[1]], X[v[2]])
            T[f, v[-1]] = -circumcircle_tangent(X[v[-1]], X[v[-2]], X[v[-3]])
        with np.errstate(invalid="ignore"):
            C = _unit(np.cross(T[0, rest], T[1, rest]))
        ok = np.isfinite(C).all(axis=1)
        ok[ok] &= np.abs(np.einsum("ij,ij->i", C[ok], N[rest[ok]])) > 0.5
        N[rest[ok]] = C[ok] * np.sign(np.einsum("ij,ij->i", C[ok], N[rest[ok]]))[:, None]
    return N


def _sphere_normals(mesh: QuadMesh) -> np.ndarray:
    """Star normals at star centres, the mean Meusnier-sphere normal at their neighbours,
    the mean face normal elsewhere: a robust orientation reference."""
    X, stars = mesh.vertices, mesh.stars
    N = _face_mean_normals(mesh)
    if len(stars) == 0:
        return N
    N[stars[:, 0]] = star_normals(X, stars)
    spheres = fit_star_spheres(X, stars, normals=N[stars[:, 0]])
    a, b = spheres.coefficients[:, 0], spheres.coefficients[:, 1:4]
    acc = np.zeros_like(X)
    count = np.zeros(len(X))
    for j in range(1, 5):
        v = stars[:, j]
        # gradient of a|x - c|^2 + b.(x - c) + c0 at the neighbour, b against the normal
        g = _unit(-(2 * a[:, None] * (X[v] - X[stars[:, 0]]) + b))
        ok = np.isfinite(g).all(axis=1)
        np.add.at(acc, v[ok], g[ok])
        np.add.at(count, v[ok], 1)
    fill = (mesh.star_of_vertex < 0) & (count > 0)
    mean = _unit(acc[fill])
    good = np.isfinite(mean).all(axis=1)
    N[np.flatnonzero(fill)[good]] = mean[good]
    return N


def _face_mean_normals(mesh: QuadMesh) -> np.ndarray:
    F = face_normals(mesh.vertices, mesh)
    face = mesh.corner_faces
    N = np.zeros_like(mesh.vertices)
    np.add.at(N, mesh.face_indices, F[face])
    return N / np.linalg.norm(N, axis=1, keepdims=True)


# ---------------------------------------------------------------------- development
@dataclass(frozen=True)
class Unrolled:
    """The development of many polylines at once, node arrays concatenated.

    Attributes
    ----------
    ptr : (p + 1,) int, nodes of polyline ``k`` are ``ptr[k]:ptr[k + 1]``.
    nodes : (M, 2) float, developed node positions (mm); each polyline starts at the
        origin with its first edge along +x, the top (normal side) to the left.
    axis : (M, 2) float, unit direction of the node normal in the development (towards
        the top): the lamella's ruling at the node, along which the slit runs.
    turning : (M,) float, turning angle at each node in radians (0 at the ends), positive
        towards the top.
    edge_mm : (M,) float, 3D length of the edge leaving each node (0 at the last node).
    twist : (M,) float, rotation of the normal about the edge leaving each node (radians,
        signed), 0 at the last node.
    off_orthogonal : (M,) float, angle between each node normal and the flat panels through
        its edges and their mean normals (radians), the larger of the two sides.
    lean : (M,) float, at nodes with an imposed curvature, the largest change it makes to
        the angle between the node normal and an edge (radians): how far the lamella leans
        from the normal there.
    """

    ptr: np.ndarray
    nodes: np.ndarray
    axis: np.ndarray
    turning: np.ndarray
    edge_mm: np.ndarray
    twist: np.ndarray
    off_orthogonal: np.ndarray
    lean: np.ndarray


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _segment_cumsum(values: np.ndarray, ptr: np.ndarray) -> np.ndarray:
    """Cumulative sums restarting at every segment start ``ptr[k]`` (inclusive sums)."""
    c = np.cumsum(values, axis=0)
    start = np.repeat(ptr[:-1], np.diff(ptr))
    before = np.where(start[:, None] > 0, c[np.maximum(start - 1, 0)], 0) if values.ndim == 2 \
        else np.where(start > 0, c[np.maximum(start - 1, 0)], 0)
    return c - before


def unroll_polylines(X: np.ndarray, N: np.ndarray, polylines: list, *, scale: float = 1.0,
                     curvature: np.ndarray | None = None) -> Unrolled:
    """Develop the normal-ruled lamellas along many polylines into the plane, vectorized.

    Parameters
    ----------
    X : (n, 3) float, vertex positions (model units).
    N : (n, 3) float, unit node normals (the top side of every lamella).
    polylines : sequence of (k,) int vertex index arrays, k >= 2.
    scale : millimetres per model unit.
    curvature : (M,) float, optional normal curvature (1 / model unit, positive towards the
        top) imposed at nodes of the concatenated polylines, NaN where the normals decide:
        such a node turns by ``asin(k l_in / 2) + asin(k l_out / 2)``. Its slit axis stays
        the unrolled node normal; `Unrolled.lean` measures how far that is from square.

    Returns
    -------
    Unrolled

    Examples
    --------
    Three points on a sphere of radius 2 through the south pole, normals to its centre:
    the developed nodes lie on a circle of radius 2.

    >>> import numpy as np
    >>> t = np.array([-0.3, 0.0, 0.3])
    >>> X = np.stack([2 * np.sin(t), 0 * t, 2 - 2 * np.cos(t)], axis=1)
    >>> N = np.array([0, 0, 2.0]) - X; N /= np.linalg.norm(N, axis=1, keepdims=True)
    >>> u = unroll_polylines(X, N, [np.arange(3)])
    >>> round(float(u.turning[1]), 12) == 0.3
    True
    """
    lengths = np.array([len(p) for p in polylines], dtype=np.int64)
    ptr = np.concatenate([[0], np.cumsum(lengths)])
    V = np.concatenate([np.asarray(p, dtype=np.int64) for p in polylines])
    P, Nn = X[V] * scale, N[V]
    M = len(V)
    last = np.zeros(M, bool)
    last[ptr[1:] - 1] = True
    first = np.zeros(M, bool)
    first[ptr[:-1]] = True
    e = np.zeros((M, 3))
    e[:-1] = P[1:] - P[:-1]
    e[last] = 0.0
    length = np.linalg.norm(e, axis=1)
    u = np.zeros_like(e)
    u[~last] = e[~last] / length[~last, None]
    # angles between the node normal and its outgoing / incoming edge
    cos_out = np.einsum("ij,ij->i", Nn, u)
    cos_in = np.zeros(M)
    cos_in[1:] = -np.einsum("ij,ij->i", Nn[1:], u[:-1])
    cos_in[first] = 0.0
    sin_out, sin_in = cos_out, cos_in  # sines of the turning parts, cosines of the axis angles
    lean = np.zeros(M)
    if curvature is not None:
        k = np.asarray(curvature, dtype=np.float64) / scale
        length_in = np.r_[0.0, length[:-1]]
        imposed = np.isfinite(k)
        sin_out = np.where(imposed, k * length / 2, cos_out)
        sin_in = np.where(imposed, k * length_in / 2, cos_in)
        lean = np.where(imposed, np.maximum(
            np.abs(np.arcsin(np.clip(sin_out, -1, 1)) - np.arcsin(np.clip(cos_out, -1, 1))),
            np.abs(np.arcsin(np.clip(sin_in, -1, 1)) - np.arcsin(np.clip(cos_in, -1, 1)))), 0.0)
        lean[first | last] = 0.0
    turning = np.arcsin(np.clip(sin_out, -1, 1)) + np.arcsin(np.clip(sin_in, -1, 1))
    turning[first | last] = 0.0
    heading = _segment_cumsum(turning, ptr)
    step = length[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    nodes = np.zeros((M, 2))
    nodes[1:] = _segment_cumsum(step, ptr)[:-1]
    nodes[first] = 0.0
    # the normal in the development: beta = angle(n, outgoing edge), rotated towards the top;
    # at the last node from the incoming edge
    beta = np.arccos(np.clip(cos_out, -1, 1))
    alpha = np.arccos(np.clip(cos_in, -1, 1))
    angle = heading + beta
    prev_heading = np.zeros(M)
    prev_heading[1:] = heading[:-1]
    angle[last] = prev_heading[last] + np.pi - alpha[last]
    axis = np.column_stack([np.cos(angle), np.sin(angle)])
    # twist of the normals about each edge, and the lean of flat panels
    n0 = Nn - u * np.einsum("ij,ij->i", Nn, u)[:, None]
    n1 = np.zeros_like(Nn)
    n1[:-1] = Nn[1:] - u[:-1] * np.einsum("ij,ij->i", Nn[1:], u[:-1])[:, None]
    twist = np.arctan2(np.einsum("ij,ij->i", np.cross(n0, n1), u), np.einsum("ij,ij->i", n0, n1))
    twist[last] = 0.0
    mean = np.zeros_like(Nn)
    mean[:-1] = Nn[:-1] + Nn[1:]
    F = _unit(np.cross(u, mean))
    lean_out = np.abs(np.einsum("ij,ij->i", Nn, F))
    lean_in = np.zeros(M)
    lean_in[1:] = np.abs(np.einsum("ij,ij->i", Nn[1:], F[:-1]))
    lean_out[last] = 0.0
    lean_in[first] = 0.0
    off = np.arcsin(np.clip(np.nan_to_num(np.maximum(lean_out, lean_in)), 0, 1))
    return Unrolled(ptr=ptr, nodes=nodes, axis=axis, turning=turning, edge_mm=length,
                    twist=twist, off_orthogonal=off, lean=lean)


# ---------------------------------------------------------------------- arcs
@dataclass(frozen=True)
class ArcRun:
    """Consecutive edges of a reference curve cut as arcs of one circle (or as a line).

    Attributes
    ----------
    start, stop : first and last node of the run (stop > start).
    radius_mm : signed radius, positive when the centre lies on the top side; ``inf`` for a
        straight run. A run of one edge that no circle was fitted to is straight and has
        ``fitted`` False.
    deviation_mm : largest distance of a run node from the fitted circle or line.
    fitted : whether the run was fitted (at least three nodes) rather than a lone edge.
    """

    start: int
    stop: int
    radius_mm: float
    deviation_mm: float
    fitted: bool


def _fit_circle(P: np.ndarray) -> tuple[float, np.ndarray, float]:
    """Least-squares circle through 2D points (algebraic fit refined by Gauss-Newton).

    Returns
    -------
    radius, centre (2,), largest distance of a point from the circle; radius inf when the
    points are collinear to rounding.
    """
    c0 = P.mean(axis=0)
    Q = P - c0
    scale = np.abs(Q).max() or 1.0
    Q = Q / scale
    A = np.column_stack([2 * Q, np.ones(len(Q))])
    sol, *_ = np.linalg.lstsq(A, np.sum(Q * Q, axis=1), rcond=None)
    centre = sol[:2]
    r2 = sol[2] + centre @ centre
    if not np.isfinite(r2) or r2 <= 0 or np.sqrt(r2) > 1e8:
        return math.inf, np.full(2, np.nan), math.inf
    for _ in range(5):  # geometric refinement: minimize sum (|q - c| - R)^2
        d = Q - centre
        rho = np.linalg.norm(d, axis=1)
        R = rho.mean()
        J = np.column_stack([-d / rho[:, None], -np.ones(len(Q))])
        delta, *_ = np.linalg.lstsq(J, -(rho - R), rcond=None)
        centre = centre + delta[:2]
    rho = np.linalg.norm(Q - centre, axis=1)
    R = rho.mean()
    return float(R * scale), centre * scale + c0, float(np.abs(rho - R).max() * scale)


def _line_deviation(P: np.ndarray) -> float:
    """Largest distance of 2D points from their total-least-squares line."""
    C = P - P.mean(axis=0)
    _, _, vt = np.linalg.svd(C, full_matrices=False)
    return float(np.abs(C @ vt[-1]).max())


def _fit_run(P: np.ndarray, tolerance_mm: float) -> tuple[float, float] | None:
    """The signed radius (mm; ``inf`` for a line) and deviation of the line or circle that
    holds the nodes `P` (k, 2) within `tolerance_mm`, or None."""
    dev_line = _line_deviation(P)
    if dev_line <= tolerance_mm:
        return math.inf, dev_line
    R, centre, dev = _fit_circle(P)
    if dev > tolerance_mm:
        return None
    # centre on the top (left) side of the first edge gives a positive radius (a chord
    # test would fail for runs turning by more than half a turn)
    edge = P[1] - P[0]
    side = edge[0] * (centre[1] - P[0, 1]) - edge[1] * (centre[0] - P[0, 0])
    return (R if side > 0 else -R), dev


def _longest_run(nodes: np.ndarray, i: int, min_edges: int,
                 tolerance_mm: float) -> tuple[int, tuple[float, float]] | None:
    """Largest j such that nodes i..j fit (`_fit_run`), with its fit, or None."""
    k = len(nodes)
    j = i + min_edges
    if j > k - 1 or (res := _fit_run(nodes[i:j + 1], tolerance_mm)) is None:
        return None
    best, step = (j, res), 1
    while True:  # exponential, then binary search (a subset of a fitting run fits)
        hi = min(j + step, k - 1)
        if hi == j or (res := _fit_run(nodes[i:hi + 1], tolerance_mm)) is None:
            break
        best, j, step = (hi, res), hi, step * 2
    lo, hi = j, min(j + step, k - 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if (res := _fit_run(nodes[i:mid + 1], tolerance_mm)) is not None:
            best, lo = (mid, res), mid
        else:
            hi = mid
    return best


def fit_arc_runs(nodes: np.ndarray, tolerance_mm: float) -> list[ArcRun]:
    """Split a developed polyline into runs of nodes on one circle or line.

    Greedy from the first node: each run is extended as far as all its nodes stay within
    `tolerance_mm` of their best-fit line (preferred) or circle. Three points always lie on
    a circle, so a run needs four nodes to show that a circle holds (a strip of three nodes
    is one run); a run stops three edges short of the end when the rest would be too short
    for a run of its own. Edges no run takes are straight (the polyline itself).

    Parameters
    ----------
    nodes : (k, 2) float, developed nodes (mm), k >= 2, the top to the left.
    tolerance_mm : cutting tolerance.

    Returns
    -------
    list of ArcRun covering the edges 0..k-2 in order.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 6)
    >>> runs = fit_arc_runs(np.column_stack([100 * np.sin(t), 100 - 100 * np.cos(t)]), 0.01)
    >>> [(r.start, r.stop, round(r.radius_mm, 6)) for r in runs]
    [(0, 5, 100.0)]
    """
    k = len(nodes)
    min_edges = 2 if k == 3 else 3
    runs: list[ArcRun] = []
    i = 0
    while i < k - 1:
        best = _longest_run(nodes, i, min_edges, tolerance_mm)
        if best is None:
            runs.append(ArcRun(i, i + 1, math.inf, 0.0, False))
            i += 1
            continue
        stop, res = best
        if 0 < k - 1 - stop < min_edges:
            # leave the tail enough edges for a run of its own when it fits
            cut = k - 1 - min_edges
            if (cut - i >= min_edges and _fit_run(nodes[cut:k], tolerance_mm) is not None
                    and (head := _fit_run(nodes[i:cut + 1], tolerance_mm)) is not None):
                stop, res = cut, head
        runs.append(ArcRun(i, stop, float(res[0]), float(res[1]), True))
        i = stop
    return runs
