"""Lamellas along the parameter polylines of a net, unrolled into planar strips.

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

Cut geometry
------------
The developed polyline is the strip's *reference curve*: its mid-line, at the surface, so
the two long edges are the reference curve offset by ``h / 2`` to either side (radii
``r - h/2`` and ``r + h/2`` on a constant-radius net). Runs of nodes that lie on one circle
(or line) within the cutting tolerance are written as arcs of that circle through the
nodes; the rest as straight segments. Arc lengths ``s`` along the reference curve locate
the crossings and the slits. Units: model units in 3D, millimetres in the plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ..errors import InputError
from ..io.units import check_units
from ..net.geometry import circumcircle_tangent, face_normals, fit_star_spheres, star_normals
from ..net.mesh import Polylines, QuadMesh
from .limits import DEFAULT_MAX_TWIST_DEG_PER_M
from .molds import UNITS
from .strip_boundary import StripBoundary, StripEnds, member_setback_mm, tip_setback_mm

__all__ = [
    "StripSettings",
    "ReferenceCurve",
    "ArcRun",
    "Strip",
    "Crossing",
    "StripSet",
    "strip_polylines",
    "node_normals",
    "unroll_polylines",
    "fit_arc_runs",
    "build_strips",
]

CUTTING_TOLERANCE_MM = (0.001, 10.0)
"""Cutting tolerances that mean something for arcs fitted to the strip outlines (mm)."""

MAX_SHEET_MM = 20_000.0
"""The longest sheet side accepted (mm): beyond it the sizes are in the wrong unit."""

FAMILY_LETTERS = "AB"
_LAYER_KINDS = ("cut", "slit", "engrave")


@dataclass
class StripSettings:
    """Everything that shapes the lamella strips and their cutting files (millimetres).

    Attributes
    ----------
    height_mm : lamella height ``h``; the surface runs along its middle.
    thickness_mm : material thickness; a slit is this plus `clearance_mm` wide.
    clearance_mm : play added to the slit width so the strips slide together.
    units : model units of the net, ``"m"`` or ``"mm"``.
    tolerance_mm : cutting tolerance: nodes within it of one circle are cut as an arc.
    sheet_mm : (width, height) of a sheet.
    spacing_mm : smallest gap between two parts on a sheet.
    margin_mm : smallest gap between a part and the sheet edge.
    kerf_mm : width of the cut; outlines grow and slits shrink by half of it.
    end : ``"square"`` or ``"round"`` (semicircular) ends of a strip.
    end_extension_mm : material beyond the end nodes, along the strip (default ``h / 2``).
    splice : joint between two parts of a strip split to fit a sheet: ``"overlap"`` (both
        parts run full height over the splice length, to be bolted face to face) or
        ``"lap"`` (a half-height step lap in the plane of the strip).
    splice_length_mm : length of a splice (default ``2 h``).
    slit_overcut_mm : how far a slit's cut runs past the strip edge (the edge cut crosses
        the slit mouth cleanly).
    labels : ``"stroke"`` (single-stroke vector text, for engraving), ``"outline"`` (glyph
        outlines as closed polylines) or ``"text"`` (DXF TEXT entities).
    label_height_mm : height of strip labels (default ``0.12 h`` within 3-20 mm); crossing
        and splice labels are 3/4 of it.
    layers : kind (``"cut"``, ``"slit"``, ``"engrave"``) -> (layer name, ACI colour).
    one_file : all sheets side by side in one DXF instead of one file per sheet.
    join_boundary : continue polylines of one family through boundary vertices where
        exactly two of them end (the corners of a staircase boundary).
    boundary_member_mm : thickness of the boundary member a strip run to the edge of the
        cladding ends against (default: `thickness_mm`).
    max_twist_deg_per_m : the largest twist a strip may take (degrees per metre,
        `Strip.twist_deg_per_m`); a strip that twists more is counted against it
        (`fabplan.fabricate.limits`, ``docs/fabrication-limits.md``).
    """

    height_mm: float
    thickness_mm: float
    clearance_mm: float = 0.2
    units: str = "m"
    tolerance_mm: float = 0.1
    sheet_mm: tuple[float, float] = (2500.0, 1250.0)
    spacing_mm: float = 10.0
    margin_mm: float = 10.0
    kerf_mm: float = 0.0
    end: str = "square"
    end_extension_mm: float | None = None
    splice: str = "overlap"
    splice_length_mm: float | None = None
    slit_overcut_mm: float = 1.0
    labels: str = "stroke"
    label_height_mm: float | None = None
    layers: dict = field(default_factory=lambda: {
        "cut": ("CUT", 1), "slit": ("SLIT", 6), "engrave": ("ENGRAVE", 5)})
    one_file: bool = False
    join_boundary: bool = True
    boundary_member_mm: float | None = None
    max_twist_deg_per_m: float = DEFAULT_MAX_TWIST_DEG_PER_M

    @property
    def scale(self) -> float:
        """Millimetres per model unit."""
        return UNITS[self.units]

    @property
    def slit_width_mm(self) -> float:
        """Nominal slit width: thickness plus clearance (before kerf compensation)."""
        return self.thickness_mm + self.clearance_mm

    @property
    def extension_mm(self) -> float:
        return self.height_mm / 2 if self.end_extension_mm is None else self.end_extension_mm

    @property
    def member_mm(self) -> float:
        return self.thickness_mm if self.boundary_member_mm is None else self.boundary_member_mm

    @property
    def splice_mm(self) -> float:
        return 2 * self.height_mm if self.splice_length_mm is None else self.splice_length_mm

    @property
    def text_height_mm(self) -> float:
        if self.label_height_mm is not None:
            return self.label_height_mm
        return min(max(0.12 * self.height_mm, 3.0), 20.0)

    def check(self) -> "StripSettings":
        """Validate every field; returns self.

        Raises
        ------
        InputError
            Naming the first bad setting and what it must be.
        """
        def positive(name: str, value: object) -> None:
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number of millimetres, got {value}")

        def non_negative(name: str, value: object) -> None:
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be zero or more millimetres, got {value}")

        positive("--height", self.height_mm)
        positive("--thickness", self.thickness_mm)
        non_negative("--clearance", self.clearance_mm)
        positive("--tolerance", self.tolerance_mm)
        non_negative("--spacing", self.spacing_mm)
        non_negative("--margin", self.margin_mm)
        non_negative("--kerf", self.kerf_mm)
        non_negative("--slit-overcut", self.slit_overcut_mm)
        non_negative("--extension", self.extension_mm)
        non_negative("--boundary-member", self.member_mm)
        positive("--splice-length", self.splice_mm)
        positive("--label-height", self.text_height_mm)
        if not (isinstance(self.max_twist_deg_per_m, (int, float))
                and math.isfinite(self.max_twist_deg_per_m) and self.max_twist_deg_per_m > 0):
            raise InputError(f"--max-twist must be a positive number of degrees per metre, got "
                             f"{self.max_twist_deg_per_m}")
        check_units(self.units)
        if len(self.sheet_mm) != 2:
            raise InputError(f"--sheet must be WIDTHxHEIGHT, got {self.sheet_mm}")
        for value in self.sheet_mm:
            positive("--sheet", value)
        if self.end not in ("square", "round"):
            raise InputError(f"--end must be 'square' or 'round', got {self.end!r}")
        if self.splice not in ("overlap", "lap"):
            raise InputError(f"--splice must be 'overlap' or 'lap', got {self.splice!r}")
        if self.labels not in ("stroke", "outline", "text"):
            raise InputError(f"--labels must be 'stroke', 'outline' or 'text', got {self.labels!r}")
        low, high = CUTTING_TOLERANCE_MM
        if not low <= self.tolerance_mm <= high:
            raise InputError(f"--tolerance {self.tolerance_mm:g} mm lies outside {low:g} .. "
                             f"{high:g} mm, the range a cutting machine works to")
        if max(self.sheet_mm) > MAX_SHEET_MM:
            raise InputError(f"--sheet {self.sheet_mm[0]:g}x{self.sheet_mm[1]:g} mm: no sheet is "
                             f"larger than {MAX_SHEET_MM:g} mm (is it in the wrong unit?)")
        room = min(self.sheet_mm) - 2 * self.margin_mm
        if self.height_mm >= room:
            raise InputError(f"--height {self.height_mm:g} mm does not fit on the "
                             f"{min(self.sheet_mm):g} mm side of the sheet inside its margins "
                             f"(--margin {self.margin_mm:g} mm)")
        if self.spacing_mm >= room:
            raise InputError(f"--spacing {self.spacing_mm:g} mm is wider than the sheet inside its "
                             f"margins ({room:g} mm): it must leave room for a part")
        if self.kerf_mm >= self.slit_width_mm:
            raise InputError(f"--kerf {self.kerf_mm:g} mm must be narrower than the slit "
                             f"({self.slit_width_mm:g} mm = thickness + clearance)")
        if self.slit_width_mm >= self.height_mm:
            raise InputError(f"the slit width {self.slit_width_mm:g} mm (thickness + clearance) "
                             f"must be smaller than --height {self.height_mm:g} mm")
        if self.spacing_mm < self.slit_overcut_mm + self.kerf_mm:
            raise InputError(f"--spacing {self.spacing_mm:g} mm must be at least the slit overcut "
                             f"plus the kerf ({self.slit_overcut_mm + self.kerf_mm:g} mm)")
        if self.extension_mm < self.slit_width_mm / 2 + 1.0:
            raise InputError(f"--extension {self.extension_mm:g} mm leaves no material around a "
                             f"slit at the strip end: use at least "
                             f"{self.slit_width_mm / 2 + 1.0:g} mm")
        if set(self.layers) != set(_LAYER_KINDS):
            raise InputError(f"layers must name exactly {', '.join(_LAYER_KINDS)}")
        names = [str(name) for name, _ in self.layers.values()]
        for name, colour in self.layers.values():
            if not name or any(c in str(name) for c in '<>/\\":;?*|=`'):
                raise InputError(f"layer name {name!r} is empty or has a character DXF forbids")
            if not (isinstance(colour, int) and 1 <= colour <= 255):
                raise InputError(f"layer {name}: colour must be an AutoCAD colour index 1-255, "
                                 f"got {colour}")
        if len({n.upper() for n in names}) != len(names):
            raise InputError(f"layer names must differ, got {', '.join(names)}")
        return self


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

    def fit(i: int, j: int) -> tuple[float, float] | None:
        P = nodes[i:j + 1]
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

    def longest(i: int) -> tuple[int, tuple[float, float]] | None:
        """Largest j such that nodes i..j fit, with its fit, or None."""
        j = i + min_edges
        if j > k - 1 or (res := fit(i, j)) is None:
            return None
        best, step = (j, res), 1
        while True:  # exponential, then binary search (a subset of a fitting run fits)
            hi = min(j + step, k - 1)
            if hi == j or (res := fit(i, hi)) is None:
                break
            best, j, step = (hi, res), hi, step * 2
        lo, hi = j, min(j + step, k - 1)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if (res := fit(i, mid)) is not None:
                best, lo = (mid, res), mid
            else:
                hi = mid
        return best

    runs: list[ArcRun] = []
    i = 0
    while i < k - 1:
        best = longest(i)
        if best is None:
            runs.append(ArcRun(i, i + 1, math.inf, 0.0, False))
            i += 1
            continue
        stop, res = best
        if 0 < k - 1 - stop < min_edges:
            # leave the tail enough edges for a run of its own when it fits
            cut = k - 1 - min_edges
            if (cut - i >= min_edges and fit(cut, k - 1) is not None
                    and (head := fit(i, cut)) is not None):
                stop, res = cut, head
        runs.append(ArcRun(i, stop, float(res[0]), float(res[1]), True))
        i = stop
    return runs


# ---------------------------------------------------------------------- reference curve
class ReferenceCurve:
    """A planar curve through nodes, each edge a line or a circular arc (DXF bulges).

    Parameters
    ----------
    nodes : (k, 2) float, points the curve passes through, in order (mm).
    bulges : (k - 1,) float, bulge ``tan(theta / 4)`` of each edge, ``theta`` its signed
        included angle (positive counter-clockwise); 0 for a straight edge.

    Examples
    --------
    A quarter circle of radius 10 as one arc:

    >>> import numpy as np
    >>> c = ReferenceCurve(np.array([[10.0, 0], [0, 10.0]]), np.array([np.tan(np.pi / 8)]))
    >>> round(c.length, 9) == round(5 * np.pi, 9)
    True
    >>> p, t = c.point(c.length / 2, offset=1.0)
    >>> np.round(p, 6).tolist()
    [6.363961, 6.363961]
    """

    def __init__(self, nodes: np.ndarray, bulges: np.ndarray):
        self.nodes = np.asarray(nodes, dtype=np.float64)
        self.bulges = np.asarray(bulges, dtype=np.float64)
        A, B = self.nodes[:-1], self.nodes[1:]
        chord = B - A
        self.chord = np.linalg.norm(chord, axis=1)
        self.theta = 4 * np.arctan(self.bulges)
        self.straight = np.abs(self.bulges) < 1e-12
        half = np.where(self.straight, 1.0, self.theta / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.radius = np.where(self.straight, np.inf, self.chord / (2 * np.abs(np.sin(half))))
            left = np.column_stack([-chord[:, 1], chord[:, 0]]) / self.chord[:, None]
            dist = np.where(self.straight, 0.0, self.chord / 2 / np.tan(half))
        self.centre = (A + B) / 2 + left * dist[:, None]
        self.start_angle = np.arctan2(A[:, 1] - self.centre[:, 1], A[:, 0] - self.centre[:, 0])
        with np.errstate(invalid="ignore"):
            self.edge_length = np.where(self.straight, self.chord, self.radius * np.abs(self.theta))
        self.s = np.concatenate([[0.0], np.cumsum(self.edge_length)])

    def to_data(self) -> dict:
        """The curve as plain data (`fabplan.io.typed_data`)."""
        return {"nodes": self.nodes, "bulges": self.bulges}

    @classmethod
    def from_data(cls, data: dict) -> "ReferenceCurve":
        return cls(data["nodes"], data["bulges"])

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def _edge_point(self, e: int, t: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Point and unit tangent at arc fraction t of edge e (t may leave [0, 1])."""
        A, B = self.nodes[e], self.nodes[e + 1]
        if self.straight[e]:
            tan = (B - A) / self.chord[e]
            p = A + t * (B - A)
        else:
            a = self.start_angle[e] + t * self.theta[e]
            radial = np.array([math.cos(a), math.sin(a)])
            p = self.centre[e] + self.radius[e] * radial
            tan = np.sign(self.theta[e]) * np.array([-radial[1], radial[0]])
        left = np.array([-tan[1], tan[0]])
        return p + offset * left, tan

    def locate(self, s: float) -> tuple[int, float]:
        """Edge index and arc fraction of arc length s (beyond the ends: the end edges)."""
        e = int(np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.chord) - 1))
        return e, (s - self.s[e]) / self.edge_length[e]

    def point(self, s: float, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Point at arc length `s`, moved `offset` to the left (the top), and the unit tangent."""
        e, t = self.locate(s)
        return self._edge_point(e, t, offset)

    def points(self, s: np.ndarray, offset: float | np.ndarray = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Vectorized `point`: (m, 2) points at arc lengths `s` moved `offset` (a number or
        (m,) array) to the left, and (m, 2) unit tangents."""
        s = np.asarray(s, dtype=np.float64)
        e = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.chord) - 1)
        t = (s - self.s[e]) / self.edge_length[e]
        A, B = self.nodes[e], self.nodes[e + 1]
        line_tan = (B - A) / self.chord[e, None]
        a = self.start_angle[e] + t * self.theta[e]
        radial = np.column_stack([np.cos(a), np.sin(a)])
        with np.errstate(invalid="ignore"):
            arc_p = self.centre[e] + self.radius[e, None] * radial
        arc_tan = np.sign(self.theta[e])[:, None] * np.column_stack([-radial[:, 1], radial[:, 0]])
        straight = self.straight[e, None]
        p = np.where(straight, A + t[:, None] * (B - A), arc_p)
        tan = np.where(straight, line_tan, arc_tan)
        offset = np.asarray(offset, dtype=np.float64).reshape(-1, 1)
        return p + offset * np.column_stack([-tan[:, 1], tan[:, 0]]), tan

    def path(self, s0: float, s1: float, offset: float = 0.0) -> np.ndarray:
        """The part of the curve from `s0` to `s1` (s0 < s1), offset `offset` to the left.

        Returns
        -------
        (m, 3) float rows ``x, y, bulge``: the bulge of a row belongs to the segment to the
        next row, the last row's bulge is 0. Arcs stay arcs (concentric offsets); at nodes
        inside the range the offsets of both edges meet at their mitre point.
        """
        e0, t0 = self.locate(s0)
        e1, t1 = self.locate(s1)
        rows: list[list[float]] = []
        for e in range(e0, e1 + 1):
            ta = t0 if e == e0 else 0.0
            tb = t1 if e == e1 else 1.0
            pa, _ = self._edge_point(e, ta, offset)
            bulge = 0.0 if self.straight[e] else math.tan((tb - ta) * self.theta[e] / 4)
            if rows and e > e0:
                # mitre with the previous edge at node e
                _, t_in = self._edge_point(e - 1, 1.0, 0.0)
                _, t_out = self._edge_point(e, 0.0, 0.0)
                n_in = np.array([-t_in[1], t_in[0]])
                n_out = np.array([-t_out[1], t_out[0]])
                pa = self.nodes[e] + offset * (n_in + n_out) / (1 + n_in @ n_out)
            rows.append([pa[0], pa[1], bulge])
        pb, _ = self._edge_point(e1, t1, offset)
        rows.append([pb[0], pb[1], 0.0])
        return np.array(rows)


