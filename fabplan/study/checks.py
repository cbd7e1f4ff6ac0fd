"""The checks of a study candidate against its limits, and what they say: how much room
each leaves (its margin), which binds hardest, how far an infeasible candidate is from
feasible and which limits, relaxed to what, would make it so."""

from __future__ import annotations

import math
from typing import NamedTuple

from ..fabricate.limits import LIMITS

__all__ = ["Advice", "check", "binding_check", "violation", "nearness", "relaxation_text",
           "feasible_with", "next_steps", "advised_panel_size", "out_of_range", "ANGLE_LIMITS",
           "nice_value", "LIMIT_NAMES", "limit_words", "limit_value"]

#: every limit of a study in words, with its unit; those the commands also check
#: (`fabplan.fabricate.limits.LIMITS`) in the same words
LIMIT_NAMES = {
    "max_deviation_mm": (LIMITS["max_deviation_mm"].words, LIMITS["max_deviation_mm"].unit),
    "mold_tolerance_mm": ("largest gap between a panel and its mold", "mm"),
    "max_panel_step_mm": ("largest step between neighbouring panels' molds", "mm"),
    "max_molds": ("most molds", "molds"),
    "planar_panels": ("panels must be flat", ""),
    "planarity_tolerance_mm": ("largest distance of a panel corner from the panel's plane", "mm"),
    "max_kink_deg": ("largest kink between neighbouring panels", "deg"),
    "max_line_turn_deg": ("largest turn of a net line at a vertex", "deg"),
    "min_strip_radius_mm": ("smallest arc radius of an unrolled strip", "mm"),
    "max_strip_radius_mm": ("largest arc radius of an unrolled strip", "mm"),
    "max_sheets": ("most sheets of strip material", "sheets"),
    "max_twist_deg_per_m": ("largest twist of a lamella strip", "deg/m"),
    "congruent_strips": ("strips must be congruent (one bending jig)", ""),
    "congruence_tolerance_mm": (LIMITS["congruence_tolerance_mm"].words,
                                LIMITS["congruence_tolerance_mm"].unit),
    "min_coverage": ("smallest share of the design covered by panels", "%"),
    # the check of a solve: it fails for a solve that did not converge, whatever the residual
    "max_sphere_residual": ("converged, with a largest sphere residual (of the mean edge "
                            "length)", "ratio"),
}


def limit_words(limit: str, value: float) -> str:
    """A limit set to `value`, in words.

    Examples
    --------
    >>> limit_words("max_deviation_mm", 260.0)
    'a largest deviation from the design of 260 mm'
    >>> limit_words("max_molds", 228), limit_words("congruent_strips", 8.4)
    ('at most 228 molds', 'a congruence tolerance of the strips of 8.4 mm')
    """
    if limit in ("max_molds", "max_sheets"):
        return f"at most {value:g} {LIMIT_NAMES[limit][1]}"
    name = "congruence tolerance of the strips" if limit == "congruent_strips" else \
        LIMIT_NAMES.get(limit, (limit,))[0]
    return f"a {name} of {limit_value(limit, value)}"


def limit_value(limit: str, value: float) -> str:
    """A value of a limit with its unit: ``260 mm``, ``95 %``, ``100`` (a count)."""
    unit = "mm" if limit == "congruent_strips" else LIMIT_NAMES.get(limit, ("", ""))[1]
    if unit == "%":
        return f"{100 * value:g} %"
    if unit in ("molds", "sheets", "ratio", ""):
        return f"{value:g}"
    return f"{value:g} {unit}"


class Advice(NamedTuple):
    """What to try for a failed check (`text`), and the panel size it names first, the
    largest of those it names (`panel_size`, model units; None: it names none)."""

    text: str
    panel_size: float | None = None


def check(limit: str, bound: float, measured: float | None, ok: bool, text: str, *,
          advice: str | Advice | None = None) -> dict:
    """One check: with its `margin` (the share of the bound left, negative when it fails)
    and, when it fails, `relax_to` (the value of the limit at which it would pass),
    `advice` (what to try, when the candidate's own record says more than `next_steps`'s
    general word) and `advised_panel_size` (the panel size that advice names first, model
    units, or None)."""
    if isinstance(advice, str):
        advice = Advice(advice)
    lower = limit.startswith("min_")          # min_*: the measured value must reach the bound
    margin = None
    if measured is not None and bound and math.isfinite(measured) and math.isfinite(bound):
        margin = float((measured - bound) / abs(bound) if lower else (bound - measured) / abs(bound))
    if not ok and margin is not None and margin >= 0:
        # failed on another ground than its measure (a solve that did not converge, with
        # its sphere residual within the limit): no share of the limit is left to rate
        margin = None
    relax_to = None
    # a solve that did not converge is no limit to relax: it is no net yet
    if not ok and margin is not None and measured is not None and limit != "max_sphere_residual":
        relax_to = (int(math.ceil(measured)) if limit in ("max_molds", "max_sheets")
                    else nice_value(float(measured), up=not lower))
        beyond = out_of_range(limit, relax_to)
        if beyond is not None:
            # a study file refuses that value: no relaxation, and the advice says why
            relax_to = None
            other = advice or (Advice(_TRY[limit]) if limit in _TRY else None)
            advice = Advice(f"no relaxation: {limit_words(limit, float(measured))} would be "
                            f"needed, and the limit {beyond}"
                            + (f"; or {other.text}" if other else ""),
                            None if other is None else other.panel_size)
    return {"limit": limit, "bound": bound, "measured": measured, "ok": bool(ok), "text": text,
            "margin": margin, "relax_to": relax_to,
            "advice": None if ok or advice is None else advice.text,
            "advised_panel_size": None if ok or advice is None else advice.panel_size}


