"""A design surface from a file or a built-in surface spec."""

from __future__ import annotations

import os
from pathlib import Path

from ..io.resources import DESIGN_MEMORY, check_memory
from ..io.rhino_read import RhinoDesign, is_3dm_source, read_3dm, split_source
from ..io.triangles import read_triangles
from .mesh_surface import DesignSurface
from .nurbs import NurbsSurface, trims_to_parameters
from .parametric import FILE_PARAMETERS, SURFACES, surface_from_spec

__all__ = ["load_design", "load_3dm_design", "names_a_file", "nurbs_from_rhino", "design_files"]


def names_a_file(source: str | os.PathLike) -> bool:
    """Whether `source` names a mesh file rather than a built-in surface spec: a mesh
    suffix, an existing file, or another existing path (a folder, refused as such later)
    unless it is named like a built-in surface, which it does not shadow."""
    path = Path(source)
    if path.suffix.lower() in (".obj", ".stl", ".ply", ".off"):
        return True
    try:
        return path.is_file() or (path.exists() and str(source).partition(":")[0] not in SURFACES)
    except OSError:         # a name too long for the system (a spec with many keys) is no file
        return False


def design_files(source: str | os.PathLike) -> list[Path]:
    """The files a design source reads: a mesh or Rhino file (without its ``#`` choice),
    or the files a built-in surface's parameters name (``profile=``, ``heights=``,
    ``control_points=``); outputs must not replace them.

    Examples
    --------
    >>> design_files("revolution:profile=p.txt,sweep_deg=90")
    [PosixPath('p.txt')]
    >>> design_files("roof.3dm#layer=Roof")
    [PosixPath('roof.3dm')]
    """
    text = str(source)
    if names_a_file(text) or is_3dm_source(text):
        return [Path(text.split("#", 1)[0])]
    _, _, rest = text.partition(":")
    return [Path(value.strip()) for key, eq, value in
            (item.partition("=") for item in rest.split(",")) if eq and key.strip() in FILE_PARAMETERS]


def load_design(source: str | os.PathLike, *, resolution: int | tuple | None = None,
                triangles: int = 40000) -> DesignSurface:
    """A design surface from a mesh file (OBJ, STL, PLY, OFF), a Rhino file
    (``FILE.3dm`` or ``FILE.3dm#layer=..,object=..,face=..,units=..``, see
    `fabplan.io.rhino_read`) or a built-in surface spec.

    Parameters
    ----------
    source : a path to an existing file, a .3dm source, or ``"name[:key=value,...]"``
        (`surface_from_spec`).
    resolution : grid cells of the triangulation of a parametric (or NURBS) surface.
    triangles : approximate triangle count of that triangulation when no resolution is given.
    """
    if is_3dm_source(source):
        return load_3dm_design(source, resolution=resolution, triangles=triangles)
    path = Path(source)
    if not names_a_file(source):
        surface = surface_from_spec(str(source))
        return surface.triangulate(resolution or surface.resolution_for(triangles))
    vertices, faces = read_triangles(path)
    check_memory(DESIGN_MEMORY, len(faces), where=str(path),
                 fix="lay out a coarser mesh of the design (fewer triangles)")
    return DesignSurface(vertices, faces, name=str(path))


def load_3dm_design(source: str | os.PathLike, *, resolution: int | tuple | None = None,
                    triangles: int = 40000) -> DesignSurface:
    """The design of a .3dm file: a NURBS surface (or polysurface face, trimmed) as an
    exact `NurbsSurface` sampled by a triangulation, or a mesh as it is.

    The design's `units` are the file's unit system (or those the source converts to)
    and its `source` records the object read (`RhinoDesign.to_json`).
    """
    path, choice = split_source(source)
    read = read_3dm(path, layer=choice.get("layer"), object_name=choice.get("object"),
                    face=int(choice["face"]) if "face" in choice else None,
                    units=choice.get("units"))
    name = str(source)
    if read.surface is None:
        assert read.vertices is not None and read.triangles is not None
        design = DesignSurface(read.vertices, read.triangles, name=name)
    else:
        surface = nurbs_from_rhino(read, name=name)
        design = surface.triangulate(resolution or surface.resolution_for(triangles))
    design.units = read.units
    design.source = read.to_json()
    return design


def nurbs_from_rhino(read: RhinoDesign, *, name: str | None = None) -> NurbsSurface:
    """The exact `NurbsSurface` of a surface read from a .3dm file, its trims (3D loops)
    taken into its parameter domain by closest-point projection.

    A surface closed in one direction (a tower) wraps around its seam; closed in v only,
    its directions are swapped so that u is the one that wraps (`ParametricSurface` wraps
    u). A surface closed in both directions (a torus) is cut open along its v seam.
    """
    s = read.surface
    if s is None:
        raise ValueError("not a surface")
    label = name or f"{read.path} ({read.label})"
    P, W, ku, kv, p, q = s.control_points, s.weights, s.knots_u, s.knots_v, s.degree_u, s.degree_v
    closed = s.closed_u
    if s.closed_v and not s.closed_u:
        P, W, ku, kv, p, q = P.transpose(1, 0, 2), W.T, kv, ku, q, p
        closed = True
    surface = NurbsSurface(P, W, ku, kv, p, q, name=label, periodic_u=closed)
    if s.trims is None:
        return surface
    trims = trims_to_parameters(surface, s.trims)
    if trims is None:
        return surface
    return NurbsSurface(P, W, ku, kv, p, q, name=label, trims=trims, periodic_u=closed)
