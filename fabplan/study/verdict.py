"""The verdict on a study candidate and its cost: pure functions of its measured metrics,
the limits and the cost weights, so that a changed limit or weight changes the verdict
and the ranking without a new run (and a kept candidate is judged again as a fresh one
is: `fabplan.study.cache`)."""

from __future__ import annotations

import math

from ..fabricate.molds.mold_shapes import PANEL_TYPES
from ..report.html import counted
from .checks import Advice, nice_value
from .checks import check as _check
from .definition import CostWeights, Limits

__all__ = ["verdict", "smaller_panels", "BEND_SHARE", "candidate_cost", "every_panel_flat", "differ_by"]


def verdict(metrics: dict, limits: Limits, *, panel_size: float | None = None,
            units: str = "") -> list[dict]:
    """The checks of one candidate's measured `metrics` against the `limits`.

    Parameters
    ----------
    metrics : dict, the candidate's measured metrics.
    limits : `Limits`, the limits it is judged by.
    panel_size : float, optional, the panel size it was laid out with (model units): with
        it, failed mold gaps, steps and kinks are told the panel sizes at which they might
        pass (`smaller_panels`, `_design_bend`).
    units : str, the design's units, for those words.

    Returns
    -------
    list of dicts ``{limit, bound, measured, ok, text}``, one per limit that applies;
    `text` says in plain words what was measured against what.
    """
    checks = []
    res = metrics["sphere_residual_relative_max"]
    # a net that met its constraints beyond the deviation limit is a net: the deviation
    # check fails for it (and says to what the limit would have to be relaxed)
    met = metrics["converged"] or metrics["status"] == "off-design"
    res_ok = res is not None and res <= limits.max_sphere_residual and met
    state = _solve_state(metrics)
    checks.append(_check(
        "max_sphere_residual", limits.max_sphere_residual, res, res_ok,
        f"the solve {state} after {metrics['iterations']} iterations"
        + (f", short on {_unmet_words(unmet)}" if (unmet := metrics.get("unmet")) and not met
           else "")
        + f"; largest sphere residual {_g(res)} of an edge (limit {limits.max_sphere_residual:g})",
        advice=None if met else _unconverged_advice(metrics, panel_size, units)))
    checks.append(_deviation_check(metrics, limits))
    checks += _mold_checks(metrics["molds"], limits, smaller_panels(
        metrics["molds"], limits, panel_size, units, metrics.get("panels"),
        (metrics.get("boundary_panels") or {}).get("step_max_mm")))
    if limits.planar_panels:
        p = metrics["planarity_mm"]["max"]
        checks.append(_check(
            "planarity_tolerance_mm", limits.planarity_tolerance_mm, p,
            p <= limits.planarity_tolerance_mm,
            (f"the panels are planar within {p:.2f} mm" if p <= limits.planarity_tolerance_mm
             else f"the panels are up to {p:.2f} mm out of plane")
            + f" (planar panels required: tolerance {limits.planarity_tolerance_mm:g} mm)"))
    if limits.min_coverage is not None:
        cov = metrics["coverage"]
        checks.append(_check("min_coverage", limits.min_coverage, cov, cov >= limits.min_coverage,
                             f"the panels cover {100 * cov:.1f} % of the design (limit at least "
                             f"{100 * limits.min_coverage:g} %)"))
    if limits.max_kink_deg is not None:
        k = metrics["kink_deg"]["max"]
        checks.append(_check("max_kink_deg", limits.max_kink_deg, k, k <= limits.max_kink_deg,
                             f"the largest kink between neighbouring panels is {k:.2f} deg (limit "
                             f"{limits.max_kink_deg:g} deg)",
                             advice=_design_bend(metrics, panel_size, units,
                                                 limits.max_kink_deg)))
    turn = (metrics.get("line_turn_deg") or {}).get("max")
    if limits.max_line_turn_deg is not None and turn is not None:
        checks.append(_check("max_line_turn_deg", limits.max_line_turn_deg, turn,
                             turn <= limits.max_line_turn_deg,
                             f"the net's lines turn in the surface by up to {turn:.2f} deg at a "
                             f"vertex (limit {limits.max_line_turn_deg:g} deg)"))
    strips = metrics.get("strips")
    if strips is not None:
        checks += _strip_checks(strips, limits)
    if not met:
        # a solve that did not converge is no net yet: its other measures say how far the
        # unfinished net is, not a limit at which it would be feasible
        for c in checks:
            c["relax_to"] = None
    return checks


