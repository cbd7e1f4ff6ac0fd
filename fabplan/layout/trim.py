"""Boundary panels: the net's lines extended to the design boundary and cut there.

A layout's full quads stop up to a panel short of the design boundary, in steps: only
lattice cells with all four corners on the surface become quads. The facade is built to
its edges, so the strip between the net and the boundary is cut into *boundary panels*:

1. The layout's parametrization ``(phi, psi)`` (integer values are the net's lines) maps
   the design to the plane. There the design is the union of its parameter triangles
   ``D``, the net is the union of its faces ``N`` (every vertex at the parameters of its
   closest design point), and the unclad strip is ``R = D - N``. Where a seam makes the
   parameter triangles overlap (the plane holds several sheets of the design), each
   triangle loses only the net faces on its own sheet, and the parts of ``R`` on
   different sheets are cut apart (`_unclad_by_sheet`).
2. Every line of the net that ends on the net's boundary is extended straight in the
   parameter plane (the lattice lines are straight there) until it leaves ``R``. The rays
   cut ``R`` into pieces: quads, pentagons and triangles with one side on the design
   boundary, whose corners are net vertices, ray ends on the boundary, and the design
   boundary's own vertices between them (the trim outline).
3. Pieces are mapped back to the surface through the design's triangles (barycentric;
   through the exact surface's parameters for a built-in design), so corners on the
   parameter boundary land on the design's boundary curve.

Pieces smaller than `min_panel` of a full panel join the neighbour they share the longest
side with; those left that small are *extensions*, cut as part of the full panel beside
them. Unclad regions that do not reach the design boundary (a hole the layout left open
around a singularity of the directions) are cut the same way, by the lines that end on
their rim: their pieces are *patches*. Coverage is measured on the surface, independently
of the plane: samples of the design count as clad when a panel lies straight above or
below them (`_under`).

What the plane cut is then checked on the surface (`soundness`): a piece that lies off
the design (over an opening or past the boundary, `fabplan.layout.off_design`), crosses
itself, faces against the design, overlaps the net or another piece, or runs along a side
of one the same way (`fabplan.layout.overlaps`) is left out, and its place is cut again in
its tangent plane with the gaps (`fabplan.layout.gap_patches`). Where a piece's point lies
on a side of the net in the plane, it is put on that side's straight edge in space, so
that panel and face meet without a sliver. What is still wrong is measured and recorded
(`Soundness.record`).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Protocol

import igl
import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..errors import InputError
from ..net.mesh import QuadMesh
from .gap_patches import MAX_GAP_PANELS, gap_patches, outline_triangles, unclad_components
from .off_design import MIN_OFF_PANELS, OffDesign, area_off_design
from .overlaps import edge_clashes, overlapping_pairs, self_crossing

if TYPE_CHECKING:
    from ..solve.optimize import OptimizationResult

__all__ = ["BoundaryPanels", "ChartedLayout", "ParameterChart", "Soundness", "trim_to_design",
           "add_boundary_panels", "read_boundary_panels", "net_cover", "net_coverage", "soundness",
           "slide_splits"]



class ChartedLayout(Protocol):
    """What trimming asks of a layout: its design and panel size, its parameter chart
    and the transitions across its cuts (`fabplan.layout.surface_layout.SurfaceLayout`
    is one). Declared here, so that trimming does not import the layout that calls it."""

    @property
    def design(self) -> DesignSurface:
        """The design the layout lies on."""

    @property
    def panel_size(self) -> float:
        """Target edge length (model units)."""

    @property
    def chart(self) -> ParameterChart:
        """The design in the plane of the layout's parameters."""

    @property
    def cuts(self) -> list:
        """Transitions ``(sign, jump_phi, jump_psi)`` across the layout's cuts."""

@dataclass
class BoundaryPanels:
    """The panels between a net and the design boundary, and the coverage they give.

    Attributes
    ----------
    vertices : (m, 3) float, the net's vertices (first `net_vertex_count` rows, unchanged)
        followed by the new corners and trim-outline points (on the design surface, or
        off it with the net for `follows_net`).
    polygons : list of (k,) int arrays, each boundary panel's outline into `vertices`,
        counter-clockwise about the surface normal, following the design boundary.
    net_vertex_count : number of the net's vertices at the head of `vertices`.
    on_boundary : (m,) bool, points on the design's boundary curve.
    corner : (m,) bool, panel corners: net vertices, ends of the extended lines and
        crossings off the boundary (the other points follow the boundary curve).
    neighbour_face : (p,) int, the net face each panel continues: the one it shares its
        longest side with, else (a corner cell, a sliver) the nearest one.
    area : (p,) float, area of each panel on the design (model units squared).
    panel_size : the layout's panel size.
    coverage_net : share of the design's area the net's full panels cover.
    coverage : share covered by the full and the boundary panels together.
    flipped : (k,) int, panels that face against the design (none in a sound result).
    crossed : (k,) int, panels whose outline crosses itself (none in a sound result; see
        `_untangled`; slivers along the boundary curve, `extension`, are not listed).
    patch : (p,) bool, the panels that close a hole inside the net (not reaching the
        design boundary).
    extension : (p,) bool, slivers under `min_panel` of a full panel along the side of a
        full panel: made as part of that panel (cut larger from its mold), not as panels
        of their own.
    boundary_distance_max : largest distance of a point flagged `on_boundary` from the
        design's boundary curve (the exact one for a built-in design), in panel sizes
        (with `follows_net`, lifted points: about the lift there).
    soundness : what is wrong with the net and its panels, measured on the surface
        (`Soundness.record`: ``off_design`` and ``crossings``); empty where unknown.
    follows_net : the points off the net stand off the design as the net does beside
        them (`trim_to_design(..., follow_net=True)`); offset_max : the largest such lift
        (model units).
    seconds : time taken.
    triangles : (t, 3) int into `vertices`, the panels cut into triangles in the plane of
        the parametrization (concave outlines stay whole), or None; triangle_panel :
        (t,) int, the panel of each (see `panel_triangles`).
    net_on_boundary : (n,) bool, the net's vertices on the design boundary (to a
        `touch` of a panel); empty where unknown.
    gaps : the largest parts of the design no panel covers (`coverage_gaps`), largest
        first.
    """

    vertices: np.ndarray
    polygons: list
    net_vertex_count: int
    on_boundary: np.ndarray
    corner: np.ndarray
    neighbour_face: np.ndarray
    area: np.ndarray
    panel_size: float
    coverage_net: float
    coverage: float
    flipped: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    crossed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    patch: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    extension: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    boundary_distance_max: float = 0.0
    seconds: float = 0.0
    triangles: np.ndarray | None = None
    triangle_panel: np.ndarray | None = None
    net_on_boundary: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gaps: list = field(default_factory=list)
    follows_net: bool = False
    offset_max: float = 0.0
    soundness: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        """All pieces, extensions of full panels included (the rows of every array)."""
        return len(self.polygons)

    @property
    def panel_count(self) -> int:
        """The boundary panels made as panels of their own (not extensions)."""
        return int(np.sum(~self.extension))

    def panel_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """The panels as triangles: (t, 3) int into `vertices` and (t,) int, the panel of
        each; those of the trimming when kept, else a fan from each outline's first point
        (right for the convex outlines of most boundary panels).

        Examples
        --------
        >>> panels = BoundaryPanels(np.zeros((5, 3)), [np.array([0, 1, 2, 3]), np.array([1, 4, 2])],
        ...                         0, np.zeros(5, bool), np.zeros(5, bool), np.zeros(2, int),
        ...                         np.ones(2), 1.0, 1.0, 1.0)
        >>> triangles, panel = panels.panel_triangles()
        >>> triangles.tolist(), panel.tolist()
        ([[0, 1, 2], [0, 2, 3], [1, 4, 2]], [0, 0, 1])
        """
        if self.triangles is not None and self.triangle_panel is not None:
            return np.asarray(self.triangles, np.int64), np.asarray(self.triangle_panel, np.int64)
        if not self.polygons:
            return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
        sizes = np.array([len(q) for q in self.polygons])
        ids = np.concatenate(self.polygons).astype(np.int64)
        start = np.r_[0, np.cumsum(sizes)[:-1]]
        panel = np.repeat(np.arange(len(sizes)), np.maximum(sizes - 2, 0))
        j = np.arange(len(panel)) - np.repeat(np.r_[0, np.cumsum(np.maximum(sizes - 2, 0))[:-1]],
                                              np.maximum(sizes - 2, 0)) + 1
        first = start[panel]
        return np.stack([ids[first], ids[first + j], ids[first + j + 1]], axis=1), panel

    @property
    def on_design_boundary(self) -> np.ndarray:
        """(m,) bool, the points on the design's boundary curve: the new corners and
        outline points there (`on_boundary`) and the net's vertices there
        (`net_on_boundary`)."""
        out = np.asarray(self.on_boundary, bool).copy()
        on_net = np.asarray(self.net_on_boundary, bool)
        out[:len(on_net)] |= on_net
        return out

    def corner_counts(self) -> np.ndarray:
        """(p,) int, corners of each panel: net vertices and ends of the extended lines
        (points of the trim outline between them are not corners)."""
        return np.array([int(self.corner[p].sum()) for p in self.polygons], dtype=np.int64)

    def record(self) -> dict:
        """JSON-ready summary."""
        full = self.panel_size ** 2
        own = self.area[~self.extension]
        return {
            "count": self.panel_count,
            "extensions": np.flatnonzero(self.extension).tolist(),
            "coverage_net": self.coverage_net,
            "coverage": self.coverage,
            "area_relative_to_panel": None if not self.panel_count else {
                "min": float(own.min() / full), "max": float(own.max() / full),
                "mean": float(own.mean() / full)},
            "corners": {str(k): int(c) for k, c in
                        enumerate(np.bincount(self.corner_counts()[~self.extension])) if c},
            "outline_points_max": max((len(p) for p in self.polygons), default=0),
            "flipped": self.flipped.tolist(),
            "crossed": np.asarray(self.crossed, np.int64).tolist(),
            "boundary_distance_max_relative_to_panel": self.boundary_distance_max,
            "patches": np.flatnonzero(self.patch).tolist(),
            # the points on the design's boundary curve: the new ones and the net's vertices
            "on_design_boundary": np.flatnonzero(self.on_design_boundary).tolist(),
            "uncovered": 1.0 - self.coverage,
            "gaps": self.gaps,
            # a net optimized off its design: its boundary panels stand off it with it
            "follow_net": self.follows_net,
            "offset_from_design_max_relative_to_panel": self.offset_max / self.panel_size,
            **self.soundness,
            "seconds": round(self.seconds, 4),
        }

    def obj_text(self, header: str = "") -> str:
        """OBJ text of the boundary panels: `vertices` (the net's first, numbered as in
        the net's OBJ) and one polygon face per panel."""
        from ..io.obj import format_obj

        return format_obj(self.vertices, self.polygons, header)


#: a net vertex this close to the design boundary (in panel sizes) is on it: a net held on
#: the design glides there; a net that leaves the design (OFF_DESIGN_TOUCH) ends a few
#: millimetres inside, and the strip between is no panel (a boundary member covers it)
TOUCH = 1e-3
OFF_DESIGN_TOUCH = 1e-2