# ---------------------------------------------------------------------- strips
@dataclass
class Strip:
    """One lamella: its polyline on the net and its unrolled reference curve.

    Attributes
    ----------
    id : ``A`` (family 0) or ``B`` (family 1) and a number, e.g. ``A07``.
    family : 0 or 1; family 0 is slit from the top, family 1 from the bottom.
    vertices : (k,) int, net vertices along the strip (a closed loop repeats its first).
    closed : whether the polyline was a closed loop (cut open at its first vertex).
    curve : the reference curve (mid-line) in the plane (mm).
    axis : (k, 2) float, slit direction at each node (the node normal unrolled, upwards).
    edge_mm : (k - 1,) float, 3D edge lengths (mm).
    runs : arc runs of the reference curve.
    twist_deg_per_m : largest rotation of the normals about an edge per metre of edge (edges
        shorter than a quarter of the strip's median edge taken at that length).
    max_twist_deg : largest rotation of the normals about one edge.
    off_orthogonal_deg : largest angle between a node normal and a flat panel through its
        edge and the edge's mean normal: how far a flat-panel lamella leans.
    lean_deg : largest lean at nodes without a star, where the strip continues its
        neighbours' normal curvature (see `unroll_polylines`).
    end_setback_mm : (start, end): None at a free end (cut `StripSettings.end_extension_mm`
        beyond its node), else how far short of its end node the strip ends at the boundary
        member (`fabplan.fabricate.strip_boundary`), in mm: half the member over the sine
        of their angle where the node is on the edge of the cladding; negative where the
        node stops a hair short of the edge and the strip runs on straight to the member.
    end_angle_deg : (start, end) angle between the strip and the cladding edge at a member
        end (NaN at a free end).
    boundary_nodes : (start, end) nodes beyond the net, in its boundary panels.
    end_kind : (start, end) why each end is where it is, one of
        `fabplan.fabricate.strip_boundary.END_KINDS`; ``free`` when no boundary panels were
        given.
    """

    id: str
    family: int
    vertices: np.ndarray
    closed: bool
    curve: ReferenceCurve
    axis: np.ndarray
    edge_mm: np.ndarray
    runs: list
    twist_deg_per_m: float
    max_twist_deg: float
    off_orthogonal_deg: float
    lean_deg: float
    end_setback_mm: tuple[float | None, float | None] = (None, None)
    end_angle_deg: tuple[float, float] = (math.nan, math.nan)
    boundary_nodes: tuple[int, int] = (0, 0)
    end_kind: tuple[str, str] = ("free", "free")

    def at_member(self, side: int) -> bool:
        """Whether the strip's start (`side` 0) or end (1) butts against a boundary member."""
        return self.end_setback_mm[side] is not None

    def end_extensions_mm(self, settings: "StripSettings") -> tuple[float, float]:
        """Material beyond the first and the last node along the curve (mm): the settings'
        extension at a free end, minus the set-back at a member end."""
        return tuple(settings.extension_mm if e is None else -e    # type: ignore[return-value]
                     for e in self.end_setback_mm)

    @property
    def length_mm(self) -> float:
        """3D polyline length (= the unrolled polyline's length: the development is isometric)."""
        return float(self.edge_mm.sum())

    @property
    def unrolled_length_mm(self) -> float:
        """Length of the unrolled polyline (straight chords between the developed nodes)."""
        return float(np.linalg.norm(np.diff(self.curve.nodes, axis=0), axis=1).sum())

    @property
    def cut_length_mm(self) -> float:
        """Length of the reference curve as cut (arcs through the nodes), end node to end node."""
        return self.curve.length

    @property
    def s_mm(self) -> np.ndarray:
        """(k,) arc length of each node along the reference curve as cut."""
        return self.curve.s

    @property
    def arc_radii_mm(self) -> np.ndarray:
        """Signed radii of the fitted arc runs (inf for straight runs)."""
        return np.array([r.radius_mm for r in self.runs if r.fitted])

    @property
    def radius_mm(self) -> float:
        """Length-weighted mean |radius| over the arc runs; inf when the strip is straight."""
        arcs = [r for r in self.runs if r.fitted and math.isfinite(r.radius_mm)]
        if not arcs or any(r.fitted and not math.isfinite(r.radius_mm) for r in self.runs):
            return math.inf
        w = np.array([self.curve.s[r.stop] - self.curve.s[r.start] for r in arcs])
        return float(np.average([abs(r.radius_mm) for r in arcs], weights=w))

    @property
    def arc_fraction(self) -> float:
        """Fraction of the length in fitted runs (cut as true arcs or fitted lines)."""
        fitted = sum(self.curve.s[r.stop] - self.curve.s[r.start] for r in self.runs if r.fitted)
        return float(fitted / self.curve.length) if self.curve.length else 0.0


