"""From a design surface to an initial S-net: directions, parametrization, quad extraction.

The steps follow section 4.3 of the paper, with the degrees of freedom of section 2.1.11:

1. Principal directions per triangle (`fabplan.directions`): from the exact fundamental
   forms of a parametric surface, or from libigl's per-vertex estimate
   (Rusinkiewicz-style quadric fitting) averaged as shape operators over each triangle.
2. A smooth line field (`fabplan.directions`): the principal directions, weighted by the
   anisotropy ``|k1 - k2|``, are smoothed over a length of about half a panel (near
   umbilics the surroundings decide); for orthogonal nets as a cross field, over a
   longer length where needed (`_smoothed_directions`). The field is then combed into a
   consistent sign by XOR along a minimum spanning tree of the triangle adjacency
   (pointer doubling, `fabplan.mesh.tree_parity`). Where the combing conflicts the field
   has a seam; its end points and points where the field turns around are its
   singularities.
3. S-net directions (`fabplan.directions`): the pair symmetric to the principal
   directions at the requested angle, ``t1,2 = cos(a/2) e1 +- sin(a/2) e2`` (90 degrees:
   45 degrees off the principal directions). In the second mode one family is prescribed
   (a function whose level sets are, e.g., the floor levels of a tower) and its partner
   direction is the reflection of its tangent in the principal directions (Proposition
   2.11), ``s = 2 (t . e1) e1 - t``.
4. A global parametrization ``(phi, psi)`` (`fabplan.parametrization`): sparse least
   squares for the gradients (isolines of phi along t1, of psi along t2, spacing one
   panel), with the alignment weighted above the spacing. Boundary loops around which the
   field turns (a tower) are cut open and get an integer jump, so the grid closes up.
5. Extraction (`fabplan.extraction`): the integer points of the parametrization, located
   triangle by triangle (barycentric test, vectorized over candidate points), become
   vertices; unit squares whose corners and centre exist become quads (oriented with the
   surface). Quads that fold or stretch (near singularities and seams) are dropped, the
   largest piece is kept, pinched vertices are separated, and small interior holes are
   closed by a fan of quads around a new vertex: these are the irregular vertices
   (fairness only in the solve).

Steps 1 to 5 make one layout's lattice (`fabplan.layout.lattice`); `layout_surface` runs
them at the smoothing lengths tried and judges what they clad.

`glide` then optimizes the layout into a net of a given type with its vertices held
within a small tolerance of the design surface, its boundary vertices near the surface
boundary held on it, and its edges within 0.5 - 2 panel sizes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import cached_property, partial
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface, weighted_quantile
from ..errors import BrokenLayoutError, InputError
from ..net.mesh import QuadMesh
from ..solve.constraints import Constraint, EdgeLengthRange, FamilyLevels
from .coverage import net_cover, net_coverage
from .directions import face_principal_frames
from .lattice import layout_lattice
from .off_design import MIN_OFF_PANELS, degenerate_faces, faces_off_design
from .parameter_chart import ParameterChart
from .settings import SURFACE_TOLERANCE, LayoutSettings
from .trim import add_boundary_panels, trim_to_design

if TYPE_CHECKING:
    from ..solve.optimize import OptimizationResult
    from ..solve.solver import IterationRecord, SolverSettings

__all__ = ["SurfaceLayout", "layout_surface", "layout_again", "layout_angle", "glide",
           "holding_panel_size", "HOLDING_SIZE_FACTORS",
           "layout_without_faces", "sound_faces"]


@dataclass
class SurfaceLayout:
    """An initial S-net on a design surface and what was found on the way.

    Attributes
    ----------
    mesh : the extracted quad-dominant mesh (vertices on the design surface).
    design : the `DesignSurface`.
    panel_size : target edge length (model units).
    angle_deg : intersection angle of the two families (None when one is prescribed).
    parameters : (t, 3, 2) float, ``(phi, psi)`` at the corners of every design triangle
        (integer values are the mesh lines).
    singular_points : (k, 3) float, points of the design surface where the direction field
        is singular (umbilics, seam ends), with their `singular_index` (k,) in turns.
    seam_edges : number of design edges across which the combed field flips.
    cuts : transitions ``(sign, jump_phi, jump_psi)`` across the cuts: sign 1 for a
        boundary loop cut open (the grid closes up with an integer shift), -1 for a seam of
        the line field (parameters ``c - p``).
    filled_holes, open_holes : interior holes closed with irregular vertices / left open.
    gliding_boundary : (b,) int, boundary vertices of `mesh` close enough to the design
        boundary to glide on it.
    vertex_keys : (n, 2) float, the integer parameters ``(phi, psi)`` of every mesh vertex
        (NaN for vertices added in holes).
    prescribed : (n_design,) float, the prescribed family's function on the design
        vertices (its integer levels are the first family), or None.
    family : description of the prescribed family, or None.
    level_step : level k of the prescribed family is where its function equals
        ``k * level_step`` (see `prescribed_family`), or None.
    direction_symmetry : 4 when the directions were smoothed as a cross field, 2 as a
        line field; `smoothing` the smoothing length used (panel sizes); `smoothing_tried`
        the lengths asked for, the length each used and the share of the design each
        layout's quads covered.
    bisector : the principal direction bisecting the families (`LayoutSettings.bisector`).
    turning_points, turning_deg : (k, 3), (k,) float, where the direction field turns
        faster than `LayoutSettings.max_turning_deg` per panel (umbilics and near-umbilics,
        `fabplan.directions.direction_turning`), and how fast: the net's lines cannot
        follow it there.
    seconds : time per stage.
    max_gap_panels : a net glided from this layout whose trimming leaves a larger gap (in
        full panels of area) is refused (`glide`); None: not judged.
    dropped_faces : (d,) int, faces of the layout as extracted that a glided net made no
        panels (spanning a corner of the design boundary, or three corners in a line:
        `sound_faces`) and that were dropped (`layout_without_faces`); the trimming cuts
        their place as boundary panels.
    """

    mesh: QuadMesh
    design: DesignSurface
    panel_size: float
    angle_deg: float | None
    parameters: np.ndarray
    singular_points: np.ndarray
    singular_index: np.ndarray
    seam_edges: int
    cuts: list
    filled_holes: int
    open_holes: int
    gliding_boundary: np.ndarray
    vertex_keys: np.ndarray
    prescribed: np.ndarray | None = None
    family: str | None = None
    level_step: float | None = None
    turning_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    turning_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    direction_symmetry: int = 2
    smoothing: float = 0.5
    bisector: str = "max"
    max_gap_panels: float | None = None
    smoothing_tried: list = field(default_factory=list)
    dropped_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    seconds: dict = field(default_factory=dict)

    @property
    def direction_field(self) -> str:
        """"cross" or "line": how the directions were smoothed (`direction_symmetry`)."""
        return "cross" if self.direction_symmetry == 4 else "line"

    @cached_property
    def chart(self) -> ParameterChart:
        """The design in the plane of the parameters ``(phi, psi)`` (`fabplan.layout.trim`),
        made once and shared by every net laid out from this layout."""
        return ParameterChart(self.design, self.parameters)

    def __getstate__(self) -> dict:
        # the chart is a cache about six times the layout's size: a layout sent to another
        # process (a study's Dask workers) makes it again when it needs it
        state = dict(self.__dict__)
        state.pop("chart", None)
        return state

    def record(self) -> dict:
        """JSON-ready summary (written with the optimized net)."""
        mesh = self.mesh
        return {
            "design": self.design.name,
            "design_spec": _design_spec(self.design),
            "design_resolution": _design_resolution(self.design),
            "design_triangles": int(len(self.design.triangles)),
            "design_repairs": dict(self.design.repairs),
            "design_units": self.design.units,
            "design_source": self.design.source,
            "panel_size": self.panel_size,
            "angle_deg": self.angle_deg,
            "prescribed_family": self.family,
            "level_step": self.level_step,
            "quads": int(np.sum(mesh.face_sizes == 4)),
            "other_faces": int(np.sum(mesh.face_sizes != 4)),
            "vertices": int(mesh.vertex_count),
            "irregular_vertices": mesh.irregular_vertices.tolist(),
            "singular_points": self.singular_points.tolist(),
            "singular_index": self.singular_index.tolist(),
            "fast_turning_points": self.turning_points.tolist(),
            "fast_turning_deg_per_panel": self.turning_deg.tolist(),
            "direction_field": self.direction_field,
            "smoothing_panels": self.smoothing,
            "smoothing_tried": self.smoothing_tried,
            "bisector": self.bisector,
            "seam_edges": int(self.seam_edges),
            "cuts": [list(map(int, c)) for c in self.cuts],
            "filled_holes": int(self.filled_holes),
            "open_holes": int(self.open_holes),
            "dropped_faces": np.asarray(self.dropped_faces, np.int64).tolist(),
            "gliding_boundary_vertices": int(len(self.gliding_boundary)),
            "boundary_vertices": int(mesh.is_boundary_vertex.sum()),
            "seconds": self.seconds,
        }


# ---------------------------------------------------------------------------- pipeline


def layout_surface(design: DesignSurface, panel_size: float, *, angle: float = 90.0,
                   family: str | None = None, settings: LayoutSettings | None = None,
                   refuse_broken: bool = True, judged_on: DesignSurface | None = None
                   ) -> SurfaceLayout:
    """Lay out an initial S-net on a design surface.

    Parameters
    ----------
    design : the surface.
    panel_size : target edge length (model units).
    angle : intersection angle of the two families in degrees (ignored with `family`).
    family : a prescribed first family (see `prescribed_family`); the second family is
        the complementary one that makes an S-net.
    settings : `LayoutSettings`.
    refuse_broken : refuse a layout whose lattice does not hold together (see
        `LayoutSettings.min_lattice_share` and `max_gap_panels`); False makes such a layout
        anyway (`layout_again` of a net made before).
    judged_on : for a layout on a design continued past the edges of this one
        (`fabplan.layout.margin`), of which only the part over this one is kept: the
        coverage and the gaps that judge it are those of its quads over this design (they
        reach past its edges, so no boundary panels are cut to judge it).

    Returns
    -------
    SurfaceLayout

    Raises
    ------
    InputError
        For a panel size that is not positive or too large for the surface, an angle
        outside (0, 180), a layout without a single regular vertex, or (with
        `refuse_broken`) one whose lattice does not hold together, naming why (a
        `BrokenLayoutError`, as is a layout without a single regular vertex).
    """
    from dataclasses import replace

    clock = time.perf_counter()
    s = settings or LayoutSettings()
    h = float(panel_size)
    _check_layout_request(design, h, angle, s)
    best: SurfaceLayout | None = None
    best_coverage = -1.0
    refusal: InputError | None = None
    tried: list[dict[str, float | str | None]] = []
    lengths = [s.smoothing, *(x for x in s.smoothing_tries if x > s.smoothing)]
    for k, length in enumerate(lengths):
        if any(_doubled_past(t, length) for t in tried):
            continue        # the same cross field as a try before, and the same layout
        try:
            layout = _layout_once(design, h, angle, family, replace(s, smoothing=length))
        except InputError as exc:      # this smoothing leaves no usable lattice
            refusal = refusal or exc
            tried.append({"smoothing_panels": length, "used": None, "coverage": 0.0})
            continue
        if best is None and k == len(lengths) - 1:
            # the only layout there is: nothing to compare its coverage with
            best, best_net, best_hole = layout, None, None
            tried.append({"smoothing_panels": length, "used": layout.smoothing,
                          "field": layout.direction_field, "coverage": None})
            break
        coverage, on_net, hole = _lattice_cover(layout, judged_on)
        tried.append({"smoothing_panels": length, "used": layout.smoothing,
                      "field": layout.direction_field, "coverage": coverage})
        if coverage > best_coverage:
            best, best_coverage, best_net, best_hole = layout, coverage, on_net, hole
        if coverage >= s.good_coverage:
            break
    if best is None:
        assert refusal is not None
        raise refusal
    # a few panels' raw lattice stops a panel short of the boundary all round: only
    # larger designs are judged by the share their quads cover and the gaps they leave
    judged = refuse_broken and design.area / (h * h) >= s.min_panels_judged
    if judged:
        _refuse_broken(best, best_net, best_hole, tried, judged_on or design, s)
    best.smoothing_tried = tried
    best.max_gap_panels = s.max_gap_panels if judged else None
    # the other smoothing lengths tried, and judging them, took time too
    best.seconds["other_tries"] = max(time.perf_counter() - clock - sum(best.seconds.values()), 0.0)
    return best


def _lattice_cover(layout: SurfaceLayout, judged_on: DesignSurface | None
                   ) -> tuple[float, float, dict | None]:
    """What a layout's lattice clads, as `layout_surface` judges it: the share of the
    design covered with its boundary panels, by its quads alone, and the largest gap
    inside the design (`fabplan.layout.coverage.coverage_gaps`; None where there is none).
    With `judged_on` (the design a continued one is kept over), its quads over that."""
    design, h = layout.design, layout.panel_size
    # judged with the boundary panels the net will get: the staircase along the
    # boundary is theirs to clad; what they cannot reach are the lattice's own holes
    hole = None
    if judged_on is not None:
        coverage, gaps = net_cover(layout.mesh, judged_on, h)
        on_net, hole = coverage, gaps[0] if gaps else None
    else:
        try:
            # the lattice as it is: patches would hide the holes a smoother field avoids
            panels = trim_to_design(layout.mesh, layout, patch_gaps=False)
            coverage, on_net = panels.coverage, panels.coverage_net
            # a gap inside the design; one at its boundary the glide partly closes (the
            # boundary vertices move onto the boundary): judged after it
            inside = [g for g in panels.gaps if not g["at_design_boundary"]]
            hole = inside[0] if inside else None
        except shapely.errors.GEOSException:
            coverage = on_net = net_coverage(layout.mesh, design, h)
    return coverage, on_net, hole


def _refuse_broken(best: SurfaceLayout, best_net: float | None, best_hole: dict | None,
                   tried: list, judged_on: DesignSurface, s: LayoutSettings) -> None:
    """Refuse the layout kept (`layout_surface`) where its quads clad less than
    `LayoutSettings.min_lattice_share` of `judged_on` (`best_net`, measured here when
    None) or leave a gap inside it larger than `LayoutSettings.max_gap_panels`
    (`best_hole`), naming the smoothing lengths `tried`.

    Raises
    ------
    InputError
        Saying why the lattice does not hold together (`_broken_lattice`).
    """
    lengths = [float(t["smoothing_panels"] or 0.0) for t in tried]
    if best_net is None:
        best_net = net_coverage(best.mesh, judged_on, best.panel_size)
    if best_net < s.min_lattice_share:
        raise BrokenLayoutError(_broken_lattice(best, best_net, lengths))
    if best_hole is not None and best_hole["area_relative_to_panel"] > s.max_gap_panels:
        raise BrokenLayoutError(_broken_lattice(best, best_net, lengths, best_hole))


def _doubled_past(tried: dict, length: float) -> bool:
    """Whether a smoothing try's cross field was doubled (`_smoothed_directions`) from its
    length through `length` up to the one it used: starting at `length` ends there too."""
    asked, used = tried["smoothing_panels"], tried["used"]
    if used is None or tried.get("field") != "cross" or not asked <= length <= used:
        return False
    steps = math.log2(length / asked)
    return math.isclose(steps, round(steps), abs_tol=1e-9)


def _broken_lattice(layout: SurfaceLayout, share: float | None, smoothing: list | None,
                    hole: dict | None = None) -> str:
    """Why a layout's lattice of quads does not hold together, in one line: the quads'
    share of the design (`share`, None: no interior vertex) or the `hole` it leaves
    (`fabplan.layout.trim.coverage_gaps`), the singular points and the places the
    directions turn, the smoothing lengths tried (panels) and what to try."""
    design, h = layout.design, layout.panel_size
    if share is None:
        held = "the quads laid out form no interior vertex with four quads"
    elif hole is None:
        held = f"its quads cover only {100 * share:.0f} % of the design"
    else:
        where = "at the design boundary" if hole["at_design_boundary"] else "inside the design"
        held = (f"it leaves a gap of {hole['area_relative_to_panel']:.0f} panels' area {where} "
                f"around ({', '.join(f'{v:.4g}' for v in hole['point'])})")
    why = []
    if len(layout.singular_points):
        why.append(f"{len(layout.singular_points)} singular points of the principal directions "
                   "(umbilics, where the lattice must break)")
    if len(layout.turning_points):
        why.append(f"{len(layout.turning_points)} places where they turn by up to "
                   f"{float(np.max(layout.turning_deg)):.0f} deg within a panel")
    tried = "" if not smoothing else \
        f" (direction fields smoothed over {', '.join(f'{x:g}' for x in smoothing)} panels tried)"
    advice = ("smooth the design's curvature near those points, lay it out in parts, or try "
              "another panel size" if why else "lay the design out in parts, or try another "
              "panel size")
    return (f"{design.name}: the layout at panel size {h:g} does not hold together: {held}"
            + (f"; the design has {' and '.join(why)}" if why else "") + tried + f"; {advice}")


#: the panel sizes `holding_panel_size` tries, as factors of the one asked: larger first
#: (a lattice of larger panels bridges more of the directions' turns), then smaller
HOLDING_SIZE_FACTORS = (1.5, 2.0, 0.75, 2.5)


def holding_panel_size(design: DesignSurface, panel_size: float, *, angle: float = 90.0
                       ) -> float | None:
    """Where to look when the size asked gives a `BrokenLayoutError`: another panel size
    whose lattice holds together.

    Parameters
    ----------
    design : the surface.
    panel_size : the size that broke (model units).
    angle : the layout's intersection angle (degrees).

    Returns
    -------
    float or None: the first of ``HOLDING_SIZE_FACTORS * panel_size`` (model units) at
    which `layout_surface` (default settings, on `design` itself) makes a lattice that holds
    together; None when none does. A layout per size tried, a second or a few each. The
    lattice only: gliding a net on it may still leave a gap.
    """
    for factor in HOLDING_SIZE_FACTORS:
        try:
            layout_surface(design, factor * panel_size, angle=angle)
        except (InputError, ArithmeticError, np.linalg.LinAlgError):
            continue
        return factor * panel_size
    return None


def layout_again(record: dict) -> SurfaceLayout:
    """The layout a net's JSON record describes (`SurfaceLayout.record`, under
    ``properties.layout``), made again.

    A layout is deterministic: the same design (at the same triangle count), panel size,
    angle, family and smoothing give the same net, so a net optimized after its layout can
    be trimmed to the design again (`fabplan.layout.trim.add_boundary_panels`).

    Raises
    ------
    InputError, OSError
        When the design cannot be loaded again (a file moved), or the record is
        incomplete.
    """
    from ..design.load import load_design

    try:
        # records written before the spec was kept name the design only
        spec = record.get("design_spec") or record["design"]
        resolution = record.get("design_resolution")
        design = load_design(spec, triangles=int(record["design_triangles"]),
                             resolution=None if resolution is None else tuple(resolution))
        smoothing = float(record["smoothing_panels"])
        # a line field was either asked for (`fabplan.layout.starts`) or what the cross
        # field fell back to at this length: asked for again either way
        line = record.get("direction_field") == "line"
        settings = LayoutSettings(smoothing=smoothing, smoothing_tries=(),
                                  max_smoothing=0.0 if line else
                                  max(LayoutSettings.max_smoothing, smoothing),
                                  bisector=record.get("bisector", "max"))
        layout = layout_surface(design, float(record["panel_size"]),
                                angle=float(record["angle_deg"]),
                                family=record.get("prescribed_family"), settings=settings,
                                refuse_broken=False)
        # the faces a glide dropped from it (`layout_without_faces`), dropped again
        dropped = np.asarray(record.get("dropped_faces") or [], np.int64)
        if dropped.size and dropped.max() < len(layout.mesh.faces):
            drop = np.zeros(len(layout.mesh.faces), bool)
            drop[dropped] = True
            layout = layout_without_faces(layout, drop)
        return layout
    except InputError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"the layout record is incomplete ({exc})") from None


def _design_spec(design: DesignSurface) -> str:
    """What `fabplan.design.load.load_design` loads `design` from again: a built-in
    surface's spec with its parameters, else its file or Rhino source (a built-in surface
    made from a file of values gives its name, which does not load it again)."""
    from ..design.parametric import ParametricSurface, spec_of_surface

    if isinstance(design.parametric, ParametricSurface) and (spec := spec_of_surface(design.parametric)):
        return spec
    # a file, found again from another working folder
    path = Path(design.name.split("#")[0])
    return str(path.resolve()) + design.name[len(str(path)):] if path.is_file() else design.name


def _design_resolution(design: DesignSurface) -> list[int] | None:
    """Grid cells (nu, nv) of a built-in surface's triangulation (None for a mesh)."""
    if design.parametric is None or design.uv is None:
        return None
    nu = len(np.unique(design.uv[:, 0])) - (0 if design.parametric.periodic_u else 1)
    return [int(nu), int(len(np.unique(design.uv[:, 1])) - 1)]