def trim_to_design(mesh: QuadMesh, layout: ChartedLayout, *, min_panel: float = 0.05,
                   touch: float = TOUCH, patch_gaps: bool = True,
                   follow_net: bool = False, follow: tuple | None = None) -> BoundaryPanels:
    """The boundary panels of a net laid out on a design (see the module's text).

    Parameters
    ----------
    mesh : the net (a layout's mesh, or the net solved from it: same faces, vertices
        within a small distance of the design).
    layout : the layout the net comes from (`ChartedLayout`: design, chart, cuts; a
        `fabplan.layout.surface_layout.SurfaceLayout`).
    min_panel : pieces smaller than this share of a full panel's area join a neighbour.
    touch : net vertices this close to the design boundary (panel sizes) are on it.
    patch_gaps : close the small gaps left with patches cut in their tangent planes
        (`fabplan.layout.gap_patches`); off, the lattice is judged as it is.
    follow_net : the net left the design (optimized off it): the panels' points off the
        net stand off the design as the net does near them (`_follow_net`), so that a
        boundary panel continues its net instead of stepping down to the design.
    follow : with `follow_net`, ``(points, surface)``: the points (k, 3) the panels
        follow instead of the net's vertices, and the surface they stand off (a net
        solved past the design's edge on the design continued there, and that
        continuation: `fabplan.layout.margin`). Default: the net and the design.

    Returns
    -------
    BoundaryPanels
    """
    clock = time.perf_counter()
    design, h = layout.design, layout.panel_size
    chart = layout.chart
    p_net, cell, grid, touching = _net_in_plane(mesh, chart, design, h, touch)
    by_sheet = bool(layout.cuts) and chart.overlapping
    pieces, rays, patch, sheets = _pieces_in_plane(mesh, layout.cuts, chart, p_net, touching,
                                                   by_sheet, cell, grid, min_panel, h)
    vertices, polygons, on_boundary, corner, on_side, triangles, owner, patch = \
        _pieces_on_surface(pieces, rays, patch, sheets, mesh, p_net, chart, touching, by_sheet,
                           4 * grid, h)
    offset = np.zeros((0, 3))
    # where the panels stand over the design: their points before the lift (which is
    # along the design's normals)
    footprint = vertices
    followed = (mesh.vertices, design) if follow is None else follow
    if follow_net and len(vertices) > mesh.vertex_count:
        # lifted before the outlines are checked: what crosses is judged where it is cut
        offset = _follow_net(vertices[mesh.vertex_count:], *followed)
        # the points on the net's sides are where the net is already
        offset[on_side[mesh.vertex_count:]] = 0.0
        vertices = vertices.copy()
        vertices[mesh.vertex_count:] += offset
    polygons, changed, crossed = _untangled(vertices, polygons, corner)
    triangles, owner = _retriangulated(vertices, polygons, triangles, owner, changed)
    recut, recut_area = 0, 0.0
    if patch_gaps:
        # checked on the surface: what the plane cut wrongly (off the design, over a hole;
        # crossing itself; facing against the design; over the net or another panel) is
        # left out, and its place is cut again in its tangent plane with the gaps below
        unsound = _unsound_pieces(footprint, polygons, triangles, owner, mesh, design, h)
        recut = int(unsound.sum())
        T = footprint[triangles[unsound[owner]]]
        recut_area = float(0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]),
                                                axis=1).sum())
        polygons, triangles, owner, patch = _without_pieces(polygons, triangles, owner, patch,
                                                            unsound)
    # coverage is measured on the surface, independently of the plane (`_under`), by the
    # panels' footprints: lifted with a net that leaves the design, a panel tilts against
    # it where the lift changes fast (a corner), and would seem to leave a gap beside it
    samples, normals, weight = _design_samples(design)
    on_net = _clad(samples, normals, mesh.vertices, mesh.triangles(), h)
    on_any = on_net | _clad(samples, normals, footprint,
                            np.vstack([mesh.triangles(), triangles]), h)
    # the small gaps left (pieces around singular points the plane could not cut) are
    # cut in their own tangent planes
    # a gap where pieces were left out is no failure of the layout: it is patched however
    # large those pieces were
    extra = gap_patches(design, footprint, np.vstack([mesh.triangles(), triangles]), on_any, h,
                        max_panels=MAX_GAP_PANELS + recut_area / (h * h)) if patch_gaps else None
    if extra is not None and extra.count:
        owner = np.r_[owner, len(polygons) + extra.owner]
        lifted = np.zeros((len(extra.points), 3))
        if follow_net and len(extra.points):
            # the patches' new points are on the design: they stand off it with the net too
            lifted = _follow_net(extra.points, *followed)
            offset = np.vstack([offset, lifted])
        vertices = np.vstack([vertices, extra.points + lifted])
        footprint = np.vstack([footprint, extra.points])
        polygons = polygons + extra.polygons
        triangles = np.vstack([triangles, extra.triangles])
        patch = np.r_[patch, np.ones(extra.count, bool)]
        on_boundary = np.r_[on_boundary, extra.on_boundary]
        corner = np.r_[corner, ~extra.on_boundary]
        on_any |= _clad(samples, normals, footprint, np.vstack([mesh.triangles(), triangles]), h)
    if extra is not None and extra.count:
        # a patch's outline may run out along the boundary past a neighbour's corner and
        # back (a sliver of no width between the two): the spike goes
        polygons, changed, _ = _untangled(vertices, polygons, corner)
        triangles, owner = _retriangulated(vertices, polygons, triangles, owner, changed)
        # a patch cut in its plane that still clashes (rare) is left out: a gap, reported
        unsound = _unsound_pieces(footprint, polygons, triangles, owner, mesh, design, h)
        if unsound.any():
            polygons, triangles, owner, patch = _without_pieces(polygons, triangles, owner,
                                                                patch, unsound)
            on_any = on_net | _clad(samples, normals, footprint,
                                    np.vstack([mesh.triangles(), triangles]), h)
    T = vertices[triangles]
    tri_area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    area = np.bincount(owner, tri_area, minlength=len(polygons))
    neighbour = _neighbour_faces(polygons, mesh, vertices)
    extension = area < min_panel * h * h
    flipped = _flipped(vertices, polygons, design, 1e-3 * h * h)
    crossed = np.flatnonzero(self_crossing(vertices, polygons))
    sound = soundness(vertices, polygons, triangles, owner, mesh, design, h)
    return BoundaryPanels(
        vertices=vertices, polygons=polygons, net_vertex_count=mesh.vertex_count,
        on_boundary=on_boundary, corner=corner, neighbour_face=neighbour,
        area=area, panel_size=h, extension=extension,
        coverage_net=float(weight[on_net].sum() / weight.sum()),
        coverage=float(weight[on_any].sum() / weight.sum()),
        flipped=flipped[~extension[flipped]], crossed=crossed, patch=patch,
        boundary_distance_max=_boundary_distance(design, vertices[on_boundary]) / h,
        seconds=time.perf_counter() - clock, triangles=triangles, triangle_panel=owner,
        net_on_boundary=touching, gaps=coverage_gaps(design, samples, weight, on_any, h),
        follows_net=follow_net,
        offset_max=float(np.linalg.norm(offset, axis=1).max()) if len(offset) else 0.0,
        soundness=sound.record(h, recut))


def _net_in_plane(mesh: QuadMesh, chart: ParameterChart, design: DesignSurface, h: float,
                  touch: float) -> tuple[np.ndarray, float, float, np.ndarray]:
    """The net's vertices in the parameter plane, snap-rounded, and which stand on the
    design boundary (`trim_to_design`).

    Returns
    -------
    p_net : (n, 2) float, the vertices' parameters, rounded to `grid`.
    cell : area of a full panel in the plane.
    grid : the snap-rounding grid of every overlay.
    touching : (n,) bool, vertices within `touch` (panel sizes) of the boundary.
    """
    p_net = chart.parameters_of(mesh.vertices)
    # a full panel in the plane: about one unit square of the lattice
    cell = float(np.median(np.abs(chart.param_area))) * h * h / float(np.median(design.face_areas))
    cell = cell if np.isfinite(cell) and cell > 0 else 1.0
    # every overlay is snap-rounded to this grid (a ten-millionth of a panel), so that a
    # vertex on a boundary segment to rounding is noded there
    grid = 1e-7 * cell ** 0.5
    p_net = np.round(p_net / grid) * grid
    boundary = chart.boundary_lines
    # a vertex on the boundary (to `touch` of a panel: gliding, or added on it)
    # ends its lines there; a line continued from it would run along the boundary. It is
    # joined to the boundary by the shortest way instead, which parts the slivers beside it
    points = shapely.points(p_net)
    touching = shapely.distance(points, boundary) <= touch * cell ** 0.5
    if touch > TOUCH and touching.any():
        # a net that left the design: its vertices that near the boundary stand on it in
        # the plane, so that no strip a few millimetres wide is cut beside them
        foot = shapely.get_coordinates(
            shapely.shortest_line(points[touching], boundary)).reshape(-1, 2, 2)[:, 1]
        p_net[touching] = np.round(foot / grid) * grid
    return p_net, cell, grid, touching


def _pieces_in_plane(mesh: QuadMesh, cuts: list, chart: ParameterChart, p_net: np.ndarray,
                     touching: np.ndarray, by_sheet: bool, cell: float, grid: float,
                     min_panel: float, h: float) -> tuple:
    """The unclad strip of the plane cut into pieces by the net's lines (`trim_to_design`,
    steps 1 and 2 of the module's text).

    Returns
    -------
    pieces, rays : (k,) object arrays of shapely geometry, the pieces and the rays that
        cut them.
    patch : (k,) bool, pieces of holes (not on the design boundary).
    sheets : None, or with `by_sheet` ``(rest, rest_triangle, rest_region, piece_region)``
        (`_unclad_by_sheet`, and the region (k,) each piece was cut from).
    """
    boundary = chart.boundary_lines
    faces = _face_polygons(mesh, p_net, _transition_maps(cuts))
    if by_sheet:
        # across a seam the plane holds several sheets of the design: each triangle loses
        # only the net faces on its own sheet
        rest, rest_triangle, rest_region, regions = _unclad_by_sheet(
            chart, faces, mesh, h, grid, 1e-6 * cell)
    else:
        net = shapely.union_all(_polygonal(shapely.make_valid(faces)), grid_size=grid)
        domain = shapely.union_all(_polygonal([shapely.set_precision(chart.domain, grid)]),
                                   grid_size=grid)
        regions = [shapely.union_all(_polygonal([shapely.difference(domain, net, grid_size=grid)]),
                                     grid_size=grid)]
    # regions of different sheets may overlap in the plane: each is cut on its own
    cut = [_cut_region(unclad, mesh, p_net, boundary, touching, cell, grid, min_panel)
           for unclad in regions]
    pieces = np.concatenate([c[0] for c in cut] + [np.zeros(0, dtype=object)])
    rays = np.concatenate([c[1] for c in cut] + [np.zeros(0, dtype=object)])
    patch = np.concatenate([c[2] for c in cut] + [np.zeros(0, bool)])
    sheets = None
    if by_sheet:
        piece_region = np.repeat(np.arange(len(cut)), [len(c[0]) for c in cut])
        sheets = (rest, rest_triangle, rest_region, piece_region)
    return pieces, rays, patch, sheets


