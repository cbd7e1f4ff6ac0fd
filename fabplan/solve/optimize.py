"""Optimize a quad mesh into a net of a named type, and write the result with its evidence."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError, SolverError
from ..io.obj import format_obj
from ..io.output import write_texts
from ..io.parameters import OPTIONS
from ..io.records import json_text
from ..net.buildable import BuildLimits, BuildReport, crumpled, measure_buildable
from ..net.folds import FoldReport, fold_edge_mask, measure_folds
from ..net.free_vertices import free_vertices, settle_free_vertices
from ..net.geometry import (
    canonical_stars,
    face_normals,
    fit_mannheim_spheres,
    fit_star_spheres,
    intersection_angles,
    vertex_contact_normals,
)
from ..net.measure import measure_net
from ..net.mesh import QuadMesh
from .constraints import (
    BoundaryGliding,
    Closeness,
    CoherentOrientation,
    ConstantAngle,
    ConstantCurvature,
    ConstantMannheimRadius,
    ConvexQuads,
    DeviationBound,
    EdgeCollapseBarrier,
    Fairness,
    NetState,
    NormalCone,
    RulingAngle,
    StarAngleRange,
)
from .multilevel import (
    MAX_FINE_ROUGHNESS,
    MIN_COARSE_LINES,
    MULTILEVEL_MIN_VERTICES,
    coarse_grid_net,
    coarse_lines,
    fine_roughness,
    grid_indices,
    line_parameters,
    prolong_vertices,
    start_from_coarse,
)
from .net_types import get_net, net_constraints
from .pattern import pattern_cache
from .reference import ReferenceSurface
from .smoothing import smoothed_vertices
from .solver import GuidedProjection, IterationRecord, SolverSettings

__all__ = [
    "optimize",
    "build_solver",
    "OptimizationResult",
    "boundary_path",
    "check_net_input",
    "kept_faces",
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
    message: str = ""          # what stood in the way when not converged, and what to try
    # for a net laid out on a design: the panels between it and the design's boundary
    # (`fabplan.layout.trim.BoundaryPanels`, with `obj_text()`), written beside the OBJ
    boundary_panels: Any = None

    @property
    def converged(self) -> bool:
        """Hard residuals within tolerance and no fold (see `fabplan.net.folds`)."""
        return self.status == "converged"

    def record(self) -> dict:
        """The JSON record written beside the OBJ."""
        return {
            "net": self.net,
            "parameters": self.parameters,
            "status": self.status,
            "message": self.message,
            "iterations": self.iterations,
            "seconds": self.seconds,
            "linear_solver": self.linear_solver,
            "properties": self.properties,
            "history": self.history,
        }

    def write(self, path: str | os.PathLike) -> tuple[Path, Path]:
        """Write ``path`` (OBJ) and the same name with ``.json``, and with boundary panels
        `boundary_path` beside them; all atomically."""
        path = Path(path)
        json_path = path.with_suffix(".json")
        header = (f"fabplan {self.net} net; status {self.status}; "
                  f"properties in {json_path.name}")
        texts = {path: format_obj(self.mesh.vertices, self.mesh.faces, header, self.mesh.normals),
                 json_path: json_text(self.record())}
        if self.boundary_panels is not None:
            texts[boundary_path(path)] = self.boundary_panels.obj_text(
                f"fabplan boundary panels of {path.name}: its vertices first, then the corners "
                "and outline points on the design boundary; one face per panel")
        write_texts(texts)
        return path, json_path


def boundary_path(path: str | os.PathLike) -> Path:
    """Where the boundary panels of the net written to `path` go: ``NAME.boundary.obj``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.boundary.obj")


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
        values = [int(t) for t in tokens]
    except ValueError:
        raise InputError(f"{spec}: vertex ids must be integers") from None
    return _vertex_ids(values, mesh, spec)


def _vertex_ids(values: list[int], mesh: QuadMesh, where: str) -> np.ndarray:
    """(k,) int64, vertex ids read from a file or an option, each checked to exist; an id
    too large for any integer array (2**64) is named as the others are."""
    try:
        ids = np.array(values, dtype=np.int64)
    except OverflowError:
        first = next(v for v in values if abs(v) >= 2**62)
        raise InputError(f"{where}: vertex {first} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)") from None
    bad = ids[(ids < 0) | (ids >= mesh.vertex_count)]
    if bad.size:
        raise InputError(f"{where}: vertex {bad[0]} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)")
    return ids


