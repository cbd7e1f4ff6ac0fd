"""Compiled kernels for the work of an iteration outside the factorization, and for the
pattern of the normal equations that a solve builds first (`fabplan.solve.pattern`).

The normal equations are summed from every Jacobian row's entry products
(`fabplan.solve.pattern`). In numpy that takes a buffer of all products (12 million at
30k vertices), an `np.add.at` over it and an `np.bincount` for the gradient. The kernels
here do the same sums in one pass each, without the buffer and without the GIL.

They add in the same order as numpy does and form every term with the same operations,
so the matrix and the gradient are the same to the last bit. This matters: rounding
differences in the normal equations do not stay small over a solve (benchmarks/README.md).

The kernels are a small C extension (``normal_sums.c``) that pip compiles at install. C
rather than numba: the loops are as fast either way, but numba's import and the loading
of its cached kernels cost about 0.4 s in every process, more than they save on a solve
below about 30k vertices (benchmarks/README.md, "Compiled kernels"). Where the extension
could not be built (no C compiler at install), or with ``FABPLAN_KERNELS=numpy`` in the
environment, `compiled` returns None and the solver takes its numpy path.
"""

from __future__ import annotations

import functools
import os
from types import SimpleNamespace

import numpy as np

__all__ = ["compiled"]


@functools.lru_cache(maxsize=1)
def compiled() -> SimpleNamespace | None:
    """The compiled kernels, or None (not built, or ``FABPLAN_KERNELS=numpy``).

    Returns
    -------
    A namespace of two functions:

    - ``sum_products(weighted, multiplicity, slots, start, summed) -> end``: add one
      family's entry products into the normal equations' values. `weighted`: (k, m) float,
      the weighted Jacobian, entry-major; `multiplicity`: (p, m) float or None
      (`FamilyPattern.multiplicity`); `slots`: (products,) int, `NormalPattern.slots`;
      `start`: the family's first product there; `summed`: (nnz,) or (nnz + 1,) float,
      added to in place. Returns the next family's first product.
    - ``sum_gradient(jacobian, weight, residual, columns, gradient)``: add one family's
      ``J^T W^2 r``. `jacobian`: (m, k) float, unweighted; `weight`: float or (m,) float;
      `residual`: (m,) float; `columns`: (m, k) int, free column of each entry (``nfree``
      when held); `gradient`: (nfree + 1,) float, added to in place.
    - ``pattern_rows(columns, nfree) -> (indptr, rows, repeats)``: the rows of the upper
      triangle of ``J^T J`` (`fabplan.solve.pattern`). `columns`: per family (m, k)
      int64, the free column of each entry (``nfree`` when held). `indptr`: (nfree + 1,)
      int64; `repeats`: per family, whether a row names one free variable at two
      entries; `rows`: the rows' columns, held for
    - ``pattern_fill(rows, columns, nfree, indptr, indices, slots)``, which writes them
      into `indices` (nnz,) and every product's position into `slots` (products,), both
      int32 or both int64.
    """
    if os.environ.get("FABPLAN_KERNELS", "").lower() == "numpy":
        return None
    try:
        from . import normal_sums  # type: ignore[attr-defined]
    except ImportError:
        return None

    def sum_products(weighted: np.ndarray, multiplicity: np.ndarray | None, slots: np.ndarray,
                     start: int, summed: np.ndarray) -> int:
        k, m = weighted.shape
        return int(normal_sums.sum_products(_contiguous(weighted), k, m,
                                         None if multiplicity is None else _contiguous(multiplicity),
                                         _contiguous(slots), start, summed))

    def sum_gradient(jacobian: np.ndarray, weight: np.ndarray | float, residual: np.ndarray,
                     columns: np.ndarray, gradient: np.ndarray) -> None:
        m, k = jacobian.shape
        weights = np.full(m, float(weight)) if np.ndim(weight) == 0 else _contiguous(weight)
        part = np.zeros(len(gradient))      # summed on its own first, as np.bincount does
        normal_sums.sum_gradient(_contiguous(jacobian), k, m, weights, _contiguous(residual),
                              _contiguous(columns), part)
        gradient += part

    def pattern_rows(columns: list[np.ndarray], nfree: int
                     ) -> tuple[np.ndarray, object, tuple[bool, ...]]:
        indptr = np.empty(nfree + 1, dtype=np.int64)
        rows, repeats = normal_sums.pattern_rows(columns, nfree, indptr)
        return indptr, rows, repeats

    def pattern_fill(rows: object, columns: list[np.ndarray], nfree: int, indptr: np.ndarray,
                     indices: np.ndarray, slots: np.ndarray) -> None:
        normal_sums.pattern_fill(rows, columns, nfree, indptr, indices, slots)

    return SimpleNamespace(sum_products=sum_products, sum_gradient=sum_gradient,
                           pattern_rows=pattern_rows, pattern_fill=pattern_fill)


def _contiguous(array: np.ndarray | float) -> np.ndarray:
    """A C-contiguous float64 or integer array (no copy when it already is one)."""
    a = np.asarray(array)
    if a.dtype.kind == "f":
        return np.ascontiguousarray(a, dtype=np.float64)
    return np.ascontiguousarray(a)
