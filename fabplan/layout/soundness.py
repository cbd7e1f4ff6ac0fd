"""What is wrong with a cladding (a net and its boundary panels), measured on the surface
(`Soundness`): panels off the design (`fabplan.layout.off_design`), crossing themselves,
facing against the design (`flipped_panels`), overlapping a face or another panel
(`fabplan.layout.overlaps`); and the panels to leave out for it (`unsound_pieces`,
`without_pieces`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..design.mesh_surface import DesignSurface
from ..net.mesh import QuadMesh
from .off_design import MIN_OFF_PANELS, OffDesign, area_off_design
from .overlaps import edge_clashes, overlapping_pairs, self_crossing

__all__ = ["Soundness", "soundness", "unsound_pieces", "without_pieces", "flipped_panels"]


@dataclass
class Soundness:
    """What is wrong with a cladding (a net and its boundary panels), measured on the
    surface: nothing in a sound one.

    Attributes
    ----------
    off_net : `OffDesign` of the net's faces (over a hole, or past the design boundary).
    off_panels : `OffDesign` of the boundary panels.
    crossing : (k,) int, panels whose outline crosses itself (`self_crossing`).
    overlaps : (m, 2) int, pairs of pieces that cover the same part of the surface
        (`overlapping_pairs`); overlap_area (m,) float, the area each shares.
    clashes : (c, 2) int, pairs of pieces that use a side in the same direction
        (`edge_clashes`). Pieces in `overlaps` and `clashes` are numbered the net's
        `faces` first, then the panels.
    faces : the number of the net's faces.
    """

    off_net: OffDesign
    off_panels: OffDesign
    crossing: np.ndarray
    overlaps: np.ndarray
    overlap_area: np.ndarray
    clashes: np.ndarray
    faces: int

    def _piece(self, k: int) -> dict:
        return {"face": int(k)} if k < self.faces else {"panel": int(k - self.faces)}

    def record(self, panel_size: float, cut_again: int = 0) -> dict:
        """JSON-ready: ``off_design`` (the area of panels off the design: over a hole or
        past its boundary, an error; where the largest pieces are) and ``crossings``
        (counts of panels crossing themselves, pairs of pieces overlapping and sides
        used twice the same way, with the pieces named; the panels cut again on the
        surface)."""
        least = MIN_OFF_PANELS * panel_size ** 2
        net_area = self.off_net.area[self.off_net.area > least]
        panel_area = self.off_panels.area[self.off_panels.area > least]
        total = float(net_area.sum() + panel_area.sum())
        places = self.off_net.places(least, label="face") + \
            self.off_panels.places(least, label="panel")
        places.sort(key=lambda p: -p["area"])
        return {
            "off_design": {
                "area": total, "area_relative_to_panel": total / panel_size ** 2,
                "faces": int(len(net_area)), "panels": int(len(panel_area)),
                "places": places[:5]},
            "crossings": {
                "self_crossing": int(len(self.crossing)),
                "overlapping": int(len(self.overlaps)),
                "edge_clashes": int(len(self.clashes)),
                "pairs": [[self._piece(a), self._piece(b)] for a, b in
                          np.concatenate([self.overlaps, self.clashes]).tolist()][:10],
                "cut_again": int(cut_again)},
        }


def soundness(vertices: np.ndarray, polygons: list, triangles: np.ndarray, owner: np.ndarray,
              mesh: QuadMesh, design: DesignSurface, h: float) -> Soundness:
    """The `Soundness` of a net `mesh` and its boundary panels (`polygons` into `vertices`,
    cut into `triangles` of `owner` each) on `design`, panel size `h`."""
    from .off_design import faces_off_design

    pieces = list(mesh.faces) + list(polygons)
    overlaps, shared = overlapping_pairs(vertices, pieces, len(mesh.face_sizes), h)
    return Soundness(
        off_net=faces_off_design(design, vertices, mesh.faces, h),
        off_panels=area_off_design(design, vertices, triangles, owner, len(polygons), h),
        crossing=np.flatnonzero(self_crossing(vertices, polygons)),
        overlaps=overlaps, overlap_area=shared,
        clashes=edge_clashes(pieces, len(vertices)), faces=len(mesh.face_sizes))


def unsound_pieces(vertices: np.ndarray, polygons: list, triangles: np.ndarray,
                   owner: np.ndarray, mesh: QuadMesh, design: DesignSurface, h: float
                   ) -> np.ndarray:
    """(p,) bool, the panels that are off the design, cross themselves, face against it,
    overlap a net face or an earlier panel, or share a side with one the same way."""
    sound = soundness(vertices, polygons, triangles, owner, mesh, design, h)
    bad = np.zeros(len(polygons), bool)
    bad[sound.crossing] = True
    bad[sound.off_panels.area > MIN_OFF_PANELS * h * h] = True
    bad[flipped_panels(vertices, polygons, design, 1e-3 * h * h)] = True
    # of two panels that overlap, the later goes (a patch cut twice, from two gaps that
    # meet, is kept once); a panel over a net face goes
    for pairs in (sound.overlaps, sound.clashes):
        bad[pairs.max(axis=1) - sound.faces] = True
    return bad


def without_pieces(polygons: list, triangles: np.ndarray, owner: np.ndarray, patch: np.ndarray,
                   drop: np.ndarray) -> tuple[list, np.ndarray, np.ndarray, np.ndarray]:
    """The panels less those marked in `drop` (p,) bool: their outlines, triangles (t, 3)
    with the panel of each renumbered, and `patch` (p,) bool."""
    keep = ~np.asarray(drop, bool)
    new_id = np.cumsum(keep) - 1
    kept = keep[owner]
    return ([q for q, k in zip(polygons, keep, strict=True) if k], triangles[kept],
            new_id[owner[kept]], patch[keep])


def flipped_panels(vertices: np.ndarray, polygons: list, design: DesignSurface, min_area: float
                   ) -> np.ndarray:
    """(k,) int, panels facing against the design: their vector area, longer than twice
    `min_area` (a sliver's is noise), against the design's normal at the closest point to
    their centroid."""
    if not polygons:
        return np.zeros(0, np.int64)
    X = vertices
    ring = np.concatenate(polygons)
    after = np.concatenate([np.roll(q, -1) for q in polygons])
    count = np.array([len(q) for q in polygons])
    panel = np.repeat(np.arange(len(polygons)), count)
    cross = np.cross(X[ring], X[after])
    vector = np.stack([np.bincount(panel, cross[:, k], minlength=len(polygons)) for k in range(3)],
                      axis=1)
    centroid = np.stack([np.bincount(panel, X[ring, k], minlength=len(polygons)) for k in range(3)],
                        axis=1) / count[:, None]
    _, _, tri = design.reference.closest_points(centroid)
    size = np.linalg.norm(vector, axis=1)
    return np.flatnonzero((np.sum(vector * design.face_normals[tri], axis=1) <= 0)
                          & (size > 2 * min_area))