def build_solver(mesh: QuadMesh, net: str = "snet", *, angle: float | None = None,
                 radius: float | None = None, reference: ReferenceSurface | None = None,
                 fixed: np.ndarray | None = None, settings: SolverSettings | None = None,
                 fairness: bool = True, coherent: bool = False,
                 closeness: bool = True, glide: bool = False,
                 glide_boundary: np.ndarray | None = None, surface_tolerance: float = 0.0,
                 extra: tuple = (), guards: bool = False,
                 max_deviation: float | None = None,
                 limits: BuildLimits | None = None) -> GuidedProjection:
    """The solver `optimize` runs, ready for `GuidedProjection.run` (see `optimize`)."""
    check_net_input(mesh)
    preset = get_net(net)
    check_radius_fits(mesh, radius, dual=preset.dual)
    families = net_constraints(preset, angle_deg=angle, radius=radius,
                               length_scale=mesh.mean_edge_length,
                               curvature_sign=sphere_side(mesh, dual=preset.dual))
    if coherent and not any(isinstance(f, CoherentOrientation) for f in families):
        families.append(CoherentOrientation())
    if fairness:
        turn = (limits or BuildLimits()).max_line_turn_deg
        families.append(Fairness(0.5 * turn, turn))
    families.append(EdgeCollapseBarrier())
    if reference is None and (closeness or glide or guards or max_deviation is not None):
        reference = ReferenceSurface.from_mesh(mesh)
    if glide:
        assert reference is not None
        # on the surface at convergence, boundary vertices on its boundary curves
        families.append(Closeness(reference, hard=True, tolerance=surface_tolerance))
        curves = reference.boundary_curves()
        if glide_boundary is None:
            glide_boundary = np.flatnonzero(mesh.is_boundary_vertex)
        if curves and len(glide_boundary):
            families.append(BoundaryGliding(curves, glide_boundary))
    elif closeness:
        families.append(Closeness(reference))
    if max_deviation is not None:
        families.append(DeviationBound(reference, max_deviation,
                                       (limits or BuildLimits()).deviation_vertices))
    if guards:
        families += [NormalCone(reference, GUARD_CONE_DEG), StarAngleRange(GUARD_STAR_ANGLE_DEG),
                     ConvexQuads(GUARD_CORNER_DEG)]
    families += list(extra)
    solver = GuidedProjection(mesh, families, fixed=fixed, settings=settings,
                              admissible=_admissible(mesh, families, limits or BuildLimits()))
    solver.net = preset.name
    solver.reference = reference
    return solver


# the guards added against folding (`fabplan.solve.constraints.guards`)
GUARD_CONE_DEG = 75.0        # face normals within this angle of the reference normal
GUARD_STAR_ANGLE_DEG = 15.0  # the families of a star at least this far apart
GUARD_CORNER_DEG = 5.0       # every quad convex, its corners turning by at least this


def check_radius_fits(mesh: QuadMesh, radius: float | None, *, dual: bool = False) -> None:
    """Refuse a prescribed Meusnier radius no sphere through a star can have.

    A sphere through a vertex and a neighbour at distance d has a radius of at least d / 2.
    """
    if radius is None or dual:
        return
    E = mesh.edges
    shortest = 0.5 * float(np.median(np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]],
                                                    axis=1)))
    if radius < shortest:
        raise InputError(f"--radius {radius:g} is smaller than half the edges of {mesh.name} "
                         f"({shortest:.4g}): no sphere of that radius passes through a vertex "
                         "and its neighbours; give a larger radius, or scale the net")


