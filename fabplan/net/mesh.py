"""The quad-dominant mesh: vertices, polygonal faces and the combinatorics derived from them.

Everything derived is computed once, vectorized over index arrays, and cached: edges,
boundary, valences, regular vertex stars with opposite neighbours paired and the two
families of parameter lines told apart, and the parameter polylines of both families.

Conventions
-----------
A *star* is a row ``[v, v1, v2, v3, v4]`` of an interior vertex ``v`` of valence 4, its
neighbours in counter-clockwise order (with respect to the face orientation).
``v1, v3`` lie on a parameter line of family 0 and ``v2, v4`` on one of family 1, so
``(v1, v3)`` and ``(v2, v4)`` are the opposite pairs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from ..errors import InputError
from ..io.obj import parse_obj, split_faces, write_obj
from .forest import break_cycles, pointer_jump, tree_parity
from .index_rows import unique_rows

__all__ = ["QuadMesh", "Polylines", "load_mesh"]


@dataclass(frozen=True)
class Polylines:
    """The parameter polylines of both families.

    Attributes
    ----------
    vertices : list of (k,) int arrays, vertex indices in order along each polyline.
    family : (p,) int, 0 or 1.
    closed : (p,) bool, True when the polyline is a closed loop (first vertex not repeated).
    """

    vertices: list
    family: np.ndarray
    closed: np.ndarray

    def __len__(self) -> int:
        return len(self.vertices)


class QuadMesh:
    """A quad-dominant polygon mesh with boundary, irregular vertices and non-quad faces.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : sequence of vertex index sequences (any sizes >= 3), or a (f, k) int array.
    name : a label used in error messages, usually the file name.
    normals : (n, 3) float, optional per-vertex unit normals (the tangent planes of an
        S*-net's contact elements).

    Examples
    --------
    >>> from fabplan.net.mesh import QuadMesh
    >>> import numpy as np
    >>> u, v = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    >>> grid = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1))
    >>> grid.vertex_count, len(grid.faces), grid.stars.shape
    (12, 6, (2, 5))
    """

    def __init__(self, vertices: npt.ArrayLike, faces: Sequence[Sequence[int] | np.ndarray] | np.ndarray,
                 *, name: str = "mesh", normals: npt.ArrayLike | None = None) -> None:
        self.name = name
        vertices = np.array(vertices, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise InputError(f"{name}: vertices must be an (n, 3) array, got {vertices.shape}")
        bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
        if bad.size:
            raise InputError(f"{name}: vertex {bad[0]} has a non-finite coordinate")
        self.vertices = vertices
        self.normals: np.ndarray | None = None
        if normals is not None:
            normals = np.array(normals, dtype=np.float64)
            if normals.shape != vertices.shape or not np.isfinite(normals).all():
                raise InputError(f"{name}: normals must be finite and one per vertex")
            self.normals = normals
        sizes = np.array([len(f) for f in faces], dtype=np.int64)
        if sizes.size == 0:
            raise InputError(f"{name}: the mesh has no faces")
        if sizes.min() < 3:
            raise InputError(f"{name}: face {int(np.argmin(sizes))} has fewer than 3 vertices")
        self.face_sizes = sizes
        self.face_indptr = np.concatenate([[0], np.cumsum(sizes)])
        self.face_indices = np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
        n = len(vertices)
        if self.face_indices.min() < 0 or self.face_indices.max() >= n:
            f = int(np.searchsorted(self.face_indptr, np.flatnonzero(
                (self.face_indices < 0) | (self.face_indices >= n))[0], side="right") - 1)
            raise InputError(f"{name}: face {f} refers to a vertex that does not exist")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_obj(cls, path: str | os.PathLike) -> "QuadMesh":
        """Read an OBJ file, keeping quads, vertex order and indices exactly."""
        vertices, faces, normals = parse_obj(path)
        return cls(vertices, faces, name=str(path), normals=normals)

    @classmethod
    def grid(cls, points: np.ndarray, *, name: str = "grid") -> "QuadMesh":
        """A quad mesh on a regular (m, k, 3) array of points, faces counter-clockwise in (i, j)."""
        points = np.asarray(points, dtype=np.float64)
        m, k = points.shape[:2]
        idx = np.arange(m * k).reshape(m, k)
        quads = np.stack(
            [idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1
        ).reshape(-1, 4)
        return cls(points.reshape(-1, 3), quads, name=name)

    def to_data(self) -> dict:
        """The mesh as plain data (`fabplan.io.typed_data`): arrays, its name."""
        return {"vertices": self.vertices, "face_sizes": self.face_sizes,
                "face_indices": self.face_indices, "name": self.name, "normals": self.normals}

    @classmethod
    def from_data(cls, data: dict) -> "QuadMesh":
        """The mesh `to_data` gave (checked as any new mesh is)."""
        sizes = np.asarray(data["face_sizes"], dtype=np.int64)
        faces = np.split(np.asarray(data["face_indices"], dtype=np.int64), np.cumsum(sizes)[:-1])
        return cls(data["vertices"], faces, name=str(data["name"]), normals=data["normals"])

    def with_vertices(self, vertices: np.ndarray, normals: np.ndarray | None = None) -> "QuadMesh":
        """The same combinatorics with new vertex positions (and normals, dropped unless
        given); the cached topology is shared."""
        new = object.__new__(QuadMesh)
        new.__dict__.update({k: v for k, v in self.__dict__.items() if k != "vertices"})
        new.vertices = np.array(vertices, dtype=np.float64).reshape(-1, 3)
        new.normals = None if normals is None else np.array(normals, dtype=np.float64)
        for name in _GEOMETRIC_CACHE:      # measured on the old positions
            new.__dict__.pop(name, None)
        return new

    def write_obj(self, path: str | os.PathLike, header: str = "") -> None:
        """Write the mesh as OBJ atomically (quads and order kept)."""
        write_obj(path, self.vertices, self.faces, header, normals=self.normals)

    # ------------------------------------------------------------------ basic sizes
    @property
    def vertex_count(self) -> int:
        return len(self.vertices)

    @property
    def faces(self) -> list:
        """list of (k,) int arrays, one per face."""
        return split_faces(self.face_indices, self.face_sizes)

    @cached_property
    def quads(self) -> np.ndarray:
        """(q, 4) int, the vertex indices of the faces with four vertices."""
        starts = self.face_indptr[:-1][self.face_sizes == 4]
        return self.face_indices[starts[:, None] + np.arange(4)]

    @cached_property
    def quad_ids(self) -> np.ndarray:
        """(q,) int, the face index of each row of `quads`."""
        return np.flatnonzero(self.face_sizes == 4)

    def triangles(self) -> np.ndarray:
        """(t, 3) int, a fan triangulation of all faces (for rendering and closest points)."""
        sizes, ptr, idx = self.face_sizes, self.face_indptr, self.face_indices
        face = np.repeat(np.arange(len(sizes)), sizes - 2)
        k = np.arange(len(face)) - np.repeat(np.cumsum(sizes - 2) - (sizes - 2), sizes - 2)
        first = idx[ptr[face]]
        return np.stack([first, idx[ptr[face] + k + 1], idx[ptr[face] + k + 2]], axis=1)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """(f,) float, area of every face: its vector area's length, ``|sum p_i x p_i+1| / 2``
        (exact for planar faces; for a skew face the area of its projection on the
        plane normal to that vector, independent of the diagonal a triangulation would
        choose).

        Examples
        --------
        >>> QuadMesh([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]]).face_areas
        array([2.])
        """
        X = self.vertices
        sizes, idx = self.face_sizes, self.face_indices
        nxt = np.arange(len(idx)) + 1
        ends = np.cumsum(sizes)
        nxt[ends - 1] = ends - sizes
        vector = np.cross(X[idx], X[idx[nxt]])
        face = np.repeat(np.arange(len(sizes)), sizes)
        total = np.stack([np.bincount(face, vector[:, k], minlength=len(sizes)) for k in range(3)],
                         axis=1)
        return 0.5 * np.linalg.norm(total, axis=1)

    # ------------------------------------------------------------------ corners
    @cached_property
    def corner_faces(self) -> np.ndarray:
        """(c,) int, the face of every corner, aligned with `face_indices`."""
        return np.repeat(np.arange(len(self.face_sizes)), self.face_sizes)

    @cached_property
    def corner_next_vertices(self) -> np.ndarray:
        """(c,) int, aligned with `face_indices`: the vertex after each corner in its face."""
        return self._corners["nxt"]

    @cached_property
    def corner_previous_vertices(self) -> np.ndarray:
        """(c,) int, aligned with `face_indices`: the vertex before each corner in its face."""
        return self._corners["prv"]

    @cached_property
    def faces_across(self) -> np.ndarray:
        """(c,) int, aligned with `face_indices`: the face across the edge from each corner to
        the next corner of its face, or -1 where that edge is on the boundary."""
        c = self._corners
        return np.where(c["twin"] >= 0, c["face"][np.maximum(c["twin"], 0)], -1)

    @cached_property
    def _corners(self) -> dict:
        """Per corner (face, local index): vertex, next vertex, previous vertex, twin corner."""
        sizes, ptr = self.face_sizes, self.face_indptr
        n = self.vertex_count
        face = self.corner_faces
        local = np.arange(len(face)) - ptr[face]
        vert = self.face_indices
        nxt_corner = np.where(local == sizes[face] - 1, ptr[face], np.arange(len(face)) + 1)
        prv_corner = np.where(local == 0, ptr[face] + sizes[face] - 1, np.arange(len(face)) - 1)
        nxt, prv = vert[nxt_corner], vert[prv_corner]
        by_face = np.sort(face * n + vert)
        repeated = np.flatnonzero(by_face[1:] == by_face[:-1])
        if repeated.size:
            raise InputError(f"{self.name}: face {by_face[repeated[0]] // n} repeats a vertex")
        key = vert * n + nxt
        order = np.argsort(key, kind="stable")
        skey = key[order]
        dup = np.flatnonzero(skey[1:] == skey[:-1])
        if dup.size:
            c0, c1 = order[dup[0]], order[dup[0] + 1]
            raise InputError(
                f"{self.name}: edge ({vert[c0]}, {nxt[c0]}) is used twice in the same direction "
                f"by faces {face[c0]} and {face[c1]}: the mesh is non-manifold or inconsistently "
                "oriented"
            )
        twin_key = nxt * n + vert
        pos = np.clip(np.searchsorted(skey, twin_key), 0, len(skey) - 1)
        twin = np.where(skey[pos] == twin_key, order[pos], -1)
        return dict(face=face, local=local, vert=vert, nxt=nxt, prv=prv, twin=twin,
                    sorted_key=skey, order=order)

    def _corner_of_halfedge(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Corner whose outgoing half-edge is a -> b, or -1."""
        c = self._corners
        key = a * self.vertex_count + b
        pos = np.clip(np.searchsorted(c["sorted_key"], key), 0, len(c["sorted_key"]) - 1)
        return np.where(c["sorted_key"][pos] == key, c["order"][pos], -1)

    # ------------------------------------------------------------------ edges, boundary
    @cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) int, each undirected edge once, lower index first, sorted."""
        c = self._corners
        pairs = np.sort(np.stack([c["vert"], c["nxt"]], axis=1), axis=1)
        return unique_rows(pairs)

    @cached_property
    def _interior_corners(self) -> np.ndarray:
        c = self._corners
        return np.flatnonzero(c["twin"] > np.arange(len(c["twin"])))

    @cached_property
    def interior_edge_faces(self) -> np.ndarray:
        """(i, 2) int, the two faces on either side of every interior edge."""
        c, corner = self._corners, self._interior_corners
        return np.stack([c["face"][corner], c["face"][c["twin"][corner]]], axis=1)

    @cached_property
    def interior_edges(self) -> np.ndarray:
        """(i, 2) int, the vertices of every interior edge, in the order of
        `interior_edge_faces`."""
        c, corner = self._corners, self._interior_corners
        return np.stack([c["vert"][corner], c["nxt"][corner]], axis=1)

    @cached_property
    def mean_edge_length(self) -> float:
        e = self.edges
        return float(np.linalg.norm(self.vertices[e[:, 0]] - self.vertices[e[:, 1]], axis=1).mean())

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """(b, 2) int, boundary half-edges oriented as in their face."""
        c = self._corners
        mask = c["twin"] < 0
        return np.stack([c["vert"][mask], c["nxt"][mask]], axis=1)

    @cached_property
    def is_boundary_vertex(self) -> np.ndarray:
        """(n,) bool"""
        mask = np.zeros(self.vertex_count, bool)
        mask[self.boundary_edges.ravel()] = True
        return mask

    @cached_property
    def valence(self) -> np.ndarray:
        """(n,) int, number of edges at each vertex."""
        return np.bincount(self.edges.ravel(), minlength=self.vertex_count)

    @cached_property
    def irregular_vertices(self) -> np.ndarray:
        """(k,) int, interior vertices whose valence is not 4 (singularities of the net)."""
        return np.flatnonzero(~self.is_boundary_vertex & (self.valence != 4) & (self.valence > 0))

    # ------------------------------------------------------------------ families
    @cached_property
    def _face_parity(self) -> np.ndarray:
        """(f,) int 0/1 per face so that local edge j of a quad has family (j + parity) % 2.

        Found by propagating across shared edges along a spanning forest of the quad
        adjacency graph (vectorized by pointer doubling); non-quads get parity 0.
        """
        c = self._corners
        nf = len(self.face_sizes)
        isquad = self.face_sizes == 4
        inner = (c["twin"] >= 0) & isquad[c["face"]]
        inner &= isquad[c["face"][np.maximum(c["twin"], 0)]]
        f, g = c["face"][inner], c["face"][c["twin"][inner]]
        # parity of the step f -> g: r_g = r_f + j_f + j_g (mod 2)
        flip = (c["local"][inner] + c["local"][c["twin"][inner]]) % 2
        return tree_parity(nf, f, g, flip)

    @cached_property
    def edge_family(self) -> np.ndarray:
        """(n_corners,) int, family (0/1) of the half-edge leaving each corner; -1 off quads."""
        c = self._corners
        fam = (c["local"] + self._face_parity[c["face"]]) % 2
        return np.where(self.face_sizes[c["face"]] == 4, fam, -1)

    # ------------------------------------------------------------------ stars
    @cached_property
    def _star_data(self) -> tuple[np.ndarray, np.ndarray]:
        c = self._corners
        n = self.vertex_count
        # successor of a corner around its vertex (counter-clockwise): the corner at the same
        # vertex whose outgoing edge is this corner's incoming edge reversed.
        succ = self._corner_of_halfedge(c["vert"], c["prv"])
        count = np.bincount(c["vert"], minlength=n)
        candidate = ~self.is_boundary_vertex & (count == 4) & (self.valence == 4)
        # one corner per candidate vertex, preferably in a quad (for the family labels)
        fam = self.edge_family
        pref = np.where(fam >= 0, 0, 1)
        order = np.lexsort((pref, c["vert"]))
        first = order[np.searchsorted(c["vert"][order], np.arange(n))[candidate]]
        ring_corners = [first]
        for _ in range(3):
            ring_corners.append(succ[ring_corners[-1]])
        ring = np.stack(ring_corners, axis=1)
        closed = np.all(ring >= 0, axis=1)
        closed[closed] &= succ[ring[closed, 3]] == ring[closed, 0]
        ring = ring[closed]
        centre = np.flatnonzero(candidate)[closed]
        nbrs = c["nxt"][ring]
        rotate = fam[ring[:, 0]] == 1
        nbrs[rotate] = np.roll(nbrs[rotate], -1, axis=1)
        stars = np.concatenate([centre[:, None], nbrs], axis=1)
        star_of_vertex = np.full(n, -1)
        star_of_vertex[centre] = np.arange(len(centre))
        return stars, star_of_vertex

    @property
    def stars(self) -> np.ndarray:
        """(s, 5) int, regular vertex stars ``[v, v1, v2, v3, v4]`` (see module notes)."""
        return self._star_data[0]

    @property
    def star_of_vertex(self) -> np.ndarray:
        """(n,) int, index into `stars` of the star centred at each vertex, or -1."""
        return self._star_data[1]

    # ------------------------------------------------------------------ polylines
    @cached_property
    def polylines(self) -> Polylines:
        """Parameter polylines of both families.

        A polyline runs straight through regular vertices (and along the boundary through
        boundary vertices of valence 3) and ends at boundary corners, where it meets the
        boundary, or at irregular vertices.
        """
        c = self._corners
        e = self.edges
        n = self.vertex_count
        ne = len(e)
        # directed edges: d in [0, ne) is e[d,0] -> e[d,1]; d + ne is the reverse
        tail = np.concatenate([e[:, 0], e[:, 1]])
        head = np.concatenate([e[:, 1], e[:, 0]])
        dkey = tail * n + head
        dorder = np.argsort(dkey)
        stars = self.stars
        # through-going pairs at regular vertices: (v1 -> v) continues as (v -> v3), etc.
        # ... and along the boundary through boundary vertices of valence 3
        s, bt = stars, self.boundary_triples
        ins = np.concatenate([s[:, 1], s[:, 3], s[:, 2], s[:, 4], bt[:, 0], bt[:, 2]])
        outs = np.concatenate([s[:, 3], s[:, 1], s[:, 4], s[:, 2], bt[:, 2], bt[:, 0]])
        mid = np.concatenate([np.tile(s[:, 0], 4), bt[:, 1], bt[:, 1]])
        d_in = dorder[np.searchsorted(dkey[dorder], ins * n + mid)]
        d_out = dorder[np.searchsorted(dkey[dorder], mid * n + outs)]
        successor = np.full(2 * ne, -1)
        successor[d_in] = d_out
        cut = break_cycles(successor)
        predecessor = np.full(2 * ne, -1)
        predecessor[cut[cut >= 0]] = np.flatnonzero(cut >= 0)
        start, rank = pointer_jump(predecessor)
        end, _ = pointer_jump(cut)
        # A chain and its reverse are the same polyline: keep the direction in which the
        # chain's smallest undirected edge is traversed forwards.
        undirected = np.arange(2 * ne) % ne
        min_edge = np.full(2 * ne, ne)
        np.minimum.at(min_edge, start, undirected)
        forward = np.zeros(2 * ne, bool)
        hit = undirected == min_edge[start]
        forward[start[hit]] = np.arange(2 * ne)[hit] < ne
        ids = np.flatnonzero(forward[start])
        ids = ids[np.lexsort((rank[ids], start[ids]))]
        groups = np.split(ids, np.flatnonzero(np.diff(start[ids])) + 1)
        # family of each directed edge, from an adjacent quad
        fam_dir = np.full(2 * ne, -1)
        corner_d = dorder[np.searchsorted(dkey[dorder], c["vert"] * n + c["nxt"])]
        fam_dir[corner_d] = self.edge_family
        reverse = np.r_[np.arange(ne) + ne, np.arange(ne)]
        fam_dir = np.where(fam_dir >= 0, fam_dir, fam_dir[reverse])
        loop = successor[end] == start  # the cut edge closes the chain into a loop
        vertices = [np.r_[tail[g[0]], head[g[:-1]] if loop[g[0]] else head[g]] for g in groups]
        return Polylines(
            vertices=vertices,
            family=np.array([fam_dir[g[0]] for g in groups], dtype=np.int64),
            closed=np.array([bool(loop[g[0]]) for g in groups], dtype=bool),
        )

    # ------------------------------------------------------------------ fairness stencils
    @cached_property
    def boundary_triples(self) -> np.ndarray:
        """(b, 3) int, consecutive boundary vertices (a, b, c) with b of valence 3."""
        be = self.boundary_edges
        n = self.vertex_count
        nxt = np.full(n, -1)
        nxt[be[:, 0]] = be[:, 1]
        a, b = be[:, 0], be[:, 1]
        cc = nxt[b]
        ok = (cc >= 0) & (self.valence[b] == 3)
        return np.stack([a[ok], b[ok], cc[ok]], axis=1)

    def neighbours(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Neighbour lists as CSR: (indptr, indices) for the given vertex ids."""
        e = self.edges
        adj = sp.coo_matrix(
            (np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
            shape=(self.vertex_count,) * 2,
        ).tocsr()
        sub = adj[v]
        return sub.indptr, sub.indices

    def __repr__(self) -> str:
        return (f"QuadMesh({self.name!r}, vertices={self.vertex_count}, faces={len(self.face_sizes)},"
                f" stars={len(self.stars)})")


# the cached properties of a `QuadMesh` that depend on its vertex positions (the others
# are its combinatorics, which `with_vertices` shares)
_GEOMETRIC_CACHE = ("face_areas", "mean_edge_length")


def load_mesh(path: str | os.PathLike) -> QuadMesh:
    """Read a quad mesh from OBJ (the only format that keeps polygons exactly)."""
    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise InputError(f"{path}: quad meshes are read from OBJ files (got {path.suffix or 'no suffix'})")
    return QuadMesh.from_obj(path)
