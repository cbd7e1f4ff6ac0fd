"""Whether the relaxation a study without a feasible candidate names for its nearest
candidate makes it feasible.

The relaxation is read off the measured numbers: each failed limit set to what was
measured (`fabplan.study.checks`). That holds as said for the limits a verdict alone
judges (molds counted, kinks, coverage), but not for those the run itself is made with:
the molds are planned at the mold tolerance and the step limit, a net that leaves the
design holds a share of the deviation limit inside its solve, flat panels a share of the
planarity tolerance, and the strips are cut at their congruence tolerance. At a relaxed
mold tolerance the molds are other molds, and the boundary panels cut from them stand
elsewhere: a user who set every limit to what a study named found a boundary panel
209 mm off the design, against the 190 mm named. So the study runs its nearest candidate
again under the relaxed limits, and relaxes once more by what that run measured when it
still fails (a continuation: each round's limits at least those of the one before).
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import TYPE_CHECKING, Callable

from .advised_size import MAX_CHECKED_PANELS
from .checks import feasible_with, limit_value, limit_words
from .definition import Candidate, Limits, Study
from .ranking import judge_study, nearest_candidate
from .result import CandidateResult, StudyResult

if TYPE_CHECKING:
    from .cache import CandidateCache

__all__ = ["check_relaxation", "relaxed_limits", "run_limits", "RUN_LIMITS"]

#: the `Limits` field a check's limit names, where the two differ
_FIELDS = {"congruent_strips": "congruence_tolerance_mm"}

#: the limits a candidate's run is made with (its solve, molds or strips), not only judged
#: by: relaxing one of them changes what is measured (`run_limits`)
RUN_LIMITS = ("max_deviation_mm", "mold_tolerance_mm", "max_panel_step_mm",
              "planarity_tolerance_mm", "congruence_tolerance_mm")


def run_limits(candidate: Candidate) -> tuple[str, ...]:
    """The `RUN_LIMITS` a candidate's run is made with: a net on the design holds no
    deviation in its solve (its boundary panels' distance comes from its molds)."""
    return tuple(f for f in RUN_LIMITS if not (candidate.glides and f == "max_deviation_mm"))


#: runs of the nearest candidate at most: the relaxation named, and once more relaxed by
#: what that run measured
ROUNDS = 2

#: the most panels the nearest candidate is run again with: about a minute's solve, the
#: bound of the advised panel size's check too
MAX_RUN_PANELS = MAX_CHECKED_PANELS


def relaxed_limits(limits: Limits, checks: list[dict]) -> Limits | None:
    """`limits` with each failed check's limit set to the value that would pass it
    (``relax_to``); None when a candidate passes every check or a failed check names no
    relaxation (a solve that gave no buildable net, a value a study file refuses)."""
    failed = [c for c in checks if not c["ok"]]
    if not failed or any(c.get("relax_to") is None for c in failed):
        return None
    relaxed = {_FIELDS.get(c["limit"], c["limit"]): c["relax_to"] for c in failed}
    if not all(hasattr(limits, f) for f in relaxed):
        return None
    return replace(limits, **relaxed)


def check_relaxation(result: StudyResult, say: Callable[[str], None], *,
                     cache: CandidateCache | None = None, resume: bool = False) -> None:
    """Run the nearest candidate of a study without a feasible candidate again under the
    limits its relaxation names, when one of them is a limit its run is made with
    (`run_limits`), and say in its recommendation what that run gave.

    When the run still fails, its own relaxation (from the relaxed limits) is tried once
    more (`ROUNDS`): run again where it changes a limit the run is made with, else judged
    on the same run. `result.relaxation_check` records ``{candidate, rounds, feasible,
    limits, text}``: each round's relaxed limits (``limits``: name to value, the limits
    changed from the study's), whether it ``ran`` the candidate again, whether it was
    ``feasible``, the limits it ``failed`` (name to measured value) and, for the feasible
    one, the ``least`` limits it needs (`_least`); `feasible` whether a round was (None
    when the check could not be finished); `limits` that round's ``least`` (else None).
    Nothing is done for a study with a feasible candidate, without a candidate near it,
    with a relaxation the verdict alone judges, or with more than `MAX_RUN_PANELS`
    panels; what goes wrong in a run is said after what the rounds before it found, and
    never fails the study. With a `cache` each run is kept in it under its relaxed
    limits, and with `resume` taken from it (`fabplan.study.cache`).
    """
    measured = [r for r in result.candidates if not r.failed]
    nearest = None if result.recommended is not None else nearest_candidate(measured)
    if nearest is None:
        return
    now = result.study.limits_of(nearest.candidate)
    limits = relaxed_limits(now, nearest.checks)
    if limits is None or not _changed(now, limits, run_limits(nearest.candidate)) \
            or _panels(nearest) > MAX_RUN_PANELS:
        return
    rounds: list[dict] = []
    said: list[str] = []
    finished = True
    try:
        _rounds(result, nearest, limits, rounds, said, say, (cache, resume))
    except Exception as exc:          # noqa: BLE001 - the study's results are kept
        finished = False
        said.append(f"Whether {nearest.name} is feasible under "
                    f"{'those' if not rounds else 'further relaxed'} limits could not be "
                    f"checked ({type(exc).__name__}: {exc}).")
    feasible = next((r for r in rounds if r["feasible"]), None)
    text = " ".join(said)
    result.relaxation_check = {"candidate": nearest.name, "rounds": rounds,
                               "feasible": (feasible is not None) if finished else None,
                               "limits": None if feasible is None else feasible["least"],
                               "text": text}
    told = feasible_with(nearest.checks).strip()
    if told and told in result.recommendation:
        # said right after the relaxation it checks
        result.recommendation = result.recommendation.replace(told, f"{told} {text}", 1)
    else:
        result.recommendation = f"{result.recommendation}\n{text}"


def _rounds(result: StudyResult, nearest: CandidateResult, limits: Limits, rounds: list[dict],
            said: list[str], say: Callable[[str], None], kept: tuple) -> None:
    """Run `nearest` under `limits`, and try its own relaxation of them while it fails,
    at most `ROUNDS` times; each round recorded in `rounds` once it is done, and what it
    found appended to `said`."""
    name, study = nearest.name, result.study
    now = study.limits_of(nearest.candidate)
    anew = "(its net solved and its molds planned anew)"
    made, before = None, now
    for k in range(ROUNDS):
        ran = made is None or _changed(before, limits, run_limits(nearest.candidate))
        if ran:
            say(f"the relaxation of {name} checked: run again with {_changes_text(now, limits)}")
            made = _run_under(_relaxed_study(study, limits), result, nearest, say, *kept)
        assert made is not None
        judged = judge_study(_relaxed_study(study, limits), result.design, [made]).candidates[0]
        failed = [c for c in judged.checks if not c["ok"]]
        least = _least(result, now, limits, judged) if judged.feasible else None
        rounds.append({"limits": _changes(now, limits), "ran": ran,
                       "feasible": bool(judged.feasible),
                       "failed": {c["limit"]: c["measured"] for c in failed},
                       **({} if least is None else {"least": _changes(now, least)})})
        if least is not None:
            if k == 0:
                said.append(f"Run again under those limits {anew}, {name} meets every limit"
                            + ("." if least == limits else
                               f"; it needs no more than {_changes_text(now, least)}, the other "
                               "limits as they are."))
            else:
                said.append(f"It meets every limit with {_changes_text(now, least)}, the other "
                            "limits as they are" + (", as a second run showed." if ran else "."))
            return
        fails = "; ".join(c["text"] for c in failed)
        said.append(f"Run again under those limits {anew}, {name} still fails: {fails}."
                    if k == 0 else f"Relaxed by that, a second run still fails: {fails}.")
        more = relaxed_limits(limits, judged.checks)
        if more is None:
            said.append("No limit relaxed further would do.")
            return
        before, limits = limits, more
    said.append("The nearest candidate's measures move with its limits: relax them in steps "
                "and run the study again, or take the other ways.")


def _least(result: StudyResult, now: Limits, limits: Limits, judged: CandidateResult) -> Limits:
    """The least of `limits` that a feasible run (`judged`) needs: each relaxed limit
    that only judges it (not in `run_limits`: molds counted, kinks) set back to the
    study's (`now`), or to what the run measured where that is more. The limits the run
    is made with stay as they were: another value would make another run."""
    made_with = run_limits(judged.candidate)
    back = {f: getattr(now, f) for f in _changes(now, limits) if f not in made_with}
    if not back:
        return limits
    tight = replace(limits, **back)
    again = judge_study(_relaxed_study(result.study, tight), result.design, [judged]).candidates[0]
    if again.feasible:
        return tight
    return relaxed_limits(tight, again.checks) or limits


def _run_under(study: Study, result: StudyResult, nearest: CandidateResult,
               say: Callable[[str], None], cache: CandidateCache | None = None,
               resume: bool = False) -> CandidateResult:
    """`nearest` solved and fabricated again under `study` (its relaxed limits): the same
    layout and net type, no cached layout or start; kept in `cache` (and with `resume`
    taken from it). Returns the measured candidate, not judged."""
    from .candidate_measure import fabricate_candidate
    from .candidate_solve import solve_candidate

    candidate = replace(nearest.candidate, mold_tolerance_mm=None)
    cache = None if cache is None else cache.under(study)
    made = None if cache is None or not resume else cache.load(candidate)
    if made is not None:
        say(f"    {candidate.name} under those limits: taken from the cache")
        return made
    solved = solve_candidate(study, result.design, candidate, {}, {}, say)
    made = fabricate_candidate(study, result.design, solved, None, say)
    if cache is not None:
        cache.store(made)
    return made


def _relaxed_study(study: Study, limits: Limits) -> Study:
    """`study` judged and run under `limits`; its strips cut at their congruence
    tolerance."""
    strips = study.strips
    if strips is not None and strips.congruence_tolerance_mm != limits.congruence_tolerance_mm:
        strips = replace(strips, congruence_tolerance_mm=limits.congruence_tolerance_mm)
    return replace(study, limits=limits, strips=strips)


def _changes(before: Limits, after: Limits) -> dict:
    """The limits of `after` that differ from `before`, by name."""
    return {f.name: getattr(after, f.name) for f in fields(after)
            if getattr(after, f.name) != getattr(before, f.name)}


def _changed(before: Limits, after: Limits, names: tuple[str, ...]) -> bool:
    """Whether a limit of `names` differs between `before` and `after`."""
    return any(f in names for f in _changes(before, after))


def _changes_text(before: Limits, after: Limits) -> str:
    """The limits changed from `before` to `after`, in words (`limit_words`), each with
    its value in `before`."""
    names = {v: k for k, v in _FIELDS.items()}
    return " and ".join(f"{limit_words(names.get(f, f), v)} (now "
                        f"{limit_value(names.get(f, f), _value(before, f))})"
                        for f, v in _changes(before, after).items())


def _value(limits: Limits, field: str) -> float:
    """A limit's value as its check bounds it (the step limit: twice the mold tolerance
    when not given)."""
    return limits.panel_step_limit_mm if field == "max_panel_step_mm" else getattr(limits, field)


def _panels(r: CandidateResult) -> int:
    """A measured candidate's panels, its boundary panels included."""
    return int(r.metrics.get("panels") or 0)

