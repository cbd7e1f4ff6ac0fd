"""Property-based fuzzing of every command, option, surface parameter and study key, with
Hypothesis strategies drawn from the schemas.

Nothing here lists a parameter. The options are found in the argparse parsers (a checked
number draws from its `Parameter` range in `fabplan.io.parameters.OPTIONS`, a choice from
its choices, a flag is set or not, any other text option draws hostile text and file
names); the surface parameters come from `SURFACE_PARAMETERS` and the catalogue's
signatures (`fabplan.design.parametric.SURFACES`); the study keys are those
`fabplan.study.spec` asks for while it reads the bundled templates. A new option, surface
parameter or study key is fuzzed the day it is added.

Each value is valid, on a boundary (the bound itself, the next float past it) or hostile
(NaN, infinities, 1e300, 1e-300, negatives, 2^64, unicode digits, empty and very long
text). Study files get hostile values under their real keys, unknown keys, deep nesting,
huge arrays, unicode names and names of files that are no study input (the study file
itself, a folder, a FIFO, a link loop, binary junk). Every example runs `fabplan.cli.main`
in-process and must

- return 0, 2 or 3 (a run stopped where its solve or study would start counts as accepted),
- on exit 2 print exactly one ``fabplan: error:`` line, and no traceback or warning ever,
- refuse (exit 2) any number outside its range,
- write nothing when it refuses or before its work starts (the folder listing unchanged),
- leave every input byte for byte as it was (hashed before and after).

The machine is made to have 800 MB available (`fabplan.io.resources.available_memory`),
so that the resource guards, not the fuzzing, decide how large a valid run may be; the
solver, the layout's solve and the study's candidates are stopped where they would start,
and molds, strips and mill where they would write their reports (the checks and plans
before them are what is fuzzed; `test_parameter_ranges`, `test_study` and the command
tests run the rest).

Tiers: the quick tier draws 460 examples in every test run, CI's included (about 14 s of
one core on this project's 2-core machine). The slow tier draws 5,400 more (70 s on its two
cores, and minutes more to shrink a failure): marked ``slow`` and run only with ``FABPLAN_FUZZ_SLOW=1``,
which the README's whole-suite command sets, so that a plain ``python -m pytest -q`` while
working is not a third longer for examples of the same kinds the quick tier draws.
Examples are derandomized (a fixed seed per test): every run draws the same examples, and
a failure prints the argv (or the study's text) that reproduces it.
"""

from __future__ import annotations

import contextlib
import hashlib
import inspect
import io
import json
import math
import os
import re
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from helpers import memory_cap
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from fabplan.cli import InRange, build_parser, command_parser, main
from fabplan.design.parametric import FILE_PARAMETERS, SURFACES
from fabplan.errors import InputError
from fabplan.io.parameters import SURFACE_PARAMETERS, Parameter
from fabplan.net.mesh import QuadMesh

SLOW = os.environ.get("FABPLAN_FUZZ_SLOW") == "1"


def _tier(examples: int) -> settings:
    # derandomize: the same examples on every run (CI included); no deadline: a valid run
    # of strips or mill takes a second, a refusal a few milliseconds
    return settings(max_examples=examples, derandomize=True, deadline=None, database=None,
                    suppress_health_check=list(HealthCheck), print_blob=False)


# ---------------------------------------------------------------------------- values
#: texts no number parser should take for a number in range
HOSTILE_TEXT = ["", " ", "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e300", "-1e300",
                "1e-300", "1e400", "-1e400", "0", "-0", "-1", "18446744073709551616",
                "-18446744073709551617", "²", "１２", "٣", "1_000", "0x10", "1e", "1,5", "--",
                "\n", "1\n2", "\x00", "\t3", "1e-320", "5e-324", "9" * 400]


def hostile_text() -> st.SearchStrategy[str]:
    """Text a user (or a script gone wrong) may give anywhere a value is due."""
    long = st.builds(lambda c, n: c * n, st.characters(codec="utf-8", exclude_characters="\x00"),
                     st.integers(256, 5000))
    return st.one_of(st.sampled_from(HOSTILE_TEXT), st.text(max_size=24), long)


