"""The page of one net: ``OUT.html`` of ``fabplan layout --html`` and ``fabplan optimize --html``.

A self-contained HTML page (`fabplan.report.html.html_page`) with the net's key numbers
from its JSON record in a table with units, the interactive 3D view
(`fabplan.report.viewer`) of the net and its boundary panels, and a static picture as a
fallback where WebGL is missing (and for print). The colour modes are those a single net
has (`fabplan.net.view.net_scene`): deviation from the design or reference, Meusnier
radius, intersection angle, kink, line turn and, for a layout, the design's uncovered
parts.
"""

from __future__ import annotations

import base64
from typing import Any, Sequence

import numpy as np

from ..io.rhino_read import MM_PER_UNIT
from ..net.mesh import QuadMesh
from ..net.view import net_scene
from ..report import figures, html, viewer
from ..report.html import counted
from .boundary_panels import BoundaryPanels

__all__ = ["boundary_layer", "uncovered_triangles", "net_numbers", "net_picture_uri",
           "net_view_html", "BOUNDARY_KINDS"]

#: What a boundary panel is, by the code `boundary_layer` shows for it.
BOUNDARY_KINDS = ("trimmed to the design boundary", "closes a hole in the net",
                  "extension cut with the full panel beside it")

_VIEW_HELP = ("How to use the 3D view: drag to orbit, scroll to zoom, right-drag (or shift-drag) "
              "to pan. The buttons show the net from eye level (a person 1.7 m tall standing "
              "in front of it), from the front, from 30 degrees above and from the top. Click "
              "a panel to pin its numbers (face id, deviation, radius, kink, line turn; for a "
              "boundary panel its kind and the face it continues); hover to read them. It "
              "needs WebGL; the picture further down shows the same net.")

_PICTURE_HOW = ("The same net as the 3D view, drawn once from where people see it: for a "
                "browser without WebGL, and for print.")


def boundary_layer(panels: BoundaryPanels, *, units: str = "",
                   info: Sequence[viewer.PanelInfo] = ()) -> viewer.PanelLayer:
    """The boundary panels of a net as a layer of its 3D view (drawn green, as in the
    static pictures, and hatched); only the points they use are kept.

    Parameters
    ----------
    panels : the net's `BoundaryPanels`.
    units : model units (the areas are shown in units squared).
    info : more numbers per panel (p,), shown after the panel's kind, the full panel it
        continues, its area and corners (e.g. the mold it is cut from:
        `fabplan.fabricate.molds.boundary_molds.boundary_mold_info`).

    Returns
    -------
    `fabplan.report.viewer.PanelLayer`
    """
    triangles, panel = panels.panel_triangles()
    sizes = np.array([len(q) for q in panels.polygons], dtype=np.int64)
    indices = (np.concatenate(panels.polygons).astype(np.int64) if len(sizes)
               else np.zeros(0, np.int64))
    # only the points the panels use: the net's other vertices would double the bytes
    used, inverse = np.unique(np.r_[indices, triangles.ravel()], return_inverse=True)
    vertices = panels.vertices[used]
    indices, triangles = inverse[:len(indices)], inverse[len(indices):].reshape(-1, 3)
    kind = np.where(panels.extension, 2, np.where(panels.patch, 1, 0)) if len(sizes) else sizes
    area_unit = f"{units}²" if units else "units²"
    layer_info = [viewer.PanelInfo("kind", kind, names=BOUNDARY_KINDS),
                  viewer.PanelInfo("continues face", np.asarray(panels.neighbour_face),
                                   integer=True, absent="none"),
                  viewer.PanelInfo("area", np.asarray(panels.area, float), area_unit, 3),
                  viewer.PanelInfo("corners", panels.corner_counts() if len(sizes) else sizes,
                                   integer=True),
                  *info]
    return viewer.PanelLayer(
        "boundary panel", vertices, sizes, indices, triangles, panel, info=layer_info,
        how=f"Green, hatched: {counted(panels.panel_count, 'boundary panel')} between the net and the "
            "design boundary, the net's lines extended to the boundary and cut there"
            + (f" (and {counted(panels.count - panels.panel_count, 'sliver')} cut as part of the "
               "full panel beside it)" if panels.count > panels.panel_count else "")
            + "; click one for the face it continues. The check box above hides them.",
        toggle=f"{counted(panels.panel_count, 'boundary panel')} (green)")