def _admissible(mesh: QuadMesh, families: list,
                limits: BuildLimits) -> Callable[[NetState], bool]:
    """The solver's test of an iterate: no fold edge, buildable (no dart, no line turning
    more than the limit: `fabplan.net.buildable.crumpled`), within a deviation limit
    the solve holds, and no farther from the reference than at the start or one mean
    edge, whichever is more (when a closeness family says how far the net is)."""
    edge_faces = mesh.interior_edge_faces
    closeness = next((f for f in families if isinstance(f, Closeness)), None)
    bound = next((f for f in families if isinstance(f, DeviationBound)), None)
    allowed: list[float] = []

    def admissible(state: NetState) -> bool:
        normals = face_normals(state.X, mesh)
        if fold_edge_mask(normals, edge_faces).any():
            return False
        if crumpled(mesh, state.X, state.stars, limits.max_line_turn_deg,
                    turns=state.data.get("line_turns"), normals=normals):
            return False
        if bound is not None and float(bound.distances(state).max(initial=0.0)) > \
                bound.limit / state.length_scale:
            return False
        if closeness is None:
            return True
        far = float(closeness.distances(state).max(initial=0.0))
        if not allowed:
            allowed.append(max(far, 1.0))      # normalized units: 1 is the mean edge
        return far <= allowed[0]

    return admissible


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
    """Hard constraint families whose residual on the net the solve ends with is above
    the tolerance: name -> max |residual| (mean edges for distances, cosines for angles)."""
    last = solver.history[-1].residuals if solver.history else {}
    if solver.status != "converged" and solver.best is not None:
        last = solver.best.residuals       # a solve that stops short ends at its best
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
             extra: tuple = (), guards: bool | None = None,
             settle_free: float | None = None,
             max_deviation: float | None = None, max_line_turn: float = 90.0,
             deviation_vertices: np.ndarray | None = None,
             progress: Callable[[IterationRecord], None] | None = None
             ) -> OptimizationResult:
    """Optimize `mesh` into a net of type `net`.

    Parameters
    ----------
    mesh : the starting quad mesh.
    net : a name from `fabplan.solve.net_types.NETS`.
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
    guards : the constraints against folding (`fabplan.solve.constraints.guards`): face
        normals within 75 degrees of the reference's, star angles within 15 to 165
        degrees. None (default): solve without them and, when that net folds (or has
        degenerate stars or collapsed edges), solve again with them, then from a smoothed
        copy of the start (`fabplan.solve.smoothing`) without and with them, still pulled
        towards the start, until one converges fold-free; the best is kept (the
        parameters say which: ``guards``, ``smoothed_start``). True: with them from the
        start; False: never, and no retry.
    settle_free : move the vertices in no star (the tips of a zigzag boundary, which no
        condition of the net holds) onto the surface the net continues
        (`fabplan.net.free_vertices.settle_free_vertices`), so that the faces at them are
        patches of the net's own surface, at the price of their distance from the
        reference: those of faces whose surface steps against a neighbour's by more than
        this (model units; 0: all of them). None (default): none. The parameters record
        how many there are and how far they moved (``free_vertices``).
    max_deviation : the largest distance of a vertex from the reference (model units),
        held inside the solve as an inequality (`fabplan.solve.constraints.DeviationBound`).
        When the net type cannot keep to it, the solve tightens the limit step by step
        from a loose one (a continuation) and the result is "off-design": its message
        gives the smallest limit the net converged to, or says that none was found, and
        ``parameters["deviation"]`` records the limits tried. None (default): no limit.
    max_line_turn : a converged net's lines turn in the surface by at most this at any
        vertex (degrees, in (0, 180]); over 90 a line doubles back.
    deviation_vertices : (k,) int, the vertices `max_deviation` holds at (default: all):
        a net continued past its design's edge is held where it will be built
        (`fabplan.net.buildable.BuildLimits.deviation_vertices`).
    progress : called after every iteration with its record.

    Returns
    -------
    OptimizationResult, with the properties measured on the result. Its status is
    "converged" (hard residuals within tolerance and buildable: no fold, no non-convex
    quad, no line turning more than `max_line_turn`, within `max_deviation`, no
    degenerate star or collapsed edge: `fabplan.net.buildable`, `fabplan.net.folds`);
    "folded", "crumpled" (a dart or a line doubling back), "degenerate" (stars whose lines
    run together, or edges collapsed) or "off-design" (beyond `max_deviation`) when the
    residuals are within tolerance but the net is not buildable; "stagnated" or
    "iteration cap" (stopped short: the net is the best iterate, buildable and near the
    reference where one was reached). `message` says what stood in the way, where and
    what to try.

    Raises
    ------
    SolverError
        When handles ask for a net the constraints cannot reach (the message names the
        constraint families left unmet and their residuals), or the residuals are not
        finite.
    """
    check_limits(max_deviation, max_line_turn)
    limits = BuildLimits(max_line_turn_deg=max_line_turn, max_deviation=max_deviation,
                         deviation_vertices=deviation_vertices)
    handle_ids, targets = _handle_arrays(handles, mesh)
    held = np.union1d(np.asarray([] if fixed is None else fixed, dtype=np.int64), handle_ids)
    start = time.perf_counter()
    if reference is None and max_deviation is not None:
        reference = ReferenceSurface.from_mesh(mesh)

    def make(with_guards: bool, start_mesh: QuadMesh = mesh,
             start_reference: ReferenceSurface | None = reference,
             deviation: float | None = max_deviation) -> GuidedProjection:
        return build_solver(start_mesh, net, angle=angle, radius=radius, reference=start_reference,
                            fixed=held, settings=settings, fairness=fairness, coherent=coherent,
                            closeness=closeness, glide=glide, glide_boundary=glide_boundary,
                            surface_tolerance=surface_tolerance, extra=extra, guards=with_guards,
                            max_deviation=deviation, limits=limits)

    def judge(name: str, solver: GuidedProjection, deviation: float | None = max_deviation,
              stop: Stage | None = None) -> Attempt:
        return Attempt(name, solver, measure_buildable(
            mesh, solver.vertices, reference=solver.reference,
            limits=replace(limits, max_deviation=deviation)), stop)

    def attempt(name: str, solver: GuidedProjection) -> Attempt:
        return judge(name, solver, stop=_solve(solver, handle_ids, targets, progress))

    levels: list[dict] = []
    grid = _multilevel_grid(mesh, net, settings, plain=not (held.size or glide or extra or guards
                                                            or max_deviation is not None))
    attempts: list[Attempt] = []
    if grid is not None:
        if reference is None and (closeness or guards):
            reference = ReferenceSurface.from_mesh(mesh)
        fine = make(False, mesh, reference)
        levels = _solve_coarse_levels(fine, mesh, grid, lambda m: make(False, m, reference),
                                      progress)
        attempts.append(attempt("multilevel", fine))
    if not attempts or not attempts[0].succeeded:
        attempts.append(attempt("guards" if guards else "plain", make(bool(guards))))
    first = attempts[-1]
    unreachable = handle_ids.size and first.solver.status != "converged"
    if guards is None and first.needs_guards and not unreachable:
        # a start far from every net of the type: first the guards against folding and
        # crumpling, then the same two solves from a smoothed start, still pulled towards
        # the original
        attempts.append(attempt("guards", make(True)))
        if not attempts[-1].succeeded:
            base = first.solver.reference
            smooth = mesh.with_vertices(smoothed_vertices(mesh, held=held))
            attempts.append(attempt("smoothed start", make(False, smooth, base)))
            if not attempts[-1].succeeded:
                attempts.append(attempt("smoothed start with guards", make(True, smooth, base)))
    deviation = None
    if max_deviation is not None and not min(attempts, key=Attempt.rank).succeeded \
            and not unreachable:
        found, deviation = _deviation_continuation(
            lambda limit: make(bool(guards), deviation=limit), judge, max_deviation,
            float(np.max(reference.distances(mesh.vertices), initial=0.0)) if reference is not None
            else 0.0, progress)
        attempts += found
    chosen = min(attempts, key=Attempt.rank)
    if deviation is not None and deviation["smallest_converged"] is not None:
        # a net of the type within a looser limit: the one to write, off the design
        chosen = found[0]
    solver, build, stop = chosen.solver, chosen.build, chosen.stop
    if handle_ids.size and solver.status != "converged":
        raise SolverError(f"the handles ask for a net that cannot be reached ({solver.status} after "
                          f"{len(solver.history) - 1} iterations{_stopped_at(stop)}): "
                          f"{describe_unmet(unmet_constraints(solver))}")
    result_mesh = mesh.with_vertices(solver.vertices, normals=solver_normals(solver))
    free = free_vertices(result_mesh)
    moved = np.zeros(result_mesh.vertex_count)
    # planar faces hold every corner, tips included: nothing is free to settle
    # (and a gliding net holds every vertex on the design)
    faces_held = any(c.name == "planar-faces" for c in solver.constraints)
    if settle_free is not None and free.any() and not faces_held and not glide:
        result_mesh, moved = settle_free_vertices(result_mesh, keep=held, step=settle_free)
        if moved.any():
            build = measure_buildable(mesh, result_mesh.vertices, reference=solver.reference,
                                      limits=limits)
    seconds = time.perf_counter() - start
    parameters = {"angle_deg": angle, "radius": radius, **solved_parameters(solver),
                  "coherent": coherent, "fixed_vertices": int(len(solver.fixed)),
                  "guards": any(isinstance(c, NormalCone) for c in solver.constraints),
                  "smoothed_start": chosen.name.startswith("smoothed"),
                  "free_vertices": {"count": int(free.sum()), "settled": bool(moved.any()),
                                    "largest_move": float(moved.max(initial=0.0))},
                  "handles": {int(i): t.tolist() for i, t in zip(handle_ids, targets, strict=True)},
                  "multilevel": {"levels": levels, "full_iterations": solver.accepted_steps}
                  if chosen.name == "multilevel" else None,
                  "max_line_turn_deg": max_line_turn, "max_deviation": max_deviation,
                  "deviation": deviation}
    status = _status(solver.status, build)
    return OptimizationResult(
        mesh=result_mesh,
        net=solver.net,
        parameters=parameters,
        status=status,
        iterations=solver.accepted_steps,
        seconds=seconds,
        linear_solver=solver.linear_solver,
        history=[h.as_dict() for h in solver.history],
        properties=measure_net(result_mesh, reference=solver.reference, limits=limits),
        message=_explain(solver, status, build, mesh, angle, attempts if len(attempts) > 1 else [],
                         glide=glide, deviation=deviation),
    )


