"""The mold report: ``report.html``, ``molds.json`` and ``panels.csv`` of a `MoldPlan`.

The HTML page is self-contained (pictures embedded, see `fabplan.report`) and shows the
counts, why the count is what it is (the Weingarten evidence), the pictures of the paper's
Figs. 1 and 19 (panels coloured by mold, isolines of constant curvature) and the (k1, k2)
plane with the molds, then one table row per mold and per panel.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Mapping

import numpy as np
from scipy.spatial.transform import Rotation

from ...io.output import check_apart, output_folder, write_texts
from ...io.records import json_text
from ...layout.boundary_panels import BoundaryPanels
from ...net.geometry import face_normals
from ...net.view import net_edges, net_scene
from ...report import figures, html, viewer
from ...report.html import counted
from ...report.pdf import PdfDocument
from ..limits import LimitCheck, limit_row_label, limit_row_text, limits_record
from .boundary_molds import BoundaryMolds, boundary_molds_text, boundary_panels_csv
from .mold_plan import MoldPlan
from .mold_shapes import MOLD_TYPES, PANEL_TYPES
from .panel_classes import CLASS_WORDS, CLASSES

__all__ = ["explain_mold_count", "facade_view", "mold_figure", "step_figure", "class_figure",
           "classes_section", "mold_report_html",
           "mold_report_files",
           "write_mold_report", "net_viewer_scene", "net_edges", "mold_pictures", "mold_report_pdf",
           "MOLD_FILES"]

PANEL_SURFACE_TEXT = {
    "shared": "pieces of one surface through the net's vertices; neighbours share their edges",
    "local_fit": "one quadric per face, fitted to the corners around it; neighbours may "
                 "differ along their shared edges",
    "corners": "the least curved surface through each face's corners",
    "design": "the patches of the exact design the net lies on",
}
"""What each panel surface model (`fabplan.fabricate.molds.panels`) means, for the report."""

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
    face = mesh.corner_faces
    total = np.bincount(mesh.face_indices, face_values[face], minlength=mesh.vertex_count)
    count = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    return total / np.maximum(count, 1)


def _mold_colors(plan: MoldPlan) -> np.ndarray:
    return figures.distinct_colors(max(plan.mold_count, 1))


def facade_view(mesh) -> tuple:
    """Face normals and the viewing frame of the pictures: seen from where people see the
    design (`fabplan.report.viewer.scene_front`): a facade or a ring from in front, 10
    degrees above the horizon; a roof from 30 degrees above."""
    normals = face_normals(mesh.vertices, mesh)
    front, initial = viewer.scene_front(normals, mesh.face_areas, mesh.vertices)
    elevation = 30.0 if initial == "above" else 10.0
    return normals, figures.elevation_frame(front, elevation)


def net_viewer_scene(plan: MoldPlan, *, title: str, deviation_mm: np.ndarray | None = None,
                     deviation_limit_mm: float | None = None, gaps: np.ndarray | None = None,
                     infinite_radius: float | None = None,
                     boundary_own: int = 0) -> viewer.ViewerScene:
    """The 3D view of a net and its molds (`fabplan.report.viewer`).

    Parameters
    ----------
    plan : the net's `MoldPlan` (its mesh, molds, panel curvatures).
    title : the scene's name in the viewer.
    deviation_mm : (n,) float, distance of every vertex from the design (mm), or None (the
        molds report: the deviation mode then shows each panel's gap to its mold).
    deviation_limit_mm : the limit marked on the deviation scale.
    gaps : (g, 3, 3) float, triangles of the design the net leaves uncovered, or None.
    infinite_radius : Meusnier radii above this (model units) show as planar (grey).
    boundary_own : the molds the net's boundary panels need of their own beyond the net's
        (a study's ``boundary_own_molds``), said beside the net's.

    Returns
    -------
    `fabplan.report.viewer.ViewerScene` with the colour modes mold, deviation, Meusnier
    radius, angle, kink and (with `gaps`) coverage gaps (`fabplan.net.view.net_scene`).
    """
    settings = plan.settings
    scene = net_scene(plan.mesh, title=title, units=settings.units,
                      mm_per_unit=settings.mm_per_unit, deviation_mm=deviation_mm,
                      deviation_limit_mm=deviation_limit_mm, gaps=gaps,
                      infinite_radius=infinite_radius)
    said = (f"the net's panels use {counted(plan.mold_count, 'mold')}, and its boundary panels "
            f"{boundary_own} more of their own" if boundary_own > 0
            else counted(plan.mold_count, 'mold'))
    molds = viewer.ColourMode(
        "mold", "mold (one colour per mold)",
        f"Each colour is one mold ({said}); click a panel for its mold id, the row of the "
        "molds table.",
        values=plan.mold, categorical=True, palette=_mold_colors(plan))
    scene.modes.insert(0, molds)
    if deviation_mm is None:
        scene.modes.insert(1, viewer.ColourMode(
            "deviation", "gap to its mold [mm]",
            "Largest gap between a panel and its mold, measured on the densely sampled panel; "
            "red is above the tolerance.", values=plan.deviation_mm, unit="mm",
            value_range=(0.0, max(float(plan.deviation_mm.max()), settings.tolerance_mm)),
            limit=settings.tolerance_mm))
    # mold first, the deviation from the design (when given) next, then the mold's numbers
    at = 1 if deviation_mm is not None else 0
    scene.info[at:at] = [viewer.PanelInfo("gap to its mold", plan.deviation_mm, "mm", 3),
                         viewer.PanelInfo("k1", plan.curvature[:, 0] * _PER_M, "1/m", 3),
                         viewer.PanelInfo("k2", plan.curvature[:, 1] * _PER_M, "1/m", 3)]
    scene.info.insert(0, viewer.PanelInfo("mold", plan.mold, integer=True))
    return scene


def mold_figure(plan: MoldPlan, *, title: str | None = None) -> str:
    """Data URI of the design with its panels coloured by mold (failures red), seen from
    where people see it (`facade_view`), mold ids written on the panels large enough."""

    mesh = plan.mesh
    normals, view = facade_view(mesh)
    colors = _mold_colors(plan)[plan.mold]
    fail = plan.failures
    colors[fail] = (0.85, 0.1, 0.1, 1.0)
    fig = figures.new_figure((9, 7))
    ax = fig.subplots()
    figures.draw_mesh(ax, mesh.vertices, mesh.faces, colors, view, normals=normals)
    labelled = figures.label_faces(ax, mesh.vertices, mesh.face_indices, mesh.face_sizes,
                                   [str(int(m)) for m in plan.mold], view, normals=normals)
    ax.set_title(title or (f"{counted(plan.panel_count, 'panel')} on "
                           f"{counted(plan.mold_count, 'mold')}: one colour per mold"
                           + (f" ({fail.size} failures in red)" if fail.size else "")))
    if labelled:
        ax.text(0.0, -0.02, f"numbers: mold ids ({counted(labelled, 'panel')} large enough on "
                "the picture to carry one)", transform=ax.transAxes, fontsize=8, va="top")
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
    over = plan.steps_over
    # the edges over the limit in red, over a face they border and hidden by nearer ones
    figures.draw_mesh(ax, mesh.vertices, mesh.faces, colors, view, normals=normals,
                      lines=mesh.vertices[mesh.interior_edges[over]],
                      line_faces=pairs[over, 0] if len(pairs) else np.zeros(0, np.int64),
                      line_colors=(0.85, 0.1, 0.1, 1.0), line_width=1.5)
    sm = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0.0, limit), cmap=cmap)
    fig.colorbar(sm, ax=ax, shrink=0.7, label="largest step to a neighbour's mold [mm]")
    ax.set_title(f"Steps between neighbouring panels' molds\nlargest {plan.max_step_mm:.2f} mm, "
                 f"{over.size} edges over {limit:g} mm")
    return figures.figure_to_data_uri(fig)


#: colours of the panel classes (flat, cold-bent, roll-bent, molded)
CLASS_COLORS = ("#b8c4cc", "#3a8fd0", "#39a85a", "#d9822b")


def class_figure(plan: MoldPlan) -> str:
    """Data URI: the map of the panel classes (left) and every panel's governing figure
    against its limit (right: the cold-bent and molded panels' stress, the flat panels'
    gap to a plane, the roll-bent panels' smallest radius as limit over radius)."""
    from matplotlib.patches import Patch

    classes = plan.classes
    assert classes is not None
    mesh = plan.mesh
    normals, view = facade_view(mesh)
    colors = np.array([figures.rgba(CLASS_COLORS[k]) for k in classes.panel_class])
    fig = figures.new_figure((13, 5.6))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.4, 1]})
    figures.draw_mesh(left, mesh.vertices, mesh.faces, colors, view, normals=normals)
    counts = classes.counts
    left.legend(handles=[Patch(color=CLASS_COLORS[i], label=f"{CLASS_WORDS[c]} ({counts[c]})")
                         for i, c in enumerate(CLASSES)], loc="upper center", fontsize=9,
                bbox_to_anchor=(0.5, -0.01), ncol=4, frameon=False)
    left.set_title(f"Panel classes in {classes.material.label}")
    value, limit, _ = classes.figure()
    use = np.where(classes.panel_class == CLASSES.index("roll_bent"),
                   limit / np.maximum(value, 1e-300), value / np.maximum(limit, 1e-300))
    bins = np.linspace(0.0, max(2.0, float(np.quantile(use, 0.98))), 40)
    for i, c in enumerate(CLASSES):
        pick = classes.panel_class == i
        if pick.any():
            right.hist(np.minimum(use[pick], bins[-1]), bins=bins, color=CLASS_COLORS[i],
                       label=CLASS_WORDS[c], alpha=0.85)
    right.axvline(1.0, color="#c0392b", lw=1.5, label="limit")
    right.set_xlabel("governing figure / its limit (stress, gap to a plane; roll: limit / radius)")
    right.set_ylabel("panels")
    right.legend(fontsize=9)
    right.set_title("How close each panel comes to its class's limit")
    return figures.figure_to_data_uri(fig)


