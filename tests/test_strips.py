"""Lamella strips: unrolling, arcs, slits, nesting and the DXF files, checked on what is written.

Fixture nets (model units: metres):
- ``const_net``: an exact linear Weingarten S-net of revolution whose Meusnier spheres all
  have radius 15 m (`fabplan.net.generate.rotational_weingarten_snet`, scaled by 10);
- ``anet``: an A-net on a catenoid (asymptotic lines, curved in space), from a rotational
  S-net at 90 degrees optimized with the ``anet`` preset;
- the bundled Weingarten net ``wein99`` (Meusnier radius about 20.12, staircase boundary).

The slit test reads positions from the DXF geometry (arcs, slit rectangles, TEXT labels)
with ezdxf's own bulge and path tools and compares them with arc lengths computed here from
the net's vertices, not with fabplan's internal strip data.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
from dataclasses import replace

import ezdxf
import numpy as np
import pytest
import shapely
from ezdxf import path as dxfpath
from ezdxf import recover
from ezdxf.math import bulge_to_arc

import fabplan
from fabplan.cli import main
from fabplan.errors import FabplanError, InputError
from fabplan.fabricate.strips import StripSettings, build_strips, fit_arc_runs, strip_plan, strip_polylines
from fabplan.fabricate.strips.dxf import (
    SheetGeometry,
    check_sheet,
    geometry_document,
    geometry_preview_png,
    preview_png,
    segment_problems,
    sheet_dxf_text,
    sheet_geometry,
    write_sheet_file,
)
from fabplan.fabricate.strips.nesting import Nesting, Placement, Sheet, _Candidate, _lowest_fit, check_nesting
from fabplan.fabricate.strips.strip_plan import plan_strips
from fabplan.net.generate import rotational_snet, rotational_weingarten_snet
from fabplan.net.geometry import fit_star_spheres
from fabplan.net.mesh import QuadMesh

R_MM = 15000.0           # Meusnier radius of const_net, mm
H_MM = 100.0             # lamella height
T_MM = 6.0               # material thickness
LENGTH_TOL_MM = 0.1
RADIUS_TOL_REL = 1e-3    # 0.1 %
SHEET = (3000.0, 1500.0)


@pytest.fixture(scope="module")
def const_net() -> QuadMesh:
    return rotational_weingarten_snet(8, 10, radius=1.5, angle_deg=80, scale=10)


@pytest.fixture(scope="module")
def anet() -> QuadMesh:
    start = rotational_snet(9, 9, profile="catenoid", angle_deg=90, scale=10)
    result = fabplan.optimize(start, "anet")
    assert result.converged
    return result.mesh


def _settings(**kw) -> StripSettings:
    base = dict(height_mm=H_MM, thickness_mm=T_MM, sheet_mm=SHEET)
    base.update(kw)
    return StripSettings(**base)


@pytest.fixture(scope="module")
def text_run(const_net, tmp_path_factory):
    """The constant-radius net planned and written with TEXT labels (readable ids)."""
    out = tmp_path_factory.mktemp("strips-text")
    plan = plan_strips(const_net, _settings(labels="text"))
    files = plan.write(out)
    return plan, out, files


@pytest.fixture(scope="module")
def stroke_run(const_net, tmp_path_factory):
    """The same net with the default single-stroke labels and a lap splice."""
    out = tmp_path_factory.mktemp("strips-stroke")
    plan = plan_strips(const_net, _settings(splice="lap", end="round"))
    files = plan.write(out)
    return plan, out, files


def _dxf_files(files):
    return [f for f in files if f.suffix == ".dxf"]


# ---------------------------------------------------------------------- unrolling
def test_unrolled_strips_keep_their_3d_length(const_net, anet, wein99):
    for mesh in (const_net, anet, wein99):
        strips = build_strips(mesh, _settings())
        X = mesh.vertices
        for s in strips.strips:
            length_3d = np.linalg.norm(np.diff(X[s.vertices], axis=0), axis=1).sum() * 1000
            unrolled = np.linalg.norm(np.diff(s.curve.nodes, axis=0), axis=1).sum()
            assert abs(unrolled - length_3d) < LENGTH_TOL_MM, s.id
            assert s.length_mm == pytest.approx(length_3d, abs=1e-6)


def test_constant_radius_strips_unroll_to_one_circle(const_net):
    spheres = fit_star_spheres(const_net.vertices, const_net.stars)
    assert np.allclose(spheres.radius * 1000, R_MM, rtol=1e-9)  # the fixture is exact
    strips = build_strips(const_net, _settings())
    for s in strips.strips:
        assert all(r.fitted for r in s.runs), s.id
        for radius in s.arc_radii_mm:
            assert abs(abs(radius) / R_MM - 1) < RADIUS_TOL_REL, (s.id, radius)
        # every developed node on one circle (through the first, middle and last), of radius r
        P = s.curve.nodes
        a, b, c = P[0], P[len(P) // 2], P[-1]
        d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        ux = ((a @ a) * (b[1] - c[1]) + (b @ b) * (c[1] - a[1]) + (c @ c) * (a[1] - b[1])) / d
        uy = ((a @ a) * (c[0] - b[0]) + (b @ b) * (a[0] - c[0]) + (c @ c) * (b[0] - a[0])) / d
        dist = np.linalg.norm(P - [ux, uy], axis=1)
        assert np.abs(dist - dist[0]).max() < LENGTH_TOL_MM, s.id
        assert abs(dist[0] / R_MM - 1) < RADIUS_TOL_REL, s.id


def test_wein99_strips_keep_the_meusnier_radius(wein99):
    spheres = fit_star_spheres(wein99.vertices, wein99.stars)
    r = float(np.median(spheres.radius)) * 1000
    strips = build_strips(wein99, _settings())
    radii = np.concatenate([np.abs(s.arc_radii_mm) for s in strips.strips])
    assert np.isfinite(radii).all()
    assert np.abs(radii / r - 1).max() < RADIUS_TOL_REL
    assert strips.summary()["unrolled_length_error_mm"] < 1e-6


def test_staircase_boundary_polylines_are_joined_at_valence_4_corners(wein99):
    raw = wein99.polylines
    joined = strip_polylines(wein99)
    assert len(joined) < len(raw)
    assert sum(len(v) - 1 for v in joined.vertices) == sum(len(v) - 1 for v in raw.vertices)
    corner = wein99.is_boundary_vertex & (wein99.valence == 4)
    for v in joined.vertices:
        inner = v[1:-1]
        # a joined polyline passes a boundary vertex only at a valence-4 corner
        assert np.all(~wein99.is_boundary_vertex[inner] | corner[inner])
    # only the four corner edges between two valence-2 vertices stay alone
    assert sorted(len(v) for v in joined.vertices)[:5] == [2, 2, 2, 2, 4]


def test_anet_strips_unroll_straight(anet):
    strips = build_strips(anet, _settings())
    assert strips.summary()["straight"]
    X = anet.vertices
    for s in strips.strips:
        P = s.curve.nodes
        chord = (P[-1] - P[0]) / np.linalg.norm(P[-1] - P[0])
        off = np.abs((P - P[0]) @ np.array([-chord[1], chord[0]]))
        assert off.max() < LENGTH_TOL_MM, s.id
        # the 3D polyline itself is curved: straightness comes from the development
        Q = X[s.vertices] * 1000
        dev = np.linalg.norm(np.cross(Q - Q[0], (Q[-1] - Q[0]) / np.linalg.norm(Q[-1] - Q[0])),
                             axis=1)
        if len(Q) > 4:
            assert dev.max() > 10 * LENGTH_TOL_MM


@pytest.mark.slow
def test_anet_parts_are_straight_in_the_dxf(anet, tmp_path):
    plan = plan_strips(anet, _settings())
    files = plan.write(tmp_path, previews=False)
    for f in _dxf_files(files):
        doc = ezdxf.readfile(f)
        for e in doc.modelspace().query('LWPOLYLINE[layer=="CUT"]'):
            rows = np.array(list(e.get_points("xyb")))
            assert np.all(rows[:, 2] == 0)
            poly = shapely.Polygon(rows[:, :2])
            box = poly.minimum_rotated_rectangle
            assert poly.symmetric_difference(box).area < 1.0  # mm^2: a rectangle
            sides = np.linalg.norm(np.diff(np.asarray(box.exterior.coords), axis=0), axis=1)
            assert min(sides) == pytest.approx(H_MM, abs=LENGTH_TOL_MM)


def test_noisy_polyline_falls_back_to_straight_edges():
    rng = np.random.default_rng(1)
    x = np.arange(12) * 500.0
    nodes = np.column_stack([x, rng.normal(scale=5.0, size=12)])
    runs = fit_arc_runs(nodes, 0.1)
    assert sum(r.stop - r.start for r in runs) == 11
    assert any(not r.fitted for r in runs)
    t = np.linspace(0, 1, 12)
    circle = np.column_stack([R_MM * np.sin(t), R_MM * (1 - np.cos(t))])
    assert [(r.start, r.stop, r.fitted) for r in fit_arc_runs(circle, 0.1)] == [(0, 11, True)]


# ---------------------------------------------------------------------- the written files
def _arc_radii(rows: np.ndarray) -> np.ndarray:
    n = len(rows)
    radii = []
    for i in range(n):
        if rows[i, 2] != 0:
            _, _, _, r = bulge_to_arc(rows[i, :2], rows[(i + 1) % n, :2], rows[i, 2])
            radii.append(r)
    return np.array(radii)


def _flatten(entity) -> np.ndarray:
    return np.array([(v.x, v.y) for v in dxfpath.make_path(entity).flattening(0.01)])


@pytest.mark.slow
def test_every_dxf_reads_back_clean(text_run, stroke_run):
    for plan, _, files in (text_run, stroke_run):
        W, H = plan.strips.settings.sheet_mm
        spacing = plan.strips.settings.spacing_mm
        dxfs = _dxf_files(files)
        assert len(dxfs) == plan.summary()["sheets"] >= 2
        for f in dxfs:
            doc = ezdxf.readfile(f)
            assert doc.dxfversion == "AC1024"
            assert doc.header["$INSUNITS"] == 4
            assert not doc.audit().has_errors
            _, auditor = recover.readfile(f)
            assert not auditor.has_errors
            assert {layer.dxf.name: layer.color for layer in doc.layers
                    if layer.dxf.name not in ("0", "Defpoints")} \
                == {"CUT": 1, "SLIT": 6, "ENGRAVE": 5}
            msp = doc.modelspace()
            cuts = msp.query('LWPOLYLINE[layer=="CUT"]')
            slits = msp.query('LWPOLYLINE[layer=="SLIT"]')
            assert len(cuts) and len(slits)
            assert all(e.closed for e in cuts) and all(e.closed for e in slits)
            polys = [shapely.Polygon(_flatten(e)) for e in cuts]
            sheet = shapely.box(0, 0, W, H)
            for p in polys:
                assert p.is_valid and sheet.contains(p)
            for i in range(len(polys)):
                for j in range(i + 1, len(polys)):
                    assert polys[i].distance(polys[j]) >= spacing - 1e-6
            assert segment_problems(f) == []


def test_dxf_arcs_have_the_meusnier_radius(text_run):
    plan, _, files = text_run
    seen = set()
    for f in _dxf_files(files):
        for e in ezdxf.readfile(f).modelspace().query('LWPOLYLINE[layer=="CUT"]'):
            radii = _arc_radii(np.array(list(e.get_points("xyb"))))
            inner = np.abs(radii / (R_MM - H_MM / 2) - 1) < RADIUS_TOL_REL
            outer = np.abs(radii / (R_MM + H_MM / 2) - 1) < RADIUS_TOL_REL
            assert np.all(inner | outer), radii[~(inner | outer)]
            seen.update({"inner"} if inner.any() else set())
            seen.update({"outer"} if outer.any() else set())
    assert seen == {"inner", "outer"}
    summary = plan.summary()
    assert summary["congruent"] and summary["congruence_deviation_mm"] < 0.1


def _expected_s(mesh: QuadMesh, vertices: list, node: int) -> float:
    """Arc length to a node along the circle of radius R through the unrolled nodes, from
    the net's own vertices (chord l subtends an arc 2 R asin(l / 2R))."""
    P = mesh.vertices[np.asarray(vertices)] * 1000
    chords = np.linalg.norm(np.diff(P, axis=0), axis=1)[:node]
    return float(np.sum(2 * R_MM * np.arcsin(chords / (2 * R_MM))))


