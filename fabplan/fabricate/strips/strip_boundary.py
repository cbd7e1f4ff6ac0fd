"""Lamellas to the design boundary: the net's lines continued through its boundary panels.

A layout's boundary panels (`fabplan.layout.trim`) are cut by the net's lines continued
straight in the layout's parameters until they meet the design boundary: a continued
line runs along panel sides from the net's last vertex, through the panel corners where it
crosses other continued lines, to a corner on the boundary. `StripBoundary.extend` follows
every strip end the same way, along the panel side that continues it most straightly
(turning less than `MAX_TURN_DEG` at a corner, through the panels' own corners only),
until it reaches the edge of the cladding. There the lamella ends against a *boundary
member* standing on the surface along the edge. Both contain the surface normal, so they
meet along it and the lamella's end is cut square (along its ruling), set back from the
edge so that both of its faces stay clear of the member (`member_setback_mm`).

The edge of the cladding is where the polygons (the net's faces and the panels) do not
close around a point: their corner angles there sum to about 180 degrees, not 360. The
panels' rings come from overlays in the layout's parameter plane, so a point may lie on
another polygon's side without being its corner (a T-junction), and two points may map to
one place; both are allowed for (`WELD`, `T_JUNCTION`).

Normals at the new nodes are the mean of the panels' (Newell) normals at each corner, each
panel turned to the side of the net's normals. Units: model units in 3D.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ...net.mesh import QuadMesh

__all__ = ["END_KINDS", "MAX_TURN_DEG", "MIN_MEMBER_ANGLE_DEG", "StripBoundary", "StripEnds",
           "member_setback_mm", "tip_setback_mm"]

MAX_TURN_DEG = 35.0
"""Largest turn of a continued line at a boundary panel corner (a crossing line turns by
the net's angle, far more)."""

MIN_MEMBER_ANGLE_DEG = 15.0
"""A lamella meeting the cladding's edge at a smaller angle runs along it: its end is free,
not cut against a boundary member (it would be cut back without end)."""

EDGE_ANGLE_SUM_DEG = 300.0
"""Polygons whose corner angles at a point sum to less than this leave it on the edge."""

WELD = 1e-3
"""Points closer than this share of the net's mean edge are one place."""

T_JUNCTION = 2e-3
"""A point this close (a share of the net's mean edge) to the inside of another polygon's
side lies on it."""

HAIR = 0.25
"""A strip end this close to the edge (a share of its last edge) through one panel side
that does not continue it ends at the edge: its straight continuation reaches it."""

EDGE_REACH = 1.5
"""The edge's direction at a point is taken from edge points within this many strip edges."""

END_KINDS = ("member", "along edge", "not continued", "inside", "closed")
"""Why a strip end is where it is (`StripEnds.kind`); all but ``member`` are free ends."""

MAX_STEPS = 64
"""Most panel corners a continued line passes (a few in practice: the boundary strip is a
panel or two wide)."""


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class StripEnds:
    """Where the strips' polylines end after `StripBoundary.extend`.

    Attributes
    ----------
    vertices : list of (k,) int arrays, the polylines with their continuations (into
        `StripBoundary.vertices`).
    at_edge : (p, 2) bool, whether the first / last node lies on the edge of the cladding
        (the lamella ends at a boundary member there).
    angle_deg : (p, 2) float, angle between the lamella's end edge and the cladding edge
        in the tangent plane at `at_edge` ends (NaN elsewhere). An end meeting the edge at
        less than `MIN_MEMBER_ANGLE_DEG` runs along it and stays free.
    added : (p, 2) int, nodes added before the first / after the last net node.
    reach : (p, 2) float, model units: at an end that stops a hair short of the edge (a
        panel side no longer than `HAIR` of its last edge joins it to the edge, across the
        strip), how far the strip's straight continuation runs on to the edge; else 0.
    along_edge : (p,) bool, polylines whose nodes all lie on the edge: the boundary member
        takes their place.
    kind : (p, 2) str, why each end is where it is (`END_KINDS`): ``member`` (at the edge,
        against the boundary member), ``along edge`` (meets the edge at less than
        `MIN_MEMBER_ANGLE_DEG`, or the polyline lies along it), ``not continued`` (on the
        net's boundary, but no panel side goes on straight to the edge), ``inside`` (inside
        the net: a line stopping at an irregular vertex), ``closed`` (a loop).
    """

    vertices: list
    at_edge: np.ndarray
    angle_deg: np.ndarray
    added: np.ndarray
    reach: np.ndarray
    along_edge: np.ndarray
    kind: np.ndarray

    @property
    def not_continued(self) -> int:
        """Open ends on the net's boundary that no panel side continues to the edge."""
        return int((self.kind == "not continued").sum())

    def subset(self, keep: np.ndarray) -> "StripEnds":
        """The ends of the polylines `keep` (k,) int only."""
        return StripEnds(vertices=[self.vertices[k] for k in keep], at_edge=self.at_edge[keep],
                         angle_deg=self.angle_deg[keep], added=self.added[keep],
                         reach=self.reach[keep], along_edge=self.along_edge[keep],
                         kind=self.kind[keep])


@dataclass(frozen=True)
class _Rings:
    """Polygons as one table of corners (the net's faces first, then the panels)."""

    corner: np.ndarray      # (c,) int, point of each corner
    owner: np.ndarray       # (c,) int, its polygon
    after: np.ndarray       # (c,) int, the next corner of its polygon
    before: np.ndarray      # (c,) int, the previous corner
    normal: np.ndarray      # (p, 3) float, Newell normal of each polygon (area-weighted)


def _rings(polygons: list) -> _Rings:
    sizes = np.array([len(p) for p in polygons], dtype=np.int64)
    ptr = np.r_[0, np.cumsum(sizes)]
    owner = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(ptr[-1]) - ptr[owner]
    after = np.where(local == sizes[owner] - 1, ptr[owner], np.arange(ptr[-1]) + 1)
    before = np.where(local == 0, ptr[owner] + sizes[owner] - 1, np.arange(ptr[-1]) - 1)
    corner = np.concatenate(polygons).astype(np.int64) if len(polygons) else np.zeros(0, np.int64)
    return _Rings(corner=corner, owner=owner, after=after, before=before,
                  normal=np.zeros((len(sizes), 3)))


@dataclass(frozen=True)
class StripBoundary:
    """A net's boundary panels, as the strips see them.

    Attributes
    ----------
    mesh : the net.
    vertices : (m, 3) float, the net's vertices (first ``mesh.vertex_count`` rows) and the
        panels' new corners and outline points.
    polygons : list of (k,) int arrays into `vertices`, one per boundary panel.
    on_design_boundary : (m,) bool, the points the trimming put on the design's boundary
        curve, or None where unknown (`on_edge`).
    """

    mesh: QuadMesh
    vertices: np.ndarray
    polygons: list
    on_design_boundary: np.ndarray | None = None

    @classmethod
    def from_panels(cls, mesh: QuadMesh, panels) -> "StripBoundary":
        """From a `fabplan.layout.trim.BoundaryPanels` of `mesh`."""
        on = np.asarray(panels.on_design_boundary, bool)
        return cls(mesh=mesh, vertices=np.asarray(panels.vertices, float),
                   polygons=[np.asarray(p, np.int64) for p in panels.polygons],
                   on_design_boundary=on if on.any() else None)

    @classmethod
    def from_obj(cls, mesh: QuadMesh, path, record: dict | None = None) -> "StripBoundary":
        """From the ``NET.boundary.obj`` a layout or study writes beside ``NET.obj``, with
        the ``properties.boundary_panels`` `record` of its ``NET.json`` where known.

        Raises
        ------
        InputError
            When the file does not continue `mesh` (`fabplan.layout.trim.read_boundary_panels`).
        """
        from ...layout.boundary_panels import read_boundary_panels

        return cls.from_panels(mesh, read_boundary_panels(mesh, path, record))

    # ------------------------------------------------------------------ topology
    @cached_property
    def _all(self) -> _Rings:
        """The net's faces and the panels as one corner table, with Newell normals."""
        rings = _rings(list(self.mesh.faces) + self.polygons)
        X = self.vertices
        normal = np.zeros_like(rings.normal)
        np.add.at(normal, rings.owner, 0.5 * np.cross(X[rings.corner], X[rings.corner[rings.after]]))
        return _Rings(rings.corner, rings.owner, rings.after, rings.before, normal)

    @cached_property
    def _panel_sides(self) -> sp.csr_matrix:
        """(m, m) adjacency of the panels' sides, both directions."""
        m = len(self.vertices)
        if not self.polygons:
            return sp.csr_matrix((m, m))
        a = np.concatenate(self.polygons)
        b = np.concatenate([np.roll(p, -1) for p in self.polygons])
        A = sp.csr_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])), shape=(m, m))
        A.sum_duplicates()
        return A

    @cached_property
    def _welded(self) -> np.ndarray:
        """(m,) int, one label per place: points closer than `WELD` of the net's mean edge
        (a panel corner that maps onto a net vertex or onto another corner) share it."""
        X = self.vertices
        pairs = cKDTree(X).query_pairs(WELD * self.mesh.mean_edge_length, output_type="ndarray")
        graph = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                              shape=(len(X), len(X)))
        return connected_components(graph, directed=False)[1]

    @cached_property
    def on_edge(self) -> np.ndarray:
        """(m,) bool, points on the edge of the cladding (see the module's text): the corner
        angles of the polygons at a place, each signed about its polygon's normal (a reflex
        corner counts more than 180 degrees), and a straight angle for every other
        polygon's side through it (`_t_junctions`), sum to less than `EDGE_ANGLE_SUM_DEG`;
        and the point is one the trimming put on the design boundary (`on_design_boundary`)
        or, where that is unknown, has two such places next to it along sides."""
        X, label, r = self.vertices, self._welded, self._all
        # corners whose side to the previous corner has no length (two points of one
        # place) are left out; the polygon's angle at that place is the kept corner's
        keep = label[r.corner] != label[r.corner[r.before]]
        # the nearest kept corner after / before each kept one, along its ring
        after, before = r.after.copy(), r.before.copy()
        for _ in range(int(np.bincount(r.owner).max(initial=0))):
            moved = ~keep[after]
            if not moved.any():
                break
            after = np.where(moved, r.after[after], after)
        for _ in range(int(np.bincount(r.owner).max(initial=0))):
            moved = ~keep[before]
            if not moved.any():
                break
            before = np.where(moved, r.before[before], before)
        c = np.flatnonzero(keep)
        e1 = X[r.corner[after[c]]] - X[r.corner[c]]
        e2 = X[r.corner[before[c]]] - X[r.corner[c]]
        n = _unit(r.normal[r.owner[c]])
        angle = np.arctan2(np.einsum("ij,ij->i", np.cross(e1, e2), n), np.einsum("ij,ij->i", e1, e2))
        angle = np.where(angle < 0, angle + 2 * math.pi, angle)
        places = int(label.max()) + 1
        total = np.bincount(label[r.corner[c]], angle, minlength=places)
        np.add.at(total, label[self._t_junctions], math.pi)
        used = np.bincount(label[r.corner[c]], minlength=places) > 0
        edge = used & (total < math.radians(EDGE_ANGLE_SUM_DEG))
        # else the edge is a chain of sides: a place with fewer than two edge places next to
        # it along sides is a notch of one panel inside the cladding (two corners of one
        # overlay a hair apart), not a point of the edge
        if self.on_design_boundary is not None:
            # where the trimming says which points it put on the design's boundary curve,
            # the edge is those (a gap the trimming left inside is no edge for a member)
            on = np.zeros(places, bool)
            on[label[self.on_design_boundary]] = True
            return (edge & on)[label]
        sides = self._place_sides
        p, q = sides.nonzero()
        along = np.bincount(p[edge[p] & edge[q]], minlength=places)
        return (edge & (along >= 2))[label]

    @cached_property
    def _place_sides(self) -> sp.csr_matrix:
        """(places, places) adjacency of the places (`_welded`) joined by a polygon side."""
        label, r = self._welded, self._all
        places = int(label.max()) + 1
        a, b = label[r.corner], label[r.corner[r.after]]
        keep = a != b
        A = sp.csr_matrix((np.ones(2 * keep.sum()), (np.r_[a[keep], b[keep]], np.r_[b[keep], a[keep]])),
                          shape=(places, places))
        A.sum_duplicates()
        return A

    @cached_property
    def _t_junctions(self) -> np.ndarray:
        """(k,) int, points inside a side of another polygon (a panel's, or a boundary side
        of the net's: the net itself has none) within `T_JUNCTION`: one entry per side
        through the point. Points of the side's own polygon or of the places of its ends
        are not."""
        X, label, r = self.vertices, self._welded, self._all
        n_faces = len(self.mesh.face_sizes)
        a, b = r.corner, r.corner[r.after]
        net_boundary = np.zeros(len(a), bool)
        if n_faces:
            twin = np.zeros(len(a), bool)
            face_corners = r.owner < n_faces
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            key = lo * len(X) + hi
            fk = key[face_corners]
            _, inverse, count = np.unique(fk, return_inverse=True, return_counts=True)
            twin[face_corners] = count[inverse] > 1
            net_boundary = face_corners & ~twin
        side = np.flatnonzero((r.owner >= n_faces) | net_boundary)
        if side.size == 0:
            return np.zeros(0, np.int64)
        A, B = X[a[side]], X[b[side]]
        length = np.linalg.norm(B - A, axis=1)
        near = T_JUNCTION * self.mesh.mean_edge_length
        hits = cKDTree(X).query_ball_point(0.5 * (A + B), 0.5 * length + near)
        count = np.array([len(h) for h in hits])
        s = np.repeat(np.arange(len(side)), count)
        p = np.concatenate([np.asarray(h, np.int64) for h in hits]) if count.sum() else np.zeros(0, np.int64)
        d = B[s] - A[s]
        t = np.einsum("ij,ij->i", X[p] - A[s], d) / length[s] ** 2
        off = np.linalg.norm(X[p] - A[s] - t[:, None] * d, axis=1)
        inside = (t > 0) & (t < 1) & (off < near)
        inside &= (label[p] != label[a[side[s]]]) & (label[p] != label[b[side[s]]])
        # not a corner of the side's own polygon
        idx = np.flatnonzero(inside)
        if idx.size:
            corners_of = sp.csr_matrix((np.ones(len(r.corner)), (r.owner, r.corner)),
                                       shape=(len(r.normal), len(X)))
            own = np.asarray(corners_of[r.owner[side[s[idx]]], p[idx]]).ravel() > 0
            inside[idx[own]] = False
        return p[inside]

    def normals(self, net_normals: np.ndarray) -> np.ndarray:
        """(m, 3) unit normals: `net_normals` (n, 3) at the net's vertices, the mean of the
        panels' Newell normals at the others, each panel turned to the side of the net's
        normal at its nearest net vertex (panels without area left out)."""
        X, n = self.vertices, self.mesh.vertex_count
        N = np.zeros_like(X)
        N[:n] = net_normals
        if not self.polygons or len(X) == n:
            return N
        panels = _rings(self.polygons)
        normal = np.zeros((len(self.polygons), 3))
        np.add.at(normal, panels.owner, np.cross(X[panels.corner], X[panels.corner[panels.after]]))
        centre = np.stack([np.bincount(panels.owner, X[panels.corner, k]) for k in range(3)], 1) \
            / np.bincount(panels.owner)[:, None]
        nearest = cKDTree(X[:n]).query(centre)[1]
        normal *= np.where(np.einsum("ij,ij->i", normal, net_normals[nearest]) < 0, -1.0, 1.0)[:, None]
        size = np.linalg.norm(normal, axis=1)
        normal = np.where(size[:, None] > 1e-12 * self.mesh.mean_edge_length ** 2,
                          normal / np.maximum(size, 1e-300)[:, None], 0.0)
        at = np.zeros_like(X)
        np.add.at(at, panels.corner, normal[panels.owner])
        new = _unit(at[n:])
        # a point only degenerate panels reach takes the nearest net vertex's normal
        lone = ~np.isfinite(new).all(axis=1)
        if lone.any():
            new[lone] = net_normals[cKDTree(X[:n]).query(X[n:][lone])[1]]
        N[n:] = new
        return N

    # ------------------------------------------------------------------ continuation
    def _continue(self, start: int, before: int) -> tuple[list[int], bool]:
        """The nodes after `start` (coming from `before`) to the edge, and whether the
        edge was reached."""
        X, sides, n = self.vertices, self._panel_sides, self.mesh.vertex_count
        path: list[int] = []
        cur, prev = start, before
        limit = math.cos(math.radians(MAX_TURN_DEG))
        for _ in range(MAX_STEPS):
            if self.on_edge[cur]:
                return path, True
            nb = sides.indices[sides.indptr[cur]:sides.indptr[cur + 1]]
            # a continued line crosses the panels through their own corners: never along
            # the net, never onto a vertex of the net (another line's end)
            nb = nb[(nb != prev) & (nb >= n)]
            if nb.size == 0:
                return path, False
            straight = _unit(X[nb] - X[cur]) @ _unit(X[cur] - X[prev])
            best = int(np.argmax(straight))
            if straight[best] < limit:
                return path, False
            path.append(int(nb[best]))
            prev, cur = cur, int(nb[best])
        return path, False

    def _hair_point(self, end: int, before: int) -> int:
        """The edge point nearest `end` through a panel side within `HAIR` of the last
        edge, or -1."""
        X, sides = self.vertices, self._panel_sides
        nb = sides.indices[sides.indptr[end]:sides.indptr[end + 1]]
        gap = np.linalg.norm(X[nb] - X[end], axis=1)
        ok = self.on_edge[nb] & (gap <= HAIR * float(np.linalg.norm(X[end] - X[before])))
        return int(nb[ok][np.argmin(gap[ok])]) if ok.any() else -1

    def _surface_normal(self, q: int, hint: np.ndarray) -> np.ndarray:
        """(3,) unit normal at point `q`: the mean of the unit Newell normals of the
        polygons with a corner at its place, turned to the side of `hint` (at a corner of
        the net, the polygons there, not a node normal averaged over a ring)."""
        r, label = self._all, self._welded
        at = label[r.corner] == label[q]
        normal = _unit(r.normal[r.owner[at]])
        normal = normal[np.isfinite(normal).all(axis=1)]
        if normal.size == 0:
            return hint
        normal *= np.where(normal @ hint < 0, -1.0, 1.0)[:, None]
        mean = _unit(normal.sum(axis=0))
        return mean if np.isfinite(mean).all() else hint

    def _edge_tangent(self, q: int, radius: float) -> np.ndarray | None:
        """(3,) the cladding edge's direction at its point `q`: from the nearest edge point
        to the nearest one on the other side of `q` (or to `q`), within `radius` or joined to
        `q` by a polygon side, points of `q`'s own place left out (None when `q` has no edge
        point near)."""
        X, label = self.vertices, self._welded
        edge = np.flatnonzero(self.on_edge & (label != label[q]))
        d = X[edge] - X[q]
        dist = np.linalg.norm(d, axis=1)
        # edge points near, and the edge places a side joins to q's (a long panel side)
        sides = self._place_sides
        joined = sides.indices[sides.indptr[label[q]]:sides.indptr[label[q] + 1]]
        ok = (dist <= radius) | np.isin(label[edge], joined)
        if not ok.any():
            return None
        edge, d, dist = edge[ok], d[ok], dist[ok]
        first = int(np.argmin(dist))
        other = np.flatnonzero(d @ d[first] < 0)
        if other.size == 0:
            return d[first]
        second = other[np.argmin(dist[other])]
        return X[edge[second]] - X[edge[first]]

    def _edge_angle(self, q: int, direction: np.ndarray, normal: np.ndarray) -> float:
        """Angle (degrees) between a strip running along `direction` and the cladding edge
        at its point `q` (from edge points within `EDGE_REACH` strip edges), in the tangent
        plane of `normal`."""
        t_edge = self._edge_tangent(q, EDGE_REACH * float(np.linalg.norm(direction)))
        if t_edge is None:
            return 90.0
        t_edge = t_edge - (t_edge @ normal) * normal
        t_strip = direction - (direction @ normal) * normal
        s = abs(float(np.cross(_unit(t_strip), _unit(t_edge)) @ normal))
        return math.degrees(math.asin(min(1.0, s)))

    def _reach(self, end: int, before: int, q: int, normal: np.ndarray) -> float:
        """How far the straight continuation of the strip's last edge runs, in the tangent
        plane, to the edge of the cladding at its point `q` next to `end` (0 when the
        continuation misses it)."""
        X = self.vertices
        last = float(np.linalg.norm(X[end] - X[before]))
        t_edge = self._edge_tangent(q, EDGE_REACH * last)
        if t_edge is None:
            return 0.0
        flat = np.eye(3) - np.outer(normal, normal)
        d = _unit(flat @ (X[end] - X[before]))
        t = _unit(flat @ t_edge)
        # end + r d = q + s t in the tangent plane
        (r, _), *_ = np.linalg.lstsq(np.column_stack([d, -t]), flat @ (X[q] - X[end]), rcond=None)
        return float(r) if 0.0 <= r <= 2 * HAIR * last else 0.0

    def extend(self, polylines: list, closed: np.ndarray, normals: np.ndarray) -> StripEnds:
        """Continue every open polyline that ends on the net's boundary to the edge of the
        cladding (see the module's text).

        Parameters
        ----------
        polylines : list of (k,) int arrays of net vertices.
        closed : (p,) bool, closed loops (never continued).
        normals : (m, 3) float, unit normals (`normals`).
        """
        X = self.vertices
        boundary = self.mesh.is_boundary_vertex
        out, at_edge, angle, added, reach, along, kinds = [], [], [], [], [], [], []
        for v, loop in zip(polylines, closed, strict=True):
            v = np.asarray(v, np.int64)
            ends: list[list[int]] = [[], []]
            reached = [False, False]
            angles = [math.nan, math.nan]
            beyond = [0.0, 0.0]
            flat_along = len(v) >= 2 and bool(self.on_edge[v].all())
            kind = ["closed"] * 2 if loop else ["along edge"] * 2 if flat_along else ["inside"] * 2
            if not loop and len(v) >= 2 and not flat_along:
                for side, (end, before) in enumerate(((int(v[0]), int(v[1])), (int(v[-1]), int(v[-2])))):
                    if not boundary[end]:
                        continue
                    path, reached[side] = self._continue(end, before)
                    chain = [before, end] + path
                    q = chain[-1]
                    normal = self._surface_normal(q, normals[q])
                    if not reached[side] and not path:
                        q = self._hair_point(end, before)
                        if q >= 0:
                            normal = self._surface_normal(q, normals[end])
                            beyond[side] = self._reach(end, before, q, normal)
                            reached[side] = beyond[side] > 0
                    if not reached[side]:
                        kind[side] = "not continued"
                        continue
                    angles[side] = self._edge_angle(q, X[chain[-1]] - X[chain[-2]], normal)
                    if angles[side] < MIN_MEMBER_ANGLE_DEG:       # along the edge: no member
                        reached[side], angles[side], beyond[side] = False, math.nan, 0.0
                        kind[side] = "along edge"
                        continue
                    ends[side] = path
                    kind[side] = "member"
            out.append(np.r_[np.array(ends[0][::-1], np.int64), v, np.array(ends[1], np.int64)])
            at_edge.append(reached)
            angle.append(angles)
            added.append([len(ends[0]), len(ends[1])])
            reach.append(beyond)
            along.append(flat_along)
            kinds.append(kind)
        return StripEnds(vertices=out, at_edge=np.array(at_edge, bool).reshape(-1, 2),
                         angle_deg=np.array(angle, float).reshape(-1, 2),
                         added=np.array(added, np.int64).reshape(-1, 2),
                         reach=np.array(reach, float).reshape(-1, 2),
                         along_edge=np.array(along, bool),
                         kind=np.array(kinds, dtype=object).reshape(-1, 2))


def member_setback_mm(member_mm: float, thickness_mm: float, angle_deg: float) -> float:
    """How far a lamella `thickness_mm` thick ends short of the cladding edge at a boundary
    member `member_mm` thick meeting it at `angle_deg`, so that its square end clears the
    member's face with both of its own faces (mm): ``(m / 2) / sin a + (t / 2) / tan a``.

    Examples
    --------
    >>> round(member_setback_mm(20.0, 6.0, 90.0), 9)
    10.0
    """
    a = math.radians(max(angle_deg, MIN_MEMBER_ANGLE_DEG))
    return 0.5 * member_mm / math.sin(a) + 0.5 * thickness_mm / math.tan(a)


def tip_setback_mm(thickness_mm: float, angle_deg: float) -> float:
    """How far two lamellas `thickness_mm` thick that end at one point, meeting at
    `angle_deg`, must each stop short of it to clear each other (mm):
    ``(t / 2) / tan(angle / 2)``."""
    return 0.5 * thickness_mm / math.tan(math.radians(max(angle_deg, 1.0)) / 2)
