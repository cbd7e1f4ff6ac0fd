"""Facade feasibility studies: run the candidate rationalizations of a design, measure
each against the fabrication limits, rank them by cost and recommend one.

For every candidate the pipeline is the one a user would run by hand::

    layout on the design  ->  net type solved  ->  measured  ->  molds  ->  strips
    (fabplan.layout)         (glide / optimize)   (this module)  (molds)   (strips)

Net types that exist on every surface (general, isogonal, orthogonal S-nets) are solved
exactly on the design (gliding); the others change the surface, so they start from the
gliding S-net and stay close to the design by a soft pull: how far they move is then a
measured deviation, judged against the limit. The baseline, a general S-net on the design,
is always run first, so that savings are measured against something.

Every verdict is computed from the metrics by `verdict`, a pure function of the measured
numbers and the limits: a change of a limit changes the verdict without a new run.
"""

from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .errors import FabplanError
from .geometry import face_planarity, kink_angles
from .molds import PANEL_TYPES
from .nets import get_net
from .study_spec import Candidate, CostWeights, Limits, Study

__all__ = [
    "CandidateResult",
    "StudyResult",
    "run_study",
    "measure_candidate",
    "start_angle",
    "verdict",
    "candidate_cost",
    "rank_candidates",
    "recommend",
]


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
    net, molds, strips, layout : the objects behind the metrics (for the files).
    """

    candidate: Candidate
    error: str | None = None
    metrics: dict = field(default_factory=dict)
    checks: list = field(default_factory=list)
    feasible: bool = False
    reasons: list = field(default_factory=list)
    cost: float | None = None
    cost_terms: dict = field(default_factory=dict)
    rank: int | None = None
    net: object = None
    molds: object = None
    strips: object = None
    layout: object = None

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
    recommendation : the recommendation in plain words.
    seconds : wall time of the run.
    """

    study: Study
    design: object
    candidates: list
    recommended: str | None
    recommendation: str
    seconds: float

    @property
    def baseline(self) -> CandidateResult:
        return next(c for c in self.candidates if c.candidate.baseline)

    def ranked(self) -> list:
        """Measured candidates in rank order, then the failed ones."""
        done = sorted((c for c in self.candidates if c.rank is not None), key=lambda c: c.rank)
        return done + [c for c in self.candidates if c.rank is None]