def test_slits_sit_at_the_crossing_arc_length_on_both_strips(text_run, const_net):
    plan, out, files = text_run
    record = json.loads((out / "strips.json").read_text())
    parts = {p["id"]: p for p in record["parts"]}
    strips = {s["strip"]: s for s in record["strips"]}
    extension = record["settings"]["height_mm"] / 2
    width = T_MM + record["settings"]["clearance_mm"]
    found: dict = {}
    for f in _dxf_files(files):
        msp = ezdxf.readfile(f).modelspace()
        texts = [(t.dxf.text, np.array([t.dxf.align_point.x, t.dxf.align_point.y]), t.dxf.rotation)
                 for t in msp.query("TEXT")]
        slit_rects = [np.array(list(e.get_points("xy"))) for e in msp.query('LWPOLYLINE[layer=="SLIT"]')]
        for e in msp.query('LWPOLYLINE[layer=="CUT"]'):
            rows = np.array(list(e.get_points("xyb")))
            poly = shapely.Polygon(_flatten(e))
            inside = [t for t in texts if poly.contains(shapely.Point(t[1]))]
            (part_id, label_at, rotation), = [t for t in inside if re.fullmatch(r"[AB]\d+(-\d+)?", t[0])]
            # the common centre of the long edges' arcs
            centres = []
            n = len(rows)
            for i in range(n):
                if rows[i, 2] != 0:
                    c, _, _, _ = bulge_to_arc(rows[i, :2], rows[(i + 1) % n, :2], rows[i, 2])
                    centres.append((c.x, c.y))
            C = np.mean(centres, axis=0)
            tangent = np.array([math.cos(math.radians(rotation)), math.sin(math.radians(rotation))])
            u = label_at - C
            ccw = (u[0] * tangent[1] - u[1] * tangent[0]) > 0   # s grows counter-clockwise
            # the part's start: the straight radial end cut at the smaller angle along s
            ends = []
            for i in range(n):
                a, b = rows[i, :2], rows[(i + 1) % n, :2]
                if rows[i, 2] == 0 and abs(np.linalg.norm(b - a) - H_MM) < 1e-3:
                    m = (a + b) / 2
                    ends.append(math.atan2(m[1] - C[1], m[0] - C[0]))
            ref = math.atan2(u[1], u[0])

            def along(angle, ref=ref, ccw=ccw):
                d = (angle - ref + math.pi) % (2 * math.pi) - math.pi
                return d if ccw else -d

            start = min(along(a) for a in ends)
            for rect in slit_rects:
                centre = rect.mean(axis=0)
                if not poly.buffer(2.0).contains(shapely.Point(centre)):
                    continue
                sides = [(rect[i] + rect[(i + 1) % 4]) / 2 for i in range(4)]
                lengths = [np.linalg.norm(rect[(i + 1) % 4] - rect[i]) for i in range(4)]
                short = [sides[i] for i in range(4) if abs(lengths[i] - width) < 1e-6]
                assert len(short) == 2
                closed_end = min(short, key=lambda p: abs(np.linalg.norm(p - C) - R_MM))
                assert abs(np.linalg.norm(closed_end - C) - R_MM) < LENGTH_TOL_MM
                s = parts[part_id]["s_start_mm"] + R_MM * (along(math.atan2(*(closed_end - C)[::-1])) - start)
                labels = [t for t in inside if t[0].startswith("X")]
                crossing = min(labels, key=lambda t: np.linalg.norm(t[1] - centre))[0]
                mouth = max(short, key=lambda p: abs(np.linalg.norm(p - C) - R_MM))
                left = np.array([-tangent[1], tangent[0]])  # the top side
                from_top = (mouth - closed_end) @ left > 0
                strip_id = part_id.split("-")[0]
                found.setdefault(int(crossing[1:]), {})[strip_id] = (s, from_top)
            if parts[part_id]["index"] == 1:
                assert parts[part_id]["s_start_mm"] == pytest.approx(-extension)
    crossings = record["crossings"]
    assert len(found) == len(crossings) == plan.summary()["crossings"]
    for c in crossings:
        seen = found[c["id"]]
        assert set(seen) == set(c["strips"])
        for strip_id in c["strips"]:
            vertices = strips[strip_id]["vertices"]
            expected = _expected_s(const_net, vertices, vertices.index(c["vertex"]))
            s, from_top = seen[strip_id]
            assert abs(s - expected) < LENGTH_TOL_MM, (c["id"], strip_id, s, expected)
            assert from_top == strip_id.startswith("A")


