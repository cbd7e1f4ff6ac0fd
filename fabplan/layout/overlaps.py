"""Pieces of a cladding that overlap one another, cross themselves or clash at an edge.

A cladding is the net's faces and the boundary panels cut beside them, all polygons into
one list of points. It is sound when every piece is a simple outline (its sides do not
cross), no two pieces cover the same part of the surface, and no side is used twice in
the same direction (two pieces on one side of it: a fold, which a mold plan or a strip
cannot read). These are measured here on the pieces as they are, in space: two pieces
near each other are seen along their common normal (the sum of their vector areas), and
they overlap when their outlines, made valid in that view, share more than
`OVERLAP_PANELS` of a full panel of area.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..net.index_rows import unique_rows

__all__ = ["overlapping_pairs", "edge_clashes", "self_crossing", "OVERLAP_PANELS"]

#: two pieces sharing less area than this share of a full panel touch: seen along one
#: direction, two curved pieces along a shared side (a non-planar face's outline against
#: a patch cut in the plane of a gap) share up to a few thousandths of a panel
OVERLAP_PANELS = 5e-3


def _rings(pieces: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenated outlines: (c,) int points, (p,) int sizes, (p,) int starts."""
    sizes = np.array([len(q) for q in pieces], dtype=np.int64)
    ring = np.concatenate(pieces).astype(np.int64) if len(pieces) else np.zeros(0, np.int64)
    return ring, sizes, np.r_[0, np.cumsum(sizes)[:-1]].astype(np.int64)


def _vector_areas(X: np.ndarray, ring: np.ndarray, sizes: np.ndarray, start: np.ndarray
                  ) -> np.ndarray:
    """(p, 3) float, the vector area of every outline."""
    piece = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(ring)) - start[piece]
    after = ring[start[piece] + (local + 1) % sizes[piece]]
    cross = 0.5 * np.cross(X[ring], X[after])
    return np.stack([np.bincount(piece, cross[:, k], minlength=len(sizes)) for k in range(3)],
                    axis=1)


def overlapping_pairs(points: np.ndarray, pieces: list, first_checked: int, panel_size: float,
                      *, min_share: float = OVERLAP_PANELS) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of pieces that overlap, of which at least one is checked.

    Parameters
    ----------
    points : (n, 3) float.
    pieces : list of (k,) int arrays into `points`, the outlines (net faces first).
    first_checked : the pieces from this one on are checked against every other (the
        ones before it, a net's faces, are not checked against one another).
    panel_size : the panel size; pairs sharing more than `min_share` of a full panel of
        area overlap.

    Returns
    -------
    pairs : (m, 2) int, ``i < j``, the overlapping pairs.
    area : (m,) float, the area each pair shares (model units squared).

    Examples
    --------
    Two unit squares side by side, and one shifted half over the second:

    >>> X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0],
    ...               [1.5, 0, 0], [2.5, 0, 0], [2.5, 1, 0], [1.5, 1, 0]], float)
    >>> pairs, area = overlapping_pairs(X, [np.array([0, 1, 2, 3]), np.array([1, 4, 5, 2]),
    ...                                     np.array([6, 7, 8, 9])], 1, 1.0)
    >>> pairs.tolist(), area.round(6).tolist()
    ([[1, 2]], [0.5])
    """
    X = np.asarray(points, np.float64)
    count = len(pieces)
    empty = (np.zeros((0, 2), np.int64), np.zeros(0))
    if count < 2 or first_checked >= count:
        return empty
    ring, sizes, start = _rings(pieces)
    piece = np.repeat(np.arange(count), sizes)
    centre = np.stack([np.bincount(piece, X[ring, k], minlength=count) for k in range(3)],
                      axis=1) / sizes[:, None]
    radius = np.zeros(count)
    np.maximum.at(radius, piece, np.linalg.norm(X[ring] - centre[piece], axis=1))
    tree = cKDTree(centre)
    pairs = tree.query_pairs(2.0 * float(radius.max()), output_type="ndarray")
    if len(pairs) == 0:
        return empty
    a, b = pairs[:, 0], pairs[:, 1]
    near = np.linalg.norm(centre[a] - centre[b], axis=1) <= radius[a] + radius[b]
    near &= np.maximum(a, b) >= first_checked
    # an outline of fewer than three points has no area to share
    near &= (sizes[a] >= 3) & (sizes[b] >= 3)
    a, b = np.minimum(a, b)[near], np.maximum(a, b)[near]
    if len(a) == 0:
        return empty
    # each pair seen along its common normal
    vector = _vector_areas(X, ring, sizes, start)
    normal = vector[a] + vector[b]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normal, helper)
    e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-300)
    e2 = np.cross(normal, e1)
    origin = 0.5 * (centre[a] + centre[b])

    def seen(which: np.ndarray) -> np.ndarray:
        counts = sizes[which]
        pair = np.repeat(np.arange(len(which)), counts)
        local = np.arange(counts.sum()) - np.repeat(np.r_[0, np.cumsum(counts)[:-1]], counts)
        P = X[ring[start[which][pair] + local]] - origin[pair]
        flat = np.stack([np.sum(P * e1[pair], axis=1), np.sum(P * e2[pair], axis=1)], axis=1)
        return shapely.make_valid(shapely.polygons(shapely.linearrings(flat, indices=pair)))

    shared = shapely.area(shapely.intersection(seen(a), seen(b)))
    hit = shared > min_share * panel_size ** 2
    return np.stack([a[hit], b[hit]], axis=1), shared[hit]


def edge_clashes(pieces: list, point_count: int) -> np.ndarray:
    """(m, 2) int, pairs of pieces ``i < j`` that use a side in the same direction (the
    pieces lie on one side of it: a fold).

    Examples
    --------
    >>> edge_clashes([np.array([0, 1, 2]), np.array([0, 1, 3]), np.array([1, 0, 4])], 5).tolist()
    [[0, 1]]
    """
    if not pieces:
        return np.zeros((0, 2), np.int64)
    ring, sizes, start = _rings(pieces)
    piece = np.repeat(np.arange(len(pieces)), sizes)
    local = np.arange(len(ring)) - start[piece]
    after = ring[start[piece] + (local + 1) % sizes[piece]]
    key = ring * point_count + after
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order][1:] == key[order][:-1])
    pairs = np.stack([piece[order[same]], piece[order[same + 1]]], axis=1)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return unique_rows(pairs) if len(pairs) else pairs


def self_crossing(points: np.ndarray, pieces: list) -> np.ndarray:
    """(p,) bool, outlines two of whose sides cross, seen along the outline's vector
    area (or its best fitting plane's normal where the lobes of a bow tie cancel).

    Examples
    --------
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> self_crossing(X, [np.array([0, 1, 2, 3]), np.array([0, 2, 1, 3])]).tolist()
    [False, True]
    """
    X = np.asarray(points, np.float64)
    out = np.zeros(len(pieces), bool)
    for k, q in enumerate(pieces):
        if len(q) < 4:
            continue
        P = X[np.asarray(q)]
        centred = P - P.mean(axis=0)
        normal = np.sum(np.cross(P, np.roll(P, -1, axis=0)), axis=0)
        if np.linalg.norm(normal) <= 1e-9 * np.sum(centred ** 2):
            normal = np.linalg.svd(centred)[2][2]
        axes = np.linalg.svd(normal[None, :])[2][1:]
        flat = centred @ axes.T
        out[k] = not shapely.LinearRing(flat).is_simple
    return out
