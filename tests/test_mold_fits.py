"""The fit of mold placements (`fabplan.fabricate.molds.mold_fits`): its compiled steps and its
numpy steps find the same placements, and both find a mold that the points lie on.

Points are sampled on a known placed mold and the fit starts from a disturbed placement;
the gaps are recomputed here from the placed points, not by the module's own measure.
"""

from __future__ import annotations

import numpy as np
import pytest

from fabplan.fabricate.molds import mold_fits


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    # Rodrigues, written here on its own
    a = axis / np.linalg.norm(axis)
    S = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * S + (1.0 - np.cos(angle)) * S @ S


def _panels(count: int, seed: int, *, points: int = 30, padding: int = 6,
            cylinders: bool = False):
    """Points (model units, metres) on molds ``z = (k1 x^2 + k2 y^2) / 2`` (mm) placed by
    known motions, with padding rows of weight 0; a disturbed start placement; the true
    placements and curvatures."""
    rng = np.random.default_rng(seed)
    truth = np.zeros((count, 4, 4))
    start = np.zeros((count, 4, 4))
    shapes = rng.uniform(-1.0, 1.0, (count, 2)) * 1e-4     # radii of 10 m and more, in mm
    if cylinders:
        shapes[:, 1] = 0.0
    P = np.zeros((count, points + padding, 3))
    W = np.zeros((count, points + padding))
    for i in range(count):
        R = _rotation(rng.normal(size=3), rng.uniform(0.0, np.pi))
        t = rng.normal(size=3) * 5e4
        truth[i, :3, :3], truth[i, :3, 3], truth[i, 3, 3] = 1000.0 * R, t, 1.0
        # points in mold coordinates (mm) on the mold, mapped back to model units
        xy = rng.uniform(-1500.0, 1500.0, (points, 2))
        z = 0.5 * (shapes[i, 0] * xy[:, 0] ** 2 + shapes[i, 1] * xy[:, 1] ** 2)
        q = np.column_stack([xy, z])
        P[i, :points] = (q - t) @ R / 1000.0
        W[i, :points] = 1.0
        D = np.eye(4)
        D[:3, :3] = _rotation(rng.normal(size=3), 0.01)
        D[:3, 3] = rng.normal(size=3) * 20.0
        start[i] = D @ truth[i]
    return P, W, start, shapes, truth


def _gaps(P: np.ndarray, M: np.ndarray, K: np.ndarray) -> np.ndarray:
    q = np.einsum("pij,psj->psi", M[:, :3, :3], P) + M[:, None, :3, 3]
    return q[..., 2] - 0.5 * (K[:, None, 0] * q[..., 0] ** 2 + K[:, None, 1] * q[..., 1] ** 2)


def _fit(monkeypatch, kernels: str, *args, **kwargs):
    monkeypatch.setenv("FABPLAN_KERNELS", kernels)
    mold_fits.compiled_kernel.cache_clear()
    try:
        return mold_fits.fit_mold_placements(*args, **kwargs)
    finally:
        mold_fits.compiled_kernel.cache_clear()


