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

Every verdict is computed from the metrics by `verdict`, a pure function of the measured
numbers and the limits: a change of a limit changes the verdict without a new run.
"""

from __future__ import annotations

import math
import time
import traceback
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import FabplanError
from ..fabricate.molds.mold_shapes import MOLD_TYPES, PANEL_TYPES
from ..net.free_vertices import free_vertices
from ..net.geometry import face_planarity, kink_angles
from ..report.html import counted
from .checks import LIMIT_NAMES, binding_check, relaxation_text, violation
from .definition import Candidate, Study
from .result import CandidateResult, StudyResult, by_rank
from .search import first_points, next_points
from .verdict import candidate_cost, differ_by, every_panel_flat, verdict

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..design.mesh_surface import DesignSurface
    from ..fabricate.molds.boundary_molds import BoundaryMolds
    from ..fabricate.molds.mold_plan import MoldPlan
    from ..fabricate.strips.strip_plan import StripPlan
    from ..layout.margin import ContinuedDesign
    from ..layout.surface_layout import SurfaceLayout
    from ..net.mesh import QuadMesh
    from ..solve.optimize import OptimizationResult
    from ..solve.solver import IterationRecord, SolverSettings
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

# the limits a lamella study does not speak of: its strips are bent, not molded
_MOLD_LIMITS = ("mold_tolerance_mm", "max_molds", "max_panel_step_mm")


# ---------------------------------------------------------------------------- running
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
    background : `fabplan.study.background.BackgroundCandidates` (or another class like
        it), to measure every solved candidate (molds, strips, measurements) in a forked
        process beside the next candidates' solves, one process per core (on Linux, else
        here); with `files` (and `rhino`, `ifc` as in `write_study`) its files too, which come
        back in `StudyResult.made_files` for `write_study` to write. The results are those
        of the serial run. None: every candidate is measured here, in turn.

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
    results: list[CandidateResult] = []

    def run(candidates: list[Candidate], title: str = "") -> None:
        """Run `candidates` after the ones in `results`, measured before it returns."""
        nonlocal results
        _run_candidates(study, design, helper, cache, resume, layouts, starts, solves, say,
                        candidates, results, title)
        if helper is not None:
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
    except BaseException:
        if helper is not None:
            helper.cancel()
        raise
    judged = judge_study(searched_study(study, results), design, results,
                         seconds_run=time.perf_counter() - start)
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


def _run_candidates(study: Study, design: DesignSurface, helper: Any, cache: CandidateCache | None,
                    resume: bool, layouts: Layouts, starts: Starts,
                    solves: dict[tuple, CandidateResult], say: Callable[[str], None],
                    candidates: list[Candidate], results: list[CandidateResult],
                    title: str = "") -> None:
    """Each of `candidates` in turn, appended to `results` (the candidates before them,
    whose nets later ones may share: see `run_study`): solved here, measured here or by
    `helper` (`fabplan.study.background.BackgroundCandidates`)."""
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
        try:
            solved, twin = _solve_with_twin(study, design, candidate, layouts, starts, solves,
                                            results, say)
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
    return design, layout_surface(design, study.panel_size, angle=90.0)


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

    source, triangles = study.design.source, study.design.triangles
    design = load_design(source) if triangles is None else load_design(source, triangles=triangles)
    say(f"design {study.design.label}: {len(design.triangles)} triangles, area "
        f"{design.area:.4g} {study.design.units}^2")
    smallest = min(study.panel_size_of(c) for c in study.candidates)
    check_panel_count(design.area / smallest**2, max_panels=max_panels,
                      bytes_per_panel=STUDY_BYTES_PER_PANEL,
                      what=f"{study.path or study.name}: layouts of panel size "
                           f"{smallest:g} {study.design.units} on a design of area "
                           f"{design.area:.4g} {study.design.units}^2",
                      fix="give a larger panels.size")
    return design


def judge_study(study: Study, design: DesignSurface, results: list[CandidateResult], *,
                seconds_run: float = 0.0) -> StudyResult:
    """Checks, verdicts, costs, ranks and the recommendation of measured candidates.

    A pure function of the candidates' metrics and the study's limits and weights: judging
    the same results under other limits (``dataclasses.replace(study, limits=...)``) needs
    no new run. The given `results` are left unchanged; the returned `StudyResult` holds
    judged copies.

    Strip sheets enter the cost only when every measured candidate has strips: with
    ``[strips] nets = "auto"`` only the lamella nets get strips, and charging their sheets
    would make them look dearer than nets that are not asked for strips at all.
    """
    measured = [r for r in results if not r.failed]
    charge_sheets = bool(measured) and all(r.metrics.get("strips") for r in measured)
    judged = []
    for r in results:
        if r.failed:
            judged.append(replace(r, checks=[], feasible=False, cost=None, cost_terms={},
                                  rank=None, notes=[]))
            continue
        checks = verdict(r.metrics, study.limits_of(r.candidate))
        feasible = all(c["ok"] for c in checks)
        cost, terms = candidate_cost(r.metrics, study.cost, charge_sheets=charge_sheets)
        notes = [f"the same net as {r.same_net_as} (the same panels, every vertex within "
                 f"{SAME_NET_TOLERANCE:g} of the panel size of it; its molds and strips are "
                 f"those of {r.same_net_as}): not a separate option"] if r.same_net_as else []
        judged.append(replace(r, checks=checks, feasible=feasible,
                              reasons=_reasons(checks, feasible), cost=cost, cost_terms=terms,
                              rank=None, notes=notes))
    rank_candidates(judged)
    measured = [r for r in judged if not r.failed]
    for r, optimal in zip(measured, pareto_optimal(cost_drivers(measured)), strict=True):
        r.pareto = bool(optimal)
    recommended, text = recommend(judged, study, sheets_charged=charge_sheets)
    return StudyResult(study, design, judged, recommended, text, sheets_charged=charge_sheets,
                       seconds_run=seconds_run)


#: Two candidates end at the same net when they share the combinatorics and every vertex
#: lies within this fraction of the panel size of its counterpart (10 micrometres on a 1 m
#: panel: two solves of one net, held to the design by a bound, end this close)
SAME_NET_TOLERANCE = 1e-5


def same_net(a: QuadMesh, b: QuadMesh, tolerance: float) -> bool:
    """Whether two meshes are the same net: the same faces (same vertex order) and every
    vertex within `tolerance` (model units) of its counterpart.

    Examples
    --------
    >>> from fabplan.net.mesh import QuadMesh
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    >>> a, b = QuadMesh(X, [[0, 1, 2, 3]]), QuadMesh(X + 1e-9, [[0, 1, 2, 3]])
    >>> same_net(a, b, 1e-6), same_net(a, QuadMesh(X, [[1, 2, 3, 0]]), 1e-6)
    (True, False)
    """
    if a.vertex_count != b.vertex_count or not np.array_equal(a.face_sizes, b.face_sizes):
        return False
    if not np.array_equal(a.face_indices, b.face_indices):
        return False
    return bool(np.abs(a.vertices - b.vertices).max(initial=0.0) <= tolerance)


def twin_of(i: int, candidates: list[Candidate], nets: list[QuadMesh | None],
            twins: list[int | None], study: Study) -> int | None:
    """The earlier candidate whose net candidate `i` ended at, or None.

    Candidates are compared in the order of the study, each with the earlier ones that
    are options of their own (no twin, or a twin planned at another mold tolerance). Of
    those that ended at the same net (`same_net` within `SAME_NET_TOLERANCE` of the panel
    size), one at candidate `i`'s mold tolerance comes first: its molds and strips are
    `i`'s; else the first, whose strips are `i`'s.

    Parameters
    ----------
    i : the candidate's index in `candidates` (the study's order).
    nets : solved net (its mesh) of every candidate up to `i` (None for a failed one).
    twins : what this function gave for every candidate before `i`.
    """
    net = nets[i]
    if net is None:
        return None
    tolerance = [study.mold_tolerance_of(c) for c in candidates[:i + 1]]
    own = [j for j, t in enumerate(twins[:i]) if t is None or tolerance[t] != tolerance[j]]
    size = study.panel_size_of(candidates[i])
    same = [j for j in own if (other := nets[j]) is not None and
            same_net(other, net, SAME_NET_TOLERANCE * size)]
    same.sort(key=lambda j: tolerance[j] != tolerance[i])
    return same[0] if same else None


def _where(exc: BaseException) -> str:
    """File and line where an unexpected error arose (for the report, not a traceback)."""
    frame = traceback.extract_tb(exc.__traceback__)[-1]
    return f"{frame.filename.rsplit('/', 1)[-1]}:{frame.lineno}"


#: Layouts of a study by start angle (degrees) and panel size (model units).
Layouts = dict[tuple, "SurfaceLayout"]
#: Gliding S-nets that the nets leaving the design start from, keyed as `Layouts`.
Starts = dict[tuple, "OptimizationResult"]


def _solve_with_twin(study: Study, design: DesignSurface, candidate: Candidate,
                     layouts: Layouts, starts: Starts, solves: dict[tuple, CandidateResult],
                     earlier: list[CandidateResult], say: Callable[[str], None]
                     ) -> tuple[CandidateResult, CandidateResult | None]:
    """Solve one candidate (the serial path) and find the earlier candidate it ended at
    the same net as (`twin_of`), if any. Candidates that differ only in their mold
    tolerance share the solve kept in `solves`."""
    if candidate.solve_key in solves:
        say("    its net is that of an earlier candidate of the sweep")
        solved = shared_solve(solves[candidate.solve_key], candidate)
    else:
        solved = solve_candidate(study, design, candidate, layouts, starts, say)
        solves[candidate.solve_key] = solved
    position = {r.name: k for k, r in enumerate(earlier)}
    twins = [None if r.twin is None else position[r.twin] for r in earlier]
    j = twin_of(len(earlier), [*(r.candidate for r in earlier), candidate],
                [r.net.mesh if r.net is not None else None for r in [*earlier, solved]], twins,
                study)
    return solved, None if j is None else earlier[j]


def shared_solve(solved: CandidateResult, candidate: Candidate) -> CandidateResult:
    """The solved half of `candidate` taken from another candidate's (`solved`) with the
    same `Candidate.solve_key`: the same net, no seconds of its own (or the same failure)."""
    if solved.failed:
        return CandidateResult(candidate, error=solved.error, reasons=list(solved.reasons))
    return CandidateResult(candidate, metrics={"seconds": {"layout": 0.0, "optimize": 0.0}},
                           net=solved.net, singular_points=solved.singular_points)


def solve_candidate(study: Study, design: DesignSurface, candidate: Candidate,
                    layouts: Layouts, starts: Starts,
                    say: Callable[[str], None]) -> CandidateResult:
    """The first half of a candidate: its layout (cached in `layouts` by start angle and
    panel size) and its solved net (an S-net start for the nets that leave the design,
    cached in `starts`). With `Study.layout_starts` above 1 a net that glides on the design
    is the fairest of its starts, on its own layout, and so is the S-net start (its layout
    then replaces the cached one).

    Returns
    -------
    CandidateResult with `net` and `layout`, its seconds so far in ``metrics["seconds"]``.
    """
    from ..layout.starts import glide_fairest
    from ..layout.surface_layout import glide, layout_surface
    from ..layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels
    from ..solve.solver import SolverSettings

    seconds: dict[str, float] = {}
    clock = time.perf_counter()
    angle = start_angle(candidate, design)
    size = study.panel_size_of(candidate)
    key = (angle, size)
    several = study.layout_starts > 1
    # curved panels on molds of a net that leaves a built-in design: solved past its edges
    continued = None if candidate.glides or not _on_molds(study, candidate) \
        else _continued(study, design, size)
    if key not in layouts and not several and continued is None:
        say(f"    layout at {angle:g} deg, panel size {size:g}")
        layouts[key] = layout_surface(design, size, angle=angle)
    layout = layouts.get(key)
    seconds["layout"] = time.perf_counter() - clock
    settings = SolverSettings(max_iterations=study.max_iterations)

    def report(rec: IterationRecord) -> None:
        if rec.iteration % 10 == 0:
            say(f"    iteration {rec.iteration:3d}  residual {rec.hard_residual:.2e}")

    def fairest(net_type: str, net_angle: float | None) -> tuple[SurfaceLayout, OptimizationResult]:
        # several starts, the fairest kept (`fabplan.layout.starts`)
        laid, solved = glide_fairest(design, size, net_type, angle=angle, net_angle=net_angle,
                                     solver=settings, starts=study.layout_starts,
                                     progress=report)
        say(f"    {net_type} from {len(solved.properties['layout_starts'])} starts: "
            + ", ".join(f"{t['start']} {t['status']}" + (" (kept)" if t["chosen"] else "")
                        for t in solved.properties["layout_starts"]))
        return laid, solved

    clock, laid_before = time.perf_counter(), seconds["layout"]
    if candidate.glides and several:
        layout, net = fairest(candidate.net, candidate.angle)
        if candidate.net == "snet":     # it starts the nets that leave the design too
            layouts[key], starts[key] = layout, net
    elif candidate.glides:
        assert layout is not None
        net = glide(layout, candidate.net, angle=candidate.angle, settings=settings,
                    progress=report)
        if candidate.net == "snet":
            starts[key] = net
    elif continued is not None:
        # its boundary panels then continue it within the deviation limit
        net, layout = _solve_continued(study, design, candidate, continued, angle, size,
                                       layouts, starts, settings, report, say, seconds)
    else:
        if key not in starts and several:
            # the fairest S-net starts the nets that leave the design, on its own layout
            layouts[key], starts[key] = fairest("snet", None)
        elif key not in starts:
            assert layout is not None
            # only its mesh is used: the solved net gets boundary panels of its own
            starts[key] = glide(layout, "snet", settings=settings, boundary_panels=False)
        layout = layouts[key]
        # a net that leaves the design: a zigzag tip (a vertex in no star) whose face would
        # step against its neighbours by more than the step limit follows the surface the
        # net continues instead of the design, so that the panels meet
        step = study.limits_of(candidate).panel_step_limit_mm / study.design.mm_per_unit
        # the deviation limit is held inside the solve (a net type that cannot keep to it
        # ends off-design, at the smallest limit it reached); the net is held a little
        # inside it, since its boundary panels continue its surface past its edge
        limit = (DEVIATION_HELD * study.limits_of(candidate).max_deviation_mm
                 / study.design.mm_per_unit)
        net = optimize_held(study, candidate, starts[key].mesh, reference=design.reference,
                            settings=settings, settle_free=step, max_deviation=limit,
                            progress=report)
        # its boundary panels continue it where it stands off the design, as `fabplan
        # optimize` cuts them: their molds are fitted to the net's panels beside them
        add_boundary_panels(net, layout, touch=OFF_DESIGN_TOUCH, follow_net=True)
    seconds["optimize"] = time.perf_counter() - clock - (seconds["layout"] - laid_before)
    if several and "layout_starts" in net.properties:
        # the starts' layouts were made in the solve: counted as layout time
        laid_out = sum(t.get("layout_seconds", 0.0) for t in net.properties["layout_starts"])
        seconds["layout"] += laid_out
        seconds["optimize"] = max(seconds["optimize"] - laid_out, 0.0)
    say(f"    {net.status} after {net.iterations} iterations ({seconds['optimize']:.1f} s)")
    net.properties["units"] = study.design.units     # read back by the commands on net.obj
    return CandidateResult(candidate, metrics={"seconds": seconds}, net=net,
                           singular_points=None if layout is None else layout.singular_points)


def planarity_held(study: Study, candidate: Candidate) -> tuple:
    """The constraint families that hold a candidate's quads planar within the study's
    tolerance, when the study asks for flat panels and the net type's quads are not
    planar already; else ().

    The bound holds every quad's corners within `PLANARITY_HELD` of the tolerance of a
    plane of the quad's own; the study's check measures them from their least-squares
    plane, which lies up to about a tenth farther from skew quads' corners."""
    from ..solve.constraints import PlanarityBound, PlaneNormalization
    from ..solve.net_types import get_net

    limits = study.limits_of(candidate)
    if not limits.planar_panels or get_net(candidate.net).planar_faces:
        return ()
    limit = PLANARITY_HELD * limits.planarity_tolerance_mm / study.design.mm_per_unit
    return (PlanarityBound(limit), PlaneNormalization())


