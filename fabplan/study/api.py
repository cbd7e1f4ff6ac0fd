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

This module holds the nets' calls (layout, optimize, measure, arcs, milling, studies, OBJ);
`fabplan.study.api_products` the molds, strips and the files that carry them (3DM, glTF,
IFC). Both only wrap the stages (`fabplan.layout`, `fabplan.solve`, `fabplan.fabricate`,
`fabplan.study.run`); they sit in the study stage, the top of the flow, because they reach
every stage below. Kept apart, an optimize in a notebook loads neither molds nor strips
(and their scipy modules: about a second).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Union

import numpy as np

from ..errors import InputError
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
    "as_mesh",
    "layout_net",
    "optimize",
    "measure",
    "run_study",
    "arcs",
    "mill",
    "read_obj",
    "write_obj",
    "read_3dm",
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
    from ..io.rhino_write import read_3dm_net

    vertices, faces, _ = read_3dm_net(path)
    return QuadMesh(vertices, faces, name=str(path))
