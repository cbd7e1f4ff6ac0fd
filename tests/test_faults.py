"""Faults in the middle of writing: disk full, Ctrl-C, kill -9.

Each test first writes an earlier result, then breaks a second run while it writes (the
k-th file it opens for writing raises ENOSPC or KeyboardInterrupt; or the process gets
SIGKILL). The earlier result must be intact, byte for byte, with nothing beside it; and
a next run must succeed and leave no staging folder behind.
"""

from __future__ import annotations

import builtins
import errno
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import interruptible

from fabplan.cli import main
from fabplan.net.mesh import QuadMesh


def listing(folder: Path) -> dict:
    """Every path under `folder`, hidden ones included, with the bytes of the files."""
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


def inject(monkeypatch, folder: Path, k: int, error) -> list:
    """Make the `k`-th file opened for writing under `folder` raise `error()`; returns a
    one-element list counting the opens, to prove the fault fired."""
    count = [0]
    real_open, real_os_open = builtins.open, os.open
    root = Path(os.path.realpath(folder))

    def hit(path, writing) -> None:
        if writing and Path(os.path.realpath(path)).is_relative_to(root):
            count[0] += 1
            if count[0] == k:
                raise error(path)

    def fake_open(file, mode="r", *args, **kwargs):
        if isinstance(file, (str, os.PathLike)):
            hit(file, any(c in mode for c in "wax+"))
        return real_open(file, mode, *args, **kwargs)

    def fake_os_open(path, flags, *args, **kwargs):
        hit(path, flags & (os.O_WRONLY | os.O_RDWR))
        return real_os_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(io, "open", fake_open)
    monkeypatch.setattr(os, "open", fake_os_open)
    return count


def disk_full(path) -> OSError:
    return OSError(errno.ENOSPC, "No space left on device", str(path))


def interrupt(path) -> KeyboardInterrupt:
    return KeyboardInterrupt()


@pytest.fixture
def net(tmp_path) -> Path:
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    path = tmp_path / "net.obj"
    QuadMesh.grid(np.stack([u, v, 0.05 * u * v], axis=-1)).write_obj(path)
    return path


# quiet (-q): the error must be the one line on standard error, without the stage lines
COMMANDS = {
    "layout": lambda net, out, variant: [
        "layout", "hyperbolic-paraboloid", "--net", "snet", "--triangles", "500", "-q",
        "--max-iter", "2", "--panel-size", ["4", "3"][variant], "-o", str(out / "net.obj")],
    "strips": lambda net, out, variant: [
        "strips", str(net), "--height", ["40", "50"][variant], "--thickness", "4", "-q",
        "--no-previews", "-o", str(out)],
}


def _faulted_run(command, k, error, net, tmp_path, capsys, monkeypatch) -> None:
    out = tmp_path / "out"
    assert main(COMMANDS[command](net, out, 0)) in (0, 3)
    capsys.readouterr()
    before = listing(tmp_path)
    with monkeypatch.context() as patch:
        opened = inject(patch, out, k, error)
        code = main(COMMANDS[command](net, out, 1))
    assert opened[0] >= k, "the fault never fired"
    err = capsys.readouterr().err
    if error is disk_full:
        assert code == 2 and err.count("\n") == 1, err
        assert err.startswith("fabplan: error: ") and "No space left on device" in err
    else:
        assert code == 130 and err == "fabplan: interrupted\n"
    assert listing(tmp_path) == before          # earlier output intact, nothing left
    assert main(COMMANDS[command](net, out, 1)) in (0, 3)
    assert not [p for p in out.rglob(".*")], "a staging folder or temporary file was left"


@pytest.mark.parametrize("k, error", [
    (1, disk_full), (3, disk_full), (2, interrupt),
    pytest.param(2, disk_full, marks=pytest.mark.slow),
    pytest.param(1, interrupt, marks=pytest.mark.slow),
    pytest.param(3, interrupt, marks=pytest.mark.slow)])
