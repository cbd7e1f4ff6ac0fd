"""Parts cut from the strips, and their placement on sheets.

A strip longer than a sheet is split into parts between crossings: each split lies in a
bay between two slits (several in one bay when the bay is longer than a sheet), with a
splice (an overlap or a step lap of `splice_length_mm`) that keeps clear of the slits;
both parts carry the splice's engraved marks and number. Each part is as long as the sheet
allows. Parts keep the local frame of their strip's development (millimetres, the strip's
top to the left of increasing arc length).

Nesting is a skyline placement on a grid of `NESTING_RESOLUTION_MM` cells: every part
lies with its chord (or principal axis) along the sheet's long side, upright or turned
half a turn, and is dropped to the lowest position its lower envelope allows over the
sheets' upper skyline, dilated by the spacing; parts go longest first, each to the first
sheet it fits. Congruent circular parts therefore stack inside one another like nested
arcs. The placement is then checked exactly with shapely: every part inside the sheet's
margin, no two closer than the spacing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely
from scipy.ndimage import maximum_filter1d
from shapely import affinity
from shapely.geometry import Polygon

from ...errors import FabplanError, InputError
from .bulges import bulge_polygon

if TYPE_CHECKING:  # pragma: no cover
    from .strip_set import StripSet, StripSettings

__all__ = [
    "NESTING_RESOLUTION_MM",
    "Label",
    "Part",
    "Placement",
    "Sheet",
    "Nesting",
    "make_parts",
    "nest_parts",
    "congruence",
    "part_congruence_mm",
    "check_nesting",
    "placed_footprints",
]

NESTING_RESOLUTION_MM = 2.0
"""Cell width of the skyline grid; envelopes are taken conservatively per cell."""


@dataclass(frozen=True)
class Label:
    """Text to engrave: centred at `position`, baseline at `angle_deg`, cap height `height`."""

    text: str
    position: tuple[float, float]
    angle_deg: float
    height: float
    kind: str


@dataclass
class Part:
    """One piece of material: a whole strip or a part of a split strip (mm, strip frame).

    Attributes
    ----------
    id : e.g. ``A07`` (whole strip) or ``A07-2`` (its second part).
    strip : index of the strip in the StripSet.
    index, count : number of this part (1-based) and parts of its strip.
    s_range : (s0, s1) arc lengths covered along the strip's reference curve, ends and
        splices included.
    outline : (m, 3) float rows ``x, y, bulge`` of the closed, counter-clockwise outline.
    slits : list of (4, 2) float closed rectangles, counter-clockwise.
    slit_crossings : list of (crossing id, arc length, ``"top"`` or ``"bottom"``).
    marks : list of (k, 2) float open polylines to engrave (splice lines, orientation arrow).
    labels : list of Label.
    splices : list of (splice id, zone start, zone end) along the strip.
    chord_deg : direction of the chord of the part's reference curve (the frame in which
        the sheet fit was checked).
    """

    id: str
    strip: int
    index: int
    count: int
    s_range: tuple[float, float]
    outline: np.ndarray
    slits: list
    slit_crossings: list
    marks: list
    labels: list
    splices: list = field(default_factory=list)
    chord_deg: float = 0.0

    @property
    def polygon(self) -> Polygon:
        """The outline as a shapely polygon (arcs flattened)."""
        if "_polygon" not in self.__dict__:
            self.__dict__["_polygon"] = bulge_polygon(self.outline)
        return self.__dict__["_polygon"]

    @property
    def footprint(self):
        """Outline and slit cuts together: the area the part's cuts touch."""
        if "_footprint" not in self.__dict__:
            self.__dict__["_footprint"] = shapely.union_all(
                [self.polygon] + [Polygon(s) for s in self.slits])
        return self.__dict__["_footprint"]

    @property
    def area_mm2(self) -> float:
        """Material area: outline minus slits."""
        slits = shapely.union_all([Polygon(s) for s in self.slits]) if self.slits else None
        return float(self.polygon.area - (self.polygon.intersection(slits).area if slits else 0.0))


# ---------------------------------------------------------------------- splitting
def _usable_sheet(settings: "StripSettings") -> tuple[float, float]:
    """(long, short) usable sheet lengths inside the margin (mm)."""
    w, h = settings.sheet_mm
    return max(w, h) - 2 * settings.margin_mm, min(w, h) - 2 * settings.margin_mm


