"""`fabplan edit NET.obj --net TYPE -o OUT.obj`: open a net (reopening a saved one where it
was left) and serve it until Ctrl-C or the last page closes."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..net.validate import load_net
from ..solve.net_types import NETS, check_angle, check_radius
from .record import read_saved

__all__ = ["edit_command"]


def edit_command(args: argparse.Namespace, output: Path, *, reference: Any = None,
                 units: str = "m") -> int:
    """Run the command on parsed arguments (`fabplan.cli`); returns the exit code."""
    from .server import require_web_stack, run_editor
    from .session import EditOptions, EditSession

    require_web_stack()                       # the optional extra, before any work
    check_angle(args.angle)
    check_radius(args.radius)
    mesh = load_net(args.input)
    saved = read_saved(args.input)
    options = dict(saved.options) if saved is not None else {}
    if args.net is None and "net" not in options:
        raise InputError(f"{args.input}: give the net type with --net (one of "
                         f"{', '.join(NETS)}); only a net saved by fabplan edit knows its own")
    if args.net is not None and args.net != options.get("net"):
        # another type than the one saved: its prescribed values do not carry over
        options = {k: v for k, v in options.items() if k not in ("angle", "radius")}
        options["net"] = args.net
    for key in ("angle", "radius"):
        if getattr(args, key) is not None:
            options[key] = getattr(args, key)
    options["units"] = units
    session = EditSession(mesh, EditOptions(**options), reference=reference,
                          handles=saved.handles if saved else (), pins=saved.pins if saved else (),
                          history=saved.history if saved else None, source=str(args.input))
    if not args.quiet:
        reopened = (f"; reopened with {len(session.handles)} handles and {len(session.pins)} pins"
                    if saved is not None else "")
        print(f"fabplan edit: {Path(args.input).name} as {session.options.net}: "
              f"{session.status}{reopened}", flush=True)
    return run_editor(session, output, port=args.port, open_browser=not args.no_open,
                      quiet=args.quiet)
