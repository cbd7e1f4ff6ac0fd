"""A design continued past its boundary, so that a net that leaves the design is solved
beyond it and its boundary panels continue it.

A net that may leave its design (linear Weingarten, constant radius, ...) is held to it by
a deviation limit at its vertices. Its boundary panels are cut between its outermost
faces and the design's boundary, up to a panel wide; they stand off the design as the
net does beside them. Where the net was solved only up to its zigzag edge, nothing held
the surface it continues there: it curls away from the design over the last panel (the
stadium's linear Weingarten nets: vertices within 97-113 mm, their tips and boundary
panels 260-290 mm off).

So the net is laid out and solved on the design continued by `MARGIN_PANELS` panels past
every open edge, its vertices there held to the continuation with the same limit (ghost
rows solved with the net). The net kept is made of the faces on the design itself; its
boundary panels follow the whole solved net, ghost rows included (`follow`), and so
continue it to the design's edge within the limit. This needs a continuation: a built-in
design (a parametric surface, continued by its own formula) or an untrimmed NURBS
surface (expanded about its edge to second order: `NurbsSurface.extended`); a design given as a mesh
or a trimmed NURBS face keeps the solve on the design alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..design.nurbs import NurbsSurface
from ..design.parametric import ParametricSurface
from ..net.mesh import QuadMesh

__all__ = ["ContinuedDesign", "continued_design", "design_layout", "faces_on_design",
           "held_vertices",
           "MARGIN_PANELS"]

#: how far the design is continued past its open edges (panel sizes): the net's held
#: vertices (those in stars) then reach past the design's edge everywhere
MARGIN_PANELS = 2.0


@dataclass
class ContinuedDesign:
    """A design and its continuation past its open edges.

    Attributes
    ----------
    design : the continued design (a `DesignSurface` on the larger parameter domain, on
        the same grid of parameters).
    inside : (t,) int, the continued design's triangles that are the design's own, in the
        order of the design's triangles.
    """

    design: DesignSurface
    inside: np.ndarray

    def on_design(self, points: np.ndarray) -> np.ndarray:
        """(m,) bool, the points (m, 3) whose closest point of the continued design lies
        on the design itself."""
        _, _, tri = self.design.reference.closest_points(np.asarray(points, np.float64))
        mask = np.zeros(len(self.design.triangles), bool)
        mask[self.inside] = True
        return mask[tri]


def continued_design(design: DesignSurface, margin: float) -> ContinuedDesign | None:
    """`design` continued by `margin` (model units) past its open edges, on the same grid
    of parameters, or None where it cannot be: not a built-in surface, closed in both
    directions, or its formula breaks down past its edges (not finite, or the cells of
    the continuation collapse or turn over).

    Examples
    --------
    >>> from fabplan.design.parametric import hyperbolic_paraboloid
    >>> saddle = hyperbolic_paraboloid(width=4.0, depth=4.0).triangulate(8)
    >>> more = continued_design(saddle, 1.5)
    >>> more.design.parametric.domain, len(more.inside) == len(saddle.triangles)
    (((-6.0, 6.0), (-6.0, 6.0)), True)
    """
    surface, uv = design.parametric, design.uv
    if not isinstance(surface, ParametricSurface) or uv is None \
            or not (np.isfinite(margin) and margin > 0):
        return None
    (u0, u1), (v0, v1) = surface.domain
    nu = len(np.unique(uv[:, 0])) - (0 if surface.periodic_u else 1)
    nv = len(np.unique(uv[:, 1])) - 1
    if nu < 1 or nv < 1:
        return None
    du, dv = (u1 - u0) / nu, (v1 - v0) / nv

    def widened(ku: float, kv: float) -> ParametricSurface:
        domain = ((u0 - ku * du, u1 + ku * du), (v0 - kv * dv, v1 + kv * dv))
        if isinstance(surface, NurbsSurface):
            return surface.extended(domain)       # expanded about its edge
        return replace(surface, domain=domain)

    if isinstance(surface, NurbsSurface) and surface.trims is not None:
        return None             # a trimmed face's design is the region its trims bound
    if type(surface) is not ParametricSurface and not isinstance(surface, NurbsSurface):
        return None
    # a NURBS surface is evaluated on its domain only: probed on one twice as wide
    probe = widened(nu, nv) if isinstance(surface, NurbsSurface) else surface
    # cells added on each side: an even count keeps the alternating diagonals of the grid
    ku = 0 if surface.periodic_u else _cells(probe, surface.domain, margin, du, along_u=True)
    kv = _cells(probe, surface.domain, margin, dv, along_u=False)
    if ku is None or kv is None:
        return None
    wider = widened(ku, kv)
    with np.errstate(all="ignore"):
        try:
            continued = wider.triangulate((nu + 2 * ku, nv + 2 * kv))
        except Exception:       # a formula that breaks down past the design's edges
            return None
    continued.units = design.units
    inside = _same_triangles(continued, design)
    if inside is None or not _sound(continued, inside):
        return None
    return ContinuedDesign(continued, inside)


def _cells(surface, domain: tuple, margin: float, step: float, *, along_u: bool) -> int | None:
    """The even number of grid cells of `step` (parameter units) that spans at least
    `margin` (model units) at both edges of `domain` in that direction, or None where
    the surface does not grow there (a formula that stalls)."""
    (u0, u1), (v0, v1) = domain
    across = np.linspace(v0, v1, 17) if along_u else np.linspace(u0, u1, 17)
    shortest = math.inf
    for edge, out in (((u0, -step) if along_u else (v0, -step)),
                      ((u1, step) if along_u else (v1, step))):
        with np.errstate(all="ignore"):
            if along_u:
                a, b = surface.points(edge, across), surface.points(edge + out, across)
            else:
                a, b = surface.points(across, edge), surface.points(across, edge + out)
        length = np.linalg.norm(b - a, axis=1)
        if not np.all(np.isfinite(length)):
            return None
        shortest = min(shortest, float(length.min()))
    if not shortest > 1e-9 * margin:
        return None
    k = math.ceil(margin / shortest)
    return k + k % 2 if k <= 400 else None


def _same_triangles(continued: DesignSurface, design: DesignSurface) -> np.ndarray | None:
    """(t,) int, the triangles of `continued` with the corners of each of `design`'s, or
    None when some has none."""
    if not (np.all(np.isfinite(continued.vertices))):
        return None
    size = float(np.ptp(design.vertices, axis=0).max()) or 1.0
    mine = design.vertices[design.triangles]
    theirs = continued.vertices[continued.triangles]
    distance, at = cKDTree(theirs.mean(axis=1)).query(mine.mean(axis=1))
    if np.any(distance > 1e-9 * size):
        return None
    # the same corners (in any order)
    a = np.sort(np.round(mine / (1e-9 * size)), axis=1)
    b = np.sort(np.round(theirs[at] / (1e-9 * size)), axis=1)
    if np.abs(a - b).max() > 2:
        return None
    return at.astype(np.int64)


def _sound(continued: DesignSurface, inside: np.ndarray) -> bool:
    """The continuation's triangles keep the design's orientation and do not collapse:
    each at least a tenth of the design's smallest, its normal within 60 degrees of the
    design's nearest triangle."""
    areas = continued.face_areas
    mask = np.ones(len(areas), bool)
    mask[inside] = False
    if not mask.any():
        return True
    if areas[mask].min() < 0.1 * areas[inside].min():
        return False
    centres = continued.vertices[continued.triangles].mean(axis=1)
    near = cKDTree(centres[inside]).query(centres[mask])[1]
    normals = continued.face_normals
    return bool(np.all(np.sum(normals[mask] * normals[inside][near], axis=1) > 0.5))


