"""Reading and writing files: OBJ quad meshes (quads kept exactly) and atomic outputs.

trimesh and most OBJ loaders triangulate polygons silently, so fabplan reads OBJ itself:
vertex order, face order and face sizes come back exactly as written.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from .errors import InputError

__all__ = [
    "read_obj",
    "parse_obj",
    "write_obj",
    "atomic_path",
    "write_json",
    "write_texts",
    "check_writable",
    "json_text",
    "format_obj",
]


def read_obj(path: str | os.PathLike) -> tuple[np.ndarray, list[np.ndarray]]:
    """Read vertices and polygonal faces from an OBJ file (see `parse_obj`).

    Returns
    -------
    vertices : (n, 3) float64
    faces : list of (k,) int arrays, 0-based vertex indices in file order.
    """
    vertices, faces, _ = parse_obj(path)
    return vertices, faces


def parse_obj(path: str | os.PathLike) -> tuple[np.ndarray, list[np.ndarray], np.ndarray | None]:
    """Read vertices, polygonal faces and per-vertex normals from an OBJ file.

    Parameters
    ----------
    path : path of the OBJ file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : list of (k,) int arrays, 0-based vertex indices in file order.
    normals : (n, 3) float64 when the file has one ``vn`` line per vertex (in vertex
        order, as fabplan writes the contact elements of S*-nets), else None.

    Raises
    ------
    InputError
        When the file is missing, unreadable, not an OBJ, or has bad coordinates or
        indices; the message names the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")  # tolerate a byte order mark
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text OBJ file (binary content)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None

    vertices: list[list[float]] = []
    normals: list[list[float]] = []
    faces: list[list[int]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        if tag == "v":
            try:
                xyz = [float(p) for p in parts[1:4]]
            except ValueError:
                raise InputError(f"{path}:{lineno}: malformed vertex line {line.strip()!r}") from None
            if len(xyz) != 3:
                raise InputError(f"{path}:{lineno}: vertex needs 3 coordinates")
            if not all(math.isfinite(c) for c in xyz):
                raise InputError(
                    f"{path}:{lineno}: vertex {len(vertices)} has a non-finite coordinate"
                )
            vertices.append(xyz)
        elif tag == "f":
            face = []
            for token in parts[1:]:
                try:
                    index = int(token.split("/")[0])
                except ValueError:
                    raise InputError(f"{path}:{lineno}: malformed face line {line.strip()!r}") from None
                if index == 0:
                    raise InputError(f"{path}:{lineno}: OBJ vertex indices start at 1, not 0")
                # OBJ indices are 1-based; negative ones count back from the last vertex.
                face.append(index - 1 if index > 0 else len(vertices) + index)
            if len(face) < 3:
                raise InputError(f"{path}:{lineno}: face {len(faces)} has fewer than 3 vertices")
            faces.append(face)
        elif tag == "vn":
            try:
                normals.append([float(p) for p in parts[1:4]])
            except ValueError:
                raise InputError(f"{path}:{lineno}: malformed normal line {line.strip()!r}") from None
        elif tag in ("vt", "vp", "o", "g", "s", "l", "usemtl", "mtllib", "p"):
            continue
        else:
            raise InputError(f"{path}:{lineno}: not an OBJ line: {line.strip()[:40]!r}")

    if not vertices:
        raise InputError(f"{path}: no vertices (is this an OBJ file?)")
    if not faces:
        raise InputError(f"{path}: no faces")
    n = len(vertices)
    face_arrays = [np.asarray(f, dtype=np.int64) for f in faces]
    for i, f in enumerate(face_arrays):
        if f.min() < 0 or f.max() >= n:
            raise InputError(f"{path}: face {i} refers to a vertex outside 1..{n}")
    per_vertex = None
    if len(normals) == n and all(len(v) == 3 for v in normals):
        per_vertex = np.asarray(normals, dtype=np.float64)
        if not np.isfinite(per_vertex).all():
            raise InputError(f"{path}: a vertex normal has a non-finite coordinate")
    return np.asarray(vertices, dtype=np.float64), face_arrays, per_vertex


def format_obj(vertices: np.ndarray, faces, header: str = "",
               normals: np.ndarray | None = None) -> str:
    """OBJ text for a polygon mesh; coordinates round-trip exactly (17 significant digits).
    With `normals` (n, 3), one ``vn`` per vertex is written and faces refer to it."""
    lines = [f"# {row}" for row in header.splitlines()] if header else []
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in np.asarray(vertices, float)]
    if normals is None:
        lines += ["f " + " ".join(str(int(i) + 1) for i in face) for face in faces]
    else:
        lines += [f"vn {x:.17g} {y:.17g} {z:.17g}" for x, y, z in np.asarray(normals, float)]
        lines += ["f " + " ".join(f"{int(i) + 1}//{int(i) + 1}" for i in face) for face in faces]
    return "\n".join(lines) + "\n"


_UMASK = os.umask(0)
os.umask(_UMASK)


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it onto `path` only if the block succeeds.

    A failed run therefore never leaves a half-written file behind.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_obj(path: str | os.PathLike, vertices: np.ndarray, faces, header: str = "",
              normals: np.ndarray | None = None) -> None:
    """Write a polygon mesh as OBJ atomically, keeping vertex and face order and face sizes
    (and per-vertex normals when given)."""
    text = format_obj(vertices, faces, header, normals)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def _finite_or_none(obj):
    """Replace NaN and infinities (undefined measurements) by None, recursively."""
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite_or_none(obj.tolist())
    if isinstance(obj, (float, np.floating)) and not math.isfinite(obj):
        return None
    return obj


def json_text(record: dict) -> str:
    """JSON text of a record; numpy values become plain JSON, NaN and infinities null."""
    return json.dumps(_finite_or_none(record), indent=2, default=_json_default,
                      allow_nan=False) + "\n"


def write_json(path: str | os.PathLike, record: dict) -> None:
    """Write a JSON record atomically (see `json_text`)."""
    write_texts({Path(path): json_text(record)})


def write_texts(files: dict) -> None:
    """Write several text files as one step: all of them, or none.

    Every file goes to a temporary file beside it first; the renames happen only after
    all writes succeeded, and leftovers are removed on failure.

    Raises
    ------
    InputError
        When a file cannot be written (the message names it).
    """
    temporary: dict = {}
    current = None
    try:
        for current, text in files.items():
            current = Path(current)
            check_writable(current)
            fd, tmp = tempfile.mkstemp(prefix=f".{current.name}.", suffix=".tmp",
                                       dir=current.parent)
            temporary[current] = Path(tmp)
            os.chmod(tmp, 0o666 & ~_UMASK)   # mkstemp makes 0600; outputs are for sharing
            with os.fdopen(fd, "w", encoding="utf-8") as handle:
                handle.write(text)
        for current, tmp in temporary.items():
            os.replace(tmp, current)
    except OSError as exc:
        raise InputError(f"{current}: cannot write ({exc.strerror or exc})") from None
    finally:
        for tmp in temporary.values():
            if tmp.exists():
                tmp.unlink()


def check_writable(path: str | os.PathLike) -> None:
    """Make sure `path` can be written (creating its folder), before any long work.

    Raises
    ------
    InputError
        When the path is a folder, or a file stands where a folder is needed, or the
        folder is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        raise InputError(f"{path}: cannot create its folder {path.parent}") from None
    if not os.access(path.parent, os.W_OK):
        raise InputError(f"{path}: the folder is not writable")
