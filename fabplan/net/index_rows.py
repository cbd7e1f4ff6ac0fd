"""Unique rows of integer arrays (edges, index pairs, lattice keys), fast.

``np.unique(rows, axis=0)`` views every row as one opaque record and sorts those: at a
design's 100k edges it takes a quarter of a second. Rows of integers whose column ranges
multiply to less than 2**62 are one int64 each instead, in the same lexicographic order,
and numpy sorts those about five times as fast. The results are those of
``np.unique(rows, axis=0, ...)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["unique_rows"]


def unique_rows(rows: np.ndarray, *, return_index: bool = False, return_inverse: bool = False,
                return_counts: bool = False) -> Any:
    """``np.unique(rows, axis=0, ...)`` for an integer array, with its results.

    Parameters
    ----------
    rows : (m, k) int.
    return_index, return_inverse, return_counts : as for `np.unique`.

    Returns
    -------
    The array alone, or a tuple of it and the outputs asked for, as `np.unique` returns
    them (typed ``Any`` as numpy's own is, for the callers' unpacking):

    unique : (u, k), the distinct rows in lexicographic order, of the dtype of `rows`; then,
    as asked, index (u,) int (first occurrences), inverse (m,) int (one-dimensional with
    every numpy version) and counts (u,) int.

    Examples
    --------
    >>> import numpy as np
    >>> unique_rows(np.array([[2, 1], [0, 5], [2, 1]]), return_counts=True)
    (array([[0, 5],
           [2, 1]]), array([1, 2]))
    """
    rows = np.asarray(rows)
    unique: Any = np.unique     # (its typed overloads take only literal flags)
    key = _row_keys(rows)
    if key is None:
        found = unique(rows, axis=0, return_index=return_index, return_inverse=return_inverse,
                       return_counts=return_counts)
        if not return_inverse:
            return found
        found = list(found)
        found[1 + return_index] = found[1 + return_index].ravel()    # (m, 1) in numpy 2.0.0
        return tuple(found)
    # the first occurrences are always asked for: they give the rows, and they make numpy
    # sort stably, as it does for rows
    _, first, *rest = unique(key, return_index=True, return_inverse=return_inverse,
                             return_counts=return_counts)
    result = [rows[first]] + ([first] if return_index else []) + rest
    return result[0] if len(result) == 1 else tuple(result)


def _row_keys(rows: np.ndarray) -> np.ndarray | None:
    """(m,) int64, one key per row ordered as the rows are lexicographically, or None
    (not a 2-d integer array, or column ranges that multiply to 2**62 or more)."""
    if rows.ndim != 2 or rows.shape[1] == 0 or not np.issubdtype(rows.dtype, np.integer):
        return None
    if len(rows) == 0:
        return np.zeros(0, dtype=np.int64)
    low, high = rows.min(axis=0), rows.max(axis=0)
    # the ranges in floats first: in the rows' own type they may not fit (int64 extremes)
    if float(np.prod(high.astype(np.float64) - low.astype(np.float64) + 1.0)) >= 2.0 ** 62:
        return None
    # every offset and span is now below 2**62: exact in int64 (uint64 subtracts in its own
    # type, where the values may exceed int64)
    offset = (rows - low if rows.dtype == np.uint64 else rows.astype(np.int64) - low).astype(np.int64)
    span = offset.max(axis=0) + 1
    key = np.zeros(len(rows), dtype=np.int64)
    for column in range(rows.shape[1]):       # a few columns (2 to 4), not rows
        key = key * span[column] + offset[:, column]
    return key
