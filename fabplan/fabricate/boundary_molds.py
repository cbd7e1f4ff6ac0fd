"""Boundary panels on molds: each is cut from the mold of the full panel it continues.

A boundary panel (`fabplan.layout.trim`) is the part of the design between a net's last
full panel and the design boundary. It is made on the mold of its neighbour, the full
panel it shares its longest side with: the mold surface goes on past the neighbour's
edge, and the boundary panel is that surface cut to the boundary outline. What is to be
checked is how far that surface stays from the design over the boundary panel: every
outline point (on the design) is placed by the neighbour's placement and its gap to the
mold measured (`fabplan.fabricate.molds.placement_deviations`, an upper bound of the
distance). Beside a flat panel, a boundary panel is flat stock cut in its own plane: its
gap is that of its outline to its best-fitting plane. A curved boundary panel whose gap
exceeds the allowed deviation from the design needs a mold of its own: counted as one
more mold each (an upper bound: such panels are few and rarely share a shape). So the
mold count of a study depends on its deviation limit, through its boundary panels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout.trim import BoundaryPanels
from ..report.viewer import PanelInfo
from .molds import MOLD_TYPES, MoldPlan, placement_deviations

__all__ = ["BoundaryMolds", "boundary_molds", "planned_boundary_molds", "boundary_molds_text",
           "boundary_panels_csv", "boundary_mold_info"]


@dataclass
class BoundaryMolds:
    """Which mold each boundary panel is cut from, and how well it meets the design.

    Attributes
    ----------
    neighbour_face : (p,) int, the full panel each boundary panel continues (-1: none).
    mold : (p,) int, the mold it is cut from (its neighbour's), -1 where it needs its own.
    deviation_mm : (p,) float, the largest gap between the panel's outline on the design
        and its neighbour's mold surface (mm; inf without a neighbour).
    limit_mm : the gap allowed on a neighbour's mold.
    extension : (p,) bool, slivers made as part of their neighbour (not panels).
    planned_with_net : the molds the net's own panels use, when the boundary panels were
        planned as panels with them (`planned_boundary_molds`); None when each is cut
        from its neighbour's mold or a mold of its own (`boundary_molds`).
    """

    neighbour_face: np.ndarray
    mold: np.ndarray
    deviation_mm: np.ndarray
    limit_mm: float
    extension: np.ndarray
    planned_with_net: np.ndarray | None = None

    @property
    def molds_of_their_own(self) -> int:
        """Molds only boundary panels use, when planned with the net's panels."""
        if self.planned_with_net is None:
            return int(np.sum((self.mold < 0) & ~self.extension))
        used = np.unique(self.mold[(self.mold >= 0) & ~self.extension])
        return int(np.sum(~np.isin(used, self.planned_with_net)))

    @property
    def count(self) -> int:
        """Boundary panels made as panels of their own (extensions of full panels not
        counted)."""
        return int(np.sum(~self.extension))

    @property
    def own_molds(self) -> int:
        """Boundary panels that need a mold of their own (slivers are cut with their full
        panel: they need none); none when planned with the net's panels, whose plan
        counts their molds."""
        if self.planned_with_net is not None:
            return 0
        return int(np.sum((self.mold < 0) & ~self.extension))

    @property
    def on_net_molds(self) -> int:
        """Boundary panels (slivers aside) on molds the net's own panels use, when planned
        with them."""
        if self.planned_with_net is None:
            return 0
        return int(np.sum(np.isin(self.mold[~self.extension], self.planned_with_net)))

    @property
    def sliver_deviation_max_mm(self) -> float | None:
        """The largest gap of a sliver, cut with its full panel, to the design (mm)."""
        sliver = self.extension & np.isfinite(self.deviation_mm)
        return float(self.deviation_mm[sliver].max()) if sliver.any() else None

    @property
    def slivers_over_limit(self) -> np.ndarray:
        """(s,) int, the slivers whose gap on their full panel's mold exceeds `limit_mm`."""
        return np.flatnonzero(self.extension & (self.deviation_mm > self.limit_mm))

    def record(self, net_molds: int | None = None) -> dict:
        """JSON-ready summary; with the net's own mold count `net_molds`, also
        ``molds_in_all``."""
        fits = np.isfinite(self.deviation_mm) & (self.mold >= 0) & ~self.extension
        rec = {
            "panels": self.count,
            "extensions_of_full_panels": int(self.extension.sum()),
            "planned_with_net": self.planned_with_net is not None,
            "deviation_limit_mm": self.limit_mm,
            "deviation_max_mm": float(self.deviation_mm[fits].max()) if fits.any() else None,
            # slivers are cut with their full panel, from its mold: how far that is off
            "extensions_deviation_max_mm": self.sliver_deviation_max_mm,
            "extensions_over_limit": self.slivers_over_limit.tolist(),
            "mold": self.mold.tolist(),
            "neighbour_face": self.neighbour_face.tolist(),
        }
        if self.planned_with_net is None:
            rec.update(cut_from_neighbour_mold=int(fits.sum()), own_molds=self.own_molds)
        else:
            # their molds are among the plan's: none to add to its count
            rec.update(on_molds_full_panels_use=self.on_net_molds,
                       molds_only_boundary_panels_use=self.molds_of_their_own, own_molds=0)
        if net_molds is not None:
            rec["molds_in_all"] = net_molds + self.own_molds
        return rec


def boundary_molds_text(molds: BoundaryMolds, net_molds: int, source: object = None) -> str:
    """One sentence: how the boundary panels are made, and the molds in all with theirs."""
    slivers = (f", {int(molds.extension.sum())} slivers cut with their full panel"
               if molds.extension.any() else "")
    head = f"{molds.count} boundary panels" + (f" ({source})" if source is not None else "")
    if molds.planned_with_net is not None:
        shared = molds.on_net_molds
        return (f"{head}: planned with the net's panels, {shared} on molds full panels use, "
                f"{molds.count - shared} on the {molds.molds_of_their_own} molds only boundary "
                f"panels use{slivers}; {net_molds} molds in all")
    fits = int(np.sum(molds.mold[~molds.extension] >= 0))
    return (f"{head}: {fits} cut from the mold of the full panel they continue (within "
            f"{molds.limit_mm:g} mm), {molds.own_molds} need a mold of their own{slivers}; "
            f"{net_molds + molds.own_molds} molds in all")


def planned_boundary_molds(plan: MoldPlan, panels: BoundaryPanels) -> BoundaryMolds:
    """The molds of boundary panels planned as panels with the net's: `plan` is of the
    net's faces followed by the boundary panels that are no slivers, in order. A sliver is
    cut with the full panel it continues, from that panel's mold.

    Returns
    -------
    BoundaryMolds whose `mold` and `deviation_mm` are the plan's (a sliver's, its
    neighbour's mold and its gap to it), with `planned_with_net` the molds the net's own
    panels use.
    """
    n_faces = len(plan.mold) - int(np.sum(~np.asarray(panels.extension, bool)))
    neighbour = boundary_molds(plan, panels, limit_mm=np.inf)
    own = np.flatnonzero(~np.asarray(panels.extension, bool))
    mold, deviation = neighbour.mold.copy(), neighbour.deviation_mm.copy()
    mold[own] = plan.mold[n_faces:]
    deviation[own] = plan.deviation_mm[n_faces:]
    return BoundaryMolds(neighbour.neighbour_face, mold, deviation,
                         float(plan.settings.tolerance_mm), neighbour.extension,
                         planned_with_net=np.unique(plan.mold[:n_faces]))





def boundary_panels_csv(panels: BoundaryPanels, molds: BoundaryMolds) -> str:
    """One row per boundary panel: its id (its face in ``NAME.boundary.obj``), what it is
    (a trimmed panel, a patch closing a hole, or an extension cut as part of the full
    panel beside it), the full panel it continues, its mold (``own`` for one of its own),
    its gap to that mold (mm), its corners and its area (model units squared)."""
    kind = np.where(panels.extension, "extension", np.where(panels.patch, "patch", "trimmed"))
    corners = panels.corner_counts()
    rows = ["panel,kind,neighbour_face,mold,deviation_mm,corners,area"]
    for k in range(panels.count):
        mold = str(molds.mold[k]) if molds.mold[k] >= 0 else "own"
        gap = f"{molds.deviation_mm[k]:.6g}" if np.isfinite(molds.deviation_mm[k]) else ""
        rows.append(f"{k},{kind[k]},{panels.neighbour_face[k]},{mold},{gap},{corners[k]},"
                    f"{panels.area[k]:.9g}")
    return "\n".join(rows) + "\n"


def boundary_mold_info(molds: BoundaryMolds) -> list[PanelInfo]:
    """What the 3D view shows of a picked boundary panel's mold (`fabplan.layout.view.
    boundary_layer`): the mold it is cut from (that of the full panel it continues, the
    id of the molds table) or a mold of its own, and its gap to that mold (mm)."""
    gap = np.where(np.isfinite(molds.deviation_mm), molds.deviation_mm, np.nan)
    return [PanelInfo("cut from mold", molds.mold, integer=True,
                      absent=f"a mold of its own (over {molds.limit_mm:g} mm from its neighbour's)"),
            PanelInfo("gap to the mold", gap, "mm", 3)]


def boundary_molds(plan: MoldPlan, panels: BoundaryPanels, limit_mm: float) -> BoundaryMolds:
    """The molds of a net's boundary panels (see the module's text).

    Parameters
    ----------
    plan : the `MoldPlan` of the net the panels border.
    panels : its `BoundaryPanels` (model units, as the net).
    limit_mm : the largest gap between a curved boundary panel and the design allowed on
        its neighbour's mold.

    Returns
    -------
    BoundaryMolds
    """
    p = panels.count
    face = np.asarray(panels.neighbour_face, dtype=np.int64)
    if p == 0:
        return BoundaryMolds(face, np.zeros(0, np.int64), np.zeros(0), float(limit_mm),
                             np.zeros(0, bool))
    # the outline points of every panel, padded by repeating its first point
    size = max(len(q) for q in panels.polygons)
    idx = np.array([np.r_[q, np.full(size - len(q), q[0])] for q in panels.polygons])
    points = panels.vertices[idx]                                   # (p, s, 3)
    deviation = np.full(p, np.inf)
    has = face >= 0
    neighbour_mold = plan.mold[np.maximum(face, 0)]
    # beside a flat panel a boundary panel is flat stock too, cut in its own plane: its
    # gap is that of its outline to its best-fitting plane, and it needs no mold
    flat = has & (np.asarray(plan.mold_type)[neighbour_mold] == MOLD_TYPES.index("plane"))
    curved = has & ~flat
    if curved.any():
        f = face[curved]
        deviation[curved] = placement_deviations(points[curved], plan.placement[f],
                                                 plan.mold_shape[plan.mold[f]])
    if flat.any():
        deviation[flat] = [_plane_gap(panels.vertices[panels.polygons[k]]) * plan.settings.mm_per_unit
                           for k in np.flatnonzero(flat)]
    # a sliver is cut with its full panel, from that panel's mold, whatever its gap
    extension = np.asarray(panels.extension, bool)
    mold = np.where(flat | (curved & ((deviation <= limit_mm) | extension)), neighbour_mold, -1)
    return BoundaryMolds(face, mold, deviation, float(limit_mm), np.asarray(panels.extension, bool))


def _plane_gap(points: np.ndarray) -> float:
    """Largest distance of points (k, 3) from their least-squares plane (model units)."""
    centred = points - points.mean(axis=0)
    return float(np.abs(centred @ np.linalg.svd(centred)[2][2]).max())
