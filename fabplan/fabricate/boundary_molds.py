"""Boundary panels on molds: each is cut from the mold of the full panel it continues.

A boundary panel (`fabplan.layout.trim`) is the part of the design between a net's last
full panel and the design boundary. It is made on the mold of its neighbour, the full
panel it shares its longest side with: the mold surface goes on past the neighbour's
edge, and the boundary panel is that surface cut to the boundary outline. What is to be
checked is how far that surface stays from the design over the boundary panel: every
outline point (on the design) is placed by the neighbour's placement and its gap to the
mold measured (`fabplan.fabricate.molds.placement_deviations`, an upper bound of the
distance). A panel whose gap exceeds the allowed deviation, or that touches the net only
at a corner, needs a mold of its own: counted as one more mold each (an upper bound: such
panels are few and rarely share a shape).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout.trim import BoundaryPanels
from .molds import MoldPlan, placement_deviations

__all__ = ["BoundaryMolds", "boundary_molds"]


@dataclass
class BoundaryMolds:
    """Which mold each boundary panel is cut from, and how well it meets the design.

    Attributes
    ----------
    neighbour_face : (p,) int, the full panel each boundary panel continues (-1: none).
    mold : (p,) int, the mold it is cut from (its neighbour's), -1 where it needs its own.
    deviation_mm : (p,) float, the largest gap between the panel's outline on the design
        and its neighbour's mold surface (mm; inf without a neighbour).
    limit_mm : the gap allowed.
    """

    neighbour_face: np.ndarray
    mold: np.ndarray
    deviation_mm: np.ndarray
    limit_mm: float

    @property
    def count(self) -> int:
        return len(self.mold)

    @property
    def own_molds(self) -> int:
        """Boundary panels that need a mold of their own."""
        return int(np.sum(self.mold < 0))

    def record(self) -> dict:
        """JSON-ready summary."""
        fits = np.isfinite(self.deviation_mm) & (self.mold >= 0)
        return {
            "panels": self.count,
            "cut_from_neighbour_mold": int(fits.sum()),
            "own_molds": self.own_molds,
            "deviation_limit_mm": self.limit_mm,
            "deviation_max_mm": float(self.deviation_mm[fits].max()) if fits.any() else None,
            "mold": self.mold.tolist(),
            "neighbour_face": self.neighbour_face.tolist(),
        }


def boundary_molds(plan: MoldPlan, panels: BoundaryPanels, limit_mm: float) -> BoundaryMolds:
    """The molds of a net's boundary panels (see the module's text).

    Parameters
    ----------
    plan : the `MoldPlan` of the net the panels border.
    panels : its `BoundaryPanels` (model units, as the net).
    limit_mm : the largest gap between a boundary panel and the design allowed on its
        neighbour's mold.

    Returns
    -------
    BoundaryMolds
    """
    p = panels.count
    face = np.asarray(panels.neighbour_face, dtype=np.int64)
    if p == 0:
        return BoundaryMolds(face, np.zeros(0, np.int64), np.zeros(0), float(limit_mm))
    # the outline points of every panel, padded by repeating its first point
    size = max(len(q) for q in panels.polygons)
    idx = np.array([np.r_[q, np.full(size - len(q), q[0])] for q in panels.polygons])
    points = panels.vertices[idx]                                   # (p, s, 3)
    deviation = np.full(p, np.inf)
    has = face >= 0
    if has.any():
        f = face[has]
        deviation[has] = placement_deviations(points[has], plan.placement[f],
                                              plan.mold_shape[plan.mold[f]])
    mold = np.where(has & (deviation <= limit_mm), plan.mold[np.maximum(face, 0)], -1)
    return BoundaryMolds(face, mold, deviation, float(limit_mm))
