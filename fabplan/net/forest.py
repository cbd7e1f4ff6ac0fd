"""Spanning forests over index arrays: parents, pointer jumping, parities along trees.

Used wherever a quantity is propagated over a graph without a Python loop per node:
face orientation of triangle meshes, combing direction fields, ordering polylines.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

__all__ = ["pointer_jump", "xor_to_root", "forest_parents", "tree_edge_values", "tree_parity",
           "break_cycles"]


def pointer_jump(successor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Follow successor pointers to the end of each chain.

    Parameters
    ----------
    successor : (m,) int, next element of each element's chain or -1 at a chain end.
        Chains must not be cycles.

    Returns
    -------
    end : (m,) int, last element of the chain through each element.
    steps : (m,) int, number of steps from each element to its chain end.
    """
    m = len(successor)
    end = np.where(successor < 0, np.arange(m), successor)
    steps = (successor >= 0).astype(np.int64)
    # Pointer doubling: log2(longest chain) rounds, each one vectorized.
    while True:
        nxt = end[end]
        moving = nxt != end
        if not moving.any():
            break
        steps = steps + np.where(moving, steps[end], 0)
        end = nxt
    return end, steps


def xor_to_root(parent: np.ndarray, step: np.ndarray) -> np.ndarray:
    """XOR of `step` along each element's path to its root, by pointer doubling.

    Parameters
    ----------
    parent : (m,) int, parent of each element in a forest, -1 at roots.
    step : (m,) int 0/1, value of the edge to the parent (ignored at roots).

    Returns
    -------
    (m,) int 0/1

    Examples
    --------
    >>> xor_to_root(np.array([-1, 0, 1, 2]), np.array([0, 1, 1, 1])).tolist()
    [0, 1, 0, 1]
    """
    parity = np.where(parent >= 0, step, 0).astype(np.int64)
    ptr = parent.copy()
    while np.any(ptr >= 0):
        act = ptr >= 0
        parity[act] ^= parity[ptr[act]]
        ptr[act] = ptr[ptr[act]]
    return parity


def forest_parents(count: int, f: np.ndarray, g: np.ndarray) -> np.ndarray:
    """(count,) int64, parent of every element in a breadth-first spanning forest of the
    pairs (f, g), rooted at the first element of every component; -1 at the roots."""
    f, g = np.asarray(f, np.int64), np.asarray(g, np.int64)
    adj = sp.coo_matrix((np.ones(len(f)), (f, g)), shape=(count, count)).tocsr()
    ncomp, label = csgraph.connected_components(adj, directed=False)
    root = count  # a virtual node joined to one element of every component
    first = np.full(ncomp, count)
    np.minimum.at(first, label, np.arange(count))
    rows, cols = np.r_[f, np.full(ncomp, root)], np.r_[g, first]
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(count + 1,) * 2).tocsr()
    _, pred = csgraph.breadth_first_order(graph, root, directed=False, return_predecessors=True)
    # scipy's predecessors are int32: keys like parent * count overflow from 46,341 on
    parent = pred[:count].astype(np.int64)
    parent[(parent == root) | (parent < 0)] = -1
    return parent


def tree_edge_values(count: int, f: np.ndarray, g: np.ndarray, value: np.ndarray,
                     parent: np.ndarray) -> np.ndarray:
    """(count,) int64, `value` of the pair (parent[x], x) for every x with a parent (the pair
    given in either order), else 0."""
    f, g, parent = (np.asarray(a, np.int64) for a in (f, g, parent))
    out = np.zeros(count, np.int64)
    key = np.r_[f * count + g, g * count + f]
    vals = np.r_[value, value]
    order = np.argsort(key)
    has = parent >= 0
    pos = np.searchsorted(key[order], parent[has] * count + np.flatnonzero(has))
    out[has] = vals[order[pos]]
    return out


def tree_parity(count: int, f: np.ndarray, g: np.ndarray, step: np.ndarray,
                parent: np.ndarray | None = None) -> np.ndarray:
    """(count,) int 0/1 labels with ``label[g] = label[f] ^ step`` along a spanning forest
    (`forest_parents` unless `parent` is given), by pointer doubling. Pairs off the
    forest are not checked here."""
    if parent is None:
        parent = forest_parents(count, f, g)
    return xor_to_root(parent, tree_edge_values(count, f, g, step, parent))


def break_cycles(successor: np.ndarray) -> np.ndarray:
    """Cut every cycle of a successor map at its smallest element (its predecessor points to -1)."""
    successor = successor.copy()
    m = len(successor)
    has_pred = np.zeros(m, bool)
    has_pred[successor[successor >= 0]] = True
    # Elements reachable from a chain start are on paths; the rest lie on cycles.
    on_path = np.zeros(m, bool)
    frontier = np.flatnonzero(~has_pred)
    while frontier.size:
        on_path[frontier] = True
        nxt = successor[frontier]
        frontier = nxt[(nxt >= 0)]
        frontier = frontier[~on_path[frontier]]
    cyc = np.flatnonzero(~on_path)
    if cyc.size:
        graph = sp.coo_matrix((np.ones(cyc.size), (cyc, successor[cyc])), shape=(m, m))
        _, label = csgraph.connected_components(graph.tocsr(), directed=False)
        smallest = np.full(label.max() + 1, m)
        np.minimum.at(smallest, label[cyc], cyc)
        starts = smallest[np.unique(label[cyc])]
        successor[cyc[np.isin(successor[cyc], starts)]] = -1
    return successor
