"""Discrete S-net geometry against exact answers.

Exact S-nets come from surfaces of revolution ``p(s, phi) = (r(s) cos phi, r(s) sin phi,
z(s))`` sampled diagonally: vertex (i, j) at ``phi = (i + j) d / 2``, ``s = s0 + (j - i) d / 2``.
Each star is mirror-symmetric in the meridian plane through its centre (the reflection swaps
``(i + 1, j)`` with ``(i, j - 1)`` and ``(i - 1, j)`` with ``(i, j + 1)``), so the sphere
through the centre and two neighbours with its centre on that plane passes through all five.
"""

from __future__ import annotations

import numpy as np
import pytest

from fabplan.net.geometry import (
    canonical_stars,
    circumcircle_tangent,
    face_planarity,
    fit_star_spheres,
    intersection_angles,
    principal_curvatures,
    principal_directions,
    star_normals,
    star_planarity,
)
from fabplan.net.mesh import QuadMesh

RNG_SEED = 20240611


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def revolution_net(r, z, *, s0: float, d: float, n: int = 11, transpose: bool = False,
                   name: str = "revolution") -> QuadMesh:
    """The diagonal n x n net on a surface of revolution (see the module notes).

    `transpose` swaps the index directions, which reverses the face orientation.
    """
    i, j = np.meshgrid(np.arange(n) - n // 2, np.arange(n) - n // 2, indexing="ij")
    phi = (i + j) * d / 2
    s = s0 + (j - i) * d / 2
    P = np.stack([r(s) * np.cos(phi), r(s) * np.sin(phi), z(s)], axis=-1)
    return QuadMesh.grid(P.transpose(1, 0, 2) if transpose else P, name=name)


SPHERE_R = 3.0
CYLINDER_R = 2.0

PROFILES = {
    "sphere": (lambda s: SPHERE_R * np.sin(s / SPHERE_R), lambda s: -SPHERE_R * np.cos(s / SPHERE_R),
               SPHERE_R * 1.2),
    "cylinder": (lambda s: CYLINDER_R + 0 * s, lambda s: s, 0.0),
    "torus": (lambda s: 4 + np.cos(s), lambda s: np.sin(s), 0.4),
    "vase": (lambda s: 2 + 0.5 * np.sin(1.3 * s), lambda s: s + 0.1 * s * s, 0.3),
}


def profile_net(name: str, *, d: float = 0.15, transpose: bool = False) -> QuadMesh:
    r, z, s0 = PROFILES[name]
    return revolution_net(r, z, s0=s0, d=d, transpose=transpose, name=name)


# ---------------------------------------------------------------------------- Lemma 2.12


def _circumcentres(A, B, C):
    a, b = B - A, C - A
    axb = np.cross(a, b)
    return A + np.cross(np.sum(a * a, 1, keepdims=True) * b - np.sum(b * b, 1, keepdims=True) * a,
                        axb) / (2 * np.sum(axb * axb, 1, keepdims=True))


def test_circumcircle_tangent_touches_the_circle_and_points_towards_b():
    rng = np.random.default_rng(RNG_SEED)
    A, B, C = (rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-2, 2, size=(500, 1))
               for _ in range(3))
    # keep triangles whose smallest angle is at least 5 degrees
    def angle(p, q, r):
        return np.arccos(np.clip(np.sum(_unit(q - p) * _unit(r - p), 1), -1, 1))
    ok = np.min([angle(A, B, C), angle(B, C, A), angle(C, A, B)], axis=0) > np.radians(5)
    A, B, C = A[ok], B[ok], C[ok]
    assert len(A) > 200
    centre = _circumcentres(A, B, C)
    rho = np.linalg.norm(A - centre, axis=1)
    assert np.allclose(np.linalg.norm(B - centre, axis=1), rho, rtol=1e-9)
    assert np.allclose(np.linalg.norm(C - centre, axis=1), rho, rtol=1e-9)

    T = circumcircle_tangent(A, B, C)
    t = _unit(T)
    assert np.abs(np.sum(t * (A - centre), 1) / rho).max() < 1e-9          # orthogonal to the radius
    m = _unit(np.cross(A - C, B - A))                                   # normal of c -> a -> b
    assert np.abs(np.sum(t * m, 1)).max() < 1e-9                        # in the circle's plane
    # the direction of travel c -> a -> b at a
    travel = _unit(np.cross(m, A - centre))
    assert np.sum(t * travel, 1).min() > 1 - 1e-9
    # |T| is the distance of the images of b and c under inversion in a unit sphere at a
    want = np.linalg.norm(B - C, axis=1) / (np.linalg.norm(B - A, axis=1) * np.linalg.norm(C - A, axis=1))
    assert np.allclose(np.linalg.norm(T, axis=1), want, rtol=1e-9)


