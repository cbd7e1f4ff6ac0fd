"""The whole strip job: strips, parts on sheets, and their files (DXF sheets, schedule).

Data flow: `fabplan.fabricate.strips` builds the lamellas of a net, `.nesting` cuts them
into parts and nests the parts on sheets, `.dxf` draws and checks one sheet; this module
runs the three and writes every file of a plan as one output transaction.
"""

from __future__ import annotations

import csv
import fnmatch
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from ...io.forked import map_in_processes
from ...io.output import check_apart, output_folder
from ...io.records import json_text
from ...net.mesh import QuadMesh
from ..limits import LimitCheck, limit_check, limits_record
from .nesting import Nesting, Part, Placement, congruence, make_parts, nest_parts, part_congruence_mm
from .strip_boundary import StripBoundary
from .strip_set import Strip, StripSet, StripSettings, build_strips

if TYPE_CHECKING:
    from .dxf import SheetGeometry

__all__ = ["StripPlan", "plan_strips", "strip_limit_checks", "congruence_without_boundary_mm",
           "schedule_rows", "write_plan",
           "SHEETS_PER_PROCESS", "STRIP_FILES"]

SHEETS_PER_PROCESS = 8
"""Fewest sheets per process when sheets are written in several processes."""


@dataclass
class StripPlan:
    """Strips, parts and sheets of one run, ready to write.

    Attributes
    ----------
    strips : the StripSet.
    parts : list of `fabplan.fabricate.strips.nesting.Part`.
    nesting : the `Nesting` of the parts on sheets.
    seconds : wall time of the planning.
    limits : the fabrication limits the strips were measured against
        (`strip_limit_checks`), in the summary as ``limits``.
    """

    strips: StripSet
    parts: list[Part]
    nesting: Nesting
    seconds: float = 0.0
    limits: list[LimitCheck] = field(default_factory=list)
    _measured: dict | None = field(default=None, init=False, repr=False, compare=False)

    def summary(self) -> dict:
        """Everything measured, for the JSON schedule and the facade study (measured once:
        a plan is not changed after it is made; a copy each call)."""
        if self._measured is None:
            rec = self.strips.summary()
            rec.update(congruence(self.parts, self.strips))
            rec.update(self.nesting.summary())
            rec["limits"] = limits_record(self.limits)
            self._measured = rec
        return {**self._measured, "seconds": self.seconds}

    def write(self, out_dir: str | os.PathLike, *, name: str = "strips",
              previews: bool = True, workers: int | None = 1,
              protect: Mapping[Path, str] | None = None) -> list[Path]:
        """Write DXF sheets, the schedule (CSV, JSON) and preview PNGs into `out_dir`.

        Everything is built in a temporary folder beside `out_dir`, every DXF is audited
        and checked before it is written there, and only then are the files moved into
        place: a failed run leaves no partial output. Files of an earlier run listed in
        ``NAME.json`` are replaced. `workers` processes write the sheets (None: one per
        CPU). No file replaces one of `protect` (the run's inputs, path -> what it is).
        Returns the written paths.
        """
        return write_plan(self, out_dir, name=name, previews=previews, workers=workers,
                          protect=protect)


def strip_limit_checks(strips: StripSet, parts: list[Part], *,
                       constant_radius: bool = False) -> list[LimitCheck]:
    """The strips measured against their fabrication limits (`fabplan.fabricate.limits`).

    Parameters
    ----------
    strips : the StripSet; its settings give the bounds (`StripSettings.max_twist_deg_per_m`,
        and `StripSettings.tolerance_mm` for congruence).
    parts : the parts the strips are cut into (`make_parts`).
    constant_radius : the net claims a constant (or infinite) Meusnier radius, so its
        strips claim to be pieces of one arc: each part is held to the common arc within
        the cutting tolerance (as a study's ``congruent_strips`` limit holds them).

    Returns
    -------
    list of LimitCheck: ``max_twist_deg_per_m`` over the strips, and with
    `constant_radius` ``congruence_tolerance_mm`` over the parts.
    """
    settings = strips.settings
    twist = np.array([s.twist_deg_per_m for s in strips.strips], dtype=np.float64)
    checks = [limit_check("max_twist_deg_per_m", twist, settings.max_twist_deg_per_m,
                          parts="strips")]
    if constant_radius:
        _, deviation = part_congruence_mm(parts, strips)
        checks.append(limit_check("congruence_tolerance_mm", deviation, settings.tolerance_mm,
                                  parts="strip parts"))
    return checks