def uncovered_triangles(design: Any, vertices: np.ndarray, triangles: np.ndarray, *,
                        gap: float) -> np.ndarray:
    """The design's triangles no panel covers: those whose centroid lies farther than
    `gap` (model units) from the panels.

    Parameters
    ----------
    design : a surface with ``vertices`` (n, 3) and ``triangles`` (t, 3) (a
        `DesignSurface`).
    vertices : (m, 3) float and triangles : (k, 3) int, the panels (the net's and the
        boundary panels' triangles together).

    Returns
    -------
    (g, 3, 3) float, the uncovered triangles' corners.
    """
    import igl

    V, T = np.asarray(design.vertices, float), np.asarray(design.triangles, np.int64)
    centroids = V[T].mean(axis=1)
    sq, _, _ = igl.point_mesh_squared_distance(centroids, np.asarray(vertices, float),
                                               np.asarray(triangles, np.int64))
    return V[T[np.asarray(sq) > gap * gap]]


def _stat(props: dict, key: str, which: str) -> float | None:
    value = (props.get(key) or {}).get(which)
    return float(value) if isinstance(value, (int, float)) else None


def net_numbers(record: dict, *, units: str, mm_per_unit: float,
                distance_key: str = "distance_to_design") -> list[list]:
    """The key numbers of a net's JSON record as rows ``[quantity, value, unit]``: the
    unit is ``"count"`` for counts, ``"(ratio)"`` for ratios, empty for words only.

    Parameters
    ----------
    record : the record written beside the OBJ (`OptimizationResult.record`).
    units : the model units; mm_per_unit : millimetres per model unit (distances to the
        design are shown in mm).
    distance_key : the record's distance of the net from its surface:
        ``distance_to_design`` (a layout) or ``distance_to_reference`` (an optimization).

    Examples
    --------
    >>> rows = net_numbers({"status": "converged", "iterations": 6, "seconds": 0.27,
    ...                     "properties": {"faces": 400, "mean_edge_length": 1.01,
    ...                                    "distance_to_design": {"max": 2e-4, "mean": 4e-5}}},
    ...                    units="m", mm_per_unit=1000.0)
    >>> [r for r in rows if r[0].startswith("distance")]
    [['distance from the design, largest', 0.2, 'mm'], ['distance from the design, mean', 0.04, 'mm']]
    """
    props = record.get("properties") or {}
    rows: list[list] = [["status", record.get("status"), ""],
                        ["solver iterations", record.get("iterations"), "count"],
                        ["solve time", record.get("seconds"), "s"]]
    for key, value in (record.get("parameters") or {}).items():
        if not isinstance(value, float):
            continue
        if key.endswith("_deg"):
            rows.append([f"{key[:-4].replace('_', ' ')} (solved or given)", value, "deg"])
        elif key in ("radius", "panel_size", "mannheim_radius"):
            rows.append([f"{key.replace('_', ' ')} (solved or given)", value, units])
    for key, label in (("vertices", "vertices"), ("faces", "panels (faces)")):
        if props.get(key) is not None:
            rows.append([label, props[key], "count"])
    if props.get("irregular_vertices") is not None:
        rows.append(["irregular vertices", len(props["irregular_vertices"]), "count"])
    boundary = props.get("boundary_panels") or {}
    if "count" in boundary:
        rows.append(["boundary panels", boundary["count"], "count"])
    if props.get("mean_edge_length") is not None:
        rows.append(["mean edge length", props["mean_edge_length"], units])
    edge = props.get("edge_length_relative_to_panel")
    if edge:
        rows.append(["edge length / panel size", html.format_range(edge["min"], edge["max"]),
                     "(ratio)"])
    for which, word in (("max", "largest"), ("mean", "mean")):
        d = _stat(props, distance_key, which)
        if d is not None:
            what = "the design" if distance_key == "distance_to_design" else "the reference"
            rows.append([f"distance from {what}, {word}", d * mm_per_unit, "mm"])
    if props.get("coverage") is not None:
        if props.get("coverage_net") is not None:
            rows.append(["design covered by the full panels", 100 * props["coverage_net"], "%"])
        rows.append(["design covered by all panels", 100 * props["coverage"], "%"])
    off = boundary.get("off_design")
    if off is not None:
        # panels over a hole or past the boundary: an error, said with where it is
        places = off.get("places") or []
        where = "" if not places else " (largest around " + ", ".join(
            f"{v:.4g}" for v in places[0]["point"]) + ")"
        rows.append([f"panel area off the design{where}", off["area"], f"{units}²"])
    crossings = boundary.get("crossings")
    if crossings is not None:
        rows.append(["boundary panels crossing themselves or overlapping",
                     crossings["self_crossing"] + crossings["overlapping"]
                     + crossings["edge_clashes"], "count"])
    for check in (props.get("limits") or {}).values():
        # a fabrication limit checked on the net (`fabplan.fabricate.limits`), as recorded
        rows.append([f"{check['words']}: limit ({check['option']})", check["limit"], check["unit"]])
        rows.append([f"{check['words']}: {check['parts']} over the limit", check["over"], "count"])
        if check["worst"] is not None:
            rows.append([f"{check['words']}: largest", check["worst"], check["unit"]])
    residual = _stat(props, "sphere_residual_relative", "max")
    if residual is not None:
        rows.append(["sphere residual, largest / mean edge", residual, "(ratio)"])
    for which, word in (("min", "smallest"), ("median", "median")):
        r = _stat(props, "meusnier_radius", which)
        if r is not None:
            rows.append([f"Meusnier radius, {word}", r, units])
    lo, hi = (_stat(props, "intersection_angle_deg", "min"),
              _stat(props, "intersection_angle_deg", "max"))
    if lo is not None and hi is not None:
        rows.append(["intersection angle", html.format_range(lo, hi), "deg"])
    planarity = _stat(props, "face_planarity_relative", "max")
    if planarity is not None:
        rows.append(["face planarity, largest / mean edge", planarity, "(ratio)"])
    turn = ((props.get("fairness") or {}).get("line_turn_deg") or {}).get("max")
    if turn is not None:
        rows.append(["line turn in the surface, largest", turn, "deg"])
    folds = props.get("folds")
    if folds is not None:
        flipped = (folds.get("flipped_faces") or {}).get("count", 0)
        rows.append(["folds", "none" if not folds.get("folded") else
                     counted(int(flipped), "flipped panel"), ""])
    build = props.get("buildable")
    if build is not None:
        darts = int(build["nonconvex_faces"]["count"])
        sharp = int(build["sharp_line_turns"]["count"])
        rows.append(["darts and lines doubling back", "none" if not (darts or sharp) else
                     f"{counted(darts, 'non-convex panel')}, {counted(sharp, 'sharp line turn')}",
                     ""])
    return rows