# the statuses of a solve whose residuals are within tolerance: judged again on a part
_SOLVED = ("converged", "folded", "crumpled", "degenerate", "off-design")


def kept_faces(result: OptimizationResult, keep: np.ndarray, reference: ReferenceSurface,
               max_line_turn: float = 90.0, max_deviation: float | None = None
               ) -> OptimizationResult:
    """The part of a solved net on faces `keep` (f,) bool, measured and judged again on
    its own against `reference` (a net solved on a design continued past its edges, kept
    where the design is: `fabplan.layout.margin`). Vertices left without a face go; the
    others keep their order.

    Returns
    -------
    OptimizationResult, its status judged on the part (the solve's residuals hold for
    the whole net), its properties measured on the part, ``parameters["continued"]`` the
    faces solved and kept.
    """
    mesh = result.mesh
    keep = np.asarray(keep, bool)
    faces = [f for f, kept in zip(mesh.faces, keep, strict=True) if kept]
    used = np.unique(np.concatenate(faces)) if faces else np.zeros(0, np.int64)
    new_id = np.full(mesh.vertex_count, -1)
    new_id[used] = np.arange(len(used))
    part = QuadMesh(mesh.vertices[used], [new_id[f] for f in faces], name=mesh.name)
    limits = BuildLimits(max_line_turn_deg=max_line_turn, max_deviation=max_deviation)
    build = measure_buildable(part, reference=reference, limits=limits)
    status = _status("converged", build) if result.status in _SOLVED else result.status
    free = free_vertices(part)
    parameters = {**result.parameters,
                  "free_vertices": {"count": int(free.sum()), "settled": False,
                                    "largest_move": 0.0},
                  "continued": {"faces_solved": len(mesh.faces), "faces_kept": len(faces),
                                "vertices_solved": mesh.vertex_count}}
    message = "" if status == "converged" else (build.describe() if status in _SOLVED
                                                else result.message)
    return replace(result, mesh=part, parameters=parameters, status=status, message=message,
                   properties=measure_net(part, reference=reference, limits=limits),
                   boundary_panels=None)


