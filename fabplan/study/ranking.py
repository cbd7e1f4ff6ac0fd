"""A study's measured candidates judged: their checks, verdicts and costs, their ranks and
the Pareto front of their cost drivers, and the recommendation in plain words.

Every verdict is computed from the metrics (`fabplan.study.verdict`), a pure function of
the measured numbers and the limits: a change of a limit changes the verdict without a new
run (`judge_study`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..report.html import counted
from .checks import LIMIT_NAMES, binding_check, feasible_with, nearness, next_steps
from .definition import Candidate, Study
from .mold_counts import material_sentence
from .result import CandidateResult, StudyResult, by_rank
from .twins import SAME_NET_TOLERANCE
from .verdict import candidate_cost, differ_by, every_panel_flat, verdict

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..design.mesh_surface import DesignSurface

__all__ = ["judge_study", "cost_drivers", "pareto_optimal", "rank_candidates", "is_lamella_study",
           "binding_limit", "recommend", "baseline_of", "nearest_candidate"]


# the limits a lamella study does not speak of: its strips are bent, not molded
_MOLD_LIMITS = ("mold_tolerance_mm", "max_molds", "max_panel_step_mm")

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
        checks = verdict(r.metrics, study.limits_of(r.candidate),
                         panel_size=study.panel_size_of(r.candidate), units=study.design.units)
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


# ---------------------------------------------------------------------------- recommending
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


def binding_limit(result: CandidateResult, study: Study) -> dict | None:
    """The check of `result` that binds hardest (`binding_check`), as the report names it
    and ``study.json`` records it: in a lamella study (`is_lamella_study`) among the
    limits other than the molds', of which it does not speak."""
    return binding_check([c for c in result.checks if not (
        is_lamella_study(study) and c["limit"] in _MOLD_LIMITS)])


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
        return None, _nearest_text([r for r in results if not r.failed])
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
    binding = binding_limit(best, study)
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


def nearest_candidate(measured: list[CandidateResult]) -> CandidateResult | None:
    """The measured candidate nearest to feasible (`nearness`, ties by rank); None when
    no solve gave a buildable net, and so none is near."""
    near = {r.name: nearness(r.checks, r.metrics["status"]) for r in measured}
    best = min(measured, key=lambda r: (near[r.name], by_rank(r)), default=None)
    return None if best is None or near[best.name][0] == 2 else best


def _nearest_text(measured: list[CandidateResult]) -> str:
    """What a study without a feasible candidate says: its nearest candidate (`nearness`),
    what that fails, the relaxation that makes it feasible and the other ways; or, when no
    solve gave a buildable net, that none is near and what to try."""
    if not measured:
        return "No candidate produced a net; see the reasons of each below."
    best = nearest_candidate(measured)
    if best is None:
        # no net to be near: naming the cheapest unfinished one would mislead
        # each candidate's advice, its alternatives ("...; or ...") said once across them
        steps = _said_once([(part, r.name) for r in measured for step in next_steps(r.checks)
                            for part in step.split("; or ")], len(measured))
        return ("No candidate meets every limit, and none is near: no solve gave a buildable "
                "net (see the reasons of each below)."
                + (f" To try: {'; '.join(steps)}." if steps else ""))
    # the ranking counts the limits failed first, so it may put another first: the text
    # says which it means
    on_design = nearness(best.checks, best.metrics["status"])[0] == 0
    ranked = "" if best.rank in (None, 1) else (
        f" (ranked {best.rank}: the ranking counts the limits failed first; this is the "
        f"{'net on the design' if on_design else 'net'} the least many times over its limits)")
    off = "" if on_design else (
        " No candidate gave a net on the design: this one met its constraints only off it.")
    relax = feasible_with(best.checks).strip()
    text = (f"No candidate meets every limit. The nearest is {_named(best)}{ranked}, "
            "which fails: " + "; ".join(best.reasons) + "." + off + (f"\n{relax}" if relax else ""))
    steps = next_steps(best.checks)
    return text + (f"\nOther ways: {'; '.join(steps)}." if steps else "")


def _said_once(steps: list[tuple[str, str]], candidates: int) -> list[str]:
    """The (step, candidate) `steps` of `candidates` candidates, each step said once, with
    the candidates it is for where it is not for all of them: those that say the same
    before their reason (the text after the first ": ") and differ in it, said without it
    ("... from 4 layout starts", "... from 5 layout starts")."""
    heads: dict[str, tuple[set[str], list[str]]] = {}
    for step, name in steps:
        head, _, reason = step.partition(": ")
        reasons, names = heads.setdefault(head, (set(), []))
        reasons.add(reason)
        if name not in names:
            names.append(name)
    said = []
    for head, (reasons, names) in heads.items():
        text = head if len(reasons) > 1 or reasons == {""} else f"{head}: {reasons.pop()}"
        said.append(text if len(names) == candidates else f"{text} (for {', '.join(names)})")
    return said


def _named(result: CandidateResult) -> str:
    """A candidate's name, with its description where that says more."""
    described = result.candidate.describe()
    return result.name if described == result.name else f"{result.name} ({described})"


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