class _Band:
    """Dense samples of both edges of a strip's band (half-width `half`) for extent tests."""

    def __init__(self, curve, s0: float, s1: float, half: float):
        radius = np.min(np.abs(curve.radius)) if len(curve.radius) else np.inf
        step = max(min(25.0, 0.05 * radius) if np.isfinite(radius) else 25.0, 0.5)
        s = np.arange(s0, s1, step)
        self.s = np.unique(np.concatenate([s, [s1], curve.s[(curve.s > s0) & (curve.s < s1)]]))
        self.curve, self.half = curve, half
        self.low = curve.points(self.s, -half)[0]
        self.high = curve.points(self.s, half)[0]

    def extent(self, a: float, b: float) -> tuple[float, float]:
        """Length along the chord and height across it of the band between arc lengths
        a and b (a rectangle in the chord's frame that holds the band there)."""
        i, j = np.searchsorted(self.s, [a, b])
        h = self.half
        ends, tan = self.curve.points(np.array([a, b, a, b, a, b]), np.array([-h, -h, h, h, 0, 0]))
        pts = np.concatenate([self.low[i:j], self.high[i:j], ends[:4]])
        d = ends[5] - ends[4]
        n = np.linalg.norm(d)
        d = d / n if n > 1e-9 else tan[4]
        x = pts @ d
        y = pts @ np.array([-d[1], d[0]])
        return float(x.max() - x.min()), float(y.max() - y.min())


def _split_strip(strip, node_s: np.ndarray, settings: "StripSettings") -> list:
    """Split points (splice centres) so that every part fits the usable sheet.

    Returns
    -------
    list of float, increasing arc lengths of the splice centres (empty: one part).

    Raises
    ------
    InputError
        When no part beyond the previous split fits the sheet.
    """
    curve = strip.curve
    h = settings.height_mm
    e0, e1 = strip.end_extensions_mm(settings)
    splice = settings.splice_mm
    kerf = settings.kerf_mm
    long_side, short_side = _usable_sheet(settings)
    half = h / 2 + settings.slit_overcut_mm + kerf / 2
    # round caps at free ends; a strip is cut square against a boundary member
    cap0, cap1 = (h / 2 if settings.end == "round" and not strip.at_member(k) else 0.0
                  for k in (0, 1))
    length = curve.length
    slack = 1.0  # mm kept free of the sheet's margin for rounding

    band = _Band(curve, -e0 - splice, length + e1 + splice, half)

    def fits(a: float, b: float, end_caps: float) -> bool:
        along, across = band.extent(a, b)
        return along + end_caps + kerf <= long_side - slack and across <= short_side - slack

    if 2 * half > short_side - slack:
        raise InputError(f"the sheet {settings.sheet_mm[0]:g}x{settings.sheet_mm[1]:g} mm is too "
                         f"small: a strip {2 * half:.0f} mm high (height, slit overcut and kerf) "
                         f"does not fit inside its {settings.margin_mm:g} mm margin")
    a = -e0
    if fits(a, length + e1, cap0 + cap1):
        return []
    # splice zones must keep clear of every slit and of the strip's end nodes
    clear = splice / 2 + settings.slit_width_mm / 2 + max(settings.text_height_mm, 2.0)
    # ... and of the strip's cut ends (set back at a boundary member)
    allowed = [(max(lo, -e0) + clear, min(hi, length + e1) - clear)
               for lo, hi in zip(node_s[:-1], node_s[1:], strict=True)
               if min(hi, length + e1) - max(lo, -e0) > 2 * clear]
    allowed = [(lo, hi) for lo, hi in allowed if hi >= lo]
    if not allowed:
        raise InputError(
            f"strip {strip.id} ({length:.0f} mm) is longer than the sheet and no bay between its "
            f"crossings is long enough for a {splice:g} mm splice: use a larger --sheet or a "
            "shorter --splice-length")
    splits: list[float] = []
    while not fits(a, length + e1, cap1 + (0 if splits else cap0)):
        best = _farthest_split(fits, a, allowed, splice, cap0 if not splits else 0.0)
        if best is None:
            raise InputError(
                f"the sheet {settings.sheet_mm[0]:g}x{settings.sheet_mm[1]:g} mm is too small for "
                f"strip {strip.id}: no part between two of its crossings fits inside the margin; "
                "use a larger --sheet or a smaller --spacing/--margin")
        splits.append(best)
        a = best - splice / 2
    return splits


def _farthest_split(fits: Callable[[float, float, float], bool], a: float, allowed: list,
                    splice: float, caps: float) -> float | None:
    """The farthest splice centre (arc length, mm) of the `allowed` intervals at which the
    part starting at `a` still `fits` the sheet (with `caps` mm of end caps), within half a
    millimetre; None when no part beyond `a` fits."""
    # intervals beyond the part's start; the part grows with the split point, so the
    # last interval whose start still fits is found by bisection
    usable = [(max(lo, a + splice / 2 + 1.0), hi) for lo, hi in allowed]
    usable = [(lo, hi) for lo, hi in usable if lo <= hi]
    first, last = 0, len(usable)
    while first < last:
        mid = (first + last) // 2
        if fits(a, usable[mid][0] + splice / 2, caps):
            first = mid + 1
        else:
            last = mid
    if first == 0:
        return None
    lo, hi = usable[first - 1]
    if fits(a, hi + splice / 2, caps):
        return hi
    good, bad = lo, hi
    while bad - good > 0.5:
        mid = (good + bad) / 2
        if fits(a, mid + splice / 2, caps):
            good = mid
        else:
            bad = mid
    return good


