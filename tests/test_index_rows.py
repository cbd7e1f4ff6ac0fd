"""`unique_rows` against ``np.unique(..., axis=0)``: the same results, every one of them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fabplan.net.index_rows import unique_rows


def _cases():
    rng = np.random.default_rng(7)
    yield rng.integers(0, 50, size=(400, 2))                  # edges with repeats
    yield rng.integers(-30, 30, size=(300, 2))                # lattice keys, negative
    yield rng.integers(0, 6, size=(200, 3)).astype(np.int32)  # three columns, int32
    yield np.zeros((0, 2), dtype=np.int64)                    # none
    yield np.array([[5, 5]])                                  # one
    yield np.array([[2**40, 1], [0, 2**40], [2**40, 1]])      # ranges past one int64: numpy's


@pytest.mark.parametrize("rows", list(_cases()), ids=lambda r: f"{r.shape}-{r.dtype}")
def test_the_same_as_numpys_unique_rows(rows):
    for flags in itertools.product([False, True], repeat=3):
        asked = dict(zip(["return_index", "return_inverse", "return_counts"], flags, strict=True))
        mine, numpys = unique_rows(rows, **asked), np.unique(rows, axis=0, **asked)
        mine = mine if isinstance(mine, tuple) else (mine,)
        numpys = numpys if isinstance(numpys, tuple) else (numpys,)
        assert len(mine) == len(numpys)
        for a, b in zip(mine, numpys, strict=True):
            assert a.dtype.kind == b.dtype.kind
            np.testing.assert_array_equal(a, np.reshape(b, a.shape) if a.size == b.size else b)
            assert a.size == b.size
