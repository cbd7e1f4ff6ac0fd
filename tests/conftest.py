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


@pytest.fixture(scope="session")
def stadium_study(tmp_path_factory):
    """The stadium template's study, run once per session with its output piped
    (about 45-60 s): (output folder, PipedRun)."""
    folder = tmp_path_factory.mktemp("stadium")
    out = folder / "study"
    run = PipedRun(["study", "stadium", "-o", str(out)], cwd=str(folder))
    return out, run
