"""The solve of a command that makes a net (`optimize`, `layout`): its settings from the
command line, its iterations on the progress output, and a net that did not converge."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..report.progress import Progress
from ..solve.solver import SolverSettings

__all__ = ["IterationReport", "solver_options", "warn_not_converged"]


class IterationReport:
    """The solver's progress callback: each iteration to `progress` (a line each with -v;
    the live line of `stage` on a terminal)."""

    def __init__(self, progress: Progress):
        self.progress = progress
        self.stage: Any = None
        self.prefix = ""         # which of several solves (`fabplan layout`'s starts)

    def __call__(self, rec: Any) -> None:
        # a multilevel start solves coarse nets first, each counting its own iterations
        net = self.prefix + (f"coarse net of {rec.coarse_vertices:,} vertices, "
                             if rec.coarse_vertices else "")
        if self.stage is not None:
            self.stage.note(f"{net}iteration {rec.iteration}, residual {rec.hard_residual:.2e}")
        self.progress.iteration(f"{net}iteration {rec.iteration:3d}  residual "
                                f"{rec.hard_residual:.3e}  step {rec.step:.2e}  "
                                f"{rec.seconds * 1000:.0f} ms")


def solver_options(args: argparse.Namespace,
                   progress: Progress) -> tuple[SolverSettings, IterationReport]:
    """Solver settings from --max-iter, and the callback that reports the iterations."""
    settings = SolverSettings()
    if args.max_iter is not None:
        settings.max_iterations = args.max_iter
    if getattr(args, "no_multilevel", False):
        settings.multilevel = False
    return settings, IterationReport(progress)


def warn_not_converged(result, json_path: Path) -> None:
    what = {"iteration cap": "stopped at the iteration cap", "folded": "ended folded",
            "degenerate": "ended degenerate", "crumpled": "ended crumpled",
            "off-design": "ended off the design"}.get(
        result.status, f"stopped ({result.status})")
    said = f"stopped ({result.status}) "
    # the status is said once: "stopped (stagnated) with ..." continues the sentence
    message = (" " + result.message[len(said):] if result.message.startswith(said)
               else ": " + result.message)
    print(f"fabplan: warning: the optimization {what}{message} (details in {json_path})",
          file=sys.stderr)
