"""Flank milling with cones on S*-nets: every cutter location re-read from the files and
checked against spheres fitted here, the simulated cone against closed forms, the example
S*-net milled without gouge, bad input refused.

The geometric checks recompute what they check from the written net (its ``v``/``vn``/``f``
lines, read here) and the written files (a regex over the CL file, the CSV) with code of
their own: they do not call the planning code they test.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.fabricate.milling import MillSettings, parse_tool
from fabplan.fabricate.milling.mill_simulation import Cutter, entry_heights
from fabplan.net.mesh import QuadMesh

GOTO = re.compile(r"^GOTO/(.*)$")
CUTTER = re.compile(r"^CUTTER/(.*)$")
TOOL = "cone:angle=45,length=10,tip=24"


# ------------------------------------------------------------------------------ fixtures
def saddle_start(path: Path, half: float = 30.0, step: float = 3.0) -> Path:
    """A grid on the saddle z = -x^2/500 + y^2/140 (mm), lines at +-45 degrees."""
    u = np.arange(-half, half + step / 2, step)
    U, V = np.meshgrid(u, u, indexing="ij")
    x, y = (U - V) / np.sqrt(2), (U + V) / np.sqrt(2)
    QuadMesh.grid(np.stack([x, y, -x**2 / 500 + y**2 / 140], axis=-1)).write_obj(path)
    return path


def read_net(path: Path) -> tuple[np.ndarray, np.ndarray, list]:
    """Vertices, vn normals and faces (0-based) of an OBJ, read independently."""
    V, N, F = [], [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            V.append([float(p) for p in parts[1:4]])
        elif parts[0] == "vn":
            N.append([float(p) for p in parts[1:4]])
        elif parts[0] == "f":
            F.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    return np.array(V), np.array(N), F


def neighbours_of(vertex: int, faces: list) -> list:
    """The vertices sharing an edge with `vertex`."""
    out = set()
    for f in faces:
        if vertex in f:
            k = f.index(vertex)
            out.update([f[k - 1], f[(k + 1) % len(f)]])
    return sorted(out)


def mannheim_radius(points: np.ndarray, normals: np.ndarray) -> float:
    """Signed radius rho of the sphere touching the planes (p_i, n_i): n_i . m - rho = n_i . p_i."""
    A = np.column_stack([normals, -np.ones(len(normals))])
    b = np.sum(normals * points, axis=1)
    return float(np.linalg.lstsq(A, b, rcond=None)[0][3])


@pytest.fixture(scope="module")
def cone_milled(tmp_path_factory):
    """`fabplan optimize --net sstar` on the saddle start, then `fabplan mill` with a cone."""
    folder = tmp_path_factory.mktemp("cone")
    start = saddle_start(folder / "start.obj")
    assert main(["optimize", str(start), "--net", "sstar", "--units", "mm", "-q",
                 "-o", str(folder / "net.obj")]) == 0
    code = main(["mill", str(folder / "net.obj"), "--tool", TOOL, "--sim-step", "1.0",
                 "--scallop", "0.025", "-q", "-o", str(folder / "out")])
    assert code == 0
    return folder / "out", folder / "net.obj"


def read_locations(out: Path) -> tuple[np.ndarray, np.ndarray, dict, np.ndarray]:
    """Tips and axes of the cutting moves, CSV columns and the CUTTER parameters."""
    rows, cutter, retract = [], None, False
    for line in (out / "path.cl").read_text().splitlines():
        if line.startswith("$$ pass "):
            retract = False
        elif line.startswith("$$ retract"):
            retract = True
        if CUTTER.match(line):
            cutter = np.array([float(v) for v in CUTTER.match(line).group(1).split(",")])
        match = GOTO.match(line)
        if match and not retract:
            rows.append([float(v) for v in match.group(1).split(",")])
    values = np.array(rows)
    with open(out / "path.csv") as handle:
        table = list(csv.DictReader(handle))
    col = {k: np.array([float(r[k]) for r in table]) for k in table[0]}
    assert cutter is not None and len(table) == len(values)
    return values[:, :3], values[:, 3:], col, cutter


def xyz(col: dict, name: str) -> np.ndarray:
    return np.column_stack([col[f"{name}_x"], col[f"{name}_y"], col[f"{name}_z"]])


# ------------------------------------------------------------------------------ geometry
def test_every_cone_is_tangent_to_its_safety_sphere_within_a_micrometre_thousandth(cone_milled):
    """The cone of every CL location (apex, axis and half angle from the GOTO and CUTTER
    statements) is circumscribed to its safety sphere within 1e-6 mm, touches the tangent
    plane along the ruling through the contact point, on its flank."""
    out, _ = cone_milled
    tip, axis, col, cutter = read_locations(out)
    tip_radius, angle, length = cutter[0] / 2, np.radians(cutter[5]), cutter[6]
    assert np.allclose(np.linalg.norm(axis, axis=1), 1, atol=1e-11)
    apex = tip - (tip_radius / np.tan(angle)) * axis
    contact, normal = xyz(col, "contact"), xyz(col, "normal")
    radius = col["safety_radius_mm"]
    centre = contact + radius[:, None] * normal
    w = centre - apex
    along = np.sum(w * axis, axis=1)
    # the sphere's centre on the axis, and its distance from the cone's surface = radius
    assert np.linalg.norm(w - along[:, None] * axis, axis=1).max() < 1e-6
    assert np.abs(np.linalg.norm(w, axis=1) * np.sin(angle) - radius).max() < 1e-6
    # the contact on the cone's surface, on the flank, and the ruling through it in the
    # tangent plane
    c = contact - apex
    height = np.sum(c * axis, axis=1)
    off_axis = np.linalg.norm(c - height[:, None] * axis, axis=1)
    assert np.abs(off_axis * np.cos(angle) - height * np.sin(angle)).max() < 1e-6
    flank = height - tip_radius / np.tan(angle)
    assert flank.min() > -1e-6 and flank.max() < length + 1e-6
    assert np.abs(np.sum(c * normal, axis=1)).max() < 1e-6
    assert np.allclose(np.sum(axis * normal, axis=1), np.sin(angle), atol=1e-9)


def test_cone_nodes_use_the_nets_contact_elements_and_mannheim_spheres(cone_milled):
    """At the nodes: contact = the net's vertex, normal = its vn (tool side), and the safety
    sphere inside the Mannheim sphere fitted here: radius min(rho - margin, R_end)."""
    out, net = cone_milled
    _, _, col, cutter = read_locations(out)
    record = json.loads((out / "mill.json").read_text())
    V, N, F = read_net(net)
    node = col["vertex"] >= 0
    vertex = col["vertex"][node].astype(int)
    contact, normal = xyz(col, "contact")[node], xyz(col, "normal")[node]
    assert np.abs(contact - V[vertex]).max() < 1e-8
    side = np.sign(np.sum(N[vertex] * normal, axis=1))
    assert np.all(side == side[0])
    assert np.abs(side[:, None] * N[vertex] - normal).max() < 1e-9
    angle = np.radians(cutter[5])
    end_radius = (cutter[0] / 2 + cutter[6] * np.tan(angle)) / np.cos(angle)
    rho = np.array([side[0] * mannheim_radius(V[[v, *neighbours_of(v, F)]],
                                              N[[v, *neighbours_of(v, F)]])
                    for v in vertex[::7]])   # a test may loop: every 7th node
    expected = np.minimum(rho - record["margin_mm"], end_radius)
    assert np.abs(col["safety_radius_mm"][node][::7] - expected).max() < 1e-6
    assert np.all(col["safety_radius_mm"][node][::7] <= rho - record["margin_mm"] + 1e-9)


def test_cl_file_carries_the_cone(cone_milled):
    out, _ = cone_milled
    _, _, _, cutter = read_locations(out)
    assert cutter.tolist() == [24.0, 0.0, 0.0, 0.0, 0.0, 45.0, 10.0]
    record = json.loads((out / "mill.json").read_text())
    assert record["tool"]["kind"] == "cone"
    assert record["tilt_deg"] == {"min": 45.0, "max": 45.0}
    assert record["mannheim_residual_max_mm"] < 1e-6
    assert record["passes"] >= 10 and record["path_length_mm"] > 0
    assert any("next to the boundary" in note for note in record["notes"])


def test_cone_cut_of_the_sstar_example_has_no_gouge(cone_milled):
    out, _ = cone_milled
    record = json.loads((out / "mill.json").read_text())
    assert record["gouge_check"]["passed"]
    assert record["simulation"]["max_gouge_mm"] <= 0.005
    # second-order prediction (developable ahead, end circle behind) against the sweep on
    # a 1 mm grid, which samples the cusps up to 0.5 mm off their crest
    assert record["simulation"]["max_scallop_mm"] == pytest.approx(record["predicted_scallop_mm"],
                                                                   rel=0.25)
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3 and "Mannheim radius" in html


# ------------------------------------------------------------------------------ simulation
def test_cone_entry_matches_the_closed_form_of_an_upright_cone():
    r0, a, length = 3.0, np.radians(30.0), 12.0
    rho = np.linspace(0, r0 + length * np.tan(a) + 1, 60)
    z = entry_heights(Cutter("cone", r0, length, angle_deg=30.0), np.zeros((60, 3)),
                      np.tile([0.0, 0, 1], (60, 1)), rho, np.zeros(60))
    expected = np.where(rho <= r0, 0.0, (rho - r0) / np.tan(a))
    expected = np.where(rho <= r0 + length * np.tan(a), expected, np.inf)
    assert np.allclose(z, expected, atol=1e-9)


def test_tilted_cone_entry_lies_on_the_cone():
    rng = np.random.default_rng(5)
    axis = np.array([0.5, -0.3, 0.8])
    axis /= np.linalg.norm(axis)
    tip = np.array([1.0, 2.0, 3.0])
    x, y = rng.uniform(-12, 12, 400), rng.uniform(-12, 12, 400)
    z = entry_heights(Cutter("cone", 2.0, 8.0, angle_deg=40.0), tip, axis, x, y)
    hit = np.isfinite(z)
    p = np.column_stack([x, y, z])[hit] - tip
    h = p @ axis
    r = np.linalg.norm(p - h[:, None] * axis, axis=1)
    on_flank = np.abs(r - (2.0 + h * np.tan(np.radians(40.0)))) < 1e-8
    on_tip = (np.abs(h) < 1e-8) & (r <= 2.0 + 1e-8)
    assert hit.sum() > 50 and np.all(on_flank | on_tip)
    assert np.all((h > -1e-8) & (h < 8.0 + 1e-8))


# ------------------------------------------------------------------------------ refusals
def refused(tmp_path: Path, capsys, net: Path, *options: str) -> str:
    out = tmp_path / "out"
    code = main(["mill", str(net), *options, "-q", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert not out.exists()
    lines = err.strip().splitlines()          # -q: no progress, only the message
    assert len(lines) == 1 and lines[0].startswith("fabplan: error: ")
    return err


def bowl(radius: float = 300.0, half: float = 45.0, step: float = 7.5, *, normals: bool):
    u = np.arange(-half, half + step / 2, step)
    x, y = np.meshgrid(u, u, indexing="ij")
    z = radius - np.sqrt(radius**2 - x**2 - y**2)
    mesh = QuadMesh.grid(np.stack([x, y, z], axis=-1), name="bowl.obj")
    if normals:   # the sphere's own tangent planes: an S*-net whose Mannheim sphere is it
        centre = np.array([0.0, 0.0, radius])
        mesh = mesh.with_vertices(mesh.vertices, (centre - mesh.vertices) / radius)
    return mesh


def test_a_net_that_is_not_an_sstar_net_is_refused(tmp_path, capsys):
    u = np.arange(-30.0, 30.1, 7.5)
    x, y = np.meshgrid(u, u, indexing="ij")
    QuadMesh.grid(np.stack([x, y, x * x / 300 + y * y / 900], axis=-1)).write_obj(tmp_path / "p.obj")
    err = refused(tmp_path, capsys, tmp_path / "p.obj", "--tool", TOOL)
    assert "not an S*-net" in err and "--net sstar" in err


def test_a_cone_on_a_dome_side_curving_towards_it_is_refused(tmp_path, capsys):
    """Inside a bowl every direction curves towards the tool: the straight flank digs in."""
    bowl(normals=True).write_obj(tmp_path / "bowl.obj")
    err = refused(tmp_path, capsys, tmp_path / "bowl.obj", "--tool", "cone:angle=45,length=20")
    assert "curves towards the tool along the rulings" in err and "saddle" in err


def test_a_cone_too_long_for_the_safety_spheres_is_refused(tmp_path, capsys, cone_milled):
    """Its flank widens beyond the smallest Mannheim sphere (47 mm): the fitting length is
    named, and it fits."""
    _, net = cone_milled
    err = refused(tmp_path, capsys, net, "--tool", "cone:angle=45,length=20,tip=30")
    assert "too long (too wide) for the safety spheres" in err
    longest = float(re.search(r"use length <= ([0-9.]+) mm", err).group(1))
    assert 0 < longest < 20
    out = tmp_path / "fits"
    assert main(["mill", str(net), "--tool", f"cone:angle=45,length={longest * 0.99:.4f},tip=30",
                 "--no-simulation", "--scallop", "0.1", "-q", "-o", str(out)]) == 0


def test_a_given_margin_moves_the_contact_circle_towards_the_tip(tmp_path, cone_milled):
    """With a larger margin the safety spheres shrink: the contact circles move off the
    flank's wide end, and stay on the flank between the nodes too."""
    _, net = cone_milled
    out = tmp_path / "out"
    assert main(["mill", str(net), "--tool", TOOL, "--margin", "20", "--no-simulation",
                 "--scallop", "0.1", "-q", "-o", str(out)]) == 0
    tip, axis, col, cutter = read_locations(out)
    contact_radius = col["contact_radius_mm"]
    assert contact_radius.max() <= cutter[0] / 2 + cutter[6] + 1e-9   # tan 45 = 1
    assert contact_radius.min() < contact_radius.max() - 1


