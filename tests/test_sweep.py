"""Sweeps in a study file: panel sizes and mold tolerances expand into candidates that
share what they can (a net solved once per panel size, molds per tolerance), and the
report compares them (sortable table, Pareto plot of the cost drivers)."""

from __future__ import annotations

import csv
import html
import json

import numpy as np
import pytest
from helpers import without_timings

from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.study.report import write_study
from fabplan.study.run import baseline_of, run_study
from fabplan.study.spec import parse_study

# a saddle: CMC ends at the minimal net (a twin), at two panel sizes and two tolerances
SWEEP = """\
[study]
name = "Sweep test"
max_iterations = 80

[design]
surface = "hyperbolic-paraboloid"
parameters = { width = 4, depth = 4, rise = 1.2 }
triangles = 3000

[panels]
size = { from = 0.7, to = 0.9, count = 2 }

[limits]
max_deviation_mm = 200
mold_tolerance_mm = [1.5, 3]

[[candidates]]
net = "minimal"

[[candidates]]
net = "cmc"
"""


def _study() -> str:
    return SWEEP


def test_sweep_values_expand_into_named_candidates():
    study = parse_study(_study())
    names = [c.name for c in study.candidates]
    assert names == [f"{n}-p{p}-t{t}" for n in ("baseline", "minimal", "cmc")
                     for p in ("0.7", "0.9") for t in ("1.5", "3")]
    assert study.swept == {"panel_size": [0.7, 0.9], "mold_tolerance_mm": [1.5, 3.0]}
    assert study.panel_size == 0.7 and study.limits.mold_tolerance_mm == 1.5
    c = study.candidates[7]                                   # minimal-p0.9-t3
    assert (study.panel_size_of(c), study.limits_of(c).mold_tolerance_mm) == (0.9, 3.0)
    assert study.limits_of(c).max_deviation_mm == 200
    assert "panels 0.9" in c.describe() and "mold tolerance 3 mm" in c.describe()
    # the tolerance does not change the net: two candidates share a solve
    assert c.solve_key == study.candidates[6].solve_key != study.candidates[5].solve_key
    assert study.record()["sweep"] == study.swept


def test_an_unswept_study_keeps_its_names_and_record():
    text = _study().replace("{ from = 0.7, to = 0.9, count = 2 }", "0.7").replace(
        "[1.5, 3]", "1.5")
    study = parse_study(text)
    assert [c.name for c in study.candidates] == ["baseline", "minimal", "cmc"]
    assert all(c.panel_size is None and c.mold_tolerance_mm is None for c in study.candidates)
    assert "sweep" not in study.record()


@pytest.mark.parametrize("value, message", [
    ("{ from = 0.7, to = 0.9, step = 0.1, count = 3 }", "either 'step' or 'count'"),
    ("{ from = 0.7, to = 0.9 }", "either 'step' or 'count'"),
    ("{ from = 0.7, to = 0.9, count = 1 }", "'from' and 'to' must then be equal"),
    ("{ from = 0.9, to = 0.7, count = 3 }", "must not be below 'from'"),
    ("{ from = 0.5, to = 2.0, count = 51 }", "at most 50"),
    ("[]", "is an empty list"),
    ("[0.7, 0.7]", "lists a value twice"),
    ('"free"', "must be a positive number"),
    ("[0.7, -1]", "must be a positive number"),
])
def test_bad_sweeps_are_named(value, message):
    text = _study().replace("{ from = 0.7, to = 0.9, count = 2 }", value)
    with pytest.raises(InputError, match=message) as info:
        parse_study(text)
    assert "panels.size" in str(info.value)


def test_a_tolerance_sweep_of_a_missing_tolerance_is_named():
    text = _study().replace("mold_tolerance_mm = [1.5, 3]\n", "")
    with pytest.raises(InputError, match="limits.mold_tolerance_mm is missing"):
        parse_study(text)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep")
    study = parse_study(_study())
    result = run_study(study)
    write_study(result, folder / "out", view_3d=False, pdf=False)
    return folder, study, result


@pytest.mark.slow
def test_candidates_of_one_net_share_the_solve_and_get_their_own_molds(swept):
    _, study, result = swept
    by_name = {c.name: c for c in result.candidates}
    assert not any(c.failed for c in result.candidates)
    for c in result.candidates:
        tolerance = study.limits_of(c.candidate).mold_tolerance_mm
        assert c.molds.settings.tolerance_mm == tolerance
        check = next(k for k in c.checks if k["limit"] == "mold_tolerance_mm")
        assert check["bound"] == tolerance
        size = study.panel_size_of(c.candidate)
        edges = c.net.mesh.vertices[c.net.mesh.edges]
        mean_edge = np.linalg.norm(edges[:, 0] - edges[:, 1], axis=1).mean()
        assert 0.6 * size < mean_edge < 1.4 * size
    for net in ("baseline", "minimal", "cmc"):
        for size in ("0.7", "0.9"):
            low, high = by_name[f"{net}-p{size}-t1.5"], by_name[f"{net}-p{size}-t3"]
            assert low.net is high.net            # one solve for both tolerances
            assert low.molds is not high.molds
    assert (by_name["minimal-p0.7-t1.5"].net.mesh.vertex_count
            > by_name["minimal-p0.9-t1.5"].net.mesh.vertex_count)
    # CMC on a saddle ends at the minimal net: the same net as the minimal candidate of
    # its own tolerance, not the first one of another tolerance
    for size in ("0.7", "0.9"):
        for tol in ("1.5", "3"):
            cmc = by_name[f"cmc-p{size}-t{tol}"]
            assert cmc.same_net_as == f"minimal-p{size}-t{tol}"
            assert cmc.molds is by_name[f"minimal-p{size}-t{tol}"].molds