def test_a_layout_broken_while_writing_keeps_the_earlier_one(net, tmp_path, capsys, monkeypatch,
                                                             k, error):
    """Disk full while `layout` saved its PNG gave three chained tracebacks, and a picture
    of the new net beside the earlier net."""
    _faulted_run("layout", k, error, net, tmp_path, capsys, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("error", [disk_full, interrupt])
@pytest.mark.parametrize("k", [1, 3, 5])
def test_strips_broken_while_writing_keep_the_earlier_ones(net, tmp_path, capsys, monkeypatch,
                                                           k, error):
    _faulted_run("strips", k, error, net, tmp_path, capsys, monkeypatch)


STUDY = """
[design]
surface = "hyperbolic-paraboloid"
triangles = 2000
[design.parameters]
width = 8.0
depth = 8.0
[panels]
size = {size}
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
[study]
max_iterations = 10
[[candidates]]
net = "isogonal"
angle = 80
"""


@pytest.mark.slow
@pytest.mark.parametrize("error", [disk_full, interrupt])
def test_a_study_broken_while_writing_keeps_the_earlier_one(tmp_path, capsys, monkeypatch,
                                                            error):
    study = tmp_path / "s.toml"
    out = tmp_path / "out"
    study.write_text(STUDY.format(size=2.0), encoding="utf-8")
    assert main(["study", str(study), "-q", "-o", str(out)]) == 0
    capsys.readouterr()
    before = listing(tmp_path)
    study.write_text(STUDY.format(size=1.6), encoding="utf-8")
    before[study.name] = study.read_bytes()
    with monkeypatch.context() as patch:
        opened = inject(patch, tmp_path, 4, error)
        code = main(["study", str(study), "-q", "-o", str(out)])
    assert opened[0] >= 4
    err = capsys.readouterr().err
    assert code == (2 if error is disk_full else 130) and err.count("\n") == 1, err
    assert listing(tmp_path) == before
    assert main(["study", str(study), "-q", "-o", str(out)]) == 0
    # nothing hidden but the study's list of its files
    assert [p.name for p in tmp_path.rglob(".*")] == [".fabplan-files"]


def _wait_for(predicate, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return False


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_strips_killed_while_writing_leave_the_earlier_ones(net, tmp_path, sig):
    """A killed `strips` left a 12 MB staging folder that later runs never removed;
    SIGTERM and SIGHUP left it like SIGKILL."""
    out = tmp_path / "out"
    argv = [sys.executable, "-c", "import sys; from fabplan.cli import main; sys.exit(main())",
            "strips", str(net), "--thickness", "4", "-o", str(out)]
    subprocess.run([*argv, "--height", "40"], check=True, capture_output=True)
    before = listing(out)
    process = subprocess.Popen([*argv, "--height", "50"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, preexec_fn=interruptible)
    staged = _wait_for(lambda: any(p.name.startswith(".") for p in out.iterdir()), 60)
    process.send_signal(sig)
    _, err = process.communicate(timeout=60)
    assert staged, "the run never staged its files"
    left = {k: v for k, v in listing(out).items() if not k.startswith(".")}
    # the earlier output intact; or, where the signal came after the new files were all
    # moved in (a loaded machine), the new output whole: never a mix of the two
    finished = left != before
    if finished:
        listed = json.loads(left["strips.json"])["files"]
        assert sorted(left) == sorted(listed)
        assert all(left[name] != before.get(name) for name in listed if name.endswith(".dxf"))
    else:
        assert left == before
    if sig == signal.SIGINT:
        assert process.returncode in ((0, 130) if finished else (130,))
        assert process.returncode == 0 or err == b"fabplan: interrupted\n"
    elif sig != signal.SIGKILL:
        assert process.returncode in ((0, 128 + sig) if finished else (128 + sig,))
        assert process.returncode == 0 or \
            err == f"fabplan: stopped by {signal.Signals(sig).name}\n".encode()
    if sig != signal.SIGKILL:
        assert listing(out) == left           # and nothing left behind
    subprocess.run([*argv, "--height", "50"], check=True, capture_output=True)
    assert not [p for p in out.rglob(".*")], "the stale staging folder was not removed"
