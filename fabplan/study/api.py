"""The whole pipeline as plain function calls, for scripts (Grasshopper, COMPAS, Jupyter).

Every function takes a net as a `QuadMesh` or as ``(V, F)`` arrays (vertices ``(n, 3)``,
faces ``(f, 4)`` or a list of index sequences) and returns a typed result: a dataclass
holding the arrays, with ``.to_json()`` for the measured numbers. The `plan_*` functions
share one calling convention: a settings object, or its fields as keyword options::

    design = load_design("hyperbolic-paraboloid:width=8,depth=8,rise=2.5")
    net = layout_net(design, 1.5)                # NetResult
    molds = plan_molds(net, tolerance_mm=5)      # MoldResult
    strips = plan_strips(net, height_mm=120, thickness_mm=6)
    write_3dm(net, "net.3dm", molds=molds, strips=strips)

This module only wraps the stages (`fabplan.layout`, `fabplan.solve`, `fabplan.fabricate`,
`fabplan.study.run`); it sits in the study stage, the top of the flow, because it reaches
every stage below.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Union

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
from ..io.rhino_write import NetDrawing, read_3dm_net, write_net_3dm
from ..net.measure import measure_net
from ..net.mesh import QuadMesh
from ..solve.optimize import OptimizationResult
from ..solve.optimize import optimize as _optimize_impl

if TYPE_CHECKING:  # pragma: no cover
    from ..design.mesh_surface import DesignSurface  # noqa: F811 - imported again where used
    from ..fabricate.arcs import ArcStructure
    from ..fabricate.milling.mill_plan import MillSettings, MillTool
    from ..fabricate.milling.mill_report import MillResult
    from ..layout.surface_layout import SurfaceLayout
    from ..solve.reference import ReferenceSurface
    from .definition import Study
    from .result import StudyResult

__all__ = [
    "NetLike",
    "NetResult",
    "Measurement",
    "MoldResult",
    "StripResult",
    "as_mesh",
    "layout_net",
    "optimize",
    "measure",
    "plan_molds",
    "plan_strips",
    "run_study",
    "arcs",
    "mill",
    "read_obj",
    "write_obj",
    "read_3dm",
    "net_drawing",
    "write_3dm",
    "write_glb",
    "ifc_facade",
    "write_ifc",
]

NetLike = Union[QuadMesh, OptimizationResult, tuple]
"""A net: a `QuadMesh`, a result holding one (``.mesh``), or ``(V, F)`` arrays."""


def as_mesh(net: NetLike, *, name: str = "net") -> QuadMesh:
    """The `QuadMesh` of a net given as a mesh, a result with a ``.mesh``, or ``(V, F)``.

    Examples
    --------
    >>> as_mesh(([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]])).vertex_count
    4
    """
    if isinstance(net, QuadMesh):
        return net
    mesh = getattr(net, "mesh", None)
    if isinstance(mesh, QuadMesh):
        return mesh
    if isinstance(net, tuple) and len(net) == 2:
        vertices, faces = net
        return QuadMesh(vertices, [np.asarray(f, dtype=np.int64) for f in faces], name=name)
    raise InputError(f"a net is a QuadMesh or a (V, F) pair of arrays, got {type(net).__name__}")


# ----------------------------------------------------------------------------- results
@dataclass
class NetResult(OptimizationResult):
    """An optimized net (an `OptimizationResult`) with array accessors and ``to_json()``.

    Attributes beyond `OptimizationResult`'s: ``layout``, the `SurfaceLayout` the net was
    laid out from (`layout_net` only).
    """

    layout: Any = None

    @classmethod
    def of(cls, result: OptimizationResult, layout: Any = None) -> "NetResult":
        values = {f.name: getattr(result, f.name) for f in fields(OptimizationResult)}
        return cls(**values, layout=layout)

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float, the net's vertices (model units)."""
        return self.mesh.vertices

    @property
    def faces(self) -> list:
        """list of (k,) int vertex index arrays."""
        return self.mesh.faces

    def to_json(self) -> dict:
        """The record written beside the OBJ (status, parameters, measured properties)."""
        return self.record()

    def write_html(self, path: str | os.PathLike, *, surface: Any = None,
                   units: str = "m") -> Path:
        """Write the net's page, as ``fabplan layout --html`` does (atomically): its key
        numbers, its interactive 3D view with its boundary panels, and a picture.

        surface : what the deviation mode measures to (with ``distances(points)``):
            default the design the net was laid out on (`layout_net`); None without one.
        units : the model units (``"m"``, ``"mm"``, ...).
        """
        from ..io.output import write_texts
        from ..layout.view import net_view_html

        design = getattr(self.layout, "design", None)
        surface = surface if surface is not None else design
        path = Path(path)
        write_texts({path: net_view_html(
            self, title=f"{self.net} net: {path.stem}", surface=surface, units=units,
            deviation_from="the design" if surface is not None and surface is design
            else "the reference")})
        return path


@dataclass
class Measurement:
    """What `measure` found on a net.

    Attributes
    ----------
    mesh : the net measured.
    properties : the measured record (`fabplan.net.measure.measure_net`): sphere
        residuals, radii, angles, curvatures, planarity, folds.
    """

    mesh: QuadMesh
    properties: dict

    def to_json(self) -> dict:
        return self.properties


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


