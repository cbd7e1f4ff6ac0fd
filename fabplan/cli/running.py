"""How a command runs and ends: its exit code, its progress and warnings on stderr, a bad
input or a failure as one line without a traceback, SIGTERM and SIGHUP as Ctrl-C.

Exit codes: 0 success; 2 bad input or a solver that failed (one-line message, nothing
written); 3 the optimization stopped without converging (result written, with its
measured residuals and status), or some panels fit no mold (`molds`: report written, the
failures listed), or a part goes past a fabrication limit (`fabplan.fabricate.limits`:
files written, the limit and the excess named).
"""

from __future__ import annotations

import argparse
import os
import sys
from contextlib import contextmanager
from typing import Any, Callable, Iterator

from ..errors import CannotMakeError, FabplanError
from ..report.progress import Progress

__all__ = ["EXIT_BAD_INPUT", "EXIT_NOT_CONVERGED", "Stopped", "command_progress", "name_text",
           "one_line", "run_command", "stopped_by_signals", "unparsable", "warn", "warn_after"]

EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3


def warn(message: str | None, quiet: bool = False) -> None:
    if message and not quiet:
        print(f"fabplan: warning: {message}", file=sys.stderr)


def warn_after(args: argparse.Namespace, message: str | None) -> None:
    """A warning printed when the command has run (`run_command`): a refusal on the way
    comes alone, without a warning before it."""
    if message:
        args.warnings_after = [*getattr(args, "warnings_after", []), message]


def command_progress(args) -> Progress:
    """The run's progress output (`fabplan.report.progress`): a live line on a terminal,
    a line per stage and every few seconds off one; -q none, -v the solver's iterations."""
    return Progress(sys.stderr, quiet=getattr(args, "quiet", False),
                    verbose=getattr(args, "verbose", False))


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP: the run stops as at Ctrl-C, cleaning up what it staged."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


@contextmanager
def stopped_by_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP raise `Stopped` in the main thread while the command runs, so
    that they leave nothing behind, as Ctrl-C does; once one of them (or Ctrl-C) has come,
    the others are ignored, so that the cleanup runs to its end. A signal the process was
    started with ignored (``nohup``) stays ignored. The handlers before are restored."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    names = [s for s in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, s)]
    wanted = [n for n in names if signal.getsignal(getattr(signal, n)) is not signal.SIG_IGN]

    def stop(signum: int, frame: Any) -> None:
        for name in wanted:                 # the cleanup is not interrupted again
            signal.signal(getattr(signal, name), signal.SIG_IGN)
        raise KeyboardInterrupt if signum == signal.SIGINT else Stopped(signum)

    before = {name: signal.signal(getattr(signal, name), stop) for name in wanted}
    try:
        yield
    finally:
        for name, handler in before.items():
            signal.signal(getattr(signal, name), handler)


def one_line(message: str) -> str:
    """A message on one line: a line break or other control character that came in with a
    name the user gave is shown as its escape (``\\n``).

    Examples
    --------
    >>> one_line("a\\nb.obj: no such file")
    'a\\\\nb.obj: no such file'
    """
    if message.isprintable():
        return message
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def name_text(name: object) -> str:
    """A file name for a one-line message: as given when printable, else quoted with its
    escapes (a line break in it), shortened past 200 characters."""
    text = os.fsdecode(name) if isinstance(name, (str, bytes, os.PathLike)) else str(name)
    if not text.isprintable():
        text = repr(text)
    return text if len(text) <= 200 else text[:197] + "..."


def unparsable(argv: list[str]) -> str | None:
    """Why an argument cannot be parsed as fabplan means it, or None: a NUL character (no
    shell passes one, a caller in Python can), or ``--`` given as an option's value
    (``--units=--``, ``-o--``), which argparse drops, handing the command an empty list
    (no option takes ``--``; a file of that name is ``./--``)."""
    for arg in map(str, argv):
        if "\x00" in arg:
            return f"{one_line(name_text(arg))}: an argument cannot hold a NUL character"
        if arg.startswith("-") and arg != "--" and (
                arg.endswith("=--") or (arg[1:2] != "-" and arg[2:] == "--")):
            return (f"{one_line(name_text(arg))}: '--' is no value of an option (a file "
                    "named '--' is ./--)")
    return None


def run_command(run: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command (`fabplan.cli.registry.Command.run`) on its parsed arguments and
    return its exit code: its warnings after it, a failure as one line on stderr."""
    try:
        if getattr(args, "ifc", False):      # before any work: is IfcOpenShell there?
            from ..io.ifc import ifcopenshell_module

            ifcopenshell_module()
        with stopped_by_signals():
            code = run(args)
        for message in getattr(args, "warnings_after", []):
            warn(message, getattr(args, "quiet", False))
        return code
    except CannotMakeError as exc:
        # the input is sound; what was asked cannot be made from it as it stands
        print(f"fabplan: cannot make it: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    except FabplanError as exc:
        print(f"fabplan: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Stopped as exc:
        import signal

        print(f"fabplan: stopped by {signal.Signals(exc.signum).name}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("fabplan: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (e.g. `| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except MemoryError:
        print("fabplan: error: out of memory: use a larger panel size or a smaller net "
              "(--max-panels sets the limit that is checked up front)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        # a file system failure while writing (disk full, a vanished folder): outputs are
        # staged, so nothing half-written is left; say what failed in one line
        where = f"{name_text(exc.filename)}: " if exc.filename else ""
        print(f"fabplan: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
