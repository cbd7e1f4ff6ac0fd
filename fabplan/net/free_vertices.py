"""Vertices no condition of a net holds, and where they belong.

A vertex in no star (neither a star's centre nor one of its four neighbours: the tips of a
zigzag boundary, the corners of a patch) takes part in no sphere, angle, curvature or
Weingarten condition. A solve leaves it where fairness and the pull to the reference put
it; where the net leaves the reference, the face at such a vertex bends to reach it and
matches neither its neighbours nor any of their molds. `settle_free_vertices` places these
vertices on the surface the net continues: the net's conditions are unchanged, and the
faces at them become patches of the same smooth surface as the rest.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .quadrics import face_frames, face_neighbourhoods, fit_height_fields, height_field_values

__all__ = ["free_vertices", "settle_free_vertices"]


def free_vertices(mesh) -> np.ndarray:
    """(n,) bool, the vertices in no star of `mesh` (see the module notes).

    Examples
    --------
    >>> from fabplan.net.generate import height_field_grid
    >>> int(free_vertices(height_field_grid(4, 4, lambda x, y: 0 * x)).sum())  # the corners
    4
    """
    held = np.zeros(mesh.vertex_count, bool)
    held[np.asarray(mesh.stars).ravel()] = True
    return ~held


def settle_free_vertices(mesh, keep: np.ndarray | None = None):
    """The net with every free vertex (`free_vertices`) moved onto the surface its
    neighbourhood continues.

    Every face without a free corner gets the paraboloid through its corners that fits the
    held vertices of the faces around it (`fabplan.net.quadrics`). A free vertex is moved
    along each such face's normal onto its paraboloid, for every face at one of its edge
    neighbours, and placed at the mean of those points. Its position across the surface is
    kept (up to the tilt between the face normals), so the net's outline and coverage stay.

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    keep : (k,) int, vertices that stay where they are (fixed vertices, handles).

    Returns
    -------
    mesh : `fabplan.net.mesh.QuadMesh`, the same object when nothing moves (no free vertex
        next to a held one, or no star at all).
    moved : (n,) float, how far each vertex moved (model units).
    """
    n = mesh.vertex_count
    free = free_vertices(mesh)
    if not free.any() or not len(mesh.stars):
        return mesh, np.zeros(n)
    X = mesh.vertices
    nf = len(mesh.face_sizes)
    face = np.repeat(np.arange(nf), mesh.face_sizes)
    held_face = np.bincount(face, free[mesh.face_indices], minlength=nf) == 0
    # (free vertex, held face at one of its edge neighbours) pairs
    movable = free.copy()
    if keep is not None:
        movable[np.asarray(keep, dtype=np.int64)] = False
    a, b = np.concatenate([mesh.edges, mesh.edges[:, ::-1]]).T
    step = movable[a] & ~free[b]
    neighbour = sp.csr_matrix((np.ones(int(step.sum())), (a[step], b[step])), shape=(n, n))
    keep = held_face[face]
    at = sp.csr_matrix((np.ones(int(keep.sum())), (mesh.face_indices[keep], face[keep])),
                       shape=(n, nf))
    pairs = (neighbour @ at).tocoo()
    if pairs.nnz == 0:
        return mesh, np.zeros(n)
    v, f = pairs.row, pairs.col
    origin, frame, scale = face_frames(mesh)
    vertices, weight = face_neighbourhoods(mesh, ring=True, ignore=free)
    used = np.unique(f)
    coefficients = np.zeros((nf, 6))
    coefficients[used] = fit_height_fields(X[vertices[used]], weight[used], origin[used],
                                           frame[used], scale[used])
    q = np.einsum("pj,pij->pi", X[v] - origin[f], frame[f]) / scale[f, None]
    lift = (height_field_values(coefficients[f], q[:, :2]) - q[:, 2]) * scale[f]
    target = X[v] + lift[:, None] * frame[f, 2]
    total = np.zeros_like(X)
    np.add.at(total, v, target)
    count = np.bincount(v, minlength=n)
    Y = X.copy()
    moved = count > 0
    Y[moved] = total[moved] / count[moved, None]
    return mesh.with_vertices(Y), np.linalg.norm(Y - X, axis=1)
