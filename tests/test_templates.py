"""Every bundled template runs as it is and shows what it is for (read from study.json).

What is checked (the README's template table quotes the measured numbers, these tests the
claims that must hold whatever the exact numbers):

- every template: the comparison table of report.html and of report.pdf shows, for every
  candidate, the rank, verdict, molds, panels, coverage, deviation and cost study.json
  holds;
- stadium: the linear Weingarten candidates keep the deviation limit in their solve or
  end off the design naming the smallest limit they met; the one with fewest molds has
  its panels and boundary panels meeting their neighbours (rechecked from the export) on
  at most a fifth of the baseline's molds and at most twice the square root of its panels;
  no candidate meets every limit, and the study names the nearest, its failures and the
  relaxation that makes it feasible;
- pavilion: a constant-radius candidate is feasible with congruent strips (one arc
  radius) that read back from their DXF files, where the baseline's are not congruent;
  the recommendation leads with the baseline's congruence failure and the strips, not
  with molds;
- tower: the characteristic conjugate candidate has planar panels and flat boundary panels
  meeting them within the step limit (rechecked from its files), needs no molds (and pays
  none) and is recommended; the baseline's quads are more than 10 times the tolerance out
  of plane;
- canopy: the minimal candidate is a minimal surface within the deviation limit with
  straight lamellas; CMC ends at the same net and is named so; the description's sizes
  are the design's.
"""

from __future__ import annotations

import html
import json
import re

import ezdxf
import igl
import numpy as np
import pytest
from helpers import (
    PANEL_CLASSES,
    dense_panel_samples,
    edge_midpoint_steps,
    exported_class_counts,
    exported_molds,
    recheck_made_molds,
    recheck_panel_classes,
)

from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.io.obj import read_obj
from fabplan.net.mesh import QuadMesh
from fabplan.study.candidate_solve import DEVIATION_HELD
from fabplan.study.definition import GLIDING_NETS
from fabplan.study.spec import read_study
from fabplan.study.templates import template_names, template_path

# every template study runs for 10 to 90 s: the full suite runs them, `-m "not slow"` does not
pytestmark = pytest.mark.slow


def _run(name: str, folder) -> dict:
    assert main(["study", name, "-o", str(folder), "-q"]) == 0
    return _checked(name, folder)


def _checked(name: str, folder) -> dict:
    """The checks every template's study passes, read from its output folder."""
    record = json.loads((folder / "study.json").read_text(encoding="utf-8"))
    assert (folder / "report.html").stat().st_size > 100_000          # pictures embedded
    assert all(c["error"] is None for c in record["candidates"]), \
        [c["error"] for c in record["candidates"]]
    # the whole facade is clad: full panels and boundary panels trimmed to the design.
    # Nets held on the design are clad to 99.9 %; nets that leave it meet the design
    # boundary through boundary panels continuing their surface, some of which are cut
    # again where they would overlap: clad to 98 %, the rest reported as gaps
    for c in record["candidates"]:
        coverage = c["metrics"]["coverage"]
        glides = c["net"] in GLIDING_NETS
        assert coverage >= (0.999 if glides else 0.98), (c["name"], coverage)
        if glides:
            assert c["metrics"]["boundary_panels"]["flipped"] == 0
    report = (folder / "report.html").read_text(encoding="utf-8")
    assert "boundary panel" in report and "design covered" in report
    _pages_agree_with_the_record(folder, record)
    _classes_agree_with_the_export(name, folder, record)
    return record


#: the panel material each template carries (its `[material]`, docs/study-file.md)
TEMPLATE_MATERIALS = {"stadium": "glass-annealed:12mm", "pavilion": "aluminium:2mm",
                      "tower": "glass-laminated:2x8mm", "canopy": "glass-laminated:2x8mm"}


