"""One layout's lattice at one smoothing of the directions (steps 1 to 5 of
`fabplan.layout.surface_layout`): the principal directions smoothed and combed
(`fabplan.layout.directions`), the gradients the parameters ``(phi, psi)`` should have, the
design cut open and the parameters integrated (`fabplan.layout.parametrization`), the
integer lattice extracted as quads (`fabplan.layout.extraction`), its holes filled, and
the boundary vertices that glide on the design boundary (`layout_lattice`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..errors import InputError
from ..net.mesh import QuadMesh
from .directions import (
    comb_cross_field,
    comb_line_field,
    direction_turning,
    face_adjacency,
    face_principal_frames,
    find_whole_turns,
    gradient_vectors,
    line_field_index,
    prescribed_family,
    smooth_direction_field,
    snet_directions,
)
from .extraction import clean_quads, extract_quads, fill_boundary_cells, fill_holes, sound_quads
from .parametrization import (
    CutMesh,
    boundary_circulation,
    cut_mesh,
    cut_paths,
    directional_derivatives,
    gradient_target,
    integrate_directions,
)
from .settings import LayoutSettings

__all__ = ["Lattice", "layout_lattice", "umbilic_design", "axis_directions", "UMBILIC_ANISOTROPY"]


@dataclass
class Lattice:
    """A layout's lattice of quads on the design and what was found on the way to it
    (`layout_lattice`; `fabplan.layout.surface_layout.SurfaceLayout` takes its fields).

    Attributes
    ----------
    mesh : the quad-dominant mesh, holes filled.
    parameters : (t, 3, 2) float, ``(phi, psi)`` at the corners of every design triangle,
        shifted as the extraction's grid.
    singular : (k,) int, the design vertices where the combed field is singular, and
        `index` (n_design,) float, the field's index at every design vertex (turns).
    seam_edges : number of design edges across which the combed field flips.
    transitions : ``(sign, jump)`` across the cuts.
    filled_holes, open_holes : interior holes closed with irregular vertices / left open.
    gliding_boundary : (b,) int, boundary vertices that glide on the design boundary.
    vertex_keys : (n, 2) float, the lattice parameters of every vertex (NaN in holes).
    prescribed, family, level_step : the prescribed family's function on the design
        vertices, its description and level step (None without one).
    turning_points, turning_deg : (k, 3), (k,) float, where the field turns too fast.
    direction_symmetry : 4 for a cross field, 2 for a line field; smoothing : the
        smoothing length used (panel sizes).
    seconds : time per stage.
    """

    mesh: QuadMesh
    parameters: np.ndarray
    singular: np.ndarray
    index: np.ndarray
    seam_edges: int
    transitions: list
    filled_holes: int
    open_holes: int
    gliding_boundary: np.ndarray
    vertex_keys: np.ndarray
    prescribed: np.ndarray | None
    family: str | None
    level_step: float | None
    turning_points: np.ndarray
    turning_deg: np.ndarray
    direction_symmetry: int
    smoothing: float
    seconds: dict


def layout_lattice(design: DesignSurface, h: float, angle: float, family: str | None,
                   s: LayoutSettings) -> Lattice:
    """One layout's lattice at the smoothing of `s`, panel size `h`, for an S-net at
    `angle` or the prescribed `family` (see `fabplan.layout.surface_layout.layout_surface`).

    Raises
    ------
    InputError
        When no quad can be laid out.
    """
    seconds: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds[name] = round(now - clock, 4)
        clock = now

    V = design.vertices
    normal = design.face_normals
    k1, k2, e1 = face_principal_frames(design, radius=s.curvature_radius)
    anisotropy = np.abs(k1 - k2)
    if umbilic_design(k1, k2, design.face_areas):
        # a sphere (a dome) has no principal directions: every net on it is an S-net, so
        # the lines follow the design's long axis, which has no singular point on a cap
        e1 = axis_directions(design)
        anisotropy = np.ones_like(k1)
    if s.bisector == "min":
        e1 = np.cross(normal, e1)
    e1_raw = e1       # the bisector's principal direction (`LayoutSettings.bisector`)
    lap("principal_directions")
    e1, symmetry, smoothing = _smoothed_directions(
        design, e1, anisotropy * design.face_areas, h, s, cross=family is None)
    if symmetry == 4 and angle != 90.0:
        # the combed cross field is a principal direction everywhere, continuous across
        # the lines where the larger principal curvature swaps direction (a wave's
        # inflections): the bisector of the families, turned to the `bisector` setting
        # where most of the design's anisotropy is
        agree = np.abs(np.sum(e1 * e1_raw, axis=1)) >= math.sqrt(0.5)
        weight = anisotropy * design.face_areas
        if weight[agree].sum() < weight[~agree].sum():
            e1 = np.cross(normal, e1)
    lap("smoothing")
    e1, seam = comb_line_field(design, e1)
    index = line_field_index(design, e1)
    singular = np.flatnonzero(np.nan_to_num(index) != 0)
    turning = _turning_spots(design, direction_turning(design, e1, h), s.max_turning_deg, h)
    lap("combing")
    whole_turns, turn_starts = find_whole_turns(V, singular, index[singular], h)
    fields = _gradient_fields(design, e1, anisotropy, h, angle, family, whole_turns, s)
    lap("directions")
    cut = _cut_open(design, fields, seam, e1, turn_starts)
    lap("cuts")
    P2, transitions = _integrate(design, fields, cut)
    lap("integration")
    verts, quads, keys, off = _extract(design, P2, transitions, h, s, cut.seams,
                                       fields.prescribed is not None, whole_turns)
    lap("extraction")
    if len(quads) == 0:
        raise InputError(_no_quad(design, h, s, len(singular), len(turning[0])))
    faces = list(quads)
    verts, faces, filled, opened = fill_holes(
        verts, faces, design, h, s.fill_holes_up_to,
        poles=V[whole_turns] if fields.prescribed is None else None)
    vertex_keys = np.full((len(verts), 2), np.nan)
    vertex_keys[:len(keys)] = keys
    mesh = QuadMesh(verts, faces, name=f"layout-{Path(design.name).stem}")
    lap("holes")
    gliding = _near_design_boundary(mesh, design, s.boundary_snap * h, fields.prescribed,
                                    vertex_keys[:, 0])
    lap("boundary")
    return Lattice(
        mesh=mesh, parameters=P2 + np.asarray(off), singular=singular, index=index,
        seam_edges=len(seam), transitions=transitions, filled_holes=filled, open_holes=opened,
        gliding_boundary=gliding, vertex_keys=vertex_keys, prescribed=fields.prescribed,
        family=fields.description, level_step=fields.level_step, turning_points=turning[0],
        turning_deg=turning[1], direction_symmetry=symmetry, smoothing=smoothing,
        seconds=seconds)


@dataclass
class _GradientFields:
    """What the parametrization integrates: per parameter, rows (direction, value, weight)
    of prescribed directional derivatives, the target gradients of both parameters, and
    the prescribed family's function (or None)."""

    rows: dict
    targets: list
    prescribed: np.ndarray | None = None
    description: str | None = None
    level_step: float | None = None


