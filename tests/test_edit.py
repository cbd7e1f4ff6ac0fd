"""Editing with handles (task B): feasible moves keep the net type, impossible ones are
reported with the residuals that could not be met."""

from __future__ import annotations

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.net.geometry import canonical_stars, fit_star_spheres, intersection_angles, star_normals
from fabplan.solve.handles import read_handles


def _check_linear_weingarten(mesh):
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    spheres = fit_star_spheres(X, stars)
    angles = np.degrees(intersection_angles(X, stars))
    assert spheres.residual.max() <= 1e-6 * mesh.mean_edge_length
    assert np.ptp(spheres.radius) / spheres.radius.mean() <= 1e-4
    assert np.ptp(angles) <= 0.01


@pytest.fixture(scope="module")
def handle(wein99):
    """An interior vertex and a target half an edge off the surface."""
    vid = int(np.flatnonzero(~wein99.is_boundary_vertex)[600])
    stars = canonical_stars(wein99.vertices, wein99.stars)
    normal = star_normals(wein99.vertices, stars)[wein99.star_of_vertex[vid]]
    return vid, wein99.vertices[vid] + 0.5 * wein99.mean_edge_length * normal


def test_feasible_handle_keeps_a_linear_weingarten_net(wein99, handle):
    vid, target = handle
    result = fabplan.optimize(wein99, "linear-weingarten", handles={vid: target})
    assert result.converged
    assert np.array_equal(result.mesh.vertices[vid], target)
    _check_linear_weingarten(result.mesh)
    # the net really moved to follow the handle, not just the handle vertex
    moved = np.linalg.norm(result.mesh.vertices - wein99.vertices, axis=1)
    assert (moved > 0.01 * wein99.mean_edge_length).sum() > 10


def test_editor_drag_steps_reuse_the_factorization(wein99, handle):
    vid, target = handle
    editor = fabplan.NetEditor(wein99, "linear-weingarten", handles=[vid])
    start = wein99.vertices[vid]
    factor = None
    for step in np.linspace(0.2, 1.0, 5):
        editor.drag({vid: start + step * (target - start)})
        factor = factor or editor.solver._linear._factor
        assert editor.solver._linear._factor is factor      # symbolic analysis kept
    report = editor.release()
    assert report["converged"], report["message"]
    assert np.array_equal(editor.vertices[vid], target)
    _check_linear_weingarten(editor.mesh)


