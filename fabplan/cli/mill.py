"""`fabplan mill NET.obj --tool TOOL -o DIR`: curvature-adaptive milling paths, checked by
simulation: face milling from the Meusnier spheres of an S-net, flank milling with a cone
from the Mannheim spheres of an S*-net."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.output import check_output_folder, output_argument
from ..io.parameters import option_parameter
from ..io.units import MM_PER_UNIT
from ..net.validate import load_net
from ..report.html import counted
from .arguments import add_max_panels, add_number, add_units, add_verbosity
from .files import file_inputs, folder_apart, layout_design_inputs, net_inputs
from .limits import limits_exit
from .memory import check_net_memory, check_simulation_memory
from .records import net_properties, net_units
from .registry import Command, register
from .running import EXIT_NOT_CONVERGED, command_progress, warn, warn_after

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..fabricate.milling import MillSettings, parse_tool
    from ..fabricate.milling.mill_report import MILL_FILES, mill_net, write_mill_report
    from ..fabricate.milling.mill_simulation import SimulationSettings

    tool = parse_tool(args.tool)
    settings = MillSettings(along=args.along, units=net_units(args, args.net, default="mm"),
                            margin_mm=args.margin,
                            scallop_mm=args.scallop, side=args.side, paths_on=args.paths_on)
    settings.check()
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**net_inputs(args.net), **file_inputs((args.design, "the design")),
              **layout_design_inputs(args.net)}
    folder_apart(out, [*MILL_FILES, "paths.3dm"], inputs)
    mesh = load_net(args.net)
    check_net_memory(args, mesh, "mill")
    if not args.no_simulation:
        cells = check_simulation_memory(mesh, settings.mm_per_unit, args.sim_step)
        _note_simulation_time(cells, args.sim_step, tool.kind)
    progress = command_progress(args)
    with progress.stage("reading the design"):
        design = _mill_design(args, settings.units)
    with progress.stage("planning the passes and simulating the cut"):
        result = mill_net(mesh, tool, settings, simulate=not args.no_simulation,
                          simulation=SimulationSettings(step_mm=args.sim_step), design=design)
    with progress.stage("writing the tool paths and the report"):
        files = write_mill_report(result, out, rhino=args.rhino, protect=inputs)
    if args.quiet:
        print(f"{counted(result.plan.path.pass_count, 'pass', 'passes')}; wrote {files[0]}")
    else:
        print(result.summary())
        print(f"wrote {', '.join(str(f) for f in files)}")
        for note in result.plan.notes:
            warn(note)
    gouged = _warn_gouge(result, out)
    code = limits_exit([result.scallop_check], out / "mill.json")
    return EXIT_NOT_CONVERGED if gouged else code


def _note_simulation_time(cells: float, step_mm: float, kind: str) -> None:
    """Say up front when a simulation of `cells` grid cells will take minutes
    (`SIMULATION_MEMORY`'s time per cell, measured with a face mill's two cuts, its own
    and the conventional ball end's; a cone has one)."""
    from ..io.resources import SIMULATION_MEMORY

    minutes = SIMULATION_MEMORY.seconds_per_unit * cells * (1 if kind == "face" else 0.5) / 60
    if minutes >= 2:
        coarsest = option_parameter("mill", "--sim-step").high or step_mm
        coarser = min(2 * step_mm, coarsest)
        faster = (f"--sim-step {coarser:g} takes {(step_mm / coarser) ** 2:.2g} of that, "
                  if coarser > step_mm else "")
        print(f"fabplan: note: the simulation of about {cells:,.0f} cells at --sim-step "
              f"{step_mm:g} will take about {minutes:.0f} minutes; {faster}--no-simulation "
              "none", file=sys.stderr)


def _warn_gouge(result: Any, out: Path) -> bool:
    """Warn when the simulated cut gouges its target, saying why; True when it does."""
    if not result.gouge_free and result.simulation is not None:
        # a margin keeps the tool inside the spheres; a face wider than the surface's
        # curvature allows over its width gouges whatever the margin
        why = "try a smaller tool or a larger --margin"
        if result.plan.margin_tries:
            why = ("try a smaller tool: margins up to "
                   f"{max(m for m, _ in result.plan.margin_tries):.4g} mm were tried in "
                   "simulation, and the least gouging is kept")
        distance = result.net_distance
        faceting = result.design_faceting_mm
        if faceting is not None and result.simulation.max_gouge_mm <= 2 * faceting:
            why = (f"the design is a triangle mesh whose flat faces stand up to about "
                   f"{faceting:.2g} mm off a smooth surface through its vertices, which the "
                   "cut follows: give a finer mesh, or the exact design (a .3dm NURBS surface "
                   "or a built-in spec)")
        elif distance is not None and result.plan.placed_on == "net":
            why = (f"the passes follow the net, which is up to "
                   f"{distance.vertex_max_mm:.4g} mm off the design: place them on "
                   "the design (--paths-on design) or give a larger --margin")
        print(f"fabplan: warning: the simulated cut gouges "
              f"{'the net' if result.design is None else 'the design'} by "
              f"{result.simulation.max_gouge_mm:.4g} mm: {why} "
              f"(details in {out / 'report.html'})", file=sys.stderr)
        return True
    return False


def _mill_design(args: argparse.Namespace, units: str) -> Any:
    """The design `fabplan mill` measures against: ``--design``, else the design the
    net's record (``NET.json``) names (a layout's design, an optimize's reference), else
    None (the net's own surface).

    A design its record names that cannot be loaded again (a file moved) is said in a
    warning, and the net's surface is measured instead. A design whose file states other
    units than the net's is scaled to the net's."""
    from ..design.load import load_design

    design = None
    if args.design is not None:
        design = load_design(args.design, triangles=args.triangles)
    else:
        properties = net_properties(args.net)
        layout = properties.get("layout")
        spec = (layout.get("design_spec") or layout.get("design")) if isinstance(layout, dict) else None
        if not (isinstance(spec, str) and spec):     # an optimize's --reference
            layout, spec = {}, properties.get("reference")
        if isinstance(spec, str) and spec:
            assert isinstance(layout, dict)
            resolution = layout.get("design_resolution")
            try:
                design = load_design(spec, triangles=int(layout.get("design_triangles") or 40000),
                                     resolution=None if resolution is None else tuple(resolution))
            except (InputError, OSError) as exc:
                warn_after(args, f"the design {spec} that {Path(args.net).with_suffix('.json')} "
                           f"names could not be read ({exc}): the cut was measured "
                           "against the net's surface")
                return None
    if design is not None and design.units is not None and design.units != units \
            and design.units in MM_PER_UNIT:
        from ..design.mesh_surface import DesignSurface

        scale = MM_PER_UNIT[design.units] / MM_PER_UNIT[units]
        scaled = DesignSurface(design.vertices * scale, design.triangles, name=design.name)
        scaled.units = units
        return scaled
    return design


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("net", help="the S-net, or for a cone the S*-net with its vn normals (OBJ), "
                               "a regular quad net")
    p.add_argument("--tool", required=True,
                   metavar="face:D=MM[,corner=MM][,length=MM]|cone:angle=DEG,length=MM[,tip=MM]",
                   help="cylindrical face mill of diameter D (toroidal with a corner radius), or "
                        "a conical flank mill: half angle between axis and flank, flank length "
                        "along the axis, tip diameter (default 0)")
    p.add_argument("--along", choices=["A", "B"], default="A",
                   help="family whose lines the passes follow (A: the first, default)")
    add_units(p, default="mm")
    add_number(p, "--margin", metavar="MM",
               help="Meusnier radius minus safety sphere radius (cone: Mannheim radius "
               "minus at least this) (default: the rule of docs/milling.md, which keeps "
               "the cut above the target)")
    add_number(p, "--scallop", default=0.01, metavar="MM",
               help="largest predicted scallop height between passes (default 0.01)")
    p.add_argument("--side", choices=["auto", "+", "-"], default="auto",
                   help="side the tool comes from: that of the Meusnier (cone: Mannheim) "
                        "spheres (auto), of the face normals (cone: the vn normals) (+) or the "
                        "other (-)")
    add_max_panels(p, memory=True)
    add_number(p, "--sim-step", default=0.5, metavar="MM",
               help="grid step of the milling simulation (default 0.5)")
    p.add_argument("--no-simulation", action="store_true",
                   help="plan only: no simulated scallop, gouge check or comparison")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net was made for, which the cut is measured against "
                        "(the net's distance from it reported apart): a triangle mesh, a "
                        "Rhino file or a built-in surface spec as for `fabplan layout` "
                        "(default: the design NET.json names, a layout's design or an "
                        "optimize's --reference; else the net's own surface)")
    add_number(p, "--triangles", default=40000, metavar="N",
               help="triangles of a built-in or NURBS --design's triangulation, where its "
               "exact surface is searched from (default 40000)")
    p.add_argument("--paths-on", choices=["design", "net"], default="design",
                   help="with a design: put the passes' nodes on the design (its closest "
                        "points to the net's vertices, its normals; default), or keep them "
                        "on the net's vertices")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the files")
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write the tool paths as DIR/paths.3dm (a polyline of cutter tips "
                        "and one of contact points per pass, in mm)")
    add_verbosity(p)


COMMAND = register(Command("mill", "curvature-adaptive milling paths, checked by simulation "
                                   "(CL + CSV + mill.json + report.html): face milling from the "
                                   "Meusnier spheres of an S-net, flank milling with a cone from "
                                   "the Mannheim spheres of an S*-net",
                           add_arguments, run))
