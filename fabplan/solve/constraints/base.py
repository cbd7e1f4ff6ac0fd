"""What every constraint family provides, and the state they read."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Constraint", "NetState", "VariableBlocks"]


@dataclass
class VariableBlocks:
    """Named variable blocks inside one flat vector.

    Attributes
    ----------
    blocks : dict name -> (offset, shape)
    size : total number of variables.
    """

    blocks: dict = field(default_factory=dict)
    size: int = 0

    def add(self, name: str, shape: tuple) -> None:
        if name in self.blocks:
            if self.blocks[name][1] != tuple(shape):
                raise ValueError(f"variable block {name!r} declared with two shapes")
            return
        self.blocks[name] = (self.size, tuple(shape))
        self.size += int(np.prod(shape))

    def __contains__(self, name: object) -> bool:
        return name in self.blocks

    def index(self, name: str) -> np.ndarray:
        """Global variable indices of a block, shaped like the block."""
        offset, shape = self.blocks[name]
        return offset + np.arange(int(np.prod(shape))).reshape(shape)

    def view(self, x: np.ndarray, name: str) -> np.ndarray:
        """A writable view of a block inside the flat vector ``x``."""
        offset, shape = self.blocks[name]
        return x[offset:offset + int(np.prod(shape))].reshape(shape)


@dataclass
class NetState:
    """Everything a constraint family reads while the solver runs (normalized units).

    Coordinates are translated to the centroid and divided by the mean edge length of the
    input, so that every residual is measured in mean edges.
    """

    mesh: object                   # fabplan.mesh.QuadMesh (combinatorics)
    stars: np.ndarray              # (s, 5) int, canonical labelling
    blocks: VariableBlocks
    x: np.ndarray                  # (N,) float, all variables
    length_scale: float            # model units per normalized unit
    origin: np.ndarray             # (3,) model coordinates of the normalized origin
    data: dict = field(default_factory=dict)  # per-iteration data shared between families

    @property
    def X(self) -> np.ndarray:
        """(n, 3) vertex positions (normalized), a view into ``x``."""
        return self.blocks.view(self.x, "vertices")

    def footpoints(self, reference, ids: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``reference.closest_points`` of the vertices `ids` (None: all) in model units:
        footpoints (k, 3), normals (k, 3), triangles (k,). Found once for all vertices
        per position of the net and reference, and shared: the closeness to a surface and
        a deviation limit from it ask for the same points every iteration."""
        cached = self.data.get("footpoints")
        if cached is None or cached[0] is not reference or not np.array_equal(cached[1], self.X):
            model = self.X * self.length_scale + self.origin
            cached = (reference, self.X.copy(), reference.closest_points(model))
            self.data["footpoints"] = cached
        foot, normal, triangle = cached[2]
        if ids is None:
            return foot, normal, triangle
        return foot[ids], normal[ids], triangle[ids]


class Constraint:
    """A family of residuals ``r(x) = 0`` with a fixed sparsity pattern.

    Subclasses set `name`, declare their variable blocks in `declare`, fill initial values
    of their own blocks in `initialize`, give the column pattern ``(m, k)`` once in
    `columns`, and return residuals ``(m,)`` and Jacobian values ``(m, k)`` in `evaluate`.
    `prepare` runs once per iteration before evaluation (rebasing, footpoints).
    Soft families (fairness, closeness) have ``hard = False``: they guide the solution and
    are not part of the convergence test; their weight fades as the solve goes on. A soft
    family may hold part of its rows longer: an attribute ``held`` (rows,) in [0, 1],
    set by `prepare`, gives those rows a slowly fading weight of their own on top (see
    `Fairness`). A soft family whose ``weight`` is not None is weighted by it instead
    (its owner fades it: `DisplacementFairness`).
    """

    name = "constraint"
    hard = True
    held: np.ndarray | None = None    # (rows,) in [0, 1]: rows a soft family holds longer
    weight: float | None = None       # a soft family's own row weight (it fades itself),
                                      # instead of the solver's fading one

    def declare(self, state: NetState) -> dict:
        """Variable blocks this family needs: name -> shape."""
        return {}

    def initialize(self, state: NetState) -> None:
        """Set initial values of the blocks this family owns."""

    def prepare(self, state: NetState) -> None:
        """Per-iteration update of constant data (runs before `evaluate`)."""

    def columns(self, state: NetState) -> np.ndarray:
        raise NotImplementedError

    def evaluate(self, state: NetState) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"
