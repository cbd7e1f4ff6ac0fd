"""Panel materials and classes: every class check recomputed from the exported data.

The figures of molds.json (the bent shape's frame and twist, its stress, the cone of a
roll-bent panel) are recomputed here with code of the test's own: its own frame from the
net's corners, its own least-squares fits with numpy, its own plate formulas. The panels'
dense samples come from the panel surfaces the mold plan verifies
(`fabplan.fabricate.panels`, the ``shared`` surface of the net), not from the classifier.
"""

from __future__ import annotations

import csv
import html
import json

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.fabricate.materials import PRESETS, parse_material
from fabplan.fabricate.molds import plan_molds
from fabplan.fabricate.panels import fit_panel_surfaces, shared_panel_samples
from fabplan.net.generate import height_field_grid
from fabplan.net.mesh import QuadMesh
from fabplan.study.run import candidate_cost, verdict
from fabplan.study.spec import CostWeights, Limits, parse_study

VERIFY_LEVEL = 12          # the mold plan's dense samples (MoldSettings.verify_level)


def _dense(mesh: QuadMesh) -> np.ndarray:
    return shared_panel_samples(mesh, fit_panel_surfaces(mesh, "local_fit"), VERIFY_LEVEL)


def _own_frame(mesh: QuadMesh, face: int, normal: np.ndarray) -> np.ndarray:
    """x along the face's first edge in the plane normal to `normal`, y = n x x."""
    a, b = mesh.faces[face][:2]
    e = mesh.vertices[b] - mesh.vertices[a]
    e = e - (e @ normal) * normal
    x = e / np.linalg.norm(e)
    return np.array([x, np.cross(normal, x), normal])


def _own_bent_shape(points_mm: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2)/2: (a, c, b), its gap
    once shifted, and the radius of the disk around the centre that holds the points."""
    q = (points_mm - points_mm.mean(axis=0)) @ frame.T
    x, y, z = q.T
    A = np.column_stack([np.ones_like(x), x, y, x * x / 2, x * y, y * y / 2])
    c, *_ = np.linalg.lstsq(A, z, rcond=None)
    r = z - A @ c
    return np.array([c[3], c[5], c[4]]), 0.5 * (r.max() - r.min()), float(np.hypot(x, y).max())


def _own_stress(material: dict, kxx: float, kyy: float, kxy: float, radius: float) -> float:
    """Kirchhoff bending of the principal curvatures plus E |K| rho^2 / 8 (docs/materials.md)."""
    E, nu, t = material["youngs_modulus_mpa"], material["poisson"], material["stress_thickness_mm"]
    k1, k2 = np.linalg.eigvalsh(np.array([[kxx, kxy], [kxy, kyy]]))
    bending = E * t / (2 * (1 - nu**2)) * max(abs(k1 + nu * k2), abs(k2 + nu * k1))
    return bending + E * abs(k1 * k2) * radius**2 / 8


def _check_classes(mesh: QuadMesh, record: dict) -> dict:
    """Recompute every panel's class checks from molds.json and the net; return the counts."""
    mm = record["mm_per_unit"]
    tol = record["tolerance_mm"]
    classes = record["panel_classes"]
    material = classes["material"]
    dense = _dense(mesh) * mm
    counts = dict.fromkeys(("flat", "cold_bent", "roll_bent", "molded"), 0)
    for p in classes["panels"]:
        i, cls, shape = p["face"], p["class"], p["bent_shape"]
        counts[cls] += 1
        normal = np.array(shape["normal"])
        frame = _own_frame(mesh, i, normal)
        assert np.allclose(frame[0], shape["x_axis"], atol=1e-9)
        k, gap, radius = _own_bent_shape(dense[i], frame)
        stress = _own_stress(material, *k, radius)
        assert np.allclose(k, shape["curvature_per_mm"], rtol=1e-5, atol=1e-12), i
        assert shape["twist_per_mm"] == pytest.approx(k[2], rel=1e-5, abs=1e-12)
        assert shape["stress_mpa"] == pytest.approx(stress, rel=1e-5, abs=1e-9), i
        assert shape["gap_mm"] == pytest.approx(gap, rel=1e-5, abs=1e-6)
        cold_ok = gap <= tol and stress <= material["max_bend_stress_mpa"]
        q = dense[i] @ frame.T
        A = np.column_stack([np.ones(len(q)), q[:, 0], q[:, 1]])
        r = q[:, 2] - A @ np.linalg.lstsq(A, q[:, 2], rcond=None)[0]
        plane_gap = 0.5 * (r.max() - r.min())
        flat_limit = tol if material["flatness_mm_per_m"] is None else \
            min(tol, material["flatness_mm_per_m"] * 2 * radius / 1000)
        flat_ok = plane_gap <= flat_limit
        if cls == "flat":
            assert flat_ok and p["figure"] == pytest.approx(plane_gap, rel=1e-5, abs=1e-6)
        elif cls == "cold_bent":
            assert cold_ok and not flat_ok
            assert p["figure"] == pytest.approx(stress, rel=1e-5) and p["unit"] == "MPa"
            assert p["limit"] == material["max_bend_stress_mpa"]
        elif cls == "roll_bent":
            roll = p["roll"]
            C = np.array(roll["axis_point"]) * mm
            d = np.array(roll["axis_direction"])
            v = dense[i] - C
            s = v @ d
            rho = np.linalg.norm(v - np.outer(s, d), axis=1)
            t = roll["taper"]
            dist = (rho - roll["radius_mm"] - t * s) / np.sqrt(1 + t * t)
            assert np.abs(dist).max() <= tol + 1e-6, (i, np.abs(dist).max())
            smallest = ((roll["radius_mm"] + t * s) * np.sqrt(1 + t * t)).min()
            assert smallest == pytest.approx(roll["min_radius_mm"], rel=1e-6)
            assert smallest >= material["min_roll_radius_mm"]
            assert not flat_ok and not cold_ok
        else:
            assert not flat_ok and not cold_ok, i
            if "roll" in p and material["min_roll_radius_mm"] is not None:
                assert (p["roll"]["gap_mm"] > tol
                        or p["roll"]["min_radius_mm"] < material["min_roll_radius_mm"])
    assert counts == classes["counts"]
    return counts