#: the limits whose range a study file checks (`fabplan.study.spec`), by the command-line
#: option they are handed to
_LIMIT_OPTIONS = {"mold_tolerance_mm": "--tolerance-mm", "max_panel_step_mm": "--step-limit",
                  "max_line_turn_deg": "--max-line-turn", "congruent_strips": "--tolerance"}


#: the limits that are angles between neighbouring panels or along a line
ANGLE_LIMITS = ("max_kink_deg", "max_line_turn_deg")


def out_of_range(limit: str, value: float) -> str | None:
    """Why a study file refuses `limit` set to `value` (``must be at most 10 mm ...``),
    or None where it takes it."""
    from ..io.parameters import OPTIONS

    if limit in ANGLE_LIMITS and not 0 < value < 180:
        return "must lie between 0 and 180 degrees"
    option = _LIMIT_OPTIONS.get(limit)
    return None if option is None else OPTIONS[option].reason(value)


def nice_value(value: float, *, up: bool) -> float:
    """`value` rounded to two significant digits, up (or down), so that a limit set to it
    is met.

    Examples
    --------
    >>> nice_value(357.8, up=True), nice_value(0.0137, up=True), nice_value(212.0, up=False)
    (360.0, 0.014, 210.0)
    """
    if value == 0 or not math.isfinite(value):
        return value
    step = 10 ** (math.floor(math.log10(abs(value))) - 1)
    rounded = (math.ceil if up else math.floor)(round(value / step, 9)) * step
    return float(f"{rounded:.12g}")


def binding_check(checks: list[dict]) -> dict | None:
    """The check with the least margin: the limit that binds hardest (for a feasible
    candidate, the first to fail if the limits were tightened); a failed check without a
    margin first (a solve that gave no buildable net: no limit it passes binds it)."""
    unrated = [c for c in checks if not c["ok"] and c.get("margin") is None]
    if unrated:
        return unrated[0]
    rated = [c for c in checks if c.get("margin") is not None]
    return min(rated, key=lambda c: c["margin"]) if rated else None


#: limits that measure one failure, counted once by `violation`: a panel's gap to its mold
#: makes the step between neighbouring molds (whose limit is twice the gap's unless set)
_SAME_FAILURE = {"max_panel_step_mm": "mold_tolerance_mm"}


def violation(checks: list[dict]) -> float:
    """How far a candidate is from feasible: over its failed limits, the sum of how many
    times over its limit each is, on a log scale: ln(measured / bound) for a largest
    value, ln(bound / measured) for a smallest (inf when a failed check cannot be rated: it
    has no margin, as a solve that failed on another ground than its residual, or its
    measure is unbounded).

    On that scale a limit missed by a factor of two counts as much whichever it is, and a
    gap to the molds forty times the tolerance does not outweigh a net twelve times the
    deviation limit off the design by the ratio of the two. The gap to the molds and the
    step between neighbouring molds are one failure: the larger counts.

    Examples
    --------
    >>> gap = {"limit": "mold_tolerance_mm", "ok": False, "margin": -3.0}     # 4 times
    >>> step = {"limit": "max_panel_step_mm", "ok": False, "margin": -1.0}    # 2 times
    >>> round(violation([gap, step]), 4) == round(math.log(4.0), 4)
    True
    >>> violation([{"limit": "min_coverage", "ok": False, "margin": -0.5}]) == math.log(2.0)
    True
    """
    worst: dict[str, float] = {}
    for c in checks:
        if c["ok"]:
            continue
        margin = c.get("margin")
        if margin is None or not math.isfinite(margin):
            return math.inf
        # how many times the measured value is over its bound (under it, for a smallest)
        if c["limit"].startswith("min_"):
            over = math.inf if margin <= -1.0 else 1.0 / (1.0 + margin)
        else:
            over = 1.0 - margin
        key = _SAME_FAILURE.get(c["limit"], c["limit"])
        worst[key] = max(worst.get(key, 0.0), math.log(over))
    return sum(worst.values())


