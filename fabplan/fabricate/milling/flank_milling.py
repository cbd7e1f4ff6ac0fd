"""Flank milling with conical tools from the Mannheim spheres of an S*-net (paper 3.2.3).

An S*-net is a net of oriented tangent planes, given as contact elements (a vertex and
its unit normal); the five planes of every star touch one oriented sphere, the Mannheim
sphere, whose radius ``rho`` is the dual curvature radius of both ruling directions
(Def. 2.19). Three successive planes of a line envelope a cone whose ruling through the
contact point (Eq. 5) is the ruling of the developable that touches the surface along the
line; by Prop. 2.10 every cone with its vertex on that ruling and tangent to the Mannheim
sphere osculates such a developable.

The tool is a cone of revolution (half angle ``a``, tip radius ``r0``, flank length ``L``
along the axis) cutting with its flank. At a node ``p`` of a pass (normal ``n`` towards
the tool, ruling ``u`` of the pass family pointing to the tool's tip), the *safety sphere*
is the Mannheim sphere shrunk by the margin, touching the tangent plane at ``p``: radius
``R_s = rho - margin``, centre ``c = p + R_s n`` (smaller still, ``r_end / cos(a)``, where
the flank's wide end, radius ``r_end``, would otherwise not reach the contact circle). The
cone touches the tangent plane along the ruling and is circumscribed to the safety sphere:
its apex lies on the ruling at ``R_s / tan(a)`` from ``p``, its axis runs through ``c`` and
is tilted by ``90 - a`` degrees from ``n``, and it touches the sphere along the circle of
radius ``R_s cos(a)`` through ``p``: the flank's circle of that radius is the contact
circle. Moved along the line, the cone touches the developable of the line along its
rulings at every instant: the cut is that developable, whatever the margin, as long as the
cone stays inside the developable's osculating cones (margin rule below). Where the
surface curves away from the tool along the ruling (on a saddle on the side of the
Mannheim spheres) the developable stays above the surface and the flank leaves material
between passes, like a scallop. The nodes are the stars whose four neighbours are star
centres: the rulings use the neighbours' normals, and a boundary vertex's normal is held
by a single sphere.

Conventions as in `fabplan.fabricate.milling`: lengths in millimetres, angles in degrees
at the interface, the mill side is the side of the Mannheim sphere centres.

Reference: Pellis et al., "Principal Symmetric Meshes", sections 2.1.9, 2.3 and 3.2.3.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError
from ...net.geometry import (
    fit_mannheim_spheres,
    normal_curvatures,
    osculating_tangents,
    ruling_directions,
    vertex_contact_normals,
)
from ...net.mesh import QuadMesh
from .face_milling import (
    beyond_design_notes,
    check_passes_cover,
    choose_stride,
    describe_region,
    pass_lines,
    place_passes_on_design,
    trace_passes,
    walk_across_lines,
)
from .mill_plan import MillPlan, MillSettings, MillTool, at_most, every_kth

__all__ = ["ConePlan", "cone_tool_pose", "plan_flank_milling", "default_cone_margin_mm",
           "safety_radii"]

_FLANK_SAMPLES = 17


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def cone_tool_pose(contact: np.ndarray, normal: np.ndarray, ruling: np.ndarray,
                   safety_radius: np.ndarray, angle_deg: float, tip_radius_mm: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tool tip and axis of a cone touching the tangent plane along the ruling and
    circumscribed to the safety sphere.

    Parameters
    ----------
    contact : (k, 3) float, contact points (mm).
    normal : (k, 3) float, unit normals towards the tool.
    ruling : (k, 3) float, unit ruling directions in the tangent plane, towards the tip.
    safety_radius : (k,) float, safety sphere radii (mm); the sphere's centre is
        ``contact + safety_radius * normal``.
    angle_deg : half angle of the cone.
    tip_radius_mm : radius of the tool's tip (0: a sharp cone).

    Returns
    -------
    tip : (k, 3) float, centre of the tip's end face (the apex for a sharp cone).
    axis : (k, 3) float, unit axis from the tip to the spindle, ``sin(a) n - cos(a) u``.
    contact_radius : (k,) float, radius of the flank circle through the contact,
        ``R_s cos(a)``.

    Examples
    --------
    >>> tip, axis, rc = cone_tool_pose(np.zeros((1, 3)), np.array([[0.0, 0, 1]]),
    ...                                np.array([[1.0, 0, 0]]), np.array([10.0]), 45.0, 0.0)
    >>> np.round(tip, 9).tolist(), np.round(axis * np.sqrt(2), 9).tolist()
    ([[10.0, 0.0, 0.0]], [[-1.0, 0.0, 1.0]])
    """
    a = np.radians(angle_deg)
    R = np.asarray(safety_radius, dtype=np.float64)[:, None]
    apex = contact + (R / np.tan(a)) * ruling
    axis = np.sin(a) * normal - np.cos(a) * ruling
    tip = apex + (tip_radius_mm / np.tan(a)) * axis
    return tip, axis, R[:, 0] * np.cos(a)


