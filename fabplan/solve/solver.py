"""The guided-projection solver (Algorithm 1): regularized Gauss-Newton on constraint families.

Every iteration linearizes all residuals, solves ``(J^T J + eps I) h = -J^T r`` and steps.
The sparsity pattern of the normal equations is fixed for the whole run: it is analysed
once, and each iteration only refills values (one `np.bincount`) and refactors numerically.
Coordinates are normalized (centroid at the origin, mean edge length 1) so that weights,
tolerances and the regularization mean the same on every net.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..net.geometry import canonical_stars
from .constraints import Constraint, NetState, VariableBlocks
from .linalg import SparseSPDSolver

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
    fade : factor applied to the soft weights after every step.
    stagnation : stop when the best hard residual has not improved by 10 % over this many
        iterations.
    backend : linear solver backend (see `fabplan.linalg`).
    """

    max_iterations: int = 50
    tolerance: float = 1e-10
    epsilon: float = 1e-3
    fairness_weight: float = 1e-3
    closeness_weight: float = 1e-2
    fade: float = 0.1
    stagnation: int = 15
    backend: str = "auto"


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

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class _FamilyPattern:
    """Where one family's Jacobian entries land in the normal equations.

    A row with ``k`` entries gives the ``k (k + 1) / 2`` products of its entry pairs
    ``i <= j``; they are stored pair-major, ``(p, m)``, so that the pairs of entry ``i``
    come out of one broadcast multiply of column ``i`` with columns ``i..k-1``.
    """

    gradient_cols: np.ndarray  # (m, k) free-variable column of each entry, nfree if fixed
    shape: tuple               # (p, m): the family's block in the shared product buffer
    multiplicity: np.ndarray | None = None  # (p, m) 2 where a row repeats a variable


@dataclass
class _Pattern:
    families: list             # _FamilyPattern per constraint family
    indptr: np.ndarray         # upper triangle of J^T J + eps I, CSR (= lower, CSC)
    indices: np.ndarray
    diagonal: np.ndarray       # (nfree,) positions of the diagonal entries
    slots: np.ndarray          # all families' slots, concatenated
    products: np.ndarray       # buffer for all families' products, same length


