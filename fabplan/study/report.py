"""The files of a facade study: ``report.html``, ``study.json``, ``candidates.csv`` and,
per candidate, the net (OBJ + measured JSON), its molds (CSV, JSON) and strips (DXF).

The output folder is built beside its destination and moved into place only when every
file is written: a failed run leaves no partial folder. The schema of ``study.json`` is
``docs/study-schema.md``; every number of the report is in it.

Owns writing the files (`write_study`): a candidate's folder (made here, on Dask workers
or beside the run), the script that reproduces its molds and strips, and the folder a
study may replace (`check_output_folder`). What the files hold is made by
`fabplan.study.records` (``study.json``, ``candidates.csv``), `fabplan.study.pages`
(``report.html``, ``report.pdf``, with `fabplan.study.tables`) and
`fabplan.study.pictures`; the names of theirs in `__all__` are named here too.
"""

from __future__ import annotations

import os
import re
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from ..errors import InputError
from ..io import output
from ..io.forked import ForkedFile, forked_processes, map_in_processes
from ..io.records import json_text
from ..layout.picture import (
    curvature_difference_figure,
    fairness_marks,
    write_layout_picture,
)
from ..report.html import counted
from .cache import CACHE_FOLDER
from .checks import LIMIT_NAMES
from .pages import coverage_gap_triangles, study_html, study_pdf, study_viewer_scenes
from .pictures import (
    PARETO_MIN_CANDIDATES,
    comparison_figure,
    deviation_figure,
    pareto_figure,
    png_uri,
    search_figure,
)
from .records import STUDY_SCHEMA, candidates_csv, study_record
from .result import CandidateResult, StudyResult
from .search import search_record
from .tables import sharpest_turn
from .verdict import every_panel_flat

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from .definition import Study


__all__ = ["write_study", "study_record", "check_output_folder", "STUDY_SCHEMA", "LIMIT_NAMES",
           "coverage_gap_triangles", "study_viewer_scenes", "candidate_file_bytes",
           "candidate_files_task"]


#: what a study writes at the top of its folder (besides ``candidates/``)
STUDY_FILES = ("report.html", "report.pdf", "study.json", "candidates.csv")
#: the names a study writes: only such files can be an earlier study's, whatever a
#: folder's list of files says (a candidate's files, its strip sheets and schedule)
_STUDY_FILE = re.compile(
    r"(report\.html|report\.pdf|study\.json|candidates\.csv|" + re.escape(output.MANIFEST) + "|"
    r"candidates/[^/]+/(net\.(obj|json|png|3dm|glb|ifc)|net\.boundary\.obj|molds\.(csv|json)|"
    r"boundary-panels\.(csv|obj)|reproduce\.sh|"
    r"strips/(strips(-sheet-\d+\.(dxf|png)|-sheets\.dxf|\.csv|\.json)|sheet-preview\.png)))")


def study_files(folder: Path) -> set[str] | None:
    """The files an earlier study wrote in `folder`, which a new study replaces: those
    its manifest lists (`fabplan.io.output.MANIFEST`), else (a study written without one,
    or a list that does not read) those under ``candidates/`` and at the top that a study
    writes; only names a study writes in either case. An empty set for a folder that
    holds only the candidates an interrupted study kept (`fabplan.study.cache`); None for
    a folder that holds no study."""
    folder = Path(folder)
    listed = output.read_manifest(folder)
    if listed is None and (folder / "study.json").is_file():
        candidates = folder / "candidates"
        listed = {name for name in STUDY_FILES if (folder / name).is_file()} | (set() if (
            candidates.is_symlink() or not candidates.is_dir()) else {
            p.relative_to(folder).as_posix() for p in candidates.rglob("*")
            if p.is_file() or p.is_symlink()})
    if listed is not None:
        return {name for name in listed if _STUDY_FILE.fullmatch(name)}
    return set() if (folder / CACHE_FOLDER).is_dir() else None


