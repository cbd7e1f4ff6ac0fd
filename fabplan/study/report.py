"""The files of a facade study: ``report.html``, ``study.json``, ``candidates.csv`` and,
per candidate, the net (OBJ + measured JSON), its molds (CSV, JSON) and strips (DXF).

The output folder is built beside its destination and moved into place only when every
file is written: a failed run leaves no partial folder. The schema of ``study.json`` is
``docs/study-schema.md``; every number of the report is in it.
"""

from __future__ import annotations

import base64
import csv
import io
import math
import os
import re
import time
from html import escape as html_escape
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from ..fabricate.molds.mold_report import net_viewer_scene
from ..io import output
from ..io.forked import ForkedFile
from ..io.records import json_text
from ..layout.picture import (
    curvature_difference_figure,
    fairness_marks,
    write_layout_picture,
)
from ..layout.picture import kink_text as layout_kink_text
from ..report import figures, html, viewer
from ..report.figures import agreeing_normal
from ..report.html import counted, format_range
from ..report.pdf import PdfDocument
from .cache import CACHE_FOLDER
from .candidate_measure import vertex_deviation_mm
from .checks import LIMIT_NAMES, binding_check, relaxation_text
from .mold_counts import material_sentence, molds_text
from .ranking import cost_drivers
from .result import CandidateResult, StudyResult
from .search import search_record
from .verdict import every_panel_flat

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from .definition import Study

__all__ = ["write_study", "study_record", "check_output_folder", "STUDY_SCHEMA", "LIMIT_NAMES",
           "coverage_gap_triangles", "study_viewer_scenes", "candidate_file_bytes",
           "candidate_files_task"]

STUDY_SCHEMA = "fabplan-study/1"


# ---------------------------------------------------------------------------- records
def _candidate_record(c: CandidateResult, outputs: dict, recommended: str | None,
                      study: Study) -> dict:
    return {
        "name": c.name,
        "net": c.candidate.net,
        "description": c.candidate.describe(),
        "baseline": c.candidate.baseline,
        "recommended": c.name == recommended,
        "requested": {"angle_deg": c.candidate.angle, "radius": c.candidate.radius,
                      "panel_size": study.panel_size_of(c.candidate),
                      "mold_tolerance_mm": study.mold_tolerance_of(c.candidate)},
        "feasible": c.feasible,
        "reasons": c.reasons,
        "same_net_as": c.same_net_as,
        "notes": c.notes,
        "error": c.error,
        "checks": c.checks,
        "binding_limit": None if (b := binding_check(c.checks)) is None else b["limit"],
        "relaxation": relaxation_text(c.checks) or None,
        "metrics": c.metrics,
        "cost": c.cost,
        "cost_terms": c.cost_terms,
        "rank": c.rank,
        "pareto": c.pareto,
        "outputs": outputs,
    }


def study_record(result: StudyResult, outputs: dict | None = None, *,
                 seconds_total: float | None = None) -> dict:
    """The ``study.json`` record (schema ``docs/study-schema.md``).

    `seconds_total` is the wall time including writing the files (`write_study` measures
    it); without it, the run time.
    """
    outputs = outputs or {}
    design = result.design
    triangles = int(len(design.triangles))
    study = result.study.record()
    if study["design"]["triangles"] is None:          # a design file: its own triangles
        study["design"]["triangles"] = triangles
    return {
        "schema": STUDY_SCHEMA,
        "study": study,
        "design": {"label": result.study.design.label, "source": result.study.design.source,
                   "triangles": triangles, "area": float(design.area),
                   "size": result.design_size, "units": result.study.design.units},
        "recommended": result.recommended,
        "recommendation": result.recommendation,
        "sheets_charged": result.sheets_charged,
        "candidates": [_candidate_record(c, outputs.get(c.name, {}), result.recommended,
                                         result.study)
                       for c in result.candidates],
        "searches": [search_record(s, result.candidates) for s in result.study.searches],
        "seconds_run": result.seconds_run,
        "seconds_total": result.seconds_run if seconds_total is None else seconds_total,
        # fabplan-study/1 readers knew the run time as `seconds`: the same as seconds_total
        "seconds": result.seconds_run if seconds_total is None else seconds_total,
    }


_CSV_COLUMNS = ["rank", "name", "net", "panel_size", "mold_tolerance_mm", "feasible", "cost",
                "molds", "panels", "boundary_panels",
                "planar", "single_curved", "double_curved", "coverage", "coverage_full_panels",
                "folded", "deviation_max_mm",
                "deviation_p95_mm",
                "planarity_max_mm", "kink_max_deg", "angle_min_deg", "angle_max_deg",
                "radius_min", "radius_max", "sheets", "strips_congruent", "seconds", "reasons"]


def _row(c: CandidateResult, study: Study) -> dict:
    m = c.metrics
    asked = {"name": c.name, "net": c.candidate.net,
             "panel_size": _num(study.panel_size_of(c.candidate)),
             "mold_tolerance_mm": _num(study.mold_tolerance_of(c.candidate))}
    if c.failed:
        return {**asked, "feasible": "no",
                "reasons": "; ".join(c.reasons), "seconds": _num(m.get("seconds", {}).get("total"))}
    types = m["molds"]["panel_types"]
    angle, radius, strips = m["intersection_angle_deg"], m["meusnier_radius"], m["strips"]
    return {
        **asked, "rank": c.rank,
        "feasible": "yes" if c.feasible else "no", "cost": _num(c.cost),
        "molds": m["molds"]["count"], "panels": m["panels"],
        "boundary_panels": (m.get("boundary_panels") or {}).get("count", 0),
        "coverage_full_panels": _num(m.get("coverage_net", m["coverage"])),
        "planar": types.get("planar", 0), "single_curved": types.get("single_curved", 0),
        "double_curved": types.get("double_curved", 0),
        "coverage": _num(m["coverage"]),
        "folded": "yes" if (m.get("folds") or {}).get("folded") else "no",
        "deviation_max_mm": _num(m["largest_deviation_mm"]),
        "deviation_p95_mm": _num(m["deviation_mm"]["p95"]),
        "planarity_max_mm": _num(m["planarity_mm"]["max"]),
        "kink_max_deg": _num(m["kink_deg"]["max"]),
        "angle_min_deg": _num(angle and angle["min"]), "angle_max_deg": _num(angle and angle["max"]),
        "radius_min": _num(radius and radius["min"]), "radius_max": _num(radius and radius["max"]),
        "sheets": strips["sheets"] if strips else "",
        "strips_congruent": ("yes" if strips["congruent"] else "no") if strips else "",
        "seconds": _num(m["seconds"]["total"]), "reasons": "; ".join(c.reasons),
    }


def _num(value) -> str:
    return "" if value is None else f"{value:.6g}"