def _layout_once(design: DesignSurface, h: float, angle: float, family: str | None,
                 s: LayoutSettings) -> SurfaceLayout:
    """One layout at the smoothing of `s` (see `layout_surface`): its lattice
    (`fabplan.layout.lattice.layout_lattice`), refused where it has no interior vertex."""
    lattice = layout_lattice(design, h, angle, family, s)
    mesh, singular = lattice.mesh, lattice.singular
    layout = SurfaceLayout(
        mesh=mesh, design=design, panel_size=h,
        angle_deg=None if family is not None else float(angle),
        parameters=lattice.parameters, singular_points=design.vertices[singular],
        singular_index=lattice.index[singular], seam_edges=lattice.seam_edges,
        cuts=[(int(sign), *np.round(shift, 6).tolist()) for sign, shift in lattice.transitions],
        filled_holes=lattice.filled_holes, open_holes=lattice.open_holes,
        gliding_boundary=lattice.gliding_boundary, vertex_keys=lattice.vertex_keys,
        prescribed=lattice.prescribed, family=lattice.family, level_step=lattice.level_step,
        turning_points=lattice.turning_points, turning_deg=lattice.turning_deg,
        direction_symmetry=lattice.direction_symmetry, smoothing=lattice.smoothing,
        bisector=s.bisector, seconds=lattice.seconds)
    if len(mesh.stars) == 0:
        if design.area / (h * h) < s.min_panels_judged:     # the panel size is why
            raise InputError(f"{design.name}: panel size {h:g} is too large for the surface "
                             "(the layout has no interior vertex with four quads)")
        raise BrokenLayoutError(_broken_lattice(layout, None, None))
    return layout


