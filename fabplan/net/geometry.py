"""Discrete differential geometry of S-nets, vectorized over vertex stars.

All functions take vertex positions ``X : (n, 3) float`` and stars ``(s, 5) int`` rows
``[v, v1, v2, v3, v4]`` (see `fabplan.mesh`) and return one value per star. Lengths are in
model units, angles in radians, curvatures signed with respect to the discrete normal:
a Meusnier sphere of curvature ``k`` has its centre at ``v + n / k``.

References are to the sections and equations of "Principal Symmetric Meshes" (Pellis et al.).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "osculating_tangents",
    "star_normals",
    "intersection_angles",
    "canonical_stars",
    "StarSpheres",
    "fit_star_spheres",
    "vertex_normals",
    "principal_curvatures",
    "principal_directions",
    "face_planarity",
    "kink_angles",
    "star_planarity",
    "circumcircle_tangent",
    "face_normals",
    "vertex_contact_normals",
    "MannheimSpheres",
    "fit_mannheim_spheres",
    "ruling_directions",
    "ruling_angles",
    "normal_curvatures",
]


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def circumcircle_tangent(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Tangent at ``a`` of the circle through ``c, a, b``, pointing towards ``b`` (Lemma 2.12).

    Parameters
    ----------
    a, b, c : (..., 3) float

    Returns
    -------
    (..., 3) float, ``(b - a) / |b - a|^2 - (c - a) / |c - a|^2`` (not normalized).

    Examples
    --------
    >>> import numpy as np
    >>> a, b, c = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, -1.0, 0])
    >>> circumcircle_tangent(a, b, c)  # unit circle at (1, 0, 0): tangent along +y
    array([0., 1., 0.])
    """
    ab, ac = b - a, c - a
    with np.errstate(invalid="ignore", divide="ignore"):  # coincident points give NaN
        return (ab / np.sum(ab * ab, axis=-1, keepdims=True)
                - ac / np.sum(ac * ac, axis=-1, keepdims=True))