def _classes_agree_with_the_export(name: str, folder, record: dict) -> None:
    """Every template carries a material: every measured candidate's panels are counted
    in the four classes, and the counts study.json and report.html give are the ones its
    files give (the class column of molds.csv, the boundary panels by the rule of
    docs/materials.md); every class check is recomputed from the exported net and
    molds.json (tests/helpers.py), and molds are made for molded panels only."""
    study = read_study(template_path(name))
    assert study.material is not None and study.material.spec == TEMPLATE_MATERIALS[name]
    assert record["study"]["material"]["spec"] == TEMPLATE_MATERIALS[name]
    design = None
    page = " ".join(html.unescape(re.sub(r"<.*?>", " ", (folder / "report.html").read_text(
        encoding="utf-8"))).split())
    for c in record["candidates"]:
        if c["rank"] is None:
            continue
        m = c["metrics"]
        molds, classes = m["molds"], m["molds"]["panel_classes"]
        assert sum(classes.values()) == m["panels"], c["name"]
        assert molds["count"] + molds["saved"] == molds["all_curved_molded"]
        cand = folder / "candidates" / c["name"]
        plan = json.loads((cand / "molds.json").read_text(encoding="utf-8"))
        recheck_made_molds(plan)
        boundary = cand / "boundary-panels.csv"
        assert exported_class_counts(cand / "molds.json", cand / "molds.csv",
                                     boundary if boundary.exists() else None) == classes
        own = plan.get("boundary_panels", {}).get("own_molds", 0)
        assert plan["molds_made"] + own == molds["count"], c["name"]
        # the report's sentence of the candidate: its four counts and the molds saved
        said = (f"its panels are {classes['flat']} flat, {classes['cold_bent']} cold-bent, "
                f"{classes['roll_bent']} roll-bent and {classes['molded']} molded: ")
        said += ("no panel is curved, no mold." if molds["all_curved_molded"] == 0 else
                 f"{molds['count']} mold{'' if molds['count'] == 1 else 's'}, none saved by "
                 "the material." if molds["saved"] == 0 else
                 f"{molds['count']} mold{'' if molds['count'] == 1 else 's'} instead of "
                 f"{molds['all_curved_molded']} with every curved panel molded, "
                 f"{molds['saved']} mold{'' if molds['saved'] == 1 else 's'} saved by the material.")
        assert said in page, (c["name"], said)
        if c["same_net_as"]:
            continue                 # the files of the net it ended at, checked there
        assert plan["panel_classes"]["order"] == list(PANEL_CLASSES)
        net = QuadMesh.from_obj(cand / "net.obj")
        if plan["panel_surface"] == "design" and design is None:
            design = load_design(study.design.source, triangles=study.design.triangles)
        dense = dense_panel_samples(net, plan["panel_surface"], design)
        counts = recheck_panel_classes(net, plan, dense)
        assert counts == plan["panel_classes"]["counts"]
    best = next(c for c in record["candidates"] if c["recommended"])
    assert "its panels are" in record["recommendation"]
    if best["metrics"]["molds"]["all_curved_molded"]:
        assert "saved by the material" in record["recommendation"]


def _cells(row: str) -> list[str]:
    return [html.unescape(re.sub(r"<.*?>", "", c)).strip()
            for c in re.findall(r"<t[hd][^>]*>.*?</t[hd]>", row, flags=re.S)]


def _pages_agree_with_the_record(folder, record: dict) -> None:
    """Every figure of the comparison table, in report.html and in report.pdf, is the one
    study.json holds for its candidate (read from the written pages, as a person reads
    them)."""
    from pypdf import PdfReader

    page = re.sub(r"<(script|style).*?</\1>", "", (folder / "report.html").read_text(
        encoding="utf-8"), flags=re.S)
    table = next(t for t in re.findall(r"<table.*?</table>", page, flags=re.S)
                 if "molds [count]" in t)
    rows = [_cells(r) for r in re.findall(r"<tr.*?</tr>", table, flags=re.S)]
    head, body = rows[0], rows[1:]
    measured = [c for c in record["candidates"] if c["rank"] is not None]
    assert len(body) == len(measured)
    pdf = " ".join(p.extract_text() for p in PdfReader(folder / "report.pdf").pages[:3])
    pdf = re.sub(r"\s+", " ", pdf)
    for row in body:
        cell = dict(zip(head, row, strict=True))
        c = next(c for c in measured if c["name"] == cell["candidate"])
        m = c["metrics"]
        shown = {"rank": str(c["rank"]), "feasible": "yes" if c["feasible"] else "no",
                 "molds [count]": str(m["molds"]["count"]), "panels [count]": str(m["panels"]),
                 "design covered [%]": f"{100 * m['coverage']:.1f}",
                 "max deviation [mm]": f"{m['largest_deviation_mm']:.1f}",
                 "cost [cost units]": f"{c['cost']:.0f}"}
        classes = m["molds"].get("panel_classes")
        flat = m["molds"]["all_panels_flat"] and (classes is None
                                                  or classes["flat"] == m["panels"])
        for key, value in shown.items():
            if key == "molds [count]" and m["molds"]["count"] == 0:
                # the page says why there are none
                value = "none (all flat)" if flat else "none (none molded)"
            assert cell[key] == value, (c["name"], key, cell[key], value)
        if "molds saved by the material [count]" in cell:
            assert cell["molds saved by the material [count]"] == str(m["molds"]["saved"])
        if "of them boundary panels [count]" in cell:
            assert cell["of them boundary panels [count]"] == str(m["boundary_panels"]["count"])
        # the PDF's comparison row: rank, name, verdict, molds, panels, deviation, cost
        assert (f"{c['rank']} {c['name']} {shown['feasible']} {shown['molds [count]']} "
                f"{shown['panels [count]']} {shown['max deviation [mm]']} "
                f"{shown['cost [cost units]']}") in pdf, c["name"]


