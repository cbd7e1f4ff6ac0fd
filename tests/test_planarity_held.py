"""A study that asks for flat panels holds its nets' quads planar in the solve
(`PlanarityBound`), and says so; a net type that cannot be planar there is solved
without the bound and judged by the planarity check as before."""

from __future__ import annotations

import numpy as np
import pytest

from fabplan.net.mesh import QuadMesh
from fabplan.solve.constraints import PlanarityBound, PlaneNormalization
from fabplan.study.candidate_solve import PLANARITY_HELD
from fabplan.study.run import run_study
from fabplan.study.spec import parse_study

STUDY = """
[design]
surface = "paraboloid"
parameters = { radius_x = 14, radius_y = 20, width = 6, depth = 5 }
triangles = 4000
[panels]
size = 1.5
[limits]
max_deviation_mm = 150
mold_tolerance_mm = 2
planar_panels = true
planarity_tolerance_mm = 3.0
[[candidates]]
net = "cmc"
"""


def _corner_distances(X: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(q,) float, the largest distance of a quad's corners from its least-squares plane,
    written here on its own."""
    P = X[quads]
    C = P - P.mean(axis=1, keepdims=True)
    normal = np.linalg.svd(C)[2][:, -1]
    return np.abs(np.einsum("qkj,qj->qk", C, normal)).max(axis=1)


@pytest.fixture(scope="module")
def studies():
    held = parse_study(STUDY)
    free = parse_study(STUDY.replace("planar_panels = true", "planar_panels = false"))
    return run_study(held), run_study(free)


def test_flat_panels_asked_for_are_held_in_the_solve(studies):
    held, free = studies
    a, b = (next(c for c in r.candidates if c.candidate.net == "cmc") for r in (held, free))
    tolerance = 3.0
    # without the bound the CMC net's quads are well out of plane; with it within the limit
    unheld = _corner_distances(b.net.mesh.vertices, b.net.mesh.quads).max() * 1000.0
    planar = _corner_distances(a.net.mesh.vertices, a.net.mesh.quads).max() * 1000.0
    assert unheld > tolerance
    assert planar <= tolerance
    assert a.net.converged and a.net.parameters["planarity"]["kept"] is True
    assert a.net.parameters["planarity"]["held_mm"] == pytest.approx(PLANARITY_HELD * tolerance)
    assert "planarity" not in b.net.parameters
    check = next(c for c in a.checks if c["limit"] == "planarity_tolerance_mm")
    assert check["ok"] and check["measured"] == pytest.approx(planar, rel=1e-6)


def test_the_bound_holds_every_corner_near_a_plane_of_its_quad():
    # a 3 x 3 grid of quads on a saddle, bent out of plane; held within 1 % of its edge
    u, v = np.meshgrid(np.linspace(-1, 1, 4), np.linspace(-1, 1, 4), indexing="ij")
    X = np.c_[u.ravel(), v.ravel(), 0.3 * (u * v).ravel()]
    ids = np.arange(16).reshape(4, 4)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], -1).reshape(-1, 4)
    mesh = QuadMesh(X, quads)
    from fabplan.solve.optimize import optimize

    limit = 0.01 * 2.0 / 3.0
    before = _corner_distances(X, quads).max()
    result = optimize(mesh, "snet", extra=(PlanarityBound(limit), PlaneNormalization()))
    after = _corner_distances(result.mesh.vertices, quads).max()
    assert before > limit
    assert result.converged
    # the bound holds the corners to a plane of the quad's own; the least-squares plane
    # of a skew quad lies at most a little farther from them
    assert after <= 1.15 * limit


def test_a_bound_that_is_no_length_is_refused():
    for limit in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="positive length"):
            PlanarityBound(limit)
