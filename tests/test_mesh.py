"""QuadMesh combinatorics: OBJ round trips, stars, polylines, boundary and validation.

The fixture meshes are small and built by hand, so that every count is known exactly:
a planar grid (also with the corners of each face listed from a different start), a
cylinder (closed in one direction), a torus (closed in both) and polar meshes whose centre
is an irregular vertex of valence 3 or 5.
"""

from __future__ import annotations

import numpy as np
import pytest

from fabplan.errors import InputError
from fabplan.io.obj import read_obj, write_obj
from fabplan.net.mesh import QuadMesh

# ---------------------------------------------------------------------------- builders

GRID_SHAPE = (6, 5)        # points along i (x) and j (y)
CYLINDER_SHAPE = (7, 4)    # points around (odd on purpose) and along the axis
TORUS_SHAPE = (6, 5)
POLAR_RINGS = 3            # quads along each side of a sector


def _grid_points(m: int, k: int) -> np.ndarray:
    u, v = np.meshgrid(np.arange(m, dtype=float), np.arange(k, dtype=float), indexing="ij")
    return np.stack([u, v, 0 * u], axis=-1)


def _periodic_quads(n: int, m: int, *, close_j: bool) -> np.ndarray:
    """Quads ``(i, j), (i+1, j), (i+1, j+1), (i, j+1)`` on an n x m index grid, i periodic."""
    i, j = np.meshgrid(np.arange(n), np.arange(m if close_j else m - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()

    def idx(a, b):
        return (a % n) * m + b % m

    return np.stack([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)], axis=1)


def make_grid() -> QuadMesh:
    return QuadMesh.grid(_grid_points(*GRID_SHAPE), name="grid")


def make_rotated_grid() -> QuadMesh:
    """The same grid with each face's corner list starting at a different corner."""
    grid = make_grid()
    shift = np.arange(len(grid.quads)) % 4
    faces = [np.roll(q, s) for q, s in zip(grid.quads, shift, strict=True)]
    return QuadMesh(grid.vertices, faces, name="rotated_grid")


def make_cylinder() -> QuadMesh:
    n, m = CYLINDER_SHAPE
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    phi = 2 * np.pi * i / n
    X = np.stack([np.cos(phi), np.sin(phi), 0.5 * j], axis=-1).reshape(-1, 3)
    return QuadMesh(X, _periodic_quads(n, m, close_j=False), name="cylinder")


def make_torus() -> QuadMesh:
    n, m = TORUS_SHAPE
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    u, v = 2 * np.pi * i / n, 2 * np.pi * j / m
    X = np.stack([(3 + np.cos(v)) * np.cos(u), (3 + np.cos(v)) * np.sin(u), np.sin(v)],
                 axis=-1).reshape(-1, 3)
    return QuadMesh(X, _periodic_quads(n, m, close_j=True), name="torus")


def make_polar(valence: int, rings: int = POLAR_RINGS) -> QuadMesh:
    """`valence` square sectors of rings x rings quads glued around vertex 0.

    Sector s spans the spokes s and s + 1; its point (a, b) sits at ``a d_s + b d_{s+1}``
    (unit spoke directions ``d``), lifted onto a paraboloid so that the mesh is not planar.
    Faces are counter-clockwise seen from +z.
    """
    ids: dict = {}
    points: list = []

    def vid(s: int, a: int, b: int) -> int:
        if a == 0 and b == 0:
            key = ("centre",)
        elif b == 0:
            key = ("spoke", s % valence, a)
        elif a == 0:
            key = ("spoke", (s + 1) % valence, b)
        else:
            key = ("sector", s, a, b)
        if key not in ids:
            t0, t1 = 2 * np.pi * s / valence, 2 * np.pi * (s + 1) / valence
            ids[key] = len(points)
            points.append(a * np.array([np.cos(t0), np.sin(t0), 0.0])
                          + b * np.array([np.cos(t1), np.sin(t1), 0.0]))
        return ids[key]

    faces = [[vid(s, a, b), vid(s, a + 1, b), vid(s, a + 1, b + 1), vid(s, a, b + 1)]
             for s in range(valence) for a in range(rings) for b in range(rings)]
    X = np.array(points)
    X[:, 2] = 0.05 * (X[:, 0] ** 2 + X[:, 1] ** 2)
    return QuadMesh(X, faces, name=f"polar{valence}")


@pytest.fixture(scope="module")
def grid() -> QuadMesh:
    return make_grid()


@pytest.fixture(scope="module")
def rotated_grid() -> QuadMesh:
    return make_rotated_grid()


@pytest.fixture(scope="module")
def cylinder() -> QuadMesh:
    return make_cylinder()


@pytest.fixture(scope="module")
def torus() -> QuadMesh:
    return make_torus()


@pytest.fixture(scope="module")
def polar3() -> QuadMesh:
    return make_polar(3)


@pytest.fixture(scope="module")
def polar5() -> QuadMesh:
    return make_polar(5)


_m, _k = GRID_SHAPE
_n, _h = CYLINDER_SHAPE
_tn, _tm = TORUS_SHAPE
_r = POLAR_RINGS


def _polar_counts(valence: int) -> dict:
    return dict(vertices=1 + valence * _r + valence * _r * _r, stars=valence * ((_r - 1) + (_r - 1) ** 2),
                edges=valence * (2 * _r * (_r + 1) - _r), boundary=valence * 2 * _r,
                polylines=valence * (1 + _r), closed=0, irregular=[0])


# Everything here is counted by hand from the construction above.
EXPECTED = {
    "grid": dict(vertices=_m * _k, stars=(_m - 2) * (_k - 2), edges=_m * (_k - 1) + _k * (_m - 1),
                 boundary=2 * (_m - 1) + 2 * (_k - 1), polylines=_m + _k, closed=0,
                 irregular=[]),
    "cylinder": dict(vertices=_n * _h, stars=_n * (_h - 2), edges=_n * _h + _n * (_h - 1),
                     boundary=2 * _n, polylines=_n + _h, closed=_h, irregular=[]),
    "torus": dict(vertices=_tn * _tm, stars=_tn * _tm, edges=2 * _tn * _tm, boundary=0,
                  polylines=_tn + _tm, closed=_tn + _tm, irregular=[]),
    "polar3": _polar_counts(3),
    "polar5": _polar_counts(5),
}
EXPECTED["rotated_grid"] = EXPECTED["grid"]

ALL_MESHES = ["grid", "rotated_grid", "cylinder", "torus", "polar3", "polar5"]
# meshes whose two families are globally consistent (no odd-valence singularity)
CONSISTENT = ["grid", "rotated_grid", "cylinder", "torus"]
# meshes that are graphs over the xy-plane with counter-clockwise faces seen from +z
PLAN_MESHES = ["grid", "rotated_grid", "polar3", "polar5"]


@pytest.fixture
def mesh(request) -> QuadMesh:
    return request.getfixturevalue(request.param)


def _faces_containing(mesh: QuadMesh) -> np.ndarray:
    """(f, n) bool incidence of faces and vertices."""
    inc = np.zeros((len(mesh.face_sizes), mesh.vertex_count), bool)
    inc[np.repeat(np.arange(len(mesh.face_sizes)), mesh.face_sizes), mesh.face_indices] = True
    return inc


def _polyline_edges(mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray]:
    """All edges walked by the polylines (sorted pairs) and the family of each."""
    pairs, fams = [], []
    for verts, fam, closed in zip(mesh.polylines.vertices, mesh.polylines.family,
                                  mesh.polylines.closed, strict=True):
        walk = np.r_[verts, verts[:1]] if closed else verts
        pairs.append(np.sort(np.stack([walk[:-1], walk[1:]], axis=1), axis=1))
        fams.append(np.full(len(walk) - 1, fam))
    return np.concatenate(pairs), np.concatenate(fams)


# ---------------------------------------------------------------------------- OBJ round trip

HAND_OBJ = """\
# a hand-written quad-dominant mesh: four quads, a triangle and a pentagon
mtllib scene.mtl
o patch
v 0 0 0
v 1 0 0
v 2 0 0
v 0 1 0.1
v 1 1 0.3333333333333333
v 2 1 -0.0
v 0 2 1e-300
v 1 2 2.5e-7
v 2 2 123456789.125
v 3 0.5 0
vt 0 0
vt 1 0
vn 0 0 1
g quads
s off
usemtl steel
f 1/1/1 2/2/1 5/2/1 4/1/1
f 2//1 3//1 6//1 5//1
f 4/1 5/2 8/2 7/1
f 5 6 9 8
f -5 -8 -1
v 1.25 2.75 0
v 0.5 3.25 0
v -0.25 2.75 0
f 7 8 -3 -2 -1
"""

HAND_FACES = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7], [5, 2, 9],
              [6, 7, 10, 11, 12]]


