"""IFC4 files of a facade plan: panels, molds, lamellas and nodes for the building model
(IfcOpenShell, the optional extra ``fabplan[ifc]``).

What a file holds (entities and the reasons for them: ``docs/ifc.md``)::

    IfcProject > IfcSite > IfcBuilding      the spatial structure, in the net's units
      IfcElementAssembly "facade"           contained in the building; aggregates:
        IfcPlate (CURTAIN_PANEL)            one per panel, its surface an IfcTriangulatedFaceSet;
                                            property set ``fabplan_Panel``
        IfcMember (USERDEFINED "lamella")   one per strip: centre curve (Axis) and body (Body),
                                            cross-section as an IfcMaterialProfileSetUsage;
                                            property set ``fabplan_Strip``
    IfcGroup "mold N"                       the panels cut or cast on mold N
    IfcStructuralAnalysisModel "net"        the net as an analytical model: one
                                            IfcStructuralPointConnection per vertex, one
                                            IfcStructuralCurveMember per edge, connected

Names and tags carry the ids of fabplan's CSV files: a panel's ``FaceId`` is its row in
``panels.csv`` (for a boundary panel its row in ``boundary-panels.csv``), ``MoldId`` its
``mold`` there, a lamella's ``StripId`` its ``strip`` in ``strips.csv``; a node is named
for its vertex in the OBJ (``node 17``, counted from 0), an edge member for its two
vertices (``edge 17-18``). Lengths and areas are in the project units
(the net's); GlobalIds are derived from the model's name and the element's id, so that the
same plan gives the same file.

This module writes plain data (`FacadeModel`); `fabplan.study.api.ifc_facade` makes it
from a net, its mold plan, boundary panels and strips.
"""

from __future__ import annotations

import math
import os
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import InputError
from .output import atomic_path
from .rhino_write import category_colours
from .units import MM_PER_UNIT

__all__ = ["IFC_UNITS", "PRECISION_MM", "coordinate_decimals", "IfcProperty", "PanelSet",
           "StripSet", "FacadeModel", "ifcopenshell_module", "write_ifc"]

IFC_UNITS = {"mm": ("MILLI", None), "cm": ("CENTI", None), "m": (None, None),
             "in": (None, ("inch", "square inch")), "ft": (None, ("foot", "square foot"))}
"""fabplan unit -> (SI prefix of the metre, or the names of the conversion-based length and
area units IFC knows for it)."""

PRECISION_MM = 0.001
"""The coordinates' step in the file (mm): a micrometre, far below any fabrication tolerance;
the representation context states it as its precision."""

PANEL_PSET = "fabplan_Panel"
STRIP_PSET = "fabplan_Strip"
_GUID_NAMESPACE = uuid.UUID("6f1b1d4e-38a1-4f7e-9a7a-3c2a0f1e5b38")


def ifcopenshell_module() -> Any:
    """`ifcopenshell`, or a one-line `InputError` saying how to install it."""
    try:
        import ifcopenshell
    except ImportError:
        raise InputError("--ifc needs IfcOpenShell, which is not installed: "
                         "pip install 'fabplan[ifc]'") from None
    return ifcopenshell


@dataclass
class IfcProperty:
    """One property of every element of a set.

    Attributes
    ----------
    name : the property's name in the property set.
    ifc_type : its IFC value type (``IfcInteger``, ``IfcLabel``, ``IfcLengthMeasure``,
        ``IfcAreaMeasure``, ``IfcBoolean``, ``IfcReal``).
    values : one value per element; None leaves the property out for that element.
    """

    name: str
    ifc_type: str
    values: Sequence[Any]


@dataclass
class PanelSet:
    """Panels of one kind (the net's, or its boundary panels), as triangle meshes.

    Attributes
    ----------
    points : (v, 3) float, model units; panel i's are ``points[point_ptr[i]:point_ptr[i+1]]``.
    triangles : (t, 3) int into `points`; panel i's are
        ``triangles[triangle_ptr[i]:triangle_ptr[i+1]]``.
    point_ptr, triangle_ptr : (p + 1,) int.
    names : (p,) the elements' names (``panel 12``); tags : (p,) their tags.
    mold : (p,) int, the mold of every panel (-1: none), or None: no molds.
    properties : the panels' properties (`IfcProperty`).
    """

    points: np.ndarray
    triangles: np.ndarray
    point_ptr: np.ndarray
    triangle_ptr: np.ndarray
    names: Sequence[str]
    tags: Sequence[str]
    mold: np.ndarray | None = None
    properties: list[IfcProperty] = field(default_factory=list)

    @property
    def count(self) -> int:
        return len(self.point_ptr) - 1


