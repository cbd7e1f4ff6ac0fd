"""Every constraint family's Jacobian agrees with central differences of its residuals.

The families are set up by `fabplan.solver.GuidedProjection` on a slightly noisy grid on a
dome (so that no star is special), and each variable block a family reads is checked
separately with a random direction, so a failure names the block with the wrong columns;
blocks a family does not declare must not change its residuals either.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import noisy
from surfaces import DOME, quadric_grid

from fabplan.solve.constraints import (
    Closeness,
    CoherentOrientation,
    ConstantAngle,
    ConstantCurvature,
    ConstantMannheimRadius,
    ContactNormals,
    ConvexQuads,
    DeviationBound,
    EdgeCollapseBarrier,
    EdgeLengthRange,
    Fairness,
    FamilyLevels,
    MannheimTangency,
    NormalCone,
    NormalNormalization,
    PlanarFaces,
    PlaneNormalization,
    RulingAngle,
    SphereCondition,
    SphereNormalization,
    StarAngleRange,
)
from fabplan.solve.reference import ReferenceSurface
from fabplan.solve.solver import GuidedProjection

STEP = 1e-6
# The cosine between Eq. 5 rulings has large second derivatives on a noisy grid: its
# central differences need a finer step (their error falls as step^2, checked by hand).
FINE_STEP = {"ruling-angle-orthogonal", "ruling-angle-prescribed", "ruling-angle-free"}
TOLERANCE = 1e-6  # relative to the largest directional derivative


def _reference() -> ReferenceSurface:
    return ReferenceSurface.from_mesh(quadric_grid(DOME, angle_deg=70, size=8))


# Each entry: the families to set up, the last one being checked (earlier ones initialize
# the variable blocks it reads, as in a preset).
FAMILIES = {
    "sphere": lambda: [SphereCondition()],
    "sphere-normalization": lambda: [SphereCondition(), SphereNormalization()],
    "angle-prescribed": lambda: [ConstantAngle(math.cos(math.radians(70)))],
    "angle-free": lambda: [ConstantAngle(None)],
    "radius-prescribed": lambda: [SphereCondition(), ConstantCurvature(-0.05)],
    "radius-free": lambda: [SphereCondition(), ConstantCurvature(None)],
    "orientation": lambda: [SphereCondition(), CoherentOrientation()],
    "fairness": lambda: [Fairness()],
    # every edge shorter than 1.5 times its start length: the barrier is active everywhere
    "edge-collapse": lambda: [EdgeCollapseBarrier(1.5)],
    "edge-length-range": lambda: [EdgeLengthRange(0.05, 5.0)],
    "closeness": lambda: [Closeness(_reference())],
    "surface-band": lambda: [Closeness(_reference(), hard=True, tolerance=0.02)],
    "deviation": lambda: [DeviationBound(_reference(), 0.02)],
    "convex-quads": lambda: [ConvexQuads(5.0)],
    "levels": lambda: [FamilyLevels(_reference(), _reference().vertices[:, 0],
                                    np.arange(64), np.zeros(64))],
    "planar-faces": lambda: [PlanarFaces()],
    "plane-normalization": lambda: [PlanarFaces(), PlaneNormalization()],
    "contact-normals": lambda: [ContactNormals()],
    "normal-normalization": lambda: [ContactNormals(), NormalNormalization()],
    "mannheim": lambda: [ContactNormals(), MannheimTangency()],
    "mannheim-radius-prescribed": lambda: [ContactNormals(), MannheimTangency(),
                                           ConstantMannheimRadius(-20.0)],
    "mannheim-radius-free": lambda: [ContactNormals(), MannheimTangency(),
                                     ConstantMannheimRadius(None)],
    "ruling-angle-orthogonal": lambda: [ContactNormals(), RulingAngle(0.0)],
    "ruling-angle-prescribed": lambda: [ContactNormals(), RulingAngle(math.cos(math.radians(80)))],
    "ruling-angle-free": lambda: [ContactNormals(), RulingAngle(None)],
    "normal-cone": lambda: [NormalCone(_reference(), 30.0)],
    "star-angle-range": lambda: [StarAngleRange(60.0)],
}


@pytest.mark.parametrize("name", FAMILIES)
def test_constraint_jacobian_matches_finite_differences(name):
    mesh = noisy(quadric_grid(DOME, angle_deg=70, size=8), 0.05, seed=11)
    families = FAMILIES[name]()
    solver = GuidedProjection(mesh, families)
    state = solver.state
    for c in families:
        c.prepare(state)
    family = families[-1]
    columns = np.asarray(family.columns(state))
    r0, J = family.evaluate(state)
    J = np.asarray(J)
    assert J.shape == columns.shape
    assert r0.shape == (len(columns),)
    x0 = state.x.copy()
    rng = np.random.default_rng(5)
    blocks = state.blocks
    read = np.unique(columns)
    for block in blocks.blocks:
        declared = np.isin(blocks.index(block), read).any()
        direction = np.zeros_like(x0)
        direction[blocks.index(block).ravel()] = rng.normal(size=blocks.index(block).size)
        step = STEP / 100 if name in FINE_STEP else STEP
        state.x[:] = x0 + step * direction
        forward, _ = family.evaluate(state)
        state.x[:] = x0 - step * direction
        backward, _ = family.evaluate(state)
        state.x[:] = x0
        numeric = (forward - backward) / (2 * step)
        analytic = np.sum(J * direction[columns], axis=1)
        scale = max(np.abs(analytic).max(), np.abs(numeric).max())
        assert scale > 0 or not declared, f"{name}: no dependence on declared block {block!r}"
        error = np.abs(numeric - analytic).max()
        assert error <= TOLERANCE * max(scale, 1.0), \
            f"{name}: block {block!r}, error {error:.3g} of {scale:.3g}"


def test_edge_length_range_starts_off_its_stationary_points():
    """A slack that starts at a bound has a vanishing derivative, and Gauss-Newton then
    holds the edge at its start length: every edge must start strictly inside its range,
    also those starting outside the range or on its lower bound."""
    mesh = noisy(quadric_grid(DOME, angle_deg=70, size=8), 0.05, seed=11)
    X = mesh.vertices
    length = np.linalg.norm(X[mesh.edges[:, 0]] - X[mesh.edges[:, 1]], axis=1)
    family = EdgeLengthRange(np.median(length), 1.05 * np.median(length))
    solver = GuidedProjection(mesh, [family])
    r, J = family.evaluate(solver.state)
    assert (length < family.minimum).any() and (length > family.maximum).any()
    assert np.abs(J[:, -1]).min() > 0.04                          # d r / d angle = -cos
    inside = (length >= family.minimum) & (length <= family.maximum)
    assert np.abs(r[inside]).max() < 1e-12 and np.abs(r[length < family.minimum]).max() < 2e-3
    assert (r[length > family.maximum] > 0).all()                 # pulled into the range
