"""Lamella strips of a net (`build_strips`): the settings, every strip's reference curve,
crossings and slits, and the set of strips; the unrolling they stand on is
`fabplan.fabricate.strips.unrolling`.

Cut geometry
------------
The developed polyline is the strip's *reference curve*: its mid-line, at the surface, so
the two long edges are the reference curve offset by ``h / 2`` to either side (radii
``r - h/2`` and ``r + h/2`` on a constant-radius net). Runs of nodes that lie on one circle
(or line) within the cutting tolerance are written as arcs of that circle through the
nodes; the rest as straight segments. Arc lengths ``s`` along the reference curve locate
the crossings and the slits. Units: model units in 3D, millimetres in the plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ...errors import InputError
from ...io.units import MM_PER_UNIT as UNITS
from ...io.units import check_units
from ...net.geometry import fit_star_spheres
from ...net.mesh import Polylines, QuadMesh
from ..limits import DEFAULT_MAX_TWIST_DEG_PER_M
from .strip_boundary import StripBoundary, StripEnds, member_setback_mm, tip_setback_mm
from .unrolling import ArcRun, Unrolled, fit_arc_runs, node_normals, strip_polylines, unroll_polylines

__all__ = [
    "StripSettings",
    "ReferenceCurve",
    "Strip",
    "Crossing",
    "StripSet",
    "build_strips",
]

CUTTING_TOLERANCE_MM = (0.001, 10.0)
"""Cutting tolerances that mean something for arcs fitted to the strip outlines (mm)."""

MAX_SHEET_MM = 20_000.0
"""The longest sheet side accepted (mm): beyond it the sizes are in the wrong unit."""

FAMILY_LETTERS = "AB"
_LAYER_KINDS = ("cut", "slit", "engrave")


def _check_positive_mm(name: str, value: object) -> None:
    """Raise InputError unless `value` is a positive finite number (the setting `name`, mm)."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive number of millimetres, got {value}")


