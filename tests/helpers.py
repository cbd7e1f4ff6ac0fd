"""Test helpers shared by several test modules."""

from __future__ import annotations

import numpy as np

from fabplan.mesh import QuadMesh


def noisy(mesh: QuadMesh, fraction: float, seed: int = 0) -> QuadMesh:
    """Every vertex moved by a seeded random vector of length `fraction` x mean edge."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=mesh.vertices.shape)
    d *= fraction * mesh.mean_edge_length / np.linalg.norm(d, axis=1, keepdims=True)
    return mesh.with_vertices(mesh.vertices + d)