@pytest.mark.slow
def test_slit_width_and_outline_height_follow_the_kerf(const_net, tmp_path):
    kerf = 0.3
    plan = plan_strips(const_net, _settings(kerf_mm=kerf, spacing_mm=12))
    files = plan.write(tmp_path, previews=False)
    clearance = plan.strips.settings.clearance_mm
    doc = ezdxf.readfile(_dxf_files(files)[0])
    for e in doc.modelspace().query('LWPOLYLINE[layer=="SLIT"]'):
        P = np.array(list(e.get_points("xy")))
        sides = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        assert sides.min() == pytest.approx(T_MM + clearance - kerf, abs=1e-9)
    for e in doc.modelspace().query('LWPOLYLINE[layer=="CUT"]'):
        radii = _arc_radii(np.array(list(e.get_points("xyb"))))
        assert radii.max() - radii.min() == pytest.approx(H_MM + kerf, abs=1e-3)


def _band_area(plan, strip) -> float:
    """Area of a whole strip: mid-line length (ends included) times the height, plus the
    two half discs of round ends (the slits are separate cuts)."""
    s = plan.strips.settings
    area = s.height_mm * (strip.cut_length_mm + 2 * s.extension_mm)
    return area + (math.pi * s.height_mm ** 2 / 4 if s.end == "round" else 0.0)


