"""Mold reports: every panel fits its mold, rechecked here independently of fabplan.

The recheck (`_recheck`) rebuilds every panel surface from the OBJ with its own loop and
least squares (the definition in docs/molds-schema.md), samples it at random points,
applies the exported 4 x 4 placement and measures the gap to the mold surface
``z = (k1 x^2 + k2 y^2) / 2`` of the exported mold: it shares no code with the assignment.
"""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import edge_midpoint_steps, measured_saddle_candidate

import fabplan
from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.fabricate.molds import MoldSettings, plan_molds
from fabplan.fabricate.molds.mold_report import explain_mold_count, mold_report_files
from fabplan.net.generate import height_field_grid
from fabplan.net.mesh import QuadMesh
from fabplan.net.weingarten import weingarten_fit
from fabplan.report.figures import isoline_segments

# the bundled Weingarten net stretched by a volume-preserving affine map: same faces, panel
# sizes and curvature range, but k1 and k2 no longer tied by a relation (an "ellipsoidal" net)
STRETCH = np.array([0.8, 1.25, 1.0])


# ----------------------------------------------------------------------------- test nets
def cylinder_helical(radius: float = 5.0, n: int = 16, step: float = 0.5) -> QuadMesh:
    """A net of helices on a cylinder: its quads are twisted, the surface single curved."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    theta = (i + j) * step / radius
    height = (i - j) * step
    pts = np.stack([radius * np.cos(theta), radius * np.sin(theta), height], axis=-1)
    return QuadMesh.grid(pts, name="cylinder-helices")


def cylinder_rulings(radius: float = 5.0, n: int = 12, step: float = 0.6) -> QuadMesh:
    """Rulings and circles on a cylinder: flat rectangular quads on a single curved surface."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    theta = i * step / radius
    pts = np.stack([radius * np.cos(theta), radius * np.sin(theta), j * step], axis=-1)
    return QuadMesh.grid(pts, name="cylinder-rulings")


def planar_quad_net() -> QuadMesh:
    """A translational surface z = f(x) + g(y) on an axis-aligned grid: every quad is a flat
    parallelogram, the surface is doubly curved."""
    return height_field_grid(14, 12, lambda x, y: 0.03 * x**2 + 0.8 * np.sin(y / 3.0), spacing=1.0)


def sphere_patch(radius: float = 10.0, n: int = 12) -> QuadMesh:
    """Latitude-longitude quads on a sphere: all panels have the same curvature."""
    t, p = np.meshgrid(np.linspace(0.35 * np.pi, 0.65 * np.pi, n),
                       np.linspace(0.0, 0.5 * np.pi, n), indexing="ij")
    pts = radius * np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return QuadMesh.grid(pts, name="sphere-patch")


# ----------------------------------------------------------------------------- recheck
def _panel_surface(X: np.ndarray, faces: list, i: int, neighbours: set, model: str):
    """Face frame, scale and coefficients of panel i, straight from the definition."""
    face = faces[i]
    C = X[face]
    origin = C.mean(axis=0)
    n = np.zeros(3)
    for a, b in zip(C, np.roll(C, -1, axis=0), strict=True):
        n += np.cross(a, b)
    n /= np.linalg.norm(n)
    u = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    frame = np.stack([u, np.cross(n, u), n])
    scale = math.sqrt(np.mean(np.sum((C - origin) ** 2, axis=1)))
    ids = sorted(set(face.tolist()) | (neighbours if model == "local_fit" else set()))
    w = np.array([1e6 if v in set(face.tolist()) else 1.0 for v in ids])
    x, y, z = ((X[ids] - origin) @ frame.T / scale).T
    A = np.column_stack([np.ones_like(x), x, y, x * x / 2, x * y, y * y / 2])
    ridge = math.sqrt(1e-9 * w.sum())
    A_all = np.vstack([A * np.sqrt(w)[:, None], np.diag([0, 0, 0, ridge, ridge, ridge])])
    b_all = np.concatenate([z * np.sqrt(w), np.zeros(6)])
    coef = np.linalg.lstsq(A_all, b_all, rcond=None)[0]
    return origin, frame, scale, coef


def _held_vertices(faces: list, n: int) -> np.ndarray:
    """(n,) bool, vertices in a star: an interior vertex with four edges and four faces, or
    one of its edge neighbours (written from the docs, not from the planner)."""
    edge_faces: dict = {}
    for face in faces:
        for a, b in zip(face, np.roll(face, -1), strict=True):
            edge_faces.setdefault(frozenset((int(a), int(b))), []).append(face)
    nbrs: dict = {}
    interior = np.ones(n, bool)
    for e, fs in edge_faces.items():
        a, b = tuple(e)
        nbrs.setdefault(a, set()).add(b)
        nbrs.setdefault(b, set()).add(a)
        if len(fs) == 1:
            interior[a] = interior[b] = False
    count = np.bincount(np.concatenate(faces), minlength=n)
    held = np.zeros(n, bool)
    for v, nb in nbrs.items():
        if interior[v] and len(nb) == 4 and count[v] == 4:
            held[v] = True
            held[list(nb)] = True
    return held


