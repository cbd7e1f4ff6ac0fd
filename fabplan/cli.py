"""The `fabplan` command. Every subcommand is a thin wrapper over the Python API.

Exit codes: 0 success; 2 bad input or a solver that failed (one-line message, nothing
written); 3 the optimization stopped without converging (result written, with its
measured residuals and status), or some panels fit no mold (`molds`: report written, the
failures listed), or a part goes past a fabrication limit (`fabplan.fabricate.limits`:
files written, the limit and the excess named).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Iterator

from . import __version__
from .errors import CannotMakeError, FabplanError, InputError
from .fabricate.limits import (
    DEFAULT_MAX_ARC_ANGLE_DEG,
    DEFAULT_MAX_DEVIATION_MM,
    DEFAULT_MAX_TWIST_DEG_PER_M,
    limits_record,
)
from .io.inputs import check_input_file
from .io.output import (
    atomic_path,
    check_apart,
    check_output_file,
    check_output_folder,
    output_argument,
)
from .io.parameters import Parameter, option_parameter
from .io.records import write_json
from .io.units import DEFAULT_UNITS, MM_PER_UNIT, UNIT_WORDS, units_warning
from .net.buildable import BuildLimits
from .net.measure import format_summary, measure_net
from .net.validate import load_net, net_units_warning
from .report.html import counted, panel_areas
from .report.progress import Progress
from .solve.net_types import NETS, check_angle, check_radius
from .solve.optimize import (
    boundary_path,
    check_limits,
    check_net_input,
    optimize,
    read_fixed,
    read_handles,
)
from .solve.reference import load_reference
from .solve.solver import SolverSettings

__all__ = ["main"]

EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3


def _cmd_nets(args) -> int:
    width = max(len(n) for n in NETS)
    for net in NETS.values():
        print(f"{net.name:<{width}}  {net.summary}")
    return 0


def _cmd_measure(args) -> int:
    out = (output_argument(args.output) if args.output is not None
           else Path(args.net).with_suffix(".measure.json"))
    check_limits(args.max_deviation, args.max_line_turn)
    if args.max_deviation is not None and args.reference is None:
        raise InputError("--max-deviation needs --reference: the surface to measure the distance to")
    _check_outputs([out], {**_net_inputs(args.net), **_file_inputs((args.reference, "the reference"))})
    mesh = load_net(args.net)
    units = _net_units(args, args.net)
    _check_units(args, mesh, units)
    reference = _reference(args.reference)
    record = measure_net(mesh, reference=reference, limits=BuildLimits(
        max_line_turn_deg=args.max_line_turn, max_deviation=args.max_deviation))
    record["file"] = str(args.net)
    record["units"] = units
    write_json(out, record)           # the file first: the terminal may go away
    print(format_summary(record))
    print(f"wrote {out}")
    return 0


def _warn(message: str | None, quiet: bool = False) -> None:
    if message and not quiet:
        print(f"fabplan: warning: {message}", file=sys.stderr)


def _net_units(args: argparse.Namespace, net: str | os.PathLike | None, *,
               default: str = DEFAULT_UNITS) -> str:
    """The model units of a command's net: ``--units``, else those its record NET.json
    states (a layout's or optimize's ``properties.units``, a layout's design units), else
    `default`."""
    if args.units is not None:
        return args.units
    properties = _net_properties(Path(net)) if net else {}
    layout = properties.get("layout")
    recorded = properties.get("units") or (layout.get("design_units") if isinstance(layout, dict)
                                           else None)
    return recorded if recorded in MM_PER_UNIT else default


def _check_units(args: argparse.Namespace, mesh: Any, units: str) -> None:
    """Warn (or with ``--strict-units`` refuse now) when the net's size does not fit
    `units`; the warning comes after the run (`_warn_after`)."""
    _warn_after(args, net_units_warning(mesh, units, strict=args.strict_units))


def _warn_after(args: argparse.Namespace, message: str | None) -> None:
    """A warning printed when the command has run (`main`): a refusal on the way comes
    alone, without a warning before it."""
    if message:
        args.warnings_after = [*getattr(args, "warnings_after", []), message]


def _progress(args) -> Progress:
    """The run's progress output (`fabplan.report.progress`): a live line on a terminal,
    a line per stage and every few seconds off one; -q none, -v the solver's iterations."""
    return Progress(sys.stderr, quiet=getattr(args, "quiet", False),
                    verbose=getattr(args, "verbose", False))


def _check_outputs(outputs: list[Path], inputs: dict[Path, str]) -> None:
    """Refuse outputs that would overwrite an input or cannot be written, before working."""
    check_apart(outputs, inputs)
    for out in outputs:
        check_output_file(out)


def _net_inputs(net: str | os.PathLike | None, what: str = "the input net") -> dict[Path, str]:
    """A net file and the files beside it that fabplan reads back with it (its record
    ``NET.json`` and its boundary panels ``NET.boundary.obj``, where they exist): no
    output may replace them."""
    if not net:
        return {}
    path = Path(net)
    files = {path: what}
    # beside the path given, the file it links to and its other names (hard links)
    names = [path, Path(os.path.realpath(path))]
    try:
        info = os.stat(path)
        if info.st_nlink > 1:
            names += [Path(e.path) for e in os.scandir(path.parent or ".")
                      if e.name.lower().endswith(".obj") and e.inode() == info.st_ino]
    except OSError:
        pass
    for near in dict.fromkeys(names):
        if not near.name:           # '.', '/': a folder, refused where the net is read
            continue
        beside = {near.with_suffix(".json"): f"the record of {near.name}",
                  boundary_path(near): f"the boundary panels of {near.name}"}
        files.update({p: w for p, w in beside.items() if os.path.lexists(p)})
    return files


def _file_inputs(*options: tuple[str | None, str]) -> dict[Path, str]:
    """The files named by options that take a file or a design (`--fix`, `--reference`,
    a Rhino file with its choice after ``#``, a built-in surface whose parameters name
    files), with what each is."""
    from .design.load import design_files

    files = {}
    for value, what in options:
        if value:
            files.update(dict.fromkeys(design_files(value), what))
    return files


def _folder_apart(folder: Path, names: list[str], inputs: dict[Path, str]) -> None:
    """Refuse a run whose output folder holds an input under a name it writes (`names`:
    file names or patterns such as ``strips-sheet-*.dxf``), before the work."""
    import fnmatch

    for path, what in inputs.items():
        inside = os.path.dirname(os.path.realpath(path)) == os.path.realpath(folder)
        if inside and any(fnmatch.fnmatch(path.name, n) for n in names):
            check_apart([folder / path.name], {path: what})


def _check_option_files(*options: tuple[str | None, str]) -> None:
    """Name a folder, FIFO or device given to an option that reads a file (`--fix`,
    `--handle`, `--family`) as what it is, instead of "no such file" or a hang."""
    for value, what in options:
        if value and os.path.lexists(value):
            check_input_file(value, what)


def _output_path(args) -> Path:
    out = output_argument(args.output)
    if out.suffix.lower() != ".obj":
        raise InputError(f"{out}: the output must be an .obj file")
    inputs = {**_net_inputs(args.input), **_layout_design_inputs(args.input),
              **_file_inputs((args.reference, "the reference"),
                             (None if args.fix == "boundary" else args.fix, "the file of fixed vertices")),
              **{Path(h): "a handle file" for h in args.handle or [] if ":" not in h}}
    _check_outputs([out, out.with_suffix(".json"), boundary_path(out), *_viewer_paths(args, out)],
                   inputs)
    return out


def _layout_design_inputs(net: str) -> dict[Path, str]:
    """The design file a layout net's record names (``NET.json``), which `optimize`
    reads to cut the net's boundary panels again."""
    from .design.load import design_files

    layout = _net_properties(net).get("layout")
    source = layout.get("design_source") if isinstance(layout, dict) else None
    names = [source.get("file")] if isinstance(source, dict) else []
    if isinstance(layout, dict):
        # what `layout_again` loads the design from: its spec (an absolute path for a file)
        names += [layout.get("design_spec"), layout.get("design")]
    return {path: f"the design of {Path(net).name}" for n in names
            if isinstance(n, str) and n for path in design_files(n) if path.is_file()}


class _IterationReport:
    """The solver's progress callback: each iteration to `progress` (a line each with -v;
    the live line of `stage` on a terminal)."""

    def __init__(self, progress: Progress):
        self.progress = progress
        self.stage: Any = None
        self.prefix = ""         # which of several solves (`fabplan layout`'s starts)

    def __call__(self, rec: Any) -> None:
        # a multilevel start solves coarse nets first, each counting its own iterations
        net = self.prefix + (f"coarse net of {rec.coarse_vertices:,} vertices, "
                             if rec.coarse_vertices else "")
        if self.stage is not None:
            self.stage.note(f"{net}iteration {rec.iteration}, residual {rec.hard_residual:.2e}")
        self.progress.iteration(f"{net}iteration {rec.iteration:3d}  residual "
                                f"{rec.hard_residual:.3e}  step {rec.step:.2e}  "
                                f"{rec.seconds * 1000:.0f} ms")


def _solver_options(args, progress: Progress) -> tuple[SolverSettings, _IterationReport]:
    """Solver settings from --max-iter, and the callback that reports the iterations."""
    settings = SolverSettings()
    if args.max_iter is not None:
        settings.max_iterations = args.max_iter
    if getattr(args, "no_multilevel", False):
        settings.multilevel = False
    return settings, _IterationReport(progress)


def _warn_not_converged(result, json_path: Path) -> None:
    what = {"iteration cap": "stopped at the iteration cap", "folded": "ended folded",
            "degenerate": "ended degenerate", "crumpled": "ended crumpled",
            "off-design": "ended off the design"}.get(
        result.status, f"stopped ({result.status})")
    said = f"stopped ({result.status}) "
    # the status is said once: "stopped (stagnated) with ..." continues the sentence
    message = (" " + result.message[len(said):] if result.message.startswith(said)
               else ": " + result.message)
    print(f"fabplan: warning: the optimization {what}{message} (details in {json_path})",
          file=sys.stderr)


def _listing(paths: list[Path]) -> str:
    """'a, b and c'"""
    names = [str(p) for p in paths]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _viewer_paths(args: argparse.Namespace, base: Path) -> list[Path]:
    """OUT.3dm and OUT.glb when `--3dm` asks for them, OUT.html when `--html` does, OUT.ifc
    when `--ifc` does (checked before any work)."""
    return ([base.with_suffix(".3dm"), base.with_suffix(".glb")] if args.rhino else []) + (
        [base.with_suffix(".html")] if getattr(args, "html", False) else []) + (
        [base.with_suffix(".ifc")] if getattr(args, "ifc", False) else [])


@contextmanager
def _html_file(args: argparse.Namespace, base: Path) -> Iterator[Path | None]:
    """With `--html`: the staged path of ``BASE.html``, moved into place when the block
    (writing the command's other files) succeeds, and gone when it fails."""
    if not args.html:
        yield None
        return
    with atomic_path(base.with_suffix(".html")) as staged:
        yield staged


@contextmanager
def _viewer_files(args: argparse.Namespace, base: Path, mesh: Any, *, units: str,
                  molds: Any = None, strips: Any = None, boundary: Any = None,
                  net_type: str | None = None) -> Iterator[list[Path]]:
    """With `--3dm`: the net as Rhino ``BASE.3dm`` (mesh, polylines per family, panels per
    mold, strip curves) and ``BASE.glb`` (coloured by mold) for web viewers; with `--ifc`
    the facade plan as ``BASE.ifc`` (`fabplan.io.ifc`: panels with `boundary` panels,
    molds, lamellas, nodes).

    They are written before the block (the command's other files) runs and land only when
    it succeeds, so that a failure leaves neither them nor the other files behind.
    """
    with ExitStack() as stack:
        written = []
        if args.rhino:
            from .study.api import write_3dm, write_glb

            rhino, glb = base.with_suffix(".3dm"), base.with_suffix(".glb")
            write_3dm(mesh, stack.enter_context(atomic_path(rhino)), molds=molds, strips=strips,
                      units=units)
            write_glb(mesh, stack.enter_context(atomic_path(glb)), molds=molds, units=units)
            written += [rhino, glb]
        if getattr(args, "ifc", False):
            from .study.api import write_ifc

            ifc = base.with_suffix(".ifc")
            write_ifc(mesh, stack.enter_context(atomic_path(ifc)), molds=molds, boundary=boundary,
                      strips=strips, units=units, net_type=net_type, name=Path(base).name)
            written.append(ifc)
        yield written


def _reference(spec: str | None):
    """A reference surface from a mesh file, a Rhino file or a built-in surface spec
    (`fabplan layout`)."""
    from .io.rhino_read import is_3dm_source

    if spec is None:
        return None
    from .design.load import load_design, names_a_file

    if not is_3dm_source(spec) and names_a_file(spec):
        return load_reference(spec)

    return load_design(spec).reference


def _cmd_optimize(args) -> int:
    check_angle(args.angle)
    check_radius(args.radius)
    check_limits(args.max_deviation, args.max_line_turn)
    _check_option_files((None if args.fix == "boundary" else args.fix, "a file of vertex ids"),
                        *[(h, "a file of handles") for h in args.handle or []])
    out = _output_path(args)
    mesh = load_net(args.input)
    check_net_input(mesh)
    units = _net_units(args, args.input)
    _check_units(args, mesh, units)
    reference = _reference(args.reference)
    fixed = read_fixed(args.fix, mesh)
    handles = read_handles(args.handle)
    progress = _progress(args)
    settings, report = _solver_options(args, progress)
    with progress.stage("solving") as stage:
        report.stage = stage
        result = optimize(mesh, args.net, angle=args.angle, radius=args.radius,
                          reference=reference, fixed=fixed, handles=handles, settings=settings,
                          coherent=args.coherent, guards=args.guards,
                          settle_free=0.0 if args.settle_free else None,
                          max_deviation=args.max_deviation, max_line_turn=args.max_line_turn,
                          progress=report)
    result.properties["units"] = units
    limits = []
    if reference is not None:
        limits = [deviation_check(reference.distances(result.mesh.vertices), units=units,
                                  max_deviation=args.max_deviation, option="--max-deviation")]
        result.properties["limits"] = limits_record(limits)
    panels_note = _boundary_panels_again(Path(args.input), mesh, result, progress)
    with progress.stage("writing the net" + (" and its page" if args.html else "")), \
            _html_file(args, out) as page, \
            _viewer_files(args, out, result.mesh, units=units, boundary=result.boundary_panels,
                          net_type=result.net) as viewers:
        if page is not None:
            from .layout.view import net_view_html
            from .solve.reference import ReferenceSurface

            page.write_text(net_view_html(
                result, title=f"{result.net} net: {out.name}",
                subtitle=f"fabplan optimize {Path(args.input).name}: {result.status} after "
                         f"{counted(result.iterations, 'iteration')}; model units {units}",
                surface=reference if reference is not None else ReferenceSurface.from_mesh(mesh),
                deviation_from="the reference", units=units,
                picture_caption=f"{result.net} net {out.name}"), encoding="utf-8")
        obj_path, json_path = result.write(out)
    if page is not None:
        viewers = [out.with_suffix(".html"), *viewers]
    params = ", ".join(f"{k} {v:.6g}" for k, v in result.parameters.items()
                       if isinstance(v, float))
    if not args.quiet:
        print(format_summary(result.properties))
        print(f"{result.net}: {result.status} after {result.iterations} iterations in "
              f"{result.seconds:.2f} s" + (f" ({params})" if params else ""))
        for check in limits:
            print(f"limit: {check.text()}")
    written = [obj_path, json_path]
    if result.boundary_panels is not None:
        written.append(boundary_path(out))
    print(f"wrote {_listing([*written, *viewers])}" if not args.quiet else
          f"{result.net}: {result.status} after {result.iterations} iterations; wrote {obj_path}")
    if panels_note:
        print(f"fabplan: note: {panels_note}", file=sys.stderr)
    elif result.boundary_panels is not None:
        panels = result.properties.get("boundary_panels") or {}
        lift = panels.get("offset_from_design_max_relative_to_panel") or 0.0
        if panels.get("follow_net") and lift > 1e-3:
            print(f"fabplan: note: the boundary panels continue the net where it stands off the "
                  f"design: their points between the net and the design boundary stand off the "
                  f"design as the net does beside them, by up to {lift:.3g} of the panel size "
                  "(properties.boundary_panels.offset_from_design_max_relative_to_panel)",
                  file=sys.stderr)
        for warning in boundary_warnings(result.properties):
            _warn(warning)
    if not result.converged:
        _warn_not_converged(result, json_path)
        return EXIT_NOT_CONVERGED
    return _limits_exit(limits, json_path)


def deviation_check(distances: Any, *, units: str, max_deviation: float | None = None,
                    option: str = "--max-deviation-mm") -> Any:
    """The net's vertices against the deviation limit (`fabplan.fabricate.limits`).

    Parameters
    ----------
    distances : (n,) float, each vertex's distance from the design or reference (model
        units).
    units : the model units (`MM_PER_UNIT` key).
    max_deviation : the limit in model units (``optimize --max-deviation``); None for the
        default in mm.
    option : the option that changes the limit.
    """
    import numpy as np

    from .fabricate.limits import DEFAULT_MAX_DEVIATION_MM, limit_check

    mm = MM_PER_UNIT[units]
    bound = DEFAULT_MAX_DEVIATION_MM if max_deviation is None else max_deviation * mm
    return limit_check("max_deviation_mm", np.asarray(distances, dtype=np.float64) * mm, bound,
                       parts="vertices", option=option)


def _boundary_panels_again(source: Path, mesh, result, progress) -> str | None:
    """Trim an optimized layout net to its design again, as its layout did: the layout
    recorded in ``NET.json`` is made again (`layout_again`) and, when it gives the net's
    faces, the optimized net's boundary panels are cut from it. Only for a net with a
    ``NET.boundary.obj`` beside it. Returns a note when the panels could not be cut."""
    import numpy as np

    from .layout.surface_layout import layout_again
    from .layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels

    old = boundary_path(source)
    if not old.is_file():
        return None
    lost = (f"the boundary panels of {old} belong to the net before it was optimized and "
            "were not carried over")
    layout_record = _net_properties(source).get("layout")
    if not isinstance(layout_record, dict):
        return f"{lost}: {source.with_suffix('.json')} does not record the layout to cut them from"
    with progress.stage("cutting the boundary panels again"):
        try:
            layout = layout_again(layout_record)
        except (InputError, OSError) as exc:
            return f"{lost}: its layout could not be made again ({exc})"
        same = len(layout.mesh.faces) == len(mesh.faces) and all(
            np.array_equal(a, b) for a, b in zip(layout.mesh.faces, mesh.faces, strict=True))
        if not same:
            return f"{lost}: the net's faces are not those of the layout in {source.with_suffix('.json')}"
        if add_boundary_panels(result, layout, touch=OFF_DESIGN_TOUCH, follow_net=True) is None:
            return f"{lost}: {result.properties['boundary_panels']['error']}"
    return None


def _cmd_molds(args) -> int:
    import numpy as np

    from .fabricate.molds import MoldSettings, plan_molds
    from .fabricate.molds.boundary_molds import boundary_molds, boundary_molds_text
    from .fabricate.molds.materials import parse_material
    from .fabricate.molds.mold_report import MOLD_FILES, write_mold_report
    from .fabricate.molds.panels import check_panels
    from .layout.trim import read_boundary_panels

    settings = MoldSettings(tolerance_mm=args.tolerance_mm, units=_net_units(args, args.net),
                            max_mold_size_mm=args.max_mold_size, panel_surface=args.panel_surface,
                            step_limit_mm=args.step_limit,
                            material=None if args.material is None else parse_material(args.material))
    settings.check()
    if args.design is None and args.panel_surface == "design":
        raise InputError("--panel-surface design needs --design SURFACE, the design the net lies on")
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**_net_inputs(args.net), **_file_inputs((args.boundary, "the boundary panels"),
                                                      (args.design, "the design"))}
    _folder_apart(out, [*MOLD_FILES, "net.3dm", "net.glb", "net.ifc"], inputs)
    mesh = load_net(args.net, quads=False)   # every polygon is a panel
    check_panels(mesh)
    _check_net_memory(args, mesh, "molds")
    _check_units(args, mesh, settings.units)
    design = None
    if args.design is not None:
        from .design.load import load_design

        _check_triangles(args.design, args.triangles)
        design = load_design(args.design, triangles=args.triangles)
        if args.panel_surface == "design":
            _check_net_on_design(args, mesh, design)
    boundary_file = _boundary_file(args)
    panels = None if boundary_file is None else read_boundary_panels(
        mesh, boundary_file, _boundary_record(args))
    progress = _progress(args)
    with progress.stage(f"fitting molds to {len(mesh.face_sizes)} panels"):
        plan = plan_molds(mesh, settings, design=design)
    limits = []
    if design is not None:
        limits = [deviation_check(design.distances(mesh.vertices), units=settings.units,
                                  max_deviation=args.max_deviation_mm / MM_PER_UNIT[settings.units])]
    boundary = None
    if panels is not None:
        # each boundary panel on a mold of the net's panels, placed to meet its
        # neighbours (a mold of its own where none does)
        with progress.stage(f"placing {panels.panel_count} boundary panels on the molds"):
            boundary = (panels, boundary_molds(plan, panels))
    with progress.stage("writing the report"), \
            _viewer_files(args, out / "net", mesh, units=settings.units, molds=plan,
                          boundary=None if boundary is None else boundary[1],
                          net_type=_net_properties(args.net).get("net")) as viewers:
        files = write_mold_report(plan, out, view_3d=not args.no_3d, boundary=boundary,
                                  protect=inputs, limits=limits) + viewers
    if args.quiet:
        made = "" if plan.classes is None else f" ({plan.made_mold_count} made for the molded panels)"
        print(f"{counted(plan.panel_count, 'panel')} on {counted(plan.mold_count, 'mold')}{made} "
              f"at {settings.tolerance_mm:g} mm; wrote {files[0]}")
    else:
        print(plan.summary())
        if boundary is not None:
            print(boundary_molds_text(boundary[1], plan.mold_count, boundary_file))
        for check in limits:
            print(f"limit: {check.text()}")
        print(f"wrote {', '.join(str(f) for f in files)}")
    molds = None if boundary is None else boundary[1]
    over = np.zeros(0, np.int64) if molds is None else molds.steps_over_limit
    if molds is not None and over.size:
        one = over.size == 1
        slivers = int(molds.extension[over].sum())
        print(f"fabplan: warning: {counted(over.size, 'boundary panel')} step{'s' if one else ''} "
              f"against a neighbour by up to {molds.step_mm[over].max():.2f} mm (limit "
              f"{molds.step_limit_mm:g} mm; ids in {boundary_file}: {over.tolist()[:10]}"
              + (f", {counted(slivers, 'sliver')} cut with its full panel among them"
                 if slivers else "")
              + "): trim them by hand or give a looser tolerance", file=sys.stderr)
    if plan.failures.size:
        too_large = sum("needs a mold of" in (plan.problem[i] or "") for i in plan.failures)
        why = []
        if too_large:
            why.append(f"{too_large} need a mold larger than --max-mold-size "
                       f"{settings.max_mold_size_mm:g} mm")
        if plan.failures.size - too_large:
            why.append(f"{plan.failures.size - too_large} deviate from every mold by more than "
                       f"{settings.tolerance_mm:g} mm")
        print(f"fabplan: warning: {counted(plan.failures.size, 'panel')} fit no mold "
              f"({'; '.join(why)}); they are listed in {out / 'report.html'}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    if not plan.fits_all:
        print(f"fabplan: warning: the molds of neighbouring panels step up to "
              f"{plan.max_step_mm:.2f} mm apart at {plan.steps_over.size} shared edges "
              f"(limit {plan.step_limit_mm:g} mm); see the step map in {out / 'report.html'}",
              file=sys.stderr)
        return EXIT_NOT_CONVERGED
    if over.size:
        return EXIT_NOT_CONVERGED
    return _limits_exit(limits, out / "molds.json")


def _cmd_mill(args) -> int:
    from .fabricate.milling import MillSettings, parse_tool
    from .fabricate.milling.mill_report import MILL_FILES, mill_net, write_mill_report
    from .fabricate.milling.mill_simulation import SimulationSettings

    tool = parse_tool(args.tool)
    settings = MillSettings(along=args.along, units=_net_units(args, args.net, default="mm"),
                            margin_mm=args.margin,
                            scallop_mm=args.scallop, side=args.side, paths_on=args.paths_on)
    settings.check()
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**_net_inputs(args.net), **_file_inputs((args.design, "the design")),
              **_layout_design_inputs(args.net)}
    _folder_apart(out, [*MILL_FILES, "paths.3dm"], inputs)
    mesh = load_net(args.net)
    _check_net_memory(args, mesh, "mill")
    if not args.no_simulation:
        _check_simulation_memory(mesh, settings.mm_per_unit, args.sim_step)
    progress = _progress(args)
    with progress.stage("reading the design"):
        design = _mill_design(args, settings.units)
    with progress.stage("planning the passes and simulating the cut"):
        result = mill_net(mesh, tool, settings, simulate=not args.no_simulation,
                          simulation=SimulationSettings(step_mm=args.sim_step), design=design)
    with progress.stage("writing the tool paths and the report"):
        files = write_mill_report(result, out, rhino=args.rhino, protect=inputs)
    if args.quiet:
        print(f"{counted(result.plan.path.pass_count, 'pass', 'passes')}; wrote {files[0]}")
    else:
        print(result.summary())
        print(f"wrote {', '.join(str(f) for f in files)}")
        for note in result.plan.notes:
            _warn(note)
    if not result.gouge_free and result.simulation is not None:
        # a margin keeps the tool inside the spheres; a face wider than the surface's
        # curvature allows over its width gouges whatever the margin
        why = "try a smaller tool or a larger --margin"
        distance = result.net_distance
        if distance is not None and result.plan.placed_on == "net":
            why = (f"the passes follow the net, which is up to "
                   f"{distance.vertex_max_mm:.4g} mm off the design: place them on "
                   "the design (--paths-on design) or give a larger --margin")
        print(f"fabplan: warning: the simulated cut gouges "
              f"{'the net' if result.design is None else 'the design'} by "
              f"{result.simulation.max_gouge_mm:.4g} mm: {why} "
              f"(details in {out / 'report.html'})", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def _mill_design(args: argparse.Namespace, units: str) -> Any:
    """The design `fabplan mill` measures against: ``--design``, else the design the
    net's record (``NET.json``, a layout's) names, else None (the net's own surface).

    A design its record names that cannot be loaded again (a file moved) is said in a
    warning, and the net's surface is measured instead. A design whose file states other
    units than the net's is scaled to the net's."""
    from .design.load import load_design

    design = None
    if args.design is not None:
        design = load_design(args.design, triangles=args.triangles)
    else:
        layout = _net_properties(args.net).get("layout")
        spec = (layout.get("design_spec") or layout.get("design")) if isinstance(layout, dict) else None
        if isinstance(spec, str) and spec:
            assert isinstance(layout, dict)
            resolution = layout.get("design_resolution")
            try:
                design = load_design(spec, triangles=int(layout.get("design_triangles") or 40000),
                                     resolution=None if resolution is None else tuple(resolution))
            except (InputError, OSError) as exc:
                _warn_after(args, f"the design {spec} that {Path(args.net).with_suffix('.json')} "
                                  f"names could not be read ({exc}): the cut was measured "
                                  "against the net's surface")
                return None
    if design is not None and design.units is not None and design.units != units \
            and design.units in MM_PER_UNIT:
        from .design.mesh_surface import DesignSurface

        scale = MM_PER_UNIT[design.units] / MM_PER_UNIT[units]
        scaled = DesignSurface(design.vertices * scale, design.triangles, name=design.name)
        scaled.units = units
        return scaled
    return design


def _check_layout_options(args: argparse.Namespace, preset: Any) -> None:
    """Refuse options of `fabplan layout` that cannot go together, before any work."""
    check_angle(args.angle)
    if args.family is not None and args.angle is not None:
        raise InputError("--family and --angle exclude each other: the prescribed family "
                         "decides the angle")
    if preset.angle == "right" and args.angle not in (None, 90.0):
        raise InputError(f"net type {preset.name!r} is orthogonal; --angle must be 90 or omitted")
    if args.family is not None and preset.angle != "none":
        raise InputError(f"--family and net type {preset.name!r} exclude each other: a prescribed "
                         "family decides the angle, which this net type fixes (use snet, "
                         "const-radius, anet or char-conjugate)")


def _start_text(start: dict) -> str:
    """One start of `fabplan layout` (`fabplan.layout.starts`) in a few words."""
    text = f"{start['start']}{' (kept)' if start['chosen'] else ''}: {start['status']}"
    if start["status"] == "refused":
        return f"{text}: {start['message']}"
    turn = start.get("line_turn_p95_deg")
    edges = start.get("edge_length_relative_to_panel") or {}
    return (text + f", coverage {100 * (start.get('coverage') or 0):.2f} %"
            + ("" if turn is None else f", lines turn {turn:.1f} deg at the 95th percentile")
            + (f", edges {edges['min']:.2f} .. {edges['max']:.2f} panels" if edges else "")
            + (f" ({start['less_even_than_first']} than {start['compared_with']}'s)"
               if start.get("less_even_than_first") else "")
            + f", {start['seconds']:.1f} s")


def _print_layout_report(props: dict, layout: Any, json_path: Path) -> None:
    """What `fabplan layout` measured on its net, and what a user should know about it."""
    print(format_summary(props))
    d = props["distance_to_design"]
    rel = props["distance_to_design_relative_to_panel"]
    print(f"distance to the design surface: max {d['max']:.3e} ({rel['max']:.2e} of the panel "
          f"size), mean {d['mean']:.3e} ({rel['mean']:.2e})")
    edge = props["edge_length_relative_to_panel"]
    record = props["layout"]
    print(f"net: {record['quads']} quads covering {100 * props['coverage_net']:.1f} % of the design, "
          f"{boundary_text(props)}; "
          f"edges {edge['min']:.3f} .. {edge['max']:.3f} of the panel size; "
          f"{len(record['irregular_vertices'])} irregular vertices "
          f"{record['irregular_vertices'][:12]}{' ...' if len(record['irregular_vertices']) > 12 else ''}; "
          f"{record['gliding_boundary_vertices']} of {record['boundary_vertices']} boundary vertices "
          "glide on the surface boundary")
    # welding is how STL files are read: the other repairs change the design
    changed = [f"{v} {k.replace('_', ' ')}" for k, v in (record.get("design_repairs") or {}).items()
               if v and k != "welded_vertices"]
    if changed:
        print(f"fabplan: note: the design was repaired as it was read: {', '.join(changed)} "
              "(properties.layout.design_repairs)", file=sys.stderr)
    starts = props.get("layout_starts") or []
    if len(starts) > 1:
        print("starts (the fairest kept):")
        for start in starts:
            print(f"  {_start_text(start)}")
        for start in props.get("layout_starts_left_out") or []:
            print(f"  {start['start']}: left out ({start['why']})")
    if len(layout.turning_points):
        where = ", ".join(f"({', '.join(f'{c:.4g}' for c in p)})" for p in layout.turning_points[:3])
        print(f"fabplan: warning: the principal directions turn by up to "
              f"{layout.turning_deg.max():.0f} deg within one panel at {len(layout.turning_points)} "
              f"place{'s' if len(layout.turning_points) > 1 else ''} ({where}"
              f"{', ...' if len(layout.turning_points) > 3 else ''}: umbilics or near-umbilics): "
              "the net's lines cannot follow them there, and the solve is likely to stagnate "
              "or fold; a design without these near-umbilics (its curvature smoothed there) "
              "avoids it", file=sys.stderr)
    if len(layout.singular_points):
        print(f"fabplan: note: the direction field is singular at {len(layout.singular_points)} "
              f"points (umbilics or seam ends, listed in {json_path.name}); "
              f"{record['filled_holes']} holes around them were closed with irregular vertices, "
              f"{record['open_holes']} left open; the rest of the layout is regular",
              file=sys.stderr)


def _cmd_layout(args) -> int:
    from .design.load import load_design
    from .layout.picture import fairness_marks, write_layout_picture
    from .layout.settings import LayoutSettings
    from .layout.starts import glide_fairest
    from .layout.surface_layout import layout_angle
    from .solve.net_types import get_net
    from .solve.optimize import boundary_path

    preset = get_net(args.net)
    _check_layout_options(args, preset)
    check_limits(None, args.max_line_turn)
    out = output_argument(args.output)
    if out.suffix.lower() != ".obj":
        raise InputError(f"{out}: the output must be an .obj file")
    picture = out.with_suffix(".png")
    _check_option_files((args.family, "a file of polylines"))
    family_file = args.family if args.family and Path(args.family).is_file() else None
    _check_outputs([out, out.with_suffix(".json"), boundary_path(out), picture,
                    *_viewer_paths(args, out)],
                   _file_inputs((args.surface, "the design"), (family_file, "the family file")))
    _check_triangles(args.surface, args.triangles)
    design = load_design(args.surface, triangles=args.triangles)
    if design.source is not None and not args.quiet:
        print(f"design: {design.source['object']} of {design.source['file']}, in "
              f"{_units_said(design.units)}" + (f" (converted from {design.source['file_units']})"
                                                if design.source["scale"] != 1 else ""))
    units = _design_units(args, design)
    _check_layout_size(design, args.panel_size, args.max_panels)
    _warn_after(args, units_warning(Path(design.name).name, units, panel=args.panel_size,
                                    extent=design.extent, strict=args.strict_units))
    progress = _progress(args)    # after the checks: a refusal is one line on its own
    start = layout_angle(preset.name, design, args.angle) if args.family is None else 90.0
    settings_layout = (LayoutSettings() if args.smoothing is None else
                       LayoutSettings(smoothing=args.smoothing, smoothing_tries=()))
    settings, report = _solver_options(args, progress)
    with progress.stage("laying out the net and solving it on the design") as stage:
        report.stage = stage

        def starting(k: int, n: int, name: str) -> None:
            if n > 1:
                report.prefix = f"start {k + 1} of {n} ({name}), "
                stage.note(report.prefix.rstrip(", "))

        layout, result = glide_fairest(
            design, args.panel_size, preset.name, angle=start,
            net_angle=args.angle if preset.angle == "param" else None, family=args.family,
            settings=settings_layout, solver=settings, starts=args.starts,
            vary_smoothing=args.smoothing is None, progress=report, on_start=starting,
            max_line_turn=args.max_line_turn)
    result.properties["units"] = units
    angle = result.parameters.get("angle_deg")
    title = (f"{preset.name} on {Path(design.name).name}, panel {args.panel_size:g}"
             + (f", {layout.family}" if layout.family else
                f", {angle:.4g} deg" if isinstance(angle, float) else ""))
    # the picture and the Rhino files land only with the net they show
    with progress.stage("writing the net and its picture" + (" and page" if args.html else "")), \
            atomic_path(picture) as staged, _html_file(args, out) as page, \
            _viewer_files(args, out, result.mesh, units=units, boundary=result.boundary_panels,
                          net_type=result.net) as viewers:
        write_layout_picture(staged, design, result.mesh, title=title,
                             singular_points=layout.singular_points,
                             marks=fairness_marks(result.properties),
                             boundary_panels=result.boundary_panels)
        if page is not None:
            import numpy as np

            from .layout.picture import curvature_difference_figure, kink_text
            from .layout.view import net_view_html

            # marks given as a vertex id are put where the vertex is
            marks = {}
            for label, at in fairness_marks(result.properties).items():
                where = np.asarray(at)
                marks[label] = result.mesh.vertices[int(where)] if where.ndim == 0 else where
            kinks = curvature_difference_figure(
                design, args.panel_size, marks=marks, singular_points=layout.singular_points,
                title=f"|k1 - k2| of {Path(design.name).name}, panel {args.panel_size:g}")
            page.write_text(net_view_html(
                result, title=f"Layout: {title}",
                subtitle=f"fabplan layout {args.surface}: {result.status} after "
                         f"{counted(result.iterations, 'iteration')}; model units {units}",
                surface=design, units=units, picture_png=staged.read_bytes(),
                picture_caption=f"{picture.name}: the net (blue) on the design (grey), boundary "
                                "panels green, the places its lines turn most marked",
                figures_after=((kinks, "Where the design makes lines kink: the design coloured "
                                "by |k1 - k2| times the panel size. "
                                + kink_text(design, args.panel_size, result.properties),
                                "Dark places are near umbilics: there the principal directions "
                                "turn fast or are not defined, and the lines of any S-net "
                                "must turn with them. The marks are the net's sharpest turns "
                                "and the direction field's singular points."),)),
                encoding="utf-8")
        obj_path, json_path = result.write(out)
    if page is not None:
        viewers = [out.with_suffix(".html"), *viewers]
    props = result.properties
    starts = props.get("layout_starts") or []
    params = ", ".join(f"{k} {v:.6g}" for k, v in result.parameters.items() if isinstance(v, float))
    if args.quiet:
        print(f"{result.net}: {result.status} after {result.iterations} iterations; wrote "
              f"{obj_path}")
    else:
        _print_layout_report(props, layout, json_path)
        print(f"{result.net}: {result.status} after {result.iterations} iterations in "
              f"{result.seconds:.2f} s (layout {sum(layout.seconds.values()):.2f} s"
              + (f"; {len(starts)} starts laid out and solved in "
                 f"{sum(t['seconds'] for t in starts):.1f} s" if len(starts) > 1 else "")
              + (f", boundary panels {props['boundary_panels']['seconds']:.2f} s"
                 if (props.get("boundary_panels") or {}).get("seconds") is not None else "")
              + ")"
              + (f" ({params})" if params else ""))
        print(f"wrote {_listing([obj_path, json_path, boundary_path(obj_path), picture, *viewers])}")
        for warning in layout_warnings(props):
            print(f"fabplan: warning: {warning}", file=sys.stderr)
    if not result.converged:
        _warn_not_converged(result, json_path)
        if args.quiet:
            return EXIT_NOT_CONVERGED
        if preset.radius == "param" or preset.planar_faces:
            print(f"fabplan: note: {preset.name} nets exist on special surfaces only; held this "
                  f"close to the design the net cannot become one. `fabplan optimize {obj_path} --net "
                  f"{preset.name} --reference {args.surface}` lets it leave the design a little "
                  "(`fabplan study` measures how far)", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def _design_units(args: argparse.Namespace, design: Any) -> str:
    """The model units of a layout: those of its design's file (a .3dm file's unit system,
    converted with ``#units=U``), else ``--units``, else metres; a --units that
    contradicts the file is refused."""
    if design.units is None:
        return args.units or DEFAULT_UNITS
    if args.units is not None and args.units != design.units:
        raise InputError(f"--units {args.units}: the design is in {UNIT_WORDS[design.units]} "
                         f"(its file says so); to convert it, choose it as FILE.3dm#units={args.units}")
    return str(design.units)


def _units_said(units: str | None) -> str:
    """Model units in words for the terminal (a unitless .3dm file has none)."""
    return {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches",
            "ft": "feet"}.get(units or "", "model units (the file has no unit system)")


def _check_net_memory(args: argparse.Namespace, mesh: Any, command: str) -> None:
    """Refuse a net whose `command` (``molds``, ``mill``) would need more memory than this
    run may use, or more faces than ``--max-panels`` when it is given, before the work
    (`fabplan.io.resources`)."""
    from .io.resources import MILL_MEMORY, MOLDS_MEMORY, check_memory, check_panel_count

    model = {"molds": MOLDS_MEMORY, "mill": MILL_MEMORY}[command]
    faces = len(mesh.face_sizes)
    fix = f"run {command} on a coarser net or on parts of it"
    if args.max_panels is not None:
        check_panel_count(faces, max_panels=args.max_panels, bytes_per_panel=model.bytes_per_unit,
                          what=f"{args.net}: {model.work} a net of {faces:,} faces", fix=fix)
    else:
        check_memory(model, faces, where=str(args.net),
                     fix=f"{fix}, or give --max-panels to run it anyway")


def _check_simulation_memory(mesh: Any, mm_per_unit: float, step_mm: float) -> None:
    """Refuse a milling simulation whose grid at ``--sim-step`` would need more memory than
    is left beside the plan, naming the smallest step that fits (a grid over the cap of
    `height_target` is refused there, before it is made)."""
    from .fabricate.milling.mill_simulation import MAX_SIMULATION_CELLS, simulation_cells
    from .io.resources import MILL_MEMORY, SIMULATION_MEMORY, check_memory, memory_limit

    cells = simulation_cells(mesh.vertices * mm_per_unit, mesh.triangles(), step_mm)
    if cells > MAX_SIMULATION_CELLS:
        return
    plan = MILL_MEMORY.peak_bytes(len(mesh.face_sizes))
    fits = max(SIMULATION_MEMORY.largest_fitting(memory_limit() - plan), 1)
    check_memory(SIMULATION_MEMORY, cells, where=f"--sim-step {step_mm:g}", beside_bytes=plan,
                 fix=f"a --sim-step of {1.01 * step_mm * math.sqrt(cells / fits):.3g} mm or more "
                     "fits, or give --no-simulation")


#: with --panel-surface design, a net whose vertices lie farther than this many of its mean
#: edges from the design is refused: its panels would be cut from a surface they are not on
NET_OFF_DESIGN_EDGES = 2.0


def _check_net_on_design(args: argparse.Namespace, mesh: Any, design: Any) -> None:
    """Refuse `--panel-surface design` for a net (`QuadMesh`) that does not lie on its
    design (`DesignSurface`)."""
    import numpy as np

    with np.errstate(all="ignore"):
        distance = design.distances(mesh.vertices)
    edge = mesh.mean_edge_length
    far = float(np.max(distance)) if np.all(np.isfinite(distance)) else math.inf
    if far > NET_OFF_DESIGN_EDGES * edge:
        raise InputError(f"{args.net}: --panel-surface design: the net lies up to {far:.4g} "
                         f"from the design {args.design} ({far / edge:.3g} of its mean edges): "
                         "its panels are cut from the design only where they lie on it; give "
                         "the design the net was laid out on, or another --panel-surface")


def _check_triangles(surface: str, triangles: int) -> None:
    """Refuse a ``--triangles`` whose triangulation of a built-in or NURBS surface would
    need more memory than this run may use (a mesh file keeps its own triangles, checked
    as it is read)."""
    from .design.load import names_a_file
    from .io.resources import DESIGN_MEMORY, check_memory
    from .io.rhino_read import is_3dm_source

    if is_3dm_source(surface) or not names_a_file(surface):
        check_memory(DESIGN_MEMORY, triangles, where=f"--triangles {triangles}",
                     fix="give fewer --triangles")


def _check_layout_size(design: Any, panel_size: float, max_panels: int | None) -> None:
    """Refuse a layout whose panel count (design area / panel size squared) would exhaust
    the memory, before the layout starts (see `fabplan.io.resources`)."""
    from .io.resources import check_panel_count, default_max_panels

    if panel_size > design.extent:
        raise InputError(f"--panel-size {panel_size:g}: must be at most the extent of "
                         f"{Path(design.name).name} ({design.extent:.4g} model units, the diagonal "
                         "of its bounding box)")
    panels = design.area / panel_size**2
    limit = default_max_panels() if max_panels is None else max_panels
    fitting = (design.area / (0.5 * limit)) ** 0.5
    hint = (f"; the design spans {design.extent:.4g} units: if it is in millimetres, give "
            "the panel size in millimetres too" if design.extent > 2000 else "")
    check_panel_count(
        panels, max_panels=limit,
        what=f"{Path(design.name).name}: a layout at panel size {panel_size:g} of a surface "
             f"of area {design.area:.4g}",
        fix=f"use a larger --panel-size (about {fitting:.2g} gives {0.5 * limit:,.0f} "
            f"panels){hint}")


def boundary_text(properties: dict) -> str:
    """The boundary panels of a layout and the coverage they bring, in words."""
    panels = properties.get("boundary_panels") or {}
    count = panels.get("count", 0)
    text = (f"{count} boundary panel{'' if count == 1 else 's'} trimmed to the design boundary "
            f"bring it to {100 * properties['coverage']:.2f} %")
    patches = panels.get("patches") or []
    if patches:
        text += (f" (of them {len(patches)} patch{'' if len(patches) == 1 else 'es'} closing holes "
                 "inside the net, ids under properties.boundary_panels.patches)")
    slivers = len(panels.get("extensions") or [])
    if slivers:
        # the boundary OBJ has a face for each: say why it has more faces than panels
        text += (f", and {counted(slivers, 'sliver')} cut as part of the full panel beside "
                 f"{'it' if slivers == 1 else 'them'} ({count + slivers} faces in the boundary OBJ)")
    return text


#: a layout whose net's lines turn more than this at a vertex (degrees) is warned about
LINE_TURN_WARNING_DEG = 45.0


def boundary_warnings(properties: dict) -> list:
    """What falls short in a net's cladding of its design (coverage, boundary panels
    facing against it or crossing themselves), in plain words."""
    out = []
    coverage = properties["coverage"]
    panels = properties.get("boundary_panels") or {}
    if coverage < 0.999:
        gaps = panels.get("gaps") or []
        where = "" if not gaps else (
            f"; the largest gap, of {panel_areas(gaps[0]['area_relative_to_panel'])}, lies "
            f"{'at the design boundary' if gaps[0]['at_design_boundary'] else 'inside the design'} "
            f"around ({', '.join(f'{v:.4g}' for v in gaps[0]['point'])})")
        out.append(f"the panels cover only {100 * coverage:.1f} % of the design surface "
                   f"(measured by area on the design{where}; the largest gaps are listed "
                   "under properties.boundary_panels.gaps in the JSON)")
    flipped = panels.get("flipped") or []
    if flipped:
        out.append(f"{counted(len(flipped), 'boundary panel')} face{'s' if len(flipped) == 1 else ''} "
                   "against the design (ids under properties.boundary_panels.flipped)")
    crossed = panels.get("crossed") or []
    if crossed:
        one = len(crossed) == 1
        out.append(f"{counted(len(crossed), 'boundary panel')} "
                   f"{'crosses itself' if one else 'cross themselves'} (ids under "
                   "properties.boundary_panels.crossed): the outline turns back at a net vertex "
                   "off the design boundary; trim the net there by hand")
    off = panels.get("off_design") or {}
    if off.get("area", 0.0) > 0:
        places = off.get("places") or []
        where = "" if not places else (
            f"; the largest, {places[0]['area']:.4g} units squared of "
            f"{'face' if 'face' in places[0] else 'boundary panel'} "
            f"{places[0].get('face', places[0].get('panel'))}, around "
            f"({', '.join(f'{v:.4g}' for v in places[0]['point'])})")
        out.append(f"{off['area']:.4g} units squared of panels lie off the design, over a hole "
                   f"or past its boundary ({off.get('faces', 0)} net faces and "
                   f"{off.get('panels', 0)} boundary panels{where}; listed under "
                   "properties.boundary_panels.off_design): trim them there by hand")
    crossings = panels.get("crossings") or {}
    clashes = crossings.get("overlapping", 0) + crossings.get("edge_clashes", 0)
    if clashes:
        out.append(f"{counted(clashes, 'pair')} of panels overlap or share a side the same way "
                   "(listed under properties.boundary_panels.crossings.pairs: a face is a net "
                   "face, a panel a face of the boundary OBJ, numbered from 0)")
    return out


def layout_warnings(properties: dict) -> list:
    """What a user should know about a layout's measured result, in plain words."""
    out = boundary_warnings(properties)
    coverage = properties["coverage"]
    net = properties.get("coverage_net", coverage)
    if coverage - net > 0.1:
        out.append(f"the full panels cover only {100 * net:.0f} % of the design: the layout stops far "
                   "short of the boundary or leaves holes, and boundary panels and patches cover "
                   f"{100 * (coverage - net):.0f} % (try a smaller --panel-size)")
    edge = properties["edge_length_relative_to_panel"]
    if edge["min"] < 0.5 or edge["max"] > 2.0:
        out.append(f"edges range over {edge['min']:.2f} .. {edge['max']:.2f} of the panel size "
                   "(more than a factor 2 from it)")
    angle = properties.get("intersection_angle_deg") or {}
    if angle.get("min") is not None and (angle["min"] < 20 or angle["max"] > 160):
        out.append(f"the families meet at {angle['min']:.1f} .. {angle['max']:.1f} deg: some "
                   "panels are nearly degenerate")
    turn = ((properties.get("fairness") or {}).get("line_turn_deg")) or {}
    if turn.get("max") is not None and turn["max"] > LINE_TURN_WARNING_DEG:
        out.append(f"the net's lines turn within the surface by up to {turn['max']:.0f} deg at "
                   f"vertex {turn['vertex']} (median {turn['median']:.1f} deg, 95 % below "
                   f"{turn['p95']:.0f}): the solve bent the layout's lines to make a net of its "
                   "type; a smaller --panel-size or another net type may be fairer (a study "
                   "judges it with max_line_turn_deg)")
    folds = properties.get("folds") or {}
    if folds.get("folded"):
        out.append(f"the net folds: {folds['flipped_faces']['count']} flipped faces (ids in the "
                   f"JSON under properties.folds), {folds['fold_edges']['count']} fold edges")
    build = properties.get("buildable") or {}
    if build.get("crumpled"):
        out.append(f"the net is crumpled: {build['nonconvex_faces']['count']} non-convex panels, "
                   f"lines turning more than {build['sharp_line_turns']['turn_above_deg']:g} deg "
                   f"at {build['sharp_line_turns']['count']} vertices (ids and the worst places "
                   "in the JSON under properties.buildable)")
    off = properties["distance_to_design_relative_to_panel"]["max"]
    if off > 0.01:
        chord = properties.get("design_chord_error") or 0.0
        coarse = chord > 0.5 * properties["distance_to_design"]["max"]
        out.append(f"the net is up to {100 * off:.1f} % of a panel off the design surface"
                   + (" (its triangulation is too coarse: raise --triangles)" if coarse else ""))
    return out


def _parse_sheet(text: str) -> tuple[float, float]:
    """'2500x1250' -> (2500.0, 1250.0) millimetres."""
    parts = text.lower().replace("*", "x").split("x")
    try:
        w, h = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--sheet must be WIDTHxHEIGHT in millimetres, e.g. 2500x1250, "
                         f"got {text!r}") from None
    return w, h


def _parse_layers(specs: list | None) -> dict:
    """['cut=LASER_CUT:1', 'engrave=MARK'] -> the layers of StripSettings, defaults kept."""
    from .fabricate.strips import StripSettings

    layers = dict(StripSettings(height_mm=1, thickness_mm=0.1).layers)
    for spec in specs or []:
        kind, _, rest = spec.partition("=")
        name, _, colour = rest.partition(":")
        if kind not in layers or not name:
            raise InputError(f"--layer must be KIND=NAME[:COLOUR] with KIND one of "
                             f"{', '.join(layers)}, got {spec!r}")
        try:
            layers[kind] = (name, int(colour) if colour else layers[kind][1])
        except ValueError:
            raise InputError(f"--layer {spec!r}: the colour must be an AutoCAD colour index "
                             "1-255") from None
    return layers


def _cmd_strips(args) -> int:
    from .fabricate.strips import StripSettings, build_strips
    from .fabricate.strips.nesting import make_parts, nest_parts
    from .fabricate.strips.strip_plan import STRIP_FILES, StripPlan, strip_limit_checks
    from .io.resources import check_panel_count, worker_count

    worker_count(args.workers)  # a bad value fails before any work

    settings = StripSettings(
        height_mm=args.height, thickness_mm=args.thickness, clearance_mm=args.clearance,
        units=_net_units(args, args.net), tolerance_mm=args.tolerance,
        sheet_mm=_parse_sheet(args.sheet),
        spacing_mm=args.spacing, margin_mm=args.margin, kerf_mm=args.kerf, end=args.end,
        end_extension_mm=args.extension, splice=args.splice, splice_length_mm=args.splice_length,
        labels=args.labels, label_height_mm=args.label_height, layers=_parse_layers(args.layer),
        one_file=args.one_file, boundary_member_mm=args.boundary_member,
        max_twist_deg_per_m=args.max_twist)
    settings.check()
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**_net_inputs(args.net), **_file_inputs((args.boundary, "the boundary panels"),
                                                      (args.design, "the design"))}
    _folder_apart(out, [*STRIP_FILES, "strips.3dm", "strips.glb", "strips.ifc"], inputs)
    started = time.perf_counter()
    mesh = load_net(args.net)
    boundary_file, boundary = _strip_boundary(args, mesh)
    check_panel_count(len(mesh.face_sizes), max_panels=args.max_panels,
                      what=f"{args.net}: strips of a net of {len(mesh.face_sizes)} faces",
                      fix="plan the strips of a coarser net or of parts of it")
    _check_units(args, mesh, settings.units)
    design = None
    if args.design is not None:
        from .design.load import load_design

        design = load_design(args.design, triangles=args.triangles)
    # the stages of `plan_strips`, one by one so that each shows its progress
    progress = _progress(args)
    planning = time.perf_counter()
    with progress.stage("unrolling the strips"):
        strips = build_strips(mesh, settings, boundary)
    with progress.stage(f"splitting {len(strips.strips)} strips into parts that fit the sheets"):
        parts = make_parts(strips, settings)
    with progress.stage(f"nesting {len(parts)} parts"):
        nesting = nest_parts(parts, settings, workers=worker_count(args.workers))
    claim = _constant_radius_claim(args.net)
    plan = StripPlan(strips=strips, parts=parts, nesting=nesting,
                     seconds=time.perf_counter() - planning,
                     limits=strip_limit_checks(strips, parts, constant_radius=claim is not None))
    if design is not None:
        plan.limits.append(deviation_check(
            design.distances(mesh.vertices), units=settings.units,
            max_deviation=args.max_deviation_mm / MM_PER_UNIT[settings.units]))
    with progress.stage(f"writing {len(nesting.sheets)} sheets and checking them"), \
            _viewer_files(args, out / "strips", mesh, units=settings.units, strips=plan,
                          net_type=_net_properties(args.net).get("net")) as viewers:
        files = plan.write(out, previews=not args.no_previews,
                           workers=worker_count(args.workers), protect=inputs) + viewers
    s = plan.summary()
    if s["ends_set_back_past_half_an_edge"]:      # a warning, so also with --quiet
        print(f"fabplan: warning: the {settings.member_mm:g} mm boundary member sets "
              f"{counted(s['ends_set_back_past_half_an_edge'], 'strip end')} back by more "
              f"than half their last edge (up to {s['member_setback_max_mm']:.0f} mm): is it "
              "that thick? (--boundary-member is in mm)", file=sys.stderr)
    if args.quiet:
        print(f"{counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} on "
              f"{counted(s['sheets'], 'sheet')}; wrote {len(files)} files to {out}")
        return _limits_exit(plan.limits, out / "strips.json", claim)
    radius = s["radius_mm"]
    print(f"{s['strips']} strips ({s['strips_per_family'][0]} A, {s['strips_per_family'][1]} B), "
          f"{s['crossings']} crossings, {s['total_length_mm'] / 1000:.2f} m of strip, "
          f"unrolled length error {s['unrolled_length_error_mm']:.1e} mm (the net read in "
          f"{settings.units}: --units)")
    if radius:
        print(f"arc radius {radius['median']:.1f} mm, the median (relative spread "
              f"{radius['spread_relative']:.2e}); "
              f"parts {'congruent' if s['congruent'] else 'not congruent'} within "
              f"{settings.tolerance_mm:g} mm (deviation {s['congruence_deviation_mm']:.3f} mm)")
    else:
        print("all strips straight")
    print(f"twist up to {s['twist_deg_per_m']:.2f} deg/m; flat panels would lean up to "
          f"{s['off_orthogonal_deg']:.2f} deg from orthogonal")
    for check in plan.limits:
        print(f"limit: {check.text()}")
    print(f"{s['parts']} parts on {s['sheets']} sheets of {settings.sheet_mm[0]:g}x"
          f"{settings.sheet_mm[1]:g} mm, material use {100 * s['material_use']:.1f} %")
    print(f"wrote {len(files)} files to {out} in {time.perf_counter() - started:.1f} s "
          f"(planning {s['seconds']:.1f} s, every sheet audited and checked before writing)")
    if boundary is not None:
        from .fabricate.strips.strip_boundary import MAX_TURN_DEG

        angle = s["member_angle_min_deg"]
        print(f"{counted(s['ends_at_boundary_member'], 'strip end')} reach the edge of the "
              f"cladding ({counted(s['boundary_nodes'], 'node')} added in the boundary panels of "
              f"{boundary_file}) and are cut square against a {settings.member_mm:g} mm "
              "boundary member"
              + (f" (smallest angle to it {angle:.0f} deg)" if angle is not None else "")
              + f"; {_free_ends_text(s)}")
        if s["strips_along_edge"]:
            print(f"fabplan: note: {counted(s['strips_along_edge'], 'polyline')} lie along the "
                  "edge of the cladding, where the boundary member runs: no strips are cut "
                  "for them", file=sys.stderr)
        if s["ends_not_continued"]:
            print(f"fabplan: note: {counted(s['ends_not_continued'], 'strip end')} on the net's "
                  "boundary could not be continued to the edge (no boundary panel side goes on "
                  f"straight from it, turning less than {MAX_TURN_DEG:g} deg): they end free, listed as "
                  f"'free (not continued)' in {out / 'strips.csv'}", file=sys.stderr)
    if s["junctions"]:
        print(f"fabplan: note: {s['junctions']} vertices join more than one strip of a family "
              "(irregular vertices): no slits there, they need node connectors; listed in "
              f"{out / 'strips.json'}", file=sys.stderr)
    return _limits_exit(plan.limits, out / "strips.json", claim)


