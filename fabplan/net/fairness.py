"""Fairness of a net's lines: how they turn in the surface, how their edges grow, how the
two families meet.

A net can be an exact S-net and still be a net no facade designer would build: lines that
wander and kink where the principal directions turn, edges that jump in length from one
panel to the next, families that meet at 25 deg. Measured at every regular star
``[v, v1, v2, v3, v4]`` (family 0 runs v1 -> v -> v3, family 1 v2 -> v -> v4):

- *line turn*: the angle between the edges ``v - v1`` and ``v3 - v`` (and of the other
  family) projected onto the star's tangent plane: the geodesic kink of the line at v,
  free of the bending that follows the surface;
- *edge ratio*: the longer of two consecutive edges of a line over the shorter;
- the intersection angle of the two families (`fabplan.net.geometry.intersection_angles`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .geometry import canonical_stars, intersection_angles

if TYPE_CHECKING:
    from .mesh import QuadMesh

__all__ = ["line_turns", "fairness_record"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def line_turns(X: np.ndarray, stars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic turn (radians) and edge ratio of both families' lines at every star.

    Parameters
    ----------
    X : (n, 3) float; stars : (s, 5) int, canonical stars.

    Returns
    -------
    turn : (s, 2) float, radians, family 0 then 1.
    ratio : (s, 2) float, >= 1.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[0, 0, 0], [-1, 0, 0], [0, -1, 0], [1, 0.1, 0], [0, 1, 0.0]])
    >>> turn, ratio = line_turns(X, np.array([[0, 1, 2, 3, 4]]))
    >>> np.degrees(turn).round(3).tolist(), ratio.round(4).tolist()
    ([[5.711, 0.0]], [[1.005, 1.0]])
    """
    P = X[stars]                                        # (s, 5, 3)
    normal = _unit(np.cross(P[:, 3] - P[:, 1], P[:, 4] - P[:, 2]))
    E = P[:, 1:] - P[:, :1]                             # v -> v1, v2, v3, v4
    length = np.sqrt(np.einsum("sij,sij->si", E, E))
    ratio = np.maximum(length[:, :2], length[:, 2:]) / np.maximum(
        np.minimum(length[:, :2], length[:, 2:]), 1e-300)
    # projected on the tangent plane: the bending along the surface is left out
    T = E - np.einsum("sij,sj->si", E, normal)[:, :, None] * normal[:, None, :]
    size = np.maximum(np.sqrt(np.einsum("sij,sij->si", T, T)), 1e-300)
    # a line a - v - b turns by the angle between v - a and b - v
    cosine = -np.einsum("sij,sij->si", T[:, :2], T[:, 2:]) / (size[:, :2] * size[:, 2:])
    return np.arccos(np.clip(cosine, -1.0, 1.0)), ratio


def _worst(values: np.ndarray, where: np.ndarray, X: np.ndarray) -> dict:
    """max / median / 95 % of `values` with the vertex and point of the maximum."""
    if values.size == 0:
        return {"max": None, "median": None, "p95": None, "vertex": None, "point": None}
    k = int(np.argmax(values))
    return {"max": float(values[k]), "median": float(np.median(values)),
            "p95": float(np.percentile(values, 95)), "vertex": int(where[k]),
            "point": X[where[k]].tolist()}


def fairness_record(mesh: QuadMesh, X: np.ndarray | None = None) -> dict:
    """JSON-ready fairness of a net: line turns (degrees), edge ratios along the lines,
    the intersection angle range and edge lengths against the mean, with the vertex and
    point of the worst of each."""
    X = mesh.vertices if X is None else X
    stars = canonical_stars(X, mesh.stars)
    turn, ratio = line_turns(X, stars) if len(stars) else (np.zeros((0, 2)), np.ones((0, 2)))
    centre = np.repeat(stars[:, 0], 2) if len(stars) else np.zeros(0, np.int64)
    angle = np.degrees(intersection_angles(X, stars)) if len(stars) else np.zeros(0)
    E = mesh.edges
    length = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)
    mean = float(length.mean()) if len(length) else 0.0
    record = {
        "line_turn_deg": _worst(np.degrees(turn).ravel(), centre, X),
        "edge_ratio_along_lines": _worst(ratio.ravel(), centre, X),
        "intersection_angle_deg": {"min": None, "max": None, "min_vertex": None,
                                   "max_vertex": None},
        "edge_length_relative": {"min": float(length.min() / mean) if mean else None,
                                 "max": float(length.max() / mean) if mean else None},
    }
    if angle.size:
        lo, hi = int(np.argmin(angle)), int(np.argmax(angle))
        record["intersection_angle_deg"] = {"min": float(angle[lo]), "max": float(angle[hi]),
                                            "min_vertex": int(stars[lo, 0]),
                                            "max_vertex": int(stars[hi, 0])}
    return record
