"""The fabrication limits a command checks its parts against (`fabplan.fabricate.limits`),
and how it ends when a part goes past one."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from ..io.units import MM_PER_UNIT
from .running import EXIT_NOT_CONVERGED

__all__ = ["deviation_check", "deviation_limit", "deviation_option", "limits_exit"]


def deviation_option(args: Any) -> str:
    """The option that sets the deviation limit of `measure` and `optimize`, as given."""
    return "--max-deviation-mm" if getattr(args, "max_deviation_mm", None) is not None \
        else "--max-deviation"


def deviation_limit(args: Any, mesh: Any, units: str) -> float | None:
    """The deviation limit of `measure` and `optimize` in model units: ``--max-deviation``
    (model units) or ``--max-deviation-mm``; None when neither is given.

    A ``--max-deviation`` larger than the net itself (the diagonal of its bounding box) is
    refused as a limit meant in millimetres: 28 on a 12 m canopy in metres was a limit of
    28,000 mm, which no net misses.
    """
    import numpy as np

    from ..errors import InputError

    given, in_mm = args.max_deviation, getattr(args, "max_deviation_mm", None)
    if given is not None and in_mm is not None:
        raise InputError("give the deviation limit once: --max-deviation (model units) or "
                         "--max-deviation-mm")
    if in_mm is not None:
        return in_mm / MM_PER_UNIT[units]
    if given is None:
        return None
    size = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    if given > size:
        raise InputError(f"--max-deviation {given:g} is in the net's units ({units}): "
                         f"{given:g} {units}, more than the net's own size ({size:.3g} {units}); "
                         f"for {given:g} mm give --max-deviation-mm {given:g}")
    return given


def deviation_check(distances: Any, *, units: str, max_deviation: float | None = None,
                    option: str = "--max-deviation-mm") -> Any:
    """The net's vertices against the deviation limit (`fabplan.fabricate.limits`).

    Parameters
    ----------
    distances : (n,) float, each vertex's distance from the design or reference (model
        units).
    units : the model units (`MM_PER_UNIT` key).
    max_deviation : the limit in model units (``optimize --max-deviation``); None for the
        default in mm.
    option : the option that changes the limit.
    """
    import numpy as np

    from ..fabricate.limits import DEFAULT_MAX_DEVIATION_MM, limit_check

    mm = MM_PER_UNIT[units]
    bound = DEFAULT_MAX_DEVIATION_MM if max_deviation is None else max_deviation * mm
    return limit_check("max_deviation_mm", np.asarray(distances, dtype=np.float64) * mm, bound,
                       parts="vertices", option=option)


def limits_exit(checks: list, record: Path, why: str = "") -> int:
    """Exit 3, with a warning naming each limit exceeded and by how much (and `why`, said
    after it), when a part exceeds a fabrication limit (`fabplan.fabricate.limits`); else
    0."""
    from ..fabricate.limits import exceeded_text

    text = exceeded_text(checks)
    if text is None:
        return 0
    print(f"fabplan: warning: {text}{why}; counted in {record} (limits)", file=sys.stderr)
    return EXIT_NOT_CONVERGED
