"""One worker thread per editing session: commands run in the order they came, one at a
time, and drags that wait for a running solve are coalesced (the latest wins).

A drag arriving while a solve runs takes the place of a drag still waiting, so that at
most one drag waits: the net follows the pointer's latest position and never works off a
backlog. Every request that was coalesced gets the result of the drag that replaced it.
"""

from __future__ import annotations

import threading
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = ["CommandQueue"]


@dataclass
class _Job:
    run: Callable[[], Any]
    coalesce: str | None                      # jobs of one key replace each other while waiting
    futures: list[Future] = field(default_factory=list)


class CommandQueue:
    """Run callables on one worker thread, in order.

    Parameters
    ----------
    name : the worker thread's name.

    Examples
    --------
    >>> import threading
    >>> queue = CommandQueue()
    >>> gate = threading.Event()
    >>> first = queue.submit(gate.wait)                 # holds the worker
    >>> a = queue.submit(lambda: "a", coalesce="drag")
    >>> b = queue.submit(lambda: "b", coalesce="drag")  # replaces the waiting a
    >>> _ = gate.set()
    >>> a.result(), b.result(), queue.ran
    ('b', 'b', 2)
    >>> queue.close()
    """

    def __init__(self, name: str = "fabplan-edit") -> None:
        self._jobs: deque[_Job] = deque()
        self._wake = threading.Condition()
        self._closed = False
        self.ran = 0            # jobs run (coalesced ones count once)
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def submit(self, run: Callable[[], Any], *, coalesce: str | None = None) -> Future:
        """Queue `run`; with a `coalesce` key it replaces a job of that key still waiting
        at the end of the queue. Returns a future of its result."""
        future: Future = Future()
        with self._wake:
            if self._closed:
                future.set_exception(RuntimeError("the editing session has ended"))
                return future
            last = self._jobs[-1] if self._jobs else None
            if coalesce is not None and last is not None and last.coalesce == coalesce:
                last.run = run
                last.futures.append(future)
            else:
                self._jobs.append(_Job(run, coalesce, [future]))
            self._wake.notify()
        return future

    def _work(self) -> None:
        while True:
            with self._wake:
                while not self._jobs and not self._closed:
                    self._wake.wait()
                if not self._jobs:
                    return
                job = self._jobs.popleft()
            try:
                value = job.run()
            except BaseException as exc:   # handed to the waiting requests, not lost
                self.ran += 1
                for f in job.futures:
                    f.set_exception(exc)
            else:
                self.ran += 1
                for f in job.futures:
                    f.set_result(value)

    def close(self, timeout: float | None = 30.0) -> None:
        """Refuse new jobs, cancel those waiting, let the running one finish and end the
        thread."""
        with self._wake:
            self._closed = True
            waiting = list(self._jobs)
            self._jobs.clear()
            self._wake.notify_all()
        for job in waiting:
            for f in job.futures:
                f.set_exception(RuntimeError("the editing session has ended"))
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