def _lift(surface, p: np.ndarray) -> np.ndarray:
    """Points p (m, 3) moved along a face's normal onto its quadric (origin, frame, scale, coef)."""
    origin, frame, scale, coef = surface
    x, y, z = ((p - origin) @ frame.T / scale).T
    h = coef[0] + coef[1] * x + coef[2] * y + 0.5 * (coef[3] * x * x + 2 * coef[4] * x * y
                                                    + coef[5] * y * y)
    return p + ((h - z) * scale)[:, None] * frame[2]


def _fit_quadric(points: np.ndarray, weight: np.ndarray, frame_of) -> tuple:
    """Weighted least-squares quadric of points in the frame of a face (origin, frame,
    scale, _)."""
    origin, frame, scale, _ = frame_of
    x, y, z = ((points - origin) @ frame.T / scale).T
    A = np.column_stack([np.ones_like(x), x, y, x * x / 2, x * y, y * y / 2])
    w = np.sqrt(weight)
    return origin, frame, scale, np.linalg.lstsq(A * w[:, None], z * w, rcond=None)[0]


def _shared_points(X, face, local, across, a, b, j) -> np.ndarray:
    """Points of a ``shared`` panel (docs/molds-schema.md) at corner weights (a, b) of the
    fan triangles (centre, corner j, corner j+1): its own quadric through its corners and
    near its edges, bent onto them; an edge is the mean of its two faces' local quadrics
    over the chord."""
    k = len(face)
    C = X[face]

    def edge(jj, tau):
        chord = C[jj] + tau[:, None] * (C[(jj + 1) % k] - C[jj])
        out = np.empty_like(chord)
        for e in range(k):
            at = jj == e
            out[at] = 0.5 * (_lift(local[0], chord[at]) + _lift(across[e], chord[at]))
        return out

    tau8 = np.arange(8) / 8
    outline = np.vstack([edge(np.full(8, jj), tau8) for jj in range(k)])
    base = _fit_quadric(outline, np.tile(np.r_[1e6, np.ones(7)], k), local[0])   # through the corners
    origin, frame, scale, _ = base
    P = ((C - origin) @ frame.T / scale)[:, :2]

    def on_base(xy):
        p = origin + scale * np.column_stack([xy, np.zeros(len(xy))]) @ frame
        return _lift(base, p)

    w = a + b
    tau = np.where(w > 0, b / np.maximum(w, 1e-300), 0.0)
    inner = on_base(a[:, None] * P[j] + b[:, None] * P[(j + 1) % k])
    chord_on_base = on_base((1 - tau)[:, None] * P[j] + tau[:, None] * P[(j + 1) % k])
    return inner + w[:, None] * (edge(j, tau) - chord_on_base)


def _recheck(record: dict, mesh: QuadMesh, samples: int = 40, seed: int = 7) -> np.ndarray:
    """Largest gap of every panel from its exported mold, computed from scratch (mm)."""
    rng = np.random.default_rng(seed)
    X, faces = mesh.vertices, mesh.faces
    held = _held_vertices(faces, len(X))
    held |= not held.any()                      # a net without stars: every vertex counts
    at_vertex: dict = {}
    at_edge: dict = {}
    for f, face in enumerate(faces):
        for v in face:
            at_vertex.setdefault(int(v), []).append(f)
        for u, v in zip(face, np.roll(face, -1), strict=True):
            at_edge.setdefault(frozenset((int(u), int(v))), []).append(f)
    model = record["panel_surface"]
    fitted = "local_fit" if model == "shared" else model

    def surface_of(i):
        # vertices in no star are no neighbours of a local fit (docs/molds-schema.md)
        neighbours = {int(v) for c in faces[i] for f in at_vertex[int(c)] for v in faces[f]
                      if held[v]} | {int(v) for v in faces[i]}
        return _panel_surface(X, faces, i, neighbours, fitted)

    local = [surface_of(i) for i in range(len(faces))]
    molds = {m["id"]: m for m in record["molds"]}
    mm = record["mm_per_unit"]
    gaps = np.zeros(len(faces))
    for panel in record["panels"]:
        i = panel["face"]
        face = faces[i]
        k = len(face)
        # random points in the fan triangles (centre, corner j, corner j+1), plus the corners
        j = np.concatenate([rng.integers(0, k, samples), np.arange(k)])
        a, b = rng.random(samples), rng.random(samples)
        flip = a + b > 1
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        a, b = np.concatenate([a, np.ones(k)]), np.concatenate([b, np.zeros(k)])
        if model == "shared":
            across = [local[next((f for f in at_edge[frozenset((int(face[jj]), int(face[(jj + 1) % k])))]
                                  if f != i), i)] for jj in range(k)]
            P = _shared_points(X, face, [local[i]], across, a, b, j)
        else:
            origin, frame, scale, coef = local[i]
            corners = ((X[face] - origin) @ frame.T / scale)[:, :2]
            xy = a[:, None] * corners[j] + b[:, None] * corners[(j + 1) % k]
            P = _lift(local[i], origin + scale * np.column_stack([xy, np.zeros(len(xy))]) @ frame)
        M = np.array(panel["placement"])
        R = M[:3, :3] / mm
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0
        q = P @ M[:3, :3].T + M[:3, 3]
        mold = molds[panel["mold"]]
        gaps[i] = np.abs(q[:, 2] - 0.5 * (mold["k1"] * q[:, 0] ** 2 + mold["k2"] * q[:, 1] ** 2)).max()
    return gaps


