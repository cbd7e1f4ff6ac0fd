"""The 3D view of a net from its geometry alone: the colour modes every net has.

`net_scene` gives a `fabplan.report.viewer.ViewerScene` coloured by the distance from a
design or reference surface, the Meusnier radius, the intersection angle, the kink
between neighbouring panels, the turn of the net's lines and the design's uncovered
parts. Reports that know more add to it: the molds report its molds
(`fabplan.fabricate.molds.mold_report.net_viewer_scene`), a layout its boundary panels
(`fabplan.layout.view`).
"""

from __future__ import annotations

import numpy as np

from ..report import viewer
from .fairness import line_turns
from .geometry import canonical_stars, face_normals, fit_star_spheres, intersection_angles, kink_angles
from .mesh import QuadMesh

__all__ = ["net_scene", "net_edges", "face_max", "face_mean"]


def net_edges(mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray]:
    """Every edge of a net once, with the family of the net's lines it belongs to.

    Returns
    -------
    edges : (e, 2) int vertex ids; family : (e,) int, 0 or 1 (the two strip families),
    -1 on edges of faces that are not quads.
    """
    idx, ptr, sizes = mesh.face_indices, mesh.face_indptr, mesh.face_sizes
    face = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(idx)) - ptr[face]
    nxt = np.where(local == sizes[face] - 1, ptr[face], np.arange(len(idx)) + 1)
    pairs = np.sort(np.stack([idx, idx[nxt]], axis=1), axis=1)
    family = np.asarray(mesh.edge_family)
    # an edge seen from a quad keeps the quad's family over a non-quad's -1
    order = np.lexsort((-family, pairs[:, 1], pairs[:, 0]))
    pairs, family = pairs[order], family[order]
    first = np.ones(len(pairs), bool)
    first[1:] = np.any(pairs[1:] != pairs[:-1], axis=1)
    return pairs[first], family[first]


def face_max(mesh: QuadMesh, vertex_values: np.ndarray) -> np.ndarray:
    """(f,) float, the largest of each face's corner values (n,)."""
    face = mesh.corner_faces
    out = np.full(len(mesh.face_sizes), -np.inf)
    np.maximum.at(out, face, vertex_values[mesh.face_indices])
    return out


def face_mean(mesh: QuadMesh, vertex_values: np.ndarray) -> np.ndarray:
    """(f,) float, the mean of each face's finite corner values (n,); NaN where none is.

    Examples
    --------
    >>> mesh = QuadMesh(np.eye(4, 3), [np.arange(4)])
    >>> face_mean(mesh, np.array([1.0, np.nan, 3.0, np.nan])).tolist()
    [2.0]
    """
    face = mesh.corner_faces
    values = vertex_values[mesh.face_indices]
    finite = np.isfinite(values)
    count = np.bincount(face, finite, minlength=len(mesh.face_sizes))
    total = np.bincount(face, np.where(finite, values, 0.0), minlength=len(mesh.face_sizes))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def net_scene(mesh: QuadMesh, *, title: str, units: str, mm_per_unit: float,
              deviation_mm: np.ndarray | None = None, deviation_limit_mm: float | None = None,
              deviation_from: str = "the design", gaps: np.ndarray | None = None,
              infinite_radius: float | None = None, line_turn: bool = False
              ) -> viewer.ViewerScene:
    """The 3D view of a net with the colour modes of its geometry.

    Parameters
    ----------
    mesh : the net.
    title : the scene's name in the viewer.
    units : the model units (shown with radii); mm_per_unit : millimetres per model unit
        (eye height).
    deviation_mm : (n,) float, distance of every vertex from `deviation_from` (mm), or None
        (no deviation mode).
    deviation_limit_mm : the limit marked on the deviation scale, or None.
    deviation_from : what the distance is measured to, in words (``"the reference"``).
    gaps : (g, 3, 3) float, triangles of the design no panel covers (model units), or None
        (no gaps mode); an empty array gives the mode, saying there are none.
    infinite_radius : Meusnier radii above this (model units) show as planar (grey).
    line_turn : add the mode of the turn of the net's lines within the surface.

    Returns
    -------
    `fabplan.report.viewer.ViewerScene` with the modes deviation (when given), Meusnier
    radius and angle (when the net has regular stars), kink, line turn (when asked) and
    gaps (when given), in that order, and the matching panel numbers.
    """
    X = mesh.vertices
    normals = face_normals(X, mesh)
    front, initial = viewer.scene_front(normals, mesh.face_areas, X)
    modes: list[viewer.ColourMode] = []
    info: list[viewer.PanelInfo] = []
    if deviation_mm is not None:
        _deviation_mode(mesh, deviation_mm, deviation_limit_mm, deviation_from, modes, info)
    stars = canonical_stars(X, mesh.stars)
    if len(stars):
        _star_modes(mesh, stars, units, infinite_radius, modes, info)
    _kink_mode(mesh, modes, info)
    if line_turn and len(stars):
        _line_turn_mode(mesh, stars, modes, info)
    if gaps is not None:
        modes.append(viewer.ColourMode(
            "gaps", "coverage gaps (red)",
            (f"Red: parts of the design no panel covers ({len(gaps)} design triangles); grey: "
             "the panels." if len(gaps) else
             "No part of the design is left uncovered: every design triangle lies under a "
             "panel.")))
    edges, family = net_edges(mesh)
    return viewer.ViewerScene(title=title, vertices=X, face_sizes=mesh.face_sizes,
                              face_indices=mesh.face_indices, modes=modes, info=info,
                              edges=edges, edge_family=family, gaps=gaps, front=front,
                              initial=initial, eye_height=1700.0 / mm_per_unit)