def _deviation_check(metrics: dict, limits: Limits) -> dict:
    """The check of the net's and its boundary panels' largest deviation from the design."""
    dev = metrics["deviation_mm"]["max"]
    edge = (metrics.get("boundary_panels") or {}).get("deviation_max_mm")
    both = metrics["largest_deviation_mm"]
    own = (metrics.get("boundary_panels") or {}).get("own_molds", 0)
    return _check(
        "max_deviation_mm", limits.max_deviation_mm, both, both <= limits.max_deviation_mm,
        f"the net deviates up to {dev:.1f} mm from the design"
        + (f" at its free tips (its other vertices within {held:.1f} mm)"
           if (held := metrics["deviation_mm"].get("held_max")) is not None
           and held < 0.9 * dev and dev >= 0.1 * limits.max_deviation_mm else "")
        + (f", its boundary panels as cut from their molds up to {edge:.1f} mm"
           + (f" ({counted(own, 'boundary panel')} on molds of their own)" if own else "")
           if edge is not None else "")
        + f" (limit {limits.max_deviation_mm:g} mm)",
        advice=_deviation_advice(metrics, limits, dev, edge))


def _deviation_advice(metrics: dict, limits: Limits, dev: float, edge: float | None
                      ) -> str | None:
    """What to try when a converged net is too far from the design, where the general
    advice would mislead: a characteristic conjugate net on a design partly saddle-shaped
    (it cannot exist there), or a net within the limit whose boundary panels are not."""
    saddle = metrics.get("design_anticlastic") or 0.0
    if saddle > 0.02:
        return (f"trim the design to where it curves the same way in every direction: "
                f"{100 * saddle:.0f} % of it is saddle-shaped, where no characteristic "
                "conjugate net exists (its directions are real only where the Gaussian "
                "curvature is positive); or another net type there")
    if edge is not None and dev <= limits.max_deviation_mm < edge:
        # the net keeps to the limit, the boundary panels cut from its molds do not
        return ("a smaller panel size: the net keeps within the limit, its boundary panels "
                "as cut from their molds do not")
    return None


def _unmet_words(unmet: dict) -> str:
    """The families a solve left unmet, the three worst with their residuals: ``angle
    (0.015), radius (0.011)``."""
    worst = sorted(unmet.items(), key=lambda kv: -kv[1])
    more = f" and {len(worst) - 3} more" if len(worst) > 3 else ""
    return ", ".join(f"{name} ({_g(r)})" for name, r in worst[:3]) + more


#: the most of the design's curvature a panel may span, in degrees, before the advice on
#: a solve that gave no net names a smaller panel size (`_design_bend`)
PANEL_SPAN_DEG = 30.0

#: the share of the design's area, its most curved, whose radius is not the design's bend
#: radius (``design_bend_radius``: `fabplan.study.candidate_measure.bend_radius`)
BEND_SHARE = 0.05


def _design_bend(metrics: dict, panel_size: float | None, units: str, limit_deg: float
                 ) -> Advice | None:
    """A smaller panel size where the design's own curvature turns a panel by more than
    `limit_deg` (degrees): neighbouring panels meet at about their size over the radius
    the design curves with (``design_bend_radius``); None where it does not, or unknown."""
    radius = metrics.get("design_bend_radius")
    if not radius or panel_size is None or math.degrees(panel_size / radius) <= limit_deg:
        return None
    size = nice_value(math.radians(limit_deg) * radius, up=False)
    return Advice(f"a smaller panel size, at most about {size:g} {units} (now {panel_size:g} "
                  f"{units}): the design curves with radii down to {_length(radius)} {units} over "
                  f"its most curved {100 * BEND_SHARE:g} %, of which a panel spans "
                  f"{math.degrees(panel_size / radius):.0f} deg, and {limit_deg:g} deg at "
                  "that size", size)