def test_lap_splices_share_the_strip_without_overlap(stroke_run):
    plan, _, _ = stroke_run
    split = 0
    for k, strip in enumerate(plan.strips.strips):
        parts = [p for p in plan.parts if p.strip == k]
        split += len(parts) > 1
        # parts stay in their strip's development frame: the half-height tongues of a lap
        # are complementary, so the parts tile the strip exactly
        union = shapely.union_all([p.polygon for p in parts])
        assert sum(p.polygon.area for p in parts) == pytest.approx(union.area, rel=1e-6)
        assert union.area == pytest.approx(_band_area(plan, strip), rel=1e-5)
        for a, b in zip(parts, parts[1:], strict=False):
            (shared,) = {sp for sp in a.splices} & {sp for sp in b.splices}
            assert shared[2] - shared[1] == pytest.approx(plan.strips.settings.splice_mm)
    assert split >= 5


def test_overlap_splices_double_the_material_over_the_splice(text_run):
    plan, _, _ = text_run
    L, h = plan.strips.settings.splice_mm, plan.strips.settings.height_mm
    for k, strip in enumerate(plan.strips.strips):
        parts = [p for p in plan.parts if p.strip == k]
        total = sum(p.polygon.area for p in parts)
        assert total == pytest.approx(_band_area(plan, strip) + (len(parts) - 1) * L * h, rel=1e-5)


