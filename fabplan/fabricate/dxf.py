"""DXF cutting files of nested lamella parts, their schedule and previews.

Every sheet becomes an R2010 DXF in millimetres (``$INSUNITS = 4``) with three layers (names
and colours configurable): closed LWPOLYLINE outlines with bulges on the cut layer, closed
slit rectangles on the slit layer (their mouths run `slit_overcut_mm` past the strip edge,
so cutting the slits first and the outline after frees them cleanly), and engravings on
the engrave layer: labels as single-stroke polylines, as glyph outlines, or as TEXT, plus
the orientation arrows and splice marks. Files are built in a temporary folder, read back
(``ezdxf.readfile`` and ``ezdxf.recover.readfile``), audited and checked (closed outlines
inside the sheet and apart, no zero-length or duplicate segments) before they are moved
into place.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

import ezdxf
import numpy as np
import shapely
from ezdxf import recover
from ezdxf.document import Drawing
from ezdxf.entities import LWPolyline
from ezdxf.enums import TextEntityAlignment
from ezdxf.layouts import BaseLayout

from ..errors import FabplanError, InputError
from ..report.figures import new_figure
from .nesting import Label, bulge_polygon

if TYPE_CHECKING:  # pragma: no cover
    from .nesting import Nesting, Sheet
    from .strips import StripSettings

__all__ = [
    "STROKE_FONT",
    "stroke_text",
    "outline_text",
    "sheet_document",
    "SheetDrawing",
    "read_sheet",
    "check_sheet",
    "segment_problems",
    "preview_png",
]

SHEET_GAP_MM = 100.0
"""Gap between sheets laid side by side in one file."""

SHEET_LAYER = ("SHEET", 8)
"""Non-plotting layer of the sheet frames drawn when all sheets share one file."""

# Single-stroke font on a 4 x 6 grid (cap height 6, advance 5): strokes as point lists.
STROKE_FONT: dict[str, list] = {
    "0": [[(0, 0), (4, 0), (4, 6), (0, 6), (0, 0)], [(0, 0), (4, 6)]],
    "1": [[(1, 5), (2, 6), (2, 0)], [(1, 0), (3, 0)]],
    "2": [[(0, 6), (4, 6), (4, 3), (0, 3), (0, 0), (4, 0)]],
    "3": [[(0, 6), (4, 6), (4, 0), (0, 0)], [(1, 3), (4, 3)]],
    "4": [[(3, 0), (3, 6), (0, 2), (4, 2)]],
    "5": [[(4, 6), (0, 6), (0, 3), (3, 3), (4, 2), (4, 1), (3, 0), (0, 0)]],
    "6": [[(4, 6), (0, 6), (0, 0), (4, 0), (4, 3), (0, 3)]],
    "7": [[(0, 6), (4, 6), (1, 0)]],
    "8": [[(0, 0), (4, 0), (4, 6), (0, 6), (0, 0)], [(0, 3), (4, 3)]],
    "9": [[(4, 3), (0, 3), (0, 6), (4, 6), (4, 0), (0, 0)]],
    "A": [[(0, 0), (0, 4), (2, 6), (4, 4), (4, 0)], [(0, 3), (4, 3)]],
    "B": [[(0, 0), (0, 6), (3, 6), (4, 5), (4, 4), (3, 3), (0, 3)],
          [(3, 3), (4, 2), (4, 1), (3, 0), (0, 0)]],
    "C": [[(4, 6), (0, 6), (0, 0), (4, 0)]],
    "D": [[(0, 0), (0, 6), (2, 6), (4, 4), (4, 2), (2, 0), (0, 0)]],
    "E": [[(4, 6), (0, 6), (0, 0), (4, 0)], [(0, 3), (3, 3)]],
    "F": [[(4, 6), (0, 6), (0, 0)], [(0, 3), (3, 3)]],
    "G": [[(4, 6), (0, 6), (0, 0), (4, 0), (4, 3), (2, 3)]],
    "H": [[(0, 6), (0, 0)], [(4, 6), (4, 0)], [(0, 3), (4, 3)]],
    "I": [[(1, 6), (3, 6)], [(2, 6), (2, 0)], [(1, 0), (3, 0)]],
    "J": [[(4, 6), (4, 0), (0, 0), (0, 2)]],
    "K": [[(0, 6), (0, 0)], [(4, 6), (0, 2)], [(1, 3), (4, 0)]],
    "L": [[(0, 6), (0, 0), (4, 0)]],
    "M": [[(0, 0), (0, 6), (2, 3), (4, 6), (4, 0)]],
    "N": [[(0, 0), (0, 6), (4, 0), (4, 6)]],
    "O": [[(0, 0), (4, 0), (4, 6), (0, 6), (0, 0)]],
    "P": [[(0, 0), (0, 6), (4, 6), (4, 3), (0, 3)]],
    "Q": [[(0, 0), (4, 0), (4, 6), (0, 6), (0, 0)], [(2, 2), (4, -1)]],
    "R": [[(0, 0), (0, 6), (4, 6), (4, 3), (0, 3)], [(1, 3), (4, 0)]],
    "S": [[(4, 6), (0, 6), (0, 3), (4, 3), (4, 0), (0, 0)]],
    "T": [[(0, 6), (4, 6)], [(2, 6), (2, 0)]],
    "U": [[(0, 6), (0, 0), (4, 0), (4, 6)]],
    "V": [[(0, 6), (2, 0), (4, 6)]],
    "W": [[(0, 6), (1, 0), (2, 3), (3, 0), (4, 6)]],
    "X": [[(0, 0), (4, 6)], [(0, 6), (4, 0)]],
    "Y": [[(0, 6), (2, 3), (4, 6)], [(2, 3), (2, 0)]],
    "Z": [[(0, 6), (4, 6), (0, 0), (4, 0)]],
    "-": [[(1, 3), (3, 3)]],
    "+": [[(0, 3), (4, 3)], [(2, 1), (2, 5)]],
    ".": [[(1.5, 0), (2.5, 0)]],
    "/": [[(0, 0), (4, 6)]],
    ":": [[(1.5, 1), (2.5, 1)], [(1.5, 5), (2.5, 5)]],
    "_": [[(0, 0), (4, 0)]],
    " ": [],
}


def _label_frame(label: Label, width: float, height: float) -> np.ndarray:
    """(2, 3) affine matrix taking text coordinates (origin at the lower left of a text
    box `width` x `height`) to the label's centred, rotated position."""
    a = math.radians(label.angle_deg)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    t = np.asarray(label.position) - R @ np.array([width / 2, height / 2])
    return np.column_stack([R, t])


