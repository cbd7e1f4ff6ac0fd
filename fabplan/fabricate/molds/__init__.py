"""Panels and molds: the panels' surfaces, sheet materials and panel classes, the molds a
net's panels need and every panel's placement on its mold, boundary panels on those molds
(or flat), and the molds' report.

Owns: panel surfaces (`panels`), their triangle meshes (`panel_meshes`), sheet materials
(`materials`) and panel classes (`panel_classes`); molds and what is measured on them
(`mold_shapes`), the plan record (`mold_plan`) and the planning (`mold_assignment`:
`plan_molds`), the fit of mold placements (`mold_fits`, with its compiled kernel
`mold_fit_kernel`), boundary panels (`boundary_sides`, `boundary_molds`,
`flat_boundary`) and the report files (`mold_report`).
May import: the shared modules of `fabplan.fabricate` (`limits`), and `fabplan.layout`,
`fabplan.design`, `fabplan.solve`, `fabplan.net`, `fabplan.report`, `fabplan.io`,
`fabplan.errors`; never another product of `fabplan.fabricate` (`strips`, `milling`,
`arcs`).

The names of the former module ``fabplan.fabricate.molds`` are here, imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import exported

# public name -> the module that owns it; imported on first use, so that one module of this
# package can be imported without the others
_EXPORTS = {
    "UNITS": "fabplan.fabricate.molds.mold_shapes",
    "TOLERANCE_RANGE_MM": "fabplan.fabricate.molds.mold_shapes",
    "PANEL_TYPES": "fabplan.fabricate.molds.mold_shapes",
    "MOLD_TYPES": "fabplan.fabricate.molds.mold_shapes",
    "MoldSettings": "fabplan.fabricate.molds.mold_shapes",
    "MoldPlan": "fabplan.fabricate.molds.mold_plan",
    "plan_molds": "fabplan.fabricate.molds.mold_assignment",
    "mold_heights": "fabplan.fabricate.molds.mold_shapes",
    "placement_deviations": "fabplan.fabricate.molds.mold_shapes",
    "closest_mold_points": "fabplan.fabricate.molds.mold_shapes",
    "panel_steps": "fabplan.fabricate.molds.mold_shapes",
    "chord_steps": "fabplan.fabricate.molds.mold_shapes",
    "mold_count_bound": "fabplan.fabricate.molds.mold_shapes",
    # public before, not in __all__
    "STEP_ROUNDS": "fabplan.fabricate.molds.mold_assignment",
}

__all__ = [
    "UNITS",
    "TOLERANCE_RANGE_MM",
    "PANEL_TYPES",
    "MOLD_TYPES",
    "MoldSettings",
    "MoldPlan",
    "plan_molds",
    "mold_heights",
    "placement_deviations",
    "closest_mold_points",
    "panel_steps",
    "chord_steps",
    "mold_count_bound",
]

if TYPE_CHECKING:  # what a type checker sees; at run time `__getattr__` imports
    from .mold_assignment import plan_molds
    from .mold_plan import MoldPlan
    from .mold_shapes import (
        MOLD_TYPES,
        PANEL_TYPES,
        TOLERANCE_RANGE_MM,
        UNITS,
        MoldSettings,
        chord_steps,
        closest_mold_points,
        mold_count_bound,
        mold_heights,
        panel_steps,
        placement_deviations,
    )


def __getattr__(name: str) -> Any:
    return exported(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
