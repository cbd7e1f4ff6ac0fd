"""Rhino .3dm designs in: exact NURBS surfaces, their layouts, the choice of an object,
unit systems, trims, and bad files refused in one line with nothing written.

Every .3dm file here is written with rhino3dm in the test: the surface's arrays are kept,
so the NURBS it is measured against is built from them, not read back.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.design.nurbs import NurbsSurface, basis_function_derivatives, triangulate_trimmed
from fabplan.design.parametric import ParametricSurface
from fabplan.errors import InputError
from fabplan.io.rhino_read import describe_3dm, read_3dm, split_source
from fabplan.net.mesh import QuadMesh
from fabplan.study.spec import parse_study

r3 = pytest.importorskip("rhino3dm")

PANEL_MM = 1000.0


def _shell_arrays(scale: float = 1.0):
    """A rational, non-uniform bicubic saddle of 12 x 9 m in mm: 7 x 6 control points,
    interior knots at uneven spacing, weights 1..1.5."""
    rng = np.random.default_rng(7)
    nu, nv = 7, 6
    ku = np.r_[[0.0] * 4, 0.2, 0.45, 0.6, [1.0] * 4]
    kv = np.r_[[0.0] * 4, 0.7, 1.6, [2.0] * 4]
    s, t = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv), indexing="ij")
    P = np.stack([12000 * s, 9000 * t + 800 * s * t,
                  4000 * (s - 0.5) * (t - 0.5) + 600 * s * s - 400 * t**3], axis=-1) * scale
    W = 1 + 0.5 * rng.random((nu, nv))
    return P, W, ku, kv


def _rhino_nurbs(P, W, ku, kv, degree=3):
    ns = r3.NurbsSurface.Create(3, True, degree + 1, degree + 1, P.shape[0], P.shape[1])
    for i, k in enumerate(ku[1:-1]):         # Rhino stores no superfluous end knots
        ns.KnotsU[i] = k
    for i, k in enumerate(kv[1:-1]):
        ns.KnotsV[i] = k
    for i in range(P.shape[0]):
        for j in range(P.shape[1]):
            ns.Points[i, j] = r3.Point4d(*(W[i, j] * P[i, j]), W[i, j])
    assert ns.IsValid
    return ns


def _write(path: Path, objects, units=None) -> Path:
    """A .3dm file of (geometry, name, layer) objects."""
    model = r3.File3dm()
    model.Settings.ModelUnitSystem = units or r3.UnitSystem.Millimeters
    layers: dict[str, int] = {}
    for geometry, name, layer in objects:
        attributes = r3.ObjectAttributes()
        if name:
            attributes.Name = name
        if layer:
            if layer not in layers:
                new = r3.Layer()
                new.Name = layer
                layers[layer] = model.Layers.Add(new)
            attributes.LayerIndex = layers[layer]
        add = {r3.NurbsSurface: model.Objects.AddSurface, r3.Brep: model.Objects.AddBrep,
               r3.Mesh: model.Objects.AddMesh}.get(type(geometry))
        if add is not None:
            add(geometry, attributes)
        elif isinstance(geometry, r3.Point3d):
            model.Objects.AddPoint(geometry, attributes)
        else:
            model.Objects.AddCurve(geometry, attributes)
    assert model.Write(str(path), 8)
    return path


@pytest.fixture(scope="module")
def shell():
    P, W, ku, kv = _shell_arrays()
    return NurbsSurface(P, W, ku, kv, 3, 3, name="shell")


@pytest.fixture(scope="module")
def shell_3dm(tmp_path_factory) -> Path:
    P, W, ku, kv = _shell_arrays()
    return _write(tmp_path_factory.mktemp("rhino") / "shell.3dm",
                  [(_rhino_nurbs(P, W, ku, kv), "shell", "Roof")])


# ---------------------------------------------------------------------------- the NURBS itself
def test_basis_functions_partition_unity_and_their_derivatives_sum_to_zero():
    knots = np.r_[[0.0] * 4, 0.1, 0.1, 0.55, 0.8, [1.0] * 4]       # a double interior knot
    t = np.linspace(0, 1, 301)
    count = len(knots) - 4
    span = np.clip(np.searchsorted(knots, t, side="right") - 1, 3, count - 1)
    d = basis_function_derivatives(knots, 3, span, t, 3)
    assert np.allclose(d[:, 0].sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(d[:, 1:].sum(axis=2), 0.0, atol=1e-9)
    assert (d[:, 0] >= -1e-15).all()


def test_points_and_normals_agree_with_rhino(shell):
    ns = _rhino_nurbs(*_shell_arrays())
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0, 1, 200), rng.uniform(0, 2, 200)
    ours = shell.points(u, v)
    theirs = np.array([[p.X, p.Y, p.Z] for p in (ns.PointAt(a, b) for a, b in zip(u, v, strict=True))])
    assert np.abs(ours - theirs).max() < 1e-9 * 12000
    *_, n = shell.principal_frames(u, v)
    normals = np.array([[p.X, p.Y, p.Z] for p in (ns.NormalAt(a, b) for a, b in zip(u, v, strict=True))])
    assert np.abs(np.sum(n * normals, axis=1)).min() > 1 - 1e-12


def test_principal_curvatures_agree_with_finite_differences(shell):
    """100 points (away from the knots, where the third derivative jumps and central
    differences lose their order): exact curvatures against curvatures from central
    differences of the exact points."""
    rng = np.random.default_rng(11)
    knots_u, knots_v = np.unique(shell.knots_u), np.unique(shell.knots_v)
    u, v = rng.uniform(0, 1, 400), rng.uniform(0, 2, 400)
    clear = (np.abs(u[:, None] - knots_u).min(1) > 0.01) & (np.abs(v[:, None] - knots_v).min(1) > 0.02)
    u, v = u[clear][:100], v[clear][:100]
    assert len(u) == 100
    k1, k2, e1, e2, n = shell.principal_frames(u, v)
    by_differences = ParametricSurface("shell-fd", shell.points, shell.domain)
    f1, f2, d1, d2, m = by_differences.principal_frames(u, v)
    scale = np.maximum(np.abs(k1), np.abs(k2))
    assert scale.min() > 1e-6           # curved everywhere (1/mm)
    assert np.abs(k1 - f1).max() / scale.min() < 1e-6
    assert np.abs(k2 - f2).max() / scale.min() < 1e-6
    assert np.abs(np.sum(e1 * d1, axis=1)).min() > 1 - 1e-6
    assert np.all(k1 > 0) and np.all(k2 < 0)        # a saddle: no umbilic


def test_closest_points_converge_and_beat_a_dense_sampling(shell):
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(5)
    u, v = rng.uniform(0, 1, 500), rng.uniform(0, 2, 500)
    *_, n = shell.principal_frames(u, v)
    offset = rng.uniform(-300, 300, 500)
    queries = shell.points(u, v) + offset[:, None] * n
    found = shell.closest_points(queries)
    assert found.converged.all()
    inside = (u > 0.05) & (u < 0.95) & (v > 0.1) & (v < 1.9)
    # off along the normal within the domain: the foot is the point it left from
    assert np.abs(found.distances[inside] - np.abs(offset[inside])).max() < 1e-6
    grid = np.meshgrid(np.linspace(0, 1, 500), np.linspace(0, 2, 500), indexing="ij")
    dense, _ = cKDTree(shell.points(grid[0].ravel(), grid[1].ravel())).query(queries)
    assert (found.distances <= dense + 1e-9).all()


# ---------------------------------------------------------------------------- reading
def test_the_file_units_are_honoured_and_converted(tmp_path):
    P, W, ku, kv = _shell_arrays()
    base = read_3dm(_write(tmp_path / "mm.3dm", [(_rhino_nurbs(P, W, ku, kv), "s", None)]))
    assert base.units == base.file_units == "mm" and base.scale == 1
    for units, per_mm, name in ((r3.UnitSystem.Meters, 1e-3, "m"),
                                (r3.UnitSystem.Centimeters, 0.1, "cm"),
                                (r3.UnitSystem.Inches, 1 / 25.4, "in"),
                                (r3.UnitSystem.Feet, 1 / 304.8, "ft")):
        path = _write(tmp_path / f"{name}.3dm", [(_rhino_nurbs(P * per_mm, W, ku, kv), "s", None)],
                      units=units)
        read = read_3dm(path)
        assert read.units == read.file_units == name
        assert np.allclose(read.surface.control_points, P * per_mm, rtol=1e-12)
        converted = read_3dm(path, units="mm")
        assert converted.units == "mm" and converted.file_units == name
        assert np.allclose(converted.surface.control_points, P, rtol=1e-12, atol=1e-9)
        assert np.array_equal(converted.surface.weights, base.surface.weights)
        design = load_design(f"{path}#units=mm", triangles=2000)
        assert design.units == "mm" and design.source["file_units"] == name
        assert design.area == pytest.approx(load_design(tmp_path / "mm.3dm", triangles=2000).area,
                                            rel=1e-9)


def test_a_file_without_a_unit_system_keeps_model_units(tmp_path, capsys):
    P, W, ku, kv = _shell_arrays(scale=1e-3)
    path = _write(tmp_path / "plain.3dm", [(_rhino_nurbs(P, W, ku, kv), "s", None)],
                  units=getattr(r3.UnitSystem, "None"))
    read = read_3dm(path)
    assert read.units is None and read.file_units is None and read.scale == 1
    with pytest.raises(InputError, match="has no unit system, so it cannot be converted to mm"):
        read_3dm(path, units="mm")


def test_what_a_file_holds_is_said_in_one_line(bad_folder):
    folder, _ = bad_folder
    assert describe_3dm(folder / "two.3dm") == \
        "the file holds surface 'a' on layer 'Roof'; surface 'b' on layer 'Roof'"
    assert describe_3dm(folder / "nothing.3dm") == "the file holds 1 curve; 1 point"
    assert describe_3dm(folder / "box.3dm") == \
        "the file holds polysurface of 6 faces 'box' on layer 'Default'"


def test_an_object_is_picked_by_layer_object_name_and_face(tmp_path):
    P, W, ku, kv = _shell_arrays()
    lifted = P + np.array([0, 0, 5000.0])
    brep = r3.Brep.CreateFromSurface(_rhino_nurbs(lifted, W, ku, kv))
    path = _write(tmp_path / "two.3dm", [(_rhino_nurbs(P, W, ku, kv), "low", "Roof"),
                                         (brep, "high", "Facade")])
    low = load_design(f"{path}#layer=Roof", triangles=2000)
    high = load_design(f"{path}#object=high", triangles=2000)
    assert low.source["kind"] == "surface" and high.source["kind"] == "polysurface face"
    assert high.vertices[:, 2].min() - low.vertices[:, 2].min() == pytest.approx(5000.0, abs=1e-6)
    # a polysurface made of a whole surface keeps the whole domain (no trims)
    assert high.parametric.trims is None
    assert load_design(f"{path}#layer=Facade,object=high,face=0", triangles=2000).area == \
        pytest.approx(high.area, rel=1e-12)
    assert split_source(f"{path}#layer=Roof") == (path, {"layer": "Roof"})


def test_a_mesh_object_is_read_with_its_quads_split(tmp_path):
    mesh = r3.Mesh()
    for j in range(4):
        for i in range(5):
            mesh.Vertices.Add(1000.0 * i, 1000.0 * j, 100.0 * i * j)
    for j in range(3):
        for i in range(4):
            a = 5 * j + i
            mesh.Faces.AddFace(a, a + 1, a + 6, a + 5)
    path = _write(tmp_path / "mesh.3dm", [(mesh, "m", None)])
    design = load_design(path)
    assert design.parametric is None and design.units == "mm"
    assert len(design.triangles) == 24 and len(design.vertices) == 20
    assert design.source["kind"] == "mesh"


def test_a_trimmed_face_is_laid_out_inside_its_trim(tmp_path):
    disc = r3.Brep.CreateTrimmedPlane(r3.Plane.WorldXY(),
                                      r3.Circle(r3.Point3d(5, 5, 0), 3).ToNurbsCurve())
    path = _write(tmp_path / "disc.3dm", [(disc, "disc", None)], units=r3.UnitSystem.Meters)
    design = load_design(path, triangles=4000)
    assert design.units == "m" and design.parametric.trims is not None
    assert len(design.boundary_loops) == 1
    radius = np.linalg.norm(design.vertices[design.boundary_loops[0], :2] - 5, axis=1)
    # the trim is followed as the polygon of 64 samples along its edge
    assert radius.max() < 3 + 1e-9 and radius.min() > 3 * (1 - 2e-3)
    assert np.linalg.norm(design.vertices[:, :2] - 5, axis=1).max() < 3 + 1e-9
    import shapely

    trim = design.parametric.trims[0]
    assert len(trim) == 64
    polygon = shapely.Polygon(design.parametric.points(trim[:, 0], trim[:, 1])[:, :2])
    assert design.area == pytest.approx(polygon.area, rel=1e-9)
    assert design.area == pytest.approx(9 * np.pi, rel=2e-3)


def test_trims_with_a_hole_give_one_conforming_mesh():
    square = np.array([[0.1, 0.2], [0.9, 0.15], [0.85, 0.9], [0.15, 0.8]])
    angle = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    hole = 0.5 + 0.15 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    uv, tri = triangulate_trimmed([square, hole[::-1]], ((0, 1), (0, 1)), (23, 17))
    corners = uv[tri]
    ab, ac = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    area = 0.5 * np.abs(ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
    import shapely

    expected = shapely.Polygon(square).difference(shapely.Polygon(hole)).area
    assert area.sum() == pytest.approx(expected, rel=1e-12)
    # every edge in one or two triangles, and the one-triangle edges are the two trims
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() == 2
    from fabplan.design.mesh_surface import DesignSurface

    design = DesignSurface(np.c_[uv, np.zeros(len(uv))], tri)
    assert len(design.boundary_loops) == 2 and not design.repairs


def test_a_study_reads_a_3dm_design_with_its_choice_and_units(tmp_path):
    P, W, ku, kv = _shell_arrays()
    _write(tmp_path / "shell.3dm", [(_rhino_nurbs(P, W, ku, kv), "shell", "Roof"),
                                    (r3.Point3d(0, 0, 0), "origin", None)])
    text = ('[design]\nfile = "shell.3dm"\nlayer = "Roof"\n{units}[panels]\nsize = {size}\n'
            '[limits]\nmax_deviation_mm = 30\nmold_tolerance_mm = 2\n')
    study = parse_study(text.format(units="", size=1000), path=tmp_path / "s.toml")
    assert study.design.units == "mm" and study.design.source.endswith("#layer=Roof,units=mm")
    assert study.design.triangles == 20000
    in_m = parse_study(text.format(units='units = "m"\n', size=1.0), path=tmp_path / "s.toml")
    assert in_m.design.units == "m" and in_m.design.source.endswith("units=m")
    design = load_design(in_m.design.source, triangles=2000)
    assert design.units == "m" and np.ptp(design.vertices[:, 0]) == pytest.approx(12.0)
    with pytest.raises(InputError, match="design.layer picks an object of a Rhino file"):
        parse_study(text.format(units="", size=1000).replace("shell.3dm", "shell.obj"),
                    path=tmp_path / "s.toml")
    with pytest.raises(InputError, match="no object matches layer 'Wall'"):
        parse_study(text.format(units="", size=1000).replace('"Roof"', '"Wall"'),
                    path=tmp_path / "s.toml")


# ---------------------------------------------------------------------------- bad files
def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _bad_files(folder: Path) -> dict[str, tuple[str, list[str]]]:
    """name -> (source on the command line, fragments the one-line message holds)."""
    P, W, ku, kv = _shell_arrays()
    line = r3.LineCurve(r3.Point3d(0, 0, 0), r3.Point3d(1, 0, 0))
    _write(folder / "nothing.3dm", [(r3.Point3d(1, 2, 3), "p", None), (line, "axis", "Lines")])
    _write(folder / "two.3dm", [(_rhino_nurbs(P, W, ku, kv), "a", "Roof"),
                                (_rhino_nurbs(P + 1, W, ku, kv), "b", "Roof")])
    _write(folder / "empty.3dm", [])
    good = _write(folder / "good.3dm", [(_rhino_nurbs(P, W, ku, kv), "a", None)]).read_bytes()
    (folder / "corrupt.3dm").write_bytes(good[: len(good) // 3])
    (folder / "garbage.3dm").write_bytes(b"3D Geometry File Format " + bytes(range(256)) * 8)
    (folder / "zero.3dm").write_bytes(b"")
    box = r3.Brep.CreateFromBoundingBox(r3.BoundingBox(r3.Point3d(0, 0, 0), r3.Point3d(1, 1, 1)))
    _write(folder / "box.3dm", [(box, "box", None)])
    _write(folder / "km.3dm", [(_rhino_nurbs(P, W, ku, kv), "a", None)], units=r3.UnitSystem.Kilometers)
    (folder / "good.3dm").unlink()
    return {
        "no surface": ("nothing.3dm", ["no surface, polysurface or mesh to read",
                                       "1 curve", "1 point"]),
        "two surfaces": ("two.3dm", ["2 surfaces or meshes", "#layer=NAME",
                                     "surface 'a' on layer 'Roof'", "surface 'b' on layer 'Roof'"]),
        "empty": ("empty.3dm", ["the file holds no objects"]),
        "corrupt": ("corrupt.3dm", ["not a readable Rhino .3dm file"]),
        "garbage": ("garbage.3dm", ["not a readable Rhino .3dm file"]),
        "zero bytes": ("zero.3dm", ["empty file"]),
        "no match": ("two.3dm#layer=Wall", ["no object matches layer 'Wall'", "the file holds"]),
        "not a surface": ("nothing.3dm#object=axis", ["only curve (unsupported)"]),
        "box": ("box.3dm", ["has 6 faces", "face=K"]),
        "face out of range": ("box.3dm#face=6", ["has 6 faces (0..5)"]),
        "bad key": ("box.3dm#colour=red", ["unknown choice 'colour'"]),
        "unit system": ("km.3dm", ["Kilometers"]),
        "face of a surface": ("two.3dm#object=a,face=0", ["face=0 picks a face of a polysurface",
                                                          "is a surface"]),
    }


BAD = ["no surface", "two surfaces", "empty", "corrupt", "garbage", "zero bytes", "no match",
       "not a surface", "box", "face out of range", "bad key", "unit system", "face of a surface"]


@pytest.fixture(scope="module")
def bad_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bad3dm")
    return folder, _bad_files(folder)


@pytest.mark.parametrize("case", BAD)
@pytest.mark.parametrize("how", ["layout", "reference"])
def test_bad_files_are_refused_in_one_line_with_nothing_written(bad_folder, capsys, case, how):
    folder, cases = bad_folder
    source, fragments = cases[case]
    before = _snapshot(folder)
    if how == "layout":
        argv = ["layout", str(folder / source), "--net", "snet", "--panel-size", "1000",
                "-o", str(folder / "out" / "net.obj")]
    else:
        net = folder / "net.obj"
        if not net.exists():
            QuadMesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]),
                     [[0, 1, 2, 3]]).write_obj(net)
            before = _snapshot(folder)
        argv = ["measure", str(net), "--reference", str(folder / source),
                "-o", str(folder / "out.json")]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1 and "Traceback" not in err
    for fragment in fragments:
        assert fragment in err
    assert out == ""
    assert _snapshot(folder) == before


# ---------------------------------------------------------------------------- layouts
@pytest.fixture(scope="module")
def shell_layout(shell_3dm, tmp_path_factory):
    out = tmp_path_factory.mktemp("shell-net") / "shell.obj"
    code = main(["layout", str(shell_3dm), "--net", "snet", "--panel-size", str(PANEL_MM),
                 "-q", "-o", str(out)])
    assert code == 0
    return out


@pytest.mark.slow
def test_a_nurbs_design_is_laid_out_on_the_exact_surface(shell, shell_layout, capsys):
    record = json.loads(shell_layout.with_suffix(".json").read_text())
    props = record["properties"]
    assert record["status"] == "converged" and props["folds"]["folded"] is False
    assert props["layout"]["design_units"] == "mm"
    assert props["layout"]["design_source"]["nurbs"] == {
        "degree": [3, 3], "control_points": [7, 6], "rational": True, "trim_loops": 0}
    mesh = QuadMesh.from_obj(shell_layout)
    found = shell.closest_points(mesh.vertices)
    assert found.converged.all()
    # within the layout's bound: every vertex within 0.5 % of a panel of the NURBS surface
    assert found.distances.max() <= 0.005 * PANEL_MM
    assert props["distance_to_design"]["max"] == pytest.approx(found.distances.max(), rel=1e-6,
                                                               abs=1e-9)
    assert props["coverage"] > 0.95
    assert props["distance_measured_to"] == "the exact parametric surface"


@pytest.mark.slow
def test_the_same_design_as_obj_and_as_3dm_gives_agreeing_nets(shell, shell_layout, tmp_path,
                                                               capsys):
    obj = tmp_path / "shell.obj"
    shell.triangulate((160, 120)).write(obj)
    out = tmp_path / "net" / "from-obj.obj"
    # an OBJ has no unit system: the millimetres the .3dm file states are said
    assert main(["layout", str(obj), "--net", "snet", "--panel-size", str(PANEL_MM), "-q",
                 "--units", "mm", "-o", str(out)]) == 0
    a = json.loads(shell_layout.with_suffix(".json").read_text())["properties"]
    b = json.loads(out.with_suffix(".json").read_text())["properties"]
    assert abs(a["coverage"] - b["coverage"]) <= 0.01
    from_3dm = shell.closest_points(QuadMesh.from_obj(shell_layout).vertices).distances
    from_obj = shell.closest_points(QuadMesh.from_obj(out).vertices).distances
    assert abs(from_3dm.max() - from_obj.max()) <= 0.01 * PANEL_MM
    assert abs(from_3dm.mean() - from_obj.mean()) <= 0.01 * PANEL_MM


@pytest.mark.slow
def test_a_3dm_reference_measures_to_the_nurbs(shell_layout, shell_3dm, tmp_path, capsys):
    out = tmp_path / "measure.json"
    assert main(["measure", str(shell_layout), "--reference", f"{shell_3dm}#object=shell",
                 "-o", str(out)]) == 0
    measured = json.loads(out.read_text())
    assert measured["distance_to_reference"]["max"] <= 0.005 * PANEL_MM


def _tower(waist: float = 0.6):
    """A rational surface of revolution closed around its axis, in v (Rhino's circle of 9
    control points, a quadratic profile from radius 8 m through a waist to 8 m over 20 m):
    its directions are swapped so that u wraps."""
    circle = r3.NurbsSurface.CreateFromCylinder(r3.Cylinder(r3.Circle(r3.Point3d(0, 0, 0), 1.0), 1.0))
    ring = np.array(circle.Points)[:, 0]                         # (9, 4) homogeneous, radius 1
    ring_w = ring[:, 3]
    ring_xy = ring[:, :2] / ring_w[:, None]
    radius, height = np.array([8000.0, 8000 * waist, 8000.0]), np.array([0.0, 10000, 20000])
    P = np.concatenate([radius[:, None, None] * ring_xy[None], np.broadcast_to(
        height[:, None, None], (3, 9, 1))], axis=2)              # (3 profile, 9 ring, 3)
    W = np.ones(3)[:, None] * ring_w[None]
    ns = r3.NurbsSurface.Create(3, True, 3, 3, 3, 9)
    for i, k in enumerate([0.0, 0, 1, 1]):
        ns.KnotsU[i] = k
    ring_knots = circle.KnotsU.ToList()
    for i, k in enumerate(ring_knots):
        ns.KnotsV[i] = k
    for i in range(3):
        for j in range(9):
            ns.Points[i, j] = r3.Point4d(*(W[i, j] * P[i, j]), W[i, j])
    assert ns.IsValid and ns.IsClosed(1) and not ns.IsClosed(0)
    return ns


def test_a_surface_closed_around_its_axis_wraps_without_a_seam(tmp_path):
    path = _write(tmp_path / "tower.3dm", [(_tower(), "tower", None)])
    design = load_design(path, triangles=6000)
    assert design.parametric.periodic_u
    # only the bottom and top circles are boundaries: the seam is closed
    assert len(design.boundary_loops) == 2
    z = design.vertices[np.concatenate(design.boundary_loops), 2]
    assert np.all((np.abs(z) < 1e-9) | (np.abs(z - 20000) < 1e-9))
    rho = np.linalg.norm(design.vertices[:, :2], axis=1)
    # a surface of revolution: at the bottom and top every point is 8 m from the axis
    assert np.abs(rho[np.abs(design.vertices[:, 2]) < 1e-9] - 8000).max() < 1e-9
    k1, k2, *_ = design.parametric.principal_frames(np.array([0.3, 2.0]), np.array([0.5, 0.5]))
    assert np.allclose(k1, k1[0], rtol=1e-9) and np.allclose(k2, k2[0], rtol=1e-9)


@pytest.mark.slow
def test_a_rhino_tower_is_laid_out_closing_up_around_its_axis(tmp_path, capsys):
    path = _write(tmp_path / "tower.3dm", [(_tower(), "tower", None)])
    out = tmp_path / "tower-net.obj"
    assert main(["layout", str(path), "--net", "snet", "--panel-size", "2000", "--triangles",
                 "12000", "-q", "-o", str(out)]) == 0
    mesh = QuadMesh.from_obj(out)
    z = mesh.vertices[mesh.is_boundary_vertex, 2]
    assert np.all((z < 2 * 2000) | (z > 20000 - 2 * 2000))     # no seam left open
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["status"] == "converged"
    assert record["properties"]["distance_to_design"]["max"] <= 0.005 * 2000


def test_a_nurbs_design_travels_to_other_processes(shell_3dm):
    """Studies send designs to worker processes (pickle, cloudpickle): the surface comes
    back whole, exact evaluation and closest points included."""
    import pickle

    design = load_design(f"{shell_3dm}#object=shell", triangles=2000)
    back = pickle.loads(pickle.dumps(design))
    u, v = np.array([0.13, 0.77]), np.array([0.4, 1.9])
    assert np.array_equal(back.parametric.points(u, v), design.parametric.points(u, v))
    assert back.units == "mm" and back.source == design.source
    probe = design.vertices[:50] + 100.0
    assert np.array_equal(back.distances(probe), design.distances(probe))


@pytest.mark.slow
def test_a_study_of_a_rhino_design_in_mm_runs_in_metres(shell_3dm, tmp_path, capsys):
    """`design.file = "shell.3dm"` with `units = "m"`: the millimetre file is converted,
    and every candidate's deviation is measured to the NURBS surface (in mm)."""
    import shutil

    shutil.copyfile(shell_3dm, tmp_path / "shell.3dm")
    (tmp_path / "study.toml").write_text(
        '[study]\nmax_iterations = 40\n[design]\nfile = "shell.3dm"\nobject = "shell"\n'
        'units = "m"\ntriangles = 8000\n[panels]\nsize = 1.5\n[limits]\nmax_deviation_mm = 30\n'
        'mold_tolerance_mm = 2\n[[candidates]]\nnet = "isogonal"\nangle = 80\n')
    out = tmp_path / "study"
    assert main(["study", str(tmp_path / "study.toml"), "-q", "-o", str(out)]) == 0
    record = json.loads((out / "study.json").read_text())
    assert record["design"]["units"] == "m" and record["design"]["source"].endswith("units=m")
    assert record["design"]["area"] == pytest.approx(114.5, rel=0.01)     # 12 x 9 m saddle
    P, W, ku, kv = _shell_arrays(scale=1e-3)
    exact = NurbsSurface(P, W, ku, kv, 3, 3)
    for candidate in record["candidates"]:
        net = QuadMesh.from_obj(out / "candidates" / candidate["name"] / "net.obj")
        found = exact.closest_points(net.vertices)
        assert found.converged.all()
        assert candidate["metrics"]["deviation_mm"]["max"] == pytest.approx(
            1000 * found.distances.max(), rel=1e-6, abs=1e-9)


