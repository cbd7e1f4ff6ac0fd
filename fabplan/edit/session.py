"""An editing session: one net, its handles and pins, one solver kept alive, undo and redo.

The session is the document the pages and scripts of one `fabplan edit` server work on.
Its commands are not thread-safe: the server runs them one at a time on its worker thread
(`fabplan.edit.command_queue.CommandQueue`).

A drag moves handles (a vertex dragged becomes a handle) and solves with
`fabplan.solve.edit.NetEditor.solve_drag`: the net shown is always a solved one, the last
good one when a solve fails. The drags of one gesture (pointer down to up) make one step
of the undo history; each drag of a script is a step of its own.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.obj import format_obj
from ..io.output import write_texts
from ..io.records import json_text
from ..io.units import MM_PER_UNIT
from ..net.measure import measure_net
from ..net.mesh import QuadMesh
from ..net.view import net_scene
from ..solve.edit import DragResult, NetEditor
from ..solve.net_types import get_net
from ..solve.optimize import check_net_input, solved_parameters
from ..solve.reference import ReferenceSurface
from ..solve.region import RegionNet, region_net
from ..solve.solver import SolverSettings
from .record import EDIT_KEY, edit_section

__all__ = ["EditOptions", "EditSession", "Update"]


@dataclass
class EditOptions:
    """What a session solves for and how long it may take.

    Attributes
    ----------
    net : net type name (`fabplan.solve.net_types.NETS`).
    angle : prescribed intersection angle (degrees) of isogonal types, or None.
    radius : prescribed Meusnier radius (model units) of constant-radius types, or None.
    units : model units (a `fabplan.io.units.MM_PER_UNIT` key), for the page's scales.
    tolerance : a solve is converged when every hard residual is below this, in mean
        edges (the spheres: distance of each vertex from its star's sphere).
    max_iterations, max_seconds : the budget of one drag's solve.
    influence : the radius, in mean edges, over which the net starts by following a
        dragged handle (`fabplan.solve.edit.NetEditor.solve_drag`); 0 for none.
    region : vertices farther than this (mean edges) from every handle are held where
        they are while the handles are dragged: the solve works on the region around
        them (on a large net several times faster), the rest of the net stays as it is
        (and stays solved). The region moves with the handles. 0: the whole net.
    smooth, smooth_fade : the weight of the fairness of each drag's move at its start
        (`fabplan.solve.constraints.DisplacementFairness`), and the factor it fades by
        with every step (gone below a thousandth): the net follows a handle as a smooth
        membrane instead of bending the faces around it. 0: none.
    """

    net: str = "snet"
    angle: float | None = None
    radius: float | None = None
    units: str = "m"
    tolerance: float = 1e-6
    max_iterations: int = 40
    max_seconds: float | None = 5.0
    influence: float = 12.0
    region: float = 24.0
    smooth: float = 3.0
    smooth_fade: float = 0.1

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Update:
    """The outcome of a drag: the solve's `DragResult` and the session's step number."""

    seq: int
    result: DragResult
    solved_targets: dict

    def to_json(self) -> dict:
        return {"seq": self.seq, **self.result.to_json(),
                "targets": {str(k): [float(c) for c in v] for k, v in self.solved_targets.items()}}


@dataclass
class _Snapshot:
    vertices: np.ndarray
    handles: dict
    pins: frozenset
    report: tuple          # status, residual, message, where of the net


@dataclass
class _Gesture:
    key: str
    before: _Snapshot
    targets: dict = field(default_factory=dict)
    result: DragResult | None = None
    drags: int = 0


class EditSession:
    """A net being edited.

    Parameters
    ----------
    mesh : the net as opened.
    options : `EditOptions`.
    reference : the surface closeness pulls towards at the start of every solve and the
        deviation colours measure from; default: the net as opened.
    handles : (h,) int, vertices that are handles from the start (at their positions).
    pins : (p,) int, vertices held where they are.
    history : the edit history the net was saved with (continued).
    source : where the net came from (a file name), for the record.

    Examples
    --------
    >>> import fabplan
    >>> net = fabplan.QuadMesh.from_obj(fabplan.data_path("cmc1.obj"))
    >>> session = EditSession(net, EditOptions("snet"))
    >>> before = session.vertices.copy()
    >>> target = before[120] + [0.0, 0.0, 0.02]
    >>> update = session.drag({120: target})
    >>> update.result.status, bool((session.vertices[120] == target).all())
    ('converged', True)
    >>> session.undo(), bool((session.vertices == before).all())
    (True, True)
    """

    def __init__(self, mesh: QuadMesh, options: EditOptions, *,
                 reference: ReferenceSurface | None = None,
                 handles: Any = (), pins: Any = (), history: list | None = None,
                 source: str = "") -> None:
        check_net_input(mesh)
        get_net(options.net)
        self.options = options
        self.mesh = mesh
        self.source = source or mesh.name
        self.vertices = mesh.vertices.copy()
        self._checked(np.concatenate([np.ravel(handles), np.ravel(pins)]).astype(np.int64))
        self.handles: dict[int, np.ndarray] = {int(i): self.vertices[int(i)].copy()
                                               for i in np.ravel(handles)}
        self.pins: set[int] = {int(i) for i in np.ravel(pins)} - set(self.handles)
        self._reference = reference
        self.deviation_from = "the reference" if reference is not None else "the net as opened"
        self.centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
        self.history: list[dict] = list(history or [])
        self._undo: list[_Snapshot] = []
        self._redo: list[_Snapshot] = []
        self._editor: NetEditor | None = None
        self._region: tuple[list[int], np.ndarray, float] | None = None
        self._part: RegionNet | None = None          # what the editor solves
        self._solved = self.vertices                 # the net of the last accepted solve
        self._gesture: _Gesture | None = None
        self.seq = 0                   # drags solved
        self.changes = 0               # changes of the net, handles or pins
        self.saved_changes = 0         # `changes` when last saved
        self.last: DragResult | None = None
        self.status, self.residual, self.message = "not solved", float("nan"), ""
        self.where = np.zeros(0, np.int64)
        self._settle()
        self._opened = self._snapshot()

    # ------------------------------------------------------------------ state
    @property
    def reference(self) -> ReferenceSurface:
        """The reference surface (built from the opened net on first use)."""
        if self._reference is None:
            self._reference = ReferenceSurface.from_mesh(self.mesh)
        return self._reference

    @property
    def net(self) -> QuadMesh:
        """The current net."""
        return self.mesh.with_vertices(self.vertices)

    @property
    def unsaved(self) -> bool:
        return self.changes != self.saved_changes

    def _checked(self, ids: np.ndarray) -> np.ndarray:
        bad = ids[(ids < 0) | (ids >= self.mesh.vertex_count)]
        if bad.size:
            raise InputError(f"vertex {int(bad[0])} does not exist (the net has "
                             f"{self.mesh.vertex_count} vertices, numbered from 0)")
        return ids

    def _snapshot(self) -> _Snapshot:
        return _Snapshot(self.vertices.copy(), {k: v.copy() for k, v in self.handles.items()},
                         frozenset(self.pins),
                         (self.status, self.residual, self.message, self.where.copy()))

    def _restore(self, snap: _Snapshot) -> None:
        """Go to a state seen before, as it was (solved then: no solve now)."""
        self.vertices = snap.vertices.copy()
        self.handles = {k: v.copy() for k, v in snap.handles.items()}
        self.pins = set(snap.pins)
        self.status, self.residual, self.message, where = snap.report
        self.where = where.copy()
        self._editor = None

    def _editor_now(self) -> NetEditor:
        """The solver for the current held set, built on the current net when the held set
        changed (its pattern comes from the cache when this set was held before). It
        solves the part of the net that can move (`fabplan.solve.region.region_net`):
        with a region, the faces near the handles, not the whole net with the rest held."""
        if self._editor is None:
            o = self.options
            n = self.mesh.vertex_count
            moving = np.ones(n, bool)
            moving[sorted(self.pins)] = False
            self._region = None
            if self.handles and o.region > 0:
                centres = np.array([self.vertices[k] for k in sorted(self.handles)])
                radius = o.region * self.mesh.mean_edge_length
                moving &= np.min(np.linalg.norm(self.vertices[:, None, :] - centres[None], axis=2),
                                 axis=1) <= radius
                self._region = (sorted(self.handles), centres, radius)
            moving[sorted(self.handles)] = True
            part = self._part = region_net(self.mesh, self.vertices, moving)
            # the tolerance is in mean edges of the whole net, the part's solver measures
            # in its own
            scale = self.mesh.mean_edge_length / part.mesh.mean_edge_length
            self._editor = NetEditor(
                part.mesh, o.net, handles=part.local(sorted(self.handles)), fixed=part.held,
                angle=o.angle, radius=o.radius, reference=self.reference,
                settings=SolverSettings(tolerance=o.tolerance * scale,
                                        max_iterations=o.max_iterations, multilevel=False),
                smooth=o.smooth > 0, closeness=False)
        return self._editor

    def _solve(self, targets: dict) -> DragResult:
        """Solve a drag ({net vertex id: (3,) float}) on the part, in the net's terms."""
        editor, part, o = self._editor_now(), self._part, self.options
        assert part is not None
        local = dict(zip(part.local(list(targets)).tolist(), targets.values(), strict=True))
        edge = self.mesh.mean_edge_length
        result = editor.solve_drag(local, max_iterations=o.max_iterations,
                                   max_seconds=o.max_seconds, influence=o.influence * edge,
                                   smooth=o.smooth, smooth_fade=o.smooth_fade)
        result.residual *= editor.solver.length_scale / edge
        result.where = part.vertices[result.where]
        if result.accepted:
            X = self.vertices.copy()
            X[part.vertices] = editor.vertices
            self._solved = X
        return result

    def _region_holds(self, targets: dict) -> bool:
        """Whether the solve region still suits the handles going to `targets`: they stay
        within a third of the region's radius of where it was centred."""
        if self._region is None:
            return not (self.handles and self.options.region > 0)
        ids, centres, radius = self._region
        if ids != sorted(self.handles):
            return False
        moved = [np.linalg.norm(targets[k] - centres[ids.index(k)]) for k in targets if k in ids]
        return bool(max(moved, default=0.0) <= radius / 3)

    def _settle(self) -> None:
        """Solve the net as it stands (the net opened, or after undo): the page starts
        from a solved net, or says why the net is not one."""
        self._take(self._solve({}))

    def _take(self, result: DragResult) -> None:
        self.last = result
        if result.accepted:
            self.vertices = self._solved
            self.status, self.residual, self.message = "converged", result.residual, ""
            self.where = np.zeros(0, np.int64)
        else:
            # the net stays the last good one; the status says why the drag was refused
            self.status, self.message, self.where = result.status, result.message, result.where
            self.residual = result.residual

    # ------------------------------------------------------------------ commands
    def drag(self, targets: dict, *, gesture: str | None = None) -> Update:
        """Move handles to targets ({vertex id: (3,) float}) and solve; a vertex not yet a
        handle becomes one. Drags with the same `gesture` key make one undo step (a
        gesture ends with `release` or a drag of another key); without a key, every drag
        is a step of its own."""
        targets = {int(k): np.asarray(v, dtype=np.float64).reshape(3) for k, v in targets.items()}
        self._checked(np.array(list(targets), dtype=np.int64))
        if not all(np.isfinite(v).all() for v in targets.values()):
            raise InputError("a drag target has a non-finite coordinate")
        if self._gesture is not None and self._gesture.key != gesture:
            self.release()
        if self._gesture is None:
            self._gesture = _Gesture(gesture or "", self._snapshot())
        new = [k for k in targets if k not in self.handles]
        if new:
            for k in new:
                self.handles[k] = self.vertices[k].copy()
                self.pins.discard(k)
            self._editor = None
        if self._editor is not None and not self._region_holds(targets):
            self._editor = None
        result = self._solve(targets)
        self._take(result)
        if result.accepted:
            for k, v in targets.items():
                self.handles[k] = v.copy()
            self.changes += 1
        self.seq += 1
        g = self._gesture
        g.targets.update(targets)
        g.result, g.drags = result, g.drags + 1
        update = Update(self.seq, result, targets)
        if gesture is None:
            self.release()
        return update

    def release(self) -> None:
        """End the current gesture: its drags become one step of the undo history."""
        g, self._gesture = self._gesture, None
        if g is None:
            return
        changed = not np.array_equal(g.before.vertices, self.vertices) or \
            set(g.before.handles) != set(self.handles)
        if changed:
            self._undo.append(g.before)
            self._redo.clear()
        self._log("drag", vertices=sorted(g.targets), targets=[g.targets[k].tolist() for k in
                                                               sorted(g.targets)],
                  drags=g.drags, status=g.result.status if g.result else "",
                  residual=g.result.residual if g.result else None, changed=changed)

    def set_role(self, vertex: int, role: str) -> None:
        """Make a vertex a ``"handle"``, a ``"pin"`` (held where it is) or ``"free"``."""
        if role not in ("handle", "pin", "free"):
            raise InputError(f"a vertex's role is handle, pin or free, not {role!r}")
        vertex = int(self._checked(np.array([vertex], dtype=np.int64))[0])
        self.release()
        now = "handle" if vertex in self.handles else "pin" if vertex in self.pins else "free"
        if now == role:
            return
        self._undo.append(self._snapshot())
        self._redo.clear()
        self.handles.pop(vertex, None)
        self.pins.discard(vertex)
        if role == "handle":
            self.handles[vertex] = self.vertices[vertex].copy()
        elif role == "pin":
            self.pins.add(vertex)
        self._editor = None
        self.changes += 1
        self._log(role, vertices=[vertex])

    def undo(self) -> bool:
        """Go back one step; False when there is none."""
        self.release()
        if not self._undo:
            return False
        self._redo.append(self._snapshot())
        self._restore(self._undo.pop())
        self._after_jump("undo")
        return True

    def redo(self) -> bool:
        """Go forward one step undone; False when there is none."""
        self.release()
        if not self._redo:
            return False
        self._undo.append(self._snapshot())
        self._restore(self._redo.pop())
        self._after_jump("redo")
        return True

    def reset(self) -> None:
        """Back to the net, handles and pins as opened (a step that can be undone)."""
        self.release()
        self._undo.append(self._snapshot())
        self._redo.clear()
        self._restore(self._opened)
        self._after_jump("reset")

    def _after_jump(self, action: str) -> None:
        self.changes += 1
        self._log(action)

    def _log(self, action: str, **detail: Any) -> None:
        self.history.append({"action": action, "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
                             **detail})

    # ------------------------------------------------------------------ output
    def record(self) -> dict:
        """The JSON record of the current net: its measured properties (`measure_net`,
        against the reference) and, under ``edit``, its handles, pins and history."""
        net = self.net
        properties = measure_net(net, reference=self.reference)
        properties["units"] = self.options.units
        parameters = solved_parameters(self._editor_now().solver)
        return {
            "net": get_net(self.options.net).name,
            "parameters": parameters,
            "status": self.status if self.status != "not solved" else "stagnated",
            "message": self.message,
            "properties": properties,
            EDIT_KEY: edit_section(self.source, self.options.to_json(), self.handles, self.pins,
                                   self.history),
        }

    def save(self, path: str | Path) -> tuple[Path, Path]:
        """Write the net as OBJ and its record as JSON beside it (same name, ``.json``),
        both or neither (`fabplan.io.output.write_texts`)."""
        self.release()
        path = Path(path)
        json_path = path.with_suffix(".json")
        record = self.record()
        header = (f"fabplan {record['net']} net edited from {Path(self.source).name}; "
                  f"status {record['status']}; handles and history in {json_path.name}")
        write_texts({path: format_obj(self.vertices, self.mesh.faces, header),
                     json_path: json_text(record)})
        self.saved_changes = self.changes
        self._log("save", file=str(path))
        return path, json_path

    def state(self) -> dict:
        """What a page or script needs to know besides the positions."""
        return {
            "seq": self.seq, "status": self.status, "residual": self.residual,
            "message": self.message, "where": [int(i) for i in self.where],
            "last": None if self.last is None else self.last.to_json(),
            "handles": {str(k): v.tolist() for k, v in sorted(self.handles.items())},
            "pins": sorted(self.pins), "undo": len(self._undo), "redo": len(self._redo),
            "unsaved": self.unsaved, "net": get_net(self.options.net).name,
            "vertices": self.mesh.vertex_count, "faces": int(len(self.mesh.face_sizes)),
            "mean_edge": float(self.mesh.mean_edge_length), "options": self.options.to_json(),
        }

    def scene_json(self) -> dict:
        """The page's 3D view of the current net (`fabplan.net.view.net_scene`, with the
        reports' colour modes), centred where the net was opened."""
        net = self.net
        mm = MM_PER_UNIT.get(self.options.units, 1000.0)
        deviation = np.asarray(self.reference.distances(net.vertices)) * mm
        scene = net_scene(net, title=Path(self.source).name, units=self.options.units,
                          mm_per_unit=mm, deviation_mm=deviation,
                          deviation_from=self.deviation_from, line_turn=True)
        scene.centre = self.centre
        return scene.to_json()

    def vertex_normals(self) -> np.ndarray:
        """(n, 3) unit normals of the current net at its vertices (area-weighted face
        normals), the direction of a drag along the normal."""
        from ..net.geometry import face_normals

        net = self.net
        normals = face_normals(net.vertices, net) * net.face_areas[:, None]
        out = np.zeros((net.vertex_count, 3))
        np.add.at(out, net.face_indices, normals[net.corner_faces])
        length = np.linalg.norm(out, axis=1, keepdims=True)
        return np.divide(out, length, out=np.zeros_like(out), where=length > 0)
