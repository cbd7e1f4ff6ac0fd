"""`fabplan.io.forked.map_in_processes`: batches in forked processes give the results in
order, an error of one batch is raised here with every other process stopped, a batch
whose process died is an error, and an interrupted caller leaves no process running."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
from helpers import process_alive

from fabplan.errors import CannotMakeError
from fabplan.io.forked import map_in_processes

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="forks and reads /proc")

PARENT = os.getpid()


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_batches_come_back_in_order_from_processes_of_their_own():
    results = map_in_processes(_square_and_pid, list(range(7)), 2)
    assert [r[0] for r in results] == [x * x for x in range(7)]
    pids = {r[1] for r in results}
    assert len(pids) == 7 and os.getpid() not in pids
    assert not any(process_alive(p) for p in pids)


class _BatchError(Exception):
    def __init__(self, batch: int, reason: str):     # does not unpickle from its args
        super().__init__(f"batch {batch}: {reason}")
        self.batch = batch


def _slow_or_failing(x: int) -> int:
    if x == 1:
        raise ValueError("batch 1 is bad")
    if x == 2:
        raise _BatchError(2, "worse")
    time.sleep(30.0)
    return x


# an error that does not unpickle comes back as a RuntimeError with its text; where
# tblib's pickling is installed (dask's distributed does), it unpickles as itself
@pytest.mark.parametrize("failing, raised", [(1, ValueError), (2, (RuntimeError, _BatchError))])
def test_an_error_is_raised_here_and_stops_the_other_processes(tmp_path, failing, raised):
    # batch 0 sleeps: its process is stopped, not waited for
    clock = time.monotonic()
    with pytest.raises(raised, match=f"batch {failing}"):
        map_in_processes(_slow_or_failing, [0, failing], 2)
    assert time.monotonic() - clock < 20.0


def _dies_in_a_process(x: int) -> int:
    if x == 1 and os.getpid() != PARENT:
        os.kill(os.getpid(), signal.SIGKILL)
    return 10 * x


def test_a_batch_whose_process_died_is_an_error_naming_the_signal():
    # killed from outside or by the kernel for memory: run here, it might take this
    # process with it
    with pytest.raises(CannotMakeError, match="killed by signal 9"):
        map_in_processes(_dies_in_a_process, [0, 1, 2], 2)


def test_one_process_runs_the_batches_here():
    assert map_in_processes(_square_and_pid, [1, 2], 1) == [(1, PARENT), (4, PARENT)]


def _sleep_and_note(folder: str) -> None:
    (Path(folder) / str(os.getpid())).write_text("")
    time.sleep(60.0)


def test_an_interrupted_caller_leaves_no_process_running(tmp_path):
    # an interrupt arrives while the batches run: the processes are killed at once
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    clock = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            map_in_processes(_sleep_and_note, [str(tmp_path)] * 2, 2)
    finally:
        timer.cancel()
    assert time.monotonic() - clock < 20.0
    pids = [int(p.name) for p in tmp_path.iterdir()]
    assert len(pids) == 2 and not any(process_alive(p) for p in pids)
