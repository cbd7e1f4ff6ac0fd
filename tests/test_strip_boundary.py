"""Lamellas run through the boundary panels to the edge of the cladding.

The checks rebuild what they need from the written files (the net's OBJ and its
``NET.boundary.obj``) with their own code: the cladding's outline (sides used by one polygon
among the net's faces and the boundary panels), the strips' 3D nodes, the angle to the
outline and the set-back of a strip end cut against the boundary member.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from fabplan.cli import main
from fabplan.io.obj import read_obj

HEIGHT, THICKNESS = 100.0, 6.0


@pytest.fixture(scope="module", params=[1.0, 0.8], ids=["panel-1.0", "panel-0.8"])
def laid_out(tmp_path_factory, request):
    """An S-net layout of a paraboloid with its boundary panels, and its strips run to
    the edge and not. At panel size 0.8 a boundary panel has a notch: two of its corners a
    hair apart inside the cladding, which is no point of the edge."""
    root = tmp_path_factory.mktemp("strip-boundary")
    net = root / "saddle.obj"
    assert main(["layout", "paraboloid", "--net", "snet", "--panel-size", str(request.param),
                 "--triangles", "6000", "-o", str(net), "-q"]) == 0
    assert (root / "saddle.boundary.obj").is_file()
    common = ["--height", str(HEIGHT), "--thickness", str(THICKNESS), "--no-previews", "-q"]
    assert main(["strips", str(net), *common, "-o", str(root / "to-edge")]) == 0
    assert main(["strips", str(net), *common, "--no-boundary", "-o", str(root / "at-net")]) == 0
    return root


def _record(folder):
    return json.loads((folder / "strips.json").read_text())


def _design_edge(triangles: int) -> np.ndarray:
    """(e, 2, 3) the paraboloid design's boundary segments (sides of one triangle)."""
    import fabplan

    design = fabplan.load_design("paraboloid", triangles=triangles)
    T = np.asarray(design.triangles)
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    key, count = np.unique(e, axis=0, return_counts=True)
    return np.asarray(design.vertices)[key[count == 1]]


def _to_edge(p: np.ndarray, segments: np.ndarray) -> tuple[float, np.ndarray]:
    """Distance of point p from the boundary segments, and the nearest one's direction."""
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0, 1)
    dist = np.linalg.norm(a + t[:, None] * d - p, axis=1)
    k = int(np.argmin(dist))
    return float(dist[k]), d[k] / np.linalg.norm(d[k])


def test_strips_run_through_the_boundary_panels_to_the_edge(laid_out):
    X_net, net_faces = read_obj(laid_out / "saddle.obj")
    X, panels = read_obj(laid_out / "saddle.boundary.obj")
    assert np.allclose(X[:len(X_net)], X_net)
    edge = _design_edge(6000)
    edge_rec, net_rec = _record(laid_out / "to-edge"), _record(laid_out / "at-net")
    s_edge, s_net = edge_rec["summary"], net_rec["summary"]
    assert s_edge["ends_at_boundary_member"] > 0 and s_net["ends_at_boundary_member"] == 0
    assert s_edge["boundary_nodes"] > 0 and s_edge["total_length_mm"] > s_net["total_length_mm"]
    net_edges = {(min(int(a), int(b)), max(int(a), int(b)))
                 for f in net_faces for a, b in zip(f, np.roll(f, -1), strict=True)}
    panel_sides = {(min(int(a), int(b)), max(int(a), int(b)))
                   for p in panels for a, b in zip(p, np.roll(p, -1), strict=True)}
    members = 0
    for strip in edge_rec["strips"]:
        v = np.array(strip["vertices"])
        before, after = strip["boundary_nodes"]
        # the nodes beyond the net are boundary panel corners, joined by panel sides that are
        # no net edges, turning little
        for lo, hi in ((0, before + 1), (len(v) - after - 1, len(v))):
            for a, b in zip(v[lo:hi - 1], v[lo + 1:hi], strict=True):
                key = (min(a, b), max(a, b))
                assert key in panel_sides and key not in net_edges
        if before or after:
            assert max(_turns(X, v[:before + 2]) + _turns(X, v[len(v) - after - 2:])) < 36
        for side, (end, prev) in enumerate(((v[0], v[1]), (v[-1], v[-2]))):
            setback = strip["end_setback_mm"][side]
            if setback is None:
                continue
            members += 1
            angle = strip["end_angle_deg"][side]
            assert angle >= 15.0
            # clear of the member (as thick as the lamella here) with both faces; more at a
            # tip where two strips end; less where the end runs on to an edge a hair beyond
            a = math.radians(angle)
            clear = 0.5 * THICKNESS / math.sin(a) + 0.5 * THICKNESS / math.tan(a)
            reach = max(clear - setback, 0.0) / 1000.0
            direction = (X[end] - X[prev]) / np.linalg.norm(X[end] - X[prev])
            gap, along = _to_edge(X[end] + reach * direction, edge)
            assert gap < 0.016, (strip["strip"], side, gap)     # 2 % of a panel
            mine = math.degrees(math.asin(min(1.0, np.linalg.norm(np.cross(direction, along)))))
            assert angle == pytest.approx(mine, abs=3.0), (strip["strip"], side)
    assert members == s_edge["ends_at_boundary_member"]


