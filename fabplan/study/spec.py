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

Owns reading a study file and its tables (`read_study`, `parse_study`); what it is read
into is `fabplan.study.definition` (its dataclasses are named here too), the
``[[candidates]]`` are expanded by `fabplan.study.candidates`, each table is read key by
key through `fabplan.study.table`, and the bundled templates are `fabplan.study.templates`.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import InputError
from ..fabricate.limits import DEFAULT_MAX_TWIST_DEG_PER_M
from ..fabricate.molds.materials import material_from_table
from ..io.inputs import check_input_file, check_text
from ..io.units import MM_PER_UNIT
from ..layout.settings import MAX_STARTS
from ..solve.net_types import NETS
from .candidates import AUTO_CANDIDATES, read_candidates, sweep_candidates, swept_values
from .checks import ANGLE_LIMITS, out_of_range
from .definition import (
    SEARCH_BUDGET,
    Candidate,
    CostWeights,
    DesignSpec,
    Limits,
    Search,
    StripOptions,
    Study,
)
from .table import Table, suggest

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
    "MAX_STUDY_BYTES",
    "AUTO_CANDIDATES",
]

#: The largest study file read (bytes of UTF-8): its tables fit in a few KB, with
#: `fabplan.study.candidates.MAX_CANDIDATES` candidates in about 40.
MAX_STUDY_BYTES = 256 * 1024
#: The tables of a study file.
TABLES = ("study", "design", "panels", "limits", "strips", "material", "cost", "candidates")


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
    if (size := path.stat().st_size) > MAX_STUDY_BYTES:
        raise _too_large(str(path), size)          # refused before it is read
    return parse_study(check_text(path, "TOML study"), path=path)


def _parsed(text: str, file: str) -> dict:
    """The tables of a study's TOML `text` (from `file`, for messages).

    Raises
    ------
    InputError
        When the text is over `MAX_STUDY_BYTES`, not valid TOML or nests too deep.
    """
    size = len(text.encode("utf-8", "surrogatepass")) if len(text) > MAX_STUDY_BYTES // 4 else 0
    if size > MAX_STUDY_BYTES:
        # parsing TOML costs about 0.1 s per 10,000 keys: a file the size of a data set
        # would keep the command busy for minutes before any check could refuse it
        raise _too_large(file, size)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{file}: not a valid TOML study file: {exc}") from None
    except RecursionError:
        # the parser recurses once per level of nested arrays and inline tables
        raise InputError(f"{file}: not a valid TOML study file: its arrays or tables nest "
                         "too deep (a study nests a few levels)") from None


def _too_large(file: str, size: int) -> InputError:
    """The refusal of a study file of `size` bytes, over `MAX_STUDY_BYTES`."""
    return InputError(f"{file}: a study file of {size:,} bytes: at most {MAX_STUDY_BYTES:,} "
                      "(its tables take a few thousand; profiles, heights and control points "
                      "go in the files it names)")


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
    top = Table(_parsed(text, file), "", file)
    top.only(TABLES)
    folder = path.parent if path else Path.cwd()

    meta = Table(top.get("study", {}), "study", file)
    name = meta.text("name", path.stem if path else "study")
    description = meta.text("description", "")
    max_iterations = meta.number("max_iterations", 100, integer=True)
    layout_starts = meta.number("layout_starts", 1, integer=True, positive=False)
    if not 1 <= layout_starts <= MAX_STARTS:
        meta.fail("layout_starts", f"must lie between 1 and {MAX_STARTS}, got {layout_starts}")
    meta.done()

    panels = Table(top.get("panels", {}), "panels", file)
    if not panels.has("size"):
        panels.missing("size", "give a positive number (model units)")
    sizes = swept_values(panels, "size", "model units", free=False)
    # the direction field's smoothing length, as `fabplan layout --smoothing` sets it
    smoothing = panels.number("smoothing", unit="panels")
    panels.within("smoothing", smoothing, "--smoothing")
    panels.done()

    design = _design(Table(top.get("design", None) or {}, "design", file), folder)
    for size in sizes:
        _check_panel_units(size, design, file)
    strips = _strips(Table(top.get("strips"), "strips", file)) if top.has("strips") else None
    limits, tolerances = _limits(Table(top.get("limits", None) or {}, "limits", file),
                                 congruence_tolerance_mm=strips.congruence_tolerance_mm
                                 if strips else 0.1)
    cost = _cost(Table(top.get("cost", {}), "cost", file))
    material = None
    if top.has("material"):
        table = top.get("material")
        if not isinstance(table, dict):
            raise InputError(f"{file}: [material] must be a table")
        material = material_from_table(table, f"{file}: material")
    fixed, searches = read_candidates(top.get("candidates", "auto"), file)
    if searches and (len(sizes) > 1 or len(tolerances) > 1):
        raise InputError(f"{file}: a search ({searches[0].name}) and a sweep of panels.size or "
                         "limits.mold_tolerance_mm cannot go together; search at one size and "
                         "tolerance")
    candidates = sweep_candidates(fixed, sizes, tolerances, file)
    top.done()
    return Study(name=name, path=path, description=description, design=design,
                 panel_size=sizes[0], limits=limits, strips=strips, cost=cost,
                 candidates=candidates, max_iterations=max_iterations,
                 layout_starts=int(layout_starts), searches=searches, material=material,
                 smoothing=smoothing)


