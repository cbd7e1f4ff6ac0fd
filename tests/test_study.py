"""Facade studies: the study file, the run, the verdicts, the files, the CLI.

A small study on a saddle runs once per module (about 10 s) and the tests read what it
wrote: every verdict must trace to a number in ``study.json``, the files must be real
(nets that reload with the measured residuals, DXF that reads back, a report with its
pictures embedded), and a limit changed in the study file must flip the verdict for the
right reason. Judging is a pure function of the metrics (`judge_study`), so other limits
are tried on the same run without solving again.
"""

from __future__ import annotations

import csv
import dataclasses
import html
import json
import re
from pathlib import Path

import ezdxf
import numpy as np
import pytest

from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.errors import InputError, SolverError
from fabplan.fabricate.molds import plan_molds
from fabplan.io.obj import read_obj
from fabplan.net.geometry import canonical_stars, fit_star_spheres
from fabplan.net.mesh import QuadMesh, load_mesh
from fabplan.study.pages import study_html
from fabplan.study.records import study_record
from fabplan.study.report import check_output_folder
from fabplan.study.run import candidate_cost, judge_study, mold_metrics, run_study, same_net, verdict
from fabplan.study.spec import CostWeights, parse_study, read_study
from fabplan.study.templates import template_names, template_path

STUDY = """\
[study]
name = "Saddle test"
description = "A small saddle canopy with three candidates."
max_iterations = 80

[design]
surface = "hyperbolic-paraboloid"
parameters = {{ width = 4, depth = 4, rise = 1.2 }}
triangles = 4000

[panels]
size = 0.7

[limits]
max_deviation_mm = {deviation}
mold_tolerance_mm = 1.5
max_kink_deg = 20

[strips]
height_mm = 60
thickness_mm = 3
sheet_mm = [1200, 600]

[[candidates]]
net = "isogonal"
angle = 80

[[candidates]]
net = "const-radius"
"""

CANDIDATE_KEYS = {"name", "net", "feasible", "reasons", "metrics", "outputs"}


