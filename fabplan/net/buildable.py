"""Whether a net can be built: what its residuals and folds do not show.

A net can meet every sphere condition, have no flipped face and no fold edge, and still
be a net no one could build: a quad with one corner bent inwards (a *dart*), a face that
crosses itself, a line that doubles back on itself at a vertex, edges that jump in length
from one panel to the next. This module measures them on every result:

- *non-convex faces*: faces whose turns, in their least-squares plane, do not all have
  one sign;
- *self-crossing faces*: faces whose turns add up to less than half a turn (a bow-tie
  quad turns by +180 and -180 degrees and ends where it began);
- *sharp line turns*: regular stars where a line turns in the surface by more than
  `BuildLimits.max_line_turn_deg` (`fabplan.net.fairness.line_turns`; over 90 degrees
  the line doubles back);
- *edge jumps*: regular stars where two consecutive edges of a line differ in length by
  more than the factor `BuildLimits.max_edge_ratio` (measured, not a condition);
- *far vertices*: with a reference surface and `BuildLimits.max_deviation`, vertices
  farther from it than that.

A net is *buildable* when it has no fold (`fabplan.net.folds`), no non-convex face, no
sharp line turn and no far vertex.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .fairness import line_turns
from .folds import FoldReport, SurfaceWithNormals, measure_folds
from .geometry import canonical_stars, face_normals

if TYPE_CHECKING:
    from .mesh import QuadMesh

__all__ = ["BuildLimits", "BuildReport", "measure_buildable", "corner_turns", "best_plane_normals",
           "crumpled"]


@dataclass(frozen=True)
class BuildLimits:
    """What a buildable net keeps to.

    Attributes
    ----------
    max_line_turn_deg : a line may turn in the surface by at most this at a vertex.
    max_edge_ratio : consecutive edges of a line longer than this factor of each other
        count as an edge jump (reported, not part of buildable).
    max_deviation : largest distance of a vertex from the reference surface (model
        units); None: no limit.
    deviation_vertices : (k,) int, the vertices the limit holds at; None: all. A net
        continued past its design's edge (`fabplan.layout.margin`) is held where it will
        be built: not at its tips (in no star) nor its rows beyond the edge.
    """

    max_line_turn_deg: float = 90.0
    max_edge_ratio: float = 3.0
    max_deviation: float | None = None
    deviation_vertices: np.ndarray | None = None


def best_plane_normals(X: np.ndarray, mesh: QuadMesh) -> np.ndarray:
    """(f, 3) unit normals of every face's least-squares plane (through its corners'
    mean), turned to agree with its vector area (`fabplan.net.geometry.face_normals`).

    The normal is the eigenvector of the smallest eigenvalue of the corners' scatter
    matrix, found in closed form for all faces at once (the solver asks for it on every
    iterate it may keep: a LAPACK call per 3 x 3 matrix would cost more than the rest).
    """
    sizes, ptr = mesh.face_sizes, mesh.face_indptr[:-1]
    if len(sizes) and sizes.min() == sizes.max() == 4:
        # quads only (most nets): corners in a (q, 4, 3) block, the vector area from the
        # diagonals
        P = X[mesh.face_indices].reshape(-1, 4, 3)
        D = P - P.mean(axis=1, keepdims=True)
        x, y, z = D[..., 0], D[..., 1], D[..., 2]
        sxx, syy, szz = np.einsum("qk,qk->q", x, x), np.einsum("qk,qk->q", y, y), \
            np.einsum("qk,qk->q", z, z)
        sxy, sxz, syz = np.einsum("qk,qk->q", x, y), np.einsum("qk,qk->q", x, z), \
            np.einsum("qk,qk->q", y, z)
        area = np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 1])
    else:
        P = X[mesh.face_indices]
        centres = np.add.reduceat(P, ptr, axis=0) / sizes[:, None]
        D = P - np.repeat(centres, sizes, axis=0)
        x, y, z = D.T
        # the scatter matrix's six entries, summed over each face's corners
        sxx, syy, szz, sxy, sxz, syz = np.add.reduceat(
            np.stack([x * x, y * y, z * z, x * y, x * z, y * z], axis=1), ptr, axis=0).T
        area = face_normals(X, mesh)
    # its smallest eigenvalue (trigonometric form for symmetric 3 x 3 matrices)
    q = (sxx + syy + szz) / 3
    off = sxy * sxy + sxz * sxz + syz * syz
    a, b, c = sxx - q, syy - q, szz - q
    spread = np.sqrt(np.maximum((a * a + b * b + c * c + 2 * off) / 6, 1e-300))
    det = (a * (b * c - syz * syz) - sxy * (sxy * c - syz * sxz)
           + sxz * (sxy * syz - b * sxz)) / spread**3
    smallest = q + 2 * spread * np.cos(np.arccos(np.clip(det / 2, -1.0, 1.0)) / 3 + 2 * np.pi / 3)
    a, b, c = sxx - smallest, syy - smallest, szz - smallest
    # the eigenvector is normal to the rows of S - smallest I: the longest cross product
    # of two of its rows (r0 = a sxy sxz, r1 = sxy b syz, r2 = sxz syz c)
    crosses = np.stack([
        np.stack([sxy * syz - sxz * b, sxz * sxy - a * syz, a * b - sxy * sxy], axis=1),
        np.stack([sxy * c - sxz * syz, sxz * sxz - a * c, a * syz - sxy * sxz], axis=1),
        np.stack([b * c - syz * syz, syz * sxz - sxy * c, sxy * syz - b * sxz], axis=1)])
    length = np.sqrt(np.einsum("kfi,kfi->kf", crosses, crosses))
    pick = np.argmax(length, axis=0)
    rows = np.arange(len(sizes))
    best = length[pick, rows]
    normal = crosses[pick, rows] / np.maximum(best, 1e-300)[:, None]
    # a face whose corners lie on a line (no plane) keeps its vector area's direction
    normal = np.where((best > 1e-12 * np.maximum(q, 1e-300) ** 2)[:, None], normal, area)
    return normal * np.where(np.einsum("fi,fi->f", normal, area) < 0, -1.0, 1.0)[:, None]


def corner_turns(X: np.ndarray, mesh: QuadMesh) -> np.ndarray:
    """(c,) float, radians, aligned with ``mesh.face_indices``: the signed turn of each
    face's boundary at each corner, in the face's least-squares plane
    (`best_plane_normals`; positive: turning the way the face's corners run).

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.mesh import QuadMesh
    >>> dart = QuadMesh([[0, 0, 0], [2, 0, 0], [0.5, 0.5, 0], [0, 2, 0]], [[0, 1, 2, 3]])
    >>> np.degrees(corner_turns(dart.vertices, dart)).round(1).tolist()
    [90.0, 161.6, -53.1, 161.6]
    """
    normals = best_plane_normals(X, mesh)[mesh.corner_faces]
    vert = mesh.face_indices
    here = X[vert]
    incoming = here - X[mesh.corner_previous_vertices]
    outgoing = X[mesh.corner_next_vertices] - here
    (ix, iy, iz), (ox, oy, oz) = incoming.T, outgoing.T
    nx, ny, nz = normals.T
    sine = (iy * oz - iz * oy) * nx + (iz * ox - ix * oz) * ny + (ix * oy - iy * ox) * nz
    cosine = ix * ox + iy * oy + iz * oz
    return np.arctan2(sine, cosine)


def crumpled(mesh: QuadMesh, X: np.ndarray, stars: np.ndarray, max_line_turn_deg: float = 90.0,
             *, turns: np.ndarray | None = None, normals: np.ndarray | None = None) -> bool:
    """Whether a net has a non-convex face or a line turning more than the limit at one of
    its canonical `stars` (s, 5): the test `measure_buildable` counts, in one answer (the
    solver asks it of every iterate it may keep). `turns`: the (s, 2) line turns
    (radians, `fabplan.net.fairness.line_turns`) when they were found already.
    `normals`: (f, 3) face normals to judge the corners' turns by instead of the
    least-squares planes' (the solver passes the vector-area normals it has: for a quad
    the plane parallel to both diagonals, which differs from the least-squares plane only
    on strongly twisted quads)."""
    if normals is None:
        sine = corner_turns(X, mesh)
    else:
        here = X[mesh.face_indices]
        sine = np.einsum("ij,ij->i", np.cross(here - X[mesh.corner_previous_vertices],
                                              X[mesh.corner_next_vertices] - here),
                         normals[mesh.corner_faces])
    face = mesh.corner_faces
    tiny = 1e-9 * (float(np.abs(sine).max(initial=0.0)) if normals is not None else 1.0)
    if np.any((np.bincount(face, sine < -tiny, minlength=len(mesh.face_sizes)) > 0)
              & (np.bincount(face, sine > tiny, minlength=len(mesh.face_sizes)) > 0)):
        return True
    if len(stars) == 0:
        return False
    if turns is None:
        turns, _ = line_turns(X, stars)
    return bool(np.any(turns > np.radians(max_line_turn_deg)))


@dataclass
class BuildReport:
    """What keeps a net from being built (element ids from 0, as in the OBJ order).

    Attributes
    ----------
    folds : the `FoldReport` of the net.
    nonconvex_faces : (a,) int, face ids, the worst (deepest reflex corner) first.
    reflex_deg : (a,) float, how far the reflex corner of each turns the wrong way.
    self_crossing_faces : (b,) int, face ids.
    sharp_turns : (c,) int, vertex ids of the stars where a line turns too much, the
        sharpest first; ``turn_deg`` (c,) float their turns.
    edge_jumps : (d,) int, vertex ids of stars with an edge jump, the largest first;
        ``edge_ratio`` (d,) float their ratios.
    far_vertices : (e,) int, vertex ids farther than the limit, the farthest first;
        ``deviation`` (e,) float their distances.
    points : vertex positions, to name where each worst place is.
    limits : the `BuildLimits` used.
    """

    folds: FoldReport
    nonconvex_faces: np.ndarray
    reflex_deg: np.ndarray
    self_crossing_faces: np.ndarray
    sharp_turns: np.ndarray
    turn_deg: np.ndarray
    edge_jumps: np.ndarray
    edge_ratio: np.ndarray
    far_vertices: np.ndarray
    deviation: np.ndarray
    face_centres: np.ndarray
    points: np.ndarray
    limits: BuildLimits = field(default_factory=BuildLimits)

    @property
    def crumpled(self) -> bool:
        """A non-convex face or a sharp line turn."""
        return bool(self.nonconvex_faces.size or self.sharp_turns.size)

    @property
    def off_design(self) -> bool:
        """A vertex farther from the reference than the limit."""
        return bool(self.far_vertices.size)

    @property
    def buildable(self) -> bool:
        """No fold, no degenerate star or collapsed edge, not crumpled, not off the design:
        what a converged net is."""
        return not (self.folds.folded or self.folds.degenerate or self.crumpled
                    or self.off_design)

    def record(self, *, listed: int = 200) -> dict:
        """JSON-ready counts, (up to `listed`) element ids and the worst place of each."""
        def part(ids, values, key, where, **extra):
            ids = np.asarray(ids)
            worst = None
            if ids.size:
                worst = {key: float(values[0]), "id": int(ids[0]),
                         "point": where[ids[0]].tolist()}
            return {"count": int(ids.size), "ids": ids[:listed].tolist(), "worst": worst, **extra}

        limits = self.limits
        return {
            "buildable": self.buildable,
            "crumpled": self.crumpled,
            "nonconvex_faces": part(self.nonconvex_faces, self.reflex_deg, "reflex_turn_deg",
                                    self.face_centres),
            "self_crossing_faces": {"count": int(self.self_crossing_faces.size),
                                    "ids": self.self_crossing_faces[:listed].tolist()},
            "sharp_line_turns": part(self.sharp_turns, self.turn_deg, "turn_deg", self.points,
                                     turn_above_deg=limits.max_line_turn_deg),
            "edge_jumps": part(self.edge_jumps, self.edge_ratio, "edge_ratio", self.points,
                               ratio_above=limits.max_edge_ratio),
            "far_vertices": part(self.far_vertices, self.deviation, "distance", self.points,
                                 farther_than=limits.max_deviation),
        }

    def describe(self) -> str:
        """One clause naming what keeps the net from being built, where the worst of each
        is and how many places there are; an empty string for a buildable net."""
        parts = []
        if self.folds.folded:
            parts.append(self.folds.describe())
        if self.nonconvex_faces.size:
            f = int(self.nonconvex_faces[0])
            n = self.nonconvex_faces.size
            crossing = (f" ({self.self_crossing_faces.size} of them crossing themselves)"
                        if self.self_crossing_faces.size else "")
            parts.append(f"{n} face{'s are' if n > 1 else ' is'} non-convex{crossing}, the worst "
                         f"face {f} at {_point(self.face_centres[f])} with a corner turned "
                         f"{self.reflex_deg[0]:.0f} deg the wrong way")
        if self.sharp_turns.size:
            v, n = int(self.sharp_turns[0]), self.sharp_turns.size
            parts.append(f"lines turn by more than {self.limits.max_line_turn_deg:g} deg at {n} "
                         f"{'vertices' if n > 1 else 'vertex'}, the worst {self.turn_deg[0]:.0f} deg at "
                         f"vertex {v} {_point(self.points[v])}")
        if self.far_vertices.size:
            v, n = int(self.far_vertices[0]), self.far_vertices.size
            parts.append(f"{n} {'vertices are' if n > 1 else 'vertex is'} farther than "
                         f"{self.limits.max_deviation:.4g} (model units) from the reference, the farthest "
                         f"vertex {v} {_point(self.points[v])} at {self.deviation[0]:.4g}")
        return "; ".join(parts)


def _point(p: np.ndarray) -> str:
    return "({:.4g}, {:.4g}, {:.4g})".format(*p)


def _sorted_desc(ids: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(-values, kind="stable")
    return ids[order], values[order]


def measure_buildable(mesh: QuadMesh, X: np.ndarray | None = None, *,
                      reference: SurfaceWithNormals | None = None,
                      limits: BuildLimits | None = None,
                      folds: FoldReport | None = None) -> BuildReport:
    """Find what keeps a net from being built.

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    X : (n, 3) float, vertex positions (default: the mesh's).
    reference : optional reference surface: folds are judged against it, and with
        ``limits.max_deviation`` the vertices farther from it are counted.
    limits : `BuildLimits`.
    folds : the net's `FoldReport` when it was measured already.

    Returns
    -------
    BuildReport

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import height_field_grid
    >>> grid = height_field_grid(5, 5, lambda x, y: 0.05 * x * y)
    >>> measure_buildable(grid).buildable
    True
    >>> X = grid.vertices.copy()
    >>> X[12, :2] = X[6, :2] + 0.1           # the middle vertex pushed past its neighbour
    >>> report = measure_buildable(grid, X)
    >>> report.buildable, report.nonconvex_faces.size > 0, report.sharp_turns.tolist()
    (False, True, [12])
    """
    limits = limits or BuildLimits()
    X = mesh.vertices if X is None else np.asarray(X, dtype=np.float64)
    if folds is None:
        folds = measure_folds(mesh, X, reference=reference)
    sizes = mesh.face_sizes
    turns = corner_turns(X, mesh)
    face = mesh.corner_faces
    tiny = 1e-9
    wrong = np.bincount(face, turns < -tiny, minlength=len(sizes)) > 0
    right = np.bincount(face, turns > tiny, minlength=len(sizes)) > 0
    nonconvex = np.flatnonzero(wrong & right)
    reflex = np.zeros(len(sizes))
    np.minimum.at(reflex, face, turns)
    total = np.bincount(face, turns, minlength=len(sizes))
    crossing = np.flatnonzero(np.abs(total) < np.pi)
    nonconvex_ids, reflex_deg = _sorted_desc(nonconvex, -np.degrees(reflex[nonconvex]))
    centres = np.zeros((len(sizes), 3))
    np.add.at(centres, face, X[mesh.face_indices])
    centres /= np.maximum(sizes, 1)[:, None]
    stars = canonical_stars(X, mesh.stars)
    if len(stars):
        turn, ratio = line_turns(X, stars)
        turn_deg, ratio_max = np.degrees(turn).max(axis=1), ratio.max(axis=1)
    else:
        turn_deg, ratio_max = np.zeros(0), np.zeros(0)
    sharp = turn_deg > limits.max_line_turn_deg
    sharp_ids, sharp_deg = _sorted_desc(stars[sharp, 0] if len(stars) else np.zeros(0, np.int64),
                                        turn_deg[sharp])
    jump = ratio_max > limits.max_edge_ratio
    jump_ids, jump_ratio = _sorted_desc(stars[jump, 0] if len(stars) else np.zeros(0, np.int64),
                                        ratio_max[jump])
    far_ids, far = np.zeros(0, np.int64), np.zeros(0)
    if reference is not None and limits.max_deviation is not None:
        d = reference.distances(X)
        if limits.deviation_vertices is not None:
            d[np.setdiff1d(np.arange(len(d)), limits.deviation_vertices)] = 0.0
        outside = np.flatnonzero(d > limits.max_deviation)
        far_ids, far = _sorted_desc(outside, d[outside])
    return BuildReport(folds=folds, nonconvex_faces=nonconvex_ids, reflex_deg=reflex_deg,
                       self_crossing_faces=crossing, sharp_turns=sharp_ids, turn_deg=sharp_deg,
                       edge_jumps=jump_ids, edge_ratio=jump_ratio, far_vertices=far_ids,
                       deviation=far, face_centres=centres, points=X, limits=limits)
