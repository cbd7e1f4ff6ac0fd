"""Panels of a net: the surface each face stands for, its principal frame and its samples.

Every face of a net is a panel. Three panel surface models:

``osculating`` (the panels of a curved facade)
    one surface for the whole facade, built from the net's own curvature elements
    (`net_curvature`): every vertex carries its discrete normal, principal directions and
    principal curvatures (Def. 2.13, 2.16, Eq. 7-9) and a third-order term fitted to its
    neighbours, hence an osculating surface whose normal sections are the circles of
    Euler's normal curvatures (`osculating_points`). Vertices without Eq. 7-9 (the boundary,
    the ring next to it, irregular vertices) borrow the surface of the nearest interior
    vertex, so the boundary is extended from the interior and a linear Weingarten relation
    of the interior holds there too. A point of the one surface over a face is the blend of
    its corners' surfaces (`osculating_panel_samples`); along an edge only the edge's two
    vertices count, so the one surface is continuous across every edge. It passes through
    every vertex with its own surface and within `NetCurvature.miss` of the others. The
    panel cast on a mold is the least-squares quadric of that piece
    (`fit_osculating_surfaces`, with its gap from the one surface).
``local_fit``
    each panel is its own quadratic height field in the face frame (origin at the mean of
    its corners, ``z`` along its Newell normal)::

        z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2) / 2

    fitted by weighted least squares to its corners (weight `CORNER_WEIGHT`) and the corners
    of every face that shares a vertex with it (weight 1). Neighbouring panels meet at the
    net's vertices only; near the boundary the fit is one-sided and neighbours may bend
    differently along the edge they share. Kept for comparison and for nets without
    discrete principal curvatures.
``corners``
    the panel's corners only, with the least curvature that passes through them: a planar
    face gives a flat panel, a twisted quad its hyperbolic paraboloid. This is the panel of
    a planar-quad (or ruled) paneling.

`surface_model` picks ``corners`` for a net whose faces are all flat within the tolerance
(its panels are meant to be cut flat) and ``osculating`` otherwise.

Distances are in model units, curvatures in inverse model units; the principal curvatures
are signed with respect to the face normal (positive when the panel bends towards it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..errors import InputError
from ..net.geometry import (
    face_normals,
    face_planarity,
    principal_curvatures,
    principal_directions,
    star_normals,
)

__all__ = [
    "CORNER_WEIGHT",
    "SURFACE_MODELS",
    "PanelSurfaces",
    "PanelShapes",
    "check_panels",
    "surface_model",
    "panel_neighbourhoods",
    "fit_panel_surfaces",
    "panel_shapes",
    "panel_samples",
    "placement_frames",
    "NetCurvature",
    "extend_vertex_values",
    "free_vertices",
    "settle_free_vertices",
    "net_curvature",
    "osculating_points",
    "osculating_panel_samples",
    "fit_osculating_surfaces",
]

CORNER_WEIGHT = 1.0e6
"""Least-squares weight of a panel's own corners against 1 for its neighbours' vertices."""

SURFACE_MODELS = ("osculating", "local_fit", "corners")

_RIDGE = 1.0e-9  # relative weight pulling undetermined curvature terms to zero


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _face_of_corner(mesh) -> np.ndarray:
    return np.repeat(np.arange(len(mesh.face_sizes)), mesh.face_sizes)


def _corner_means(mesh) -> np.ndarray:
    """(f, 3) mean of each face's corners."""
    face = _face_of_corner(mesh)
    X = mesh.vertices[mesh.face_indices]
    total = np.stack([np.bincount(face, X[:, d], minlength=len(mesh.face_sizes)) for d in range(3)], 1)
    return total / mesh.face_sizes[:, None]


def check_panels(mesh) -> None:
    """Refuse a net with a degenerate face, naming it (`QuadMesh` already refuses a mesh
    without faces).

    Raises
    ------
    InputError
        When a face has (almost) no area: its corners coincide or lie on one line.
    """
    X = mesh.vertices
    face = _face_of_corner(mesh)
    ptr, sizes = mesh.face_indptr, mesh.face_sizes
    local = np.arange(len(face)) - ptr[face]
    nxt = mesh.face_indices[np.where(local == sizes[face] - 1, ptr[face], np.arange(len(face)) + 1)]
    cross = np.cross(X[mesh.face_indices], X[nxt])
    area2 = np.zeros((len(sizes), 3))
    np.add.at(area2, face, cross)
    area = 0.5 * np.linalg.norm(area2, axis=1)
    edge = np.linalg.norm(X[nxt] - X[mesh.face_indices], axis=1)
    perimeter = np.bincount(face, edge, minlength=len(sizes))
    bad = np.flatnonzero(~(area > 1e-9 * perimeter**2))
    if bad.size:
        raise InputError(f"{mesh.name}: face {bad[0]} is degenerate (zero area: its corners "
                         "coincide or lie on a line); remove or repair it")