def test_impossible_handles_are_reported(wein99, tmp_path, capsys):
    src = tmp_path / "wein99.obj"
    src.write_bytes(fabplan.data_path("wein99.obj").read_bytes())
    vid = int(np.flatnonzero(~wein99.is_boundary_vertex)[600])
    x, y, z = wein99.vertices[vid] + [0.0, 0.0, 8 * wein99.mean_edge_length]
    out = tmp_path / "out.obj"
    code = main(["optimize", str(src), "--net", "linear-weingarten", "--fix", "boundary",
                 "--handle", f"{vid}:{x},{y},{z}", "-q", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    # with -q the error is the only line (without it, progress lines come first)
    assert len(err) == 1 and err[0].startswith("fabplan: error: the handles ask for")
    assert "sphere residual" in err[0]
    # the first step of a mean edge could not be solved: the seven beyond it are not tried
    assert "at step 1 of 8 towards them" in err[0]
    assert not out.exists() and not out.with_suffix(".json").exists()
    assert src.read_bytes() == fabplan.data_path("wein99.obj").read_bytes()


def test_an_unreachable_handle_gives_up_after_its_first_stage(wein99):
    """Before: every stage and both phases ran, 63 iterations (2-10 s); now the stage that
    cannot be solved ends the continuation."""
    from fabplan.solve.stages import STAGE_ITERATIONS

    vid = int(np.flatnonzero(~wein99.is_boundary_vertex)[600])
    target = wein99.vertices[vid] + [0.0, 0.0, 8 * wein99.mean_edge_length]
    records = []
    with pytest.raises(fabplan.SolverError, match=r"at step 1 of 8 towards them.*radius residual"):
        fabplan.optimize(wein99, "linear-weingarten", fixed=np.flatnonzero(wein99.is_boundary_vertex),
                         handles={vid: target}, progress=records.append)
    assert len(records) <= STAGE_ITERATIONS


def test_handle_file_and_bad_handles(tmp_path, wein99):
    good = tmp_path / "handles.txt"
    good.write_text("# id x y z\n12 1.0 2.0 3.0\n40 4 5 6\n")
    assert read_handles([str(good), "7:0,0,1"]) == {12: [1.0, 2.0, 3.0], 40: [4.0, 5.0, 6.0],
                                                     7: [0.0, 0.0, 1.0]}
    with pytest.raises(fabplan.InputError, match="ID:X,Y,Z"):
        read_handles(["12:1,2"])
    with pytest.raises(fabplan.InputError, match="vertex 99999 does not exist"):
        fabplan.optimize(wein99, "snet", handles={99999: [0, 0, 0]})


@pytest.mark.parametrize("edges, budget, smooth", [(8.0, 40, 0.0), (8.0, 3, 0.0), (8.0, 3, 3.0)])
def test_a_refused_drag_leaves_no_trace_on_the_next(wein99, edges, budget, smooth):
    """A drag refused (folded, or out of iterations) and then one the net can follow end
    where the second drag alone ends on a fresh editor: nothing of the refused solve (the
    families' first-run data, soft weights, variables) steers the next one."""
    vid = int(np.flatnonzero(wein99.star_of_vertex >= 0)[len(wein99.stars) // 2])
    stars = canonical_stars(wein99.vertices, wein99.stars)
    normal = star_normals(wein99.vertices, stars)[wein99.star_of_vertex[vid]]
    edge = wein99.mean_edge_length
    settings = fabplan.SolverSettings(tolerance=1e-6, multilevel=False)
    good = {vid: wein99.vertices[vid] + 0.5 * edge * normal}

    refused = fabplan.NetEditor(wein99, "snet", handles=[vid], settings=settings,
                                smooth=smooth > 0)
    first = refused.solve_drag({vid: wein99.vertices[vid] + edges * edge * normal},
                               max_iterations=budget, smooth=smooth)
    assert not first.accepted
    assert np.abs(refused.vertices - wein99.vertices).max() <= 1e-12 * edge
    after = refused.solve_drag(good, smooth=smooth)
    fresh = fabplan.NetEditor(wein99, "snet", handles=[vid], settings=settings,
                              smooth=smooth > 0)
    alone = fresh.solve_drag(good, smooth=smooth)
    assert after.accepted and alone.accepted
    assert after.iterations == alone.iterations
    assert np.abs(refused.vertices - fresh.vertices).max() <= 1e-12 * edge
    assert np.array_equal(refused.vertices[vid], good[vid])


def test_the_region_a_drag_moves_holds_every_star_and_face_around_its_moving_vertices(wein99):
    """The part a session solves holds every star (as a vertex set) and face that has a
    moving vertex, with the same positions, and holds exactly the vertices that do not
    move."""
    from fabplan.solve.region import region_net

    X = wein99.vertices
    moving = np.linalg.norm(X - X[900], axis=1) <= 6 * wein99.mean_edge_length
    part = region_net(wein99, X, moving)
    assert np.array_equal(part.mesh.vertices, X[part.vertices])
    held = np.zeros(part.mesh.vertex_count, bool)
    held[part.held] = True
    assert np.array_equal(held, ~moving[part.vertices])
    assert moving[part.vertices].sum() == moving.sum()
    sub_stars = {frozenset(part.vertices[s].tolist()) for s in part.mesh.stars}
    for star in wein99.stars[moving[wein99.stars].any(axis=1)]:
        assert frozenset(star.tolist()) in sub_stars
    sub_faces = {frozenset(part.vertices[f].tolist()) for f in part.mesh.faces}
    for face in wein99.faces:
        if moving[face].any():
            assert frozenset(np.asarray(face).tolist()) in sub_faces
    assert part.mesh.vertex_count < wein99.vertex_count


def test_a_handle_pulled_along_the_normal_keeps_the_faces_around_it_convex():
    """On a rotational linear Weingarten net (900 vertices), a handle dragged along the
    surface normal half an edge per drag, out to two edges and back both ways, gives an
    accepted S-net at every drag: the move spreads over the net instead of bending the
    faces around the handle (which the plain solve does from one edge on)."""
    from fabplan.edit.session import EditOptions, EditSession
    from fabplan.net.generate import rotational_weingarten_snet

    net = rotational_weingarten_snet(30, 30, radius=3.0, angle_deg=80.0)
    vid = 15 * 30 + 15
    stars = canonical_stars(net.vertices, net.stars)
    normal = star_normals(net.vertices, stars)[net.star_of_vertex[vid]]
    half = 0.5 * net.mean_edge_length
    session = EditSession(net, EditOptions("snet"))
    start = net.vertices[vid].copy()
    for k in [1, 2, 3, 4, 3, 2, 1, 0, -1, -2, -3, -4, -3, -2, -1, 0]:
        target = start + k * half * normal
        update = session.drag({vid: target})
        assert update.result.accepted, (k, update.result.message)
        X = session.vertices
        assert np.array_equal(X[vid], target)
        # every star on its sphere within 1e-6 of a mean edge (a fit of our own)
        spheres = fit_star_spheres(X, canonical_stars(X, net.stars))
        assert spheres.residual.max() <= 1e-6 * net.mean_edge_length
        # every quad convex: its corners turn the same way about its Newell normal
        quads = X[net.quads]                                          # (f, 4, 3)
        newell = np.cross(quads, np.roll(quads, -1, axis=1)).sum(axis=1)
        turns = np.einsum("fcj,fj->fc", np.cross(quads - np.roll(quads, 1, axis=1),
                                                 np.roll(quads, -1, axis=1) - quads), newell)
        assert (turns > 0).all()


def test_a_session_goes_on_after_a_refused_drag_as_if_it_had_not_been_tried(wein99):
    """The session keeps its solver after a refused drag: the next drag ends where it ends
    in a session that never tried the refused one."""
    from fabplan.edit.session import EditOptions, EditSession

    vid = int(np.flatnonzero(wein99.star_of_vertex >= 0)[len(wein99.stars) // 2])
    stars = canonical_stars(wein99.vertices, wein99.stars)
    normal = star_normals(wein99.vertices, stars)[wein99.star_of_vertex[vid]]
    edge = wein99.mean_edge_length
    good = {vid: wein99.vertices[vid] + 0.5 * edge * normal}
    tried = EditSession(wein99, EditOptions("snet", max_iterations=3))
    settled = tried.vertices.copy()         # the net as opened, solved to the tolerance
    assert not tried.drag({vid: wein99.vertices[vid] + 8 * edge * normal}).result.accepted
    assert np.array_equal(tried.vertices, settled)
    tried.options.max_iterations = 40
    assert tried.drag(good).result.accepted
    plain = EditSession(wein99, EditOptions("snet"))
    assert plain.drag(good).result.accepted
    assert np.abs(tried.vertices - plain.vertices).max() <= 1e-12 * edge