def _write_study(folder: Path, deviation: float) -> Path:
    path = folder / "saddle.toml"
    path.write_text(STUDY.format(deviation=deviation), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def study_result(tmp_path_factory):
    """The saddle study run and written as `fabplan study` does: (study file, output
    folder, study.json, StudyResult, progress lines).

    The output folder holds an earlier study written without a list of its files (a
    study.json and a candidate's file) and a file of the user's before: the new study
    must replace the earlier study's files and keep the user's."""
    from fabplan.study.report import write_study

    folder = tmp_path_factory.mktemp("study")
    path = _write_study(folder, 200)
    out = folder / "out"
    out.mkdir()
    (out / "study.json").write_text("{}", encoding="utf-8")
    (out / "candidates" / "gone").mkdir(parents=True)
    (out / "candidates" / "gone" / "net.obj").write_text("of the earlier run", encoding="utf-8")
    (out / "notes.txt").write_text("the user's", encoding="utf-8")
    lines: list = []
    result = run_study(read_study(path), progress=lines.append)
    write_study(result, out, progress=lines.append)
    return path, out, json.loads((out / "study.json").read_text(encoding="utf-8")), result, lines


@pytest.fixture(scope="module")
def study_run(study_result):
    """(study file, output folder, study.json) of the saddle study."""
    return study_result[:3]


def _candidate(record: dict, name: str) -> dict:
    return next(c for c in record["candidates"] if c["name"] == name)


# ---------------------------------------------------------------------------- study file
def test_sweeps_expand_into_named_candidates():
    study = parse_study(STUDY.format(deviation=50).replace(
        "angle = 80", "angle = { from = 60, to = 90, step = 10 }"))
    assert [c.name for c in study.candidates] == [
        "baseline", "isogonal-60", "isogonal-70", "isogonal-80", "isogonal-90", "const-radius"]
    assert study.candidates[0].baseline and study.candidates[0].net == "snet"
    assert [c.angle for c in study.candidates[1:5]] == [60, 70, 80, 90]


def test_auto_candidates_cover_the_rationalizations():
    text = STUDY.format(deviation=50).split("[[candidates]]")[0]
    nets = {c.net for c in parse_study(text).candidates}
    assert {"snet", "isogonal", "linear-weingarten", "const-radius", "char-conjugate",
            "cmc"} <= nets


@pytest.mark.parametrize("change, fragment", [
    (("max_deviation_mm = 50", "max_deviaton_mm = 50"), "limits.max_deviaton_mm is not a known "
                                                        "key (did you mean 'max_deviation_mm'?)"),
    (("size = 0.7", "size = \"big\""), "panels.size must be a positive number"),
    (("net = \"const-radius\"", "net = \"const-radios\""), "candidates[1].net must be one of"),
    (("surface = \"hyperbolic-paraboloid\"", "surface = \"hypar\""), "design.surface is 'hypar'"),
    (("rise = 1.2", "rise = 1.2, wdth = 3"), "design.parameters do not describe a surface"),
    (("angle = 80", "angle = 200"), "candidates[0].angle must lie in [1, 90] degrees, got 200"),
    (("angle = 80", "angle = 120"), "candidates[0].angle must lie in [1, 90] degrees, got 120: an "
                                    "isogonal net of angle a is the same net as one of 180 - a "
                                    "with the families swapped (ask for 60)"),
    (("angle = 80", "angle = { from = 80, to = 100, step = 10 }"),
     "candidates[0].angle must lie in [1, 90] degrees, got 100"),
    (("angle = 80", "angle = 0"), "candidates[0].angle must be"),
    (("angle = 80", "angle = 0.5"), "candidates[0].angle must lie in [1, 90] degrees, got 0.5"),
    (("mold_tolerance_mm = 1.5", "mold_tolerance_mm = 0.001"),
     "limits.mold_tolerance_mm must be at least 0.01 mm"),
    (("mold_tolerance_mm = 1.5", "mold_tolerance_mm = 1.5\nmax_line_turn_deg = 0.05"),
     "limits.max_line_turn_deg must be at least 0.1 degrees"),
    (("height_mm = 60", "height_mm = 1e9"), "strips.height_mm must be at most"),
    (("[panels]", "[panel]"), "study: [panel] is not a known table (did you mean [panels]?)"),
    (("[limits]", "[limts]"), "[limts] is not a known table (did you mean [limits]?)"),
    (("triangles = 4000", "triangles = 4000\nresolution = 3"), "design.resolution is not a known key"),
    (("sheet_mm = [1200, 600]", "sheet_mm = [1200, 600]\ncongruence_tolerance_mm = 0"),
     "strips.congruence_tolerance_mm must be a positive number (mm), got 0"),
    # the range of the strips' own tolerance, before anything runs (it was refused only
    # after every candidate had been solved)
    (("sheet_mm = [1200, 600]", "sheet_mm = [1200, 600]\ncongruence_tolerance_mm = 11"),
     "strips.congruence_tolerance_mm must be at most 10 mm"),
    (("sheet_mm = [1200, 600]", "sheet_mm = [1200, 600]\ncongruence_tolerance_mm = \"fine\""),
     "strips.congruence_tolerance_mm must be a positive number (mm)"),
    (("net = \"const-radius\"", "net = \"const-radius\"\nangle = 70"),
     "candidates[1].angle does not apply to net type 'const-radius'"),
    (("net = \"const-radius\"", "net = \"sstar\""), "candidates[1].net is the S*-net type"),
    (("mold_tolerance_mm = 1.5", "mold_tolerance_mm = -1"), "limits.mold_tolerance_mm must be "
                                                            "a positive number"),
    (("mold_tolerance_mm = 1.5\n", ""), "limits.mold_tolerance_mm is missing"),
    (("sheet_mm = [1200, 600]", "sheet_mm = 1200"), "strips.sheet_mm must be [width, height]"),
    (("[panels]", "[panels\n"), "not a valid TOML study file"),
])
def test_a_bad_study_file_is_refused_naming_the_key(change, fragment):
    text = STUDY.format(deviation=50).replace(*change)
    with pytest.raises(InputError) as info:
        parse_study(text)
    assert fragment in str(info.value)


def test_a_missing_design_file_is_named(tmp_path):
    text = STUDY.format(deviation=50).replace(
        'surface = "hyperbolic-paraboloid"\nparameters = { width = 4, depth = 4, rise = 1.2 }',
        'file = "facade.stl"')
    path = tmp_path / "s.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=r"design.file names 'facade.stl', which does not exist"):
        read_study(path)


@pytest.mark.parametrize("argv, fragment", [
    (["study", "no-such-template", "-o", "OUT"], "unknown template 'no-such-template'"),
    (["study", "missing.toml", "-o", "OUT"], "missing.toml: no such study file"),
    (["study", "BAD", "-o", "OUT"], "candidates[1].net must be one of"),
])
def test_the_cli_refuses_bad_studies_without_leaving_a_folder(tmp_path, capsys, monkeypatch,
                                                               argv, fragment):
    monkeypatch.chdir(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text(STUDY.format(deviation=50).replace('net = "const-radius"', 'net = "nope"'),
                   encoding="utf-8")
    argv = [str(bad) if a == "BAD" else str(tmp_path / "out") if a == "OUT" else a for a in argv]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1 and fragment in err
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_every_template_is_a_valid_study_listed_by_the_cli(capsys):
    names = template_names()
    assert {"stadium", "pavilion", "tower", "canopy"} <= set(names)
    for name in names:
        study = read_study(template_path(name))
        assert study.candidates[0].baseline and len(study.candidates) >= 2
        assert study.description
    assert main(["templates"]) == 0
    listed = capsys.readouterr().out
    for name in names:
        assert re.search(rf"^{name}\s+\S", listed, re.M)


def test_a_template_is_copied_to_start_a_study(tmp_path, capsys):
    target = tmp_path / "mine.toml"
    assert main(["templates", "canopy", "-o", str(target)]) == 0
    study = read_study(target)
    assert study.candidates == read_study(template_path("canopy")).candidates
    assert main(["templates", "canopy", "-o", str(target)]) == 2     # never overwrites
    assert "exists" in capsys.readouterr().err


def test_templates_copied_to_a_folder_keep_their_name(tmp_path):
    """`-o newdir/` (trailing slash) wrote newdir.toml; a folder gets NAME.toml in it."""
    assert main(["templates", "pavilion", "-o", str(tmp_path / "newdir") + "/"]) == 0
    assert (tmp_path / "newdir" / "pavilion.toml").is_file()
    assert not (tmp_path / "newdir.toml").exists()
    (tmp_path / "there").mkdir()
    assert main(["templates", "tower", "-o", str(tmp_path / "there")]) == 0
    assert read_study(tmp_path / "there" / "tower.toml").candidates == \
        read_study(template_path("tower")).candidates
    assert (tmp_path / "there" / "tower-profile.txt").is_file()   # the file it refers to
    assert main(["templates", "pavilion", "-o", str(tmp_path / "plain")]) == 0
    assert (tmp_path / "plain.toml").is_file()                     # no slash: a file name


# ---------------------------------------------------------------------------- the run
def test_study_json_lists_every_candidate_with_its_evidence(study_run):
    _, out, record = study_run
    assert record["schema"] == "fabplan-study/1"
    names = [c["name"] for c in record["candidates"]]
    assert names == ["baseline", "isogonal-80", "const-radius"]
    for c in record["candidates"]:
        assert CANDIDATE_KEYS <= set(c)
        assert c["error"] is None, c["error"]
        assert c["reasons"] and all(isinstance(r, str) and r for r in c["reasons"])
        m = c["metrics"]
        assert m["panels"] > 20 and 0.7 < m["coverage"] <= 1.0
        # (not mean <= p95: a few panels can carry the whole mean)
        assert max(m["deviation_mm"]["mean"], m["deviation_mm"]["p95"]) <= m["deviation_mm"]["max"]
    assert record["recommended"] in names
    assert _candidate(record, record["recommended"])["feasible"]
    flags = {c["name"]: c["recommended"] for c in record["candidates"]}
    assert all(isinstance(v, bool) for v in flags.values())
    assert [n for n, v in flags.items() if v] == [record["recommended"]]


def test_study_json_records_run_and_total_seconds(study_run):
    """`seconds` used to leave out writing the files (canopy: 27 s claimed, 100 s wall)."""
    _, out, record = study_run
    assert record["seconds"] == record["seconds_total"]       # the earlier name, kept
    assert 0 < record["seconds_run"] < record["seconds_total"]
    html_text = (out / "report.html").read_text(encoding="utf-8")
    assert f"run in {record['seconds_total']:.0f} s including the files of the candidates" in html_text
    per_candidate = sum(c["metrics"]["seconds"]["total"] for c in record["candidates"])
    assert per_candidate <= record["seconds_run"]


def test_gliding_candidates_lie_on_the_design_and_meet_their_type(study_run):
    _, out, record = study_run
    # held on the design's triangulation: off the exact saddle by at most its chord error
    design = load_design("hyperbolic-paraboloid:width=4,depth=4,rise=1.2", triangles=4000)
    chord_mm = 1000 * design.chord_error
    for name in ("baseline", "isogonal-80"):
        m = _candidate(record, name)["metrics"]
        assert m["converged"]
        assert m["deviation_mm"]["max"] <= 1.5 * chord_mm
        assert m["sphere_residual_relative_max"] < 1e-6
    angle = _candidate(record, "isogonal-80")["metrics"]["intersection_angle_deg"]
    assert abs(angle["min"] - 80) < 0.05 and abs(angle["max"] - 80) < 0.05


def test_every_verdict_traces_to_a_measured_number(study_run):
    """The checks in study.json are recomputed from its metrics and limits."""
    path, _, record = study_run
    study = read_study(path)
    for c in record["candidates"]:
        m = c["metrics"]
        assert verdict(m, study.limits, panel_size=c["requested"]["panel_size"],
                       units=study.design.units) == c["checks"]
        by_limit = {ck["limit"]: ck for ck in c["checks"]}
        # the net's vertices and its boundary panels on their neighbours' molds
        edge = (m["boundary_panels"] or {}).get("deviation_max_mm")
        assert by_limit["max_deviation_mm"]["measured"] == max(m["deviation_mm"]["max"], edge or 0.0)
        assert by_limit["max_kink_deg"]["measured"] == m["kink_deg"]["max"]
        assert by_limit["mold_tolerance_mm"]["measured"] == m["molds"]["max_deviation_mm"]
        for ck in c["checks"]:
            assert f"{ck['bound']:g}" in ck["text"]
        assert c["feasible"] == all(ck["ok"] for ck in c["checks"])


def test_counts_are_written_in_words_with_the_right_number(study_result):
    """"1 molds" in the terminal lines and picture titles."""
    _, out, _, _, lines = study_result
    page = (out / "report.html").read_text(encoding="utf-8")
    text = " ".join(lines) + " " + page
    assert re.search(r"\b1 mold\b", text)          # the saddle's S-nets need one mold
    assert not re.search(r"\b1 (molds|panels|sheets|strips|parts|lamellas)\b", text)
    assert not re.search(r"\b(0|[2-9]|\d\d+) (mold|panel|sheet|strip|part)\b(?!-)", text)


def test_candidate_files_are_real(study_run):
    _, out, record = study_run
    for c in record["candidates"]:
        outputs = c["outputs"]
        mesh = load_mesh(out / outputs["net"])
        measured = json.loads((out / outputs["measured"]).read_text(encoding="utf-8"))
        assert mesh.vertex_count == c["metrics"]["vertices"]
        spheres = fit_star_spheres(mesh.vertices, canonical_stars(mesh.vertices, mesh.stars))
        residual = spheres.residual.max() / mesh.mean_edge_length
        assert residual == pytest.approx(measured["properties"]["sphere_residual_relative"]["max"],
                                         rel=1e-3, abs=1e-12)
        rows = (out / outputs["molds_csv"]).read_text(encoding="utf-8").strip().splitlines()
        # the full panels in molds.csv, the boundary panels (not the slivers cut as part
        # of a full panel) in boundary-panels.csv
        edge = (out / outputs["boundary_panels_csv"]).read_text(encoding="utf-8").splitlines()
        own = [r for r in edge[1:] if r.split(",")[1] != "extension"]
        assert len(rows) - 1 + len(own) == c["metrics"]["panels"]
        assert len(own) == c["metrics"]["boundary_panels"]["count"]
        _, faces = read_obj(out / outputs["boundary_panels"])
        assert len(faces) == len(edge) - 1
        curved = {int(r.split(",")[1]) for r in rows[1:] if r.split(",")[2] != "planar"}
        # the boundary panels' own molds are numbered after the net's
        net_molds = json.loads((out / outputs["molds_json"]).read_text())["mold_count"]
        own_molds = {int(r.split(",")[3]) for r in edge[1:] if int(r.split(",")[3]) >= net_molds}
        assert len(curved) + len(own_molds) == c["metrics"]["molds"]["count"]   # flat panels need none
        _, cut = read_obj(out / outputs["boundary_panels_cut"])
        assert [len(f) for f in cut] == [len(f) for f in faces]


@pytest.mark.slow
def test_fabplan_molds_on_a_candidates_files_finds_its_boundary_molds(study_run, tmp_path):
    """The study's boundary panel molds are reproduced by `fabplan molds` on the files it
    wrote for a net that leaves the design: the same mold for every panel, the same steps
    and molds in all."""
    _, out, record = study_run
    c = _candidate(record, "const-radius")
    folder = out / Path(c["outputs"]["net"]).parent
    study_molds = json.loads((folder / "molds.json").read_text(encoding="utf-8"))
    tolerance = study_molds["tolerance_mm"]
    assert main(["molds", str(folder / "net.obj"), "--tolerance-mm", f"{tolerance:.17g}",
                 "--no-3d", "-q", "-o", str(tmp_path / "molds")]) in (0, 3)
    again = json.loads((tmp_path / "molds" / "molds.json").read_text(encoding="utf-8"))
    mine, theirs = study_molds["boundary_panels"], again["boundary_panels"]
    assert mine["panels"] > 0
    assert theirs["mold"] == mine["mold"]
    assert theirs["molds_in_all"] == mine["molds_in_all"]
    assert theirs["step_max_mm"] == pytest.approx(mine["step_max_mm"], rel=1e-9, abs=1e-12)
    # the study's count and the molds file's are both the molds to make
    assert c["metrics"]["molds"]["count"] == mine["molds_in_all"] == \
        study_molds["molds_made"] + mine["own_molds"]


def test_lamella_candidates_get_strips_that_read_back(study_run):
    _, out, record = study_run
    c = _candidate(record, "const-radius")
    strips = c["metrics"]["strips"]
    assert strips is not None and strips["sheets"] == len(c["outputs"]["strips_dxf"]) >= 1
    assert strips["unrolled_length_error_mm"] < 1e-6
    for name in c["outputs"]["strips_dxf"]:
        doc = ezdxf.readfile(out / name)
        auditor = doc.audit()
        assert not auditor.has_errors
        assert len(doc.modelspace().query("LWPOLYLINE")) > 0
    assert _candidate(record, "isogonal-80")["metrics"]["strips"] is None   # not a lamella net


def test_the_report_links_every_file_relatively(study_run):
    """The Files list was plain text; it links each file relative to report.html."""
    _, out, record = study_run
    page = (out / "report.html").read_text(encoding="utf-8")
    links = re.findall(r'<a href="([^"]+)"', page)
    hrefs = [h for h in links if not h.startswith("#")]
    for anchor in set(links) - set(hrefs):     # the contents and the 3D view's links
        assert f'id="{anchor[1:]}"' in page
    expected = set()
    for c in record["candidates"]:
        for value in c["outputs"].values():
            expected.update(value if isinstance(value, list) else [value])
    assert expected and set(hrefs) == expected
    for href in hrefs:
        assert not href.startswith(("/", "file:")) and ":" not in href
        assert (out / href).is_file()


def test_the_report_embeds_a_picture_per_candidate(study_run):
    _, out, record = study_run
    html = (out / "report.html").read_text(encoding="utf-8")
    # nothing fetched: no address in an attribute or a style (the vendored three.js names
    # the XHTML namespace in a string, which is no fetch)
    fetched = r"(?:src|href|action)\s*=\s*[\"']?(?:https?:)?//|url\(\s*[\"']?(?:https?:)?//"
    assert re.search(fetched, html) is None
    images = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]{200,})"', html)
    assert len(images) >= 3 * len(record["candidates"]) + 1
    assert record["recommendation"].split(".")[0] in html.replace("&#x27;", "'")
    csv_rows = (out / "candidates.csv").read_text(encoding="utf-8").strip().splitlines()
    assert len(csv_rows) == 1 + len(record["candidates"])