def stroke_text(label: Label) -> list:
    """Single-stroke polylines of a label (cap height `label.height`).

    Returns
    -------
    list of (k, 2) float open polylines.

    Examples
    --------
    >>> from fabplan.fabricate.nesting import Label
    >>> lines = stroke_text(Label("A1", (0.0, 0.0), 0.0, 6.0, "strip"))
    >>> len(lines), lines[0].shape
    (4, (5, 2))
    """
    scale = label.height / 6.0
    text = label.text.upper()
    width = (len(text) * 5 - 1) * scale
    M = _label_frame(label, width, label.height)
    out = []
    for i, ch in enumerate(text):
        if ch not in STROKE_FONT:
            raise InputError(f"label {label.text!r}: no stroke glyph for {ch!r}")
        for stroke in STROKE_FONT[ch]:
            P = (np.asarray(stroke, dtype=np.float64) + [5 * i, 0]) * scale
            out.append(P @ M[:, :2].T + M[:, 2])
    return out


def outline_text(label: Label) -> list:
    """Glyph outlines of a label (DejaVu Sans through matplotlib), cap height `label.height`.

    Returns
    -------
    list of (k, 2) float closed polylines (first point not repeated).
    """
    polys, width = _glyph_outlines(label.text, round(label.height, 9))
    M = _label_frame(label, width, label.height)
    return [P @ M[:, :2].T + M[:, 2] for P in polys]


@lru_cache(maxsize=4096)
def _glyph_outlines(text: str, height: float) -> tuple[list, float]:
    """Outlines of `text` at cap height `height`, origin at the lower left; and its width."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    prop = FontProperties(family="DejaVu Sans")
    path = TextPath((0, 0), text, size=height / _cap_height(), prop=prop)
    ext = path.get_extents()
    out = []
    for poly in path.to_polygons(closed_only=True):
        P = np.asarray(poly, dtype=np.float64)
        if len(P) > 1 and np.allclose(P[0], P[-1]):
            P = P[:-1]
        keep = np.r_[True, np.linalg.norm(np.diff(P, axis=0), axis=1) > 1e-6]
        P = P[keep] - [ext.x0, 0.0]
        if len(P) >= 3:
            out.append(P)
    return out, float(ext.width)


@lru_cache(maxsize=1)
def _cap_height() -> float:
    """Cap height of DejaVu Sans at size 1."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    return float(TextPath((0, 0), "H", size=1.0,
                          prop=FontProperties(family="DejaVu Sans")).get_extents().height)


