"""Seeded fuzzing of every command through `fabplan.cli.main`, in-process.

Valid OBJ nets, STL designs (binary and ASCII), OFF designs, study TOML files and option sets are
mutated: truncation, byte flips, NaN and infinities, bad indices, huge and tiny numbers,
empty and random binary files, wrong types. Whatever the mutation, a run must

- never let an exception escape `main` (no traceback) nor a warning reach the user,
- exit 0 or 3 (the mutant was still valid) or 2 with exactly one ``fabplan: error:`` line,
- write nothing when it exits 2 (the folder listing is unchanged, hidden files included),
- leave its input files byte for byte as they were.

Each case is generated from its seed alone, so a failure names a reproducible case.
115 cases run in the quick tier, 1,250 more in the slow tier. Studies that are
still valid after mutation are stopped where the candidates would start to run (the
reading, validation and output checks before it are what is fuzzed; `test_study` runs
whole studies).
"""

from __future__ import annotations

import contextlib
import io
import re
import shutil
import struct
import traceback
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from helpers import memory_cap

from fabplan.cli import main
from fabplan.net.mesh import QuadMesh

HOSTILE_NUMBERS = ["nan", "inf", "-inf", "-1", "0", "-0", "1e300", "-1e300", "1e-300", "1e308",
                   "1e400", "99999999999999999999999", "0x10", "1,5", "", " ", "abc", "1e",
                   "--", "1/2", "∞", "\x00", "NaN", "3.5"]
HOSTILE_INDICES = ["0", "-1", "-999", "31", "99999", "99999999999999999999999", "1.5", "a",
                   "1//", "/1", "-0"]


# ---------------------------------------------------------------------------- seeds
def _grid() -> QuadMesh:
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    return QuadMesh.grid(np.stack([u, v, 0.05 * u * v], axis=-1), name="grid")


def _obj_text() -> str:
    from fabplan.io.obj import format_obj

    grid = _grid()
    return format_obj(grid.vertices, grid.faces, header="fuzz seed")


def _saddle_triangles() -> np.ndarray:
    u, v = np.meshgrid(np.linspace(-3, 3, 7), np.linspace(-3, 3, 7), indexing="ij")
    V = np.stack([u, v, 0.1 * u * v], axis=-1).reshape(-1, 3)
    i = np.arange(6)[:, None] * 7 + np.arange(6)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 7, i.ravel() + 8, i.ravel() + 1
    return V[np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])]


def _stl_binary() -> bytes:
    T = _saddle_triangles()
    record = np.zeros(len(T), dtype=[("n", "<f4", (3,)), ("c", "<f4", (3, 3)), ("a", "<u2")])
    record["c"] = T
    return b"fuzz".ljust(80, b" ") + len(T).to_bytes(4, "little") + record.tobytes()


def _stl_ascii() -> str:
    lines = ["solid fuzz"]
    for t in _saddle_triangles():
        lines += ["facet normal 0 0 1", "outer loop"]
        lines += [f"vertex {x:.6g} {y:.6g} {z:.6g}" for x, y, z in t]
        lines += ["endloop", "endfacet"]
    return "\n".join(lines + ["endsolid fuzz"]) + "\n"


def _off_text() -> str:
    T = _saddle_triangles()
    lines = ["OFF", f"{3 * len(T)} {len(T)} 0"]
    lines += [f"{x:.6g} {y:.6g} {z:.6g}" for x, y, z in T.reshape(-1, 3)]
    lines += [f"3 {3 * i} {3 * i + 1} {3 * i + 2}" for i in range(len(T))]
    return "\n".join(lines) + "\n"


TOML = """\
[study]
name = "fuzz"
max_iterations = 20

[design]
surface = "hyperbolic-paraboloid"
triangles = 2000

[design.parameters]
width = 8.0
depth = 8.0

[panels]
size = 2.0

[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2

[strips]
height_mm = 40
thickness_mm = 4

[cost]
mold = 1000

[[candidates]]
net = "isogonal"
angle = 80
name = "iso"
"""


