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
    P = X[stars]
    v = P[:, 0]
    normal = _unit(np.cross(P[:, 3] - P[:, 1], P[:, 4] - P[:, 2]))
    turn, ratio = np.zeros((len(stars), 2)), np.ones((len(stars), 2))
    for family, (a, b) in enumerate(((1, 3), (2, 4))):
        before, after = v - P[:, a], P[:, b] - v
        la, lb = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
        ratio[:, family] = np.maximum(la, lb) / np.maximum(np.minimum(la, lb), 1e-300)
        # projected on the tangent plane: the bending along the surface is left out
        pa = _unit(before - np.sum(before * normal, axis=1, keepdims=True) * normal)
        pb = _unit(after - np.sum(after * normal, axis=1, keepdims=True) * normal)
        turn[:, family] = np.arccos(np.clip(np.sum(pa * pb, axis=1), -1.0, 1.0))
    return turn, ratio


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
