"""The pages of a study report: the self-contained ``report.html`` (the recommendation,
the comparison, the searches, the 3D view of every net and a section per candidate) and
the printable ``report.pdf``; their tables and sentences are `fabplan.study.tables`, their
pictures `fabplan.study.pictures`.
"""

from __future__ import annotations

import os
from html import escape as html_escape
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..fabricate.molds.mold_report import net_viewer_scene
from ..report import html, viewer
from ..report.html import counted
from ..report.pdf import PdfDocument
from .candidate_measure import vertex_deviation_mm
from .result import CandidateResult, StudyResult
from .search import search_record
from .tables import (
    INFINITE_RADIUS_FACTOR,
    RANK_RULE,
    candidate_facts,
    check_rows,
    comparison_rows,
    comparison_table,
    cost_line,
    cost_table,
    kink_text,
    limit_items,
    limit_text,
    limits_table,
    pareto_text,
    search_text,
)
from .verdict import every_panel_flat

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface


__all__ = ["study_html", "study_pdf", "study_viewer_scenes", "coverage_gap_triangles"]


def _candidate_section(c: CandidateResult, pictures: dict, outputs: dict,
                       result: StudyResult, scene: int | None = None) -> str:
    head = f"{c.rank}. {c.name}" if c.rank else c.name
    if c.failed:
        return html.html_section(head, html.html_paragraph(
            f"{c.candidate.describe()}: failed. {c.error}", cls="fail"))
    units = result.study.design.units
    molds = c.metrics["molds"]
    verdict, facts = candidate_facts(c, result)
    checks = html.html_table(
        ["limit", "measured", "bound", "met", "what was measured"], check_rows(c),
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
            boundary_own=c.metrics["molds"].get("boundary_own_molds", 0))
        if trimmed:
            scene.layer = boundary_layer(
                panels, units=result.study.design.units,
                info=boundary_mold_info(c.boundary_molds) if c.boundary_molds is not None else ())
        scenes.append(scene)
    return scenes, index


def _design_text(study) -> str:
    """The design as the report's header names it: its file (a mesh or Rhino file, with
    its choices), else the built-in surface."""
    source = study.design.source
    file = source.split("#", 1)[0]
    if os.path.isfile(file):
        return f"Design {study.design.label} (from {Path(file).name})"
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
           + (" including the files of the candidates" if seconds_total is not None else ""))
    parts = []
    if study.description:
        parts.append(html.html_paragraph(study.description))
    parts.append(html.html_section(
        "Recommendation", html.html_paragraph(result.recommendation,
                                                cls="note" if result.recommended else "fail")))
    overview = [comparison_table(result)]
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
    overview += [limits_table(result), cost_table(result),
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
    first = doc.section("Recommendation and comparison")
    for paragraph in result.recommendation.split("\n"):
        first.text(paragraph)
    columns, rows = comparison_rows(result)
    first.table(columns, rows, widths=[0.5, 1.6, 0.7, 0.7, 0.7, 0.9, 0.8, 2.2])
    first.text(RANK_RULE, size=7.5, style="italic")
    first.text(cost_line(result), size=7.5)
    first.table(["limit", "value"], [list(limit_text(k, v)) for k, v in
                                     limit_items(result)], widths=[3, 1])
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
        verdict, facts = candidate_facts(c, result)
        section.text(verdict)
        section.table(["quantity", "value"], facts, widths=[1.2, 3])
        section.table(["limit", "measured", "bound", "met", "what was measured"],
                      check_rows(c), widths=[1.6, 0.8, 0.8, 0.4, 2.6])
        own = pictures.get(c.name, {})
        for key, caption in (("deviation", "Deviation from the design (mm); red line on the "
                                            "scale: the limit."),
                             ("molds", "Panels coloured by mold; numbers are mold ids."),
                             ("net", "The net on the design surface."),
                             ("sheet", "First strip sheet as cut.")):
            if key in own:
                section.image(own[key], caption, max_height=0.4)
    return doc
