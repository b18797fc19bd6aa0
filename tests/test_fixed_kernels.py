"""spectrageo.linalg._fixed: the fixed-order kernels behind the bit-identical decoders.

Differential tests against SciPy / NumPy with tolerances from the conditioning, and the exactness
properties the decoders rely on: the same inputs give the same bits whatever their memory
layout, the format of the sparse matrix, the number of right-hand sides solved together or the
number of calls; products and differences are rounded separately (no fused multiply-add).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu, spsolve

from spectrageo import InvalidInputError
from spectrageo.graph import adjacency_matrix, laplacian_from_adjacency
from spectrageo.linalg._fixed import (
    SparseCholesky,
    _gemm_nt_sub,
    _min_degree,
    fill_reducing_order,
    matmul,
    orthonormal_columns,
)

from conftest import grid, icosphere

EPS = np.finfo(np.float64).eps


def _binary_laplacian(F, n):
    C = adjacency_matrix(F, n)
    C.data[:] = 1.0
    return laplacian_from_adjacency(C).tocsr()


def _normal_equations(L, anchors, weight=1.0):
    """``L^T L + w^2 I_a^T I_a``: the matrix of Eq. (5.51) / (5.54)."""
    d = np.zeros(L.shape[0])
    d[anchors] = weight * weight
    return (L.T @ L + sp.diags(d)).tocsr()


def _systems():
    """Laplacian-like SPD systems: anchored bi-Laplacians of a sphere, a grid and two
    components (one anchor each), and a shifted grid Laplacian ``L + I / 2``."""
    out = []
    V, F = icosphere(3)
    L = _binary_laplacian(F, V.shape[0])
    out.append(("sphere", _normal_equations(L, np.arange(0, V.shape[0], 37))))
    Vg, Fg = grid(30, 25)
    Lg = _binary_laplacian(Fg, Vg.shape[0])
    out.append(("grid", _normal_equations(Lg, np.array([0, 400, 749]))))
    F2 = np.r_[F, Fg + V.shape[0]]
    n2 = V.shape[0] + Vg.shape[0]
    L2 = _binary_laplacian(F2, n2)
    out.append(("two components", _normal_equations(L2, np.array([5, V.shape[0] + 7]))))
    out.append(("shifted", (Lg + 0.5 * sp.eye(Lg.shape[0])).tocsr()))
    return out


SYSTEMS = _systems()


# ----------------------------------------------------------------------------- sparse Cholesky
@pytest.mark.parametrize("name,K", SYSTEMS, ids=[s[0] for s in SYSTEMS])
@pytest.mark.parametrize("m", [1, 3, 20])
def test_sparse_cholesky_solves_like_spsolve(name, K, m):
    """Against SciPy's ``spsolve``. Both solvers are backward stable, so each solution has a
    relative error of at most ``cond(K)`` times a small multiple of the machine epsilon; the
    two differ by no more than the sum. The residual ``K x - b`` is checked against the
    backward-error bound ``||K|| ||x||`` times a multiple of epsilon, which does not depend on
    the conditioning."""
    rng = np.random.default_rng(7)
    n = K.shape[0]
    B = rng.standard_normal((n, m))
    X = SparseCholesky(K).solve(B)
    ref = spsolve(K.tocsc(), B).reshape(n, m)
    cond = np.linalg.cond(K.toarray())
    scale = np.abs(ref).max()
    assert np.abs(X - ref).max() <= 100 * cond * EPS * scale
    knorm = abs(K).sum(axis=1).max()
    assert np.abs(K @ X - B).max() <= 1000 * n * EPS * knorm * np.abs(X).max()


def test_sparse_cholesky_gives_the_anchored_laplacian_its_vertices_back():
    """The exact deltas and anchors of Eq. (5.54) give the vertices back: the right-hand side
    ``L^T L V + I_a^T V_a`` solves to ``V`` up to rounding amplified by the conditioning."""
    V, F = icosphere(3)
    n = V.shape[0]
    L = _binary_laplacian(F, n)
    a = np.arange(0, n, 37)
    K = _normal_equations(L, a)
    rhs = np.asarray(L.T @ (L @ V))
    rhs[a] += V[a]
    np.testing.assert_allclose(SparseCholesky(K).solve(rhs), V, rtol=0, atol=1e-9)


def test_sparse_cholesky_bits_do_not_depend_on_layout_format_or_batching():
    """The decoders' promise: the same values give the same bits. A vector, a C- or
    Fortran-ordered or strided matrix of right-hand sides, the matrix as CSR, CSC, COO with
    unsorted duplicates or int64 indices, columns solved one at a time or together (above and
    below the batch size where the solve switches kernels), repeated calls and factorisations:
    all identical."""
    _name, K = SYSTEMS[1]
    n = K.shape[0]
    rng = np.random.default_rng(3)
    B = rng.standard_normal((n, 24))
    chol = SparseCholesky(K)
    X = chol.solve(B)
    assert X.flags.c_contiguous and X.dtype == np.float64
    np.testing.assert_array_equal(chol.solve(B), X)
    np.testing.assert_array_equal(chol.solve(np.asfortranarray(B)), X)
    wide = np.zeros((n, 48))
    wide[:, ::2] = B
    np.testing.assert_array_equal(chol.solve(wide[:, ::2]), X)
    for j in (0, 5, 23):
        np.testing.assert_array_equal(chol.solve(B[:, j]), X[:, j])
    for lo, hi in ((0, 3), (3, 11), (11, 24)):
        np.testing.assert_array_equal(chol.solve(B[:, lo:hi]), X[:, lo:hi])
    coo = K.tocoo()
    half = coo.data / 2
    dup = sp.coo_matrix(
        (np.r_[half, half][::-1], (np.r_[coo.row, coo.row][::-1], np.r_[coo.col, coo.col][::-1])),
        shape=K.shape,
    )
    K64 = K.copy()
    K64.indptr = K64.indptr.astype(np.int64)
    K64.indices = K64.indices.astype(np.int64)
    for other in (K.tocsc(), dup, K64, K.copy()):
        np.testing.assert_array_equal(SparseCholesky(other).solve(B), X)


def test_sparse_cholesky_does_not_touch_its_inputs():
    """A matrix with unsorted indices is put in canonical form on a copy (the caller's arrays
    keep their order) and gives the same bits as the sorted one; the right-hand sides are
    not written to."""
    _name, K = SYSTEMS[0]
    n = K.shape[0]
    indices, data = K.indices.copy(), K.data.copy()
    for r in range(n):
        sl = slice(K.indptr[r], K.indptr[r + 1])
        indices[sl] = indices[sl][::-1]
        data[sl] = data[sl][::-1]
    Ku = sp.csr_matrix((data, indices, K.indptr.copy()), shape=K.shape)
    assert not Ku.has_canonical_format
    B = np.ones((n, 2))
    X = SparseCholesky(Ku).solve(B)
    np.testing.assert_array_equal(Ku.indices, indices)
    np.testing.assert_array_equal(Ku.data, data)
    np.testing.assert_array_equal(B, 1.0)
    np.testing.assert_array_equal(X, SparseCholesky(K).solve(B))


def test_sparse_cholesky_rejects_bad_input():
    _name, K = SYSTEMS[0]
    n = K.shape[0]
    with pytest.raises(InvalidInputError, match="must be square"):
        SparseCholesky(sp.random(4, 5, density=0.5, format="csr"))
    chol = SparseCholesky(K)
    with pytest.raises(InvalidInputError, match=rf"`B` must have shape \({n},\)"):
        chol.solve(np.ones(n + 1))
    with pytest.raises(InvalidInputError, match="`B` must have shape"):
        chol.solve(np.ones((n, 2, 2)))
    # singular with an exactly zero second pivot (a singular matrix whose pivots are rounded
    # to tiny positive numbers instead is factorised: no threshold could tell it from an
    # ill-conditioned one)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        SparseCholesky(sp.csr_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0, 0, 1.0]])))
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        SparseCholesky(sp.diags([1.0, -1.0, 2.0]))


def test_sparse_cholesky_small_and_diagonal_matrices():
    for K in (sp.csr_matrix([[4.0]]), sp.diags([2.0, 3.0]), sp.diags(np.arange(1.0, 30.0))):
        b = np.arange(1.0, K.shape[0] + 1)
        np.testing.assert_allclose(SparseCholesky(K).solve(b), b / K.diagonal(), rtol=1e-15)


# ----------------------------------------------------------------------------- ordering
def _factor_entries(K, perm):
    """Entries of the Cholesky factor of ``K[perm][:, perm]`` (dense, small systems)."""
    Lf = np.linalg.cholesky(K.toarray()[np.ix_(perm, perm)])
    return int(np.count_nonzero(np.abs(Lf) > 1e-13 * np.abs(Lf).max()))


def test_minimum_degree_order_is_a_deterministic_fill_reducing_permutation():
    """A permutation, the same on every call, with less fill than the natural order of a grid
    (whose bandwidth makes the natural factor dense within the band) and than a random
    order, and about as little as SuperLU's multiple minimum degree."""
    V, F = grid(50, 50)
    K = _normal_equations(_binary_laplacian(F, V.shape[0]), np.array([0, 1300]))
    n = K.shape[0]
    perm = fill_reducing_order(K)
    np.testing.assert_array_equal(np.sort(perm), np.arange(n))
    np.testing.assert_array_equal(fill_reducing_order(K), perm)
    np.testing.assert_array_equal(fill_reducing_order(K.tocsc()), perm)
    ours = _factor_entries(K, perm)
    assert ours < 0.65 * _factor_entries(K, np.arange(n))
    rand = np.random.default_rng(0).permutation(n)
    assert ours < 0.3 * _factor_entries(K, rand)
    # SuperLU's multiple minimum degree on the same pattern (its column order)
    mmd = splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0).perm_c
    inv = np.empty(n, np.int64)
    inv[mmd] = np.arange(n)
    assert ours <= 1.1 * _factor_entries(K, inv)