# ---------------------------------------------------------------------------- mutations
def _mutate_text(text: str, rng: np.random.Generator, *, numbers: bool = True) -> bytes:
    """One hostile change to a text input, chosen by `rng`."""
    lines = text.splitlines()
    kind = rng.integers(10)
    if kind == 0:                                           # truncation
        data = text.encode()
        return data[: int(rng.integers(len(data)))]
    if kind == 1:                                           # byte flips
        data = bytearray(text.encode())
        for _ in range(int(rng.integers(1, 6))):
            data[int(rng.integers(len(data)))] = int(rng.integers(256))
        return bytes(data)
    if kind == 2:                                           # empty, or binary noise
        return b"" if rng.random() < 0.3 else rng.bytes(int(rng.integers(1, 400)))
    if kind == 3:                                           # lines dropped or repeated
        i = int(rng.integers(len(lines)))
        lines = lines[:i] + lines[i + 1:] if rng.random() < 0.5 else lines[:i] + [lines[i]] * 3 + lines[i:]
        return ("\n".join(lines) + "\n").encode()
    if kind == 4:                                           # a wrong type of value
        i = int(rng.integers(len(lines)))
        lines[i] = re.sub(r"= .*", "= " + str(rng.choice(['"text"', "[1, 2]", "{ a = 1 }",
                                                           "true", "1979-05-27", '"../x"'])),
                          lines[i]) if "=" in lines[i] else lines[i] + " junk"
        return ("\n".join(lines) + "\n").encode()
    if kind == 5:                                           # non-UTF-8 bytes in a line
        i = int(rng.integers(len(lines)))
        return ("\n".join(lines[:i]) + "\n").encode() + b"\xff\xfe\x80" + \
            ("\n".join(lines[i:]) + "\n").encode()
    # kinds 6-9: replace numbers (coordinates, indices, values) by hostile ones
    tokens = [(i, m) for i, line in enumerate(lines)
              for m in re.finditer(r"(?<![\w.])-?\d+(\.\d*)?(e[-+]?\d+)?(?![\w.])", line)]
    if not tokens or not numbers:
        return text.encode()[::-1]
    for _ in range(int(rng.integers(1, 4))):
        i, m = tokens[int(rng.integers(len(tokens)))]
        is_index = lines[i].startswith("f ")
        pool = HOSTILE_INDICES if is_index and rng.random() < 0.7 else HOSTILE_NUMBERS
        value = str(rng.choice(pool))
        lines[i] = lines[i][: m.start()] + value + lines[i][m.end():]
        tokens = [(j, mm) for j, line in enumerate(lines)
                  for mm in re.finditer(r"(?<![\w.])-?\d+(\.\d*)?(e[-+]?\d+)?(?![\w.])", line)]
        if not tokens:
            break
    return ("\n".join(lines) + "\n").encode()


def _mutate_stl(rng: np.random.Generator) -> bytes:
    if rng.random() < 0.3:
        return _mutate_text(_stl_ascii(), rng)
    data = bytearray(_stl_binary())
    kind = rng.integers(6)
    if kind == 0:
        return bytes(data[: int(rng.integers(len(data)))])
    if kind == 1:
        for _ in range(int(rng.integers(1, 8))):
            data[int(rng.integers(len(data)))] = int(rng.integers(256))
        return bytes(data)
    if kind == 2:                                           # the triangle count lies
        data[80:84] = int(rng.choice([0, 1, 71, 73, 2**31, 2**32 - 1])).to_bytes(4, "little")
        return bytes(data)
    if kind == 3:                                           # hostile coordinates
        value = float(rng.choice([np.nan, np.inf, -np.inf, 3e38, -3e38, 1e-45, 0.0]))
        for _ in range(int(rng.integers(1, 10))):
            t, c = int(rng.integers(72)), int(rng.integers(9))
            struct.pack_into("<f", data, 84 + 50 * t + 12 + 4 * c, value)
        return bytes(data)
    if kind == 4:                                           # every corner the same point
        for t in range(72):
            struct.pack_into("<9f", data, 84 + 50 * t + 12, *([1.0] * 9))
        return bytes(data)
    return bytes(data) + rng.bytes(int(rng.integers(1, 100)))


