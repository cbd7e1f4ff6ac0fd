"""fabplan: from a freeform design to molds, strips and panels with principal symmetric meshes.

The main objects are re-exported here::

    import fabplan
    mesh = fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    result = fabplan.optimize(mesh, "linear-weingarten")
    result.properties["sphere_residual_relative"]["max"]
"""

from pathlib import Path

from .edit import NetEditor
from .errors import FabplanError, InputError, SolverError
from .measure import measure_net
from .mesh import QuadMesh, load_mesh
from .molds import MoldPlan, MoldSettings, plan_molds
from .nets import NETS, get_net
from .optimize import OptimizationResult, optimize
from .reference import ReferenceSurface, load_reference
from .solver import GuidedProjection, SolverSettings
from .strips import StripSettings, build_strips, plan_strips

__version__ = "0.1.0"

__all__ = [
    "FabplanError",
    "InputError",
    "SolverError",
    "QuadMesh",
    "load_mesh",
    "measure_net",
    "plan_molds",
    "MoldSettings",
    "MoldPlan",
    "NETS",
    "get_net",
    "optimize",
    "NetEditor",
    "OptimizationResult",
    "ReferenceSurface",
    "load_reference",
    "GuidedProjection",
    "SolverSettings",
    "StripSettings",
    "build_strips",
    "plan_strips",
    "data_path",
]


def data_path(name: str) -> Path:
    """Path of a bundled data file (``wein99.obj``, ``cmc1.obj``)."""
    return Path(__file__).parent / "data" / name