@dataclass(frozen=True)
class Crossing:
    """Two strips of different families meeting at a net vertex.

    Attributes
    ----------
    id : running number, engraved next to both slits.
    vertex : net vertex.
    strips : (a, b) strip indices, family 0 first.
    nodes : (i, j) node indices on strips a and b.
    s_mm : (s_a, s_b) arc lengths of the node along both reference curves.
    angle_deg : angle between the two strips' polylines at the vertex (3D).
    """

    id: int
    vertex: int
    strips: tuple[int, int]
    nodes: tuple[int, int]
    s_mm: tuple[float, float]
    angle_deg: float


@dataclass
class StripSet:
    """All lamellas of a net with their crossings and summary measurements.

    Attributes
    ----------
    strips : list of Strip, family 0 first, each family ordered across the net.
    crossings : list of Crossing.
    junctions : (j,) int, vertices where more than one strip of a family meets (irregular
        vertices): no slit is cut there, they need a node connector.
    settings : the settings used.
    positions : (m, 3) float, where the strips' vertices are (model units): the net's
        vertices, then the corners of its boundary panels the strips run through.
    ends_not_continued : strip ends on the net's boundary that no boundary panel side
        continues to the edge (0 without boundary panels).
    crossings_at_member : crossings left without slits because a strip ends there
        against the boundary member (two strips meeting at a tip of the boundary).
    along_edge : polylines left out because they lie along the edge of the cladding, where
        the boundary member runs.
    normals : (m, 3) float, the unit node normal at every one of `positions`: the line the
        lamella stands on there (None for a set made without them).
    """

    strips: list
    crossings: list
    junctions: np.ndarray
    settings: StripSettings
    positions: np.ndarray
    ends_not_continued: int = 0
    crossings_at_member: int = 0
    along_edge: int = 0
    normals: np.ndarray | None = None

    @cached_property
    def crossings_of_strip(self) -> list:
        """For each strip, the list of (crossing, side) it takes part in (side 0 or 1)."""
        out: list = [[] for _ in self.strips]
        for c in self.crossings:
            out[c.strips[0]].append((c, 0))
            out[c.strips[1]].append((c, 1))
        return out

    def summary(self) -> dict:
        """Measured facts about the strips (lengths in mm, angles in degrees)."""
        radii = np.array([abs(r) for s in self.strips for r in s.arc_radii_mm if math.isfinite(r)])
        lengths = np.array([s.length_mm for s in self.strips])
        length_error = np.array([abs(s.unrolled_length_mm - s.length_mm) for s in self.strips])
        straight = all(math.isinf(s.radius_mm) for s in self.strips)
        rec = {
            "strips": len(self.strips),
            "strips_per_family": [int(sum(s.family == f for s in self.strips)) for f in (0, 1)],
            "crossings": len(self.crossings),
            "junctions": int(len(self.junctions)),
            "total_length_mm": float(lengths.sum()),
            "length_mm": {"min": float(lengths.min()), "max": float(lengths.max())},
            "unrolled_length_error_mm": float(length_error.max()),
            "straight": bool(straight),
            "arc_fraction": float(np.average([s.arc_fraction for s in self.strips],
                                             weights=lengths)),
            "twist_deg_per_m": float(max(s.twist_deg_per_m for s in self.strips)),
            "off_orthogonal_deg": float(max(s.off_orthogonal_deg for s in self.strips)),
            "boundary_lean_deg": float(max(s.lean_deg for s in self.strips)),
            "ends_at_boundary_member": int(sum(s.at_member(k) for s in self.strips for k in (0, 1))),
            "ends_free": int(sum(not s.closed and not s.at_member(k)
                                 for s in self.strips for k in (0, 1))),
            "ends_not_continued": self.ends_not_continued,
            "ends_free_by_kind": {kind: int(sum(not s.closed and not s.at_member(k)
                                                and s.end_kind[k] == kind
                                                for s in self.strips for k in (0, 1)))
                                  for kind in ("free", "inside", "along edge", "not continued")},
            "crossings_at_member": self.crossings_at_member,
            "strips_along_edge": self.along_edge,
            "boundary_nodes": int(sum(sum(s.boundary_nodes) for s in self.strips)),
        }
        angles = [a for s in self.strips for a in s.end_angle_deg if math.isfinite(a)]
        rec["member_angle_min_deg"] = float(min(angles)) if angles else None
        setbacks = [(e, last) for s in self.strips
                    for e, last in zip(s.end_setback_mm, (s.edge_mm[0], s.edge_mm[-1]), strict=True)
                    if e is not None]
        rec["member_setback_max_mm"] = max((e for e, _ in setbacks), default=None)
        # a member eating up more than half the last edge of a strip is no edge member
        rec["ends_set_back_past_half_an_edge"] = sum(e > 0.5 * last for e, last in setbacks)
        if radii.size:
            med = float(np.median(radii))
            rec["radius_mm"] = {"median": med, "min": float(radii.min()), "max": float(radii.max()),
                                "spread_relative": float((radii.max() - radii.min()) / med)}
        else:
            rec["radius_mm"] = None
        return rec


