"""The solves `fabplan.solve.optimize` tries, how each ended, and what to tell the user.

An `Attempt` is one solve with its buildability measured; `Attempt.rank` orders them so
that the best is written. `deviation_continuation` approaches a deviation limit the net
type cannot keep to from a loose one; `explain_result` says in one line what stood in the
way of a converged net, where, and what to try.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..net.buildable import BuildReport
from ..net.folds import FoldReport, measure_folds
from ..net.geometry import canonical_stars, intersection_angles
from ..net.mesh import QuadMesh
from .constraints import DeviationBound
from .solver import GuidedProjection, IterationRecord
from .stages import Stage

__all__ = ["Attempt", "result_status", "explain_result", "deviation_continuation",
           "unmet_constraints", "describe_unmet"]


def unmet_constraints(solver: GuidedProjection) -> dict:
    """Hard constraint families whose residual on the net the solve ends with is above
    the tolerance: name -> max |residual| (mean edges for distances, cosines for angles)."""
    last = solver.history[-1].residuals if solver.history else {}
    if solver.status != "converged" and solver.best is not None:
        last = solver.best.residuals       # a solve that stops short ends at its best
    hard = {c.name for c in solver.constraints if c.hard}
    tol = solver.settings.tolerance
    return {name: r for name, r in last.items() if name in hard and r > tol}


def describe_unmet(unmet: dict) -> str:
    """One line naming the constraint families that could not be met and their residuals."""
    return ", ".join(f"{name} residual {r:.2e}" for name, r in sorted(unmet.items()))


@dataclass
class Attempt:
    """One solve of `optimize`: the plain one, or a retry after it folded."""

    name: str                   # "plain", "guards", "smoothed start", ...
    solver: GuidedProjection
    build: BuildReport          # measured on the net it ends with (its folds too)
    stop: Stage | None          # the handle stage its continuation gave up at, if it did

    @property
    def folds(self) -> FoldReport:
        return self.build.folds

    @property
    def succeeded(self) -> bool:
        """Converged and buildable (which includes no degenerate star or collapsed edge)."""
        return self.solver.status == "converged" and self.build.buildable

    @property
    def needs_guards(self) -> bool:
        """Folded, crumpled or degenerate: what the guards and a smoothed start are for."""
        return self.folds.folded or self.build.crumpled or self.folds.degenerate

    def rank(self) -> tuple:
        """Sort key: buildable first (no fold, then no dart or sharp turn, then within the
        deviation limit), then without degenerate stars, then converged, then by hard
        residual."""
        history = self.solver.history
        hard = history[-1].hard_residual if history else np.inf
        return (self.folds.folded, self.build.crumpled, self.build.off_design,
                self.folds.degenerate, self.solver.status != "converged", hard)

    def outcome(self) -> str:
        """A few words: how this solve ended."""
        return result_status(self.solver.status, self.build)


def result_status(solver_status: str, build: BuildReport) -> str:
    """The status of a result: the solver's, or for a net within tolerance what keeps it
    from being built."""
    if solver_status != "converged":
        return solver_status
    if build.folds.folded:
        return "folded"
    if build.crumpled:
        return "crumpled"
    if build.folds.degenerate:
        return "degenerate"
    if build.off_design:
        return "off-design"
    return "converged"


# a deviation limit the net type cannot keep to is approached from a loose one: limits
# shrinking by this factor, from the first at least this many times the asked one (and
# the start's own distance), in at most this many stages; then the smallest limit met is
# narrowed down by this many bisections between it and the first one missed
DEVIATION_FACTOR, DEVIATION_START, DEVIATION_STAGES, DEVIATION_BISECTIONS = 2.0, 32.0, 8, 2


def deviation_continuation(make: Callable[[float], GuidedProjection],
                            judge: Callable[[str, GuidedProjection, float], Attempt],
                            limit: float, start_distance: float,
                            progress: Callable[[IterationRecord], None] | None
                            ) -> tuple[list[Attempt], dict]:
    """Tighten a deviation limit from a loose one towards `limit` (model units), each
    stage continuing from the net of the one before, until a stage does not converge
    buildable within its limit.

    Returns the attempt at the smallest limit the net converged buildable to (or, when
    none did, the first stage's), judged by `judge(name, solver, limit)`, and a record:
    the limits tried, and the smallest at which the net converged (None when none did).
    """
    loosest = max(limit * DEVIATION_START, 1.5 * start_distance)
    stages = int(min(DEVIATION_STAGES, np.ceil(np.log(loosest / limit) / np.log(DEVIATION_FACTOR))))
    limits = [limit * (loosest / limit) ** (k / stages) for k in range(stages, -1, -1)]
    solver = make(limits[0])
    bound = next(c for c in solver.constraints if isinstance(c, DeviationBound))
    tried: list[float] = []
    met: tuple[float, np.ndarray] | None = None
    missed: float | None = None
    for k, value in enumerate(limits):
        bound.limit = value
        if k:
            solver.restart_soft_terms()
        solver.run(callback=progress)
        tried.append(value)
        if not judge("", solver, value).succeeded:
            missed = value
            break
        met = (value, solver.state.x.copy())
    for _ in range(DEVIATION_BISECTIONS if met is not None and missed is not None else 0):
        assert met is not None and missed is not None
        # halfway (in the log) between the smallest limit met and the first missed, from
        # the net that met it
        value = float(np.sqrt(met[0] * missed))
        solver.state.x[:] = met[1]
        bound.limit = value
        solver.restart_soft_terms()
        solver.run(callback=progress)
        tried.append(value)
        if judge("", solver, value).succeeded:
            met = (value, solver.state.x.copy())
        else:
            missed = value
    if met is not None and met[0] != tried[-1]:
        # back to the net that met the smallest limit (the next stage moved the solver on)
        bound.limit = met[0]
        solver.state.x[:] = met[1]
        solver.status = "converged"
    smallest = None if met is None else met[0]
    name = f"continuation to {smallest:.4g}" if smallest is not None else "continuation"
    record = {"limit": limit, "tried": tried, "smallest_converged": smallest}
    return [judge(name, solver, limit)], record


def explain_result(solver: GuidedProjection, status: str, build: BuildReport, start: QuadMesh,
             angle: float | None, attempts: list[Attempt], *, glide: bool = False,
             deviation: dict | None = None) -> str:
    """One line: what stood in the way of a converged net, where, and what to try;
    `attempts` are the solves tried when there were more than one; with `glide` the start
    is a layout's lattice on its design, not the user's net; `deviation` the record of a
    deviation limit's continuation."""
    if status == "converged":
        return ""
    folds = build.folds
    parts = []
    if status in ("folded", "degenerate", "crumpled", "off-design"):
        parts.append(f"the constraints are met but {_obstacles(build)}")
    else:
        unmet = describe_unmet(unmet_constraints(solver))
        parts.append(f"stopped ({status}) with {unmet or 'residuals above the tolerance'}")
        best = solver.best
        if best is not None and best.admissible and build.buildable:
            parts.append("the net written is the best iterate, buildable (no fold, dart or line "
                         "doubling back)")
        if best is not None and best.iteration <= solver.run_start:
            parts.append("no step improved on the start: it may be far from any net of this "
                         "type, or the type may not exist on this surface")
        if not build.buildable:
            parts.append(f"on the net written {_obstacles(build)}")
    if deviation is not None and build.off_design:
        smallest = deviation["smallest_converged"]
        loosest = deviation["tried"][0] if deviation["tried"] else None
        if smallest is not None:
            parts.append(f"tightening the limit from {loosest:.4g} step by step, the net converged "
                         f"buildable down to a limit of {smallest:.4g} (the smallest found): give "
                         f"--max-deviation {smallest:.4g} (model units; --max-deviation-mm in mm) "
                         "or more, or another net type")
        elif loosest is not None:
            parts.append(f"tightening the limit from {loosest:.4g} step by step, no limit gave a "
                         "converged buildable net (none found): this net type may not fit the "
                         "reference; try another net type or a finer net")
    if attempts:
        tried = ", ".join(f"{a.name} {a.outcome()}" for a in attempts)
        written = next(a.name for a in attempts if a.solver is solver)
        parts.append(f"tried {len(attempts)} solves ({tried}); the net written is the {written} one")
        start_folds = measure_folds(start, reference=solver.reference)
        if start_folds.folded and glide:
            parts.append(f"the layout's lattice folds there ({start_folds.describe()}): "
                         "another panel size or net type may avoid it")
        elif glide:
            parts.append("the layout is too far from any net of this type on this design for "
                         "a buildable one near it: try another panel size or net type")
        elif start_folds.folded:
            parts.append(f"the input itself folds ({start_folds.describe()}): repair or smooth it")
        elif not build.off_design or build.crumpled or folds.folded:
            parts.append("the input is too far from any net of this type for a buildable one "
                         "near it: smooth it, or lay a net out on its design with `fabplan layout`")
    if build.crumpled and not attempts:
        parts.append("try the guards from the start (--guards), a smoother input, or "
                     "`fabplan layout` on the design")
    if angle is not None and len(start.stars):
        here = float(np.degrees(np.median(intersection_angles(start.vertices,
                                                              canonical_stars(start.vertices,
                                                                              start.stars)))))
        gap = min(abs(here - angle), abs(180.0 - here - angle))
        if gap > 15.0:
            parts.append(f"the requested angle is {gap:.0f} deg from the start's ({here:.0f} deg); "
                         "try `fabplan layout` on the design, which starts from the right "
                         "directions")
    return "; ".join(parts)


def _obstacles(build: BuildReport) -> str:
    """What keeps a net from being built, with its degenerate stars and collapsed edges."""
    said = [build.describe()]
    if build.folds.degenerate and not build.folds.folded:
        said.append(build.folds.describe())
    return "; ".join(p for p in said if p)
