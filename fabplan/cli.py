"""The `fabplan` command. Every subcommand is a thin wrapper over the Python API.

Exit codes: 0 success; 2 bad input or a solver that failed (one-line message, nothing
written); 3 the optimization stopped without converging (result written, with its
measured residuals and status), or some panels fit no mold (`molds`: report written, the
failures listed).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from . import __version__
from .errors import FabplanError, InputError
from .io import check_writable, write_json, write_texts
from .measure import format_summary, measure_net
from .mesh import load_mesh
from .nets import NETS, check_angle, check_radius
from .optimize import check_net_input, optimize, read_fixed, read_handles
from .reference import load_reference
from .solver import SolverSettings

__all__ = ["main"]

EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3


def _cmd_nets(args) -> int:
    width = max(len(n) for n in NETS)
    for net in NETS.values():
        print(f"{net.name:<{width}}  {net.summary}")
    return 0


def _cmd_measure(args) -> int:
    out = Path(args.output) if args.output else Path(args.net).with_suffix(".measure.json")
    _check_outputs([out], [args.net, args.reference])
    mesh = load_mesh(args.net)
    reference = load_reference(args.reference) if args.reference else None
    record = measure_net(mesh, reference=reference)
    record["file"] = str(args.net)
    print(format_summary(record))
    write_json(out, record)
    print(f"wrote {out}")
    return 0


def _check_outputs(outputs: list[Path], inputs: list[str | None]) -> None:
    """Refuse outputs that would overwrite an input or cannot be written, before working."""
    protected = {Path(p).resolve() for p in inputs if p}
    for out in outputs:
        if out.resolve() in protected:
            raise InputError(f"{out}: refusing to overwrite the input file")
        check_writable(out)


def _output_path(args) -> Path:
    out = Path(args.output)
    if out.suffix.lower() != ".obj":
        raise InputError(f"{out}: the output must be an .obj file")
    _check_outputs([out, out.with_suffix(".json")], [args.input, args.reference, args.fix])
    return out


def _cmd_optimize(args) -> int:
    check_angle(args.angle)
    check_radius(args.radius)
    if args.max_iter is not None and args.max_iter < 1:
        raise InputError(f"--max-iter must be at least 1, got {args.max_iter}")
    out = _output_path(args)
    mesh = load_mesh(args.input)
    check_net_input(mesh)
    reference = load_reference(args.reference) if args.reference else None
    fixed = read_fixed(args.fix, mesh)
    handles = read_handles(args.handle)
    settings = SolverSettings()
    if args.max_iter is not None:
        settings.max_iterations = args.max_iter
    show = (sys.stderr.isatty() or args.verbose) and not args.quiet

    def progress(rec):
        if show:
            print(f"  iteration {rec.iteration:3d}  residual {rec.hard_residual:.3e}  "
                  f"step {rec.step:.2e}  {rec.seconds * 1000:.0f} ms", file=sys.stderr)

    result = optimize(mesh, args.net, angle=args.angle, radius=args.radius,
                      reference=reference, fixed=fixed, handles=handles, settings=settings,
                      coherent=args.coherent, progress=progress)
    obj_path, json_path = result.write(out)
    print(format_summary(result.properties))
    params = ", ".join(f"{k} {v:.6g}" for k, v in result.parameters.items()
                       if isinstance(v, float))
    print(f"{result.net}: {result.status} after {result.iterations} iterations in "
          f"{result.seconds:.2f} s" + (f" ({params})" if params else ""))
    print(f"wrote {obj_path} and {json_path}")
    if not result.converged:
        print(f"fabplan: warning: the optimization {result.status} before reaching the "
              f"tolerance; see the residuals in {json_path}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def _check_output_folder(folder: Path) -> None:
    """Refuse an output folder that cannot be made or written, without creating it."""
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder")
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK):
        raise InputError(f"{folder}: cannot write there ({existing} is not a writable folder)")


def _cmd_molds(args) -> int:
    from .mold_report import mold_report_files
    from .molds import MoldSettings, plan_molds
    from .panels import check_panels

    settings = MoldSettings(tolerance_mm=args.tolerance_mm, units=args.units,
                            max_mold_size_mm=args.max_mold_size, panel_surface=args.panel_surface)
    settings.check()
    out = Path(args.output)
    _check_output_folder(out)
    mesh = load_mesh(args.net)
    check_panels(mesh)
    plan = plan_molds(mesh, settings)
    files = mold_report_files(plan, out)
    write_texts(files)
    print(plan.summary())
    print(f"wrote {', '.join(str(f) for f in files)}")
    if not plan.fits_all:
        print(f"fabplan: warning: {plan.failures.size} panels do not fit a mold within "
              f"{settings.tolerance_mm:g} mm; they are listed in {out / 'report.html'}",
              file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line and exit code 2, like every other bad input."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"fabplan: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fabplan", description="Fabrication planning with principal symmetric meshes.")
    parser.add_argument("--version", action="version", version=f"fabplan {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("nets", help="list the net types and their defining properties")
    p.set_defaults(func=_cmd_nets)

    p = sub.add_parser("measure", help="measure the S-net properties of a quad mesh")
    p.add_argument("net", help="quad mesh (OBJ)")
    p.add_argument("-o", "--output", help="JSON file to write (default: NET.measure.json)")
    p.add_argument("--reference", help="surface to measure the distance to (OBJ/STL/PLY/OFF)")
    p.set_defaults(func=_cmd_measure)

    p = sub.add_parser("optimize", help="optimize a quad mesh into a net of a given type")
    p.add_argument("input", help="quad mesh (OBJ)")
    p.add_argument("--net", required=True, choices=list(NETS), metavar="NAME",
                   help="net type (see `fabplan nets`)")
    p.add_argument("--angle", type=float, help="intersection angle in degrees (isogonal types)")
    p.add_argument("--radius", type=float, help="Meusnier radius in model units")
    p.add_argument("--reference", help="surface to stay close to (default: the input)")
    p.add_argument("--fix", help="'boundary' or a file of vertex ids to hold in place")
    p.add_argument("--handle", action="append", metavar="ID:X,Y,Z",
                   help="move vertex ID to (X, Y, Z) and hold it there; repeatable, or a file "
                        "of 'ID X Y Z' lines")
    p.add_argument("--coherent", action="store_true",
                   help="keep all Meusnier spheres on one side of the surface")
    p.add_argument("--max-iter", type=int, help="iteration cap (default 50)")
    p.add_argument("-o", "--output", required=True, help="output OBJ; its .json sits beside it")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.add_argument("-v", "--verbose", action="store_true", help="progress lines even off a terminal")
    p.set_defaults(func=_cmd_optimize)

    p = sub.add_parser("molds", help="count the molds a net's curved panels need and write a "
                                     "report (report.html, molds.json, panels.csv)")
    p.add_argument("net", help="quad mesh (OBJ); every face is a panel")
    p.add_argument("--tolerance-mm", type=float, required=True, metavar="T",
                   help="largest allowed gap between a panel and its mold, in mm")
    p.add_argument("--units", default="m", help="unit of the net's coordinates: m (default) or mm")
    p.add_argument("--max-mold-size", type=float, metavar="MM",
                   help="largest mold side in mm (default: no limit)")
    p.add_argument("--panel-surface", default="auto", choices=["auto", "smooth", "corners"],
                   help="panel shape: smooth (follows the surface the net samples), corners "
                        "(least curved through its corners), auto (corners for a net of flat "
                        "faces, else smooth)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the report")
    p.set_defaults(func=_cmd_molds)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except FabplanError as exc:
        print(f"fabplan: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("fabplan: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