def candidates_csv(result: StudyResult) -> str:
    """``candidates.csv``: one row per candidate in rank order."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=_CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for c in result.ranked():
        writer.writerow(_row(c, result.study))
    return buffer.getvalue()


# ---------------------------------------------------------------------------- pictures
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


def search_text(record: dict, unit: str) -> str:
    """A search's outcome in words."""
    points = record["points"]
    values = ", ".join(f"{p['value']:g}" for p in points)
    if record["best"] is None:
        return (f"{record['name']}: {record['parameter']} searched in {record['low']:g} .. "
                f"{record['high']:g} {unit} at {values}: no point meets every limit.")
    low, high = record["feasible_range"]
    band = f"{low:g}" if low == high else f"{low:g} .. {high:g}"
    return (f"{record['name']}: {record['parameter']} searched in {record['low']:g} .. "
            f"{record['high']:g} {unit} at {values}; feasible at {band} {unit}; the cheapest "
            f"feasible point is {record['best']}.")


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


def _png_uri(path: Path) -> str:
    png = figures.compact_png(path.read_bytes())
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


# ---------------------------------------------------------------------------- HTML
#: Radii beyond this multiple of the design's size are shown as infinite: the stars (or
#: strips) are planar (straight) to within what a computation can tell.
INFINITE_RADIUS_FACTOR = 1e4


def _fmt_range(r: dict | None, unit: str = "", digits: int = 4) -> str:
    if not r:
        return ""
    return format_range(r["min"], r["max"], unit, digits)


def radius_text(r: dict | float | None, unit: str, beyond: float, infinite: str) -> str:
    """A radius or a ``{min, max}`` range of radii with its unit; values above `beyond`
    (or infinite, or None) are `infinite`.

    Examples
    --------
    >>> radius_text({"min": 3.558e9, "max": 1.033e16}, "m", 2.8e5, "infinite (planar stars)")
    'infinite (planar stars)'
    >>> radius_text({"min": 12.25, "max": 3e9}, "m", 2.8e5, "infinite")
    '12.25 m .. infinite'
    >>> radius_text({"min": 12.25, "max": 73548.6}, "m", 2.8e5, "infinite")
    '12.25 .. 73549 m'
    >>> radius_text({"min": 97.0512, "max": 97.0498}, "m", 2.8e5, "infinite")
    '97.05 m'
    >>> radius_text(2e11, "m", 1e5, "infinite"), radius_text(None, "mm", 1e8, "infinite (straight)")
    ('infinite', 'infinite (straight)')
    """
    def big(v):
        return v is None or not math.isfinite(v) or abs(v) > beyond

    def text(v):          # 4 significant digits, but no exponent for a large radius
        return f"{v:.0f}" if v >= 1e4 else html.format_value(v)

    if not isinstance(r, dict):
        return infinite if r is None or big(r) else f"{text(abs(r))} {unit}"
    lo, hi = sorted((r["min"], r["max"]), key=lambda v: (big(v), abs(v)))
    if big(lo):
        return infinite
    if big(hi):
        return f"{text(abs(lo))} {unit} .. {infinite}"
    if text(abs(lo)) == text(abs(hi)):
        return f"{text(abs(lo))} {unit}"
    return f"{text(abs(lo))} .. {text(abs(hi))} {unit}"


def _meusnier_text(result: StudyResult, r) -> str:
    return radius_text(r, result.study.design.units, INFINITE_RADIUS_FACTOR * result.design_size,
                       "infinite (planar stars)")


def _strip_radius_text(result: StudyResult, r) -> str:
    beyond = INFINITE_RADIUS_FACTOR * result.design_size * result.study.design.mm_per_unit
    return radius_text(r, "mm", beyond, "infinite (straight)")


#: How the comparison table is ordered (`fabplan.study.ranking.rank_candidates`).
_RANK_RULE = ("Rank: the candidates that meet every limit (feasible) come first, cheapest "
              "first; then those that break a limit (red rows), those breaking fewer limits "
              "first, cheapest first among equals. So a cheaper candidate that breaks a limit "
              "ranks below a dearer one that meets them all.")


def limit_text(key: str, value) -> tuple[str, str]:
    """The human name of a limit and its value with its unit.

    Examples
    --------
    >>> limit_text("max_deviation_mm", 40.0)
    ('largest deviation from the design', '40 mm')
    >>> limit_text("min_coverage", 0.95)[1], limit_text("max_molds", 1)[1]
    ('95 %', '1 mold')
    """
    name, unit = LIMIT_NAMES.get(key, (key.replace("_", " "), ""))
    if isinstance(value, bool):
        return name, "yes" if value else "no"
    if unit == "%":
        return name, f"{100 * value:g} %"
    if unit in ("molds", "sheets"):
        return name, counted(int(value), unit[:-1])
    return name, f"{html.format_value(value)} {unit}".strip()


def _sharpest_turn(result: StudyResult) -> CandidateResult | None:
    """The recommended candidate (else the first measured one) when its lines' largest
    turn was measured, else None."""
    measured = [c for c in result.ranked() if not c.failed and c.net is not None]
    best = next((c for c in measured if c.name == result.recommended), None)
    c = best or (measured[0] if measured else None)
    if c is None or c.net is None:
        return None
    turn = ((c.net.properties.get("fairness") or {}).get("line_turn_deg") or {})
    return None if turn.get("point") is None or turn.get("max") is None else c


def kink_text(result: StudyResult) -> str:
    """Where the sharpest turn of the lines lies, and whether the design forces it (near
    an umbilic) or the layout does (`fabplan.layout.picture.kink_text`)."""
    c = _sharpest_turn(result)
    if c is None or c.net is None:
        return ""
    return layout_kink_text(result.design, result.study.panel_size_of(c.candidate),
                            c.net.properties, name=c.name, units=result.study.design.units)


def pareto_text(result: StudyResult) -> str:
    """The Pareto-optimal candidates in words, and whether the recommended one is one."""
    optimal = [c.name for c in result.ranked() if c.pareto]
    text = (f"Pareto-optimal: {', '.join(optimal)}." if optimal else "")
    best = next((c for c in result.candidates if c.name == result.recommended), None)
    if best is not None and not best.pareto:
        text += (f" The recommended {best.name} is not among them: the cost also counts "
                 "panels by type and weighs the drivers, and a cheaper point may break a "
                 "limit.")
    return text.strip()


def _rounded(value: float | None, digits: int) -> html.Cell | str:
    """A number shown to `digits` decimals that sorts by its full value."""
    return "" if value is None else html.Cell(f"{value:.{digits}f}", value)


