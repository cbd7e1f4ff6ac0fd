"""Mold reduction: how many molds the curved panels of a net need, verified panel by panel.

A doubly curved panel is hot-bent on a mold. On a Weingarten surface both principal
curvatures are constant along one family of curves, so the panels along such a curve can
share a mold, and about ``sqrt(N)`` molds serve ``N`` panels (paper, section 3.5). This
module counts the molds a net really needs at a stated tolerance:

1. Panel model (`fabplan.panels`): every face is a quadratic surface patch with its
   principal curvatures and frame; it is *planar* when a plane, *single curved* when a
   cylinder and otherwise *double curved* fits it within the tolerance.
2. Molds: every mold is the surface ``z = (k1 x^2 + k2 y^2) / 2`` in mold coordinates
   (millimetres): a *plane* (``k1 = k2 = 0``), a *cylinder* (``k2 = 0``; the parabolic
   cylinder, which differs from the circular one of radius ``1 / k1`` by about
   ``k1^3 x^4 / 8`` over a panel) or a *paraboloid*. Each panel type gets molds of its own
   type. A panel is placed on a mold by a rigid motion that takes its principal frame to
   the mold's axes (in one of the four principal placements of
   `fabplan.panels.placement_frames`) and shifts it along the mold axis to even out the
   gap; its deviation is the largest vertical gap between panel and mold, an upper bound of
   the distance. For fixed placement frames that gap is piecewise linear and convex in the
   mold curvatures, so it is computed exactly for every (panel, mold) pair, not estimated.
3. Assignment: a greedy set cover of the panels by candidate molds (the panels' own
   shapes), then rounds of refitting every mold's curvatures to its panels (a small linear
   program minimizing the largest deviation), reassigning panels to their closest mold and
   removing molds whose panels all fit elsewhere. Everything is sorted and deterministic.
4. Verification: every panel is sampled again, densely, placed by its exported 4 x 4
   matrix and measured against its mold; panels found above the tolerance get molds of
   their own; a panel that fits no mold (or exceeds the largest mold size) is reported as
   a failure, never dropped.
5. Weingarten evidence: how close the panels' ``(k1, k2)`` lie to a line
   ``a k1 + b k2 = c`` (and to a conic), against the curvature difference one mold absorbs.

Model coordinates are in the net's units (``units``: ``"m"`` or ``"mm"``); every
fabrication output (mold curvatures, sizes, placements, deviations) is in millimetres.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from ...errors import InputError
from ...net.mesh import QuadMesh
from ...net.weingarten import weingarten_fit
from .mold_fits import compiled_kernel
from .mold_plan import MoldPlan
from .mold_shapes import MOLD_TYPES, MoldSettings, panel_steps, placement_deviations
from .panel_classes import classify_panels
from .panel_meshes import PANEL_MESH_LEVEL, panel_surface_mesh
from .panels import (
    check_panels,
    design_panel_samples,
    fit_design_panels,
    fit_panel_surfaces,
    fit_shared_panels,
    panel_samples,
    panel_shapes,
    placement_frames,
    shared_panel_samples,
    surface_model,
    surface_steps,
)

__all__ = [
    "plan_molds",
]

STEP_ROUNDS = 3
"""Rounds of casting the panels of over-limit steps on closer molds (tolerance halved in
each round)."""
_FREE_DIMS = {"plane": 0, "cylinder": 1, "paraboloid": 2}  # mold curvatures that are fitted


def _offset_gap(U: np.ndarray, Z: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deviation and best shift along the mold axis for fixed placement frames.

    U : (..., s, 2) squared mold coordinates ``(x^2, y^2)``; Z : (..., s) heights;
    K : (..., 2) mold curvatures. Returns (deviation, shift), each (...,), mm.
    """
    r = Z - 0.5 * (U[..., 0] * K[..., None, 0] + U[..., 1] * K[..., None, 1])
    hi, lo = r.max(axis=-1), r.min(axis=-1)
    return 0.5 * (hi - lo), 0.5 * (hi + lo)


# ----------------------------------------------------------------------------- the panels
@dataclass
class _Panels:
    """Panel data for the assignment (internal): samples in the four placement frames."""

    shapes: np.ndarray      # (p, 4, 2) panel curvatures in each frame (1/mm)
    U: np.ndarray           # (p, 4, s, 2) squared mold x, y of the samples (mm^2)
    Z: np.ndarray           # (p, 4, s) mold z of the samples (mm)
    reach: np.ndarray       # (p,) curvature distance beyond which molds are not tried (1/mm)


def _frame_coordinates(points: np.ndarray, point: np.ndarray, frames: np.ndarray,
                       mm: float) -> np.ndarray:
    """(p, v, s, 3) mold coordinates (mm) of samples (p, s, 3) in frames (p, v, 3, 3)."""
    d = points - point[:, None, :]
    return mm * np.einsum("pvij,psj->pvsi", frames, d)