def _pieces_on_surface(pieces: np.ndarray, rays: np.ndarray, patch: np.ndarray,
                       sheets: tuple | None, mesh: QuadMesh, p_net: np.ndarray,
                       chart: ParameterChart, touching: np.ndarray, by_sheet: bool,
                       tol: float, h: float) -> tuple:
    """The pieces of the plane mapped to the surface (`_to_surface`, step 3 of the
    module's text), less those that map across a seam or clad the design twice.

    Returns
    -------
    vertices, polygons, on_boundary, corner, on_side : as `_to_surface` gives them.
    triangles, owner : the pieces' triangles (m, 3) int and the piece (m,) of each.
    patch : (k',) bool, `patch` of the pieces kept.
    """
    design, boundary = chart.design, chart.boundary_lines
    vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
        pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
    # a piece over a seam of the parametrization, where the plane holds several sheets
    # of the design, may map to points of different sheets: its sides then stretch far
    # beyond their length in the plane (about a panel per unit). Such pieces are left
    # out and their area counted as unclad
    sane = _sane_on_surface(pieces, vertices, polygons, h)
    if not sane.all():
        pieces = pieces[sane]
        if sheets is not None:
            sheets = (*sheets[:3], sheets[3][sane])
        vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
            pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
    patch = patch[sane]
    triangles, owner = _triangles_on_surface(pieces, ring_ids)
    # near a singular point the plane's sheets overlap, and a "hole" there may lie under
    # net faces on the surface: such a patch would clad the design twice. Cut by sheet,
    # any piece may: along a seam a face whose corners lie on both sides is folded in the
    # plane and leaves part of the triangles under it unclad there
    double = (patch | by_sheet) & \
        (_share_under(vertices, triangles, owner, len(pieces), mesh, h) > 0.5)
    if by_sheet:
        # a piece of a hole at a singular point, where the sheets meet, may map across
        # the fold there: it faces against the design and overlaps its neighbours
        double[_flipped(vertices, polygons, design, 1e-3 * h * h)] = True
    if double.any():
        pieces, patch = pieces[~double], patch[~double]
        if sheets is not None:
            sheets = (*sheets[:3], sheets[3][~double])
        vertices, polygons, on_boundary, corner, ring_ids, on_side = _to_surface(
            pieces, mesh, p_net, chart, boundary, rays, tol, touching, sheets)
        triangles, owner = _triangles_on_surface(pieces, ring_ids)
    return vertices, polygons, on_boundary, corner, on_side, triangles, owner, patch


@dataclass
class Soundness:
    """What is wrong with a cladding (a net and its boundary panels), measured on the
    surface: nothing in a sound one.

    Attributes
    ----------
    off_net : `OffDesign` of the net's faces (over a hole, or past the design boundary).
    off_panels : `OffDesign` of the boundary panels.
    crossing : (k,) int, panels whose outline crosses itself (`self_crossing`).
    overlaps : (m, 2) int, pairs of pieces that cover the same part of the surface
        (`overlapping_pairs`); overlap_area (m,) float, the area each shares.
    clashes : (c, 2) int, pairs of pieces that use a side in the same direction
        (`edge_clashes`). Pieces in `overlaps` and `clashes` are numbered the net's
        `faces` first, then the panels.
    faces : the number of the net's faces.
    """

    off_net: OffDesign
    off_panels: OffDesign
    crossing: np.ndarray
    overlaps: np.ndarray
    overlap_area: np.ndarray
    clashes: np.ndarray
    faces: int

    def _piece(self, k: int) -> dict:
        return {"face": int(k)} if k < self.faces else {"panel": int(k - self.faces)}

    def record(self, panel_size: float, cut_again: int = 0) -> dict:
        """JSON-ready: ``off_design`` (the area of panels off the design: over a hole or
        past its boundary, an error; where the largest pieces are) and ``crossings``
        (counts of panels crossing themselves, pairs of pieces overlapping and sides
        used twice the same way, with the pieces named; the panels cut again on the
        surface)."""
        least = MIN_OFF_PANELS * panel_size ** 2
        net_area = self.off_net.area[self.off_net.area > least]
        panel_area = self.off_panels.area[self.off_panels.area > least]
        total = float(net_area.sum() + panel_area.sum())
        places = self.off_net.places(least, label="face") + \
            self.off_panels.places(least, label="panel")
        places.sort(key=lambda p: -p["area"])
        return {
            "off_design": {
                "area": total, "area_relative_to_panel": total / panel_size ** 2,
                "faces": int(len(net_area)), "panels": int(len(panel_area)),
                "places": places[:5]},
            "crossings": {
                "self_crossing": int(len(self.crossing)),
                "overlapping": int(len(self.overlaps)),
                "edge_clashes": int(len(self.clashes)),
                "pairs": [[self._piece(a), self._piece(b)] for a, b in
                          np.concatenate([self.overlaps, self.clashes]).tolist()][:10],
                "cut_again": int(cut_again)},
        }


def soundness(vertices: np.ndarray, polygons: list, triangles: np.ndarray, owner: np.ndarray,
              mesh: QuadMesh, design: DesignSurface, h: float) -> Soundness:
    """The `Soundness` of a net `mesh` and its boundary panels (`polygons` into `vertices`,
    cut into `triangles` of `owner` each) on `design`, panel size `h`."""
    from .off_design import faces_off_design

    pieces = list(mesh.faces) + list(polygons)
    overlaps, shared = overlapping_pairs(vertices, pieces, len(mesh.face_sizes), h)
    return Soundness(
        off_net=faces_off_design(design, vertices, mesh.faces, h),
        off_panels=area_off_design(design, vertices, triangles, owner, len(polygons), h),
        crossing=np.flatnonzero(self_crossing(vertices, polygons)),
        overlaps=overlaps, overlap_area=shared,
        clashes=edge_clashes(pieces, len(vertices)), faces=len(mesh.face_sizes))


def _unsound_pieces(vertices: np.ndarray, polygons: list, triangles: np.ndarray,
                    owner: np.ndarray, mesh: QuadMesh, design: DesignSurface, h: float
                    ) -> np.ndarray:
    """(p,) bool, the panels that are off the design, cross themselves, face against it,
    overlap a net face or an earlier panel, or share a side with one the same way."""
    sound = soundness(vertices, polygons, triangles, owner, mesh, design, h)
    bad = np.zeros(len(polygons), bool)
    bad[sound.crossing] = True
    bad[sound.off_panels.area > MIN_OFF_PANELS * h * h] = True
    bad[_flipped(vertices, polygons, design, 1e-3 * h * h)] = True
    # of two panels that overlap, the later goes (a patch cut twice, from two gaps that
    # meet, is kept once); a panel over a net face goes
    for pairs in (sound.overlaps, sound.clashes):
        bad[pairs.max(axis=1) - sound.faces] = True
    return bad


def _without_pieces(polygons: list, triangles: np.ndarray, owner: np.ndarray, patch: np.ndarray,
                    drop: np.ndarray) -> tuple[list, np.ndarray, np.ndarray, np.ndarray]:
    """The panels less those marked in `drop` (p,) bool: their outlines, triangles (t, 3)
    with the panel of each renumbered, and `patch` (p,) bool."""
    keep = ~np.asarray(drop, bool)
    new_id = np.cumsum(keep) - 1
    kept = keep[owner]
    return ([q for q, k in zip(polygons, keep, strict=True) if k], triangles[kept],
            new_id[owner[kept]], patch[keep])


def _follow_net(points: np.ndarray, net: np.ndarray, design: DesignSurface,
                neighbours: int = 4) -> np.ndarray:
    """(m, 3) float, how far the net stands off the design near each point of the design
    (`points` (m, 3)), along the design's normal there: the signed normal distances of the
    `neighbours` nearest net vertices (`net` (n, 3)) from the design, weighted by the
    inverse square of their footpoints' distances to the point (a point at a footpoint
    takes that vertex's distance)."""
    foot, _, tri = design.reference.closest_points(net)
    # measured to the exact surface where there is one (a built-in or NURBS design)
    along = np.sum((net - design.closest_points(net)) * design.face_normals[tri], axis=1)
    k = min(neighbours, len(net))
    d, near = cKDTree(foot).query(points, k=k)
    d, near = d.reshape(len(points), k), near.reshape(len(points), k)
    weight = 1.0 / np.maximum(d, 1e-12) ** 2
    carried = np.sum(weight * along[near], axis=1) / np.sum(weight, axis=1)
    _, _, at = design.reference.closest_points(points)
    return carried[:, None] * design.face_normals[at]


def read_boundary_panels(mesh: QuadMesh, path: str | os.PathLike,
                         record: dict | None = None) -> BoundaryPanels:
    """The boundary panels of `mesh` from the ``NET.boundary.obj`` a layout, an optimize or
    a study writes beside ``NET.obj``.

    The file holds the panels' outlines; what it does not hold is rebuilt: the face each
    panel continues (`BoundaryPanels.neighbour_face`, as `trim_to_design` chooses it), the
    panels' areas (of their outlines' fans), and their corners (net vertices, and points
    two polygons share: the ends of the extended lines; the points between are the trim
    outline's). `record` (``properties.boundary_panels`` of ``NET.json``) gives the
    slivers, the patches, the points on the design boundary and the coverage, where known;
    the panel size is taken as the net's mean edge.

    Raises
    ------
    InputError
        When the file does not continue `mesh`: fewer vertices than the net, or the net's
        vertices moved (the net was changed after its boundary panels were cut); or when
        a panel runs along a side of the net or of another panel the same way (they
        overlap), naming the panel by its face in the file.
    """
    from ..io.obj import read_obj

    vertices, polygons = read_obj(path)
    n = mesh.vertex_count
    scale = max(float(np.ptp(mesh.vertices, axis=0).max()), 1e-300)
    if len(vertices) < n or not np.allclose(vertices[:n], mesh.vertices, atol=1e-6 * scale):
        raise InputError(f"{path}: its first {n} vertices are not the net's {mesh.name} "
                         "(boundary panels of another net, or of the net before it was "
                         "changed?); cut them again or use --no-boundary")
    polygons = [np.asarray(q, np.int64) for q in polygons]
    # the net's own faces are no boundary panels (the net given as its own boundary file)
    faces = {tuple(sorted(f.tolist())) for f in mesh.faces}
    own = [k for k, q in enumerate(polygons) if tuple(sorted(q.tolist())) in faces]
    if own:
        raise InputError(f"{path}: face {own[0] + 1} is a face of the net {mesh.name}, not a "
                         "boundary panel (the net itself given as its boundary file?); give "
                         "NET.boundary.obj or use --no-boundary")
    vertices = np.asarray(vertices, float)
    # a panel on a side of the net or of another panel the same way folds over it: named
    # by its face in the file (numbered from 1, as in the OBJ), not in a combined mesh
    clash = edge_clashes(list(mesh.faces) + polygons, len(vertices))
    if len(clash):
        a, b = (int(k) for k in clash[0])
        f = len(mesh.face_sizes)
        other = f"face {a + 1} of the net {mesh.name}" if a < f else f"face {a - f + 1}"
        raise InputError(f"{path}: face {b - f + 1} (boundary panel {b - f}) runs along a side "
                         f"of {other} the same way (the two overlap): cut the boundary panels "
                         "again with fabplan, or use --no-boundary")
    record = record or {}
    p = len(polygons)
    flags = {key: np.isin(np.arange(p), np.asarray(record.get(key, []), np.int64))
             for key in ("extensions", "patches")}
    on = np.zeros(len(vertices), bool)
    on[[i for i in record.get("on_design_boundary", []) if 0 <= i < len(vertices)]] = True
    on_boundary, net_on_boundary = on.copy(), on[:n].copy()
    on_boundary[:n] = False
    ids = np.concatenate(polygons) if p else np.zeros(0, np.int64)
    owner = np.repeat(np.arange(p), [len(q) for q in polygons])
    nxt = np.concatenate([np.roll(q, -1) for q in polygons]) if p else ids
    newell = np.zeros((p, 3))
    np.add.at(newell, owner, 0.5 * np.cross(vertices[ids], vertices[nxt]))
    shared = np.bincount(np.r_[ids, mesh.face_indices], minlength=len(vertices))
    corner = (np.arange(len(vertices)) < n) | (shared >= 2)
    coverage = record.get("coverage", math.nan)
    return BoundaryPanels(
        vertices=vertices, polygons=polygons, net_vertex_count=n,
        on_boundary=on_boundary, corner=corner,
        neighbour_face=_neighbour_faces(polygons, mesh, vertices),
        area=np.linalg.norm(newell, axis=1), panel_size=mesh.mean_edge_length,
        coverage_net=record.get("coverage_net", math.nan), coverage=coverage,
        patch=flags["patches"], extension=flags["extensions"], net_on_boundary=net_on_boundary,
        flipped=_ids(record.get("flipped"), p), crossed=_ids(record.get("crossed"), p),
        gaps=list(record.get("gaps") or []),
        soundness={key: record[key] for key in ("off_design", "crossings") if key in record})


