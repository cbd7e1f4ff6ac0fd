"""Direction fields on a design surface: principal frames, the smoothed and combed line
field, its singularities, and the two directions of an S-net.

Principal directions per triangle come from the exact fundamental forms of a parametric
surface or from libigl's per-vertex estimate. They are smoothed, weighted by the
anisotropy ``|k1 - k2|``, as a line field or as a cross field (`smooth_direction_field`)
and then combed into consistent signs; where combing conflicts the field has a seam,
whose end points and the points the field turns around are its singularities
(`line_field_index`). The S-net directions are
symmetric to the principal directions (`snet_directions`); with a prescribed first
family (`prescribed_family`) the partner is its reflection in them
(`complementary_directions`, Proposition 2.11).
"""

from __future__ import annotations

import math
from pathlib import Path

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..design.topology import edge_corners
from ..errors import InputError
from ..net.forest import forest_parents, tree_parity
from ..solve.linalg import solve_spd_columns

__all__ = [
    "face_principal_frames",
    "smooth_direction_field",
    "comb_cross_field",
    "comb_line_field",
    "line_field_index",
    "direction_turning",
    "snet_directions",
    "complementary_directions",
    "prescribed_family",
]


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
        uv = design.triangle_uv(np.arange(len(T))).mean(axis=1)   # unwrapped at a seam
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


