"""A multilevel start for large nets: solve a coarse net first, prolong it, finish on the net.

On a regular grid patch (every face a quad, every interior vertex of valence 4, four
corners) the parameter lines give each vertex integer coordinates ``(i, j)``. The coarse
net keeps every second line of both families and the boundary lines; it is solved with
the same net type, settings and reference (itself from its own coarse net while that is
large), and its solution is prolonged to the full net by tensor-product cubic
interpolation along the lines, in the parameters where the lines lie
(``(-1, 9, 9, -1) / 16`` between evenly spaced coarse lines, one-sided cubics next to
the boundary). The full solve then starts from the prolonged net with the coarse solve's
common values (angle, radius), while its objective stays that of the plain solve:
closeness to the user's reference, not to the prolonged net. Its Gauss-Newton
iterations start near a solution, so fewer of them run on the full net (on the
benchmark's 100k-vertex linear Weingarten net 6 instead of 17, `benchmarks/README.md`).

The noise of a start leaves a family of nets near it; the multilevel and the plain solve
pick nets of that family as close to the noise-free one (on the benchmark nets within
2 % of an edge, both) but not the same to the last digit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..net.mesh import QuadMesh

if TYPE_CHECKING:
    from .solver import GuidedProjection

__all__ = [
    "MULTILEVEL_MIN_VERTICES",
    "MIN_COARSE_LINES",
    "MAX_FINE_ROUGHNESS",
    "fine_roughness",
    "grid_indices",
    "coarse_lines",
    "line_parameters",
    "prolongation_matrix",
    "coarse_grid_net",
    "prolong_vertices",
    "start_from_coarse",
]

# nets with at least this many vertices take the multilevel start when it is automatic
MULTILEVEL_MIN_VERTICES = 20_000
# a coarse net needs at least this many lines of each family: the coarser its lines, the
# farther its solution from the full net's (coarsening a 100 x 100 net down to 5 x 5 left
# the solution edges away from the plain solve's)
MIN_COARSE_LINES = 16
# an automatic multilevel start needs a net its coarse net stands for: its vertices off the
# prolonged coarse net by at most this share of the mean edge (RMS). On rougher nets the
# coarse solve settles elsewhere: on a 158 x 158 height-field grid with 3.7 % roughness the
# S-net's angles spread over 68-110 deg against the plain solve's 82-98, and it ended 3x
# farther from the grid; the benchmark's nets with 1 % noise have 1.1 %
MAX_FINE_ROUGHNESS = 0.015


def grid_indices(mesh: QuadMesh) -> np.ndarray | None:
    """The vertex ids of a regular grid patch by their line coordinates, or None.

    Parameters
    ----------
    mesh : the net.

    Returns
    -------
    (m, k) int array ``G`` with ``G[i, j]`` the vertex on line ``i`` of one family and line
    ``j`` of the other, every vertex exactly once, and the faces of the mesh exactly the
    cells ``[G[i, j], G[i + 1, j], G[i + 1, j + 1], G[i, j + 1]]`` in this cyclic order
    (the mesh's orientation). None when the mesh is no such patch: a non-quad face, an
    irregular vertex, a closed line, a hole or more than one patch.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.mesh import QuadMesh
    >>> u, v = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    >>> grid_indices(QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))).shape
    (4, 3)
    """
    if np.any(mesh.face_sizes != 4) or len(mesh.irregular_vertices):
        return None
    corners = np.flatnonzero(mesh.valence == 2)
    lines = mesh.polylines
    if len(corners) != 4 or lines.closed.any():
        return None
    n = mesh.vertex_count
    ends = np.array([[line[0], line[-1]] for line in lines.vertices])
    through = np.flatnonzero((ends == corners[0]).any(axis=1))
    if len(through) != 2 or lines.family[through[0]] == lines.family[through[1]]:
        return None
    first = lines.vertices[through[0]]
    if first[0] != corners[0]:
        first = first[::-1]
    # the lines of the other family, each oriented to start on `first`
    family = lines.family[through[1]]
    ids = np.flatnonzero(lines.family == family)
    starts, stops = np.full(n, -1), np.full(n, -1)
    starts[ends[ids, 0]], stops[ends[ids, 1]] = ids, ids
    rows = []
    for v in first:
        if starts[v] >= 0:
            rows.append(lines.vertices[starts[v]])
        elif stops[v] >= 0:
            rows.append(lines.vertices[stops[v]][::-1])
        else:
            return None
    if len({len(r) for r in rows}) != 1 or len(rows) * len(rows[0]) != n:
        return None
    G = np.array(rows, dtype=np.int64)
    if not np.array_equal(np.sort(G.ravel()), np.arange(n)):
        return None
    orientation = _cell_orientation(mesh, G)
    if orientation == 0:
        return None
    return G if orientation > 0 else G.T.copy()


def _cell_orientation(mesh: QuadMesh, G: np.ndarray) -> int:
    """+1 when the faces of `mesh` are the cells of `G` in its cyclic order, -1 when all
    of them in the reverse order, 0 when they are not the cells of `G`."""
    cells = np.stack([G[:-1, :-1], G[1:, :-1], G[1:, 1:], G[:-1, 1:]], axis=-1).reshape(-1, 4)
    quads = mesh.quads
    if len(cells) != len(quads):
        return 0

    def canonical(q: np.ndarray) -> np.ndarray:
        # rotate every cycle to start at its smallest vertex
        shift = np.argmin(q, axis=1)
        return q[np.arange(len(q))[:, None], (shift[:, None] + np.arange(4)) % 4]

    def rows_sorted(q: np.ndarray) -> np.ndarray:
        return q[np.lexsort(q.T[::-1])]

    faces = rows_sorted(canonical(quads))
    if np.array_equal(faces, rows_sorted(canonical(cells))):
        return 1
    if np.array_equal(faces, rows_sorted(canonical(cells[:, ::-1]))):
        return -1
    return 0


def coarse_lines(m: int) -> np.ndarray:
    """The lines a coarse net keeps of `m` lines: every second one, and the last.

    Examples
    --------
    >>> coarse_lines(7).tolist(), coarse_lines(6).tolist()
    ([0, 2, 4, 6], [0, 2, 4, 5])
    """
    kept = np.arange(0, m, 2)
    return kept if kept[-1] == m - 1 else np.r_[kept, m - 1]


def prolongation_matrix(params: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """(m, c) float: values on `m` lines from values on the `c` lines `kept` of them.

    Parameters
    ----------
    params : (m,) float, increasing parameters of the lines: their indices, or where the
        lines lie (`line_parameters`); on a coarse net those of the full net's lines it
        keeps, which are not evenly spaced where a boundary line was kept one step after
        the line before.
    kept : (c,) int, the indices of the kept lines, increasing, the first and last among
        them.

    A kept line takes its value; a line between two kept ones the cubic through the four
    nearest kept lines (Lagrange weights in the parameter: ``(-1, 9, 9, -1) / 16`` in the
    middle of evenly spaced lines, a one-sided cubic next to the ends), or the interpolant
    of lower degree through all of them when fewer than four are kept.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(9.0)
    >>> P = prolongation_matrix(t, coarse_lines(9))
    >>> (P[3] * 16).tolist()
    [-1.0, 9.0, 9.0, -1.0, 0.0]
    >>> bool(np.allclose(P @ np.arange(0.0, 9.0, 2.0) ** 3, t ** 3))
    True
    """
    params = np.asarray(params, dtype=np.float64)
    kept = np.asarray(kept, dtype=np.int64)
    m, c = len(params), len(kept)
    P = np.zeros((m, c))
    P[kept, np.arange(c)] = 1.0
    t = np.setdiff1d(np.arange(m), kept)
    if t.size == 0:
        return P
    q = min(4, c)
    # the stencil: q kept lines around t, two either side where there are
    start = np.clip(np.searchsorted(kept, t) - q // 2, 0, c - q)
    S = start[:, None] + np.arange(q)                 # (t, q) columns
    x, u = params[kept[S]], params[t]
    W = np.ones((len(t), q))
    for a in range(q):
        for b in range(q):
            if a != b:
                W[:, a] *= (u - x[:, b]) / (x[:, a] - x[:, b])
    P[t[:, None], S] = W
    return P


def line_parameters(vertices: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters of the lines of a grid patch: the mean distance between neighbouring
    lines, summed from the first line.

    Parameters
    ----------
    vertices : (n, 3) float, the net's vertices (model units).
    G : (m, k) int, its vertex ids by line coordinates (`grid_indices`).

    Returns
    -------
    u, v : (m,) and (k,) float, increasing from 0 (model units): the parameters in which
    `prolongation_matrix` interpolates, so that a net whose lines are spaced unevenly
    (here more densely than there) is interpolated where its lines are.

    Examples
    --------
    >>> import numpy as np
    >>> u, v = np.meshgrid([0.0, 1.0, 3.0], [0.0, 2.0], indexing="ij")
    >>> P = np.stack([u, v, 0 * u], axis=-1).reshape(-1, 3)
    >>> [t.tolist() for t in line_parameters(P, np.arange(6).reshape(3, 2))]
    [[0.0, 1.0, 3.0], [0.0, 2.0]]
    """
    P = vertices[G]
    u = np.linalg.norm(np.diff(P, axis=0), axis=2).mean(axis=1)
    v = np.linalg.norm(np.diff(P, axis=1), axis=2).mean(axis=0)
    return np.r_[0.0, np.cumsum(u)], np.r_[0.0, np.cumsum(v)]