def slide_splits(panels: BoundaryPanels, ids: np.ndarray, origins: np.ndarray,
                 directions: np.ndarray, *, reach: float
                 ) -> tuple[BoundaryPanels, np.ndarray]:
    """Where two boundary panels part on the design boundary, moved along it onto given
    lines: the point ``ids[i]``, the end on the design boundary of a side two panels share,
    slides along the boundary to where the line through ``origins[i]`` along
    ``directions[i]`` passes closest to it, and is put on that line; the boundary's points
    it passes go over from one panel to the other.

    The point slides between the two panels' next corners on the boundary (points of the
    net, or shared with another panel; it stays where it is where the line passes
    closest at or beyond one of them, leaving a panel without a rim), and only where the
    line passes within `reach` of the boundary. Points shared by more than two panels
    stay too. What it does depends only on what ``NET.boundary.obj`` and its record hold
    (`read_boundary_panels`), so that panels read back slide as they did when cut. The
    panels changed are cut into triangles again and their areas measured again.

    Parameters
    ----------
    panels : `BoundaryPanels`.
    ids : (k,) int, points of ``panels.vertices`` on the design boundary.
    origins, directions : (k, 3) float, the lines (model units; any length but zero).
    reach : how far from the boundary a line may pass (model units); points within a
        hundredth of it of a moved point are dropped (no side of no length).

    Returns
    -------
    panels : a copy of `panels` with the points moved.
    moved : (k,) bool, the points of `ids` that moved.

    Examples
    --------
    Two panels on the boundary ``y = 0`` between the net's vertices 0, 1 and 2, parting at
    the point 3 (``x = 1``), moved onto ``x = 1.4`` and ``x = 1.7``, past the point 4:

    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [2, 0, 0], [1, 1, 0], [1, 0, 0], [1.5, 0, 0]])
    >>> polygons = [np.array([0, 3, 2]), np.array([3, 4, 1, 2])]
    >>> on = np.array([True, True, False, True, True])
    >>> panels = BoundaryPanels(V, polygons, 3, on, ~on, np.zeros(2, int), np.ones(2), 1.0,
    ...                         1.0, 1.0)
    >>> up = np.array([[0.0, 1, 0]])
    >>> moved, ok = slide_splits(panels, np.array([3]), np.array([[1.4, 1, 0]]), up, reach=0.1)
    >>> ok.tolist(), moved.vertices[3].tolist(), [q.tolist() for q in moved.polygons]
    ([True], [1.4, 0.0, 0.0], [[0, 3, 2], [3, 4, 1, 2]])
    >>> moved, ok = slide_splits(panels, np.array([3]), np.array([[1.7, 1, 0]]), up, reach=0.1)
    >>> moved.vertices[3].tolist(), [q.tolist() for q in moved.polygons]
    ([1.7, 0.0, 0.0], [[0, 4, 3, 2], [3, 1, 2]])
    """
    ids = np.asarray(ids, np.int64)
    moved = np.zeros(len(ids), bool)
    polygons = [np.asarray(q, np.int64).copy() for q in panels.polygons]
    if not len(ids) or not polygons:
        return panels, moved
    V = np.array(panels.vertices, dtype=np.float64)
    on = panels.on_design_boundary
    d = np.asarray(directions, float)
    d = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    # the panels holding each point (a point moves only its two panels' outlines; which
    # panels hold it never changes, nor which points are corners)
    flat = np.concatenate(polygons)
    owner = np.repeat(np.arange(len(polygons)), [len(q) for q in polygons])
    corner = np.bincount(flat, minlength=len(V)) >= 2
    corner[:panels.net_vertex_count] = True
    changed: set = set()
    for i, r in enumerate(ids):
        holders = np.unique(owner[flat == r])
        if len(holders) != 2 or not on[r]:
            continue
        ends = _rim_chains(polygons, holders, r, on, corner)
        if ends is None:
            continue
        (fwd, at_f, chain_f), (bwd, at_b, chain_b) = ends
        C = np.r_[chain_b[::-1], chain_f]               # corner .. corner, through r
        if len(C) < 2:
            continue
        S0, E = V[C[:-1]], V[C[1:]] - V[C[:-1]]
        # the line's closest approach to every segment of the boundary between the corners
        w = origins[i] - S0
        b, c = E @ d[i], np.sum(E * E, axis=1)
        denom = np.maximum(c - b * b, 1e-300)
        u = np.clip((np.sum(E * w, axis=1) - b * (w @ d[i])) / denom, 0.0, 1.0)
        s = u * b - w @ d[i]
        gap = np.linalg.norm(origins[i] + s[:, None] * d[i] - S0 - u[:, None] * E, axis=1)
        j = int(np.argmin(gap))
        foot = S0[j] + u[j] * E[j]
        eps = 1e-2 * reach
        if (gap[j] > reach or np.linalg.norm(foot - V[C[0]]) <= eps
                or np.linalg.norm(foot - V[C[-1]]) <= eps):
            continue
        # points within a thousandth of a panel of the new place go (no side of no length)
        length = np.sqrt(c[j])
        keep_b = C[:j + 1] if (u[j] * length > eps or j == 0) else C[:j]
        keep_f = C[j + 1:] if ((1 - u[j]) * length > eps or j + 1 == len(C) - 1) else C[j + 2:]
        for k, ring in ((bwd, np.r_[np.roll(polygons[bwd], -at_b)[:len(polygons[bwd]) - len(chain_b)],
                                    keep_b]),
                        (fwd, np.r_[r, keep_f, np.roll(polygons[fwd], -at_f)[1 + len(chain_f):]])):
            # each outline starts where it did, where that point is still in it
            start = np.flatnonzero(ring == polygons[k][0])
            polygons[k] = np.roll(ring, -int(start[0])) if len(start) else ring
        V[r] = origins[i] + s[j] * d[i]
        moved[i] = True
        changed.update((int(fwd), int(bwd)))
    if not changed:
        return panels, moved
    which = np.array(sorted(changed), np.int64)
    triangles, triangle_panel = panels.triangles, panels.triangle_panel
    if triangles is not None and triangle_panel is not None:
        triangles, triangle_panel = _retriangulated(V, polygons, np.asarray(triangles, np.int64),
                                                    np.asarray(triangle_panel, np.int64), which)
    out = replace(panels, vertices=V, polygons=polygons, triangles=triangles,
                  triangle_panel=triangle_panel)
    T, panel = out.panel_triangles()
    P = V[T]
    area = np.bincount(panel, 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]),
                                                   axis=1), minlength=len(polygons))
    out.area = np.where(np.isin(np.arange(len(polygons)), which), area, panels.area)
    return out, moved


def _rim_chains(polygons: list, holders: np.ndarray, r: int, on: np.ndarray,
                corner: np.ndarray) -> tuple | None:
    """The two panels `holders` parting at the boundary point `r`: for the one whose
    shared side runs towards `r` and then the other, ``(panel, index of r, chain)``, the
    chain being its points along the boundary from `r` (excluded) to its next corner
    (included), or to its last point before the outline leaves the boundary, forwards and
    backwards; None where the two do not share a side at `r`."""
    a, b = (int(k) for k in holders)
    qa, qb = polygons[a], polygons[b]
    ia, ib = int(np.flatnonzero(qa == r)[0]), int(np.flatnonzero(qb == r)[0])
    if qa[ia - 1] == qb[(ib + 1) % len(qb)]:
        fwd, at_f, bwd, at_b = a, ia, b, ib
    elif qb[ib - 1] == qa[(ia + 1) % len(qa)]:
        fwd, at_f, bwd, at_b = b, ib, a, ia
    else:
        return None
    chains = []
    for panel, at, step in ((fwd, at_f, 1), (bwd, at_b, -1)):
        q = polygons[panel]
        chain = []
        for k in range(1, len(q) - 1):
            p = q[(at + step * k) % len(q)]
            if not (on[p] or corner[p]):
                # the outline leaves the boundary: its last point there ends the chain
                break
            chain.append(p)
            if corner[p]:
                break
        else:
            return None
        if not chain:
            return None
        chains.append((panel, at, np.array(chain, np.int64)))
    return tuple(chains)


def _ids(values, count: int) -> np.ndarray:
    """The panel ids of a record's list that exist among `count` panels (int array)."""
    ids = np.asarray(values or [], np.int64)
    return ids[(ids >= 0) & (ids < count)]


def add_boundary_panels(result: OptimizationResult, layout: ChartedLayout, *,
                        touch: float = TOUCH, follow_net: bool = False,
                        follow: tuple | None = None) -> BoundaryPanels | None:
    """Trim a net solved from `layout` to the design (`trim_to_design`), attach the panels
    to `result` (written beside its OBJ) and record what they give in its properties:
    ``coverage`` (full and boundary panels), ``coverage_net`` (full panels only) and
    ``boundary_panels`` (`BoundaryPanels.record`). A net the overlays fail on gets none,
    and the reason under ``boundary_panels.error``. `touch`: as in `trim_to_design`
    (`OFF_DESIGN_TOUCH` for a net that left the design), `follow_net` and `follow` too."""
    try:
        panels = trim_to_design(result.mesh, layout, touch=touch, follow_net=follow_net,
                                follow=follow)
    except shapely.errors.GEOSException as exc:
        # the overlays failed on a degenerate net: it is reported without boundary panels
        coverage = net_coverage(result.mesh, layout.design, layout.panel_size)
        result.properties["coverage"] = result.properties["coverage_net"] = coverage
        result.properties["boundary_panels"] = {
            "count": 0, "coverage": coverage, "coverage_net": coverage,
            "error": f"the net could not be trimmed to the design boundary: {exc}"}
        return None
    result.boundary_panels = panels
    result.properties["coverage"] = panels.coverage
    result.properties["coverage_net"] = panels.coverage_net
    result.properties["boundary_panels"] = panels.record()
    return panels


def net_coverage(mesh: QuadMesh, design: DesignSurface, panel_size: float) -> float:
    """The share of the design's area under the faces of `mesh` (`_clad`)."""
    return net_cover(mesh, design, panel_size, gaps=False)[0]


def net_cover(mesh: QuadMesh, design: DesignSurface, panel_size: float, *,
              gaps: bool = True) -> tuple[float, list[dict]]:
    """The share of the design's area under the faces of `mesh` (`_clad`) and the largest
    parts it leaves unclad (`coverage_gaps`; none with ``gaps=False``)."""
    samples, normals, weight = _design_samples(design)
    on = _clad(samples, normals, mesh.vertices, mesh.triangles(), panel_size)
    share = float(weight[on].sum() / weight.sum())
    return share, coverage_gaps(design, samples, weight, on, panel_size) if gaps else []


#: gaps smaller than this share of a full panel are not listed (measuring noise)
MIN_GAP = 0.01


