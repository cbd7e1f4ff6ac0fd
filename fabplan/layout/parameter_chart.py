"""The design in the parameter plane of a layout (`ParameterChart`): point location both
ways between the plane and the surface, the domain, its boundary, and the areas of the
design triangles there. Trimming (`fabplan.layout.trim`) cuts boundary panels in it."""

from __future__ import annotations

from functools import cached_property

import igl
import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..design.mesh_surface import DesignSurface
from ..net.index_rows import unique_rows

__all__ = ["ParameterChart"]


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
        _, inverse, counts = unique_rows(key, return_inverse=True, return_counts=True)
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
