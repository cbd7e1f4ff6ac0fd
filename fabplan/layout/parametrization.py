"""A global parametrization ``(phi, psi)`` of a design surface whose isolines follow two
direction fields, one panel apart.

The gradients are fitted by sparse least squares on the design mesh cut open: boundary
loops around which the field turns (a tower) and points it turns around are cut to the
outer boundary and get an integer jump, so the grid closes up; seams of the combed line
field map the parameters to ``c - p``. `fabplan.extraction` turns the integer isolines
into quads.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ..design.mesh_surface import DesignSurface
from ..design.topology import edge_corners
from ..net.index_rows import unique_rows
from ..solve.linalg import solve_spd_columns

__all__ = ["integrate_directions", "cut_mesh", "CutMesh"]


# ---------------------------------------------------------------------------- cuts


def boundary_circulation(design: DesignSurface, loops: list, targets: list) -> np.ndarray:
    """(loops, k) float, circulation of each target gradient field (t, 3) along each loop."""
    V, T = design.vertices, design.triangles
    n, t = len(V), len(T)
    c0, c1 = edge_corners(T, n)
    has_twin = np.zeros(3 * t, bool)
    has_twin[c0] = has_twin[c1] = True
    corner = np.flatnonzero(~has_twin)
    a, b = T.ravel()[corner], T[:, [1, 2, 0]].ravel()[corner]
    loop_of = np.full(n, -1)
    for i, loop in enumerate(loops):
        loop_of[loop] = i
    out = np.zeros((len(loops), len(targets)))
    edge = V[b] - V[a]
    ok = loop_of[a] >= 0
    for k, g in enumerate(targets):
        contrib = np.sum(g[corner // 3] * edge, axis=1)
        out[:, k] = np.bincount(loop_of[a[ok]], weights=contrib[ok], minlength=len(loops))
    return out


def cut_paths(design: DesignSurface, starts: list, avoid: np.ndarray) -> list:
    """Disjoint shortest edge paths from each start (an inner boundary loop, or a singular
    vertex) to the outer boundary loop, avoiding the `avoid` vertices (seams).

    Returns a list of (k,) int vertex paths, each from its start to the outer loop.
    """
    V, T = design.vertices, design.triangles
    n = len(V)
    loops = design.boundary_loops
    if not loops:
        return []
    e = unique_rows(np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1))
    length = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    used = np.asarray(avoid, bool).copy()
    paths = []
    outer = loops[0]
    for inner in starts:
        used[inner] = False      # a singular vertex may end a seam: start from it anyway
        ok = ~(used[e[:, 0]] | used[e[:, 1]])
        graph = sp.coo_matrix((length[ok], (e[ok, 0], e[ok, 1])), shape=(n, n)).tocsr()
        dist, pred, _ = csgraph.dijkstra(graph, directed=False, indices=outer, min_only=True,
                                         return_predecessors=True)
        target = inner[np.argmin(dist[inner])]
        if not np.isfinite(dist[target]):
            continue
        parent = np.where(pred >= 0, pred, -1)
        depth = _depth(parent)
        # the path: ancestors of the target (hop distance to it along the tree adds up)
        tree = sp.coo_matrix((np.ones(int((parent >= 0).sum())),
                              (np.flatnonzero(parent >= 0), parent[parent >= 0])), shape=(n, n))
        hops = csgraph.shortest_path(tree, directed=False, unweighted=True, indices=target)
        on_path = np.flatnonzero(np.isfinite(hops) & (depth + hops == depth[target]))
        path = on_path[np.argsort(-depth[on_path])]
        used[path] = True
        paths.append(path)
    return paths


def _depth(parent: np.ndarray) -> np.ndarray:
    """(m,) int, number of steps to the root in a forest given by parent pointers."""
    depth = (parent >= 0).astype(np.int64)
    ptr = parent.copy()
    while np.any(ptr >= 0):
        act = ptr >= 0
        depth[act] += depth[ptr[act]]
        ptr[act] = ptr[ptr[act]]
    return depth


@dataclass
class CutMesh:
    """The design mesh cut open along translation cuts and field seams.

    Every design vertex on a cut has several copies; one (the master) carries the vertex's
    unknown, another is ``sign * master + jumps``: ``+master + J`` across a translation cut
    (a loop around which the grid closes up with an integer shift), ``-master + c`` across
    a seam of the line field (the combed field flips there, and so do both parameters).
    Copies where cuts branch or cross get unknowns of their own.
    """

    triangles: np.ndarray       # (t, 3) copy ids
    copy_vertex: np.ndarray     # (c,) design vertex of each copy
    sign: np.ndarray            # (c,) +1 / -1 relative to the master, 0 for free copies
    side: np.ndarray            # (c, p) coefficient of each translation jump
    seam: np.ndarray            # (c,) seam component whose constant applies, or -1
    paths: int
    seams: int

    def substitution(self) -> tuple[sp.csr_matrix, int]:
        """(c, m) copies from unknowns ``[vertices, free copies, jumps, seam constants]``,
        and the number m - n of trailing jump columns."""
        n = int(self.copy_vertex.max()) + 1
        c = len(self.copy_vertex)
        free = np.flatnonzero(self.sign == 0)
        bound = np.flatnonzero(self.sign != 0)
        nfree = len(free)
        rows = [bound, free]
        cols = [self.copy_vertex[bound], n + np.arange(nfree)]
        vals = [self.sign[bound].astype(np.float64), np.ones(nfree)]
        r, k = np.nonzero(self.side[bound])
        rows.append(bound[r])
        cols.append(n + nfree + k)
        vals.append(self.side[bound][r, k])
        flipped = bound[self.seam[bound] >= 0]
        rows.append(flipped)
        cols.append(n + nfree + self.paths + self.seam[flipped])
        vals.append(np.ones(len(flipped)))
        m = n + nfree + self.paths + self.seams
        S = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(c, m))
        return S, self.paths + self.seams


def cut_mesh(design: DesignSurface, paths: list, seam_edges: np.ndarray,
              e1: np.ndarray) -> CutMesh:
    """Cut the design mesh open along translation `paths` and the field's `seam_edges`.

    Parameters
    ----------
    paths : list of (k,) int vertex paths (each from an inner boundary loop outwards).
    seam_edges : (s, 2) int, design edges across which the combed field flips.
    e1 : (t, 3) float, the combed field (tells which side of a seam a copy is on).
    """
    T = design.triangles
    n, t = len(design.vertices), len(T)
    a = T.ravel()
    c0, c1 = edge_corners(T, n)
    ea, eb = a[c0], a[c1]        # c0 owns the half-edge ea -> eb, c1 the reverse one
    key = np.minimum(ea, eb) * n + np.maximum(ea, eb)
    path_key = [np.minimum(p[:-1], p[1:]) * n + np.maximum(p[:-1], p[1:]) for p in paths]
    seam_key = np.minimum(seam_edges[:, 0], seam_edges[:, 1]) * n + \
        np.maximum(seam_edges[:, 0], seam_edges[:, 1])
    keep = ~np.isin(key, np.concatenate(path_key + [seam_key]))

    def nxt(c):
        return 3 * (c // 3) + (c % 3 + 1) % 3

    k0, k1 = c0[keep], c1[keep]
    src = np.r_[k0, nxt(k0)]
    dst = np.r_[nxt(k1), k1]
    adj = sp.coo_matrix((np.ones(len(src)), (src, dst)), shape=(3 * t,) * 2)
    count, corner_copy = csgraph.connected_components(adj, directed=False)
    copy_vertex = np.zeros(count, np.int64)
    copy_vertex[corner_copy] = a
    copies = np.bincount(copy_vertex, minlength=n)
    master = np.full(n, count)
    np.minimum.at(master, copy_vertex, np.arange(count))
    is_master = master[copy_vertex] == np.arange(count)
    # which side of the cut: the field in the copy's triangles against the master's
    field = np.zeros((count, 3))
    np.add.at(field, corner_copy, e1[np.arange(3 * t) // 3])
    parity = np.sign(np.sum(field * field[master[copy_vertex]], axis=1))
    side = np.zeros((count, len(paths)))
    hb = T[:, [1, 2, 0]].ravel()
    on_path = np.zeros(n, bool)
    for i, p in enumerate(paths):
        # corners owning a half-edge p[k+1] -> p[k] are in the right-hand triangles
        right = np.flatnonzero(np.isin(a * n + hb, p[1:] * n + p[:-1]))
        side[corner_copy[right], i] = 1.0
        side[corner_copy[nxt(right)], i] = 1.0
        on_path[p] = True
    side -= side[master[copy_vertex]]
    on_seam = np.zeros(n, bool)
    on_seam[seam_edges.ravel()] = True
    seam_label = np.full(n, -1)
    nseam = 0
    if len(seam_edges):
        graph = sp.coo_matrix((np.ones(len(seam_edges)), (seam_edges[:, 0], seam_edges[:, 1])),
                              shape=(n, n))
        _, label = csgraph.connected_components(graph, directed=False)
        used, seam_label[on_seam] = np.unique(label[on_seam], return_inverse=True)
        nseam = len(used)
    v = copy_vertex
    sign = np.where(is_master, 1.0, 0.0)
    plain_path = ~is_master & on_path[v] & ~on_seam[v] & (copies[v] == 2) & (parity > 0)
    plain_seam = ~is_master & on_seam[v] & ~on_path[v] & (copies[v] == 2) & (parity < 0)
    sign[plain_path] = 1.0
    sign[plain_seam] = -1.0
    seam = np.where(plain_seam, seam_label[v], -1)
    side[sign <= 0] = 0.0
    return CutMesh(corner_copy.reshape(-1, 3), copy_vertex, sign, side, seam, len(paths), nseam)


# ---------------------------------------------------------------------------- integration


def integrate_directions(vertices: np.ndarray, triangles: np.ndarray, substitution: sp.spmatrix,
                         rows: list, free_jumps: int = 0) -> np.ndarray:
    """Least-squares scalar field with prescribed directional derivatives per triangle.

    Minimizes ``sum_rows sum_f w_f (d_f . grad u_f - value_f)^2`` over the unknowns ``x``
    with ``u = substitution @ x`` on the (cut) mesh.

    Parameters
    ----------
    vertices : (c, 3) float, vertex copies of the cut mesh.
    triangles : (t, 3) int, triangles on the copies.
    substitution : (c, m) sparse, copies from unknowns (vertex values and jumps).
    rows : list of (direction (t, 3), value (t,), weight (t,)).
    free_jumps : number of trailing unknowns that are jumps (not regularized).

    Returns
    -------
    x : (m,) float
    """
    G = igl.grad(vertices, triangles)
    t = len(triangles)
    blocks, rhs = [], []
    for d, value, w in rows:
        s = np.sqrt(w)
        D = (sp.diags(s * d[:, 0]) @ G[:t] + sp.diags(s * d[:, 1]) @ G[t:2 * t]
             + sp.diags(s * d[:, 2]) @ G[2 * t:])
        blocks.append(D @ substitution)
        rhs.append(s * value)
    A = sp.vstack(blocks).tocsr()
    b = np.concatenate(rhs)
    normal = (A.T @ A).tocsr()
    m = normal.shape[0]
    reg = np.full(m, 1e-9 * float(normal.diagonal().mean()))
    if free_jumps:
        reg[m - free_jumps:] = 1e-12 * float(normal.diagonal().mean())
    return solve_spd_columns(normal + sp.diags(reg), (A.T @ b)[:, None])[:, 0]


def gradient_target(normal: np.ndarray, along: np.ndarray, across: np.ndarray,
                    clip: bool = False) -> np.ndarray:
    """(t, 3) vector g in the tangent plane with ``g . along = 0`` and ``g . across = 1``."""
    g = np.cross(normal, along)
    denom = np.sum(g * across, axis=1, keepdims=True)
    if clip:
        denom = np.where(np.abs(denom) < 0.1, 0.1 * np.sign(denom + 1e-300), denom)
    return g / denom


def directional_derivatives(Xc, Tc, u, d) -> np.ndarray:
    """(t,) float, ``d . grad u`` per triangle."""
    G = igl.grad(Xc, Tc)
    t = len(Tc)
    g = G @ u
    return d[:, 0] * g[:t] + d[:, 1] * g[t:2 * t] + d[:, 2] * g[2 * t:]
