"""Panel materials and classes: every class check recomputed from the exported data.

The figures of molds.json (the bent shape's frame and twist, its stress, the cone of a
roll-bent panel) are recomputed with code of the tests' own (tests/helpers.py, shared with
the template studies of tests/test_templates.py): its own frame from the net's corners, its
own least-squares fits with numpy, its own plate formulas. The panels' dense samples come
from the panel surfaces the mold plan verifies (`fabplan.fabricate.molds.panels`, the ``shared``
surface of the net), not from the classifier.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from helpers import exported_class_counts, recheck_made_molds, recheck_panel_classes

import fabplan
from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.fabricate.molds import plan_molds
from fabplan.fabricate.molds.materials import PRESETS, parse_material
from fabplan.net.generate import height_field_grid
from fabplan.net.mesh import QuadMesh
from fabplan.study.run import candidate_cost, verdict
from fabplan.study.spec import CostWeights, Limits, parse_study


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
    counts = recheck_panel_classes(wein99, record)
    recheck_made_molds(record)
    # the net is strongly curved at 0.9 m panels: every class but the one glass is not
    # rolled into occurs, and the material saves molds
    assert counts["cold_bent"] > 100 and counts["molded"] > 100
    assert (counts["roll_bent"] > 0) is (spec == "steel:2mm")
    assert record["molds_saved_by_material"] > 0
    assert exported_class_counts(out / "molds.json", out / "panels.csv") == counts
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


@pytest.mark.slow
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
    counts = recheck_panel_classes(net, record)
    recheck_made_molds(record)
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
