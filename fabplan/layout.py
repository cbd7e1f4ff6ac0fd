"""From a design surface to an initial S-net: directions, parametrization, quad extraction.

The steps follow section 4.3 of the paper, with the degrees of freedom of section 2.1.11:

1. Principal directions per triangle: from the exact fundamental forms of a parametric
   surface, or from libigl's per-vertex estimate (Rusinkiewicz-style quadric fitting)
   averaged as shape operators over each triangle.
2. A smooth line field: the traceless part of the shape operator, weighted by the
   anisotropy ``|k1 - k2|``, is smoothed over a length of about half a panel (near
   umbilics the surroundings decide), then combed into a consistent sign by XOR along a
   minimum spanning tree of the triangle adjacency (pointer doubling, as in
   `fabplan.mesh.QuadMesh._face_parity`). Where the combing conflicts the field has a
   seam; its end points and points where the field turns around are its singularities.
3. S-net directions: the pair symmetric to the principal directions at the requested
   angle, ``t1,2 = cos(a/2) e1 +- sin(a/2) e2`` (90 degrees: 45 degrees off the principal
   directions). In the second mode one family is prescribed (a function whose level sets
   are, e.g., the floor levels of a tower) and its partner direction is the reflection of
   its tangent in the principal directions (Proposition 2.11), ``s = 2 (t . e1) e1 - t``.
4. A global parametrization ``(phi, psi)``: sparse least squares for the gradients (isolines
   of phi along t1, of psi along t2, spacing one panel), with the alignment weighted above
   the spacing. Boundary loops around which the field turns (a tower) are cut open and
   get an integer jump, so the grid closes up.
5. Extraction: the integer points of the parametrization, located triangle by triangle
   (barycentric test, vectorized over candidate points), become vertices; unit squares
   whose corners and centre exist become quads (oriented with the surface). Quads that
   fold or stretch (near singularities and seams) are dropped, the largest piece is
   kept, pinched vertices are separated, and small interior holes are closed by a fan of
   quads around a new vertex: these are the irregular vertices (fairness only in the
   solve).

`glide` then optimizes the layout into a net of a given type with its vertices held on
the design surface and its boundary vertices near the surface boundary held on it.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .constraints import FamilyLevels
from .errors import InputError
from .linalg import SparseSPDSolver
from .mesh import QuadMesh, xor_to_root
from .surfaces import DesignSurface, _edge_corners, _edge_values

__all__ = [
    "LayoutSettings",
    "SurfaceLayout",
    "layout_surface",
    "face_principal_frames",
    "smooth_line_field",
    "comb_line_field",
    "line_field_index",
    "snet_directions",
    "complementary_directions",
    "prescribed_family",
    "integrate_directions",
    "extract_quads",
    "glide",
    "write_layout_picture",
]


@dataclass
class LayoutSettings:
    """Numbers that steer the layout (lengths in panel sizes unless stated).

    Attributes
    ----------
    bisector : the principal direction bisecting the angle between the families, "max"
        (the larger principal curvature) or "min". Irrelevant at 90 degrees.
    smoothing : smoothing length of the direction field.
    scale_weight : weight of uniform spacing against alignment with the directions in
        the integration (alignment has weight 1): smaller values follow the directions
        more closely and let the spacing vary.
    curvature_radius : neighbourhood of libigl's curvature estimate (in mean edges of
        the design mesh), for triangle meshes.
    min_edge, max_edge : extracted quads with an edge outside this range are dropped.
    fill_holes_up_to : interior holes bounded by at most this many edges are closed with
        a fan around a new (irregular) vertex; larger holes stay open.
    boundary_snap : boundary vertices of the layout within this distance of the design
        boundary glide on it; the others stay free on the surface.
    offsets : trial shifts of the integer grid per direction (offsets**2 trials); the
        extraction with the most quads is kept.
    """

    bisector: str = "max"
    smoothing: float = 0.5
    scale_weight: float = 0.1
    curvature_radius: int = 5
    min_edge: float = 0.4
    max_edge: float = 2.2
    fill_holes_up_to: int = 24
    boundary_snap: float = 0.75
    offsets: int = 2


@dataclass
class SurfaceLayout:
    """An initial S-net on a design surface and what was found on the way.

    Attributes
    ----------
    mesh : the extracted quad-dominant mesh (vertices on the design surface).
    design : the `DesignSurface`.
    panel_size : target edge length (model units).
    angle_deg : intersection angle of the two families (None when one is prescribed).
    parameters : (t, 3, 2) float, ``(phi, psi)`` at the corners of every design triangle
        (integer values are the mesh lines).
    singular_points : (k, 3) float, points of the design surface where the direction field
        is singular (umbilics, seam ends), with their `singular_index` (k,) in turns.
    seam_edges : number of design edges across which the combed field flips.
    cuts : transitions ``(sign, jump_phi, jump_psi)`` across the cuts: sign 1 for a
        boundary loop cut open (the grid closes up with an integer shift), -1 for a seam of
        the line field (parameters ``c - p``).
    filled_holes, open_holes : interior holes closed with irregular vertices / left open.
    gliding_boundary : (b,) int, boundary vertices of `mesh` close enough to the design
        boundary to glide on it.
    vertex_keys : (n, 2) float, the integer parameters ``(phi, psi)`` of every mesh vertex
        (NaN for vertices added in holes).
    prescribed : (n_design,) float, the prescribed family's function on the design
        vertices (its integer levels are the first family), or None.
    family : description of the prescribed family, or None.
    level_step : level k of the prescribed family is where its function equals
        ``k * level_step`` (see `prescribed_family`), or None.
    seconds : time per stage.
    """

    mesh: QuadMesh
    design: DesignSurface
    panel_size: float
    angle_deg: float | None
    parameters: np.ndarray
    singular_points: np.ndarray
    singular_index: np.ndarray
    seam_edges: int
    cuts: list
    filled_holes: int
    open_holes: int
    gliding_boundary: np.ndarray
    vertex_keys: np.ndarray
    prescribed: np.ndarray | None = None
    family: str | None = None
    level_step: float | None = None
    seconds: dict = field(default_factory=dict)

    def record(self) -> dict:
        """JSON-ready summary (written with the optimized net)."""
        mesh = self.mesh
        return {
            "design": self.design.name,
            "design_triangles": int(len(self.design.triangles)),
            "design_repairs": dict(self.design.repairs),
            "panel_size": self.panel_size,
            "angle_deg": self.angle_deg,
            "prescribed_family": self.family,
            "level_step": self.level_step,
            "quads": int(np.sum(mesh.face_sizes == 4)),
            "other_faces": int(np.sum(mesh.face_sizes != 4)),
            "vertices": int(mesh.vertex_count),
            "irregular_vertices": mesh.irregular_vertices.tolist(),
            "singular_points": self.singular_points.tolist(),
            "singular_index": self.singular_index.tolist(),
            "seam_edges": int(self.seam_edges),
            "cuts": [list(map(int, c)) for c in self.cuts],
            "filled_holes": int(self.filled_holes),
            "open_holes": int(self.open_holes),
            "gliding_boundary_vertices": int(len(self.gliding_boundary)),
            "boundary_vertices": int(mesh.is_boundary_vertex.sum()),
            "seconds": self.seconds,
        }


# ---------------------------------------------------------------------------- directions


def _face_frames(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, 3) unit tangent b1 (along the first edge), b2 = n x b1, and the normal n."""
    P = design.vertices[design.triangles]
    n = design.face_normals
    b1 = P[:, 1] - P[:, 0]
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    return b1, np.cross(n, b1), n


