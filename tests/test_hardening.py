"""Bad input and hostile paths, every command: refused in one line, nothing written.

Regression tests: device files replaced by outputs, study candidate names leaving the
output folder, a folder or FIFO given as input reported as missing, meshes
with 1e300 coordinates, coincident or duplicate vertices, triangles or non-manifold
edges accepted or ending in a traceback, binary STL failing on a missing package; and
the cases `test_property_fuzz` found. The tests make their own FIFOs and sockets; they
never read the system's devices (``/proc/self/mem`` is only looked at).
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
from fabplan.errors import InputError
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


PLY = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 {y} 0\n3 0 1 2\n")


@pytest.mark.parametrize("name, text, fragment", [
    ("big.ply", PLY.format(y="1e39"), "big.ply: vertex 2 has a non-finite coordinate (0, inf, 0)"),
    ("short.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1\n", "short.off: cannot read as OFF"),
    ("nan.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 nan\n3 0 1 2\n",
     "nan.off: vertex 2 has a non-finite coordinate (0, 1, nan)"),
])
def test_a_broken_ply_or_off_is_refused_without_a_warning(tmp_path, capsys, name, text, fragment):
    """A PLY number beyond float range printed numpy's overflow RuntimeWarning."""
    (tmp_path / name).write_text(text)
    refused(["layout", tmp_path / name, "--net", "snet", "--panel-size", "1", "-o",
             tmp_path / "l.obj"], capsys, tmp_path, fragment)


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


# ---------------------------------------------------------------------------- resources
def test_a_layout_that_would_need_5_gb_is_refused_in_under_2_s(tmp_path, capsys, monkeypatch):
    """Panel size 0.05 on a 30 m design ran 46 s into a MemoryError at 5.3 GB. Here the
    machine is made to have 4 GB available: the layout is refused up front."""
    import time

    from fabplan.io import resources

    monkeypatch.setattr(resources, "available_memory", lambda: 4 * 10**9)
    started = time.perf_counter()
    err = refused(["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "0.05",
                   "-o", tmp_path / "out" / "l.obj"], capsys, tmp_path,
                  "about 164,704 panels (about 6.6 GB of memory), more than the limit of 50,000",
                  "use a larger --panel-size (about 0.13 gives 25,000 panels)", "--max-panels")
    assert time.perf_counter() - started < 2.0, err


def test_a_design_in_millimetres_read_with_a_panel_in_metres_is_refused(tmp_path, capsys):
    path = tmp_path / "wall.stl"
    path.write_bytes(_stl_bytes(1000.0 * _saddle_triangles()))
    refused(["layout", path, "--net", "snet", "--panel-size", "1", "-o", tmp_path / "l.obj"],
            capsys, tmp_path, "wall.stl: a layout at panel size 1 of a surface of area",
            "if it is in millimetres, give the panel size in millimetres too")


@pytest.mark.parametrize("argv, fragment", [
    (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
      "--max-panels", "50"], "about 103 panels (about 4 MB of memory), more than the limit of 50"),
    (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
      "--max-panels", "0"], "--max-panels 0: must be at least 1 (range [1, 1000000000])"),
    (["strips", "{net}", "--height", "40", "--thickness", "4", "--max-panels", "10"],
     "strips of a net of 20 faces: about 20 panels"),
    (["strips", "{net}", "--height", "40", "--thickness", "4", "--spacing", "1e9"],
     "--spacing 1e9: must be at most 20000 mm (range [0, 20000])"),
    (["strips", "{net}", "--height", "40", "--thickness", "4", "--spacing", "1500"],
     "--spacing 1500 mm is wider than the sheet inside its margins (1230 mm)"),
    (["strips", "{net}", "--height", "40", "--thickness", "4", "--sheet", "1e9x1e9"],
     "no sheet is larger than 20000 mm"),
    (["strips", "{net}", "--height", "2000", "--thickness", "4"],
     "--height 2000 mm does not fit on the 1250 mm side of the sheet"),
    (["strips", "{net}", "--height", "40", "--thickness", "4", "--tolerance", "1e12"],
     "--tolerance 1e12: must be at most 10 mm (range [0.001, 10])"),
])
def test_runs_beyond_the_limits_are_refused_before_the_work(work, capsys, argv, fragment):
    argv = [a.format(net=work / "grid.obj") for a in argv]
    refused([*argv, "-o", work / "out" / ("l.obj" if argv[0] == "layout" else "")], capsys,
            work, fragment)


