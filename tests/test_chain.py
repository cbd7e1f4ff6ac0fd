"""The whole chain on designs of a user's own, as a new user runs it: ``layout`` ->
``optimize`` (linear Weingarten, constant radius) -> ``molds`` -> ``strips`` -> ``mill``
-> ``arcs``, with ``--3dm``, each command on the files the one before wrote.

Four designs made here by seeded code (a wavy facade STL, a facade with a door, a bowl in
millimetres, a NURBS roof in a .3dm file in millimetres), each at two panel sizes. Every
step ends in exit 0, or in exit 3 with a line saying why; never in exit 2 (a fabplan
file refused by fabplan); and no number in one file contradicts another: counts, units,
statuses and the files listed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rhino3dm as r3
import trimesh

from fabplan.cli import main
from fabplan.net.mesh import QuadMesh

pytestmark = pytest.mark.slow


def _grid_triangles(shape: tuple[int, int]) -> np.ndarray:
    """(t, 3) int, two triangles per cell of a grid of points `shape` (row-major ids)."""
    idx = np.arange(shape[0] * shape[1]).reshape(shape)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                           np.stack([a, c, d], -1).reshape(-1, 3)])


def _height_field(f, width: float, height: float, step: float, keep=None) -> tuple:
    """Triangles of the facade ``(x, f(x, y), y)`` over [0, width] x [0, height] (y up),
    without those whose centre `keep` refuses."""
    x, y = np.meshgrid(np.linspace(0, width, round(width / step) + 1),
                       np.linspace(0, height, round(height / step) + 1), indexing="ij")
    V = np.stack([x, f(x, y), y], axis=-1).reshape(-1, 3)
    T = _grid_triangles(x.shape)
    if keep is not None:
        centre = V[T].mean(axis=1)
        T = T[keep(centre[:, 0], centre[:, 2])]
    return V, T


def _wavy(folder: Path) -> Path:
    rng = np.random.default_rng(11)
    amp, kx, ky = rng.uniform(0.25, 0.5), rng.uniform(0.3, 0.6), rng.uniform(0.3, 0.6)
    V, T = _height_field(lambda x, y: amp * np.sin(kx * x) * np.cos(ky * y), 9.0, 4.5, 0.075)
    path = folder / "wavy.stl"
    trimesh.Trimesh(V, T, process=False).export(path)
    return path


def _door(folder: Path) -> Path:
    rng = np.random.default_rng(12)
    x0 = 0.125 * round(rng.uniform(2.0, 5.0) / 0.125)
    V, T = _height_field(lambda x, y: 0.3 * np.sin(0.5 * x) * np.cos(0.4 * y), 9.0, 5.0, 0.125,
                         keep=lambda x, y: ~((x > x0) & (x < x0 + 1.25) & (y < 2.25)))
    path = folder / "door.obj"
    trimesh.Trimesh(V, T, process=False).export(path)
    return path


def _bowl_mm(folder: Path) -> Path:
    half = 75.0
    x, y = np.meshgrid(np.linspace(-half, half, 81), np.linspace(-half, half, 81), indexing="ij")
    V = np.stack([x, y, 30.0 * (x * x + y * y) / half**2], axis=-1).reshape(-1, 3)
    T = _grid_triangles(x.shape)
    path = folder / "bowl.stl"
    trimesh.Trimesh(V, T, process=False).export(path)
    return path


def _roof_3dm(folder: Path) -> Path:
    """A bicubic NURBS roof 12 x 9 m, its control points jittered (seeded), in millimetres."""
    rng = np.random.default_rng(13)
    n = 6
    u, v = np.meshgrid(np.linspace(0, 12000, n), np.linspace(0, 9000, n), indexing="ij")
    z = 2500 * np.sin(np.pi * u / 12000) * np.sin(np.pi * v / 9000) + rng.uniform(-250, 250, u.shape)
    surface = r3.NurbsSurface.Create(3, False, 4, 4, n, n)
    knots = [0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1]
    for i, k in enumerate(knots):
        surface.KnotsU[i] = k
        surface.KnotsV[i] = k
    for i in range(n):
        for j in range(n):
            surface.Points[i, j] = r3.Point4d(u[i, j], v[i, j], z[i, j], 1.0)
    assert surface.IsValid
    model = r3.File3dm()
    model.Settings.ModelUnitSystem = r3.UnitSystem.Millimeters
    model.Objects.AddSurface(surface)
    path = folder / "roof.3dm"
    assert model.Write(str(path), 8)
    return path


#: design, its maker, the two panel sizes (its units), the units to say (None: the file's,
#: or metres), mold tolerance (mm), strip height and thickness (mm), face mill diameter (mm)
DESIGNS = {
    "wavy": (_wavy, (0.9, 1.4), None, 2.0, (100, 6), 200),
    "door": (_door, (0.8, 1.2), None, 2.0, (100, 6), 200),
    "bowl-mm": (_bowl_mm, (15.0, 25.0), "mm", 0.2, (5, 1), 6),
    "roof-3dm": (_roof_3dm, (1500.0, 2200.0), None, 2.0, (100, 6), 200),
}
CASES = [pytest.param(name, k, id=f"{name}-{DESIGNS[name][1][k]:g}")
         for name in DESIGNS for k in (0, 1)]


class _Chain:
    """Runs fabplan commands as a user does and keeps what each said."""

    def __init__(self, capsys, units: str | None):
        self.capsys, self.units, self.codes = capsys, units, {}

    def __call__(self, step: str, *args: object) -> int:
        units = ["--units", self.units] if self.units else []
        code = main([str(a) for a in args] + units + ["-q"])
        err = self.capsys.readouterr().err.strip().splitlines()
        self.codes[step] = code
        assert code in (0, 3), (step, code, err)
        if code == 3:                 # it says why, in a line of its own
            assert err and err[-1].startswith("fabplan: ") and len(err[-1]) > 30, (step, err)
        return code


def _faces(path: Path) -> int:
    return len(QuadMesh.from_obj(path).face_sizes)


def _polygons(path: Path) -> int:
    return sum(line.startswith("f ") for line in path.read_text().splitlines())


@pytest.mark.parametrize("name, k", CASES)
def test_the_chain_on_a_users_design(name, k, tmp_path, capsys):
    make, sizes, units, tolerance, (height, thickness), tool = DESIGNS[name]
    design = make(tmp_path)
    expected_units = units or ("mm" if design.suffix == ".3dm" else "m")
    run = _Chain(capsys, units)
    lay = tmp_path / "lay.obj"
    assert run("layout", "layout", design, "--net", "snet", "--panel-size", sizes[k],
               "--3dm", "-o", lay) in (0, 3)
    record = json.loads(lay.with_suffix(".json").read_text())
    props = record["properties"]
    assert props["units"] == expected_units
    assert props["faces"] == _faces(lay)
    boundary = lay.with_suffix(".boundary.obj")
    if boundary.exists():
        bp = props["boundary_panels"]            # panels, and slivers cut with a full one
        assert bp["count"] + len(bp["extensions"]) == _polygons(boundary)
    _agrees_with_3dm(lay, expected_units)

    nets = {}
    for net in ("linear-weingarten", "const-radius"):
        out = tmp_path / f"{net}.obj"
        code = run(net, "optimize", lay, "--net", net, "--reference", design, "--3dm", "-o", out)
        result = json.loads(out.with_suffix(".json").read_text())
        # exit 0: converged and within the deviation limit from the design
        deviation = result["properties"]["limits"]["max_deviation_mm"]
        assert (code == 0) == (result["status"] == "converged" and not deviation["exceeded"]), \
            (net, code, result["status"], deviation)
        assert result["properties"]["units"] == expected_units
        assert result["properties"]["faces"] == _faces(out) == props["faces"]
        _agrees_with_3dm(out, expected_units)
        nets[net] = out

    folder = tmp_path / "molds"
    run("molds", "molds", nets["linear-weingarten"], "--tolerance-mm", tolerance, "-o", folder)
    plan = json.loads((folder / "molds.json").read_text())
    assert plan["units"] == expected_units
    assert plan["panel_count"] == _faces(nets["linear-weingarten"])
    assert plan["fits_all"] == (plan["failures"] == [])
    bp = nets["linear-weingarten"].with_suffix(".boundary.obj")
    if bp.exists():
        panels = plan["boundary_panels"]
        assert panels["panels"] + panels["extensions_of_full_panels"] == _polygons(bp)
        assert len(panels["mold"]) == _polygons(bp)
        assert plan["boundary_panels"]["molds_in_all"] == \
            plan["molds_made"] + plan["boundary_panels"]["own_molds"]
    csv_rows = (folder / "panels.csv").read_text().strip().splitlines()[1:]
    assert len(csv_rows) == plan["panel_count"]

    folder = tmp_path / "strips"
    if run("strips", "strips", nets["const-radius"], "--height", height, "--thickness", thickness,
           "-o", folder) == 0:
        strips = json.loads((folder / "strips.json").read_text())
        assert strips["model_units"] == expected_units
        dxf = sorted(p.name for p in folder.glob("*.dxf"))
        assert dxf == [f for f in strips["files"] if f.endswith(".dxf")]
        assert strips["summary"]["sheets"] == len(dxf)
        assert sorted(p.name for p in folder.iterdir()) == sorted(strips["files"])

    folder = tmp_path / "mill"
    if run("mill", "mill", lay, "--tool", f"face:D={tool}", "-o", folder) == 0:
        mill = json.loads((folder / "mill.json").read_text())
        assert (folder / "path.cl").stat().st_size > 0 and mill
        # the layout's record names its design: the cut is measured against it
        assert mill["target"]["surface"] == "design" and mill["gouge_check"]["passed"]
        assert mill["net_from_design"]["units"] == "mm"

    arcs = tmp_path / "arcs.3dm"
    code = run("arcs", "arcs", nets["const-radius"], "-o", arcs)
    record = json.loads(arcs.with_suffix(".json").read_text())
    assert code == (3 if record["limits"]["max_arc_angle_deg"]["exceeded"] else 0)
    summary = record["summary"]
    assert summary["arcs"] == len(QuadMesh.from_obj(nets["const-radius"]).edges)
    assert summary["end_vertex_gap_relative_to_edge"] < 1e-9
    model = r3.File3dm.Read(str(arcs))
    assert model is not None and len(model.Objects) == summary["arcs"]


def _agrees_with_3dm(obj: Path, units: str) -> None:
    """The .3dm beside a net holds its mesh, vertex for vertex, in its units."""
    model = r3.File3dm.Read(str(obj.with_suffix(".3dm")))
    assert model is not None
    assert {"m": r3.UnitSystem.Meters, "mm": r3.UnitSystem.Millimeters}[units] \
        == model.Settings.ModelUnitSystem
    meshes = [o.Geometry for o in model.Objects if isinstance(o.Geometry, r3.Mesh)]
    net = QuadMesh.from_obj(obj)
    assert meshes and len(meshes[0].Vertices) == net.vertex_count
    first = meshes[0].Vertices[0]
    assert np.allclose([first.X, first.Y, first.Z], net.vertices[0], rtol=1e-6, atol=1e-6)
