"""Curvature-adaptive face milling paths from the Meusnier spheres of an S-net (paper 3.2.1).

A cylindrical cutter cuts with the circular edge of its base. At every node of a pass the
cutting circle lies on the *safety sphere*: the Meusnier sphere of the node shrunk by a
margin, touching the same tangent plane at the node. Of the circles on that sphere
through the node, the one used is tangent to the line of the *other* family there: its
normal curvature in that direction is ``1 / R_safe``, slightly more than the surface's
``1 / R``, so the cut osculates the cross direction almost exactly while the tool moves
along the pass. The circle fixes the tool: its plane makes the angle ``phi`` with the
normal plane of the cross tangent, ``cos(phi) = r / R_safe`` (Meusnier's theorem), and
the tool axis is the circle plane's normal, tilted by ``asin(r / R_safe)`` from the
surface normal. A toroidal cutter (corner radius ``c``) is planned as the cylinder of
radius ``r - c`` on the target offset by ``c``: its corner circle lies on the safety
sphere shrunk by ``c`` about the same centre.

Conventions: every length here is in millimetres (the net's coordinates are scaled by
``mm_per_unit``), angles in degrees at the interface. The mill side is the side of the
surface the tool comes from; its unit normal ``n`` points from the surface to the tool,
and the Meusnier sphere centres must lie on that side (``p + R n``).

Reference: Pellis et al., "Principal Symmetric Meshes", sections 2.1.7 and 3.2.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import CubicSpline, PchipInterpolator
from scipy.sparse import csgraph

from ...errors import CannotMakeError, InputError
from ...net.geometry import (
    fit_star_spheres,
    osculating_tangents,
    principal_curvatures,
    principal_directions,
    star_normals,
)
from ...net.mesh import QuadMesh
from .mill_plan import MillPlan, MillSettings, MillTool, ToolPath, at_most

__all__ = [
    "circle_tool_pose",
    "plan_face_milling",
    "default_margin_mm",
    "describe_region",
    "line_sequence",
    "pass_frames",
    "evaluate_pass_frames",
    "refine_pass",
    "PassLines",
    "pass_lines",
    "choose_stride",
    "check_passes_cover",
    "walk_across_lines",
    "trace_passes",
    "place_passes_on_design",
    "beyond_design_notes",
]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def circle_tool_pose(contact: np.ndarray, normal: np.ndarray, cross: np.ndarray,
                     lead: np.ndarray, safety_radius: np.ndarray, circle_radius: float,
                     corner: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tool tip and axis whose cutting circle lies on the safety sphere, tangent to `cross`.

    Parameters
    ----------
    contact : (k, 3) float, contact points on the target (mm).
    normal : (k, 3) float, unit normals pointing to the tool side.
    cross : (k, 3) float, unit tangents of the other family's line (the circle's tangent).
    lead : (k, 3) float, tangent direction the circle's centre is moved towards (its sign
        only: the centre trails the contact point when `lead` is minus the motion).
    safety_radius : (k,) float, safety sphere radii (mm, inf for a flat target).
    circle_radius : radius of the circle put on the sphere (the cutter radius minus
        `corner`).
    corner : corner radius of a toroidal cutter: the circle is placed on the target offset
        by `corner`, on the sphere of radius ``safety_radius - corner`` about the same centre.

    Returns
    -------
    tip : (k, 3) float, centre of the cutter's end face.
    axis : (k, 3) float, unit tool axis pointing from the tip to the spindle.
    tilt : (k,) float, angle between axis and normal in radians, ``asin(r / (R_s - c))``.
    """
    sphere = np.asarray(safety_radius, dtype=np.float64) - corner
    side = _unit(np.cross(normal, cross))
    side = np.where((np.sum(side * lead, axis=1) < 0)[:, None], -side, side)
    with np.errstate(divide="ignore"):
        sin_tilt = np.where(np.isfinite(sphere), circle_radius / sphere, 0.0)
    cos_tilt = np.sqrt(np.clip(1 - sin_tilt**2, 0.0, 1.0))
    # in-plane direction from the contact to the circle's centre: cos(phi) n + sin(phi) side,
    # with cos(phi) = r / R = sin(tilt)
    inward = sin_tilt[:, None] * normal + cos_tilt[:, None] * side
    axis = cos_tilt[:, None] * normal - sin_tilt[:, None] * side
    centre = contact + corner * normal + circle_radius * inward
    tip = centre - corner * axis
    return tip, axis, np.arcsin(sin_tilt)


# --------------------------------------------------------------------------- net analysis
@dataclass
class _Nodes:
    """Per regular star: what milling needs, mill side applied (mm)."""

    vertex: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    cross: np.ndarray
    radius: np.ndarray          # Meusnier radius, inf when flat
    largest_curvature: np.ndarray  # larger principal curvature towards the tool, NaN unknown
    principal: np.ndarray       # (s, 2) principal curvatures towards the tool (NaN unknown)
    principal_directions: np.ndarray  # (s, 2, 3) their unit directions
    sphere_residual: np.ndarray  # (s,) largest distance of a star vertex from its sphere (mm)
    cross_neighbour: np.ndarray  # (s, 2) vertex ids along the other family: (-, +)


