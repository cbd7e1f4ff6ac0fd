"""Panels of a net: the surface each face stands for, its principal frame and its samples.

Every face of a net is a panel. What is cast is a quadratic height field in the face's own
frame (origin at the mean of its corners, ``z`` along its Newell normal)::

    z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2) / 2

fitted by weighted least squares, over the face's polygon projected into the face plane.
The surface models differ in the surface a panel is a piece of, and so in the points the
fit sees:

``shared`` (one surface for the whole facade)
    the panels are pieces of one continuous surface through the net's vertices. Every edge
    is the mean of the two ``local_fit`` quadrics of its faces over the edge's chord (each
    lifted along its face's normal), so the two panels of an edge share it exactly; a
    panel is the quadric through its edges bent onto them (`shared_panel_samples`), and
    its cast quadric the least-squares fit of that. Neighbours then step apart only by
    their molds' gaps (at most twice the tolerance where every panel fits), and a panel
    that is far from any quadric shows as a panel no mold fits, not as a hidden step.
    The net's Meusnier spheres and principal curvatures enter through the ``local_fit``
    quadrics (fitted to the star and its ring); `benchmarks/bench_molds.py` measures the
    one surface's normal curvature along the net's edges against the spheres.
``local_fit`` (one quadric per face)
    the panel's corners (weight `CORNER_WEIGHT`, so the panel passes through them) and the
    corners of every face that shares a vertex with it (weight 1), vertices in no star
    excepted: the panel follows the surface the net samples (its osculating paraboloid).
    Neighbouring panels meet at the net's vertices; along the edge between them their
    quadrics, each fitted to its own neighbourhood, may differ (`surface_steps`), most
    near the boundary, where the fit is one-sided.
``corners``
    the panel's corners only, with the least curvature that passes through them: a planar
    face gives a flat panel, a twisted quad its hyperbolic paraboloid. This is the panel of
    a planar-quad (or ruled) paneling.
``design`` (a net laid out on a design with an exact surface: a built-in or NURBS design)
    the panel is the patch of the design over the face: the ``local_fit`` panel's points
    moved to their closest points on the exact design (`design_panel_samples`), and its
    quadric (for its curvatures and frame) the least-squares fit of those. Neighbouring
    panels are patches of one surface and share their edges exactly.

`surface_model` picks ``corners`` for a net whose faces are all flat within the tolerance
(its panels are meant to be cut flat), else ``design`` when an exact design is given and
``shared`` otherwise.

Distances are in model units, curvatures in inverse model units; the principal curvatures
are signed with respect to the face normal (positive when the panel bends towards it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...errors import InputError
from ...net.free_vertices import free_vertices
from ...net.geometry import face_planarity
from ...net.quadrics import (
    CORNER_WEIGHT,
    edge_steps,
    face_frames,
    face_neighbourhoods,
    fit_height_fields,
    height_field_values,
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
    "surface_steps",
    "design_panel_samples",
    "fit_design_panels",
    "shared_edge_points",
    "shared_panel_samples",
    "fit_shared_panels",
]

SURFACE_MODELS = ("shared", "local_fit", "corners", "design")


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def check_panels(mesh) -> None:
    """Refuse a net with a degenerate face, naming it (`QuadMesh` already refuses a mesh
    without faces).

    Raises
    ------
    InputError
        When a face has (almost) no area: its corners coincide or lie on one line.
    """
    X = mesh.vertices
    face = mesh.corner_faces
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


def surface_model(mesh, tolerance: float, model: str = "auto", design=None) -> str:
    """The panel surface model to use: ``model`` itself, or for ``"auto"`` ``"corners"`` when
    every face lies within `tolerance` (model units) of a plane, else ``"design"`` when
    `design` (a `fabplan.design.DesignSurface`) has an exact surface that every vertex of
    the net lies within `tolerance` of (and of its triangulation's chord error), else
    ``"shared"``. A net off its design (a net type that leaves it) is not cut from it: its
    panels would be patches of a surface they are not on, and their molds those of other
    panels.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import height_field_grid
    >>> flat = height_field_grid(4, 4, lambda x, y: 0 * x)
    >>> surface_model(flat, 0.001), surface_model(flat, 0.001, "local_fit")
    ('corners', 'local_fit')
    """
    model = "local_fit" if model == "smooth" else model       # its earlier name
    if model not in ("auto",) + SURFACE_MODELS:
        raise InputError(f"unknown panel surface model {model!r}: use auto, "
                         + ", ".join(SURFACE_MODELS))
    exact = design is not None and design.exact
    if model == "design" and not exact:
        raise InputError("the panel surface 'design' needs a net laid out on a built-in or NURBS "
                         "design (an exact surface)")
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
    if flat:
        return "corners"
    return "design" if exact and _on_design(mesh, design, tolerance) else "shared"


def _on_design(mesh, design, tolerance: float) -> bool:
    """Whether every vertex of `mesh` lies within `tolerance` (model units) of `design`,
    or of its triangulation (a net laid out on the design glides on its triangles, off the
    exact surface by up to their chord error)."""
    with np.errstate(all="ignore"):
        distance = design.distances(mesh.vertices)
    return bool(np.all(distance <= tolerance + design.chord_error))


def panel_neighbourhoods(mesh, model: str = "local_fit") -> tuple[np.ndarray, np.ndarray]:
    """The vertices each panel's surface is fitted to (`fabplan.net.quadrics.face_neighbourhoods`):
    for ``local_fit`` also the vertices of the faces sharing a vertex with it, except vertices in
    no star (`fabplan.net.free_vertices`: nothing of the net holds them, so they say nothing of
    its surface), which count only as their own faces' corners."""
    # a net without a single star holds none of its vertices: all of them count then
    ignore = free_vertices(mesh) if model == "local_fit" and len(mesh.stars) else None
    return face_neighbourhoods(mesh, ring=model == "local_fit", ignore=ignore)


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
    model : the surface model, ``"shared"``, ``"local_fit"``, ``"corners"`` or ``"design"``.
    """

    origin: np.ndarray
    frame: np.ndarray
    scale: np.ndarray
    coefficients: np.ndarray
    corners: np.ndarray
    model: str

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(f, s) scaled heights of the surfaces at scaled plane points ``xy`` (f, s, 2)."""
        return height_field_values(self.coefficients[:, None, :], xy)

    def to_model(self, xyz: np.ndarray) -> np.ndarray:
        """(f, s, 3) model coordinates of scaled face-frame points (f, s, 3)."""
        return self.origin[:, None, :] + self.scale[:, None, None] * (xyz @ self.frame)


def fit_panel_surfaces(mesh, model: str = "local_fit") -> PanelSurfaces:
    """Fit the quadratic surface of every panel (see the module notes).

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh`, faces of any size; check it with `check_panels` first.
    model : ``"local_fit"`` or ``"corners"`` (the ``shared`` and ``design`` panels start from
        ``local_fit``: `fit_shared_panels`, `fit_design_panels`).

    Returns
    -------
    PanelSurfaces
    """
    if model not in ("local_fit", "corners"):
        raise InputError(f"fit_panel_surfaces fits local_fit or corners panels, not {model!r}")
    X = mesh.vertices
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    origin, frame, scale = face_frames(mesh)
    vertices, weight = panel_neighbourhoods(mesh, model)
    coefficients = fit_height_fields(X[vertices], weight, origin, frame, scale)

    k_max = int(sizes.max())
    slot = np.minimum(np.arange(k_max), sizes[:, None] - 1)
    corner_ids = mesh.face_indices[ptr[:-1, None] + slot]
    corners = np.einsum("fkj,fij->fki", X[corner_ids] - origin[:, None, :], frame)[..., :2]
    corners = corners / scale[:, None, None]
    return PanelSurfaces(origin=origin, frame=frame, scale=scale, coefficients=coefficients,
                         corners=corners, model=model)


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


def _face_slots(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every face's corners padded to the largest face size.

    Returns
    -------
    corner, following : (f, k_max) int, index into ``face_indices`` of corner j and of the
        corner after it; padding slots repeat the last edge.
    valid : (f, k_max) bool, the slots that are the face's own.
    """
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    j = np.arange(int(sizes.max()))[None, :]
    corner = ptr[:-1, None] + np.minimum(j, sizes[:, None] - 1)
    following = ptr[:-1, None] + np.where(j + 1 >= sizes[:, None], 0, j + 1)
    return corner, following, j < sizes[:, None]


def _fan_points(mesh, surfaces: PanelSurfaces, weights: np.ndarray) -> np.ndarray:
    """Points of every fan triangle (face centre, corner j, corner j+1) at barycentric
    `weights` (t, 2) of its two corners, in the face plane and lifted onto `surfaces`.

    Returns
    -------
    (f, k_max, t, 3) float model coordinates; padding slots repeat the face's first point.
    """
    corner, following, valid = _face_slots(mesh)
    offset = mesh.face_indptr[:-1, None]
    P = surfaces.corners
    P_j = np.take_along_axis(P, (corner - offset)[..., None], axis=1)
    P_next = np.take_along_axis(P, (following - offset)[..., None], axis=1)
    xy = weights[None, None, :, :1] * P_j[:, :, None, :] + weights[None, None, :, 1:] * P_next[:, :, None, :]
    xy = np.where(valid[:, :, None, None], xy, xy[:, :1, :1, :])
    f, k, t = xy.shape[:3]
    z = surfaces.height(xy.reshape(f, k * t, 2))
    return surfaces.to_model(np.concatenate([xy.reshape(f, k * t, 2), z[..., None]], axis=2)
                             ).reshape(f, k, t, 3)


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
    points = _fan_points(mesh, surfaces, _fan_weights(level))
    return points.reshape(len(points), -1, 3)


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



def surface_steps(mesh, surfaces: PanelSurfaces, fractions: np.ndarray) -> np.ndarray:
    """How far the surfaces of the two panels of every interior edge differ along it
    (`fabplan.net.quadrics.edge_steps`): what a step keeps even with exact molds.

    Returns
    -------
    (i,) float, model units, for the edges in the order of ``mesh.interior_edge_faces``.
    """
    return edge_steps(mesh, surfaces.origin, surfaces.frame, surfaces.scale,
                      surfaces.coefficients, fractions)


def design_panel_samples(mesh, surfaces: PanelSurfaces, design, level: int) -> np.ndarray:
    """`panel_samples` moved onto the exact design: the points of the patch of `design` over
    every face (model ``design``; `surfaces` give the points they start from: the faces'
    ``local_fit`` or their ``design`` quadrics).

    Returns
    -------
    (f, s, 3) float model coordinates, padded like `panel_samples`.
    """
    points = panel_samples(mesh, surfaces, level)
    return design.closest_points(points.reshape(-1, 3)).reshape(points.shape)


def _fit_to_samples(mesh, local: PanelSurfaces, points: np.ndarray, model: str) -> PanelSurfaces:
    """Each face's least-squares height field of its samples (f, s, 3) (padded like
    `panel_samples`: padding gets no weight), in the frames of `local`."""
    sizes = mesh.face_sizes
    k_max = int(sizes.max())
    weight = np.repeat(np.arange(k_max)[None, :] < sizes[:, None], points.shape[1] // k_max,
                       axis=1).astype(float)
    coefficients = fit_height_fields(points, weight, local.origin, local.frame, local.scale)
    return replace(local, coefficients=coefficients, model=model)


def fit_design_panels(mesh, design, level: int) -> tuple[PanelSurfaces, np.ndarray]:
    """The quadrics of the patches of `design` over the faces (model ``design``): each
    face's least-squares height field of its `design_panel_samples` at `level`, in the
    frame of its ``local_fit`` panel.

    Returns
    -------
    surfaces : `PanelSurfaces` with model ``"design"``.
    points : (f, s, 3) float, the samples they were fitted to (padded like `panel_samples`).
    """
    local = fit_panel_surfaces(mesh, "local_fit")
    points = design_panel_samples(mesh, local, design, level)
    return _fit_to_samples(mesh, local, points, "design"), points


# ----------------------------------------------------------------------------- shared
def _lift(local: PanelSurfaces, face: np.ndarray, points: np.ndarray) -> np.ndarray:
    """`points` (f, k, t, 3) moved along the normal of `face` (f, k) onto its quadric."""
    origin, frame, scale = local.origin[face], local.frame[face], local.scale[face]
    q = np.einsum("fktj,fkij->fkti", points - origin[:, :, None, :], frame) / scale[..., None, None]
    lift = height_field_values(local.coefficients[face][:, :, None, :], q[..., :2]) - q[..., 2]
    return points + (lift * scale[..., None])[..., None] * frame[:, :, None, 2, :]


def shared_edge_points(mesh, local: PanelSurfaces, tau: np.ndarray) -> np.ndarray:
    """Points of every face's edges on the one surface of the net (model ``shared``).

    The point at fraction `tau` of the edge from corner j to corner j+1 is the mean of the
    chord's point lifted along the normals of the two faces of the edge onto their
    ``local_fit`` quadrics (`local`); on the boundary the face's own. Both faces of an edge
    get the same points.

    Returns
    -------
    (f, k_max, t, 3) float model coordinates, padded like `_fan_points`.
    """
    X = mesh.vertices
    corner, following, _ = _face_slots(mesh)
    a, b = X[mesh.face_indices[corner]], X[mesh.face_indices[following]]
    chord = a[:, :, None, :] + tau[None, None, :, None] * (b - a)[:, :, None, :]
    own = np.broadcast_to(np.arange(len(corner))[:, None], corner.shape)
    across = mesh.faces_across[corner]
    across = np.where(across >= 0, across, own)
    return 0.5 * (_lift(local, own, chord) + _lift(local, across, chord))


SHARED_OUTLINE_STEPS = 8
"""Points per edge (``tau = 0, 1/8, ..., 7/8``) the quadric of a ``shared`` panel is fitted to."""


def shared_panel_samples(mesh, local: PanelSurfaces, level: int) -> np.ndarray:
    """`panel_samples` of the one surface of the net (model ``shared``).

    A panel is the least-squares quadric of its `shared_edge_points` (at
    `SHARED_OUTLINE_STEPS` points per edge, its corners with weight `CORNER_WEIGHT`, so it
    passes through them), bent onto them: the point of the fan triangle (centre, corner j,
    corner j+1) with corner weights ``(s, t)`` is the quadric's point plus ``s + t`` times
    the offset of edge j from the quadric at ``t / (s + t)``. On the outline the panel is
    its edges exactly; at the centre and along the fan's spokes (the offsets vanish at the
    corners) it is the quadric.

    Returns
    -------
    (f, s, 3) float model coordinates, padded like `panel_samples`.
    """
    _, _, valid = _face_slots(mesh)
    f, k_max = valid.shape
    steps = SHARED_OUTLINE_STEPS
    outline = shared_edge_points(mesh, local, np.arange(steps) / steps).reshape(f, -1, 3)
    weight = np.repeat(valid, steps, axis=1) * np.tile(np.r_[CORNER_WEIGHT, np.ones(steps - 1)], k_max)
    coefficients = fit_height_fields(outline, weight, local.origin, local.frame, local.scale,
                                     ridge_weight=steps * valid.sum(axis=1))
    base = replace(local, coefficients=coefficients, model="shared")
    weights = _fan_weights(level)
    on_edge = weights.sum(axis=1)              # s + t: 0 at the centre, 1 on the edge
    tau = np.where(on_edge > 0, weights[:, 1] / np.maximum(on_edge, 1e-300), 0.0)
    # a fan grid has `level` + 1 distinct fractions along the edge: lift each once
    tau, which = np.unique(tau, return_inverse=True)
    offset = shared_edge_points(mesh, local, tau) - _fan_points(mesh, base, np.column_stack([1 - tau, tau]))
    offset = np.where(valid[:, :, None, None], offset, 0.0)       # padding: the face centre
    points = _fan_points(mesh, base, weights) + on_edge[None, None, :, None] * offset[:, :, which.ravel()]
    return points.reshape(len(points), -1, 3)


def fit_shared_panels(mesh, local: PanelSurfaces, level: int) -> tuple[PanelSurfaces, np.ndarray]:
    """The quadrics of the panels of the one surface of the net (model ``shared``): each
    face's least-squares height field of its `shared_panel_samples` at `level`.

    Parameters
    ----------
    local : the faces' ``local_fit`` surfaces (`fit_panel_surfaces`).

    Returns
    -------
    surfaces : `PanelSurfaces` with model ``"shared"``.
    points : (f, s, 3) float, the samples they were fitted to (padded like `panel_samples`).
    """
    points = shared_panel_samples(mesh, local, level)
    return _fit_to_samples(mesh, local, points, "shared"), points