def classes_section(plan: MoldPlan) -> str:
    """The report's section on the panel classes (with a material), or ""."""
    classes = plan.classes
    if classes is None:
        return ""
    m = classes.material
    counts = classes.counts
    cold = classes.panel_class == CLASSES.index("cold_bent")
    roll = classes.panel_class == CLASSES.index("roll_bent")
    rows = [
        ["material", m.label],
        ["cold-bend limit (largest permanent stress)", f"{m.max_bend_stress_mpa:.3g} MPa"],
        ["smallest roll radius", "not rolled" if m.min_roll_radius_mm is None
         else f"{m.min_roll_radius_mm:.3g} mm"],
        ["flatness tolerance", f"the mold tolerance {classes.tolerance_mm:g} mm"
         + ("" if m.flatness_mm_per_m is None else
            f", at most {m.flatness_mm_per_m:g} mm per m of the panel's span")],
        ["panels by class", ", ".join(f"{counts[c]} {CLASS_WORDS[c]}" for c in CLASSES)],
        ["largest stress of a cold-bent panel",
         f"{classes.stress_mpa[cold].max():.1f} MPa (bending "
         f"{classes.bending_stress_mpa[cold].max():.1f}, membrane "
         f"{classes.membrane_stress_mpa[cold].max():.1f})" if cold.any() else "-"],
        ["largest twist of a cold-bent panel",
         f"{np.abs(classes.curvature[cold, 2]).max() * _PER_M:.3g} 1/m" if cold.any() else "-"],
        ["smallest radius of a roll-bent panel",
         f"{classes.roll['min_radius_mm'][roll].min():.0f} mm" if roll.any() else "-"],
        ["molds made (for molded panels)", counted(plan.made_mold_count, "mold")],
        ["molds saved against every curved panel molded",
         f"{counted(plan.molds_saved, 'mold')} (of "
         f"{plan.made_mold_count + plan.molds_saved} curved molds)"],
    ]
    value, limit, unit = classes.figure()
    table = html.html_details(f"{counted(plan.panel_count, 'panel')}: class and governing "
                              "figure (click to open)", html.html_table(
        ["face id", "class", "figure", "limit", "unit", "why"],
        [[i, CLASS_WORDS[CLASSES[classes.panel_class[i]]], float(value[i]), float(limit[i]),
          unit[i], classes.reason(i)] for i in range(plan.panel_count)]))
    return html.html_section(
        "Panel classes",
        html.html_paragraph(
            "Every panel goes to the cheapest class whose check it passes on its densely "
            "sampled surface: flat (a plane within the flatness tolerance), cold-bent (the "
            "best shape a flat sheet takes when bent onto its supports, a twist plus "
            "cylindrical bending, fits within the mold tolerance, and its bending and "
            "membrane stress stays within the material's limit), roll-bent (a cone or "
            "cylinder fits, no tighter than the smallest roll radius), else molded. Only "
            "molded panels need molds (docs/materials.md)."),
        html.html_table(["quantity", "value"], rows),
        html.html_figure(class_figure(plan), "Panel classes (left) and every panel's "
                         "governing figure against its limit (right).",
                         how="Left: one colour per class, seen from where people see the "
                             "design. Right: a bar left of the red line is within its "
                             "limit; molded panels are those whose cheaper checks failed."),
        table)


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


