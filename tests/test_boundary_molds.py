"""Boundary panels on the net's molds, checked by code apart from the planner: the steps
between neighbouring panels recomputed from the placements and mold curvatures alone
(`helpers.chord_steps`, at other points of the shared sides; `helpers.exported_molds`
from the files written), the panels as cut measured on their molds and against the exact
surfaces they continue."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import chord_steps, exported_molds, mold_gaps

from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.design.mesh_surface import DesignSurface
from fabplan.fabricate.molds import MoldSettings, plan_molds
from fabplan.fabricate.molds.boundary_molds import boundary_molds, boundary_sides
from fabplan.io.obj import read_obj
from fabplan.layout.surface_layout import glide, layout_surface
from fabplan.layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels


def _cylinder(radius: float, length: float, arc: float, cells: int) -> DesignSurface:
    """A piece of a circular cylinder about the y axis: x = r sin a, z = r cos a."""
    a, y = np.meshgrid(np.linspace(-arc / 2, arc / 2, cells + 1), np.linspace(0, length, cells + 1),
                       indexing="ij")
    V = np.stack([radius * np.sin(a), y, radius * np.cos(a)], axis=-1).reshape(-1, 3)
    idx = np.arange(V.shape[0]).reshape(a.shape)
    q = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    T = np.concatenate([np.stack([q[0], q[1], q[2]], -1).reshape(-1, 3),
                        np.stack([q[0], q[2], q[3]], -1).reshape(-1, 3)])
    return DesignSurface(V, T, name="cylinder")


@pytest.fixture(scope="module")
def cylinder():
    """A 6 x 8 m piece of a cylinder of radius 12 m, its gliding isogonal net of 60 degrees
    (a staircase of boundary panels along its edges), its molds at 1 mm and
    its boundary panels' molds."""
    design = _cylinder(12.0, 8.0, 0.5, 48)
    net = glide(layout_surface(design, 0.9, angle=60.0), "isogonal", angle=60.0)
    plan = plan_molds(net.mesh, MoldSettings(tolerance_mm=1.0, units="m"))
    return design, net, plan, boundary_molds(plan, net.boundary_panels, design=design)


def test_boundary_panels_of_a_cylinder_are_cut_from_its_one_mold(cylinder):
    """On a cylinder every panel has one curvature: the boundary panels are cut from the
    net's one mold, and as cut they lie on the cylinder."""
    design, net, plan, molds = cylinder
    panels = net.boundary_panels
    assert panels.panel_count >= 10
    assert int(np.sum(plan.mold_type > 0)) == 1
    assert molds.own_molds == 0 and np.all(molds.mold == 0)
    # the panels as cut, measured against the cylinder itself: x^2 + z^2 = r^2
    cut = np.concatenate(molds.cut_outlines)
    off = np.abs(np.hypot(cut[:, 0], cut[:, 2]) - 12.0) * 1000.0
    assert off.max() <= plan.settings.tolerance_mm
    assert molds.deviation_max_mm == pytest.approx(
        max(design.distances(c).max() for c in molds.cut_outlines) * 1000.0, abs=0.5)


def _recheck(net, plan, molds) -> tuple[np.ndarray, np.ndarray]:
    """Steps (mm) along every side a boundary panel shares with a net face, and along every
    side two boundary panels share, recomputed here."""
    panels = net.boundary_panels
    X = panels.vertices
    faces = {}
    for f, q in enumerate(net.mesh.faces):
        for a, b in zip(q, np.roll(q, -1), strict=True):
            faces[(int(a), int(b))] = f
    sides = {}
    for k, q in enumerate(panels.polygons):
        for a, b in zip(q, np.roll(q, -1), strict=True):
            sides[(int(a), int(b))] = k
    net_shape = plan.mold_shape[plan.mold]
    with_net, between = [], []
    for (a, b), k in sides.items():
        if (b, a) in faces:
            f = faces[(b, a)]
            with_net.append((X[[a, b]], molds.placement[k], molds.shape[k], plan.placement[f],
                             net_shape[f]))
        elif (b, a) in sides and k < sides[(b, a)]:
            j = sides[(b, a)]
            between.append((X[[a, b]], molds.placement[k], molds.shape[k], molds.placement[j],
                            molds.shape[j]))
    out = []
    for rows in (with_net, between):
        if not rows:
            out.append(np.zeros(0))
            continue
        chords, A, KA, B, KB = (np.array(v) for v in zip(*rows, strict=True))
        out.append(chord_steps(chords, A, KA, B, KB))
    return out[0], out[1]