def _assert_every_panel_fits(record: dict, mesh: QuadMesh) -> None:
    tol = record["tolerance_mm"]
    gaps = _recheck(record, mesh)
    assert record["failures"] == []
    # fits_all also asks that neighbours meet: no step over twice the tolerance
    assert record["fits_all"] == (not record["panel_steps"]["over_limit"])
    assert gaps.max() <= tol + 1e-6, (gaps.max(), int(gaps.argmax()))
    reported = np.array([p["deviation_mm"] for p in record["panels"]])
    assert reported.max() <= tol
    # the report measures the same gaps: random samples never exceed the dense ones by more
    # than what lies between samples
    assert np.all(gaps <= reported + 0.01 * tol)
    assert record["panel_count"] == len(mesh.faces) == len(record["panels"])
    counts = np.bincount([p["mold"] for p in record["panels"]], minlength=record["mold_count"])
    assert [m["panel_count"] for m in record["molds"]] == counts.tolist()
    assert counts.min() >= 1


# ----------------------------------------------------------------------------- Weingarten net
@pytest.fixture(scope="module")
def wein99_run(wein99_molds):
    """`fabplan molds wein99.obj --tolerance-mm 5 -q`, the session's shared run
    (tests/conftest.py; the bundled net is in metres, as its record says). Read only."""
    return wein99_molds


def test_wein99_needs_at_most_sqrt_n_molds_and_every_panel_fits(wein99_run, wein99):
    code, out = wein99_run
    assert code == 0
    record = json.loads((out / "molds.json").read_text())
    n = record["panel_count"]
    assert n == 1601 and record["units"] == "m" and record["tolerance_mm"] == 5.0
    assert record["mold_count"] <= math.sqrt(n)
    assert record["molds_per_sqrt_panels"] == pytest.approx(record["mold_count"] / math.sqrt(n))
    assert record["panel_surface"] == "shared" and record["reassigned_by_verification"] == []
    assert sum(record["panel_types"].values()) == n
    # the panels' curvatures lie on a line a k1 + b k2 = c: a thin band of their spread
    assert record["weingarten"]["thickness"] < 0.05
    for mold in record["molds"]:
        if mold["type"] == "paraboloid":
            assert {"k1", "k2", "size_mm", "panel_count", "max_deviation_mm"} <= set(mold)
    _assert_every_panel_fits(record, wein99)


def test_wein99_report_files_agree_and_embed_their_pictures(wein99_run):
    _, out = wein99_run
    record = json.loads((out / "molds.json").read_text())
    rows = list(csv.DictReader((out / "panels.csv").read_text().splitlines()))
    assert len(rows) == record["panel_count"]
    for row, panel in zip(rows[::97], record["panels"][::97], strict=True):
        assert int(row["mold"]) == panel["mold"]
        assert float(row["deviation_mm"]) == pytest.approx(panel["deviation_mm"], abs=1e-4)
        matrix = np.array([float(row[f"m{r}{c}"]) for r in range(4) for c in range(4)])
        assert np.allclose(matrix.reshape(4, 4), panel["placement"], rtol=1e-10, atol=1e-6)
    page = (out / "report.html").read_text()
    assert page.count('<img src="data:image/png;base64,') == 5      # with the step map
    # nothing fetched: no address in an attribute or a style (the vendored three.js names
    # the XHTML namespace in a string, which is no fetch)
    fetched = r"(?:src|href|action)\s*=\s*[\"']?(?:https?:)?//|url\(\s*[\"']?(?:https?:)?//"
    assert re.search(fetched, page) is None
    assert f"{record['mold_count']} molds" in page and "one-parameter family" in page


