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

from ..design.mesh_surface import DesignSurface
from ..errors import InputError, SolverError
from .checks import advised_panel_size, nice_value
from .definition import Candidate, Study
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
    Nothing is done when a candidate is feasible or no size is advised.
    """
    from ..io.resources import STUDY_BYTES_PER_PANEL, default_max_panels

    measured = [r for r in result.candidates if not r.failed]
    if result.recommended is not None or not measured:
        return
    nearest = nearest_candidate(measured)
    size = max((s for r in ([nearest] if nearest else measured)
                if (s := advised_panel_size(r.checks))), default=None)
    if size is None:
        return
    design, units = result.design, result.study.design.units
    at = f"{size:g} {units}"
    lays_out: bool | None = None
    panels = None
    limit = default_max_panels(STUDY_BYTES_PER_PANEL) if max_panels is None else max_panels
    if design.area / size**2 > limit:
        text = (f"The largest panel size advised, {at}, was not laid out here: about "
                f"{design.area / size**2:,.0f} panels, more than the limit of {limit:,} "
                "(--max-panels).")
    else:
        say(f"the panel size advised: a general S-net laid out and solved on the design at {at}")
        lays_out, panels, text = _general_net_at(result.study, design,
                                                 result.baseline.candidate, size, at, say)
    between: list[dict] = []
    if lays_out is False:
        now = result.study.panel_size_of(nearest.candidate if nearest else
                                         result.baseline.candidate)
        between, found = _sizes_between(result, size, now, say)
        text = f"{text} {found}" if found else text
    result.advised_layout = {"panel_size": size, "panels": panels, "lays_out": lays_out,
                             "between": between, "text": text}
    result.recommendation = f"{result.recommendation} {text}"


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
        ok, panels, _ = _general_net_at(result.study, result.design, result.baseline.candidate,
                                        size, f"{size:g} {units}", say)
        tried.append({"panel_size": size, "lays_out": ok, "panels": panels})
        if ok:
            assert panels is not None
            return tried, (f"At {size:g} {units}, between {advised:g} {units} and the study's "
                           f"{now:g} {units}, the general S-net converges ({panels:,} panels): "
                           "the smallest size tried that gives a net.")
    if not tried:
        return tried, ""
    return tried, (f"Nor does the general S-net converge at "
                   f"{' or '.join(f'{s:g}' for s in sizes)} {units}, the sizes tried between "
                   f"{advised:g} {units} and the study's {now:g} {units}.")


def _general_net_at(study: Study, design: DesignSurface, baseline: Candidate, size: float,
                    at: str, say: Callable[[str], None]) -> tuple[bool, int | None, str]:
    """Whether the study's `baseline` (its general S-net) lays out and converges on
    `design` at panel `size`, solved as the study solves it (`solve_candidate`: its layout
    starts, its iterations): (it does, its panels, the sentence that says so). The lattice
    alone is not enough: one that holds together may leave a gap at the design boundary
    that only the solve on the design shows."""
    from .candidate_solve import solve_candidate

    try:
        solved = solve_candidate(replace(study, panel_size=size), design,
                                 replace(baseline, panel_size=None), {}, {}, say)
    except (InputError, SolverError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return False, None, (f"The largest panel size advised, {at}, does not lay out on "
                             f"this design, though: {str(exc).removeprefix(f'{design.name}: ')}.")
    net = solved.net
    assert net is not None
    panels = len(net.mesh.faces) + int((net.properties.get("boundary_panels") or {}).get("count", 0))
    cover = net.properties.get("coverage")
    clad = "" if cover is None else f", {100 * cover:.1f} % of the design clad"
    if not net.converged:
        return False, panels, (f"At the largest panel size advised, {at}, the general S-net "
                               f"laid out on the design does not converge, though ({net.status}"
                               f"{clad}): a smaller panel size alone may not do.")
    return True, panels, (f"At the largest panel size advised, {at}, the general S-net on "
                          f"the design converges ({panels:,} panels{clad}).")
