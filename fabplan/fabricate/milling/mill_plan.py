"""A milling job's terms and its result, the same for face and flank milling: the tool
(`MillTool`, parsed from ``face:D=MM`` or ``cone:angle=DEG,length=MM`` by `parse_tool`),
the settings (`MillSettings`), the tool paths (`ToolPath`) and the plan (`MillPlan`).
Lengths in millimetres, angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...io.units import MM_PER_UNIT, check_units

__all__ = [
    "MillTool",
    "MillSettings",
    "ToolPath",
    "MillPlan",
    "parse_tool",
    "every_kth",
    "at_most",
]


@dataclass(frozen=True)
class MillTool:
    """A milling cutter.

    Attributes
    ----------
    kind : ``"face"``, a cylindrical (face) mill cutting with its base circle, or
        ``"cone"``, a conical flank mill cutting with its side (a cone of revolution).
    diameter_mm : face: cutter diameter D; cone: diameter of the tip (the small end, 0
        for a sharp tip).
    corner_mm : corner radius c of a toroidal (bull-nose) cutter, 0 for a sharp edge.
    length_mm : face: length of the cutter body the simulation sweeps (default: D); cone:
        length of the conical flank along the axis, from the tip.
    angle_deg : cone: half the opening angle, between the axis and the flank (0 < a < 90).
    """

    kind: str
    diameter_mm: float
    corner_mm: float = 0.0
    length_mm: float = 0.0
    angle_deg: float = 0.0

    @property
    def radius_mm(self) -> float:
        """Cutter radius D / 2 (cone: the tip's radius)."""
        return self.diameter_mm / 2

    @property
    def circle_radius_mm(self) -> float:
        """Radius of the circle that is put on the safety sphere: r - c."""
        return self.radius_mm - self.corner_mm

    @property
    def body_length_mm(self) -> float:
        """Length of the cutter body (``length_mm``, or D when not given)."""
        return self.length_mm if self.length_mm > 0 else self.diameter_mm

    @property
    def end_radius_mm(self) -> float:
        """Cone: radius of the flank's wide end, ``tip radius + length tan(angle)``."""
        return self.radius_mm + self.length_mm * float(np.tan(np.radians(self.angle_deg)))

    def spec(self) -> str:
        """The tool as the CLI writes it (``face:D=50,corner=2``, ``cone:angle=20,length=30,tip=6``)."""
        if self.kind == "cone":
            return (f"cone:angle={self.angle_deg:g},length={self.length_mm:g}"
                    + (f",tip={self.diameter_mm:g}" if self.diameter_mm else ""))
        text = f"{self.kind}:D={self.diameter_mm:g}"
        return text + (f",corner={self.corner_mm:g}" if self.corner_mm else "")

    def to_json(self) -> dict:
        if self.kind == "cone":
            return {"kind": "cone", "angle_deg": self.angle_deg, "length_mm": self.length_mm,
                    "tip_diameter_mm": self.diameter_mm,
                    "end_diameter_mm": 2 * self.end_radius_mm, "spec": self.spec()}
        return {"kind": self.kind, "diameter_mm": self.diameter_mm, "corner_mm": self.corner_mm,
                "length_mm": self.body_length_mm, "spec": self.spec()}


_TOOL_FORMS = "face:D=MM[,corner=MM][,length=MM] or cone:angle=DEG,length=MM[,tip=MM]"
_TOOL_KEYS = {"face": ("d", "corner", "length"), "cone": ("angle", "length", "tip")}


def parse_tool(spec: str) -> MillTool:
    """A `MillTool` from ``face:D=50[,corner=R][,length=L]`` or
    ``cone:angle=DEG,length=L[,tip=D]`` (millimetres, degrees).

    Examples
    --------
    >>> parse_tool("face:D=50,corner=2").circle_radius_mm
    23.0
    >>> round(parse_tool("cone:angle=45,length=10,tip=4").end_radius_mm, 12)
    12.0
    >>> parse_tool("ball:D=10")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: --tool ball:D=10: unknown tool kind 'ball'; fabplan mill plans \
face mills or conical flank mills: face:D=MM[,corner=MM][,length=MM] or \
cone:angle=DEG,length=MM[,tip=MM]
    """
    kind, _, rest = spec.partition(":")
    if kind not in _TOOL_KEYS:
        raise InputError(f"--tool {spec}: unknown tool kind {kind!r}; fabplan mill plans face "
                         f"mills or conical flank mills: {_TOOL_FORMS}")
    keys = _TOOL_KEYS[kind]
    values: dict[str, float] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq or key not in keys:
            expected = ("D=MM, corner=MM or length=MM" if kind == "face"
                        else "angle=DEG, length=MM or tip=MM")
            raise InputError(f"--tool {spec}: cannot read {item!r}; expected {expected}")
        try:
            number = float(value)
        except ValueError:
            unit = "degrees" if key == "angle" else "mm"
            said = item.partition("=")[0].strip()     # as the user wrote it (D, not d)
            raise InputError(f"--tool {spec}: {said} must be a number of {unit}, got {value!r}") from None
        if not (np.isfinite(number) and number >= 0):
            raise InputError(f"--tool {spec}: {key} must be a finite value >= 0, got {value}")
        values[key] = number
    if kind == "cone":
        angle, length = values.get("angle"), values.get("length")
        if angle is None or not 0.5 <= angle <= 85:
            raise InputError(f"--tool {spec}: the cone's half angle (between axis and flank) "
                             "must lie in 0.5 .. 85 degrees")
        if length is None or not 0.1 <= length <= 1000:
            raise InputError(f"--tool {spec}: the flank length must lie in 0.1 .. 1000 mm")
        tip = values.get("tip", 0.0)
        if tip > 1000:
            raise InputError(f"--tool {spec}: the tip diameter must lie in 0 .. 1000 mm")
        return MillTool("cone", tip, 0.0, length, angle)
    diameter = values.get("d")
    if diameter is None or not 0.1 <= diameter <= 1000:
        raise InputError(f"--tool {spec}: the diameter D must lie in 0.1 .. 1000 mm")
    corner = values.get("corner", 0.0)
    if corner >= diameter / 2:
        raise InputError(f"--tool {spec}: the corner radius must be smaller than D / 2")
    return MillTool("face", diameter, corner, values.get("length", 0.0))


@dataclass
class MillSettings:
    """Options of a milling plan (the CLI's options).

    Attributes
    ----------
    along : ``"A"`` passes along the lines of family 0, ``"B"`` along family 1.
    units : model units of the net (a key of `fabplan.io.units.MM_PER_UNIT`).
    margin_mm : the Meusnier sphere radius minus the safety sphere radius; None chooses
        it by `default_margin_mm`.
    scallop_mm : largest predicted scallop height the pass selection allows.
    side : ``"auto"`` (the side of the Meusnier centres), ``"+"`` (the side the face
        normals point to) or ``"-"``.
    chordal_tolerance_mm : largest distance of the planned tool-tip path from the
        straight moves between consecutive CL points.
    discretization_share : share of the Meusnier radius added to the default margin for
        the difference between the discrete spheres and the smooth surface they sample.
    flat_curvature : normal curvatures (1/mm) below this in magnitude count as flat:
        a sphere of infinite radius, millable from either side.
    mannheim_tolerance_mm : cone: largest distance of a star's five tangent planes from
        their Mannheim sphere for the net to count as an S*-net.
    flank_dig_mm : cone: largest depth the straight flank may reach below the target along
        its contact line where the target curves towards the tool.
    paths_on : with a design, where the passes' nodes are put: ``"design"``, its closest
        points to the net's vertices with its normals there (the cut follows the design),
        or ``"net"``, the net's vertices and normals as they are.
    """

    along: str = "A"
    units: str = "mm"
    margin_mm: float | None = None
    scallop_mm: float = 0.01
    side: str = "auto"
    chordal_tolerance_mm: float = 0.001
    discretization_share: float = 0.005
    flat_curvature: float = 1e-9
    mannheim_tolerance_mm: float = 0.001
    flank_dig_mm: float = 0.001
    paths_on: str = "design"

    @property
    def mm_per_unit(self) -> float:
        return MM_PER_UNIT[self.units]

    def check(self) -> None:
        """Refuse impossible options (`InputError`, one line)."""
        if self.along not in ("A", "B"):
            raise InputError(f"--along must be A or B, got {self.along!r}")
        check_units(self.units)
        if self.side not in ("auto", "+", "-"):
            raise InputError(f"--side must be auto, + or -, got {self.side!r}")
        if self.paths_on not in ("design", "net"):
            raise InputError(f"--paths-on must be design or net, got {self.paths_on!r}")
        if self.margin_mm is not None and not (np.isfinite(self.margin_mm) and self.margin_mm >= 0):
            raise InputError(f"--margin must be a length >= 0 mm, got {self.margin_mm}")
        if not (np.isfinite(self.scallop_mm) and 1e-5 <= self.scallop_mm <= 10):
            raise InputError(f"--scallop must lie in 0.00001 .. 10 mm, got {self.scallop_mm}")
        if not 1e-6 <= self.chordal_tolerance_mm <= 1:
            raise InputError("the chordal tolerance must lie in 1e-6 .. 1 mm")


@dataclass
class ToolPath:
    """The cutter locations of a plan, in pass order (mm, the mill frame of the net).

    Attributes
    ----------
    pass_id : (k,) int, pass of each location (0, 1, ...).
    contact : (k, 3) float, contact point on the target.
    normal : (k, 3) float, unit normal at the contact, towards the tool.
    cross : (k, 3) float, unit cutting direction at the contact: the tangent of the other
        family's line (face mill), or the ruling, pointing to the tool's tip (cone).
    tip : (k, 3) float, centre of the cutter's end face (the CL point).
    axis : (k, 3) float, unit tool axis (tip to spindle).
    tilt_deg : (k,) float, angle between axis and normal.
    safety_radius : (k,) float, safety sphere radius (inf where flat).
    vertex : (k,) int, the net vertex of a node location, -1 between nodes.
    """

    pass_id: np.ndarray
    contact: np.ndarray
    normal: np.ndarray
    cross: np.ndarray
    tip: np.ndarray
    axis: np.ndarray
    tilt_deg: np.ndarray
    safety_radius: np.ndarray
    vertex: np.ndarray

    def __len__(self) -> int:
        return len(self.pass_id)

    @property
    def pass_count(self) -> int:
        return int(self.pass_id.max()) + 1 if len(self.pass_id) else 0

    def pass_slices(self) -> list[slice]:
        """One slice of the location arrays per pass."""
        bounds = np.flatnonzero(np.diff(self.pass_id)) + 1
        starts = np.r_[0, bounds]
        ends = np.r_[bounds, len(self.pass_id)]
        return [slice(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]

    def path_length_mm(self) -> float:
        """Length of the tool-tip path within the passes (no links between passes)."""
        step = np.linalg.norm(np.diff(self.tip, axis=0), axis=1)
        same = np.diff(self.pass_id) == 0
        return float(step[same].sum())

    def csv(self, *, cross_name: str = "cross", extra: dict[str, np.ndarray] | None = None) -> str:
        """The cutter locations as CSV text, one row per location: pass, vertex, tip
        (``x, y, z``), axis (``i, j, k``), contact, normal, cutting direction, tilt (deg)
        and safety sphere radius (mm), then the `extra` columns.

        Parameters
        ----------
        cross_name : name of the cutting direction in its columns' heads (``cross_x`` ...).
        extra : column head -> (k,) float, columns appended in their order.

        Returns
        -------
        str, the head line and one line per location (numbers to 12 significant digits),
        each ending in a newline.

        Examples
        --------
        >>> path = ToolPath(np.array([0]), np.zeros((1, 3)), np.array([[0.0, 0, 1]]),
        ...                 np.array([[1.0, 0, 0]]), np.array([[0.0, 0, 2]]),
        ...                 np.array([[0.0, 0, 1]]), np.array([0.0]), np.array([np.inf]),
        ...                 np.array([7]))
        >>> text = path.csv(cross_name="ruling", extra={"flag": np.array([1.5])})
        >>> text.splitlines()[0].split(",")[14:]
        ['ruling_x', 'ruling_y', 'ruling_z', 'tilt_deg', 'safety_radius_mm', 'flag']
        >>> text.splitlines()[1]
        '0,7,0,0,2,0,0,1,0,0,0,0,0,1,1,0,0,0,inf,1.5'
        >>> empty = ToolPath(*(array[:0] for array in vars(path).values()))
        >>> empty.csv() == path.csv().splitlines()[0] + "\\n"   # the head alone
        True
        """
        extra = extra or {}
        head = ",".join(["pass", "vertex", "x", "y", "z", "i", "j", "k",
                         *(f"{name}_{c}" for name in ("contact", "normal", cross_name) for c in "xyz"),
                         "tilt_deg", "safety_radius_mm", *extra])
        table = np.column_stack([self.tip, self.axis, self.contact, self.normal, self.cross,
                                 self.tilt_deg, self.safety_radius, *extra.values()])
        rows = [f"{int(a)},{int(b)}," + ",".join(f"{v:.12g}" for v in row)
                for a, b, row in zip(self.pass_id, self.vertex, table, strict=True)]
        return "\n".join([head, *rows]) + "\n"


@dataclass
class MillPlan:
    """A face-milling plan: tool, passes, cutter locations and the predicted scallop.

    Attributes
    ----------
    net : name of the net.
    tool, settings : what the plan was made with.
    path : the cutter locations.
    margin_mm : the margin used; margin_rule says how it was chosen.
    stride : passes run along every stride-th line of the family.
    lines : number of lines of the family holding regular stars.
    predicted_scallop_mm : (stride,) largest predicted scallop for each stride 1.. tried.
    meusnier_radius_mm : (m,) Meusnier radius at the pass nodes.
    side : ``"+"`` or ``"-"``, the side of the face normals the tool comes from.
    sphere_residual_mm : largest distance of a star vertex from its fitted sphere.
    seconds : planning time.
    notes : what a user should know (not an S-net, scallop limit out of reach).
    placed_on : ``"net"`` (the nodes are the net's vertices) or ``"design"`` (the design's
        closest points to them, with its normals).
    node_shift_mm : (m,) float, distance each pass node was moved from its vertex onto the
        design (mm; empty when placed on the net).
    scallop_by_node_mm : (p,) float, the predicted scallop beside each node of the passes
        (mm; NaN beside the last pass).
    margin_tries : ``(margin_mm, gouge_mm)`` of the rule's margin and each larger one
        tried in simulation where the rule's cut gouged (`fabplan.fabricate.milling.
        mill_report`); empty otherwise.
    """

    net: str
    tool: MillTool
    settings: MillSettings
    path: ToolPath
    margin_mm: float
    margin_rule: str
    stride: int
    lines: int
    predicted_scallop_mm: np.ndarray
    meusnier_radius_mm: np.ndarray
    side: str
    sphere_residual_mm: float = 0.0
    seconds: float = 0.0
    notes: list = field(default_factory=list)
    placed_on: str = "net"
    node_shift_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    scallop_by_node_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    margin_tries: tuple = ()

    @property
    def predicted_max_scallop_mm(self) -> float:
        return float(self.predicted_scallop_mm[self.stride - 1])

    def record(self) -> dict:
        """JSON-ready summary (no per-location arrays; those are in the CSV)."""
        path = self.path
        nodes = path.vertex >= 0
        finite = np.isfinite(path.safety_radius)
        return {
            "net": self.net,
            "tool": self.tool.to_json(),
            "along": self.settings.along,
            "units": self.settings.units,
            "side": self.side,
            "margin_mm": self.margin_mm,
            "margin_rule": self.margin_rule,
            "margin_tries": [{"margin_mm": float(m), "gouge_mm": float(g)}
                             for m, g in self.margin_tries],
            "scallop_limit_mm": self.settings.scallop_mm,
            "chordal_tolerance_mm": self.settings.chordal_tolerance_mm,
            "lines": self.lines,
            "stride": self.stride,
            "passes": path.pass_count,
            "cutter_locations": len(path),
            "nodes": int(nodes.sum()),
            "tilt_deg": {"min": float(path.tilt_deg.min()), "max": float(path.tilt_deg.max())},
            "sphere_residual_max_mm": self.sphere_residual_mm,
            "meusnier_radius_mm": {"min": float(self.meusnier_radius_mm.min()),
                                   "max": float(self.meusnier_radius_mm.max())},
            "safety_radius_mm": {
                "min": float(path.safety_radius[finite].min()) if finite.any() else None,
                "max": float(path.safety_radius[finite].max()) if finite.any() else None},
            "path_length_mm": path.path_length_mm(),
            "predicted_scallop_mm": float(self.predicted_max_scallop_mm),
            "predicted_scallop_by_stride_mm": self.predicted_scallop_mm.tolist(),
            "paths": {
                "placed_on": self.placed_on,
                "node_shift_from_net_mm": {
                    "max": float(self.node_shift_mm.max()) if self.node_shift_mm.size else 0.0,
                    "mean": float(self.node_shift_mm.mean()) if self.node_shift_mm.size else 0.0}},
            "plan_seconds": self.seconds,
            "notes": list(self.notes),
        }

    def csv(self) -> str:
        """One row per cutter location: pass, vertex, tip, axis, contact, normal, cross
        tangent, tilt and safety sphere radius (mm, degrees)."""
        return self.path.csv()

    def summary(self) -> str:
        r = self.record()
        return (f"{r['passes']} passes along family {r['along']} "
                f"({every_kth(self.stride, self.lines)}), {r['cutter_locations']} cutter locations, tilt "
                f"{r['tilt_deg']['min']:.2f} .. {r['tilt_deg']['max']:.2f} deg, margin "
                f"{self.margin_mm:.4g} mm, predicted scallop {self.predicted_max_scallop_mm:.4g} "
                f"mm, path {r['path_length_mm']:.0f} mm, planned in {self.seconds:.2f} s")


def every_kth(stride: int, lines: int) -> str:
    """Which lines the passes follow, in words.

    Examples
    --------
    >>> every_kth(1, 20), every_kth(2, 19), every_kth(3, 30), every_kth(11, 40)
    ('every one of 20 lines', 'every 2nd of 19 lines', 'every 3rd of 30 lines', 'every 11th of 40 lines')
    """
    if stride == 1:
        return f"every one of {lines} lines"
    suffix = "th" if 10 <= stride % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(stride % 10, "th")
    return f"every {stride}{suffix} of {lines} lines"


def at_most(value: float) -> str:
    """`value` to four significant digits, rounded down: a bound the user can give back.

    Examples
    --------
    >>> at_most(696.58), at_most(0.012349), at_most(0.0)
    ('696.5', '0.01234', '0')
    """
    if not value > 0:
        return "0"
    unit = 10.0 ** (np.floor(np.log10(value)) - 3)
    return f"{np.floor(value / unit * (1 + 1e-12)) * unit:.4g}"