def _by_net(record: dict, net: str) -> list:
    return [c for c in record["candidates"] if c["net"] == net and not c["baseline"]]


def _baseline(record: dict) -> dict:
    return next(c for c in record["candidates"] if c["baseline"])


def _sentences(text: str) -> list:
    return re.split(r"(?<=[.)])\s+(?=[A-Z])", text)


def _baseline_failure_comes_first(record: dict) -> None:
    """The recommendation's second sentence names the limit the baseline fails, with the
    measured number against the limit, before anything about the recommended candidate."""
    base = _baseline(record)
    assert not base["feasible"]
    second = _sentences(record["recommendation"])[1]
    assert second.startswith("The baseline")
    for check in base["checks"]:
        assert (check["text"] in second) is (not check["ok"])


def test_stadium_linear_weingarten_nets_keep_the_design_limit_in_the_solve(stadium_study):
    # the session's run of `fabplan study stadium` (tests/conftest.py), read only
    out, run = stadium_study
    assert run.code == 0, run.lines[-5:]
    record = _checked("stadium", out)
    limits = read_study(template_path("stadium")).limits
    tol = limits.mold_tolerance_mm
    lw = _by_net(record, "linear-weingarten")
    base_plan = json.loads((out / "candidates" / "baseline" / "molds.json").read_text())
    for c in lw:
        m = c["metrics"]
        # the deviation limit is held inside the solve (at 90 % of it): a net that cannot
        # keep to that ends off the design at the smallest limit it met, and is judged
        # against the study's limit like every other
        deviation = next(ck for ck in c["checks"] if ck["limit"] == "max_deviation_mm")
        if not deviation["ok"]:
            assert deviation["relax_to"] >= deviation["measured"]
            assert "largest deviation from the design of" in c["relaxation"]
        # solved past the design's edge, the whole net kept keeps the bound the solve was
        # given (or, off the design, the smallest it reached), and its boundary panels, cut
        # from the molds, continue it
        solved = json.loads((out / "candidates" / c["name"] / "net.json").read_text())
        continued = solved["parameters"]["continued"]
        assert continued["faces_kept"] == len(QuadMesh.from_obj(
            out / "candidates" / c["name"] / "net.obj").faces) < continued["faces_solved"]
        held = DEVIATION_HELD * limits.max_deviation_mm
        if m.get("solve_status", m["status"]) == "off-design":
            assert solved["status"] == "off-design"          # the net record keeps the solver's
            held = 1000 * solved["parameters"]["deviation"]["smallest_converged"]
        assert m["deviation_mm"]["max"] <= held + 1e-6
        largest = max(m["deviation_mm"]["max"], m["boundary_panels"]["deviation_max_mm"])
        assert deviation["ok"] is (largest <= limits.max_deviation_mm)
        # off only the share the solve held, within the study's limit: converged for the study
        assert ("solve_status" in m) is (solved["status"] == "off-design"
                                         and largest <= limits.max_deviation_mm)
        if "solve_status" in m:
            assert m["status"] == "converged" and f"{largest:.1f} mm" in m["status_note"]
    # the study recommends a linear Weingarten net that meets every limit, as the paper's
    # stadium (Fig. 19): rechecked from the exported files by code apart from the planner;
    # its hot-bent glass is molded panel by panel, so the net's molds are the molds made
    chosen = next(c for c in record["candidates"] if c["recommended"])
    assert chosen["net"] == "linear-weingarten" and chosen["feasible"]
    assert record["recommendation"].startswith(f"Recommended: {chosen['name']} ")
    assert chosen["metrics"]["molds"]["saved"] == 0
    folder = out / "candidates" / chosen["name"]
    plan = json.loads((folder / "molds.json").read_text())
    net = QuadMesh.from_obj(folder / "net.obj")
    assert plan["panel_surface"] == "shared"             # it left the design: its own surface
    assert edge_midpoint_steps(plan, net).max() <= plan["panel_steps"]["max_mm"] + 1e-6
    assert plan["mold_count"] <= 0.2 * base_plan["mold_count"]
    found = exported_molds(folder / "net.obj", folder / "net.boundary.obj",
                           folder / "molds.json", folder / "boundary-panels.csv",
                           folder / "boundary-panels.obj")
    assert found["cut_gap_mm"] <= 1e-6
    assert found["panels"] == chosen["metrics"]["panels"]
    # every mold counted, boundary panels' own included: at most 2 sqrt(N) for N panels
    assert found["molds_in_all"] == chosen["metrics"]["molds"]["count"] \
        <= min(2 * np.sqrt(found["panels"]), limits.max_molds)
    steps = np.concatenate([v for v in found["steps"].values() if v.size])
    assert steps.max() <= limits.panel_step_limit_mm
    assert steps.max() == pytest.approx(chosen["metrics"]["molds"]["max_panel_step_mm"],
                                        rel=0.1, abs=0.1)
    assert chosen["metrics"]["molds"]["max_deviation_mm"] <= tol
    # the net's vertices and the boundary panels as cut from their molds, measured against
    # the design's triangles by libigl
    design = load_design(f"revolution:profile={template_path('stadium').parent}/stadium-profile.txt,"
                         "sweep_deg=360,aspect=0.7", triangles=80000)
    cut = read_obj(folder / "boundary-panels.obj")[0]
    squared, _, _ = igl.point_mesh_squared_distance(np.vstack([net.vertices, cut]),
                                                    design.vertices, design.triangles)
    assert np.sqrt(squared.max()) * 1000 <= limits.max_deviation_mm
    # the baseline lies on the design: its panels are patches of the design itself, which
    # meet within the limit too, on many more molds
    assert base_plan["panel_surface"] == "design" and base_plan["fits_all"]
    assert edge_midpoint_steps(base_plan, QuadMesh.from_obj(
        out / "candidates" / "baseline" / "net.obj")).max() <= 2 * tol


