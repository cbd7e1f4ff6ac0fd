"""The interactive 3D view of a report: a net's panels in a single, offline HTML file.

A report page holds one viewer (`viewer_block`) with one or more scenes (`ViewerScene`,
one per candidate net), and once per page the script that draws them (`viewer_assets`):
three.js r187 (MIT, vendored in ``vendor/`` with its licence and build recipe) and
``viewer.js``. The mesh travels as base64 typed arrays in a JSON block, so the page opens
from disk without a server or a network.

What the viewer offers: orbit (drag), zoom (wheel), pan (right-drag); views from eye
level, from the front, from 30 degrees above and from the top; colour modes given by the
scene (`ColourMode`: by mold, deviation, Meusnier radius, angle, kink, coverage gaps);
click or hover a panel for its numbers (`PanelInfo`); the net's edges coloured by
family (the two strip families) on request; a second set of panels in a colour of its
own (`PanelLayer`: the boundary panels between a net and the design boundary), shown or
hidden by a check box and picked like the net's.

This module knows nothing of nets or molds: `fabplan.fabricate.molds.mold_report` builds the
scenes of a net.
"""

from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass, field
from importlib import resources
from typing import Sequence

import numpy as np

__all__ = [
    "ColourMode",
    "PanelInfo",
    "PanelLayer",
    "ViewerScene",
    "encode_array",
    "scene_front",
    "viewer_assets",
    "viewer_block",
    "VIEWER_HELP",
]

#: What the reader can do with the view, shown under it.
VIEWER_HELP = ("How to use the 3D view: drag to orbit, scroll to zoom, right-drag (or "
               "shift-drag) to pan. The buttons show the design from eye level (a person "
               "1.7 m tall standing in front of it), from the front, from 30 degrees above "
               "and from the top. Click a panel to pin its numbers (face id, mold id, "
               "deviation, curvatures); hover to read them. Boundary panels, where a net "
               "has them, are drawn green and can be hidden with their check box. It needs "
               "WebGL; the static pictures further down show the same.")

_VIEWS = ("eye", "front", "above", "top")


def encode_array(values: np.ndarray, dtype: str) -> str:
    """``TYPE:BASE64`` of `values`, the form ``viewer.js`` decodes into a typed array.

    `dtype` ``"f4"`` stores float32; ``"int"`` the smallest of int8, uint8, uint16, int32
    that holds the values (mesh indices of up to 65,536 vertices take two bytes).

    Examples
    --------
    >>> encode_array(np.array([1, 2]), "int"), encode_array(np.array([-1, 300]), "int")
    ('u1:AQI=', 'i4://///ywBAAA=')
    """
    v = np.asarray(values).ravel()
    if dtype == "int":
        lo, hi = (int(v.min()), int(v.max())) if v.size else (0, 0)
        dtype = ("u1" if lo >= 0 and hi < 256 else "i1" if -128 <= lo and hi < 128 else
                 "u2" if lo >= 0 and hi < 65536 else "i4")
    data = np.ascontiguousarray(v, dtype="<" + dtype if dtype != "u1" and dtype != "i1" else dtype)
    return dtype + ":" + base64.b64encode(data.tobytes()).decode("ascii")