def optimize_held(study: Study, candidate: Candidate, start: QuadMesh, **options: Any
                  ) -> OptimizationResult:
    """`fabplan.solve.optimize.optimize` of a candidate's net from `start`, its quads held
    planar in the solve when the study asks for flat panels (`planarity_held`). A net type
    that cannot be planar there does not converge: it is solved again without the bound,
    and the study's planarity check then says how far out of plane its panels are."""
    from ..solve.optimize import optimize

    held = planarity_held(study, candidate)
    net = optimize(start, candidate.net, angle=candidate.angle, radius=candidate.radius,
                   extra=held, **options)
    if not held:
        return net
    tolerance = study.limits_of(candidate).planarity_tolerance_mm
    record: dict[str, Any] = {"held_mm": PLANARITY_HELD * tolerance, "kept": net.converged}
    if not net.converged:
        record["without_it"] = (f"held planar, the solve ended {net.status} after "
                                f"{net.iterations} iterations: solved without the bound")
        net = optimize(start, candidate.net, angle=candidate.angle, radius=candidate.radius,
                       **options)
    net.parameters["planarity"] = record      # in net.json
    return net


def _on_molds(study: Study, candidate: Candidate) -> bool:
    """The candidate's panels are curved panels on molds: not a lamella study's strips
    (they end on the net's own settled tips) nor flat panels (their boundary panels are
    cut flat in the planes of the net's sides: `fabplan.fabricate.molds.flat_boundary`)."""
    from ..solve.net_types import get_net

    return not is_lamella_study(study) and not get_net(candidate.net).planar_faces


