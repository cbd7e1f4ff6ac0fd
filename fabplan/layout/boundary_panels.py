"""Boundary panels as a result (`BoundaryPanels`): the panels between a net and the design
boundary, what they cover, read back from ``NET.boundary.obj`` (`read_boundary_panels`),
and their split points slid along the boundary onto given lines (`slide_splits`). They are
cut by `fabplan.layout.trim`."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..net.mesh import QuadMesh
from .outlines import retriangulated
from .overlaps import edge_clashes

__all__ = ["BoundaryPanels", "read_boundary_panels", "slide_splits", "neighbour_faces"]


@dataclass
class BoundaryPanels:
    """The panels between a net and the design boundary, and the coverage they give.

    Attributes
    ----------
    vertices : (m, 3) float, the net's vertices (first `net_vertex_count` rows, unchanged)
        followed by the new corners and trim-outline points (on the design surface, or
        off it with the net for `follows_net`).
    polygons : list of (k,) int arrays, each boundary panel's outline into `vertices`,
        counter-clockwise about the surface normal, following the design boundary.
    net_vertex_count : number of the net's vertices at the head of `vertices`.
    on_boundary : (m,) bool, points on the design's boundary curve.
    corner : (m,) bool, panel corners: net vertices, ends of the extended lines and
        crossings off the boundary (the other points follow the boundary curve).
    neighbour_face : (p,) int, the net face each panel continues: the one it shares its
        longest side with, else (a corner cell, a sliver) the nearest one.
    area : (p,) float, area of each panel on the design (model units squared).
    panel_size : the layout's panel size.
    coverage_net : share of the design's area the net's full panels cover.
    coverage : share covered by the full and the boundary panels together.
    flipped : (k,) int, panels that face against the design (none in a sound result).
    crossed : (k,) int, panels whose outline crosses itself (none in a sound result; see
        `untangled`; slivers along the boundary curve, `extension`, are not listed).
    patch : (p,) bool, the panels that close a hole inside the net (not reaching the
        design boundary).
    extension : (p,) bool, slivers under `min_panel` of a full panel along the side of a
        full panel: made as part of that panel (cut larger from its mold), not as panels
        of their own.
    boundary_distance_max : largest distance of a point flagged `on_boundary` from the
        design's boundary curve (the exact one for a built-in design), in panel sizes
        (with `follows_net`, lifted points: about the lift there).
    soundness : what is wrong with the net and its panels, measured on the surface
        (`Soundness.record`: ``off_design`` and ``crossings``); empty where unknown.
    follows_net : the points off the net stand off the design as the net does beside
        them (`trim_to_design(..., follow_net=True)`); offset_max : the largest such lift
        (model units).
    seconds : time taken.
    triangles : (t, 3) int into `vertices`, the panels cut into triangles in the plane of
        the parametrization (concave outlines stay whole), or None; triangle_panel :
        (t,) int, the panel of each (see `panel_triangles`).
    net_on_boundary : (n,) bool, the net's vertices on the design boundary (to a
        `touch` of a panel); empty where unknown.
    gaps : the largest parts of the design no panel covers (`coverage_gaps`), largest
        first.
    """

    vertices: np.ndarray
    polygons: list
    net_vertex_count: int
    on_boundary: np.ndarray
    corner: np.ndarray
    neighbour_face: np.ndarray
    area: np.ndarray
    panel_size: float
    coverage_net: float
    coverage: float
    flipped: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    crossed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    patch: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    extension: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    boundary_distance_max: float = 0.0
    seconds: float = 0.0
    triangles: np.ndarray | None = None
    triangle_panel: np.ndarray | None = None
    net_on_boundary: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gaps: list = field(default_factory=list)
    follows_net: bool = False
    offset_max: float = 0.0
    soundness: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        """All pieces, extensions of full panels included (the rows of every array)."""
        return len(self.polygons)

    @property
    def panel_count(self) -> int:
        """The boundary panels made as panels of their own (not extensions)."""
        return int(np.sum(~self.extension))

    def panel_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """The panels as triangles: (t, 3) int into `vertices` and (t,) int, the panel of
        each; those of the trimming when kept, else a fan from each outline's first point
        (right for the convex outlines of most boundary panels).

        Examples
        --------
        >>> panels = BoundaryPanels(np.zeros((5, 3)), [np.array([0, 1, 2, 3]), np.array([1, 4, 2])],
        ...                         0, np.zeros(5, bool), np.zeros(5, bool), np.zeros(2, int),
        ...                         np.ones(2), 1.0, 1.0, 1.0)
        >>> triangles, panel = panels.panel_triangles()
        >>> triangles.tolist(), panel.tolist()
        ([[0, 1, 2], [0, 2, 3], [1, 4, 2]], [0, 0, 1])
        """
        if self.triangles is not None and self.triangle_panel is not None:
            return np.asarray(self.triangles, np.int64), np.asarray(self.triangle_panel, np.int64)
        if not self.polygons:
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
        sizes = np.array([len(q) for q in self.polygons])
        ids = np.concatenate(self.polygons).astype(np.int64)
        start = np.r_[0, np.cumsum(sizes)[:-1]]
        panel = np.repeat(np.arange(len(sizes)), np.maximum(sizes - 2, 0))
        j = np.arange(len(panel)) - np.repeat(np.r_[0, np.cumsum(np.maximum(sizes - 2, 0))[:-1]],
                                              np.maximum(sizes - 2, 0)) + 1
        first = start[panel]
        return np.stack([ids[first], ids[first + j], ids[first + j + 1]], axis=1), panel

    @property
    def on_design_boundary(self) -> np.ndarray:
        """(m,) bool, the points on the design's boundary curve: the new corners and
        outline points there (`on_boundary`) and the net's vertices there
        (`net_on_boundary`)."""
        out = np.asarray(self.on_boundary, bool).copy()
        on_net = np.asarray(self.net_on_boundary, bool)
        out[:len(on_net)] |= on_net
        return out

    def corner_counts(self) -> np.ndarray:
        """(p,) int, corners of each panel: net vertices and ends of the extended lines
        (points of the trim outline between them are not corners)."""
        return np.array([int(self.corner[p].sum()) for p in self.polygons], dtype=np.int64)

    def record(self) -> dict:
        """JSON-ready summary."""
        full = self.panel_size ** 2
        own = self.area[~self.extension]
        return {
            "count": self.panel_count,
            "extensions": np.flatnonzero(self.extension).tolist(),
            "coverage_net": self.coverage_net,
            "coverage": self.coverage,
            "area_relative_to_panel": None if not self.panel_count else {
                "min": float(own.min() / full), "max": float(own.max() / full),
                "mean": float(own.mean() / full)},
            "corners": {str(k): int(c) for k, c in
                        enumerate(np.bincount(self.corner_counts()[~self.extension])) if c},
            "outline_points_max": max((len(p) for p in self.polygons), default=0),
            "flipped": self.flipped.tolist(),
            "crossed": np.asarray(self.crossed, np.int64).tolist(),
            "boundary_distance_max_relative_to_panel": self.boundary_distance_max,
            "patches": np.flatnonzero(self.patch).tolist(),
            # the points on the design's boundary curve: the new ones and the net's vertices
            "on_design_boundary": np.flatnonzero(self.on_design_boundary).tolist(),
            "uncovered": 1.0 - self.coverage,
            "gaps": self.gaps,
            # a net optimized off its design: its boundary panels stand off it with it
            "follow_net": self.follows_net,
            "offset_from_design_max_relative_to_panel": self.offset_max / self.panel_size,
            **self.soundness,
            "seconds": round(self.seconds, 4),
        }

    def obj_text(self, header: str = "") -> str:
        """OBJ text of the boundary panels: `vertices` (the net's first, numbered as in
        the net's OBJ) and one polygon face per panel."""
        from ..io.obj import format_obj

        return format_obj(self.vertices, self.polygons, header)


def read_boundary_panels(mesh: QuadMesh, path: str | os.PathLike,
                         record: dict | None = None) -> BoundaryPanels:
    """The boundary panels of `mesh` from the ``NET.boundary.obj`` a layout, an optimize or
    a study writes beside ``NET.obj``.

    The file holds the panels' outlines; what it does not hold is rebuilt: the face each
    panel continues (`BoundaryPanels.neighbour_face`, as `trim_to_design` chooses it), the
    panels' areas (of their outlines' fans), and their corners (net vertices, and points
    two polygons share: the ends of the extended lines; the points between are the trim
    outline's). `record` (``properties.boundary_panels`` of ``NET.json``) gives the
    slivers, the patches, the points on the design boundary and the coverage, where known;
    the panel size is taken as the net's mean edge.

    Raises
    ------
    InputError
        When the file does not continue `mesh`: fewer vertices than the net, or the net's
        vertices moved (the net was changed after its boundary panels were cut); or when
        a panel runs along a side of the net or of another panel the same way (they
        overlap), naming the panel by its face in the file.
    """
    from ..io.obj import read_obj

    vertices, polygons = read_obj(path)
    n = mesh.vertex_count
    scale = max(float(np.ptp(mesh.vertices, axis=0).max()), 1e-300)
    if len(vertices) < n or not np.allclose(vertices[:n], mesh.vertices, atol=1e-6 * scale):
        raise InputError(f"{path}: its first {n} vertices are not the net's {mesh.name} "
                         "(boundary panels of another net, or of the net before it was "
                         "changed?); cut them again or use --no-boundary")
    polygons = [np.asarray(q, np.int64) for q in polygons]
    # the net's own faces are no boundary panels (the net given as its own boundary file)
    faces = {tuple(sorted(f.tolist())) for f in mesh.faces}
    own = [k for k, q in enumerate(polygons) if tuple(sorted(q.tolist())) in faces]
    if own:
        raise InputError(f"{path}: face {own[0] + 1} is a face of the net {mesh.name}, not a "
                         "boundary panel (the net itself given as its boundary file?); give "
                         "NET.boundary.obj or use --no-boundary")
    vertices = np.asarray(vertices, float)
    # a panel on a side of the net or of another panel the same way folds over it: named
    # by its face in the file (numbered from 1, as in the OBJ), not in a combined mesh
    clash = edge_clashes(list(mesh.faces) + polygons, len(vertices))
    if len(clash):
        a, b = (int(k) for k in clash[0])
        f = len(mesh.face_sizes)
        other = f"face {a + 1} of the net {mesh.name}" if a < f else f"face {a - f + 1}"
        raise InputError(f"{path}: face {b - f + 1} (boundary panel {b - f}) runs along a side "
                         f"of {other} the same way (the two overlap): cut the boundary panels "
                         "again with fabplan, or use --no-boundary")
    record = record or {}
    p = len(polygons)
    flags = {key: np.isin(np.arange(p), np.asarray(record.get(key, []), np.int64))
             for key in ("extensions", "patches")}
    on = np.zeros(len(vertices), bool)
    on[[i for i in record.get("on_design_boundary", []) if 0 <= i < len(vertices)]] = True
    on_boundary, net_on_boundary = on.copy(), on[:n].copy()
    on_boundary[:n] = False
    ids = np.concatenate(polygons) if p else np.zeros(0, np.int64)
    owner = np.repeat(np.arange(p), [len(q) for q in polygons])
    nxt = np.concatenate([np.roll(q, -1) for q in polygons]) if p else ids
    newell = np.zeros((p, 3))
    np.add.at(newell, owner, 0.5 * np.cross(vertices[ids], vertices[nxt]))
    shared = np.bincount(np.r_[ids, mesh.face_indices], minlength=len(vertices))
    corner = (np.arange(len(vertices)) < n) | (shared >= 2)
    coverage = record.get("coverage", math.nan)
    return BoundaryPanels(
        vertices=vertices, polygons=polygons, net_vertex_count=n,
        on_boundary=on_boundary, corner=corner,
        neighbour_face=neighbour_faces(polygons, mesh, vertices),
        area=np.linalg.norm(newell, axis=1), panel_size=mesh.mean_edge_length,
        coverage_net=record.get("coverage_net", math.nan), coverage=coverage,
        patch=flags["patches"], extension=flags["extensions"], net_on_boundary=net_on_boundary,
        flipped=_ids(record.get("flipped"), p), crossed=_ids(record.get("crossed"), p),
        gaps=list(record.get("gaps") or []),
        soundness={key: record[key] for key in ("off_design", "crossings") if key in record})


def _ids(values, count: int) -> np.ndarray:
    """The panel ids of a record's list that exist among `count` panels (int array)."""
    ids = np.asarray(values or [], np.int64)
    return ids[(ids >= 0) & (ids < count)]


def slide_splits(panels: BoundaryPanels, ids: np.ndarray, origins: np.ndarray,
                 directions: np.ndarray, *, reach: float
                 ) -> tuple[BoundaryPanels, np.ndarray]:
    """Where two boundary panels part on the design boundary, moved along it onto given
    lines: the point ``ids[i]``, the end on the design boundary of a side two panels share,
    slides along the boundary to where the line through ``origins[i]`` along
    ``directions[i]`` passes closest to it, and is put on that line; the boundary's points
    it passes go over from one panel to the other.

    The point slides between the two panels' next corners on the boundary (points of the
    net, or shared with another panel; it stays where it is where the line passes
    closest at or beyond one of them, leaving a panel without a rim), and only where the
    line passes within `reach` of the boundary. Points shared by more than two panels
    stay too. What it does depends only on what ``NET.boundary.obj`` and its record hold
    (`read_boundary_panels`), so that panels read back slide as they did when cut. The
    panels changed are cut into triangles again and their areas measured again.

    Parameters
    ----------
    panels : `BoundaryPanels`.
    ids : (k,) int, points of ``panels.vertices`` on the design boundary.
    origins, directions : (k, 3) float, the lines (model units; any length but zero).
    reach : how far from the boundary a line may pass (model units); points within a
        hundredth of it of a moved point are dropped (no side of no length).

    Returns
    -------
    panels : a copy of `panels` with the points moved.
    moved : (k,) bool, the points of `ids` that moved.

    Examples
    --------
    Two panels on the boundary ``y = 0`` between the net's vertices 0, 1 and 2, parting at
    the point 3 (``x = 1``), moved onto ``x = 1.4`` and ``x = 1.7``, past the point 4:

    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [2, 0, 0], [1, 1, 0], [1, 0, 0], [1.5, 0, 0]])
    >>> polygons = [np.array([0, 3, 2]), np.array([3, 4, 1, 2])]
    >>> on = np.array([True, True, False, True, True])
    >>> panels = BoundaryPanels(V, polygons, 3, on, ~on, np.zeros(2, int), np.ones(2), 1.0,
    ...                         1.0, 1.0)
    >>> up = np.array([[0.0, 1, 0]])
    >>> moved, ok = slide_splits(panels, np.array([3]), np.array([[1.4, 1, 0]]), up, reach=0.1)
    >>> ok.tolist(), moved.vertices[3].tolist(), [q.tolist() for q in moved.polygons]
    ([True], [1.4, 0.0, 0.0], [[0, 3, 2], [3, 4, 1, 2]])
    >>> moved, ok = slide_splits(panels, np.array([3]), np.array([[1.7, 1, 0]]), up, reach=0.1)
    >>> moved.vertices[3].tolist(), [q.tolist() for q in moved.polygons]
    ([1.7, 0.0, 0.0], [[0, 4, 3, 2], [3, 1, 2]])
    """
    ids = np.asarray(ids, np.int64)
    moved = np.zeros(len(ids), bool)
    polygons = [np.asarray(q, np.int64).copy() for q in panels.polygons]
    if not len(ids) or not polygons:
        return panels, moved
    V = np.array(panels.vertices, dtype=np.float64)
    on = panels.on_design_boundary
    d = np.asarray(directions, float)
    d = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    # the panels holding each point (a point moves only its two panels' outlines; which
    # panels hold it never changes, nor which points are corners)
    flat = np.concatenate(polygons)
    owner = np.repeat(np.arange(len(polygons)), [len(q) for q in polygons])
    corner = np.bincount(flat, minlength=len(V)) >= 2
    corner[:panels.net_vertex_count] = True
    changed: set = set()
    for i, r in enumerate(ids):
        holders = np.unique(owner[flat == r])
        if len(holders) != 2 or not on[r]:
            continue
        pair = _slide_point(V, polygons, holders, r, on, corner, origins[i], d[i], reach)
        if pair is not None:
            moved[i] = True
            changed.update(pair)
    if not changed:
        return panels, moved
    return _remeasured(panels, V, polygons, np.array(sorted(changed), np.int64)), moved


def _slide_point(V: np.ndarray, polygons: list, holders: np.ndarray, r: int, on: np.ndarray,
                 corner: np.ndarray, origin: np.ndarray, direction: np.ndarray, reach: float
                 ) -> tuple[int, int] | None:
    """Slide the point `r` the two panels `holders` part at along the design boundary
    to where the line through `origin` (3,) along the unit `direction` (3,) passes
    closest to it (`slide_splits`), changing `V` (m, 3) and the two outlines of
    `polygons` in place; the two panels, or None where it stays."""
    ends = _rim_chains(polygons, holders, r, on, corner)
    if ends is None:
        return None
    (fwd, at_f, chain_f), (bwd, at_b, chain_b) = ends
    C = np.r_[chain_b[::-1], chain_f]               # corner .. corner, through r
    if len(C) < 2:
        return None
    S0, E = V[C[:-1]], V[C[1:]] - V[C[:-1]]
    # the line's closest approach to every segment of the boundary between the corners
    w = origin - S0
    b, c = E @ direction, np.sum(E * E, axis=1)
    denom = np.maximum(c - b * b, 1e-300)
    u = np.clip((np.sum(E * w, axis=1) - b * (w @ direction)) / denom, 0.0, 1.0)
    s = u * b - w @ direction
    gap = np.linalg.norm(origin + s[:, None] * direction - S0 - u[:, None] * E, axis=1)
    j = int(np.argmin(gap))
    foot = S0[j] + u[j] * E[j]
    eps = 1e-2 * reach
    if (gap[j] > reach or np.linalg.norm(foot - V[C[0]]) <= eps
            or np.linalg.norm(foot - V[C[-1]]) <= eps):
        return None
    # points within a thousandth of a panel of the new place go (no side of no length)
    length = np.sqrt(c[j])
    keep_b = C[:j + 1] if (u[j] * length > eps or j == 0) else C[:j]
    keep_f = C[j + 1:] if ((1 - u[j]) * length > eps or j + 1 == len(C) - 1) else C[j + 2:]
    for k, ring in ((bwd, np.r_[np.roll(polygons[bwd], -at_b)[:len(polygons[bwd]) - len(chain_b)],
                                keep_b]),
                    (fwd, np.r_[r, keep_f, np.roll(polygons[fwd], -at_f)[1 + len(chain_f):]])):
        # each outline starts where it did, where that point is still in it
        start = np.flatnonzero(ring == polygons[k][0])
        polygons[k] = np.roll(ring, -int(start[0])) if len(start) else ring
    V[r] = origin + s[j] * direction
    return int(fwd), int(bwd)


def _remeasured(panels: BoundaryPanels, V: np.ndarray, polygons: list, which: np.ndarray
                ) -> BoundaryPanels:
    """A copy of `panels` with the points `V` (m, 3) and outlines `polygons`, the panels
    `which` (k,) int cut into triangles again and their areas measured again."""
    triangles, triangle_panel = panels.triangles, panels.triangle_panel
    if triangles is not None and triangle_panel is not None:
        triangles, triangle_panel = retriangulated(V, polygons, np.asarray(triangles, np.int64),
                                                   np.asarray(triangle_panel, np.int64), which)
    out = replace(panels, vertices=V, polygons=polygons, triangles=triangles,
                  triangle_panel=triangle_panel)
    T, panel = out.panel_triangles()
    P = V[T]
    area = np.bincount(panel, 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]),
                                                   axis=1), minlength=len(polygons))
    out.area = np.where(np.isin(np.arange(len(polygons)), which), area, panels.area)
    return out


