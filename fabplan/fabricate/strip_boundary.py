"""Lamellas to the design boundary: the net's lines continued through its boundary panels.

A layout's boundary panels (`fabplan.layout.trim`) are cut by the net's lines continued
straight in the layout's parameters until they meet the design boundary: a continued
line runs along panel sides from the net's last vertex, through the corners where it
crosses other continued lines, to a corner on the boundary. `StripBoundary.extend`
follows every strip end the same way, along the panel side that continues it most
straightly (turning less than `MAX_TURN_DEG` at a corner), until it reaches the edge of the
cladding, where the lamella ends at a *boundary member*: a member standing on the surface
along the edge. Both contain the surface normal there, so they meet along it and the
lamella's end is cut square (along its ruling), set back from the edge by half the
member's thickness over the sine of the angle between lamella and edge.

Normals at the new nodes are the boundary panels' (Newell) normals averaged at each
corner, on the side of the net's normals. Units: model units in 3D.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from ..net.mesh import QuadMesh

__all__ = ["MAX_TURN_DEG", "MIN_MEMBER_ANGLE_DEG", "StripBoundary", "StripEnds",
           "member_setback_mm"]

MAX_TURN_DEG = 35.0
"""Largest turn of a continued line at a boundary panel corner (a crossing line turns by
the net's angle, far more)."""

EDGE_ANGLE_SUM_DEG = 300.0
"""Polygons whose corner angles at a point sum to less than this leave it on the edge."""

WELD = 1e-3
"""Points closer than this share of the net's mean edge are one place."""

HAIR = 0.25
"""A strip end this close to the edge (a share of its last edge) through one panel side
that does not continue it ends at the edge: its straight continuation reaches it."""

MIN_MEMBER_ANGLE_DEG = 15.0
"""A lamella meeting the cladding's edge at a smaller angle runs along it: its end is free,
not cut against a boundary member (it would be cut back without end)."""


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
    not_continued : number of open strip ends on the net's boundary that no panel side
        continues to the edge, or that would meet it at less than `MIN_MEMBER_ANGLE_DEG`
        after running through the panels (they keep their free end).
    """

    vertices: list
    at_edge: np.ndarray
    angle_deg: np.ndarray
    added: np.ndarray
    reach: np.ndarray
    not_continued: int


@dataclass(frozen=True)
class StripBoundary:
    """A net's boundary panels, as the strips see them.

    Attributes
    ----------
    mesh : the net.
    vertices : (m, 3) float, the net's vertices (first ``mesh.vertex_count`` rows) and the
        panels' new corners and outline points.
    polygons : list of (k,) int arrays into `vertices`, one per boundary panel.
    """

    mesh: QuadMesh
    vertices: np.ndarray
    polygons: list

    @classmethod
    def from_panels(cls, mesh: QuadMesh, panels) -> "StripBoundary":
        """From a `fabplan.layout.trim.BoundaryPanels` of `mesh`."""
        return cls(mesh=mesh, vertices=np.asarray(panels.vertices, float),
                   polygons=[np.asarray(p, np.int64) for p in panels.polygons])

    @classmethod
    def from_obj(cls, mesh: QuadMesh, path) -> "StripBoundary":
        """From the ``NET.boundary.obj`` a layout or study writes beside ``NET.obj``.

        Raises
        ------
        InputError
            When the file does not continue `mesh`: fewer vertices than the net, or the
            net's vertices moved.
        """
        from ..io.obj import read_obj

        vertices, polygons = read_obj(path)
        n = mesh.vertex_count
        scale = max(float(np.ptp(mesh.vertices, axis=0).max()), 1e-300)
        if len(vertices) < n or not np.allclose(vertices[:n], mesh.vertices, atol=1e-6 * scale):
            raise InputError(f"{path}: its first {n} vertices are not the net's {mesh.name} "
                             "(boundary panels of another net?)")
        return cls(mesh=mesh, vertices=np.asarray(vertices, float),
                   polygons=[np.asarray(p, np.int64) for p in polygons])

    # ------------------------------------------------------------------ topology
    @cached_property
    def _sides(self) -> sp.csr_matrix:
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
    def _net_edges(self) -> sp.csr_matrix:
        """(m, m) adjacency of the net's edges."""
        m = len(self.vertices)
        e = self.mesh.edges
        return sp.csr_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                             shape=(m, m))

    def _net_edge(self, a: int, b: np.ndarray) -> np.ndarray:
        """(k,) bool, whether (a, b_i) is an edge of the net."""
        row = self._net_edges.indices[self._net_edges.indptr[a]:self._net_edges.indptr[a + 1]]
        return np.isin(b, row)

    @cached_property
    def _welded(self) -> np.ndarray:
        """(m,) int, one label per place: points closer than `WELD` of the net's mean edge
        (a panel corner that maps onto a net vertex or onto another corner) share it."""
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree

        X = self.vertices
        pairs = cKDTree(X).query_pairs(WELD * self.mesh.mean_edge_length, output_type="ndarray")
        graph = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                              shape=(len(X), len(X)))
        return connected_components(graph, directed=False)[1]

    @cached_property
    def on_edge(self) -> np.ndarray:
        """(m,) bool, points on the edge of the cladding: where the polygons around a point
        (the net's faces and the panels) do not close around it. Their corner angles at the
        point sum to about 360 degrees inside and to about 180 on the edge; a point on a side
        of another polygon that does not have it as a corner (a T-junction: a line crossing
        the side noded one ring and not the other) has that side straight through it.
        Points at one place (`_welded`) count as one."""
        X, label = self.vertices, self._welded
        rings = []
        for p in list(self.mesh.faces) + self.polygons:
            lab = label[p]
            keep = lab != np.roll(lab, 1)           # a side between two points of one place
            if keep.sum() >= 3:
                rings.append(np.asarray(p)[keep])
        at = np.concatenate(rings)
        before = np.concatenate([np.roll(p, 1) for p in rings])
        after = np.concatenate([np.roll(p, -1) for p in rings])
        u, w = _unit(X[before] - X[at]), _unit(X[after] - X[at])
        corner = np.arccos(np.clip(np.einsum("ij,ij->i", u, w), -1.0, 1.0))
        places = int(label.max()) + 1
        total = np.bincount(label[at], corner, minlength=places)
        np.add.at(total, label[self._on_sides], math.pi)
        used = np.bincount(label[at], minlength=places) > 0
        return (used & (total < math.radians(EDGE_ANGLE_SUM_DEG)))[label]

    @cached_property
    def _on_sides(self) -> np.ndarray:
        """(k,) int, points that lie on a side of a polygon (the net's or a panel's) that
        does not have them as a corner, within 1 % of its length: T-junctions, one entry per
        side through the point."""
        from scipy.spatial import cKDTree

        X = self.vertices
        polygons = list(self.mesh.faces) + self.polygons
        a_id = np.concatenate(polygons)
        b_id = np.concatenate([np.roll(p, -1) for p in polygons])
        a, b = X[a_id], X[b_id]
        length = np.linalg.norm(b - a, axis=1)
        found = []
        for k, hits in enumerate(cKDTree(X).query_ball_point(0.5 * (a + b), 0.51 * length)):
            if len(hits) > 2:                         # a few points each, the ends among them
                h = np.asarray(hits)
                q = X[h]
                t = (q - a[k]) @ (b[k] - a[k]) / length[k] ** 2
                off = np.linalg.norm(q - a[k] - t[:, None] * (b[k] - a[k]), axis=1)
                found.append(h[(t > 0.01) & (t < 0.99) & (off < 0.01 * length[k])])
        return np.concatenate(found) if found else np.zeros(0, np.int64)

    def normals(self, net_normals: np.ndarray) -> np.ndarray:
        """(m, 3) unit normals: `net_normals` (n, 3) at the net's vertices, the mean of the
        panels' Newell normals at the others, turned to the side of the net's normals."""
        X, n = self.vertices, self.mesh.vertex_count
        N = np.zeros_like(X)
        N[:n] = net_normals
        if not self.polygons:
            return N
        sizes = np.array([len(p) for p in self.polygons])
        a = np.concatenate(self.polygons)
        b = np.concatenate([np.roll(p, -1) for p in self.polygons])
        panel = np.repeat(np.arange(len(sizes)), sizes)
        newell = np.zeros((len(sizes), 3))
        np.add.at(newell, panel, np.cross(X[a], X[b]))
        at = np.zeros_like(X)
        np.add.at(at, a, newell[panel])
        new = _unit(at[n:])
        # the panels' orientation against the net's, where they share a vertex
        shared = a < n
        side = np.sum(newell[panel[shared]] * net_normals[a[shared]])
        N[n:] = -new if side < 0 else new
        return N

    # ------------------------------------------------------------------ continuation
    def _continue(self, start: int, before: int) -> tuple[list[int], bool]:
        """The nodes after `start` (coming from `before`) to the edge, and whether the
        edge was reached."""
        X, sides = self.vertices, self._sides
        path: list[int] = []
        cur, prev = start, before
        limit = math.cos(math.radians(MAX_TURN_DEG))
        for _ in range(64):
            if self.on_edge[cur]:
                return path, True
            nb = sides.indices[sides.indptr[cur]:sides.indptr[cur + 1]]
            # a continued line crosses the panels, never runs along an edge of the net
            nb = nb[(nb != prev) & ~self._net_edge(cur, nb)]
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
        X, sides = self.vertices, self._sides
        nb = sides.indices[sides.indptr[end]:sides.indptr[end + 1]]
        gap = np.linalg.norm(X[nb] - X[end], axis=1)
        ok = self.on_edge[nb] & (gap <= HAIR * float(np.linalg.norm(X[end] - X[before])))
        return int(nb[ok][np.argmin(gap[ok])]) if ok.any() else -1

    def _edge_tangent(self, q: int, radius: float) -> np.ndarray | None:
        """(3,) the cladding edge's direction at its point `q`: from the nearest edge point
        to the nearest one on the other side of `q` (or to `q`), within `radius` (None when
        `q` has no edge point near)."""
        X = self.vertices
        edge = np.flatnonzero(self.on_edge)
        d = X[edge] - X[q]
        dist = np.linalg.norm(d, axis=1)
        ok = (dist > 1e-9 * radius) & (dist <= radius)
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
        at its point `q` (from edge points within 1.5 strip edges), in the tangent plane of
        `normal`."""
        t_edge = self._edge_tangent(q, 1.5 * float(np.linalg.norm(direction)))
        if t_edge is None:
            return 90.0
        t_edge = t_edge - (t_edge @ normal) * normal
        t_strip = direction - (direction @ normal) * normal
        s = abs(float(np.cross(_unit(t_strip), _unit(t_edge)) @ normal))
        return math.degrees(math.asin(min(1.0, s)))

    def _reach(self, end: int, before: int, normal: np.ndarray) -> float:
        """How far the straight continuation of the strip's last edge runs, in the tangent
        plane, to the edge of the cladding next to `end` (0 when no edge point is within
        `HAIR` of the last edge through a panel side, or the continuation misses it)."""
        X = self.vertices
        q = self._hair_point(end, before)
        t_edge = None if q < 0 else self._edge_tangent(q, 1.5 * float(np.linalg.norm(X[end] - X[before])))
        if t_edge is None:
            return 0.0
        flat = np.eye(3) - np.outer(normal, normal)
        d = _unit(flat @ (X[end] - X[before]))
        t = _unit(flat @ t_edge)
        # end + r d = q + s t in the tangent plane
        (r, _), *_ = np.linalg.lstsq(np.column_stack([d, -t]), flat @ (X[q] - X[end]), rcond=None)
        last = float(np.linalg.norm(X[end] - X[before]))
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
        mesh = self.mesh
        boundary = mesh.is_boundary_vertex
        out, at_edge, angle, added, reach = [], [], [], [], []
        missed = 0
        for v, loop in zip(polylines, closed, strict=True):
            v = np.asarray(v, np.int64)
            ends: list[list[int]] = [[], []]
            reached = [False, False]
            angles = [math.nan, math.nan]
            beyond = [0.0, 0.0]
            if not loop and len(v) >= 2:
                for side, (end, before) in enumerate(((v[0], v[1]), (v[-1], v[-2]))):
                    if not boundary[end]:
                        continue
                    path, reached[side] = self._continue(int(end), int(before))
                    if not reached[side] and not path:
                        beyond[side] = self._reach(int(end), int(before), normals[end])
                        reached[side] = beyond[side] > 0
                    if not reached[side]:
                        missed += 1
                        continue
                    chain = [int(before), int(end)] + path
                    q = self._hair_point(int(end), int(before)) if beyond[side] > 0 else chain[-1]
                    angles[side] = self._edge_angle(q, self.vertices[chain[-1]] - self.vertices[chain[-2]],
                                                    normals[chain[-1]])
                    if angles[side] < MIN_MEMBER_ANGLE_DEG:       # along the edge: no member
                        reached[side], angles[side], beyond[side] = False, math.nan, 0.0
                        if path:
                            missed += 1
                        continue
                    ends[side] = path
            out.append(np.r_[np.array(ends[0][::-1], np.int64), v, np.array(ends[1], np.int64)])
            at_edge.append(reached)
            angle.append(angles)
            added.append([len(ends[0]), len(ends[1])])
            reach.append(beyond)
        return StripEnds(vertices=out, at_edge=np.array(at_edge, bool).reshape(-1, 2),
                         angle_deg=np.array(angle, float).reshape(-1, 2),
                         added=np.array(added, np.int64).reshape(-1, 2),
                         reach=np.array(reach, float).reshape(-1, 2), not_continued=missed)


def member_setback_mm(member_mm: float, angle_deg: float) -> float:
    """How far a lamella ends short of the cladding edge at a boundary member `member_mm`
    thick meeting it at `angle_deg` (mm): half the member over the sine of the angle."""
    return 0.5 * member_mm / math.sin(math.radians(max(angle_deg, MIN_MEMBER_ANGLE_DEG)))
