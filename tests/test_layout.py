"""Layouts on design surfaces: initial S-nets that glide into S-nets on the surface.

Every result is measured after the solve, independently of the solver's residuals: star
spheres refitted, distances to the design surface from its own closest-point structure,
edge lengths against the requested panel size, angles between osculating tangents.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.design.mesh_surface import DesignSurface
from fabplan.design.parametric import height_field, surface_from_spec
from fabplan.errors import InputError
from fabplan.layout.directions import (
    comb_cross_field,
    comb_line_field,
    complementary_directions,
    face_principal_frames,
    line_field_index,
    smooth_direction_field,
)
from fabplan.layout.lattice import umbilic_design
from fabplan.layout.settings import SURFACE_TOLERANCE, LayoutSettings
from fabplan.layout.surface_layout import glide, layout_surface
from fabplan.net.geometry import canonical_stars, fit_star_spheres, intersection_angles
from fabplan.net.mesh import QuadMesh
from fabplan.solve.constraints.closeness import closest_points_on_polylines

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from check_buildable import check  # noqa: E402


def _facade_height(x, y):
    """A freeform facade: a twisted saddle with a wave, negatively curved everywhere."""
    return 0.03 * x * y + 0.5 * np.sin(0.2 * x) * np.cos(0.15 * y) + 0.004 * x * x


def assert_snet_on_design(mesh: QuadMesh, design: DesignSurface, panel: float, *,
                          angle: float | None = None) -> dict:
    """The acceptance bounds of a layout; returns the measured numbers."""
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    spheres = fit_star_spheres(X, stars)
    sphere = spheres.residual.max() / mesh.mean_edge_length
    distance = design.distances(X) / panel
    e = mesh.edges
    length = np.linalg.norm(X[e[:, 0]] - X[e[:, 1]], axis=1) / panel
    assert sphere <= 1e-6
    assert distance.max() <= 0.01
    assert 0.5 <= length.min() and length.max() <= 2.0
    measured = dict(sphere=sphere, distance=distance.max(), edges=(length.min(), length.max()))
    if angle is not None:
        a = np.degrees(intersection_angles(X, stars))
        error = np.abs(a - min(angle, 180 - angle)).max()
        assert error <= 0.05
        measured["angle_error"] = error
    return measured


@pytest.fixture(scope="module")
def hypar() -> DesignSurface:
    return load_design("hyperbolic-paraboloid:rise=5", triangles=10000)


@pytest.fixture(scope="module")
def facade_stl(tmp_path_factory) -> Path:
    """A freeform facade as a triangle mesh of more than 20k triangles, saved as STL."""
    surface = height_field(_facade_height, width=30.0, depth=16.0)
    design = surface.triangulate(surface.resolution_for(24000))
    path = tmp_path_factory.mktemp("facade") / "facade.stl"
    design.write(path)
    return path


# ---------------------------------------------------------------------------- acceptance


@pytest.mark.parametrize("net, angle", [("orthogonal", None), ("isogonal", 70.0)])
def test_hyperbolic_paraboloid_layout_glides_into_an_snet(hypar, net, angle):
    layout = layout_surface(hypar, 1.0, angle=angle or 90.0)
    assert len(layout.mesh.irregular_vertices) == 0 and len(layout.singular_points) == 0
    result = glide(layout, net, angle=angle)
    assert result.converged and result.iterations <= 20
    assert_snet_on_design(result.mesh, hypar, 1.0, angle=angle or 90.0)
    # gliding boundary vertices sit on the design boundary
    X = result.mesh.vertices[layout.gliding_boundary]
    foot, _ = closest_points_on_polylines(X, hypar.boundary_curves())
    assert len(X) > 20 and np.linalg.norm(foot - X, axis=1).max() <= 1e-6
    # the record carries the same distances, to the exact surface; the net stays within
    # the gliding band of the triangulation it glided on
    props = result.properties
    X = result.mesh.vertices
    assert props["distance_to_design"]["max"] == pytest.approx(hypar.distances(X).max(), abs=1e-15)
    assert hypar.reference.distances(X).max() <= SURFACE_TOLERANCE * 1.0 * (1 + 1e-6)


def test_tower_of_revolution_closes_up_around_its_axis():
    design = load_design("revolution:height=30,radius=6,waist=0.7", triangles=12000)
    layout = layout_surface(design, 1.5, angle=75.0)
    # one cut, shifting the grid by whole panels: the net closes up around the tower
    assert len(layout.cuts) == 1 and layout.cuts[0][0] == 1 and any(layout.cuts[0][1:])
    mesh = layout.mesh
    z = mesh.vertices[mesh.is_boundary_vertex, 2]
    assert np.all((z < 2 * 1.5) | (z > 30 - 2 * 1.5))   # boundary only at the bottom and top
    result = glide(layout, "isogonal", angle=75.0)
    assert result.converged
    assert_snet_on_design(result.mesh, design, 1.5, angle=75.0)


@pytest.mark.slow
def test_freeform_facade_mesh_through_the_cli(facade_stl, tmp_path, capsys):
    original = facade_stl.read_bytes()
    out = tmp_path / "net" / "facade.obj"
    code = main(["layout", str(facade_stl), "--net", "orthogonal", "--panel-size", "1.0",
                 "-o", str(out)])
    stdout, stderr = capsys.readouterr()
    assert code == 0, stderr
    # progress lines only: no warning, no error
    assert not [line for line in stderr.splitlines() if line.startswith("fabplan:")], stderr
    assert sorted(p.name for p in out.parent.iterdir()) == ["facade.boundary.obj", "facade.json",
                                                           "facade.obj", "facade.png"]
    assert facade_stl.read_bytes() == original
    design = load_design(facade_stl)
    assert len(design.triangles) >= 20000 and design.repairs["welded_vertices"] > 0
    mesh = QuadMesh.from_obj(out)
    measured = assert_snet_on_design(mesh, design, 1.0, angle=90.0)
    record = json.loads(out.with_suffix(".json").read_text())
    props = record["properties"]
    assert props["distance_to_design"]["max"] == pytest.approx(measured["distance"], abs=1e-12)
    assert props["layout"]["design_triangles"] == len(design.triangles)
    assert props["layout"]["quads"] == int(np.sum(mesh.face_sizes == 4)) > 400
    assert "distance to the design surface: max" in stdout
    import matplotlib.image

    picture = matplotlib.image.imread(out.with_suffix(".png"))
    assert picture.ndim == 3 and min(picture.shape[:2]) > 300 and picture.std() > 0.01


@pytest.mark.slow
def test_freeform_facade_mesh_isogonal(facade_stl):
    design = load_design(facade_stl)
    layout = layout_surface(design, 1.0, angle=75.0)
    result = glide(layout, "isogonal", angle=75.0)
    assert result.converged
    assert_snet_on_design(result.mesh, design, 1.0, angle=75.0)


def test_prescribed_floor_levels_get_their_complementary_family():
    design = load_design("tower-facade", triangles=12000)
    layout = layout_surface(design, 1.0, family="z")
    assert layout.angle_deg is None and layout.family.startswith("z levels every")
    result = glide(layout, "snet")
    assert result.converged
    assert_snet_on_design(result.mesh, design, 1.0)
    # the prescribed family stays on the floor levels: each level's vertices at one height,
    # also the corners added on the boundary curve to close the staircase (93 % covered,
    # 88 % without them)
    X, level = result.mesh.vertices, layout.vertex_keys[:, 0]
    assert np.abs(X[:, 2] - level * layout.level_step).max() <= 1e-9
    assert result.properties["coverage"] >= 0.92
    # and the other family is the partner symmetric to the principal directions (S-net):
    # its angle to the floors is twice the floors' angle to a principal direction, here
    # about 45 degrees, far from the degenerate 0
    stars = canonical_stars(X, result.mesh.stars)
    angles = np.degrees(intersection_angles(X, stars))
    assert 35 < angles.min() and angles.max() < 60


def test_floors_given_as_polylines(tmp_path):
    design = load_design("tower-facade:height=12", triangles=8000)
    x = np.linspace(-6.0, 6.0, 25)
    heights = [0.0, 3.0, 6.0, 9.0, 12.0]
    lines = []
    for z in heights:
        y = 4.0 * (2 * x / 12.0) * (z / 12.0) + 0.03 * x * x   # on the facade
        lines += [f"{a:.9f} {b:.9f} {z:.9f}" for a, b in zip(x, y, strict=True)] + [""]
    floors = tmp_path / "floors.txt"
    floors.write_text("\n".join(lines))
    layout = layout_surface(design, 1.0, family=str(floors))
    assert "5 polylines" in layout.family
    result = glide(layout, "snet")
    assert result.converged
    assert_snet_on_design(result.mesh, design, 1.0)
    # vertices on the levels of the polylines lie on those floors
    per_floor = round(1 / layout.level_step)
    level = layout.vertex_keys[:, 0]
    on_floor = np.isfinite(level) & (np.mod(level, per_floor) == 0)
    z = result.mesh.vertices[on_floor, 2]
    assert on_floor.sum() > 20
    assert np.abs(z - 3.0 * level[on_floor] / per_floor).max() <= 0.01


@pytest.mark.slow
def test_umbilics_give_irregular_vertices_in_the_layout_and_the_report(tmp_path, capsys):
    out = tmp_path / "dome.obj"
    code = main(["layout", "paraboloid:radius_x=10,radius_y=14,width=8,depth=8",
                 "--net", "snet", "--panel-size", "0.8", "--triangles", "20000",
                 "--max-iter", "15", "-o", str(out)])
    stdout, stderr = capsys.readouterr()
    assert code in (0, 3), stderr
    assert "the direction field is singular at 2 points" in stderr
    record = json.loads(out.with_suffix(".json").read_text())["properties"]
    layout = record["layout"]
    # the two umbilics of the elliptic paraboloid, lemons of index 1/2, on its long axis
    assert sorted(layout["singular_index"]) == [0.5, 0.5]
    assert np.allclose(np.abs(np.array(layout["singular_points"])[:, 0]), 6.27, atol=0.15)
    assert layout["seam_edges"] > 0 and all(c[0] == -1 for c in layout["cuts"])
    mesh = QuadMesh.from_obj(out)
    assert len(layout["irregular_vertices"]) > 0
    assert layout["irregular_vertices"] == mesh.irregular_vertices.tolist()
    assert record["irregular_vertices"] == layout["irregular_vertices"]
    assert f"{len(layout['irregular_vertices'])} irregular vertices" in stdout


def test_a_field_turning_around_a_point_does_not_crash():
    """At the apex of a paraboloid of revolution every direction is principal and the
    field turns once around it: the net's spirals close in, the layout leaves them out
    within two panels and closes the hole with a fan around one many-valent vertex. (As a
    cross field the turn splits into four quarter-turn singularities no lattice follows:
    the line field is kept.)"""
    design = load_design("paraboloid", triangles=10000)
    layout = layout_surface(design, 0.8)
    assert layout.direction_symmetry == 2
    # one whole turn, found at the apex (or split into two half turns next to it)
    assert layout.singular_index.sum() == 1.0
    assert np.linalg.norm(layout.singular_points, axis=1).max() < 0.5
    assert layout.filled_holes == 1 and layout.open_holes == 0
    mesh = layout.mesh
    pole = np.argmin(np.linalg.norm(mesh.vertices, axis=1))
    assert np.linalg.norm(mesh.vertices[pole]) < 0.2 and mesh.valence[pole] >= 8
    assert pole in mesh.irregular_vertices
    # and the direction field is reported as turning too fast there
    assert np.linalg.norm(layout.turning_points, axis=1).min() < 0.5


# ---------------------------------------------------------------------------- bad input


def _assert_refused(code, capsys, folder: Path, *fragments: str) -> None:
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1
    assert out == "" and "Traceback" not in err
    for fragment in fragments:
        assert fragment in err, err
    assert not list(folder.glob("out*"))


@pytest.mark.parametrize("name, content, fragment", [
    ("notes.obj", b"hello, these are notes\n", "not an OBJ line"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    ("picture.stl", bytes(range(256)) * 4, "picture.stl"),
    ("empty.ply", b"", "empty file"),
    ("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n", "no area"),
    ("fin.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n",
     "edge (0, 1) is shared by 3 triangles (0, 1, 2): the surface is non-manifold"),
    # two sheets touching at one vertex: formerly the smaller one was dropped silently
    ("bowtie.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0 0\nv -1 -1 0\nv 0 -1 0\n"
     b"f 1 2 3\nf 1 3 4\nf 1 5 6\nf 1 6 7\n", "vertex 0 joins two sheets"),
    ("two.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 3 0 0\nv 4 0 0\nv 4 1 0\nv 3 1 0\n"
     b"f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n", "2 separate pieces (the largest is 50 % of the area)"),
])
def test_bad_surfaces_are_refused_in_one_line(tmp_path, capsys, name, content, fragment):
    path = tmp_path / name
    path.write_bytes(content)
    code = main(["layout", str(path), "--net", "snet", "--panel-size", "1",
                 "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, fragment)
    assert path.read_bytes() == content


def test_a_moebius_strip_cannot_be_oriented(tmp_path, capsys):
    k = 24
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    rows = []
    for s in (-0.3, 0.3):
        rows.append(np.stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                              s * np.sin(t / 2)], axis=1))
    V = np.concatenate(rows)
    i = np.arange(k)
    j = (i + 1) % k
    a, b, c, d = i, j, k + j, k + i
    # the last quad closes the strip with a half twist: inner and outer rows swap
    b[-1], c[-1] = k + 0, 0
    T = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    path = tmp_path / "moebius.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V)
                    + "".join(f"f {p + 1} {q + 1} {r + 1}\n" for p, q, r in T))
    code = main(["layout", str(path), "--net", "snet", "--panel-size", "0.1",
                 "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, "cannot be oriented consistently")


@pytest.mark.parametrize("args, fragment", [
    (["--panel-size", "40"], "--panel-size 40: must be at most the extent of hyperbolic-paraboloid"),
    (["--panel-size", "0"], "--panel-size 0: must be at least 1e-06 model units"),
    (["--panel-size", "1", "--angle", "200"], "--angle 200: must be at most 179 degrees"),
    (["--panel-size", "1", "--family", "z", "--angle", "60"], "exclude each other"),
    (["--panel-size", "1", "--family", "missing.txt"], "not x, y, z nor a file of polylines"),
    (["--panel-size", "1", "--triangles", "-5"], "--triangles -5: must be at least 100 (range [100, 5000000"),
])
def test_bad_layout_options_are_refused(tmp_path, capsys, args, fragment):
    code = main(["layout", "hyperbolic-paraboloid", "--net", "snet", "--triangles", "2000",
                 *args, "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, fragment)


@pytest.mark.parametrize("spec, fragment", [
    ("saddle", "unknown surface 'saddle'; known: hyperbolic-paraboloid"),
    ("torus:minor=12", "the minor radius must be smaller than the major radius"),
    ("paraboloid:width=wide", "paraboloid: width wide: must be a number between 0.001 and 1e+07"),
    ("bspline:control_points=nothing.txt", "nothing.txt: no such file"),
    ("paraboloid:radius=5", "surface 'paraboloid' has no parameter 'radius'; its parameters: "
     "radius_x=10, radius_y=10, width=6, depth=6"),
    ("height-field", "surface 'height-field' needs heights=FILE"),
    ("torus:u_deg=5", "u_deg is LO..HI degrees"),     # was a traceback (one number)
])
def test_bad_surface_specs_are_refused(tmp_path, capsys, spec, fragment):
    code = main(["layout", spec, "--net", "snet", "--panel-size", "1",
                 "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, fragment)


# ---------------------------------------------------------------------------- building blocks


def test_complementary_direction_is_symmetric_to_the_principal_directions():
    rng = np.random.default_rng(4)
    angle = rng.uniform(0, np.pi, 50)
    t = np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=1)
    e1 = np.tile([[np.cos(0.3), np.sin(0.3), 0.0]], (50, 1))
    s = complementary_directions(t, e1)
    assert np.allclose(np.linalg.norm(s, axis=1), 1.0)
    # same angle to e1 on the other side: equal normal curvature by Euler's formula
    cross_t = np.cross(e1, t)[:, 2]
    cross_s = np.cross(e1, s)[:, 2]
    assert np.allclose(np.sum(t * e1, axis=1), np.sum(s * e1, axis=1))
    assert np.allclose(cross_t, -cross_s)
    assert np.allclose(complementary_directions(t, -e1), s)


def test_analytic_and_estimated_principal_directions_agree():
    surface = surface_from_spec("hyperbolic-paraboloid:rise=5")
    analytic = surface.triangulate(surface.resolution_for(20000))
    mesh = DesignSurface(analytic.vertices, analytic.triangles, name="same mesh")
    k1a, k2a, e1a = face_principal_frames(analytic)
    k1m, k2m, e1m = face_principal_frames(mesh)
    inner = np.abs(analytic.vertices[analytic.triangles].mean(axis=1)[:, :2]).max(axis=1) < 8
    assert np.abs(k1m - k1a)[inner].max() <= 0.02 * np.abs(k1a).max()
    cosine = np.clip(np.abs(np.sum(e1a * e1m, axis=1)), 0.0, 1.0)
    assert np.degrees(np.arccos(cosine[inner])).max() < 2.0


def test_combing_restores_a_sign_scrambled_field():
    design = surface_from_spec("torus").triangulate(40)
    _, _, e1 = face_principal_frames(design)
    rng = np.random.default_rng(0)
    scrambled = e1 * rng.choice([-1.0, 1.0], size=len(e1))[:, None]
    combed, seam = comb_line_field(design, scrambled)
    reference, reference_seam = comb_line_field(design, e1)
    assert len(seam) == len(reference_seam) == 0
    # the same field up to one global sign
    agree = np.sum(combed * reference, axis=1)
    assert np.allclose(np.abs(agree), 1.0) and np.all(np.sign(agree) == np.sign(agree[0]))


def test_field_index_finds_umbilics():
    lemons = load_design("paraboloid:radius_x=10,radius_y=14,width=8,depth=8", triangles=8000)
    _, _, e1 = face_principal_frames(lemons)
    combed, seam = comb_line_field(lemons, e1)
    index = line_field_index(lemons, combed)
    found = np.flatnonzero(np.nan_to_num(index) != 0)
    assert index[found].tolist() == [0.5, 0.5]
    # the seam of the combed field joins them to the boundary: odd degree at each umbilic
    degree = np.bincount(seam.ravel(), minlength=len(index))
    assert np.all(degree[found] % 2 == 1)


def test_stl_is_welded_and_a_flipped_triangle_is_repaired(tmp_path):
    surface = surface_from_spec("hyperbolic-paraboloid")
    design = surface.triangulate(12)
    T = design.triangles.copy()
    T[7] = T[7][[0, 2, 1]]
    path = tmp_path / "flipped.stl"   # written as a modeller would, flipped triangle and all
    trimesh.Trimesh(design.vertices, T, process=False).export(path)
    loaded = load_design(path)
    assert loaded.repairs["welded_vertices"] == 3 * len(T) - len(design.vertices)
    assert len(loaded.vertices) == len(design.vertices)
    assert loaded.repairs["flipped_triangles"] == 1
    assert np.allclose(loaded.area, design.area)


def test_layout_settings_change_what_is_kept():
    design = load_design("hyperbolic-paraboloid", triangles=4000)
    strict = layout_surface(design, 1.0, settings=LayoutSettings(boundary_snap=0.0))
    assert len(strict.gliding_boundary) <= len(layout_surface(design, 1.0).gliding_boundary)
    with pytest.raises(InputError, match="bisector must be"):
        layout_surface(design, 1.0, settings=LayoutSettings(bisector="mean"))


def _panel_area(mesh: QuadMesh) -> float:
    X, tri = mesh.vertices, mesh.triangles()
    return float(0.5 * np.linalg.norm(np.cross(X[tri[:, 1]] - X[tri[:, 0]],
                                               X[tri[:, 2]] - X[tri[:, 0]]), axis=1).sum())


@pytest.mark.parametrize("spec, angle", [("hyperbolic-paraboloid:width=8,depth=8,rise=2.5", 80.0),
                                         ("tower-facade", 90.0)])
def test_the_boundary_staircase_is_closed_on_the_boundary_curve(spec, angle):
    """Lattice cells cut by the design boundary become quads with their outer corners on
    the boundary curve: the net covers the design up to small corner gaps, and every
    vertex (also those outside the gliding set) ends on the surface."""
    from fabplan.layout.settings import LayoutSettings

    design = load_design(spec, triangles=12000)
    panel = 1.2
    filled = layout_surface(design, panel, angle=angle)
    plain = layout_surface(design, panel, angle=angle,
                           settings=LayoutSettings(boundary_min_edge=10.0))   # nothing passes
    result = glide(filled, "isogonal", angle=angle)
    assert result.converged
    covered = _panel_area(result.mesh) / design.area
    assert covered >= 0.93
    assert covered >= _panel_area(plain.mesh) / design.area + 0.03
    assert_snet_on_design(result.mesh, design, panel, angle=angle)
    assert design.reference.distances(result.mesh.vertices).max() <= SURFACE_TOLERANCE * panel * (1 + 1e-6)


def test_a_prescribed_family_with_a_fixed_angle_net_is_refused(tmp_path, capsys):
    code = main(["layout", "tower-facade", "--net", "orthogonal", "--family", "z",
                 "--panel-size", "1", "--triangles", "2000", "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, "--family and net type 'orthogonal' exclude each other")


def test_a_crumb_of_a_few_triangles_is_dropped_and_counted():
    big = trimesh.creation.box().subdivide().subdivide()
    top = big.vertices[:, 2] > 0.49
    faces = big.faces[top[big.faces].all(axis=1)]
    crumb = np.array([[5.0, 5.0, 0.0], [5.01, 5.0, 0.0], [5.0, 5.01, 0.0]])
    V = np.vstack([big.vertices, crumb])
    T = np.vstack([faces, [[len(big.vertices), len(big.vertices) + 1, len(big.vertices) + 2]]])
    design = DesignSurface(V, T, name="with-crumb")
    assert design.repairs["dropped_pieces"] == 1 and design.repairs["dropped_piece_triangles"] == 1
    assert len(design.triangles) == len(faces)


def _layout_cli(out: Path, capsys, *args: str) -> tuple[dict, QuadMesh, str]:
    """`fabplan layout ARGS --net snet -o OUT`: the measured properties, the net and
    standard error (its warnings and progress lines)."""
    main(["layout", *args, "--net", "snet", "-o", str(out)])
    _, err = capsys.readouterr()
    return json.loads(out.with_suffix(".json").read_text())["properties"], QuadMesh.from_obj(out), err


@pytest.mark.slow
def test_low_coverage_is_measured_and_warned_about(tmp_path, capsys):
    """A dome whose apex is a rotationally symmetric umbilic: the S-net's spirals close in
    on it and leave a hole; the net's share of the design is measured and reported."""
    props, net, err = _layout_cli(tmp_path / "dome.obj", capsys, "paraboloid", "--panel-size",
                                  "0.8", "--triangles", "20000")
    X, faces = net.vertices, net.faces
    design = load_design("paraboloid", triangles=20000)
    area = sum(0.5 * np.linalg.norm(np.cross(X[f[2]] - X[f[0]], X[f[3]] - X[f[1]])) for f in faces)
    # the full panels' share, sampled on the design, against their area: the two measures
    # agree to the panels' curvature and the net's distance from the design
    assert props["coverage_net"] == pytest.approx(area / design.area, abs=0.02)
    assert props["coverage"] >= props["coverage_net"]
    if props["coverage"] < 0.999:
        assert f"cover only {100 * props['coverage']:.1f} % of the design" in err
        gap = props["boundary_panels"]["gaps"][0]       # the largest, said where it is
        assert "around (" + ", ".join(f"{v:.4g}" for v in gap["point"]) + ")" in err
        assert sum(g["area"] for g in props["boundary_panels"]["gaps"]) <= \
            (1 - props["coverage"]) * design.area * (1 + 1e-9)
    else:
        assert "cover only" not in err


