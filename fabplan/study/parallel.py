"""A study's candidates run in parallel: in local processes or on a Dask cluster.

The candidates of a study are independent but for two things the serial run shares:
the layouts (one per start angle and panel size) and the nets that end at the same net as
an earlier candidate (whose molds and strips are reused). The parallel run keeps both, so
that its `study.json` is the serial one apart from timings, as a pipeline of tasks:

1. every candidate's net is solved in a task of its own (its layout computed there; the
   baseline layout at 90 deg is a task of its own that the candidates starting from it
   wait for); candidates that differ only in their mold tolerance share one solve, as in
   the serial run;
2. as the solves finish, the client takes their nets (only the meshes travel) and finds,
   in the order of the study, the candidates that ended at the same net as an earlier
   one, as the serial run does;
3. each candidate's molds, strips and measurements are made in a task as soon as every
   earlier candidate's net is known, from its solve's result where it lies (a twin's
   after, and from, its original's).

The engine is Dask (`dask.distributed`): `LocalCluster` for ``--workers N`` on this
machine, or a running scheduler for ``--scheduler tcp://HOST:PORT``, whose workers have
fabplan installed. A task that raises a fabplan error records the candidate as failed
with its message, and the others go on; a worker that dies has its task retried
(`RETRIES` times) before the candidate is recorded as failed.
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ..errors import BrokenLayoutError, FabplanError, InputError
from ..io.forked import quiet_interrupts
from ..io.resources import worker_count
from .advised_size import check_advised_size
from .candidate_measure import fabricate_candidate
from .candidate_solve import solve_candidate, start_angle
from .inputs import shared_inputs
from .ranking import judge_study
from .relaxation_check import check_relaxation
from .result import CandidateResult, StudyResult
from .run import load_study_design, refused_baseline, searched_study, with_first_points
from .search import next_points
from .twins import shared_solve, twin_of

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from ..layout.surface_layout import SurfaceLayout
    from ..net.mesh import QuadMesh
    from .cache import CandidateCache
    from .definition import Candidate, Study

__all__ = ["run_study_parallel", "RETRIES", "worker_count", "dask_client"]

RETRIES = 2   # a task whose worker died is run again this many times


def _quiet(message: str) -> None:
    pass


def _failed(candidate: Candidate, exc: BaseException) -> CandidateResult:
    reason = str(exc) if isinstance(exc, FabplanError) else f"{type(exc).__name__}: {exc}"
    return CandidateResult(candidate, error=reason, reasons=[reason])


def _baseline_task(study: Study, design: DesignSurface) -> SurfaceLayout | FabplanError:
    """The baseline layout, or why there is none: returned, not raised, because a worker
    logs a raised error with its traceback on the user's terminal."""
    from ..layout.surface_layout import layout_surface

    try:
        return layout_surface(design, study.panel_size, angle=90.0,
                              settings=study.layout_settings)
    except FabplanError as exc:
        return exc


def _solved_mesh(solved: CandidateResult) -> QuadMesh | None:
    """What the client needs of a solve to find twins: its net's mesh (None: failed)."""
    return None if solved.net is None else solved.net.mesh


def _fabricate_task(study: Study, design: DesignSurface, solved: CandidateResult,
                    candidate: Candidate, twin: CandidateResult | None) -> CandidateResult:
    if solved.candidate != candidate:          # a solve shared in a sweep of tolerances
        solved = shared_solve(solved, candidate)
    if solved.failed:
        return solved
    clock = time.perf_counter()
    try:
        result = fabricate_candidate(study, design, solved, twin, _quiet)
    except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        result = _failed(solved.candidate, exc)
    seconds = result.metrics.setdefault("seconds", {})
    seconds["total"] = (solved.metrics.get("seconds", {}).get("solve_task", 0.0)
                        + time.perf_counter() - clock)
    seconds.pop("solve_task", None)
    return result


