"""The tables and sentences of a study report, shared by its page (``report.html``) and
its print (``report.pdf``): the comparison of the candidates, the limits and the cost
weights, a candidate's measured facts and checks, and the numbers told in words (radii,
limits, coverage, the sharpest turn of the lines, the Pareto front, a search).
"""

from __future__ import annotations

import math

from ..layout.picture import kink_text as layout_kink_text
from ..report import html
from ..report.html import counted, format_range
from .checks import LIMIT_NAMES, feasible_with, next_steps
from .mold_counts import material_sentence, molds_text
from .result import CandidateResult, StudyResult
from .verdict import every_panel_flat

__all__ = ["INFINITE_RADIUS_FACTOR", "RANK_RULE", "radius_text", "limit_text", "limit_items",
           "sharpest_turn", "kink_text", "pareto_text", "search_text", "cost_line",
           "comparison_table", "comparison_rows", "limits_table", "cost_table",
           "candidate_facts", "check_rows"]


def search_text(record: dict, unit: str) -> str:
    """A search's outcome in words."""
    points = record["points"]
    values = ", ".join(f"{p['value']:g}" for p in points)
    if record["best"] is None:
        return (f"{record['name']}: {record['parameter']} searched in {record['low']:g} .. "
                f"{record['high']:g} {unit} at {values}: no point meets every limit.")
    low, high = record["feasible_range"]
    band = f"{low:g}" if low == high else f"{low:g} .. {high:g}"
    return (f"{record['name']}: {record['parameter']} searched in {record['low']:g} .. "
            f"{record['high']:g} {unit} at {values}; feasible at {band} {unit}; the cheapest "
            f"feasible point is {record['best']}.")



#: Radii beyond this multiple of the design's size are shown as infinite: the stars (or
#: strips) are planar (straight) to within what a computation can tell.
INFINITE_RADIUS_FACTOR = 1e4


def _fmt_range(r: dict | None, unit: str = "", digits: int = 4) -> str:
    if not r:
        return ""
    return format_range(r["min"], r["max"], unit, digits)


def radius_text(r: dict | float | None, unit: str, beyond: float, infinite: str) -> str:
    """A radius or a ``{min, max}`` range of radii with its unit; values above `beyond`
    (or infinite, or None) are `infinite`.

    Examples
    --------
    >>> radius_text({"min": 3.558e9, "max": 1.033e16}, "m", 2.8e5, "infinite (planar stars)")
    'infinite (planar stars)'
    >>> radius_text({"min": 12.25, "max": 3e9}, "m", 2.8e5, "infinite")
    '12.25 m .. infinite'
    >>> radius_text({"min": 12.25, "max": 73548.6}, "m", 2.8e5, "infinite")
    '12.25 .. 73549 m'
    >>> radius_text({"min": 97.0512, "max": 97.0498}, "m", 2.8e5, "infinite")
    '97.05 m'
    >>> radius_text(2e11, "m", 1e5, "infinite"), radius_text(None, "mm", 1e8, "infinite (straight)")
    ('infinite', 'infinite (straight)')
    """
    def big(v):
        return v is None or not math.isfinite(v) or abs(v) > beyond

    def text(v):          # 4 significant digits, but no exponent for a large radius
        return f"{v:.0f}" if v >= 1e4 else html.format_value(v)

    if not isinstance(r, dict):
        return infinite if r is None or big(r) else f"{text(abs(r))} {unit}"
    lo, hi = sorted((r["min"], r["max"]), key=lambda v: (big(v), abs(v)))
    if big(lo):
        return infinite
    if big(hi):
        return f"{text(abs(lo))} {unit} .. {infinite}"
    if text(abs(lo)) == text(abs(hi)):
        return f"{text(abs(lo))} {unit}"
    return f"{text(abs(lo))} .. {text(abs(hi))} {unit}"