# ----------------------------------------------------------------------------- not Weingarten
@pytest.mark.slow
def test_a_freeform_of_the_same_size_needs_several_times_the_molds(wein99_run, wein99):
    wein = json.loads((wein99_run[1] / "molds.json").read_text())
    freeform = wein99.with_vertices(wein99.vertices * STRETCH)
    plan = plan_molds(freeform, tolerance_mm=5.0, units="m")
    record = plan.record()
    assert record["panel_count"] == wein["panel_count"]
    assert record["mold_count"] >= 3 * wein["mold_count"]
    assert record["weingarten"]["thickness"] > 5 * wein["weingarten"]["thickness"]
    assert "fill a region" in explain_mold_count(plan)
    _assert_every_panel_fits(record, freeform)


# ----------------------------------------------------------------------------- panel types
def test_a_planar_quad_net_has_only_planar_panels_and_no_curved_mold():
    net = planar_quad_net()
    record = plan_molds(net, tolerance_mm=2.0, units="m").record()
    assert record["panel_surface"] == "corners"
    assert record["panel_types"] == {"planar": len(net.faces), "single_curved": 0, "double_curved": 0}
    assert record["mold_count"] == 1 and record["curved_mold_count"] == 0
    assert record["molds"][0]["type"] == "plane" and record["max_deviation_mm"] < 1e-6
    _assert_every_panel_fits(record, net)


def test_a_cylinder_has_single_curved_panels_on_cylinder_molds_of_its_radius():
    net = cylinder_helical(radius=5.0)
    plan = plan_molds(net, tolerance_mm=1.0, units="m")
    record = plan.record()
    assert record["panel_surface"] == "shared"
    assert record["panel_types"]["single_curved"] == len(net.faces)
    assert record["mold_types"] == {"plane": 0, "cylinder": record["mold_count"], "paraboloid": 0}
    for mold in record["molds"]:
        assert mold["k2"] == 0.0 and mold["radius1_mm"] == pytest.approx(5000.0, rel=0.05)
    # the panels' own curvatures: 1/R across the helices' bisector, 0 along the rulings
    k = np.abs(plan.curvature * 1000.0)
    assert np.allclose(np.max(k, axis=1), 0.2, rtol=0.02) and np.max(np.min(k, axis=1)) < 0.005
    _assert_every_panel_fits(record, net)


def test_flat_faces_on_a_cylinder_are_planar_unless_the_smooth_surface_is_asked_for():
    net = cylinder_rulings()
    flat = plan_molds(net, tolerance_mm=5.0).record()
    assert flat["panel_surface"] == "corners" and flat["panel_types"]["planar"] == len(net.faces)
    local = plan_molds(net, tolerance_mm=1.0, panel_surface="local_fit").record()
    assert local["panel_types"]["single_curved"] == len(net.faces)
    _assert_every_panel_fits(local, net)


def test_panels_of_one_curvature_share_one_mold_in_any_orientation():
    net = sphere_patch(radius=10.0)
    record = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="local_fit").record()
    assert record["panel_types"]["double_curved"] == len(net.faces)
    assert record["mold_count"] == 1
    k1, k2 = record["molds"][0]["k1"], record["molds"][0]["k2"]
    # a paraboloid mold evens out its difference from the sphere (k^3 r^4 / 8) over the panels
    assert abs(k1) == pytest.approx(1e-4, rel=0.03) and k2 == pytest.approx(k1, rel=0.03)
    _assert_every_panel_fits(record, net)


def test_units_in_millimetres_give_the_same_molds():
    net = cylinder_helical(radius=5.0, n=8)
    in_m = plan_molds(net, tolerance_mm=1.0, units="m").record()
    in_mm = plan_molds(net.with_vertices(net.vertices * 1000.0), tolerance_mm=1.0, units="mm").record()
    assert in_mm["mold_count"] == in_m["mold_count"]
    assert [m["k1"] for m in in_mm["molds"]] == pytest.approx([m["k1"] for m in in_m["molds"]], rel=1e-6)
    # the same motion: metres are scaled to millimetres by the placement itself
    to_mm = np.diag([1000.0, 1000.0, 1000.0, 1.0])
    assert np.allclose([np.array(p["placement"]) @ to_mm for p in in_mm["panels"]],
                       [p["placement"] for p in in_m["panels"]], atol=1e-6)