def test_circumcircle_tangent_broadcasts_over_leading_axes():
    rng = np.random.default_rng(1)
    A, B, C = (rng.normal(size=(4, 6, 3)) for _ in range(3))
    T = circumcircle_tangent(A, B, C)
    assert T.shape == (4, 6, 3)
    assert np.array_equal(T.reshape(-1, 3), circumcircle_tangent(*(p.reshape(-1, 3) for p in (A, B, C))))


# ---------------------------------------------------------------------------- sphere fits


def _stars_on_spheres(count: int, rng):
    """Stars whose five vertices lie on random spheres; half of them listed clockwise."""
    centre = rng.normal(size=(count, 3)) * 20
    radius = 10.0 ** rng.uniform(-1, 2, size=count)
    normal = _unit(rng.normal(size=(count, 3)))
    e1 = _unit(np.cross(normal, rng.normal(size=(count, 3))))
    e2 = np.cross(normal, e1)
    v = centre + radius[:, None] * normal
    angles = np.array([0.0, 0.5, 1.0, 1.5]) * np.pi + rng.uniform(-0.3, 0.3, size=(count, 4))
    length = radius[:, None] * rng.uniform(0.05, 0.3, size=(count, 4))
    flat = v[:, None] + length[..., None] * (np.cos(angles)[..., None] * e1[:, None]
                                              + np.sin(angles)[..., None] * e2[:, None])
    nbrs = centre[:, None] + radius[:, None, None] * _unit(flat - centre[:, None])
    clockwise = rng.random(count) < 0.5
    nbrs[clockwise] = nbrs[clockwise][:, ::-1]
    X = np.concatenate([v[:, None], nbrs], axis=1).reshape(-1, 3)
    stars = np.arange(5 * count).reshape(count, 5)
    return X, stars, centre, radius


def test_fit_star_spheres_recovers_exact_spheres():
    rng = np.random.default_rng(RNG_SEED)
    X, stars, centre, radius = _stars_on_spheres(400, rng)
    fit = fit_star_spheres(X, stars)
    size = np.linalg.norm(X[stars[:, 1:]] - X[stars[:, :1]], axis=2).mean(axis=1)
    assert np.max(fit.residual / size) < 1e-10
    assert np.allclose(fit.radius, radius, rtol=1e-8)
    assert np.allclose(np.abs(fit.curvature), 1 / radius, rtol=1e-8)
    assert np.max(np.linalg.norm(fit.centre - centre, axis=1) / radius) < 1e-8
    # sign convention: the centre lies at v + n / k, on the side of the normal when k > 0
    n = star_normals(X, stars)
    assert np.allclose(fit.centre, X[stars[:, 0]] + n / fit.curvature[:, None], rtol=0,
                       atol=1e-8 * radius.max())
    side = np.sum((fit.centre - X[stars[:, 0]]) * n, axis=1)
    assert np.all(np.sign(side) == np.sign(fit.curvature))
    assert (fit.curvature > 0).any() and (fit.curvature < 0).any()  # both orientations tested
    # normalized coefficients with b against the normal
    a, b, c = fit.coefficients[:, 0], fit.coefficients[:, 1:4], fit.coefficients[:, 4]
    assert np.allclose(np.sum(b * b, 1) - 4 * a * c, 1, atol=1e-9)
    assert np.all(np.sum(b * n, 1) <= 0)