def _check_non_negative_mm(name: str, value: object) -> None:
    """Raise InputError unless `value` is a finite number >= 0 (the setting `name`, mm)."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise InputError(f"{name} must be zero or more millimetres, got {value}")


@dataclass
class StripSettings:
    """Everything that shapes the lamella strips and their cutting files (millimetres).

    Attributes
    ----------
    height_mm : lamella height ``h``; the surface runs along its middle.
    thickness_mm : material thickness; a slit is this plus `clearance_mm` wide.
    clearance_mm : play added to the slit width so the strips slide together.
    units : model units of the net, ``"m"`` or ``"mm"``.
    tolerance_mm : cutting tolerance: nodes within it of one circle are cut as an arc.
    sheet_mm : (width, height) of a sheet.
    spacing_mm : smallest gap between two parts on a sheet.
    margin_mm : smallest gap between a part and the sheet edge.
    kerf_mm : width of the cut; outlines grow and slits shrink by half of it.
    end : ``"square"`` or ``"round"`` (semicircular) ends of a strip.
    end_extension_mm : material beyond the end nodes, along the strip (default ``h / 2``).
    splice : joint between two parts of a strip split to fit a sheet: ``"overlap"`` (both
        parts run full height over the splice length, to be bolted face to face) or
        ``"lap"`` (a half-height step lap in the plane of the strip).
    splice_length_mm : length of a splice (default ``2 h``).
    slit_overcut_mm : how far a slit's cut runs past the strip edge (the edge cut crosses
        the slit mouth cleanly).
    labels : ``"stroke"`` (single-stroke vector text, for engraving), ``"outline"`` (glyph
        outlines as closed polylines) or ``"text"`` (DXF TEXT entities).
    label_height_mm : height of strip labels (default ``0.12 h`` within 3-20 mm); crossing
        and splice labels are 3/4 of it.
    layers : kind (``"cut"``, ``"slit"``, ``"engrave"``) -> (layer name, ACI colour).
    one_file : all sheets side by side in one DXF instead of one file per sheet.
    join_boundary : continue polylines of one family through boundary vertices where
        exactly two of them end (the corners of a staircase boundary).
    boundary_member_mm : thickness of the boundary member a strip run to the edge of the
        cladding ends against (default: `thickness_mm`).
    max_twist_deg_per_m : the largest twist a strip may take (degrees per metre,
        `Strip.twist_deg_per_m`); a strip that twists more is counted against it
        (`fabplan.fabricate.limits`, ``docs/fabrication-limits.md``).
    """

    height_mm: float
    thickness_mm: float
    clearance_mm: float = 0.2
    units: str = "m"
    tolerance_mm: float = 0.1
    sheet_mm: tuple[float, float] = (2500.0, 1250.0)
    spacing_mm: float = 10.0
    margin_mm: float = 10.0
    kerf_mm: float = 0.0
    end: str = "square"
    end_extension_mm: float | None = None
    splice: str = "overlap"
    splice_length_mm: float | None = None
    slit_overcut_mm: float = 1.0
    labels: str = "stroke"
    label_height_mm: float | None = None
    layers: dict = field(default_factory=lambda: {
        "cut": ("CUT", 1), "slit": ("SLIT", 6), "engrave": ("ENGRAVE", 5)})
    one_file: bool = False
    join_boundary: bool = True
    boundary_member_mm: float | None = None
    max_twist_deg_per_m: float = DEFAULT_MAX_TWIST_DEG_PER_M

    @property
    def scale(self) -> float:
        """Millimetres per model unit."""
        return UNITS[self.units]

    @property
    def slit_width_mm(self) -> float:
        """Nominal slit width: thickness plus clearance (before kerf compensation)."""
        return self.thickness_mm + self.clearance_mm

    @property
    def extension_mm(self) -> float:
        return self.height_mm / 2 if self.end_extension_mm is None else self.end_extension_mm

    @property
    def member_mm(self) -> float:
        return self.thickness_mm if self.boundary_member_mm is None else self.boundary_member_mm

    @property
    def splice_mm(self) -> float:
        return 2 * self.height_mm if self.splice_length_mm is None else self.splice_length_mm

    @property
    def text_height_mm(self) -> float:
        if self.label_height_mm is not None:
            return self.label_height_mm
        return min(max(0.12 * self.height_mm, 3.0), 20.0)

    def check(self) -> "StripSettings":
        """Validate every field; returns self.

        Raises
        ------
        InputError
            Naming the first bad setting and what it must be.
        """
        _check_positive_mm("--height", self.height_mm)
        _check_positive_mm("--thickness", self.thickness_mm)
        _check_non_negative_mm("--clearance", self.clearance_mm)
        _check_positive_mm("--tolerance", self.tolerance_mm)
        _check_non_negative_mm("--spacing", self.spacing_mm)
        _check_non_negative_mm("--margin", self.margin_mm)
        _check_non_negative_mm("--kerf", self.kerf_mm)
        _check_non_negative_mm("--slit-overcut", self.slit_overcut_mm)
        _check_non_negative_mm("--extension", self.extension_mm)
        _check_non_negative_mm("--boundary-member", self.member_mm)
        _check_positive_mm("--splice-length", self.splice_mm)
        _check_positive_mm("--label-height", self.text_height_mm)
        if not (isinstance(self.max_twist_deg_per_m, (int, float))
                and math.isfinite(self.max_twist_deg_per_m) and self.max_twist_deg_per_m > 0):
            raise InputError(f"--max-twist must be a positive number of degrees per metre, got "
                             f"{self.max_twist_deg_per_m}")
        check_units(self.units)
        if len(self.sheet_mm) != 2:
            raise InputError(f"--sheet must be WIDTHxHEIGHT, got {self.sheet_mm}")
        for value in self.sheet_mm:
            _check_positive_mm("--sheet", value)
        if self.end not in ("square", "round"):
            raise InputError(f"--end must be 'square' or 'round', got {self.end!r}")
        if self.splice not in ("overlap", "lap"):
            raise InputError(f"--splice must be 'overlap' or 'lap', got {self.splice!r}")
        if self.labels not in ("stroke", "outline", "text"):
            raise InputError(f"--labels must be 'stroke', 'outline' or 'text', got {self.labels!r}")
        low, high = CUTTING_TOLERANCE_MM
        if not low <= self.tolerance_mm <= high:
            raise InputError(f"--tolerance {self.tolerance_mm:g} mm lies outside {low:g} .. "
                             f"{high:g} mm, the range a cutting machine works to")
        if max(self.sheet_mm) > MAX_SHEET_MM:
            raise InputError(f"--sheet {self.sheet_mm[0]:g}x{self.sheet_mm[1]:g} mm: no sheet is "
                             f"larger than {MAX_SHEET_MM:g} mm (is it in the wrong unit?)")
        room = min(self.sheet_mm) - 2 * self.margin_mm
        if self.height_mm >= room:
            raise InputError(f"--height {self.height_mm:g} mm does not fit on the "
                             f"{min(self.sheet_mm):g} mm side of the sheet inside its margins "
                             f"(--margin {self.margin_mm:g} mm)")
        if self.spacing_mm >= room:
            raise InputError(f"--spacing {self.spacing_mm:g} mm is wider than the sheet inside its "
                             f"margins ({room:g} mm): it must leave room for a part")
        if self.kerf_mm >= self.slit_width_mm:
            raise InputError(f"--kerf {self.kerf_mm:g} mm must be narrower than the slit "
                             f"({self.slit_width_mm:g} mm = thickness + clearance)")
        if self.slit_width_mm >= self.height_mm:
            raise InputError(f"the slit width {self.slit_width_mm:g} mm (thickness + clearance) "
                             f"must be smaller than --height {self.height_mm:g} mm")
        if self.spacing_mm < self.slit_overcut_mm + self.kerf_mm:
            raise InputError(f"--spacing {self.spacing_mm:g} mm must be at least the slit overcut "
                             f"plus the kerf ({self.slit_overcut_mm + self.kerf_mm:g} mm)")
        if self.extension_mm < self.slit_width_mm / 2 + 1.0:
            raise InputError(f"--extension {self.extension_mm:g} mm leaves no material around a "
                             f"slit at the strip end: use at least "
                             f"{self.slit_width_mm / 2 + 1.0:g} mm")
        if set(self.layers) != set(_LAYER_KINDS):
            raise InputError(f"layers must name exactly {', '.join(_LAYER_KINDS)}")
        names = [str(name) for name, _ in self.layers.values()]
        for name, colour in self.layers.values():
            if not name or any(c in str(name) for c in '<>/\\":;?*|=`'):
                raise InputError(f"layer name {name!r} is empty or has a character DXF forbids")
            if not (isinstance(colour, int) and 1 <= colour <= 255):
                raise InputError(f"layer {name}: colour must be an AutoCAD colour index 1-255, "
                                 f"got {colour}")
        if len({n.upper() for n in names}) != len(names):
            raise InputError(f"layer names must differ, got {', '.join(names)}")
        return self


# ---------------------------------------------------------------------- reference curve
class ReferenceCurve:
    """A planar curve through nodes, each edge a line or a circular arc (DXF bulges).

    Parameters
    ----------
    nodes : (k, 2) float, points the curve passes through, in order (mm).
    bulges : (k - 1,) float, bulge ``tan(theta / 4)`` of each edge, ``theta`` its signed
        included angle (positive counter-clockwise); 0 for a straight edge.

    Examples
    --------
    A quarter circle of radius 10 as one arc:

    >>> import numpy as np
    >>> c = ReferenceCurve(np.array([[10.0, 0], [0, 10.0]]), np.array([np.tan(np.pi / 8)]))
    >>> round(c.length, 9) == round(5 * np.pi, 9)
    True
    >>> p, t = c.point(c.length / 2, offset=1.0)
    >>> np.round(p, 6).tolist()
    [6.363961, 6.363961]
    """

    def __init__(self, nodes: np.ndarray, bulges: np.ndarray):
        self.nodes = np.asarray(nodes, dtype=np.float64)
        self.bulges = np.asarray(bulges, dtype=np.float64)
        A, B = self.nodes[:-1], self.nodes[1:]
        chord = B - A
        self.chord = np.linalg.norm(chord, axis=1)
        self.theta = 4 * np.arctan(self.bulges)
        self.straight = np.abs(self.bulges) < 1e-12
        half = np.where(self.straight, 1.0, self.theta / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.radius = np.where(self.straight, np.inf, self.chord / (2 * np.abs(np.sin(half))))
            left = np.column_stack([-chord[:, 1], chord[:, 0]]) / self.chord[:, None]
            dist = np.where(self.straight, 0.0, self.chord / 2 / np.tan(half))
        self.centre = (A + B) / 2 + left * dist[:, None]
        self.start_angle = np.arctan2(A[:, 1] - self.centre[:, 1], A[:, 0] - self.centre[:, 0])
        with np.errstate(invalid="ignore"):
            self.edge_length = np.where(self.straight, self.chord, self.radius * np.abs(self.theta))
        self.s = np.concatenate([[0.0], np.cumsum(self.edge_length)])

    def to_data(self) -> dict:
        """The curve as plain data (`fabplan.io.typed_data`)."""
        return {"nodes": self.nodes, "bulges": self.bulges}

    @classmethod
    def from_data(cls, data: dict) -> "ReferenceCurve":
        return cls(data["nodes"], data["bulges"])

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def _edge_point(self, e: int, t: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Point and unit tangent at arc fraction t of edge e (t may leave [0, 1])."""
        A, B = self.nodes[e], self.nodes[e + 1]
        if self.straight[e]:
            tan = (B - A) / self.chord[e]
            p = A + t * (B - A)
        else:
            a = self.start_angle[e] + t * self.theta[e]
            radial = np.array([math.cos(a), math.sin(a)])
            p = self.centre[e] + self.radius[e] * radial
            tan = np.sign(self.theta[e]) * np.array([-radial[1], radial[0]])
        left = np.array([-tan[1], tan[0]])
        return p + offset * left, tan

    def locate(self, s: float) -> tuple[int, float]:
        """Edge index and arc fraction of arc length s (beyond the ends: the end edges)."""
        e = int(np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.chord) - 1))
        return e, (s - self.s[e]) / self.edge_length[e]

    def point(self, s: float, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Point at arc length `s`, moved `offset` to the left (the top), and the unit tangent."""
        e, t = self.locate(s)
        return self._edge_point(e, t, offset)

    def points(self, s: np.ndarray, offset: float | np.ndarray = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Vectorized `point`: (m, 2) points at arc lengths `s` moved `offset` (a number or
        (m,) array) to the left, and (m, 2) unit tangents."""
        s = np.asarray(s, dtype=np.float64)
        e = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.chord) - 1)
        t = (s - self.s[e]) / self.edge_length[e]
        A, B = self.nodes[e], self.nodes[e + 1]
        line_tan = (B - A) / self.chord[e, None]
        a = self.start_angle[e] + t * self.theta[e]
        radial = np.column_stack([np.cos(a), np.sin(a)])
        with np.errstate(invalid="ignore"):
            arc_p = self.centre[e] + self.radius[e, None] * radial
        arc_tan = np.sign(self.theta[e])[:, None] * np.column_stack([-radial[:, 1], radial[:, 0]])
        straight = self.straight[e, None]
        p = np.where(straight, A + t[:, None] * (B - A), arc_p)
        tan = np.where(straight, line_tan, arc_tan)
        offset = np.asarray(offset, dtype=np.float64).reshape(-1, 1)
        return p + offset * np.column_stack([-tan[:, 1], tan[:, 0]]), tan

    def path(self, s0: float, s1: float, offset: float = 0.0) -> np.ndarray:
        """The part of the curve from `s0` to `s1` (s0 < s1), offset `offset` to the left.

        Returns
        -------
        (m, 3) float rows ``x, y, bulge``: the bulge of a row belongs to the segment to the
        next row, the last row's bulge is 0. Arcs stay arcs (concentric offsets); at nodes
        inside the range the offsets of both edges meet at their mitre point.
        """
        e0, t0 = self.locate(s0)
        e1, t1 = self.locate(s1)
        rows: list[list[float]] = []
        for e in range(e0, e1 + 1):
            ta = t0 if e == e0 else 0.0
            tb = t1 if e == e1 else 1.0
            pa, _ = self._edge_point(e, ta, offset)
            bulge = 0.0 if self.straight[e] else math.tan((tb - ta) * self.theta[e] / 4)
            if rows and e > e0:
                # mitre with the previous edge at node e
                _, t_in = self._edge_point(e - 1, 1.0, 0.0)
                _, t_out = self._edge_point(e, 0.0, 0.0)
                n_in = np.array([-t_in[1], t_in[0]])
                n_out = np.array([-t_out[1], t_out[0]])
                pa = self.nodes[e] + offset * (n_in + n_out) / (1 + n_in @ n_out)
            rows.append([pa[0], pa[1], bulge])
        pb, _ = self._edge_point(e1, t1, offset)
        rows.append([pb[0], pb[1], 0.0])
        return np.array(rows)