def _comparison_table(result: StudyResult) -> str:
    """All candidates, sortable by any column; a sweep's panel size and mold tolerance
    get columns of their own."""
    rows: list[list[object]] = []
    bad: list[int] = []
    study = result.study
    units = study.design.units
    swept = study.swept
    for c in result.ranked():
        m = c.metrics
        asked = ([study.panel_size_of(c.candidate)] if "panel_size" in swept else []) + \
            ([study.mold_tolerance_of(c.candidate)]
             if "mold_tolerance_mm" in swept else [])
        if c.failed:
            rows.append(["", c.name, c.candidate.describe(), *asked, "failed",
                         *[""] * 13, c.reasons[0]])
            bad.append(len(rows) - 1)
            continue
        s = m["strips"]
        rows.append([
            c.rank, c.name, c.candidate.describe(), *asked, "yes" if c.feasible else "no",
            m["molds"]["count"] if m["molds"]["count"] else
            ("none (all flat)" if every_panel_flat(m["molds"]) else "none (none molded)"),
            m["molds"].get("saved", ""), m["panels"],
            (m.get("boundary_panels") or {}).get("count", 0),
            _rounded(100 * m["coverage"], 1), _rounded(m["largest_deviation_mm"], 1),
            _rounded(m["planarity_mm"]["max"], 2), _rounded(m["kink_deg"]["max"], 2),
            _fmt_range(m["intersection_angle_deg"]),
            _meusnier_text(result, m["meusnier_radius"]) if m["meusnier_radius"] else "",
            "" if s is None else f"{s['sheets']}{' (congruent)' if s['congruent'] else ''}",
            _rounded(c.cost, 0), "yes" if c.pareto else "",
            f"the same net as {c.same_net_as}" if c.same_net_as else ""])
        if not c.feasible:
            bad.append(len(rows) - 1)
    asked_columns = ([f"panel size [{units}]"] if "panel_size" in swept else []) + \
        (["mold tolerance [mm]"] if "mold_tolerance_mm" in swept else [])
    return html.html_table(
        ["rank", "candidate", "net", *asked_columns, "feasible", "molds [count]",
         "molds saved by the material [count]", "panels [count]",
         "of them boundary panels [count]", "design covered [%]",
         "max deviation [mm]", "planarity [mm]", "max kink [deg]", "angle [deg]",
         f"Meusnier radius [{units}]", "strip sheets [count]", "cost [cost units]",
         "Pareto-optimal", "note"], rows,
        caption="All candidates, best first (click a column's header to sort by it). "
        + _RANK_RULE, bad_rows=bad, hide_empty=True, sortable=True)


def _limits_table(result: StudyResult) -> str:
    rows = [list(limit_text(k, v)) for k, v in _limit_items(result)]
    return html.html_table(["limit", "value"], rows, caption="Fabrication limits")


def _cost_table(result: StudyResult) -> str:
    from dataclasses import asdict

    names = {"mold": "mold", "flat_panel": "flat panel", "single_curved_panel":
             "single curved panel", "double_curved_panel": "double curved panel",
             "sheet": "sheet of strip material", "deviation_mm": "mm of largest deviation"}
    rows = [[names.get(k, k.replace("_", " ")), html.format_value(v)]
            for k, v in asdict(result.study.cost).items()]
    return html.html_table(["per", "weight [cost units]"], rows,
                           caption="Cost weights (cost units are relative prices: by default a "
                                   "flat panel costs 1, a mold 100; give them in a currency in "
                                   "the study file to read costs in it)")


def _coverage_text(coverage: float, full: float | None = None) -> str:
    """The share of the design the panels cover, and what the rest means for the counts."""
    text = f"{100 * coverage:.2f} % of the design's area"
    if full is not None and full < coverage:
        text += f" ({100 * full:.1f} % by full panels, the rest by boundary panels)"
    if coverage < 0.999:
        text += (f": {100 * (1 - coverage):.1f} % is left unclad, and the panel, mold, sheet and "
                 "cost figures leave it out")
    return text


def _boundary_text(boundary: dict | None) -> str:
    """The boundary panels of a candidate: how many, and on which molds."""
    if not boundary or not boundary["count"]:
        return ""
    own = boundary["own_molds"]
    flat = boundary.get("flat") or 0
    if flat == boundary["count"]:
        how = "all flat (no molds), placed to meet their neighbours"
    else:
        how = "each cut from a mold of the net's panels and placed to meet its neighbours"
        if flat:
            how += f" ({flat} of them flat)"
    text = f"; and {counted(boundary['count'], 'boundary panel')} trimmed to the design boundary, {how}"
    if boundary.get("step_max_mm") is not None:
        text += f" (steps up to {boundary['step_max_mm']:.2f} mm"
        if boundary.get("deviation_max_mm") is not None:
            text += f", up to {boundary['deviation_max_mm']:.1f} mm from the design"
        text += ")"
    if own:
        text += f", {counted(own, 'panel')} on a mold of its own"
    if boundary.get("flipped"):
        text += f"; {counted(boundary['flipped'], 'boundary panel')} facing against the design"
    return text


def _turn_text(turn: dict | None) -> str:
    """How much the net's lines turn within the surface, and where the most."""
    if not turn or turn.get("max") is None:
        return "-"
    return (f"up to {turn['max']:.2f} deg at vertex {turn['vertex']} (median {turn['median']:.2f}, "
            f"95 % below {turn['p95']:.2f} deg)")


def _folds_text(folds: dict | None) -> str:
    if not folds:
        return "-"
    counts = [(folds["flipped_faces"], "flipped face"), (folds["fold_edges"], "fold edge"),
              (folds["degenerate_stars"], "degenerate star"),
              (folds["collapsed_edges"], "collapsed edge")]
    found = [counted(n, what) for n, what in counts if n]
    return ", ".join(found) if found else "none (no flipped face, fold, degenerate star or " \
                                         "collapsed edge)"


def cost_line(result: StudyResult) -> str:
    """How the cost is made up, in words (as charged in this study)."""
    measured = [c for c in result.candidates if not c.failed]
    with_strips = [c for c in measured if c.metrics.get("strips")]
    material = result.study.material
    text = ("Cost = the weights times the molds (of the curved panels: flat panels need "
            "none), the panels by type, " if material is None else
            f"Cost = the weights times the molds (of the molded panels: in {material.label} "
            "flat, cold-bent and roll-bent panels need none), the panels by class (the "
            "molded ones by type), ")
    if result.sheets_charged:
        text += "the strip sheets "
    text += "and the largest deviation in mm; feasible candidates rank first, by cost."
    if with_strips and not result.sheets_charged:
        text += (f" Strip sheets are reported but not charged: only {len(with_strips)} of "
                 f"{len(measured)} candidates {'gets' if len(with_strips) == 1 else 'get'} "
                 "strips, and charging them would make those "
                 "look dearer than candidates that were not asked for strips.")
    return text


def _check_value(key: str, value) -> str:
    if value is None or isinstance(value, str):
        return html.format_value(value)
    if key == "congruent_strips":        # its bound is the congruence tolerance
        return f"{html.format_value(value)} mm"
    return limit_text(key, value)[1]


def _check_rows(c: CandidateResult) -> list[list]:
    return [[limit_text(ck["limit"], ck["bound"])[0],
             _check_value(ck["limit"], ck["measured"]), _check_value(ck["limit"], ck["bound"]),
             "yes" if ck["ok"] else "NO", ck["text"]] for ck in c.checks]