# ---------------------------------------------------------------------------- running
def run_study(study: Study, *, progress: Callable[[str], None] | None = None) -> StudyResult:
    """Run every candidate of `study` and judge it.

    A candidate that fails (a layout or a solve that breaks) is recorded with its reason
    and the study goes on.

    Raises
    ------
    InputError
        When the design cannot be loaded or the baseline layout is impossible (panel
        size too large for the surface, ...): nothing could be compared.
    """
    from .layout import layout_surface
    from .surfaces import load_design

    say = progress or (lambda message: None)
    start = time.perf_counter()
    design = load_design(study.design.source, triangles=study.design.triangles)
    say(f"design {study.design.label}: {len(design.triangles)} triangles, area "
        f"{design.area:.4g} {study.design.units}^2")
    layouts = {90.0: layout_surface(design, study.panel_size, angle=90.0)}
    starts: dict = {}
    results = []
    count = len(study.candidates)
    for i, candidate in enumerate(study.candidates, 1):
        say(f"[{i}/{count}] {candidate.name}: {candidate.describe()}")
        clock = time.perf_counter()
        try:
            result = _run_candidate(study, design, candidate, layouts, starts, say)
        except (FabplanError, ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            reason = str(exc) if isinstance(exc, FabplanError) else \
                f"{type(exc).__name__}: {exc} ({_where(exc)})"
            result = CandidateResult(candidate, error=reason, reasons=[reason])
            say(f"    failed: {reason}")
        result.metrics.setdefault("seconds", {})["total"] = time.perf_counter() - clock
        results.append(result)
    for r in results:
        if not r.failed:
            r.checks = verdict(r.metrics, study.limits)
            r.feasible = all(c["ok"] for c in r.checks)
            r.reasons = _reasons(r.checks, r.feasible)
            r.cost, r.cost_terms = candidate_cost(r.metrics, study.cost)
    rank_candidates(results)
    recommended, text = recommend(results, study.limits)
    return StudyResult(study, design, results, recommended, text, time.perf_counter() - start)


def _where(exc: BaseException) -> str:
    """File and line where an unexpected error arose (for the report, not a traceback)."""
    frame = traceback.extract_tb(exc.__traceback__)[-1]
    return f"{frame.filename.rsplit('/', 1)[-1]}:{frame.lineno}"


def _run_candidate(study: Study, design, candidate: Candidate, layouts: dict, starts: dict,
                   say) -> CandidateResult:
    from .layout import glide, layout_surface
    from .molds import MoldSettings, plan_molds
    from .optimize import optimize
    from .solver import SolverSettings
    from .strips import StripSettings, plan_strips

    seconds: dict = {}
    clock = time.perf_counter()
    angle = start_angle(candidate, design)
    if angle != 90.0:
        say(f"    layout at {angle:g} deg")
    if angle not in layouts:
        layouts[angle] = layout_surface(design, study.panel_size, angle=angle)
    layout = layouts[angle]
    seconds["layout"] = time.perf_counter() - clock
    settings = SolverSettings(max_iterations=study.max_iterations)

    def report(rec):
        if rec.iteration % 10 == 0:
            say(f"    iteration {rec.iteration:3d}  residual {rec.hard_residual:.2e}")

    clock = time.perf_counter()
    if candidate.glides:
        net = glide(layout, candidate.net, angle=candidate.angle, settings=settings,
                    progress=report)
        if candidate.net == "snet":
            starts[angle] = net
    else:
        if angle not in starts:
            starts[angle] = glide(layout, "snet", settings=settings)
        net = optimize(starts[angle].mesh, candidate.net, angle=candidate.angle,
                       radius=candidate.radius, reference=design.reference, settings=settings,
                       progress=report)
    seconds["optimize"] = time.perf_counter() - clock
    say(f"    {net.status} after {net.iterations} iterations ({seconds['optimize']:.1f} s)")

    clock = time.perf_counter()
    units = study.design.units
    molds = plan_molds(net.mesh, MoldSettings(tolerance_mm=study.limits.mold_tolerance_mm,
                                              units=units))
    seconds["molds"] = time.perf_counter() - clock
    say(f"    {molds.mold_count} molds for {molds.panel_count} panels "
        f"({seconds['molds']:.1f} s)")

    strips = None
    if study.strips is not None and study.strips.wanted(candidate.net):
        clock = time.perf_counter()
        options = study.strips
        strips = plan_strips(net.mesh, StripSettings(
            height_mm=options.height_mm, thickness_mm=options.thickness_mm, units=units,
            sheet_mm=options.sheet_mm))
        seconds["strips"] = time.perf_counter() - clock
        s = strips.summary()
        say(f"    {s['strips']} strips, {s['parts']} parts on {s['sheets']} sheets "
            f"({seconds['strips']:.1f} s)")
    metrics = measure_candidate(net, design, molds, strips, mm_per_unit=study.design.mm_per_unit)
    metrics["seconds"] = seconds
    return CandidateResult(candidate, metrics=metrics, net=net, molds=molds, strips=strips,
                           layout=layout)


def start_angle(candidate: Candidate, design) -> float:
    """Intersection angle (degrees) of the layout a candidate starts from.

    The candidate's own angle when it has one, else its ``start_angle``; else, for a
    characteristic conjugate net, the angle of the conjugate directions symmetric to the
    principal ones, ``2 atan(sqrt(k1 / k2))`` (area-weighted median over the design where
    K > 0); for a linear Weingarten net of free angle, the angle whose Euler formula
    ``k1 cos^2 + k2 sin^2`` matches the line ``a k1 + b k2 = c`` fitted to the design's
    curvatures, ``2 atan(sqrt(b / a))``; 90 degrees otherwise. A start far from the angle
    the net ends at makes the solve shear the whole net, and a closed or constrained
    layout cannot absorb that without leaving the design.
    """
    if candidate.angle is not None:
        return float(candidate.angle)
    if candidate.start_angle is not None:
        return float(candidate.start_angle)
    preset = get_net(candidate.net)
    if not (preset.planar_faces or (preset.angle == "param" and preset.radius == "param")):
        return 90.0
    from .directions import face_principal_frames
    from .molds import weingarten_fit

    k1, k2, _ = face_principal_frames(design)
    area = design.face_areas
    if preset.planar_faces:
        ratio = np.divide(k1, k2, out=np.full(len(k1), -1.0), where=k2 != 0)
        ok = ratio > 0
        if area[ok].sum() < 0.5 * area.sum():
            return 90.0
        angles = 2 * np.degrees(np.arctan(np.sqrt(ratio[ok])))
        return round(_weighted_median(angles, area[ok]), 1)
    line = weingarten_fit(k1, k2)["line"]
    if line is None or line["a"] * line["b"] <= 0:
        return 90.0
    return round(float(2 * np.degrees(np.arctan(np.sqrt(line["b"] / line["a"])))), 1)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


# ---------------------------------------------------------------------------- measuring
def _range(values: np.ndarray) -> dict | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    return {"min": float(v.min()), "max": float(v.max()), "mean": float(v.mean())}


def measure_candidate(net, design, molds, strips, *, mm_per_unit: float) -> dict:
    """Everything a verdict and a report need, measured on the solved net.

    Parameters
    ----------
    net : `fabplan.optimize.OptimizationResult`.
    design : the `DesignSurface` (deviation is measured to it).
    molds : the `MoldPlan` of the net; strips : its `StripPlan` or None.
    mm_per_unit : millimetres per model unit.

    Returns
    -------
    dict, JSON-ready: lengths in model units unless the key ends in ``_mm``, angles in
    degrees.
    """
    mesh = net.mesh
    X = mesh.vertices
    props = net.properties
    deviation = design.reference.distances(X) * mm_per_unit
    edges = np.linalg.norm(X[mesh.edges[:, 0]] - X[mesh.edges[:, 1]], axis=1)
    tri = mesh.triangles()
    tri_face = np.repeat(np.arange(len(mesh.face_sizes)), mesh.face_sizes - 2)
    tri_area = 0.5 * np.linalg.norm(np.cross(X[tri[:, 1]] - X[tri[:, 0]],
                                             X[tri[:, 2]] - X[tri[:, 0]]), axis=1)
    area = np.bincount(tri_face, tri_area, minlength=len(mesh.face_sizes))
    coverage = float(area.sum() / design.area)
    planarity = face_planarity(X, mesh.quads) * mm_per_unit
    kinks = np.degrees(kink_angles(X, mesh))
    residual = props.get("sphere_residual_relative", {}).get("max")
    plan = molds.record()
    metrics = {
        "status": net.status,
        "converged": net.converged,
        "iterations": net.iterations,
        "parameters": {k: v for k, v in net.parameters.items()
                       if k in ("angle_deg", "radius") and v is not None},
        "sphere_residual_relative_max": residual,
        "deviation_mm": {"max": float(deviation.max()), "mean": float(deviation.mean()),
                         "p95": float(np.percentile(deviation, 95))},
        "panels": int(len(mesh.face_sizes)),
        "quads": int(np.sum(mesh.face_sizes == 4)),
        "other_faces": int(np.sum(mesh.face_sizes != 4)),
        "vertices": int(mesh.vertex_count),
        "irregular_vertices": int(len(mesh.irregular_vertices)),
        "edge_length": _range(edges),
        "panel_area": _range(area),
        "coverage": coverage,
        "planarity_mm": _range(planarity) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "kink_deg": _range(kinks) or {"min": 0.0, "max": 0.0, "mean": 0.0},
        "intersection_angle_deg": _pick(props.get("intersection_angle_deg")),
        "meusnier_radius": _pick(props.get("meusnier_radius")),
        "molds": {
            "count": plan["mold_count"],
            "fits_all": plan["fits_all"],
            "failures": len(plan["failures"]),
            "max_deviation_mm": plan["max_deviation_mm"],
            "molds_per_sqrt_panels": plan["molds_per_sqrt_panels"],
            "panel_types": plan["panel_types"],
            "mold_types": plan["mold_types"],
            "panels_per_mold_max": plan["panels_per_mold"]["max"],
        },
        "strips": None,
    }
    if strips is not None:
        s = strips.summary()
        radius = s["radius_mm"]
        metrics["strips"] = {
            "strips": s["strips"],
            "parts": s["parts"],
            "sheets": s["sheets"],
            "material_use": s["material_use"],
            "total_length_mm": s["total_length_mm"],
            "straight": s["straight"],
            "congruent": s["congruent"],
            "congruence_deviation_mm": s["congruence_deviation_mm"],
            "radius_mm": None if radius is None else
            {"min": radius["min"], "max": radius["max"], "median": radius["median"]},
            "min_radius_mm": math.inf if radius is None else radius["min"],
            "max_radius_mm": math.inf if s["straight"] or radius is None or
            any(math.isinf(st.radius_mm) for st in strips.strips.strips) else radius["max"],
            "unrolled_length_error_mm": s["unrolled_length_error_mm"],
        }
    return metrics


def _pick(stats: dict | None) -> dict | None:
    if not stats or stats.get("min") is None:
        return None
    return {"min": stats["min"], "max": stats["max"]}


# ---------------------------------------------------------------------------- judging
def _check(limit: str, bound, measured, ok: bool, text: str) -> dict:
    return {"limit": limit, "bound": bound, "measured": measured, "ok": bool(ok), "text": text}


def verdict(metrics: dict, limits: Limits) -> list:
    """The checks of one candidate's measured `metrics` against the `limits`.

    Returns
    -------
    list of dicts ``{limit, bound, measured, ok, text}``, one per limit that applies;
    `text` says in plain words what was measured against what.
    """
    checks = []
    res = metrics["sphere_residual_relative_max"]
    res_ok = res is not None and res <= limits.max_sphere_residual and metrics["converged"]
    state = "converged" if metrics["converged"] else f"stopped ({metrics['status']})"
    checks.append(_check(
        "max_sphere_residual", limits.max_sphere_residual, res, res_ok,
        f"the solve {state} after {metrics['iterations']} iterations; largest sphere residual "
        f"{_g(res)} of an edge (limit {limits.max_sphere_residual:g})"))
    dev = metrics["deviation_mm"]["max"]
    checks.append(_check(
        "max_deviation_mm", limits.max_deviation_mm, dev, dev <= limits.max_deviation_mm,
        f"deviates at most {dev:.1f} mm from the design (limit {limits.max_deviation_mm:g} mm)"))
    molds = metrics["molds"]
    checks.append(_check(
        "mold_tolerance_mm", limits.mold_tolerance_mm, molds["max_deviation_mm"],
        molds["fits_all"],
        f"every panel fits its mold within {limits.mold_tolerance_mm:g} mm (largest gap "
        f"{molds['max_deviation_mm']:.2f} mm)" if molds["fits_all"] else
        f"{molds['failures']} panels fit no mold within {limits.mold_tolerance_mm:g} mm"))
    if limits.max_molds is not None:
        n = molds["count"]
        checks.append(_check("max_molds", limits.max_molds, n, n <= limits.max_molds,
                             f"needs {_count(n, 'mold')} (limit {limits.max_molds})"))
    if limits.planar_panels:
        p = metrics["planarity_mm"]["max"]
        checks.append(_check(
            "planarity_tolerance_mm", limits.planarity_tolerance_mm, p,
            p <= limits.planarity_tolerance_mm,
            f"panels planar within {p:.2f} mm (planar panels required, tolerance "
            f"{limits.planarity_tolerance_mm:g} mm)"))
    if limits.min_coverage is not None:
        cov = metrics["coverage"]
        checks.append(_check("min_coverage", limits.min_coverage, cov, cov >= limits.min_coverage,
                             f"panels cover {100 * cov:.1f} % of the design (limit at least "
                             f"{100 * limits.min_coverage:g} %)"))
    if limits.max_kink_deg is not None:
        k = metrics["kink_deg"]["max"]
        checks.append(_check("max_kink_deg", limits.max_kink_deg, k, k <= limits.max_kink_deg,
                             f"largest kink between neighbouring panels {k:.2f} deg (limit "
                             f"{limits.max_kink_deg:g} deg)"))
    strips = metrics.get("strips")
    if strips is not None:
        if limits.min_strip_radius_mm is not None:
            r = strips["min_radius_mm"]
            checks.append(_check(
                "min_strip_radius_mm", limits.min_strip_radius_mm, r,
                r >= limits.min_strip_radius_mm,
                f"smallest strip radius {_mm(r)} (limit at least {limits.min_strip_radius_mm:g} mm)"))
        if limits.max_strip_radius_mm is not None:
            r = strips["max_radius_mm"]
            checks.append(_check(
                "max_strip_radius_mm", limits.max_strip_radius_mm, r,
                r <= limits.max_strip_radius_mm,
                f"largest strip radius {_mm(r)} (limit at most {limits.max_strip_radius_mm:g} mm)"))
        if limits.congruent_strips:
            ok = strips["congruent"]
            checks.append(_check(
                "congruent_strips", True, ok, ok,
                ("all strip parts are congruent" if ok else "the strip parts are not congruent")
                + f" (largest difference {strips['congruence_deviation_mm']:.2f} mm)"))
        if limits.max_sheets is not None:
            n = strips["sheets"]
            checks.append(_check("max_sheets", limits.max_sheets, n, n <= limits.max_sheets,
                                 f"strips nested on {n} sheets (limit {limits.max_sheets})"))
    return checks


def _g(value) -> str:
    return "n/a" if value is None else f"{value:.2g}"


def _mm(value: float) -> str:
    return "infinite (straight)" if math.isinf(value) else f"{value:.0f} mm"


def _reasons(checks: list, feasible: bool) -> list:
    if feasible:
        return [f"meets all {len(checks)} limits: " + "; ".join(c["text"] for c in checks)]
    return [c["text"] for c in checks if not c["ok"]]


def candidate_cost(metrics: dict, weights: CostWeights) -> tuple[float, dict]:
    """The ranking cost of a candidate and its terms (see `CostWeights`)."""
    types = metrics["molds"]["panel_types"]
    strips = metrics.get("strips")
    # panels are counted for the whole design: a net with gaps must not look cheaper
    whole = 1.0 / max(min(metrics["coverage"], 1.0), 1e-6)
    terms = {
        "molds": weights.mold * metrics["molds"]["count"],
        "flat panels": weights.flat_panel * types.get(PANEL_TYPES[0], 0) * whole,
        "single curved panels": weights.single_curved_panel * types.get(PANEL_TYPES[1], 0) * whole,
        "double curved panels": weights.double_curved_panel * types.get(PANEL_TYPES[2], 0) * whole,
        "sheets": weights.sheet * (strips["sheets"] if strips else 0),
        "deviation": weights.deviation_mm * metrics["deviation_mm"]["max"],
    }
    return float(sum(terms.values())), terms


def rank_candidates(results: list) -> None:
    """Set `rank`: feasible candidates by cost, then the others by failed checks, cost."""
    done = [r for r in results if not r.failed]
    order = sorted(done, key=lambda r: (not r.feasible,
                                        sum(not c["ok"] for c in r.checks), r.cost))
    for i, r in enumerate(order, 1):
        r.rank = i


def recommend(results: list, limits: Limits) -> tuple[str | None, str]:
    """The recommended candidate (cheapest feasible) and why, in plain words."""
    base = next((r for r in results if r.candidate.baseline and not r.failed), None)
    feasible = sorted((r for r in results if r.feasible), key=lambda r: r.rank)
    if not feasible:
        measured = sorted((r for r in results if not r.failed), key=lambda r: r.rank)
        if not measured:
            return None, "No candidate produced a net; see the reasons of each below."
        best = measured[0]
        return None, (f"No candidate meets every limit. The closest is {best.name} "
                      f"({best.candidate.describe()}), which fails: "
                      + "; ".join(best.reasons) + ".")
    best = feasible[0]
    m = best.metrics
    words = [f"Recommended: {best.name} ({best.candidate.describe()})."]
    if best.candidate.baseline:
        words.append("The general S-net on the design is the cheapest feasible candidate: no "
                     "rationalization saves enough to pay for its deviation.")
    elif base is not None:
        b = base.metrics
        words.append(f"It needs {_count(m['molds']['count'], 'mold')} where the baseline needs "
                     f"{b['molds']['count']}" + _saving(m['molds']['count'], b['molds']['count'])
                     + f", deviates at most {m['deviation_mm']['max']:.1f} mm from the design "
                     f"(limit {limits.max_deviation_mm:g} mm) and costs {best.cost:.0f} units "
                     f"against {base.cost:.0f} for the baseline.")
    if m.get("strips"):
        s = m["strips"]
        shape = ", all straight" if s["straight"] else ", all congruent" if s["congruent"] else ""
        words.append(f"Its {s['strips']} lamellas are cut as {s['parts']} parts on "
                     f"{s['sheets']} sheets{shape}.")
    if limits.planar_panels:
        words.append(f"Its panels are planar within {m['planarity_mm']['max']:.2f} mm.")
    others = [r for r in feasible[1:]]
    if others:
        words.append("Also feasible: " + ", ".join(f"{r.name} ({r.cost:.0f})" for r in others)
                     + ".")
    infeasible = [r for r in results if not r.feasible]
    if infeasible:
        words.append("Not feasible: " + "; ".join(f"{r.name}: {r.reasons[0]}" for r in infeasible)
                     + ".")
    return best.name, " ".join(words)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _saving(n: int, base: int) -> str:
    if base <= 0 or n >= base:
        return ""
    return f" ({100 * (base - n) / base:.0f} % fewer)"