def _check_layout_request(design: DesignSurface, h: float, angle: float,
                          s: LayoutSettings) -> None:
    """Refuse a panel size, angle or setting that cannot give a layout."""
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"--panel-size must be a positive length, got {h}")
    if not 0 < angle < 180:
        raise InputError(f"--angle must lie strictly between 0 and 180 degrees, got {angle}")
    if s.bisector not in ("max", "min"):
        raise InputError(f"bisector must be 'max' or 'min', got {s.bisector!r}")
    expected = design.area / (h * h * math.sin(math.radians(angle)))
    if expected < 9:
        raise InputError(f"{design.name}: panel size {h:g} is too large for the surface (area "
                         f"{design.area:.4g}: about {expected:.1f} panels; at most "
                         f"{math.sqrt(design.area / 9):.4g} gives a 3 x 3 patch)")


# ---------------------------------------------------------------------------- gliding


def layout_angle(net: str, design: DesignSurface, angle: float | None = None) -> float:
    """Intersection angle (degrees) of the layout a net type should start from.

    The given `angle` when there is one. Else, for a characteristic conjugate net, the
    angle of the conjugate directions symmetric to the principal ones,
    ``2 atan(sqrt(k1 / k2))`` (area-weighted median where K > 0); for an A-net (planar
    vertex stars: the families follow the asymptotic directions), ``2 atan(sqrt(-k1 /
    k2))`` where K < 0; for a linear Weingarten net of free angle, the angle whose Euler
    formula ``k1 cos^2 + k2 sin^2`` matches the line ``a k1 + b k2 = c`` fitted to the
    design's curvatures, ``2 atan(sqrt(b / a))``; 90 degrees otherwise (and where the
    surface does not have the curvature the formula needs). A start far from the angle
    the net ends at makes the solve shear the whole net.

    Examples
    --------
    >>> from fabplan.design.load import load_design
    >>> saddle = load_design("hyperbolic-paraboloid", triangles=2000)
    >>> layout_angle("anet", saddle)      # z = k x y: asymptotic lines along x and y
    90.0
    >>> layout_angle("isogonal", saddle, 70.0)
    70.0
    """
    from ..net.weingarten import weingarten_fit
    from ..solve.net_types import get_net

    if angle is not None:
        return float(angle)
    preset = get_net(net)
    asymptotic = preset.radius == "infinite" and preset.angle != "right"
    weingarten = preset.angle == "param" and preset.radius == "param"
    if not (preset.planar_faces or asymptotic or weingarten):
        return 90.0
    k1, k2, _ = face_principal_frames(design)
    area = design.face_areas
    if weingarten:
        line = weingarten_fit(k1, k2)["line"]
        if line is None or line["a"] * line["b"] <= 0:
            return 90.0
        return round(float(2 * np.degrees(np.arctan(np.sqrt(line["b"] / line["a"])))), 1)
    ratio = np.divide(k1, k2, out=np.zeros(len(k1)), where=k2 != 0)
    ratio = ratio if preset.planar_faces else -ratio
    ok = ratio > 0
    if area[ok].sum() < 0.5 * area.sum():
        return 90.0
    angles = 2 * np.degrees(np.arctan(np.sqrt(ratio[ok])))
    return round(weighted_quantile(angles, area[ok], 0.5), 1)


