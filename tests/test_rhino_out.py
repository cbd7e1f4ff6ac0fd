""".3dm and GLB outputs (`--3dm`): read back with rhino3dm and trimesh, they hold the
net of the OBJ to the float, one layer per mold with that mold's panels, the polylines of
both families, strip curves, and ids that are found in the CSV files."""

from __future__ import annotations

import csv
import json
from collections import Counter

import numpy as np
import pytest
from helpers import patch_of

import fabplan
from fabplan.cli import main
from fabplan.io.obj import read_obj
from fabplan.io.rhino_write import category_colours, read_3dm_net

rhino3dm = pytest.importorskip("rhino3dm")


def _objects(path):
    """(layer name, object) of every object of a .3dm file, and its unit system."""
    doc = rhino3dm.File3dm.Read(str(path))
    layers = {i: layer.Name for i, layer in enumerate(doc.Layers)}
    return [(layers[o.Attributes.LayerIndex], o) for o in doc.Objects], doc.Settings.ModelUnitSystem


def _mesh_arrays(mesh):
    vertices = np.array([[p.X, p.Y, p.Z] for p in (mesh.Vertices.Point3dAt(i)
                                                   for i in range(len(mesh.Vertices)))])
    faces = [list(mesh.Faces[k]) for k in range(mesh.Faces.Count)]
    return vertices, [f[:3] if f[2] == f[3] else f for f in faces]


def _points(curve):
    assert isinstance(curve, rhino3dm.PolylineCurve)
    return np.array([[p.X, p.Y, p.Z] for p in (curve.Point(i) for i in range(curve.PointCount))])


@pytest.fixture(scope="module")
def patch_file(tmp_path_factory, wein99):
    path = tmp_path_factory.mktemp("net") / "patch.obj"
    patch_of(wein99, 0.1).write_obj(path)
    return path


@pytest.fixture(scope="module")
def mold_run(tmp_path_factory, patch_file):
    out = tmp_path_factory.mktemp("molds") / "molds"
    assert main(["molds", str(patch_file), "--tolerance-mm", "5", "--3dm", "-o", str(out)]) == 0
    return out


def test_molds_3dm_holds_the_net_of_the_obj_to_the_float(mold_run, patch_file):
    objects, units = _objects(mold_run / "net.3dm")
    assert units == rhino3dm.UnitSystem.Meters
    nets = [o for layer, o in objects if layer == "net"]
    assert len(nets) == 1
    vertices, faces = _mesh_arrays(nets[0].Geometry)
    obj_vertices, obj_faces = read_obj(patch_file)
    assert np.array_equal(vertices, obj_vertices)            # bit for bit
    assert faces == [f.tolist() for f in obj_faces]
    assert nets[0].Attributes.GetUserString("units") == "m"
    # the library's reader gives the same
    again, again_faces, again_units = read_3dm_net(mold_run / "net.3dm")
    assert np.array_equal(again, obj_vertices) and again_units == "m"
    assert [f.tolist() for f in again_faces] == [f.tolist() for f in obj_faces]


def test_molds_3dm_has_one_layer_per_mold_with_its_panels(mold_run):
    record = json.loads((mold_run / "molds.json").read_text())
    objects, _ = _objects(mold_run / "net.3dm")
    faces_per_layer = Counter()
    for layer, o in objects:
        if layer.startswith("mold "):
            faces_per_layer[layer] += o.Geometry.Faces.Count
            assert int(o.Attributes.GetUserString("mold")) == int(layer.split()[1])
    assert faces_per_layer == {f"mold {m['id']}": m["panel_count"] for m in record["molds"]}
    assert len(faces_per_layer) == record["mold_count"]