def _constant_radius_claim(net: str | os.PathLike) -> str | None:
    """The net type a net's record ``NET.json`` names when that type claims a constant (or
    infinite) Meusnier radius, so that its strips claim to be pieces of one arc
    (``const-radius``, ``cmc``, ``linear-weingarten``, the A-nets); None otherwise."""
    import json

    try:
        name = json.loads(Path(net).with_suffix(".json").read_text(encoding="utf-8")).get("net")
    except (OSError, ValueError, AttributeError):
        return None
    preset = NETS.get(name) if isinstance(name, str) else None
    if preset is None or preset.dual or preset.radius not in ("param", "infinite"):
        return None
    return name


def _limits_exit(checks: list, record: Path, claim: str | None = None) -> int:
    """Exit 3, with a warning naming each limit exceeded and by how much, when a part
    exceeds a fabrication limit (`fabplan.fabricate.limits`); else 0."""
    from .fabricate.limits import exceeded_text

    text = exceeded_text(checks)
    if text is None:
        return 0
    why = (f" (the net's record names it a {claim} net, whose strips are pieces of one arc)"
           if claim is not None and any(c.exceeded and c.limit == "congruence_tolerance_mm"
                                        for c in checks) else "")
    print(f"fabplan: warning: {text}{why}; counted in {record} (limits)", file=sys.stderr)
    return EXIT_NOT_CONVERGED