#: the edge lengths a gliding net keeps, in panel sizes: 0.5 - 2, with a margin
EDGE_RANGE = (0.51, 1.99)


def glide(layout: SurfaceLayout, net: str = "snet", *, angle: float | None = None,
          radius: float | None = None, settings: SolverSettings | None = None,
          fixed: np.ndarray | None = None, surface_tolerance: float = SURFACE_TOLERANCE,
          progress: Callable[[IterationRecord], None] | None = None,
          boundary_panels: bool = True,
          edge_range: tuple[float, float] = EDGE_RANGE,
          max_line_turn: float = 90.0) -> OptimizationResult:
    """Optimize a layout into a net of type `net` while it glides on the design surface.

    The vertices are held within `surface_tolerance` panel sizes of the design surface
    (point-to-plane distance to footpoints recomputed every iteration, a hard
    constraint), the layout's boundary vertices near the design boundary on the boundary
    curves; everything else is `fabplan.optimize`. The tolerance is what lets an exact
    S-net form on a curved design: held at zero distance the vertices could only slide.
    Nets with a prescribed family are held on the surface (its levels are read there).
    A net that only starts another solve needs no boundary panels (``boundary_panels=False``:
    its trim to the design is left out). `edge_range`: the edges' lengths allowed, in
    panel sizes (`EDGE_RANGE` by default). `max_line_turn`: a converged net's lines turn by
    at most this (degrees; see `fabplan.optimize`). A face the glide leaves spanning a
    corner of the design boundary (a door's) or with three corners in a line is no panel
    (`sound_faces`): it is dropped from the layout and the net solved again, up to
    `RECUTS` times, as long as the net solved again converges; the layout record of the
    result lists the faces dropped (``dropped_faces``), and the trimming cuts their place
    as boundary panels.

    Returns
    -------
    `fabplan.optimize.OptimizationResult`, with the panels between the net and the design
    boundary (`fabplan.layout.trim`) as its ``boundary_panels``; its properties also hold
    ``distance_to_design`` (model units), ``distance_to_design_relative_to_panel``,
    ``edge_length_relative_to_panel``, ``coverage`` (share of the design's area the
    full and boundary panels cover), ``coverage_net`` (the full panels alone) and
    ``boundary_panels`` (none of these three without `boundary_panels`).

    Raises
    ------
    InputError
        For an S*-net type; `BrokenLayoutError` when the trimmed net leaves a gap larger
        than the layout's `max_gap_panels` (its lattice broke there).
    """
    from ..solve.net_types import get_net

    if get_net(net).dual:
        raise InputError(f"net type {net!r}: layouts are computed for S-nets; optimize the "
                         "S-net first and then the S*-net with `fabplan optimize`")
    solve = partial(_solve_gliding, net=net, angle=angle, radius=radius, settings=settings,
                    surface_tolerance=surface_tolerance, progress=progress,
                    edge_range=edge_range, max_line_turn=max_line_turn)
    layout, result = _without_unsound_faces(layout, fixed, solve(layout, fixed), solve)
    _measure_on_design(result, layout)
    if boundary_panels:
        panels = add_boundary_panels(result, layout)
        if panels is not None and panels.gaps and layout.max_gap_panels is not None and \
                panels.gaps[0]["area_relative_to_panel"] > layout.max_gap_panels:
            raise BrokenLayoutError(_broken_lattice(layout, panels.coverage_net, None,
                                                    panels.gaps[0]))
    result.properties["layout"] = layout.record()
    result.parameters["panel_size"] = layout.panel_size
    return result