def _candidate_facts(c: CandidateResult, result: StudyResult) -> tuple[str, list[list]]:
    """The verdict of a measured candidate and its "quantity, value" rows."""
    m = c.metrics
    units = result.study.design.units
    verdict = ("Feasible: " if c.feasible else "Not feasible: ") + "; ".join(c.reasons) + "."
    if c.notes:
        verdict += " Note: " + "; ".join(c.notes) + "."
    types = m["molds"]["panel_types"]
    parameters = []
    for k, v in m["parameters"].items():
        if not isinstance(v, float):
            continue
        parameters.append(f"radius {_meusnier_text(result, v)}" if k == "radius" else
                          f"angle {v:.6g} deg" if k == "angle_deg" else f"{k} {v:.6g}")
    molds = m["molds"]
    facts = [
        ["net", c.candidate.describe()],
        ["solve", f"{m['status']} after {m['iterations']} iterations"
                  + (f" ({m['status_note']})" if m.get("status_note") else "")],
        ["solved parameters", ", ".join(parameters) or "-"],
        ["panels", f"{m['panels']}: {m['quads']} quads, {m['other_faces']} other "
                   f"({m['irregular_vertices']} irregular vertices)"
                   + _boundary_text(m.get("boundary_panels"))],
        ["panel types", ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in types.items())],
        ["design covered", _coverage_text(m["coverage"], m.get("coverage_net"))],
        ["line turns", _turn_text(m.get("line_turn_deg"))],
        ["folds", _folds_text(m.get("folds"))],
        ["edge length", _fmt_range(m["edge_length"], units)],
        ["panel area", _fmt_range(m["panel_area"], f"{units}^2")],
        ["Meusnier radius", _meusnier_text(result, m["meusnier_radius"])
         if m["meusnier_radius"] else "-"],
        ["deviation from the design [mm]",
         f"largest {m['largest_deviation_mm']:.2f} (the net and its boundary panels as built); "
         f"the net's vertices: max {m['deviation_mm']['max']:.2f}, mean "
         f"{m['deviation_mm']['mean']:.2f}, 95 % {m['deviation_mm']['p95']:.2f}"],
        *([["panel classes (material)", material_sentence(molds)]]
          if molds.get("panel_classes") is not None else []),
        ["molds", (molds_text(molds) if molds["count"] == 0 else
                   f"{molds_text(molds)} for the "
                   f"{'molded' if molds.get('panel_classes') is not None else 'curved'} panels "
                   f"({molds['molds_per_sqrt_panels']:.2f} x sqrt of the panel count)")
         + f"; largest gap of a panel to its mold (flat panels: to a plane) "
           f"{molds['max_deviation_mm']:.2f} mm"],
        ["sphere residual (largest, of the mean edge length)",
         f"{html.format_value(m['sphere_residual_relative_max'])} of an edge"],
        ["intersection angle", _fmt_range(m["intersection_angle_deg"], "deg") or "-"],
        ["run time", ", ".join(f"{k} {v:.1f} s" for k, v in m["seconds"].items())],
    ]
    if m["strips"]:
        s = m["strips"]
        shape = "all straight (so all congruent)" if s["straight"] else (
            f"arc radius {_strip_radius_text(result, s['radius_mm'])}; the parts differ from "
            f"one common arc by up to {s['congruence_deviation_mm']:.3g} mm"
            + (" (congruent)" if s["congruent"] else " (not congruent)"))
        facts.append(["strips", f"{counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} "
                      f"on {counted(s['sheets'], 'sheet')} ({100 * s['material_use']:.0f} % "
                      f"material use); {shape}"])
        if s.get("ends_at_boundary_member"):
            facts.append(["strip ends", _strip_ends_text(s)])
    return verdict, facts


def _strip_ends_text(s: dict) -> str:
    """Where the strips end: at the boundary member, and why the others are free."""
    kinds = s.get("ends_free_by_kind") or {}
    why = [f"{kinds[k]} {text}" for k, text in (
        ("inside", "inside the net at irregular vertices (node connectors)"),
        ("along edge", "along the edge"), ("not continued", "not continued to the edge"))
        if kinds.get(k)]
    return (f"{counted(s['ends_at_boundary_member'], 'end')} cut square against a "
            f"{s['boundary_member_mm']:g} mm boundary member at the edge of the cladding; "
            f"{s['ends_free']} free" + (f" ({', '.join(why)})" if why else ""))


def _candidate_section(c: CandidateResult, pictures: dict, outputs: dict,
                       result: StudyResult, scene: int | None = None) -> str:
    head = f"{c.rank}. {c.name}" if c.rank else c.name
    if c.failed:
        return html.html_section(head, html.html_paragraph(
            f"{c.candidate.describe()}: failed. {c.error}", cls="fail"))
    units = result.study.design.units
    molds = c.metrics["molds"]
    verdict, facts = _candidate_facts(c, result)
    checks = html.html_table(
        ["limit", "measured", "bound", "met", "what was measured"], _check_rows(c),
        caption="Checks", bad_rows=[i for i, ck in enumerate(c.checks) if not ck["ok"]])
    parts = [html.html_paragraph(verdict, cls="note" if c.feasible else "fail"),
             html.html_table(["quantity", "value"], facts, caption="Measured"), checks]
    limit = result.study.limits.max_deviation_mm
    captions = {
        "net": ("The net on the design surface (grey), axes to scale.",
                f"The net's lines over the design; axes in {units}. Marks show where the "
                "lines turn or the panels change size most."),
        "deviation": ("Deviation heat map: the distance of the net from the design.",
                      f"Colour is the distance in mm, measured at every vertex and blended "
                      f"across the panels; the red line on the scale is the limit "
                      f"({limit:g} mm), and the largest distance is circled."),
        "molds": ("Panels coloured by mold" + (
            f" ({'all flat' if every_panel_flat(molds) else 'none molded'}: no molds)."
            if molds["count"] == 0 else "."),
                  "One colour per mold; the number on a panel is its mold id, the row of "
                  "molds.csv (written where the panel is large enough on the picture)."),
        "sheet": ("First strip sheet as cut.",
                  "Red: outlines to cut; magenta: slits; blue: engraved labels (strip ids)."),
    }
    figs = [html.html_figure(pictures[key], caption, how=how)
            for key, (caption, how) in captions.items() if key in pictures]
    if figs:
        parts.append(html.html_figure_grid(*figs))
    if scene is not None:
        parts.append(f'<p><a href="#3d-view" data-fp-scene="{scene}">Show {html_escape(c.name)} '
                     "in the 3D view</a></p>")
    links = []
    for key, value in outputs.items():
        for i, href in enumerate(value if isinstance(value, list) else [value]):
            links.append((Path(href).name if i else f"{key.replace('_', ' ')}: {Path(href).name}",
                          href))
    if links:
        parts.append(html.html_links("Files", links))
        parts.append(html.html_paragraph(html.LINKS_NOTE))
    return html.html_section(head, *parts)


def coverage_gap_triangles(design: DesignSurface, mesh, *, gap: float) -> np.ndarray:
    """(g, 3, 3) float: the design's triangles no panel covers, those whose centroid lies
    farther than `gap` (model units) from the net."""
    import igl

    V, T = np.asarray(design.vertices, float), np.asarray(design.triangles, np.int64)
    centroids = V[T].mean(axis=1)
    tri = mesh.triangles()
    sq, _, _ = igl.point_mesh_squared_distance(centroids, np.asarray(mesh.vertices, float),
                                               np.asarray(tri, np.int64))
    return V[T[np.asarray(sq) > gap * gap]]