def check_output_folder(folder: str | os.PathLike, study: Study | None = None) -> None:
    """Refuse a folder that cannot hold a study, without creating anything.

    A study replaces what an earlier study wrote in its folder and leaves every other
    file there as it is. A folder that does not exist yet, an empty one, or one that
    holds an earlier study (`study_files`) is accepted; a file, an unwritable place, a
    folder of other files, or the folder that holds the `study` file itself is refused.
    """
    output.check_output_folder(folder, owned=study_files)
    path = None if study is None else study.path
    if path is not None and Path(os.path.realpath(path)).is_relative_to(os.path.realpath(folder)):
        raise InputError(f"{folder}: holds the study file {path}; a study's files go to a "
                         "folder of their own: choose another -o (a new folder beside it)")


def reproduce_commands(c: CandidateResult, study: Study) -> list[list[str]]:
    """The commands that give a candidate's molds (and strips) from the files in its
    folder, as the study planned them: `fabplan molds` on ``net.obj`` (with its boundary
    panels, ``net.boundary.obj``) at the candidate's mold tolerance and step limit, on the
    design's patches for a net that glides on it (checked against the study's deviation
    limit); `fabplan strips` with the study's strip options. Run in the candidate's
    folder."""
    units = study.design.units
    limits = study.limits_of(c.candidate)
    molds = ["fabplan", "molds", "net.obj", "--tolerance-mm", f"{limits.mold_tolerance_mm!r}",
             "--step-limit", f"{limits.panel_step_limit_mm!r}", "--units", units]
    if c.molds is not None and c.molds.panel_surface == "design":
        molds += ["--panel-surface", "design", "--design", study.design.source,
                  "--max-deviation-mm", f"{limits.max_deviation_mm!r}"]
        if study.design.triangles is not None:
            molds += ["--triangles", str(study.design.triangles)]
    if study.material is not None:
        molds += ["--material", study.material.spec]
    molds += ["-o", "reproduced/molds"]
    commands = [molds]
    options = study.strips
    if c.strips is not None and options is not None:
        commands.append(["fabplan", "strips", "net.obj", "--height", f"{options.height_mm!r}",
                         "--thickness", f"{options.thickness_mm!r}", "--units", units,
                         "--sheet", f"{options.sheet_mm[0]!r}x{options.sheet_mm[1]!r}",
                         "--tolerance", f"{options.congruence_tolerance_mm!r}",
                         "--max-twist", f"{limits.max_twist_deg_per_m!r}", "-o",
                         "reproduced/strips"])
    return commands


def reproduce_script(c: CandidateResult, study: Study) -> str:
    """``reproduce.sh``: `reproduce_commands` as a shell script that runs in its folder."""
    import shlex

    lines = ["#!/bin/sh",
             f"# {c.name}: the commands that give this candidate's net molds and strips from",
             "# net.obj, as the study planned them, in reproduced/molds and reproduced/strips.",
             "# A command that exits with 3 wrote its files and found a fabrication limit not",
             "# met, as the study did: the script goes on, and exits with 3. Any other failure",
             "# stops it.",
             'cd "$(dirname "$0")" || exit 2', "status=0"]
    # `set -e` would stop at the molds of an infeasible candidate, before its strips
    carry_on = ' || { code=$?; [ "$code" -eq 3 ] || exit "$code"; status=3; }'
    commands = [shlex.join(cmd) + carry_on for cmd in reproduce_commands(c, study)]
    return "\n".join([*lines, *commands, 'exit "$status"']) + "\n"