def test_a_study_beyond_the_panel_limit_is_refused_before_any_layout(tmp_path, capsys,
                                                                      monkeypatch):
    from fabplan.layout import surface_layout

    def no_layout(*args, **kwargs):
        raise AssertionError("a layout started")

    monkeypatch.setattr(surface_layout, "layout_surface", no_layout)
    study = tmp_path / "s.toml"
    study.write_text(_study_text().replace("size = 2.0", "size = 0.02"), encoding="utf-8")
    refused(["study", study, "-q", "-o", tmp_path / "out", "--max-panels", "100000"], capsys,
            tmp_path, "layouts of panel size 0.02 m on a design of area 411.8 m^2: about "
            "1,029,405 panels (about 50 GB of memory), more than the limit of 100,000",
            "give a larger panels.size")


def test_a_panel_size_meant_in_metres_on_a_millimetre_design_is_told_so(tmp_path, capsys):
    """``size = 3`` on a design in millimetres asks for 3 mm panels: the refusal says what
    to give for 3 m panels."""
    import numpy as np

    u, v = np.meshgrid(np.linspace(0.0, 20_000.0, 21), np.linspace(0.0, 12_000.0, 13))
    X = np.column_stack([u.ravel(), v.ravel(), 300.0 * np.sin(u.ravel() / 3_000.0)])
    i = (np.arange(12)[:, None] * 21 + np.arange(20)[None, :]).ravel()
    lines = [f"v {x:.3f} {y:.3f} {z:.3f}" for x, y, z in X]
    lines += [f"f {a + 1} {a + 2} {a + 23}\nf {a + 1} {a + 23} {a + 22}" for a in i]
    (tmp_path / "wall.obj").write_text("\n".join(lines) + "\n", encoding="utf-8")
    study = tmp_path / "s.toml"
    study.write_text(_study_text().replace('surface = "hyperbolic-paraboloid"',
                                           'file = "wall.obj"\nunits = "mm"')
                     .replace("size = 2.0", "size = 3"), encoding="utf-8")
    refused(["study", study, "-q", "-o", tmp_path / "out"], capsys, tmp_path,
            "panels.size is in the design's units (mm): for panels of 3 m give 3000")


# ---------------------------------------------------------------------------- units
def test_molds_in_millimetres_on_a_model_in_metres_is_refused(tmp_path, capsys):
    """`molds --units mm` on a net in metres reported 1 mold for 100 planar panels."""
    net = tmp_path / "wein99.obj"
    shutil.copyfile(fabplan.data_path("wein99.obj"), net)
    refused(["molds", net, "--tolerance-mm", "1", "--units", "mm", "-o", tmp_path / "m"],
            capsys, tmp_path, "wein99.obj: panels of 0.62 mm (median edge 0.6198 mm) cannot be",
            "is the model in metres? Give --units m")


@pytest.mark.parametrize("value", ["1e12", "1e-5", "inf"])
def test_a_mold_tolerance_outside_its_range_is_refused(work, capsys, value):
    fragment = {"1e12": "--tolerance-mm 1e12: must be at most 1000 mm (range [0.01, 1000])",
                "1e-5": "--tolerance-mm 1e-5: must be at least 0.01 mm (range [0.01, 1000])",
                "inf": "--tolerance-mm inf: must be a finite number between 0.01 and 1000 mm"}[value]
    refused(["molds", work / "grid.obj", "--tolerance-mm", value, "-o", work / "m"], capsys, work,
            fragment)


def test_a_plausible_but_odd_panel_size_warns_and_names_the_other_unit():
    from fabplan.net.validate import net_units_warning

    net = QuadMesh.grid(grid_points() * 5.0, name="small.obj")   # 5 mm panels
    assert net_units_warning(net, "mm") == (
        "small.obj: panels of 5.02 mm (median edge 5.025 mm) read in millimetres: implausible "
        "for a building; if the file is in metres, give --units m")
    assert net_units_warning(net, "m") is None
    big = QuadMesh.grid(grid_points() * 30.0, name="big.obj")   # 30 m panels
    assert "if the file is in centimetres, give --units cm" in net_units_warning(big, "m")
    with pytest.raises(InputError, match=r"implausible for a building; .* \(--strict-units\)"):
        net_units_warning(big, "m", strict=True)
    tiny = QuadMesh.grid(grid_points() * 0.002, name="tiny.obj")   # a 10 x 8 mm model in metres
    assert "a design 10 mm across read in metres" in net_units_warning(tiny, "m")