def describe_region(mesh: QuadMesh, vertices: np.ndarray) -> str:
    """The vertices (the first eight) and their bounding box in model units, for messages."""
    X = mesh.vertices[vertices]
    lo, hi = X.min(axis=0), X.max(axis=0)
    ids = ", ".join(str(int(v)) for v in vertices[:8]) + (" ..." if len(vertices) > 8 else "")
    box = " .. ".join("(" + ", ".join(f"{c:.4g}" for c in p) + ")" for p in (lo, hi))
    return f"vertices {ids} ({len(vertices)} in all, within {box})"


def _net_nodes(mesh: QuadMesh, settings: MillSettings) -> tuple[_Nodes, str]:
    """Stars with their normals, tangents and Meusnier radii on the mill side."""
    stars = mesh.stars
    if len(stars) == 0:
        raise InputError(f"{mesh.name}: the net has no regular vertex star (interior vertex of "
                         "valence 4): there is no Meusnier sphere to mill with")
    scale = settings.mm_per_unit
    X = mesh.vertices * scale
    normals = star_normals(X, stars)
    spheres = fit_star_spheres(X, stars, normals)
    t1, t2 = osculating_tangents(X, stars)
    bad = np.flatnonzero(~np.isfinite(normals).all(axis=1) | ~np.isfinite(spheres.curvature))
    if bad.size:
        raise InputError(f"{mesh.name}: the star of vertex {int(stars[bad[0], 0])} is degenerate "
                         "(no normal): merge or move its vertices")
    k = spheres.curvature
    flat = np.abs(k) < settings.flat_curvature
    if settings.side == "auto":
        side = "+" if np.sum(np.sign(k[~flat])) >= 0 else "-"
    else:
        side = settings.side
    sign = 1.0 if side == "+" else -1.0
    k = sign * k
    wrong = np.flatnonzero((k < 0) & ~flat)
    if wrong.size:
        raise CannotMakeError(
            f"{mesh.name}: the Meusnier spheres switch sides: at "
            f"{describe_region(mesh, stars[wrong, 0])} they lie on the {'-+'[side == '-']} "
            f"side, the others on the {side} side; a face mill can only cut from the side of "
            "the spheres: split the net there and mill the parts from their own sides")
    f = 0 if settings.along == "A" else 1
    cross = t2 if f == 0 else t1
    neighbours = stars[:, [4, 2]] if f == 0 else stars[:, [3, 1]]
    with np.errstate(divide="ignore"):
        radius = np.where(flat, np.inf, 1.0 / np.where(flat, 1.0, k))
    k1, k2 = principal_curvatures(X, stars, spheres.curvature)
    e1, e2 = principal_directions(X, stars)
    return _Nodes(vertex=stars[:, 0], point=X[stars[:, 0]], normal=sign * normals,
                  cross=_unit(cross), radius=radius,
                  largest_curvature=np.fmax(sign * k1, sign * k2),
                  principal=np.column_stack([sign * k1, sign * k2]),
                  principal_directions=np.stack([e1, e2], axis=1),
                  sphere_residual=spheres.residual,
                  cross_neighbour=neighbours), side


def default_margin_mm(points: np.ndarray, radius: np.ndarray, largest_curvature: np.ndarray,
                      circle_radius_mm: float, share: float = 0.005) -> float:
    """The margin that keeps a face mill's cut above the target: the rule of docs/milling.md.

    A point of the cutting circle seen from the contact in the tangent direction psi stands
    ``d^2 / (2 R_s)`` above the tangent plane (it lies on the safety sphere), the target
    ``kappa(psi) d^2 / 2`` with kappa the normal curvature; as the circle runs round, psi
    runs through every direction. The circle stays above the target only where
    ``1 / R_s`` is at least the largest principal curvature k_max; the rule takes k_max
    over the nodes within a cutter radius r (the worst direction, 45 degrees off the
    cross tangent on an orthogonal net, is reached about 1.4 r from the contact, and the
    target's height there averages its curvature along the chord).
    The rule takes the largest shortfall over the nodes and adds ``share * max R`` for the
    difference between the discrete spheres and the smooth surface they sample:

    ``margin = max_i (R_i - 1 / max{k_max,j : |p_j - p_i| <= r}) + share * max_i R_i``

    On an umbilic surface (k_max = 1/R) only the share remains; the spread of the principal
    curvatures is what the margin, and with it the scallop, grows with.

    Parameters
    ----------
    points : (s, 3) float, node positions (mm).
    radius : (s,) float, Meusnier radii (mm, inf where flat).
    largest_curvature : (s,) float, larger principal curvature towards the tool (1/mm, NaN
        where unknown: the node's own 1/R is used).
    circle_radius_mm : radius r of the cutting circle.
    share : discretization share.

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [10, 0, 0], [200, 0, 0]])
    >>> R = np.array([300.0, 310, 320])
    >>> k = np.array([1 / 280, 1 / 300, 1 / 300])
    >>> round(default_margin_mm(P, R, k, 25.0, 0.0), 6)   # 310 - 280
    30.0
    """
    from scipy.spatial import cKDTree

    finite = np.isfinite(radius)
    if not finite.any():
        return 0.0
    P, R = points[finite], radius[finite]
    k = np.where(np.isfinite(largest_curvature[finite]), largest_curvature[finite], 1.0 / R)
    k = np.maximum(k, 1.0 / R)
    tree = cKDTree(P)
    pairs = tree.sparse_distance_matrix(tree, circle_radius_mm, output_type="coo_matrix")
    reach = k.copy()
    np.maximum.at(reach, pairs.row, k[pairs.col])
    return float(np.max(R - 1.0 / reach) + share * R.max())


