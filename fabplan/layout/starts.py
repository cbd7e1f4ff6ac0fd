"""Several starts of one net on a design, each laid out and glided: the fairest is kept.

Where a glided net's lines kink is decided by the lattice it starts from and by the solve
as much as by the design: the solve moves the lattice's vertices until every star is a
star of the net type, and a lattice whose lines lean away from the principal directions'
symmetry must bend there. Each start after the first varies one choice (`layout_starts`):

- how long the fairness term guides the solve (`SolverSettings.fairness_weight` and
  `fade`): held for a few dozen steps instead of fading after three, the solve keeps the
  lines straighter on its way to the same constraints;
- which principal direction bisects the two families (an S-net at an angle other than
  90 deg is symmetric about either; `LayoutSettings.bisector`);
- how far the principal directions are smoothed before the lattice follows them (a longer
  smoothing gives straighter lattice lines that the solve may bend more);
- whether they are smoothed as a cross field or as a line field (one principal direction
  followed through its turns).

Which one gives the fairest net depends on the design (measured on the corpus of
`benchmarks/designs.py`: each is the best on some designs and the worst on others), so
each is solved and measured (`_fairest`): first by what a net must do (clad the design to
`UNCLAD`, converge, which means fold-free, clad it to `CLAD`), then among the starts whose
panels are as even as the first start's (`_Tried.uneven_against`: straighter lines bought
with stretched edges are no fairer net) by the 95th percentile of the lines' turns
(`fabplan.net.fairness`; the sharpest places are mostly where the design forces them,
near-umbilics, the 95th percentile is the net's fairness as a whole), by a clear margin
over the first start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import FabplanError, InputError, SolverError
from ..solve.solver import SolverSettings
from .settings import MAX_STARTS, SURFACE_TOLERANCE, LayoutSettings
from .surface_layout import EDGE_RANGE, SurfaceLayout, glide, layout_surface

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from ..solve.optimize import OptimizationResult
    from ..solve.solver import IterationRecord

__all__ = ["LayoutStart", "layout_starts", "glide_fairest", "MAX_STARTS"]

#: the fairness term of the "fairness held longer" start: its initial weight, and the
#: factor after every step (it falls below 1e-10 after about 45 steps, within the default
#: 50 iterations; measured on the corpus, 0.7 gave no fairer nets and hit the cap more)
HELD_FAIRNESS, HELD_FADE = 1.0, 0.6
HELD_SOLVER = {"fairness_weight": HELD_FAIRNESS, "fade": HELD_FADE}

#: coverage at which a start counts as cladding the whole design (judged by fairness then),
#: and below which it leaves part of it unclad (judged after every start that clads it)
CLAD, UNCLAD = 0.999, 0.995

#: a start's panels are as even as the first start's when its longest over shortest edge
#: is at most this factor of the first's, its intersection angles stay within this many
#: degrees of the first's range, and it stands off the design by at most this factor of
#: the first's distance (or 1 % of a panel)
EVEN_EDGES, EVEN_ANGLES_DEG, EVEN_OFFSET = 1.15, 5.0, 1.25

#: the starts that straighten the lines keep their edges within the first start's range
#: widened by this factor at both ends (so their edge spread stays within `EVEN_EDGES`)
EVEN_EDGE_MARGIN = 1.05

#: another start replaces the first only when its lines turn less by this many degrees
#: and this share at the 95th percentile (a few tenths of a degree is no fairer net)
CLEARER_DEG, CLEARER_SHARE = 1.0, 0.1


@dataclass(frozen=True)
class LayoutStart:
    """One way to lay a net out and solve it.

    Attributes
    ----------
    name : what it varies, for reports.
    layout : its `LayoutSettings`; None: the first start's layout, solved otherwise.
    solver : `SolverSettings` fields it sets.
    smoothing : its layout smooths the directions over this factor of the length the
        first start's layout used (known only once that layout is made), and tries no
        other; None: as its settings say.
    even : its edges are held within the first start's range of edge lengths (widened by
        `EVEN_EDGE_MARGIN`): a solve that straightens the lines would otherwise slide the
        boundary vertices along the boundary and stretch the edge rows there.
    """

    name: str
    layout: LayoutSettings | None
    solver: dict = field(default_factory=dict)
    smoothing: float | None = None
    even: bool = False


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
    list of `LayoutStart` (the fairness start reuses the first layout).
    """
    starts = [LayoutStart("as set", settings),
              LayoutStart("fairness held longer", None, HELD_SOLVER, even=True)]
    if family is None and not math.isclose(angle, 90.0):
        other = "min" if settings.bisector == "max" else "max"
        starts.append(LayoutStart(f"bisector {other}", replace(settings, bisector=other)))
    if vary_smoothing:
        starts.append(LayoutStart("smoothing doubled", settings, smoothing=2.0))
    if family is None:
        # the principal directions smoothed as a line field (no cross field tried) over the
        # first layout's length, solved as the fairness start: a lattice that follows one
        # principal direction through its turns
        starts.append(LayoutStart("line field", replace(settings, max_smoothing=0.0),
                                  HELD_SOLVER, smoothing=1.0, even=True))
    return starts[:max(int(count), 1)]


