"""The mold report: ``report.html``, ``molds.json`` and ``panels.csv`` of a `MoldPlan`.

The HTML page is self-contained (pictures embedded, see `fabplan.report`) and shows the
counts, why the count is what it is (the Weingarten evidence), the pictures of the paper's
Figs. 1 and 19 (panels coloured by mold, isolines of constant curvature) and the (k1, k2)
plane with the molds, then one table row per mold and per panel.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..io.output import output_folder, write_texts
from ..io.records import json_text
from ..net.geometry import face_normals
from ..report import figures, html
from .molds import MOLD_TYPES, PANEL_TYPES, MoldPlan

__all__ = ["explain_mold_count", "facade_view", "mold_figure", "step_figure", "mold_report_html",
           "mold_report_files", "write_mold_report"]

_PER_M = 1000.0  # curvatures are stored per mm; the pictures and tables show them per m


def explain_mold_count(plan: MoldPlan) -> str:
    """Why the net needs the molds it needs, in two or three sentences with its numbers."""
    w = plan.weingarten
    reach = plan.curvature_reach(0.5) * _PER_M
    reach_large = plan.curvature_reach(0.9) * _PER_M
    n, m = plan.panel_count, plan.mold_count
    text = (f"One mold absorbs a curvature difference of about 16 t / w^2 for panels of width "
            f"w at tolerance t = {plan.settings.tolerance_mm:g} mm: {reach:.3g} 1/m for the "
            f"median panel (w = {plan.panel_width_mm(0.5) / 1000:.3g} m), {reach_large:.3g} 1/m "
            f"for the largest tenth (w >= {plan.panel_width_mm(0.9) / 1000:.3g} m). ")
    if w.get("thickness") is None:
        return text + "There are too few panels to measure how their curvatures spread."
    band = 2.0 * w["line_residual_rms"] * _PER_M
    length = 4.0 * w["spread"] * _PER_M
    text += (f"The panels' principal curvature pairs (k1, k2) spread over about {length:.3g} 1/m "
             f"along the line a k1 + b k2 = c and lie within {band / 2:.3g} 1/m (rms) of it: "
             f"a band {band / max(reach_large, 1e-300):.2g} times as wide as one mold's reach "
             f"for the large panels (Weingarten residual {w['thickness']:.3f} of the spread). ")
    if band <= reach_large:
        text += (f"The pairs form a one-parameter family, as on a Weingarten surface: panels "
                 f"along a curve of constant curvature share a mold, the molds line up along "
                 f"the curve, and {m} molds serve {n} panels (M / sqrt(N) = "
                 f"{m / math.sqrt(n):.2f}).")
    else:
        text += (f"The pairs fill a region of the (k1, k2) plane, not a curve: the molds must "
                 f"tile an area rather than a line, so {m} molds are needed for {n} panels "
                 f"(M / sqrt(N) = {m / math.sqrt(n):.2f}), and their number grows towards N "
                 f"as the tolerance tightens or the panels grow.")
    return text


def _vertex_values(mesh, face_values: np.ndarray) -> np.ndarray:
    face = np.repeat(np.arange(len(mesh.face_sizes)), mesh.face_sizes)
    total = np.bincount(mesh.face_indices, face_values[face], minlength=mesh.vertex_count)
    count = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    return total / np.maximum(count, 1)


def _mold_colors(plan: MoldPlan) -> np.ndarray:
    return figures.distinct_colors(max(plan.mold_count, 1))


def facade_view(mesh) -> tuple:
    """Face normals and the viewing frame of the facade pictures."""
    normals = face_normals(mesh.vertices, mesh)
    return normals, figures.view_frame(mesh.vertices, normals, mesh.face_areas)


def mold_figure(plan: MoldPlan, *, title: str | None = None) -> str:
    """Data URI of the facade with its panels coloured by mold (failures red)."""

    mesh = plan.mesh
    normals, view = facade_view(mesh)
    colors = _mold_colors(plan)[plan.mold]
    fail = plan.failures
    colors[fail] = (0.85, 0.1, 0.1, 1.0)
    fig = figures.new_figure((9, 7))
    ax = fig.subplots()
    figures.draw_mesh(ax, mesh.vertices, mesh.faces, colors, view, normals=normals)
    ax.set_title(title or (f"{plan.panel_count} panels on {plan.mold_count} molds: one colour "
                           "per mold" + (f" ({fail.size} failures in red)" if fail.size else "")))
    return figures.figure_to_data_uri(fig)


def step_figure(plan: MoldPlan) -> str:
    """Data URI of the step map: every panel coloured by the largest step between its mold
    and a neighbour's at their shared edges, edges over the limit drawn in red."""
    import matplotlib as mpl

    mesh = plan.mesh
    normals, view = facade_view(mesh)
    pairs = mesh.interior_edge_faces
    worst = np.zeros(plan.panel_count)
    if len(pairs):
        np.maximum.at(worst, pairs[:, 0], plan.step_mm)
        np.maximum.at(worst, pairs[:, 1], plan.step_mm)
    limit = plan.step_limit_mm
    cmap = mpl.colormaps["viridis"]
    colors = cmap(np.clip(worst / limit, 0.0, 1.0))
    fig = figures.new_figure((9, 7))
    ax = fig.subplots()
    figures.draw_mesh(ax, mesh.vertices, mesh.faces, colors, view, normals=normals)
    over = plan.steps_over
    if over.size:
        from matplotlib.collections import LineCollection

        segments = (mesh.vertices[mesh.interior_edges[over]] @ view.T)[..., :2]
        ax.add_collection(LineCollection(segments, colors=[(0.85, 0.1, 0.1)], linewidths=1.5,
                                         zorder=10))
    sm = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0.0, limit), cmap=cmap)
    fig.colorbar(sm, ax=ax, shrink=0.7, label="largest step to a neighbour's mold [mm]")
    ax.set_title(f"Steps between neighbouring panels' molds: largest {plan.max_step_mm:.2f} mm, "
                 f"{over.size} edges over {limit:g} mm")
    return figures.figure_to_data_uri(fig)


