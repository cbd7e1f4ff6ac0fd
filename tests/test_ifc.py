"""IFC export (`--ifc`): read back with IfcOpenShell's geometry engine and validator, and
opened by a second, independent reader (web-ifc, through Node).

Everything checked here is recomputed from the files: the OBJ's vertices by a reader of
this module's own, the panels' areas from the triangles IfcOpenShell's geometry engine
gives, the molds from ``panels.csv``.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fabplan
from fabplan.cli import main

pytest.importorskip("ifcopenshell")
import ifcopenshell  # noqa: E402
import ifcopenshell.geom  # noqa: E402
import ifcopenshell.util.element  # noqa: E402
import ifcopenshell.util.unit  # noqa: E402
import ifcopenshell.validate  # noqa: E402

WEIN99 = fabplan.data_path("wein99.obj")
HYPAR = "hyperbolic-paraboloid:width=8,depth=8,rise=2.5"
WEB_IFC = "web-ifc@0.0.78"
NODE_CHECK = Path(__file__).with_name("web_ifc_check.cjs")


def _obj(path: Path) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices and faces of an OBJ file (a reader of the test's own)."""
    vertices, faces = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            vertices.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    return np.array(vertices), faces


def _shapes(model, elements) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """element id -> (vertices (k, 3), triangles (t, 3)) from IfcOpenShell's geometry
    engine, in world coordinates and the file's own units."""
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    settings.set("convert-back-units", True)
    settings.set("weld-vertices", False)
    out = {}
    iterator = ifcopenshell.geom.iterator(settings, model, 1, include=list(elements),
                                          geometry_library="hybrid-cgal-simple-opencascade")
    assert iterator.initialize()
    while True:
        shape = iterator.get()
        out[shape.id] = (np.array(shape.geometry.verts).reshape(-1, 3),
                         np.array(shape.geometry.faces).reshape(-1, 3))
        if not iterator.next():
            break
    return out


def _area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    T = vertices[triangles]
    return float(0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum())


def _volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    T = vertices[triangles]
    return float(np.einsum("ij,ij->i", T[:, 0], np.cross(T[:, 1], T[:, 2])).sum() / 6.0)


def _props(element) -> dict:
    return ifcopenshell.util.element.get_psets(element)


def _validation_errors(path: Path, *, rules: bool) -> list:
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(ifcopenshell.open(str(path)), logger, express_rules=rules)
    return [s for s in logger.statements if s.get("level") == "error"]


