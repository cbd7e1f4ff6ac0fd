"""The results of a study: what each candidate produced and how it was judged, and the
whole study ranked with its recommendation. Plain records: `fabplan.study.run` fills them,
the cache (`fabplan.study.cache`), the search and the report read them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .definition import Candidate, Study

if TYPE_CHECKING:
    from ..design.mesh_surface import DesignSurface
    from ..fabricate.molds.boundary_molds import BoundaryMolds
    from ..fabricate.molds.mold_plan import MoldPlan
    from ..fabricate.strips.strip_plan import StripPlan
    from ..solve.optimize import OptimizationResult

__all__ = ["CandidateResult", "StudyResult", "by_rank"]


@dataclass
class CandidateResult:
    """What one candidate produced and how it was judged.

    Attributes
    ----------
    candidate : the `Candidate`.
    error : why the candidate failed to produce a net (None when it did).
    metrics : measured numbers (see ``docs/study-schema.md``).
    checks : one dict per limit: ``limit, bound, measured, ok, text``.
    feasible : every check passed.
    reasons : the verdict in plain words (the failed checks, or what was met).
    cost, cost_terms : the ranking cost and its parts (None for a failed candidate).
    rank : 1 for the best candidate.
    pareto : no other measured candidate is at least as good in every cost driver (molds,
        strip sheets, largest deviation) and better in one (`cost_drivers`).
    same_net_as : name of an earlier candidate that ended at the same net (see
        `same_net`) and planned its molds at this one's mold tolerance, or None.
    twin : name of an earlier candidate that ended at the same net, at any mold
        tolerance (its strips are this one's), or None.
    notes : remarks beside the verdict (that it is the same net as another candidate).
    net, molds, strips : the objects behind the metrics (for the files).
    singular_points : (k, 3) float, the singular points of the direction field of the
        layout the net was made from (marked on its pictures), or None.
    boundary_molds : the molds of the net's boundary panels (`BoundaryMolds`), or None.
    deviation_mm : (n,) float, distance of every net vertex from the design (mm), which
        the deviation metrics and the heat map are made of.
    """

    candidate: Candidate
    error: str | None = None
    metrics: dict = field(default_factory=dict)
    checks: list[dict] = field(default_factory=list)
    feasible: bool = False
    reasons: list[str] = field(default_factory=list)
    cost: float | None = None
    cost_terms: dict = field(default_factory=dict)
    rank: int | None = None
    pareto: bool = False
    same_net_as: str | None = None
    twin: str | None = None
    deviation_mm: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    net: OptimizationResult | None = None
    molds: MoldPlan | None = None
    strips: StripPlan | None = None
    singular_points: np.ndarray | None = None
    boundary_molds: BoundaryMolds | None = None

    @property
    def name(self) -> str:
        return self.candidate.name

    @property
    def failed(self) -> bool:
        return self.error is not None


@dataclass
class StudyResult:
    """All candidates of a study, ranked, with the recommendation.

    Attributes
    ----------
    study : the `Study`.
    design : the `fabplan.surfaces.DesignSurface`.
    candidates : `CandidateResult` in the order of the study file (baseline first).
    recommended : name of the recommended candidate, or None when none is feasible.
    recommendation : the recommendation in plain words, its paragraphs on lines of their
        own (a study without a feasible candidate: what its nearest fails, the relaxation
        that makes it feasible, the other ways, the panel size advised).
    sheets_charged : whether strip sheets enter the cost (only when every measured
        candidate has strips, see `judge_study`).
    made_files : the candidates' files made beside the computation, by a parallel run's
        workers or a serial run's forked processes (name -> what
        `fabplan.study.report.candidate_file_bytes` returns), for `write_study` to write;
        empty otherwise.
    seconds_run : wall time from loading the design to the last verdict (writing the
        files is not included: `fabplan.study_report.write_study` adds it).
    advised_layout : for a study without a feasible candidate that advises a smaller
        panel size, whether its general S-net converges at it (and at sizes between, where
        it does not: `fabplan.study.advised_size.check_advised_size`); None otherwise.
    relaxation_check : for a study without a feasible candidate whose nearest candidate's
        relaxation changes what its run is made with (its molds, its held deviation),
        that candidate run again under the relaxed limits
        (`fabplan.study.relaxation_check.check_relaxation`); None otherwise.
    """

    study: Study
    design: DesignSurface
    candidates: list[CandidateResult]
    recommended: str | None
    recommendation: str
    sheets_charged: bool = False
    seconds_run: float = 0.0
    made_files: dict = field(default_factory=dict)
    advised_layout: dict | None = None
    relaxation_check: dict | None = None

    @property
    def baseline(self) -> CandidateResult:
        return next(c for c in self.candidates if c.candidate.baseline)

    @property
    def design_size(self) -> float:
        """Diagonal of the design's bounding box (model units)."""
        return self.design.extent

    def ranked(self) -> list[CandidateResult]:
        """Measured candidates in rank order, then the failed ones."""
        return sorted(self.candidates, key=by_rank)


def by_rank(result: CandidateResult) -> tuple[bool, int]:
    """Sort key: ranked candidates in rank order, then the unranked (failed) ones in their
    order (sorting is stable)."""
    return (result.rank is None, 0 if result.rank is None else result.rank)
