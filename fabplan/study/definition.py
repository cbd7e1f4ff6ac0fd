"""What a study asks for, as validated data: the study (`Study`), its design, limits,
strip options and cost weights, and the candidates and searches it runs.

Owns the frozen dataclasses a study file is read into (`fabplan.study.spec` reads and
validates the file; `fabplan.study.candidates` expands its ``[[candidates]]``) and the
names candidates are given (`candidate_name`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..fabricate.limits import DEFAULT_MAX_TWIST_DEG_PER_M
from ..fabricate.molds.materials import Material
from ..io.units import MM_PER_UNIT
from ..solve.net_types import get_net

if TYPE_CHECKING:  # imported where used: a study file is read without the layout stage
    from ..layout.settings import LayoutSettings

__all__ = ["Study", "DesignSpec", "Limits", "StripOptions", "CostWeights", "Candidate", "Search",
           "SEARCH_BUDGET", "GLIDING_NETS", "candidate_name"]

#: Net types that exist on every surface: they glide on the design exactly.
GLIDING_NETS = ("snet", "isogonal", "orthogonal", "mean-curvature-spheres")

@dataclass(frozen=True)
class DesignSpec:
    """The design surface of a study.

    Attributes
    ----------
    source : a triangle-mesh file (absolute path), a Rhino file with its choices
        ``"/path/x.3dm#layer=..,object=..,face=..,units=.."`` (see
        `fabplan.io.rhino_read`), or a built-in surface spec ``"name:key=value,..."``
        (see `fabplan.surfaces`).
    label : what the report calls it.
    parameters : parameters of a built-in surface (for the record).
    triangles : triangles of the design mesh a built-in or NURBS surface is sampled with
        (about); None for a mesh file, which keeps its own triangles.
    units : model units (a key of `fabplan.io.units.MM_PER_UNIT`).
    """

    source: str
    label: str
    parameters: dict
    triangles: int | None = 20000
    units: str = "m"

    @property
    def mm_per_unit(self) -> float:
        return MM_PER_UNIT[self.units]

    def files(self) -> list[Path]:
        """The existing files the design reads: its mesh or Rhino file, and the files a
        built-in surface's parameters name (a profile, a grid of heights)."""
        names = [self.source.split("#", 1)[0], *(str(v) for v in self.parameters.values())]
        names += [part.split("=", 1)[-1] for part in self.source.replace(":", ",").split(",")]
        found: list[Path] = []
        for name in names:
            try:
                path = Path(name)
                if path.is_file() and path not in found:
                    found.append(path)
            except (OSError, ValueError):
                continue
        return found


@dataclass(frozen=True)
class Limits:
    """What fabrication can do (millimetres and degrees; None: no limit).

    Attributes
    ----------
    max_deviation_mm : largest distance of a net vertex from the design surface.
    mold_tolerance_mm : largest gap between a panel and its mold.
    max_panel_step_mm : largest step between the molds of neighbouring panels at a shared
        edge (`fabplan.fabricate.molds.panel_steps`); None: twice `mold_tolerance_mm`.
    max_molds : most molds the budget allows.
    planar_panels : panels must be flat (glass): face planarity within
        `planarity_tolerance_mm`.
    planarity_tolerance_mm : largest distance of a quad's corner from its best-fit plane.
    max_kink_deg : largest angle between the normals of neighbouring panels.
    max_line_turn_deg : largest turn of a net line within the surface at a vertex
        (`fabplan.net.fairness`): how much the lines may wander and kink.
    min_strip_radius_mm, max_strip_radius_mm : range of the arc radii of the unrolled
        lamella strips (a straight strip has an infinite radius).
    max_sheets : most sheets of strip material.
    max_twist_deg_per_m : largest twist of a lamella strip (its normals' rotation about
        its edges per metre), as ``fabplan strips --max-twist`` checks it (the same
        default).
    congruent_strips : every strip must be cut from one circle (or line): all parts
        congruent within `congruence_tolerance_mm`, so one bending form or jig serves all.
    congruence_tolerance_mm : how far a strip part may differ from the common arc and
        still count as congruent (from ``[strips] congruence_tolerance_mm``; it is also
        the cutting tolerance the strips are planned with).
    min_coverage : smallest fraction of the design's area the panels must cover (the
        layout may leave gaps of up to one panel along the boundary).
    max_sphere_residual : largest sphere residual (relative to the mean edge) for a net to
        count as the net type it claims to be.
    """

    max_deviation_mm: float
    mold_tolerance_mm: float
    max_molds: int | None = None
    max_panel_step_mm: float | None = None
    planar_panels: bool = False
    planarity_tolerance_mm: float = 2.0
    max_kink_deg: float | None = None
    max_line_turn_deg: float | None = None
    min_strip_radius_mm: float | None = None
    max_strip_radius_mm: float | None = None
    max_sheets: int | None = None
    max_twist_deg_per_m: float = DEFAULT_MAX_TWIST_DEG_PER_M
    congruent_strips: bool = False
    congruence_tolerance_mm: float = 0.1
    min_coverage: float | None = None
    max_sphere_residual: float = 1e-6

    @property
    def panel_step_limit_mm(self) -> float:
        """`max_panel_step_mm`, or twice the mold tolerance when not given."""
        return (self.max_panel_step_mm if self.max_panel_step_mm is not None
                else 2.0 * self.mold_tolerance_mm)