def test_distance_to_a_parametric_design_is_measured_to_the_exact_surface(tmp_path, capsys):
    """A net glided on a 200-triangle torus follows its chords; measured against the exact
    torus it is off by the chord error, and the user is told to refine the triangulation."""
    props, net, err = _layout_cli(tmp_path / "torus.obj", capsys, "torus", "--panel-size", "1.5",
                                  "--triangles", "200")
    X = net.vertices
    # independent measure: distance to the torus of radii 10 and 4 about the z-axis
    ring = np.hypot(X[:, 0], X[:, 1]) - 10.0
    exact = np.abs(np.hypot(ring, X[:, 2]) - 4.0)
    assert props["distance_measured_to"] == "the exact parametric surface"
    assert props["distance_to_design"]["max"] == pytest.approx(exact.max(), rel=1e-6)
    assert exact.max() > 0.01 * 1.5
    assert "raise --triangles" in err


def test_floors_of_a_surface_of_revolution_have_no_partner_family(tmp_path, capsys):
    """The floor levels of a tower of revolution are lines of curvature: the reflection in
    the principal directions maps them onto themselves, so no S-net partner crosses them."""
    code = main(["layout", "revolution", "--net", "snet", "--family", "z", "--panel-size", "1",
                 "--triangles", "4000", "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, tmp_path, "follow a principal direction")


@pytest.mark.slow
def test_a_net_type_that_changes_the_surface_is_pointed_to_optimize(tmp_path, capsys):
    """Held near a dome, a linear Weingarten net cannot form (exit 3, with the way out);
    optimized with the dome as a reference surface (a built-in spec) it does."""
    first = tmp_path / "glide.obj"
    code = main(["layout", "paraboloid", "--net", "linear-weingarten", "--panel-size", "1",
                 "--triangles", "6000", "-o", str(first)])
    _, err = capsys.readouterr()
    assert code == 3 and "exist on special surfaces only" in err
    second = tmp_path / "free.obj"
    # within 0.1 (held in the solve: the default limit of 20 mm is for facades in metres)
    code = main(["optimize", str(first), "--net", "linear-weingarten", "--reference",
                 "paraboloid", "--max-deviation", "0.1", "-q", "-o", str(second)])
    props = json.loads(second.with_suffix(".json").read_text())["properties"]
    assert code == 0 and props["sphere_residual_relative"]["max"] <= 1e-6
    assert props["distance_to_reference"]["max"] <= 0.1


def _wavy_height(x, y):
    """A wavy facade of mixed curvature, 30 x 15, with three near-umbilics inside: points
    where |k1 - k2| drops to a few hundredths of its median without the principal
    directions becoming singular, so that they turn fast around them."""
    x, y = x + 15.0, y + 7.5
    u, w = x - 15.0, y - 7.5
    return 0.02 * u * w + 0.6 * np.sin(0.25 * x) * np.cos(0.2 * y) + 0.003 * u * u


@pytest.mark.slow
def test_fast_turning_principal_directions_are_found_and_reported():
    """At 70 degrees the net's directions are the principal ones turned by 35 degrees. As
    a line field (here forced: no cross field is tried) they turn fast around the
    near-umbilics, and the layout says where; by default the combed cross field carries
    the bisector instead and turns slowly (next test)."""
    wavy = height_field(_wavy_height, width=30.0, depth=15.0).triangulate((120, 60))
    layout = layout_surface(wavy, 1.0, angle=70.0, settings=LayoutSettings(max_smoothing=0.25))
    assert layout.direction_symmetry == 2
    # the near-umbilics, located independently: minima of |k1 - k2| on a fine grid
    expected = np.array([[2.45, 4.75], [27.55, 4.7], [22.7, 11.0]]) - [15.0, 7.5]
    found = layout.turning_points[:, :2]
    assert len(found) == 3
    gap = np.linalg.norm(found[:, None] - expected[None], axis=2).min(axis=0)
    assert gap.max() < 1.5 and (layout.turning_deg > 30).all()
    record = layout.record()
    assert len(record["fast_turning_points"]) == 3 and record["direction_field"] == "line"
    # a facade of the same size whose principal directions turn slowly has none
    calm = height_field(_facade_height, width=30.0, depth=16.0).triangulate((120, 60))
    assert len(layout_surface(calm, 1.0, angle=70.0).turning_points) == 0


def test_the_bisector_setting_turns_the_isogonal_layout():
    """Regression: the combed cross field was turned to the larger principal curvature's
    direction whatever `LayoutSettings.bisector` said. On the saddle z = x y the principal
    directions run along the diagonals, so the families of a 70 deg net lie 35 deg from
    the one diagonal ("max") or the other ("min"): 20 deg apart."""
    saddle = surface_from_spec("hyperbolic-paraboloid:width=5,depth=5,rise=3").triangulate((60, 60))

    def family_angles(bisector: str) -> np.ndarray:
        layout = layout_surface(saddle, 0.8, angle=70.0, settings=LayoutSettings(bisector=bisector))
        X = layout.mesh.vertices
        f = min(layout.mesh.faces, key=lambda q: np.linalg.norm(X[q][:, :2].mean(axis=0)))
        d = X[f[1:3]][:, :2] - X[f[:2]][:, :2]
        return np.sort(np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180.0)

    a, b = family_angles("max"), family_angles("min")
    gap = np.abs((a[:, None] - b[None, :] + 90.0) % 180.0 - 90.0).min(axis=1)
    assert np.all(gap > 10.0), (a, b)


def test_an_isogonal_net_takes_its_bisector_from_the_cross_field():
    """Regression: an isogonal layout smoothed the larger principal direction as a line
    field, which swaps by a quarter turn where a wave's curvature changes sign; the
    parametrization folded there and the nets of the wavy facades covered 85-95 % of them.
    The combed cross field is a principal direction everywhere and turns slowly."""
    wavy = height_field(_wavy_height, width=30.0, depth=15.0).triangulate((120, 60))
    layout = layout_surface(wavy, 1.0, angle=70.0)
    assert layout.direction_symmetry == 4 and len(layout.turning_points) == 0
    net = glide(layout, "isogonal", angle=70.0)
    assert net.converged and net.properties["coverage"] >= 0.999
    # the parametrization does not fold: its triangles' parameter areas sum to its union
    import shapely

    triangles = shapely.polygons(layout.chart.P)
    assert shapely.area(triangles).sum() <= 1.01 * shapely.union_all(triangles).area


@pytest.mark.slow
@pytest.mark.parametrize("panel", [1.0, 0.6])
def test_a_facade_with_near_umbilics_gets_an_orthogonal_snet(tmp_path, panel):
    """Across the near-umbilics of the wavy facade the principal directions turn by a
    quarter turn within two panels, which no lattice follows as a line field; as a cross
    field they need not turn at all, and the net forms within the acceptance bounds
    (it stagnated at 87 % coverage before, and folded at panel 0.4)."""
    surface = height_field(_wavy_height, width=30.0, depth=15.0)
    path = tmp_path / "wavy.stl"
    surface.triangulate(surface.resolution_for(24000)).write(path)
    design = load_design(path)
    assert len(design.triangles) >= 20000 and design.parametric is None
    layout = layout_surface(design, panel)
    assert layout.direction_symmetry == 4 and len(layout.turning_points) == 0
    result = glide(layout, "snet")
    assert result.converged
    measured = assert_snet_on_design(result.mesh, design, panel)
    assert measured["distance"] <= SURFACE_TOLERANCE * (1 + 1e-6)
    assert result.properties["coverage"] >= 0.97


def test_closest_points_on_a_parametric_design_never_move_away():
    """Gauss-Newton steps were taken unchecked: inside a tower one point came out at
    14.6 where the surface is at most 9.7 away. Now a step that does not bring the point
    closer is halved, and the result is checked against the torus's own distance."""
    design = load_design("revolution:height=30,radius=6,waist=0.7", triangles=4000)
    inside = np.array([[0.5, 0.3, 15.0], [0.0, 0.0, 2.0], [1.0, -1.0, 28.0]])
    d = design.distances(inside)
    mesh_d = design.reference.distances(inside)
    assert np.all(d <= mesh_d + design.chord_error + 1e-9)
    torus = load_design("torus", triangles=4000)
    rng = np.random.default_rng(0)
    foot = torus.vertices[rng.integers(0, len(torus.vertices), 50)]
    points = foot + 0.3 * rng.normal(size=foot.shape)
    ring = np.hypot(points[:, 0], points[:, 1]) - 10.0
    exact = np.abs(np.hypot(ring, points[:, 2]) - 4.0)
    # inside the patch the distance to the patch is the distance to the whole torus
    assert np.all(torus.distances(points) >= exact - 1e-9)
    assert np.median(torus.distances(points) - exact) < 1e-9


def test_tree_edge_values_do_not_overflow_on_large_designs():
    """Keys ``parent * count + child`` overflowed 32 bits from 46,341 triangles on (scipy
    returns int32 predecessors): on a 50k-triangle facade the cross field was combed
    wrong across 6,786 of 74,533 edges."""
    from fabplan.net.forest import tree_edge_values

    count = 60000
    child = np.arange(1, count)
    parent = np.r_[-1, child - 1].astype(np.int32)          # a chain, 32-bit as from scipy
    value = (child % 3 == 0).astype(np.int64)
    out = tree_edge_values(count, child - 1, child, value, parent)
    assert np.array_equal(out[1:], value) and out[0] == 0


def _flat_disk(seed: int = 0) -> DesignSurface:
    """A flat disk of radius 5 whose triangles start at random corners (random frames)."""
    surface = height_field(lambda x, y: 0 * x, width=10.0, depth=10.0)
    design = surface.triangulate((40, 40))
    V = design.vertices
    keep = np.linalg.norm(V[design.triangles].mean(axis=1)[:, :2], axis=1) < 5.0
    T = design.triangles[keep]
    shift = np.random.default_rng(seed).integers(0, 3, len(T))
    T = np.take_along_axis(T, (np.arange(3) + shift[:, None]) % 3, axis=1)
    used, T = np.unique(T, return_inverse=True)
    return DesignSurface(V[used], T.reshape(-1, 3), name="disk")


@pytest.mark.parametrize("symmetry", [2, 4])
def test_a_constant_field_survives_smoothing_in_any_frames(symmetry):
    disk = _flat_disk()
    d = np.tile([np.cos(0.3), np.sin(0.3), 0.0], (len(disk.triangles), 1))
    if symmetry == 4:            # the cross scrambled by quarter turns, as a cross it is one
        quarter = np.random.default_rng(1).integers(0, 2, len(d)).astype(bool)
        d[quarter] = np.cross(disk.face_normals[quarter], d[quarter])
    out, coherence = smooth_direction_field(disk, d, np.ones(len(d)), 2.0, symmetry=symmetry)
    if symmetry == 4:
        out = comb_cross_field(disk, out)
        assert np.allclose(np.abs(np.sum(out * d, axis=1)) + np.abs(
            np.sum(np.cross(out, d) * disk.face_normals, axis=1)), 1.0, atol=1e-6)
    lines = np.abs(np.sum(out * out[0], axis=1))
    assert lines.min() > 1 - 1e-9 and coherence.min() > 1 - 1e-6


@pytest.mark.parametrize("turns", [1, -1, 2])
def test_a_cross_field_turning_a_quarter_around_a_point_has_index_a_quarter(turns):
    disk = _flat_disk()
    c = disk.vertices[disk.triangles].mean(axis=1)
    theta = turns * np.arctan2(c[:, 1], c[:, 0]) / 4
    d = np.stack([np.cos(theta), np.sin(theta), 0 * theta], axis=1)
    index = line_field_index(disk, d, symmetry=4)
    inner = np.flatnonzero(np.nan_to_num(index) != 0)
    assert len(inner) == 1 and index[inner[0]] == turns / 4
    assert np.linalg.norm(disk.vertices[inner[0], :2]) < 0.5


def test_distance_to_a_built_in_reference_is_measured_to_the_exact_surface():
    """A net whose vertices lie on the exact saddle is 0 from it, although its
    triangulation's chords are off the surface between their corners."""
    from fabplan.net.measure import measure_net

    design = load_design("hyperbolic-paraboloid:width=6,depth=4,rise=2", triangles=800)
    s = design.parametric
    u, v = np.meshgrid(np.linspace(-5.3, 5.3, 12), np.linspace(-3.3, 3.3, 9), indexing="ij")
    net = QuadMesh.grid(s.points(u, v))
    record = measure_net(net, reference=design.reference)
    assert record["distance_to_reference"]["max"] <= 1e-9
    chords = np.linalg.norm(design.reference.closest_points(net.vertices)[0] - net.vertices, axis=1)
    assert chords.max() > 1e-4      # what the triangles alone would have said


def test_a_pickled_layout_leaves_its_chart_behind_and_makes_it_again():
    """A study's workers exchange layouts: the chart cache (several times the layout's
    size) is not sent, and a received layout makes the same chart again."""
    import cloudpickle  # what Dask sends with: built-in designs hold lambdas

    from fabplan.layout.surface_layout import layout_surface

    design = load_design("hyperbolic-paraboloid:width=6,depth=6,rise=1.5", triangles=3000)
    layout = layout_surface(design, 1.0, angle=90.0)
    bare = len(cloudpickle.dumps(layout))
    chart = layout.chart
    assert len(cloudpickle.dumps(layout)) < 1.2 * bare          # the cache stays home
    received = cloudpickle.loads(cloudpickle.dumps(layout))
    assert "chart" not in vars(received)
    np.testing.assert_array_equal(received.chart.P, chart.P)
    np.testing.assert_array_equal(received.vertex_keys, layout.vertex_keys)


def _bumps(seed: int):
    """Six seeded Gaussian bumps and dents on 16 x 16 m: domes, saddles and umbilics
    between them."""
    rng = np.random.default_rng(seed)
    centres, heights = rng.uniform(-6, 6, size=(6, 2)), rng.uniform(-1.2, 1.2, size=6)
    widths = rng.uniform(2.0, 4.0, size=6)

    def z(x, y):
        return sum(h * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / w**2)
                   for (cx, cy), h, w in zip(centres, heights, widths, strict=True)) + 0 * x

    surface = height_field(z, width=16.0, depth=16.0)
    return surface.triangulate(surface.resolution_for(12000))


@pytest.mark.slow
def test_a_lattice_broken_by_umbilics_is_refused_with_the_reason(tmp_path, capsys):
    """Regression: on six bumps and dents the layout's quads covered 3 % of the design
    and boundary panels the size of the gaps the rest; the net was written as converged.
    Such a layout is refused, counting the singular points, with nothing written; a
    coarse layout of a few panels (whose raw lattice stops short all round) is not."""
    path = tmp_path / "bumps.obj"
    _bumps(3).write(path)
    out = tmp_path / "out" / "net.obj"
    code = main(["layout", str(path), "--net", "snet", "--panel-size", "0.72", "-o", str(out), "-q"])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("fabplan: error:")]
    assert code != 0 and len(lines) == 1 and "does not hold together" in lines[0], err
    assert "7 singular points of the principal directions" in lines[0]
    assert not (tmp_path / "out").exists()
    coarse = tmp_path / "coarse" / "net.obj"
    assert main(["layout", "paraboloid", "--net", "snet", "--panel-size", "4.2", "-o", str(coarse),
                 "-q"]) == 0


