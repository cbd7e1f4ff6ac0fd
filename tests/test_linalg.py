"""Sparse SPD backends: every installed one solves the solver's systems alike."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import noisy

import fabplan
from fabplan.errors import SolverError
from fabplan.solve.linalg import PARDISO_MIN_UNKNOWNS, SparseSPDSolver, available_backends
from fabplan.solve.solver import SolverSettings

BACKENDS = available_backends()


def _upper(matrix: sp.spmatrix) -> sp.csr_matrix:
    upper = sp.triu(matrix, format="csr")
    upper.sort_indices()
    return upper


def _spd_pattern(n: int, seed: int) -> sp.csr_matrix:
    """A sparse SPD matrix with the coupling of a 2D grid (5-point stencil, diagonal heavy)."""
    k = int(np.sqrt(n))
    grid = sp.diags([1.0, 1.0], [1, k], shape=(n, n))
    rng = np.random.default_rng(seed)
    off = grid.tocsr()
    off.data = rng.uniform(-1, 1, off.nnz)
    sym = off + off.T
    return (sym + sp.diags(np.abs(sym).sum(axis=1).A1 + 1.0)).tocsr()


@pytest.mark.parametrize("backend", BACKENDS)
def test_backend_refactors_one_pattern_and_solves_exactly(backend):
    solver = SparseSPDSolver(backend)
    rng = np.random.default_rng(3)
    for seed in range(3):      # new values, same pattern: the analysis is reused
        A = _spd_pattern(900, seed)
        upper = _upper(A)
        solver.factor(upper)
        b = rng.standard_normal(A.shape[0])
        x = solver.solve(b)
        assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)


@pytest.mark.parametrize("backend", [b for b in BACKENDS if b != "superlu"])
def test_indefinite_matrix_is_refused(backend):
    A = _spd_pattern(400, 0).tolil()
    A[7, 7] = -50.0
    with pytest.raises(SolverError, match="not positive definite"):
        SparseSPDSolver(backend).factor(_upper(A.tocsr()))


def test_auto_keeps_small_systems_on_one_core():
    assert SparseSPDSolver("auto", unknowns=5000).backend != "pardiso"
    big = SparseSPDSolver("auto", unknowns=PARDISO_MIN_UNKNOWNS).backend
    assert big == ("pardiso" if "pardiso" in BACKENDS else BACKENDS[0])


@pytest.mark.slow
def test_every_backend_gives_the_same_linear_weingarten_net(wein99):
    start = noisy(wein99, 0.01, seed=4)
    results = {b: fabplan.optimize(start, "linear-weingarten", settings=SolverSettings(backend=b))
               for b in BACKENDS}
    reference = results[BACKENDS[0]].mesh.vertices
    for backend, result in results.items():
        assert result.converged and result.linear_solver == backend
        assert result.properties["sphere_residual_relative"]["max"] <= 1e-6
        # the nearly square systems pass rounding differences on: same net within 1e-4 of
        # an edge, a hundredth of the noise the solve removed
        gap = np.abs(result.mesh.vertices - reference).max()
        assert gap <= 1e-4 * wein99.mean_edge_length, backend
