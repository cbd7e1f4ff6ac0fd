"""What a command reads with its net: the record ``NET.json`` beside it (its units, the
layout it came from, its boundary panels), the boundary panels ``NET.boundary.obj``, and a
reference surface."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.units import DEFAULT_UNITS, MM_PER_UNIT
from ..net.validate import net_units_warning
from ..solve.reference import load_reference
from .running import warn_after

__all__ = ["boundary_panels_file", "boundary_record", "check_units", "has_faces", "net_properties",
           "net_units", "reference_surface"]


def net_properties(net: str | Path) -> dict:
    """``properties`` of the ``NET.json`` beside a net a layout, optimize or study wrote
    ({} where there is none, or it holds none)."""
    import json

    try:
        properties = json.loads(Path(net).with_suffix(".json").read_text(encoding="utf-8"))["properties"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return properties if isinstance(properties, dict) else {}


def net_units(args: argparse.Namespace, net: str | os.PathLike | None, *,
              default: str = DEFAULT_UNITS) -> str:
    """The model units of a command's net: ``--units``, else those its record NET.json
    states (a layout's or optimize's ``properties.units``, a layout's design units), else
    `default`."""
    if args.units is not None:
        return args.units
    properties = net_properties(Path(net)) if net else {}
    layout = properties.get("layout")
    recorded = properties.get("units") or (layout.get("design_units") if isinstance(layout, dict)
                                           else None)
    return recorded if recorded in MM_PER_UNIT else default


def check_units(args: argparse.Namespace, mesh: Any, units: str) -> None:
    """Warn (or with ``--strict-units`` refuse now) when the net's size does not fit
    `units`; the warning comes after the run (`warn_after`)."""
    warn_after(args, net_units_warning(mesh, units, strict=args.strict_units))


def reference_surface(spec: str | None):
    """A reference surface from a mesh file, a Rhino file or a built-in surface spec
    (`fabplan layout`)."""
    from ..io.rhino_read import is_3dm_source

    if spec is None:
        return None
    from ..design.load import load_design, names_a_file

    if not is_3dm_source(spec) and names_a_file(spec):
        return load_reference(spec)

    return load_design(spec).reference


def boundary_panels_file(args) -> Path | None:
    """The net's boundary panels: ``--boundary FILE``, else ``NET.boundary.obj`` beside the
    net when a layout, optimize or study wrote one; None for none (``--no-boundary``)."""
    from ..solve.optimize import boundary_path

    if args.no_boundary:
        return None
    if args.boundary is None:
        path = boundary_path(args.net)
        # a layout whose net clads its design to the boundary writes one without faces
        return path if path.is_file() and has_faces(path) else None
    path = Path(args.boundary)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the boundary panels, NET.boundary.obj)")
    return path


def has_faces(path: Path) -> bool:
    """Whether an OBJ file holds a face line."""
    try:
        with path.open(encoding="utf-8", errors="replace") as handle:
            return any(line.startswith("f ") for line in handle)
    except OSError:
        return True           # the reader names what is wrong with it


def boundary_record(args) -> dict | None:
    """What NET.json records of the boundary panels beside the net (which are slivers,
    patches, points on the design boundary); None for panels given by ``--boundary``."""
    return None if args.boundary is not None else net_properties(args.net).get("boundary_panels")
