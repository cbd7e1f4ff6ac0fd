"""Fabrication limits (`fabplan.fabricate.limits`): strip twist and congruence (``strips``),
arc angle (``arcs``), the net's deviation from its reference or design (``optimize``,
``molds``). For each, a run past the limit ends in exit 3 with the limit and the excess
named, its files written and the count in the JSON; a run within it ends in exit 0. Where
the command has a report, the figure it shows is the JSON's.

Nets: the bundled ``cmc1`` (an orthogonal S-net of nearly constant radius, 272 vertices,
metres), the same net optimized as ``cmc`` (constant radius to 1e-12), and a layout of the
built-in hyperbolic paraboloid.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.fabricate.limits import LIMITS, limit_check, limit_row_text
from fabplan.net.mesh import QuadMesh

CMC1 = fabplan.data_path("cmc1.obj")
STRIPS = ["--height", "60", "--thickness", "4", "--no-previews", "--workers", "1"]


def _warning(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.startswith("fabplan: warning")]
    assert lines, err
    return lines[-1]


@pytest.fixture(scope="module")
def claimed_cmc(tmp_path_factory) -> Path:
    """The bundled cmc1 net as it is (radius constant only nearly) beside a record that
    names it a ``cmc`` net: a claim of constant radius its strips do not keep."""
    folder = tmp_path_factory.mktemp("claimed")
    net = folder / "cmc1.obj"
    shutil.copy(CMC1, net)
    net.with_suffix(".json").write_text(json.dumps({"net": "cmc", "properties": {"units": "m"}}))
    return net


@pytest.fixture(scope="module")
def optimized_cmc(tmp_path_factory) -> Path:
    """cmc1 optimized as ``cmc``: its record claims a constant radius, which it keeps."""
    out = tmp_path_factory.mktemp("optimized") / "cmc.obj"
    assert main(["optimize", str(CMC1), "--net", "cmc", "-o", str(out), "-q"]) == 0
    return out


# ------------------------------------------------------------------------ strip twist
def test_strips_twisting_past_the_limit_end_in_exit_3(tmp_path, capsys):
    out = tmp_path / "strips"
    assert main(["strips", str(CMC1), *STRIPS, "--max-twist", "5", "-o", str(out)]) == 3
    err = capsys.readouterr().err
    record = json.loads((out / "strips.json").read_text())
    twist = record["summary"]["limits"]["max_twist_deg_per_m"]
    per_strip = np.array([s["twist_deg_per_m"] for s in record["strips"]])
    assert twist["limit"] == 5.0 and twist["exceeded"]
    assert twist["measured"] == len(per_strip) == record["summary"]["strips"]
    assert twist["over"] == int(np.sum(per_strip > 5.0)) > 0
    assert twist["worst"] == pytest.approx(per_strip.max(), abs=1e-3)
    assert twist["worst"] == pytest.approx(record["summary"]["twist_deg_per_m"])
    warning = _warning(err)
    assert f"{twist['over']} of {twist['measured']} strips exceed the largest twist" in warning
    assert f"{twist['worst'] - 5.0:.3g} deg/m over (--max-twist)" in warning
    assert (out / "strips-sheet-001.dxf").is_file()          # the files are written


def test_strips_within_the_twist_limit_end_in_exit_0(tmp_path, capsys):
    out = tmp_path / "strips"
    assert main(["strips", str(CMC1), *STRIPS, "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    twist = json.loads((out / "strips.json").read_text())["summary"]["limits"]["max_twist_deg_per_m"]
    assert twist["limit"] == LIMITS["max_twist_deg_per_m"].default and twist["over"] == 0
    assert twist["worst"] < twist["limit"]
    # the summary's figure is the JSON's
    shown = re.search(r"limit: all (\d+) strips within the largest twist of a lamella strip of "
                      r"([\d.]+) deg/m \(up to ([\d.]+) deg/m\)", printed)
    assert shown, printed
    assert int(shown[1]) == twist["measured"] and float(shown[2]) == twist["limit"]
    assert float(shown[3]) == pytest.approx(twist["worst"], rel=5e-3)
    # no claim of constant radius in a net without a record: congruence is not a limit
    assert "congruence_tolerance_mm" not in json.loads(
        (out / "strips.json").read_text())["summary"]["limits"]


# ------------------------------------------------------------- strip congruence on a claim
def test_strips_of_a_claimed_constant_radius_net_that_differ_end_in_exit_3(claimed_cmc, tmp_path,
                                                                          capsys):
    out = tmp_path / "strips"
    assert main(["strips", str(claimed_cmc), *STRIPS, "-o", str(out)]) == 3
    err = capsys.readouterr().err
    summary = json.loads((out / "strips.json").read_text())["summary"]
    check = summary["limits"]["congruence_tolerance_mm"]
    assert check["limit"] == 0.1 and check["option"] == "--tolerance"
    assert check["measured"] == summary["parts"]
    assert check["over"] == summary["parts_not_congruent"] > 0
    assert check["worst"] == pytest.approx(summary["congruence_deviation_mm"])
    assert not summary["congruent"]
    warning = _warning(err)
    assert "strip parts exceed the largest difference of a strip from the common arc" in warning
    assert "names it a cmc net" in warning and "(--tolerance)" in warning


def test_strips_of_a_constant_radius_net_that_keeps_it_end_in_exit_0(optimized_cmc, tmp_path):
    out = tmp_path / "strips"
    assert main(["strips", str(optimized_cmc), *STRIPS, "-o", str(out), "-q"]) == 0
    check = json.loads((out / "strips.json").read_text())["summary"]["limits"][
        "congruence_tolerance_mm"]
    assert check["over"] == 0 and check["worst"] < 1e-6 and check["measured"] > 0


def test_strips_over_the_tolerance_only_with_boundary_panels_say_so(optimized_cmc):
    """Parts of a constant radius net's strips that miss the common arc only where its
    boundary panels lengthen them (a linear Weingarten net: 104 of 213 parts up to 6.2 mm,
    none without the boundary panels) are not blamed on the net type: the warning says
    the net's own strips keep to it, and that --no-boundary cuts them alone."""
    from types import SimpleNamespace

    from fabplan.cli.strips import _claim_text
    from fabplan.fabricate.strips.strip_set import StripSettings

    mesh = fabplan.read_obj(optimized_cmc)
    settings = StripSettings(height_mm=80, thickness_mm=4)
    plan = SimpleNamespace(limits=[limit_check("congruence_tolerance_mm", np.array([6.2, 0.0]),
                                               0.1, parts="strip parts")])
    with_boundary = _claim_text(plan, "cmc", mesh, settings, boundary=object())
    assert with_boundary.startswith(" (the net's record names it a cmc net, whose strips are "
                                    "pieces of one arc: without its boundary panels they are")
    assert "--no-boundary cuts the net's strips alone)" in with_boundary
    assert _claim_text(plan, "cmc", mesh, settings, boundary=None).endswith("one arc)")
    # past the tolerance without them too: the net type's claim alone
    tight = StripSettings(height_mm=80, thickness_mm=4, tolerance_mm=0.001)
    claimed = fabplan.read_obj(CMC1)          # radius constant only nearly
    assert _claim_text(plan, "cmc", claimed, tight, boundary=object()).endswith("one arc)")


