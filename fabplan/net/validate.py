"""The one check of a net read from a file, before any command computes with it."""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from ..io.inputs import check_coordinates, check_input_file
from ..io.units import units_warning
from .mesh import QuadMesh, load_mesh

__all__ = ["check_net", "load_net", "net_units_warning"]


def check_net(mesh: QuadMesh, *, quads: bool = True, manifold: bool = True) -> QuadMesh:
    """Refuse a net no fabplan command can compute with; return it unchanged otherwise.

    - finite coordinates of plausible magnitude, not all coincident
      (`fabplan.io.inputs.check_coordinates`),
    - no edge of zero length (two corners of a face at the same point),
    - with `quads`, a quad-dominant mesh (at least half of the faces are quads),
    - with `manifold`, every edge shared by at most two faces, consistently oriented.

    Parameters
    ----------
    mesh : the net.
    quads : require quads (measure, optimize, strips); molds takes any polygon panels.
    manifold : require a manifold, consistently oriented mesh.

    Raises
    ------
    InputError
        Naming the mesh and the first offending face or edge.

    Examples
    --------
    >>> tri = QuadMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]],
    ...                name="tri.obj")
    >>> check_net(tri)
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: tri.obj: face 0 is a triangle and only 0 of 2 faces are quads: \
a net is a quad mesh (quad-dominant)
    """
    check_coordinates(mesh.vertices, mesh.name)
    X, sizes, ptr, idx = mesh.vertices, mesh.face_sizes, mesh.face_indptr, mesh.face_indices
    face = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(idx)) - ptr[face]
    following = np.where(local == sizes[face] - 1, ptr[face], np.arange(len(idx)) + 1)
    a, b = idx, idx[following]
    length = np.linalg.norm(X[a] - X[b], axis=1)
    scale = float(np.ptp(X, axis=0).max())
    short = np.flatnonzero(length <= 1e-12 * scale)
    if short.size:
        c = short[0]
        raise InputError(f"{mesh.name}: edge ({a[c]}, {b[c]}) of face {face[c]} has zero length: "
                         f"vertices {a[c]} and {b[c]} coincide (duplicate vertices; merge them)")
    if quads:
        is_quad = sizes == 4
        if 2 * int(is_quad.sum()) < len(sizes):
            first = int(np.flatnonzero(~is_quad)[0])
            kind = {3: "a triangle"}.get(int(sizes[first]), f"a {int(sizes[first])}-gon")
            raise InputError(f"{mesh.name}: face {first} is {kind} and only {int(is_quad.sum())} "
                             f"of {len(sizes)} faces are quads: a net is a quad mesh "
                             "(quad-dominant)")
    if manifold:
        mesh.edges  # noqa: B018 -- building the edge table raises for non-manifold edges
    return mesh


def load_net(path: str | os.PathLike, *, quads: bool = True, manifold: bool = True) -> QuadMesh:
    """Read a net from OBJ and check it (`check_net`): the one way commands read a net."""
    check_input_file(path, "a quad mesh (OBJ file)")
    return check_net(load_mesh(path), quads=quads, manifold=manifold)


def net_units_warning(mesh: QuadMesh, units: str, *, strict: bool = False) -> str | None:
    """Whether the net's size fits the `units` it is read in (`fabplan.io.units.units_warning`
    on its median edge and its largest extent).

    Returns
    -------
    A warning for a size a building does not have, else None.

    Raises
    ------
    InputError
        With `strict` instead of the warning, and always for panels a factor 10 beyond
        `fabplan.io.units.PLAUSIBLE_PANEL_MM`, naming the likely unit.

    Examples
    --------
    >>> import numpy as np
    >>> u, v = np.meshgrid(np.arange(4.0) / 2, np.arange(3.0) / 2, indexing="ij")
    >>> net = QuadMesh.grid(np.stack([u, v, 0 * u], axis=-1), name="roof.obj")
    >>> net_units_warning(net, "mm")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: roof.obj: panels of 0.5 mm (median edge 0.5 mm) cannot be \
meant for fabrication: is the model in metres? Give --units m
    >>> net_units_warning(net, "m") is None
    True
    """
    edges = mesh.edges
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    return units_warning(mesh.name, units, panel=float(np.median(lengths)), extent=extent,
                         strict=strict)