def _solve_gliding(layout: SurfaceLayout, fixed: np.ndarray | None, *, net: str,
                   angle: float | None, radius: float | None, settings: SolverSettings | None,
                   surface_tolerance: float, progress: Callable[[IterationRecord], None] | None,
                   edge_range: tuple[float, float], max_line_turn: float) -> OptimizationResult:
    """One solve of `glide`: the layout's mesh optimized into a net of type `net` on its
    design, its vertices `fixed` held (the options as `glide` takes them)."""
    from ..solve.optimize import optimize

    design = layout.design
    extra: tuple[Constraint, ...] = ()
    # a prescribed family's levels are read on the surface: its nets are held on it
    tolerance = 0.0 if layout.prescribed is not None else surface_tolerance
    if layout.prescribed is not None:
        on_level = np.flatnonzero(np.isfinite(layout.vertex_keys[:, 0]))
        extra = (FamilyLevels(design.reference, layout.prescribed, on_level,
                              layout.vertex_keys[on_level, 0]),)
    # edges within their range (the shorter ones at their start length)
    extra += (EdgeLengthRange(edge_range[0] * layout.panel_size,
                              edge_range[1] * layout.panel_size),)
    return optimize(layout.mesh, net, angle=angle, radius=radius, reference=design.reference,
                    fixed=fixed, settings=settings, glide=True,
                    glide_boundary=layout.gliding_boundary,
                    surface_tolerance=tolerance * layout.panel_size, extra=extra,
                    max_line_turn=max_line_turn, progress=progress)


