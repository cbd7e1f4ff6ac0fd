"""The records of a study: ``study.json`` (`study_record`, schema ``docs/study-schema.md``:
every number of the report is in it) and ``candidates.csv`` (`candidates_csv`, one row
per candidate in rank order).
"""

from __future__ import annotations

import csv
import io
from typing import TYPE_CHECKING

from .checks import next_steps, relaxation_text
from .ranking import binding_limit
from .result import CandidateResult, StudyResult
from .search import search_record

if TYPE_CHECKING:
    from .definition import Study


__all__ = ["STUDY_SCHEMA", "study_record", "candidates_csv"]


STUDY_SCHEMA = "fabplan-study/1"


def _candidate_record(c: CandidateResult, outputs: dict, recommended: str | None,
                      study: Study) -> dict:
    return {
        "name": c.name,
        "net": c.candidate.net,
        "description": c.candidate.describe(),
        "baseline": c.candidate.baseline,
        "recommended": c.name == recommended,
        "requested": {"angle_deg": c.candidate.angle, "radius": c.candidate.radius,
                      "panel_size": study.panel_size_of(c.candidate),
                      "mold_tolerance_mm": study.mold_tolerance_of(c.candidate)},
        "feasible": c.feasible,
        "reasons": c.reasons,
        "same_net_as": c.same_net_as,
        "notes": c.notes,
        "error": c.error,
        "checks": c.checks,
        "binding_limit": None if (b := binding_limit(c, study)) is None else b["limit"],
        "relaxation": relaxation_text(c.checks) or None,
        "next_steps": [] if c.feasible else next_steps(c.checks),
        "metrics": c.metrics,
        "cost": c.cost,
        "cost_terms": c.cost_terms,
        "rank": c.rank,
        "pareto": c.pareto,
        "outputs": outputs,
    }


def study_record(result: StudyResult, outputs: dict | None = None, *,
                 seconds_total: float | None = None) -> dict:
    """The ``study.json`` record (schema ``docs/study-schema.md``).

    `seconds_total` is the wall time including writing the files (`write_study` measures
    it); without it, the run time.
    """
    outputs = outputs or {}
    design = result.design
    triangles = int(len(design.triangles))
    study = result.study.record()
    if study["design"]["triangles"] is None:          # a design file: its own triangles
        study["design"]["triangles"] = triangles
    return {
        "schema": STUDY_SCHEMA,
        "study": study,
        "design": {"label": result.study.design.label, "source": result.study.design.source,
                   "triangles": triangles, "area": float(design.area),
                   "size": result.design_size, "units": result.study.design.units},
        "recommended": result.recommended,
        "recommendation": result.recommendation,
        "advised_layout": result.advised_layout,
        "relaxation_check": result.relaxation_check,
        "sheets_charged": result.sheets_charged,
        "candidates": [_candidate_record(c, outputs.get(c.name, {}), result.recommended,
                                         result.study)
                       for c in result.candidates],
        "searches": [search_record(s, result.candidates) for s in result.study.searches],
        "seconds_run": result.seconds_run,
        "seconds_total": result.seconds_run if seconds_total is None else seconds_total,
        # fabplan-study/1 readers knew the run time as `seconds`: the same as seconds_total
        "seconds": result.seconds_run if seconds_total is None else seconds_total,
    }


_CSV_COLUMNS = ["rank", "name", "net", "panel_size", "mold_tolerance_mm", "feasible", "cost",
                "molds", "panels", "boundary_panels",
                "planar", "single_curved", "double_curved", "coverage", "coverage_full_panels",
                "folded", "deviation_max_mm",
                "deviation_p95_mm",
                "planarity_max_mm", "kink_max_deg", "angle_min_deg", "angle_max_deg",
                "radius_min", "radius_max", "sheets", "strips_congruent", "seconds", "reasons"]


def _row(c: CandidateResult, study: Study) -> dict:
    m = c.metrics
    asked = {"name": c.name, "net": c.candidate.net,
             "panel_size": _num(study.panel_size_of(c.candidate)),
             "mold_tolerance_mm": _num(study.mold_tolerance_of(c.candidate))}
    if c.failed:
        return {**asked, "feasible": "no",
                "reasons": "; ".join(c.reasons), "seconds": _num(m.get("seconds", {}).get("total"))}
    types = m["molds"]["panel_types"]
    angle, radius, strips = m["intersection_angle_deg"], m["meusnier_radius"], m["strips"]
    return {
        **asked, "rank": c.rank,
        "feasible": "yes" if c.feasible else "no", "cost": _num(c.cost),
        "molds": m["molds"]["count"], "panels": m["panels"],
        "boundary_panels": (m.get("boundary_panels") or {}).get("count", 0),
        "coverage_full_panels": _num(m.get("coverage_net", m["coverage"])),
        "planar": types.get("planar", 0), "single_curved": types.get("single_curved", 0),
        "double_curved": types.get("double_curved", 0),
        "coverage": _num(m["coverage"]),
        "folded": "yes" if (m.get("folds") or {}).get("folded") else "no",
        "deviation_max_mm": _num(m["largest_deviation_mm"]),
        "deviation_p95_mm": _num(m["deviation_mm"]["p95"]),
        "planarity_max_mm": _num(m["planarity_mm"]["max"]),
        "kink_max_deg": _num(m["kink_deg"]["max"]),
        "angle_min_deg": _num(angle and angle["min"]), "angle_max_deg": _num(angle and angle["max"]),
        "radius_min": _num(radius and radius["min"]), "radius_max": _num(radius and radius["max"]),
        "sheets": strips["sheets"] if strips else "",
        "strips_congruent": ("yes" if strips["congruent"] else "no") if strips else "",
        "seconds": _num(m["seconds"]["total"]), "reasons": "; ".join(c.reasons),
    }


def _num(value) -> str:
    return "" if value is None else f"{value:.6g}"


def candidates_csv(result: StudyResult) -> str:
    """``candidates.csv``: one row per candidate in rank order."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=_CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for c in result.ranked():
        writer.writerow(_row(c, result.study))
    return buffer.getvalue()