def _assert_same_mesh(vertices_a, faces_a, vertices_b, faces_b):
    assert vertices_a.dtype == vertices_b.dtype == np.float64
    assert vertices_a.shape == vertices_b.shape
    # bit-identical, including the sign of zero
    assert vertices_a.tobytes() == vertices_b.tobytes()
    assert [len(f) for f in faces_a] == [len(f) for f in faces_b]
    assert all(np.array_equal(f, g) for f, g in zip(faces_a, faces_b, strict=True))


def test_read_obj_handwritten_keeps_polygons_and_resolves_index_styles(tmp_path):
    path = tmp_path / "hand.obj"
    path.write_text(HAND_OBJ)
    vertices, faces = read_obj(path)
    assert vertices.shape == (13, 3)
    assert vertices[4, 2] == float("0.3333333333333333")
    assert vertices[6, 2] == 1e-300
    assert np.signbit(vertices[5, 2])
    assert [f.tolist() for f in faces] == HAND_FACES


def test_obj_write_read_round_trip_is_bit_identical(tmp_path):
    path = tmp_path / "hand.obj"
    path.write_text(HAND_OBJ)
    vertices, faces = read_obj(path)
    rng = np.random.default_rng(11)
    # awkward magnitudes: every digit of a double must survive the text format
    vertices = vertices * 10.0 ** rng.integers(-300, 300, size=vertices.shape)
    vertices[0] = [5e-324, -0.0, np.finfo(float).max]
    out = tmp_path / "out.obj"
    write_obj(out, vertices, faces, header="first line\nsecond line")
    again_v, again_f = read_obj(out)
    _assert_same_mesh(vertices, faces, again_v, again_f)
    # atomic writing leaves no temporary file behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hand.obj", "out.obj"]


