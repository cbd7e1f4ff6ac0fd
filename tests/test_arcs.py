"""Circular arc structures: every edge an arc through its end vertices, all arcs at a
vertex tangent to one plane, written as true arcs to .3dm and DXF and read back."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import patch_of

import fabplan
from fabplan.cli import main
from fabplan.fabricate.arcs import arc_structure
from fabplan.net.geometry import fit_star_spheres


def _tangents_from_circles(arcs, end: int) -> np.ndarray:
    """Unit tangents at an end of every arc from its circle alone (centre, axis), not
    from the tangents the construction stored; straight arcs give the chord."""
    X = arcs.mesh.vertices
    p = X[arcs.edges[:, end]]
    t = np.cross(arcs.axis, p - arcs.centre)
    chord = X[arcs.edges[:, 1]] - X[arcs.edges[:, 0]]
    t = np.where(arcs.straight[:, None], chord, t)
    return t / np.linalg.norm(t, axis=1, keepdims=True)


def _plane_defects(arcs) -> np.ndarray:
    """(n,) largest angle between a vertex's arc tangents and the plane that fits them
    best (its own fit, independent of the planes the construction chose)."""
    tangents = np.r_[_tangents_from_circles(arcs, 0), _tangents_from_circles(arcs, 1)]
    at = np.r_[arcs.edges[:, 0], arcs.edges[:, 1]]
    order = np.argsort(at, kind="stable")
    groups = np.split(tangents[order], np.flatnonzero(np.diff(at[order])) + 1)
    out = []
    for t in groups:
        normal = np.linalg.svd(t)[2][-1]
        out.append(np.arcsin(np.abs(t @ normal).max()))
    return np.array(out)


@pytest.fixture(scope="module")
def wein_arcs(wein99):
    return arc_structure(wein99)


def test_arcs_pass_through_their_end_vertices(wein_arcs, wein99):
    X, e = wein99.vertices, wein_arcs.edges
    edge = wein99.mean_edge_length
    curved = ~wein_arcs.straight
    assert curved.all()
    for end in (0, 1):
        on_circle = np.abs(np.linalg.norm(X[e[:, end]] - wein_arcs.centre, axis=1) - wein_arcs.radius)
        assert on_circle.max() < 1e-9 * edge
        in_plane = np.abs(np.sum((X[e[:, end]] - wein_arcs.centre) * wein_arcs.axis, axis=1))
        assert in_plane.max() < 1e-9 * edge
    assert np.linalg.norm(wein_arcs.points(1.0) - X[e[:, 1]], axis=1).max() < 1e-9 * edge


def test_arcs_at_every_vertex_touch_one_plane(wein_arcs):
    defects = _plane_defects(wein_arcs)
    assert len(defects) == wein_arcs.mesh.vertex_count
    assert defects.max() < 1e-6
    assert np.nanmax(wein_arcs.tangent_defect) < 1e-6


def test_inner_arcs_are_where_the_spheres_meet(wein_arcs, wein99):
    """An arc between two regular vertices lies on both their Meusnier spheres, up to the
    net's sphere residual (an independent sphere fit, not the construction's planes)."""
    X = wein99.vertices
    spheres = fit_star_spheres(X, wein99.stars)
    star_of = wein99.star_of_vertex
    inner = np.all(star_of[wein_arcs.edges] >= 0, axis=1)
    residual = spheres.residual.max()
    for t in (0.25, 0.5, 0.75):
        p = wein_arcs.points(t)[inner]
        for end in (0, 1):
            s = star_of[wein_arcs.edges[inner, end]]
            gap = np.abs(np.linalg.norm(p - spheres.centre[s], axis=1) - spheres.radius[s])
            assert gap.max() < 2 * residual + 1e-12
    # Fig. 21: on this Weingarten net the inner arcs are short arcs of near-constant radius
    assert np.degrees(wein_arcs.angle[inner]).max() < 20
    assert np.ptp(wein_arcs.radius[inner]) < 0.01 * np.median(wein_arcs.radius[inner])


def test_arcs_of_a_net_on_a_sphere_lie_on_it():
    theta, phi = np.meshgrid(np.linspace(0.5, 1.3, 6), np.linspace(0, 1.2, 7), indexing="ij")
    points = 3 * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)],
                          axis=-1)
    arcs = arc_structure(fabplan.QuadMesh.grid(points))
    for t in (0.3, 0.5):
        assert np.abs(np.linalg.norm(arcs.points(t), axis=1) - 3).max() < 1e-12
    assert _plane_defects(arcs).max() < 1e-9
    # meridians are great circles
    meridian = arcs.family == arcs.family[0]
    assert np.allclose(arcs.radius[meridian], 3) or np.allclose(arcs.radius[~meridian], 3)


def test_arcs_of_a_plane_net_are_straight():
    u, v = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-1, 1, 5), indexing="ij")
    arcs = arc_structure(fabplan.QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1)))
    assert arcs.straight.all() and np.all(arcs.sagitta == 0)
    summary = arcs.summary()
    assert summary["straight_arcs"] == len(arcs.edges) and summary["radius"]["max"] is None


@pytest.mark.parametrize("bend", [1e-6, 1e-8, 1e-10])
def test_arcs_of_a_nearly_plane_net_end_at_their_vertices(bend):
    """Arcs of radii up to 1e10 edges (a facade that is almost flat) still end where their
    edges do, and bow by the sagitta their radius gives."""
    u, v = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-1, 1, 5), indexing="ij")
    mesh = fabplan.QuadMesh.grid(np.stack([u, v, bend * (u * u + v * v)], axis=-1))
    arcs = arc_structure(mesh)
    X = mesh.vertices
    assert np.abs(arcs.points(0.0) - X[arcs.edges[:, 0]]).max() < 1e-12
    assert np.abs(arcs.points(1.0) - X[arcs.edges[:, 1]]).max() < 1e-12
    assert arcs.summary()["end_vertex_gap_relative_to_edge"] < 1e-10
    curved = ~arcs.straight
    chord = np.linalg.norm(X[arcs.edges[curved, 1]] - X[arcs.edges[curved, 0]], axis=1)
    R = arcs.radius[curved]
    assert curved.any() and np.allclose(arcs.sagitta[curved],
                                        chord**2 / 4 / (R + np.sqrt(R**2 - chord**2 / 4)),
                                        rtol=1e-9, atol=0)
    mid = arcs.points(0.5)[curved] - 0.5 * (X[arcs.edges[curved, 0]] + X[arcs.edges[curved, 1]])
    assert np.allclose(np.linalg.norm(mid, axis=1), arcs.sagitta[curved], rtol=1e-6, atol=1e-14)


NETS = [pytest.param(0.12, id="wein99-patch"),
        pytest.param(None, id="wein99", marks=pytest.mark.slow)]


@pytest.fixture
def net_file(request, tmp_path, wein99):
    """The bundled Weingarten net, or a patch of it (quick), as an OBJ file."""
    if request.param is None:
        return fabplan.data_path("wein99.obj")
    path = tmp_path / "patch.obj"
    patch_of(wein99, request.param).write_obj(path)
    return path


@pytest.mark.parametrize("net_file", NETS, indirect=True)
def test_arcs_dxf_reads_back_audit_clean(tmp_path, net_file):
    import ezdxf

    wein99 = fabplan.read_obj(net_file)
    wein_arcs = arc_structure(wein99)
    out = tmp_path / "arcs.dxf"
    # exit 3 only for arcs past the angle limit (the long arcs where boundary fronts meet)
    code = main(["arcs", str(net_file), "-o", str(out)])
    angle = json.loads(out.with_suffix(".json").read_text())["limits"]["max_arc_angle_deg"]
    assert code == (3 if angle["over"] else 0)
    doc = ezdxf.readfile(out)
    auditor = doc.audit()
    assert not auditor.has_errors and not auditor.has_fixes
    assert doc.header["$INSUNITS"] == 4
    entities = doc.modelspace().query("ARC")
    assert len(entities) == len(wein_arcs.edges)
    start = np.array([list(a.start_point) for a in entities]) / 1000
    end = np.array([list(a.end_point) for a in entities]) / 1000
    radius = np.array([a.dxf.radius for a in entities]) / 1000
    extrusion = np.array([list(a.dxf.extrusion) for a in entities])
    X, e = wein99.vertices, wein_arcs.edges
    edge = wein99.mean_edge_length
    assert np.abs(start - X[e[:, 0]]).max() < 1e-9 * edge
    assert np.abs(end - X[e[:, 1]]).max() < 1e-9 * edge
    assert np.allclose(radius, wein_arcs.radius, rtol=1e-12)
    assert np.allclose(extrusion, wein_arcs.axis, atol=1e-12)
    layers = {a.dxf.layer for a in entities}
    assert layers == {"ARCS_A", "ARCS_B"}
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["units"] == "mm" and len(report["arcs"]) == len(entities)
    assert report["summary"]["tangent_plane_defect_deg"]["max"] < np.degrees(1e-6)


@pytest.mark.parametrize("net_file", NETS, indirect=True)
def test_arcs_3dm_holds_true_arcs(tmp_path, net_file):
    import rhino3dm

    wein99 = fabplan.read_obj(net_file)
    wein_arcs = arc_structure(wein99)
    out = tmp_path / "arcs.3dm"
    # exit 3 only for arcs past the angle limit (the long arcs where boundary fronts meet)
    code = main(["arcs", str(net_file), "-o", str(out)])
    angle = json.loads(out.with_suffix(".json").read_text())["limits"]["max_arc_angle_deg"]
    assert code == (3 if angle["over"] else 0)
    doc = rhino3dm.File3dm.Read(str(out))
    assert doc.Settings.ModelUnitSystem == rhino3dm.UnitSystem.Meters
    X, e = wein99.vertices, wein_arcs.edges
    seen = 0
    for obj in doc.Objects:
        curve = obj.Geometry
        assert isinstance(curve, rhino3dm.ArcCurve)
        k = int(obj.Attributes.GetUserString("edge"))
        assert obj.Attributes.Name == f"edge {k}"
        a, b = curve.PointAtStart, curve.PointAtEnd
        assert np.allclose([a.X, a.Y, a.Z], X[e[k, 0]], atol=1e-9)
        assert np.allclose([b.X, b.Y, b.Z], X[e[k, 1]], atol=1e-9)
        assert curve.Radius == pytest.approx(wein_arcs.radius[k], rel=1e-9)
        seen += 1
    assert seen == len(e)


def test_arcs_refuses_other_outputs_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "arcs.svg"
    assert main(["arcs", str(fabplan.data_path("wein99.obj")), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ".3dm or a .dxf" in err[0]
    assert list(tmp_path.iterdir()) == []


def test_arcs_dxf_in_millimetres_from_feet(tmp_path, wein99):
    """A net in feet: the DXF's arcs are its arcs scaled to millimetres."""
    net = patch_of(wein99, 0.1)
    net.write_obj(tmp_path / "net.obj")
    out = tmp_path / "arcs.dxf"
    # the patch's corner arcs reach past the default angle limit: this test is of units
    assert main(["arcs", str(tmp_path / "net.obj"), "--units", "ft", "--max-arc-angle", "180",
                 "-o", str(out)]) == 0
    import ezdxf

    radius = sorted(a.dxf.radius for a in ezdxf.readfile(out).modelspace().query("ARC"))
    assert np.allclose(radius, np.sort(arc_structure(net).radius) * 304.8, rtol=1e-12)