def _candidate_files(c: CandidateResult, folder: Path, study: Study, design: DesignSurface,
                     say, twin_strips: dict[str, bytes] | None = None,
                     rhino: bool = False, ifc: bool = False) -> tuple:
    """Write one candidate's files into `folder`; `twin_strips` are the strip files
    (``strips/NAME``: bytes) of the earlier candidate whose net and strip plan this one
    shares, if any: they are copied rather than made and read back a second time.

    Returns
    -------
    outputs : what each file is -> its path (or paths) inside the study folder.
    pictures : the candidate's pictures as data URIs, by name.
    """
    if c.net is None or c.molds is None:
        raise ValueError(f"candidate {c.name!r} has no net to write (it failed)")
    folder.mkdir(parents=True)
    outputs = _net_and_mold_files(c, folder, study)
    pictures = _candidate_pictures(c, folder, study, design)
    if c.strips is not None:
        pictures["sheet"] = _strip_files(c, folder, twin_strips, outputs)
    _model_files(c, folder, study, outputs, rhino=rhino, ifc=ifc)
    say(f"    wrote {c.name}")
    return {k: (f"candidates/{c.name}/{v}" if isinstance(v, str) else
                [f"candidates/{c.name}/{x}" for x in v]) for k, v in outputs.items()}, pictures


def _net_and_mold_files(c: CandidateResult, folder: Path, study: Study
                        ) -> dict[str, str | list[str]]:
    """The net (OBJ and its measured JSON), its molds (CSV, JSON), the script that
    reproduces them and the boundary panels' files; what each is -> its name."""
    from ..fabricate.molds.boundary_molds import boundary_panels_csv

    net, molds_plan = c.net, c.molds
    assert net is not None and molds_plan is not None
    net.write(folder / "net.obj")
    record = molds_plan.record()
    if c.boundary_molds is not None:
        # the same count as the report's: the net's molds and the boundary panels' own
        record["boundary_panels"] = c.boundary_molds.record(net_molds=molds_plan.made_mold_count)
    output.write_texts({folder / "molds.csv": molds_plan.panels_csv(),
                        folder / "molds.json": json_text(record),
                        folder / "reproduce.sh": reproduce_script(c, study)})
    outputs: dict[str, str | list[str]] = {
        "net": "net.obj", "measured": "net.json", "molds_csv": "molds.csv",
        "molds_json": "molds.json", "picture": "net.png", "reproduce": "reproduce.sh"}
    if net.boundary_panels is not None and c.boundary_molds is not None:
        output.write_texts({
            folder / "boundary-panels.csv": boundary_panels_csv(net.boundary_panels,
                                                                c.boundary_molds),
            folder / "boundary-panels.obj": c.boundary_molds.cut_obj_text(
                "fabplan boundary panels as cut from their molds (placements in "
                "boundary-panels.csv), one face per panel of net.boundary.obj")})
        outputs["boundary_panels"] = "net.boundary.obj"
        outputs["boundary_panels_csv"] = "boundary-panels.csv"
        outputs["boundary_panels_cut"] = "boundary-panels.obj"
    return outputs


def _candidate_pictures(c: CandidateResult, folder: Path, study: Study,
                        design: DesignSurface) -> dict[str, str]:
    """The net on the design (written as ``net.png``), its deviation heat map and its
    panels coloured by mold, as data URIs."""
    from ..fabricate.molds.mold_report import mold_figure

    net, molds_plan = c.net, c.molds
    assert net is not None and molds_plan is not None
    title = f"{c.name}: {c.candidate.describe()}"
    write_layout_picture(folder / "net.png", design, net.mesh, title=title,
                         singular_points=c.singular_points,
                         marks=fairness_marks(net.properties),
                         boundary_panels=net.boundary_panels)
    pictures = {"net": png_uri(folder / "net.png"),
                "deviation": deviation_figure(c, design, study.limits.max_deviation_mm,
                                              study.design.mm_per_unit)}
    molds = c.metrics["molds"]
    own = molds["count"] - molds_plan.mold_count         # the boundary panels' own molds
    pictures["molds"] = mold_figure(molds_plan, title=f"{c.name}: {counted(molds_plan.panel_count, 'panel')}"
                                    + (f", {'all flat' if every_panel_flat(molds) else 'none molded'}: "
                                       "no molds" if molds["count"] == 0 else
                                       f", {counted(molds_plan.mold_count, 'mold')} for the "
                                       "curved ones (one colour per mold)"
                                       + (f"; {molds['count']} in all with the {own} the boundary "
                                          "panels need of their own" if own > 0 else "")))
    return pictures