def _length(value: float) -> str:
    """A length to three digits, without an exponent where it has more: ``3,650``."""
    return f"{value:,.0f}" if abs(value) >= 1000 else f"{value:.3g}"


def _unconverged_advice(metrics: dict, panel_size: float | None = None, units: str = ""
                        ) -> Advice:
    """What to try for a solve that did not give a net, from what it tried already; first
    a smaller panel size where a panel spans more than `PANEL_SPAN_DEG` of the design."""
    sharp = _design_bend(metrics, panel_size, units, PANEL_SPAN_DEG)
    advice = _retry_advice(metrics)
    return Advice(advice) if sharp is None else Advice(f"{sharp.text}; or {advice}",
                                                       sharp.panel_size)


def _retry_advice(metrics: dict) -> str:
    """What to try for a solve that did not give a net at this panel size."""
    search, status = metrics.get("deviation_search"), metrics["status"]
    if status in ("folded", "crumpled", "degenerate"):
        # it met its constraints: longer solves would not help, another lattice may
        return (f"another angle or panel size, or a design smoothed where the net is {status}: "
                "the net met its constraints but cannot be built as it is")
    if search and search["smallest_converged_mm"] is None:
        return (f"another net type: no net of this type converged buildable on this design "
                f"within {search['loosest_mm']:,.0f} mm of it, the loosest deviation its solve "
                "tried, so no limit relaxed makes it feasible")
    starts = metrics.get("layout_starts", 1)
    if status == "stagnated":
        # it stopped making progress before its iterations ran out: more would not help
        return ("another angle or panel size"
                + ("" if starts > 1 else ", or several layout starts (layout_starts)")
                + ": the solve stagnated (it stopped making progress"
                + (f" from {starts} layout starts" if starts > 1 else "")
                + "), so more iterations would not help")
    if starts > 1:
        return ("let the solve run longer (max_iterations) or try another angle or panel size: "
                f"the net did not converge from {starts} layout starts")
    return ("let the solve run longer (max_iterations), lay the design out from several "
            "starts (layout_starts) or try another angle or panel size: the net did not "
            "converge")


def _solve_state(metrics: dict) -> str:
    """How the solve ended, in words: converged, stopped, or met its constraints on a net
    that folds, is degenerate, crumpled or only off the design."""
    state = "converged" if metrics["converged"] else f"stopped ({metrics['status']})"
    folds = metrics.get("folds")
    if folds and metrics["status"] in ("folded", "degenerate"):
        state = (f"met its constraints on a net that folds ("
                 f"{counted(folds['flipped_faces'], 'flipped face')}, "
                 f"{counted(folds['fold_edges'], 'fold edge')})" if folds["folded"] else
                 f"met its constraints on a degenerate net ("
                 f"{counted(folds['degenerate_stars'], 'star')} with their lines run together, "
                 f"{counted(folds['collapsed_edges'], 'collapsed edge')})")
    build = metrics.get("buildable")
    if build and metrics["status"] in ("crumpled", "off-design"):
        state = (f"met its constraints on a crumpled net ("
                 f"{counted(build['nonconvex_faces'], 'non-convex face')}, "
                 f"{counted(build['sharp_line_turns'], 'vertex', 'vertices')} where a line "
                 "turns too much)" if metrics["status"] == "crumpled" else
                 "met its constraints only off the design (held within the limit it cannot "
                 "be this net type; the nearest it came is below)")
    if metrics.get("status_note"):
        state += f" ({metrics['status_note']})"
    return state