def mold_pictures(plan: MoldPlan) -> dict[str, str]:
    """Data URIs of the report's pictures: ``molds``, ``isolines``, ``curvatures``,
    ``deviations``."""
    by_mold, isolines = _facade_figures(plan)
    return {"molds": by_mold, "isolines": isolines, "curvatures": _curvature_figure(plan),
            "deviations": _deviation_figure(plan)}


def mold_report_html(plan: MoldPlan, *, view_3d: bool = True,
                     pictures: dict[str, str] | None = None,
                     boundary: BoundaryMolds | None = None,
                     limits: dict | None = None) -> str:
    """The self-contained HTML report of a mold plan (`view_3d`: with the interactive 3D
    view, about 0.6 MB more; `pictures`: `mold_pictures` when already drawn; `boundary`:
    the molds of the net's boundary panels, listed in ``boundary-panels.csv``; `limits`:
    the fabrication limits checked, as ``molds.json`` holds them, `limits_record`)."""
    r = plan.record()
    tol = r["tolerance_mm"]
    summary_rows = _summary_rows(plan, r, boundary, limits)
    verdict = _verdict(plan, r)
    pictures = pictures or mold_pictures(plan)
    mold_rows, panel_rows = _mold_rows(plan), _panel_rows(plan)
    parts = [
        html.html_section("Summary", verdict, html.html_table(["quantity", "value"], summary_rows)),
        html.html_section("Why this many molds", html.html_paragraph(explain_mold_count(plan))),
    ]
    if plan.classes is not None:
        parts.append(classes_section(plan))
    if view_3d:
        scene = net_viewer_scene(plan, title=Path(str(r["net"])).name)
        parts.append(html.html_section("3D view", viewer.viewer_block([scene])))
    parts += [
        _pictures_section(plan, pictures, tol),
        html.html_section(
            "Molds",
            html.html_paragraph("Mold surface z = (k1 x^2 + k2 y^2) / 2 in mold coordinates "
                                  "(mm), centred on its apex; size is the rectangle centred on "
                                  "the apex that holds all its panels. An empty radius is "
                                  "infinite (a straight direction)."),
            html.html_table(["mold id", "type", "k1 [1/m]", "k2 [1/m]", "R1 [mm]", "R2 [mm]",
                               "size x [mm]", "size y [mm]", "panels [count]",
                               "largest gap [mm]"], mold_rows)),
        html.html_section(
            "Panels",
            html.html_paragraph("Placement: the rigid motion taking the panel from model "
                                  "coordinates onto its mold, p_mold = s R p + t with s the mm "
                                  "per model unit, R the rotation given by its rotation vector "
                                  "(axis times angle) and t the translation; the full 4 x 4 "
                                  "matrices are in molds.json and panels.csv."),
            html.html_details(f"{counted(plan.panel_count, 'panel')} (click to open)", html.html_table(
                ["face id", "mold id", "type", "k1 [1/m]", "k2 [1/m]", "rotation vector [deg]",
                 "translation [mm]", "footprint x [mm]", "footprint y [mm]", "gap to mold [mm]",
                 "status"], panel_rows,
                bad_rows=plan.failures.tolist()))),
        html.html_section(
            "Files",
            html.html_paragraph("molds.json: the counts, every mold and every panel with its "
                                  "placement (schema: docs/molds-schema.md). panels.csv: one row "
                                  "per panel. Curvatures there are in 1/mm, lengths in mm. Both "
                                  "sit beside this report in its folder.")),
    ]
    return html.html_page(f"Mold report: {Path(str(r['net'])).name}", parts,
                            subtitle=f"{counted(r['panel_count'], 'panel')}, {_molds_headline(r)} "
                                     f"at {tol:g} mm, made by fabplan",
                            scripts=viewer.viewer_assets() if view_3d else "")