def study_viewer_scenes(result: StudyResult) -> tuple[list[viewer.ViewerScene], dict[str, int]]:
    """The 3D view's scenes of a study, one per measured net (a candidate that ended at
    an earlier one's net shows that one), and the scene index of every candidate.

    A net with boundary panels shows them green, each with the full panel and the mold it
    is cut from; its coverage gaps are the design's parts neither covers."""
    from ..fabricate.molds.boundary_molds import boundary_mold_info
    from ..layout.view import boundary_layer, uncovered_triangles

    scenes: list[viewer.ViewerScene] = []
    index: dict[str, int] = {}
    limit = result.study.limits.max_deviation_mm
    mm = result.study.design.mm_per_unit
    for c in result.ranked():
        if c.failed or c.net is None or c.molds is None:
            continue
        if c.same_net_as is not None and c.same_net_as in index:
            index[c.name] = index[c.same_net_as]
            continue
        mesh = c.net.mesh
        deviation = (c.deviation_mm if c.deviation_mm is not None else
                     vertex_deviation_mm(mesh, result.design, mm))
        panels = c.net.boundary_panels
        trimmed = panels is not None and panels.count > 0
        gaps = None
        if c.metrics.get("coverage", 1.0) < 0.999:
            # the panels, boundary panels included, against the design
            V, T = mesh.vertices, mesh.triangles()
            if trimmed:
                V, T = panels.vertices, np.vstack([T, panels.panel_triangles()[0]])
            gaps = uncovered_triangles(result.design, V, T, gap=0.3 * mesh.mean_edge_length)
        index[c.name] = len(scenes)
        scene = net_viewer_scene(
            c.molds, title=f"{c.rank}. {c.name}", deviation_mm=deviation,
            deviation_limit_mm=limit, gaps=gaps,
            infinite_radius=INFINITE_RADIUS_FACTOR * result.design_size,
            molds_in_all=c.metrics["molds"]["count"])
        if trimmed:
            scene.layer = boundary_layer(
                panels, units=result.study.design.units,
                info=boundary_mold_info(c.boundary_molds) if c.boundary_molds is not None else ())
        scenes.append(scene)
    return scenes, index


def _design_text(study) -> str:
    source = study.design.source
    if os.path.isfile(source):
        return f"Design {study.design.label} (from {Path(source).name})"
    return f"Design: built-in {study.design.label} surface"


def study_html(result: StudyResult, pictures: dict, outputs: dict, *,
               seconds_total: float | None = None, view_3d: bool = True) -> str:
    """The self-contained ``report.html`` (links to the candidates' files are relative).

    `view_3d`: with the interactive 3D view of every candidate's net (three.js and the
    meshes embedded; see `fabplan.report.viewer`).
    """
    study = result.study
    seconds = result.seconds_run if seconds_total is None else seconds_total
    sub = (f"{_design_text(study)}, panel size {study.panel_size:g} {study.design.units}, "
           f"{counted(len(result.candidates), 'candidate')}, run in {seconds:.0f} s"
           + (" including writing the files" if seconds_total is not None else ""))
    parts = []
    if study.description:
        parts.append(html.html_paragraph(study.description))
    parts.append(html.html_section(
        "Recommendation", html.html_paragraph(result.recommendation,
                                                cls="note" if result.recommended else "fail")))
    overview = [_comparison_table(result)]
    if "comparison" in pictures:
        overview.append(html.html_figure(
            pictures["comparison"], "Molds and deviation of each candidate, in rank order.",
            how="One bar per candidate, green when it meets every limit, red when not; the "
                "dashed lines are the limits. Left: molds for the curved panels; right: the "
                "largest distance from the design in mm."))
    if "pareto" in pictures:
        overview.append(html.html_figure(
            pictures["pareto"], "Cost drivers: molds (and strip sheets) against the largest "
            "deviation from the design, one point per candidate.",
            how="Green dots meet every limit, red crosses do not; dashed lines are the limits. "
                "Ringed and named are the Pareto-optimal candidates: no other candidate needs "
                "at most as many molds and sheets and deviates at most as far, with one of "
                "them less. The star is the recommended one. " + pareto_text(result)))
    overview += [_limits_table(result), _cost_table(result),
                 html.html_paragraph(cost_line(result))]
    parts.append(html.html_section("Comparison", *overview))
    for k, record in enumerate(search_record(s, result.candidates) for s in study.searches):
        unit = "deg" if record["parameter"] == "angle" else study.design.units
        parts.append(html.html_section(
            f"Search: {record['name']}", html.html_figure(
                pictures[f"search-{k}"], search_text(record, unit),
                how="Each point is a solve of the candidate at that value (listed below as a "
                    "candidate of its own): green dots meet every limit, red crosses do not; "
                    "the shaded band spans the feasible points; the ringed point is the "
                    "cheapest feasible one. The search solves a few points across the range, "
                    "then the midpoints beside the best point so far."),
            anchor=f"search-{k}"))
    if "curvature" in pictures:
        parts.append(html.html_section("Where the design makes lines kink", html.html_figure(
            pictures["curvature"], "The design coloured by how far its principal "
            "curvatures part over a panel, with the sharpest turn of the lines marked.",
            how="Dark is near an umbilic: the two principal curvatures nearly agree, so the "
                "principal directions, and the lines of every net that follows them, turn "
                "fast or are not defined there; white dots are the direction field's "
                "singular points. " + kink_text(result)), anchor="curvature"))
    scenes, index = study_viewer_scenes(result) if view_3d else ([], {})
    if scenes:
        parts.append(html.html_section("3D view", viewer.viewer_block(scenes), anchor="3d-view"))
    for c in result.ranked():
        parts.append(_candidate_section(c, pictures.get(c.name, {}), outputs.get(c.name, {}),
                                        result, scene=index.get(c.name)))
    return html.html_page(f"Facade study: {study.name}", parts, subtitle=sub,
                          scripts=viewer.viewer_assets() if scenes else "")


def _comparison_rows(result: StudyResult) -> tuple[list[str], list[list]]:
    """The comparison table for print: fewer, wider columns than the page's."""
    rows: list[list] = []
    for c in result.ranked():
        if c.failed:
            rows.append(["", c.name, "failed", "", "", "", "", c.reasons[0]])
            continue
        m = c.metrics
        rows.append([c.rank, c.name, "yes" if c.feasible else "no", m["molds"]["count"],
                     m["panels"], f"{m['largest_deviation_mm']:.1f}", f"{c.cost:.0f}",
                     c.candidate.describe()])
    return (["rank", "candidate", "feasible", "molds [count]", "panels [count]",
             "max deviation [mm]", "cost [cost units]", "net"], rows)


