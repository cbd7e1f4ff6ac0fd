"""An independent check of whether a quad net can be built, written without fabplan.

Given vertex positions and faces only (no fabplan function, no fabplan mesh), it finds:

- *darts*: quads whose four turns, in the quad's least-squares plane, do not all have one
  sign (a corner bent inwards, or a quad crossing itself);
- *lines doubling back*: at every interior vertex with four quads around it, the two
  lines through it (each neighbour continues to the one it shares no quad with) and
  the angle between consecutive edges of each, projected on the plane normal to the
  cross product of the star's diagonals;
- the ratio of consecutive edge lengths along those lines.

The corpus benchmark (`bench_corpus.py --hard`) and the tests judge fabplan's statuses by
it, so it must not share code with what it judges.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

__all__ = ["dart_quads", "interior_stars", "line_turns", "check"]


def dart_quads(X: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(d,) int, the quads whose turns in their best plane disagree in sign."""
    Q = X[np.asarray(quads)]                                  # (q, 4, 3)
    centred = Q - Q.mean(axis=1, keepdims=True)
    normal = np.linalg.svd(centred)[2][:, 2]                  # least-squares plane normal
    edges = np.roll(Q, -1, axis=1) - Q                        # corner i -> i + 1
    turns = np.einsum("qij,qj->qi", np.cross(np.roll(edges, 1, axis=1), edges), normal)
    scale = np.abs(turns).max(axis=1, keepdims=True) + 1e-300
    sign = np.sign(np.where(np.abs(turns) < 1e-12 * scale, 0.0, turns))
    positive, negative = (sign > 0).any(axis=1), (sign < 0).any(axis=1)
    return np.flatnonzero(positive & negative)


def interior_stars(faces: list, vertex_count: int) -> np.ndarray:
    """(s, 5) int, ``[v, a, b, c, d]`` for every vertex with exactly four faces and four
    neighbours, lines ``a - v - c`` and ``b - v - d``."""
    around: dict = defaultdict(list)
    neighbours: dict = defaultdict(set)
    for face in faces:
        n = len(face)
        for i, v in enumerate(face):
            before, after = face[i - 1], face[(i + 1) % n]
            around[int(v)].append((int(before), int(after)))
            neighbours[int(v)].update((int(before), int(after)))
    stars = []
    for v in range(vertex_count):
        if len(around[v]) != 4 or len(neighbours[v]) != 4:
            continue
        shares = defaultdict(set)
        for before, after in around[v]:
            shares[before].add(after)
            shares[after].add(before)
        a = min(neighbours[v])
        opposite = neighbours[v] - shares[a] - {a}
        if len(opposite) != 1:
            continue
        c = opposite.pop()
        b, d = sorted(neighbours[v] - {a, c})
        stars.append((v, a, b, c, d))
    return np.array(stars, dtype=np.int64).reshape(-1, 5)


def line_turns(X: np.ndarray, stars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Turn (degrees) and edge ratio (longer over shorter) of both lines at every star:
    (s, 2) each."""
    P = X[stars]
    v = P[:, 0]
    n = np.cross(P[:, 3] - P[:, 1], P[:, 4] - P[:, 2])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    turns, ratios = [], []
    for a, b in ((1, 3), (2, 4)):
        d0, d1 = v - P[:, a], P[:, b] - v
        l0, l1 = np.linalg.norm(d0, axis=1), np.linalg.norm(d1, axis=1)
        ratios.append(np.maximum(l0, l1) / np.maximum(np.minimum(l0, l1), 1e-300))
        d0 = d0 - np.sum(d0 * n, axis=1, keepdims=True) * n
        d1 = d1 - np.sum(d1 * n, axis=1, keepdims=True) * n
        c = np.sum(d0 * d1, axis=1) / np.maximum(
            np.linalg.norm(d0, axis=1) * np.linalg.norm(d1, axis=1), 1e-300)
        turns.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.stack(turns, axis=1), np.stack(ratios, axis=1)


def check(X: np.ndarray, faces: list, *, max_turn_deg: float = 90.0) -> dict:
    """Darts, line turns and edge ratios of a net: a JSON-ready record with ``buildable``
    (no dart, no line turning more than `max_turn_deg`)."""
    X = np.asarray(X, dtype=np.float64)
    quads = np.array([f for f in faces if len(f) == 4], dtype=np.int64).reshape(-1, 4)
    darts = dart_quads(X, quads) if len(quads) else np.zeros(0, np.int64)
    stars = interior_stars(faces, len(X))
    turn, ratio = line_turns(X, stars) if len(stars) else (np.zeros((0, 2)), np.ones((0, 2)))
    sharp = int(np.sum(turn > max_turn_deg))
    return {"darts": int(len(darts)), "sharp_turns": sharp,
            "turn_max": float(turn.max()) if turn.size else 0.0,
            "edge_ratio_max": float(ratio.max()) if ratio.size else 1.0,
            "buildable": not len(darts) and not sharp}
