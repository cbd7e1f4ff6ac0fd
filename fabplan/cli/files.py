"""The files a command reads and writes, checked before any work: no output may replace an
input (a net, the files beside it, a design, a reference) or fail to be written; and the
viewer files (``--html``, ``--3dm``, ``--ifc``) that land only with the command's others."""

from __future__ import annotations

import argparse
import os
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Iterator

from ..errors import InputError
from ..io.inputs import check_input_file
from ..io.output import atomic_path, check_apart, check_output_file, output_argument
from ..solve.optimize import boundary_path
from .records import net_properties

__all__ = ["check_option_files", "check_outputs", "file_inputs", "folder_apart", "html_file",
           "layout_design_inputs", "listing", "net_inputs", "obj_output", "viewer_files",
           "viewer_paths"]


def check_outputs(outputs: list[Path], inputs: dict[Path, str]) -> None:
    """Refuse outputs that would overwrite an input or cannot be written, before working."""
    check_apart(outputs, inputs)
    for out in outputs:
        check_output_file(out)


def net_inputs(net: str | os.PathLike | None, what: str = "the input net") -> dict[Path, str]:
    """A net file and the files beside it that fabplan reads back with it (its record
    ``NET.json`` and its boundary panels ``NET.boundary.obj``, where they exist): no
    output may replace them."""
    if not net:
        return {}
    path = Path(net)
    files = {path: what}
    # beside the path given, the file it links to and its other names (hard links)
    names = [path, Path(os.path.realpath(path))]
    try:
        info = os.stat(path)
        if info.st_nlink > 1:
            names += [Path(e.path) for e in os.scandir(path.parent or ".")
                      if e.name.lower().endswith(".obj") and e.inode() == info.st_ino]
    except OSError:
        pass
    for near in dict.fromkeys(names):
        if not near.name:           # '.', '/': a folder, refused where the net is read
            continue
        beside = {near.with_suffix(".json"): f"the record of {near.name}",
                  boundary_path(near): f"the boundary panels of {near.name}"}
        files.update({p: w for p, w in beside.items() if os.path.lexists(p)})
    return files


def file_inputs(*options: tuple[str | None, str]) -> dict[Path, str]:
    """The files named by options that take a file or a design (`--fix`, `--reference`,
    a Rhino file with its choice after ``#``, a built-in surface whose parameters name
    files), with what each is."""
    from ..design.load import design_files

    files = {}
    for value, what in options:
        if value:
            files.update(dict.fromkeys(design_files(value), what))
    return files


def layout_design_inputs(net: str) -> dict[Path, str]:
    """The design file a layout net's record names (``NET.json``), which `optimize`
    reads to cut the net's boundary panels again."""
    from ..design.load import design_files

    layout = net_properties(net).get("layout")
    source = layout.get("design_source") if isinstance(layout, dict) else None
    names = [source.get("file")] if isinstance(source, dict) else []
    if isinstance(layout, dict):
        # what `layout_again` loads the design from: its spec (an absolute path for a file)
        names += [layout.get("design_spec"), layout.get("design")]
    return {path: f"the design of {Path(net).name}" for n in names
            if isinstance(n, str) and n for path in design_files(n) if path.is_file()}


def folder_apart(folder: Path, names: list[str], inputs: dict[Path, str]) -> None:
    """Refuse a run whose output folder holds an input under a name it writes (`names`:
    file names or patterns such as ``strips-sheet-*.dxf``), before the work."""
    import fnmatch

    for path, what in inputs.items():
        inside = os.path.dirname(os.path.realpath(path)) == os.path.realpath(folder)
        if inside and any(fnmatch.fnmatch(path.name, n) for n in names):
            check_apart([folder / path.name], {path: what})


def check_option_files(*options: tuple[str | None, str]) -> None:
    """Name a folder, FIFO or device given to an option that reads a file (`--fix`,
    `--handle`, `--family`) as what it is, instead of "no such file" or a hang."""
    for value, what in options:
        if value and os.path.lexists(value):
            check_input_file(value, what)


def obj_output(text: str) -> Path:
    """The output ``-o`` names, refused unless it is an .obj file."""
    out = output_argument(text)
    if out.suffix.lower() != ".obj":
        raise InputError(f"{out}: the output must be an .obj file")
    return out


def listing(paths: list[Path]) -> str:
    """'a, b and c'"""
    names = [str(p) for p in paths]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def viewer_paths(args: argparse.Namespace, base: Path) -> list[Path]:
    """OUT.3dm and OUT.glb when `--3dm` asks for them, OUT.html when `--html` does, OUT.ifc
    when `--ifc` does (checked before any work)."""
    return ([base.with_suffix(".3dm"), base.with_suffix(".glb")] if args.rhino else []) + (
        [base.with_suffix(".html")] if getattr(args, "html", False) else []) + (
        [base.with_suffix(".ifc")] if getattr(args, "ifc", False) else [])


@contextmanager
def html_file(args: argparse.Namespace, base: Path) -> Iterator[Path | None]:
    """With `--html`: the staged path of ``BASE.html``, moved into place when the block
    (writing the command's other files) succeeds, and gone when it fails."""
    if not args.html:
        yield None
        return
    with atomic_path(base.with_suffix(".html")) as staged:
        yield staged


@contextmanager
def viewer_files(args: argparse.Namespace, base: Path, mesh: Any, *, units: str,
                 molds: Any = None, strips: Any = None, boundary: Any = None,
                 net_type: str | None = None) -> Iterator[list[Path]]:
    """With `--3dm`: the net as Rhino ``BASE.3dm`` (mesh, polylines per family, panels per
    mold, strip curves) and ``BASE.glb`` (coloured by mold) for web viewers; with `--ifc`
    the facade plan as ``BASE.ifc`` (`fabplan.io.ifc`: panels with `boundary` panels,
    molds, lamellas, nodes).

    They are written before the block (the command's other files) runs and land only when
    it succeeds, so that a failure leaves neither them nor the other files behind.
    """
    with ExitStack() as stack:
        written = []
        if args.rhino:
            from ..study.api_products import write_3dm, write_glb

            rhino, glb = base.with_suffix(".3dm"), base.with_suffix(".glb")
            write_3dm(mesh, stack.enter_context(atomic_path(rhino)), molds=molds, strips=strips,
                      units=units)
            write_glb(mesh, stack.enter_context(atomic_path(glb)), molds=molds, units=units)
            written += [rhino, glb]
        if getattr(args, "ifc", False):
            from ..study.api_products import write_ifc

            ifc = base.with_suffix(".ifc")
            write_ifc(mesh, stack.enter_context(atomic_path(ifc)), molds=molds, boundary=boundary,
                      strips=strips, units=units, net_type=net_type, name=Path(base).name)
            written.append(ifc)
        yield written