def test_a_cone_tip_wider_than_the_contact_circle_is_refused(tmp_path, capsys, cone_milled):
    _, net = cone_milled
    err = refused(tmp_path, capsys, net, "--tool", TOOL, "--margin", "40")
    assert "not wider than the tip" in err and "use tip <" in err


def test_spheres_switching_sides_are_refused_for_a_cone(tmp_path, capsys, cone_milled):
    _, net = cone_milled
    mesh = QuadMesh.from_obj(net)
    flip = mesh.vertices[:, 0] > 0   # mirror the half x > 0 through the tangent plane
    V = mesh.vertices.copy()
    N = mesh.normals.copy()
    V[flip, 2] *= -1
    N[flip, :2] *= -1
    mesh.with_vertices(V, N).write_obj(tmp_path / "wave.obj")
    err = refused(tmp_path, capsys, tmp_path / "wave.obj", "--tool", TOOL)
    assert "not an S*-net" in err or "switch sides" in err


@pytest.mark.parametrize("tool", ["cone:angle=0,length=5", "cone:angle=45", "cone:length=5",
                                  "cone:angle=45,length=5,D=3", "cone:angle=90,length=5",
                                  "cone:angle=45,length=5,tip=x"])
def test_bad_cone_specs_are_refused(tool):
    with pytest.raises(InputError):
        parse_tool(tool)