def _continued(study: Study, design: DesignSurface, size: float) -> ContinuedDesign | None:
    """The design continued past its edges for the nets that leave it
    (`fabplan.layout.margin`), made once per panel size; None where it cannot be."""
    from ..layout.margin import MARGIN_PANELS, continued_design

    cache = design.__dict__.setdefault("_continued", {})
    if size not in cache:
        cache[size] = continued_design(design, MARGIN_PANELS * size)
    return cache[size]


def _solve_continued(study: Study, design: DesignSurface, candidate: Candidate,
                     continued: ContinuedDesign, angle: float, size: float, layouts: Layouts,
                     starts: Starts, settings: SolverSettings, report: Callable,
                     say: Callable[[str], None], seconds: dict[str, float]
                     ) -> tuple[OptimizationResult, SurfaceLayout]:
    """A net that leaves the design, solved on the design continued past its edges: laid
    out there, started from the S-net glided there (the fairest of several with
    `Study.layout_starts`), held to the deviation limit at its vertices in stars over the
    design and one edge beyond; the faces over the design are kept, and its boundary
    panels follow the whole net solved (`fabplan.layout.margin`).

    Returns
    -------
    net : OptimizationResult, the faces kept, with their boundary panels.
    layout : the layout read on the design itself.
    """
    from ..layout.margin import design_layout, faces_on_design, held_vertices
    from ..layout.starts import glide_fairest
    from ..layout.surface_layout import glide, layout_surface
    from ..layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels
    from ..solve.optimize import kept_faces

    key = (angle, size, "continued")
    where = f"at {angle:g} deg, panel size {size:g}, on the design continued past its edges"
    if key not in starts and study.layout_starts > 1:
        # the fairest S-net of several starts starts it (`fabplan.layout.starts`)
        say(f"    S-nets from {study.layout_starts} starts {where}")
        layouts[key], starts[key] = glide_fairest(
            continued.design, size, "snet", angle=angle, solver=settings,
            starts=study.layout_starts, progress=report)
    if key not in layouts:
        clock = time.perf_counter()
        say(f"    layout {where}")
        layouts[key] = layout_surface(continued.design, size, angle=angle, judged_on=design)
        # counted as layout time (`seconds` is the candidate's record)
        seconds["layout"] += time.perf_counter() - clock
    if key not in starts:
        starts[key] = glide(layouts[key], "snet", settings=settings, boundary_panels=False)
    limits = study.limits_of(candidate)
    limit = DEVIATION_HELD * limits.max_deviation_mm / study.design.mm_per_unit
    start = starts[key].mesh
    solved = optimize_held(study, candidate, start, reference=continued.design.reference,
                           settings=settings, max_deviation=limit,
                           deviation_vertices=held_vertices(start, continued), progress=report)
    net = kept_faces(solved, faces_on_design(solved.mesh, continued), design.reference,
                     max_deviation=limit)
    net.parameters["continued"]["starts"] = len(
        starts[key].properties.get("layout_starts") or [None])
    layout = design_layout(layouts[key], continued, design)
    held = np.unique(np.asarray(solved.mesh.stars).ravel())
    add_boundary_panels(net, layout, touch=OFF_DESIGN_TOUCH, follow_net=True,
                        follow=(solved.mesh.vertices[held], continued.design))
    return net, layout