@dataclass
class _Tried:
    """A start solved (or refused), with what judges it."""

    start: LayoutStart
    layout: SurfaceLayout | None
    result: OptimizationResult | None
    refusal: Exception | None
    seconds: float

    def _get(self, *keys: str) -> float | None:
        """A number of the result's properties, by its keys (None when absent)."""
        value: Any = None if self.result is None else self.result.properties
        for key in keys:
            value = value.get(key) if isinstance(value, dict) else None
        return None if value is None else float(value)

    @property
    def turn(self) -> float:
        """95th percentile of the lines' turns (degrees)."""
        value = self._get("fairness", "line_turn_deg", "p95")
        return math.inf if value is None else value

    @property
    def edge_spread(self) -> float:
        """Longest edge over the shortest."""
        lo = self._get("edge_length_relative_to_panel", "min")
        hi = self._get("edge_length_relative_to_panel", "max")
        return math.inf if not lo or hi is None else hi / lo

    def tier(self) -> tuple:
        """What comes before fairness: whether it clads the design (`UNCLAD`), how it
        ended, then how much of the design it clads."""
        if self.result is None:
            return (1, 2, 0.0)
        coverage = self._get("coverage") or 0.0
        # a net that leaves a visible part of the design unclad is no start to keep, even
        # converged; a design clad to 99.9 % is clad (what a template study asks), and
        # below that the start that clads more comes first, whatever its lines
        return (int(coverage < UNCLAD), 0 if self.result.converged else 1,
                -round(min(coverage, CLAD), 4))

    def uneven_against(self, other: _Tried) -> str | None:
        """Why its panels are less even than `other`'s, or None when they are about as
        even: straighter lines bought with uneven panels (edges stretched to the solve's
        limits, angles opened) or a net further off the design are no fairer net."""
        if other.result is None or self is other:
            return None
        if self.edge_spread > EVEN_EDGES * other.edge_spread:
            return "its edges are less even"
        angle = ("fairness", "intersection_angle_deg")
        lo, other_lo = self._get(*angle, "min"), other._get(*angle, "min")
        hi, other_hi = self._get(*angle, "max"), other._get(*angle, "max")
        if (lo is not None and other_lo is not None and lo < other_lo - EVEN_ANGLES_DEG) or \
                (hi is not None and other_hi is not None and hi > other_hi + EVEN_ANGLES_DEG):
            return "its lines meet at a wider range of angles"
        off = self._get("distance_to_design_relative_to_panel", "max") or 0.0
        other_off = other._get("distance_to_design_relative_to_panel", "max") or 0.0
        # within the 1 % of a panel a layout is judged by, any gliding net is on the design
        if off > max(EVEN_OFFSET * other_off, 2 * SURFACE_TOLERANCE):
            return "it stands further off the design"
        return None

    def record(self, chosen: bool, uneven: str | None, first: str) -> dict:
        out: dict = {"start": self.start.name, "chosen": chosen,
                     "seconds": round(self.seconds, 3)}
        if self.layout is not None:
            out.update(bisector=self.layout.bisector, smoothing_panels=self.layout.smoothing,
                       direction_field=self.layout.direction_field,
                       # its own layout's time (none for a start solving the first layout)
                       layout_seconds=0.0 if self.start.layout is None else
                       round(sum(self.layout.seconds.values()), 3))
        out.update(self.start.solver)
        if self.start.even:
            out["edges_held_to_first"] = True
        if self.result is None:
            out.update(status="refused", message=str(self.refusal))
            return out
        props = self.result.properties
        angles = (props.get("fairness") or {}).get("intersection_angle_deg") or {}
        out.update(status=self.result.status, coverage=props.get("coverage"),
                   line_turn_p95_deg=self._get("fairness", "line_turn_deg", "p95"),
                   line_turn_max_deg=self._get("fairness", "line_turn_deg", "max"),
                   edge_length_relative_to_panel=props.get("edge_length_relative_to_panel"),
                   intersection_angle_deg={"min": angles.get("min"), "max": angles.get("max")},
                   distance_to_design_relative_to_panel_max=self._get(
                       "distance_to_design_relative_to_panel", "max"),
                   edge_ratio_along_lines_p95=self._get("fairness", "edge_ratio_along_lines", "p95"),
                   less_even_than_first=uneven,
                   compared_with=None if self.start.name == first else first)
        return out