def _meusnier_text(result: StudyResult, r) -> str:
    return radius_text(r, result.study.design.units, INFINITE_RADIUS_FACTOR * result.design_size,
                       "infinite (planar stars)")


def _strip_radius_text(result: StudyResult, r) -> str:
    beyond = INFINITE_RADIUS_FACTOR * result.design_size * result.study.design.mm_per_unit
    return radius_text(r, "mm", beyond, "infinite (straight)")


#: How the comparison table is ordered (`fabplan.study.ranking.rank_candidates`).
RANK_RULE = ("Rank: the candidates that meet every limit (feasible) come first, cheapest "
              "first; then those that break a limit (red rows), those breaking fewer limits "
              "first, cheapest first among equals. So a cheaper candidate that breaks a limit "
              "ranks below a dearer one that meets them all.")


def limit_text(key: str, value) -> tuple[str, str]:
    """The human name of a limit and its value with its unit.

    Examples
    --------
    >>> limit_text("max_deviation_mm", 40.0)
    ('largest deviation from the design', '40 mm')
    >>> limit_text("min_coverage", 0.95)[1], limit_text("max_molds", 1)[1]
    ('95 %', '1 mold')
    >>> limit_text("mold_tolerance_mm", (0.5, 1.0))[1]        # a sweep's values
    '0.5, 1 mm'
    """
    name, unit = LIMIT_NAMES.get(key, (key.replace("_", " "), ""))
    if isinstance(value, tuple):
        return name, f"{', '.join(html.format_value(v) for v in value)} {unit}".strip()
    if isinstance(value, bool):
        return name, "yes" if value else "no"
    if unit == "%":
        return name, f"{100 * value:g} %"
    if unit in ("molds", "sheets"):
        return name, counted(int(value), unit[:-1])
    return name, f"{html.format_value(value)} {unit}".strip()


def sharpest_turn(result: StudyResult) -> CandidateResult | None:
    """The recommended candidate (else the first measured one) when its lines' largest
    turn was measured, else None."""
    measured = [c for c in result.ranked() if not c.failed and c.net is not None]
    best = next((c for c in measured if c.name == result.recommended), None)
    c = best or (measured[0] if measured else None)
    if c is None or c.net is None:
        return None
    turn = ((c.net.properties.get("fairness") or {}).get("line_turn_deg") or {})
    return None if turn.get("point") is None or turn.get("max") is None else c


def kink_text(result: StudyResult) -> str:
    """Where the sharpest turn of the lines lies, and whether the design forces it (near
    an umbilic) or the layout does (`fabplan.layout.picture.kink_text`)."""
    c = sharpest_turn(result)
    if c is None or c.net is None:
        return ""
    return layout_kink_text(result.design, result.study.panel_size_of(c.candidate),
                            c.net.properties, name=c.name, units=result.study.design.units)


def pareto_text(result: StudyResult) -> str:
    """The Pareto-optimal candidates in words, and whether the recommended one is one."""
    optimal = [c.name for c in result.ranked() if c.pareto]
    text = (f"Pareto-optimal: {', '.join(optimal)}." if optimal else "")
    best = next((c for c in result.candidates if c.name == result.recommended), None)
    if best is not None and not best.pareto:
        text += (f" The recommended {best.name} is not among them: the cost also counts "
                 "panels by type and weighs the drivers, and a cheaper point may break a "
                 "limit.")
    return text.strip()


def _rounded(value: float | None, digits: int) -> html.Cell | str:
    """A number shown to `digits` decimals that sorts by its full value."""
    return "" if value is None else html.Cell(f"{value:.{digits}f}", value)


