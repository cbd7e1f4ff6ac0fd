"""Pictures for reports: figures outside pyplot, colours, views and mesh drawings.

Mesh pictures are orthographic views drawn with the painter's algorithm (faces sorted by
depth), so lines drawn on a surface (isolines, edges) are hidden behind nearer faces.
Figures are made with `new_figure`, never through pyplot: fabplan never switches a host
program's matplotlib backend.
"""

from __future__ import annotations

import base64
import io
import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "new_figure",
    "png_bytes",
    "compact_png",
    "figure_to_data_uri",
    "distinct_colors",
    "agreeing_normal",
    "net_view_angles",
    "view_frame",
    "elevation_frame",
    "label_faces",
    "draw_mesh",
    "rgba",
    "isoline_segments",
]


def new_figure(figsize: tuple[float, float] = (8.0, 6.0), *, dpi: int = 110) -> "Figure":
    """A matplotlib Figure with its own Agg canvas, outside pyplot.

    pyplot and the host's backend are left alone, so a Jupyter or Rhino session that
    imports fabplan keeps its own; the figure is freed with its last reference.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig: "Figure", *, dpi: int = 110, tight: bool = True) -> bytes:
    """The PNG of a figure, in 256 colours (`compact_png`)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight" if tight else None,
                facecolor="white")
    return compact_png(buffer.getvalue())


def compact_png(png: bytes) -> bytes:
    """The same picture as a 256-colour PNG: a half to a third of the bytes for plots and
    mesh drawings, which the reports embed by the dozen."""
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    out = io.BytesIO()
    # zlib's default level: its best (``optimize``) costs four times the time for 3 % of
    # the bytes
    image.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        out, format="png", compress_level=6)
    return out.getvalue() if out.tell() < len(png) else png


def figure_to_data_uri(fig: "Figure", *, dpi: int = 110) -> str:
    """PNG of a matplotlib figure as a ``data:image/png;base64,...`` URI."""
    return "data:image/png;base64," + base64.b64encode(png_bytes(fig, dpi=dpi)).decode("ascii")


# ----------------------------------------------------------------------------- colours
def distinct_colors(n: int) -> np.ndarray:
    """(n, 4) RGBA colours, neighbours in the sequence clearly different (tab20 up to 20,
    then hues spaced by the golden angle with alternating lightness)."""
    import matplotlib.colors as mcolors
    from matplotlib import colormaps

    if n <= 20:
        return colormaps["tab20"](np.arange(n) % 20)
    i = np.arange(n)
    hue = (i * 0.618033988749895) % 1.0
    sat = np.where(i % 3 == 0, 0.75, np.where(i % 3 == 1, 0.55, 0.9))
    val = np.where(i % 2 == 0, 0.9, 0.7)
    rgb = mcolors.hsv_to_rgb(np.stack([hue, sat, val], axis=1))
    return np.column_stack([rgb, np.ones(n)])


# ----------------------------------------------------------------------------- mesh drawings
def view_frame(X: np.ndarray, normals: np.ndarray, areas: np.ndarray, *,
               lift: float = 0.35) -> np.ndarray:
    """A viewing frame that looks at the side of a surface most faces turn to.

    Parameters
    ----------
    X : (n, 3) float, vertices (their principal axes give the view of a closed surface).
    normals : (f, 3) float, unit face normals; areas : (f,) float.
    lift : how far the eye is raised above the mean normal (towards +z).

    Returns
    -------
    (3, 3) float, rows: screen right, screen up, towards the viewer.
    """
    towards = np.nansum(normals * areas[:, None], axis=0)
    if np.linalg.norm(towards) < 1e-9 * max(float(areas.sum()), 1e-300):
        _, _, vt = np.linalg.svd(X - X.mean(axis=0))
        towards = vt[2]
    towards = towards / np.linalg.norm(towards)
    up_world = np.array([0.0, 0.0, 1.0])
    if abs(towards @ up_world) > 0.95:
        up_world = np.array([0.0, 1.0, 0.0])
    towards = towards + lift * up_world
    towards /= np.linalg.norm(towards)
    right = np.cross(up_world, towards)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(towards, right), towards])