def number_values(parameter: Parameter) -> st.SearchStrategy[str]:
    """Valid, boundary and hostile texts for a numeric parameter, from its range."""
    low, high = parameter.low, parameter.high
    if parameter.integer:
        valid: st.SearchStrategy = st.integers(
            int(low) if low is not None else -(2**63), int(high) if high is not None else 2**63)
        edges = [b + d for b in (low, high) if b is not None for d in (-1, 0, 1)]
        boundary = st.sampled_from([int(e) for e in edges])
        wild: st.SearchStrategy = st.integers()
    else:
        valid = st.floats(low, high, allow_nan=False, allow_infinity=False,
                          exclude_min=parameter.low_open, exclude_max=parameter.high_open)
        if parameter.signed:
            valid = st.one_of(valid, valid.map(lambda x: -x))
        edges = [e for b in (low, high) if b is not None
                 for e in (b, math.nextafter(b, -math.inf), math.nextafter(b, math.inf))]
        boundary = st.sampled_from(edges or [0.0])
        wild = st.floats()
    return st.one_of(valid.map(repr), boundary.map(repr), wild.map(repr), hostile_text())


#: names a path argument may be given as: the example's own inputs and outputs, and
#: things that are no file to read or write ({...} filled in per example)
PATH_WORDS = ["{net}", "{stl}", "{study}", "{out}", "{out}/x.obj", "{dir}", "{fifo}", "{loop}",
              "{junk}", "{empty}", "{missing}", "{net}/x", "{out}/a/../m", "{out}/x.json/",
              "{dir}/" + "a" * 300, "{dir}/été ⌘.obj", "", ".", "..", "/", "/dev/null",
              "/dev/zero", "/proc/self/mem"]


#: names of files a study or a surface parameter may give ({...} filled in per example)
FILE_WORDS = [w for w in PATH_WORDS if not w.startswith("{out}")] + [
    "design.stl", "net.obj", "grid.txt", "junk.obj", "a\x00b.stl", "../" * 40 + "etc/passwd",
    "x.3dm", "design.3dm", "dir/../design.stl", "~/design.stl", "a" * 300 + ".stl"]


def path_values() -> st.SearchStrategy[str]:
    return st.one_of(st.sampled_from(PATH_WORDS), hostile_text())


# ---------------------------------------------------------------------------- commands
def _commands() -> dict:
    import argparse

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


COMMANDS = _commands()

#: the smallest valid run of each command: what a fuzzed option is added to
BASE = {
    "nets": [],
    "measure": ["{net}", "-o", "{out}/m.json"],
    "optimize": ["{net}", "--net", "snet", "-o", "{out}/o.obj", "-q"],
    "molds": ["{net}", "--tolerance-mm", "1", "-o", "{out}", "--no-3d", "-q"],
    "layout": ["hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2", "--triangles",
               "2000", "-o", "{out}/l.obj", "-q"],
    "strips": ["{net}", "--height", "40", "--thickness", "4", "--no-previews", "--workers", "1",
               "-o", "{out}", "-q"],
    "arcs": ["{net}", "-o", "{out}/a.dxf"],
    "mill": ["{net}", "--tool", "face:D=10", "--no-simulation", "-o", "{out}", "-q"],
    "study": ["{study}", "-o", "{out}", "-q"],
    "templates": ["canopy", "-o", "{out}/t.toml"],
    # stopped where it would serve the page (`sandbox`): its checks and its first solve run
    "edit": ["{net}", "--net", "snet", "--no-open", "-o", "{out}/e.obj", "-q"],
}


@dataclass(frozen=True)
class Option:
    """One option of one command and what to draw for it."""
    command: str
    flag: str
    parameter: Parameter | None     # a checked number
    choices: tuple | None
    takes_value: bool


def _options(name: str) -> list[Option]:
    found = []
    for action in COMMANDS[name]._actions:
        if not action.option_strings or action.dest == "help":
            continue
        flag = action.option_strings[-1]
        found.append(Option(name, flag, action.parameter if isinstance(action, InRange) else None,
                            tuple(action.choices) if action.choices else None,
                            action.nargs != 0))
    return found


OPTIONS = {name: _options(name) for name in COMMANDS}