def test_minimum_degree_order_does_not_depend_on_its_workspace():
    """The element lists are compacted when the workspace runs out (and the workspace grows
    when that is not enough); neither changes any decision, so the order is the same with no
    spare room as with plenty."""
    for _name, K in SYSTEMS[:3]:
        K = K.tocsr()
        n = K.shape[0]
        roomy = _min_degree(n, K.indptr, K.indices, 10 * K.nnz)
        tight = _min_degree(n, K.indptr, K.indices, 0)
        np.testing.assert_array_equal(tight, roomy)


def test_minimum_degree_orders_dense_rows_last_and_handles_edge_cases():
    """A star (one row joined to all others, denser than ``10 sqrt(n)``) comes last; isolated
    vertices and tiny graphs give valid permutations."""
    n = 500
    star = sp.coo_matrix((np.ones(n - 1), (np.zeros(n - 1, int), np.arange(1, n))), shape=(n, n))
    path = sp.diags([np.ones(n - 1)], [1], shape=(n, n))
    G = (star + star.T + path + path.T + sp.eye(n)).tocsr()
    perm = fill_reducing_order(G)
    np.testing.assert_array_equal(np.sort(perm), np.arange(n))
    assert perm[-1] == 0
    for K in (sp.eye(1), sp.eye(2), sp.eye(7), sp.csr_matrix((3, 3))):
        p = fill_reducing_order(K)
        np.testing.assert_array_equal(np.sort(p), np.arange(K.shape[0]))


