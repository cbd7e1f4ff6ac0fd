"""The command line's parser and the options several commands share: numbers checked
against their ranges as they are parsed (`fabplan.io.parameters`), units, verbosity, the
viewer files, the fabrication limits and the boundary panels."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import InputError
from ..fabricate.limits import DEFAULT_MAX_DEVIATION_MM
from ..io.parameters import Parameter, option_parameter
from ..io.units import DEFAULT_UNITS, MM_PER_UNIT
from .running import EXIT_BAD_INPUT

__all__ = ["InRange", "Parser", "add_3dm", "add_boundary_options", "add_html", "add_ifc",
           "add_max_deviation_mm", "add_max_line_turn", "add_max_panels", "add_number",
           "add_units", "add_verbosity"]


class Parser(argparse.ArgumentParser):
    """Usage errors as one line and exit code 2, like every other bad input."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"fabplan: error: {message} (see '{self.prog} --help')\n")


class InRange(argparse.Action):
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


def add_number(p: argparse.ArgumentParser, option: str, *, help: str, **kwargs: Any) -> None:
    """A numeric option, checked against its range in `fabplan.io.parameters.OPTIONS`
    (which every numeric option must have), the range stated in its help."""
    parameter = option_parameter(p.prog.split()[-1], option)
    units = f" {parameter.units}" if parameter.units else ""
    p.add_argument(option, action=InRange, parameter=parameter,
                   help=f"{help} (range {parameter.interval}{units}"
                        f"{', a whole number' if parameter.integer else ''})", **kwargs)


def add_max_deviation_mm(p: argparse.ArgumentParser) -> None:
    """The deviation limit of a net checked against its --design (molds, strips)."""
    add_number(p, "--max-deviation-mm", default=DEFAULT_MAX_DEVIATION_MM, metavar="MM",
               help="with --design: the largest distance of a net vertex from the design, in "
               f"mm; a net farther off ends the run in exit 3 (default "
               f"{DEFAULT_MAX_DEVIATION_MM:g}, see docs/fabrication-limits.md)")


def add_max_panels(p: argparse.ArgumentParser, *, memory: bool = False) -> None:
    add_number(p, "--max-panels", metavar="N",
               help="refuse nets of more faces than this (default: what half the available "
               "memory holds, estimated from the net's faces)" if memory else
               "refuse runs estimated to need more panels than this (default: what "
               "half the available memory holds, at least 20000)")


def add_max_line_turn(p: argparse.ArgumentParser, *, measured: bool = False) -> None:
    """--max-line-turn: for a command that solves (`measured` False) or one that measures a
    net as it is (`fabplan measure`)."""
    add_number(p, "--max-line-turn", default=90.0, metavar="DEG",
               help="a buildable net's lines turn in the surface by at most DEG at any vertex "
               "(default 90: over it a line doubles back); a net that turns more, or has a "
               "non-convex quad, is not buildable (exit 3)" if measured else
               "a converged net's lines turn in the surface by at most DEG at any vertex "
               "(default 90: over it a line doubles back); a net within tolerance that "
               "turns more, or has a non-convex quad, ends 'crumpled' (exit 3)")


def add_verbosity(p: argparse.ArgumentParser) -> None:
    """-q and -v, the same for every long-running command (`fabplan.report.progress`)."""
    level = p.add_mutually_exclusive_group()
    level.add_argument("-q", "--quiet", action="store_true",
                       help="print only errors and a one-line summary")
    level.add_argument("-v", "--verbose", action="store_true",
                       help="also print every solver iteration")


def add_boundary_options(p: argparse.ArgumentParser, use: str, without: str) -> None:
    """``--boundary FILE`` and ``--no-boundary``: what the command does with a net's boundary
    panels (`use`), and without them (`without`)."""
    ends = p.add_mutually_exclusive_group()
    ends.add_argument("--boundary", metavar="FILE",
                      help="the net's boundary panels (default: NET.boundary.obj beside the net, "
                           f"as layout, optimize and study write it): {use}")
    ends.add_argument("--no-boundary", action="store_true",
                      help=f"{without}, even when boundary panels are beside it")


def add_html(p: argparse.ArgumentParser) -> None:
    p.add_argument("--html", action="store_true",
                   help="also write OUT.html: a page that opens offline with the net in an "
                        "interactive 3D view (colour by deviation, Meusnier radius, angle, "
                        "kink, line turn; boundary panels green), its key numbers and its "
                        "picture (about 0.7 MB, most of it the viewer)")


def add_units(p: argparse.ArgumentParser, default: str = DEFAULT_UNITS) -> None:
    """--units (the same five on every command) and --strict-units."""
    p.add_argument("--units", choices=list(MM_PER_UNIT), metavar="U",
                   help="unit of the model's coordinates: mm, cm, m, in or ft (default: the "
                        f"units the net's record NET.json states, else {default})")
    p.add_argument("--strict-units", action="store_true",
                   help="refuse, instead of warning, a net or design whose size does not fit "
                        "its units (panels under 10 mm or over 20 m, a design under 1 m in "
                        "metres or feet)")


def add_3dm(p: argparse.ArgumentParser) -> None:
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write the net as a Rhino .3dm file (mesh, polylines per family, "
                        "panels per mold, strip curves; ids as in the CSV/JSON) and a .glb "
                        "for web viewers, coloured by mold")
    add_ifc(p, "the net as an IFC4 file beside them")


def add_ifc(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--ifc", action="store_true",
                   help=f"also write {what}: panels as IfcPlate (their surfaces, mold ids), "
                        "molds as IfcGroup, lamellas as IfcMember, the net as a structural "
                        "analysis model (docs/ifc.md; needs pip install 'fabplan[ifc]')")


