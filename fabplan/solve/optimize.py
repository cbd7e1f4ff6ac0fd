"""Optimize a quad mesh into a net of a named type, and write the result with its evidence."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import InputError, SolverError
from ..io.obj import format_obj
from ..io.output import write_texts
from ..io.records import json_text
from ..net.geometry import canonical_stars, fit_mannheim_spheres, fit_star_spheres, vertex_contact_normals
from ..net.measure import measure_net
from ..net.mesh import QuadMesh
from .constraints import (
    BoundaryGliding,
    Closeness,
    CoherentOrientation,
    ConstantAngle,
    ConstantCurvature,
    ConstantMannheimRadius,
    EdgeCollapseBarrier,
    Fairness,
    RulingAngle,
)
from .net_types import get_net, net_constraints
from .reference import ReferenceSurface
from .solver import GuidedProjection, IterationRecord, SolverSettings

__all__ = [
    "optimize",
    "build_solver",
    "OptimizationResult",
    "check_net_input",
    "read_fixed",
    "read_handles",
    "solved_parameters",
    "unmet_constraints",
]


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
    linear_solver: str = ""    # the sparse backend that solved the normal equations

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
            "linear_solver": self.linear_solver,
            "properties": self.properties,
            "history": self.history,
        }

    def write(self, path: str | os.PathLike) -> tuple[Path, Path]:
        """Write ``path`` (OBJ) and the same name with ``.json``; both atomically."""
        path = Path(path)
        json_path = path.with_suffix(".json")
        header = (f"fabplan {self.net} net; status {self.status}; "
                  f"properties in {json_path.name}")
        obj_text = format_obj(self.mesh.vertices, self.mesh.faces, header, self.mesh.normals)
        write_texts({path: obj_text, json_path: json_text(self.record())})
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
    try:
        tokens = path.read_text(encoding="utf-8").replace(",", " ").split()
    except (UnicodeDecodeError, OSError):
        raise InputError(f"{spec}: not a text file of vertex ids") from None
    try:
        ids = np.array([int(t) for t in tokens], dtype=np.int64)
    except ValueError:
        raise InputError(f"{spec}: vertex ids must be integers") from None
    bad = ids[(ids < 0) | (ids >= mesh.vertex_count)]
    if bad.size:
        raise InputError(f"{spec}: vertex {bad[0]} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)")
    return ids


def build_solver(mesh: QuadMesh, net: str = "snet", *, angle: float | None = None,
                 radius: float | None = None, reference: ReferenceSurface | None = None,
                 fixed: np.ndarray | None = None, settings: SolverSettings | None = None,
                 fairness: bool = True, coherent: bool = False,
                 closeness: bool = True, glide: bool = False,
                 glide_boundary: np.ndarray | None = None, surface_tolerance: float = 0.0,
                 extra: tuple = ()) -> GuidedProjection:
    """The solver `optimize` runs, ready for `GuidedProjection.run` (see `optimize`)."""
    check_net_input(mesh)
    preset = get_net(net)
    families = net_constraints(preset, angle_deg=angle, radius=radius,
                               length_scale=mesh.mean_edge_length,
                               curvature_sign=sphere_side(mesh, dual=preset.dual))
    if coherent and not any(isinstance(f, CoherentOrientation) for f in families):
        families.append(CoherentOrientation())
    if fairness:
        families.append(Fairness())
    families.append(EdgeCollapseBarrier())
    if reference is None and (closeness or glide):
        reference = ReferenceSurface.from_mesh(mesh)
    if glide:
        # on the surface at convergence, boundary vertices on its boundary curves
        families.append(Closeness(reference, hard=True, tolerance=surface_tolerance))
        curves = reference.boundary_curves()
        if glide_boundary is None:
            glide_boundary = np.flatnonzero(mesh.is_boundary_vertex)
        if curves and len(glide_boundary):
            families.append(BoundaryGliding(curves, glide_boundary))
    elif closeness:
        families.append(Closeness(reference))
    families += list(extra)
    solver = GuidedProjection(mesh, families, fixed=fixed, settings=settings)
    solver.net = preset.name
    solver.reference = reference
    return solver


def sphere_side(mesh: QuadMesh, *, dual: bool = False) -> float:
    """+1 or -1: the side of the surface where most spheres of `mesh` lie, as the sign of
    the normal curvature of its Meusnier spheres (the Mannheim radius for S*-nets).
    Flat stars say nothing about the side and are left out."""
    stars = canonical_stars(mesh.vertices, mesh.stars)
    if dual:
        normals = mesh.normals if mesh.normals is not None else \
            vertex_contact_normals(mesh, mesh.vertices, stars)
        value = fit_mannheim_spheres(mesh.vertices, normals, stars).radius
        value = value[np.isfinite(value)]
    else:
        value = fit_star_spheres(mesh.vertices, stars).curvature
        value = value[np.abs(value) * mesh.mean_edge_length > 1e-9]
    return -1.0 if value.size and np.median(value) < 0 else 1.0


def solved_parameters(solver: GuidedProjection) -> dict:
    """The common angle (degrees) and Meusnier radius (model units) of a solved net, where
    its net type has them."""
    blocks, parameters = solver.state.blocks, {}
    for family in solver.constraints:
        if isinstance(family, ConstantMannheimRadius) and family.radius is not None:
            parameters["radius"] = abs(family.radius) * solver.length_scale
        if isinstance(family, RulingAngle) and family.cosine is not None:
            parameters["angle_deg"] = float(np.degrees(np.arccos(family.cosine)))
        if isinstance(family, ConstantAngle) and family.cosine is not None:
            parameters["angle_deg"] = float(np.degrees(np.arccos(family.cosine)))
        if isinstance(family, ConstantCurvature) and family.curvature is not None:
            k = family.curvature / solver.length_scale
            parameters["radius"] = float(abs(1 / k)) if k != 0 else float("inf")
    if "cosine" in blocks:
        cosine = np.clip(solver.variable("cosine")[0], -1.0, 1.0)
        parameters["angle_deg"] = float(np.degrees(np.arccos(cosine)))
    if "curvature" in blocks:
        k = solver.variable("curvature")[0] / solver.length_scale
        parameters["radius"] = float(abs(1 / k)) if k != 0 else float("inf")
    if "ruling-cosine" in blocks:
        cosine = np.clip(solver.variable("ruling-cosine")[0], -1.0, 1.0)
        parameters["angle_deg"] = float(np.degrees(np.arccos(cosine)))
    if "mannheim-common" in blocks:
        parameters["radius"] = float(abs(solver.variable("mannheim-common")[0]) * solver.length_scale)
    return parameters


def solver_normals(solver: GuidedProjection) -> np.ndarray | None:
    """(n, 3) unit normals of the contact elements of an S*-net solve, else None."""
    if "normals" not in solver.state.blocks:
        return None
    N = solver.variable("normals")
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def unmet_constraints(solver: GuidedProjection) -> dict:
    """Hard constraint families whose last measured residual is above the tolerance:
    name -> max |residual| (mean edges for distances, cosines for angles)."""
    last = solver.history[-1].residuals if solver.history else {}
    hard = {c.name for c in solver.constraints if c.hard}
    tol = solver.settings.tolerance
    return {name: r for name, r in last.items() if name in hard and r > tol}


def describe_unmet(unmet: dict) -> str:
    """One line naming the constraint families that could not be met and their residuals."""
    return ", ".join(f"{name} residual {r:.2e}" for name, r in sorted(unmet.items()))


def optimize(mesh: QuadMesh, net: str = "snet", *, angle: float | None = None,
             radius: float | None = None, reference: ReferenceSurface | None = None,
             fixed: np.ndarray | None = None, handles: dict | None = None,
             settings: SolverSettings | None = None, fairness: bool = True,
             coherent: bool = False, closeness: bool = True, glide: bool = False,
             glide_boundary: np.ndarray | None = None, surface_tolerance: float = 0.0,
             extra: tuple = (), progress: Callable[[IterationRecord], None] | None = None
             ) -> OptimizationResult:
    """Optimize `mesh` into a net of type `net`.

    Parameters
    ----------
    mesh : the starting quad mesh.
    net : a name from `fabplan.nets.NETS`.
    angle : prescribed intersection angle in degrees (isogonal types).
    radius : prescribed Meusnier radius in model units (constant-radius types).
    reference : surface to stay close to; defaults to the input mesh itself.
    fixed : (k,) int, vertices held in place.
    handles : {vertex id: (3,) target position}: vertices moved to their targets and held.
    settings : solver settings.
    fairness : add the fading fairness term.
    coherent : keep every Meusnier sphere on the side where most of them start (stars
        that would cross over become planar rather than flip).
    closeness : pull towards the reference; off for form-finding from combinatorics,
        where the start positions are only a guess.
    glide : keep the net on the reference as a constraint (not a fading pull), with its
        boundary vertices on the reference's boundary curves: a layout that glides on a
        design surface.
    glide_boundary : (b,) int, the boundary vertices that glide on the reference's
        boundary curves (default: all boundary vertices of the net).
    surface_tolerance : with `glide`, how far the vertices may leave the reference
        (model units; 0 holds them on it).
    extra : further constraint families to solve with (e.g. prescribed levels).
    progress : called after every iteration with its record.

    Returns
    -------
    OptimizationResult, with the properties measured on the result.

    Raises
    ------
    SolverError
        When handles ask for a net the constraints cannot reach (the message names the
        constraint families left unmet and their residuals), or the solver diverges.
    """
    handle_ids, targets = _handle_arrays(handles, mesh)
    held = np.union1d(np.asarray([] if fixed is None else fixed, dtype=np.int64), handle_ids)
    start = time.perf_counter()
    solver = build_solver(mesh, net, angle=angle, radius=radius, reference=reference,
                          fixed=held, settings=settings, fairness=fairness, coherent=coherent,
                          closeness=closeness, glide=glide, glide_boundary=glide_boundary,
                          surface_tolerance=surface_tolerance, extra=extra)
    if handle_ids.size:
        solver.set_vertices(handle_ids, targets)
    status = solver.run(callback=progress)
    if handle_ids.size and status != "converged":
        raise SolverError(f"the handles ask for a net that cannot be reached ({status} after "
                          f"{len(solver.history) - 1} iterations): "
                          f"{describe_unmet(unmet_constraints(solver))}")
    seconds = time.perf_counter() - start
    result_mesh = mesh.with_vertices(solver.vertices, normals=solver_normals(solver))
    parameters = {"angle_deg": angle, "radius": radius, **solved_parameters(solver),
                  "coherent": coherent, "fixed_vertices": int(len(solver.fixed)),
                  "handles": {int(i): t.tolist() for i, t in zip(handle_ids, targets, strict=True)}}
    return OptimizationResult(
        mesh=result_mesh,
        net=solver.net,
        parameters=parameters,
        status=status,
        iterations=sum(1 for h in solver.history if h.step > 0),
        seconds=seconds,
        linear_solver=solver.linear_solver,
        history=[h.as_dict() for h in solver.history],
        properties=measure_net(result_mesh, reference=solver.reference),
    )


def _handle_arrays(handles: dict | None, mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray]:
    if not handles:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    ids = np.array(list(handles), dtype=np.int64)
    targets = np.array([np.asarray(handles[i], dtype=np.float64) for i in handles]).reshape(-1, 3)
    bad = ids[(ids < 0) | (ids >= mesh.vertex_count)]
    if bad.size:
        raise InputError(f"handle vertex {bad[0]} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)")
    if not np.isfinite(targets).all():
        raise InputError("handle targets must be finite coordinates")
    return ids, targets


def read_handles(specs: list[str] | None) -> dict:
    """Handles from ``ID:X,Y,Z`` strings or files of ``ID X Y Z`` lines."""
    handles: dict = {}
    for spec in specs or []:
        path = Path(spec)
        lines = [spec]
        if ":" not in spec and path.is_file():
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except (UnicodeDecodeError, OSError):
                raise InputError(f"{spec}: not a text file of handles") from None
        for line in lines:
            line = line.split("#")[0].strip()
            if not line:
                continue
            parts = line.replace(":", " ").replace(",", " ").split()
            try:
                vid, xyz = int(parts[0]), [float(p) for p in parts[1:]]
            except (ValueError, IndexError):
                xyz = []
            if len(xyz) != 3:
                where = f"{spec}" if lines == [spec] else f"{spec}: line {line!r}"
                raise InputError(f"{where}: a handle is ID:X,Y,Z (or a file of 'ID X Y Z' lines)")
            handles[vid] = xyz
    return handles
