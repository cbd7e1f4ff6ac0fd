"""The normal equations' pattern: built from node pairs, it is the pattern that ranking every
product gives, on every net type, with held vertices and handles, on irregular meshes; a
pattern is reused for the same structure and rebuilt when the topology or the held set
changes; and a solve with it goes exactly as a solve with the ranked one."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import noisy

import fabplan
import fabplan.solve.solver as solver_module
from fabplan.net.generate import rotational_weingarten_snet
from fabplan.solve import kernels
from fabplan.solve.constraints import VariableBlocks
from fabplan.solve.edit import NetEditor
from fabplan.solve.net_types import NETS
from fabplan.solve.optimize import build_solver
from fabplan.solve.pattern import (
    FamilyPattern,
    NormalPattern,
    PatternCache,
    normal_pattern,
    pattern_cache,
    pattern_key,
    rank_keys,
    variable_nodes,
)


def ranked_pattern(columns: list, blocks: VariableBlocks, free: np.ndarray) -> NormalPattern:
    """The construction the solver used before: every product's key ``p nfree + q`` ranked
    among all keys (one sort of all of them)."""
    nfree = len(free)
    col_map = np.full(blocks.size, -1)
    col_map[free] = np.arange(nfree)
    families, pair_keys = [], []
    for c in columns:
        cols = col_map[np.asarray(c)]
        first, second = np.triu_indices(cols.shape[1])
        cp, cq = cols.T[first], cols.T[second]
        lo, hi = np.minimum(cp, cq), np.maximum(cp, cq)
        pair_keys.append(np.where(lo >= 0, lo * nfree + hi, -1))
        twice = (cp == cq) & (cp >= 0) & (first != second)[:, None]
        families.append(FamilyPattern(np.where(cols < 0, nfree, cols), cp.shape,
                                      np.where(twice, 2.0, 1.0) if twice.any() else None))
    keys = np.concatenate([np.arange(nfree) * (nfree + 1)] + [k.ravel() for k in pair_keys])
    valid = keys >= 0
    distinct, ranks = rank_keys(keys[valid], nfree * nfree)
    slots = np.full(len(keys), len(distinct))
    slots[valid] = ranks
    return NormalPattern(tuple(families), np.searchsorted(distinct // nfree, np.arange(nfree + 1)),
                         distinct % nfree, slots[:nfree], slots[nfree:])


def assert_same_pattern(built: NormalPattern, ranked: NormalPattern) -> None:
    assert np.array_equal(built.indptr, ranked.indptr)
    assert np.array_equal(built.indices, ranked.indices)
    assert np.array_equal(built.diagonal, ranked.diagonal)
    assert np.array_equal(built.slots, ranked.slots)
    assert len(built.families) == len(ranked.families)
    for a, b in zip(built.families, ranked.families, strict=True):
        assert a.shape == b.shape
        assert np.array_equal(a.gradient_cols, b.gradient_cols)
        assert (a.multiplicity is None) == (b.multiplicity is None)
        if a.multiplicity is not None:
            assert np.array_equal(a.multiplicity, b.multiplicity)


def solver_columns(solver) -> list:
    for c in solver.constraints:
        c.prepare(solver.state)
    return [np.asarray(c.columns(solver.state)) for c in solver.constraints]


def check_solver(solver) -> None:
    columns = solver_columns(solver)
    blocks, free = solver.state.blocks, solver.free
    assert_same_pattern(normal_pattern(columns, blocks, free), ranked_pattern(columns, blocks, free))


def tetrapod():
    """The CMC example's start: irregular vertices of valence 6 and rings of triangles."""
    path = Path(__file__).resolve().parent.parent / "examples" / "formfind_cmc.py"
    spec = importlib.util.spec_from_file_location("example_formfind_cmc", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.tetrapod_mesh(rings=2)


@pytest.fixture(autouse=True, params=["compiled", "numpy"])
def empty_cache(request, monkeypatch):
    """Every test on both paths that build a pattern: the compiled kernels
    (`fabplan.solve.kernels`, where built) and numpy."""
    if request.param == "numpy":
        monkeypatch.setenv("FABPLAN_KERNELS", "numpy")
    elif kernels.compiled() is None:
        pytest.skip("the compiled kernels are not built or switched off")
    kernels.compiled.cache_clear()
    pattern_cache.clear()
    yield
    pattern_cache.clear()
    kernels.compiled.cache_clear()


@pytest.mark.parametrize("net", sorted(NETS))
def test_pattern_of_every_net_type_is_the_ranked_one(cmc1, net):
    check_solver(build_solver(cmc1, net))


def test_pattern_of_a_regular_grid_is_the_ranked_one():
    check_solver(build_solver(noisy(rotational_weingarten_snet(14, 14, radius=3.0), 0.01),
                              "linear-weingarten"))


def test_pattern_with_irregular_vertices_is_the_ranked_one():
    mesh = tetrapod()
    assert len(mesh.irregular_vertices) and (mesh.face_sizes == 3).any()
    check_solver(build_solver(mesh, "cmc", closeness=False))


@pytest.mark.parametrize("net", ["snet", "sstar", "linear-weingarten"])
def test_pattern_with_held_vertices_is_the_ranked_one(wein99, net):
    boundary = np.flatnonzero(wein99.is_boundary_vertex)
    scattered = np.arange(0, wein99.vertex_count, 7)       # every 7th: stars half held
    for fixed in (boundary, scattered):
        solver = build_solver(wein99, net, fixed=fixed)
        assert len(solver.free) == solver.state.blocks.size - 3 * len(fixed)
        check_solver(solver)


def test_pattern_with_guards_gliding_and_orientation_is_the_ranked_one(wein99):
    # one-sided barriers with a slack per row, the design surface as a hard constraint
    # with its band and boundary curves, a slack per sphere
    check_solver(build_solver(wein99, "snet", guards=True, glide=True, coherent=True,
                              fixed=[5, 6, 7]))


def test_pattern_of_handles_is_the_ranked_one(cmc1):
    editor = NetEditor(cmc1, "sstar", handles=[120, 40])
    check_solver(editor.solver)


def test_pattern_of_mixed_blocks_and_repeated_variables_is_the_ranked_one():
    """Nodes wider than a mask allows (single variables then), one-dimensional blocks,
    nodes partly held, rows that name a variable twice, empty families."""
    rng = np.random.default_rng(5)
    blocks = VariableBlocks()
    for name, shape in [("vertices", (30, 3)), ("wide", (6, 9)), ("loose", (7,)),
                        ("coefficients", (12, 8)), ("one", (1,))]:
        blocks.add(name, shape)
    columns = [rng.integers(0, blocks.size, size=(m, k)) for m, k in [(40, 5), (25, 17), (9, 1)]]
    columns.append(np.repeat(blocks.index("vertices")[rng.integers(0, 30, 20)], 2, axis=1))
    columns.append(np.zeros((0, 4), dtype=np.int64))
    columns.append(np.zeros((3, 0), dtype=np.int64))
    for held in (0.0, 0.3, 0.7):
        free = np.flatnonzero(rng.random(blocks.size) >= held)
        built = normal_pattern(columns, blocks, free)
        assert_same_pattern(built, ranked_pattern(columns, blocks, free))
        assert built.families[3].multiplicity is not None
    nothing_free = normal_pattern(columns, blocks, np.zeros(0, dtype=np.int64))
    assert nothing_free.nnz == 0 and nothing_free.indptr.tolist() == [0]
    assert (nothing_free.slots == 0).all()


def test_variable_nodes_split_at_held_variables():
    blocks = VariableBlocks()
    blocks.add("vertices", (3, 3))
    blocks.add("wide", (1, 9))
    node, first = variable_nodes(blocks, np.array([0, 2, 3, 4, 5, 9, 10]))
    # vertex 0 without its y, vertex 1 whole, vertex 2 held, the wide row one by one
    assert node.tolist() == [0, 0, 1, 1, 1, 2, 3]
    assert first.tolist() == [0, 2, 5, 6]


def test_pattern_arrays_are_read_only(cmc1):
    solver = build_solver(cmc1, "snet")
    solver.run(0)
    with pytest.raises(ValueError):
        solver.pattern.indices[0] = 0
    with pytest.raises(ValueError):
        solver.pattern.diagonal[0] = 0


def test_a_second_solver_on_the_same_structure_reuses_the_pattern(wein99):
    first = build_solver(wein99, "linear-weingarten")
    first.run(0)
    assert pattern_cache.misses == 1 and pattern_cache.hits == 0
    # a study candidate on the same topology, moved: the same pattern object
    second = build_solver(noisy(wein99, 0.02, seed=4), "linear-weingarten")
    second.run(0)
    assert second.pattern is first.pattern
    assert pattern_cache.hits == 1
    if first.linear_solver == "cholmod":       # and CHOLMOD's matrix of the pattern
        first.run(1)
        shared = first.pattern.shared["cholmod"]
        second.run(2)
        assert second.pattern.shared["cholmod"] is shared
        pattern_cache.clear()
        alone = build_solver(noisy(wein99, 0.02, seed=4), "linear-weingarten")
        alone.run(2)
        assert alone.pattern.shared["cholmod"] is not shared
        assert np.array_equal(alone.vertices, second.vertices)


def test_pattern_is_rebuilt_when_the_held_set_or_the_topology_changes(wein99, cmc1):
    base = build_solver(wein99, "snet")
    base.run(0)
    held = build_solver(wein99, "snet", fixed=[3, 4])
    held.run(0)
    other_held = build_solver(wein99, "snet", fixed=[3, 5])
    other_held.run(0)
    other_mesh = build_solver(cmc1, "snet")
    other_mesh.run(0)
    other_type = build_solver(wein99, "isogonal")
    other_type.run(0)
    patterns = [s.pattern for s in (base, held, other_held, other_mesh, other_type)]
    assert len({p.key for p in patterns}) == 5
    assert pattern_cache.misses == 5 and pattern_cache.hits == 0
    assert held.pattern.nnz < base.pattern.nnz
    check_solver(other_held)


def test_editors_reuse_the_pattern_of_their_handles(cmc1):
    editor = NetEditor(cmc1, "snet", handles=[120])
    target = cmc1.vertices[120] + [0.0, 0.0, 0.02]
    editor.drag({120: target})
    pattern = editor.solver.pattern
    editor.drag({120: target + [0.0, 0.01, 0.0]})
    assert editor.solver.pattern is pattern and pattern_cache.misses == 1
    again = NetEditor(cmc1, "snet", handles=[120])
    again.drag({120: target})
    assert again.solver.pattern is pattern and pattern_cache.hits == 1
    elsewhere = NetEditor(cmc1, "snet", handles=[121])
    elsewhere.drag({121: cmc1.vertices[121]})
    assert elsewhere.solver.pattern is not pattern


def test_pattern_cache_keeps_the_most_recent_within_its_limits():
    blocks = VariableBlocks()
    blocks.add("x", (4, 3))
    free = np.arange(12)

    def built(seed: int) -> NormalPattern:
        cols = [np.random.default_rng(seed).integers(0, 12, size=(5, 3))]
        return normal_pattern(cols, blocks, free, key=pattern_key(cols, blocks, free))

    cache = PatternCache(max_entries=2)
    a, b, c = built(0), built(1), built(2)
    for p in (a, b, c):
        assert cache.put(p) is p
    assert a.key not in cache and b.key in cache and c.key in cache
    assert cache.get(b.key) is b
    cache.put(a)                  # c is now the least recently used
    assert c.key not in cache and cache.get(c.key) is None
    small = PatternCache(max_bytes=1)
    small.put(a)
    small.put(b)                  # too big together: the newest stays
    assert len(small) == 1 and b.key in small
    cache.discard(b.key)
    cache.discard(b.key)          # gone already: nothing to do
    assert b.key not in cache and a.key in cache and len(cache) == 1


def test_pattern_key_tells_columns_and_held_sets_apart():
    blocks = VariableBlocks()
    blocks.add("x", (4, 3))
    cols = [np.arange(12).reshape(4, 3)]
    key = pattern_key(cols, blocks, np.arange(12))
    assert pattern_key([c.copy() for c in cols], blocks, np.arange(12)) == key
    assert pattern_key(cols, blocks, np.arange(11)) != key
    assert pattern_key([cols[0][::-1]], blocks, np.arange(12)) != key
    assert pattern_key([cols[0].reshape(6, 2)], blocks, np.arange(12)) != key


@pytest.mark.parametrize("case", ["free", "boundary held", "handle"])
def test_solve_with_the_built_pattern_matches_the_ranked_one_exactly(wein99, monkeypatch, case):
    """Same slots, same summation order: every iterate is the same to the last bit."""
    start = noisy(wein99, 0.01)
    options = {"boundary held": {"fixed": np.flatnonzero(wein99.is_boundary_vertex)},
               "handle": {"handles": {10: wein99.vertices[10] + [0.0, 0.0, 0.02]}}}.get(case, {})
    built = fabplan.optimize(start, "linear-weingarten", **options)
    pattern_cache.clear()

    def ranked(columns, blocks, free, *, key=b""):
        p = ranked_pattern(columns, blocks, free)
        return NormalPattern(p.families, p.indptr, p.indices, p.diagonal, p.slots, key)

    monkeypatch.setattr(solver_module, "normal_pattern", ranked)
    reference = fabplan.optimize(start, "linear-weingarten", **options)
    assert built.status == reference.status and built.iterations == reference.iterations
    assert [h["hard_residual"] for h in built.history] == \
        [h["hard_residual"] for h in reference.history]
    assert np.array_equal(built.mesh.vertices, reference.mesh.vertices)


# the last: key and index need 62 + 11 bits, more than 63, so the keys are sorted in 1,024
# ranges of their high bits (200,000 keys made that 131,072 ranges and 7 s, for the same path)
@pytest.mark.parametrize("n, bound", [(0, 8), (1, 1), (1000, 50), (100_000, 10**12),
                                      (2_000, 2**62)])
def test_rank_keys_is_unique_with_inverse_and_leaves_the_keys(n, bound):
    keys = np.random.default_rng(n).integers(0, bound, n)
    kept = keys.copy()
    distinct, position = rank_keys(keys, bound)
    expected, inverse = np.unique(keys, return_inverse=True)
    assert np.array_equal(keys, kept)
    assert np.array_equal(distinct, expected) and np.array_equal(position, inverse)