def _panel_data(points: np.ndarray, point: np.ndarray, frames: np.ndarray, shapes: np.ndarray,
                mm: float, tolerance: float) -> _Panels:
    """Samples (p, s, 3) of panels with apex points (p, 3) in their placement frames
    (p, 4, 3, 3), their shapes there (p, 4, 2) and their reach at the tolerance (mm)."""
    Q = _frame_coordinates(points, point, frames, mm)
    U, Z = Q[..., :2] ** 2, Q[..., 2]
    width = np.minimum(np.ptp(Q[:, 0, :, 0], axis=1), np.ptp(Q[:, 0, :, 1], axis=1))
    # A shift along the mold axis leaves a gap of about dk w^2 / 16 for a curvature error dk
    # across a width w; molds four times farther than the tolerance allows are not tried
    # (a generous cut: it can only cost a mold, never accept a panel that does not fit).
    reach = 64.0 * tolerance / np.maximum(width, 1e-9) ** 2
    return _Panels(shapes=shapes, U=U, Z=Z, reach=reach)


def _cylinder_fits(U: np.ndarray, Z: np.ndarray, k1: np.ndarray,
                   iterations: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Best ``K1`` of a cylinder mold ``(K1, 0)`` for each panel (frame F0), by golden
    section on the convex gap. Returns (K1, deviation), each (p,)."""
    span = 2.0 * np.abs(k1) + 1e-9
    lo, hi = k1 - span, k1 + span
    g = (math.sqrt(5) - 1) / 2

    def gap(K1: np.ndarray) -> np.ndarray:
        return _offset_gap(U, Z, np.stack([K1, np.zeros_like(K1)], -1))[0]

    for _ in range(iterations):
        a, b = hi - g * (hi - lo), lo + g * (hi - lo)
        left = gap(a) < gap(b)
        hi, lo = np.where(left, b, hi), np.where(left, lo, a)
    K1 = 0.5 * (lo + hi)
    return K1, gap(K1)


# ----------------------------------------------------------------------------- gaps and cover
#: Panels per block of `_gap_matrix`'s arithmetic.
_GAP_ROWS = 32


def _gap_matrix(data: _Panels, molds: np.ndarray, chunk: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Exact gaps of every panel on every mold, in the best of the four placements.

    Molds are taken in blocks of nearby curvatures; a block is only evaluated for the
    panels whose shape in a placement lies within their reach (see `_panel_data`) of the
    block's bounding box: farther pairs are left at infinity (treated as not fitting).
    The gaps of a block are computed by the compiled kernel (``mold_fit_kernel.gap_block``)
    where it is built, else in numpy: the same numbers.

    Returns
    -------
    deviation : (p, m) float, mm, inf where not evaluated.
    variant : (p, m) int, the placement frame that gives it.
    """
    p = len(data.shapes)
    m = len(molds)
    deviation = np.full((p, m), np.inf)
    variant = np.zeros((p, m), np.int64)
    order = np.lexsort((molds[:, 1], molds[:, 0]))
    # a build of the kernel from before it had gap_block: the numpy path
    gap_block = getattr(compiled_kernel(), "gap_block", None) if p and m else None
    if gap_block is not None:
        U, Z = np.ascontiguousarray(data.U, np.float64), np.ascontiguousarray(data.Z, np.float64)
    for start in range(0, m, chunk):
        cols = order[start:start + chunk]
        K = np.ascontiguousarray(molds[cols], np.float64)
        lo, hi = K.min(axis=0), K.max(axis=0)
        for v in range(4):
            shape = data.shapes[:, v]
            gap = np.maximum(np.maximum(lo - shape, shape - hi), 0.0).max(axis=1)
            rows = np.flatnonzero(gap <= data.reach)
            if rows.size == 0:
                continue
            if gap_block is not None:
                gap_block(U, Z, np.ascontiguousarray(rows, np.int64),
                          np.ascontiguousarray(cols, np.int64), v, K, deviation, variant, p,
                          Z.shape[2], m)
            else:
                _gap_block(data, rows, cols, v, K, deviation, variant)
    return deviation, variant


def _gap_block(data: _Panels, rows: np.ndarray, cols: np.ndarray, v: int, K: np.ndarray,
               deviation: np.ndarray, variant: np.ndarray) -> None:
    """The numpy path of ``mold_fit_kernel.gap_block``: the gaps of panels `rows` in frame
    `v` on molds `cols` (curvatures `K`), written into `deviation` and `variant` (p, m)
    where smaller than what they hold."""
    dev = np.empty((rows.size, len(cols)))                  # (rows, chunk)
    # rows in blocks: the (rows, samples, chunk) temporaries stay in the cache
    for b in range(0, rows.size, _GAP_ROWS):
        U, Z = data.U[rows[b:b + _GAP_ROWS], v], data.Z[rows[b:b + _GAP_ROWS], v]
        r = Z[..., None] - 0.5 * (U[..., 0, None] * K[:, 0] + U[..., 1, None] * K[:, 1])
        dev[b:b + _GAP_ROWS] = 0.5 * (r.max(axis=1) - r.min(axis=1))
    block = deviation[np.ix_(rows, cols)]
    better = dev < block
    deviation[np.ix_(rows, cols)] = np.where(better, dev, block)
    variant[np.ix_(rows, cols)] = np.where(better, v, variant[np.ix_(rows, cols)])


def _greedy_cover(fits: np.ndarray) -> np.ndarray:
    """Columns of `fits` (p, c) bool chosen greedily, the one covering most uncovered rows
    first (lowest index on ties), until every coverable row is covered.

    The uncovered rows of every column are counted once and then less the rows each
    choice covers (integers: no product of the whole matrix per choice)."""
    uncovered = np.any(fits, axis=1)
    count = fits.sum(axis=0, dtype=np.int64)
    chosen: list[int] = []
    while uncovered.any():
        best = int(np.argmax(count))
        chosen.append(best)
        covered = uncovered & fits[:, best]
        count -= fits[covered].sum(axis=0, dtype=np.int64)
        uncovered &= ~covered
    return np.array(chosen, dtype=np.int64)


def _refit_molds(U: np.ndarray, Z: np.ndarray, owner: np.ndarray, K: np.ndarray, free: int,
                 reach: np.ndarray) -> np.ndarray:
    """Mold curvatures minimizing the largest gap of each mold's panels (fixed frames, each
    panel with its own shift along the mold axis), for several molds at once.

    Each mold is a linear program in (K, shifts, gap) over the samples that are highest or
    lowest for some curvature near its `K` (within its `reach`), with samples found
    violating the result added until none does (cutting planes): a few small programs
    instead of one over all samples. The programs of all molds are independent blocks of
    one program whose cost is the sum of their gaps, so one solve serves every mold (the
    solver's fixed cost per call is most of a small program's time); a mold leaves it once
    its samples settle.

    Parameters
    ----------
    U : (q, s, 2) float, Z : (q, s) float, the squared mold x, y (mm^2) and mold z (mm) of
        the samples of all molds' panels in their frames, each mold's panels together.
    owner : (q,) int, the mold of each panel, nondecreasing.
    K : (g, 2) float, the molds' start curvatures (1/mm).
    free : how many curvatures are fitted (0: none, 1: ``k1``, 2: both).
    reach : (g,) float, the curvature distance of each mold's panels (1/mm).

    Returns
    -------
    (g, 2) float, the fitted curvatures (1/mm); a mold whose program fails keeps its
    last fit.
    """
    best = np.array(K, dtype=np.float64)
    if free == 0 or len(best) == 0:
        return best
    g = len(best)
    size = np.bincount(owner, minlength=g)
    first = np.cumsum(size) - size
    local = np.arange(len(owner)) - first[owner]
    scale = np.full(g, -np.inf)
    np.maximum.at(scale, owner, U.max(axis=(1, 2)))
    scale = np.maximum(scale, 1e-12)
    steps = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], float) * 0.25
    steps[:, free:] = 0.0
    active = np.zeros(Z.shape, bool)
    for d in steps:
        _mark_extremes(active, U, Z, best[owner] + d * reach[owner, None])
    open_ = np.ones(g, bool)
    for _ in range(20):
        rows = open_[owner]
        res, column = _refit_program(U, Z, owner, active & rows[:, None], open_, size, local,
                                     scale, free)
        if res.status != 0:
            if g == 1:
                return best
            # the joint program may run into numerical trouble where the blocks' scales
            # differ; each open mold is then fitted on its own, from where it stands
            for m in np.flatnonzero(open_):
                mine = owner == m
                best[m] = _refit_molds(U[mine], Z[mine], np.zeros(int(mine.sum()), np.int64),
                                       best[m:m + 1], free, reach[m:m + 1])[0]
            return best
        which = np.flatnonzero(open_)
        best[which, :free] = res.x[column[which, None] + np.arange(free)] / scale[which, None]
        before = np.bincount(owner, weights=active.sum(axis=1), minlength=g)
        marked = np.flatnonzero(rows)
        sub = active[marked]
        _mark_extremes(sub, U[marked], Z[marked], best[owner[marked]])
        active[marked] = sub
        after = np.bincount(owner, weights=active.sum(axis=1), minlength=g)
        open_ &= after > before
        if not open_.any():
            break
    return best