@pytest.fixture(scope="module")
def wein(tmp_path_factory) -> Path:
    """`fabplan molds wein99.obj --tolerance-mm 5 --ifc`."""
    out = tmp_path_factory.mktemp("ifc") / "molds"
    assert main(["molds", str(WEIN99), "--tolerance-mm", "5", "--ifc", "-q", "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def hypar(tmp_path_factory) -> Path:
    """A laid-out net with boundary panels, its molds and its strips, each with --ifc."""
    folder = tmp_path_factory.mktemp("ifc-hypar")
    net = folder / "net.obj"
    assert main(["layout", HYPAR, "--net", "snet", "--panel-size", "1.5", "--triangles", "4000",
                 "--ifc", "-q", "-o", str(net)]) == 0
    assert main(["molds", str(net), "--tolerance-mm", "5", "--ifc", "-q", "-o", str(folder / "molds")]) == 0
    assert main(["strips", str(net), "--height", "120", "--thickness", "6", "--ifc", "-q",
                 "-o", str(folder / "strips")]) in (0, 3)
    return folder


def test_one_plate_per_panel_with_the_mold_of_panels_csv(wein):
    model = ifcopenshell.open(str(wein / "net.ifc"))
    _, faces = _obj(WEIN99)
    plates = model.by_type("IfcPlate")
    assert len(plates) == len(faces)
    rows = list(csv.DictReader((wein / "panels.csv").open()))
    by_face = {}
    for plate in plates:
        props = _props(plate)["fabplan_Panel"]
        by_face[props["FaceId"]] = props
    assert sorted(by_face) == list(range(len(faces)))
    for row in rows:
        props = by_face[int(row["face"])]
        assert props["MoldId"] == int(row["mold"])
        assert props["PanelClass"] == row["type"]
        assert props["FitsMold"] == (row["fits"] == "yes")
        # deviation in the file's units (metres here), panels.csv in mm to 4 decimals
        assert props["DeviationFromMold"] * 1000 == pytest.approx(float(row["deviation_mm"]), abs=6e-5)
    # every mold is a group of exactly its panels
    groups = {g.Name: g for g in model.by_type("IfcGroup") if g.ObjectType == "mold"}
    for name, group in groups.items():
        members = {_props(p)["fabplan_Panel"]["FaceId"]
                   for rel in group.IsGroupedBy for p in rel.RelatedObjects}
        mold = int(name.split()[-1])
        assert members == {int(r["face"]) for r in rows if int(r["mold"]) == mold}
    assert len(groups) == len({r["mold"] for r in rows})


@pytest.mark.slow
def test_a_material_gives_each_plate_its_class_and_the_plates_their_material(tmp_path):
    """`molds --material ... --ifc`: every plate carries its class as panels.csv has it and
    whether its mold is made (molds.json), and the plates are of the material."""
    out = tmp_path / "molds"
    assert main(["molds", str(WEIN99), "--tolerance-mm", "5", "--material", "aluminium:3mm",
                 "--ifc", "-q", "-o", str(out)]) == 0
    model = ifcopenshell.open(str(out / "net.ifc"))
    record = json.loads((out / "molds.json").read_text())
    made = {m["id"]: m["made"] for m in record["molds"]}
    rows = {int(r["face"]): r for r in csv.DictReader((out / "panels.csv").open())}
    plates = model.by_type("IfcPlate")
    assert len(plates) == len(rows)
    classes = set()
    for plate in plates:
        props = _props(plate)["fabplan_Panel"]
        row = rows[props["FaceId"]]
        assert props["MaterialClass"] == row["class"]
        assert props["MoldMade"] is made[int(row["mold"])]
        classes.add(row["class"])
        material = ifcopenshell.util.element.get_material(plate)
        assert material is not None and material.Name == record["panel_classes"]["material"]["label"]
    assert len(classes) >= 2          # aluminium sheet bends most panels cold: a real mix


def test_plate_vertices_are_the_obj_vertices_and_the_area_the_mold_reports(wein):
    model = ifcopenshell.open(str(wein / "net.ifc"))
    X, faces = _obj(WEIN99)
    plates = model.by_type("IfcPlate")
    shapes = _shapes(model, plates)
    assert len(shapes) == len(plates)
    total = 0.0
    extent = np.ptp(X, axis=0).max()
    precision, = {c.Precision for c in model.by_type("IfcGeometricRepresentationContext")
                  if not c.is_a("IfcGeometricRepresentationSubContext")}
    assert precision == pytest.approx(1e-6)           # a micrometre, in metres
    for plate in plates:
        props = _props(plate)["fabplan_Panel"]
        vertices, triangles = shapes[plate.id()]
        corners = X[faces[props["FaceId"]]]
        # each corner of the OBJ's face is a vertex of the plate, to the file's precision
        gap = np.abs(corners[:, None, :] - vertices[None, :, :]).max(axis=2).min(axis=1)
        assert gap.max() <= 0.5 * precision * (1 + 1e-9) + 1e-15 * extent
        # the surface stays near its face: off its mean plane by a tenth of a diagonal at most
        normal = np.cross(corners[2] - corners[0], corners[3] - corners[1])
        diagonal = max(np.linalg.norm(corners[2] - corners[0]), np.linalg.norm(corners[3] - corners[1]))
        off = np.abs((vertices - corners.mean(axis=0)) @ normal).max() / np.linalg.norm(normal)
        assert off < 0.1 * diagonal
        area = _area(vertices, triangles)
        assert props["Area"] == pytest.approx(area, rel=1e-5)    # coordinates to a micrometre
        total += area
    reported = json.loads((wein / "molds.json").read_text())["panel_area"]
    assert reported["units"] == "m^2"
    assert abs(total - reported["total"]) <= 1e-6 * reported["total"]
    # the panel surface is curved: more area than the flat quads, by a small share
    flat = sum(0.5 * np.linalg.norm(np.cross(X[f[2]] - X[f[0]], X[f[3]] - X[f[1]])) for f in faces)
    assert flat < total < 1.02 * flat


def test_structure_units_and_nodes(wein):
    model = ifcopenshell.open(str(wein / "net.ifc"))
    assert model.schema == "IFC4"
    project, = model.by_type("IfcProject")
    assert ifcopenshell.util.unit.calculate_unit_scale(model) == 1.0     # metres
    site, = project.IsDecomposedBy[0].RelatedObjects
    building, = site.IsDecomposedBy[0].RelatedObjects
    assembly, = building.ContainsElements[0].RelatedElements
    assert assembly.is_a("IfcElementAssembly")
    parts = {p.id() for rel in assembly.IsDecomposedBy for p in rel.RelatedObjects}
    assert parts == {p.id() for p in model.by_type("IfcPlate")}
    X, faces = _obj(WEIN99)
    nodes = model.by_type("IfcStructuralPointConnection")
    points = np.array([n.Representation.Representations[0].Items[0].VertexGeometry.Coordinates
                       for n in nodes])
    ids = [int(n.Name.split()[-1]) for n in nodes]
    assert sorted(ids) == list(range(len(X)))
    assert np.abs(points - X[ids]).max() <= 0.5e-6 * (1 + 1e-9)
    edges = {tuple(sorted((f[k], f[(k + 1) % len(f)]))) for f in faces for k in range(len(f))}
    members = model.by_type("IfcStructuralCurveMember")
    assert {tuple(int(v) for v in m.Name.split()[1].split("-")) for m in members} == edges
    assert all(len(m.ConnectedBy) == 2 for m in members)


@pytest.mark.slow
def test_validate_reports_no_error_on_wein99(wein):
    assert _validation_errors(wein / "net.ifc", rules=True) == []


def test_boundary_panels_and_lamellas(hypar):
    model = ifcopenshell.open(str(hypar / "molds" / "net.ifc"))
    X, faces = _obj(hypar / "net.obj")
    rows = list(csv.DictReader((hypar / "molds" / "boundary-panels.csv").open()))
    plates = model.by_type("IfcPlate")
    # a sliver cut in one piece with its full panel is part of that panel's plate
    slivers = [k for k, r in enumerate(rows) if r["kind"] == "extension"]
    assert rows and len(plates) == len(faces) + len(rows) - len(slivers)
    shapes = _shapes(model, plates)
    record = json.loads((hypar / "molds" / "molds.json").read_text())
    boundary_area = net_area = 0.0
    cut_X, cut_faces = _obj(hypar / "molds" / "boundary-panels.obj")
    for plate in plates:
        props = _props(plate)["fabplan_Panel"]
        area = _area(*shapes[plate.id()])
        if props["PanelKind"] == "net panel":
            net_area += area
            # the plate holds the slivers cut with it: their outlines among its vertices
            vertices = shapes[plate.id()][0]
            for k in slivers:
                if int(rows[k]["neighbour_face"]) == props["FaceId"]:
                    outline = cut_X[cut_faces[k]]
                    assert np.linalg.norm(outline[:, None] - vertices[None], axis=2).min(axis=1).max() < 1e-6
            continue
        assert props["PanelKind"] != "boundary sliver"
        boundary_area += area
        row = rows[props["FaceId"]]
        assert props["MoldId"] == int(row["mold"])
        # the plate is the panel as cut: its vertices are those of boundary-panels.obj
        outline = cut_X[cut_faces[props["FaceId"]]]
        vertices = shapes[plate.id()][0]
        assert np.linalg.norm(vertices[:, None] - outline[None], axis=2).min(axis=1).max() < 1e-6
    # the total within 1e-6, each kind within 1e-6 of the total (the slivers here are tiny:
    # a micrometre's rounding moves their own area by 1e-4 of it)
    cut = record["boundary_panels"]["cut_area"]
    total = record["panel_area"]["total"] + cut
    assert abs(net_area + boundary_area - total) <= 1e-6 * total
    sliver_area = sum(float(rows[k]["area"]) for k in slivers)     # as the csv rounds them
    assert abs(net_area - record["panel_area"]["total"] - sliver_area) <= 1e-6 * total + 1e-6 * len(slivers)
    assert abs(boundary_area + sliver_area - cut) <= 1e-6 * total + 1e-6 * len(slivers)
    assert _validation_errors(hypar / "molds" / "net.ifc", rules=False) == []

    # the layout's own file: the faces flat, the boundary panels as trimmed
    laid = ifcopenshell.open(str(hypar / "net.ifc"))
    assert len(laid.by_type("IfcPlate")) == len(plates)
    assert all(_props(p)["fabplan_Panel"]["NetType"] == "snet" for p in laid.by_type("IfcPlate"))

    strips = ifcopenshell.open(str(hypar / "strips" / "strips.ifc"))
    schedule = [r for r in csv.reader((hypar / "strips" / "strips.csv").open())
                if r and not r[0].startswith("#")]
    head, rows = schedule[0], schedule[1:]
    members = strips.by_type("IfcMember")
    assert sorted(m.Tag for m in members) == sorted(r[head.index("strip")] for r in rows)
    bodies = _shapes(strips, members)
    for m in members:
        props = _props(m)["fabplan_Strip"]
        row = next(r for r in rows if r[head.index("strip")] == m.Tag)
        length = float(row[head.index("length_mm")]) / 1000
        assert props["Length"] == pytest.approx(length, rel=1e-5)
        axis = next(r for r in m.Representation.Representations if r.RepresentationIdentifier == "Axis")
        centre = np.array([p.Coordinates for p in axis.Items[0].Points])
        assert np.linalg.norm(np.diff(centre, axis=0), axis=1).sum() == pytest.approx(length, rel=1e-5)
        # a closed lamella of the schedule's length and the section's size
        volume = _volume(*bodies[m.id()])
        assert volume == pytest.approx(length * 0.12 * 0.006, rel=0.02)
    profile, = strips.by_type("IfcRectangleProfileDef")
    assert (profile.XDim, profile.YDim) == pytest.approx((0.006, 0.12))
    assert _validation_errors(hypar / "strips" / "strips.ifc", rules=False) == []


@pytest.mark.parametrize("units, scale, name", [("mm", 0.001, None), ("ft", 0.3048, "FOOT")])
def test_unit_assignment_follows_the_net(tmp_path, units, scale, name):
    from fabplan.study.api import read_obj
    from fabplan.study.api_products import write_ifc

    net = read_obj(WEIN99)
    path = write_ifc(net, tmp_path / "net.ifc", units=units)
    model = ifcopenshell.open(str(path))
    assert ifcopenshell.util.unit.calculate_unit_scale(model) == pytest.approx(scale)
    length = ifcopenshell.util.unit.get_project_unit(model, "LENGTHUNIT")
    area = ifcopenshell.util.unit.get_project_unit(model, "AREAUNIT")
    if name is None:
        assert (length.Prefix, length.Name) == ("MILLI", "METRE")
        assert (area.Prefix, area.Name) == ("MILLI", "SQUARE_METRE")
    else:
        assert length.Name.upper() == name
        assert area.ConversionFactor.ValueComponent.wrappedValue == pytest.approx(scale**2)
    # the coordinates stay the net's numbers; the units say what they mean
    X, _ = _obj(WEIN99)
    node = model.by_type("IfcStructuralPointConnection")[0]
    v = int(node.Name.split()[-1])
    point = node.Representation.Representations[0].Items[0].VertexGeometry.Coordinates
    assert np.abs(np.array(point) - X[v]).max() <= 0.5 * 10.0 ** -{"mm": 3, "ft": 6}[units] * (1 + 1e-9)


@pytest.mark.slow
def test_a_failed_run_leaves_no_ifc(tmp_path, monkeypatch):
    import fabplan.fabricate.molds.mold_report as report

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(report, "write_mold_report", broken)
    out = tmp_path / "molds"
    assert main(["molds", str(WEIN99), "--tolerance-mm", "5", "--ifc", "-q", "-o", str(out)]) == 2
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_without_ifcopenshell_one_line_and_nothing_written(tmp_path):
    script = ("import sys; sys.modules['ifcopenshell'] = None; from fabplan.cli import main; "
              f"sys.exit(main(['molds', {str(WEIN99)!r}, '--tolerance-mm', '5', '--ifc', '-o', "
              f"{str(tmp_path / 'out')!r}]))")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(Path(fabplan.__file__).parents[1])})
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "pip install 'fabplan[ifc]'" in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "out").exists()