def _order_across(mid: np.ndarray) -> np.ndarray:
    """Order of polylines by their midpoints' position along the main spread direction."""
    if len(mid) < 2:
        return np.arange(len(mid))
    C = mid - mid.mean(axis=0)
    _, _, vt = np.linalg.svd(C, full_matrices=False)
    return np.argsort(C @ vt[0], kind="stable")


def build_strips(mesh: QuadMesh, settings: StripSettings,
                 boundary: StripBoundary | None = None) -> StripSet:
    """Lamellas along every parameter polyline of both families, unrolled and fitted.

    Parameters
    ----------
    mesh : the net (model units, see `StripSettings.units`).
    settings : validated with `StripSettings.check`.
    boundary : the net's boundary panels: strips ending on the net's boundary run on
        through them to the edge of the cladding and end at a boundary member there
        (`fabplan.fabricate.strip_boundary`). None: they end at the net's last vertex.

    Raises
    ------
    InputError
        When the net has no parameter polylines, or a polyline has a repeated vertex or a
        zero-length edge.
    """
    settings.check()
    lines = strip_polylines(mesh, join_boundary=settings.join_boundary)
    if len(lines) == 0:
        raise InputError(f"{mesh.name}: no parameter polylines (the net has no quads)")
    verts = [np.r_[v, v[:1]] if c else np.asarray(v) for v, c in
             zip(lines.vertices, lines.closed, strict=True)]
    keep = [i for i, v in enumerate(verts) if len(v) >= 2]
    if not keep:
        raise InputError(f"{mesh.name}: no parameter polyline has an edge")
    X = mesh.vertices
    mid = np.array([X[verts[i]].mean(axis=0) for i in keep])
    fam = lines.family[keep]
    order = []
    for f in (0, 1):
        idx = np.flatnonzero(fam == f)
        order += [keep[i] for i in idx[_order_across(mid[idx])]]
    verts = [verts[i] for i in order]
    family = lines.family[order]
    closed = lines.closed[order]
    N = node_normals(mesh, lines)
    bad = ~np.isfinite(N).all(axis=1)
    used = np.unique(np.concatenate(verts))
    if bad[used].any():
        vertex = int(used[bad[used]][0])
        raise InputError(f"{mesh.name}: vertex {vertex} has no surface normal (degenerate faces)")
    ends = None
    along_edge = 0
    setback = np.full((len(verts), 2), np.nan)
    if boundary is not None and boundary.polygons:
        N = boundary.normals(N)
        ends = boundary.extend(verts, closed, N)
        # a polyline lying along the cladding's edge is where the boundary member runs
        kept = np.flatnonzero(~ends.along_edge)
        along_edge = len(verts) - len(kept)
        if kept.size == 0:
            raise InputError(f"{mesh.name}: every parameter polyline runs along the edge of the "
                             "cladding, where the boundary member is; use --no-boundary")
        ends = ends.subset(kept)
        verts, family, closed, X = ends.vertices, family[kept], closed[kept], boundary.vertices
        setback = _member_setbacks(X, ends, settings)
    u = unroll_polylines(X, N, verts, scale=settings.scale,
                         curvature=_continued_curvature(mesh, verts, len(X)))
    zero = np.flatnonzero((u.edge_mm < 1e-9) & ~np.isin(np.arange(len(u.edge_mm)), u.ptr[1:] - 1))
    if zero.size:
        k = int(np.searchsorted(u.ptr, zero[0], side="right") - 1)
        vertex = verts[k][zero[0] - u.ptr[k]]
        raise InputError(f"{mesh.name}: a polyline has a zero-length edge at vertex {vertex}")
    counters = [0, 0]
    strips = []
    for k, v in enumerate(verts):
        a, b = u.ptr[k], u.ptr[k + 1]
        nodes = u.nodes[a:b]
        runs = fit_arc_runs(nodes, settings.tolerance_mm)
        if len(v) == 2:
            runs = [_one_edge_run(mesh, N, v, settings.scale)]
        bulges = np.zeros(len(v) - 1)
        for r in runs:
            if r.fitted and math.isfinite(r.radius_mm):
                chord = np.linalg.norm(np.diff(nodes[r.start:r.stop + 1], axis=0), axis=1)
                half = np.arcsin(np.clip(chord / (2 * abs(r.radius_mm)), 0, 1))
                bulges[r.start:r.stop] = np.sign(r.radius_mm) * np.tan(half / 2)
        edge = u.edge_mm[a:b - 1]
        twist = np.abs(u.twist[a:b - 1])
        f = int(family[k])
        counters[f] += 1
        member = [None if math.isnan(x) else float(x) for x in setback[k]]
        angle, added, kind = (math.nan, math.nan), (0, 0), ("free", "free")
        if ends is not None:
            angle = (float(ends.angle_deg[k, 0]), float(ends.angle_deg[k, 1]))
            added = (int(ends.added[k, 0]), int(ends.added[k, 1]))
            kind = (str(ends.kind[k, 0]), str(ends.kind[k, 1]))
        strips.append(Strip(
            id=f"{FAMILY_LETTERS[f]}{counters[f]:02d}", family=f, vertices=np.asarray(v),
            closed=bool(closed[k]), curve=ReferenceCurve(nodes, bulges), axis=u.axis[a:b],
            edge_mm=edge, runs=runs,
            # per metre over at least a quarter of the strip's median edge: a sliver's
            # millimetre edge at a boundary panel corner would make any turn a huge rate
            twist_deg_per_m=float(np.degrees(
                twist / (np.maximum(edge, 0.25 * np.median(edge)) / 1000.0)).max()),
            max_twist_deg=float(np.degrees(twist).max()),
            off_orthogonal_deg=float(np.degrees(u.off_orthogonal[a:b]).max()),
            lean_deg=float(np.degrees(u.lean[a:b]).max()),
            end_setback_mm=(member[0], member[1]), end_angle_deg=angle, boundary_nodes=added,
            end_kind=kind))
    half = settings.height_mm / 2 + settings.kerf_mm / 2
    for s in strips:
        e0, e1 = s.end_extensions_mm(settings)
        if s.curve.length + e0 + e1 < settings.slit_width_mm + 2.0:
            raise InputError(
                f"strip {s.id} is {s.curve.length:.0f} mm long, but its ends against the "
                f"{settings.member_mm:g} mm boundary member leave {s.curve.length + e0 + e1:.0f} "
                "mm of it: use a thinner --boundary-member, or --no-boundary")
        radii = np.abs(s.arc_radii_mm)
        if radii.size and radii.min() <= half:
            raise InputError(f"strip {s.id} bends with a radius of {radii.min():.1f} mm, less than "
                             f"half the height ({half:g} mm): its inner edge would fold over; "
                             f"lower --height or check --units ({settings.units})")
    crossings, junctions = _find_crossings(X, strips)
    # where two strips end against the boundary member at one node (a zigzag boundary's
    # tip), they meet at the member, not in slits; a slit cut off by a member end neither
    slit = [c for c in crossings if all(_slit_inside(strips[c.strips[k]], c.nodes[k], settings)
                                        for k in (0, 1))]
    at_member = len(crossings) - len(slit)
    slit = [replace(c, id=i + 1) for i, c in enumerate(slit)]
    return StripSet(strips=strips, crossings=slit, junctions=junctions, settings=settings,
                    positions=X, ends_not_continued=0 if ends is None else ends.not_continued,
                    crossings_at_member=at_member, along_edge=along_edge, normals=N)