def _verification_rows(r: dict) -> list[list]:
    """The rows of the verification (gaps, failures, steps) that report.html and report.pdf
    both give, from the plan's record `r`."""
    return [
        ["largest measured gap to a mold", f"{r['max_deviation_mm']:.3f} mm"],
        ["panels that do not fit", counted(len(r["failures"]), "panel")],
        ["largest step between neighbouring panels' molds",
         f"{r['panel_steps']['max_mm']:.3f} mm (limit {r['panel_steps']['limit_mm']:g} mm)"],
        ["shared edges with a step over the limit",
         f"{len(r['panel_steps']['over_limit'])} of {r['panel_steps']['edge_count']}"],
    ]


def _summary_rows(plan: MoldPlan, r: dict, boundary: BoundaryMolds | None,
                  limits: dict | None) -> list[list]:
    """The rows (quantity, value) of the report's summary table, from the plan's
    record `r`."""
    tol = r["tolerance_mm"]
    w = plan.weingarten
    per_mold = r["panels_per_mold"]
    summary_rows = [
        ["net", r["net"]],
        ["model units", f"{r['units']} ({r['mm_per_unit']:g} mm per {r['units']})"],
        ["tolerance (largest gap between a panel and its mold)", f"{tol:g} mm"],
        ["panel surface", f"{r['panel_surface']}: {PANEL_SURFACE_TEXT[r['panel_surface']]}"],
        ["panels N", counted(r["panel_count"], "panel")],
        ["molds M" + (" (every curved panel molded)" if plan.classes is not None else ""),
         counted(r["mold_count"], "mold")],
        *([["molds made for the molded panels (panel classes below)",
            f"{counted(r['molds_made'], 'mold')}; {r['molds_saved_by_material']} saved by "
            f"the material against every curved panel molded"]]
          if plan.classes is not None else []),
        ["M / sqrt(N)", f"{r['molds_per_sqrt_panels']:.2f} (ratio)"],
        ["panels per mold (mean / median / max)",
         f"{per_mold['mean']:.1f} / {per_mold['median']:g} / {per_mold['max']} panels"],
        ["panel types", ", ".join(counted(v, k.replace('_', ' ') + " panel")
                                  for k, v in r["panel_types"].items())],
        ["mold types", ", ".join(counted(v, k) for k, v in r["mold_types"].items())],
        *_verification_rows(r),
        ["largest angle between neighbouring molds at shared edges",
         f"{r['panel_steps']['max_kink_deg']:.2f} deg"],
        ["fewest molds, estimated (curvature set length / reach of one mold)",
         counted(r["mold_count_bound"]["molds"], "mold")],
        ["panels the verification moved to new molds",
         counted(len(r["reassigned_by_verification"]), "panel")],
        ["Weingarten residual (rms distance from the line)",
         "–" if w.get("line_residual_rms") is None else
         f"{w['line_residual_rms'] * _PER_M:.3g} 1/m"],
        ["Weingarten residual / curvature spread",
         "–" if w.get("thickness") is None else f"{w['thickness']:.3g} (ratio)"],
        ["largest mold size",
         "no limit" if r["max_mold_size_mm"] is None else f"{r['max_mold_size_mm']:g} mm"],
        ["run time", f"{r['seconds']:.1f} s"],
    ]
    summary_rows += [[limit_row_label(c), limit_row_text(c)] for c in (limits or {}).values()]
    if boundary is not None:
        summary_rows.insert(6, ["boundary panels (boundary-panels.csv)",
                                boundary_molds_text(boundary, plan)])
    return summary_rows


