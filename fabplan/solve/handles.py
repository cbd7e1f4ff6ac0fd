"""Held vertices and handles of a solve, read from the command line or from files.

`read_fixed` and `read_handles` read what a user typed or wrote; `handle_arrays` checks the
handles against the net (ids in range, targets finite and within its reach) and gives the
arrays the solve moves them with (`fabplan.solve.stages`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..net.mesh import QuadMesh

__all__ = ["read_fixed", "read_handles", "handle_arrays", "HANDLE_REACH"]


def read_fixed(spec: str | None, mesh: QuadMesh) -> np.ndarray:
    """Vertices to hold: ``"boundary"``, or a file of vertex ids (0-based, any separators)."""
    if spec is None:
        return np.zeros(0, dtype=np.int64)
    if spec == "boundary":
        return np.flatnonzero(mesh.is_boundary_vertex)
    path = Path(spec)
    if not path.is_file():
        raise InputError(f"{spec}: no such file (--fix takes 'boundary' or a file of vertex ids)")
    try:
        tokens = path.read_text(encoding="utf-8").replace(",", " ").split()
    except (UnicodeDecodeError, OSError):
        raise InputError(f"{spec}: not a text file of vertex ids") from None
    try:
        values = [int(t) for t in tokens]
    except ValueError:
        raise InputError(f"{spec}: vertex ids must be integers") from None
    return _vertex_ids(values, mesh, spec)


def _vertex_ids(values: list[int], mesh: QuadMesh, where: str) -> np.ndarray:
    """(k,) int64, vertex ids read from a file or an option, each checked to exist; an id
    too large for any integer array (2**64) is named as the others are."""
    try:
        ids = np.array(values, dtype=np.int64)
    except OverflowError:
        first = next(v for v in values if abs(v) >= 2**62)
        raise InputError(f"{where}: vertex {first} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)") from None
    bad = ids[(ids < 0) | (ids >= mesh.vertex_count)]
    if bad.size:
        raise InputError(f"{where}: vertex {bad[0]} does not exist (the mesh has "
                         f"{mesh.vertex_count} vertices, numbered from 0)")
    return ids


#: how far a handle may move a vertex from the net's bounding box, in net extents
HANDLE_REACH = 10.0


def handle_arrays(handles: dict | None, mesh: QuadMesh) -> tuple[np.ndarray, np.ndarray]:
    if not handles:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    ids = _vertex_ids(list(handles), mesh, "--handle")
    targets = np.array([np.asarray(handles[i], dtype=np.float64) for i in handles]).reshape(-1, 3)
    if not np.isfinite(targets).all():
        k = int(np.flatnonzero(~np.isfinite(targets).all(axis=1))[0])
        raise InputError(f"--handle {ids[k]}:{','.join(f'{c:g}' for c in targets[k])}: the target "
                         "must be finite coordinates")
    # a handle moves a vertex within the net's reach: farther than this many times the
    # net's extent from its bounding box is a typing or unit mistake
    low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    extent = float(np.linalg.norm(high - low))
    # along the farthest axis: a norm of 1e300 would overflow
    away = np.maximum(np.maximum(low - targets, targets - high), 0.0).max(axis=1)
    far = np.flatnonzero(away > HANDLE_REACH * extent)
    if far.size:
        k = far[0]
        raise InputError(f"--handle {ids[k]}:{','.join(f'{c:g}' for c in targets[k])}: the target "
                         f"lies {away[k]:.3g} from the net, more than {HANDLE_REACH:g} times its "
                         f"extent ({extent:.4g} model units, the diagonal of its bounding box)")
    return ids, targets


def read_handles(specs: list[str] | None) -> dict:
    """Handles from ``ID:X,Y,Z`` strings or files of ``ID X Y Z`` lines."""
    handles: dict = {}
    for spec in specs or []:
        path = Path(spec)
        lines = [spec]
        if ":" not in spec and path.is_file():
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except (UnicodeDecodeError, OSError):
                raise InputError(f"{spec}: not a text file of handles") from None
        for line in lines:
            line = line.split("#")[0].strip()
            if not line:
                continue
            parts = line.replace(":", " ").replace(",", " ").split()
            try:
                vid, xyz = int(parts[0]), [float(p) for p in parts[1:]]
            except (ValueError, IndexError):
                xyz = []
            if len(xyz) != 3:
                where = f"{spec}" if lines == [spec] else f"{spec}: line {line!r}"
                raise InputError(f"{where}: a handle is ID:X,Y,Z (or a file of 'ID X Y Z' lines)")
            handles[vid] = xyz
    return handles