def test_quadmesh_obj_round_trip_keeps_order_and_sizes(tmp_path):
    path = tmp_path / "hand.obj"
    path.write_text(HAND_OBJ)
    mesh = QuadMesh.from_obj(path)
    assert mesh.face_sizes.tolist() == [4, 4, 4, 4, 3, 5]
    assert mesh.quad_ids.tolist() == [0, 1, 2, 3]
    mesh.write_obj(tmp_path / "copy.obj", header="copy")
    again = QuadMesh.from_obj(tmp_path / "copy.obj")
    _assert_same_mesh(mesh.vertices, mesh.faces, again.vertices, again.faces)
    assert np.array_equal(again.edges, mesh.edges)


def test_read_obj_rejects_index_zero(tmp_path):
    path = tmp_path / "zero.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\nv 0 1 0\n")
    with pytest.raises(InputError, match="zero.obj"):
        read_obj(path)


def test_read_obj_accepts_utf8_byte_order_mark(tmp_path):
    path = tmp_path / "bom.obj"
    path.write_bytes("\ufeff# exported on Windows\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                     "f 1 2 3 4\n".encode("utf-8"))
    vertices, faces = read_obj(path)
    assert vertices.shape == (4, 3) and faces[0].tolist() == [0, 1, 2, 3]


_READER_CASES = {
    # read in bulk
    "plain": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 2 5 3\n",
    "objects and comments": "# cad\no part\ng side\ns off\nusemtl steel\nvt 0 0\nv 0 0 0\n"
                            "v 1 0 0\nv 1 1 0\nv 0 1 0\n\nf 1/1 2/1 3/1 4/1\n",
    "normals": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\n"
               "vn 0 0 1\nf 1//1 2//2 3//3 4//4\n",
    "extra columns": "v 0 0 0 0.5 0.5 0.5\nv 1 0 0 1 1 1\nv 1 1 0 1 1 1\nf 1 2 3\n",
    "windows lines": "v 0 0 0\r\nv 1 0 0\r\nv 1 1 0\r\nf 1 2 3\r\n",
    "fewer normals": "v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nf 1 2 3\n",
    # read a line at a time (the bulk reader declines them)
    "negative indices": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\n",
    "tabs and spaces": "v\t0 0 0\nv 1 0 0\nv 1 1 0\nf 1  2 3\n",
    # refused alike
    "a bad coordinate": "v 0 0 0\nv 1 0 x\nv 1 1 0\nf 1 2 3\n",
    "an infinite coordinate": "v 0 0 0\nv 1e999 0 0\nv 1 1 0\nf 1 2 3\n",
    "an index past the end": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 4\n",
    "a two-corner face": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\nf 1 2 3\n",
    "an unknown line": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nbevel 2\n",
    "a bad normal": "v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 z\nf 1 2 3\n",
}


@pytest.mark.parametrize("case", list(_READER_CASES))
def test_the_bulk_obj_reader_reads_as_the_line_reader_does(case, tmp_path, monkeypatch):
    """Most files are read in bulk (`_parse_plain`); what it reads must be what the
    line-by-line reader reads, to the bit, and what it declines must still be read or
    refused with the line named."""
    from fabplan.io import obj

    path = tmp_path / "case.obj"
    path.write_bytes(_READER_CASES[case].encode())
    text = path.read_text()

    def read():
        try:
            return obj.parse_obj(path)
        except InputError as exc:
            return str(exc)

    bulk = read()
    monkeypatch.setattr(obj, "_parse_plain", lambda text: None)
    by_line = read()
    if isinstance(by_line, str):
        assert bulk == by_line and str(path) in by_line
        return
    assert not isinstance(bulk, str)
    _assert_same_mesh(bulk[0], bulk[1], by_line[0], by_line[1])
    assert (bulk[2] is None) == (by_line[2] is None)
    if bulk[2] is not None:
        assert bulk[2].tobytes() == by_line[2].tobytes()
    # the first six cases are the bulk reader's own
    monkeypatch.undo()
    assert (obj._parse_plain(text) is not None) == (list(_READER_CASES).index(case) < 6)


def test_the_bulk_obj_reader_keeps_every_digit(tmp_path):
    """Coordinates of every magnitude, written by fabplan, come back to the bit through
    the bulk reader."""
    from fabplan.io import obj

    rng = np.random.default_rng(5)
    vertices = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-300, 300, size=(500, 3))
    vertices[0] = [5e-324, -0.0, np.finfo(float).max]
    faces = rng.integers(0, 500, size=(300, 4))
    write_obj(tmp_path / "n.obj", vertices, faces)
    text = (tmp_path / "n.obj").read_text()
    again, again_faces, _ = obj._parse_plain(text)
    assert again.tobytes() == vertices.tobytes()
    assert np.array_equal(np.asarray(again_faces), faces)