def _edges_of(first: _Tried) -> tuple[float, float]:
    """The edge lengths (panel sizes) a start held as even as `first` keeps: the first's
    range widened by `EVEN_EDGE_MARGIN`, within `EDGE_RANGE` (all of it when the first
    start made no net)."""
    lo = first._get("edge_length_relative_to_panel", "min")
    hi = first._get("edge_length_relative_to_panel", "max")
    if lo is None or hi is None:
        return EDGE_RANGE
    return (max(lo / EVEN_EDGE_MARGIN, EDGE_RANGE[0]), min(hi * EVEN_EDGE_MARGIN, EDGE_RANGE[1]))


def _left_out(plan: list[LayoutStart], angle: float, family: str | None,
              vary_smoothing: bool) -> list[dict]:
    """The starts not in `plan`, each with why."""
    names = {s.name for s in plan}
    why = {"fairness held longer": "not asked for", "smoothing doubled":
           "not asked for" if vary_smoothing else "the smoothing length is set",
           "line field": "not asked for" if family is None else
           "a prescribed family's lattice follows it"}
    if family is not None or math.isclose(angle, 90.0):
        why["bisector"] = ("at 90 deg either principal direction bisects the families"
                           if family is None else "a prescribed family's lattice follows it")
    elif not any(n.startswith("bisector") for n in names):
        why["bisector"] = "not asked for"
    return [{"start": name, "why": text} for name, text in why.items() if name not in names]


def _fairest(tried: list[_Tried]) -> _Tried:
    """The start kept: the best `tier`, then among those whose panels are as even as the
    first solved start's, the lowest 95th percentile of line turns; another start replaces
    the first only where its lines turn clearly less (`CLEARER_DEG`, `CLEARER_SHARE`)."""
    solved = [t for t in tried if t.result is not None]
    first = solved[0]
    best = min(solved, key=lambda t: (t.tier(), t.uneven_against(first) is not None,
                                      round(t.turn, 1)))
    if best is not first and first.tier() == best.tier() and \
            best.turn > min(first.turn - CLEARER_DEG, (1 - CLEARER_SHARE) * first.turn):
        return first
    return best