def study_pdf(result: StudyResult, pictures: dict, *, seconds_total: float | None = None
              ) -> PdfDocument:
    """The printable report (``report.pdf``): the recommendation and comparison, then two
    to four pages per candidate (verdict, measurements, checks, pictures)."""
    study = result.study
    seconds = result.seconds_run if seconds_total is None else seconds_total
    doc = PdfDocument(f"Facade study: {study.name}",
                      f"{_design_text(study)}, panel size {study.panel_size:g} "
                      f"{study.design.units}, {counted(len(result.candidates), 'candidate')}, run "
                      f"in {seconds:.0f} s. The interactive 3D view and the files are in "
                      "report.html beside this file.")
    first = doc.section("Recommendation and comparison").text(result.recommendation)
    columns, rows = _comparison_rows(result)
    first.table(columns, rows, widths=[0.5, 1.6, 0.7, 0.7, 0.7, 0.9, 0.8, 2.2])
    first.text(_RANK_RULE, size=7.5, style="italic")
    first.text(cost_line(result), size=7.5)
    first.table(["limit", "value"], [list(limit_text(k, v)) for k, v in
                                     _limit_items(result)], widths=[3, 1])
    if "comparison" in pictures:
        first.image(pictures["comparison"], "Molds and deviation of each candidate, in rank "
                    "order: green meets every limit, red does not; dashed lines are the limits.")
    if "pareto" in pictures:
        first.image(pictures["pareto"], "Cost drivers of every candidate: ringed are the "
                    "Pareto-optimal ones, the star is the recommended one. "
                    + pareto_text(result))
    if "curvature" in pictures:
        first.image(pictures["curvature"], "The design's |k1 - k2| over a panel (dark: near "
                    "an umbilic). " + kink_text(result))
    for k, s in enumerate(study.searches):
        record = search_record(s, result.candidates)
        unit = "deg" if record["parameter"] == "angle" else study.design.units
        first.image(pictures[f"search-{k}"], "Search: " + search_text(record, unit))
    for c in result.ranked():
        head = f"{c.rank}. {c.name}" if c.rank else c.name
        section = doc.section(head)
        if c.failed:
            section.text(f"{c.candidate.describe()}: failed. {c.error}")
            continue
        verdict, facts = _candidate_facts(c, result)
        section.text(verdict)
        section.table(["quantity", "value"], facts, widths=[1.2, 3])
        section.table(["limit", "measured", "bound", "met", "what was measured"],
                      _check_rows(c), widths=[1.6, 0.8, 0.8, 0.4, 2.6])
        own = pictures.get(c.name, {})
        for key, caption in (("deviation", "Deviation from the design (mm); red line on the "
                                            "scale: the limit."),
                             ("molds", "Panels coloured by mold; numbers are mold ids."),
                             ("net", "The net on the design surface."),
                             ("sheet", "First strip sheet as cut.")):
            if key in own:
                section.image(own[key], caption, max_height=0.4)
    return doc


def _limit_items(result: StudyResult) -> list[tuple[str, object]]:
    from dataclasses import asdict

    limits = asdict(result.study.limits)
    if not limits["planar_panels"]:
        del limits["planarity_tolerance_mm"]
    if not limits["congruent_strips"]:
        del limits["congruence_tolerance_mm"]
    return [(k, v) for k, v in limits.items() if v is not None and v is not False]


# ---------------------------------------------------------------------------- writing
#: what a study writes at the top of its folder (besides ``candidates/``)
STUDY_FILES = ("report.html", "report.pdf", "study.json", "candidates.csv")
#: the names a study writes: only such files can be an earlier study's, whatever a
#: folder's list of files says (a candidate's files, its strip sheets and schedule)
_STUDY_FILE = re.compile(
    r"(report\.html|report\.pdf|study\.json|candidates\.csv|" + re.escape(output.MANIFEST) + "|"
    r"candidates/[^/]+/(net\.(obj|json|png|3dm|glb|ifc)|net\.boundary\.obj|molds\.(csv|json)|"
    r"boundary-panels\.(csv|obj)|reproduce\.sh|"
    r"strips/(strips(-sheet-\d+\.(dxf|png)|-sheets\.dxf|\.csv|\.json)|sheet-preview\.png)))")


def study_files(folder: Path) -> set[str] | None:
    """The files an earlier study wrote in `folder`, which a new study replaces: those
    its manifest lists (`fabplan.io.output.MANIFEST`), else (a study written without one,
    or a list that does not read) those under ``candidates/`` and at the top that a study
    writes; only names a study writes in either case. An empty set for a folder that
    holds only the candidates an interrupted study kept (`fabplan.study.cache`); None for
    a folder that holds no study."""
    folder = Path(folder)
    listed = output.read_manifest(folder)
    if listed is None and (folder / "study.json").is_file():
        candidates = folder / "candidates"
        listed = {name for name in STUDY_FILES if (folder / name).is_file()} | (set() if (
            candidates.is_symlink() or not candidates.is_dir()) else {
            p.relative_to(folder).as_posix() for p in candidates.rglob("*")
            if p.is_file() or p.is_symlink()})
    if listed is not None:
        return {name for name in listed if _STUDY_FILE.fullmatch(name)}
    return set() if (folder / CACHE_FOLDER).is_dir() else None


def check_output_folder(folder: str | os.PathLike, study: Study | None = None) -> None:
    """Refuse a folder that cannot hold a study, without creating anything.

    A study replaces what an earlier study wrote in its folder and leaves every other
    file there as it is. A folder that does not exist yet, an empty one, or one that
    holds an earlier study (`study_files`) is accepted; a file, an unwritable place, a
    folder of other files, or the folder that holds the `study` file itself is refused.
    """
    output.check_output_folder(folder, owned=study_files)
    path = None if study is None else study.path
    if path is not None and Path(os.path.realpath(path)).is_relative_to(os.path.realpath(folder)):
        raise InputError(f"{folder}: holds the study file {path}; a study's files go to a "
                         "folder of their own: choose another -o (a new folder beside it)")


def reproduce_commands(c: CandidateResult, study: Study) -> list[list[str]]:
    """The commands that give a candidate's molds (and strips) from the files in its
    folder, as the study planned them: `fabplan molds` on ``net.obj`` (with its boundary
    panels, ``net.boundary.obj``) at the candidate's mold tolerance and step limit, on the
    design's patches for a net that glides on it (checked against the study's deviation
    limit); `fabplan strips` with the study's strip options. Run in the candidate's
    folder."""
    units = study.design.units
    limits = study.limits_of(c.candidate)
    molds = ["fabplan", "molds", "net.obj", "--tolerance-mm", f"{limits.mold_tolerance_mm!r}",
             "--step-limit", f"{limits.panel_step_limit_mm!r}", "--units", units]
    if c.molds is not None and c.molds.panel_surface == "design":
        molds += ["--panel-surface", "design", "--design", study.design.source,
                  "--max-deviation-mm", f"{limits.max_deviation_mm!r}"]
        if study.design.triangles is not None:
            molds += ["--triangles", str(study.design.triangles)]
    if study.material is not None:
        molds += ["--material", study.material.spec]
    molds += ["-o", "reproduced/molds"]
    commands = [molds]
    options = study.strips
    if c.strips is not None and options is not None:
        commands.append(["fabplan", "strips", "net.obj", "--height", f"{options.height_mm!r}",
                         "--thickness", f"{options.thickness_mm!r}", "--units", units,
                         "--sheet", f"{options.sheet_mm[0]!r}x{options.sheet_mm[1]!r}",
                         "--tolerance", f"{options.congruence_tolerance_mm!r}", "-o",
                         "reproduced/strips"])
    return commands


