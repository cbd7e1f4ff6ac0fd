"""A study's molds counted and told: only curved panels need a mold, and with a panel
material only the molded ones (`mold_metrics`), in words for the report and the
recommendation (`molds_text`, `material_sentence`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..fabricate.molds.mold_shapes import MOLD_TYPES, PANEL_TYPES
from ..report.html import counted
from .verdict import every_panel_flat

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..fabricate.molds.boundary_molds import BoundaryMolds
    from ..fabricate.molds.mold_plan import MoldPlan

__all__ = ["mold_metrics", "material_sentence", "molds_text"]


def mold_metrics(plan: MoldPlan, boundary: BoundaryMolds | None = None) -> dict:
    """The mold numbers of a study: only curved panels need a mold, and with a material
    only the molded ones.

    A flat panel is cut from flat stock (glass, sheet) and needs no mold, so `count` is
    the number of molds of the single and double curved panels; the plane "mold" that a
    `fabplan.molds.MoldPlan` assigns to its flat panels is not counted. With a material
    (`MoldPlan.classes`) cold-bent, roll-bent and flat panels need none either: `count` is
    the molds that molded panels sit on (`MoldPlan.mold_made`).

    Parameters
    ----------
    plan : `fabplan.molds.MoldPlan`.
    boundary : the `BoundaryMolds` of the net's boundary panels, or None. A boundary
        panel is cut from one of the net's molds (and is of that mold's type) or from a
        mold of its own (a paraboloid, counted); its steps against its neighbours count
        with the net's. With a material a boundary panel cut from a net mold that no
        molded panel sits on is a piece of its neighbours' bent surface and is bent like
        them (its class: the class of the net panel it continues); one on a made mold is
        molded, and one on a mold of its own is molded on it.

    Returns
    -------
    dict: ``count`` (molds made for the curved panels, the boundary panels' own included),
    ``all_panels_flat``, ``fits_all``, ``failures``, ``max_deviation_mm`` (largest
    panel-to-mold gap, flat panels measured against a plane), ``molds_per_sqrt_panels``
    (``count / sqrt(panels)``, boundary panels counted), ``panel_types``, ``mold_types``
    (the plane type counts the plane flat panels are checked against),
    ``panels_per_mold_max`` (over the curved molds; 0 without any),
    ``max_panel_step_mm`` (largest step between neighbouring panels' molds at a shared
    edge, boundary panels included), ``panel_steps_over`` (shared edges whose step exceeds
    the step limit), ``bound`` (an estimate of the fewest molds the panels' curvature set
    allows, `MoldPlan.mold_count_bound`), ``boundary_own_molds`` and ``net_molds`` (the
    curved molds of the net's own panels); with a material also ``panel_classes`` (panels
    per class, boundary panels counted), ``molded_types`` (the molded panels' types),
    ``all_curved_molded`` (the molds if every curved panel were molded) and ``saved``
    (the molds the material saves against that).
    """
    curved = np.asarray(plan.mold_type) > 0
    made = plan.mold_made
    n = _with_boundary_panels(plan, boundary)
    count = int(made.sum()) + n.own
    curved_molds = int(curved.sum()) + n.own     # every curved panel molded
    panels = len(n.panel_type)
    out: dict[str, Any] = {
        "count": count,
        "net_molds": int(made.sum()),
        # no curved panel at all (with a material a curved panel may need no mold either)
        "all_panels_flat": curved_molds == 0,
        "fits_all": bool(plan.fits_all) and n.over == int(plan.steps_over.size),
        "failures": int(plan.failures.size),
        "max_panel_step_mm": n.step,
        "panel_steps_over": n.over,
        "bound": plan.mold_count_bound()[1],
        "max_deviation_mm": float(np.max(plan.deviation_mm)),
        "molds_per_sqrt_panels": count / math.sqrt(panels),
        "panel_types": {t: int(np.sum(n.panel_type == i)) for i, t in enumerate(PANEL_TYPES)},
        "mold_types": {t: int(np.sum(plan.mold_type == i)) + (n.own if t == "paraboloid" else 0)
                       for i, t in enumerate(MOLD_TYPES)},
        "panels_per_mold_max": int(n.per_mold[made].max()) if made.any() else 0,
        "boundary_own_molds": n.own,
    }
    if n.classes is not None:
        out.update(_class_counts(plan, n, curved_molds, count))
    return out


@dataclass
class _PanelCounts:
    """The net's panels with its boundary panels (`mold_metrics`): panels per mold (m,),
    panel types (p,), classes (p,) or None without a material, the boundary panels' own
    molds, the largest step between neighbouring molds (mm) and the steps over the limit."""

    per_mold: np.ndarray
    panel_type: np.ndarray
    classes: np.ndarray | None
    own: int
    step: float
    over: int


def _with_boundary_panels(plan: MoldPlan, boundary: BoundaryMolds | None) -> _PanelCounts:
    """The counts of `plan`'s panels, the boundary panels added (those that extend a net
    panel are not panels of their own)."""
    per_mold = plan.panels_per_mold.copy()
    panel_type = np.asarray(plan.panel_type)
    classes = None if plan.classes is None else plan.classes.panel_class.copy()
    own = 0
    step = plan.max_step_mm
    over = int(plan.steps_over.size)
    if boundary is not None and boundary.count:
        cut = (boundary.mold >= 0) & (boundary.mold < len(per_mold)) & ~boundary.extension
        per_mold += np.bincount(boundary.mold[cut], minlength=len(per_mold))
        own = boundary.own_molds
        kept = ~boundary.extension
        panel_type = np.r_[panel_type, boundary.panel_types()[kept]]
        if classes is not None:
            classes = np.r_[classes, _boundary_classes(plan, boundary)[kept]]
        step = max(step, boundary.step_max_mm)
        known = np.isfinite(boundary.side_step_mm)
        over += int(np.sum(boundary.side_step_mm[known] > boundary.step_limit_mm + 1e-9))
    return _PanelCounts(per_mold, panel_type, classes, own, step, over)


def _class_counts(plan: MoldPlan, n: _PanelCounts, all_curved_molded: int, count: int) -> dict:
    """The material's part of `mold_metrics`: panels per class, the molded panels' types,
    the molds with every curved panel molded and those the material saves."""
    from ..fabricate.molds.panel_classes import CLASSES

    classes, panel_type = n.classes, n.panel_type
    assert classes is not None and plan.classes is not None
    molded = classes == CLASSES.index("molded")
    return {"panel_classes": {c: int(np.sum(classes == i)) for i, c in enumerate(CLASSES)},
            "molded_types": {t: int(np.sum(molded & (panel_type == i)))
                             for i, t in enumerate(PANEL_TYPES)},
            "all_curved_molded": all_curved_molded,
            "saved": all_curved_molded - count,
            "material": plan.classes.material.label}


def _boundary_classes(plan: MoldPlan, boundary: BoundaryMolds) -> np.ndarray:
    """(b,) the class of every boundary panel (`mold_metrics`)."""
    from ..fabricate.molds.panel_classes import CLASSES

    assert plan.classes is not None
    molded = CLASSES.index("molded")
    net = (boundary.mold >= 0) & (boundary.mold < plan.mold_count)
    on_made = net & plan.mold_made[np.clip(boundary.mold, 0, max(plan.mold_count - 1, 0))]
    face = np.asarray(boundary.neighbour_face)
    like = np.where(face >= 0, plan.classes.panel_class[np.maximum(face, 0)], molded)
    flat = boundary.panel_types() == 0
    return np.where(flat, CLASSES.index("flat"), np.where(net & ~on_made, like, molded))


def material_sentence(molds: dict) -> str:
    """What the panel material saves, in a sentence (`mold_metrics` with a material).

    Examples
    --------
    >>> text = material_sentence({"material": "tempered glass, 8 mm", "saved": 3, "count": 1,
    ...     "all_curved_molded": 4, "panel_classes": {"flat": 2, "cold_bent": 30,
    ...     "roll_bent": 0, "molded": 5}})
    >>> text[:73]
    'In tempered glass, 8 mm, its panels are 2 flat, 30 cold-bent, 0 roll-bent'
    >>> text[73:]
    ' and 5 molded: 1 mold instead of 4 with every curved panel molded, 3 molds saved by the material.'
    >>> material_sentence({"material": "steel", "saved": 0, "count": 0, "all_curved_molded": 0,
    ...     "panel_classes": {"flat": 9, "cold_bent": 0, "roll_bent": 0, "molded": 0}})[-42:]
    'and 0 molded: no panel is curved, no mold.'
    >>> material_sentence({"material": "annealed glass", "saved": 0, "count": 2,
    ...     "all_curved_molded": 2, "panel_classes": {"flat": 0, "cold_bent": 0,
    ...     "roll_bent": 0, "molded": 9}})[-50:]
    'and 9 molded: 2 molds, none saved by the material.'
    """
    c = molds["panel_classes"]
    head = (f"In {molds['material']}, its panels are {c['flat']} flat, {c['cold_bent']} cold-bent, "
            f"{c['roll_bent']} roll-bent and {c['molded']} molded: ")
    if molds["all_curved_molded"] == 0:
        # nothing to save: "0 molds instead of 0" says nothing
        return head + "no panel is curved, no mold."
    if molds["saved"] == 0:
        # nor does "17 molds instead of 17"
        return head + f"{counted(molds['count'], 'mold')}, none saved by the material."
    return (head + f"{counted(molds['count'], 'mold')} instead of {molds['all_curved_molded']} "
            f"with every curved panel molded, {counted(molds['saved'], 'mold')} saved by the "
            "material.")


def molds_text(molds: dict) -> str:
    """The molds of a candidate in words: ``"no molds: all panels flat"``, with a material
    whose panels are bent ``"no molds: no panel molded"``, or ``"12 molds"``.

    Examples
    --------
    >>> molds_text({"count": 0, "all_panels_flat": True}), molds_text({"count": 12})
    ('no molds: all panels flat', '12 molds')
    >>> molds_text({"count": 0, "all_panels_flat": False, "panel_classes": {"flat": 0,
    ...     "cold_bent": 5, "roll_bent": 0, "molded": 0}})
    'no molds: no panel molded'
    """
    if molds["count"] == 0:
        return "no molds: all panels flat" if every_panel_flat(molds) else "no molds: no panel molded"
    return counted(molds["count"], "mold")