def _deviation_mode(mesh: QuadMesh, deviation_mm: np.ndarray, deviation_limit_mm: float | None,
                    deviation_from: str, modes: list[viewer.ColourMode],
                    info: list[viewer.PanelInfo]) -> None:
    """Add the deviation mode of `net_scene` and its panel number to `modes` and `info`."""
    # the scale reaches past the limit, so that the limit's mark sits inside it
    top = max(float(np.max(deviation_mm)), 1.15 * (deviation_limit_mm or 0.0))
    modes.append(viewer.ColourMode(
        "deviation", f"deviation from {deviation_from} [mm]",
        f"Distance of the net from {deviation_from}, measured at the vertices and blended "
        "across each panel" + ("; red is above the limit." if deviation_limit_mm is not None
                               else "."),
        values=deviation_mm, where="vertex", unit="mm", value_range=(0.0, top),
        limit=deviation_limit_mm))
    info.append(viewer.PanelInfo(f"deviation from {deviation_from} (largest corner)",
                                 face_max(mesh, deviation_mm), "mm", 3))


def _star_modes(mesh: QuadMesh, stars: np.ndarray, units: str, infinite_radius: float | None,
                modes: list[viewer.ColourMode], info: list[viewer.PanelInfo]) -> None:
    """Add the Meusnier radius (where finite) and angle modes of `net_scene`, for the
    regular `stars`, to `modes` and `info`."""
    X = mesh.vertices
    radius = np.full(mesh.vertex_count, np.nan)
    radius[stars[:, 0]] = fit_star_spheres(X, stars).radius
    if infinite_radius is not None:
        radius[radius > infinite_radius] = np.nan
    finite = radius[np.isfinite(radius)]
    if finite.size:
        modes.append(viewer.ColourMode(
            "radius", f"Meusnier radius [{units}]",
            "Radius of the sphere through each vertex and its four neighbours (blended "
            "across the panels); one colour everywhere is a constant radius. Grey: "
            "planar stars, boundary.", values=radius, where="vertex", unit=units,
            value_range=(float(np.quantile(finite, 0.02)), float(np.quantile(finite, 0.98)))))
        info.append(viewer.PanelInfo("Meusnier radius (mean of corners)",
                                     face_mean(mesh, radius), units))
    angle = np.full(mesh.vertex_count, np.nan)
    angle[stars[:, 0]] = np.degrees(intersection_angles(X, stars))
    modes.append(viewer.ColourMode(
        "angle", "angle between the families [deg]",
        "Angle at which the net's two families of lines cross at each vertex; one colour "
        "everywhere is a constant angle. Grey: boundary and irregular vertices.",
        values=angle, where="vertex", unit="deg"))


def _kink_mode(mesh: QuadMesh, modes: list[viewer.ColourMode], info: list[viewer.PanelInfo]) -> None:
    """Add the kink mode of `net_scene` and its panel number to `modes` and `info`."""
    pairs = mesh.interior_edge_faces
    kink = np.zeros(len(mesh.face_sizes))
    if len(pairs):
        k = np.degrees(kink_angles(mesh.vertices, mesh))
        np.maximum.at(kink, pairs[:, 0], k)
        np.maximum.at(kink, pairs[:, 1], k)
    modes.append(viewer.ColourMode(
        "kink", "kink to the neighbours [deg]",
        "Largest angle between a panel and its neighbours across an edge: 0 where the "
        "panels continue each other smoothly.", values=kink, unit="deg"))
    info.append(viewer.PanelInfo("kink", kink, "deg", 3))


def _line_turn_mode(mesh: QuadMesh, stars: np.ndarray, modes: list[viewer.ColourMode],
                    info: list[viewer.PanelInfo]) -> None:
    """Add the line turn mode of `net_scene` and its panel number to `modes` and `info`."""
    turn = np.full(mesh.vertex_count, np.nan)
    turn[stars[:, 0]] = np.degrees(line_turns(mesh.vertices, stars)[0].max(axis=1))
    modes.append(viewer.ColourMode(
        "turn", "line turn in the surface [deg]",
        "How much the net's lines turn within the surface at each vertex (the larger of "
        "the two families): 0 for lines as straight as the surface lets them be; fair "
        "lines turn little and evenly. Grey: boundary and irregular vertices.",
        values=turn, where="vertex", unit="deg"))
    info.append(viewer.PanelInfo("line turn (largest corner)",
                                 face_max(mesh, np.nan_to_num(turn)), "deg", 3))