def _gradient_fields(design: DesignSurface, e1: np.ndarray, anisotropy: np.ndarray, h: float,
                     angle: float, family: str | None, whole_turns: np.ndarray,
                     s: LayoutSettings) -> _GradientFields:
    """The directional derivatives the two parameters should have on every triangle."""
    V, T, normal = design.vertices, design.triangles, design.face_normals
    mu = s.scale_weight
    area = design.face_areas / design.face_areas.mean()
    # near umbilics every direction is nearly symmetric to the principal ones: alignment
    # counts less there, and hardly at all within two panels of a point the field turns
    # around (a rotationally symmetric umbilic, where the grid would shrink to a point)
    confidence = np.clip(anisotropy / max(float(np.median(anisotropy)), 1e-300), 0.1, 1.0)
    if whole_turns.size and family is None:
        centroid = V[T].mean(axis=1)
        near, _ = cKDTree(V[whole_turns]).query(centroid, distance_upper_bound=2 * h)
        area = np.where(np.isfinite(near), 1e-3 * area, area)
    if family is None:
        t1, t2 = snet_directions(e1, normal, angle)
        align = confidence * area
        rows = {
            "phi": [(h * t1, np.zeros(len(T)), align), (h * t2, np.ones(len(T)), mu * area)],
            "psi": [(h * t2, np.zeros(len(T)), align), (h * t1, np.ones(len(T)), mu * area)],
        }
        targets = [gradient_target(normal, t1, t2) / h, gradient_target(normal, t2, t1) / h]
        return _GradientFields(rows, targets)
    prescribed, t, s_dir, description, level_step = prescribed_family(design, family, h, e1)
    rows = {"psi": [(h * s_dir, np.zeros(len(T)), area), (h * t, np.ones(len(T)), mu * area)]}
    targets = [np.zeros_like(t), gradient_target(normal, s_dir, t, clip=True) / h]
    return _GradientFields(rows, targets, prescribed, description, level_step)