# ---------------------------------------------------------------------- strips
@dataclass
class Strip:
    """One lamella: its polyline on the net and its unrolled reference curve.

    Attributes
    ----------
    id : ``A`` (family 0) or ``B`` (family 1) and a number, e.g. ``A07``.
    family : 0 or 1; family 0 is slit from the top, family 1 from the bottom.
    vertices : (k,) int, net vertices along the strip (a closed loop repeats its first).
    closed : whether the polyline was a closed loop (cut open at its first vertex).
    curve : the reference curve (mid-line) in the plane (mm).
    axis : (k, 2) float, slit direction at each node (the node normal unrolled, upwards).
    edge_mm : (k - 1,) float, 3D edge lengths (mm).
    runs : arc runs of the reference curve.
    twist_deg_per_m : largest rotation of the normals about an edge per metre of edge (edges
        shorter than a quarter of the strip's median edge taken at that length).
    max_twist_deg : largest rotation of the normals about one edge.
    off_orthogonal_deg : largest angle between a node normal and a flat panel through its
        edge and the edge's mean normal: how far a flat-panel lamella leans.
    lean_deg : largest lean at nodes without a star, where the strip continues its
        neighbours' normal curvature (see `unroll_polylines`).
    end_setback_mm : (start, end): None at a free end (cut `StripSettings.end_extension_mm`
        beyond its node), else how far short of its end node the strip ends at the boundary
        member (`fabplan.fabricate.strip_boundary`), in mm: half the member over the sine
        of their angle where the node is on the edge of the cladding; negative where the
        node stops a hair short of the edge and the strip runs on straight to the member.
    end_angle_deg : (start, end) angle between the strip and the cladding edge at a member
        end (NaN at a free end).
    boundary_nodes : (start, end) nodes beyond the net, in its boundary panels.
    end_kind : (start, end) why each end is where it is, one of
        `fabplan.fabricate.strip_boundary.END_KINDS`; ``free`` when no boundary panels were
        given.
    """

    id: str
    family: int
    vertices: np.ndarray
    closed: bool
    curve: ReferenceCurve
    axis: np.ndarray
    edge_mm: np.ndarray
    runs: list
    twist_deg_per_m: float
    max_twist_deg: float
    off_orthogonal_deg: float
    lean_deg: float
    end_setback_mm: tuple[float | None, float | None] = (None, None)
    end_angle_deg: tuple[float, float] = (math.nan, math.nan)
    boundary_nodes: tuple[int, int] = (0, 0)
    end_kind: tuple[str, str] = ("free", "free")

    def at_member(self, side: int) -> bool:
        """Whether the strip's start (`side` 0) or end (1) butts against a boundary member."""
        return self.end_setback_mm[side] is not None

    def end_extensions_mm(self, settings: "StripSettings") -> tuple[float, float]:
        """Material beyond the first and the last node along the curve (mm): the settings'
        extension at a free end, minus the set-back at a member end."""
        return tuple(settings.extension_mm if e is None else -e    # type: ignore[return-value]
                     for e in self.end_setback_mm)

    @property
    def length_mm(self) -> float:
        """3D polyline length (= the unrolled polyline's length: the development is isometric)."""
        return float(self.edge_mm.sum())

    @property
    def unrolled_length_mm(self) -> float:
        """Length of the unrolled polyline (straight chords between the developed nodes)."""
        return float(np.linalg.norm(np.diff(self.curve.nodes, axis=0), axis=1).sum())

    @property
    def cut_length_mm(self) -> float:
        """Length of the reference curve as cut (arcs through the nodes), end node to end node."""
        return self.curve.length

    @property
    def s_mm(self) -> np.ndarray:
        """(k,) arc length of each node along the reference curve as cut."""
        return self.curve.s

    @property
    def arc_radii_mm(self) -> np.ndarray:
        """Signed radii of the fitted arc runs (inf for straight runs)."""
        return np.array([r.radius_mm for r in self.runs if r.fitted])

    @property
    def radius_mm(self) -> float:
        """Length-weighted mean |radius| over the arc runs; inf when the strip is straight."""
        arcs = [r for r in self.runs if r.fitted and math.isfinite(r.radius_mm)]
        if not arcs or any(r.fitted and not math.isfinite(r.radius_mm) for r in self.runs):
            return math.inf
        w = np.array([self.curve.s[r.stop] - self.curve.s[r.start] for r in arcs])
        return float(np.average([abs(r.radius_mm) for r in arcs], weights=w))

    @property
    def arc_fraction(self) -> float:
        """Fraction of the length in fitted runs (cut as true arcs or fitted lines)."""
        fitted = sum(self.curve.s[r.stop] - self.curve.s[r.start] for r in self.runs if r.fitted)
        return float(fitted / self.curve.length) if self.curve.length else 0.0


