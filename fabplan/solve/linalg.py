"""Sparse symmetric positive definite solves that reuse their symbolic analysis.

The normal equations of the solver keep one sparsity pattern for a whole run, so the
fill-reducing ordering and the symbolic factorization are computed once and only the
numeric factorization is repeated. Backends:

- ``pardiso``: Intel MKL's PARDISO, multi-threaded, when the MKL runtime is installed
  (``pip install "fabplan[pardiso]"``, x86-64 Linux and Windows); "auto" takes it for
  systems of at least `PARDISO_MIN_UNKNOWNS` unknowns, where its threads pay off;
- ``cholmod``: SuiteSparse's supernodal CHOLMOD as shipped in the cvxopt wheels (a
  default dependency: pip alone installs it on Linux, macOS and Windows), single-threaded;
- ``superlu``: scipy's SuperLU with a symmetric minimum-degree ordering, the fallback
  when cvxopt cannot be imported.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import os
import sys
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import FabplanError, SolverError

__all__ = ["SparseSPDSolver", "available_backends", "solve_spd_columns", "PARDISO_MIN_UNKNOWNS"]

# From about this size on PARDISO on two cores refactors the solver's systems faster than
# CHOLMOD on one (median refactorization 0.17 against 0.25 s at 79k unknowns in
# benchmarks/results/solver-2026-12-01*.json; on par on the bundled net's 14k, where
# thread start-up eats the gain).
PARDISO_MIN_UNKNOWNS = 50_000


def available_backends() -> list[str]:
    """Names of the installed backends."""
    names = ["pardiso"] if _mkl_runtime() is not None else []
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return names + ["superlu"]
    return names + ["cholmod", "superlu"]


@functools.lru_cache(maxsize=1)
def _mkl_runtime() -> ctypes.CDLL | None:
    """MKL's single dynamic library (from the ``mkl`` wheel), or None when not installed."""
    import site

    found = ctypes.util.find_library("mkl_rt")
    candidates = [found] if found else []
    for root in (sys.prefix, site.getuserbase()):          # a venv, or pip install --user
        for pattern in ("lib/libmkl_rt.so*", "Library/bin/mkl_rt*.dll"):
            candidates += sorted(glob.glob(os.path.join(root, pattern)), key=len)
    for path in candidates:
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        # 32-bit indices (LP64), whatever MKL_INTERFACE_LAYER says
        library.MKL_Set_Interface_Layer(ctypes.c_int(0))
        return library
    return None


class _Pardiso:
    """PARDISO for one real SPD sparsity pattern (upper triangle, CSR, 0-based)."""

    _PHASES = {"analysis": 11, "numeric": 22, "solve": 33, "release": -1}

    def __init__(self, upper: sp.csr_matrix) -> None:
        runtime = _mkl_runtime()
        if runtime is None:
            raise FabplanError("linear solver backend 'pardiso' is not installed")
        self._call = runtime.pardiso
        self._call.restype = None
        self.n = upper.shape[0]
        if upper.nnz >= 2**31 - 1:
            raise SolverError(f"the normal equations have {upper.nnz} entries, more than "
                              "PARDISO's 32-bit indices hold; use the cholmod backend")
        self.indptr = np.ascontiguousarray(upper.indptr, dtype=np.int32)
        self.indices = np.ascontiguousarray(upper.indices, dtype=np.int32)
        self.handle = np.zeros(64, dtype=np.int64)        # PARDISO's internal pointers
        self.iparm = np.zeros(64, dtype=np.int32)
        self.iparm[0] = 1      # these parameters, not the defaults
        self.iparm[1] = 2      # METIS nested dissection
        self.iparm[34] = 1     # 0-based indices
        self.data = np.zeros(len(self.indices))
        self._run("analysis")

    def _run(self, phase: str, b: np.ndarray | None = None) -> np.ndarray:
        b = np.zeros(self.n) if b is None else np.ascontiguousarray(b, dtype=np.float64)
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)

        def integer(value: int) -> object:
            return ctypes.byref(ctypes.c_int32(value))

        def pointer(array: np.ndarray) -> ctypes.c_void_p:
            return array.ctypes.data_as(ctypes.c_void_p)

        self._call(pointer(self.handle), integer(1), integer(1), integer(2),
                   integer(self._PHASES[phase]), integer(self.n), pointer(self.data),
                   pointer(self.indptr), pointer(self.indices), None, integer(1),
                   pointer(self.iparm), integer(0), pointer(b), pointer(x), ctypes.byref(error))
        if error.value == -4:
            raise SolverError("the normal equations are not positive definite")
        if error.value == -2:
            raise SolverError("PARDISO ran out of memory (use the cholmod backend)")
        if error.value:
            raise SolverError(f"PARDISO failed in its {phase} phase (error {error.value})")
        return x

    def factor(self, data: np.ndarray) -> None:
        self.data[:] = data
        self._run("numeric")

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._run("solve", b)

    def __del__(self) -> None:
        if self.handle.any():      # free PARDISO's memory; nothing to report at exit
            try:
                self._run("release")
            except Exception:  # noqa: BLE001
                pass