def test_molds_3dm_ids_are_found_in_panels_csv(mold_run, patch_file):
    with open(mold_run / "panels.csv", newline="") as handle:
        rows = {int(r["face"]): int(r["mold"]) for r in csv.DictReader(handle)}
    objects, _ = _objects(mold_run / "net.3dm")
    panels = [o for layer, o in objects if layer.startswith("mold ")]
    assert len(panels) == len(rows)
    X, faces = read_obj(patch_file)
    colours = category_colours(max(rows.values()) + 1)
    for o in panels:
        face = int(o.Attributes.GetUserString("face"))
        mold = int(o.Attributes.GetUserString("mold"))
        assert rows[face] == mold and o.Attributes.Name == f"panel {face}"
        corners, _ = _mesh_arrays(o.Geometry)
        assert np.array_equal(corners, X[faces[face]])          # the panel is that face
        assert tuple(o.Attributes.ObjectColor)[:3] == tuple(colours[mold, :3])


def test_molds_3dm_polylines_per_family(mold_run, patch_file):
    mesh = fabplan.read_obj(patch_file)
    lines = mesh.polylines
    objects, _ = _objects(mold_run / "net.3dm")
    for family, letter in enumerate("AB"):
        curves = [o for layer, o in objects if layer == f"lines {letter}"]
        ids = np.flatnonzero(lines.family == family)
        assert len(curves) == len(ids) > 0
        for o in curves:
            p = int(o.Attributes.GetUserString("polyline"))
            assert lines.family[p] == family
            assert np.array_equal(_points(o.Geometry), mesh.vertices[lines.vertices[p]])


def test_glb_is_the_net_coloured_by_mold(mold_run, patch_file):
    import trimesh

    record = json.loads((mold_run / "molds.json").read_text())
    scene = trimesh.load(mold_run / "net.glb", force="scene")
    (mesh,) = scene.geometry.values()
    net = fabplan.read_obj(patch_file)
    triangles = net.triangles()
    assert len(mesh.faces) == len(triangles)
    # every triangle carries its panel's mold colour, and sits on its panel's corners
    face_of_triangle = np.repeat(np.arange(len(net.faces)), net.face_sizes - 2)
    mold = np.array([p["mold"] for p in record["panels"]])
    colours = category_colours(record["mold_count"])[mold[face_of_triangle]]
    assert np.array_equal(mesh.visual.face_colors, colours)
    assert np.allclose(mesh.vertices[mesh.faces], net.vertices[triangles], atol=1e-6)


def test_optimize_3dm_matches_its_obj(tmp_path, patch_file):
    out = tmp_path / "net.obj"
    code = main(["optimize", str(patch_file), "--net", "snet", "--max-iter", "5", "--3dm",
                 "--units", "cm", "-o", str(out), "-q"])
    assert code in (0, 3)
    objects, units = _objects(out.with_suffix(".3dm"))
    assert units == rhino3dm.UnitSystem.Centimeters
    assert json.loads(out.with_suffix(".json").read_text())["properties"]["units"] == "cm"
    (net,) = [o for layer, o in objects if layer == "net"]
    vertices, faces = _mesh_arrays(net.Geometry)
    obj_vertices, obj_faces = read_obj(out)
    assert np.array_equal(vertices, obj_vertices)
    assert faces == [f.tolist() for f in obj_faces]
    assert not any(layer.startswith("mold ") for layer, _ in objects)
    import trimesh

    (glb,) = trimesh.load(out.with_suffix(".glb"), force="scene").geometry.values()
    net = fabplan.read_obj(out)
    # glTF is in metres: the net in centimetres comes out a hundredth of its size
    assert np.allclose(glb.vertices[glb.faces], net.vertices[net.triangles()] / 100, atol=1e-9)


