"""The guided-projection solver (Algorithm 1): regularized Gauss-Newton on constraint families.

Every iteration linearizes all residuals, solves ``(J^T J + mu I) h = -J^T r`` and tries
the step. The step is taken only when it lowers the merit function, the weighted sum of
squares of all residuals (hard constraints and the current soft terms), by a fair share
of what the linearization predicts (Levenberg-Marquardt with a gain ratio): otherwise the
damping is raised and the step recomputed from the same factorization pattern. A step
that lowers the merit as predicted lets the damping fall back towards its base value, so
a solve that went well before goes the same way now. The solver keeps the best iterate
(judged by a caller's test, e.g. fold-free and near the design, then by the hard
residual) and returns to it when it stops short of the tolerance.

The sparsity pattern of the normal equations is fixed for the whole run: it is built once
from the structure of the variables (`fabplan.solve.pattern`; solvers of the same topology
and held set share it), analysed once, and each iteration only refills values (one
`np.add.at` into the linear solver's own buffer) and refactors numerically.
Coordinates are normalized (centroid at the origin, mean edge length 1) so that weights,
tolerances and the regularization mean the same on every net.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..net.geometry import canonical_stars
from . import kernels
from .constraints import Constraint, NetState, VariableBlocks
from .linalg import SparseSPDSolver
from .pattern import NormalPattern, normal_pattern, pattern_cache, pattern_key

if TYPE_CHECKING:
    from ..net.mesh import QuadMesh

__all__ = ["SolverSettings", "IterationRecord", "GuidedProjection"]


@dataclass
class SolverSettings:
    """Numbers that steer the solve (lengths in mean edges of the input net).

    Attributes
    ----------
    max_iterations : iteration cap.
    tolerance : converged when every hard residual is below this (mean edges for spheres,
        cosine for angles, curvature times mean edge for radii).
    epsilon : regularization of the normal equations at unit residual; keeps steps short
        in the directions the constraints leave free. It is scaled by the current hard
        residual (Levenberg-Marquardt with damping proportional to the residual), which
        keeps the convergence quadratic near a solution.
    fairness_weight, closeness_weight : initial row weights of the soft families.
    turning_fairness_weight, turning_fairness_fade : initial weight of the fairness rows
        held where lines turn (`fabplan.solve.constraints.Fairness`), and the factor it
        fades by with every step: more slowly than `fade`, so that it still pulls where a
        line starts to double back late in the solve.
    fade : factor applied to the soft weights after every step.
    stagnation : stop when the best hard residual has not improved by 10 % over this many
        iterations.
    backend : linear solver backend (see `fabplan.solve.linalg`).
    max_rejections : how many times one iteration may raise its damping (fourfold each
        time) for a step that lowers the merit function, before the solve stops as
        stagnated.
    watchdog : Gauss-Newton steps may raise the hard residuals for this many steps; when
        they have not come below their best by then, the solve returns to the best point
        and continues with steps that must lower the merit function.
    climb : a free Gauss-Newton step is refused at once when it raises the hard residuals'
        sum of squares beyond this factor of the best.
    multilevel : start a large grid-patch net from the solution of its coarse net (every
        second line of both families; `fabplan.solve.multilevel`). None (default): when the
        net has at least `fabplan.solve.multilevel.MULTILEVEL_MIN_VERTICES` vertices and
        its coarse net stands for it (`fabplan.solve.multilevel.MAX_FINE_ROUGHNESS`);
        True: whenever the net allows it; False: never. Nets that are no regular grid
        patch, and solves with held vertices, handles, gliding, guards or extra families,
        are solved plainly.
    """

    max_iterations: int = 50
    tolerance: float = 1e-10
    epsilon: float = 1e-3
    fairness_weight: float = 1e-3
    closeness_weight: float = 1e-2
    turning_fairness_weight: float = 1e-2
    turning_fairness_fade: float = 0.5
    fade: float = 0.1
    stagnation: int = 15
    backend: str = "auto"
    max_rejections: int = 12
    watchdog: int = 15
    climb: float = 1e8
    multilevel: bool | None = None


@dataclass
class IterationRecord:
    """What happened in one iteration; residuals are measured before its step."""

    iteration: int
    residuals: dict            # family name -> max |residual| (unweighted, normalized units)
    hard_residual: float
    step: float                # norm of the step (mean edges)
    seconds: float
    assembly_seconds: float = 0.0
    factor_seconds: float = 0.0
    solve_seconds: float = 0.0
    merit: float = 0.0         # weighted sum of squares before the step (hard and soft terms)
    rejected: int = 0          # trial steps rejected (damping raised) before this one
    damping: float = 0.0       # damping of the accepted step
    coarse_vertices: int = 0   # the coarse net's vertices, in a multilevel start's coarse solve

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class GuidedProjection:
    """Solve a set of constraint families on a quad mesh.

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh`, the starting net.
    constraints : list of `Constraint`, hard and soft families.
    fixed : (k,) int, vertices held at their positions.
    settings : `SolverSettings`.
    admissible : a test of an iterate (its `NetState`, after `prepare`): iterates that pass
        it are preferred as the best iterate (for example: no fold, near the design).

    The instance keeps its state between calls of `run`, so an interactive editor can run
    one iteration per drag step and reuse the symbolic factorization.
    """

    def __init__(self, mesh: QuadMesh, constraints: list[Constraint], *,
                 fixed: np.ndarray | None = None, settings: SolverSettings | None = None,
                 admissible: Callable[[NetState], bool] | None = None) -> None:
        self.mesh = mesh
        self.net = ""                # the net type's name, when a preset built the solver
        self.reference: Any = None   # the surface a preset measures closeness to
        self.constraints = list(constraints)
        self.settings = settings or SolverSettings()
        X = mesh.vertices
        self.length_scale = float(mesh.mean_edge_length)
        self.origin = X.mean(axis=0)
        stars = canonical_stars(X, mesh.stars)
        blocks = VariableBlocks()
        blocks.add("vertices", (mesh.vertex_count, 3))
        self.state = NetState(mesh=mesh, stars=stars, blocks=blocks, x=np.zeros(0),
                              length_scale=self.length_scale, origin=self.origin)
        for c in self.constraints:
            for name, shape in c.declare(self.state).items():
                blocks.add(name, shape)
        self.state.x = np.zeros(blocks.size)
        self.state.X[:] = (X - self.origin) / self.length_scale
        for c in self.constraints:
            c.initialize(self.state)
        self.fixed = np.unique(np.asarray([] if fixed is None else fixed, dtype=np.int64))
        self._held = X[self.fixed].copy()
        free = np.ones(blocks.size, bool)
        free[blocks.index("vertices")[self.fixed].ravel()] = False
        self.free = np.flatnonzero(free)
        self.history: list[IterationRecord] = []
        self._linear = SparseSPDSolver(self.settings.backend, unknowns=len(self.free))
        self._pattern: NormalPattern | None = None
        self._buffers: _AssemblyBuffers | None = None    # reused by every assembly
        self._kernels = kernels.compiled()   # the assembly's compiled sums, or None: numpy
        self._upper: sp.csr_matrix | None = None        # the normal equations, refilled
        self.status = "not started"
        self.admissible = admissible
        self.best: _Iterate | None = None    # the best iterate seen (see `run`)
        self._damping_scale = 1.0              # raised on rejected steps, >= 1
        self._fade_start = 0                   # accepted steps before the soft terms restart
        self._phase_start = 0                  # first record of the current phase
        self.run_start = 0                     # first record of the last `run`

    # -------------------------------------------------------------- results
    @property
    def linear_solver(self) -> str:
        """Name of the sparse backend solving the normal equations (`fabplan.linalg`)."""
        return self._linear.backend

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float, current vertex positions in model units (held vertices exactly as
        given, free of the normalization's rounding)."""
        X = self.state.X * self.length_scale + self.origin
        X[self.fixed] = self._held
        return X

    def variable(self, name: str) -> np.ndarray:
        """Current value of a variable block (normalized units)."""
        return self.state.blocks.view(self.state.x, name).copy()

    def set_vertices(self, ids: np.ndarray, positions: np.ndarray) -> None:
        """Move vertices (model units), e.g. handles dragged by a user."""
        ids, positions = np.asarray(ids), np.asarray(positions, dtype=np.float64)
        self.state.X[ids] = (positions - self.origin) / self.length_scale
        held = np.isin(ids, self.fixed)
        self._held[np.searchsorted(self.fixed, ids[held])] = positions[held]

    # -------------------------------------------------------------- assembly
    def _build_pattern(self) -> NormalPattern:
        """Fix the sparsity of the normal equations once for the whole run.

        Row ``i`` of ``J`` contributes ``J[i, p] J[i, q]`` to entry ``(p, q)`` of ``J^T J``;
        every product has its slot in the upper triangle (`fabplan.solve.pattern`), so each
        iteration assembles ``J^T J`` with a single `np.add.at` over all families, keeping
        exact zeros as entries (the factorization's symbolic analysis stays valid). A
        pattern built for the same columns and free variables before (another candidate
        on this topology, a solve with the same handles) is taken from `pattern_cache`.
        """
        state = self.state
        columns = [np.asarray(c.columns(state)) for c in self.constraints]
        key = pattern_key(columns, state.blocks, self.free)
        pattern = pattern_cache.get(key)
        if pattern is None:
            pattern = pattern_cache.put(normal_pattern(columns, state.blocks, self.free, key=key))
        return pattern

    @property
    def pattern(self) -> NormalPattern:
        """The fixed sparsity pattern of the normal equations (built by the first `run`)."""
        if self._pattern is None:
            raise SolverError("the solver has not been run yet: no sparsity pattern")
        return self._pattern

    def _assemble(self, jacobians: list, residuals: list, weights: list,
                  damping: float) -> tuple[sp.csr_matrix, np.ndarray]:
        """Upper triangle of ``J^T J + damping I`` (CSR) and the gradient ``J^T r`` of the
        weighted system (`jacobians` and `residuals` unweighted, one row weight per family).

        The matrix is one object for the whole run (its index arrays are the pattern's, its
        values the linear solver's buffer) and the per-family buffers are reused: an
        iteration only computes values.
        """
        pat = self.pattern
        nnz, nfree = pat.nnz, len(self.free)
        if self._buffers is None:
            self._buffers = _AssemblyBuffers.for_pattern(pat, self._linear.values(nnz),
                                                         products=self._kernels is None)
        buffers = self._buffers
        gradient = np.zeros(nfree + 1)
        if self._kernels is not None:
            self._assemble_compiled(jacobians, residuals, weights, gradient)
        else:
            self._assemble_numpy(jacobians, residuals, weights, gradient)
        buffers.data[pat.diagonal] += damping
        if self._upper is None:
            self._upper = sp.csr_matrix((buffers.data, pat.indices, pat.indptr),
                                        shape=(nfree, nfree))
            self._upper.data = buffers.data     # the buffer itself, not a view: no copy
        return self._upper, gradient[:nfree]

    def _assemble_compiled(self, jacobians: list, residuals: list, weights: list,
                           gradient: np.ndarray) -> None:
        """`_assemble`'s sums by the compiled kernels: the same terms in the same order as
        `_assemble_numpy`, without the buffer of all products."""
        pat, buffers, compiled = self.pattern, self._buffers, self._kernels
        assert buffers is not None and compiled is not None
        buffers.summed.fill(0.0)
        start = 0
        for f, J, r, w, columns in zip(pat.families, jacobians, residuals, weights,
                                       buffers.columns, strict=True):
            if J.size == 0:
                start += int(np.prod(f.shape))
                continue
            np.multiply(J.T, w, out=columns)                 # weighted, entry-major
            start = compiled.sum_products(columns, f.multiplicity, pat.slots, start,
                                          buffers.summed)
            compiled.sum_gradient(J, w, r, f.gradient_cols, gradient)
        if buffers.summed is not buffers.data:
            buffers.data[:] = buffers.summed[:pat.nnz]

    def _assemble_numpy(self, jacobians: list, residuals: list, weights: list,
                        gradient: np.ndarray) -> None:
        """`_assemble`'s sums in numpy: every product into one buffer, summed by one
        `np.add.at`, and the gradient by `np.bincount`."""
        pat, buffers = self.pattern, self._buffers
        assert buffers is not None
        nfree = len(self.free)
        start = 0
        for f, J, r, w, columns, entries in zip(pat.families, jacobians, residuals, weights,
                                                buffers.columns, buffers.entries, strict=True):
            out = buffers.products[start:start + int(np.prod(f.shape))].reshape(f.shape)
            start += out.size
            if J.size == 0:
                continue
            np.multiply(J, w if np.ndim(w) == 0 else w[:, None], out=entries)  # weighted
            np.copyto(columns, entries.T)                # and entry-major
            k, pair = len(columns), 0
            for i in range(k):     # entries of a row, not rows: k <= 16 broadcast multiplies
                np.multiply(columns[i], columns[i:], out=out[pair:pair + k - i])
                pair += k - i
            if f.multiplicity is not None:
                out *= f.multiplicity
            entries *= (w * r)[:, None]
            gradient += np.bincount(f.gradient_cols.ravel(), weights=entries.ravel(),
                                    minlength=nfree + 1)
        # summed in place, in the order of the products (as np.bincount would, without a
        # fresh array every iteration); products on held variables go to a last slot
        buffers.summed.fill(0.0)
        np.add.at(buffers.summed, pat.slots, buffers.products)
        if buffers.summed is not buffers.data:
            buffers.data[:] = buffers.summed[:pat.nnz]

    def _factor(self, upper: sp.csr_matrix, damping: float) -> None:
        """Factor, adding damping when rounding makes the matrix lose definiteness."""
        diagonal = self.pattern.diagonal
        for _ in range(4):
            try:
                self._linear.factor(upper)
                return
            except SolverError:
                upper.data[diagonal] += 100 * damping
                damping *= 101
        raise SolverError("the normal equations stay singular even with strong damping")

    def _stagnant(self, hard: float) -> bool:
        """No 10 % improvement of the best residual over the last `stagnation` iterations
        (of the current phase: free or monotone steps)."""
        window = self.settings.stagnation
        past = [h.hard_residual for h in self.history[self._phase_start:] if h.step > 0]
        if len(past) < window:
            return False
        return min(past[-window + 1:] + [hard]) > 0.9 * min(past[:-window + 1] or [np.inf])

    # -------------------------------------------------------------- iteration
    def _evaluate(self) -> _Evaluation:
        """Prepare every family at the current point and evaluate its residuals (m,) and
        Jacobian values (m, k), unweighted."""
        for c in self.constraints:
            c.prepare(self.state)
        residuals, jacobians, measured = [], [], {}
        for c in self.constraints:
            r, J = c.evaluate(self.state)
            residuals.append(np.asarray(r, dtype=np.float64))
            jacobians.append(np.asarray(J, dtype=np.float64))
            measured[c.name] = float(np.max(np.abs(r))) if len(r) else 0.0
        finite = all(np.isfinite(r).all() and np.isfinite(J).all()
                     for r, J in zip(residuals, jacobians, strict=True))
        return _Evaluation(residuals, jacobians, measured, finite)

    def soft_weights(self, steps: int) -> dict[str, float]:
        """Row weight of every soft family after `steps` accepted steps: they fade with
        every step (since the last `restart_soft_terms`)."""
        s = self.settings
        fade = s.fade ** max(steps - self._fade_start, 0)
        soft = {"fairness": s.fairness_weight, "closeness": s.closeness_weight}
        return {c.name: soft.get(c.name, 1.0) * fade for c in self.constraints if not c.hard}

    def _weights(self, steps: int) -> list:
        """Row weight of every family, in the order of `constraints`: a number, or (rows,)
        for a soft family that holds some of its rows (``held``, e.g. `Fairness` where
        lines turn), those rows' weight fading by `SolverSettings.turning_fairness_fade`;
        a soft family's own ``weight`` when it has one."""
        s = self.settings
        soft = self.soft_weights(steps)
        slow = s.turning_fairness_weight * s.turning_fairness_fade ** max(steps - self._fade_start, 0)
        weights: list = []
        for c in self.constraints:
            held = None if c.hard else c.held
            w = 1.0 if c.hard else soft.get(c.name, 1.0) if c.weight is None else c.weight
            weights.append(w if held is None or slow == 0 else w + slow * held)
        return weights

    def restart_soft_terms(self, faded: int = 0) -> None:
        """Give the soft terms their initial weights again (a new stage of a continuation:
        fairness and closeness guide it as they guided the first), or the weights they
        have after `faded` accepted steps (a solve that continues one on a coarse net)."""
        self._fade_start = self.accepted_steps - faded

    @property
    def soft_steps(self) -> int:
        """Accepted steps the soft terms have faded over (since `restart_soft_terms`)."""
        return self.accepted_steps - self._fade_start

    @property
    def accepted_steps(self) -> int:
        return sum(1 for h in self.history if h.step > 0)

    def _snapshot(self) -> _Iterate:
        data = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.state.data.items()}
        return _Iterate(self.state.x.copy(), data)

    def _restore(self, iterate: _Iterate) -> None:
        self.state.x[:] = iterate.x
        self.state.data = {k: (v.copy() if isinstance(v, np.ndarray) else v)
                           for k, v in iterate.data.items()}

    def _remember(self, hard: float, residuals: dict) -> None:
        """Keep the current iterate when it beats the best: admissible first, then by hard
        residual."""
        best = self.best
        if best is not None and best.admissible and hard >= best.hard:
            return      # cannot beat the best: spare the test (it runs every iteration)
        ok = True if self.admissible is None else bool(self.admissible(self.state))
        if best is None or (ok, -hard) > (best.admissible, -best.hard):
            self.best = self._snapshot()
            self.best.hard, self.best.admissible = hard, ok
            self.best.residuals, self.best.iteration = dict(residuals), len(self.history)

    def return_to_best(self) -> bool:
        """Go back to the best iterate seen; True when that moved the net."""
        if self.best is None or np.array_equal(self.best.x, self.state.x):
            return False
        self._restore(self.best)
        return True

    def run(self, max_iterations: int | None = None,
            callback: Callable[[IterationRecord], None] | None = None) -> str:
        """Iterate until converged, stagnant or at the cap; returns the status.

        Steps are Gauss-Newton steps as long as the hard residuals come below their best
        within `SolverSettings.watchdog` steps (a step may climb a little on its way: the
        constraints are far from linear). When they do not, the solve returns to the best
        point and goes on with steps that must lower the merit function (Levenberg-
        Marquardt with a gain ratio; see the module docstring). A solve that stops short of
        the tolerance ends at its best iterate: ``self.best`` says whether that iterate was
        admissible.

        Raises
        ------
        SolverError
            When the residuals at the start are not finite.
        """
        s = self.settings
        cap = s.max_iterations if max_iterations is None else max_iterations
        hard_index = [i for i, c in enumerate(self.constraints) if c.hard]
        if self._pattern is None:
            self._prepare()
        first = self.run_start = len(self.history)
        self.status = "iteration cap"
        self.best, self._damping_scale, self.monotone = None, 1.0, False
        current = self._evaluate()
        if not current.finite:
            raise SolverError(f"the solver diverged at iteration {len(self.history)}: "
                              "non-finite residuals")
        watch = (self._snapshot(), current.hard_merit(hard_index), 0)
        self._phase_start = len(self.history)
        while True:
            it = len(self.history)
            t0 = time.perf_counter()
            hard = max([current.measured[self.constraints[i].name] for i in hard_index], default=0.0)
            if not self.monotone:
                current, hard, watch = self._watch(current, hard, watch, hard_index)
            steps = self.accepted_steps
            weights = self._weights(steps)
            self._remember(hard, current.measured)
            merit = current.merit(weights)
            if hard <= s.tolerance or it - first >= cap or self._stagnant(hard):
                if hard <= s.tolerance:
                    self.status = "converged"
                elif it - first < cap:
                    self.status = "stagnated"
                self.history.append(IterationRecord(it, current.measured, hard, 0.0,
                                                    time.perf_counter() - t0, merit=merit))
                break
            # Damping proportional to the residual (stable far away, quadratic near the end),
            # but fading no faster than the soft terms: otherwise fairness and closeness take
            # long steps along the solution manifold that the linearization cannot follow.
            soft = s.fade ** max(steps - self._fade_start, 0) \
                if any(not c.hard for c in self.constraints) else 0.0
            base = max(s.epsilon * min(hard, 1.0), s.epsilon * soft, 1e-10)
            measured = current.measured
            ceiling = None if self.monotone else s.climb * watch[1]
            step = self._step(current, weights, merit, base, hard_index, ceiling)
            if step is None:
                self.status = "stagnated"        # no step lowers the merit function
                self.history.append(IterationRecord(it, current.measured, hard, 0.0,
                                                    time.perf_counter() - t0, merit=merit,
                                                    rejected=s.max_rejections))
                break
            current, record = step
            if not self.monotone:
                watch = (watch[0], watch[1], watch[2] + 1)
            record.iteration, record.residuals, record.hard_residual = it, measured, hard
            record.seconds = time.perf_counter() - t0
            self.history.append(record)
            if callback is not None:
                callback(record)
        if self.status != "converged":
            self.return_to_best()
        return self.status

    def _prepare(self) -> None:
        """The set-up of a first run: the families' fixed data, the pattern of the normal
        equations and the linear solver with its symbolic analysis."""
        for c in self.constraints:
            c.prepare(self.state)
        self._pattern = self._build_pattern()
        self._linear = SparseSPDSolver(self.settings.backend, unknowns=len(self.free),
                                       shared=self._pattern.shared)

    def _watch(self, current: _Evaluation, hard: float, watch: tuple, hard_index: list
               ) -> tuple[_Evaluation, float, tuple]:
        """The watchdog of the free steps: remember a new best point of the hard merit, or,
        when the steps climbed or crawled for too long, go back to the best and switch to
        monotone steps. `watch` is (snapshot, its hard merit, steps since).

        Returns the evaluation and largest hard residual to go on from, and the watch.
        """
        hard_merit = current.hard_merit(hard_index)
        if hard_merit < watch[1]:
            watch = (self._snapshot(), hard_merit, 0)
        elif watch[2] >= self.settings.watchdog or (hard > self.settings.tolerance
                                                    and self._stagnant(hard)):
            # the free steps climbed, or crawled, for too long: back to their best
            # point, and from there only steps that lower the merit function
            self._restore(watch[0])
            current, self.monotone = self._evaluate(), True
            self._phase_start = len(self.history)
            hard = max([current.measured[self.constraints[i].name] for i in hard_index],
                       default=0.0)
        return current, hard, watch

    def _step(self, current: _Evaluation, weights: list, merit: float, base: float,
              hard_index: list[int], ceiling: float | None
              ) -> tuple[_Evaluation, IterationRecord] | None:
        """Find the next step.

        With a `ceiling` (free steps), the Gauss-Newton step is taken when its hard
        residuals' sum of squares stays below the ceiling. Otherwise, and in the monotone
        phase, the damping is raised until a step lowers the merit function by a fair share
        of what the linearization predicts.

        Returns the evaluation at the new point and the iteration's record (the residuals
        in it are those before the step), or None when every trial failed.
        """
        s = self.settings
        t0 = time.perf_counter()
        damping = base * self._damping_scale
        upper, gradient = self._assemble(current.jacobians, current.residuals, weights, damping)
        t_assembly = time.perf_counter() - t0
        t_factor = t_solve = 0.0
        growth = 4.0            # each rejection raises the damping fourfold
        before = self._snapshot()
        for rejected in range(s.max_rejections + 1):
            t1 = time.perf_counter()
            self._factor(upper, damping)
            t2 = time.perf_counter()
            h = self._linear.solve(-gradient)
            t3 = time.perf_counter()
            t_factor += t2 - t1
            t_solve += t3 - t2
            # the step, then (past a free step) shorter ones along it: a kink of the merit
            # function (a one-sided barrier, a flipped orientation) stops the full step only
            for length in (1.0,) if rejected == 0 and ceiling is not None else (1.0, 0.5, 0.25):
                if not np.isfinite(h).all():
                    break
                self.state.x[self.free] += length * h
                trial = self._evaluate()
                if trial.finite and self._acceptable(
                        trial, weights, merit, damping, length * h, gradient, hard_index,
                        ceiling if rejected == 0 else None, length=length):
                    return trial, IterationRecord(
                        0, {}, 0.0, float(length * np.sqrt(_dot(h, h))), 0.0, t_assembly,
                        t_factor, t_solve, merit=merit, rejected=rejected, damping=damping)
                self._restore(before)
            raised = damping * growth
            upper.data[self.pattern.diagonal] += raised - damping
            damping = raised
            self._damping_scale *= growth
        self._restore(before)
        for c in self.constraints:      # back to the data of the point the solve ends at
            c.prepare(self.state)
        return None

    def _acceptable(self, trial: _Evaluation, weights: list, merit: float, damping: float,
                    h: np.ndarray, gradient: np.ndarray, hard_index: list[int],
                    ceiling: float | None, *, length: float = 1.0) -> bool:
        """Whether a trial step `h` (`length` times the solution of the damped system) is
        taken (see `_step`); adapts the damping scale."""
        if ceiling is not None:
            return trial.hard_merit(hard_index) <= ceiling
        # the decrease the linearization predicts for t h, h solving (J^T J + mu) h = -g:
        # -t g.h - t^2 h^T J^T J h / 2, with h^T J^T J h = -g.h - mu |h|^2 (here h is t h)
        full = h / length
        gh, hh = _dot(gradient, full), _dot(full, full)
        predicted = -length * gh + 0.5 * length * length * (gh + damping * hh)
        achieved = merit - trial.merit(weights)
        gain = achieved / predicted if predicted > 0 else (1.0 if achieved >= 0 else -1.0)
        if gain <= 1e-4:
            return False
        # a step the linearization predicted well lets the damping fall back towards its base
        if gain > 0.75:
            self._damping_scale = max(1.0, self._damping_scale / 4.0)
        elif gain < 0.25:
            self._damping_scale *= 2.0
        return True


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b`` in this thread: BLAS would split a long vector over its threads, and on
    a machine whose other core is busy every iteration waits for that thread (tens of ms
    at 30k vertices)."""
    return float(np.einsum("i,i->", a, b))


@dataclass
class _AssemblyBuffers:
    """Arrays an assembly fills, allocated once per solver (not shared: a pattern may be)."""

    products: np.ndarray       # (products,) every family's entry products (numpy path)
    columns: list              # per family (k, m): the weighted Jacobian, entry-major
    entries: list              # per family (m, k): weighted Jacobian times weighted residual
    data: np.ndarray           # (nnz,) the matrix's values: the linear solver's buffer
    summed: np.ndarray         # what the products are summed into: `data`, or (nnz + 1,)
                               # when some products fall on held variables (the last slot)

    @classmethod
    def for_pattern(cls, pattern: NormalPattern, data: np.ndarray, *,
                    products: bool = True) -> _AssemblyBuffers:
        """Buffers for `pattern`; `data`: the (nnz,) array the matrix's values go to;
        `products`: whether to hold every product (the numpy path; the compiled kernels sum
        them as they form them)."""
        shapes = [f.gradient_cols.shape for f in pattern.families]
        held = len(pattern.slots) > 0 and int(pattern.slots.max()) >= pattern.nnz
        return cls(np.empty(len(pattern.slots) if products else 0), [np.empty((k, m)) for m, k in shapes],
                   [np.empty((m, k)) for m, k in shapes], data,
                   np.empty(pattern.nnz + 1) if held else data)


@dataclass
class _Evaluation:
    """Unweighted residuals and Jacobians of every family at one point."""

    residuals: list
    jacobians: list
    measured: dict             # family name -> max |residual|
    finite: bool

    def merit(self, weights: list) -> float:
        """Half the weighted sum of squares of all residuals (a weight per family, or per
        row)."""
        return 0.5 * sum(w * w * _dot(r, r) if np.ndim(w) == 0 else _dot(w * r, w * r)
                         for w, r in zip(weights, self.residuals, strict=True))

    def hard_merit(self, hard_index: list[int]) -> float:
        """Half the sum of squares of the hard residuals (comparable across iterations)."""
        return 0.5 * sum(_dot(self.residuals[i], self.residuals[i]) for i in hard_index)


@dataclass
class _Iterate:
    """A copy of the solver's state: variables and per-iteration data."""

    x: np.ndarray
    data: dict
    hard: float = np.inf
    admissible: bool = False
    residuals: dict = field(default_factory=dict)   # family name -> max |residual|
    iteration: int = 0                               # its index in the history
