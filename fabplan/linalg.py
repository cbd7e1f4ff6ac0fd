"""Sparse symmetric positive definite solves that reuse their symbolic analysis.

The normal equations of the solver keep one sparsity pattern for a whole run, so the
ordering and symbolic factorization are computed once and only the numeric factorization
is repeated. Backends, fastest first, picked automatically when installed:

- ``cholmod``: CHOLMOD through scikit-sparse (optional extra ``fabplan[cholmod]``);
- ``qdldl``: the QDLDL LDL^T factorization with AMD ordering (a default dependency);
- ``superlu``: scipy's SuperLU with a symmetric minimum-degree ordering (always present).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import FabplanError

__all__ = ["SparseSPDSolver", "available_backends"]


def available_backends() -> list[str]:
    """Names of the installed backends, fastest first."""
    names = []
    try:
        import sksparse.cholmod  # noqa: F401
        names.append("cholmod")
    except ImportError:
        pass
    try:
        import qdldl  # noqa: F401
        names.append("qdldl")
    except ImportError:
        pass
    names.append("superlu")
    return names


class SparseSPDSolver:
    """Repeated solves ``A x = b`` for SPD matrices sharing one sparsity pattern.

    Parameters
    ----------
    backend : "auto", "cholmod", "qdldl" or "superlu".
    """

    def __init__(self, backend: str = "auto"):
        names = available_backends()
        if backend == "auto":
            backend = names[0]
        if backend not in ("cholmod", "qdldl", "superlu"):
            raise FabplanError(f"unknown linear solver backend {backend!r}")
        if backend not in names:
            raise FabplanError(f"linear solver backend {backend!r} is not installed")
        self.backend = backend
        self._factor = None

    def factor(self, A: sp.csc_matrix) -> None:
        """Numeric factorization of ``A`` (CSC, full symmetric); symbolic analysis on first use."""
        if self.backend == "cholmod":
            from sksparse.cholmod import analyze
            if self._factor is None:
                self._factor = analyze(A, mode="supernodal")
            self._factor.cholesky_inplace(A)
        elif self.backend == "qdldl":
            import qdldl
            upper = sp.triu(A, format="csc")
            if self._factor is None:
                self._factor = qdldl.Solver(upper, upper=True)
            else:
                self._factor.update(upper, upper=True)
        else:
            self._factor = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                     options=dict(SymmetricMode=True))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.backend == "cholmod":
            return self._factor(b)
        return self._factor.solve(b)