def surface_model(mesh, tolerance: float, model: str = "auto") -> str:
    """The panel surface model to use: ``model`` itself, or for ``"auto"`` ``"corners"`` when
    every face lies within `tolerance` (model units) of a plane and ``"osculating"`` otherwise.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import height_field_grid
    >>> flat = height_field_grid(4, 4, lambda x, y: 0 * x)
    >>> surface_model(flat, 0.001), surface_model(flat, 0.001, "local_fit")
    ('corners', 'local_fit')
    """
    if model not in ("auto",) + SURFACE_MODELS:
        raise InputError(f"unknown panel surface model {model!r}: use auto, osculating, "
                         "local_fit or corners")
    if model != "auto":
        return model
    X = mesh.vertices
    flat = True
    for k in np.unique(mesh.face_sizes):  # one batch per face size (3, 4, 5 ...)
        if k == 3:
            continue
        starts = mesh.face_indptr[:-1][mesh.face_sizes == k]
        polys = mesh.face_indices[starts[:, None] + np.arange(k)]
        flat &= bool(np.all(face_planarity(X, polys) <= tolerance))
    return "corners" if flat else "osculating"


def panel_neighbourhoods(mesh, model: str = "local_fit") -> tuple[np.ndarray, np.ndarray]:
    """The vertices each panel's surface is fitted to.

    Returns
    -------
    vertices : (f, m) int, padded with the face's first corner.
    weight : (f, m) float, `CORNER_WEIGHT` for the face's corners, 1 for the other vertices
        of faces sharing a vertex with it (``local_fit`` only), 0 for padding.
    """
    nf, n = len(mesh.face_sizes), mesh.vertex_count
    face = _face_of_corner(mesh)
    incidence = sp.csr_matrix((np.ones(len(face)), (face, mesh.face_indices)), shape=(nf, n))
    if model == "local_fit":
        reach = (incidence @ (incidence.T @ incidence)).tocsr()
    else:
        reach = incidence.copy()
    reach.sort_indices()
    counts = np.diff(reach.indptr)
    m = int(counts.max())
    row = np.repeat(np.arange(nf), counts)
    col = np.arange(len(row)) - reach.indptr[row]
    vertices = np.repeat(mesh.face_indices[mesh.face_indptr[:-1]][:, None], m, axis=1)
    vertices[row, col] = reach.indices
    weight = np.zeros((nf, m))
    is_corner = np.asarray(incidence[row, reach.indices]).ravel() > 0
    weight[row, col] = np.where(is_corner, CORNER_WEIGHT, 1.0)
    return vertices, weight


