"""Candidates that end at the same net: two solves of one net (CMC on a saddle ending at the
minimal surface, a sweep of mold tolerances) are found in the order of the study, so
that a later candidate takes the earlier one's molds and strips instead of its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .definition import Candidate, Study
from .result import CandidateResult

if TYPE_CHECKING:  # imported where used: a study pulls in every stage only when it runs
    from ..net.mesh import QuadMesh

__all__ = ["SAME_NET_TOLERANCE", "same_net", "twin_of", "shared_solve"]


#: Two candidates end at the same net when they share the combinatorics and every vertex
#: lies within this fraction of the panel size of its counterpart (10 micrometres on a 1 m
#: panel: two solves of one net, held to the design by a bound, end this close)
SAME_NET_TOLERANCE = 1e-5


def same_net(a: QuadMesh, b: QuadMesh, tolerance: float) -> bool:
    """Whether two meshes are the same net: the same faces (same vertex order) and every
    vertex within `tolerance` (model units) of its counterpart.

    Examples
    --------
    >>> from fabplan.net.mesh import QuadMesh
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    >>> a, b = QuadMesh(X, [[0, 1, 2, 3]]), QuadMesh(X + 1e-9, [[0, 1, 2, 3]])
    >>> same_net(a, b, 1e-6), same_net(a, QuadMesh(X, [[1, 2, 3, 0]]), 1e-6)
    (True, False)
    """
    if a.vertex_count != b.vertex_count or not np.array_equal(a.face_sizes, b.face_sizes):
        return False
    if not np.array_equal(a.face_indices, b.face_indices):
        return False
    return bool(np.abs(a.vertices - b.vertices).max(initial=0.0) <= tolerance)


def twin_of(i: int, candidates: list[Candidate], nets: list[QuadMesh | None],
            twins: list[int | None], study: Study) -> int | None:
    """The earlier candidate whose net candidate `i` ended at, or None.

    Candidates are compared in the order of the study, each with the earlier ones that
    are options of their own (no twin, or a twin planned at another mold tolerance). Of
    those that ended at the same net (`same_net` within `SAME_NET_TOLERANCE` of the panel
    size), one at candidate `i`'s mold tolerance comes first: its molds and strips are
    `i`'s; else the first, whose strips are `i`'s.

    Parameters
    ----------
    i : the candidate's index in `candidates` (the study's order).
    nets : solved net (its mesh) of every candidate up to `i` (None for a failed one).
    twins : what this function gave for every candidate before `i`.
    """
    net = nets[i]
    if net is None:
        return None
    tolerance = [study.mold_tolerance_of(c) for c in candidates[:i + 1]]
    own = [j for j, t in enumerate(twins[:i]) if t is None or tolerance[t] != tolerance[j]]
    size = study.panel_size_of(candidates[i])
    same = [j for j in own if (other := nets[j]) is not None and
            same_net(other, net, SAME_NET_TOLERANCE * size)]
    same.sort(key=lambda j: tolerance[j] != tolerance[i])
    return same[0] if same else None


def shared_solve(solved: CandidateResult, candidate: Candidate) -> CandidateResult:
    """The solved half of `candidate` taken from another candidate's (`solved`) with the
    same `Candidate.solve_key`: the same net, no seconds of its own (or the same failure)."""
    if solved.failed:
        return CandidateResult(candidate, error=solved.error, reasons=list(solved.reasons))
    return CandidateResult(candidate, metrics={"seconds": {"layout": 0.0, "optimize": 0.0}},
                           net=solved.net, singular_points=solved.singular_points)
