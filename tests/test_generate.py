"""Generated meshes: exact rotational S-nets and height-field grids."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fabplan.errors import InputError
from fabplan.net.generate import (
    PROFILES,
    Profile,
    height_field_grid,
    rotational_snet,
    rotational_weingarten_snet,
)
from fabplan.net.geometry import (
    canonical_stars,
    fit_star_spheres,
    intersection_angles,
    principal_curvatures,
    star_normals,
)

SIZES = [(3, 3), (5, 8), (17, 11), (60, 60)]
DOMES = ["sphere", "paraboloid"]
SADDLES = ["catenoid", "hyperboloid"]
# Largest / smallest edge length at the default span and an angle of at most 90 degrees.
# Edges between two meridian levels all have the same length, about proportional to the
# distance from the axis: the profiles centred on a neck or equator vary least.
EDGE_RATIO = {"sphere": 1.35, "catenoid": 1.35, "hyperboloid": 1.35, "paraboloid": 2.1}


def _edge_lengths(mesh) -> np.ndarray:
    e = mesh.edges
    return np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)


def _sphere_fit(mesh):
    X = mesh.vertices
    return fit_star_spheres(X, canonical_stars(X, mesh.stars))


def _angles_deg(mesh) -> np.ndarray:
    X = mesh.vertices
    return np.degrees(intersection_angles(X, canonical_stars(X, mesh.stars)))


def test_every_profile_has_a_stated_edge_ratio():
    assert set(EDGE_RATIO) == set(PROFILES)
    assert set(DOMES + SADDLES) == set(PROFILES) == set(ON_SURFACE)


@pytest.mark.parametrize("isogonal", [False, True], ids=["conformal", "isogonal"])
@pytest.mark.parametrize("size", SIZES, ids=[f"{m}x{k}" for m, k in SIZES])
@pytest.mark.parametrize("profile", list(PROFILES))
def test_rotational_snet_is_an_exact_snet(profile, size, isogonal):
    m, k = size
    net = rotational_snet(m, k, profile=profile, angle_deg=80.0, isogonal=isogonal)
    assert net.vertex_count == m * k
    assert len(net.faces) == (m - 1) * (k - 1)
    assert np.all(net.face_sizes == 4)
    assert len(net.stars) == (m - 2) * (k - 2)
    assert len(net.irregular_vertices) == 0
    lengths = _edge_lengths(net)
    assert _sphere_fit(net).residual.max() < 1e-9 * lengths.mean()


@pytest.mark.parametrize("angle_deg", [30.0, 60.0, 90.0])
@pytest.mark.parametrize("profile", list(PROFILES))
def test_rotational_snet_edge_lengths_are_nearly_uniform(profile, angle_deg):
    for m, k in SIZES:
        lengths = _edge_lengths(rotational_snet(m, k, profile=profile, angle_deg=angle_deg))
        assert lengths.max() <= EDGE_RATIO[profile] * lengths.min()


# Each profile's surface as an implicit equation in r = |(x, y)| and z.
ON_SURFACE = {
    "sphere": lambda r, z: r * r + z * z - 1,
    "paraboloid": lambda r, z: z - r * r / 2,
    "catenoid": lambda r, z: r - np.cosh(z),
    "hyperboloid": lambda r, z: r * r - z * z - 1,
}


@pytest.mark.parametrize("profile", list(PROFILES))
def test_rotational_snet_vertices_lie_on_the_profile(profile):
    X = rotational_snet(9, 14, profile=profile, scale=2.5).vertices / 2.5
    r = np.hypot(X[:, 0], X[:, 1])
    np.testing.assert_allclose(ON_SURFACE[profile](r, X[:, 2]), 0.0, atol=1e-13)


@pytest.mark.parametrize("profile", list(PROFILES))
def test_rotational_snet_faces_point_away_from_the_axis(profile):
    net = rotational_snet(10, 10, profile=profile)
    X = net.vertices
    centre = X[net.stars[:, 0]]
    outward = np.sum(star_normals(X, net.stars)[:, :2] * centre[:, :2], axis=1)
    assert np.all(outward > 0)


@pytest.mark.parametrize("profile", DOMES + SADDLES)
def test_rotational_snet_gaussian_curvature_has_the_profiles_sign(profile):
    net = rotational_snet(20, 20, profile=profile, angle_deg=70.0)
    k1, k2 = principal_curvatures(net.vertices, canonical_stars(net.vertices, net.stars))
    gauss = (k1 * k2)[np.isfinite(k1 * k2)]
    assert len(gauss) == 16 * 16  # stars whose four neighbours are stars too
    if profile in DOMES:
        assert gauss.min() > 0
    else:
        assert gauss.max() < 0


@pytest.mark.parametrize("angle_deg", [50.0, 80.0, 90.0, 130.0])
@pytest.mark.parametrize("profile", list(PROFILES))
def test_isogonal_rotational_snet_has_exactly_the_requested_angle(profile, angle_deg):
    net = rotational_snet(25, 40, profile=profile, angle_deg=angle_deg, isogonal=True)
    expected = min(angle_deg, 180.0 - angle_deg)  # measured in (0, 90]
    np.testing.assert_allclose(_angles_deg(net), expected, atol=1e-9)


@pytest.mark.parametrize("profile", list(PROFILES))
def test_conformal_rotational_snet_angle_tends_to_the_requested_angle(profile):
    coarse = np.abs(_angles_deg(rotational_snet(8, 8, profile=profile, angle_deg=70.0)) - 70.0)
    fine = np.abs(_angles_deg(rotational_snet(64, 64, profile=profile, angle_deg=70.0)) - 70.0)
    assert coarse.max() < 1.0
    assert fine.max() < 0.02 * coarse.max()


@pytest.mark.parametrize("size", [(5, 5), (40, 70)])
def test_isogonal_sphere_net_is_linear_weingarten(size):
    net = rotational_snet(*size, profile="sphere", angle_deg=80.0, isogonal=True, scale=3.0)
    fit = _sphere_fit(net)
    np.testing.assert_allclose(fit.radius, 3.0, rtol=1e-9)
    np.testing.assert_allclose(_angles_deg(net), 80.0, atol=1e-9)


def test_rotational_snet_step_sets_the_longitude_increment():
    m, k, d = 6, 9, 0.05
    X = rotational_snet(m, k, profile="catenoid", step=d).vertices.reshape(m, k, 3)
    phi = np.arctan2(X[..., 1], X[..., 0])
    np.testing.assert_allclose(np.diff(phi, axis=0), d / 2, rtol=1e-12)
    np.testing.assert_allclose(np.diff(phi, axis=1), d / 2, rtol=1e-12)
    np.testing.assert_allclose(phi[0, 0] + phi[-1, -1], 0.0, atol=1e-15)  # symmetric about xz


def test_rotational_snet_default_step_spans_the_requested_longitude():
    X = rotational_snet(7, 12, profile="sphere", span_deg=120.0).vertices.reshape(7, 12, 3)
    phi = np.degrees(np.arctan2(X[..., 1], X[..., 0]))
    assert phi[-1, -1] - phi[0, 0] == pytest.approx(120.0, rel=1e-12)


def test_rotational_snet_accepts_a_custom_profile():
    torus = Profile("torus", lambda s: 3 + np.cos(s), np.sin, (-3.0, 3.0), 0.0)
    net = rotational_snet(15, 15, profile=torus, isogonal=True, angle_deg=75.0)
    assert _sphere_fit(net).residual.max() < 1e-9 * net.mean_edge_length
    np.testing.assert_allclose(_angles_deg(net), 75.0, atol=1e-9)


@pytest.mark.parametrize("kwargs, message", [
    (dict(m=1, k=5), "at least 2 x 2"),
    (dict(m=5, k=5, profile="torus"), "unknown profile"),
    (dict(m=5, k=5, angle_deg=180.0), "angle_deg"),
    (dict(m=5, k=5, span_deg=360.0), "below 360"),
    (dict(m=5, k=5, step=-0.1), "below 360"),
    (dict(m=50, k=50, profile="sphere", span_deg=350.0, angle_deg=170.0), "domain"),
])
def test_rotational_snet_rejects_impossible_parameters(kwargs, message):
    with pytest.raises(InputError, match=message):
        rotational_snet(**kwargs)


WEINGARTEN = [(1.5, 80.0), (3.0, 80.0), (2.0, 60.0), (1.2, 110.0)]  # (radius, angle_deg)


@pytest.mark.parametrize("size", [(3, 3), (6, 11), (50, 50)], ids=["3x3", "6x11", "50x50"])
@pytest.mark.parametrize("radius, angle_deg", WEINGARTEN)
def test_rotational_weingarten_snet_is_linear_weingarten(radius, angle_deg, size):
    m, k = size
    net = rotational_weingarten_snet(m, k, radius=radius, angle_deg=angle_deg, scale=2.0)
    assert net.vertex_count == m * k and len(net.faces) == (m - 1) * (k - 1)
    assert len(net.stars) == (m - 2) * (k - 2)
    fit = _sphere_fit(net)
    assert fit.residual.max() < 1e-9 * net.mean_edge_length
    np.testing.assert_allclose(fit.radius, 2.0 * radius, rtol=1e-9)
    np.testing.assert_allclose(_angles_deg(net), min(angle_deg, 180 - angle_deg), atol=1e-9)
    lengths = _edge_lengths(net)
    assert lengths.max() <= 1.6 * lengths.min()  # 1.5 at 110 degrees, near 1 at 80


@pytest.mark.parametrize("radius, angle_deg", WEINGARTEN)
def test_rotational_weingarten_snet_curvature_sign_follows_the_radius(radius, angle_deg):
    net = rotational_weingarten_snet(20, 20, radius=radius, angle_deg=angle_deg)
    k1, k2 = principal_curvatures(net.vertices, canonical_stars(net.vertices, net.stars))
    gauss = (k1 * k2)[np.isfinite(k1 * k2)]
    assert len(gauss) == 16 * 16
    barrel = radius < 1 / math.cos(math.radians(angle_deg) / 2) ** 2
    assert (gauss.min() > 0) if barrel else (gauss.max() < 0)
    # the middle parallel is the unit circle
    X = net.vertices.reshape(20, 20, 3)
    np.testing.assert_allclose(np.hypot(*np.diagonal(X)[:2]), 1.0, rtol=1e-12)


def test_rotational_weingarten_snet_of_unit_radius_is_the_sphere():
    net = rotational_weingarten_snet(30, 30, radius=1.0, angle_deg=70.0)
    np.testing.assert_allclose(np.linalg.norm(net.vertices, axis=1), 1.0, atol=1e-11)


@pytest.mark.parametrize("kwargs, message", [
    (dict(m=2, k=5), "at least 3 x 3"),
    (dict(m=5, k=5, radius=0.0), "radius"),
    (dict(m=5, k=5, angle_deg=0.0), "angle_deg"),
    (dict(m=5, k=5, span_deg=400.0), "below 360"),
    (dict(m=40, k=40, radius=1.0, span_deg=300.0, angle_deg=150.0), "cannot be continued"),
])
def test_rotational_weingarten_snet_rejects_impossible_parameters(kwargs, message):
    with pytest.raises(InputError, match=message):
        rotational_weingarten_snet(**kwargs)


def _family_directions(mesh, m, k):
    """Plan-view unit directions of the edges along i and along j, (e, 2) each."""
    P = mesh.vertices.reshape(m, k, 3)[..., :2]
    along_i = (P[1:] - P[:-1]).reshape(-1, 2)
    along_j = (P[:, 1:] - P[:, :-1]).reshape(-1, 2)
    return (along_i / np.linalg.norm(along_i, axis=1, keepdims=True),
            along_j / np.linalg.norm(along_j, axis=1, keepdims=True))


@pytest.mark.parametrize("rotation_deg", [0.0, 25.0, -140.0])
@pytest.mark.parametrize("angle_deg", [30.0, 72.5, 90.0, 135.0])
def test_height_field_grid_lines_meet_at_the_requested_angle(angle_deg, rotation_deg):
    m, k = 7, 5
    grid = height_field_grid(m, k, lambda x, y: 0.05 * x * x - 0.03 * x * y + np.sin(y),
                             spacing=0.7, angle_deg=angle_deg, rotation_deg=rotation_deg)
    di, dj = _family_directions(grid, m, k)
    # every pair of crossing lines meets at the same angle in plan view
    cross = np.degrees(np.arccos(np.clip(di @ dj.T, -1, 1)))
    np.testing.assert_allclose(cross, angle_deg, atol=1e-9)
    heading = np.degrees(np.arctan2(di[:, 1], di[:, 0]))
    np.testing.assert_allclose(np.cos(np.radians(heading - rotation_deg)), 1.0, atol=1e-12)


@pytest.mark.parametrize("angle_deg", [40.0, 90.0, 120.0])
def test_flat_height_field_grid_has_the_requested_net_angle(angle_deg):
    grid = height_field_grid(6, 6, lambda x, y: 0.0, angle_deg=angle_deg, rotation_deg=10.0)
    np.testing.assert_allclose(_angles_deg(grid), min(angle_deg, 180 - angle_deg), atol=1e-9)


def test_height_field_grid_samples_the_height_function():
    m, k, spacing = 9, 4, 0.25
    grid = height_field_grid(m, k, lambda x, y: x * x - y, spacing=spacing, angle_deg=60.0)
    X = grid.vertices
    np.testing.assert_allclose(X[:, 2], X[:, 0] ** 2 - X[:, 1], atol=1e-15)
    np.testing.assert_allclose(X[:, :2].mean(axis=0), 0.0, atol=1e-12)
    plan = X.reshape(m, k, 3)[..., :2]
    np.testing.assert_allclose(np.linalg.norm(np.diff(plan, axis=0), axis=-1), spacing)
    np.testing.assert_allclose(np.linalg.norm(np.diff(plan, axis=1), axis=-1), spacing)
    assert grid.vertex_count == m * k and len(grid.faces) == (m - 1) * (k - 1)
    assert len(grid.stars) == (m - 2) * (k - 2)
    assert np.all(star_normals(X, grid.stars)[:, 2] > 0)


@pytest.mark.parametrize("kwargs, message", [
    (dict(m=2, k=1), "at least 2 x 2"),
    (dict(m=3, k=3, angle_deg=0.0), "angle_deg"),
    (dict(m=3, k=3, spacing=-1.0), "spacing"),
])
def test_height_field_grid_rejects_impossible_parameters(kwargs, message):
    with pytest.raises(InputError, match=message):
        height_field_grid(f=lambda x, y: x, **kwargs)


def test_profiles_are_positive_on_their_domain():
    for p in PROFILES.values():
        s = np.linspace(*p.domain, 1001)
        assert np.all(p.radius(s) > 0), p.name
        assert p.domain[0] < p.centre < p.domain[1]
        assert math.isfinite(p.conformal_table()[1][-1])