def _trimmed_shell(shell):
    """The shell trimmed to an ellipse in its parameter domain, with a round hole, the
    trims given as 3D polylines on the surface (as a polysurface face's edges are)."""
    from fabplan.design.nurbs import trims_to_parameters

    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    outer = np.stack([0.5 + 0.45 * np.cos(t), 1.0 + 0.9 * np.sin(t)], axis=1)
    hole = np.stack([0.62 + 0.08 * np.cos(t), 1.1 + 0.16 * np.sin(t)], axis=1)[::-1]
    loops = [shell.points(c[:, 0], c[:, 1]) for c in (outer, hole)]
    trims = trims_to_parameters(shell, loops)
    return outer, hole, NurbsSurface(shell.control_points, shell.weights, shell.knots_u,
                                     shell.knots_v, 3, 3, name="trimmed", trims=trims)


def test_trims_on_a_curved_face_come_back_in_its_parameters(shell):
    outer, hole, trimmed = _trimmed_shell(shell)
    assert np.abs(trimmed.trims[0] - outer).max() < 1e-9
    assert np.abs(trimmed.trims[1] - hole).max() < 1e-9
    design = trimmed.triangulate(trimmed.resolution_for(6000))
    assert len(design.boundary_loops) == 2 and not design.repairs
    # every vertex is on the surface, and the boundary runs along the trims
    assert design.distances(design.vertices).max() < 1e-9
    import shapely

    rings = [shapely.LinearRing(c) for c in (outer, hole)]
    for loop in design.boundary_loops:
        gaps = [min(ring.distance(shapely.Point(p)) for ring in rings) for p in design.uv[loop]]
        assert max(gaps) < 1e-9
    # about 6000 triangles inside the trims, not over the whole domain
    assert 4000 < len(design.triangles) < 9000