# ---------------------------------------------------------------------- writing
def _new_document(settings: "StripSettings", *, frames: bool = False):
    doc = ezdxf.new("R2010", units=ezdxf.units.MM, setup=False)
    doc.header["$MEASUREMENT"] = 1
    for kind in ("cut", "slit", "engrave"):
        name, colour = settings.layers[kind]
        doc.layers.add(str(name), color=int(colour))
    if frames:
        layer = doc.layers.add(SHEET_LAYER[0], color=SHEET_LAYER[1])
        layer.dxf.plot = 0
    return doc


def _add_sheet(msp, layout: "Nesting", sheet: "Sheet", settings: "StripSettings",
               dx: float = 0.0) -> None:
    cut, slit, engrave = (str(settings.layers[k][0]) for k in ("cut", "slit", "engrave"))
    for placement in sheet.placements:
        part = layout.parts[placement.part]
        M = placement.matrix()
        M[0, 2] += dx

        def tf(P: np.ndarray, M=M) -> list:
            return (np.asarray(P)[:, :2] @ M[:, :2].T + M[:, 2]).tolist()

        # a rotation keeps bulges (angles and their signs)
        rows = np.column_stack([tf(part.outline), part.outline[:, 2]])
        msp.add_lwpolyline(rows.tolist(), format="xyb", close=True, dxfattribs={"layer": cut})
        for rect in part.slits:
            msp.add_lwpolyline(tf(rect), format="xy", close=True, dxfattribs={"layer": slit})
        for mark in part.marks:
            msp.add_lwpolyline(tf(mark), format="xy", close=False, dxfattribs={"layer": engrave})
        angle = math.degrees(math.atan2(M[1, 0], M[0, 0]))
        for label in part.labels:
            pos = tf(np.array([label.position]))[0]
            placed = Label(label.text, (pos[0], pos[1]), label.angle_deg + angle, label.height,
                           label.kind)
            if settings.labels == "text":
                msp.add_text(placed.text, height=placed.height, rotation=placed.angle_deg,
                             dxfattribs={"layer": engrave}).set_placement(
                    pos, align=TextEntityAlignment.MIDDLE_CENTER)
            elif settings.labels == "outline":
                for P in outline_text(placed):
                    msp.add_lwpolyline(P.tolist(), format="xy", close=True,
                                       dxfattribs={"layer": engrave})
            else:
                for P in stroke_text(placed):
                    msp.add_lwpolyline(P.tolist(), format="xy", close=False,
                                       dxfattribs={"layer": engrave})


def sheet_document(layout: "Nesting", sheets: list, settings: "StripSettings"):
    """An ezdxf document with the given sheets, side by side when there are several.

    Parameters
    ----------
    layout : the nesting result.
    sheets : list of Sheet to draw; sheet k sits at x = k (width + `SHEET_GAP_MM`).
    settings : layers and label style.
    """
    frames = len(sheets) > 1
    doc = _new_document(settings, frames=frames)
    msp = doc.modelspace()
    W, H = settings.sheet_mm
    for k, sheet in enumerate(sheets):
        dx = k * (W + SHEET_GAP_MM)
        _add_sheet(msp, layout, sheet, settings, dx)
        if frames:
            msp.add_lwpolyline([(dx, 0), (dx + W, 0), (dx + W, H), (dx, H)], close=True,
                               dxfattribs={"layer": SHEET_LAYER[0]})
    width = len(sheets) * W + (len(sheets) - 1) * SHEET_GAP_MM
    doc.header["$EXTMIN"] = (0, 0, 0)
    doc.header["$EXTMAX"] = (width, H, 0)
    doc.header["$LIMMIN"] = (0, 0)
    doc.header["$LIMMAX"] = (width, H)
    return doc