def comparison_table(result: StudyResult) -> str:
    """All candidates, sortable by any column; a sweep's panel size and mold tolerance
    get columns of their own."""
    rows: list[list[object]] = []
    bad: list[int] = []
    study = result.study
    units = study.design.units
    swept = study.swept
    for c in result.ranked():
        m = c.metrics
        asked = ([study.panel_size_of(c.candidate)] if "panel_size" in swept else []) + \
            ([study.mold_tolerance_of(c.candidate)]
             if "mold_tolerance_mm" in swept else [])
        if c.failed:
            rows.append(["", c.name, c.candidate.describe(), *asked, "failed",
                         *[""] * 13, c.reasons[0]])
            bad.append(len(rows) - 1)
            continue
        s = m["strips"]
        rows.append([
            c.rank, c.name, c.candidate.describe(), *asked, "yes" if c.feasible else "no",
            m["molds"]["count"] if m["molds"]["count"] else
            ("none (all flat)" if every_panel_flat(m["molds"]) else "none (none molded)"),
            m["molds"].get("saved", ""), m["panels"],
            (m.get("boundary_panels") or {}).get("count", 0),
            _rounded(100 * m["coverage"], 1), _rounded(m["largest_deviation_mm"], 1),
            _rounded(m["planarity_mm"]["max"], 2), _rounded(m["kink_deg"]["max"], 2),
            _fmt_range(m["intersection_angle_deg"]),
            _meusnier_text(result, m["meusnier_radius"]) if m["meusnier_radius"] else "",
            "" if s is None else f"{s['sheets']}{' (congruent)' if s['congruent'] else ''}",
            _rounded(c.cost, 0), "yes" if c.pareto else "",
            f"the same net as {c.same_net_as}" if c.same_net_as else ""])
        if not c.feasible:
            bad.append(len(rows) - 1)
    asked_columns = ([f"panel size [{units}]"] if "panel_size" in swept else []) + \
        (["mold tolerance [mm]"] if "mold_tolerance_mm" in swept else [])
    return html.html_table(
        ["rank", "candidate", "net", *asked_columns, "feasible", "molds [count]",
         "molds saved by the material [count]", "panels [count]",
         "of them boundary panels [count]", "design covered [%]",
         "max deviation [mm]", "planarity [mm]", "max kink [deg]", "angle [deg]",
         f"Meusnier radius [{units}]", "strip sheets [count]", "cost [cost units]",
         "Pareto-optimal", "note"], rows,
        caption="All candidates, best first (click a column's header to sort by it). "
        + RANK_RULE, bad_rows=bad, hide_empty=True, sortable=True)


def limits_table(result: StudyResult) -> str:
    rows = [list(limit_text(k, v)) for k, v in limit_items(result)]
    return html.html_table(["limit", "value"], rows, caption="Fabrication limits")


def cost_table(result: StudyResult) -> str:
    from dataclasses import asdict

    names = {"mold": "mold", "flat_panel": "flat panel", "single_curved_panel":
             "single curved panel", "double_curved_panel": "double curved panel",
             "sheet": "sheet of strip material", "deviation_mm": "mm of largest deviation"}
    rows = [[names.get(k, k.replace("_", " ")), html.format_value(v)]
            for k, v in asdict(result.study.cost).items()]
    return html.html_table(["per", "weight [cost units]"], rows,
                           caption="Cost weights (cost units are relative prices: by default a "
                                   "flat panel costs 1, a mold 100; give them in a currency in "
                                   "the study file to read costs in it)")


def _coverage_text(coverage: float, full: float | None = None) -> str:
    """The share of the design the panels cover, and what the rest means for the counts."""
    text = f"{100 * coverage:.2f} % of the design's area"
    if full is not None and full < coverage:
        text += f" ({100 * full:.1f} % by full panels, the rest by boundary panels)"
    if coverage < 0.999:
        text += (f": {100 * (1 - coverage):.1f} % is left unclad; the panel, mold and sheet "
                 "counts leave it out, the cost charges its panels (the panel terms divided by "
                 "the covered share)")
    return text