def test_pavilion_constant_radius_strips_are_congruent(tmp_path):
    out = tmp_path / "pavilion"
    record = _run("pavilion", out)
    c = _by_net(record, "const-radius")[0]
    strips = c["metrics"]["strips"]
    assert c["feasible"] and strips["congruent"]
    radius = strips["radius_mm"]
    assert (radius["max"] - radius["min"]) / radius["median"] <= 1e-6
    assert not _baseline(record)["metrics"]["strips"]["congruent"]
    assert strips["sheets"] == len(c["outputs"]["strips_dxf"])
    for name in c["outputs"]["strips_dxf"]:
        doc = ezdxf.readfile(out / name)
        assert not doc.audit().has_errors
    # a lamella study: the recommendation is about strips, not about molds
    _baseline_failure_comes_first(record)
    text = record["recommendation"]
    chosen = next(c for c in record["candidates"] if c["recommended"])["metrics"]["strips"]
    assert f"Its {chosen['strips']} lamellas are cut as {chosen['parts']} parts, all congruent" \
        in text and f"nested on {chosen['sheets']} sheets" in text
    # molds come up only in the sentence of the material, after the strips
    first, material = text.index("lamellas are cut as"), text.index(" its panels are ")
    assert first < material and "mold" not in text[:material]
    assert "mold" not in re.sub(r"In aluminium sheet[^.]*\.", "", text)
    assert record["sheets_charged"] is True          # every candidate has strips