def _member_setbacks(X: np.ndarray, ends: StripEnds, settings: StripSettings) -> np.ndarray:
    """(p, 2) float, mm: how far short of its end node each strip end ends against the
    boundary member (NaN at a free end).

    Both faces of the lamella clear the member (`member_setback_mm`); an end that runs on
    straight to the edge a hair beyond its node (`StripEnds.reach`) ends that much later
    (a negative set-back); where two strips end at one node (a zigzag boundary's tip) each
    also clears the other (`tip_setback_mm`)."""
    out = np.full(ends.at_edge.shape, np.nan)
    direction: dict = {}
    for k, v in enumerate(ends.vertices):
        for side in (0, 1):
            if not ends.at_edge[k, side]:
                continue
            end, before = (v[0], v[1]) if side == 0 else (v[-1], v[-2])
            out[k, side] = (member_setback_mm(settings.member_mm, settings.thickness_mm,
                                              float(ends.angle_deg[k, side]))
                            - ends.reach[k, side] * settings.scale)
            d = X[end] - X[before]
            direction.setdefault(int(end), []).append((k, side, d / np.linalg.norm(d)))
    for meeting in direction.values():
        for i, (k, side, d) in enumerate(meeting):
            for j, (_, _, e) in enumerate(meeting):
                if i != j:
                    angle = math.degrees(math.acos(float(np.clip(d @ e, -1.0, 1.0))))
                    out[k, side] = max(out[k, side], tip_setback_mm(settings.thickness_mm, angle))
    return out


