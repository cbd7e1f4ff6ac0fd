"""Rhino .3dm files in: the one surface, polysurface face or mesh a design is read from.

A .3dm file may hold many objects. `read_3dm` picks the design among its surfaces,
polysurfaces (Breps, extrusions) and meshes, by layer and/or object name when there is
more than one, and returns its geometry as plain arrays: a NURBS surface's control
points, weights and knot vectors (with the trims of a polysurface face as 3D polylines),
or a mesh's vertices and triangles, in the file's unit system or converted to another.
Anything it cannot use is refused with one line that lists what the file holds.

A design is named on the command line and in study files as ``FILE.3dm`` or
``FILE.3dm#key=value,...`` (`split_source`) with the keys ``layer`` (a layer name or
full path ``Parent::Child``), ``object`` (an object name), ``face`` (a face number of a
polysurface, from 0) and ``units`` (convert to mm, cm, m, in or ft).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .inputs import check_coordinates, check_input_file
from .units import MM_PER_UNIT

__all__ = ["MM_PER_UNIT", "SOURCE_KEYS", "RhinoSurface", "RhinoDesign", "read_3dm",
           "split_source", "is_3dm_source", "describe_3dm"]

#: Millimetres per model unit of the unit systems a design file may be in.

#: The choices a ``FILE.3dm#key=value,...`` source may make.
SOURCE_KEYS = ("layer", "object", "face", "units")

# Rhino's unit systems by their enum name, and the name fabplan uses
_RHINO_UNITS = {"Millimeters": "mm", "Centimeters": "cm", "Meters": "m", "Inches": "in",
                "Feet": "ft", "None": None}

# edge samples per trim: a polyline this fine follows a trim within a small fraction of
# the layout's triangles
_TRIM_SAMPLES = 64


@dataclass
class RhinoSurface:
    """A NURBS surface read from a .3dm file, in standard (clamped or not) knot form.

    Attributes
    ----------
    control_points : (nu, nv, 3) float, Euclidean (model units).
    weights : (nu, nv) float.
    knots_u, knots_v : (nu + degree_u + 1,), (nv + degree_v + 1,) float (Rhino's knots
        with the superfluous first and last added).
    degree_u, degree_v : int.
    closed_u, closed_v : the surface closes up in that direction (its two edges meet, a
        tower's seam).
    trims : the loops of a polysurface face as closed 3D polylines, list of (k, 3)
        float, the outer loop first; None for a surface without trims.
    """

    control_points: np.ndarray
    weights: np.ndarray
    knots_u: np.ndarray
    knots_v: np.ndarray
    degree_u: int
    degree_v: int
    closed_u: bool = False
    closed_v: bool = False
    trims: list[np.ndarray] | None = None


@dataclass
class RhinoDesign:
    """The design read from a .3dm file.

    Attributes
    ----------
    path : the file.
    kind : ``"surface"``, ``"polysurface face"``, ``"extrusion"`` or ``"mesh"``.
    label : the object as a user finds it in Rhino (name, layer, face).
    units : unit of the returned coordinates (``MM_PER_UNIT`` key), or None when the file
        has no unit system and none was asked for.
    file_units : the file's own unit system (None: unitless), and `rhino_units` its
        Rhino name.
    scale : factor applied to the file's coordinates to give `units`.
    surface : the NURBS surface (all kinds but meshes), or None.
    vertices, triangles : (n, 3) float and (t, 3) int of a mesh (quads split in two), or
        None.
    holds : what the file holds, for messages.
    """

    path: Path
    kind: str
    label: str
    units: str | None
    file_units: str | None
    rhino_units: str
    scale: float
    surface: RhinoSurface | None = None
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None
    holds: str = ""
    choice: dict[str, str] = field(default_factory=dict)

    @property
    def mm_per_unit(self) -> float | None:
        return None if self.units is None else MM_PER_UNIT[self.units]

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"file": str(self.path), "kind": self.kind, "object": self.label,
                               "units": self.units, "file_units": self.file_units,
                               "scale": self.scale, "choice": dict(self.choice)}
        if self.surface is not None:
            s = self.surface
            out["nurbs"] = {"degree": [s.degree_u, s.degree_v],
                            "control_points": list(s.control_points.shape[:2]),
                            "rational": bool(np.ptp(s.weights) > 0),
                            "trim_loops": 0 if s.trims is None else len(s.trims)}
        else:
            out["mesh"] = {"vertices": int(len(self.vertices if self.vertices is not None else [])),
                           "triangles": int(len(self.triangles if self.triangles is not None else []))}
        return out


def is_3dm_source(source: str | os.PathLike) -> bool:
    """True for ``FILE.3dm`` and ``FILE.3dm#...`` (any case).

    Examples
    --------
    >>> is_3dm_source("roof.3dm#layer=Shell"), is_3dm_source("roof.obj")
    (True, False)
    """
    text = str(source)
    if Path(text).suffix.lower() == ".3dm":
        return True
    head, sep, _ = text.rpartition("#")
    return bool(sep) and Path(head).suffix.lower() == ".3dm"


def split_source(source: str | os.PathLike) -> tuple[Path, dict[str, str]]:
    """The file and the choices of a ``FILE.3dm#key=value,...`` source.

    A path that exists as given is a file even when it holds a ``#``.

    Raises
    ------
    InputError
        For an unknown key, a key without a value, or a value out of range.

    Examples
    --------
    >>> split_source("roof.3dm#layer=Facade::South,face=2")
    (PosixPath('roof.3dm'), {'layer': 'Facade::South', 'face': '2'})
    """
    text = str(source)
    head, sep, tail = text.rpartition("#")
    if not sep or Path(text).exists() or Path(head).suffix.lower() != ".3dm":
        return Path(text), {}
    choice: dict[str, str] = {}
    for item in filter(None, (p.strip() for p in tail.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq or not value.strip():
            raise InputError(f"{text}: expected key=value after '#', got {item!r} "
                             f"(keys: {', '.join(SOURCE_KEYS)})")
        if key not in SOURCE_KEYS:
            raise InputError(f"{text}: unknown choice {key!r}; a .3dm design takes "
                             f"{', '.join(SOURCE_KEYS)}")
        choice[key] = value.strip()
    if "units" in choice and choice["units"] not in MM_PER_UNIT:
        raise InputError(f"{text}: units must be one of {', '.join(MM_PER_UNIT)}, got "
                         f"{choice['units']!r}")
    if "face" in choice and not choice["face"].isdigit():
        raise InputError(f"{text}: face must be a face number (0, 1, ...), got {choice['face']!r}")
    return Path(head), choice


# ----------------------------------------------------------------------------- reading
def _open_3dm(path: Path) -> Any:
    try:
        import rhino3dm
    except ImportError:   # pragma: no cover - a base dependency; a broken install says so
        raise InputError(f"{path}: reading .3dm files needs the rhino3dm package "
                         "(pip install rhino3dm)") from None
    check_input_file(path, "a Rhino .3dm file")
    with open(path, "rb") as handle:
        head = handle.read(32)
    model = rhino3dm.File3dm.Read(str(path)) if head.startswith(b"3D Geometry File Format") else None
    if model is None:
        raise InputError(f"{path}: not a readable Rhino .3dm file (corrupt, truncated or "
                         "another format)")
    return model


@dataclass
class _Entry:
    """One object of the file, as listed in messages and matched against a choice."""

    index: int
    kind: str            # what it is, in words
    usable: bool
    name: str
    layer: str
    layer_path: str
    geometry: Any
    faces: int = 1

    def describe(self) -> str:
        name = f"'{self.name}'" if self.name else "unnamed"
        faces = f" of {self.faces} faces" if self.faces > 1 else ""
        return f"{self.kind}{faces} {name} on layer '{self.layer}'"


def _entries(model: Any) -> list[_Entry]:
    import rhino3dm

    layers = {layer.Index: layer for layer in model.Layers}
    kinds = {rhino3dm.ObjectType.Surface: "surface", rhino3dm.ObjectType.Brep: "polysurface",
             rhino3dm.ObjectType.Extrusion: "extrusion", rhino3dm.ObjectType.Mesh: "mesh"}
    entries = []
    for i, obj in enumerate(model.Objects):
        geometry, attributes = obj.Geometry, obj.Attributes
        if geometry is None:
            continue
        layer = layers.get(attributes.LayerIndex)
        kind = kinds.get(geometry.ObjectType)
        faces = len(geometry.Faces) if kind == "polysurface" else 1
        entries.append(_Entry(
            i, kind or _object_kind(geometry), kind is not None, attributes.Name or "",
            layer.Name if layer is not None else "Default",
            (layer.FullPath or layer.Name) if layer is not None else "Default", geometry, faces))
    return entries


def _object_kind(geometry: Any) -> str:
    """An unsupported object in words (``curve``, ``point``, ``SubD`` ...)."""
    name = str(geometry.ObjectType).split(".")[-1]
    words = {"Curve": "curve", "Point": "point", "PointSet": "point cloud", "SubD": "SubD",
             "Annotation": "annotation", "InstanceReference": "block instance",
             "TextDot": "text dot", "Hatch": "hatch", "Light": "light"}
    return words.get(name, name.lower() or "object")


def _summary(entries: list[_Entry], limit: int = 6) -> str:
    """What the file holds, in one line: usable objects named, the rest counted."""
    if not entries:
        return "the file holds no objects"
    usable = [e for e in entries if e.usable]
    others: dict[str, int] = {}
    for e in entries:
        if not e.usable:
            others[e.kind] = others.get(e.kind, 0) + 1
    parts = [e.describe() for e in usable[:limit]]
    if len(usable) > limit:
        parts.append(f"{len(usable) - limit} more surfaces or meshes")
    parts += [f"{n} {kind}{'s' if n > 1 else ''}" for kind, n in sorted(others.items())]
    return "the file holds " + "; ".join(parts)


def describe_3dm(path: str | os.PathLike) -> str:
    """One line saying what a .3dm file holds (objects, their names and layers).

    Raises
    ------
    InputError
        When the file is missing or not a readable .3dm file.
    """
    return _summary(_entries(_open_3dm(Path(path))))


def read_3dm(path: str | os.PathLike, *, layer: str | None = None, object_name: str | None = None,
             face: int | None = None, units: str | None = None) -> RhinoDesign:
    """The design surface or mesh of a .3dm file.

    Parameters
    ----------
    path : the file (a ``FILE.3dm#key=value`` source is split by `split_source` first).
    layer : take only objects on this layer (name or full path).
    object_name : take only objects of this name.
    face : the face of a polysurface of several faces (from 0).
    units : convert the coordinates to these units (a `MM_PER_UNIT` key); None keeps the
        file's.

    Returns
    -------
    `RhinoDesign`.

    Raises
    ------
    InputError
        A missing, empty or corrupt file; no surface or mesh (after the choice); more than
        one and no choice that singles one out; a polysurface of several faces and no
        face; a unit system fabplan does not know, or a conversion from a unitless file;
        unusable coordinates. The message lists what the file holds.
    """
    path = Path(path)
    model = _open_3dm(path)
    entries = _entries(model)
    holds = _summary(entries)
    choice = {k: v for k, v in (("layer", layer), ("object", object_name)) if v is not None}
    if face is not None:
        choice["face"] = str(face)
    entry = _chosen_entry(path, entries, holds, layer, object_name, choice)
    file_units, rhino_units = _unit_system(model, path)
    if units is not None and units not in MM_PER_UNIT:
        raise InputError(f"{path}: units must be one of {', '.join(MM_PER_UNIT)}, got {units!r}")
    if units is not None and file_units is None:
        raise InputError(f"{path}: the file has no unit system, so it cannot be converted to "
                         f"{units}; set the units in Rhino (Document Properties > Units)")
    scale = 1.0 if units is None or file_units is None else MM_PER_UNIT[file_units] / MM_PER_UNIT[units]
    out_units = units or file_units
    label = entry.describe()
    design = RhinoDesign(path, entry.kind, label, out_units, file_units, rhino_units, scale,
                         holds=holds, choice=choice)
    _read_geometry(design, entry, face, path)
    return design


def _chosen_entry(path: Path, entries: list[_Entry], holds: str, layer: str | None,
                  object_name: str | None, choice: dict[str, str]) -> _Entry:
    """The one surface, polysurface or mesh of `entries` on `layer` and of `object_name`
    (None: any); InputError when there is none or more than one, saying what the file
    `holds`."""
    picked = [e for e in entries
              if (layer is None or layer in (e.layer, e.layer_path))
              and (object_name is None or e.name == object_name)]
    usable = [e for e in picked if e.usable]
    said = " and ".join(f"{k} {v!r}" for k, v in choice.items() if k != "face")
    if not usable:
        if not said:
            raise InputError(f"{path}: no surface, polysurface or mesh to read; {holds}")
        if picked:
            kinds = sorted({e.kind for e in picked})
            raise InputError(f"{path}: {said} holds no surface, polysurface or mesh, only "
                             f"{', '.join(kinds)} (unsupported); {holds}")
        raise InputError(f"{path}: no object matches {said}; {holds}")
    if len(usable) > 1:
        how = "name one with FILE.3dm#layer=NAME or #object=NAME (design.layer / design.object " \
              "in a study)"
        raise InputError(f"{path}: {len(usable)} surfaces or meshes{' match ' + said if said else ''}"
                         f" and no choice singles one out: {how}; {holds}")
    return usable[0]


def _read_geometry(design: RhinoDesign, entry: _Entry, face: int | None, path: Path) -> None:
    """Read the mesh, or the surface (a polysurface's `face`), of `entry` into `design`,
    scaled to its units, and check its coordinates."""
    geometry, label, scale = entry.geometry, design.label, design.scale
    if face is not None and entry.kind != "polysurface":
        raise InputError(f"{path}: face={face} picks a face of a polysurface; {label} is a "
                         f"{entry.kind}")
    if entry.kind == "mesh":
        design.vertices, design.triangles = _mesh_arrays(geometry, path)
        design.vertices = design.vertices * scale
        check_coordinates(design.vertices, f"{path} ({label})")
        return
    if entry.kind == "polysurface":
        count = len(geometry.Faces)
        if face is None and count > 1:
            raise InputError(f"{path}: {label} has {count} faces: pick one with "
                             f"FILE.3dm#object=NAME,face=K (design.face in a study), K in 0..{count - 1}")
        k = 0 if face is None else face
        if not 0 <= k < count:
            raise InputError(f"{path}: face={k}, but {label} has {count} faces (0..{count - 1})")
        design.kind = "polysurface face"
        design.label = f"{label}, face {k}" if count > 1 else label
        design.surface = _brep_face(geometry, k, path)
    else:   # a surface, or an extrusion's side surface
        design.surface = _nurbs_arrays(geometry.ToNurbsSurface(), path, label)
    s = design.surface
    s.control_points = s.control_points * scale
    s.trims = None if s.trims is None else [t * scale for t in s.trims]
    check_coordinates(s.control_points.reshape(-1, 3), f"{path} ({label})", element="control point")


def _unit_system(model: Any, path: Path) -> tuple[str | None, str]:
    name = str(model.Settings.ModelUnitSystem).split(".")[-1]
    if name not in _RHINO_UNITS:
        raise InputError(f"{path}: the model is in {name}; fabplan reads designs in millimetres, "
                         "centimetres, metres, inches or feet (change the units in Rhino: "
                         "Document Properties > Units, scaling the model)")
    return _RHINO_UNITS[name], name


def _nurbs_arrays(ns: Any, path: Path, label: str) -> RhinoSurface:
    """Control points, weights and standard knot vectors of a rhino3dm NurbsSurface."""
    if ns is None:
        raise InputError(f"{path}: {label} has no NURBS form")
    homogeneous = np.array(ns.Points, dtype=np.float64)          # (nu, nv, 3 or 4)
    if homogeneous.shape[2] == 4:
        weights = homogeneous[..., 3].copy()
        if not (weights > 0).all():
            raise InputError(f"{path}: {label} has a control point of weight "
                             f"{weights.min():g}; weights must be positive")
        points = homogeneous[..., :3] / weights[..., None]
    else:
        weights = np.ones(homogeneous.shape[:2])
        points = homogeneous[..., :3]
    knots = []
    for direction in (ns.KnotsU, ns.KnotsV):
        k = np.array(direction.ToList(), dtype=np.float64)
        knots.append(np.r_[k[:1], k, k[-1:]])   # Rhino omits one superfluous knot at each end
    return RhinoSurface(points, weights, knots[0], knots[1], ns.OrderU - 1, ns.OrderV - 1,
                        bool(ns.IsClosed(0)), bool(ns.IsClosed(1)))


def _brep_face(brep: Any, k: int, path: Path) -> RhinoSurface:
    """The NURBS form of face `k` of a Brep, with its loops as 3D polylines sampled along
    the edges of their trims."""
    face = brep.Faces[k]
    surface = _nurbs_arrays(face.ToNurbsSurface(), path, f"face {k}")
    loops: list[np.ndarray] = []
    for loop in face.Loops:
        kind = loop.LoopType.name          # Outer, Inner; slits and curves on the surface aside
        if kind not in ("Outer", "Inner"):
            continue
        pieces = []
        for t in range(loop.TrimCount):
            trim = loop.Trims[t]
            if trim.EdgeIndex < 0:       # a singular trim (a pole) has no edge
                continue
            edge = brep.Edges[trim.EdgeIndex]
            domain = edge.Domain
            ts = np.linspace(domain.T0, domain.T1, _TRIM_SAMPLES + 1)
            xyz = np.array([[p.X, p.Y, p.Z] for p in (edge.PointAt(x) for x in ts)])
            pieces.append(xyz[::-1] if trim.IsReversed else xyz)
        if pieces:
            polyline = np.concatenate([p[:-1] for p in pieces])
            if kind == "Outer":
                loops.insert(0, polyline)
            else:
                loops.append(polyline)
    surface.trims = loops or None
    return surface


def _mesh_arrays(mesh: Any, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a rhino3dm Mesh (each quad split along its 0-2 diagonal)."""
    vertices = np.array([[p.X, p.Y, p.Z] for p in mesh.Vertices.ToPoint3dArray()], dtype=np.float64)
    faces = np.array([tuple(mesh.Faces[i]) for i in range(len(mesh.Faces))], dtype=np.int64)
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(f"{path}: the mesh has no faces")
    quads = faces[:, 2] != faces[:, 3]
    triangles = np.concatenate([faces[:, :3], faces[quads][:, [0, 2, 3]]])
    return vertices, triangles
