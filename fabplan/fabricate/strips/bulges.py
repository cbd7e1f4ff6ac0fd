"""Outlines with arcs, as DXF writes them: rows ``x, y, bulge`` (the bulge of a segment is
the tangent of a quarter of its arc's central angle; 0 is straight), their points with the
arcs flattened within a tolerance, and their polygons (millimetres).
"""

from __future__ import annotations

import math

import numpy as np
from shapely.geometry import Polygon

__all__ = [
    "ARC_FLATTENING_MM",
    "bulge_points",
    "bulge_polygon",
]

ARC_FLATTENING_MM = 0.02
"""Largest distance between an arc and the polygon that stands for it in geometry tests."""


def bulge_points(outline: np.ndarray, *, closed: bool = True,
                 tolerance_mm: float = ARC_FLATTENING_MM) -> np.ndarray:
    """Points along a bulged polyline, arcs flattened within `tolerance_mm`.

    Parameters
    ----------
    outline : (m, 3) float rows ``x, y, bulge``.
    closed : whether the last row connects back to the first.

    Returns
    -------
    (p, 2) float, the first point not repeated at the end.

    Examples
    --------
    >>> import numpy as np
    >>> half = bulge_points(np.array([[1.0, 0, 1], [-1.0, 0, 0]]), closed=False)
    >>> bool(np.allclose(np.linalg.norm(half, axis=1), 1))
    True
    """
    P = outline[:, :2]
    m = len(P)
    stop = m if closed else m - 1
    out = []
    for i in range(stop):
        a, b, bulge = P[i], P[(i + 1) % m], outline[i, 2]
        out.append(a[None])
        if abs(bulge) < 1e-12:
            continue
        theta = 4 * math.atan(bulge)
        chord = float(np.linalg.norm(b - a))
        radius = chord / (2 * abs(math.sin(theta / 2)))
        step = 2 * math.acos(max(-1.0, 1 - tolerance_mm / radius)) if radius > tolerance_mm else 0.5
        n = max(2, int(math.ceil(abs(theta) / max(step, 1e-9))))
        d = b - a
        left = np.array([-d[1], d[0]]) / chord
        centre = (a + b) / 2 + left * (chord / 2 / math.tan(theta / 2))
        a0 = math.atan2(a[1] - centre[1], a[0] - centre[0])
        t = a0 + theta * np.arange(1, n) / n
        out.append(centre + radius * np.column_stack([np.cos(t), np.sin(t)]))
    if not closed:
        out.append(P[-1][None])
    return np.concatenate(out)


def bulge_polygon(outline: np.ndarray) -> Polygon:
    """Shapely polygon of a closed bulged outline."""
    return Polygon(bulge_points(outline, closed=True))
