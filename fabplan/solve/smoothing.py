"""A smoothed start: the net's vertices with the noise of its lines taken out.

A start far from every net of a type (strong noise on a surface) can make the solver meet
its constraints on a folded net: the nearest solution it reaches keeps the kinks of the
noise. Solving the same conditions from a smoothed copy, with the closeness still pulling
towards the original, reaches a fold-free net where the plain solve folds (see
`fabplan.solve.optimize`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..net.geometry import canonical_stars
from ..net.mesh import QuadMesh
from .constraints.fairness import fairness_stencils
from .linalg import solve_spd_columns

__all__ = ["smoothed_vertices", "SMOOTHING_WEIGHT"]

# weight of the second differences against the pull to the start (both dimensionless):
# at 1 the noise of an edge's length is damped about tenfold on a 25 x 25 grid, while
# the shape over a few edges stays
SMOOTHING_WEIGHT = 1.0


def smoothed_vertices(mesh: QuadMesh, *, weight: float = SMOOTHING_WEIGHT,
                      held: np.ndarray | None = None) -> np.ndarray:
    """Vertices minimizing ``|X - X0|^2 + weight |F X|^2``, with ``F`` the fairness
    stencils (second differences along both families and the boundary, the umbrella at
    irregular vertices, `fabplan.solve.constraints.fairness_stencils`).

    Parameters
    ----------
    mesh : the net; its vertices are ``X0``.
    weight : how strongly the second differences are damped (dimensionless: the same on
        every scale).
    held : (k,) int, vertices that keep their positions.

    Returns
    -------
    (n, 3) float, the smoothed vertices (model units; held ones exactly as given).

    Examples
    --------
    >>> from fabplan.net.generate import height_field_grid
    >>> flat = height_field_grid(4, 4, lambda x, y: 0 * x)
    >>> bump = np.zeros((flat.vertex_count, 3))
    >>> bump[5, 2] = 1.0
    >>> Z = smoothed_vertices(flat.with_vertices(flat.vertices + bump))[:, 2]
    >>> bool(0 < Z[5] < 1 and abs(Z.sum() - 1) < 1e-9)   # spread out, its volume kept
    True
    >>> bool(smoothed_vertices(flat.with_vertices(flat.vertices + bump), held=[5])[5, 2] == 1.0)
    True
    """
    X0 = mesh.vertices
    stencils, coefficients = fairness_stencils(mesh, canonical_stars(X0, mesh.stars))
    rows = np.repeat(np.arange(len(stencils)), stencils.shape[1])
    F = sp.csr_matrix((coefficients.ravel(), (rows, stencils.ravel())),
                      shape=(len(stencils), mesh.vertex_count))
    system = (sp.identity(mesh.vertex_count, format="csr") + weight * (F.T @ F)).tocsr()
    held = np.unique(np.asarray([] if held is None else held, dtype=np.int64))
    free = np.setdiff1d(np.arange(mesh.vertex_count), held)
    X = X0.copy()
    if free.size:
        # the held vertices move to the right-hand side
        rhs = X0[free] - system[free][:, held] @ X0[held]
        X[free] = solve_spd_columns(system[free][:, free], rhs)
    return X
