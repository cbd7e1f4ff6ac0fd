"""Work done in a forked copy of the process, on another core, while the caller goes on.

May import: `fabplan.errors` only. A bare `os.fork` that leaves by `os._exit`: the child runs
none of the parent's exit handlers and writes nothing to the parent's streams. Elsewhere
than on Linux, or on one core, nothing is forked.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import CannotMakeError

__all__ = ["ForkedFile", "forked_processes", "die_with_parent", "map_in_processes",
           "worker_start", "quiet_interrupts"]

_PR_SET_PDEATHSIG = 1     # prctl(2): the signal a process gets when its parent ends


def die_with_parent(parent: int) -> None:
    """Make this process (a worker or forked child of `parent`) end when its parent
    does, so that a parent killed with SIGKILL leaves no worker running.

    On Linux the kernel sends SIGKILL (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon
    thread checks every second whether the parent is still there. A parent that is
    already gone ends this process at once.
    """
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass
    else:
        import time

        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(1.0)
            os._exit(1)

        threading.Thread(target=watch, daemon=True, name="fabplan-parent-watch").start()
    if os.getppid() != parent:
        os._exit(1)


def forked_processes(processes: int | None = None) -> int:
    """How many forked processes may work at once: one per core (`processes` when
    given), none but on Linux or on one core."""
    if not sys.platform.startswith("linux"):
        return 0
    count = (os.cpu_count() or 1) if processes is None else processes
    return count if count > 1 else 0


def worker_start(parent: int) -> None:
    """What a worker process does first: end with `parent` (`die_with_parent`), leave
    Ctrl-C to the parent (which stops the workers) and end at SIGTERM or SIGHUP without a
    traceback."""
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)


def map_in_processes(function: Callable, batches: list, processes: int) -> list:
    """``[function(b) for b in batches]`` in at most `processes` forked processes, in order.

    Each batch runs in a process forked for it: it inherits the batch (nothing is pickled
    on the way in) and sends back its result, or the error it raised, pickled in a file.
    No pool and no lock is shared with the processes, so stopping them never waits on
    one (``multiprocessing.Pool.terminate`` can: for a lock a stopped worker held).
    Elsewhere than on Linux (see `forked_processes`) the batches run here, in turn.

    Parameters
    ----------
    function : called with each batch; its result must pickle.
    batches : the batches (anything: they are inherited, not pickled).
    processes : how many processes may run at once.

    Returns
    -------
    list, ``function(batch)`` of every batch, in the order of `batches`.

    Raises
    ------
    Exception
        The first error a batch raised, as soon as its batch ends, the other processes
        killed (an error that does not unpickle comes back as a RuntimeError with its
        text). When this process is interrupted (Ctrl-C, or SIGTERM as `fabplan.cli`
        turns it into an error), the processes are killed at once and the interrupt
        goes on.
    CannotMakeError
        A process ended without its result: killed (out of memory, say) or crashed.
    """
    if not forked_processes(processes):
        return [function(b) for b in batches]
    with tempfile.TemporaryDirectory(prefix="fabplan-batches-") as folder:
        batch_run = _ForkedBatches(function, batches, Path(folder))
        try:
            for k in range(len(batches)):
                while len(batch_run.running) >= processes:
                    batch_run.reap_one()
                batch_run.start(k)
            while batch_run.running:
                batch_run.reap_one()
        except BaseException:
            batch_run.kill()
            raise
        return batch_run.results


class _ForkedBatches:
    """The processes of one `map_in_processes` call: started, reaped as they end, killed."""

    def __init__(self, function: Callable, batches: list, folder: Path) -> None:
        self.function, self.batches, self.folder = function, batches, folder
        self.results: list = [None] * len(batches)
        self.running: dict[int, tuple[int, int]] = {}   # read end of its pipe -> (pid, batch)
        self.ends = select.poll()
        self.parent = os.getpid()
        # an interrupt between a fork and the child's entry in `running` would leave the
        # child unstopped: the signals wait until it is entered
        self.interrupts = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                           if hasattr(signal, n)}

    def path(self, k: int) -> Path:
        return self.folder / f"{k}.pickle"

    def start(self, k: int) -> None:
        """Fork the process of batch `k` (or run it here when no process can be forked)."""
        ends, end = os.pipe()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, self.interrupts)
        try:
            pid = os.fork()
            if pid == 0:
                code = 1
                try:
                    os.close(ends)
                    worker_start(self.parent)
                    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
                    _send(self.function, self.batches[k], self.path(k))
                    code = 0
                finally:
                    os._exit(code)
            self.running[ends] = (pid, k)
            self.ends.register(ends, select.POLLIN | select.POLLHUP)
        except OSError:                        # no process to spare: the batch runs here
            os.close(ends)
            self.results[k] = self.function(self.batches[k])
        finally:
            if os.getpid() == self.parent:
                os.close(end)
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)

    def reap_one(self) -> None:
        """Take in the first process to end (a process's end of its pipe closes when it
        ends); raise its error, or `CannotMakeError` when it ended without a result."""
        ends = self.ends.poll()[0][0]
        self.ends.unregister(ends)
        pid, k = self.running.pop(ends)
        os.close(ends)
        _, status = os.waitpid(pid, 0)
        code = os.waitstatus_to_exitcode(status)
        if code != 0 or not self.path(k).is_file():
            how = f"was killed by signal {-code}" if code < 0 else f"ended with code {code}"
            raise CannotMakeError(f"a worker process {how} before its batch was done (out of "
                                  "memory?); run again with fewer workers")
        failed, value = pickle.loads(self.path(k).read_bytes())
        if failed:
            raise value
        self.results[k] = value

    def kill(self) -> None:
        """Kill every process still running, at once."""
        for ends, (pid, _) in self.running.items():
            os.close(ends)
            try:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
        self.running = {}


def _send(function: Callable, batch: object, path: Path) -> None:
    """What a process of `map_in_processes` does: ``function(batch)``, or the error it
    raised (as a plain one when it does not unpickle), written to `path` whole."""
    try:
        message = (False, function(batch))
    except Exception as exc:          # noqa: BLE001 - sent back to be raised by the parent
        message = (True, exc)
    try:
        data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        if message[0]:
            pickle.loads(data)        # an error class may pickle and not unpickle
    except Exception as exc:          # noqa: BLE001 - sent back as a plain error
        data = pickle.dumps((True, RuntimeError(f"{type(message[1]).__name__}: {message[1]}"
                                                if message[0] else
                                                f"a result that does not pickle: {exc}")))
    part = path.with_suffix(".part")
    part.write_bytes(data)
    os.replace(part, path)


@contextmanager
def quiet_interrupts() -> Iterator[None]:
    """Start processes inside this block with Ctrl-C ignored (they keep it across exec):
    the parent stops them, and no traceback of theirs reaches the terminal."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)


class ForkedFile:
    """One file written by `write(path)` in a forked process while the caller goes on
    (the study's PDF report beside its HTML report): `finish` waits for it, `cancel`
    stops it when the caller failed.

    The file is written beside `path` and renamed, so `path` is whole or absent; where
    nothing is forked (see `forked_processes`, or the fork fails), or the child
    failed, `finish` writes the file in this process.
    """

    def __init__(self, write: Callable[[Path], None], path: Path) -> None:
        self.write, self.path = write, Path(path)
        self._part = self.path.with_name(self.path.name + ".part")
        self._pid: int | None = None
        parent = os.getpid()
        if forked_processes():
            try:
                self._pid = os.fork()
            except OSError:          # no process to spare: written by `finish`
                self._pid = None
        if self._pid == 0:
            code = 1
            try:
                die_with_parent(parent)
                sys.stdout = sys.stderr = open(os.devnull, "w")
                self._write_whole()
                code = 0
            finally:
                os._exit(code)

    def _write_whole(self) -> None:
        self.write(self._part)
        os.replace(self._part, self.path)

    def finish(self) -> None:
        """Wait for the child; write the file here when it did not."""
        if self._pid is not None:
            pid, self._pid = self._pid, None
            _, status = os.waitpid(pid, 0)
            if os.waitstatus_to_exitcode(status) == 0 and self.path.is_file():
                return
        self._part.unlink(missing_ok=True)
        self._write_whole()

    def cancel(self) -> None:
        """Stop the child and remove what it wrote (the caller failed)."""
        if self._pid is not None:
            pid, self._pid = self._pid, None
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)
        self._part.unlink(missing_ok=True)
