"""Folds and degeneracies of a net: what a sphere residual does not show.

A star can meet its sphere exactly while its quads have turned over, and four points of a
collapsed star lie on a sphere trivially. "Converged" therefore needs more than small
residuals. This module measures, on every result:

- *flipped faces*: faces whose normal opposes the reference surface's normal at their
  centre (with a reference), or the normals of most of their neighbours (without one);
- *fold edges*: interior edges across which the two faces turn by more than
  `FoldLimits.fold_angle_deg`;
- *degenerate stars*: vertex stars whose families meet at less than
  `FoldLimits.min_star_angle_deg` (or more than 180 minus it): the lines run together;
- *collapsed edges*: edges shorter than `FoldLimits.min_edge_fraction` of the mean edge.

A net is *folded* when it has a flipped face or a fold edge.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .geometry import canonical_stars, face_normals, intersection_angles

if TYPE_CHECKING:
    from .mesh import QuadMesh

__all__ = ["FoldLimits", "FoldReport", "SurfaceWithNormals", "measure_folds", "fold_edge_mask",
           "flipped_against"]


class SurfaceWithNormals(Protocol):
    """A reference surface: closest points with the surface normal there (for example
    `fabplan.solve.reference.ReferenceSurface`)."""

    def closest_points(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def distances(self, points: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class FoldLimits:
    """Where a face, star or edge counts as folded or degenerate.

    Attributes
    ----------
    fold_angle_deg : an interior edge whose two faces turn by more than this folds.
    min_star_angle_deg : stars whose families meet at less than this (or more than 180
        minus it) are degenerate.
    min_edge_fraction : edges shorter than this fraction of the mean edge are collapsed.
    """

    fold_angle_deg: float = 90.0
    min_star_angle_deg: float = 10.0
    min_edge_fraction: float = 0.1


@dataclass
class FoldReport:
    """Folds and degeneracies found on a net (element ids from 0, as in the OBJ order).

    Attributes
    ----------
    flipped_faces : (a,) int, face ids.
    fold_edges : (b, 2) int, vertex ids of the interior edges that fold.
    degenerate_stars : (c,) int, vertex ids of the degenerate stars.
    collapsed_edges : (d, 2) int, vertex ids of the collapsed edges.
    centroid : (3,) float, the mean position of the flipped faces (None without any).
    against_reference : whether faces were judged against a reference surface's normals.
    limits : the `FoldLimits` used.
    """

    flipped_faces: np.ndarray
    fold_edges: np.ndarray
    degenerate_stars: np.ndarray
    collapsed_edges: np.ndarray
    centroid: np.ndarray | None = None
    against_reference: bool = False
    limits: FoldLimits = field(default_factory=FoldLimits)

    @property
    def folded(self) -> bool:
        return bool(self.flipped_faces.size or self.fold_edges.size)

    @property
    def degenerate(self) -> bool:
        return bool(self.degenerate_stars.size or self.collapsed_edges.size)

    def record(self, *, listed: int = 200) -> dict:
        """JSON-ready counts and (up to `listed`) element ids."""
        def part(ids, **extra):
            ids = np.asarray(ids)
            return {"count": int(len(ids)), "ids": ids[:listed].tolist(), **extra}

        return {
            "folded": self.folded,
            "flipped_faces": part(self.flipped_faces, against=("the reference surface's normals"
                                                                if self.against_reference else
                                                                "the neighbouring faces' normals")),
            "fold_edges": part(self.fold_edges, turn_above_deg=self.limits.fold_angle_deg),
            "degenerate_stars": part(self.degenerate_stars,
                                     angle_below_deg=self.limits.min_star_angle_deg),
            "collapsed_edges": part(self.collapsed_edges,
                                    shorter_than_mean_edge=self.limits.min_edge_fraction),
            "flipped_centroid": None if self.centroid is None else self.centroid.tolist(),
        }

    def describe(self) -> str:
        """One clause naming what folds and where, or an empty string."""
        parts = []
        if self.flipped_faces.size:
            ids = ", ".join(str(int(i)) for i in self.flipped_faces[:5])
            more = ", ..." if self.flipped_faces.size > 5 else ""
            where = "" if self.centroid is None else \
                " around ({:.4g}, {:.4g}, {:.4g})".format(*self.centroid)
            parts.append(f"{self.flipped_faces.size} faces are flipped (faces {ids}{more}){where}")
        if self.fold_edges.size and not self.flipped_faces.size:
            parts.append(f"{len(self.fold_edges)} edges fold (first between vertices "
                         f"{self.fold_edges[0, 0]} and {self.fold_edges[0, 1]})")
        if self.degenerate_stars.size:
            parts.append(f"{self.degenerate_stars.size} stars have their lines within "
                         f"{self.limits.min_star_angle_deg:g} deg of each other (vertex "
                         f"{self.degenerate_stars[0]}, ...)")
        if self.collapsed_edges.size:
            parts.append(f"{len(self.collapsed_edges)} edges are shorter than "
                         f"{self.limits.min_edge_fraction:g} of the mean edge")
        return "; ".join(parts)


def fold_edge_mask(normals: np.ndarray, edge_faces: np.ndarray, fold_angle_deg: float = 90.0
                   ) -> np.ndarray:
    """(i,) bool, interior edges whose faces (unit `normals` (f, 3)) turn by more than the
    angle; `edge_faces` (i, 2) int from `QuadMesh.interior_edge_faces`."""
    cosine = np.sum(normals[edge_faces[:, 0]] * normals[edge_faces[:, 1]], axis=1)
    return cosine < np.cos(np.radians(fold_angle_deg))


def flipped_against(normals: np.ndarray, reference_normals: np.ndarray, areas: np.ndarray
                    ) -> np.ndarray:
    """(f,) bool, faces whose normal opposes the reference normal at their centre.

    The reference's orientation is a convention: it is turned to agree with most of the
    net's area first, so a reference oriented the other way flags nothing by itself.
    """
    agree = np.sum(normals * reference_normals, axis=1)
    if np.sum(areas * np.sign(agree)) < 0:
        agree = -agree
    return agree < 0


def _flipped_among_neighbours(normals: np.ndarray, edge_faces: np.ndarray) -> np.ndarray:
    """Faces whose normal opposes the normals of more than half of their neighbours."""
    f = len(normals)
    opposing = np.sum(normals[edge_faces[:, 0]] * normals[edge_faces[:, 1]], axis=1) < 0
    against = np.bincount(edge_faces[opposing].ravel(), minlength=f)
    total = np.bincount(edge_faces.ravel(), minlength=f)
    return 2 * against > total


def measure_folds(mesh: QuadMesh, X: np.ndarray | None = None, *,
                  reference: SurfaceWithNormals | None = None,
                  limits: FoldLimits | None = None) -> FoldReport:
    """Find flipped faces, fold edges, degenerate stars and collapsed edges.

    Parameters
    ----------
    mesh : `fabplan.net.mesh.QuadMesh`.
    X : (n, 3) float, vertex positions (default: the mesh's).
    reference : optional reference surface with ``closest_points`` (for example
        `fabplan.solve.reference.ReferenceSurface`): faces are judged against its normals.
    limits : `FoldLimits`.

    Returns
    -------
    FoldReport

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.generate import height_field_grid
    >>> grid = height_field_grid(4, 4, lambda x, y: 0 * x)
    >>> measure_folds(grid).folded
    False
    >>> X = grid.vertices.copy()
    >>> X[5, 2], X[6, 2] = 3.0, -3.0        # two inner vertices pulled through the plane
    >>> report = measure_folds(grid, X)
    >>> report.folded, report.fold_edges.shape[1]
    (True, 2)
    """
    limits = limits or FoldLimits()
    X = mesh.vertices if X is None else np.asarray(X, dtype=np.float64)
    normals = face_normals(X, mesh)
    edge_faces = mesh.interior_edge_faces
    fold = fold_edge_mask(normals, edge_faces, limits.fold_angle_deg)
    sizes = mesh.face_sizes
    face = np.repeat(np.arange(len(sizes)), sizes)
    centres = np.zeros((len(sizes), 3))
    np.add.at(centres, face, X[mesh.face_indices])
    centres /= sizes[:, None]
    if reference is not None:
        _, ref_normals, _ = reference.closest_points(centres)
        flipped = flipped_against(normals, ref_normals, np.ones(len(sizes)))
    else:
        flipped = _flipped_among_neighbours(normals, edge_faces)
    flipped_ids = np.flatnonzero(flipped)
    stars = canonical_stars(X, mesh.stars)
    degenerate = np.zeros(0, np.int64)
    if len(stars):
        angle = np.degrees(intersection_angles(X, stars))
        low = limits.min_star_angle_deg
        degenerate = stars[(angle < low) | (angle > 180.0 - low) | ~np.isfinite(angle), 0]
    E = mesh.edges
    length = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)
    collapsed = E[length < limits.min_edge_fraction * max(float(length.mean()), 1e-300)]
    return FoldReport(
        flipped_faces=flipped_ids,
        fold_edges=mesh.interior_edges[fold],
        degenerate_stars=np.sort(degenerate),
        collapsed_edges=collapsed,
        centroid=centres[flipped_ids].mean(axis=0) if flipped_ids.size else None,
        against_reference=reference is not None,
        limits=limits,
    )