def _facade_figures(plan: MoldPlan) -> tuple[str, str]:
    """Data URIs of the facade coloured by mold and of its curvature isolines."""
    from matplotlib.lines import Line2D

    by_mold = mold_figure(plan)
    mesh = plan.mesh
    X = mesh.vertices
    faces = mesh.faces
    normals, view = facade_view(mesh)
    tri = mesh.triangles()
    tri_face = np.repeat(np.arange(len(mesh.face_sizes)), mesh.face_sizes - 2)

    fig = figures.new_figure((9, 7))
    ax = fig.subplots()
    grey = np.tile((0.88, 0.88, 0.88, 1.0), (len(faces), 1))
    lines, owners, colours = [], [], []
    k1 = _vertex_values(mesh, plan.curvature[:, 0] * _PER_M)
    k2 = _vertex_values(mesh, plan.curvature[:, 1] * _PER_M)
    k1_levels = np.quantile(k1, np.linspace(0.04, 0.96, 12))
    # k2 levels paired with the k1 levels through the fitted line a k1 + b k2 = c: on a
    # Weingarten surface each pair of isolines is one curve
    line = plan.weingarten.get("line")
    if line and abs(line["b"]) > 0.2:
        k2_levels = (line["c"] * _PER_M - line["a"] * k1_levels) / line["b"]
    else:
        k2_levels = np.quantile(k2, np.linspace(0.04, 0.96, 12))
    for values, levels, colour in ((k1, k1_levels, "#1f4e9c"), (k2, k2_levels, "#e07b00")):
        if np.ptp(values) <= 1e-12:
            continue
        seg, t, _ = figures.isoline_segments(X, tri, values, np.unique(levels))
        lines.append(seg)
        owners.append(tri_face[t])
        colours.append(np.tile(figures.rgba(colour), (len(seg), 1)))
    if lines:
        figures.draw_mesh(ax, X, faces, grey, view, normals=normals, edge_color="#bbbbbb",
                         edge_width=0.1, lines=np.concatenate(lines),
                         line_faces=np.concatenate(owners), line_colors=np.concatenate(colours))
    else:
        figures.draw_mesh(ax, X, faces, grey, view, normals=normals)
    ax.legend(handles=[Line2D([], [], color="#1f4e9c", label="k1 constant"),
                       Line2D([], [], color="#e07b00", label="k2 constant")], loc="lower right")
    ax.set_title("Isolines of constant k1 and of the k2 the fitted line pairs with it")
    return by_mold, figures.figure_to_data_uri(fig)