def _rank(keys: np.ndarray, bound: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct keys and the position of every key among them.

    Parameters
    ----------
    keys : (n,) int64, values in ``[0, bound)``.
    bound : exclusive upper bound of the keys.

    Returns
    -------
    distinct : (u,) int64, the sorted distinct keys.
    position : (n,) int64, ``distinct[position] == keys``.

    Each key is packed with its index into one int64 and sorted (``np.sort`` is far
    faster than ``argsort`` or a search of tens of millions of keys); when key and index
    need more than 63 bits the keys are sorted in ranges of their high bits.

    Examples
    --------
    >>> distinct, position = _rank(np.array([7, 3, 7, 0]), 8)
    >>> distinct.tolist(), position.tolist()
    ([0, 3, 7], [2, 1, 2, 0])
    """
    keys = np.asarray(keys, dtype=np.int64)
    n = len(keys)
    index_bits = max(1, (n - 1).bit_length())
    key_bits = max(1, (int(bound) - 1).bit_length())
    low_bits = min(key_bits, 63 - index_bits)
    position = np.empty(n, dtype=np.int64)
    distinct, found = [], 0
    high = keys >> low_bits
    for part in range(int(high.max()) + 1 if n else 0):
        mine = np.flatnonzero(high == part) if low_bits < key_bits else slice(None)
        packed = (keys[mine] - (part << low_bits)) << index_bits
        packed |= np.arange(len(packed))
        packed.sort()
        low = packed >> index_bits
        new = np.empty(len(low), dtype=bool)
        new[:1] = True
        np.not_equal(low[1:], low[:-1], out=new[1:])
        starts = np.flatnonzero(new)
        rank = np.repeat(np.arange(found, found + len(starts)), np.diff(np.r_[starts, len(low)]))
        order = packed & ((1 << index_bits) - 1)
        if isinstance(mine, slice):
            position[order] = rank
        else:
            position[mine[order]] = rank
        distinct.append(low[starts] + (part << low_bits))
        found += len(starts)
    return (np.concatenate(distinct) if distinct else np.zeros(0, dtype=np.int64)), position


class GuidedProjection:
    """Solve a set of constraint families on a quad mesh.

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh`, the starting net.
    constraints : list of `Constraint`, hard and soft families.
    fixed : (k,) int, vertices held at their positions.
    settings : `SolverSettings`.

    The instance keeps its state between calls of `run`, so an interactive editor can run
    one iteration per drag step and reuse the symbolic factorization.
    """

    def __init__(self, mesh, constraints: list[Constraint], *, fixed=None,
                 settings: SolverSettings | None = None):
        self.mesh = mesh
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
        self._pattern: _Pattern | None = None
        self.status = "not started"

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
    def _build_pattern(self) -> _Pattern:
        """Fix the sparsity of the normal equations once for the whole run.

        Row ``i`` of ``J`` contributes ``J[i, p] J[i, q]`` to entry ``(p, q)`` of ``J^T J``;
        every product is mapped once to its slot in the upper triangle, so each iteration
        assembles ``J^T J`` with a single `np.bincount` over all families, keeping exact
        zeros as entries (the factorization's symbolic analysis stays valid).
        """
        state = self.state
        nfree = len(self.free)
        col_map = np.full(state.blocks.size, -1)
        col_map[self.free] = np.arange(nfree)
        families, pair_keys = [], []
        for c in self.constraints:
            cols = col_map[np.asarray(c.columns(state))]
            # J^T J is symmetric: the pairs p <= q of a row's entries fill its upper triangle
            first, second = np.triu_indices(cols.shape[1])
            cp, cq = cols.T[first], cols.T[second]            # (p, m), pair-major
            lo, hi = np.minimum(cp, cq), np.maximum(cp, cq)
            # -1 marks a pair on a held variable: it has no slot
            pair_keys.append(np.where(lo >= 0, lo * nfree + hi, -1))
            # a row naming one variable at two entries adds their product twice
            twice = (cp == cq) & (first != second)[:, None]
            families.append(_FamilyPattern(
                np.where(cols < 0, nfree, cols), cp.shape,
                np.where(twice, 2.0, 1.0) if twice.any() else None))
        # the diagonal first (always present), then every family's pairs
        keys = np.concatenate([np.arange(nfree) * (nfree + 1)] + [k.ravel() for k in pair_keys])
        valid = keys >= 0
        ukeys, ranks = _rank(keys if valid.all() else keys[valid], nfree * nfree)
        slots = np.full(len(keys), len(ukeys))   # held pairs: a dummy slot past the end
        slots[valid] = ranks
        return _Pattern(families=families,
                        indptr=np.searchsorted(ukeys // nfree, np.arange(nfree + 1)),
                        indices=ukeys % nfree, diagonal=slots[:nfree],
                        slots=slots[nfree:], products=np.empty(len(keys) - nfree))

    def _assemble(self, jacobians: list, residuals: list,
                  damping: float) -> tuple[sp.csr_matrix, np.ndarray]:
        """Upper triangle of ``J^T J + damping I`` (CSR) and the gradient ``J^T r``."""
        pat = self._pattern
        nnz, nfree = len(pat.indices), len(self.free)
        gradient = np.zeros(nfree + 1)
        start = 0
        for f, J, r in zip(pat.families, jacobians, residuals, strict=True):
            out = pat.products[start:start + int(np.prod(f.shape))].reshape(f.shape)
            start += out.size
            if J.size == 0:
                continue
            columns = np.ascontiguousarray(J.T)
            k, pair = len(columns), 0
            for i in range(k):     # entries of a row, not rows: k <= 16 broadcast multiplies
                np.multiply(columns[i], columns[i:], out=out[pair:pair + k - i])
                pair += k - i
            if f.multiplicity is not None:
                out *= f.multiplicity
            gradient += np.bincount(f.gradient_cols.ravel(), weights=(J * r[:, None]).ravel(),
                                    minlength=nfree + 1)
        data = np.bincount(pat.slots, weights=pat.products, minlength=nnz + 1)[:nnz]
        data[pat.diagonal] += damping
        upper = sp.csr_matrix((data, pat.indices, pat.indptr), shape=(nfree, nfree))
        return upper, gradient[:nfree]

    def _factor(self, upper: sp.csr_matrix, damping: float) -> None:
        """Factor, adding damping when rounding makes the matrix lose definiteness."""
        diagonal = self._pattern.diagonal
        for _ in range(4):
            try:
                self._linear.factor(upper)
                return
            except SolverError:
                upper.data[diagonal] += 100 * damping
                damping *= 101
        raise SolverError("the normal equations stay singular even with strong damping")

    def _stagnant(self, hard: float) -> bool:
        """No 10 % improvement of the best residual over the last `stagnation` iterations."""
        window = self.settings.stagnation
        past = [h.hard_residual for h in self.history if h.step > 0]
        if len(past) < window:
            return False
        return min(past[-window + 1:] + [hard]) > 0.9 * min(past[:-window + 1] or [np.inf])

    # -------------------------------------------------------------- iteration
    def _evaluate(self, weights: dict) -> tuple[list, list, dict]:
        """Weighted residuals (m,) and Jacobian values (m, k) of every family, and the
        unweighted max residual of each."""
        residuals, jacobians, measured = [], [], {}
        for c in self.constraints:
            r, J = c.evaluate(self.state)
            w = weights.get(c.name, 1.0)
            measured[c.name] = float(np.max(np.abs(r))) if len(r) else 0.0
            residuals.append(w * np.asarray(r, dtype=np.float64))
            jacobians.append(w * np.asarray(J, dtype=np.float64))
        return residuals, jacobians, measured

    def _weights(self, iteration: int) -> dict:
        s = self.settings
        fade = s.fade ** iteration
        soft = {"fairness": s.fairness_weight, "closeness": s.closeness_weight}
        return {c.name: soft.get(c.name, 1.0) * fade for c in self.constraints if not c.hard}

    def run(self, max_iterations: int | None = None,
            callback: Callable[[IterationRecord], None] | None = None) -> str:
        """Iterate until converged, stagnant or at the cap; returns the status.

        Raises
        ------
        SolverError
            When the residuals become non-finite or grow without bound.
        """
        s = self.settings
        cap = s.max_iterations if max_iterations is None else max_iterations
        hard_names = {c.name for c in self.constraints if c.hard}
        if self._pattern is None:
            for c in self.constraints:
                c.prepare(self.state)
            self._pattern = self._build_pattern()
        first = len(self.history)
        self.status = "iteration cap"
        for _ in range(cap + 1):
            it = len(self.history)
            t0 = time.perf_counter()
            for c in self.constraints:
                c.prepare(self.state)
            steps = sum(1 for h in self.history if h.step > 0)   # soft terms fade per step
            residuals, jacobians, measured = self._evaluate(self._weights(steps))
            hard = max([measured[n] for n in hard_names], default=0.0)
            if not all(np.isfinite(r).all() and np.isfinite(J).all()
                       for r, J in zip(residuals, jacobians, strict=True)):
                raise SolverError(f"the solver diverged at iteration {it}: non-finite residuals")
            initial = self.history[0].hard_residual if self.history else hard
            if hard > 1e6 * max(initial, 1.0):
                raise SolverError(
                    f"the solver diverged at iteration {it}: residual {hard:.3g} "
                    f"(started at {initial:.3g})")
            if hard <= s.tolerance:
                self.status = "converged"
                self.history.append(IterationRecord(it, measured, hard, 0.0,
                                                    time.perf_counter() - t0))
                break
            if it - first >= cap:
                self.history.append(IterationRecord(it, measured, hard, 0.0,
                                                    time.perf_counter() - t0))
                break
            if self._stagnant(hard):
                self.status = "stagnated"
                self.history.append(IterationRecord(it, measured, hard, 0.0,
                                                    time.perf_counter() - t0))
                break
            # Damping proportional to the residual (stable far away, quadratic near the end),
            # but fading no faster than the soft terms: otherwise fairness and closeness take
            # long steps along the solution manifold that the linearization cannot follow.
            soft = s.fade ** steps if any(not c.hard for c in self.constraints) else 0.0
            damping = max(s.epsilon * min(hard, 1.0), s.epsilon * soft, 1e-10)
            upper, gradient = self._assemble(jacobians, residuals, damping)
            t1 = time.perf_counter()
            self._factor(upper, damping)
            t2 = time.perf_counter()
            h = self._linear.solve(-gradient)
            t3 = time.perf_counter()
            if not np.isfinite(h).all():
                raise SolverError(f"the solver diverged at iteration {it}: singular system")
            self.state.x[self.free] += h
            rec = IterationRecord(it, measured, hard, float(np.linalg.norm(h)),
                                  time.perf_counter() - t0, t1 - t0, t2 - t1, t3 - t2)
            self.history.append(rec)
            if callback is not None:
                callback(rec)
        return self.status