def _boundary_text(boundary: dict | None) -> str:
    """The boundary panels of a candidate: how many, and on which molds."""
    if not boundary or not boundary["count"]:
        return ""
    own = boundary["own_molds"]
    flat = boundary.get("flat") or 0
    if flat == boundary["count"]:
        how = "all flat (no molds), placed to meet their neighbours"
    else:
        # those on molds of their own are said after the steps: "each" would not hold
        each = "each" if not own else "the others"
        how = f"{each} cut from a mold of the net's panels and placed to meet its neighbours"
        if flat:
            how += f" ({flat} of them flat)"
    text = f"; and {counted(boundary['count'], 'boundary panel')} trimmed to the design boundary"
    if own:
        text += f", {counted(own, 'on a mold of its own', 'on molds of their own')}"
    text += f", {how}"
    if boundary.get("step_max_mm") is not None:
        text += f" (steps up to {boundary['step_max_mm']:.2f} mm"
        if boundary.get("deviation_max_mm") is not None:
            text += f", up to {boundary['deviation_max_mm']:.1f} mm from the design"
        text += ")"
    if boundary.get("flipped"):
        text += f"; {counted(boundary['flipped'], 'boundary panel')} facing against the design"
    return text


def _turn_text(turn: dict | None) -> str:
    """How much the net's lines turn within the surface, and where the most."""
    if not turn or turn.get("max") is None:
        return "-"
    return (f"up to {turn['max']:.2f} deg at vertex {turn['vertex']} (median {turn['median']:.2f}, "
            f"95 % below {turn['p95']:.2f} deg)")


def _folds_text(folds: dict | None) -> str:
    if not folds:
        return "-"
    counts = [(folds["flipped_faces"], "flipped face"), (folds["fold_edges"], "fold edge"),
              (folds["degenerate_stars"], "degenerate star"),
              (folds["collapsed_edges"], "collapsed edge")]
    found = [counted(n, what) for n, what in counts if n]
    return ", ".join(found) if found else "none (no flipped face, fold, degenerate star or " \
                                         "collapsed edge)"


def cost_line(result: StudyResult) -> str:
    """How the cost is made up, in words (as charged in this study)."""
    measured = [c for c in result.candidates if not c.failed]
    with_strips = [c for c in measured if c.metrics.get("strips")]
    material = result.study.material
    text = ("Cost = the weights times the molds (of the curved panels: flat panels need "
            "none), the panels by type, " if material is None else
            f"Cost = the weights times the molds (of the molded panels: in {material.label} "
            "flat, cold-bent and roll-bent panels need none), the panels by class (the "
            "molded ones by type), ")
    if result.sheets_charged:
        text += "the strip sheets "
    text += "and the largest deviation in mm; feasible candidates rank first, by cost."
    if with_strips and not result.sheets_charged:
        text += (f" Strip sheets are reported but not charged: only {len(with_strips)} of "
                 f"{len(measured)} candidates {'gets' if len(with_strips) == 1 else 'get'} "
                 "strips, and charging them would make those "
                 "look dearer than candidates that were not asked for strips.")
    return text


def _check_value(key: str, value) -> str:
    if value is None or isinstance(value, str):
        return html.format_value(value)
    if key == "congruent_strips":        # its bound is the congruence tolerance
        return f"{html.format_value(value)} mm"
    return limit_text(key, value)[1]


def check_rows(c: CandidateResult) -> list[list]:
    return [[limit_text(ck["limit"], ck["bound"])[0], _measured(ck),
             _check_value(ck["limit"], ck["bound"]), "yes" if ck["ok"] else "NO", ck["text"]]
            for ck in c.checks]


def _measured(check: dict) -> str:
    """A check's measured value; a solve's residual within its bound, failed because the
    solve gave no buildable net (no margin to rate: `fabplan.study.checks.check`), says so
    beside the number."""
    value = _check_value(check["limit"], check["measured"])
    if check["limit"] == "max_sphere_residual" and not check["ok"] and check["margin"] is None:
        value += " (no buildable net)"
    return value


