"""`fabplan layout SURFACE --net TYPE --panel-size L -o OUT.obj`: lay out a net on a design
surface and optimize it gliding on the surface (OBJ, JSON, PNG; a page and Rhino files on
request), from several starts, keeping the fairest."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.output import atomic_path
from ..io.units import DEFAULT_UNITS, UNIT_WORDS, units_warning
from ..net.measure import edge_jump_warning, format_summary
from ..report.html import counted
from ..solve.net_types import NETS, check_angle
from ..solve.optimize import check_limits
from .arguments import (
    add_3dm,
    add_html,
    add_max_line_turn,
    add_max_panels,
    add_number,
    add_units,
    add_verbosity,
)
from .cladding import boundary_text, boundary_warnings
from .files import (
    check_option_files,
    check_outputs,
    file_inputs,
    html_file,
    listing,
    obj_output,
    viewer_files,
    viewer_paths,
)
from .memory import check_layout_size, check_triangles
from .registry import Command, register
from .running import EXIT_NOT_CONVERGED, command_progress, warn_after
from .solving import solver_options, warn_not_converged

__all__ = ["COMMAND", "LINE_TURN_WARNING_DEG", "add_arguments", "layout_warnings", "run"]

#: a layout whose net's lines turn more than this at a vertex (degrees) is warned about
LINE_TURN_WARNING_DEG = 45.0


def run(args: argparse.Namespace) -> int:
    from ..design.load import load_design
    from ..solve.net_types import get_net

    preset = get_net(args.net)
    out, picture = _layout_outputs(args, preset)
    check_triangles(args.surface, args.triangles)
    design = load_design(args.surface, triangles=args.triangles)
    if design.source is not None and not args.quiet:
        print(f"design: {design.source['object']} of {design.source['file']}, in "
              f"{_units_said(design.units)}" + (f" (converted from {design.source['file_units']})"
                                                if design.source["scale"] != 1 else ""))
    units = _design_units(args, design)
    check_layout_size(design, args.panel_size, args.max_panels)
    warn_after(args, units_warning(Path(design.name).name, units, panel=args.panel_size,
                                   extent=design.extent, strict=args.strict_units))
    progress = command_progress(args)    # after the checks: a refusal is one line on its own
    layout, result = _solve_layout(args, preset, design, progress)
    result.properties["units"] = units
    angle = result.parameters.get("angle_deg")
    title = (f"{preset.name} on {Path(design.name).name}, panel {args.panel_size:g}"
             + (f", {layout.family}" if layout.family else
                f", {angle:.4g} deg" if isinstance(angle, float) else ""))
    # the picture and the Rhino files land only with the net they show
    with progress.stage("writing the net and its picture" + (" and page" if args.html else "")), \
            atomic_path(picture) as staged, html_file(args, out) as page, \
            viewer_files(args, out, result.mesh, units=units, boundary=result.boundary_panels,
                         net_type=result.net) as viewers:
        _write_picture_and_page(args, design, layout, result, staged, page,
                                title=title, units=units, picture=picture)
        obj_path, json_path = result.write(out)
    if page is not None:
        viewers = [out.with_suffix(".html"), *viewers]
    _print_layout_result(args, result, layout, obj_path, json_path, [picture, *viewers],
                         ring=boundary_ring_share(design, args.panel_size))
    if not result.converged:
        warn_not_converged(result, json_path)
        if args.quiet:
            return EXIT_NOT_CONVERGED
        if preset.radius == "param" or preset.planar_faces:
            print(f"fabplan: note: {preset.name} nets exist on special surfaces only; held this "
                  f"close to the design the net cannot become one. `fabplan optimize {obj_path} --net "
                  f"{preset.name} --reference {args.surface}` lets it leave the design a little "
                  "(`fabplan study` measures how far)", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def _layout_outputs(args: argparse.Namespace, preset: Any) -> tuple[Path, Path]:
    """The output net and its picture, after refusing options that cannot go together and
    outputs that would replace an input or cannot be written."""
    from ..solve.optimize import boundary_path

    _check_layout_options(args, preset)
    check_limits(None, args.max_line_turn)
    out = obj_output(args.output)
    picture = out.with_suffix(".png")
    check_option_files((args.family, "a file of polylines"))
    family_file = args.family if args.family and Path(args.family).is_file() else None
    check_outputs([out, out.with_suffix(".json"), boundary_path(out), picture,
                   *viewer_paths(args, out)],
                  file_inputs((args.surface, "the design"), (family_file, "the family file")))
    return out, picture


def _solve_layout(args: argparse.Namespace, preset: Any, design: Any, progress: Any) -> tuple[Any, Any]:
    """The layout and its solved net, the fairest of ``--starts`` (`glide_fairest`)."""
    from ..layout.settings import LayoutSettings
    from ..layout.starts import glide_fairest
    from ..layout.surface_layout import layout_angle

    start = layout_angle(preset.name, design, args.angle) if args.family is None else 90.0
    settings_layout = (LayoutSettings() if args.smoothing is None else
                       LayoutSettings(smoothing=args.smoothing, smoothing_tries=()))
    settings, report = solver_options(args, progress)
    with progress.stage("laying out the net and solving it on the design") as stage:
        report.stage = stage

        def starting(k: int, n: int, name: str) -> None:
            if n > 1:
                report.prefix = f"start {k + 1} of {n} ({name}), "
                stage.note(report.prefix.rstrip(", "))

        return glide_fairest(
            design, args.panel_size, preset.name, angle=start,
            net_angle=args.angle if preset.angle == "param" else None, family=args.family,
            settings=settings_layout, solver=settings, starts=args.starts,
            vary_smoothing=args.smoothing is None, progress=report, on_start=starting,
            max_line_turn=args.max_line_turn)


def _write_picture_and_page(args: argparse.Namespace, design: Any, layout: Any, result: Any,
                            staged: Path, page: Path | None, *, title: str, units: str,
                            picture: Path) -> None:
    """The net's picture to `staged` (landing as `picture`) and, with ``--html``, its page
    to `page`."""
    from ..layout.picture import fairness_marks, write_layout_picture

    write_layout_picture(staged, design, result.mesh, title=title,
                         singular_points=layout.singular_points,
                         marks=fairness_marks(result.properties),
                         boundary_panels=result.boundary_panels)
    if page is not None:
        import numpy as np

        from ..layout.picture import curvature_difference_figure, kink_text
        from ..layout.view import net_view_html

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


def _print_layout_result(args: argparse.Namespace, result: Any, layout: Any, obj_path: Path,
                         json_path: Path, others: list[Path], *, ring: float = 0.0) -> None:
    """The solve's outcome in a line with -q; else what was measured on the net, the time
    taken, the files written (the net, its record, its boundary panels, `others`) and the
    warnings."""
    from ..solve.optimize import boundary_path

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
        print(f"wrote {listing([obj_path, json_path, boundary_path(obj_path), *others])}")
        for warning in layout_warnings(props, ring):
            print(f"fabplan: warning: {warning}", file=sys.stderr)


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


def boundary_ring_share(design: Any, panel_size: float) -> float:
    """The share of a design's area within a panel of its boundary (its boundary's length
    times the panel size, over its area): what one row of boundary panels may cover."""
    length = sum(design.loop_length(loop) for loop in design.boundary_loops)
    return float(length * panel_size / design.area) if design.area > 0 else 0.0


def layout_warnings(properties: dict, ring: float = 0.0) -> list:
    """What a user should know about a layout's measured result, in plain words; `ring`
    the share of the design that one row of boundary panels may cover
    (`boundary_ring_share`), which boundary panels and patches may cover before the layout
    is said to stop short of the boundary."""
    out = boundary_warnings(properties)
    coverage = properties["coverage"]
    net = properties.get("coverage_net", coverage)
    if coverage - net > max(0.1, ring):
        out.append(f"the full panels cover only {100 * net:.0f} % of the design: the layout stops far "
                   "short of the boundary or leaves holes, and boundary panels and patches cover "
                   f"{100 * (coverage - net):.0f} %, more than a row of panels along the boundary "
                   f"would ({100 * ring:.0f} %) (try a smaller --panel-size)")
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
    if (jumps := edge_jump_warning(properties.get("buildable"))) is not None:
        out.append(jumps)
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


def _first_sentence(doc: str | None) -> str:
    """The first paragraph of a docstring on one line, without reST literals: what a
    built-in surface is (``width`` and ``depth`` are half-sizes: ``[-width, width]``)."""
    return " ".join((doc or "").strip().split("\n\n")[0].split()).replace("``", "")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("surface", help="design surface: a triangle mesh (OBJ/STL/PLY/OFF), a Rhino "
                                   "file 'FILE.3dm[#layer=L,object=NAME,face=K,units=U]' (a NURBS "
                                   "surface, polysurface face or mesh), or a built-in surface "
                                   "'NAME[:key=value,...]' (hyperbolic-paraboloid, paraboloid, torus, "
                                   "revolution, tower-facade, height-field, bspline)")
    p.add_argument("--net", required=True, choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`)")
    add_number(p, "--angle",
               help="intersection angle of the two families in degrees (default 90)")
    add_number(p, "--panel-size", required=True, metavar="L",
               help="target edge length in model units")
    p.add_argument("--family", metavar="x|y|z[:STEP]|FILE",
                   help="prescribe the first family: x, y or z (levels of a coordinate, e.g. "
                        "floors; z:3.5 for levels every 3.5), or a file of polylines (OBJ "
                        "'l' lines or 'x y z' rows with blank lines between curves)")
    add_number(p, "--triangles", default=40000,
               help="triangles of a built-in surface's triangulation (default 40000)")
    add_number(p, "--max-iter", help="iteration cap (default 50)")
    add_number(p, "--smoothing", metavar="PANELS",
               help="smooth the principal directions over this many panels and no other "
               "(default: from half a panel, longer while the lattice leaves the design "
               "unclad; longer smoothing holds the lattice together near umbilics, "
               "shorter keeps the lines fairer after the solve)")
    add_number(p, "--starts", default=5, metavar="N",
               help="lay the net out and solve it from up to N starts (as set; the "
               "fairness term held longer in the solve; the other principal direction "
               "as the bisector, at angles other than 90 deg; the directions smoothed "
               "twice as long; smoothed as a line field) and keep the one that clads "
               "the design, converges and, among those whose panels are as even as "
               "the first start's, whose lines turn least (default 5; 1 is the "
               "fastest)")
    add_max_panels(p)
    add_max_line_turn(p)
    p.add_argument("-o", "--output", required=True,
                   help="output OBJ; its .json and .png sit beside it")
    add_html(p)
    add_3dm(p)
    add_units(p)
    add_verbosity(p)


def _parser_options() -> dict:
    """The built-in surfaces and their parameters, after the options."""
    from ..design.parametric import SURFACES, describe_surface_parameters

    return {"formatter_class": argparse.RawDescriptionHelpFormatter,
            "epilog": "built-in surfaces and their parameters (defaults):\n" + "\n".join(
                f"  {name}: {describe_surface_parameters(name)}\n"
                f"      {_first_sentence(SURFACES[name].__doc__)}" for name in SURFACES)}


COMMAND = register(Command("layout", "lay out an S-net on a design surface and optimize it "
                                     "gliding on the surface (OBJ + JSON + PNG)",
                           add_arguments, run, _parser_options))