OPTION_SETS = {
    "measure": (["measure", "{net}", "-o", "{out}/m.json"], []),
    "optimize": (["optimize", "{net}", "--net", "snet", "--max-iter", "2", "-o", "{out}/o.obj"],
                 ["--angle", "--radius", "--max-iter", "--handle", "--fix"]),
    "molds": (["molds", "{net}", "--tolerance-mm", "2", "-o", "{out}/m"],
              ["--tolerance-mm", "--max-mold-size", "--units", "--panel-surface"]),
    "strips": (["strips", "{net}", "--height", "40", "--thickness", "4", "--no-previews",
                "--max-panels", "1", "-o", "{out}/s"],
               ["--height", "--thickness", "--units", "--sheet", "--spacing", "--margin", "--kerf",
                "--clearance", "--tolerance", "--end", "--extension", "--splice",
                "--splice-length", "--labels", "--label-height", "--layer", "--max-panels"]),
    "layout": (["layout", "{stl}", "--net", "snet", "--panel-size", "2", "--max-iter", "2",
                "--max-panels", "3000", "-o", "{out}/l.obj"],
               ["--panel-size", "--angle", "--family", "--triangles", "--max-iter", "--net",
                "--max-panels"]),
    "templates": (["templates", "canopy", "-o", "{out}/t.toml"], []),
}
HOSTILE_WORDS = ["", "x", "../../x", "/", "snet", "m", "ft", "1e9x1e9", "nanxnan", "0x0",
                 "cut=", "cut=A:999", "1:1,1", "abc:1,2,3", "z:0", "z:-1", "x:nan"]


def _mutate_options(rng: np.random.Generator, net: Path, stl: Path, out: Path) -> list:
    command = str(rng.choice(list(OPTION_SETS)))
    base, options = OPTION_SETS[command]
    argv = [a.format(net=net, stl=stl, out=out) for a in base]
    for _ in range(int(rng.integers(1, 3))):
        pool = HOSTILE_NUMBERS + HOSTILE_WORDS
        if options and rng.random() < 0.8:
            argv[-2:-2] = [str(rng.choice(options)), str(rng.choice(pool))]
        elif rng.random() < 0.5:                           # a missing or extra argument
            del argv[int(rng.integers(1, len(argv)))]
        else:
            argv.insert(int(rng.integers(1, len(argv) + 1)), str(rng.choice(pool)))
    return argv


# ---------------------------------------------------------------------------- one case
class _StudyAccepted(Exception):
    """Raised by the stand-in of `run_study`: the study passed every check before it."""


def _case(kind: str, seed: int, folder: Path) -> tuple[list, dict]:
    """The argv of case `seed` of `kind` and its input files (name -> bytes)."""
    rng = np.random.default_rng([seed, sum(map(ord, kind))])
    net, stl, study = folder / "net.obj", folder / "design.stl", folder / "study.toml"
    out = folder / "out"
    inputs = {net.name: _obj_text().encode(), stl.name: _stl_binary(),
              study.name: TOML.encode()}
    if kind == "obj":
        inputs[net.name] = _mutate_text(_obj_text(), rng)
        command = rng.choice(["measure", "optimize", "strips", "strips", "molds"],
                             p=[0.35, 0.25, 0.15, 0.15, 0.1])
        argv = [a.format(net=net, stl=stl, out=out) for a in OPTION_SETS[str(command)][0]]
    elif kind == "stl":
        inputs[stl.name] = _mutate_stl(rng)
        argv = [a.format(net=net, stl=stl, out=out) for a in OPTION_SETS["layout"][0]]
    elif kind == "off":                                     # read through trimesh
        off = folder / "design.off"
        inputs[off.name] = _mutate_text(_off_text(), rng)
        argv = [a.format(net=net, stl=off, out=out) for a in OPTION_SETS["layout"][0]]
    elif kind == "toml":
        inputs[study.name] = _mutate_text(TOML, rng)
        argv = ["study", str(study), "-q", "-o", str(out / "study")]
    else:
        argv = _mutate_options(rng, net, stl, out)
    return argv, inputs