@dataclass
class StripSet:
    """Lamellas: a centre curve per strip and the normal the lamella stands on at its nodes.

    Attributes
    ----------
    curves : list of (k, 3) float, every strip's nodes (model units).
    normals : list of (k, 3) float, the unit node normals (the lamella's height direction).
    height, thickness : the cross-section (model units).
    names : the strip ids (``A07``).
    properties : their properties (`IfcProperty`).
    """

    curves: list
    normals: list
    height: float
    thickness: float
    names: Sequence[str]
    properties: list[IfcProperty] = field(default_factory=list)


@dataclass
class FacadeModel:
    """Everything an IFC file of a facade plan holds (see the module notes).

    Attributes
    ----------
    name : the project's name (and the seed of the GlobalIds).
    units : the model units (a key of `IFC_UNITS`).
    panels : the panel sets (net panels, boundary panels).
    molds : mold id -> (name, description) of its IfcGroup.
    strips : the lamellas, or None.
    nodes : (n, 3) float, the net's vertices, or None: no analytical model.
    edges : (e, 2) int, the net's edges (vertex pairs), the analytical model's members.
    node_normals : (n, 3) float, unit surface normals at the nodes: the members' local z
        axes lie in the plane of the edge and the mean normal of its ends.
    panel_material, strip_material : names of the materials the panels and the lamellas are
        made of, or None: no material assigned.
    description : the project's description.
    """

    name: str
    units: str = "m"
    panels: list[PanelSet] = field(default_factory=list)
    molds: dict[int, tuple[str, str]] = field(default_factory=dict)
    strips: StripSet | None = None
    nodes: np.ndarray | None = None
    edges: np.ndarray | None = None
    node_normals: np.ndarray | None = None
    panel_material: str | None = None
    strip_material: str | None = None
    description: str = ""


class _Writer:
    """An IFC4 file being built with IfcOpenShell's entity constructor (the high-level API
    adds several hundred microseconds per call, too slow for thousands of panels)."""

    def __init__(self, model: FacadeModel) -> None:
        ifcopenshell_module()
        import ifcopenshell
        import ifcopenshell.guid

        self.model = model
        self.decimals = coordinate_decimals(model.units)
        self.file = ifcopenshell.file(schema="IFC4")
        self._compress = ifcopenshell.guid.compress
        self.create = self.file.create_entity

    def guid(self, key: str) -> str:
        return str(self._compress(uuid.uuid5(_GUID_NAMESPACE, f"{self.model.name}/{key}").hex))

    def placement(self, relative_to: Any = None) -> Any:
        origin = self.create("IfcAxis2Placement3D", Location=self.create(
            "IfcCartesianPoint", Coordinates=(0.0, 0.0, 0.0)))
        return self.create("IfcLocalPlacement", PlacementRelTo=relative_to,
                           RelativePlacement=origin)

    def units(self) -> Any:
        prefix, named = IFC_UNITS[self.model.units]
        if named is None:
            length = self.create("IfcSIUnit", UnitType="LENGTHUNIT", Prefix=prefix, Name="METRE")
            area = self.create("IfcSIUnit", UnitType="AREAUNIT", Prefix=prefix, Name="SQUARE_METRE")
        else:
            metres = MM_PER_UNIT[self.model.units] / 1000.0
            metre = self.create("IfcSIUnit", UnitType="LENGTHUNIT", Name="METRE")
            square = self.create("IfcSIUnit", UnitType="AREAUNIT", Name="SQUARE_METRE")
            length = self.create(
                "IfcConversionBasedUnit",
                Dimensions=self.create("IfcDimensionalExponents", 1, 0, 0, 0, 0, 0, 0),
                UnitType="LENGTHUNIT", Name=named[0], ConversionFactor=self.create(
                    "IfcMeasureWithUnit", ValueComponent=self.create("IfcLengthMeasure", metres),
                    UnitComponent=metre))
            area = self.create(
                "IfcConversionBasedUnit",
                Dimensions=self.create("IfcDimensionalExponents", 2, 0, 0, 0, 0, 0, 0),
                UnitType="AREAUNIT", Name=named[1], ConversionFactor=self.create(
                    "IfcMeasureWithUnit", ValueComponent=self.create("IfcAreaMeasure", metres**2),
                    UnitComponent=square))
        angle = self.create("IfcSIUnit", UnitType="PLANEANGLEUNIT", Name="RADIAN")
        return self.create("IfcUnitAssignment", Units=[length, area, angle])

    def properties(self, element_key: str, elements: list, props: list[IfcProperty],
                   name: str) -> None:
        """A property set per element with its values of `props`."""
        cache: dict[tuple, Any] = {}
        for i, element in enumerate(elements):
            values = []
            for p in props:
                v = p.values[i]
                if v is None:
                    continue
                v = float(v) if p.ifc_type in ("IfcLengthMeasure", "IfcAreaMeasure", "IfcReal") else (
                    bool(v) if p.ifc_type == "IfcBoolean" else int(v) if p.ifc_type == "IfcInteger"
                    else str(v))
                key = (p.name, p.ifc_type, v)
                if key not in cache:      # equal values share one property entity
                    cache[key] = self.create("IfcPropertySingleValue", Name=p.name,
                                             NominalValue=self.create(p.ifc_type, v))
                values.append(cache[key])
            if not values:
                continue
            pset = self.create("IfcPropertySet", GlobalId=self.guid(f"{element_key}/{i}/pset"),
                               Name=name, HasProperties=values)
            self.create("IfcRelDefinesByProperties", GlobalId=self.guid(f"{element_key}/{i}/props"),
                        RelatedObjects=[element], RelatingPropertyDefinition=pset)

    def material(self, name: str, elements: list, key: str) -> None:
        if elements:
            self.create("IfcRelAssociatesMaterial", GlobalId=self.guid(f"material/{key}"),
                        RelatedObjects=elements, RelatingMaterial=self.create("IfcMaterial", Name=name))


