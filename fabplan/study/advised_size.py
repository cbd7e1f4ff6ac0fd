"""Whether the smaller panel size a study without a feasible candidate advises lays out
on its design.

The advice comes from the measured candidates: the size at which the design's own
curvature turns a panel less (`fabplan.study.verdict`), or at which the mold gaps would
shrink within their tolerance. Neither knows whether a lattice of that size holds
together on the design: at smaller panels the layout resolves umbilics that a larger
one smoothed over, and a design with many of them (an egg-crate facade) lays out at
2.5 m but not at the 0.5 m its curvature asks for. So the study lays the design out once
at the size it advises, and says what it found, rather than send its user to a size at
which the next run is refused.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import InputError
from .checks import advised_panel_size
from .ranking import nearest_candidate
from .result import StudyResult

__all__ = ["check_advised_size"]


def check_advised_size(result: StudyResult, say: Callable[[str], None],
                       max_panels: int | None = None) -> None:
    """Lay the design out at the largest panel size a study without a feasible candidate
    advises, and add what was found to its recommendation.

    The size is the largest that the next steps of the nearest candidate name
    (`fabplan.study.checks.advised_panel_size`), or of every candidate when none is near.
    The layout is the baseline's (90 deg, default settings). `result.advised_layout`
    records ``{panel_size, panels, lays_out, text}``: `panels` the layout's panel count
    (None when it does not hold together, or is not tried because its estimate exceeds
    `max_panels`, the study's limit), `lays_out` true, false, or None when not tried.
    Nothing is done when a candidate is feasible or no size is advised.
    """
    from ..io.resources import STUDY_BYTES_PER_PANEL, default_max_panels
    from ..layout.surface_layout import layout_surface

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
        say(f"the panel size advised: laying the design out at {at}")
        try:
            layout = layout_surface(design, size, angle=90.0)
        except (InputError, ArithmeticError, np.linalg.LinAlgError) as exc:
            lays_out = False
            text = (f"The largest panel size advised, {at}, does not lay out on this design, "
                    f"though: {str(exc).removeprefix(f'{design.name}: ')}.")
        else:
            lays_out, panels = True, len(layout.mesh.faces)
            text = (f"At the largest panel size advised, {at}, the design lays out "
                    f"({panels:,} panels at 90 deg).")
    result.advised_layout = {"panel_size": size, "panels": panels, "lays_out": lays_out,
                             "text": text}
    result.recommendation = f"{result.recommendation} {text}"