@pytest.mark.slow
def test_a_tighter_limit_is_designed_for_in_the_solve(study_run, tmp_path, capsys):
    """Lower max_deviation_mm below what const-radius measured: the solve holds the net
    within the new limit (it designs for it), or the candidate fails for its deviation
    alone, naming the limit it would meet; the nets on the design stay the same
    (deterministic)."""
    _, _, record = study_run
    before = _candidate(record, "const-radius")
    measured = before["metrics"]["largest_deviation_mm"]
    assert before["feasible"] and measured > 0.01
    limit = round(measured / 2, 6)
    path = _write_study(tmp_path, limit)
    (tmp_path / "out").mkdir()                      # an empty folder is used as it is
    assert main(["study", str(path), "-o", str(tmp_path / "out")]) == 0
    again = json.loads((tmp_path / "out" / "study.json").read_text(encoding="utf-8"))
    # the last line (without -q) states the whole time, including writing the files
    last = capsys.readouterr().out.strip().splitlines()[-1]
    total, run, write = map(int, re.search(r"in (\d+) s: (\d+) s to run the candidates, "
                                           r"(\d+) s to write the files$", last).groups())
    assert abs(total - (run + write)) <= 1 and write >= 1
    assert total >= round(again["seconds_total"]) >= round(again["seconds_run"])
    after = _candidate(again, "const-radius")
    net_mm = after["metrics"]["deviation_mm"]["max"]
    if after["metrics"]["status"] == "off-design":
        failed = [ck for ck in after["checks"] if not ck["ok"]]
        assert "max_deviation_mm" in [ck["limit"] for ck in failed]
        deviation = next(ck for ck in failed if ck["limit"] == "max_deviation_mm")
        assert deviation["relax_to"] >= deviation["measured"] > limit
    else:                   # held within the limit, less the boundary panels' share
        assert net_mm <= limit * (1 + 1e-6)
    assert net_mm < measured
    for name in ("baseline", "isogonal-80"):       # the nets on the design: as before
        a, b = (_candidate(r, name)["metrics"] for r in (record, again))
        assert a["deviation_mm"] == b["deviation_mm"] and a["iterations"] == b["iterations"]