def test_every_free_end_says_why(laid_out):
    """A free end is inside the net (where a line stops at an irregular vertex), meets the
    edge at a glancing angle, or could not be continued; the schedule says which."""
    X_net, faces = read_obj(laid_out / "saddle.obj")
    sides = np.sort(np.concatenate([np.c_[f, np.roll(f, -1)] for f in faces]), axis=1)
    key, count = np.unique(sides, axis=0, return_counts=True)
    on_net_boundary = np.zeros(len(X_net), bool)
    on_net_boundary[key[count == 1].ravel()] = True
    rec = _record(laid_out / "to-edge")
    kinds = rec["summary"]["ends_free_by_kind"]
    assert sum(kinds.values()) == rec["summary"]["ends_free"] and kinds["free"] == 0
    assert kinds["not continued"] == rec["summary"]["ends_not_continued"]
    with open(laid_out / "to-edge" / "strips.csv", newline="") as f:
        rows = {r["strip"]: r for r in csv.DictReader(line for line in f if not line.startswith("#"))}
    for strip in rec["strips"]:
        v = strip["vertices"]
        for side, end in ((0, v[0]), (1, v[-1])):
            text = rows[strip["strip"]]["start" if side == 0 else "end"]
            if text == "free (inside)":
                assert end < len(X_net) and not on_net_boundary[end]
            elif text.startswith("free"):
                assert text in ("free (along edge)", "free (not continued)")
                assert end < len(X_net) and on_net_boundary[end]
            else:
                assert text.startswith("member")