def coverage_gaps(design: DesignSurface, samples: np.ndarray, weight: np.ndarray,
                  clad: np.ndarray, h: float, *, count: int = 5) -> list[dict]:
    """The largest parts of the design left unclad, for a user to find them.

    Parameters
    ----------
    design : the design; `samples` (4 t, 3), `weight` (4 t,) its points and their areas
        (`_design_samples`, four per triangle in the triangle order), `clad` (4 t,) bool
        which are covered; `h` the panel size.
    count : at most this many gaps, largest first.

    Returns
    -------
    list of dict: ``area`` (model units squared) and ``area_relative_to_panel`` of each
    gap (unclad triangles that share edges), ``point`` (3,) its unclad sample nearest to
    its centroid (a point on the design), and ``at_design_boundary`` whether it reaches
    the design's boundary.
    """
    unclad, label, open_, area = unclad_components(design, clad)
    if len(unclad) == 0:
        return []
    w = weight.reshape(-1, 4)[unclad] * open_               # the unclad samples' areas
    edge = np.zeros(len(design.vertices), bool)
    edge[np.concatenate(design.boundary_loops or [np.zeros(0, np.int64)])] = True
    reaches = np.bincount(label, edge[design.triangles[unclad]].any(axis=1)) > 0
    P = samples.reshape(-1, 4, 3)[unclad]
    centroid = np.stack([np.bincount(label, (w * P[..., k]).sum(axis=1)) for k in range(3)],
                        axis=1) / np.maximum(area, 1e-300)[:, None]
    out = []
    for gap in np.argsort(-area, kind="stable")[:count]:
        if area[gap] < MIN_GAP * h * h:
            break
        mine = (label == gap)[:, None] & open_
        points = P[mine]
        nearest = points[np.argmin(np.linalg.norm(points - centroid[gap], axis=1))]
        out.append({"area": float(area[gap]), "area_relative_to_panel": float(area[gap] / (h * h)),
                    "point": [float(v) for v in nearest], "at_design_boundary": bool(reaches[gap])})
    return out


# ---------------------------------------------------------------------------- the chart


class ParameterChart:
    """The design in the parameter plane of a layout: point location both ways, the
    domain, its boundary, and areas on the surface of regions of the plane."""

    def __init__(self, design: DesignSurface, parameters: np.ndarray):
        self.design = design
        P = np.asarray(parameters, dtype=np.float64)           # (t, 3, 2)
        e0, e1 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
        self.param_area = 0.5 * (e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0])
        # triangles the map squeezes to nothing carry no area of the plane
        self.usable = np.abs(self.param_area) > 1e-12 * np.abs(self.param_area).max()
        self.P = P
        self.triangles = shapely.polygons(np.concatenate([P, P[:, :1]], axis=1))
        self.tree = shapely.STRtree(self.triangles)
        self.centroids = cKDTree(P.mean(axis=1))

    @cached_property
    def domain(self):
        """The union of the parameter triangles (shapely geometry)."""
        # the triangles tile the plane where the map keeps its orientation: a coverage
        # union is then exact and many times faster than the general one
        upright = self.param_area > 0
        if upright.all():
            domain = shapely.coverage_union_all(self.triangles)
            if domain.is_valid:
                return domain
        return shapely.make_valid(shapely.union_all(self.triangles[self.usable]))

    @cached_property
    def overlapping(self) -> bool:
        """Whether the parameter triangles overlap (the plane holds several sheets of the
        design somewhere: around a seam's end): their areas add up to more than their
        union's (to a millionth)."""
        total = float(np.abs(self.param_area[self.usable]).sum())
        return total > (1.0 + 1e-6) * self.domain.area

    @cached_property
    def boundary_lines(self):
        """The design's boundary edges in the parameter plane (not the cuts)."""
        T = self.design.triangles
        directed = np.stack([T, np.roll(T, -1, axis=1)], axis=2).reshape(-1, 2)
        key = np.sort(directed, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        lone = counts[inverse.ravel()] == 1
        corner = np.flatnonzero(lone)
        tri, k = corner // 3, corner % 3
        segments = np.stack([self.P[tri, k], self.P[tri, (k + 1) % 3]], axis=1)
        return shapely.multilinestrings(shapely.linestrings(segments))

    def locate(self, points: np.ndarray, near: np.ndarray | None = None, *, reach: float = 0.0
               ) -> tuple[np.ndarray, np.ndarray]:
        """The parameter triangle holding each point and the point's barycentric
        coordinates in it (clipped into the triangle).

        The plane of a parametrization with seams can hold several sheets of the design
        over one point; of the triangles holding a point, the one whose surface point is
        nearest to `near` (m, 3) is taken (the first without, or where its row is NaN);
        triangles within `reach` of a point count as holding it. A point in no triangle
        (outside by rounding) takes the triangle it is least outside of among the twelve
        nearest.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        m = len(points)
        tri = np.full(m, -1)
        bary = np.zeros((m, 3))
        if m == 0:
            return tri, bary
        if reach > 0:
            which, hold = self.tree.query(shapely.points(points), predicate="dwithin",
                                          distance=reach)
        else:
            which, hold = self.tree.query(shapely.points(points), predicate="intersects")
        ok = self.usable[hold]
        which, hold = which[ok], hold[ok]
        if len(which):
            b = np.clip(_barycentric(self.P[hold], points[which]), 0.0, None)
            b /= b.sum(axis=1, keepdims=True)
            score = np.zeros(len(which))
            if near is not None:
                X = np.einsum("mk,mkj->mj", b, self.design.vertices[self.design.triangles[hold]])
                # a point without a preference (NaN) takes the first sheet
                score = np.nan_to_num(np.linalg.norm(X - near[which], axis=1), nan=0.0)
            order = np.lexsort((score, which))
            first = order[np.r_[True, which[order][1:] != which[order][:-1]]]
            tri[which[first]], bary[which[first]] = hold[first], b[first]
        lost = np.flatnonzero(tri < 0)
        if lost.size:
            k = min(12, len(self.P))
            _, cand = self.centroids.query(points[lost], k=k)
            cand = cand.reshape(len(lost), k)
            b = _barycentric(self.P[cand.ravel()], np.repeat(points[lost], k, axis=0)).reshape(-1, k, 3)
            score = np.where(self.usable[cand], b.min(axis=-1), -np.inf)
            best = np.argmax(score, axis=1)
            rows = np.arange(len(lost))
            chosen = np.clip(b[rows, best], 0.0, None)
            tri[lost], bary[lost] = cand[rows, best], chosen / chosen.sum(axis=1, keepdims=True)
        return tri, bary

    def to_surface(self, points: np.ndarray, near: np.ndarray | None = None, *,
                   reach: float = 0.0) -> np.ndarray:
        """(m, 3) float, the points of the design at parameters `points` (m, 2), on the
        sheet nearest to `near` (m, 3, NaN rows for no preference) where the plane holds
        several, of the triangles within `reach` (`locate`)."""
        tri, bary = self.locate(points, near, reach=reach)
        design = self.design
        if design.parametric is not None and design.uv is not None:
            uv = np.einsum("mk,mkj->mj", bary, design.triangle_uv(tri))
            return design.parametric.points(uv[:, 0], uv[:, 1])
        X = design.vertices[design.triangles[tri]]
        return np.einsum("mk,mkj->mj", bary, X)

    def parameters_of(self, points: np.ndarray) -> np.ndarray:
        """(m, 2) float, the parameters of the design points closest to `points`."""
        design = self.design
        foot, _, tri = design.reference.closest_points(points)
        X = design.vertices[design.triangles[tri]]
        bary = igl.barycentric_coordinates(foot, X[:, 0].copy(), X[:, 1].copy(), X[:, 2].copy())
        return np.einsum("mk,mkj->mj", bary, self.P[tri])



def _barycentric(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m, 3) float, barycentric coordinates of `points` (m, 2) in `triangles` (m, 3, 2)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    l1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
    l2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    return np.stack([1 - l1 - l2, l1, l2], axis=1)


def _polygonal(geometries) -> np.ndarray:
    """The polygons among the parts of `geometries` (a degenerate face made valid may
    leave lines and points, which no overlay with areas accepts)."""
    parts = shapely.get_parts(np.asarray(geometries, dtype=object))
    return parts[shapely.get_type_id(parts) == 3]


def _areas_only(geometries: np.ndarray) -> np.ndarray:
    """The geometries with the lines and points that snap-rounding leaves beside their
    areas dropped (a collection of both is no input to a further overlay).

    Examples
    --------
    >>> mixed = shapely.GeometryCollection([shapely.box(0, 0, 1, 1),
    ...                                     shapely.LineString([(2, 0), (3, 0)])])
    >>> [g.geom_type for g in _areas_only(np.array([mixed, shapely.box(0, 0, 1, 1)]))]
    ['Polygon', 'Polygon']
    """
    out = np.asarray(geometries, dtype=object).copy()
    for k in np.flatnonzero(shapely.get_type_id(out) == 7):       # collections only
        out[k] = shapely.union_all(_polygonal([out[k]]))
    return out


def _transition_maps(cuts: list) -> list[tuple[int, np.ndarray]]:
    """The maps ``p -> sign p + shift`` between the sides of the layout's cuts (the
    identity first): a loop cut open shifts by its jump both ways, a seam turns a half
    turn about its centre."""
    maps = [(1, np.zeros(2))]
    for sign, jp, js in cuts:
        shift = np.array([jp, js], dtype=np.float64)
        maps += [(1, shift), (1, -shift)] if sign > 0 else [(-1, shift)]
    return maps


def _face_polygons(mesh: QuadMesh, p: np.ndarray, maps: list) -> np.ndarray:
    """The net's faces in the parameter plane. Across a cut a face's corners are taken to
    the side of its first corner, and every face also enters in its images under the
    cuts' maps, so that it covers the plane on both sides of the cut."""
    sizes, idx, ptr = mesh.face_sizes, mesh.face_indices, mesh.face_indptr
    face = np.repeat(np.arange(len(sizes)), sizes)
    corner_p = p[idx]
    if len(maps) > 1:
        anchor = p[idx[ptr[face]]]
        images = np.stack([sign * corner_p + shift for sign, shift in maps])   # (m, c, 2)
        pick = np.argmin(np.linalg.norm(images - anchor[None], axis=2), axis=0)
        corner_p = images[pick, np.arange(len(idx))]
    # a closed ring per face: its corners and the first again
    closing = np.insert(corner_p, ptr[1:], corner_p[ptr[:-1]], axis=0)
    ring_of = np.repeat(np.arange(len(sizes)), sizes + 1)
    out = [shapely.polygons(shapely.linearrings(closing, indices=ring_of))]
    out += [shapely.polygons(shapely.linearrings(sign * closing + shift, indices=ring_of))
            for sign, shift in maps[1:]]
    return np.concatenate(out)