def coordinate_decimals(units: str) -> int:
    """Decimals of the model unit the coordinates are written with: a step of at most
    `PRECISION_MM`.

    Examples
    --------
    >>> [coordinate_decimals(u) for u in ("mm", "cm", "m", "in", "ft")]
    [3, 4, 6, 5, 6]
    """
    return int(math.ceil(-math.log10(PRECISION_MM / MM_PER_UNIT[units]) - 1e-9))


def _fixed(points: np.ndarray, decimals: int) -> list:
    """Coordinates rounded to `decimals` as plain floats for IfcOpenShell (which refuses
    numpy scalars, and writes a rounded number several times faster than a full double)."""
    return np.round(np.asarray(points, np.float64), decimals).tolist()


def _lamella_body(curve: np.ndarray, normal: np.ndarray, height: float, thickness: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A lamella as a closed triangle mesh: its rectangular cross-section (height along the
    node normal, thickness across) at every node, joined along the curve and capped.

    The four sides between two nodes are twisted where the normals turn about the edge;
    each is cut into four triangles about its centre, so that no diagonal's choice bends a
    thin lamella to one side.

    Returns
    -------
    points : (4 k + 4 (k - 1), 3) float; triangles : (16 (k - 1) + 4, 3) int, facing
    outwards.
    """
    k = len(curve)
    tangent = np.gradient(curve, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    up = normal - np.sum(normal * tangent, axis=1, keepdims=True) * tangent
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    side = np.cross(tangent, up)
    corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [height / 2, thickness / 2]
    ring = (curve[:, None, :] + corners[None, :, :1] * up[:, None, :]
            + corners[None, :, 1:] * side[:, None, :]).reshape(-1, 3)
    a = np.arange(k - 1)[:, None] * 4
    s = np.arange(4)[None, :]
    p00, p10, p11, p01 = a + s, a + 4 + s, a + 4 + (s + 1) % 4, a + (s + 1) % 4
    centre = 0.25 * (ring[p00] + ring[p10] + ring[p11] + ring[p01]).reshape(-1, 3)
    c = 4 * k + np.arange(4 * (k - 1)).reshape(k - 1, 4)
    sides = np.concatenate([np.stack(t, -1).reshape(-1, 3) for t in
                            ((p00, p10, c), (p10, p11, c), (p11, p01, c), (p01, p00, c))])
    last = 4 * (k - 1)
    caps = np.array([[0, 1, 2], [0, 2, 3], [last, last + 2, last + 1], [last, last + 3, last + 2]])
    points = np.concatenate([ring, centre])
    triangles = np.concatenate([sides, caps])
    T = points[triangles]
    volume = np.einsum("ij,ij->i", T[:, 0], np.cross(T[:, 1], T[:, 2])).sum()
    if volume < 0:
        triangles = triangles[:, ::-1]
    return points, triangles


def _edge_axes(nodes: np.ndarray, edges: np.ndarray, normals: np.ndarray | None) -> np.ndarray:
    """(e, 3) unit directions, each across its edge: the mean normal of the edge's ends with
    its part along the edge taken out (the global z, or x, where there is no normal)."""
    along = nodes[edges[:, 1]] - nodes[edges[:, 0]]
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    axis = (np.zeros_like(along) if normals is None else normals[edges].sum(axis=1))
    axis = np.where(np.isfinite(axis), axis, 0.0)
    axis -= np.sum(axis * along, axis=1, keepdims=True) * along
    weak = np.linalg.norm(axis, axis=1) < 1e-6
    fallback = np.where((np.abs(along[:, 2]) < 0.9)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    fallback -= np.sum(fallback * along, axis=1, keepdims=True) * along
    axis = np.where(weak[:, None], fallback, axis)
    return axis / np.linalg.norm(axis, axis=1, keepdims=True)


def _analytical_model(w: _Writer, model: FacadeModel, facade_place: Any, context: Any,
                      building: Any) -> None:
    """The net as a structural analysis model: a point connection per vertex, a curve
    member per edge, each member connected to its two end nodes (IFC asks every point
    connection to connect a member)."""
    create = w.create
    nodes_xyz = np.asarray(model.nodes, np.float64)
    edges = np.zeros((0, 2), np.int64) if model.edges is None else np.asarray(model.edges, np.int64)
    used = np.zeros(len(nodes_xyz), bool)
    used[edges.ravel()] = True
    shared = w.placement(facade_place)
    analysis = create("IfcStructuralAnalysisModel", GlobalId=w.guid("net"), Name="net",
                      Description="the net's vertices (node N: vertex N of the OBJ) and edges",
                      PredefinedType="LOADING_3D", SharedPlacement=shared)
    vertex: dict[int, Any] = {}
    node: dict[int, Any] = {}
    for v in np.flatnonzero(used).tolist():
        vertex[v] = create("IfcVertexPoint", VertexGeometry=create(
            "IfcCartesianPoint", Coordinates=_fixed(nodes_xyz[v], w.decimals)))
        shape = create("IfcProductDefinitionShape", Representations=[create(
            "IfcTopologyRepresentation", ContextOfItems=context, RepresentationIdentifier="Reference",
            RepresentationType="Vertex", Items=[vertex[v]])])
        node[v] = create("IfcStructuralPointConnection", GlobalId=w.guid(f"node/{v}"),
                         Name=f"node {v}", ObjectPlacement=shared, Representation=shape)
    members = []
    axes = _edge_axes(nodes_xyz, edges, model.node_normals)
    for (a, b), z in zip(edges.tolist(), _fixed(axes, 12), strict=True):
        shape = create("IfcProductDefinitionShape", Representations=[create(
            "IfcTopologyRepresentation", ContextOfItems=context, RepresentationIdentifier="Reference",
            RepresentationType="Edge", Items=[create("IfcEdge", EdgeStart=vertex[a], EdgeEnd=vertex[b])])])
        member = create("IfcStructuralCurveMember", GlobalId=w.guid(f"edge/{a}-{b}"),
                        Name=f"edge {a}-{b}", ObjectPlacement=shared, Representation=shape,
                        PredefinedType="RIGID_JOINED_MEMBER",
                        Axis=create("IfcDirection", DirectionRatios=z))
        for end in (a, b):
            create("IfcRelConnectsStructuralMember", GlobalId=w.guid(f"edge/{a}-{b}/{end}"),
                   RelatingStructuralMember=member, RelatedStructuralConnection=node[end])
        members.append(member)
    create("IfcRelAssignsToGroup", GlobalId=w.guid("net/items"),
           RelatedObjects=list(node.values()) + members, RelatingGroup=analysis)
    create("IfcRelServicesBuildings", GlobalId=w.guid("net/building"), RelatingSystem=analysis,
           RelatedBuildings=[building])


def write_ifc(path: str | os.PathLike, model: FacadeModel) -> Path:
    """Write a facade plan as an IFC4 file (see the module notes), atomically.

    Raises
    ------
    InputError
        When IfcOpenShell is not installed, or for units IFC has no name for.
    """
    if model.units not in IFC_UNITS:
        raise InputError(f"unknown units {model.units!r} for an IFC file: use " + ", ".join(IFC_UNITS))
    w = _Writer(model)
    context, body, axis, building, facade, facade_place = _spatial_structure(w, model)
    # every part sits at the facade's placement: the coordinates are the net's
    part_place = w.placement(facade_place)
    # a list of its own: the plates' list went into their material's relation
    parts = list(_panel_plates(w, model, body, part_place))
    if model.strips is not None and model.strips.curves:
        parts += _strip_members(w, model.strips, model.strip_material, axis, body, part_place)
    if parts:
        w.create("IfcRelAggregates", GlobalId=w.guid("facade/parts"), RelatingObject=facade,
                 RelatedObjects=parts)

    if model.nodes is not None and len(model.nodes):
        _analytical_model(w, model, facade_place, context, building)

    path = Path(path)
    with atomic_path(path) as tmp:
        w.file.write(str(tmp), format=".ifc")
    return path


def _spatial_structure(w: _Writer, model: FacadeModel) -> tuple[Any, Any, Any, Any, Any, Any]:
    """The file's contexts and spatial structure (project, site, building, the facade
    assembly): the model context, its body and axis subcontexts, the building, the facade
    and the facade's placement."""
    create = w.create
    origin = create("IfcAxis2Placement3D", Location=create("IfcCartesianPoint", Coordinates=(0.0, 0.0, 0.0)))
    context = create("IfcGeometricRepresentationContext", ContextType="Model",
                     CoordinateSpaceDimension=3, Precision=10.0**-w.decimals,
                     WorldCoordinateSystem=origin)
    body = create("IfcGeometricRepresentationSubContext", ContextIdentifier="Body", ContextType="Model",
                  ParentContext=context, TargetView="MODEL_VIEW")
    axis = create("IfcGeometricRepresentationSubContext", ContextIdentifier="Axis", ContextType="Model",
                  ParentContext=context, TargetView="GRAPH_VIEW")
    project = create("IfcProject", GlobalId=w.guid("project"), Name=model.name,
                     Description=model.description or None, RepresentationContexts=[context],
                     UnitsInContext=w.units())
    site_place = w.placement()
    site = create("IfcSite", GlobalId=w.guid("site"), Name="site", ObjectPlacement=site_place,
                  CompositionType="ELEMENT")
    building_place = w.placement(site_place)
    building = create("IfcBuilding", GlobalId=w.guid("building"), Name="building",
                      ObjectPlacement=building_place, CompositionType="ELEMENT")
    create("IfcRelAggregates", GlobalId=w.guid("project/site"), RelatingObject=project, RelatedObjects=[site])
    create("IfcRelAggregates", GlobalId=w.guid("site/building"), RelatingObject=site,
           RelatedObjects=[building])
    facade_place = w.placement(building_place)
    facade = create("IfcElementAssembly", GlobalId=w.guid("facade"), Name="facade",
                    ObjectType="facade", ObjectPlacement=facade_place, AssemblyPlace="FACTORY",
                    PredefinedType="USERDEFINED")
    create("IfcRelContainedInSpatialStructure", GlobalId=w.guid("building/facade"),
           RelatedElements=[facade], RelatingStructure=building)
    return context, body, axis, building, facade, facade_place


