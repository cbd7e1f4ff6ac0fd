"""DXF cutting files of nested lamella parts, their schedule and previews.

Every sheet becomes an R2010 DXF in millimetres (``$INSUNITS = 4``) with three layers (names
and colours configurable): closed LWPOLYLINE outlines with bulges on the cut layer, closed
slit rectangles on the slit layer (their mouths run `slit_overcut_mm` past the strip edge,
so cutting the slits first and the outline after frees them cleanly), and engravings on
the engrave layer: labels as single-stroke polylines, as glyph outlines, or as TEXT, plus
the orientation arrows and splice marks. A sheet's entities are first gathered as plain
arrays (`SheetGeometry`). The file is the empty document ezdxf writes (header, tables,
layers: audited by ezdxf) with the entities written straight into its ENTITIES section
(`sheet_dxf_text`; ezdxf's own document of them, `geometry_document`, gives the same
file's geometry to the last bit, and draws the previews in tests). The entities are checked
before they are written (closed outlines inside the sheet and apart, no zero-length or
duplicate segments), the bytes on disk are compared with those written by their SHA-256,
and `check_sheet` reads a written file back with ezdxf, audits it and runs the same checks.
"""

from __future__ import annotations

import hashlib
import io
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

from ...errors import FabplanError, InputError
from .bulges import bulge_points, bulge_polygon
from .nesting import Label

if TYPE_CHECKING:  # pragma: no cover
    from .nesting import Nesting
    from .strip_set import StripSettings

