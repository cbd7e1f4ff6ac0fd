"""The first half of a study candidate: its layout on the design and its solved net.

Net types that exist on every surface (general, isogonal, orthogonal S-nets) are solved
exactly on the design (gliding); the others change the surface, so they start from the
gliding S-net and stay close to the design by a bound on their deviation, held inside the
solve (`DEVIATION_HELD`), and their quads planar where the study asks for flat panels
(`PLANARITY_HELD`). Curved panels on molds of a net that leaves a built-in design are
solved on the design continued past its edges (`fabplan.layout.margin`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import BrokenLayoutError
from .definition import Candidate, Study
from .ranking import is_lamella_study
from .result import CandidateResult

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..design.mesh_surface import DesignSurface
    from ..layout.margin import ContinuedDesign
    from ..layout.surface_layout import SurfaceLayout
    from ..net.mesh import QuadMesh
    from ..solve.optimize import OptimizationResult
    from ..solve.solver import IterationRecord, SolverSettings

__all__ = ["Layouts", "Starts", "solve_candidate", "planarity_held", "optimize_held", "start_angle",
           "with_holding_size", "DEVIATION_HELD", "PLANARITY_HELD"]


#: Layouts of a study by start angle (degrees) and panel size (model units).
Layouts = dict[tuple, "SurfaceLayout"]
#: Gliding S-nets that the nets leaving the design start from, keyed as `Layouts`.
Starts = dict[tuple, "OptimizationResult"]


def solve_candidate(study: Study, design: DesignSurface, candidate: Candidate,
                    layouts: Layouts, starts: Starts,
                    say: Callable[[str], None]) -> CandidateResult:
    """The first half of a candidate: its layout (cached in `layouts` by start angle and
    panel size) and its solved net (an S-net start for the nets that leave the design,
    cached in `starts`). With `Study.layout_starts` above 1 a net that glides on the design
    is the fairest of its starts, on its own layout, and so is the S-net start (its layout
    then replaces the cached one). With one, a net that glides and does not converge on
    the study's layout is solved from the other layout starts too, the fairest kept (the
    S-net start stays the first glide).

    Returns
    -------
    CandidateResult with `net` and `layout`, its seconds so far in ``metrics["seconds"]``.
    """
    from ..layout.surface_layout import layout_surface
    from ..solve.solver import SolverSettings

    seconds: dict[str, float] = {}
    clock = time.perf_counter()
    solve = _CandidateSolve(study, design, candidate, layouts, starts, say,
                            start_angle(candidate, design), study.panel_size_of(candidate),
                            SolverSettings(max_iterations=study.max_iterations))
    angle, size = solve.angle, solve.size
    # curved panels on molds of a net that leaves a built-in design: solved past its edges
    continued = None if candidate.glides or not _on_molds(study, candidate) \
        else _continued(study, design, size)
    if solve.key not in layouts and not solve.several and continued is None:
        say(f"    layout at {angle:g} deg, panel size {size:g}")
        layouts[solve.key] = layout_surface(design, size, angle=angle,
                                            settings=study.layout_settings)
    layout = layouts.get(solve.key)
    seconds["layout"] = time.perf_counter() - clock
    clock, laid_before = time.perf_counter(), seconds["layout"]
    if candidate.glides:
        net, layout = solve.gliding(layout)
    elif continued is not None:
        # its boundary panels then continue it within the deviation limit
        net, layout = solve.past_edges(continued, seconds)
    else:
        net, layout = solve.off_design(layout)
    _count_solve_seconds(seconds, net, clock, laid_before)
    say(f"    {net.status} after {net.iterations} iterations ({seconds['optimize']:.1f} s)")
    net.properties["units"] = study.design.units     # read back by the commands on net.obj
    return CandidateResult(candidate, metrics={"seconds": seconds}, net=net,
                           singular_points=None if layout is None else layout.singular_points)


@dataclass
class _CandidateSolve:
    """What the steps of one candidate's solve (`solve_candidate`) share: the study's
    caches of layouts and S-net starts, the start angle and panel size (their key) and
    the solver's settings."""

    study: Study
    design: DesignSurface
    candidate: Candidate
    layouts: Layouts
    starts: Starts
    say: Callable[[str], None]
    angle: float
    size: float
    settings: SolverSettings

    @property
    def key(self) -> tuple:
        return (self.angle, self.size)

    @property
    def several(self) -> bool:
        """Several layout starts, the fairest kept (`Study.layout_starts`)."""
        return self.study.layout_starts > 1

    def report(self, rec: IterationRecord) -> None:
        """The solver's progress, every tenth iteration."""
        if rec.iteration % 10 == 0:
            self.say(f"    iteration {rec.iteration:3d}  residual {rec.hard_residual:.2e}")

    def fairest(self, net_type: str, net_angle: float | None, starts: int | None = None,
                first_solved: tuple[SurfaceLayout, OptimizationResult] | None = None
                ) -> tuple[SurfaceLayout, OptimizationResult]:
        """A gliding net of several starts (default: the study's), the fairest kept
        (`fabplan.layout.starts`); `first_solved` the first start, made already."""
        from ..layout.starts import glide_fairest

        laid, solved = glide_fairest(self.design, self.size, net_type, angle=self.angle,
                                     net_angle=net_angle, solver=self.settings,
                                     settings=self.study.layout_settings,
                                     vary_smoothing=self.study.smoothing is None,
                                     starts=starts or self.study.layout_starts,
                                     progress=self.report, first_solved=first_solved)
        self.say(f"    {net_type} from {len(solved.properties['layout_starts'])} starts: "
                 + ", ".join(f"{t['start']} {t['status']}" + (" (kept)" if t["chosen"] else "")
                             for t in solved.properties["layout_starts"]))
        return laid, solved

    def gliding(self, layout: SurfaceLayout | None
                ) -> tuple[OptimizationResult, SurfaceLayout | None]:
        """A net that exists on every surface, glided on the design from `layout` (the
        fairest of several starts, on its own layout); a general S-net is kept as the
        start of the nets that leave the design."""
        from ..layout.starts import MAX_STARTS
        from ..layout.surface_layout import glide

        candidate, key = self.candidate, self.key
        if self.several:
            layout, net = self.fairest(candidate.net, candidate.angle)
            if candidate.net == "snet":     # it starts the nets that leave the design too
                self.layouts[key], self.starts[key] = layout, net
        else:
            assert layout is not None
            net = glide(layout, candidate.net, angle=candidate.angle, settings=self.settings,
                        progress=self.report)
            if candidate.net == "snet":
                # the start of the nets that leave the design, whichever candidate makes it
                # first: the same glide, so that no result depends on the candidates' order
                self.starts[key] = net
            if not net.converged:
                # one start's lattice may lie where the net type stalls on this design;
                # other starts often do not (a wavy facade's isogonal net: 1 of 5 converged)
                self.say(f"    {net.status} from the study's layout: solved from other "
                         "layout starts too")
                layout, net = self.fairest(candidate.net, candidate.angle, MAX_STARTS,
                                           first_solved=(layout, net))
        return net, layout

    def off_design(self, layout: SurfaceLayout | None
                    ) -> tuple[OptimizationResult, SurfaceLayout]:
        """A net that leaves the design, solved from the gliding S-net of its key (made
        now if no candidate made it before), held to the deviation limit, with boundary
        panels that continue it."""
        from ..layout.surface_layout import glide
        from ..layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels

        study, candidate, key = self.study, self.candidate, self.key
        layouts, starts = self.layouts, self.starts
        if key not in starts and self.several:
            # the fairest S-net starts the nets that leave the design, on its own layout
            layouts[key], starts[key] = self.fairest("snet", None)
        elif key not in starts:
            assert layout is not None
            # only its mesh is used: the solved net gets boundary panels of its own
            starts[key] = glide(layout, "snet", settings=self.settings, boundary_panels=False)
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
        net = optimize_held(study, candidate, starts[key].mesh, reference=self.design.reference,
                            settings=self.settings, settle_free=step, max_deviation=limit,
                            progress=self.report)
        # its boundary panels continue it where it stands off the design, as `fabplan
        # optimize` cuts them: their molds are fitted to the net's panels beside them
        add_boundary_panels(net, layout, touch=OFF_DESIGN_TOUCH, follow_net=True)
        return net, layout

    def past_edges(self, continued: ContinuedDesign, seconds: dict[str, float]
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

        study, design, candidate = self.study, self.design, self.candidate
        angle, size, layouts, starts = self.angle, self.size, self.layouts, self.starts
        settings, report, say = self.settings, self.report, self.say
        key = (angle, size, "continued")
        where = f"at {angle:g} deg, panel size {size:g}, on the design continued past its edges"
        if key not in starts and study.layout_starts > 1:
            # the fairest S-net of several starts starts it (`fabplan.layout.starts`)
            say(f"    S-nets from {study.layout_starts} starts {where}")
            layouts[key], starts[key] = glide_fairest(
                continued.design, size, "snet", angle=angle, solver=settings,
                settings=study.layout_settings, vary_smoothing=study.smoothing is None,
                starts=study.layout_starts, progress=report)
        if key not in layouts:
            clock = time.perf_counter()
            say(f"    layout {where}")
            layouts[key] = layout_surface(continued.design, size, angle=angle, judged_on=design,
                                          settings=study.layout_settings)
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


#: the share of a study's deviation limit its nets off the design are held within in the
#: solve: the rest is left to their boundary panels, which continue the net's surface
#: past its edge and so stand off the design a little further than the net
DEVIATION_HELD = 0.9
#: the share of a study's planarity tolerance its nets' quads are held within in the solve
#: (`planarity_held`)
PLANARITY_HELD = 0.8


def _count_solve_seconds(seconds: dict[str, float], net: OptimizationResult, clock: float,
                         laid_before: float) -> None:
    """``seconds["optimize"]``: the solve's time since `clock`, less the layouts made in it
    (counted as layout time, as are the layouts of several starts)."""
    seconds["optimize"] = time.perf_counter() - clock - (seconds["layout"] - laid_before)
    if "layout_starts" in net.properties:
        # the starts' layouts were made in the solve: counted as layout time
        laid_out = sum(t.get("layout_seconds", 0.0) for t in net.properties["layout_starts"])
        seconds["layout"] += laid_out
        seconds["optimize"] = max(seconds["optimize"] - laid_out, 0.0)


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


def with_holding_size(exc: BrokenLayoutError, design: DesignSurface, size: float,
                      angle: float, key: str = "panels.size") -> BrokenLayoutError:
    """`exc`, a layout at panel `size` and `angle` that does not hold together, saying at
    which panel size its lattice on the design does (`fabplan.layout.surface_layout.
    holding_panel_size`, found once per design object, size and angle) and the study `key`
    to give it, or that none of those tried does."""
    from ..layout.surface_layout import HOLDING_SIZE_FACTORS, holding_panel_size

    found = design.__dict__.setdefault("_holding_sizes", {})
    if (size, angle) not in found:
        found[size, angle] = holding_panel_size(design, size, angle=angle)
    held = found[size, angle]
    if held is None:
        tried = ", ".join(f"{f * size:g}" for f in HOLDING_SIZE_FACTORS)
        return BrokenLayoutError(f"{exc}; nor does it at panel sizes {tried}")
    return BrokenLayoutError(f"{exc}; a lattice on the design holds together at panel size "
                             f"{held:g}: give {key} = {held:g}")


def start_angle(candidate: Candidate, design: DesignSurface) -> float:
    """Intersection angle (degrees) of the layout a candidate starts from: the
    candidate's own angle, else its ``start_angle``, else the natural one of its net
    type on the design (`fabplan.layout.layout_angle`)."""
    from ..layout.surface_layout import layout_angle

    if candidate.start_angle is not None and candidate.angle is None:
        return float(candidate.start_angle)
    return layout_angle(candidate.net, design, candidate.angle)