def elevation_frame(front: np.ndarray, elevation_deg: float) -> np.ndarray:
    """A viewing frame looking from the horizontal direction `front` (towards the viewer),
    raised `elevation_deg` above the horizon, z up on the screen.

    Examples
    --------
    >>> (elevation_frame(np.array([0.0, -1.0]), 0.0).round(3) + 0.0).tolist()
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
    """
    f = np.array([front[0], front[1], 0.0])
    f /= np.linalg.norm(f)
    e = math.radians(elevation_deg)
    up_world = np.array([0.0, 0.0, 1.0])
    towards = math.cos(e) * f + math.sin(e) * up_world
    right = np.cross(up_world, towards)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(towards, right), towards])


def label_faces(ax, X: np.ndarray, face_indices: np.ndarray, face_sizes: np.ndarray,
                labels: list, view: np.ndarray, *, normals: np.ndarray | None = None,
                fontsize: float = 6.0) -> int:
    """Write a label on each face drawn large enough to hold it (after `draw_mesh`).

    The picture is cut into cells of one label's size; in each cell only the face nearest
    to the viewer is a candidate, so hidden faces get no label and labels do not pile up.

    Parameters
    ----------
    X : (n, 3) float; face_indices : the faces' vertex ids one face after the other;
    face_sizes : (f,) int; labels : (f,) texts; view : (3, 3) the frame of `draw_mesh`.
    normals : (f, 3) unit face normals: faces seen at a grazing angle (more than 60 deg
        off) get no label, which would crowd the picture's edges.

    Returns
    -------
    int, the number of labels written.
    """
    P = X @ view.T
    owner = np.repeat(np.arange(len(face_sizes)), face_sizes)
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]])
    D = ax.transData.transform(P[face_indices, :2])              # display pixels
    lo = np.stack([np.minimum.reduceat(D[:, 0], starts), np.minimum.reduceat(D[:, 1], starts)], 1)
    hi = np.stack([np.maximum.reduceat(D[:, 0], starts), np.maximum.reduceat(D[:, 1], starts)], 1)
    centre = np.stack([np.bincount(owner, D[:, k]) / face_sizes for k in (0, 1)], axis=1)
    depth = np.bincount(owner, P[face_indices, 2]) / face_sizes
    px = ax.figure.dpi / 72.0 * fontsize
    width = np.array([0.62 * px * len(str(t)) + 2 for t in labels])
    fits = (hi[:, 0] - lo[:, 0] >= 1.3 * width) & (hi[:, 1] - lo[:, 1] >= 1.6 * px)
    if normals is not None:
        fits &= np.abs(normals @ view[2]) >= 0.5
    cell = np.array([max(width.max(), px) * 1.3, 1.5 * px])
    key = np.floor(centre / cell).astype(np.int64)
    key -= key.min(axis=0)
    key = key[:, 0] * (key[:, 1].max() + 1) + key[:, 1]
    order = np.lexsort((-depth, key))                 # nearest face first in each cell
    first = np.ones(len(order), bool)
    first[1:] = key[order][1:] != key[order][:-1]
    chosen = order[first]
    chosen = chosen[fits[chosen]]
    if len(chosen):
        where = ax.transData.inverted().transform(centre[chosen])
        _draw_labels(ax, [str(labels[f]) for f in chosen], where, fontsize)
    return int(len(chosen))


