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


@pytest.fixture(scope="module")
def laid_out(tmp_path_factory):
    """An S-net layout of a paraboloid with its boundary panels, and its strips run to
    the edge and not."""
    root = tmp_path_factory.mktemp("strip-boundary")
    net = root / "saddle.obj"
    assert main(["layout", "paraboloid", "--net", "snet", "--panel-size", "1.0",
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
            # the end node, or where the strip runs on straight to (a hair beyond it), lies
            # on the design's edge, at the angle reported
            reach = (0.5 * THICKNESS / math.sin(math.radians(angle)) - setback) / 1000.0
            assert reach >= -1e-12
            direction = (X[end] - X[prev]) / np.linalg.norm(X[end] - X[prev])
            gap, along = _to_edge(X[end] + reach * direction, edge)
            assert gap < 0.02, (strip["strip"], side, gap)     # 2 % of a 1 m panel
            mine = math.degrees(math.asin(min(1.0, np.linalg.norm(np.cross(direction, along)))))
            assert angle == pytest.approx(mine, abs=3.0), (strip["strip"], side)
    assert members == s_edge["ends_at_boundary_member"]


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