# ---------------------------------------------------------------------- part geometry
def _side_rows(curve, segments: list, *, reverse: bool) -> list:
    """Rows (x, y, bulge) along a boundary made of (s0, s1, offset) segments in increasing
    s; straight steps join segments of different offsets. Reversed for the top side."""
    paths = [curve.path(s0, s1, off) for s0, s1, off in segments if s1 - s0 > 1e-9]
    if reverse:
        paths = [_reverse_path(p) for p in paths[::-1]]
    rows = []
    for p in paths:
        rows.extend(p.tolist())  # the last row's bulge 0 makes the step to the next path
    return rows


def _reverse_path(rows: np.ndarray) -> np.ndarray:
    out = rows[::-1].copy()
    out[:-1, 2] = -rows[:-1, 2][::-1]
    out[-1, 2] = 0.0
    return out


def _clean_outline(rows: list) -> np.ndarray:
    """Drop rows that repeat the next point (zero-length segments), keeping the bulge of the
    surviving segment, and merge collinear straight runs."""
    R = np.array(rows, dtype=np.float64)
    changed = True
    while changed and len(R) > 3:
        changed = False
        nxt = np.roll(R[:, :2], -1, axis=0)
        short = np.linalg.norm(nxt - R[:, :2], axis=1) < 1e-6
        if short.any():
            R = R[~short]
            changed = True
            continue
        prev = np.roll(R, 1, axis=0)
        d1 = R[:, :2] - prev[:, :2]
        d2 = np.roll(R[:, :2], -1, axis=0) - R[:, :2]
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        straight = (np.abs(prev[:, 2]) < 1e-12) & (np.abs(R[:, 2]) < 1e-12)
        collinear = straight & (np.abs(cross) < 1e-9 * np.linalg.norm(d1, axis=1)
                                * np.linalg.norm(d2, axis=1)) & (np.einsum("ij,ij->i", d1, d2) > 0)
        if collinear.any():
            R = np.delete(R, np.flatnonzero(collinear)[0], axis=0)
            changed = True
    return R


def _text_width(text: str, height: float) -> float:
    """Advance width of stroke text (see `fabplan.dxf`): 5/6 of the height per character."""
    return len(text) * height * 5 / 6 - height / 6


def _part_geometry(strip, strip_crossings, settings, a: float, b: float,
                   start_kind: str, end_kind: str, splice_ids: tuple) -> dict:
    """Outline, slits, labels and marks of the part of `strip` between arc lengths a and b.

    start_kind / end_kind : ``"end"`` (free strip end), ``"member"`` (strip end cut square
    against a boundary member), ``"overlap"``, ``"lap-top"`` (this part keeps the top half
    over the splice zone at that end) or ``"lap-bottom"``.
    """
    curve = strip.curve
    h = settings.height_mm
    bottom_segments, top_segments, marks, labels, splices = _splice_zones(
        curve, settings, a, b, (start_kind, end_kind), splice_ids)
    cap = 1.0 if settings.end == "round" else 0.0
    rows = _side_rows(curve, bottom_segments, reverse=False)
    rows[-1][2] = cap if end_kind == "end" else 0.0
    rows += _side_rows(curve, top_segments, reverse=True)
    rows[-1][2] = cap if start_kind == "end" else 0.0
    outline = _clean_outline(rows)
    slits, slit_info, feature_s, numbers = _part_slits(strip, strip_crossings, settings, a, b)
    labels += numbers
    for _, z0, z1 in splices:
        feature_s.append((z0, z1))
    # the part label in the widest free stretch along the mid-line, with an up arrow
    feature_s.sort()
    free, cursor = [], a + (h / 2 if settings.end == "round" and start_kind == "end" else 0.0)
    for lo, hi in feature_s:
        if lo > cursor:
            free.append((cursor, lo))
        cursor = max(cursor, hi)
    end_limit = b - (h / 2 if settings.end == "round" and end_kind == "end" else 0.0)
    if end_limit > cursor:
        free.append((cursor, end_limit))
    lo, hi = max(free, key=lambda f: f[1] - f[0]) if free else (a, b)
    return dict(outline=outline, slits=slits, slit_info=slit_info, marks=marks, labels=labels,
                splices=splices, label_span=(lo, hi), label_size=min(settings.text_height_mm, 0.4 * h))


