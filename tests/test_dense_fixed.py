"""Fixed-order dense kernels of the codec decoders (:mod:`spectrageo.compress._dense_fixed`).

The kernels replace BLAS and LAPACK on the decode path. They are checked here against numpy's
LAPACK-based routines within tolerances (different algorithms and summation orders agree to a
small multiple of the machine epsilon times the matrix norm, the backward-error bound of the
Householder and QL/Jacobi methods), and for what only they promise: the same bits on every call,
for any number of columns, and documented eigenvector signs.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from spectrageo.compress import _dense_fixed as D

from conftest import grid

EPS = np.finfo(np.float64).eps


def _sym(n: int, seed: int) -> np.ndarray:
    A = np.random.default_rng(seed).standard_normal((n, n))
    return A + A.T


def _laplacian(F: np.ndarray, n: int) -> np.ndarray:
    """Dense binary Laplacian ``D - C`` of a triangle mesh."""
    i = F[:, [0, 1, 2]].ravel()
    j = F[:, [1, 2, 0]].ravel()
    C = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    C = ((C + C.T) > 0).astype(np.float64).toarray()
    return np.diag(C.sum(axis=1)) - C


def _q_of(A: np.ndarray, tau: np.ndarray) -> np.ndarray:
    Q = np.eye(A.shape[0])
    D.apply_q(A, tau, Q)
    return Q


@pytest.mark.parametrize("n", [1, 2, 3, 7, 60])
def test_tridiagonalisation_reconstructs_the_matrix(n):
    A = _sym(n, n)
    B = A.copy()
    tau, d, e = D.tridiagonalise(B)
    Q = _q_of(B, tau)
    T = np.diag(d) + np.diag(e[: n - 1], 1) + np.diag(e[: n - 1], -1)
    scale = np.abs(A).sum(axis=1).max()
    # Householder tridiagonalisation is backward stable: errors of order n eps ||A||
    assert np.abs(Q.T @ Q - np.eye(n)).max() < 10 * n * EPS
    assert np.abs(Q @ T @ Q.T - A).max() < 10 * n * EPS * scale
    assert Q[0, 0] == 1.0 and np.all(Q[0, 1:] == 0.0)  # Q leaves the first coordinate alone
    # Q^T applied by the reflectors is the transpose
    Y = np.random.default_rng(1).standard_normal((n, 4))
    Z = Y.copy()
    D.apply_qt(B, tau, Z)
    assert np.abs(Z - Q.T @ Y).max() < 10 * n * EPS * np.abs(Y).max()


def test_tridiagonalisation_skips_zero_columns():
    A = _sym(12, 3)
    A[:5, 5:] = A[5:, :5] = 0.0  # two diagonal blocks: column 4 has nothing to reduce
    B = A.copy()
    tau, d, e = D.tridiagonalise(B)
    assert tau[4] == 0.0
    T = np.diag(d) + np.diag(e[:-1], 1) + np.diag(e[:-1], -1)
    np.testing.assert_allclose(np.linalg.eigvalsh(T), np.linalg.eigvalsh(A), atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 5, 40, 150])
def test_eigh_matches_numpy(n):
    A = _sym(n, 10 + n)
    w, U, info = D.eigh(A)
    w0, U0 = np.linalg.eigh(A)
    scale = np.abs(A).sum(axis=1).max()
    assert info == 0
    assert np.all(np.diff(w) >= 0)  # ascending
    # eigenvalues of a symmetric matrix are perfectly conditioned: |dw| <= backward error
    assert np.abs(w - w0).max() < 20 * n * EPS * scale
    assert np.abs(U.T @ U - np.eye(n)).max() < 20 * n * EPS
    assert np.abs(A @ U - U * w).max() < 20 * n * EPS * scale
    # random spectra are well separated: eigenvectors agree up to sign (then exactly signed)
    i = np.argmax(np.abs(U0), axis=0)
    U0 = U0 * np.sign(U0[i, np.arange(n)])
    gap = np.min(np.diff(w0)) if n > 1 else 1.0
    assert np.abs(U - U0).max() < 100 * n * EPS * scale / gap


def test_eigenvector_sign_convention():
    """Every eigenvector's largest-magnitude entry (the first of equal ones) is positive."""
    V, F = grid(9, 7)
    L = _laplacian(F, len(V))
    for _w, U, _info in (D.eigh(L), D.eigh_lowest(L, 10), D.eigh(_sym(30, 2))):
        i = np.argmax(np.abs(U), axis=0)
        assert np.all(U[i, np.arange(U.shape[1])] > 0)
    # ties: the first of two entries of equal magnitude decides
    U = np.array([[-1.0, 0.5], [1.0, -0.5], [0.0, 0.0]])
    D.fix_signs(U)
    np.testing.assert_array_equal(U, [[1.0, 0.5], [-1.0, -0.5], [0.0, 0.0]])