def _strip_files(c: CandidateResult, folder: Path, twin_strips: dict[str, bytes] | None,
                 outputs: dict[str, str | list[str]]) -> str:
    """The strips' sheets, schedule and a preview of the first sheet (copied from the
    twin's files when given), added to `outputs`; the preview as a data URI."""
    from ..fabricate.strips.dxf import preview_png, sheet_document

    strips = c.strips
    assert strips is not None
    if twin_strips:
        (folder / "strips").mkdir()
        for name, data in twin_strips.items():
            output.path_inside(folder, *name.split("/")).write_bytes(data)
        files = sorted((folder / "strips").iterdir())
    else:
        files = strips.write(folder / "strips", previews=False)
    layout, settings = strips.nesting, strips.strips.settings
    sheet = layout.sheets[0]
    preview = folder / "strips" / "sheet-preview.png"
    preview_png(sheet_document(layout, [sheet], settings), preview, settings.sheet_mm,
                title=f"{c.name}: sheet 1 of {len(layout.sheets)}")
    outputs["strips_dxf"] = sorted(f"strips/{f.name}" for f in files if f.suffix == ".dxf")
    outputs["strips_schedule"] = "strips/strips.csv"
    outputs["strips_preview"] = "strips/sheet-preview.png"
    return png_uri(preview)


def _model_files(c: CandidateResult, folder: Path, study: Study,
                 outputs: dict[str, str | list[str]], *, rhino: bool, ifc: bool) -> None:
    """With `rhino` ``net.3dm`` and ``net.glb``, with `ifc` ``net.ifc``, added to `outputs`."""
    net, molds_plan = c.net, c.molds
    assert net is not None and molds_plan is not None
    if rhino:
        from .api_products import write_3dm, write_glb

        write_3dm(net, folder / "net.3dm", molds=molds_plan, strips=c.strips, units=study.design.units,
                  user_text={"candidate": c.name, "net_type": net.net, "status": net.status})
        write_glb(net, folder / "net.glb", molds=molds_plan, units=study.design.units)
        outputs["rhino"] = "net.3dm"
        outputs["gltf"] = "net.glb"
    if ifc:
        from .api_products import write_ifc

        write_ifc(net, folder / "net.ifc", molds=molds_plan, boundary=c.boundary_molds,
                  strips=c.strips, units=study.design.units, net_type=net.net, name=c.name)
        outputs["ifc"] = "net.ifc"


def candidate_file_bytes(c: CandidateResult, study: Study, design: DesignSurface,
                         twin_files: dict[str, bytes] | None = None, rhino: bool = False,
                         ifc: bool = False
                         ) -> tuple[dict[str, bytes], dict, dict]:
    """One candidate's files made in a folder of its own and returned as bytes, so that
    a Dask worker, on this machine or another, can make them (see `write_study`).

    Parameters
    ----------
    twin_files : the files of the candidate whose strips this one shares (its
        ``strips/`` are copied).

    Returns
    -------
    files : path inside the candidate's folder -> bytes.
    outputs, pictures : as the serial writer gives them.
    """
    import tempfile

    strips = None if twin_files is None else {
        k: v for k, v in twin_files.items() if k.startswith("strips/")}
    with tempfile.TemporaryDirectory(prefix="fabplan-candidate-") as tmp:
        folder = Path(tmp) / "candidate"
        outputs, pictures = _candidate_files(c, folder, study, design, lambda message: None,
                                             twin_strips=strips, rhino=rhino, ifc=ifc)
        files = {p.relative_to(folder).as_posix(): p.read_bytes()
                 for p in sorted(folder.rglob("*")) if p.is_file()}
    return files, outputs, pictures


