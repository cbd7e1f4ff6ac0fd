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
from ..net.folds import fold_edge_mask
from ..net.free_vertices import free_vertices, settle_free_vertices, undo_new_darts
from ..net.geometry import (
    canonical_stars,
    face_normals,
    fit_mannheim_spheres,
    fit_star_spheres,
    vertex_contact_normals,
)
from ..net.measure import measure_net
from ..net.mesh import QuadMesh
from .attempts import (
    Attempt,
    describe_unmet,
    deviation_continuation,
    explain_result,
    result_status,
    unmet_constraints,
)
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
from .handles import handle_arrays
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
from .stages import Stage, solve_in_stages, stopped_at

__all__ = [
    "optimize",
    "build_solver",
    "OptimizationResult",
    "boundary_path",
    "check_net_input",
    "kept_faces",
    "solved_parameters",
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
                bound.held_limit / state.length_scale:
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
            # an isogonal net's angle, said in (0, 90] as below
            parameters["angle_deg"] = float(np.degrees(np.arccos(abs(family.cosine))))
        if isinstance(family, ConstantCurvature) and family.curvature is not None:
            k = family.curvature / solver.length_scale
            parameters["radius"] = float(abs(1 / k)) if k != 0 else float("inf")
    if "cosine" in blocks:
        # the same net as the one of 180 - a with its families swapped: said in (0, 90]
        cosine = np.clip(abs(solver.variable("cosine")[0]), 0.0, 1.0)
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
    handle_ids, targets = handle_arrays(handles, mesh)
    held = np.union1d(np.asarray([] if fixed is None else fixed, dtype=np.int64), handle_ids)
    start = time.perf_counter()
    if reference is None and max_deviation is not None:
        reference = ReferenceSurface.from_mesh(mesh)
    solves = _Solves(mesh, net, dict(angle=angle, radius=radius, settings=settings,
                                     fairness=fairness, coherent=coherent, closeness=closeness,
                                     glide=glide, glide_boundary=glide_boundary,
                                     surface_tolerance=surface_tolerance, extra=extra),
                     held, limits, reference, max_deviation, handle_ids, targets, progress)
    grid = _multilevel_grid(mesh, net, settings, plain=not (held.size or glide or extra or guards
                                                            or max_deviation is not None))
    attempts, levels, unreachable = _solve_with_retries(solves, grid, guards,
                                                        closeness or bool(guards))
    deviation = None
    if max_deviation is not None and not min(attempts, key=Attempt.rank).succeeded \
            and not unreachable:
        found, deviation = deviation_continuation(
            lambda limit: solves.make(bool(guards), deviation=limit), solves.judge, max_deviation,
            float(np.max(reference.distances(mesh.vertices), initial=0.0)) if reference is not None
            else 0.0, progress)
        attempts += found
    chosen = min(attempts, key=Attempt.rank)
    if deviation is not None and deviation["smallest_converged"] is not None:
        # a net of the type within a looser limit: the one to write, off the design
        chosen = found[0]
    solver, stop = chosen.solver, chosen.stop
    if handle_ids.size and solver.status != "converged":
        raise SolverError(f"the handles ask for a net that cannot be reached ({solver.status} after "
                          f"{len(solver.history) - 1} iterations{stopped_at(stop)}): "
                          f"{describe_unmet(unmet_constraints(solver))}")
    result_mesh, build, free, moved = _settled(chosen, mesh, held, limits, settle_free, glide)
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
                  "deviation": deviation,
                  # the hard families a solve that stopped short left above the tolerance
                  "unmet": unmet_constraints(solver) if solver.status != "converged" else {}}
    status = result_status(solver.status, build)
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
        message=explain_result(solver, status, build, mesh, angle,
                               attempts if len(attempts) > 1 else [], glide=glide,
                               deviation=deviation),
    )


@dataclass
class _Solves:
    """How `optimize` builds, runs and judges each of its solves (they differ in their
    start, their guards and their deviation limit).

    Attributes
    ----------
    mesh : the user's start; every solve is judged against its combinatorics.
    net : the net type's name.
    options : the other `build_solver` keywords all solves share.
    held : (k,) int, the vertices held in place (fixed ones and handles).
    limits : what a buildable net keeps to.
    reference : the reference as given (or made for a deviation limit), else None.
    max_deviation : the deviation limit asked (model units), else None.
    handle_ids, targets : (h,) int and (h, 3) float, the handles and where they go.
    progress : called after every iteration with its record.
    """

    mesh: QuadMesh
    net: str
    options: dict
    held: np.ndarray
    limits: BuildLimits
    reference: ReferenceSurface | None
    max_deviation: float | None
    handle_ids: np.ndarray
    targets: np.ndarray
    progress: Callable[[IterationRecord], None] | None

    def make(self, with_guards: bool,
             start: tuple[QuadMesh, ReferenceSurface | None] | None = None,
             deviation: float | None = None) -> GuidedProjection:
        """A solver from `start`, a start net and the reference it is pulled to (default:
        the user's start and the reference given), held within `deviation` (default: the
        limit asked)."""
        start_mesh, start_reference = (self.mesh, self.reference) if start is None else start
        return build_solver(start_mesh, self.net, reference=start_reference, guards=with_guards,
                            max_deviation=self.max_deviation if deviation is None else deviation,
                            fixed=self.held, limits=self.limits, **self.options)

    def judge(self, name: str, solver: GuidedProjection, deviation: float | None = None,
              stop: Stage | None = None) -> Attempt:
        """The attempt `name` of `solver`, its net measured against `deviation` (default:
        the limit asked)."""
        limit = self.max_deviation if deviation is None else deviation
        return Attempt(name, solver, measure_buildable(
            self.mesh, solver.vertices, reference=solver.reference,
            limits=replace(self.limits, max_deviation=limit)), stop)

    def attempt(self, name: str, solver: GuidedProjection) -> Attempt:
        """Run `solver` in stages towards its targets and handles, and judge it."""
        return self.judge(name, solver, stop=solve_in_stages(solver, self.handle_ids, self.targets,
                                                             self.progress))