def test_eigh_lowest_is_the_first_columns_of_eigh_on_a_laplacian():
    V, F = grid(12, 10)
    L = _laplacian(F, len(V))
    w, U, info = D.eigh(L)
    wk, Uk, infok = D.eigh_lowest(L, 17)
    assert info == infok == 0
    # same operations on each column: the truncated basis is the full one's first columns
    np.testing.assert_array_equal(wk, w[:17])
    np.testing.assert_array_equal(Uk, U[:, :17])
    assert abs(w[0]) < 1e-12  # connected: one zero eigenvalue, constant eigenvector
    np.testing.assert_allclose(U[:, 0], 1 / np.sqrt(len(V)), atol=1e-12)


def test_jacobi_fallback_matches_numpy():
    A = _sym(25, 4)
    w, U, info = D.eigh_jacobi(A)
    order = np.argsort(w)
    w, U = w[order], U[:, order]
    assert info == 0
    np.testing.assert_allclose(w, np.linalg.eigvalsh(A), atol=1e-12 * np.abs(A).max() * 25)
    assert np.abs(U.T @ U - np.eye(25)).max() < 1e-13
    assert np.abs(A @ U - U * w).max() < 1e-12 * np.abs(A).max() * 25


def test_repeated_calls_are_bit_identical():
    A = _sym(80, 5)
    Y = np.random.default_rng(6).standard_normal((200, 12))
    first = (D.eigh(A), D.qr(Y), D.svd(Y), D.matmul(Y, A[:12, :9]), D.matmul_tn(Y, Y))
    for _ in range(3):
        again = (D.eigh(A), D.qr(Y), D.svd(Y), D.matmul(Y, A[:12, :9]), D.matmul_tn(Y, Y))
        for a, b in zip(first, again):
            for x, y in zip(
                a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,)
            ):
                np.testing.assert_array_equal(x, y)


def test_columns_are_transformed_independently():
    """Batched signals (pca-spectral synthesises many at once) get the bits of single ones."""
    A = _sym(50, 7)
    B = A.copy()
    tau, d, e = D.tridiagonalise(B)
    cap = 2 * 50 * 50
    z = np.zeros(50)
    z[0] = 1.0
    idx, cs, sn, M, info = D.ql_rotations(
        d, e, np.empty(cap, np.int32), np.empty(cap), np.empty(cap), z
    )
    e0 = np.zeros((50, 1))
    e0[0] = 1.0
    D.rotate_t(idx, cs, sn, M, e0)
    np.testing.assert_array_equal(z, e0[:, 0])  # the row tracked during the iteration
    Y = np.random.default_rng(8).standard_normal((50, 7))
    for apply in (
        lambda Z: D.apply_q(B, tau, Z),
        lambda Z: D.apply_qt(B, tau, Z),
        lambda Z: D.rotate(idx, cs, sn, M, Z),
        lambda Z: D.rotate_t(idx, cs, sn, M, Z),
    ):
        Z = Y.copy()
        apply(Z)
        for c in range(7):
            z = np.ascontiguousarray(Y[:, c : c + 1])
            apply(z)
            np.testing.assert_array_equal(z[:, 0], Z[:, c])


def test_matmul_sums_in_ascending_order():
    rng = np.random.default_rng(9)
    A = rng.standard_normal((4, 30))
    B = rng.standard_normal((30, 5))
    want = np.zeros((4, 5))
    for i in range(4):
        for j in range(5):
            acc = 0.0
            for t in range(30):
                acc += A[i, t] * B[t, j]
            want[i, j] = acc
    np.testing.assert_array_equal(D.matmul(A, B), want)
    np.testing.assert_array_equal(D.matmul_tn(np.ascontiguousarray(A.T), B), want)


@pytest.mark.parametrize("shape", [(9, 9), (300, 5), (40, 17)])
def test_qr_and_svd_match_numpy(shape):
    m, n = shape
    Y = np.random.default_rng(m + n).standard_normal(shape)
    Q, R = D.qr(Y)
    assert np.abs(Q.T @ Q - np.eye(n)).max() < 10 * m * EPS
    assert np.all(np.tril(R, -1) == 0)
    assert np.abs(Q @ R - Y).max() < 10 * m * EPS * np.abs(Y).max()
    np.testing.assert_array_equal(D.r_factor(Y), R)
    U, s, V, info = D.svd(Y)
    s0 = np.linalg.svd(Y, compute_uv=False)
    assert info == 0 and np.all(np.diff(s) <= 0)
    # one-sided Jacobi is accurate to a few eps relative to the largest singular value
    assert np.abs(s - s0).max() < 50 * m * EPS * s0[0]
    assert np.abs(U.T @ U - np.eye(n)).max() < 50 * m * EPS * s0[0] / s0[-1]
    assert np.abs(V.T @ V - np.eye(n)).max() < 50 * m * EPS
    assert np.abs((U * s) @ V.T - Y).max() < 50 * m * EPS * s0[0]
    s2, V2, _ = D.svd_values(Y)
    np.testing.assert_array_equal(s2, s)
    np.testing.assert_array_equal(V2, V)