def _web_ifc() -> Path:
    """web-ifc installed with npm into a cache folder outside the project (once)."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.skip("web-ifc check needs node and npm, which are not installed")
    cache = Path(os.environ.get("FABPLAN_WEB_IFC", Path.home() / ".cache" / "fabplan-tests" / "web-ifc"))
    module = cache / "node_modules" / "web-ifc"
    if not module.is_dir():
        cache.mkdir(parents=True, exist_ok=True)
        run = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--silent", "--prefix",
                              str(cache), WEB_IFC], capture_output=True, text=True, timeout=600)
        if run.returncode != 0 or not module.is_dir():
            pytest.skip(f"npm could not install {WEB_IFC}: {run.stderr.strip()[-200:]}")
    return module


def test_web_ifc_opens_the_file(wein):
    module = _web_ifc()
    run = subprocess.run(["node", str(NODE_CHECK), str(wein / "net.ifc")], capture_output=True,
                         text=True, timeout=300, env={**os.environ, "WEB_IFC_MODULE": str(module)})
    assert run.returncode == 0, run.stderr
    found = json.loads(run.stdout.strip().splitlines()[-1])
    _, faces = _obj(WEIN99)
    assert found["errors"] == [] and found["schema"] == "IFC4"
    assert found["plates"] == found["meshes"] == len(faces)
    assert found["nodes"] == len(_obj(WEIN99)[0])
    reported = json.loads((wein / "molds.json").read_text())["panel_area"]["total"]
    assert found["area"] == pytest.approx(reported, rel=1e-6)


def test_web_ifc_opens_the_lamellas(hypar):
    module = _web_ifc()
    path = hypar / "strips" / "strips.ifc"
    run = subprocess.run(["node", str(NODE_CHECK), str(path)], capture_output=True,
                         text=True, timeout=300, env={**os.environ, "WEB_IFC_MODULE": str(module)})
    assert run.returncode == 0, run.stderr
    found = json.loads(run.stdout.strip().splitlines()[-1])
    members = len(ifcopenshell.open(str(path)).by_type("IfcMember"))
    assert found["errors"] == [] and found["members"] == members > 0
    assert found["meshes"] == found["plates"] + members


@pytest.mark.slow
def test_template_study_with_ifc_validates(tmp_path):
    out = tmp_path / "pavilion"
    assert main(["study", "pavilion", "--ifc", "-q", "-o", str(out)]) == 0
    study = json.loads((out / "study.json").read_text())
    written = [c for c in study["candidates"] if c.get("outputs", {}).get("ifc")]
    assert written
    for c in written:
        path = out / c["outputs"]["ifc"]
        folder = path.parent
        model = ifcopenshell.open(str(path))
        rows = list(csv.DictReader((folder / "molds.csv").open()))
        net = [p for p in model.by_type("IfcPlate") if _props(p)["fabplan_Panel"]["PanelKind"] == "net panel"]
        assert len(net) == len(rows)
        molds = sorted(_props(p)["fabplan_Panel"]["MoldId"] for p in net)
        assert molds == sorted(int(r["mold"]) for r in rows)
        strips = [r for r in csv.reader((folder / "strips" / "strips.csv").open()) if r and r[0][0] != "#"]
        assert len(model.by_type("IfcMember")) == len(strips) - 1
        assert _validation_errors(path, rules=True) == []
