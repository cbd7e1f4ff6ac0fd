"""Memory estimates before the work: molds and mill from the net's faces, a triangulation
from ``--triangles`` (layout, molds --design, a study's design.triangles), a design or
reference mesh from its triangles (`fabplan.io.resources`).

The machine is made to have a known amount of memory available (`available_memory`
patched), so that the same request is refused on every machine; each refusal must come
within 5 s, in one line naming the option, key or file and the largest size that fits,
with nothing written.
"""

from __future__ import annotations

import re
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from fabplan.cli import main
from fabplan.io import resources
from fabplan.io.resources import (
    DESIGN_MEMORY,
    MILL_MEMORY,
    MOLDS_MEMORY,
    REFERENCE_MEMORY,
    SIMULATION_MEMORY,
    MemoryModel,
    check_memory,
    memory_reason,
)
from fabplan.net.mesh import QuadMesh


def _listing(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


def refused_quickly(argv: list, capsys, folder: Path, *fragments: str) -> str:
    """Run `argv`: exit 2 within 5 s, one line with `fragments`, `folder` unchanged."""
    before = _listing(folder)
    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main([str(a) for a in argv])
    seconds = time.perf_counter() - started
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, err
    assert _listing(folder) == before
    assert seconds < 5.0, (seconds, err)
    return err


def _memory(monkeypatch, gigabytes: float) -> float:
    """Make the machine have `gigabytes` available; returns the limit of a run, bytes."""
    monkeypatch.setattr(resources, "available_memory", lambda: int(gigabytes * 1e9))
    return resources.memory_limit()


def _dome(path: Path, side: int) -> Path:
    """A (side - 1)^2-face grid net on a dome of radius twice its width (model units m)."""
    u, v = np.meshgrid(np.arange(float(side)), np.arange(float(side)), indexing="ij")
    u, v = u - u.mean(), v - v.mean()
    QuadMesh.grid(np.stack([u, v, -(u**2 + v**2) / (4 * side)], axis=-1)).write_obj(path)
    return path


def _stl(path: Path, side: int) -> Path:
    """A binary STL of 2 (side - 1)^2 triangles on a saddle 20 units wide."""
    u, v = np.meshgrid(np.linspace(-10, 10, side), np.linspace(-10, 10, side), indexing="ij")
    P = np.stack([u, v, 0.02 * (u**2 - v**2)], axis=-1).reshape(-1, 3)
    i = (np.arange(side - 1)[:, None] * side + np.arange(side - 1)[None, :]).ravel()
    T = np.concatenate([np.stack([i, i + side, i + side + 1], 1),
                        np.stack([i, i + side + 1, i + 1], 1)])
    record = np.zeros(len(T), dtype=[("n", "<f4", (3,)), ("c", "<f4", (3, 3)), ("a", "<u2")])
    record["c"] = P[T]
    path.write_bytes(b"saddle".ljust(80, b" ") + len(T).to_bytes(4, "little") + record.tobytes())
    return path


@pytest.fixture(scope="module")
def large_net(tmp_path_factory) -> Path:
    """A net of 19,600 faces: about 1 GB for molds or mill."""
    return _dome(tmp_path_factory.mktemp("large") / "dome.obj", 141)


# ---------------------------------------------------------------------------- the models
@pytest.mark.parametrize("model", [MOLDS_MEMORY, MILL_MEMORY, DESIGN_MEMORY, REFERENCE_MEMORY,
                                   SIMULATION_MEMORY])
def test_the_largest_size_that_fits_is_the_boundary_of_the_refusals(model, monkeypatch):
    limit = _memory(monkeypatch, 16)
    largest = model.largest_fitting(limit)
    assert largest > 0
    assert model.peak_bytes(largest) <= limit < model.peak_bytes(largest + 1)
    assert memory_reason(model, largest) is None
    reason = memory_reason(model, largest + 1)
    assert reason is not None and f"holds at most {largest:,} {model.unit}" in reason


def test_the_models_lie_above_the_measured_peaks():
    """The peaks of benchmarks/README.md (MiB at three sizes) are within each line."""
    measured = {MOLDS_MEMORY: [(2_500, 221), (10_000, 572), (40_000, 1_949)],
                MILL_MEMORY: [(2_500, 265), (10_000, 473), (40_000, 1_626)],
                DESIGN_MEMORY: [(100_000, 484), (400_000, 1_738), (1_600_000, 6_845)],
                REFERENCE_MEMORY: [(100_000, 146), (400_000, 370), (1_600_000, 1_212)]}
    for model, peaks in measured.items():
        for size, mib in peaks:
            assert mib * 2**20 <= model.peak_bytes(size) <= 1.35 * mib * 2**20 + 200e6, \
                (model.work, size)
    # the simulation on top of the plan of the same 2,500 faces
    for cells, mib in [(250_000, 420), (1_000_000, 1_203)]:
        peak = MILL_MEMORY.peak_bytes(2_500) + SIMULATION_MEMORY.peak_bytes(cells)
        assert mib * 2**20 <= peak <= 1.35 * mib * 2**20, cells


def test_a_size_within_the_memory_passes(monkeypatch):
    _memory(monkeypatch, 4)
    check_memory(MOLDS_MEMORY, 20_000, where="net.obj", fix="-")
    check_memory(DESIGN_MEMORY, 40_000, where="--triangles 40000", fix="-")
    with pytest.raises(Exception, match="net.obj: molds of 2,000,000 faces would need about 97 GB"):
        check_memory(MOLDS_MEMORY, 2_000_000, where="net.obj", fix="-")
    assert "minutes" not in (memory_reason(MemoryModel("x of", "y", 0, 1e9), 2) or "")


# ---------------------------------------------------------------------------- commands
def test_molds_of_a_net_beyond_the_memory_is_refused(large_net, tmp_path, capsys, monkeypatch):
    """molds on a 100k-face net ended in a generic out-of-memory message after a minute."""
    limit = _memory(monkeypatch, 1)
    largest = MOLDS_MEMORY.largest_fitting(limit)
    refused_quickly(["molds", large_net, "--tolerance-mm", "2", "-o", tmp_path / "m"], capsys,
                    tmp_path, f"{large_net}: molds of 19,600 faces would need about 1.1 GB of "
                    "memory", f"0.5 GB holds at most {largest:,} faces",
                    "run molds on a coarser net or on parts of it, or give --max-panels")
    refused_quickly(["molds", large_net, "--tolerance-mm", "2", "--max-panels", "1000",
                     "-o", tmp_path / "m"], capsys, tmp_path,
                    "molds of a net of 19,600 faces: about 19,600 panels", "limit of 1,000")


def test_mill_of_a_net_beyond_the_memory_is_refused(large_net, tmp_path, capsys, monkeypatch):
    limit = _memory(monkeypatch, 1)
    largest = MILL_MEMORY.largest_fitting(limit)
    refused_quickly(["mill", large_net, "--units", "m", "--tool", "face:D=40", "-o",
                     tmp_path / "p"], capsys, tmp_path,
                    f"{large_net}: milling paths of 19,600 faces would need about",
                    f"holds at most {largest:,} faces", "run mill on a coarser net")


def test_a_simulation_beyond_the_memory_is_refused_naming_the_step(tmp_path, capsys,
                                                                   monkeypatch):
    """A 500 mm net simulated at 0.5 mm: a million cells, 1.2 GB and four minutes."""
    limit = _memory(monkeypatch, 2)
    net = _dome(tmp_path / "n.obj", 51)
    plan = MILL_MEMORY.peak_bytes(2_500)
    fits = SIMULATION_MEMORY.largest_fitting(limit - plan)
    err = refused_quickly(["mill", net, "--units", "cm", "--tool", "face:D=40", "--sim-step",
                           "0.5", "-o", tmp_path / "p"], capsys, tmp_path,
                          "--sim-step 0.5: a milling simulation of 1,002,001 cells would need",
                          f"holds at most {fits:,} cells beside the rest",
                          "or give --no-simulation")
    step = float(re.search(r"a --sim-step of ([0-9.]+) mm or more fits", err).group(1))
    assert SIMULATION_MEMORY.peak_bytes(1_002_001 * (0.5 / step) ** 2) + plan <= limit


def test_a_net_within_the_memory_is_milled(tmp_path, capsys, monkeypatch):
    _memory(monkeypatch, 2)
    net = _dome(tmp_path / "small.obj", 11)
    # in cm: lines 10 mm apart, which a 40 mm cutter mills
    code = main(["mill", str(net), "--units", "cm", "--tool", "face:D=40", "--no-simulation",
                 "-q", "-o", str(tmp_path / "p")])
    assert code in (0, 3), capsys.readouterr().err
    assert (tmp_path / "p" / "mill.json").is_file()


@pytest.mark.parametrize("command", ["layout", "molds"])
def test_too_many_triangles_are_refused_naming_the_option(command, tmp_path, capsys,
                                                         monkeypatch):
    """layout --triangles 5000000 ran out of memory after 103 s."""
    limit = _memory(monkeypatch, 8)
    largest = DESIGN_MEMORY.largest_fitting(limit)
    net = _dome(tmp_path / "n.obj", 6)
    argv = (["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "1",
             "--triangles", "5000000", "-o", tmp_path / "o" / "l.obj"] if command == "layout" else
            ["molds", net, "--tolerance-mm", "2", "--panel-surface", "design", "--design",
             "hyperbolic-paraboloid",
             "--triangles", "5000000", "-o", tmp_path / "o"])
    refused_quickly(argv, capsys, tmp_path,
                    "--triangles 5000000: a design of 5,000,000 triangles would need about "
                    "23 GB of memory", f"4.0 GB holds at most {largest:,} triangles",
                    "give fewer --triangles")


def test_a_design_or_reference_mesh_beyond_the_memory_is_refused(tmp_path, capsys, monkeypatch):
    stl = _stl(tmp_path / "design.stl", 101)           # 20,000 triangles
    limit = _memory(monkeypatch, 0.2)
    refused_quickly(["layout", stl, "--net", "snet", "--panel-size", "1", "-o",
                     tmp_path / "o" / "l.obj"], capsys, tmp_path,
                    f"{stl}: a design of 20,000 triangles would need about",
                    f"holds at most {DESIGN_MEMORY.largest_fitting(limit):,} triangles",
                    "lay out a coarser mesh")
    net = _dome(tmp_path / "n.obj", 6)
    refused_quickly(["optimize", net, "--net", "snet", "--reference", stl, "-o",
                     tmp_path / "o" / "o.obj"], capsys, tmp_path,
                    f"{stl}: a reference of 20,000 triangles would need about",
                    f"holds at most {REFERENCE_MEMORY.largest_fitting(limit):,} triangles")


def test_a_study_with_too_many_triangles_is_refused_naming_the_key(tmp_path, capsys,
                                                                   monkeypatch):
    _memory(monkeypatch, 8)
    study = tmp_path / "s.toml"
    text = """
[design]
surface = "hyperbolic-paraboloid"
triangles = {triangles}
[panels]
size = 2.0
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
[[candidates]]
net = "isogonal"
angle = 80
"""
    study.write_text(text.format(triangles=5_000_000), encoding="utf-8")
    refused_quickly(["study", study, "-q", "-o", tmp_path / "out"], capsys, tmp_path,
                    f"{study}: design.triangles 5000000: a design of 5,000,000 triangles "
                    "would need about 23 GB", "give fewer")
    study.write_text(text.format(triangles=50_000_000), encoding="utf-8")
    refused_quickly(["study", study, "-q", "-o", tmp_path / "out"], capsys, tmp_path,
                    f"{study}: design.triangles must be at most 5000000 (range [100, 5000000])")