def line_sequence(mesh: QuadMesh, vertex: np.ndarray, cross_neighbour: np.ndarray,
                  family: int, node_of_vertex: np.ndarray | None = None
                  ) -> tuple[list, np.ndarray]:
    """The lines of `family` holding stars, in order across the net.

    Parameters
    ----------
    mesh : the net.
    vertex : (s,) int, the centre vertex of each star (``mesh.stars[:, 0]``).
    cross_neighbour : (s, 2) int, each star's two neighbours along the other family.
    family : 0 (A) or 1 (B).
    node_of_vertex : (n,) int, the node (index into `vertex`) centred at each vertex or -1;
        default ``mesh.star_of_vertex`` (every star is a node).

    Returns
    -------
    runs : list of (k,) int arrays, star indices along each pass candidate (a contiguous run
        of stars on one line), in line order.
    order : (runs,) int, position of each run's line in the sequence of lines.
    """
    lines = mesh.polylines
    s_of_v = mesh.star_of_vertex if node_of_vertex is None else node_of_vertex
    runs, line_of_run = [], []
    for i in np.flatnonzero(lines.family == family):
        s = s_of_v[lines.vertices[i]]
        ok = s >= 0
        if not ok.any():
            continue
        cuts = np.flatnonzero(np.diff(ok.astype(np.int8)) != 0) + 1
        for piece, good in zip(np.split(s, cuts), np.split(ok, cuts), strict=True):
            if good[0] and len(piece) >= 2:
                runs.append(piece)
                line_of_run.append(i)
    if not runs:
        raise CannotMakeError(f"{mesh.name}: no line of family {'AB'[family]} runs through two "
                              "regular stars: nothing to mill along")
    line_ids, run_line = np.unique(np.array(line_of_run), return_inverse=True)
    star_line = np.full(len(vertex), -1)
    star_line[np.concatenate(runs)] = np.repeat(run_line, [len(r) for r in runs])
    v_line = np.full(mesh.vertex_count, -1)
    v_line[vertex] = star_line
    a = np.repeat(star_line, 2)
    b = v_line[cross_neighbour.ravel()]
    keep = (a >= 0) & (b >= 0) & (a != b)
    n = len(line_ids)
    graph = sp.coo_matrix((np.ones(keep.sum()), (a[keep], b[keep])), shape=(n, n)).tocsr()
    graph = ((graph + graph.T) > 0).astype(np.int8)
    degree = np.asarray(graph.sum(axis=1)).ravel()
    count, _ = csgraph.connected_components(graph, directed=False)
    if count > 1 or degree.max(initial=0) > 2 or (n > 1 and graph.nnz // 2 != n - 1):
        raise CannotMakeError(f"{mesh.name}: the lines of family {'AB'[family]} do not follow "
                              "one another in one sequence across the net (irregular vertices "
                              "or a net with holes): mill the regular parts separately")
    start = int(np.flatnonzero(degree <= 1)[0])
    order_of_line = np.empty(n, dtype=np.int64)
    order_of_line[csgraph.breadth_first_order(graph, start, directed=False,
                                              return_predecessors=False)] = np.arange(n)
    return runs, order_of_line[run_line]


@dataclass
class PassLines:
    """The lines a plan's passes may run along, in order across the net (`pass_lines`).

    Attributes
    ----------
    runs : list of (m,) int arrays, node indices along each run (a contiguous stretch of
        nodes on one line), all oriented alike so that alternate passes run back and forth.
    order : (runs,) int, position of each run's line in the sequence of lines.
    node_line : (s,) int, position of each node's line in the sequence, -1 off every run.
    towards : (s,) int, which cross neighbour of each node (0: the '-' one, 1: the '+'
        one) lies towards the next line.
    count : number of lines.
    """

    runs: list
    order: np.ndarray
    node_line: np.ndarray
    towards: np.ndarray
    count: int

    @property
    def max_stride(self) -> int:
        """Largest stride a plan tries: passes along every k-th line, k < count, k <= 12."""
        return max(1, min(self.count - 1, 12))

    def first_line(self, stride: int) -> int:
        """Position of the first pass's line when passes run along every `stride`-th line:
        the passes are centred in the sequence."""
        return ((self.count - 1) % stride) // 2

    def on_pass(self, stride: int) -> np.ndarray:
        """(s,) bool, the nodes on the lines of the passes of `stride`."""
        return (self.node_line >= 0) & ((self.node_line - self.first_line(stride)) % stride == 0)

    def pass_runs(self, stride: int) -> list:
        """The runs the passes of `stride` follow, in pass order, every other one reversed
        (zig-zag)."""
        first = self.first_line(stride)
        chosen = np.flatnonzero((self.order - first) % stride == 0)
        chosen = chosen[np.argsort(self.order[chosen], kind="stable")]
        return [self.runs[i][::-1] if ((self.order[i] - first) // stride) % 2 else self.runs[i]
                for i in chosen]


def pass_lines(mesh: QuadMesh, point: np.ndarray, vertex: np.ndarray, cross_neighbour: np.ndarray,
               family: int, node_of_vertex: np.ndarray | None = None) -> PassLines:
    """The lines of `family` holding nodes, in order across the net (`line_sequence`), their
    runs oriented like the first line's.

    Parameters
    ----------
    mesh : the net.
    point : (s, 3) float, the nodes' positions.
    vertex, cross_neighbour, family, node_of_vertex : as for `line_sequence`.

    Returns
    -------
    PassLines

    Examples
    --------
    >>> g = np.arange(5.0)
    >>> net = QuadMesh.grid(np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1)[:, :, 0])
    >>> stars = net.stars
    >>> lines = pass_lines(net, net.vertices[stars[:, 0]], stars[:, 0], stars[:, [4, 2]], 0)
    >>> lines.count, lines.max_stride, lines.first_line(2), len(lines.pass_runs(2))
    (3, 2, 0, 2)
    """
    runs, order = line_sequence(mesh, vertex, cross_neighbour, family, node_of_vertex)
    reference = point[runs[int(np.argmin(order))]]
    heading = reference[-1] - reference[0]
    runs = [run if np.dot(point[run[-1]] - point[run[0]], heading) >= 0 else run[::-1]
            for run in runs]
    v_order = np.full(mesh.vertex_count, -1)
    for run, o in zip(runs, order, strict=True):
        v_order[vertex[run]] = o
    own = v_order[vertex]
    minus, plus = v_order[cross_neighbour[:, 0]], v_order[cross_neighbour[:, 1]]
    towards = np.where((plus == own + 1) | (minus == own - 1), 1, 0)
    return PassLines(runs=runs, order=order, node_line=own, towards=towards,
                     count=int(order.max()) + 1)


def choose_stride(per_node: np.ndarray, lines: PassLines,
                  scallop_mm: float) -> tuple[np.ndarray, int]:
    """The predicted scallop of every stride, and the largest stride within `scallop_mm`.

    Parameters
    ----------
    per_node : (max_stride, s) float, predicted scallop between each node and the line k
        lines on, for k = 1 .. max_stride (NaN where no pass runs there).
    lines : the lines of the passes.
    scallop_mm : the largest scallop allowed.

    Returns
    -------
    predicted : (max_stride,) float, for each stride the largest prediction over the nodes
        on its passes (inf where none is finite).
    stride : int, the largest stride whose prediction keeps the limit; 1 when none does.

    Examples
    --------
    >>> lines = PassLines([], np.arange(4), np.arange(4), np.ones(4, int), 4)
    >>> per_node = np.array([[0.002, 0.003, 0.002, np.nan],
    ...                      [0.008, 0.020, 0.009, np.nan],
    ...                      [0.030, np.nan, np.nan, np.nan]])
    >>> predicted, stride = choose_stride(per_node, lines, 0.01)
    >>> predicted.tolist(), stride
    ([0.003, 0.009, 0.03], 2)
    """
    predicted = np.full(len(per_node), np.inf)
    for k in range(1, len(per_node) + 1):
        values = per_node[k - 1, lines.on_pass(k)]
        if np.isfinite(values).any():
            predicted[k - 1] = float(np.nanmax(values))
    fits = np.flatnonzero(predicted <= scallop_mm)
    return predicted, int(fits.max()) + 1 if fits.size else 1


def check_passes_cover(mesh: QuadMesh, per_node: np.ndarray, lines: PassLines,
                       vertex: np.ndarray, cross_neighbour: np.ndarray, mm_per_unit: float,
                       tool: MillTool, family: str) -> None:
    """CannotMakeError where passes along every line leave a band uncut between them (a
    predicted scallop of inf): the lines lie farther apart than one pass cuts across.

    Parameters
    ----------
    mesh : the net (its name and vertices, model units).
    per_node : (max_stride, s) float, predicted scallops (`choose_stride`'s input).
    lines : the lines of the passes.
    vertex, cross_neighbour : (s,) and (s, 2) int, each node's vertex and its neighbours
        on the lines beside its own.
    mm_per_unit : the net's scale.
    tool : the cutter, named in the message.
    family : ``"A"`` or ``"B"``, the family the passes run along.
    """
    uncut = np.flatnonzero(lines.on_pass(1) & np.isposinf(per_node[0]))
    if uncut.size == 0:
        return
    X = mesh.vertices * mm_per_unit
    # the spacing to the neighbouring lines that carry passes (their vertices are nodes)
    on_a_pass = np.isin(cross_neighbour[uncut], vertex)
    gap = np.linalg.norm(X[cross_neighbour[uncut]] - X[vertex[uncut], None], axis=2)
    gap = float(np.max(np.where(on_a_pass, gap, 0.0)))
    raise CannotMakeError(
        f"{mesh.name}: passes along every line of family {family} leave bands uncut between "
        f"them at {describe_region(mesh, vertex[uncut])}: the lines lie up to {gap:.4g} mm "
        f"apart, farther than a pass of tool {tool.spec()} cuts across; mill a net whose "
        "lines lie closer (a layout at a smaller --panel-size), or use a wider tool")


def walk_across_lines(vertex: np.ndarray, cross_neighbour: np.ndarray, node_of_vertex: np.ndarray,
                      towards: np.ndarray, max_stride: int
                      ) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Walk from every node along the other family towards the next line, one line further
    at each step, as long as the walk passes through nodes.

    Parameters
    ----------
    vertex : (s,) int, the nodes' vertices.
    cross_neighbour : (s, 2) int, each node's two neighbours along the other family.
    node_of_vertex : (n,) int, the node centred at each vertex, -1 for none.
    towards : (s,) int, which cross neighbour (0 or 1) lies towards the next line.
    max_stride : the most steps.

    Yields
    ------
    k : int, the steps taken, 1 .. max_stride; the walk ends before the first k at which
        no walk reaches a node.
    i : (r,) int, the nodes whose walk reaches a node k lines on.
    q : (r,) int, the vertices of the nodes reached.
    """
    previous = vertex.copy()
    current = cross_neighbour[np.arange(len(vertex)), towards]
    alive = current >= 0
    for k in range(1, max_stride + 1):
        if k > 1:
            node = node_of_vertex[np.maximum(current, 0)]
            alive &= node >= 0
            candidates = cross_neighbour[np.maximum(node, 0)]
            step = np.where(candidates[:, 0] == previous, candidates[:, 1], candidates[:, 0])
            previous, current = current, np.where(alive, step, -1)
            alive &= current >= 0
        i = np.flatnonzero(alive & (node_of_vertex[np.maximum(current, 0)] >= 0))
        if not i.size:
            return
        yield k, i, current[i]


def _second_form(nodes: _Nodes, who: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """II(a, b) at nodes `who` from the discrete principal curvatures and directions
    (0 where they are unknown)."""
    k = nodes.principal[who]
    e = nodes.principal_directions[who]
    value = (k[:, 0] * np.sum(a * e[:, 0], axis=1) * np.sum(b * e[:, 0], axis=1)
             + k[:, 1] * np.sum(a * e[:, 1], axis=1) * np.sum(b * e[:, 1], axis=1))
    return np.where(np.isfinite(value), value, 0.0)


def _predicted_scallops(nodes: _Nodes, X: np.ndarray, safety: np.ndarray, circle_radius: float,
                        corner: float, max_stride: int, star_of_vertex: np.ndarray,
                        towards: np.ndarray, trailing: np.ndarray) -> np.ndarray:
    """(max_stride, s) predicted scallop between each node and the pass k lines on.

    From every node the walk goes k steps along the other family towards the next pass,
    through stars (NaN where it leaves them: no pass runs there). A point of the cutting
    circle at lateral offset x from the contact trails it by ``b = r - sqrt(r^2 - x^2)``
    and lies on the safety sphere; the target below it stands
    ``(R - sqrt(R^2 - x^2)) + II(w, s) x b + II(s, s) b^2 / 2`` above the tangent plane
    (w lateral, s trailing, the normal curvature across is 1/R, the one along the pass
    ``k1 + k2 - 1/R``). What is left between two passes is where the two profiles cross,
    found by bisection.

    Parameters
    ----------
    trailing : (max_stride, s, 3) float, unit direction behind the contact at each node
        for the passes of each stride (the motion reversed; passes alternate).
    """
    out = np.full((max_stride, len(nodes.vertex)), np.nan)

    def tangential(v, who):
        n = nodes.normal[who]
        v = v - np.sum(v * n, axis=1, keepdims=True) * n
        return _unit(v)

    def profile(who, lateral, behind):
        """The material left beside node `who` as a function of the lateral offset."""
        rs = safety[who] - corner
        R = nodes.radius[who] - corner
        k_sum = np.sum(nodes.principal[who], axis=1)
        inverse = np.where(np.isfinite(R), 1.0 / np.where(np.isfinite(R), R, 1.0), 0.0)
        k_along = np.where(np.isfinite(k_sum), k_sum - inverse, inverse)
        k_mixed = _second_form(nodes, who, lateral, behind)

        def left(x):
            with np.errstate(invalid="ignore"):
                b = circle_radius - np.sqrt(np.maximum(circle_radius**2 - x * x, 0))
                d2 = x * x + b * b
                h_cut = np.where(np.isfinite(rs), rs - np.sqrt(np.maximum(rs * rs - d2, 0)), 0.0)
                across = np.where(np.isfinite(R), R - np.sqrt(np.maximum(R * R - x * x, 0)), 0.0)
            h_target = across + k_mixed * x * b + k_along * b * b / 2
            return np.where(x < circle_radius, h_cut - h_target, np.inf)

        return left

    for k, i, q in walk_across_lines(nodes.vertex, nodes.cross_neighbour, star_of_vertex, towards,
                                     max_stride):
        j = star_of_vertex[q]
        w = np.linalg.norm(X[q] - nodes.point[i], axis=1)
        lateral_i = tangential(X[q] - nodes.point[i], i)
        lateral_j = tangential(nodes.point[i] - X[q], j)
        near = profile(i, lateral_i, trailing[k - 1, i])
        far = profile(j, lateral_j, trailing[k - 1, j])
        lo, hi = np.zeros(len(i)), w.copy()
        for _ in range(50):   # to 1e-15 of the spacing
            mid = (lo + hi) / 2
            near_higher = near(mid) > far(w - mid)
            hi = np.where(near_higher, mid, hi)
            lo = np.where(near_higher, lo, mid)
        out[k - 1, i] = near(lo)
    return out


def pass_frames(contact: np.ndarray, normal: np.ndarray, cross: np.ndarray,
                safety: np.ndarray) -> tuple[np.ndarray, list]:
    """Cubic splines through one pass's node frames, by arc length.

    Parameters
    ----------
    contact, normal, cross : (k, 3) float, the nodes' contact points (mm), unit normals and
        unit cutting directions.
    safety : (k,) float, safety sphere radii (mm, inf where flat); splined as curvature.

    Returns
    -------
    s : (k,) float, arc length of the nodes; splines : list of three `CubicSpline` (contact,
        normal, cross) and a `PchipInterpolator` of the safety curvature, which stays
        between its values at the nodes.
    """
    seg = np.linalg.norm(np.diff(contact, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    kind = "not-a-knot"   # exact on cubics: no end curvature forced to zero
    splines = [CubicSpline(s, contact, bc_type=kind), CubicSpline(s, normal, bc_type=kind),
               CubicSpline(s, cross, bc_type=kind)]
    finite = np.isfinite(safety)
    curvature = np.where(finite, 1.0 / np.where(finite, safety, 1.0), 0.0)
    # monotone between nodes: a cubic overshoots where the radii jump between long
    # segments, and a curvature crossing zero there turns the safety radius negative
    splines.append(PchipInterpolator(s, curvature))
    return s, splines


def evaluate_pass_frames(splines: list, t: np.ndarray) -> tuple:
    """Contact (k, 3), unit normal (k, 3), unit cutting direction in the tangent plane
    (k, 3) and safety radius (k,) at arc lengths `t` (k,) of `pass_frames` splines."""
    p = splines[0](t)
    n = _unit(splines[1](t))
    c = splines[2](t)
    c = _unit(c - np.sum(c * n, axis=1, keepdims=True) * n)
    k = splines[3](t)
    with np.errstate(divide="ignore"):
        radius = np.where(np.abs(k) > 0, 1.0 / k, np.inf)
    return p, n, c, radius


def refine_pass(splines: list, s: np.ndarray, tip_of, tolerance: float) -> np.ndarray:
    """Parameters of the CL points of one pass: the nodes, plus midpoints wherever the
    planned tip path leaves the straight move between neighbours by more than `tolerance`.

    Parameters
    ----------
    splines, s : the pass's frames by arc length (`pass_frames`).
    tip_of : ``tip_of(p, n, c, R, motion) -> (k, 3)`` tool tips of frames (contact, normal,
        cutting direction, safety radius, unit motion), all (k, 3) or (k,).
    tolerance : chordal tolerance (mm).
    """
    def pose(t):
        p, n, c, R = evaluate_pass_frames(splines, t)
        return tip_of(p, n, c, R, _unit(splines[0](t, 1)))
    t = s.copy()
    for _ in range(20):
        mid = (t[:-1] + t[1:]) / 2
        tips = pose(np.r_[t, mid])
        a, b, m = tips[: len(t) - 1], tips[1: len(t)], tips[len(t):]
        ab = b - a
        lam = np.clip(np.sum((m - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0, 1)
        error = np.linalg.norm(m - (a + lam[:, None] * ab), axis=1)
        split = error > tolerance
        if not split.any():
            break
        t = np.sort(np.r_[t, mid[split]])
    return t


def trace_passes(passes: Iterable[tuple[np.ndarray, ...]],
                 pose: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
                 tolerance_mm: float) -> ToolPath:
    """The cutter locations of passes through node frames: each pass splined through its
    nodes (`pass_frames`), refined to the chordal tolerance (`refine_pass`) and posed.

    Parameters
    ----------
    passes : in pass order, each pass's nodes as (contact (m, 3) float in mm, unit normal
        (m, 3), unit cutting direction (m, 3), safety radius (m,) in mm, vertex (m,) int).
    pose : ``pose(p, n, c, R, motion) -> (tip, axis, tilt_deg, R)``: tool tips (k, 3),
        axes (k, 3), tilts (k,) and the safety radii the tool keeps (k,) at frames (contact,
        normal, cutting direction, safety radius, unit motion).
    tolerance_mm : chordal tolerance.

    Returns
    -------
    ToolPath
    """
    parts = []
    for number, (contact, normal, cross, safety, node_vertex) in enumerate(passes):
        s, splines = pass_frames(contact, normal, cross, safety)
        t = refine_pass(splines, s, lambda *frame: pose(*frame)[0], tolerance_mm)
        p, n, c, R = evaluate_pass_frames(splines, t)
        tip, axis, tilt_deg, R = pose(p, n, c, R, _unit(splines[0](t, 1)))
        vertex = np.full(len(t), -1)
        vertex[np.searchsorted(t, s)] = node_vertex
        parts.append((np.full(len(t), number), p, n, c, tip, axis, tilt_deg, R, vertex))
    return ToolPath(*(np.concatenate(arrays) for arrays in zip(*parts, strict=True)))


def place_passes_on_design(passes: list, design: Any, mm_per_unit: float
                           ) -> tuple[list, np.ndarray, np.ndarray]:
    """The passes' nodes moved onto the design: each contact to the design's closest point
    to it, each normal to the design's there (on the tool's side); the cutting directions
    and safety radii stay the net's (the frames project them into the new tangent planes).

    A node whose closest point is not straight below or above it (the line to it more
    than about 6 degrees off the design's normal: a point on the design's boundary, the
    node beyond it) stays on its vertex.

    Parameters
    ----------
    passes : in pass order, each pass's nodes as (contact (m, 3) float in mm, unit normal
        (m, 3), unit cutting direction (m, 3), safety radius (m,) in mm, vertex (m,) int).
    design : a `fabplan.design.DesignSurface` in the net's model units.
    mm_per_unit : millimetres per model unit.

    Returns
    -------
    passes : the same, contacts and normals on the design.
    shift : (total nodes,) float, distance each node moved (mm), in pass order.
    beyond : (total nodes,) bool, the nodes left on their vertices (no design beneath).
    """
    from .mill_design import design_frames

    if not passes:
        return passes, np.zeros(0), np.zeros(0, bool)
    contact = np.concatenate([p[0] for p in passes])
    normal = np.concatenate([p[1] for p in passes])
    foot, design_normal = design_frames(design, contact, mm_per_unit)
    design_normal = np.where((np.sum(design_normal * normal, axis=1) < 0)[:, None],
                             -design_normal, design_normal)
    gap = contact - foot
    along = np.sum(gap * design_normal, axis=1)
    sideways = np.linalg.norm(gap - along[:, None] * design_normal, axis=1)
    beyond = sideways > 0.1 * np.abs(along) + 1e-9 * max(float(np.abs(contact).max()), 1.0)
    foot = np.where(beyond[:, None], contact, foot)
    design_normal = np.where(beyond[:, None], normal, design_normal)
    bounds = np.cumsum([len(p[0]) for p in passes])[:-1]
    moved = [(c, n, *rest) for (_, _, *rest), c, n in
             zip(passes, np.split(foot, bounds), np.split(design_normal, bounds), strict=True)]
    return moved, np.linalg.norm(foot - contact, axis=1), beyond


def beyond_design_notes(beyond: np.ndarray) -> list[str]:
    """The note on pass nodes left on the net, beyond the design (`place_passes_on_design`).

    Examples
    --------
    >>> print(*beyond_design_notes(np.array([False, True, True])))
    2 of 3 pass nodes have no point of the design straight beneath them (the design ends \
before them): they stay on the net
    >>> beyond_design_notes(np.zeros(2, bool))
    []
    """
    if not beyond.any():
        return []
    return [f"{int(beyond.sum())} of {len(beyond)} pass nodes have no point of the design "
            "straight beneath them (the design ends before them): they stay on the net"]


def _face_margin(nodes: _Nodes, tool: MillTool, settings: MillSettings) -> tuple[float, str]:
    """The margin (mm) between Meusnier and safety radii and the rule it follows, in words."""
    if settings.margin_mm is None:
        margin = default_margin_mm(nodes.point, nodes.radius, nodes.largest_curvature,
                                   tool.circle_radius_mm, settings.discretization_share)
        rule = (f"max over nodes of (R - 1 / k_max within r) + {settings.discretization_share:g}"
                " x max R (R: Meusnier radius, k_max: larger principal curvature, r: cutting "
                "circle radius)")
    else:
        margin = float(settings.margin_mm)
        rule = "given (--margin)"
    return margin, rule


def _safety_radii(mesh: QuadMesh, nodes: _Nodes, tool: MillTool, margin: float) -> np.ndarray:
    """(n,) float, the nodes' safety sphere radii (mm); InputError where the tool's cutting
    circle does not fit inside them (the nodes named, with the largest diameter that fits)."""
    r = tool.circle_radius_mm
    safety = nodes.radius - margin
    too_small = np.flatnonzero(safety - tool.corner_mm < r * (1 + 1e-9))
    if too_small.size:
        largest = 2 * (float(np.min(safety)) - tool.corner_mm) + 2 * tool.corner_mm
        raise InputError(
            f"{mesh.name}: tool {tool.spec()} is larger than the safety spheres allow at "
            f"{describe_region(mesh, nodes.vertex[too_small])}: the safety "
            f"sphere radius (Meusnier radius {np.min(nodes.radius[too_small]):.4g} mm minus margin "
            f"{margin:.4g} mm) must exceed the cutter radius; use D <= {at_most(largest)} mm")
    return safety


def _trailing_directions(nodes: _Nodes, lines: PassLines) -> np.ndarray:
    """(s, n, 3) float, the unit direction behind every node's pass at every stride 1..s:
    the passes of a stride run back and forth, each node's run oriented alike."""
    # each node's forward direction along its run (the runs are oriented alike)
    forward = np.zeros_like(nodes.point)
    for run in lines.runs:
        forward[run] = _unit(np.gradient(nodes.point[run], axis=0))
    max_stride = lines.max_stride
    trailing = np.empty((max_stride, len(nodes.vertex), 3))
    for k in range(1, max_stride + 1):
        pass_number = (lines.node_line - lines.first_line(k)) // k
        trailing[k - 1] = np.where((pass_number % 2 == 0)[:, None], -forward, forward)
    return trailing