def _free_ends_text(summary: dict) -> str:
    """``N ends are free: a inside the net (...), b along the edge, c not continued``."""
    from .fabricate.strips.strip_boundary import MIN_MEMBER_ANGLE_DEG

    kinds = summary["ends_free_by_kind"]
    why = {"inside": "inside the net, where a line stops at an irregular vertex",
           "along edge": f"along the edge (meeting it at less than {MIN_MEMBER_ANGLE_DEG:g} deg)",
           "not continued": "not continued to the edge"}
    parts = [f"{kinds[k]} {text}" for k, text in why.items() if kinds.get(k)]
    free = summary["ends_free"]
    return f"{counted(free, 'end')} {'is' if free == 1 else 'are'} free" + \
        (": " + ", ".join(parts) if parts else "")


def _boundary_file(args) -> Path | None:
    """The net's boundary panels: ``--boundary FILE``, else ``NET.boundary.obj`` beside the
    net when a layout, optimize or study wrote one; None for none (``--no-boundary``)."""
    from .solve.optimize import boundary_path

    if args.no_boundary:
        return None
    if args.boundary is None:
        path = boundary_path(args.net)
        # a layout whose net clads its design to the boundary writes one without faces
        return path if path.is_file() and _has_faces(path) else None
    path = Path(args.boundary)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the boundary panels, NET.boundary.obj)")
    return path