def _verdict(plan: MoldPlan, r: dict) -> str:
    """The report's verdict in a paragraph: every panel fits and meets its neighbours, or
    which do not."""
    tol = r["tolerance_mm"]
    steps = r["panel_steps"]
    if plan.fits_all:
        verdict = html.html_paragraph(
            f"Every panel fits its mold within {tol:g} mm, measured on densely sampled panels "
            "placed by their exported matrices, and neighbouring panels meet: the largest step "
            f"between their molds at a shared edge is {steps['max_mm']:.2f} mm (limit "
            f"{steps['limit_mm']:g} mm).", cls="note")
    elif len(r["failures"]):
        verdict = html.html_paragraph(f"{counted(len(r['failures']), 'panel')} do not fit (faces "
                                      f"{', '.join(map(str, r['failures'][:20]))}"
                                      f"{' ...' if len(r['failures']) > 20 else ''}); see the "
                                      "panel table.", cls="fail")
    else:
        verdict = html.html_paragraph(
            f"Every panel fits its mold, but {counted(len(steps['over_limit']), 'shared edge')} "
            f"have a step over {steps['limit_mm']:g} mm between the two panels' molds (largest "
            f"{steps['max_mm']:.2f} mm); see the step map.", cls="fail")
    return verdict


def _mold_rows(plan: MoldPlan) -> list[list]:
    """One row of the molds table per mold."""
    ext, mdev, per = plan.mold_extent_mm(), plan.mold_deviation_mm(), plan.panels_per_mold
    mold_rows = [[j, MOLD_TYPES[plan.mold_type[j]], plan.mold_shape[j, 0] * _PER_M,
                  plan.mold_shape[j, 1] * _PER_M,
                  None if plan.mold_shape[j, 0] == 0 else 1 / plan.mold_shape[j, 0],
                  None if plan.mold_shape[j, 1] == 0 else 1 / plan.mold_shape[j, 1],
                  round(float(ext[j, 0])), round(float(ext[j, 1])), int(per[j]), float(mdev[j])]
                 for j in range(plan.mold_count)]
    return mold_rows