@dataclass
class ConePlan(MillPlan):
    """A flank-milling plan: `MillPlan` whose spheres are the Mannheim spheres.

    Besides those of `MillPlan` (where ``meusnier_radius_mm`` holds the nodes' Mannheim
    radii and ``sphere_residual_mm`` the largest misfit of their stars' planes, in mm):

    Attributes
    ----------
    ruling_curvature : (s,) float, normal curvature of the target along the pass family's
        ruling at the nodes, towards the tool (1/mm; negative: curving away).
    foot_offset_mm : (s,) float, distance between a node and the point where its discrete
        Mannheim sphere touches its tangent plane.
    flank_reach_mm : (2,) float, the shortest flank length ahead of (towards the tip) and
        behind the contact over the nodes, along the ruling.
    """

    ruling_curvature: np.ndarray = None  # type: ignore[assignment]
    foot_offset_mm: np.ndarray = None  # type: ignore[assignment]
    flank_reach_mm: np.ndarray = None  # type: ignore[assignment]

    def contact_radius_mm(self) -> np.ndarray:
        """(k,) float, radius of the flank circle through each contact, ``R_s cos(a)``."""
        return self.path.safety_radius * np.cos(np.radians(self.tool.angle_deg))

    def flank_position_mm(self) -> np.ndarray:
        """(k,) float, height of each contact circle above the tip, along the axis."""
        tan = np.tan(np.radians(self.tool.angle_deg))
        return (self.contact_radius_mm() - self.tool.radius_mm) / tan

    def record(self) -> dict:
        record = super().record()
        record["mannheim_radius_mm"] = record.pop("meusnier_radius_mm")
        record["mannheim_residual_max_mm"] = record.pop("sphere_residual_max_mm")
        rc = self.contact_radius_mm()
        height = self.flank_position_mm()
        record.update({
            "contact_diameter_mm": {"min": float(2 * rc.min()), "max": float(2 * rc.max())},
            "contact_height_above_tip_mm": {"min": float(height.min()), "max": float(height.max())},
            "ruling_curvature_per_mm": {"min": float(self.ruling_curvature.min()),
                                        "max": float(self.ruling_curvature.max())},
            "mannheim_foot_offset_max_mm": float(self.foot_offset_mm.max()),
            "flank_reach_mm": {"ahead": float(self.flank_reach_mm[0]),
                               "behind": float(self.flank_reach_mm[1])},
        })
        return record

    def csv(self) -> str:
        """One row per cutter location: pass, vertex, tip, axis, contact, normal, ruling
        (towards the tip), tilt, safety sphere radius and contact circle radius (mm, deg)."""
        return self.path.csv(cross_name="ruling",
                             extra={"contact_radius_mm": self.contact_radius_mm()})

    def summary(self) -> str:
        r = self.record()
        return (f"{r['passes']} flank passes along family {r['along']} "
                f"({every_kth(self.stride, self.lines)}), {r['cutter_locations']} cutter locations, tilt "
                f"{r['tilt_deg']['min']:.2f} deg, margin {self.margin_mm:.4g} mm, contact "
                f"diameter {r['contact_diameter_mm']['min']:.4g} .. "
                f"{r['contact_diameter_mm']['max']:.4g} mm, predicted scallop "
                f"{self.predicted_max_scallop_mm:.4g} mm, path {r['path_length_mm']:.0f} mm, "
                f"planned in {self.seconds:.2f} s")