def test_round_ends_are_semicircles_in_the_dxf(stroke_run):
    _, _, files = stroke_run
    caps = 0
    for f in _dxf_files(files):
        for e in ezdxf.readfile(f).modelspace().query('LWPOLYLINE[layer=="CUT"]'):
            rows = np.array(list(e.get_points("xyb")))
            semis = np.flatnonzero(np.isclose(np.abs(rows[:, 2]), 1.0))
            for i in semis:
                _, _, _, r = bulge_to_arc(rows[i, :2], rows[(i + 1) % len(rows), :2], rows[i, 2])
                assert r == pytest.approx(H_MM / 2, abs=1e-9)
            caps += len(semis)
    assert caps == 2 * len(stroke_run[0].strips.strips)


@pytest.mark.slow
def test_schedule_lists_every_strip_with_its_sheets(text_run):
    plan, out, _ = text_run
    lines = (out / "strips.csv").read_text().splitlines()
    assert lines[0].startswith("# fabplan strip schedule")
    header = lines[1].split(",")
    assert header[:6] == ["strip", "family", "length_mm", "cut_length_mm", "radius_mm", "crossings"]
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[2:]]
    assert len(rows) == len(plan.strips.strips)
    for row, strip in zip(rows, plan.strips.strips, strict=True):
        assert row["strip"] == strip.id
        assert float(row["radius_mm"]) == pytest.approx(R_MM, rel=RADIUS_TOL_REL)
        assert float(row["length_mm"]) == pytest.approx(strip.length_mm, abs=0.01)
        assert row["sheets"] and all(1 <= int(s) <= plan.summary()["sheets"]
                                     for s in row["sheets"].split())
    record = json.loads((out / "strips.json").read_text())
    assert record["summary"]["congruent"] is True
    assert 0 < record["summary"]["material_use"] < 1
    assert sorted(record["files"]) == sorted(f.name for f in out.iterdir())


@pytest.mark.slow
def test_labels_as_outlines_and_one_file(const_net, tmp_path):
    plan = plan_strips(const_net, _settings(labels="outline", one_file=True))
    files = plan.write(tmp_path, previews=False)
    dxfs = _dxf_files(files)
    assert [f.name for f in dxfs] == ["strips-sheets.dxf"]
    check_sheet(dxfs[0], plan.strips.settings, plan.summary()["sheets"])
    doc = ezdxf.readfile(dxfs[0])
    engrave = doc.modelspace().query('LWPOLYLINE[layer=="ENGRAVE"]')
    assert sum(e.closed for e in engrave) > 10 * len(plan.parts)  # glyph outlines
    frames = doc.modelspace().query('LWPOLYLINE[layer=="SHEET"]')
    assert len(frames) == plan.summary()["sheets"]
    assert doc.layers.get("SHEET").dxf.plot == 0


@pytest.mark.slow
def test_custom_layers(const_net, tmp_path):
    layers = {"cut": ("LASER_CUT", 2), "slit": ("LASER_SLOT", 3), "engrave": ("MARK", 4)}
    plan = plan_strips(const_net, _settings(layers=layers))
    files = plan.write(tmp_path, previews=False)
    doc = ezdxf.readfile(_dxf_files(files)[0])
    assert {layer.dxf.name: layer.color for layer in doc.layers
                    if layer.dxf.name not in ("0", "Defpoints")} == \
        {"LASER_CUT": 2, "LASER_SLOT": 3, "MARK": 4}


# ---------------------------------------------------------------------- written as planned
def _placed_rows(plan, placement) -> np.ndarray:
    """A part's outline rows ``x, y, bulge`` on its sheet, from the placement's angle and
    offset (a rotation keeps the bulges)."""
    a = math.radians(placement.angle_deg)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    outline = plan.parts[placement.part].outline
    return np.column_stack([outline[:, :2] @ R.T + placement.offset, outline[:, 2]])


@pytest.mark.parametrize("run", ["text_run", "stroke_run"])
def test_written_dxf_holds_the_planned_parts_to_1e9_mm(run, request):
    """The files are no longer read back when written: read them here, independently."""
    plan, out, files = request.getfixturevalue(run)
    record = json.loads((out / "strips.json").read_text())
    settings = plan.strips.settings
    for sheet in plan.nesting.sheets:
        name = record["parts"][sheet.placements[0].part]["file"]
        doc = ezdxf.readfile(out / name)
        assert len(doc.audit().errors) == 0
        msp = doc.modelspace()
        cut = [np.array(list(e.get_points("xyb"))) for e in msp.query("LWPOLYLINE")
               if e.dxf.layer == settings.layers["cut"][0]]
        slits = [np.array(list(e.get_points("xy"))) for e in msp.query("LWPOLYLINE")
                 if e.dxf.layer == settings.layers["slit"][0]]
        assert len(cut) == len(sheet.placements)
        assert len(slits) == sum(len(plan.parts[p.part].slits) for p in sheet.placements)
        for rows, placement in zip(cut, sheet.placements, strict=True):
            expected = _placed_rows(plan, placement)
            assert rows.shape == expected.shape
            assert np.abs(rows - expected).max() < 1e-9
        k = 0
        for placement in sheet.placements:
            a = math.radians(placement.angle_deg)
            R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            for rect in plan.parts[placement.part].slits:
                assert np.abs(slits[k] - (rect[:, :2] @ R.T + placement.offset)).max() < 1e-9
                k += 1