def glide_fairest(design: DesignSurface, panel_size: float, net: str, *, angle: float,
                  net_angle: float | None = None, family: str | None = None,
                  settings: LayoutSettings | None = None, solver: SolverSettings | None = None,
                  starts: int = MAX_STARTS, vary_smoothing: bool = True,
                  progress: Callable[[IterationRecord], None] | None = None,
                  on_start: Callable[[int, int, str], None] | None = None,
                  max_line_turn: float = 90.0,
                  first_solved: tuple[SurfaceLayout, OptimizationResult] | None = None,
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
    max_line_turn : a converged net's lines turn by at most this (degrees; see
        `fabplan.optimize`).
    first_solved : the first start's layout and glided net, when they were made already
        (with `settings` and `solver` as given): kept as they are, not made again.

    Returns
    -------
    (layout, result): the chosen start's. ``result.properties["layout_starts"]`` lists
    every start with how it ended, its coverage and line turns, and which was chosen.

    Raises
    ------
    InputError
        For `starts` outside 1 .. `MAX_STARTS`.
    FabplanError, ArithmeticError, numpy.linalg.LinAlgError
        When no start made a net: the first start's error.
    """
    if not 1 <= starts <= MAX_STARTS:
        raise InputError(f"starts must lie between 1 and {MAX_STARTS}, got {starts}")
    base = settings or LayoutSettings()
    solver = solver or SolverSettings()
    plan = layout_starts(base, angle, family=family, count=starts,
                         vary_smoothing=vary_smoothing)
    left_out = _left_out(plan, angle, family, vary_smoothing)
    tried: list[_Tried] = []
    first: SurfaceLayout | None = None
    for k, start in enumerate(plan):
        if (start.layout is None or start.smoothing is not None) and first is None:
            left_out.append({"start": start.name, "why": "the first start made no layout"})
            continue
        line_field = start.layout is not None and start.layout.max_smoothing == 0.0
        if line_field and first is not None and first.direction_field == "line":
            left_out.append({"start": start.name, "why": "the first layout is a line field"})
            continue
        if k == 0 and first_solved is not None:
            first = first_solved[0]
            tried.append(_Tried(start, first, first_solved[1], None, 0.0))
            continue
        if on_start is not None:
            on_start(k, len(plan), start.name)
        clock = time.perf_counter()
        layout: SurfaceLayout | None = first if start.layout is None else None
        try:
            if layout is None:
                assert start.layout is not None
                layout_settings = start.layout
                if start.smoothing is not None:
                    assert first is not None
                    length, cap = start.smoothing * first.smoothing, start.layout.max_smoothing
                    # a cross field is tried from that length on (a line field's cap is 0)
                    layout_settings = replace(start.layout, smoothing=length, smoothing_tries=(),
                                              max_smoothing=max(cap, length) if cap > 0 else 0.0)
                layout = layout_surface(design, panel_size, angle=angle, family=family,
                                        settings=layout_settings)
                if k == 0:
                    first = layout
            edges = _edges_of(tried[0]) if start.even and tried else EDGE_RANGE
            result = glide(layout, net, angle=net_angle, settings=replace(solver, **start.solver),
                           progress=progress, edge_range=edges, max_line_turn=max_line_turn)
            tried.append(_Tried(start, layout, result, None, time.perf_counter() - clock))
        except (FabplanError, ArithmeticError, np.linalg.LinAlgError) as exc:
            # this start's lattice does not hold together, or its solve broke down: the
            # others may still make a net
            tried.append(_Tried(start, layout, None, exc, time.perf_counter() - clock))
    solved = [t for t in tried if t.result is not None]
    if not solved:
        raise tried[0].refusal or SolverError("no start made a net")
    best = _fairest(tried)
    assert best.layout is not None and best.result is not None
    best.result.properties["layout_starts"] = [
        t.record(t is best, t.uneven_against(solved[0]), solved[0].start.name) for t in tried]
    best.result.properties["layout_starts_left_out"] = left_out
    layout = best.layout
    if first is not None and layout is not first and "layout" in best.result.properties:
        # the singular points are the design's (its umbilics): said as the least smoothed
        # field has them, whichever start's lattice is kept (a longer smoothing moves them)
        layout = replace(layout, singular_points=first.singular_points,
                         singular_index=first.singular_index)
        best.result.properties["layout"].update(
            singular_points=first.singular_points.tolist(),
            singular_index=first.singular_index.tolist())
    return layout, best.result