def test_fit_star_spheres_follows_the_given_normals():
    rng = np.random.default_rng(3)
    X, stars, centre, _ = _stars_on_spheres(50, rng)
    n = star_normals(X, stars)
    fit, flipped = fit_star_spheres(X, stars, n), fit_star_spheres(X, stars, -n)
    assert np.array_equal(flipped.curvature, -fit.curvature)
    assert np.allclose(flipped.centre, fit.centre, rtol=1e-12, atol=1e-9)


PLANES = {"xy": (0.0, 0.0), "tilted": (1.0, 2.0), "steep": (3.0, 1.0), "shallow": (0.5, -0.25)}


def _planar_grid(slope) -> QuadMesh:
    """A skewed grid on the plane z = a x + b y with exactly representable coordinates."""
    a, b = slope
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    u = u + 0.25 * v + 7
    return QuadMesh.grid(np.stack([u, v, a * u + b * v], axis=-1), name="plane")


# the 0/0 warnings of a flat Gauss map are a known bug (see test_cli)
@pytest.mark.filterwarnings("ignore:invalid value encountered in divide:RuntimeWarning")
@pytest.mark.parametrize("slope", PLANES.values(), ids=PLANES.keys())
def test_planar_stars_have_zero_curvature_and_infinite_radius(slope):
    mesh = _planar_grid(slope)
    X, S = mesh.vertices, mesh.stars
    fit = fit_star_spheres(X, S)
    assert len(S) == 12
    assert np.all(fit.curvature == 0)
    assert np.all(np.isinf(fit.radius))
    assert fit.residual.max() < 1e-14 * mesh.mean_edge_length * 10
    assert star_planarity(X, S).max() < 1e-13
    assert face_planarity(X, mesh.quads).max() < 1e-13
    k1, k2 = principal_curvatures(X, S)
    # the shape operator of the normals' differences where every neighbour has a normal
    # (the Gauss map formula divides zero by zero on a plane), NaN elsewhere
    inner = np.isfinite(k1)
    assert inner.sum() == 2 and np.isfinite(k2[inner]).all()
    assert np.abs(k1[inner]).max() < 1e-12 and np.abs(k2[inner]).max() < 1e-12


def test_planar_star_centre_is_nan():
    mesh = _planar_grid(PLANES["tilted"])
    fit = fit_star_spheres(mesh.vertices, mesh.stars)
    assert np.isnan(fit.centre).all()


def test_face_planarity_measures_the_twist_of_a_quad():
    twist = np.array([0.01, 0.1, 0.3])
    corners = np.array([[0, 0, 1], [1, 0, -1], [1, 1, 1], [0, 1, -1]], float)
    X = np.concatenate([corners * [1, 1, t] for t in twist])
    quads = np.arange(12).reshape(3, 4)
    # the best-fit plane of this symmetric twist is z = 0, at distance t from every corner
    assert np.allclose(face_planarity(X, quads), twist, rtol=1e-12)
    assert face_planarity(X, np.zeros((0, 4), int)).shape == (0,)


def test_star_planarity_is_positive_on_a_sphere():
    mesh = profile_net("sphere")
    assert star_planarity(mesh.vertices, mesh.stars).min() > 1e-3 * mesh.mean_edge_length


# ---------------------------------------------------------------------------- exact S-nets


@pytest.mark.parametrize("name", PROFILES)
def test_rotational_diagonal_net_is_an_exact_snet(name):
    mesh = profile_net(name)
    X, S = mesh.vertices, mesh.stars
    assert len(S) == 81
    fit = fit_star_spheres(X, S)
    assert fit.residual.max() < 1e-10 * mesh.mean_edge_length
    # the fitted centres lie on the axis' meridian plane through each star centre
    phi = np.arctan2(X[S[:, 0], 1], X[S[:, 0], 0])
    across = -fit.centre[:, 0] * np.sin(phi) + fit.centre[:, 1] * np.cos(phi)
    assert np.abs(across).max() < 1e-9 * fit.radius.max()