def congruence_without_boundary_mm(mesh: QuadMesh, settings: StripSettings) -> float:
    """How far the parts of a net's own strips, without its boundary panels, differ from
    their common arc at most (mm, `part_congruence_mm`): whether the boundary panels are
    what takes a constant radius net's strips off one arc."""
    strips = build_strips(mesh, settings, None)
    _, deviation = part_congruence_mm(make_parts(strips, settings), strips)
    return float(deviation.max(initial=0.0))


def plan_strips(mesh: QuadMesh, settings: StripSettings, *, boundary: Any = None,
                constant_radius: bool = False) -> StripPlan:
    """Build the strips of a net, split them into parts that fit the sheets and nest them.

    Parameters
    ----------
    mesh : the net.
    settings : strip, sheet and file options.
    boundary : the net's boundary panels (`fabplan.layout.trim.BoundaryPanels`, or a
        `fabplan.fabricate.strips.strip_boundary.StripBoundary`): the strips run through them to
        the edge of the cladding and end at a boundary member there. None: they end at
        the net's last vertices.
    constant_radius : the net claims a constant (or infinite) Meusnier radius: its strip
        parts are held to one common arc (`strip_limit_checks`).

    Returns
    -------
    StripPlan; call ``.write(out_dir)`` for the files and ``.summary()`` for the numbers.

    Raises
    ------
    InputError
        Bad settings, a net without polylines, a sheet too small for a part, crossings too
        close for their slits or splices.
    """
    t0 = time.perf_counter()
    if boundary is not None and not isinstance(boundary, StripBoundary):
        boundary = StripBoundary.from_panels(mesh, boundary)
    strips = build_strips(mesh, settings, boundary)
    parts = make_parts(strips, settings)
    nesting = nest_parts(parts, settings)
    return StripPlan(strips=strips, parts=parts, nesting=nesting,
                     seconds=time.perf_counter() - t0,
                     limits=strip_limit_checks(strips, parts, constant_radius=constant_radius))


def schedule_rows(plan: StripPlan) -> list:
    """One dict per strip: id, family, lengths, radius, crossings, parts and sheets."""
    sheets_of_part = {}
    for sheet in plan.nesting.sheets:
        for p in sheet.placements:
            sheets_of_part[p.part] = sheet.index
    parts_of_strip: dict = {}
    for i, part in enumerate(plan.parts):
        parts_of_strip.setdefault(part.strip, []).append(i)
    rows = []
    for k, strip in enumerate(plan.strips.strips):
        crossings = sorted(c.id for c, _ in plan.strips.crossings_of_strip[k])
        parts = parts_of_strip.get(k, [])
        rows.append({
            "strip": strip.id,
            "family": strip.family,
            "length_mm": round(strip.length_mm, 2),
            "cut_length_mm": round(strip.cut_length_mm, 2),
            "radius_mm": round(strip.radius_mm, 2) if math.isfinite(strip.radius_mm) else "inf",
            "crossings": len(crossings),
            "crossing_ids": " ".join(str(c) for c in crossings),
            "parts": len(parts),
            "sheets": " ".join(str(s) for s in sorted({sheets_of_part[i] for i in parts})),
            "twist_deg_per_m": round(strip.twist_deg_per_m, 3),
            "off_orthogonal_deg": round(strip.off_orthogonal_deg, 3),
            "boundary_lean_deg": round(strip.lean_deg, 3),
            "start": _end_text(strip, 0),
            "end": _end_text(strip, 1),
        })
    return rows


def _end_text(strip: Strip, side: int) -> str:
    """How a strip end is cut: ``free`` (beyond its last node, with why in brackets where
    boundary panels were given: ``inside`` the net at an irregular vertex, ``along edge``,
    ``not continued``), or ``member A deg -D mm`` (square against the boundary member,
    meeting it at A degrees, D mm short of its end node; ``+D mm`` where it runs on past the
    node to an edge a hair beyond); ``closed`` for a loop."""
    if strip.closed:
        return "closed"
    setback = strip.end_setback_mm[side]
    if setback is None:
        kind = strip.end_kind[side]
        return "free" if kind == "free" else f"free ({kind})"
    return f"member {strip.end_angle_deg[side]:.1f} deg {-setback:+.1f} mm"


