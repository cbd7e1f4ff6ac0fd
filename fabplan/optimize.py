"""Optimize a quad mesh into a net of a named type, and write the result with its evidence."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .constraints import Closeness, CoherentOrientation, Fairness
from .errors import InputError
from .geometry import canonical_stars, fit_star_spheres
from .io import write_json
from .measure import measure_net
from .mesh import QuadMesh
from .nets import get_net, net_constraints
from .reference import ReferenceSurface
from .solver import GuidedProjection, IterationRecord, SolverSettings

__all__ = ["optimize", "OptimizationResult", "check_net_input", "read_fixed"]


@dataclass
class OptimizationResult:
    """An optimized net and the evidence measured on it after the solve."""

    mesh: QuadMesh
    net: str
    parameters: dict
    status: str
    iterations: int
    seconds: float
    history: list = field(default_factory=list)
    properties: dict = field(default_factory=dict)

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    def record(self) -> dict:
        """The JSON record written beside the OBJ."""
        return {
            "net": self.net,
            "parameters": self.parameters,
            "status": self.status,
            "iterations": self.iterations,
            "seconds": self.seconds,
            "properties": self.properties,
            "history": self.history,
        }

    def write(self, path: str | os.PathLike) -> tuple[Path, Path]:
        """Write ``path`` (OBJ) and the same name with ``.json``; both atomically."""
        path = Path(path)
        json_path = path.with_suffix(".json")
        header = (f"fabplan {self.net} net; status {self.status}; "
                  f"properties in {json_path.name}")
        self.mesh.write_obj(path, header=header)
        write_json(json_path, self.record())
        return path, json_path


def check_net_input(mesh: QuadMesh) -> None:
    """Refuse meshes on which no S-net condition can be posed, with the reason."""
    if not np.any(mesh.face_sizes == 4):
        raise InputError(f"{mesh.name}: no quad faces (triangles where quads are needed)")
    if len(mesh.stars) == 0:
        raise InputError(f"{mesh.name}: no regular vertex star (no interior vertex of valence 4 "
                         "surrounded by four faces)")


def read_fixed(spec: str | None, mesh: QuadMesh) -> np.ndarray:
    """Vertices to hold: ``"boundary"``, or a file of vertex ids (0-based, any separators)."""
    if spec is None:
        return np.zeros(0, dtype=np.int64)
    if spec == "boundary":
        return np.flatnonzero(mesh.is_boundary_vertex)
    path = Path(spec)
    if not path.is_file():
        raise InputError(f"{spec}: no such file (--fix takes 'boundary' or a file of vertex ids)")
    tokens = path.read_text().replace(",", " ").split()
    try:
        ids = np.array([int(t) for t in tokens], dtype=np.int64)
    except ValueError:
        raise InputError(f"{spec}: vertex ids must be integers") from None
    bad = ids[(ids < 0) | (ids >= mesh.vertex_count)]
    if bad.size:
        raise InputError(f"{spec}: vertex {bad[0]} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)")
    return ids


def optimize(mesh: QuadMesh, net: str = "snet", *, angle: float | None = None,
             radius: float | None = None, reference: ReferenceSurface | None = None,
             fixed: np.ndarray | None = None, settings: SolverSettings | None = None,
             fairness: bool = True, coherent: bool = False,
             progress: Callable[[IterationRecord], None] | None = None) -> OptimizationResult:
    """Optimize `mesh` into a net of type `net`.

    Parameters
    ----------
    mesh : the starting quad mesh.
    net : a name from `fabplan.nets.NETS`.
    angle : prescribed intersection angle in degrees (isogonal types).
    radius : prescribed Meusnier radius in model units (constant-radius types).
    reference : surface to stay close to; defaults to the input mesh itself.
    fixed : (k,) int, vertices held in place.
    settings : solver settings.
    fairness : add the fading fairness term.
    coherent : keep every Meusnier sphere on the side where most of them start (stars
        that would cross over become planar rather than flip).
    progress : called after every iteration with its record.

    Returns
    -------
    OptimizationResult, with the properties measured on the result.
    """
    check_net_input(mesh)
    preset = get_net(net)
    stars = canonical_stars(mesh.vertices, mesh.stars)
    side = np.nanmedian(fit_star_spheres(mesh.vertices, stars).curvature)
    families = net_constraints(preset, angle_deg=angle, radius=radius,
                               length_scale=mesh.mean_edge_length, curvature_sign=np.sign(side))
    if coherent and not any(isinstance(f, CoherentOrientation) for f in families):
        families.append(CoherentOrientation())
    if reference is None:
        reference = ReferenceSurface.from_mesh(mesh)
    if fairness:
        families.append(Fairness())
    families.append(Closeness(reference))
    start = time.perf_counter()
    solver = GuidedProjection(mesh, families, fixed=fixed, settings=settings)
    status = solver.run(callback=progress)
    seconds = time.perf_counter() - start
    result_mesh = mesh.with_vertices(solver.vertices)
    parameters = {"angle_deg": angle, "radius": radius, "coherent": coherent,
                  "fixed_vertices": int(len(solver.fixed))}
    layout = solver.state.layout
    if "cosine" in layout.blocks:
        parameters["angle_deg"] = float(np.degrees(np.arccos(np.clip(solver.variable("cosine")[0], -1, 1))))
    if "curvature" in layout.blocks:
        k = solver.variable("curvature")[0] / solver.length_scale
        parameters["radius"] = float(abs(1 / k)) if k != 0 else float("inf")
    return OptimizationResult(
        mesh=result_mesh,
        net=preset.name,
        parameters=parameters,
        status=status,
        iterations=sum(1 for h in solver.history if h.step > 0),
        seconds=seconds,
        history=[h.as_dict() for h in solver.history],
        properties=measure_net(result_mesh, reference=reference),
    )
