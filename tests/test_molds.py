"""Mold reports: every panel fits its mold and neighbours meet, rechecked here
independently of fabplan.

The recheck (`_recheck`) samples every exported panel surface (the quadric in its face
frame, docs/molds-schema.md) at random points, applies the exported 4 x 4 placement and
measures the gap to the mold surface ``z = (k1 x^2 + k2 y^2) / 2`` of the exported mold; for
the ``local_fit`` and ``corners`` models it also rebuilds the surface from the OBJ with its
own loop and least squares. `_recheck_steps` puts the midpoint of every shared edge on one
panel's mold and measures its distance from the other's. Neither shares code with the
planner.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.fabricate.mold_report import explain_mold_count, mold_report_files
from fabplan.fabricate.molds import MoldSettings, plan_molds
from fabplan.fabricate.panels import net_curvature, osculating_panel_samples
from fabplan.net.generate import height_field_grid
from fabplan.net.mesh import QuadMesh
from fabplan.net.weingarten import weingarten_fit
from fabplan.report.figures import isoline_segments

WEIN99 = fabplan.data_path("wein99.obj")
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


def _recheck(record: dict, mesh: QuadMesh, samples: int = 40, seed: int = 7) -> np.ndarray:
    """Largest gap of every panel from its exported mold, computed from scratch (mm)."""
    rng = np.random.default_rng(seed)
    X, faces = mesh.vertices, mesh.faces
    at_vertex: dict = {}
    for f, face in enumerate(faces):
        for v in face:
            at_vertex.setdefault(int(v), []).append(f)
    molds = {m["id"]: m for m in record["molds"]}
    mm = record["mm_per_unit"]
    model = record["panel_surface"]
    gaps = np.zeros(len(faces))
    for panel in record["panels"]:
        i = panel["face"]
        surface = panel["surface"]
        origin, frame = np.array(surface["origin"]), np.array(surface["frame"])
        scale, coef = surface["scale"], np.array(surface["coefficients"])
        assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-9)
        if model != "osculating":
            neighbours = {int(v) for c in faces[i] for f in at_vertex[int(c)] for v in faces[f]}
            o2, f2, s2, c2 = _panel_surface(X, faces, i, neighbours, model)
            # the same surface in another frame: compare heights along the normal
            assert np.allclose(f2[2], frame[2], atol=1e-9) and s2 == pytest.approx(scale)
        corners = ((X[faces[i]] - origin) @ frame.T / scale)[:, :2]
        # random points in the fan triangles (centre, corner j, corner j+1), plus the corners
        k = len(corners)
        j = rng.integers(0, k, samples)
        a, b = rng.random(samples), rng.random(samples)
        flip = a + b > 1
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        centre = corners.mean(axis=0)
        xy = np.vstack([a[:, None] * corners[j] + b[:, None] * corners[(j + 1) % k]
                        + (1 - a - b)[:, None] * centre, corners])
        x, y = xy.T
        z = coef[0] + coef[1] * x + coef[2] * y + 0.5 * (coef[3] * x * x + 2 * coef[4] * x * y
                                                        + coef[5] * y * y)
        if model != "osculating":
            xy2 = ((origin + scale * np.column_stack([x, y, z]) @ frame - o2) @ f2.T / s2)[:, :2]
            z2 = c2[0] + c2[1] * xy2[:, 0] + c2[2] * xy2[:, 1] + 0.5 * (
                c2[3] * xy2[:, 0] ** 2 + 2 * c2[4] * xy2[:, 0] * xy2[:, 1] + c2[5] * xy2[:, 1] ** 2)
            here = ((origin + scale * np.column_stack([x, y, z]) @ frame - o2) @ f2.T / s2)[:, 2]
            assert np.abs(here - z2).max() * s2 * mm < 0.01  # the exported surface is the fit
        P = origin + scale * np.column_stack([x, y, z]) @ frame
        M = np.array(panel["placement"])
        R = M[:3, :3] / mm
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0
        q = P @ M[:3, :3].T + M[:3, 3]
        mold = molds[panel["mold"]]
        gaps[i] = np.abs(q[:, 2] - 0.5 * (mold["k1"] * q[:, 0] ** 2 + mold["k2"] * q[:, 1] ** 2)).max()
    return gaps


def _onto_mold(p: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Closest point of the mold z = (k1 x^2 + k2 y^2) / 2 to p (3,), by the fixed point
    x = p_xy - (f(x) - p_z) grad f(x) of the closest-point condition."""
    x, y = p[0], p[1]
    for _ in range(60):
        f = 0.5 * (k1 * x * x + k2 * y * y)
        x, y = p[0] - (f - p[2]) * k1 * x, p[1] - (f - p[2]) * k2 * y
    return np.array([x, y, 0.5 * (k1 * x * x + k2 * y * y)])


