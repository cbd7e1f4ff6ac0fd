"""Lamella strips: the lamellas along a net's parameter polylines, unrolled, cut into parts,
nested on sheets and written as DXF sheets, with the whole strip job and its files.

Owns: the polylines, node normals and unrolling (`unrolling`), the strips (`strip_set`:
`StripSettings`, `build_strips`), their ends at the boundary (`strip_boundary`), outlines
with arcs (`bulges`), parts on sheets (`nesting`), DXF sheets (`dxf`) and the strip job
with its files (`strip_plan`).
May import: the shared modules of `fabplan.fabricate` (`limits`), and `fabplan.layout`,
`fabplan.solve`, `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`; never
another product of `fabplan.fabricate` (`molds`, `milling`, `arcs`).

The names of the former module ``fabplan.fabricate.strips`` are here, imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import exported

# public name -> the module that owns it; imported on first use, so that one module of this
# package can be imported without the others
_EXPORTS = {
    "StripSettings": "fabplan.fabricate.strips.strip_set",
    "ReferenceCurve": "fabplan.fabricate.strips.strip_set",
    "Strip": "fabplan.fabricate.strips.strip_set",
    "Crossing": "fabplan.fabricate.strips.strip_set",
    "StripSet": "fabplan.fabricate.strips.strip_set",
    "ArcRun": "fabplan.fabricate.strips.unrolling",
    "build_strips": "fabplan.fabricate.strips.strip_set",
    "strip_polylines": "fabplan.fabricate.strips.unrolling",
    "node_normals": "fabplan.fabricate.strips.unrolling",
    "unroll_polylines": "fabplan.fabricate.strips.unrolling",
    "fit_arc_runs": "fabplan.fabricate.strips.unrolling",
    # public before, not in __all__
    "CUTTING_TOLERANCE_MM": "fabplan.fabricate.strips.strip_set",
    "MAX_SHEET_MM": "fabplan.fabricate.strips.strip_set",
    "FAMILY_LETTERS": "fabplan.fabricate.strips.strip_set",
    "Unrolled": "fabplan.fabricate.strips.unrolling",
}

__all__ = [
    "StripSettings",
    "ReferenceCurve",
    "ArcRun",
    "Strip",
    "Crossing",
    "StripSet",
    "strip_polylines",
    "node_normals",
    "unroll_polylines",
    "fit_arc_runs",
    "build_strips",
]

if TYPE_CHECKING:  # what a type checker sees; at run time `__getattr__` imports
    from .strip_set import (
        Crossing,
        ReferenceCurve,
        Strip,
        StripSet,
        StripSettings,
        build_strips,
    )
    from .unrolling import ArcRun, fit_arc_runs, node_normals, strip_polylines, unroll_polylines


def __getattr__(name: str) -> Any:
    return exported(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