@pytest.mark.skipif(mold_fits.compiled_kernel() is None, reason="the compiled fit was not built")
@pytest.mark.parametrize("free", [False, True])
def test_compiled_and_numpy_fits_find_the_same_placements(monkeypatch, free):
    P, W, start, shapes, truth = _panels(40, seed=3)
    # molds of their own start from a flat mold; the net's molds from their curvatures
    K0 = np.zeros_like(shapes) if free else shapes
    free_shape = np.full(len(P), free)
    a = _fit(monkeypatch, "numpy", P, W, start, K0, free_shape=free_shape)
    b = _fit(monkeypatch, "", P, W, start, K0, free_shape=free_shape)
    # shifts of 50 m in mm; a mold of its own that comes out nearly flat (radius 300 m:
    # panel 5) slides along itself at a gap below a micrometre, so the two sums' rounding
    # (which differs with the processor's vector width) places it within 1e-6 only
    np.testing.assert_allclose(b[0], a[0], rtol=1e-5 if free else 1e-8, atol=1e-6)
    np.testing.assert_allclose(b[1], a[1], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(b[2], a[2], rtol=0, atol=1e-6)
    # both found the mold the points lie on: the gaps recomputed here, padding left out
    real = W > 0
    for M, K, gap in (a, b):
        measured = np.abs(np.where(real, _gaps(P, M, K), 0.0)).max(axis=1)
        np.testing.assert_allclose(gap, measured, rtol=1e-9, atol=1e-9)
        assert measured.max() < 1e-3


@pytest.mark.skipif(mold_fits.compiled_kernel() is None, reason="the compiled fit was not built")
def test_a_flat_mold_does_not_poison_the_compiled_fit(monkeypatch):
    # a cylinder mold (k2 = 0 exactly) has a Jacobian column of zeros: its scale underflows
    # when squared, which once turned every step into NaN and refused it
    P, W, start, shapes, _ = _panels(8, seed=5, cylinders=True)
    before = np.abs(np.where(W > 0, _gaps(P, start, shapes), 0.0)).max(axis=1)
    a = _fit(monkeypatch, "numpy", P, W, start, shapes)
    b = _fit(monkeypatch, "", P, W, start, shapes)
    assert np.all(np.isfinite(b[0])) and np.all(b[2] < 0.1 * before)
    np.testing.assert_allclose(b[2], a[2], rtol=1e-6, atol=1e-6)


def test_the_numpy_fit_brings_a_disturbed_placement_back(monkeypatch):
    P, W, start, shapes, truth = _panels(12, seed=11)
    before = np.abs(np.where(W > 0, _gaps(P, start, shapes), 0.0)).max(axis=1)
    M, K, gap = _fit(monkeypatch, "numpy", P, W, start, shapes)
    after = np.abs(np.where(W > 0, _gaps(P, M, K), 0.0)).max(axis=1)
    assert np.all(before > 1.0) and np.all(after < 1e-3)
    np.testing.assert_allclose(gap, after, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(K, shapes)            # the net's molds keep their shape


def test_an_empty_batch_gives_empty_arrays():
    M, K, gap = mold_fits.fit_mold_placements(np.zeros((0, 4, 3)), np.zeros((0, 4)),
                                              np.zeros((0, 4, 4)), np.zeros((0, 2)))
    assert M.shape == (0, 4, 4) and K.shape == (0, 2) and gap.shape == (0,)


def _gap_matrix(monkeypatch, kernels: str, data, molds):
    from fabplan.fabricate.molds import mold_assignment

    monkeypatch.setenv("FABPLAN_KERNELS", kernels)
    mold_fits.compiled_kernel.cache_clear()
    try:
        return mold_assignment._gap_matrix(data, molds)
    finally:
        mold_fits.compiled_kernel.cache_clear()


@pytest.mark.skipif(mold_fits.compiled_kernel() is None, reason="the compiled fit was not built")
def test_compiled_and_numpy_gap_matrices_are_the_same_numbers(monkeypatch):
    from fabplan.fabricate.molds.mold_assignment import _Panels

    rng = np.random.default_rng(8)
    p, s = 150, 23
    xy = rng.uniform(-1500.0, 1500.0, (p, 4, s, 2))
    shapes = rng.normal(size=(p, 4, 2)) * 1e-5
    Z = 0.5 * np.einsum("pvsk,pvk->pvs", xy ** 2, shapes) + rng.normal(size=(p, 4, s))
    Z[7, 2, 5] = np.nan          # a NaN gap replaces nothing, on both paths
    data = _Panels(shapes=shapes, U=xy ** 2, Z=Z, reach=np.full(p, 4e-6))
    molds = np.concatenate([shapes[::3, 0], rng.normal(size=(40, 2)) * 1e-5])
    dev_c, var_c = _gap_matrix(monkeypatch, "", data, molds)
    dev_n, var_n = _gap_matrix(monkeypatch, "numpy", data, molds)
    np.testing.assert_array_equal(dev_c, dev_n)
    np.testing.assert_array_equal(var_c, var_n)
    # the gaps recomputed here for the pairs within reach, in the frame chosen
    rows, cols = np.nonzero(np.isfinite(dev_c))
    assert 0 < len(rows) < dev_c.size
    v = var_c[rows, cols]
    r = Z[rows, v] - 0.5 * np.einsum("ask,ak->as", xy[rows, v] ** 2, molds[cols])
    np.testing.assert_allclose(dev_c[rows, cols], 0.5 * (r.max(axis=1) - r.min(axis=1)),
                               rtol=1e-12, atol=1e-12)
