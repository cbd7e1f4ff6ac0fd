"""The footpoints of a net's vertices on a reference are found once per position of the
net and shared by the families that need them (closeness, the deviation limit)."""

from __future__ import annotations

import numpy as np

import fabplan
from fabplan.solve.constraints import Closeness, DeviationBound
from fabplan.solve.optimize import build_solver
from fabplan.solve.reference import ReferenceSurface


class CountingReference(ReferenceSurface):
    """A reference surface that counts its closest-point queries."""

    queries = 0

    def closest_points(self, points):
        self.queries += 1
        return super().closest_points(points)


def test_closeness_and_the_deviation_limit_ask_once_per_position():
    mesh = fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    reference = CountingReference(mesh.vertices, mesh.triangles())
    solver = build_solver(mesh, "snet", reference=reference, max_deviation=0.5)
    families = [c for c in solver.constraints if isinstance(c, (Closeness, DeviationBound))]
    assert {type(c) for c in families} == {Closeness, DeviationBound}
    state = solver.state
    state.blocks.view(state.x, "vertices")[:] += 0.001        # a net the solver has not seen
    before = reference.queries
    for family in families:
        family.prepare(state)
    assert reference.queries == before + 1
    # what each family got is what a query of its own vertices gives
    model = state.X * state.length_scale + state.origin
    foot, normal, _ = ReferenceSurface.closest_points(reference, model)
    deviation = next(c for c in families if isinstance(c, DeviationBound))
    held = deviation.vertices              # every vertex: no deviation_vertices given
    assert len(held) == mesh.vertex_count
    np.testing.assert_array_equal(
        deviation.distances(state),
        np.linalg.norm(state.X[held] - (foot[held] - state.origin) / state.length_scale, axis=1))
    # a moved net asks again
    state.blocks.view(state.x, "vertices")[0] += 0.01
    for family in families:
        family.prepare(state)
    assert reference.queries == before + 2
