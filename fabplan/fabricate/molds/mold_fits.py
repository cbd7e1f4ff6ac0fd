"""Placing a mold to meet given points: the rigid motion (and, for a mold of its own, the
curvatures) that bring the mold surface ``z = (k1 x^2 + k2 y^2) / 2`` closest to them.

A panel cut from a mold is the mold surface itself: where it must meet its neighbours,
their mold surfaces along the shared edges are the points it must pass through. The fit
is a Gauss-Newton (Levenberg-Marquardt) solve on the six parameters of a small rigid
motion applied in mold coordinates, and on the two curvatures when they are free, of the
vertical gaps ``z - (k1 x^2 + k2 y^2) / 2`` of the placed points (an upper bound of their
distance from the mold, as in `fabplan.fabricate.molds`). The largest gap is brought down
by reweighting (Lawson's iteration: every point's weight grows with its gap), so the
result approaches the minimax fit the step limit asks for. Every fit is batched over
panels: arrays in, arrays out. The steps run in a small C extension
(``mold_fit_kernel.c``, compiled at install) one panel at a time, in one pass over its
points per step; where it could not be built, or with ``FABPLAN_KERNELS=numpy``, the same
steps run in numpy over all panels at once.

Coordinates: points in model units, placements map them to mold coordinates in mm (the
upper left block is millimetres per unit times a rotation), curvatures in 1/mm.
"""

from __future__ import annotations

import functools
import os
from types import ModuleType

import numpy as np

from .mold_shapes import closest_mold_points

__all__ = ["mold_gaps", "mold_points", "rotation_matrices", "fit_mold_placements",
           "polish_mold_placements", "compiled_kernel"]


def mold_gaps(points: np.ndarray, placements: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """Signed vertical gaps of placed points to their molds.

    Parameters
    ----------
    points : (p, s, 3) float, model coordinates.
    placements : (p, 4, 4) float, model -> mold coordinates (mm).
    shapes : (p, 2) float, ``(k1, k2)`` of each mold (1/mm).

    Returns
    -------
    (p, s) float, mm: ``z - (k1 x^2 + k2 y^2) / 2`` of every placed point.

    Examples
    --------
    >>> import numpy as np
    >>> flat = np.eye(4)[None]
    >>> mold_gaps(np.array([[[1.0, 2.0, 3.0]]]), flat, np.zeros((1, 2)))
    array([[3.]])
    """
    return _placed_gaps(_placed(points, placements), shapes)


def rotation_matrices(w: np.ndarray) -> np.ndarray:
    """(p, 3, 3) rotations about the axes `w` (p, 3) by their lengths (radians; Rodrigues).

    Examples
    --------
    >>> import numpy as np
    >>> np.round(rotation_matrices(np.array([[0.0, 0.0, np.pi / 2]]))[0] @ [1.0, 0.0, 0.0], 12)
    array([0., 1., 0.])
    """
    angle = np.linalg.norm(w, axis=1)
    axis = w / np.maximum(angle, 1e-300)[:, None]
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - K.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3)[None] + s * K + (1.0 - c) * (K @ K)