def fabricate_candidate(study: Study, design: DesignSurface, solved: CandidateResult,
                        twin: CandidateResult | None, say: Callable[[str], None]
                        ) -> CandidateResult:
    """The second half of a candidate: molds, strips and every measurement of its net.

    A `twin` is an earlier candidate that ended at the same net (CMC on a saddle ending at
    the minimal surface): its strips are this candidate's, not planned again, and so are
    its molds when they were planned at this candidate's mold tolerance; only then is the
    candidate the twin's net (`same_net_as`) rather than an option of its own.
    """
    from ..fabricate.molds.boundary_molds import boundary_molds
    from ..fabricate.molds.mold_assignment import plan_molds
    from ..fabricate.molds.mold_shapes import MoldSettings
    from ..fabricate.strips.strip_plan import plan_strips
    from ..fabricate.strips.strip_set import StripSettings

    net, candidate = solved.net, solved.candidate
    assert net is not None
    seconds = dict(solved.metrics.get("seconds", {}))
    tolerance = study.mold_tolerance_of(candidate)
    same_molds = (twin is not None and twin.molds is not None
                  and twin.molds.settings.tolerance_mm == tolerance)
    if twin is not None:
        say(f"    the same net as {twin.name}: its {'molds and ' if same_molds else ''}strips "
            "are reused")
    clock = time.perf_counter()
    units = study.design.units
    if same_molds:
        assert twin is not None and twin.molds is not None
        molds = twin.molds
    else:
        # a net held on the design: its panels are patches of the design itself
        limit = study.limits_of(candidate).panel_step_limit_mm
        molds = plan_molds(net.mesh, MoldSettings(tolerance_mm=tolerance, units=units,
                                                  step_limit_mm=limit, material=study.material,
                                                  class_order=study_class_order(study)),
                           design=design if candidate.glides else None)
    bounds = None
    if net.boundary_panels is not None:
        # on the net's molds, placed to meet their neighbours; their distance from the
        # design measured as cut
        bounds = boundary_molds(molds, net.boundary_panels, design=design)
        if bounds.panels is not None and bounds.panels is not net.boundary_panels:
            # flat panels part along the lines where their planes cross: written so, the
            # boundary file gives `fabplan molds` the same panels
            net.boundary_panels = bounds.panels
            net.properties["boundary_panels"] = bounds.panels.record()
    seconds["molds"] = time.perf_counter() - clock
    say(f"    {molds_text(mold_metrics(molds, bounds))} for {counted(molds.panel_count, 'panel')}"
        + (f" and {counted(bounds.count, 'boundary panel')}" if bounds is not None else "")
        + f" ({seconds['molds']:.1f} s)")

    strips = None
    options = study.strips
    if options is not None and options.wanted(candidate.net):
        if twin is not None and twin.strips is not None:
            strips = twin.strips
        else:
            clock = time.perf_counter()
            strips = plan_strips(net.mesh, StripSettings(
                height_mm=options.height_mm, thickness_mm=options.thickness_mm, units=units,
                sheet_mm=options.sheet_mm, tolerance_mm=options.congruence_tolerance_mm),
                boundary=net.boundary_panels)
            seconds["strips"] = time.perf_counter() - clock
            s = strips.summary()
            say(f"    {counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} on "
                f"{counted(s['sheets'], 'sheet')} ({seconds['strips']:.1f} s)")
    deviation = vertex_deviation_mm(net.mesh, design, study.design.mm_per_unit)
    metrics = measure_candidate(net, design, molds, strips, mm_per_unit=study.design.mm_per_unit,
                                deviation_mm=deviation, boundary=bounds)
    _within_study_limit(metrics, study.limits_of(candidate).max_deviation_mm)
    metrics["seconds"] = seconds
    return CandidateResult(candidate, metrics=metrics, net=net, molds=molds, strips=strips,
                           singular_points=solved.singular_points, boundary_molds=bounds,
                           same_net_as=twin.name if same_molds and twin is not None else None,
                           twin=twin.name if twin is not None else None,
                           deviation_mm=deviation)


def _within_study_limit(metrics: dict, limit_mm: float) -> None:
    """A solve that ended "off-design" only against the share of the limit it held
    (`DEVIATION_HELD`), with the net and its boundary panels within the study's own
    deviation limit, gave the study the net it asked for: its status is "converged", and
    ``solve_status`` and ``status_note`` keep what the solve said (its net record keeps
    the solver's status)."""
    if metrics["status"] != "off-design" or metrics["largest_deviation_mm"] > limit_mm:
        return
    metrics["solve_status"], metrics["status"], metrics["converged"] = "off-design", "converged", True
    metrics["status_note"] = (
        f"{metrics['largest_deviation_mm']:.1f} mm off the design: past the "
        f"{DEVIATION_HELD * limit_mm:.0f} mm the solve held, within the study's "
        f"{limit_mm:g} mm")


def study_class_order(study: Study) -> tuple[str, ...]:
    """The order a study's panels try the classes in (`fabplan.fabricate.molds.panel_classes.
    class_order`): cold or roll bending first by the study's ``[cost]``."""
    from ..fabricate.molds.panel_classes import class_order

    return class_order(study.cost.cold_bent_panel, study.cost.roll_bent_panel)


#: the share of a study's deviation limit its nets off the design are held within in the
#: solve: the rest is left to their boundary panels, which continue the net's surface
#: past its edge and so stand off the design a little further than the net
DEVIATION_HELD = 0.9
#: the share of a study's planarity tolerance its nets' quads are held within in the solve
#: (`planarity_held`)
PLANARITY_HELD = 0.8


def start_angle(candidate: Candidate, design: DesignSurface) -> float:
    """Intersection angle (degrees) of the layout a candidate starts from: the
    candidate's own angle, else its ``start_angle``, else the natural one of its net
    type on the design (`fabplan.layout.layout_angle`)."""
    from ..layout.surface_layout import layout_angle

    if candidate.start_angle is not None and candidate.angle is None:
        return float(candidate.start_angle)
    return layout_angle(candidate.net, design, candidate.angle)


# ---------------------------------------------------------------------------- measuring
def _range(values: np.ndarray) -> dict | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    return {"min": float(v.min()), "max": float(v.max()), "mean": float(v.mean())}


def vertex_deviation_mm(mesh: QuadMesh, design: DesignSurface, mm_per_unit: float) -> np.ndarray:
    """(n,) float, distance of every vertex of a net from the design in mm (to the exact
    surface of a built-in or NURBS design, to the triangle mesh of a mesh file)."""
    return design.distances(mesh.vertices) * mm_per_unit


