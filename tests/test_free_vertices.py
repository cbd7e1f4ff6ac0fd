"""Vertices in no star and where they belong (`fabplan.net.free_vertices`)."""

from __future__ import annotations

import numpy as np

from fabplan.net.free_vertices import free_vertices, settle_free_vertices
from fabplan.net.generate import height_field_grid
from fabplan.net.quadrics import edge_steps, face_frames, face_neighbourhoods, fit_height_fields
from fabplan.solve.optimize import optimize

R = 20.0  # radius of the test sphere (model units)


def _cap(x, y):
    return np.sqrt(R * R - x * x - y * y) - R


def test_only_the_corners_of_a_grid_are_free():
    net = height_field_grid(6, 5, _cap)
    free = np.flatnonzero(free_vertices(net))
    corners = {0, 4, 25, 29}
    assert set(free.tolist()) == corners


def test_a_lifted_corner_goes_back_onto_the_surface_its_neighbours_continue():
    net = height_field_grid(7, 7, _cap, spacing=1.0)
    free = free_vertices(net)
    X = net.vertices.copy()
    X[free, 2] += 0.4                                   # tips left 0.4 off the sphere
    settled, moved = settle_free_vertices(net.with_vertices(X))
    Y = settled.vertices
    # distance of the tips from the sphere the grid lies on
    off = np.abs(np.linalg.norm(Y[free] - np.array([0.0, 0.0, -R]), axis=1) - R)
    assert np.all(moved[~free] == 0) and np.allclose(Y[~free], X[~free])
    assert off.max() < 0.01 and moved[free].min() > 0.35


def test_settling_keeps_held_vertices_and_is_recorded():
    net = height_field_grid(7, 7, lambda x, y: 0.05 * (x * x - y * y), spacing=1.0)
    corner = int(np.flatnonzero(free_vertices(net))[0])
    X = net.vertices.copy()
    X[free_vertices(net), 2] += 0.3
    start = net.with_vertices(X)
    result = optimize(start, "snet", settle_free=0.0, fixed=np.array([corner]))
    record = result.parameters["free_vertices"]
    assert record["count"] == 4 and record["settled"] and record["largest_move"] > 0.1
    assert np.allclose(result.mesh.vertices[corner], X[corner])
    plain = optimize(start, "snet")
    assert plain.parameters["free_vertices"] == {"count": 4, "settled": False, "largest_move": 0.0}


def test_only_tips_whose_faces_step_move_when_a_step_is_given():
    net = height_field_grid(7, 7, _cap, spacing=1.0)
    free = free_vertices(net)
    X = net.vertices.copy()
    lifted = np.flatnonzero(free)[:2]
    X[lifted[0], :2] += 0.3                               # far off: its face steps
    X[lifted[0], 2] += 0.4
    X[lifted[1], 2] += 1e-4                               # a tenth of a millimetre
    start = net.with_vertices(X)
    # the steps of the two tips' faces against their neighbours, measured as the settling does
    origin, frame, scale = face_frames(start)
    vertices, weight = face_neighbourhoods(start, ignore=free)
    steps = edge_steps(start, origin, frame, scale,
                       fit_height_fields(X[vertices], weight, origin, frame, scale), (0.25, 0.5, 0.75))
    pairs = start.interior_edge_faces
    face_of = [next(f for f, face in enumerate(start.faces) if v in face) for v in lifted]
    far, near = (steps[np.any(pairs == f, axis=1)].max() for f in face_of)
    assert far > 100 * near
    _, moved = settle_free_vertices(start, step=np.sqrt(far * near))
    assert moved[lifted[0]] > 0.1 and moved[lifted[1]] == 0.0
    assert np.count_nonzero(moved) == 1
    _, none = settle_free_vertices(start, step=10.0)
    assert not none.any()
