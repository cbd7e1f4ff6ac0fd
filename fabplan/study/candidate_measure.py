"""The second half of a study candidate: its molds and strips planned, and every number a
verdict and a report need measured on its net (`measure_candidate`: JSON-ready, lengths in
model units unless the key ends in ``_mm``, angles in degrees).
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..net.free_vertices import free_vertices
from ..net.geometry import face_planarity, kink_angles
from ..report.html import counted
from .candidate_solve import DEVIATION_HELD
from .definition import Candidate, Study
from .mold_counts import mold_metrics, molds_text
from .result import CandidateResult
from .verdict import BEND_SHARE

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..design.mesh_surface import DesignSurface
    from ..fabricate.molds.boundary_molds import BoundaryMolds
    from ..fabricate.molds.mold_plan import MoldPlan
    from ..fabricate.strips.strip_plan import StripPlan
    from ..fabricate.strips.strip_set import StripSettings
    from ..net.mesh import QuadMesh
    from ..solve.optimize import OptimizationResult

__all__ = ["fabricate_candidate", "study_class_order", "vertex_deviation_mm", "measure_candidate"]


def fabricate_candidate(study: Study, design: DesignSurface, solved: CandidateResult,
                        twin: CandidateResult | None, say: Callable[[str], None]
                        ) -> CandidateResult:
    """The second half of a candidate: molds, strips and every measurement of its net.

    A `twin` is an earlier candidate that ended at the same net (CMC on a saddle ending at
    the minimal surface): its strips are this candidate's, not planned again, and so are
    its molds when they were planned at this candidate's mold tolerance; only then is the
    candidate the twin's net (`same_net_as`) rather than an option of its own.
    """
    from ..fabricate.molds.boundary_molds import boundary_molds
    from ..fabricate.molds.mold_assignment import plan_molds
    from ..fabricate.molds.mold_shapes import MoldSettings
    from ..fabricate.strips.strip_plan import plan_strips

    net, candidate = solved.net, solved.candidate
    assert net is not None
    seconds = dict(solved.metrics.get("seconds", {}))
    tolerance = study.mold_tolerance_of(candidate)
    same_molds = (twin is not None and twin.molds is not None
                  and twin.molds.settings.tolerance_mm == tolerance)
    if twin is not None:
        say(f"    the same net as {twin.name}: its {'molds and ' if same_molds else ''}strips "
            "are reused")
    clock = time.perf_counter()
    units = study.design.units
    if same_molds:
        assert twin is not None and twin.molds is not None
        molds = twin.molds
    else:
        # a net held on the design: its panels are patches of the design itself
        limit = study.limits_of(candidate).panel_step_limit_mm
        molds = plan_molds(net.mesh, MoldSettings(tolerance_mm=tolerance, units=units,
                                                  step_limit_mm=limit, material=study.material,
                                                  class_order=study_class_order(study)),
                           design=design if candidate.glides else None)
    bounds = None
    if net.boundary_panels is not None:
        # on the net's molds, placed to meet their neighbours; their distance from the
        # design measured as cut
        bounds = boundary_molds(molds, net.boundary_panels, design=design)
        if bounds.panels is not None and bounds.panels is not net.boundary_panels:
            # flat panels part along the lines where their planes cross: written so, the
            # boundary file gives `fabplan molds` the same panels
            net.boundary_panels = bounds.panels
            net.properties["boundary_panels"] = bounds.panels.record()
    seconds["molds"] = time.perf_counter() - clock
    say(f"    {molds_text(mold_metrics(molds, bounds))} for {counted(molds.panel_count, 'panel')}"
        + (f" and {counted(bounds.count, 'boundary panel')}" if bounds is not None else "")
        + f" ({seconds['molds']:.1f} s)")

    strips = None
    options = study.strips
    if options is not None and options.wanted(candidate.net):
        if twin is not None and twin.strips is not None:
            strips = twin.strips
        else:
            clock = time.perf_counter()
            strips = plan_strips(net.mesh, _strip_settings(study, candidate, units),
                                 boundary=net.boundary_panels)
            seconds["strips"] = time.perf_counter() - clock
            s = strips.summary()
            say(f"    {counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} on "
                f"{counted(s['sheets'], 'sheet')} ({seconds['strips']:.1f} s)")
    deviation = vertex_deviation_mm(net.mesh, design, study.design.mm_per_unit)
    metrics = measure_candidate(net, design, molds, strips, mm_per_unit=study.design.mm_per_unit,
                                deviation_mm=deviation, boundary=bounds)
    _within_study_limit(metrics, study.limits_of(candidate).max_deviation_mm)
    if candidate.net == "char-conjugate":
        # its directions are real only where the design is synclastic: the verdict says so
        metrics["design_anticlastic"] = anticlastic_share(design)
    # what the verdict says of kinks and failed solves at this panel size (None: a plane)
    radius = bend_radius(design)
    metrics["design_bend_radius"] = radius if math.isfinite(radius) else None
    metrics["seconds"] = seconds
    return CandidateResult(candidate, metrics=metrics, net=net, molds=molds, strips=strips,
                           singular_points=solved.singular_points, boundary_molds=bounds,
                           same_net_as=twin.name if same_molds and twin is not None else None,
                           twin=twin.name if twin is not None else None,
                           deviation_mm=deviation)


def _within_study_limit(metrics: dict, limit_mm: float) -> None:
    """A solve that ended "off-design" only against the share of the limit it held
    (`DEVIATION_HELD`), with the net and its boundary panels within the study's own
    deviation limit, gave the study the net it asked for: its status is "converged", and
    ``solve_status`` and ``status_note`` keep what the solve said (its net record keeps
    the solver's status)."""
    if metrics["status"] != "off-design" or metrics["largest_deviation_mm"] > limit_mm:
        return
    metrics["solve_status"], metrics["status"], metrics["converged"] = "off-design", "converged", True
    metrics["status_note"] = (
        f"{metrics['largest_deviation_mm']:.1f} mm off the design: past the "
        f"{DEVIATION_HELD * limit_mm:.0f} mm the solve held, within the study's "
        f"{limit_mm:g} mm")


def study_class_order(study: Study) -> tuple[str, ...]:
    """The order a study's panels try the classes in (`fabplan.fabricate.molds.panel_classes.
    class_order`): cold or roll bending first by the study's ``[cost]``."""
    from ..fabricate.molds.panel_classes import class_order

    return class_order(study.cost.cold_bent_panel, study.cost.roll_bent_panel)


# ---------------------------------------------------------------------------- measuring
def _range(values: np.ndarray) -> dict | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    return {"min": float(v.min()), "max": float(v.max()), "mean": float(v.mean())}


def vertex_deviation_mm(mesh: QuadMesh, design: DesignSurface, mm_per_unit: float) -> np.ndarray:
    """(n,) float, distance of every vertex of a net from the design in mm (to the exact
    surface of a built-in or NURBS design, to the triangle mesh of a mesh file)."""
    return design.distances(mesh.vertices) * mm_per_unit


def _free_vertex_record(net: OptimizationResult, mm_per_unit: float) -> dict | None:
    """How many vertices of the net are in no star, and how far the solve settled them
    onto the surface the net continues (mm); None for a net solved before this was recorded."""
    free = net.parameters.get("free_vertices")
    if free is None:
        return None
    return {"count": free["count"], "settled": free["settled"],
            "largest_move_mm": free["largest_move"] * mm_per_unit}


def measure_candidate(net: OptimizationResult, design: DesignSurface, molds: MoldPlan,
                      strips: StripPlan | None, *, mm_per_unit: float,
                      deviation_mm: np.ndarray | None = None,
                      boundary: BoundaryMolds | None = None) -> dict:
    """Everything a verdict and a report need, measured on the solved net.

    Parameters
    ----------
    net : `fabplan.optimize.OptimizationResult`.
    design : the `DesignSurface` (deviation is measured to it).
    molds : the `MoldPlan` of the net; strips : its `StripPlan` or None.
    mm_per_unit : millimetres per model unit.
    deviation_mm : (n,) float, the vertices' distances from the design (mm), when already
        measured (`vertex_deviation_mm`).
    boundary : the `BoundaryMolds` of the net's boundary panels, when it has them: they
        count as panels, with their molds, and their coverage.

    Returns
    -------
    dict, JSON-ready: lengths in model units unless the key ends in ``_mm``, angles in
    degrees.
    """
    mesh = net.mesh
    X = mesh.vertices
    props = net.properties
    deviation = vertex_deviation_mm(mesh, design, mm_per_unit) if deviation_mm is None else deviation_mm
    edges = np.linalg.norm(X[mesh.edges[:, 0]] - X[mesh.edges[:, 1]], axis=1)
    area = mesh.face_areas
    coverage = float(props.get("coverage", area.sum() / design.area))
    trimmed = props.get("boundary_panels") or {}
    planarity = face_planarity(X, mesh.quads) * mm_per_unit
    tips = free_vertices(mesh)
    kinks = np.degrees(kink_angles(X, mesh))
    residual = props.get("sphere_residual_relative", {}).get("max")
    metrics = {
        "status": net.status,
        "converged": net.converged,
        "iterations": net.iterations,
        "parameters": {k: v for k, v in net.parameters.items()
                       if k in ("angle_deg", "radius") and v is not None},
        "sphere_residual_relative_max": residual,
        **_solve_record(net, mm_per_unit),
        "deviation_mm": {"max": float(deviation.max()), "mean": float(deviation.mean()),
                         "p95": float(np.percentile(deviation, 95)),
                         # the vertices the net's conditions hold (in a star), apart from
                         # the free tips settled onto the surface the net continues
                         "held_max": float(deviation[~tips].max()) if (~tips).any()
                         else None},
        "panels": int(len(mesh.face_sizes)) + (boundary.count if boundary is not None else 0),
        "full_panels": int(len(mesh.face_sizes)),
        "boundary_panels": None if boundary is None else _boundary_panel_metrics(boundary, trimmed),
        "quads": int(np.sum(mesh.face_sizes == 4)),
        "other_faces": int(np.sum(mesh.face_sizes != 4)),
        "vertices": int(mesh.vertex_count),
        "irregular_vertices": int(len(mesh.irregular_vertices)),
        "edge_length": _range(edges),
        "panel_area": _range(area),
        "coverage": coverage,
        "coverage_net": float(props.get("coverage_net", coverage)),
        "planarity_mm": _range(planarity) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "kink_deg": _range(kinks) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "intersection_angle_deg": _pick(props.get("intersection_angle_deg")),
        "meusnier_radius": _pick(props.get("meusnier_radius")),
        "folds": _fold_counts(props.get("folds")),
        "buildable": _buildable_counts(props.get("buildable")),
        "line_turn_deg": (props.get("fairness") or {}).get("line_turn_deg"),
        "free_vertices": _free_vertex_record(net, mm_per_unit),
        "molds": mold_metrics(molds, boundary),
        "strips": None if strips is None else _strip_metrics(strips),
    }
    # the facade as built: the net's vertices and the boundary panels on their molds
    edge = (metrics.get("boundary_panels") or {}).get("deviation_max_mm")
    metrics["largest_deviation_mm"] = (max(metrics["deviation_mm"]["max"], edge)
                                       if edge is not None else metrics["deviation_mm"]["max"])
    return metrics


def anticlastic_share(design: DesignSurface) -> float:
    """The share of the design's area that is saddle-shaped (Gaussian curvature below
    zero, the principal curvatures of opposite signs beyond a thousandth of their typical
    size), found once per design. No characteristic conjugate net exists there: its two
    directions, symmetric to the principal ones and conjugate, are real only where the
    Gaussian curvature is positive."""
    cached = design.__dict__.get("_anticlastic_share")
    if cached is None:
        from ..layout.directions import face_principal_frames

        k1, k2, _ = face_principal_frames(design)
        typical = float(np.median(np.abs(k1) + np.abs(k2))) or 1.0
        saddle = k1 * k2 < -(1e-3 * typical) ** 2
        cached = float(design.face_areas[saddle].sum() / design.face_areas.sum())
        design.__dict__["_anticlastic_share"] = cached
    return cached


def bend_radius(design: DesignSurface, share: float = BEND_SHARE) -> float:
    """The radius (model units) the design curves with over its most curved `share` of
    area: the smallest radius of curvature, max(|k1|, |k2|) inverted, of all but that
    share (one stray triangle does not set it), found once per design; inf for a plane."""
    cached = design.__dict__.get("_bend_radius")
    if cached is None:
        from ..design.mesh_surface import weighted_quantile
        from ..layout.directions import face_principal_frames

        k1, k2, _ = face_principal_frames(design)
        sharp = weighted_quantile(np.maximum(np.abs(k1), np.abs(k2)), design.face_areas,
                                  1.0 - share)
        cached = 1.0 / sharp if sharp > 0 else math.inf
        design.__dict__["_bend_radius"] = cached
    return cached


def _strip_settings(study: Study, candidate: Candidate, units: str) -> StripSettings:
    """The strips of a candidate as the study plans them: its ``[strips]`` options and the
    candidate's twist limit."""
    from ..fabricate.strips.strip_set import StripSettings

    options = study.strips
    assert options is not None
    return StripSettings(height_mm=options.height_mm, thickness_mm=options.thickness_mm,
                         units=units, sheet_mm=options.sheet_mm,
                         tolerance_mm=options.congruence_tolerance_mm,
                         max_twist_deg_per_m=study.limits_of(candidate).max_twist_deg_per_m)


def _boundary_panel_metrics(boundary: BoundaryMolds, trimmed: dict) -> dict:
    """The ``boundary_panels`` part of a candidate's metrics: their molds (`BoundaryMolds`)
    and what the trimming recorded (`trimmed`: flipped panels, patches)."""
    return {
        "count": boundary.count,
        "on_net_molds": boundary.on_net_molds,
        "flat": boundary.flat,
        "own_molds": boundary.own_molds,
        # as cut from their molds: their largest distance from the design, and step
        # against a neighbour
        "deviation_max_mm": boundary.deviation_max_mm,
        "step_max_mm": boundary.step_max_mm,
        "flipped": len(trimmed.get("flipped") or []),
        "patches": len(trimmed.get("patches") or []),
    }


def _strip_metrics(strips: StripPlan) -> dict:
    """The ``strips`` part of a candidate's metrics (`measure_candidate`): counts, sheets,
    lengths, radii (mm) and how the strips end, from `StripPlan.summary`."""
    s = strips.summary()
    radius = s["radius_mm"]
    return {
        "strips": s["strips"],
        "parts": s["parts"],
        "sheets": s["sheets"],
        "material_use": s["material_use"],
        "total_length_mm": s["total_length_mm"],
        "straight": s["straight"],
        "congruent": s["congruent"],
        "congruence_deviation_mm": s["congruence_deviation_mm"],
        "max_twist_deg_per_m": s["twist_deg_per_m"],
        "radius_mm": None if radius is None else
        {"min": radius["min"], "max": radius["max"], "median": radius["median"]},
        "min_radius_mm": math.inf if radius is None else radius["min"],
        "max_radius_mm": math.inf if s["straight"] or radius is None or
        any(math.isinf(st.radius_mm) for st in strips.strips.strips) else radius["max"],
        "unrolled_length_error_mm": s["unrolled_length_error_mm"],
        "ends_at_boundary_member": s["ends_at_boundary_member"],
        "ends_free": s["ends_free"],
        "ends_free_by_kind": s["ends_free_by_kind"],
        "ends_not_continued": s["ends_not_continued"],
        "boundary_member_mm": strips.strips.settings.member_mm,
    }


def _buildable_counts(build: dict | None) -> dict | None:
    """The counts of `fabplan.net.buildable` on the net (non-convex and self-crossing
    faces, sharp line turns, edge jumps, far vertices) and whether it can be built."""
    if build is None:
        return None
    keys = ("nonconvex_faces", "self_crossing_faces", "sharp_line_turns", "edge_jumps",
            "far_vertices")
    return {"buildable": bool(build["buildable"]),
            **{k: int((build.get(k) or {"count": 0})["count"]) for k in keys}}


def _fold_counts(folds: dict | None) -> dict | None:
    """The counts of `fabplan.net.folds` on the net (flipped faces, fold edges, degenerate
    stars, collapsed edges) and whether it folds."""
    if folds is None:
        return None
    keys = ("flipped_faces", "fold_edges", "degenerate_stars", "collapsed_edges")
    return {"folded": bool(folds["folded"]), **{k: int(folds[k]["count"]) for k in keys}}


def _pick(stats: dict | None) -> dict | None:
    if not stats or stats.get("min") is None:
        return None
    return {"min": stats["min"], "max": stats["max"]}


def _solve_record(net: OptimizationResult, mm_per_unit: float) -> dict:
    """What a candidate's solve tried and left: ``unmet`` (the hard families a solve that
    stopped short left above the tolerance), ``deviation_search`` (how far its deviation
    continuation looked for a net of the type: `_deviation_search`), ``layout_starts``
    (a gliding net's own starts, else those of the S-net a net past the edges began at)
    and ``continued`` (whether it was solved on the design continued past its edges)."""
    return {"unmet": {k: float(v) for k, v in (net.parameters.get("unmet") or {}).items()},
            "continued": bool(net.parameters.get("continued")),
            "deviation_search": _deviation_search(net.parameters.get("deviation"), mm_per_unit),
            "layout_starts": len(net.properties.get("layout_starts") or [])
            or int((net.parameters.get("continued") or {}).get("starts", 1))}


def _deviation_search(record: dict | None, mm_per_unit: float) -> dict | None:
    """The deviation continuation of a solve (`fabplan.solve.attempts.deviation_continuation`)
    in millimetres: the loosest limit it tried and the smallest it converged buildable to
    (None when none did); None when the solve needed none."""
    if not record or not record.get("tried"):
        return None
    smallest = record.get("smallest_converged")
    return {"loosest_mm": float(record["tried"][0]) * mm_per_unit,
            "smallest_converged_mm": None if smallest is None else float(smallest) * mm_per_unit}