def _refit_program(U: np.ndarray, Z: np.ndarray, owner: np.ndarray, active: np.ndarray,
                   open_: np.ndarray, size: np.ndarray, local: np.ndarray, scale: np.ndarray,
                   free: int) -> tuple[Any, np.ndarray]:
    """Solve the joint linear program of the open molds of `_refit_molds` over their
    `active` (q, s) samples: the result of `scipy.optimize.linprog` (the open molds'
    curvatures scaled by `scale`) and the first column of every mold's block, (g,) int."""
    p, j = np.nonzero(active)
    # columns of each open mold's block: its curvatures, its panels' shifts, its gap
    width = np.where(open_, free + size + 1, 0)
    column = np.cumsum(width) - width
    b = owner[p]
    A = _refit_constraints(U[p, j, :free] / scale[b, None], column[b],
                           column[b] + free + local[p], column[b] + free + size[b],
                           int(width.sum()))
    cost = np.zeros(int(width.sum()))
    cost[(column + free + size)[open_]] = 1.0
    lower = np.full(len(cost), -np.inf)
    lower[(column + free + size)[open_]] = 0.0
    z = Z[p, j]
    res = linprog(cost, A_ub=A, b_ub=np.concatenate([-z, z]),
                  bounds=np.column_stack([lower, np.full(len(cost), np.inf)]),
                  method="highs")
    return res, column


