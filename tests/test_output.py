"""The output transaction: all files or none, nothing left behind, special files refused."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest

from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.io.output import (
    STAGING_MARKER,
    atomic_path,
    check_output_file,
    check_output_folder,
    output_folder,
    remove_stale_staging,
    write_texts,
)


def _tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def test_write_texts_writes_all_files_with_the_umask_applied(tmp_path):
    write_texts({tmp_path / "a" / "x.txt": "x", tmp_path / "a" / "b" / "y.txt": "y"})
    assert (tmp_path / "a" / "x.txt").read_text() == "x"
    assert (tmp_path / "a" / "b" / "y.txt").read_text() == "y"
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "a" / "x.txt").stat().st_mode & 0o777 == 0o666 & ~mask
    assert _tree(tmp_path) == ["a", "a/b", "a/b/y.txt", "a/x.txt"]


def test_write_texts_is_all_or_nothing_and_removes_the_folders_it_made(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(InputError, match="cannot write"):
        write_texts({tmp_path / "new" / "deep" / "x.txt": "x", blocker / "y.txt": "y"})
    assert _tree(tmp_path) == ["file"]


def test_an_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    calls = []

    def interrupted(src, dst):
        calls.append(dst)
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_texts({tmp_path / "out" / "x.txt": "x"})
    assert calls and _tree(tmp_path) == []


def test_atomic_path_leaves_no_folder_on_failure(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "new" / "pic.png") as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("drawing failed")
    assert _tree(tmp_path) == []


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe"
    os.mkfifo(path)
    return path


@pytest.fixture
def unix_socket(tmp_path):
    path = tmp_path / "sock"
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    yield path
    server.close()


def test_special_files_are_refused_as_outputs(fifo, unix_socket):
    for path, kind in ((fifo, "FIFO"), (unix_socket, "socket")):
        with pytest.raises(InputError, match=kind):
            check_output_file(path)
        with pytest.raises(InputError, match=kind):
            write_texts({path: "text"})
        with pytest.raises(InputError, match=kind):
            check_output_folder(path)
    # only looked at: a check never writes to a device
    with pytest.raises(InputError, match="character device"):
        check_output_file(os.devnull)


def test_measure_refuses_a_fifo_and_a_socket_and_leaves_them_alone(fifo, unix_socket, capsys):
    net = os.path.join(os.path.dirname(__file__), "..", "fabplan", "data", "cmc1.obj")
    for path in (fifo, unix_socket):
        assert main(["measure", net, "-o", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "not a regular file" in err[0]
    assert fifo.is_fifo() and unix_socket.is_socket()


def _earlier_study(folder):
    return {"study.json"} if (folder / "study.json").is_file() else None


def test_a_replaced_folder_survives_a_failed_run(tmp_path):
    out = tmp_path / "study"
    out.mkdir()
    (out / "study.json").write_text("earlier")
    with pytest.raises(RuntimeError):
        with output_folder(out, replace=True, owned=_earlier_study) as stage:
            (stage / "study.json").write_text("new")
            raise RuntimeError("candidate failed")
    assert _tree(tmp_path) == ["study", "study/study.json"]
    assert (out / "study.json").read_text() == "earlier"
    with output_folder(out, replace=True, owned=_earlier_study) as stage:
        (stage / "study.json").write_text("new")
    assert _tree(tmp_path) == ["study", "study/.fabplan-files", "study/study.json"]
    assert (out / "study.json").read_text() == "new"


def test_a_folder_of_other_files_is_not_replaced(tmp_path):
    (tmp_path / "mine.txt").write_text("keep")
    with pytest.raises(InputError, match="not empty"):
        with output_folder(tmp_path, replace=True, owned=lambda f: None):
            pass
    assert (tmp_path / "mine.txt").read_text() == "keep"


def test_a_new_output_folder_is_not_created_when_the_run_fails(tmp_path):
    with pytest.raises(ValueError):
        with output_folder(tmp_path / "a" / "b") as stage:
            (stage / "x.txt").write_text("x")
            raise ValueError("bad")
    assert _tree(tmp_path) == []


def test_staging_of_a_killed_run_is_removed_by_the_next_one(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    stale = tmp_path / ".out.staging-0123456789ab"
    stale.mkdir()
    (stale / STAGING_MARKER).write_text(dead)
    (stale / "big.dxf").write_text("x" * 1000)
    alive = tmp_path / ".other.staging-ba9876543210"
    alive.mkdir()
    (alive / STAGING_MARKER).write_text(str(os.getpid()))
    with output_folder(tmp_path / "out") as stage:
        (stage / "x.txt").write_text("x")
    assert not stale.exists() and alive.exists()
    assert (tmp_path / "out" / "x.txt").read_text() == "x"
    assert remove_stale_staging(tmp_path) == []


def test_relative_paths_are_written_in_the_working_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out.txt").write_text("earlier")
    write_texts({"out.txt": "new", "sub/x.txt": "x"})
    assert (tmp_path / "out.txt").read_text() == "new"
    assert (tmp_path / "sub" / "x.txt").read_text() == "x"
    with pytest.raises(InputError, match="is not a folder"):
        check_output_file("out.txt/inside.txt")