# ---------------------------------------------------------------------------- counts


@pytest.mark.parametrize("mesh", ALL_MESHES, indirect=True)
def test_counts_match_the_construction(mesh):
    want = EXPECTED[mesh.name]
    assert mesh.vertex_count == want["vertices"]
    assert len(mesh.stars) == want["stars"]
    assert len(mesh.edges) == want["edges"]
    assert len(mesh.boundary_edges) == want["boundary"]
    assert len(mesh.polylines) == want["polylines"]
    assert int(mesh.polylines.closed.sum()) == want["closed"]
    assert mesh.irregular_vertices.tolist() == want["irregular"]


@pytest.mark.parametrize("mesh", ALL_MESHES, indirect=True)
def test_edges_are_unique_sorted_and_match_euler_characteristic(mesh):
    e = mesh.edges
    assert np.all(e[:, 0] < e[:, 1])
    assert len(np.unique(e, axis=0)) == len(e)
    assert np.array_equal(e, e[np.lexsort((e[:, 1], e[:, 0]))])
    # V - E + F: a disc 1, a cylinder and a torus 0
    chi = mesh.vertex_count - len(e) + len(mesh.face_sizes)
    assert chi == {"cylinder": 0, "torus": 0}.get(mesh.name, 1)
    # valence is the number of edges at a vertex: the sum counts each edge twice
    assert mesh.valence.sum() == 2 * len(e)