@pytest.mark.slow
def test_a_failing_candidate_is_reported_and_the_study_goes_on(monkeypatch):
    import importlib

    module = importlib.import_module("fabplan.solve.optimize")   # the package re-exports the function
    real = module.optimize

    def broken(mesh, net, **kw):
        if net == "const-radius":
            raise SolverError("the solver diverged at iteration 3: residual 1e9")
        return real(mesh, net, **kw)

    monkeypatch.setattr(module, "optimize", broken)
    text = STUDY.format(deviation=200).replace("sheet_mm = [1200, 600]",
                                               "sheet_mm = [1200, 600]\ncongruence_tolerance_mm = 0.05")
    study = parse_study(text.replace('net = "isogonal"\nangle = 80', 'net = "cmc"'))
    assert study.limits.congruence_tolerance_mm == study.strips.congruence_tolerance_mm == 0.05
    result = run_study(study)
    failed = next(c for c in result.candidates if c.name == "const-radius")
    assert failed.failed and not failed.feasible and failed.rank is None
    assert failed.reasons == ["the solver diverged at iteration 3: residual 1e9"]
    # a failed candidate's metrics hold only the time until it failed (as the schema says)
    assert set(failed.metrics) == {"seconds"} and set(failed.metrics["seconds"]) == {"total"}
    cmc = next(c for c in result.candidates if c.name == "cmc")
    assert not cmc.failed and cmc.rank is not None
    assert cmc.strips.strips.settings.tolerance_mm == 0.05        # passed to the strip planning
    assert result.recommended is not None and result.recommended != "const-radius"
    record = study_record(result)
    assert record["study"]["limits"]["congruence_tolerance_mm"] == 0.05
    assert _candidate(record, "const-radius")["metrics"] == failed.metrics