@pytest.mark.slow
def test_the_pareto_front_and_the_baseline_of_each_candidate(swept):
    _, study, result = swept
    done = [c for c in result.candidates if not c.failed]
    drivers = [(c.metrics["molds"]["count"], c.metrics["largest_deviation_mm"]) for c in done]
    for c, (m, d) in zip(done, drivers, strict=True):
        dominated = any(m2 <= m and d2 <= d and (m2 < m or d2 < d) for m2, d2 in drivers)
        assert c.pareto == (not dominated), c.name
    assert any(c.pareto for c in done)
    for c in done:
        base = baseline_of(c.candidate, result.candidates)
        assert base.candidate.baseline
        assert (base.candidate.panel_size, base.candidate.mold_tolerance_mm) == (
            c.candidate.panel_size, c.candidate.mold_tolerance_mm)


@pytest.mark.slow
def test_the_report_compares_the_sweep(swept):
    folder, study, result = swept
    out = folder / "out"
    record = json.loads((out / "study.json").read_text(encoding="utf-8"))
    assert record["study"]["sweep"] == {"panel_size": [0.7, 0.9], "mold_tolerance_mm": [1.5, 3]}
    for c in record["candidates"]:
        size, tol = c["name"].rsplit("-p", 1)[1].split("-t")
        assert c["requested"]["panel_size"] == float(size)
        assert c["requested"]["mold_tolerance_mm"] == float(tol)
    assert {c["name"] for c in record["candidates"] if c["pareto"]} == {
        c.name for c in result.candidates if c.pareto}
    rows = list(csv.DictReader((out / "candidates.csv").open(encoding="utf-8")))
    assert len(rows) == 12
    assert {(r["panel_size"], r["mold_tolerance_mm"]) for r in rows} == {
        ("0.7", "1.5"), ("0.7", "3"), ("0.9", "1.5"), ("0.9", "3")}
    page = (out / "report.html").read_text(encoding="utf-8")
    assert '<table class="sortable">' in page and "aria-sort" in page
    assert "<th>panel size [m]</th>" in page and "<th>mold tolerance [mm]</th>" in page
    assert "Pareto-optimal:" in page and "Cost drivers" in page
    # sortable cells carry their full value
    assert 'data-v="0.7"' in page and 'data-v="3.0"' in page
    # the limits list each tolerance of the sweep, and the step limit each implies
    for name, values in [("largest gap between a panel and its mold", "1.5, 3 mm"),
                         ("largest step between neighbouring panels' molds", "3, 6 mm")]:
        assert f"<td>{html.escape(name)}</td><td>{values}</td>" in page
    # strip-less saddle: the tolerance twins share no strip files, every folder is complete
    for c in record["candidates"]:
        assert (out / "candidates" / c["name"] / "net.obj").is_file()


@pytest.mark.slow
def test_a_sweep_on_two_workers_is_the_serial_sweep(tmp_path, capsys):
    """Twelve candidates, six solves (the tolerances share them), the same study.json as
    the serial run apart from timings, and the same candidate files (made on the
    workers)."""
    pytest.importorskip("distributed")
    (tmp_path / "sweep.toml").write_text(_study(), encoding="utf-8")
    assert main(["study", str(tmp_path / "sweep.toml"), "-o", str(tmp_path / "serial"),
                 "--no-3d"]) == 0
    assert main(["study", str(tmp_path / "sweep.toml"), "-o", str(tmp_path / "parallel"),
                 "--no-3d", "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "6 of 6 solved" in err and "12 of 12 measured" in err
    serial, parallel = (without_timings(json.loads((tmp_path / name / "study.json").read_text(
        encoding="utf-8"))) for name in ("serial", "parallel"))
    assert parallel == serial
    # the workers made the candidates' files: the same files, byte for byte (JSON: but
    # for the timings)
    made = {}
    for name in ("serial", "parallel"):
        folder = tmp_path / name / "candidates"
        made[name] = {p.relative_to(folder).as_posix():
                      without_timings(json.loads(p.read_text(encoding="utf-8")))
                      if p.suffix == ".json" else p.read_bytes()
                      for p in folder.rglob("*") if p.is_file()}
    assert made["parallel"].keys() == made["serial"].keys()
    assert len(made["serial"]) >= 12 * 5
    differ = [k for k in made["serial"] if made["serial"][k] != made["parallel"][k]]
    assert not differ