@pytest.mark.slow
def test_a_warning_on_the_panel_size_reaches_the_user_of_molds(work, capsys):
    net = QuadMesh.grid(grid_points() * 5.0)      # 5 mm panels in millimetres
    net.write_obj(work / "small.obj")
    code = main(["molds", str(work / "small.obj"), "--tolerance-mm", "1", "--units", "mm",
                 "-o", str(work / "m")])
    err = capsys.readouterr().err
    assert code in (0, 3)
    # after the run, on its own line: a refusal on the way would have come alone
    assert f"\nfabplan: warning: {work / 'small.obj'}: panels of 5.02 mm" in err
    assert err.rstrip().splitlines()[-1].startswith("fabplan: warning:")


@pytest.mark.parametrize("size, units, fragment", [
    ("0.0005", "m", "panels.size 0.0005 m is 0.5 mm, not a panel of a building: is the design "
                    "in mm?"),
    ("0.5", "mm", 'panels.size 0.5 mm is 0.5 mm, not a panel of a building: is the design in '
                  'm? Set design.units = "m"'),
    ("300", "m", "panels.size 300 m is 300000 mm, not a panel of a building: is the design in "
                 "mm?"),
])
def test_a_study_panel_size_implausible_in_its_units_is_refused(tmp_path, capsys, size, units,
                                                                fragment):
    study = tmp_path / "s.toml"
    study.write_text(_study_text().replace("size = 2.0", f"size = {size}").replace(
        'surface = "hyperbolic-paraboloid"', f'surface = "hyperbolic-paraboloid"\nunits = "{units}"'),
        encoding="utf-8")
    refused(["study", study, "-o", tmp_path / "out"], capsys, tmp_path, fragment)