def candidate_files_task(c: CandidateResult, study: Study, design: DesignSurface,
                         twin_made: tuple | None, rhino: bool = False,
                         ifc: bool = False) -> tuple | None:
    """`candidate_file_bytes` as a Dask task: `twin_made` is what the task of the
    candidate's twin (`CandidateResult.twin`) made, whose strip files this one takes when
    both have strips (the same strip plan, see `fabricate_candidate`); None for a failed
    candidate."""
    if c.failed:
        return None
    twin_files = twin_made[0] if twin_made is not None and c.strips is not None else None
    return candidate_file_bytes(c, study, design, twin_files, rhino=rhino, ifc=ifc)


def _strip_twin(c: CandidateResult, by_name: dict[str, CandidateResult]) -> str | None:
    """The candidate whose strip files `c` takes (the same net and strip plan), or None."""
    twin = None if c.twin is None else by_name.get(c.twin)
    shared = twin is not None and twin.strips is not None and c.strips is not None
    return twin.name if shared and twin is not None else None


def _write_files(folder: Path, files: dict[str, bytes]) -> None:
    for relative, data in files.items():
        path = output.path_inside(folder, *relative.split("/"))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def _write_candidates(result: StudyResult, tmp: Path, say, rhino: bool, client,
                      ifc: bool = False) -> tuple:
    """Every measured candidate's folder in `tmp`: from the files made already beside the
    run (`StudyResult.made_files`: a parallel run's workers, a serial run's forked
    processes), else made on the workers of `client` (each in memory, see
    `candidate_file_bytes`; this process writes them), else here. Returns the outputs and
    pictures by candidate name."""
    outputs, pictures = {}, {}
    by_name = {c.name: c for c in result.candidates}
    done = [c for c in result.candidates if not c.failed]
    if all(c.name in result.made_files for c in done):
        for c in done:
            files, outputs[c.name], pictures[c.name] = result.made_files[c.name]
            _write_files(output.path_inside(tmp, "candidates", c.name), files)
            say(f"    wrote {c.name}")
        return outputs, pictures
    if client is None:
        for c in done:
            if c.name in result.made_files:   # made beside a serial run
                files, outputs[c.name], pictures[c.name] = result.made_files[c.name]
                _write_files(output.path_inside(tmp, "candidates", c.name), files)
                say(f"    wrote {c.name}")
                continue
            # names are checked when the study is read; this guards the API too
            folder = output.path_inside(tmp, "candidates", c.name)
            twin = _strip_twin(c, by_name)
            strips = None if twin is None else {
                p.relative_to(folder.parent / twin).as_posix(): p.read_bytes()
                for p in sorted((folder.parent / twin / "strips").rglob("*")) if p.is_file()}
            outputs[c.name], pictures[c.name] = _candidate_files(
                c, folder, result.study, result.design, say, twin_strips=strips, rhino=rhino,
                ifc=ifc)
        return outputs, pictures
    from distributed import as_completed

    from .inputs import shared_inputs

    study, design = shared_inputs(client, result.study, result.design)
    futures: dict[str, Any] = {}
    for c in done:                         # in the study's order: a twin comes after its own
        twin = _strip_twin(c, by_name)
        futures[c.name] = client.submit(
            candidate_files_task, c, study, design, None if twin is None else futures[twin],
            rhino, ifc, key=f"files-{c.name}", pure=False)
    names = {f.key: name for name, f in futures.items()}
    for future in as_completed(list(futures.values())):
        name = names[future.key]
        files, outputs[name], pictures[name] = future.result()
        _write_files(output.path_inside(tmp, "candidates", name), files)
        say(f"    wrote {name}")
    return outputs, pictures