def test_boundary_panels_meet_their_neighbours_within_the_step_limit(cylinder):
    """Rechecked from the placements alone, every boundary panel meets the full panels and
    the boundary panels beside it within the step limit; the planner's largest step is the
    one found here (at other points of the sides)."""
    _, net, plan, molds = cylinder
    with_net, between = _recheck(net, plan, molds)
    assert len(with_net) >= 20
    steps = np.r_[with_net, between]
    assert steps.max() <= molds.step_limit_mm
    assert steps.max() == pytest.approx(molds.step_max_mm, rel=0.2, abs=0.05)
    # the panels as cut lie on their molds (no gap but rounding)
    for k, cut in enumerate(molds.cut_outlines):
        gap = mold_gaps(cut, np.repeat(molds.placement[k][None], len(cut), 0),
                        np.repeat(molds.shape[k][None], len(cut), 0))
        assert gap.max() <= 1e-6


def test_slivers_are_cut_with_their_full_panel(cylinder):
    _, net, plan, molds = cylinder
    panels = net.boundary_panels
    sliver = np.flatnonzero(panels.extension)
    f = panels.neighbour_face[sliver]
    assert np.array_equal(molds.mold[sliver], plan.mold[f])
    assert np.allclose(molds.placement[sliver], plan.placement[f])


def test_boundary_sides_name_what_lies_across():
    """A panel's side along a net face names that face; two panels' shared side names the
    other panel; a side along the design boundary neither."""
    net = glide(layout_surface(_cylinder(12.0, 8.0, 0.5, 48), 0.9, angle=90.0), "snet")
    panels = net.boundary_panels
    sides = boundary_sides(panels, net.mesh)
    X = panels.vertices
    on_face = sides.face >= 0
    assert on_face.any() and (sides.across >= 0).any()
    for k in np.flatnonzero(on_face):
        face = list(net.mesh.faces[sides.face[k]])
        assert sides.start[k] in face and sides.end[k] in face
    for k in np.flatnonzero(sides.across >= 0):
        other = list(panels.polygons[sides.across[k]])
        assert sides.start[k] in other and sides.end[k] in other
    # along the design boundary: both ends on the boundary curve
    free = np.flatnonzero((sides.face < 0) & (sides.across < 0))
    on = panels.on_design_boundary
    assert np.all(on[sides.start[free]] & on[sides.end[free]])
    assert np.all(np.isfinite(X[sides.start]))


@pytest.fixture(scope="module")
def off_design(tmp_path_factory):
    """A constant-radius net optimized off a saddle (it leaves the design by some mm) from
    an isogonal layout of 60 degrees (a staircase of boundary panels on every edge), its
    boundary panels following it, written as `fabplan optimize` writes them, and its molds
    as `fabplan molds` writes them."""
    import fabplan

    folder = tmp_path_factory.mktemp("off")
    design = load_design("hyperbolic-paraboloid:width=4,depth=4,rise=1.2", triangles=4000)
    layout = layout_surface(design, 0.7, angle=60.0)
    start = glide(layout, "isogonal", angle=60.0)
    net = fabplan.optimize(start.mesh, "const-radius", reference=design.reference)
    add_boundary_panels(net, layout, touch=OFF_DESIGN_TOUCH, follow_net=True)
    net.write(folder / "net.obj")
    assert main(["molds", str(folder / "net.obj"), "--tolerance-mm", "1.5", "--no-3d", "-q",
                 "-o", str(folder / "molds")]) in (0, 3)
    return design, net, folder


