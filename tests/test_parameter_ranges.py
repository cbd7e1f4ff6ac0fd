"""Every numeric option of every command, and every numeric parameter of every built-in
surface, fuzzed with hostile numbers against its range (`fabplan.io.parameters`).

The options are found in the argparse parsers and the surface parameters in the
catalogue's signatures, so that a new one is fuzzed without anyone listing it; one without
a range in the table fails `test_every_numeric_option_has_a_range`. Each case runs
`fabplan.cli.main` in-process and must return an int (no exception escapes). A value
outside the range must be refused at parse time: exit 2, one ``fabplan: error:`` line
naming the option (or the surface and the key), no warning, nothing written and the
inputs unchanged. A value inside the range runs the command on a tiny net and must end in
exit 0, 2 or 3, a refusal in one line.
"""

from __future__ import annotations

import argparse
import inspect
import warnings
from pathlib import Path

import numpy as np
import pytest

from fabplan.cli import InRange, build_parser, main
from fabplan.design.parametric import FILE_PARAMETERS, SURFACES, surface_from_spec
from fabplan.errors import InputError
from fabplan.io.parameters import SURFACE_PARAMETERS, Parameter
from fabplan.net.mesh import QuadMesh

HOSTILE = ["nan", "inf", "-inf", "1e300", "-1e300", "0", "-1", "1e-300", "1e400",
           "18446744073709551616", "abc", ""]