def face_principal_frames(design: DesignSurface, *, radius: int = 5) -> tuple:
    """Principal curvatures and directions per triangle, in the triangle's plane.

    Parameters
    ----------
    design : a parametric surface's triangulation uses the exact fundamental forms at the
        triangle centroids; other meshes use libigl's per-vertex estimate, averaged over
        each triangle as shape operators.
    radius : libigl's neighbourhood size (mean edges).

    Returns
    -------
    k1, k2 : (t,) float, k1 >= k2 (1/model units, signed w.r.t. the triangle normals).
    e1 : (t, 3) float, unit direction of k1 in the triangle plane.
    """
    T = design.triangles
    if design.parametric is not None and design.uv is not None:
        uv = design.uv[T].mean(axis=1)
        k1, k2, d1, d2, n = design.parametric.principal_frames(uv[:, 0], uv[:, 1])
        side = np.sign(np.sum(n * design.face_normals, axis=1))[:, None, None]
        S = side * (k1[:, None, None] * d1[:, :, None] * d1[:, None, :]
                    + k2[:, None, None] * d2[:, :, None] * d2[:, None, :])
    else:
        d1, d2, v1, v2, _ = igl.principal_curvature(design.vertices, T, radius)
        # libigl's curvatures have the opposite sign to fabplan's (normal of the triangles)
        Sv = -(v1[:, None, None] * d1[:, :, None] * d1[:, None, :]
               + v2[:, None, None] * d2[:, :, None] * d2[:, None, :])
        S = Sv[T].mean(axis=1)
        bad = ~np.isfinite(S).all(axis=(1, 2))
        S[bad] = 0.0
    b1, b2, _ = _face_frames(design)
    s11 = np.einsum("ti,tij,tj->t", b1, S, b1)
    s12 = np.einsum("ti,tij,tj->t", b1, S, b2)
    s22 = np.einsum("ti,tij,tj->t", b2, S, b2)
    theta = 0.5 * np.arctan2(2 * s12, s11 - s22)
    half = 0.5 * np.hypot(s11 - s22, 2 * s12)
    mean = 0.5 * (s11 + s22)
    e1 = np.cos(theta)[:, None] * b1 + np.sin(theta)[:, None] * b2
    return mean + half, mean - half, e1


def _face_adjacency(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Interior edges as corner pairs (c0, c1) and their triangles (f, g)."""
    c0, c1 = _edge_corners(design.triangles, len(design.vertices))
    return c0, c1, c0 // 3, c1 // 3


def smooth_line_field(design: DesignSurface, e1: np.ndarray, weight: np.ndarray,
                      length: float) -> tuple[np.ndarray, np.ndarray]:
    """Smooth a line field per triangle, weighted by confidence.

    Minimizes ``sum_f w_f |X_f - D_f|^2 + kappa sum_(f,g) |X_f - X_g|^2`` over 3x3 tensors,
    with ``D_f = e1 e1^T - e2 e2^T`` (sign-free) and ``kappa`` giving a smoothing radius of
    `length`; one sparse factorization, six right-hand sides.

    Parameters
    ----------
    design : the surface.
    e1 : (t, 3) float, unit directions in the triangle planes.
    weight : (t,) float >= 0, confidence (e.g. ``|k1 - k2|``), normalized internally.
    length : smoothing length (model units); 0 keeps the field.

    Returns
    -------
    e1 : (t, 3) float, smoothed unit directions in the triangle planes.
    coherence : (t,) float in [0, 1], how well the neighbourhood agrees (0 at a
        singularity of the smoothed field).
    """
    b1, b2, n = _face_frames(design)
    e2 = np.cross(n, e1)
    D = e1[:, :, None] * e1[:, None, :] - e2[:, :, None] * e2[:, None, :]
    if length > 0:
        _, _, f, g = _face_adjacency(design)
        t = len(e1)
        centroid = design.vertices[design.triangles].mean(axis=1)
        spacing = float(np.linalg.norm(centroid[f] - centroid[g], axis=1).mean())
        kappa = (length / spacing) ** 2
        w = np.asarray(weight, dtype=np.float64)
        w = w / max(float(np.median(w[w > 0])) if np.any(w > 0) else 1.0, 1e-300)
        w = np.clip(w, 1e-3, 4.0)
        adj = sp.coo_matrix((np.ones(len(f)), (f, g)), shape=(t, t))
        adj = (adj + adj.T).tocsr()
        lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
        system = (sp.diags(w) + kappa * lap).tocsr()
        rhs = (D * w[:, None, None]).reshape(t, 9)[:, [0, 1, 2, 4, 5, 8]]
        sol = _solve_spd(system, rhs)
        D = sol[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(t, 3, 3)
    a = np.einsum("ti,tij,tj->t", b1, D, b1) - np.einsum("ti,tij,tj->t", b2, D, b2)
    b = 2 * np.einsum("ti,tij,tj->t", b1, D, b2)
    theta = 0.5 * np.arctan2(b, a)
    coherence = np.clip(0.5 * np.hypot(a, b), 0.0, 1.0)
    return np.cos(theta)[:, None] * b1 + np.sin(theta)[:, None] * b2, coherence


def comb_line_field(design: DesignSurface, e1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Give a line field consistent signs: XOR along a minimum spanning tree of the
    triangle adjacency weighted by ``1 - |e1_f . e1_g|`` (smooth steps first).

    Returns
    -------
    e1 : (t, 3) float, the combed field.
    seam : (e, 2) int, design vertices of the interior edges across which the combed field
        still flips (empty when the field is combable).
    """
    c0, _, f, g = _face_adjacency(design)
    t = len(e1)
    dot = np.sum(e1[f] * e1[g], axis=1)
    parent = _spanning_parent(t, f, g, 1.0 - np.abs(dot) + 1e-9)
    step = _edge_values(t, f, g, (dot < 0).astype(np.int64), parent)
    sign = 1 - 2 * xor_to_root(parent, step)
    e1 = e1 * sign[:, None]
    flips = np.sum(e1[f] * e1[g], axis=1) < 0
    T = design.triangles
    a = T.ravel()[c0[flips]]
    b = T[:, [1, 2, 0]].ravel()[c0[flips]]
    return e1, np.stack([a, b], axis=1)


def _spanning_parent(count: int, f: np.ndarray, g: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(count,) int, parent of every element in a minimum spanning forest of the pairs
    (f, g) with positive weights, -1 at the roots (one per component)."""
    graph = sp.coo_matrix((weight, (f, g)), shape=(count, count)).tocsr()
    tree = csgraph.minimum_spanning_tree(graph).tocoo()
    ncomp, label = csgraph.connected_components(tree, directed=False)
    root = count
    first = np.full(ncomp, count)
    np.minimum.at(first, label, np.arange(count))
    rows = np.r_[tree.row, np.full(ncomp, root)]
    cols = np.r_[tree.col, first]
    full = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(count + 1,) * 2).tocsr()
    _, pred = csgraph.breadth_first_order(full, root, directed=False, return_predecessors=True)
    parent = pred[:count].copy()
    parent[(parent == root) | (parent < 0)] = -1
    return parent


def line_field_index(design: DesignSurface, e1: np.ndarray) -> np.ndarray:
    """(n,) float, index of a line field around every interior vertex (turns: multiples of
    1/2; 0 where regular, NaN on the boundary).

    The rotation of the field across each edge around the vertex is measured against the
    edge itself (discrete parallel transport), reduced modulo a half turn, summed, and
    corrected by the angle defect.
    """
    V, T = design.vertices, design.triangles
    n, t = len(V), len(T)
    N = design.face_normals
    vert = T.ravel()
    w1 = T[:, [1, 2, 0]].ravel()
    w2 = T[:, [2, 0, 1]].ravel()
    face = np.repeat(np.arange(t), 3)
    u1 = V[w1] - V[vert]
    u2 = V[w2] - V[vert]
    e = e1[face]
    nn = N[face]
    A = np.arctan2(np.sum(np.cross(u1, e) * nn, axis=1), np.sum(u1 * e, axis=1))
    gamma = np.arctan2(np.linalg.norm(np.cross(u1, u2), axis=1), np.sum(u1 * u2, axis=1))
    B = A - gamma
    c0, c1 = _edge_corners(T, n)
    twin = np.full(3 * t, -1)
    twin[c0], twin[c1] = c1, c0
    # the corner (k+2) of a triangle owns the half-edge w2 -> v; its twin starts at v
    prev_corner = 3 * face + (np.arange(3 * t) % 3 + 2) % 3
    nxt = twin[prev_corner]
    has = nxt >= 0
    delta = np.zeros(3 * t)
    delta[has] = A[nxt[has]] - B[has]
    delta = delta - np.pi * np.round(delta / np.pi)
    open_corner = np.bincount(vert, weights=(~has).astype(float), minlength=n) > 0
    total = np.bincount(vert, weights=delta, minlength=n)
    defect = 2 * np.pi - np.bincount(vert, weights=gamma, minlength=n)
    index = np.round((total + defect) / np.pi) / 2
    index[open_corner] = np.nan
    return index


def snet_directions(e1: np.ndarray, normal: np.ndarray, angle_deg: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The two directions symmetric to the principal directions, meeting at `angle_deg`.

    Parameters
    ----------
    e1 : (t, 3) float, unit principal direction bisecting the angle.
    normal : (t, 3) float, unit normals.
    angle_deg : intersection angle (degrees, in (0, 180)).

    Returns
    -------
    t1, t2 : (t, 3) float, ``cos(a/2) e1 +- sin(a/2) e2`` with ``e2 = n x e1``.

    Examples
    --------
    >>> t1, t2 = snet_directions(np.array([[1.0, 0, 0]]), np.array([[0, 0, 1.0]]), 90.0)
    >>> np.round(t1, 6).tolist(), np.round(t2, 6).tolist()
    ([[0.707107, 0.707107, 0.0]], [[0.707107, -0.707107, 0.0]])
    """
    half = math.radians(angle_deg) / 2
    e2 = np.cross(normal, e1)
    return math.cos(half) * e1 + math.sin(half) * e2, math.cos(half) * e1 - math.sin(half) * e2


def complementary_directions(t: np.ndarray, e1: np.ndarray) -> np.ndarray:
    """(m, 3) float, the direction symmetric to `t` with respect to the principal directions:
    its reflection in the line of `e1` (Proposition 2.11), ``2 (t . e1) e1 - t``.

    Independent of the sign of `e1`.

    Examples
    --------
    >>> complementary_directions(np.array([[0.6, 0.8, 0.0]]), np.array([[1.0, 0, 0]])).tolist()
    [[0.6, -0.8, 0.0]]
    """
    return 2 * np.sum(t * e1, axis=1, keepdims=True) * e1 - t


# ---------------------------------------------------------------------------- prescribed family


def prescribed_family(design: DesignSurface, spec: str, panel_size: float, e1: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str, float]:
    """A prescribed first family and the directions of its S-net partner.

    Parameters
    ----------
    design : the surface.
    spec : ``"x"``, ``"y"`` or ``"z"`` (levels of a coordinate, about one panel apart along
        the partner family), ``"z:3.5"`` (levels every 3.5 model units, subdivided so that
        the spacing stays near the panel size), or a file of polylines: OBJ ``l``
        elements, or text rows ``x y z`` with blank lines between polylines, in order (the
        curves become consecutive levels, interpolated smoothly between them and
        subdivided like ``z:STEP``).
    panel_size : target spacing (model units).
    e1 : (t, 3) float, a principal direction per triangle (its sign does not matter).

    Returns
    -------
    phi : (n,) float, on the design vertices; its integer levels are the family.
    t : (t, 3) float, unit tangents of the prescribed family.
    s : (t, 3) float, unit tangents of the partner family, ``t`` reflected in ``e1``.
    description : what was prescribed and the level spacing, for the record.
    level_step : change of the prescribed function from one level to the next (model units
        for a coordinate; polyline numbers for polylines): level k is ``f = k * level_step``.
    """
    V = design.vertices
    axis = spec.split(":")[0]
    step = None
    if axis in ("x", "y", "z"):
        value = V[:, "xyz".index(axis)].copy()
        if ":" in spec:
            try:
                step = float(spec.split(":", 1)[1])
            except ValueError:
                raise InputError(f"--family {spec}: the level spacing must be a number") from None
            if not (step > 0 and math.isfinite(step)):
                raise InputError(f"--family {spec}: the level spacing must be positive")
        what = f"{axis} levels"
    else:
        curves = _read_polylines(spec)
        if len(curves) < 2:
            raise InputError(f"{spec}: at least two polylines are needed to prescribe a family")
        value, step, what = _interpolate_levels(design, curves), 1.0, f"{len(curves)} polylines"
    g = _gradient_vectors(design, value)
    normal = design.face_normals
    t = np.cross(normal, g)
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    if not np.any(norm > 0):
        raise InputError(f"--family {spec}: the prescribed function is constant on {design.name}")
    t /= np.maximum(norm, 1e-300)
    s = complementary_directions(t, e1)
    s /= np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-300)
    # change of the function per unit length along the partner family: the level spacing
    rate = np.abs(np.sum(g * s, axis=1))
    rate = float(np.median(rate[rate > 0])) if np.any(rate > 0) else 1.0
    if step is None:
        step, per_step = panel_size * rate, 1.0
    else:
        per_step = max(1.0, round(step / rate / panel_size))
    phi = value / step * per_step
    if np.ptp(phi) < 2.0:
        raise InputError(f"--family {spec}: fewer than three levels on {design.name}")
    return phi, t, s, f"{what} every {step / per_step:.6g} ({spec})", step / per_step


def _gradient_vectors(design, value) -> np.ndarray:
    G = igl.grad(design.vertices, design.triangles)
    t = len(design.triangles)
    g = G @ value
    return np.stack([g[:t], g[t:2 * t], g[2 * t:]], axis=1)


def _read_polylines(spec: str) -> list:
    path = Path(spec)
    if not path.is_file():
        raise InputError(f"--family {spec}: not x, y, z nor a file of polylines")
    try:
        text = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError):
        raise InputError(f"{spec}: not a text file of polylines") from None
    curves: list = []
    if path.suffix.lower() == ".obj":
        verts, lines = [], []
        for lineno, line in enumerate(text.splitlines(), start=1):
            parts = line.split()
            if parts[:1] == ["v"]:
                try:
                    verts.append([float(p) for p in parts[1:4]])
                except ValueError:
                    raise InputError(f"{spec}:{lineno}: malformed vertex line") from None
            elif parts[:1] == ["l"]:
                lines.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
        verts = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
        curves = [verts[idx] for idx in lines if len(idx) >= 2]
    else:
        block: list = []
        for lineno, line in enumerate(text.splitlines() + [""], start=1):
            line = line.split("#")[0].strip()
            if not line:
                if len(block) >= 2:
                    curves.append(np.asarray(block))
                block = []
                continue
            try:
                xyz = [float(p) for p in line.replace(",", " ").split()]
            except ValueError:
                raise InputError(f"{spec}:{lineno}: expected 'x y z'") from None
            if len(xyz) != 3:
                raise InputError(f"{spec}:{lineno}: expected 'x y z'")
            block.append(xyz)
    if not all(np.isfinite(c).all() for c in curves):
        raise InputError(f"{spec}: non-finite polyline coordinates")
    return curves