def _free_vertex_record(net: OptimizationResult, mm_per_unit: float) -> dict | None:
    """How many vertices of the net are in no star, and how far the solve settled them
    onto the surface the net continues (mm); None for a net solved before this was recorded."""
    free = net.parameters.get("free_vertices")
    if free is None:
        return None
    return {"count": free["count"], "settled": free["settled"],
            "largest_move_mm": free["largest_move"] * mm_per_unit}


def measure_candidate(net: OptimizationResult, design: DesignSurface, molds: MoldPlan,
                      strips: StripPlan | None, *, mm_per_unit: float,
                      deviation_mm: np.ndarray | None = None,
                      boundary: BoundaryMolds | None = None) -> dict:
    """Everything a verdict and a report need, measured on the solved net.

    Parameters
    ----------
    net : `fabplan.optimize.OptimizationResult`.
    design : the `DesignSurface` (deviation is measured to it).
    molds : the `MoldPlan` of the net; strips : its `StripPlan` or None.
    mm_per_unit : millimetres per model unit.
    deviation_mm : (n,) float, the vertices' distances from the design (mm), when already
        measured (`vertex_deviation_mm`).
    boundary : the `BoundaryMolds` of the net's boundary panels, when it has them: they
        count as panels, with their molds, and their coverage.

    Returns
    -------
    dict, JSON-ready: lengths in model units unless the key ends in ``_mm``, angles in
    degrees.
    """
    mesh = net.mesh
    X = mesh.vertices
    props = net.properties
    deviation = vertex_deviation_mm(mesh, design, mm_per_unit) if deviation_mm is None else deviation_mm
    edges = np.linalg.norm(X[mesh.edges[:, 0]] - X[mesh.edges[:, 1]], axis=1)
    area = mesh.face_areas
    coverage = float(props.get("coverage", area.sum() / design.area))
    trimmed = props.get("boundary_panels") or {}
    planarity = face_planarity(X, mesh.quads) * mm_per_unit
    tips = free_vertices(mesh)
    kinks = np.degrees(kink_angles(X, mesh))
    residual = props.get("sphere_residual_relative", {}).get("max")
    metrics = {
        "status": net.status,
        "converged": net.converged,
        "iterations": net.iterations,
        "parameters": {k: v for k, v in net.parameters.items()
                       if k in ("angle_deg", "radius") and v is not None},
        "sphere_residual_relative_max": residual,
        "deviation_mm": {"max": float(deviation.max()), "mean": float(deviation.mean()),
                         "p95": float(np.percentile(deviation, 95)),
                         # the vertices the net's conditions hold (in a star), apart from
                         # the free tips settled onto the surface the net continues
                         "held_max": float(deviation[~tips].max()) if (~tips).any()
                         else None},
        "panels": int(len(mesh.face_sizes)) + (boundary.count if boundary is not None else 0),
        "full_panels": int(len(mesh.face_sizes)),
        "boundary_panels": None if boundary is None else _boundary_panel_metrics(boundary, trimmed),
        "quads": int(np.sum(mesh.face_sizes == 4)),
        "other_faces": int(np.sum(mesh.face_sizes != 4)),
        "vertices": int(mesh.vertex_count),
        "irregular_vertices": int(len(mesh.irregular_vertices)),
        "edge_length": _range(edges),
        "panel_area": _range(area),
        "coverage": coverage,
        "coverage_net": float(props.get("coverage_net", coverage)),
        "planarity_mm": _range(planarity) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "kink_deg": _range(kinks) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "intersection_angle_deg": _pick(props.get("intersection_angle_deg")),
        "meusnier_radius": _pick(props.get("meusnier_radius")),
        "folds": _fold_counts(props.get("folds")),
        "buildable": _buildable_counts(props.get("buildable")),
        "line_turn_deg": (props.get("fairness") or {}).get("line_turn_deg"),
        "free_vertices": _free_vertex_record(net, mm_per_unit),
        "molds": mold_metrics(molds, boundary),
        "strips": None if strips is None else _strip_metrics(strips),
    }
    # the facade as built: the net's vertices and the boundary panels on their molds
    edge = (metrics.get("boundary_panels") or {}).get("deviation_max_mm")
    metrics["largest_deviation_mm"] = (max(metrics["deviation_mm"]["max"], edge)
                                       if edge is not None else metrics["deviation_mm"]["max"])
    return metrics


def _boundary_panel_metrics(boundary: BoundaryMolds, trimmed: dict) -> dict:
    """The ``boundary_panels`` part of a candidate's metrics: their molds (`BoundaryMolds`)
    and what the trimming recorded (`trimmed`: flipped panels, patches)."""
    return {
        "count": boundary.count,
        "on_net_molds": boundary.on_net_molds,
        "flat": boundary.flat,
        "own_molds": boundary.own_molds,
        # as cut from their molds: their largest distance from the design, and step
        # against a neighbour
        "deviation_max_mm": boundary.deviation_max_mm,
        "step_max_mm": boundary.step_max_mm,
        "flipped": len(trimmed.get("flipped") or []),
        "patches": len(trimmed.get("patches") or []),
    }


def _strip_metrics(strips: StripPlan) -> dict:
    """The ``strips`` part of a candidate's metrics (`measure_candidate`): counts, sheets,
    lengths, radii (mm) and how the strips end, from `StripPlan.summary`."""
    s = strips.summary()
    radius = s["radius_mm"]
    return {
        "strips": s["strips"],
        "parts": s["parts"],
        "sheets": s["sheets"],
        "material_use": s["material_use"],
        "total_length_mm": s["total_length_mm"],
        "straight": s["straight"],
        "congruent": s["congruent"],
        "congruence_deviation_mm": s["congruence_deviation_mm"],
        "radius_mm": None if radius is None else
        {"min": radius["min"], "max": radius["max"], "median": radius["median"]},
        "min_radius_mm": math.inf if radius is None else radius["min"],
        "max_radius_mm": math.inf if s["straight"] or radius is None or
        any(math.isinf(st.radius_mm) for st in strips.strips.strips) else radius["max"],
        "unrolled_length_error_mm": s["unrolled_length_error_mm"],
        "ends_at_boundary_member": s["ends_at_boundary_member"],
        "ends_free": s["ends_free"],
        "ends_free_by_kind": s["ends_free_by_kind"],
        "ends_not_continued": s["ends_not_continued"],
        "boundary_member_mm": strips.strips.settings.member_mm,
    }


def _buildable_counts(build: dict | None) -> dict | None:
    """The counts of `fabplan.net.buildable` on the net (non-convex and self-crossing
    faces, sharp line turns, edge jumps, far vertices) and whether it can be built."""
    if build is None:
        return None
    keys = ("nonconvex_faces", "self_crossing_faces", "sharp_line_turns", "edge_jumps",
            "far_vertices")
    return {"buildable": bool(build["buildable"]),
            **{k: int((build.get(k) or {"count": 0})["count"]) for k in keys}}