def _study_pictures(result: StudyResult, *, fork: bool = False) -> dict[str, str]:
    """The study's own pictures, data URIs by name: the candidates compared, their Pareto
    front, every search, the design's curvature where lines turn most. With `fork` they
    are drawn in forked processes, one per core (`fabplan.io.forked.map_in_processes`):
    each is its own figure."""
    drawers: dict[str, Callable[[], str]] = {}
    if any(not c.failed for c in result.candidates):
        drawers["comparison"] = lambda: comparison_figure(result)
    if sum(not c.failed for c in result.candidates) >= PARETO_MIN_CANDIDATES:
        drawers["pareto"] = lambda: pareto_figure(result)
    for k, s in enumerate(result.study.searches):
        drawers[f"search-{k}"] = partial(search_figure, result,
                                         search_record(s, result.candidates))
    c = sharpest_turn(result)
    if c is not None and c.net is not None:
        turn = c.net.properties["fairness"]["line_turn_deg"]
        drawers["curvature"] = lambda: curvature_difference_figure(
            result.design, result.study.panel_size_of(c.candidate),
            marks={f"{c.name}: lines turn most ({turn['max']:.0f} deg)": turn["point"]},
            singular_points=c.singular_points,
            title="The design's curvature: where its principal directions are weak")
    processes = forked_processes() if fork else 0
    if processes > 1 and len(drawers) > 1:
        return dict(zip(drawers, map_in_processes(_drawn, list(drawers.values()), processes),
                        strict=True))
    return {name: draw() for name, draw in drawers.items()}


def _drawn(draw: Callable[[], str]) -> str:
    return draw()


def write_study(result: StudyResult, out_dir, *, progress=None, rhino: bool = False, ifc: bool = False,
                view_3d: bool = True, pdf: bool = True, client: Any = None,
                fork: bool = False) -> list[Path]:
    """Write every file of a study into `out_dir`, replacing the folder as a whole.

    `progress` is called with a line per written candidate; `view_3d` puts the
    interactive 3D view into ``report.html``; `pdf` writes ``report.pdf`` beside it (with
    `fork`, in a forked process meanwhile, `fabplan.io.forked.ForkedFile`: the
    command does; a notebook or a Dask client's process had better not fork). With
    `rhino`, every candidate's folder also gets ``net.3dm`` (the net, its polylines, its
    panels by mold and its strip curves) and ``net.glb``; with `ifc` ``net.ifc`` (its facade
    plan for the building model, `fabplan.io.ifc`).

    With a Dask `client` (``distributed.Client``), the candidates' files are made on its
    workers, in parallel (`candidate_file_bytes`), and written here; a parallel run that
    made them already (`run_study_parallel` with ``files=True``) only has them written.

    `out_dir` may be new, empty, or hold an earlier study (see `check_output_folder`).
    The time recorded as ``seconds_total`` (and shown in the report) is the run time
    plus writing every file up to the last three (``study.json``, ``candidates.csv``,
    ``report.html``), which must hold it.

    Returns
    -------
    list of Path: ``report.html``, ``study.json``, ``candidates.csv`` (the candidate
    folders are listed in ``study.json``; ``report.pdf`` sits beside them).
    """
    say = progress or (lambda message: None)
    clock = time.perf_counter()
    out_dir = Path(out_dir)
    check_output_folder(out_dir, result.study)
    with output.output_folder(out_dir, replace=True, owned=study_files,
                              protect=result.study.input_files()) as tmp:
        outputs, pictures = _write_candidates(result, tmp, say, rhino, client, ifc)
        pictures.update(_study_pictures(result, fork=fork))
        total = result.seconds_run + time.perf_counter() - clock
        record = study_record(result, outputs, seconds_total=total)
        def print_pdf(path: Path) -> None:
            study_pdf(result, pictures, seconds_total=total).write(path)

        printed = None
        if pdf and fork:     # the PDF is drawn on the other core while this one writes the rest
            printed = ForkedFile(print_pdf, tmp / "report.pdf")
        elif pdf:
            print_pdf(tmp / "report.pdf")
        try:
            output.write_texts({tmp / "study.json": json_text(record),
                                tmp / "candidates.csv": candidates_csv(result),
                                tmp / "report.html": study_html(result, pictures, outputs,
                                                                seconds_total=total,
                                                                view_3d=view_3d)})
        except BaseException:
            if printed is not None:
                printed.cancel()
            raise
        if printed is not None:
            printed.finish()
    return [out_dir / "report.html", out_dir / "study.json", out_dir / "candidates.csv"]