def test_without_3dm_no_rhino_files(tmp_path, patch_file):
    out = tmp_path / "net.obj"
    main(["optimize", str(patch_file), "--net", "snet", "--max-iter", "1", "-o", str(out), "-q"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.json", "net.obj"]


def test_strip_curves_carry_the_strip_ids(tmp_path, wein99):
    """Strip reference curves on a layer per family, named by the ids of strips.csv."""
    net = patch_of(wein99, 0.08)
    plan = fabplan.plan_strips(net, height_mm=100, thickness_mm=5)
    path = fabplan.write_3dm(net, tmp_path / "strips.3dm", strips=plan)
    objects, _ = _objects(path)
    curves = {o.Attributes.GetUserString("strip"): (layer, o) for layer, o in objects
              if layer.startswith("strips ")}
    ids = {s.id: s for s in plan.strips.strips}
    assert set(curves) == set(ids)
    for strip_id, (layer, o) in curves.items():
        strip = ids[strip_id]
        assert layer == f"strips {'AB'[strip.family]}" and o.Attributes.Name == strip_id
        assert np.array_equal(_points(o.Geometry), net.vertices[strip.vertices])


def test_unknown_3dm_units_are_refused(tmp_path, wein99):
    from fabplan.errors import InputError

    with pytest.raises(InputError, match="unknown units 'furlong'"):
        fabplan.write_3dm(wein99, tmp_path / "x.3dm", units="furlong")
    assert list(tmp_path.iterdir()) == []


SMALL_STUDY = """\
[study]
name = "Saddle with Rhino files"
max_iterations = 60

[design]
surface = "hyperbolic-paraboloid"
parameters = { width = 4, depth = 4, rise = 1.2 }
triangles = 2000

[panels]
size = 1.0

[limits]
max_deviation_mm = 200
mold_tolerance_mm = 5

[strips]
height_mm = 60
thickness_mm = 3
sheet_mm = [1200, 600]

[[candidates]]
net = "isogonal"
angle = 80

[[candidates]]
net = "anet"
"""


@pytest.mark.slow
def test_study_candidates_get_3dm_and_glb(tmp_path):
    """`fabplan study --3dm`: every candidate's net.3dm holds its net.obj to the float,
    its molds (as in molds.json) and its strips (ids of strips/strips.csv)."""
    path = tmp_path / "saddle.toml"
    path.write_text(SMALL_STUDY, encoding="utf-8")
    assert main(["study", str(path), "-o", str(tmp_path / "out"), "--3dm", "-q"]) == 0
    record = json.loads((tmp_path / "out" / "study.json").read_text())
    folders = sorted((tmp_path / "out" / "candidates").iterdir())
    assert len(folders) == len(record["candidates"]) == 3
    drawn_strips = 0
    for folder in folders:
        objects, units = _objects(folder / "net.3dm")
        assert units == rhino3dm.UnitSystem.Meters
        (net,) = [o for layer, o in objects if layer == "net"]
        vertices, faces = _mesh_arrays(net.Geometry)
        obj_vertices, obj_faces = read_obj(folder / "net.obj")
        assert np.array_equal(vertices, obj_vertices)
        assert faces == [f.tolist() for f in obj_faces]
        molds = json.loads((folder / "molds.json").read_text())
        per_layer = Counter(layer for layer, _ in objects if layer.startswith("mold "))
        assert per_layer == {f"mold {m['id']}": m["panel_count"] for m in molds["molds"]}
        strip_ids = set()     # strips are planned for lamella candidates only
        if (folder / "strips").is_dir():
            with open(folder / "strips" / "strips.csv", newline="") as handle:
                strip_ids = {r["strip"] for r in csv.DictReader(line for line in handle
                                                                if not line.startswith("#"))}
        drawn = {o.Attributes.GetUserString("strip") for layer, o in objects
                 if layer.startswith("strips ")}
        assert drawn == strip_ids
        drawn_strips += len(drawn)
        assert (folder / "net.glb").stat().st_size > 0
        candidate = next(c for c in record["candidates"] if c["name"] == folder.name)
        assert candidate["outputs"]["rhino"].endswith("net.3dm")
    assert drawn_strips > 0


def test_a_3dm_that_cannot_be_written_leaves_nothing(tmp_path, patch_file, capsys):
    (tmp_path / "net.3dm").mkdir()             # a folder where the .3dm would go
    out = tmp_path / "net.obj"
    code = main(["optimize", str(patch_file), "--net", "snet", "--3dm", "-o", str(out), "-q"])
    assert code == 2
    assert "net.3dm: is a folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.3dm"]


@pytest.mark.slow
def test_molds_without_3dm_write_no_rhino_files(tmp_path, patch_file):
    out = tmp_path / "molds"
    assert main(["molds", str(patch_file), "--tolerance-mm", "5", "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["molds.json", "panels.csv", "report.html",
                                                     "report.pdf"]