def test_grid_valence_and_boundary(grid):
    m, k = GRID_SHAPE
    valence = grid.valence.reshape(m, k)
    assert valence[[0, 0, -1, -1], [0, -1, 0, -1]].tolist() == [2, 2, 2, 2]
    assert np.all(valence[1:-1, 1:-1] == 4)
    assert np.all(valence[0, 1:-1] == 3) and np.all(valence[1:-1, 0] == 3)
    boundary = grid.is_boundary_vertex.reshape(m, k)
    assert boundary.sum() == 2 * (m + k) - 4 and not boundary[1:-1, 1:-1].any()
    # boundary half-edges keep the faces' orientation: the loop encloses the area positively
    X = grid.vertices
    a, b = grid.boundary_edges.T
    signed_area = 0.5 * np.sum(X[a, 0] * X[b, 1] - X[b, 0] * X[a, 1])
    assert signed_area == pytest.approx((m - 1) * (k - 1), abs=1e-12)


def test_closed_meshes_have_no_boundary(torus, cylinder):
    assert not torus.is_boundary_vertex.any()
    # the cylinder's boundary is its two end circles
    n, m = CYLINDER_SHAPE
    assert np.flatnonzero(cylinder.is_boundary_vertex).tolist() == sorted(
        [i * m for i in range(n)] + [i * m + m - 1 for i in range(n)])
    assert np.all(cylinder.valence[cylinder.is_boundary_vertex] == 3)


@pytest.mark.parametrize("mesh", ["polar3", "polar5"], indirect=True)
def test_irregular_vertex_has_its_valence(mesh):
    valence = int(mesh.name[-1])
    assert mesh.valence[0] == valence
    assert not mesh.is_boundary_vertex[0]
    assert mesh.star_of_vertex[0] == -1


def test_closed_mesh_of_valence_three_is_all_irregular():
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    # outward-oriented faces of the unit cube (vertex 4x + 2y + z)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    mesh = QuadMesh(cube, faces, name="cube")
    assert mesh.irregular_vertices.tolist() == list(range(8))
    assert len(mesh.stars) == 0 and len(mesh.boundary_edges) == 0


def test_fan_triangulation_preserves_area_and_orientation(tmp_path):
    path = tmp_path / "hand.obj"
    path.write_text(HAND_OBJ)
    mesh = QuadMesh.from_obj(path)
    flat = mesh.with_vertices(mesh.vertices * [1, 1, 0])
    tri = flat.triangles()
    assert len(tri) == int(np.sum(flat.face_sizes - 2))
    X = flat.vertices
    cross = np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])
    assert np.all(cross[:, 2] > 0)  # every triangle keeps its face's counter-clockwise order
    shoelace = sum(0.5 * np.sum(X[f, 0] * X[np.roll(f, -1), 1] - X[np.roll(f, -1), 0] * X[f, 1])
                   for f in flat.faces)
    assert 0.5 * cross[:, 2].sum() == pytest.approx(shoelace, rel=1e-14)


def test_fan_triangulation_of_grid_has_grid_area(grid):
    m, k = GRID_SHAPE
    rng = np.random.default_rng(2)
    # a small in-plane jitter keeps every quad convex and the outline fixed
    X = grid.vertices.copy()
    inner = ~grid.is_boundary_vertex
    X[inner, :2] += rng.uniform(-0.2, 0.2, size=(inner.sum(), 2))
    tri = grid.triangles()
    assert len(tri) == 2 * len(grid.quads)
    cross = np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])
    assert np.all(cross[:, 2] > 0)
    assert 0.5 * cross[:, 2].sum() == pytest.approx((m - 1) * (k - 1), rel=1e-13)


# ---------------------------------------------------------------------------- stars