def reproduce_script(c: CandidateResult, study: Study) -> str:
    """``reproduce.sh``: `reproduce_commands` as a shell script that runs in its folder."""
    import shlex

    lines = ["#!/bin/sh",
             f"# {c.name}: the commands that give this candidate's net molds and strips from",
             "# net.obj, as the study planned them, in reproduced/molds and reproduced/strips",
             "set -e", 'cd "$(dirname "$0")"']
    return "\n".join([*lines, *(shlex.join(cmd) for cmd in reproduce_commands(c, study))]) + "\n"


def _candidate_files(c: CandidateResult, folder: Path, study: Study, design: DesignSurface,
                     say, twin_strips: dict[str, bytes] | None = None,
                     rhino: bool = False, ifc: bool = False) -> tuple:
    """Write one candidate's files into `folder`; `twin_strips` are the strip files
    (``strips/NAME``: bytes) of the earlier candidate whose net and strip plan this one
    shares, if any: they are copied rather than made and read back a second time."""
    from ..fabricate.molds.boundary_molds import boundary_panels_csv
    from ..fabricate.strips.dxf import preview_png, sheet_document

    net, molds_plan = c.net, c.molds
    if net is None or molds_plan is None:
        raise ValueError(f"candidate {c.name!r} has no net to write (it failed)")
    folder.mkdir(parents=True)
    net_obj, net_json = net.write(folder / "net.obj")
    record = molds_plan.record()
    if c.boundary_molds is not None:
        # the same count as the report's: the net's molds and the boundary panels' own
        record["boundary_panels"] = c.boundary_molds.record(net_molds=molds_plan.mold_count)
    output.write_texts({folder / "molds.csv": molds_plan.panels_csv(),
                        folder / "molds.json": json_text(record),
                        folder / "reproduce.sh": reproduce_script(c, study)})
    outputs: dict[str, str | list[str]] = {
        "net": "net.obj", "measured": "net.json", "molds_csv": "molds.csv",
        "molds_json": "molds.json", "picture": "net.png", "reproduce": "reproduce.sh"}
    if net.boundary_panels is not None and c.boundary_molds is not None:
        output.write_texts({
            folder / "boundary-panels.csv": boundary_panels_csv(net.boundary_panels,
                                                                c.boundary_molds),
            folder / "boundary-panels.obj": c.boundary_molds.cut_obj_text(
                "fabplan boundary panels as cut from their molds (placements in "
                "boundary-panels.csv), one face per panel of net.boundary.obj")})
        outputs["boundary_panels"] = "net.boundary.obj"
        outputs["boundary_panels_csv"] = "boundary-panels.csv"
        outputs["boundary_panels_cut"] = "boundary-panels.obj"
    title = f"{c.name}: {c.candidate.describe()}"
    write_layout_picture(folder / "net.png", design, net.mesh, title=title,
                         singular_points=c.singular_points,
                         marks=fairness_marks(net.properties),
                         boundary_panels=net.boundary_panels)
    pictures = {"net": _png_uri(folder / "net.png"),
                "deviation": deviation_figure(c, design, study.limits.max_deviation_mm,
                                              study.design.mm_per_unit)}
    from ..fabricate.molds.mold_report import mold_figure

    molds = c.metrics["molds"]
    own = molds["count"] - molds_plan.mold_count         # the boundary panels' own molds
    pictures["molds"] = mold_figure(molds_plan, title=f"{c.name}: {counted(molds_plan.panel_count, 'panel')}"
                                    + (f", {'all flat' if every_panel_flat(molds) else 'none molded'}: "
                                       "no molds" if molds["count"] == 0 else
                                       f", {counted(molds_plan.mold_count, 'mold')} for the "
                                       "curved ones (one colour per mold)"
                                       + (f"; {molds['count']} in all with the {own} the boundary "
                                          "panels need of their own" if own > 0 else "")))
    if c.strips is not None:
        if twin_strips:
            (folder / "strips").mkdir()
            for name, data in twin_strips.items():
                output.path_inside(folder, *name.split("/")).write_bytes(data)
            files = sorted((folder / "strips").iterdir())
        else:
            files = c.strips.write(folder / "strips", previews=False)
        layout, settings = c.strips.nesting, c.strips.strips.settings
        sheet = layout.sheets[0]
        preview = folder / "strips" / "sheet-preview.png"
        preview_png(sheet_document(layout, [sheet], settings), preview, settings.sheet_mm,
                    title=f"{c.name}: sheet 1 of {len(layout.sheets)}")
        pictures["sheet"] = _png_uri(preview)
        outputs["strips_dxf"] = sorted(f"strips/{f.name}" for f in files if f.suffix == ".dxf")
        outputs["strips_schedule"] = "strips/strips.csv"
        outputs["strips_preview"] = "strips/sheet-preview.png"
    if rhino:
        from .api import write_3dm, write_glb

        write_3dm(net, folder / "net.3dm", molds=molds_plan, strips=c.strips, units=study.design.units,
                  user_text={"candidate": c.name, "net_type": net.net, "status": net.status})
        write_glb(net, folder / "net.glb", molds=molds_plan, units=study.design.units)
        outputs["rhino"] = "net.3dm"
        outputs["gltf"] = "net.glb"
    if ifc:
        from .api import write_ifc

        write_ifc(net, folder / "net.ifc", molds=molds_plan, boundary=c.boundary_molds,
                  strips=c.strips, units=study.design.units, net_type=net.net, name=c.name)
        outputs["ifc"] = "net.ifc"
    say(f"    wrote {c.name}")
    return {k: (f"candidates/{c.name}/{v}" if isinstance(v, str) else
                [f"candidates/{c.name}/{x}" for x in v]) for k, v in outputs.items()}, pictures


def candidate_file_bytes(c: CandidateResult, study: Study, design: DesignSurface,
                         twin_files: dict[str, bytes] | None = None, rhino: bool = False,
                         ifc: bool = False
                         ) -> tuple[dict[str, bytes], dict, dict]:
    """One candidate's files made in a folder of its own and returned as bytes, so that
    a Dask worker, on this machine or another, can make them (see `write_study`).

    Parameters
    ----------
    twin_files : the files of the candidate whose strips this one shares (its
        ``strips/`` are copied).

    Returns
    -------
    files : path inside the candidate's folder -> bytes.
    outputs, pictures : as the serial writer gives them.
    """
    import tempfile

    strips = None if twin_files is None else {
        k: v for k, v in twin_files.items() if k.startswith("strips/")}
    with tempfile.TemporaryDirectory(prefix="fabplan-candidate-") as tmp:
        folder = Path(tmp) / "candidate"
        outputs, pictures = _candidate_files(c, folder, study, design, lambda message: None,
                                             twin_strips=strips, rhino=rhino, ifc=ifc)
        files = {p.relative_to(folder).as_posix(): p.read_bytes()
                 for p in sorted(folder.rglob("*")) if p.is_file()}
    return files, outputs, pictures