def _draw_labels(ax, texts: list[str], where: np.ndarray, fontsize: float) -> None:
    """Write `texts` centred at `where` (k, 2) data coordinates, each on a rounded white
    box: as two collections of outlines (a label's outline made once per distinct text),
    since a thousand text artists take seconds to lay out and draw."""
    from matplotlib.collections import PathCollection
    from matplotlib.font_manager import FontProperties
    from matplotlib.patches import BoxStyle
    from matplotlib.textpath import TextPath
    from matplotlib.transforms import Affine2D

    prop = FontProperties(size=fontsize)
    pad = 0.1 * fontsize
    glyphs, boxes = {}, {}
    for text in set(texts):
        path = TextPath((0.0, 0.0), text, prop=prop)           # in points
        box = path.get_extents()
        glyphs[text] = path.transformed(Affine2D().translate(-0.5 * (box.x0 + box.x1),
                                                             -0.5 * (box.y0 + box.y1)))
        # the box of a text line (ascent and descent), not of the glyphs' ink
        width, height = box.width + 0.25 * fontsize, 1.1 * fontsize
        boxes[text] = BoxStyle.Round(pad=pad)(-0.5 * width, -0.5 * height, width, height, 1.0)
    points = Affine2D().scale(1.0 / 72.0) + ax.figure.dpi_scale_trans   # points to pixels
    for paths, color, order in (([boxes[t] for t in texts], (1.0, 1.0, 1.0, 0.6), 1000),
                                ([glyphs[t] for t in texts], (0.0, 0.0, 0.0, 1.0), 1001)):
        ax.add_collection(PathCollection(paths, offsets=where, offset_transform=ax.transData,
                                         transform=points, facecolors=[color],
                                         edgecolors="none", linewidths=0.0, zorder=order),
                          autolim=False)


def draw_mesh(ax, X: np.ndarray, faces: list, face_colors: np.ndarray, view: np.ndarray, *,
              normals: np.ndarray | None = None, edge_color="#333333", edge_width: float = 0.15,
              lines: np.ndarray | None = None, line_faces: np.ndarray | None = None,
              line_colors=None, line_width: float = 0.9, layers: int = 40) -> None:
    """Draw a polygon mesh in an orthographic view, nearer faces over farther ones.

    Parameters
    ----------
    ax : a matplotlib Axes (2-d).
    X : (n, 3) float, vertices; faces : list of (k,) int arrays.
    face_colors : (f, 4) RGBA; shaded by the angle to the viewer when `normals` is given.
    view : (3, 3) rows right, up, towards the viewer (see `view_frame`).
    lines : optional (s, 2, 3) segments on the surface, drawn over the face they lie on
        (`line_faces` (s,) int) and hidden by nearer faces.
    line_colors : one colour or (s, 4) RGBA.
    layers : number of depth layers the drawing is split into for the hiding.
    """
    from matplotlib.collections import LineCollection, PolyCollection

    P = X @ view.T
    sizes = np.array([len(f) for f in faces])
    flat = np.concatenate(faces)
    owner = np.repeat(np.arange(len(faces)), sizes)
    depth = np.bincount(owner, P[flat, 2], minlength=len(faces)) / sizes
    colors = np.array(face_colors, dtype=float)
    if normals is not None:
        shade = 0.55 + 0.45 * np.abs(normals @ view[2])
        colors[:, :3] *= shade[:, None]
    order = np.argsort(depth, kind="stable")
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    layer = rank * layers // max(len(order), 1)
    polys = np.split(P[flat, :2], np.cumsum(sizes)[:-1])
    if lines is not None and len(lines):
        seg_layer = layer[line_faces]
        if line_colors is None or isinstance(line_colors, (str, tuple)):
            seg_colors = np.tile(rgba(line_colors), (len(lines), 1))
        else:
            seg_colors = np.asarray(line_colors, float)
        seg2d = lines @ view[:2].T
    for k in range(layers):
        ids = order[layer[order] == k]
        if ids.size:
            ax.add_collection(PolyCollection([polys[i] for i in ids], facecolors=colors[ids],
                                             edgecolors=edge_color, linewidths=edge_width,
                                             zorder=2 * k))
        if lines is not None and len(lines):
            sel = seg_layer == k
            if sel.any():
                ax.add_collection(LineCollection(seg2d[sel], colors=seg_colors[sel],
                                                 linewidths=line_width, zorder=2 * k + 1))
    ax.set_xlim(P[:, 0].min(), P[:, 0].max())
    ax.set_ylim(P[:, 1].min(), P[:, 1].max())
    ax.set_aspect("equal")
    ax.set_axis_off()


