"""The `fabplan` command: results that match the API, and bad input refused cleanly.

Most tests call `fabplan.cli.main(argv)` in-process; one runs the installed console script.
A refused command must exit 2 with one line on stderr, ``fabplan: error: ...``, naming the
problem, write nothing, and leave its input bytes untouched.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import noisy

import fabplan
from fabplan.cli import main
from fabplan.io.obj import read_obj, write_obj
from fabplan.net.mesh import QuadMesh
from fabplan.solve.constraints.angle import ConstantAngle
from fabplan.solve.net_types import NETS

BASE_NETS = ["snet", "isogonal", "orthogonal", "const-radius", "cmc", "linear-weingarten"]


def _snapshot(folder: Path) -> dict:
    """Every file under `folder` (hidden temporaries included) with its bytes."""
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _assert_refused(code: int, capsys, before: dict, folder: Path, *fragments: str) -> str:
    """Exit 2, one `fabplan: error:` line naming the problem, nothing written or changed."""
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.endswith("\n")
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in err
    assert out == ""
    assert _snapshot(folder) == before
    return err


@pytest.fixture
def cmc_copy(tmp_path) -> Path:
    path = tmp_path / "cmc1.obj"
    shutil.copyfile(fabplan.data_path("cmc1.obj"), path)
    return path


# ---------------------------------------------------------------------------- nets


def test_nets_lists_every_type_with_its_summary(capsys):
    assert main(["nets"]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = out.splitlines()
    assert len(lines) == len(NETS)
    listed = dict(line.split(None, 1) for line in lines)
    assert set(BASE_NETS) <= set(listed)
    for name, summary in listed.items():
        assert summary == NETS[name].summary and len(summary) > 20


# ---------------------------------------------------------------------------- measure


def test_measure_writes_the_api_record(tmp_path, capsys):
    net = tmp_path / "wein99.obj"
    shutil.copyfile(fabplan.data_path("wein99.obj"), net)
    original = net.read_bytes()
    assert main(["measure", str(net)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    written = tmp_path / "wein99.measure.json"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["wein99.measure.json", "wein99.obj"]
    record = json.loads(written.read_text())
    assert record.pop("file") == str(net)
    assert record.pop("units") == "m"       # none given, none recorded: metres
    # JSON keeps every digit of a float: the record is the API's, number for number
    expected = json.loads(json.dumps(fabplan.measure_net(QuadMesh.from_obj(net))))
    assert record == expected
    assert record["regular_stars"] == 1472
    assert re.search(r"Meusnier radius: 20\.1\d* \.\. 20\.1\d*", out)
    assert out.rstrip().endswith(f"wrote {written}")
    assert net.read_bytes() == original


def test_measure_output_option(tmp_path, capsys, cmc_copy):
    target = tmp_path / "reports" / "cmc.json"
    assert main(["measure", str(cmc_copy), "-o", str(target)]) == 0
    record = json.loads(target.read_text())
    assert record["vertices"] == 272 and record["face_sizes"] == {"4": 240}
    assert record["intersection_angle_deg"]["min"] > 89.99
    assert not (tmp_path / "cmc1.measure.json").exists()


def test_measure_refuses_to_overwrite_its_input(tmp_path, capsys, cmc_copy):
    before = _snapshot(tmp_path)
    code = main(["measure", str(cmc_copy), "-o", str(cmc_copy)])
    _assert_refused(code, capsys, before, tmp_path, "cmc1.obj")


def test_measure_of_a_planar_net_warns_nothing(tmp_path, capsys):
    u, v = np.meshgrid(np.arange(5.0), np.arange(5.0), indexing="ij")
    path = tmp_path / "plane.obj"
    QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1)).write_obj(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["measure", str(path), "-o", str(tmp_path / "plane.json")]) == 0
    record = json.loads((tmp_path / "plane.json").read_text())
    assert record["regular_stars"] == 9
    assert record["normal_curvature"]["max"] == record["normal_curvature"]["min"] == 0
    assert record["meusnier_radius"]["count"] == 0  # infinite radii are left out
    # the one star whose neighbours are star centres: the shape operator's zero curvature
    curvature = record["principal_curvature_1"]
    assert curvature["count"] == 1 and abs(curvature["max"]) < 1e-12
    assert capsys.readouterr().err == ""
    assert [str(w.message) for w in caught] == []


# ---------------------------------------------------------------------------- optimize
PROGRESS_LINE = re.compile(r"^(\S.* \.\.\.|\S.*: done in .*|  \.\.\. .*)$")



def test_optimize_noisy_cmc_net(tmp_path, capsys, cmc1):
    start = noisy(cmc1, 0.01, seed=3)
    source = tmp_path / "noisy.obj"
    start.write_obj(source)
    original = source.read_bytes()
    out_obj = tmp_path / "out.obj"
    assert main(["optimize", str(source), "--net", "cmc", "-o", str(out_obj)]) == 0
    out, err = capsys.readouterr()
    # off a terminal: a line per stage (fabplan.report.progress), no warning; only the note
    # of how far the net moved with nothing holding it to a design (43 mm here)
    said = [line for line in err.splitlines() if not PROGRESS_LINE.match(line)]
    assert len(said) <= 1 and all(line.startswith("fabplan: note: the net moved up to ")
                                  for line in said)
    out_json = tmp_path / "out.json"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["noisy.obj", "out.json", "out.obj"]
    assert source.read_bytes() == original

    vertices, faces = read_obj(out_obj)
    assert [f.tolist() for f in faces] == [f.tolist() for f in start.faces]
    assert vertices.shape == start.vertices.shape
    moved = np.linalg.norm(vertices - start.vertices, axis=1)
    assert 0 < moved.mean() <= 0.02 * start.mean_edge_length

    record = json.loads(out_json.read_text())
    assert record["net"] == "cmc" and record["status"] == "converged"
    props = record["properties"]
    assert props["sphere_residual_relative"]["max"] <= 1e-6
    assert abs(props["intersection_angle_deg"]["max"] - 90) <= 0.01
    assert abs(props["intersection_angle_deg"]["min"] - 90) <= 0.01
    radius = props["meusnier_radius"]
    assert (radius["max"] - radius["min"]) / radius["median"] <= 1e-4
    assert record["parameters"]["angle_deg"] == pytest.approx(90)
    assert record["parameters"]["radius"] == pytest.approx(radius["median"], rel=1e-4)
    # the evidence describes the OBJ that was written
    remeasured = fabplan.measure_net(QuadMesh.from_obj(out_obj))
    assert props["sphere_residual_relative"] == remeasured["sphere_residual_relative"]
    assert props["meusnier_radius"] == remeasured["meusnier_radius"]

    history = record["history"]
    assert isinstance(history, list) and len(history) >= 2
    assert record["iterations"] == sum(1 for h in history if h["step"] > 0)
    for entry in history:
        assert {"sphere", "angle", "radius"} <= set(entry["residuals"])
        assert all(np.isfinite(v) and v >= 0 for v in entry["residuals"].values())
    assert history[-1]["hard_residual"] <= 1e-10 < history[0]["hard_residual"]
    assert f"cmc: converged after {record['iterations']} iterations" in out
    assert out.rstrip().endswith(f"wrote {out_obj} and {out_json}")


# ---------------------------------------------------------------------------- bad input


def _write_strip(path: Path) -> None:
    """One row of four quads: no interior vertex at all."""
    X = np.array([[i, j, 0] for j in range(2) for i in range(5)], float)
    write_obj(path, X, [[i, i + 1, i + 6, i + 5] for i in range(4)])


def _write_triangles(path: Path) -> None:
    u, v = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij")
    grid = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))
    q = grid.quads
    write_obj(path, grid.vertices, np.r_[q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


INPUT_FILES = {
    "garbage.obj": lambda p: p.write_bytes(bytes(range(256)) * 8),
    "prose.obj": lambda p: p.write_text("Dear reader,\nthis file describes a roof in words.\n"),
    "nan.obj": lambda p: p.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n"),
    "triangles.obj": _write_triangles,
    "strip.obj": _write_strip,
}


UNUSABLE = {
    "missing.obj": ["missing.obj: no such file"],
    "garbage.obj": ["garbage.obj: not a text OBJ file"],
    "prose.obj": ["prose.obj:1: not an OBJ line", "Dear reader"],
    "nan.obj": ["nan.obj:2: vertex 1 has a non-finite coordinate"],
    "triangles.obj": ["triangles.obj: face 0 is a triangle", "a net is a quad mesh"],
    "strip.obj": ["strip.obj: no regular vertex star"],
}
UNREADABLE = ["missing.obj", "garbage.obj", "prose.obj", "nan.obj"]


@pytest.mark.parametrize("name", UNUSABLE)
def test_optimize_refuses_unusable_input(tmp_path, capsys, name):
    path = tmp_path / name
    if name in INPUT_FILES:
        INPUT_FILES[name](path)
    before = _snapshot(tmp_path)
    code = main(["optimize", str(path), "--net", "snet", "-o", str(tmp_path / "out.obj")])
    _assert_refused(code, capsys, before, tmp_path, *UNUSABLE[name])


@pytest.mark.parametrize("name", UNREADABLE)
def test_measure_refuses_unreadable_input(tmp_path, capsys, name):
    path = tmp_path / name
    if name in INPUT_FILES:
        INPUT_FILES[name](path)
    before = _snapshot(tmp_path)
    _assert_refused(main(["measure", str(path)]), capsys, before, tmp_path, *UNUSABLE[name])


def test_measure_of_a_net_without_stars_says_so(tmp_path, capsys):
    path = tmp_path / "strip.obj"
    _write_strip(path)
    assert main(["measure", str(path), "-o", str(tmp_path / "strip.json")]) == 0
    record = json.loads((tmp_path / "strip.json").read_text())
    assert record["regular_stars"] == 0 and "sphere_residual" not in record
    assert record["boundary_vertices"] == 10 and record["face_planarity_relative"]["max"] == 0


BAD_OPTIONS = [
    (["--net", "isogonal", "--angle", "0"], ["--angle 0: must be at least 1 degrees (range [1, 179])"]),
    (["--net", "isogonal", "--angle", "180"], ["--angle 180: must be at most 179 degrees"]),
    (["--net", "isogonal", "--angle", "-5"], ["--angle -5: must be at least 1 degrees"]),
    (["--net", "isogonal", "--angle", "nan"], ["--angle nan: must be a finite number between 1 and 179"]),
    (["--net", "cmc", "--radius", "0"], ["--radius 0: must be at least 1e-06 model units"]),
    (["--net", "cmc", "--radius", "-1"], ["--radius -1: must be at least 1e-06 model units"]),
    (["--net", "cmc", "--radius", "inf"], ["--radius inf: must be a finite number between 1e-06 and 1e+10"]),
    (["--net", "snet", "--angle", "60"], ["net type 'snet' takes no --angle"]),
    (["--net", "orthogonal", "--angle", "60"], ["net type 'orthogonal' takes no --angle"]),
    (["--net", "isogonal", "--radius", "5"], ["net type 'isogonal' takes no --radius"]),
    (["--net", "snet", "--max-iter", "0"], ["--max-iter 0: must be at least 1 (range [1, 100000])"]),
    (["--net", "snet", "--fix", "{tmp}/nofix.txt"], ["nofix.txt: no such file"]),
    (["--net", "snet", "--fix", "{tmp}/ids.txt"], ["ids.txt: vertex 272 does not exist", "272 vertices"]),
    (["--net", "snet", "--fix", "{tmp}/words.txt"], ["words.txt: vertex ids must be integers"]),
    (["--net", "snet", "--reference", "{tmp}/noref.obj"], ["noref.obj: no such file"]),
]


@pytest.mark.parametrize("options, fragments",
                         [pytest.param(o, f, id=" ".join(o).replace("{tmp}/", "")) for o, f in BAD_OPTIONS])
def test_bad_option_is_refused(tmp_path, capsys, cmc_copy, options, fragments):
    (tmp_path / "ids.txt").write_text("0, 5\n17 272\n")
    (tmp_path / "words.txt").write_text("first and last row\n")
    before = _snapshot(tmp_path)
    argv = ["optimize", str(cmc_copy), *[o.format(tmp=tmp_path) for o in options],
            "-o", str(tmp_path / "out.obj"), "-q"]
    _assert_refused(main(argv), capsys, before, tmp_path, *fragments)


@pytest.mark.parametrize("output", ["{input}", "{tmp}/./cmc1.obj", "{tmp}/sub/../cmc1.obj"])
def test_output_onto_the_input_is_refused(tmp_path, capsys, cmc_copy, output):
    (tmp_path / "sub").mkdir()
    before = _snapshot(tmp_path)
    target = output.format(input=cmc_copy, tmp=tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "-o", target])
    _assert_refused(code, capsys, before, tmp_path, "refusing to overwrite the input")


@pytest.mark.parametrize("output", ["out.json", "out", "out.obj.txt"])
def test_output_must_be_obj(tmp_path, capsys, cmc_copy, output):
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "-o", str(tmp_path / output)])
    _assert_refused(code, capsys, before, tmp_path, f"{output}: the output must be an .obj file")


def test_output_onto_the_reference_is_refused(tmp_path, capsys, cmc_copy):
    reference = tmp_path / "ref.obj"
    shutil.copyfile(cmc_copy, reference)
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "--reference", str(reference),
                 "-o", str(reference), "-q"])
    _assert_refused(code, capsys, before, tmp_path, "ref.obj")


def test_binary_fix_file_is_refused(tmp_path, capsys, cmc_copy):
    fix = tmp_path / "ids.bin"
    fix.write_bytes(bytes(range(256)))
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "--fix", str(fix),
                 "-o", str(tmp_path / "out.obj"), "-q"])
    _assert_refused(code, capsys, before, tmp_path, "ids.bin")


def test_output_below_a_file_is_refused(tmp_path, capsys, cmc_copy):
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "-o",
                 str(tmp_path / "cmc1.obj" / "out.obj"), "-q"])
    _assert_refused(code, capsys, before, tmp_path, "out.obj")


def test_failed_json_write_leaves_no_obj(tmp_path, capsys, cmc_copy):
    (tmp_path / "out.json").mkdir()
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "snet", "-o", str(tmp_path / "out.obj"), "-q"])
    _assert_refused(code, capsys, before, tmp_path, "out.json")


# ---------------------------------------------------------------------------- solver failure


def test_absurd_radius_is_refused_cleanly(tmp_path, capsys, cmc_copy):
    """No sphere through a star can be smaller than half its edges: refused before solving."""
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "cmc", "--radius", "1e-3",
                 "-o", str(tmp_path / "out.obj"), "-q"])
    err = _assert_refused(code, capsys, before, tmp_path, "smaller than half the edges")
    assert re.search(r"\(\d+\.\d+\)", err)


def test_non_finite_residuals_diverge_cleanly(tmp_path, capsys, cmc_copy, monkeypatch):
    def poisoned(self, state):
        r, J = original(self, state)
        return np.full_like(r, np.nan), J

    original = ConstantAngle.evaluate
    monkeypatch.setattr(ConstantAngle, "evaluate", poisoned)
    before = _snapshot(tmp_path)
    code = main(["optimize", str(cmc_copy), "--net", "orthogonal", "-o", str(tmp_path / "out.obj"),
                 "-q"])
    _assert_refused(code, capsys, before, tmp_path, "diverged", "non-finite residuals")


# ---------------------------------------------------------------------------- console script


def test_console_script_refuses_bad_input(tmp_path):
    script = shutil.which("fabplan", path=str(Path(sys.executable).parent)) or shutil.which("fabplan")
    assert script, "the fabplan console script is not installed"
    source = tmp_path / "nan.obj"
    INPUT_FILES["nan.obj"](source)
    before = _snapshot(tmp_path)
    proc = subprocess.run([script, "optimize", str(source), "--net", "cmc", "-o", "out.obj"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr == f"fabplan: error: {source}:2: vertex 1 has a non-finite coordinate\n"
    assert _snapshot(tmp_path) == before


def test_a_folder_named_like_a_built_in_surface_does_not_shadow_it(tmp_path, monkeypatch):
    """Regression: with a folder ``paraboloid`` (a project's output, say) in the working
    folder, ``fabplan layout paraboloid`` read the folder as a mesh file and failed."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paraboloid").mkdir()
    assert main(["layout", "paraboloid", "--net", "snet", "--panel-size", "1.5",
                 "--triangles", "2000", "-o", "net.obj", "-q"]) == 0
    assert (tmp_path / "net.obj").is_file()