def _fold_counts(folds: dict | None) -> dict | None:
    """The counts of `fabplan.net.folds` on the net (flipped faces, fold edges, degenerate
    stars, collapsed edges) and whether it folds."""
    if folds is None:
        return None
    keys = ("flipped_faces", "fold_edges", "degenerate_stars", "collapsed_edges")
    return {"folded": bool(folds["folded"]), **{k: int(folds[k]["count"]) for k in keys}}


def mold_metrics(plan: MoldPlan, boundary: BoundaryMolds | None = None) -> dict:
    """The mold numbers of a study: only curved panels need a mold, and with a material
    only the molded ones.

    A flat panel is cut from flat stock (glass, sheet) and needs no mold, so `count` is
    the number of molds of the single and double curved panels; the plane "mold" that a
    `fabplan.molds.MoldPlan` assigns to its flat panels is not counted. With a material
    (`MoldPlan.classes`) cold-bent, roll-bent and flat panels need none either: `count` is
    the molds that molded panels sit on (`MoldPlan.mold_made`).

    Parameters
    ----------
    plan : `fabplan.molds.MoldPlan`.
    boundary : the `BoundaryMolds` of the net's boundary panels, or None. A boundary
        panel is cut from one of the net's molds (and is of that mold's type) or from a
        mold of its own (a paraboloid, counted); its steps against its neighbours count
        with the net's. With a material a boundary panel cut from a net mold that no
        molded panel sits on is a piece of its neighbours' bent surface and is bent like
        them (its class: the class of the net panel it continues); one on a made mold is
        molded, and one on a mold of its own is molded on it.

    Returns
    -------
    dict: ``count`` (molds made for the curved panels, the boundary panels' own included),
    ``all_panels_flat``, ``fits_all``, ``failures``, ``max_deviation_mm`` (largest
    panel-to-mold gap, flat panels measured against a plane), ``molds_per_sqrt_panels``
    (``count / sqrt(panels)``, boundary panels counted), ``panel_types``, ``mold_types``
    (the plane type counts the plane flat panels are checked against),
    ``panels_per_mold_max`` (over the curved molds; 0 without any),
    ``max_panel_step_mm`` (largest step between neighbouring panels' molds at a shared
    edge, boundary panels included), ``panel_steps_over`` (shared edges whose step exceeds
    the step limit), ``bound`` (an estimate of the fewest molds the panels' curvature set
    allows, `MoldPlan.mold_count_bound`), ``boundary_own_molds`` and ``net_molds`` (the
    curved molds of the net's own panels); with a material also ``panel_classes`` (panels
    per class, boundary panels counted), ``molded_types`` (the molded panels' types),
    ``all_curved_molded`` (the molds if every curved panel were molded) and ``saved``
    (the molds the material saves against that).
    """
    curved = np.asarray(plan.mold_type) > 0
    made = plan.mold_made
    per_mold = plan.panels_per_mold.copy()
    panel_type = np.asarray(plan.panel_type)
    classes = None if plan.classes is None else plan.classes.panel_class.copy()
    own = 0
    step = plan.max_step_mm
    over = int(plan.steps_over.size)
    if boundary is not None and boundary.count:
        cut = (boundary.mold >= 0) & (boundary.mold < len(per_mold)) & ~boundary.extension
        per_mold += np.bincount(boundary.mold[cut], minlength=len(per_mold))
        own = boundary.own_molds
        kept = ~boundary.extension
        panel_type = np.r_[panel_type, boundary.panel_types()[kept]]
        if classes is not None:
            classes = np.r_[classes, _boundary_classes(plan, boundary)[kept]]
        step = max(step, boundary.step_max_mm)
        known = np.isfinite(boundary.side_step_mm)
        over += int(np.sum(boundary.side_step_mm[known] > boundary.step_limit_mm + 1e-9))
    count = int(made.sum()) + own
    panels = len(panel_type)
    out: dict[str, Any] = {
        "count": count,
        "net_molds": int(made.sum()),
        # no curved panel at all (with a material a curved panel may need no mold either)
        "all_panels_flat": int(curved.sum()) + own == 0,
        "fits_all": bool(plan.fits_all) and over == int(plan.steps_over.size),
        "failures": int(plan.failures.size),
        "max_panel_step_mm": step,
        "panel_steps_over": over,
        "bound": plan.mold_count_bound()[1],
        "max_deviation_mm": float(np.max(plan.deviation_mm)),
        "molds_per_sqrt_panels": count / math.sqrt(panels),
        "panel_types": {t: int(np.sum(panel_type == i)) for i, t in enumerate(PANEL_TYPES)},
        "mold_types": {t: int(np.sum(plan.mold_type == i)) + (own if t == "paraboloid" else 0)
                       for i, t in enumerate(MOLD_TYPES)},
        "panels_per_mold_max": int(per_mold[made].max()) if made.any() else 0,
        "boundary_own_molds": own,
    }
    if classes is not None:
        from ..fabricate.molds.panel_classes import CLASSES

        molded = classes == CLASSES.index("molded")
        out["panel_classes"] = {c: int(np.sum(classes == i)) for i, c in enumerate(CLASSES)}
        out["molded_types"] = {t: int(np.sum(molded & (panel_type == i)))
                               for i, t in enumerate(PANEL_TYPES)}
        out["all_curved_molded"] = int(curved.sum()) + own
        out["saved"] = out["all_curved_molded"] - count
        out["material"] = plan.classes.material.label if plan.classes is not None else None
    return out


def _boundary_classes(plan: MoldPlan, boundary: BoundaryMolds) -> np.ndarray:
    """(b,) the class of every boundary panel (`mold_metrics`)."""
    from ..fabricate.molds.panel_classes import CLASSES

    assert plan.classes is not None
    molded = CLASSES.index("molded")
    net = (boundary.mold >= 0) & (boundary.mold < plan.mold_count)
    on_made = net & plan.mold_made[np.clip(boundary.mold, 0, max(plan.mold_count - 1, 0))]
    face = np.asarray(boundary.neighbour_face)
    like = np.where(face >= 0, plan.classes.panel_class[np.maximum(face, 0)], molded)
    flat = boundary.panel_types() == 0
    return np.where(flat, CLASSES.index("flat"), np.where(net & ~on_made, like, molded))


