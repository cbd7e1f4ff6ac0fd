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
   different sheets are cut apart (`fabplan.layout.plane_cut`).
2. Every line of the net that ends on the net's boundary is extended straight in the
   parameter plane (the lattice lines are straight there) until it leaves ``R``. The rays
   cut ``R`` into pieces: quads, pentagons and triangles with one side on the design
   boundary, whose corners are net vertices, ray ends on the boundary, and the design
   boundary's own vertices between them (the trim outline; `fabplan.layout.plane_cut`).
3. Pieces are mapped back to the surface through the design's triangles (barycentric;
   through the exact surface's parameters for a built-in design), so corners on the
   parameter boundary land on the design's boundary curve (`fabplan.layout.surface_pieces`,
   through the `fabplan.layout.parameter_chart`).

Pieces smaller than `min_panel` of a full panel join the neighbour they share the longest
side with; those left that small are *extensions*, cut as part of the full panel beside
them. Unclad regions that do not reach the design boundary (a hole the layout left open
around a singularity of the directions) are cut the same way, by the lines that end on
their rim: their pieces are *patches*. Coverage is measured on the surface, independently
of the plane: samples of the design count as clad when a panel lies straight above or
below them (`fabplan.layout.coverage`).

What the plane cut is then checked on the surface (`fabplan.layout.soundness`): a piece that lies off
the design (over an opening or past the boundary, `fabplan.layout.off_design`), crosses
itself, faces against the design, overlaps the net or another piece, or runs along a side
of one the same way (`fabplan.layout.overlaps`) is left out, and its place is cut again in
its tangent plane with the gaps (`fabplan.layout.gap_patches`). Where a piece's point lies
on a side of the net in the plane, it is put on that side's straight edge in space, so
that panel and face meet without a sliver. Outlines that turn back on themselves lose
their zigzags (`fabplan.layout.outlines`). What is still wrong is measured and recorded
(`Soundness.record`). The panels are a `fabplan.layout.boundary_panels.BoundaryPanels`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import igl
import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..net.mesh import QuadMesh
from .boundary_panels import BoundaryPanels, neighbour_faces, read_boundary_panels, slide_splits
from .coverage import clad_points, coverage_gaps, design_samples, net_cover, net_coverage
from .gap_patches import MAX_GAP_PANELS, gap_patches
from .outlines import retriangulated, untangled
from .parameter_chart import ParameterChart
from .plane_cut import net_in_plane, pieces_in_plane
from .soundness import Soundness, flipped_panels, soundness, unsound_pieces, without_pieces
from .surface_pieces import pieces_on_surface

if TYPE_CHECKING:
    from ..solve.optimize import OptimizationResult

# `BoundaryPanels`, `ParameterChart`, `Soundness`, `soundness`, `read_boundary_panels`,
# `net_cover`, `net_coverage` and `slide_splits` are owned by the modules above; they stay
# importable from here, where they were first documented
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
    cut, touching = _cut(mesh, layout, min_panel, touch)
    followed = (mesh.vertices, design) if follow is None else follow
    if follow_net and len(cut.vertices) > mesh.vertex_count:
        # lifted before the outlines are checked: what crosses is judged where it is cut
        cut.lift(mesh.vertex_count, followed)
    cut.untangle()
    recut, recut_area = 0, 0.0
    if patch_gaps:
        # checked on the surface: what the plane cut wrongly (off the design, over a hole;
        # crossing itself; facing against the design; over the net or another panel) is
        # left out, and its place is cut again in its tangent plane with the gaps below
        recut, recut_area = cut.leave_out_unsound(mesh, design, h)
    # coverage is measured on the surface, independently of the plane
    # (`fabplan.layout.coverage`), by the panels' footprints: lifted with a net that leaves
    # the design, a panel tilts against it where the lift changes fast (a corner), and
    # would seem to leave a gap beside it
    samples, normals, weight = design_samples(design)
    on_net = clad_points(samples, normals, mesh.vertices, mesh.triangles(), h)
    on_any = on_net | cut.clad(samples, normals, mesh, h)
    if patch_gaps:
        on_any = _patch_gaps(cut, mesh, design, h, (samples, normals, on_net, on_any),
                             recut_area, followed if follow_net else None)
    vertices, polygons, triangles, owner = cut.vertices, cut.polygons, cut.triangles, cut.owner
    T = vertices[triangles]
    tri_area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    area = np.bincount(owner, tri_area, minlength=len(polygons))
    neighbour = neighbour_faces(polygons, mesh, vertices)
    extension = area < min_panel * h * h
    flipped = flipped_panels(vertices, polygons, design, 1e-3 * h * h)
    sound = soundness(vertices, polygons, triangles, owner, mesh, design, h)
    return BoundaryPanels(
        vertices=vertices, polygons=polygons, net_vertex_count=mesh.vertex_count,
        on_boundary=cut.on_boundary, corner=cut.corner, neighbour_face=neighbour,
        area=area, panel_size=h, extension=extension,
        coverage_net=float(weight[on_net].sum() / weight.sum()),
        coverage=float(weight[on_any].sum() / weight.sum()),
        flipped=flipped[~extension[flipped]], crossed=sound.crossing, patch=cut.patch,
        boundary_distance_max=_boundary_distance(design, vertices[cut.on_boundary]) / h,
        seconds=time.perf_counter() - clock, triangles=triangles, triangle_panel=owner,
        net_on_boundary=touching, gaps=coverage_gaps(design, samples, weight, on_any, h),
        follows_net=follow_net,
        offset_max=float(np.linalg.norm(cut.offset, axis=1).max()) if len(cut.offset) else 0.0,
        soundness=sound.record(h, recut))


