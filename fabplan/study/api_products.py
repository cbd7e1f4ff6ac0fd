"""The molds, strips and the files that carry them (3DM, glTF, IFC) as plain function
calls: the products' half of the Python API (`fabplan.study.api` holds the nets')."""

from __future__ import annotations

import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..fabricate.molds.mold_assignment import plan_molds as _plan_molds_impl
from ..fabricate.molds.mold_plan import MoldPlan
from ..fabricate.molds.mold_shapes import MoldSettings
from ..fabricate.molds.panel_meshes import PanelMesh
from ..fabricate.strips.strip_boundary import StripBoundary
from ..fabricate.strips.strip_plan import StripPlan, schedule_rows
from ..fabricate.strips.strip_plan import plan_strips as _plan_strips_impl
from ..fabricate.strips.strip_set import StripSettings
from ..io.gltf import write_glb as _write_glb_file
from ..io.ifc import FacadeModel, IfcProperty, PanelSet
from ..io.ifc import StripSet as IfcStripSet
from ..io.ifc import write_ifc as _write_ifc_file
from ..io.rhino_write import NetDrawing, write_net_3dm
from ..net.mesh import QuadMesh
from .api import NetLike, as_mesh

__all__ = [
    "MoldResult",
    "StripResult",
    "plan_molds",
    "plan_strips",
    "net_drawing",
    "write_3dm",
    "write_glb",
    "ifc_facade",
    "write_ifc",
]


# ----------------------------------------------------------------------------- results
@dataclass
class MoldResult(MoldPlan):
    """A `MoldPlan` with ``to_json()`` (the record of ``molds.json``)."""

    @classmethod
    def of(cls, plan: MoldPlan) -> "MoldResult":
        return cls(**{f.name: getattr(plan, f.name) for f in fields(MoldPlan)})

    def to_json(self) -> dict:
        return self.record()


@dataclass
class StripResult(StripPlan):
    """A `StripPlan` with ``to_json()`` (its summary and schedule, millimetres)."""

    @classmethod
    def of(cls, plan: StripPlan) -> "StripResult":
        return cls(**{f.name: getattr(plan, f.name) for f in fields(StripPlan) if f.init})

    def to_json(self) -> dict:
        return {"summary": self.summary(), "strips": schedule_rows(self)}



def plan_molds(net: NetLike, settings: MoldSettings | None = None, *, design: Any = None,
               **options: Any) -> MoldResult:
    """The molds of a net's panels (``fabplan molds``): `MoldSettings`, or its fields as
    keyword options (``tolerance_mm=5, units="m"``); `design`: the design the net lies on
    (its panels are then patches of it, `fabplan.fabricate.molds.plan_molds`)."""
    return MoldResult.of(_plan_molds_impl(as_mesh(net), settings, design=design, **options))


def plan_strips(net: NetLike, settings: StripSettings | None = None, *, boundary: Any = "auto",
                **options: Any) -> StripResult:
    """The lamella strips of a net, on sheets (``fabplan strips``): `StripSettings`, or its
    fields as keyword options (``height_mm=120, thickness_mm=6``). `boundary`: the net's
    boundary panels, which the strips run through to the edge of the cladding: a
    `fabplan.layout.trim.BoundaryPanels`, or the path of a ``NET.boundary.obj``; ``"auto"``
    those of a layout or glide result given as `net`; None: the strips end at the net."""
    if settings is None:
        settings = StripSettings(**options)
    elif options:
        raise InputError("give either settings or keyword options, not both")
    settings.check()
    mesh = as_mesh(net)
    if isinstance(boundary, str) and boundary == "auto":
        boundary = getattr(net, "boundary_panels", None)
    elif isinstance(boundary, (str, os.PathLike)):      # a NET.boundary.obj
        if not Path(boundary).is_file():
            raise InputError(f"{boundary}: no such file (the boundary panels, NET.boundary.obj)")
        boundary = StripBoundary.from_obj(mesh, boundary)
    return StripResult.of(_plan_strips_impl(mesh, settings, boundary=boundary))