def net_picture_uri(mesh: QuadMesh, boundary_panels: BoundaryPanels | None = None, *,
                    title: str = "") -> str:
    """Data URI of a picture of the net (light blue) and its boundary panels (green), seen
    from where people see it (a facade from in front, a roof from 30 degrees above)."""
    from ..net.geometry import face_normals

    X = mesh.vertices
    normals = face_normals(X, mesh)
    front, initial = viewer.scene_front(normals, mesh.face_areas, X)
    view = figures.elevation_frame(front, 30.0 if initial == "above" else 10.0)
    faces = list(mesh.faces)
    colours = np.tile([0.55, 0.7, 0.95, 1.0], (len(faces), 1))
    if boundary_panels is not None and boundary_panels.count:
        # the boundary panels' vertices start with the net's: one drawing holds both
        X = boundary_panels.vertices
        faces += [np.asarray(q) for q in boundary_panels.polygons]
        colours = np.vstack([colours, np.tile([0.55, 0.85, 0.55, 1.0], (boundary_panels.count, 1))])
        normals = np.vstack([normals, _polygon_normals(X, boundary_panels.polygons, normals)])
    fig = figures.new_figure((9, 7))
    ax = fig.subplots()
    figures.draw_mesh(ax, X, faces, colours, view, normals=np.nan_to_num(normals))
    if title:
        ax.set_title(title, fontsize=10)
    return figures.figure_to_data_uri(fig)