# --------------------------------------------------------------------------- net analysis
@dataclass
class _ConeNodes:
    """Per regular star: what flank milling needs, mill side applied (mm)."""

    vertex: np.ndarray           # (s,) star centres
    point: np.ndarray            # (s, 3)
    normal: np.ndarray           # (s, 3) towards the tool
    ruling: np.ndarray           # (s, 3) unit ruling of the pass family, towards the tip
    tangent: np.ndarray          # (s, 3) unit tangent of the pass family's line
    radius: np.ndarray           # (s,) Mannheim radius (> 0 on the tool side)
    ruling_curvature: np.ndarray  # (s,) II(u, u) towards the tool
    cross_curvature: np.ndarray  # (s,) II(n x u, n x u) towards the tool
    residual: np.ndarray         # (s,) plane misfit of the Mannheim sphere (mm)
    foot_offset: np.ndarray      # (s,) Mannheim sphere's touching point to the node (mm)
    cross_neighbour: np.ndarray  # (s, 2) vertex ids along the other family: (-, +)
    node_of_vertex: np.ndarray   # (n,) node centred at each vertex, -1 for none


def _cone_nodes(mesh: QuadMesh, settings: MillSettings) -> tuple[_ConeNodes, str]:
    """The nodes with their Mannheim spheres, rulings and curvatures on the mill side, and
    that side; refuses a net that is not an S*-net or whose spheres switch sides."""
    stars = mesh.stars
    if len(stars) == 0:
        raise InputError(f"{mesh.name}: the net has no regular vertex star (interior vertex of "
                         "valence 4): there is no Mannheim sphere to mill with")
    X = mesh.vertices * settings.mm_per_unit
    given = mesh.normals is not None
    N = _unit(mesh.normals) if mesh.normals is not None else vertex_contact_normals(mesh, X, stars)
    spheres = fit_mannheim_spheres(X, N, stars)
    worst = int(np.argmax(spheres.residual))
    if not np.isfinite(spheres.residual).all() or spheres.residual[worst] > settings.mannheim_tolerance_mm:
        source = "its vertex normals" if given else "the normals of its vertex stars (it has no vn)"
        raise InputError(
            f"{mesh.name}: not an S*-net: with {source} the five tangent planes of the star "
            f"of vertex {int(stars[worst, 0])} lie up to {spheres.residual[worst]:.3g} mm off "
            f"their Mannheim sphere (limit {settings.mannheim_tolerance_mm:g} mm); a cone "
            "needs an S*-net: run fabplan optimize NET --net sstar first")
    # nodes: the stars whose four neighbours are star centres too. The rulings (Eq. 5) and
    # the curvature along them use the neighbours' normals, and a boundary vertex's normal
    # is held by one star's sphere only: next to the boundary they are not to be trusted
    inner = np.flatnonzero(np.all(mesh.star_of_vertex[stars[:, 1:]] >= 0, axis=1))
    if not inner.size:
        raise InputError(f"{mesh.name}: no regular star of the net is surrounded by regular "
                         "stars: there is no ruling to mill along (the net needs at least 3 x 3 "
                         "interior vertices)")
    stars = stars[inner]
    spheres = type(spheres)(spheres.centre[inner], spheres.radius[inner], spheres.residual[inner])
    rho = spheres.radius
    if settings.side == "auto":
        side = "+" if np.sum(np.sign(rho)) >= 0 else "-"
    else:
        side = settings.side
    sign = 1.0 if side == "+" else -1.0
    wrong = np.flatnonzero(sign * rho <= 0)
    if wrong.size:
        raise InputError(
            f"{mesh.name}: the Mannheim spheres switch sides: at "
            f"{describe_region(mesh, stars[wrong, 0])} they lie on the {'-+'[side == '-']} "
            f"side (or are planes), the others on the {side} side; a cone can only be "
            "circumscribed to spheres on its own side: split the net there and mill the parts "
            "from their own sides")
    family = 0 if settings.along == "A" else 1
    rulings = ruling_directions(X, N, stars)
    tangents = osculating_tangents(X, stars)
    n = sign * N[stars[:, 0]]
    ruling = rulings[family]
    ruling = _unit(ruling - np.sum(ruling * n, axis=1, keepdims=True) * n)
    bad = np.flatnonzero(~np.isfinite(ruling).all(axis=1))
    if bad.size:
        raise InputError(f"{mesh.name}: the three tangent planes along the line through vertex "
                         f"{int(stars[bad[0], 0])} meet in no ruling (they are parallel): "
                         "optimize the net first")
    # one orientation for the whole net: along the field from the first node
    ruling *= np.where(np.sum(ruling * ruling[:1], axis=1) < 0, -1.0, 1.0)[:, None]
    tangent = _unit(tangents[family])
    centre = spheres.centre
    foot = centre - rho[:, None] * N[stars[:, 0]]
    neighbours = stars[:, [4, 2]] if family == 0 else stars[:, [3, 1]]
    node_of_vertex = np.full(mesh.vertex_count, -1)
    node_of_vertex[stars[:, 0]] = np.arange(len(stars))
    return _ConeNodes(
        vertex=stars[:, 0], point=X[stars[:, 0]], normal=n, ruling=ruling, tangent=tangent,
        radius=sign * rho, ruling_curvature=normal_curvatures(X, sign * N, stars, ruling),
        cross_curvature=normal_curvatures(X, sign * N, stars, _unit(np.cross(n, ruling))),
        residual=spheres.residual, foot_offset=np.linalg.norm(foot - X[stars[:, 0]], axis=1),
        cross_neighbour=neighbours, node_of_vertex=node_of_vertex), side