@pytest.mark.parametrize("mesh", ALL_MESHES, indirect=True)
def test_star_neighbours_are_the_ring_with_opposites_paired(mesh):
    S = mesh.stars
    inc = _faces_containing(mesh)
    # every star centre is a regular interior vertex, listed once, found by star_of_vertex
    assert len(np.unique(S[:, 0])) == len(S)
    assert np.all(mesh.valence[S[:, 0]] == 4) and not mesh.is_boundary_vertex[S[:, 0]].any()
    assert np.array_equal(mesh.star_of_vertex[S[:, 0]], np.arange(len(S)))
    assert np.sum(mesh.star_of_vertex >= 0) == len(S)
    # the four neighbours are exactly the edge neighbours of v
    indptr, nbrs = mesh.neighbours(S[:, 0])
    assert np.all(np.diff(indptr) == 4)
    assert np.array_equal(np.sort(nbrs.reshape(-1, 4), axis=1), np.sort(S[:, 1:], axis=1))

    def share_face(a, b):
        return (inc[:, S[:, 0]] & inc[:, S[:, a]] & inc[:, S[:, b]]).any(axis=0)

    for a, b in [(1, 2), (2, 3), (3, 4), (4, 1)]:
        assert share_face(a, b).all(), f"consecutive neighbours v{a}, v{b} share no face with v"
    for a, b in [(1, 3), (2, 4)]:
        assert not share_face(a, b).any(), f"opposite neighbours v{a}, v{b} share a face"


@pytest.mark.parametrize("mesh", PLAN_MESHES, indirect=True)
def test_stars_turn_counter_clockwise_like_the_faces(mesh):
    X, S = mesh.vertices, mesh.stars
    d = X[S[:, 1:]] - X[S[:, :1]]
    turns = np.cross(d, np.roll(d, -1, axis=1))[..., 2]  # v1 x v2, v2 x v3, v3 x v4, v4 x v1
    assert np.all(turns > 0)
    # and the faces themselves are counter-clockwise seen from +z
    q = X[mesh.quads]
    face_normal_z = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])[:, 2]
    assert np.all(face_normal_z > 0)


def test_cylinder_stars_turn_with_the_outward_faces(cylinder):
    X, S = cylinder.vertices, cylinder.stars
    d = X[S[:, 1:]] - X[S[:, :1]]
    radial = X[S[:, 0]] * [1, 1, 0]
    turns = np.einsum("sij,sj->si", np.cross(d, np.roll(d, -1, axis=1)), radial)
    assert np.all(turns > 0)


@pytest.mark.parametrize("mesh", ["grid", "rotated_grid"], indirect=True)
def test_family_zero_is_one_grid_direction(mesh):
    X, S = mesh.vertices, mesh.stars
    along1 = np.abs(X[S[:, 3]] - X[S[:, 1]])
    along2 = np.abs(X[S[:, 4]] - X[S[:, 2]])
    # v1 - v - v3 runs along the same grid axis in every star, v2 - v - v4 along the other
    axis = int(np.argmax(along1[0]))
    assert axis in (0, 1)
    assert np.all(along1[:, axis] == 2) and np.all(np.delete(along1, axis, axis=1) == 0)
    assert np.all(along2[:, 1 - axis] == 2) and np.all(np.delete(along2, 1 - axis, axis=1) == 0)


def test_cylinder_families_are_circles_and_rulings(cylinder):
    X, S = cylinder.vertices, cylinder.stars
    # one family joins v to neighbours on its circle, the other to neighbours on its ruling
    same_circle = (X[S[:, 1:], 2] == X[S[:, :1], 2])
    same_ruling = np.all(X[S[:, 1:], :2] == X[S[:, :1], :2], axis=2)
    assert np.all(same_circle ^ same_ruling)
    assert np.all(same_circle == same_circle[0]) and same_circle[0].tolist() in (
        [True, False, True, False], [False, True, False, True])


# ---------------------------------------------------------------------------- polylines


@pytest.mark.parametrize("mesh", ALL_MESHES, indirect=True)
def test_polylines_cover_every_edge_exactly_once(mesh):
    walked, _ = _polyline_edges(mesh)
    assert len(walked) == len(mesh.edges)
    assert np.array_equal(np.unique(walked, axis=0), mesh.edges)


@pytest.mark.parametrize("mesh", CONSISTENT, indirect=True)
def test_polyline_families_agree_with_star_labels(mesh):
    walked, family = _polyline_edges(mesh)
    n = mesh.vertex_count
    key = walked[:, 0] * n + walked[:, 1]
    order = np.argsort(key)

    def family_of(a, b):
        k = np.minimum(a, b) * n + np.maximum(a, b)
        return family[order[np.searchsorted(key[order], k)]]

    S = mesh.stars
    assert np.all(family_of(S[:, 0], S[:, 1]) == 0) and np.all(family_of(S[:, 0], S[:, 3]) == 0)
    assert np.all(family_of(S[:, 0], S[:, 2]) == 1) and np.all(family_of(S[:, 0], S[:, 4]) == 1)