def _unclad_by_sheet(chart: ParameterChart, faces: np.ndarray, mesh: QuadMesh, h: float,
                     grid: float, min_area: float) -> tuple:
    """The unclad region ``D - N`` of a chart whose parameter triangles overlap (a seam):
    every design triangle minus the net faces on its own sheet, united.

    A face lies on the sheet of the triangles it overlaps in the plane that lie under it
    on the surface: their centroid within the face's radius (its corners' largest
    distance from its centroid) and half a panel `h` of its centroid. On another sheet
    the triangle lies a few panels away, but where the sheets meet (at a singular point)
    the face lies on all of them.

    Parameters
    ----------
    chart : the layout's `ParameterChart`.
    faces : (f * k,) Polygons, the net's f faces in the plane and their images under the
        cuts' maps (`_face_polygons`): row i is face ``i % f``.
    mesh : the net.
    h : panel size (model units).
    grid : the overlays' snap-rounding grid.
    min_area : regions of no more area (in the plane) are left out.

    Returns
    -------
    rest : (u,) Polygons, what is left of the design triangles.
    rest_triangle : (u,) int, the design triangle of each.
    rest_region : (u,) int, the region of each (-1: one left out).
    regions : list of polygonal geometries, the unclad region in parts that hang
        together on the surface (each on one sheet; two may overlap in the plane).
    """
    f = len(mesh.face_sizes)
    valid = shapely.make_valid(faces)
    parts, row = shapely.get_parts(valid, return_index=True)
    polygon = shapely.get_type_id(parts) == 3
    parts, face = parts[polygon], row[polygon] % f
    sizes, idx, ptr = mesh.face_sizes, mesh.face_indices, mesh.face_indptr
    centre3 = np.stack([np.add.reduceat(mesh.vertices[idx, k], ptr[:-1]) for k in range(3)],
                       axis=1) / sizes[:, None]
    corner_face = np.repeat(np.arange(f), sizes)
    radius = np.zeros(f)
    np.maximum.at(radius, corner_face, np.linalg.norm(mesh.vertices[idx] - centre3[corner_face], axis=1))
    part, tri = chart.tree.query(parts, predicate="intersects")
    keep = chart.usable[tri]
    part, tri = part[keep], tri[keep]
    design = chart.design
    gap = np.linalg.norm(design.vertices[design.triangles[tri]].mean(axis=1) - centre3[face[part]],
                         axis=1)
    own = gap <= radius[face[part]] + 0.5 * h
    part, tri = part[own], tri[own]
    # most triangles lie inside one face of their sheet: nothing of them is left
    covered = np.zeros(len(chart.P), bool)
    covered[tri[shapely.covers(parts[part], chart.triangles[tri])]] = True
    part, tri = part[~covered[tri]], tri[~covered[tri]]
    # each triangle loses its faces one rank at a time: a loop over the few faces a
    # triangle meets, not over the triangles
    order = np.lexsort((part, tri))
    part, tri = part[order], tri[order]
    first = np.r_[True, tri[1:] != tri[:-1]]
    rank = np.arange(len(tri)) - np.maximum.accumulate(np.where(first, np.arange(len(tri)), 0))
    usable = np.flatnonzero(chart.usable & ~covered)
    rest = np.full(len(chart.P), None, dtype=object)
    rest[usable] = chart.triangles[usable]
    for k in range(int(rank.max(initial=-1)) + 1):
        at = rank == k
        rest[tri[at]] = _areas_only(shapely.difference(rest[tri[at]], parts[part[at]],
                                                       grid_size=grid))
    left = usable[~shapely.is_empty(rest[usable])]
    rest, at = shapely.get_parts(rest[left], return_index=True)
    polygon = shapely.get_type_id(rest) == 3
    rest, left = rest[polygon], left[at[polygon]]
    # parts hang together where their triangles share a corner on the design and they
    # meet in the plane; parts of other sheets over them in the plane share no corner
    a, b = shapely.STRtree(rest).query(rest, predicate="intersects")
    T = chart.design.triangles
    linked = (T[left[a]][:, :, None] == T[left[b]][:, None, :]).any(axis=(1, 2))
    graph = coo_matrix((np.ones(int(linked.sum())), (a[linked], b[linked])),
                       shape=(len(rest), len(rest)))
    count, region = connected_components(graph, directed=False)
    # regions of rounding size are no panels (as the specks among the pieces)
    large = np.flatnonzero(np.bincount(region, shapely.area(rest), minlength=count) > min_area)
    regions = [shapely.union_all(_polygonal([shapely.union_all(rest[region == k], grid_size=grid)]),
                                 grid_size=grid) for k in large]
    number = np.full(count, -1)
    number[large] = np.arange(len(large))
    return rest, left, number[region], regions


def _cut_region(unclad, mesh: QuadMesh, p_net: np.ndarray, boundary, touching: np.ndarray,
                cell: float, grid: float, min_panel: float) -> tuple:
    """One unclad region cut into pieces by the net's lines extended into it.

    Returns
    -------
    pieces : (p,) Polygons, counter-clockwise.
    rays : (r,) LineStrings, the lines that cut it (`_clipped_rays`, `_connectors`).
    patch : (p,) bool, pieces of parts of the region that do not reach the design
        boundary (holes inside the net).
    """
    tol = 4 * grid
    rays = np.concatenate([
        _clipped_rays(mesh, p_net, unclad, ~touching, grid),
        _connectors(p_net[touching & mesh.is_boundary_vertex], boundary, unclad, grid)])
    pieces = _split_large(_split(unclad, rays, grid), 1.5 * cell, grid)
    # specks of rounding size are no panels (their area stays in the uncovered share)
    pieces = shapely.orient_polygons(
        _merge_small(pieces[shapely.area(pieces) > 1e-6 * cell], min_panel * cell))
    # unclad regions that do not reach the design boundary are holes inside the net
    regions = shapely.get_parts(unclad)
    inner = regions[shapely.distance(regions, boundary) > tol]
    patch = np.zeros(len(pieces), bool)
    if len(pieces) and len(inner):
        hit, _ = shapely.STRtree(inner).query(shapely.point_on_surface(pieces), predicate="within")
        patch[hit] = True
    return pieces, rays, patch


def _clipped_rays(mesh: QuadMesh, p: np.ndarray, unclad, free: np.ndarray, grid: float
                  ) -> np.ndarray:
    """The net's lines that end on its boundary, continued straight in the parameter
    plane from their last vertex through the unclad strip, up to where they leave it.

    A boundary vertex with one face continues both its edges, one with two faces its
    interior edge; with three or more faces every line through it goes on in the net.
    Only vertices marked `free` (n,) bool (off the design boundary) start rays. The
    overlays are snap-rounded to `grid`.

    Returns
    -------
    (r,) array of LineStrings.
    """
    faces_at = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    boundary = mesh.is_boundary_vertex & free
    starts, throughs = [], []
    _, idx, nxt, prv = _corner_table(mesh)
    lone = boundary[idx] & (faces_at[idx] == 1)
    starts += [idx[lone], idx[lone]]
    throughs += [nxt[lone], prv[lone]]
    e = mesh.interior_edges
    for a, b in ((e[:, 0], e[:, 1]), (e[:, 1], e[:, 0])):
        ok = boundary[a] & (faces_at[a] == 2)
        starts.append(a[ok])
        throughs.append(b[ok])
    start, through = np.concatenate(starts), np.concatenate(throughs)
    if start.size == 0 or unclad.is_empty:
        return np.zeros(0, dtype=object)
    direction = p[start] - p[through]
    length = np.linalg.norm(direction, axis=1)
    ok = length > 0
    start, direction, length = start[ok], direction[ok], length[ok]
    # long enough to cross any strip the net leaves (a few panels)
    reach = 6.0 * float(np.median(length))
    end = p[start] + direction / length[:, None] * reach
    lines = shapely.linestrings(np.stack([p[start], end], axis=1))
    inside = shapely.intersection(lines, unclad, grid_size=grid)
    rays = [_first_piece(line, o, grid) for line, o in zip(inside, p[start], strict=True)]
    return np.array([r for r in rays if r is not None], dtype=object)


def _connectors(points: np.ndarray, boundary, unclad, grid: float) -> np.ndarray:
    """(r,) LineStrings, the shortest segments from `points` (k, 2) near the boundary to
    it, where they run through the unclad region (a hair longer, to be noded)."""
    if len(points) == 0 or unclad.is_empty:
        return np.zeros(0, dtype=object)
    lines = shapely.shortest_line(shapely.points(points), boundary)
    ends = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    step = ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(step, axis=1)
    ok = length > 2 * grid
    ends, step, length = ends[ok], step[ok], length[ok]
    ends[:, 1] += 10 * grid * step / length[:, None]
    segments = shapely.linestrings(ends)
    return segments[shapely.within(shapely.line_interpolate_point(segments, 0.5, normalized=True),
                                   unclad)]


def _first_piece(line, origin: np.ndarray, grid: float):
    """The part of a clipped ray that starts at `origin` (2,), as a straight segment a
    few grid steps longer (so that it crosses the boundary it ends on and is noded
    there), or None."""
    parts = shapely.get_parts(line)
    parts = parts[shapely.get_type_id(parts) == 1]
    if len(parts) == 0:
        return None
    d = shapely.distance(parts, shapely.points(origin))
    best = int(np.argmin(d))
    if d[best] > 2 * grid or shapely.length(parts[best]) < 10 * grid:
        return None
    end = np.asarray(parts[best].coords)[-1]
    step = end - origin
    return shapely.linestrings([origin, end + 10 * grid * step / np.linalg.norm(step)])


def _split(unclad, rays: np.ndarray, grid: float) -> np.ndarray:
    """The pieces the rays cut the unclad region into (polygons; noded on `grid`)."""
    if unclad.is_empty:
        return np.zeros(0, dtype=object)
    lines = [shapely.boundary(unclad)] + list(rays)
    noded = shapely.union_all(np.array(lines, dtype=object), grid_size=grid)
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
    if len(faces) == 0:
        return faces
    inside = shapely.contains(unclad, shapely.point_on_surface(faces))
    pieces = faces[inside & (shapely.area(faces) > 0)]
    return pieces


def _split_large(pieces: np.ndarray, max_area: float, grid: float) -> np.ndarray:
    """Pieces above `max_area` (where the net stops more than a panel short of the
    boundary) cut further by the lattice lines ``phi = k``, ``psi = k`` that cross them:
    the lines the net would have there."""
    big = shapely.area(pieces) > max_area
    if not big.any():
        return pieces
    out = [pieces[~big]]
    for piece in pieces[big]:
        x0, y0, x1, y1 = piece.bounds
        xs = np.arange(np.ceil(x0), np.floor(x1) + 1)
        ys = np.arange(np.ceil(y0), np.floor(y1) + 1)
        lines = [shapely.linestrings([[x, y0 - 1], [x, y1 + 1]]) for x in xs] + \
            [shapely.linestrings([[x0 - 1, y], [x1 + 1, y]]) for y in ys]
        out.append(_split(piece, np.array(lines, dtype=object), grid) if lines else np.array([piece]))
    return np.concatenate(out)


def _merge_small(pieces: np.ndarray, min_area: float) -> np.ndarray:
    """Pieces below `min_area` joined to the neighbour they share the longest side with
    (the smallest first, one at a time); one without a neighbour stays."""
    pieces = np.asarray(pieces, dtype=object)
    stuck: set[int] = set()
    while len(pieces) > 1:
        area = shapely.area(pieces)
        small = [i for i in np.argsort(area) if area[i] < min_area and i not in stuck]
        if not small:
            break
        i = int(small[0])
        shared = shapely.length(shapely.intersection(shapely.boundary(pieces[i]),
                                                     shapely.boundary(pieces)))
        shared[i] = 0.0
        j = int(np.argmax(shared))
        union = shapely.union(pieces[j], pieces[i]) if shared[j] > 0 else None
        if union is None or union.geom_type != "Polygon":
            stuck.add(i)
            continue
        pieces[j] = union
        pieces = np.delete(pieces, i)
        stuck = {k - (k > i) for k in stuck}
    return pieces