def _multilevel_grid(mesh: QuadMesh, net: str, settings: SolverSettings | None, *,
                     plain: bool) -> np.ndarray | None:
    """The grid coordinates (`fabplan.solve.multilevel.grid_indices`) of a net of type `net`
    that takes the multilevel start under `settings`, or None for a plain solve. `plain`
    says that nothing else of the solve stands in the way (held vertices, handles,
    gliding, guards or extra families do; so do an S*-net's normals)."""
    wanted = (settings or SolverSettings()).multilevel
    if not plain or wanted is False or (wanted is None
                                        and mesh.vertex_count < MULTILEVEL_MIN_VERTICES):
        return None
    if get_net(net).dual:
        return None
    grid = grid_indices(mesh)
    if grid is None or min(len(coarse_lines(m)) for m in grid.shape) < MIN_COARSE_LINES:
        return None
    if wanted is None and fine_roughness(mesh, grid) > MAX_FINE_ROUGHNESS:
        return None
    return grid


def _solve_coarse_levels(fine: GuidedProjection, mesh: QuadMesh, grid: np.ndarray,
                         make: Callable[[QuadMesh], GuidedProjection],
                         progress: Callable[[IterationRecord], None] | None,
                         params: tuple[np.ndarray, np.ndarray] | None = None) -> list[dict]:
    """Solve the coarse net of a grid patch (itself from its own coarse net while that has
    at least `MULTILEVEL_MIN_VERTICES` vertices) and start `fine` from its prolonged
    solution. `params` are the parameters of the lines of `grid` (default: where they
    lie on `mesh`, `fabplan.solve.multilevel.line_parameters`).

    Returns one record per coarse level solved, the coarsest first: vertices, accepted
    iterations, status and seconds.
    """
    t0 = time.perf_counter()
    if params is None:
        params = line_parameters(mesh.vertices, grid)
    coarse_mesh, rows, cols = coarse_grid_net(mesh, grid)
    coarse = make(coarse_mesh)
    levels: list[dict] = []
    # a coarse net below that size is solved plainly: the coarser its lines, the farther
    # its solution from the full net's
    if coarse_mesh.vertex_count >= MULTILEVEL_MIN_VERTICES \
            and min(len(coarse_lines(len(rows))), len(coarse_lines(len(cols)))) >= MIN_COARSE_LINES:
        coarse_grid = np.arange(coarse_mesh.vertex_count).reshape(len(rows), len(cols))
        levels = _solve_coarse_levels(coarse, coarse_mesh, coarse_grid, make, progress,
                                      (params[0][rows], params[1][cols]))
    def tell(record: IterationRecord) -> None:
        record.coarse_vertices = coarse_mesh.vertex_count
        if progress is not None:
            progress(record)

    _solve(coarse, np.zeros(0, dtype=np.int64), np.zeros((0, 3)), tell)
    pattern_cache.discard(coarse.pattern.key)     # room for the full net's
    start_from_coarse(fine, coarse, prolong_vertices(coarse.vertices, grid, rows, cols, params))
    levels.append({"vertices": coarse_mesh.vertex_count, "iterations": coarse.accepted_steps,
                   "status": coarse.status, "seconds": time.perf_counter() - t0})
    return levels


@dataclass
class Attempt:
    """One solve of `optimize`: the plain one, or a retry after it folded."""

    name: str                   # "plain", "guards", "smoothed start", ...
    solver: GuidedProjection
    build: BuildReport          # measured on the net it ends with (its folds too)
    stop: Stage | None          # the handle stage its continuation gave up at, if it did

    @property
    def folds(self) -> FoldReport:
        return self.build.folds

    @property
    def succeeded(self) -> bool:
        """Converged, buildable and without degenerate stars or collapsed edges."""
        return self.solver.status == "converged" and self.build.buildable \
            and not self.folds.degenerate

    @property
    def needs_guards(self) -> bool:
        """Folded, crumpled or degenerate: what the guards and a smoothed start are for."""
        return self.folds.folded or self.build.crumpled or self.folds.degenerate

    def rank(self) -> tuple:
        """Sort key: buildable first (no fold, then no dart or sharp turn, then within the
        deviation limit), then without degenerate stars, then converged, then by hard
        residual."""
        history = self.solver.history
        hard = history[-1].hard_residual if history else np.inf
        return (self.folds.folded, self.build.crumpled, self.build.off_design,
                self.folds.degenerate, self.solver.status != "converged", hard)

    def outcome(self) -> str:
        """A few words: how this solve ended."""
        return _status(self.solver.status, self.build)


