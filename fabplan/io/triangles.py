"""Triangle mesh files (OBJ, STL, PLY, OFF) as vertex and triangle arrays."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from .inputs import check_coordinates, check_input_file, check_text
from .obj import read_obj

__all__ = ["read_triangles", "read_binary_stl", "read_ascii_stl", "TRIANGLE_FORMATS"]

TRIANGLE_FORMATS = (".obj", ".stl", ".ply", ".off")


def read_triangles(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a mesh file: OBJ (polygons fan-triangulated), STL, PLY, OFF.

    The one reader of triangle mesh files: design surfaces and reference surfaces both
    read through it.

    Raises
    ------
    InputError
        When the file is missing, empty, not a regular file, unreadable, malformed, holds
        no faces or unusable coordinates (see `check_input_file`, `check_coordinates`).
    """
    path = check_input_file(path, "a surface file")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        vertices, polygons = read_obj(path)
        check_coordinates(vertices, str(path))
        tris = [np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], axis=1) for f in polygons]
        return vertices, np.concatenate(tris)
    if suffix not in (".stl", ".ply", ".off"):
        raise InputError(f"{path}: unknown surface format {suffix or '(none)'}; "
                         "use OBJ, STL, PLY or OFF")
    if suffix == ".stl":
        # fabplan reads STL itself: trimesh decodes text that is not UTF-8 through an
        # optional package (charset_normalizer), logs tracebacks and warns on bad numbers
        binary = _is_binary_stl(path)
        vertices, faces = read_binary_stl(path) if binary else read_ascii_stl(path)
    else:
        if suffix == ".off":
            check_text(path, "OFF")   # see above: refuse binary content with a message
        vertices, faces = _read_with_trimesh(path, suffix)
    check_coordinates(vertices, str(path))
    return vertices, faces


_STL_TRIANGLE = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)),
                          ("attribute", "<u2")])   # 50 bytes per triangle


def _is_binary_stl(path: Path) -> bool:
    """True when the file starts like a binary STL: text STL starts with 'solid' and has
    no NUL byte; a binary header may also start with 'solid', so the size decides."""
    with open(path, "rb") as handle:
        head = handle.read(84)
    size = path.stat().st_size
    if len(head) == 84:
        count = int.from_bytes(head[80:84], "little")
        if size == 84 + _STL_TRIANGLE.itemsize * count:
            return True
    return not head.lstrip().lower().startswith(b"solid") or b"\0" in head


def read_binary_stl(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a binary STL file (80-byte header, uint32 count, then 50
    bytes per triangle); each triangle has its own three vertices (weld them later).

    Returns
    -------
    vertices : (3 m, 3) float64
    triangles : (m, 3) int64

    Raises
    ------
    InputError
        When the size does not match the triangle count in the header (a truncated or
        non-STL file), or there are no triangles.
    """
    path = Path(path)
    data = path.read_bytes()
    if len(data) < 84:
        raise InputError(f"{path}: not an STL file (a binary STL has an 84-byte header, "
                         f"this file has {len(data)} bytes)")
    count = int.from_bytes(data[80:84], "little")
    expected = 84 + _STL_TRIANGLE.itemsize * count
    if len(data) != expected:
        raise InputError(f"{path}: not a valid binary STL: its header announces {count} "
                         f"triangles ({expected} bytes) but the file has {len(data)} bytes "
                         "(truncated or not an STL file)")
    if count == 0:
        raise InputError(f"{path}: no faces")
    records = np.frombuffer(data, dtype=_STL_TRIANGLE, count=count, offset=84)
    vertices = records["corners"].reshape(-1, 3).astype(np.float64)
    return vertices, np.arange(3 * count, dtype=np.int64).reshape(-1, 3)


def read_ascii_stl(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a text STL file: every ``vertex x y z`` line, three per
    facet; each triangle has its own three vertices (weld them later).

    Returns
    -------
    vertices : (3 m, 3) float64
    triangles : (m, 3) int64

    Raises
    ------
    InputError
        For binary content, a malformed vertex line (named by its line number), or a
        vertex count that is not a whole number of triangles.
    """
    path = Path(path)
    text = check_text(path, "STL")
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].lower() != "vertex":
            continue
        try:
            if len(parts) != 4:
                raise ValueError
            rows.append([float(p) for p in parts[1:]])
        except ValueError:
            raise InputError(f"{path}:{lineno}: malformed vertex line "
                             f"{line.strip()[:60]!r}") from None
    if not rows:
        raise InputError(f"{path}: no faces (no 'vertex' lines: is this an STL file?)")
    if len(rows) % 3:
        raise InputError(f"{path}: {len(rows)} vertex lines, not three per facet")
    vertices = np.asarray(rows, dtype=np.float64)
    return vertices, np.arange(len(rows), dtype=np.int64).reshape(-1, 3)


def _read_with_trimesh(path: Path, suffix: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    try:
        # numbers beyond float range become inf with a RuntimeWarning; the coordinates are
        # checked right after, so the warning is not needed
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        detail = (str(exc).splitlines() or ["malformed"])[0][:80]
        raise InputError(f"{path}: cannot read as {suffix[1:].upper()} "
                         f"({type(exc).__name__}: {detail})") from None
    if not isinstance(loaded, trimesh.Trimesh):  # force="mesh" returns one Trimesh
        raise InputError(f"{path}: no faces")
    vertices, faces = np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces)
    if faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"{path}: no faces")
    return vertices, faces


# ---------------------------------------------------------------------------- topology helpers