def _has_faces(path: Path) -> bool:
    """Whether an OBJ file holds a face line."""
    try:
        with path.open(encoding="utf-8", errors="replace") as handle:
            return any(line.startswith("f ") for line in handle)
    except OSError:
        return True           # the reader names what is wrong with it


def _strip_boundary(args, mesh):
    """``(file, StripBoundary)`` of the boundary panels strips run through, or
    ``(None, None)`` (`_boundary_file`)."""
    from .fabricate.strips.strip_boundary import StripBoundary

    path = _boundary_file(args)
    if path is None:
        return None, None
    return path, StripBoundary.from_obj(mesh, path, _boundary_record(args))


def _net_properties(net: str | Path) -> dict:
    """``properties`` of the ``NET.json`` beside a net a layout, optimize or study wrote
    ({} where there is none, or it holds none)."""
    import json

    try:
        properties = json.loads(Path(net).with_suffix(".json").read_text(encoding="utf-8"))["properties"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return properties if isinstance(properties, dict) else {}


def _boundary_record(args) -> dict | None:
    """What NET.json records of the boundary panels beside the net (which are slivers,
    patches, points on the design boundary); None for panels given by ``--boundary``."""
    return None if args.boundary is not None else _net_properties(args.net).get("boundary_panels")


def _cmd_arcs(args) -> int:
    from .fabricate.arcs import arc_limit_checks, arc_structure, write_arcs

    out = output_argument(args.output)
    if out.suffix.lower() not in (".3dm", ".dxf"):
        raise InputError(f"{out}: the output must be a .3dm or a .dxf file")
    _check_outputs([out, out.with_suffix(".json")], _net_inputs(args.net))
    mesh = load_net(args.net, quads=False)
    units = _net_units(args, args.net)
    _check_units(args, mesh, units)
    progress = _progress(args)
    with progress.stage("the arcs"):
        arcs = arc_structure(mesh)
    limits = arc_limit_checks(arcs, max_arc_angle_deg=args.max_arc_angle)
    with progress.stage("writing the arcs"):
        files = write_arcs(arcs, out, units=units, limits=limits)
    s = arcs.summary()
    if args.quiet:
        print(f"{counted(s['arcs'], 'arc')}; wrote {files[0]}")
        return _limits_exit(limits, files[1])
    sources = ", ".join(f"{count} {name}" for name, count in s["plane_sources"].items() if count)
    print(f"{s['arcs']} arcs ({s['straight_arcs']} straight): radius {s['radius']['min']:.4g} .. "
          f"{s['radius']['max']:.4g}, angle {s['angle_deg']['min']:.3g} .. "
          f"{s['angle_deg']['max']:.3g} deg, arc-chord deviation up to "
          f"{s['arc_chord_deviation']['max']:.3g}")
    print(f"tangent-plane defect up to {s['tangent_plane_defect_deg']['max']:.2e} deg; ends off "
          f"their vertices by {s['end_vertex_gap_relative_to_edge']:.1e} of the mean edge; arcs "
          f"off the vertex spheres by up to {s['sphere_deviation_relative_to_edge']['max']:.1e} "
          f"of the mean edge")
    print(f"vertex planes: {sources}")
    for check in limits:
        print(f"limit: {check.text()}")
    print(f"wrote {', '.join(str(f) for f in files)}")
    return _limits_exit(limits, files[1])


def _cmd_study(args) -> int:
    from .study.report import check_output_folder, write_study
    from .study.run import run_study
    from .study.spec import read_study, resolve_study

    progress = _progress(args)
    say = progress.say()
    started = time.perf_counter()
    out = output_argument(args.output, folder=True)
    study = read_study(resolve_study(args.study))
    check_output_folder(out, study)
    cache = None
    if args.resume:
        from .study.cache import CandidateCache

        cache = CandidateCache(out, study, note=say)
    with ExitStack() as stack:
        client = None
        if args.workers is not None or args.scheduler is not None:
            from .study.parallel import dask_client, run_study_parallel, worker_count

            workers = None if args.workers is None else worker_count(args.workers)
            client = stack.enter_context(dask_client(workers, args.scheduler))
            result = run_study_parallel(study, client=client, progress=say,
                                        max_panels=args.max_panels, cache=cache,
                                        resume=args.resume, files=True, rhino=args.rhino,
                                        ifc=args.ifc)
        else:
            from .study.background import BackgroundCandidates

            searching = (f" and {counted(len(study.searches), 'search', 'searches')}"
                         if study.searches else "")
            with progress.stage(f"running {counted(len(study.candidates), 'candidate')}{searching}"):
                result = run_study(study, progress=say, max_panels=args.max_panels, cache=cache,
                                   resume=args.resume, files=True, rhino=args.rhino,
                                   ifc=args.ifc,
                                   # a --resume run keeps each candidate as it finishes,
                                   # in the order of the study
                                   background=BackgroundCandidates if cache is None else None)
        writing = time.perf_counter()
        # with workers, they make the candidates' files too
        with progress.stage("writing the report and the candidates' files"):
            files = write_study(result, out, progress=say, rhino=args.rhino, ifc=args.ifc,
                                view_3d=not args.no_3d, client=client, fork=client is None)
    done = time.perf_counter()
    if args.quiet:
        verdict = (f"recommended: {result.recommended}" if result.recommended else
                   "no candidate meets the limits")
        print(f"{verdict}; wrote {files[0]} in {done - started:.0f} s")
        return 0
    for c in result.ranked():
        if c.failed:
            print(f"  {c.name:<28} failed: {c.error}")
            continue
        m = c.metrics
        note = f"  (the same net as {c.same_net_as})" if c.same_net_as else ""
        print(f"{c.rank:>2} {c.name:<28} {'feasible' if c.feasible else 'not feasible':<12} "
              f"molds {m['molds']['count']:>4}  panels {m['panels']:>5}  deviation "
              f"{m['largest_deviation_mm']:8.1f} mm  cost {c.cost:9.0f}{note}")
    print(result.recommendation)
    print(f"wrote {files[0]} (and study.json, candidates.csv, candidates/) in "
          f"{done - started:.0f} s: {result.seconds_run:.0f} s to run the candidates, "
          f"{done - writing:.0f} s to write the files")
    return 0


def _cmd_templates(args) -> int:
    from .study.spec import copy_template, template_names, template_summary

    if args.name is None:
        names = template_names()
        width = max(map(len, names), default=0)
        for name in names:
            print(f"{name:<{width}}  {template_summary(name)}")
        print("run one with `fabplan study NAME -o DIR`; copy one with "
              "`fabplan templates NAME -o my-study.toml`")
        return 0
    if args.output is None:
        from .study.spec import template_path

        print(template_path(args.name).read_text(encoding="utf-8"), end="")
        return 0
    output_argument(args.output, folder=True)       # named, and short enough
    for path in copy_template(args.name, args.output):
        print(f"wrote {path}")
    return 0


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line and exit code 2, like every other bad input."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"fabplan: error: {message} (see '{self.prog} --help')\n")


class _InRange(argparse.Action):
    """Store an option's number checked against its range (`fabplan.io.parameters`) as
    the command line is parsed: a bad value is refused before any work, in one line
    naming the option, the value and the range."""

    def __init__(self, option_strings: list[str], dest: str, *, parameter: Parameter,
                 **kwargs: Any):
        super().__init__(option_strings, dest, **kwargs)
        self.parameter = parameter

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        try:
            setattr(namespace, self.dest, self.parameter.check(values))
        except InputError as exc:
            parser.error(str(exc))


def _add_number(p: argparse.ArgumentParser, option: str, *, help: str, **kwargs: Any) -> None:
    """A numeric option, checked against its range in `fabplan.io.parameters.OPTIONS`
    (which every numeric option must have), the range stated in its help."""
    parameter = option_parameter(p.prog.split()[-1], option)
    units = f" {parameter.units}" if parameter.units else ""
    p.add_argument(option, action=_InRange, parameter=parameter,
                   help=f"{help} (range {parameter.interval}{units}"
                        f"{', a whole number' if parameter.integer else ''})", **kwargs)


def _add_max_deviation_mm(p: argparse.ArgumentParser) -> None:
    """The deviation limit of a net checked against its --design (molds, strips)."""
    _add_number(p, "--max-deviation-mm", default=DEFAULT_MAX_DEVIATION_MM, metavar="MM",
                help="with --design: the largest distance of a net vertex from the design, in "
                     f"mm; a net farther off ends the run in exit 3 (default "
                     f"{DEFAULT_MAX_DEVIATION_MM:g}, see docs/fabrication-limits.md)")


def _add_max_panels(p: argparse.ArgumentParser, *, memory: bool = False) -> None:
    _add_number(p, "--max-panels", metavar="N",
                help="refuse nets of more faces than this (default: what half the available "
                     "memory holds, estimated from the net's faces)" if memory else
                     "refuse runs estimated to need more panels than this (default: what "
                     "half the available memory holds, at least 20000)")


def _add_max_line_turn(p: argparse.ArgumentParser) -> None:
    _add_number(p, "--max-line-turn", default=90.0, metavar="DEG",
                help="a converged net's lines turn in the surface by at most DEG at any vertex "
                     "(default 90: over it a line doubles back); a net within tolerance that "
                     "turns more, or has a non-convex quad, ends 'crumpled' (exit 3)")


def _add_verbosity(p: argparse.ArgumentParser) -> None:
    """-q and -v, the same for every long-running command (`fabplan.report.progress`)."""
    level = p.add_mutually_exclusive_group()
    level.add_argument("-q", "--quiet", action="store_true",
                       help="print only errors and a one-line summary")
    level.add_argument("-v", "--verbose", action="store_true",
                       help="also print every solver iteration")


def _add_nets(sub: Any) -> None:
    p = sub.add_parser("nets", help="list the net types and their defining properties")
    p.set_defaults(func=_cmd_nets)


def _add_measure(sub: Any) -> None:
    p = sub.add_parser("measure", help="measure the S-net properties of a quad mesh")
    p.add_argument("net", help="quad mesh (OBJ)")
    p.add_argument("-o", "--output", help="JSON file to write (default: NET.measure.json)")
    p.add_argument("--reference", help="surface to measure the distance to (OBJ/STL/PLY/OFF, "
                                       "FILE.3dm[#...] or a built-in surface)")
    _add_number(p, "--max-deviation", metavar="D",
                help="count the vertices farther than D (model units) from --reference as "
                     "keeping the net from being built")
    _add_max_line_turn(p)
    _add_units(p)
    p.set_defaults(func=_cmd_measure)


def _add_optimize(sub: Any) -> None:
    p = sub.add_parser("optimize", help="optimize a quad mesh into a net of a given type")
    p.add_argument("input", help="quad mesh (OBJ)")
    p.add_argument("--net", required=True, choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`)")
    _add_number(p, "--angle", help="intersection angle in degrees (isogonal types)")
    _add_number(p, "--radius", help="Meusnier radius in model units")
    p.add_argument("--reference", help="surface to stay close to: a mesh file, a .3dm file or a "
                                       "built-in surface as for `fabplan layout` (default: the input)")
    p.add_argument("--fix", help="'boundary' or a file of vertex ids to hold in place")
    p.add_argument("--handle", action="append", metavar="ID:X,Y,Z",
                   help="move vertex ID to (X, Y, Z) and hold it there; repeatable, or a file "
                        "of 'ID X Y Z' lines")
    p.add_argument("--coherent", action="store_true",
                   help="keep all Meusnier spheres on one side of the surface")
    guards = p.add_mutually_exclusive_group()
    guards.add_argument("--guards", dest="guards", action="store_const", const=True,
                        help="solve with the guards against folding from the start (face normals "
                             "within 75 deg of the reference's, star angles within 15..165 deg); "
                             "by default they are added only when a first solve folds, and "
                             "then a smoothed copy of the start is tried too")
    guards.add_argument("--no-guards", dest="guards", action="store_const", const=False,
                        help="never add the guards against folding, nor retry a folded solve")
    p.add_argument("--settle-free", action="store_true",
                   help="move the vertices in no star (zigzag boundary tips, patch corners), "
                        "which no condition of the net holds, onto the surface the net "
                        "continues, so that the panels at them meet their neighbours' molds")
    _add_number(p, "--max-deviation", metavar="D",
                help="keep every vertex within D (model units) of the reference: a limit held "
                     "in the solve; a net type that cannot keep to it ends 'off-design' (exit "
                     "3) with the smallest limit it reached. Without it a net with --reference "
                     f"is checked against {DEFAULT_MAX_DEVIATION_MM:g} mm (not held in the "
                     "solve; exit 3 beyond it, see docs/fabrication-limits.md)")
    _add_max_line_turn(p)
    _add_number(p, "--max-iter", help="iteration cap (default 50)")
    p.add_argument("--no-multilevel", action="store_true",
                   help="solve a large grid net at full size from the start (by default, from "
                        "20,000 vertices, its coarse net of every second line is solved first)")
    p.add_argument("-o", "--output", required=True, help="output OBJ; its .json sits beside it")
    _add_html(p)
    _add_3dm(p)
    _add_units(p)
    _add_verbosity(p)
    p.set_defaults(func=_cmd_optimize)


def _add_molds(sub: Any) -> None:
    p = sub.add_parser("molds", help="count the molds a net's curved panels need and write a "
                                     "report (report.html, molds.json, panels.csv)")
    p.add_argument("net", help="quad mesh (OBJ); every face is a panel")
    _add_number(p, "--tolerance-mm", required=True, metavar="T",
                help="largest allowed gap between a panel and its mold, in mm")
    _add_units(p)
    _add_number(p, "--max-mold-size", metavar="MM",
                help="largest mold side in mm (default: no limit)")
    p.add_argument("--panel-surface", default="auto",
                   choices=["auto", "shared", "local_fit", "corners", "design", "smooth"],
                   help="panel shape: shared (pieces of one surface through the net: "
                        "neighbouring panels share their edges), local_fit (a quadric per "
                        "face, fitted to the corners around it; neighbours may step apart), "
                        "corners (least curved through its corners), design (patches of the "
                        "exact design the net lies on, --design: what a study plans for a "
                        "net on its design), auto (corners for a net of flat faces, else "
                        "design with --design, else shared); smooth is local_fit's earlier name")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net lies on, for --panel-surface design: a built-in "
                        "surface spec or a .3dm NURBS surface as for `fabplan layout`")
    _add_number(p, "--triangles", default=20000, metavar="N",
                help="triangles of the --design's triangulation, where the exact surface is "
                     "searched from (default 20000, a study's)")
    _add_number(p, "--step-limit", metavar="MM",
                help="largest step between neighbouring panels' molds in mm (default twice "
                     "the tolerance)")
    p.add_argument("--material", metavar="NAME[:THICKNESS]",
                   help="the panels' sheet: each panel is then flat, cold-bent, roll-bent or "
                        "molded, and only molded panels get molds (glass-annealed, "
                        "glass-heat-strengthened, glass-tempered, glass-laminated[-tempered], "
                        "aluminium, steel; e.g. glass-tempered:8mm, glass-laminated:2x8mm; "
                        "docs/materials.md)")
    _add_max_deviation_mm(p)
    _add_max_panels(p, memory=True)
    _add_boundary_options(p, "each is cut from a mold of the net's panels, placed to meet "
                             "its neighbours (a mold of its own where none does; slivers cut "
                             "with their full panel)", "plan the net's own panels only")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the report")
    _add_3dm(p)
    p.add_argument("--no-3d", action="store_true",
                   help="leave the interactive 3D view out of report.html (0.6 MB smaller)")
    _add_verbosity(p)
    p.set_defaults(func=_cmd_molds)


def _first_sentence(doc: str | None) -> str:
    """The first paragraph of a docstring on one line, without reST literals: what a
    built-in surface is (``width`` and ``depth`` are half-sizes: ``[-width, width]``)."""
    return " ".join((doc or "").strip().split("\n\n")[0].split()).replace("``", "")


def _add_boundary_options(p: argparse.ArgumentParser, use: str, without: str) -> None:
    """``--boundary FILE`` and ``--no-boundary``: what the command does with a net's boundary
    panels (`use`), and without them (`without`)."""
    ends = p.add_mutually_exclusive_group()
    ends.add_argument("--boundary", metavar="FILE",
                      help="the net's boundary panels (default: NET.boundary.obj beside the net, "
                           f"as layout, optimize and study write it): {use}")
    ends.add_argument("--no-boundary", action="store_true",
                      help=f"{without}, even when boundary panels are beside it")


def _add_mill(sub: Any) -> None:
    p = sub.add_parser("mill", help="curvature-adaptive milling paths, checked by simulation "
                                    "(CL + CSV + mill.json + report.html): face milling from the "
                                    "Meusnier spheres of an S-net, flank milling with a cone from "
                                    "the Mannheim spheres of an S*-net")
    p.add_argument("net", help="the S-net, or for a cone the S*-net with its vn normals (OBJ), "
                               "a regular quad net")
    p.add_argument("--tool", required=True,
                   metavar="face:D=MM[,corner=MM][,length=MM]|cone:angle=DEG,length=MM[,tip=MM]",
                   help="cylindrical face mill of diameter D (toroidal with a corner radius), or "
                        "a conical flank mill: half angle between axis and flank, flank length "
                        "along the axis, tip diameter (default 0)")
    p.add_argument("--along", choices=["A", "B"], default="A",
                   help="family whose lines the passes follow (A: the first, default)")
    _add_units(p, default="mm")
    _add_number(p, "--margin", metavar="MM",
                help="Meusnier radius minus safety sphere radius (cone: Mannheim radius "
                     "minus at least this) (default: the rule of docs/milling.md, which keeps "
                     "the cut above the target)")
    _add_number(p, "--scallop", default=0.01, metavar="MM",
                help="largest predicted scallop height between passes (default 0.01)")
    p.add_argument("--side", choices=["auto", "+", "-"], default="auto",
                   help="side the tool comes from: that of the Meusnier (cone: Mannheim) "
                        "spheres (auto), of the face normals (cone: the vn normals) (+) or the "
                        "other (-)")
    _add_max_panels(p, memory=True)
    _add_number(p, "--sim-step", default=0.5, metavar="MM",
                help="grid step of the milling simulation (default 0.5)")
    p.add_argument("--no-simulation", action="store_true",
                   help="plan only: no simulated scallop, gouge check or comparison")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net was made for, which the cut is measured against "
                        "(the net's distance from it reported apart): a triangle mesh, a "
                        "Rhino file or a built-in surface spec as for `fabplan layout` "
                        "(default: the design NET.json names, for a layout's net; else the "
                        "net's own surface)")
    _add_number(p, "--triangles", default=40000, metavar="N",
                help="triangles of a built-in or NURBS --design's triangulation, where its "
                     "exact surface is searched from (default 40000)")
    p.add_argument("--paths-on", choices=["design", "net"], default="design",
                   help="with a design: put the passes' nodes on the design (its closest "
                        "points to the net's vertices, its normals; default), or keep them "
                        "on the net's vertices")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the files")
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write the tool paths as DIR/paths.3dm (a polyline of cutter tips "
                        "and one of contact points per pass, in mm)")
    _add_verbosity(p)
    p.set_defaults(func=_cmd_mill)


def _add_layout(sub: Any) -> None:
    from .design.parametric import SURFACES, describe_surface_parameters

    p = sub.add_parser("layout", help="lay out an S-net on a design surface and optimize it "
                                      "gliding on the surface (OBJ + JSON + PNG)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       epilog="built-in surfaces and their parameters (defaults):\n" + "\n".join(
                           f"  {name}: {describe_surface_parameters(name)}\n"
                           f"      {_first_sentence(SURFACES[name].__doc__)}" for name in SURFACES))
    p.add_argument("surface", help="design surface: a triangle mesh (OBJ/STL/PLY/OFF), a Rhino "
                                   "file 'FILE.3dm[#layer=L,object=NAME,face=K,units=U]' (a NURBS "
                                   "surface, polysurface face or mesh), or a built-in surface "
                                   "'NAME[:key=value,...]' (hyperbolic-paraboloid, paraboloid, torus, "
                                   "revolution, tower-facade, height-field, bspline)")
    p.add_argument("--net", required=True, choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`)")
    _add_number(p, "--angle",
                help="intersection angle of the two families in degrees (default 90)")
    _add_number(p, "--panel-size", required=True, metavar="L",
                help="target edge length in model units")
    p.add_argument("--family", metavar="x|y|z[:STEP]|FILE",
                   help="prescribe the first family: x, y or z (levels of a coordinate, e.g. "
                        "floors; z:3.5 for levels every 3.5), or a file of polylines (OBJ "
                        "'l' lines or 'x y z' rows with blank lines between curves)")
    _add_number(p, "--triangles", default=40000,
                help="triangles of a built-in surface's triangulation (default 40000)")
    _add_number(p, "--max-iter", help="iteration cap (default 50)")
    _add_number(p, "--smoothing", metavar="PANELS",
                help="smooth the principal directions over this many panels and no other "
                     "(default: from half a panel, longer while the lattice leaves the design "
                     "unclad; longer smoothing holds the lattice together near umbilics, "
                     "shorter keeps the lines fairer after the solve)")
    _add_number(p, "--starts", default=5, metavar="N",
                help="lay the net out and solve it from up to N starts (as set; the "
                     "fairness term held longer in the solve; the other principal direction "
                     "as the bisector, at angles other than 90 deg; the directions smoothed "
                     "twice as long; smoothed as a line field) and keep the one that clads "
                     "the design, converges and, among those whose panels are as even as "
                     "the first start's, whose lines turn least (default 5; 1 is the "
                     "fastest)")
    _add_max_panels(p)
    _add_max_line_turn(p)
    p.add_argument("-o", "--output", required=True,
                   help="output OBJ; its .json and .png sit beside it")
    _add_html(p)
    _add_3dm(p)
    _add_units(p)
    _add_verbosity(p)
    p.set_defaults(func=_cmd_layout)


def _add_strips(sub: Any) -> None:
    p = sub.add_parser("strips", help="lamella strips along the parameter lines, unrolled, "
                                      "slit, labelled and nested on sheets (DXF + schedule)")
    p.add_argument("net", help="the net (OBJ)")
    _add_number(p, "--height", required=True, metavar="MM",
                help="lamella height; the surface runs along its middle")
    _add_number(p, "--thickness", required=True, metavar="MM",
                help="material thickness (the slits are this plus --clearance wide)")
    _add_units(p)
    p.add_argument("--sheet", default="2500x1250", metavar="WxH",
                   help="sheet size in mm (default 2500x1250)")
    _add_number(p, "--spacing", default=10.0, metavar="MM",
                help="gap between parts (default 10)")
    _add_number(p, "--margin", default=10.0, metavar="MM",
                help="gap to the sheet edge (default 10)")
    _add_number(p, "--kerf", default=0.0, metavar="MM",
                help="cut width to compensate: outlines grow, slits shrink by half (default 0)")
    _add_number(p, "--clearance", default=0.2, metavar="MM",
                help="play added to the slit width (default 0.2)")
    _add_number(p, "--tolerance", default=0.1, metavar="MM",
                help="cutting tolerance for fitting arcs, and on a net whose record claims a "
                     "constant radius how far a strip part may differ from the common arc "
                     "(exit 3 beyond it; default 0.1)")
    _add_number(p, "--max-twist", default=DEFAULT_MAX_TWIST_DEG_PER_M, metavar="DEG_PER_M",
                help="the largest twist of a strip, in degrees per metre; a strip that twists "
                     f"more ends the run in exit 3 (default {DEFAULT_MAX_TWIST_DEG_PER_M:g}, see "
                     "docs/fabrication-limits.md)")
    p.add_argument("--end", choices=["square", "round"], default="square",
                   help="strip ends (default square)")
    _add_number(p, "--extension", metavar="MM",
                help="material beyond the end crossings at free ends (default height / 2)")
    _add_boundary_options(p, "strips run through them to the edge of the cladding and are "
                             "cut square against a boundary member there",
                          "end the strips at the net's last vertices")
    _add_number(p, "--boundary-member", metavar="MM",
                help="thickness of the boundary member strips end against (default "
                     "--thickness)")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net lies on (a mesh file, a built-in surface spec or "
                        "a .3dm NURBS surface as for `fabplan layout`): the net's vertices are "
                        "checked against --max-deviation-mm from it")
    _add_number(p, "--triangles", default=20000, metavar="N",
                help="triangles of the --design's triangulation, where the exact surface is "
                     "searched from (default 20000)")
    _add_max_deviation_mm(p)
    p.add_argument("--splice", choices=["overlap", "lap"], default="overlap",
                   help="joint of a strip split to fit the sheets (default overlap)")
    _add_number(p, "--splice-length", metavar="MM",
                help="length of a splice (default 2 x height)")
    p.add_argument("--labels", choices=["stroke", "outline", "text"], default="stroke",
                   help="engraved labels: single-stroke lines, glyph outlines or DXF TEXT "
                        "(default stroke)")
    _add_number(p, "--label-height", metavar="MM",
                help="strip label height (default 0.12 x height, 3-20 mm)")
    p.add_argument("--layer", action="append", metavar="KIND=NAME[:COLOUR]",
                   help="layer name and colour for cut, slit or engrave (defaults CUT:1 red, "
                        "SLIT:6 magenta, ENGRAVE:5 blue); repeatable")
    p.add_argument("--one-file", action="store_true",
                   help="all sheets side by side in one DXF instead of one file per sheet")
    p.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    p.add_argument("--workers", metavar="N|auto", default="auto",
                   help="write the sheets in N processes (default auto: one per core)")
    _add_max_panels(p)
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the files")
    _add_3dm(p)
    _add_verbosity(p)
    p.set_defaults(func=_cmd_strips)


def _add_html(p: argparse.ArgumentParser) -> None:
    p.add_argument("--html", action="store_true",
                   help="also write OUT.html: a page that opens offline with the net in an "
                        "interactive 3D view (colour by deviation, Meusnier radius, angle, "
                        "kink, line turn; boundary panels green), its key numbers and its "
                        "picture (about 0.7 MB, most of it the viewer)")


def _add_units(p: argparse.ArgumentParser, default: str = DEFAULT_UNITS) -> None:
    """--units (the same five on every command) and --strict-units."""
    p.add_argument("--units", choices=list(MM_PER_UNIT), metavar="U",
                   help="unit of the model's coordinates: mm, cm, m, in or ft (default: the "
                        f"units the net's record NET.json states, else {default})")
    p.add_argument("--strict-units", action="store_true",
                   help="refuse, instead of warning, a net or design whose size does not fit "
                        "its units (panels under 10 mm or over 20 m, a design under 1 m in "
                        "metres or feet)")


def _add_3dm(p: argparse.ArgumentParser) -> None:
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write the net as a Rhino .3dm file (mesh, polylines per family, "
                        "panels per mold, strip curves; ids as in the CSV/JSON) and a .glb "
                        "for web viewers, coloured by mold")
    _add_ifc(p, "the net as an IFC4 file beside them")


def _add_ifc(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--ifc", action="store_true",
                   help=f"also write {what}: panels as IfcPlate (their surfaces, mold ids), "
                        "molds as IfcGroup, lamellas as IfcMember, the net as a structural "
                        "analysis model (docs/ifc.md; needs pip install 'fabplan[ifc]')")


def _add_arcs(sub: Any) -> None:
    p = sub.add_parser("arcs", help="circular arc structure: every edge replaced by the arc in "
                                    "which its end vertices' spheres meet (3dm or DXF + JSON)")
    p.add_argument("net", help="the net (OBJ)")
    _add_units(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT.3dm|OUT.dxf",
                   help="the arcs as Rhino ArcCurves or DXF ARC entities; the report goes to "
                        "OUT.json")
    _add_number(p, "--max-arc-angle", default=DEFAULT_MAX_ARC_ANGLE_DEG, metavar="DEG",
                help="the largest central angle of an arc the bending shop takes; a longer arc "
                     f"ends the run in exit 3 (default {DEFAULT_MAX_ARC_ANGLE_DEG:g}, see "
                     "docs/fabrication-limits.md)")
    _add_verbosity(p)
    p.set_defaults(func=_cmd_arcs)


def _add_study(sub: Any) -> None:
    p = sub.add_parser("study", help="facade feasibility study: run the candidate nets of a "
                       "design, judge them against the fabrication limits, recommend one",
                       description="Run a facade feasibility study and write its report. "
                       "A study replaces what an earlier study wrote in the output folder (listed "
                       "in DIR/.fabplan-files) and keeps every other file, so a study can be "
                       "re-run into its folder; a folder of other files only, a file, or the "
                       "folder of the study file is refused.")
    p.add_argument("study", help="study file (TOML, see docs/study-file.md) or a template "
                   "name (see `fabplan templates`)")
    p.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for report.html, study.json, candidates.csv and candidates/: "
                        "new, empty, or holding an earlier study (whose files are replaced)")
    p.add_argument("--workers", metavar="N|auto",
                   help="run the candidates in N local processes (auto: one per core) with Dask")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run the candidates on a running Dask cluster (see docs/parallel.md)")
    p.add_argument("--resume", action="store_true",
                   help="keep every finished candidate in DIR/.fabplan-cache as it finishes, and "
                        "take those an earlier (or interrupted) --resume run kept there instead "
                        "of computing them again")
    _add_max_panels(p)
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write every candidate's net as candidates/NAME/net.3dm (mesh, "
                        "polylines, panels per mold, strip curves) and net.glb")
    _add_ifc(p, "every candidate's facade plan as candidates/NAME/net.ifc")
    p.add_argument("--no-3d", action="store_true",
                   help="leave the interactive 3D view out of report.html")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print only errors and a one-line summary")
    p.set_defaults(func=_cmd_study)


