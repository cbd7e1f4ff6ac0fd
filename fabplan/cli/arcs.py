"""`fabplan arcs NET.obj -o OUT.3dm|OUT.dxf`: the circular arc structure of a net, every
edge replaced by the arc in which its end vertices' spheres meet."""

from __future__ import annotations

import argparse

from ..errors import InputError
from ..fabricate.limits import DEFAULT_MAX_ARC_ANGLE_DEG
from ..io.output import output_argument
from ..net.validate import load_net
from ..report.html import counted
from .arguments import add_number, add_units, add_verbosity
from .files import check_outputs, net_inputs
from .limits import limits_exit
from .records import check_units, net_units
from .registry import Command, register
from .running import command_progress

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..fabricate.arcs import arc_limit_checks, arc_structure, write_arcs

    out = output_argument(args.output)
    if out.suffix.lower() not in (".3dm", ".dxf"):
        raise InputError(f"{out}: the output must be a .3dm or a .dxf file")
    check_outputs([out, out.with_suffix(".json")], net_inputs(args.net))
    mesh = load_net(args.net, quads=False)
    units = net_units(args, args.net)
    check_units(args, mesh, units)
    progress = command_progress(args)
    with progress.stage("the arcs"):
        arcs = arc_structure(mesh)
    limits = arc_limit_checks(arcs, max_arc_angle_deg=args.max_arc_angle)
    with progress.stage("writing the arcs"):
        files = write_arcs(arcs, out, units=units, limits=limits)
    s = arcs.summary()
    if args.quiet:
        print(f"{counted(s['arcs'], 'arc')}; wrote {files[0]}")
        return limits_exit(limits, files[1])
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
    return limits_exit(limits, files[1])


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("net", help="the net (OBJ)")
    add_units(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT.3dm|OUT.dxf",
                   help="the arcs as Rhino ArcCurves or DXF ARC entities; the report goes to "
                        "OUT.json")
    add_number(p, "--max-arc-angle", default=DEFAULT_MAX_ARC_ANGLE_DEG, metavar="DEG",
               help="the largest central angle of an arc the bending shop takes; a longer arc "
               f"ends the run in exit 3 (default {DEFAULT_MAX_ARC_ANGLE_DEG:g}, see "
               "docs/fabrication-limits.md)")
    add_verbosity(p)


COMMAND = register(Command("arcs", "circular arc structure: every edge replaced by the arc in "
                                   "which its end vertices' spheres meet (3dm or DXF + JSON)",
                           add_arguments, run))