def _connect(workers: int | None, scheduler: str | None) -> tuple[Any, Any]:
    """A Dask client (and the local cluster it owns, if any)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("parallel studies need dask.distributed: pip install "
                         "\"fabplan[parallel]\"") from None
    if scheduler is not None:
        import re

        if not re.fullmatch(r"(tcp|tls|inproc|ucx|ws|wss)://[^\s/:]+(:\d{1,5})?", scheduler):
            raise InputError(f"--scheduler {scheduler!r}: give the scheduler's address as "
                             "tcp://HOST:PORT")
        try:
            return Client(scheduler, timeout="5s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    # the workers leave Ctrl-C to this process, which closes them: no traceback of theirs;
    # and Dask's warnings stay out of the terminal (a run stopped by a refused input would
    # end in the workers' notes on their cancelled tasks, not in its one-line reason)
    with quiet_interrupts(), warnings.catch_warnings():
        # the scheduler's own HTTP port, taken by another study's cluster: it takes another
        warnings.filterwarnings("ignore", message="Port .* is already in use")
        cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
    return Client(cluster), cluster


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client for a study's run and files: a `LocalCluster` of `workers` processes
    (one thread each), or the running scheduler at `scheduler`; closed on exit.

    Raises
    ------
    InputError
        dask.distributed is not installed, or the scheduler cannot be reached.
    """
    with contextlib.ExitStack() as stack:
        # the local workers' scratch space (and its lock files) in a folder of the study's
        # own, removed with them: nothing is left in the system's temporary folder
        with contextlib.suppress(ImportError):      # without Dask, `_connect` says so
            import dask

            if scheduler is None:
                scratch = stack.enter_context(tempfile.TemporaryDirectory(prefix="fabplan-dask-"))
                stack.enter_context(dask.config.set({"temporary-directory": scratch}))
        client, cluster = _connect(workers, scheduler)
        if cluster is not None:
            stack.callback(cluster.close)
        stack.callback(client.close)                 # closed first
        yield client


def run_study_parallel(study: Study, *, workers: int | None = None, scheduler: str | None = None,
                       progress: Callable[[str], None] | None = None,
                       client: Any = None, max_panels: int | None = None,
                       cache: CandidateCache | None = None, resume: bool = False,
                       files: bool = False, rhino: bool = False, ifc: bool = False) -> StudyResult:
    """Run every candidate of `study` on Dask workers and judge them (see the module).

    Parameters
    ----------
    study : the study.
    workers : local worker processes (a `LocalCluster`), when no `scheduler` is given.
    scheduler : address of a running Dask scheduler (``tcp://HOST:PORT``).
    progress : called with one line per event (candidates done, running, failed, ETA).
    client : an existing `distributed.Client` to use instead (not closed here).
    max_panels : refuse a study whose layouts would have more panels (see `run_study`).
    cache, resume : finished candidates are kept in `cache`; with `resume` those it holds
        are taken from it (see `fabplan.study.cache`).
    files : the workers also make every candidate's files as soon as it is measured
        (`fabplan.study.report.candidate_file_bytes`, with `rhino`, `ifc` as in `write_study`),
        beside the other candidates' computation; they come back in
        `StudyResult.made_files` for `write_study` to write.

    Raises
    ------
    InputError
        When the design cannot be loaded or the baseline layout is impossible, or the
        scheduler cannot be reached.
    """
    say = progress or _quiet
    start = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(dask_client(workers, scheduler))
        design = load_study_design(study, say, max_panels)
        first = with_first_points(study)
        results, made = _run_on(client, replace(study, candidates=tuple(first)), design, say,
                                cache, resume, files=files, rhino=rhino, ifc=ifc)
        # a search's further rounds, each on the workers at once (`fabplan.study.search`)
        for k in range(2, 2 + max((s.budget for s in study.searches), default=0)):
            judged = judge_study(searched_study(study, results), design, results)
            more = [c for s in study.searches for c in next_points(s, judged.candidates)]
            if not more:
                break
            say(f"  search round {k}: {', '.join(c.name for c in more)}")
            found, made_now = _run_on(client, replace(study, candidates=tuple(more)), design,
                                      say, cache, resume, files=files, rhino=rhino, ifc=ifc,
                                      tag=f"-r{k}")
            results += found
            made.update(made_now)
    result = judge_study(searched_study(study, results), design, results)
    check_relaxation(result, say, cache=cache, resume=resume)
    check_advised_size(result, say, max_panels)
    result.seconds_run = time.perf_counter() - start
    result.made_files = made
    return result


