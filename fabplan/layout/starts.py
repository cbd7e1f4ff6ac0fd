"""Several starts of one net on a design, each laid out and glided: the fairest is kept.

Where a glided net's lines kink is decided by the lattice it starts from and by the solve
as much as by the design: the solve moves the lattice's vertices until every star is a
star of the net type, and a lattice whose lines lean away from the principal directions'
symmetry must bend there. A start varies one of three choices:

- how long the fairness term guides the solve (`SolverSettings.fairness_weight` and
  `fade`): held for a few dozen steps instead of fading after three, the solve keeps the
  lines straighter on its way to the same constraints;
- which principal direction bisects the two families (an S-net at an angle other than
  90 deg is symmetric about either; `LayoutSettings.bisector`);
- how far the principal directions are smoothed before the lattice follows them (a longer
  smoothing gives straighter lattice lines that the solve may bend more).

Which one gives the fairest net depends on the design (measured on the corpus of
`benchmarks/designs.py`: each is the best on some designs and the worst on others), so
each is solved and measured. A start is judged by how it ended (converged, which means
fold-free, first), then by its coverage of the design, then by the 95th percentile of its
lines' turns (`fabplan.net.fairness`): the sharpest places are mostly where the design
forces them (near-umbilics), the 95th percentile is the net's fairness as a whole.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Callable

from ..errors import InputError
from ..solve.solver import SolverSettings
from .settings import MAX_STARTS, LayoutSettings
from .surface_layout import SurfaceLayout, glide, layout_surface

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from ..solve.optimize import OptimizationResult
    from ..solve.solver import IterationRecord

__all__ = ["LayoutStart", "layout_starts", "glide_fairest", "MAX_STARTS"]

#: the fairness term of the "fairness held longer" start: its initial weight, and the
#: factor after every step (it falls below 1e-10 after about 45 steps, within the default
#: 50 iterations; measured on the corpus, 0.7 gave no fairer nets and hit the cap more)
HELD_FAIRNESS, HELD_FADE = 1.0, 0.6

#: coverage at which a start counts as cladding the whole design (judged by fairness then)
CLAD = 0.999


@dataclass(frozen=True)
class LayoutStart:
    """One way to lay a net out and solve it.

    Attributes
    ----------
    name : what it varies, for reports.
    layout : its `LayoutSettings`; None: the first start's layout, solved otherwise.
    solver : `SolverSettings` fields it sets.
    double_smoothing : its layout smooths the directions twice as long as the first
        start's layout did (known only once that layout is made).
    """

    name: str
    layout: LayoutSettings | None
    solver: dict = field(default_factory=dict)
    double_smoothing: bool = False


def layout_starts(settings: LayoutSettings, angle: float, *, family: str | None = None,
                  count: int = MAX_STARTS, vary_smoothing: bool = True) -> list[LayoutStart]:
    """The starts to try, the given settings first.

    Parameters
    ----------
    settings : the layout's settings (the first start).
    angle : the layout's intersection angle (degrees); at 90 deg the bisector is no choice.
    family : a prescribed first family (its lattice follows it: the bisector is no choice).
    count : how many starts at most (1: the given settings alone).
    vary_smoothing : whether a longer smoothing is a start (not when a user set it).

    Returns
    -------
    list of `LayoutStart`, the cheapest first (the fairness start reuses the first layout).
    """
    starts = [LayoutStart("as set", settings),
              LayoutStart("fairness held longer", None,
                          {"fairness_weight": HELD_FAIRNESS, "fade": HELD_FADE})]
    if family is None and not math.isclose(angle, 90.0):
        other = "min" if settings.bisector == "max" else "max"
        starts.append(LayoutStart(f"bisector {other}", replace(settings, bisector=other)))
    if vary_smoothing:
        starts.append(LayoutStart("smoothing doubled", settings, double_smoothing=True))
    return starts[:max(int(count), 1)]


@dataclass
class _Tried:
    """A start solved, with what judges it."""

    start: LayoutStart
    layout: SurfaceLayout | None
    result: OptimizationResult | None
    refusal: InputError | None
    seconds: float

    def rank(self) -> tuple:
        r = self.result
        if r is None:
            return (3, 0.0, math.inf)
        coverage = float(r.properties.get("coverage") or 0.0)
        turn = (r.properties.get("fairness") or {}).get("line_turn_deg", {}).get("p95")
        # a design clad to 99.9 % is clad (what a template study asks); below that the
        # start that clads more comes first, whatever its lines
        return (0 if r.converged else 1, -round(min(coverage, CLAD), 4),
                math.inf if turn is None else round(turn, 1))

    def record(self, chosen: bool) -> dict:
        out: dict = {"start": self.start.name, "chosen": chosen,
                     "seconds": round(self.seconds, 3)}
        if self.layout is not None:
            out.update(bisector=self.layout.bisector, smoothing_panels=self.layout.smoothing,
                       direction_field="cross" if self.layout.direction_symmetry == 4 else "line")
        out.update(self.start.solver)
        if self.result is None:
            out.update(status="refused", message=str(self.refusal))
            return out
        turn = (self.result.properties.get("fairness") or {}).get("line_turn_deg", {})
        out.update(status=self.result.status, coverage=self.result.properties.get("coverage"),
                   line_turn_p95_deg=turn.get("p95"), line_turn_max_deg=turn.get("max"))
        return out


def glide_fairest(design: DesignSurface, panel_size: float, net: str, *, angle: float,
                  net_angle: float | None = None, family: str | None = None,
                  settings: LayoutSettings | None = None, solver: SolverSettings | None = None,
                  starts: int = MAX_STARTS, vary_smoothing: bool = True,
                  progress: Callable[[IterationRecord], None] | None = None,
                  on_start: Callable[[int, int, str], None] | None = None,
                  ) -> tuple[SurfaceLayout, OptimizationResult]:
    """Lay out and glide a net from each of `layout_starts` and keep the fairest.

    Parameters
    ----------
    design : the surface; panel_size : target edge length (model units).
    net : the net type (`fabplan.solve.net_types`).
    angle : the layout's intersection angle (degrees; `layout_angle`).
    net_angle : the net type's own angle parameter (isogonal nets), or None.
    family : a prescribed first family (see `layout_surface`).
    settings : `LayoutSettings` of the first start; solver : `SolverSettings`.
    starts : how many starts at most; 1 is `layout_surface` then `glide`.
    vary_smoothing : whether a longer smoothing is one of them (see `layout_starts`).
    progress : the solver's callback, for every start's iterations.
    on_start : called as ``on_start(k, n, name)`` before start k (0-based) of n.

    Returns
    -------
    (layout, result): the chosen start's. ``result.properties["layout_starts"]`` lists
    every start with how it ended, its coverage and line turns, and which was chosen.

    Raises
    ------
    InputError
        When every start was refused: the first start's reason.
    """
    base = settings or LayoutSettings()
    solver = solver or SolverSettings()
    plan = layout_starts(base, angle, family=family, count=starts,
                         vary_smoothing=vary_smoothing)
    tried: list[_Tried] = []
    first: SurfaceLayout | None = None
    for k, start in enumerate(plan):
        if (start.layout is None or start.double_smoothing) and first is None:
            continue          # the first start made no layout to solve otherwise or double
        if on_start is not None:
            on_start(k, len(plan), start.name)
        clock = time.perf_counter()
        layout: SurfaceLayout | None = first if start.layout is None else None
        try:
            if layout is None:
                assert start.layout is not None
                layout_settings = start.layout
                if start.double_smoothing:
                    assert first is not None
                    length = 2 * first.smoothing
                    layout_settings = replace(start.layout, smoothing=length, smoothing_tries=(),
                                              max_smoothing=max(start.layout.max_smoothing, length))
                layout = layout_surface(design, panel_size, angle=angle, family=family,
                                        settings=layout_settings)
                if k == 0:
                    first = layout
            result = glide(layout, net, angle=net_angle, settings=replace(solver, **start.solver),
                           progress=progress)
            tried.append(_Tried(start, layout, result, None, time.perf_counter() - clock))
        except InputError as exc:      # this start's lattice does not hold together
            tried.append(_Tried(start, layout, None, exc, time.perf_counter() - clock))
    solved = [t for t in tried if t.result is not None]
    if not solved:
        refusal = tried[0].refusal
        assert refusal is not None
        raise refusal
    best = min(solved, key=_Tried.rank)      # the first of equals: the given settings
    assert best.layout is not None and best.result is not None
    best.result.properties["layout_starts"] = [t.record(t is best) for t in tried]
    return best.layout, best.result
