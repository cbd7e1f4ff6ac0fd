"""A reference surface given as a triangle mesh, with exact closest points.

Closest points come from libigl's axis-aligned bounding-box tree (built once, exact,
about 1.5 microseconds per query point on this machine kind).
"""

from __future__ import annotations

import os
from functools import cached_property
from typing import Callable

import igl
import numpy as np

from ..errors import InputError
from ..io.resources import REFERENCE_MEMORY, check_memory
from ..io.triangles import read_triangles
from ..net.index_rows import unique_rows
from ..net.mesh import QuadMesh

__all__ = ["ReferenceSurface", "load_reference"]


class ReferenceSurface:
    """A triangle mesh to stay close to or to measure distances from.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int

    Attributes
    ----------
    exact_distances : for the triangulation of an exact surface (a built-in or NURBS
        design), ``points (m, 3) -> (m,)`` distances to that surface, which `distances`
        then reports instead of those to the chords; None otherwise. The solver's
        closest points stay on the triangles (`held_distance`).
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        self.exact_distances: Callable[[np.ndarray], np.ndarray] | None = None
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int64)
        T = self.vertices[self.triangles]
        normal = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        self.face_normals = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
        self._tree = igl.AABB()
        self._tree.init(self.vertices, self.triangles)

    def __getstate__(self) -> dict:
        # libigl's tree does not pickle: it is rebuilt on arrival (studies send designs to
        # other processes)
        return {k: v for k, v in self.__dict__.items() if k != "_tree"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._tree = igl.AABB()
        self._tree.init(self.vertices, self.triangles)

    @classmethod
    def from_mesh(cls, mesh: QuadMesh) -> "ReferenceSurface":
        """The triangulated faces of a `QuadMesh` as a reference surface."""
        return cls(mesh.vertices, mesh.triangles())

    def closest_points(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points on the surface.

        Parameters
        ----------
        points : (m, 3) float

        Returns
        -------
        footpoints : (m, 3) float
        normals : (m, 3) float, unit normal of the triangle holding each footpoint.
        triangle : (m,) int

        Examples
        --------
        >>> import numpy as np
        >>> ref = ReferenceSurface(np.eye(3), np.array([[0, 1, 2]]))
        >>> foot, normal, tri = ref.closest_points(np.zeros((1, 3)))
        >>> foot.round(4), tri
        (array([[0.3333, 0.3333, 0.3333]]), array([0]))
        """
        P = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        _, triangle, foot = self._tree.squared_distance(self.vertices, self.triangles, P)
        triangle = np.asarray(triangle, dtype=np.int64)
        return np.asarray(foot), self.face_normals[triangle], triangle

    @cached_property
    def chord_error(self) -> float:
        """How far the triangles lie from the exact surface `exact_distances` measures
        (model units): the largest distance of a triangle's centre or side midpoint from
        it; 0 without one."""
        if self.exact_distances is None or len(self.triangles) == 0:
            return 0.0
        T = self.vertices[self.triangles]
        points = np.concatenate([T.mean(axis=1), 0.5 * (T + T[:, [1, 2, 0]]).reshape(-1, 3)])
        return float(np.max(self.exact_distances(points)))

    def held_distance(self, limit: float) -> float:
        """The distance to the triangles that keeps a point within `limit` of the surface
        `distances` measures: `limit` less the triangles' `chord_error` (at least half of
        `limit`, for a triangulation as coarse as the limit is tight).

        Examples
        --------
        >>> import numpy as np
        >>> ReferenceSurface(np.eye(3), np.array([[0, 1, 2]])).held_distance(0.1)
        0.1
        """
        return max(limit - self.chord_error, 0.5 * limit)

    def on_boundary(self, foot: np.ndarray, triangle: np.ndarray, *,
                    tolerance: float = 1e-9) -> np.ndarray:
        """(m,) bool, which footpoints (from `closest_points`) lie on a boundary edge.

        A point off the surface beyond its boundary has its footpoint there; elsewhere the
        footpoint is where the surface normal through the point meets the surface.
        """
        if not hasattr(self, "_boundary_sides"):
            T = self.triangles
            sides = np.stack([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]], axis=1)   # opposite corner k
            key = np.sort(sides, axis=2).reshape(-1, 2)
            _, inverse, count = unique_rows(key, return_inverse=True, return_counts=True)
            self._boundary_sides = (count[inverse.ravel()] == 1).reshape(-1, 3)
        sides = self._boundary_sides[triangle]
        # only footpoints on a triangle with a boundary side can be on the boundary: the
        # others (most of them, every iteration of a solve) need no coordinates
        near = np.flatnonzero(sides.any(axis=1))
        result = np.zeros(len(triangle), dtype=bool)
        if len(near):
            T = self.vertices[self.triangles[triangle[near]]]
            foot = np.ascontiguousarray(np.asarray(foot, dtype=np.float64)[near])
            bary = igl.barycentric_coordinates(foot, T[:, 0].copy(), T[:, 1].copy(),
                                               T[:, 2].copy())
            result[near] = np.any((bary <= tolerance) & sides[near], axis=1)
        return result

    def boundary_curves(self) -> list:
        """The boundary loops of the surface as closed polylines, list of (k, 3) float."""
        loops = igl.boundary_loop_all(self.triangles)
        return [self.vertices[np.asarray(loop)] for loop in loops if len(loop) > 2]

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(m,) float, distance of each point from the surface (the exact one where
        `exact_distances` is set)."""
        if self.exact_distances is not None:
            return self.exact_distances(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        foot, _, _ = self.closest_points(points)
        return np.linalg.norm(foot - np.asarray(points).reshape(-1, 3), axis=1)


def load_reference(path: str | os.PathLike) -> ReferenceSurface:
    """A reference surface from a mesh file: OBJ (any polygons), STL, PLY or OFF.

    Raises
    ------
    InputError
        When the file is missing, unreadable, holds no triangles with area, or more
        triangles than the memory holds (`fabplan.io.resources.REFERENCE_MEMORY`).
    """
    vertices, triangles = read_triangles(path)
    check_memory(REFERENCE_MEMORY, len(triangles), where=str(path),
                 fix="give a coarser mesh as the reference (fewer triangles)")
    if not np.isfinite(vertices).all():
        raise InputError(f"{path}: non-finite vertex coordinates")
    surface = ReferenceSurface(vertices, triangles)
    if not np.any(np.abs(surface.face_normals).sum(axis=1) > 0):
        raise InputError(f"{path}: the surface has no area")
    return surface
