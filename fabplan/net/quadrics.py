"""Quadratic height fields over the faces of a net: the local surface each face stands for.

Every face gets a frame (origin at the mean of its corners, ``z`` along its Newell normal)
and a height field in it::

    z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2) / 2

fitted by weighted least squares to the face's corners (weight `CORNER_WEIGHT`, so the
surface passes through them) and, optionally, to the corners of every face that shares a
vertex with it (weight 1): the osculating paraboloid of the surface the net samples there.
Coordinates are divided by the face's RMS corner distance (`scale`) before the fit.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from .geometry import face_normals

__all__ = ["CORNER_WEIGHT", "face_frames", "face_neighbourhoods", "fit_height_fields",
           "height_field_values", "edge_steps"]

CORNER_WEIGHT = 1.0e6
"""Least-squares weight of a face's own corners against 1 for its neighbours' vertices."""

_RIDGE = 1.0e-9  # relative weight pulling undetermined curvature terms to zero


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def face_frames(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame of every face.

    Returns
    -------
    origin : (f, 3) float, mean of the face's corners (model units).
    frame : (f, 3, 3) float, rows: x-axis (towards the first corner), y-axis and unit
        Newell normal.
    scale : (f,) float, RMS distance of the corners from `origin` (model units).
    """
    X = mesh.vertices
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    nf = len(sizes)
    face = mesh.corner_faces
    corners = X[mesh.face_indices]
    origin = np.stack([np.bincount(face, corners[:, d], minlength=nf) for d in range(3)], 1) \
        / sizes[:, None]
    normal = face_normals(X, mesh)
    first = X[mesh.face_indices[ptr[:-1]]] - origin
    xaxis = _unit(first - np.sum(first * normal, axis=1, keepdims=True) * normal)
    frame = np.stack([xaxis, np.cross(normal, xaxis), normal], axis=1)
    d2 = np.sum((corners - origin[face]) ** 2, axis=1)
    scale = np.sqrt(np.bincount(face, d2, minlength=nf) / sizes)
    return origin, frame, scale