def smaller_panels(molds: dict, limits: Limits, panel_size: float | None, units: str,
                   panels: int | None, boundary_step: float | None = None) -> Advice | None:
    """What to try when panels fit no mold or neighbouring molds step apart, with the
    panel sizes at which they might not.

    A panel's gap to its mold, and so the step between neighbouring molds, shrinks with
    the panel size to a power measured between 1.1 (a gentle wavy facade's gap, 2 to 1 m
    panels) and 2.6 (a sharper one's, 3 to 1.5 m). So two sizes are given: the one at
    which the largest would be within its limit were it to shrink with the square of the
    size, and the one were it to shrink in proportion. A largest step at the boundary
    panels is named instead of counted: their slivers, cut from the design's edge, come at
    every panel size (the net's own steps are not known apart then).

    Parameters
    ----------
    molds : a candidate's ``metrics["molds"]`` (gap and step in mm).
    limits : the limits it is judged by.
    panel_size : its panel size (model units); None gives None (the general advice).
    units : the design's units, for the text.
    panels : its panel count, for the counts at the sizes given.
    boundary_step : the largest step at its boundary panels (mm), if it has them.

    Returns
    -------
    `Advice` (its panel size the first of the two), or None when the gap and the step are
    within their limits (or unrated).

    Examples
    --------
    >>> molds = {"failures": 12, "max_deviation_mm": 23.0, "max_panel_step_mm": 43.0}
    >>> limits = Limits(max_deviation_mm=150.0, mold_tolerance_mm=1.0)
    >>> print(smaller_panels(molds, limits, 2.0, "m", 96).text)  # doctest: +NORMALIZE_WHITESPACE
    a larger mold_tolerance_mm, or a smaller panel size (now 2 m, 96 panels): the largest
    gap and step are up to 23 times their limits, so 0.41 m (2,300 panels) were they to
    shrink with the square of the panel size, 0.086 m (52,000 panels) were they to shrink
    in proportion
    """
    tolerance, step_limit = limits.mold_tolerance_mm, limits.panel_step_limit_mm
    gap, step = float(molds["max_deviation_mm"]), float(molds.get("max_panel_step_mm") or 0.0)
    if not (math.isfinite(gap) and math.isfinite(step)):
        return None
    over = {"gap": gap / tolerance} if molds["failures"] else {}
    at_boundary = step > step_limit and boundary_step is not None and boundary_step >= step
    if step > step_limit and not at_boundary:
        over["step"] = step / step_limit
    # the step's own limit, when it is set apart from the mold tolerance's
    larger = "max_panel_step_mm" if limits.max_panel_step_mm is not None and "gap" not in over \
        else "mold_tolerance_mm"
    edge = ("the largest step is at the boundary panels, whose slivers come at every panel "
            "size: see boundary-panels.csv") if at_boundary else ""
    if not over or panel_size is None:
        return Advice(f"a larger {larger}, or trim the boundary panels: {edge}") if edge else None
    worst = max(over.values())
    square, proportion = (nice_value(panel_size / worst ** power, up=False)
                          for power in (0.5, 1.0))

    def many(count: float) -> str:
        return f"{count:,.0f} panel{'' if count == 1 else 's'}"

    def at(size: float) -> str:
        return f"{size:g} {units}" + (
            f" ({many(nice_value(panels * (panel_size / size) ** 2, up=True))})" if panels else "")

    measured = " and ".join(over)
    return Advice(f"a larger {larger}, or a smaller panel size (now {panel_size:g} {units}"
            f"{', ' + many(panels) if panels else ''}): the largest {measured} "
            f"{'are' if len(over) > 1 else 'is'} up to {worst:.3g} times "
            f"{'their limits' if len(over) > 1 else 'its limit'}, so {at(square)} were "
            f"{'they' if len(over) > 1 else 'it'} to shrink with the square of the panel size, "
            f"{at(proportion)} were {'they' if len(over) > 1 else 'it'} to shrink in proportion"
            + (f"; {edge}" if edge else ""), square)