def _splice_zones(curve, settings, a: float, b: float, kinds: tuple[str, str], splice_ids: tuple
                  ) -> tuple[list, list, list, list, list]:
    """The bottom and top sides ``[s0, s1, offset]`` of the part between arc lengths a and b
    (kerf included; a step lap steps one of them at a splice), and the splice zones at its
    ends whose `kinds` (start, end) are splices: their engraved marks, labels and
    ``(id, s0, s1)`` zones."""
    h = settings.height_mm
    k2 = settings.kerf_mm / 2
    splice = settings.splice_mm
    s0, s1 = a - k2, b + k2
    bottom_segments = [[s0, s1, -h / 2 - k2]]
    top_segments = [[s0, s1, h / 2 + k2]]
    marks, labels, splices = [], [], []
    th = settings.text_height_mm
    for where, kind, sid in (("start", kinds[0], splice_ids[0]), ("end", kinds[1], splice_ids[1])):
        if kind in ("end", "member"):
            continue
        zone = (a, a + splice) if where == "start" else (b - splice, b)
        splices.append((sid, zone[0], zone[1]))
        mid = (zone[0] + zone[1]) / 2
        if kind == "overlap":
            # the other part ends at the far side of the zone: engrave where it sits
            s_mark = zone[1] if where == "start" else zone[0]
            marks.append(np.array([curve.point(s_mark, -h / 2 + 0.5)[0],
                                   curve.point(s_mark, h / 2 - 0.5)[0]]))
            level = 0.0
        elif kind == "lap-top":  # keep the top half over the zone: the bottom steps up
            # the step face looks away from the full-height material: kerf moves it that way
            step = (zone[1] - k2) if where == "start" else (zone[0] + k2)
            seg = bottom_segments[0] if where == "start" else bottom_segments[-1]
            if where == "start":
                bottom_segments.insert(0, [s0, step, -k2])
                seg[0] = step
            else:
                bottom_segments.append([step, s1, -k2])
                seg[1] = step
            level = h / 4
        else:  # lap-bottom: keep the bottom half, the top steps down
            step = (zone[1] - k2) if where == "start" else (zone[0] + k2)
            seg = top_segments[0] if where == "start" else top_segments[-1]
            if where == "start":
                top_segments.insert(0, [s0, step, k2])
                seg[0] = step
            else:
                top_segments.append([step, s1, k2])
                seg[1] = step
            level = -h / 4
        text = f"S{sid}"
        size = min(0.75 * th, 0.3 * h)
        p, t = curve.point(mid, level)
        labels.append(Label(text, (float(p[0]), float(p[1])),
                            math.degrees(math.atan2(t[1], t[0])), size, "splice"))
    return bottom_segments, top_segments, marks, labels, splices


def _part_slits(strip, strip_crossings, settings, a: float, b: float
                ) -> tuple[list, list, list, list]:
    """The slits at the crossings of `strip` between arc lengths a and b: their (4, 2)
    rectangles (mm), ``(crossing, s, side)`` and the spans ``(s0, s1)`` they and their
    numbers take along the part, and the numbers' labels."""
    curve = strip.curve
    h = settings.height_mm
    k2 = settings.kerf_mm / 2
    th = settings.text_height_mm
    w = settings.slit_width_mm - settings.kerf_mm
    slits, slit_info, labels = [], [], []
    feature_s = []
    for crossing, side in strip_crossings:
        i = crossing.nodes[side]
        s = strip.s_mm[i]
        if not (a <= s <= b):
            continue
        up = strip.family == 0
        axis = strip.axis[i] * (1 if up else -1)
        node = curve.nodes[i]
        _, tan = curve.point(s)
        normal = np.array([-tan[1], tan[0]]) * (1 if up else -1)
        depth = (h / 2 + k2) / max(float(axis @ normal), 0.5) + settings.slit_overcut_mm
        perp = np.array([-axis[1], axis[0]])
        base = node + k2 * axis
        mouth = base + (depth - k2) * axis
        rect = np.array([base - perp * w / 2, mouth - perp * w / 2,
                         mouth + perp * w / 2, base + perp * w / 2])
        if _signed_area(rect) < 0:
            rect = rect[::-1]
        slits.append(rect)
        slit_info.append((crossing.id, float(s), "top" if up else "bottom"))
        # crossing number beside the slit, in the slit's half
        text = f"X{crossing.id}"
        size = min(0.75 * th, 0.3 * h)
        offset_s = w / 2 + 0.4 * size + _text_width(text, size) / 2
        s_label = s + offset_s if s + offset_s + _text_width(text, size) / 2 < b else s - offset_s
        p, t = curve.point(s_label, h / 4 if up else -h / 4)
        labels.append(Label(text, (float(p[0]), float(p[1])),
                            math.degrees(math.atan2(t[1], t[0])), size, "crossing"))
        feature_s.append((s - offset_s - _text_width(text, size) / 2 - w,
                          s + offset_s + _text_width(text, size) / 2 + w))
    return slits, slit_info, feature_s, labels