@pytest.mark.parametrize("mesh", ALL_MESHES, indirect=True)
def test_polylines_go_straight_and_end_at_boundary_or_irregular_vertices(mesh):
    pl = mesh.polylines
    sov = mesh.star_of_vertex
    S = mesh.stars
    ends = set(mesh.irregular_vertices.tolist()) | set(np.flatnonzero(mesh.is_boundary_vertex))
    for verts, closed in zip(pl.vertices, pl.closed, strict=True):
        assert len(np.unique(verts)) == len(verts)
        if not closed:
            assert verts[0] in ends and verts[-1] in ends
        inner = verts if closed else verts[1:-1]
        assert not set(inner.tolist()) & set(mesh.irregular_vertices.tolist())
        walk = np.r_[verts[-1:], verts, verts[:1]] if closed else verts
        prev, mid, nxt = walk[:-2], walk[1:-1], walk[2:]
        star = sov[mid]
        regular = star >= 0
        # through a regular vertex a polyline continues to the opposite neighbour
        row = S[star[regular]]
        assert (row[:, 1:] == prev[regular, None]).any(axis=1).all()
        assert (row[:, 1:] == nxt[regular, None]).any(axis=1).all()
        pos_prev = np.argmax(row[:, 1:] == prev[regular, None], axis=1)
        pos_next = np.argmax(row[:, 1:] == nxt[regular, None], axis=1)
        assert np.all((pos_prev - pos_next) % 4 == 2)
        # elsewhere only along the boundary, through boundary vertices of valence 3
        assert np.all(mesh.is_boundary_vertex[mid[~regular]])
        assert np.all(mesh.valence[mid[~regular]] == 3)


def test_grid_polylines_by_family(grid):
    m, k = GRID_SHAPE
    pl = grid.polylines
    assert not pl.closed.any()
    lengths = [sorted(len(v) for v, f in zip(pl.vertices, pl.family, strict=True) if f == fam)
               for fam in (0, 1)]
    # one family: a polyline of m points per j; the other: one of k points per i
    assert lengths in ([[m] * k, [k] * m], [[k] * m, [m] * k])


def test_cylinder_polylines_are_circles_and_rulings(cylinder):
    n, m = CYLINDER_SHAPE
    pl = cylinder.polylines
    X = cylinder.vertices
    circles = [v for v, c in zip(pl.vertices, pl.closed, strict=True) if c]
    rulings = [v for v, c in zip(pl.vertices, pl.closed, strict=True) if not c]
    assert len(circles) == m and all(len(v) == n for v in circles)
    assert all(np.ptp(X[v, 2]) == 0 for v in circles)
    assert len(rulings) == n and all(len(v) == m for v in rulings)
    assert all(np.ptp(X[v, 0]) == 0 and np.ptp(X[v, 1]) == 0 for v in rulings)
    assert len(set(pl.family[pl.closed].tolist())) == 1
    assert set(pl.family[~pl.closed].tolist()) == {1 - pl.family[pl.closed][0]}


@pytest.mark.parametrize("mesh", ["polar3", "polar5"], indirect=True)
def test_spokes_end_at_the_irregular_vertex(mesh):
    valence = int(mesh.name[-1])
    pl = mesh.polylines
    at_centre = [v for v in pl.vertices if 0 in (v[0], v[-1])]
    assert len(at_centre) == valence
    assert all(len(v) == POLAR_RINGS + 1 for v in at_centre)
    # the spokes leave the centre towards all of its neighbours
    firsts = sorted(int(v[1] if v[0] == 0 else v[-2]) for v in at_centre)
    _, nbrs = mesh.neighbours(np.array([0]))
    assert firsts == sorted(nbrs.tolist())


# ---------------------------------------------------------------------------- bad meshes

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0],
                   [0, -1, 0], [1, -1, 0]], float)


def _build_and_inspect(vertices, faces):
    """Construct and touch the combinatorics (validation of the faces is lazy)."""
    mesh = QuadMesh(vertices, faces, name="bad.obj")
    return mesh.edges, mesh.stars, mesh.polylines