def _cut_open(design: DesignSurface, fields: _GradientFields, seam: np.ndarray, e1: np.ndarray,
              turn_starts: np.ndarray) -> CutMesh:
    """Cut the design open along the boundary loops around which the field turns, the
    seams of the line field and the whole-turn umbilics (`cut_mesh`)."""
    loops = design.boundary_loops
    paths: list = []
    starts: list = []
    if len(loops) > 1:
        circulation = boundary_circulation(design, loops, fields.targets)
        starts = [loops[i] for i in range(1, len(loops)) if np.abs(circulation[i]).max() >= 0.5]
    if fields.prescribed is None:
        # a field turning a whole turn around a point (a rotationally symmetric umbilic)
        # gets a cut like a hole, with a shift of the grid across it
        starts += [np.array([v]) for v in turn_starts]
    if starts:
        avoid = np.zeros(len(design.vertices), bool)
        avoid[seam.ravel()] = True
        paths = cut_paths(design, starts, avoid)
    return cut_mesh(design, paths, seam if fields.prescribed is None else np.zeros((0, 2), np.int64), e1)


def _integrate(design: DesignSurface, fields: _GradientFields, cut: CutMesh) -> tuple[np.ndarray, list]:
    """The parameters ``(phi, psi)`` at the corners of every triangle, (t, 3, 2), and the
    transitions ``(sign, jump)`` across the cuts."""
    S, njump = cut.substitution()
    Tc, Xc = cut.triangles, design.vertices[cut.copy_vertex]
    values, constants = {}, {}
    for name, rows in fields.rows.items():
        x = integrate_directions(Xc, Tc, S, rows, njump)
        if njump:
            # integer jumps make the integer grid match across the cuts and seams
            fixed = np.round(x[-njump:])
            shift = S[:, -njump:] @ fixed
            moved = [(d, v - directional_derivatives(Xc, Tc, shift, d), w) for d, v, w in rows]
            x = np.r_[integrate_directions(Xc, Tc, S[:, :-njump].tocsr(), moved), fixed]
        values[name] = S @ x
        constants[name] = x[len(x) - njump:]
    if fields.prescribed is not None:
        values["phi"] = fields.prescribed[cut.copy_vertex]
        constants["phi"] = np.zeros(njump)
    P2 = np.stack([values["phi"][Tc], values["psi"][Tc]], axis=-1)     # (t, 3, 2)
    e0, e1p = P2[:, 1] - P2[:, 0], P2[:, 2] - P2[:, 0]
    if np.sum(design.face_areas * np.sign(e0[:, 0] * e1p[:, 1] - e0[:, 1] * e1p[:, 0])) < 0:
        P2[..., 1] *= -1
        constants["psi"] = -constants["psi"]
    jumps = np.stack([constants["phi"], constants["psi"]], axis=1).astype(np.int64)
    transitions = [(1, j) for j in jumps[:cut.paths] if np.any(j)] + \
        [(-1, c) for c in jumps[cut.paths:]]
    return P2, transitions


def _extract(design: DesignSurface, P2: np.ndarray, transitions: list, h: float,
             s: LayoutSettings, seams: int, prescribed: bool, whole_turns: np.ndarray) -> tuple:
    """The quads of the integer lattice, tried at several shifts of the grid (the one with
    the most quads is kept), with the boundary staircase closed.

    Returns
    -------
    vertices (n, 3), quads (q, 4), keys (n, 2) the lattice parameters, and the shift used.
    """
    V, T = design.vertices, design.triangles
    best: tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float]] | None = None
    # a seam maps phi to c - phi: only half-integer shifts keep the lattice on itself
    count = 2 if seams else s.offsets
    shifts = np.arange(count) / count
    trials = [(a, b) for a in shifts for b in shifts]
    if prescribed:
        trials = [(0.0, b) for b in shifts]
    X3 = V[T]
    for off in trials:
        moved = [(sign, shift + (2 * np.asarray(off) if sign < 0 else 0)) for sign, shift in transitions]
        verts, quads, keys = extract_quads(P2 + np.asarray(off), X3, design.face_normals, h, moved, s)
        if whole_turns.size and len(quads):
            # the grid degenerates towards a point the field turns around: leave a hole
            gap, _ = cKDTree(V[whole_turns]).query(verts[quads].mean(axis=1))
            quads = quads[gap > 2 * h]
        # quads spanning a corner of the boundary (a door's) are cut as boundary panels
        quads = quads[sound_quads(design, verts, quads, h)]
        used, quads = clean_quads(verts, quads)
        if best is None or len(quads) > len(best[1]):
            best = (verts[used], quads, keys[used], off)
    if best is None:
        raise InputError(f"{design.name}: no grid shift to try (LayoutSettings.offsets is {s.offsets}, "
                         "it must be at least 1)")
    verts, quads, keys, off = best
    if len(quads):
        verts, quads, keys, _ = fill_boundary_cells(
            verts, quads, keys, design, h, min_edge=s.boundary_min_edge, max_edge=s.max_edge)
    return verts, quads, keys, off


