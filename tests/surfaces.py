"""Generated quad grids on analytic test surfaces, for the preset tests.

The surfaces are quadrics ``z = x^2 / (2 R1) + y^2 / (2 R2)`` given by their signed
principal radii at the origin (``R1`` along x, ``R2`` along y, model units): a dome has both
radii of one sign, a saddle radii of opposite signs. Their principal directions at the
origin are x and y.

The grids are sampled through their projection to the xy-plane: two families of straight
lines with unit spacing that meet at `angle_deg` and are placed symmetrically about the
x-axis, so their bisectors are the principal directions at the origin. Such a net has equal
normal curvature along both families at the origin (an S-net to first order there), and
its intersection angle near the origin is close to `angle_deg`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fabplan.net.mesh import QuadMesh

__all__ = ["Quadric", "DOME", "SADDLE", "quadric_grid"]


@dataclass(frozen=True)
class Quadric:
    """The graph ``z = x^2 / (2 R1) + y^2 / (2 R2)``.

    Attributes
    ----------
    name : label used in test ids.
    radius_x, radius_y : signed principal radii of curvature at the origin (model units).
    """

    name: str
    radius_x: float
    radius_y: float

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return x * x / (2 * self.radius_x) + y * y / (2 * self.radius_y)


# Radii of 20 to 40 edges on a patch of 11 x 11 edges: curved enough that the presets differ,
# flat enough that a straight-line grid is a good start. Unequal radii keep the cases generic
# (no umbilic, and a saddle that is not minimal at the origin).
DOME = Quadric("dome", -20.0, -30.0)
SADDLE = Quadric("saddle", 20.0, -40.0)


def quadric_grid(surface: Quadric, *, angle_deg: float = 90.0, size: int = 12,
                 spacing: float = 1.0) -> QuadMesh:
    """A ``size x size`` grid on `surface`, its families meeting at `angle_deg` in plan view.

    Parameters
    ----------
    surface : the quadric to sample.
    angle_deg : angle between the two families of grid lines in the xy-plane; the x-axis
        bisects it.
    size : vertices along each family.
    spacing : distance between neighbouring vertices in plan view (model units).

    Returns
    -------
    QuadMesh with ``size**2`` vertices, centred on the origin, faces oriented so that the
    normal points up (+z).
    """
    half = np.radians(angle_deg) / 2
    d1 = spacing * np.array([np.cos(half), -np.sin(half)])
    d2 = spacing * np.array([np.cos(half), np.sin(half)])
    t = np.arange(size) - (size - 1) / 2
    i, j = np.meshgrid(t, t, indexing="ij")
    xy = i[..., None] * d1 + j[..., None] * d2
    x, y = xy[..., 0], xy[..., 1]
    points = np.stack([x, y, surface.height(x, y)], axis=-1)
    return QuadMesh.grid(points, name=f"{surface.name}-{angle_deg:g}deg")
