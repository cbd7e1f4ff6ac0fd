"""Test helpers shared by several test modules."""

from __future__ import annotations

import numpy as np

from fabplan.net.mesh import QuadMesh


def noisy(mesh: QuadMesh, fraction: float, seed: int = 0) -> QuadMesh:
    """Every vertex moved by a seeded random vector of length `fraction` x mean edge."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=mesh.vertices.shape)
    d *= fraction * mesh.mean_edge_length / np.linalg.norm(d, axis=1, keepdims=True)
    return mesh.with_vertices(mesh.vertices + d)


def jet_curvatures(X: np.ndarray, faces: list, vertices: np.ndarray):
    """Principal curvatures at the given vertices from a degree-4 height function fitted
    to the two face rings around each vertex (25 points on a regular quad grid, for 15
    coefficients) in a PCA frame (osculating jet, Cazals and Pouget 2003): an estimator
    independent of fabplan's spheres.

    Returns
    -------
    k1, k2 : (k,) float, signed with respect to `normal` (k1 <= k2).
    normal : (k, 3) float, the unit normal of the fitted height function.
    """
    n = len(X)
    adj = np.eye(n, dtype=int)
    for face in faces:  # vertices sharing a face are neighbours
        adj[np.ix_(face, face)] = 1
    two_ring = (adj @ adj) > 0
    powers = [(i, k - i) for k in range(5) for i in range(k + 1)]  # x^i y^j, degree <= 4
    k1, k2, normals = [], [], []
    for v in vertices:
        P = X[two_ring[v]] - X[v]
        _, _, vt = np.linalg.svd(P - P.mean(axis=0))
        x, y, z = P @ vt[0], P @ vt[1], P @ vt[2]
        coef = np.linalg.lstsq(np.column_stack([x**i * y**j for i, j in powers]), z, rcond=None)[0]
        c = dict(zip(powers, coef, strict=True))
        fx, fy = c[(1, 0)], c[(0, 1)]
        fxx, fxy, fyy = 2 * c[(2, 0)], c[(1, 1)], 2 * c[(0, 2)]
        w = np.sqrt(1 + fx * fx + fy * fy)
        first = np.array([[1 + fx * fx, fx * fy], [fx * fy, 1 + fy * fy]])
        second = np.array([[fxx, fxy], [fxy, fyy]]) / w
        a, b = np.sort(np.linalg.eigvals(np.linalg.solve(first, second)).real)
        k1.append(a)
        k2.append(b)
        normals.append((-fx * vt[0] - fy * vt[1] + vt[2]) / w)
    return np.array(k1), np.array(k2), np.array(normals)


def patch_of(mesh: QuadMesh, fraction: float, *, name: str = "patch.obj") -> QuadMesh:
    """The faces of `mesh` whose vertices all lie within `fraction` of the bounding box
    diagonal from its centre vertex, as a mesh of its own (vertices renumbered in order)."""
    X = mesh.vertices
    centre = X[np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1))]
    radius = fraction * np.linalg.norm(np.ptp(X, axis=0))
    inside = np.linalg.norm(X - centre, axis=1) < radius
    faces = [f for f in mesh.faces if inside[f].all()]
    used = np.unique(np.concatenate(faces))
    renumber = np.full(len(X), -1)
    renumber[used] = np.arange(len(used))
    return QuadMesh(X[used], [renumber[f] for f in faces], name=name)


def without_timings(value):
    """A JSON record without its timings (keys naming seconds), to compare runs."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if "second" not in k}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value