# ----------------------------------------------------------------------------- dense kernels
def test_matmul_matches_numpy_and_is_layout_independent():
    """Against ``A @ B``: each entry is a sum of ``k`` products, so any two summation orders
    differ by at most about ``k * eps * sum_k |A_ik B_kj|``. The bits do not depend on the
    memory layout of the inputs."""
    rng = np.random.default_rng(1)
    for m, k, n in ((16, 13, 1000), (7, 1, 5), (3, 0, 4), (1, 9, 1), (175, 175, 300)):
        A = rng.standard_normal((m, k))
        B = rng.standard_normal((k, n))
        C = matmul(A, B)
        bound = (k + 1) * EPS * (np.abs(A) @ np.abs(B))
        assert np.all(np.abs(C - A @ B) <= bound)
        np.testing.assert_array_equal(matmul(np.asfortranarray(A), B), C)
        np.testing.assert_array_equal(matmul(A, np.asfortranarray(B)), C)
        wide = np.zeros((k, 2 * n))
        wide[:, 1::2] = B
        np.testing.assert_array_equal(matmul(A, wide[:, 1::2]), C)
        np.testing.assert_array_equal(matmul(A.T.copy().T, B.T.copy().T), C)
        np.testing.assert_array_equal(matmul(A, B), C)
    with pytest.raises(InvalidInputError, match="do not chain"):
        matmul(np.ones((2, 3)), np.ones((4, 2)))