def _run_on(client: Any, study: Study, design: DesignSurface, say: Callable[[str], None],
            cache: CandidateCache | None, resume: bool, *, files: bool = False,
            rhino: bool = False, ifc: bool = False, tag: str = ""
            ) -> tuple[list[CandidateResult], dict[str, tuple]]:
    """The candidates' results in the order of the study, and the files the workers made
    of them (with `files`) by name; `tag` ends the task keys (a search's later rounds)."""
    from distributed import as_completed

    candidates = list(study.candidates)
    kept = [cache.load(c) if cache is not None and resume else None for c in candidates]
    if any(k is not None for k in kept):
        say(f"  {sum(k is not None for k in kept)} of {len(candidates)} candidates taken from "
            "the cache")
    todo = [i for i, k in enumerate(kept) if k is None]
    shared = shared_inputs(client, study, design)
    graph = _TaskGraph(client, study, design, shared, candidates, kept, files=files,
                       rhino=rhino, ifc=ifc, tag=tag)
    baseline = client.submit(_baseline_task, *shared, key=f"baseline-layout{tag}", pure=False,
                             retries=RETRIES)
    clock = time.perf_counter()
    waiting = graph.submit_solves({(90.0, study.panel_size): baseline}, todo)
    refused = baseline.result()
    if isinstance(refused, FabplanError):     # no baseline layout: nothing can be compared
        client.cancel([*waiting, *(graph.solves[key] for key in waiting.values())])
        if isinstance(refused, BrokenLayoutError):      # as a serial run says it
            raise refused_baseline(refused, study, design, say) from None
        raise refused
    graph.submit_ready()
    graph.wait_for_nets(waiting, clock, say, as_completed)
    # the measuring's own clock: its rate since the solves' would count their time too
    done = iter(_gather([graph.made[i] for i in todo], [candidates[i] for i in todo], "measured",
                        say, time.perf_counter(), as_completed, cache))
    results = [k if k is not None else next(done) for k in kept]
    return results, graph.made_files()


