"""Facade study files: read a TOML study, validate every key, expand the candidates.

A study file says what the design is, how large its panels should be, what the
fabrication can do (the limits) and which rationalizations to try. The keys are
documented in ``docs/study-file.md``; a minimal study::

    [design]
    surface = "hyperbolic-paraboloid"
    parameters = { width = 10, depth = 10, rise = 3 }

    [panels]
    size = 1.5

    [limits]
    max_deviation_mm = 50
    mold_tolerance_mm = 3

    [[candidates]]
    net = "isogonal"
    angle = { from = 60, to = 90, step = 10 }

Every problem is reported as one `InputError` naming the file and the key.
"""

from __future__ import annotations

import difflib
import math
import os
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Literal, NoReturn, Sequence, overload

from ..errors import InputError
from ..fabricate.molds.materials import Material, material_from_table
from ..io.inputs import check_input_file, check_text
from ..io.parameters import OPTIONS
from ..io.units import MM_PER_UNIT
from ..layout.settings import MAX_STARTS
from ..solve.net_types import NETS, get_net

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "Study",
    "DesignSpec",
    "Limits",
    "StripOptions",
    "CostWeights",
    "Candidate",
    "Search",
    "SEARCH_BUDGET",
    "read_study",
    "parse_study",
    "AUTO_CANDIDATES",
]

#: Net types that exist on every surface: they glide on the design exactly.
GLIDING_NETS = ("snet", "isogonal", "orthogonal", "mean-curvature-spheres")

#: The tables of a study file.
TABLES = ("study", "design", "panels", "limits", "strips", "material", "cost", "candidates")

#: The candidates ``net = "auto"`` stands for (the baseline is always added).
AUTO_CANDIDATES = (
    ("isogonal", None, None),
    ("linear-weingarten", None, None),
    ("const-radius", None, None),
    ("char-conjugate", None, None),
    ("cmc", None, None),
)


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
        """The candidate at `value` of the searched parameter; `start_angle` (a warm start
        from a neighbouring point's layout) when given, else the search's."""
        angle = value if self.parameter == "angle" else self.angle
        radius = value if self.parameter == "radius" else self.radius
        name = self.name + _name(self.net, angle, radius)[len(self.net):]
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
            **({"searches": [asdict(s) for s in self.searches]} if self.searches else {}),
        }