def _panel_rows(plan: MoldPlan) -> list[list]:
    """One row of the panels table per panel."""
    rotation = Rotation.from_matrix(plan.placement[:, :3, :3] / plan.settings.mm_per_unit)
    turn = np.degrees(rotation.as_rotvec())
    panel_rows = [[i, int(plan.mold[i]), PANEL_TYPES[plan.panel_type[i]].replace("_", " "),
                   plan.curvature[i, 0] * _PER_M, plan.curvature[i, 1] * _PER_M,
                   "({:.2f}, {:.2f}, {:.2f})".format(*turn[i]),
                   "({:.1f}, {:.1f}, {:.1f})".format(*plan.placement[i, :3, 3]),
                   round(float(plan.footprint_mm[i, 0])), round(float(plan.footprint_mm[i, 1])),
                   float(plan.deviation_mm[i]), plan.problem[i] or "fits"]
                  for i in range(plan.panel_count)]
    return panel_rows


def _pictures_section(plan: MoldPlan, pictures: dict[str, str], tol: float) -> str:
    """The report's section of pictures (`mold_pictures`), each with how to read it."""
    by_mold, isolines = pictures["molds"], pictures["isolines"]
    return (
        html.html_section(
            "Pictures",
            html.html_figure(by_mold, "Panels coloured by mold (as in Fig. 1a of the paper), "
                                      "seen from where people see the design.",
                             how="One colour per mold; the number on a panel is its mold id, "
                                 "the row of the molds table below (written where the panel "
                                 "is large enough on the picture). Neighbouring molds can "
                                 "share similar colours: trust the numbers, or click the panel "
                                 "in the 3D view."),
            html.html_figure(isolines, "Isolines of constant k1 (blue) at 12 quantiles, and "
                               "of constant k2 (orange) at the values the fitted line "
                               "a k1 + b k2 = c pairs with them.",
                             how="On a Weingarten surface each blue line runs with an orange "
                                 "one: both curvatures are constant along it, and the panels "
                                 "along it share a mold (Fig. 1b). Where the lines cross, the "
                                 "curvatures vary independently and more molds are needed."),
            html.html_figure(pictures["curvatures"],
                               "Left: every panel's principal curvatures and the fitted line "
                               "a k1 + b k2 = c. Right: the panels' curvatures in their placement "
                               "on their mold, coloured by mold, and the molds (crosses).",
                             how="Each dot is a panel, in 1/m (1 / radius). Dots close to a "
                                 "line mean few molds; the crosses on the right are the molds, "
                                 "numbered by mold id when there are at most 60."),
            html.html_figure(pictures["deviations"],
                               "Measured gaps of the panels to their molds (left) and panels "
                               "per mold (right).",
                             how=f"Left: how many panels have each gap, in mm; all must lie "
                                 f"left of the red tolerance line ({tol:g} mm). Right: one "
                                 "bar per mold id, its height the panels cast on it."),
            html.html_figure(step_figure(plan),
                               "Step map: each panel coloured by the largest step between its "
                               "mold and a neighbour's mold, measured at points of their shared "
                               "edges (a point put on one mold, its distance from the other); "
                               "edges over twice the tolerance in red.",
                             how="A fabricator sees the step where two finished panels meet; "
                                 "yellow panels reach the limit of twice the tolerance."),
        )
    )


