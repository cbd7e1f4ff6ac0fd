"""fabplan: from a freeform design to molds, strips and panels with principal symmetric meshes.

The package reads as its data flow; each stage is a subpackage that imports only the
stages below it::

    design -> layout -> net -> solve (optimize, measure) -> fabricate -> study -> report

The main objects are re-exported here and imported on first use, so that ``import
fabplan`` stays cheap for a host program::

    import fabplan
    mesh = fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    result = fabplan.optimize(mesh, "linear-weingarten")
    result.properties["sphere_residual_relative"]["max"]
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import FabplanError, InputError, SolverError

__version__ = "0.1.0"

# public name -> the module that owns it
_EXPORTS = {
    "QuadMesh": "fabplan.net.mesh",
    "load_mesh": "fabplan.net.mesh",
    "measure_net": "fabplan.net.measure",
    "NETS": "fabplan.solve.net_types",
    "get_net": "fabplan.solve.net_types",
    "optimize": "fabplan.study.api",
    "OptimizationResult": "fabplan.solve.optimize",
    "NetEditor": "fabplan.solve.edit",
    "ReferenceSurface": "fabplan.solve.reference",
    "load_reference": "fabplan.solve.reference",
    "GuidedProjection": "fabplan.solve.solver",
    "SolverSettings": "fabplan.solve.solver",
    "DesignSurface": "fabplan.design.mesh_surface",
    "load_design": "fabplan.design.load",
    "layout_surface": "fabplan.layout.surface_layout",
    "glide": "fabplan.layout.surface_layout",
    "plan_molds": "fabplan.study.api_products",
    "MoldSettings": "fabplan.fabricate.molds.mold_shapes",
    "MoldPlan": "fabplan.fabricate.molds.mold_plan",
    "StripSettings": "fabplan.fabricate.strips.strip_set",
    "build_strips": "fabplan.fabricate.strips.strip_set",
    "plan_strips": "fabplan.study.api_products",
    "StripPlan": "fabplan.fabricate.strips.strip_plan",
    "read_study": "fabplan.study.spec",
    "run_study": "fabplan.study.api",
    # the pipeline for scripts: (V, F) or a QuadMesh in, typed results with .to_json() out
    # `layout` is the name of the layout stage's subpackage, so the call is `layout_net`
    "layout_net": "fabplan.study.api",
    "measure": "fabplan.study.api",
    "arcs": "fabplan.study.api",
    "read_obj": "fabplan.study.api",
    "write_obj": "fabplan.study.api",
    "read_3dm": "fabplan.study.api",
    "write_3dm": "fabplan.study.api_products",
    "write_glb": "fabplan.study.api_products",
    "NetResult": "fabplan.study.api",
    "Measurement": "fabplan.study.api",
    "MoldResult": "fabplan.study.api_products",
    "StripResult": "fabplan.study.api_products",
    "ArcStructure": "fabplan.fabricate.arcs",
    "mill": "fabplan.study.api",
}

__all__ = [
    "FabplanError",
    "InputError",
    "SolverError",
    "data_path",
    "QuadMesh",
    "load_mesh",
    "measure_net",
    "NETS",
    "get_net",
    "optimize",
    "OptimizationResult",
    "NetEditor",
    "ReferenceSurface",
    "load_reference",
    "GuidedProjection",
    "SolverSettings",
    "DesignSurface",
    "load_design",
    "layout_surface",
    "glide",
    "plan_molds",
    "MoldSettings",
    "MoldPlan",
    "StripSettings",
    "build_strips",
    "plan_strips",
    "StripPlan",
    "read_study",
    "run_study",
    "layout_net",
    "measure",
    "arcs",
    "mill",
    "read_obj",
    "write_obj",
    "read_3dm",
    "write_3dm",
    "write_glb",
    "NetResult",
    "Measurement",
    "MoldResult",
    "StripResult",
    "ArcStructure",
]

if TYPE_CHECKING:  # what a type checker and an IDE see; at run time `__getattr__` imports
    from .design.load import load_design
    from .design.mesh_surface import DesignSurface
    from .fabricate.arcs import ArcStructure
    from .fabricate.molds.mold_plan import MoldPlan
    from .fabricate.molds.mold_shapes import MoldSettings
    from .fabricate.strips.strip_plan import StripPlan
    from .fabricate.strips.strip_set import StripSettings, build_strips
    from .layout.surface_layout import glide, layout_surface
    from .net.measure import measure_net
    from .net.mesh import QuadMesh, load_mesh
    from .solve.edit import NetEditor
    from .solve.net_types import NETS, get_net
    from .solve.optimize import OptimizationResult
    from .solve.reference import ReferenceSurface, load_reference
    from .solve.solver import GuidedProjection, SolverSettings
    from .study.api import (
        Measurement,
        NetResult,
        arcs,
        layout_net,
        measure,
        mill,
        optimize,
        read_3dm,
        read_obj,
        run_study,
        write_obj,
    )
    from .study.api_products import MoldResult, StripResult, plan_molds, plan_strips, write_3dm, write_glb
    from .study.spec import read_study


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'fabplan' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


def data_path(name: str) -> Path:
    """Path of a bundled data file (``wein99.obj``, ``cmc1.obj``)."""
    return Path(__file__).parent / "data" / name
