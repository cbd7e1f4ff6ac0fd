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

from .buildable import BuildLimits, BuildReport, measure_buildable
from .folds import SurfaceWithNormals
from .quadrics import (
    edge_steps,
    face_frames,
    face_neighbourhoods,
    fit_height_fields,
    height_field_values,
)

__all__ = ["free_vertices", "settle_free_vertices", "undo_new_darts"]


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


STEP_FRACTIONS = (0.25, 0.5, 0.75)
"""Where along an edge the faces' surfaces are compared (`settle_free_vertices`)."""


def settle_free_vertices(mesh, keep: np.ndarray | None = None, step: float = 0.0):
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
    step : only the free corners of faces whose surface differs from a neighbour's by more
        than this along their shared edge (model units; `fabplan.net.quadrics.edge_steps`)
        move: the others bend their faces too little to matter and stay where the solve
        left them. 0 moves them all.

    Returns
    -------
    mesh : `fabplan.net.mesh.QuadMesh`, the same object when no free vertex can move (none
        next to a held one, none stepping, or no star at all).
    moved : (n,) float, how far each vertex moved (model units).
    """
    n = mesh.vertex_count
    free = free_vertices(mesh)
    if not free.any() or not len(mesh.stars):
        return mesh, np.zeros(n)
    X = mesh.vertices
    nf = len(mesh.face_sizes)
    face = mesh.corner_faces
    held_face = np.bincount(face, free[mesh.face_indices], minlength=nf) == 0
    # (free vertex, held face at one of its edge neighbours) pairs
    movable = free.copy()
    if keep is not None:
        movable[np.asarray(keep, dtype=np.int64)] = False
    a, b = np.concatenate([mesh.edges, mesh.edges[:, ::-1]]).T
    toward = movable[a] & ~free[b]
    neighbour = sp.csr_matrix((np.ones(int(toward.sum())), (a[toward], b[toward])), shape=(n, n))
    held_corner = held_face[face]
    at = sp.csr_matrix((np.ones(int(held_corner.sum())),
                        (mesh.face_indices[held_corner], face[held_corner])), shape=(n, nf))
    pairs = (neighbour @ at).tocoo()
    if pairs.nnz == 0:
        return mesh, np.zeros(n)
    v, f = pairs.row, pairs.col
    origin, frame, scale = face_frames(mesh)
    vertices, weight = face_neighbourhoods(mesh, ring=True, ignore=free)
    coefficients = fit_height_fields(X[vertices], weight, origin, frame, scale)
    if step > 0:
        # only the free corners of faces that step against a neighbour
        over = edge_steps(mesh, origin, frame, scale, coefficients, STEP_FRACTIONS) > step
        stepping = np.zeros(nf, bool)
        stepping[mesh.interior_edge_faces[over].ravel()] = True
        corner_of = np.zeros(n, bool)
        corner_of[mesh.face_indices[stepping[face]]] = True
        chosen = corner_of[v]
        v, f = v[chosen], f[chosen]
        if v.size == 0:
            return mesh, np.zeros(n)
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


def undo_new_darts(mesh, settled: np.ndarray, solved: np.ndarray, moved: np.ndarray,
                   before: BuildReport, *, reference: SurfaceWithNormals | None = None,
                   limits: BuildLimits | None = None, rounds: int = 3
                   ) -> tuple[np.ndarray, np.ndarray, BuildReport]:
    """Put back where the solve left them the settled vertices whose move made a face
    non-convex or a line turn too much that did not before (`settle_free_vertices` lifts
    a tip along a face normal by up to half a panel: near a steep fold of the continued
    surface that can turn a corner the wrong way).

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`, the combinatorics.
    settled, solved : (n, 3) float, the positions after and before settling.
    moved : (n,) float, how far each vertex moved (model units).
    before : the `BuildReport` of `solved`.
    reference, limits : as `fabplan.net.buildable.measure_buildable` takes them.
    rounds : at most this many rounds of putting back (a vertex put back may leave its
        neighbour's move to blame).

    Returns
    -------
    positions : (n, 3) float; moved : (n,) float, zero where put back; the `BuildReport`
    of the positions.

    Examples
    --------
    >>> from fabplan.net.generate import height_field_grid
    >>> grid = height_field_grid(4, 4, lambda x, y: 0 * x)
    >>> before = measure_buildable(grid)
    >>> X = grid.vertices.copy()
    >>> X[0, :2] = X[5, :2] + 0.2 * (X[5, :2] - X[0, :2])   # a corner pushed past the centre
    >>> moved = np.linalg.norm(X - grid.vertices, axis=1)
    >>> measure_buildable(grid, X).buildable
    False
    >>> Y, left, build = undo_new_darts(grid, X, grid.vertices, moved, before)
    >>> bool(np.array_equal(Y, grid.vertices)), float(left.max()), build.buildable
    (True, 0.0, True)
    """
    X, moved = settled.copy(), moved.copy()
    stars = np.asarray(mesh.stars).reshape(-1, 5)
    for _ in range(rounds):
        build = measure_buildable(mesh, X, reference=reference, limits=limits)
        blamed = np.zeros(len(X), bool)
        faces = np.setdiff1d(build.nonconvex_faces, before.nonconvex_faces)
        blamed[mesh.face_indices[np.isin(mesh.corner_faces, faces)]] = True
        turns = np.setdiff1d(build.sharp_turns, before.sharp_turns)
        blamed[stars[np.isin(stars[:, 0], turns)].ravel()] = True
        blamed &= moved > 0
        if not blamed.any():
            return X, moved, build
        X[blamed], moved[blamed] = solved[blamed], 0.0
    return X, moved, measure_buildable(mesh, X, reference=reference, limits=limits)