def _signed_area(P: np.ndarray) -> float:
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _place_part_label(curve, part_id: str, span: tuple, size: float, h: float) -> tuple:
    """Label and orientation arrow centred in the free stretch `span` of the mid-line."""
    lo, hi = span
    width = _text_width(part_id, size) + 1.5 * size  # text, gap, arrow
    room = hi - lo - 2 * size
    if room < width:
        size = max(2.0, size * max(room, 0) / width)
        width = _text_width(part_id, size) + 1.5 * size
    centre = (lo + hi) / 2
    s_text = centre - width / 2 + _text_width(part_id, size) / 2
    p, t = curve.point(s_text, 0.0)
    label = Label(part_id, (float(p[0]), float(p[1])), math.degrees(math.atan2(t[1], t[0])),
                  size, "strip")
    # the arrow points to the top of the strip (the side the surface normal points to)
    s_arrow = centre + width / 2 - 0.25 * size
    base, _ = curve.point(s_arrow, -size / 2)
    tip, _ = curve.point(s_arrow, size / 2)
    left, _ = curve.point(s_arrow - 0.3 * size, 0.2 * size)
    right, _ = curve.point(s_arrow + 0.3 * size, 0.2 * size)
    arrow = [np.array([base, tip]), np.array([left, tip, right])]
    return label, arrow


def make_parts(strips: "StripSet", settings: "StripSettings") -> list[Part]:
    """Split every strip into parts that fit the sheet and build their cut geometry.

    Parameters
    ----------
    strips : the lamellas with their crossings.
    settings : sheet, splice, end and label options.

    Returns
    -------
    list of Part, in strip order.

    Raises
    ------
    InputError
        When the sheet is too small for some part, or slits come too close to each other.
    """
    parts = []
    w = settings.slit_width_mm
    splice_counter = 0
    for k, strip in enumerate(strips.strips):
        crossings = strips.crossings_of_strip[k]
        node_s = strip.s_mm
        cs = np.sort([node_s[c.nodes[side]] for c, side in crossings])
        if len(cs) > 1 and np.diff(cs).min() < w + 2.0:
            raise InputError(f"strip {strip.id}: two crossings are {np.diff(cs).min():.1f} mm "
                             f"apart, too close for {w:g} mm slits")
        splits = _split_strip(strip, node_s, settings)
        e0, e1 = strip.end_extensions_mm(settings)
        bounds = [-e0] + [c for c in splits] + [strip.curve.length + e1]
        first_kind, last_kind = ("member" if strip.at_member(k) else "end" for k in (0, 1))
        count = len(splits) + 1
        first_splice = splice_counter + 1
        splice_counter += len(splits)
        for j in range(count):
            a = bounds[j] if j == 0 else bounds[j] - settings.splice_mm / 2
            b = bounds[j + 1] if j == count - 1 else bounds[j + 1] + settings.splice_mm / 2
            if settings.splice == "overlap":
                start_kind = first_kind if j == 0 else "overlap"
                end_kind = last_kind if j == count - 1 else "overlap"
            else:
                start_kind = first_kind if j == 0 else "lap-bottom"
                end_kind = last_kind if j == count - 1 else "lap-top"
            ids = (first_splice + j - 1, first_splice + j)
            g = _part_geometry(strip, crossings, settings, a, b, start_kind, end_kind, ids)
            part_id = strip.id if count == 1 else f"{strip.id}-{j + 1}"
            label, arrow = _place_part_label(strip.curve, part_id, g["label_span"],
                                             g["label_size"], settings.height_mm)
            ends = strip.curve.points(np.array([a, b]))[0]
            chord = ends[1] - ends[0]
            part = Part(
                id=part_id, strip=k, index=j + 1, count=count, s_range=(a, b),
                outline=g["outline"], slits=g["slits"], slit_crossings=g["slit_info"],
                marks=g["marks"] + arrow, labels=[label] + g["labels"], splices=g["splices"],
                chord_deg=math.degrees(math.atan2(chord[1], chord[0])))
            if not part.polygon.is_valid:
                raise InputError(f"part {part_id}: its outline crosses itself (the strip turns "
                                 f"too sharply at a node for a {settings.height_mm:g} mm height)")
            parts.append(part)
    return parts


def congruence(parts: list[Part], strips: "StripSet") -> dict:
    """Whether all parts are pieces of one annulus (or all straight) within the tolerance.

    The deviation of a part from the common radius ``R`` (the median arc radius) is bounded
    by ``L^2 / 8 |1/r - 1/R|`` over each of its arc runs of length ``L`` and radius ``r``
    (`part_congruence_mm`).

    Returns
    -------
    dict with ``congruent`` (bool), ``common_radius_mm`` (inf when straight),
    ``congruence_deviation_mm`` (the largest bound over all parts) and
    ``parts_not_congruent`` (how many parts exceed the tolerance).
    """
    tol = strips.settings.tolerance_mm
    common, deviation = part_congruence_mm(parts, strips)
    worst = float(deviation.max()) if deviation.size else 0.0
    return {"congruent": bool(worst <= tol), "common_radius_mm": common,
            "congruence_deviation_mm": worst,
            "parts_not_congruent": int(np.count_nonzero(deviation > tol))}