def _solved_on(c: CandidateResult, study) -> str:
    """Where a net that leaves the design was solved, and why not past the design's edges
    where it was not (docs/study-file.md): "" for a net on the design, or a candidate
    measured before this was recorded."""
    from ..solve.net_types import get_net
    from .ranking import is_lamella_study

    continued = c.metrics.get("continued")
    if c.candidate.glides or continued is None:
        return ""
    if continued:
        return "; solved on the design continued past its edges"
    why = ("a lamella study: its strips end on the net's own tips" if is_lamella_study(study)
           else "flat panels are cut in the planes of the net's sides"
           if get_net(c.candidate.net).planar_faces
           else "this design is not continued past its edges: a mesh file, a trimmed NURBS "
                "face, or a formula that breaks down there")
    return f"; solved on the design alone ({why})"


def candidate_facts(c: CandidateResult, result: StudyResult) -> tuple[str, list[list]]:
    """The verdict of a measured candidate and its "quantity, value" rows."""
    m = c.metrics
    units = result.study.design.units
    verdict = ("Feasible: " if c.feasible else "Not feasible: ") + "; ".join(c.reasons) + "."
    if not c.feasible:
        relax = feasible_with(c.checks)
        check = result.relaxation_check
        if relax and check is not None and check["candidate"] == c.name:
            relax += " " + check["text"]        # the relaxation run, as the recommendation says
        # beside a relaxation, the other ways (a panel size named); without one (a solve
        # that did not converge) what to try
        steps = next_steps(c.checks)
        verdict += relax + (f" {'Other ways' if relax else 'To try'}: " + "; ".join(steps) + "."
                            if steps else "")
    if c.notes:
        verdict += " Note: " + "; ".join(c.notes) + "."
    types = m["molds"]["panel_types"]
    parameters = []
    for k, v in m["parameters"].items():
        if not isinstance(v, float):
            continue
        parameters.append(f"radius {_meusnier_text(result, v)}" if k == "radius" else
                          f"angle {v:.6g} deg" if k == "angle_deg" else f"{k} {v:.6g}")
    molds = m["molds"]
    facts = [
        ["net", c.candidate.describe()],
        ["solve", f"{m['status']} after {m['iterations']} iterations"
                  + (f" ({m['status_note']})" if m.get("status_note") else "")
                  + _solved_on(c, result.study)],
        ["solved parameters", ", ".join(parameters) or "-"],
        ["panels", f"{m['panels']}: {m['quads']} quads, {m['other_faces']} other "
                   f"({m['irregular_vertices']} irregular vertices)"
                   + _boundary_text(m.get("boundary_panels"))],
        ["panel types", ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in types.items())],
        ["design covered", _coverage_text(m["coverage"], m.get("coverage_net"))],
        ["line turns", _turn_text(m.get("line_turn_deg"))],
        ["folds", _folds_text(m.get("folds"))],
        ["edge length", _fmt_range(m["edge_length"], units)],
        ["panel area", _fmt_range(m["panel_area"], f"{units}^2")],
        ["Meusnier radius", _meusnier_text(result, m["meusnier_radius"])
         if m["meusnier_radius"] else "-"],
        ["deviation from the design [mm]",
         f"largest {m['largest_deviation_mm']:.2f} (the net and its boundary panels as built); "
         f"the net's vertices: max {m['deviation_mm']['max']:.2f}, mean "
         f"{m['deviation_mm']['mean']:.2f}, 95 % {m['deviation_mm']['p95']:.2f}"],
        *([["panel classes (material)", material_sentence(molds)]]
          if molds.get("panel_classes") is not None else []),
        ["molds", (molds_text(molds) if molds["count"] == 0 else
                   f"{molds_text(molds)} for the "
                   f"{'molded' if molds.get('panel_classes') is not None else 'curved'} panels "
                   f"({molds['molds_per_sqrt_panels']:.2f} x sqrt of the panel count)")
         + f"; largest gap of a panel to its mold (flat panels: to a plane) "
           f"{molds['max_deviation_mm']:.2f} mm"],
        ["sphere residual (largest, of the mean edge length)",
         f"{html.format_value(m['sphere_residual_relative_max'])} of an edge"],
        ["intersection angle", _fmt_range(m["intersection_angle_deg"], "deg") or "-"],
        ["run time", ", ".join(f"{k} {v:.1f} s" for k, v in m["seconds"].items())],
    ]
    if m["strips"]:
        s = m["strips"]
        shape = "all straight (so all congruent)" if s["straight"] else (
            f"arc radius {_strip_radius_text(result, s['radius_mm'])}; the parts differ from "
            f"one common arc by up to {s['congruence_deviation_mm']:.3g} mm"
            + (" (congruent)" if s["congruent"] else " (not congruent)"))
        facts.append(["strips", f"{counted(s['strips'], 'strip')}, {counted(s['parts'], 'part')} "
                      f"on {counted(s['sheets'], 'sheet')} ({100 * s['material_use']:.0f} % "
                      f"material use); {shape}"])
        if s.get("ends_at_boundary_member"):
            facts.append(["strip ends", _strip_ends_text(s)])
    return verdict, facts


