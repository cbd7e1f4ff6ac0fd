"""A study's candidates run in parallel: in local processes or on a Dask cluster.

The candidates of a study are independent but for two things the serial run shares:
the layouts (one per start angle) and the nets that end at the same net as an earlier
candidate (whose molds and strips are reused). The parallel run keeps both, in three
steps, so that its `study.json` is the serial one apart from timings:

1. every candidate's net is solved in a task of its own (its layout computed there; the
   baseline layout at 90 deg, computed first, travels with the tasks); candidates that
   differ only in their mold tolerance share one solve, as in the serial run;
2. the client finds the candidates that ended at the same net as an earlier one, in the
   order of the study, as the serial run does;
3. every candidate's molds, strips and measurements are made in a task, a twin's after
   (and from) its original's.

The engine is Dask (`dask.distributed`): `LocalCluster` for ``--workers N`` on this
machine, or a running scheduler for ``--scheduler tcp://HOST:PORT``, whose workers have
fabplan installed. A task that raises a fabplan error records the candidate as failed
with its message, and the others go on; a worker that dies has its task retried
(`RETRIES` times) before the candidate is recorded as failed.
"""

from __future__ import annotations

import contextlib
import time
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ..errors import FabplanError, InputError
from ..io.resources import worker_count
from .run import (
    CandidateResult,
    StudyResult,
    fabricate_candidate,
    judge_study,
    prepare_design,
    shared_solve,
    solve_candidate,
    twin_of,
)

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from ..layout.surface_layout import SurfaceLayout
    from .cache import CandidateCache
    from .spec import Candidate, Study

__all__ = ["run_study_parallel", "RETRIES", "worker_count", "dask_client"]

RETRIES = 2   # a task whose worker died is run again this many times


def _quiet(message: str) -> None:
    pass


def _failed(candidate: Candidate, exc: BaseException) -> CandidateResult:
    reason = str(exc) if isinstance(exc, FabplanError) else f"{type(exc).__name__}: {exc}"
    return CandidateResult(candidate, error=reason, reasons=[reason])


def _solve_task(study: Study, design: DesignSurface, baseline: SurfaceLayout,
                candidate: Candidate) -> CandidateResult:
    clock = time.perf_counter()
    try:
        result = solve_candidate(study, design, candidate, {(90.0, study.panel_size): baseline},
                                 {}, _quiet)
    except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        result = _failed(candidate, exc)
    result.metrics.setdefault("seconds", {})["solve_task"] = time.perf_counter() - clock
    return result


def _fabricate_task(study: Study, design: DesignSurface, solved: CandidateResult,
                    twin: CandidateResult | None) -> CandidateResult:
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
        try:
            return Client(scheduler, timeout="5s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True,
                           dashboard_address=None)
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
    client, cluster = _connect(workers, scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_study_parallel(study: Study, *, workers: int | None = None, scheduler: str | None = None,
                       progress: Callable[[str], None] | None = None,
                       client: Any = None, max_panels: int | None = None,
                       cache: CandidateCache | None = None, resume: bool = False) -> StudyResult:
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

    Raises
    ------
    InputError
        When the design cannot be loaded or the baseline layout is impossible, or the
        scheduler cannot be reached.
    """
    say = progress or _quiet
    start = time.perf_counter()
    own = client is None
    cluster = None
    if own:
        client, cluster = _connect(workers, scheduler)
    try:
        design, baseline = prepare_design(study, say, max_panels)
        results = _run_on(client, study, design, baseline, say, cache, resume)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return judge_study(study, design, results, seconds_run=time.perf_counter() - start)


def _run_on(client: Any, study: Study, design: DesignSurface, baseline: SurfaceLayout,
            say: Callable[[str], None], cache: CandidateCache | None,
            resume: bool) -> list[CandidateResult]:
    from distributed import as_completed

    candidates = list(study.candidates)
    kept = [cache.load(c) if cache is not None and resume else None for c in candidates]
    if any(k is not None for k in kept):
        say(f"  {sum(k is not None for k in kept)} of {len(candidates)} candidates taken from "
            "the cache")
    todo = [i for i, k in enumerate(kept) if k is None]
    # one solve per solve key: a sweep of mold tolerances shares its nets
    keys = [c.solve_key for c in candidates]
    by_key = {keys[i]: k for i, k in enumerate(kept) if k is not None}
    unique = [i for i in todo if keys[i] not in by_key and
              next(j for j in todo if keys[j] == keys[i]) == i]
    shared = client.scatter([study, design, baseline], broadcast=True, hash=False)
    clock = time.perf_counter()
    solving = [client.submit(_solve_task, *shared, candidates[i], key=f"solve-{i}-{candidates[i].name}",
                             pure=False, retries=RETRIES) for i in unique]
    fresh = _gather(solving, [candidates[i] for i in unique], "solved", say, clock, as_completed)
    by_key.update({keys[i]: r for i, r in zip(unique, fresh, strict=True)})
    solved: list[CandidateResult] = [
        k if k is not None else by_key[keys[i]] if i in unique else
        shared_solve(by_key[keys[i]], candidates[i]) for i, k in enumerate(kept)]
    # twins in the order of the study, as the serial run finds them
    twins: list[int | None] = []
    for i in range(len(candidates)):
        twins.append(twin_of(i, candidates, [r.net for r in solved], twins, study))
    clock = time.perf_counter()
    made: list[Any] = list(kept)
    for i in todo:
        original = twins[i]
        made[i] = client.submit(
            _fabricate_task, shared[0], shared[1], solved[i],
            None if original is None else made[original],
            key=f"fabricate-{i}-{candidates[i].name}", pure=False, retries=RETRIES)
    done = iter(_gather([made[i] for i in todo], [candidates[i] for i in todo], "measured", say,
                        clock, as_completed, cache))
    return [k if k is not None else next(done) for k in kept]


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
