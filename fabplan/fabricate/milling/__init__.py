"""CNC milling: curvature-adaptive face milling of S-nets and flank milling of S*-nets
(paper 3.2), the simulation of the cut, the distance to the design and the report files.

Owns: the tool, settings and plan record (`mill_plan`), face milling (`face_milling`),
flank milling (`flank_milling`), the height-map simulation (`mill_simulation`), the
design's heights and frames (`mill_design`) and the whole job with its files
(`mill_report`).
May import: the shared modules of `fabplan.fabricate` (`limits`), and `fabplan.design`,
`fabplan.solve`, `fabplan.net`, `fabplan.report`, `fabplan.io`, `fabplan.errors`; never
another product of `fabplan.fabricate` (`molds`, `strips`, `arcs`).

The names of the former module ``fabplan.fabricate.milling`` are here, imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import exported

# public name -> the module that owns it; imported on first use, so that one module of this
# package can be imported without the others
_EXPORTS = {
    "MillTool": "fabplan.fabricate.milling.mill_plan",
    "MillSettings": "fabplan.fabricate.milling.mill_plan",
    "ToolPath": "fabplan.fabricate.milling.mill_plan",
    "MillPlan": "fabplan.fabricate.milling.mill_plan",
    "PassLines": "fabplan.fabricate.milling.face_milling",
    "parse_tool": "fabplan.fabricate.milling.mill_plan",
    "circle_tool_pose": "fabplan.fabricate.milling.face_milling",
    "describe_region": "fabplan.fabricate.milling.face_milling",
    "default_margin_mm": "fabplan.fabricate.milling.face_milling",
    "line_sequence": "fabplan.fabricate.milling.face_milling",
    "pass_lines": "fabplan.fabricate.milling.face_milling",
    "choose_stride": "fabplan.fabricate.milling.face_milling",
    "walk_across_lines": "fabplan.fabricate.milling.face_milling",
    "pass_frames": "fabplan.fabricate.milling.face_milling",
    "evaluate_pass_frames": "fabplan.fabricate.milling.face_milling",
    "refine_pass": "fabplan.fabricate.milling.face_milling",
    "trace_passes": "fabplan.fabricate.milling.face_milling",
    "place_passes_on_design": "fabplan.fabricate.milling.face_milling",
    "beyond_design_notes": "fabplan.fabricate.milling.face_milling",
    "plan_face_milling": "fabplan.fabricate.milling.face_milling",
}

__all__ = [
    "MillTool",
    "MillSettings",
    "ToolPath",
    "MillPlan",
    "PassLines",
    "parse_tool",
    "circle_tool_pose",
    "describe_region",
    "default_margin_mm",
    "line_sequence",
    "pass_lines",
    "choose_stride",
    "walk_across_lines",
    "pass_frames",
    "evaluate_pass_frames",
    "refine_pass",
    "trace_passes",
    "place_passes_on_design",
    "beyond_design_notes",
    "plan_face_milling",
]

if TYPE_CHECKING:  # what a type checker sees; at run time `__getattr__` imports
    from .face_milling import (
        PassLines,
        beyond_design_notes,
        choose_stride,
        circle_tool_pose,
        default_margin_mm,
        describe_region,
        evaluate_pass_frames,
        line_sequence,
        pass_frames,
        pass_lines,
        place_passes_on_design,
        plan_face_milling,
        refine_pass,
        trace_passes,
        walk_across_lines,
    )
    from .mill_plan import MillPlan, MillSettings, MillTool, ToolPath, parse_tool


def __getattr__(name: str) -> Any:
    return exported(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