def net_drawing(net: NetLike, *, molds: MoldPlan | None = None, strips: StripPlan | None = None,
                units: str = "m", user_text: dict | None = None) -> NetDrawing:
    """What `write_3dm` draws: the mesh, its polylines, the molds' panels, the strips."""
    mesh = as_mesh(net)
    lines = mesh.polylines
    return NetDrawing(
        vertices=mesh.vertices, faces=mesh.faces,
        polylines=list(zip(lines.vertices, lines.family.tolist(), strict=True)),
        face_mold=None if molds is None else molds.mold,
        strips=[] if strips is None else [(s.id, s.family, strips.strips.positions[s.vertices])
                                          for s in strips.strips.strips],
        units=units, name=Path(str(mesh.name)).name, user_text=dict(user_text or {}))


def write_3dm(net: NetLike, path: str | os.PathLike, *, molds: MoldPlan | None = None,
              strips: StripPlan | None = None, units: str = "m",
              user_text: dict | None = None) -> Path:
    """Write a net as a Rhino .3dm file: the quad mesh, the parameter polylines per family,
    with `molds` the panels on one layer per mold, with `strips` their reference curves
    (see `fabplan.io.rhino_write`)."""
    return write_net_3dm(path, net_drawing(net, molds=molds, strips=strips, units=units,
                                           user_text=user_text))


def write_glb(net: NetLike, path: str | os.PathLike, *, molds: MoldPlan | None = None,
              units: str = "m") -> Path:
    """Write a net as binary glTF (in metres, from the model `units`), its panels coloured
    by mold (grey without molds)."""
    mesh = as_mesh(net)
    return _write_glb_file(path, mesh.vertices, mesh.faces,
                           face_mold=None if molds is None else molds.mold, units=units)



def _panel_set(panels: Any, names: list[str], tags: list[str], mold: np.ndarray | None,
               properties: list[IfcProperty]) -> PanelSet:
    """A `PanelSet` of the triangle meshes `panels` (`fabplan.fabricate.molds.panel_meshes.PanelMesh`)."""
    return PanelSet(points=panels.points, triangles=panels.triangles, point_ptr=panels.point_ptr,
                    triangle_ptr=panels.triangle_ptr, names=names, tags=tags, mold=mold,
                    properties=properties)


def _mold_text(kind: str, k1: float, k2: float) -> str:
    """An IfcGroup's description of a mold of curvatures `k1`, `k2` (1/mm)."""
    return f"{kind} mold, k1 {k1 * 1000:.6g} 1/m, k2 {k2 * 1000:.6g} 1/m"


def _net_panels(mesh: QuadMesh, molds: MoldPlan | None, mm: float, net_type: str | None
                ) -> tuple[PanelSet, dict[int, tuple[str, str]]]:
    """The net's panels (with `molds` their triangulated surfaces, else the faces) and the
    molds' groups."""
    from ..fabricate.molds.mold_shapes import MOLD_TYPES, PANEL_TYPES
    from ..fabricate.molds.panel_meshes import face_fan_mesh

    f = len(mesh.face_sizes)
    surface = face_fan_mesh(mesh) if molds is None or molds.surface is None else molds.surface
    props = [IfcProperty("FaceId", "IfcInteger", range(f)),
             IfcProperty("PanelKind", "IfcLabel", ["net panel"] * f)]
    groups: dict[int, tuple[str, str]] = {}
    if molds is not None:
        kinds = [MOLD_TYPES[t] for t in molds.mold_type]
        groups = {j: (f"mold {j}", _mold_text(kinds[j], k1, k2))
                  for j, (k1, k2) in enumerate(molds.mold_shape.tolist())}
        props += [IfcProperty("PanelClass", "IfcLabel", [PANEL_TYPES[t] for t in molds.panel_type]),
                  IfcProperty("MoldId", "IfcInteger", molds.mold.tolist()),
                  IfcProperty("MoldType", "IfcLabel", [kinds[m] for m in molds.mold]),
                  IfcProperty("DeviationFromMold", "IfcLengthMeasure", (molds.deviation_mm / mm).tolist()),
                  IfcProperty("FitsMold", "IfcBoolean", [p is None for p in molds.problem])]
        if molds.classes is not None:
            # with a material, how each panel is made (panels.csv's `class`) and whether
            # its mold is made at all
            from ..fabricate.molds.panel_classes import CLASSES

            props += [IfcProperty("MaterialClass", "IfcLabel",
                                  [CLASSES[c] for c in molds.classes.panel_class]),
                      IfcProperty("MoldMade", "IfcBoolean", molds.mold_made[molds.mold].tolist())]
    props += [IfcProperty("Area", "IfcAreaMeasure", surface.areas().tolist()),
              IfcProperty("NetType", "IfcLabel", [net_type] * f)]
    panels = _panel_set(surface, [f"panel {i}" for i in range(f)], [str(i) for i in range(f)],
                        None if molds is None else molds.mold, props)
    return panels, groups