# ---------------------------------------------------------------------------- validation
class _Table:
    """One TOML table and its path in the file, for messages that name the key."""

    def __init__(self, data: object, where: str, file: str) -> None:
        if not isinstance(data, dict):
            raise InputError(f"{file}: [{where}] must be a table")
        self.data: dict[str, Any] = data    # TOML values: whatever the file holds
        self.where, self.file = where, file
        self.used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.file}: {self.where}.{key}" if self.where else f"{self.file}: {key}"

    def fail(self, key: str, what: str) -> NoReturn:
        raise InputError(f"{self._name(key)} {what}")

    def within(self, key: str, value: float | None, option: str) -> None:
        """Refuse `value` of `key` outside the range of the command-line option it is
        given to (`fabplan.io.parameters.OPTIONS`), naming the key."""
        reason = None if value is None else OPTIONS[option].reason(value)
        if reason is not None:
            self.fail(key, reason)

    def missing(self, key: str, what: str) -> NoReturn:
        """A required key is absent: name a present key that looks like a typo of it."""
        close = difflib.get_close_matches(key, [k for k in self.data if k not in self.used], n=1)
        if close:
            self.fail(close[0], f"is not a known key (did you mean {key!r}?)")
        self.fail(key, f"is missing: {what}")

    def get(self, key: str, default: Any = None) -> Any:
        self.used.add(key)
        return self.data.get(key, default)

    def has(self, key: str) -> bool:
        return key in self.data

    # number and text return None only for an absent key without a default that is not
    # required, and number an int with integer=True: the overloads say so to the checker
    @overload
    def number(self, key: str, default: int, *, positive: bool = ..., integer: Literal[True],
               unit: str = ...) -> int: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ..., integer: Literal[True],
               unit: str = ...) -> int | None: ...
    @overload
    def number(self, key: str, default: float, *, positive: bool = ..., unit: str = ...) -> float: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ..., required: Literal[True],
               unit: str = ...) -> float: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ...,
               unit: str = ...) -> float | None: ...

    def number(self, key: str, default: float | None = None, *, positive: bool = True,
               required: bool = False, integer: bool = False, unit: str = "") -> float | None:
        """A number (an int with `integer`); `default` when absent, unless `required`."""
        value = self.get(key)
        if value is None:
            if required:
                self.missing(key, f"give a {'positive ' if positive else ''}number"
                             + (f" ({unit})" if unit else ""))
            return default
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if ok and integer:
            ok = float(value).is_integer()
        if not ok or (positive and value <= 0):
            kind = "a positive " if positive else "a "
            kind += "whole number" if integer else "number"
            # as the file says it (TOML's true, not Python's True)
            shown = str(value).lower() if isinstance(value, bool) else repr(value)
            self.fail(key, f"must be {kind}{f' ({unit})' if unit else ''}, got {shown}")
        return int(value) if integer else float(value)

    @overload
    def text(self, key: str, default: str, *, choices: Sequence[str] | None = ...) -> str: ...
    @overload
    def text(self, key: str, default: None = ..., *, choices: Sequence[str] | None = ...,
             required: Literal[True]) -> str: ...
    @overload
    def text(self, key: str, default: None = ..., *,
             choices: Sequence[str] | None = ...) -> str | None: ...

    def text(self, key: str, default: str | None = None, *, choices: Sequence[str] | None = None,
             required: bool = False) -> str | None:
        """A string (one of `choices` if given); `default` when absent, unless `required`."""
        value = self.get(key)
        if value is None:
            if required:
                self.missing(key, "give a name")
            return default
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {value!r}")
        if choices is not None and value not in choices:
            self.fail(key, f"must be one of {', '.join(map(str, choices))}; got {value!r}"
                      + _suggest(value, choices))
        return value

    def boolean(self, key: str, default: bool = False) -> bool:
        value = self.get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            self.fail(key, f"must be true or false, got {value!r}")
        return value

    def only(self, tables: Sequence[str]) -> None:
        """Refuse top-level tables other than `tables` before anything else is read, so
        that a misspelt table (``[panel]``) is named, not reported as missing keys."""
        for key in self.data:
            if key not in tables:
                header = {t: f"[[{t}]]" if t == "candidates" else f"[{t}]" for t in tables}
                close = difflib.get_close_matches(key, tables, n=1, cutoff=0.7)
                hint = f" (did you mean {header[close[0]]}?)" if close else \
                    f"; the tables are {', '.join(header.values())}"
                raise InputError(f"{self.file}: [{key}] is not a known table{hint}")

    def done(self) -> None:
        """Refuse keys nobody asked for (a typo must not silently drop a limit)."""
        for key in self.data:
            if key not in self.used:
                self.fail(key, "is not a known key" + _suggest(key, self.used))


def _suggest(word: object, options: Iterable[object]) -> str:
    close = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.7)
    return f" (did you mean {close[0]!r}?)" if close else ""


