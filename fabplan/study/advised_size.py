"""Whether the smaller panel size a study without a feasible candidate advises gives a
net on its design.

The advice comes from the measured candidates: the size at which the design's own
curvature turns a panel less (`fabplan.study.verdict`), or at which the mold gaps would
shrink within their tolerance. Neither knows whether a net of that size exists on the
design: at smaller panels the layout resolves umbilics that a larger one smoothed over,
so a design with many of them (an egg-crate facade) lays out at 2.5 m and not at the
0.5 m its curvature asks for; and a lattice that holds together may still leave a gap at
the design boundary that only the solve shows. So the study solves its general S-net at
the size it advises, as it solves its baseline, and says what it found, rather than send
its user to a size at which the next run is refused.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from ..errors import FabplanError, InputError
from .checks import advised_panel_size, nice_value
from .ranking import nearest_candidate
from .result import StudyResult

__all__ = ["check_advised_size"]


def check_advised_size(result: StudyResult, say: Callable[[str], None],
                       max_panels: int | None = None) -> None:
    """Solve the study's general S-net at the largest panel size a study without a
    feasible candidate advises, and add what was found to its recommendation.

    The size is the largest that the next steps of the nearest candidate name
    (`fabplan.study.checks.advised_panel_size`), or of every candidate when none is near.
    The study's general S-net (its baseline) is laid out and solved there, as the study
    solves it (`_general_net_at`). `result.advised_layout` records ``{panel_size, panels,
    lays_out, text}``: `panels` the net's panel count, boundary panels included (None
    when its layout does not hold together, or is not tried because its estimate exceeds
    `max_panels`, the study's limit), `lays_out` whether the net converged (None: not
    tried), `between` the sizes tried between it and the study's own where it did not
    (`_sizes_between`).
    Nothing is done when a candidate is feasible or no size is advised; what goes wrong
    in the check is said, and never fails the study. `fabplan.study.ranking.judge_study`
    alone (judging again under other limits) does not make this check.
    """
    measured = [r for r in result.candidates if not r.failed]
    if result.recommended is not None or not measured:
        return
    nearest = nearest_candidate(measured)
    # the size, and the candidate whose advice names it (its own size in a sweep)
    size, source = max(((s, r) for r in ([nearest] if nearest else measured)
                        if (s := advised_panel_size(r.checks))),
                       key=lambda pair: pair[0], default=(None, None))
    if size is None or source is None:
        return
    units = result.study.design.units
    now = result.study.panel_size_of(source.candidate)
    lays_out: bool | None = None
    panels = None
    between: list[dict] = []
    refusal = _too_many_panels(result, size, max_panels)
    if refusal is not None:
        text = refusal
    else:
        say(f"the panel size advised: a general S-net laid out and solved on the design at "
            f"{size:g} {units}")
        try:
            lays_out, panels, text = _general_net_at(result, size, "largest panel size advised",
                                                     say)
            if not lays_out and size < now:
                between, found = _sizes_between(result, size, now, say)
                text = f"{text} {found}" if found else text
        except Exception as exc:        # noqa: BLE001 - the study's results are kept
            lays_out = None
            text = (f"Whether the largest panel size advised, {size:g} {units}, gives a net "
                    f"could not be checked ({type(exc).__name__}: {exc}).")
    result.advised_layout = {"panel_size": size, "panels": panels, "lays_out": lays_out,
                             "between": between, "text": text}
    result.recommendation = f"{result.recommendation}\n{text}"


#: the most panels the general S-net is solved with to check an advised size: about a
#: minute's solve (the memory limit alone allows a study of its own)
MAX_CHECKED_PANELS = 5000


def _too_many_panels(result: StudyResult, size: float, max_panels: int | None) -> str | None:
    """Why the general S-net is not solved at `size` (its panels over `MAX_CHECKED_PANELS`
    or the study's limit), or None."""
    from ..io.resources import STUDY_BYTES_PER_PANEL, default_max_panels

    limit = default_max_panels(STUDY_BYTES_PER_PANEL) if max_panels is None else max_panels
    limit = min(limit, MAX_CHECKED_PANELS)
    count = result.design.area / size**2
    if count <= limit:
        return None
    return (f"The largest panel size advised, {size:g} {result.study.design.units}, was not "
            f"tried here: about {count:,.0f} panels, more than {limit:,}.")


#: panel sizes tried between the one advised and the study's own when the one advised
#: gives no net (`_sizes_between`): each a solve of the general S-net
BETWEEN_TRIES = 2


def _sizes_between(result: StudyResult, advised: float, now: float,
                   say: Callable[[str], None]) -> tuple[list[dict], str]:
    """Where the general S-net gives no net at the `advised` size: the sizes between it
    and the study's own (`now`), in `BETWEEN_TRIES` even steps on a log scale, smallest
    first, until one converges. Returns each size tried (``{panel_size, lays_out,
    panels}``) and the sentence that says what was found."""
    units = result.study.design.units
    sizes = sorted({nice_value(advised * (now / advised) ** (k / (BETWEEN_TRIES + 1)), up=False)
                    for k in range(1, BETWEEN_TRIES + 1)} - {advised, now})
    tried = []
    for size in sizes:
        say(f"the panel size advised gives no net: the general S-net at {size:g} {units}")
        ok, panels, _ = _general_net_at(result, size, "size", say)
        tried.append({"panel_size": size, "lays_out": ok, "panels": panels})
        if ok:
            assert panels is not None
            return tried, (f"At {size:g} {units}, between {advised:g} {units} and the study's "
                           f"{now:g} {units}, the general S-net converges ({panels:,} panels): "
                           "the smallest size tried that gives a net, larger than the limits "
                           "ask for.")
    if not tried:
        return tried, ""
    return tried, (f"Nor does the general S-net converge at "
                   f"{' or '.join(f'{s:g}' for s in sizes)} {units}, the sizes tried between "
                   f"{advised:g} {units} and the study's {now:g} {units}.")


def _general_net_at(result: StudyResult, size: float, what: str,
                    say: Callable[[str], None]) -> tuple[bool, int | None, str]:
    """Whether the study's general S-net (its baseline) lays out and converges on its
    design at panel `size`, solved as the study solves it (`solve_candidate`: its layout
    starts, its iterations): (it does, its panels, the sentence that says so, of the
    `what`). The lattice alone is not enough: one that holds together may leave a gap at
    the design boundary that only the solve on the design shows."""
    from .candidate_solve import solve_candidate

    study, design = result.study, result.design
    at = f"the {what}, {size:g} {study.design.units}"
    try:
        solved = solve_candidate(replace(study, panel_size=size), design,
                                 replace(result.baseline.candidate, panel_size=None), {}, {},
                                 say)
    except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        reason = str(exc).removeprefix(f"{design.name}: ")
        how = "does not lay out" if isinstance(exc, InputError) else "gives no net"
        return False, None, f"{at[0].upper()}{at[1:]}, {how} on this design, though: {reason}."
    net = solved.net
    assert net is not None
    panels = len(net.mesh.faces) + int((net.properties.get("boundary_panels") or {}).get("count", 0))
    cover = net.properties.get("coverage")
    clad = "" if cover is None else f", {100 * cover:.1f} % of the design clad"
    if not net.converged:
        return False, panels, (f"At {at}, the general S-net laid out on the design does not "
                               f"converge, though ({net.status}{clad}): a smaller panel size "
                               "alone may not do.")
    return True, panels, (f"At {at}, the general S-net on the design converges ({panels:,} "
                          f"panels{clad}).")
