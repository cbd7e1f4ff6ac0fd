"""Binary glTF (GLB) of a net coloured by mold, for web viewers (through trimesh).

Every face is fanned into triangles that keep its panel's colour; vertices are shared
within a panel only, so the colours stay flat per panel in any viewer.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from .output import atomic_path
from .rhino_write import MM_PER_UNIT, category_colours

__all__ = ["write_glb", "glb_triangles"]

NET_GREY = (180, 180, 180, 255)


def glb_triangles(faces: Sequence[Sequence[int]] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles of polygon faces and the face each triangle comes from.

    Returns
    -------
    triangles : (t, 3) int
    face : (t,) int

    Examples
    --------
    >>> tris, face = glb_triangles([[0, 1, 2, 3], [3, 2, 4]])
    >>> tris.tolist(), face.tolist()
    ([[0, 1, 2], [0, 2, 3], [3, 2, 4]], [0, 0, 1])
    """
    sizes = np.array([len(f) for f in faces], dtype=np.int64)
    flat = np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    face = np.repeat(np.arange(len(sizes)), sizes - 2)
    k = np.arange(len(face)) - np.repeat(np.cumsum(sizes - 2) - (sizes - 2), sizes - 2)
    triangles = np.stack([flat[start[face]], flat[start[face] + k + 1], flat[start[face] + k + 2]],
                         axis=1)
    return triangles, face


def write_glb(path: str | os.PathLike, vertices: np.ndarray,
              faces: Sequence[Sequence[int]] | np.ndarray, *,
              face_mold: np.ndarray | None = None, units: str = "m") -> Path:
    """Write the net as a GLB file, each face coloured by its mold (grey without molds).

    Parameters
    ----------
    vertices : (n, 3) float, model units.
    faces : polygon faces.
    face_mold : (f,) int, the mold of every face, or None.
    units : the model units (a key of `MM_PER_UNIT`); glTF is in metres, so the
        coordinates are scaled to metres.

    Returns
    -------
    Path of the file, written atomically.
    """
    import trimesh

    triangles, face = glb_triangles(faces)
    if face_mold is None:
        colours = np.tile(np.array(NET_GREY, dtype=np.uint8), (len(face), 1))
    else:
        mold = np.asarray(face_mold, dtype=np.int64)
        colours = category_colours(int(mold.max()) + 1)[mold[face]]
    # one copy of the corners per triangle: flat colours, no blending across panels
    metres = MM_PER_UNIT[units] / 1000.0
    corners = metres * np.asarray(vertices, dtype=np.float64)[triangles].reshape(-1, 3)
    mesh = trimesh.Trimesh(vertices=corners, faces=np.arange(len(corners)).reshape(-1, 3),
                           face_colors=colours, process=False)
    data = mesh.export(file_type="glb")
    if not isinstance(data, bytes):  # pragma: no cover - trimesh returns bytes for glb
        raise TypeError(f"trimesh exported {type(data).__name__} instead of GLB bytes")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path