def _radius_field(points: np.ndarray, normals: np.ndarray, radius: np.ndarray):
    """Mannheim radius at points (k, 3) near the part: linear over the nodes `points` (s, 3)
    seen along their mean normal, the nearest node's outside their hull."""
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

    up = _unit(normals.mean(axis=0))
    helper = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 1.0, 0])
    ex = _unit(helper - up * (helper @ up))
    frame = np.stack([ex, np.cross(up, ex)])
    xy = points @ frame.T
    nearest = NearestNDInterpolator(xy, radius)
    try:
        linear = LinearNDInterpolator(xy, radius)
    except Exception:   # fewer than three nodes off one line: no triangulation
        linear = None

    def field(at: np.ndarray) -> np.ndarray:
        q = at @ frame.T
        values = linear(q) if linear is not None else np.full(len(q), np.nan)
        outside = ~np.isfinite(values)
        values[outside] = nearest(q[outside])
        return values

    return field


def safety_radii(radius: np.ndarray, margin: float, tool: MillTool) -> np.ndarray:
    """(s,) safety sphere radii: the Mannheim radii less the margin, and at most
    ``r_end / cos(a)``, the sphere whose contact circle is the flank's wide end.

    Examples
    --------
    >>> tool = MillTool("cone", 0.0, 0.0, 10.0, 45.0)
    >>> np.round(safety_radii(np.array([8.0, 30.0]), 1.0, tool), 9).tolist()
    [7.0, 14.142135624]
    """
    a = np.radians(tool.angle_deg)
    return np.minimum(radius - margin, tool.end_radius_mm / np.cos(a))


def _flank_reach(safety: np.ndarray, tool: MillTool) -> tuple[np.ndarray, np.ndarray]:
    """Length of flank along the ruling ahead of the contact (to the tip) and behind it
    (to the flank's wide end), for safety radii `safety`."""
    a = np.radians(tool.angle_deg)
    rc = safety * np.cos(a)
    return (rc - tool.radius_mm) / np.sin(a), np.maximum(tool.end_radius_mm - rc, 0) / np.sin(a)


