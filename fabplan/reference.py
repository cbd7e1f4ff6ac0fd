"""A reference surface given as a triangle mesh, with exact closest points.

Closest points are found with a k-d tree over points sampled on the triangles and an exact,
vectorized point-triangle projection on the nearest candidates; points whose candidate
list cannot prove optimality (a triangle beyond it could still be closer) are re-queried
with a longer list, so the answer is exact.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["ReferenceSurface", "closest_point_triangles", "load_reference"]


def closest_point_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                            c: np.ndarray) -> np.ndarray:
    """Closest point to ``p`` on triangle ``(a, b, c)``, elementwise.

    Parameters
    ----------
    p, a, b, c : (..., 3) float

    Returns
    -------
    (..., 3) float

    Examples
    --------
    >>> import numpy as np
    >>> tri = np.eye(3)
    >>> closest_point_triangles(np.array([0.0, 0, 0]), *tri).round(4)
    array([0.3333, 0.3333, 0.3333])
    """
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c

    def dot(u, v):
        return np.sum(u * v, axis=-1)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        out = a + ab * v[..., None] + ac * w[..., None]
        # Voronoi regions of Ericson's test, applied so that earlier regions take priority.
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        regions = [
            (~np.isfinite(out).all(axis=-1), a),
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * t[..., None]),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * (d2 / (d2 - d6))[..., None]),
            ((d6 >= 0) & (d5 <= d6), c),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * (d1 / (d1 - d3))[..., None]),
            ((d3 >= 0) & (d4 <= d3), b),
            ((d1 <= 0) & (d2 <= 0), a),
        ]
        for mask, point in regions:
            out = np.where(mask[..., None], point, out)
    return out


class ReferenceSurface:
    """A triangle mesh to stay close to.

    Parameters
    ----------
    vertices : (n, 3) float
    triangles : (t, 3) int
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, *, candidates: int = 48):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        T = self.vertices[self.triangles]
        self._corners = T
        normal = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        with np.errstate(invalid="ignore", divide="ignore"):
            self.face_normals = np.nan_to_num(normal / np.linalg.norm(normal, axis=1, keepdims=True))
        # Sample every triangle on a barycentric grid fine enough that each point of the
        # surface lies within `self._reach` of a sample of its own triangle.
        longest = np.max(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2), axis=1)
        spacing = max(float(np.median(longest)) / 2, 1e-300)
        level = np.maximum(1, np.ceil(longest / spacing)).astype(np.int64)
        samples, owner = [], []
        for L in np.unique(level):
            ids = np.flatnonzero(level == L)
            i, j = np.meshgrid(np.arange(L + 1), np.arange(L + 1), indexing="ij")
            keep = i + j <= L
            bary = np.stack([L - i[keep] - j[keep], i[keep], j[keep]], axis=1) / L
            samples.append(np.einsum("kb,tbj->tkj", bary, T[ids]).reshape(-1, 3))
            owner.append(np.repeat(ids, len(bary)))
        self._samples = np.concatenate(samples)
        self._owner = np.concatenate(owner)
        self._tree = cKDTree(self._samples)
        self._reach = float(np.max(longest / level))
        self._k = int(min(candidates, len(self._samples)))

    @classmethod
    def from_mesh(cls, mesh) -> "ReferenceSurface":
        """The triangulated faces of a `QuadMesh` as a reference surface."""
        return cls(mesh.vertices, mesh.triangles())

    def _project(self, P: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest of the candidate triangles (m, k) for each point (m, 3)."""
        nt = len(self.triangles)
        key = np.unique(np.arange(len(P))[:, None] * nt + cand)  # distinct pairs, by point
        point, tri = key // nt, key % nt
        T = self._corners[tri]
        Q = closest_point_triangles(P[point], T[:, 0], T[:, 1], T[:, 2])
        d = np.linalg.norm(Q - P[point], axis=1)
        order = np.lexsort((d, point))
        first = order[np.r_[0, np.flatnonzero(np.diff(point[order])) + 1]]
        return Q[first], tri[first]

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
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        foot = np.empty_like(P)
        tri = np.empty(len(P), dtype=np.int64)
        todo, k = np.arange(len(P)), self._k
        while todo.size:
            dist_c, near = self._tree.query(P[todo], k=k)
            near, dist_c = near.reshape(len(todo), -1), dist_c.reshape(len(todo), -1)
            cand = self._owner[near]
            f, t = self._project(P[todo], cand)
            foot[todo], tri[todo] = f, t
            if k >= len(self._samples):
                break
            # a triangle none of whose samples is nearer than d + reach cannot be closer
            d = np.linalg.norm(f - P[todo], axis=1)
            todo = todo[dist_c[:, -1] < d + self._reach]
            k = min(4 * k, len(self._samples))
        return foot, self.face_normals[tri], tri

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(m,) float, distance of each point from the surface."""
        foot, _, _ = self.closest_points(points)
        return np.linalg.norm(foot - np.asarray(points).reshape(-1, 3), axis=1)


def load_reference(path) -> ReferenceSurface:
    """A reference surface from a mesh file: OBJ (any polygons), STL, PLY or OFF.

    Raises
    ------
    InputError
        When the file is missing, unreadable, or holds no triangles with area.
    """
    from pathlib import Path

    from .errors import InputError
    from .io import read_obj

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        vertices, faces = read_obj(path)
        tris = [np.stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]], axis=1) for f in faces]
        triangles = np.concatenate(tris)
    elif suffix in (".stl", ".ply", ".off"):
        import trimesh

        try:
            loaded = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many types for malformed files
            raise InputError(f"{path}: cannot read as {suffix[1:].upper()} ({exc})") from None
        vertices, triangles = np.asarray(loaded.vertices), np.asarray(loaded.faces)
    else:
        raise InputError(f"{path}: unknown surface format {suffix or '(none)'}; "
                         "use OBJ, STL, PLY or OFF")
    if len(triangles) == 0:
        raise InputError(f"{path}: no faces")
    if not np.isfinite(vertices).all():
        raise InputError(f"{path}: non-finite vertex coordinates")
    surface = ReferenceSurface(vertices, triangles)
    if not np.any(np.abs(surface.face_normals).sum(axis=1) > 0):
        raise InputError(f"{path}: the surface has no area")
    return surface
