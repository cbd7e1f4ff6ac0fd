"""The region of a net that a local edit moves, as a net of its own.

A drag moves the vertices near its handles and holds the rest. Solving the whole net with
the rest held still evaluates every family on every vertex and factors every star's sphere
variables; solving only the faces that reach the moving vertices gives the same solution
(every constraint that involves a moving vertex is in it) at the cost of the region.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from ..net.mesh import QuadMesh

__all__ = ["RegionNet", "region_net"]

#: rings of held vertices around the moving ones: the first completes the stars at the
#: moving vertices' neighbours, the second adds stars that are wholly held, which pin
#: the common angle or radius of the net type to the value the rest of the net has
RING_DEPTH = 2


@dataclass
class RegionNet:
    """A part of a net: the faces that reach its moving vertices, and rings around them.

    Attributes
    ----------
    mesh : the part as a net (vertices renumbered from 0, faces in the net's order).
    vertices : (k,) int, the net's vertex id of each vertex of `mesh`.
    held : (h,) int, vertices of `mesh` (its numbering) that do not move.
    """

    mesh: QuadMesh
    vertices: np.ndarray
    held: np.ndarray

    def local(self, ids: npt.ArrayLike) -> np.ndarray:
        """(m,) int, the part's numbering of net vertex `ids` (all in the part)."""
        return np.searchsorted(self.vertices, np.asarray(ids, dtype=np.int64))


def region_net(mesh: QuadMesh, vertices: np.ndarray, moving: np.ndarray) -> RegionNet:
    """The part of `mesh` that moving vertices reach.

    Parameters
    ----------
    mesh : the net (its combinatorics); vertices : (n, 3) float, its current positions.
    moving : (n,) bool, the vertices that may move.

    Returns
    -------
    RegionNet: every face with a vertex within `RING_DEPTH` edges of a moving vertex
    (so every star and fairness stencil around a moving vertex is whole), the vertices that
    do not move held.

    Examples
    --------
    >>> u, v = np.meshgrid(np.arange(9.0), np.arange(9.0), indexing="ij")
    >>> grid = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))
    >>> moving = np.zeros(81, bool); moving[40] = True           # the middle vertex
    >>> part = region_net(grid, grid.vertices, moving)
    >>> len(part.mesh.faces), part.mesh.vertex_count, len(part.held)
    (24, 37, 36)
    """
    n = mesh.vertex_count
    edges = mesh.edges
    adjacency = sp.coo_matrix((np.ones(2 * len(edges), bool),
                               (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                              shape=(n, n)).tocsr()
    reach = np.asarray(moving, bool).copy()
    for _ in range(RING_DEPTH):
        reach |= adjacency @ reach
    face_reached = np.bincount(mesh.corner_faces, reach[mesh.face_indices],
                               minlength=len(mesh.face_sizes)) > 0
    corners = face_reached[mesh.corner_faces]
    ids = np.unique(mesh.face_indices[corners])
    renumber = np.full(n, -1, np.int64)
    renumber[ids] = np.arange(len(ids))
    sizes = mesh.face_sizes[face_reached]
    faces = np.split(renumber[mesh.face_indices[corners]], np.cumsum(sizes)[:-1])
    part = QuadMesh(vertices[ids], faces, name=mesh.name)
    return RegionNet(part, ids, np.flatnonzero(~np.asarray(moving, bool)[ids]))