#: a design whose principal curvatures differ by less than this share of their mean size
#: (on 90 % of its area) is a sphere to the layout: its principal directions are noise
UMBILIC_ANISOTROPY = 0.02


def umbilic_design(k1: np.ndarray, k2: np.ndarray, area: np.ndarray) -> bool:
    """Whether a design is umbilic (a sphere) nearly everywhere: ``|k1 - k2|`` below
    `UMBILIC_ANISOTROPY` of ``(|k1| + |k2|) / 2`` on 90 % of its area (a plane, without
    curvature, is not).

    Examples
    --------
    >>> import numpy as np
    >>> umbilic_design(np.full(4, 0.0501), np.full(4, 0.05), np.ones(4))
    True
    >>> umbilic_design(np.array([0.13, 0.13]), np.zeros(2), np.ones(2))
    False
    """
    size = 0.5 * (np.abs(k1) + np.abs(k2))
    if not np.any(size > 0):
        return False
    close = np.abs(k1 - k2) <= UMBILIC_ANISOTROPY * size
    close &= size > 1e-6 * float(np.max(size))
    return bool(np.sum(area[close]) >= 0.9 * np.sum(area))


def axis_directions(design: DesignSurface) -> np.ndarray:
    """(t, 3) float, the design's long axis (the principal axis of its area in which it is
    widest, of those across its mean normal) in every triangle's plane, unit; a
    triangle facing along the axis takes the next axis."""
    centres = design.vertices[design.triangles].mean(axis=1)
    centre = np.average(centres, axis=0, weights=design.face_areas)
    spread = (centres - centre) * np.sqrt(design.face_areas)[:, None]
    _, _, axes = np.linalg.svd(spread, full_matrices=False)          # widest first
    up = np.average(design.face_normals, axis=0, weights=design.face_areas)
    # of the two widest axes, the one across the mean normal (a cap's plan, not its rise)
    axis, other = sorted(axes[:2], key=lambda a: abs(float(a @ up)))
    n = design.face_normals
    along = axis - np.sum(n * axis, axis=1, keepdims=True) * n
    weak = np.linalg.norm(along, axis=1) < 0.1
    along[weak] = other - np.sum(n[weak] * other, axis=1, keepdims=True) * n[weak]
    return along / np.linalg.norm(along, axis=1, keepdims=True)


def _smoothed_directions(design: DesignSurface, e1: np.ndarray, weight: np.ndarray,
                         panel_size: float, s: LayoutSettings, *, cross: bool
                         ) -> tuple[np.ndarray, int, float]:
    """The principal directions smoothed for the layout: as a cross field where the net
    allows it, else as a line field.

    An orthogonal S-net is the same net with its two families swapped, so its directions
    are a cross field: across a near-umbilic the principal directions may turn by a
    quarter turn without the net's lines turning at all. An S-net at another angle is
    symmetric about either principal direction, so the combed cross field serves as its
    bisector as well (`layout_lattice` turns it to the `bisector` setting). The cross field
    is smoothed over `LayoutSettings.smoothing` panels, doubled up to `max_smoothing`,
    until it has no quarter-turn singularity (which the lattice cannot follow; four of them
    surround a dome's apex); failing that, and for a prescribed family, the line field is
    smoothed.

    Returns
    -------
    e1 : (t, 3) float, the smoothed line field (uncombed).
    symmetry : 4 for a cross field, 2 for a line field.
    smoothing : the smoothing length used (panel sizes).
    """
    length = s.smoothing
    while cross and length <= s.max_smoothing:
        d, _ = smooth_direction_field(design, e1, weight, length * panel_size, symmetry=4)
        index = line_field_index(design, d, symmetry=4)
        if np.all(np.nan_to_num(2 * index) == np.round(np.nan_to_num(2 * index))):
            return comb_cross_field(design, d), 4, length
        length *= 2
    d, _ = smooth_direction_field(design, e1, weight, s.smoothing * panel_size, symmetry=2)
    return d, 2, s.smoothing