def material_sentence(molds: dict) -> str:
    """What the panel material saves, in a sentence (`mold_metrics` with a material).

    Examples
    --------
    >>> text = material_sentence({"material": "tempered glass, 8 mm", "saved": 3, "count": 1,
    ...     "all_curved_molded": 4, "panel_classes": {"flat": 2, "cold_bent": 30,
    ...     "roll_bent": 0, "molded": 5}})
    >>> text[:73]
    'In tempered glass, 8 mm, its panels are 2 flat, 30 cold-bent, 0 roll-bent'
    >>> text[73:]
    ' and 5 molded: 1 mold instead of 4 with every curved panel molded, 3 molds saved by the material.'
    >>> material_sentence({"material": "steel", "saved": 0, "count": 0, "all_curved_molded": 0,
    ...     "panel_classes": {"flat": 9, "cold_bent": 0, "roll_bent": 0, "molded": 0}})[-42:]
    'and 0 molded: no panel is curved, no mold.'
    >>> material_sentence({"material": "annealed glass", "saved": 0, "count": 2,
    ...     "all_curved_molded": 2, "panel_classes": {"flat": 0, "cold_bent": 0,
    ...     "roll_bent": 0, "molded": 9}})[-50:]
    'and 9 molded: 2 molds, none saved by the material.'
    """
    c = molds["panel_classes"]
    head = (f"In {molds['material']}, its panels are {c['flat']} flat, {c['cold_bent']} cold-bent, "
            f"{c['roll_bent']} roll-bent and {c['molded']} molded: ")
    if molds["all_curved_molded"] == 0:
        # nothing to save: "0 molds instead of 0" says nothing
        return head + "no panel is curved, no mold."
    if molds["saved"] == 0:
        # nor does "17 molds instead of 17"
        return head + f"{counted(molds['count'], 'mold')}, none saved by the material."
    return (head + f"{counted(molds['count'], 'mold')} instead of {molds['all_curved_molded']} "
            f"with every curved panel molded, {counted(molds['saved'], 'mold')} saved by the "
            "material.")


def molds_text(molds: dict) -> str:
    """The molds of a candidate in words: ``"no molds: all panels flat"``, with a material
    whose panels are bent ``"no molds: no panel molded"``, or ``"12 molds"``.

    Examples
    --------
    >>> molds_text({"count": 0, "all_panels_flat": True}), molds_text({"count": 12})
    ('no molds: all panels flat', '12 molds')
    >>> molds_text({"count": 0, "all_panels_flat": False, "panel_classes": {"flat": 0,
    ...     "cold_bent": 5, "roll_bent": 0, "molded": 0}})
    'no molds: no panel molded'
    """
    if molds["count"] == 0:
        return "no molds: all panels flat" if every_panel_flat(molds) else "no molds: no panel molded"
    return counted(molds["count"], "mold")


def _pick(stats: dict | None) -> dict | None:
    if not stats or stats.get("min") is None:
        return None
    return {"min": stats["min"], "max": stats["max"]}


# ---------------------------------------------------------------------------- judging
def _reasons(checks: list[dict], feasible: bool) -> list[str]:
    if feasible:
        return [f"meets all {len(checks)} limits: " + "; ".join(c["text"] for c in checks)]
    return [c["text"] for c in checks if not c["ok"]]


def cost_drivers(results: list[CandidateResult]) -> np.ndarray:
    """(n, 3) float, what makes each measured candidate dear: molds, strip sheets (0
    without strips) and the largest deviation from the design (mm)."""
    return np.array([[r.metrics["molds"]["count"], (r.metrics.get("strips") or {}).get("sheets", 0),
                      r.metrics["largest_deviation_mm"]] for r in results],
                    dtype=np.float64).reshape(-1, 3)


def pareto_optimal(points: np.ndarray) -> np.ndarray:
    """(n,) bool, the points no other point dominates (at most as large in every column
    and smaller in one): the Pareto front of costs to be minimised.

    Examples
    --------
    >>> pareto_optimal(np.array([[1, 5], [2, 2], [3, 3], [1, 5], [4, 1.0]])).tolist()
    [True, True, False, True, True]
    """
    p = np.asarray(points, dtype=np.float64)
    no_worse = (p[:, None, :] <= p[None, :, :]).all(axis=2)   # [j, i]: j is nowhere worse
    better = (p[:, None, :] < p[None, :, :]).any(axis=2)      # [j, i]: j is better somewhere
    return np.asarray(~(no_worse & better).any(axis=0), dtype=bool)


def rank_candidates(results: list[CandidateResult]) -> None:
    """Set `rank`: feasible candidates by cost, then the others by failed checks, cost. A
    candidate that ended at the net of another ranks right after it (their costs differ by
    rounding only)."""
    done = [r for r in results if not r.failed]
    named = {r.name: r for r in done}

    def key(r: CandidateResult) -> tuple[bool, int, float, bool]:
        twin = r if r.same_net_as is None else named.get(r.same_net_as, r)
        cost = math.inf if twin.cost is None else twin.cost
        return (not r.feasible, sum(not c["ok"] for c in r.checks), cost, twin is not r)

    order = sorted(done, key=key)
    for i, r in enumerate(order, 1):
        r.rank = i


def is_lamella_study(study: Study) -> bool:
    """Whether a study is about lamella strips rather than panels: every candidate gets
    strips (``[strips] nets = "all"``) or a strip limit is set."""
    limits = study.limits
    return study.strips is not None and (
        study.strips.nets == "all" or limits.congruent_strips or limits.max_sheets is not None
        or limits.min_strip_radius_mm is not None or limits.max_strip_radius_mm is not None)


def recommend(results: list[CandidateResult], study: Study, *,
              sheets_charged: bool = True) -> tuple[str | None, str]:
    """The recommended candidate (the cheapest feasible one) and why, in plain words.

    The text says first what decides the study: when the baseline fails a limit, which one
    (measured against the limit). Then what the recommended candidate achieves: its strips
    and sheets in a lamella study (`is_lamella_study`), its molds in a panel study, planar
    panels where they are required; then its deviation and its cost against the
    baseline's. A candidate that ended at the same net as an earlier one is named as that
    net, not as another option.
    """
    feasible = sorted((r for r in results if r.feasible), key=by_rank)
    if not feasible:
        measured = sorted((r for r in results if not r.failed),
                          key=lambda r: (violation(r.checks), by_rank(r)))
        if not measured:
            return None, "No candidate produced a net; see the reasons of each below."
        best = measured[0]
        text = (f"No candidate meets every limit. The nearest is {_named(best)}, which "
                "fails: " + "; ".join(best.reasons) + ".")
        relax = relaxation_text(best.checks)
        if relax:
            text += f" It would be feasible with {relax}, the other limits as they are."
        steps = _next_steps(best)
        return None, text + (f" Other ways: {'; '.join(steps)}." if steps else "")
    best = feasible[0]
    base = baseline_of(best.candidate, results)
    limits = study.limits
    words = [f"Recommended: {_named(best)}."]
    said = None                        # a candidate whose failure is already told
    if best.candidate.baseline:
        words.append("The general S-net on the design meets every limit, and no other "
                     "candidate that does is cheaper.")
    elif base is not None and not base.feasible:
        failed = [c["text"] for c in base.checks if not c["ok"]]
        words.append("The baseline, a general S-net on the design, does not meet the limits: "
                     + "; ".join(failed) + ".")
        said = base
    if best.same_net_as:
        words.append(f"It ends at the same net as {best.same_net_as}.")
    words += _achievements(best, None if best.candidate.baseline else base, study)
    # a lamella study is told in strips: its binding limit among the others
    binding = binding_check([c for c in best.checks if not (
        is_lamella_study(study) and c["limit"] in _MOLD_LIMITS)])
    if binding is not None:
        name = LIMIT_NAMES.get(binding["limit"], (binding["limit"],))[0]
        words.append(f"The limit that binds hardest is the {name}: "
                     f"{_g3(binding['measured'])} against {binding['bound']:g} "
                     f"({100 * binding['margin']:.0f} % to spare).")
    m = best.metrics
    words.append(f"It deviates at most {m['largest_deviation_mm']:.1f} mm from the design "
                 f"(limit {limits.max_deviation_mm:g} mm).")
    if base is not None and not best.candidate.baseline:
        words.append(_cost_sentence(best, base))
    with_strips = [r for r in results if not r.failed and r.metrics.get("strips")]
    measured = [r for r in results if not r.failed]
    if with_strips and not sheets_charged:
        words.append(f"Strip sheets are reported but not charged: only {len(with_strips)} of "
                     f"{len(measured)} candidates {'gets' if len(with_strips) == 1 else 'get'} "
                     "strips.")
    others = feasible[1:]
    if others:
        words.append("Also feasible: " + ", ".join(_also(r) for r in others) + ".")
    infeasible = [r for r in results if not r.feasible and r is not said]
    if infeasible:
        words.append("Not feasible: " + "; ".join(
            f"{r.name}: {r.reasons[0]}" + (f" (the same net as {r.same_net_as})"
                                            if r.same_net_as else "")
            for r in infeasible) + ".")
    return best.name, " ".join(words)


