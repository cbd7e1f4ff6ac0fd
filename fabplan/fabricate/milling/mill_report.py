"""A milling run and its files: ``path.cl``, ``path.csv``, ``mill.json`` and ``report.html``.

`mill_net` plans the curvature-adaptive passes (`fabplan.fabricate.milling`), builds the
target height map, simulates the planned cut and the conventional one (a ball end of the
same diameter normal to the surface through the same contact points) with
`fabplan.fabricate.milling.mill_simulation`, and keeps the evidence side by side. The target is the
design the net was made for when one is given (`fabplan.fabricate.milling.mill_design`): the cut
is measured against it, and against the net's own surface apart, with the net's distance
from the design; without one it is the net's surface.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ...errors import InputError
from ...io.cldata import cldata_text
from ...io.output import output_folder, write_texts
from ...io.records import json_text
from ...io.rhino_write import Rhino3dmWriter
from ...net.mesh import QuadMesh
from ...report import figures, html
from ..limits import LimitCheck, limit_check, limit_row_label, limit_row_text
from .face_milling import plan_face_milling
from .flank_milling import plan_flank_milling
from .mill_design import NetDistance, design_heights, mesh_faceting_mm, net_distance_from_design
from .mill_plan import MillPlan, MillSettings, MillTool, every_kth
from .mill_simulation import (
    Cutter,
    HeightTarget,
    SimulationResult,
    SimulationSettings,
    ball_end_path,
    height_target,
    measure_cut,
    simulate_milling,
)

__all__ = ["MillResult", "mill_net", "mill_report_html", "mill_report_files", "write_mill_report",
           "MILL_FILES"]

MILL_FILES = ("path.cl", "path.csv", "mill.json", "report.html")


@dataclass
class MillResult:
    """A plan with its simulated cut and the conventional comparison.

    Attributes
    ----------
    plan : the passes.
    target : the target height map (None without simulation): the design's heights when
        a design is given, else the net's surface (`height_target`: its star vertices'
        best-fit sphere and the spline through their departures from it).
    simulation : the simulated adaptive cut, measured against `target` (None without
        simulation).
    conventional : the simulated ball-end cut through the same contacts (or None).
    simulation_settings : resolution used.
    seconds : time per stage.
    design : name of the design measured against (None: the net's surface).
    against_net : with a design, the same adaptive cut measured against the net's surface.
    net_distance : with a design, the net's distance from it.
    design_faceting_mm : with a design given as a triangle mesh, about how far its flat
        faces stand off a smooth surface through its vertices (`mesh_faceting_mm`); None
        for an exact design or none.
    """

    plan: MillPlan
    target: HeightTarget | None
    simulation: SimulationResult | None
    conventional: SimulationResult | None
    simulation_settings: SimulationSettings
    seconds: dict = field(default_factory=dict)
    design: str | None = None
    against_net: SimulationResult | None = None
    net_distance: NetDistance | None = None
    design_faceting_mm: float | None = None

    @property
    def measured_against(self) -> str:
        """What the cut is measured against, in words."""
        if self.design is None:
            return ("the net's surface (its best-fit sphere and the spline through its vertices; "
                    "no design given)")
        return f"the design {self.design}"

    @property
    def gouge_free(self) -> bool:
        """True when the simulated cut stays above the target within the gouge tolerance
        (and when nothing was simulated)."""
        sim = self.simulation
        return sim is None or sim.max_gouge_mm <= self.simulation_settings.gouge_tolerance_mm

    @property
    def scallop_check(self) -> LimitCheck:
        """The scallop limit (``--scallop``): the simulated scallop of every strip between
        neighbouring passes, else the predicted scallop beside every pass node."""
        bound = self.plan.settings.scallop_mm
        sim = self.simulation
        if sim is not None and self.against_net is not None and self.plan.placed_on == "net":
            sim = self.against_net     # passes on the net: its offset from the design is no scallop
        if sim is not None:
            check = limit_check("max_scallop_mm", sim.scallop_by_strip_mm, bound,
                                parts="strips between passes")
            if check.measured:
                return check
        return limit_check("max_scallop_mm", self.plan.scallop_by_node_mm, bound,
                           parts="pass nodes (predicted)")

    def record(self) -> dict:
        """The contents of ``mill.json``."""
        record = self.plan.record()
        record["limits"] = {"max_scallop_mm": self.scallop_check.to_json()}
        sim, conv = self.simulation, self.conventional
        settings = self.simulation_settings
        record["simulation_settings"] = {
            "step_mm": settings.step_mm, "pose_spacing_mm": settings.pose_spacing_mm,
            "golden_rounds": settings.golden_rounds, "body_mm": settings.body_mm,
            "end_trim_mm": settings.end_trim_mm}
        record["target"] = {"surface": "net" if self.design is None else "design",
                            "design": self.design, "measured_against": self.measured_against,
                            "design_faceting_mm": self.design_faceting_mm, "units": "mm"}
        if self.net_distance is not None:
            record["net_from_design"] = self.net_distance.to_json()
        if sim is not None:
            predicted = self.plan.predicted_max_scallop_mm
            record["simulation"] = sim.record()
            record["gouge_check"] = {"tolerance_mm": settings.gouge_tolerance_mm,
                                     "max_gouge_mm": sim.max_gouge_mm,
                                     "measured_against": record["target"]["surface"],
                                     "passed": self.gouge_free}
            if self.against_net is not None:
                net = self.against_net
                record["against_net"] = {"units": "mm", "max_scallop_mm": net.max_scallop_mm,
                                         "max_gouge_mm": net.max_gouge_mm,
                                         "gouge_cells": net.gouge_cells}
            record["scallop_simulated_over_predicted"] = (
                sim.max_scallop_mm / predicted if 0 < predicted < np.inf else None)
        if conv is not None and sim is not None:
            record["conventional"] = {
                "tool": f"ball end D={self.plan.tool.diameter_mm:g} mm, axis along the normal",
                "passes": self.plan.path.pass_count, **conv.record()}
            record["comparison"] = {
                "adaptive_max_scallop_mm": sim.max_scallop_mm,
                "conventional_max_scallop_mm": conv.max_scallop_mm,
                "scallop_ratio": conv.max_scallop_mm / sim.max_scallop_mm,
                "adaptive_median_scallop_mm": _median_between(sim),
                "conventional_median_scallop_mm": _median_between(conv)}
        record["seconds"] = dict(self.seconds)
        return record

    def summary(self) -> str:
        lines = [self.plan.summary()]
        tries = self.plan.margin_tries
        if tries:
            lines.append("margins tried in simulation, the rule's first: " + ", ".join(
                f"{m:.4g} mm gouging {g:.3g} mm" for m, g in tries)
                + f"; kept {self.plan.margin_mm:.4g} mm")
        sim, conv = self.simulation, self.conventional
        distance = self.net_distance
        if distance is not None:
            lines.append(f"the net is up to {distance.vertex_max_mm:.4g} mm off the design "
                         f"{self.design} (vertices; mean {distance.vertex_mean_mm:.4g} mm); the "
                         f"passes are placed on the {self.plan.placed_on}")
        if sim is not None:
            against = "the net's surface" if self.design is None else "the design"
            lines.append(f"simulated against {against}: scallop {sim.max_scallop_mm:.4g} mm "
                         f"(predicted {self.plan.predicted_max_scallop_mm:.4g}), gouge "
                         f"{sim.max_gouge_mm:.4g} mm "
                         f"({'within' if self.gouge_free else 'BEYOND'} "
                         f"{self.simulation_settings.gouge_tolerance_mm:g} mm), {sim.seconds:.1f} s")
        if self.against_net is not None:
            lines.append(f"the same cut against the net's surface: scallop "
                         f"{self.against_net.max_scallop_mm:.4g} mm, gouge "
                         f"{self.against_net.max_gouge_mm:.4g} mm")
        if sim is not None and conv is not None:
            lines.append(f"conventional ball end, same passes: scallop {conv.max_scallop_mm:.4g} mm "
                         f"({conv.max_scallop_mm / sim.max_scallop_mm:.1f} x)")
        return "\n".join(lines)


def _median_between(sim: SimulationResult) -> float:
    values = sim.left[sim.between]
    values = values[np.isfinite(values)]
    return float(np.median(values)) if values.size else float("nan")


def mill_net(mesh: QuadMesh, tool: MillTool, settings: MillSettings, *, simulate: bool = True,
             simulation: SimulationSettings | None = None, conventional: bool = True,
             design: Any = None) -> MillResult:
    """Plan face milling on an S-net, or flank milling with a cone on an S*-net, and check
    it by simulation.

    Parameters
    ----------
    mesh : the net.
    tool, settings : see `plan_face_milling` and `plan_flank_milling` (for a cone).
    simulate : run the simulation. The target is the design's heights when `design` is
        given, else the net's surface through its star vertices (`height_target`), on a grid seen from
        the mean tool-side normal over the part the net's faces cover.
    simulation : its resolution.
    conventional : also simulate the conventional ball-end path (face mills only).
    design : the `fabplan.design.DesignSurface` the net was made for (the net's model
        units), or None. With it the passes are placed on the design
        (``settings.paths_on``), the cut is measured against it, and against the net's
        surface apart, and the net's distance from it is measured.

    Returns
    -------
    MillResult
    """
    sim_settings = simulation or SimulationSettings()
    started = time.perf_counter()
    cone = tool.kind == "cone"
    planner = plan_flank_milling if cone else plan_face_milling
    plan = planner(mesh, tool, settings, design=design)
    seconds = {"plan": plan.seconds}
    target = adaptive = ball = against_net = None
    scale = settings.mm_per_unit
    net_target = None
    faceting = None
    if design is not None and not getattr(design, "exact", False):
        faceting = mesh_faceting_mm(design.vertices, design.triangles, scale)
    if simulate:
        clock = time.perf_counter()
        path = plan.path
        net_target = target = _net_target(mesh, path.normal.mean(axis=0), scale,
                                          sim_settings.step_mm)
        if design is not None:
            target = replace(net_target, z=design_heights(design, net_target, scale))
        seconds["target"] = time.perf_counter() - clock
        cutter = _cutter(tool, sim_settings)
        adaptive = simulate_milling(target, cutter, path.tip, path.axis, path.contact,
                                    path.pass_id, sim_settings)
        seconds["simulate"] = adaptive.seconds
        if not cone and _rule_gouges(settings, plan, adaptive, sim_settings, design, faceting):
            plan, adaptive, seconds["margin_tries"] = _gouge_free_margin(
                mesh, tool, settings, design, plan, adaptive, (target, cutter, sim_settings))
            path = plan.path
        if design is not None and adaptive.strip is not None:
            against_net = measure_cut(adaptive.cut, net_target.z, adaptive.strip,
                                      len(adaptive.scallop_by_strip_mm),
                                      sim_settings.gouge_tolerance_mm)
        if conventional and not cone:
            tips, axes = ball_end_path(path.contact, path.normal, tool.radius_mm)
            ball_cutter = Cutter("ball", tool.radius_mm,
                                 tool.radius_mm + min(tool.body_length_mm, sim_settings.body_mm))
            ball = simulate_milling(target, ball_cutter, tips, axes, path.contact, path.pass_id,
                                    sim_settings)
            seconds["conventional"] = ball.seconds
    distance = None
    if design is not None:
        clock = time.perf_counter()
        distance = net_distance_from_design(
            design, mesh.vertices * scale, scale, None if net_target is None else net_target.z,
            None if target is None else target.z)
        seconds["design_distance"] = time.perf_counter() - clock
        if distance.coverage is not None and distance.coverage < 0.99:
            plan.notes.append(
                f"the design reaches only {100 * distance.coverage:.1f} % of the part the net's "
                "faces cover, seen from the mill direction: the rest is not measured (is it the "
                "net's design, in the net's units?)")
    seconds["total"] = time.perf_counter() - started
    return MillResult(plan=plan, target=target, simulation=adaptive, conventional=ball,
                      simulation_settings=sim_settings, seconds=seconds,
                      design=None if design is None else design_label(design),
                      against_net=against_net, net_distance=distance, design_faceting_mm=faceting)


def _cutter(tool: MillTool, simulation: SimulationSettings) -> Cutter:
    """The tool as the simulation cuts with it: a cone's whole flank, a face mill's end."""
    if tool.kind == "cone":
        return Cutter("cone", tool.radius_mm, tool.length_mm, angle_deg=tool.angle_deg)
    return Cutter("flat", tool.radius_mm, min(tool.body_length_mm, simulation.body_mm),
                  tool.corner_mm)


#: plans and simulations of a face mill's margin raised past its rule's, at most
MARGIN_TRIES = 4
#: the first margin tried past the rule's: this factor of it, plus `MARGIN_STEP_SHARE` of
#: the largest finite Meusnier radius (a rule's margin of 0 on an umbilic part)
MARGIN_FIRST_FACTOR = 1.25
MARGIN_STEP_SHARE = 0.001


def _rule_gouges(settings: MillSettings, plan: MillPlan, cut: SimulationResult,
                 simulation: SimulationSettings, design: Any, faceting: float | None) -> bool:
    """Whether the margin rule's own cut gouges its target, where neither the design's
    facets nor passes on a net off it explain the gouge (`fabplan.cli.mill` says those)."""
    return (settings.margin_mm is None and cut.max_gouge_mm > simulation.gouge_tolerance_mm
            and (design is None or plan.placed_on == "design")
            and not (faceting is not None and cut.max_gouge_mm <= 2 * faceting))


#: a gouge that shrinks by less than this factor from one margin tried to the next is no
#: longer the margin's: the tool's face is wider than the surface allows, or a faceted design
MARGIN_PLATEAU = 0.8


def _gouge_free_margin(mesh: QuadMesh, tool: MillTool, settings: MillSettings, design: Any,
                       plan: MillPlan, cut: SimulationResult, simulation: tuple
                       ) -> tuple[MillPlan, SimulationResult, float]:
    """A face mill's plan at a margin larger than its rule's, where the rule's cut gouges
    the target in simulation: the rule takes the curvature at the net's nodes, and the
    surface between and beyond them may curve more (a torus part of 147 mm took a margin of
    87 mm where the rule gave 69 mm). The margin is raised by a quarter
    (`MARGIN_FIRST_FACTOR`), then by the secant of the logarithm of the gouge, aiming at
    half the gouge tolerance, at most `MARGIN_TRIES` times, and no more once the gouge
    stops shrinking (`MARGIN_PLATEAU`). The first plan whose cut keeps within the
    tolerance is kept, else the least gouging tried, with a note; its `margin_tries` and
    rule say so. Returns the plan, its cut and the seconds the tries took.
    """
    target, cutter, sim = simulation
    tolerance = sim.gouge_tolerance_mm
    started = time.perf_counter()
    tried = [(plan.margin_mm, cut.max_gouge_mm)]
    best = (plan, cut)
    radius = plan.meusnier_radius_mm[np.isfinite(plan.meusnier_radius_mm)]
    margin = MARGIN_FIRST_FACTOR * plan.margin_mm + MARGIN_STEP_SHARE * float(radius.max(initial=0.0))
    why = f"raising it {MARGIN_TRIES} times did not keep the cut within the gouge tolerance"
    for _ in range(MARGIN_TRIES):
        try:
            again = plan_face_milling(mesh, tool, replace(settings, margin_mm=margin),
                                      design=design)
        except InputError:
            why = f"no safety sphere is left at a margin of {margin:.4g} mm"
            break
        path = again.path
        result = simulate_milling(target, cutter, path.tip, path.axis, path.contact,
                                  path.pass_id, sim)
        tried.append((margin, result.max_gouge_mm))
        if result.max_gouge_mm < MARGIN_PLATEAU * best[1].max_gouge_mm \
                or result.max_gouge_mm <= tolerance:
            best = (again, result)           # a smaller margin where the gouge is the same
        if result.max_gouge_mm <= tolerance:
            break
        (m0, g0), (m1, g1) = tried[-2:]
        if g1 > MARGIN_PLATEAU * g0:
            why = ("the gouge no longer shrinks with the margin: the tool's face is wider than "
                   "the surface's curvature allows, or the design is faceted")
            break
        slope = (np.log(g1) - np.log(g0)) / (m1 - m0) if g0 > 0 and g1 > 0 and m1 != m0 else 0.0
        step = np.log(tolerance / 2 / g1) / slope if slope < 0 else 0.25 * m1
        margin = m1 + float(np.clip(step, 0.05 * m1, 0.5 * m1))
    kept, kept_cut = best
    said = ", ".join(f"{m:.4g} mm gouged by {g:.3g} mm" for m, g in tried if m != kept.margin_mm)
    if kept is not plan:
        within = kept_cut.max_gouge_mm <= tolerance
        kept = replace(kept, margin_tries=tuple(tried), margin_rule=(
            f"{plan.margin_rule}; raised in simulation ({said}) to {kept.margin_mm:.4g} mm, "
            + ("the first tried that keeps the cut within the gouge tolerance" if within else
               f"the least gouging tried ({kept_cut.max_gouge_mm:.3g} mm)")))
    else:
        kept = replace(plan, margin_tries=tuple(tried))
    if kept_cut.max_gouge_mm > tolerance:
        every = ", ".join(f"{m:.4g} mm gouged by {g:.3g} mm" for m, g in tried)
        kept.notes.append(f"the margin rule's cut gouges, and raising the margin did not keep it "
                          f"within the gouge tolerance ({why}; tried {every}; kept "
                          f"{kept.margin_mm:.4g} mm)")
    return kept, kept_cut, time.perf_counter() - started


def _net_target(mesh: QuadMesh, up: np.ndarray, scale: float, step_mm: float) -> HeightTarget:
    """The net's surface seen from `up` as a height map (`height_target`, mm). A vertex in
    no star (a grid's corner) is bound by no sphere: it outlines the part but does not
    shape the target."""
    in_star = np.zeros(len(mesh.vertices), bool)
    in_star[mesh.stars.ravel()] = True
    return height_target(mesh.vertices * scale, mesh.triangles(), up, step_mm=step_mm,
                         samples=in_star)


def design_label(design: Any) -> str:
    """The design as the record names it: its built-in surface spec with its parameters,
    else its file (or Rhino source)."""
    from ...design.parametric import spec_of_surface

    parametric = getattr(design, "parametric", None)
    spec = spec_of_surface(parametric) if parametric is not None else None
    return spec or str(getattr(design, "name", "the design"))


# ------------------------------------------------------------------------------ pictures
def _paths_figure(result: MillResult) -> str:
    plan, target = result.plan, result.target
    fig = figures.new_figure((7.5, 6.5))
    ax = fig.add_subplot(1, 1, 1)
    path = plan.path
    if target is not None:
        C = target.to_frame(path.contact)
        T = target.to_frame(path.tip)
        image = ax.imshow(target.z, origin="lower", cmap="Greys", alpha=0.6,
                          extent=(target.x[0], target.x[-1], target.y[0], target.y[-1]))
        fig.colorbar(image, ax=ax, shrink=0.7, label="target height in the mill frame [mm]")
    else:
        C, T = path.contact, path.tip
    colors = figures.distinct_colors(path.pass_count)
    for number, part in enumerate(path.pass_slices()):
        ax.plot(C[part, 0], C[part, 1], "-", color=colors[number], lw=1.5)
        ax.plot(T[part, 0], T[part, 1], ":", color=colors[number], lw=0.8)
        ax.annotate(str(number + 1), (float(C[part][0, 0]), float(C[part][0, 1])), fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title("contact paths (solid) and tool tips (dotted), seen along the mill direction")
    return figures.figure_to_data_uri(fig)


def _scallop_figure(result: MillResult) -> str:
    target = result.target
    assert target is not None
    runs = [("curvature adaptive", result.simulation)]
    if result.conventional is not None:
        runs.append(("conventional ball end", result.conventional))
    fig = figures.new_figure((6.0 * len(runs), 5.2))
    extent = (target.x[0], target.x[-1], target.y[0], target.y[-1])
    for i, (title, sim) in enumerate(runs):
        assert sim is not None
        ax = fig.add_subplot(1, len(runs), i + 1)
        left = np.where(np.isfinite(sim.left), sim.left * 1000, np.nan)
        top = np.nanpercentile(left[sim.between], 99.5) if sim.between.any() else 1.0
        image = ax.imshow(left, origin="lower", cmap="viridis", extent=extent, vmin=min(0, np.nanmin(left)),
                          vmax=max(top, 1e-3))
        fig.colorbar(image, ax=ax, shrink=0.75, label="cut above target [um]")
        ax.set_title(f"{title}: max scallop {sim.max_scallop_mm * 1000:.2f} um")
        ax.set_aspect("equal")
    return figures.figure_to_data_uri(fig)


def _tilt_figure(result: MillResult) -> str:
    path = result.plan.path
    fig = figures.new_figure((8.0, 3.6))
    ax = fig.add_subplot(1, 1, 1)
    for number, part in enumerate(path.pass_slices()):
        arc = np.r_[0, np.cumsum(np.linalg.norm(np.diff(path.contact[part], axis=0), axis=1))]
        ax.plot(arc, path.tilt_deg[part], lw=1, label=f"pass {number + 1}" if number < 12 else None)
    ax.set_xlabel("arc length along the pass [mm]")
    ax.set_ylabel("tilt from the normal [deg]")
    ax.legend(fontsize=6, ncol=4)
    ax.grid(alpha=0.3)
    return figures.figure_to_data_uri(fig)


def mill_report_html(result: MillResult) -> str:
    """The self-contained report page."""
    r = result.record()
    cone = result.plan.tool.kind == "cone"
    spheres = "mannheim_radius_mm" if cone else "meusnier_radius_mm"
    rows = [("tool", r["tool"]["spec"]), ("passes", f"{r['passes']} along family {r['along']} "
                                                    f"({every_kth(r['stride'], r['lines'])})"),
            ("margin [mm]", f"{r['margin_mm']:.4g} ({r['margin_rule']})"),
            ("tilt [deg]", f"{r['tilt_deg']['min']:.3f} .. {r['tilt_deg']['max']:.3f}"),
            (f"{'Mannheim' if cone else 'Meusnier'} radius [mm]",
             f"{r[spheres]['min']:.4g} .. {r[spheres]['max']:.4g}"),
            ("path length [mm]", f"{r['path_length_mm']:.1f}"),
            ("cutter locations", r["cutter_locations"]),
            ("predicted scallop [mm]", f"{r['predicted_scallop_mm']:.4g}")]
    if cone:
        rows += [("contact circle diameter [mm]", f"{r['contact_diameter_mm']['min']:.4g} .. "
                                                  f"{r['contact_diameter_mm']['max']:.4g}"),
                 ("ruling curvature [1/mm]", f"{r['ruling_curvature_per_mm']['min']:.3g} .. "
                                             f"{r['ruling_curvature_per_mm']['max']:.3g}")]
    parts = []
    rows.append(("measured against", r["target"]["measured_against"]))
    distance = r.get("net_from_design")
    if distance is not None:
        rows += [("passes placed on", f"the {r['paths']['placed_on']}"
                  + (f" (nodes moved up to {r['paths']['node_shift_from_net_mm']['max']:.4g} mm "
                     "from the net's vertices)" if r["paths"]["placed_on"] == "design" else "")),
                 ("net's vertices off the design [mm]", f"max {distance['vertex_max_mm']:.4g}, "
                  f"mean {distance['vertex_mean_mm']:.4g}")]
        if distance["measured_cells"]:
            rows.append(("net's surface above / below the design [mm]",
                         f"{distance['surface_above_design_max_mm']:.4g} / "
                         f"{distance['surface_below_design_max_mm']:.4g}"))
    if "simulation" in r:
        against = "" if distance is None else " against the design"
        rows += [(f"simulated scallop{against} [mm]", f"{r['simulation']['max_scallop_mm']:.4g}"),
                 (f"simulated gouge{against} [mm]", f"{r['gouge_check']['max_gouge_mm']:.4g} "
                  f"({'passed' if r['gouge_check']['passed'] else 'FAILED'}, tolerance "
                  f"{r['gouge_check']['tolerance_mm']:g})")]
    if "against_net" in r:
        rows += [("the same cut against the net's surface: scallop / gouge [mm]",
                  f"{r['against_net']['max_scallop_mm']:.4g} / "
                  f"{r['against_net']['max_gouge_mm']:.4g}")]
    rows += [(limit_row_label(c), limit_row_text(c)) for c in r["limits"].values()]
    parts.append(html.html_section("Summary", html.html_table(["quantity", "value"], rows)))
    if "comparison" in r:
        c = r["comparison"]
        parts.append(html.html_section(
            "Curvature adaptive against conventional",
            html.html_paragraph(
                "Both cuts are simulated on the same height map with the same passes through the "
                "same contact points; the conventional cutter is a ball end of the same diameter "
                "with its axis along the surface normal."),
            html.html_table(["path", "max scallop [mm]", "median scallop [mm]", "max gouge [mm]"], [
                ("curvature adaptive face mill", c["adaptive_max_scallop_mm"],
                 c["adaptive_median_scallop_mm"], r["simulation"]["max_gouge_mm"]),
                ("conventional ball end", c["conventional_max_scallop_mm"],
                 c["conventional_median_scallop_mm"], r["conventional"]["max_gouge_mm"])]),
            html.html_paragraph(f"The conventional path leaves {c['scallop_ratio']:.1f} times the "
                                "scallop.")))
    figures_html = [html.html_figure(_paths_figure(result), "Passes on the part.")]
    if result.target is not None and result.simulation is not None:
        figures_html.append(html.html_figure(_scallop_figure(result),
                                             "Material left above the target (scallop height map), "
                                             f"the target being {result.measured_against}."))
    figures_html.append(html.html_figure(_tilt_figure(result), "Tool tilt along each pass."))
    parts.append(html.html_section("Pictures", *figures_html))
    direction = ("ruling (towards the tip), tilt, safety sphere radius and contact circle "
                 "radius" if cone else "cross tangent, tilt and safety sphere radius")
    parts.append(html.html_section("Files", html.html_paragraph(
        "path.cl: APT CLDATA (GOTO/x, y, z, i, j, k in mm: tool tip and axis). path.csv: the same "
        f"locations with contact point, normal, {direction}. mill.json: every number of this "
        "page.")))
    return html.html_page(f"Milling report: {Path(str(r['net'])).name}", parts,
                          subtitle=f"{r['tool']['spec']}, {r['passes']} passes, made by fabplan")


def mill_report_files(result: MillResult, folder: str | os.PathLike) -> dict:
    """{path: text} of the four files in `folder`."""
    folder = Path(folder)
    plan = result.plan
    path = plan.path
    comments = []
    for number, part in enumerate(path.pass_slices()):
        vertices = path.vertex[part][path.vertex[part] >= 0]
        comments.append(f"pass {number + 1}: vertices {int(vertices[0])} .. {int(vertices[-1])}, "
                        f"{part.stop - part.start} locations")
    header = [f"fabplan mill {plan.tool.spec()} along {plan.settings.along}",
              f"margin {plan.margin_mm:.6g} mm, tilt {path.tilt_deg.min():.4f} .. "
              f"{path.tilt_deg.max():.4f} deg"]
    cone = plan.tool.kind == "cone"
    cl = cldata_text(path.tip, path.axis, path.pass_id, part=Path(str(plan.net)).stem,
                     diameter_mm=plan.tool.diameter_mm, corner_mm=plan.tool.corner_mm,
                     length_mm=plan.tool.length_mm if cone else plan.tool.body_length_mm,
                     side_angle_deg=plan.tool.angle_deg if cone else 0.0,
                     pass_comments=comments, header=header)
    return {folder / "path.cl": cl, folder / "path.csv": plan.csv(),
            folder / "mill.json": json_text(result.record()),
            folder / "report.html": mill_report_html(result)}


def mill_drawing(result: MillResult) -> Rhino3dmWriter:
    """The tool paths as a Rhino document (mm, the frame of the CL file): one polyline of
    cutter tips per pass on layer ``tool tips`` and of contact points on layer
    ``contacts``, named and user-texted by pass as in ``path.cl``."""
    path = result.plan.path
    doc = Rhino3dmWriter("mm")
    doc.layer("tool tips", (200, 40, 40, 255))
    doc.layer("contacts", (40, 90, 200, 255))
    for number, part in enumerate(path.pass_slices()):
        text = {"pass": number + 1}
        doc.add_polyline(path.tip[part], layer="tool tips", name=f"pass {number + 1}",
                         user_text=text)
        doc.add_polyline(path.contact[part], layer="contacts", name=f"pass {number + 1}",
                         user_text=text)
    return doc


def write_mill_report(result: MillResult, folder: str | os.PathLike, *,
                      rhino: bool = False,
                      protect: Mapping[Path, str] | None = None) -> list[Path]:
    """Write the four files into `folder`, all or none, and with `rhino` also
    ``paths.3dm`` (`mill_drawing`); none replaces one of `protect` (the run's inputs);
    returns their paths."""
    folder = Path(folder)
    names = MILL_FILES + (("paths.3dm",) if rhino else ())
    with output_folder(folder, protect=protect) as staging:
        write_texts(mill_report_files(result, staging))
        if rhino:
            mill_drawing(result).write(staging / "paths.3dm")
    return [folder / name for name in names]
