"""Interactive editing of a net with handles (task B of the paper, section 3).

A `NetEditor` keeps one solver alive: the pattern of the normal equations and the
symbolic factorization are computed once, every drag step runs one iteration, and a
release runs a few more, as in the paper's editing loop (section 4.5). Another editor with
the same handles on the same net takes the pattern from `fabplan.solve.pattern`'s cache.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..net.mesh import QuadMesh
from .optimize import (
    build_solver,
    describe_unmet,
    solved_parameters,
    solver_normals,
    unmet_constraints,
)
from .solver import IterationRecord, SolverSettings

__all__ = ["NetEditor"]


class NetEditor:
    """Move handle vertices of a net and keep it a net of its type.

    Parameters
    ----------
    mesh : the net to edit (normally already optimized).
    net : net type name (see `fabplan.nets.NETS`).
    handles : (h,) int, the vertices the user drags; they are held where they are put.
    angle, radius, fixed, settings, coherent : as in `fabplan.optimize`.

    Examples
    --------
    >>> import fabplan
    >>> net = fabplan.QuadMesh.from_obj(fabplan.data_path("cmc1.obj"))
    >>> editor = NetEditor(net, "snet", handles=[120])
    >>> target = net.vertices[120] + [0.0, 0.0, 0.05]
    >>> _ = editor.drag({120: target})          # one iteration per drag step
    >>> editor.release()["converged"]           # converge on release
    True
    >>> bool((editor.vertices[120] == target).all())
    True
    """

    def __init__(self, mesh: QuadMesh, net: str, handles: npt.ArrayLike, *,
                 angle: float | None = None, radius: float | None = None,
                 fixed: npt.ArrayLike | None = None, settings: SolverSettings | None = None,
                 coherent: bool = False) -> None:
        self.handles = np.unique(np.asarray(handles, dtype=np.int64))
        held = np.union1d(np.asarray([] if fixed is None else fixed, dtype=np.int64), self.handles)
        self._mesh = mesh
        self.solver = build_solver(mesh, net, angle=angle, radius=radius, fixed=held,
                                   settings=settings, coherent=coherent)

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float, current vertex positions."""
        return self.solver.vertices

    @property
    def mesh(self) -> QuadMesh:
        """The current net."""
        return self._mesh.with_vertices(self.solver.vertices, normals=solver_normals(self.solver))

    def drag(self, targets: dict, iterations: int = 1) -> IterationRecord | None:
        """Put handles at new positions ({vertex id: (3,) float}) and run `iterations`."""
        ids = np.array(list(targets), dtype=np.int64)
        unknown = np.setdiff1d(ids, self.handles)
        if unknown.size:
            raise ValueError(f"vertex {unknown[0]} is not a handle of this editor")
        self.solver.set_vertices(ids, np.array([targets[i] for i in targets], dtype=np.float64))
        self.solver.run(iterations)
        return self.solver.history[-1] if self.solver.history else None

    def release(self, iterations: int | None = None) -> dict:
        """Iterate until converged (or `iterations` more, for a fixed interactive budget)
        and report whether the net type still holds with the handles where they are.

        Returns
        -------
        dict with ``converged`` (bool), ``status``, ``unmet`` ({family: residual} of the
        hard constraints above the tolerance), ``message`` and the net's ``parameters``.
        """
        status = self.solver.run(iterations)
        unmet = unmet_constraints(self.solver)
        return {
            "converged": not unmet,
            "status": status,
            "unmet": unmet,
            "message": "all constraints met" if not unmet else
                       f"cannot be met with the handles where they are: {describe_unmet(unmet)}",
            "parameters": solved_parameters(self.solver),
        }
