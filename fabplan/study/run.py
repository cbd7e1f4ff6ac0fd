"""Facade feasibility studies: run the candidate rationalizations of a design, measure
each against the fabrication limits, rank them by cost and recommend one.

For every candidate the pipeline is the one a user would run by hand::

    layout on the design  ->  net type solved  ->  measured  ->  molds  ->  strips
    (fabplan.layout)         (glide / optimize)   (this module)  (molds)   (strips)

Net types that exist on every surface (general, isogonal, orthogonal S-nets) are solved
exactly on the design (gliding); the others change the surface, so they start from the
gliding S-net and stay close to the design by a soft pull: how far they move is then a
measured deviation, judged against the limit. The baseline, a general S-net on the design,
is always run first, so that savings are measured against something.

Owns running the candidates in turn (`run_study`): the design and its baseline layout
made first, the layouts, solves and nets the candidates share, a search's rounds. A
candidate's two halves are `fabplan.study.candidate_solve` and
`fabplan.study.candidate_measure` (its molds counted by `fabplan.study.mold_counts`), the
nets it shares with an earlier candidate `fabplan.study.twins`, and the judging and the
recommendation `fabplan.study.ranking` (its verdict is computed from the metrics by
`verdict`, a pure function of the measured numbers and the limits: a change of a limit
changes the verdict without a new run). The names of those modules in `__all__` are
named here too.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import BrokenLayoutError, FabplanError
from .advised_size import check_advised_size
from .candidate_measure import fabricate_candidate, measure_candidate, vertex_deviation_mm
from .candidate_solve import Layouts, Starts, solve_candidate, start_angle, with_holding_size
from .definition import Candidate, Study
from .mold_counts import material_sentence, mold_metrics, molds_text
from .ranking import (
    baseline_of,
    cost_drivers,
    is_lamella_study,
    judge_study,
    pareto_optimal,
    rank_candidates,
    recommend,
)
from .relaxation_check import check_relaxation
from .result import CandidateResult, StudyResult
from .search import first_points, next_points, search_points
from .twins import SAME_NET_TOLERANCE, same_net, shared_solve, twin_of
from .verdict import candidate_cost, every_panel_flat, verdict

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..design.mesh_surface import DesignSurface
    from ..layout.surface_layout import SurfaceLayout
    from .cache import CandidateCache

__all__ = [
    "searched_study",
    "with_first_points",
    "CandidateResult",
    "StudyResult",
    "run_study",
    "judge_study",
    "prepare_design",
    "load_study_design",
    "solve_candidate",
    "fabricate_candidate",
    "measure_candidate",
    "vertex_deviation_mm",
    "mold_metrics",
    "molds_text",
    "every_panel_flat",
    "material_sentence",
    "same_net",
    "twin_of",
    "start_angle",
    "verdict",
    "candidate_cost",
    "rank_candidates",
    "recommend",
    "is_lamella_study",
    "SAME_NET_TOLERANCE",
    "baseline_of",
    "cost_drivers",
    "pareto_optimal",
    "shared_solve",
    "failure_reason",
    "Layouts",
    "Starts",
]


def run_study(study: Study, *, progress: Callable[[str], None] | None = None,
              max_panels: int | None = None, cache: CandidateCache | None = None,
              resume: bool = False, background: Callable[..., Any] | None = None,
              files: bool = False, rhino: bool = False, ifc: bool = False) -> StudyResult:
    """Run every candidate of `study` and judge it.

    A candidate that fails (a layout or a solve that breaks) is recorded with its reason
    and the study goes on.

    Parameters
    ----------
    study : the study.
    progress : called with one line per step.
    max_panels : refuse a study whose layouts would have more panels (default: what the
        memory holds, `fabplan.io.resources.default_max_panels`).
    cache : where finished candidates are kept (`fabplan.study.cache.CandidateCache`).
    resume : take the candidates the cache already holds instead of computing them.
    background : `fabplan.study.background.BackgroundCandidates` (or a subclass), to
        measure every solved candidate (molds, strips, measurements) in a forked process
        beside the next candidates' solves, one process per core (on Linux, else here),
        and the points of a search solved ahead of their round too; with `files` (and
        `rhino`, `ifc` as in `write_study`) its files too, which come back in
        `StudyResult.made_files` for `write_study` to write. The results are those of the
        serial run. None: every candidate is measured here, in turn.

    Raises
    ------
    InputError
        When the design cannot be loaded, the layouts would need more panels than
        `max_panels`, or the baseline layout is impossible (panel size too large for the
        surface, ...): nothing could be compared.
    """
    say = progress or (lambda message: None)
    start = time.perf_counter()
    design, baseline = prepare_design(study, say, max_panels)
    helper = None
    if background is not None:
        helper = background(study, design, say, files=files, rhino=rhino, ifc=ifc,
                            done=None if cache is None else cache.store)
        helper = helper if helper.active else None
    layouts: Layouts = {(90.0, study.panel_size): baseline}
    starts: Starts = {}
    solves: dict[tuple, CandidateResult] = {}
    ahead: Ahead = {}
    results: list[CandidateResult] = []

    def run(candidates: list[Candidate], title: str = "") -> None:
        """Run `candidates` after the ones in `results`, measured before it returns."""
        nonlocal results
        if helper is not None:   # what was measured ahead for other points is not needed
            helper.drop_ahead(keep=[ahead[c][0] for c in candidates if c in ahead])
        _run_candidates(study, design, helper, cache, resume, layouts, starts, solves, say,
                        candidates, results, title, ahead)
        if helper is not None:
            helper.drop_ahead()      # those the round did not take (a solve it shared)
            _solve_ahead(study, design, helper, results, layouts, starts, solves, ahead)
            measured = helper.collect()
            results = [measured.get(r.name, r) for r in results]

    try:
        run(with_first_points(study))
        for k in range(2, 2 + max((s.budget for s in study.searches), default=0)):
            judged = judge_study(searched_study(study, results), design, results)
            more = [c for s in study.searches for c in next_points(s, judged.candidates)]
            if not more:
                break
            run(more, f"search round {k}: ")
        if helper is not None:
            helper.drop_ahead()
    except BaseException:
        if helper is not None:
            helper.cancel()
        raise
    judged = judge_study(searched_study(study, results), design, results)
    check_relaxation(judged, say, cache=cache, resume=resume)
    check_advised_size(judged, say, max_panels)
    judged.seconds_run = time.perf_counter() - start
    judged.made_files = {} if helper is None else helper.made_files
    return judged


def with_first_points(study: Study) -> list[Candidate]:
    """The study's candidates and the first points of its searches (a point that is one
    of the candidates already is not solved twice)."""
    names = {c.name for c in study.candidates}
    return [*study.candidates, *(c for s in study.searches for c in first_points(s)
                                 if c.name not in names)]


def searched_study(study: Study, results: list[CandidateResult]) -> Study:
    """`study` with every candidate it ran: its own and the points of its searches."""
    if not study.searches:
        return study
    return replace(study, candidates=tuple(r.candidate for r in results))


#: Candidates solved ahead of their round (`_solve_ahead`): the solved candidate, its
#: progress lines and its solve's seconds.
Ahead = dict[Candidate, tuple[CandidateResult, list[str], float]]


def _solve_ahead(study: Study, design: DesignSurface, helper: Any, results: list[CandidateResult],
                 layouts: Layouts, starts: Starts, solves: dict[tuple, CandidateResult],
                 ahead: Ahead) -> None:
    """While the last candidates of a round are measured, solve the points the searches'
    next round will likely take: the midpoints beside the best point known so far
    (`next_points`, with the points still being measured pending). The next round takes
    a point solved here instead of solving it. A guess it does not take costs the time
    the run waited, and at most one solve more: a solve is not stopped when the
    measuring ends. Solves are deterministic, so the results are those of a run that
    solves every point in its round.

    A point solved here whose net is no earlier candidate's is measured ahead too, in a
    process the round's last candidates leave free (`helper.measure_ahead`); its round
    takes that measuring when it takes the solve, and stops it when it does not."""
    if not study.searches or not helper.is_busy():
        return
    measuring = helper.measuring()
    measured = helper.measured()
    known = [measured.get(r.name, r) for r in results if r.name not in measuring]
    judged = judge_study(searched_study(study, known), design, known).candidates
    waiting = [r for r in results if r.name in measuring]
    guesses = [c for s in study.searches
               for c in next_points(s, judged, pending=tuple(p.value for p in
                                                             search_points(s, waiting)))]
    for candidate in guesses:
        if not helper.is_busy():
            return
        if candidate.solve_key in solves or any(c.solve_key == candidate.solve_key
                                                for c in ahead):
            continue
        lines: list[str] = []
        clock = time.perf_counter()
        try:
            solved = solve_candidate(study, design, candidate, layouts, starts, lines.append)
        except Exception:     # noqa: BLE001 - solved again in its round, which records why
            continue
        ahead[candidate] = (solved, lines, time.perf_counter() - clock)
        if _twin_index(study, results, candidate, solved) is None:
            helper.measure_ahead(solved)


def _run_candidates(study: Study, design: DesignSurface, helper: Any, cache: CandidateCache | None,
                    resume: bool, layouts: Layouts, starts: Starts,
                    solves: dict[tuple, CandidateResult], say: Callable[[str], None],
                    candidates: list[Candidate], results: list[CandidateResult],
                    title: str = "", ahead: Ahead | None = None) -> None:
    """Each of `candidates` in turn, appended to `results` (the candidates before them,
    whose nets later ones may share: see `run_study`): solved here (or taken from those
    solved `ahead`), measured here or by `helper`
    (`fabplan.study.background.BackgroundCandidates`)."""
    count = len(candidates)
    for i, candidate in enumerate(candidates, 1):
        kept = cache.load(candidate) if cache is not None and resume else None
        if kept is not None:
            say(f"{title}[{i}/{count}] {candidate.name}: taken from the cache")
            solves.setdefault(candidate.solve_key, kept)
            results.append(kept)
            continue
        say(f"{title}[{i}/{count}] {candidate.name}: {candidate.describe()}")
        clock = time.perf_counter()
        # a point solved ahead whose net an earlier candidate of the round has shares it
        early = None if ahead is None or candidate.solve_key in solves \
            else ahead.pop(candidate, None)
        if early is not None:
            for line in early[1]:
                say(line)
            clock -= early[2]         # its solve, while the round before was measured
        try:
            solved, twin = _solve_with_twin(study, design, candidate, layouts, starts, solves,
                                            results, say, None if early is None else early[0])
            if helper is not None:
                twin = None if twin is None else helper.complete(twin.name) or twin
                helper.submit(solved, twin, time.perf_counter() - clock)
                # stands in for the candidate until it is measured: its net and twin are
                # what the later candidates' twins are found by
                results.append(CandidateResult(candidate, metrics=solved.metrics,
                                               net=solved.net,
                                               singular_points=solved.singular_points,
                                               twin=None if twin is None else twin.name))
                continue
            result = fabricate_candidate(study, design, solved, twin, say)
        except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            if isinstance(exc, BrokenLayoutError):
                exc = with_holding_size(exc, design, study.panel_size_of(candidate),
                                        start_angle(candidate, design),
                                        "panels.size" if candidate.panel_size is None
                                        else "panels.size (among the sizes it sweeps)")
            reason = failure_reason(exc)
            result = CandidateResult(candidate, error=reason, reasons=[reason])
            say(f"    failed: {reason}")
        result.metrics.setdefault("seconds", {})["total"] = time.perf_counter() - clock
        if cache is not None:
            cache.store(result)
        results.append(result)


def failure_reason(exc: BaseException) -> str:
    """Why a candidate failed, for the report: a fabplan error's message, else the type
    and message of the error and where it arose (not a traceback)."""
    return str(exc) if isinstance(exc, FabplanError) else \
        f"{type(exc).__name__}: {exc} ({_where(exc)})"


def prepare_design(study: Study, say: Callable[[str], None],
                   max_panels: int | None = None) -> tuple[DesignSurface, SurfaceLayout]:
    """The study's design and its baseline layout (at 90 deg): what every candidate is
    compared on, made before any candidate runs.

    Raises
    ------
    InputError
        When the design cannot be loaded, the layouts would need more panels than
        `max_panels`, or the baseline layout is impossible.
    """
    from ..layout.surface_layout import layout_surface

    design = load_study_design(study, say, max_panels)
    try:
        return design, layout_surface(design, study.panel_size, angle=90.0,
                                      settings=study.layout_settings)
    except BrokenLayoutError as exc:
        raise refused_baseline(exc, study, design, say) from None


def refused_baseline(exc: BrokenLayoutError, study: Study, design: DesignSurface,
                     say: Callable[[str], None]) -> BrokenLayoutError:
    """Why a study's baseline layout does not hold together, with the panel size at which
    a lattice on the design does (`with_holding_size`): serial and on workers alike."""
    say("the baseline layout does not hold together: trying other panel sizes")
    return with_holding_size(exc, design, study.panel_size, 90.0)


#: a panel size under this many millimetres, in a design's units smaller than metres, is
#: taken to be meant in metres when the study is refused for too many panels
_METRES_MEANT_MM = 100.0


def load_study_design(study: Study, say: Callable[[str], None],
                      max_panels: int | None = None) -> DesignSurface:
    """The study's design, checked for the panel count of its smallest panel size.

    Raises
    ------
    InputError
        When the design cannot be loaded or the layouts would need more panels than
        `max_panels`.
    """
    from ..design.load import load_design
    from ..io.resources import STUDY_BYTES_PER_PANEL, check_panel_count
    from ..io.units import likely_design_units

    source, triangles = study.design.source, study.design.triangles
    units = study.design.units
    design = load_design(source) if triangles is None else load_design(source, triangles=triangles)
    say(f"design {study.design.label}: {len(design.triangles)} triangles, area "
        f"{design.area:.4g} {units}^2")
    fix = "give a larger panels.size"
    likely = likely_design_units(design.extent, units)
    if likely is not None:
        # a design 24 km across is a millimetre file read in metres, and its panels too many
        across = f"{design.extent:,.0f}" if design.extent >= 10 else f"{design.extent:.3g}"
        unit_fix = (f"the design is {across} {units} across: is it in {likely}? "
                    f'Set design.units = "{likely}"')
        say(f"warning: {unit_fix}")
        fix = f"{unit_fix}, or {fix}"
    smallest = min(study.panel_size_of(c) for c in study.candidates)
    size_mm = smallest * study.design.mm_per_unit
    if units != "m" and size_mm < _METRES_MEANT_MM:
        # a size meant in metres, given in the design's smaller units
        given = "(mm)" if units == "mm" else f"({smallest:g} {units} is {size_mm:g} mm)"
        meant = smallest * 1000.0 / study.design.mm_per_unit
        fix = (f"panels.size is in the design's units {given}: for panels of {smallest:g} m "
               f"give {meant:g}, or {fix}")
    check_panel_count(design.area / smallest**2, max_panels=max_panels,
                      bytes_per_panel=STUDY_BYTES_PER_PANEL,
                      what=f"{study.path or study.name}: layouts of panel size "
                           f"{smallest:g} {units} on a design of area "
                           f"{design.area:.4g} {units}^2",
                      fix=fix)
    return design


def _where(exc: BaseException) -> str:
    """File and line where an unexpected error arose (for the report, not a traceback)."""
    frame = traceback.extract_tb(exc.__traceback__)[-1]
    return f"{frame.filename.rsplit('/', 1)[-1]}:{frame.lineno}"


def _solve_with_twin(study: Study, design: DesignSurface, candidate: Candidate,
                     layouts: Layouts, starts: Starts, solves: dict[tuple, CandidateResult],
                     earlier: list[CandidateResult], say: Callable[[str], None],
                     solved: CandidateResult | None = None
                     ) -> tuple[CandidateResult, CandidateResult | None]:
    """Solve one candidate (the serial path; `solved`: solved already, ahead of its
    round) and find the earlier candidate it ended at the same net as (`twin_of`), if
    any. Candidates that differ only in their mold tolerance share the solve kept in
    `solves`."""
    if candidate.solve_key in solves:
        say("    its net is that of an earlier candidate of the sweep")
        solved = shared_solve(solves[candidate.solve_key], candidate)
    else:
        if solved is None:
            solved = solve_candidate(study, design, candidate, layouts, starts, say)
        solves[candidate.solve_key] = solved
    j = _twin_index(study, earlier, candidate, solved)
    return solved, None if j is None else earlier[j]


def _twin_index(study: Study, earlier: list[CandidateResult], candidate: Candidate,
                solved: CandidateResult) -> int | None:
    """The index in `earlier` of the candidate that `candidate`, solved (`solved`), ended
    at the same net as (`twin_of`), or None."""
    position = {r.name: k for k, r in enumerate(earlier)}
    twins = [None if r.twin is None else position[r.twin] for r in earlier]
    return twin_of(len(earlier), [*(r.candidate for r in earlier), candidate],
                   [r.net.mesh if r.net is not None else None for r in [*earlier, solved]],
                   twins, study)