@pytest.mark.slow
def test_a_trimmed_face_is_laid_out_up_to_its_trims(shell):
    from fabplan.layout.surface_layout import glide, layout_surface

    outer, hole, trimmed = _trimmed_shell(shell)
    design = trimmed.triangulate(trimmed.resolution_for(20000))
    layout = layout_surface(design, PANEL_MM, angle=90.0)
    result = glide(layout, "snet")
    assert result.converged
    X = result.mesh.vertices
    found = trimmed.closest_points(X)
    assert found.converged.all() and found.distances.max() <= 0.005 * PANEL_MM
    import shapely

    # no vertex beyond the trims or in the hole: all within the layout's tolerance (0.5 %
    # of a panel) of the trimmed face's triangles, and in its parameters at most 1e-4
    # (about a millimetre) outside the trims
    assert design.reference.distances(X).max() <= 0.005 * PANEL_MM
    region = shapely.Polygon(outer, [hole])
    assert shapely.distance(region, shapely.points(found.uv)).max() < 1e-4
    assert result.properties["coverage"] > 0.8


def test_an_extrusion_is_read_as_its_side_surface(tmp_path):
    """An arc of radius 17/3 m through (-5, 0), (0, 3), (5, 0) extruded 4 m: a rational
    quadratic cylinder whose curvatures are exactly 3/17 and 0."""
    arc = r3.NurbsCurve.CreateFromArc(r3.Arc(r3.Point3d(-5, 0, 0), r3.Point3d(0, 3, 0),
                                             r3.Point3d(5, 0, 0)))
    model = r3.File3dm()
    model.Settings.ModelUnitSystem = r3.UnitSystem.Meters
    model.Objects.AddExtrusion(r3.Extrusion.Create(arc, 4.0, False))
    model.Write(str(tmp_path / "wall.3dm"), 8)
    design = load_design(tmp_path / "wall.3dm", triangles=4000)
    assert design.source["kind"] == "extrusion" and design.units == "m"
    surface = design.parametric
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.linspace(u0, u1, 7), np.linspace(v0, v1, 7)
    k1, k2, *_ = surface.principal_frames(u, v)
    curvatures = np.sort(np.abs(np.stack([k1, k2])), axis=0)
    assert np.abs(curvatures[0]).max() < 1e-12 and np.abs(curvatures[1] - 3 / 17).max() < 1e-12
    length = 17 / 3 * 2 * np.arctan2(5, 8 / 3)
    assert design.area == pytest.approx(4 * length, rel=1e-3)