def fine_roughness(mesh: QuadMesh, G: np.ndarray) -> float:
    """How much of a grid patch its coarse net does not see: the RMS distance of its
    vertices from the prolonged coarse net of its own vertices, in mean edges.

    Parameters
    ----------
    mesh : the net.
    G : (m, k) int, its vertex ids by line coordinates (`grid_indices`).

    Examples
    --------
    >>> import numpy as np
    >>> u, v = np.meshgrid(np.arange(9.0), np.arange(9.0), indexing="ij")
    >>> smooth = QuadMesh.grid(np.stack([u, v, 0.01 * u * v], axis=-1))
    >>> G = np.arange(81).reshape(9, 9)
    >>> fine_roughness(smooth, G) < 1e-12
    True
    """
    coarse, rows, cols = coarse_grid_net(mesh, G)
    prolonged = prolong_vertices(coarse.vertices, G, rows, cols, line_parameters(mesh.vertices, G))
    off = np.linalg.norm(prolonged - mesh.vertices, axis=1)
    return float(np.sqrt(np.mean(off ** 2)) / mesh.mean_edge_length)


def coarse_grid_net(mesh: QuadMesh, G: np.ndarray) -> tuple[QuadMesh, np.ndarray, np.ndarray]:
    """The coarse net of a grid patch: every second line of both families, the boundary
    lines kept.

    Parameters
    ----------
    mesh : the full net.
    G : (m, k) int, its vertex ids by line coordinates (`grid_indices`).

    Returns
    -------
    coarse : QuadMesh on ``len(rows) * len(cols)`` vertices, oriented as `mesh`: its
        vertex ``a * len(cols) + b`` is ``G[rows[a], cols[b]]``, so that its own grid
        coordinates are ``np.arange(len(rows) * len(cols)).reshape(len(rows), -1)``.
    rows, cols : the kept line indices of the two families.
    """
    rows, cols = coarse_lines(G.shape[0]), coarse_lines(G.shape[1])
    points = mesh.vertices[G[np.ix_(rows, cols)]]
    return QuadMesh.grid(points, name=f"{mesh.name} (coarse)"), rows, cols


