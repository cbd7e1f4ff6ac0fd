"""`fabplan study STUDY -o DIR`: a facade feasibility study, its candidate nets run, judged
against the fabrication limits and ranked, and its report."""

from __future__ import annotations

import argparse
import time
from contextlib import ExitStack
from typing import TYPE_CHECKING

from ..io.output import output_argument
from ..report.html import counted
from .arguments import add_ifc, add_max_panels
from .registry import Command, register
from .running import command_progress

if TYPE_CHECKING:
    from ..study.result import StudyResult

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..study.report import check_output_folder, write_study
    from ..study.run import run_study
    from ..study.spec import read_study
    from ..study.templates import resolve_study

    progress = command_progress(args)
    say = progress.say()
    started = time.perf_counter()
    out = output_argument(args.output, folder=True)
    study = read_study(resolve_study(args.study))
    check_output_folder(out, study)
    cache = None
    if args.resume:
        from ..study.cache import CandidateCache

        cache = CandidateCache(out, study, note=say)
    with ExitStack() as stack:
        client = None
        if args.workers is not None or args.scheduler is not None:
            from ..study.parallel import dask_client, run_study_parallel, worker_count

            workers = None if args.workers is None else worker_count(args.workers)
            client = stack.enter_context(dask_client(workers, args.scheduler))
            result = run_study_parallel(study, client=client, progress=say,
                                        max_panels=args.max_panels, cache=cache,
                                        resume=args.resume, files=True, rhino=args.rhino,
                                        ifc=args.ifc)
        else:
            from ..study.background import BackgroundCandidates

            searching = (f" and {counted(len(study.searches), 'search', 'searches')}"
                         if study.searches else "")
            with progress.stage(f"running {counted(len(study.candidates), 'candidate')}{searching}"):
                result = run_study(study, progress=say, max_panels=args.max_panels, cache=cache,
                                   resume=args.resume, files=True, rhino=args.rhino,
                                   ifc=args.ifc,
                                   # a --resume run keeps each candidate as it finishes,
                                   # in the order of the study
                                   background=BackgroundCandidates if cache is None else None)
        writing = time.perf_counter()
        # with workers, they make the candidates' files too
        with progress.stage("writing the report and the candidates' files"):
            files = write_study(result, out, progress=say, rhino=args.rhino, ifc=args.ifc,
                                view_3d=not args.no_3d, client=client, fork=client is None)
    done = time.perf_counter()
    if args.quiet:
        verdict = (f"recommended: {result.recommended}" if result.recommended else
                   "no candidate meets the limits")
        print(f"{verdict}; wrote {files[0]} in {done - started:.0f} s")
        return _study_exit(result)
    for c in result.ranked():
        if c.failed:
            print(f"  {c.name:<28} failed: {c.error}")
            continue
        m = c.metrics
        note = f"  (the same net as {c.same_net_as})" if c.same_net_as else ""
        print(f"{c.rank:>2} {c.name:<28} {'feasible' if c.feasible else 'not feasible':<12} "
              f"molds {m['molds']['count']:>4}  panels {m['panels']:>5}  deviation "
              f"{m['largest_deviation_mm']:8.1f} mm  cost {c.cost:9.0f}{note}")
    print(result.recommendation)
    print(f"wrote {files[0]} (and study.json, candidates.csv, candidates/) in "
          f"{done - started:.0f} s: {result.seconds_run:.0f} s to run the candidates, "
          f"{done - writing:.0f} s to write the files")
    return _study_exit(result)


def _study_exit(result: StudyResult) -> int:
    """0 with a recommendation, 3 when no candidate meets every limit (a fabrication
    limit not met, as the other commands say it; the files are written)."""
    return 0 if result.recommended else 3


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("study", help="study file (TOML, see docs/study-file.md) or a template "
                   "name (see `fabplan templates`)")
    p.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for report.html, study.json, candidates.csv and candidates/: "
                        "new, empty, or holding an earlier study (whose files are replaced)")
    p.add_argument("--workers", metavar="N|auto",
                   help="run the candidates in N local processes (auto: one per core) with Dask")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run the candidates on a running Dask cluster (see docs/parallel.md)")
    p.add_argument("--resume", action="store_true",
                   help="keep every finished candidate in DIR/.fabplan-cache as it finishes, and "
                        "take those an earlier (or interrupted) --resume run kept there instead "
                        "of computing them again")
    add_max_panels(p)
    p.add_argument("--3dm", dest="rhino", action="store_true",
                   help="also write every candidate's net as candidates/NAME/net.3dm (mesh, "
                        "polylines, panels per mold, strip curves) and net.glb")
    add_ifc(p, "every candidate's facade plan as candidates/NAME/net.ifc")
    p.add_argument("--no-3d", action="store_true",
                   help="leave the interactive 3D view out of report.html")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print only errors and a one-line summary")


def _parser_options() -> dict:
    return {"description": "Run a facade feasibility study and write its report. "
            "A study replaces what an earlier study wrote in the output folder (listed "
            "in DIR/.fabplan-files) and keeps every other file, so a study can be "
            "re-run into its folder; a folder of other files only, a file, or the "
            "folder of the study file is refused."}


COMMAND = register(Command("study", "facade feasibility study: run the candidate nets of a "
                                    "design, judge them against the fabrication limits, recommend one",
                           add_arguments, run, _parser_options))