def _rim_chains(polygons: list, holders: np.ndarray, r: int, on: np.ndarray,
                corner: np.ndarray) -> tuple | None:
    """The two panels `holders` parting at the boundary point `r`: for the one whose
    shared side runs towards `r` and then the other, ``(panel, index of r, chain)``, the
    chain being its points along the boundary from `r` (excluded) to its next corner
    (included), or to its last point before the outline leaves the boundary, forwards and
    backwards; None where the two do not share a side at `r`."""
    a, b = (int(k) for k in holders)
    qa, qb = polygons[a], polygons[b]
    ia, ib = int(np.flatnonzero(qa == r)[0]), int(np.flatnonzero(qb == r)[0])
    if qa[ia - 1] == qb[(ib + 1) % len(qb)]:
        fwd, at_f, bwd, at_b = a, ia, b, ib
    elif qb[ib - 1] == qa[(ia + 1) % len(qa)]:
        fwd, at_f, bwd, at_b = b, ib, a, ia
    else:
        return None
    chains = []
    for panel, at, step in ((fwd, at_f, 1), (bwd, at_b, -1)):
        q = polygons[panel]
        chain = []
        for k in range(1, len(q) - 1):
            p = q[(at + step * k) % len(q)]
            if not (on[p] or corner[p]):
                # the outline leaves the boundary: its last point there ends the chain
                break
            chain.append(p)
            if corner[p]:
                break
        else:
            return None
        if not chain:
            return None
        chains.append((panel, at, np.array(chain, np.int64)))
    return tuple(chains)


