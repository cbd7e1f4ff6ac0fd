"""Studies run in parallel: local processes or a Dask cluster, the serial result bit for
bit (apart from timings), failures recorded, a killed worker's candidates retried."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import interruptible, without_timings

from fabplan.cli import main
from fabplan.errors import InputError
from fabplan.study.parallel import worker_count

pytest.importorskip("distributed")

# a saddle with a twin (CMC ends at the minimal net) and a candidate that fails
STUDY = """\
[study]
name = "Parallel test"
max_iterations = 80

[design]
surface = "hyperbolic-paraboloid"
parameters = { width = 4, depth = 4, rise = 1.2 }
triangles = 4000

[panels]
size = 0.7

[limits]
max_deviation_mm = 200
mold_tolerance_mm = 1.5

[strips]
height_mm = 60
thickness_mm = 3
sheet_mm = [1200, 600]

[[candidates]]
net = "isogonal"
angle = 80

[[candidates]]
net = "minimal"

[[candidates]]
net = "cmc"

[[candidates]]
net = "const-radius"
radius = 0.01
"""


def _record(folder: Path) -> dict:
    return without_timings(json.loads((folder / "study.json").read_text(encoding="utf-8")))


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("parallel")
    (folder / "small.toml").write_text(STUDY, encoding="utf-8")
    assert main(["study", str(folder / "small.toml"), "-o", str(folder / "serial"), "-q"]) == 0
    return folder, _record(folder / "serial")


def test_worker_counts_are_checked():
    assert worker_count("auto") == (os.cpu_count() or 1)
    assert worker_count("3") == 3
    for bad in ("0", "x", "-2"):
        with pytest.raises(InputError, match="--workers"):
            worker_count(bad)


def test_local_workers_leave_nothing_in_the_temporary_folder(tmp_path, monkeypatch):
    """The local cluster's scratch space and its lock files are the study's own, removed
    with the workers (Dask's default leaves ``dask-scratch-space`` in the system's
    temporary folder)."""
    import socket
    import tempfile
    import warnings

    from fabplan.study.parallel import dask_client

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with socket.socket() as taken, warnings.catch_warnings(record=True) as said:
        # the scheduler's HTTP port held by another study: nor a warning on the terminal
        warnings.simplefilter("always")
        with contextlib.suppress(OSError):              # held by one already
            taken.bind(("127.0.0.1", 8787))
            taken.listen()
        with dask_client(1) as client:
            assert client.submit(sum, [1, 2]).result() == 3
            assert len(list(tmp_path.iterdir())) == 1       # its scratch folder, while it runs
    assert list(tmp_path.iterdir()) == []
    assert not [w for w in said if "already in use" in str(w.message)]


@pytest.mark.slow
def test_local_workers_give_the_serial_study(serial, capsys):
    folder, expected = serial
    assert main(["study", str(folder / "small.toml"), "-o", str(folder / "local"),
                 "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "5 of 5 measured" in err and "1 failed" in err
    record = _record(folder / "local")
    assert record == expected
    names = {c["name"]: c for c in record["candidates"]}
    assert names["cmc"]["same_net_as"] == "minimal"
    assert "smaller than half the edges" in names["const-radius-r0.01"]["error"]


def _start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(args, stdout=log.open("w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


@pytest.mark.slow
def test_a_dask_cluster_survives_a_killed_worker(serial, tmp_path):
    """A real scheduler and two workers on loopback, the second joining after the study has
    started; the first is killed with SIGKILL while the candidates run: its tasks, and the
    study and design they read, are computed again on the other, and the study is the
    serial one."""
    folder, expected = serial
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler_file = tmp_path / "scheduler.json"
    procs = [_start(dask + ["--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                            "--scheduler-file", str(scheduler_file)], tmp_path / "scheduler.log")]
    try:
        for _ in range(200):
            if scheduler_file.is_file() and scheduler_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]

        def worker(k: int) -> subprocess.Popen:
            return _start([sys.executable, "-m", "distributed.cli.dask_worker", address,
                           "--nthreads", "1", "--no-dashboard", "--name", f"w{k}"],
                          tmp_path / f"worker{k}.log")

        procs.append(worker(0))
        for _ in range(300):
            if "Registered to" in (tmp_path / "worker0.log").read_text(errors="replace"):
                break
            time.sleep(0.1)
        study = subprocess.Popen(
            [sys.executable, "-m", "fabplan.cli", "study", str(folder / "small.toml"), "-o",
             str(tmp_path / "cluster"), "--scheduler", address],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = study.stderr.readline()           # the study has connected and submitted
        procs.append(worker(1))
        # kill the first worker once the first candidates are solved (it holds the inputs,
        # tasks and results)
        line = ""
        while "of 5 solved" not in line and study.poll() is None:
            line = study.stderr.readline()
        os.killpg(procs[1].pid, signal.SIGKILL)
        out, err = study.communicate(timeout=600)
        assert study.returncode == 0, err
        assert _record(tmp_path / "cluster") == expected
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait()


@pytest.mark.slow
def test_an_unreachable_scheduler_is_one_line(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(STUDY, encoding="utf-8")
    code = main(["study", str(tmp_path / "small.toml"), "-o", str(tmp_path / "out"),
                 "--scheduler", "tcp://127.0.0.1:9", "-q"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot connect" in err[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_an_interrupted_study_resumes_with_only_the_missing_candidates(serial, tmp_path):
    """Ctrl-C after two candidates of a --resume run: the folder keeps an earlier study
    intact and the two finished candidates; --resume computes the other three and gives
    the serial study."""
    folder, expected = serial
    out = tmp_path / "out"
    out.mkdir()
    (out / "study.json").write_text('{"earlier": true}', encoding="utf-8")
    run = subprocess.Popen([sys.executable, "-m", "fabplan.cli", "study",
                            str(folder / "small.toml"), "-o", str(out), "--resume"],
                           stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
    for line in run.stderr:
        if line.startswith("[3/5]"):
            run.send_signal(signal.SIGINT)
            break
    run.communicate(timeout=300)
    assert run.returncode != 0
    assert json.loads((out / "study.json").read_text()) == {"earlier": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]      # nothing beside it
    assert len(list((out / ".fabplan-cache").glob("*.json"))) == 2
    resumed = subprocess.run([sys.executable, "-m", "fabplan.cli", "study",
                              str(folder / "small.toml"), "-o", str(out), "--resume"],
                             capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stderr.count("taken from the cache") == 2
    assert resumed.stderr.count("] ") - resumed.stderr.count("taken from the cache") == 3
    assert _record(out) == expected


@pytest.mark.slow
def test_an_impossible_baseline_on_workers_is_one_line(tmp_path):
    """Regression: the baseline layout runs on a worker; its refusal was raised there and
    the worker logged its traceback on the terminal beside the one-line message."""
    text = STUDY.replace("size = 0.7", "size = 3.9")
    (tmp_path / "big.toml").write_text(text, encoding="utf-8")
    run = subprocess.run([sys.executable, "-m", "fabplan.cli", "study", str(tmp_path / "big.toml"),
                          "-o", str(tmp_path / "out"), "--workers", "1", "-q"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2
    assert "Traceback" not in run.stderr, run.stderr
    assert "distributed" not in run.stderr, run.stderr       # nor Dask's own warnings
    assert "too large for the surface" in run.stderr
    assert not (tmp_path / "out").exists()
