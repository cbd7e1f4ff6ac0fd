"""Circular arc structures of S-nets (paper, Sec. 3.7 and Fig. 21).

Every edge ``(v, w)`` of an S-net is replaced by an arc of the circle in which the
Meusnier spheres of ``v`` and ``w`` meet: both spheres pass through both vertices (each
sphere holds its star), so the circle does too, and all arcs at ``v`` lie on the sphere
of ``v``: they touch its tangent plane there (a circular arc structure in the sense of
Bo et al. 2011).

How the arcs are computed. A circle through ``v`` and ``w`` is tangent at ``v`` to a
plane ``P_v`` and at ``w`` to a plane ``P_w`` exactly when its tangent at ``v`` lies in
``P_v`` and in the mirror image of ``P_w`` in the bisecting plane of the edge; that
tangent is the cross product of the two normals. With ``P_v`` the tangent plane of the
sphere of ``v`` at ``v`` this is the sphere-intersection circle, but it passes through
both vertices exactly and every arc at a vertex touches its plane exactly even when the
net is an S-net only up to its sphere residual; the remaining sphere residual shows as
the arcs' distance from the spheres (`sphere_deviation`), reported.

Vertices without a sphere of their own (boundary vertices, and irregular vertices, which
have no regular star) use the neighbouring spheres. An edge from a regular vertex ``w``
to such a vertex ``v`` becomes the circle through ``v``, ``w`` and the vertex beyond
``w`` on their parameter line: a circle of the sphere of ``w``, so it touches the plane of
``w``. The plane of ``v`` holds the tangents of these arcs: exactly for two of them
(boundary vertices of valence 4, where two lines end), by a best fit for more (irregular
vertices of valence 5 and up, whose defect the report shows). A vertex with one such arc
(a boundary vertex of valence 3) lies on the sphere of that arc's regular end: its plane
turns about the arc's tangent to the nearest to that sphere's tangent plane. The
vertices with none (the net's corners) get their planes ring by ring from the vertices
with a plane: the arc of an edge from a vertex with a plane is the circle tangent to that
plane in the plane of the chord and its normal (the flattest one), and the new vertex's
plane holds the arcs arriving. An edge between two vertices whose planes were chosen
apart (along the boundary) is the flattest circle tangent to the mean of its two planes
(one mirrored): the circle tangent to both would turn on their small mismatch into up to
a half circle (149 degrees on a boundary edge of a 0.9 m hypar net), while this one
misses each plane by half the mismatch, reported as the vertices' tangent-plane defect.
`plane_source` says which vertex got its plane how; a net without any
regular vertex falls back on face normals.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import FabplanError, InputError
from ..io.output import atomic_path
from ..io.records import json_text
from ..io.rhino_write import FAMILY_NAMES, MM_PER_UNIT, RHINO_UNITS, Rhino3dmWriter
from ..net.geometry import StarSpheres, circumcircle_tangent, fit_star_spheres
from ..net.mesh import QuadMesh
from .limits import DEFAULT_MAX_ARC_ANGLE_DEG, LimitCheck, limit_check, limits_record

__all__ = ["ArcStructure", "PLANE_SOURCES", "MIRROR_TOLERANCE", "arc_structure", "arc_limit_checks",
           "write_arcs_3dm", "write_arcs_dxf", "write_arcs"]

PLANE_SOURCES = ("own sphere", "arcs on neighbouring spheres", "a neighbouring sphere",
                 "arcs from neighbours with a plane", "faces")
"""Where a vertex's tangent plane comes from (`ArcStructure.plane_source` indexes this)."""

