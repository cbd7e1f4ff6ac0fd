"""What falls short in a net's cladding of its design (coverage, boundary panels facing
against it, crossing themselves or lying off it), in plain words for the terminal."""

from __future__ import annotations

from ..report.html import counted, panel_areas

__all__ = ["boundary_text", "boundary_warnings"]


def boundary_text(properties: dict) -> str:
    """The boundary panels of a layout and the coverage they bring, in words."""
    panels = properties.get("boundary_panels") or {}
    count = panels.get("count", 0)
    text = (f"{count} boundary panel{'' if count == 1 else 's'} trimmed to the design boundary "
            f"bring it to {100 * properties['coverage']:.2f} %")
    patches = panels.get("patches") or []
    if patches:
        text += (f" (of them {len(patches)} patch{'' if len(patches) == 1 else 'es'} closing holes "
                 "inside the net, ids under properties.boundary_panels.patches)")
    slivers = len(panels.get("extensions") or [])
    if slivers:
        # the boundary OBJ has a face for each: say why it has more faces than panels
        text += (f", and {counted(slivers, 'sliver')} cut as part of the full panel beside "
                 f"{'it' if slivers == 1 else 'them'} ({count + slivers} faces in the boundary OBJ)")
    return text


def boundary_warnings(properties: dict) -> list:
    """What falls short in a net's cladding of its design (coverage, boundary panels
    facing against it or crossing themselves), in plain words."""
    out = []
    coverage = properties["coverage"]
    panels = properties.get("boundary_panels") or {}
    if coverage < 0.999:
        gaps = panels.get("gaps") or []
        where = "" if not gaps else (
            f"; the largest gap, of {panel_areas(gaps[0]['area_relative_to_panel'])}, lies "
            f"{'at the design boundary' if gaps[0]['at_design_boundary'] else 'inside the design'} "
            f"around ({', '.join(f'{v:.4g}' for v in gaps[0]['point'])})")
        out.append(f"the panels cover only {100 * coverage:.1f} % of the design surface "
                   f"(measured by area on the design{where}; the largest gaps are listed "
                   "under properties.boundary_panels.gaps in the JSON)")
    flipped = panels.get("flipped") or []
    if flipped:
        out.append(f"{counted(len(flipped), 'boundary panel')} face{'s' if len(flipped) == 1 else ''} "
                   "against the design (ids under properties.boundary_panels.flipped)")
    crossed = panels.get("crossed") or []
    if crossed:
        one = len(crossed) == 1
        out.append(f"{counted(len(crossed), 'boundary panel')} "
                   f"{'crosses itself' if one else 'cross themselves'} (ids under "
                   "properties.boundary_panels.crossed): the outline turns back at a net vertex "
                   "off the design boundary; trim the net there by hand")
    off = panels.get("off_design") or {}
    # in the net's units where it records them (an area said without units read as mm^2
    # or m^2 alike)
    area_unit = f"{units}^2" if (units := properties.get("units")) else "model units squared"
    if off.get("area", 0.0) > 0:
        places = off.get("places") or []
        where = "" if not places else (
            f"; the largest, {places[0]['area']:.4g} {area_unit} of "
            f"{'face' if 'face' in places[0] else 'boundary panel'} "
            f"{places[0].get('face', places[0].get('panel'))}, around "
            f"({', '.join(f'{v:.4g}' for v in places[0]['point'])})")
        out.append(f"{off['area']:.4g} {area_unit} of panels lie off the design, over a hole "
                   f"or past its boundary ({off.get('faces', 0)} net faces and "
                   f"{off.get('panels', 0)} boundary panels{where}; listed under "
                   "properties.boundary_panels.off_design): trim them there by hand")
    crossings = panels.get("crossings") or {}
    clashes = crossings.get("overlapping", 0) + crossings.get("edge_clashes", 0)
    if clashes:
        out.append(f"{counted(clashes, 'pair')} of panels overlap or share a side the same way "
                   "(listed under properties.boundary_panels.crossings.pairs: a face is a net "
                   "face, a panel a face of the boundary OBJ, numbered from 0)")
    return out