def _schedule_csv(rows: list, header: str) -> str:
    buf = io.StringIO()
    buf.write(header)
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def _plan_record(plan: StripPlan, files: list, sheet_files: dict, summary: dict) -> dict:
    s = plan.strips.settings
    sheet_of_part: dict[int, tuple[int, Placement]] = {}
    for sheet in plan.nesting.sheets:
        for p in sheet.placements:
            sheet_of_part[p.part] = (sheet.index, p)
    parts = []
    for i, part in enumerate(plan.parts):
        sheet_index, placement = sheet_of_part[i]
        parts.append({
            "id": part.id, "strip": plan.strips.strips[part.strip].id, "index": part.index,
            "count": part.count, "s_start_mm": part.s_range[0], "s_end_mm": part.s_range[1],
            "sheet": sheet_index, "file": sheet_files[sheet_index], "angle_deg": placement.angle_deg,
            "offset_mm": list(placement.offset),
            "slits": [{"crossing": c, "s_mm": sv, "from": side}
                      for c, sv, side in part.slit_crossings],
            "splices": [{"id": sid, "s_start_mm": z0, "s_end_mm": z1}
                        for sid, z0, z1 in part.splices],
            "area_mm2": part.area_mm2,
        })
    strips = plan.strips.strips
    return {
        "units": "millimetres; arc lengths s along each strip's reference curve (its mid-line, "
                 "at the surface), from its first node",
        "model_units": s.units,
        "vertices": "strip and crossing vertex ids number the net's vertices and, beyond them, "
                    "the corners of its boundary panels (NET.boundary.obj, net's vertices first)",
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(s).items()},
        "summary": summary,
        "files": files,
        "strips": [dict(row, vertices=[int(v) for v in strip.vertices],
                        boundary_nodes=list(strip.boundary_nodes),
                        end_setback_mm=list(strip.end_setback_mm),
                        end_angle_deg=[None if math.isnan(a) else a for a in strip.end_angle_deg],
                        runs=[{"start": r.start, "stop": r.stop, "radius_mm": r.radius_mm,
                               "deviation_mm": r.deviation_mm, "fitted": r.fitted}
                              for r in strip.runs])
                   for row, strip in zip(schedule_rows(plan), strips, strict=True)],
        "crossings": [{"id": c.id, "vertex": c.vertex,
                       "strips": [strips[c.strips[0]].id, strips[c.strips[1]].id],
                       "s_mm": list(c.s_mm), "angle_deg": c.angle_deg} for c in plan.strips.crossings],
        "junctions": [int(v) for v in plan.strips.junctions],
        "parts": parts,
    }


def write_plan(plan: StripPlan, out_dir: str | os.PathLike, *, name: str = "strips",
               previews: bool = True, workers: int | None = 1,
               protect: Mapping[Path, str] | None = None) -> list[Path]:
    """Write the DXF sheets, schedule (CSV and JSON) and preview PNGs of a plan.

    Every sheet's entities are checked before they are written, the bytes on disk are
    compared with those written (`fabplan.fabricate.strips.dxf.write_sheet_file`), and the first
    sheet file is read back with ezdxf, audited and checked again.
    All files are built in a staging folder first, then moved into `out_dir`
    (`fabplan.io.output.output_folder`); on any failure nothing is left behind. Files of an
    earlier run with the same `name` (listed in its JSON) are removed.

    Parameters
    ----------
    plan : the strip plan.
    out_dir : the output folder.
    name : the stem of every file.
    previews : also draw one PNG per sheet.
    workers : processes that write the sheets; None for one per CPU. One writes them in
        this process, as do several for fewer than `SHEETS_PER_PROCESS` sheets each.
    protect : the run's inputs (path -> what it is): no file written or removed is one.

    Returns
    -------
    list of Path, the files written.
    """
    # ezdxf is imported when sheets are written, not with the strips' plan
    from .dxf import check_sheet, sheet_geometry, write_sheet_file

    out_dir = Path(out_dir)
    settings = plan.strips.settings
    layout = plan.nesting
    W, H = settings.sheet_mm
    with output_folder(out_dir, protect=protect) as tmp:
        files: list[str] = []
        sheet_files: dict = {}
        digits = max(3, len(str(len(layout.sheets))))
        jobs = []
        for sheet in layout.sheets:
            if settings.one_file and not previews:
                continue
            stem = f"{name}-sheet-{sheet.index:0{digits}d}"
            dxf = None if settings.one_file else f"{stem}.dxf"
            png = f"{stem}.png" if previews else None
            title = (f"sheet {sheet.index} of {len(layout.sheets)}: "
                     f"{', '.join(layout.parts[p.part].id for p in sheet.placements)}")
            jobs.append(_SheetJob(sheet_geometry(layout, [sheet], settings), dxf, png, title))
            if dxf is not None:
                files.append(dxf)
                sheet_files[sheet.index] = dxf
            if png is not None:
                files.append(png)
        _run_sheet_jobs(jobs, settings, tmp, workers)
        if settings.one_file:
            write_sheet_file(sheet_geometry(layout, layout.sheets, settings), settings,
                             tmp / f"{name}-sheets.dxf")
            files.insert(0, f"{name}-sheets.dxf")
            sheet_files = {s.index: f"{name}-sheets.dxf" for s in layout.sheets}
        # the files are written as text (`sheet_dxf_text`): one of them is read back with
        # ezdxf and audited, so that a file no CAD program would open never leaves here
        if sheet_files:
            first = min(sheet_files)
            check_sheet(tmp / sheet_files[first], settings,
                        len(layout.sheets) if settings.one_file else 1)
        rows = schedule_rows(plan)
        summary = plan.summary()
        header = (f"# fabplan strip schedule: {summary['strips']} strips, {summary['sheets']} "
                  f"sheets of {W:g}x{H:g} mm; lengths and radii in millimetres\n")
        (tmp / f"{name}.csv").write_text(_schedule_csv(rows, header), encoding="utf-8")
        files += [f"{name}.csv", f"{name}.json"]
        record = _plan_record(plan, files, sheet_files, summary)
        # what a later run may remove as its own: only a file still as written here
        record["file_sha256"] = {f: _sha256(tmp / f) for f in files[:-1]}
        (tmp / f"{name}.json").write_text(json_text(record), encoding="utf-8")
        stale = _stale_files(out_dir, name, files)
        check_apart(stale, protect or {})
    for target in stale:
        target.unlink(missing_ok=True)
    return [out_dir / f for f in files]