def _mold_checks(molds: dict, limits: Limits, smaller: Advice | None = None) -> list[dict]:
    """The checks of a candidate's molds (``metrics["molds"]``, `mold_metrics`): every
    panel fits a mold, neighbouring molds meet, and (when limited) how many molds;
    `smaller` the advice on the first two (`smaller_panels`)."""
    checks = []
    panels_fit = molds["failures"] == 0
    checks.append(_check(
        "mold_tolerance_mm", limits.mold_tolerance_mm, molds["max_deviation_mm"], panels_fit,
        f"every panel fits its mold within {limits.mold_tolerance_mm:g} mm (largest gap "
        f"{molds['max_deviation_mm']:.2f} mm)" if panels_fit else
        f"{counted(molds['failures'], 'panel fits', 'panels fit')} no mold within "
        f"{limits.mold_tolerance_mm:g} mm", advice=smaller))
    step = molds.get("max_panel_step_mm")
    if step is not None:
        step_limit = limits.panel_step_limit_mm
        # flat panels are cut, not molded: their own edges step
        between, apart = ("them", "neighbouring panels") if every_panel_flat(molds) else \
            ("their molds", "the molds of neighbouring panels")
        checks.append(_check(
            "max_panel_step_mm", step_limit, step, step <= step_limit,
            f"neighbouring panels meet: the largest step between {between} is {step:.2f} mm "
            f"(limit {step_limit:g} mm)" if step <= step_limit else
            f"{apart} step up to {step:.2f} mm apart at "
            f"{counted(molds['panel_steps_over'], 'shared edge')} (limit {step_limit:g} mm)",
            advice=smaller))
    if limits.max_molds is not None:
        n = molds["count"]
        bent = molds.get("panel_classes") is not None
        needs = ("it needs no molds: all panels are flat" if every_panel_flat(molds) else
                 "it needs no molds: no panel is molded") if n == 0 else \
            f"its {'molded' if bent else 'curved'} panels need {counted(n, 'mold')}"
        if bent:
            needs += f" ({molds['saved']} saved by {molds['material']})"
        checks.append(_check("max_molds", limits.max_molds, n, n <= limits.max_molds,
                             f"{needs} (limit {limits.max_molds})"))
    return checks


def _strip_checks(strips: dict, limits: Limits) -> list[dict]:
    """The checks of a candidate's strips (``metrics["strips"]``) against the strip limits
    that are set: radii, congruence, twist (always: `fabplan strips` checks it too),
    sheets."""
    checks = []
    if limits.min_strip_radius_mm is not None:
        r = strips["min_radius_mm"]
        checks.append(_check(
            "min_strip_radius_mm", limits.min_strip_radius_mm, r,
            r >= limits.min_strip_radius_mm,
            f"the smallest strip radius is {_mm(r)} (limit at least "
            f"{limits.min_strip_radius_mm:g} mm)"))
    if limits.max_strip_radius_mm is not None:
        r = strips["max_radius_mm"]
        checks.append(_check(
            "max_strip_radius_mm", limits.max_strip_radius_mm, r,
            r <= limits.max_strip_radius_mm,
            f"the largest strip radius is {_mm(r)} (limit at most "
            f"{limits.max_strip_radius_mm:g} mm)"))
    if limits.congruent_strips:
        d, tol = strips["congruence_deviation_mm"], limits.congruence_tolerance_mm
        ok = d <= tol
        checks.append(_check(
            "congruent_strips", tol, d, ok,
            ("all strip parts are congruent" if ok else "the strip parts are not congruent")
            + f" (they differ from one common arc {differ_by(d)}; congruence "
            f"tolerance {tol:g} mm)"))
    twist = strips.get("max_twist_deg_per_m")       # absent from candidates kept before it
    if twist is not None:
        checks.append(_check(
            "max_twist_deg_per_m", limits.max_twist_deg_per_m, twist,
            twist <= limits.max_twist_deg_per_m,
            f"the strips twist by up to {twist:.1f} deg/m (limit {limits.max_twist_deg_per_m:g} "
            "deg/m)"))
    if limits.max_sheets is not None:
        n = strips["sheets"]
        checks.append(_check("max_sheets", limits.max_sheets, n, n <= limits.max_sheets,
                             f"the strips nest on {counted(n, 'sheet')} (limit "
                             f"{limits.max_sheets})"))
    return checks


