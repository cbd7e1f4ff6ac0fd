"""Rhino .3dm files of nets, molds, strips and arcs (rhino3dm, openNURBS 8).

A net is written as one quad mesh with double-precision vertices (the coordinates of
``OUT.obj`` exactly), its parameter polylines on one layer per family, and, when known,
its panels on one layer per mold (each panel one mesh object, coloured by its mold) and
the strips' reference curves on one layer per family. Object names and user text carry
the ids of fabplan's CSV and JSON files (``face`` and ``mold`` of ``panels.csv``,
``strip`` of ``strips.csv``, ``edge`` of an arc report), so that a row can be found in
Rhino with ``SelName`` or the user text panel. The file's unit system is the net's.

Layers (flat names, so that scripts find them by name)::

    net                 the quad mesh
    lines A, lines B    parameter polylines of family 0 and 1
    mold 0, mold 1, ... the panels of each mold (user text: face, mold)
    strips A, strips B  strip reference curves (user text: strip, family)
    arcs A, arcs B      circular arcs of the edges of each family (`fabplan arcs`)

`read_3dm_net` reads such a file's net back (the round trip of the tests and of scripts
that edit a net in Rhino); design surfaces are read by `fabplan.io.rhino_read`.
"""

from __future__ import annotations

import colorsys
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InputError
from .inputs import check_input_file
from .output import atomic_path
from .units import MM_PER_UNIT

__all__ = [
    "RHINO_UNITS",
    "MM_PER_UNIT",
    "FAMILY_NAMES",
    "category_colours",
    "Rhino3dmWriter",
    "NetDrawing",
    "write_net_3dm",
    "read_3dm_net",
]

RHINO_UNITS = {"mm": "Millimeters", "cm": "Centimeters", "m": "Meters", "in": "Inches",
               "ft": "Feet"}
"""fabplan unit name -> the `rhino3dm.UnitSystem` member a file is written in."""


FAMILY_NAMES = ("A", "B")
"""Letters of the two families of parameter lines, as in strip ids (``A07``)."""

NET_LAYER = "net"
NET_COLOUR = (170, 170, 170, 255)
LINE_COLOURS = ((200, 40, 40, 255), (40, 80, 200, 255))


def category_colours(count: int) -> np.ndarray:
    """(count, 4) uint8 RGBA colours, one per category (mold), neighbours far apart in hue.

    Hues step by the golden angle, so that molds with neighbouring ids (often panels next
    to each other) get clearly different colours, and the same id always the same colour.

    Examples
    --------
    >>> category_colours(3)
    array([[217,  87,  87, 255],
           [ 87, 217, 125, 255],
           [163,  87, 217, 255]], dtype=uint8)
    """
    hues = (np.arange(count) * 0.381966011250105) % 1.0
    rgb = [colorsys.hsv_to_rgb(h, 0.6, 0.85) for h in hues]
    out = np.full((count, 4), 255, dtype=np.uint8)
    if count:
        out[:, :3] = np.rint(np.array(rgb) * 255).astype(np.uint8)
    return out


def _rhino() -> Any:
    try:
        import rhino3dm
    except ImportError as exc:  # pragma: no cover - a base dependency
        raise InputError("writing .3dm files needs rhino3dm: pip install rhino3dm") from exc
    return rhino3dm


