"""The picture of a net on its design surface (layouts and studies)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..design.mesh_surface import DesignSurface, weighted_quantile
from ..io.output import atomic_path
from ..net.mesh import QuadMesh
from ..report.figures import net_view_angles, new_figure
from ..report.html import counted, panel_areas
from .boundary_panels import BoundaryPanels

__all__ = ["write_layout_picture", "fairness_marks", "curvature_difference_figure",
           "curvature_difference_at", "kink_text", "NEAR_UMBILIC"]

#: Where |k1 - k2| is below this share of its median over the design, the design itself
#: makes the lines kink (near an umbilic).
NEAR_UMBILIC = 0.25


def fairness_marks(properties: dict) -> dict[str, list]:
    """Where a measured net is least fair (`fabplan.net.fairness`), as labelled points for
    `write_layout_picture`: the vertex its lines turn most, the smallest angle, and the
    largest part of the design left unclad (`fabplan.layout.trim.coverage_gaps`) when the
    panels cover less than 99.9 % of it."""
    fairness = properties.get("fairness") or {}
    marks = {}
    gaps = (properties.get("boundary_panels") or {}).get("gaps") or []
    if gaps and properties.get("coverage", 1.0) < 0.999:
        marks[f"largest gap ({panel_areas(gaps[0]['area_relative_to_panel'])})"] = gaps[0]["point"]
    turn = fairness.get("line_turn_deg") or {}
    if turn.get("point") is not None:
        marks[f"lines turn most ({turn['max']:.1f} deg)"] = turn["point"]
    angle = fairness.get("intersection_angle_deg") or {}
    if angle.get("min_vertex") is not None and properties.get("vertices"):
        marks[f"smallest angle ({angle['min']:.1f} deg)"] = angle["min_vertex"]
    return marks


def _frame_design(ax, design: DesignSurface) -> None:
    """Look at the design from `net_view_angles`, its bounding box filling the axes at one
    scale on all three axes, without the axes themselves."""
    elevation, azimuth = net_view_angles(design)
    ax.view_init(elev=elevation, azim=azimuth)
    lo, hi = design.vertices.min(axis=0), design.vertices.max(axis=0)
    span = np.maximum(hi - lo, 1e-3 * (hi - lo).max())
    for axis, a, b in zip("xyz", lo, lo + span, strict=True):
        getattr(ax, f"set_{axis}lim")(a, b)
    ax.set_box_aspect(span)                       # equal scale on all three axes
    ax.set_axis_off()


def write_layout_picture(path: str | os.PathLike, design: DesignSurface, mesh: QuadMesh, *,
                         title: str = "", singular_points: np.ndarray | None = None,
                         marks: dict | None = None,
                         boundary_panels: BoundaryPanels | None = None) -> Path:
    """A PNG of the net on the design surface, axes to scale (atomically written).

    The design is drawn light grey with its boundary black, the net's faces blue with
    their edges, its `boundary_panels` (`fabplan.layout.trim`) green, irregular vertices
    red and singular points of the layout's direction field orange; `marks` ({label:
    point (3,) or vertex id}, e.g. `fairness_marks`) are drawn as labelled markers; the
    view is `net_view_angles`.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    path = Path(path)
    fig = new_figure((8, 7))
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False      # markers are drawn over the faces, in the order added
    T = design.triangles
    if len(T) > 30000:  # a coarser sample of the surface keeps the picture quick
        T = T[:: int(math.ceil(len(T) / 30000))]
    # autolim off everywhere: the limits are set below, and matplotlib pads the faces of
    # polygons of different sizes with uninitialised memory that autoscaling would read
    # (NaN or infinite limits, at random)
    ax.add_collection3d(Poly3DCollection(design.vertices[T], facecolor=(0.85, 0.85, 0.85, 0.35),
                                         edgecolor="none"), autolim=False)
    for curve in design.boundary_curves():
        loop = np.vstack([curve, curve[:1]])
        ax.plot(loop[:, 0], loop[:, 1], loop[:, 2], color="black", lw=0.8)
    ax.add_collection3d(Poly3DCollection([mesh.vertices[f] for f in mesh.faces],
                                         facecolor=(0.55, 0.7, 0.95, 0.9),
                                         edgecolor=(0.1, 0.2, 0.5, 1.0), linewidths=0.4),
                       autolim=False)
    trimmed = boundary_panels is not None and boundary_panels.count > 0
    if trimmed:
        assert boundary_panels is not None
        ax.add_collection3d(Poly3DCollection(
            [boundary_panels.vertices[p] for p in boundary_panels.polygons],
            facecolor=(0.55, 0.85, 0.55, 0.9), edgecolor=(0.1, 0.4, 0.1, 1.0), linewidths=0.4,
            # counted as in the record and the 3D view: the slivers cut with their full
            # panel are drawn, not counted as panels
            label=f"boundary panels ({boundary_panels.panel_count})"
                  + (f" and {counted(boundary_panels.count - boundary_panels.panel_count, 'sliver')}"
                     if boundary_panels.count > boundary_panels.panel_count else "")),
            autolim=False)
    irregular = mesh.vertices[mesh.irregular_vertices]
    if len(irregular):
        ax.scatter(*irregular.T, color="red", s=18, depthshade=False, label="irregular vertices")
    if singular_points is not None and len(singular_points):
        ax.scatter(*np.asarray(singular_points).T, color="orange", s=12, depthshade=False,
                   label="field singularities")
    for (label, where), style in zip((marks or {}).items(), ("v", "s", "D", "^"), strict=False):
        point = mesh.vertices[where] if isinstance(where, (int, np.integer)) else np.asarray(where)
        ax.scatter(*point[:, None], color="magenta", edgecolor="black", marker=style, s=70,
                   depthshade=False, label=label, zorder=10)
    _frame_design(ax, design)
    if title:
        ax.set_title(title, fontsize=9)
    if trimmed or len(irregular) or marks or (singular_points is not None and len(singular_points)):
        ax.legend(loc="lower left", fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    return path


def _curvature_difference(design: DesignSurface, panel_size: float) -> np.ndarray:
    """(t,) float, |k1 - k2| of every design triangle times the panel size: how far a
    panel's two principal curvatures part (near 0 the principal directions, and the
    lines of every S-net with them, are not determined)."""
    from .directions import face_principal_frames

    k1, k2, _ = face_principal_frames(design)
    return np.abs(k1 - k2) * panel_size


def curvature_difference_at(design: DesignSurface, panel_size: float,
                            points: np.ndarray) -> np.ndarray:
    """(m,) float, `_curvature_difference` at the design triangles nearest to `points`
    (m, 3), relative to its area-weighted median over the design (1: a typical place;
    below about 0.2: near an umbilic)."""
    from scipy.spatial import cKDTree

    value = _curvature_difference(design, panel_size)
    median = weighted_quantile(value, design.face_areas, 0.5)
    centres = design.vertices[design.triangles].mean(axis=1)
    nearest = cKDTree(centres).query(np.atleast_2d(points))[1]
    return value[nearest] / max(float(median), 1e-300)


def kink_text(design: DesignSurface, panel_size: float, properties: dict, *,
              name: str = "the net", units: str = "") -> str:
    """Where the lines of a measured net (its `properties`, `fabplan.net.measure`) turn
    most, and whether the design forces it (near an umbilic, `NEAR_UMBILIC`) or the
    layout does; "" when no turn was measured."""
    turn = ((properties.get("fairness") or {}).get("line_turn_deg") or {})
    if turn.get("point") is None or turn.get("max") is None:
        return ""
    point = np.asarray(turn["point"], dtype=np.float64)
    share = float(curvature_difference_at(design, panel_size, point)[0])
    where = ", ".join(f"{x:.1f}" for x in point)
    head = (f"The lines of {name} turn most, by {float(turn['max']):.0f} deg, at ({where})"
            f"{' ' + units if units else ''}, where |k1 - k2| is {100 * share:.0f} % of its "
            "median over the design")
    if share < NEAR_UMBILIC:
        return (head + ": near an umbilic, so the design forces the turn; every net whose "
                "lines follow the principal directions turns there, and only smaller panels "
                "make the kink per panel smaller.")
    return (head + ": the principal directions are well defined there, so the turn comes "
            "from the layout, not from the design; a longer smoothing of the directions "
            "(`fabplan layout --smoothing`, a study's `[panels] smoothing`) or another start "
            "angle may lower it.")


def curvature_difference_figure(design: DesignSurface, panel_size: float, *,
                                marks: dict | None = None,
                                singular_points: np.ndarray | None = None,
                                title: str = "") -> str:
    """Data URI: the design coloured by |k1 - k2| times the panel size (dark: near an
    umbilic, where the principal directions turn fast or are not defined and a net's
    lines must kink), seen as `write_layout_picture` sees it, with `marks` ({label:
    point (3,)}) and the direction field's `singular_points`."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ..report.figures import figure_to_data_uri

    value = _curvature_difference(design, panel_size)
    T = design.triangles
    step = max(1, int(math.ceil(len(T) / 30000)))     # a coarser sample keeps it quick
    fig = new_figure((8, 6.5))
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False
    top = float(np.quantile(value, 0.98)) or 1.0
    norm, cmap = Normalize(0.0, top), colormaps["magma"]
    ax.add_collection3d(Poly3DCollection(design.vertices[T[::step]],
                                         facecolor=cmap(norm(value[::step])), edgecolor="none"),
                       autolim=False)
    if singular_points is not None and len(singular_points):
        ax.scatter(*np.asarray(singular_points).T, color="white", edgecolor="black", s=30,
                   depthshade=False, label="singularities of the direction field")
    for (label, point), style in zip((marks or {}).items(), ("v", "s", "D", "^"), strict=False):
        ax.scatter(*np.asarray(point, float)[:, None], color="lime", edgecolor="black",
                   marker=style, s=80, depthshade=False, label=label, zorder=10)
    _frame_design(ax, design)
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7)
    bar.set_label("|k1 - k2| x panel size (dark: near an umbilic)")
    if title:
        ax.set_title(title, fontsize=9)
    if marks or (singular_points is not None and len(singular_points)):
        ax.legend(loc="lower left", fontsize=8)
    return figure_to_data_uri(fig)
