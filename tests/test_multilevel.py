"""The multilevel start: grid coordinates, coarse nets, prolongation, and a solve that reaches
the plain solve's net with fewer iterations on the full net."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import noisy

import fabplan
from fabplan.net.generate import rotational_weingarten_snet
from fabplan.net.geometry import canonical_stars, fit_star_spheres, intersection_angles
from fabplan.net.mesh import QuadMesh
from fabplan.solve.multilevel import (
    coarse_grid_net,
    coarse_lines,
    grid_indices,
    prolong_vertices,
    prolongation_matrix,
)
from fabplan.solve.solver import SolverSettings

ANGLE_DEG, RADIUS = 80.0, 3.0


@pytest.fixture(scope="module")
def weingarten_grid() -> QuadMesh:
    """An exact linear Weingarten net of revolution on a 42 x 42 grid (an even count: the
    coarse net keeps the last line one step after the one before)."""
    return rotational_weingarten_snet(42, 42, radius=RADIUS, angle_deg=ANGLE_DEG)


@pytest.fixture(scope="module")
def plain_and_multilevel(weingarten_grid):
    """The noisy net solved plainly and with the multilevel start: (start, plain, multilevel)."""
    start = noisy(weingarten_grid, 0.01, seed=3)
    plain = fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(multilevel=False))
    multi = fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(multilevel=True))
    return start, plain, multi


def _cycles(quads: np.ndarray) -> np.ndarray:
    """Quads as cycles starting at their smallest vertex, rows sorted."""
    shift = np.argmin(quads, axis=1)
    q = quads[np.arange(len(quads))[:, None], (shift[:, None] + np.arange(4)) % 4]
    return q[np.lexsort(q.T[::-1])]


def _cells(G: np.ndarray) -> np.ndarray:
    return np.stack([G[:-1, :-1], G[1:, :-1], G[1:, 1:], G[:-1, 1:]], axis=-1).reshape(-1, 4)


@pytest.mark.parametrize("reverse", [False, True])
def test_grid_indices_give_the_faces_in_their_orientation(weingarten_grid, reverse):
    mesh = weingarten_grid
    if reverse:        # faces turned over and listed in another order
        quads = mesh.quads[::-1, ::-1]
        mesh = QuadMesh(mesh.vertices, quads)
    G = grid_indices(mesh)
    assert G is not None and G.shape == (42, 42)
    assert np.array_equal(np.sort(G.ravel()), np.arange(mesh.vertex_count))
    assert np.array_equal(_cycles(_cells(G)), _cycles(mesh.quads))


def test_nets_that_are_no_grid_patch_have_no_grid_indices(wein99, weingarten_grid):
    assert grid_indices(wein99) is None            # irregular vertices and boundary
    points = weingarten_grid.vertices.reshape(42, 42, 3)
    cells = _cells(np.arange(42 * 42).reshape(42, 42))
    holed = QuadMesh(weingarten_grid.vertices, np.delete(cells, 20 * 41 + 20, axis=0))
    assert grid_indices(holed) is None             # a hole: four more corners
    assert grid_indices(QuadMesh.grid(points[:, :2])) is not None
    two = QuadMesh(np.r_[points[:3, :3].reshape(-1, 3), points[:3, :3].reshape(-1, 3) + 10],
                   np.r_[_cells(np.arange(9).reshape(3, 3)), _cells(np.arange(9, 18).reshape(3, 3))])
    assert grid_indices(two) is None               # two patches


@pytest.mark.parametrize("m", [7, 8, 9, 42])
def test_prolongation_keeps_coarse_values_and_reproduces_cubics(m):
    kept = coarse_lines(m)
    assert kept[0] == 0 and kept[-1] == m - 1 and np.all(np.diff(kept) <= 2)
    for t in (np.arange(m, dtype=np.float64),             # a full net's lines
              coarse_lines(2 * m).astype(np.float64)):    # a coarse net's: the last step short
        P = prolongation_matrix(t, kept)
        assert np.array_equal(P[kept], np.eye(len(kept)))
        for degree in range(4):
            assert np.allclose(P @ t[kept] ** degree, t ** degree, rtol=1e-12,
                               atol=1e-9 * t[-1] ** degree)


def test_coarse_net_of_a_coarse_net_prolongs_at_its_line_parameters(weingarten_grid):
    # the net's coarse net keeps its last line one step after the line before, so the
    # lines of the coarse net are not evenly spaced: interpolating in their indices
    # would put the lines next to that boundary a sixth of an edge off
    mesh = weingarten_grid
    middle, rows, cols = coarse_grid_net(mesh, grid_indices(mesh))
    G = np.arange(middle.vertex_count).reshape(len(rows), len(cols))
    coarse, r, c = coarse_grid_net(middle, G)
    prolonged = prolong_vertices(coarse.vertices, G, r, c, (rows.astype(float), cols.astype(float)))
    error = np.linalg.norm(prolonged - middle.vertices, axis=1) / middle.mean_edge_length
    assert error.max() < 1e-3


def test_prolonged_coarse_net_lies_on_the_smooth_net(weingarten_grid):
    mesh = weingarten_grid
    G = grid_indices(mesh)
    coarse, rows, cols = coarse_grid_net(mesh, G)
    assert coarse.vertex_count == 22 * 22
    assert np.array_equal(coarse.vertices, mesh.vertices[G[np.ix_(rows, cols)]].reshape(-1, 3))
    prolonged = prolong_vertices(coarse.vertices, G, rows, cols)
    error = np.linalg.norm(prolonged - mesh.vertices, axis=1) / mesh.mean_edge_length
    assert error.max() < 1e-3
    assert np.array_equal(prolonged[G[np.ix_(rows, cols)]].reshape(-1, 3), coarse.vertices)
    # the coarse net is oriented as the full net: its face normals point the same way
    n_fine = np.cross(*(mesh.vertices[G[1, 0]] - mesh.vertices[G[0, 0]],
                        mesh.vertices[G[0, 1]] - mesh.vertices[G[0, 0]]))
    q = coarse.quads[0]
    n_coarse = np.cross(coarse.vertices[q[1]] - coarse.vertices[q[0]],
                        coarse.vertices[q[3]] - coarse.vertices[q[0]])
    assert float(np.dot(n_fine, n_coarse)) > 0


def _measured(mesh: QuadMesh):
    stars = canonical_stars(mesh.vertices, mesh.stars)
    spheres = fit_star_spheres(mesh.vertices, stars)
    angles = np.degrees(intersection_angles(mesh.vertices, stars))
    return spheres, np.minimum(angles, 180.0 - angles)


def test_multilevel_solve_reaches_the_plain_solution_in_fewer_full_iterations(weingarten_grid,
                                                                              plain_and_multilevel):
    start, plain, multi = plain_and_multilevel
    assert plain.converged and multi.converged
    record = multi.parameters["multilevel"]
    assert plain.parameters["multilevel"] is None
    assert [level["vertices"] for level in record["levels"]] == [22 * 22]
    assert record["levels"][0]["status"] == "converged" and record["levels"][0]["iterations"] > 0
    assert record["full_iterations"] == multi.iterations < plain.iterations
    assert len([h for h in multi.history if h["step"] > 0]) == multi.iterations
    L = start.mean_edge_length
    for result in (plain, multi):
        spheres, angles = _measured(result.mesh)
        assert spheres.residual.max() <= 1e-10 * L
        assert np.ptp(angles) <= 1e-6
        assert np.ptp(np.abs(spheres.radius)) <= 1e-8 * RADIUS
    assert abs(multi.parameters["angle_deg"] - plain.parameters["angle_deg"]) <= 2e-3
    assert abs(multi.parameters["radius"] / plain.parameters["radius"] - 1) <= 2e-4
    # the noise (1 % of an edge) leaves a family of nets to choose from: both solves
    # recover the noise-free net equally well, and lie as close to each other
    exact = weingarten_grid.vertices
    off_plain = np.linalg.norm(plain.mesh.vertices - exact, axis=1) / L
    off_multi = np.linalg.norm(multi.mesh.vertices - exact, axis=1) / L
    assert off_multi.mean() <= 1.1 * off_plain.mean() and off_multi.max() <= 0.02
    apart = np.linalg.norm(multi.mesh.vertices - plain.mesh.vertices, axis=1) / L
    assert apart.max() <= 0.03 and apart.mean() <= 1.2 * off_plain.mean()
    near, near_plain = (r.properties["distance_to_reference"] for r in (multi, plain))
    assert near["mean"] <= 1.1 * near_plain["mean"] and near["max"] <= 0.03 * L


def test_large_nets_take_nested_coarse_levels_automatically(monkeypatch):
    # with the threshold at 1,000 vertices a 64 x 64 net is large, and so is its coarse
    # net (33 x 33): it is solved from its own coarse net (17 x 17), whose lines are not
    # evenly spaced (the regression: interpolated as if they were, the boundary rows of
    # the middle net started a sixth of an edge off and the solve ended half an edge off)
    monkeypatch.setattr("fabplan.solve.optimize.MULTILEVEL_MIN_VERTICES", 1000)
    exact = rotational_weingarten_snet(64, 64, radius=RADIUS, angle_deg=ANGLE_DEG)
    start = noisy(exact, 0.01, seed=5)
    result = fabplan.optimize(start, "linear-weingarten")
    plain = fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(multilevel=False))
    assert result.converged and plain.converged
    levels = result.parameters["multilevel"]["levels"]
    assert [level["vertices"] for level in levels] == [17 * 17, 33 * 33]
    assert result.iterations < plain.iterations
    L = exact.mean_edge_length
    for r in (result, plain):
        assert np.linalg.norm(r.mesh.vertices - exact.vertices, axis=1).max() <= 0.02 * L


def test_multilevel_start_is_automatic_for_large_nets_only(weingarten_grid, plain_and_multilevel):
    start = plain_and_multilevel[0]
    auto = fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(max_iterations=1))
    assert auto.parameters["multilevel"] is None      # below MULTILEVEL_MIN_VERTICES


def test_solves_the_multilevel_start_cannot_take_fall_back(wein99, plain_and_multilevel):
    # held vertices, irregular nets, guards and S*-nets
    start = plain_and_multilevel[0]
    on = SolverSettings(multilevel=True, max_iterations=2)
    held = fabplan.optimize(start, "linear-weingarten", fixed=np.array([0]), settings=on)
    assert held.parameters["multilevel"] is None
    irregular = fabplan.optimize(wein99, "linear-weingarten", settings=on)
    assert irregular.parameters["multilevel"] is None
    guarded = fabplan.optimize(start, "linear-weingarten", guards=True, settings=on)
    assert guarded.parameters["multilevel"] is None and guarded.parameters["guards"]
    dual = fabplan.optimize(start, "sstar", settings=on)          # normals are variables too
    assert dual.parameters["multilevel"] is None


def test_a_failed_multilevel_start_falls_back_to_the_plain_solve(plain_and_multilevel, monkeypatch):
    start, plain, _ = plain_and_multilevel
    rng = np.random.default_rng(1)

    def scrambled(coarse_vertices, G, rows, cols, params=None):   # a prolongation gone wrong: folded
        return start.vertices + rng.normal(scale=3 * start.mean_edge_length, size=start.vertices.shape)

    monkeypatch.setattr("fabplan.solve.optimize.prolong_vertices", scrambled)
    result = fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(multilevel=True))
    assert result.converged and result.parameters["multilevel"] is None
    assert np.allclose(result.mesh.vertices, plain.mesh.vertices, rtol=0, atol=1e-9 * start.mean_edge_length)


def test_the_command_reports_the_coarse_net_and_can_leave_it_out(plain_and_multilevel, tmp_path,
                                                                 monkeypatch, capsys):
    import json

    from fabplan.cli import main

    monkeypatch.setattr("fabplan.solve.optimize.MULTILEVEL_MIN_VERTICES", 1000)
    start = tmp_path / "start.obj"
    plain_and_multilevel[0].write_obj(start)
    out = {}
    for name, extra in (("multi", []), ("plain", ["--no-multilevel"])):
        target = tmp_path / f"{name}.obj"
        assert main(["optimize", str(start), "--net", "linear-weingarten", "-v", *extra,
                     "-o", str(target)]) == 0
        out[name] = capsys.readouterr().err
        record = json.loads(target.with_suffix(".json").read_text())
        levels = (record["parameters"]["multilevel"] or {}).get("levels")
        assert (levels is not None) == (name == "multi")
    assert "coarse net of 484 vertices, iteration" in out["multi"]
    assert "coarse net" not in out["plain"]


def test_a_rough_net_is_solved_plainly_unless_asked(weingarten_grid, monkeypatch):
    """Regression: on a rough grid (a noisy height field) the automatic multilevel start
    settled elsewhere than the plain solve (angles over 68-110 deg against 82-98). A net
    whose coarse net does not stand for it is solved plainly; asked for, it still gets the
    multilevel start."""
    from fabplan.solve.multilevel import MAX_FINE_ROUGHNESS, fine_roughness

    monkeypatch.setattr("fabplan.solve.optimize.MULTILEVEL_MIN_VERTICES", 1000)
    G = grid_indices(weingarten_grid)
    smooth, rough = noisy(weingarten_grid, 0.01, seed=3), noisy(weingarten_grid, 0.04, seed=3)
    assert fine_roughness(weingarten_grid, G) < 1e-3
    assert fine_roughness(smooth, G) < MAX_FINE_ROUGHNESS < fine_roughness(rough, G)
    once = SolverSettings(max_iterations=1)
    assert fabplan.optimize(smooth, "linear-weingarten", settings=once).parameters["multilevel"]
    assert fabplan.optimize(rough, "linear-weingarten", settings=once).parameters["multilevel"] is None
    asked = SolverSettings(max_iterations=1, multilevel=True)
    assert fabplan.optimize(rough, "linear-weingarten", settings=asked).parameters["multilevel"]