def neighbour_faces(polygons: list, mesh: QuadMesh, vertices: np.ndarray) -> np.ndarray:
    """(p,) int, the net face sharing a side (two consecutive net vertices) with each
    panel, the longest such side deciding; a piece touching no full panel along a side (a
    corner cell, a sliver) continues the face whose centre is nearest its own."""
    out = _side_faces(polygons, mesh)
    lone = np.flatnonzero(out < 0)
    if lone.size:
        centre = np.array([vertices[polygons[k]].mean(axis=0) for k in lone])
        face_centre = np.stack([np.bincount(mesh.corner_faces,
                                            mesh.vertices[mesh.face_indices, k]) for k in range(3)],
                               axis=1) / mesh.face_sizes[:, None]
        out[lone] = cKDTree(face_centre).query(centre)[1]
    return out


def _side_faces(polygons: list, mesh: QuadMesh) -> np.ndarray:
    """(p,) int, the net face sharing a side (two consecutive net vertices) with each
    panel, the longest such side deciding; -1 where none."""
    out = np.full(len(polygons), -1)
    if not polygons:
        return out
    n = mesh.vertex_count
    face, vert, nxt = mesh.corner_faces, mesh.face_indices, mesh.corner_next_vertices
    a = np.concatenate(polygons)
    b = np.concatenate([np.roll(q, -1) for q in polygons])
    panel = np.repeat(np.arange(len(polygons)), [len(q) for q in polygons])
    net_side = (a < n) & (b < n)
    a, b, panel = a[net_side], b[net_side], panel[net_side]
    # the panel runs along the face's half-edge the other way
    key = vert * n + nxt
    order = np.argsort(key)
    at = np.clip(np.searchsorted(key[order], b * n + a), 0, len(key) - 1)
    found = key[order][at] == b * n + a
    a, b, panel, corner = a[found], b[found], panel[found], order[at[found]]
    if not len(panel):              # no panel runs along a net side (all meet at corners)
        return out
    length = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1)
    best = np.lexsort((-length, panel))
    first = best[np.r_[True, panel[best][1:] != panel[best][:-1]]]
    out[panel[first]] = face[corner[first]]
    return out
