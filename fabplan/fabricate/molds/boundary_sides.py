"""The sides of boundary panels, and what lies across each: a face of the net, another
boundary panel, or nothing (the design boundary)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...layout.boundary_panels import BoundaryPanels

__all__ = ["BoundarySides", "boundary_sides"]


@dataclass(frozen=True)
class BoundarySides:
    """The sides of boundary panels and what lies across each.

    Attributes
    ----------
    panel : (s,) int, the boundary panel of every side.
    start, end : (s,) int, its ends (ids into `BoundaryPanels.vertices`, in outline order).
    face : (s,) int, the net face across the side, -1 where none.
    across : (s,) int, the boundary panel across the side, -1 where none (a net face, or
        the design boundary).
    """

    panel: np.ndarray
    start: np.ndarray
    end: np.ndarray
    face: np.ndarray
    across: np.ndarray


def boundary_sides(panels: BoundaryPanels, mesh) -> BoundarySides:
    """The sides of every boundary panel (consecutive outline points) and the net face or
    boundary panel that runs along each the other way.

    Parameters
    ----------
    panels : `BoundaryPanels` of `mesh` (its net vertices numbered as the net's).
    mesh : the net (`fabplan.net.mesh.QuadMesh`).

    Returns
    -------
    BoundarySides
    """
    polygons = [np.asarray(q, np.int64) for q in panels.polygons]
    if not polygons:
        empty = np.zeros(0, np.int64)
        return BoundarySides(empty, empty, empty, empty, empty)
    start = np.concatenate(polygons)
    end = np.concatenate([np.roll(q, -1) for q in polygons])
    panel = np.repeat(np.arange(len(polygons)), [len(q) for q in polygons])
    n = max(len(panels.vertices), mesh.vertex_count)
    back = end * n + start
    # net faces: their half-edges the other way
    key = mesh.face_indices.astype(np.int64) * n + mesh.corner_next_vertices
    face = _lookup(key, mesh.corner_faces, back)
    # boundary panels: their sides the other way (not where a net face is across)
    across = np.where(face < 0, _lookup(start * n + end, panel, back), -1)
    return BoundarySides(panel, start, end, face, across)


def _lookup(keys: np.ndarray, values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The value of every `wanted` key among `keys` (each once), -1 where absent."""
    if len(keys) == 0:
        return np.full(len(wanted), -1)
    order = np.argsort(keys, kind="stable")
    at = np.clip(np.searchsorted(keys[order], wanted), 0, len(keys) - 1)
    return np.where(keys[order][at] == wanted, np.asarray(values)[order[at]], -1)