def rgba(color) -> tuple:
    """RGBA tuple of any matplotlib colour specification (black for None)."""
    from matplotlib.colors import to_rgba

    return to_rgba("black" if color is None else color)


def isoline_segments(X: np.ndarray, triangles: np.ndarray, values: np.ndarray,
                     levels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Isolines of a piecewise linear function on a triangle mesh (marching triangles).

    Parameters
    ----------
    X : (n, 3) float; triangles : (t, 3) int; values : (n,) float at the vertices;
    levels : (l,) float.

    Returns
    -------
    segments : (s, 2, 3) float; triangle : (s,) int, the triangle each lies in;
    level : (s,) int, index into `levels`.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    >>> seg, tri, lev = isoline_segments(X, np.array([[0, 1, 2]]), X[:, 0], np.array([0.5]))
    >>> seg.round(3).tolist()
    [[[0.5, 0.0, 0.0], [0.5, 0.5, 0.0]]]
    """
    values = np.asarray(values, float)
    segments, owner, which = [], [], []
    edges = np.array([[0, 1], [1, 2], [2, 0]])
    for i, level in enumerate(np.asarray(levels, float)):
        f = values[triangles] - level
        f = np.where(f == 0, 1e-300, f)  # a vertex on the level counts as above it
        a, b = f[:, edges[:, 0]], f[:, edges[:, 1]]
        cross = (a * b) < 0                                   # (t, 3)
        hit = np.flatnonzero(cross.sum(axis=1) == 2)
        if hit.size == 0:
            continue
        # the interpolation parameter of edges without a crossing is never used
        t = np.where(cross[hit], a[hit] / np.where(cross[hit], a[hit] - b[hit], 1.0), 0.0)
        pa = X[triangles[hit][:, edges[:, 0]]]
        pb = X[triangles[hit][:, edges[:, 1]]]
        pts = pa + t[..., None] * (pb - pa)                    # (h, 3, 3)
        pick = np.argsort(~cross[hit], axis=1, kind="stable")[:, :2]
        segments.append(np.take_along_axis(pts, pick[..., None], axis=1))
        owner.append(hit)
        which.append(np.full(hit.size, i))
    if not segments:
        return np.zeros((0, 2, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(segments), np.concatenate(owner), np.concatenate(which)


def agreeing_normal(normals: np.ndarray, areas: np.ndarray) -> np.ndarray | None:
    """The area-weighted mean normal when the faces agree on a side (a roof, a facade
    patch), else None (a closed ring or barrel)."""
    mean = np.nansum(normals * areas[:, None], axis=0)
    if np.linalg.norm(mean) <= 0.3 * areas.sum():
        return None
    return mean / np.linalg.norm(mean)


def net_view_angles(design) -> tuple[float, float]:
    """Elevation and azimuth (degrees, matplotlib's ``view_init``) of the net picture.

    A roof (faces agreeing on a side within 45 degrees of vertical) is seen from 30
    degrees above the horizon, 75 degrees off the diagonal of its plan, so that both its
    rise and its net show (from above, as a cladding layout is usually drawn, a saddle
    looks flat; from lower, the far half of the net is lost); a facade patch from its
    side, 20 degrees up; a closed surface (a ring, a barrel) from 20 degrees up.
    """
    n = agreeing_normal(design.face_normals, design.face_areas)
    if n is None:
        return 20.0, -60.0
    if abs(n[2]) >= math.cos(math.radians(45)):
        span = np.ptp(design.vertices, axis=0)
        return 30.0, float(np.degrees(np.arctan2(span[1], span[0]))) - 75.0
    return 20.0, float(np.degrees(np.arctan2(n[1], n[0]))) + 25.0
