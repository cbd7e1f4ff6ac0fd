"""Interactive editing of a net with handles (task B of the paper, section 3).

A `NetEditor` keeps one solver alive: the pattern of the normal equations and the
symbolic factorization are computed once, every drag step runs one iteration, and a
release runs a few more, as in the paper's editing loop (section 4.5). Another editor with
the same handles on the same net takes the pattern from `fabplan.solve.pattern`'s cache.

`NetEditor.solve_drag` is the live editor's step (`fabplan edit`): it iterates until the
net is converged within a budget, and keeps the last good net when the solve fails, folds
or crumples, saying why and where (`DragResult`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ..errors import SolverError
from ..net.buildable import crumpled, measure_buildable
from ..net.folds import measure_folds
from ..net.geometry import canonical_stars, fit_star_spheres
from ..net.mesh import QuadMesh
from .attempts import describe_unmet, unmet_constraints
from .constraints import DisplacementFairness
from .net_types import get_net
from .optimize import build_solver, solved_parameters, solver_normals
from .reference import ReferenceSurface
from .solver import IterationRecord, SolverSettings

__all__ = ["NetEditor", "DragResult", "DRAG_STATUSES", "falloff_move"]

#: what `NetEditor.solve_drag` says of a solve: only "converged" is taken
DRAG_STATUSES = ("converged", "folded", "crumpled", "not converged", "failed")
#: iteration records a long session's solver keeps (see `NetEditor.solve_drag`)
_HISTORY_KEPT = 200
#: failure places listed at most (vertex ids, worst first)
_WHERE_LISTED = 50


@dataclass
class DragResult:
    """The outcome of one `NetEditor.solve_drag`.

    Attributes
    ----------
    status : one of `DRAG_STATUSES`: ``converged`` (every hard residual within the
        tolerance, no fold, no crumpled face or line), ``folded`` or ``crumpled``
        (converged, but faces turned over, or a dart or a line doubling back),
        ``not converged`` (the budget ran out or the solve stagnated), ``failed`` (the
        solve broke down: non-finite residuals).
    residual : the largest hard residual the solve ended with, in mean edges of the
        net the editor was built on (normalized units of the solver).
    iterations : iterations run; seconds : wall time of the solve and its checks.
    message : what stood in the way, in one line ("" when converged).
    where : (k,) int, vertex ids where it fails, the worst first (at most 50): the
        vertices of flipped faces and fold edges, of non-convex faces and sharp line
        turns, or the star centres whose sphere is missed by more than the tolerance.
    predicted : whether the solve started from the extrapolated net (see `solve_drag`).
    """

    status: str
    residual: float
    iterations: int
    seconds: float
    message: str = ""
    where: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    predicted: bool = False

    @property
    def accepted(self) -> bool:
        """The editor's net is the solved one (else it is the last good one)."""
        return self.status == "converged"

    def to_json(self) -> dict:
        return {"status": self.status, "accepted": self.accepted, "residual": self.residual,
                "iterations": self.iterations, "seconds": self.seconds,
                "message": self.message, "where": [int(i) for i in self.where],
                "predicted": self.predicted}


def falloff_move(points: np.ndarray, handles: np.ndarray, moves: np.ndarray,
                 radius: float) -> np.ndarray:
    """The move of points that follow handles with a smooth falloff.

    Parameters
    ----------
    points : (m, 3) float; handles : (h, 3) float, where the handles are; moves : (h, 3)
        float, how they move; radius : where the following ends (model units).

    Returns
    -------
    (m, 3) float: each point moves as its nearest handle, times ``(1 - (d / radius)^2)^2``
    at distance ``d`` from it (0 beyond `radius`).

    Examples
    --------
    >>> falloff_move(np.array([[0.0, 0, 0], [0.5, 0, 0], [2, 0, 0]]), np.zeros((1, 3)),
    ...              np.array([[0.0, 0, 1]]), 1.0)[:, 2].tolist()
    [1.0, 0.5625, 0.0]
    """
    d = np.linalg.norm(points[:, None, :] - handles[None, :, :], axis=2)     # (m, h)
    nearest = np.argmin(d, axis=1)
    r = d[np.arange(len(points)), nearest] / radius
    weight = np.where(r < 1.0, (1.0 - r * r) ** 2, 0.0)
    return weight[:, None] * moves[nearest]


class _OutOfTime(Exception):
    """Raised by the iteration callback when a drag's time budget is spent."""