# ----------------------------------------------------------------------------- stages
def layout_net(design: DesignSurface | str | os.PathLike, panel_size: float, net: str = "snet", *,
           angle: float | None = None, family: str | None = None, settings: Any = None,
           starts: int = 5, progress: Callable[..., None] | None = None) -> NetResult:
    """Lay out a net of type `net` on a design and solve it gliding on the surface
    (``fabplan layout``).

    Parameters
    ----------
    design : a `DesignSurface`, or what `load_design` reads (a file or a built-in spec).
    panel_size : target edge length (model units).
    net : a net type (``fabplan nets``).
    angle : intersection angle in degrees for isogonal nets (default: the design's).
    family : prescribed first family (``"z"``, ``"z:3.5"`` or a file), see the CLI.
    settings : `fabplan.SolverSettings`.
    starts : how many starts to solve and choose the fairest from
        (`fabplan.layout.starts.glide_fairest`; 1: one layout, one solve).
    """
    from ..design.load import load_design
    from ..design.mesh_surface import DesignSurface
    from ..layout.starts import glide_fairest
    from ..layout.surface_layout import layout_angle
    from ..solve.net_types import get_net

    surface = design if isinstance(design, DesignSurface) else load_design(design)
    preset = get_net(net)
    start = layout_angle(preset.name, surface, angle) if family is None else 90.0
    laid: SurfaceLayout
    laid, result = glide_fairest(surface, panel_size, preset.name, angle=start,
                                 net_angle=angle if preset.angle == "param" else None,
                                 family=family, solver=settings, starts=starts,
                                 progress=progress)
    return NetResult.of(result, layout=laid)


def optimize(net: NetLike, net_type: str = "snet", **options: Any) -> NetResult:
    """Optimize a net into a net type (``fabplan optimize``); `options` are those of
    `fabplan.solve.optimize.optimize` (``angle``, ``radius``, ``reference``, ``fixed``,
    ``handles``, ``settings``, ``guards``, ...).

    Examples
    --------
    >>> import fabplan
    >>> result = optimize(fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj")), "snet")
    >>> result.converged, result.vertices.shape
    (True, (1732, 3))
    """
    return NetResult.of(_optimize_impl(as_mesh(net), net_type, **options))


def measure(net: NetLike, *, reference: ReferenceSurface | None = None) -> Measurement:
    """Measure a net (``fabplan measure``): sphere residuals, radii, angles, curvatures."""
    mesh = as_mesh(net)
    return Measurement(mesh=mesh, properties=measure_net(mesh, reference=reference))


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


def mill(net: NetLike, tool: MillTool | str, settings: MillSettings | None = None, *,
         simulate: bool = True, design: Any = None, **options: Any) -> MillResult:
    """Curvature-adaptive milling of a net (``fabplan mill``): face milling of an S-net, or
    flank milling of an S*-net with a cone; the tool as a `MillTool` or its spec
    (``"face:D=50"``, ``"cone:angle=45,length=10,tip=24"``), `MillSettings` or its fields as keyword
    options (``along="A", units="mm", scallop_mm=0.01``); with `simulate` the paths are
    checked by the milling simulation against the conventional ball-end cut. `design`: the
    design the net was made for (a `fabplan.design.DesignSurface` or what `load_design`
    reads, in the net's units), which the passes are placed on and the cut is measured
    against (``fabplan mill --design``). The result's ``record()`` is what ``mill.json``
    holds."""
    # the milling and arc modules (scipy's interpolation) load with their calls: the
    # rest of the API (an optimize in a notebook) does without them
    from ..fabricate.milling.mill_plan import MillSettings, parse_tool
    from ..fabricate.milling.mill_report import mill_net

    if settings is None:
        settings = MillSettings(**options)
    elif options:
        raise InputError("give either settings or keyword options, not both")
    if isinstance(design, (str, os.PathLike)):
        from ..design.load import load_design

        design = load_design(design)
    return mill_net(as_mesh(net), parse_tool(tool) if isinstance(tool, str) else tool, settings,
                    simulate=simulate, design=design)


def run_study(study: Study | str | os.PathLike, **options: Any) -> StudyResult:
    """Run a facade study (``fabplan study``): a `Study`, a study file or a template name;
    `options` are those of `fabplan.study.run.run_study` (``progress``, ``max_panels``)."""
    from .run import run_study as run
    from .spec import read_study
    from .templates import resolve_study

    if isinstance(study, (str, os.PathLike)):
        study = read_study(resolve_study(str(study)))
    return run(study, **options)


def arcs(net: NetLike) -> ArcStructure:
    """The circular arc structure of a net (``fabplan arcs``)."""
    from ..fabricate.arcs import arc_structure

    return arc_structure(as_mesh(net))


# ----------------------------------------------------------------------------- files
def read_obj(path: str | os.PathLike) -> QuadMesh:
    """Read a net from OBJ, quads and vertex order kept."""
    return QuadMesh.from_obj(path)


def write_obj(net: NetLike, path: str | os.PathLike) -> Path:
    """Write a net as OBJ (atomically); returns the path."""
    as_mesh(net).write_obj(path)
    return Path(path)


def read_3dm(path: str | os.PathLike) -> QuadMesh:
    """Read the net of a .3dm file fabplan wrote (the mesh on layer ``net``)."""
    vertices, faces, _ = read_3dm_net(path)
    return QuadMesh(vertices, faces, name=str(path))


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