def test_an_existing_folder_of_other_files_is_not_replaced(tmp_path, capsys):
    path = _write_study(tmp_path, 50)
    keep = tmp_path / "out"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine", encoding="utf-8")
    assert main(["study", str(path), "-o", str(keep), "-q"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert [p.name for p in keep.iterdir()] == ["notes.txt"]
    (tmp_path / "file").write_text("mine", encoding="utf-8")
    assert main(["study", str(path), "-o", str(tmp_path / "file"), "-q"]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    assert (tmp_path / "file").read_text(encoding="utf-8") == "mine"


def test_an_empty_folder_or_an_earlier_study_is_replaced(study_run, tmp_path, capsys):
    """Re-running a study into its folder replaces the earlier study's files and keeps the
    others (documented, also in --help)."""
    _, out, record = study_run
    assert not (out / "candidates" / "gone").exists()      # the earlier study's files are gone
    assert record["schema"] == "fabplan-study/1"           # and its study.json replaced
    assert (out / "notes.txt").read_text(encoding="utf-8") == "the user's"
    (tmp_path / "empty").mkdir()
    check_output_folder(tmp_path / "empty")
    check_output_folder(out)
    check_output_folder(tmp_path / "new" / "deeper")
    assert main(["study", "--help"]) == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert "replaces what an earlier study wrote in the output folder" in help_text
    assert "keeps every other file" in help_text
    assert "the folder of the study file is refused" in help_text


def test_kinks_and_coverage_are_measured_on_the_net(study_run):
    _, out, record = study_run
    c = _candidate(record, "baseline")
    mesh = load_mesh(out / c["outputs"]["net"])
    X = mesh.vertices
    pairs = mesh.interior_edge_faces
    normals = []
    for f in mesh.faces:                       # independent: plane fit per face
        P = X[f] - X[f].mean(axis=0)
        normals.append(np.linalg.svd(P)[2][2])
    normals = np.array(normals)
    cos = np.abs(np.sum(normals[pairs[:, 0]] * normals[pairs[:, 1]], axis=1))
    kink = np.degrees(np.arccos(np.clip(cos, -1, 1))).max()
    assert kink == pytest.approx(c["metrics"]["kink_deg"]["max"], abs=0.2)


def test_the_heat_map_shows_the_peak_deviation_at_its_vertex(study_result):
    """Panels were coloured by the mean of their corners: the peak never showed."""

    import base64
    import io

    import matplotlib.image as mpimg
    from matplotlib import colormaps

    from fabplan.study.pictures import deviation_figure


    result = study_result[3]
    c = next(c for c in result.candidates if c.name == "const-radius")
    uri = deviation_figure(c, result.design, 1e-3, result.study.design.mm_per_unit)
    image = mpimg.imread(io.BytesIO(base64.b64decode(uri.split(",", 1)[1])), format="png")
    picture = image[:, : int(0.85 * image.shape[1]), :3]           # left of the colour bar
    top = np.array(colormaps["viridis"](1.0)[:3])                  # the colour of the maximum
    near = np.linalg.norm(picture - top, axis=2) < 0.1
    assert near.sum() >= 3


def test_a_roof_is_seen_from_low_enough_to_show_its_rise(study_result):
    """The canopy's saddle looked flat (seen from 60 degrees up)."""
    from fabplan.design.load import load_design
    from fabplan.report.figures import net_view_angles

    elevation, _ = net_view_angles(study_result[3].design)
    assert 10 <= elevation <= 30
    tower = load_design(f"revolution:profile={template_path('tower').parent / 'tower-profile.txt'}",
                        triangles=2000)
    assert net_view_angles(tower)[0] <= 30


def test_char_conjugate_starts_at_the_conjugate_angle_of_the_design():
    """On a barrel (K > 0) the layout starts where the conjugate directions symmetric to
    the principal ones meet, measured independently from the parametric surface."""
    from fabplan.design.load import load_design
    from fabplan.study.run import start_angle
    from fabplan.study.spec import Candidate

    profile = template_path("tower").parent / "tower-profile.txt"
    design = load_design(f"revolution:profile={profile}", triangles=4000)
    angle = start_angle(Candidate("c", "char-conjugate"), design)
    uv = design.uv
    k1, k2, *_ = design.parametric.principal_frames(uv[:, 0], uv[:, 1])
    ratio = np.minimum(k1, k2) / np.maximum(k1, k2)      # both negative or both positive
    expected = 2 * np.degrees(np.arctan(np.sqrt(np.median(ratio[ratio > 0]))))
    # which of the two supplementary angles depends on the side the normals point to
    assert min(abs(angle - expected), abs(angle - (180 - expected))) <= 1.5
    assert abs(angle - 90) > 10
    assert start_angle(Candidate("c", "char-conjugate", start_angle=70), design) == 70
    assert start_angle(Candidate("c", "isogonal", angle=65), design) == 65
    assert start_angle(Candidate("c", "snet"), design) == 90


# ---------------------------------------------------------------------------- judging
def _rejudge(result, **limits):
    """The same measured candidates judged under other limits (no new run)."""
    study = dataclasses.replace(result.study,
                                limits=dataclasses.replace(result.study.limits, **limits))
    return judge_study(study, result.design, result.candidates)


def _verdict_box(page: str, name: str) -> str:
    """The text of the verdict box of candidate `name` in a report."""
    section = re.search(rf"<h2>(?:\d+\. )?{re.escape(name)}</h2>(.*?)</section>", page, re.S)
    box = re.search(r'<p class="(?:note|fail)">(.*?)</p>', section.group(1), re.S)
    return html.unescape(box.group(1))


def test_infeasible_verdict_boxes_name_the_failed_checks(study_result):
    """Every "Not feasible" box listed the checks the candidate passed, not the failing one."""
    result = study_result[3]
    by_name = {c.name: c for c in result.candidates}
    deviation = by_name["const-radius"].metrics["deviation_mm"]["max"]
    kink = by_name["isogonal-80"].metrics["kink_deg"]["max"]
    judged = _rejudge(result, max_deviation_mm=deviation / 2, max_kink_deg=kink - 0.01)
    page = study_html(judged, {}, {})
    infeasible = [c for c in judged.candidates if not c.feasible]
    assert {c.name for c in infeasible} >= {"const-radius", "isogonal-80"}
    for c in infeasible:
        box = _verdict_box(page, c.name)
        assert box.startswith("Not feasible: ")
        failed = [ck["text"] for ck in c.checks if not ck["ok"]]
        passed = [ck["text"] for ck in c.checks if ck["ok"]]
        assert failed and c.reasons == failed
        for text in failed:
            assert text in box
        for text in passed:
            assert text not in box
    for c in judged.candidates:
        if c.feasible:
            box = _verdict_box(page, c.name)
            assert box.startswith("Feasible: ") and all(ck["text"] in box for ck in c.checks)
    # judging again left the run's own verdicts alone
    assert all(c.feasible for c in result.candidates)


def test_sheets_are_charged_only_when_every_candidate_has_strips(study_result):
    """With nets = "auto" only const-radius got strips: its sheets (24 here) made it look
    dearer than candidates with the same molds and panels."""
    _, _, record, result, _ = study_result
    assert record["sheets_charged"] is False and result.sheets_charged is False
    lamella = _candidate(record, "const-radius")
    assert lamella["metrics"]["strips"]["sheets"] > 0
    assert lamella["cost_terms"]["sheets"] == 0
    assert lamella["cost"] == pytest.approx(sum(lamella["cost_terms"].values()))
    page = html.unescape((study_result[1] / "report.html").read_text(encoding="utf-8"))
    assert "Strip sheets are reported but not charged: only 1 of 3 candidates gets strips" in page
    assert "not charged" in record["recommendation"]
    # every candidate with strips: now they are charged
    strips = result.candidates[2].metrics["strips"]
    same = [dataclasses.replace(c, metrics={**c.metrics, "strips": strips})
            for c in result.candidates]
    judged = judge_study(result.study, result.design, same)
    assert judged.sheets_charged
    weight = result.study.cost.sheet
    for before, after in zip(result.candidates, judged.candidates, strict=True):
        assert after.cost_terms["sheets"] == weight * strips["sheets"] > 0
        assert after.cost == pytest.approx(before.cost + weight * strips["sheets"])
    assert "not charged" not in judged.recommendation


def test_candidate_cost_charges_sheets_only_when_asked():
    metrics = {"molds": {"count": 3, "panel_types": {"planar": 10, "double_curved": 5}},
               "coverage": 0.5, "strips": {"sheets": 7}, "deviation_mm": {"max": 2.0},
               "largest_deviation_mm": 2.0}
    w = CostWeights()
    charged, terms = candidate_cost(metrics, w)
    free, free_terms = candidate_cost(metrics, w, charge_sheets=False)
    assert terms["sheets"] == 35 and free_terms["sheets"] == 0
    assert charged - free == pytest.approx(35)
    assert free == pytest.approx(300 + (10 + 4 * 5) / 0.5 + 2)


def test_congruence_check_is_judged_on_its_tolerance(study_result):
    """The check had a hidden tolerance (0.1 mm); its measured value was a bool."""
    c = study_result[3].candidates[2]
    strips = {**c.metrics["strips"], "congruence_deviation_mm": 0.3, "congruent": False}
    metrics = {**c.metrics, "strips": strips}
    limits = study_result[3].study.limits
    for tol, ok in ((0.1, False), (0.5, True)):
        checks = verdict(metrics, dataclasses.replace(limits, congruent_strips=True,
                                                      congruence_tolerance_mm=tol))
        check = next(ck for ck in checks if ck["limit"] == "congruent_strips")
        assert (check["bound"], check["measured"], check["ok"]) == (tol, 0.3, ok)
        assert f"{tol:g} mm" in check["text"] and "0.30 mm" in check["text"]
        assert ("not congruent" in check["text"]) is (not ok)


def test_study_file_congruence_tolerance_defaults_and_is_recorded(study_run):
    _, _, record = study_run
    assert record["study"]["strips"]["congruence_tolerance_mm"] == 0.1
    assert record["study"]["limits"]["congruence_tolerance_mm"] == 0.1
    study = parse_study(STUDY.format(deviation=50).replace(
        "sheet_mm = [1200, 600]", "sheet_mm = [1200, 600]\ncongruence_tolerance_mm = 0.4"))
    assert study.strips.congruence_tolerance_mm == study.limits.congruence_tolerance_mm == 0.4


def test_a_candidate_that_ends_at_an_earlier_net_is_named_so(study_result):
    """CMC on the canopy converged to the minimal surface and was shown as a saving."""
    result = study_result[3]
    iso = next(c for c in result.candidates if c.name == "isogonal-80")
    assert iso.same_net_as is None
    assert same_net(iso.net.mesh, iso.net.mesh.with_vertices(iso.net.mesh.vertices + 1e-9),
                    1e-6 * result.study.panel_size)
    assert not same_net(iso.net.mesh, iso.net.mesh.with_vertices(iso.net.mesh.vertices + 1e-5),
                        1e-6 * result.study.panel_size)
    twin = dataclasses.replace(iso, candidate=dataclasses.replace(iso.candidate, name="iso-again"),
                               same_net_as="isogonal-80")
    judged = judge_study(result.study, result.design, [*result.candidates, twin])
    again = next(c for c in judged.candidates if c.name == "iso-again")
    assert any("the same net as isogonal-80" in n for n in again.notes)
    assert "iso-again (the same net as isogonal-80)" in judged.recommendation
    assert "the same net as isogonal-80" in _verdict_box(study_html(judged, {}, {}), "iso-again")
    # the run found no twins among the saddle's three different nets
    assert [c.same_net_as for c in result.candidates] == [None, None, None]


def test_flat_panels_need_no_mold():
    """The tower's planar glass was said to need 1 mold and charged 100 units for it."""
    u, v = np.meshgrid(np.linspace(0, 4, 5), np.linspace(0, 3, 4), indexing="ij")
    flat = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))
    plan = plan_molds(flat, tolerance_mm=1.0, units="m")
    assert plan.mold_count == 1                        # the plane the flat panels lie on
    m = mold_metrics(plan)
    assert m["count"] == 0 and m["all_panels_flat"] and m["panel_types"]["planar"] == 12
    saddle = QuadMesh.grid(np.stack([u, v, 0.3 * (u - 2) * (v - 1.5)], axis=-1))
    curved = mold_metrics(plan_molds(saddle, tolerance_mm=1.0, units="m"))
    assert curved["count"] >= 1 and not curved["all_panels_flat"]
    metrics = {"molds": m, "coverage": 1.0, "strips": None, "deviation_mm": {"max": 0.0},
               "largest_deviation_mm": 0.0, "sphere_residual_relative_max": 0.0,
               "converged": True, "status": "converged",
               "iterations": 1, "planarity_mm": {"max": 0.0}, "kink_deg": {"max": 0.0}}
    cost, terms = candidate_cost(metrics, CostWeights())
    assert terms["molds"] == 0 and cost == pytest.approx(12)
    limits = parse_study(STUDY.format(deviation=50).replace(
        "max_kink_deg = 20", "max_kink_deg = 20\nmax_molds = 1")).limits
    check = next(ck for ck in verdict(metrics, limits) if ck["limit"] == "max_molds")
    assert check["ok"] and check["measured"] == 0
    assert check["text"] == "it needs no molds: all panels are flat (limit 1)"


def test_a_design_file_records_its_own_triangle_count(tmp_path):
    """study.design.triangles said 20000 for a file of 7832 triangles."""
    from fabplan.design.load import load_design

    u, v = np.meshgrid(np.linspace(-2, 2, 9), np.linspace(-2, 2, 7), indexing="ij")
    X = np.stack([u, v, 0.1 * u * v], axis=-1).reshape(-1, 3)
    ids = np.arange(63).reshape(9, 7)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], -1).reshape(-1, 4)
    lines = [f"v {x} {y} {z}" for x, y, z in X]
    lines += [f"f {a + 1} {b + 1} {c + 1}\nf {a + 1} {c + 1} {d + 1}" for a, b, c, d in quads]
    (tmp_path / "facade.obj").write_text("\n".join(lines) + "\n", encoding="utf-8")
    text = STUDY.format(deviation=50).replace(
        'surface = "hyperbolic-paraboloid"\nparameters = { width = 4, depth = 4, rise = 1.2 }\n'
        'triangles = 4000', 'file = "facade.obj"')
    (tmp_path / "s.toml").write_text(text, encoding="utf-8")
    study = read_study(tmp_path / "s.toml")
    assert study.design.triangles is None
    design = load_design(study.design.source)
    record = study_record(judge_study(study, design, []))
    assert record["study"]["design"]["triangles"] == record["design"]["triangles"] == 96
    (tmp_path / "s.toml").write_text(text.replace('file = "facade.obj"',
                                                  'file = "facade.obj"\ntriangles = 5000'),
                                     encoding="utf-8")
    with pytest.raises(InputError, match="design.triangles belongs to a built-in surface"):
        read_study(tmp_path / "s.toml")