def candidate_files_task(c: CandidateResult, study: Study, design: DesignSurface,
                         twin_made: tuple | None, rhino: bool = False,
                         ifc: bool = False) -> tuple | None:
    """`candidate_file_bytes` as a Dask task: `twin_made` is what the task of the
    candidate's twin (`CandidateResult.twin`) made, whose strip files this one takes when
    both have strips (the same strip plan, see `fabricate_candidate`); None for a failed
    candidate."""
    if c.failed:
        return None
    twin_files = twin_made[0] if twin_made is not None and c.strips is not None else None
    return candidate_file_bytes(c, study, design, twin_files, rhino=rhino, ifc=ifc)


def _strip_twin(c: CandidateResult, by_name: dict[str, CandidateResult]) -> str | None:
    """The candidate whose strip files `c` takes (the same net and strip plan), or None."""
    twin = None if c.twin is None else by_name.get(c.twin)
    shared = twin is not None and twin.strips is not None and c.strips is not None
    return twin.name if shared and twin is not None else None


def _write_files(folder: Path, files: dict[str, bytes]) -> None:
    for relative, data in files.items():
        path = output.path_inside(folder, *relative.split("/"))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def _write_candidates(result: StudyResult, tmp: Path, say, rhino: bool, client,
                      ifc: bool = False) -> tuple:
    """Every measured candidate's folder in `tmp`: from the files made already beside the
    run (`StudyResult.made_files`: a parallel run's workers, a serial run's forked
    processes), else made on the workers of `client` (each in memory, see
    `candidate_file_bytes`; this process writes them), else here. Returns the outputs and
    pictures by candidate name."""
    outputs, pictures = {}, {}
    by_name = {c.name: c for c in result.candidates}
    done = [c for c in result.candidates if not c.failed]
    if all(c.name in result.made_files for c in done):
        for c in done:
            files, outputs[c.name], pictures[c.name] = result.made_files[c.name]
            _write_files(output.path_inside(tmp, "candidates", c.name), files)
            say(f"    wrote {c.name}")
        return outputs, pictures
    if client is None:
        for c in done:
            if c.name in result.made_files:   # made beside a serial run
                files, outputs[c.name], pictures[c.name] = result.made_files[c.name]
                _write_files(output.path_inside(tmp, "candidates", c.name), files)
                say(f"    wrote {c.name}")
                continue
            # names are checked when the study is read; this guards the API too
            folder = output.path_inside(tmp, "candidates", c.name)
            twin = _strip_twin(c, by_name)
            strips = None if twin is None else {
                p.relative_to(folder.parent / twin).as_posix(): p.read_bytes()
                for p in sorted((folder.parent / twin / "strips").rglob("*")) if p.is_file()}
            outputs[c.name], pictures[c.name] = _candidate_files(
                c, folder, result.study, result.design, say, twin_strips=strips, rhino=rhino,
                ifc=ifc)
        return outputs, pictures
    from distributed import as_completed

    from .inputs import shared_inputs

    study, design = shared_inputs(client, result.study, result.design)
    futures: dict[str, Any] = {}
    for c in done:                         # in the study's order: a twin comes after its own
        twin = _strip_twin(c, by_name)
        futures[c.name] = client.submit(
            candidate_files_task, c, study, design, None if twin is None else futures[twin],
            rhino, ifc, key=f"files-{c.name}", pure=False)
    names = {f.key: name for name, f in futures.items()}
    for future in as_completed(list(futures.values())):
        name = names[future.key]
        files, outputs[name], pictures[name] = future.result()
        _write_files(output.path_inside(tmp, "candidates", name), files)
        say(f"    wrote {name}")
    return outputs, pictures


def write_study(result: StudyResult, out_dir, *, progress=None, rhino: bool = False, ifc: bool = False,
                view_3d: bool = True, pdf: bool = True, client: Any = None,
                fork: bool = False) -> list[Path]:
    """Write every file of a study into `out_dir`, replacing the folder as a whole.

    `progress` is called with a line per written candidate; `view_3d` puts the
    interactive 3D view into ``report.html``; `pdf` writes ``report.pdf`` beside it (with
    `fork`, in a forked process meanwhile, `fabplan.io.forked.ForkedFile`: the
    command does; a notebook or a Dask client's process had better not fork). With
    `rhino`, every candidate's folder also gets ``net.3dm`` (the net, its polylines, its
    panels by mold and its strip curves) and ``net.glb``; with `ifc` ``net.ifc`` (its facade
    plan for the building model, `fabplan.io.ifc`).

    With a Dask `client` (``distributed.Client``), the candidates' files are made on its
    workers, in parallel (`candidate_file_bytes`), and written here; a parallel run that
    made them already (`run_study_parallel` with ``files=True``) only has them written.

    `out_dir` may be new, empty, or hold an earlier study (see `check_output_folder`).
    The time recorded as ``seconds_total`` (and shown in the report) is the run time
    plus writing every file up to the last three (``study.json``, ``candidates.csv``,
    ``report.html``), which must hold it.

    Returns
    -------
    list of Path: ``report.html``, ``study.json``, ``candidates.csv`` (the candidate
    folders are listed in ``study.json``; ``report.pdf`` sits beside them).
    """
    say = progress or (lambda message: None)
    clock = time.perf_counter()
    out_dir = Path(out_dir)
    check_output_folder(out_dir, result.study)
    with output.output_folder(out_dir, replace=True, owned=study_files,
                              protect=result.study.input_files()) as tmp:
        outputs, pictures = _write_candidates(result, tmp, say, rhino, client, ifc)
        if any(not c.failed for c in result.candidates):
            pictures["comparison"] = comparison_figure(result)
        if sum(not c.failed for c in result.candidates) >= PARETO_MIN_CANDIDATES:
            pictures["pareto"] = pareto_figure(result)
        for k, s in enumerate(result.study.searches):
            pictures[f"search-{k}"] = search_figure(result, search_record(s, result.candidates))
        c = _sharpest_turn(result)
        if c is not None and c.net is not None:
            turn = c.net.properties["fairness"]["line_turn_deg"]
            pictures["curvature"] = curvature_difference_figure(
                result.design, result.study.panel_size_of(c.candidate),
                marks={f"{c.name}: lines turn most ({turn['max']:.0f} deg)": turn["point"]},
                singular_points=c.singular_points,
                title="The design's curvature: where its principal directions are weak")
        total = result.seconds_run + time.perf_counter() - clock
        record = study_record(result, outputs, seconds_total=total)
        def print_pdf(path: Path) -> None:
            study_pdf(result, pictures, seconds_total=total).write(path)

        printed = None
        if pdf and fork:     # the PDF is drawn on the other core while this one writes the rest
            printed = ForkedFile(print_pdf, tmp / "report.pdf")
        elif pdf:
            print_pdf(tmp / "report.pdf")
        try:
            output.write_texts({tmp / "study.json": json_text(record),
                                tmp / "candidates.csv": candidates_csv(result),
                                tmp / "report.html": study_html(result, pictures, outputs,
                                                                seconds_total=total,
                                                                view_3d=view_3d)})
        except BaseException:
            if printed is not None:
                printed.cancel()
            raise
        if printed is not None:
            printed.finish()
    return [out_dir / "report.html", out_dir / "study.json", out_dir / "candidates.csv"]