def face_neighbourhoods(mesh, ring: bool = True,
                        ignore: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The vertices each face's height field is fitted to.

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    ring : also the corners of every face sharing a vertex with the face (else its own
        corners only).
    ignore : (n,) bool, vertices that count only as a face's own corners, never as its
        neighbours' (vertices nothing holds, which say nothing of the surface around them).

    Returns
    -------
    vertices : (f, m) int, padded with the face's first corner.
    weight : (f, m) float, `CORNER_WEIGHT` for the face's corners, 1 for the other vertices,
        0 for padding and ignored neighbours.
    """
    nf, n = len(mesh.face_sizes), mesh.vertex_count
    face = mesh.corner_faces
    incidence = sp.csr_matrix((np.ones(len(face)), (face, mesh.face_indices)), shape=(nf, n))
    reach = (incidence @ (incidence.T @ incidence)).tocsr() if ring else incidence.copy()
    reach.sort_indices()
    counts = np.diff(reach.indptr)
    m = int(counts.max())
    row = np.repeat(np.arange(nf), counts)
    col = np.arange(len(row)) - reach.indptr[row]
    vertices = np.repeat(mesh.face_indices[mesh.face_indptr[:-1]][:, None], m, axis=1)
    vertices[row, col] = reach.indices
    weight = np.zeros((nf, m))
    is_corner = np.asarray(incidence[row, reach.indices]).ravel() > 0
    other = 1.0 if ignore is None else np.where(ignore[reach.indices], 0.0, 1.0)
    weight[row, col] = np.where(is_corner, CORNER_WEIGHT, 1.0 * other)
    return vertices, weight


def fit_height_fields(points: np.ndarray, weight: np.ndarray, origin: np.ndarray,
                      frame: np.ndarray, scale: np.ndarray,
                      ridge_weight: np.ndarray | None = None) -> np.ndarray:
    """Weighted least-squares height fields of points in the face frames.

    Parameters
    ----------
    points : (f, m, 3) float, model units; weight : (f, m) float.
    origin, frame, scale : the face frames (`face_frames`).
    ridge_weight : (f,) float, the weight the ridge is a share of (default: the sum of
        `weight`); points a fit must pass through (weight `CORNER_WEIGHT`) count as one
        each where the others are to settle the curvature.

    Returns
    -------
    (f, 6) float, ``(c0, c1, c2, a, b, c)`` in coordinates divided by `scale`.
    """
    P = np.einsum("fmj,fij->fmi", points - origin[:, None, :], frame) / scale[:, None, None]
    x, y, z = P[..., 0], P[..., 1], P[..., 2]
    A = np.stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=2)
    AtW = A.transpose(0, 2, 1) * weight[:, None, :]
    normal_matrix = AtW @ A
    # A tiny ridge on the curvature terms settles what the points leave free (a lone quad
    # fitted to its corners): the least-curved surface through them.
    total = weight.sum(axis=1) if ridge_weight is None else ridge_weight
    ridge = _RIDGE * total[:, None] * np.array([0, 0, 0, 1, 1, 1.0])
    normal_matrix[:, np.arange(6), np.arange(6)] += ridge
    rhs = AtW @ z[..., None]
    try:
        return np.linalg.solve(normal_matrix, rhs)[..., 0]
    except np.linalg.LinAlgError:
        # points that leave a slope free (all on one line: the samples of a design a face
        # overhangs, pulled onto its boundary): the least-norm fit, as pinv gives it
        return (np.linalg.pinv(normal_matrix) @ rhs)[..., 0]


def height_field_values(coefficients: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(...) heights of height fields (..., 6) at scaled plane points ``xy`` (..., 2)."""
    c = coefficients
    x, y = xy[..., 0], xy[..., 1]
    return (c[..., 0] + c[..., 1] * x + c[..., 2] * y
            + 0.5 * (c[..., 3] * x * x + 2 * c[..., 4] * x * y + c[..., 5] * y * y))


def edge_steps(mesh, origin: np.ndarray, frame: np.ndarray, scale: np.ndarray,
               coefficients: np.ndarray, fractions: npt.ArrayLike) -> np.ndarray:
    """How far the height fields of the two faces of every interior edge differ along it.

    At points of the edge's chord (`fractions` of the way from its first vertex), the point
    is lifted along face A's normal onto A's height field and measured along B's normal
    against B's, and the other way round.

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    origin, frame, scale : the face frames (`face_frames`); coefficients : (f, 6) their
        height fields (`fit_height_fields`).
    fractions : (t,) float.

    Returns
    -------
    (i,) float, model units, the largest over the points and both directions, for the edges
    in the order of ``mesh.interior_edge_faces``.
    """
    pairs, edges = mesh.interior_edge_faces, mesh.interior_edges
    if len(pairs) == 0:
        return np.zeros(0)
    t = np.asarray(fractions, float)
    X = mesh.vertices
    P = (1 - t[None, :, None]) * X[edges[:, :1]] + t[None, :, None] * X[edges[:, 1:]]  # (i, t, 3)

    def local(face: np.ndarray, q: np.ndarray) -> np.ndarray:
        d = q - origin[face][:, None, :]
        return np.einsum("etj,eij->eti", d, frame[face]) / scale[face, None, None]

    step = np.zeros(len(pairs))
    for a, b in ((0, 1), (1, 0)):
        A, B = pairs[:, a], pairs[:, b]
        c = local(A, P)
        lift = height_field_values(coefficients[A][:, None, :], c[..., :2]) - c[..., 2]
        on_a = P + (lift * scale[A, None])[..., None] * frame[A][:, None, 2, :]
        c = local(B, on_a)
        gap = np.abs(height_field_values(coefficients[B][:, None, :], c[..., :2]) - c[..., 2])
        step = np.maximum(step, (gap * scale[B, None]).max(axis=1))
    return step