@dataclass
class ColourMode:
    """One way of colouring the panels.

    Attributes
    ----------
    key : short identifier (``"mold"``, ``"deviation"``, ...), unique in a scene.
    label : what the colour menu shows.
    how : one sentence under the view saying how to read the colours.
    values : (f,) per face or (n,) per vertex, or None for plain grey panels; categories
        (mold ids) as int, -1 for none.
    where : ``"face"`` or ``"vertex"`` (vertex values are blended across each panel).
    unit : unit of `values`, shown on the colour scale.
    categorical : the values index `palette`.
    palette : (k, 3) float RGB in [0, 1] of the categories.
    value_range : (lo, hi) of the colour scale (default: the finite values' range).
    limit : values above it are drawn red, and the scale marks it.
    """

    key: str
    label: str
    how: str
    values: np.ndarray | None = None
    where: str = "face"
    unit: str = ""
    categorical: bool = False
    palette: np.ndarray | None = None
    value_range: tuple[float, float] | None = None
    limit: float | None = None

    def to_json(self) -> dict:
        out: dict = {"key": self.key, "label": self.label, "how": self.how, "where": self.where,
                     "unit": self.unit, "categorical": self.categorical, "limit": self.limit}
        if self.values is None:
            return out
        v = np.asarray(self.values)
        if self.categorical:
            out["values"] = encode_array(v, "int")
            out["palette"] = encode_array(np.asarray(self.palette, float)[:, :3], "f4")
            return out
        finite = v[np.isfinite(v)]
        lo, hi = self.value_range or ((float(finite.min()), float(finite.max())) if finite.size
                                      else (0.0, 1.0))
        if hi - lo <= 1e-3 * max(abs(lo), abs(hi)):
            # a constant (an isogonal net's angle): one colour in the middle of the scale
            mid = 0.5 * (lo + hi)
            lo, hi = mid - max(0.01 * abs(mid), 1e-9), mid + max(0.01 * abs(mid), 1e-9)
        out["values"] = encode_array(np.where(np.isfinite(v), v, np.nan), "f4")
        out["range"] = [float(lo), float(hi) if hi > lo else float(lo) + 1e-9]
        return out


@dataclass
class PanelInfo:
    """One number shown for the panel under the pointer.

    Attributes
    ----------
    label : its name (``"mold"``, ``"k1"``).
    values : (f,) one value per face.
    unit : its unit ("" for ids and counts).
    digits : significant digits; integer : shown as an integer (ids).
    names : texts the (integer) values index, shown instead of the number (a kind).
    absent : with `integer`, the text shown for a negative value (an id that is none,
        e.g. ``"own mold"``); the value itself when empty.
    """

    label: str
    values: np.ndarray
    unit: str = ""
    digits: int = 4
    integer: bool = False
    names: Sequence[str] | None = None
    absent: str = ""

    def to_json(self) -> dict:
        integer = self.integer or self.names is not None
        out = {"label": self.label, "unit": self.unit, "digits": self.digits,
               "integer": integer, "absent": self.absent,
               "values": encode_array(self.values, "int" if integer else "f4")}
        if self.names is not None:
            out["names"] = list(self.names)
        return out


@dataclass
class PanelLayer:
    """Panels drawn beside a scene's net in one colour of their own, picked on their own.

    The boundary panels of a net laid out on a design (`fabplan.layout.trim`) are such a
    layer: polygons with many outline points, concave where the design boundary is, so
    they come already cut into triangles.

    Attributes
    ----------
    label : what the panels are (``"boundary panel"``), shown with the picked panel's id
        and beside the check box that shows or hides them.
    vertices : (m, 3) float, model units (the scene's own, not re-centred).
    face_sizes : (p,) int and face_indices : (sum of sizes,) int, each panel's outline.
    triangles : (t, 3) int into `vertices`; triangle_panel : (t,) int, the panel of each.
    info : the numbers shown for a picked panel (its id always comes first).
    colour : (3,) float RGB in [0, 1] of the panels (green, as in the static pictures).
    how : one sentence under the view saying what the panels are.
    toggle : the text beside the check box (default: their number and `label`).
    """

    label: str
    vertices: np.ndarray
    face_sizes: np.ndarray
    face_indices: np.ndarray
    triangles: np.ndarray
    triangle_panel: np.ndarray
    info: list[PanelInfo] = field(default_factory=list)
    colour: tuple[float, float, float] = (0.40, 0.80, 0.45)
    how: str = ""
    toggle: str = ""

    def to_json(self, centre: np.ndarray) -> dict:
        n = len(self.face_sizes)
        return {"label": self.label, "how": self.how,
                "toggle": self.toggle or f"{n} {self.label}{'' if n == 1 else 's'}",
                "positions": encode_array(np.asarray(self.vertices, float) - centre, "f4"),
                "face_sizes": encode_array(self.face_sizes, "int"),
                "face_indices": encode_array(self.face_indices, "int"),
                "triangles": encode_array(self.triangles, "int"),
                "triangle_panel": encode_array(self.triangle_panel, "int"),
                "colour": [float(c) for c in self.colour],
                "info": [i.to_json() for i in self.info]}


