"""RPCA (Eq. 4.16-4.23, 5.29-5.35): planted low-rank + sparse recovery, chunked vs dense paths,
non-convergence reporting and input validation."""

from __future__ import annotations

import dataclasses
import importlib
import warnings

import numpy as np
import pytest

from spectrageo import ConvergenceError, ConvergenceWarning, InvalidInputError
from spectrageo.linalg import RPCAResult, RPCASolverOptions, rpca
from spectrageo.linalg._chunked import CoreAccumulator
from spectrageo.linalg._common import estimate_rank, noise_sigma_from_singular_values

# the package re-exports the function `rpca`, which shadows the submodule as an attribute
rpca_mod = importlib.import_module("spectrageo.linalg.rpca")


def planted(m=200, n=200, r=5, frac=0.05, seed=0):
    """Low-rank L (entries ~ N(0, r)) plus gross errors of magnitude 10..50 on ``frac`` entries."""
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(m, r)) @ rng.normal(size=(r, n))
    mask = rng.random((m, n)) < frac
    S = np.where(mask, rng.choice([-1.0, 1.0], (m, n)) * rng.uniform(10, 50, (m, n)), 0.0)
    return L, S


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def knn_like(m_points=2000, k=10, seed=0, offset=0.0):
    """A tall (3 m_points, k + 1) matrix shaped like the kNN patch matrix of Eq. 5.98."""
    rng = np.random.default_rng(seed)
    P = rng.random((m_points, 3)) + offset
    nb = P[:, None, :] + 0.01 * rng.normal(size=(m_points, k, 3))
    M = np.concatenate([P[:, None, :], nb], axis=1).transpose(0, 2, 1).reshape(3 * m_points, k + 1)
    out = rng.choice(m_points, m_points // 20, replace=False)
    M[3 * out, 0] += rng.uniform(0.3, 1.0, out.size)  # gross error on x of the centre point
    return M


# ---------------------------------------------------------------------------------------------
# PCP by inexact ALM


@pytest.mark.parametrize("backend", ["chunked", "dense"])
def test_ialm_recovers_planted_low_rank_plus_sparse(backend):
    L, S = planted()
    M = L + S
    res = rpca(M, options=RPCASolverOptions(backend=backend))
    assert isinstance(res, RPCAResult)
    assert res.converged and res.residual <= 1e-7
    assert rel(res.low_rank, L) < 1e-3
    assert rel(res.sparse, S) < 1e-3
    assert res.rank == 5
    # the stopping rule of Eq. 4.22: ||M - E - S||_F <= 1e-7 ||M||_F
    assert np.linalg.norm(M - res.low_rank - res.sparse) <= 1e-7 * np.linalg.norm(M) * 1.0001
    assert np.linalg.matrix_rank(res.low_rank, tol=1e-6 * np.linalg.norm(L, 2)) == 5


def test_ialm_thesis_fixed_mu_recovers_too():
    L, S = planted(100, 80, 3, seed=3)
    res = rpca(L + S, options=RPCASolverOptions(mu="thesis", backend="dense"))
    assert res.converged
    assert rel(res.low_rank, L) < 1e-3
    # fixed mu = m n / (4 ||M||_1) needs more iterations than the continuation schedule
    assert res.n_iter > rpca(L + S, options=RPCASolverOptions(backend="dense")).n_iter


def test_ialm_chunked_and_dense_agree_and_input_untouched():
    L, S = planted(300, 40, 4, seed=1)
    M = L + S
    M0 = M.copy()
    a = rpca(M, options=RPCASolverOptions(backend="chunked"))
    b = rpca(M, options=RPCASolverOptions(backend="dense"))
    np.testing.assert_array_equal(M, M0)
    assert a.n_iter == b.n_iter
    assert rel(a.low_rank, b.low_rank) < 1e-9
    assert rel(a.sparse, b.sparse) < 1e-9


def test_ialm_wide_matrix_is_transpose_of_tall():
    L, S = planted(30, 120, 3, seed=2)
    a = rpca(L + S)
    b = rpca((L + S).T)
    assert a.low_rank.shape == (30, 120)
    np.testing.assert_allclose(a.low_rank, b.low_rank.T, atol=1e-10)
    np.testing.assert_allclose(a.sparse, b.sparse.T, atol=1e-10)


def test_ialm_rank_cap():
    L, S = planted(120, 100, 6, seed=4)
    res = rpca(L + S, rank=2, on_nonconvergence="ignore", max_iter=300)
    assert res.rank <= 2
    assert np.linalg.matrix_rank(res.low_rank, tol=1e-8 * np.abs(res.low_rank).max()) <= 2


def test_ialm_zero_matrix():
    res = rpca(np.zeros((20, 5)))
    assert res.converged and res.n_iter == 0
    assert not res.low_rank.any() and not res.sparse.any()


def test_tall_skinny_chunks_match_single_pass(monkeypatch):
    M = knn_like(4000)
    ref = rpca(M, options=RPCASolverOptions(backend="dense"))
    one = rpca(M, options=RPCASolverOptions(backend="chunked"))
    monkeypatch.setattr(rpca_mod, "CHUNK_BYTES", 1715 * 11 * 8)  # 7 row chunks of 1715 rows
    many = rpca(M, options=RPCASolverOptions(backend="chunked"))
    assert ref.converged and one.converged and many.converged
    assert many.n_iter == one.n_iter
    np.testing.assert_allclose(many.sparse, one.sparse, atol=1e-10 * np.abs(M).max())
    assert rel(one.low_rank, ref.low_rank) < 1e-8
    assert rel(one.sparse, ref.sparse) < 1e-6


@pytest.mark.slow
def test_tall_skinny_300k_rows_agrees_with_plain_path():
    """A 300000 x 11 patch-like matrix (four row chunks) against the plain full-SVD path."""
    M = knn_like(100_000, seed=5)
    big = rpca(M)  # auto -> chunked
    assert big.converged
    plain = rpca(M, options=RPCASolverOptions(backend="dense"))
    assert big.n_iter == plain.n_iter
    assert rel(big.low_rank, plain.low_rank) < 1e-8
    assert rel(big.sparse, plain.sparse) < 1e-6


def test_ill_conditioned_tall_matrix_uses_tsqr_and_matches_dense():
    # coordinates far from the origin (e.g. UTM): s_min / s_max ~ 1e-7, a plain Gram matrix
    # would lose every digit of the small singular values
    M = knn_like(3000, seed=6, offset=1e4)
    acc = CoreAccumulator(11, "gram")
    acc.add(M)
    assert acc.finish() is None  # rejected: too ill-conditioned
    qr = CoreAccumulator(11, "qr")
    for i in range(0, M.shape[0], 1000):
        qr.add(M[i : i + 1000])
    s_qr, V_qr = qr.finish()
    s_ref = np.linalg.svd(M, compute_uv=False)
    np.testing.assert_allclose(s_qr, s_ref, rtol=1e-9)
    # preconditioned Gram with a nearby factorisation is accurate again
    pg = CoreAccumulator(11, "gram", precond=(s_qr, V_qr))
    pg.add(M + 1e-6)
    s_pg, _ = pg.finish()
    np.testing.assert_allclose(s_pg, np.linalg.svd(M + 1e-6, compute_uv=False), rtol=1e-8)
    a = rpca(M, options=RPCASolverOptions(backend="chunked"), rng=0)
    b = rpca(M, options=RPCASolverOptions(backend="dense"))
    assert a.converged and b.converged
    assert rel(a.sparse, b.sparse) < 1e-5


def test_core_svd_falls_back_to_gesvd_when_gesdd_fails(monkeypatch):
    # LAPACK's gesdd reports no convergence on some finite, nearly rank-deficient matrices
    # (seen on the DAE's temporal rows of an animation): the QR-iteration driver takes over
    M = knn_like(2000, seed=8)
    s_ref = np.linalg.svd(M, compute_uv=False)
    calls = []

    def failing_svd(*args, **kwargs):
        calls.append(1)
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(np.linalg, "svd", failing_svd)
    for mode in ("qr", "gram"):
        acc = CoreAccumulator(11, mode)
        acc.add(M)
        s, V = acc.finish()
        np.testing.assert_allclose(s, s_ref, rtol=1e-8)
        assert np.allclose(V.T @ V, np.eye(11), atol=1e-10)
    assert len(calls) == 2


def test_float32_mode_close_to_float64():
    M = knn_like(3000, seed=7)
    r64 = rpca(M, tol=1e-6)
    r32 = rpca(M, tol=1e-6, options=RPCASolverOptions(dtype="float32"))
    assert r32.low_rank.dtype == np.float32 and r32.sparse.dtype == np.float32
    assert r32.converged
    assert rel(r32.sparse.astype(np.float64), r64.sparse) < 1e-3
    # float32 input is processed in float32 by default
    assert rpca(M.astype(np.float32), tol=1e-6).sparse.dtype == np.float32


# ---------------------------------------------------------------------------------------------
# GoDec bilateral factorisation (Eq. 5.29-5.35)


@pytest.mark.parametrize("backend", ["chunked", "dense"])
def test_godec_hard_threshold_recovers_exactly(backend):
    L, S = planted(seed=0)
    res = rpca(
        L + S,
        method="godec",
        rank=5,
        options=RPCASolverOptions(threshold="hard", backend=backend),
        rng=1,
    )
    assert res.converged
    assert rel(res.low_rank, L) < 1e-5
    assert rel(res.sparse, S) < 1e-5
    assert res.rank == 5


def test_godec_soft_threshold_small_bias():
    L, S = planted(seed=1)
    res = rpca(L + S, method="godec", rank=5, lam=0.5, rng=0)
    assert res.converged
    # soft thresholding (Eq. 5.32) shrinks every outlier by lam: small, not exact
    assert rel(res.low_rank, L) < 5e-2
    assert np.linalg.matrix_rank(res.low_rank, tol=1e-8 * np.abs(res.low_rank).max()) == 5
    # the fixed point satisfies S = D_lam(M - E)
    Z = L + S - res.low_rank
    np.testing.assert_allclose(res.sparse, np.sign(Z) * np.maximum(np.abs(Z) - 0.5, 0), atol=1e-5)


def test_godec_chunked_equals_literal_qr_updates():
    L, S = planted(400, 60, 4, seed=2)
    a = rpca(L + S, method="godec", rank=4, options=RPCASolverOptions(backend="chunked"), rng=3)
    b = rpca(L + S, method="godec", rank=4, options=RPCASolverOptions(backend="dense"), rng=3)
    assert a.n_iter == b.n_iter
    assert rel(a.low_rank, b.low_rank) < 1e-8
    assert rel(a.sparse, b.sparse) < 1e-8


def test_godec_rank_estimate_and_noise_term():
    rng = np.random.default_rng(4)
    L = rng.normal(size=(300, 4)) @ rng.normal(size=(4, 150))
    G = 0.05 * rng.normal(size=L.shape)
    assert estimate_rank(np.linalg.svd(L + G, compute_uv=False), 300, 150) == 4
    res = rpca(L + G, method="godec", noise_aware=True, rng=0)
    assert res.rank == 4
    assert res.noise is not None
    np.testing.assert_allclose(res.low_rank + res.sparse + res.noise, L + G, atol=1e-10)
    assert rel(res.low_rank, L) < 0.02


# ---------------------------------------------------------------------------------------------
# noise-aware model M = E + S + G (Eq. 4.23)


def test_noise_sigma_estimate():
    rng = np.random.default_rng(5)
    L = rng.normal(size=(400, 3)) @ rng.normal(size=(3, 200))
    s = np.linalg.svd(L + 0.1 * rng.normal(size=L.shape), compute_uv=False)
    assert noise_sigma_from_singular_values(s, 400, 200) == pytest.approx(0.1, rel=0.05)


@pytest.mark.parametrize("backend", [pytest.param("chunked", marks=pytest.mark.slow), "dense"])
def test_stable_pcp_separates_noise(backend):
    L, S = planted(300, 200, 5, seed=6)
    rng = np.random.default_rng(7)
    G = 0.05 * rng.normal(size=L.shape)
    M = L + S + G
    res = rpca(M, noise_aware=True, options=RPCASolverOptions(backend=backend))
    assert res.converged and res.noise is not None
    np.testing.assert_allclose(res.low_rank + res.sparse + res.noise, M, atol=1e-9)
    err = rel(res.low_rank, L)
    assert err < 0.02
    # much better than exact PCP, which has to put the dense noise into E or S
    exact = rpca(M)
    assert err < rel(exact.low_rank, L)
    # noise level given explicitly: same model
    res2 = rpca(M, noise_aware=True, options=RPCASolverOptions(noise_level=0.05, backend=backend))
    assert rel(res2.low_rank, L) < 0.02


# ---------------------------------------------------------------------------------------------
# non-convergence


@pytest.mark.parametrize("kw", [{}, {"method": "godec", "rank": 5}, {"noise_aware": True}])
def test_nonconvergence_is_reported(kw):
    L, S = planted(60, 50, 3, seed=8)
    with pytest.warns(ConvergenceWarning, match="did not converge in 1 iterations"):
        res = rpca(L + S, max_iter=1, **kw)
    assert not res.converged and res.n_iter == 1
    with pytest.raises(ConvergenceError, match="did not converge") as info:
        rpca(L + S, max_iter=1, on_nonconvergence="raise", **kw)
    assert isinstance(info.value.partial, RPCAResult)
    assert not info.value.partial.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet = rpca(L + S, max_iter=1, on_nonconvergence="ignore", **kw)
    assert not quiet.converged


# ---------------------------------------------------------------------------------------------
# validation


@pytest.mark.parametrize(
    ("M", "kw", "match"),
    [
        (np.ones(5), {}, r"`M` must be a 2-D array"),
        (np.ones((0, 3)), {}, r"`M` is empty"),
        (np.array([[1.0, np.nan], [0.0, 1.0]]), {}, r"`M` contains NaN or inf"),
        (np.array([["a", "b"]]), {}, r"`M` must be a numeric 2-D array"),
        (np.ones((4, 3)), {"method": "svd"}, r"`method` must be one of"),
        (np.ones((4, 3)), {"backend": "gpu"}, r"`backend` must be one of"),
        (np.ones((4, 3)), {"threshold": "medium"}, r"`threshold` must be one of"),
        (np.ones((4, 3)), {"rank": 0}, r"`rank` must be between 1 and min\(m, n\) = 3; got 0"),
        (np.ones((4, 3)), {"rank": 4}, r"`rank` must be between 1 and min\(m, n\) = 3; got 4"),
        (np.ones((4, 3)), {"rank": 2.5}, r"`rank` must be an integer"),
        (np.ones((4, 3)), {"lam": -1.0}, r"`lam` must be > 0"),
        (np.ones((4, 3)), {"tol": 0.0}, r"`tol` must be > 0"),
        (np.ones((4, 3)), {"max_iter": 0}, r"`max_iter` must be > 0"),
        (np.ones((4, 3)), {"mu": "fast"}, r"`mu` must be one of"),
        (np.ones((4, 3)), {"mu": -2.0}, r"`mu` must be > 0"),
        (np.ones((4, 3)), {"rho": 0.5}, r"`rho` must be >= 1"),
        (np.ones((4, 3)), {"dtype": "int8"}, r"`dtype` must be 'float32' or 'float64'"),
        (np.ones((4, 3)), {"noise_level": -1.0}, r"`noise_level` must be > 0"),
        (np.ones((4, 3)), {"on_nonconvergence": "shout"}, r"`on_nonconvergence` must be one of"),
        (np.ones((4, 3)), {"rng": "seed"}, r"`rng` must be an int seed"),
    ],
)
def test_validation(M, kw, match):
    fields = {f.name for f in dataclasses.fields(RPCASolverOptions)}
    opts = {k: v for k, v in kw.items() if k in fields}
    direct = {k: v for k, v in kw.items() if k not in fields}
    with pytest.raises(InvalidInputError, match=match):
        rpca(M, options=RPCASolverOptions(**opts), **direct)
    with pytest.raises(InvalidInputError, match=match), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        rpca(M, **kw)


def test_legacy_keywords_warn_and_match_options():
    rng = np.random.default_rng(5)
    M = rng.normal(size=(60, 4)) @ rng.normal(size=(4, 30))
    with pytest.warns(DeprecationWarning, match=r"RPCASolverOptions\(backend=\.\.\., mu=\.\.\.\)"):
        old = rpca(M, backend="dense", mu="thesis")
    new = rpca(M, options=RPCASolverOptions(backend="dense", mu="thesis"))
    np.testing.assert_array_equal(old.sparse, new.sparse)
    with pytest.raises(TypeError, match="unexpected keyword argument 'speed'"):
        rpca(M, speed=2)
    with pytest.raises(InvalidInputError, match="`options` must be a RPCASolverOptions"):
        rpca(M, options={"backend": "dense"})


def test_validation_sparse_input():
    import scipy.sparse as sp

    with pytest.raises(InvalidInputError, match=r"`M` must be a dense array"):
        rpca(sp.eye(5, format="csr"))