def test_plans_are_deterministic():
    net = cylinder_helical(radius=4.0, n=10)
    a = plan_molds(net, tolerance_mm=0.5).record()
    b = plan_molds(net, tolerance_mm=0.5).record()
    a.pop("seconds"), b.pop("seconds")
    assert a == b


@pytest.mark.slow
def test_panels_the_coarse_assignment_misjudged_are_caught_by_the_dense_verification():
    # assignment on corners and centres only, no reserve: some panels are more curved than
    # those samples show; the verification must classify them again and give them molds
    net = height_field_grid(12, 12, lambda x, y: 0.05 * x * x + 0.3 * np.sin(y / 2) + 0.02 * x * y,
                            rotation_deg=25.0)
    coarse = plan_molds(net, settings=MoldSettings(tolerance_mm=1.0, cover_level=1, reserve=0.0,
                                                   panel_surface="local_fit"))
    fine = plan_molds(net, tolerance_mm=1.0, panel_surface="local_fit")
    assert np.array_equal(coarse.panel_type, fine.panel_type)
    assert coarse.reassigned.size > 0 and fine.reassigned.size == 0
    assert coarse.mold_count >= fine.mold_count
    _assert_every_panel_fits(coarse.record(), net)


# ----------------------------------------------------------------------------- failures
@pytest.mark.slow
def test_panels_larger_than_the_largest_mold_are_reported_not_hidden(tmp_path, capsys):
    net_path = tmp_path / "cyl.obj"
    cylinder_helical(radius=5.0, n=6).write_obj(net_path)
    out = tmp_path / "report"
    code = main(["molds", str(net_path), "--tolerance-mm", "1", "--max-mold-size", "600",
                 "-o", str(out)])
    _, err = capsys.readouterr()
    assert code == 3 and "fit no mold" in err and "--max-mold-size" in err
    record = json.loads((out / "molds.json").read_text())
    assert not record["fits_all"] and len(record["failures"]) == record["panel_count"]
    assert all("larger than the largest mold" in p["problem"] for p in record["panels"])
    assert "do not fit" in (out / "report.html").read_text()


def _degenerate_obj(path: Path) -> None:
    # face 1 is a quad with its corners on one line; the mesh is manifold otherwise
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nv 0 1 0\nv 1 1 0\nv 4 0 0\n"
                    "f 1 2 6 5\nf 2 3 4 7\n")


@pytest.mark.parametrize("case, fragment", [
    ("no-faces", "no faces"),
    ("degenerate", "face 1 is degenerate"),
    ("zero-tolerance", "--tolerance-mm 0: must be at least 0.01 mm"),
    ("negative-tolerance", "--tolerance-mm -1: must be at least 0.01 mm"),
    ("nan-tolerance", "--tolerance-mm nan: must be a finite number"),
    ("units", "read in centimetres: implausible for a building; if the file is in metres, give "
              "--units m (--strict-units)"),
    ("mold-size", "--max-mold-size 0: must be at least 1 mm"),
    ("missing", "no such file"),
])
def test_bad_input_is_refused_in_one_line_and_writes_nothing(tmp_path, capsys, case, fragment):
    net = tmp_path / "net.obj"
    cylinder_helical(n=4).write_obj(net)
    args = ["--tolerance-mm", "5"]
    if case == "no-faces":
        net.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    elif case == "degenerate":
        _degenerate_obj(net)
    elif case.endswith("tolerance"):
        args = ["--tolerance-mm", {"zero-tolerance": "0", "negative-tolerance": "-1",
                                   "nan-tolerance": "nan"}[case]]
    elif case == "units":
        args += ["--units", "cm", "--strict-units"]
    elif case == "mold-size":
        args += ["--max-mold-size", "0"]
    elif case == "missing":
        net = tmp_path / "absent.obj"
    out = tmp_path / "out"
    code = main(["molds", str(net), *args, "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.err.startswith("fabplan: error: ") and captured.err.count("\n") == 1
    assert fragment in captured.err and "Traceback" not in captured.err
    assert captured.out == ""
    assert not out.exists()


def test_the_python_api_refuses_bad_settings_with_input_errors():
    net = cylinder_helical(n=4)
    with pytest.raises(InputError, match="unknown panel surface"):
        plan_molds(net, tolerance_mm=1.0, panel_surface="wavy")
    with pytest.raises(InputError, match="tolerance"):
        plan_molds(net, settings=MoldSettings(tolerance_mm=-2.0))
    sliver = QuadMesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0], [1, 1, 0]]),
                      np.array([[0, 1, 2], [0, 3, 1]]), name="sliver")
    with pytest.raises(InputError, match="sliver: face 0 is degenerate"):
        plan_molds(sliver, tolerance_mm=1.0)