def _molds_headline(record: dict) -> str:
    """The molds in a report's headline: those to make, and with a material also those
    every curved panel molded would need (one count, said the same way everywhere)."""
    if record.get("panel_classes") is None:
        return counted(record["mold_count"], "mold")
    return (f"{counted(record['molds_made'], 'mold')} to make "
            f"({record['mold_count']} with every curved panel molded)")


def mold_report_files(plan: MoldPlan, folder: str | os.PathLike, *, view_3d: bool = True) -> dict:
    """{path: text} of the three report files in `folder`."""
    folder = Path(folder)
    return {folder / "report.html": mold_report_html(plan, view_3d=view_3d),
            folder / "molds.json": json_text(plan.record()),
            folder / "panels.csv": plan.panels_csv()}


def mold_report_pdf(plan: MoldPlan, pictures: dict[str, str] | None = None, *,
                    boundary: BoundaryMolds | None = None,
                    limits: dict | None = None) -> PdfDocument:
    """The printable report (``report.pdf``): summary (the verification's figures, the
    boundary panels' molds and the fabrication limits as report.html gives them), why
    this many molds, the pictures and the molds table (the panels are in ``panels.csv``)."""
    r = plan.record()
    pictures = pictures or mold_pictures(plan)
    doc = PdfDocument(f"Mold report: {Path(str(r['net'])).name}",
                      f"{counted(r['panel_count'], 'panel')}, {counted(r['mold_count'], 'mold')} "
                      f"at {r['tolerance_mm']:g} mm, made by fabplan. The 3D view is in "
                      "report.html beside this file; every panel is in panels.csv.")
    summary = doc.section("Summary")
    summary.text(explain_mold_count(plan))
    summary.table(["quantity", "value"], [
        ["panels", counted(r["panel_count"], "panel")],
        ["molds", counted(r["mold_count"], "mold")],
        *([["panel classes (" + plan.classes.material.label + ")",
            ", ".join(f"{n} {CLASS_WORDS[c]}" for c, n in plan.classes.counts.items())],
           ["molds made for the molded panels",
            f"{counted(r['molds_made'], 'mold')} ({r['molds_saved_by_material']} saved by the "
            "material)"]] if plan.classes is not None else []),
        ["tolerance (largest gap between a panel and its mold)", f"{r['tolerance_mm']:g} mm"],
        *_verification_rows(r),
        *([["boundary panels (boundary-panels.csv)",
            boundary_molds_text(boundary, plan)]] if boundary is not None else []),
        *[[limit_row_label(c), limit_row_text(c)] for c in (limits or {}).values()],
    ], widths=[2, 1])
    figures_section = doc.section("Pictures")
    for key, caption in (("molds", "Panels coloured by mold; numbers are mold ids."),
                         ("isolines", "Isolines of constant k1 (blue) and k2 (orange)."),
                         ("curvatures", "Panels' principal curvatures (1/m) and the molds."),
                         ("deviations", "Gaps of the panels to their molds (mm); panels per "
                                        "mold.")):
        figures_section.image(pictures[key], caption, max_height=0.38)
    ext, mdev, per = plan.mold_extent_mm(), plan.mold_deviation_mm(), plan.panels_per_mold
    doc.section("Molds").table(
        ["mold id", "type", "k1 [1/m]", "k2 [1/m]", "size [mm]", "panels [count]",
         "largest gap [mm]"],
        [[j, MOLD_TYPES[plan.mold_type[j]], f"{plan.mold_shape[j, 0] * _PER_M:.4g}",
          f"{plan.mold_shape[j, 1] * _PER_M:.4g}", f"{ext[j, 0]:.0f} x {ext[j, 1]:.0f}",
          int(per[j]), f"{mdev[j]:.3g}"] for j in range(plan.mold_count)])
    return doc