def nearness(checks: list[dict], status: str) -> tuple[int, float]:
    """How near a candidate is to feasible, the nearest smallest: a net on the design (0:
    status ``converged``) before one that met its constraints only off it (1: status
    ``off-design``; however little it misses its limits, held to the deviation limit it
    cannot be this net type) before a solve that gave no buildable net (2: it stopped
    short, or met its constraints on a net that folds, is crumpled or degenerate); within
    each, its `violation`.

    Examples
    --------
    >>> gap = [{"limit": "mold_tolerance_mm", "ok": False, "margin": -40.0}]
    >>> off = [{"limit": "max_deviation_mm", "ok": False, "margin": -0.5}]
    >>> nearness(gap, "converged") < nearness(off, "off-design") < nearness(off, "stagnated")
    True
    """
    return {"converged": 0, "off-design": 1}.get(status, 2), violation(checks)


#: what else to try for a failed check, beside relaxing its limit (`next_steps`)
_TRY = {
    # a net whose solve converged above a tightened limit (one that did not converge is
    # told what to try by its check's own advice: `fabplan.study.verdict`)
    "max_sphere_residual": "let the solve run longer (max_iterations) or relax "
                           "max_sphere_residual",
    "max_deviation_mm": "keep the net nearer the design: a net type that glides on it "
                        "(isogonal, orthogonal, the baseline) or a smaller panel size",
    "mold_tolerance_mm": "a larger mold_tolerance_mm, or a smaller panel size",
    "max_molds": "a net type whose panels share molds (linear Weingarten, constant radius) or "
                 "a larger mold_tolerance_mm",
    # the same words as the mold tolerance's: the two fail together, and are said once
    "max_panel_step_mm": "a larger mold_tolerance_mm, or a smaller panel size",
    "max_kink_deg": "a smaller panel size",
    "max_line_turn_deg": "another net type or angle, or a smaller panel size",
    "planarity_tolerance_mm": "a net type with planar panels (char-conjugate)",
    "max_twist_deg_per_m": "another net type or angle: lamellas along lines nearer the "
                           "design's principal directions twist less",
}


def next_steps(checks: list[dict]) -> list[str]:
    """What to try for a candidate's failed `checks`, beside relaxing their limits
    (`relaxation_text`): one suggestion per failed limit (its check's own `advice`, else
    the general one), each once and none said within another, in the checks' order; for a
    solve that did not converge, only what to try for the solve.

    Examples
    --------
    >>> next_steps([{"limit": "max_kink_deg", "ok": False},
    ...             {"limit": "max_molds", "ok": True}])
    ['a smaller panel size']
    >>> next_steps([{"limit": "max_kink_deg", "ok": False},
    ...             {"limit": "mold_tolerance_mm", "ok": False, "advice": "a smaller panel "
    ...              "size: about 0.45 m"}])
    ['a smaller panel size: about 0.45 m']
    """
    steps = list(dict.fromkeys(c.get("advice") or _TRY[c["limit"]] for c in _advised(checks)))
    # "a smaller panel size" is said already where another step names the size
    return [s for s in steps if not any(s in other for other in steps if other != s)]


def advised_panel_size(checks: list[dict]) -> float | None:
    """The largest panel size that the advice of `next_steps` names (model units): the
    first smaller size to try; None when it names none."""
    sizes = [c["advised_panel_size"] for c in _advised(checks) if c.get("advised_panel_size")]
    return max(sizes, default=None)


def _advised(checks: list[dict]) -> list[dict]:
    """The failed checks that `next_steps` advises on."""
    failed = [c for c in checks if not c["ok"] and (c.get("advice") or c["limit"] in _TRY)]
    if any(c["limit"] == "max_sphere_residual" and c.get("advice") for c in failed):
        # a solve that did not converge gave no net yet: the other checks measured a net
        # that is not one, and their advice would mislead
        failed = [c for c in failed if c["limit"] == "max_sphere_residual"]
    return failed


def feasible_with(checks: list[dict]) -> str:
    """The sentence that says which limits, relaxed to what, make a candidate feasible
    (`relaxation_text`), with a leading space; '' when none would."""
    relax = relaxation_text(checks)
    if not relax:
        return ""
    replanned = any(c["limit"] == "mold_tolerance_mm" and not c["ok"] for c in checks) and \
        any(c["limit"] != "mold_tolerance_mm" and not c["ok"] for c in checks)
    # the molds are planned at the tolerance: at another they are other molds
    return (f" It would be feasible with {relax}, the other limits as they are"
            + (" (as measured on today's molds: at that mold tolerance the molds are planned "
               "anew, and their count, their steps and the boundary panels cut from them "
               "move with them)" if replanned else "") + ".")


def relaxation_text(checks: list[dict]) -> str:
    """The limits to relax, and to what, for a candidate to be feasible, in words; ''
    when a failed check cannot be relaxed (the solve did not converge)."""
    failed = [c for c in checks if not c["ok"]]
    if not failed or any(c.get("relax_to") is None for c in failed):
        return ""
    return " and ".join(f"{limit_words(c['limit'], c['relax_to'])} "
                        f"(now {limit_value(c['limit'], c['bound'])})" for c in failed)