def _no_quad(design: DesignSurface, h: float, s: LayoutSettings, singular: int,
             turning: int) -> str:
    """Why no quad could be laid out at panel size `h`, with the reason that holds: the
    size (a design of a few panels), else the line field (its `singular` points and the
    `turning` places where it turns too fast for the size)."""
    panels = design.area / (h * h)
    why = (f"too large for the surface: about {panels:.0f} panels" if panels < s.min_panels_judged
           else f"at about {panels:.0f} panels the line field gives no quad: {singular} singular "
                f"points (umbilics) and {turning} places where it turns too fast for the size; "
                "try other panel sizes, --smoothing, or a design smoothed there")
    return f"{design.name}: no quad could be laid out at panel size {h:g} ({why})"


def _turning_spots(design: DesignSurface, turning: np.ndarray, limit: float,
                   panel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the field turns faster than `limit` degrees per panel: one point per
    connected patch of such triangles (its fastest one), and that patch's turning."""
    fast = np.flatnonzero(turning > limit)
    if fast.size == 0:
        return np.zeros((0, 3)), np.zeros(0)
    _, _, f, g = face_adjacency(design)
    both = np.isin(f, fast) & np.isin(g, fast)
    graph = sp.coo_matrix((np.ones(int(both.sum())), (f[both], g[both])),
                          shape=(len(turning),) * 2)
    _, label = csgraph.connected_components(graph, directed=False)
    patch = label[fast]
    order = np.lexsort((-turning[fast], patch))
    first = order[np.r_[True, patch[order][1:] != patch[order][:-1]]]
    # patches smaller than a tenth of a panel are noise of the curvature estimate
    area = np.bincount(patch, weights=design.face_areas[fast])[patch[first]]
    peak = fast[first[area >= 0.1 * panel_size**2]]
    centroid = design.vertices[design.triangles[peak]].mean(axis=1)
    return centroid, turning[peak]


def _near_design_boundary(mesh: QuadMesh, design: DesignSurface, radius: float,
                          prescribed: np.ndarray | None = None,
                          levels: np.ndarray | None = None) -> np.ndarray:
    """(b,) int, boundary vertices of the layout within `radius` of the design boundary,
    at most two faces each.

    With a prescribed family (`prescribed` on the design vertices, `levels` per layout
    vertex), a vertex only glides where its level reaches the boundary near it (within a
    quarter level), so that gliding and staying on its level do not contradict.
    """
    from ..solve.constraints.closeness import closest_points_on_polylines

    boundary = np.flatnonzero(mesh.is_boundary_vertex)
    curves = design.boundary_curves()
    if not curves or boundary.size == 0:
        return np.zeros(0, np.int64)
    foot, tangent = closest_points_on_polylines(mesh.vertices[boundary], curves)
    near = np.linalg.norm(foot - mesh.vertices[boundary], axis=1) <= radius
    # concave corners of the layout's boundary (three faces or more) would flatten their
    # faces onto the boundary curve: they stay free on the surface
    faces_at = np.bincount(mesh.face_indices, minlength=mesh.vertex_count)
    near &= faces_at[boundary] <= 2
    if prescribed is not None and levels is not None:
        # sliding along the boundary by at most the radius must reach the vertex's level
        # (linearly): a boundary running along a level set is not glided on
        step = 0.1 * radius
        at_foot = _value_at(design, prescribed, foot)
        ahead = _value_at(design, prescribed, foot + step * tangent)
        behind = _value_at(design, prescribed, foot - step * tangent)
        slope = np.abs(ahead - behind) / (2 * step)
        # ... crossing the levels, not running along one (where a level may never meet it)
        _, _, tri = design.reference.closest_points(foot)
        rate = np.linalg.norm(gradient_vectors(design, prescribed)[tri], axis=1)
        level = levels[boundary]
        near &= ~np.isfinite(level) | ((np.abs(at_foot - level) <= slope * radius)
                                       & (slope >= 0.3 * rate))
    return boundary[near]


def _value_at(design: DesignSurface, value: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m,) float, a function on the design vertices interpolated at the closest points."""
    foot, _, tri = design.reference.closest_points(points)
    V, T = design.vertices, design.triangles[tri]
    bary = igl.barycentric_coordinates(foot, V[T[:, 0]], V[T[:, 1]], V[T[:, 2]])
    return np.sum(bary * value[T], axis=1)