@dataclass
class _SheetJob:
    """One sheet's files: its entities, the DXF and PNG names (None: not written)."""

    geometry: SheetGeometry
    dxf: str | None
    png: str | None
    title: str


def _write_sheet_jobs(jobs: list[_SheetJob], settings: StripSettings, folder: Path) -> None:
    """Write the DXF (checked) and the preview of each job into `folder`."""
    # ezdxf is imported when sheets are written, not with the strips' plan
    from .dxf import geometry_preview_png, write_sheet_file

    for job in jobs:
        if job.dxf is not None:
            write_sheet_file(job.geometry, settings, folder / job.dxf)
        if job.png is not None:
            geometry_preview_png(job.geometry, settings, folder / job.png, title=job.title)


def _run_sheet_jobs(jobs: list[_SheetJob], settings: StripSettings, folder: Path,
                    workers: int | None) -> None:
    """Run the jobs here or spread over `workers` processes.

    Each job is independent (its own document and files), so the processes only receive
    plain arrays and return nothing but errors. A plan of few sheets is written here: a
    process costs about as much to start as a sheet to write.
    """
    count = min((os.cpu_count() or 1) if workers is None else workers,
                len(jobs) // SHEETS_PER_PROCESS)
    if count <= 1:
        _write_sheet_jobs(jobs, settings, folder)
        return
    # interleaved batches: the first sheets hold the longest parts and take the longest
    batches = [(b, settings, folder) for k in range(4 * count) if (b := jobs[k::4 * count])]
    map_in_processes(_write_sheet_batch, batches, count)


def _write_sheet_batch(batch: tuple[list[_SheetJob], StripSettings, Path]) -> None:
    """`_write_sheet_jobs` of one batch, for a worker process."""
    _write_sheet_jobs(*batch)


def _stale_files(out_dir: Path, name: str, files: list[str]) -> list[Path]:
    """The files of an earlier run named `name` that this run does not write."""
    old = out_dir / f"{name}.json"
    if not old.is_file():
        return []
    try:
        listed = json.loads(old.read_text(encoding="utf-8")).get("files", [])
    except (ValueError, OSError, AttributeError):
        listed = []
    try:
        written = dict(json.loads(old.read_text(encoding="utf-8")).get("file_sha256", {}))
    except (ValueError, OSError, AttributeError, TypeError):
        written = {}
    # only names such a run writes, and only files still as it wrote them: the list is
    # data from the folder, and must not make a run remove anything else (a file of the
    # user's that happens to be named like a sheet, or one edited since)
    targets = [out_dir / Path(str(f)).name for f in listed]
    return [t for t in targets if t.is_file() and not t.is_symlink() and t.name not in files
            and any(fnmatch.fnmatchcase(t.name, p.replace("strips", name, 1)) for p in STRIP_FILES)
            and written.get(t.name) == _sha256(t)]


def _sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


#: the files `write_plan` writes into its folder (of the default name ``strips``)
STRIP_FILES = ("strips-sheet-*.dxf", "strips-sheet-*.png", "strips-sheets.dxf", "strips.csv",
               "strips.json")