def _status(solver_status: str, build: BuildReport) -> str:
    """The status of a result: the solver's, or for a net within tolerance what keeps it
    from being built."""
    if solver_status != "converged":
        return solver_status
    if build.folds.folded:
        return "folded"
    if build.crumpled:
        return "crumpled"
    if build.folds.degenerate:
        return "degenerate"
    if build.off_design:
        return "off-design"
    return "converged"


def check_limits(max_deviation: float | None, max_line_turn: float) -> None:
    """Refuse a deviation limit or a line-turn limit no net can keep to."""
    if max_deviation is not None:
        OPTIONS["--max-deviation"].check(max_deviation)
    OPTIONS["--max-line-turn"].check(max_line_turn)


# a deviation limit the net type cannot keep to is approached from a loose one: limits
# shrinking by this factor, from the first at least this many times the asked one (and
# the start's own distance), in at most this many stages; then the smallest limit met is
# narrowed down by this many bisections between it and the first one missed
DEVIATION_FACTOR, DEVIATION_START, DEVIATION_STAGES, DEVIATION_BISECTIONS = 2.0, 32.0, 8, 2


def _deviation_continuation(make: Callable[[float], GuidedProjection],
                            judge: Callable[[str, GuidedProjection, float], Attempt],
                            limit: float, start_distance: float,
                            progress: Callable[[IterationRecord], None] | None
                            ) -> tuple[list[Attempt], dict]:
    """Tighten a deviation limit from a loose one towards `limit` (model units), each
    stage continuing from the net of the one before, until a stage does not converge
    buildable within its limit.

    Returns the attempt at the smallest limit the net converged buildable to (or, when
    none did, the first stage's), judged by `judge(name, solver, limit)`, and a record:
    the limits tried, and the smallest at which the net converged (None when none did).
    """
    loosest = max(limit * DEVIATION_START, 1.5 * start_distance)
    stages = int(min(DEVIATION_STAGES, np.ceil(np.log(loosest / limit) / np.log(DEVIATION_FACTOR))))
    limits = [limit * (loosest / limit) ** (k / stages) for k in range(stages, -1, -1)]
    solver = make(limits[0])
    bound = next(c for c in solver.constraints if isinstance(c, DeviationBound))
    tried: list[float] = []
    met: tuple[float, np.ndarray] | None = None
    missed: float | None = None
    for k, value in enumerate(limits):
        bound.limit = value
        if k:
            solver.restart_soft_terms()
        solver.run(callback=progress)
        tried.append(value)
        if not judge("", solver, value).succeeded:
            missed = value
            break
        met = (value, solver.state.x.copy())
    for _ in range(DEVIATION_BISECTIONS if met is not None and missed is not None else 0):
        assert met is not None and missed is not None
        # halfway (in the log) between the smallest limit met and the first missed, from
        # the net that met it
        value = float(np.sqrt(met[0] * missed))
        solver.state.x[:] = met[1]
        bound.limit = value
        solver.restart_soft_terms()
        solver.run(callback=progress)
        tried.append(value)
        if judge("", solver, value).succeeded:
            met = (value, solver.state.x.copy())
        else:
            missed = value
    if met is not None and met[0] != tried[-1]:
        # back to the net that met the smallest limit (the next stage moved the solver on)
        bound.limit = met[0]
        solver.state.x[:] = met[1]
        solver.status = "converged"
    smallest = None if met is None else met[0]
    name = f"continuation to {smallest:.4g}" if smallest is not None else "continuation"
    record = {"limit": limit, "tried": tried, "smallest_converged": smallest}
    return [judge(name, solver, limit)], record


# a prescribed angle this far (degrees) from the start's is reached in stages
CONTINUATION_STEP_DEG = 10.0
# a prescribed Meusnier radius more than this factor from the start's (or less than its
# inverse) is reached in stages, each this factor at most from the one before
CONTINUATION_RADIUS_FACTOR = 1.5
# at most this many stages for the angle and radius together (and 10 for the handles)
MAX_STAGES = 12
# each stage but the last is solved to this tolerance, in at most this many iterations
STAGE_TOLERANCE, STAGE_ITERATIONS = 1e-4, 25


@dataclass
class Stage:
    """One stage of a continuation: what it sets, and how far along the way it is.

    Attributes
    ----------
    apply : sets the stage's targets on the solver.
    kind : "targets" (the prescribed angle and radius), "handles" or "" (a plain solve).
    step, steps : the stage's number (from 1) among the stages of its kind.
    """

    apply: Callable[[], None]
    kind: str = ""
    step: int = 1
    steps: int = 1