@dataclass
class _Trimming:
    """The boundary panels while `trim_to_design` cuts them: the arrays its steps share.

    Attributes
    ----------
    vertices : (m, 3) float, the net's vertices, then the panels' points (lifted off the
        design with a net that left it, `lift`).
    footprint : (m, 3) float, the same points before the lift: where the panels stand
        over the design (the lift is along the design's normals).
    polygons : list of (k,) int arrays, the panels' outlines into `vertices`.
    on_boundary, corner : (m,) bool, points on the design's boundary curve; panel corners.
    on_side : (m,) bool, points put on a boundary side of the net.
    triangles : (t, 3) int, the panels' triangles; owner : (t,) int, the panel of each.
    patch : (p,) bool, the panels that close a hole inside the net.
    offset : (k, 3) float, the lift of each point after the net's (none without one).
    """

    vertices: np.ndarray
    footprint: np.ndarray
    polygons: list
    on_boundary: np.ndarray
    corner: np.ndarray
    on_side: np.ndarray
    triangles: np.ndarray
    owner: np.ndarray
    patch: np.ndarray
    offset: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def lift(self, n: int, followed: tuple) -> None:
        """The points after the net's `n` vertices stand off the design as the net does
        near them (`_follow_net` of `followed`, ``(points, surface)``)."""
        self.offset = _follow_net(self.vertices[n:], *followed)
        # the points on the net's sides are where the net is already
        self.offset[self.on_side[n:]] = 0.0
        self.vertices = self.vertices.copy()
        self.vertices[n:] += self.offset

    def untangle(self) -> None:
        """The outlines without their zigzags, and the panels that changed cut into
        triangles again (`fabplan.layout.outlines`)."""
        self.polygons, changed, _ = untangled(self.vertices, self.polygons, self.corner)
        self.triangles, self.owner = retriangulated(self.vertices, self.polygons, self.triangles,
                                                    self.owner, changed)

    def unsound(self, mesh: QuadMesh, design: DesignSurface, h: float) -> np.ndarray:
        """(p,) bool, the panels to leave out (`fabplan.layout.soundness.unsound_pieces`),
        judged where they stand over the design."""
        return unsound_pieces(self.footprint, self.polygons, self.triangles, self.owner, mesh,
                              design, h)

    def drop(self, unsound: np.ndarray) -> None:
        """The panels less those marked in `unsound` (p,) bool."""
        self.polygons, self.triangles, self.owner, self.patch = without_pieces(
            self.polygons, self.triangles, self.owner, self.patch, unsound)

    def leave_out_unsound(self, mesh: QuadMesh, design: DesignSurface, h: float
                          ) -> tuple[int, float]:
        """Leave out the panels the plane cut wrongly (`unsound`): how many, and their area
        over the design (model units squared), which the gap patches cut again."""
        unsound = self.unsound(mesh, design, h)
        recut = int(unsound.sum())
        T = self.footprint[self.triangles[unsound[self.owner]]]
        recut_area = float(0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]),
                                                axis=1).sum())
        self.drop(unsound)
        return recut, recut_area

    def clad(self, samples: np.ndarray, normals: np.ndarray, mesh: QuadMesh, h: float
             ) -> np.ndarray:
        """(s,) bool, the design's `samples` the net and the panels' footprints clad."""
        return clad_points(samples, normals, self.footprint,
                           np.vstack([mesh.triangles(), self.triangles]), h)


