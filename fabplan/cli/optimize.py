"""`fabplan optimize NET.obj --net TYPE -o OUT.obj`: optimize a quad mesh into a net of a
given type, near a reference surface, with vertices held or moved by handles."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from ..fabricate.limits import DEFAULT_MAX_DEVIATION_MM, limits_record
from ..net.measure import edge_jump_warning, format_summary
from ..net.validate import load_net
from ..report.html import counted
from ..solve.handles import read_fixed, read_handles
from ..solve.net_types import NETS, check_angle, check_radius
from ..solve.optimize import (
    boundary_path,
    check_limits,
    check_net_input,
    optimize,
)
from .arguments import add_3dm, add_html, add_max_line_turn, add_number, add_units, add_verbosity
from .cladding import boundary_warnings
from .files import (
    check_option_files,
    check_outputs,
    file_inputs,
    html_file,
    layout_design_inputs,
    listing,
    net_inputs,
    obj_output,
    viewer_files,
    viewer_paths,
)
from .limits import deviation_check, deviation_limit, deviation_option, limits_exit
from .records import check_units, net_properties, net_units, reference_surface
from .registry import Command, register
from .running import EXIT_NOT_CONVERGED, command_progress, warn
from .solving import solver_options, warn_not_converged

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    check_angle(args.angle)
    check_radius(args.radius)
    check_limits(args.max_deviation, args.max_line_turn)
    check_option_files((None if args.fix == "boundary" else args.fix, "a file of vertex ids"),
                       *[(h, "a file of handles") for h in args.handle or []])
    out = _output_path(args)
    mesh = load_net(args.input)
    check_net_input(mesh)
    units = net_units(args, args.input)
    check_units(args, mesh, units)
    args.max_deviation = deviation_limit(args, mesh, units)
    reference = reference_surface(args.reference)
    fixed = read_fixed(args.fix, mesh)
    handles = read_handles(args.handle)
    progress = command_progress(args)
    settings, report = solver_options(args, progress)
    with progress.stage("solving") as stage:
        report.stage = stage
        result = optimize(mesh, args.net, angle=args.angle, radius=args.radius,
                          reference=reference, fixed=fixed, handles=handles, settings=settings,
                          coherent=args.coherent, guards=args.guards,
                          settle_free=0.0 if args.settle_free else None,
                          max_deviation=args.max_deviation, max_line_turn=args.max_line_turn,
                          progress=report)
    result.properties["units"] = units
    limits = _deviation_limits(mesh, result, reference, units, args.max_deviation,
                               deviation_option(args))
    _record_reference(result, args.reference)
    panels_note = _boundary_panels_again(Path(args.input), mesh, result, progress)
    with progress.stage("writing the net" + (" and its page" if args.html else "")), \
            html_file(args, out) as page, \
            viewer_files(args, out, result.mesh, units=units, boundary=result.boundary_panels,
                         net_type=result.net) as viewers:
        if page is not None:
            from ..layout.view import net_view_html
            from ..solve.reference import ReferenceSurface

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
    print(f"wrote {listing([*written, *viewers])}" if not args.quiet else
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
            warn(warning)
    if (jumps := edge_jump_warning(result.properties.get("buildable"))) is not None:
        warn(jumps)
    if not result.converged:
        warn_not_converged(result, json_path)
        return EXIT_NOT_CONVERGED
    return limits_exit(limits, json_path)


def _deviation_limits(mesh, result, reference, units: str, max_deviation: float | None,
                      option: str) -> list:
    """The net against the deviation limit from its reference, recorded under
    ``properties.limits``; without a reference none (`_note_the_move`)."""
    if reference is None:
        _note_the_move(mesh, result, units)
        return []
    limits = [deviation_check(reference.distances(result.mesh.vertices), units=units,
                              max_deviation=max_deviation, option=option)]
    result.properties["limits"] = limits_record(limits)
    return limits


def _record_reference(result, spec: str | None) -> None:
    """Name the reference in the net's record (``properties.reference``: a file's absolute
    path, else the built-in spec), so that the commands after (`fabplan mill`) measure
    against the design the net was held to."""
    if spec is None:
        return
    file = spec.split("#")[0]          # a Rhino source keeps its #object=... tail
    try:
        found = Path(file).is_file()
    except OSError:                    # a built-in spec longer than a file name may be
        found = False
    result.properties["reference"] = str(Path(file).resolve()) + spec[len(file):] if found else spec


def _note_the_move(mesh, result, units: str) -> None:
    """Without --reference nothing holds the net to a design, and no deviation limit is
    checked: record how far its vertices moved from the input (model units,
    ``moved_from_input_max``), and say so where that is more than the deviation limit a
    reference would be checked against."""
    import numpy as np

    from ..io.units import MM_PER_UNIT

    moved = float(np.linalg.norm(result.mesh.vertices - mesh.vertices, axis=1).max(initial=0.0))
    result.properties["moved_from_input_max"] = moved
    mm = moved * MM_PER_UNIT[units]
    if mm > DEFAULT_MAX_DEVIATION_MM:
        print(f"fabplan: note: the net moved up to {mm:.1f} mm from the input, and nothing held "
              "it to a design: give --reference DESIGN to keep it within "
              f"{DEFAULT_MAX_DEVIATION_MM:g} mm (or --max-deviation) of it", file=sys.stderr)


def _output_path(args) -> Path:
    out = obj_output(args.output)
    inputs = {**net_inputs(args.input), **layout_design_inputs(args.input),
              **file_inputs((args.reference, "the reference"),
                            (None if args.fix == "boundary" else args.fix, "the file of fixed vertices")),
              **{Path(h): "a handle file" for h in args.handle or [] if ":" not in h}}
    check_outputs([out, out.with_suffix(".json"), boundary_path(out), *viewer_paths(args, out)],
                  inputs)
    return out


def _boundary_panels_again(source: Path, mesh, result, progress) -> str | None:
    """Trim an optimized layout net to its design again, as its layout did: the layout
    recorded in ``NET.json`` is made again (`layout_again`) and, when it gives the net's
    faces, the optimized net's boundary panels are cut from it. Only for a net with a
    ``NET.boundary.obj`` beside it. Returns a note when the panels could not be cut."""
    old = boundary_path(source)
    if not old.is_file():
        return None
    # imported here: the layout's modules take a third of a second, and most nets have no
    # boundary panels
    import numpy as np

    from ..layout.surface_layout import layout_again
    from ..layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels

    lost = (f"the boundary panels of {old} belong to the net before it was optimized and "
            "were not carried over")
    layout_record = net_properties(source).get("layout")
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


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="quad mesh (OBJ)")
    p.add_argument("--net", required=True, choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`)")
    add_number(p, "--angle", help="intersection angle in degrees (isogonal types)")
    add_number(p, "--radius", help="Meusnier radius in model units")
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
    add_number(p, "--max-deviation", metavar="D",
               help="keep every vertex within D (model units) of the reference: a limit held "
               "in the solve; a net type that cannot keep to it ends 'off-design' (exit "
               "3) with the smallest limit it reached. Without it a net with --reference "
               f"is checked against {DEFAULT_MAX_DEVIATION_MM:g} mm (not held in the "
               "solve; exit 3 beyond it, see docs/fabrication-limits.md)")
    add_number(p, "--max-deviation-mm", metavar="MM",
               help="--max-deviation in mm, whatever the net's units")
    add_max_line_turn(p)
    add_number(p, "--max-iter", help="iteration cap (default 50)")
    p.add_argument("--no-multilevel", action="store_true",
                   help="solve a large grid net at full size from the start (by default, from "
                        "20,000 vertices, its coarse net of every second line is solved first)")
    p.add_argument("-o", "--output", required=True, help="output OBJ; its .json sits beside it")
    add_html(p)
    add_3dm(p)
    add_units(p)
    add_verbosity(p)


COMMAND = register(Command("optimize", "optimize a quad mesh into a net of a given type",
                           add_arguments, run))