def osculating_tangents(X: np.ndarray, stars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangents of the discrete osculating circles of both parameter lines at each star centre.

    Returns
    -------
    t1 : (s, 3) float, tangent of the circle through v3, v, v1, pointing towards v1.
    t2 : (s, 3) float, tangent of the circle through v4, v, v2, pointing towards v2.
    """
    P = X[stars]
    return (circumcircle_tangent(P[:, 0], P[:, 1], P[:, 3]),
            circumcircle_tangent(P[:, 0], P[:, 2], P[:, 4]))


def star_normals(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(s, 3) unit discrete normals (Def. 2.13): orthogonal to both osculating tangents,
    oriented like the faces (counter-clockwise stars give ``t1 x t2``)."""
    t1, t2 = osculating_tangents(X, stars)
    return _unit(np.cross(t1, t2))


def intersection_angles(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(s,) float, angle in radians between the two osculating tangents (the net's angle)."""
    t1, t2 = osculating_tangents(X, stars)
    c = np.sum(_unit(t1) * _unit(t2), axis=1)
    return np.arccos(np.clip(c, -1.0, 1.0))


def canonical_stars(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """Stars relabelled so that the mean intersection angle is at most 90 degrees.

    An isogonal net of angle ``a`` is the same net as one of angle ``180 - a`` with the
    families swapped; fabplan reports and constrains the angle in (0, 90].
    """
    if len(stars) == 0:
        return stars
    if np.nanmean(np.cos(intersection_angles(X, stars))) < 0:
        return stars[:, [0, 2, 3, 4, 1]]
    return stars


@dataclass(frozen=True)
class StarSpheres:
    """Spheres fitted to the five vertices of each star.

    Attributes
    ----------
    centre : (s, 3) float, NaN for planar stars.
    radius : (s,) float, inf for planar stars.
    curvature : (s,) float, signed normal curvature ``1 / radius``, positive when the centre
        lies on the side of the discrete normal; 0 for a plane.
    residual : (s,) float, largest distance of a star vertex from its sphere (model units).
    coefficients : (s, 5) float, ``(a, b1, b2, b3, c)`` of ``a|x - v|^2 + b.(x - v) + c = 0``
        with ``|b|^2 - 4ac = 1`` and ``b`` pointing against the normal.
    """

    centre: np.ndarray
    radius: np.ndarray
    curvature: np.ndarray
    residual: np.ndarray
    coefficients: np.ndarray


def fit_star_spheres(X: np.ndarray, stars: np.ndarray,
                     normals: np.ndarray | None = None) -> StarSpheres:
    """Least-squares sphere (or plane) through the five vertices of each star.

    The fit is algebraic in coordinates centred at the star centre and scaled by the star's
    size (one batched SVD), then measured geometrically: `residual` is a true distance.

    Parameters
    ----------
    X : (n, 3) float
    stars : (s, 5) int
    normals : (s, 3) float, orientation reference; defaults to `star_normals`.
    """
    if normals is None:
        normals = star_normals(X, stars)
    P = X[stars] - X[stars[:, :1]]
    scale = np.linalg.norm(P[:, 1:], axis=2).mean(axis=1)
    Q = P / scale[:, None, None]
    D = np.concatenate([np.sum(Q * Q, axis=2)[..., None], Q, np.ones_like(Q[..., :1])], axis=2)
    _, _, vt = np.linalg.svd(D)
    u = vt[:, -1, :]
    a, b, c = u[:, 0], u[:, 1:4], u[:, 4]
    with np.errstate(invalid="ignore", divide="ignore"):
        u = u / np.sqrt(np.sum(b * b, axis=1) - 4 * a * c)[:, None]
        # orient so that the gradient at the centre vertex points against the normal
        flip = np.sum(u[:, 1:4] * normals, axis=1) > 0
        u[flip] *= -1
        a, b, c = u[:, 0], u[:, 1:4], u[:, 4]
        fq = a[:, None] * np.sum(Q * Q, axis=2) + np.einsum("sij,sj->si", Q, b) + c[:, None]
        denom = np.linalg.norm(a[:, None, None] * Q + b[:, None, :] / 2, axis=2) + 0.5
        residual = np.max(np.abs(fq) / denom, axis=1) * scale
        a_model = a / scale  # coefficients in model units: a/scale, b, c*scale
        curvature = 2 * a_model
        radius = np.abs(1 / curvature)
        centre = np.where(curvature[:, None] != 0, X[stars[:, 0]] - b / curvature[:, None], np.nan)
    coefficients = np.column_stack([a_model, b, c * scale])
    return StarSpheres(centre=centre, radius=radius, curvature=curvature, residual=residual,
                       coefficients=coefficients)


def vertex_normals(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(n, 3) float, the discrete normal at each star centre and NaN at other vertices."""
    N = np.full_like(X, np.nan)
    N[stars[:, 0]] = star_normals(X, stars)
    return N


def principal_directions(X: np.ndarray, stars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s, 3), (s, 3) unit discrete principal directions: bisectors of the osculating
    tangents (Def. 2.16), ``e1`` bisecting the angle between the families, ``e2`` its
    supplement."""
    t1, t2 = osculating_tangents(X, stars)
    t1, t2 = _unit(t1), _unit(t2)
    return _unit(t1 + t2), _unit(t1 - t2)


def principal_curvatures(X: np.ndarray, stars: np.ndarray,
                         curvature: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Discrete principal curvatures through the discrete Gauss map (Eq. 7-9).

    ``k1`` belongs to the direction ``e1`` of `principal_directions`, ``k2`` to ``e2``.
    A star whose neighbours are not all star centres themselves (no Gauss map star) gets
    NaN. Where the formula's denominator keeps less than `_GAUSS_MAP_BALANCE` of its terms
    (lines near the asymptotic directions, a Meusnier sphere that is a plane), the
    curvatures of the shape operator fitted to the normals' differences along both lines
    are taken (`_shape_operator_curvatures`; on well-posed stars of the authors' nets the
    two agree to 0.3-0.6 % in the median).

    Parameters
    ----------
    X : (n, 3) float
    stars : (s, 5) int
    curvature : (s,) float, signed normal curvature; defaults to the fitted spheres'.

    Returns
    -------
    k1, k2 : (s,) float
    """
    if curvature is None:
        curvature = fit_star_spheres(X, stars).curvature
    N = vertex_normals(X, stars)
    G = N[stars]  # (s, 5, 3) Gauss map star, NaN where a neighbour has no normal
    n = G[:, 0]
    t1, t2 = osculating_tangents(X, stars)
    w1 = circumcircle_tangent(G[:, 0], G[:, 1], G[:, 3])
    w2 = circumcircle_tangent(G[:, 0], G[:, 2], G[:, 4])
    t1, t2, w1, w2 = _unit(t1), _unit(t2), _unit(w1), _unit(w2)
    eta1, eta2 = t1 + t2, t1 - t2
    xi1, xi2 = w1 + w2, w1 - w2

    def det(p, q, r):
        return np.sum(np.cross(p, q) * r, axis=1)

    with np.errstate(invalid="ignore", divide="ignore"):
        d_n = det(xi1 / np.sum(xi1 * xi1, axis=1, keepdims=True), xi2, n)
        d_v = det(eta1 / np.sum(eta1 * eta1, axis=1, keepdims=True), eta2, n)
        s = np.sum(t1 * t2, axis=1)
        denom = d_v * (1 + s) + d_n * (1 - s)
        k1 = 2 * curvature * d_v / denom
        k2 = 2 * curvature * d_n / denom
        # where the lines run near the asymptotic directions (a near-minimal saddle) the
        # normal curvature along them and the denominator both vanish, and their ratio is
        # noise (principal curvatures of 7 1/m on a roof whose largest is 0.06)
        balance = np.abs(denom) / (np.abs(d_v) * (1 + s) + np.abs(d_n) * (1 - s))
    # a flat star's sphere is a plane: the formula's 0 / 0, taken by the shape operator too
    lost = (curvature == 0) | ~(balance >= _GAUSS_MAP_BALANCE)
    if lost.any():
        k1[lost], k2[lost] = _shape_operator_curvatures(X, N, stars[lost], _unit(eta1[lost]),
                                                        _unit(eta2[lost]))
    return k1, k2


_GAUSS_MAP_BALANCE = 0.05
"""Below this share of the Gauss map formula's terms its denominator keeps, the principal
curvatures are taken from the shape operator of the normals' differences instead."""


def _shape_operator_curvatures(X: np.ndarray, N: np.ndarray, stars: np.ndarray,
                               e1: np.ndarray, e2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normal curvatures along `e1`, `e2` (s, 3) of the symmetric shape operator that fits
    the normals' central differences along both lines of each star in least squares:
    ``S dx = -dn`` in the basis (e1, e2), two equations per line, three unknowns. NaN
    where a neighbour has no normal."""
    rows, rhs = [], []
    for ahead, behind in ((1, 3), (2, 4)):
        dx = X[stars[:, ahead]] - X[stars[:, behind]]
        dn = N[stars[:, ahead]] - N[stars[:, behind]]
        cx, cy = np.sum(dx * e1, axis=1), np.sum(dx * e2, axis=1)
        zero = np.zeros_like(cx)
        rows += [np.stack([cx, cy, zero], axis=1), np.stack([zero, cx, cy], axis=1)]
        rhs += [-np.sum(dn * e1, axis=1), -np.sum(dn * e2, axis=1)]
    A = np.stack(rows, axis=1)                      # (s, 4, 3): S11, S12, S22
    B = np.stack(rhs, axis=1)
    k1, k2 = np.full(len(stars), np.nan), np.full(len(stars), np.nan)
    ok = np.isfinite(A).all(axis=(1, 2)) & np.isfinite(B).all(axis=1)
    if ok.any():
        # least squares through the pseudo-inverse: a star whose chords run in one line
        # has no unique operator (the minimum-norm one), where a solve would raise
        solution = np.einsum("sjk,sk->sj", np.linalg.pinv(np.einsum("sij,sik->sjk", A[ok], A[ok])),
                             np.einsum("sij,si->sj", A[ok], B[ok]))
        k1[ok], k2[ok] = solution[:, 0], solution[:, 2]
    return k1, k2


def _plane_distances(P: np.ndarray) -> np.ndarray:
    """(m,) largest distance of each point group (m, k, 3) from its least-squares plane."""
    C = P - P.mean(axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(C)
    normal = vt[:, -1, :]
    return np.max(np.abs(np.einsum("mkj,mj->mk", C, normal)), axis=1)


def face_planarity(X: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(q,) float, largest distance of a quad's vertices from its best-fit plane."""
    if len(quads) == 0:
        return np.zeros(0)
    return _plane_distances(X[quads])


def kink_angles(X: np.ndarray, mesh) -> np.ndarray:
    """(i,) float, angle in radians between the normals of the two faces at every interior
    edge of `mesh` (0 where neighbouring panels continue each other smoothly).

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.mesh import QuadMesh
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 1], [0, 1, 0], [1, 1, 0], [2, 1, 1.0]])
    >>> mesh = QuadMesh(X, [[0, 1, 4, 3], [1, 2, 5, 4]])
    >>> np.degrees(kink_angles(X, mesh)).round(6)
    array([45.])
    """
    pairs = mesh.interior_edge_faces
    if len(pairs) == 0:
        return np.zeros(0)
    n = face_normals(X, mesh)
    cos = np.sum(n[pairs[:, 0]] * n[pairs[:, 1]], axis=1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def star_planarity(X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(s,) float, largest distance of a star's five vertices from their best-fit plane
    (zero on an A-net)."""
    if len(stars) == 0:
        return np.zeros(0)
    return _plane_distances(X[stars])


# ---------------------------------------------------------------------- S*-nets
def face_normals(X: np.ndarray, mesh) -> np.ndarray:
    """(f, 3) unit normals of all faces (Newell's method, any polygon size)."""
    if len(mesh.face_sizes) == 0:
        return np.zeros((0, 3))
    cross = np.cross(X[mesh.face_indices], X[mesh.corner_next_vertices])
    # a face's corners are consecutive: summed corner by corner in their order, without a
    # scatter (the solver tests every iterate for folds with these normals)
    first, sizes = mesh.face_indptr[:-1], mesh.face_sizes
    normal = cross[first]
    for k in range(1, int(sizes.max())):     # corners of a face, not faces
        if sizes.min() > k:
            normal += cross[first + k]
        else:
            longer = np.flatnonzero(sizes > k)
            normal[longer] += cross[first[longer] + k]
    return _unit(normal)


def vertex_contact_normals(mesh, X: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(n, 3) unit normals for contact elements: the discrete normal (Def. 2.13) at star
    centres, the mean of the adjacent face normals elsewhere (section 4.3)."""
    F = face_normals(X, mesh)
    face = mesh.corner_faces
    N = np.zeros_like(X)
    np.add.at(N, mesh.face_indices, F[face])
    N = _unit(N)
    N[stars[:, 0]] = star_normals(X, stars)
    return N


@dataclass(frozen=True)
class MannheimSpheres:
    """Oriented spheres touching the five oriented tangent planes of each star.

    Attributes
    ----------
    centre : (s, 3) float
    radius : (s,) float, signed: the centre is at ``v + radius * n`` from each contact point.
    residual : (s,) float, largest signed-distance misfit of the five planes (model units).
    """

    centre: np.ndarray
    radius: np.ndarray
    residual: np.ndarray


def fit_mannheim_spheres(X: np.ndarray, N: np.ndarray, stars: np.ndarray) -> MannheimSpheres:
    """Least-squares oriented sphere ``n_i . (m - v_i) = rho`` for the planes of each star.

    Parameters
    ----------
    X : (n, 3) float, contact points.
    N : (n, 3) float, unit normals of the tangent planes.
    stars : (s, 5) int
    """
    n, v = N[stars], X[stars]
    origin = v[:, :1, :]
    A = np.concatenate([n, -np.ones_like(n[..., :1])], axis=2)          # (s, 5, 4)
    b = np.sum(n * (v - origin), axis=2)                                 # about the centre
    sol = np.einsum("sij,sj->si", np.linalg.pinv(A), b)
    residual = np.abs(np.einsum("sij,sj->si", A, sol) - b).max(axis=1)
    return MannheimSpheres(centre=sol[:, :3] + origin[:, 0], radius=sol[:, 3], residual=residual)


def ruling_directions(X: np.ndarray, N: np.ndarray, stars: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Rulings of the two osculating cones at each star centre (Eq. 5), not normalized.

    The cone of family 1 touches the planes at v3, v, v1; its ruling through v is
    ``<v1 - v, n1> n x n3 + <v3 - v, n3> n1 x n``; family 2 uses v2, v4 likewise.
    """
    P, M = X[stars], N[stars]

    def ruling(i, j):
        a = np.sum((P[:, i] - P[:, 0]) * M[:, i], axis=1)[:, None]
        b = np.sum((P[:, j] - P[:, 0]) * M[:, j], axis=1)[:, None]
        return a * np.cross(M[:, 0], M[:, j]) + b * np.cross(M[:, i], M[:, 0])

    return ruling(1, 3), ruling(2, 4)


def ruling_angles(X: np.ndarray, N: np.ndarray, stars: np.ndarray) -> np.ndarray:
    """(s,) float, angle in radians in [0, pi/2] between the two ruling lines of each star."""
    r1, r2 = ruling_directions(X, N, stars)
    c = np.abs(np.sum(_unit(r1) * _unit(r2), axis=1))
    return np.arccos(np.clip(c, 0.0, 1.0))


def normal_curvatures(X: np.ndarray, N: np.ndarray, stars: np.ndarray,
                      directions: np.ndarray) -> np.ndarray:
    """Normal curvature of the surface sampled by contact elements, in given directions.

    The shape operator ``S`` (``dn = -S dp`` in the tangent plane of the star centre) is
    fitted by least squares to the normal differences towards the four neighbours; the
    result is ``II(d, d) = d . S d``, positive where the surface curves towards ``N``.
    (The neighbours' heights alone leave the mixed term open: a star's four neighbours lie
    on two lines through its centre.)

    Parameters
    ----------
    X : (n, 3) float, contact points.
    N : (n, 3) float, unit normals.
    stars : (s, 5) int
    directions : (s, 3) float, unit tangent directions at the star centres.

    Returns
    -------
    (s,) float, normal curvatures (1 / model units).

    Examples
    --------
    >>> u = np.radians(np.array([0.0, 10, 0, -10, 0]))
    >>> v = np.radians(np.array([0.0, 0, 10, 0, -10]))
    >>> P = 100 * np.stack([np.sin(u) * np.cos(v), np.sin(v), -np.cos(u) * np.cos(v)], 1)
    >>> k = normal_curvatures(P, -P / 100, np.arange(5)[None], np.array([[1.0, 0, 0]]))
    >>> round(float(k[0]), 9)
    0.01
    """
    n0 = N[stars[:, 0]]
    helper = np.where(np.abs(n0[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    b1 = _unit(np.cross(n0, helper))
    b2 = np.cross(n0, b1)
    dP = X[stars[:, 1:]] - X[stars[:, :1]]
    dN = N[stars[:, 1:]] - N[stars[:, :1]]
    p1, p2 = np.sum(dP * b1[:, None], axis=2), np.sum(dP * b2[:, None], axis=2)
    q1, q2 = np.sum(dN * b1[:, None], axis=2), np.sum(dN * b2[:, None], axis=2)
    zero = np.zeros_like(p1)
    # unknowns (s11, s12, s22): -dn1 = s11 p1 + s12 p2, -dn2 = s12 p1 + s22 p2
    A = np.concatenate([np.stack([p1, p2, zero], axis=2), np.stack([zero, p1, p2], axis=2)], axis=1)
    b = -np.concatenate([q1, q2], axis=1)
    s = np.linalg.solve(np.einsum("sij,sik->sjk", A, A), np.einsum("sij,si->sj", A, b)[..., None])[..., 0]
    d1, d2 = np.sum(directions * b1, axis=1), np.sum(directions * b2, axis=1)
    return s[:, 0] * d1 * d1 + 2 * s[:, 1] * d1 * d2 + s[:, 2] * d2 * d2