def faces_on_design(mesh: QuadMesh, continued: ContinuedDesign) -> np.ndarray:
    """(f,) bool, the faces of a net solved on the continued design whose corners all
    stand over the design itself, less those that would leave the kept net touching
    itself at a corner only (two faces sharing a vertex and no side)."""
    on = continued.on_design(mesh.vertices)
    keep = np.bincount(mesh.corner_faces, on[mesh.face_indices],
                       minlength=len(mesh.face_sizes)) == mesh.face_sizes
    for _ in range(8):
        pinched = _pinched_faces(mesh, keep)
        if not pinched.any():
            break
        keep &= ~pinched
    return keep


def held_vertices(mesh: QuadMesh, continued: ContinuedDesign) -> np.ndarray:
    """(k,) int, the vertices of a net on the continued design that its deviation limit
    holds: those in a star (a tip in none is free) that stand over the design or share
    an edge with one that does (the faces across the design's edge, which the boundary
    panels follow). The rows farther out only carry the net's conditions to them."""
    on = continued.on_design(mesh.vertices)
    a, b = mesh.edges.T
    near = on.copy()
    near[a[on[b]]] = True
    near[b[on[a]]] = True
    in_star = np.zeros(mesh.vertex_count, bool)
    in_star[np.asarray(mesh.stars).ravel()] = True
    return np.flatnonzero(near & in_star)


def _pinched_faces(mesh: QuadMesh, keep: np.ndarray) -> np.ndarray:
    """(f,) bool, kept faces at a vertex where the kept faces meet in more than one fan
    (more than two boundary edges of the kept faces end there)."""
    kept = keep[mesh.corner_faces]
    a, b = mesh.face_indices[kept], mesh.corner_next_vertices[kept]
    key = np.minimum(a, b) * mesh.vertex_count + np.maximum(a, b)
    uniq, count = np.unique(key, return_counts=True)
    border = uniq[count == 1]
    ends = np.concatenate([border // mesh.vertex_count, border % mesh.vertex_count])
    per_vertex = np.bincount(ends, minlength=mesh.vertex_count)
    out = np.zeros(len(keep), bool)
    out[mesh.corner_faces[kept][per_vertex[a] > 2]] = True
    return out


def design_layout(layout, continued: ContinuedDesign, design: DesignSurface):
    """The layout `layout` (laid out on the continued design) read on `design` itself:
    the same parameters ``(phi, psi)`` on the design's own triangles, so that the net
    kept (`faces_on_design`) is trimmed to the design's boundary (`fabplan.layout.trim`).
    Its mesh stays the continued layout's; only the trimming reads it this way."""
    on = continued.on_design(layout.singular_points) if len(layout.singular_points) else \
        np.zeros(0, bool)
    out = replace(layout, design=design, parameters=layout.parameters[continued.inside],
                  singular_points=layout.singular_points[on],
                  singular_index=layout.singular_index[on], prescribed=None)
    out.__dict__.pop("chart", None)
    return out