def candidate_cost(metrics: dict, weights: CostWeights, *,
                   charge_sheets: bool = True) -> tuple[float, dict]:
    """The ranking cost of a candidate and its terms (see `CostWeights`).

    Molds are counted for the curved panels only (`mold_metrics`). With `charge_sheets`
    false the sheets term is 0: strip sheets are then reported, not charged (see
    `judge_study`).

    Examples
    --------
    >>> m = {"molds": {"count": 2, "panel_types": {"planar": 10}}, "coverage": 1.0,
    ...      "strips": {"sheets": 3}, "deviation_mm": {"max": 5.0}, "largest_deviation_mm": 5.0}
    >>> candidate_cost(m, CostWeights())[0], candidate_cost(m, CostWeights(), charge_sheets=False)[0]
    (230.0, 215.0)
    """
    types = metrics["molds"]["panel_types"]
    classes = metrics["molds"].get("panel_classes")
    strips = metrics.get("strips")
    # panels are counted for the whole design: a net with gaps must not look cheaper
    whole = 1.0 / max(min(metrics["coverage"], 1.0), 1e-6)
    bent = {}
    if classes is not None:
        # with a material: flat, cold-bent and roll-bent panels by class, the molded ones by
        # their type (a molded panel within the tolerance of a plane is priced flat)
        molded = metrics["molds"]["molded_types"]
        types = {PANEL_TYPES[0]: classes["flat"] + molded.get(PANEL_TYPES[0], 0),
                 PANEL_TYPES[1]: molded.get(PANEL_TYPES[1], 0),
                 PANEL_TYPES[2]: molded.get(PANEL_TYPES[2], 0)}
        bent = {"cold-bent panels": weights.cold_bent_panel * classes["cold_bent"] * whole,
                "roll-bent panels": weights.roll_bent_panel * classes["roll_bent"] * whole}
    terms = {
        "molds": weights.mold * metrics["molds"]["count"],
        "flat panels": weights.flat_panel * types.get(PANEL_TYPES[0], 0) * whole,
        **bent,
        "single curved panels": weights.single_curved_panel * types.get(PANEL_TYPES[1], 0) * whole,
        "double curved panels": weights.double_curved_panel * types.get(PANEL_TYPES[2], 0) * whole,
        "sheets": weights.sheet * strips["sheets"] if strips and charge_sheets else 0.0,
        "deviation": weights.deviation_mm * metrics["largest_deviation_mm"],
    }
    return float(sum(terms.values())), terms


def every_panel_flat(molds: dict) -> bool:
    """Whether every panel of a candidate is flat (`mold_metrics`): no curved panel, and
    with a material every panel of the class ``flat`` (a material's flatness tolerance may
    leave a nearly flat panel to be bent cold).

    Examples
    --------
    >>> every_panel_flat({"all_panels_flat": True})
    True
    >>> every_panel_flat({"all_panels_flat": True, "panel_classes": {"flat": 3, "cold_bent": 1,
    ...     "roll_bent": 0, "molded": 0}})
    False
    """
    classes = molds.get("panel_classes")
    return bool(molds.get("all_panels_flat")) and (
        classes is None or classes["flat"] == sum(classes.values()))


def _g(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2g}"


def _mm(value: float) -> str:
    return "infinite (straight)" if math.isinf(value) else f"{value:.0f} mm"


def differ_by(value: float) -> str:
    """How much strip parts differ (mm), in words with the digits it needs.

    Examples
    --------
    >>> [differ_by(v) for v in (0.0, 3e-12, 0.0123, 4.5)]
    ['by 0 mm', 'by less than 0.001 mm', 'by up to 0.012 mm', 'by up to 4.50 mm']
    """
    if value == 0:
        return "by 0 mm"
    if value < 0.001:
        return "by less than 0.001 mm"
    return f"by up to {value:.2g} mm" if value < 0.1 else f"by up to {value:.2f} mm"
