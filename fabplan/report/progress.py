"""Progress of a long run, in one style for every command.

On a terminal a stage shows one live line: its name, a bar with the percentage and the
time left when its size is known, else the time spent. Off a terminal (a pipe, a log
file, CI) a stage that runs longer than `Progress.delay` prints a line then, one when it
ends, and one at least every `Progress.interval` seconds in between, so that a log shows
the run is alive and where it is; a quick stage prints nothing (a command that fails at
once prints its one-line error alone). ``quiet`` prints nothing but the final summary
(errors are the caller's); ``verbose`` adds the solver's iterations.

A small module of our own rather than tqdm or rich: both draw one line with carriage
returns, which a pipe records as a single growing line or not at all until the end, and
neither prints anything while a step without callbacks runs (a layout, a nesting). The
heartbeat thread here does; it needs no dependency.

Usage::

    progress = Progress(sys.stderr, quiet=args.quiet, verbose=args.verbose)
    with progress.stage("nesting parts", total=len(parts)) as stage:
        for part in parts:
            ...
            stage.advance()
    progress.summary("42 parts on 3 sheets")
"""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator, TextIO

__all__ = ["Progress", "Stage", "format_seconds"]


def format_seconds(seconds: float) -> str:
    """A duration for people: ``8 s``, ``2 min 05 s``, ``1 h 03 min``.

    Examples
    --------
    >>> format_seconds(8.2), format_seconds(125), format_seconds(3790)
    ('8 s', '2 min 05 s', '1 h 03 min')
    """
    s = int(round(max(seconds, 0.0)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


class Stage:
    """A running stage: `advance` it by steps of a known `total`, or `note` what it does."""

    def __init__(self, progress: "Progress", name: str, total: int | None):
        self.progress = progress
        self.name = name
        self.total = total
        self.done = 0
        self.detail = ""
        self.started = time.monotonic()
        self.shown = False           # its start line is printed (off a terminal)

    def advance(self, steps: int = 1, detail: str | None = None) -> None:
        """`steps` more of `total` are done; `detail` says what (shown with the next line)."""
        self.done += steps
        if detail is not None:
            self.detail = detail
        self.progress._tick()

    def note(self, detail: str) -> None:
        """What the stage is doing now (shown with its next line)."""
        self.detail = detail
        self.progress._tick()

    def status(self, now: float) -> str:
        spent = now - self.started
        text = self.name
        if self.total:
            share = min(self.done / self.total, 1.0)
            text += f" {self.done}/{self.total} ({100 * share:.0f} %"
            if 0 < share < 1:
                text += f", about {format_seconds(spent * (1 - share) / share)} left"
            text += ")"
        text += f", {format_seconds(spent)}"
        if self.detail:
            text += f": {self.detail}"
        return text


class Progress:
    """Progress output of one command run.

    Parameters
    ----------
    stream : where the lines go (standard error: standard output keeps the results).
    terminal : draw a live line (True) or print lines (False); default: whether `stream`
        is a terminal.
    quiet : print nothing but `summary` lines.
    verbose : also print `iteration` lines (the solver's).
    interval : seconds between the lines of a running stage off a terminal (at most 5 s
        between lines is the promise; the default leaves a margin for a busy machine).
    delay : seconds a stage runs before it prints its first line off a terminal.
    """

    def __init__(self, stream: TextIO | None = None, *, terminal: bool | None = None,
                 quiet: bool = False, verbose: bool = False, interval: float = 3.0,
                 delay: float = 1.0):
        self.stream = sys.stderr if stream is None else stream
        if terminal is None:
            isatty = getattr(self.stream, "isatty", None)
            terminal = bool(isatty and isatty())
        self.terminal = terminal
        self.quiet = quiet
        self.verbose = verbose and not quiet
        self.interval = interval
        self.delay = delay
        self._stages: list[Stage] = []
        self._lock = threading.RLock()
        self._last_line = time.monotonic()
        self._live = False                  # a live line is on the terminal
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.started = time.monotonic()

    # ------------------------------------------------------------------ output
    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):      # a closed pipe must not stop the work
            pass

    def _clear_live(self) -> None:
        if self._live:
            self._write("\r\033[K")
            self._live = False

    def line(self, message: str) -> None:
        """A line of progress (not in quiet mode)."""
        if self.quiet:
            return
        with self._lock:
            self._clear_live()
            self._write(message + "\n")
            self._last_line = time.monotonic()
            self._draw_live()

    def iteration(self, message: str) -> None:
        """A solver iteration: printed only when verbose."""
        if self.verbose:
            self.line("    " + message)
        else:
            self._tick()

    def summary(self, message: str) -> None:
        """The final summary: printed even when quiet."""
        with self._lock:
            self._clear_live()
            self._write(message + "\n")

    def say(self) -> Callable[[str], None]:
        """`line` as a plain callback, for APIs that take ``progress(message)``."""
        return self.line

    # ------------------------------------------------------------------ stages
    @contextmanager
    def stage(self, name: str, total: int | None = None) -> Iterator[Stage]:
        """Run a stage: while it runs a live line (on a terminal), or (off one, once it
        has run `delay` seconds) a line, then one every `interval` seconds and one at its
        end."""
        stage = Stage(self, name, total)
        with self._lock:
            self._stages.append(stage)
        self._start_thread()
        ok = False
        try:
            yield stage
            ok = True
        finally:
            with self._lock:
                self._stages.remove(stage)
            spent = format_seconds(time.monotonic() - stage.started)
            if ok and (stage.shown or self.terminal):
                self.line(f"{name}: done in {spent}")
            else:
                with self._lock:
                    self._clear_live()
            if not self._stages:
                self._stop_thread()

    def _status(self) -> str:
        now = time.monotonic()
        return " > ".join(s.status(now) for s in self._stages)

    def _draw_live(self) -> None:
        if not (self.terminal and self._stages) or self.quiet:
            return
        stage = self._stages[-1]
        bar = ""
        if stage.total:
            filled = int(20 * min(stage.done / stage.total, 1.0))
            bar = "[" + "#" * filled + "-" * (20 - filled) + "] "
        self._write("\r\033[K" + bar + self._status()[:150])
        self._live = True

    def _tick(self) -> None:
        """Something moved: redraw the live line (on a terminal)."""
        if self.terminal and not self.quiet:
            with self._lock:
                self._draw_live()

    def _heartbeat(self) -> None:
        while not self._stop.wait(0.5 if self.terminal else 0.25):
            with self._lock:
                if not self._stages or self.quiet:
                    continue
                now = time.monotonic()
                if self.terminal:
                    self._draw_live()
                    continue
                due = now - self._last_line >= self.interval
                for stage in self._stages:
                    if not stage.shown and (due or now - stage.started >= self.delay):
                        stage.shown = True
                        self.line(f"{stage.name} ...")
                        due = False
                if due:
                    self.line("  ... " + self._status())

    def _start_thread(self) -> None:
        if self._thread is None and not self.quiet:
            self._stop.clear()
            self._thread = threading.Thread(target=self._heartbeat, name="fabplan-progress",
                                            daemon=True)
            self._thread.start()

    def _stop_thread(self) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            thread.join()