def part_congruence_mm(parts: list[Part], strips: "StripSet") -> tuple[float, np.ndarray]:
    """The common arc radius of the strips and how far each part differs from it.

    Returns
    -------
    common_radius_mm : float, the median |radius| of the fitted arc runs (inf when every
        strip is straight).
    deviation_mm : (len(parts),) float, the largest ``L^2 / 8 |1/r - 1/R|`` over the arc runs
        of each part (the part's length ``L`` in a run of radius ``r``, ``R`` the common
        radius): how far the part's reference curve leaves the common arc (mm).
    """
    radii = np.array([abs(r) for s in strips.strips for r in s.arc_radii_mm])
    finite = radii[np.isfinite(radii)]
    common = float(np.median(finite)) if finite.size else math.inf
    k_common = 0.0 if not math.isfinite(common) else 1 / common
    deviation = np.zeros(len(parts))
    for i, part in enumerate(parts):
        strip = strips.strips[part.strip]
        a, b = part.s_range
        for run in strip.runs:
            lo, hi = strip.s_mm[run.start], strip.s_mm[run.stop]
            L = max(0.0, min(b, hi) - max(a, lo))
            if L <= 0:
                continue
            k_run = 0.0 if not math.isfinite(run.radius_mm) else 1 / abs(run.radius_mm)
            deviation[i] = max(deviation[i], L * L / 8 * abs(k_run - k_common))
    return common, deviation


# ---------------------------------------------------------------------- nesting
@dataclass(frozen=True)
class Placement:
    """A part on a sheet: sheet point = R(angle) @ local point + offset (mm)."""

    part: int
    angle_deg: float
    offset: tuple[float, float]

    def matrix(self) -> np.ndarray:
        """(2, 3) affine matrix ``[R | t]``."""
        c, s = math.cos(math.radians(self.angle_deg)), math.sin(math.radians(self.angle_deg))
        return np.array([[c, -s, self.offset[0]], [s, c, self.offset[1]]])

    def apply(self, P: np.ndarray) -> np.ndarray:
        """Transform (k, 2) local points to sheet coordinates."""
        M = self.matrix()
        return P @ M[:, :2].T + M[:, 2]


@dataclass
class Sheet:
    """One sheet of `size` (width, height) mm with its placements, origin at a corner."""

    index: int
    size: tuple[float, float]
    placements: list[Placement]


@dataclass
class Nesting:
    """Parts on sheets, with the measured material use."""

    sheets: list[Sheet]
    parts: list[Part]
    settings: StripSettings

    def summary(self) -> dict:
        sheet_area = self.settings.sheet_mm[0] * self.settings.sheet_mm[1]
        used = [sum(self.parts[p.part].area_mm2 for p in s.placements) / sheet_area
                for s in self.sheets]
        return {"sheets": len(self.sheets), "sheet_mm": list(self.settings.sheet_mm),
                "parts": len(self.parts),
                "material_use": float(np.sum(used) / max(len(used), 1)),
                "material_use_per_sheet": [float(u) for u in used],
                "part_area_m2": float(sum(p.area_mm2 for p in self.parts) / 1e6)}


_FIT_PROBES = 16
"""Cells sampled per window to rule out places before a full measure (`_lowest_fit`)."""


@dataclass
class _Candidate:
    angle: float
    shift: np.ndarray   # local -> oriented frame translation (after rotation), min corner at 0
    lower: np.ndarray   # (nx,) lowest y per cell
    upper: np.ndarray   # (nx + 2 pad,) dilated highest y per cell
    pad: int
    height: float
    probes: np.ndarray  # cells sampled to rule out places quickly (`_lowest_fit`)


def _orientations(part: Part, spacing: float, res: float) -> list:
    """The part with its chord, or its principal axis, along x, upright and turned half a
    turn, with their cell envelopes."""
    outline = part.footprint
    coords = np.asarray(outline.exterior.coords) if outline.geom_type == "Polygon" else \
        np.concatenate([np.asarray(g.exterior.coords) for g in outline.geoms])
    # the principal axis of an arc-shaped part runs along its chord
    C = coords - coords.mean(axis=0)
    _, _, vt = np.linalg.svd(C, full_matrices=False)
    axis = vt[0]
    bases = [part.chord_deg]
    principal = math.degrees(math.atan2(axis[1], axis[0]))
    if abs((principal - part.chord_deg + 90) % 180 - 90) > 0.5:
        bases.append(principal)
    pad = int(math.ceil(spacing / res)) + 1
    out = []
    for angle in [a for base in bases for a in (-base, 180.0 - base)]:
        geom = affinity.rotate(part.footprint, angle, origin=(0, 0))
        geom = shapely.segmentize(geom, res / 2)
        polys = [geom] if geom.geom_type == "Polygon" else list(geom.geoms)
        pts = np.concatenate([np.asarray(g.exterior.coords) for g in polys])
        lo = pts.min(axis=0)
        pts = pts - lo
        nx = int(math.floor(pts[:, 0].max() / res)) + 1
        # every boundary segment spans at most two cells: credit both endpoints to both
        segs = [np.asarray(g.exterior.coords) - lo for g in polys]
        a = np.concatenate([s[:-1] for s in segs])
        b = np.concatenate([s[1:] for s in segs])
        ca = np.minimum(np.floor(a[:, 0] / res).astype(int), nx - 1)
        cb = np.minimum(np.floor(b[:, 0] / res).astype(int), nx - 1)
        ymax = np.maximum(a[:, 1], b[:, 1])
        ymin = np.minimum(a[:, 1], b[:, 1])
        upper = np.full(nx, -np.inf)
        lower = np.full(nx, np.inf)
        for c in (ca, cb):
            np.maximum.at(upper, c, ymax)
            np.minimum.at(lower, c, ymin)
        upper = np.where(np.isfinite(upper), upper, 0.0)
        lower = np.where(np.isfinite(lower), lower, upper)
        dilated = np.full(nx + 2 * pad, -np.inf)
        dilated[pad:pad + nx] = upper
        dilated = maximum_filter1d(dilated, size=2 * pad + 1, mode="constant", cval=-np.inf)
        dilated = np.where(np.isfinite(dilated), dilated + spacing, -np.inf)
        probes = np.unique(np.linspace(0, nx - 1, min(nx, _FIT_PROBES)).astype(np.intp))
        out.append(_Candidate(angle=angle, shift=-lo, lower=lower, upper=dilated, pad=pad,
                              height=float(pts[:, 1].max()), probes=probes))
    return out