def option_values(option: Option) -> st.SearchStrategy[str]:
    if option.parameter is not None:
        return number_values(option.parameter)
    if option.choices is not None:
        return st.one_of(st.sampled_from(option.choices), hostile_text())
    return path_values()


@st.composite
def command_lines(draw) -> tuple[list[str], list[tuple[str, str, Parameter]]]:
    """A command line: a command's base run with up to three options drawn, now and then
    its positional argument or output replaced. Returns the argv (with ``{...}`` names) and
    the numeric options given as (flag, text, parameter)."""
    name = draw(st.sampled_from(sorted(COMMANDS)))
    argv = list(BASE[name])
    numbers = []
    for option in draw(st.lists(st.sampled_from(OPTIONS[name]), max_size=3)) if OPTIONS[name] else []:
        if not option.takes_value:
            argv.append(option.flag)
            continue
        value = draw(option_values(option))
        if option.flag in argv:                 # replace the base run's value
            at = argv.index(option.flag)
            del argv[at:at + 2]
        argv.append(f"{option.flag}={value}")
        if option.parameter is not None:
            numbers.append((option.flag, value, option.parameter))
    if argv and draw(st.integers(0, 9)) == 0:
        at = 0 if draw(st.booleans()) or "-o" not in argv else argv.index("-o") + 1
        argv[at] = draw(path_values())
    return [name, *argv], numbers


# ---------------------------------------------------------------------------- surfaces
SURFACE_KEYS = {surface: [key for key, p in inspect.signature(SURFACES[surface]).parameters.items()
                          if key not in FILE_PARAMETERS and isinstance(p.default, (int, float, tuple))]
                for surface in SURFACES}
FILE_KEYS = {surface: [key for key in inspect.signature(SURFACES[surface]).parameters
                       if key in FILE_PARAMETERS] for surface in SURFACES}


def surface_value(surface: str, key: str) -> st.SearchStrategy[str]:
    parameter = SURFACE_PARAMETERS.get(surface, {}).get(key)
    values = number_values(parameter) if parameter is not None else hostile_text()
    if key in ("u_deg", "v_deg"):
        return st.tuples(values, values).map(lambda ab: f"{ab[0]}..{ab[1]}")
    return values


@st.composite
def surface_specs(draw) -> str:
    """``NAME:key=value,...``: a built-in surface with parameters drawn from their ranges,
    file parameters naming hostile files, now and then an unknown key."""
    surface = draw(st.sampled_from(sorted(SURFACES)))
    items = []
    for key in draw(st.lists(st.sampled_from(SURFACE_KEYS[surface] or ["x"]), max_size=3,
                             unique=True)):
        items.append(f"{key}={draw(surface_value(surface, key))}")
    for key in FILE_KEYS[surface]:
        if draw(st.integers(0, 3)) > 0:
            items.append(f"{key}={draw(st.sampled_from(['{grid}', '{grid}', *FILE_WORDS]))}")
    if draw(st.integers(0, 7)) == 0:
        items.append(f"{draw(hostile_text())}={draw(hostile_text())}")
    return surface + (":" + ",".join(items) if items else "")


# ---------------------------------------------------------------------------- studies
def _study_keys() -> dict[str, set[str]]:
    """Table -> the keys `fabplan.study.spec` asks for while reading the templates."""
    from fabplan.study import spec, table, templates

    keys: dict[str, set[str]] = {}
    get = table.Table.get

    def recording(self, key, default=None):
        keys.setdefault(re.sub(r"\[\d+\]", "", self.where), set()).add(key)
        return get(self, key, default)

    table.Table.get = recording
    try:
        for name in templates.template_names():
            spec.read_study(templates.template_path(name))
    finally:
        table.Table.get = get
    return keys


STUDY_KEYS = _study_keys()

BASE_STUDY = {
    "study": {"name": "fuzz", "max_iterations": 20},
    "design": {"surface": "hyperbolic-paraboloid", "triangles": 2000,
               "parameters": {"width": 8.0, "depth": 8.0}},
    "panels": {"size": 2.0},
    "limits": {"max_deviation_mm": 30, "mold_tolerance_mm": 2},
    "strips": {"height_mm": 40, "thickness_mm": 4},
    "cost": {"mold": 1000},
    "candidates": [{"net": "isogonal", "angle": 80, "name": "iso"}],
}


