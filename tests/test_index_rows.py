"""`unique_rows` against ``np.unique(..., axis=0)``: the same results, every one of them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fabplan.net.index_rows import unique_rows

I64, U64 = np.iinfo(np.int64), np.iinfo(np.uint64)


def _cases():
    rng = np.random.default_rng(7)
    yield rng.integers(0, 50, size=(400, 2))                  # edges with repeats
    yield rng.integers(-30, 30, size=(300, 2))                # lattice keys, negative
    yield rng.integers(0, 6, size=(200, 3)).astype(np.int32)  # three columns, int32
    yield rng.integers(-128, 128, size=(300, 4)).astype(np.int8)   # offsets past int8
    yield rng.integers(0, 4, size=(100, 1)).astype(np.uint16)  # one column
    yield np.zeros((0, 2), dtype=np.int64)                    # none
    yield np.array([[5, 5]])                                  # one
    yield rng.integers(0, 9, size=(50, 2))[:, ::-1]           # a view, not contiguous
    yield np.array([[2**40, 1], [0, 2**40], [2**40, 1]])      # ranges past one int64: numpy's
    yield np.array([[I64.min], [I64.max], [0], [I64.min]])    # the int64 extremes
    yield np.array([[-2**62, 0], [2**62, 0], [0, 5]])         # a span of 2**63
    yield np.array([[0, 1], [2**63, 1], [5, 1], [2**63, 1]], dtype=np.uint64)
    yield np.array([[U64.max - 3, 2], [U64.max, 1], [U64.max - 3, 2]], dtype=np.uint64)
    yield rng.integers(I64.min, I64.max, size=(200, 2), dtype=np.int64, endpoint=True)
    yield rng.integers(0, U64.max, size=(200, 2), dtype=np.uint64, endpoint=True)


def _as_tuple(found) -> tuple:
    return found if isinstance(found, tuple) else (found,)


@pytest.mark.parametrize("rows", list(_cases()), ids=lambda r: f"{r.shape}-{r.dtype}")
def test_the_same_as_numpys_unique_rows(rows):
    for flags in itertools.product([False, True], repeat=3):
        asked = dict(zip(["return_index", "return_inverse", "return_counts"], flags, strict=True))
        mine = _as_tuple(unique_rows(rows, **asked))
        numpys = _as_tuple(np.unique(rows, axis=0, **asked))
        assert len(mine) == len(numpys)
        for a, b in zip(mine, numpys, strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
            np.testing.assert_array_equal(a, b)


def test_random_rows_of_every_integer_type():
    rng = np.random.default_rng(11)
    for dtype in (np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint32, np.uint64):
        info = np.iinfo(dtype)
        for _ in range(20):
            k = int(rng.integers(1, 5))
            low = int(rng.integers(info.min, info.max // 2, endpoint=True))
            width = int(rng.choice([3, 100, 2**20]))
            high = min(info.max, low + width)
            rows = rng.integers(low, high, size=(int(rng.integers(0, 60)), k), dtype=dtype,
                                endpoint=True)
            mine = unique_rows(rows, return_index=True, return_inverse=True, return_counts=True)
            numpys = np.unique(rows, axis=0, return_index=True, return_inverse=True,
                               return_counts=True)
            for a, b in zip(mine, numpys, strict=True):
                assert a.dtype == b.dtype and a.shape == b.shape
                np.testing.assert_array_equal(a, b)