def _lowest_fit(S: np.ndarray, c: _Candidate, short_side: float) -> tuple[int, float] | None:
    """The lowest place of an oriented part on a skyline, leftmost among equals.

    Parameters
    ----------
    S : (n,) float, the sheet's skyline (highest used y per cell, mm).
    c : the part in one orientation.
    short_side : usable height of the sheet (mm).

    Returns
    -------
    (x0, y0): the first cell and the height of the part's lowest point, or None when the
    part fits nowhere.
    """
    nx = len(c.lower)
    windows = np.lib.stride_tricks.sliding_window_view(S, nx)
    # a few sampled cells bound each window's lift from below: windows they rule out are
    # never measured in full, and the others give the same lift as a full measure
    bound = (windows[:, c.probes] - c.lower[c.probes]).max(axis=1)
    todo = np.flatnonzero(np.maximum(bound, 0.0) + c.height <= short_side)
    if todo.size == 0:
        return None
    y = np.maximum((windows[todo] - c.lower).max(axis=1), 0.0)
    ok = np.flatnonzero(y + c.height <= short_side)
    if ok.size == 0:
        return None
    k = ok[np.argmin(y[ok] + c.height)]
    return int(todo[k]), float(y[k])


#: fewest parts whose orientations are worth computing in several processes
PARTS_PER_PROCESS = 200


def _orientations_batch(batch: tuple) -> list:
    """`_orientations_of` of one batch ``(parts, spacing, res)``, for a worker process."""
    return _orientations_of(*batch)


def _orientations_of(parts: list, spacing: float, res: float) -> list:
    return [_orientations(p, spacing, res) for p in parts]