class Rhino3dmWriter:
    """A .3dm document being built: layers by name, objects with names and user text.

    Parameters
    ----------
    units : a key of `RHINO_UNITS`: the file's model unit system.
    tolerance : model absolute tolerance in those units (Rhino's ``Units`` page).
    """

    def __init__(self, units: str = "m", *, tolerance: float | None = None) -> None:
        if units not in RHINO_UNITS:
            raise InputError(f"unknown units {units!r} for a .3dm file: use "
                             + ", ".join(RHINO_UNITS))
        r = _rhino()
        self.units = units
        self.doc = r.File3dm()
        self.doc.Settings.ModelUnitSystem = getattr(r.UnitSystem, RHINO_UNITS[units])
        if tolerance is not None:
            self.doc.Settings.ModelAbsoluteTolerance = float(tolerance)
        self.layers: dict[str, int] = {}

    def layer(self, name: str, colour: Sequence[int] = (0, 0, 0, 255)) -> int:
        """Index of the layer `name`, created with `colour` (RGBA 0-255) on first use."""
        if name not in self.layers:
            rgba = tuple(int(c) for c in colour)
            self.layers[name] = self.doc.Layers.AddLayer(name, rgba + (255,) * (4 - len(rgba)))
        return self.layers[name]

    def _attributes(self, layer: str, name: str, user_text: Mapping[str, object],
                    colour: Sequence[int] | None) -> Any:
        r = _rhino()
        attributes = r.ObjectAttributes()
        attributes.LayerIndex = self.layer(layer)
        attributes.Name = name
        for key, value in user_text.items():
            attributes.SetUserString(str(key), str(value))
        if colour is not None:
            attributes.ObjectColor = tuple(int(c) for c in colour)
            attributes.ColorSource = r.ObjectColorSource.ColorFromObject
        return attributes

    def add_mesh(self, vertices: np.ndarray, faces: Sequence[Sequence[int]] | np.ndarray, *,
                 layer: str, name: str = "", user_text: Mapping[str, object] | None = None,
                 colour: Sequence[int] | None = None) -> None:
        """Add a polygon mesh: triangles and quads as they are, larger faces as fans.

        Parameters
        ----------
        vertices : (n, 3) float, stored in double precision (read back exactly).
        faces : sequence of vertex index sequences into `vertices`.
        """
        r = _rhino()
        mesh = r.Mesh()
        mesh.Vertices.UseDoublePrecisionVertices = True
        for x, y, z in np.asarray(vertices, dtype=np.float64).tolist():
            mesh.Vertices.AddPoint3d(x, y, z)
        for face in faces:
            f = [int(i) for i in face]
            if len(f) == 3:
                mesh.Faces.AddFace(f[0], f[1], f[2])
            elif len(f) == 4:
                mesh.Faces.AddFace(f[0], f[1], f[2], f[3])
            else:
                for k in range(1, len(f) - 1):
                    mesh.Faces.AddFace(f[0], f[k], f[k + 1])
        self.doc.Objects.AddMesh(mesh, self._attributes(layer, name, user_text or {}, colour))

    def add_polyline(self, points: np.ndarray, *, layer: str, name: str = "",
                     user_text: Mapping[str, object] | None = None,
                     colour: Sequence[int] | None = None) -> None:
        """Add a polyline through `points` ((k, 3) float, k >= 2)."""
        r = _rhino()
        curve = r.PolylineCurve(r.Point3dList([r.Point3d(*p) for p in np.asarray(points).tolist()]))
        self.doc.Objects.AddCurve(curve, self._attributes(layer, name, user_text or {}, colour))

    def add_arc(self, start: np.ndarray, middle: np.ndarray, end: np.ndarray, *, layer: str,
                name: str = "", user_text: Mapping[str, object] | None = None,
                straight: bool = False) -> None:
        """Add the circular arc from `start` through `middle` to `end` ((3,) float each) as
        an ArcCurve (a true arc), or a LineCurve when `straight`.

        The arc is built from three points: rhino3dm's start-tangent-end constructor
        returned wrong radii (0.50 instead of 10.01 for a unit chord at 2.9 deg).
        """
        r = _rhino()
        a, m, b = (r.Point3d(*np.asarray(p, dtype=np.float64).tolist()) for p in (start, middle, end))
        attributes = self._attributes(layer, name, user_text or {}, None)
        if straight:
            self.doc.Objects.AddCurve(r.LineCurve(a, b), attributes)
            return
        self.doc.Objects.AddCurve(r.ArcCurve.CreateFromArc(r.Arc(a, m, b)), attributes)

    def write(self, path: str | os.PathLike) -> Path:
        """Write the file atomically (openNURBS version 8); returns its path."""
        path = Path(path)
        with atomic_path(path) as tmp:
            if not self.doc.Write(str(tmp), 8):
                raise InputError(f"{path}: rhino3dm could not write the file")
        return path


@dataclass
class NetDrawing:
    """What a net's .3dm file holds beside the mesh.

    Attributes
    ----------
    vertices : (n, 3) float, model units.
    faces : list of (k,) int vertex index arrays, in the order of the OBJ.
    polylines : list of ((k,) int vertex ids, family 0/1) parameter polylines.
    face_mold : (f,) int mold of every face (`fabplan.fabricate.molds.MoldPlan.mold`), or
        None: no mold layers.
    strips : list of (strip id, family, (k, 3) float points): strip reference curves (they
        may run beyond the net, through its boundary panels).
    units : a key of `RHINO_UNITS`.
    name : the net's name, stored as user text of the mesh.
    user_text : more user text of the mesh (net type, status).
    """

    vertices: np.ndarray
    faces: Sequence[Sequence[int]] | np.ndarray
    polylines: list = field(default_factory=list)
    face_mold: np.ndarray | None = None
    strips: list = field(default_factory=list)
    units: str = "m"
    name: str = "net"
    user_text: dict = field(default_factory=dict)


