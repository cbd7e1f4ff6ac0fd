"""`fabplan strips NET.obj --height MM --thickness MM -o DIR`: lamella strips along the
net's parameter lines, unrolled, slit, labelled and nested on sheets (DXF and a schedule),
run through the boundary panels to the edge of the cladding."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..fabricate.limits import DEFAULT_MAX_TWIST_DEG_PER_M
from ..io.output import check_output_folder, output_argument
from ..io.units import MM_PER_UNIT
from ..net.validate import load_net
from ..report.html import counted
from ..solve.net_types import NETS
from .arguments import (
    add_3dm,
    add_boundary_options,
    add_max_deviation_mm,
    add_max_panels,
    add_number,
    add_units,
    add_verbosity,
)
from .files import file_inputs, folder_apart, net_inputs, viewer_files
from .limits import deviation_check, limits_exit
from .records import boundary_panels_file, boundary_record, check_units, net_properties, net_units
from .registry import Command, register
from .running import command_progress

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..fabricate.strips.strip_plan import STRIP_FILES
    from ..io.resources import check_panel_count, worker_count

    worker_count(args.workers)  # a bad value fails before any work

    settings = _strip_settings(args)
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**net_inputs(args.net), **file_inputs((args.boundary, "the boundary panels"),
                                                    (args.design, "the design"))}
    folder_apart(out, [*STRIP_FILES, "strips.3dm", "strips.glb", "strips.ifc"], inputs)
    started = time.perf_counter()
    mesh = load_net(args.net)
    boundary_file, boundary = _strip_boundary(args, mesh)
    check_panel_count(len(mesh.face_sizes), max_panels=args.max_panels,
                      what=f"{args.net}: strips of a net of {len(mesh.face_sizes)} faces",
                      fix="plan the strips of a coarser net or of parts of it")
    check_units(args, mesh, settings.units)
    design = None
    if args.design is not None:
        from ..design.load import load_design

        design = load_design(args.design, triangles=args.triangles)
    progress = command_progress(args)
    plan, claim = _plan_strips(args, mesh, settings, boundary, progress)
    if design is not None:
        plan.limits.append(deviation_check(
            design.distances(mesh.vertices), units=settings.units,
            max_deviation=args.max_deviation_mm / MM_PER_UNIT[settings.units]))
    with progress.stage(f"writing {len(plan.nesting.sheets)} sheets and checking them"), \
            viewer_files(args, out / "strips", mesh, units=settings.units, strips=plan,
                         net_type=net_properties(args.net).get("net")) as viewers:
        files = plan.write(out, previews=not args.no_previews,
                           workers=worker_count(args.workers), protect=inputs) + viewers
    s = plan.summary()
    _warn_setbacks(s, settings)
    if args.quiet:
        print(f"{counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} on "
              f"{counted(s['sheets'], 'sheet')}; wrote {len(files)} files to {out}")
        return limits_exit(plan.limits, out / "strips.json",
                           _claim_text(plan, claim, mesh, settings, boundary))
    _print_strips(s, plan.limits, settings, files, out, started)
    if boundary is not None:
        _print_strip_boundary(s, settings, boundary_file, out)
    if s["junctions"]:
        print(f"fabplan: note: {s['junctions']} vertices join more than one strip of a family "
              "(irregular vertices): no slits there, they need node connectors; listed in "
              f"{out / 'strips.json'}", file=sys.stderr)
    return limits_exit(plan.limits, out / "strips.json",
                       _claim_text(plan, claim, mesh, settings, boundary))


def _claim_text(plan: Any, claim: str | None, mesh: Any, settings: Any, boundary: Any) -> str:
    """Why parts past the congruence tolerance matter, said after the warning: the net type
    its record names claims strips of one arc; and where the net's strips without its
    boundary panels keep to it, that the boundary panels are what breaks it."""
    from ..fabricate.strips.strip_plan import congruence_without_boundary_mm

    if claim is None or not any(c.exceeded and c.limit == "congruence_tolerance_mm"
                                for c in plan.limits):
        return ""
    why = f" (the net's record names it a {claim} net, whose strips are pieces of one arc"
    if boundary is None:
        return why + ")"
    alone = congruence_without_boundary_mm(mesh, settings)
    if alone > settings.tolerance_mm:
        return why + ")"
    return (f"{why}: without its boundary panels they are, up to {alone:.2g} mm: the strips "
            "the boundary panels lengthen follow the net's surface past its edge, not its "
            "radius; --no-boundary cuts the net's strips alone)")


def _strip_settings(args: argparse.Namespace) -> Any:
    """`StripSettings` from the command line, checked."""
    from ..fabricate.strips import StripSettings

    settings = StripSettings(
        height_mm=args.height, thickness_mm=args.thickness, clearance_mm=args.clearance,
        units=net_units(args, args.net), tolerance_mm=args.tolerance,
        sheet_mm=_parse_sheet(args.sheet),
        spacing_mm=args.spacing, margin_mm=args.margin, kerf_mm=args.kerf, end=args.end,
        end_extension_mm=args.extension, splice=args.splice, splice_length_mm=args.splice_length,
        labels=args.labels, label_height_mm=args.label_height, layers=_parse_layers(args.layer),
        one_file=args.one_file, boundary_member_mm=args.boundary_member,
        max_twist_deg_per_m=args.max_twist)
    settings.check()
    return settings


def _plan_strips(args: argparse.Namespace, mesh: Any, settings: Any, boundary: Any,
                 progress: Any) -> tuple[Any, str | None]:
    """The `StripPlan` of the net, and the net type its record claims strips of one arc for
    (`_constant_radius_claim`)."""
    from ..fabricate.strips import build_strips
    from ..fabricate.strips.nesting import make_parts, nest_parts
    from ..fabricate.strips.strip_plan import StripPlan, strip_limit_checks
    from ..io.resources import worker_count

    # the stages of `plan_strips`, one by one so that each shows its progress
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
    return plan, claim


def _print_strips(s: dict, limits: list, settings: Any, files: list, out: Path,
                  started: float) -> None:
    """The strips, their parts and sheets (`s`, the plan's summary), their `limits` and the
    files written, on stdout."""
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
    for check in limits:
        print(f"limit: {check.text()}")
    print(f"{s['parts']} parts on {s['sheets']} sheets of {settings.sheet_mm[0]:g}x"
          f"{settings.sheet_mm[1]:g} mm, material use {100 * s['material_use']:.1f} %")
    print(f"wrote {len(files)} files to {out} in {time.perf_counter() - started:.1f} s "
          f"(planning {s['seconds']:.1f} s, every sheet audited and checked before writing)")


def _print_strip_boundary(s: dict, settings: Any, boundary_file: Path | None, out: Path) -> None:
    """The strip ends at the edge of the cladding (`s`, the plan's summary), on stdout; the
    polylines along it and the ends not continued to it, on stderr."""
    from ..fabricate.strips.strip_boundary import MAX_TURN_DEG

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
    from ..fabricate.strips import StripSettings

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


def _free_ends_text(summary: dict) -> str:
    """``N ends are free: a inside the net (...), b along the edge, c not continued``."""
    from ..fabricate.strips.strip_boundary import MIN_MEMBER_ANGLE_DEG

    kinds = summary["ends_free_by_kind"]
    why = {"inside": "inside the net, where a line stops at an irregular vertex",
           "along edge": f"along the edge (meeting it at less than {MIN_MEMBER_ANGLE_DEG:g} deg)",
           "not continued": "not continued to the edge"}
    parts = [f"{kinds[k]} {text}" for k, text in why.items() if kinds.get(k)]
    free = summary["ends_free"]
    return f"{counted(free, 'end')} {'is' if free == 1 else 'are'} free" + \
        (": " + ", ".join(parts) if parts else "")


def _strip_boundary(args, mesh):
    """``(file, StripBoundary)`` of the boundary panels strips run through, or
    ``(None, None)`` (`boundary_panels_file`)."""
    from ..fabricate.strips.strip_boundary import StripBoundary

    path = boundary_panels_file(args)
    if path is None:
        return None, None
    return path, StripBoundary.from_obj(mesh, path, boundary_record(args))


def _warn_setbacks(s: dict, settings) -> None:
    """Warn of strip ends set back by more than half their last edge (also with --quiet):
    by the boundary member (is it that thick?), or where two strips end at one node
    nearly along each other (each clears the other), which no member thickness changes."""
    past, tips = s["ends_set_back_past_half_an_edge"], s["ends_set_back_at_tips"]
    if not past:
        return
    head = f"fabplan: warning: {counted(past, 'strip end')} {'is' if past == 1 else 'are'} " \
           f"set back by more than half their last edge (up to {s['member_setback_max_mm']:.0f} mm)"
    if tips:
        print(f"{head}: at {tips} of them two strips end at one node of the edge nearly "
              "along each other, and each is cut back to clear the other", file=sys.stderr)
    else:
        print(f"{head} by the {settings.member_mm:g} mm boundary member: is it that thick? "
              "(--boundary-member is in mm)", file=sys.stderr)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("net", help="the net (OBJ)")
    add_number(p, "--height", required=True, metavar="MM",
               help="lamella height; the surface runs along its middle")
    add_number(p, "--thickness", required=True, metavar="MM",
               help="material thickness (the slits are this plus --clearance wide)")
    add_units(p)
    p.add_argument("--sheet", default="2500x1250", metavar="WxH",
                   help="sheet size in mm (default 2500x1250)")
    add_number(p, "--spacing", default=10.0, metavar="MM",
               help="gap between parts (default 10)")
    add_number(p, "--margin", default=10.0, metavar="MM",
               help="gap to the sheet edge (default 10)")
    add_number(p, "--kerf", default=0.0, metavar="MM",
               help="cut width to compensate: outlines grow, slits shrink by half (default 0)")
    add_number(p, "--clearance", default=0.2, metavar="MM",
               help="play added to the slit width (default 0.2)")
    add_number(p, "--tolerance", default=0.1, metavar="MM",
               help="cutting tolerance for fitting arcs, and on a net whose record claims a "
               "constant radius how far a strip part may differ from the common arc "
               "(exit 3 beyond it; default 0.1)")
    add_number(p, "--max-twist", default=DEFAULT_MAX_TWIST_DEG_PER_M, metavar="DEG_PER_M",
               help="the largest twist of a strip, in degrees per metre; a strip that twists "
               f"more ends the run in exit 3 (default {DEFAULT_MAX_TWIST_DEG_PER_M:g}, see "
               "docs/fabrication-limits.md)")
    p.add_argument("--end", choices=["square", "round"], default="square",
                   help="strip ends (default square)")
    add_number(p, "--extension", metavar="MM",
               help="material beyond the end crossings at free ends (default height / 2)")
    add_boundary_options(p, "strips run through them to the edge of the cladding and are "
                         "cut square against a boundary member there",
                         "end the strips at the net's last vertices")
    add_number(p, "--boundary-member", metavar="MM",
               help="thickness of the boundary member strips end against (default "
               "--thickness)")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net lies on (a mesh file, a built-in surface spec or "
                        "a .3dm NURBS surface as for `fabplan layout`): the net's vertices are "
                        "checked against --max-deviation-mm from it")
    add_number(p, "--triangles", default=20000, metavar="N",
               help="triangles of the --design's triangulation, where the exact surface is "
               "searched from (default 20000)")
    add_max_deviation_mm(p)
    p.add_argument("--splice", choices=["overlap", "lap"], default="overlap",
                   help="joint of a strip split to fit the sheets (default overlap)")
    add_number(p, "--splice-length", metavar="MM",
               help="length of a splice (default 2 x height)")
    p.add_argument("--labels", choices=["stroke", "outline", "text"], default="stroke",
                   help="engraved labels: single-stroke lines, glyph outlines or DXF TEXT "
                        "(default stroke)")
    add_number(p, "--label-height", metavar="MM",
               help="strip label height (default 0.12 x height, 3-20 mm)")
    p.add_argument("--layer", action="append", metavar="KIND=NAME[:COLOUR]",
                   help="layer name and colour for cut, slit or engrave (defaults CUT:1 red, "
                        "SLIT:6 magenta, ENGRAVE:5 blue); repeatable")
    p.add_argument("--one-file", action="store_true",
                   help="all sheets side by side in one DXF instead of one file per sheet")
    p.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    p.add_argument("--workers", metavar="N|auto", default="auto",
                   help="write the sheets in N processes (default auto: one per core)")
    add_max_panels(p)
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the files")
    add_3dm(p)
    add_verbosity(p)


COMMAND = register(Command("strips", "lamella strips along the parameter lines, unrolled, "
                                     "slit, labelled and nested on sheets (DXF + schedule)",
                           add_arguments, run))