__all__ = [
    "STROKE_FONT",
    "stroke_text",
    "outline_text",
    "SheetGeometry",
    "sheet_geometry",
    "label_polylines",
    "geometry_document",
    "sheet_document",
    "dxf_bytes",
    "sheet_dxf_text",
    "geometry_drawing",
    "write_sheet_file",
    "SheetDrawing",
    "sheet_drawing",
    "read_sheet",
    "check_drawing",
    "check_document",
    "check_sheet",
    "segment_problems",
    "polyline_problems",
    "preview_png",
    "geometry_preview_png",
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
    >>> from fabplan.fabricate.strips.nesting import Label
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
    return _empty_document(_layer_key(settings), frames)


def _layer_key(settings: "StripSettings") -> tuple:
    """The cut, slit and engrave layers' (name, colour), hashable."""
    return tuple((str(settings.layers[k][0]), int(settings.layers[k][1]))
                 for k in ("cut", "slit", "engrave"))


def _empty_document(layers: tuple, frames: bool) -> Drawing:
    doc = ezdxf.new("R2010", units=ezdxf.units.MM, setup=False)
    doc.header["$MEASUREMENT"] = 1
    for name, colour in layers:
        doc.layers.add(name, color=colour)
    if frames:
        layer = doc.layers.add(SHEET_LAYER[0], color=SHEET_LAYER[1])
        layer.dxf.plot = 0
    return doc


def _set_extents(doc: Drawing, geom_size: tuple, sheet_count: int) -> None:
    """The drawing's extents and limits: the sheets side by side (a CAD program zooms to
    them). ezdxf writes the model space's own values into the header, so both are set."""
    W, H = geom_size
    width = sheet_count * W + (sheet_count - 1) * SHEET_GAP_MM
    msp = doc.modelspace()
    msp.dxf.extmin, msp.dxf.extmax = (0, 0, 0), (width, H, 0)
    msp.dxf.limmin, msp.dxf.limmax = (0, 0), (width, H)
    doc.header["$EXTMIN"], doc.header["$EXTMAX"] = (0, 0, 0), (width, H, 0)
    doc.header["$LIMMIN"], doc.header["$LIMMAX"] = (0, 0), (width, H)


@dataclass
class SheetGeometry:
    """The entities of one sheet file as plain arrays, in the order they are written (mm).

    Small enough to send to another process, and all that is needed to build the file's
    document (`geometry_document`) and its preview (`geometry_preview_png`).

    Attributes
    ----------
    size : (width, height) of one sheet.
    sheet_count : sheets side by side in the file.
    layers : list of str, each entity's layer kind: ``"cut"``, ``"slit"``, ``"engrave"``
        or ``"sheet"`` (the frames drawn when several sheets share the file).
    shapes : list, each entity's geometry: (m, 3) float rows ``x, y, bulge`` on the cut
        layer, (m, 2) float points on the others, or a `Label` placed on the sheet (its
        strokes, outlines or TEXT follow `StripSettings.labels`).
    closed : list of bool, whether each polyline is closed.
    """

    size: tuple[float, float]
    sheet_count: int
    layers: list[str]
    shapes: list
    closed: list[bool]


def sheet_geometry(layout: "Nesting", sheets: list, settings: "StripSettings") -> SheetGeometry:
    """The entities of a file holding `sheets`, side by side when there are several.

    Parameters
    ----------
    layout : the nesting result.
    sheets : list of Sheet to draw; sheet k sits at x = k (width + `SHEET_GAP_MM`).
    settings : sheet size.

    Returns
    -------
    SheetGeometry, per part: its outline, slits, marks and labels in that order, then the
    sheet's frame when there are several sheets.
    """
    W, H = settings.sheet_mm
    frames = len(sheets) > 1
    geom = SheetGeometry(size=(W, H), sheet_count=len(sheets), layers=[], shapes=[], closed=[])

    def add(kind: str, shape, closed: bool) -> None:
        geom.layers.append(kind)
        geom.shapes.append(shape)
        geom.closed.append(closed)

    for k, sheet in enumerate(sheets):
        dx = k * (W + SHEET_GAP_MM)
        for placement in sheet.placements:
            part = layout.parts[placement.part]
            M = placement.matrix()
            M[0, 2] += dx

            def tf(P: np.ndarray, M=M) -> np.ndarray:
                return np.asarray(P)[:, :2] @ M[:, :2].T + M[:, 2]

            # a rotation keeps bulges (angles and their signs)
            add("cut", np.column_stack([tf(part.outline), part.outline[:, 2]]), True)
            for rect in part.slits:
                add("slit", tf(rect), True)
            for mark in part.marks:
                add("engrave", tf(mark), False)
            angle = math.degrees(math.atan2(M[1, 0], M[0, 0]))
            for label in part.labels:
                pos = tf(np.array([label.position]))[0].tolist()
                add("engrave", Label(label.text, (pos[0], pos[1]), label.angle_deg + angle,
                                     label.height, label.kind), False)
        if frames:
            add("sheet", np.array([(dx, 0), (dx + W, 0), (dx + W, H), (dx, H)], dtype=np.float64),
                True)
    return geom


def label_polylines(label: Label, style: str) -> tuple[list, bool]:
    """The polylines that engrave a placed label: glyph outlines (closed) for ``"outline"``,
    single strokes (open) otherwise; none for ``"text"`` (written as TEXT)."""
    if style == "text":
        return [], False
    if style == "outline":
        return outline_text(label), True
    return stroke_text(label), False


def geometry_document(geom: SheetGeometry, settings: "StripSettings") -> Drawing:
    """The ezdxf document of a sheet file's entities (R2010, millimetres).

    Parameters
    ----------
    geom : the entities, from `sheet_geometry`.
    settings : layers and label style.
    """
    doc = _new_document(settings, frames=geom.sheet_count > 1)
    msp = doc.modelspace()
    names = {kind: str(settings.layers[kind][0]) for kind in ("cut", "slit", "engrave")}
    names["sheet"] = SHEET_LAYER[0]
    for kind, shape, closed in zip(geom.layers, geom.shapes, geom.closed, strict=True):
        attribs = {"layer": names[kind]}
        if isinstance(shape, Label):
            if settings.labels == "text":
                msp.add_text(shape.text, height=shape.height, rotation=shape.angle_deg,
                             dxfattribs=attribs).set_placement(
                    shape.position, align=TextEntityAlignment.MIDDLE_CENTER)
                continue
            lines, shut = label_polylines(shape, settings.labels)
            for P in lines:
                msp.add_lwpolyline(P.tolist(), format="xy", close=shut, dxfattribs=attribs)
        else:
            msp.add_lwpolyline(shape.tolist(), format="xyb" if shape.shape[1] == 3 else "xy",
                               close=closed, dxfattribs=attribs)
    _set_extents(doc, geom.size, geom.sheet_count)
    return doc


@lru_cache(maxsize=8)
def _template(layers: tuple, frames: bool, size: tuple, sheet_count: int) -> tuple[str, str, int, str]:
    """An empty sheet file as ezdxf writes it, cut open at its ENTITIES section.

    Returns
    -------
    head : the text up to the ENTITIES section's first entity.
    tail : the text from the end of the ENTITIES section on.
    seed : the first free handle.
    owner : the handle of the model space's block record (every entity's owner).
    """
    doc = _empty_document(layers, frames)
    _set_extents(doc, size, sheet_count)
    if doc.audit().errors:                     # pragma: no cover - ezdxf's own document
        raise FabplanError("the empty DXF sheet does not pass ezdxf's audit")
    stream = io.StringIO()
    doc.write(stream)
    text = stream.getvalue()
    start = text.index(_ENTITIES) + len(_ENTITIES)
    end = text.index("  0\nENDSEC\n", start)
    seed = int(str(doc.header["$HANDSEED"]), 16)
    return text[:start], text[end:], seed, str(doc.modelspace().block_record_handle)


_ENTITIES = "  0\nSECTION\n  2\nENTITIES\n"


def _lwpolyline_tags(handle: int, owner: str, layer: str, rows: np.ndarray, closed: bool) -> str:
    """The tags of an R2010 LWPOLYLINE (as ezdxf writes it): points (m, 2) or rows
    (m, 3) ``x, y, bulge``, bulges only where they are not zero."""
    head = (f"  0\nLWPOLYLINE\n  5\n{handle:X}\n330\n{owner}\n100\nAcDbEntity\n  8\n{layer}\n"
            f"100\nAcDbPolyline\n 90\n{len(rows)}\n 70\n{1 if closed else 0}\n")
    if rows.shape[1] == 3:
        points = "".join(f" 10\n{x!r}\n 20\n{y!r}\n" + (f" 42\n{b!r}\n" if b else "")
                         for x, y, b in rows.tolist())
    else:
        points = "".join(f" 10\n{x!r}\n 20\n{y!r}\n" for x, y in rows.tolist())
    return head + points


def _text_tags(handle: int, owner: str, layer: str, label: Label) -> str:
    """The tags of an R2010 TEXT centred on the label's position (as ezdxf writes it)."""
    x, y = (float(v) for v in label.position)
    return (f"  0\nTEXT\n  5\n{handle:X}\n330\n{owner}\n100\nAcDbEntity\n  8\n{layer}\n"
            f"100\nAcDbText\n 10\n{x!r}\n 20\n{y!r}\n 30\n0.0\n 40\n{float(label.height)!r}\n"
            f"  1\n{label.text}\n 50\n{float(label.angle_deg)!r}\n 72\n1\n 11\n{x!r}\n"
            f" 21\n{y!r}\n 31\n0.0\n100\nAcDbText\n 73\n2\n")


def _entities(geom: SheetGeometry, settings: "StripSettings"
              ) -> Iterator[tuple[str, np.ndarray | Label, bool]]:
    """Every entity of a sheet file as written: (layer name, (m, 2|3) rows or a TEXT
    `Label`, closed), labels broken into their polylines."""
    names = {kind: str(settings.layers[kind][0]) for kind in ("cut", "slit", "engrave")}
    names["sheet"] = SHEET_LAYER[0]
    for kind, shape, closed in zip(geom.layers, geom.shapes, geom.closed, strict=True):
        if isinstance(shape, Label):
            if settings.labels == "text":
                yield names[kind], shape, False
                continue
            lines, shut = label_polylines(shape, settings.labels)
            for P in lines:
                yield names[kind], np.asarray(P, dtype=np.float64), shut
        else:
            yield names[kind], np.asarray(shape, dtype=np.float64), closed


def sheet_dxf_text(geom: SheetGeometry, settings: "StripSettings") -> str:
    """The text of a sheet file: the same entities `geometry_document` builds, written
    straight into the empty document ezdxf writes (`_template`), with handles from its
    seed on. Coordinates are written as Python writes floats (exactly, as ezdxf does).
    Used because building and exporting thousands of ezdxf entities took most of a
    strip plan's time."""
    head, tail, seed, owner = _template(_layer_key(settings), geom.sheet_count > 1,
                                        tuple(geom.size), geom.sheet_count)
    parts = []
    handle = seed
    for layer, shape, closed in _entities(geom, settings):
        if isinstance(shape, Label):
            parts.append(_text_tags(handle, owner, layer, shape))
        else:
            parts.append(_lwpolyline_tags(handle, owner, layer, shape, closed))
        handle += 1
    old = f"$HANDSEED\n  5\n{seed:X}\n"
    if old not in head:                        # pragma: no cover - ezdxf's header layout
        raise FabplanError("the empty DXF sheet has no $HANDSEED to continue")
    return head.replace(old, f"$HANDSEED\n  5\n{handle:X}\n") + "".join(parts) + tail


def geometry_drawing(geom: SheetGeometry, settings: "StripSettings") -> SheetDrawing:
    """What a sheet file written by `sheet_dxf_text` holds, from its entities (for
    `check_drawing` before it is written)."""
    cut, slit = (str(settings.layers[k][0]) for k in ("cut", "slit"))
    outlines, closed_o, slits, closed_s, polylines = [], [], [], [], []
    engravings = 0
    for layer, shape, closed in _entities(geom, settings):
        if isinstance(shape, Label):
            engravings += 1
            continue
        rows = shape if shape.shape[1] == 3 else np.column_stack([shape, np.zeros(len(shape))])
        polylines.append((rows, closed, layer))
        if layer == cut:
            outlines.append(rows)
            closed_o.append(closed)
        elif layer == slit:
            slits.append(shape[:, :2])
            closed_s.append(closed)
        elif layer != SHEET_LAYER[0]:
            engravings += 1
    return SheetDrawing(outlines=outlines, outline_closed=closed_o, slits=slits,
                        slit_closed=closed_s, engravings=engravings, insunits=4,
                        version="AC1024", audit_errors=0, recover_errors=0, polylines=polylines)


def sheet_document(layout: "Nesting", sheets: list, settings: "StripSettings") -> Drawing:
    """An ezdxf document with the given sheets, side by side when there are several.

    Parameters
    ----------
    layout : the nesting result.
    sheets : list of Sheet to draw; sheet k sits at x = k (width + `SHEET_GAP_MM`).
    settings : layers and label style.
    """
    return geometry_document(sheet_geometry(layout, sheets, settings), settings)


def dxf_bytes(doc: Drawing) -> bytes:
    """The bytes of an ASCII DXF file of `doc`, as ``doc.saveas`` writes them."""
    stream = io.StringIO()
    doc.write(stream)
    return doc.encode(stream.getvalue())


def write_sheet_file(geom: SheetGeometry, settings: "StripSettings",
                     path: str | os.PathLike) -> str:
    """Build, check and write one sheet file; return the SHA-256 of its bytes.

    The entities are checked as written (`geometry_drawing`, `check_drawing`: closed
    outlines inside the sheet and apart, no zero-length or duplicate segments), then the
    text (`sheet_dxf_text`) is written, and the bytes on disk are hashed again and
    compared with those written, which stands in for reading the whole file back
    (`fabplan.fabricate.strips.strip_plan.write_plan` reads one sheet back with ezdxf and audits it).

    Raises
    ------
    FabplanError
        When a check fails or the file on disk differs from the bytes written.
    """
    path = Path(path)
    check_drawing(geometry_drawing(geom, settings), settings, geom.sheet_count, name=path.name)
    data = sheet_dxf_text(geom, settings).encode("utf-8")
    digest = hashlib.sha256(data).hexdigest()
    path.write_bytes(data)
    if hashlib.sha256(path.read_bytes()).hexdigest() != digest:
        raise FabplanError(f"{path.name}: the file on disk differs from the bytes written; "
                           "check the disk and write the plan again")
    return digest


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
    polylines : without a document, every polyline as (rows ``x, y, bulge``, closed,
        layer) for the segment check.
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
    polylines: list | None = None


def _lwpolylines(layout: BaseLayout) -> Iterator[LWPolyline]:
    """The LWPOLYLINE entities of a layout, typed as such."""
    for e in layout.query("LWPOLYLINE"):
        if isinstance(e, LWPolyline):
            yield e


def sheet_drawing(doc: Drawing, layers: dict, *, audit_errors: int = 0,
                  recover_errors: int = 0) -> SheetDrawing:
    """What a sheet document holds, in memory or read from a file.

    Parameters
    ----------
    doc : the document.
    layers : kind -> (name, colour), as in `StripSettings.layers`.
    audit_errors, recover_errors : the error counts to record.
    """
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
    return SheetDrawing(outlines=outlines, outline_closed=closed_o, slits=slits,
                        slit_closed=closed_s, engravings=engravings,
                        insunits=int(doc.header.get("$INSUNITS", 0)), version=doc.dxfversion,
                        audit_errors=audit_errors, recover_errors=recover_errors, doc=doc)


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
    return sheet_drawing(doc, layers, audit_errors=len(auditor.errors),
                         recover_errors=recover_errors)


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
    return polyline_problems([(np.array(list(e.get_points("xyb")), dtype=np.float64),
                               bool(e.closed), e.dxf.layer) for e in _lwpolylines(doc.modelspace())])


def polyline_problems(polylines: list) -> list:
    """`segment_problems` of polylines given as (rows (m, 3) ``x, y, bulge``, closed,
    layer)."""
    starts, ends, bulges, layers = [], [], [], []
    for pts, closed, layer in polylines:
        if len(pts) < 2:
            continue
        nxt = np.roll(pts, -1, axis=0)
        count = len(pts) if closed else len(pts) - 1
        starts.append(pts[:count, :2])
        ends.append(nxt[:count, :2])
        bulges.append(pts[:count, 2])
        layers += [layer] * count
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


def check_drawing(d: SheetDrawing, settings: "StripSettings", sheet_count: int = 1, *,
                  name: str = "sheet") -> SheetDrawing:
    """Check a sheet as a cutter would need it; `name` names it in the messages.

    Checks: R2010, $INSUNITS 4, no audit errors, closed cut and slit polylines, outlines
    inside their sheet and `spacing_mm` apart, no zero-length or duplicate segments.

    Raises
    ------
    FabplanError
        Naming the file and the first failed check.
    """
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
    problems = (segment_problems(d.doc) if d.doc is not None else
                polyline_problems(d.polylines) if d.polylines is not None else [])
    if problems:
        raise FabplanError(f"{name}: {problems[0]}")
    return d


def check_document(doc: Drawing, settings: "StripSettings", sheet_count: int = 1, *,
                   name: str = "sheet") -> SheetDrawing:
    """Audit a sheet document in memory (``doc.audit()``) and check it (`check_drawing`).

    Raises
    ------
    FabplanError
        Naming `name` and the first failed check.
    """
    auditor = doc.audit()
    d = sheet_drawing(doc, settings.layers, audit_errors=len(auditor.errors))
    return check_drawing(d, settings, sheet_count, name=name)


def check_sheet(path: str | os.PathLike, settings: "StripSettings", sheet_count: int = 1) -> SheetDrawing:
    """Read a written sheet file back with ezdxf and check it (`check_drawing`).

    Raises
    ------
    FabplanError
        Naming the file and the first failed check.
    """
    d = read_sheet(path, settings.layers, recover_too=False)
    return check_drawing(d, settings, sheet_count, name=Path(path).name)


def preview_png(doc, path, size: tuple, *, title: str = "") -> None:
    """Draw a sheet document's entities as they are in the file (PNG, `_draw_preview`).

    Polylines are flattened from their bulges and drawn in their layer's colour, TEXT at
    its insertion point; the sheet's outline is drawn in grey.
    """
    from ezdxf.colors import aci2rgb

    colours = {layer.dxf.name: np.array(aci2rgb(layer.color)) / 255 for layer in doc.layers}
    lines, cols, texts = [], [], []
    for e in doc.modelspace():
        colour = colours.get(e.dxf.layer, np.zeros(3))
        if e.dxftype() == "LWPOLYLINE":
            rows = np.array(list(e.get_points("xyb")), dtype=np.float64)
            lines.append(_preview_line(rows, bool(e.closed)))
            cols.append(colour)
        elif e.dxftype() == "TEXT":
            at = e.dxf.align_point if e.dxf.hasattr("align_point") else e.dxf.insert
            texts.append((at.x, at.y, e.dxf.text, e.dxf.rotation, e.dxf.height, colour))
    _draw_preview(lines, cols, texts, size, path, title)


def geometry_preview_png(geom: SheetGeometry, settings: "StripSettings", path, *,
                         title: str = "") -> None:
    """Draw a sheet file's entities from their arrays, as `preview_png` draws the document
    (the same picture, without building or reading the document)."""
    from ezdxf.colors import aci2rgb

    colours = {kind: np.array(aci2rgb(int(settings.layers[kind][1]))) / 255
               for kind in ("cut", "slit", "engrave")}
    colours["sheet"] = np.array(aci2rgb(SHEET_LAYER[1])) / 255
    lines, cols, texts = [], [], []
    for kind, shape, closed in zip(geom.layers, geom.shapes, geom.closed, strict=True):
        if isinstance(shape, Label):
            if settings.labels == "text":
                texts.append((shape.position[0], shape.position[1], shape.text, shape.angle_deg,
                              shape.height, colours[kind]))
                continue
            strokes, shut = label_polylines(shape, settings.labels)
            lines += [_preview_line(P, shut) for P in strokes]
            cols += [colours[kind]] * len(strokes)
        else:
            lines.append(_preview_line(shape, closed))
            cols.append(colours[kind])
    _draw_preview(lines, cols, texts, geom.size, path, title)


def _preview_line(rows: np.ndarray, closed: bool) -> np.ndarray:
    """(p, 2) points drawing a polyline, arcs flattened to 0.2 mm, closed ones closed."""
    if rows.shape[1] == 3 and np.any(np.abs(rows[:, 2]) >= 1e-12):
        P = bulge_points(rows, closed=closed, tolerance_mm=0.2)
    else:
        P = rows[:, :2]
    return np.vstack([P, P[:1]]) if closed else P


#: the preview's long side (pixels)
PREVIEW_PIXELS = 1540


def _draw_preview(lines: list, colours: list, texts: list, size: tuple, path, title: str) -> None:
    """Rasterize a sheet: the polylines in their colours, the texts, the sheet in grey
    (PNG, `PREVIEW_PIXELS` on the long side).

    Pillow draws the polylines one pixel wide straight into a palette image, as a CAD
    program shows a drawing: a sheet of 500 strips takes a few milliseconds, where
    matplotlib's artists took 60-120."""
    from PIL import Image, ImageDraw, ImageFont

    W, H = size
    scale = PREVIEW_PIXELS / max(W, H)
    margin = 0.01 * max(W, H) * scale
    head = 24 if title else 0
    width = int(round(W * scale + 2 * margin))
    height = int(round(H * scale + 2 * margin)) + head
    rgb = [tuple(int(round(255 * c)) for c in colour) for colour in colours]
    text_rgb = [tuple(int(round(255 * c)) for c in t[5]) for t in texts]
    palette = list(dict.fromkeys([(255, 255, 255), (0, 0, 0), (153, 153, 153), *rgb, *text_rgb]))
    index = {colour: k for k, colour in enumerate(palette)}
    image = Image.new("P", (width, height), 0)
    image.putpalette([c for colour in palette for c in colour])
    draw = ImageDraw.Draw(image)

    def pixels(P: np.ndarray) -> list:
        P = np.asarray(P, dtype=np.float64)
        return np.column_stack([margin + P[:, 0] * scale,
                                height - margin - P[:, 1] * scale]).ravel().tolist()   # y up

    draw.line(pixels(np.array([[0, 0], [W, 0], [W, H], [0, H], [0, 0]])), fill=index[(153, 153, 153)])
    for P, colour in zip(lines, rgb, strict=True):
        if len(P) >= 2:
            draw.line(pixels(P), fill=index[colour])
    for (x, y, text, rotation, text_height, _), colour in zip(texts, text_rgb, strict=True):
        font = ImageFont.load_default(size=max(8.0, text_height * scale))
        box = draw.textbbox((0, 0), text, font=font)
        label = Image.new("L", (int(math.ceil(box[2] - box[0])) + 2,
                                int(math.ceil(box[3] - box[1])) + 2), 0)
        ImageDraw.Draw(label).text((-box[0] + 1, -box[1] + 1), text, font=font, fill=255)
        label = label.rotate(rotation, expand=True).point(lambda v: 255 if v >= 48 else 0)
        cx, cy = pixels(np.array([[x, y]]))
        image.paste(index[colour], (int(cx - label.width / 2), int(cy - label.height / 2),
                                    int(cx - label.width / 2) + label.width,
                                    int(cy - label.height / 2) + label.height), label)
    if title:
        draw.text((width / 2, 4), title, fill=index[(0, 0, 0)], anchor="ma",
                  font=ImageFont.load_default(size=14))
    image.save(path, format="PNG", compress_level=3)