def _panel_plates(w: _Writer, model: FacadeModel, body: Any, part_place: Any) -> list:
    """The panels as plates (one triangulated surface each, coloured by mold), grouped by
    mold, with their properties and material; returns the plates."""
    create = w.create
    mold_styles: dict[int, Any] = {}
    mold_ids = sorted({int(m) for s in model.panels if s.mold is not None for m in s.mold if m >= 0})
    colours = category_colours(max(mold_ids, default=-1) + 1)
    for m in mold_ids:
        r, g, b = (float(c) / 255.0 for c in colours[m][:3])
        mold_styles[m] = create("IfcSurfaceStyle", Name=f"mold {m}", Side="BOTH", Styles=[create(
            "IfcSurfaceStyleShading", SurfaceColour=create("IfcColourRgb", Red=r, Green=g, Blue=b))])
    members_of: dict[int, list] = {m: [] for m in mold_ids}
    plates: list = []
    for k, panels in enumerate(model.panels):
        made = []
        for i in range(panels.count):
            a, b = panels.point_ptr[i], panels.point_ptr[i + 1]
            t0, t1 = panels.triangle_ptr[i], panels.triangle_ptr[i + 1]
            surface = create("IfcTriangulatedFaceSet", Coordinates=create(
                "IfcCartesianPointList3D", CoordList=_fixed(panels.points[a:b], w.decimals)),
                Closed=False, CoordIndex=(panels.triangles[t0:t1] - a + 1).tolist())
            mold = -1 if panels.mold is None else int(panels.mold[i])
            if mold >= 0:
                create("IfcStyledItem", Item=surface, Styles=[mold_styles[mold]])
            shape = create("IfcProductDefinitionShape", Representations=[create(
                "IfcShapeRepresentation", ContextOfItems=body, RepresentationIdentifier="Body",
                RepresentationType="Tessellation", Items=[surface])])
            plate = create("IfcPlate", GlobalId=w.guid(f"panels{k}/{i}"), Name=panels.names[i],
                           ObjectPlacement=part_place, Representation=shape, Tag=panels.tags[i],
                           PredefinedType="CURTAIN_PANEL")
            made.append(plate)
            if mold >= 0:
                members_of[mold].append(plate)
        w.properties(f"panels{k}", made, panels.properties, PANEL_PSET)
        plates += made
    for m in mold_ids:
        name, text = model.molds.get(m, (f"mold {m}", ""))
        group = create("IfcGroup", GlobalId=w.guid(f"mold/{m}"), Name=name, Description=text or None,
                       ObjectType="mold")
        create("IfcRelAssignsToGroup", GlobalId=w.guid(f"mold/{m}/panels"),
               RelatedObjects=members_of[m], RelatingGroup=group)
    if model.panel_material:
        w.material(model.panel_material, plates, "panels")
    return plates


