"""Topology of triangle meshes: edges shared by two triangles, components, vertex fans."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ..net.index_rows import unique_rows

__all__ = ["edge_corners", "triangle_pairs", "triangle_components", "vertex_fan_count"]


def triangle_pairs(T: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangles sharing an edge: (f, g, same) with same = both use it in one direction."""
    c0, c1 = edge_corners(T, n)
    a = T.ravel()
    return c0 // 3, c1 // 3, a[c0] == a[c1]


def edge_corners(T: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The two corners (3 t + k, the corner whose outgoing half-edge it is) of every edge
    shared by two triangles."""
    a, b = T.ravel(), T[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * n + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    skey = key[order]
    first = np.flatnonzero(skey[1:] == skey[:-1])
    return order[first], order[first + 1]


def triangle_components(T: np.ndarray, n: int) -> tuple[int, np.ndarray]:
    f, g, _ = triangle_pairs(T, n)
    adj = sp.coo_matrix((np.ones(len(f)), (f, g)), shape=(len(T), len(T)))
    return csgraph.connected_components(adj, directed=False)


def vertex_fan_count(T: np.ndarray, n: int) -> np.ndarray:
    """(n,) int, number of edge-connected fans of triangles around each vertex."""
    c0, c1 = edge_corners(T, n)
    a = T.ravel()

    def nxt(c):
        return 3 * (c // 3) + (c % 3 + 1) % 3

    same = a[c0] == a[c1]
    # corners at the edge's first vertex x = a[c0] and at its other end y
    x1 = np.where(same, c1, nxt(c1))
    y1 = np.where(same, nxt(c1), c1)
    src = np.r_[c0, nxt(c0)]
    dst = np.r_[x1, y1]
    adj = sp.coo_matrix((np.ones(len(src)), (src, dst)), shape=(3 * len(T),) * 2)
    _, label = csgraph.connected_components(adj, directed=False)
    pairs = unique_rows(np.stack([a, label], axis=1))
    return np.bincount(pairs[:, 0], minlength=n)