@dataclass(frozen=True)
class PanelSurfaces:
    """The quadratic surface of every panel, in its face frame.

    Attributes
    ----------
    origin : (f, 3) float, mean of the face's corners (model units).
    frame : (f, 3, 3) float, rows: face x-axis, y-axis and unit Newell normal.
    scale : (f,) float, RMS distance of the corners from `origin`; the coefficients are
        those of the surface in coordinates divided by it.
    coefficients : (f, 6) float, ``(c0, c1, c2, a, b, c)`` of
        ``z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2) / 2`` in scaled coordinates.
    corners : (f, k_max, 2) float, the corners projected into the face plane (scaled), padded
        by repeating the last corner.
    model : the surface model, ``"local_fit"`` or ``"corners"``.
    """

    origin: np.ndarray
    frame: np.ndarray
    scale: np.ndarray
    coefficients: np.ndarray
    corners: np.ndarray
    model: str

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(f, s) scaled heights of the surfaces at scaled plane points ``xy`` (f, s, 2)."""
        c = self.coefficients[:, None, :]
        x, y = xy[..., 0], xy[..., 1]
        return (c[..., 0] + c[..., 1] * x + c[..., 2] * y
                + 0.5 * (c[..., 3] * x * x + 2 * c[..., 4] * x * y + c[..., 5] * y * y))

    def to_model(self, xyz: np.ndarray) -> np.ndarray:
        """(f, s, 3) model coordinates of scaled face-frame points (f, s, 3)."""
        return self.origin[:, None, :] + self.scale[:, None, None] * (xyz @ self.frame)


def fit_panel_surfaces(mesh, model: str = "local_fit") -> PanelSurfaces:
    """Fit the quadratic surface of every panel (see the module notes).

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh`, faces of any size; check it with `check_panels` first.
    model : ``"local_fit"`` or ``"corners"``.

    Returns
    -------
    PanelSurfaces
    """
    if model not in ("local_fit", "corners"):
        raise InputError(f"fit_panel_surfaces fits one quadric per face: model {model!r} must be "
                         "local_fit or corners")
    X = mesh.vertices
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    nf = len(sizes)
    normal = face_normals(X, mesh)
    origin = _corner_means(mesh)
    first = X[mesh.face_indices[ptr[:-1]]] - origin
    xaxis = _unit(first - np.sum(first * normal, axis=1, keepdims=True) * normal)
    frame = np.stack([xaxis, np.cross(normal, xaxis), normal], axis=1)
    face = _face_of_corner(mesh)
    d2 = np.sum((X[mesh.face_indices] - origin[face]) ** 2, axis=1)
    scale = np.sqrt(np.bincount(face, d2, minlength=nf) / sizes)

    vertices, weight = panel_neighbourhoods(mesh, model)
    coefficients = _height_fits(X[vertices], weight, origin, frame, scale)

    k_max = int(sizes.max())
    slot = np.minimum(np.arange(k_max), sizes[:, None] - 1)
    corner_ids = mesh.face_indices[ptr[:-1, None] + slot]
    corners = np.einsum("fkj,fij->fki", X[corner_ids] - origin[:, None, :], frame)[..., :2]
    corners = corners / scale[:, None, None]
    return PanelSurfaces(origin=origin, frame=frame, scale=scale, coefficients=coefficients,
                         corners=corners, model=model)


def _height_fits(points: np.ndarray, weight: np.ndarray, origin: np.ndarray, frame: np.ndarray,
                 scale: np.ndarray) -> np.ndarray:
    """(f, 6) weighted least-squares quadratic height fields of points (f, m, 3) in the face
    frames (see `PanelSurfaces`)."""
    P = np.einsum("fmj,fij->fmi", points - origin[:, None, :], frame) / scale[:, None, None]
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    A = np.stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=2)
    AtW = A.transpose(0, 2, 1) * weight[:, None, :]
    normal_matrix = AtW @ A
    # A tiny ridge on the curvature terms settles what the points leave free (a lone quad
    # of the corners model): the least-curved surface through the corners.
    ridge = _RIDGE * weight.sum(axis=1)[:, None] * np.array([0, 0, 0, 1, 1, 1.0])
    normal_matrix[:, np.arange(6), np.arange(6)] += ridge
    return np.linalg.solve(normal_matrix, (AtW @ z[..., None]))[..., 0]


@dataclass(frozen=True)
class PanelShapes:
    """Principal curvatures and frame of every panel surface at the point over its centre.

    Attributes
    ----------
    point : (f, 3) float, the surface point over the mean of the corners (model units).
    normal : (f, 3) float, unit surface normal there, on the side of the face normal.
    k1, k2 : (f,) float, principal curvatures, ``k1 >= k2`` (inverse model units).
    e1, e2 : (f, 3) float, unit principal directions; ``(e1, e2, normal)`` is right-handed.
    """

    point: np.ndarray
    normal: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    e1: np.ndarray
    e2: np.ndarray


def panel_shapes(surfaces: PanelSurfaces) -> PanelShapes:
    """Principal curvatures and directions of the panel surfaces (first and second
    fundamental forms of the height field at the face centre)."""
    c0, c1, c2, a, b, c = surfaces.coefficients.T
    h = surfaces.scale
    F = surfaces.frame
    first = np.stack([np.stack([1 + c1 * c1, c1 * c2], -1), np.stack([c1 * c2, 1 + c2 * c2], -1)], -2)
    w = np.sqrt(1 + c1 * c1 + c2 * c2)
    second = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2) / (w * h)[:, None, None]
    # generalized symmetric eigenproblem II v = k I v through the Cholesky factor of I
    L = np.linalg.cholesky(first)
    Linv = np.linalg.inv(L)
    k, y = np.linalg.eigh(Linv @ second @ Linv.transpose(0, 2, 1))
    v = Linv.transpose(0, 2, 1) @ y  # columns: parameter directions of k2, k1
    t1 = v[:, 0, 1, None] * np.stack([np.ones_like(c1), 0 * c1, c1], -1) \
        + v[:, 1, 1, None] * np.stack([0 * c1, np.ones_like(c1), c2], -1)
    e1 = _unit(np.einsum("fi,fij->fj", t1, F))
    normal = _unit(np.einsum("fi,fij->fj", np.stack([-c1, -c2, np.ones_like(c1)], -1), F))
    e1 = _unit(e1 - np.sum(e1 * normal, axis=1, keepdims=True) * normal)
    # an eigenvector's sign is arbitrary: point e1 along the face's first edge
    e1 *= np.where(np.sum(e1 * F[:, 0], axis=1) < 0, -1.0, 1.0)[:, None]
    e2 = np.cross(normal, e1)
    point = surfaces.origin + (h * c0)[:, None] * F[:, 2]
    return PanelShapes(point=point, normal=normal, k1=k[:, 1], k2=k[:, 0], e1=e1, e2=e2)


def _fan_weights(level: int) -> np.ndarray:
    """(t, 2) barycentric weights (of corner j, corner j+1) of a triangular grid with
    `level` steps per side; the third vertex is the face centre."""
    i, j = np.meshgrid(np.arange(level + 1), np.arange(level + 1), indexing="ij")
    keep = i + j <= level
    return np.stack([i[keep], j[keep]], axis=1) / level


def panel_samples(mesh, surfaces: PanelSurfaces, level: int) -> np.ndarray:
    """Points spread over every panel: its outline and interior on its surface.

    Each face is split into a fan of triangles from the mean of its corners; every triangle
    gets a grid with `level` steps per side (corners and the outline included), lifted
    onto the panel surface.

    Returns
    -------
    (f, s, 3) float model coordinates; faces with fewer samples than the largest repeat
    their first sample (so maxima and minima over a panel are unchanged).
    """
    sizes = mesh.face_sizes
    B = _fan_weights(level)
    k_max = int(sizes.max())
    s = k_max * len(B)
    corners = surfaces.corners
    nxt = np.minimum(np.arange(k_max) + 1, k_max - 1)
    nxt = np.where(np.arange(k_max)[None, :] + 1 >= sizes[:, None], 0, nxt[None, :])
    # (f, k_max, t, 2) points b * P_j + c * P_{j+1}
    P_next = np.take_along_axis(corners, nxt[..., None], axis=1)
    xy = B[None, None, :, :1] * corners[:, :, None, :] + B[None, None, :, 1:] * P_next[:, :, None, :]
    valid = np.arange(k_max)[None, :] < sizes[:, None]
    xy = np.where(valid[:, :, None, None], xy, xy[:, :1, :1, :])
    xy = xy.reshape(len(sizes), s, 2)
    z = surfaces.height(xy)
    return surfaces.to_model(np.concatenate([xy, z[..., None]], axis=2))


def placement_frames(shapes: PanelShapes) -> tuple[np.ndarray, np.ndarray]:
    """The four principal placements of every panel on a mold ``z = (K1 x^2 + K2 y^2) / 2``.

    The canonical frame ``F0`` puts the panel's point at the mold apex with its larger
    curvature in magnitude along x and a non-negative mean curvature (the panel is turned
    over when its mean curvature is negative). The variants are F0 turned a quarter about
    z (``F1``), turned over about x (``F2``), and both (``F3``); a half turn about z maps
    every mold onto itself, so these four are all principal placements.

    Returns
    -------
    frames : (f, 4, 3, 3) float, rows: the mold x, y, z axes in model coordinates.
    shapes : (f, 4, 2) float, the panel's ``(K1, K2)`` in each frame: ``(k1, k2)``,
        ``(k2, k1)``, ``(-k1, -k2)``, ``(-k2, -k1)`` of its canonical curvatures.
    """
    flip = (shapes.k1 + shapes.k2) < 0
    a = np.where(flip[:, None], shapes.e2, shapes.e1)
    b = np.where(flip[:, None], shapes.e1, shapes.e2)
    c = np.where(flip[:, None], -shapes.normal, shapes.normal)
    k1 = np.where(flip, -shapes.k2, shapes.k1)
    k2 = np.where(flip, -shapes.k1, shapes.k2)
    frames = np.stack([
        np.stack([a, b, c], 1),
        np.stack([b, -a, c], 1),
        np.stack([a, -b, -c], 1),
        np.stack([b, a, -c], 1),
    ], axis=1)
    kk = np.stack([np.stack([k1, k2], -1), np.stack([k2, k1], -1),
                   np.stack([-k1, -k2], -1), np.stack([-k2, -k1], -1)], axis=1)
    return frames, kk


# ----------------------------------------------------------------------------- one surface
CUBIC_RINGS = 2
"""Rings of neighbours each vertex's third-order term is fitted to (`net_curvature`)."""
OUTLIER_FACTOR = 5.0
"""A vertex whose osculating surface misses a neighbour by more than this many times the
median such miss (at least 1e-4 of the mean edge) gets extended elements (`net_curvature`)."""
TILT_ITERATIONS = 4
"""Rounds of the tangent-plane fit of a vertex without a discrete normal (`net_curvature`)."""


@dataclass(frozen=True)
class NetCurvature:
    """The curvature elements of a net at every vertex: what its one surface is built from.

    Attributes
    ----------
    origin : (n, 3) float, the point each vertex's osculating surface passes through: the
        vertex itself.
    normal : (n, 3) float, unit normals: the discrete normal (Def. 2.13) at a star centre,
        else the normal of the tangent plane fitted to the neighbours (`net_curvature`).
    e1, e2 : (n, 3) float, unit principal directions (bisectors of the net's osculating
        tangents, Def. 2.16, or extended from the interior); ``(e1, e2, normal)`` is
        right-handed.
    k1, k2 : (n,) float, principal curvatures of `e1` and `e2` (Eq. 7-9, or extended from
        the interior), signed with respect to `normal` (inverse model units).
    cubic : (n, 4) float, ``(c0, c1, c2, c3)`` of the third-order term
        ``(c0 x^3 + 3 c1 x^2 y + 3 c2 x y^2 + c3 y^3) / 6`` of the surface over the tangent
        plane in the coordinates ``x, y`` along `e1`, `e2` (inverse square model units).
    measured : (n,) bool, True where k1, k2 and the third-order term are the vertex's own
        (Eq. 7-9 applies), False where they are extended from the interior.
    miss : (n,) float, distance of each vertex from its own osculating surface (model
        units; zero up to rounding: every surface passes through its vertex).
    """

    origin: np.ndarray
    normal: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    cubic: np.ndarray
    measured: np.ndarray
    miss: np.ndarray


def net_curvature(mesh) -> NetCurvature:
    """The net's curvature elements at every vertex (Def. 2.13, 2.16, Eq. 7-9).

    Where Eq. 7-9 applies (a regular star whose neighbours are star centres too, with a
    Meusnier sphere that is no plane) a vertex carries its own discrete normal, principal
    directions and curvatures, and a third-order term fitted to its `CUBIC_RINGS`-ring
    neighbours, unless that surface misses a neighbour by more than `OUTLIER_FACTOR` times
    the median miss (Eq. 9 breaks down near umbilics). At every other vertex (the
    boundary, the ring next to it, irregular vertices) the principal curvatures, the
    third-order term and (off star centres) the principal direction are extended from the
    interior by the smoothest continuation along the net (`extend_vertex_values`: a
    biharmonic extension, which continues linear trends across the boundary). The extension
    is an affine combination of interior values, so a linear Weingarten relation of the
    interior holds at every vertex. A vertex that is no star centre (the boundary) gets the
    tangent plane through it that fits its neighbours best with those curvatures. Every
    vertex's osculating surface passes through the vertex itself: the one surface passes
    through every vertex of the net.

    Raises
    ------
    InputError
        When no vertex has discrete principal curvatures: use another panel surface model.
    """
    X, stars = mesh.vertices, mesh.stars
    n = len(X)
    normal, e1 = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    k = np.full((n, 2), np.nan)
    if len(stars):
        k1, k2 = principal_curvatures(X, stars)
        k[stars[:, 0]] = np.column_stack([k1, k2])
        normal[stars[:, 0]] = star_normals(X, stars)
        e1[stars[:, 0]] = principal_directions(X, stars)[0]
    framed = (np.all(np.isfinite(normal), axis=1) & np.all(np.isfinite(e1), axis=1)
              & (np.linalg.norm(np.nan_to_num(normal), axis=1) > 0))
    measured = framed & np.all(np.isfinite(k), axis=1)
    if not measured.any():
        raise InputError(f"{mesh.name}: no vertex star has discrete principal curvatures "
                         "(Eq. 7-9); use the panel surface 'local_fit' or 'corners'")
    normal = np.where(framed[:, None], normal, 0.0)
    e1 = np.where(framed[:, None], e1, 0.0)
    k = np.where(measured[:, None], k, 0.0)
    e1 = _unit(e1 - np.sum(e1 * normal, axis=1, keepdims=True) * normal)
    e1 = np.where(framed[:, None], e1, 0.0)
    e2 = np.cross(normal, e1)
    cubic = np.zeros((n, 4))
    own = np.flatnonzero(measured)
    cubic[own] = _cubic_terms(mesh, own, normal[own], e1[own], e2[own], k[own], CUBIC_RINGS)
    # Eq. 7-9 break down near umbilics and flat stars (a vanishing denominator): a vertex
    # whose own surface misses its neighbours by far more than is usual is extended instead
    elements = NetCurvature(origin=X, normal=normal, e1=e1, e2=e2, k1=k[:, 0], k2=k[:, 1],
                            cubic=cubic, measured=measured, miss=np.zeros(n))
    a, b = np.concatenate([mesh.edges, mesh.edges[:, ::-1]]).T
    miss = np.linalg.norm(osculating_points(elements, a, X[b]) - X[b], axis=1)
    worst = np.zeros(n)
    np.maximum.at(worst, a, np.where(measured[a], miss, 0.0))
    usual = max(float(np.median(worst[measured])), 1e-4 * mesh.mean_edge_length)
    measured &= worst <= OUTLIER_FACTOR * usual
    k = extend_vertex_values(mesh, measured, k)
    # third-order terms are too noisy to continue: an extended vertex has none
    cubic = np.where(measured[:, None], cubic, 0.0)
    # off the star centres the principal direction is extended too, then fitted in the
    # tangent plane found for it
    guide = extend_vertex_values(mesh, framed, e1)
    start = _vertex_face_normals(mesh)
    loose = np.flatnonzero(~framed)
    normal[loose], e1[loose] = _fit_tangent_planes(mesh, loose, start[loose], guide[loose],
                                                   k[loose], cubic[loose])
    e2 = np.cross(normal, e1)
    elements = NetCurvature(origin=X, normal=normal, e1=e1, e2=e2, k1=k[:, 0], k2=k[:, 1],
                            cubic=cubic, measured=measured, miss=np.zeros(n))
    miss = np.linalg.norm(osculating_points(elements, np.arange(n), X) - X, axis=1)
    return replace(elements, miss=miss)


def free_vertices(mesh) -> np.ndarray:
    """(n,) bool, the vertices in no star (neither a star's centre nor one of its four
    neighbours): no sphere, angle or curvature condition of a net holds them (the tips of a
    zigzag boundary).

    Examples
    --------
    >>> from fabplan.net.generate import height_field_grid
    >>> int(free_vertices(height_field_grid(4, 4, lambda x, y: 0 * x)).sum())  # the corners
    4
    """
    held = np.zeros(mesh.vertex_count, bool)
    held[np.asarray(mesh.stars).ravel()] = True
    return ~held


def settle_free_vertices(mesh):
    """The net with its free vertices (`free_vertices`) moved onto the net's own surface.

    A free vertex is held by no condition of the net, so a layout leaves it where the
    design is; where the net departs from the design, the panels at such a vertex bend to
    reach it. Each one is moved along the normal onto the mean of its edge neighbours'
    osculating surfaces (`net_curvature`, fitted without the free vertices): the net's
    spheres, angles and curvatures are unchanged, and its panels continue its surface.

    Returns
    -------
    `fabplan.net.mesh.QuadMesh` (the same mesh when no vertex is free) and (n,) float, how
    far each vertex moved (model units).
    """
    free = free_vertices(mesh)
    if not free.any() or not len(mesh.stars):
        return mesh, np.zeros(mesh.vertex_count)
    elements = net_curvature(mesh)
    X = mesh.vertices
    a, b = np.concatenate([mesh.edges, mesh.edges[:, ::-1]]).T
    use = free[a] & ~free[b]
    a, b = a[use], b[use]
    target = osculating_points(elements, b, X[a])
    total = np.zeros_like(X)
    np.add.at(total, a, target)
    count = np.bincount(a, minlength=len(X))
    moved = count > 0
    Y = X.copy()
    Y[moved] = total[moved] / count[moved, None]
    return mesh.with_vertices(Y), np.linalg.norm(Y - X, axis=1)


EXTENSION_BOUNDARY_WEIGHT = 1.0e-3
"""Weight of the Laplacian at boundary vertices in `extend_vertex_values` (their one-sided
Laplacian should not pull the extension flat)."""


def extend_vertex_values(mesh, known: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Values at every vertex: `values` where `known`, elsewhere the biharmonic extension.

    The unknown values minimize the sum of squared umbrella Laplacians (each vertex's value
    minus the mean of its neighbours' along the edges) over the vertices, the boundary's
    weighted by `EXTENSION_BOUNDARY_WEIGHT`: a linear trend across the boundary is continued,
    and the result is an affine combination of the known values (constants are kept).

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    known : (n,) bool.
    values : (n, d) float, read where `known`.

    Returns
    -------
    (n, d) float; zero on a part of the net without a known vertex.
    """
    n = mesh.vertex_count
    e = mesh.edges
    A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                      shape=(n, n)).tocsr()
    degree = np.asarray(A.sum(axis=1)).ravel()
    L = sp.identity(n, format="csr") - sp.diags(1.0 / np.maximum(degree, 1)) @ A
    w = np.where(mesh.is_boundary_vertex, EXTENSION_BOUNDARY_WEIGHT, 1.0)
    E = sp.diags(w) @ L
    B = (E.T @ E).tocsr()
    free = np.flatnonzero(~known)
    out = np.where(known[:, None], values, 0.0).astype(float)
    if free.size == 0:
        return out
    fixed = np.flatnonzero(known)
    M = B[free][:, free]
    # a tiny ridge keeps a part without known vertices solvable (at zero)
    M = M + 1e-12 * sp.identity(free.size)
    rhs = -(B[free][:, fixed] @ values[fixed])
    out[free] = np.asarray(spsolve(M.tocsc(), rhs)).reshape(free.size, -1)
    return out


def _vertex_face_normals(mesh) -> np.ndarray:
    """(n, 3) unit mean of the normals of the faces at each vertex."""
    normals = face_normals(mesh.vertices, mesh)
    face = _face_of_corner(mesh)
    total = np.zeros((mesh.vertex_count, 3))
    np.add.at(total, mesh.face_indices, normals[face])
    return _unit(total)


def _fit_tangent_planes(mesh, vertices: np.ndarray, normal: np.ndarray, guide: np.ndarray,
                        k: np.ndarray, cubic: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent planes at `vertices` (w,) whose osculating surfaces, with the given
    curvatures (w, 2) and third-order terms (w, 4), fit the `CUBIC_RINGS`-ring neighbours
    best: the surface's tilt is fitted by least squares (its height at the vertex is 0),
    a few rounds from the start normals (w, 3). Returns unit normals and principal
    directions (``guide`` (w, 3) projected into the plane), each (w, 3)."""
    if vertices.size == 0:
        return normal, guide
    X = mesh.vertices
    ids, real = _ring_neighbourhoods(mesh, vertices, CUBIC_RINGS)
    d = X[ids] - X[vertices][:, None, :]
    # vertices in no star are held by no condition of the net (a layout leaves them on
    # the design): they do not say where the net's surface runs
    w = (real & ~free_vertices(mesh)[ids]).astype(float)
    for _ in range(TILT_ITERATIONS):
        e1 = _unit(guide - np.sum(guide * normal, axis=1, keepdims=True) * normal)
        e2 = np.cross(normal, e1)
        x = np.einsum("vmj,vj->vm", d, e1)
        y = np.einsum("vmj,vj->vm", d, e2)
        z = np.einsum("vmj,vj->vm", d, normal)
        c = cubic
        r = z - (_circle_heights(k[:, :1], k[:, 1:], x, y)
                 + (c[:, :1] * x ** 3 + 3 * c[:, 1:2] * x * x * y + 3 * c[:, 2:3] * x * y * y
                    + c[:, 3:] * y ** 3) / 6.0)
        A = np.stack([x, y], axis=2)
        M = np.einsum("vmi,vm,vmj->vij", A, w, A)
        M[:, np.arange(2), np.arange(2)] += 1e-12 * (np.trace(M, axis1=1, axis2=2)[:, None] + 1e-300)
        slope = np.linalg.solve(M, np.einsum("vmi,vm,vm->vi", A, w, r)[..., None])[..., 0]
        # the height gains slope . (x, y): the normal tilts against it
        normal = _unit(normal - slope[:, :1] * e1 - slope[:, 1:] * e2)
    e1 = _unit(guide - np.sum(guide * normal, axis=1, keepdims=True) * normal)
    return normal, e1


def _ring_neighbourhoods(mesh, vertices: np.ndarray, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """(w, m) ids of the vertices within `rings` edges of each of `vertices` (w,), padded with
    the vertex itself, and (w, m) bool: a real neighbour (not the vertex, not padding)."""
    n = mesh.vertex_count
    e = mesh.edges
    A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                      shape=(n, n)).tocsr()
    reach = sp.identity(n, format="csr")
    for _ in range(rings):
        reach = reach + reach @ A
    reach = reach[vertices].tocsr()
    reach.sort_indices()
    counts = np.diff(reach.indptr)
    m = int(counts.max())
    row = np.repeat(np.arange(len(vertices)), counts)
    col = np.arange(len(row)) - reach.indptr[row]
    ids = np.repeat(vertices[:, None], m, axis=1)
    ids[row, col] = reach.indices
    return ids, ids != vertices[:, None]


def _circle_heights(k1: np.ndarray, k2: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Heights over the tangent plane of the surface whose normal section in every direction
    is the circle of its normal curvature ``(k1 x^2 + k2 y^2) / r^2`` (Euler's formula)."""
    Q = k1 * x * x + k2 * y * y
    r2 = np.maximum(x * x + y * y, 1e-300)
    return Q / (1.0 + np.sqrt(np.maximum(1.0 - Q * Q / r2, 0.0)))


def _cubic_terms(mesh, vertices: np.ndarray, normal: np.ndarray, e1: np.ndarray, e2: np.ndarray,
                 k: np.ndarray, rings: int) -> np.ndarray:
    """(w, 4) third-order terms at `vertices` (see `NetCurvature`): least squares on what the
    circles of the normal curvatures leave of the heights of the `rings`-ring neighbours."""
    X = mesh.vertices
    ids, real = _ring_neighbourhoods(mesh, vertices, rings)
    d = X[ids] - X[vertices][:, None, :]
    x = np.einsum("vmj,vj->vm", d, e1)
    y = np.einsum("vmj,vj->vm", d, e2)
    z = np.einsum("vmj,vj->vm", d, normal)
    r = z - _circle_heights(k[:, :1], k[:, 1:], x, y)
    w = real.astype(float)
    scale = np.sqrt(np.sum(w * (x * x + y * y), axis=1) / np.maximum(w.sum(axis=1), 1)) + 1e-300
    xs, ys = x / scale[:, None], y / scale[:, None]
    A = np.stack([xs ** 3, 3 * xs * xs * ys, 3 * xs * ys * ys, ys ** 3], axis=2) / 6.0
    M = np.einsum("vmi,vm,vmj->vij", A, w, A)
    # a tiny ridge settles a neighbourhood too small or too thin for all four terms
    M[:, np.arange(4), np.arange(4)] += 1e-9 * (np.trace(M, axis1=1, axis2=2)[:, None] + 1e-300)
    b = np.einsum("vmi,vm,vm->vi", A, w, r)
    return np.linalg.solve(M, b[..., None])[..., 0] / scale[:, None] ** 3


def osculating_points(curvature: NetCurvature, vertex: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Points of the vertices' osculating paraboloids over parameter points.

    The osculating surface of vertex ``v`` is the height field over its tangent plane
    (``x, y`` along ``e1, e2``) whose normal section in every direction is the circle of the
    normal curvature ``kn = Q / r^2``, ``Q = k1 x^2 + k2 y^2`` (Euler's formula, Meusnier):
    ``h = Q / (1 + sqrt(1 - Q^2 / r^2))`` (``Q / 2`` to second order), plus the vertex's
    third-order term (`NetCurvature.cubic`); a point ``q`` is moved along the normal onto it.

    Parameters
    ----------
    curvature : `NetCurvature`.
    vertex : (...) int; q : (..., 3) float, model units.

    Returns
    -------
    (..., 3) float
    """
    d = q - curvature.origin[vertex]
    n, e1, e2 = curvature.normal[vertex], curvature.e1[vertex], curvature.e2[vertex]
    x, y, z = np.sum(d * e1, -1), np.sum(d * e2, -1), np.sum(d * n, -1)
    c = curvature.cubic[vertex]
    h = (_circle_heights(curvature.k1[vertex], curvature.k2[vertex], x, y)
         + (c[..., 0] * x ** 3 + 3 * c[..., 1] * x * x * y + 3 * c[..., 2] * x * y * y
            + c[..., 3] * y ** 3) / 6.0)
    return q + (h - z)[..., None] * n


def _padded_corners(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(f, k_max) corner ids padded with the last corner, and (f, k_max) validity."""
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    k_max = int(sizes.max())
    slot = np.minimum(np.arange(k_max), sizes[:, None] - 1)
    return mesh.face_indices[ptr[:-1, None] + slot], np.arange(k_max)[None, :] < sizes[:, None]


def _corner_weights(sizes: np.ndarray, level: int) -> np.ndarray:
    """(f, k_max, t, k_max) weights of the corners at the fan grid points of every face.

    A fan point ``b0 P_j + b1 P_j+1 + bc C`` (see `panel_samples`) of a quad has the
    bilinear weights of its point ``b0 c_j + b1 c_j+1 + bc (1/2, 1/2)`` of the unit square;
    of another face the weights ``b0 + bc / k``, ``b1 + bc / k`` and ``bc / k``. On an edge
    (``bc = 0``) both are ``b0, b1`` of its two ends only.
    """
    B = _fan_weights(level)                                          # (t, 2)
    bc = 1.0 - B.sum(axis=1)
    k_max = int(sizes.max())
    nf, t = len(sizes), len(B)
    j = np.arange(k_max)
    nxt = np.where(j[None, :] + 1 >= sizes[:, None], 0, np.minimum(j + 1, k_max - 1)[None, :])
    W = np.zeros((nf, k_max, t, k_max))
    valid = j[None, :] < sizes[:, None]
    share = np.where(valid, 1.0 / sizes[:, None], 0.0)               # (f, k_max)
    W += share[:, None, None, :] * bc[None, None, :, None]
    rows, slots = np.nonzero(valid)
    # each (face, slot, corner) triple occurs once, so plain fancy-index updates add up
    W[rows, slots, :, slots] += B[:, 0]
    W[rows, slots, :, nxt[rows, slots]] += B[:, 1]
    quad = sizes == 4
    if quad.any():
        square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        uv = (B[None, :, :1] * square[:4, None, :] + B[None, :, 1:] * np.roll(square, -1, 0)[:, None, :]
              + bc[None, :, None] * 0.5)                             # (4, t, 2)
        u, v = uv[..., 0], uv[..., 1]
        bilinear = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], axis=-1)
        W[quad] = 0.0
        W[np.ix_(quad, np.arange(4), np.arange(t), np.arange(4))] = bilinear[None]
    return W


def osculating_panel_samples(mesh, curvature: NetCurvature, level: int) -> np.ndarray:
    """Points spread over every panel of the one surface through the net (model ``osculating``).

    Each face is split into a fan of triangles from the mean of its corners, with a grid of
    `level` steps per side, each grid point with weights ``w_i`` of the corners
    (`_corner_weights`: bilinear on a quad). The point is ``sum_i w_i S_i(q)`` at
    ``q = sum_i w_i P_i``: the blend of the corners' osculating paraboloids
    (`osculating_points`). On an edge only its two end vertices have weight, so the two
    panels of an edge share it exactly.

    Returns
    -------
    (f, s, 3) float model coordinates, padded like `panel_samples`.
    """
    X = mesh.vertices
    sizes = mesh.face_sizes
    nf = len(sizes)
    ids, valid = _padded_corners(mesh)
    W = _corner_weights(sizes, level)                                # (f, k, t, k)
    q = np.einsum("fktc,fcd->fktd", W, X[ids])
    S = np.zeros_like(q)
    for c in range(ids.shape[1]):  # one pass per corner slot (at most the largest face size)
        S += W[..., c, None] * osculating_points(curvature, ids[:, c, None, None], q)
    S = np.where(valid[:, :, None, None], S, S[:, :1, :1, :])
    return S.reshape(nf, -1, 3)


def fit_osculating_surfaces(mesh, curvature: NetCurvature,
                            level: int = 6) -> tuple[PanelSurfaces, np.ndarray]:
    """The panels of the one surface as quadrics: every panel's least-squares quadratic height
    field (in its face frame, see `PanelSurfaces`) of the one surface's points over the face
    (`osculating_panel_samples` at `level`).

    A mold is a quadric; a piece of the one surface over a 3 m panel is not one exactly
    (blending the corners' osculating surfaces leaves some tenths of a millimetre), so the
    panel that is cast is its quadric, and `gap` says how far that lies from the one surface.

    Returns
    -------
    surfaces : `PanelSurfaces` with model ``"osculating"``.
    gap : (f,) float, the largest distance (model units) between each panel's quadric and
        the one surface, measured along the face normal at the samples.
    """
    frames = fit_panel_surfaces(mesh, "corners")
    points = osculating_panel_samples(mesh, curvature, level)
    coefficients = _height_fits(points, np.ones(points.shape[:2]), frames.origin, frames.frame,
                                frames.scale)
    surfaces = replace(frames, coefficients=coefficients, model="osculating")
    P = np.einsum("fmj,fij->fmi", points - frames.origin[:, None, :], frames.frame)
    P = P / frames.scale[:, None, None]
    gap = np.abs(P[..., 2] - surfaces.height(P[..., :2])).max(axis=1) * frames.scale
    return surfaces, gap
