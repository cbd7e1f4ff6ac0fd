"""Shared fixtures: the bundled nets and small generated meshes."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest

import fabplan
from fabplan.net.mesh import QuadMesh


@pytest.fixture(scope="session")
def wein99() -> QuadMesh:
    return QuadMesh.from_obj(fabplan.data_path("wein99.obj"))


@pytest.fixture(scope="session")
def cmc1() -> QuadMesh:
    return QuadMesh.from_obj(fabplan.data_path("cmc1.obj"))


class PipedRun:
    """A `fabplan` command run in a subprocess with its output piped, each output line
    with the time it arrived (seconds from the start)."""

    def __init__(self, argv: list, cwd: str):
        import os
        import subprocess
        import sys
        import time
        from pathlib import Path

        env = dict(os.environ, PYTHONPATH=str(Path(fabplan.__file__).parents[1]),
                   PYTHONUNBUFFERED="1")
        started = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "fabplan.cli", *argv], cwd=cwd, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list = []
        assert proc.stdout is not None
        for line in proc.stdout:
            self.lines.append((time.monotonic() - started, line.rstrip("\n")))
        self.code = proc.wait()
        self.seconds = time.monotonic() - started

    def longest_silence(self) -> float:
        """The longest time without an output line, from the start to the end."""
        times = [0.0] + [t for t, _ in self.lines] + [self.seconds]
        return max(b - a for a, b in zip(times[:-1], times[1:], strict=True))


    @classmethod
    def replayed(cls, record: dict) -> PipedRun:
        """A run as `record` (from `as_record`) keeps it, without running it again."""
        run = cls.__new__(cls)
        run.code, run.seconds = record["code"], record["seconds"]
        run.lines = [(t, line) for t, line in record["lines"]]
        return run

    def as_record(self) -> dict:
        return {"code": self.code, "seconds": self.seconds, "lines": self.lines}


@contextlib.contextmanager
def _locked(path: Path):
    """Holds an exclusive lock on `path` (created) while the block runs."""
    import fcntl

    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _once(tmp_path_factory, name: str, make) -> tuple[Path, dict]:
    """Runs ``make(folder) -> dict`` once per test run, also when pytest-xdist spreads the
    tests over processes: the first process to ask runs it in a folder all of them share
    (the parent of their temporary folders) under a lock, the others wait and read its
    record. Without fcntl (Windows) each process runs it once in its own folder."""
    import json
    import os

    try:
        import fcntl  # noqa: F401
        root = tmp_path_factory.getbasetemp()
        shared = bool(os.environ.get("PYTEST_XDIST_WORKER"))
    except ImportError:
        root, shared = tmp_path_factory.getbasetemp(), False
    folder = (root.parent if shared else root) / f"shared-{name}"
    folder.mkdir(exist_ok=True)
    record = folder / "record.json"
    with _locked(folder / "lock") if shared else contextlib.nullcontext():
        if not record.exists():
            record.write_text(json.dumps(make(folder)), encoding="utf-8")
    return folder, json.loads(record.read_text(encoding="utf-8"))


def _study(tmp_path_factory, name: str, *options: str) -> tuple[Path, PipedRun]:
    """`fabplan study NAME OPTIONS -o FOLDER/study` run once per test run with its output
    piped: (output folder, PipedRun)."""
    def make(folder: Path) -> dict:
        return PipedRun(["study", name, *options, "-o", str(folder / "study")],
                        cwd=str(folder)).as_record()

    folder, record = _once(tmp_path_factory, f"study-{name}", make)
    return folder / "study", PipedRun.replayed(record)


@pytest.fixture(scope="session")
def stadium_study(tmp_path_factory):
    """The stadium template's study, run once per test run with its output piped
    (about 80 s): (output folder, PipedRun). Read only: a test that writes beside its
    files copies the folder first."""
    return _study(tmp_path_factory, "stadium")


@pytest.fixture(scope="session")
def canopy_study(tmp_path_factory):
    """The canopy template's study, run once per test run with its output piped
    (about 40 s): (output folder, PipedRun). Read only, as `stadium_study`."""
    return _study(tmp_path_factory, "canopy")


@pytest.fixture(scope="session")
def tower_study(tmp_path_factory):
    """The tower template's study run quietly (`-q`) once per test run with its output
    piped (about 30 s): (output folder, PipedRun). Read only, as `stadium_study`."""
    return _study(tmp_path_factory, "tower", "-q")


@pytest.fixture(scope="session")
def wein99_molds(tmp_path_factory):
    """`fabplan molds wein99.obj --tolerance-mm 5 -q`, run once per test run (the molds
    report's figures and its 3D view are checked on it): (exit code, output folder).
    Read only."""
    from fabplan.cli import main

    def make(folder: Path) -> dict:
        return {"code": main(["molds", str(fabplan.data_path("wein99.obj")), "--tolerance-mm",
                              "5", "-q", "-o", str(folder / "wein99")])}

    folder, record = _once(tmp_path_factory, "molds-wein99", make)
    return record["code"], folder / "wein99"