def read_study(path: str | Path) -> Study:
    """Read and validate a study file.

    Raises
    ------
    InputError
        A missing or unreadable file, invalid TOML, an unknown or malformed key, an
        unknown net type or surface, a missing design file; the message names the file
        and the key.
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise InputError(f"{path}: no such study file")
    check_input_file(path, "a study file")
    return parse_study(check_text(path, "TOML study"), path=path)


def parse_study(text: str, *, path: Path | None = None) -> Study:
    """Validate a study given as TOML text (design files are found beside `path`).

    Examples
    --------
    >>> s = parse_study('''
    ... [design]
    ... surface = "hyperbolic-paraboloid"
    ... [panels]
    ... size = 2.0
    ... [limits]
    ... max_deviation_mm = 30
    ... mold_tolerance_mm = 2
    ... [[candidates]]
    ... net = "isogonal"
    ... angle = { from = 70, to = 90, step = 10 }
    ... ''')
    >>> [c.name for c in s.candidates]
    ['baseline', 'isogonal-70', 'isogonal-80', 'isogonal-90']
    >>> parse_study('[panels]\\nsize = -1')
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: study: panels.size must be a positive number (model units), got -1
    """
    file = str(path) if path else "study"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{file}: not a valid TOML study file: {exc}") from None
    except RecursionError:
        # the parser recurses once per level of nested arrays and inline tables
        raise InputError(f"{file}: not a valid TOML study file: its arrays or tables nest "
                         "too deep (a study nests a few levels)") from None
    top = _Table(data, "", file)
    top.only(TABLES)
    folder = path.parent if path else Path.cwd()

    meta = _Table(top.get("study", {}), "study", file)
    name = meta.text("name", path.stem if path else "study")
    description = meta.text("description", "")
    max_iterations = meta.number("max_iterations", 100, integer=True)
    layout_starts = meta.number("layout_starts", 1, integer=True, positive=False)
    if not 1 <= layout_starts <= MAX_STARTS:
        meta.fail("layout_starts", f"must lie between 1 and {MAX_STARTS}, got {layout_starts}")
    meta.done()

    panels = _Table(top.get("panels", {}), "panels", file)
    if not panels.has("size"):
        panels.missing("size", "give a positive number (model units)")
    sizes = _values(panels, "size", "model units", free=False)
    panels.done()

    design = _design(_Table(top.get("design", None) or {}, "design", file), folder)
    for size in sizes:
        _check_panel_units(size, design, file)
    strips = _strips(_Table(top.get("strips"), "strips", file)) if top.has("strips") else None
    limits, tolerances = _limits(_Table(top.get("limits", None) or {}, "limits", file),
                                 congruence_tolerance_mm=strips.congruence_tolerance_mm
                                 if strips else 0.1)
    cost = _cost(_Table(top.get("cost", {}), "cost", file))
    material = None
    if top.has("material"):
        table = top.get("material")
        if not isinstance(table, dict):
            raise InputError(f"{file}: [material] must be a table")
        material = material_from_table(table, f"{file}: material")
    fixed, searches = _candidates(top.get("candidates", "auto"), file)
    if searches and (len(sizes) > 1 or len(tolerances) > 1):
        raise InputError(f"{file}: a search ({searches[0].name}) and a sweep of panels.size or "
                         "limits.mold_tolerance_mm cannot go together; search at one size and "
                         "tolerance")
    candidates = _sweep(fixed, sizes, tolerances, file)
    top.done()
    return Study(name=name, path=path, description=description, design=design,
                 panel_size=sizes[0], limits=limits, strips=strips, cost=cost,
                 candidates=candidates, max_iterations=max_iterations,
                 layout_starts=int(layout_starts), searches=searches, material=material)


def _design(t: _Table, folder: Path) -> DesignSpec:
    from ..design.parametric import SURFACES

    surface, file = t.text("surface"), t.text("file")
    if (surface is None) == (file is None):
        t.fail("surface", "or design.file: give exactly one (a built-in surface name or a "
               "triangle-mesh or Rhino file)")
    parameters = t.get("parameters", {})
    if not isinstance(parameters, dict):
        t.fail("parameters", "must be a table of surface parameters")
    rhino_keys = [k for k in ("layer", "object", "face") if t.has(k)]
    if file is not None and Path(file).suffix.lower() == ".3dm":
        if parameters:
            t.fail("parameters", "belongs to a built-in surface, not to a design file")
        return _rhino_design(t, folder, file)
    if rhino_keys:
        t.fail(rhino_keys[0], "picks an object of a Rhino file: it belongs with a design.file "
               "ending in .3dm")
    units = t.text("units", "m", choices=tuple(MM_PER_UNIT))
    if file is not None:
        if parameters:
            t.fail("parameters", "belongs to a built-in surface, not to a design file")
        source = _resolved(t, "file", folder, file)
        if not source.is_file():
            t.fail("file", f"names {file!r}, which does not exist (looked in {folder})")
        if t.has("triangles"):
            t.fail("triangles", "belongs to a built-in surface; a design file keeps its own "
                   "triangles")
        t.done()
        return DesignSpec(str(source), Path(file).name, {}, None, units)
    triangles = _triangles(t)
    if surface is None or surface not in SURFACES:
        t.fail("surface", f"is {surface!r}, not a built-in surface; known: {', '.join(SURFACES)}"
               + _suggest(surface, SURFACES))
    items = []
    for key, value in parameters.items():
        if isinstance(value, list) and key in ("u_deg", "v_deg") and len(value) == 2:
            items.append(f"{key}={value[0]}..{value[1]}")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            items.append(f"{key}={value}")
        elif isinstance(value, str) and key in ("heights", "control_points", "profile"):
            target = _resolved(t, f"parameters.{key}", folder, value)
            if not target.is_file():
                t.fail(f"parameters.{key}", f"names {value!r}, which does not exist "
                       f"(looked in {folder})")
            items.append(f"{key}={target}")
        else:
            t.fail(f"parameters.{key}", f"has an unusable value {value!r}")
    t.done()
    spec = surface + (":" + ",".join(items) if items else "")
    _check_surface(spec, t)
    return DesignSpec(spec, surface, dict(parameters), triangles, units)


def _resolved(t: _Table, key: str, folder: Path, name: str) -> Path:
    """The file `name` of `key`, beside the study file; a name no file can have (a NUL
    character in it, too long for the system, a link loop) refused naming the key."""
    try:
        path = (folder / name).resolve()
        path.is_file()
    except (OSError, ValueError, RuntimeError) as exc:
        why = "a NUL character" if "\x00" in name else getattr(exc, "strerror", None) or exc
        shown = name if len(name) <= 80 else name[:77] + "..."
        t.fail(key, f"names {shown!r}, which cannot name a file ({why})")
    return path


def _triangles(t: _Table) -> int:
    """``design.triangles``: within the range of ``--triangles`` and the memory this run
    may use (`fabplan.io.resources.DESIGN_MEMORY`)."""
    from ..io.resources import DESIGN_MEMORY, memory_reason

    triangles = t.number("triangles", 20000, integer=True)
    t.within("triangles", triangles, "--triangles")
    reason = memory_reason(DESIGN_MEMORY, triangles)
    if reason is not None:
        t.fail("triangles", f"{triangles}: {reason}; give fewer")
    return triangles


def _rhino_design(t: _Table, folder: Path, file: str) -> DesignSpec:
    """A design in a .3dm file: the object that `layer`, `object` and `face` pick, read
    now so that a bad choice is named before the study starts. The model units are
    `units` when given (the file's coordinates converted to them), else the file's own
    unit system, else (a file without one) metres."""
    from ..io.rhino_read import read_3dm

    source = _resolved(t, "file", folder, file)
    if not source.is_file():
        t.fail("file", f"names {file!r}, which does not exist (looked in {folder})")
    layer, name = t.text("layer"), t.text("object")
    face = t.number("face", None, positive=False, integer=True)
    if face is not None and face < 0:
        t.fail("face", f"must be a face number (0, 1, ...), got {face}")
    asked = t.text("units", None, choices=tuple(MM_PER_UNIT))
    triangles = _triangles(t)
    t.done()
    read = read_3dm(source, layer=layer, object_name=name, face=face)
    if asked is not None and read.file_units is None:
        units = asked          # a unitless file is taken to be in the units the study says
    else:
        units = asked or read.file_units or "m"
    choice = {"layer": layer, "object": name, "face": None if face is None else str(face),
              "units": units if read.file_units is not None else None}
    fragment = ",".join(f"{k}={v}" for k, v in choice.items() if v is not None)
    return DesignSpec(f"{source}#{fragment}" if fragment else str(source), Path(file).name,
                      {k: v for k, v in choice.items() if v is not None and k != "units"},
                      triangles, units)


def _check_panel_units(panel_size: float, design: DesignSpec, file: str) -> None:
    """Refuse a panel size no building has in the design's units (a factor 10 beyond
    `PLAUSIBLE_PANEL_MM`): the units are wrong."""
    from ..io.units import PLAUSIBLE_PANEL_MM

    size_mm = panel_size * design.mm_per_unit
    low, high = PLAUSIBLE_PANEL_MM
    if not 0.1 * low <= size_mm <= 10 * high:
        other = "mm" if design.units == "m" else "m"
        raise InputError(f"{file}: panels.size {panel_size:g} {design.units} is {size_mm:g} mm, "
                         f"not a panel of a building: is the design in {other}? Set "
                         f'design.units = "{other}"')


def _check_surface(spec: str, t: _Table) -> None:
    """Build the parametric surface once, so that a bad parameter is named now."""
    from ..design.parametric import surface_from_spec

    try:
        surface_from_spec(spec)
    except InputError as exc:
        t.fail("parameters", f"do not describe a surface: {exc}")


def _limits(t: _Table, *, congruence_tolerance_mm: float = 0.1) -> tuple[Limits, list[float]]:
    """The limits (with the first mold tolerance) and every mold tolerance swept."""
    if not t.has("mold_tolerance_mm"):
        t.missing("mold_tolerance_mm", "give a positive number (mm)")
    tolerances = _values(t, "mold_tolerance_mm", "mm", free=False)
    limits = Limits(
        max_deviation_mm=t.number("max_deviation_mm", required=True, unit="mm"),
        mold_tolerance_mm=tolerances[0],
        max_molds=t.number("max_molds", integer=True),
        max_panel_step_mm=t.number("max_panel_step_mm", unit="mm"),
        planar_panels=t.boolean("planar_panels"),
        planarity_tolerance_mm=t.number("planarity_tolerance_mm", 2.0, unit="mm"),
        max_kink_deg=t.number("max_kink_deg", unit="degrees"),
        max_line_turn_deg=t.number("max_line_turn_deg", unit="degrees"),
        min_strip_radius_mm=t.number("min_strip_radius_mm", unit="mm"),
        max_strip_radius_mm=t.number("max_strip_radius_mm", unit="mm"),
        max_sheets=t.number("max_sheets", integer=True),
        congruent_strips=t.boolean("congruent_strips"),
        congruence_tolerance_mm=congruence_tolerance_mm,
        min_coverage=t.number("min_coverage"),
        max_sphere_residual=t.number("max_sphere_residual", 1e-6),
    )
    # the limits the study hands to the solver and the mold plan: their ranges there
    for tolerance in tolerances:
        t.within("mold_tolerance_mm", tolerance, "--tolerance-mm")
    t.within("max_panel_step_mm", limits.max_panel_step_mm, "--step-limit")
    t.within("max_line_turn_deg", limits.max_line_turn_deg, "--max-line-turn")
    for key in ("max_kink_deg", "max_line_turn_deg"):
        value = getattr(limits, key)
        if value is not None and not 0 < value < 180:
            t.fail(key, f"must lie between 0 and 180 degrees, got {value:g}")
    if limits.min_coverage is not None and limits.min_coverage > 1:
        t.fail("min_coverage", f"is a fraction of the design's area, at most 1; got "
               f"{limits.min_coverage:g}")
    lo, hi = limits.min_strip_radius_mm, limits.max_strip_radius_mm
    if lo is not None and hi is not None and lo > hi:
        t.fail("min_strip_radius_mm", f"({lo:g}) is larger than max_strip_radius_mm ({hi:g})")
    t.done()
    return limits, tolerances


def _strips(t: _Table) -> StripOptions:
    from ..fabricate.strips.strip_set import MAX_SHEET_MM

    sheet = t.get("sheet_mm", [2500.0, 1250.0])
    if (not isinstance(sheet, list) or len(sheet) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and 0 < v <= MAX_SHEET_MM for v in sheet)):
        t.fail("sheet_mm", f"must be [width, height] in mm (each at most {MAX_SHEET_MM:g}), "
               f"got {sheet!r}")
    nets = t.get("nets", "auto")
    if isinstance(nets, list):
        for net in nets:
            if net not in NETS:
                t.fail("nets", f"names an unknown net type {net!r}" + _suggest(net, NETS))
        nets = tuple(nets)
    elif nets not in ("auto", "all"):
        t.fail("nets", f"must be \"auto\", \"all\" or a list of net types, got {nets!r}")
    options = StripOptions(height_mm=t.number("height_mm", required=True, unit="mm"),
                           thickness_mm=t.number("thickness_mm", required=True, unit="mm"),
                           sheet_mm=(float(sheet[0]), float(sheet[1])), nets=nets,
                           congruence_tolerance_mm=t.number("congruence_tolerance_mm", 0.1,
                                                            unit="mm"))
    t.within("height_mm", options.height_mm, "--height")
    t.within("thickness_mm", options.thickness_mm, "--thickness")
    t.done()
    return options


def _cost(t: _Table) -> CostWeights:
    defaults = CostWeights()
    weights = {key: t.number(key, getattr(defaults, key), positive=False)
               for key in defaults.__dataclass_fields__}
    for key, value in weights.items():
        if value < 0:
            t.fail(key, f"must not be negative, got {value:g}")
    t.done()
    return CostWeights(**weights)


#: Most values one swept key may take.
MAX_SWEEP_VALUES = 50


@overload
def _values(t: _Table, key: str, unit: str, *, free: Literal[False]) -> list[float]: ...
@overload
def _values(t: _Table, key: str, unit: str, *, free: bool = ...) -> list[float | None]: ...
def _values(t: _Table, key: str, unit: str, *, free: bool = True) -> Sequence[float | None]:
    """A parameter as a list of values: a number, ``"free"`` (with `free`), a list, or a
    sweep ``{from, to, step}`` or ``{from, to, count}`` (both ends included)."""
    value = t.get(key)
    if free and (value is None or value == "free"):
        return [None]
    if isinstance(value, dict):
        sweep = _Table(value, f"{t.where}.{key}", t.file)
        lo = sweep.number("from", required=True, unit=unit)
        hi = sweep.number("to", required=True, unit=unit)
        if sweep.has("step") == sweep.has("count"):
            t.fail(key, "is a sweep: give either 'step' or 'count' with 'from' and 'to'")
        if hi < lo:
            t.fail(key, f"sweeps from {lo:g} down to {hi:g}: 'to' must not be below 'from'")
        if sweep.has("count"):
            count = sweep.number("count", 1, integer=True)
            if count == 1 and hi > lo:
                t.fail(key, "is a sweep of count 1: 'from' and 'to' must then be equal")
            step = (hi - lo) / max(count - 1, 1)
        else:
            step = sweep.number("step", required=True, unit=unit)
            count = int(math.floor((hi - lo) / step + 1e-9)) + 1
        sweep.done()
        if count > MAX_SWEEP_VALUES:
            t.fail(key, f"sweep has {count} values; at most {MAX_SWEEP_VALUES}")
        # rounded, so that names and cache keys read 1.25, not 1.2500000000000002
        return [round(lo + i * step, 9) for i in range(count)]
    items = value if isinstance(value, list) else [value]
    if not items:
        t.fail(key, "is an empty list")
    if len(items) > MAX_SWEEP_VALUES:
        t.fail(key, f"lists {len(items)} values; at most {MAX_SWEEP_VALUES}")
    out: list[float | None] = []
    for v in items:
        if free and v == "free":
            out.append(None)
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
            out.append(float(v))
        elif not free and not isinstance(value, list):
            t.fail(key, f"must be a positive number ({unit}), got {v!r}")
        else:
            t.fail(key, f"must be {chr(34) + 'free' + chr(34) + ', ' if free else ''}a positive "
                   f"number ({unit}), a list of them or {{ from = .., to = .., step = .. }} "
                   f"(or count = .. instead of step); got {v!r}")
    if len(set(out)) < len(out):
        t.fail(key, f"lists a value twice: {items!r}")
    return out


def _search(t: _Table, key: str, unit: str) -> tuple[float, float, int] | None:
    """``{ search = [low, high], budget = N }`` of `key`, or None when it is no search."""
    value = t.get(key)
    if not (isinstance(value, dict) and "search" in value):
        return None
    table = _Table(value, f"{t.where}.{key}", t.file)
    bounds = table.get("search")
    if not (isinstance(bounds, list) and len(bounds) == 2 and all(
            isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) and b > 0
            for b in bounds) and bounds[0] < bounds[1]):
        table.fail("search", f"must be [low, high], two positive numbers ({unit}) with low < "
                   f"high; got {bounds!r}")
    low, high, default = SEARCH_BUDGET
    budget = table.number("budget", default, integer=True)
    if not low <= budget <= high:
        table.fail("budget", f"must lie between {low} and {high} solves, got {budget}")
    table.done()
    return float(bounds[0]), float(bounds[1]), int(budget)


def _candidates(value: object, file: str) -> tuple[tuple[Candidate, ...], tuple[Search, ...]]:
    baseline = Candidate("baseline", "snet", baseline=True)
    searches: list[Search] = []
    if value == "auto":
        value = [{"net": "auto"}]
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise InputError(f"{file}: candidates must be \"auto\" or a list of [[candidates]] tables")
    out: list[Candidate] = [baseline]
    for i, entry in enumerate(value):
        t = _Table(entry, f"candidates[{i}]", file)
        net = t.text("net", required=True, choices=(*NETS, "auto"))
        if net == "auto":
            t.done()
            out += [Candidate(_name(n, a, r), n, a, r) for n, a, r in AUTO_CANDIDATES]
            continue
        preset = get_net(net)
        if preset.dual:
            t.fail("net", f"is the S*-net type {net!r}: studies lay out S-nets on the design; "
                   "optimize an S*-net from a study's net with `fabplan optimize`")
        searched = {key: found for key, unit in (("angle", "degrees"), ("radius", "model units"))
                    if (found := _search(t, key, unit)) is not None}
        if len(searched) > 1:
            t.fail("radius", "is searched with the angle: search one of them at a time")
        angles = [None] if "angle" in searched else _values(t, "angle", "degrees")
        radii = [None] if "radius" in searched else _values(t, "radius", "model units")
        label = t.text("name")
        if label is not None and not SAFE_NAME.fullmatch(label):
            t.fail("name", f"is {label!r}, {_SAFE_NAME_RULE}")
        start = t.number("start_angle", unit="degrees")
        if start is not None and not 0 < start < 180:
            t.fail("start_angle", f"must lie strictly between 0 and 180 degrees, got {start:g}")
        t.done()
        if angles != [None] and preset.angle != "param":
            t.fail("angle", f"does not apply to net type {net!r} (its angle is "
                   f"{'90 degrees' if preset.angle == 'right' else 'not constrained'})")
        if radii != [None] and preset.radius != "param":
            t.fail("radius", f"does not apply to net type {net!r}")
        if "angle" in searched and preset.angle != "param":
            t.fail("angle", f"does not apply to net type {net!r}: there is no angle to search")
        if "radius" in searched and preset.radius != "param":
            t.fail("radius", f"does not apply to net type {net!r}: there is no radius to search")
        lowest = float(OPTIONS["--angle"].low or 0)      # the solver's smallest angle
        if "angle" in searched and not lowest <= searched["angle"][0] <= searched["angle"][1] <= 90:
            t.fail("angle", f"search must lie in [{lowest:g}, 90] degrees, got "
                   f"{searched['angle'][0]:g} to {searched['angle'][1]:g}")
        if searched:
            if len(angles) * len(radii) > 1:
                t.fail("angle" if len(angles) > 1 else "radius", "sweeps while the other is "
                       "searched: search one parameter, the other fixed or free")
            (parameter, (low, high, budget)), = searched.items()
            searches.append(Search(label or net, net, parameter, low, high, budget,
                                   angle=angles[0], radius=radii[0], start_angle=start))
            continue
        for a in angles:
            if a is not None and not lowest <= a <= 90:
                t.fail("angle", f"must lie in [{lowest:g}, 90] degrees, got {a:g}: an isogonal "
                       f"net of angle a is the same net as one of 180 - a with the families "
                       f"swapped (ask for {180 - a:g})" if 90 < a < 180 else
                       f"must lie in [{lowest:g}, 90] degrees, got {a:g}")
        for r in radii:
            t.within("radius", r, "--radius")
        sweep = len(angles) * len(radii) > 1
        for a in angles:
            for r in radii:
                name = _name(net, a, r) if (label is None or sweep) else label
                if label is not None and sweep:
                    name = label + name[len(net):]
                out.append(Candidate(name, net, a, r, start_angle=start))
    names = [c.name for c in out]
    for c in out:
        if not SAFE_NAME.fullmatch(c.name):
            raise InputError(f"{file}: candidate name {c.name!r} {_SAFE_NAME_RULE}")
    for c in out:
        if names.count(c.name) > 1:
            raise InputError(f"{file}: two candidates are both called {c.name!r}; give them "
                             "different names (candidates[].name)")
    labels = [s.name for s in searches]
    for s in searches:
        if labels.count(s.name) > 1 or not SAFE_NAME.fullmatch(s.name):
            raise InputError(f"{file}: two searches are both called {s.name!r}, or the name is "
                             "not a safe folder name; give them names (candidates[].name)")
    return tuple(out), tuple(searches)


def _sweep(candidates: tuple[Candidate, ...], sizes: list[float], tolerances: list[float],
           file: str) -> tuple[Candidate, ...]:
    """Every candidate (the baseline included) at every swept panel size and mold
    tolerance, named with the swept values (``isogonal-60-p1.5-t2``); unswept studies
    keep their candidates as they are."""
    if len(sizes) == 1 and len(tolerances) == 1:
        return candidates
    out = []
    for c in candidates:
        for size in sizes:
            for tolerance in tolerances:
                name = c.name
                if len(sizes) > 1:
                    name += f"-p{size:g}"
                if len(tolerances) > 1:
                    name += f"-t{tolerance:g}"
                out.append(replace(c, name=name,
                                   panel_size=size if len(sizes) > 1 else None,
                                   mold_tolerance_mm=tolerance if len(tolerances) > 1 else None))
    if len(out) > MAX_CANDIDATES:
        raise InputError(f"{file}: the sweep makes {len(out)} candidates "
                         f"({len(candidates)} nets x {len(sizes)} panel sizes x "
                         f"{len(tolerances)} mold tolerances); at most {MAX_CANDIDATES}")
    for c in out:
        if not SAFE_NAME.fullmatch(c.name):
            raise InputError(f"{file}: candidate name {c.name!r} {_SAFE_NAME_RULE}")
    names = [c.name for c in out]
    twice = next((n for n in names if names.count(n) > 1), None)
    if twice is not None:
        raise InputError(f"{file}: two candidates of the sweep are both called {twice!r}; "
                         "give the candidates different names (candidates[].name)")
    return tuple(out)


#: Most candidates a study may expand into (a sweep of sweeps grows fast).
MAX_CANDIDATES = 1000


SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._+-]{0,63}")
"""A candidate name: it becomes a folder inside the study folder, so no separators, no
leading dot (no '..', no hidden folder) and nothing a shell or a file system mangles."""
_SAFE_NAME_RULE = ("which is not a safe folder name: use up to 64 letters, digits, '.', '_', "
                   "'+' and '-', starting with a letter, digit or '_' (no '/', '..' or spaces)")


def _name(net: str, angle: float | None, radius: float | None) -> str:
    name = net
    if angle is not None:
        name += f"-{angle:g}"
    if radius is not None:
        name += f"-r{radius:g}"
    return name


# ---------------------------------------------------------------------------- templates
def templates_folder() -> Path:
    """The folder of the bundled study templates (``templates/`` of the project)."""
    from importlib.util import find_spec

    try:
        spec = find_spec("fabplan.templates")
    except ModuleNotFoundError:
        spec = None
    for location in (spec.submodule_search_locations or []) if spec else []:
        if Path(location).is_dir():
            return Path(location)
    return Path(__file__).resolve().parents[2] / "templates"


def template_names() -> list[str]:
    """Names of the bundled templates (``templates/NAME.toml``), sorted."""
    return sorted(p.stem for p in templates_folder().glob("*.toml"))


def template_path(name: str) -> Path:
    """The study file of a bundled template.

    Raises
    ------
    InputError
        For an unknown template name (the message lists the known ones).
    """
    path = templates_folder() / f"{name}.toml"
    if not path.is_file():
        names = template_names()
        raise InputError(f"unknown template {name!r}; templates: {', '.join(names)}"
                         + _suggest(name, names))
    return path


def template_summary(name: str) -> str:
    """The one-line description of a template (its ``study.description``)."""
    data = tomllib.loads(template_path(name).read_text(encoding="utf-8"))
    text = str(data.get("study", {}).get("description", ""))
    return text.split(". ")[0].rstrip(".")


def resolve_study(source: str) -> Path:
    """A study file path from a path or a template name (a folder of the same name, such as
    an earlier study's output, does not hide the template)."""
    path = Path(source)
    if path.suffix.lower() == ".toml" or path.is_file():
        return path
    if path.is_dir() and source not in template_names():
        raise InputError(f"{source}: a folder, not a study file (a .toml file or a template "
                         f"name: {', '.join(template_names())})")
    return template_path(source)


def copy_template(name: str, destination: str | Path) -> list[Path]:
    """Copy a template (and the files it refers to beside it) to start a new study.

    Returns
    -------
    list of Path written. Refuses to overwrite an existing file.
    """
    from ..io.output import check_output_file, write_texts

    source = template_path(name)
    folder = str(destination).endswith(("/", os.sep)) or Path(destination).is_dir()
    destination = Path(destination)
    if not folder:
        check_output_file(destination)  # a device or FIFO is refused, not renamed .toml
    if folder:
        destination = destination / source.name
    elif destination.suffix.lower() != ".toml":
        destination = destination.with_suffix(".toml")
    study = read_study(source)
    files = {destination: source.read_text(encoding="utf-8")}
    referenced = [Path(study.design.source)] if Path(study.design.source).is_file() else []
    referenced += [Path(v.split("=", 1)[1]) for v in study.design.source.split(":", 1)[-1].split(",")
                   if "=" in v and Path(v.split("=", 1)[1]).is_file()]
    for path in referenced:
        files[destination.parent / path.name] = path.read_text(encoding="utf-8")
    for path in files:
        if path.exists():
            raise InputError(f"{path}: exists; refusing to overwrite it")
    write_texts(files)
    return list(files)