def test_report_files_can_be_built_in_memory_for_other_reports():
    plan = plan_molds(sphere_patch(n=5), tolerance_mm=1.0, panel_surface="local_fit")
    files = mold_report_files(plan, "somewhere")
    assert sorted(p.name for p in files) == ["molds.json", "panels.csv", "report.html"]
    assert json.loads(files[Path("somewhere") / "molds.json"])["mold_count"] == plan.mold_count


# ----------------------------------------------------------------------------- pieces
def test_weingarten_fit_tells_a_curve_from_a_cloud():
    t = np.linspace(-1.0, 1.0, 200)
    line = weingarten_fit(0.3 + 0.2 * t, -0.1 - 0.15 * t)
    assert line["line_residual_max"] < 1e-12 and line["thickness"] < 1e-10
    a, b, c = line["line"]["a"], line["line"]["b"], line["line"]["c"]
    assert a * 0.3 + b * -0.1 == pytest.approx(c) and a * a + b * b == pytest.approx(1.0)
    rng = np.random.default_rng(0)
    cloud = weingarten_fit(rng.random(500), rng.random(500))
    assert cloud["thickness"] > 0.8
    circle = weingarten_fit(np.cos(3 * t), np.sin(3 * t))  # a curve, but not a line
    assert circle["conic_residual_rms"] < 1e-9 < circle["line_residual_rms"]
    assert weingarten_fit(np.ones(2), np.ones(2))["thickness"] is None


def test_isolines_of_a_linear_function_are_straight_and_at_their_level():
    net = height_field_grid(6, 6, lambda x, y: 0 * x)
    X = net.vertices
    seg, _, level = isoline_segments(X, net.triangles(), X[:, 0] + 0.5 * X[:, 1],
                                     np.array([-1.0, 0.25, 1.5]))
    values = seg[..., 0] + 0.5 * seg[..., 1]
    assert np.allclose(values, np.array([-1.0, 0.25, 1.5])[level][:, None])
    assert len(np.unique(level)) == 3


def test_a_looser_tolerance_never_needs_more_molds():
    """Regression: at 5 mm some saddle panels pass as single curved and got a cylinder
    mold of their own beside the paraboloid mold that fits them all (2 molds at 5 mm,
    1 at 2 mm). Curved molds whose panels all fit another curved mold are dropped."""
    from fabplan.design.load import load_design
    from fabplan.layout.surface_layout import glide, layout_surface

    design = load_design("hyperbolic-paraboloid:width=6,depth=6,rise=1.5", triangles=4000)
    net = glide(layout_surface(design, 1.0, angle=90.0), "snet").mesh
    plans = {t: plan_molds(net, tolerance_mm=t, units="m") for t in (2.0, 5.0)}
    assert (plans[5.0].panel_type == 1).any()              # the case the merge is for
    assert plans[5.0].mold_count <= plans[2.0].mold_count
    for t, plan in plans.items():
        assert plan.fits_all and plan.deviation_mm.max() <= t


# ----------------------------------------------------------------------------- steps
def test_neighbouring_panels_meet_on_wein99_rechecked_from_the_export(wein99_run, wein99):
    record = json.loads((wein99_run[1] / "molds.json").read_text())
    steps = record["panel_steps"]
    mine = edge_midpoint_steps(record, wein99)
    assert steps["edge_count"] == len(mine) == len(wein99.interior_edges)
    # the plan measures at the quarter points too: never less than the midpoints show
    assert mine.max() <= steps["max_mm"] + 1e-6
    assert steps["max_mm"] <= 2 * record["tolerance_mm"] and steps["over_limit"] == []
    assert record["mold_count"] <= 21 and record["fits_all"]
    bound = record["mold_count_bound"]
    assert 1 <= bound["molds"] <= record["mold_count"]