def face_adjacency(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Interior edges as corner pairs (c0, c1) and their triangles (f, g)."""
    c0, c1 = edge_corners(design.triangles, len(design.vertices))
    return c0, c1, c0 // 3, c1 // 3


def _edge_transport(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interior edges as triangle pairs (f, g) and the discrete Levi-Civita connection:
    an angle ``a`` in f's frame (`_face_frames`) is ``a + rotation`` in g's (the angle to
    the shared edge is kept), (e,) float in radians."""
    c0, _, f, g = face_adjacency(design)
    T, V = design.triangles, design.vertices
    b1, b2, _ = _face_frames(design)
    edge = V[T[:, [1, 2, 0]].ravel()[c0]] - V[T.ravel()[c0]]

    def edge_angle(face):
        return np.arctan2(np.sum(edge * b2[face], axis=1), np.sum(edge * b1[face], axis=1))

    return f, g, edge_angle(g) - edge_angle(f)


def smooth_direction_field(design: DesignSurface, e1: np.ndarray, weight: np.ndarray,
                           length: float, *, symmetry: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Smooth a field of directions with a `symmetry`-fold ambiguity, weighted by
    confidence: a line field (2, the principal directions) or a cross field (4, the
    principal directions and their normals taken as one).

    Every triangle's directions are one complex number ``z = exp(i symmetry a)`` (a, the
    angle in the triangle's frame); minimizes ``sum_f w_f |z_f - d_f|^2 + kappa
    sum_(f,g) |r_fg z_f - z_g|^2`` (r_fg, the parallel transport across the shared edge;
    kappa gives a smoothing radius of `length`): one sparse factorization. As a cross
    field, the principal directions turning a quarter turn across a region of small
    ``|k1 - k2|`` (a near-umbilic) need not turn at all: both ends are the same cross.

    Parameters
    ----------
    design : the surface.
    e1 : (t, 3) float, unit directions in the triangle planes.
    weight : (t,) float >= 0, confidence (e.g. ``|k1 - k2|`` times area), normalized
        internally.
    length : smoothing length (model units); 0 keeps the field.
    symmetry : 2 or 4.

    Returns
    -------
    e1 : (t, 3) float, one unit direction of the smoothed field per triangle (a cross
        field is then combed into a line field with `comb_cross_field`).
    coherence : (t,) float in [0, 1], how well the neighbourhood agrees (0 at a
        singularity of the smoothed field).
    """
    if symmetry not in (2, 4):
        raise ValueError(f"symmetry must be 2 (a line field) or 4 (a cross field), got {symmetry}")
    b1, b2, _ = _face_frames(design)
    t = len(e1)
    angle = symmetry * np.arctan2(np.sum(e1 * b2, axis=1), np.sum(e1 * b1, axis=1))
    z = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    if length > 0:
        f, g, rotation = _edge_transport(design)
        centroid = design.vertices[design.triangles].mean(axis=1)
        spacing = float(np.linalg.norm(centroid[f] - centroid[g], axis=1).mean())
        kappa = (length / spacing) ** 2
        w = np.asarray(weight, dtype=np.float64)
        w = w / max(float(np.median(w[w > 0])) if np.any(w > 0) else 1.0, 1e-300)
        w = np.clip(w, 1e-3, 4.0)
        # |R z_f - z_g|^2 in real pairs: blocks R^T R = I on the diagonal, -R and -R^T off it
        c, s = np.cos(symmetry * rotation), np.sin(symmetry * rotation)
        R = np.stack([c, -s, s, c], axis=1).reshape(-1, 2, 2)          # (e, 2, 2)
        i, j = np.meshgrid([0, 1], [0, 1], indexing="ij")
        rows = (2 * g[:, None, None] + i).ravel()
        cols = (2 * f[:, None, None] + j).ravel()
        off = sp.coo_matrix((-kappa * R.ravel(), (rows, cols)), shape=(2 * t, 2 * t))
        degree = np.bincount(np.r_[f, g], minlength=t).astype(np.float64)
        system = (off + off.T + sp.diags(np.repeat(w + kappa * degree, 2))).tocsr()
        z = solve_spd_columns(system, (z * w[:, None]).reshape(-1, 1)).reshape(t, 2)
    theta = np.arctan2(z[:, 1], z[:, 0]) / symmetry
    coherence = np.clip(np.hypot(z[:, 0], z[:, 1]), 0.0, 1.0)
    return np.cos(theta)[:, None] * b1 + np.sin(theta)[:, None] * b2, coherence


def comb_cross_field(design: DesignSurface, d: np.ndarray) -> np.ndarray:
    """One direction of a cross field per triangle, chosen so that neighbours agree as
    lines: a quarter turn where they would meet at more than 45 degrees, by XOR along a
    minimum spanning tree (as `comb_line_field` does for signs).

    Parameters
    ----------
    design : the surface.
    d : (t, 3) float, one unit direction of the cross in every triangle plane.

    Returns
    -------
    (t, 3) float, the cross's line field: ``d`` or ``n x d`` per triangle (combable with
    `comb_line_field` wherever the cross field has no quarter-turn singularity).
    """
    _, _, f, g = face_adjacency(design)
    t = len(d)
    dot = np.abs(np.sum(d[f] * d[g], axis=1))
    agreement = np.maximum(dot, np.sqrt(np.maximum(1.0 - dot * dot, 0.0)))
    parent = _spanning_parent(t, f, g, 1.0 - agreement + 1e-9)
    quarter = tree_parity(t, f, g, (dot < math.sqrt(0.5)).astype(np.int64), parent).astype(bool)
    return np.where(quarter[:, None], np.cross(design.face_normals, d), d)


def comb_line_field(design: DesignSurface, e1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Give a line field consistent signs: XOR along a minimum spanning tree of the
    triangle adjacency weighted by ``1 - |e1_f . e1_g|`` (smooth steps first).

    Returns
    -------
    e1 : (t, 3) float, the combed field.
    seam : (e, 2) int, design vertices of the interior edges across which the combed field
        still flips (empty when the field is combable).
    """
    c0, _, f, g = face_adjacency(design)
    t = len(e1)
    dot = np.sum(e1[f] * e1[g], axis=1)
    parent = _spanning_parent(t, f, g, 1.0 - np.abs(dot) + 1e-9)
    sign = 1 - 2 * tree_parity(t, f, g, (dot < 0).astype(np.int64), parent)
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
    return forest_parents(count, tree.row, tree.col)


def line_field_index(design: DesignSurface, e1: np.ndarray, *, symmetry: int = 2) -> np.ndarray:
    """(n,) float, index of a line field (or, with ``symmetry=4``, a cross field given by
    one of its directions) around every interior vertex (turns: multiples of
    1/symmetry; 0 where regular, NaN on the boundary).

    The rotation of the field across each edge around the vertex is measured against the
    edge itself (discrete parallel transport), reduced modulo ``1/symmetry`` turn, summed,
    and corrected by the angle defect.
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
    c0, c1 = edge_corners(T, n)
    twin = np.full(3 * t, -1)
    twin[c0], twin[c1] = c1, c0
    # the corner (k+2) of a triangle owns the half-edge w2 -> v; its twin starts at v
    prev_corner = 3 * face + (np.arange(3 * t) % 3 + 2) % 3
    nxt = twin[prev_corner]
    has = nxt >= 0
    delta = np.zeros(3 * t)
    delta[has] = A[nxt[has]] - B[has]
    period = 2 * np.pi / symmetry
    delta = delta - period * np.round(delta / period)
    open_corner = np.bincount(vert, weights=(~has).astype(float), minlength=n) > 0
    total = np.bincount(vert, weights=delta, minlength=n)
    defect = 2 * np.pi - np.bincount(vert, weights=gamma, minlength=n)
    index = np.round((total + defect) / period) / symmetry
    index[open_corner] = np.nan
    return index


def direction_turning(design: DesignSurface, e1: np.ndarray, length: float) -> np.ndarray:
    """(t,) float, how far a line field turns over `length` around each triangle (degrees).

    Across each interior edge the field's angle to the edge is compared in the two
    triangles' planes (parallel transport across the edge, so the surface's own bending
    does not count), per unit distance of their centroids; the rates are averaged over
    a triangle's edges, then over a neighbourhood of about a third of `length`, and
    multiplied by `length`.

    An S-net's lines follow directions symmetric to the principal ones; where those turn
    by tens of degrees within one panel (near an umbilic, or a near-umbilic where
    ``|k1 - k2|`` almost vanishes without the field becoming singular) the net's lines
    cannot follow them.

    Examples
    --------
    >>> from fabplan.design.load import load_design
    >>> tube = load_design("revolution:height=8,radius=4,waist=1", triangles=4000)
    >>> e1 = face_principal_frames(tube)[2]          # along the parallels of a cylinder
    >>> float(np.percentile(direction_turning(tube, e1, 2.0), 95)) < 1.0
    True
    """
    f, g, rotation = _edge_transport(design)
    T, V = design.triangles, design.vertices
    t = len(e1)
    b1, b2, _ = _face_frames(design)
    angle = np.arctan2(np.sum(e1 * b2, axis=1), np.sum(e1 * b1, axis=1))
    turn = angle[g] - angle[f] - rotation
    turn = np.abs(turn - np.pi * np.round(turn / np.pi))          # lines: modulo a half turn
    centroid = V[T].mean(axis=1)
    spacing = np.maximum(np.linalg.norm(centroid[f] - centroid[g], axis=1), 1e-300)
    rate = np.bincount(f, turn / spacing, t) + np.bincount(g, turn / spacing, t)
    edges = np.bincount(f, minlength=t) + np.bincount(g, minlength=t)
    rate = rate / np.maximum(edges, 1)
    # averaging over neighbours spreads like a diffusion: (radius / spacing)^2 steps
    adjacency = sp.coo_matrix((np.ones(2 * len(f)), (np.r_[f, g], np.r_[g, f])), shape=(t, t))
    adjacency = (sp.diags(1.0 / np.maximum(edges, 1)) @ adjacency).tocsr()
    for _ in range(int(min(200, (0.5 * length / float(np.median(spacing))) ** 2))):
        rate = 0.5 * (rate + adjacency @ rate)
    return np.degrees(rate * length)


def find_whole_turns(V: np.ndarray, singular: np.ndarray, index: np.ndarray,
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
    g = gradient_vectors(design, value)
    normal = design.face_normals
    t = np.cross(normal, g)
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    if not np.any(norm > 0):
        raise InputError(f"--family {spec}: the prescribed function is constant on {design.name}")
    t /= np.maximum(norm, 1e-300)
    s = complementary_directions(t, e1)
    s /= np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-300)
    # a family along a principal direction is its own mirror image: no partner crosses it
    crossing = np.linalg.norm(np.cross(t, s), axis=1)      # sine of their angle
    area = design.face_areas
    if np.sum(area * (crossing < math.sin(math.radians(10)))) > 0.5 * area.sum():
        raise InputError(
            f"--family {spec}: the prescribed curves follow a principal direction over most of "
            f"{design.name} (as the floors of a surface of revolution do), so the S-net partner "
            "family would run along them; prescribe curves that cross the principal directions, "
            "or lay out without --family")
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


def gradient_vectors(design, value) -> np.ndarray:
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
        vertex_rows, lines = [], []
        for lineno, line in enumerate(text.splitlines(), start=1):
            parts = line.split()
            if parts[:1] == ["v"]:
                try:
                    vertex_rows.append([float(p) for p in parts[1:4]])
                except ValueError:
                    raise InputError(f"{spec}:{lineno}: malformed vertex line") from None
            elif parts[:1] == ["l"]:
                lines.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
        verts = np.asarray(vertex_rows, dtype=np.float64).reshape(-1, 3)
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
    return solve_spd_columns(system, (weight * (C.T @ target))[:, None])[:, 0]