def _interpolate_levels(design: DesignSurface, curves: list) -> np.ndarray:
    """A smooth function equal to k on polyline k: least squares with the squared
    Laplacian (linear growth beyond the first and last polyline)."""
    V, T = design.vertices, design.triangles
    samples, values = [], []
    spacing = 0.5 * design.mean_edge_length
    for k, c in enumerate(curves):
        seg = np.linalg.norm(np.diff(c, axis=0), axis=1)
        s = np.r_[0.0, np.cumsum(seg)]
        count = max(2, int(s[-1] / spacing))
        at = np.linspace(0.0, s[-1], count)
        samples.append(np.stack([np.interp(at, s, c[:, i]) for i in range(3)], axis=1))
        values.append(np.full(count, float(k)))
    P = np.concatenate(samples)
    target = np.concatenate(values)
    sq, tri, foot = igl.point_mesh_squared_distance(P, V, T)
    near = np.sqrt(sq) <= 2 * design.mean_edge_length
    if near.sum() < 2 * len(curves):
        raise InputError("the prescribed polylines do not lie on the design surface")
    tri, foot, target = tri[near], foot[near], target[near]
    bary = igl.barycentric_coordinates(foot, V[T[tri, 0]], V[T[tri, 1]], V[T[tri, 2]])
    rows = np.repeat(np.arange(len(tri)), 3)
    C = sp.csr_matrix((bary.ravel(), (rows, T[tri].ravel())), shape=(len(tri), len(V)))
    L = igl.cotmatrix(V, T)
    M = igl.massmatrix(V, T, igl.MASSMATRIX_TYPE_VORONOI)
    Minv = sp.diags(1.0 / np.maximum(M.diagonal(), 1e-300))
    bilap = (L.T @ Minv @ L).tocsr()
    weight = float(bilap.diagonal().mean()) * 1e2
    system = (bilap + weight * (C.T @ C) + 1e-10 * weight * sp.eye(len(V))).tocsr()
    return _solve_spd(system, (weight * (C.T @ target))[:, None])[:, 0]