def _masked(data: bytes) -> list:
    """DXF lines with the header's dates and GUIDs and ezdxf's creation stamp masked."""
    lines = data.split(b"\n")
    for i in range(len(lines) - 2):
        if lines[i].strip() in (b"$TDCREATE", b"$TDUCREATE", b"$TDUPDATE", b"$TDUUPDATE"):
            lines[i + 2] = b""
    return [re.sub(rb"\{[0-9A-F-]{36}\}", b"", re.sub(rb" @ \d{4}-\S*", b"", line))
            for line in lines]


@pytest.mark.slow
def test_sheets_written_in_two_processes_equal_those_written_in_one(stroke_run, tmp_path,
                                                                    monkeypatch):
    plan, out, files = stroke_run
    monkeypatch.setattr(strip_plan, "SHEETS_PER_PROCESS", 1)
    two = plan.write(tmp_path, workers=2)
    assert [f.name for f in two] == [f.name for f in files]
    for f in _dxf_files(files):
        assert _masked((tmp_path / f.name).read_bytes()) == _masked(f.read_bytes())
    assert (tmp_path / "strips.csv").read_bytes() == (out / "strips.csv").read_bytes()


@pytest.mark.slow
def test_a_sheet_failing_in_a_worker_process_leaves_no_files(stroke_run, tmp_path, monkeypatch):
    plan, _, _ = stroke_run
    assert len(plan.nesting.sheets) >= 2
    (tmp_path / "keep.txt").write_text("earlier")
    from fabplan.fabricate.strips import dxf

    real = dxf.write_sheet_file

    def failing(geom, settings, path):
        if path.name.endswith("-002.dxf"):
            raise FabplanError(f"{path.name}: refused")
        return real(geom, settings, path)

    # the worker processes are forked from this one and see the patched function
    monkeypatch.setattr(dxf, "write_sheet_file", failing)
    monkeypatch.setattr(strip_plan, "SHEETS_PER_PROCESS", 1)
    with pytest.raises(FabplanError, match="-002.dxf: refused"):
        plan.write(tmp_path, workers=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_sheet_geometry_preview_equals_the_document_preview(text_run, stroke_run, tmp_path):
    from matplotlib.image import imread

    for plan, _, _ in (text_run, stroke_run):
        settings = plan.strips.settings
        geom = sheet_geometry(plan.nesting, [plan.nesting.sheets[0]], settings)
        geometry_preview_png(geom, settings, tmp_path / "a.png", title="sheet 1")
        preview_png(geometry_document(geom, settings), tmp_path / "b.png", settings.sheet_mm,
                    title="sheet 1")
        a, b = imread(tmp_path / "a.png"), imread(tmp_path / "b.png")
        assert a.shape == b.shape and np.array_equal(a, b)
        assert (a[..., :3] < 0.5).any()  # something is drawn


@pytest.mark.parametrize("labels", ["stroke", "outline", "text"])
def test_written_sheet_text_holds_what_the_ezdxf_document_holds(text_run, labels):
    # the file text is written without ezdxf's entities: read back, it must hold ezdxf's own
    # document of the same sheets entity by entity, to the bit, and pass ezdxf's audit
    import io

    plan = text_run[0]
    settings = replace(plan.strips.settings, labels=labels)
    for sheets in ([plan.nesting.sheets[0]], plan.nesting.sheets[:3]):      # one, side by side
        geom = sheet_geometry(plan.nesting, sheets, settings)
        mine = ezdxf.read(io.StringIO(sheet_dxf_text(geom, settings)))
        theirs = geometry_document(geom, settings)
        assert not mine.audit().errors and mine.dxfversion == "AC1024"
        assert mine.header["$INSUNITS"] == 4
        width = geom.size[0] * len(sheets) + 100.0 * (len(sheets) - 1)      # 100 mm between
        assert mine.header["$EXTMAX"] == theirs.header["$EXTMAX"] == (width, geom.size[1], 0)
        assert [(y.dxf.name, y.color) for y in mine.layers] == \
            [(y.dxf.name, y.color) for y in theirs.layers]
        ours, ref = list(mine.modelspace()), list(theirs.modelspace())
        assert len(ours) == len(ref) > 0
        for a, b in zip(ours, ref, strict=True):
            assert (a.dxftype(), a.dxf.layer) == (b.dxftype(), b.dxf.layer)
            if a.dxftype() == "LWPOLYLINE":
                assert a.closed == b.closed
                assert list(a.get_points("xyb")) == list(b.get_points("xyb"))
            else:
                assert (a.dxf.text, a.dxf.height, a.dxf.rotation, a.dxf.align_point) == \
                    (b.dxf.text, b.dxf.height, b.dxf.rotation, b.dxf.align_point)
        handles = [e.dxf.handle for e in mine.entitydb.values()]
        assert len(handles) == len(set(handles))
        assert int(mine.header["$HANDSEED"], 16) > max(int(h, 16) for h in handles)


def test_write_sheet_file_refuses_overlapping_outlines_before_writing(tmp_path):
    settings = _settings()
    square = np.array([[10, 10, 0], [200, 10, 0], [200, 100, 0], [10, 100, 0]], dtype=float)
    geom = SheetGeometry(size=settings.sheet_mm, sheet_count=1, layers=["cut", "cut"],
                         shapes=[square, square + [100, 20, 0]], closed=[True, True])
    with pytest.raises(FabplanError, match="bad.dxf: two outlines are closer than the spacing"):
        write_sheet_file(geom, settings, tmp_path / "bad.dxf")
    assert not (tmp_path / "bad.dxf").exists()
    geom.shapes[1] = square + [300, 0, 0]
    digest = write_sheet_file(geom, settings, tmp_path / "good.dxf")
    import hashlib

    assert hashlib.sha256((tmp_path / "good.dxf").read_bytes()).hexdigest() == digest
    assert check_sheet(tmp_path / "good.dxf", settings).outlines[1][0, 0] == 310.0


def test_write_sheet_file_notices_bytes_changed_on_the_way_to_disk(tmp_path, monkeypatch):
    from pathlib import Path

    settings = _settings()
    square = np.array([[10, 10, 0], [200, 10, 0], [200, 100, 0], [10, 100, 0]], dtype=float)
    geom = SheetGeometry(size=settings.sheet_mm, sheet_count=1, layers=["cut"],
                         shapes=[square], closed=[True])
    write = Path.write_bytes
    monkeypatch.setattr(Path, "write_bytes", lambda self, data: write(self, data[:-1]))
    with pytest.raises(FabplanError, match="differs from the bytes written"):
        write_sheet_file(geom, settings, tmp_path / "sheet.dxf")


def test_lowest_fit_equals_measuring_every_window():
    """Ruling places out by sampled cells finds the same place as the full measure."""
    rng = np.random.default_rng(7)
    for trial in range(200):
        n, nx = 300, int(rng.integers(1, 120))
        S = np.maximum.accumulate(rng.random(n)) * rng.uniform(0, 900) if trial % 2 else \
            rng.random(n) * rng.uniform(0, 900)
        lower = rng.random(nx) * 80
        height = float(lower.max() + rng.uniform(0, 400))
        probes = np.unique(np.linspace(0, nx - 1, min(nx, 16)).astype(np.intp))
        c = _Candidate(angle=0.0, shift=np.zeros(2), lower=lower, upper=lower, pad=0,
                       height=height, probes=probes)
        y = np.maximum((np.lib.stride_tricks.sliding_window_view(S, nx) - lower).max(axis=1), 0)
        ok = np.flatnonzero(y + height <= 1000.0)
        expected = None if ok.size == 0 else (int(ok[np.argmin(y[ok] + height)]),
                                               float(y[ok[np.argmin(y[ok] + height)]]))
        assert _lowest_fit(S, c, 1000.0) == expected


# ---------------------------------------------------------------------- checks of the checks
def test_segment_problems_finds_duplicates_and_zero_length():
    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 10)], dxfattribs={"layer": "A"})
    msp.add_lwpolyline([(10, 0), (0, 0)], dxfattribs={"layer": "B"})
    msp.add_lwpolyline([(5, 5), (5, 5), (6, 6)], dxfattribs={"layer": "A"})
    problems = segment_problems(doc)
    assert any("duplicate" in p for p in problems)
    assert any("zero-length" in p for p in problems)