# ----------------------------------------------------------------------- arc angle
def test_arcs_longer_than_the_limit_end_in_exit_3(tmp_path, capsys):
    out = tmp_path / "arcs.dxf"
    assert main(["arcs", str(CMC1), "--max-arc-angle", "5", "-o", str(out)]) == 3
    err = capsys.readouterr().err
    record = json.loads(out.with_suffix(".json").read_text())
    angles = np.array([a["angle_deg"] for a in record["arcs"]])
    check = record["limits"]["max_arc_angle_deg"]
    assert check["limit"] == 5.0 and check["measured"] == len(angles) == record["summary"]["arcs"]
    assert check["over"] == int(np.sum(angles > 5.0)) > 0
    assert check["worst"] == pytest.approx(angles.max()) == pytest.approx(
        record["summary"]["angle_deg"]["max"])
    assert out.is_file()
    assert f"{check['over']} of {check['measured']} arcs exceed the largest central angle of an " \
           "arc of 5 deg" in _warning(err)


def test_arcs_within_the_angle_limit_end_in_exit_0(tmp_path, capsys):
    out = tmp_path / "arcs.dxf"
    assert main(["arcs", str(CMC1), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    check = json.loads(out.with_suffix(".json").read_text())["limits"]["max_arc_angle_deg"]
    assert check["limit"] == 90.0 and check["over"] == 0
    assert f"limit: all {check['measured']} arcs within the largest central angle of an arc of " \
           f"90 deg (up to {check['worst']:.3g} deg)" in printed


def test_a_179_degree_arc_is_counted():
    """The arcs of the issue: 179 deg against the default."""
    check = limit_check("max_arc_angle_deg", np.array([12.0, 179.0]), 90.0, parts="arcs")
    assert check.exceeded and check.over == 1 and check.worst == 179.0


# ------------------------------------------------------------- deviation: optimize
def test_optimize_off_its_reference_ends_in_exit_3(tmp_path, capsys):
    """cmc1 held at its boundary and pulled towards a copy of itself 50 mm higher: the
    held boundary stays 50 mm off, past the default 20 mm."""
    cmc1 = fabplan.read_obj(CMC1)
    QuadMesh(cmc1.vertices + [0.0, 0.0, 0.05], cmc1.faces).write_obj(tmp_path / "shifted.obj")
    out = tmp_path / "o.obj"
    assert main(["optimize", str(CMC1), "--net", "cmc", "--reference", str(tmp_path / "shifted.obj"),
                 "--fix", "boundary", "--html", "-o", str(out)]) == 3
    err = capsys.readouterr().err
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["status"] == "converged"      # a net of its type, but off its reference
    check = record["properties"]["limits"]["max_deviation_mm"]
    assert check["limit"] == 20.0 and check["over"] > 0 and check["measured"] == 272
    assert check["worst"] == pytest.approx(1000 * record["properties"]["distance_to_reference"]["max"])
    warning = _warning(err)
    assert "vertices exceed the largest deviation from the design of 20 mm" in warning
    assert f"{check['worst'] - 20:.3g} mm over (--max-deviation)" in warning
    # the page's key numbers are the record's
    page = out.with_suffix(".html").read_text()
    over = re.search(r"largest deviation from the design: vertices over the limit</td>"
                     r"<td class=\"num\">(\d+)<", page)
    worst = re.search(r"largest deviation from the design: largest</td><td class=\"num\">"
                      r"([\d.]+)<", page)
    assert over and int(over[1]) == check["over"]
    assert worst and float(worst[1]) == pytest.approx(check["worst"], rel=5e-4)


def test_optimize_near_its_reference_ends_in_exit_0(tmp_path):
    out = tmp_path / "o.obj"
    assert main(["optimize", str(CMC1), "--net", "cmc", "--reference", str(CMC1),
                 "-o", str(out), "-q"]) == 0
    check = json.loads(out.with_suffix(".json").read_text())["properties"]["limits"][
        "max_deviation_mm"]
    assert check["over"] == 0 and 0 < check["worst"] < 20.0


def test_optimize_without_a_reference_checks_no_deviation(tmp_path):
    out = tmp_path / "o.obj"
    assert main(["optimize", str(CMC1), "--net", "cmc", "-o", str(out), "-q"]) == 0
    assert "limits" not in json.loads(out.with_suffix(".json").read_text())["properties"]


@pytest.mark.parametrize("given, code", [(None, 3), ("0.06", 0)])
def test_measure_against_a_reference_holds_the_deviation_limit(tmp_path, capsys, given, code):
    """`fabplan measure --reference` holds the net to the same limit as optimize: cmc1
    against a copy 50 mm higher is past the default 20 mm (exit 3, counted in its record),
    and within a given 60 mm."""
    cmc1 = fabplan.read_obj(CMC1)
    QuadMesh(cmc1.vertices + [0.0, 0.0, 0.05], cmc1.faces).write_obj(tmp_path / "shifted.obj")
    out = tmp_path / "m.json"
    argv = ["measure", str(CMC1), "--reference", str(tmp_path / "shifted.obj"), "-o", str(out)]
    assert main(argv + ([] if given is None else ["--max-deviation", given])) == code
    check = json.loads(out.read_text())["limits"]["max_deviation_mm"]
    assert check["limit"] == (20.0 if given is None else 60.0)
    assert check["worst"] == pytest.approx(50.0, abs=0.5) and check["exceeded"] == (code == 3)
    err = capsys.readouterr().err
    assert ("exceed the largest deviation from the design" in err) == (code == 3)


def test_a_deviation_limit_is_given_in_mm_or_refused_when_larger_than_the_net(tmp_path, capsys):
    """`--max-deviation` is in the net's units: 28 meant as millimetres on a net in metres
    was a limit of 28 m, larger than the net, and no net missed it. It is refused, and
    `--max-deviation-mm` gives the limit in millimetres, as molds and strips take it."""
    cmc1 = fabplan.read_obj(CMC1)
    QuadMesh(cmc1.vertices + [0.0, 0.0, 0.05], cmc1.faces).write_obj(tmp_path / "shifted.obj")
    size = float(np.linalg.norm(np.ptp(cmc1.vertices, axis=0)))
    out = tmp_path / "m.json"
    argv = ["measure", str(CMC1), "--reference", str(tmp_path / "shifted.obj"), "-o", str(out)]
    assert main([*argv, "--max-deviation", f"{1.5 * size:g}"]) == 2 and not out.exists()
    err = capsys.readouterr().err
    assert "is in the net's units (m)" in err and "give --max-deviation-mm" in err
    assert main([*argv, "--max-deviation-mm", "40"]) == 3
    check = json.loads(out.read_text())["limits"]["max_deviation_mm"]
    assert check["limit"] == 40.0 and check["exceeded"] and check["option"] == "--max-deviation-mm"
    # the limit and the worst vertex on the terminal, as the other commands print them
    printed = capsys.readouterr().out
    assert re.search(rf"limit: {check['over']} of {check['measured']} vertices exceed the "
                     r"largest deviation from the design of 40 mm: up to ", printed), printed
    assert "distance to reference: max" in printed and "(m)" in printed
    assert main([*argv, "--max-deviation-mm", "40", "--max-deviation", "0.04"]) == 2
    # optimize holds it in the solve: the same limit either way
    nets = [tmp_path / "a.obj", tmp_path / "b.obj"]
    for net, given in zip(nets, (["--max-deviation", "0.06"], ["--max-deviation-mm", "60"]),
                          strict=True):
        assert main(["optimize", str(CMC1), "--net", "cmc", "--reference",
                     str(tmp_path / "shifted.obj"), *given, "-q", "-o", str(net)]) == 0
    a, b = (fabplan.read_obj(n).vertices for n in nets)
    assert np.array_equal(a, b)


# ---------------------------------------------------------------- deviation: molds
@pytest.fixture(scope="module")
def hypar_net(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("hypar") / "l.obj"
    assert main(["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
                 "-o", str(out), "-q"]) == 0
    return out


def _mold_report_row(folder: Path) -> str:
    page = (folder / "report.html").read_text()
    row = re.search(r"largest deviation from the design \(limit [^<]*\)</t[dh]><td>([^<]*)<", page)
    assert row, "no deviation row in the report"
    return row[1]


def test_molds_off_the_design_end_in_exit_3(hypar_net, tmp_path, capsys):
    out = tmp_path / "molds"
    assert main(["molds", str(hypar_net), "--tolerance-mm", "5", "--design",
                 "hyperbolic-paraboloid", "--max-deviation-mm", "0.01", "--no-3d",
                 "-o", str(out)]) == 3
    err = capsys.readouterr().err
    check = json.loads((out / "molds.json").read_text())["limits"]["max_deviation_mm"]
    assert check["limit"] == 0.01 and check["over"] > 0 and check["worst"] > 0.01
    assert "(--max-deviation-mm)" in _warning(err)
    # the report's figures are the JSON's
    assert _mold_report_row(out) == limit_row_text(check)
    shown = re.search(r"(\d+) of (\d+) vertices over the limit; largest ([\d.e+-]+) mm",
                      _mold_report_row(out))
    assert shown and int(shown[1]) == check["over"] and int(shown[2]) == check["measured"]
    assert float(shown[3]) == pytest.approx(check["worst"], rel=5e-4)


def test_molds_on_the_design_end_in_exit_0(hypar_net, tmp_path):
    out = tmp_path / "molds"
    assert main(["molds", str(hypar_net), "--tolerance-mm", "5", "--design",
                 "hyperbolic-paraboloid", "--no-3d", "-o", str(out), "-q"]) == 0
    check = json.loads((out / "molds.json").read_text())["limits"]["max_deviation_mm"]
    assert check["limit"] == 20.0 and check["over"] == 0
    assert _mold_report_row(out).startswith("0 of ")


def test_molds_without_a_design_check_no_deviation(hypar_net, tmp_path):
    out = tmp_path / "molds"
    assert main(["molds", str(hypar_net), "--tolerance-mm", "5", "--no-3d", "-o", str(out),
                 "-q"]) == 0
    assert json.loads((out / "molds.json").read_text())["limits"] == {}


# ---------------------------------------------------------------- deviation: strips
@pytest.mark.parametrize("limit_mm, code", [(0.01, 3), (None, 0)])
def test_strips_check_the_net_against_its_design(hypar_net, tmp_path, capsys, limit_mm, code):
    out = tmp_path / "strips"
    limit = [] if limit_mm is None else ["--max-deviation-mm", str(limit_mm)]
    assert main(["strips", str(hypar_net), *STRIPS, "--design", "hyperbolic-paraboloid", *limit,
                 "-o", str(out)]) == code
    printed, err = capsys.readouterr()
    check = json.loads((out / "strips.json").read_text())["summary"]["limits"]["max_deviation_mm"]
    assert check["limit"] == (limit_mm or 20.0) and check["measured"] == 121
    assert check["exceeded"] == (code == 3) and (check["over"] > 0) == (code == 3)
    assert 0 < check["worst"] < 1.0
    if code == 3:
        assert "(--max-deviation-mm)" in _warning(err)
    else:
        assert "limit: all 121 vertices within the largest deviation from the design of 20 mm " \
               f"(up to {check['worst']:.3g} mm)" in printed


# -------------------------------------------------------------------- the definitions
def test_the_study_names_the_shared_limits_in_the_same_words():
    from fabplan.study.checks import LIMIT_NAMES

    for name in ("max_deviation_mm", "congruence_tolerance_mm"):
        assert LIMIT_NAMES[name] == (LIMITS[name].words, LIMITS[name].unit)