def _add_templates(sub: Any) -> None:
    p = sub.add_parser("templates", help="list the study templates, print or copy one")
    p.add_argument("name", nargs="?", help="template to print (or copy with -o)")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="copy the template here: a .toml file, or a folder (an existing one, "
                        "or a path ending in /) that gets NAME.toml")
    p.set_defaults(func=_cmd_templates)


# every subcommand adds its parser; a new command is one function and one entry here
def _cmd_edit(args) -> int:
    from .edit.command import edit_command

    out = _output_path_plain(args.output)
    _check_outputs([out, out.with_suffix(".json")],
                   {**_net_inputs(args.input), **_file_inputs((args.reference, "the reference"))})
    return edit_command(args, out, reference=_reference(args.reference),
                        units=_net_units(args, args.input))


def _output_path_plain(text: str) -> Path:
    out = output_argument(text)
    if out.suffix.lower() != ".obj":
        raise InputError(f"{out}: the output must be an .obj file")
    return out


def _add_edit(sub: Any) -> None:
    p = sub.add_parser("edit", help="edit a net live in the browser: drag handles, the net "
                                    "follows as a net of its type (a local web page)")
    p.add_argument("input", help="quad mesh (OBJ); a net saved by fabplan edit reopens with "
                                 "its handles, pins and history")
    p.add_argument("--net", choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`); default: the one a saved net was "
                        "edited as")
    _add_number(p, "--angle", help="intersection angle in degrees (isogonal types)")
    _add_number(p, "--radius", help="Meusnier radius in model units")
    p.add_argument("--reference", help="surface the solves are pulled towards at their start "
                                       "and the deviation is shown from (default: the input)")
    _add_number(p, "--port", default=0, metavar="N", help="port on 127.0.0.1 (default: a free one)")
    p.add_argument("--no-open", action="store_true", help="print the page's address, do not "
                                                          "open a browser")
    p.add_argument("-o", "--output", required=True,
                   help="OBJ that Save writes; its record (handles, history) beside it as .json")
    _add_units(p)
    _add_verbosity(p)
    p.set_defaults(func=_cmd_edit)


_SUBCOMMANDS = [_add_nets, _add_measure, _add_optimize, _add_molds, _add_layout, _add_strips,
               _add_arcs, _add_mill, _add_study, _add_templates, _add_edit]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fabplan", description="Fabrication planning with principal symmetric meshes.")
    parser.add_argument("--version", action="version", version=f"fabplan {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


class _Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP: the run stops as at Ctrl-C, cleaning up what it staged."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


@contextmanager
def _stopped_by_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP raise `_Stopped` in the main thread while the command runs, so
    that they leave nothing behind, as Ctrl-C does; once one of them (or Ctrl-C) has come,
    the others are ignored, so that the cleanup runs to its end. A signal the process was
    started with ignored (``nohup``) stays ignored. The handlers before are restored."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    names = [s for s in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, s)]
    wanted = [n for n in names if signal.getsignal(getattr(signal, n)) is not signal.SIG_IGN]

    def stop(signum: int, frame: Any) -> None:
        for name in wanted:                 # the cleanup is not interrupted again
            signal.signal(getattr(signal, name), signal.SIG_IGN)
        raise KeyboardInterrupt if signum == signal.SIGINT else _Stopped(signum)

    before = {name: signal.signal(getattr(signal, name), stop) for name in wanted}
    try:
        yield
    finally:
        for name, handler in before.items():
            signal.signal(getattr(signal, name), handler)


def _one_line(message: str) -> str:
    """A message on one line: a line break or other control character that came in with a
    name the user gave is shown as its escape (``\\n``).

    Examples
    --------
    >>> _one_line("a\\nb.obj: no such file")
    'a\\\\nb.obj: no such file'
    """
    if message.isprintable():
        return message
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def _name_text(name: object) -> str:
    """A file name for a one-line message: as given when printable, else quoted with its
    escapes (a line break in it), shortened past 200 characters."""
    text = os.fsdecode(name) if isinstance(name, (str, bytes, os.PathLike)) else str(name)
    if not text.isprintable():
        text = repr(text)
    return text if len(text) <= 200 else text[:197] + "..."


def _unparsable(argv: list[str]) -> str | None:
    """Why an argument cannot be parsed as fabplan means it, or None: a NUL character (no
    shell passes one, a caller in Python can), or ``--`` given as an option's value
    (``--units=--``, ``-o--``), which argparse drops, handing the command an empty list
    (no option takes ``--``; a file of that name is ``./--``)."""
    for arg in map(str, argv):
        if "\x00" in arg:
            return f"{_one_line(_name_text(arg))}: an argument cannot hold a NUL character"
        if arg.startswith("-") and arg != "--" and (
                arg.endswith("=--") or (arg[1:2] != "-" and arg[2:] == "--")):
            return (f"{_one_line(_name_text(arg))}: '--' is no value of an option (a file "
                    "named '--' is ./--)")
    return None


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    refused = _unparsable(sys.argv[1:] if argv is None else argv)
    if refused is not None:
        print(f"fabplan: error: {refused}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        # a usage error or a value out of its range (one line printed), --help, --version
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        if getattr(args, "ifc", False):      # before any work: is IfcOpenShell there?
            from .io.ifc import ifcopenshell_module

            ifcopenshell_module()
        with _stopped_by_signals():
            code = args.func(args)
        for message in getattr(args, "warnings_after", []):
            _warn(message, getattr(args, "quiet", False))
        return code
    except CannotMakeError as exc:
        # the input is sound; what was asked cannot be made from it as it stands
        print(f"fabplan: cannot make it: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    except FabplanError as exc:
        print(f"fabplan: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except _Stopped as exc:
        import signal

        print(f"fabplan: stopped by {signal.Signals(exc.signum).name}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("fabplan: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (e.g. `| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except MemoryError:
        print("fabplan: error: out of memory: use a larger panel size or a smaller net "
              "(--max-panels sets the limit that is checked up front)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        # a file system failure while writing (disk full, a vanished folder): outputs are
        # staged, so nothing half-written is left; say what failed in one line
        where = f"{_name_text(exc.filename)}: " if exc.filename else ""
        print(f"fabplan: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
