"""Shared fixtures: the bundled nets and small generated meshes."""

from __future__ import annotations

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


#: the session's shared runs: every test that reads one runs in the same process
#: (`--dist loadgroup` of pytest-xdist), so that each runs once per test run
STUDY_FIXTURES = ("stadium_study", "canopy_study", "tower_study", "wein99_molds")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    # before pytest-xdist turns the group into the node id's suffix
    for item in items:
        for name in STUDY_FIXTURES:
            if name in getattr(item, "fixturenames", ()):
                item.add_marker(pytest.mark.xdist_group(name))


@pytest.fixture(scope="session")
def stadium_study(tmp_path_factory):
    """The stadium template's study, run once per session with its output piped
    (about 80 s): (output folder, PipedRun). Read only: a test that writes beside its
    files copies the folder first."""
    folder = tmp_path_factory.mktemp("stadium")
    out = folder / "study"
    run = PipedRun(["study", "stadium", "-o", str(out)], cwd=str(folder))
    return out, run


@pytest.fixture(scope="session")
def canopy_study(tmp_path_factory):
    """The canopy template's study, run once per session with its output piped
    (about 40 s): (output folder, PipedRun). Read only, as `stadium_study`."""
    folder = tmp_path_factory.mktemp("canopy")
    out = folder / "study"
    run = PipedRun(["study", "canopy", "-o", str(out)], cwd=str(folder))
    return out, run


@pytest.fixture(scope="session")
def tower_study(tmp_path_factory):
    """The tower template's study run quietly (`-q`) once per session with its output
    piped (about 30 s): (output folder, PipedRun). Read only, as `stadium_study`."""
    folder = tmp_path_factory.mktemp("tower")
    out = folder / "study"
    run = PipedRun(["study", "tower", "-q", "-o", str(out)], cwd=str(folder))
    return out, run


@pytest.fixture(scope="session")
def wein99_molds(tmp_path_factory):
    """`fabplan molds wein99.obj --tolerance-mm 5 -q`, run once per session (the molds
    report's figures and its 3D view are checked on it): (exit code, output folder).
    Read only."""
    from fabplan.cli import main

    out = tmp_path_factory.mktemp("molds") / "wein99"
    code = main(["molds", str(fabplan.data_path("wein99.obj")), "--tolerance-mm", "5", "-q",
                 "-o", str(out)])
    return code, out