def _boundary_panels(boundary: Any, mm: float, net_type: str | None
                     ) -> tuple[PanelSet | None, dict[int, tuple[str, str]]]:
    """The boundary panels: as cut from their molds (a `BoundaryMolds`) or trimmed (a
    `BoundaryPanels`), and the groups of the molds of their own."""
    from ..fabricate.molds.boundary_molds import BoundaryMolds
    from ..fabricate.molds.mold_shapes import MOLD_TYPES, PANEL_TYPES
    from ..fabricate.molds.panel_meshes import boundary_cut_mesh

    cut_molds = boundary if isinstance(boundary, BoundaryMolds) else None
    made = boundary.panels if cut_molds is not None else boundary
    if made is None or not made.polygons:
        return None, {}
    cut = cut_molds.cut_mesh() if cut_molds is not None else boundary_cut_mesh(made)
    p = made.count
    kind = np.where(made.extension, "boundary sliver",
                    np.where(made.patch, "boundary patch", "boundary panel"))
    props = [IfcProperty("FaceId", "IfcInteger", range(p)),
             IfcProperty("PanelKind", "IfcLabel", kind.tolist()),
             IfcProperty("NeighbourFace", "IfcInteger", np.asarray(made.neighbour_face).tolist())]
    groups: dict[int, tuple[str, str]] = {}
    mold = None
    if cut_molds is not None and cut is not None:
        mold = np.asarray(cut_molds.mold, np.int64)
        first = cut_molds.net_mold_count
        groups = {first + j: (f"mold {first + j}", _mold_text("paraboloid", k1, k2)
                              + ", a boundary panel's own")
                  for j, (k1, k2) in enumerate(np.asarray(cut_molds.own_shapes).tolist())}
        types = cut_molds.panel_types()
        props += [IfcProperty("PanelClass", "IfcLabel", [PANEL_TYPES[t] for t in types]),
                  IfcProperty("MoldId", "IfcInteger", mold.tolist()),
                  IfcProperty("MoldType", "IfcLabel", [MOLD_TYPES[t] for t in types]),
                  IfcProperty("StepToNeighbours", "IfcLengthMeasure",
                              (np.asarray(cut_molds.step_mm) / mm).tolist())]
    assert cut is not None
    props += [IfcProperty("Area", "IfcAreaMeasure", cut.areas().tolist()),
              IfcProperty("NetType", "IfcLabel", [net_type] * p)]
    panels = _panel_set(cut, [f"boundary panel {k}" for k in range(p)], [f"B{k}" for k in range(p)],
                        mold, props)
    return panels, groups