def _without_unsound_faces(layout: SurfaceLayout, fixed: np.ndarray | None,
                           result: OptimizationResult,
                           solve: Callable[[SurfaceLayout, np.ndarray | None], OptimizationResult]
                           ) -> tuple[SurfaceLayout, OptimizationResult]:
    """The layout and its glided net `result` less the faces that are no panels
    (`sound_faces`): dropped from the layout and the net solved again (`solve`), up to
    `RECUTS` times, while the net solved again converges."""
    design = layout.design
    for _ in range(RECUTS):
        # gliding on the boundary, a face may come to span a corner of it (a door's) or
        # line up three corners along it: it is no panel, and its place is cut as
        # boundary panels of a net solved without it
        # (a net that did not converge is reported as it is: its faces say why)
        if not result.converged:
            break
        unsound = ~sound_faces(design, result.mesh.vertices, result.mesh.faces,
                               layout.panel_size)
        if not unsound.any() or unsound.all():
            break
        kept = layout_without_faces(layout, unsound)
        if len(kept.mesh.stars) == 0:
            break
        kept_fixed = None if fixed is None else \
            _renumbered(np.asarray(fixed, np.int64), layout.mesh, kept.mesh)
        again = solve(kept, kept_fixed)
        if not again.converged:
            # the net without them does not form: the converged one is kept, and the
            # trimming reports its faces off the design
            break
        layout, fixed, result = kept, kept_fixed, again
    return layout, result