def _recheck_steps(record: dict, mesh: QuadMesh) -> dict:
    """Step at the midpoint of every shared edge, both ways, from the exported placements:
    {(face a, face b): mm}."""
    mm = record["mm_per_unit"]
    molds = {m["id"]: m for m in record["molds"]}
    panels = {p["face"]: p for p in record["panels"]}
    sides: dict = {}
    for f, face in enumerate(mesh.faces):
        for a, b in zip(face, np.roll(face, -1), strict=True):
            sides.setdefault((min(a, b), max(a, b)), []).append(f)
    steps = {}
    for (a, b), fs in sides.items():
        if len(fs) != 2:
            continue
        mid = 0.5 * (mesh.vertices[a] + mesh.vertices[b])
        worst = 0.0
        for fa, fb in (fs, fs[::-1]):
            A, B = np.array(panels[fa]["placement"]), np.array(panels[fb]["placement"])
            ma, mb = molds[panels[fa]["mold"]], molds[panels[fb]["mold"]]
            on_a = _onto_mold(A[:3, :3] @ mid + A[:3, 3], ma["k1"], ma["k2"])
            model_point = np.linalg.solve(A[:3, :3], on_a - A[:3, 3])
            q = B[:3, :3] @ model_point + B[:3, 3]
            worst = max(worst, float(np.linalg.norm(q - _onto_mold(q, mb["k1"], mb["k2"]))))
        steps[tuple(sorted(fs))] = worst
    assert mm > 0
    return steps


def _assert_neighbours_meet_as_reported(record: dict, mesh: QuadMesh) -> dict:
    steps = _recheck_steps(record, mesh)
    reported = record["panel_steps"]
    assert reported["edge_count"] == len(steps)
    # the midpoint is one of the reported points: the report's largest step is at least it
    assert max(steps.values()) <= reported["max_mm"] + 1e-6
    over = {tuple(sorted(e["faces"])) for e in reported["over_limit"]}
    limit = 2 * record["tolerance_mm"]
    assert reported["limit_mm"] == limit
    assert {e for e, d in steps.items() if d > limit} <= over
    assert record["fits_all"] == (not over and not record["failures"])
    return steps


def _assert_every_panel_fits(record: dict, mesh: QuadMesh) -> None:
    tol = record["tolerance_mm"]
    gaps = _recheck(record, mesh)
    assert record["failures"] == []
    assert record["fits_all"] == (record["panel_steps"]["over_limit"] == [])
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
def wein99_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("molds") / "wein99"
    code = main(["molds", str(WEIN99), "--tolerance-mm", "5", "--units", "m", "-o", str(out)])
    return code, out


def test_wein99_needs_at_most_sqrt_n_molds_and_every_panel_fits(wein99_run, wein99):
    code, out = wein99_run
    assert code == 0
    record = json.loads((out / "molds.json").read_text())
    n = record["panel_count"]
    assert n == 1601 and record["units"] == "m" and record["tolerance_mm"] == 5.0
    assert record["mold_count"] <= math.sqrt(n)
    assert record["molds_per_sqrt_panels"] == pytest.approx(record["mold_count"] / math.sqrt(n))
    assert record["panel_surface"] in ("osculating", "local_fit")
    assert record["reassigned_by_verification"] == []
    # auto planned with both panel surfaces and kept the one whose panels meet best
    alt = record["panel_surface_alternatives"]
    assert set(alt) == {"osculating", "local_fit"}
    kept = alt[record["panel_surface"]]
    assert kept["mold_count"] == record["mold_count"]
    assert all((kept["failures"], kept["steps_over_limit"], kept["mold_count"])
               <= (a["failures"], a["steps_over_limit"], a["mold_count"]) for a in alt.values())
    # neighbours meet within twice the tolerance, and the plan is not below its own bound
    steps = _assert_neighbours_meet_as_reported(record, wein99)
    assert max(steps.values()) <= 2 * record["tolerance_mm"]
    assert 1 <= record["mold_count_bound"]["molds"] <= record["mold_count"]
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
    assert page.count('<img src="data:image/png;base64,') == 5
    # nothing fetched: no address in an attribute or a style (the vendored three.js names
    # the XHTML namespace in a string, which is no fetch)
    fetched = r"(?:src|href|action)\s*=\s*[\"']?(?:https?:)?//|url\(\s*[\"']?(?:https?:)?//"
    assert re.search(fetched, page) is None
    assert "Step map" in page
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
    assert record["panel_surface"] in ("osculating", "local_fit")
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
    smooth = plan_molds(net, tolerance_mm=1.0, panel_surface="local_fit").record()
    assert smooth["panel_types"]["single_curved"] == len(net.faces)
    _assert_every_panel_fits(smooth, net)
    # rulings are straight: no star has a Meusnier sphere, so there is no one surface to build
    with pytest.raises(InputError, match="cylinder-rulings: no vertex star has discrete principal"):
        plan_molds(net, tolerance_mm=1.0, panel_surface="osculating")


