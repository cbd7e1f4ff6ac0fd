"""The mold plan of a net (`MoldPlan`): the molds, every panel's placement on its mold and
deviation from it, the steps between neighbours, and its JSON record and tables.

Made by `fabplan.fabricate.molds.mold_assignment.plan_molds`; written as files by
`fabplan.fabricate.molds.mold_report`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...net.mesh import QuadMesh
from ...report.html import counted
from .mold_shapes import MOLD_TYPES, PANEL_TYPES, MoldSettings, mold_count_bound
from .panel_classes import CLASSES, PanelClasses
from .panel_meshes import PANEL_MESH_LEVEL, PanelMesh

__all__ = [
    "MoldPlan",
]


# ----------------------------------------------------------------------------- the plan
@dataclass
class MoldPlan:
    """The molds of a net and every panel's placement on its mold, as measured.

    Attributes
    ----------
    mesh : the net (`fabplan.mesh.QuadMesh`).
    settings : the `MoldSettings` used.
    panel_surface : the panel surface model used (``"shared"``, ``"local_fit"``,
        ``"corners"`` or ``"design"``).
    panel_type : (p,) int, index into `PANEL_TYPES`.
    curvature : (p, 2) float, signed principal curvatures ``k1 >= k2`` of every panel
        with respect to its face normal (1/mm).
    mold_type : (m,) int, index into `MOLD_TYPES`.
    mold_shape : (m, 2) float, ``(k1, k2)`` of every mold (1/mm).
    panel_shape : (p, 2) float, every panel's own ``(k1, k2)`` in its placement frame on its
        mold (1/mm): what its mold's curvatures approximate.
    mold : (p,) int, the mold of every panel.
    placement : (p, 4, 4) float, model coordinates -> mold coordinates (mm); the upper
        left block is ``mm_per_unit`` times a rotation.
    deviation_mm : (p,) float, largest gap between the densely sampled panel and its
        mold, measured through `placement`.
    footprint_mm : (p, 2) float, ``2 max |x|``, ``2 max |y|`` of the placed panel.
    problem : list of str or None per panel: why it does not fit, if it does not.
    weingarten : `weingarten_fit` of the panel curvatures (1/mm).
    reassigned : (k,) int, panels the dense verification found above the tolerance on their
        first mold, classified again and moved to new molds.
    step_mm : (i,) float, the step between the molds of the two panels of every interior
        edge (`panel_steps`), in the order of ``mesh.interior_edge_faces``.
    kink_deg : (i,) float, the largest angle between those two molds' normals there.
    surface_step_mm : (i,) float, how far the two panels' surfaces themselves differ along
        every interior edge (`fabplan.fabricate.panels.surface_steps`): the part of a step
        no mold can close.
    recast_for_steps : (k,) int, panels at edges whose first molds stepped apart by more
        than twice the tolerance, cast again on molds that fit them closer.
    classes : with a material (`MoldSettings.material`), every panel's class
        (`fabplan.fabricate.panel_classes.PanelClasses`); None without one (every curved
        panel is molded). The molds are planned for every curved panel either way: a
        cold-bent, roll-bent or flat panel keeps its mold as the surface its neighbours'
        steps and the boundary panels are measured against, but only the molds of molded
        panels are made (`mold_made`).
    surface : the panel surfaces as triangle meshes (`fabplan.fabricate.panel_meshes`,
        `PANEL_MESH_LEVEL`), corners on the net's vertices: what the IFC export writes
        and `panel_area` measures; None for a plan made without them.
    seconds : run time.
    """

    mesh: QuadMesh
    settings: MoldSettings
    panel_surface: str
    panel_type: np.ndarray
    curvature: np.ndarray
    mold_type: np.ndarray
    mold_shape: np.ndarray
    panel_shape: np.ndarray
    mold: np.ndarray
    placement: np.ndarray
    deviation_mm: np.ndarray
    footprint_mm: np.ndarray
    problem: list[str | None]
    weingarten: dict
    reassigned: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    step_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kink_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    surface_step_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    recast_for_steps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    classes: PanelClasses | None = None
    surface: PanelMesh | None = None
    seconds: float = 0.0
    stage_seconds: dict[str, float] = field(default_factory=dict)

    # ------------------------------------------------------------------ derived numbers
    @property
    def panel_count(self) -> int:
        return len(self.mold)

    @property
    def mold_count(self) -> int:
        return len(self.mold_shape)

    @property
    def mold_made(self) -> np.ndarray:
        """(m,) bool, the molds that are made: the curved molds (a plane is no mold) that a
        molded panel sits on; without a material every curved mold."""
        made = np.asarray(self.mold_type) > 0
        if self.classes is not None:
            made &= np.bincount(self.mold[self.classes.molded], minlength=self.mold_count) > 0
        return made

    @property
    def made_mold_count(self) -> int:
        """The molds made (`mold_made`)."""
        return int(self.mold_made.sum())

    @property
    def molds_saved(self) -> int:
        """The curved molds that every curved panel molded would need and the material's
        classes do not: cold-bent, roll-bent and flat panels need none."""
        return int(np.sum(np.asarray(self.mold_type) > 0)) - self.made_mold_count

    @property
    def failures(self) -> np.ndarray:
        """(k,) int, faces that do not fit their mold."""
        return np.array([i for i, p in enumerate(self.problem) if p], dtype=np.int64)

    @property
    def step_limit_mm(self) -> float:
        """Largest step allowed between neighbouring panels (`MoldSettings.step_limit_mm`)."""
        s = self.settings
        return 2.0 * s.tolerance_mm if s.step_limit_mm is None else float(s.step_limit_mm)

    @property
    def steps_over(self) -> np.ndarray:
        """(k,) int, interior edges (rows of ``mesh.interior_edge_faces``) whose step
        exceeds `step_limit_mm`."""
        return np.flatnonzero(self.step_mm > self.step_limit_mm)

    @property
    def max_step_mm(self) -> float:
        return float(self.step_mm.max()) if self.step_mm.size else 0.0

    @property
    def fits_all(self) -> bool:
        """Every panel fits its mold and no step between neighbours exceeds the limit."""
        return self.failures.size == 0 and self.steps_over.size == 0

    def mold_count_bound(self) -> tuple[float, int]:
        """`mold_count_bound` of the curved panels' curvatures, each in the form a mold takes
        it (turned over when its mean curvature is negative: ``(-k2, -k1)``), at the median
        panel's reach; ``(0.0, 0)`` when every panel is flat."""
        curved = np.asarray(self.panel_type) > 0
        if not curved.any():
            return 0.0, 0
        k = self.curvature[curved]
        turned = np.where((k.sum(axis=1) < 0)[:, None], -k[:, ::-1], k)
        return mold_count_bound(turned, self.curvature_reach(0.5))

    @property
    def panel_area(self) -> np.ndarray | None:
        """(p,) float, every panel's area on its triangulated surface (`surface`; model
        units squared), or None without it."""
        return None if self.surface is None else self.surface.areas()

    @property
    def panels_per_mold(self) -> np.ndarray:
        """(m,) int"""
        return np.bincount(self.mold, minlength=self.mold_count)

    def mold_extent_mm(self) -> np.ndarray:
        """(m, 2) float, the rectangle centred on each mold's apex that holds its panels."""
        ext = np.zeros((self.mold_count, 2))
        np.maximum.at(ext, self.mold, self.footprint_mm)
        return ext

    def mold_deviation_mm(self) -> np.ndarray:
        """(m,) float, the largest deviation of a mold's panels."""
        dev = np.zeros(self.mold_count)
        np.maximum.at(dev, self.mold, self.deviation_mm)
        return dev

    def panel_width_mm(self, quantile: float = 0.5) -> float:
        """A quantile of the panels' widths (the smaller side of their footprints), mm."""
        return float(np.quantile(np.min(self.footprint_mm, axis=1), quantile))

    def curvature_reach(self, quantile: float = 0.5) -> float:
        """Curvature difference (1/mm) one mold absorbs for a panel of the given width
        quantile: a pure shift leaves a gap of ``dk w^2 / 16`` over a panel of width ``w``,
        so larger panels (higher quantiles) absorb less."""
        w = self.panel_width_mm(quantile)
        return 16.0 * self.settings.tolerance_mm / w**2 if w > 0 else math.inf

    def record(self) -> dict:
        """The JSON record (``molds.json``; schema in ``docs/molds-schema.md``)."""
        mm = self.settings.mm_per_unit
        types, counts = np.unique(self.panel_type, return_counts=True)
        per = self.panels_per_mold
        area = self.panel_area
        n = self.panel_count
        length, bound = self.mold_count_bound()
        return {
            "schema": "fabplan-molds/2",
            "net": str(getattr(self.mesh, "name", "")),
            "units": self.settings.units,
            "mm_per_unit": mm,
            "tolerance_mm": float(self.settings.tolerance_mm),
            "max_mold_size_mm": self.settings.max_mold_size_mm,
            "panel_surface": self.panel_surface,
            "panel_count": n,
            "mold_count": self.mold_count,
            "curved_mold_count": int(np.sum(self.mold_type > 0)),
            "molds_per_sqrt_panels": self.mold_count / math.sqrt(n),
            "panel_types": {t: int(counts[types == i].sum()) for i, t in enumerate(PANEL_TYPES)},
            "mold_types": {t: int(np.sum(self.mold_type == i)) for i, t in enumerate(MOLD_TYPES)},
            "panels_per_mold": {"min": int(per.min()), "median": float(np.median(per)),
                                "mean": float(per.mean()), "max": int(per.max())},
            "max_deviation_mm": float(self.deviation_mm.max()),
            **({} if area is None else {"panel_area": {
                "total": float(area.sum()), "units": f"{self.settings.units}^2",
                "surface": f"the panel surfaces triangulated, {PANEL_MESH_LEVEL} steps per side "
                           "of every fan triangle (as the IFC export writes them)"}}),
            "panel_steps": self._steps_record(),
            "mold_count_bound": {"curvature_set_length_per_mm": length,
                                 "mold_reach_per_mm": self.curvature_reach(0.5),
                                 "molds": bound},
            "fits_all": self.fits_all,
            "failures": self.failures.tolist(),
            "reassigned_by_verification": self.reassigned.tolist(),
            "recast_for_steps": self.recast_for_steps.tolist(),
            "weingarten": self.weingarten,
            "molds_made": self.made_mold_count,
            "molds_saved_by_material": self.molds_saved,
            "panel_classes": None if self.classes is None else self.classes.record(mm),
            "curvature_reach_per_mm": {"median_panel": self.curvature_reach(0.5),
                                       "large_panels": self.curvature_reach(0.9)},
            "seconds": self.seconds,
            "molds": self._mold_records(),
            "panels": self._panel_records(area),
        }

    def _mold_records(self) -> list[dict]:
        """Every mold's entry of `record` (``molds``)."""
        per = self.panels_per_mold
        ext, mdev = self.mold_extent_mm(), self.mold_deviation_mm()
        made = self.mold_made
        molds = []
        for j in range(self.mold_count):
            k1, k2 = (float(v) for v in self.mold_shape[j])
            molds.append({
                "id": j,
                "type": MOLD_TYPES[self.mold_type[j]],
                "k1": k1,
                "k2": k2,
                "radius1_mm": 1.0 / k1 if k1 else None,
                "radius2_mm": 1.0 / k2 if k2 else None,
                "size_mm": [float(ext[j, 0]), float(ext[j, 1])],
                "panel_count": int(per[j]),
                "max_deviation_mm": float(mdev[j]),
                "made": bool(made[j]),
            })
        return molds

    def _panel_records(self, area: np.ndarray | None) -> list[dict]:
        """Every panel's entry of `record` (``panels``), with its `area` (`panel_area`)."""
        panels = []
        for i in range(self.panel_count):
            panels.append({
                **({} if area is None else {"area": float(area[i])}),
                "face": i,
                "mold": int(self.mold[i]),
                "type": PANEL_TYPES[self.panel_type[i]],
                "k1": float(self.curvature[i, 0]),
                "k2": float(self.curvature[i, 1]),
                "placement": self.placement[i].tolist(),
                "deviation_mm": float(self.deviation_mm[i]),
                "footprint_mm": [float(v) for v in self.footprint_mm[i]],
                "fits": self.problem[i] is None,
                "problem": self.problem[i],
                **({} if self.classes is None else
                   {"class": CLASSES[self.classes.panel_class[i]]}),
            })
        return panels

    def _steps_record(self) -> dict:
        pairs, edges = self.mesh.interior_edge_faces, self.mesh.interior_edges
        over = self.steps_over
        over = over[np.argsort(-self.step_mm[over], kind="stable")]
        return {
            "limit_mm": self.step_limit_mm,
            "edge_count": int(len(self.step_mm)),
            "max_mm": self.max_step_mm,
            "median_mm": float(np.median(self.step_mm)) if self.step_mm.size else 0.0,
            "max_kink_deg": float(self.kink_deg.max()) if self.kink_deg.size else 0.0,
            "panel_surfaces_max_mm": (float(self.surface_step_mm.max())
                                      if self.surface_step_mm.size else 0.0),
            "fractions": [float(v) for v in self.settings.step_fractions],
            "over_limit": [{"faces": [int(a), int(b)], "vertices": [int(u), int(v)],
                            "step_mm": float(d), "panel_surfaces_mm": float(g)}
                           for (a, b), (u, v), d, g in zip(
                               pairs[over].tolist(), edges[over].tolist(),
                               self.step_mm[over].tolist(), self.surface_step_mm[over].tolist(),
                               strict=True)],
        }

    def panels_csv(self) -> str:
        """``panels.csv``: one row per panel (placement flattened row by row)."""
        head = ["face", "mold", "type", "k1_per_mm", "k2_per_mm", "deviation_mm",
                "footprint_x_mm", "footprint_y_mm", "fits"]
        head += [f"m{r}{c}" for r in range(4) for c in range(4)]
        if self.classes is not None:
            head += ["class", "class_figure", "class_limit", "class_unit"]
            value, limit, unit = self.classes.figure()
        lines = [",".join(head)]
        for i in range(self.panel_count):
            row = [str(i), str(int(self.mold[i])), PANEL_TYPES[self.panel_type[i]],
                   f"{self.curvature[i, 0]:.9g}", f"{self.curvature[i, 1]:.9g}",
                   f"{self.deviation_mm[i]:.4f}", f"{self.footprint_mm[i, 0]:.1f}",
                   f"{self.footprint_mm[i, 1]:.1f}", "yes" if self.problem[i] is None else "no"]
            row += [f"{v:.12g}" for v in self.placement[i].ravel()]
            if self.classes is not None:
                row += [CLASSES[self.classes.panel_class[i]], f"{value[i]:.6g}",
                        f"{limit[i]:.6g}", unit[i]]
            lines.append(",".join(row))
        return "\n".join(lines) + "\n"

    def summary(self) -> str:
        """A few lines for the terminal."""
        r = self.record()
        t = r["panel_types"]
        w = self.weingarten
        lines = [
            f"{r['panel_count']} panels ({t['planar']} planar, {t['single_curved']} single curved, "
            f"{t['double_curved']} double curved) at {r['tolerance_mm']:g} mm; panel surface "
            f"{r['panel_surface']}",
            f"{counted(r['mold_count'], 'mold')} ({r['mold_types']['plane']} plane, "
            f"{r['mold_types']['cylinder']} cylinder, {r['mold_types']['paraboloid']} paraboloid)"
            + (" with every curved panel molded" if self.classes is not None else "")
            + f"; M / sqrt(N) = {r['molds_per_sqrt_panels']:.2f}",
            f"largest deviation {r['max_deviation_mm']:.3f} mm; "
            + ("every panel fits its mold" if self.failures.size == 0 else
               f"{len(r['failures'])} panels do not fit (faces {r['failures'][:10]})"),
            f"largest step between neighbouring panels' molds {self.max_step_mm:.3f} mm "
            f"(limit {self.step_limit_mm:g} mm, {self.steps_over.size} shared edges over it); "
            f"the curvature set's length over one mold's reach suggests about "
            f"{counted(r['mold_count_bound']['molds'], 'mold')} (an estimate, not a bound)",
        ]
        if self.classes is not None:
            c = self.classes.counts
            lines.append(f"{self.classes.material.label}: {c['flat']} flat, {c['cold_bent']} "
                         f"cold-bent, {c['roll_bent']} roll-bent, {c['molded']} molded panels: "
                         f"{counted(self.made_mold_count, 'mold')} to make, {self.molds_saved} saved by "
                         "the material")
        if w.get("thickness") is not None:
            lines.append(f"Weingarten residual: rms {w['line_residual_rms'] * 1000:.4g} 1/m from the "
                         f"line a k1 + b k2 = c, {w['thickness']:.3f} of the curvature spread")
        return "\n".join(lines)
