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

__all__ = ["read_obj", "write_obj", "atomic_path", "write_json", "format_obj"]


def read_obj(path: str | os.PathLike) -> tuple[np.ndarray, list[np.ndarray]]:
    """Read vertices and polygonal faces from an OBJ file.

    Parameters
    ----------
    path : path of the OBJ file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : list of (k,) int arrays, 0-based vertex indices in file order.

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
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text OBJ file (binary content)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None

    vertices: list[list[float]] = []
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
                # OBJ indices are 1-based; negative ones count back from the last vertex.
                face.append(index - 1 if index > 0 else len(vertices) + index)
            if len(face) < 3:
                raise InputError(f"{path}:{lineno}: face {len(faces)} has fewer than 3 vertices")
            faces.append(face)
        elif tag in ("vn", "vt", "vp", "o", "g", "s", "l", "usemtl", "mtllib", "p"):
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
    return np.asarray(vertices, dtype=np.float64), face_arrays


def format_obj(vertices: np.ndarray, faces, header: str = "") -> str:
    """OBJ text for a polygon mesh; coordinates round-trip exactly (17 significant digits)."""
    lines = [f"# {row}" for row in header.splitlines()] if header else []
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in np.asarray(vertices, float)]
    lines += ["f " + " ".join(str(int(i) + 1) for i in face) for face in faces]
    return "\n".join(lines) + "\n"


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it onto `path` only if the block succeeds.

    A failed run therefore never leaves a half-written file behind.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_obj(path: str | os.PathLike, vertices: np.ndarray, faces, header: str = "") -> None:
    """Write a polygon mesh as OBJ atomically, keeping vertex and face order and face sizes."""
    text = format_obj(vertices, faces, header)
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


def write_json(path: str | os.PathLike, record: dict) -> None:
    """Write a JSON record atomically; numpy values become plain JSON, NaN becomes null."""
    text = json.dumps(_finite_or_none(record), indent=2, default=_json_default, allow_nan=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