def _check_molds(record: dict) -> None:
    """Molds are made for molded panels only; the saving is the curved molds left unmade."""
    classes = {p["face"]: p["class"] for p in record["panel_classes"]["panels"]}
    molded_on = {p["mold"] for p in record["panels"] if classes[p["face"]] == "molded"}
    for m in record["molds"]:
        assert m["made"] == (m["type"] != "plane" and m["id"] in molded_on), m["id"]
    curved = sum(m["type"] != "plane" for m in record["molds"])
    made = sum(m["made"] for m in record["molds"])
    assert record["molds_made"] == made
    assert record["molds_saved_by_material"] == curved - made


@pytest.fixture(scope="module")
def wein99_runs(tmp_path_factory):
    """`fabplan molds` on the bundled wein99 net at 5 mm, in tempered glass and in steel."""
    runs = {}
    for spec in ("glass-tempered:8mm", "steel:2mm"):
        out = tmp_path_factory.mktemp("molds") / spec.replace(":", "-")
        assert main(["molds", str(fabplan.data_path("wein99.obj")), "--tolerance-mm", "5",
                     "--material", spec, "--no-3d", "-q", "-o", str(out)]) == 0
        runs[spec] = out
    return runs


@pytest.mark.slow          # two runs of `fabplan molds` on 1601 panels: about 30 s
@pytest.mark.parametrize("spec", ["glass-tempered:8mm", "steel:2mm"])
def test_wein99_classes_recomputed_from_the_export(wein99_runs, wein99, spec):
    out = wein99_runs[spec]
    record = json.loads((out / "molds.json").read_text(encoding="utf-8"))
    counts = _check_classes(wein99, record)
    _check_molds(record)
    # the net is strongly curved at 0.9 m panels: every class but the one glass is not
    # rolled into occurs, and the material saves molds
    assert counts["cold_bent"] > 100 and counts["molded"] > 100
    assert (counts["roll_bent"] > 0) is (spec == "steel:2mm")
    assert record["molds_saved_by_material"] > 0
    rows = list(csv.DictReader((out / "panels.csv").read_text().splitlines()))
    by_face = {p["face"]: p for p in record["panel_classes"]["panels"]}
    for row in rows:
        p = by_face[int(row["face"])]
        assert row["class"] == p["class"] and row["class_unit"] == p["unit"]
        assert float(row["class_figure"]) == pytest.approx(p["figure"], rel=1e-5)
        assert float(row["class_limit"]) == pytest.approx(p["limit"], rel=1e-5)
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "Panel classes" in page and f"{counts['cold_bent']} cold-bent" in page


def _twisted_facade(twist_per_m: float) -> QuadMesh:
    """A 12 x 12 m hyperbolic paraboloid facade z = w x y, 1.5 m panels."""
    return height_field_grid(9, 9, lambda x, y: twist_per_m * x * y, spacing=1.5)


