"""The numbers that steer a layout."""

from __future__ import annotations

from dataclasses import dataclass

from ..io.parameters import OPTIONS

__all__ = ["LayoutSettings", "SURFACE_TOLERANCE", "MAX_STARTS"]


# how far a gliding net may leave the design, in panel sizes: half of the 1 % a layout is
# judged by (measured: up to 0.45 % used on a facade with near-umbilics)
SURFACE_TOLERANCE = 0.005

#: the starts a net may be laid out and solved from (`fabplan.layout.starts`)
MAX_STARTS = int(OPTIONS["--starts"].high or 1)


@dataclass
class LayoutSettings:
    """Numbers that steer the layout (lengths in panel sizes unless stated).

    Attributes
    ----------
    bisector : the principal direction bisecting the angle between the families, "max"
        (the larger principal curvature) or "min". Irrelevant at 90 degrees.
    smoothing : smoothing length of the direction field (the first one tried).
    smoothing_tries : longer smoothing lengths tried in turn while the layout's quads and
        boundary panels (`fabplan.layout.trim`) cover less than `good_coverage` of the
        design: near umbilics a longer smoothing gives fewer seams and singular points,
        so the lattice holds together; the layout covering the most is kept.
    good_coverage : share of the design's area whose covering ends the tries.
    max_smoothing : orthogonal nets smooth the directions as a cross field, over
        `smoothing` doubled up to this length until the field has no quarter-turn
        singularity (see `fabplan.layout.lattice`).
    scale_weight : weight of uniform spacing against alignment with the directions in
        the integration (alignment has weight 1): smaller values follow the directions
        more closely and let the spacing vary.
    curvature_radius : neighbourhood of libigl's curvature estimate (in mean edges of
        the design mesh), for triangle meshes.
    min_edge, max_edge : extracted quads with an edge outside this range are dropped.
    fill_holes_up_to : interior holes bounded by at most this many edges are closed with
        a fan around a new (irregular) vertex; larger holes stay open.
    boundary_min_edge : quads added along the design boundary (closing the staircase of
        whole lattice cells, see `fill_boundary_cells`) keep their edges at least this long.
    boundary_snap : boundary vertices of the layout within this distance of the design
        boundary glide on it; the others stay free on the surface.
    offsets : trial shifts of the integer grid per direction (offsets**2 trials); the
        extraction with the most quads is kept.
    max_turning_deg : the direction field turning faster than this per panel is reported
        (`SurfaceLayout.turning_points`).
    min_lattice_share : a layout whose full quads cover less of the design than this is
        refused (`layout_surface`): the rest would be boundary pieces as large as the gaps.
    max_gap_panels : a layout that leaves a gap of more full panels of area than this,
        after its boundary panels and patches, is refused: its lattice broke there.
    min_panels_judged : designs of fewer panels (area over the panel size squared) are
        not judged by the two limits above (a few panels' raw lattice stops a panel short
        of the boundary all round).
    """

    bisector: str = "max"
    smoothing: float = 0.5
    smoothing_tries: tuple[float, ...] = (1.0, 2.0, 4.0)
    good_coverage: float = 0.995
    max_smoothing: float = 4.0
    scale_weight: float = 0.1
    curvature_radius: int = 5
    min_edge: float = 0.4
    max_edge: float = 2.2
    fill_holes_up_to: int = 24
    boundary_min_edge: float = 0.75
    boundary_snap: float = 0.75
    offsets: int = 2
    max_turning_deg: float = 30.0
    min_lattice_share: float = 0.5
    max_gap_panels: float = 10.0
    min_panels_judged: float = 36.0