# ---------------------------------------------------------------------- reading back
@dataclass
class SheetDrawing:
    """What a DXF sheet file holds, read back with ezdxf (mm).

    Attributes
    ----------
    outlines : list of (m, 3) float rows ``x, y, bulge`` of the cut layer's polylines.
    outline_closed : list of bool.
    slits : list of (m, 2) float, the slit layer's polylines.
    slit_closed : list of bool.
    engravings : number of entities on the engrave layer.
    insunits : the $INSUNITS header value.
    version : the DXF version string.
    audit_errors : number of errors ``doc.audit()`` reports.
    recover_errors : number of errors left after ``ezdxf.recover.readfile``.
    doc : the document as read (not part of the comparison).
    """

    outlines: list
    outline_closed: list
    slits: list
    slit_closed: list
    engravings: int
    insunits: int
    version: str
    audit_errors: int
    recover_errors: int
    doc: Drawing | None = None


def _lwpolylines(layout: BaseLayout) -> Iterator[LWPolyline]:
    """The LWPOLYLINE entities of a layout, typed as such."""
    for e in layout.query("LWPOLYLINE"):
        if isinstance(e, LWPolyline):
            yield e


def read_sheet(path: str | os.PathLike, layers: dict, *, recover_too: bool = True) -> SheetDrawing:
    """Read a sheet DXF back with ezdxf and audit it.

    Parameters
    ----------
    path : the DXF file.
    layers : kind -> (name, colour), as in `StripSettings.layers`.
    recover_too : also load it with ``ezdxf.recover.readfile`` and count its errors.
    """
    doc = ezdxf.readfile(str(path))
    auditor = doc.audit()
    recover_errors = len(recover.readfile(str(path))[1].errors) if recover_too else 0
    cut, slit, engrave = (str(layers[k][0]) for k in ("cut", "slit", "engrave"))
    msp = doc.modelspace()
    outlines, closed_o, slits, closed_s = [], [], [], []
    for e in _lwpolylines(msp):
        if e.dxf.layer == cut:
            outlines.append(np.array(list(e.get_points("xyb")), dtype=np.float64))
            closed_o.append(bool(e.closed))
        elif e.dxf.layer == slit:
            slits.append(np.array(list(e.get_points("xy")), dtype=np.float64))
            closed_s.append(bool(e.closed))
    engravings = len(msp.query(f'*[layer=="{engrave}"]'))
    drawing = SheetDrawing(outlines=outlines, outline_closed=closed_o, slits=slits,
                           slit_closed=closed_s, engravings=engravings,
                           insunits=int(doc.header.get("$INSUNITS", 0)), version=doc.dxfversion,
                           audit_errors=len(auditor.errors), recover_errors=recover_errors)
    drawing.doc = doc
    return drawing


def segment_problems(doc_or_path: str | os.PathLike | Drawing) -> list:
    """Zero-length and duplicate segments among all LWPOLYLINEs of a document.

    Two segments are duplicates when they join the same points (to 1e-4 mm, either way
    round) along the same arc or line, whatever their layers.

    Returns
    -------
    list of str, one per problem (empty when clean).
    """
    doc = ezdxf.readfile(str(doc_or_path)) if isinstance(doc_or_path, (str, os.PathLike)) \
        else doc_or_path
    starts, ends, bulges, layers = [], [], [], []
    for e in _lwpolylines(doc.modelspace()):
        pts = np.array(list(e.get_points("xyb")), dtype=np.float64)
        if len(pts) < 2:
            continue
        nxt = np.roll(pts, -1, axis=0)
        count = len(pts) if e.closed else len(pts) - 1
        starts.append(pts[:count, :2])
        ends.append(nxt[:count, :2])
        bulges.append(pts[:count, 2])
        layers += [e.dxf.layer] * count
    if not starts:
        return []
    a, b, bulge = np.concatenate(starts), np.concatenate(ends), np.concatenate(bulges)
    problems = [f"zero-length segment on layer {layers[i]} at {a[i].round(3)}"
                for i in np.flatnonzero(np.linalg.norm(b - a, axis=1) < 1e-6)]
    ka, kb = np.round(a, 4), np.round(b, 4)
    swap = (ka[:, 0] > kb[:, 0]) | ((ka[:, 0] == kb[:, 0]) & (ka[:, 1] > kb[:, 1]))
    key = np.column_stack([np.where(swap[:, None], kb, ka), np.where(swap[:, None], ka, kb),
                           np.round(np.where(swap, -bulge, bulge), 8)])
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    for i in first[counts > 1]:
        problems.append(f"duplicate segment on layer {layers[i]} at {a[i].round(3)}")
    return problems