def test_products_and_differences_are_rounded_separately():
    """No fused multiply-add: ``1 - (1 + 2^-30)(1 - 2^-30)`` is ``1 - 1 = 0`` when the product
    is rounded first (``(1 - 2^-60)`` rounds to 1) and ``2^-60`` when fused. The host CPU may
    have FMA; the kernels must not use it, or a machine without it would decode other bits."""
    a = 1.0 + 2.0**-30
    b = 1.0 - 2.0**-30
    assert matmul(np.array([[1.0, a]]), np.array([[1.0], [-b]]))[0, 0] == 0.0
    for n_cols, kk in ((4, 1), (4, 4), (1, 1), (1, 4), (5, 5)):
        A = np.zeros(kk)
        A[-1] = a
        Bm = np.zeros((n_cols, kk))
        Bm[:, -1] = b
        C = np.ones(n_cols)
        _gemm_nt_sub(C, 0, 1, A, 0, 1, Bm.ravel(order="F"), 0, n_cols, 1, n_cols, kk, False)
        np.testing.assert_array_equal(C, 0.0)
    # the factorisation: K = [[1, a], [a, a^2 + 2^-20]] ... its second pivot is 2^-20 exactly
    # only when a*a is rounded before the subtraction
    K = sp.csr_matrix(np.array([[1.0, a], [a, a * a + 2.0**-20]]))
    chol = SparseCholesky(K, perm=np.array([0, 1]))
    assert chol.Lx[chol.Lpx[-1] - 1] == 2.0**-10


def test_orthonormal_columns_match_lapack_qr():
    """Against LAPACK's QR with the signs of ``R``'s diagonal made positive (the unique thin
    QR of a full-rank matrix): both are backward stable, so they agree to ``cond(A)`` times
    a multiple of epsilon. Orthonormal to a few ulps; layout-independent bits; a zero column
    keeps a unit vector; no columns gives no columns."""
    rng = np.random.default_rng(2)
    for m, k in ((16, 16), (16, 5), (175, 40), (3, 1)):
        A = rng.standard_normal((m, k))
        Q = orthonormal_columns(A)
        Qr, R = np.linalg.qr(A)
        s = np.sign(np.diag(R))
        s[s == 0] = 1.0
        assert np.abs(Q - Qr * s).max() <= 100 * np.linalg.cond(A) * EPS
        assert np.abs(Q.T @ Q - np.eye(k)).max() <= 10 * m * EPS
        np.testing.assert_array_equal(orthonormal_columns(np.asfortranarray(A)), Q)
        np.testing.assert_array_equal(orthonormal_columns(A), Q)
    A = rng.standard_normal((6, 3))
    A[:, 1] = 0.0
    Q = orthonormal_columns(A)
    np.testing.assert_allclose(np.linalg.norm(Q, axis=0), 1.0, rtol=1e-15)
    assert orthonormal_columns(np.zeros((5, 0))).shape == (5, 0)
    with pytest.raises(InvalidInputError, match="k <= m"):
        orthonormal_columns(np.ones((2, 3)))
