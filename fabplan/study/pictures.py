"""The pictures of a study report, each a PNG data URI: a candidate's deviation heat map,
the candidates side by side (molds and deviation), a search's points against its
parameter, and the Pareto plot of the cost drivers.
"""

from __future__ import annotations

import base64
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..report import figures, viewer
from ..report.figures import agreeing_normal
from .candidate_measure import vertex_deviation_mm
from .ranking import cost_drivers
from .result import CandidateResult, StudyResult

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface


__all__ = ["deviation_view", "deviation_figure", "comparison_figure", "search_figure",
           "PARETO_MIN_CANDIDATES", "pareto_figure", "png_uri"]


def _view(mesh):
    from ..fabricate.molds.mold_report import facade_view

    return facade_view(mesh)


def deviation_view(mesh, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Face normals and a viewing frame for a heat map that must show `point`.

    A facade is seen from in front (as the mold pictures); a roof from 30 degrees above
    and a closed surface (a ring, a barrel) from 10 degrees above, both from the side of
    `point`, so that the worst point is on the near side, not hidden behind the near
    wall or foreshortened at the far edge.
    """
    normals, view = _view(mesh)
    X = mesh.vertices
    _, initial = viewer.scene_front(normals, mesh.face_areas, X)
    roof = initial == "above"
    if roof or agreeing_normal(normals, mesh.face_areas) is None:
        out = point - X.mean(axis=0)
        out[2] = 0.0
        if np.linalg.norm(out) > 1e-9 * np.ptp(X, axis=0).max():
            view = figures.elevation_frame(out[:2], 30.0 if roof else 10.0)
    return normals, view


def deviation_figure(c: CandidateResult, design: DesignSurface, limit_mm: float,
                     mm_per_unit: float) -> str:
    """Data URI: the net coloured by its distance from the design (mm) at every vertex.

    The distance is measured at the vertices and interpolated linearly across the
    triangles of each panel (Gouraud shading), so the largest value shows at its vertex;
    that vertex is circled and labelled. Faces are drawn far to near in depth layers with
    their edges, so nearer panels hide farther ones.
    """
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    if c.net is None:
        raise ValueError(f"candidate {c.name!r} has no net to draw (it failed)")
    mesh = c.net.mesh
    X = mesh.vertices
    d = c.deviation_mm if c.deviation_mm is not None else vertex_deviation_mm(mesh, design, mm_per_unit)
    worst = int(np.argmax(d))
    _, view = deviation_view(mesh, X[worst])
    P = X @ view.T
    sizes = mesh.face_sizes
    owner = np.repeat(np.arange(len(sizes)), sizes)
    depth = np.bincount(owner, P[mesh.face_indices, 2], minlength=len(sizes)) / sizes
    layers = 40
    layer = np.empty(len(sizes), np.int64)
    layer[np.argsort(depth, kind="stable")] = np.arange(len(sizes)) * layers // len(sizes)
    tri = mesh.triangles()
    tri_layer = np.repeat(layer, sizes - 2)
    polys = np.split(P[mesh.face_indices, :2], mesh.face_indptr[1:-1])
    # the scale reaches past the limit, so that the limit's mark sits inside it
    top = max(1.15 * limit_mm, float(d.max()), 1e-9)
    norm = Normalize(0.0, top)
    cmap = colormaps["viridis"]
    fig = figures.new_figure((8, 6))
    ax = fig.subplots()
    for k in range(layers):
        ids = np.flatnonzero(tri_layer == k)
        if ids.size == 0:
            continue
        ax.tripcolor(P[:, 0], P[:, 1], d, triangles=tri[ids], shading="gouraud", cmap=cmap,
                     norm=norm, zorder=2 * k)
        ax.add_collection(PolyCollection([polys[f] for f in np.flatnonzero(layer == k)],
                                         facecolors="none", edgecolors=(0.1, 0.1, 0.1, 0.5),
                                         linewidths=0.2, zorder=2 * k + 1))
    ax.plot(P[worst, 0], P[worst, 1], "o", ms=14, mfc="none", mec="#c0392b", mew=2.2,
            zorder=2 * layers + 2)
    # the label points inwards, so that it stays inside the picture
    right = P[worst, 0] > 0.5 * (P[:, 0].min() + P[:, 0].max())
    above = P[worst, 1] > 0.5 * (P[:, 1].min() + P[:, 1].max())
    ax.annotate(f"max {d[worst]:.1f} mm", (P[worst, 0], P[worst, 1]),
                xytext=(-14 if right else 14, -14 if above else 14), textcoords="offset points",
                ha="right" if right else "left", va="top" if above else "bottom",
                color="#c0392b", fontsize=10, fontweight="bold", zorder=2 * layers + 3,
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "#c0392b", "alpha": 0.85})
    pad = 0.03 * np.ptp(P[:, :2], axis=0).max()      # the circle must not be cut at an edge
    ax.set_xlim(P[:, 0].min() - pad, P[:, 0].max() + pad)
    ax.set_ylim(P[:, 1].min() - pad, P[:, 1].max() + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.8)
    bar.set_label("distance from the design at the vertices [mm]")
    bar.ax.axhline(limit_mm, color="white", lw=5)
    bar.ax.axhline(limit_mm, color="#c0392b", lw=2.5)
    bar.ax.text(-0.15, limit_mm, f"limit {limit_mm:g} ", color="#c0392b", fontweight="bold",
                fontsize=9, ha="right", va="center", transform=bar.ax.get_yaxis_transform())
    ax.set_title(f"{c.name}: deviation from the design\nmax {d.max():.1f} mm (circled), "
                 f"limit {limit_mm:g} mm (red line on the scale)")
    return figures.figure_to_data_uri(fig)


def comparison_figure(result: StudyResult) -> str:
    """Data URI: molds and deviation of every measured candidate, limits marked."""
    done = [c for c in result.ranked() if not c.failed]
    limits = result.study.limits
    names = [c.name for c in done]
    colors = ["#2e8b57" if c.feasible else "#c0392b" for c in done]
    fig = figures.new_figure((12, 0.45 * len(done) + 1.8))
    left, right = fig.subplots(1, 2)
    y = np.arange(len(done))
    molds = [c.metrics["molds"]["count"] for c in done]
    left.barh(y, molds, color=colors)
    left.set_yticks(y, names)
    left.invert_yaxis()
    left.set_xlabel("molds (for the curved panels; flat panels need none)")
    if limits.max_molds is not None:
        left.axvline(limits.max_molds, color="black", ls="--", lw=1, label="limit")
        left.legend(loc="lower right")
    for yi, n in zip(y, molds, strict=True):
        left.text(n, yi, f" {n}", va="center", fontsize=8)
    dev = [c.metrics["largest_deviation_mm"] for c in done]
    right.barh(y, dev, color=colors)
    right.set_yticks(y, [""] * len(done))
    right.invert_yaxis()
    right.axvline(limits.max_deviation_mm, color="black", ls="--", lw=1, label="limit")
    right.set_xlabel("largest deviation from the design [mm]")
    right.legend(loc="lower right")
    for yi, v in zip(y, dev, strict=True):
        right.text(v, yi, f" {v:.1f}", va="center", fontsize=8)
    fig.suptitle("Candidates in rank order (green: feasible, red: not)")
    fig.tight_layout()
    return figures.figure_to_data_uri(fig)


def search_figure(result: StudyResult, record: dict) -> str:
    """Data URI: a search's cost, molds and largest deviation against its parameter, the
    feasible points green, the others red, the feasible range shaded, the best ringed."""
    points = [p for p in record["points"] if not p["failed"]]
    unit = "deg" if record["parameter"] == "angle" else result.study.design.units
    limits = result.study.limits
    fig = figures.new_figure((9, 7))
    axes = fig.subplots(3, 1, sharex=True)
    x = np.array([p["value"] for p in points])
    ok = np.array([p["feasible"] for p in points], bool)
    series = (("cost", "cost [units]", None), ("molds", "molds", limits.max_molds),
              ("deviation_mm", "largest deviation [mm]", limits.max_deviation_mm))
    for ax, (key, label, limit) in zip(axes, series, strict=True):
        y = np.array([p[key] for p in points], float)
        ax.plot(x, y, color="0.6", lw=1, zorder=1)
        ax.scatter(x[ok], y[ok], color="#2e8b57", zorder=2, label="meets every limit")
        ax.scatter(x[~ok], y[~ok], color="#c0392b", marker="x", zorder=2, label="does not")
        if limit is not None:
            ax.axhline(limit, color="black", ls="--", lw=1, label="limit")
        if record["feasible_range"] is not None:
            ax.axvspan(*record["feasible_range"], color="#2e8b57", alpha=0.12, lw=0)
        best = next((p for p in points if p["candidate"] == record["best"]), None)
        if best is not None:
            ax.scatter([best["value"]], [best[key]], s=160, facecolors="none",
                       edgecolors="black", zorder=3, label="best")
        ax.set_ylabel(label)
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel(f"{record['parameter']} [{unit}]")
    fig.suptitle(f"Search of {record['name']}: {len(record['points'])} of at most "
                 f"{record['budget']} solves")
    fig.tight_layout()
    return figures.figure_to_data_uri(fig)



#: Studies with at least this many measured candidates get the Pareto plot.
PARETO_MIN_CANDIDATES = 3


def pareto_figure(result: StudyResult) -> str:
    """Data URI: the cost drivers of every measured candidate (molds and, with strips,
    sheets against the largest deviation), feasible ones filled, the Pareto-optimal ones
    (`fabplan.study.ranking.pareto_optimal`) ringed and named, the recommended one starred."""
    done = [c for c in result.ranked() if not c.failed]
    drivers = cost_drivers(done)
    limits = result.study.limits
    axes_x = [(0, "molds [count]", limits.max_molds)]
    if drivers[:, 1].any():
        axes_x.append((1, "strip sheets [count]", limits.max_sheets))
    from matplotlib.ticker import MaxNLocator

    fig = figures.new_figure((6.2 * len(axes_x), 5.2))
    feasible = np.array([c.feasible for c in done])
    optimal = np.array([c.pareto for c in done])
    best = np.array([c.name == result.recommended for c in done])
    for k, (column, label, limit) in enumerate(axes_x):
        ax = fig.add_subplot(1, len(axes_x), k + 1)
        x, y = drivers[:, column], drivers[:, 2]
        ax.scatter(x[feasible], y[feasible], s=42, color="#2e8b57", label="feasible", zorder=3)
        ax.scatter(x[~feasible], y[~feasible], s=42, marker="x", color="#c0392b",
                   label="not feasible", zorder=3)
        ax.scatter(x[optimal], y[optimal], s=150, facecolors="none", edgecolors="black",
                   lw=1.2, label="Pareto-optimal", zorder=4)
        if best.any():
            ax.scatter(x[best], y[best], s=260, marker="*", color="#f1c40f",
                       edgecolors="black", lw=0.8, label="recommended", zorder=5)
        # one label per point: candidates at the same place share it
        named: dict[tuple[float, float], list[str]] = {}
        for c, xi, yi in zip(done, x, y, strict=True):
            if c.pareto or c.name == result.recommended:
                named.setdefault((float(xi), round(float(yi), 1)), []).append(c.name)
        for (xi, yi), names in named.items():
            ax.annotate(",\n".join(names), (xi, yi), xytext=(6, 4), textcoords="offset points",
                        fontsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.axhline(limits.max_deviation_mm, color="black", ls="--", lw=1)
        if limit is not None:
            ax.axvline(limit, color="black", ls="--", lw=1)
        ax.set_xlabel(label)
        ax.set_ylabel("largest deviation from the design [mm]")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=8, loc="best")
    fig.suptitle("Cost drivers of every candidate (lower left is better; dashed: limits)")
    fig.tight_layout()
    return figures.figure_to_data_uri(fig)


def png_uri(path: Path) -> str:
    png = figures.compact_png(path.read_bytes())
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")