def _listing(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


def _run_case(kind: str, seed: int, folder: Path, monkeypatch) -> str | None:
    """Run one case; the outcome ('refused', 'accepted') or raise AssertionError."""
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir()
    argv, inputs = _case(kind, seed, folder)
    for name, data in inputs.items():
        (folder / name).write_bytes(data)
    before = _listing(folder)
    stdout, stderr = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught, \
            contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        warnings.simplefilter("always")
        try:
            code = main(argv)
        except _StudyAccepted:
            code = None
        except SystemExit as exc:                          # argparse usage errors
            code = exc.code
        except BaseException:
            raise AssertionError(f"{kind} case {seed}: {argv}\n{traceback.format_exc()}") from None
    err = stderr.getvalue()
    where = f"{kind} case {seed}: {argv}"
    assert not caught, f"{where}: warnings {[str(w.message) for w in caught]}"
    assert "Traceback" not in err, f"{where}\n{err}"
    assert "out of memory" not in err, f"{where}: the resource guards let it through\n{err}"
    for name, data in inputs.items():
        assert (folder / name).read_bytes() == data, f"{where}: the input {name} changed"
    if code is None:
        assert _listing(folder) == before, f"{where}: the study wrote before running"
        return "accepted"
    assert code in (0, 2, 3), f"{where}: exit {code}\n{err}"
    if code == 2:
        assert err.startswith("fabplan: error: ") and err.count("\n") == 1, f"{where}\n{err}"
        assert _listing(folder) == before, f"{where}: wrote something and exited 2\n{err}"
        return "refused"
    return "accepted"


def _fuzz(kind: str, seeds: range, tmp_path: Path, monkeypatch) -> Counter:
    from fabplan.study import run

    def accepted(*args, **kwargs):
        raise _StudyAccepted

    monkeypatch.setattr(run, "run_study", accepted)
    outcomes: Counter = Counter()
    failures = []
    with memory_cap(4 * 2**30):
        for seed in seeds:
            try:
                outcomes[_run_case(kind, seed, tmp_path / "case", monkeypatch)] += 1
            except AssertionError as exc:
                failures.append(str(exc))
    print(f"fuzz {kind}: {len(seeds)} cases, {dict(outcomes)}")
    assert not failures, f"{len(failures)} of {len(seeds)} failed:\n\n" + "\n\n".join(failures[:5])
    return outcomes


KINDS = ["obj", "stl", "off", "toml", "options"]
QUICK = {"obj": 30, "stl": 20, "off": 10, "toml": 30, "options": 25}
SLOW = {"obj": 350, "stl": 200, "off": 150, "toml": 300, "options": 250}


@pytest.mark.parametrize("kind", KINDS)
def test_fuzz_sample(kind, tmp_path, monkeypatch):
    """The quick tier's sample (the first seeds of every kind)."""
    outcomes = _fuzz(kind, range(QUICK[kind]), tmp_path, monkeypatch)
    assert outcomes["refused"] > 0      # the mutations do reach the checks


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_fuzz_full(kind, tmp_path, monkeypatch):
    """1,250 further cases (seeds from 1000 on)."""
    outcomes = _fuzz(kind, range(1000, 1000 + SLOW[kind]), tmp_path, monkeypatch)
    assert outcomes["refused"] > 0