def _polygon_normals(X: np.ndarray, polygons: list, fallback: np.ndarray) -> np.ndarray:
    """(p, 3) unit normals of polygons (Newell's method), the mean of `fallback` where a
    polygon has no area."""
    sizes = np.array([len(q) for q in polygons])
    ids = np.concatenate(polygons)
    start = np.repeat(np.r_[0, np.cumsum(sizes)[:-1]], sizes)
    local = np.arange(len(ids)) - start
    nxt = ids[np.where(local == np.repeat(sizes, sizes) - 1, start, np.arange(len(ids)) + 1)]
    cross = np.cross(X[ids], X[nxt])
    owner = np.repeat(np.arange(len(sizes)), sizes)
    n = np.stack([np.bincount(owner, cross[:, k], minlength=len(sizes)) for k in range(3)], axis=1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    mean = np.nanmean(fallback, axis=0)
    return np.where(length > 0, n / np.maximum(length, 1e-300), mean / max(np.linalg.norm(mean), 1e-300))


def net_view_html(result: Any, *, title: str, subtitle: str = "", surface: Any = None,
                  deviation_from: str = "the design", units: str = "m",
                  picture_png: bytes | None = None, picture_caption: str = "",
                  figures_after: tuple = ()) -> str:
    """The page of one net (see the module's text).

    Parameters
    ----------
    result : an `OptimizationResult` (its mesh, record and boundary panels).
    title, subtitle : the page's heading.
    surface : what the net's deviation is measured to, with ``distances(points)``: the
        `DesignSurface` of a layout, the `ReferenceSurface` of an optimization; None for
        no deviation mode. A layout (a record with ``coverage``) also gets the mode of the
        design's parts no panel covers.
    deviation_from : that surface in words (``"the design"``, ``"the reference"``).
    units : the model units (``MM_PER_UNIT`` key).
    picture_png : the static picture the command wrote (``OUT.png`` of a layout); without
        it one is drawn (`net_picture_uri`).
    picture_caption : its caption.
    figures_after : ``(data URI, caption, how to read it)`` of further pictures, shown
        after it (the design's |k1 - k2| map of a layout).

    Returns
    -------
    str, a complete HTML document.
    """
    mesh, panels = result.mesh, result.boundary_panels
    mm = MM_PER_UNIT[units]
    record = result.record()
    deviation = None if surface is None else np.asarray(surface.distances(mesh.vertices)) * mm
    gaps = None
    if surface is not None and "coverage" in result.properties and hasattr(surface, "triangles"):
        V, T = mesh.vertices, mesh.triangles()
        if panels is not None and panels.count:
            V, T = panels.vertices, np.vstack([T, panels.panel_triangles()[0]])
        gaps = uncovered_triangles(surface, V, T, gap=0.3 * mesh.mean_edge_length)
    scene = net_scene(mesh, title=title, units=units, mm_per_unit=mm, deviation_mm=deviation,
                      deviation_from=deviation_from, gaps=gaps, line_turn=True,
                      infinite_radius=_infinite_radius(mesh))
    if panels is not None and panels.count:
        scene.layer = boundary_layer(panels, units=units)
    rows = net_numbers(record, units=units, mm_per_unit=mm,
                       distance_key="distance_to_design" if "distance_to_design" in result.properties
                       else "distance_to_reference")
    if picture_png is not None:
        # in 256 colours: half the bytes of the file the command wrote
        picture = ("data:image/png;base64,"
                   + base64.b64encode(figures.compact_png(picture_png)).decode("ascii"))
    else:
        picture = net_picture_uri(mesh, panels)
    parts = [
        html.html_section("Key numbers", html.html_table(
            ["quantity", "value", "unit"], rows,
            caption="Measured on the solved net (the full record is in the JSON file beside "
                    "this page)")),
        html.html_section("3D view", viewer.viewer_block([scene], caption=_VIEW_HELP),
                          anchor="3d-view"),
        html.html_section("Picture", html.html_figure(picture, picture_caption or title,
                                                      how=_PICTURE_HOW),
                          *(html.html_figure(uri, caption, how=how)
                            for uri, caption, how in figures_after)),
    ]
    return html.html_page(title, parts, subtitle=subtitle or None,
                          scripts=viewer.viewer_assets())


def _infinite_radius(mesh: QuadMesh) -> float:
    """Meusnier radii beyond a thousand times the net's size read as planar: a nearly flat
    star's sphere radius is noise, and would stretch the colour scale."""
    return 1000.0 * float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