def _turns(X: np.ndarray, v: np.ndarray) -> list:
    d = np.diff(X[v], axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return [math.degrees(math.acos(np.clip(a @ b, -1, 1))) for a, b in zip(d[:-1], d[1:], strict=True)]


def test_a_strip_end_at_the_member_is_cut_square_at_its_set_back(laid_out):
    rec = _record(laid_out / "to-edge")
    strips = {s["strip"]: s for s in rec["strips"]}
    ext = HEIGHT / 2
    checked = 0
    for part in rec["parts"]:
        strip = strips[part["strip"]]
        count = sum(p["strip"] == part["strip"] for p in rec["parts"])
        length = strip["cut_length_mm"]
        start_setback, end_setback = strip["end_setback_mm"]
        if part["index"] == 1:
            want = -ext if start_setback is None else start_setback
            assert part["s_start_mm"] == pytest.approx(want, abs=1e-6)
        if part["index"] == count:
            want = length + ext if end_setback is None else length - end_setback
            assert part["s_end_mm"] == pytest.approx(want, abs=0.006)   # the length is rounded
            checked += end_setback is not None
    assert checked > 0
    with open(laid_out / "to-edge" / "strips.csv", newline="") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
    assert sum(r["end"].startswith("member") for r in rows) \
        + sum(r["start"].startswith("member") for r in rows) == rec["summary"]["ends_at_boundary_member"]


def test_a_boundary_file_of_another_net_is_refused(laid_out, tmp_path, capsys):
    other = tmp_path / "other.boundary.obj"
    X, panels = read_obj(laid_out / "saddle.boundary.obj")
    text = "".join(f"v {x + 1:.9g} {y:.9g} {z:.9g}\n" for x, y, z in X)
    text += "".join("f " + " ".join(str(i + 1) for i in p) + "\n" for p in panels)
    other.write_text(text)
    out = tmp_path / "out"
    code = main(["strips", str(laid_out / "saddle.obj"), "--height", "100", "--thickness", "6",
                 "--boundary", str(other), "-o", str(out), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and not out.exists()
    assert len(err) == 1 and "other.boundary.obj" in err[0] and "not the net" in err[0]


@pytest.mark.slow
def test_the_api_runs_a_glide_results_strips_to_its_edge():
    import fabplan

    design = fabplan.load_design("paraboloid", triangles=4000)
    result = fabplan.glide(fabplan.layout_surface(design, 1.0), "snet")
    assert result.boundary_panels is not None
    to_edge = fabplan.plan_strips(result, height_mm=HEIGHT, thickness_mm=THICKNESS).summary()
    at_net = fabplan.plan_strips(result, boundary=None, height_mm=HEIGHT,
                                 thickness_mm=THICKNESS).summary()
    assert to_edge["ends_at_boundary_member"] > 0 and at_net["ends_at_boundary_member"] == 0
    # every open end either meets the member or stays free
    assert to_edge["ends_at_boundary_member"] + to_edge["ends_free"] == at_net["ends_free"]


# ----------------------------------------------------------------------------- a synthetic ring
def _ringed_grid(n: int = 4, radius: float = 300.0, open_side: bool = False):
    """A net of n x n quads on a sphere cap (1 m spacing) and a ring of boundary panels one
    quad wide around it (none along y = max with `open_side`): (net, vertices, panels)."""
    from fabplan.net.mesh import QuadMesh

    m = n + 3
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    x, y = i - (m - 1) / 2, j - (m - 1) / 2
    P = np.stack([x, y, np.sqrt(radius ** 2 - x * x - y * y) - radius], -1).reshape(-1, 3).astype(float)
    inner = ((i >= 1) & (i <= m - 2) & (j >= 1) & (j <= m - 2)).ravel()
    ids = np.empty(m * m, np.int64)
    ids[inner] = np.arange(inner.sum())
    ids[~inner] = inner.sum() + np.arange((~inner).sum())
    V = np.zeros_like(P)
    V[ids] = P
    ids = ids.reshape(m, m)
    faces, panels = [], []
    for a in range(m - 1):
        for b in range(m - 1):
            q = [ids[a, b], ids[a + 1, b], ids[a + 1, b + 1], ids[a, b + 1]]
            if all(v < inner.sum() for v in q):
                faces.append(q)
            elif not (open_side and b == m - 2):
                panels.append(q)
    net = QuadMesh(V[:inner.sum()], [np.array(f) for f in faces])
    return net, V, [np.array(p) for p in panels]


def _strips(net, V, panels, **settings):
    from fabplan.fabricate.strips import StripSettings, build_strips
    from fabplan.fabricate.strips.strip_boundary import StripBoundary

    options = dict(height_mm=60.0, thickness_mm=THICKNESS)
    options.update(settings)
    return build_strips(net, StripSettings(**options), StripBoundary(net, V, panels))


def test_every_line_of_a_ringed_net_runs_one_panel_on_to_the_member():
    net, V, panels = _ringed_grid()
    strips = _strips(net, V, panels)
    s = strips.summary()
    assert s["strips"] == 10 and s["boundary_nodes"] == 20 and s["ends_not_continued"] == 0
    assert s["ends_at_boundary_member"] == 20 and s["strips_along_edge"] == 0
    for strip in strips.strips:
        assert strip.boundary_nodes == (1, 1)
        # square to the straight edge: (m / 2) / sin 90 + (t / 2) / tan 90 = 3 mm
        assert strip.end_angle_deg == pytest.approx((90.0, 90.0), abs=0.5)
        assert strip.end_setback_mm == pytest.approx((3.0, 3.0), abs=0.05)
        assert strip.length_mm == pytest.approx(6000.0, rel=1e-3)      # 4 bays + 2 panels


def test_a_panel_wrapping_a_net_corner_leaves_the_corner_inside():
    # the three ring panels at a corner of the net as one L-shaped panel: a reflex corner
    net, V, panels = _ringed_grid()
    at = [p for p in panels if 0 in p]
    rest = [p for p in panels if 0 not in p]
    import shapely

    union = shapely.union_all([shapely.Polygon(V[p][:, :2]) for p in at])
    ring = np.asarray(union.exterior.coords)[:-1]
    wrap = np.array([int(np.argmin(np.linalg.norm(V[:, :2] - xy, axis=1))) for xy in ring])
    from fabplan.fabricate.strips.strip_boundary import StripBoundary

    assert not StripBoundary(net, V, rest + [wrap]).on_edge[0]
    assert StripBoundary(net, V, rest + [wrap]).on_edge[wrap[wrap >= net.vertex_count]].sum() >= 4


def test_a_line_along_the_edge_is_the_members_place_and_a_thick_member_is_refused():
    net, V, panels = _ringed_grid(open_side=True)
    strips = _strips(net, V, panels)
    s = strips.summary()
    assert s["strips_along_edge"] == 1 and s["strips"] == 9
    from fabplan.errors import InputError

    with pytest.raises(InputError, match="boundary-member"):
        _strips(net, V, panels, boundary_member_mm=6000.0)


def test_a_member_that_eats_the_last_panel_is_questioned(laid_out, tmp_path, capsys):
    """A boundary member given in the wrong units (1000 mm) sets the ends back by more than
    half their last edge: the command warns, naming the option and its unit."""
    common = ["--height", str(HEIGHT), "--thickness", str(THICKNESS), "--no-previews", "-q"]
    assert main(["strips", str(laid_out / "saddle.obj"), *common, "--boundary-member", "1000",
                 "-o", str(tmp_path / "thick")]) == 0
    err = capsys.readouterr().err
    assert "by the 1000 mm boundary member: is it that thick?" in err
    assert "--boundary-member is in mm" in err and "nearly along each other" not in err
    summary = _record(tmp_path / "thick")["summary"]
    assert summary["ends_set_back_past_half_an_edge"] > 0 and summary["ends_set_back_at_tips"] == 0
    assert summary["member_setback_max_mm"] >= 500.0
    assert _record(laid_out / "to-edge")["summary"]["ends_set_back_past_half_an_edge"] == 0


def test_ends_cut_back_where_two_strips_meet_the_edge_together_are_not_blamed_on_the_member(
        tmp_path, capsys):
    """Where two lines of a net end at one node of the edge nearly along each other, each
    strip is cut back to clear the other (344 mm here, with a 6 mm member): the warning
    said "the 6 mm boundary member sets 4 strip ends back ...: is it that thick?"."""
    from pathlib import Path

    data = Path(__file__).parent / "data"
    for name in ("strip-tips.obj", "strip-tips.boundary.obj"):
        (tmp_path / name).write_bytes((data / name).read_bytes())
    assert main(["strips", str(tmp_path / "strip-tips.obj"), "--height", str(HEIGHT),
                 "--thickness", str(THICKNESS), "--no-previews", "-q",
                 "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    summary = _record(tmp_path / "out")["summary"]
    past = summary["ends_set_back_past_half_an_edge"]
    assert past > 0 and summary["ends_set_back_at_tips"] == past
    assert summary["member_setback_max_mm"] > 100.0
    assert (f"{past} strip ends are set back by more than half their last edge" in err
            and "nearly along each other" in err and "is it that thick" not in err)


def test_member_ends_lie_on_the_edge_also_without_the_layouts_record(laid_out, tmp_path):
    """Given as --boundary FILE, the panels come without NET.json's record of the points on
    the design boundary; the edge is then found from the polygons alone (a notch of one
    panel is no point of it), and every member end still lies on the design's edge."""
    common = ["--height", str(HEIGHT), "--thickness", str(THICKNESS), "--no-previews", "-q"]
    assert main(["strips", str(laid_out / "saddle.obj"), *common, "--boundary",
                 str(laid_out / "saddle.boundary.obj"), "-o", str(tmp_path / "file")]) == 0
    X, _ = read_obj(laid_out / "saddle.boundary.obj")
    edge = _design_edge(6000)
    rec = _record(tmp_path / "file")
    assert rec["summary"]["ends_at_boundary_member"] > 0
    for strip in rec["strips"]:
        v = strip["vertices"]
        for side, end in ((0, v[0]), (1, v[-1])):
            setback = strip["end_setback_mm"][side]
            if setback is not None and setback > 0:      # not a hair end running on
                assert _to_edge(X[end], edge)[0] < 0.016, (strip["strip"], side)