def test_the_molds_of_a_net_off_its_design_are_rechecked_from_the_files(off_design):
    """From molds.json, boundary-panels.csv, boundary-panels.obj and the nets' OBJ files
    alone (`helpers.exported_molds`): the panels as cut lie on the molds the CSV names with
    its placements, every shared side steps within the limit, as far as the planner says,
    and the molds in all are the net's curved molds and the boundary panels' own."""
    design, net, folder = off_design
    out = folder / "molds"
    found = exported_molds(folder / "net.obj", folder / "net.boundary.obj", out / "molds.json",
                           out / "boundary-panels.csv", out / "boundary-panels.obj")
    record = found["record"]
    bp = record["boundary_panels"]
    assert found["cut_gap_mm"] <= 1e-6
    steps = found["steps"]
    boundary = np.r_[steps["net-boundary"], steps["boundary-boundary"]]
    limit = record["panel_steps"]["limit_mm"]
    assert len(boundary) >= 20
    assert max(boundary.max(), steps["net-net"].max()) <= limit
    assert boundary.max() == pytest.approx(bp["step_max_mm"], rel=0.1, abs=0.05)
    assert bp["molds_in_all"] == found["molds_in_all"] == record["molds_made"] + bp["own_molds"]
    # the panels as cut stand off the design about as far as the net does
    cut, _ = read_obj(out / "boundary-panels.obj")
    assert design.distances(cut).max() <= design.distances(net.mesh.vertices).max() + 0.03


def test_a_net_off_its_design_gets_few_molds_of_its_own(off_design):
    """The boundary panels of a constant-radius net (its panels of about one curvature)
    are cut from the net's molds: fewer of their own than the net has molds; the study's
    reading of the same files finds the same molds."""
    _, net, folder = off_design
    record = json.loads((folder / "molds" / "molds.json").read_text())
    bp = record["boundary_panels"]
    assert bp["panels"] >= 12          # enough boundary panels for the count to mean something
    assert bp["own_molds"] <= record["mold_count"]
    assert bp["on_molds_full_panels_use"] >= bp["panels"] - bp["own_molds"]
    from fabplan.layout.boundary_panels import read_boundary_panels
    from fabplan.net.mesh import load_mesh

    mesh = load_mesh(folder / "net.obj")
    plan = plan_molds(mesh, MoldSettings(tolerance_mm=1.5, units="m"))
    panels = read_boundary_panels(mesh, folder / "net.boundary.obj",
                                  net.properties["boundary_panels"])
    again = boundary_molds(plan, panels)
    assert again.mold.tolist() == bp["mold"]
    assert again.step_max_mm == pytest.approx(bp["step_max_mm"], rel=1e-9)


@pytest.fixture(scope="module")
def flat_glass(tmp_path_factory):
    """A characteristic conjugate net (planar quads: flat glass) optimized off an elliptic
    paraboloid from an S-net layout, its boundary panels following it, its molds at 1 mm
    (one plane) and its boundary panels' molds; written as a study writes them (the
    boundary panels as made) with `fabplan molds` run on the files."""
    import fabplan

    folder = tmp_path_factory.mktemp("flat")
    design = load_design("paraboloid:radius_x=9,radius_y=15,width=8,depth=6", triangles=6000)
    layout = layout_surface(design, 1.5)
    net = fabplan.optimize(glide(layout, "snet").mesh, "char-conjugate",
                           reference=design.reference)
    add_boundary_panels(net, layout, touch=OFF_DESIGN_TOUCH, follow_net=True)
    cut = net.boundary_panels
    plan = plan_molds(net.mesh, MoldSettings(tolerance_mm=1.0, units="m"))
    molds = boundary_molds(plan, cut, design=design)
    net.boundary_panels = molds.panels
    net.write(folder / "net.obj")
    assert main(["molds", str(folder / "net.obj"), "--tolerance-mm", "1", "--units", "m",
                 "--no-3d", "-q", "-o", str(folder / "molds")]) == 0
    return net, cut, plan, molds, folder