def _flank_excess(points: np.ndarray, ruling: np.ndarray, field, safety: np.ndarray,
                  tool: MillTool, share_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(s, m) how far each flank circle's sphere exceeds the Mannheim sphere where it lies,
    less the discretization share: ``R_s - t tan(a) - rho(p + t u) + share`` at positions
    t (s, m) along the ruling over the flank (t > 0 towards the tip), and those t."""
    ahead, behind = _flank_reach(safety, tool)
    f = np.linspace(0.0, 1.0, _FLANK_SAMPLES)
    t = np.concatenate([-behind[:, None] * f[::-1][None, :-1],
                        np.maximum(ahead, 0)[:, None] * f[None, :]], axis=1)
    at = points[:, None, :] + t[..., None] * ruling[:, None, :]
    rho_there = field(at.reshape(-1, 3)).reshape(t.shape)
    tan = np.tan(np.radians(tool.angle_deg))
    return safety[:, None] - t * tan - rho_there + share_mm, t


def default_cone_margin_mm(points: np.ndarray, normals: np.ndarray, ruling: np.ndarray,
                           radius: np.ndarray, tool: MillTool, share_mm: float) -> float:
    """The margin of docs/milling.md for a cone: every circle of the flank inside the
    Mannheim sphere of the surface where the flank lies, less a share of the radius.

    The cone's circle at distance t along the ruling from the contact (t > 0 towards the
    tip) is the contact circle of a sphere of radius ``R_s - t tan(a)`` touching the
    tangent plane on the ruling: second-order contact analysis of the cone against the
    surface shows the flank stays above it where that radius is at most the dual
    curvature radius there, ``rho(p + t u)`` (interpolated over the nodes). With
    ``R_s = min(rho - margin, R_end)``:

    ``margin = max over nodes with R_s = rho - margin, and flank points t, of
    (rho_i - rho(p_i + t u_i) - t tan(a)) + share``

    The flank positions depend on the margin: the rule is iterated to its fixed point.

    Parameters
    ----------
    points : (s, 3) float, nodes (mm).
    normals : (s, 3) float, unit normals towards the tool.
    ruling : (s, 3) float, unit rulings towards the tip.
    radius : (s,) float, Mannheim radii (mm, > 0).
    tool : the cone.
    share_mm : the discretization share (mm).

    Examples
    --------
    >>> g = np.arange(0.0, 30.0, 3.0)
    >>> P = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) @ np.eye(2, 3)
    >>> N, U = np.tile([0.0, 0, 1], (len(P), 1)), np.tile([1.0, 0, 0], (len(P), 1))
    >>> tool = MillTool("cone", 24.0, 0.0, 10.0, 45.0)    # R_end = 44 mm
    >>> default_cone_margin_mm(P, N, U, 40 + P[:, 0] / 10, tool, 0.25)   # all at R_end
    0.25
    """
    field = _radius_field(points, normals, radius)
    margin = share_mm
    widest = tool.end_radius_mm / np.cos(np.radians(tool.angle_deg))
    for _ in range(60):
        safety = safety_radii(radius, margin, tool)
        excess, _ = _flank_excess(points, ruling, field, safety, tool, share_mm)
        free = safety < widest
        new = max(share_mm, float((margin + excess[free].max(axis=1)).max()) if free.any() else share_mm)
        if abs(new - margin) <= 1e-9 * max(1.0, margin) or new >= radius.min():
            return new
        margin = new
    return margin


def _check_cone(mesh: QuadMesh, nodes: _ConeNodes, field, margin: float, tool: MillTool,
                settings: MillSettings, share_mm: float) -> np.ndarray:
    """The safety radii (s,); refuses a cone that cannot touch or would cut into the
    target (`InputError`)."""
    a = np.radians(tool.angle_deg)
    widest = max(float(nodes.radius.min()) - share_mm, 0.0) * np.cos(a)   # radius

    def too_big(where: np.ndarray, excess: float) -> InputError:
        # the flank's circles grow towards its wide end: a shorter flank (or a narrower
        # angle) is what fits; a flank ahead of the contact never needs more than its end
        longest = (widest - tool.radius_mm) / np.tan(a)
        fix = (f"use length <= {at_most(longest)} mm (a flank ending at a diameter <= "
               f"{at_most(2 * widest)} mm)" if longest > 0 else
               f"use a tip narrower than {2 * widest:.4g} mm")
        return InputError(
            f"{mesh.name}: tool {tool.spec()} is too long (too wide) for the safety spheres at "
            f"{describe_region(mesh, nodes.vertex[where])}: its flank ends at a diameter of "
            f"{2 * tool.end_radius_mm:.4g} mm, whose circle needs a sphere up to {excess:.4g} mm "
            f"larger than the Mannheim spheres where the flank lies allow; {fix}, or a smaller "
            "angle")

    safety = safety_radii(nodes.radius, margin, tool)
    rc = safety * np.cos(a)
    where = np.flatnonzero(rc < tool.radius_mm * (1 + 1e-12) + 1e-12)
    if where.size:
        # no margin helps a flank whose wide end is too flat: say so rather than the tip
        least = safety_radii(nodes.radius, share_mm, tool)
        if np.all(least * np.cos(a) > tool.radius_mm):
            excess, t = _flank_excess(nodes.point, nodes.ruling, field, least, tool, share_mm)
            bad = excess > 1e-9 * np.maximum(nodes.radius, 1.0)[:, None]
            if bad.any():
                raise too_big(np.flatnonzero(bad.any(axis=1)), float(excess.max()))
        fits = max(2 * float(rc.min()), 0.0)
        raise InputError(
            f"{mesh.name}: tool {tool.spec()} is too wide for the safety spheres at "
            f"{describe_region(mesh, nodes.vertex[where])}: the circle where the cone touches "
            f"the safety sphere (Mannheim radius down to {nodes.radius[where].min():.4g} mm "
            f"less the margin {margin:.4g} mm) is not wider than the tip "
            f"({tool.diameter_mm:g} mm); use tip < {fits:.4g} mm, a smaller angle or a "
            "smaller --margin")
    excess, t = _flank_excess(nodes.point, nodes.ruling, field, safety, tool, share_mm)
    bad = excess > 1e-9 * np.maximum(nodes.radius, 1.0)[:, None]
    if bad.any():
        raise too_big(np.flatnonzero(bad.any(axis=1)), float(excess.max()))
    ahead, behind_reach = _flank_reach(safety, tool)
    reach = np.maximum(ahead, behind_reach)
    dig = np.maximum(nodes.ruling_curvature, 0) * reach**2 / 2
    where = np.flatnonzero(dig > settings.flank_dig_mm)
    if where.size:
        k = nodes.ruling_curvature[where]
        allowed = float(np.sqrt(2 * settings.flank_dig_mm / k.max()))
        raise InputError(
            f"{mesh.name}: the target curves towards the tool along the rulings at "
            f"{describe_region(mesh, nodes.vertex[where])} (positive Gaussian curvature on the "
            f"side of the Mannheim spheres): the straight flank of {tool.spec()} would cut up "
            f"to {dig.max():.3g} mm below it; flank milling needs a saddle-shaped part there, "
            f"or a flank reaching at most {allowed:.3g} mm from the contact")
    return safety


# ------------------------------------------------------------------------ scallop prediction
def _predicted_scallops(nodes: _ConeNodes, safety: np.ndarray, tool: MillTool,
                        max_stride: int, node_of_vertex: np.ndarray,
                        towards: np.ndarray) -> np.ndarray:
    """(max_stride, s) predicted scallop between each node's pass and the pass k lines on.

    The flank's cut is the developable of the pass's line: above a point of the target at
    distance w from the line (in the tangent plane, across the line) it stands
    ``g w^2 / 2`` high, ``g = -II(u, u) / sin^2(u, t)`` (second order: the developable and
    the surface share their second fundamental form but for a rank-one difference that
    vanishes along the line), as far across as the flank reaches, ahead of the contact
    (towards the tip) or behind it. Where the contact circle is the flank's wide end, the
    end circle cuts behind the contact: it lies on the safety sphere and is tangent to
    ``f = n x u``, so it stands ``(1 / R_s - II(f, f)) (w / cos(u, t))^2 / 2`` above the
    target, as far as ``r_end cos(u, t)``. What is left between two passes is the largest
    lower envelope of the two profiles over the gap between them (inf where they leave a
    band uncut).
    """
    out = np.full((max_stride, len(nodes.vertex)), np.nan)
    ahead, behind = _flank_reach(safety, tool)
    cos = np.abs(np.sum(nodes.ruling * nodes.tangent, axis=1))
    sin = np.sqrt(np.maximum(1 - cos * cos, 0))
    g = np.maximum(-nodes.ruling_curvature, 0) / np.maximum(sin, 1e-12) ** 2
    end_circle = behind <= 1e-9
    g_rim = np.maximum(1 / safety - nodes.cross_curvature, 0) / np.maximum(cos, 1e-12) ** 2
    rim_reach = np.where(end_circle, tool.end_radius_mm * cos, 0.0)
    f = np.linspace(0.0, 1.0, 257)

    def profile(who, ahead_side, w):
        """Height left at distance w (r, m) across the line of nodes `who` (r,)."""
        reach = np.where(ahead_side, ahead[who], behind[who]) * sin[who]
        flank = np.where(w <= reach[:, None] * (1 + 1e-9), g[who, None] * w**2 / 2, np.inf)
        rim_ok = (~ahead_side & end_circle[who])[:, None] & (w <= rim_reach[who, None])
        rim = np.where(rim_ok, g_rim[who, None] * w**2 / 2, np.inf)
        return np.minimum(flank, rim)

    for k, i, q in walk_across_lines(nodes.vertex, nodes.cross_neighbour, node_of_vertex, towards,
                                     max_stride):
        j = node_of_vertex[q]
        gap = nodes.point[j] - nodes.point[i]
        gap -= np.sum(gap * nodes.normal[i], axis=1, keepdims=True) * nodes.normal[i]
        across_i = gap - np.sum(gap * nodes.tangent[i], axis=1, keepdims=True) * nodes.tangent[i]
        width = np.linalg.norm(across_i, axis=1)
        x = width[:, None] * f[None, :]
        near = profile(i, np.sum(nodes.ruling[i] * gap, axis=1) > 0, x)
        far = profile(j, np.sum(nodes.ruling[j] * gap, axis=1) < 0, width[:, None] - x)
        out[k - 1, i] = np.minimum(near, far).max(axis=1)
    return out


# ---------------------------------------------------------------------------- the plan
def _tip_to_the_mean_normal(nodes: _ConeNodes, a: float) -> None:
    """Turn the rulings of `nodes` (`_cone_nodes`) so that the cone of half angle `a` (rad)
    has its tip towards the side that keeps the axes closest to the mean normal."""
    up = _unit(nodes.normal.mean(axis=0))
    lean = [np.min(np.sin(a) * nodes.normal @ up - np.cos(a) * s * nodes.ruling @ up)
            for s in (1.0, -1.0)]
    if lean[1] > lean[0]:
        nodes.ruling = -nodes.ruling


def _cone_margin(nodes: _ConeNodes, tool: MillTool,
                 settings: MillSettings) -> tuple[float, str, float]:
    """The margin (mm) between Mannheim and safety radii, the rule it follows in words, and
    the discretization share (mm) the cone's check allows for (0 with a given margin)."""
    share = settings.discretization_share * float(nodes.radius.max())
    if settings.margin_mm is None:
        margin = default_cone_margin_mm(nodes.point, nodes.normal, nodes.ruling, nodes.radius,
                                        tool, share)
        rule = (f"max over nodes and flank points of (rho - rho(p + t u) - t tan a) + "
                f"{settings.discretization_share:g} x max rho (rho: Mannheim radius, t: position "
                "along the ruling towards the tip, a: the cone's half angle); safety radius "
                "min(rho - margin, r_end / cos a)")
    else:
        margin = float(settings.margin_mm)
        rule = "given (--margin)"
        share = 0.0   # a given margin is checked on the geometry alone, as for face mills
    return margin, rule, share