def scene_front(normals: np.ndarray, areas: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, str]:
    """The horizontal direction a person looks at the design from, and the first view.

    A facade (faces agreeing on a side, the mean normal within 45 degrees of horizontal)
    is seen from in front of it, at eye level; a roof (mean normal near vertical) from 30
    degrees above, along the diagonal of its plan; a closed surface (a ring) from the
    side its longest horizontal axis shows most of, at eye level.

    Parameters
    ----------
    normals : (f, 3) unit face normals; areas : (f,) face areas; vertices : (n, 3).

    Returns
    -------
    front : (2,) float, unit horizontal vector from the design towards the viewer.
    initial : ``"eye"`` or ``"above"``.

    Examples
    --------
    >>> n = np.tile([0.0, -1.0, 0.0], (4, 1))
    >>> front, initial = scene_front(n, np.ones(4), np.zeros((3, 3)))
    >>> front.round(3).tolist(), initial
    ([0.0, -1.0], 'eye')
    """
    weighted = np.nan_to_num(normals) * areas[:, None]
    total = float(areas.sum())
    sideways = float(np.linalg.norm(weighted[:, :2], axis=1).sum())   # area facing sideways
    mean = weighted.sum(axis=0)
    ring = sideways > 0.5 * total and np.linalg.norm(mean[:2]) < 0.3 * sideways
    if not ring and np.linalg.norm(mean) > 0.3 * total:
        mean = mean / np.linalg.norm(mean)
        if abs(mean[2]) >= np.cos(np.radians(45)):
            span = np.ptp(vertices[:, :2], axis=0)
            azimuth = np.arctan2(span[1], span[0]) - np.radians(75)
            return np.array([np.cos(azimuth), np.sin(azimuth)]), "above"
        return mean[:2] / np.linalg.norm(mean[:2]), "eye"
    # a ring (a stadium, a tower) or a closed surface: look across the shorter horizontal
    # axis, so that its long side faces the viewer
    centred = vertices[:, :2] - vertices[:, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    front = vt[-1] if vt.shape[0] > 1 else np.array([0.0, -1.0])
    return front / np.linalg.norm(front), "eye"


@dataclass
class ViewerScene:
    """One mesh to show, with its colour modes and panel numbers.

    Attributes
    ----------
    title : shown in the candidate menu.
    vertices : (n, 3) float, model units; face_sizes : (f,) int; face_indices : (sum of
        sizes,) int, the faces' vertex ids one face after the other.
    modes : the colour modes, the first is shown first.
    info : the numbers shown for a picked panel (its face id always comes first).
    edges : (e, 2) int vertex ids; edge_family : (e,) int, 0 or 1 for the two families
        of the net's lines (the strip families), -1 for others.
    gaps : (g, 3, 3) float triangles of the design the net leaves uncovered, drawn red in
        the ``"gaps"`` mode, or None.
    front : (2,) horizontal unit vector towards the viewer (`scene_front`); initial : the
        first view, one of ``eye``, ``front``, ``above``, ``top``.
    eye_height : 1.7 m in model units.
    layer : more panels shown beside the net (`PanelLayer`: its boundary panels), or None.
    centre : (3,) float, the point the view is centred on (model units); None: the middle
        of the vertices' bounding box. A view whose net changes (`fabplan edit`) keeps one
        centre, so that its positions stay put where the net does not move.
    """

    title: str
    vertices: np.ndarray
    face_sizes: np.ndarray
    face_indices: np.ndarray
    modes: list[ColourMode]
    info: list[PanelInfo] = field(default_factory=list)
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    edge_family: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    gaps: np.ndarray | None = None
    front: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0]))
    initial: str = "front"
    eye_height: float = 1.7
    layer: PanelLayer | None = None
    centre: np.ndarray | None = None

    def to_json(self) -> dict:
        if self.initial not in _VIEWS:
            raise ValueError(f"initial view must be one of {_VIEWS}, got {self.initial!r}")
        X = np.asarray(self.vertices, float)
        # positions relative to a centre: float32 keeps mm on a 10 km site
        centre = (0.5 * (X.min(axis=0) + X.max(axis=0)) if self.centre is None
                  else np.asarray(self.centre, float))
        out = {
            "title": self.title,
            "positions": encode_array(X - centre, "f4"),
            "face_sizes": encode_array(self.face_sizes, "int"),
            "face_indices": encode_array(self.face_indices, "int"),
            "edges": encode_array(self.edges, "int"),
            "edge_family": encode_array(self.edge_family, "int"),
            "modes": [m.to_json() for m in self.modes],
            "info": [i.to_json() for i in self.info],
            "views": {"front": [float(v) for v in self.front], "initial": self.initial,
                      "ground": float(X[:, 2].min() - centre[2]), "eye_height": self.eye_height},
        }
        if self.gaps is not None and len(self.gaps):
            out["gaps"] = encode_array(np.asarray(self.gaps, float) - centre, "f4")
        if self.layer is not None and len(self.layer.face_sizes):
            out["layer"] = self.layer.to_json(centre)
        return out