@pytest.mark.parametrize("transpose", [False, True], ids=["outward", "inward"])
def test_sphere_net_curvatures_are_the_sphere(transpose):
    mesh = profile_net("sphere", transpose=transpose)
    X, S = mesh.vertices, mesh.stars
    n = star_normals(X, S)
    outward = np.sum(n * X[S[:, 0]], axis=1) / SPHERE_R
    assert np.allclose(np.abs(outward), 1, atol=1e-12)  # the discrete normal is radial
    sign = np.sign(outward[0])
    assert np.all(np.sign(outward) == sign) and sign == (-1 if transpose else 1)

    fit = fit_star_spheres(X, S)
    assert np.allclose(fit.radius, SPHERE_R, rtol=1e-10)
    # k = -1/R for the outward normal, +1/R for the inward one: centre = v + n / k = origin
    assert np.allclose(fit.curvature, -sign / SPHERE_R, rtol=1e-10)
    assert np.abs(X[S[:, 0]] + n / fit.curvature[:, None]).max() < 1e-9
    assert np.abs(fit.centre).max() < 1e-9

    k1, k2 = principal_curvatures(X, S, fit.curvature)
    defined = np.isfinite(k1)
    assert defined.sum() == 7 * 7  # stars whose four neighbours are star centres
    assert np.allclose(k1[defined], -sign / SPHERE_R, rtol=1e-9)
    assert np.allclose(k2[defined], -sign / SPHERE_R, rtol=1e-9)
    assert np.allclose(np.abs(k1 + k2)[defined] / 2, 1 / SPHERE_R, rtol=1e-9)


def test_cylinder_net_principal_curvatures_and_directions():
    mesh = profile_net("cylinder")
    X, S = mesh.vertices, mesh.stars
    fit = fit_star_spheres(X, S)
    k1, k2 = principal_curvatures(X, S, fit.curvature)
    e1, e2 = principal_directions(X, S)
    theta = intersection_angles(X, S)
    defined = np.isfinite(k1)
    assert defined.sum() == 49
    k1, k2, e1, e2, theta, kn = (a[defined] for a in (k1, k2, e1, e2, theta, fit.curvature))
    # this net's families are not orthogonal, so Euler's formula is not trivial here
    assert np.all(np.abs(np.degrees(theta) - 90) > 10)
    # e1 bisects the families' angle and runs around the axis, e2 along the rulings
    assert np.abs(e1[:, 2]).max() < 1e-9 and np.abs(np.abs(e2[:, 2]) - 1).max() < 1e-9
    assert np.abs(np.abs(k1) * CYLINDER_R - 1).max() < 0.03
    assert np.abs(k2).max() < 1e-9 / CYLINDER_R
    # the spheres sit on the side of the axis: curvature sign of the circle's
    n = star_normals(X, S)[defined]
    towards_axis = -np.sum(n * (X[S[defined, 0]] * [1, 1, 0]), axis=1)
    assert np.all(np.sign(k1) == np.sign(towards_axis))
    assert np.allclose(k1 * np.cos(theta / 2) ** 2 + k2 * np.sin(theta / 2) ** 2, kn,
                       rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["torus", "vase"])
def test_euler_formula_on_rotational_nets(name):
    mesh = profile_net(name)
    X, S = mesh.vertices, mesh.stars
    fit = fit_star_spheres(X, S)
    k1, k2 = principal_curvatures(X, S, fit.curvature)
    theta = intersection_angles(X, S)
    defined = np.isfinite(k1)
    assert defined.sum() == 49
    euler = k1 * np.cos(theta / 2) ** 2 + k2 * np.sin(theta / 2) ** 2
    assert np.abs(euler - fit.curvature)[defined].max() < 1e-12


# ---------------------------------------------------------------------------- bundled nets


@pytest.fixture(params=["wein99", "cmc1"])
def bundled(request):
    mesh = request.getfixturevalue(request.param)
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    fit = fit_star_spheres(X, stars)
    k1, k2 = principal_curvatures(X, stars, fit.curvature)
    return mesh, stars, fit, k1, k2, intersection_angles(X, stars)