@pytest.mark.parametrize(
    "vertices, faces, pattern",
    [
        pytest.param(np.where(np.arange(24).reshape(8, 3) == 7, np.nan, SQUARE), [[0, 1, 2, 3]],
                     r"bad\.obj: vertex 2 has a non-finite coordinate", id="nan-vertex"),
        pytest.param(np.where(np.arange(24).reshape(8, 3) == 13, np.inf, SQUARE), [[0, 1, 2, 3]],
                     r"bad\.obj: vertex 4 has a non-finite coordinate", id="inf-vertex"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [1, 4, 5, 8]],
                     r"bad\.obj: face 1 refers to a vertex that does not exist", id="index-too-big"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [6, 7, 1, -1]],
                     r"bad\.obj: face 1 refers to a vertex that does not exist", id="negative-index"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [1, 4, 4, 5]],
                     r"bad\.obj: face 1 repeats a vertex", id="repeated-consecutive"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [1, 4]],
                     r"bad\.obj: face 1 has fewer than 3 vertices", id="two-gon"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [1, 4, 5, 2], [6, 7, 1, 0], [0, 1, 5, 3]],
                     r"bad\.obj: edge \(0, 1\) is used twice in the same direction by faces 0 and 3"
                     r".*non-manifold", id="three-faces-on-an-edge"),
        pytest.param(SQUARE, [[0, 1, 2, 3], [1, 2, 5, 4]],
                     r"bad\.obj: edge \(1, 2\) is used twice in the same direction by faces 0 and 1"
                     r".*inconsistently oriented", id="flipped-neighbour"),
    ],
)
def test_bad_mesh_raises_input_error_naming_the_element(vertices, faces, pattern):
    with pytest.raises(InputError, match=pattern):
        _build_and_inspect(vertices, faces)


def test_flipped_face_in_a_grid_is_reported(grid):
    faces = [f.copy() for f in grid.faces]
    faces[7] = faces[7][::-1]
    with pytest.raises(InputError, match=r"grid: edge .* faces (\d+ and 7|7 and \d+).*oriented"):
        QuadMesh(grid.vertices, faces, name="grid").stars  # noqa: B018


def test_bad_obj_file_names_file_and_line(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"nan\.obj:2: vertex 1 has a non-finite coordinate"):
        QuadMesh.from_obj(path)


def test_face_repeating_a_vertex_at_non_consecutive_corners_is_rejected():
    with pytest.raises(InputError, match="face 1 repeats a vertex"):
        _build_and_inspect(SQUARE, [[0, 1, 2, 3], [1, 4, 1, 5]])


def test_families_on_a_mesh_of_more_than_46341_faces():
    """The face parity's keys ``parent * (faces + 1) + face`` overflowed 32 bits (scipy's
    predecessors are int32): on a 230 x 230 grid whose faces start at random corners the
    two families got mixed up (half the stars had their first family across the grid)."""
    m = 230
    i, j = np.meshgrid(np.arange(m + 1), np.arange(m + 1), indexing="ij")
    X = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(float)
    v = (i[:-1, :-1] * (m + 1) + j[:-1, :-1]).ravel()
    faces = np.stack([v, v + m + 1, v + m + 2, v + 1], axis=1)
    shift = np.random.default_rng(3).integers(0, 4, len(faces))
    faces = np.take_along_axis(faces, (np.arange(4) + shift[:, None]) % 4, axis=1)
    mesh = QuadMesh(X, faces)
    stars = mesh.stars
    assert len(stars) == (m - 1) ** 2
    # the first family (v1, v3) of every star runs along one and the same grid direction
    along_i = np.abs(X[stars[:, 1], 0] - X[stars[:, 0], 0]) > 0.5
    assert along_i.all() or not along_i.any()


def test_with_vertices_measures_its_own_positions_regression():
    """A moved net shares its combinatorics, not its areas or edge lengths: a study's
    candidate solved from a measured start reported the start's panel areas."""
    u, v = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    mesh = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))
    assert np.allclose(mesh.face_areas, 1.0) and mesh.mean_edge_length == pytest.approx(1.0)
    moved = mesh.with_vertices(2 * mesh.vertices)
    assert np.allclose(moved.face_areas, 4.0)
    assert moved.mean_edge_length == pytest.approx(2.0)
    assert moved.edges is mesh.edges                       # the topology is shared