def test_a_step_over_twice_the_tolerance_fails_the_plan():
    # a twisted surface whose twist grows across it, at 1 mm on 2 m panels: every panel
    # quadric fits a mold, but neighbouring molds step apart by more than 2 mm
    net = height_field_grid(8, 8, lambda x, y: 0.002 * x * x * y + 0.01 * x * y, spacing=2.0)
    plan = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="local_fit")
    record = plan.record()
    mine = edge_midpoint_steps(record, net)
    assert record["failures"] == []
    assert mine.max() > 2.0 and not record["fits_all"]
    over = record["panel_steps"]["over_limit"]
    assert over and over[0]["step_mm"] == pytest.approx(record["panel_steps"]["max_mm"])
    assert {tuple(sorted(o["faces"])) for o in over} <= {
        tuple(sorted(p)) for p in net.interior_edge_faces.tolist()}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_shared_panels_meet_wherever_they_fit_their_molds(seed):
    # seeded cubic height fields, 1.5-2.5 m panels at 1 mm: with panels of one surface,
    # neighbours share their edges, so two panels that fit their molds step apart by at
    # most their two gaps; where no quadric mold takes a panel, it is reported as a failure
    rng = np.random.default_rng(seed)
    c = rng.normal(0, 1, 7) * np.array([0.03, 0.03, 0.03, 0.002, 0.002, 0.002, 0.002])
    net = height_field_grid(8, 7, lambda x, y: c[0] * x * x + c[1] * x * y + c[2] * y * y + c[3] * x ** 3
                            + c[4] * x * x * y + c[5] * x * y * y + c[6] * y ** 3,
                            spacing=rng.uniform(1.5, 2.5))
    record = plan_molds(net, tolerance_mm=1.0, units="m").record()
    assert record["panel_surface"] == "shared"
    gaps = _recheck(record, net)
    fits = gaps <= 1.0 + 1e-6
    assert set(np.flatnonzero(~fits)) <= set(record["failures"])
    step, faces = edge_midpoint_steps(record, net, with_faces=True)
    both = fits[faces].all(axis=1)
    assert both.any() and step[both].max() <= 2.0 * 1.02
    assert record["fits_all"] == (not record["failures"] and not record["panel_steps"]["over_limit"])


def test_a_study_limits_the_step_between_neighbouring_panels():
    from fabplan.study.run import verdict
    from fabplan.study.spec import Limits

    _, plan, metrics = measured_saddle_candidate(1.0)
    step = metrics["molds"]["max_panel_step_mm"]
    assert step == plan.max_step_mm > 0
    assert metrics["molds"]["panel_steps_over"] == plan.steps_over.size

    def check(limit):
        limits = Limits(max_deviation_mm=1e9, mold_tolerance_mm=1.0, max_panel_step_mm=limit)
        return next(c for c in verdict(metrics, limits) if c["limit"] == "max_panel_step_mm")

    assert check(None)["bound"] == 2.0             # not given: twice the mold tolerance
    assert check(step * 1.01)["ok"] and not check(step * 0.99)["ok"]
    assert f"{step:.2f} mm" in check(step * 0.99)["text"]


def test_panels_of_a_net_on_an_exact_design_are_its_patches():
    design = fabplan.load_design("torus", triangles=6000)
    net = fabplan.glide(fabplan.layout_surface(design, 1.0), "snet").mesh
    record = plan_molds(net, tolerance_mm=1.0, units="m", design=design).record()
    assert record["panel_surface"] == "design" and record["failures"] == []
    assert plan_molds(net, tolerance_mm=1.0, units="m").record()["panel_surface"] == "shared"
    # rechecked apart from the planner: random points of every face, moved onto the exact
    # design (its own closest points), against the exported mold and placement
    rng = np.random.default_rng(3)
    molds = {m["id"]: m for m in record["molds"]}
    worst = 0.0
    for panel in record["panels"]:
        corners = net.vertices[net.faces[panel["face"]]]
        centre = corners.mean(axis=0)
        j = rng.integers(0, len(corners), 30)
        a, b = rng.random(30), rng.random(30)
        flip = a + b > 1
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        p = centre + a[:, None] * (corners[j] - centre) \
            + b[:, None] * (corners[(j + 1) % len(corners)] - centre)
        q = design.closest_points(p) @ np.array(panel["placement"])[:3, :3].T \
            + np.array(panel["placement"])[:3, 3]
        mold = molds[panel["mold"]]
        gap = np.abs(q[:, 2] - 0.5 * (mold["k1"] * q[:, 0] ** 2 + mold["k2"] * q[:, 1] ** 2))
        worst = max(worst, float(gap.max()))
    assert worst <= 1.02 * record["tolerance_mm"]
    # patches of one surface: the molds of neighbours meet within twice the tolerance
    steps = edge_midpoint_steps(record, net)
    assert steps.max() <= record["panel_steps"]["max_mm"] + 1e-6 <= 2 * record["tolerance_mm"]
    assert record["panel_steps"]["panel_surfaces_max_mm"] == 0.0