def test_cone_spec_round_trips():
    tool = parse_tool("cone:angle=30,length=12,tip=6")
    assert parse_tool(tool.spec()) == tool
    assert tool.end_radius_mm == pytest.approx(3 + 12 * np.tan(np.radians(30)))


def test_a_face_mill_plan_refuses_a_cone():
    from fabplan.fabricate.milling import plan_face_milling

    with pytest.raises(InputError):
        plan_face_milling(bowl(normals=False), parse_tool(TOOL), MillSettings())


# ------------------------------------------------------------------------------ example
@pytest.mark.slow
def test_cone_example_mills_its_sstar_net_without_gouge(tmp_path):
    from tests.test_examples import load_example

    example = load_example("mill_cone_saddle")
    result = example.main(["-o", str(tmp_path)])
    record = json.loads((tmp_path / "mill.json").read_text())
    # against the analytic saddle the S*-net leaves by up to 0.05 mm, with the passes
    # placed on the saddle; the net's distance reported apart
    assert record["target"]["surface"] == "design" and record["paths"]["placed_on"] == "design"
    assert record["gouge_check"]["max_gouge_mm"] <= 0.005
    assert 0.01 < record["net_from_design"]["vertex_max_mm"] < 0.1
    assert record["paths"]["node_shift_from_net_mm"]["max"] <= record["net_from_design"]["vertex_max_mm"]
    assert record["simulation_settings"]["step_mm"] == 0.5
    assert result.plan.path.pass_count == record["passes"]
    simulated, predicted = record["simulation"]["max_scallop_mm"], record["predicted_scallop_mm"]
    assert simulated == pytest.approx(predicted, rel=0.10)
    assert predicted <= example.SCALLOP_MM