MIRROR_TOLERANCE = 1e-5
"""Sine of the angle below which an edge's two tangent planes count as mirror images: the
spheres of its ends meet in a circle too badly determined to take (on a sphere sampled to
0.0004 mm, 508 of 760 such circles turned more than 90 degrees), and the parameter line's
circle, which misses the plane of one end by at most this, is taken instead."""


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass
class ArcStructure:
    """The arcs replacing the edges of a net, with their measurements.

    Every arc runs counter-clockwise about `axis` from its edge's first vertex to its
    second; a straight arc (both planes containing the chord) has infinite radius.

    Attributes
    ----------
    mesh : the net.
    edges : (e, 2) int, vertex ids, as `QuadMesh.edges`.
    family : (e,) int, 0 or 1 (family A, B), -1 for edges of no quad.
    tangent : (e, 3) float, unit tangent at the first vertex, into the arc.
    end_tangent : (e, 3) float, unit tangent at the second vertex, along the arc.
    centre : (e, 3) float, circle centre (NaN for a straight arc).
    axis : (e, 3) float, unit normal of the arc's plane (NaN for a straight arc).
    radius : (e,) float, model units (inf for a straight arc).
    angle : (e,) float, the arc's central angle (radians).
    sagitta : (e,) float, largest distance between the arc and its chord (model units).
    sphere_deviation : (e,) float, distance of the arc's midpoint from the spheres of its
        end vertices that have one (NaN if neither does): the net's departure from an
        S-net, seen on the arcs.
    normal : (n, 3) float, unit normal of every vertex's tangent plane.
    plane_source : (n,) int, index into `PLANE_SOURCES`.
    tangent_defect : (n,) float, largest angle (radians) between an arc's tangent at the
        vertex and the vertex's tangent plane (NaN at isolated vertices).
    """

    mesh: QuadMesh
    edges: np.ndarray
    family: np.ndarray
    tangent: np.ndarray
    end_tangent: np.ndarray
    centre: np.ndarray
    axis: np.ndarray
    radius: np.ndarray
    angle: np.ndarray
    sagitta: np.ndarray
    sphere_deviation: np.ndarray
    normal: np.ndarray
    plane_source: np.ndarray
    tangent_defect: np.ndarray

    @property
    def straight(self) -> np.ndarray:
        """(e,) bool, arcs that are straight segments."""
        return ~np.isfinite(self.radius)

    def points(self, t: np.ndarray | float) -> np.ndarray:
        """(e, 3) points of every arc at fraction `t` (0 start, 1 end) of its angle."""
        X = self.mesh.vertices
        a, b = X[self.edges[:, 0]], X[self.edges[:, 1]]
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), self.radius.shape)
        phi = (t * self.angle)[:, None]
        start = a - self.centre
        # from the start point, not the centre: a centre a radius of 1e8 edges away would
        # lose the arc's points to rounding (1 - cos phi = 2 sin^2(phi / 2) keeps them)
        curved = (a - 2 * np.sin(phi / 2) ** 2 * start
                  + np.sin(phi) * np.cross(self.axis, start))
        return np.where(self.straight[:, None], a + t[:, None] * (b - a), curved)

    def summary(self) -> dict:
        """The measured numbers (model units, degrees), for the JSON report and the terminal."""
        edge = self.mesh.mean_edge_length
        X = self.mesh.vertices
        gap = np.maximum(np.linalg.norm(self.points(0.0) - X[self.edges[:, 0]], axis=1),
                         np.linalg.norm(self.points(1.0) - X[self.edges[:, 1]], axis=1))
        curved = ~self.straight
        radius = self.radius[curved]
        defect = self.tangent_defect[np.isfinite(self.tangent_defect)]
        sources = np.bincount(self.plane_source, minlength=len(PLANE_SOURCES))
        deviation = self.sphere_deviation[np.isfinite(self.sphere_deviation)]

        def stats(values: np.ndarray, scale: float = 1.0) -> dict:
            if values.size == 0:
                return {"min": None, "max": None, "mean": None}
            return {"min": float(values.min() * scale), "max": float(values.max() * scale),
                    "mean": float(values.mean() * scale)}

        return {
            "arcs": len(self.edges),
            "straight_arcs": int(np.sum(self.straight)),
            "mean_edge": edge,
            "radius": stats(radius),
            "angle_deg": stats(self.angle, 180 / math.pi),
            "arc_chord_deviation": stats(self.sagitta),
            "end_vertex_gap_relative_to_edge": float(gap.max() / edge),
            "tangent_plane_defect_deg": stats(defect, 180 / math.pi),
            "sphere_deviation_relative_to_edge": stats(deviation, 1 / edge),
            "plane_sources": {name: int(c) for name, c in zip(PLANE_SOURCES, sources, strict=True)},
            "method": "an edge between two regular vertices is the circle where their spheres "
                      "meet (through both vertices, tangent to both spheres' planes); an edge "
                      "from a regular vertex to a boundary or irregular one is the circle of "
                      "its parameter line through the regular vertex's neighbours, on that "
                      "vertex's sphere; a boundary or irregular vertex's plane holds the "
                      "tangents of its arcs (see plane_sources); an edge between two "
                      "vertices without a sphere is the flattest circle tangent to the mean "
                      "of their planes, which are fitted to these circles in turn",
        }

    def to_json(self) -> dict:
        """The report: summary, one record per arc and the defect of every vertex."""
        return {
            "schema": "fabplan-arcs/1",
            "net": str(self.mesh.name),
            "summary": self.summary(),
            "arcs": [{"edge": i, "vertices": [int(a), int(b)],
                      "family": FAMILY_NAMES[f] if f in (0, 1) else None,
                      "radius": float(r), "angle_deg": math.degrees(float(t)),
                      "arc_chord_deviation": float(s)}
                     for i, ((a, b), f, r, t, s) in enumerate(zip(
                         self.edges.tolist(), self.family.tolist(), self.radius, self.angle,
                         self.sagitta, strict=True))],
            "vertices": [{"vertex": v, "plane_source": PLANE_SOURCES[s],
                          "tangent_defect_deg": math.degrees(float(d)),
                          "normal": [float(c) for c in X_n]}
                         for v, (s, d, X_n) in enumerate(zip(
                             self.plane_source.tolist(), self.tangent_defect, self.normal,
                             strict=True))],
        }