def _strip_ends_text(s: dict) -> str:
    """Where the strips end: at the boundary member, and why the others are free."""
    kinds = s.get("ends_free_by_kind") or {}
    why = [f"{kinds[k]} {text}" for k, text in (
        ("inside", "inside the net at irregular vertices (node connectors)"),
        ("along edge", "along the edge"), ("not continued", "not continued to the edge"))
        if kinds.get(k)]
    return (f"{counted(s['ends_at_boundary_member'], 'end')} cut square against a "
            f"{s['boundary_member_mm']:g} mm boundary member at the edge of the cladding; "
            f"{s['ends_free']} free" + (f" ({', '.join(why)})" if why else ""))



def comparison_rows(result: StudyResult) -> tuple[list[str], list[list]]:
    """The comparison table for print: fewer, wider columns than the page's."""
    rows: list[list] = []
    for c in result.ranked():
        if c.failed:
            rows.append(["", c.name, "failed", "", "", "", "", c.reasons[0]])
            continue
        m = c.metrics
        rows.append([c.rank, c.name, "yes" if c.feasible else "no", m["molds"]["count"],
                     m["panels"], f"{m['largest_deviation_mm']:.1f}", f"{c.cost:.0f}",
                     c.candidate.describe()])
    return (["rank", "candidate", "feasible", "molds [count]", "panels [count]",
             "max deviation [mm]", "cost [cost units]", "net"], rows)



def limit_items(result: StudyResult) -> list[tuple[str, object]]:
    """The limits a study judges by, as its report lists them: those set, the step between
    neighbouring molds always (twice the mold tolerance unless set), the strips' twist
    only where a candidate has strips. A sweep of mold tolerances lists each (a tuple),
    and the step limit of each."""
    from dataclasses import asdict

    study = result.study
    limits = asdict(study.limits)
    limits["max_panel_step_mm"] = study.limits.panel_step_limit_mm
    swept = study.swept.get("mold_tolerance_mm")
    if swept:
        # each tolerance of the sweep, and the step limit each implies when not set
        limits["mold_tolerance_mm"] = tuple(swept)
        if study.limits.max_panel_step_mm is None:
            limits["max_panel_step_mm"] = tuple(2.0 * t for t in swept)
    if not any(c.metrics.get("strips") for c in result.candidates if not c.failed):
        del limits["max_twist_deg_per_m"]
    if not limits["planar_panels"]:
        del limits["planarity_tolerance_mm"]
    if not limits["congruent_strips"]:
        del limits["congruence_tolerance_mm"]
    return [(k, v) for k, v in limits.items() if v is not None and v is not False]