@dataclass(frozen=True)
class Crossing:
    """Two strips of different families meeting at a net vertex.

    Attributes
    ----------
    id : running number, engraved next to both slits.
    vertex : net vertex.
    strips : (a, b) strip indices, family 0 first.
    nodes : (i, j) node indices on strips a and b.
    s_mm : (s_a, s_b) arc lengths of the node along both reference curves.
    angle_deg : angle between the two strips' polylines at the vertex (3D).
    """

    id: int
    vertex: int
    strips: tuple[int, int]
    nodes: tuple[int, int]
    s_mm: tuple[float, float]
    angle_deg: float


@dataclass
class StripSet:
    """All lamellas of a net with their crossings and summary measurements.

    Attributes
    ----------
    strips : list of Strip, family 0 first, each family ordered across the net.
    crossings : list of Crossing.
    junctions : (j,) int, vertices where more than one strip of a family meets (irregular
        vertices): no slit is cut there, they need a node connector.
    settings : the settings used.
    positions : (m, 3) float, where the strips' vertices are (model units): the net's
        vertices, then the corners of its boundary panels the strips run through.
    ends_not_continued : strip ends on the net's boundary that no boundary panel side
        continues to the edge (0 without boundary panels).
    crossings_at_member : crossings left without slits because a strip ends there
        against the boundary member (two strips meeting at a tip of the boundary).
    along_edge : polylines left out because they lie along the edge of the cladding, where
        the boundary member runs.
    normals : (m, 3) float, the unit node normal at every one of `positions`: the line the
        lamella stands on there (None for a set made without them).
    """

    strips: list
    crossings: list
    junctions: np.ndarray
    settings: StripSettings
    positions: np.ndarray
    ends_not_continued: int = 0
    crossings_at_member: int = 0
    along_edge: int = 0
    normals: np.ndarray | None = None

    @cached_property
    def crossings_of_strip(self) -> list:
        """For each strip, the list of (crossing, side) it takes part in (side 0 or 1)."""
        out: list = [[] for _ in self.strips]
        for c in self.crossings:
            out[c.strips[0]].append((c, 0))
            out[c.strips[1]].append((c, 1))
        return out

    def summary(self) -> dict:
        """Measured facts about the strips (lengths in mm, angles in degrees)."""
        radii = np.array([abs(r) for s in self.strips for r in s.arc_radii_mm if math.isfinite(r)])
        lengths = np.array([s.length_mm for s in self.strips])
        length_error = np.array([abs(s.unrolled_length_mm - s.length_mm) for s in self.strips])
        straight = all(math.isinf(s.radius_mm) for s in self.strips)
        rec = {
            "strips": len(self.strips),
            "strips_per_family": [int(sum(s.family == f for s in self.strips)) for f in (0, 1)],
            "crossings": len(self.crossings),
            "junctions": int(len(self.junctions)),
            "total_length_mm": float(lengths.sum()),
            "length_mm": {"min": float(lengths.min()), "max": float(lengths.max())},
            "unrolled_length_error_mm": float(length_error.max()),
            "straight": bool(straight),
            "arc_fraction": float(np.average([s.arc_fraction for s in self.strips],
                                             weights=lengths)),
            "twist_deg_per_m": float(max(s.twist_deg_per_m for s in self.strips)),
            "off_orthogonal_deg": float(max(s.off_orthogonal_deg for s in self.strips)),
            "boundary_lean_deg": float(max(s.lean_deg for s in self.strips)),
            "ends_at_boundary_member": int(sum(s.at_member(k) for s in self.strips for k in (0, 1))),
            "ends_free": int(sum(not s.closed and not s.at_member(k)
                                 for s in self.strips for k in (0, 1))),
            "ends_not_continued": self.ends_not_continued,
            "ends_free_by_kind": {kind: int(sum(not s.closed and not s.at_member(k)
                                                and s.end_kind[k] == kind
                                                for s in self.strips for k in (0, 1)))
                                  for kind in ("free", "inside", "along edge", "not continued")},
            "crossings_at_member": self.crossings_at_member,
            "strips_along_edge": self.along_edge,
            "boundary_nodes": int(sum(sum(s.boundary_nodes) for s in self.strips)),
        }
        angles = [a for s in self.strips for a in s.end_angle_deg if math.isfinite(a)]
        rec["member_angle_min_deg"] = float(min(angles)) if angles else None
        settings = self.settings
        setbacks = [(e, last, member_setback_mm(settings.member_mm, settings.thickness_mm, a))
                    for s in self.strips
                    for e, last, a in zip(s.end_setback_mm, (s.edge_mm[0], s.edge_mm[-1]),
                                          s.end_angle_deg, strict=True)
                    if e is not None]
        rec["member_setback_max_mm"] = max((e for e, _, _ in setbacks), default=None)
        # a member eating up more than half the last edge of a strip is no edge member;
        # unless another strip ending at the node sets it back further (each clears the
        # other: two lines that meet the edge nearly along each other). The member's own
        # set-back is taken without the hair an end may run on past its node (not kept on
        # the strip), so a tip clearance within that hair of it counts as the member's
        past = [(e, member) for e, last, member in setbacks if e > 0.5 * last]
        rec["ends_set_back_past_half_an_edge"] = len(past)
        rec["ends_set_back_at_tips"] = sum(e > member + 1e-6 for e, member in past)
        if radii.size:
            med = float(np.median(radii))
            rec["radius_mm"] = {"median": med, "min": float(radii.min()), "max": float(radii.max()),
                                "spread_relative": float((radii.max() - radii.min()) / med)}
        else:
            rec["radius_mm"] = None
        return rec