@dataclass(frozen=True)
class StripOptions:
    """Lamella strips for the candidates that suit them.

    Attributes
    ----------
    height_mm, thickness_mm, sheet_mm : strip height, material thickness, sheet size.
    nets : ``"auto"`` (nets whose lamellas unroll onto circles or lines: constant radius,
        CMC, linear Weingarten and the A-nets), ``"all"``, or a list of net types.
    congruence_tolerance_mm : cutting tolerance of the strips
        (`fabplan.strips.StripSettings.tolerance_mm`): parts that differ from one common
        arc by at most this much are congruent, and runs of nodes within it of one circle
        are cut as one arc.
    """

    height_mm: float
    thickness_mm: float
    sheet_mm: tuple[float, float] = (2500.0, 1250.0)
    nets: tuple | str = "auto"
    congruence_tolerance_mm: float = 0.1

    def wanted(self, net: str) -> bool:
        if self.nets == "all":
            return True
        if self.nets == "auto":
            preset = get_net(net)
            return not preset.dual and preset.radius != "none"
        return net in self.nets


@dataclass(frozen=True)
class CostWeights:
    """The cost a candidate is ranked by: a weighted sum of what it takes to build.

    ``cost = mold * molds + (flat_panel * planar panels + single_curved_panel * single
    curved panels + double_curved_panel * double curved panels) / coverage + sheet * strip
    sheets + deviation_mm * largest deviation from the design (mm)``, where coverage is
    the fraction of the design's area the net's panels cover (panels are counted for the
    whole design, so that a net with gaps at the boundary does not look cheaper). With a
    ``[material]`` the panels are counted by class: flat, cold-bent (`cold_bent_panel`),
    roll-bent (`roll_bent_panel`), and the molded ones as single or double curved; molds
    are those of the molded panels.

    The defaults are relative prices: a mold costs as much as 100 flat panels.
    """

    mold: float = 100.0
    flat_panel: float = 1.0
    single_curved_panel: float = 2.0
    double_curved_panel: float = 4.0
    cold_bent_panel: float = 1.5
    roll_bent_panel: float = 2.0
    sheet: float = 5.0
    deviation_mm: float = 1.0


@dataclass(frozen=True)
class Candidate:
    """One rationalization to try.

    Attributes
    ----------
    name : unique name (folder name of its outputs).
    net : net type (`fabplan.nets.NETS`).
    angle : intersection angle in degrees, or None (free, or fixed by the type).
    radius : Meusnier radius in model units, or None (free).
    baseline : the unrationalized reference (a general S-net on the design).
    start_angle : intersection angle of the layout the candidate starts from (degrees);
        None: the candidate's angle, or one suited to the design (see
        `fabplan.study.start_angle`).
    panel_size : its panel size (model units) when the study sweeps ``[panels] size``;
        None: the study's.
    mold_tolerance_mm : its mold tolerance when the study sweeps
        ``[limits] mold_tolerance_mm``; None: the study's.
    """

    name: str
    net: str
    angle: float | None = None
    radius: float | None = None
    baseline: bool = False
    start_angle: float | None = None
    panel_size: float | None = None
    mold_tolerance_mm: float | None = None

    @property
    def solve_key(self) -> tuple:
        """What its net depends on: candidates with the same key (a sweep of mold
        tolerances) share one solve."""
        return (self.net, self.angle, self.radius, self.start_angle, self.panel_size)

    @property
    def glides(self) -> bool:
        """The net exists on every surface: it is solved exactly on the design."""
        return self.net in GLIDING_NETS

    def describe(self) -> str:
        parts = [self.net]
        if self.angle is not None:
            parts.append(f"angle {self.angle:g} deg")
        elif get_net(self.net).angle == "param":
            parts.append("free angle")
        if self.radius is not None:
            parts.append(f"radius {self.radius:g}")
        elif get_net(self.net).radius == "param":
            parts.append("free radius")
        if self.panel_size is not None:
            parts.append(f"panels {self.panel_size:g}")
        if self.mold_tolerance_mm is not None:
            parts.append(f"mold tolerance {self.mold_tolerance_mm:g} mm")
        return ", ".join(parts)


