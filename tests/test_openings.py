"""Trimming that respects the design: no net face or boundary panel covers an opening of
the design (a door), the cladding covers the rest, and no panel crosses itself, another
or the net. Measured here by code written apart from `fabplan.layout.trim`: points on a
grid in the facade's plane, each tested against every panel's outline by its winding
number (the facades are height fields over that plane)."""

from __future__ import annotations

import numpy as np
import pytest

from fabplan.design.mesh_surface import DesignSurface
from fabplan.layout.surface_layout import glide, layout_surface


def _door_facade(seed: int) -> tuple[DesignSurface, tuple, float]:
    """A seeded facade with a door on the ground: (design, door box (x0, x1, y0, y1),
    panel size). Sizes 10-20 x 5-10 m, door 0.9-2.5 x 2.1-3.2 m, flat or wavy, panels
    0.6-1.5 m."""
    rng = np.random.default_rng(seed)
    width, height = rng.uniform(10, 20), rng.uniform(5, 10)
    step = 0.125
    nx, ny = int(round(width / step)), int(round(height / step))
    width, height = nx * step, ny * step
    wide, high = step * round(rng.uniform(0.9, 2.5) / step), step * round(rng.uniform(2.1, 3.2) / step)
    x0 = step * round(rng.uniform(1.0, width - wide - 1.0) / step)
    wavy = 0.4 * bool(rng.integers(2))
    panel = float(rng.uniform(0.6, 1.5))
    x, y = np.meshgrid(np.linspace(0, width, nx + 1), np.linspace(0, height, ny + 1), indexing="ij")
    z = wavy * np.sin(0.5 * x) * np.cos(0.4 * y) + 0.01 * x * y
    V = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    idx = np.arange(V.shape[0]).reshape(x.shape)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    centre = V[T].mean(axis=1)
    door = (centre[:, 0] > x0) & (centre[:, 0] < x0 + wide) & (centre[:, 1] < high)
    return DesignSurface(V, T[~door], name=f"door-{seed}"), (x0, x0 + wide, 0.0, high), panel