def _slivers_into_their_panels(net: PanelSet, boundary: PanelSet
                               ) -> tuple[PanelSet, PanelSet | None]:
    """A boundary sliver is cut in one piece with the full panel it extends: one plate.

    Its triangles join that panel's (`NeighbourFace`) and its area the panel's ``Area``;
    the other boundary panels stay plates of their own. Returns the net's panels and the
    boundary panels left (None when none is).
    """
    props = {p.name: p for p in boundary.properties}
    sliver = np.array([k == "boundary sliver" for k in props["PanelKind"].values], bool)
    if not sliver.any():
        return net, boundary
    owner = np.asarray(list(props["NeighbourFace"].values), np.int64)
    pieces = [[_panel_piece(net, i)] for i in range(net.count)]
    area = np.array(list({p.name: p for p in net.properties}["Area"].values), np.float64)
    sliver_area = np.asarray(list(props["Area"].values), np.float64)
    for k in np.flatnonzero(sliver).tolist():
        pieces[owner[k]].append(_panel_piece(boundary, k))
        area[owner[k]] += sliver_area[k]
    joined = PanelMesh.join([_joined(parts) for parts in pieces])
    merged = PanelSet(points=joined.points, triangles=joined.triangles, point_ptr=joined.point_ptr,
                      triangle_ptr=joined.triangle_ptr, names=net.names, tags=net.tags,
                      mold=net.mold, properties=[
                          IfcProperty("Area", "IfcAreaMeasure", area.tolist()) if p.name == "Area"
                          else p for p in net.properties])
    keep = np.flatnonzero(~sliver).tolist()
    if not keep:
        return merged, None
    rest = PanelMesh.join([_panel_piece(boundary, k) for k in keep])
    values = {p.name: list(p.values) for p in boundary.properties}
    return merged, PanelSet(
        points=rest.points, triangles=rest.triangles, point_ptr=rest.point_ptr,
        triangle_ptr=rest.triangle_ptr, names=[boundary.names[k] for k in keep],
        tags=[boundary.tags[k] for k in keep],
        mold=None if boundary.mold is None else np.asarray(boundary.mold)[keep],
        properties=[IfcProperty(p.name, p.ifc_type, [values[p.name][k] for k in keep])
                    for p in boundary.properties])


def _panel_piece(panels: PanelSet, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Panel `i` of `panels`: its points (k, 3) and its triangles (t, 3) into them."""
    a, b = panels.point_ptr[i], panels.point_ptr[i + 1]
    return (panels.points[a:b],
            panels.triangles[panels.triangle_ptr[i]:panels.triangle_ptr[i + 1]] - a)


def _joined(parts: list) -> tuple[np.ndarray, np.ndarray]:
    """One panel's pieces (points, triangles into them) as one mesh."""
    if len(parts) == 1:
        return parts[0]
    offsets = np.cumsum([0] + [len(points) for points, _ in parts[:-1]])
    return (np.concatenate([points for points, _ in parts]),
            np.concatenate([triangles + o for (_, triangles), o in zip(parts, offsets, strict=True)]))


def _lamellas(mesh: QuadMesh, strips: StripPlan, net_type: str | None) -> IfcStripSet:
    """The strips as lamellas: node polylines, node normals, cross-section, ids."""
    from ..fabricate.molds.mold_shapes import UNITS

    lamellas = strips.strips
    scale = UNITS[lamellas.settings.units]
    normals = lamellas.normals
    if normals is None:        # a plan made before the normals were kept: the net's nearest
        from scipy.spatial import cKDTree

        from ..fabricate.strips.unrolling import node_normals

        normals = node_normals(mesh)[cKDTree(mesh.vertices).query(lamellas.positions)[1]]
    chosen = lamellas.strips
    n = len(chosen)
    height, thickness = lamellas.settings.height_mm / scale, lamellas.settings.thickness_mm / scale
    radius = [s.radius_mm / scale if np.isfinite(s.radius_mm) else None for s in chosen]
    return IfcStripSet(
        curves=[lamellas.positions[s.vertices] for s in chosen],
        normals=[normals[s.vertices] for s in chosen], height=height, thickness=thickness,
        names=[s.id for s in chosen],
        properties=[IfcProperty("StripId", "IfcLabel", [s.id for s in chosen]),
                    IfcProperty("Family", "IfcLabel", ["AB"[s.family] for s in chosen]),
                    IfcProperty("Length", "IfcLengthMeasure", [s.length_mm / scale for s in chosen]),
                    IfcProperty("ArcRadius", "IfcLengthMeasure", radius),
                    IfcProperty("Height", "IfcLengthMeasure", [height] * n),
                    IfcProperty("Thickness", "IfcLengthMeasure", [thickness] * n),
                    IfcProperty("NetType", "IfcLabel", [net_type] * n)])


def _vertex_normals(mesh: QuadMesh) -> np.ndarray:
    """(n, 3) unit normals at the vertices: the sum of their faces' Newell vectors."""
    newell = np.cross(mesh.vertices[mesh.face_indices], mesh.vertices[mesh.corner_next_vertices])
    normals = np.zeros_like(mesh.vertices)
    np.add.at(normals, mesh.face_indices, np.repeat(
        np.add.reduceat(newell, mesh.face_indptr[:-1], axis=0), mesh.face_sizes, axis=0))
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)


