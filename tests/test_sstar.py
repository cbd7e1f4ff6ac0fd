"""S*-net presets (the S*-net column of Table 2) reach their defining properties.

An S*-net is a net of oriented tangent planes, stored as contact elements (vertex and
unit normal). The start grids lie on the test quadrics with their lines chosen so that
the cone rulings of Eq. 5 (conjugate to the grid lines: tan(theta) = -k1 / (k2 tan(phi)))
meet near the angle the preset asks for. Properties are measured on the written result
with `fabplan.geometry`, not read from the solver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from helpers import jet_curvatures
from surfaces import DOME, SADDLE, Quadric, quadric_grid

import fabplan
from fabplan.net.geometry import (
    canonical_stars,
    fit_mannheim_spheres,
    osculating_tangents,
    ruling_angles,
    vertex_contact_normals,
)

TOLERANCE_RELATIVE = 1e-6      # x mean edge: planes tangent to the Mannheim sphere
ANGLE_TOLERANCE_DEG = 0.01
RADIUS_TOLERANCE_RELATIVE = 1e-4


def grid_angle_for_rulings(surface: Quadric, ruling_angle_deg: float) -> float:
    """Angle between the grid lines (symmetric about x) whose conjugate rulings meet at
    `ruling_angle_deg` at the origin."""
    k1, k2 = 1 / surface.radius_x, 1 / surface.radius_y
    theta = math.radians(ruling_angle_deg / 2)
    return 2 * math.degrees(math.atan(abs(k1 / (k2 * math.tan(theta)))))


@dataclass(frozen=True)
class DualCase:
    label: str
    net: str
    surface: Quadric
    ruling_start_deg: float | None = None    # None: a 90-degree grid
    angle_deg: float | None = None
    radius_factor: float | None = None
    isogonal: bool = False
    orthogonal: bool = False
    constant_radius: bool = False
    zero_radius: bool = False

    @property
    def grid_angle(self) -> float:
        if self.ruling_start_deg is None:
            return 90.0
        return grid_angle_for_rulings(self.surface, self.ruling_start_deg)


CASES = [
    DualCase("sstar-saddle", "sstar", SADDLE),
    DualCase("sstar-dome", "sstar", DOME),
    DualCase("isogonal-80-saddle", "sstar-isogonal", SADDLE, 80, angle_deg=80, isogonal=True),
    DualCase("isogonal-80-dome", "sstar-isogonal", DOME, 80, angle_deg=80, isogonal=True),
    DualCase("isogonal-free-dome", "sstar-isogonal", DOME, 80, isogonal=True),
    DualCase("orthogonal-saddle", "sstar-orthogonal", SADDLE, 90, orthogonal=True),
    DualCase("orthogonal-dome", "sstar-orthogonal", DOME, 90, orthogonal=True),
    DualCase("const-radius-free-saddle", "sstar-const-radius", SADDLE, constant_radius=True),
    DualCase("const-radius-free-dome", "sstar-const-radius", DOME, 90, constant_radius=True),
    DualCase("const-radius-prescribed-saddle", "sstar-const-radius", SADDLE, radius_factor=1.02,
             constant_radius=True),
    # constant harmonic mean surfaces are offsets of minimal surfaces: a saddle start
    DualCase("harmonic-mean-saddle", "harmonic-mean", SADDLE, 90, orthogonal=True,
             constant_radius=True),
    # Mannheim radius 0 needs k1 k2 < 0: the grid follows the saddle's asymptotic lines
    DualCase("dual-anet-saddle", "dual-anet", SADDLE, 109.47, zero_radius=True),
]


def _contact(mesh):
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    return X, mesh.normals, stars


def _start_normals(start):
    stars = canonical_stars(start.vertices, start.stars)
    return vertex_contact_normals(start, start.vertices, stars)


@pytest.mark.parametrize("case", [pytest.param(c, id=c.label) for c in CASES])
def test_dual_preset_reaches_its_defining_properties(case, tmp_path):
    start = quadric_grid(case.surface, angle_deg=case.grid_angle)
    X0, N0 = start.vertices, _start_normals(start)
    stars = canonical_stars(X0, start.stars)
    before = fit_mannheim_spheres(X0, N0, stars)
    radius = None
    if case.radius_factor is not None:
        radius = case.radius_factor * float(np.median(np.abs(before.radius)))
    result = fabplan.optimize(start, case.net, angle=case.angle_deg, radius=radius)
    assert result.converged, [h["hard_residual"] for h in result.history]

    # what is written is what is checked: contact elements travel as OBJ normals
    path, _ = result.write(tmp_path / "net.obj")
    net = fabplan.QuadMesh.from_obj(path)
    X, N, stars = _contact(net)
    L = net.mean_edge_length
    assert np.abs(np.linalg.norm(N, axis=1) - 1).max() <= 1e-9
    t1, t2 = osculating_tangents(X, stars)
    for t in (t1, t2):   # the planes are tangent planes of the contact net
        cosine = np.sum(N[stars[:, 0]] * t, axis=1) / np.linalg.norm(t, axis=1)
        assert np.abs(cosine).max() <= 1e-9

    spheres = fit_mannheim_spheres(X, N, stars)
    assert before.residual.max() > TOLERANCE_RELATIVE * start.mean_edge_length
    assert spheres.residual.max() <= TOLERANCE_RELATIVE * L
    angles = np.degrees(ruling_angles(X, N, stars))
    if case.isogonal:
        assert np.ptp(angles) <= ANGLE_TOLERANCE_DEG
        expected = case.angle_deg if case.angle_deg is not None else result.parameters["angle_deg"]
        assert np.abs(angles - expected).max() <= ANGLE_TOLERANCE_DEG
    if case.orthogonal:
        assert np.abs(angles - 90).max() <= ANGLE_TOLERANCE_DEG
    if case.constant_radius:
        assert np.ptp(before.radius) / np.abs(before.radius).mean() > RADIUS_TOLERANCE_RELATIVE
        assert np.ptp(spheres.radius) / np.abs(spheres.radius).mean() <= RADIUS_TOLERANCE_RELATIVE
        target = radius if radius is not None else result.parameters["radius"]
        assert np.abs(np.abs(spheres.radius) / target - 1).max() <= RADIUS_TOLERANCE_RELATIVE
    if case.zero_radius:
        assert np.abs(spheres.radius).max() <= TOLERANCE_RELATIVE * L
    displacement = np.linalg.norm(X - X0, axis=1).mean()
    assert displacement <= 0.1 * start.mean_edge_length
    # the measurement record of the result says the same
    assert result.properties["mannheim_residual_relative"]["max"] <= TOLERANCE_RELATIVE


def test_harmonic_mean_radius_is_the_mean_of_the_curvature_radii():
    """Blaschke: on an orthogonal S*-net the Mannheim radius is (1/k1 + 1/k2) / 2,
    checked with principal curvatures from an independent jet fit."""
    start = quadric_grid(SADDLE, angle_deg=grid_angle_for_rulings(SADDLE, 90), size=16)
    result = fabplan.optimize(start, "harmonic-mean")
    assert result.converged
    X, N, stars = _contact(result.mesh)
    rho = fit_mannheim_spheres(X, N, stars).radius
    ring = result.mesh.is_boundary_vertex.copy()
    for _ in range(2):   # the jet needs its full two face rings
        ring[result.mesh.edges[ring[result.mesh.edges].any(axis=1)].ravel()] = True
    inner = np.flatnonzero(~ring)
    assert inner.size > 50
    k1, k2, jet_normal = jet_curvatures(X, result.mesh.faces, inner)
    sign = np.sign(np.sum(jet_normal * N[inner], axis=1))   # curvatures w.r.t. N
    harmonic = (1 / (sign * k1) + 1 / (sign * k2)) / 2
    star_rho = rho[result.mesh.star_of_vertex[inner]]
    assert np.abs(harmonic / star_rho - 1).max() <= 0.05


def test_sstar_initialized_from_an_snet_stays_close(cmc1):
    """Section 4.3: the contact elements of an S-net start the S*-net optimization."""
    result = fabplan.optimize(cmc1, "sstar")
    assert result.converged
    assert result.properties["mannheim_residual_relative"]["max"] <= TOLERANCE_RELATIVE
    moved = np.linalg.norm(result.mesh.vertices - cmc1.vertices, axis=1).mean()
    assert moved <= 0.01 * cmc1.mean_edge_length
