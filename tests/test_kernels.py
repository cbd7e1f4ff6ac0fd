"""The compiled sums of the normal equations against numpy, to the last bit.

The kernels (fabplan/solve/normal_sums.c) must give the same matrix, gradient and iterates as
the numpy path: rounding differences do not stay small over a solve.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import fabplan
from fabplan.net.generate import rotational_weingarten_snet
from fabplan.solve import kernels
from fabplan.solve.constraints import VariableBlocks
from fabplan.solve.optimize import build_solver
from fabplan.solve.pattern import normal_pattern
from fabplan.solve.reference import ReferenceSurface

FORCED_NUMPY = os.environ.get("FABPLAN_KERNELS", "").lower() == "numpy"


@pytest.fixture
def compiled():
    """The compiled kernels; CI builds them (pip compiles the extension at install)."""
    if FORCED_NUMPY:
        pytest.skip("FABPLAN_KERNELS=numpy: the compiled kernels are switched off")
    found = kernels.compiled()
    assert found is not None, ("fabplan.solve.normal_sums is not built: pip install -e . "
                               "compiles it (a C compiler is needed)")
    return found


@pytest.fixture
def numpy_path(monkeypatch):
    """Switch the compiled kernels off for what the test builds next."""
    def switch(off: bool) -> None:
        if off:
            monkeypatch.setenv("FABPLAN_KERNELS", "numpy")
        else:
            monkeypatch.delenv("FABPLAN_KERNELS", raising=False)
        kernels.compiled.cache_clear()
    yield switch
    kernels.compiled.cache_clear()


def random_system(seed: int):
    """A pattern with held variables, a row naming one variable twice and an empty family,
    and random Jacobians, weights (one per family, or one per row) and residuals."""
    rng = np.random.default_rng(seed)
    blocks = VariableBlocks()
    blocks.add("vertices", (40, 3))
    blocks.add("spheres", (15, 5))
    blocks.add("cosine", (1,))
    columns = [rng.integers(0, blocks.size, size=(m, k)) for m, k in [(60, 5), (30, 11), (9, 1)]]
    columns.append(np.repeat(blocks.index("vertices")[rng.integers(0, 40, 25)], 2, axis=1))
    columns.append(np.zeros((0, 4), dtype=np.int64))
    free = np.flatnonzero(rng.random(blocks.size) >= 0.2)
    pattern = normal_pattern(columns, blocks, free)
    jacobians = [rng.normal(size=c.shape) for c in columns]
    residuals = [rng.normal(size=len(c)) for c in columns]
    weights = [0.3, rng.random(30), 1.0, 1e-3, 1.0]
    return pattern, columns, free, jacobians, residuals, weights


def numpy_sums(pattern, jacobians, residuals, weights):
    """The values and the gradient the way numpy sums them: every product pair-major, then
    by row, into one np.add.at; the gradient by np.bincount per family."""
    nfree = len(pattern.indptr) - 1
    products = []
    gradient = np.zeros(nfree + 1)
    for f, J, r, w in zip(pattern.families, jacobians, residuals, weights, strict=True):
        if J.size == 0:
            products.append(np.zeros(int(np.prod(f.shape))))
            continue
        weighted = (J * (w if np.ndim(w) == 0 else w[:, None])).T
        k = len(weighted)
        out = np.concatenate([weighted[i] * weighted[i:] for i in range(k)])
        if f.multiplicity is not None:
            out = out * f.multiplicity
        products.append(out.ravel())
        entries = J * (w if np.ndim(w) == 0 else w[:, None]) * (w * r)[:, None]
        gradient += np.bincount(f.gradient_cols.ravel(), weights=entries.ravel(),
                                minlength=nfree + 1)
    summed = np.zeros(pattern.nnz + 1)
    np.add.at(summed, pattern.slots, np.concatenate(products))
    return summed, gradient


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sums_equal_numpys_to_the_bit(compiled, seed):
    pattern, columns, free, jacobians, residuals, weights = random_system(seed)
    assert any(f.multiplicity is not None for f in pattern.families)
    assert int(pattern.slots.max()) == pattern.nnz          # some products on held variables
    expected, expected_gradient = numpy_sums(pattern, jacobians, residuals, weights)

    summed = np.zeros(pattern.nnz + 1)
    gradient = np.zeros(len(free) + 1)
    start = 0
    for f, J, r, w in zip(pattern.families, jacobians, residuals, weights, strict=True):
        if J.size == 0:
            start += int(np.prod(f.shape))
            continue
        weighted = np.ascontiguousarray((J * (w if np.ndim(w) == 0 else w[:, None])).T)
        start = compiled.sum_products(weighted, f.multiplicity, pattern.slots, start, summed)
        compiled.sum_gradient(J, w, r, f.gradient_cols, gradient)
    assert start == len(pattern.slots)
    assert np.array_equal(summed, expected)
    assert np.array_equal(gradient, expected_gradient)

    # and they are J^T W^2 J and J^T W^2 r: the upper triangle of the dense product
    dense_j = np.zeros((sum(len(c) for c in columns), len(free)))
    column_of = np.full(max(int(c.max(initial=0)) for c in columns) + 1, -1)
    column_of[free[free < len(column_of)]] = np.flatnonzero(free < len(column_of))
    row = 0
    rhs = []
    for c, J, r, w in zip(columns, jacobians, residuals, weights, strict=True):
        ww = np.broadcast_to(w, (len(c),))
        for i in range(len(c)):
            for j in range(c.shape[1]):
                if column_of[c[i, j]] >= 0:
                    dense_j[row, column_of[c[i, j]]] += ww[i] * J[i, j]
            rhs.append(ww[i] * r[i])
            row += 1
    normal = dense_j.T @ dense_j
    upper = np.zeros_like(normal)
    rows = np.repeat(np.arange(len(free)), np.diff(pattern.indptr))
    upper[rows, pattern.indices] = summed[:pattern.nnz]
    assert np.allclose(np.triu(normal), upper, atol=1e-12)
    assert np.allclose(dense_j.T @ np.array(rhs), gradient[:-1], atol=1e-12)


def solve_both(numpy_path, make_solver):
    """Run the same solve with the compiled kernels and with numpy: (vertices, history)."""
    results = []
    for off in (False, True):
        numpy_path(off)
        solver = make_solver()
        assert (solver._kernels is None) == off
        solver.run()
        results.append((solver.vertices, [h.as_dict() for h in solver.history]))
    return results


def same_runs(a, b) -> None:
    (va, ha), (vb, hb) = a, b
    assert np.array_equal(va, vb)
    assert len(ha) == len(hb)
    for x, y in zip(ha, hb, strict=True):
        assert x["residuals"] == y["residuals"] and x["step"] == y["step"]
        assert x["damping"] == y["damping"] and x["rejected"] == y["rejected"]


@pytest.mark.parametrize("net, fixed", [("linear-weingarten", None), ("snet", [3, 50, 700])])
def test_solves_are_the_same_to_the_bit(compiled, numpy_path, net, fixed):
    """The bundled net moved by noise, solved as a linear Weingarten net and as an S-net
    with held vertices, with the kernels and without: the same iterates."""
    wein99 = fabplan.QuadMesh.from_obj(fabplan.data_path("wein99.obj"))
    rng = np.random.default_rng(3)
    start = wein99.with_vertices(wein99.vertices
                                 + 0.01 * wein99.mean_edge_length * rng.normal(size=(1732, 3)))
    a, b = solve_both(numpy_path, lambda: build_solver(start, net, fixed=fixed))
    same_runs(a, b)


def test_generated_net_with_closeness_is_the_same_to_the_bit(compiled, numpy_path):
    net = rotational_weingarten_snet(40, 60, radius=3.0, angle_deg=80.0)
    rng = np.random.default_rng(4)
    start = net.with_vertices(net.vertices + 0.01 * net.mean_edge_length
                              * rng.normal(size=net.vertices.shape))
    reference = ReferenceSurface.from_mesh(net)
    a, b = solve_both(numpy_path, lambda: build_solver(start, "cmc", reference=reference))
    same_runs(a, b)


def test_bad_arrays_are_refused_not_read(compiled):
    from fabplan.solve import normal_sums

    weighted = np.ones((2, 3))
    slots = np.zeros(9, dtype=np.int32)
    with pytest.raises(TypeError, match="weighted"):
        normal_sums.sum_products(weighted.astype(np.float32), 2, 3, None, slots, 0, np.zeros(4))
    with pytest.raises(ValueError, match="shapes"):       # more products than slots
        normal_sums.sum_products(weighted, 2, 3, None, slots[:5], 0, np.zeros(4))
    with pytest.raises(ValueError, match="shapes"):       # a slot beyond the values
        normal_sums.sum_products(weighted, 2, 3, None, slots + 7, 0, np.zeros(4))
    with pytest.raises(ValueError, match="read-only"):      # values not writable
        values = np.zeros(4)
        values.flags.writeable = False
        normal_sums.sum_products(weighted, 2, 3, None, slots, 0, values)


def test_pattern_arrays_that_do_not_match_are_refused(compiled):
    from fabplan.solve import normal_sums

    columns = [np.array([[0, 1], [1, 2]], dtype=np.int64)]
    indptr, rows, repeats = compiled.pattern_rows(columns, 3)
    assert indptr.tolist() == [0, 2, 4, 5] and repeats == (False,)
    with pytest.raises(TypeError, match="int64"):           # columns of another type
        normal_sums.pattern_rows([columns[0].astype(np.int32)], 3, np.empty(4, np.int64))
    with pytest.raises(ValueError, match="indptr"):         # indptr of the wrong size
        normal_sums.pattern_rows(columns, 3, np.empty(3, np.int64))
    with pytest.raises(ValueError, match="match"):          # fewer slots than products
        normal_sums.pattern_fill(rows, columns, 3, indptr, np.empty(5, np.int32),
                                 np.empty(5, np.int32))
    indices, slots = np.empty(5, np.int32), np.empty(6, np.int32)
    normal_sums.pattern_fill(rows, columns, 3, indptr, indices, slots)
    assert indices.tolist() == [0, 1, 1, 2, 2]
    assert slots.tolist() == [0, 2, 1, 3, 2, 4]             # (0,0) (1,1) | (0,1) (1,2) | (1,1) (2,2)