def ifc_facade(net: NetLike, *, molds: MoldPlan | None = None, boundary: Any = None,
               strips: StripPlan | None = None, units: str = "m", net_type: str | None = None,
               name: str | None = None, nodes: bool = True) -> FacadeModel:
    """What `write_ifc` writes (`fabplan.io.ifc.FacadeModel`).

    Parameters
    ----------
    net : the net.
    molds : its `MoldPlan`: the panels are its triangulated panel surfaces
        (`MoldPlan.surface`), with their molds; None: the faces themselves, flat fans.
    boundary : the boundary panels: a `BoundaryMolds` (as cut from their molds, the
        ``fabplan molds`` report) or the `fabplan.layout.trim.BoundaryPanels` of a layout
        (their trimmed outlines); None: none.
    strips : its `StripPlan`: the lamellas.
    units : the model units.
    net_type : the net's type, a property of every panel (default: the result's ``net``).
    name : the project's name (default: the net's file name).
    nodes : write the net as a structural analysis model (vertices and edges).
    """
    from ..fabricate.molds.mold_shapes import UNITS

    mesh = as_mesh(net)
    mm = UNITS[units]
    net_type = net_type if net_type is not None else getattr(net, "net", None)
    name = name or Path(str(mesh.name)).name
    panels, groups = _net_panels(mesh, molds, mm, net_type)
    sets = [panels]
    if boundary is not None:
        more, own = _boundary_panels(boundary, mm, net_type)
        if more is not None:
            panels, more = _slivers_into_their_panels(panels, more)
            sets = [panels] + ([] if more is None else [more])
        groups.update(own)
    lamellas = None if strips is None or not strips.strips.strips else _lamellas(mesh, strips, net_type)
    material = None if molds is None or molds.classes is None else molds.classes.material.label
    return FacadeModel(name=name, units=units, panels=sets, molds=groups, strips=lamellas,
                       panel_material=material,
                       nodes=mesh.vertices if nodes else None, edges=mesh.edges,
                       node_normals=_vertex_normals(mesh),
                       description=f"fabplan facade plan of {name}"
                       + (f", a {net_type} net" if net_type else ""))

def write_ifc(net: NetLike, path: str | os.PathLike, *, molds: MoldPlan | None = None,
              boundary: Any = None, strips: StripPlan | None = None, units: str = "m",
              net_type: str | None = None, name: str | None = None) -> Path:
    """Write a net's facade plan as an IFC4 file (`ifc_facade`, `fabplan.io.ifc`): its panels
    (with `molds` their surfaces and molds), boundary panels, lamellas and nodes. Needs
    IfcOpenShell (``pip install 'fabplan[ifc]'``)."""
    return _write_ifc_file(path, ifc_facade(net, molds=molds, boundary=boundary, strips=strips,
                                            units=units, net_type=net_type, name=name))