def write_net_3dm(path: str | os.PathLike, drawing: NetDrawing) -> Path:
    """Write a net with its polylines, molds and strips as a .3dm file (see module notes).

    Returns
    -------
    Path of the file written (atomically).
    """
    X = np.asarray(drawing.vertices, dtype=np.float64)
    doc = Rhino3dmWriter(drawing.units)
    doc.layer(NET_LAYER, NET_COLOUR)
    for f, letter in enumerate(FAMILY_NAMES):
        doc.layer(f"lines {letter}", LINE_COLOURS[f])
    doc.add_mesh(X, drawing.faces, layer=NET_LAYER, name=drawing.name,
                 user_text={"net": drawing.name, "units": drawing.units, **drawing.user_text})
    for p, (ids, family) in enumerate(drawing.polylines):
        letter = FAMILY_NAMES[int(family)] if int(family) in (0, 1) else "other"
        doc.add_polyline(X[np.asarray(ids)], layer=f"lines {letter}", name=f"polyline {p}",
                         user_text={"polyline": p, "family": letter})
    if drawing.face_mold is not None:
        mold = np.asarray(drawing.face_mold, dtype=np.int64)
        colours = category_colours(int(mold.max()) + 1 if mold.size else 0)
        for m in np.unique(mold):
            doc.layer(f"mold {m}", colours[m].tolist())
        for i, face in enumerate(drawing.faces):
            _add_panel(doc, X, face, i, int(mold[i]), colours[mold[i]])
    for f, letter in enumerate(FAMILY_NAMES):
        if any(int(family) == f for _, family, _ in drawing.strips):
            doc.layer(f"strips {letter}", LINE_COLOURS[f])
    for strip_id, family, points in drawing.strips:
        letter = FAMILY_NAMES[int(family)]
        doc.add_polyline(np.asarray(points, np.float64), layer=f"strips {letter}", name=str(strip_id),
                         user_text={"strip": strip_id, "family": letter},
                         colour=LINE_COLOURS[int(family)])
    return doc.write(path)


def _add_panel(doc: Rhino3dmWriter, X: np.ndarray, face: Sequence[int], index: int, mold: int,
               colour: np.ndarray) -> None:
    """One panel as its own small mesh (its corners only), named for ``panels.csv``."""
    ids = np.asarray(face, dtype=np.int64)
    doc.add_mesh(X[ids], [list(range(len(ids)))], layer=f"mold {mold}", name=f"panel {index}",
                 user_text={"face": index, "mold": mold}, colour=colour.tolist())


def read_3dm_net(path: str | os.PathLike, *, layer: str = NET_LAYER
                 ) -> tuple[np.ndarray, list[np.ndarray], str | None]:
    """Read the net a fabplan .3dm file holds: the first mesh on `layer`.

    Returns
    -------
    vertices : (n, 3) float64, in the file's units.
    faces : list of (3,) or (4,) int arrays.
    units : the fabplan name of the file's unit system (a key of `RHINO_UNITS`), or None.

    Raises
    ------
    InputError
        When the file cannot be read or holds no mesh on that layer.
    """
    r = _rhino()
    path = check_input_file(path, "a .3dm file")
    doc = r.File3dm.Read(str(path))
    if doc is None:
        raise InputError(f"{path}: not a readable .3dm file")
    index = next((i for i, lay in enumerate(doc.Layers) if lay.Name == layer), None)
    for obj in doc.Objects:
        geometry = obj.Geometry
        if isinstance(geometry, r.Mesh) and (index is None or obj.Attributes.LayerIndex == index):
            n = len(geometry.Vertices)
            points = [geometry.Vertices.Point3dAt(i) for i in range(n)]
            vertices = np.array([[p.X, p.Y, p.Z] for p in points], dtype=np.float64)
            faces = []
            for k in range(geometry.Faces.Count):
                a, b, c, d = geometry.Faces[k]
                faces.append(np.array([a, b, c] if c == d else [a, b, c, d], dtype=np.int64))
            unit_name = doc.Settings.ModelUnitSystem.name
            units = next((k for k, v in RHINO_UNITS.items() if v == unit_name), None)
            return vertices, faces, units
    raise InputError(f"{path}: holds no mesh on layer {layer!r}")
