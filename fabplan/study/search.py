"""Searches: the value of a candidate's angle or radius with the lowest cost that meets
every limit.

A study candidate may give its free parameter a range instead of a value
(``angle = { search = [30, 60], budget = 6 }``). The study then solves it at points of
the range, coarse to fine, and keeps every point as a candidate of its own (named like a
sweep's, ``linear-weingarten-41.25``), judged like the others:

1. the first round: up to four points spread evenly over the range, ends included;
2. every further round: the best point so far (feasible and cheapest; without a feasible
   one the nearest, `fabplan.study.checks.nearness`) and the midpoints between it
   and its evaluated neighbours, as long as the budget and the resolution (a 64th of the
   range) allow. A midpoint carries the start angle of the best point: the points of a
   radius search share its layout; a point of an angle search keeps its own angle, and
   so is laid out at it (`fabplan.study.candidate_solve.start_angle`).

The search is deterministic: the same study gives the same points in the same order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .checks import nearness

if TYPE_CHECKING:
    from .definition import Candidate, Search
    from .result import CandidateResult

__all__ = ["first_points", "next_points", "SearchPoint", "search_points", "search_record",
           "FIRST_ROUND", "RESOLUTION"]

FIRST_ROUND = 4
"""Points of the first round (fewer when the budget is smaller)."""

RESOLUTION = 1 / 64
"""The smallest gap between two points, as a share of the range."""


def _rounded(value: float) -> float:
    """Values rounded to 4 decimals, so that names and cache keys read 41.25."""
    return round(value, 4)


def first_points(search: Search) -> list[Candidate]:
    """The first round's candidates: points spread evenly over the range.

    Examples
    --------
    >>> from fabplan.study.definition import Search
    >>> [c.name for c in first_points(Search("lw", "linear-weingarten", "angle", 30, 60))]
    ['lw-30', 'lw-40', 'lw-50', 'lw-60']
    """
    count = min(FIRST_ROUND, search.budget)
    step = (search.high - search.low) / (count - 1)
    return [search.candidate(_rounded(search.low + k * step)) for k in range(count)]


@dataclass
class SearchPoint:
    """One evaluated point of a search: its value and its judged candidate."""

    value: float
    result: CandidateResult

    @property
    def rank_key(self) -> tuple:
        """Feasible and cheap first, then the least infeasible."""
        r = self.result
        if r.failed:
            return (2, float("inf"), 0.0)
        if r.feasible:
            return (0, r.cost if r.cost is not None else float("inf"), 0.0)
        return (1, *nearness(r.checks, r.metrics["status"]),
                r.cost if r.cost is not None else float("inf"))


def search_points(search: Search, results: list[CandidateResult]) -> list[SearchPoint]:
    """The evaluated points of `search` among the judged `results`, by value."""
    names = {}
    for r in results:
        value = r.candidate.angle if search.parameter == "angle" else r.candidate.radius
        if value is not None and r.candidate.net == search.net and \
                search.candidate(value).name == r.name:
            names[r.name] = SearchPoint(float(value), r)
    return sorted(names.values(), key=lambda p: p.value)


def next_points(search: Search, results: list[CandidateResult],
                pending: tuple[float, ...] = ()) -> list[Candidate]:
    """The next round's candidates (empty when the search is done): the midpoints
    between the best point so far and its neighbours, each with the best point's start
    angle (see the module).

    Parameters
    ----------
    search : the search.
    results : the judged candidates (those of other searches and candidates too).
    pending : values solved but not measured yet. They count against the budget and may
        be a neighbour, never the best: with them, the points the next round will likely
        take, guessed before this round is measured (`fabplan.study.run` solves them
        while it waits).

    Returns
    -------
    list of Candidate, at most two.

    Examples
    --------
    Nothing measured, nothing to refine; the points pending do not change that:

    >>> from fabplan.study.definition import Search
    >>> search = Search("lw", "linear-weingarten", "angle", 30, 60, budget=5)
    >>> next_points(search, [], pending=(30.0, 40.0))
    []

    (``tests/test_limits.py`` shows a guess with points pending beside the best.)
    """
    points = search_points(search, results)
    values = sorted({p.value for p in points} | set(pending))
    left = search.budget - len(values)
    if left <= 0 or not points:
        return []
    best = min(points, key=lambda p: p.rank_key)
    at = values.index(best.value)
    gap = RESOLUTION * (search.high - search.low)
    new: list[Candidate] = []
    taken = set(values)
    for k in (at - 1, at + 1):
        if not 0 <= k < len(values) or len(new) >= left:
            continue
        a, b = best.value, values[k]
        value = _rounded((a + b) / 2)
        if abs(b - a) / 2 < gap or value in taken:
            continue
        warm = best.result.candidate
        start = warm.start_angle if warm.start_angle is not None else warm.angle
        new.append(search.candidate(value, start_angle=start if search.parameter == "angle"
                                    else None))
        taken.add(value)
    return new


def search_record(search: Search, results: list[CandidateResult]) -> dict:
    """What a search found, for ``study.json``: every point with its verdict, cost, molds
    and deviation, and the best point (None when no point is feasible)."""
    from dataclasses import asdict

    points = search_points(search, results)
    feasible = [p for p in points if p.result.feasible]
    best = min(feasible, key=lambda p: p.rank_key) if feasible else None
    return {
        **asdict(search),
        "points": [{
            "value": p.value, "candidate": p.result.name, "feasible": p.result.feasible,
            "failed": p.result.failed, "cost": p.result.cost,
            "molds": None if p.result.failed else p.result.metrics["molds"]["count"],
            "deviation_mm": None if p.result.failed else
            p.result.metrics["largest_deviation_mm"]} for p in points],
        "best": None if best is None else best.result.name,
        "feasible_range": None if not feasible else [feasible[0].value, feasible[-1].value],
    }
