"""The sparsity pattern of the normal equations, built from the structure of the variables.

Row ``i`` of the Jacobian ``J`` adds ``J[i, p] J[i, q]`` to entry ``(p, q)`` of ``J^T J``.
The solver computes these products with one broadcast multiply per pair of a row's entries
and sums them into the upper triangle of ``J^T J`` with one `np.bincount`; a
`NormalPattern` says which entries the upper triangle has and where each product goes
(its *slot*). It depends only on the families' column patterns and on which variables are
free, so it is built once per topology and held set and kept in `pattern_cache`: the
candidates of a study that share a topology, a second solve on the same mesh and the
attempts of one `optimize` call reuse it.

Building it does not sort the products (12 million at 30k vertices). Variables come in
*nodes*, the rows of a two-dimensional variable block: a vertex's three coordinates, a
sphere's five coefficients. The entries of a family's rows fall into groups that name one
node in every row (the coordinates of a star's second vertex), so a row couples few node
pairs: a sphere row couples its vertex and its sphere, three node pairs for its 36
products. Only these node pairs are ranked. Which variable pairs inside a node pair occur
is a 64-bit mask (nodes are at most 8 wide), and the upper triangle and every product's
slot follow from the ranked node pairs and their masks by counting bits.

Where the compiled kernels are built (`fabplan.solve.kernels`), they build the same
arrays more directly: each row's columns gathered, made distinct and sorted, then every
product's column looked up in its row, a Jacobian row at a time (its products name few
rows of the pattern): a third of the numpy construction's time at 10k to 30k vertices.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from .constraints import VariableBlocks
from .kernels import compiled

__all__ = [
    "FamilyPattern",
    "NormalPattern",
    "PatternCache",
    "index_dtype",
    "normal_pattern",
    "pattern_cache",
    "pattern_key",
    "rank_keys",
    "variable_nodes",
]

MAX_NODE_WIDTH = 8          # variables per node: a node pair's variable pairs fit 64 bits
_CHUNK = 1 << 20            # elements of the temporaries: fresh memory is slow to touch

# popcount of every byte, and of its bits below bit b (at byte * 8 + b)
_POPCOUNT = np.unpackbits(np.arange(256, dtype=np.uint8)[:, None], axis=1).sum(axis=1).astype(np.uint8)
_RANK_BELOW = np.array([bin(v & ((1 << b) - 1)).count("1") for v in range(256) for b in range(8)],
                       dtype=np.uint8)
# the diagonal of a node w wide: bits 9 a for a < w
_DIAGONAL_BITS = np.array([sum(1 << (9 * a) for a in range(w)) for w in range(MAX_NODE_WIDTH + 1)],
                          dtype=np.uint64)


@dataclass(frozen=True)
class FamilyPattern:
    """Where one family's Jacobian entries land in the normal equations.

    A row with ``k`` entries gives the ``k (k + 1) / 2`` products of its entry pairs
    ``i <= j``; they are stored pair-major, ``(p, m)``, so that the pairs of entry ``i``
    come out of one broadcast multiply of column ``i`` with columns ``i..k-1``.

    Attributes
    ----------
    gradient_cols : (m, k) int, free-variable column of each entry, ``nfree`` if held.
    shape : (p, m), the family's block in the shared product buffer.
    multiplicity : (p, m) float, 2 where a row repeats a variable, else None.
    """

    gradient_cols: np.ndarray
    shape: tuple
    multiplicity: np.ndarray | None = None


@dataclass(frozen=True)
class NormalPattern:
    """The fixed sparsity of ``J^T J + mu I`` and the slot of every product.

    Attributes
    ----------
    families : one `FamilyPattern` per constraint family, in the solver's order.
    indptr, indices : (nfree + 1,), (nnz,) int, the upper triangle in CSR form (the lower
        triangle in CSC form), column indices sorted within each row.
    diagonal : (nfree,) int, positions of the diagonal entries in ``indices``.
    slots : (products,) int, every family's products' positions in ``indices``,
        concatenated; ``nnz`` for a product on a held variable.
    key : the `pattern_key` it was built for.
    shared : what linear solver backends build from the pattern alone, kept for the
        next solver of the pattern (see `fabplan.solve.linalg.SparseSPDSolver`).

    The index arrays are int32 when ``nnz`` allows it (`index_dtype`): the slots are the
    pattern's largest array, 12 million at 30k vertices.
    """

    families: tuple
    indptr: np.ndarray
    indices: np.ndarray
    diagonal: np.ndarray
    slots: np.ndarray
    key: bytes = b""
    shared: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def nnz(self) -> int:
        return len(self.indices)

    @property
    def nbytes(self) -> int:
        """Memory held by the pattern's arrays (and, roughly, what backends left in
        `shared`: a matrix of the pattern each)."""
        arrays = [self.indptr, self.indices, self.diagonal, self.slots]
        arrays += [a for f in self.families for a in (f.gradient_cols, f.multiplicity)
                   if a is not None]
        return sum(a.nbytes for a in arrays) + 16 * self.nnz * len(self.shared)


def index_dtype(nnz: int) -> type:
    """The integer type of a pattern's index arrays: int32 while the ``nnz + 1`` slots
    (the last for products on held variables) fit in it, int64 beyond.

    Examples
    --------
    >>> index_dtype(1000).__name__, index_dtype(2**31).__name__
    ('int32', 'int64')
    """
    return np.int32 if nnz < np.iinfo(np.int32).max else np.int64


def rank_keys(keys: np.ndarray, bound: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct keys and the position of every key among them.

    Parameters
    ----------
    keys : (n,) int64, values in ``[0, bound)``.
    bound : exclusive upper bound of the keys.

    Returns
    -------
    distinct : (u,) int64, the sorted distinct keys.
    position : (n,) int64, ``distinct[position] == keys``.

    Each key is packed with its index into one int64 and sorted (``np.sort`` is far
    faster than ``argsort`` or a search of tens of millions of keys); when key and index
    need more than 63 bits the keys are sorted in ranges of their high bits.

    Examples
    --------
    >>> distinct, position = rank_keys(np.array([7, 3, 7, 0]), 8)
    >>> distinct.tolist(), position.tolist()
    ([0, 3, 7], [2, 1, 2, 0])
    >>> [a.tolist() for a in rank_keys(np.zeros(0, dtype=np.int64), 8)]
    [[], []]
    """
    keys = np.asarray(keys, dtype=np.int64)
    n = len(keys)
    index_bits = max(1, (n - 1).bit_length())
    key_bits = max(1, (int(bound) - 1).bit_length())
    low_bits = min(key_bits, 63 - index_bits)
    position = np.empty(n, dtype=np.int64)
    distinct, found = [], 0
    high = keys >> low_bits
    for part in range(int(high.max()) + 1 if n else 0):
        mine = np.flatnonzero(high == part) if low_bits < key_bits else slice(None)
        # a copy, worked on in place (fresh memory is slow to touch)
        packed = keys.copy() if isinstance(mine, slice) else keys[mine]
        packed -= part << low_bits
        packed <<= index_bits
        packed |= np.arange(len(packed))
        packed.sort()
        low = packed >> index_bits
        new = np.empty(len(low), dtype=bool)
        new[:1] = True
        np.not_equal(low[1:], low[:-1], out=new[1:])
        rank = np.cumsum(new)
        rank += found - 1
        packed &= (1 << index_bits) - 1             # the keys' indices, in sorted order
        if isinstance(mine, slice):
            position[packed] = rank
        else:
            position[mine[packed]] = rank
        distinct.append(low[new] + (part << low_bits))
        found += int(rank[-1]) - found + 1 if len(rank) else 0
    return (np.concatenate(distinct) if distinct else np.zeros(0, dtype=np.int64)), position


