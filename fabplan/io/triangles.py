"""Triangle mesh files (OBJ, STL, PLY, OFF) as vertex and triangle arrays."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from .obj import read_obj

__all__ = ["read_triangles", "TRIANGLE_FORMATS"]

TRIANGLE_FORMATS = (".obj", ".stl", ".ply", ".off")


def read_triangles(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a mesh file: OBJ (polygons fan-triangulated), STL, PLY, OFF.

    The one reader of triangle mesh files: design surfaces and reference surfaces both
    read through it.

    Raises
    ------
    InputError
        When the file is missing, empty, a folder, unreadable or holds no faces.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a surface file")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file (not a surface)")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        vertices, polygons = read_obj(path)
        tris = [np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], axis=1) for f in polygons]
        return vertices, np.concatenate(tris)
    if suffix not in (".stl", ".ply", ".off"):
        raise InputError(f"{path}: unknown surface format {suffix or '(none)'}; "
                         "use OBJ, STL, PLY or OFF")
    import trimesh

    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise InputError(f"{path}: cannot read as {suffix[1:].upper()} "
                         f"({type(exc).__name__})") from None
    if not isinstance(loaded, trimesh.Trimesh):  # force="mesh" returns one Trimesh
        raise InputError(f"{path}: no faces")
    vertices, faces = np.asarray(loaded.vertices), np.asarray(loaded.faces)
    if faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"{path}: no faces")
    return vertices, faces


# ---------------------------------------------------------------------------- topology helpers