def plan_flank_milling(mesh: QuadMesh, tool: MillTool, settings: MillSettings, *,
                       design: Any = None) -> ConePlan:
    """Plan flank milling passes with a cone along one family of an S*-net.

    Parameters
    ----------
    mesh : the S*-net (contact elements: vertices and their ``vn`` normals; model units
        ``settings.units``).
    tool : a cone (`fabplan.fabricate.milling.parse_tool`).
    settings : the options (``margin_mm``: Mannheim radius minus safety radius).
    design : the `fabplan.design.DesignSurface` the net was made for (its model units), or
        None; with ``settings.paths_on == "design"`` the passes' nodes are put on it
        (`fabplan.fabricate.milling.place_passes_on_design`).

    Returns
    -------
    ConePlan

    Raises
    ------
    InputError
        No regular star; not an S*-net (the star named); Mannheim spheres on both sides;
        a cone too wide, too long or too short for the safety spheres, or a target
        curving towards the tool along the rulings (the nodes named, with what fits).
    """
    started = time.perf_counter()
    settings.check()
    if tool.kind != "cone":
        raise InputError(f"{mesh.name}: tool {tool.spec()} is not a cone")
    nodes, side = _cone_nodes(mesh, settings)
    family = 0 if settings.along == "A" else 1
    a = np.radians(tool.angle_deg)
    _tip_to_the_mean_normal(nodes, a)
    field = _radius_field(nodes.point, nodes.normal, nodes.radius)
    margin, rule, share = _cone_margin(nodes, tool, settings)
    safety = _check_cone(mesh, nodes, field, margin, tool, settings, share)
    lines = pass_lines(mesh, nodes.point, nodes.vertex, nodes.cross_neighbour, family,
                       nodes.node_of_vertex)
    per_node = _predicted_scallops(nodes, safety, tool, lines.max_stride, nodes.node_of_vertex,
                                   lines.towards)
    check_passes_cover(mesh, per_node, lines, nodes.vertex, nodes.cross_neighbour,
                       settings.mm_per_unit, tool, settings.along)
    predicted, stride = choose_stride(per_node, lines, settings.scallop_mm)
    notes = []
    left_out = len(mesh.stars) - len(nodes.vertex)
    if left_out:
        notes.append(f"{left_out} of {len(mesh.stars)} stars, those next to the boundary, carry "
                     "no pass: their rulings rest on boundary normals a single sphere holds")
    if predicted[stride - 1] > settings.scallop_mm:
        notes.append(f"even with passes along every line the predicted scallop is "
                     f"{predicted[0]:.4g} mm, above the limit {settings.scallop_mm:g} mm")
    tilt = 90.0 - tool.angle_deg
    widest = tool.end_radius_mm / np.cos(a)   # splines between nodes must not pass it

    def pose(p, n, u, R, motion):
        R = np.minimum(R, widest)
        tip, axis, _ = cone_tool_pose(p, n, u, R, tool.angle_deg, tool.radius_mm)
        return tip, axis, np.full(len(p), tilt), R

    passes = [(nodes.point[run], nodes.normal[run], nodes.ruling[run], safety[run],
               nodes.vertex[run]) for run in lines.pass_runs(stride)]
    placed_on, shift = "net", np.zeros(0)
    if design is not None and settings.paths_on == "design":
        passes, shift, beyond = place_passes_on_design(passes, design, settings.mm_per_unit)
        placed_on = "design"
        notes += beyond_design_notes(beyond)
    path = trace_passes(passes, pose, settings.chordal_tolerance_mm)
    ahead, behind = _flank_reach(safety, tool)
    return ConePlan(net=mesh.name, tool=tool, settings=settings, path=path, margin_mm=margin,
                    margin_rule=rule, stride=stride, lines=lines.count, predicted_scallop_mm=predicted,
                    meusnier_radius_mm=nodes.radius, side=side,
                    sphere_residual_mm=float(nodes.residual.max()),
                    seconds=time.perf_counter() - started, notes=notes, placed_on=placed_on,
                    node_shift_mm=shift, scallop_by_node_mm=per_node[stride - 1, lines.on_pass(stride)],
                    ruling_curvature=nodes.ruling_curvature,
                    foot_offset_mm=nodes.foot_offset,
                    flank_reach_mm=np.array([ahead.min(), behind.min()]))