def _strip_members(w: _Writer, strips: StripSet, strip_material: str | None, axis: Any,
                   body: Any, part_place: Any) -> list:
    """The strips as members (centre line and lamella solid each) with their profile,
    material and properties; returns the members."""
    create = w.create
    members: list = []
    profile = create("IfcRectangleProfileDef", ProfileType="AREA",
                     ProfileName=f"lamella {strips.thickness:.6g} x {strips.height:.6g}",
                     XDim=float(strips.thickness), YDim=float(strips.height))
    # IFC lets a profile go without a material; readers such as web-ifc expect one
    material = create("IfcMaterial", Name=strip_material or "lamella",
                      Category=None if strip_material else "not given")
    usage = create("IfcMaterialProfileSetUsage", ForProfileSet=create(
        "IfcMaterialProfileSet", Name="lamella", MaterialProfiles=[create(
            "IfcMaterialProfile", Name="lamella", Material=material, Profile=profile)]),
        CardinalPoint=5)
    for i, (curve, normal) in enumerate(zip(strips.curves, strips.normals, strict=True)):
        curve = np.asarray(curve, np.float64)
        points, triangles = _lamella_body(curve, np.asarray(normal, np.float64),
                                          strips.height, strips.thickness)
        centre = create("IfcPolyline", Points=[create("IfcCartesianPoint", Coordinates=p)
                                               for p in _fixed(curve, w.decimals)])
        solid = create("IfcTriangulatedFaceSet", Coordinates=create(
            "IfcCartesianPointList3D", CoordList=_fixed(points, w.decimals)), Closed=True,
            CoordIndex=(triangles + 1).tolist())
        shape = create("IfcProductDefinitionShape", Representations=[
            create("IfcShapeRepresentation", ContextOfItems=axis, RepresentationIdentifier="Axis",
                   RepresentationType="Curve3D", Items=[centre]),
            create("IfcShapeRepresentation", ContextOfItems=body, RepresentationIdentifier="Body",
                   RepresentationType="Tessellation", Items=[solid])])
        members.append(create("IfcMember", GlobalId=w.guid(f"strip/{i}"), Name=strips.names[i],
                              ObjectType="lamella", ObjectPlacement=part_place,
                              Representation=shape, Tag=strips.names[i],
                              PredefinedType="USERDEFINED"))
    create("IfcRelAssociatesMaterial", GlobalId=w.guid("material/strips"), RelatedObjects=members,
           RelatingMaterial=usage)
    w.properties("strip", members, strips.properties, STRIP_PSET)
    return members
