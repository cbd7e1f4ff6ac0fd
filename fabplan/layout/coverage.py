"""Coverage measured on the surface: samples of the design (`design_samples`) count as
clad where a panel lies straight above or below them (`clad_points`), independently of the
plane the panels were cut in; the share of the design clad (`net_cover`) and the largest
parts left unclad (`coverage_gaps`)."""

from __future__ import annotations

import igl
import numpy as np

from ..design.mesh_surface import DesignSurface
from ..net.mesh import QuadMesh
from .gap_patches import unclad_components

__all__ = ["net_coverage", "net_cover", "coverage_gaps", "design_samples", "clad_points",
           "share_under_net", "MIN_GAP"]


def net_coverage(mesh: QuadMesh, design: DesignSurface, panel_size: float) -> float:
    """The share of the design's area under the faces of `mesh` (`clad_points`)."""
    return net_cover(mesh, design, panel_size, gaps=False)[0]


def net_cover(mesh: QuadMesh, design: DesignSurface, panel_size: float, *,
              gaps: bool = True) -> tuple[float, list[dict]]:
    """The share of the design's area under the faces of `mesh` (`clad_points`) and the largest
    parts it leaves unclad (`coverage_gaps`; none with ``gaps=False``)."""
    samples, normals, weight = design_samples(design)
    on = clad_points(samples, normals, mesh.vertices, mesh.triangles(), panel_size)
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
        (`design_samples`, four per triangle in the triangle order), `clad` (4 t,) bool
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


def design_samples(design: DesignSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points spread over the design, four per triangle: (m, 3) points, their (m, 3)
    unit normals and the (m,) area each stands for."""
    X = design.vertices[design.triangles]
    weights = np.array([[4, 1, 1], [1, 4, 1], [1, 1, 4], [1, 1, 1]]) / np.array([[6], [6], [6], [3]])
    points = np.einsum("sk,tkj->tsj", weights, X).reshape(-1, 3)
    return points, np.repeat(design.face_normals, 4, axis=0), np.repeat(design.face_areas / 4, 4)


def share_under_net(vertices: np.ndarray, triangles: np.ndarray, owner: np.ndarray, count: int,
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


def clad_points(points: np.ndarray, normals: np.ndarray, V: np.ndarray, F: np.ndarray, h: float
                ) -> np.ndarray:
    """(m,) bool, design points the cladding (V, F) covers: `_under` it, or within a
    quarter panel of it with their closest cladding point off its free edges (the sides
    of one triangle only: the cladding's outline and the rims of its gaps).

    A net solved away from the design stands off it and tilts against it, so a point under
    it may see its closest point well off its normal; a point in a gap always has it on
    the gap's rim."""
    if len(F) == 0:
        return np.zeros(len(points), bool)
    F = np.asarray(F, dtype=np.int64)
    d2, tri, closest = igl.point_mesh_squared_distance(points, V, F)
    under = _under_closest(points, normals, d2, closest, h)
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
    return _under_closest(points, normals, d2, closest, h)


def _under_closest(points: np.ndarray, normals: np.ndarray, d2: np.ndarray, closest: np.ndarray,
                   h: float) -> np.ndarray:
    """`_under`, from the squared distances (m,) and closest panel points (m, 3) of
    `points` (m, 3) found already."""
    offset = closest - points
    distance = np.sqrt(d2)
    along = np.abs(np.sum(offset * normals, axis=1))
    return (distance <= 0.01 * h) | ((along >= 0.95 * distance) & (distance <= 0.25 * h))
