"""What of a cladding lies off its design: over a hole, or past the design boundary.

A facade with a door is a design whose boundary runs round the opening. Panels are laid
out on the design, but a panel is a flat or gently curved piece between its corners: a
quad whose corners all lie on the design may still span a door's corner, and a panel
cut in a chart that folds may cover the opening. This is measured on the surface,
independently of how the panels were made: every cladding triangle is sampled (the
centres of its `SAMPLE_LEVEL` squared sub-triangles, each carrying its share of the area),
and a sample is off the design when its closest design point lies on the design's
boundary curve and it stands beside that point rather than above or below it (sideways
by more than `OFF_TOLERANCE` of a panel). A sample over a gap between panels has its
closest point inside the design, straight below it: gaps are not counted here. A side
running from the boundary to the boundary close along it (a chord of a curved stretch,
`CHORD_SAG`) sags off it by its nature; that sag is not counted either: straight sides
cannot follow a curve, and a window's round rim is clad by faceted panels.

The same module says which faces are *degenerate*: three corners in a line (a corner
whose sides run straight on, or fold back), which a mill, a mold or a strip cannot read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..design.mesh_surface import DesignSurface
from ..net.index_rows import unique_rows

__all__ = ["OffDesign", "area_off_design", "faces_off_design", "degenerate_faces",
           "boundary_turning", "may_leave_design",
           "BOUNDARY_FOOT", "MIN_OFF_PANELS", "SAMPLE_LEVEL", "OFF_TOLERANCE",
           "STRAIGHT_DEG"]

#: each cladding triangle is cut into this many sub-triangles per side, one sample each
SAMPLE_LEVEL = 4

#: a sample standing this far (panel sizes) beside the design boundary is off the design;
#: below it, the chord between two outline points on a curved boundary (a ten-thousandth
#: of a panel on the designs of the corpus)
OFF_TOLERANCE = 1e-3

#: a closest design point this close to the design boundary (panel sizes) is on it
BOUNDARY_FOOT = 1e-6

#: a piece with less of its area off the design than this share of a full panel is on
#: it (the sampling's noise along a boundary the piece follows)
MIN_OFF_PANELS = 1e-4

#: a side from the design boundary to the design boundary that never leaves it by more
#: than this share of its length is a chord of a curved boundary (its sag: an arc of
#: radius 1.25 sides sags a tenth of a side), not a panel spanning a corner or a hole
CHORD_SAG = 0.1

#: a chord's ends may turn this much more than its arc (degrees): the boundary of a
#: triangle mesh turns in steps
CHORD_TURN_SLACK_DEG = 5.0

#: a corner whose sides turn by less than this from a straight line (or from folding back
#: on themselves) makes a face degenerate (degrees)
STRAIGHT_DEG = 2.0


@dataclass
class OffDesign:
    """The area of each piece of a cladding that lies off its design.

    Attributes
    ----------
    area : (p,) float, area of each piece off the design (model units squared).
    point : (p, 3) float, the sample of each piece farthest off the design (NaN rows for
        pieces wholly on it).
    """

    area: np.ndarray
    point: np.ndarray

    def pieces(self, min_area: float = 0.0) -> np.ndarray:
        """(k,) int, the pieces with more than `min_area` off the design, largest first."""
        hit = np.flatnonzero(self.area > min_area)
        return hit[np.argsort(-self.area[hit], kind="stable")]

    def places(self, min_area: float, *, label: str, ids: np.ndarray | None = None,
               count: int = 5) -> list[dict]:
        """JSON-ready list of the largest pieces off the design: ``{label: id, "area",
        "point"}``, at most `count`, ids renumbered through `ids` where given."""
        out = []
        for k in self.pieces(min_area)[:count]:
            out.append({label: int(k if ids is None else ids[k]), "area": float(self.area[k]),
                        "point": [float(v) for v in self.point[k]]})
        return out


def _sample_pattern(level: int) -> np.ndarray:
    """(level**2, 3) float, barycentric coordinates of the centres of the sub-triangles of
    a triangle cut `level` times per side.

    Examples
    --------
    >>> _sample_pattern(1).round(4).tolist()
    [[0.3333, 0.3333, 0.3333]]
    >>> _sample_pattern(3).shape, bool(np.allclose(_sample_pattern(3).sum(axis=1), 1))
    ((9, 3), True)
    """
    grid_i, grid_j = np.meshgrid(np.arange(level), np.arange(level), indexing="ij")
    i, j = grid_i.ravel(), grid_j.ravel()
    up = i + j <= level - 1
    down = i + j <= level - 2
    uv = np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], axis=1),
                         np.stack([i[down] + 2 / 3, j[down] + 2 / 3], axis=1)]) / level
    return np.column_stack([1.0 - uv.sum(axis=1), uv])


def area_off_design(design: DesignSurface, points: np.ndarray, triangles: np.ndarray,
                    owner: np.ndarray, count: int, panel_size: float, *,
                    level: int = SAMPLE_LEVEL) -> OffDesign:
    """The area of each piece of a cladding that lies off the design (see the module).

    Parameters
    ----------
    design : the design surface.
    points : (n, 3) float, the cladding's points.
    triangles : (t, 3) int into `points`, the cladding cut into triangles.
    owner : (t,) int, the piece (net face or panel) of each triangle, in ``0 .. count - 1``.
    count : the number of pieces.
    panel_size : the panel size (the tolerance is a share of it).
    level : sub-triangles per side sampled in each triangle.

    Returns
    -------
    OffDesign

    Examples
    --------
    A unit square design and a panel reaching half a unit past its right side:

    >>> square = DesignSurface([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
    ...                        [[0, 1, 2], [0, 2, 3]])
    >>> panel = np.array([[0.5, 0, 0], [1.5, 0, 0], [1.5, 1, 0], [0.5, 1, 0]])
    >>> off = area_off_design(square, panel, np.array([[0, 1, 2], [0, 2, 3]]),
    ...                       np.array([0, 0]), 1, 1.0)
    >>> round(float(off.area[0]), 6)
    0.5
    >>> area_off_design(square, panel[[0, 0, 3, 3]] - [0.5, 0, 0], np.array([[0, 1, 2]]),
    ...                 np.array([0]), 1, 1.0).area.tolist()
    [0.0]
    """
    points = np.asarray(points, np.float64)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    owner = np.asarray(owner, np.int64)
    curves = design.boundary_curves()
    if len(triangles) == 0 or not curves:
        return OffDesign(np.zeros(count), np.full((count, 3), np.nan))
    outline = _outline_sides(triangles, owner)
    sides = _sides_off_design(design, points, *outline, count, panel_size, curves)
    return _area_given_outline(design, points, triangles, owner, count, panel_size, level,
                               curves, sides)


def _area_given_outline(design: DesignSurface, points: np.ndarray, triangles: np.ndarray,
                        owner: np.ndarray, count: int, panel_size: float, level: int,
                        curves: list, sides: tuple[np.ndarray, np.ndarray, np.ndarray]
                        ) -> OffDesign:
    """The `OffDesign` of `area_off_design` (its arguments, and the design's boundary
    `curves`) given what `_sides_off_design` measured along the pieces' outlines
    (`sides`): the samples inside the triangles added to it."""
    where = np.full((count, 3), np.nan)
    pattern = _sample_pattern(level)
    T = points[triangles]                                              # (t, 3, 3)
    samples = np.einsum("sk,tkj->tsj", pattern, T).reshape(-1, 3)
    tri_area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    weight = np.repeat(tri_area / len(pattern), len(pattern))
    piece = np.repeat(owner, len(pattern))
    centre = T.mean(axis=1)
    near = np.repeat(may_leave_design(design, centre,
                                      np.linalg.norm(T - centre[:, None], axis=2).max(axis=1),
                                      curves, panel_size), len(pattern))
    sideways = np.zeros(len(samples))
    off = np.zeros(len(samples), bool)
    # only the samples of triangles that may reach the design boundary are measured: no
    # other sample can be off the design
    if near.any():
        sideways[near], off[near] = _off_boundary(design, samples[near], curves, panel_size)
    area = np.bincount(piece[off], weight[off], minlength=count).astype(np.float64)
    # a sliver along a side that leaves the design by less than the interior samples'
    # spacing: its area is the side's distance off the design summed along it. A side
    # from the boundary to the boundary along a curved stretch of it (a chord) sags off
    # it by its nature: what lies within that sag (and half again, the samples' error)
    # is no panel over a hole
    side_area, side_where, sag = sides
    area = np.maximum(area - 1.5 * sag, 0.0)
    take = (area == 0) & (side_area > 0)
    area = np.where(take, side_area, area)
    if not off.any():
        return OffDesign(area, side_where)
    hit = np.flatnonzero(off)
    order = hit[np.lexsort((-sideways[hit], piece[hit]))]
    first = order[np.r_[True, piece[order][1:] != piece[order][:-1]]]
    where[piece[first]] = samples[first]
    where[take] = side_where[take]
    return OffDesign(area, where)


def _off_boundary(design: DesignSurface, samples: np.ndarray, curves: list,
                  panel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """(m,) float, how far each sample (m, 3) stands beside its closest design point,
    along the design; (m,) bool, which samples are off the design: beside that point by
    more than `OFF_TOLERANCE` of a panel, with the point on the design boundary."""
    from ..solve.constraints.closeness import closest_points_on_polylines

    foot, _, tri = design.reference.closest_points(samples)
    offset = samples - foot
    normal = design.face_normals[tri]
    sideways = np.linalg.norm(offset - np.sum(offset * normal, axis=1, keepdims=True) * normal,
                              axis=1)
    off = sideways > OFF_TOLERANCE * panel_size
    if off.any():
        # beside a foot inside the design is a fold of the design mesh, not its edge
        edge_foot, _ = closest_points_on_polylines(foot[off], curves)
        off[off] = np.linalg.norm(edge_foot - foot[off], axis=1) <= BOUNDARY_FOOT * panel_size
    return sideways, off


def may_leave_design(design: DesignSurface, centre: np.ndarray, radius: np.ndarray,
                     curves: list, panel_size: float) -> np.ndarray:
    """(m,) bool, which balls (centres (m, 3), radii (m,)) may hold a point whose closest
    design point lies on the design boundary (`curves`, closed polylines, within
    `BOUNDARY_FOOT` of a panel): False only where none can.

    A point within ``r`` of the centre ``c`` is at most ``d(c) + r`` from the design, so
    its closest design point is on the boundary only if the boundary is at most
    ``d(c) + 2 r`` (and the tolerance) from ``c``; the boundary is no nearer to ``c``
    than its nearest vertex less half its longest side. Most of a cladding is far from
    the design boundary and on the design: its samples need no closest points.

    Examples
    --------
    >>> square = DesignSurface([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
    ...                        [[0, 1, 2], [0, 2, 3]])
    >>> centres = np.array([[0.5, 0.5, 0.0], [0.95, 0.5, 0.0], [0.5, 0.5, 2.0]])
    >>> may_leave_design(square, centres, np.full(3, 0.01), square.boundary_curves(),
    ...                  0.01).tolist()
    [False, True, True]
    >>> may_leave_design(square, np.zeros((0, 3)), np.zeros(0), square.boundary_curves(),
    ...                  1.0).tolist()
    []
    """
    from scipy.spatial import cKDTree

    centre = np.asarray(centre, np.float64).reshape(-1, 3)
    if len(centre) == 0:
        return np.zeros(0, bool)
    corners = np.concatenate(curves)
    longest = max(float(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1).max()) for c in curves)
    to_corner, _ = cKDTree(corners).query(centre)
    to_edge = to_corner - 0.5 * longest
    foot, _, _ = design.reference.closest_points(centre)
    to_design = np.linalg.norm(centre - foot, axis=1)
    # the margin covers the tolerance and the rounding of the distances many times over
    margin = (BOUNDARY_FOOT + 1e-3) * panel_size + 1e-9 * (to_corner + to_design + longest)
    return to_edge <= to_design + 2.0 * np.asarray(radius, np.float64) + margin


#: samples along every side of a piece's outline
SIDE_SAMPLES = 32


def _outline_sides(triangles: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outline of each piece: (k, 2) int, the sides of `triangles` (t, 3) int that no
    other triangle of the same piece shares, each as its triangle runs; (k,) int, the
    piece of each (`owner` (t,) int)."""
    sides = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    piece = np.tile(owner, 3)
    _, inverse, counts = unique_rows(np.column_stack([np.sort(sides, axis=1), piece]),
                                     return_inverse=True, return_counts=True)
    alone = counts[inverse] == 1
    return sides[alone], piece[alone]


def _sides_off_design(design: DesignSurface, points: np.ndarray, sides: np.ndarray,
                      piece: np.ndarray, count: int, panel_size: float, curves: list
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(count,) float, the area between each piece's outline (its `sides` (k, 2) int into
    `points`, of `piece` (k,) int each: `_outline_sides`) and the design boundary where the
    outline leaves the design (its distance off the design integrated along it,
    `SIDE_SAMPLES` samples a side), less its chords of the boundary; (count, 3) float,
    the point farthest off (NaN where none); (count,) float, the area between each
    piece's chords and the boundary (the sag it may have). A chord is a side from the
    boundary to the boundary that stays within `CHORD_SAG` of its length of it, where
    the boundary turns between its ends as an arc of that sag would (not at a corner, nor
    not at all: `boundary_turning`).
    """
    from ..solve.constraints.closeness import closest_points_on_polylines

    area, where = np.zeros(count), np.full((count, 3), np.nan)
    sag = np.zeros(count)
    if len(sides) == 0:
        return area, where, sag
    # sides that cannot reach the design boundary have no sample off it: left out
    A, B = points[sides[:, 0]], points[sides[:, 1]]
    near = may_leave_design(design, 0.5 * (A + B), 0.5 * np.linalg.norm(B - A, axis=1), curves,
                            panel_size)
    sides, piece, A, B = sides[near], piece[near], A[near], B[near]
    if len(sides) == 0:
        return area, where, sag
    t = (np.arange(SIDE_SAMPLES) + 0.5) / SIDE_SAMPLES
    S = (A[:, None] + t[None, :, None] * (B - A)[:, None]).reshape(-1, 3)
    step = np.repeat(np.linalg.norm(B - A, axis=1) / SIDE_SAMPLES, SIDE_SAMPLES)
    at = np.repeat(piece, SIDE_SAMPLES)
    sideways, off = _off_boundary(design, S, curves, panel_size)
    if not off.any():
        return area, where, sag
    # chords: both ends on the boundary curve, never farther off it than a sag
    ends = np.unique(sides)
    end_foot, _ = closest_points_on_polylines(points[ends], curves)
    on_curve = np.zeros(len(points), bool)
    on_curve[ends] = np.linalg.norm(end_foot - points[ends], axis=1) <= OFF_TOLERANCE * panel_size
    length = np.linalg.norm(B - A, axis=1)
    deepest = np.max(np.where(off, sideways, 0.0).reshape(-1, SIDE_SAMPLES), axis=1)
    chord = on_curve[sides[:, 0]] & on_curve[sides[:, 1]] & (deepest <= CHORD_SAG * length)
    if chord.any():
        # an arc whose chord sags s turns by 4 atan(2 s / L) between its ends; a side
        # across a corner of the boundary (a door's), or beside a straight stretch of it,
        # sags little but the boundary turns sharply, or not at all, between its ends
        arc_turn = 4.0 * np.arctan(2.0 * deepest[chord] / np.maximum(length[chord], 1e-300))
        turn = boundary_turning(curves, points[sides[chord, 0]], points[sides[chord, 1]])
        slack = np.radians(CHORD_TURN_SLACK_DEG)
        chord[chord] = (turn <= 1.5 * arc_turn + slack) & (turn >= 0.5 * arc_turn - slack)
    on_chord = np.repeat(chord, SIDE_SAMPLES)
    sag = np.bincount(at[off & on_chord], (sideways * step)[off & on_chord],
                      minlength=count).astype(np.float64)
    off &= ~on_chord
    if not off.any():
        return area, where, sag
    area = np.bincount(at[off], sideways[off] * step[off], minlength=count).astype(np.float64)
    hit = np.flatnonzero(off)
    order = hit[np.lexsort((-sideways[hit], at[hit]))]
    first = order[np.r_[True, at[order][1:] != at[order][:-1]]]
    where[at[first]] = S[first]
    return area, where, sag


def boundary_turning(curves: list, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(m,) float, how far the design boundary turns (radians, the sizes of the turns at
    its vertices added up) between the points nearest `start` (m, 3) and `end` (m, 3),
    along the shorter way; inf where the two lie on different boundary curves. A corner
    counts whole, and so does every step of a boundary that zigzags along a grid.

    Examples
    --------
    The unit square's boundary turns a quarter turn between two points on sides that
    meet, and not at all between two points of one side:

    >>> square = DesignSurface([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
    ...                        [[0, 1, 2], [0, 2, 3]])
    >>> turn = boundary_turning(square.boundary_curves(),
    ...                         np.array([[0.5, 0, 0], [0.2, 0, 0]]),
    ...                         np.array([[1, 0.5, 0], [0.7, 0, 0]]))
    >>> np.degrees(turn).round(6).tolist()
    [90.0, 0.0]
    """
    lengths = [len(c) for c in curves]
    first = np.r_[0, np.cumsum(lengths)[:-1]]
    a = np.concatenate(curves)
    curve_of = np.repeat(np.arange(len(curves)), lengths)
    local = np.arange(len(a)) - first[curve_of]
    after = first[curve_of] + (local + 1) % np.asarray(lengths)[curve_of]
    before = first[curve_of] + (local - 1) % np.asarray(lengths)[curve_of]
    # the turn at every vertex
    d_in, d_out = a - a[before], a[after] - a
    turn_at = np.arctan2(np.linalg.norm(np.cross(d_in, d_out), axis=1),
                         np.sum(d_in * d_out, axis=1))
    step = np.linalg.norm(d_out, axis=1)
    # running sums per curve: turn before vertex i, length before vertex i
    turn_sum = np.cumsum(turn_at) - np.r_[0, np.cumsum(turn_at)][first[curve_of]]
    length_sum = np.cumsum(step) - step - np.r_[0, np.cumsum(step)][first[curve_of]]

    def segment(points: np.ndarray) -> np.ndarray:
        b = a[after]
        ab = b - a
        length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
        out = np.empty(len(points), np.int64)
        for lo in range(0, len(points), 256):      # blocks bound the memory
            P = points[lo:lo + 256, None, :]
            t = np.clip(np.sum((P - a) * ab, axis=2) / length2, 0.0, 1.0)
            out[lo:lo + 256] = np.argmin(np.sum((a + t[..., None] * ab - P) ** 2, axis=2), axis=1)
        return out

    i, j = segment(np.asarray(start, np.float64)), segment(np.asarray(end, np.float64))
    same = curve_of[i] == curve_of[j]
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    # forward from segment lo to segment hi: the turns at vertices lo + 1 .. hi
    forward_turn = turn_sum[hi] - turn_sum[lo]
    forward_length = length_sum[hi] - length_sum[lo]
    total_turn = np.bincount(curve_of, turn_at, minlength=len(curves))[curve_of[lo]]
    total_length = np.bincount(curve_of, step, minlength=len(curves))[curve_of[lo]]
    shorter = np.where(forward_length <= total_length - forward_length, forward_turn,
                       total_turn - forward_turn)
    return np.where(same, shorter, np.inf)


def faces_off_design(design: DesignSurface, vertices: np.ndarray, faces: list | np.ndarray,
                     panel_size: float) -> OffDesign:
    """`area_off_design` of the polygons `faces` (list of (k,) int into `vertices` (n, 3)):
    each cut into triangles both ways, fanned from its first and from its second corner
    (a quad off its plane spans both), the two areas averaged.

    Examples
    --------
    >>> square = DesignSurface([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
    ...                        [[0, 1, 2], [0, 2, 3]])
    >>> V = np.array([[0.5, 0, 0], [1.5, 0, 0], [1.5, 1, 0], [0.5, 1, 0]])
    >>> round(float(faces_off_design(square, V, [np.arange(4)], 1.0).area[0]), 6)
    0.5
    """
    faces = [np.asarray(f, np.int64) for f in faces]
    count = len(faces)
    if count == 0:
        return OffDesign(np.zeros(0), np.zeros((0, 3)))
    vertices = np.asarray(vertices, np.float64)
    sizes = np.array([len(f) for f in faces])
    ring = np.concatenate(faces)
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    fans = np.maximum(sizes - 2, 0)
    face = np.repeat(np.arange(count), fans)
    j = np.arange(len(face)) - np.repeat(np.r_[0, np.cumsum(fans)[:-1]], fans) + 1
    area, point = np.zeros(count), np.full((count, 3), np.nan)
    curves = design.boundary_curves()
    if len(face) == 0 or not curves:
        return OffDesign(area, point)
    # both fans of a face have its sides for outline (but for a face that runs over a
    # corner twice): each outline measured once, keyed by its sorted (piece, side) rows
    measured: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for first in (0, 1):          # the fan from corner 0, then from corner 1
        corner = [ring[start[face] + (first + k) % sizes[face]] for k in (0 * j, j, j + 1)]
        fan = np.stack(corner, axis=1)
        outline = _outline_sides(fan, face)
        rows = np.column_stack([outline[1], outline[0]])       # (piece, side start, end)
        key = np.ascontiguousarray(rows[np.lexsort(rows.T[::-1])]).tobytes()
        if key not in measured:
            measured[key] = _sides_off_design(design, vertices, *outline, count, panel_size,
                                              curves)
        off = _area_given_outline(design, vertices, fan, face, count, panel_size,
                                  SAMPLE_LEVEL, curves, measured[key])
        area += 0.5 * off.area
        point = np.where(np.isnan(point), off.point, point)
    return OffDesign(area, point)


def degenerate_faces(vertices: np.ndarray, faces: list | np.ndarray, *,
                     straight_deg: float = STRAIGHT_DEG) -> np.ndarray:
    """(f,) bool, faces with three corners in a line: at some corner the two sides
    meeting there run within `straight_deg` of straight on, or of folding back (or one
    of them has no length).

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    >>> degenerate_faces(V, [np.array([0, 1, 3, 4]), np.array([0, 1, 2, 3])]).tolist()
    [False, True]
    """
    faces = [np.asarray(f, np.int64) for f in faces]
    if not faces:
        return np.zeros(0, bool)
    sizes = np.array([len(f) for f in faces])
    ring = np.concatenate(faces)
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    face = np.repeat(np.arange(len(faces)), sizes)
    local = np.arange(len(ring)) - start[face]
    nxt = ring[start[face] + (local + 1) % sizes[face]]
    prv = ring[start[face] + (local - 1) % sizes[face]]
    X = np.asarray(vertices, np.float64)
    a, b = X[prv] - X[ring], X[nxt] - X[ring]
    la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    scale = max(float(np.median(np.r_[la, lb])), 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = np.linalg.norm(np.cross(a, b), axis=1) / (la * lb)
    flat = ~(sine >= np.sin(np.radians(straight_deg))) | (la <= 1e-9 * scale) | \
        (lb <= 1e-9 * scale)
    return np.bincount(face, flat, minlength=len(faces)) > 0