def _to_surface(pieces: np.ndarray, mesh: QuadMesh, p_net: np.ndarray, chart: ParameterChart,
                boundary, rays: np.ndarray, tol: float, touching: np.ndarray,
                sheets: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
                ) -> tuple:
    """The pieces as polygons on the surface: corners at net vertices are those vertices,
    the others are mapped through the chart (shared points once; points within `tol` of
    the design boundary are first put on it, so that they land on its curve). Net
    vertices marked `touching` (n,) bool lie on the boundary as far as corners go.

    Returns
    -------
    vertices (m, 3), polygons (list of int arrays), on_boundary (m,) bool, corner (m,) bool,
    the id of every point of every piece's ring (list of int arrays, repeats kept), and
    on_side (m,) bool, the points put on a boundary side of the net
    (`_net_side_points`).
    """
    n = mesh.vertex_count
    if len(pieces) == 0:
        return (mesh.vertices.copy(), [], np.zeros(n, bool), np.ones(n, bool), [],
                np.zeros(n, bool))
    rings = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    points = np.concatenate(rings)
    # a point is a net vertex when the parameters agree to the grid
    d, nearest = cKDTree(p_net).query(points)
    is_net = d <= tol
    other = np.flatnonzero(~is_net)
    ids = np.where(is_net, nearest, -1)
    new_p = np.zeros((0, 2))
    first = np.zeros(0, np.int64)
    if other.size:
        # the overlays are snap-rounded: equal points are equal coordinates
        _, first, inverse = np.unique(points[other], axis=0, return_index=True, return_inverse=True)
        ids[other] = n + inverse.ravel()
        new_p = points[other[first]]
    new_points = shapely.points(new_p)
    on_boundary = np.zeros(n + len(new_p), bool)
    on_boundary[n:] = shapely.distance(new_points, boundary) <= tol
    exact = new_p.copy()
    if on_boundary[n:].any():
        at = on_boundary[n:]
        exact[at] = shapely.get_coordinates(
            shapely.line_interpolate_point(boundary, shapely.line_locate_point(boundary, new_points[at])))
    # where the plane holds several sheets of the design, a point belongs to the sheet of
    # the net vertices of its panel
    sizes = np.array([len(r) for r in rings])
    piece = np.repeat(np.arange(len(rings)), sizes)
    weight = is_net.astype(np.float64)
    count = np.bincount(piece, weight, minlength=len(rings))
    anchor = np.stack([np.bincount(piece, weight * mesh.vertices[nearest, k], minlength=len(rings))
                       for k in range(3)], axis=1) / np.maximum(count, 1)[:, None]
    # a panel without a net vertex has no sheet to prefer (NaN); the others keep theirs
    anchor[count == 0] = np.nan
    if sheets is not None:
        # where the plane holds several sheets, the piece is on that of the design
        # triangles it was cut from (the net vertices in its ring may be another's)
        anchor = _piece_anchors(pieces, *sheets, chart, anchor)
    near = anchor[piece[other[first]]] if other.size else np.zeros((0, 3))
    # over a seam a point on one sheet's boundary may be inside another sheet's triangle
    # only, to rounding: the triangles within `tol` are candidates too
    reach = tol if sheets is not None else 0.0
    vertices = np.vstack([mesh.vertices, chart.to_surface(exact, near, reach=reach)])
    # a point on a side of the net in the plane is on that side on the surface too: the
    # straight edge between its two vertices, not the chart's curve under it (which
    # leaves a sliver between the panel and the face, over or beside it)
    # (points on the design boundary stay on its curve)
    at, chord = _net_side_points(new_p, p_net, mesh, tol)
    inside = ~on_boundary[n + at]
    at, chord = at[inside], chord[inside]
    vertices[n + at] = chord
    on_side = np.zeros(len(vertices), bool)
    on_side[n + at] = True
    on_ray = np.zeros(len(vertices), bool)
    if len(rays) and len(new_p):
        on_ray[n:] = shapely.distance(new_points, shapely.union_all(rays)) <= tol
    ring_ids = np.split(ids, np.cumsum(sizes)[:-1])
    polygons = ring_ids
    # drop repeated consecutive ids (two points of one ring mapped to one net vertex)
    polygons = [q[np.r_[True, q[1:] != q[:-1]] & ~((np.arange(len(q)) == len(q) - 1) & (q == q[0]))]
                for q in polygons]
    # a corner is off the boundary, ends a line, or is where the outline meets or leaves
    # the boundary; the points between follow the boundary curve
    ring = np.concatenate(polygons)
    before = np.concatenate([np.roll(q, 1) for q in polygons])
    after = np.concatenate([np.roll(q, -1) for q in polygons])
    ob = on_boundary.copy()
    ob[:n] = touching
    corner = np.zeros(len(vertices), bool)
    corner[ring[(ring < n) | ~ob[ring] | ~ob[before] | ~ob[after] | on_ray[ring]]] = True
    return vertices, polygons, on_boundary, corner, ring_ids, on_side


def _net_side_points(points: np.ndarray, p_net: np.ndarray, mesh: QuadMesh, tol: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The points (m, 2) of the plane within `tol` of a boundary edge of the net (its
    vertices at `p_net` (n, 2)), not at its ends: (k,) int which, and (k, 3) float, where
    they lie on the edge's straight side in space (at the same share of its length)."""
    edges = mesh.boundary_edges
    if len(points) == 0 or len(edges) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    A, B = p_net[edges[:, 0]], p_net[edges[:, 1]]
    tree = shapely.STRtree(shapely.linestrings(np.stack([A, B], axis=1)))
    point, edge = tree.query(shapely.points(points), predicate="dwithin", distance=tol)
    d = B[edge] - A[edge]
    share = np.sum((points[point] - A[edge]) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-300)
    length = np.sqrt(np.sum(d * d, axis=1))
    inner = (share * length > tol) & ((1 - share) * length > tol)
    point, edge, share = point[inner], edge[inner], share[inner]
    point, first = np.unique(point, return_index=True)
    edge, share = edge[first], share[first]
    X = mesh.vertices
    return point, (1 - share)[:, None] * X[edges[edge, 0]] + share[:, None] * X[edges[edge, 1]]


def _piece_anchors(pieces: np.ndarray, rest: np.ndarray, rest_triangle: np.ndarray,
                   rest_region: np.ndarray, piece_region: np.ndarray, chart: ParameterChart,
                   default: np.ndarray) -> np.ndarray:
    """(p, 3) float, a point of the surface on each piece's sheet: the centroid on the
    surface of the design triangle with the largest unclad part (`rest` (u,) Polygons of
    the triangles `rest_triangle` (u,) int in regions `rest_region` (u,) int,
    `_unclad_by_sheet`) in the piece and its region (`piece_region` (p,) int); the row
    of `default` (p, 3) for a piece that holds none."""
    anchor = default.copy()
    if len(rest) == 0 or len(pieces) == 0:
        return anchor
    piece, part = shapely.STRtree(shapely.point_on_surface(rest)).query(pieces, predicate="covers")
    same = rest_region[part] == piece_region[piece]
    piece, part = piece[same], part[same]
    if len(piece) == 0:
        return anchor
    share = shapely.area(rest[part])
    best = np.lexsort((-share, piece))
    best = best[np.r_[True, piece[best][1:] != piece[best][:-1]]]
    design = chart.design
    anchor[piece[best]] = design.vertices[design.triangles[rest_triangle[part[best]]]].mean(axis=1)
    return anchor


def _triangles_on_surface(pieces: np.ndarray, ring_ids: list) -> tuple[np.ndarray, np.ndarray]:
    """The pieces triangulated in the plane (constrained Delaunay: concave outlines stay
    whole) with corners numbered as their ring points (`ring_ids`); (t, 3) int and the
    piece of each (t,)."""
    if len(pieces) == 0:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    rings = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(pieces), return_index=True)
    corners = shapely.get_coordinates(shapely.get_exterior_ring(parts[0])).reshape(-1, 4, 2)[:, :3]
    owner = parts[1]
    # a corner is a point of its piece's ring: numbered as that point is
    points = np.concatenate(rings)
    piece_of = np.repeat(np.arange(len(rings)), [len(r) for r in rings])
    ids = np.concatenate(ring_ids)
    tree = cKDTree(np.c_[points, piece_of * 1e6])
    _, at = tree.query(np.c_[corners.reshape(-1, 2), np.repeat(owner, 3) * 1e6])
    triangles = ids[at].reshape(-1, 3)
    keep = (triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2]) & \
        (triangles[:, 0] != triangles[:, 2])
    return triangles[keep], owner[keep]


def _design_samples(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points spread over the design, four per triangle: (m, 3) points, their (m, 3)
    unit normals and the (m,) area each stands for."""
    X = design.vertices[design.triangles]
    weights = np.array([[4, 1, 1], [1, 4, 1], [1, 1, 4], [1, 1, 1]]) / np.array([[6], [6], [6], [3]])
    points = np.einsum("sk,tkj->tsj", weights, X).reshape(-1, 3)
    return points, np.repeat(design.face_normals, 4, axis=0), np.repeat(design.face_areas / 4, 4)


def _share_under(vertices: np.ndarray, triangles: np.ndarray, owner: np.ndarray, count: int,
                 mesh: QuadMesh, h: float) -> np.ndarray:
    """(count,) float, the share of each piece's area (triangles (t, 3) of `vertices`,
    `owner` (t,) their piece) that the net's faces already cover (`_under`)."""
    T = vertices[triangles]
    normal = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    area = 0.5 * np.linalg.norm(normal, axis=1)
    normal = normal / np.maximum(2.0 * area, 1e-300)[:, None]
    under = _under(T.mean(axis=1), normal, mesh.vertices, mesh.triangles(), h)
    total = np.bincount(owner, area, minlength=count)
    return np.bincount(owner, area * under, minlength=count) / np.maximum(total, 1e-300)


def _clad(points: np.ndarray, normals: np.ndarray, V: np.ndarray, F: np.ndarray, h: float
          ) -> np.ndarray:
    """(m,) bool, design points the cladding (V, F) covers: `_under` it, or within a
    quarter panel of it with their closest cladding point off its free edges (the sides
    of one triangle only: the cladding's outline and the rims of its gaps).

    A net solved away from the design stands off it and tilts against it, so a point under
    it may see its closest point well off its normal; a point in a gap always has it on
    the gap's rim."""
    under = _under(points, normals, V, F, h)
    if len(F) == 0:
        return under
    F = np.asarray(F, dtype=np.int64)
    d2, tri, closest = igl.point_mesh_squared_distance(points, V, F)
    T = V[F[tri]]
    bary = igl.barycentric_coordinates(closest, T[:, 0].copy(), T[:, 1].copy(), T[:, 2].copy())
    # free edges: sides of one triangle only
    n = len(V)
    sides = np.sort(np.concatenate([F[:, [1, 2]], F[:, [2, 0]], F[:, [0, 1]]]), axis=1)
    key, count = np.unique(sides[:, 0] * n + sides[:, 1], return_counts=True)
    free_key = key[count == 1]
    free_vertex = np.zeros(n, bool)
    free_vertex[free_key // n] = free_vertex[free_key % n] = True
    on_rim = np.zeros(len(points), bool)
    small = bary < 1e-6
    for k in range(3):        # on the side opposite corner k (of the three sides)
        a, b = F[tri, (k + 1) % 3], F[tri, (k + 2) % 3]
        side = np.minimum(a, b) * n + np.maximum(a, b)
        at = np.clip(np.searchsorted(free_key, side), 0, max(len(free_key) - 1, 0))
        on_rim |= small[:, k] & (len(free_key) > 0) & (free_key[at] == side) if len(free_key) \
            else np.zeros(len(points), bool)
    # at a corner (two coordinates near zero): on the rim when the corner is on it
    corner = small.sum(axis=1) >= 2
    on_rim |= corner & free_vertex[F[tri, np.argmax(bary, axis=1)]]
    return under | (~on_rim & (np.sqrt(d2) <= 0.25 * h))


def _under(points: np.ndarray, normals: np.ndarray, V: np.ndarray, F: np.ndarray, h: float
           ) -> np.ndarray:
    """(m,) bool, design points under the panels (V, F): their closest panel point is
    within a hundredth of a panel, or straight above or below them (the offset within
    18 deg of the normal) and within a quarter panel. A point in a gap beside a panel
    has its closest point on the panel's edge, off to the side."""
    if len(F) == 0:
        return np.zeros(len(points), bool)
    d2, _, closest = igl.point_mesh_squared_distance(points, V, np.asarray(F, dtype=np.int64))
    offset = closest - points
    distance = np.sqrt(d2)
    along = np.abs(np.sum(offset * normals, axis=1))
    return (distance <= 0.01 * h) | ((along >= 0.95 * distance) & (distance <= 0.25 * h))


def _sane_on_surface(pieces: np.ndarray, vertices: np.ndarray, polygons: list, h: float
                     ) -> np.ndarray:
    """(p,) bool, pieces whose sides on the surface are at most three times their length
    in the plane times the panel size `h` (plus a tenth of a panel)."""
    if not polygons:
        return np.zeros(0, bool)
    plane = [np.asarray(g.exterior.coords)[:-1] for g in pieces]
    ok = np.ones(len(polygons), bool)
    for k, (q, r) in enumerate(zip(polygons, plane, strict=True)):
        if len(q) != len(r):      # a ring with points merged into one net vertex
            r = r[:len(q)] if len(r) > len(q) else r
        side3 = np.linalg.norm(vertices[q] - vertices[np.roll(q, -1)], axis=1).sum()
        side2 = np.linalg.norm(r - np.roll(r, -1, axis=0), axis=1).sum()
        ok[k] = side3 <= 3 * h * side2 + 0.1 * h
    return ok


def _neighbour_faces(polygons: list, mesh: QuadMesh, vertices: np.ndarray) -> np.ndarray:
    """(p,) int, the net face sharing a side (two consecutive net vertices) with each
    panel, the longest such side deciding; a piece touching no full panel along a side (a
    corner cell, a sliver) continues the face whose centre is nearest its own."""
    out = _side_faces(polygons, mesh)
    lone = np.flatnonzero(out < 0)
    if lone.size:
        centre = np.array([vertices[polygons[k]].mean(axis=0) for k in lone])
        face_centre = np.stack([np.bincount(mesh.corner_faces,
                                            mesh.vertices[mesh.face_indices, k]) for k in range(3)],
                               axis=1) / mesh.face_sizes[:, None]
        out[lone] = cKDTree(face_centre).query(centre)[1]
    return out


def _side_faces(polygons: list, mesh: QuadMesh) -> np.ndarray:
    """(p,) int, the net face sharing a side (two consecutive net vertices) with each
    panel, the longest such side deciding; -1 where none."""
    out = np.full(len(polygons), -1)
    if not polygons:
        return out
    n = mesh.vertex_count
    face, vert, nxt, _ = _corner_table(mesh)
    a = np.concatenate(polygons)
    b = np.concatenate([np.roll(q, -1) for q in polygons])
    panel = np.repeat(np.arange(len(polygons)), [len(q) for q in polygons])
    net_side = (a < n) & (b < n)
    a, b, panel = a[net_side], b[net_side], panel[net_side]
    # the panel runs along the face's half-edge the other way
    key = vert * n + nxt
    order = np.argsort(key)
    at = np.clip(np.searchsorted(key[order], b * n + a), 0, len(key) - 1)
    found = key[order][at] == b * n + a
    a, b, panel, corner = a[found], b[found], panel[found], order[at[found]]
    if not len(panel):              # no panel runs along a net side (all meet at corners)
        return out
    length = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1)
    best = np.lexsort((-length, panel))
    first = best[np.r_[True, panel[best][1:] != panel[best][:-1]]]
    out[panel[first]] = face[corner[first]]
    return out