# ---------------------------------------------------------------------------- cuts


def _boundary_circulation(design: DesignSurface, loops: list, targets: list) -> np.ndarray:
    """(loops, k) float, circulation of each target gradient field (t, 3) along each loop."""
    V, T = design.vertices, design.triangles
    n, t = len(V), len(T)
    c0, c1 = _edge_corners(T, n)
    has_twin = np.zeros(3 * t, bool)
    has_twin[c0] = has_twin[c1] = True
    corner = np.flatnonzero(~has_twin)
    a, b = T.ravel()[corner], T[:, [1, 2, 0]].ravel()[corner]
    loop_of = np.full(n, -1)
    for i, loop in enumerate(loops):
        loop_of[loop] = i
    out = np.zeros((len(loops), len(targets)))
    edge = V[b] - V[a]
    ok = loop_of[a] >= 0
    for k, g in enumerate(targets):
        contrib = np.sum(g[corner // 3] * edge, axis=1)
        out[:, k] = np.bincount(loop_of[a[ok]], weights=contrib[ok], minlength=len(loops))
    return out


def _cut_paths(design: DesignSurface, starts: list, avoid: np.ndarray) -> list:
    """Disjoint shortest edge paths from each start (an inner boundary loop, or a singular
    vertex) to the outer boundary loop, avoiding the `avoid` vertices (seams).

    Returns a list of (k,) int vertex paths, each from its start to the outer loop.
    """
    V, T = design.vertices, design.triangles
    n = len(V)
    loops = design.boundary_loops
    if not loops:
        return []
    e = np.unique(np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1), axis=0)
    length = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    used = np.asarray(avoid, bool).copy()
    paths = []
    outer = loops[0]
    for inner in starts:
        used[inner] = False      # a singular vertex may end a seam: start from it anyway
        ok = ~(used[e[:, 0]] | used[e[:, 1]])
        graph = sp.coo_matrix((length[ok], (e[ok, 0], e[ok, 1])), shape=(n, n)).tocsr()
        dist, pred, _ = csgraph.dijkstra(graph, directed=False, indices=outer, min_only=True,
                                         return_predecessors=True)
        target = inner[np.argmin(dist[inner])]
        if not np.isfinite(dist[target]):
            continue
        parent = np.where(pred >= 0, pred, -1)
        depth = _depth(parent)
        # the path: ancestors of the target (hop distance to it along the tree adds up)
        tree = sp.coo_matrix((np.ones(int((parent >= 0).sum())),
                              (np.flatnonzero(parent >= 0), parent[parent >= 0])), shape=(n, n))
        hops = csgraph.shortest_path(tree, directed=False, unweighted=True, indices=target)
        on_path = np.flatnonzero(np.isfinite(hops) & (depth + hops == depth[target]))
        path = on_path[np.argsort(-depth[on_path])]
        used[path] = True
        paths.append(path)
    return paths


def _depth(parent: np.ndarray) -> np.ndarray:
    """(m,) int, number of steps to the root in a forest given by parent pointers."""
    depth = (parent >= 0).astype(np.int64)
    ptr = parent.copy()
    while np.any(ptr >= 0):
        act = ptr >= 0
        depth[act] += depth[ptr[act]]
        ptr[act] = ptr[ptr[act]]
    return depth


@dataclass
class _CutMesh:
    """The design mesh cut open along translation cuts and field seams.

    Every design vertex on a cut has several copies; one (the master) carries the vertex's
    unknown, another is ``sign * master + jumps``: ``+master + J`` across a translation cut
    (a loop around which the grid closes up with an integer shift), ``-master + c`` across
    a seam of the line field (the combed field flips there, and so do both parameters).
    Copies where cuts branch or cross get unknowns of their own.
    """

    triangles: np.ndarray       # (t, 3) copy ids
    copy_vertex: np.ndarray     # (c,) design vertex of each copy
    sign: np.ndarray            # (c,) +1 / -1 relative to the master, 0 for free copies
    side: np.ndarray            # (c, p) coefficient of each translation jump
    seam: np.ndarray            # (c,) seam component whose constant applies, or -1
    paths: int
    seams: int

    def substitution(self) -> tuple[sp.csr_matrix, int]:
        """(c, m) copies from unknowns ``[vertices, free copies, jumps, seam constants]``,
        and the number m - n of trailing jump columns."""
        n = int(self.copy_vertex.max()) + 1
        c = len(self.copy_vertex)
        free = np.flatnonzero(self.sign == 0)
        bound = np.flatnonzero(self.sign != 0)
        nfree = len(free)
        rows = [bound, free]
        cols = [self.copy_vertex[bound], n + np.arange(nfree)]
        vals = [self.sign[bound].astype(np.float64), np.ones(nfree)]
        r, k = np.nonzero(self.side[bound])
        rows.append(bound[r])
        cols.append(n + nfree + k)
        vals.append(self.side[bound][r, k])
        flipped = bound[self.seam[bound] >= 0]
        rows.append(flipped)
        cols.append(n + nfree + self.paths + self.seam[flipped])
        vals.append(np.ones(len(flipped)))
        m = n + nfree + self.paths + self.seams
        S = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(c, m))
        return S, self.paths + self.seams