def test_heat_map_and_metrics_measure_the_same_deviation(study_result):
    """The heat map measured to the design's triangulation, the metrics to the exact
    surface: the circled maximum (331.3 mm) differed from the table's (328.6 mm)."""
    from fabplan.study.pictures import deviation_figure
    from fabplan.study.run import vertex_deviation_mm

    result = study_result[3]
    c = next(c for c in result.candidates if c.name == "const-radius")
    d = vertex_deviation_mm(c.net.mesh, result.design, result.study.design.mm_per_unit)
    assert d.max() == c.metrics["deviation_mm"]["max"]
    exact = result.design.distances(c.net.mesh.vertices) * result.study.design.mm_per_unit
    assert np.array_equal(d, exact)
    assert deviation_figure(c, result.design, 1e-3, result.study.design.mm_per_unit).startswith(
        "data:image/png;base64,")


def test_a_candidate_that_is_another_net_ranks_right_after_it():
    """CMC on a saddle ends at the minimal net; their costs differed by 1e-8 and the copy
    was recommended over the net it copies."""
    from types import SimpleNamespace

    from fabplan.study.run import rank_candidates

    def result(name, cost, twin=None):
        return SimpleNamespace(name=name, failed=False, feasible=True, checks=[], cost=cost,
                               same_net_as=twin, rank=None)

    minimal, cmc, other = result("minimal", 2001.5577149), result("cmc", 2001.5577148, "minimal"), \
        result("isogonal", 2001.6)
    rank_candidates([cmc, other, minimal])
    assert (minimal.rank, cmc.rank, other.rank) == (1, 2, 3)