def fit_mold_placements(points: np.ndarray, weights: np.ndarray, placements: np.ndarray,
                        shapes: np.ndarray, *, must: np.ndarray | None = None,
                        free_shape: np.ndarray | None = None,
                        iterations: int = 12, rounds: int = 8
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Placements (and curvatures, where free) that bring molds closest to points.

    Parameters
    ----------
    points : (p, s, 3) float, the points each mold is to pass through (model units);
        padding rows get weight 0.
    weights : (p, s) float >= 0, how much each point counts (0: not at all).
    must : (p, s) bool, the points that must be met: their largest gap is brought down
        and returned (the others only steady the fit); None: those whose weight is at
        least half the largest of their panel.
    placements : (p, 4, 4) float, the start: model -> mold coordinates (mm).
    shapes : (p, 2) float, ``(k1, k2)`` of each mold (1/mm).
    free_shape : (p,) bool, the molds whose curvatures are fitted too (molds of their own);
        None: none.
    iterations : Gauss-Newton steps per round.
    rounds : reweighting rounds towards the smallest largest gap (1: least squares).

    Returns
    -------
    placements : (p, 4, 4) float.
    shapes : (p, 2) float.
    gaps : (p,) float, mm, the largest ``|gap|`` (`mold_gaps`) over the points that must
        be met (of the rounds, the one where it is smallest is returned).
    """
    M = np.array(placements, dtype=np.float64)
    K = np.array(shapes, dtype=np.float64)
    p = len(M)
    free = np.zeros(p, bool) if free_shape is None else np.asarray(free_shape, bool)
    base = np.asarray(weights, dtype=np.float64)
    if must is None:
        must = base >= 0.5 * base.max(axis=1, keepdims=True)
    must = np.asarray(must, bool) & (base > 0)
    kernel = compiled_kernel()
    if kernel is not None and p:
        points = np.ascontiguousarray(points, dtype=np.float64)
        s = points.shape[1]
        best_M, best_K, best_gap = np.empty((p, 4, 4)), np.empty((p, 2)), np.empty(p)
        kernel.fit(points, np.ascontiguousarray(base), np.ascontiguousarray(must, np.uint8),
                   np.ascontiguousarray(free, np.uint8), M, K, best_M, best_K, best_gap,
                   p, s, iterations, rounds)
        return best_M, best_K, best_gap
    return _fit_placements_numpy(points, base, must, free, M, K, iterations, rounds)


def _placed(points: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(p, s, 3) float, the points in mold coordinates, as `mold_gaps` places them."""
    return points @ M[:, :3, :3].transpose(0, 2, 1) + M[:, None, :3, 3]


def _placed_gaps(q: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(p, s) float, `mold_gaps` of placed points `q` on molds `K` (p, 2)."""
    return q[..., 2] - 0.5 * (K[:, None, 0] * q[..., 0] ** 2 + K[:, None, 1] * q[..., 1] ** 2)


def _gap_jacobian(q: np.ndarray, K: np.ndarray, free: np.ndarray, unknowns: int) -> np.ndarray:
    """(p, s, unknowns) float, the gaps' derivatives by a rotation and shift of every mold
    (and its curvatures, with 8 unknowns, where `free`)."""
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    # a rotation w and shift t in mold coordinates move q by w x q + t: the gap by
    # w . (q x g) + t . g with g = (-k1 x, -k2 y, 1); the curvatures enter with
    # -x^2 / 2, -y^2 / 2. The columns are written in place: the terms of q x g
    # are those of np.cross (its products by g's 1 left out: the same numbers)
    J = np.empty(q.shape[:2] + (unknowns,))
    gx, gy = J[..., 3], J[..., 4]
    np.multiply(-K[:, None, 0], x, out=gx)
    np.multiply(-K[:, None, 1], y, out=gy)
    J[..., 5] = 1.0
    np.subtract(y, z * gy, out=J[..., 0])
    np.subtract(z * gx, x, out=J[..., 1])
    np.subtract(x * gy, y * gx, out=J[..., 2])
    if unknowns == 8:
        J[..., 6:] = -0.5 * q[..., :2] ** 2 * free[:, None, None]
    return J


def _damped_step(J: np.ndarray, w: np.ndarray, r: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """(p, u) float, the damped weighted Gauss-Newton step of every mold for the Jacobian
    `J` (p, s, u), weights `w` and gaps `r` (p, s)."""
    unknowns = J.shape[2]
    # columns scaled to unit size: the curvature columns are a million times the
    # shift's, the rotation's a thousand
    Jw = J * w[..., None]
    scale = np.sqrt(np.sum(Jw * J, axis=1)) + 1e-300
    Js = J / scale[:, None, :]
    Jw /= scale[:, None, :]
    A = Jw.transpose(0, 2, 1) @ Js
    b = -np.sum(Jw * r[..., None], axis=1)
    A[:, np.arange(unknowns), np.arange(unknowns)] += damping[:, None]
    return np.linalg.solve(A, b[..., None])[..., 0] / scale


def _fit_placements_numpy(points: np.ndarray, base: np.ndarray, must: np.ndarray,
                          free: np.ndarray, M: np.ndarray, K: np.ndarray, iterations: int,
                          rounds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`fit_mold_placements` in numpy, where the compiled kernel is missing: the same
    steps, weights and result."""
    p = len(M)
    lawson = np.ones_like(base)
    w = base.copy()
    unknowns = 8 if free.any() else 6
    damping = np.full(p, 1e-4)
    # the placed points and their gaps follow the placements as steps are taken
    q = _placed(points, M)
    r = _placed_gaps(q, K)
    # the reweighting may overshoot: the round with the smallest largest gap is kept
    best_M, best_K = M.copy(), K.copy()
    best_gap = np.max(np.where(must, np.abs(r), 0.0), axis=1)
    for _ in range(max(rounds, 1)):
        current = np.sum(w * r ** 2, axis=1)
        for _ in range(iterations):
            step = _damped_step(_gap_jacobian(q, K, free, unknowns), w, r, damping)
            D = np.zeros((p, 4, 4))
            D[:, :3, :3] = rotation_matrices(step[:, :3])
            D[:, :3, 3] = step[:, 3:6]
            D[:, 3, 3] = 1.0
            trial_M = D @ M
            trial_K = K + step[:, 6:8] * free[:, None] if unknowns == 8 else K
            trial_q = _placed(points, trial_M)
            trial_r = _placed_gaps(trial_q, trial_K)
            trial = np.sum(w * trial_r ** 2, axis=1)
            # Levenberg-Marquardt: a step that lowers the cost is taken and the damping
            # eased; one that does not is refused and the damping raised
            better = trial < current
            M = np.where(better[:, None, None], trial_M, M)
            K = np.where(better[:, None], trial_K, K)
            q = np.where(better[:, None, None], trial_q, q)
            r = np.where(better[:, None], trial_r, r)
            current = np.where(better, trial, current)
            damping = np.clip(np.where(better, damping / 3.0, damping * 10.0), 1e-12, 1e12)
            if not np.any(better & (np.abs(step[:, 3:6]).max(axis=1) > 1e-9)):
                break
        size = np.abs(r)
        top = np.max(np.where(must, size, 0.0), axis=1, keepdims=True)
        better = top[:, 0] < best_gap
        best_M[better], best_K[better], best_gap[better] = M[better], K[better], top[better, 0]
        # Lawson: the weights of the points that must be met grow with their gaps (the
        # lighter points keep theirs)
        lawson = np.where(must, lawson * (size + 1e-3 * top + 1e-12), 0.0)
        lawson = lawson * np.sum(must, axis=1, keepdims=True) / np.maximum(
            np.sum(lawson, axis=1, keepdims=True), 1e-300)
        w = base * np.where(must, lawson, 1.0)
    return best_M, best_K, best_gap


@functools.lru_cache(maxsize=1)
def compiled_kernel() -> ModuleType | None:
    """The compiled fit and gaps (``mold_fit_kernel``), or None: not built, or
    ``FABPLAN_KERNELS=numpy`` in the environment."""
    if os.environ.get("FABPLAN_KERNELS", "").lower() == "numpy":
        return None
    try:
        from . import mold_fit_kernel  # compiled: Any to mypy (the package has a __getattr__)
    except ImportError:
        return None
    return mold_fit_kernel


def mold_points(points: np.ndarray, placements: np.ndarray, shapes: np.ndarray, *,
                closest: bool = True) -> np.ndarray:
    """Points moved onto placed molds, in model coordinates.

    Parameters
    ----------
    points : (p, s, 3) float, model coordinates.
    placements : (p, 4, 4) float, model -> mold coordinates (mm).
    shapes : (p, 2) float, ``(k1, k2)`` of each mold (1/mm).
    closest : True: each point's closest point on its mold; False: the mold point straight
        above or below it along the mold's axis (its mold ``x, y`` kept).

    Returns
    -------
    (p, s, 3) float, model coordinates.

    Examples
    --------
    >>> import numpy as np
    >>> flat = np.eye(4) * np.array([1000.0, 1000.0, 1000.0, 1.0])
    >>> mold_points(np.array([[[0.5, 0.2, 0.3]]]), flat[None], np.zeros((1, 2)))
    array([[[0.5, 0.2, 0. ]]])
    """
    q = _placed(points, placements)
    if closest:
        c = closest_mold_points(q, shapes[:, None, :])
    else:
        c = q.copy()
        c[..., 2] = 0.5 * (shapes[:, None, 0] * q[..., 0] ** 2 + shapes[:, None, 1] * q[..., 1] ** 2)
    # the rotation block is mm times a rotation: its inverse is its transpose over mm^2
    mm2 = np.sum(placements[:, 0, :3] ** 2, axis=1)
    return (c - placements[:, None, :3, 3]) @ placements[:, :3, :3] / mm2[:, None, None]


def polish_mold_placements(points: np.ndarray, must: np.ndarray, placements: np.ndarray,
                           shapes: np.ndarray, *, free_shape: np.ndarray | None = None,
                           iterations: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The largest gap of fitted placements brought down further, exactly: sequential
    linear programs (the gaps linearized in a small rigid motion, and the curvatures where
    free, minimizing their largest absolute value within a trust region that shrinks when
    a step does not lower it). For the few panels where it matters: a loop over panels.

    Parameters
    ----------
    points, placements, shapes, free_shape : as `fit_mold_placements`.
    must : (p, s) bool, the points whose largest gap is brought down.
    iterations : linear programs per panel at most.

    Returns
    -------
    placements (p, 4, 4), shapes (p, 2), gaps (p,) mm: as `fit_mold_placements`, never
    worse than the start.
    """
    from scipy.optimize import linprog

    M = np.array(placements, dtype=np.float64)
    K = np.array(shapes, dtype=np.float64)
    free = np.zeros(len(M), bool) if free_shape is None else np.asarray(free_shape, bool)
    gaps = np.zeros(len(M))
    for k in range(len(M)):
        P = points[k][np.asarray(must[k], bool)]
        n = 8 if free[k] else 6
        best = float(np.abs(mold_gaps(P[None], M[k:k + 1], K[k:k + 1])).max(initial=0.0))
        radius = 1.0
        for _ in range(iterations if len(P) else 0):
            q = P @ M[k, :3, :3].T + M[k, :3, 3]
            r = q[:, 2] - 0.5 * (K[k, 0] * q[:, 0] ** 2 + K[k, 1] * q[:, 1] ** 2)
            g = np.stack([-K[k, 0] * q[:, 0], -K[k, 1] * q[:, 1], np.ones(len(q))], axis=-1)
            J = np.concatenate([np.cross(q, g), g, -0.5 * q[:, :2] ** 2], axis=-1)[:, :n]
            scale = np.abs(J).max(axis=0) + 1e-300
            Js = J / scale
            # variables: the scaled step (n) and the largest gap t: J d - t <= -r, -J d - t <= r
            A = np.block([[Js, -np.ones((len(r), 1))], [-Js, -np.ones((len(r), 1))]])
            cost = np.r_[np.zeros(n), 1.0]
            bounds = [(-radius * best, radius * best)] * n + [(0, None)]
            res = linprog(cost, A_ub=A, b_ub=np.r_[-r, r], bounds=bounds, method="highs")
            if res.status != 0:
                break
            step = res.x[:n] / scale
            if not np.all(np.abs(step[:3]) < 1e150):
                # a degenerate panel, its mold missing it by astronomical gaps: a step too
                # large to turn by fails as a trial does (its rotation would overflow)
                radius *= 0.25
                if radius < 1e-6:
                    break
                continue
            D = np.eye(4)
            D[:3, :3] = rotation_matrices(step[None, :3])[0]
            D[:3, 3] = step[3:6]
            trial_M = D @ M[k]
            trial_K = K[k] + (step[6:8] if n == 8 else 0.0)
            trial = float(np.abs(mold_gaps(P[None], trial_M[None], trial_K[None])).max())
            if trial < best:
                M[k], K[k], best = trial_M, trial_K, trial
                radius = min(radius * 2.0, 1.0)
            else:
                radius *= 0.25
                if radius < 1e-6:
                    break
        gaps[k] = best
    return M, K, gaps