def check_sheet(path: str | os.PathLike, settings: "StripSettings", sheet_count: int = 1) -> SheetDrawing:
    """Read a written sheet file back and check it as a cutter would need it.

    Checks: R2010, $INSUNITS 4, no audit errors (plain and recover reader), closed cut and
    slit polylines, outlines inside their sheet and `spacing_mm` apart, no zero-length or
    duplicate segments.

    Raises
    ------
    FabplanError
        Naming the file and the first failed check.
    """
    d = read_sheet(path, settings.layers, recover_too=False)
    name = Path(path).name
    if d.version != "AC1024":
        raise FabplanError(f"{name}: DXF version {d.version}, expected R2010 (AC1024)")
    if d.insunits != 4:
        raise FabplanError(f"{name}: $INSUNITS is {d.insunits}, expected 4 (millimetres)")
    if d.audit_errors or d.recover_errors:
        raise FabplanError(f"{name}: ezdxf audit reports {d.audit_errors + d.recover_errors} errors")
    if not all(d.outline_closed) or not all(d.slit_closed):
        raise FabplanError(f"{name}: an outline or slit polyline is not closed")
    W, H = settings.sheet_mm
    polys = [bulge_polygon(o) for o in d.outlines]
    boxes = [shapely.box(k * (W + SHEET_GAP_MM) - 1e-6, -1e-6, k * (W + SHEET_GAP_MM) + W + 1e-6,
                         H + 1e-6) for k in range(sheet_count)]
    for p in polys:
        if not any(box.contains(p) for box in boxes):
            raise FabplanError(f"{name}: an outline is not inside a sheet")
    tree = shapely.STRtree(polys)
    pairs = tree.query(polys, predicate="dwithin", distance=max(settings.spacing_mm - 1e-3, 0))
    if any(a < b for a, b in pairs.T):
        raise FabplanError(f"{name}: two outlines are closer than the spacing")
    problems = segment_problems(d.doc if d.doc is not None else path)
    if problems:
        raise FabplanError(f"{name}: {problems[0]}")
    return d


def preview_png(doc, path, size: tuple, *, title: str = "") -> None:
    """Draw a sheet document's entities as they are in the file (matplotlib PNG).

    Polylines are flattened from their bulges and drawn in their layer's colour, TEXT at
    its insertion point; the sheet's outline is drawn in grey.
    """
    from ezdxf.colors import aci2rgb
    from matplotlib.collections import LineCollection

    from .nesting import bulge_points

    W, H = size
    scale = 14.0 / max(W, H)
    fig = new_figure((max(W * scale, 2), max(H * scale, 2) + (0.3 if title else 0)), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1 if not title else H * scale / (H * scale + 0.3)))
    colours = {layer.dxf.name: np.array(aci2rgb(layer.color)) / 255 for layer in doc.layers}
    lines, cols = [], []
    for e in doc.modelspace():
        colour = colours.get(e.dxf.layer, np.zeros(3))
        if e.dxftype() == "LWPOLYLINE":
            rows = np.array(list(e.get_points("xyb")), dtype=np.float64)
            P = bulge_points(rows, closed=bool(e.closed), tolerance_mm=0.2)
            if e.closed:
                P = np.vstack([P, P[:1]])
            lines.append(P)
            cols.append(colour)
        elif e.dxftype() == "TEXT":
            at = e.dxf.align_point if e.dxf.hasattr("align_point") else e.dxf.insert
            x, y = at.x, at.y
            ax.text(x, y, e.dxf.text, rotation=e.dxf.rotation, ha="center", va="center",
                    fontsize=max(2.0, e.dxf.height * scale * 72 / 1.4), color=colour,
                    rotation_mode="anchor")
    ax.add_collection(LineCollection(lines, colors=cols, linewidths=0.6))
    ax.plot([0, W, W, 0, 0], [0, 0, H, H, 0], color="0.6", lw=0.8)
    ax.set_xlim(-0.01 * W, 1.01 * W)
    ax.set_ylim(-0.01 * H, 1.01 * H)
    ax.set_aspect("equal", adjustable="datalim")
    ax.axis("off")
    if title:
        fig.suptitle(title, fontsize=9, y=0.995)
    fig.savefig(path, dpi=110, facecolor="white")
