"""`fabplan measure NET.obj`: the S-net properties of a quad mesh, printed and written as
JSON."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError
from ..fabricate.limits import limits_record
from ..io.output import output_argument
from ..io.records import write_json
from ..net.buildable import BuildLimits
from ..net.measure import buildable_summary, format_summary, measure_net
from ..net.validate import load_net
from ..solve.optimize import check_limits
from .arguments import add_max_line_turn, add_number, add_units
from .files import check_outputs, file_inputs, net_inputs
from .limits import deviation_check, deviation_limit, deviation_option, limits_exit
from .records import check_units, net_units, reference_surface
from .registry import Command, register
from .running import EXIT_NOT_CONVERGED

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    out = (output_argument(args.output) if args.output is not None
           else Path(args.net).with_suffix(".measure.json"))
    check_limits(args.max_deviation, args.max_line_turn)
    if (args.max_deviation is not None or args.max_deviation_mm is not None) \
            and args.reference is None:
        raise InputError(f"{deviation_option(args)} needs --reference: the surface to measure "
                         "the distance to")
    check_outputs([out], {**net_inputs(args.net), **file_inputs((args.reference, "the reference"))})
    mesh = load_net(args.net)
    units = net_units(args, args.net)
    check_units(args, mesh, units)
    args.max_deviation = deviation_limit(args, mesh, units)
    reference = reference_surface(args.reference)
    record = measure_net(mesh, reference=reference, limits=BuildLimits(
        max_line_turn_deg=args.max_line_turn, max_deviation=args.max_deviation))
    record["file"] = str(args.net)
    record["units"] = units
    limits = []
    if reference is not None:      # the same limit as optimize's, 20 mm unless given
        limits = [deviation_check(reference.distances(mesh.vertices), units=units,
                                  max_deviation=args.max_deviation, option=deviation_option(args))]
        record["limits"] = limits_record(limits)
    write_json(out, record)           # the file first: the terminal may go away
    print(format_summary(record))
    for check in limits:
        print(f"limit: {check.text()}")
    print(f"wrote {out}")
    build = record.get("buildable")
    if build is not None and not build["buildable"]:
        # measured against its limits, as the other commands' parts are: a script can
        # tell a net that cannot be built from one that can
        print(f"fabplan: warning: {args.net} is "
              f"{buildable_summary(build, record.get('folds'))}; counted in {out} "
              "(buildable)", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return limits_exit(limits, out)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("net", help="quad mesh (OBJ)")
    p.add_argument("-o", "--output", help="JSON file to write (default: NET.measure.json)")
    p.add_argument("--reference", help="surface to measure the distance to (OBJ/STL/PLY/OFF, "
                                       "FILE.3dm[#...] or a built-in surface)")
    add_number(p, "--max-deviation", metavar="D",
               help="count the vertices farther than D (model units) from --reference as "
                    "keeping the net from being built")
    add_number(p, "--max-deviation-mm", metavar="MM",
               help="--max-deviation in mm, whatever the net's units")
    add_max_line_turn(p, measured=True)
    add_units(p)


COMMAND = register(Command("measure", "measure the S-net properties of a quad mesh",
                           add_arguments, run))