@dataclass(frozen=True)
class Search:
    """A candidate whose angle or radius the study searches for (``angle = { search =
    [30, 60], budget = 6 }``): the value in the range with the lowest cost that meets every
    limit, found coarse to fine (`fabplan.study.search`).

    Attributes
    ----------
    name : the name its points are named after (``linear-weingarten`` gives
        ``linear-weingarten-41.25``).
    net : the net type.
    parameter : ``"angle"`` (degrees) or ``"radius"`` (model units).
    low, high : the range searched, both ends included.
    budget : the most solves the search may spend (the first round's points included).
    angle, radius : the other parameter, fixed (None: free).
    start_angle : as `Candidate.start_angle`.
    """

    name: str
    net: str
    parameter: str
    low: float
    high: float
    budget: int = 6
    angle: float | None = None
    radius: float | None = None
    start_angle: float | None = None

    def candidate(self, value: float, start_angle: float | None = None) -> Candidate:
        """The candidate at `value` of the searched parameter; `start_angle` (the angle
        of the layout it starts from, where its own angle is free) when given, else the
        search's."""
        angle = value if self.parameter == "angle" else self.angle
        radius = value if self.parameter == "radius" else self.radius
        name = self.name + candidate_name(self.net, angle, radius)[len(self.net):]
        return Candidate(name, self.net, angle, radius,
                         start_angle=self.start_angle if start_angle is None else start_angle)

    def describe(self) -> str:
        unit = "deg" if self.parameter == "angle" else "model units"
        return (f"{self.net}, {self.parameter} searched in {self.low:g} .. {self.high:g} {unit} "
                f"(at most {self.budget} solves)")


#: Fewest and most solves a search may be given, and its default
SEARCH_BUDGET = (3, 25, 6)


@dataclass(frozen=True)
class Study:
    """A validated study (see `read_study`).

    `panel_size` and ``limits.mold_tolerance_mm`` are the first values of a sweep; each
    candidate of a sweep carries its own (`panel_size_of`, `limits_of`).
    """

    name: str
    path: Path | None
    description: str
    design: DesignSpec
    panel_size: float
    limits: Limits
    strips: StripOptions | None
    cost: CostWeights
    candidates: tuple[Candidate, ...]
    max_iterations: int = 100
    layout_starts: int = 1
    extra: dict = field(default_factory=dict)
    searches: tuple[Search, ...] = ()
    material: Material | None = None
    #: the layouts' direction fields smoothed over this many panels and no other
    #: (``[panels] smoothing``, as `fabplan layout --smoothing`); None: the layouts'
    #: own choice, and their longer smoothing one of the layout starts
    smoothing: float | None = None

    @property
    def layout_settings(self) -> LayoutSettings | None:
        """The `LayoutSettings` of the study's layouts: None, or its smoothing alone."""
        if self.smoothing is None:
            return None
        from ..layout.settings import LayoutSettings

        return LayoutSettings(smoothing=self.smoothing, smoothing_tries=())

    def panel_size_of(self, candidate: Candidate) -> float:
        """The panel size (model units) a candidate is laid out with."""
        return self.panel_size if candidate.panel_size is None else candidate.panel_size

    def mold_tolerance_of(self, candidate: Candidate) -> float:
        """The mold tolerance (mm) a candidate's molds are planned at."""
        if candidate.mold_tolerance_mm is None:
            return self.limits.mold_tolerance_mm
        return candidate.mold_tolerance_mm

    def limits_of(self, candidate: Candidate) -> Limits:
        """The limits a candidate is judged by (its own mold tolerance in a sweep)."""
        if candidate.mold_tolerance_mm is None:
            return self.limits
        return replace(self.limits, mold_tolerance_mm=self.mold_tolerance_of(candidate))

    @property
    def swept(self) -> dict[str, list[float]]:
        """The swept study-wide values (``panel_size``, ``mold_tolerance_mm``) with more
        than one value, in the order of the file."""
        out: dict[str, list[float]] = {}
        for key in ("panel_size", "mold_tolerance_mm"):
            values = [getattr(c, key) for c in self.candidates if c.baseline]
            if len(values) > 1 and None not in values:
                out[key] = sorted(set(values), key=values.index)
        return out

    def input_files(self) -> dict[Path, str]:
        """Every file the study reads, with what it is: the study file and the design's
        files (`DesignSpec.files`). No output of the study may replace one."""
        files = {path: f"a file of the design {self.design.label}" for path in self.design.files()}
        if self.path is not None:
            files[self.path] = "the study file"
        return files

    def record(self) -> dict:
        """The study as JSON (what `study.json` says was asked)."""
        from dataclasses import asdict

        return {
            "name": self.name,
            "file": str(self.path) if self.path else None,
            "description": self.description,
            "design": asdict(self.design),
            "panel_size": self.panel_size,
            **({"sweep": self.swept} if self.swept else {}),
            "limits": asdict(self.limits),
            "strips": None if self.strips is None else
            {**asdict(self.strips), "nets": self.strips.nets if isinstance(self.strips.nets, str)
             else list(self.strips.nets)},
            "cost": asdict(self.cost),
            "material": None if self.material is None else self.material.record(),
            "max_iterations": self.max_iterations,
            "layout_starts": self.layout_starts,
            "smoothing": self.smoothing,
            **({"searches": [asdict(s) for s in self.searches]} if self.searches else {}),
        }


def candidate_name(net: str, angle: float | None, radius: float | None) -> str:
    """A candidate's name from its net type, angle and radius (``isogonal-60``,
    ``const-radius-r12``)."""
    name = net
    if angle is not None:
        name += f"-{angle:g}"
    if radius is not None:
        name += f"-r{radius:g}"
    return name