def _slit_inside(strip: Strip, node: int, settings: StripSettings) -> bool:
    """Whether a slit at `node` lies within the strip as cut (its ends set back at a
    boundary member)."""
    e0, e1 = strip.end_extensions_mm(settings)
    s = strip.s_mm[node]
    half = settings.slit_width_mm / 2
    return bool(s - half >= -e0 and s + half <= strip.curve.length + e1)


def _continued_curvature(mesh: QuadMesh, verts: list, count: int | None = None) -> np.ndarray:
    """Normal curvature imposed at strip nodes that are no star centre (NaN elsewhere).

    The net does not constrain such a node (on the boundary, or next to an irregular
    vertex), so its strip continues the normal curvature of the star centres next to it
    along the strip (their mean), or else of the stars the node belongs to (at a star both
    families share the normal curvature): the net's defining property (a constant radius,
    zero on an A-net) carries on to the strip's last nodes. Nodes beyond the net (ids from
    ``mesh.vertex_count`` up to `count`, in its boundary panels) carry on the curvature of
    the nearest node along the strip that has one. Nodes no star reaches keep NaN.
    """
    X, stars = mesh.vertices, mesh.stars
    count = len(X) if count is None else count
    kappa = np.full(count, np.nan)
    nearby = np.full(count, np.nan)
    if len(stars):
        k_star = fit_star_spheres(X, stars).curvature
        kappa[stars[:, 0]] = k_star
        total = np.zeros(count)
        hits = np.zeros(count)
        for j in range(1, 5):
            np.add.at(total, stars[:, j], k_star)
            np.add.at(hits, stars[:, j], 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            nearby = total / hits
    out = []
    for v in verts:
        k = kappa[v]
        pair = np.stack([np.r_[np.nan, k[:-1]], np.r_[k[1:], np.nan]])
        known = np.isfinite(pair)
        along = np.where(known.any(axis=0),
                         np.where(known, pair, 0).sum(axis=0) / np.maximum(known.sum(axis=0), 1),
                         nearby[v])
        imposed = np.where(np.isfinite(k), np.nan, along)
        beyond = v >= len(X)
        if beyond.any():
            # the nearest node along the strip with a curvature (its star's or imposed)
            value = np.where(np.isfinite(k), k, imposed)
            have = np.flatnonzero(np.isfinite(value) & ~beyond)
            if have.size:
                pos = np.arange(len(v))
                right = np.clip(np.searchsorted(have, pos), 0, have.size - 1)
                left = np.clip(right - 1, 0, have.size - 1)
                nearest = np.where(np.abs(have[left] - pos) <= np.abs(have[right] - pos),
                                   have[left], have[right])
                imposed = np.where(beyond, value[nearest], imposed)
        out.append(imposed)
    return np.concatenate(out)


def _one_edge_run(mesh: QuadMesh, N: np.ndarray, v: np.ndarray, scale: float) -> ArcRun:
    """The run of a one-edge strip: an arc of the edge's normal curvature.

    That is ``(n_0 - n_1) . e / |e|^2``, the Meusnier circle through both ends, when the
    end normals tell it; when both ends took their normal from the same single face (a
    corner edge of the boundary) the curvature is the mean of the Meusnier spheres of the
    stars that reach the edge's faces instead. A line when neither is known.
    """
    X = mesh.vertices
    e = X[v[1]] - X[v[0]]
    length = float(np.linalg.norm(e)) * scale
    kappa = float((N[v[0]] - N[v[1]]) @ e / (e @ e)) / scale
    if np.allclose(N[v[0]], N[v[1]], atol=1e-12) and len(mesh.stars):
        idx = mesh.face_indices
        face = mesh.corner_faces
        both = np.intersect1d(face[idx == v[0]], face[idx == v[1]])
        corners = idx[np.isin(face, both)]
        near = np.isin(mesh.stars, corners).any(axis=1)  # stars reaching the edge's faces
        if near.any():
            kappa = float(np.mean(fit_star_spheres(X, mesh.stars[near]).curvature)) / scale
    if abs(kappa) * length < 1e-9 or abs(kappa) * length >= 2:
        return ArcRun(0, 1, math.inf, 0.0, True)
    return ArcRun(0, 1, 1 / kappa, 0.0, True)


def _find_crossings(X: np.ndarray, strips: list[Strip]) -> tuple[list[Crossing], np.ndarray]:
    """Crossings: vertices on exactly one strip of each family (closed loops counted once)."""
    vert_parts, fam_parts, owner_parts, local_parts = [], [], [], []
    for k, s in enumerate(strips):
        v = s.vertices[:-1] if s.closed else s.vertices
        vert_parts.append(v)
        fam_parts.append(np.full(len(v), s.family))
        owner_parts.append(np.full(len(v), k))
        local_parts.append(np.arange(len(v)))
    vert, fam, owner, local = (np.concatenate(a) for a in (vert_parts, fam_parts, owner_parts, local_parts))
    n = len(X)
    count = np.zeros((n, 2), np.int64)
    np.add.at(count, (vert, fam), 1)
    is_crossing = (count[:, 0] == 1) & (count[:, 1] == 1)
    junctions = np.flatnonzero((count.min(axis=1) >= 1) & (count.max(axis=1) >= 2))
    sel = is_crossing[vert]
    order = np.lexsort((fam[sel], vert[sel]))
    v_s, o_s, l_s = vert[sel][order], owner[sel][order], local[sel][order]
    crossings = []
    for c, i in enumerate(range(0, len(v_s), 2)):
        a, b = int(o_s[i]), int(o_s[i + 1])
        ia, ib = int(l_s[i]), int(l_s[i + 1])
        ta, tb = _polyline_tangent(X, strips[a].vertices, ia), _polyline_tangent(X, strips[b].vertices, ib)
        angle = math.degrees(math.acos(min(1.0, abs(float(ta @ tb)))))
        crossings.append(Crossing(id=c + 1, vertex=int(v_s[i]), strips=(a, b), nodes=(ia, ib),
                                  s_mm=(float(strips[a].s_mm[ia]), float(strips[b].s_mm[ib])),
                                  angle_deg=angle))
    return crossings, junctions


def _polyline_tangent(X: np.ndarray, v: np.ndarray, i: int) -> np.ndarray:
    a, b = X[v[max(i - 1, 0)]], X[v[min(i + 1, len(v) - 1)]]
    t = b - a
    return t / np.linalg.norm(t)
