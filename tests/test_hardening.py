"""Bad input and hostile paths, every command: refused in one line, nothing written.

Regression tests of issue 16: device files replaced by outputs, study candidate names
leaving the output folder, a folder or FIFO given as input reported as missing, meshes
with 1e300 coordinates, coincident or duplicate vertices, triangles or non-manifold
edges accepted or ending in a traceback, binary STL failing on a missing package.
The tests make their own FIFOs and sockets; they never touch the system's devices.
"""

from __future__ import annotations

import os
import shutil
import socket
import warnings
from pathlib import Path

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.io.obj import write_obj
from fabplan.net.mesh import QuadMesh


def listing(folder: Path) -> dict:
    """Every path under `folder` (hidden ones included) with the bytes of the files."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() and not p.is_fifo()
                                        else p.stat().st_mode)
            for p in sorted(folder.rglob("*"))}


def refused(argv: list, capsys, folder: Path, *fragments: str) -> str:
    """Run `argv`; assert exit 2, one stderr line with `fragments`, `folder` unchanged."""
    before = listing(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("error")      # no numpy warning may reach the user
        code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, err
    assert out == ""
    assert listing(folder) == before
    return err


def grid_points(nu: int = 6, nv: int = 5) -> np.ndarray:
    u, v = np.meshgrid(np.arange(float(nu)), np.arange(float(nv)), indexing="ij")
    return np.stack([u, v, 0.05 * u * v], axis=-1)


@pytest.fixture
def work(tmp_path) -> Path:
    """A folder with a valid net, a valid STL design and a FIFO and a socket."""
    grid = QuadMesh.grid(grid_points())
    grid.write_obj(tmp_path / "grid.obj")
    sockets = []
    for name in ("fifo", "fifo.obj"):
        os.mkfifo(tmp_path / name)
    for name in ("sock", "sock.obj"):
        sockets.append(socket.socket(socket.AF_UNIX))
        sockets[-1].bind(str(tmp_path / name))
    yield tmp_path
    for sock in sockets:
        sock.close()


def _study_text(name: str = "mine") -> str:
    return f"""