def _order_across(mid: np.ndarray) -> np.ndarray:
    """Order of polylines by their midpoints' position along the main spread direction."""
    if len(mid) < 2:
        return np.arange(len(mid))
    C = mid - mid.mean(axis=0)
    _, _, vt = np.linalg.svd(C, full_matrices=False)
    return np.argsort(C @ vt[0], kind="stable")


def build_strips(mesh: QuadMesh, settings: StripSettings,
                 boundary: StripBoundary | None = None) -> StripSet:
    """Lamellas along every parameter polyline of both families, unrolled and fitted.

    Parameters
    ----------
    mesh : the net (model units, see `StripSettings.units`).
    settings : validated with `StripSettings.check`.
    boundary : the net's boundary panels: strips ending on the net's boundary run on
        through them to the edge of the cladding and end at a boundary member there
        (`fabplan.fabricate.strip_boundary`). None: they end at the net's last vertex.

    Raises
    ------
    InputError
        When the net has no parameter polylines, or a polyline has a repeated vertex or a
        zero-length edge.
    """
    settings.check()
    lines = strip_polylines(mesh, join_boundary=settings.join_boundary)
    verts, family, closed = _ordered_polylines(mesh, lines)
    X = mesh.vertices
    N = node_normals(mesh, lines)
    bad = ~np.isfinite(N).all(axis=1)
    used = np.unique(np.concatenate(verts))
    if bad[used].any():
        vertex = int(used[bad[used]][0])
        raise InputError(f"{mesh.name}: vertex {vertex} has no surface normal (degenerate faces)")
    ends = None
    along_edge = 0
    setback = np.full((len(verts), 2), np.nan)
    if boundary is not None and boundary.polygons:
        N = boundary.normals(N)
        ends = boundary.extend(verts, closed, N)
        # a polyline lying along the cladding's edge is where the boundary member runs
        kept = np.flatnonzero(~ends.along_edge)
        along_edge = len(verts) - len(kept)
        if kept.size == 0:
            raise InputError(f"{mesh.name}: every parameter polyline runs along the edge of the "
                             "cladding, where the boundary member is; use --no-boundary")
        ends = ends.subset(kept)
        verts, family, closed, X = ends.vertices, family[kept], closed[kept], boundary.vertices
        setback = _member_setbacks(X, ends, settings)
    u = unroll_polylines(X, N, verts, scale=settings.scale,
                         curvature=_continued_curvature(mesh, verts, len(X)))
    zero = np.flatnonzero((u.edge_mm < 1e-9) & ~np.isin(np.arange(len(u.edge_mm)), u.ptr[1:] - 1))
    if zero.size:
        k = int(np.searchsorted(u.ptr, zero[0], side="right") - 1)
        vertex = verts[k][zero[0] - u.ptr[k]]
        raise InputError(f"{mesh.name}: a polyline has a zero-length edge at vertex {vertex}")
    counters = [0, 0]
    strips = []
    for k, v in enumerate(verts):
        f = int(family[k])
        counters[f] += 1
        strips.append(_strip(mesh, N, u, k, v, settings, f"{FAMILY_LETTERS[f]}{counters[f]:02d}",
                             f, bool(closed[k]), setback[k], ends))
    _check_strip_lengths(strips, settings)
    crossings, junctions = _find_crossings(X, strips)
    # where two strips end against the boundary member at one node (a zigzag boundary's
    # tip), they meet at the member, not in slits; a slit cut off by a member end neither
    slit = [c for c in crossings if all(_slit_inside(strips[c.strips[k]], c.nodes[k], settings)
                                        for k in (0, 1))]
    at_member = len(crossings) - len(slit)
    slit = [replace(c, id=i + 1) for i, c in enumerate(slit)]
    return StripSet(strips=strips, crossings=slit, junctions=junctions, settings=settings,
                    positions=X, ends_not_continued=0 if ends is None else ends.not_continued,
                    crossings_at_member=at_member, along_edge=along_edge, normals=N)