def _dune(folder: Path) -> str:
    """A new user's dune roof, 24 x 16 m: a bump, a ripple and noise (seeded), whose
    principal directions have many umbilics at panel sizes near a metre."""
    rng = np.random.default_rng(77)
    x, y = np.meshgrid(np.linspace(-12, 12, 11), np.linspace(-8, 8, 9), indexing="ij")
    heights = (1.2 * np.exp(-(x / 9) ** 2 - (y / 7) ** 2) + 0.3 * np.sin(x / 4)
               + 0.03 * rng.normal(size=x.shape))
    np.savetxt(folder / "dune-heights.txt", heights)
    return f"height-field:heights={folder / 'dune-heights.txt'},width=24,depth=16"


@pytest.mark.slow
def test_a_layout_that_does_not_hold_together_says_at_which_panel_size_it_does(tmp_path, capsys):
    """At 1.2 m the dune's lattice breaks apart; a study at 1.2 m is refused in one line
    that gives the panel size at which it holds (`holding_panel_size`), with nothing
    written, and the layout at that size is made."""
    import re

    from fabplan.errors import BrokenLayoutError
    from fabplan.layout.surface_layout import HOLDING_SIZE_FACTORS

    design = load_design(_dune(tmp_path), triangles=12000)
    with pytest.raises(BrokenLayoutError, match="does not hold together"):
        layout_surface(design, 1.2)
    (tmp_path / "dune.toml").write_text("""
[design]
surface = "height-field"
parameters = { heights = "dune-heights.txt", width = 24, depth = 16 }
triangles = 12000
[panels]
size = 1.2
[limits]
max_deviation_mm = 50
mold_tolerance_mm = 3
[[candidates]]
net = "cmc"
""")
    code = main(["study", str(tmp_path / "dune.toml"), "-q", "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "the layout at panel size 1.2 does not hold together" in err
    given = re.search(r"a lattice on the design holds together at panel size ([0-9.]+): give "
                      r"panels.size "
                      r"= \1$", err.strip())
    assert given, err
    held = float(given[1])
    assert any(np.isclose(held, 1.2 * f) for f in HOLDING_SIZE_FACTORS)
    assert not (tmp_path / "out").exists()
    assert len(layout_surface(design, held).mesh.stars) > 0


def _spherical_cap(radius: float = 20.0, span: float = 30.0, seed: int = 4) -> DesignSurface:
    """A dome: the cap of a sphere of `radius` over a circle of `span` (m), as an irregular
    triangulation of jittered points."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    a = span / 2
    xs = np.arange(-a, a + 0.5, 0.5)
    P = np.stack(np.meshgrid(xs, xs), axis=-1).reshape(-1, 2)
    P = P + rng.uniform(-0.075, 0.075, P.shape)
    P = P[np.hypot(P[:, 0], P[:, 1]) < a - 0.25]
    t = np.linspace(0.0, 2 * np.pi, int(np.ceil(2 * np.pi * a / 0.5)), endpoint=False)
    P = np.vstack([P, a * np.stack([np.cos(t), np.sin(t)], axis=1)])
    z = np.sqrt(radius**2 - np.sum(P**2, axis=1)) - np.sqrt(radius**2 - a**2)
    triangles = Delaunay(P).simplices
    V = np.column_stack([P, z])
    up = np.cross(V[triangles[:, 1]] - V[triangles[:, 0]], V[triangles[:, 2]] - V[triangles[:, 0]])
    triangles[up[:, 2] < 0] = triangles[up[:, 2] < 0][:, ::-1]
    return DesignSurface(V, triangles, name="dome")


@pytest.mark.parametrize("size", [1.5, 3.0])
def test_a_dome_is_laid_out_along_its_long_axis_and_glides_as_an_s_net(size):
    """A sphere has no principal directions (its anisotropy is the estimate's noise):
    the layout refused a 30 m dome at 1.5 m panels ("no quad could be laid out") and at
    0.75 m named six singular points. Every net on a sphere is an S-net: the lines follow
    the dome's long axis, without a singular point, and the net glides on the dome to a
    converged S-net whose spheres are the dome's."""
    design = _spherical_cap()
    k1, k2, _ = face_principal_frames(design)
    assert umbilic_design(k1, k2, design.face_areas)
    layout = layout_surface(design, size)
    assert len(layout.singular_points) == 0
    assert layout.mesh.irregular_vertices.size == 0
    result = glide(layout, net="snet")
    assert result.converged, result.message
    # buildable by the benchmarks' own check: no dart, no line turning back
    own = check(result.mesh.vertices, result.mesh.faces, max_turn_deg=45.0)
    assert own["buildable"] and own["darts"] == 0, own
    stars = canonical_stars(result.mesh.vertices, result.mesh.stars)
    spheres = fit_star_spheres(result.mesh.vertices, stars)
    # the dome's triangles are its chords, and the net glides on them within a tolerance:
    # a millimetre changes the sphere of a star 3 m across by about 2 %
    assert np.allclose(spheres.radius, 20.0, rtol=0.05)
    assert np.median(spheres.radius) == pytest.approx(20.0, rel=0.01)
    assert result.properties["coverage"] >= 0.999


def test_no_quad_at_a_panel_size_of_hundreds_says_why():
    """A blob canopy (two bumps and a dip, 20 x 14 m) at 1.2 m panels gives no quad: it
    was told "too large for the surface, or a degenerate direction field", while 1.5 m
    lays out. The message now gives the reason that holds: the line field, with its
    singular points, at about 200 panels."""
    def blob(x, y):
        return (3.0 + 1.6 * np.exp(-((x + 4.5) ** 2 + (y - 1.5) ** 2) / 12.0)
                + 1.1 * np.exp(-((x - 4.0) ** 2 + (y + 2.0) ** 2) / 9.0)
                - 0.8 * np.exp(-((x - 0.5) ** 2 + (y - 3.5) ** 2) / 6.0) + 0.02 * x)

    x, y = np.meshgrid(np.linspace(-10, 10, 101), np.linspace(-7, 7, 71), indexing="ij")
    idx = np.arange(x.size).reshape(x.shape)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    T = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    design = DesignSurface(np.stack([x, y, blob(x, y)], -1).reshape(-1, 3), T, name="blob")
    with pytest.raises(InputError) as caught:
        layout_surface(design, 1.2)
    text = str(caught.value)
    assert "no quad could be laid out at panel size 1.2" in text
    assert "at about 199 panels the line field gives no quad" in text and "singular points" in text
    assert "too large for the surface" not in text


def test_a_row_of_boundary_panels_is_not_said_to_stop_short():
    """A small part (147 x 126 mm at 12 mm panels) has a tenth of its area in its one row
    of boundary panels: that is no layout stopping far short of the boundary. More than a
    row's share is."""
    from fabplan import load_design
    from fabplan.cli.layout import boundary_ring_share, layout_warnings

    design = load_design("hyperbolic-paraboloid", triangles=2000)
    ring = boundary_ring_share(design, 1.0)
    extent = np.ptp(design.vertices[:, :2], axis=0)
    assert ring == pytest.approx(2 * extent.sum() / np.prod(extent), rel=0.1)
    props = {"coverage": 1.0, "coverage_net": 1.0 - 0.9 * ring,
             "edge_length_relative_to_panel": {"min": 0.9, "max": 1.1},
             "distance_to_design_relative_to_panel": {"max": 0.0},
             "distance_to_design": {"max": 0.0}}
    assert not any("stops far short" in w for w in layout_warnings(props, ring))
    props["coverage_net"] = 1.0 - 1.2 * ring
    said = [w for w in layout_warnings(props, ring) if "stops far short" in w]
    assert said and f"would ({100 * ring:.0f} %)" in said[0]