_CSS = """
.fp-viewer { border: 1px solid #ccc; padding: 0.5em; margin: 1em 0; background: #fafafa; }
.fp-bar { display: flex; flex-wrap: wrap; gap: 0.4em; align-items: center; margin-bottom: 0.4em; }
.fp-bar button { border: 1px solid #aaa; background: #fff; padding: 0.15em 0.6em; cursor: pointer; }
.fp-bar button.fp-on { background: #dfe9f7; border-color: #4a7ab5; }
.fp-canvas canvas { display: block; width: 100%; }
.fp-legend { margin-top: 0.4em; font-size: 0.9em; }
.fp-scale-wrap { display: flex; align-items: center; gap: 0.5em; margin-bottom: 1.6em; }
.fp-scale { position: relative; height: 14px; flex: 1; border: 1px solid #888; }
.fp-limit { position: absolute; top: -6px; bottom: -6px; width: 3px; margin-left: -1px;
            background: #000; }
.fp-limit span { position: absolute; top: 24px; left: -3em; width: 8em; text-align: center;
                 font-weight: 600; }
.fp-info { margin-top: 0.3em; font-size: 0.92em; min-height: 1.4em; }
.fp-item { margin-right: 1.2em; white-space: nowrap; display: inline-block; }
.fp-how { color: #444; }
.fp-swatch { display: inline-block; width: 0.9em; height: 0.9em; border: 1px solid #555;
             vertical-align: -0.1em; }
.fp-layer-how { margin-top: 0.3em; color: #444; }
@media print { .fp-viewer { display: none; } }
"""


def viewer_assets() -> str:
    """The style and scripts of the viewer, once per page (about 570 kB, most of it
    three.js), to go at the end of the page's body."""
    root = resources.files("fabplan.report")
    three = root.joinpath("vendor/three.min.js").read_text(encoding="utf-8")
    script = root.joinpath("viewer.js").read_text(encoding="utf-8")
    return (f"<style>{_CSS}</style><script>{_script_text(three)}</script>"
            f"<script>{_script_text(script)}</script>")


def _script_text(text: str) -> str:
    # a literal "</script" would end the element early; "<\/" means the same in JS strings
    return text.replace("</script", "<\\/script")


def viewer_block(scenes: Sequence[ViewerScene], *, caption: str = VIEWER_HELP) -> str:
    """The viewer's HTML: a container the script fills, its scenes as JSON, and the
    `caption` (how to use it)."""
    if not scenes:
        raise ValueError("a viewer needs at least one scene")
    data = json.dumps({"scenes": [s.to_json() for s in scenes]}, separators=(",", ":"))
    data = data.replace("</", "<\\/")     # JSON inside <script>: same escape
    return (f'<div class="fp-viewer"><script type="application/json" class="fp-scenes">{data}'
            f'</script></div><p class="note">{html.escape(caption)}</p>')