def _sphere_normals_at(points: np.ndarray, X: np.ndarray, coefficients: np.ndarray,
                       owners: np.ndarray) -> np.ndarray:
    """Unit normals at `points` of the spheres (rows of `coefficients`) of the stars
    centred at the vertices `owners` of `X`.

    The sphere ``a|x - v|^2 + b.(x - v) + c = 0`` (``b`` against the star normal) has the
    gradient ``2a(x - v) + b``; its negative, normalized, is the normal on the star
    normal's side, also for a plane (``a = 0``).
    """
    a, b = coefficients[:, 0], coefficients[:, 1:4]
    return _unit(-(2 * a[:, None] * (points - X[owners]) + b))


def _line_circle_tangents(mesh: QuadMesh, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(k, 3) unit tangent at ``v`` (towards ``w``, up to sign) of the circle through ``v``,
    the regular vertex ``w`` and the vertex beyond ``w`` on their parameter line: a circle
    of the sphere of ``w`` (all three vertices lie on it)."""
    X = mesh.vertices
    rows = mesh.stars[mesh.star_of_vertex[w]]
    k = np.argmax(rows[:, 1:] == v[:, None], axis=1)
    beyond = rows[np.arange(len(rows)), 1 + (k + 2) % 4]
    return _unit(circumcircle_tangent(X[v], X[w], X[beyond]))


def _tangent_plane_circles(X: np.ndarray, v: np.ndarray, w: np.ndarray,
                           normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangent at ``v`` of the circle through ``v`` and ``w`` tangent to the planes of
    both (its direction lies in the plane of ``v`` and in the mirror image of the plane of
    ``w`` in the edge's bisecting plane), and the sine of the angle between those two
    planes (small: the circle is badly determined)."""
    u = _unit(X[w] - X[v])
    nw = normal[w]
    mirrored = nw - 2 * np.sum(nw * u, axis=1, keepdims=True) * u
    tangent = np.cross(normal[v], mirrored)
    size = np.linalg.norm(tangent, axis=1)
    return tangent / np.maximum(size, 1e-300)[:, None], size


def _chord_in_plane(X: np.ndarray, v: np.ndarray, w: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Unit projection of the chord ``v -> w`` on the plane of ``v``."""
    u = _unit(X[w] - X[v])
    n = normal[v]
    return _unit(u - np.sum(u * n, axis=1, keepdims=True) * n)


def _planes_through(normal: np.ndarray, source: np.ndarray, vertex: np.ndarray,
                    tangents: np.ndarray, neighbour: np.ndarray, suggested: np.ndarray,
                    level: int) -> None:
    """Give each vertex of `vertex` (repeated once per arc) the plane holding its arcs'
    `tangents`: with one arc, the plane through it nearest to `suggested` (the normal its
    neighbour proposes); with two, their span; with more (irregular vertices), the best
    fit, whose defect the report shows."""
    order = np.lexsort((neighbour, vertex))
    vertex, tangents, suggested = vertex[order], tangents[order], suggested[order]
    vertices, first, counts = np.unique(vertex, return_index=True, return_counts=True)
    t, n = tangents[first], suggested[first]
    normal[vertices] = _unit(n - np.sum(n * t, axis=1, keepdims=True) * t)
    pair = counts == 2
    normal[vertices[pair]] = _unit(np.cross(t[pair], tangents[first[pair] + 1]))
    for v, start, count in zip(vertices[counts > 2], first[counts > 2], counts[counts > 2],
                               strict=True):
        normal[v] = np.linalg.svd(tangents[start:start + count])[2][-1]
    source[vertices] = level


def _circles_tangent_to_planes(mesh: QuadMesh, v: np.ndarray, w: np.ndarray,
                               normal: np.ndarray) -> np.ndarray:
    """Unit tangent at ``v`` of the circle through the regular vertices ``v`` and ``w``
    tangent to both planes: where their spheres meet.

    Where the planes are mirror images (two points of one sphere or plane), every circle
    through both that touches one touches the other: the parameter line's circle through
    the vertex beyond ``w`` is taken (a circle of the common sphere; a straight line on a
    plane).
    """
    t, sine = _tangent_plane_circles(mesh.vertices, v, w, normal)
    mirrored = sine < MIRROR_TOLERANCE
    t[mirrored] = _line_circle_tangents(mesh, v[mirrored], w[mirrored])
    return t


def _mean_plane_circles(X: np.ndarray, v: np.ndarray, w: np.ndarray,
                        normal: np.ndarray) -> np.ndarray:
    """(k, 3) unit tangent at ``v`` of the flattest circle through ``v`` and ``w`` tangent
    to the mean of the plane of ``v`` and the mirror image of the plane of ``w`` in the
    edge's bisecting plane: the chord projected on that mean plane.

    Where the two planes are mirror images this circle touches both (the flattest of the
    pencil that does); where they are not, the circle tangent to both exists, but its
    direction follows the planes' mismatch, however small, and can make a half circle of
    a short edge. This one misses each plane by about half the mismatch instead, which
    the vertices' tangent-plane defect reports.
    """
    u = _unit(X[w] - X[v])
    mirrored = _mirror(normal[w], u)
    mean = normal[v] + mirrored * np.where(np.sum(normal[v] * mirrored, axis=1) < 0, -1.0, 1.0)[:, None]
    mean = _unit(mean)
    return _unit(u - np.sum(u * mean, axis=1, keepdims=True) * mean)


def _mirror(vectors: np.ndarray, u: np.ndarray) -> np.ndarray:
    """`vectors` mirrored in the planes normal to the unit vectors `u`."""
    return vectors - 2 * np.sum(vectors * u, axis=1, keepdims=True) * u


def _edge_tangents(mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, StarSpheres]:
    """Tangent at the first vertex of every edge's arc, the vertex planes and their sources.

    Returns
    -------
    tangent : (e, 3) unit tangents at ``edges[:, 0]`` (sign not yet fixed).
    normal : (n, 3) unit normals of the vertex tangent planes.
    source : (n,) int, index into `PLANE_SOURCES`.
    spheres : the fitted `StarSpheres`.
    """
    X = mesh.vertices
    n = len(X)
    e = mesh.edges
    spheres = fit_star_spheres(X, mesh.stars)
    star_of = mesh.star_of_vertex
    regular = star_of >= 0
    normal = np.full((n, 3), np.nan)
    source = np.full(n, len(PLANE_SOURCES) - 1, dtype=np.int64)
    own = np.flatnonzero(regular)
    normal[own] = _sphere_normals_at(X[own], X, spheres.coefficients[star_of[own]], own)
    source[own] = 0
    tangent = np.full((len(e), 3), np.nan)

    # 1. both ends regular: the circle where the two spheres meet
    both = regular[e[:, 0]] & regular[e[:, 1]]
    tangent[both] = _circles_tangent_to_planes(mesh, e[both, 0], e[both, 1], normal)

    # 2. one end regular: the parameter line's circle through the edge, on that sphere
    one = regular[e[:, 0]] ^ regular[e[:, 1]]
    idx = np.flatnonzero(one)
    free = np.where(regular[e[idx, 0]], e[idx, 1], e[idx, 0])
    held = np.where(regular[e[idx, 0]], e[idx, 0], e[idx, 1])
    at_free = _line_circle_tangents(mesh, free, held)
    # at the regular end the tangent is the mirror image (the circle is symmetric about
    # the edge's bisecting plane)
    at_held = _mirror(at_free, _unit(X[held] - X[free]))
    tangent[idx] = np.where((e[idx, 0] == free)[:, None], at_free, at_held)
    decided = both | one
    suggestion = _sphere_normals_at(X[free], X, spheres.coefficients[star_of[held]], held)
    several = np.bincount(free, minlength=n)[free] >= 2
    _planes_through(normal, source, free[several], at_free[several], held[several],
                    suggestion[several], level=1)
    # a vertex with one such arc (a boundary vertex of valence 3) lies on the sphere of
    # that arc's regular end: its plane turns about the arc's tangent to the nearest to
    # that sphere's tangent plane (a choice of its own, so that no mismatch gathers along
    # the boundary from vertex to vertex)
    one = free[~several]
    t, m = at_free[~several], suggestion[~several]
    normal[one] = _unit(m - np.sum(m * t, axis=1, keepdims=True) * t)
    source[one] = 2

    # 3. the remaining vertices (corners), ring by ring from those with a plane: the arc of
    # an edge from a vertex with a plane is the circle tangent to that plane in the plane
    # of the chord and its normal (the flattest one), and the new vertex's plane holds the
    # arriving arcs (two exactly; one, the plane through it nearest the mirrored plane of
    # its neighbour)
    pairs = np.r_[e[:, ::-1], e]     # rows (open vertex, vertex with a plane)
    edge_of = np.r_[np.arange(len(e)), np.arange(len(e))]
    while True:
        open_ = np.isnan(normal[:, 0])
        keep = open_[pairs[:, 0]] & ~open_[pairs[:, 1]] & ~decided[edge_of]
        if not keep.any():
            break
        order = np.lexsort((pairs[keep, 1], pairs[keep, 0]))
        v_all, w_all, k_all = pairs[keep, 0][order], pairs[keep, 1][order], edge_of[keep][order]
        start = np.searchsorted(v_all, v_all)
        take = np.arange(len(v_all)) - start < 2
        v, w, k = v_all[take], w_all[take], k_all[take]
        u = _unit(X[v] - X[w])
        at_v = _mirror(_chord_in_plane(X, w, v, normal), u)
        decided[k] = True      # its arc is laid with the others in step 4
        first = np.searchsorted(v, v) == np.arange(len(v))
        second = np.r_[~first[1:], False]     # the first of a pair whose second follows
        suggested = _mirror(normal[w], u)
        plane = _unit(suggested - np.sum(suggested * at_v, axis=1, keepdims=True) * at_v)
        span = np.cross(np.roll(at_v, -1, axis=0), at_v)
        spans = second & (np.linalg.norm(span, axis=1) > 1e-6)
        plane[spans] = _unit(span[spans])
        v, plane = v[first], plane[first]
        normal[v] = plane
        source[v] = 3
    missing = np.flatnonzero(np.isnan(normal[:, 0]))
    if missing.size:   # a part of the net without any sphere: face normals
        tri = mesh.triangles()
        face_normal = np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])
        total = np.zeros((n, 3))
        for k in range(3):
            np.add.at(total, tri[:, k], face_normal)
        normal[missing] = _unit(total[missing])

    # 4. the edges between two vertices without a sphere: the flattest circles of their
    # mean planes, the planes of those vertices that are not held by two arcs relaxed to
    # the circles' tangents (the circle tangent to both planes would turn on their small
    # mismatch into up to a half circle)
    soft = ~regular[e[:, 0]] & ~regular[e[:, 1]]
    held_arcs = np.bincount(free, minlength=n)
    _relax_planes(X, e[soft], normal, held_arcs, one, at_free[~several])
    rest = np.flatnonzero(soft)
    tangent[rest] = _mean_plane_circles(X, e[rest, 0], e[rest, 1], normal)
    return tangent, normal, source, spheres


def _relax_planes(X: np.ndarray, edges: np.ndarray, normal: np.ndarray, held_arcs: np.ndarray,
                  one: np.ndarray, one_tangent: np.ndarray, *, rounds: int = 3000,
                  tolerance: float = 1e-10) -> None:
    """Turn the planes of the vertices at `edges` that fewer than two arcs on spheres hold
    to fit the flattest circles of the edges' mean planes (`_mean_plane_circles`), round
    by round, until no plane turns by more than `tolerance` (radians).

    Each plane is the least-squares plane of its arcs' tangents; one held by one arc
    (`one`, (k,) vertices, with that arc's tangent `one_tangent`, (k, 3)) keeps it and
    turns about it. The mismatch of the planes, which a circle tangent to both of an edge's
    planes would turn into a long arc, spreads over the boundary as small tangent-plane
    defects.

    Parameters
    ----------
    X : (n, 3) float, vertices.
    edges : (m, 2) int, the edges between vertices without a sphere.
    normal : (n, 3) float, unit plane normals, updated in place.
    held_arcs : (n,) int, arcs on spheres at each vertex.
    """
    if len(edges) == 0:
        return
    n = len(X)
    v, w = edges[:, 0], edges[:, 1]
    u = _unit(X[w] - X[v])
    relax = np.zeros(n, bool)
    relax[edges.ravel()] = True
    relax &= held_arcs < 2
    # a vertex whose arcs all run nearly in one line (a straight run of the boundary) has
    # a plane they leave free to turn about that line: it keeps the plane it has
    ends = np.r_[v, w]
    chords = np.r_[u, -u]
    spread = np.zeros((n, 3, 3))
    np.add.at(spread, ends, chords[:, :, None] * chords[:, None, :])
    spread[one] += one_tangent[:, :, None] * one_tangent[:, None, :]
    second = np.linalg.eigvalsh(spread)[:, 1] / np.maximum(np.trace(spread, axis1=1, axis2=2), 1e-300)
    relax &= second > np.sin(np.radians(30.0)) ** 2 / 2
    moving = np.flatnonzero(relax)
    if moving.size == 0:
        return
    axis = np.zeros((n, 3))
    axis[one] = one_tangent
    # projection onto the plane normal to the one arc's tangent (identity without one)
    pin = axis[moving, :, None] * axis[moving, None, :]
    project = np.eye(3) - pin
    slot = np.full(n, -1)
    slot[moving] = np.arange(len(moving))
    at_v, at_w = slot[v] >= 0, slot[w] >= 0       # the edge ends whose planes turn
    # the held arc's tangent pinned above every in-plane eigenvalue (the unit tangents
    # of the vertex's arcs add 1 each to the trace): never the normal
    arcs = np.bincount(np.r_[slot[v][at_v], slot[w][at_w]], minlength=len(moving))
    pin = pin * (2.0 + arcs)[:, None, None]
    for _ in range(rounds):
        t = _mean_plane_circles(X, v, w, normal)
        t_w = _mirror(t, u)
        scatter = np.zeros((len(moving), 3, 3))
        np.add.at(scatter, slot[v][at_v], t[at_v, :, None] * t[at_v, None, :])
        np.add.at(scatter, slot[w][at_w], t_w[at_w, :, None] * t_w[at_w, None, :])
        current = normal[moving]
        M = project @ scatter @ project + pin
        fitted = np.linalg.eigh(M)[1][:, :, 0]
        fitted *= np.where(np.sum(fitted * current, axis=1) < 0, -1.0, 1.0)[:, None]
        turn = np.linalg.norm(fitted - current, axis=1).max()
        normal[moving] = fitted
        if turn < tolerance:
            break


def _edge_families(mesh: QuadMesh) -> np.ndarray:
    """(e,) int family of every edge of `mesh.edges`, from the parameter polylines (-1 for
    edges on none)."""
    lines = mesh.polylines
    n = mesh.vertex_count
    pairs = [np.stack([ids[:-1], ids[1:]], axis=1) if not closed else
             np.stack([ids, np.roll(ids, -1)], axis=1)
             for ids, closed in zip(lines.vertices, lines.closed, strict=True)]
    family = np.full(len(mesh.edges), -1, dtype=np.int64)
    if not pairs:
        return family
    counts = [len(p) for p in pairs]
    pair = np.sort(np.concatenate(pairs), axis=1)
    keys = mesh.edges[:, 0] * n + mesh.edges[:, 1]
    family[np.searchsorted(keys, pair[:, 0] * n + pair[:, 1])] = np.repeat(lines.family, counts)
    return family


def arc_structure(mesh: QuadMesh) -> ArcStructure:
    """Replace every edge of a net by the arc in which its end vertices' spheres meet.

    Parameters
    ----------
    mesh : the net (quad-dominant; boundary and irregular vertices allowed).

    Returns
    -------
    ArcStructure

    Examples
    --------
    >>> import fabplan
    >>> arcs = arc_structure(fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj")))
    >>> bool(arcs.tangent_defect.max() < 1e-6), round(float(np.median(arcs.radius)), 1)
    (True, 20.1)
    """
    X = mesh.vertices
    e = mesh.edges
    if len(e) == 0:
        raise InputError(f"{mesh.name}: the net has no edges")
    tangent, normal, source, spheres = _edge_tangents(mesh)
    v, w = e[:, 0], e[:, 1]
    chord = X[w] - X[v]
    length = np.linalg.norm(chord, axis=1)
    u = chord / length[:, None]
    tangent = _unit(tangent)
    tangent *= np.where(np.sum(tangent * u, axis=1) < 0, -1.0, 1.0)[:, None]
    cos_half = np.clip(np.sum(tangent * u, axis=1), -1.0, 1.0)
    # from sine and cosine: arccos alone loses half the digits of a nearly straight arc's
    # angle, and its end then misses the vertex by up to an edge
    binormal = np.cross(tangent, u)
    half = np.arctan2(np.linalg.norm(binormal, axis=1), cos_half)
    straight = half < 1e-12
    with np.errstate(invalid="ignore", divide="ignore"):
        radius = np.where(straight, np.inf, length / (2 * np.sin(half)))
        # at right angles to the tangent to the last digit (u - cos * tangent is not, when
        # the arc is nearly straight)
        inward = _unit(np.cross(binormal, tangent))
        centre = np.where(straight[:, None], np.nan, X[v] + radius[:, None] * inward)
        axis = np.where(straight[:, None], np.nan, _unit(binormal))   # tangent x inward
        sagitta = np.where(straight, 0.0, 2 * radius * np.sin(half / 2) ** 2)
    angle = np.where(straight, 0.0, 2 * half)
    end_tangent = 2 * cos_half[:, None] * u - tangent
    # tangent-plane defect at each vertex: the arcs' tangents against its plane
    incidence = np.r_[v, w]
    sines = np.abs(np.sum(np.r_[tangent, end_tangent] * normal[incidence], axis=1))
    worst = np.zeros(len(X))
    np.maximum.at(worst, incidence, sines)
    defect = np.full(len(X), np.nan)
    touched = np.unique(incidence)
    defect[touched] = np.arcsin(np.clip(worst[touched], 0.0, 1.0))
    structure = ArcStructure(
        mesh=mesh, edges=e, family=_edge_families(mesh), tangent=tangent, end_tangent=end_tangent,
        centre=centre, axis=axis, radius=radius, angle=angle, sagitta=sagitta,
        sphere_deviation=np.full(len(e), np.nan), normal=normal, plane_source=source,
        tangent_defect=defect)
    structure.sphere_deviation = _sphere_deviation(structure, spheres)
    return structure


def _sphere_deviation(arcs: ArcStructure, spheres: StarSpheres) -> np.ndarray:
    """(e,) distance of every arc's midpoint from the spheres of its end vertices."""
    mid = arcs.points(0.5)
    X = arcs.mesh.vertices
    star_of = arcs.mesh.star_of_vertex
    coefficients = spheres.coefficients
    out = np.full(len(mid), np.nan)
    for end in (0, 1):
        v = arcs.edges[:, end]
        ok = star_of[v] >= 0
        a, b, c = (coefficients[star_of[v[ok]], 0], coefficients[star_of[v[ok]], 1:4],
                   coefficients[star_of[v[ok]], 4])
        d = mid[ok] - X[v[ok]]
        value = a * np.sum(d * d, axis=1) + np.sum(b * d, axis=1) + c
        gradient = np.linalg.norm(2 * a[:, None] * d + b, axis=1)
        # first-order distance f / |grad f|: exact for planes, accurate near the sphere
        distance = np.abs(value) / gradient
        out[ok] = np.fmax(out[ok], distance)
    return out


def write_arcs_3dm(arcs: ArcStructure, path: str | os.PathLike, *, units: str = "m") -> Path:
    """Write the arcs as ArcCurves (lines where straight) on layers ``arcs A``, ``arcs B``
    (and ``arcs other``), named ``edge <id>`` with user text ``edge``, ``vertices``,
    ``radius``, ``angle_deg``, in the net's own units."""
    doc = Rhino3dmWriter(units)
    for name, colour in (("arcs A", (200, 40, 40, 255)), ("arcs B", (40, 80, 200, 255))):
        doc.layer(name, colour)
    X = arcs.mesh.vertices
    middle = arcs.points(0.5)
    for k, ((v, w), family) in enumerate(zip(arcs.edges.tolist(), arcs.family.tolist(), strict=True)):
        letter = FAMILY_NAMES[family] if family in (0, 1) else "other"
        doc.add_arc(X[v], middle[k], X[w], layer=f"arcs {letter}", name=f"edge {k}",
                    straight=bool(arcs.straight[k]),
                    user_text={"edge": k, "vertices": f"{v} {w}", "radius": f"{arcs.radius[k]:.12g}",
                               "angle_deg": f"{math.degrees(arcs.angle[k]):.12g}"})
    return doc.write(path)


def write_arcs_dxf(arcs: ArcStructure, path: str | os.PathLike, *, units: str = "m") -> Path:
    """Write the arcs as DXF ARC entities in their own OCS (extrusion = the arc's axis;
    LINE where straight), in millimetres (``$INSUNITS = 4``), layers ``ARCS_A``,
    ``ARCS_B``, ``ARCS_OTHER``; the file is audited before it is moved into place.

    Raises
    ------
    InputError
        For unknown units; FabplanError when the audit finds an error.
    """
    import ezdxf
    from ezdxf.math import OCS

    if units not in MM_PER_UNIT:
        raise InputError(f"unknown units {units!r}: use " + ", ".join(MM_PER_UNIT))
    mm = MM_PER_UNIT[units]
    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 4
    msp = doc.modelspace()
    for name, colour in (("ARCS_A", 1), ("ARCS_B", 5), ("ARCS_OTHER", 8)):
        doc.layers.add(name, color=colour)
    X = arcs.mesh.vertices * mm
    centre = arcs.centre * mm
    start, end = X[arcs.edges[:, 0]], X[arcs.edges[:, 1]]
    for k, family in enumerate(arcs.family.tolist()):
        layer = ("ARCS_A", "ARCS_B")[family] if family in (0, 1) else "ARCS_OTHER"
        if arcs.straight[k]:
            msp.add_line(start[k], end[k], dxfattribs={"layer": layer})
            continue
        ocs = OCS(arcs.axis[k])
        c = ocs.from_wcs(centre[k])
        a = ocs.from_wcs(start[k]) - c
        b = ocs.from_wcs(end[k]) - c
        msp.add_arc(center=c, radius=float(arcs.radius[k] * mm),
                    start_angle=math.degrees(math.atan2(a.y, a.x)),
                    end_angle=math.degrees(math.atan2(b.y, b.x)),
                    dxfattribs={"layer": layer, "extrusion": tuple(arcs.axis[k])})
    path = Path(path)
    with atomic_path(path) as tmp:
        doc.saveas(tmp)
        written = ezdxf.readfile(tmp)
        auditor = written.audit()
        if auditor.has_errors:
            raise FabplanError(f"{path}: the DXF failed its audit: "
                               f"{auditor.errors[0].message if auditor.errors else ''}")
    return path


def arc_limit_checks(arcs: ArcStructure, *,
                     max_arc_angle_deg: float = DEFAULT_MAX_ARC_ANGLE_DEG) -> list[LimitCheck]:
    """The arcs measured against their fabrication limit (`fabplan.fabricate.limits`): the
    central angle of every arc (0 for a straight one) against `max_arc_angle_deg`.

    Returns
    -------
    list of one LimitCheck, ``max_arc_angle_deg`` over the arcs.
    """
    angle = np.degrees(arcs.angle)
    check = limit_check("max_arc_angle_deg", angle, max_arc_angle_deg, parts="arcs")
    if check.exceeded:
        k = int(np.nanargmax(angle))
        v, w = (int(i) for i in arcs.edges[k])
        middle = ", ".join(f"{c:.4g}" for c in arcs.points(0.5)[k])
        check = replace(check, where=f"edge {k} between vertices {v} and {w}, its middle at "
                                     f"({middle})")
    return [check]


def write_arcs(arcs: ArcStructure, path: str | os.PathLike, *, units: str = "m",
               limits: list[LimitCheck] | None = None) -> list[Path]:
    """Write the arcs to ``OUT.3dm`` or ``OUT.dxf`` and their report to ``OUT.json``: both,
    or neither. `limits` (`arc_limit_checks`) go into the report as ``limits``.

    Returns
    -------
    list of Path, the files written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".3dm", ".dxf"):
        raise InputError(f"{path}: arcs are written to a .3dm or a .dxf file")
    if units not in RHINO_UNITS:
        raise InputError(f"unknown units {units!r}: use " + ", ".join(RHINO_UNITS))
    report = path.with_suffix(".json")
    record = arcs.to_json()
    record["units"] = units if suffix == ".3dm" else "mm"
    record["model_units"] = units
    record["file"] = path.name
    record["limits"] = limits_record(limits or [])
    with atomic_path(path) as staged, atomic_path(report) as staged_report:
        write = write_arcs_3dm if suffix == ".3dm" else write_arcs_dxf
        write(arcs, staged, units=units)
        staged_report.write_text(json_text(record), encoding="utf-8")
    return [path, report]