def variable_nodes(blocks: VariableBlocks, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group the free variables into nodes.

    A node is a row of a two-dimensional variable block up to `MAX_NODE_WIDTH` wide (a
    vertex's coordinates, a sphere's coefficients); every other variable is a node of its
    own. Held variables are left out, so a node's free variables are consecutive columns.

    Parameters
    ----------
    blocks : the solver's variable blocks.
    free : (nfree,) int, sorted indices of the free variables.

    Returns
    -------
    node : (nfree,) int, node of each free column, non-decreasing from 0.
    first : (nodes,) int, first free column of each node.

    Examples
    --------
    >>> blocks = VariableBlocks()
    >>> blocks.add("vertices", (2, 3)); blocks.add("cosine", (1,))
    >>> node, first = variable_nodes(blocks, np.array([0, 1, 2, 3, 4, 5, 6]))
    >>> node.tolist(), first.tolist()
    ([0, 0, 0, 1, 1, 1, 2], [0, 3, 6])
    """
    whole = np.empty(blocks.size, dtype=np.int64)
    count = 0
    for offset, shape in sorted(blocks.blocks.values()):
        size = int(np.prod(shape))
        width = shape[-1] if len(shape) == 2 and 0 < shape[-1] <= MAX_NODE_WIDTH else 1
        whole[offset:offset + size] = count + np.arange(size) // width
        count += -(-size // width)
    ids = whole[np.asarray(free, dtype=np.int64)]
    new = np.ones(len(ids), dtype=bool)
    np.not_equal(ids[1:], ids[:-1], out=new[1:])
    return np.cumsum(new) - 1, np.flatnonzero(new)


def pattern_key(columns: list[np.ndarray], blocks: VariableBlocks, free: np.ndarray) -> bytes:
    """A digest of everything a `NormalPattern` depends on: the variable blocks, the free
    variables and every family's column pattern (so the topology and the held set)."""
    digest = hashlib.blake2b(digest_size=20)
    digest.update(repr(sorted(blocks.blocks.items())).encode())
    free = np.ascontiguousarray(free, dtype=np.int64)
    digest.update(repr(free.shape).encode())
    digest.update(free.data)
    for cols in columns:
        cols = np.ascontiguousarray(cols, dtype=np.int64)
        digest.update(repr(cols.shape).encode())
        digest.update(cols.data)
    return digest.digest()


def _entry_groups(nodes: np.ndarray) -> np.ndarray:
    """(k,) group of each entry of a family's rows: entries that name the same node in
    every row share a group; groups are numbered by their first entry."""
    k = nodes.shape[1]
    group = np.arange(k)
    heads: list[int] = []
    for i in range(k):          # entries of a row, not rows: k <= 17
        for h in heads:
            if np.array_equal(nodes[:, i], nodes[:, h]):
                group[i] = group[h]
                break
        else:
            group[i] = len(heads)
            heads.append(i)
    return group


def normal_pattern(columns: list[np.ndarray], blocks: VariableBlocks, free: np.ndarray, *,
                   key: bytes = b"") -> NormalPattern:
    """Build the pattern of the normal equations (see the module docstring).

    Parameters
    ----------
    columns : per family, (m, k) int, the variable of each Jacobian entry (as
        `Constraint.columns` gives it).
    blocks : the variable blocks the columns index.
    free : (nfree,) int, sorted indices of the free variables.
    key : its `pattern_key`, recorded in the result.

    Returns
    -------
    `NormalPattern`, shared by solvers (read-only but for the arrays `np.bincount` reads,
    which it would copy): the upper
    triangle has every ``(p, q)``, ``p <= q``, that some row's entries name, and the
    diagonal, columns sorted within each row; the same as ranking every product's key.

    Examples
    --------
    Two rows on three variables, ``x0 x1`` and ``x1 x2``, with ``x2`` held:

    >>> blocks = VariableBlocks()
    >>> blocks.add("x", (3,))
    >>> pattern = normal_pattern([np.array([[0, 1], [1, 2]])], blocks, np.array([0, 1]))
    >>> pattern.indptr.tolist(), pattern.indices.tolist(), pattern.diagonal.tolist()
    ([0, 2, 3], [0, 1, 1], [0, 2])
    >>> pattern.slots.tolist()    # entry pairs (0, 0), (0, 1), (1, 1) of both rows; 3: held
    [0, 2, 1, 3, 2, 3]
    """
    free = np.asarray(free, dtype=np.int64)
    nfree = len(free)
    col_map = np.full(blocks.size, nfree, dtype=np.int64)     # nfree: held
    col_map[free] = np.arange(nfree)
    kernels = compiled()
    if kernels is not None:
        return _compiled_pattern(kernels, [col_map[np.asarray(c, dtype=np.int64)] for c in columns],
                                 nfree, key)
    node, first = variable_nodes(blocks, free)
    nodes = len(first)
    offset = np.arange(nfree) - first[node]
    node_of = np.append(node, -1)       # at index nfree: a held column has no node
    offset_of = np.append(offset, 0).astype(np.uint8)

    # 1. the node pairs of every row, one per pair of its entry groups
    families, layouts = [], []
    keys = [np.arange(nodes, dtype=np.int64) * (nodes + 1)]          # the diagonal's first
    for c in columns:
        cols = col_map[np.asarray(c, dtype=np.int64)]
        family, layout, node_keys = _family_layout(cols, node_of, offset_of, nodes)
        families.append(family)
        layouts.append(layout)
        keys.append(node_keys.ravel())
    all_keys = np.concatenate(keys)
    valid = all_keys >= 0
    if valid.all():                    # nothing held: no copies (fresh memory is slow)
        pairs, pair_index = rank_keys(all_keys, max(nodes * nodes, 1))
    else:
        pairs, position = rank_keys(all_keys[valid], max(nodes * nodes, 1))
        pair_index = np.full(len(all_keys), -1, dtype=np.int64)
        pair_index[valid] = position
    owners, at = [], nodes
    for layout in layouts:
        owners.append(pair_index[at:at + layout.pairs * layout.rows].reshape(layout.pairs, layout.rows))
        at += layout.pairs * layout.rows

    # 2. which variable pairs each node pair holds: bit 8 a + b of its mask
    masks = np.zeros(len(pairs), dtype=np.uint64)
    width = np.diff(np.append(first, nfree))
    masks[pair_index[:nodes]] = _DIAGONAL_BITS[width]
    for layout, owner in zip(layouts, owners, strict=True):
        p, m = layout.within.shape
        heads = owner[layout.group_pair[layout.order[layout.bounds]]]   # (group pairs, m)
        step = max(1, _CHUNK // max(p, 1))
        for r in range(0, m if p else 0, step):     # chunks of rows: small temporaries
            bits = np.left_shift(np.uint64(1), layout.within[layout.order, r:r + step],
                                 dtype=np.uint64)
            merged = np.bitwise_or.reduceat(bits, layout.bounds, axis=0)
            held = heads[:, r:r + step]
            ok = held >= 0
            np.bitwise_or.at(masks, held[ok], merged[ok])

    # 3. the upper triangle, row by row: node P's pairs (P, Q) in the order of Q
    row_bytes = ((masks[:, None] >> (np.arange(8, dtype=np.uint64) * np.uint64(8)))
                 & np.uint64(0xFF)).astype(np.uint8)                     # (pairs, 8): byte a
    counts = _POPCOUNT[row_bytes]
    pair_row = pairs // max(nodes, 1)
    segment = np.searchsorted(pair_row, np.arange(nodes))      # (P, P) starts node P's pairs
    row_lengths = np.add.reduceat(counts, segment, axis=0, dtype=np.int64)[node, offset] \
        if nodes else np.zeros(0, dtype=np.int64)
    nnz = int(row_lengths.sum())
    dtype = index_dtype(nnz)
    indptr: np.ndarray = np.zeros(nfree + 1, dtype=dtype)
    np.cumsum(row_lengths, out=indptr[1:])
    # the start of the row of each (pair, a), shifted, with the row's byte: one word each
    packed = np.cumsum(counts, axis=0, dtype=np.int64)
    packed -= counts
    packed -= packed[segment][pair_row]
    packed += indptr[np.minimum(first[pair_row][:, None] + np.arange(8), nfree)]
    diagonal = packed[segment[node], offset].astype(dtype)
    packed <<= 8
    packed |= row_bytes
    packed = packed.ravel()
    indices: np.ndarray = np.empty(nnz, dtype=dtype)
    step = _CHUNK // 64
    pair_first = first[pairs % max(nodes, 1)]       # the first column of each pair's node Q
    for t in range(0, len(pairs), step):       # chunks of node pairs: small temporaries
        present = np.flatnonzero(np.unpackbits(row_bytes[t:t + step, :, None], axis=2,
                                               bitorder="little")) + 64 * t
        word = packed[present >> 3]
        b = present & 7
        indices[(word >> 8) + _RANK_BELOW[((word & 0xFF) << 3) | b]] = \
            pair_first[present >> 6] + b

    # 4. every product's slot: the start of its row in its node pair, plus the bits before it
    slots: np.ndarray = np.empty(sum(layout.within.size for layout in layouts), dtype=dtype)
    at = 0
    if not nnz:                         # every variable held: every product too
        slots.fill(nnz)
        layouts, owners = [], []
    for layout, owner in zip(layouts, owners, strict=True):
        p, m = layout.within.shape
        step = max(1, _CHUNK // max(m, 1))
        for r in range(0, p, step):     # chunks of entry pairs: small temporaries
            pair_owner = owner[layout.group_pair[r:r + step]]            # (c, m)
            within = layout.within[r:r + step]
            word = pair_owner << 3
            word += within >> 3
            word = packed[word]
            slot = slots[at:at + word.size].reshape(word.shape)
            np.right_shift(word, 8, out=slot)
            word &= 0xFF
            word <<= 3
            word |= within & 7
            slot += _RANK_BELOW[word]
            slot[pair_owner < 0] = nnz
            at += word.size
    # slots and gradient columns stay writeable: np.bincount copies read-only input
    for array in (indptr, indices, diagonal):
        array.flags.writeable = False
    return NormalPattern(families=tuple(families), indptr=indptr, indices=indices,
                         diagonal=diagonal, slots=slots, key=key)


def _compiled_pattern(kernels, columns: list[np.ndarray], nfree: int, key: bytes) -> NormalPattern:
    """`normal_pattern` by the compiled kernels (`fabplan.solve.kernels`): each row's
    candidate columns gathered, made distinct and sorted, then every product's column
    found in its row. The same arrays as the numpy path; `columns` are free columns
    (``nfree``: held)."""
    columns = [np.ascontiguousarray(c, dtype=np.int64) for c in columns]
    indptr64, rows, repeats = kernels.pattern_rows(columns, nfree)
    nnz = int(indptr64[-1])
    dtype = index_dtype(nnz)
    indices: np.ndarray = np.empty(nnz, dtype=dtype)
    slots = np.empty(sum(c.shape[1] * (c.shape[1] + 1) // 2 * c.shape[0] for c in columns),
                     dtype=dtype)
    kernels.pattern_fill(rows, columns, nfree, indptr64, indices, slots)
    indptr = indptr64.astype(dtype)
    diagonal = indptr[:-1].copy()           # a row's first column is its own
    for array in (indptr, indices, diagonal):
        array.flags.writeable = False
    families = tuple(FamilyPattern(c, (c.shape[1] * (c.shape[1] + 1) // 2, c.shape[0]),
                                   _multiplicity(c, nfree) if twice else None)
                     for c, twice in zip(columns, repeats, strict=True))
    return NormalPattern(families=families, indptr=indptr, indices=indices,
                         diagonal=diagonal, slots=slots, key=key)


def _multiplicity(cols: np.ndarray, nfree: int) -> np.ndarray | None:
    """(p, m) float, 2 for the products of two entries of a row on one free variable,
    else 1; None when there are none (`FamilyPattern.multiplicity`)."""
    first, second = np.triu_indices(cols.shape[1])
    repeated = np.flatnonzero(first != second)
    a, b = cols[:, first[repeated]], cols[:, second[repeated]]
    twice = (a == b) & (a < nfree)
    if not twice.any():
        return None
    multiplicity = np.ones((len(first), cols.shape[0]))
    multiplicity[repeated] = np.where(twice.T, 2.0, 1.0)
    multiplicity.flags.writeable = False
    return multiplicity


@dataclass
class _FamilyLayout:
    """How one family's products fall into the node pairs of its rows.

    Attributes
    ----------
    rows : m, the family's rows.
    pairs : its rows' pairs of entry groups.
    group_pair : (p,) the pair of entry groups of each entry pair.
    within : (p, m) uint8, ``8 a + b``: each product's variable pair (a, b) inside its
        node pair (a in the node first in order).
    order, bounds : the entry pairs sorted by group pair, and where each group pair starts.
    """

    rows: int
    pairs: int
    group_pair: np.ndarray
    within: np.ndarray
    order: np.ndarray
    bounds: np.ndarray


def _family_layout(cols: np.ndarray, node_of: np.ndarray, offset_of: np.ndarray,
                   nodes: int) -> tuple[FamilyPattern, _FamilyLayout, np.ndarray]:
    """A family's `FamilyPattern`, its layout, and the (group pairs, m) keys ``P nodes + Q``
    of the node pairs its rows couple (-1 where a held variable has none). `cols` are free
    columns, the number of free variables for a held one (the last entry of `node_of`
    and `offset_of`); they become the family's gradient columns."""
    m, k = cols.shape
    row_nodes = node_of[cols]
    group = _entry_groups(row_nodes)
    heads = np.unique(group, return_index=True)[1]
    gi, gj = np.triu_indices(len(heads))
    pair_of_groups = np.zeros((len(heads), len(heads)), dtype=np.int64)
    pair_of_groups[gi, gj] = pair_of_groups[gj, gi] = np.arange(len(gi))
    head_nodes = row_nodes.T[heads]                                     # (groups, m)
    a, b = head_nodes[gi], head_nodes[gj]
    lo = np.minimum(a, b)
    node_keys = np.where(lo >= 0, lo * nodes + np.maximum(a, b), -1)
    # the entry pairs i <= j of a row, pair-major (as the solver multiplies them)
    first_entry, second_entry = np.triu_indices(k)
    group_pair = pair_of_groups[group[first_entry], group[second_entry]]
    offsets = offset_of[cols].T.copy()                                  # (k, m) uint8
    op, oq = offsets[first_entry], offsets[second_entry]
    # a product's row in its node pair is the offset of its variable that comes first:
    # the node that comes first, or where both groups name one node, the smaller offset
    one_node = (a == b) & (a >= 0)                                      # (group pairs, m)
    swap = (a > b)[group_pair]
    tied = np.flatnonzero(one_node.any(axis=1)[group_pair])
    swap[tied] |= one_node[group_pair[tied]] & (op[tied] > oq[tied])
    within = np.where(swap, (oq << 3) | op, (op << 3) | oq)
    # a row naming one variable at two entries adds their product twice
    repeated = tied[first_entry[tied] != second_entry[tied]]
    twice = one_node[group_pair[repeated]] & (op[repeated] == oq[repeated])
    multiplicity = None
    if twice.any():
        multiplicity = np.ones(op.shape)
        multiplicity[repeated] = np.where(twice, 2.0, 1.0)
    order = np.argsort(group_pair, kind="stable")
    bounds = np.flatnonzero(np.r_[True, np.diff(group_pair[order]) != 0]) if k else \
        np.zeros(0, dtype=np.int64)
    if multiplicity is not None:
        multiplicity.flags.writeable = False
    family = FamilyPattern(cols, op.shape, multiplicity)
    return family, _FamilyLayout(m, len(gi), group_pair, within, order, bounds), node_keys


class PatternCache:
    """Normal-equation patterns by `pattern_key`, the most recently used first.

    Parameters
    ----------
    max_entries : patterns kept at most.
    max_bytes : memory the kept patterns may hold together; the newest pattern is kept
        whatever its size (its solver holds it anyway).

    Safe to share between threads: solvers only read patterns. A pattern takes about 8
    bytes per product and 16 per entry (some 0.25 GB at 30k vertices, 0.8 GB at 100k) and
    stays after its solve; `clear` frees them.
    """

    def __init__(self, max_entries: int = 4, max_bytes: int = 1 << 30) -> None:
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self.hits = 0
        self.misses = 0
        self._patterns: OrderedDict[bytes, NormalPattern] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: bytes) -> NormalPattern | None:
        """The pattern built for `key`, or None (counted as a miss)."""
        with self._lock:
            pattern = self._patterns.get(key)
            if pattern is None:
                self.misses += 1
                return None
            self.hits += 1
            self._patterns.move_to_end(key)
            return pattern

    def put(self, pattern: NormalPattern) -> NormalPattern:
        """Keep `pattern` (under its key) and return it; the least recently used ones go
        when there are too many or they hold too much."""
        with self._lock:
            self._patterns[pattern.key] = pattern
            self._patterns.move_to_end(pattern.key)
            while len(self._patterns) > 1 and (
                    len(self._patterns) > self.max_entries
                    or sum(p.nbytes for p in self._patterns.values()) > self.max_bytes):
                self._patterns.popitem(last=False)
        return pattern

    def discard(self, key: bytes) -> None:
        """Forget the pattern of `key`, if kept (a solver that will not run again, such
        as the coarse net of a multilevel solve, frees its memory for the next)."""
        with self._lock:
            self._patterns.pop(key, None)

    def clear(self) -> None:
        with self._lock:
            self._patterns.clear()
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._patterns)

    def __contains__(self, key: object) -> bool:
        return key in self._patterns


# the patterns of this process's solvers
pattern_cache = PatternCache()