def test_panels_of_one_curvature_share_one_mold_in_any_orientation():
    net = sphere_patch(radius=10.0)
    record = plan_molds(net, tolerance_mm=1.0, units="m", panel_surface="osculating").record()
    assert record["panel_surface"] == "osculating"
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
    coarse = plan_molds(net, settings=MoldSettings(tolerance_mm=1.0, cover_level=1, reserve=0.0))
    fine = plan_molds(net, tolerance_mm=1.0)
    assert coarse.panel_surface == fine.panel_surface
    assert fine.panel_surface in ("osculating", "local_fit")
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
    assert code == 3 and "do not fit" in err
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
    ("zero-tolerance", "tolerance must be a positive"),
    ("negative-tolerance", "tolerance must be a positive"),
    ("nan-tolerance", "tolerance must be a positive"),
    ("units", "unknown units 'ft'"),
    ("mold-size", "largest mold size must be a positive"),
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
        args += ["--units", "ft"]
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


# ----------------------------------------------------------------------------- one surface
def test_the_one_surface_is_continuous_across_every_edge():
    # a smooth doubly curved net with a boundary: the points of the two panels of an edge
    # along that edge coincide (the edge depends on its two vertices only)
    net = height_field_grid(9, 8, lambda x, y: 0.04 * x * x - 0.03 * y * y + 0.01 * x * y,
                            rotation_deg=20.0)
    elements = net_curvature(net)
    level = 6
    S = osculating_panel_samples(net, elements, level)
    faces = net.faces
    # outline samples of a fan triangle j: b0 + b1 = 1 (bc = 0), in the order of _fan_weights
    i, j = np.meshgrid(np.arange(level + 1), np.arange(level + 1), indexing="ij")
    keep = i + j <= level
    on_edge = (i + j)[keep] == level
    t = len(on_edge)
    edge_points: dict = {}
    for f, face in enumerate(faces):
        for c in range(len(face)):
            a, b = int(face[c]), int(face[(c + 1) % len(face)])
            pts = S[f, c * t:(c + 1) * t][on_edge]
            edge_points.setdefault((min(a, b), max(a, b)), []).append(pts)
    shared = [p for p in edge_points.values() if len(p) == 2]
    assert len(shared) == len(net.interior_edges)
    for p, q in shared:
        d = np.linalg.norm(p[:, None] - q[None], axis=2).min(axis=1)
        assert d.max() < 1e-12
    # and the one surface passes through every vertex with its own curvature elements, and
    # as far as it says from the vertices that borrow them
    corner = S[:, int(np.flatnonzero(i[keep] == level)[0])]  # fan 0 at b0 = 1: corner 0
    first = np.array([f[0] for f in faces])
    miss = np.linalg.norm(corner - net.vertices[first], axis=1)
    own = elements.measured[first]
    assert own.any() and (~own).any()
    assert miss[own].max() < 1e-12
    assert np.allclose(miss, elements.miss[first], rtol=1e-9, atol=1e-12)


def test_the_boundary_keeps_the_linear_weingarten_relation_of_the_interior(wein99):
    elements = net_curvature(wein99)
    measured = elements.measured
    assert 0 < measured.sum() < len(measured)
    fit = weingarten_fit(elements.k1[measured], elements.k2[measured])
    a, b, c = (fit["line"][key] for key in ("a", "b", "c"))
    # borrowed elements lie on the interior's line as tightly as the interior itself
    residual = np.abs(a * elements.k1 + b * elements.k2 - c)
    assert residual.max() <= 1.01 * residual[measured].max() + 1e-12
    assert np.all(elements.measured[elements.donor])


def test_steps_over_twice_the_tolerance_fail_the_plan():
    net = sphere_patch(radius=10.0, n=10)
    plan = plan_molds(net, tolerance_mm=1.0, panel_surface="osculating")
    record = plan.record()
    assert record["fits_all"] and record["panel_steps"]["over_limit"] == []
    steps = _assert_neighbours_meet_as_reported(record, net)
    assert max(steps.values()) <= 2.0
    # the same plan with one edge's step over the limit: reported, and the plan fails
    bad = plan.step_mm.copy()
    bad[5] = 2.5
    worse = replace(plan, step_mm=bad)
    r = worse.record()
    assert not worse.fits_all and not r["fits_all"]
    assert [e["faces"] for e in r["panel_steps"]["over_limit"]] == [
        net.interior_edge_faces[5].tolist()]
    assert r["panel_steps"]["max_mm"] == 2.5
