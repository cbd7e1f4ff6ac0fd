"""Every figure a molds report shows, in report.html and report.pdf, is the one molds.json
holds: the pages are read as a person reads them, and each number compared."""

from __future__ import annotations

import html
import json
import math
import re

import pytest

from fabplan.cli import main


def _tables(page: str) -> list[list[list[str]]]:
    """The tables of an HTML page, each a list of rows of cell texts."""
    page = re.sub(r"<(script|style).*?</\1>", "", page, flags=re.S)
    return [[[html.unescape(re.sub(r"<.*?>", "", c)).strip()
              for c in re.findall(r"<t[hd][^>]*>.*?</t[hd]>", row, flags=re.S)]
             for row in re.findall(r"<tr.*?</tr>", table, flags=re.S)]
            for table in re.findall(r"<table.*?</table>", page, flags=re.S)]


def _g(value: float, digits: int) -> str:
    return f"{value:.{digits}g}"


@pytest.fixture(scope="module")
def wein99_report(wein99_molds):
    """The session's `fabplan molds wein99.obj --tolerance-mm 5 -q` (tests/conftest.py)."""
    code, out = wein99_molds
    assert code in (0, 3)
    return out, json.loads((out / "molds.json").read_text(encoding="utf-8"))


def test_the_summary_table_shows_the_record(wein99_report):
    out, record = wein99_report
    summary = dict(row for row in _tables((out / "report.html").read_text(encoding="utf-8"))[0][1:])
    steps = record["panel_steps"]
    per_mold = record["panels_per_mold"]
    types, molds = record["panel_types"], record["mold_types"]
    expected = {
        "panels N": f"{record['panel_count']} panels",
        "molds M": f"{record['mold_count']} molds",
        "M / sqrt(N)": f"{record['molds_per_sqrt_panels']:.2f} (ratio)",
        "panels per mold (mean / median / max)":
            f"{per_mold['mean']:.1f} / {per_mold['median']:g} / {per_mold['max']} panels",
        "panel types": f"{types['planar']} planar panels, {types['single_curved']} single "
                       f"curved panels, {types['double_curved']} double curved panels",
        "mold types": f"{molds['plane']} planes, {molds['cylinder']} cylinders, "
                      f"{molds['paraboloid']} paraboloids",
        "largest measured gap to a mold": f"{record['max_deviation_mm']:.3f} mm",
        "panels that do not fit": f"{len(record['failures'])} panels",
        "largest step between neighbouring panels' molds":
            f"{steps['max_mm']:.3f} mm (limit {steps['limit_mm']:g} mm)",
        "shared edges with a step over the limit":
            f"{len(steps['over_limit'])} of {steps['edge_count']}",
        "largest angle between neighbouring molds at shared edges":
            f"{steps['max_kink_deg']:.2f} deg",
        "fewest molds, estimated (curvature set length / reach of one mold)":
            f"{record['mold_count_bound']['molds']} molds",
        "tolerance (largest gap between a panel and its mold)": f"{record['tolerance_mm']:g} mm",
    }
    for key, value in expected.items():
        assert summary[key] == value, (key, summary[key], value)
    # the heading says the same counts
    page = (out / "report.html").read_text(encoding="utf-8")
    assert (f"{record['panel_count']} panels, {record['mold_count']} molds at "
            f"{record['tolerance_mm']:g} mm") in page


def test_every_mold_row_and_panel_row_is_the_record(wein99_report):
    out, record = wein99_report
    tables = _tables((out / "report.html").read_text(encoding="utf-8"))
    mold_rows = next(t for t in tables if t[0][:2] == ["mold id", "type"])
    head = mold_rows[0]
    assert len(mold_rows) - 1 == record["mold_count"] == len(record["molds"])
    counts = {}
    for p in record["panels"]:
        counts[p["mold"]] = counts.get(p["mold"], 0) + 1
    for row, mold in zip(mold_rows[1:], record["molds"], strict=True):
        cell = dict(zip(head, row, strict=True))
        assert int(cell["mold id"]) == mold["id"]
        assert cell["k1 [1/m]"] == _g(mold["k1"] * 1000, 4)
        assert cell["k2 [1/m]"] == _g(mold["k2"] * 1000, 4)
        assert int(cell["panels [count]"]) == counts[mold["id"]]
    panel_rows = next(t for t in tables if t[0][:2] == ["face id", "mold id"])
    shown = panel_rows[1:]
    assert shown
    for row in shown:
        cell = dict(zip(panel_rows[0], row, strict=True))
        panel = record["panels"][int(cell["face id"])]
        assert int(cell["mold id"]) == panel["mold"]
        assert cell["status"] == ("fits" if panel["fits"] else cell["status"])


def test_the_pdf_says_what_the_page_says(wein99_report):
    from pypdf import PdfReader

    out, record = wein99_report
    text = re.sub(r"\s+", " ", " ".join(
        p.extract_text() for p in PdfReader(out / "report.pdf").pages))
    assert (f"{record['panel_count']} panels, {record['mold_count']} molds at "
            f"{record['tolerance_mm']:g} mm") in text
    assert f"{record['max_deviation_mm']:.3f} mm" in text
    assert f"{record['panel_steps']['max_mm']:.3f} mm" in text


def test_boundary_panels_and_limits_are_shown_as_recorded(tmp_path):
    """A layout's net with its boundary panels and a deviation limit it exceeds: the
    boundary panels' row and the limit's row, in report.html and report.pdf, give the
    counts and figures of molds.json."""
    from pypdf import PdfReader

    net = tmp_path / "lay.obj"
    assert main(["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
                 "--triangles", "4000", "-q", "-o", str(net)]) == 0
    out = tmp_path / "molds"
    assert main(["molds", str(net), "--tolerance-mm", "2", "--design", "hyperbolic-paraboloid",
                 "--max-deviation-mm", "0.001", "-q", "-o", str(out)]) == 3
    record = json.loads((out / "molds.json").read_text(encoding="utf-8"))
    check = record["limits"]["max_deviation_mm"]
    assert check["exceeded"] and check["over"] > 0
    bounds = record["boundary_panels"]
    summary = dict(row for row in _tables((out / "report.html").read_text(encoding="utf-8"))[0][1:])
    pdf = re.sub(r"\s+", " ", " ".join(p.extract_text() for p in PdfReader(out / "report.pdf").pages))
    limit_row = f"{check['words']} (limit {check['limit']:g} {check['unit']}, {check['option']})"
    limit_text = (f"{check['over']} of {check['measured']} {check['parts']} over the limit; "
                  f"largest {check['worst']:.4g} mm")
    assert summary[limit_row] == limit_text
    assert limit_text in pdf
    boundary = summary["boundary panels (boundary-panels.csv)"]
    assert boundary.startswith(f"{bounds['panels']} boundary panels: {bounds['on_molds_full_panels_use']} "
                               "cut from molds the net's panels use")
    # counted as a study counts them: the molds in all against every panel
    m, n = bounds["molds_in_all"], record["panel_count"] + bounds["panels"]
    assert boundary.endswith(f"{m} mold{'s' * (m != 1)} to make in all for {n:,} panels "
                             f"(M / sqrt(N) = {m / math.sqrt(n):.2f})")
    assert boundary in pdf
