"""The checks every input file and every set of coordinates passes, whatever reads it.

One place decides what counts as a readable input file and as usable coordinates, so
that `measure`, `optimize`, `layout`, `molds`, `strips` and `study` refuse the same bad
input with the same kind of message: one line naming the file and the first offending
element (``wall.obj: vertex 12 lies 1e+300 from the origin ...``).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["MAX_COORDINATE", "check_input_file", "check_coordinates", "check_text"]

MAX_COORDINATE = 1e10
"""Largest plausible coordinate magnitude in model units (10 million km in metres, 10,000
km in millimetres). Beyond it a file is a broken export or a unit mistake, never a
building, and squared lengths soon overflow."""


def check_input_file(path: str | os.PathLike, what: str = "a file") -> Path:
    """Make sure `path` is an existing, readable, non-empty regular file.

    A folder, a device, a FIFO or a socket is named as what it is instead of being read
    (reading ``/dev/zero`` or a FIFO would never end).

    Parameters
    ----------
    path : the input path.
    what : what the file should be, with its article, for messages (``"an OBJ file"``).

    Returns
    -------
    Path of the file.

    Raises
    ------
    InputError
        When the path is missing, not a regular file, empty or unreadable.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
             (stat.S_ISSOCK, "a socket"))
    for test, kind in kinds:
        if test(mode):
            raise InputError(f"{path}: is {kind}, not {what}")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: cannot read (permission denied)")
    if os.stat(path).st_size == 0:
        raise InputError(f"{path}: empty file (not {what})")
    return path


def check_text(path: str | os.PathLike, what: str) -> str:
    """The text of a file that must be UTF-8 (or ASCII) text.

    Raises
    ------
    InputError
        When the file holds binary content (named with the byte offset) or cannot be read.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a text {what} file (binary content at byte "
                         f"{exc.start})") from None


def check_coordinates(points: np.ndarray, name: str, *, element: str = "vertex") -> None:
    """Refuse coordinates no geometry can be computed from.

    Parameters
    ----------
    points : (n, 3) float, the coordinates (model units).
    name : the file or mesh name, for messages.
    element : what a row is, for messages.

    Raises
    ------
    InputError
        For a non-finite coordinate, one beyond `MAX_COORDINATE`, or when all points
        coincide; the message names the first offending row.

    Examples
    --------
    >>> check_coordinates(np.array([[0.0, 0, 0], [1e300, 0, 0]]), "wall.obj")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: wall.obj: vertex 1 lies 1e+300 from the origin, beyond any \
plausible model (more than 1e+10 model units): a broken export or a unit mistake
    """
    points = np.asarray(points, dtype=np.float64)
    if points.size == 0:
        raise InputError(f"{name}: no {element}s")
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise InputError(f"{name}: {element} {bad[0]} has a non-finite coordinate "
                         f"({', '.join(f'{c:g}' for c in points[bad[0]])})")
    size = np.abs(points).max(axis=1)
    huge = np.flatnonzero(size > MAX_COORDINATE)
    if huge.size:
        raise InputError(f"{name}: {element} {huge[0]} lies {size[huge[0]]:.3g} from the origin, "
                         f"beyond any plausible model (more than {MAX_COORDINATE:.0e} model units): "
                         "a broken export or a unit mistake")
    if len(points) > 1 and not np.ptp(points, axis=0).max() > 0:
        raise InputError(f"{name}: all {len(points)} points coincide at "
                         f"({', '.join(f'{c:g}' for c in points[0])}): no geometry")