def test_a_study_of_a_millimetre_design_read_in_metres_names_the_units(tmp_path, capsys):
    """A design 57 km across with panels of 2 m: refused for its panel count, and told that
    the design is likely in millimetres, not only to give larger panels."""
    study = tmp_path / "s.toml"
    study.write_text(_study_text().replace(
        'surface = "hyperbolic-paraboloid"',
        'surface = "hyperbolic-paraboloid"\n'
        'parameters = { width = 20000, depth = 20000, rise = 2500 }'), encoding="utf-8")
    code = main(["study", str(study), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    last = err.rstrip().splitlines()[-1]
    assert code == 2 and last.startswith("fabplan: error: "), err
    assert "more than the limit of" in last and "the design is 56,789 m across" in last
    assert 'is it in mm? Set design.units = "mm"' in last
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


@pytest.mark.parametrize("option, what", [
    (["--fix"], "a file of vertex ids"), (["--handle"], "a file of handles"),
    (["--reference"], "a surface file"), (["--family"], "a file of polylines")])
@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_folder_or_fifo_given_to_a_file_option_is_named(work, capsys, option, what, kind):
    """`--fix FIFO` said "no such file" (and reading a FIFO would wait forever)."""
    target = work / "thing"
    target.mkdir() if kind == "folder" else os.mkfifo(target)
    if option == ["--family"]:
        argv = _argv("layout", work, "l.obj")
    else:
        argv = _argv("optimize", work, "o.obj")
    argv[-2:-2] = [*option, str(target)]
    refused(argv, capsys, work, f"{target}: is a {kind.replace('fifo', 'FIFO')}, not {what}")


# ---------------------------------------------------------------------------- found by fuzzing
def _one_line(argv: list, capsys) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("fabplan: error: ") and err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("depth", [400, 1100])
def test_a_study_nested_too_deep_is_refused_in_one_line(depth, tmp_path, capsys):
    """A study with inline tables 400 deep ended in a RecursionError traceback."""
    study = tmp_path / "s.toml"
    study.write_text(_study_text() + "[deep]\nx = " + "{a = " * depth + "1" + "}" * depth
                     + "\n", encoding="utf-8")
    err = _one_line(["study", study, "-o", tmp_path / "out"], capsys)
    assert f"{study}: not a valid TOML study file: its arrays or tables nest too deep" in err
    assert not (tmp_path / "out").exists()


def test_a_study_file_the_size_of_a_data_set_is_refused_before_it_is_parsed(tmp_path, capsys,
                                                                          monkeypatch):
    """20,000 candidates (800 KB) took the TOML parser 0.2 s before the candidate count
    refused them; a file of megabytes took it minutes. A file over the size limit is refused
    in one line, unread; a study text over it given to the API too."""
    import fabplan.study.spec as spec
    from fabplan.errors import InputError

    study = tmp_path / "s.toml"
    text = _study_text() + '[[candidates]]\nnet = "isogonal"\nangle = 80\n' * 8000
    assert len(text.encode()) > spec.MAX_STUDY_BYTES
    study.write_text(text, encoding="utf-8")
    parsed, read = [], []
    monkeypatch.setattr(spec.tomllib, "loads", lambda t: parsed.append(t) or {})
    monkeypatch.setattr(spec, "check_text", lambda *a: read.append(a) or "")
    err = _one_line(["study", study, "-o", tmp_path / "out"], capsys)
    assert f"{study}: a study file of {len(text.encode()):,} bytes: at most 262,144 (" in err
    assert not parsed and not read and not (tmp_path / "out").exists()
    # the API's text: non-ASCII counted in bytes, as the file would hold them
    wide = _study_text() + "# " + "é" * (spec.MAX_STUDY_BYTES // 2) + "\n"
    with pytest.raises(InputError, match=r"study: a study file of 262,\d{3} bytes: at most 262,144"):
        spec.parse_study(wide)
    assert not parsed
    # a lone surrogate (text from Python, not a file) is counted, not an error
    with pytest.raises(InputError, match="a study file of"):
        spec.parse_study(wide + "# \ud800\n")
    # a study just under the limit is read
    monkeypatch.undo()
    small = _study_text() + "# " + "x" * (spec.MAX_STUDY_BYTES - len(_study_text()) - 10) + "\n"
    assert spec.parse_study(small).candidates


@pytest.mark.parametrize("kind, words", [
    ("proc", "/proc/self/mem: empty file (not a text file of numbers for the surface "
             "parameter profile)"),
    ("folder", "is a folder, not a text file of numbers for the surface parameter profile"),
    ("fifo", "is a FIFO, not a text file of numbers for the surface parameter profile"),
    ("comments", "not a text file of numbers for the surface parameter profile"),
    ("binary", "not a text profile file (binary content at byte 0)"),
])
def test_a_surface_file_that_is_no_file_of_numbers_is_named(kind, words, tmp_path, capsys):
    """profile=/proc/self/mem said only 'Input/output error'; a folder or FIFO was 'no
    such file'; a file of comments only printed a numpy warning first."""
    path = {"proc": Path("/proc/self/mem")}.get(kind, tmp_path / "profile.txt")
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "comments":
        path.write_text("# r z\n")
    elif kind == "binary":
        path.write_bytes(b"\xff\x00\x01")
    err = _one_line(["layout", f"revolution:profile={path}", "--net", "snet", "--panel-size",
                     "1", "-o", tmp_path / "o" / "l.obj"], capsys)
    assert words in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("spec", ["torus:nan=", "tower-facade:=", "bspline:=x"])
def test_an_unknown_surface_key_is_named_before_its_value(spec, tmp_path, capsys):
    """'torus:nan=' said "nan must be a number, got ''" instead of naming the parameters."""
    name, _, key = spec.partition(":")
    err = _one_line(["layout", spec, "--net", "snet", "--panel-size", "1",
                     "-o", tmp_path / "l.obj"], capsys)
    assert f"surface '{name}' has no parameter {key.split('=')[0]!r}; its parameters: " in err


def test_mill_with_no_strip_between_passes_warns_nothing(tmp_path, capsys):
    """The simulation of a net whose passes leave no strip to measure printed numpy's
    'All-NaN axis encountered' before the report."""
    net = tmp_path / "grid.obj"
    QuadMesh.grid(grid_points()).write_obj(net)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main(["mill", str(net), "--tool", "face:D=10", "-q", "-o", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert code in (0, 3) and "Warning" not in err, err
    assert (tmp_path / "m" / "mill.json").is_file()


@pytest.mark.parametrize("argv", [
    ["optimize", "{net}", "--net", "snet", "--handle=\x00", "-o", "{out}/o.obj"],
    ["measure", "{folder}/g\x00.obj", "-o", "{out}/m.json"],
])
def test_a_nul_character_in_an_argument_is_refused(argv, work, capsys):
    """--handle=\\x00 ended in 'ValueError: embedded null byte' (no shell passes one, a
    Python caller can)."""
    argv = [a.format(net=work / "grid.obj", out=work / "out", folder=work) for a in argv]
    err = _one_line(argv, capsys)
    assert "an argument cannot hold a NUL character" in err and "\\x00" in err
    assert not (work / "out").exists()


def test_a_line_break_in_a_name_stays_on_one_line(tmp_path, capsys):
    """A surface spec with a line break, too long to be a file name, printed 'File name
    too long' over two lines."""
    spec = "hyperbolic-paraboloid:width=\n," + "0" * 300 + "=1"
    err = _one_line(["layout", spec, "--net", "snet", "--panel-size", "1",
                     "-o", tmp_path / "l.obj"], capsys)
    assert "has no parameter" in err
    err = _one_line(["measure", tmp_path / "a\nb.obj", "-o", tmp_path / "m.json"], capsys)
    assert "a\\nb.obj: no such file" in err


@pytest.mark.parametrize("key, value", [("file", "a\\u0000b.stl"),
                                        ("file", "a" * 300 + ".stl"),
                                        ("parameters.profile", "a\\u0000b")])
def test_a_study_file_name_no_file_can_have_is_refused_naming_the_key(key, value, tmp_path,
                                                                      capsys):
    """design.file = "a\\u0000b.stl" ended in 'ValueError: embedded null byte'."""
    design = (f'file = "{value}"' if key == "file" else
              f'surface = "revolution"\nparameters = {{ profile = "{value}" }}')
    study = tmp_path / "s.toml"
    study.write_text(_study_text().replace('surface = "hyperbolic-paraboloid"', design),
                     encoding="utf-8")
    err = _one_line(["study", study, "-o", tmp_path / "out"], capsys)
    assert f"{study}: design.{key} names " in err and "which cannot name a file" in err


def test_molds_on_a_design_the_net_lies_far_off_is_refused(tmp_path, capsys):
    """molds --panel-surface design on a design the net lies far off (its panels' samples
    pulled onto one boundary line) ended in 'LinAlgError: Singular matrix'; its panels
    would be cut from a surface they are not on."""
    net = tmp_path / "grid.obj"
    QuadMesh.grid(grid_points()).write_obj(net)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main(["molds", str(net), "--tolerance-mm", "1", "--panel-surface", "design",
                     "--design", "torus:major=224", "--triangles", "2000", "--no-3d", "-q",
                     "-o", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert code == 2 and "--panel-surface design: the net lies up to" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "m").exists()


@pytest.mark.parametrize("option", ["--units=--", "--tool=--", "--reference=--", "-o--"])
def test_a_double_dash_as_an_option_value_is_refused(option, work, capsys):
    """mill --tool=-- ended in "AttributeError: 'list' object has no attribute
    'partition'": argparse drops the '--' and hands the command an empty list."""
    argv = ["mill", work / "grid.obj", "--tool", "face:D=10", "-o", work / "out", option]
    err = _one_line(argv, capsys)
    assert f"{option}: '--' is no value of an option" in err
    assert not (work / "out").exists()


@pytest.mark.parametrize("net", [".", "/", ".."])
def test_a_folder_named_without_a_file_name_is_refused_as_a_net(net, tmp_path, capsys):
    """arcs . ended in "ValueError: PosixPath('.') has an empty name" while the records
    beside the net were looked for."""
    err = _one_line(["arcs", net, "-o", tmp_path / "a.dxf"], capsys)
    assert f"{net}: is a folder, not a quad mesh" in err
    assert not (tmp_path / "a.dxf").exists()