def _refit_constraints(u: np.ndarray, k_column: np.ndarray, c_column: np.ndarray,
                       t_column: np.ndarray, columns: int) -> sp.csr_matrix:
    """The constraint matrix of `_refit_molds`'s linear program, (2 m, columns) CSR.

    For every active sample (m, with its scaled squared coordinates `u` (m, free)) the rows
    of ``z - u.k/2 - c <= t`` and ``-(z - u.k/2 - c) <= t``, ``k`` its mold's curvatures
    (columns ``k_column + 0 .. free - 1``), ``c`` its panel's shift (column `c_column`) and
    ``t`` its mold's gap (column `t_column`); zeros of ``u/2`` left out.
    """
    m, free = u.shape
    half = 0.5 * u
    row, col = np.nonzero(half)
    rows = np.arange(m)
    minus = -np.ones(m)
    k = k_column[row] + col
    row_all = np.concatenate([row, rows, rows, row + m, rows + m, rows + m])
    col_all = np.concatenate([k, c_column, t_column, k, c_column, t_column])
    data = np.concatenate([-half[row, col], minus, minus, half[row, col], -minus, minus])
    return sp.csr_matrix((data, (row_all, col_all)), shape=(2 * m, columns))


def _mark_extremes(active: np.ndarray, U: np.ndarray, Z: np.ndarray, K: np.ndarray) -> None:
    """Mark in `active` (q, s) each panel's highest and lowest sample above its mold, `K`
    (q, 2) per panel (1/mm)."""
    r = Z - 0.5 * (U[..., 0] * K[:, 0, None] + U[..., 1] * K[:, 1, None])
    rows = np.arange(len(Z))
    active[rows, r.argmax(axis=1)] = True
    active[rows, r.argmin(axis=1)] = True