def _curvature_figure(plan: MoldPlan) -> str:
    """Data URI of the (k1, k2) plane: the Weingarten fit, and the molds among their panels."""

    colors = _mold_colors(plan)
    fig = figures.new_figure((13, 5.6))
    left, right = fig.subplots(1, 2)
    k = plan.curvature * _PER_M
    left.scatter(k[:, 0], k[:, 1], s=6, c=colors[plan.mold], linewidths=0)
    line = plan.weingarten.get("line")
    if line:
        a, b, c = line["a"], line["b"], line["c"] * _PER_M
        span = np.array([k[:, 0].min(), k[:, 0].max()])
        if abs(b) > 1e-9:
            left.plot(span, (c - a * span) / b, "k--", lw=1,
                      label=f"{a:.3f} k1 + {b:.3f} k2 = {c:.4g} 1/m")
        left.legend(loc="best", fontsize=9)
    left.set_xlabel("k1 [1/m]")
    left.set_ylabel("k2 [1/m]")
    left.set_title("Panels' principal curvatures (signed, k1 >= k2)")
    left.grid(alpha=0.3)

    s = plan.panel_shape * _PER_M
    right.scatter(s[:, 0], s[:, 1], s=6, c=colors[plan.mold], linewidths=0)
    K = plan.mold_shape * _PER_M
    right.scatter(K[:, 0], K[:, 1], marker="x", c="k", s=30, linewidths=1.2, label="molds")
    if plan.mold_count <= 60:
        for j, (x, y) in enumerate(K):
            right.annotate(str(j), (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    right.set_xlabel("K1 [1/m] on the mold")
    right.set_ylabel("K2 [1/m] on the mold")
    right.set_title("Panels in their placement on the mold, and the molds")
    right.legend(loc="best", fontsize=9)
    right.grid(alpha=0.3)
    return figures.figure_to_data_uri(fig)


def _deviation_figure(plan: MoldPlan) -> str:

    fig = figures.new_figure((13, 4))
    left, right = fig.subplots(1, 2)
    tol = plan.settings.tolerance_mm
    left.hist(plan.deviation_mm, bins=40, color="#4a7ab5")
    left.axvline(tol, color="#c0392b", lw=1.5, label=f"tolerance {tol:g} mm")
    left.set_xlabel("measured deviation of a panel from its mold [mm]")
    left.set_ylabel("panels")
    left.legend()
    per = plan.panels_per_mold
    right.bar(np.arange(plan.mold_count), per, color=_mold_colors(plan)[:plan.mold_count])
    right.set_xlabel("mold id")
    right.set_ylabel("panels")
    right.set_title(f"Panels per mold (mean {per.mean():.1f})")
    return figures.figure_to_data_uri(fig)


def mold_report_html(plan: MoldPlan) -> str:
    """The self-contained HTML report of a mold plan."""
    r = plan.record()
    tol = r["tolerance_mm"]
    w = plan.weingarten
    summary_rows = [
        ["net", r["net"]],
        ["model units", f"{r['units']} ({r['mm_per_unit']:g} mm per unit)"],
        ["tolerance", f"{tol:g} mm"],
        ["panel surface", r["panel_surface"]],
        ["panels N", r["panel_count"]],
        ["molds M", r["mold_count"]],
        ["M / sqrt(N)", r["molds_per_sqrt_panels"]],
        ["panels per mold (mean / median / max)",
         f"{r['panels_per_mold']['mean']:.1f} / {r['panels_per_mold']['median']:g} / "
         f"{r['panels_per_mold']['max']}"],
        ["panel types", ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in r["panel_types"].items())],
        ["mold types", ", ".join(f"{v} {k}" for k, v in r["mold_types"].items())],
        ["largest measured deviation", f"{r['max_deviation_mm']:.3f} mm"],
        ["panels that do not fit", len(r["failures"])],
        ["largest step between neighbouring panels' molds",
         f"{r['panel_steps']['max_mm']:.3f} mm (limit {r['panel_steps']['limit_mm']:g} mm)"],
        ["shared edges with a step over the limit",
         f"{len(r['panel_steps']['over_limit'])} of {r['panel_steps']['edge_count']}"],
        ["largest angle between neighbouring molds at shared edges",
         f"{r['panel_steps']['max_kink_deg']:.2f} deg"],
        ["fewest molds possible (curvature set length / reach of one mold)",
         r["mold_count_bound"]["molds"]],
        ["largest distance of a net vertex from the panel surface",
         f"{r['max_vertex_miss_mm']:.1f} mm (vertices extended from the interior)"],
        ["largest gap between a panel's quadric and the one surface",
         f"{r['max_surface_gap_mm']:.2f} mm (panels cast from the one surface)"],
        ["panels cast from their own local_fit quadric (the one surface misses a corner)",
         r["panels_cast_locally"]],
        ["largest gap between a panel's corner (a net vertex) and its mold",
         f"{r['max_corner_deviation_mm']:.3f} mm"],
        ["panels the verification moved to new molds", len(r["reassigned_by_verification"])],
        ["Weingarten residual (rms distance from the line, 1/m)",
         None if w.get("line_residual_rms") is None else w["line_residual_rms"] * _PER_M],
        ["Weingarten residual / curvature spread", w.get("thickness")],
        ["largest mold size",
         "no limit" if r["max_mold_size_mm"] is None else f"{r['max_mold_size_mm']:g} mm"],
        ["run time", f"{r['seconds']:.1f} s"],
    ]
    steps = r["panel_steps"]
    if plan.fits_all:
        verdict = html.html_paragraph(
            f"Every panel fits its mold within {tol:g} mm, measured on densely sampled panels "
            "and their corners (the net's vertices) placed by their exported matrices, and "
            "neighbouring panels meet: the largest step "
            f"between their molds at a shared edge is {steps['max_mm']:.2f} mm (limit "
            f"{steps['limit_mm']:g} mm).", cls="note")
    elif len(r["failures"]):
        verdict = html.html_paragraph(f"{len(r['failures'])} panels do not fit (faces "
                                      f"{', '.join(map(str, r['failures'][:20]))}"
                                      f"{' ...' if len(r['failures']) > 20 else ''}); see the "
                                      "panel table.", cls="fail")
    else:
        verdict = html.html_paragraph(
            f"Every panel fits its mold, but {len(steps['over_limit'])} shared edges have a step "
            f"over {steps['limit_mm']:g} mm between the two panels' molds (largest "
            f"{steps['max_mm']:.2f} mm); see the step map.", cls="fail")
    by_mold, isolines = _facade_figures(plan)
    ext, mdev, per = plan.mold_extent_mm(), plan.mold_deviation_mm(), plan.panels_per_mold
    mold_rows = [[j, MOLD_TYPES[plan.mold_type[j]], plan.mold_shape[j, 0] * _PER_M,
                  plan.mold_shape[j, 1] * _PER_M,
                  None if plan.mold_shape[j, 0] == 0 else 1 / plan.mold_shape[j, 0],
                  None if plan.mold_shape[j, 1] == 0 else 1 / plan.mold_shape[j, 1],
                  round(float(ext[j, 0])), round(float(ext[j, 1])), int(per[j]), float(mdev[j])]
                 for j in range(plan.mold_count)]
    rotation = Rotation.from_matrix(plan.placement[:, :3, :3] / plan.settings.mm_per_unit)
    turn = np.degrees(rotation.as_rotvec())
    panel_rows = [[i, int(plan.mold[i]), PANEL_TYPES[plan.panel_type[i]].replace("_", " "),
                   plan.curvature[i, 0] * _PER_M, plan.curvature[i, 1] * _PER_M,
                   "({:.2f}, {:.2f}, {:.2f})".format(*turn[i]),
                   "({:.1f}, {:.1f}, {:.1f})".format(*plan.placement[i, :3, 3]),
                   round(float(plan.footprint_mm[i, 0])), round(float(plan.footprint_mm[i, 1])),
                   float(plan.deviation_mm[i]), plan.problem[i] or "fits"]
                  for i in range(plan.panel_count)]
    parts = [
        html.html_section("Summary", verdict, html.html_table(["quantity", "value"], summary_rows)),
        html.html_section("Why this many molds", html.html_paragraph(explain_mold_count(plan))),
        html.html_section(
            "Pictures",
            html.html_figure(by_mold, "Panels coloured by mold (as in Fig. 1a of the paper)."),
            html.html_figure(isolines, "Isolines of constant k1 (blue) at 12 quantiles, and "
                               "of constant k2 (orange) at the values the fitted line "
                               "a k1 + b k2 = c pairs with them. On a Weingarten surface each "
                               "pair is one curve along which both curvatures are constant, and "
                               "the panels along it share a mold (Fig. 1b); where the pairs "
                               "cross, the curvatures vary independently."),
            html.html_figure(_curvature_figure(plan),
                               "Left: every panel's principal curvatures and the fitted line "
                               "a k1 + b k2 = c. Right: the panels' curvatures in their placement "
                               "on their mold, coloured by mold, and the molds (crosses)."),
            html.html_figure(_deviation_figure(plan),
                               "Measured deviations (left) and panels per mold (right)."),
            html.html_figure(step_figure(plan),
                               "Step map: each panel coloured by the largest step between its "
                               "mold and a neighbour's mold, measured at points of their shared "
                               "edges (a point put on one mold, its distance from the other); "
                               "edges over twice the tolerance in red."),
        ),
        html.html_section(
            "Molds",
            html.html_paragraph("Mold surface z = (k1 x^2 + k2 y^2) / 2 in mold coordinates "
                                  "(mm), centred on its apex; size is the rectangle centred on "
                                  "the apex that holds all its panels."),
            html.html_table(["mold", "type", "k1 [1/m]", "k2 [1/m]", "R1 [mm]", "R2 [mm]",
                               "size x [mm]", "size y [mm]", "panels", "max deviation [mm]"],
                              mold_rows)),
        html.html_section(
            "Panels",
            html.html_paragraph("Placement: the rigid motion taking the panel from model "
                                  "coordinates onto its mold, p_mold = s R p + t with s the mm "
                                  "per model unit, R the rotation given by its rotation vector "
                                  "(axis times angle) and t the translation; the full 4 x 4 "
                                  "matrices are in molds.json and panels.csv."),
            html.html_details(f"{plan.panel_count} panels (click to open)", html.html_table(
                ["face", "mold", "type", "k1 [1/m]", "k2 [1/m]", "rotation vector [deg]",
                 "translation [mm]", "footprint x [mm]", "footprint y [mm]", "deviation [mm]",
                 "status"], panel_rows,
                bad_rows=plan.failures.tolist()))),
        html.html_section(
            "Files",
            html.html_paragraph("molds.json: the counts, every mold and every panel with its "
                                  "placement (schema: docs/molds-schema.md). panels.csv: one row "
                                  "per panel. Curvatures there are in 1/mm, lengths in mm.")),
    ]
    return html.html_page(f"Mold report: {Path(str(r['net'])).name}", parts,
                            subtitle=f"{r['panel_count']} panels, {r['mold_count']} molds at "
                                     f"{tol:g} mm, made by fabplan")


def mold_report_files(plan: MoldPlan, folder: str | os.PathLike) -> dict:
    """{path: text} of the three report files in `folder`."""
    folder = Path(folder)
    return {folder / "report.html": mold_report_html(plan),
            folder / "molds.json": json_text(plan.record()),
            folder / "panels.csv": plan.panels_csv()}


def write_mold_report(plan: MoldPlan, folder: str | os.PathLike) -> list[Path]:
    """Write ``report.html``, ``molds.json`` and ``panels.csv`` into `folder`, all or none.

    Returns
    -------
    list of Path, the files written.
    """
    folder = Path(folder)
    with output_folder(folder) as staging:
        write_texts(mold_report_files(plan, staging))
    return [folder / name for name in ("report.html", "molds.json", "panels.csv")]