def _translational(r1_m: float, r2_m: float) -> QuadMesh:
    """z = x^2 / (2 r1) + y^2 / (2 r2): a translational surface, its quads planar."""
    return height_field_grid(9, 9, lambda x, y: x * x / (2 * r1_m) + y * y / (2 * r2_m),
                             spacing=1.5)


@pytest.mark.parametrize("spec", ["glass-heat-strengthened:8mm", "glass-tempered:10mm",
                                  "glass-laminated:2x8mm"])
def test_mildly_twisted_facade_is_cold_bent_glass_without_molds(spec, tmp_path):
    w = 0.02                                   # twist 0.02 1/m: corners 0.72 m apart in z
    mesh = _twisted_facade(w)
    out = tmp_path / "hypar"
    mesh.write_obj(tmp_path / "hypar.obj")
    assert main(["molds", str(tmp_path / "hypar.obj"), "--tolerance-mm", "3", "--material",
                 spec, "--no-3d", "-q", "-o", str(out)]) == 0
    record = json.loads((out / "molds.json").read_text(encoding="utf-8"))
    net = QuadMesh.from_obj(tmp_path / "hypar.obj")
    counts = _check_classes(net, record)
    _check_molds(record)
    assert counts == {"flat": 0, "cold_bent": 64, "roll_bent": 0, "molded": 0}
    assert record["molds_made"] == 0 and record["molds_saved_by_material"] >= 1
    limit = parse_material(spec).max_bend_stress_mpa
    for p in record["panel_classes"]["panels"]:
        shape = p["bent_shape"]
        # the panel's twist along its edges is the surface's w_xy (its slope shortens it a
        # little at the far panels: z_xy / (1 + z_x^2 + z_y^2)^(3/2) and the tilt of the frame)
        assert abs(shape["twist_per_mm"]) * 1000 == pytest.approx(w, rel=0.1)
        assert shape["stress_mpa"] <= limit


def test_translational_surface_glass_is_cold_bent_on_its_smooth_surface():
    """A planar-quad net: cut flat on its corners' planes, or cold-bent to the smooth
    surface through it, either way without a mold."""
    mesh = _translational(40.0, -60.0)
    material = parse_material("glass-tempered:8mm")
    smooth = plan_molds(mesh, tolerance_mm=3, panel_surface="shared", material=material)
    assert smooth.classes is not None
    assert smooth.classes.counts["cold_bent"] == 64 and smooth.made_mold_count == 0
    assert smooth.classes.stress_mpa.max() <= material.max_bend_stress_mpa
    # along the parameter lines a translational surface does not twist
    assert np.abs(smooth.classes.curvature[:, 2]).max() < 0.05 * np.abs(
        smooth.classes.curvature[:, :2]).max()
    planar = plan_molds(mesh, tolerance_mm=3, material=material)    # auto: corners
    assert planar.panel_surface == "corners"
    assert planar.classes is not None and planar.classes.counts["flat"] == 64
    assert planar.made_mold_count == 0


def test_annealed_glass_is_not_bent_cold_where_tempered_is():
    mesh = _twisted_facade(0.02)
    annealed = plan_molds(mesh, tolerance_mm=3, material=parse_material("glass-annealed:8mm"))
    tempered = plan_molds(mesh, tolerance_mm=3, material=parse_material("glass-tempered:8mm"))
    assert annealed.classes is not None and tempered.classes is not None
    # the same shape, the same stress; only the limit differs
    assert np.allclose(annealed.classes.stress_mpa, tempered.classes.stress_mpa)
    assert annealed.classes.counts["molded"] == 64 and annealed.made_mold_count >= 1
    assert tempered.classes.counts["cold_bent"] == 64


def test_a_plan_without_material_makes_every_curved_mold():
    mesh = _twisted_facade(0.02)
    plan = plan_molds(mesh, tolerance_mm=3)
    assert plan.classes is None
    assert plan.made_mold_count == int(np.sum(plan.mold_type > 0)) and plan.molds_saved == 0
    assert "class" not in plan.panels_csv().splitlines()[0].split(",")


