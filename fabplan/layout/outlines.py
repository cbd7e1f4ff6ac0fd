"""Panel outlines on the surface made simple: the zigzags where an outline turns back or
crosses itself dropped (`untangled`), and the panels that changed cut into triangles again
(`retriangulated`)."""

from __future__ import annotations

import numpy as np
import shapely

from .gap_patches import outline_triangles

__all__ = ["untangled", "retriangulated", "SPIKE_DEG"]


def untangled(vertices: np.ndarray, polygons: list, corner: np.ndarray
              ) -> tuple[list, np.ndarray, np.ndarray]:
    """The outlines without the zigzags where they turn back or cross themselves, and
    the panels whose outline still does.

    A net vertex that lies past the design boundary (a net optimized off the design
    keeps its boundary vertices where the solve left them, centimetres outside) is
    followed by the boundary curve's points behind it: the outline runs out to the vertex
    and back, across itself or along itself. Where an outline turns back on itself at a
    point (a spike: its two sides run opposite ways) or two of its sides cross (in the
    plane of the panel's vector area), points that are not corners (points that only
    follow the boundary curve) are dropped: the spike's tip, or its nearer foot when the
    tip is a corner; the points of the shorter loop between crossing sides. This repeats
    until the outline is simple; a zigzag of corners only is left and reported.

    Returns
    -------
    polygons : list of (k,) int arrays, the outlines.
    changed : (g,) int, the panels that lost points.
    crossed : (c,) int, the panels whose outline still turns back or crosses itself.
    """
    out, changed, crossed = [], [], []
    for k, ring in enumerate(polygons):
        ids = list(ring)
        while len(ids) > 3:
            drop = _spike(vertices[ids], corner[ids])
            if drop is None:
                pair = _first_crossing(vertices[ids])
                if pair is None:
                    break
                i, j = pair              # sides i and j cross: points i + 1 .. j between
                inner = list(range(i + 1, j + 1))
                outer = list(range(j + 1, len(ids))) + list(range(i + 1))
                loop = inner if len(inner) <= len(outer) else outer
                drop = {m for m in loop if not corner[ids[m]]}
            if not drop or len(ids) - len(drop) < 3:
                crossed.append(k)
                break
            ids = [v for m, v in enumerate(ids) if m not in drop]
        if len(ids) < len(ring):
            changed.append(k)
        out.append(np.asarray(ids, dtype=np.asarray(ring).dtype))
    return out, np.asarray(changed, np.int64), np.asarray(crossed, np.int64)


#: an outline turning by more than this at a point turns back on itself (degrees)
SPIKE_DEG = 175.0


def _spike(P: np.ndarray, corner: np.ndarray) -> set | None:
    """The point to drop at the first place the closed outline `P` (k, 3) turns back on
    itself or repeats a point: the tip when it is no corner, else its nearer neighbour
    that is none; None where it does neither but at corners only (a needle corner
    between two corners is a shape, not a zigzag)."""
    before = P - np.roll(P, 1, axis=0)
    after = np.roll(P, -1, axis=0) - P
    lb, la = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    scale = 1e-9 * max(float(np.max(lb)), 1e-300)
    repeated = la <= scale
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.sum(before * after, axis=1) / (lb * la)
    back = (cos < np.cos(np.radians(SPIKE_DEG))) & (lb > scale) & (la > scale)
    k = len(P)
    for i in np.flatnonzero(repeated | back).tolist():
        if repeated[i]:                 # point i + 1 repeats point i: drop one not a corner
            drop = [m for m in (i, (i + 1) % k) if not corner[m]]
        elif not corner[i]:
            drop = [i]
        else:
            drop = [m for _, m in sorted(((lb[i], (i - 1) % k), (la[i], (i + 1) % k)))
                    if not corner[m]]
        if drop:
            return {drop[0]}
    return None                         # none, or needle corners between corners only


def retriangulated(vertices: np.ndarray, polygons: list, triangles: np.ndarray,
                   owner: np.ndarray, changed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of the `changed` panels made again from their outlines (constrained
    Delaunay in the plane of each outline's vector area); a panel whose outline is not
    simple in that plane keeps its triangles less those on dropped points."""
    if len(changed) == 0:
        return triangles, owner
    keep = ~np.isin(owner, changed)
    new_t, new_o = [triangles[keep]], [owner[keep]]
    for k in changed:
        ring = np.asarray(polygons[k])
        outline = shapely.Polygon(_in_own_plane(vertices[ring]))
        if outline.is_valid and outline.area > 0:
            t = outline_triangles(outline, ring)
        else:
            old = triangles[owner == k]
            t = old[np.isin(old, ring).all(axis=1)]
        new_t.append(t)
        new_o.append(np.full(len(t), k))
    return np.concatenate(new_t).astype(np.int64), np.concatenate(new_o).astype(np.int64)


def _in_own_plane(P: np.ndarray) -> np.ndarray:
    """(k, 2) the closed outline `P` (k, 3) in the plane of its vector area (of its best
    fitting plane where the lobes of a bow tie cancel), about its centroid."""
    centred = P - P.mean(axis=0)
    normal = np.sum(np.cross(P, np.roll(P, -1, axis=0)), axis=0)
    if np.linalg.norm(normal) <= 1e-9 * np.sum(centred ** 2):
        normal = np.linalg.svd(centred)[2][2]
    axis = np.linalg.svd(normal[None, :])[2][1:]           # two directions across it
    return centred @ axis.T


def _first_crossing(P: np.ndarray) -> tuple[int, int] | None:
    """The first two sides of the closed outline `P` (k, 3) that cross, in the plane of
    its vector area: (i, j), i < j, side i from point i to i + 1; None when none do."""
    n = len(P)
    if not np.isfinite(P).all():
        return None
    q = _in_own_plane(P)
    a, b = q, np.roll(q, -1, axis=0)
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))                         # the last side meets the first
    i, j = i[keep], j[keep]

    def side(p, r, s):          # which side of p -> r the point s lies on (sign of cross)
        d = r - p
        return np.sign(d[..., 0] * (s[..., 1] - p[..., 1]) - d[..., 1] * (s[..., 0] - p[..., 0]))

    hit = (side(a[i], b[i], a[j]) * side(a[i], b[i], b[j]) < 0) & \
          (side(a[j], b[j], a[i]) * side(a[j], b[j], b[i]) < 0)
    first = np.flatnonzero(hit)
    return None if len(first) == 0 else (int(i[first[0]]), int(j[first[0]]))
