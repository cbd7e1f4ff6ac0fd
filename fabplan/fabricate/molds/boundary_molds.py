"""Boundary panels on the net's molds: each is cut from a mold the net's panels use, placed
so that it meets the panels beside it.

A boundary panel (`fabplan.layout.trim`) is the part of the design between the net's last
full panels and the design boundary. Cut from a mold it is a piece of that mold's surface,
and to continue the net it must meet its neighbours: the full panels it shares sides with
(their molds as the net's plan places them) and the boundary panels beside it. On a
Weingarten net the panels along a curve of constant curvature share a mold, and the
surface goes on past the net's last row with the curvatures of the rows before it: the
boundary panels find their molds among the net's. Beside flat panels (on the plan's plane
molds) a boundary panel is cut flat where a plane holds its net sides, and two such
panels part along the line where their planes cross (`fabplan.fabricate.molds.flat_boundary`):
these are placed, not fitted. Every other boundary panel is fitted:

1. Its sides (`boundary_sides`): shared with a net face (or a sliver cut as part of one),
   with another boundary panel, or with nothing (the design boundary).
2. Targets: points along every side it shares with a net face, put on that face's mold.
3. Candidates: the molds of the net faces about its corners (two rings of faces). For
   each, the rigid placement that brings the mold closest to the targets
   (`fabplan.fabricate.molds.mold_fits`, the largest gap brought down), started from the
   placement of a face on that mold; the panel's trimmed outline steadies the fit lightly
   (a panel with one shared side could turn about it). Where the steps leave room the
   outline then weighs more, as long as the gaps to the targets stay within half the step
   limit: of the candidates within it, the one closest to the outline is kept (the
   outline stands off the design as the net does beside it); else the one with the
   smallest gap to its targets.
4. Boundary panels beside each other meet halfway: the points of their shared sides are
   put midway between their two molds and both are fitted again, for a few sweeps; then
   they too are brought closer to their outlines where the steps leave room (a quarter of
   the limit to the points midway).
5. Steps are measured along every shared side as between the net's panels
   (`fabplan.fabricate.molds.chord_steps`), at eleven points of it, its ends included. A
   panel that steps against a neighbour by more than the limit on the mold kept gets a
   mold of its own, its curvatures fitted to the same targets (where it still steps over
   the limit, its largest gap brought down exactly by linear programs): only these add
   molds. One that meets its neighbours no better on it keeps the net's mold it had; a
   step still over the limit is reported.

The panel as cut is its outline moved onto its mold along the mold's axis
(`BoundaryMolds.cut_outlines`). Where the design is known its distance from the design is
measured over that outline and the centres of its triangles. A sliver under `min_panel`
of a full panel (`BoundaryPanels.extension`) is cut with the full panel beside it, from
that panel's mold and placement.

Everything here is a function of the net, its mold plan and the boundary panels' outlines
(``NET.boundary.obj``): `fabplan molds` on the files a study writes finds the same molds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ...layout.boundary_panels import BoundaryPanels
from ...report.html import counted
from ...report.viewer import PanelInfo
from .boundary_sides import BoundarySides, boundary_sides
from .flat_boundary import flat_boundary_panels
from .mold_fits import fit_mold_placements, mold_gaps, mold_points, polish_mold_placements
from .mold_plan import MoldPlan
from .mold_shapes import MOLD_TYPES, chord_steps
from .panel_meshes import PanelMesh, boundary_cut_mesh

__all__ = ["BoundarySides", "BoundaryMolds", "BoundaryFitSettings", "boundary_sides",
           "boundary_molds", "boundary_molds_text", "boundary_panels_csv", "boundary_mold_info"]


@dataclass(frozen=True)
class BoundaryFitSettings:
    """How boundary panels are fitted to their neighbours (see the module's text).

    Attributes
    ----------
    side_fractions : where along every shared side its points are put on the neighbour's
        mold (fractions of the side, ends included).
    step_fractions : where along every shared side the step is measured, ends included
        (denser than the net's `MoldSettings.step_fractions`: a boundary panel's mold is
        placed to meet its neighbour's, and it steps most at the side's ends).
    outline_weight : the weight of the trimmed outline's points beside a target's 1.
    outline_weights : the heavier outline weights tried once the steps are met, in order;
        each is kept where the gaps to the targets stay within half the step limit.
    rings : rings of net faces about a panel's corners whose molds are tried.
    sweeps : rounds in which boundary panels beside each other meet halfway, at most.
    settled : a panel is fitted again only while the points midway on a side it shares
        with another boundary panel moved by more than this share of the step limit in the
        last round.
    flat : panels beside the net's flat panels cut flat where a plane holds their net
        sides, the sides two such panels share put on the line where their planes cross
        (`fabplan.fabricate.molds.flat_boundary`).
    split_reach : how far that line may pass from the design boundary for such a side to
        end on it (the net's mean edge lengths).
    """

    side_fractions: tuple[float, ...] = tuple(np.linspace(0.0, 1.0, 9))
    step_fractions: tuple[float, ...] = tuple(np.linspace(0.0, 1.0, 11))
    outline_weight: float = 0.05
    outline_weights: tuple[float, ...] = (0.3, 1.0, 3.0)
    rings: int = 2
    sweeps: int = 12
    settled: float = 0.01
    flat: bool = True
    split_reach: float = 0.1


@dataclass
class BoundaryMolds:
    """How every boundary panel is made: the mold it is cut from, its place on it, and how
    it meets its neighbours and the design.

    Attributes
    ----------
    neighbour_face : (p,) int, the full panel each boundary panel continues (-1: none).
    mold : (p,) int, the mold it is cut from: an id of the net's plan (below
        `net_mold_count`), or ``net_mold_count + j`` for the j-th mold of its own
        (`own_shapes`).
    placement : (p, 4, 4) float, model -> mold coordinates (mm) of the panel as cut.
    shape : (p, 2) float, ``(k1, k2)`` of its mold (1/mm).
    mold_type : (p,) int, index into `MOLD_TYPES` of its mold (a mold of its own is a
        paraboloid).
    own_shapes : (o, 2) float, the curvatures of the molds only boundary panels use.
    step_mm : (p,) float, the largest step between the panel and a neighbour (full panel
        or boundary panel) along their shared sides (mm); 0 without any.
    outline_gap_mm : (p,) float, how far the panel as cut lies from its trimmed outline:
        the largest distance of an outline point from the mold (mm).
    deviation_mm : (p,) float, the largest distance of the panel as cut from the design
        (mm), over its outline and its triangles' centres; NaN where the design is not
        known.
    cut_outlines : list of (k, 3) float arrays, every panel's outline as cut: its trimmed
        outline moved onto its mold along the mold's axis (model units).
    step_limit_mm : the step allowed between neighbouring panels (mm).
    extension : (p,) bool, slivers cut as part of the full panel beside them.
    net_mold_count : the molds of the net's plan.
    sides : the panels' `BoundarySides`; side_step_mm : (s,) float, the step along every
        side (mm; NaN for a side along the design boundary).
    panels : the `BoundaryPanels` as made: those given, with the sides two flat panels
        share put on the line where their planes cross (`fabplan.fabricate.molds.flat_boundary`);
        None where not known.
    """

    neighbour_face: np.ndarray
    mold: np.ndarray
    placement: np.ndarray
    shape: np.ndarray
    mold_type: np.ndarray
    own_shapes: np.ndarray
    step_mm: np.ndarray
    outline_gap_mm: np.ndarray
    deviation_mm: np.ndarray
    cut_outlines: list
    step_limit_mm: float
    extension: np.ndarray
    net_mold_count: int
    sides: BoundarySides | None = None
    side_step_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    panels: BoundaryPanels | None = None

    @property
    def count(self) -> int:
        """Boundary panels made as panels of their own (extensions of full panels not
        counted)."""
        return int(np.sum(~self.extension))

    @property
    def own_molds(self) -> int:
        """Molds only boundary panels use (each fitted to one panel)."""
        return len(self.own_shapes)

    @property
    def flat(self) -> int:
        """Boundary panels cut flat, from a plane (slivers aside): they need no mold."""
        plane = np.asarray(self.mold_type) == MOLD_TYPES.index("plane")
        return int(np.sum(plane & ~self.extension))

    @property
    def on_net_molds(self) -> int:
        """Boundary panels (slivers aside) cut from molds the net's own panels use."""
        return int(np.sum((self.mold < self.net_mold_count) & ~self.extension))

    @property
    def steps_over_limit(self) -> np.ndarray:
        """(k,) int, the panels that step against a neighbour by more than the limit."""
        return np.flatnonzero(self.step_mm > self.step_limit_mm + 1e-9)

    @property
    def slivers_over_limit(self) -> np.ndarray:
        """(s,) int, the slivers (cut with their full panel) that step against a
        neighbour by more than the limit."""
        return np.flatnonzero(self.extension & (self.step_mm > self.step_limit_mm + 1e-9))

    @property
    def step_max_mm(self) -> float:
        """The largest step of a boundary panel against a neighbour (mm)."""
        return float(self.step_mm.max(initial=0.0))

    @property
    def deviation_max_mm(self) -> float | None:
        """The largest distance of a boundary panel as cut from the design (mm); None
        where not measured."""
        d = self.deviation_mm[np.isfinite(self.deviation_mm)]
        return float(d.max()) if d.size else None

    def panel_types(self) -> np.ndarray:
        """(p,) int, index into `PANEL_TYPES` of every panel as cut: that of its mold (a
        plane gives a planar panel, a cylinder a single curved one)."""
        return np.asarray(self.mold_type, np.int64)

    def cut_mesh(self) -> PanelMesh | None:
        """The panels as cut, as triangle meshes (`boundary_cut_mesh`: the trimming's
        triangles over the outlines on their molds); None where the panels are not known."""
        return None if self.panels is None else boundary_cut_mesh(self.panels, self.cut_outlines)

    def record(self, net_molds: int | None = None) -> dict:
        """JSON-ready summary; with the molds the net's panels need made `net_molds`
        (`MoldPlan.made_mold_count`), also ``molds_in_all`` (those and the boundary panels'
        own: every mold to make)."""
        gap = self.outline_gap_mm[~self.extension]
        cut = self.cut_mesh()
        rec = {
            "panels": self.count,
            "extensions_of_full_panels": int(self.extension.sum()),
            "on_molds_full_panels_use": self.on_net_molds,
            "flat": self.flat,
            "own_molds": self.own_molds,
            "own_mold_shapes_per_mm": self.own_shapes.tolist(),
            "step_limit_mm": self.step_limit_mm,
            "step_max_mm": self.step_max_mm,
            "steps_over_limit": self.steps_over_limit.tolist(),
            "outline_gap_max_mm": float(gap.max()) if gap.size else None,
            "deviation_max_mm": self.deviation_max_mm,
            # model units squared, on the triangles of the panels as cut (slivers included)
            "cut_area": None if cut is None else float(cut.areas().sum()),
            "extensions_over_limit": self.slivers_over_limit.tolist(),
            "mold": self.mold.tolist(),
            "neighbour_face": self.neighbour_face.tolist(),
        }
        if net_molds is not None:
            rec["molds_in_all"] = net_molds + self.own_molds
        return rec

    def cut_obj_text(self, header: str = "") -> str:
        """OBJ text of the panels as cut: one face per panel (in the order of
        ``NET.boundary.obj``), each with points of its own on its mold."""
        from ...io.obj import format_obj

        sizes = [len(c) for c in self.cut_outlines]
        points = np.concatenate(self.cut_outlines) if sizes else np.zeros((0, 3))
        ends = np.cumsum(sizes)
        faces = [np.arange(e - s, e) for s, e in zip(sizes, ends, strict=True)]
        return format_obj(points, faces, header)


def boundary_molds_text(molds: BoundaryMolds, plan: MoldPlan, source: object = None) -> str:
    """One sentence: how the boundary panels are made, and the molds to make in all with
    theirs (the net's panels' molds to make, `MoldPlan.made_mold_count`: no plane, none
    a material saves; and the boundary panels' own) against every panel, as a study
    counts them (`fabplan.study.mold_counts`)."""
    slivers = (f", {int(molds.extension.sum())} slivers cut with their full panel"
               if molds.extension.any() else "")
    head = f"{molds.count} boundary panels" + (f" ({source})" if source is not None else "")
    over = molds.steps_over_limit
    steps = (f"steps up to {molds.step_max_mm:.2f} mm (limit {molds.step_limit_mm:g} mm"
             + (f", {len(over)} over it" if len(over) else "") + ")")
    flat = f" ({molds.flat} flat)" if molds.flat else ""
    in_all, panels = plan.made_mold_count + molds.own_molds, plan.panel_count + molds.count
    return (f"{head}: {molds.on_net_molds} cut from molds the net's panels use{flat}, "
            f"{molds.own_molds} on molds of their own{slivers}, placed to meet their "
            f"neighbours: {steps}; {counted(in_all, 'mold')} to make in all for {panels:,} panels "
            f"(M / sqrt(N) = {in_all / math.sqrt(panels):.2f})")


def boundary_panels_csv(panels: BoundaryPanels, molds: BoundaryMolds) -> str:
    """One row per boundary panel: its id (its face in ``NAME.boundary.obj``), what it is
    (a trimmed panel, a patch closing a hole, or an extension cut as part of the full
    panel beside it), the full panel it continues, its mold and the mold's curvatures
    (1/mm), its largest step against a neighbour, its outline's gap to the mold and its
    distance from the design (mm, empty where not known), its corners, its area (model
    units squared) and its placement (model -> mold coordinates, row by row)."""
    kind = np.where(panels.extension, "extension", np.where(panels.patch, "patch", "trimmed"))
    corners = panels.corner_counts()
    head = ["panel", "kind", "neighbour_face", "mold", "k1_per_mm", "k2_per_mm", "step_mm",
            "outline_gap_mm", "deviation_mm", "corners", "area"]
    head += [f"m{r}{c}" for r in range(4) for c in range(4)]
    rows = [",".join(head)]
    for k in range(panels.count):
        deviation = molds.deviation_mm[k]
        row = [str(k), str(kind[k]), str(panels.neighbour_face[k]), str(molds.mold[k]),
               f"{molds.shape[k, 0]:.9g}", f"{molds.shape[k, 1]:.9g}",
               f"{molds.step_mm[k]:.4f}", f"{molds.outline_gap_mm[k]:.4f}",
               f"{deviation:.4f}" if np.isfinite(deviation) else "",
               str(corners[k]), f"{panels.area[k]:.9g}"]
        row += [f"{v:.12g}" for v in molds.placement[k].ravel()]
        rows.append(",".join(row))
    return "\n".join(rows) + "\n"


def boundary_mold_info(molds: BoundaryMolds) -> list[PanelInfo]:
    """What the 3D view shows of a picked boundary panel's mold
    (`fabplan.layout.view.boundary_layer`): the mold it is cut from (as in
    ``boundary-panels.csv``: an id of the net's molds, or past them one of its own),
    whether only it uses that mold, its largest step against a neighbour and its distance
    from the design (mm)."""
    own = (molds.mold >= molds.net_mold_count).astype(np.int64)
    info = [PanelInfo("cut from mold", molds.mold, integer=True),
            PanelInfo("mold", own, names=("one of the net's panels", "its own")),
            PanelInfo("largest step", molds.step_mm, "mm", 3)]
    if np.isfinite(molds.deviation_mm).any():
        info.append(PanelInfo("off the design", molds.deviation_mm, "mm", 3))
    return info


def boundary_molds(plan: MoldPlan, panels: BoundaryPanels, *, design=None,
                   step_limit_mm: float | None = None,
                   settings: BoundaryFitSettings | None = None) -> BoundaryMolds:
    """The molds of a net's boundary panels and their places on them (see the module's
    text).

    Parameters
    ----------
    plan : the `MoldPlan` of the net the panels border.
    panels : its `BoundaryPanels` (model units, as the net).
    design : the `fabplan.design.DesignSurface`, to measure the panels' distance from it;
        None: not measured (NaN).
    step_limit_mm : the step allowed between neighbouring panels (mm); None: the plan's
        (`MoldPlan.step_limit_mm`).
    settings : `BoundaryFitSettings`.

    Returns
    -------
    BoundaryMolds
    """
    settings = settings or BoundaryFitSettings()
    limit = float(plan.step_limit_mm if step_limit_mm is None else step_limit_mm)
    mesh = plan.mesh
    mm = plan.settings.mm_per_unit
    p = panels.count
    face = np.asarray(panels.neighbour_face, np.int64)
    extension = np.asarray(panels.extension, bool)
    net_shape = plan.mold_shape[plan.mold]
    placement = np.zeros((p, 4, 4))
    shape = np.zeros((p, 2))
    mold = np.full(p, -1, np.int64)
    # a sliver is cut with the full panel it continues: its mold and placement
    sliver = np.flatnonzero(extension & (face >= 0))
    placement[sliver], shape[sliver], mold[sliver] = (plan.placement[face[sliver]],
                                                      net_shape[face[sliver]], plan.mold[face[sliver]])
    flat = np.zeros(p, bool)
    if settings.flat and p:
        # beside flat panels, flat panels where a plane holds their net sides, parting
        # along the lines where their planes cross: placed, not fitted
        made = flat_boundary_panels(plan, panels, step_limit_mm=limit, reach=settings.split_reach)
        panels, flat = made.panels, made.flat
        placement[flat], shape[flat], mold[flat] = made.placement[flat], 0.0, made.mold[flat]
    sides = boundary_sides(panels, mesh)
    fitted = np.flatnonzero((~extension | (face < 0)) & ~flat)
    own_shapes = np.zeros((0, 2))
    if fitted.size:
        fit = _Fit(plan, panels, sides, fitted, settings, placement, shape, limit)
        placement, shape, mold, own_shapes = fit.run(mold)
    side_step = _side_steps(sides, panels, plan, placement, shape, mm, settings.step_fractions)
    step = np.zeros(p)
    known = np.isfinite(side_step)
    np.maximum.at(step, sides.panel[known], side_step[known])
    np.maximum.at(step, sides.across[known & (sides.across >= 0)],
                  side_step[known & (sides.across >= 0)])
    cut, gap = _cut_outlines(panels, placement, shape)
    gap = gap * mm
    deviation = np.full(p, np.nan)
    if design is not None and p:
        deviation = _design_distances(design, panels, cut, placement, shape) * mm
    types = np.where(mold >= plan.mold_count, MOLD_TYPES.index("paraboloid"),
                     np.asarray(plan.mold_type)[np.clip(mold, 0, max(plan.mold_count - 1, 0))]
                     if plan.mold_count else MOLD_TYPES.index("paraboloid"))
    return BoundaryMolds(neighbour_face=face, mold=mold, placement=placement, shape=shape,
                         mold_type=np.asarray(types, np.int64), own_shapes=own_shapes,
                         step_mm=step, outline_gap_mm=gap, deviation_mm=deviation,
                         cut_outlines=cut, step_limit_mm=limit, extension=extension,
                         net_mold_count=plan.mold_count, sides=sides, side_step_mm=side_step,
                         panels=panels)


class _Fit:
    """The fit of the boundary panels `fitted` to their neighbours (module's text, 2-6)."""

    def __init__(self, plan: MoldPlan, panels: BoundaryPanels, sides: BoundarySides,
                 fitted: np.ndarray, settings: BoundaryFitSettings, placement: np.ndarray,
                 shape: np.ndarray, limit: float):
        self.plan, self.panels, self.sides, self.settings = plan, panels, sides, settings
        self.fitted, self.limit = fitted, limit
        self.placement, self.shape = placement.copy(), shape.copy()
        self.row = np.full(panels.count, -1)
        self.row[fitted] = np.arange(len(fitted))
        self.t = np.asarray(settings.side_fractions, float)
        self.X = panels.vertices
        mine = self.row[sides.panel] >= 0
        # sides of a fitted panel along a net face or a sliver (whose molds stay put)
        other = sides.across
        fixed_panel = (other >= 0) & (self.row[np.maximum(other, 0)] < 0)
        held = mine & ((sides.face >= 0) | fixed_panel)
        self.held = np.flatnonzero(held)
        # sides between two fitted panels: they meet halfway
        self.mutual = np.flatnonzero(mine & (other >= 0) & ~fixed_panel)
        chord = self._chords(self.held)
        f = sides.face[self.held]
        net_shape = plan.mold_shape[plan.mold]
        M = np.where((f >= 0)[:, None, None], plan.placement[np.maximum(f, 0)],
                     placement[np.maximum(other[self.held], 0)])
        K = np.where((f >= 0)[:, None], net_shape[np.maximum(f, 0)], shape[np.maximum(other[self.held], 0)])
        self.held_targets = mold_points(chord, M, K)                       # (h, t, 3)
        self.outline_weight = np.full(len(fitted), settings.outline_weight)
        self.room = np.zeros((len(fitted), 0))

    def _chords(self, which: np.ndarray) -> np.ndarray:
        """(w, t, 3) points of the sides `which` at the fit's fractions."""
        X, s, t = self.X, self.sides, self.t
        return ((1 - t)[None, :, None] * X[s.start[which]][:, None]
                + t[None, :, None] * X[s.end[which]][:, None])

    def _midway(self) -> np.ndarray:
        """(m, t, 3) the points of the mutual sides midway between their panels' molds."""
        chord = self._chords(self.mutual)
        a, b = self.sides.panel[self.mutual], self.sides.across[self.mutual]
        return 0.5 * (mold_points(chord, self.placement[a], self.shape[a])
                      + mold_points(chord, self.placement[b], self.shape[b]))

    def _targets(self, midway: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The padded points (q, s, 3), weights (q, s) and the points that must be met
        (q, s) of every fitted panel: its held sides' targets and the mutual sides'
        `midway` points (weight 1, to be met), its outline (its outline weight; to be met
        where it is the panel's only points). `room` gives how far each may be off."""
        t = len(self.t)
        owner = [np.repeat(self.row[self.sides.panel[self.held]], t)]
        points = [self.held_targets.reshape(-1, 3)]
        if midway is not None and len(self.mutual):
            owner.append(np.repeat(self.row[self.sides.panel[self.mutual]], t))
            points.append(midway.reshape(-1, 3))
        owner_t = np.concatenate(owner)
        points_t = np.concatenate(points)
        has = np.bincount(owner_t, minlength=len(self.fitted)) > 0
        outline = [np.asarray(self.panels.polygons[k], np.int64) for k in self.fitted]
        owner_o = np.repeat(np.arange(len(self.fitted)), [len(q) for q in outline])
        points_o = self.X[np.concatenate(outline)]
        weight_o = np.where(has, self.outline_weight, 1.0)[owner_o]
        must_o = (~has)[owner_o]
        owner_all = np.r_[owner_t, owner_o]
        # a held side's step is the panel's gap to it; a mutual side's is both panels'
        # gaps to the points midway: each may take half of what a held side may
        share = np.r_[np.full(len(self.held) * t, 0.5), np.full(len(owner_t) - len(self.held) * t, 0.25),
                      np.full(len(owner_o), np.inf)]
        self.room = _padded(owner_all, np.zeros((len(owner_all), 3)), share,
                            np.ones(len(owner_all), bool), len(self.fitted))[1]
        return _padded(owner_all, np.vstack([points_t, points_o]),
                       np.r_[np.ones(len(owner_t)), weight_o],
                       np.r_[np.ones(len(owner_t), bool), must_o], len(self.fitted))

    def _candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """(c,) rows and (c,) net faces: one face per mold about each fitted panel's
        corners (`BoundaryFitSettings.rings` rings of faces); a panel with no net corner
        tries the molds about the face it continues."""
        plan, mesh = self.plan, self.plan.mesh
        n, nf = mesh.vertex_count, len(mesh.face_sizes)
        incidence = sp.csr_matrix((np.ones(len(mesh.face_indices)),
                                   (mesh.face_indices, mesh.corner_faces)), shape=(n, nf))
        outline = [np.asarray(self.panels.polygons[k], np.int64) for k in self.fitted]
        ids = np.concatenate(outline)
        owner = np.repeat(np.arange(len(outline)), [len(q) for q in outline])
        net = ids < n
        corners = sp.csr_matrix((np.ones(int(net.sum())), (owner[net], ids[net])),
                                shape=(len(outline), n))
        ring = (corners @ incidence) > 0
        lone = np.flatnonzero(np.asarray(ring.sum(axis=1)).ravel() == 0)
        continues = np.asarray(self.panels.neighbour_face, np.int64)[self.fitted[lone]]
        ok = continues >= 0
        seed = sp.csr_matrix((np.ones(int(ok.sum())), (lone[ok], continues[ok])),
                             shape=(len(outline), nf))
        ring = (ring + seed) > 0
        for _ in range(max(self.settings.rings, 1) - 1):
            ring = ((ring @ incidence.T) @ incidence) > 0
        rows, faces = ring.nonzero()
        key = rows * (plan.mold_count + 1) + plan.mold[faces]
        order = np.lexsort((faces, key))
        first = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(key) else order
        return rows[first], faces[first]

    def run(self, mold: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fit every panel; returns placement (p, 4, 4), shape (p, 2), mold (p,) and the
        own molds' shapes (o, 2)."""
        plan, fitted, mold = self.plan, self.fitted, mold.copy()
        net_shape = plan.mold_shape[plan.mold]
        points, weights, must = self._targets(None)
        rows, faces = self._candidates()
        best_gap = np.full(len(fitted), np.inf)
        if len(rows):
            M, K, gap = fit_mold_placements(points[rows], weights[rows], plan.placement[faces],
                                            net_shape[faces], must=must[rows])
            # each candidate brought closer to the outline where its steps leave room;
            # of those within half the step limit the closest to the outline is kept,
            # else the one with the smallest gap to its targets
            lighter = (~must[rows]) & (weights[rows] > 0)
            for weight in self.settings.outline_weights:
                W = np.where(lighter, weight, weights[rows])
                M2, K2, g2 = fit_mold_placements(points[rows], W, M, K, must=must[rows])
                keep = g2 <= 0.5 * self.limit
                M[keep], K[keep], gap[keep] = M2[keep], K2[keep], g2[keep]
            outline_gap = np.max(np.where(lighter, np.abs(mold_gaps(points[rows], M, K)), 0.0),
                                 axis=1)
            score = np.where(gap <= 0.5 * self.limit, outline_gap, np.inf)
            order = np.lexsort((gap, score, rows))
            first = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
            chosen = rows[first]
            self.placement[fitted[chosen]], self.shape[fitted[chosen]] = M[first], K[first]
            mold[fitted[chosen]] = plan.mold[faces[first]]
            best_gap[chosen] = gap[first]
        # a panel without a candidate (no net face about it): a mold of its own, fitted
        # from the first face's placement
        free = np.isinf(best_gap)
        self.placement[fitted[free]] = plan.placement[0]
        if len(self.mutual) or free.any():
            self._sweeps(np.arange(len(fitted)), free)
        self._closer(np.arange(len(fitted)), free)
        # molds of their own for the panels that still step too far from a neighbour
        step = self._panel_steps()[fitted]
        own = np.flatnonzero((step > self.limit) | free)
        own_shapes = np.zeros((0, 2))
        if own.size:
            kept = (self.placement[fitted[own]].copy(), self.shape[fitted[own]].copy(),
                    step[own].copy())
            grown = np.zeros(len(fitted), bool)
            grown[own] = True
            self.outline_weight[own] = self.settings.outline_weight
            self._sweeps(own, grown)
            self._closer(own, grown)
            # those still over the limit: their largest gap brought down exactly
            step = self._panel_steps()[fitted]
            still = own[step[own] > self.limit]
            if still.size:
                points, _, must = self._targets(self._midway() if len(self.mutual) else None)
                M, K, _ = polish_mold_placements(points[still], must[still],
                                                 self.placement[fitted[still]],
                                                 self.shape[fitted[still]],
                                                 free_shape=np.ones(still.size, bool))
                self.placement[fitted[still]], self.shape[fitted[still]] = M, K
            # a mold of its own that meets the neighbours no better than the net's mold
            # the panel had is no use: that one is kept, and the step reported
            step = self._panel_steps()[fitted]
            useless = (step[own] > self.limit) & (step[own] >= kept[2]) & ~free[own]
            back = own[useless]
            self.placement[fitted[back]], self.shape[fitted[back]] = kept[0][useless], kept[1][useless]
            own = own[~useless]
            mold[fitted[own]] = plan.mold_count + np.arange(own.size)
            own_shapes = self.shape[fitted[own]].copy()
        return self.placement, self.shape, mold, own_shapes

    def _closer(self, rows: np.ndarray, free: np.ndarray) -> None:
        """The panels `rows` (those `free` with their curvatures) brought closer to their
        trimmed outlines where the steps leave room: each heavier outline weight
        (`BoundaryFitSettings.outline_weights`) is kept where the gaps to the targets stay
        within half the step limit (to the points midway on a side two fitted panels
        share: a quarter)."""
        fitted = self.fitted[rows]
        for weight in self.settings.outline_weights:
            before = self.outline_weight[rows].copy()
            self.outline_weight[rows] = weight
            points, weights, must = self._targets(self._midway() if len(self.mutual) else None)
            M, K, _ = fit_mold_placements(points[rows], weights[rows], self.placement[fitted],
                                          self.shape[fitted], must=must[rows],
                                          free_shape=free[rows])
            gap = np.abs(mold_gaps(points[rows], M, K))
            keep = np.all((gap <= self.room[rows] * self.limit) | (weights[rows] == 0), axis=1)
            self.placement[fitted[keep]], self.shape[fitted[keep]] = M[keep], K[keep]
            self.outline_weight[rows] = np.where(keep, weight, before)

    def _sweeps(self, rows: np.ndarray, free: np.ndarray) -> None:
        """Fit the panels `rows` again, those `free` with their curvatures, with the
        mutual sides met halfway, `BoundaryFitSettings.sweeps` times (once without
        mutual sides)."""
        count = self.settings.sweeps if len(self.mutual) else 1
        rows = np.asarray(rows)
        previous = None
        for sweep in range(count):
            midway = self._midway() if len(self.mutual) else None
            if sweep:
                # only the panels beside a mutual side whose midway points still move
                # change from one sweep to the next
                assert midway is not None and previous is not None
                change = np.abs(midway - previous).max(axis=(1, 2)) * self.plan.settings.mm_per_unit
                moving = change > self.settings.settled * self.limit
                ends = self.row[np.r_[self.sides.panel[self.mutual][moving],
                                      self.sides.across[self.mutual][moving]]]
                meets = np.zeros(len(self.fitted), bool)
                meets[ends[ends >= 0]] = True
                rows = rows[meets[rows]]
                if rows.size == 0:
                    break
            previous = midway
            fitted = self.fitted[rows]
            points, weights, must = self._targets(midway)
            M, K, _ = fit_mold_placements(points[rows], weights[rows], self.placement[fitted],
                                          self.shape[fitted], must=must[rows],
                                          free_shape=free[rows])
            self.placement[fitted], self.shape[fitted] = M, K

    def _panel_steps(self) -> np.ndarray:
        """(p,) float, every panel's largest step against a neighbour (mm)."""
        side = _side_steps(self.sides, self.panels, self.plan, self.placement, self.shape,
                           self.plan.settings.mm_per_unit, self.settings.step_fractions)
        step = np.zeros(self.panels.count)
        known = np.isfinite(side)
        np.maximum.at(step, self.sides.panel[known], side[known])
        mutual = known & (self.sides.across >= 0)
        np.maximum.at(step, self.sides.across[mutual], side[mutual])
        return step


def _padded(owner: np.ndarray, points: np.ndarray, weights: np.ndarray, must: np.ndarray,
            count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (m, 3) with weights (m,) and flags (m,) of `count` groups (`owner` (m,) int)
    as padded arrays (count, s, 3), (count, s) and (count, s); padding is the origin with
    weight 0."""
    order = np.argsort(owner, kind="stable")
    owner, points, weights, must = owner[order], points[order], weights[order], must[order]
    size = np.bincount(owner, minlength=count)
    width = max(int(size.max(initial=0)), 1)
    slot = np.arange(len(owner)) - np.repeat(np.cumsum(size) - size, size)
    P = np.zeros((count, width, 3))
    W = np.zeros((count, width))
    B = np.zeros((count, width), bool)
    P[owner, slot], W[owner, slot], B[owner, slot] = points, weights, must
    return P, W, B


def _side_steps(sides: BoundarySides, panels: BoundaryPanels, plan: MoldPlan,
                placement: np.ndarray, shape: np.ndarray, mm: float,
                fractions: tuple[float, ...]) -> np.ndarray:
    """(s,) float, the step along every side between its panel's mold and the mold across
    (a net face's or a boundary panel's; mm) at `fractions` of the side, as between the
    net's panels; NaN for a side along the design boundary, and for the second of two
    panels' copies of a side."""
    step = np.full(len(sides.panel), np.nan)
    net = sides.face >= 0
    mutual = (sides.across >= 0) & (sides.panel < sides.across)
    which = np.flatnonzero(net | mutual)
    if which.size == 0:
        return step
    X = panels.vertices
    chords = np.stack([X[sides.start[which]], X[sides.end[which]]], axis=1)
    net_shape = plan.mold_shape[plan.mold]
    f, o = sides.face[which], sides.across[which]
    M_other = np.where((f >= 0)[:, None, None], plan.placement[np.maximum(f, 0)],
                       placement[np.maximum(o, 0)])
    K_other = np.where((f >= 0)[:, None], net_shape[np.maximum(f, 0)], shape[np.maximum(o, 0)])
    k = sides.panel[which]
    M = np.stack([placement[k], M_other], axis=1)
    K = np.stack([shape[k], K_other], axis=1)
    step[which] = chord_steps(chords, M, K, mm, fractions=np.asarray(fractions, float))[0]
    return step


def _cut_outlines(panels: BoundaryPanels, placement: np.ndarray, shape: np.ndarray
                  ) -> tuple[list, np.ndarray]:
    """Every panel's outline moved onto its mold along the mold's axis (a list of (k, 3)
    arrays, model units) and how far it moved at most ((p,) float, model units)."""
    if not panels.polygons:
        return [], np.zeros(0)
    sizes = np.array([len(q) for q in panels.polygons])
    owner = np.repeat(np.arange(len(sizes)), sizes)
    ids = np.concatenate(panels.polygons).astype(np.int64)
    points, _, _ = _padded(owner, panels.vertices[ids], np.ones(len(ids)),
                           np.ones(len(ids), bool), len(sizes))
    moved = mold_points(points, placement, shape, closest=False)
    slot = np.arange(len(ids)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    flat = moved[owner, slot]
    gap = np.zeros(len(sizes))
    np.maximum.at(gap, owner, np.linalg.norm(flat - panels.vertices[ids], axis=1))
    return np.split(flat, np.cumsum(sizes)[:-1]), gap


def _design_distances(design, panels: BoundaryPanels, cut: list, placement: np.ndarray,
                      shape: np.ndarray) -> np.ndarray:
    """(p,) float, the largest distance from the design of every panel as cut: its
    outline on its mold and its triangles' centres moved onto its mold (model units)."""
    triangles, owner = panels.panel_triangles()
    centres = panels.vertices[triangles].mean(axis=1) if len(triangles) else np.zeros((0, 3))
    lifted = np.zeros((0, 3))
    if len(centres):
        lifted = mold_points(centres[:, None, :], placement[owner], shape[owner], closest=False)[:, 0]
    sizes = [len(c) for c in cut]
    points = np.vstack([np.concatenate(cut), lifted])
    which = np.r_[np.repeat(np.arange(len(cut)), sizes), owner]
    distance = design.distances(points)
    out = np.zeros(len(cut))
    np.maximum.at(out, which, distance)
    return out