def test_bundled_net_curvature_sign_and_euler_formula(bundled):
    mesh, stars, fit, k1, k2, theta = bundled
    X = mesh.vertices
    n = star_normals(X, stars)
    side = np.sum((fit.centre - X[stars[:, 0]]) * n, axis=1)
    assert np.all(np.sign(side) == np.sign(fit.curvature))
    defined = np.isfinite(k1) & np.isfinite(k2)
    assert defined.mean() > 0.8
    euler = k1 * np.cos(theta / 2) ** 2 + k2 * np.sin(theta / 2) ** 2
    assert np.abs(euler - fit.curvature)[defined].max() <= 1e-9


def test_orthogonal_net_mean_curvature_is_normal_curvature(cmc1):
    X = cmc1.vertices
    stars = canonical_stars(X, cmc1.stars)
    fit = fit_star_spheres(X, stars)
    k1, k2 = principal_curvatures(X, stars, fit.curvature)
    theta = intersection_angles(X, stars)
    defined = np.isfinite(k1)
    assert np.abs(np.degrees(theta) - 90).max() < 1e-4
    H = (k1 + k2) / 2
    # Lemma 2.20, up to the net's tiny departure from 90 degrees ...
    assert np.abs(H - fit.curvature)[defined].max() <= 1e-6 * np.abs(fit.curvature).max()
    # ... which accounts for the difference exactly: H - kn = -cos(theta) (k1 - k2) / 2
    assert np.allclose((H - fit.curvature)[defined], (-np.cos(theta) * (k1 - k2) / 2)[defined],
                       rtol=0, atol=1e-13)


def test_normal_curvatures_of_contact_elements_match_the_quadric():
    """Second fundamental form fitted to the normals of a star on z = x^2/100 - y^2/160:
    II(d, d) = cos^2 / 50 - sin^2 / 80 at the saddle point, for every direction d."""
    from fabplan.net.geometry import normal_curvatures

    u = np.arange(-2.0, 2.1, 1.0) * 0.5
    x, y = np.meshgrid(u, u, indexing="ij")
    grid = QuadMesh.grid(np.stack([x, y, x**2 / 100 - y**2 / 160], axis=-1))
    normals = np.column_stack([-grid.vertices[:, 0] / 50, grid.vertices[:, 1] / 80,
                               np.ones(grid.vertex_count)])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    centre = int(np.flatnonzero(np.all(grid.vertices[grid.stars[:, 0], :2] == 0, axis=1))[0])
    angles = np.radians(np.arange(0.0, 180.0, 15.0))
    d = np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
    stars = np.repeat(grid.stars[centre:centre + 1], len(d), axis=0)
    k = normal_curvatures(grid.vertices, normals, stars, d)
    assert np.allclose(k, np.cos(angles) ** 2 / 50 - np.sin(angles) ** 2 / 80, rtol=1e-3, atol=1e-7)


def test_principal_curvatures_where_the_lines_are_asymptotic():
    """On a hyperbolic paraboloid gridded along its rulings the lines' normal curvature is
    zero and the Gauss map formula divides zero by zero; the shape operator of the normals'
    differences gives the principal curvatures instead: mean and Gaussian curvature as
    the surface's, to 1e-5 and 1 % (before: NaN, and on a roof laid out near its asymptotic
    directions 7 1/m where the largest is 0.06)."""
    import fabplan.net.geometry as geometry

    u = np.linspace(-4.0, 4.0, 17)
    x, y = np.meshgrid(u, u, indexing="ij")
    mesh = QuadMesh.grid(np.stack([x, y, x * y / 16], axis=-1))
    X, stars = mesh.vertices, mesh.stars
    k1, k2 = geometry.principal_curvatures(X, stars)
    px, py = X[stars[:, 0], 0], X[stars[:, 0], 1]
    fx, fy = py / 16, px / 16
    W = 1 + fx**2 + fy**2
    H = -(2 * fx * fy / 16) / (2 * W**1.5)
    K = -(1 / 16) ** 2 / W**2
    inner = np.isfinite(k1)
    assert inner.sum() == 13 * 13      # every star whose neighbours are star centres
    assert np.abs((k1 + k2) / 2 - H)[inner].max() < 1e-5
    assert (np.abs(k1 * k2 - K) / np.abs(K))[inner].max() < 0.01