def _cut_mesh(design: DesignSurface, paths: list, seam_edges: np.ndarray,
              e1: np.ndarray) -> _CutMesh:
    """Cut the design mesh open along translation `paths` and the field's `seam_edges`.

    Parameters
    ----------
    paths : list of (k,) int vertex paths (each from an inner boundary loop outwards).
    seam_edges : (s, 2) int, design edges across which the combed field flips.
    e1 : (t, 3) float, the combed field (tells which side of a seam a copy is on).
    """
    T = design.triangles
    n, t = len(design.vertices), len(T)
    a = T.ravel()
    c0, c1 = _edge_corners(T, n)
    ea, eb = a[c0], a[c1]        # c0 owns the half-edge ea -> eb, c1 the reverse one
    key = np.minimum(ea, eb) * n + np.maximum(ea, eb)
    path_key = [np.minimum(p[:-1], p[1:]) * n + np.maximum(p[:-1], p[1:]) for p in paths]
    seam_key = np.minimum(seam_edges[:, 0], seam_edges[:, 1]) * n + \
        np.maximum(seam_edges[:, 0], seam_edges[:, 1])
    keep = ~np.isin(key, np.concatenate(path_key + [seam_key]))

    def nxt(c):
        return 3 * (c // 3) + (c % 3 + 1) % 3

    k0, k1 = c0[keep], c1[keep]
    src = np.r_[k0, nxt(k0)]
    dst = np.r_[nxt(k1), k1]
    adj = sp.coo_matrix((np.ones(len(src)), (src, dst)), shape=(3 * t,) * 2)
    count, corner_copy = csgraph.connected_components(adj, directed=False)
    copy_vertex = np.zeros(count, np.int64)
    copy_vertex[corner_copy] = a
    copies = np.bincount(copy_vertex, minlength=n)
    master = np.full(n, count)
    np.minimum.at(master, copy_vertex, np.arange(count))
    is_master = master[copy_vertex] == np.arange(count)
    # which side of the cut: the field in the copy's triangles against the master's
    field = np.zeros((count, 3))
    np.add.at(field, corner_copy, e1[np.arange(3 * t) // 3])
    parity = np.sign(np.sum(field * field[master[copy_vertex]], axis=1))
    side = np.zeros((count, len(paths)))
    hb = T[:, [1, 2, 0]].ravel()
    on_path = np.zeros(n, bool)
    for i, p in enumerate(paths):
        # corners owning a half-edge p[k+1] -> p[k] are in the right-hand triangles
        right = np.flatnonzero(np.isin(a * n + hb, p[1:] * n + p[:-1]))
        side[corner_copy[right], i] = 1.0
        side[corner_copy[nxt(right)], i] = 1.0
        on_path[p] = True
    side -= side[master[copy_vertex]]
    on_seam = np.zeros(n, bool)
    on_seam[seam_edges.ravel()] = True
    seam_label = np.full(n, -1)
    nseam = 0
    if len(seam_edges):
        graph = sp.coo_matrix((np.ones(len(seam_edges)), (seam_edges[:, 0], seam_edges[:, 1])),
                              shape=(n, n))
        _, label = csgraph.connected_components(graph, directed=False)
        used, seam_label[on_seam] = np.unique(label[on_seam], return_inverse=True)
        nseam = len(used)
    v = copy_vertex
    sign = np.where(is_master, 1.0, 0.0)
    plain_path = ~is_master & on_path[v] & ~on_seam[v] & (copies[v] == 2) & (parity > 0)
    plain_seam = ~is_master & on_seam[v] & ~on_path[v] & (copies[v] == 2) & (parity < 0)
    sign[plain_path] = 1.0
    sign[plain_seam] = -1.0
    seam = np.where(plain_seam, seam_label[v], -1)
    side[sign <= 0] = 0.0
    return _CutMesh(corner_copy.reshape(-1, 3), copy_vertex, sign, side, seam, len(paths), nseam)


# ---------------------------------------------------------------------------- integration


def _solve_spd(system: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve a sparse SPD system for the columns of `rhs` (one factorization)."""
    upper = sp.triu(system, format="csr")
    upper.sum_duplicates()
    upper.sort_indices()
    solver = SparseSPDSolver()
    solver.factor(upper)
    return np.stack([solver.solve(np.ascontiguousarray(rhs[:, k])) for k in range(rhs.shape[1])],
                    axis=1)


def integrate_directions(vertices: np.ndarray, triangles: np.ndarray, substitution: sp.spmatrix,
                         rows: list, free_jumps: int = 0) -> np.ndarray:
    """Least-squares scalar field with prescribed directional derivatives per triangle.

    Minimizes ``sum_rows sum_f w_f (d_f . grad u_f - value_f)^2`` over the unknowns ``x``
    with ``u = substitution @ x`` on the (cut) mesh.

    Parameters
    ----------
    vertices : (c, 3) float, vertex copies of the cut mesh.
    triangles : (t, 3) int, triangles on the copies.
    substitution : (c, m) sparse, copies from unknowns (vertex values and jumps).
    rows : list of (direction (t, 3), value (t,), weight (t,)).
    free_jumps : number of trailing unknowns that are jumps (not regularized).

    Returns
    -------
    x : (m,) float
    """
    G = igl.grad(vertices, triangles)
    t = len(triangles)
    blocks, rhs = [], []
    for d, value, w in rows:
        s = np.sqrt(w)
        D = (sp.diags(s * d[:, 0]) @ G[:t] + sp.diags(s * d[:, 1]) @ G[t:2 * t]
             + sp.diags(s * d[:, 2]) @ G[2 * t:])
        blocks.append(D @ substitution)
        rhs.append(s * value)
    A = sp.vstack(blocks).tocsr()
    b = np.concatenate(rhs)
    normal = (A.T @ A).tocsr()
    m = normal.shape[0]
    reg = np.full(m, 1e-9 * float(normal.diagonal().mean()))
    if free_jumps:
        reg[m - free_jumps:] = 1e-12 * float(normal.diagonal().mean())
    return _solve_spd(normal + sp.diags(reg), (A.T @ b)[:, None])[:, 0]


# ---------------------------------------------------------------------------- extraction


@dataclass
class _Points:
    key: np.ndarray        # (p, 2) int
    position: np.ndarray   # (p, 3) float
    triangle: np.ndarray   # (p,) int


def _lattice_points(P2: np.ndarray, X3: np.ndarray, shift: float) -> _Points:
    """Points ``(i + shift, j + shift)`` (i, j integers) inside each parameter triangle.

    Parameters
    ----------
    P2 : (t, 3, 2) float, parameters of the triangle corners (orientation-preserving
        triangles only).
    X3 : (t, 3, 3) float, positions of the corners.
    """
    lo = np.ceil(P2.min(axis=1) - shift - 1e-9).astype(np.int64)
    hi = np.floor(P2.max(axis=1) - shift + 1e-9).astype(np.int64)
    nx, ny = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = nx * ny
    tri = np.repeat(np.arange(len(P2)), count)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    i = lo[tri, 0] + local // np.maximum(ny[tri], 1)
    j = lo[tri, 1] + local % np.maximum(ny[tri], 1)
    q = np.stack([i, j], axis=1) + shift
    a, b, c = P2[tri, 0], P2[tri, 1], P2[tri, 2]
    v0, v1, v2 = b - a, c - a, q - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    l1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
    l2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    l0 = 1 - l1 - l2
    inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
    bary = np.stack([l0, l1, l2], axis=1)[inside]
    tri = tri[inside]
    pos = np.einsum("pk,pkj->pj", bary, X3[tri])
    return _Points(np.stack([i, j], axis=1)[inside], pos, tri)


class _KeyTable:
    """Lookup of points by integer key, several points per key told apart by position."""

    def __init__(self, key: np.ndarray, position: np.ndarray, ids: np.ndarray):
        self.base = key.min(axis=0) - 4 if len(key) else np.zeros(2, np.int64)
        self.width = int(np.ptp(key[:, 1])) + 9 if len(key) else 1
        code = self._code(key)
        order = np.argsort(code, kind="stable")
        self.code, self.position, self.ids = code[order], position[order], ids[order]
        starts = np.searchsorted(self.code, self.code, side="left")
        ends = np.searchsorted(self.code, self.code, side="right")
        self.multiplicity = int((ends - starts).max()) if len(code) else 0

    def _code(self, key):
        k = key - self.base
        return k[:, 0] * self.width + k[:, 1]

    def find(self, key: np.ndarray, near: np.ndarray, radius: float) -> np.ndarray:
        """(m,) int, id of the point with `key` nearest to `near` within `radius`, or -1."""
        k = key - self.base
        valid = (k[:, 1] >= 0) & (k[:, 1] < self.width)
        code = k[:, 0] * self.width + k[:, 1]
        start = np.searchsorted(self.code, code, side="left")
        end = np.searchsorted(self.code, code, side="right")
        best = np.full(len(key), -1)
        best_d = np.full(len(key), radius)
        for m in range(self.multiplicity):
            at = start + m
            ok = valid & (at < end)
            d = np.full(len(key), np.inf)
            d[ok] = np.linalg.norm(self.position[at[ok]] - near[ok], axis=1)
            better = d < best_d
            best[better] = self.ids[at[better]]
            best_d[better] = d[better]
        return best


def extract_quads(P2: np.ndarray, X3: np.ndarray, normals: np.ndarray, panel_size: float,
                  transitions: list, settings: LayoutSettings) -> tuple:
    """Quads on the integer points of a parametrization.

    Parameters
    ----------
    P2 : (t, 3, 2) float, ``(phi, psi)`` at the corners of every triangle (cut mesh).
    X3 : (t, 3, 3) float, corner positions.
    normals : (t, 3) float, unit triangle normals.
    panel_size : target edge length (model units).
    transitions : list of (sign, (2,) offset): the parameters ``q`` on one side of a cut
        or seam are ``sign * p + offset`` of those ``p`` on the other (a translation by an
        integer vector across a loop cut, a half turn ``c - p`` across a seam).
    settings : edge bounds of accepted quads.

    Returns
    -------
    vertices : (n, 3) float, on the triangles.
    quads : (q, 4) int, counter-clockwise about the surface normal.
    keys : (n, 2) int, integer parameters of every vertex (one of them for a vertex on a
        cut).
    """
    h = panel_size
    e0, e1 = P2[:, 1] - P2[:, 0], P2[:, 2] - P2[:, 0]
    area = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
    # triangles the map folds over or squeezes are not trusted
    X = X3
    area3 = 0.5 * np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    good = area > 1e-3 * area3 / h**2
    keep = np.flatnonzero(good)
    nodes = _lattice_points(P2[keep], X3[keep], 0.0)
    centres = _lattice_points(P2[keep], X3[keep], 0.5)
    if len(nodes.key) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64)
    # one vertex per distinct point (points on shared edges and on the cuts coincide)
    tree = cKDTree(nodes.position)
    pairs = tree.query_pairs(1e-6 * h, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                          shape=(len(nodes.key),) * 2)
    _, vertex_of = csgraph.connected_components(graph, directed=False)
    first = np.full(vertex_of.max() + 1, len(vertex_of))
    np.minimum.at(first, vertex_of, np.arange(len(vertex_of)))
    vertices = nodes.position[first]
    normal_of = normals[keep][nodes.triangle[first]]
    entries = np.unique(np.c_[nodes.key, vertex_of], axis=0)
    keys = np.zeros((len(vertices), 2), np.int64)
    keys[entries[::-1, 2]] = entries[::-1, :2]
    table = _KeyTable(entries[:, :2], vertices[entries[:, 2]], entries[:, 2])
    centre_table = _KeyTable(np.floor(centres.key).astype(np.int64), centres.position,
                             np.arange(len(centres.key)))
    base, v0 = entries[:, :2], entries[:, 2]
    steps = np.array([[1, 0], [1, 1], [0, 1]])
    maps = [(1, np.zeros(2))]
    for sign, shift in transitions:
        shift = np.asarray(shift, dtype=np.float64)
        maps += [(1, shift), (1, -shift)] if sign > 0 else [(-1, shift)]
    maps = [(sign, np.round(shift).astype(np.int64)) for sign, shift in maps]
    corners = [v0]
    reach = 2.5 * h
    for step in steps:
        found = np.full(len(base), -1)
        for sign, shift in maps:
            miss = found < 0
            found[miss] = table.find(sign * (base[miss] + step) + shift, vertices[v0[miss]], reach)
        corners.append(found)
    quads = np.stack(corners, axis=1)
    ok = (quads >= 0).all(axis=1)
    quads = quads[ok]
    # the unit square's centre must lie on the surface, near the corners' centroid
    centroid = vertices[quads].mean(axis=1)
    found = np.full(len(quads), -1)
    for sign, shift in maps:
        miss = found < 0
        # the centre p + 1/2 maps to sign (p + 1/2) + shift, whose key is its floor
        key = sign * base[ok][miss] + shift - (1 if sign < 0 else 0)
        found[miss] = centre_table.find(key, centroid[miss], 0.5 * h)
    quads = quads[found >= 0]
    quads = quads[np.all(np.diff(np.sort(quads, axis=1), axis=1) > 0, axis=1)]
    Q = vertices[quads]
    edge = np.linalg.norm(Q - np.roll(Q, -1, axis=1), axis=2)
    fold = np.sum(np.cross(Q[:, 2] - Q[:, 0], Q[:, 3] - Q[:, 1]) * normal_of[quads].sum(axis=1),
                  axis=1) <= 0
    good = (edge.min(axis=1) >= settings.min_edge * h) & (edge.max(axis=1) <= settings.max_edge * h)
    quads = quads[good & ~fold]
    quads = np.unique(quads[np.lexsort(quads.T[::-1])], axis=0) if len(quads) else quads
    # the same quad found from both sides of a cut
    _, first_q = np.unique(np.sort(quads, axis=1), axis=0, return_index=True)
    return vertices, quads[np.sort(first_q)], keys


def _clean_quads(vertices: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest edge-connected piece, no edge used twice in one direction or by three faces,
    no pinched vertex.

    Returns
    -------
    used : (n,) bool, the vertices still in use.
    quads : (q, 4) int, the kept quads, numbered over the used vertices.
    """
    for _ in range(50):
        if len(quads) == 0:
            break
        n = len(vertices)
        a, b = quads.ravel(), np.roll(quads, -1, axis=1).ravel()
        face = np.repeat(np.arange(len(quads)), 4)
        und = np.minimum(a, b) * n + np.maximum(a, b)
        _, inv, cnt = np.unique(und, return_inverse=True, return_counts=True)
        dkey = a * n + b
        order = np.argsort(dkey, kind="stable")
        skey = dkey[order]
        dup = np.zeros(len(dkey), bool)
        dup[order[1:][skey[1:] == skey[:-1]]] = True
        bad = np.zeros(len(quads), bool)
        bad[face[(cnt[inv] > 2) | dup]] = True
        pos = np.clip(np.searchsorted(skey, b * n + a), 0, len(skey) - 1)
        twin = np.where(skey[pos] == b * n + a, order[pos], -1)
        # pinched vertices: more than one outgoing boundary half-edge
        pinch = np.bincount(a[twin < 0], minlength=n) > 1
        if pinch.any():
            # drop the faces at pinched vertices that have the fewest neighbours
            neighbours = np.bincount(face[twin >= 0], minlength=len(quads))
            at_pinch = np.zeros(len(quads), bool)
            at_pinch[face[pinch[a]]] = True
            bad |= at_pinch & (neighbours == neighbours[at_pinch].min())
        inner = twin >= 0
        adj = sp.coo_matrix((np.ones(int(inner.sum())), (face[inner], face[twin[inner]])),
                            shape=(len(quads),) * 2)
        ncomp, label = csgraph.connected_components(adj, directed=False)
        if ncomp > 1:
            bad |= label != np.argmax(np.bincount(label))
        if not bad.any():
            break
        quads = quads[~bad]
    used = np.zeros(len(vertices), bool)
    used[quads.ravel()] = True
    remap = np.cumsum(used) - 1
    return used, remap[quads]


def _fill_holes(vertices: np.ndarray, faces: list, design: DesignSurface, panel_size: float,
                max_edges: int) -> tuple[np.ndarray, list, int, int]:
    """Close the interior holes of a layout (around singularities of the field).

    Holes bounded by 4 or 6 edges become one or two quads; larger ones a fan of quads
    (and one triangle when odd) around a new vertex on the surface. Holes more than
    `max_edges` long stay open; loops near the design boundary are the layout's own
    boundary and are not touched.

    Returns
    -------
    vertices, faces : the closed layout.
    filled, left_open : counts of interior holes.
    """
    from .constraints.closeness import closest_points_on_polylines

    mesh = QuadMesh(vertices, faces)
    loops = [np.asarray(loop, dtype=np.int64) for loop in igl.boundary_loop_all(mesh.triangles())]
    curves = design.boundary_curves()
    be = mesh.boundary_edges
    forward = set(zip(be[:, 0].tolist(), be[:, 1].tolist(), strict=True))
    new_faces, new_vertices = list(faces), [vertices]
    count = len(vertices)
    filled = left_open = 0
    for loop in loops:
        if curves:
            foot, _ = closest_points_on_polylines(vertices[loop], curves)
            if np.linalg.norm(foot - vertices[loop], axis=1).min() < panel_size:
                continue
        elif len(loops) == 1:
            continue
        m = len(loop)
        if m > max_edges:
            left_open += 1
            continue
        if (int(loop[0]), int(loop[1])) in forward:
            loop = loop[::-1]      # new faces run against the hole's boundary half-edges
        if m == 4:
            new_faces.append(loop)
        elif m == 6:
            new_faces += [loop[[0, 1, 2, 3]], loop[[3, 4, 5, 0]]]
        else:
            centre, _, _ = design.reference.closest_points(vertices[loop].mean(axis=0)[None])
            new_vertices.append(centre)
            new_faces += [np.array([count, loop[k], loop[k + 1], loop[(k + 2) % m]])
                          for k in range(0, m - 1, 2)]
            if m % 2:
                new_faces.append(np.array([count, loop[m - 1], loop[0]]))
            count += 1
        filled += 1
    return np.concatenate(new_vertices), new_faces, filled, left_open


# ---------------------------------------------------------------------------- pipeline


def layout_surface(design: DesignSurface, panel_size: float, *, angle: float = 90.0,
                   family: str | None = None,
                   settings: LayoutSettings | None = None) -> SurfaceLayout:
    """Lay out an initial S-net on a design surface.

    Parameters
    ----------
    design : the surface.
    panel_size : target edge length (model units).
    angle : intersection angle of the two families in degrees (ignored with `family`).
    family : a prescribed first family (see `prescribed_family`); the second family is
        the complementary one that makes an S-net.
    settings : `LayoutSettings`.

    Returns
    -------
    SurfaceLayout

    Raises
    ------
    InputError
        For a panel size that is not positive or too large for the surface, an angle
        outside (0, 180), or a layout without a single regular vertex.
    """
    s = settings or LayoutSettings()
    h = float(panel_size)
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"--panel-size must be a positive length, got {panel_size}")
    if not 0 < angle < 180:
        raise InputError(f"--angle must lie strictly between 0 and 180 degrees, got {angle}")
    if s.bisector not in ("max", "min"):
        raise InputError(f"bisector must be 'max' or 'min', got {s.bisector!r}")
    expected = design.area / (h * h * math.sin(math.radians(angle)))
    if expected < 9:
        raise InputError(f"{design.name}: panel size {h:g} is too large for the surface (area "
                         f"{design.area:.4g}: about {expected:.1f} panels; at most "
                         f"{math.sqrt(design.area / 9):.4g} gives a 3 x 3 patch)")
    seconds: dict = {}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        seconds[name] = round(now - clock, 4)
        clock = now

    V, T = design.vertices, design.triangles
    normal = design.face_normals
    k1, k2, e1 = face_principal_frames(design, radius=s.curvature_radius)
    if s.bisector == "min":
        e1 = np.cross(normal, e1)
    lap("principal_directions")
    e1, _ = smooth_line_field(design, e1, np.abs(k1 - k2) * design.face_areas, s.smoothing * h)
    lap("smoothing")
    e1, seam = comb_line_field(design, e1)
    index = line_field_index(design, e1)
    singular = np.flatnonzero(np.nan_to_num(index) != 0)
    lap("combing")

    mu = s.scale_weight
    area = design.face_areas / design.face_areas.mean()
    # near umbilics every direction is nearly symmetric to the principal ones: alignment
    # counts less there, and hardly at all within two panels of a point the field turns
    # around (a rotationally symmetric umbilic, where the grid would shrink to a point)
    anisotropy = np.abs(k1 - k2)
    confidence = np.clip(anisotropy / max(float(np.median(anisotropy)), 1e-300), 0.1, 1.0)
    whole_turns, turn_starts = _whole_turns(V, singular, index[singular], h)
    if whole_turns.size and family is None:
        centroid = V[T].mean(axis=1)
        near, _ = cKDTree(V[whole_turns]).query(centroid, distance_upper_bound=2 * h)
        area = np.where(np.isfinite(near), 1e-3 * area, area)
    description = level_step = None
    if family is None:
        t1, t2 = snet_directions(e1, normal, angle)
        align = confidence * area
        fields = {
            "phi": [(h * t1, np.zeros(len(T)), align), (h * t2, np.ones(len(T)), mu * area)],
            "psi": [(h * t2, np.zeros(len(T)), align), (h * t1, np.ones(len(T)), mu * area)],
        }
        targets = [_dual(normal, t1, t2) / h, _dual(normal, t2, t1) / h]
        prescribed = None
    else:
        prescribed, t, s_dir, description, level_step = prescribed_family(design, family, h, e1)
        fields = {"psi": [(h * s_dir, np.zeros(len(T)), area), (h * t, np.ones(len(T)), mu * area)]}
        targets = [np.zeros_like(t), _dual(normal, s_dir, t, clip=True) / h]
    lap("directions")

    # cut open the boundary loops around which the field turns
    loops = design.boundary_loops
    paths = []
    starts = []
    if len(loops) > 1:
        circulation = _boundary_circulation(design, loops, targets)
        starts = [loops[i] for i in range(1, len(loops)) if np.abs(circulation[i]).max() >= 0.5]
    if prescribed is None:
        # a field turning a whole turn around a point (a rotationally symmetric umbilic)
        # gets a cut like a hole, with a shift of the grid across it
        starts += [np.array([v]) for v in turn_starts]
    if starts:
        avoid = np.zeros(len(V), bool)
        avoid[seam.ravel()] = True
        paths = _cut_paths(design, starts, avoid)
    cut = _cut_mesh(design, paths, seam if prescribed is None else np.zeros((0, 2), np.int64), e1)
    S, njump = cut.substitution()
    Tc, Xc = cut.triangles, V[cut.copy_vertex]
    lap("cuts")

    values, constants = {}, {}
    for name, rows in fields.items():
        x = integrate_directions(Xc, Tc, S, rows, njump)
        if njump:
            # integer jumps make the integer grid match across the cuts and seams
            fixed = np.round(x[-njump:])
            shift = S[:, -njump:] @ fixed
            moved = [(d, v - _directional(Xc, Tc, shift, d), w) for d, v, w in rows]
            x = np.r_[integrate_directions(Xc, Tc, S[:, :-njump].tocsr(), moved), fixed]
        values[name] = S @ x
        constants[name] = x[len(x) - njump:]
    if prescribed is not None:
        values["phi"] = prescribed[cut.copy_vertex]
        constants["phi"] = np.zeros(njump)
    P2 = np.stack([values["phi"][Tc], values["psi"][Tc]], axis=-1)     # (t, 3, 2)
    e0, e1p = P2[:, 1] - P2[:, 0], P2[:, 2] - P2[:, 0]
    if np.sum(design.face_areas * np.sign(e0[:, 0] * e1p[:, 1] - e0[:, 1] * e1p[:, 0])) < 0:
        P2[..., 1] *= -1
        constants["psi"] = -constants["psi"]
    jumps = np.stack([constants["phi"], constants["psi"]], axis=1).astype(np.int64)
    transitions = [(1, j) for j in jumps[:cut.paths] if np.any(j)] + \
        [(-1, c) for c in jumps[cut.paths:]]
    lap("integration")

    best = None
    # a seam maps phi to c - phi: only half-integer shifts keep the lattice on itself
    count = 2 if cut.seams else s.offsets
    shifts = np.arange(count) / count
    trials = [(a, b) for a in shifts for b in shifts]
    if prescribed is not None:
        trials = [(0.0, b) for b in shifts]
    X3 = V[T]
    for off in trials:
        moved = [(sign, shift + (2 * np.asarray(off) if sign < 0 else 0)) for sign, shift in transitions]
        verts, quads, keys = extract_quads(P2 + np.asarray(off), X3, normal, h, moved, s)
        if whole_turns.size and len(quads):
            # the grid degenerates towards a point the field turns around: leave a hole
            gap, _ = cKDTree(V[whole_turns]).query(verts[quads].mean(axis=1))
            quads = quads[gap > 2 * h]
        used, quads = _clean_quads(verts, quads)
        if best is None or len(quads) > len(best[1]):
            best = (verts[used], quads, keys[used], off)
    verts, quads, keys, off = best
    lap("extraction")
    if len(quads) == 0:
        raise InputError(f"{design.name}: no quad could be laid out at panel size {h:g} "
                         "(too large for the surface, or a degenerate direction field)")
    faces = list(quads)
    verts, faces, filled, opened = _fill_holes(verts, faces, design, h, s.fill_holes_up_to)
    vertex_keys = np.full((len(verts), 2), np.nan)
    vertex_keys[:len(keys)] = keys
    mesh = QuadMesh(verts, faces, name=f"layout-{Path(design.name).stem}")
    if len(mesh.stars) == 0:
        raise InputError(f"{design.name}: panel size {h:g} is too large for the surface (the "
                         "layout has no interior vertex with four quads)")
    lap("holes")
    gliding = _near_design_boundary(mesh, design, s.boundary_snap * h, prescribed,
                                    vertex_keys[:, 0])
    lap("boundary")
    return SurfaceLayout(
        mesh=mesh, design=design, panel_size=h,
        angle_deg=None if family is not None else float(angle),
        parameters=P2 + np.asarray(off), singular_points=V[singular],
        singular_index=index[singular], seam_edges=len(seam),
        cuts=[(int(sign), *np.round(shift, 6).tolist()) for sign, shift in transitions],
        filled_holes=filled, open_holes=opened,
        gliding_boundary=gliding, vertex_keys=vertex_keys,
        prescribed=prescribed, family=description, level_step=level_step, seconds=seconds)


def _whole_turns(V: np.ndarray, singular: np.ndarray, index: np.ndarray,
                 radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Singular vertices in clusters (closer than `radius`) whose indices add up to whole
    turns, and one vertex per such cluster.

    A rotationally symmetric umbilic (index 1) often shows up as two half-turn
    singularities a few triangles apart; together they make the field turn once.
    """
    if singular.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pairs = cKDTree(V[singular]).query_pairs(radius, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                          shape=(len(singular),) * 2)
    _, label = csgraph.connected_components(graph, directed=False)
    total = np.bincount(label, weights=index)
    whole = np.abs(total) >= 1
    members = singular[whole[label]]
    first = np.full(len(total), len(singular))
    np.minimum.at(first, label, np.arange(len(singular)))
    return members, singular[first[whole]]


def _dual(normal: np.ndarray, along: np.ndarray, across: np.ndarray, clip: bool = False) -> np.ndarray:
    """(t, 3) vector g in the tangent plane with ``g . along = 0`` and ``g . across = 1``."""
    g = np.cross(normal, along)
    denom = np.sum(g * across, axis=1, keepdims=True)
    if clip:
        denom = np.where(np.abs(denom) < 0.1, 0.1 * np.sign(denom + 1e-300), denom)
    return g / denom


def _directional(Xc, Tc, u, d) -> np.ndarray:
    """(t,) float, ``d . grad u`` per triangle."""
    G = igl.grad(Xc, Tc)
    t = len(Tc)
    g = G @ u
    return d[:, 0] * g[:t] + d[:, 1] * g[t:2 * t] + d[:, 2] * g[2 * t:]


def _near_design_boundary(mesh: QuadMesh, design: DesignSurface, radius: float,
                          prescribed: np.ndarray | None = None,
                          levels: np.ndarray | None = None) -> np.ndarray:
    """(b,) int, boundary vertices of the layout within `radius` of the design boundary,
    at most two faces each.

    With a prescribed family (`prescribed` on the design vertices, `levels` per layout
    vertex), a vertex only glides where its level reaches the boundary near it (within a
    quarter level), so that gliding and staying on its level do not contradict.
    """
    from .constraints.closeness import closest_points_on_polylines

    boundary = np.flatnonzero(mesh.is_boundary_vertex)
    curves = design.boundary_curves()
    if not curves or boundary.size == 0:
        return np.zeros(0, np.int64)
    foot, tangent = closest_points_on_polylines(mesh.vertices[boundary], curves)
    near = np.linalg.norm(foot - mesh.vertices[boundary], axis=1) <= radius
    # concave corners of the layout's boundary (three faces or more) would flatten their
    # faces onto the boundary curve: they stay free on the surface
    faces_at = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    near &= faces_at[boundary] <= 2
    if prescribed is not None:
        # sliding along the boundary by at most the radius must reach the vertex's level
        # (linearly): a boundary running along a level set is not glided on
        step = 0.1 * radius
        at_foot = _value_at(design, prescribed, foot)
        ahead = _value_at(design, prescribed, foot + step * tangent)
        behind = _value_at(design, prescribed, foot - step * tangent)
        slope = np.abs(ahead - behind) / (2 * step)
        # ... crossing the levels, not running along one (where a level may never meet it)
        _, _, tri = design.reference.closest_points(foot)
        rate = np.linalg.norm(_gradient_vectors(design, prescribed)[tri], axis=1)
        level = levels[boundary]
        near &= ~np.isfinite(level) | ((np.abs(at_foot - level) <= slope * radius)
                                       & (slope >= 0.3 * rate))
    return boundary[near]


def _value_at(design: DesignSurface, value: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m,) float, a function on the design vertices interpolated at the closest points."""
    foot, _, tri = design.reference.closest_points(points)
    V, T = design.vertices, design.triangles[tri]
    bary = igl.barycentric_coordinates(foot, V[T[:, 0]], V[T[:, 1]], V[T[:, 2]])
    return np.sum(bary * value[T], axis=1)


# ---------------------------------------------------------------------------- gliding


def glide(layout: SurfaceLayout, net: str = "snet", *, angle: float | None = None,
          radius: float | None = None, settings=None, fixed: np.ndarray | None = None,
          progress=None):
    """Optimize a layout into a net of type `net` while it glides on the design surface.

    The vertices are held on the design surface (point-to-plane distance to footpoints
    recomputed every iteration, a hard constraint), the layout's boundary vertices near
    the design boundary on the boundary curves; everything else is `fabplan.optimize`.

    Returns
    -------
    `fabplan.optimize.OptimizationResult`, whose properties also hold
    ``distance_to_design`` (model units) and ``distance_to_design_relative_to_panel``.
    """
    from .nets import get_net
    from .optimize import optimize

    mesh, design = layout.mesh, layout.design
    if get_net(net).dual:
        raise InputError(f"net type {net!r}: layouts are computed for S-nets; optimize the "
                         "S-net first and then the S*-net with `fabplan optimize`")
    extra = ()
    if layout.prescribed is not None:
        on_level = np.flatnonzero(np.isfinite(layout.vertex_keys[:, 0]))
        extra = (FamilyLevels(design.reference, layout.prescribed, on_level,
                              layout.vertex_keys[on_level, 0]),)
    result = optimize(mesh, net, angle=angle, radius=radius, reference=design.reference,
                      fixed=fixed, settings=settings, glide=True,
                      glide_boundary=layout.gliding_boundary, extra=extra, progress=progress)
    X = result.mesh.vertices
    d = design.reference.distances(X)
    length = np.linalg.norm(X[result.mesh.edges[:, 0]] - X[result.mesh.edges[:, 1]], axis=1)
    result.properties["distance_to_design"] = {"max": float(d.max()), "mean": float(d.mean())}
    result.properties["distance_to_design_relative_to_panel"] = {
        "max": float(d.max() / layout.panel_size), "mean": float(d.mean() / layout.panel_size)}
    result.properties["edge_length_relative_to_panel"] = {
        "min": float(length.min() / layout.panel_size),
        "max": float(length.max() / layout.panel_size),
        "mean": float(length.mean() / layout.panel_size)}
    result.properties["layout"] = layout.record()
    result.parameters["panel_size"] = layout.panel_size
    return result


# ---------------------------------------------------------------------------- picture


def write_layout_picture(path: str | os.PathLike, design: DesignSurface, mesh: QuadMesh, *,
                         title: str = "", singular_points: np.ndarray | None = None) -> Path:
    """A PNG of the net on the design surface (atomically written).

    The design surface is drawn light grey (its boundary black), the net's faces blue with
    their edges, irregular vertices red and singular points of the direction field orange.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from .io import atomic_path

    path = Path(path)
    fig = plt.figure(figsize=(8, 8), dpi=110)
    ax = fig.add_subplot(projection="3d")
    T = design.triangles
    if len(T) > 30000:  # a coarser sample of the surface keeps the picture quick
        T = T[:: int(math.ceil(len(T) / 30000))]
    ax.add_collection3d(Poly3DCollection(design.vertices[T], facecolor=(0.85, 0.85, 0.85, 0.35),
                                         edgecolor="none"))
    for curve in design.boundary_curves():
        loop = np.vstack([curve, curve[:1]])
        ax.plot(loop[:, 0], loop[:, 1], loop[:, 2], color="black", lw=0.8)
    faces = [mesh.vertices[f] for f in mesh.faces]
    ax.add_collection3d(Poly3DCollection(faces, facecolor=(0.55, 0.7, 0.95, 0.9),
                                         edgecolor=(0.1, 0.2, 0.5, 1.0), linewidths=0.4))
    irregular = mesh.vertices[mesh.irregular_vertices]
    if len(irregular):
        ax.scatter(*irregular.T, color="red", s=18, depthshade=False, label="irregular vertices")
    if singular_points is not None and len(singular_points):
        ax.scatter(*np.asarray(singular_points).T, color="orange", s=12, depthshade=False,
                   label="field singularities")
    # look at the surface from the side its normals face (tilted a little), if they agree
    mean = np.sum(design.face_normals * design.face_areas[:, None], axis=0)
    if np.linalg.norm(mean) > 0.3 * design.area:
        n = mean / np.linalg.norm(mean)
        elev = float(np.degrees(np.arcsin(np.clip(n[2], -1, 1))))
        azim = float(np.degrees(np.arctan2(n[1], n[0])))
        ax.view_init(elev=float(np.clip(elev, -60, 60)) if abs(elev) < 80 else 60.0,
                     azim=azim + 25.0)
    lo, hi = design.vertices.min(axis=0), design.vertices.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_axis_off()
    if title:
        ax.set_title(title, fontsize=9)
    if len(irregular) or (singular_points is not None and len(singular_points)):
        ax.legend(loc="lower left", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)
    return path