[design]
surface = "hyperbolic-paraboloid"
[panels]
size = 2.0
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
[[candidates]]
net = "isogonal"
angle = 80
name = "{name}"
"""


COMMANDS = {
    "measure": ["measure", "{net}", "-o", "{out}"],
    "optimize": ["optimize", "{net}", "--net", "snet", "-o", "{out}"],
    "molds": ["molds", "{net}", "--tolerance-mm", "2", "-o", "{out}"],
    "strips": ["strips", "{net}", "--height", "40", "--thickness", "4", "-o", "{out}"],
    "layout": ["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
               "-o", "{out}"],
    "study": ["study", "{study}", "-o", "{out}"],
    "templates": ["templates", "canopy", "-o", "{out}"],
}


def _argv(command: str, folder: Path, out: str, net: str = "grid.obj") -> list:
    (folder / "s.toml").write_text(_study_text(), encoding="utf-8")
    return [a.format(net=folder / net, out=folder / out, study=folder / "s.toml")
            for a in COMMANDS[command]]


# ---------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("special", ["fifo", "sock"])
@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_fifo_or_socket_as_output_is_refused_and_kept(work, capsys, command, special):
    """`measure good.obj -o /dev/null` replaced the device by a regular file."""
    kind = {"fifo": "a FIFO", "sock": "a socket"}[special]
    if command in ("optimize", "layout"):
        special += ".obj"
    err = refused(_argv(command, work, special), capsys, work, kind)
    assert str(work / special) in err
    assert (work / special).is_fifo() if "fifo" in special else (work / special).is_socket()


@pytest.mark.parametrize("command", ["measure", "templates"])
def test_a_character_device_as_output_is_refused(work, capsys, command, monkeypatch):
    """A character device (tested on a stand-in: the device check is faked for one path,
    so that no system device is ever touched)."""
    import stat

    from fabplan.io import output

    target = work / "dev"
    target.write_bytes(b"device stand-in")
    real_stat = os.stat

    def fake_stat(path, *args, **kwargs):
        result = real_stat(path, *args, **kwargs)
        if Path(path) == target:
            return os.stat_result((stat.S_IFCHR | 0o666,) + tuple(result)[1:])
        return result

    monkeypatch.setattr(output.os, "stat", fake_stat)
    refused(_argv(command, work, "dev"), capsys, work, "a character device")


@pytest.mark.parametrize("name", ["../../../escaped", "/tmp/absolute", "a/b", "..", ".hidden",
                                  "with space", "-dash", "x" * 65, "semi;colon"])
def test_a_study_candidate_name_must_be_a_safe_folder_name(tmp_path, capsys, monkeypatch, name):
    """A candidate named ../../../escaped wrote its files outside -o with exit 0."""
    from fabplan.study import run

    def no_work(*args, **kwargs):
        raise AssertionError("the study ran before its names were checked")

    monkeypatch.setattr(run, "run_study", no_work)
    root = tmp_path / "root"
    (root / "a" / "b").mkdir(parents=True)
    study = root / "a" / "b" / "s.toml"
    study.write_text(_study_text(name.replace("\\", "\\\\")), encoding="utf-8")
    refused(["study", study, "-o", root / "a" / "b" / "out"], capsys, tmp_path,
            f"{study}: candidates[0].name is {name!r}", "not a safe folder name")


def test_study_paths_are_checked_inside_the_output_folder(tmp_path):
    from fabplan.errors import InputError
    from fabplan.io.output import path_inside

    (tmp_path / "out" / "candidates").mkdir(parents=True)
    os.symlink(tmp_path, tmp_path / "out" / "candidates" / "link")
    assert path_inside(tmp_path / "out", "candidates", "ok") == \
        Path(os.path.realpath(tmp_path)) / "out" / "candidates" / "ok"
    for parts in (("candidates", "..", "..", "x"), ("/etc",), ("candidates", "link", "x"), ()):
        with pytest.raises(InputError, match="leaves the output folder"):
            path_inside(tmp_path / "out", *parts)


@pytest.mark.parametrize("command", ["molds", "strips", "layout", "measure"])
def test_a_refused_run_leaves_no_folder(work, capsys, command):
    """Refused STLs and option errors left empty output folders behind."""
    argv = _argv(command, work, "new/deeper/out" + (".obj" if command == "layout" else ""),
                 net="missing.obj")
    if command == "layout":
        (work / "cut.stl").write_bytes(b"\0" * 90)
        argv[1] = str(work / "cut.stl")
    refused(argv, capsys, work)
    assert not (work / "new").exists()


# ---------------------------------------------------------------------------- inputs
def _bad_nets(folder: Path) -> dict:
    """name -> (file, fragment of the message naming the first offending element)."""
    X = grid_points().reshape(-1, 3)
    grid = QuadMesh.grid(grid_points())
    faces = grid.faces
    nets = {}

    def net(name, vertices, faces_=faces):
        write_obj(folder / f"{name}.obj", vertices, faces_)
        return folder / f"{name}.obj"

    nets["coincident"] = (net("coincident", np.ones_like(X)), "all 30 points coincide")
    huge = X.copy()
    huge[7] *= 1e300
    nets["huge"] = (net("huge", huge), "vertex 7 lies 2e+300 from the origin")
    dup = X.copy()
    dup[8] = dup[7]
    nets["duplicate"] = (net("duplicate", dup), "vertices 7 and 8 coincide")
    tris = [f for q in faces for f in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])]
    nets["triangles"] = (net("triangles", X, tris), "face 0 is a triangle and only 0 of 40")
    nets["non-manifold"] = (net("non-manifold", X, [*faces, faces[0][::-1]]),
                            "non-manifold")
    (folder / "folder.obj").mkdir()
    nets["folder"] = (folder / "folder.obj", "is a folder, not a quad mesh")
    os.mkfifo(folder / "pipe.obj")
    nets["fifo"] = (folder / "pipe.obj", "is a FIFO, not a quad mesh")
    (folder / "empty.obj").write_bytes(b"")
    nets["empty"] = (folder / "empty.obj", "empty file")
    (folder / "binary.obj").write_bytes(bytes(range(256)))
    nets["binary"] = (folder / "binary.obj", "not a text OBJ file (binary content at byte 128)")
    (folder / "index.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                      "f 1 2 3 99999999999999999999999\n")
    nets["index"] = (folder / "index.obj", "index.obj:5: face 0 refers to vertex")
    return nets


BAD_NETS = ["coincident", "huge", "duplicate", "triangles", "non-manifold", "folder", "fifo",
            "empty", "binary", "index"]


@pytest.mark.parametrize("command", ["measure", "optimize", "molds", "strips"])
@pytest.mark.parametrize("bad", BAD_NETS)
def test_a_bad_net_is_refused_alike_by_every_command(work, capsys, command, bad):
    """One validation path: the same one-line message, naming the file and the element."""
    if command == "molds" and bad == "triangles":
        pytest.skip("molds takes polygon panels of any kind")
    path, fragment = _bad_nets(work)[bad]
    argv = _argv(command, work, "out" + (".obj" if command == "optimize" else ""), net=path.name)
    err = refused(argv, capsys, work, fragment)
    assert str(path) in err


def _stl_bytes(triangles: np.ndarray) -> bytes:
    record = np.zeros(len(triangles), dtype=[("n", "<f4", (3,)), ("c", "<f4", (3, 3)),
                                             ("a", "<u2")])
    record["c"] = triangles
    return b"\xffbinary header, not UTF-8".ljust(80, b"\0") + \
        len(triangles).to_bytes(4, "little") + record.tobytes()


def _saddle_triangles() -> np.ndarray:
    X = grid_points(9, 9)
    q = QuadMesh.grid(X)
    V = q.vertices
    return np.array([[V[f[0]], V[f[1]], V[f[2]]] for f in q.faces] +
                    [[V[f[0]], V[f[2]], V[f[3]]] for f in q.faces])


def test_a_binary_stl_with_a_non_utf8_header_is_read(tmp_path):
    """trimesh decoded such headers through charset_normalizer, which is not installed."""
    from fabplan.io.triangles import read_triangles

    T = _saddle_triangles()
    path = tmp_path / "design.stl"
    path.write_bytes(_stl_bytes(T))
    vertices, triangles = read_triangles(path)
    assert triangles.shape == (len(T), 3)
    np.testing.assert_allclose(vertices[triangles], T.astype(np.float32))


@pytest.mark.parametrize("content, fragment", [
    (lambda d: d[: len(d) // 2], "announces 128 triangles (6484 bytes) but the file has 3242"),
    (lambda d: d[:50], "a binary STL has an 84-byte header, this file has 50 bytes"),
    (lambda d: b"solid x\n\xff\xfe garbage", "not a text STL file (binary content at byte 8)"),
    (lambda d: os.urandom(37) + b"\x00" * 300, "not a valid binary STL"),
    (lambda d: b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
               b"vertex 0 1 nan\nendloop\nendfacet\nendsolid x\n",
     "vertex 2 has a non-finite coordinate (0, 1, nan)"),
])
def test_a_broken_stl_is_named_not_a_missing_package(tmp_path, capsys, content, fragment):
    path = tmp_path / "design.stl"
    path.write_bytes(content(_stl_bytes(_saddle_triangles())))
    err = refused(["layout", path, "--net", "snet", "--panel-size", "1", "-o",
                   tmp_path / "out" / "l.obj"], capsys, tmp_path, fragment)
    assert "ModuleNotFoundError" not in err and str(path) in err


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_design_or_study_that_is_not_a_file_is_named_as_such(tmp_path, capsys, kind):
    target = tmp_path / "thing.stl"
    target.mkdir() if kind == "folder" else os.mkfifo(target)
    what = {"folder": "is a folder", "fifo": "is a FIFO"}[kind]
    refused(["layout", target, "--net", "snet", "--panel-size", "1", "-o", tmp_path / "l.obj"],
            capsys, tmp_path, f"{target}: {what}, not a surface file")
    study = tmp_path / "s.toml"
    study.mkdir() if kind == "folder" else os.mkfifo(study)
    refused(["study", study, "-o", tmp_path / "out"], capsys, tmp_path,
            f"{study}: {what}, not a study file")


def test_a_valid_net_is_measured_without_a_warning(work, capsys):
    shutil.copyfile(fabplan.data_path("wein99.obj"), work / "wein99.obj")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["measure", str(work / "wein99.obj"), "-o", str(work / "w.json")]) == 0
        assert main(["measure", str(work / "grid.obj"), "-o", str(work / "g.json")]) == 0
    assert capsys.readouterr().err == ""