def test_an_output_folder_named_like_a_template_does_not_hide_it(tmp_path, monkeypatch):
    """`fabplan study canopy -o canopy` twice: the second run read the folder as the
    study file and said "no such study file"."""
    from fabplan.study.templates import resolve_study, template_path

    monkeypatch.chdir(tmp_path)
    (tmp_path / "canopy").mkdir()
    assert resolve_study("canopy") == template_path("canopy")
    (tmp_path / "mine").mkdir()
    with pytest.raises(InputError, match="mine: a folder, not a study file"):
        resolve_study("mine")


def test_the_report_says_how_much_of_the_design_is_clad_and_whether_nets_fold(study_run):
    """Designs were left 6-9 % unclad at their edges and no report said so."""
    _, out, record = study_run
    page = html.unescape((out / "report.html").read_text(encoding="utf-8"))
    assert "design covered [%]" in page
    rows = {r["name"]: r for r in csv.DictReader(
        line for line in (out / "candidates.csv").read_text(encoding="utf-8").splitlines()
        if not line.startswith("#"))}
    for c in record["candidates"]:
        if c.get("failed"):
            continue
        m = c["metrics"]
        assert float(rows[c["name"]]["coverage"]) == pytest.approx(m["coverage"], rel=1e-5)
        assert rows[c["name"]]["folded"] == ("yes" if m["folds"]["folded"] else "no")
        assert f"{100 * m['coverage']:.2f} % of the design's area" in page
        if m["coverage"] < 0.999:
            assert f"{100 * (1 - m['coverage']):.1f} % is left unclad" in page