def _ordered_polylines(mesh: QuadMesh, lines: Polylines) -> tuple[list, np.ndarray, np.ndarray]:
    """The parameter polylines of `lines` (`strip_polylines`) with an edge, the closed ones
    ending where they start, family by family in order across the net: their vertices (a
    list of (k,) int), families and closedness (int and bool arrays)."""
    if len(lines) == 0:
        raise InputError(f"{mesh.name}: no parameter polylines (the net has no quads)")
    verts = [np.r_[v, v[:1]] if c else np.asarray(v) for v, c in
             zip(lines.vertices, lines.closed, strict=True)]
    keep = [i for i, v in enumerate(verts) if len(v) >= 2]
    if not keep:
        raise InputError(f"{mesh.name}: no parameter polyline has an edge")
    X = mesh.vertices
    mid = np.array([X[verts[i]].mean(axis=0) for i in keep])
    fam = lines.family[keep]
    order = []
    for f in (0, 1):
        idx = np.flatnonzero(fam == f)
        order += [keep[i] for i in idx[_order_across(mid[idx])]]
    return [verts[i] for i in order], lines.family[order], lines.closed[order]


def _strip(mesh: QuadMesh, N: np.ndarray, u: Unrolled, k: int, v: np.ndarray,
           settings: StripSettings, name: str, f: int, closed: bool, setback: np.ndarray,
           ends: StripEnds | None) -> Strip:
    """The strip `name` of family `f` along polyline `k` (vertices `v`) of the unrolling `u`:
    its reference curve fitted with arcs, its twist and lean, and its ends."""
    a, b = u.ptr[k], u.ptr[k + 1]
    nodes = u.nodes[a:b]
    if len(v) == 2:
        runs = [_one_edge_run(mesh, N, v, settings.scale)]
    else:
        runs = fit_arc_runs(nodes, settings.tolerance_mm)
    bulges = np.zeros(len(v) - 1)
    for r in runs:
        if r.fitted and math.isfinite(r.radius_mm):
            chord = np.linalg.norm(np.diff(nodes[r.start:r.stop + 1], axis=0), axis=1)
            half = np.arcsin(np.clip(chord / (2 * abs(r.radius_mm)), 0, 1))
            bulges[r.start:r.stop] = np.sign(r.radius_mm) * np.tan(half / 2)
    edge = u.edge_mm[a:b - 1]
    twist = np.abs(u.twist[a:b - 1])
    member = [None if math.isnan(x) else float(x) for x in setback]
    angle, added, kind = (math.nan, math.nan), (0, 0), ("free", "free")
    if ends is not None:
        angle = (float(ends.angle_deg[k, 0]), float(ends.angle_deg[k, 1]))
        added = (int(ends.added[k, 0]), int(ends.added[k, 1]))
        kind = (str(ends.kind[k, 0]), str(ends.kind[k, 1]))
    return Strip(
        id=name, family=f, vertices=np.asarray(v),
        closed=closed, curve=ReferenceCurve(nodes, bulges), axis=u.axis[a:b],
        edge_mm=edge, runs=runs,
        # per metre over at least a quarter of the strip's median edge: a sliver's
        # millimetre edge at a boundary panel corner would make any turn a huge rate
        twist_deg_per_m=float(np.degrees(
            twist / (np.maximum(edge, 0.25 * np.median(edge)) / 1000.0)).max()),
        max_twist_deg=float(np.degrees(twist).max()),
        off_orthogonal_deg=float(np.degrees(u.off_orthogonal[a:b]).max()),
        lean_deg=float(np.degrees(u.lean[a:b]).max()),
        end_setback_mm=(member[0], member[1]), end_angle_deg=angle, boundary_nodes=added,
        end_kind=kind)