def _solve(solver: GuidedProjection, handle_ids: np.ndarray, targets: np.ndarray,
           progress: Callable[[IterationRecord], None] | None) -> Stage | None:
    """Run the solver; a far target (an angle, a radius or handles far from the start) is
    moved there in stages, each solved to a loose tolerance, the last to the full one.

    Returns None when every stage ran, or the handle stage that could not be solved: the
    stages after it move the handles farther still, so solving them would only spend the
    time of a longer give-up.
    """
    stages = _continuation_stages(solver, handle_ids, targets)
    final = solver.settings
    k, stop = 0, None
    while k < len(stages):
        stages[k].apply()
        last = k == len(stages) - 1
        solver.settings = final if last else replace(
            final, tolerance=max(final.tolerance, STAGE_TOLERANCE),
            max_iterations=min(final.max_iterations, STAGE_ITERATIONS))
        if k:
            solver.restart_soft_terms()
        status = solver.run(callback=progress)
        if status == "converged" or last:
            k += 1
        elif stages[k].kind == "handles":
            stop = stages[k]
            break
        else:
            # a target stage out of reach: the ones between it and the last are farther
            # still, so the last (the real targets) is solved right away
            k = len(stages) - 1
    solver.settings = final
    return stop


def _continuation_stages(solver: GuidedProjection, handle_ids: np.ndarray,
                        targets: np.ndarray) -> list[Stage]:
    """The stages of a solve: the prescribed angle moved from the start's in steps of at
    most `CONTINUATION_STEP_DEG` and the prescribed Meusnier radius in factors of at most
    `CONTINUATION_RADIUS_FACTOR`, together; then the handles moved in steps of at most
    one mean edge."""
    moves: list[tuple[Callable[[float], None], int]] = []   # (set at fraction t, steps)
    angle = next((c for c in solver.constraints
                  if isinstance(c, ConstantAngle) and c.cosine is not None), None)
    if angle is not None and angle.cosine is not None:
        goal = float(np.degrees(np.arccos(np.clip(angle.cosine, -1.0, 1.0))))
        here = float(np.degrees(np.median(intersection_angles(solver.state.X, solver.state.stars))))

        def set_angle(t: float, family: ConstantAngle = angle) -> None:
            family.cosine = float(np.cos(np.radians(here + (goal - here) * t)))

        moves.append((set_angle, int(np.ceil(abs(goal - here) / CONTINUATION_STEP_DEG))))
    radius = next((c for c in solver.constraints if isinstance(c, ConstantCurvature)
                   and c.curvature is not None and c.curvature != 0.0), None)
    if radius is not None and radius.curvature is not None and "sphere" in solver.state.blocks:
        moves.append(_curvature_move(radius, radius.curvature,
                                     float(np.median(2 * solver.variable("sphere")[:, 0]))))
    stages: list[Stage] = []
    count = min(MAX_STAGES, max([1] + [steps for _, steps in moves]))
    if moves and count > 1:
        for i in range(1, count + 1):
            def apply(t: float = i / count) -> None:
                for move, _ in moves:
                    move(t)
            stages.append(Stage(apply, "targets", i, count))
    if handle_ids.size:
        begin = solver.vertices[handle_ids]
        far = float(np.linalg.norm(targets - begin, axis=1).max()) / solver.length_scale
        count = int(min(10, max(1, np.ceil(far))))
        for i in range(1, count + 1):
            def place(t: float = i / count) -> None:
                solver.set_vertices(handle_ids, begin + t * (targets - begin))
            stages.append(Stage(place, "handles", i, count))
    return stages or [Stage(lambda: None)]


def _curvature_move(family: ConstantCurvature, goal: float,
                    here: float) -> tuple[Callable[[float], None], int]:
    """Set the prescribed normal curvature (normalized units) at a fraction of the way from
    the start's median to the goal, and the number of steps the way needs: geometric steps
    (the radius changes by the same factor in each) when both have one sign, else equal
    steps, each at most what a factor `CONTINUATION_RADIUS_FACTOR` takes near the goal."""
    log_factor = np.log(CONTINUATION_RADIUS_FACTOR)
    if here * goal > 0:
        ratio = goal / here
        steps = int(np.ceil(abs(np.log(ratio)) / log_factor - 1e-9))

        def move(t: float) -> None:
            family.curvature = goal if t >= 1 else float(here * ratio ** t)
    else:     # flat, or curved the other way: no geometric path
        steps = int(np.ceil(abs(goal - here) / (abs(goal) * (1 - 1 / CONTINUATION_RADIUS_FACTOR))))

        def move(t: float) -> None:
            family.curvature = goal if t >= 1 else float(here + (goal - here) * t)
    return move, steps


def _stopped_at(stage: Stage | None) -> str:
    """Where a handle continuation gave up, for the message (empty when it had one step)."""
    if stage is None or stage.steps < 2:
        return ""
    return (f", at step {stage.step} of {stage.steps} towards them; the steps beyond it "
            "were not tried")