def test_tower_characteristic_conjugate_panels_are_planar(tower_study):
    out, run = tower_study
    assert run.code == 0, run.lines[-5:]
    record = _checked("tower", out)
    limits = read_study(template_path("tower")).limits
    c = _by_net(record, "char-conjugate")[0]
    assert c["feasible"]
    assert c["metrics"]["planarity_mm"]["max"] <= limits.planarity_tolerance_mm
    base = _baseline(record)
    assert base["metrics"]["planarity_mm"]["max"] > 10 * limits.planarity_tolerance_mm
    assert not base["feasible"]
    assert any(ck["limit"] == "planarity_tolerance_mm" and not ck["ok"] for ck in base["checks"])
    # flat glass needs no mold and is charged none: its boundary panels are flat too (in
    # the planes of the net's sides they border, parting along the lines where their
    # planes cross), none on a mold of its own
    molds = c["metrics"]["molds"]
    assert molds["count"] == 0 and molds["all_panels_flat"]
    assert molds["panel_classes"]["flat"] == c["metrics"]["panels"] and molds["saved"] == 0
    assert molds["panel_types"]["planar"] == c["metrics"]["panels"]
    boundary = c["metrics"]["boundary_panels"]
    assert boundary["count"] >= 50 and boundary["flat"] == boundary["count"]
    assert boundary["own_molds"] == 0
    assert c["cost_terms"]["molds"] == 0
    assert base["metrics"]["molds"]["count"] > 0 and base["cost_terms"]["molds"] > 0
    # every step between neighbouring panels, full and boundary, rechecked from the files
    # written by code apart from the planner
    folder = out / "candidates" / c["name"]
    found = exported_molds(folder / "net.obj", folder / "net.boundary.obj",
                           folder / "molds.json", folder / "boundary-panels.csv",
                           folder / "boundary-panels.obj")
    steps = found["steps"]
    assert len(steps["net-boundary"]) >= 100 and len(steps["boundary-boundary"]) >= 50
    assert max(v.max() for v in steps.values()) <= limits.panel_step_limit_mm
    assert found["molds_in_all"] == 0 and found["cut_gap_mm"] <= 1e-6
    plan = found["record"]
    assert plan["boundary_panels"]["flat"] == plan["boundary_panels"]["panels"]
    net = QuadMesh.from_obj(folder / "net.obj")
    assert edge_midpoint_steps(plan, net).max() <= limits.panel_step_limit_mm
    assert record["recommended"] == c["name"]
    _baseline_failure_comes_first(record)
    assert "It needs no molds: all its" in record["recommendation"]
    page = html.unescape((out / "report.html").read_text(encoding="utf-8"))
    section = page[page.index(f"<h2>{c['rank']}. {c['name']}</h2>"):]
    section = section[:section.index("</section>")]
    assert "no molds: all panels flat" in section and "(all flat: no molds)" in section
    assert "<td>none (all flat)</td>" in page


def test_canopy_minimal_surface_within_the_limit(canopy_study):
    out, run = canopy_study
    assert run.code == 0, run.lines[-5:]
    record = _checked("canopy", out)
    c = _by_net(record, "minimal")[0]
    assert c["feasible"] and c["metrics"]["converged"]
    assert c["metrics"]["strips"]["straight"]               # A-net lamellas unroll straight
    assert record["recommended"] == c["name"]
    # CMC on a saddle converges to the minimal surface: the same net, not another saving
    cmc = _by_net(record, "cmc")[0]
    assert cmc["same_net_as"] == c["name"]
    assert f"{cmc['name']} (the same net as {c['name']})" in record["recommendation"]
    page = html.unescape((out / "report.html").read_text(encoding="utf-8"))
    assert "infinite (planar stars)" in page
    assert not re.search(r"\d\.\d+e\+\d+ \.\. ", page)        # no radii like 3.558e+09 .. 1e+16
    _baseline_failure_comes_first(record)
    # its laminated glass bends cold where the saddle twists mildly: the recommended net
    # makes no mold, and the report says how many the glass saves
    molds = c["metrics"]["molds"]
    assert molds["count"] == 0 and molds["saved"] >= 1
    check = next(k for k in c["checks"] if k["limit"] == "max_molds")
    assert check["ok"] and "no panel is molded" in check["text"]
    assert "molds saved by the material [count]" in page
    # the limit the report names as binding hardest is the one study.json records (they
    # differed: a lamella study's words leave the molds' limits out, its record did not)
    from fabplan.study.checks import LIMIT_NAMES

    binding = c["binding_limit"]
    assert binding not in ("mold_tolerance_mm", "max_molds", "max_panel_step_mm")
    assert f"The limit that binds hardest is the {LIMIT_NAMES[binding][0]}" in record["recommendation"]


def test_canopy_description_states_the_design_sizes():
    """It said "rise 4 m" for a saddle whose corners are 4 m above and below the centre."""
    study = read_study(template_path("canopy"))
    span = np.ptp(load_design(study.design.source, triangles=2000).vertices, axis=0)
    description = " ".join(study.description.split())
    assert f"{span[0]:.0f} x {span[1]:.0f} m" in description
    assert f"{span[2] / 2:.0f} m above and below the centre" in description
    assert f"({span[2]:.0f} m from the low to the high corners)" in description


@pytest.mark.parametrize("name", ["stadium", "pavilion", "tower", "canopy"])
def test_templates_are_bundled(name):
    assert name in template_names()