def test_boundary_arcs_stay_short(wein_arcs, cmc1):
    """Arcs at boundary vertices continue the parameter lines' circles, and the planes of
    the vertices along the boundary fit the arcs between them: on both of the authors'
    nets every arc is about as short as the inner ones (on the Weingarten net the edges
    where two chains of boundary planes met were arcs of up to 98 degrees), and the arcs
    at every vertex touch its plane."""
    for net, arcs in ((cmc1, arc_structure(cmc1)), (None, wein_arcs)):
        mesh = arcs.mesh if net is None else net
        inner = np.all(mesh.star_of_vertex[arcs.edges] >= 0, axis=1)
        assert np.degrees(arcs.angle).max() <= 1.1 * np.degrees(arcs.angle[inner]).max()
        assert np.nanmax(arcs.tangent_defect) < 1e-6 and _plane_defects(arcs).max() < 1e-6


def test_boundary_arcs_of_a_saddle_grid_stay_short():
    """A grid on a hyperbolic paraboloid at 30 degrees to its principal directions (not
    an S-net: the spheres are least-squares fits): the boundary arcs are as short as the
    inner ones, where the chains of boundary planes met in an 84-degree arc before, and
    the planes' mismatch is left as a defect under a tenth of a degree."""
    x, y = np.meshgrid(np.linspace(-8, 8, 15), np.linspace(-5, 5, 11), indexing="ij")
    c, s = np.cos(0.5), np.sin(0.5)
    z = 0.04 * ((c * x - s * y) ** 2 - (s * x + c * y) ** 2)
    mesh = fabplan.QuadMesh.grid(np.stack([x, y, z], axis=-1))
    arcs = arc_structure(mesh)
    inner = np.all(mesh.star_of_vertex[arcs.edges] >= 0, axis=1)
    assert np.degrees(arcs.angle).max() <= 1.5 * np.degrees(arcs.angle[inner]).max()
    assert np.degrees(np.nanmax(arcs.tangent_defect)) < 0.1
    assert np.degrees(_plane_defects(arcs).max()) < 0.1   # the arcs' own best planes


@pytest.mark.parametrize("noise", [0.0, 1e-9])
def test_arcs_of_a_sphere_sampled_to_its_last_digits_stay_short(noise):
    """On a sphere every two neighbouring spheres are one: where they meet is decided by
    the last digits (before: arcs of up to 180 degrees between vertices 3 degrees apart).
    The arcs follow the parameter lines' circles on the sphere instead. (With noise of
    1e-7 of the radius the fitted spheres differ by more than `MIRROR_TOLERANCE`, and
    their circles are taken, long as they are: the angle limit reports them.)"""
    rng = np.random.default_rng(7)
    theta, phi = np.meshgrid(np.linspace(0.3, 1.0, 15), np.linspace(0, 0.7, 15), indexing="ij")
    points = 360 * np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                             np.cos(theta)], axis=-1)
    points *= (1 + noise * rng.standard_normal(theta.shape))[..., None]
    arcs = arc_structure(fabplan.QuadMesh.grid(points))
    assert np.degrees(arcs.angle).max() < 3.0   # the grid's own 2.9 degrees
    assert np.degrees(np.nanmax(arcs.tangent_defect)) < 0.001