def _corner_table(mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per face corner: its face, vertex, next and previous vertex (each (c,) int)."""
    sizes, idx, ptr = mesh.face_sizes, mesh.face_indices, mesh.face_indptr
    face = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(idx)) - ptr[face]
    nxt = idx[np.where(local == sizes[face] - 1, ptr[face], np.arange(len(idx)) + 1)]
    prv = idx[np.where(local == 0, ptr[face] + sizes[face] - 1, np.arange(len(idx)) - 1)]
    return face, idx, nxt, prv


def _flipped(vertices: np.ndarray, polygons: list, design: DesignSurface, min_area: float
             ) -> np.ndarray:
    """(k,) int, panels facing against the design: their vector area, longer than twice
    `min_area` (a sliver's is noise), against the design's normal at the closest point to
    their centroid."""
    if not polygons:
        return np.zeros(0, np.int64)
    X = vertices
    ring = np.concatenate(polygons)
    after = np.concatenate([np.roll(q, -1) for q in polygons])
    count = np.array([len(q) for q in polygons])
    panel = np.repeat(np.arange(len(polygons)), count)
    cross = np.cross(X[ring], X[after])
    vector = np.stack([np.bincount(panel, cross[:, k], minlength=len(polygons)) for k in range(3)],
                      axis=1)
    centroid = np.stack([np.bincount(panel, X[ring, k], minlength=len(polygons)) for k in range(3)],
                        axis=1) / count[:, None]
    _, _, tri = design.reference.closest_points(centroid)
    size = np.linalg.norm(vector, axis=1)
    return np.flatnonzero((np.sum(vector * design.face_normals[tri], axis=1) <= 0)
                          & (size > 2 * min_area))


def _untangled(vertices: np.ndarray, polygons: list, corner: np.ndarray
               ) -> tuple[list, np.ndarray, np.ndarray]:
    """The outlines without the zigzags where they turn back or cross themselves, and
    the panels whose outline still does.

    A net vertex that lies past the design boundary (a net optimized off the design
    keeps its boundary vertices where the solve left them, centimetres outside) is
    followed by the boundary curve's points behind it: the outline runs out to the vertex
    and back, across itself or along itself. Where an outline turns back on itself at a
    point (a spike: its two sides run opposite ways) or two of its sides cross (in the
    plane of the panel's vector area), points that are not corners (points that only
    follow the boundary curve) are dropped: the spike's tip, or its nearer foot when the
    tip is a corner; the points of the shorter loop between crossing sides. This repeats
    until the outline is simple; a zigzag of corners only is left and reported.

    Returns
    -------
    polygons : list of (k,) int arrays, the outlines.
    changed : (g,) int, the panels that lost points.
    crossed : (c,) int, the panels whose outline still turns back or crosses itself.
    """
    out, changed, crossed = [], [], []
    for k, ring in enumerate(polygons):
        ids = list(ring)
        while len(ids) > 3:
            drop = _spike(vertices[ids], corner[ids])
            if drop is None:
                pair = _first_crossing(vertices[ids])
                if pair is None:
                    break
                i, j = pair              # sides i and j cross: points i + 1 .. j between
                inner = list(range(i + 1, j + 1))
                outer = list(range(j + 1, len(ids))) + list(range(i + 1))
                loop = inner if len(inner) <= len(outer) else outer
                drop = {m for m in loop if not corner[ids[m]]}
            if not drop or len(ids) - len(drop) < 3:
                crossed.append(k)
                break
            ids = [v for m, v in enumerate(ids) if m not in drop]
        if len(ids) < len(ring):
            changed.append(k)
        out.append(np.asarray(ids, dtype=np.asarray(ring).dtype))
    return out, np.asarray(changed, np.int64), np.asarray(crossed, np.int64)


#: an outline turning by more than this at a point turns back on itself (degrees)
SPIKE_DEG = 175.0


def _spike(P: np.ndarray, corner: np.ndarray) -> set | None:
    """The point to drop at the first place the closed outline `P` (k, 3) turns back on
    itself or repeats a point: the tip when it is no corner, else its nearer neighbour
    that is none; None where it does neither but at corners only (a needle corner
    between two corners is a shape, not a zigzag)."""
    before = P - np.roll(P, 1, axis=0)
    after = np.roll(P, -1, axis=0) - P
    lb, la = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    scale = 1e-9 * max(float(np.max(lb)), 1e-300)
    repeated = la <= scale
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.sum(before * after, axis=1) / (lb * la)
    back = (cos < np.cos(np.radians(SPIKE_DEG))) & (lb > scale) & (la > scale)
    k = len(P)
    for i in np.flatnonzero(repeated | back).tolist():
        if repeated[i]:                 # point i + 1 repeats point i: drop one not a corner
            drop = [m for m in (i, (i + 1) % k) if not corner[m]]
        elif not corner[i]:
            drop = [i]
        else:
            drop = [m for _, m in sorted(((lb[i], (i - 1) % k), (la[i], (i + 1) % k)))
                    if not corner[m]]
        if drop:
            return {drop[0]}
    return None                         # none, or needle corners between corners only


def _retriangulated(vertices: np.ndarray, polygons: list, triangles: np.ndarray,
                    owner: np.ndarray, changed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of the `changed` panels made again from their outlines (constrained
    Delaunay in the plane of each outline's vector area); a panel whose outline is not
    simple in that plane keeps its triangles less those on dropped points."""
    if len(changed) == 0:
        return triangles, owner
    keep = ~np.isin(owner, changed)
    new_t, new_o = [triangles[keep]], [owner[keep]]
    for k in changed:
        ring = np.asarray(polygons[k])
        outline = shapely.Polygon(_in_own_plane(vertices[ring]))
        if outline.is_valid and outline.area > 0:
            t = outline_triangles(outline, ring)
        else:
            old = triangles[owner == k]
            t = old[np.isin(old, ring).all(axis=1)]
        new_t.append(t)
        new_o.append(np.full(len(t), k))
    return np.concatenate(new_t).astype(np.int64), np.concatenate(new_o).astype(np.int64)


def _in_own_plane(P: np.ndarray) -> np.ndarray:
    """(k, 2) the closed outline `P` (k, 3) in the plane of its vector area (of its best
    fitting plane where the lobes of a bow tie cancel), about its centroid."""
    centred = P - P.mean(axis=0)
    normal = np.sum(np.cross(P, np.roll(P, -1, axis=0)), axis=0)
    if np.linalg.norm(normal) <= 1e-9 * np.sum(centred ** 2):
        normal = np.linalg.svd(centred)[2][2]
    axis = np.linalg.svd(normal[None, :])[2][1:]           # two directions across it
    return centred @ axis.T


def _first_crossing(P: np.ndarray) -> tuple[int, int] | None:
    """The first two sides of the closed outline `P` (k, 3) that cross, in the plane of
    its vector area: (i, j), i < j, side i from point i to i + 1; None when none do."""
    n = len(P)
    if not np.isfinite(P).all():
        return None
    q = _in_own_plane(P)
    a, b = q, np.roll(q, -1, axis=0)
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))                         # the last side meets the first
    i, j = i[keep], j[keep]

    def side(p, r, s):          # which side of p -> r the point s lies on (sign of cross)
        d = r - p
        return np.sign(d[..., 0] * (s[..., 1] - p[..., 1]) - d[..., 1] * (s[..., 0] - p[..., 0]))

    hit = (side(a[i], b[i], a[j]) * side(a[i], b[i], b[j]) < 0) & \
          (side(a[j], b[j], a[i]) * side(a[j], b[j], b[i]) < 0)
    first = np.flatnonzero(hit)
    return None if len(first) == 0 else (int(i[first[0]]), int(j[first[0]]))


def _boundary_distance(design: DesignSurface, points: np.ndarray) -> float:
    """Largest distance of points from the design's boundary curve (model units): to
    the exact boundary of a built-in design (its parameter domain's edges), to the
    boundary polylines of a mesh design."""
    from ..solve.constraints.closeness import closest_points_on_polylines

    if len(points) == 0:
        return 0.0
    if design.parametric is not None and design.uv is not None:
        foot, _, tri = design.reference.closest_points(points)
        X = design.vertices[design.triangles[tri]]
        bary = igl.barycentric_coordinates(foot, X[:, 0].copy(), X[:, 1].copy(), X[:, 2].copy())
        uv = design.parametric.closest_parameters(
            points, np.einsum("mk,mkj->mj", bary, design.triangle_uv(tri)))
        (u0, u1), (v0, v1) = design.parametric.domain
        edge = np.stack([uv[:, 0] - u0, u1 - uv[:, 0], uv[:, 1] - v0, v1 - uv[:, 1]], axis=1)
        if design.parametric.periodic_u:
            edge = edge[:, 2:]
        uv_edge = uv.copy()
        side = np.argmin(edge, axis=1) + (2 if design.parametric.periodic_u else 0)
        uv_edge[side == 0, 0], uv_edge[side == 1, 0] = u0, u1
        uv_edge[side == 2, 1], uv_edge[side == 3, 1] = v0, v1
        exact = design.parametric.points(uv_edge[:, 0], uv_edge[:, 1])
        return float(np.linalg.norm(exact - points, axis=1).max())
    foot, _ = closest_points_on_polylines(points, design.boundary_curves())
    return float(np.linalg.norm(foot - points, axis=1).max())