@pytest.mark.parametrize("text, words", [
    ("glass-tempered:80mm", "outside the 3 .. 25 mm"),
    ("glass-tempered:2x8mm", "single sheet"),
    ("granite:20mm", "unknown material"),
    ("glass-tempered=8", "NAME[:THICKNESS]"),
])
def test_bad_material_is_refused_in_one_line(text, words, tmp_path, capsys):
    code = main(["molds", str(fabplan.data_path("wein99.obj")), "--tolerance-mm", "5",
                 "--material", text, "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and words in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_every_preset_parses_and_gives_back_its_spec():
    for name, preset in PRESETS.items():
        m = parse_material(name)
        assert m.thickness_mm == preset.thickness_mm and m.plies == preset.plies
        assert parse_material(m.spec) == m
        assert m.sources


_STUDY = """
[design]
surface = "hyperbolic-paraboloid"
[panels]
size = 2.0
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
[material]
{material}
[[candidates]]
net = "isogonal"
"""


def test_study_material_table_is_read_and_refused_by_key():
    study = parse_study(_STUDY.format(material='preset = "glass-laminated"\nthickness_mm = 8'))
    assert study.material is not None and study.material.stress_thickness_mm == 16.0
    assert study.record()["material"]["spec"] == "glass-laminated:2x8mm"
    with pytest.raises(InputError, match=r"material\.thikness_mm is not a known key"):
        parse_study(_STUDY.format(material='preset = "steel"\nthikness_mm = 2'))
    with pytest.raises(InputError, match="unknown material 'glas'"):
        parse_study(_STUDY.format(material='preset = "glas"'))


def test_study_cost_and_max_molds_count_molded_panels_only():
    molds = {"count": 2, "saved": 5, "all_curved_molded": 7, "material": "glass",
             "panel_types": {"planar": 0, "single_curved": 30, "double_curved": 70},
             "panel_classes": {"flat": 10, "cold_bent": 60, "roll_bent": 20, "molded": 10},
             "molded_types": {"planar": 0, "single_curved": 4, "double_curved": 6}}
    metrics = {"molds": molds, "coverage": 0.5, "largest_deviation_mm": 3.0}
    w = CostWeights()
    cost, terms = candidate_cost(metrics, w)
    whole = 2.0
    expected = (w.mold * 2 + whole * (w.flat_panel * 10 + w.cold_bent_panel * 60
                                      + w.roll_bent_panel * 20 + w.single_curved_panel * 4
                                      + w.double_curved_panel * 6) + w.deviation_mm * 3.0)
    assert cost == pytest.approx(expected)
    assert terms["cold-bent panels"] == pytest.approx(w.cold_bent_panel * 60 * whole)
    base = {"sphere_residual_relative_max": 0.0, "converged": True, "status": "converged",
            "iterations": 3, "deviation_mm": {"max": 3.0}, "largest_deviation_mm": 3.0,
            "molds": {**molds, "failures": 0, "max_deviation_mm": 1.0}, "kink_deg": {"max": 1}}
    check = next(c for c in verdict(base, Limits(30.0, 2.0, max_molds=2))
                 if c["limit"] == "max_molds")
    assert check["ok"] and "molded panels need 2 molds" in check["text"]
    assert "5 saved by glass" in check["text"]
    assert not next(c for c in verdict(base, Limits(30.0, 2.0, max_molds=1))
                    if c["limit"] == "max_molds")["ok"]


@pytest.mark.slow          # the canopy template study: about 60 s
def test_canopy_template_shows_the_molds_its_glass_saves(tmp_path):
    out = tmp_path / "canopy"
    assert main(["study", "canopy", "-o", str(out), "-q"]) == 0
    record = json.loads((out / "study.json").read_text(encoding="utf-8"))
    assert record["study"]["material"]["spec"] == "glass-laminated:2x8mm"
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "molds saved by the material [count]" in page
    checked = 0
    for c in record["candidates"]:
        molds = c["metrics"]["molds"]
        classes = molds["panel_classes"]
        assert sum(classes.values()) == c["metrics"]["panels"]
        assert molds["count"] + molds["saved"] == molds["all_curved_molded"]
        saved = f"{molds['saved']} mold{'' if molds['saved'] == 1 else 's'} saved by the material"
        assert saved in " ".join(html.unescape(page).split()), (c["name"], saved)
        folder = out / "candidates" / c["name"]
        plan = json.loads((folder / "molds.json").read_text(encoding="utf-8"))
        _check_molds(plan)
        assert plan["molds_made"] == molds["net_molds"]
        # the nets that leave the design (one that ended at an earlier candidate's net has
        # that net's molds)
        if plan["panel_surface"] == "shared" and not c["same_net_as"]:
            _check_classes(QuadMesh.from_obj(folder / "net.obj"), plan)
            checked += 1
    assert checked >= 1
    best = next(c for c in record["candidates"] if c["name"] == record["recommended"])
    assert "saved by the material" in record["recommendation"]
    # the saddle's mild twist: its laminated glass bends cold, no mold is made
    assert best["metrics"]["molds"]["count"] == 0 and best["metrics"]["molds"]["saved"] >= 1
    check = next(k for k in best["checks"] if k["limit"] == "max_molds")
    assert check["ok"] and "no panel is molded" in check["text"]