TWIN_STUDY = STUDY.split("[[candidates]]")[0].format(deviation=200) + """\
[[candidates]]
net = "minimal"

[[candidates]]
net = "cmc"
"""


@pytest.mark.slow
def test_forked_candidates_write_the_same_files_as_the_serial_run(tmp_path):
    """Candidates measured in forked processes (their files made there too, a twin's
    copying its twin's strips) and the PDF drawn in one: the same files as the serial run
    writes, byte for byte where no time or id is in them."""
    from fabplan.study.background import BackgroundCandidates, background_processes
    from fabplan.study.report import write_study

    if background_processes() == 0:
        pytest.skip("nothing is forked on this machine")
    path = tmp_path / "twins.toml"
    path.write_text(TWIN_STUDY, encoding="utf-8")
    serial = run_study(read_study(path))
    forked = run_study(read_study(path), background=BackgroundCandidates, files=True)
    assert {c.name: c.twin for c in forked.candidates}["cmc"] == "minimal"   # the same net
    assert {"minimal", "cmc"} <= set(forked.made_files)       # the twin's made beside, too
    write_study(serial, tmp_path / "serial")
    write_study(forked, tmp_path / "forked", fork=True)

    def files(folder: Path) -> dict:
        return {p.relative_to(folder).as_posix(): p for p in sorted(folder.rglob("*"))
                if p.is_file()}

    a, b = files(tmp_path / "serial"), files(tmp_path / "forked")
    assert a.keys() == b.keys()
    assert any(k.startswith("candidates/cmc/strips/") and k.endswith(".dxf") for k in a)
    for name in a:
        if name.startswith("candidates/") and name.endswith((".obj", ".csv")):
            assert a[name].read_bytes() == b[name].read_bytes(), name
        elif name.endswith(".dxf"):
            lines = [[(e.dxf.layer, e.get_points("xyb")) for e in
                      ezdxf.readfile(p).modelspace().query("LWPOLYLINE")] for p in (a[name], b[name])]
            assert lines[0] == lines[1] and lines[0], name
    pdf = b["report.pdf"].read_bytes()
    assert pdf.startswith(b"%PDF") and pdf.rstrip().endswith(b"%%EOF")
    assert not list((tmp_path / "forked").glob("*.part"))


def test_a_forked_file_is_written_whole_here_when_its_process_fails_and_gone_when_cancelled(tmp_path):
    import os
    import time

    from fabplan.io.forked import ForkedFile

    def write(path: Path) -> None:
        path.write_text("drawn", encoding="utf-8")

    done = ForkedFile(write, tmp_path / "a.txt")
    done.finish()
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "drawn"

    parent = os.getpid()

    def fails_elsewhere(path: Path) -> None:
        if os.getpid() != parent:
            raise RuntimeError("the forked process fails")
        path.write_text("here", encoding="utf-8")

    here = ForkedFile(fails_elsewhere, tmp_path / "b.txt")
    here.finish()
    assert (tmp_path / "b.txt").read_text(encoding="utf-8") == "here"

    def slow(path: Path) -> None:
        path.write_text("half", encoding="utf-8")
        time.sleep(30)

    stopped = ForkedFile(slow, tmp_path / "c.txt")
    clock = time.perf_counter()
    stopped.cancel()
    assert time.perf_counter() - clock < 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_the_report_names_a_rhino_design_by_its_file(tmp_path):
    """A .3dm design with its choices (``x.3dm#layer=...``) is a file, not a built-in
    surface: the report's header said "built-in saddle.3dm surface"."""
    from types import SimpleNamespace

    from fabplan.study.pages import _design_text

    rhino = tmp_path / "saddle.3dm"
    rhino.write_bytes(b"")

    def study(source, label):
        return SimpleNamespace(design=SimpleNamespace(source=source, label=label))

    assert _design_text(study(f"{rhino}#layer=roof", "saddle.3dm")) == (
        "Design saddle.3dm (from saddle.3dm)")
    assert _design_text(study("torus:major=3", "torus")) == "Design: built-in torus surface"


def test_a_study_smooths_its_layouts_as_its_panels_table_says():
    """`[panels] smoothing` sets the layouts' smoothing length, as `fabplan layout
    --smoothing` does: the report's advice of a longer smoothing can be followed in a
    study. Outside the option's range it is refused with the file."""
    from fabplan.study.run import run_study

    text = ('[design]\nsurface = "hyperbolic-paraboloid"\n[panels]\nsize = 2.0\nsmoothing = 1.5\n'
            '[limits]\nmax_deviation_mm = 30\nmold_tolerance_mm = 2\n'
            '[[candidates]]\nnet = "isogonal"\nangle = 80\n')
    study = parse_study(text)
    assert study.smoothing == 1.5 and study.record()["smoothing"] == 1.5
    result = run_study(study)
    for c in result.candidates:
        assert c.net is not None
        assert c.net.properties["layout"]["smoothing_panels"] == 1.5
    assert parse_study(text.replace("smoothing = 1.5\n", "")).record()["smoothing"] is None
    with pytest.raises(InputError, match="panels.smoothing"):
        parse_study(text.replace("smoothing = 1.5", "smoothing = 30"))