# the smallest valid run of each command (NET: a 6 x 5 grid net; OUT: a new path); the
# fuzzed option is added as --option=VALUE, in place of its value here
BASE = {
    "measure": ["{net}", "-o", "{out}/m.json"],
    "optimize": ["{net}", "--net", "snet", "-o", "{out}/o.obj", "-q"],
    "molds": ["{net}", "--tolerance-mm", "1", "-o", "{out}", "--no-3d", "-q"],
    "layout": ["hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2", "-o", "{out}/l.obj"],
    "strips": ["{net}", "--height", "40", "--thickness", "4", "--no-previews", "--workers", "1",
               "-o", "{out}", "-q"],
    "mill": ["{net}", "--tool", "face:D=10", "--no-simulation", "-o", "{out}", "-q"],
    "arcs": ["{net}", "-o", "{out}/a.3dm", "-q"],
    "study": ["canopy", "-o", "{out}", "-q"],
    # every hostile value is out of the port's range: the server never starts
    "edit": ["{net}", "--net", "snet", "--no-open", "-o", "{out}/e.obj", "-q"],
}


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _numeric_actions(command: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options of a command that take a number: checked ones, and any added with a
    plain ``type=float`` or ``type=int``."""
    return [a for a in command._actions if a.option_strings and
            (isinstance(a, InRange) or a.type in (int, float))]


COMMANDS = _commands()
OPTIONS = [(name, action.option_strings[-1]) for name, command in COMMANDS.items()
           for action in _numeric_actions(command)]
CASES = [(name, option, value) for name, option in OPTIONS for value in HOSTILE]

SURFACE_KEYS = [(surface, key) for surface in SURFACES
                for key, default in inspect.signature(SURFACES[surface]).parameters.items()
                if key not in FILE_PARAMETERS and isinstance(default.default, (int, float, tuple))]
SURFACE_CASES = [(surface, key, value) for surface, key in SURFACE_KEYS for value in HOSTILE]


def _parameter(command: str, option: str) -> Parameter:
    action = next(a for a in COMMANDS[command]._actions if option in a.option_strings)
    assert isinstance(action, InRange), f"fabplan {command} {option} has no range"
    return action.parameter


def _outside(parameter: Parameter, value: str) -> bool:
    try:
        parameter.check(value)
    except InputError:
        return True
    return False


def _listing(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


@pytest.fixture(scope="module")
def net(tmp_path_factory) -> Path:
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    path = tmp_path_factory.mktemp("net") / "grid.obj"
    QuadMesh.grid(np.stack([u, v, 0.05 * u * v], axis=-1)).write_obj(path)
    return path


def _run(argv: list[str], capsys) -> tuple[int, str, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(argv)
    _, err = capsys.readouterr()
    return code, err, [str(w.message) for w in caught]


def _argv(command: str, option: str, value: str, net: Path, out: Path) -> list[str]:
    base = [a.format(net=net, out=out) for a in BASE[command]]
    if option in base:
        at = base.index(option)
        del base[at:at + 2]
    return [command, *base, f"{option}={value}"]


def test_every_numeric_option_has_a_range():
    """A numeric option added with a plain type=float or type=int has no range."""
    plain = [f"{name} {option}" for name, option in OPTIONS
             if not isinstance(next(a for a in COMMANDS[name]._actions
                                    if option in a.option_strings), InRange)]
    assert not plain, f"numeric options without a range in fabplan.io.parameters: {plain}"
    assert set(BASE) >= {name for name, _ in OPTIONS}, "a command without a BASE run"
    assert len(OPTIONS) >= 30


def test_every_numeric_surface_parameter_has_a_range():
    missing = [f"{s}:{k}" for s, k in SURFACE_KEYS if k not in SURFACE_PARAMETERS.get(s, {})]
    assert not missing, f"surface parameters without a range in fabplan.io.parameters: {missing}"


@pytest.mark.parametrize("command, option, value", CASES)
def test_a_hostile_number_is_refused_in_one_line(command, option, value, net, tmp_path, capsys):
    out = tmp_path / "out"
    before = _listing(net.parent)
    code, err, caught = _run(_argv(command, option, value, net, out), capsys)
    assert isinstance(code, int) and not isinstance(code, bool)
    assert not caught, caught
    assert "Traceback" not in err
    assert _listing(net.parent) == before                 # the input untouched
    if _outside(_parameter(command, option), value):
        assert code == 2, err
        assert err.startswith(f"fabplan: error: {option} ") and err.count("\n") == 1, err
        assert "must be" in err, err
        assert not out.exists()                           # nothing written
    else:
        # in range: the command runs on the tiny net and ends as any run does
        assert code in (0, 2, 3), err
        assert code != 2 or (err.startswith("fabplan: error: ") and err.count("\n") == 1), err


@pytest.mark.parametrize("surface, key, value", SURFACE_CASES)
def test_a_hostile_surface_parameter_is_refused_in_one_line(surface, key, value, tmp_path,
                                                            capsys):
    text = f"{value}..10" if key in ("u_deg", "v_deg") else value
    spec = f"{surface}:{key}={text}"
    if surface in ("height-field", "bspline"):
        grid = tmp_path / "grid.txt"
        spec += f",{'heights' if surface == 'height-field' else 'control_points'}={grid}"
        rows = [f"{i} {j} {0.1 * i * j}" for i in range(4) for j in range(4)]
        grid.write_text("\n".join(
            rows if surface == "bspline" else
            [" ".join(str(0.1 * i * j) for j in range(4)) for i in range(4)]) + "\n")
    parameter = SURFACE_PARAMETERS[surface][key]
    if _outside(parameter, value):
        out = tmp_path / "out"
        code, err, caught = _run(["layout", spec, "--net", "snet", "--panel-size", "1",
                                  "-o", str(out / "l.obj")], capsys)
        assert code == 2 and err.count("\n") == 1, err
        assert err.startswith(f"fabplan: error: {surface}: {key} "), err
        assert not caught and not out.exists()
    else:
        # in range: the surface is made (or refused in one message) without a warning
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                design = surface_from_spec(spec).triangulate(8)
            except InputError:
                return
        assert np.isfinite(design.vertices).all()


def test_the_known_cases_name_the_parameter_and_its_range(net, tmp_path, capsys):
    out = tmp_path / "out"
    cases = [
        (["layout", "hyperbolic-paraboloid:width=1e300", "--net", "snet", "--panel-size", "1",
          "-o", str(out / "x.obj")],
         "hyperbolic-paraboloid: width 1e300: must be at most 1e+07 model units"),
        (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "1e300",
          "-o", str(out / "x.obj")], "--panel-size 1e300: must be at most 1e+07 model units"),
        (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "1e-300",
          "-o", str(out / "x.obj")], "--panel-size 1e-300: must be at least 1e-06 model units"),
        (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "100",
          "-o", str(out / "x.obj")], "--panel-size 100: must be at most the extent of"),
        (["optimize", str(net), "--net", "snet", "--handle", "0:1e300,0,0", "-o",
          str(out / "o.obj")], "--handle 0:1e+300,0,0: the target lies 1e+300 from the net"),
        (["optimize", str(net), "--net", "snet", "--handle", f"{2**64}:0,0,0", "-o",
          str(out / "o.obj")], f"--handle: vertex {2**64} does not exist"),
        (["optimize", str(net), "--net", "snet", "--handle=-1:0,0,0", "-o",
          str(out / "o.obj")], "--handle: vertex -1 does not exist"),
        (["optimize", str(net), "--net", "snet", "--handle", "30:0,0,0", "-o",
          str(out / "o.obj")], "--handle: vertex 30 does not exist (the mesh has 30 vertices"),
        (["strips", str(net), "--height", "40", "--thickness", "4", "--extension", "1e300",
          "-o", str(out)], "--extension 1e300: must be at most 20000 mm"),
        (["strips", str(net), "--height", "40", "--thickness", "4", "--splice-length", "1e300",
          "-o", str(out)], "--splice-length 1e300: must be at most 20000 mm"),
    ]
    for argv, fragment in cases:
        code, err, caught = _run(argv, capsys)
        assert code == 2 and err.count("\n") == 1 and fragment in err, (argv, err)
        assert not caught and not out.exists()


def test_a_fix_file_with_a_vertex_id_of_2_to_the_64_is_refused(net, tmp_path, capsys):
    ids = tmp_path / "ids.txt"
    ids.write_text(f"0 1 {2**64}\n")
    code, err, _ = _run(["optimize", str(net), "--net", "snet", "--fix", str(ids),
                         "-o", str(tmp_path / "o.obj")], capsys)
    assert code == 2 and f"ids.txt: vertex {2**64} does not exist" in err, err


@pytest.mark.parametrize("shape", ["# shape a b", "# shape 4", "# shape -4 -4", "# shape 0 16"])
def test_control_points_with_a_bad_shape_line_are_refused(tmp_path, capsys, shape):
    (tmp_path / "cp.txt").write_text(shape + "\n" + "".join(
        f"{i} {j} 0\n" for i in range(4) for j in range(4)))
    code, err, _ = _run(["layout", f"bspline:control_points={tmp_path / 'cp.txt'}", "--net",
                         "snet", "--panel-size", "0.2", "-o", str(tmp_path / "o" / "l.obj")], capsys)
    assert code == 2 and "control points must be m*k rows" in err, err