def _inside(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """(m,) bool, points (m, 2) with a non-zero winding number about the closed outline
    (k, 2)."""
    a, b = outline, np.roll(outline, -1, axis=0)
    winding = np.zeros(len(points), np.int64)
    for (x0, y0), (x1, y1) in zip(a, b, strict=True):
        cross = (x1 - x0) * (points[:, 1] - y0) - (points[:, 0] - x0) * (y1 - y0)
        up = (y0 <= points[:, 1]) & (y1 > points[:, 1]) & (cross > 0)
        down = (y0 > points[:, 1]) & (y1 <= points[:, 1]) & (cross < 0)
        winding += up.astype(np.int64) - down.astype(np.int64)
    return winding != 0


def _covered(points: np.ndarray, outlines: list) -> np.ndarray:
    """(m,) int, how many outlines (each (k, 2)) hold each point (m, 2)."""
    count = np.zeros(len(points), np.int64)
    for outline in outlines:
        lo, hi = outline.min(axis=0), outline.max(axis=0)
        near = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
        count[near] += _inside(points[near], outline)
    return count


def _outlines(net) -> list:
    """The net's faces and its boundary panels in the xy-plane."""
    X, panels = net.mesh.vertices, net.boundary_panels
    return [X[f][:, :2] for f in net.mesh.faces] + \
        [panels.vertices[p][:, :2] for p in panels.polygons]


SEEDS = [1, 2, 3, 4, 6, 9]


@pytest.fixture(scope="module", params=SEEDS)
def door_net(request):
    design, door, h = _door_facade(request.param)
    layout = layout_surface(design, h)
    return design, door, h, glide(layout, "snet")


def test_no_panel_covers_the_door(door_net):
    """0 m2 of panels over the opening: a grid of points 1 cm apart in the door (a
    centimetre in from its edges), none under a net face or a boundary panel."""
    _, (x0, x1, y0, y1), _, net = door_net
    step = 0.01
    xs, ys = np.arange(x0 + step, x1 - step / 2, step), np.arange(y0 + step, y1 - step / 2, step)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    held = _covered(points, _outlines(net))
    assert held.sum() == 0, f"{held.astype(bool).mean() * (x1 - x0) * (y1 - y0):.4f} m2 clad"
    record = net.properties["boundary_panels"]
    assert record["off_design"]["area"] == 0.0 and record["off_design"]["places"] == []


def test_the_facade_without_the_door_is_clad(door_net):
    """At least 99.5 % of the facade less its door lies under a panel, counted on a 5 cm
    grid in the facade's plane."""
    design, (x0, x1, y0, y1), _, net = door_net
    lo, hi = design.vertices[:, :2].min(axis=0), design.vertices[:, :2].max(axis=0)
    step = 0.05
    xs, ys = np.arange(lo[0] + step / 2, hi[0], step), np.arange(lo[1] + step / 2, hi[1], step)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    facade = ~((points[:, 0] > x0) & (points[:, 0] < x1) & (points[:, 1] < y1))
    held = _covered(points[facade], _outlines(net))
    assert (held > 0).mean() >= 0.995


def test_no_panel_overlaps_another_or_the_net(door_net):
    """No point of the facade lies under two pieces (beyond a centimetre band along their
    shared sides, where the grid meets the outlines), and the record counts none."""
    design, _, _, net = door_net
    lo, hi = design.vertices[:, :2].min(axis=0), design.vertices[:, :2].max(axis=0)
    step = 0.05
    xs, ys = np.arange(lo[0] + step / 3, hi[0], step), np.arange(lo[1] + step / 3, hi[1], step)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    twice = (_covered(points, _outlines(net)) > 1).mean() * np.prod(hi - lo)
    assert twice <= 1e-3 * net.parameters["panel_size"] ** 2 * len(net.mesh.faces)
    crossings = net.properties["boundary_panels"]["crossings"]
    assert crossings["self_crossing"] == crossings["overlapping"] == crossings["edge_clashes"] == 0


def test_no_net_face_has_three_corners_in_a_line(door_net):
    """Every corner of every net face turns by more than a degree."""
    *_, net = door_net
    X = net.mesh.vertices
    for face in net.mesh.faces:
        P = X[face]
        a, b = np.roll(P, 1, axis=0) - P, np.roll(P, -1, axis=0) - P
        sine = np.linalg.norm(np.cross(a, b), axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        assert sine.min() > np.sin(np.radians(1.0))


# ------------------------------------------------------------------ the measure itself


def _square_with_door(size: float = 4.0, step: float = 0.1) -> DesignSurface:
    """A flat square with a door 1 wide and 2 high from (1.5, 0)."""
    n = int(round(size / step))
    x, y = np.meshgrid(np.linspace(0, size, n + 1), np.linspace(0, size, n + 1), indexing="ij")
    V = np.stack([x, y, 0 * x], axis=-1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(x.shape)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    centre = V[T].mean(axis=1)
    door = (centre[:, 0] > 1.5) & (centre[:, 0] < 2.5) & (centre[:, 1] < 2.0)
    return DesignSurface(V, T[~door], name="square with a door")


def test_a_quad_across_the_door_is_measured_off_the_design_by_its_area():
    """A unit quad over the door's top left corner has a quarter of its area (0.25) over
    the opening; one beside the door has none; a sliver one centimetre into the door
    along its side is found though it lies between the interior samples."""
    from fabplan.layout.off_design import faces_off_design

    design = _square_with_door()
    V = np.array([[1.0, 1.5, 0], [2.0, 1.5, 0], [2.0, 2.5, 0], [1.0, 2.5, 0],
                  [0.2, 0.2, 0], [1.2, 0.2, 0], [1.2, 1.2, 0], [0.2, 1.2, 0],
                  [0.5, 0.0, 0], [1.5, 0.0, 0], [1.51, 2.0, 0], [0.5, 2.0, 0]])
    off = faces_off_design(design, V, [np.arange(4), np.arange(4, 8), np.arange(8, 12)], 1.0)
    assert off.area[0] == pytest.approx(0.25, rel=0.1)
    assert off.area[1] == 0.0
    assert off.area[2] == pytest.approx(0.5 * 2.0 * 0.01, rel=0.2)      # the sliver's triangle
    assert 1.5 < off.point[0][0] < 2.0 and 1.5 < off.point[0][1] < 2.0


def test_a_chord_of_a_round_opening_is_no_panel_over_it():
    """A quad whose side joins two points of a round window's rim sags into the window by
    its nature (straight sides cannot follow the rim): not counted. A quad across the
    window is, and so is one whose side runs 1 cm into a door along its straight side
    (`test_a_quad_across_the_door_is_measured_off_the_design_by_its_area`)."""
    from fabplan.layout.off_design import faces_off_design

    rings, around = 40, 360
    radius = np.linspace(1.5, 3.0, rings + 1)
    angle = np.linspace(0, 2 * np.pi, around, endpoint=False)
    r, t = np.meshgrid(radius, angle, indexing="ij")
    V = np.stack([r * np.cos(t), r * np.sin(t), 0 * r], axis=-1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(r.shape)
    a, b = idx[:-1], idx[1:]
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    design = DesignSurface(V, T, name="round window")
    rim = design.boundary_curves()
    inner = min(rim, key=lambda r: np.abs(r).max())
    angle = np.arctan2(inner[:, 1], inner[:, 0])
    p, q = inner[np.argmin(np.abs(angle - 0.3))], inner[np.argmin(np.abs(angle - 0.6))]
    outward = 0.5 * (p + q) / np.linalg.norm(0.5 * (p + q)) * 0.8
    chord = np.array([p, q, q + outward, p + outward])
    across = np.array([[-2.0, -0.5, 0], [2.0, -0.5, 0], [2.0, 0.5, 0], [-2.0, 0.5, 0]])
    off = faces_off_design(design, np.vstack([chord, across]), [np.arange(4), np.arange(4, 8)], 0.5)
    assert off.area[0] == 0.0
    assert off.area[1] > 2.5


def _pushed_pieces(net, h: float, seed: int) -> tuple[list, np.ndarray]:
    """The net faces and boundary panels of `net` (panel size `h`), a fifth of their
    corners pushed about a tenth of a panel at random: the pieces (into the points) and
    the points (n, 3)."""
    pieces = [*net.mesh.faces, *(np.asarray(q) + net.mesh.vertex_count
                                 for q in net.boundary_panels.polygons)]
    V = np.vstack([net.mesh.vertices, net.boundary_panels.vertices])
    rng = np.random.default_rng(seed)
    return pieces, V + rng.normal(scale=0.1 * h, size=V.shape) * (rng.random((len(V), 1)) < 0.2)


def test_measuring_only_what_may_leave_the_design_changes_no_number(door_net, monkeypatch):
    """The net faces and boundary panels of a door facade, lifted off it and pushed past
    its edges in places, measured as `faces_off_design` does (only the triangles and sides
    that `may_leave_design` keeps) and with every sample measured: the same areas and
    points to the bit, and some of them off the design."""
    import fabplan.layout.off_design as off_design

    design, _, h, net = door_net
    pieces, V = _pushed_pieces(net, h, seed=7)
    kept = off_design.faces_off_design(design, V, pieces, h)
    monkeypatch.setattr(off_design, "may_leave_design",
                        lambda d, centre, *args: np.ones(len(centre), bool))
    every = off_design.faces_off_design(design, V, pieces, h)
    assert (every.area > 0).sum() >= 3
    assert np.array_equal(kept.area, every.area)
    assert np.array_equal(kept.point, every.point, equal_nan=True)


def test_a_face_outline_measured_once_gives_the_average_of_its_two_fans(door_net):
    """`faces_off_design` measures a face's outline once for both fans: the areas of
    `area_off_design` of each fan, averaged, to rounding; and a face that runs over a
    corner twice (its two fans' outlines differ) measured fan by fan as before."""
    from fabplan.layout.off_design import area_off_design, faces_off_design

    design, _, h, net = door_net
    pieces, V = _pushed_pieces(net, h, seed=11)
    quad = np.asarray(net.mesh.faces[0])
    pieces.append(np.array([quad[0], quad[1], quad[1], quad[2]]))       # a corner twice
    measured = faces_off_design(design, V, pieces, h)
    fans = [np.array([[f[k], f[(k + j) % len(f)], f[(k + j + 1) % len(f)]]
                      for f in pieces for j in range(1, len(f) - 1)]) for k in (0, 1)]
    owner = np.repeat(np.arange(len(pieces)), [len(f) - 2 for f in pieces])
    each = [area_off_design(design, V, fan, owner, len(pieces), h) for fan in fans]
    assert (measured.area > 0).sum() >= 3
    assert np.allclose(measured.area, 0.5 * (each[0].area + each[1].area), rtol=1e-12,
                       atol=1e-15 * h * h)


def test_a_boundary_file_folded_over_the_net_names_the_panel_in_the_file(tmp_path, capsys):
    """A boundary panel running along a net face's side the same way (written by hand or
    by an older cut) is named by its face in NET.boundary.obj, not by its number in a
    mesh of net and panels together; exit 2 (the file is not one fabplan writes)."""
    from fabplan.cli import main
    from fabplan.net.mesh import QuadMesh

    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), [0.0], indexing="ij"), -1)[:, :, 0]
    net = QuadMesh.grid(g)
    net.write_obj(tmp_path / "net.obj")
    f = net.faces[0]
    lines = [f"v {x} {y} {z}" for x, y, z in net.vertices] + ["v -1 -1 0"]
    lines += [f"f {len(net.vertices) + 1} {f[1] + 1} {f[0] + 1}",     # panel 0: fine
              f"f {f[0] + 1} {f[1] + 1} {len(net.vertices) + 1}"]     # panel 1: along a side
    (tmp_path / "net.boundary.obj").write_text("\n".join(lines) + "\n")
    code = main(["molds", str(tmp_path / "net.obj"), "--tolerance-mm", "2", "-o",
                 str(tmp_path / "molds")])
    err = capsys.readouterr().err
    assert code == 2 and "boundary panel 1" in err and "face 2" in err
    assert len(err.strip().splitlines()) == 1


def test_panels_off_the_design_are_warned_about_with_where():
    from fabplan.cli import boundary_warnings

    record = {"coverage": 1.0, "boundary_panels": {"off_design": {
        "area": 0.25, "area_relative_to_panel": 0.25, "faces": 1, "panels": 0,
        "places": [{"face": 12, "area": 0.25, "point": [1.75, 1.75, 0.0]}]},
        "crossings": {"self_crossing": 0, "overlapping": 1, "edge_clashes": 0,
                      "pairs": [[{"panel": 3}, {"face": 12}]], "cut_again": 2}}}
    words = " ".join(boundary_warnings(record))
    assert "0.25" in words and "face 12" in words and "1.75, 1.75" in words
    assert "1 pair" in words