def plan_face_milling(mesh: QuadMesh, tool: MillTool, settings: MillSettings, *,
                      design: Any = None) -> MillPlan:
    """Plan curvature-adaptive face milling passes along one family of an S-net.

    Parameters
    ----------
    mesh : the net (model units ``settings.units``).
    tool : a face mill (`parse_tool`).
    settings : the options.
    design : the `fabplan.design.DesignSurface` the net was made for (its model units), or
        None; with ``settings.paths_on == "design"`` the passes' nodes are put on it
        (`place_passes_on_design`): the spheres are the net's, the surface cut the design.

    Returns
    -------
    MillPlan

    Raises
    ------
    InputError
        No regular star; a tool larger than a safety sphere allows (the nodes and the
        largest diameter named).
    CannotMakeError
        Spheres on both sides of the surface (the nodes named); lines that do not form one
        sequence (irregular vertices, holes): the net is sound, but cannot be face milled
        in one piece from one side.
    """
    started = time.perf_counter()
    settings.check()
    if tool.kind != "face":
        raise InputError(f"{mesh.name}: tool {tool.spec()} is not a face mill: plan cones with "
                         "fabplan.fabricate.flank_milling.plan_flank_milling")
    nodes, side = _net_nodes(mesh, settings)
    family = 0 if settings.along == "A" else 1
    r = tool.circle_radius_mm
    margin, rule = _face_margin(nodes, tool, settings)
    safety = _safety_radii(mesh, nodes, tool, margin)
    lines = pass_lines(mesh, nodes.point, nodes.vertex, nodes.cross_neighbour, family)
    X = mesh.vertices * settings.mm_per_unit
    per_node = _predicted_scallops(nodes, X, safety, r, tool.corner_mm, lines.max_stride,
                                   mesh.star_of_vertex, lines.towards,
                                   _trailing_directions(nodes, lines))
    check_passes_cover(mesh, per_node, lines, nodes.vertex, nodes.cross_neighbour,
                       settings.mm_per_unit, tool, settings.along)
    predicted, stride = choose_stride(per_node, lines, settings.scallop_mm)
    notes = []
    residual = float(nodes.sphere_residual.max())
    if residual > 1e-3:
        notes.append(f"the net is not an S-net within 0.001 mm: a star's vertices lie up to "
                     f"{residual:.3g} mm off their least-squares sphere (optimize it first)")
    if predicted[stride - 1] > settings.scallop_mm:
        notes.append(f"even with passes along every line the predicted scallop is "
                     f"{predicted[0]:.4g} mm, above the limit {settings.scallop_mm:g} mm")
    passes = []
    for run in lines.pass_runs(stride):
        cross = nodes.cross[run]
        # consistent cross tangent along the run (the discrete tangents may flip sign)
        cross = cross * np.where(np.sum(cross * cross[:1], axis=1) < 0, -1.0, 1.0)[:, None]
        passes.append((nodes.point[run], nodes.normal[run], cross, safety[run], nodes.vertex[run]))
    placed_on, shift = "net", np.zeros(0)
    if design is not None and settings.paths_on == "design":
        passes, shift, beyond = place_passes_on_design(passes, design, settings.mm_per_unit)
        placed_on = "design"
        notes += beyond_design_notes(beyond)

    def pose(p, n, c, R, motion):
        tip, axis, tilt = circle_tool_pose(p, n, c, -motion, R, r, tool.corner_mm)
        return tip, axis, np.degrees(tilt), R

    path = trace_passes(passes, pose, settings.chordal_tolerance_mm)
    return MillPlan(net=mesh.name, tool=tool, settings=settings, path=path, margin_mm=margin,
                    margin_rule=rule, stride=stride, lines=lines.count, predicted_scallop_mm=predicted,
                    meusnier_radius_mm=nodes.radius, side=side, sphere_residual_mm=residual,
                    seconds=time.perf_counter() - started, notes=notes, placed_on=placed_on,
                    node_shift_mm=shift, scallop_by_node_mm=per_node[stride - 1, lines.on_pass(stride)])
