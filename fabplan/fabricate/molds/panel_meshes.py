"""Panels as triangle meshes: the panel surfaces of a mold plan, and the boundary panels as cut.

A mold plan measures every panel on samples of its surface (`fabplan.fabricate.molds.panels`): a
fan of triangles from the mean of the face's corners, each with a triangular grid of
``level`` steps per side, lifted onto the panel surface. Those samples, joined into
triangles, are the panel as a triangle mesh: what the IFC export writes as a panel's
geometry and what its area is measured on (``panel_area`` in ``molds.json``).

Per panel the mesh is closed up: the samples on a spoke of the fan (shared by two fan
triangles) and the centre are kept once, and the corners are the net's vertices exactly
(the surface passes through them with a least-squares weight of
`fabplan.fabricate.molds.panels.CORNER_WEIGHT`, so this moves them by about a millionth of the
panel's size), so that a panel's outline starts and ends where the OBJ's face does.

A boundary panel as cut (`fabplan.fabricate.molds.boundary_molds.BoundaryMolds.cut_outlines`) is
its trimmed outline moved onto its mold; its mesh is the trimming's triangles over those
points (`fabplan.layout.trim.BoundaryPanels.panel_triangles`).

Coordinates are model units, areas model units squared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError

__all__ = ["PANEL_MESH_LEVEL", "PanelMesh", "fan_grid", "fan_grid_triangles",
           "panel_surface_mesh", "boundary_cut_mesh", "face_fan_mesh"]

PANEL_MESH_LEVEL = 4
"""Grid steps per side of every fan triangle of a panel's mesh: a quad becomes 64 triangles
over 41 points. A chord of a quarter of the half-diagonal sags from the surface by
``k d^2 / 512`` (``d`` the diagonal, ``k`` the curvature): 1.8 mm for a 3 m panel of 20 m
radius."""


@dataclass(frozen=True)
class PanelMesh:
    """Panels as triangle meshes, one after the other.

    Attributes
    ----------
    points : (v, 3) float, model units; the points of panel ``i`` are
        ``points[point_ptr[i]:point_ptr[i + 1]]``.
    triangles : (t, 3) int into `points`, counter-clockwise about the panel's normal; those
        of panel ``i`` are ``triangles[triangle_ptr[i]:triangle_ptr[i + 1]]``.
    point_ptr : (p + 1,) int.
    triangle_ptr : (p + 1,) int.
    """

    points: np.ndarray
    triangles: np.ndarray
    point_ptr: np.ndarray
    triangle_ptr: np.ndarray

    @property
    def panel_count(self) -> int:
        return len(self.point_ptr) - 1

    @property
    def panel(self) -> np.ndarray:
        """(t,) int, the panel of every triangle."""
        return np.repeat(np.arange(self.panel_count), np.diff(self.triangle_ptr))

    def areas(self) -> np.ndarray:
        """(p,) float, every panel's area: the sum of its triangles' (model units squared)."""
        T = self.points[self.triangles]
        area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
        return np.bincount(self.panel, area, minlength=self.panel_count)

    @staticmethod
    def join(meshes: list[tuple[np.ndarray, np.ndarray]]) -> "PanelMesh":
        """Panels given one by one as (points, triangles into them)."""
        sizes = np.array([len(p) for p, _ in meshes], np.int64)
        counts = np.array([len(t) for _, t in meshes], np.int64)
        point_ptr = np.r_[0, np.cumsum(sizes)]
        points = np.concatenate([p for p, _ in meshes]) if meshes else np.zeros((0, 3))
        triangles = (np.concatenate([np.asarray(t, np.int64) for _, t in meshes])
                     + np.repeat(point_ptr[:-1], counts)[:, None]) if meshes else np.zeros((0, 3), np.int64)
        return PanelMesh(np.asarray(points, np.float64), triangles.reshape(-1, 3), point_ptr,
                         np.r_[0, np.cumsum(counts)])


def fan_grid(level: int) -> np.ndarray:
    """(t, 2) int, the grid of a fan triangle (centre, corner j, corner j+1): steps ``(i, m)``
    towards corner j and corner j+1, ``i + m <= level``, in the order of the samples of
    `fabplan.fabricate.molds.panels.panel_samples` (their corner weights are this over `level`).

    Examples
    --------
    >>> fan_grid(1).tolist()
    [[0, 0], [0, 1], [1, 0]]
    """
    i, m = np.meshgrid(np.arange(level + 1), np.arange(level + 1), indexing="ij")
    keep = i + m <= level
    return np.stack([i[keep], m[keep]], axis=1)


def fan_grid_triangles(level: int) -> np.ndarray:
    """(level**2, 3) int into `fan_grid`: the grid's triangles, with the orientation of
    (centre, corner j, corner j+1).

    Examples
    --------
    >>> fan_grid_triangles(1).tolist()
    [[0, 2, 1]]
    """
    grid = fan_grid(level)
    at = -np.ones((level + 2, level + 2), np.int64)
    at[grid[:, 0], grid[:, 1]] = np.arange(len(grid))
    i, m = grid[:, 0], grid[:, 1]
    up = grid[i + m <= level - 1]
    down = grid[i + m <= level - 2]
    ui, um = up[:, 0], up[:, 1]
    di, dm = down[:, 0], down[:, 1]
    return np.concatenate([np.stack([at[ui, um], at[ui + 1, um], at[ui, um + 1]], axis=1),
                           np.stack([at[di + 1, dm], at[di + 1, dm + 1], at[di, dm + 1]], axis=1)])


def panel_surface_mesh(mesh, samples: np.ndarray, level: int) -> PanelMesh:
    """The panels of a mold plan as triangle meshes, from their surface samples.

    Parameters
    ----------
    mesh : the net (`fabplan.net.mesh.QuadMesh`).
    samples : (f, s, 3) float, the panel surface samples at `level`, as
        `fabplan.fabricate.molds.panels.panel_samples` (or the ``shared`` and ``design``
        samplers) give them: ``k_max`` fan triangles of ``len(fan_grid(level))`` points each.
    level : grid steps per side of a fan triangle.

    Returns
    -------
    PanelMesh, one panel per face: ``1 + k level (level + 1) / 2`` points and ``k level^2``
    triangles for a face of ``k`` corners, its corners the net's vertices.

    Examples
    --------
    >>> import numpy as np
    >>> from fabplan.net.mesh import QuadMesh
    >>> from fabplan.fabricate.molds.panels import fit_panel_surfaces, panel_samples
    >>> square = QuadMesh([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], [[0, 1, 2, 3]])
    >>> samples = panel_samples(square, fit_panel_surfaces(square, "corners"), 2)
    >>> panels = panel_surface_mesh(square, samples, 2)
    >>> len(panels.points), len(panels.triangles), panels.areas().round(12).tolist()
    (13, 16, [4.0])
    """
    grid = fan_grid(level)
    per_fan = len(grid)
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    k_max = int(sizes.max())
    if samples.shape[:2] != (len(sizes), k_max * per_fan):
        raise InputError(f"panel samples of shape {samples.shape} are not those of level {level} "
                         f"for {len(sizes)} faces of up to {k_max} corners")
    own = np.flatnonzero(grid[:, 0] >= 1)              # a fan's own points (off its first spoke)
    rank = -np.ones(per_fan, np.int64)
    rank[own] = np.arange(len(own))
    at = {tuple(g): n for n, g in enumerate(grid.tolist())}
    spoke = np.array([at[(m, 0)] for m in range(level + 1)])   # (i, 0): on spoke j
    tri = fan_grid_triangles(level)
    u = len(own)

    point_count = 1 + sizes * u
    point_ptr = np.r_[0, np.cumsum(point_count)]
    triangle_ptr = np.r_[0, np.cumsum(sizes * len(tri))]
    points = np.zeros((point_ptr[-1], 3))
    triangles = np.zeros((triangle_ptr[-1], 3), np.int64)
    for k in np.unique(sizes):
        faces = np.flatnonzero(sizes == k)
        S = samples[faces, :k * per_fan].reshape(len(faces), k, per_fan, 3)
        # local ids: 0 the centre, then every fan's own points; a point on the first spoke
        # of fan j (i = 0) is the point on the second spoke of fan j - 1
        j = np.arange(k)[:, None]
        local = np.where(grid[None, :, 0] >= 1, 1 + j * u + rank[None, :],
                         np.where(grid[None, :, 1] == 0, 0,
                                  1 + ((j + 1) % k) * u + rank[spoke[grid[None, :, 1]]]))
        block = np.empty((len(faces), 1 + k * u, 3))
        block[:, 0] = S[:, 0, 0]
        block[:, 1:] = S[:, :, own].reshape(len(faces), k * u, 3)
        corner = 1 + np.arange(k) * u + rank[at[(level, 0)]]
        block[:, corner] = mesh.vertices[mesh.face_indices[ptr[faces][:, None] + np.arange(k)]]
        rows = point_ptr[faces][:, None] + np.arange(1 + k * u)
        points[rows] = block
        face_triangles = local[:, tri].reshape(-1, 3)           # (k level^2, 3) local ids
        rows = triangle_ptr[faces][:, None] + np.arange(len(face_triangles))
        triangles[rows] = point_ptr[faces][:, None, None] + face_triangles[None]
    return PanelMesh(points, triangles, point_ptr, triangle_ptr)


def face_fan_mesh(mesh) -> PanelMesh:
    """Every face of a net as its own flat fan of triangles from its first corner (a net
    without a mold plan: its panels are its faces).

    Examples
    --------
    >>> from fabplan.net.mesh import QuadMesh
    >>> panels = face_fan_mesh(QuadMesh([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]]))
    >>> panels.triangles.tolist(), panels.areas().tolist()
    ([[0, 1, 2], [0, 2, 3]], [2.0])
    """
    sizes, ptr = mesh.face_sizes, mesh.face_indptr
    points = mesh.vertices[mesh.face_indices]
    face = np.repeat(np.arange(len(sizes)), sizes - 2)
    step = np.arange(len(face)) - np.repeat(np.cumsum(sizes - 2) - (sizes - 2), sizes - 2)
    first = ptr[:-1][face]
    triangles = np.stack([first, first + step + 1, first + step + 2], axis=1)
    return PanelMesh(points, triangles, np.asarray(ptr, np.int64), np.r_[0, np.cumsum(sizes - 2)])


def boundary_cut_mesh(panels, cut_outlines: list | None = None) -> PanelMesh:
    """The boundary panels as triangle meshes: the trimming's triangles of every panel
    (`BoundaryPanels.panel_triangles`) over its outline as cut (`cut_outlines`, a (k, 3)
    array per panel in the order of its polygon; None: the trimmed outline itself).

    Returns
    -------
    PanelMesh, one panel per boundary panel, its points those of its outline.
    """
    polygons = [np.asarray(q, np.int64) for q in panels.polygons]
    sizes = np.array([len(q) for q in polygons], np.int64)
    point_ptr = np.r_[0, np.cumsum(sizes)]
    if not polygons:
        return PanelMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), point_ptr, np.zeros(1, np.int64))
    ids = np.concatenate(polygons)
    points = (np.asarray(panels.vertices, np.float64)[ids] if cut_outlines is None
              else np.concatenate([np.asarray(c, np.float64) for c in cut_outlines]))
    owner = np.repeat(np.arange(len(sizes)), sizes)
    triangles, panel = panels.panel_triangles()
    order = np.argsort(panel, kind="stable")
    triangles, panel = triangles[order], panel[order]
    # a triangle's vertex ids -> the slot of that id in its own panel's outline
    width = int(len(panels.vertices))
    key = owner * width + ids
    sort = np.argsort(key, kind="stable")
    wanted = panel[:, None] * width + triangles
    found = np.clip(np.searchsorted(key[sort], wanted), 0, len(key) - 1)
    hit = key[sort][found] == wanted
    if not hit.all():
        bad = int(panel[~hit.all(axis=1)][0])
        raise InputError(f"boundary panel {bad}: a triangle of its trimming has a corner off "
                         "its outline")
    counts = np.bincount(panel, minlength=len(sizes))
    return PanelMesh(points, sort[found], point_ptr, np.r_[0, np.cumsum(counts)])