def test_boundary_panels_beside_flat_panels_are_flat(flat_glass):
    """Beside a net of flat panels every boundary panel is flat, on the net's plane: no
    mold of its own. Rechecked from the placements, it meets the faces beside it without
    a step (it lies in the plane of the net sides it borders), and the panels beside it
    within the limit; where two flat panels part on the design boundary, their shared side
    runs along the line where their planes cross (a point of both planes)."""
    net, cut, plan, molds, _ = flat_glass
    assert plan.mold_type.tolist() == [0]
    assert molds.count >= 15 and molds.flat == molds.count
    assert molds.own_molds == 0 and np.all(molds.mold == 0) and np.all(molds.shape == 0)
    with_net, between = _recheck(net, plan, molds)
    assert len(with_net) >= 20 and with_net.max() <= 1e-6
    assert len(between) >= 4 and between.max() <= molds.step_limit_mm
    moved = np.flatnonzero(np.any(molds.panels.vertices != cut.vertices, axis=1))
    assert len(moved) >= 4 and np.all(moved >= net.mesh.vertex_count)
    assert np.all(molds.panels.on_design_boundary[moved])
    mm = plan.settings.mm_per_unit
    for r in moved:
        holders = [k for k, q in enumerate(molds.panels.polygons) if r in q]
        assert len(holders) == 2
        for k in holders:
            height = molds.placement[k, 2, :3] @ molds.panels.vertices[r] + molds.placement[k, 2, 3]
            assert abs(height) <= 1e-6 * mm
    # the outlines are the trimmed ones but for the slid points and the boundary's points
    # they passed: the area clad is the same
    assert sum(molds.panels.area) == pytest.approx(sum(cut.area), rel=1e-3)


def test_flat_boundary_panels_are_found_again_from_their_file(flat_glass):
    """Read back from NET.boundary.obj (the panels as made), the flat panels slide no
    further and sit where they did; `fabplan molds` on the files writes the same, rechecked
    from its files alone: every step within the limit and no mold in all."""
    from fabplan.layout.boundary_panels import read_boundary_panels

    net, _, plan, molds, folder = flat_glass
    panels = read_boundary_panels(net.mesh, folder / "net.boundary.obj",
                                  net.properties["boundary_panels"])
    again = boundary_molds(plan, panels)
    assert np.array_equal(again.panels.vertices, panels.vertices)
    assert all(np.array_equal(a, b) for a, b in zip(again.panels.polygons, panels.polygons,
                                                     strict=True))
    assert np.allclose(again.placement, molds.placement, atol=1e-9)
    out = folder / "molds"
    found = exported_molds(folder / "net.obj", folder / "net.boundary.obj", out / "molds.json",
                           out / "boundary-panels.csv", out / "boundary-panels.obj")
    steps = found["steps"]
    assert max(v.max() for v in steps.values() if len(v)) <= plan.step_limit_mm
    assert found["molds_in_all"] == 0 and found["cut_gap_mm"] <= 1e-6
    bp = found["record"]["boundary_panels"]
    assert bp["flat"] == bp["panels"] == molds.count and bp["own_molds"] == 0


def test_a_run_without_boundary_panels_leaves_none_of_an_earlier_runs(flat_glass, tmp_path):
    """`fabplan molds` run again into its folder without boundary panels: the earlier
    run's boundary-panels.csv and .obj are removed (they stayed beside a molds.json that
    records none, two runs in one folder); a file of that name in a folder no molds run
    wrote is left alone."""
    folder = flat_glass[-1]
    work = tmp_path / "work"
    work.mkdir()
    for name in ("net.obj", "net.json", "net.boundary.obj"):
        (work / name).write_bytes((folder / name).read_bytes())
    common = ["--tolerance-mm", "1", "--units", "m", "--no-3d", "-q"]
    assert main(["molds", str(work / "net.obj"), *common, "-o", str(work / "molds")]) == 0
    assert (work / "molds" / "boundary-panels.obj").is_file()
    assert main(["molds", str(work / "net.obj"), *common, "--no-boundary",
                 "-o", str(work / "molds")]) == 0
    record = json.loads((work / "molds" / "molds.json").read_text(encoding="utf-8"))
    assert record.get("boundary_panels") is None
    assert not (work / "molds" / "boundary-panels.obj").exists()
    assert not (work / "molds" / "boundary-panels.csv").exists()
    # a folder of the user's own with such a file and no molds.json: nothing removed
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "boundary-panels.csv").write_text("my own\n", encoding="utf-8")
    assert main(["molds", str(work / "net.obj"), *common, "--no-boundary", "-o", str(mine)]) == 0
    assert (mine / "boundary-panels.csv").read_text(encoding="utf-8") == "my own\n"