def toml_values(depth: int = 0) -> st.SearchStrategy:
    """Any TOML value, hostile ones often: numbers, texts, booleans, arrays, tables."""
    leaves = st.one_of(
        st.sampled_from([0, -1, 1, 2**63 - 1, -(2**63), 1e300, -1e300, 1e-300, 5e-324,
                         math.nan, math.inf, -math.inf, 0.5, 3, 80, True, False, "", "auto",
                         "snet", "../x", "/etc/passwd", "{study}", "{dir}", "{fifo}", "{loop}",
                         "{junk}", "{empty}", "{grid}", "{missing}", "a" * 5000, "été ⌘ 名前",
                         *FILE_WORDS]),
        st.integers(-(2**63), 2**63 - 1), st.floats(), hostile_text())
    if depth >= 2:
        return leaves
    return st.one_of(leaves, st.lists(toml_values(depth + 1), max_size=4),
                     st.dictionaries(st.text(min_size=1, max_size=8), toml_values(depth + 1),
                                     max_size=3))


@dataclass(frozen=True)
class _Nested:
    """Inline tables nested `depth` deep (written without recursion)."""
    depth: int


def _table(doc: dict, path: str) -> dict | None:
    """The table at dotted `path` of `doc` (``candidates`` its first), made where absent;
    None where an earlier change put something else there."""
    where: object = doc
    for part in path.split(".") if path else []:
        if not isinstance(where, dict):
            return None
        where = where.setdefault(part, [{}] if part == "candidates" else {})
        if part == "candidates":
            where = where[0] if isinstance(where, list) and where else None
    return where if isinstance(where, dict) else None


@st.composite
def study_documents(draw) -> dict:
    """A study as TOML data: the base study with one to three hostile changes."""
    doc = json.loads(json.dumps(BASE_STUDY))        # a deep copy
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.integers(0, 10))
        if kind <= 4:                                     # a real key, any value
            path = draw(st.sampled_from(sorted(t for t in STUDY_KEYS if t)))
            key = draw(st.sampled_from(sorted(STUDY_KEYS[path])))
            table = _table(doc, path)
            if table is not None:
                table[key] = draw(toml_values())
        elif kind == 5:                                   # a surface parameter
            surface = draw(st.sampled_from(sorted(SURFACES)))
            keys = SURFACE_KEYS[surface] + FILE_KEYS[surface]
            design, parameters = _table(doc, "design"), _table(doc, "design.parameters")
            if keys and design is not None and parameters is not None:
                design["surface"] = surface
                parameters[draw(st.sampled_from(keys))] = draw(toml_values())
        elif kind == 6:                                   # an unknown key
            table = _table(doc, draw(st.sampled_from(["", "study", "design", "panels", "limits",
                                                      "candidates"])))
            if table is not None:
                table[draw(st.text(min_size=1, max_size=12))] = draw(toml_values())
        elif kind == 7:                                   # deep nesting
            table = _table(doc, draw(st.sampled_from(["study", "design", "limits"])))
            if table is not None:
                table["deep"] = _Nested(draw(st.sampled_from([10, 200, 600, 1100])))
        elif kind == 8:                                   # a huge array
            n = draw(st.sampled_from([1000, 20000]))
            parameters = _table(doc, "design.parameters")
            if draw(st.booleans()) or parameters is None:
                doc["candidates"] = [{"net": "isogonal", "angle": 80}] * n
            else:
                parameters["width"] = [1.0] * n
        elif kind == 10:                                  # a design file of any name
            doc["design"] = {"file": draw(st.one_of(st.sampled_from(FILE_WORDS), hostile_text()))}
            if draw(st.booleans()):
                doc["design"][draw(st.sampled_from(sorted(STUDY_KEYS["design"])))] = \
                    draw(toml_values())
        else:                                             # unicode names
            for path in ("candidates", "study"):
                table = _table(doc, path)
                if table is not None:
                    table["name"] = draw(st.one_of(st.text(max_size=40), hostile_text()))
    return doc


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_value(key)


