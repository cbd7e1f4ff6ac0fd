"""Self-contained HTML reports with pictures: page, tables, figures and mesh drawings.

Reports are single HTML files that open offline: pictures are PNG images embedded as
``data:`` URIs, styles are inline, nothing is fetched. The helpers are generic so that
every report-writing module (molds, strips, facade studies) builds its page the same way::

    from fabplan import report
    page = report.html_page("Title", [
        report.html_section("Summary", report.html_table(["quantity", "value"], rows)),
        report.html_figure(report.figure_to_data_uri(fig), "caption"),
    ])

Mesh pictures are orthographic views drawn with the painter's algorithm (faces sorted by
depth), so lines drawn on a surface (isolines, edges) are hidden behind nearer faces.
"""

from __future__ import annotations

import base64
import html
import io
import math
from typing import Iterable, Sequence

import numpy as np

__all__ = [
    "figure_to_data_uri",
    "html_page",
    "html_section",
    "html_paragraph",
    "html_table",
    "html_figure",
    "html_details",
    "format_value",
    "counted",
    "html_links",
    "distinct_colors",
    "view_frame",
    "draw_mesh",
    "isoline_segments",
]

_STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif;
       margin: 2em auto; max-width: 1200px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.7em; margin-bottom: 0.2em; }
h2 { font-size: 1.3em; margin-top: 1.8em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
p.subtitle { color: #555; margin-top: 0; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
caption { text-align: left; font-weight: 600; padding: 0.3em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f0f0f0; position: sticky; top: 0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.bad td { background: #fde2e2; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #444; font-size: 0.92em; margin-top: 0.3em; }
details summary { cursor: pointer; font-weight: 600; margin: 0.6em 0; }
.note { background: #f6f8fa; border-left: 4px solid #7a9cc6; padding: 0.6em 1em; }
.fail { background: #fde2e2; border-left: 4px solid #c0392b; padding: 0.6em 1em; }
"""


# ----------------------------------------------------------------------------- HTML
def figure_to_data_uri(fig, *, dpi: int = 110) -> str:
    """PNG of a matplotlib figure as a ``data:image/png;base64,...`` URI; closes the figure."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def format_value(value, digits: int = 4) -> str:
    """Text of a table cell: numbers with `digits` significant digits, None as an en dash.

    Examples
    --------
    >>> format_value(3.14159), format_value(12), format_value(None), format_value(True)
    ('3.142', '12', '–', 'yes')
    """
    if value is None:
        return "–"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}g}"
    return str(value)


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """A count with its noun in the right number.

    Examples
    --------
    >>> counted(1, "mold"), counted(0, "mold"), counted(3, "sheet"), counted(2, "box", "boxes")
    ('1 mold', '0 molds', '3 sheets', '2 boxes')
    """
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def html_table(columns: Sequence[str], rows: Iterable[Sequence], *, caption: str | None = None,
               digits: int = 4, bad_rows: Iterable[int] = ()) -> str:
    """An HTML table; numbers are right-aligned and formatted by `format_value`.

    Parameters
    ----------
    columns : header texts.
    rows : rows of cell values (numbers, strings, None).
    caption : optional caption above the table.
    bad_rows : indices of rows to highlight (failures).

    Examples
    --------
    >>> table = html_table(["a", "b"], [[1, None]])
    >>> table[table.index("<tbody>"):]
    '<tbody><tr><td class="num">1</td><td>–</td></tr></tbody></table>'
    """
    bad = set(bad_rows)
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = []
    for i, row in enumerate(rows):
        cells = []
        for value in row:
            numeric = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
                value, (bool, np.bool_))
            cls = ' class="num"' if numeric else ""
            cells.append(f"<td{cls}>{html.escape(format_value(value, digits))}</td>")
        tr = '<tr class="bad">' if i in bad else "<tr>"
        body.append(tr + "".join(cells) + "</tr>")
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def html_paragraph(text: str, *, cls: str | None = None) -> str:
    """A paragraph of escaped text (``cls``: ``"note"`` or ``"fail"`` for a framed box)."""
    attr = f' class="{cls}"' if cls else ""
    return f"<p{attr}>{html.escape(text)}</p>"


def html_links(label: str, links: Sequence[tuple[str, str]]) -> str:
    """A paragraph of links: `label` then ``(text, href)`` pairs (hrefs relative to the
    page, so that a report folder can be moved or shared as a whole).

    Examples
    --------
    >>> html_links("Files", [("net.obj", "candidates/a b/net.obj")])
    '<p>Files: <a href="candidates/a%20b/net.obj">net.obj</a></p>'
    """
    from urllib.parse import quote

    items = ", ".join(f'<a href="{html.escape(quote(href))}">{html.escape(text)}</a>'
                      for text, href in links)
    return f"<p>{html.escape(label)}: {items}</p>"


def html_figure(uri: str, caption: str, *, alt: str | None = None) -> str:
    """An embedded picture with its caption."""
    return (f'<figure><img src="{uri}" alt="{html.escape(alt or caption)}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def html_details(summary: str, *parts: str) -> str:
    """A collapsible block (long tables)."""
    return f"<details><summary>{html.escape(summary)}</summary>{''.join(parts)}</details>"


def html_section(title: str, *parts: str) -> str:
    """A titled section of already built HTML parts."""
    return f"<section><h2>{html.escape(title)}</h2>{''.join(parts)}</section>"


def html_page(title: str, parts: Iterable[str], *, subtitle: str | None = None) -> str:
    """A complete, self-contained HTML document."""
    sub = f'<p class="subtitle">{html.escape(subtitle)}</p>' if subtitle else ""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>"
            f"<body><h1>{html.escape(title)}</h1>{sub}{''.join(parts)}</body></html>\n")


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
            seg_colors = np.tile(_rgba(line_colors), (len(lines), 1))
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


def _rgba(color) -> tuple:
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