def test_a_net_off_its_design_is_not_cut_from_it():
    """`auto` cuts a net's panels from the design given only where the net lies on it: a
    study's linear Weingarten net 13 mm off its saddle got 41 molds cut from the saddle
    with `--design`, against the 2 of its own surface the study had planned."""
    from fabplan.net.mesh import QuadMesh

    design = fabplan.load_design("torus", triangles=6000)
    net = fabplan.glide(fabplan.layout_surface(design, 1.0), "snet").mesh
    faces = np.asarray(net.faces)
    X = net.vertices
    normals = np.zeros_like(X)
    np.add.at(normals, faces.ravel(), np.repeat(np.cross(X[faces[:, 2]] - X[faces[:, 0]],
                                                         X[faces[:, 3]] - X[faces[:, 1]]), 4, axis=0))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)

    def lifted(mm):
        return QuadMesh(X + mm / 1000 * normals, faces)

    # the net glides on the design's triangles, off its exact surface by their chord error
    off = lifted(8.0)        # the tolerance 1 mm
    assert design.distances(off.vertices).max() > 0.001 + design.chord_error
    assert plan_molds(off, tolerance_mm=1.0, units="m", design=design).record()[
        "panel_surface"] == "shared"
    # on it within the tolerance, it is
    assert plan_molds(lifted(0.5), tolerance_mm=1.0, units="m", design=design).record()[
        "panel_surface"] == "design"


def test_the_design_panel_surface_needs_an_exact_design():
    net = height_field_grid(5, 5, lambda x, y: 0.1 * x * y)
    with pytest.raises(InputError, match="built-in or NURBS"):
        plan_molds(net, tolerance_mm=1.0, panel_surface="design")


def test_a_net_without_stars_fits_its_panels_to_their_neighbours():
    # two rows of faces: no vertex is a star's, so none is left out of the fits
    net = height_field_grid(6, 2, lambda x, y: 0.05 * (x * x + y * y))
    local = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="local_fit")
    corners = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="corners")
    assert len(net.stars) == 0
    assert np.abs(local.curvature).max() > 2 * np.abs(corners.curvature).max()


def test_the_step_limit_is_a_setting_and_flat_panels_need_no_mold_by_the_bound():
    net = height_field_grid(8, 8, lambda x, y: 0.002 * x * x * y + 0.01 * x * y, spacing=2.0)
    strict = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="local_fit")
    loose = plan_molds(net, settings=MoldSettings(tolerance_mm=1.0, units="m", panel_surface="local_fit",
                                                  step_limit_mm=2 * strict.max_step_mm))
    assert strict.steps_over.size and not strict.fits_all
    assert loose.step_limit_mm == 2 * strict.max_step_mm and loose.fits_all
    assert loose.record()["panel_steps"]["limit_mm"] == loose.step_limit_mm
    with pytest.raises(InputError, match="step limit"):
        plan_molds(net, tolerance_mm=1.0, step_limit_mm=-1.0)
    flat = plan_molds(height_field_grid(4, 4, lambda x, y: 0 * x), tolerance_mm=1.0)
    assert flat.mold_count_bound() == (0.0, 0)


def test_shared_panels_are_pieces_of_one_surface():
    # a mixed net (quads and triangles) on a wavy surface: both panels of every interior edge
    # have the same points on it, the corners are the net's vertices, and the edges are
    # curves, not the chords
    from fabplan.fabricate.molds.panels import fit_panel_surfaces, shared_panel_samples

    grid = height_field_grid(6, 5, lambda x, y: 0.2 * np.sin(x) + 0.05 * x * y)
    faces = [f for f in grid.faces[:-4]]
    for f in grid.faces[-4:]:                     # split the last quads into triangles
        faces += [f[[0, 1, 2]], f[[0, 2, 3]]]
    net = QuadMesh(grid.vertices, faces)
    level = 4
    points = shared_panel_samples(net, fit_panel_surfaces(net, "local_fit"), level)
    per_side = level + 1
    fan = [(i, j) for i in range(level + 1) for j in range(level + 1) if i + j <= level]
    on_edge = [t for t, (i, j) in enumerate(fan) if i + j == level]     # from corner j to j+1
    k_max = max(len(f) for f in faces)
    edge_points = {}
    for f, face in enumerate(faces):
        P = points[f].reshape(k_max, len(fan), 3)
        for j in range(len(face)):
            a, b = int(face[j]), int(face[(j + 1) % len(face)])
            line = P[j, on_edge]
            line = line[np.argsort([fan[t][0] for t in on_edge])]   # from b to a
            assert np.allclose(line[-1], grid.vertices[a], atol=1e-6)    # corner weight 1e6
            assert np.allclose(line[0], grid.vertices[b], atol=1e-6)
            edge_points.setdefault((min(a, b), max(a, b)), []).append(line if a < b else line[::-1])
    shared = [v for v in edge_points.values() if len(v) == 2]
    assert len(shared) == len(net.interior_edges) and len(shared[0][0]) == per_side
    gap = max(np.abs(u - v).max() for u, v in shared)
    assert gap < 1e-9
    # the chord's points are not on the surface: the edges are curves
    assert max(np.abs(u[len(u) // 2] - 0.5 * (u[0] + u[-1])).max() for u, _ in shared) > 1e-3