def _measure_on_design(result: OptimizationResult, layout: SurfaceLayout) -> None:
    """Record in `result`'s properties how far its net lies from the design and how long
    its edges are, in model units and panel sizes (`glide`)."""
    design = layout.design
    X = result.mesh.vertices
    d = design.distances(X)
    length = np.linalg.norm(X[result.mesh.edges[:, 0]] - X[result.mesh.edges[:, 1]], axis=1)
    result.properties["distance_to_design"] = {"max": float(d.max()), "mean": float(d.mean())}
    result.properties["distance_to_design_relative_to_panel"] = {
        "max": float(d.max() / layout.panel_size), "mean": float(d.mean() / layout.panel_size)}
    result.properties["edge_length_relative_to_panel"] = {
        "min": float(length.min() / layout.panel_size),
        "max": float(length.max() / layout.panel_size),
        "mean": float(length.mean() / layout.panel_size)}
    result.properties["distance_measured_to"] = (
        "the exact parametric surface" if design.parametric is not None else
        "the design's triangle mesh")
    # the triangulation's chord error tells why a net is off the exact surface; it costs
    # a closest-point search per triangle, so it is measured only when that matters
    off = d.max() > 0.01 * layout.panel_size and design.parametric is not None
    result.properties["design_chord_error"] = design.chord_error if off else None