def _design(t: Table, folder: Path) -> DesignSpec:
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
               + suggest(surface, SURFACES))
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


def _resolved(t: Table, key: str, folder: Path, name: str) -> Path:
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


def _triangles(t: Table) -> int:
    """``design.triangles``: within the range of ``--triangles`` and the memory this run
    may use (`fabplan.io.resources.DESIGN_MEMORY`)."""
    from ..io.resources import DESIGN_MEMORY, memory_reason

    triangles = t.number("triangles", 20000, integer=True)
    t.within("triangles", triangles, "--triangles")
    reason = memory_reason(DESIGN_MEMORY, triangles)
    if reason is not None:
        t.fail("triangles", f"{triangles}: {reason}; give fewer")
    return triangles


def _rhino_design(t: Table, folder: Path, file: str) -> DesignSpec:
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


def _check_surface(spec: str, t: Table) -> None:
    """Build the parametric surface once, so that a bad parameter is named now."""
    from ..design.parametric import surface_from_spec

    try:
        surface_from_spec(spec)
    except InputError as exc:
        t.fail("parameters", f"do not describe a surface: {exc}")


def _limits(t: Table, *, congruence_tolerance_mm: float = 0.1) -> tuple[Limits, list[float]]:
    """The limits (with the first mold tolerance) and every mold tolerance swept."""
    if not t.has("mold_tolerance_mm"):
        t.missing("mold_tolerance_mm", "give a positive number (mm)")
    tolerances = swept_values(t, "mold_tolerance_mm", "mm", free=False)
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
        max_twist_deg_per_m=t.number("max_twist_deg_per_m", DEFAULT_MAX_TWIST_DEG_PER_M,
                                     unit="deg/m"),
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
    for key in ANGLE_LIMITS:
        value = getattr(limits, key)
        if value is not None and (reason := out_of_range(key, value)) is not None:
            t.fail(key, f"{reason}, got {value:g}")
    if limits.min_coverage is not None and limits.min_coverage > 1:
        t.fail("min_coverage", f"is a fraction of the design's area, at most 1; got "
               f"{limits.min_coverage:g}")
    if not limits.max_twist_deg_per_m > 0:
        t.fail("max_twist_deg_per_m", f"must be positive, got {limits.max_twist_deg_per_m:g}")
    lo, hi = limits.min_strip_radius_mm, limits.max_strip_radius_mm
    if lo is not None and hi is not None and lo > hi:
        t.fail("min_strip_radius_mm", f"({lo:g}) is larger than max_strip_radius_mm ({hi:g})")
    t.done()
    return limits, tolerances


def _strips(t: Table) -> StripOptions:
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
                t.fail("nets", f"names an unknown net type {net!r}" + suggest(net, NETS))
        nets = tuple(nets)
    elif nets not in ("auto", "all"):
        t.fail("nets", f"must be \"auto\", \"all\" or a list of net types, got {nets!r}")
    options = StripOptions(height_mm=t.number("height_mm", required=True, unit="mm"),
                           thickness_mm=t.number("thickness_mm", required=True, unit="mm"),
                           sheet_mm=(float(sheet[0]), float(sheet[1])), nets=nets,
                           congruence_tolerance_mm=t.number("congruence_tolerance_mm", 0.1,
                                                            unit="mm"))
    t.within("congruence_tolerance_mm", options.congruence_tolerance_mm, "--tolerance")
    t.within("height_mm", options.height_mm, "--height")
    t.within("thickness_mm", options.thickness_mm, "--thickness")
    t.done()
    return options


def _cost(t: Table) -> CostWeights:
    defaults = CostWeights()
    weights = {key: t.number(key, getattr(defaults, key), positive=False)
               for key in defaults.__dataclass_fields__}
    for key, value in weights.items():
        if value < 0:
            t.fail(key, f"must not be negative, got {value:g}")
    t.done()
    return CostWeights(**weights)
