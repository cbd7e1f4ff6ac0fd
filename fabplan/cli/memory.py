"""Refusals, before the work, of runs that would need more memory than this run may use
(`fabplan.io.resources`): a net too large for `molds` or `mill`, a milling simulation grid,
a design's triangulation, a layout's panel count."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from ..errors import InputError

__all__ = ["check_layout_size", "check_net_memory", "check_simulation_memory",
           "check_triangles"]


def check_net_memory(args: argparse.Namespace, mesh: Any, command: str) -> None:
    """Refuse a net whose `command` (``molds``, ``mill``) would need more memory than this
    run may use, or more faces than ``--max-panels`` when it is given, before the work
    (`fabplan.io.resources`)."""
    from ..io.resources import MILL_MEMORY, MOLDS_MEMORY, check_memory, check_panel_count

    model = {"molds": MOLDS_MEMORY, "mill": MILL_MEMORY}[command]
    faces = len(mesh.face_sizes)
    fix = f"run {command} on a coarser net or on parts of it"
    if args.max_panels is not None:
        check_panel_count(faces, max_panels=args.max_panels, bytes_per_panel=model.bytes_per_unit,
                          what=f"{args.net}: {model.work} a net of {faces:,} faces", fix=fix)
    else:
        check_memory(model, faces, where=str(args.net),
                     fix=f"{fix}, or give --max-panels to run it anyway")


def check_simulation_memory(mesh: Any, mm_per_unit: float, step_mm: float) -> float:
    """Refuse a milling simulation whose grid at ``--sim-step`` would need more memory than
    is left beside the plan, naming the smallest step that fits (a grid over the cap of
    `height_target` is refused there, before it is made); returns the grid's estimated
    cells (`simulation_cells`)."""
    from ..fabricate.milling.mill_simulation import MAX_SIMULATION_CELLS, simulation_cells
    from ..io.resources import MILL_MEMORY, SIMULATION_MEMORY, check_memory, memory_limit

    cells = simulation_cells(mesh.vertices * mm_per_unit, mesh.triangles(), step_mm)
    if cells > MAX_SIMULATION_CELLS:
        return cells
    plan = MILL_MEMORY.peak_bytes(len(mesh.face_sizes))
    fits = max(SIMULATION_MEMORY.largest_fitting(memory_limit() - plan), 1)
    check_memory(SIMULATION_MEMORY, cells, where=f"--sim-step {step_mm:g}", beside_bytes=plan,
                 fix=f"a --sim-step of {1.01 * step_mm * math.sqrt(cells / fits):.3g} mm or more "
                     "fits, or give --no-simulation")
    return cells


def check_triangles(surface: str, triangles: int) -> None:
    """Refuse a ``--triangles`` whose triangulation of a built-in or NURBS surface would
    need more memory than this run may use (a mesh file keeps its own triangles, checked
    as it is read)."""
    from ..design.load import names_a_file
    from ..io.resources import DESIGN_MEMORY, check_memory
    from ..io.rhino_read import is_3dm_source

    if is_3dm_source(surface) or not names_a_file(surface):
        check_memory(DESIGN_MEMORY, triangles, where=f"--triangles {triangles}",
                     fix="give fewer --triangles")


def check_layout_size(design: Any, panel_size: float, max_panels: int | None) -> None:
    """Refuse a layout whose panel count (design area / panel size squared) would exhaust
    the memory, before the layout starts (see `fabplan.io.resources`)."""
    from ..io.resources import check_panel_count, default_max_panels

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