def _toml_value(value) -> str:
    if isinstance(value, _Nested):
        return "{a = " * value.depth + "1" + "}" * value.depth
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
                if math.isinf(value) else repr(value))
    if isinstance(value, str):
        # JSON escapes are TOML basic-string escapes (TOML wants DEL escaped too)
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"


def toml_text(doc: dict) -> str:
    """TOML text of `doc`: top-level tables as tables, ``[[candidates]]`` as an array of
    tables when it is a list of tables, anything else inline."""
    lines = []
    for key, value in doc.items():
        if not isinstance(value, (dict, list)):
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    for key, value in doc.items():
        if isinstance(value, dict):
            lines.append(f"[{_toml_key(key)}]")
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()]
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for item in value:
                lines.append(f"[[{_toml_key(key)}]]")
                lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in item.items()]
        elif isinstance(value, list):
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- one run
class _Accepted(Exception):
    """Raised by a stand-in for the work of a command: every check before it passed."""


def _grid_net(path: Path) -> None:
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    QuadMesh.grid(np.stack([u, v, 0.05 * u * v], axis=-1)).write_obj(path)


def _files(folder: Path) -> dict[str, Path]:
    """The inputs of an example (and things that are no input), made in `folder`."""
    net, stl, study = folder / "net.obj", folder / "design.stl", folder / "study.toml"
    _grid_net(net)
    triangles = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0.1]], [[1, 0, 0], [1, 1, 0.2], [0, 1, 0.1]]],
                         np.float32) * 8
    record = np.zeros(2, dtype=[("n", "<f4", (3,)), ("c", "<f4", (3, 3)), ("a", "<u2")])
    record["c"] = triangles
    stl.write_bytes(b"fuzz".ljust(80, b" ") + (2).to_bytes(4, "little") + record.tobytes())
    grid = folder / "grid.txt"
    grid.write_text("".join(f"{i} {j} {0.1 * i * j}\n" for i in range(4) for j in range(4)))
    (folder / "dir").mkdir()
    os.mkfifo(folder / "fifo")
    os.symlink(folder / "loop", folder / "loop")
    (folder / "junk.obj").write_bytes(bytes(range(256)) * 4)
    (folder / "empty.obj").write_bytes(b"")
    study.write_text(toml_text(BASE_STUDY), encoding="utf-8")
    return {"net": net, "stl": stl, "study": study, "grid": grid, "dir": folder / "dir",
            "fifo": folder / "fifo", "loop": folder / "loop", "junk": folder / "junk.obj",
            "empty": folder / "empty.obj", "missing": folder / "missing.obj",
            "out": folder / "out"}


def _fill(text: str, names: dict[str, Path]) -> str:
    return re.sub(r"\{(\w+)\}", lambda m: str(names[m.group(1)]) if m.group(1) in names
                  else m.group(0), text)


def _digest(folder: Path) -> dict[str, str | None]:
    """Every entry under `folder` (hidden ones too): a hash of each regular file's bytes,
    None for anything else; links not followed, FIFOs not opened."""
    listing: dict[str, str | None] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            key = str(path.relative_to(folder))
            listing[key] = (hashlib.sha256(path.read_bytes()).hexdigest()
                            if path.is_file() and not path.is_symlink() else None)
    return listing


@pytest.fixture
def sandbox(tmp_path_factory, monkeypatch):
    """A fresh folder per example (Hypothesis calls the test many times in one fixture
    scope), the work of each command stopped where it starts, and a machine with 800 MB
    available."""
    import shutil

    from fabplan.cli import optimize as optimize_command
    from fabplan.edit import server
    from fabplan.fabricate.milling import mill_report
    from fabplan.fabricate.molds import mold_report
    from fabplan.fabricate.strips import strip_plan
    from fabplan.io import resources
    from fabplan.layout import starts
    from fabplan.study import parallel, run

    def stop(*args, **kwargs):
        raise _Accepted

    # the solves and the study's candidates; the reports of molds, strips and mill (their
    # figures take seconds: the plans before them run); the editor's server
    for module, name in [(optimize_command, "optimize"), (starts, "glide_fairest"), (run, "run_study"),
                         (parallel, "run_study_parallel"), (parallel, "dask_client"),
                         (mold_report, "write_mold_report"), (mill_report, "write_mill_report"),
                         (strip_plan.StripPlan, "write"), (server, "run_editor")]:
        monkeypatch.setattr(module, name, stop)
    monkeypatch.setattr(resources, "available_memory", lambda: 800 * 10**6)
    made: list[Path] = []

    def make() -> tuple[Path, dict[str, Path]]:
        while made:                                   # the previous example's folder
            shutil.rmtree(made.pop(), ignore_errors=True)
        made.append(tmp_path_factory.mktemp("example", numbered=True))
        monkeypatch.chdir(made[-1])                   # relative names land in the example
        return made[-1], _files(made[-1])

    with memory_cap(3 * 2**30):
        yield make