def _explain(solver: GuidedProjection, status: str, build: BuildReport, start: QuadMesh,
             angle: float | None, attempts: list[Attempt], *, glide: bool = False,
             deviation: dict | None = None) -> str:
    """One line: what stood in the way of a converged net, where, and what to try;
    `attempts` are the solves tried when there were more than one; with `glide` the start
    is a layout's lattice on its design, not the user's net; `deviation` the record of a
    deviation limit's continuation."""
    if status == "converged":
        return ""
    folds = build.folds
    parts = []
    if status in ("folded", "degenerate", "crumpled", "off-design"):
        parts.append(f"the constraints are met but {_obstacles(build)}")
    else:
        unmet = describe_unmet(unmet_constraints(solver))
        parts.append(f"stopped ({status}) with {unmet or 'residuals above the tolerance'}")
        best = solver.best
        if best is not None and best.admissible and build.buildable and not folds.degenerate:
            parts.append("the net written is the best iterate, buildable (no fold, dart or line "
                         "doubling back)")
        if best is not None and best.iteration <= solver.run_start:
            parts.append("no step improved on the start: it may be far from any net of this "
                         "type, or the type may not exist on this surface")
        if not build.buildable or folds.degenerate:
            parts.append(f"on the net written {_obstacles(build)}")
    if deviation is not None and build.off_design:
        smallest = deviation["smallest_converged"]
        loosest = deviation["tried"][0] if deviation["tried"] else None
        if smallest is not None:
            parts.append(f"tightening the limit from {loosest:.4g} step by step, the net converged "
                         f"buildable down to a limit of {smallest:.4g} (the smallest found): give "
                         f"--max-deviation {smallest:.4g} or more, or another net type")
        elif loosest is not None:
            parts.append(f"tightening the limit from {loosest:.4g} step by step, no limit gave a "
                         "converged buildable net (none found): this net type may not fit the "
                         "reference; try another net type or a finer net")
    if attempts:
        tried = ", ".join(f"{a.name} {a.outcome()}" for a in attempts)
        written = next(a.name for a in attempts if a.solver is solver)
        parts.append(f"tried {len(attempts)} solves ({tried}); the net written is the {written} one")
        start_folds = measure_folds(start, reference=solver.reference)
        if start_folds.folded and glide:
            parts.append(f"the layout's lattice folds there ({start_folds.describe()}): "
                         "another panel size or net type may avoid it")
        elif glide:
            parts.append("the layout is too far from any net of this type on this design for "
                         "a buildable one near it: try another panel size or net type")
        elif start_folds.folded:
            parts.append(f"the input itself folds ({start_folds.describe()}): repair or smooth it")
        elif not build.off_design or build.crumpled or folds.folded:
            parts.append("the input is too far from any net of this type for a buildable one "
                         "near it: smooth it, or lay a net out on its design with `fabplan layout`")
    if build.crumpled and not attempts:
        parts.append("try the guards from the start (--guards), a smoother input, or "
                     "`fabplan layout` on the design")
    if angle is not None and len(start.stars):
        here = float(np.degrees(np.median(intersection_angles(start.vertices,
                                                              canonical_stars(start.vertices,
                                                                              start.stars)))))
        gap = min(abs(here - angle), abs(180.0 - here - angle))
        if gap > 15.0:
            parts.append(f"the requested angle is {gap:.0f} deg from the start's ({here:.0f} deg); "
                         "try `fabplan layout` on the design, which starts from the right "
                         "directions")
    return "; ".join(parts)


def _obstacles(build: BuildReport) -> str:
    """What keeps a net from being built, with its degenerate stars and collapsed edges."""
    said = [build.describe()]
    if build.folds.degenerate and not build.folds.folded:
        said.append(build.folds.describe())
    return "; ".join(p for p in said if p)


#: how far a handle may move a vertex from the net's bounding box, in net extents
HANDLE_REACH = 10.0


def _handle_arrays(handles: dict | None, mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray]:
    if not handles:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    ids = _vertex_ids(list(handles), mesh, "--handle")
    targets = np.array([np.asarray(handles[i], dtype=np.float64) for i in handles]).reshape(-1, 3)
    if not np.isfinite(targets).all():
        k = int(np.flatnonzero(~np.isfinite(targets).all(axis=1))[0])
        raise InputError(f"--handle {ids[k]}:{','.join(f'{c:g}' for c in targets[k])}: the target "
                         "must be finite coordinates")
    # a handle moves a vertex within the net's reach: farther than this many times the
    # net's extent from its bounding box is a typing or unit mistake
    low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    extent = float(np.linalg.norm(high - low))
    # along the farthest axis: a norm of 1e300 would overflow
    away = np.maximum(np.maximum(low - targets, targets - high), 0.0).max(axis=1)
    far = np.flatnonzero(away > HANDLE_REACH * extent)
    if far.size:
        k = far[0]
        raise InputError(f"--handle {ids[k]}:{','.join(f'{c:g}' for c in targets[k])}: the target "
                         f"lies {away[k]:.3g} from the net, more than {HANDLE_REACH:g} times its "
                         f"extent ({extent:.4g} model units, the diagonal of its bounding box)")
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