class NetEditor:
    """Move handle vertices of a net and keep it a net of its type.

    Parameters
    ----------
    mesh : the net to edit (normally already optimized).
    net : net type name (see `fabplan.nets.NETS`).
    handles : (h,) int, the vertices the user drags; they are held where they are put.
    angle, radius, fixed, settings, coherent, reference : as in `fabplan.optimize`.
    smooth : whether drags may ask for the fairness of their move (`solve_drag`'s
        `smooth`; it adds a family to the solver).
    closeness : whether the solver's soft terms include closeness to the reference (a
        live editor leaves it out: it fades within the first drag anyway, and the net is
        meant to leave the reference).

    Examples
    --------
    >>> import fabplan
    >>> net = fabplan.QuadMesh.from_obj(fabplan.data_path("cmc1.obj"))
    >>> editor = NetEditor(net, "snet", handles=[120])
    >>> target = net.vertices[120] + [0.0, 0.0, 0.05]
    >>> _ = editor.drag({120: target})          # one iteration per drag step
    >>> editor.release()["converged"]           # converge on release
    True
    >>> bool((editor.vertices[120] == target).all())
    True
    """

    def __init__(self, mesh: QuadMesh, net: str, handles: npt.ArrayLike, *,
                 angle: float | None = None, radius: float | None = None,
                 fixed: npt.ArrayLike | None = None, settings: SolverSettings | None = None,
                 coherent: bool = False, reference: ReferenceSurface | None = None,
                 smooth: bool = False, closeness: bool = True) -> None:
        self.handles = np.unique(np.asarray(handles, dtype=np.int64))
        # the fairness of each drag's move (see `solve_drag`), when asked for
        self._smooth = DisplacementFairness() if smooth else None
        held = np.union1d(np.asarray([] if fixed is None else fixed, dtype=np.int64), self.handles)
        self._mesh = mesh
        self._dual = get_net(net).dual
        self.solver = build_solver(mesh, net, angle=angle, radius=radius, fixed=held,
                                   settings=settings, coherent=coherent, reference=reference,
                                   closeness=closeness,
                                   extra=() if self._smooth is None else (self._smooth,))
        self._free = np.setdiff1d(np.arange(mesh.vertex_count), held)
        # The solver's first run fixes what its families take from the net they first see
        # (the edge-collapse bounds, the admissible test's distance from the reference):
        # on the net as given, not on the start of the first drag, which a refused drag
        # would leave behind.
        self.solver.run(0)
        # the last accepted drag: the handles' move (h, 3) and the free vertices' (f, 3)
        self._last_move: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float, current vertex positions."""
        return self.solver.vertices

    @property
    def mesh(self) -> QuadMesh:
        """The current net."""
        return self._mesh.with_vertices(self.solver.vertices, normals=solver_normals(self.solver))

    def drag(self, targets: dict, iterations: int = 1) -> IterationRecord | None:
        """Put handles at new positions ({vertex id: (3,) float}) and run `iterations`."""
        ids = np.array(list(targets), dtype=np.int64)
        unknown = np.setdiff1d(ids, self.handles)
        if unknown.size:
            raise ValueError(f"vertex {unknown[0]} is not a handle of this editor")
        self.solver.set_vertices(ids, np.array([targets[i] for i in targets], dtype=np.float64))
        self.solver.run(iterations)
        return self.solver.history[-1] if self.solver.history else None

    def release(self, iterations: int | None = None) -> dict:
        """Iterate until converged (or `iterations` more, for a fixed interactive budget)
        and report whether the net type still holds with the handles where they are.

        Returns
        -------
        dict with ``converged`` (bool), ``status``, ``unmet`` ({family: residual} of the
        hard constraints above the tolerance), ``message`` and the net's ``parameters``.
        """
        status = self.solver.run(iterations)
        unmet = unmet_constraints(self.solver)
        return {
            "converged": not unmet,
            "status": status,
            "unmet": unmet,
            "message": "all constraints met" if not unmet else
                       f"cannot be met with the handles where they are: {describe_unmet(unmet)}",
            "parameters": solved_parameters(self.solver),
        }

    def solve_drag(self, targets: dict, *, max_iterations: int = 40,
                   max_seconds: float | None = None, influence: float = 0.0,
                   predict: bool = False, smooth: float = 0.0,
                   smooth_fade: float = 0.25) -> DragResult:
        """Put handles at new positions and iterate until the net is converged (the
        solver's tolerance, `SolverSettings.tolerance`, in mean edges) and buildable.

        A solve that does not converge within `max_iterations` or `max_seconds`, ends
        folded or crumpled, or breaks down leaves the editor at the net it had before
        (the last good net, handles included), and the result says why and where: its
        variables, the families' data and the soft terms' weights are as before the
        drag, so the next drag solves as it would have without the refused one.

        Parameters
        ----------
        targets : {vertex id: (3,) float}, handles and where they go (model units).
        max_iterations, max_seconds : the budget of the solve (None: no time limit).
        influence : radius (model units) over which the free vertices start by following
            the handles' move, fading smoothly to nothing (``(1 - (d / r)^2)^2`` of the
            move of the nearest handle at distance ``d``); the solve then corrects that
            start. Gauss-Newton alone moves the net as little as it can, around the
            handle only: a vertex pulled off the surface by more than about an edge
            becomes a spike with non-convex faces. 0: no such start.
        predict : start from the net extrapolated along the last accepted drag when the
            handles move on the same way (a steady drag): the free vertices move by the
            part of their last move that the handles repeat (instead of `influence`).
        smooth : the weight at the start of the solve of the fairness of the move from
            the net before the drag (`fabplan.solve.constraints.DisplacementFairness`; an
            editor built with ``smooth=True``): the net follows the handles as a thin plate,
            instead of by the smallest move, which bends the faces around a handle pulled
            off the surface into a spike. It fades by `smooth_fade` with every step and is
            gone below a thousandth of its start, so that the solve converges to the
            tolerance. 0: none.

        Returns
        -------
        DragResult
        """
        t0 = time.perf_counter()
        ids, goal = self._handle_targets(targets)
        solver, state = self.solver, self.solver.state
        if len(solver.history) > _HISTORY_KEPT:
            # the solver counts its accepted steps over its history: keep it short in a long
            # session, the soft terms as faded as they were
            faded = solver.soft_steps
            del solver.history[:]
            solver.restart_soft_terms(faded=faded)
        before_x = state.x.copy()
        before_data = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in state.data.items()}
        before = solver.vertices
        fair = self._smooth
        if fair is not None:    # the move's fairness, measured from the last good net
            fair.anchor, fair.weight = state.X.copy(), smooth
        soft_steps = solver.soft_steps       # a failed solve must not fade the soft terms
        predicted = self._start_free_vertices(ids, goal, before, predict, influence)
        solver.set_vertices(ids, goal)
        start = len(solver.history)
        where = np.zeros(0, np.int64)
        solved, message = self._run_within(max_iterations, max_seconds, t0, smooth, smooth_fade)
        status = "failed" if solved == "failed" else "converged"
        iterations = len(solver.history) - start
        residual = solver.history[-1].hard_residual if len(solver.history) > start else np.inf
        X = solver.vertices
        if status != "failed" and solved != "converged":
            status = "not converged"
            message = self._not_converged_message(solved, residual, max_iterations, max_seconds)
            where = self._missed_stars(X)
        elif status == "converged":
            status, message, where = self._buildable(X)
        if status == "converged":
            self._last_move = (ids, goal - before[ids], (X - before)[self._free])
        else:
            self._roll_back(before_x, before_data, ids, before[ids], soft_steps)
        where = np.asarray(where, dtype=np.int64)
        _, first = np.unique(where, return_index=True)
        return DragResult(status, float(residual), iterations, time.perf_counter() - t0, message,
                          where[np.sort(first)][:_WHERE_LISTED], predicted)

    def _run_within(self, max_iterations: int, max_seconds: float | None, t0: float,
                    smooth: float, smooth_fade: float) -> tuple[str, str]:
        """Run the solver within the budget of `solve_drag` (started at `t0`), fading the
        move's fairness as it goes: how the run ended (`GuidedProjection.run`, ``"time
        budget"`` or ``"failed"``) and the solver's message."""
        fair = self._smooth

        def budget(record: IterationRecord) -> None:
            if fair is not None and fair.weight:
                # faded, then gone: a soft term holds the solve off the tolerance
                fair.weight *= smooth_fade
                if fair.weight < 1e-3 * smooth:
                    fair.weight = 0.0
            if max_seconds is not None and time.perf_counter() - t0 > max_seconds:
                raise _OutOfTime

        message = ""
        try:
            solved = self.solver.run(max_iterations, callback=budget)
        except _OutOfTime:
            solved = "time budget"
        except SolverError as exc:
            solved, message = "failed", str(exc)
        if fair is not None:
            fair.weight = 0.0
        return solved, message

    def _roll_back(self, x: np.ndarray, data: dict, ids: np.ndarray, at: np.ndarray,
                   soft_steps: int) -> None:
        """Put the solver back where a refused drag found it: its variables `x`, the
        families' `data`, the handles `ids` at `at` (k, 3) and the soft terms faded by
        `soft_steps`; no move to repeat."""
        state = self.solver.state
        state.x[:] = x
        state.data = data
        self.solver.set_vertices(ids, at)
        self.solver.restart_soft_terms(faded=soft_steps)
        self._last_move = None

    def _handle_targets(self, targets: dict) -> tuple[np.ndarray, np.ndarray]:
        """The handles of `targets`, (k,) int in increasing order, and where they go,
        (k, 3) float; ValueError for a vertex that is no handle."""
        ids = np.array(sorted(targets), dtype=np.int64)
        unknown = np.setdiff1d(ids, self.handles)
        if unknown.size:
            raise ValueError(f"vertex {unknown[0]} is not a handle of this editor")
        goal = np.array([targets[int(i)] for i in ids], dtype=np.float64).reshape(len(ids), 3)
        return ids, goal

    def _start_free_vertices(self, ids: np.ndarray, goal: np.ndarray, before: np.ndarray,
                             predict: bool, influence: float) -> bool:
        """Move the free vertices to the start of the solve of `solve_drag` (the last move
        repeated, when `predict`, or the handles' move faded over `influence`); whether
        they moved."""
        solver = self.solver
        if predict and self._last_move is not None and self._free.size:
            moved, handle_move, free_move = self._last_move
            if np.array_equal(moved, ids):
                move = goal - before[ids]
                scale = float(np.sum(move * handle_move)) / max(float(np.sum(handle_move ** 2)), 1e-300)
                # only a drag going on the way it went: a reversal or a jump starts afresh
                if 0.0 < scale <= 2.0:
                    solver.set_vertices(self._free, before[self._free] + scale * free_move)
                    return True
        if influence > 0 and ids.size and self._free.size:
            solver.set_vertices(self._free, before[self._free] + falloff_move(
                before[self._free], before[ids], goal - before[ids], influence))
            return True
        return False

    def _not_converged_message(self, solved: str, residual: float, max_iterations: int,
                               max_seconds: float | None) -> str:
        """Why a solve that ended `solved` (`GuidedProjection.run`, or ``"time budget"``)
        did not converge, and which constraints it left unmet."""
        unmet = unmet_constraints(self.solver)
        why = {"time budget": f"the time budget of {max_seconds or 0:g} s ran out",
               "iteration cap": f"{max_iterations} iterations did not reach the tolerance",
               }.get(solved, "the solve stagnated")
        return (f"{why}: {describe_unmet(unmet) or f'residual {residual:.2e}'}; "
                "the handles ask for more than the net can follow")

    def _buildable(self, X: np.ndarray) -> tuple[str, str, np.ndarray]:
        """The status of a converged net `X` (``"converged"``, or ``"folded"`` or
        ``"crumpled"`` with why in words), and the vertices to show (empty when it holds)."""
        folds = measure_folds(self._mesh, X)
        if folds.folded:
            return "folded", folds.describe(), np.concatenate(
                [self._face_vertices(folds.flipped_faces), folds.fold_edges.ravel()])
        if crumpled(self._mesh, X, canonical_stars(X, self._mesh.stars)):
            report = measure_buildable(self._mesh, X, folds=folds)
            return "crumpled", report.describe(), np.concatenate(
                [report.sharp_turns, self._face_vertices(report.nonconvex_faces)])
        return "converged", "", np.zeros(0, np.int64)

    def _face_vertices(self, faces: np.ndarray) -> np.ndarray:
        """The vertex ids of the first listed `faces` (in their order)."""
        listed = np.asarray(faces, dtype=np.int64)[:_WHERE_LISTED]
        rank = np.full(len(self._mesh.face_sizes), -1)
        rank[listed] = np.arange(len(listed))
        corner_rank = rank[self._mesh.corner_faces]
        corners = np.flatnonzero(corner_rank >= 0)
        return self._mesh.face_indices[corners[np.argsort(corner_rank[corners], kind="stable")]]

    def _missed_stars(self, X: np.ndarray) -> np.ndarray:
        """(k,) int, centres of the stars whose sphere misses a vertex by more than the
        tolerance, the worst first (none for S*-nets, whose spheres touch planes)."""
        if self._dual or not len(self._mesh.stars):
            return np.zeros(0, np.int64)
        stars = canonical_stars(X, self._mesh.stars)
        miss = fit_star_spheres(X, stars).residual / self.solver.length_scale
        bad = np.flatnonzero(~(miss <= self.solver.settings.tolerance))
        return stars[bad[np.argsort(-np.nan_to_num(miss[bad], nan=np.inf))], 0][:_WHERE_LISTED]
