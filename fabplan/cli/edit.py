"""`fabplan edit NET.obj --net TYPE -o OUT.obj`: edit a net live in the browser
(`fabplan.edit`)."""

from __future__ import annotations

import argparse

from ..solve.net_types import NETS
from .arguments import add_number, add_units, add_verbosity
from .files import check_outputs, file_inputs, net_inputs, obj_output
from .records import net_units, reference_surface
from .registry import Command, register

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..edit.command import edit_command

    out = obj_output(args.output)
    check_outputs([out, out.with_suffix(".json")],
                  {**net_inputs(args.input), **file_inputs((args.reference, "the reference"))})
    return edit_command(args, out, reference=reference_surface(args.reference),
                        units=net_units(args, args.input))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="quad mesh (OBJ); a net saved by fabplan edit reopens with "
                                 "its handles, pins and history")
    p.add_argument("--net", choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`); default: the one a saved net was "
                        "edited as")
    add_number(p, "--angle", help="intersection angle in degrees (isogonal types)")
    add_number(p, "--radius", help="Meusnier radius in model units")
    p.add_argument("--reference", help="surface the solves are pulled towards at their start "
                                       "and the deviation is shown from (default: the input)")
    add_number(p, "--port", default=0, metavar="N", help="port on 127.0.0.1 (default: a free one)")
    p.add_argument("--no-open", action="store_true", help="print the page's address, do not "
                                                          "open a browser")
    p.add_argument("-o", "--output", required=True,
                   help="OBJ that Save writes; its record (handles, history) beside it as .json")
    add_units(p)
    add_verbosity(p)


COMMAND = register(Command("edit", "edit a net live in the browser: drag handles, the net "
                                   "follows as a net of its type (a local web page)",
                           add_arguments, run))