def _g3(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}"


#: what to try when a limit fails, by limit
_TRY = {
    "max_sphere_residual": "let the solve run longer (max_iterations) or try another angle or "
                           "panel size: the net did not converge",
    "max_deviation_mm": "keep the net nearer the design: a net type that glides on it "
                        "(isogonal, orthogonal, the baseline) or a smaller panel size",
    "mold_tolerance_mm": "a larger mold_tolerance_mm, or a smaller panel size",
    "max_molds": "a net type whose panels share molds (linear Weingarten, constant radius) or "
                 "a larger mold_tolerance_mm",
    "max_panel_step_mm": "a smaller panel size or a larger mold_tolerance_mm",
    "max_kink_deg": "a smaller panel size",
    "max_line_turn_deg": "another net type or angle, or a smaller panel size",
    "planarity_tolerance_mm": "a net type with planar panels (char-conjugate)",
}


def _named(result: CandidateResult) -> str:
    """A candidate's name, with its description where that says more."""
    described = result.candidate.describe()
    return result.name if described == result.name else f"{result.name} ({described})"


def _next_steps(best: CandidateResult) -> list[str]:
    """What else to try for the nearest candidate of a study without a feasible one,
    beside relaxing its failed limits (`relaxation_text`): one suggestion per failed
    limit."""
    steps = [_TRY[c["limit"]] for c in best.checks if not c["ok"] and c["limit"] in _TRY]
    return list(dict.fromkeys(steps))


def baseline_of(candidate: Candidate, results: list[CandidateResult]) -> CandidateResult | None:
    """The measured baseline a candidate is compared with: the one of its panel size and
    mold tolerance in a sweep, else the first."""
    bases = [r for r in results if r.candidate.baseline and not r.failed]
    return next((r for r in bases if r.candidate.panel_size == candidate.panel_size and
                 r.candidate.mold_tolerance_mm == candidate.mold_tolerance_mm),
                bases[0] if bases else None)


def _achievements(best: CandidateResult, base: CandidateResult | None, study: Study) -> list[str]:
    """What the recommended candidate achieves that the study asks for, in sentences."""
    m, limits = best.metrics, study.limits
    b = base.metrics if base is not None else None
    words = []
    s = m.get("strips")
    if is_lamella_study(study) and s:
        tol = limits.congruence_tolerance_mm
        if s["straight"]:
            shape = "all straight"
        elif s["congruence_deviation_mm"] <= tol:
            radius = s["radius_mm"]
            shape = (f"all congruent: pieces of one arc of radius {radius['median']:.0f} mm, "
                     f"differing from it {differ_by(s['congruence_deviation_mm'])} "
                     f"(tolerance {tol:g} mm)")
        else:
            shape = (f"not congruent (they differ from one common arc "
                     f"{differ_by(s['congruence_deviation_mm'])})")
        sheets = counted(s["sheets"], "sheet")
        if b is not None and b.get("strips"):
            sheets += f" (the baseline: {b['strips']['sheets']})"
        words.append(f"Its {counted(s['strips'], 'lamella')} are cut as "
                     f"{counted(s['parts'], 'part')}, {shape}, nested on {sheets}.")
        if limits.min_strip_radius_mm is not None and not s["straight"]:
            words.append(f"The smallest arc radius is {s['min_radius_mm']:.0f} mm (limit at least "
                         f"{limits.min_strip_radius_mm:g} mm).")
    else:
        molds, panels = m["molds"], m["panels"]
        if molds["count"] == 0:
            text = (f"It needs no molds: all its {counted(panels, 'panel')} are flat"
                    if every_panel_flat(molds) else
                    f"It needs no molds: none of its {counted(panels, 'panel')} is molded")
        else:
            text = f"It needs {counted(molds['count'], 'mold')} for its {counted(panels, 'panel')}"
        if limits.max_molds is not None:
            text += f" (limit {limits.max_molds})"
        if b is not None:
            bm = b["molds"]["count"]
            text += (f", where the baseline needs {'none' if bm == 0 else counted(bm, 'mold')} "
                     f"for its {b['panels']}") + (_saving(molds["count"], bm)
                                                  if molds["count"] else "")
        words.append(text + ".")
    if m["molds"].get("panel_classes") is not None:
        words.append(material_sentence(m["molds"]))
    if limits.planar_panels:
        words.append(f"Its panels are planar within {m['planarity_mm']['max']:.2f} mm "
                     f"(tolerance {limits.planarity_tolerance_mm:g} mm).")
    return words


def _cost_sentence(best: CandidateResult, base: CandidateResult) -> str:
    cost, base_cost = best.cost, base.cost
    if cost is None or base_cost is None:
        raise ValueError("only measured candidates have a cost to compare")
    if cost <= base_cost:
        less = 100 * (base_cost - cost) / base_cost if base_cost > 0 else 0.0
        return (f"It costs {cost:.0f} units against {base_cost:.0f} for the baseline "
                f"({less:.0f} % less).")
    return (f"It costs {cost:.0f} units, more than the {base_cost:.0f} of the baseline, "
            "which does not meet the limits.")


def _also(r: CandidateResult) -> str:
    if r.same_net_as:
        return f"{r.name} (the same net as {r.same_net_as})"
    return f"{r.name} (cost {r.cost:.0f})"


def _saving(n: int, base: int) -> str:
    if base <= 0 or n >= base:
        return ""
    return f" ({100 * (base - n) / base:.0f} % fewer)"