def _output_of(argv: list[str]) -> str | None:
    """The output `argv` names, as the command's own parser reads it (the last ``-o``,
    ``--output=X`` and so on); None when it does not parse or names none."""
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        try:
            namespace = command_parser().parse_args(argv)
        except SystemExit:
            return None
    return getattr(namespace, "output", None)


def _written(path: Path, argv: list[str]) -> bool:
    """Whether `path` is one a run of `argv` may write: its output or a file beside it
    of the same stem (``OUT.json``), and named nowhere else in `argv`."""
    named = _output_of(argv)
    if not named:
        return False
    out = Path(named) if Path(named).is_absolute() else Path.cwd() / named
    ours = path == out or (path.parent == out.parent and out.stem != ""
                           and path.name.startswith(out.stem + "."))
    # every mention but the output options' is an input
    others = [a for i, a in enumerate(argv) if not a.startswith(("-o", "--output"))
              and not (i > 0 and argv[i - 1] in ("-o", "--output"))]
    return ours and not any(str(path) in a for a in others)


def run_example(argv: list[str], folder: Path, names: dict[str, Path],
                show: str = "") -> tuple[int | None, str]:
    """Run `argv` ({...} filled in) and assert the properties every run must have;
    returns (exit code or None when stopped at its work, stderr)."""
    argv = [_fill(a, names) for a in argv]
    inputs = [p for p in names.values() if p.is_file() and not _written(p, argv)]
    before = _digest(folder)
    hashes = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in inputs}
    stdout, stderr = io.StringIO(), io.StringIO()
    where = f"{argv!r}{show}"
    with warnings.catch_warnings(record=True) as caught, \
            contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        warnings.simplefilter("always")
        try:
            code: int | None = main(argv)
        except _Accepted:
            code = None
        except BaseException:
            raise AssertionError(f"{where}\n{traceback.format_exc()}") from None
    err = stderr.getvalue()
    event("stopped at its work" if code is None else f"exit {code}")
    if code == 2:
        event(f"refused: {re.sub(r'[^a-z ].*', '', err[16:40]) or err[16:40]!r}"[:40])
    assert not caught, f"{where}: warnings {[str(w.message) for w in caught]}"
    assert "Traceback" not in err, f"{where}\n{err}"
    for path, digest in hashes.items():
        assert hashlib.sha256(path.read_bytes()).hexdigest() == digest, f"{where}: {path} changed"
    if code is None:
        assert _digest(folder) == before, f"{where}: wrote before its work started"
        return code, err
    assert isinstance(code, int) and code in (0, 2, 3), f"{where}: exit {code!r}\n{err}"
    if code == 2:
        assert err.startswith("fabplan: error: ") and err.count("\n") == 1, f"{where}\n{err}"
        assert _digest(folder) == before, f"{where}: wrote something and exited 2\n{err}"
    if code == 3 and err.startswith("fabplan: cannot make it: "):
        assert err.count("\n") == 1, f"{where}\n{err}"
    return code, err


def _outside(parameter: Parameter, text: str) -> bool:
    try:
        parameter.check(text)
    except InputError:
        return True
    return False


def check_command_line(example, sandbox) -> None:
    argv, numbers = example
    folder, names = sandbox()
    code, err = run_example(argv, folder, names)
    refused = [flag for flag, text, parameter in numbers if _outside(parameter, text)]
    if refused:
        assert code == 2, f"{argv}: {refused} out of range, exit {code}\n{err}"


