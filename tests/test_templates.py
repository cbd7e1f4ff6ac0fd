"""Every bundled template runs as it is and shows what it is for (read from study.json).

- stadium: a linear Weingarten candidate is feasible and needs far fewer molds than the
  baseline, within the deviation limit;
- pavilion: a constant-radius candidate has congruent strips (one arc radius) that read
  back from their DXF files, where the baseline's are not congruent;
- tower: the characteristic conjugate candidate has planar panels, the baseline not;
- canopy: the minimal candidate is a minimal surface within the deviation limit.
"""

from __future__ import annotations

import json

import ezdxf
import pytest

from fabplan.cli import main
from fabplan.study_spec import read_study, template_names, template_path


def _run(name: str, folder) -> dict:
    assert main(["study", name, "-o", str(folder), "-q"]) == 0
    record = json.loads((folder / "study.json").read_text(encoding="utf-8"))
    assert (folder / "report.html").stat().st_size > 100_000          # pictures embedded
    assert all(c["error"] is None for c in record["candidates"]), \
        [c["error"] for c in record["candidates"]]
    return record


def _by_net(record: dict, net: str) -> list:
    return [c for c in record["candidates"] if c["net"] == net and not c["baseline"]]


def _baseline(record: dict) -> dict:
    return next(c for c in record["candidates"] if c["baseline"])


def test_stadium_linear_weingarten_needs_far_fewer_molds(tmp_path):
    record = _run("stadium", tmp_path / "stadium")
    limits = read_study(template_path("stadium")).limits
    base = _baseline(record)["metrics"]
    feasible = [c for c in _by_net(record, "linear-weingarten") if c["feasible"]]
    assert feasible
    best = min(feasible, key=lambda c: c["metrics"]["molds"]["count"])["metrics"]
    assert best["deviation_mm"]["max"] <= limits.max_deviation_mm
    assert best["molds"]["count"] <= 0.7 * base["molds"]["count"]
    per_panel = best["molds"]["count"] / best["panels"]
    assert per_panel <= 0.5 * base["molds"]["count"] / base["panels"]
    assert record["recommended"] in {c["name"] for c in feasible}


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


def test_tower_characteristic_conjugate_panels_are_planar(tmp_path):
    record = _run("tower", tmp_path / "tower")
    limits = read_study(template_path("tower")).limits
    c = _by_net(record, "char-conjugate")[0]
    assert c["feasible"]
    assert c["metrics"]["planarity_mm"]["max"] <= limits.planarity_tolerance_mm
    base = _baseline(record)
    assert base["metrics"]["planarity_mm"]["max"] > 10 * limits.planarity_tolerance_mm
    assert not base["feasible"]
    assert any(ck["limit"] == "planarity_tolerance_mm" and not ck["ok"] for ck in base["checks"])


def test_canopy_minimal_surface_within_the_limit(tmp_path):
    record = _run("canopy", tmp_path / "canopy")
    c = _by_net(record, "minimal")[0]
    assert c["feasible"] and c["metrics"]["converged"]
    assert c["metrics"]["strips"]["straight"]               # A-net lamellas unroll straight


@pytest.mark.parametrize("name", ["stadium", "pavilion", "tower", "canopy"])
def test_templates_are_bundled(name):
    assert name in template_names()
