"""Neutral cutter-location data: the APT CLDATA subset a CAM post-processor reads.

Written::

    PARTNO/NAME
    UNITS/MM
    CUTTER/D, R, 0, 0, 0, B, L
    MULTAX/ON
    $$ pass 1: ...
    GOTO/x, y, z, i, j, k
    ...
    FINI

``CUTTER`` is the APT seven-parameter cutter: diameter at the tip D, corner radius R, side
angle B (0 for a cylinder; the half angle of a conical flank mill) and height L.
``GOTO`` carries the tool tip (the centre of the cutter's end) and the unit tool axis
pointing from the tip to the spindle. Between passes the tool retracts along its axis
(``$$ retract`` then a ``GOTO`` above the last point and above the next pass's first).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .inputs import check_input_file, check_text

__all__ = ["CLData", "cldata_text", "read_cldata"]


@dataclass
class CLData:
    """Cutter locations read back from a CL file.

    Attributes
    ----------
    tip : (k, 3) float, tool tips (file units).
    axis : (k, 3) float, unit tool axes.
    pass_id : (k,) int, pass of each location; -1 for retract moves.
    units : ``"MM"`` or ``"INCHES"``.
    cutter : (7,) float, the CUTTER parameters.
    comments : list of str, the ``$$`` comments in order.
    """

    tip: np.ndarray
    axis: np.ndarray
    pass_id: np.ndarray
    units: str
    cutter: np.ndarray
    comments: list


def _goto(p: np.ndarray, a: np.ndarray) -> str:
    # 1e-8 mm and 1e-12 rad: re-read locations keep sub-micrometre geometry on spheres of
    # metres
    return "GOTO/" + ", ".join(f"{v:.8f}" for v in p) + ", " + ", ".join(f"{v:.12f}" for v in a)


def cldata_text(tip: np.ndarray, axis: np.ndarray, pass_id: np.ndarray, *, part: str,
                diameter_mm: float, corner_mm: float = 0.0, length_mm: float = 0.0,
                side_angle_deg: float = 0.0, pass_comments: list | None = None,
                retract_mm: float = 5.0, header: list | None = None) -> str:
    """The CL file of a tool path, in millimetres.

    Parameters
    ----------
    tip : (k, 3) float, tool tips (mm).
    axis : (k, 3) float, unit tool axes.
    pass_id : (k,) int, passes in order (locations of a pass are consecutive).
    part : PARTNO text.
    diameter_mm, corner_mm, length_mm : the CUTTER statement (diameter at the tip, corner
        radius, height).
    side_angle_deg : the CUTTER's side angle (its sixth parameter, the angle between the
        flank and the axis): a taper of a conical cutter, 0 for a cylinder.
    pass_comments : one text per pass for its ``$$`` line.
    retract_mm : distance the tool lifts along its axis between passes.
    header : further ``$$`` lines at the top.

    Examples
    --------
    >>> text = cldata_text(np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]], np.tile([0, 0, 1.0], (2, 1)),
    ...                    np.array([0, 0]), part="demo", diameter_mm=10)
    >>> text.splitlines()[5]
    'GOTO/0.00000000, 0.00000000, 0.00000000, 0.000000000000, 0.000000000000, 1.000000000000'
    """
    passes = np.unique(pass_id)
    comments = pass_comments or [f"pass {int(p) + 1}" for p in passes]
    lines = [f"PARTNO/{part.replace(chr(10), ' ')[:66]}", "UNITS/MM",
             f"CUTTER/{diameter_mm:g}, {corner_mm:g}, 0, 0, 0, {side_angle_deg:g}, {length_mm:g}",
             "MULTAX/ON"]
    lines += [f"$$ {h}" for h in (header or [])]
    previous_end = None
    for number, p in enumerate(passes):
        sel = np.flatnonzero(pass_id == p)
        if previous_end is not None:
            lines.append("$$ retract")
            lines.append(_goto(tip[previous_end] + retract_mm * axis[previous_end], axis[previous_end]))
            lines.append(_goto(tip[sel[0]] + retract_mm * axis[sel[0]], axis[sel[0]]))
        lines.append(f"$$ {comments[number]}")
        lines += [_goto(tip[i], axis[i]) for i in sel]
        previous_end = sel[-1]
    lines.append("FINI")
    return "\n".join(lines) + "\n"


def read_cldata(path: str | os.PathLike) -> CLData:
    """Read the GOTO locations of a CL file written by `cldata_text` (or a like subset).

    Raises
    ------
    InputError
        For a GOTO without six numbers, or a file without UNITS.
    """
    path = Path(check_input_file(path, "a CL file"))
    text = check_text(path, "CL")
    tips, axes, ids, comments = [], [], [], []
    units, cutter = None, np.zeros(7)
    current, retracting = -1, False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if line.startswith("$$"):
            comment = line[2:].strip()
            comments.append(comment)
            if comment == "retract":
                retracting = True
            elif comment.startswith("pass "):
                retracting = False
                current += 1
            continue
        word, _, rest = line.partition("/")
        if word == "UNITS":
            units = rest.strip()
        elif word == "CUTTER":
            values = [float(v) for v in rest.split(",")]
            cutter[: len(values)] = values[:7]
        elif word == "GOTO":
            try:
                values = [float(v) for v in rest.split(",")]
            except ValueError:
                values = []
            if len(values) != 6:
                raise InputError(f"{path}: line {number}: GOTO needs x, y, z, i, j, k")
            tips.append(values[:3])
            axes.append(values[3:])
            ids.append(-1 if retracting else current)
    if units is None:
        raise InputError(f"{path}: no UNITS statement")
    return CLData(tip=np.array(tips).reshape(-1, 3), axis=np.array(axes).reshape(-1, 3),
                  pass_id=np.array(ids, dtype=np.int64), units=units, cutter=cutter,
                  comments=comments)