def prolong_vertices(coarse_vertices: np.ndarray, G: np.ndarray, rows: np.ndarray,
                     cols: np.ndarray, params: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> np.ndarray:
    """Vertex positions of a net from those of its coarse net.

    Parameters
    ----------
    coarse_vertices : (len(rows) * len(cols), 3) float, the coarse net's vertices in the
        order of `coarse_grid_net` (model units).
    G : (m, k) int, the net's vertex ids by line coordinates.
    rows, cols : the kept line indices of the two families.
    params : the (m,) and (k,) parameters of the net's lines (see `prolongation_matrix`
        and `line_parameters`); default their indices.

    Returns
    -------
    (m * k, 3) float, the net's vertices by vertex id: the tensor product of the cubic
    interpolation along both families (`prolongation_matrix`); kept vertices keep their
    coarse positions exactly.
    """
    m, k = G.shape
    u, v = params if params is not None else (np.arange(m, dtype=np.float64),
                                               np.arange(k, dtype=np.float64))
    C = coarse_vertices.reshape(len(rows), len(cols), 3)
    fine = np.einsum("ia,abx,jb->ijx", prolongation_matrix(u, rows), C,
                     prolongation_matrix(v, cols), optimize=True)
    out = np.empty((m * k, 3))
    out[G.ravel()] = fine.reshape(-1, 3)
    return out


# common values (one per net) carried from a coarse solve to the full one, and the power
# of the length scale they carry (normalized curvature: times length, radius: divided)
COMMON_BLOCKS = {"cosine": 0, "ruling-cosine": 0, "curvature": 1, "mannheim-common": -1}


def start_from_coarse(solver: GuidedProjection, coarse: GuidedProjection,
                      vertices: np.ndarray) -> None:
    """Start `solver` (not yet run) at `vertices` with the common values of `coarse`.

    Parameters
    ----------
    solver : the full net's solver, built on the user's start (its normalization, its
        reference and soft terms stay those of the plain solve).
    coarse : the coarse net's solver after its run.
    vertices : (n, 3) float, the prolonged coarse solution (model units).

    Every family initializes its own variables again at the new vertices (sphere fits,
    slack variables); the common angle and radius are taken from the coarse solve,
    converted from its normalized units to the full net's. The soft terms (fairness,
    closeness to the reference) go on fading from where the coarse solve left them, as
    in one solve whose first steps ran on the coarse net: the coarse steps did what
    their full weights are for (pull the shape to the reference), and full weights again
    would pull the net along the solutions, away from the prolonged start, for as many
    steps as the plain solve takes.
    """
    state = solver.state
    state.X[:] = (vertices - solver.origin) / solver.length_scale
    for family in solver.constraints:
        family.initialize(state)
    solver.restart_soft_terms(faded=coarse.soft_steps)
    ratio = solver.length_scale / coarse.length_scale
    for name, power in COMMON_BLOCKS.items():
        if name in state.blocks and name in coarse.state.blocks:
            state.blocks.view(state.x, name)[:] = coarse.variable(name) * ratio ** power