def _cut(mesh: QuadMesh, layout: ChartedLayout, min_panel: float, touch: float
         ) -> tuple[_Trimming, np.ndarray]:
    """The panels cut in the plane of the layout's parameters and mapped to the surface
    (steps 1 to 3 of the module's text), and (n,) bool, the net's vertices on the design
    boundary (to `touch` of a panel)."""
    design, h = layout.design, layout.panel_size
    chart = layout.chart
    p_net, cell, grid, touching = net_in_plane(mesh, chart, design, h, touch,
                                               onto_boundary=touch > TOUCH)
    by_sheet = bool(layout.cuts) and chart.overlapping
    pieces, rays, patch, sheets = pieces_in_plane(mesh, layout.cuts, chart, p_net, touching,
                                                  by_sheet, cell, grid, min_panel, h)
    vertices, polygons, on_boundary, corner, on_side, triangles, owner, patch = \
        pieces_on_surface(pieces, rays, patch, sheets, mesh, p_net, chart, touching, 4 * grid, h)
    return _Trimming(vertices, vertices, polygons, on_boundary, corner, on_side, triangles,
                     owner, patch), touching


def _patch_gaps(cut: _Trimming, mesh: QuadMesh, design: DesignSurface, h: float,
                coverage: tuple, recut_area: float, followed: tuple | None) -> np.ndarray:
    """The small gaps left (pieces around singular points the plane could not cut, the
    place of those left out) closed with patches cut in their own tangent planes
    (`fabplan.layout.gap_patches`), added to `cut`; `coverage` ``(samples, normals,
    on_net, on_any)`` as `trim_to_design` measures it; `followed` as in
    `_Trimming.lift`, None where the net stays on the design. Returns `on_any` (s,) bool
    with the patches."""
    samples, normals, on_net, on_any = coverage
    # a gap where pieces were left out is no failure of the layout: it is patched however
    # large those pieces were
    extra = gap_patches(design, cut.footprint, np.vstack([mesh.triangles(), cut.triangles]),
                        on_any, h, max_panels=MAX_GAP_PANELS + recut_area / (h * h))
    if not extra.count:
        return on_any
    cut.owner = np.r_[cut.owner, len(cut.polygons) + extra.owner]
    lifted = np.zeros((len(extra.points), 3))
    if followed is not None and len(extra.points):
        # the patches' new points are on the design: they stand off it with the net too
        lifted = _follow_net(extra.points, *followed)
        cut.offset = np.vstack([cut.offset, lifted])
    cut.vertices = np.vstack([cut.vertices, extra.points + lifted])
    cut.footprint = np.vstack([cut.footprint, extra.points])
    cut.polygons = cut.polygons + extra.polygons
    cut.triangles = np.vstack([cut.triangles, extra.triangles])
    cut.patch = np.r_[cut.patch, np.ones(extra.count, bool)]
    cut.on_boundary = np.r_[cut.on_boundary, extra.on_boundary]
    cut.corner = np.r_[cut.corner, ~extra.on_boundary]
    on_any |= cut.clad(samples, normals, mesh, h)
    # a patch's outline may run out along the boundary past a neighbour's corner and
    # back (a sliver of no width between the two): the spike goes
    cut.untangle()
    # a patch cut in its plane that still clashes (rare) is left out: a gap, reported
    unsound = cut.unsound(mesh, design, h)
    if unsound.any():
        cut.drop(unsound)
        on_any = on_net | cut.clad(samples, normals, mesh, h)
    return on_any


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