def _all_orientations(parts: list[Part], spacing: float, res: float, workers: int) -> list:
    """`_orientations` of every part, spread over `workers` processes when there are many
    parts (each part's are independent of the nesting)."""
    count = min(workers, len(parts) // PARTS_PER_PROCESS)
    if count <= 1:
        return _orientations_of(parts, spacing, res)
    from ...io.forked import map_in_processes

    batches = map_in_processes(_orientations_batch,
                               [(parts[k::count], spacing, res) for k in range(count)], count)
    out: list = [None] * len(parts)
    for k, batch in enumerate(batches):
        out[k::count] = batch
    return out


def nest_parts(parts: list[Part], settings: "StripSettings", *, workers: int = 1) -> Nesting:
    """Place parts on as few sheets as the skyline heuristic finds, then check exactly.

    Parameters
    ----------
    parts : list of Part.
    settings : sheet size, spacing, margin.
    workers : processes that compute the parts' orientations (the placements are the
        same whatever their number).

    Returns
    -------
    Nesting

    Raises
    ------
    InputError
        When a part does not fit an empty sheet.
    FabplanError
        When the exact check finds an overlap (a bug, never expected).
    """
    res = NESTING_RESOLUTION_MM
    long_side, short_side = _usable_sheet(settings)
    nx_sheet = int(math.floor(long_side / res))
    portrait = settings.sheet_mm[0] < settings.sheet_mm[1]
    order = sorted(range(len(parts)), key=lambda i: -parts[i].polygon.length)
    skylines: list[np.ndarray] = []
    placed: list[list] = []
    refused: list[list] = []  # per sheet: (cells, height) of parts that did not fit
    oriented = _all_orientations(parts, settings.spacing_mm, res, workers)
    for i in order:
        candidates = oriented[i]
        size = (min(len(c.lower) for c in candidates), min(c.height for c in candidates))
        best = _first_sheet_fit(skylines, refused, candidates, size, short_side, nx_sheet)
        if best is None:
            skylines.append(np.zeros(nx_sheet))
            placed.append([])
            refused.append([])
            S = skylines[-1]
            c = min(candidates, key=lambda c: c.height)
            if len(c.lower) > nx_sheet or c.height > short_side:
                raise InputError(f"part {parts[i].id} does not fit the sheet "
                                 f"{settings.sheet_mm[0]:g}x{settings.sheet_mm[1]:g} mm")
            y0 = max(float((S[:len(c.lower)] - c.lower).max()), 0.0)
            best = ((y0 + c.height, 0), len(skylines) - 1, c, 0, y0)
        _, sheet, c, x0, y0 = best
        S = skylines[sheet]
        nx = len(c.lower)
        lo, hi = x0 - c.pad, x0 + nx + c.pad
        seg = c.upper[max(0, -lo):len(c.upper) - max(0, hi - len(S))]
        S[max(lo, 0):min(hi, len(S))] = np.maximum(S[max(lo, 0):min(hi, len(S))], y0 + seg)
        placed[sheet].append((i, c.angle, c.shift + np.array([x0 * res, y0])))
    nesting = Nesting(sheets=_placed_sheets(placed, settings, portrait), parts=parts,
                      settings=settings)
    check_nesting(nesting)
    return nesting


def _first_sheet_fit(skylines: list[np.ndarray], refused: list[list], candidates: list,
                     size: tuple, short_side: float, nx_sheet: int) -> tuple | None:
    """The lowest fit of a part's oriented `candidates` on the first open sheet that takes
    it: ``((top, x0), sheet, candidate, x0, y0)`` (cells and mm), or None. A sheet that
    refuses the part of `size` (cells, height) notes it in `refused`."""
    best = None
    for sheet, S in enumerate(skylines):
        if S.min() + size[1] > short_side:
            continue
        # a part at least as long and high as one that did not fit will not fit either
        if any(size[0] >= n and size[1] >= hgt for n, hgt in refused[sheet]):
            continue
        for c in candidates:
            nx = len(c.lower)
            if nx > nx_sheet:
                continue
            fit = _lowest_fit(S, c, short_side)
            if fit is None:
                continue
            x0, y0 = fit
            score = (y0 + c.height, x0)
            if best is None or score < best[0]:
                best = (score, sheet, c, x0, y0)
        if best is not None:
            break
        # keep only the minimal refusals: they decide for all larger parts
        refused[sheet] = [r for r in refused[sheet] if not (r[0] >= size[0] and r[1] >= size[1])]
        refused[sheet].append(size)
    return best


def _placed_sheets(placed: list[list], settings: "StripSettings", portrait: bool) -> list[Sheet]:
    """The sheets of the parts placed on each, ``(part, angle, shift)`` in the skyline's
    frame, turned a quarter where the sheet stands `portrait`."""
    sheets = []
    m = settings.margin_mm
    W, H = settings.sheet_mm
    for k, items in enumerate(placed):
        placements = []
        for i, angle, t in items:
            # oriented frame: rotate by angle about the origin, then translate by t + margin
            offset = t + m
            if portrait:  # the long side runs along y: turn a quarter about the origin
                angle, offset = angle + 90.0, np.array([W - offset[1], offset[0]])
            placements.append(Placement(part=i, angle_deg=float(angle),
                                        offset=(float(offset[0]), float(offset[1]))))
        sheets.append(Sheet(index=k + 1, size=(W, H), placements=placements))
    return sheets


def placed_footprints(nesting: Nesting, sheet: Sheet) -> list:
    """Footprints of a sheet's parts in sheet coordinates (shapely)."""
    out = []
    for p in sheet.placements:
        M = p.matrix()
        out.append(affinity.affine_transform(nesting.parts[p.part].footprint,
                                             [M[0, 0], M[0, 1], M[1, 0], M[1, 1], M[0, 2], M[1, 2]]))
    return out


def check_nesting(layout: Nesting) -> None:
    """Exact check of a layout: parts inside the margin, at least `spacing_mm` apart.

    Raises
    ------
    FabplanError
        Naming the sheet and parts that break the rule.
    """
    s = layout.settings
    eps = 1e-6
    for sheet in layout.sheets:
        W, H = sheet.size
        inner = shapely.box(s.margin_mm - eps, s.margin_mm - eps, W - s.margin_mm + eps,
                            H - s.margin_mm + eps)
        geoms = placed_footprints(layout, sheet)
        for p, g in zip(sheet.placements, geoms, strict=True):
            if not inner.contains(g):
                raise FabplanError(f"sheet {sheet.index}: part {layout.parts[p.part].id} leaves "
                                   "the sheet's margin (nesting bug)")
        tree = shapely.STRtree(geoms)
        pairs = tree.query(geoms, predicate="dwithin", distance=s.spacing_mm - 1e-3)
        for a, b in pairs.T:
            if a < b:
                raise FabplanError(
                    f"sheet {sheet.index}: parts {layout.parts[sheet.placements[a].part].id} and "
                    f"{layout.parts[sheet.placements[b].part].id} are closer than the spacing "
                    "(nesting bug)")