#: a glided net is checked this many times for faces that are no panels (`sound_faces`);
#: each time they are dropped from its layout and the net is solved again
RECUTS = 3


def sound_faces(design: DesignSurface, vertices: np.ndarray, faces: list, panel_size: float
                ) -> np.ndarray:
    """(f,) bool, the faces (list of (k,) int into `vertices` (n, 3)) that are panels:
    wholly on the design (`fabplan.layout.off_design.faces_off_design`) and without three
    corners in a line (`fabplan.layout.off_design.degenerate_faces`)."""
    if len(faces) == 0:
        return np.zeros(0, bool)
    off = faces_off_design(design, vertices, faces, panel_size)
    return (off.area <= MIN_OFF_PANELS * panel_size ** 2) & ~degenerate_faces(vertices, faces)


def layout_without_faces(layout: SurfaceLayout, drop: np.ndarray) -> SurfaceLayout:
    """The layout less the faces marked in `drop` (f,) bool, and less the vertices left
    without a face (the others keep their order); the dropped faces are recorded by their
    number in the layout as extracted (`SurfaceLayout.dropped_faces`), so that
    `layout_again` drops them too."""
    from dataclasses import replace

    mesh = layout.mesh
    drop = np.asarray(drop, bool)
    faces = [f for f, gone in zip(mesh.faces, drop, strict=True) if not gone]
    used = np.unique(np.concatenate(faces))
    new_id = np.full(mesh.vertex_count, -1)
    new_id[used] = np.arange(len(used))
    kept_mesh = QuadMesh(mesh.vertices[used], [new_id[f] for f in faces], name=mesh.name)
    glide_ids = new_id[layout.gliding_boundary]
    # the faces' numbers in the layout as extracted: the ones not dropped before, in order
    total = len(mesh.faces) + len(layout.dropped_faces)
    original = np.setdiff1d(np.arange(total), layout.dropped_faces)
    out = replace(layout, mesh=kept_mesh, vertex_keys=layout.vertex_keys[used],
                  gliding_boundary=glide_ids[glide_ids >= 0],
                  dropped_faces=np.sort(np.r_[layout.dropped_faces, original[drop]]).astype(np.int64))
    if "chart" in layout.__dict__:          # the chart depends on the design only
        out.__dict__["chart"] = layout.__dict__["chart"]
    return out


def _renumbered(ids: np.ndarray, before: QuadMesh, after: QuadMesh) -> np.ndarray:
    """(k,) int, the vertices `ids` of `before` that `after` (its vertices less some,
    in order) still has, by their numbers there."""
    _, where = cKDTree(after.vertices).query(before.vertices[ids])
    found = np.linalg.norm(after.vertices[where] - before.vertices[ids], axis=1) == 0
    return where[found]