def write_mold_report(plan: MoldPlan, folder: str | os.PathLike, *, view_3d: bool = True,
                      boundary: tuple[BoundaryPanels, BoundaryMolds] | None = None,
                      protect: Mapping[Path, str] | None = None,
                      limits: list[LimitCheck] | None = None) -> list[Path]:
    """Write ``report.html``, ``report.pdf``, ``molds.json`` and ``panels.csv`` into
    `folder`, all or none (`view_3d`: the HTML report with its interactive 3D view). With
    `boundary` (the net's boundary panels and their molds, `boundary_molds`) also
    ``boundary-panels.csv``, ``boundary-panels.obj`` (the panels as cut from their molds)
    and ``boundary_panels`` in ``molds.json``. `limits` (fabrication limits checked, such
    as the net's deviation from its design) go into ``molds.json`` as ``limits`` and into
    the report's summary. No file replaces
    one of `protect` (the run's inputs, path -> what it is).

    Returns
    -------
    list of Path, the files written.
    """
    folder = Path(folder)
    pictures = mold_pictures(plan)
    record = plan.record()
    record["limits"] = limits_record(limits or [])
    texts = {"panels.csv": plan.panels_csv()}
    if boundary is not None:
        panels, molds = boundary
        record["boundary_panels"] = molds.record(net_molds=plan.made_mold_count)
        texts["boundary-panels.csv"] = boundary_panels_csv(panels, molds)
        texts["boundary-panels.obj"] = molds.cut_obj_text(
            "fabplan boundary panels as cut from their molds (placements in "
            "boundary-panels.csv), one face per panel of the net's boundary panels")
    stale = _stale_boundary_files(folder, texts)
    check_apart(stale, protect or {})          # removed like the files written: never an input
    with output_folder(folder, protect=protect) as staging:
        write_texts({staging / "report.html": mold_report_html(
                         plan, view_3d=view_3d, pictures=pictures,
                         boundary=None if boundary is None else boundary[1],
                         limits=record["limits"]),
                     staging / "molds.json": json_text(record),
                     **{staging / name: text for name, text in texts.items()}})
        mold_report_pdf(plan, pictures, boundary=None if boundary is None else boundary[1],
                        limits=record["limits"]).write(staging / "report.pdf")
    for path in stale:
        path.unlink(missing_ok=True)
    return [folder / name for name in ("report.html", "report.pdf", "molds.json", *texts)]


def _stale_boundary_files(folder: Path, texts: dict) -> list[Path]:
    """The boundary panels' files an earlier run wrote into `folder` that this run (whose
    files are `texts`) does not: they would mix two runs in one folder. Only when the
    earlier ``molds.json`` records boundary panels, and only regular files."""
    try:
        earlier = json.loads((folder / "molds.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    if not isinstance(earlier, dict) or not earlier.get("boundary_panels"):
        return []
    paths = [folder / name for name in MOLD_FILES
             if name.startswith("boundary-panels.") and name not in texts]
    return [p for p in paths if p.is_file() and not p.is_symlink()]


#: the files `write_mold_report` may write into its folder
MOLD_FILES = ("report.html", "report.pdf", "molds.json", "panels.csv", "boundary-panels.csv",
              "boundary-panels.obj")
