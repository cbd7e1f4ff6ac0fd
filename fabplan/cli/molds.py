"""`fabplan molds NET.obj --tolerance-mm T -o DIR`: the molds a net's curved panels need
(its boundary panels on them too), and a report of them."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.output import check_output_folder, output_argument
from ..io.units import MM_PER_UNIT
from ..net.validate import load_net
from ..report.html import counted
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
from .memory import check_net_memory, check_triangles
from .records import boundary_panels_file, boundary_record, check_units, net_properties, net_units
from .registry import Command, register
from .running import EXIT_NOT_CONVERGED, command_progress

__all__ = ["COMMAND", "add_arguments", "run"]

#: with --panel-surface design, a net whose vertices lie farther than this many of its mean
#: edges from the design is refused: its panels would be cut from a surface they are not on
NET_OFF_DESIGN_EDGES = 2.0


def run(args: argparse.Namespace) -> int:
    from ..fabricate.molds import plan_molds
    from ..fabricate.molds.boundary_molds import boundary_molds
    from ..fabricate.molds.mold_report import MOLD_FILES, write_mold_report
    from ..fabricate.molds.panels import check_panels
    from ..layout.boundary_panels import read_boundary_panels

    settings = _mold_settings(args)
    if args.design is None and args.panel_surface == "design":
        raise InputError("--panel-surface design needs --design SURFACE, the design the net lies on")
    out = output_argument(args.output, folder=True)
    check_output_folder(out)
    inputs = {**net_inputs(args.net), **file_inputs((args.boundary, "the boundary panels"),
                                                    (args.design, "the design"))}
    folder_apart(out, [*MOLD_FILES, "net.3dm", "net.glb", "net.ifc"], inputs)
    mesh = load_net(args.net, quads=False)   # every polygon is a panel
    check_panels(mesh)
    check_net_memory(args, mesh, "molds")
    check_units(args, mesh, settings.units)
    design = _molds_design(args, mesh)
    boundary_file = boundary_panels_file(args)
    panels = None if boundary_file is None else read_boundary_panels(
        mesh, boundary_file, boundary_record(args))
    progress = command_progress(args)
    with progress.stage(f"fitting molds to {len(mesh.face_sizes)} panels"):
        plan = plan_molds(mesh, settings, design=design)
    limits = []
    if design is not None:
        limits = [deviation_check(design.distances(mesh.vertices), units=settings.units,
                                  max_deviation=args.max_deviation_mm / MM_PER_UNIT[settings.units])]
    boundary = None
    if panels is not None:
        # each boundary panel on a mold of the net's panels, placed to meet its
        # neighbours (a mold of its own where none does)
        with progress.stage(f"placing {panels.panel_count} boundary panels on the molds"):
            boundary = (panels, boundary_molds(plan, panels))
    with progress.stage("writing the report"), \
            viewer_files(args, out / "net", mesh, units=settings.units, molds=plan,
                         boundary=None if boundary is None else boundary[1],
                         net_type=net_properties(args.net).get("net")) as viewers:
        files = write_mold_report(plan, out, view_3d=not args.no_3d, boundary=boundary,
                                  protect=inputs, limits=limits) + viewers
    _print_molds(args, plan, settings, boundary, boundary_file, limits, files)
    return _molds_exit(plan, settings, None if boundary is None else boundary[1], boundary_file,
                       limits, out)


def _mold_settings(args: argparse.Namespace) -> Any:
    """`MoldSettings` from the command line, checked."""
    from ..fabricate.molds import MoldSettings
    from ..fabricate.molds.materials import parse_material

    settings = MoldSettings(tolerance_mm=args.tolerance_mm, units=net_units(args, args.net),
                            max_mold_size_mm=args.max_mold_size, panel_surface=args.panel_surface,
                            step_limit_mm=args.step_limit,
                            material=None if args.material is None else parse_material(args.material))
    settings.check()
    return settings


def _molds_design(args: argparse.Namespace, mesh: Any) -> Any:
    """The ``--design`` the net lies on (None without one), refused for ``--panel-surface
    design`` when the net is off it."""
    design = None
    if args.design is not None:
        from ..design.load import load_design

        check_triangles(args.design, args.triangles)
        design = load_design(args.design, triangles=args.triangles)
        if args.panel_surface == "design":
            _check_net_on_design(args, mesh, design)
    return design


def _print_molds(args: argparse.Namespace, plan: Any, settings: Any, boundary: Any,
                 boundary_file: Path | None, limits: list, files: list) -> None:
    """The plan on stdout: a line with -q, else its summary, its boundary panels, its
    limits and the files written."""
    from ..fabricate.molds.boundary_molds import boundary_molds_text

    if args.quiet:
        made = "" if plan.classes is None else f" ({plan.made_mold_count} made for the molded panels)"
        print(f"{counted(plan.panel_count, 'panel')} on {counted(plan.mold_count, 'mold')}{made} "
              f"at {settings.tolerance_mm:g} mm; wrote {files[0]}")
    else:
        print(plan.summary())
        if boundary is not None:
            print(boundary_molds_text(boundary[1], plan, boundary_file))
        for check in limits:
            print(f"limit: {check.text()}")
        print(f"wrote {', '.join(str(f) for f in files)}")


def _molds_exit(plan: Any, settings: Any, molds: Any, boundary_file: Path | None, limits: list,
                out: Path) -> int:
    """Exit 3, with a warning, when boundary panels (`molds`, their `BoundaryMolds`) step
    against their neighbours, panels fit no mold, the molds of neighbours step apart, or a
    limit is exceeded; else 0."""
    import numpy as np

    over = np.zeros(0, np.int64) if molds is None else molds.steps_over_limit
    if molds is not None and over.size:
        one = over.size == 1
        slivers = int(molds.extension[over].sum())
        print(f"fabplan: warning: {counted(over.size, 'boundary panel')} step{'s' if one else ''} "
              f"against a neighbour by up to {molds.step_mm[over].max():.2f} mm (limit "
              f"{molds.step_limit_mm:g} mm; ids in {boundary_file}: {over.tolist()[:10]}"
              + (f", {counted(slivers, 'sliver')} cut with its full panel among them"
                 if slivers else "")
              + "): trim them by hand or give a looser tolerance", file=sys.stderr)
    if plan.failures.size:
        too_large = sum("needs a mold of" in (plan.problem[i] or "") for i in plan.failures)
        why = []
        if too_large:
            why.append(f"{too_large} need a mold larger than --max-mold-size "
                       f"{settings.max_mold_size_mm:g} mm")
        if plan.failures.size - too_large:
            why.append(f"{plan.failures.size - too_large} deviate from every mold by more than "
                       f"{settings.tolerance_mm:g} mm")
        print(f"fabplan: warning: {counted(plan.failures.size, 'panel')} fit no mold "
              f"({'; '.join(why)}); they are listed in {out / 'report.html'}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    if not plan.fits_all:
        print(f"fabplan: warning: the molds of neighbouring panels step up to "
              f"{plan.max_step_mm:.2f} mm apart at {plan.steps_over.size} shared edges "
              f"(limit {plan.step_limit_mm:g} mm); see the step map in {out / 'report.html'}",
              file=sys.stderr)
        return EXIT_NOT_CONVERGED
    if over.size:
        return EXIT_NOT_CONVERGED
    return limits_exit(limits, out / "molds.json")


def _check_net_on_design(args: argparse.Namespace, mesh: Any, design: Any) -> None:
    """Refuse `--panel-surface design` for a net (`QuadMesh`) that does not lie on its
    design (`DesignSurface`)."""
    import numpy as np

    with np.errstate(all="ignore"):
        distance = design.distances(mesh.vertices)
    edge = mesh.mean_edge_length
    far = float(np.max(distance)) if np.all(np.isfinite(distance)) else math.inf
    if far > NET_OFF_DESIGN_EDGES * edge:
        raise InputError(f"{args.net}: --panel-surface design: the net lies up to {far:.4g} "
                         f"from the design {args.design} ({far / edge:.3g} of its mean edges): "
                         "its panels are cut from the design only where they lie on it; give "
                         "the design the net was laid out on, or another --panel-surface")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("net", help="quad mesh (OBJ); every face is a panel")
    add_number(p, "--tolerance-mm", required=True, metavar="T",
               help="largest allowed gap between a panel and its mold, in mm")
    add_units(p)
    add_number(p, "--max-mold-size", metavar="MM",
               help="largest mold side in mm (default: no limit)")
    p.add_argument("--panel-surface", default="auto",
                   choices=["auto", "shared", "local_fit", "corners", "design", "smooth"],
                   help="panel shape: shared (pieces of one surface through the net: "
                        "neighbouring panels share their edges), local_fit (a quadric per "
                        "face, fitted to the corners around it; neighbours may step apart), "
                        "corners (least curved through its corners), design (patches of the "
                        "exact design the net lies on, --design: what a study plans for a "
                        "net on its design), auto (corners for a net of flat faces, else "
                        "design with a --design every vertex lies within the tolerance of, "
                        "else shared); smooth is local_fit's earlier name")
    p.add_argument("--design", metavar="SURFACE",
                   help="the design the net lies on, for --panel-surface design: a built-in "
                        "surface spec or a .3dm NURBS surface as for `fabplan layout`")
    add_number(p, "--triangles", default=20000, metavar="N",
               help="triangles of the --design's triangulation, where the exact surface is "
               "searched from (default 20000, a study's)")
    add_number(p, "--step-limit", metavar="MM",
               help="largest step between neighbouring panels' molds in mm (default twice "
               "the tolerance)")
    p.add_argument("--material", metavar="NAME[:THICKNESS]",
                   help="the panels' sheet: each panel is then flat, cold-bent, roll-bent or "
                        "molded, and only molded panels get molds (glass-annealed, "
                        "glass-heat-strengthened, glass-tempered, glass-laminated[-tempered], "
                        "aluminium, steel; e.g. glass-tempered:8mm, glass-laminated:2x8mm; "
                        "docs/materials.md)")
    add_max_deviation_mm(p)
    add_max_panels(p, memory=True)
    add_boundary_options(p, "each is cut from a mold of the net's panels, placed to meet "
                         "its neighbours (a mold of its own where none does; slivers cut "
                         "with their full panel)", "plan the net's own panels only")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the report")
    add_3dm(p)
    p.add_argument("--no-3d", action="store_true",
                   help="leave the interactive 3D view out of report.html (0.6 MB smaller)")
    add_verbosity(p)


COMMAND = register(Command("molds", "count the molds a net's curved panels need and write a "
                                    "report (report.html, molds.json, panels.csv)",
                           add_arguments, run))