class SparseSPDSolver:
    """Repeated solves ``A x = b`` for SPD matrices sharing one sparsity pattern.

    Matrices are passed as their upper triangle in CSR form (the same arrays describe
    the lower triangle in CSC form), with every structural entry present even when zero.

    Parameters
    ----------
    backend : "auto", "pardiso", "cholmod" or "superlu".
    unknowns : size of the systems, for "auto": PARDISO from `PARDISO_MIN_UNKNOWNS`
        on, when installed; CHOLMOD otherwise.
    shared : a dictionary kept with the sparsity pattern (`NormalPattern.shared`): what
        the backend builds from the pattern alone is left there for the next solver of
        the same pattern (CHOLMOD's matrix of the pattern, a quarter second at 30k
        vertices); the next solver works on a copy of it.
    """

    def __init__(self, backend: str = "auto", unknowns: int | None = None, *,
                 shared: dict | None = None) -> None:
        names = available_backends()
        if backend == "auto":
            small = unknowns is None or unknowns < PARDISO_MIN_UNKNOWNS
            backend = [b for b in names if not (b == "pardiso" and small)][0]
        if backend not in ("pardiso", "cholmod", "superlu"):
            raise FabplanError(f"unknown linear solver backend {backend!r}")
        if backend not in names:
            raise FabplanError(f"linear solver backend {backend!r} is not installed")
        self.backend = backend
        self._shared = shared
        # cholmod: the cvxopt matrix holding the pattern; the factorization is a _Pardiso,
        # a cvxopt CHOLMOD factor or a scipy SuperLU (the last two untyped)
        self._matrix: Any = None
        self._values: Any = None
        self._values_view = np.zeros(0)
        self._factor: _Pardiso | Any = None

    def values(self, nnz: int) -> np.ndarray:
        """(nnz,) float, a buffer for the matrices' values that `factor` takes without a
        copy when they are passed in it (as ``upper.data``): with CHOLMOD a view of the
        cvxopt matrix that feeds its matrix."""
        if len(self._values_view) != nnz:
            if self.backend == "cholmod":
                from cvxopt import matrix

                self._values = matrix(0.0, (nnz, 1))
                self._values_view = np.asarray(self._values)[:, 0]
            else:
                self._values_view = np.zeros(nnz)
        return self._values_view

    def factor(self, upper: sp.csr_matrix) -> None:
        """Numeric factorization; the symbolic analysis runs on the first call only."""
        if self.backend == "pardiso":
            if self._factor is None:
                self._factor = _Pardiso(upper)
            self._factor.factor(upper.data)
        elif self.backend == "cholmod":
            from cvxopt import cholmod, matrix, spmatrix

            # the values pass through one buffer (`values`), not a new matrix
            values = self.values(upper.nnz)
            if upper.data is not values:
                values[:] = upper.data
            if self._matrix is None:
                pattern = None if self._shared is None else self._shared.get("cholmod")
                if pattern is None:
                    n = upper.shape[0]
                    # the triplets filled in place (fresh memory is slow): the row of every
                    # entry, and its column counted up
                    rows = matrix(0, (upper.nnz, 1), "i")
                    np.asarray(rows)[:, 0] = upper.indices
                    cols = matrix(0, (upper.nnz, 1), "i")
                    column = np.asarray(cols)[:, 0]
                    starts = upper.indptr[1:-1]
                    np.add.at(column, starts[starts < upper.nnz], 1)
                    np.cumsum(column, out=column)
                    # cvxopt keeps every triplet, zeros included: the structure is the pattern's
                    self._matrix = spmatrix(self._values, rows, cols, (n, n))
                    del rows, cols, column        # not held through the factorization
                    if self._shared is not None:
                        # the next solver copies its structure (its values it overwrites)
                        self._shared["cholmod"] = self._matrix
                else:
                    self._matrix = 1.0 * pattern     # a copy, explicit zeros kept (unlike `sparse`)
                self._factor = cholmod.symbolic(self._matrix)
            self._matrix.V = self._values
            try:
                cholmod.numeric(self._matrix, self._factor)
            except ArithmeticError:
                raise SolverError("the normal equations are not positive definite") from None
        else:
            full = (upper + upper.T - sp.diags(upper.diagonal())).tocsc()
            self._factor = spla.splu(full, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                     options=dict(SymmetricMode=True))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.backend == "pardiso":
            return self._factor.solve(b)
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
    solver = SparseSPDSolver(unknowns=upper.shape[0])
    solver.factor(upper)
    return np.stack([solver.solve(np.ascontiguousarray(rhs[:, k])) for k in range(rhs.shape[1])],
                    axis=1)