@dataclass
class _TaskGraph:
    """The tasks of one round of a parallel study (`_run_on`), submitted as what they need
    becomes known: a solve per solve key (a sweep of mold tolerances shares its nets; a
    candidate kept in the cache lends its net to the others of its key), then, in the
    order of the study, each candidate's molds and strips (`made`) and its files
    (`making`, with `files`) once its own and every earlier net is known (`meshes`) and
    its twin is found (`twins`)."""

    client: Any
    study: Study
    design: DesignSurface
    shared: list[Any]
    candidates: list[Candidate]
    kept: list[CandidateResult | None]
    files: bool = False
    rhino: bool = False
    ifc: bool = False
    tag: str = ""
    keys: list[tuple] = field(init=False)
    solves: dict[tuple, Any] = field(init=False)
    meshes: dict[tuple, QuadMesh | None] = field(init=False)
    made: list[Any] = field(init=False)
    making: list[Any] = field(init=False)
    twins: list[int | None] = field(default_factory=list)

    def __post_init__(self) -> None:
        kept = self.kept
        self.keys = keys = [c.solve_key for c in self.candidates]
        self.solves = {keys[i]: k for i, k in enumerate(kept) if k is not None}
        self.meshes = {keys[i]: k.net.mesh if k.net is not None else None
                       for i, k in enumerate(kept) if k is not None}
        self.made = list(kept)
        self.making = [None] * len(self.candidates)      # the files' futures

    def submit_solves(self, layouts: dict, todo: list[int]) -> dict[Any, tuple]:
        """A solve task for every solve key of the candidates `todo` not solved yet, and a
        task that takes its mesh: the latter's futures -> their solve key. `layouts` holds
        the baseline layout's future."""
        client, study, candidates, keys, tag = (self.client, self.study, self.candidates,
                                                self.keys, self.tag)
        waiting: dict[Any, tuple] = {}
        for i in todo:
            if keys[i] in self.solves:
                continue
            # only the candidates that start from the baseline layout wait for it
            starts_there = (start_angle(candidates[i], self.design) == 90.0
                            and study.panel_size_of(candidates[i]) == study.panel_size)
            self.solves[keys[i]] = client.submit(
                _solve_task_with, *self.shared, layouts if starts_there else {}, candidates[i],
                key=f"solve-{i}-{candidates[i].name}{tag}", pure=False, retries=RETRIES)
            waiting[client.submit(_solved_mesh, self.solves[keys[i]], key=f"net-{i}{tag}",
                                  pure=False)] = keys[i]
        return waiting

    def submit_ready(self) -> None:
        """Molds and strips of every candidate whose net and earlier ones' are known."""
        from .report import candidate_files_task

        client, candidates, keys, twins, tag = (self.client, self.candidates, self.keys,
                                                self.twins, self.tag)
        while len(twins) < len(candidates) and keys[len(twins)] in self.meshes:
            i = len(twins)
            twins.append(twin_of(i, candidates, [self.meshes[k] for k in keys[:i + 1]], twins,
                                 self.study))
            if self.kept[i] is None:
                original = twins[i]
                self.made[i] = client.submit(
                    _fabricate_task, *self.shared, self.solves[keys[i]], candidates[i],
                    None if original is None else self.made[original],
                    key=f"fabricate-{i}-{candidates[i].name}{tag}", pure=False, retries=RETRIES)
            if self.files:
                # made beside the others' solves: a worker that waits for the order of
                # the study has something to do
                twin = twins[i]
                self.making[i] = client.submit(
                    candidate_files_task, self.made[i], *self.shared,
                    None if twin is None else self.making[twin], self.rhino, self.ifc,
                    key=f"files-{i}-{candidates[i].name}{tag}", pure=False, retries=RETRIES)

    def wait_for_nets(self, waiting: dict[Any, tuple], clock: float, say: Callable[[str], None],
                      as_completed: Any) -> None:
        """Take the solved meshes as they come, saying how far the solves are, and submit
        what each makes ready."""
        failed = 0
        for n, future in enumerate(as_completed(list(waiting)), 1):
            key = waiting[future]
            try:
                self.meshes[key] = future.result()
            except Exception:   # a lost worker after its retries: its candidates fail below
                self.meshes[key] = None
            failed += self.meshes[key] is None
            left = len(waiting) - n
            eta = (time.perf_counter() - clock) / n * left
            say(f"  {n} of {len(waiting)} solved, {left} to go, {failed} failed"
                + (f", about {eta:.0f} s left" if left else ""))
            self.submit_ready()

    def made_files(self) -> dict[str, tuple]:
        """The files the workers made, by candidate name (none for a task that failed)."""
        made_files: dict[str, tuple] = {}
        for c, future in zip(self.candidates, self.making, strict=True):
            try:
                made_one = None if future is None else future.result()
            except Exception:   # a lost worker after its retries: `write_study` makes them
                made_one = None
            if made_one is not None:
                made_files[c.name] = made_one
        return made_files


def _solve_task_with(study: Study, design: DesignSurface, layouts: dict,
                     candidate: Candidate) -> CandidateResult:
    """`solve_candidate` in a task: `layouts` holds the baseline layout (a future the
    worker has resolved)."""
    clock = time.perf_counter()
    refused = next((v for v in layouts.values() if isinstance(v, FabplanError)), None)
    try:
        if refused is not None:
            raise refused
        result = solve_candidate(study, design, candidate, dict(layouts), {}, _quiet)
    except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        result = _failed(candidate, exc)
    result.metrics.setdefault("seconds", {})["solve_task"] = time.perf_counter() - clock
    return result


def _gather(futures: list, candidates: list, verb: str, say: Callable[[str], None],
            clock: float, as_completed: Any,
            cache: CandidateCache | None = None) -> list[CandidateResult]:
    """Wait for the futures in the order they finish, saying how far the step is; a task
    that fails even after its retries records its candidate as failed. Finished results
    go to the `cache` as they come."""
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[CandidateResult | None] = [None] * len(futures)
    failed = 0
    for n, future in enumerate(as_completed(futures), 1):
        i = index[future.key]
        try:
            result: CandidateResult = future.result()
        except Exception as exc:   # a lost worker after its retries: the study goes on
            result = _failed(candidates[i], exc)
        results[i] = result
        if cache is not None:
            cache.store(result)
        failed += bool(result.failed)
        left = len(futures) - n
        eta = (time.perf_counter() - clock) / n * left
        say(f"  {n} of {len(futures)} {verb}, {left} to go, {failed} failed"
            + (f", about {eta:.0f} s left" if left else "") + f" ({candidates[i].name})")
    return [r for r in results if r is not None]
