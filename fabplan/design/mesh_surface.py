"""Design surfaces as validated triangle meshes: the surface a layout is computed on.

A designer brings a triangle mesh (OBJ, STL, PLY or OFF exported from a modeller) or a
shape described by a few parameters (`fabplan.design.parametric`). Both end up as a
`DesignSurface`: a manifold, consistently oriented triangle mesh with area, the surface
an S-net layout is computed on and glides on.
"""

from __future__ import annotations

import os
from functools import cached_property
from pathlib import Path
from typing import Protocol

import igl
import numpy as np
import numpy.typing as npt

from ..errors import InputError
from ..net.forest import tree_parity
from ..solve.reference import ReferenceSurface
from .topology import triangle_components, triangle_pairs, vertex_fan_count

__all__ = ["DesignSurface", "ExactSurface", "weighted_quantile"]


def weighted_quantile(values: np.ndarray, weights: np.ndarray, share: float) -> float:
    """The smallest of `values` ((k,) float) at which the `weights` ((k,) float) of those
    not larger reach `share` (0..1) of their sum: a weighted quantile (0.5: the median).

    Examples
    --------
    >>> weighted_quantile(np.array([3.0, 1.0, 2.0]), np.array([1.0, 1.0, 2.0]), 0.5)
    2.0
    """
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    at = np.searchsorted(cumulative, share * cumulative[-1])
    return float(values[order][min(int(at), len(values) - 1)])