def _solve_with_retries(solves: _Solves, grid: np.ndarray | None, guards: bool | None,
                        needs_reference: bool) -> tuple[list[Attempt], list[dict], bool]:
    """The solves of `optimize` before any deviation continuation: from coarse levels when
    `grid` is given, then plainly (or with `guards`); a start that folds or crumples is
    solved again with the guards, then from a smoothed start without and with them.

    Returns the attempts in order, the coarse levels' records, and whether the handles
    were out of reach (no retry is tried then).
    """
    mesh, held = solves.mesh, solves.held
    levels: list[dict] = []
    attempts: list[Attempt] = []
    if grid is not None:
        reference = solves.reference
        if reference is None and needs_reference:
            reference = ReferenceSurface.from_mesh(mesh)
        fine = solves.make(False, (mesh, reference))
        levels = _solve_coarse_levels(fine, mesh, grid,
                                      lambda m: solves.make(False, (m, reference)), solves.progress)
        attempts.append(solves.attempt("multilevel", fine))
    if not attempts or not attempts[0].succeeded:
        attempts.append(solves.attempt("guards" if guards else "plain", solves.make(bool(guards))))
    first = attempts[-1]
    unreachable = bool(solves.handle_ids.size) and first.solver.status != "converged"
    if guards is None and first.needs_guards and not unreachable:
        # a start far from every net of the type: first the guards against folding and
        # crumpling, then the same two solves from a smoothed start, still pulled towards
        # the original
        attempts.append(solves.attempt("guards", solves.make(True)))
        if not attempts[-1].succeeded:
            base = first.solver.reference
            smooth = mesh.with_vertices(smoothed_vertices(mesh, held=held))
            attempts.append(solves.attempt("smoothed start", solves.make(False, (smooth, base))))
            if not attempts[-1].succeeded:
                attempts.append(solves.attempt("smoothed start with guards",
                                               solves.make(True, (smooth, base))))
    return attempts, levels, unreachable


def _settled(chosen: Attempt, mesh: QuadMesh, held: np.ndarray, limits: BuildLimits,
             settle_free: float | None, glide: bool
             ) -> tuple[QuadMesh, BuildReport, np.ndarray, np.ndarray]:
    """The net of the chosen solve with its free vertices settled (`optimize`'s
    `settle_free`), measured again when any moved.

    Returns the net, its build report, (n,) bool the free vertices and (n,) their moves
    (model units).
    """
    solver, build = chosen.solver, chosen.build
    result_mesh = mesh.with_vertices(solver.vertices, normals=solver_normals(solver))
    free = free_vertices(result_mesh)
    moved = np.zeros(result_mesh.vertex_count)
    # planar faces hold every corner, tips included: nothing is free to settle
    # (and a gliding net holds every vertex on the design)
    faces_held = any(c.name == "planar-faces" for c in solver.constraints)
    if settle_free is not None and free.any() and not faces_held and not glide:
        result_mesh, moved = settle_free_vertices(result_mesh, keep=held, step=settle_free)
        if moved.any():
            # a settled tip that turns a corner the wrong way stays where the solve left it
            X, moved, build = undo_new_darts(mesh, result_mesh.vertices, solver.vertices,
                                             moved, build, reference=solver.reference,
                                             limits=limits)
            result_mesh = result_mesh.with_vertices(X)
    return result_mesh, build, free, moved


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
    status = result_status("converged", build) if result.status in _SOLVED else result.status
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

    solve_in_stages(coarse, np.zeros(0, dtype=np.int64), np.zeros((0, 3)), tell)
    pattern_cache.discard(coarse.pattern.key)     # room for the full net's
    start_from_coarse(fine, coarse, prolong_vertices(coarse.vertices, grid, rows, cols, params))
    levels.append({"vertices": coarse_mesh.vertex_count, "iterations": coarse.accepted_steps,
                   "status": coarse.status, "seconds": time.perf_counter() - t0})
    return levels


def check_limits(max_deviation: float | None, max_line_turn: float) -> None:
    """Refuse a deviation limit or a line-turn limit no net can keep to."""
    if max_deviation is not None:
        OPTIONS["--max-deviation"].check(max_deviation)
    OPTIONS["--max-line-turn"].check(max_line_turn)