def check_surface(spec: str, command: str, sandbox) -> None:
    folder, names = sandbox()
    if command == "layout":
        argv = ["layout", spec, *BASE["layout"][1:]]
    elif command == "optimize":
        argv = ["optimize", "{net}", "--net", "snet", "--reference", spec, "-o", "{out}/o.obj"]
    else:
        argv = ["molds", "{net}", "--tolerance-mm", "1", "--panel-surface", "design", "--design",
                spec, "--triangles", "2000", "--no-3d", "-q", "-o", "{out}"]
    run_example(argv, folder, names)


def check_study(doc: dict, raw: bytes | None, sandbox) -> None:
    folder, names = sandbox()
    text = _fill(toml_text(doc), {k: v for k, v in names.items()})
    names["study"].write_bytes(raw if raw is not None else text.encode("utf-8"))
    run_example(["study", "{study}", "-q", "-o", "{out}"], folder, names,
                show=f"\n--- study.toml ---\n{text[:3000]}")


def raw_studies() -> st.SearchStrategy[bytes | None]:
    """Now and then the study file's bytes themselves: cut, not UTF-8, binary, empty."""
    text = toml_text(BASE_STUDY).encode()
    return st.one_of(st.none(), st.none(), st.none(), st.none(), st.none(), st.none(),
                     st.integers(0, len(text)).map(lambda n: text[:n]),
                     st.binary(max_size=200), st.just(b"\xff\xfe" + text),
                     st.just(b"[" * 5000), st.just(b"a = " + b"[" * 5000 + b"]" * 5000))


# ---------------------------------------------------------------------------- the tiers
def test_every_command_has_a_base_run():
    """A new command needs its smallest valid run here; its options are then drawn."""
    assert set(BASE) == set(COMMANDS), sorted(set(COMMANDS) ^ set(BASE))
    assert sum(o.parameter is not None for opts in OPTIONS.values() for o in opts) >= 30
    assert {"design", "limits", "candidates", "strips"} <= set(STUDY_KEYS)


def test_the_strategies_reach_every_kind_of_value():
    """A number's strategy draws values in and out of its range; the study writer writes
    TOML that reads back as the study it was given."""
    import sys

    from hypothesis import find

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib

    parameter = Parameter("--x", 1.0, 10.0)
    find(number_values(parameter), lambda t: not _outside(parameter, t))
    find(number_values(parameter), lambda t: _outside(parameter, t))
    find(number_values(Parameter("--n", 1, 5, integer=True)), lambda t: t == "6")
    assert tomllib.loads(toml_text(BASE_STUDY)) == BASE_STUDY
    doc = {"t": {"k": ["\x7f\n", "é", 1e300, math.inf]}, "é x": {"a": {"b": -1}}}
    read = tomllib.loads(toml_text(doc))
    assert read["t"]["k"][:3] == doc["t"]["k"][:3] and read["é x"] == doc["é x"]


@_tier(250)
@given(example=command_lines())
def test_any_command_line_ends_in_one_line(example, sandbox):
    check_command_line(example, sandbox)


@_tier(80)
@given(spec=surface_specs(), command=st.sampled_from(["layout", "layout", "optimize", "molds"]))
def test_any_surface_spec_ends_in_one_line(spec, command, sandbox):
    check_surface(spec, command, sandbox)


@_tier(130)
@given(doc=study_documents(), raw=raw_studies())
def test_any_study_file_ends_in_one_line(doc, raw, sandbox):
    check_study(doc, raw, sandbox)


slow = pytest.mark.skipif(not SLOW, reason="the slow fuzzing tier runs with FABPLAN_FUZZ_SLOW=1")


@pytest.mark.slow
@slow
@_tier(3000)
@given(example=command_lines())
def test_any_command_line_ends_in_one_line_slow(example, sandbox):
    check_command_line(example, sandbox)


@pytest.mark.slow
@slow
@_tier(1000)
@given(spec=surface_specs(), command=st.sampled_from(["layout", "layout", "optimize", "molds"]))
def test_any_surface_spec_ends_in_one_line_slow(spec, command, sandbox):
    check_surface(spec, command, sandbox)


@pytest.mark.slow
@slow
@_tier(1400)
@given(doc=study_documents(), raw=raw_studies())
def test_any_study_file_ends_in_one_line_slow(doc, raw, sandbox):
    check_study(doc, raw, sandbox)

