"""Sparse symmetric positive definite solves that reuse their symbolic analysis.

The normal equations of the solver keep one sparsity pattern for a whole run, so the
fill-reducing ordering and the symbolic factorization are computed once and only the
numeric factorization is repeated. Backends, fastest first:

- ``cholmod``: SuiteSparse's supernodal CHOLMOD as shipped in the cvxopt wheels (a
  default dependency: pip alone installs it on Linux, macOS and Windows);
- ``superlu``: scipy's SuperLU with a symmetric minimum-degree ordering, the fallback
  when cvxopt cannot be imported.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import FabplanError, SolverError

__all__ = ["SparseSPDSolver", "available_backends", "solve_spd_columns"]


def available_backends() -> list[str]:
    """Names of the installed backends, fastest first."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return ["superlu"]
    return ["cholmod", "superlu"]


class SparseSPDSolver:
    """Repeated solves ``A x = b`` for SPD matrices sharing one sparsity pattern.

    Matrices are passed as their upper triangle in CSR form (the same arrays describe
    the lower triangle in CSC form), with every structural entry present even when zero.

    Parameters
    ----------
    backend : "auto", "cholmod" or "superlu".
    """

    def __init__(self, backend: str = "auto"):
        names = available_backends()
        if backend == "auto":
            backend = names[0]
        if backend not in ("cholmod", "superlu"):
            raise FabplanError(f"unknown linear solver backend {backend!r}")
        if backend not in names:
            raise FabplanError(f"linear solver backend {backend!r} is not installed")
        self.backend = backend
        self._matrix = None
        self._factor = None

    def factor(self, upper: sp.csr_matrix) -> None:
        """Numeric factorization; the symbolic analysis runs on the first call only."""
        if self.backend == "cholmod":
            from cvxopt import cholmod, matrix, spmatrix

            if self._matrix is None:
                n = upper.shape[0]
                cols = np.repeat(np.arange(n), np.diff(upper.indptr))
                # built with ones so that no structural entry is dropped, then refilled
                self._matrix = spmatrix(1.0, upper.indices.tolist(), cols.tolist(), (n, n))
                self._factor = cholmod.symbolic(self._matrix)
            self._matrix.V = matrix(upper.data)
            try:
                cholmod.numeric(self._matrix, self._factor)
            except ArithmeticError:
                raise SolverError("the normal equations are not positive definite") from None
        else:
            full = (upper + upper.T - sp.diags(upper.diagonal())).tocsc()
            self._factor = spla.splu(full, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                     options=dict(SymmetricMode=True))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.backend == "cholmod":
            from cvxopt import cholmod, matrix

            x = matrix(np.asarray(b, dtype=np.float64))
            cholmod.solve(self._factor, x)
            return np.asarray(x).ravel()
        return self._factor.solve(b)


def solve_spd_columns(system: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve a sparse SPD system for the columns of `rhs` (one factorization).

    Parameters
    ----------
    system : (m, m) sparse, symmetric positive definite (both triangles stored).
    rhs : (m, k) float, right-hand sides.

    Returns
    -------
    x : (m, k) float, ``system @ x == rhs``.
    """
    upper = sp.triu(system, format="csr")
    upper.sum_duplicates()
    upper.sort_indices()
    solver = SparseSPDSolver()
    solver.factor(upper)
    return np.stack([solver.solve(np.ascontiguousarray(rhs[:, k])) for k in range(rhs.shape[1])],
                    axis=1)