def _check_strip_lengths(strips: list[Strip], settings: StripSettings) -> None:
    """Raise InputError for a strip its boundary members leave too short for a slit, or
    bent tighter than half its height."""
    half = settings.height_mm / 2 + settings.kerf_mm / 2
    for s in strips:
        e0, e1 = s.end_extensions_mm(settings)
        if s.curve.length + e0 + e1 < settings.slit_width_mm + 2.0:
            raise InputError(
                f"strip {s.id} is {s.curve.length:.0f} mm long, but its ends against the "
                f"{settings.member_mm:g} mm boundary member leave {s.curve.length + e0 + e1:.0f} "
                "mm of it: use a thinner --boundary-member, or --no-boundary")
        radii = np.abs(s.arc_radii_mm)
        if radii.size and radii.min() <= half:
            raise InputError(f"strip {s.id} bends with a radius of {radii.min():.1f} mm, less than "
                             f"half the height ({half:g} mm): its inner edge would fold over; "
                             f"lower --height or check --units ({settings.units})")


def _member_setbacks(X: np.ndarray, ends: StripEnds, settings: StripSettings) -> np.ndarray:
    """(p, 2) float, mm: how far short of its end node each strip end ends against the
    boundary member (NaN at a free end).

    Both faces of the lamella clear the member (`member_setback_mm`); an end that runs on
    straight to the edge a hair beyond its node (`StripEnds.reach`) ends that much later
    (a negative set-back); where two strips end at one node (a zigzag boundary's tip) each
    also clears the other (`tip_setback_mm`)."""
    out = np.full(ends.at_edge.shape, np.nan)
    direction: dict = {}
    for k, v in enumerate(ends.vertices):
        for side in (0, 1):
            if not ends.at_edge[k, side]:
                continue
            end, before = (v[0], v[1]) if side == 0 else (v[-1], v[-2])
            out[k, side] = (member_setback_mm(settings.member_mm, settings.thickness_mm,
                                              float(ends.angle_deg[k, side]))
                            - ends.reach[k, side] * settings.scale)
            d = X[end] - X[before]
            direction.setdefault(int(end), []).append((k, side, d / np.linalg.norm(d)))
    for meeting in direction.values():
        for i, (k, side, d) in enumerate(meeting):
            for j, (_, _, e) in enumerate(meeting):
                if i != j:
                    angle = math.degrees(math.acos(float(np.clip(d @ e, -1.0, 1.0))))
                    out[k, side] = max(out[k, side], tip_setback_mm(settings.thickness_mm, angle))
    return out


def _slit_inside(strip: Strip, node: int, settings: StripSettings) -> bool:
    """Whether a slit at `node` lies within the strip as cut (its ends set back at a
    boundary member)."""
    e0, e1 = strip.end_extensions_mm(settings)
    s = strip.s_mm[node]
    half = settings.slit_width_mm / 2
    return bool(s - half >= -e0 and s + half <= strip.curve.length + e1)


