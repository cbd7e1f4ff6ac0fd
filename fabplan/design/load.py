"""A design surface from a file or a built-in surface spec."""

from __future__ import annotations

import os
from pathlib import Path

from ..io.triangles import read_triangles
from .mesh_surface import DesignSurface
from .parametric import surface_from_spec

__all__ = ["load_design"]


def load_design(source: str | os.PathLike, *, resolution: int | tuple | None = None,
                triangles: int = 40000) -> DesignSurface:
    """A design surface from a mesh file (OBJ, STL, PLY, OFF) or a built-in surface spec.

    Parameters
    ----------
    source : a path to an existing file, or ``"name[:key=value,...]"`` (`surface_from_spec`).
    resolution : grid cells of the triangulation of a parametric surface.
    triangles : approximate triangle count of that triangulation when no resolution is given.
    """
    path = Path(source)
    looks_like_file = path.suffix.lower() in (".obj", ".stl", ".ply", ".off") or path.exists()
    if not looks_like_file:
        surface = surface_from_spec(str(source))
        return surface.triangulate(resolution or surface.resolution_for(triangles))
    vertices, faces = read_triangles(path)
    return DesignSurface(vertices, faces, name=str(path))