def test_check_sheet_refuses_overlapping_outlines(tmp_path):
    settings = _settings()
    doc = ezdxf.new("R2010", units=4)
    doc.layers.add("CUT", color=1)
    msp = doc.modelspace()
    msp.add_lwpolyline([(10, 10), (200, 10), (200, 100), (10, 100)], close=True,
                       dxfattribs={"layer": "CUT"})
    msp.add_lwpolyline([(150, 50), (300, 50), (300, 150), (150, 150)], close=True,
                       dxfattribs={"layer": "CUT"})
    doc.saveas(tmp_path / "bad.dxf")
    with pytest.raises(FabplanError, match="closer than the spacing"):
        check_sheet(tmp_path / "bad.dxf", settings)


def test_check_nesting_refuses_overlapping_parts(text_run):
    plan, _, _ = text_run
    settings = plan.strips.settings
    twice = [Placement(0, 0.0, (500.0, 500.0)), Placement(1, 0.0, (500.0, 500.0))]
    layout = Nesting(sheets=[Sheet(1, settings.sheet_mm, twice)], parts=plan.parts,
                    settings=settings)
    with pytest.raises(FabplanError, match="closer than the spacing|margin"):
        check_nesting(layout)


# ---------------------------------------------------------------------- pictures
def test_sheet_renders_with_ezdxf_drawing(text_run, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from ezdxf.addons.drawing.matplotlib import qsave
    from matplotlib.image import imread

    _, _, files = text_run
    doc = ezdxf.readfile(_dxf_files(files)[0])
    png = tmp_path / "sheet.png"
    qsave(doc.modelspace(), str(png), bg="#FFFFFF", dpi=100, size_inches=(15, 7.5))
    img = imread(png)[..., :3]
    red = (img[..., 0] > 0.7) & (img[..., 1] < 0.4) & (img[..., 2] < 0.4)
    blue = (img[..., 2] > 0.6) & (img[..., 0] < 0.4) & (img[..., 1] < 0.4)
    magenta = (img[..., 0] > 0.7) & (img[..., 2] > 0.7) & (img[..., 1] < 0.4)
    assert red.sum() > 2000 and blue.sum() > 50 and magenta.sum() > 20


@pytest.mark.skipif(shutil.which("librecad") is None or shutil.which("pdftoppm") is None,
                    reason="LibreCAD or poppler-utils not installed")
def test_librecad_converts_a_sheet(text_run, tmp_path):
    from matplotlib.image import imread

    _, _, files = text_run
    sheet = tmp_path / "sheet.dxf"
    shutil.copy(_dxf_files(files)[0], sheet)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    subprocess.run(["librecad", "dxf2pdf", "-a", sheet.name], cwd=tmp_path, env=env,
                   check=True, timeout=120, capture_output=True)
    assert (tmp_path / "sheet.pdf").stat().st_size > 1000
    subprocess.run(["pdftoppm", "-png", "-r", "60", "sheet.pdf", "page"], cwd=tmp_path,
                   check=True, timeout=60, capture_output=True)
    img = imread(next(tmp_path.glob("page*.png")))[..., :3]
    red = (img[..., 0] > 0.7) & (img[..., 1] < 0.4) & (img[..., 2] < 0.4)
    assert red.sum() > 500


# ---------------------------------------------------------------------- CLI and bad input
@pytest.mark.slow
def test_cli_writes_the_strip_files(const_net, tmp_path, capsys):
    net = tmp_path / "net.obj"
    const_net.write_obj(net)
    out = tmp_path / "out"
    code = main(["strips", str(net), "--height", "100", "--thickness", "6", "--units", "m",
                 "--sheet", "3000x1500", "--spacing", "12", "--kerf", "0.2", "-o", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "congruent" in printed and "sheets of 3000x1500 mm" in printed
    names = {f.name for f in out.iterdir()}
    assert {"strips.csv", "strips.json", "strips-sheet-001.dxf", "strips-sheet-001.png"} <= names
    # a second run with bigger sheets replaces the earlier sheets, leaving none behind
    code = main(["strips", str(net), "--height", "100", "--thickness", "6", "--sheet",
                 "6000x3000", "-o", str(out)])
    assert code == 0
    record = json.loads((out / "strips.json").read_text())
    assert sorted(record["files"]) == sorted(f.name for f in out.iterdir())


def _triangle_obj(path):
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    return path


@pytest.mark.parametrize("case", ["no-polylines", "height-zero", "height-negative",
                                  "sheet-too-small", "bad-sheet", "bad-layer"])
def test_bad_input_exits_2_with_one_line_and_no_files(case, const_net, tmp_path, capsys):
    net = tmp_path / "net.obj"
    const_net.write_obj(net)
    args = {"no-polylines": [str(_triangle_obj(tmp_path / "tri.obj")), "--height", "100",
                             "--thickness", "6"],
            "height-zero": [str(net), "--height", "0", "--thickness", "6"],
            "height-negative": [str(net), "--height", "-5", "--thickness", "6"],
            "sheet-too-small": [str(net), "--height", "100", "--thickness", "6",
                                "--sheet", "300x100"],
            "bad-sheet": [str(net), "--height", "100", "--thickness", "6", "--sheet", "big"],
            "bad-layer": [str(net), "--height", "100", "--thickness", "6", "--layer",
                          "cut=A<B"]}[case]
    out = tmp_path / "out"
    code = main(["strips", *args, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("fabplan: error:")
    assert not out.exists()
    assert not list(tmp_path.glob(".out*"))  # no temporary folder left either


def test_sheet_too_small_for_a_bay_names_the_strip(const_net):
    with pytest.raises(InputError, match="too small for strip"):
        plan_strips(const_net, _settings(sheet_mm=(250.0, 400.0)))