def test_svd_of_a_rank_deficient_matrix():
    rng = np.random.default_rng(11)
    Y = rng.standard_normal((60, 3)) @ rng.standard_normal((3, 6))
    U, s, V, info = D.svd(Y)
    assert info == 0
    assert np.all(s[3:] < 1e-13 * s[0])
    assert np.abs((U * s) @ V.T - Y).max() < 1e-12 * s[0]


def test_hypot_is_exact_on_triples_and_does_not_overflow():
    assert D.hypot(3.0, 4.0) == 5.0
    assert D.hypot(-5.0, 12.0) == 13.0
    assert D.hypot(0.0, 0.0) == 0.0
    assert D.hypot(3e300, 4e300) == pytest.approx(5e300, rel=4 * EPS)
    assert D.hypot(1e-300, 0.0) == 1e-300


def test_reverse_cuthill_mckee_is_a_deterministic_banded_ordering():
    V, F = grid(15, 12)
    n = len(V)
    shuffle = np.random.default_rng(12).permutation(n)
    inv = np.empty(n, np.int64)
    inv[shuffle] = np.arange(n)
    L = sp.csr_matrix(_laplacian(inv[F], n))
    ptr, ind = L.indptr.astype(np.int64), L.indices.astype(np.int64)
    perm = D.reverse_cuthill_mckee(ptr, ind)
    np.testing.assert_array_equal(np.sort(perm), np.arange(n))
    np.testing.assert_array_equal(D.reverse_cuthill_mckee(ptr, ind), perm)

    def bandwidth(M):
        r, c = M.nonzero()
        return int(np.abs(r - c).max())

    assert bandwidth(L[perm][:, perm]) <= 20 < bandwidth(L)


def test_shifted_solves_match_a_dense_solve():
    V, F = grid(10, 8)
    n = len(V)
    A = _laplacian(F, n) + 0.05 * np.eye(n)
    S = sp.csr_matrix(A)
    perm = D.reverse_cuthill_mckee(S.indptr.astype(np.int64), S.indices.astype(np.int64))
    P = S[perm][:, perm].tocsr()
    Rp, Ri, Rx, ok = D.envelope_cholesky(
        P.indptr.astype(np.int64), P.indices.astype(np.int64), P.data
    )
    assert ok
    Lp, Li, Lx = D.transpose_rows(Rp, Ri, Rx)
    Y = np.random.default_rng(13).standard_normal((n, 4))
    Z = np.ascontiguousarray(Y[perm])
    D.solve_power(Lp, Li, Lx, Rp, Ri, Rx, Z, 2)
    want = np.linalg.solve(A, np.linalg.solve(A, Y))
    want /= np.linalg.norm(want, axis=0)  # the columns are normalised after every solve
    out = np.empty_like(Z)
    out[perm] = Z
    np.testing.assert_allclose(out, want, atol=1e-11)
    # not positive definite: reported, not an exception
    bad = sp.csr_matrix(_laplacian(F, n) - 0.05 * np.eye(n))
    assert not D.envelope_cholesky(
        bad.indptr.astype(np.int64), bad.indices.astype(np.int64), bad.data
    )[3]


def test_layered_rpca_follows_the_library_iteration():
    """The fixed-order RPCA of the layered decoder (``fine=True``) runs the iteration of
    :func:`spectrageo.linalg.rpca`; only the SVDs differ (Jacobi instead of LAPACK), so the
    low-rank parts agree to rounding amplified by the iteration (measured: below 1e-13)."""
    from spectrageo.compress._layered_reconstruct import _rpca_low_rank
    from spectrageo.linalg import rpca

    rng = np.random.default_rng(14)
    for m, n in ((2000, 12), (15, 30)):
        M = rng.standard_normal((m, 3)) @ rng.standard_normal((3, n))
        M += (rng.random((m, n)) < 0.05) * 5 * rng.standard_normal((m, n))
        want = rpca(M, on_nonconvergence="ignore", max_iter=100, tol=1e-5).low_rank
        got = _rpca_low_rank(M, max_iter=100, tol=1e-5)
        assert got.shape == M.shape
        assert np.abs(got - want).max() < 1e-10 * np.abs(want).max()
        np.testing.assert_array_equal(_rpca_low_rank(M, max_iter=100, tol=1e-5), got)
    assert not _rpca_low_rank(np.zeros((10, 6))).any()
