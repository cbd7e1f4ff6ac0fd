"""A serial study's candidates measured in forked processes beside the next solves.

A serial run (`fabplan.study.run.run_study`) keeps one core busy. Once a candidate's net
is solved, what remains of it (molds, strips, measurements: `fabricate_candidate`; and
its files, `fabplan.study.report.candidate_file_bytes`) needs nothing the next candidates
change, so a forked copy of the process does it on another core while the run solves the
next candidates, as the workers of a parallel run do (`fabplan.study.parallel`). The fork
inherits the candidate as it is: nothing is pickled on the way in; what comes back is the
measured candidate without its net and layout (the run holds those), the progress lines,
and the files.

The child is a bare `os.fork` that leaves by `os._exit`: it runs none of the parent's
exit handlers and writes nothing to the parent's streams (a progress thread of the parent
may hold their locks at the fork). Elsewhere than on Linux, or on one core, nothing is
forked and the run measures every candidate itself; so it does for a candidate whose
process died. `fabplan.io.forked.ForkedFile` draws one file the same way (the study's PDF
report, while the HTML report is written).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import shutil
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable

import numpy as np

from ..errors import FabplanError
from ..io.forked import die_with_parent, forked_processes

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from .definition import Study
    from .result import CandidateResult

__all__ = ["BackgroundCandidates", "background_processes", "BACKGROUND_NICENESS"]

#: how much lower the measuring processes run than the run's own solves (`os.nice`)
BACKGROUND_NICENESS = 10

#: how often a run waiting for its round's candidates looks for a free process to measure
#: a solve ahead (seconds)
_POLL_SECONDS = 0.02


def background_processes(processes: int | None = None) -> int:
    """How many candidates are measured at once beside a serial run: one per core
    (`processes` when given), none but on Linux or on one core."""
    return forked_processes(processes)


def _warm_up(files: bool) -> None:
    """Import here what every forked process needs, and draw a text (loading the font),
    so that the processes inherit them instead of loading them each."""
    from ..fabricate.molds import boundary_molds, mold_assignment, mold_plan  # noqa: F401
    from ..fabricate.strips import strip_plan  # noqa: F401

    if files:
        from ..fabricate.molds import mold_report  # noqa: F401
        from ..fabricate.strips import dxf  # noqa: F401
        from ..report import figures
        from . import report  # noqa: F401

        fig = figures.new_figure((1, 1))
        fig.text(0.5, 0.5, "0")
        figures.png_bytes(fig)


@dataclass(eq=False)
class _Job:
    solved: CandidateResult
    twin: CandidateResult | None
    pid: int
    path: Path
    seconds: float          # the candidate's solve
    ahead: bool = False     # measured ahead of its round, not taken by it (yet)
    status: int = 0         # how its process ended (`os.waitpid`), once it has


def _measure(study: Study, design: DesignSurface, solved: CandidateResult,
             twin: CandidateResult | None, files: bool, rhino: bool,
             twin_files: dict[str, bytes] | None = None, ifc: bool = False) -> tuple:
    """What the forked process sends back: (measured candidate without net and layout or
    None, why it failed or None, progress lines, files or None, seconds). `twin_files`:
    the files made for `twin`, whose strip files a candidate sharing its strips copies."""
    from .candidate_measure import fabricate_candidate
    from .report import candidate_file_bytes
    from .run import failure_reason

    clock = time.perf_counter()
    lines: list[str] = []
    try:
        result = fabricate_candidate(study, design, solved, twin, lines.append)
    except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        return None, failure_reason(exc), lines, None, time.perf_counter() - clock
    made = None
    shares_strips = result.twin is not None and result.strips is not None
    # without the twin's files, `write_study` copies the shared strips from its folder
    if files and (twin_files is not None or not shares_strips):
        made = candidate_file_bytes(result, study, design,
                                    twin_files if shares_strips else None, rhino=rhino, ifc=ifc)
    return (replace(result, net=None), None, lines, made,
            time.perf_counter() - clock)


class BackgroundCandidates:
    """Solved candidates measured in forked processes, at most `processes` at once.

    `submit` a solved candidate (with its twin, complete: `complete`); `collect` waits for
    the last ones. The files of the candidates (with `files`) come back in `made_files`;
    `done` is called with every candidate as it is measured.

    A candidate solved ahead of its round (`fabplan.study.run`) may be measured ahead too
    (`measure_ahead`), in a process that is free while the round before ends: its result
    is kept apart, and taken when its round submits that very solve; `drop_ahead` stops
    those no round took. Measuring is deterministic, so a result taken is the one the
    round would have made.
    """

    def __init__(self, study: Study, design: DesignSurface, say: Callable[[str], None], *,
                 processes: int | None = None, files: bool = False, rhino: bool = False,
                 ifc: bool = False,
                 done: Callable[[CandidateResult], None] | None = None):
        self.study, self.design, self.say, self.done = study, design, say, done
        self.files, self.rhino, self.ifc = files, rhino, ifc
        self.processes = background_processes(processes)
        self.made_files: dict[str, tuple] = {}
        self._running: list[_Job] = []
        self._queued: list[CandidateResult] = []        # solves to measure ahead
        self._finished_ahead: list[_Job] = []
        self._done: dict[str, CandidateResult] = {}
        self._folder: tempfile.TemporaryDirectory | None = None
        self._count = 0
        if self.active:
            _warm_up(files)

    @property
    def active(self) -> bool:
        """Whether candidates are measured here (else the run measures them itself)."""
        return self.processes > 0

    def submit(self, solved: CandidateResult, twin: CandidateResult | None,
               seconds: float = 0.0) -> None:
        """Measure `solved` (whose solve took `seconds`) in a forked process once one is
        free; `twin` is the earlier candidate it ended at the same net as, measured. A
        measuring of this very solve begun ahead (`measure_ahead`) is taken instead when
        it had no twin either."""
        self._queued = [q for q in self._queued if q is not solved]
        for job in [j for j in self._running if j.ahead and j.solved is solved]:
            if twin is None:
                job.ahead, job.seconds = False, seconds
                return
            self._stop(job)
        for job in [j for j in self._finished_ahead if j.solved is solved]:
            self._forget(job)
            if twin is None:
                job.ahead, job.seconds = False, seconds
                self._finish(job)
                return
        # a free process goes to this candidate before any solve measured ahead
        while len(self._running) >= self.processes:
            self._reap(wait=True, start_queued=False)
        self._fork(solved, twin, seconds)
        self._start_queued()

    def measure_ahead(self, solved: CandidateResult) -> None:
        """Measure `solved`, a candidate solved ahead of its round (one with no twin
        among the candidates before it), once a process is free; kept apart until its
        round `submit`s it."""
        self._queued.append(solved)
        self._start_queued()

    def drop_ahead(self, keep: Iterable[CandidateResult] = ()) -> None:
        """Stop measuring ahead every solve but those in `keep` (that no round will take),
        and forget what was measured of them."""
        kept = {id(solved) for solved in keep}
        self._queued = [q for q in self._queued if id(q) in kept]
        for job in [j for j in self._running if j.ahead and id(j.solved) not in kept]:
            self._stop(job)
        for job in [j for j in self._finished_ahead if id(j.solved) not in kept]:
            self._forget(job)
        if not self._running and not self._finished_ahead:
            self._clean_up()

    def _start_queued(self) -> None:
        """Begin measuring ahead the queued solves that a free process can take."""
        while self._queued and len(self._running) < self.processes:
            self._fork(self._queued.pop(0), None, 0.0, ahead=True)

    def _stop(self, job: _Job) -> None:
        """Kill the process of `job` and forget it."""
        with contextlib.suppress(ProcessLookupError, ChildProcessError):
            os.kill(job.pid, signal.SIGKILL)
            os.waitpid(job.pid, 0)
        self._running.remove(job)
        self._forget(job)

    def _forget(self, job: _Job) -> None:
        """Remove what the process of `job` (ended) wrote, and the job from the finished."""
        if job in self._finished_ahead:
            self._finished_ahead.remove(job)
        job.path.unlink(missing_ok=True)
        job.path.with_suffix(".part").unlink(missing_ok=True)
        shutil.rmtree(job.path.with_suffix(".tmp"), ignore_errors=True)

    def _fork(self, solved: CandidateResult, twin: CandidateResult | None, seconds: float,
              ahead: bool = False) -> None:
        """Measure `solved` in a new forked process (see `submit`)."""
        if self._folder is None:
            self._folder = tempfile.TemporaryDirectory(prefix="fabplan-candidates-")
        self._count += 1
        path = Path(self._folder.name) / f"{self._count}.pickle"
        twin_made = None if twin is None else self.made_files.get(twin.name)
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                die_with_parent(parent)
                # the run's solves are the path every later candidate waits on: they
                # keep a core, and the measuring takes what is left of the machine
                with contextlib.suppress(OSError):
                    os.nice(BACKGROUND_NICENESS)
                sys.stdout = sys.stderr = open(os.devnull, "w")
                # what the measuring writes on its way goes into the run's own folder,
                # which the run removes: a process stopped halfway (a solve measured
                # ahead that no round took) leaves nothing behind
                scratch = path.with_suffix(".tmp")
                scratch.mkdir()
                tempfile.tempdir = str(scratch)
                made = _measure(self.study, self.design, solved, twin, self.files, self.rhino,
                                None if twin_made is None else twin_made[0], ifc=self.ifc)
                part = path.with_suffix(".part")
                part.write_bytes(pickle.dumps(made, protocol=pickle.HIGHEST_PROTOCOL))
                os.replace(part, path)
                code = 0
            finally:
                os._exit(code)
        self._running.append(_Job(solved, twin, pid, path, seconds, ahead))
        self._reap(wait=False)

    def _round_jobs(self) -> list[_Job]:
        """The processes measuring candidates submitted by their round."""
        return [job for job in self._running if not job.ahead]

    def is_busy(self) -> bool:
        """Whether a candidate is still being measured (the finished ones taken in;
        those measured ahead of their round do not count)."""
        self._reap(wait=False)
        return bool(self._round_jobs())

    def measuring(self) -> set[str]:
        """The names of the candidates still being measured (the finished ones taken in;
        those measured ahead of their round do not count)."""
        self._reap(wait=False)
        return {job.solved.name for job in self._round_jobs()}

    def measured(self) -> dict[str, CandidateResult]:
        """The candidates measured so far, by name (the finished ones taken in)."""
        self._reap(wait=False)
        return dict(self._done)

    def complete(self, name: str) -> CandidateResult | None:
        """The measured candidate `name`, waiting for its process; None when it was not
        submitted here."""
        while name not in self._done and any(j.solved.name == name
                                             for j in self._round_jobs()):
            self._reap(wait=True)
        return self._done.get(name)

    def cancel(self) -> None:
        """Stop every process still measuring (the run was interrupted or failed)."""
        for job in list(self._running):
            self._stop(job)
        self._queued = []
        for job in list(self._finished_ahead):
            self._forget(job)
        self._clean_up()

    def collect(self) -> dict[str, CandidateResult]:
        """Wait for every candidate submitted (not those measured ahead of their round);
        the measured candidates by name."""
        while self._round_jobs():
            if self._queued:
                # a process that ends frees a place for a solve measured ahead: polled
                time.sleep(_POLL_SECONDS)
                self._reap(wait=False)
            else:
                self._reap(wait=True)
        if not self._running and not self._finished_ahead:
            self._clean_up()
        return self._done

    def _clean_up(self) -> None:
        """Remove the folder the processes write their results into."""
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None

    def _reap(self, *, wait: bool, start_queued: bool = True) -> None:
        """Take in the finished processes (with `wait`, at least the oldest submitted by
        its round, or else the oldest); those measured ahead are kept apart. With
        `start_queued`, the processes freed begin measuring queued solves ahead."""
        waiting = self._round_jobs() or self._running
        first = waiting[0] if waiting else None
        for job in list(self._running):
            pid, job.status = os.waitpid(job.pid, 0 if wait and job is first else os.WNOHANG)
            if pid == 0:
                continue
            self._running.remove(job)
            if job.ahead:
                self._finished_ahead.append(job)
            else:
                self._finish(job)
        if start_queued:
            self._start_queued()

    def _finish(self, job: _Job) -> None:
        """Take in the measured candidate of `job`, whose process has ended."""
        from .candidate_measure import fabricate_candidate
        from .result import CandidateResult
        from .run import failure_reason

        solved, name = job.solved, job.solved.name
        shutil.rmtree(job.path.with_suffix(".tmp"), ignore_errors=True)
        if os.waitstatus_to_exitcode(job.status) == 0 and job.path.is_file():
            result, failure, lines, made, spent = pickle.loads(job.path.read_bytes())
            job.path.unlink()
            for line in lines:
                self.say(f"    {name}: {line.strip()}")
        else:   # the process died: measured here, as the serial run does
            clock = time.perf_counter()
            failure, made = None, None
            try:
                result = fabricate_candidate(self.study, self.design, solved, job.twin,
                                             self.say)
            except (FabplanError, ArithmeticError, ValueError,
                    np.linalg.LinAlgError) as exc:
                failure = failure_reason(exc)
            spent = time.perf_counter() - clock
        if failure is not None:
            self.say(f"    {name}: failed: {failure}")
            result = CandidateResult(solved.candidate, error=failure, reasons=[failure])
        else:
            result = replace(result, net=solved.net)
        result.metrics.setdefault("seconds", {})["total"] = job.seconds + spent
        if made is not None:
            self.made_files[name] = made
        self._done[name] = result
        if self.done is not None:
            self.done(result)