class ExactSurface(Protocol):
    """What a design asks of the exact surface its triangles sample: a map ``(u, v) ->
    xyz`` on a rectangular domain (`fabplan.design.parametric.ParametricSurface` is one).
    Declared here, so that the design mesh does not import the surfaces that make it."""

    @property
    def name(self) -> str:
        """Label used in messages."""

    @property
    def domain(self) -> tuple:
        """``((u0, u1), (v0, v1))``."""

    @property
    def periodic_u(self) -> bool:
        """The surface closes up in ``u``."""

    def points(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(..., 3) float, points at broadcastable parameters."""

    def derivatives(self, u: np.ndarray, v: np.ndarray) -> tuple:
        """fu, fv, fuu, fuv, fvv : (m, 3) float each, for (m,) parameters."""

    def principal_frames(self, u: np.ndarray, v: np.ndarray) -> tuple:
        """k1, k2 (m,), e1, e2, n (m, 3): principal curvatures and frames."""

    def closest_parameters(self, points: np.ndarray, start: np.ndarray, *,
                           iterations: int = 8) -> np.ndarray:
        """(m, 2) float, parameters of the surface points closest to `points` (m, 3)."""


class DesignSurface:
    """A validated triangle mesh to lay an S-net out on.

    Parameters
    ----------
    vertices : (n, 3) float, model units.
    triangles : (t, 3) int.
    name : label for messages (the file name or the parametric surface's name).
    uv : (n, 2) float, parameters of the vertices when triangulated from `parametric`.
    parametric : the exact surface the mesh samples (`ExactSurface`, a
        `ParametricSurface`), if any.
    units : the model units of the coordinates when the source says (a .3dm file's unit
        system), else None.
    source : what the design was read from, JSON-ready (a .3dm file's object, layer and
        units), else None.

    Raises
    ------
    InputError
        When the mesh is empty, has no area, is non-manifold (an edge in more than two
        triangles, a vertex joining separate fans) or cannot be oriented consistently.

    Notes
    -----
    Exactly coincident vertices are welded (STL stores every triangle separately),
    triangles without area and unreferenced vertices are dropped, the orientation is made
    consistent, and only the largest connected piece is kept; `repairs` counts what was
    done. Messages number vertices and triangles as in the input (from 0).
    """

    def __init__(self, vertices: npt.ArrayLike, triangles: npt.ArrayLike, *, name: str = "surface",
                 uv: npt.ArrayLike | None = None, parametric: ExactSurface | None = None,
                 units: str | None = None, source: dict | None = None) -> None:
        self.name = name
        self.parametric = parametric
        self.units = units
        self.source = source
        V = np.asarray(vertices, dtype=np.float64)
        T = np.asarray(triangles)
        if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
            raise InputError(f"{name}: no vertices (is this a surface?)")
        if T.ndim != 2 or T.shape[1] != 3 or len(T) == 0:
            raise InputError(f"{name}: no triangles (is this a surface?)")
        T = T.astype(np.int64)
        if T.min() < 0 or T.max() >= len(V):
            raise InputError(f"{name}: triangle {int(np.flatnonzero((T < 0) | (T >= len(V)))[0] // 3)}"
                             " refers to a vertex that does not exist")
        if not np.isfinite(V).all():
            raise InputError(f"{name}: vertex {int(np.flatnonzero(~np.isfinite(V).all(1))[0])} has a "
                             "non-finite coordinate")
        self.repairs: dict[str, int] = {}
        uv = None if uv is None else np.asarray(uv, dtype=np.float64)
        # input numbers of the kept vertices and triangles, for messages
        self._vertex_ids = np.arange(len(V))
        self._triangle_ids = np.arange(len(T))
        if parametric is None:
            V, T = self._weld(V, T)
        V, T, uv = self._clean(V, T, uv)
        self.vertices, self.triangles, self.uv = V, T, uv
        self._check_manifold()
        self._orient()

    # ------------------------------------------------------------------ repairs and checks
    def _weld(self, V: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Merge exactly coincident vertices, keeping the first of each in input order."""
        _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
        if len(first) == len(V):
            return V, T
        self.repairs["welded_vertices"] = int(len(V) - len(first))
        order = np.argsort(first)
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        self._vertex_ids = first[order]
        return V[first[order]], rank[inverse.ravel()][T]

    def _clean(self, V: np.ndarray, T: np.ndarray,
               uv: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        P = V[T]
        double_area = np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
        scale = float(np.ptp(V, axis=0).max())
        if not double_area.sum() > 1e-20 * max(scale, 1e-300) ** 2 or scale == 0:
            raise InputError(f"{self.name}: the surface has no area")
        repeated = (T[:, 0] == T[:, 1]) | (T[:, 1] == T[:, 2]) | (T[:, 0] == T[:, 2])
        flat = repeated | (double_area <= 1e-12 * double_area.max())
        if flat.any():
            self.repairs["dropped_degenerate_triangles"] = int(flat.sum())
            T = T[~flat]
            self._triangle_ids = self._triangle_ids[~flat]
        # keep the largest piece (triangles connected through shared edges); only crumbs
        # (at most 1 % of the area) are dropped, anything larger is a second design
        n_comp, label = triangle_components(T, len(V))
        if n_comp > 1:
            area = np.bincount(label, weights=double_area[~flat])
            main = int(np.argmax(area))
            if area.sum() - area[main] > 0.01 * area.sum():
                other = int(np.argsort(-area)[1])
                shared = np.intersect1d(T[label == main].ravel(), T[label == other].ravel())
                if shared.size:
                    raise InputError(
                        f"{self.name}: vertex {self._vertex_ids[shared[0]]} joins two sheets of "
                        "triangles that share no edge: the surface is non-manifold")
                raise InputError(
                    f"{self.name}: the surface has {n_comp} separate pieces (the largest is "
                    f"{100 * area[main] / area.sum():.0f} % of the area): lay out one piece "
                    "per file")
            self.repairs["dropped_pieces"] = int(n_comp - 1)
            self.repairs["dropped_piece_triangles"] = int(np.sum(label != main))
            keep = label == main
            T, self._triangle_ids = T[keep], self._triangle_ids[keep]
        used = np.zeros(len(V), bool)
        used[T.ravel()] = True
        if not used.all():
            remap = np.cumsum(used) - 1
            V, T = V[used], remap[T]
            uv = None if uv is None else uv[used]
            self._vertex_ids = self._vertex_ids[used]
        return V, T, uv

    def _check_manifold(self) -> None:
        T, n = self.triangles, len(self.vertices)
        a, b = T.ravel(), T[:, [1, 2, 0]].ravel()
        key = np.minimum(a, b) * n + np.maximum(a, b)
        order = np.argsort(key, kind="stable")
        skey = key[order]
        starts = np.flatnonzero(np.r_[True, skey[1:] != skey[:-1]])
        counts = np.diff(np.r_[starts, len(skey)])
        vid, tid = self._vertex_ids, self._triangle_ids
        if counts.max() > 2:
            s = starts[np.argmax(counts > 2)]
            faces = np.sort(tid[order[s:s + counts[counts > 2][0]] // 3])
            e = skey[s]
            raise InputError(
                f"{self.name}: edge ({vid[e // n]}, {vid[e % n]}) is shared by {len(faces)} "
                f"triangles ({', '.join(str(f) for f in faces[:4])}): the surface is non-manifold")
        # a vertex whose triangles form more than one fan (two sheets touching at a point)
        fans = vertex_fan_count(T, n)
        bad = np.flatnonzero(fans > 1)
        if bad.size:
            raise InputError(f"{self.name}: vertex {vid[bad[0]]} joins {fans[bad[0]]} separate fans "
                             "of triangles: the surface is non-manifold")

    def _orient(self) -> None:
        """Flip triangles so that neighbours agree, by XOR along a spanning tree."""
        T, n = self.triangles, len(self.vertices)
        f, g, same = triangle_pairs(T, n)
        flip = tree_parity(len(T), f, g, same.astype(np.int64)).astype(bool)
        if flip.sum() > len(T) / 2:
            flip = ~flip  # keep the orientation most triangles of the input have
        if flip.any():
            T = np.where(flip[:, None], T[:, [0, 2, 1]], T)
            self.repairs["flipped_triangles"] = int(flip.sum())
        f, g, same = triangle_pairs(T, n)
        if same.any():
            tid = self._triangle_ids
            raise InputError(f"{self.name}: triangles {tid[f[same][0]]} and {tid[g[same][0]]} "
                             "cannot be oriented consistently (a non-orientable surface)")
        self.triangles = T

    # ------------------------------------------------------------------ derived data
    @property
    def exact(self) -> bool:
        """Whether the design has an exact surface beside its triangles (a built-in or NURBS
        design), which `closest_points` and `distances` then use."""
        return self.parametric is not None and self.uv is not None

    def closest_points(self, points: np.ndarray) -> np.ndarray:
        """(m, 3) float, the closest point of the design to each point.

        For a parametric design it lies on the exact surface: found by Gauss-Newton from the
        one on the triangulation (which alone lies on the chords, off the surface by up to
        the triangulation's chord error). Elsewhere it lies on the triangle mesh.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        foot, _, tri = self.reference.closest_points(points)
        if self.parametric is None or self.uv is None:
            return foot
        corners = self.vertices[self.triangles[tri]]
        bary = igl.barycentric_coordinates(foot, corners[:, 0].copy(), corners[:, 1].copy(),
                                           corners[:, 2].copy())
        start = np.einsum("mk,mkj->mj", bary, self.triangle_uv(tri))
        uv = self.parametric.closest_parameters(points, start)
        return self.parametric.points(uv[:, 0], uv[:, 1])

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(m,) float, distance of each point from the design (`closest_points`)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.linalg.norm(self.closest_points(points) - points, axis=1)

    def triangle_uv(self, tri: np.ndarray) -> np.ndarray:
        """(m, 3, 2) float, parameters of the corners of triangles `tri`, a triangle across
        the seam of a periodic surface unwrapped to one side of it."""
        if self.parametric is None or self.uv is None:
            raise InputError(f"{self.name}: not a parametric design, its triangles have no parameters")
        uv = self.uv[self.triangles[tri]].copy()
        if self.parametric.periodic_u:
            (u0, u1), _ = self.parametric.domain
            period = u1 - u0
            uv[..., 0] += period * (uv[..., 0] - uv[:, :1, 0] < -period / 2)
            uv[..., 0] -= period * (uv[..., 0] - uv[:, :1, 0] > period / 2)
        return uv

    @property
    def chord_error(self) -> float:
        """How far the triangulation of a parametric design is off the exact surface: the
        largest distance of a triangle's centre or edge midpoint from it (0 for a mesh
        design; `ReferenceSurface.chord_error`)."""
        return self.reference.chord_error

    @cached_property
    def reference(self) -> ReferenceSurface:
        """The closest-point structure (libigl AABB tree) on this mesh; for a parametric
        design its distances are measured to the exact surface (`distances`)."""
        surface = ReferenceSurface(self.vertices, self.triangles)
        if self.parametric is not None and self.uv is not None:
            surface.exact_distances = self.distances
        return surface

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(t, 3) float, unit normals of the triangles."""
        P = self.vertices[self.triangles]
        N = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
        return N / np.linalg.norm(N, axis=1, keepdims=True)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """(t,) float, triangle areas."""
        P = self.vertices[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)

    @property
    def area(self) -> float:
        return float(self.face_areas.sum())

    @cached_property
    def mean_edge_length(self) -> float:
        P = self.vertices[self.triangles]
        return float(np.linalg.norm(P - P[:, [1, 2, 0]], axis=2).mean())

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """list of (k,) int arrays, the boundary loops (vertex ids in order), longest first."""
        import igl

        loops = [np.asarray(loop, dtype=np.int64) for loop in igl.boundary_loop_all(self.triangles)]
        loops = [loop for loop in loops if len(loop) > 2]
        lengths = [self.loop_length(loop) for loop in loops]
        return [loops[i] for i in np.argsort(lengths)[::-1]]

    def loop_length(self, loop: np.ndarray) -> float:
        P = self.vertices[loop]
        return float(np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1).sum())

    def boundary_curves(self) -> list[np.ndarray]:
        """The boundary loops as closed polylines, list of (k, 3) float."""
        return [self.vertices[loop] for loop in self.boundary_loops]

    @property
    def extent(self) -> float:
        """Diagonal of the bounding box (model units)."""
        return float(np.linalg.norm(np.ptp(self.vertices, axis=0)))

    def write(self, path: str | os.PathLike) -> None:
        """Write the mesh atomically: OBJ by fabplan, STL/PLY/OFF through trimesh."""
        from ..io.obj import write_obj
        from ..io.output import atomic_path

        path = Path(path)
        if path.suffix.lower() == ".obj":
            write_obj(path, self.vertices, self.triangles, f"design surface {self.name}")
            return
        import trimesh

        mesh = trimesh.Trimesh(self.vertices, self.triangles, process=False)
        with atomic_path(path) as tmp:
            mesh.export(tmp, file_type=path.suffix.lower()[1:])

    def __repr__(self) -> str:
        return (f"DesignSurface({self.name!r}, vertices={len(self.vertices)}, "
                f"triangles={len(self.triangles)})")