def _continued_curvature(mesh: QuadMesh, verts: list, count: int | None = None) -> np.ndarray:
    """Normal curvature imposed at strip nodes that are no star centre (NaN elsewhere).

    The net does not constrain such a node (on the boundary, or next to an irregular
    vertex), so its strip continues the normal curvature of the star centres next to it
    along the strip (their mean), or else of the stars the node belongs to (at a star both
    families share the normal curvature): the net's defining property (a constant radius,
    zero on an A-net) carries on to the strip's last nodes. Nodes beyond the net (ids from
    ``mesh.vertex_count`` up to `count`, in its boundary panels) carry on the curvature of
    the nearest node along the strip that has one. Nodes no star reaches keep NaN.
    """
    X, stars = mesh.vertices, mesh.stars
    count = len(X) if count is None else count
    kappa = np.full(count, np.nan)
    nearby = np.full(count, np.nan)
    if len(stars):
        k_star = fit_star_spheres(X, stars).curvature
        kappa[stars[:, 0]] = k_star
        total = np.zeros(count)
        hits = np.zeros(count)
        for j in range(1, 5):
            np.add.at(total, stars[:, j], k_star)
            np.add.at(hits, stars[:, j], 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            nearby = total / hits
    out = []
    for v in verts:
        k = kappa[v]
        pair = np.stack([np.r_[np.nan, k[:-1]], np.r_[k[1:], np.nan]])
        known = np.isfinite(pair)
        along = np.where(known.any(axis=0),
                         np.where(known, pair, 0).sum(axis=0) / np.maximum(known.sum(axis=0), 1),
                         nearby[v])
        imposed = np.where(np.isfinite(k), np.nan, along)
        beyond = v >= len(X)
        if beyond.any():
            # the nearest node along the strip with a curvature (its star's or imposed)
            value = np.where(np.isfinite(k), k, imposed)
            have = np.flatnonzero(np.isfinite(value) & ~beyond)
            if have.size:
                pos = np.arange(len(v))
                right = np.clip(np.searchsorted(have, pos), 0, have.size - 1)
                left = np.clip(right - 1, 0, have.size - 1)
                nearest = np.where(np.abs(have[left] - pos) <= np.abs(have[right] - pos),
                                   have[left], have[right])
                imposed = np.where(beyond, value[nearest], imposed)
        out.append(imposed)
    return np.concatenate(out)


def _one_edge_run(mesh: QuadMesh, N: np.ndarray, v: np.ndarray, scale: float) -> ArcRun:
    """The run of a one-edge strip: an arc of the edge's normal curvature.

    That is ``(n_0 - n_1) . e / |e|^2``, the Meusnier circle through both ends, when the
    end normals tell it; when both ends took their normal from the same single face (a
    corner edge of the boundary) the curvature is the mean of the Meusnier spheres of the
    stars that reach the edge's faces instead. A line when neither is known.
    """
    X = mesh.vertices
    e = X[v[1]] - X[v[0]]
    length = float(np.linalg.norm(e)) * scale
    kappa = float((N[v[0]] - N[v[1]]) @ e / (e @ e)) / scale
    if np.allclose(N[v[0]], N[v[1]], atol=1e-12) and len(mesh.stars):
        idx = mesh.face_indices
        face = mesh.corner_faces
        both = np.intersect1d(face[idx == v[0]], face[idx == v[1]])
        corners = idx[np.isin(face, both)]
        near = np.isin(mesh.stars, corners).any(axis=1)  # stars reaching the edge's faces
        if near.any():
            kappa = float(np.mean(fit_star_spheres(X, mesh.stars[near]).curvature)) / scale
    if abs(kappa) * length < 1e-9 or abs(kappa) * length >= 2:
        return ArcRun(0, 1, math.inf, 0.0, True)
    return ArcRun(0, 1, 1 / kappa, 0.0, True)


def _find_crossings(X: np.ndarray, strips: list[Strip]) -> tuple[list[Crossing], np.ndarray]:
    """Crossings: vertices on exactly one strip of each family (closed loops counted once)."""
    vert_parts, fam_parts, owner_parts, local_parts = [], [], [], []
    for k, s in enumerate(strips):
        v = s.vertices[:-1] if s.closed else s.vertices
        vert_parts.append(v)
        fam_parts.append(np.full(len(v), s.family))
        owner_parts.append(np.full(len(v), k))
        local_parts.append(np.arange(len(v)))
    vert, fam, owner, local = (np.concatenate(a) for a in (vert_parts, fam_parts, owner_parts, local_parts))
    n = len(X)
    count = np.zeros((n, 2), np.int64)
    np.add.at(count, (vert, fam), 1)
    is_crossing = (count[:, 0] == 1) & (count[:, 1] == 1)
    junctions = np.flatnonzero((count.min(axis=1) >= 1) & (count.max(axis=1) >= 2))
    sel = is_crossing[vert]
    order = np.lexsort((fam[sel], vert[sel]))
    v_s, o_s, l_s = vert[sel][order], owner[sel][order], local[sel][order]
    crossings = []
    for c, i in enumerate(range(0, len(v_s), 2)):
        a, b = int(o_s[i]), int(o_s[i + 1])
        ia, ib = int(l_s[i]), int(l_s[i + 1])
        ta, tb = _polyline_tangent(X, strips[a].vertices, ia), _polyline_tangent(X, strips[b].vertices, ib)
        angle = math.degrees(math.acos(min(1.0, abs(float(ta @ tb)))))
        crossings.append(Crossing(id=c + 1, vertex=int(v_s[i]), strips=(a, b), nodes=(ia, ib),
                                  s_mm=(float(strips[a].s_mm[ia]), float(strips[b].s_mm[ib])),
                                  angle_deg=angle))
    return crossings, junctions


def _polyline_tangent(X: np.ndarray, v: np.ndarray, i: int) -> np.ndarray:
    a, b = X[v[max(i - 1, 0)]], X[v[min(i + 1, len(v) - 1)]]
    t = b - a
    return t / np.linalg.norm(t)
