"""Matrix completion (Eq. 5.80-5.89), incremental SVD (Eq. 5.69-5.71), LASSO by ADMM (Eq. 5.96),
Laplacian interpolation (Eq. 4.24-4.27) and the normal-driven vertex update (Eq. 4.28-4.29)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from spectrageo import ConvergenceError, ConvergenceWarning, InvalidInputError
from spectrageo.geometry import face_normals, vertex_normals
from spectrageo.graph import adjacency_matrix, laplacian_from_adjacency
from spectrageo.linalg import (
    CompletionResult,
    IncrementalSVD,
    LassoResult,
    complete_matrix,
    isvd_update,
    laplacian_interpolation,
    lasso,
    update_vertices,
)

from conftest import cube, grid, icosphere


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


# ---------------------------------------------------------------------------------- completion
def low_rank(m, n, r, seed):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(m, r)) @ rng.normal(size=(r, n))


@pytest.mark.parametrize(("m", "n", "seed"), [(150, 150, 0), (200, 120, 1)])
def test_completion_recovers_rank5_from_60_percent(m, n, seed):
    M = low_rank(m, n, 5, seed)
    observed = np.random.default_rng(seed + 10).random(M.shape) < 0.6
    data = np.where(observed, M, np.nan)  # unobserved entries may be anything, NaN included
    res = complete_matrix(data, observed, rng=0)
    assert isinstance(res, CompletionResult)
    assert res.converged and res.residual < 1e-7
    assert rel(res.completed, M) < 1e-5
    assert rel(res.completed[~observed], M[~observed]) < 1e-5
    np.testing.assert_array_equal(res.completed[observed], M[observed])  # keep_observed
    assert res.rank == 5
    # the raw low-rank estimate E is rank 5 as well
    E = complete_matrix(data, observed, keep_observed=False, rng=0).completed
    assert np.linalg.matrix_rank(E, tol=1e-6 * np.linalg.norm(E, 2)) == 5


def test_completion_fully_observed_and_zero():
    M = low_rank(40, 30, 3, 2)
    res = complete_matrix(M, np.ones(M.shape, bool))
    np.testing.assert_array_equal(res.completed, M)
    z = complete_matrix(np.zeros((5, 4)), np.ones((5, 4), bool))
    assert z.converged and not z.completed.any()


def test_completion_nonconvergence_policy():
    M = low_rank(40, 30, 3, 3)
    obs = np.random.default_rng(0).random(M.shape) < 0.6
    with pytest.warns(ConvergenceWarning, match="Matrix completion .* did not converge in 2"):
        res = complete_matrix(M, obs, max_iter=2)
    assert not res.converged and res.n_iter == 2
    with pytest.raises(ConvergenceError) as info:
        complete_matrix(M, obs, max_iter=2, on_nonconvergence="raise")
    assert isinstance(info.value.partial, CompletionResult) and not info.value.partial.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not complete_matrix(M, obs, max_iter=2, on_nonconvergence="ignore").converged


@pytest.mark.parametrize(
    ("M", "obs", "kw", "match"),
    [
        (np.ones(4), np.ones(4, bool), {}, r"`M` must be a non-empty 2-D array"),
        ([["a"]], np.ones((1, 1), bool), {}, r"`M` must be a numeric 2-D array"),
        (np.ones((3, 3)), np.ones((3, 2), bool), {}, r"`observed` must have the shape"),
        (np.ones((3, 3)), np.full((3, 3), 2), {}, r"`observed` must be a boolean mask"),
        (np.ones((3, 3)), np.zeros((3, 3), bool), {}, r"`observed` selects no entry"),
        (np.full((3, 3), np.nan), np.ones((3, 3), bool), {}, r"`M` contains NaN or inf"),
        (np.ones((3, 3)), np.ones((3, 3), bool), {"sv_start": 4}, r"`sv_start` and `sv_max`"),
        (np.ones((3, 3)), np.ones((3, 3), bool), {"sv_max": 0}, r"`sv_max` must be > 0"),
        (np.ones((3, 3)), np.ones((3, 3), bool), {"rho": 0.5}, r"`rho` must be >= 1"),
        (np.ones((3, 3)), np.ones((3, 3), bool), {"mu": -1.0}, r"`mu` must be > 0"),
        (np.ones((3, 3)), np.ones((3, 3), bool), {"tol": 0}, r"`tol` must be > 0"),
        (
            np.ones((3, 3)),
            np.ones((3, 3), bool),
            {"on_nonconvergence": "x"},
            r"`on_nonconvergence`",
        ),
    ],
)
def test_completion_validation(M, obs, kw, match):
    with pytest.raises(InvalidInputError, match=match):
        complete_matrix(M, obs, **kw)


# ---------------------------------------------------------------------------------- ISVD
def test_isvd_matches_full_svd():
    A = np.random.default_rng(0).normal(size=(80, 30))
    inc = IncrementalSVD()
    for j in range(0, 30, 7):  # uneven blocks, the last one of 2 columns
        inc.update(A[:, j : j + 7])
    assert inc.n_columns == 30
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    np.testing.assert_allclose(inc.s, s, rtol=1e-10)
    np.testing.assert_allclose(inc.reconstruct(), A, atol=1e-10)
    # singular vectors equal up to sign
    signs = np.sign(np.sum(inc.U * U, axis=0))
    np.testing.assert_allclose(inc.U * signs, U, atol=1e-8)
    np.testing.assert_allclose(inc.Vt * signs[:, None], Vt, atol=1e-8)
    np.testing.assert_allclose(inc.U.T @ inc.U, np.eye(30), atol=1e-10)


def test_isvd_low_rank_stream_and_truncation():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(100, 4)) @ rng.normal(size=(4, 60))
    inc = IncrementalSVD(compute_v=False)
    for j in range(60):  # one column at a time: the rank stays 4 (redundant directions dropped)
        inc.update(A[:, j])
    assert inc.s.size == 4 and inc.Vt is None
    np.testing.assert_allclose(inc.s, np.linalg.svd(A, compute_uv=False)[:4], rtol=1e-9)
    with pytest.raises(InvalidInputError, match="right singular vectors are not tracked"):
        inc.reconstruct()
    # truncated updates of a full-rank matrix: the best rank-r approximation of the update
    B = rng.normal(size=(50, 20))
    U, s, Vt = np.linalg.svd(B[:, :10], full_matrices=False)
    U2, s2, Vt2 = isvd_update(U, s, Vt, B[:, 10:], rank=5)
    sb = np.linalg.svd(B, compute_uv=False)
    np.testing.assert_allclose(s2, sb[:5], rtol=1e-10)
    Ub, _, Vtb = np.linalg.svd(B, full_matrices=False)
    np.testing.assert_allclose((U2 * s2) @ Vt2, (Ub[:, :5] * sb[:5]) @ Vtb[:5], atol=1e-10)


def test_isvd_validation():
    U, s, Vt = np.eye(4)[:, :2], np.ones(2), np.eye(2)
    with pytest.raises(InvalidInputError, match=r"`s` must have shape \(2,\)"):
        isvd_update(U, np.ones(3), Vt, np.ones((4, 1)))
    with pytest.raises(InvalidInputError, match="`C` must have 4 rows"):
        isvd_update(U, s, Vt, np.ones((3, 1)))
    with pytest.raises(InvalidInputError, match="`Vt` must have 2 rows"):
        isvd_update(U, s, np.eye(3), np.ones((4, 1)))
    with pytest.raises(InvalidInputError, match="`C` contains NaN"):
        isvd_update(U, s, Vt, np.full((4, 1), np.nan))
    with pytest.raises(InvalidInputError, match="`U` must be a 2-D array"):
        isvd_update(np.ones((2, 2, 2)), s, Vt, np.ones((4, 1)))
    with pytest.raises(InvalidInputError, match="`rank` must be > 0"):
        isvd_update(U, s, Vt, np.ones((4, 1)), rank=0)
    with pytest.raises(InvalidInputError, match="`tol` must be >= 0"):
        isvd_update(U, s, Vt, np.ones((4, 1)), tol=-1.0)
    with pytest.raises(InvalidInputError, match="`rank` must be > 0"):
        IncrementalSVD(rank=0)
    inc = IncrementalSVD().update(np.ones((4, 1)))
    with pytest.raises(InvalidInputError, match="`C` must have 4 rows like the previous"):
        inc.update(np.ones((3, 1)))
    with pytest.raises(InvalidInputError, match="no column has been added"):
        IncrementalSVD().reconstruct()


# ---------------------------------------------------------------------------------- LASSO
def _lasso_problem(n, p, seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, p))
    x = np.zeros(p)
    x[rng.choice(p, max(1, p // 8), replace=False)] = rng.normal(scale=3, size=max(1, p // 8))
    return A, A @ x + 0.1 * rng.normal(size=n)


@pytest.mark.parametrize(("n", "p", "alpha"), [(100, 40, 0.1), (40, 100, 0.05), (60, 60, 0.5)])
def test_lasso_matches_scikit_learn(n, p, alpha):
    from sklearn import linear_model

    A, b = _lasso_problem(n, p, seed=n + p)
    res = lasso(A, b, alpha=alpha, tol=1e-10, max_iter=50_000)
    assert isinstance(res, LassoResult) and res.converged
    ref = linear_model.Lasso(alpha=alpha, fit_intercept=False, tol=1e-12, max_iter=100_000).fit(
        A, b
    )
    np.testing.assert_allclose(res.coef, ref.coef_, atol=1e-6)
    # same objective scaling: (1 / (2 n_samples)) ||b - A x||^2 + alpha ||x||_1
    obj_ref = 0.5 / n * np.sum((b - A @ ref.coef_) ** 2) + alpha * np.abs(ref.coef_).sum()
    assert res.objective == pytest.approx(obj_ref, rel=1e-8)
    assert np.array_equal(res.coef == 0, np.abs(ref.coef_) < 1e-12)  # same support, exact zeros


def test_lasso_sparse_matrix_and_several_targets():
    A, b = _lasso_problem(80, 30, seed=5)
    B = np.c_[b, -2 * b, np.zeros_like(b)]
    dense = lasso(A, B, alpha=0.1, tol=1e-10, max_iter=20_000)
    sparse = lasso(sp.csr_matrix(A), B, alpha=0.1, tol=1e-10, max_iter=20_000)
    assert dense.coef.shape == (30, 3)
    np.testing.assert_allclose(sparse.coef, dense.coef, atol=1e-7)
    for j in range(2):
        single = lasso(A, B[:, j], alpha=0.1, tol=1e-10, max_iter=20_000)
        np.testing.assert_allclose(dense.coef[:, j], single.coef, atol=1e-7)
    assert not dense.coef[:, 2].any()
    # alpha = 0 is least squares; a large alpha zeroes everything
    ls = lasso(A, b, alpha=0.0, tol=1e-12, max_iter=20_000)
    np.testing.assert_allclose(ls.coef, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-7)
    big = lasso(A, b, alpha=1e3)
    assert not big.coef.any()


def test_lasso_nonconvergence_policy():
    A, b = _lasso_problem(50, 20, seed=6)
    with pytest.warns(ConvergenceWarning, match=r"LASSO \(ADMM\) did not converge in 3"):
        res = lasso(A, b, alpha=0.1, max_iter=3)
    assert not res.converged and res.n_iter == 3
    with pytest.raises(ConvergenceError, match="did not converge") as info:
        lasso(A, b, alpha=0.1, max_iter=3, on_nonconvergence="raise")
    assert isinstance(info.value.partial, LassoResult)


def test_lasso_validation():
    A, b = np.ones((5, 3)), np.ones(5)
    cases = [
        ((np.ones(5), b), {"alpha": 1.0}, r"`A` must be a non-empty 2-D array"),
        ((np.full((5, 3), np.nan), b), {"alpha": 1.0}, r"`A` contains NaN"),
        ((sp.csr_matrix(np.full((5, 3), np.inf)), b), {"alpha": 1.0}, r"`A` contains NaN"),
        ((A, np.ones(4)), {"alpha": 1.0}, r"`b` must have shape \(5,\)"),
        ((A, np.full(5, np.nan)), {"alpha": 1.0}, r"`b` contains NaN"),
        ((A, b), {"alpha": -1.0}, r"`alpha` must be >= 0"),
        ((A, b), {"alpha": 1.0, "rho": 0.0}, r"`rho` must be > 0"),
        ((A, b), {"alpha": 1.0, "x0": np.ones(4)}, r"`x0` must have 3 entries"),
        ((A, b), {"alpha": 1.0, "max_iter": 0}, r"`max_iter` must be > 0"),
    ]
    for args, kw, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            lasso(*args, **kw)


# ---------------------------------------------------------------------------------- interpolation
def test_interpolation_reproduces_harmonic_functions():
    V, F = grid(15, 12)
    n = V.shape[0]
    L = laplacian_from_adjacency(adjacency_matrix(F, n))
    # on this regular triangulation every interior vertex has the neighbours +-x, +-y, +-(x + y):
    # linear functions are discrete harmonic there
    f = np.c_[2.0 * V[:, 0] - 3.0 * V[:, 1] + 0.5, V[:, 0] + V[:, 1]]
    assert np.abs(L @ f)[_interior(V)].max() < 1e-12
    boundary = np.flatnonzero(~_interior(V))
    w = np.ones(n)
    w[boundary] = 0.0  # no equation at the known vertices: harmonic (Dirichlet) interpolation
    out = laplacian_interpolation(L, boundary, f[boundary], weights=w)
    np.testing.assert_allclose(out, f, atol=1e-10)
    # unweighted thesis form (Eq. 4.27): constants are reproduced exactly
    rng = np.random.default_rng(0)
    known = rng.choice(n, 20, replace=False)
    const = laplacian_interpolation(L, known, np.full(20, 3.5))
    np.testing.assert_allclose(const, 3.5, atol=1e-10)


def _interior(V):
    x, y = V[:, 0], V[:, 1]
    return (x > 1e-9) & (x < 1 - 1e-9) & (y > 1e-9) & (y < 1 - 1e-9)


def test_interpolation_equals_dense_least_squares():
    V, F = icosphere(2)
    n = V.shape[0]
    L = laplacian_from_adjacency(adjacency_matrix(F, n))
    rng = np.random.default_rng(1)
    known = np.sort(rng.choice(n, 40, replace=False))
    vals = rng.normal(size=(40, 3))
    w = rng.uniform(0.5, 2.0, n)
    out = laplacian_interpolation(L, known, vals, weights=w)
    unknown = np.setdiff1d(np.arange(n), known)
    Ld = L.toarray() * np.sqrt(w)[:, None]
    Bu = np.linalg.lstsq(Ld[:, unknown], -Ld[:, known] @ vals, rcond=None)[0]  # Eq. 4.26
    np.testing.assert_allclose(out[unknown], Bu, atol=1e-9)
    np.testing.assert_array_equal(out[known], vals)
    # 1-D values, dense input matrix: same answer column by column
    out1 = laplacian_interpolation(L.toarray(), known, vals[:, 0], weights=w)
    np.testing.assert_allclose(out1, out[:, 0], atol=1e-9)


def test_interpolation_validation():
    V, F = icosphere(1)
    n = V.shape[0]
    L = laplacian_from_adjacency(adjacency_matrix(F, n))
    two = sp.block_diag([L, L]).tocsr()  # two components
    cases = [
        ((np.ones(3), [0], [1.0]), {}, r"`L` must be a square \(n, n\) matrix"),
        ((np.ones((3, 4)), [0], [1.0]), {}, r"`L` must be a square"),
        ((sp.csr_matrix(np.full((2, 2), np.nan)), [0], [1.0]), {}, r"`L` contains NaN"),
        ((L, [[0]], [1.0]), {}, r"`known_idx` must be a 1-D array"),
        ((L, [0.5], [1.0]), {}, r"`known_idx` must be a 1-D array of integer"),
        ((L, np.zeros(0, int), np.zeros(0)), {}, r"`known_idx` is empty"),
        ((L, [n], [1.0]), {}, r"`known_idx` has indices out of range"),
        ((L, [1, 1], [1.0, 2.0]), {}, r"`known_idx` contains repeated"),
        ((L, [0, 1], [1.0]), {}, r"`known_values` must have shape \(2,\)"),
        ((L, [0], [np.nan]), {}, r"`known_values` contains NaN"),
        ((L, [0], [1.0]), {"weights": np.ones(3)}, rf"`weights` must have shape \({n},\)"),
        ((L, [0], [1.0]), {"weights": -np.ones(n)}, r"`weights` must be finite and non-negative"),
        ((two, [0], [1.0]), {}, r"connected component\(s\) of `L` contain no known vertex"),
    ]
    for args, kw, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            laplacian_interpolation(*args, **kw)
    # all known: returned as is
    np.testing.assert_array_equal(
        laplacian_interpolation(L, np.arange(n), np.arange(n) * 1.0), np.arange(n)
    )


# ---------------------------------------------------------------------------------- vertex update
@pytest.mark.parametrize("mesh", ["sphere", "cube"])
def test_update_vertices_recovers_mesh_from_its_face_normals(mesh):
    V, F = icosphere(3) if mesh == "sphere" else cube(4)
    N = face_normals(V, F)
    # the mesh is a fixed point of Eq. 4.29 for its own normals
    np.testing.assert_allclose(update_vertices(V, F, N, n_iter=10), V, atol=1e-12)
    rng = np.random.default_rng(0)
    Vn = V + 0.02 * rng.normal(size=(V.shape[0], 1)) * vertex_normals(V, F)
    Vn0 = Vn.copy()

    def mean_angle(X):
        c = np.clip(np.sum(face_normals(X, F) * N, axis=1), -1, 1)
        return np.degrees(np.arccos(c)).mean()

    out = update_vertices(Vn, F, N, n_iter=100)
    np.testing.assert_array_equal(Vn, Vn0)  # input untouched
    assert mean_angle(Vn) > 5.0
    assert mean_angle(out) < 0.1  # the face normals are restored
    d0 = np.linalg.norm(Vn - V, axis=1).mean()
    d1 = np.linalg.norm(out - V, axis=1).mean()
    assert d1 < 0.15 * d0  # and the positions (up to the drift normals cannot see)
    # fixed vertices do not move; zero target normals leave their faces inactive
    fixed = np.zeros(V.shape[0], bool)
    fixed[::3] = True
    part = update_vertices(Vn, F, N, n_iter=20, fixed=fixed)
    np.testing.assert_array_equal(part[fixed], Vn[fixed])
    np.testing.assert_array_equal(update_vertices(Vn, F, np.zeros_like(N), n_iter=5), Vn)


def test_update_vertices_validation():
    V, F = icosphere(1)
    N = face_normals(V, F)
    with pytest.raises(InvalidInputError, match="`target_normals` must have shape"):
        update_vertices(V, F, N[:3])
    with pytest.raises(InvalidInputError, match="`target_normals` contains NaN"):
        update_vertices(V, F, np.full_like(N, np.nan))
    with pytest.raises(InvalidInputError, match="`fixed` must have shape"):
        update_vertices(V, F, N, fixed=np.ones(3, bool))
    with pytest.raises(InvalidInputError, match="`n_iter` must be"):
        update_vertices(V, F, N, n_iter=-1)


@pytest.mark.parametrize("shape", [(400, 30), (30, 400)])
def test_completion_svt_from_gram_equals_svd(shape):
    """Eq. 5.85-5.86 from the Gram matrix equal the SVD form on tall and wide matrices."""
    from spectrageo.linalg.completion import _svt_gram

    g = np.random.default_rng(3)
    X = g.normal(size=(shape[0], 6)) @ g.normal(size=(6, shape[1])) + 0.01 * g.normal(size=shape)
    U, s, Vt = np.linalg.svd(X, full_matrices=False)
    for k, tau in ((10, 0.5), (4, 2.0), (10, 1e9)):
        shr = np.maximum(s[:k] - tau, 0.0)
        ref = (U[:, :k] * shr) @ Vt[:k]
        E, lam, r = _svt_gram(X, k, tau)
        np.testing.assert_allclose(lam, s[:k], rtol=1e-8)
        assert r == int(np.count_nonzero(shr))
        np.testing.assert_allclose(E, ref, atol=1e-9 * s[0])


def test_spd_factor_solves_anchored_laplacian_normal_equations_with_less_fill():
    """The normal equations of Eq. (5.54) on a sphere (bi-Laplacian plus anchors): the symmetric
    no-pivoting factorisation solves them like a dense solver and keeps fewer factor entries
    than SuperLU's default partial pivoting."""
    from scipy.sparse.linalg import splu

    from spectrageo.linalg._common import spd_factor

    V, F = icosphere(3)
    n = V.shape[0]
    C = adjacency_matrix(F, n)
    C.data[:] = 1.0
    L = laplacian_from_adjacency(C).tocsr()
    a = np.arange(0, n, 37)
    P = sp.csr_matrix((np.ones(a.size), (np.arange(a.size), a)), shape=(a.size, n))
    K = (L.T @ L + P.T @ P).tocsc()
    rhs = np.asarray(L.T @ (L @ V) + P.T @ V[a])
    lu = spd_factor(K)
    assert np.allclose(lu.solve(rhs), np.linalg.solve(K.toarray(), rhs), atol=1e-9)
    assert np.allclose(lu.solve(rhs), V, atol=1e-9)  # the exact deltas and anchors give V back
    default = splu(K)
    assert lu.L.nnz + lu.U.nnz < default.L.nnz + default.U.nnz