def _thin_candidates(K: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Indices of candidate molds, one per grid cell of their own scale.

    A candidate from a panel of reach ``r`` (see `_panel_data`) falls in a cell of side
    about ``r / 64`` (a power of two, so cells of different scales nest): moving a mold
    that far changes its gaps by about a sixteenth of the tolerance, so candidates closer
    than that cover nearly the same panels. The first candidate of every cell is kept.
    """
    cell = 2.0 ** np.floor(np.log2(np.maximum(reach, 1e-300) / 64.0))
    key = np.column_stack([np.log2(cell), np.floor(K / cell[:, None])])
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


@dataclass
class _Stage:
    """The molds of one type and the assignment of that type's panels (internal)."""

    molds: np.ndarray       # (m, 2) 1/mm
    mold: np.ndarray        # (n,) mold index of each panel
    variant: np.ndarray     # (n,) placement frame of each panel


def _assign(data: _Panels, candidates: np.ndarray, free: int, tolerance: float,
            rounds: int) -> _Stage:
    """Cover the panels by molds, then refit, reassign and remove molds until stable.

    ``candidates`` (c, 2): one candidate mold per panel (its own shape), thinned here by
    `_thin_candidates`, or the only mold of a plane.
    """
    n = len(data.shapes)
    if n == 0:
        return _Stage(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(candidates) == n:
        candidates = candidates[_thin_candidates(candidates[:, :max(free, 1)], data.reach)]
    dev, _ = _gap_matrix(data, candidates)
    fits = dev <= tolerance
    molds = candidates[_greedy_cover(fits)]
    # a panel that no candidate fits gets a mold of its own shape (refitted below)
    alone = np.flatnonzero(~fits.any(axis=1))
    if alone.size:
        own = data.shapes[alone, 0].copy()
        own[:, free:] = 0.0
        molds = np.concatenate([molds, own])
    mold = np.full(n, -1)
    state: tuple[int, bytes] | None = None
    # (mold, members, placements) already refitted: a refit is a fixpoint
    refitted: set[tuple[bytes, bytes, bytes]] = set()
    for _ in range(max(rounds, 1)):
        dev, var = _gap_matrix(data, molds)
        rows = np.arange(n)
        # every panel to its closest mold; a panel stays unless another fits strictly better
        best = np.argmin(dev, axis=1)
        stay = (mold >= 0) & (dev[rows, np.maximum(mold, 0)] <= dev[rows, best])
        mold = np.where(stay, mold, best)
        mold, molds, dev, var = _remove_molds(mold, molds, dev, var, tolerance)
        variant, deviation = var[rows, mold], dev[rows, mold]
        groups = [np.flatnonzero(mold == j) for j in range(len(molds))]
        keys = [(molds[j].tobytes(), m.tobytes(), variant[m].tobytes())
                for j, m in enumerate(groups)]
        todo = [j for j in range(len(molds)) if keys[j] not in refitted]
        if todo:
            members = np.concatenate([groups[j] for j in todo])
            owner = np.repeat(np.arange(len(todo)), [groups[j].size for j in todo])
            U, Z = data.U[members, variant[members]], data.Z[members, variant[members]]
            reach = np.array([np.median(data.reach[groups[j]]) for j in todo])
            new = _refit_molds(U, Z, owner, molds[todo], free, reach)
            gap = np.zeros(len(todo))
            np.maximum.at(gap, owner, _offset_gap(U, Z, new[owner])[0])
            worst = np.zeros(len(todo))
            np.maximum.at(worst, owner, deviation[members])
            for i, j in enumerate(todo):
                if gap[i] <= worst[i]:
                    molds[j] = new[i]
                refitted.add((molds[j].tobytes(), keys[j][1], keys[j][2]))
        settled = (len(molds), mold.tobytes())
        if settled == state:
            break
        state = settled
    _, var = _gap_matrix(data, molds)
    return _Stage(molds=molds, mold=mold, variant=var[np.arange(n), mold])


def _remove_molds(mold: np.ndarray, molds: np.ndarray, dev: np.ndarray, var: np.ndarray,
                  tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop molds (fewest panels first) whose panels all fit another remaining mold, moving
    each of them to its closest remaining mold."""
    alive = np.ones(len(molds), bool)
    fits = dev <= tolerance
    counts = np.bincount(mold, minlength=len(molds))
    for j in np.lexsort((np.arange(len(molds)), counts)):
        members = np.flatnonzero(mold == j)
        others = alive.copy()
        others[j] = False
        if members.size and not np.all((fits[members] & others).any(axis=1)):
            continue
        if members.size:
            d = np.where(others, dev[members], np.inf)
            mold[members] = np.argmin(d, axis=1)
        alive[j] = False
    renumber = np.cumsum(alive) - 1
    return renumber[mold], molds[alive].copy(), dev[:, alive], var[:, alive]


def plan_molds(mesh: QuadMesh, settings: MoldSettings | None = None, *, design: Any = None,
               **options: Any) -> MoldPlan:
    """Find few molds that fit every panel of a net, and verify every panel on its mold.

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh` (faces of any size).
    settings : `MoldSettings`; or give its fields as keyword options
        (``plan_molds(mesh, tolerance_mm=5, units="m")``).
    design : the `fabplan.design.DesignSurface` the net lies on, when it was laid out on one
        and held there: with an exact surface (a built-in or NURBS design) the panels are
        its patches (panel surface ``design``, `fabplan.fabricate.panels`).

    Returns
    -------
    MoldPlan

    Raises
    ------
    InputError
        For impossible settings, a net without faces or with a degenerate face.
    """
    start = time.perf_counter()
    settings = _checked_settings(settings, options)
    check_panels(mesh)
    mm = settings.mm_per_unit
    tol = settings.tolerance_mm
    work = settings.working_tolerance_mm
    clock: dict[str, float] = {}

    model = _PanelModel.fit(mesh, surface_model(mesh, tol / mm, settings.panel_surface, design),
                            design, settings.cover_level)
    shapes = panel_shapes(model.surfaces)
    frames, kk = placement_frames(shapes)
    kk = kk / mm
    data = _panel_data(model.points, shapes.point, frames, kk, mm, work)
    clock["panel model"] = time.perf_counter() - start

    panel_type, cylinder = _classify(data, work)
    # the dense samples verify the molds below; with a material they decide every panel's
    # class first (the classes do not change the molds' assignment: the molds the curved
    # panels would need are planned in full, and only those of molded panels are made)
    dense = model.samples(mesh, settings.verify_level)
    classes = None if settings.material is None else classify_panels(
        mesh, dense, shapes.normal, settings.material, tol, mm, settings.class_order)
    clock["classification"] = time.perf_counter() - start - sum(clock.values())
    cast = _Casting(dense, shapes.point, frames, kk, mm, work, settings.rounds, panel_type,
                    *_assign_by_type(data, panel_type, cylinder, work, settings.rounds))
    clock["assignment"] = time.perf_counter() - start - sum(clock.values())

    # verification on dense samples; a panel found above the tolerance is classified again
    # on them (it may be more curved than the assignment samples showed) and gets a new mold
    cast.placement, deviation = _place(dense, shapes.point, frames, cast.variant,
                                       cast.mold_shape[cast.mold], mm)
    over = np.flatnonzero(deviation > tol)
    if over.size:
        cast.recast(over, work)
    step, kink, surface_step, stepped = cast.close_steps(mesh, model, settings)
    cast.classify_moved()
    clock["steps"] = time.perf_counter() - start - sum(clock.values())
    footprint, deviation = cast.measure()
    clock["verification"] = time.perf_counter() - start - sum(clock.values())

    n = len(panel_type)
    problem = _problems(deviation, footprint, tol, settings.max_mold_size_mm)
    curvature = np.column_stack([shapes.k1, shapes.k2]) / mm
    weingarten = weingarten_fit(curvature[:, 0], curvature[:, 1])
    # the panels as triangle meshes: the assignment's samples when they are at that level
    surface = panel_surface_mesh(mesh, model.points if settings.cover_level == PANEL_MESH_LEVEL
                                 else model.samples(mesh, PANEL_MESH_LEVEL), PANEL_MESH_LEVEL)
    clock["panel meshes"] = time.perf_counter() - start - sum(clock.values())
    return MoldPlan(mesh=mesh, settings=settings, panel_surface=model.kind, panel_type=panel_type,
                    curvature=curvature, mold_type=cast.mold_type, mold_shape=cast.mold_shape,
                    panel_shape=kk[np.arange(n), cast.variant], mold=cast.mold,
                    placement=cast.placement, deviation_mm=deviation, footprint_mm=footprint,
                    problem=problem, weingarten=weingarten, reassigned=over,
                    step_mm=step, kink_deg=kink, surface_step_mm=surface_step,
                    recast_for_steps=stepped, classes=classes, surface=surface,
                    seconds=time.perf_counter() - start, stage_seconds=clock)


def _checked_settings(settings: MoldSettings | None, options: dict[str, Any]) -> MoldSettings:
    """The settings given, or made of the keyword `options`, checked."""
    if settings is None:
        settings = MoldSettings(**options)
    elif options:
        raise InputError("give either settings or keyword options, not both")
    settings.check()
    return settings


@dataclass
class _PanelModel:
    """The panels' surfaces of one model (``kind``: a name of
    `fabplan.fabricate.panels.PANEL_SURFACES`) and their assignment samples.

    Attributes
    ----------
    kind : the panel surface model.
    surfaces : the fitted panel surfaces.
    points : (p, s, 3) float, the samples the assignment fits molds to (model units): those
        the quadrics of the design and shared models were fitted to, else a cover of the
        surfaces.
    local : the panels' own local fits the shared model starts from (None for the others).
    design : the design surface of the ``design`` model (None for the others).
    """

    kind: str
    surfaces: Any
    points: np.ndarray
    local: Any = None
    design: Any = None

    @classmethod
    def fit(cls, mesh: QuadMesh, kind: str, design: Any, level: int) -> _PanelModel:
        """Fit the panel surfaces of `kind` and sample them at the cover `level`."""
        if kind == "design":
            surfaces, points = fit_design_panels(mesh, design, level)
            return cls(kind, surfaces, points, design=design)
        if kind == "shared":
            local = fit_panel_surfaces(mesh, "local_fit")
            surfaces, points = fit_shared_panels(mesh, local, level)
            return cls(kind, surfaces, points, local=local)
        surfaces = fit_panel_surfaces(mesh, kind)
        return cls(kind, surfaces, panel_samples(mesh, surfaces, level))

    def samples(self, mesh: QuadMesh, level: int) -> np.ndarray:
        """(p, s, 3) float, the panels sampled at `level` (model units)."""
        if self.kind == "design":
            return design_panel_samples(mesh, self.surfaces, self.design, level)
        if self.kind == "shared":
            return shared_panel_samples(mesh, self.local, level)
        return panel_samples(mesh, self.surfaces, level)


@dataclass
class _Casting:
    """The panels on their molds while the plan verifies them and casts some anew.

    Attributes
    ----------
    dense : (p, s, 3) float, the dense verification samples (model units).
    point : (p, 3) float, frames : (p, 4, 3, 3) float, kk : (p, 4, 2) float, every panel's
        centre, placement frames and shapes per frame (1/mm), as `placement_frames` gives.
    mm : millimetres per model unit; work : the working tolerance (mm); rounds : the
        assignment's refit rounds.
    panel_type : (p,) int, the panel types (raised where the dense samples show more curve).
    mold, variant : (p,) int, every panel's mold and placement frame.
    mold_shape : (m, 2) float, mold_type : (m,) int, the molds.
    placement : (p, 4, 4) float, the panels' placements on their molds (set once verified).
    """

    dense: np.ndarray
    point: np.ndarray
    frames: np.ndarray
    kk: np.ndarray
    mm: float
    work: float
    rounds: int
    panel_type: np.ndarray
    mold: np.ndarray
    variant: np.ndarray
    mold_shape: np.ndarray
    mold_type: np.ndarray
    placement: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))

    def recast(self, faces: np.ndarray, tolerance: float) -> None:
        """Classify `faces` again on the dense samples (at the working tolerance) and give
        them new molds of their own at `tolerance` (mm)."""
        mm, work = self.mm, self.work
        data = _panel_data(self.dense[faces], self.point[faces], self.frames[faces],
                           self.kk[faces], mm, tolerance)
        dense_type, cylinder = _classify(data, work)
        self.panel_type[faces] = np.maximum(self.panel_type[faces], dense_type)
        new = _assign_by_type(data, self.panel_type[faces], cylinder, tolerance, self.rounds)
        self.mold[faces] = new[0] + len(self.mold_shape)
        self.variant[faces] = new[1]
        self.mold, self.mold_shape, self.mold_type = _drop_empty(
            self.mold, np.concatenate([self.mold_shape, new[2]]),
            np.concatenate([self.mold_type, new[3]]))
        self.placement, _ = _place(self.dense, self.point, self.frames, self.variant,
                                   self.mold_shape[self.mold], mm)

    def close_steps(self, mesh: QuadMesh, model: _PanelModel, settings: MoldSettings
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cast the panels of edges whose molds step apart by more than the limit on closer
        molds, round by round; the steps (mm) and kinks (deg) of the interior edges, the
        steps of the panel surfaces alone (mm) and the panels recast."""
        mm, work, tol = self.mm, self.work, settings.tolerance_mm
        # neighbours whose molds step apart by more than twice the tolerance: the panels of
        # those edges are cast on molds of their own that fit them closer, halving the gap
        # each round (a step is at most the two gaps plus what the panel surfaces differ by:
        # where these alone take up the limit, closer molds cannot help and would only add
        # molds)
        fractions = np.asarray(settings.step_fractions, float)
        step, kink = panel_steps(mesh, self.placement, self.mold_shape[self.mold], mm,
                                 fractions=fractions)
        # pieces of one surface share their edges; the other panels' surfaces may differ there
        surface_step = (np.zeros(len(mesh.interior_edge_faces)) if model.kind in ("design", "shared")
                        else surface_steps(mesh, model.surfaces, fractions) * mm)
        step_limit = 2.0 * tol if settings.step_limit_mm is None else float(settings.step_limit_mm)
        closable = surface_step + 2.0 * work * 0.5**STEP_ROUNDS <= step_limit
        stepped = np.zeros(0, np.int64)
        for k in range(1, STEP_ROUNDS + 1):
            faces = np.unique(mesh.interior_edge_faces[(step > step_limit) & closable])
            if faces.size == 0:
                break
            stepped = np.union1d(stepped, faces)
            self.recast(faces, work * 0.5**k)
            step, kink = panel_steps(mesh, self.placement, self.mold_shape[self.mold], mm,
                                     fractions=fractions)
        return step, kink, surface_step, stepped

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """Every panel's footprint on its mold, (p, 2) float (mm), and its gap to the mold
        measured on the dense samples, (p,) float (mm)."""
        placement = self.placement
        q = np.einsum("pij,psj->psi", placement[:, :3, :3], self.dense) + placement[:, None, :3, 3]
        footprint = 2.0 * np.abs(q[..., :2]).max(axis=1)
        return footprint, placement_deviations(self.dense, placement, self.mold_shape[self.mold])

    def classify_moved(self) -> None:
        """Classify on the dense samples the panels classified single curved on the
        assignment samples but cast on a doubly curved mold (`_merge_curved_molds`): they
        were never checked against a cylinder there."""
        moved = np.flatnonzero((self.panel_type == 1) & (self.mold_type[self.mold] != 1))
        if moved.size:
            data = _panel_data(self.dense[moved], self.point[moved], self.frames[moved],
                               self.kk[moved], self.mm, self.work)
            self.panel_type[moved] = np.maximum(self.panel_type[moved],
                                                _classify(data, self.work)[0])


def _problems(deviation: np.ndarray, footprint: np.ndarray, tol: float,
              max_mold_size_mm: float | None) -> list[str | None]:
    """Every panel's problem in words (None where it fits): a gap over the tolerance `tol`
    (mm), or a footprint (p, 2) larger than the largest mold."""
    problem: list[str | None] = [None] * len(deviation)
    for i in np.flatnonzero(deviation > tol):
        problem[i] = f"deviates {deviation[i]:.3f} mm from its mold (tolerance {tol:g} mm)"
    if max_mold_size_mm is not None:
        limit = max_mold_size_mm
        for i in np.flatnonzero(footprint.max(axis=1) > limit):
            problem[i] = (f"needs a mold of {footprint[i, 0]:.0f} x {footprint[i, 1]:.0f} mm, "
                          f"larger than the largest mold ({limit:g} mm)")
    return problem


def _classify(data: _Panels, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Panel types (indices into `PANEL_TYPES`): planar when the plane, else single curved
    when the best cylinder mold fits within `tolerance` (mm), else double curved; and the
    best cylinder curvature of every panel (1/mm)."""
    plane = _offset_gap(data.U[:, 0], data.Z[:, 0], np.zeros(2))[0]
    cylinder, cylinder_gap = _cylinder_fits(data.U[:, 0], data.Z[:, 0], data.shapes[:, 0, 0])
    return np.where(plane <= tolerance, 0, np.where(cylinder_gap <= tolerance, 1, 2)), cylinder


def _assign_by_type(data: _Panels, panel_type: np.ndarray, cylinder: np.ndarray,
                    tolerance: float, rounds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Molds for panels, each type on molds of its own type (plane, cylinder, paraboloid).

    Returns mold (p,) int, variant (p,) int, mold shapes (m, 2), mold types (m,) int.
    """
    n = len(panel_type)
    mold = np.zeros(n, np.int64)
    variant = np.zeros(n, np.int64)
    shapes, types = [np.zeros((0, 2))], [np.zeros(0, np.int64)]
    count = 0
    for t, kind in enumerate(MOLD_TYPES):
        idx = np.flatnonzero(panel_type == t)
        if idx.size == 0:
            continue
        sub = _subset(data, idx)
        if kind == "plane":
            candidates = np.zeros((1, 2))
        elif kind == "cylinder":
            candidates = np.column_stack([cylinder[idx], np.zeros(idx.size)])
        else:
            candidates = sub.shapes[:, 0]
        order = np.lexsort((candidates[:, 1], candidates[:, 0]))
        stage = _assign(sub, candidates[order], _FREE_DIMS[kind], tolerance, rounds)
        mold[idx] = stage.mold + count
        variant[idx] = stage.variant
        shapes.append(stage.molds)
        types.append(np.full(len(stage.molds), t))
        count += len(stage.molds)
    return _merge_curved_molds(data, mold, variant, np.concatenate(shapes),
                               np.concatenate(types), tolerance)


def _merge_curved_molds(data: _Panels, mold: np.ndarray, variant: np.ndarray,
                        shapes: np.ndarray, types: np.ndarray, tolerance: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drop the cylinder or paraboloid molds whose panels all fit the other curved molds.

    A single curved panel may sit on a doubly curved mold (and a doubly curved one on a
    cylinder, within the tolerance). Without this, a looser tolerance that lets a few
    panels pass as single curved would give them a cylinder mold of their own beside the
    paraboloid mold that already fits them: more molds at a looser tolerance.
    """
    curved = np.flatnonzero(types[mold] > 0)
    kept = np.flatnonzero(types > 0)
    if len(np.unique(types[kept])) < 2:
        return mold, variant, shapes, types
    local = np.full(len(shapes), -1)
    local[kept] = np.arange(len(kept))
    dev, var = _gap_matrix(_subset(data, curved), shapes[kept])
    members = local[mold[curved]]
    # a panel's own mold fits it on the assignment samples, whatever the gap matrix's
    # reach cut says
    dev[np.arange(len(curved)), members] = np.minimum(dev[np.arange(len(curved)), members],
                                                      tolerance)
    tagged = np.column_stack([shapes[kept], kept])         # which molds survive
    members, tagged, dev, var = _remove_molds(members, tagged, dev, var, tolerance)
    survivors = tagged[:, 2].astype(np.int64)
    if len(survivors) == len(kept):
        return mold, variant, shapes, types
    moved = survivors[members] != mold[curved]
    variant = variant.copy()
    variant[curved[moved]] = var[np.flatnonzero(moved), members[moved]]
    mold = mold.copy()
    mold[curved] = survivors[members]
    mold, shapes, types = _drop_empty(mold, shapes, types)
    return mold, variant, shapes, types


def _subset(data: _Panels, idx: np.ndarray) -> _Panels:
    return _Panels(shapes=data.shapes[idx], U=data.U[idx], Z=data.Z[idx], reach=data.reach[idx])


def _drop_empty(mold: np.ndarray, mold_shape: np.ndarray,
                mold_type: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    used = np.bincount(mold, minlength=len(mold_shape)) > 0
    renumber = np.cumsum(used) - 1
    return renumber[mold], mold_shape[used], mold_type[used]


def _place(points: np.ndarray, point: np.ndarray, frames: np.ndarray, variant: np.ndarray,
           shape: np.ndarray, mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Placement matrices (frame of the chosen variant, shift evening out the gap) and the
    resulting deviations, for samples (p, s, 3) and mold shapes (p, 2)."""
    R = frames[np.arange(len(variant)), variant]                     # (p, 3, 3)
    Q = mm * np.einsum("pij,psj->psi", R, points - point[:, None, :])
    dev, shift = _offset_gap(Q[..., :2] ** 2, Q[..., 2], shape)
    placement = np.zeros((len(variant), 4, 4))
    placement[:, :3, :3] = mm * R
    placement[:, :3, 3] = -mm * np.einsum("pij,pj->pi", R, point)
    placement[:, 2, 3] -= shift
    placement[:, 3, 3] = 1.0
    return placement, dev
