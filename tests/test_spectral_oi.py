"""Orthogonal iterations (Eq. 4.7, Algorithms 6-7, Appendix A) and the partitioned low-pass (Eq. 5.45)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from spectrageo._errors import ConvergenceError, ConvergenceWarning, InvalidInputError
from spectrageo.datasets import fandisk
from spectrageo.graph import adjacency_matrix, knn_graph, laplacian_from_adjacency, mesh_laplacian
from spectrageo.spectral import (
    DOIResult,
    LowpassOptions,
    LowpassResult,
    ShiftedFactor,
    SubmeshOptions,
    dynamic_orthogonal_iteration,
    fix_signs,
    lowpass,
    lowpass_whole,
    orthogonal_iteration,
    orthogonal_iteration_result,
    overlapped_submeshes,
    reassemble,
    shifted_factor,
    submesh_eigenbases,
    submesh_eigenbases_result,
    submesh_laplacian,
)

from conftest import icosphere


@pytest.fixture(scope="module")
def fan():
    m = fandisk()
    V, F = m.vertices, m.faces
    C = adjacency_matrix(F, V.shape[0])
    subs = overlapped_submeshes(C, submesh_size=700, rng=0)
    return V, F, C, subs


def _grid_graph(a: int, b: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """4-neighbour a x b grid (Cartesian product of two paths) and its analytic Laplacian spectrum."""

    def path(m):
        i = np.arange(m - 1)
        return sp.csr_matrix(
            (np.ones(2 * i.size), (np.r_[i, i + 1], np.r_[i + 1, i])), shape=(m, m)
        )

    C = (sp.kron(path(a), sp.identity(b)) + sp.kron(sp.identity(a), path(b))).tocsr()
    la = 2 - 2 * np.cos(np.pi * np.arange(a) / a)
    lb = 2 - 2 * np.cos(np.pi * np.arange(b) / b)
    return C, np.sort((la[:, None] + lb[None, :]).ravel())


def _gap_k(w: np.ndarray, lo: int, hi: int) -> int:
    """Subspace size in [lo, hi] with the largest relative gap lambda_{k+1} / lambda_k."""
    ks = np.arange(lo, hi + 1)
    return int(ks[np.argmax(w[ks] / np.maximum(w[ks - 1], 1e-12))])


def _max_angle(A: np.ndarray, B: np.ndarray) -> float:
    return float(sla.subspace_angles(A, B).max())


def test_oi_converges_to_dense_eigh_on_fandisk_submesh(fan):
    _, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[3])
    w, U = np.linalg.eigh(L.toarray())
    k = _gap_k(w, 20, 60)
    rng = np.random.default_rng(0)
    res = orthogonal_iteration_result(
        L, rng.standard_normal((L.shape[0], k)), zeta=4, n_iter=500, tol=1e-11
    )
    assert res.converged and res.residual <= 1e-11
    assert res.n_iter < 500
    assert _max_angle(res.eigenvectors, U[:, :k]) < 1e-6
    np.testing.assert_allclose(res.eigenvalues, w[:k], rtol=1e-8, atol=1e-10)
    # ascending Ritz values, orthonormal, signs fixed
    assert np.all(np.diff(res.eigenvalues) >= 0)
    np.testing.assert_allclose(res.eigenvectors.T @ res.eigenvectors, np.eye(k), atol=1e-12)
    assert np.array_equal(fix_signs(res.eigenvectors), res.eigenvectors)
    idx = np.argmax(np.abs(res.eigenvectors), axis=0)
    assert (res.eigenvectors[idx, np.arange(k)] > 0).all()


def test_oi_on_grid_graph_matches_analytic_spectrum():
    C, lam = _grid_graph(23, 31)
    L = laplacian_from_adjacency(C)
    k = _gap_k(lam, 8, 30)
    U0 = np.random.default_rng(1).standard_normal((L.shape[0], k))
    res = orthogonal_iteration_result(L, U0, zeta=3, n_iter=2000, tol=1e-12)
    assert res.converged
    np.testing.assert_allclose(res.eigenvalues, lam[:k], atol=1e-9)
    _, U = np.linalg.eigh(L.toarray())
    assert _max_angle(res.eigenvectors, U[:, :k]) < 1e-6
    # returns the basis only by default, the same one
    U_only = orthogonal_iteration(L, U0, zeta=3, n_iter=res.n_iter, tol=1e-12)
    np.testing.assert_allclose(U_only, res.eigenvectors, atol=1e-12)


def test_one_iteration_improves_and_factor_is_reusable(fan):
    _, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[0])
    _, U = np.linalg.eigh(L.toarray())
    k = 40
    U0 = np.random.default_rng(2).standard_normal((L.shape[0], k))
    ang = [
        _max_angle(orthogonal_iteration(L, U0, zeta=z)[:, : k // 2], U[:, : k // 2]) for z in (1, 4)
    ]
    assert ang[1] < ang[0]  # a higher power converges faster (Section 4.1.4)
    fac = shifted_factor(L, delta=0.05)
    assert isinstance(fac, ShiftedFactor) and fac.method == "cholesky"
    a = orthogonal_iteration(L, U0, factor=fac, n_iter=3)
    b = orthogonal_iteration(L, U0, delta=0.05, n_iter=3)
    np.testing.assert_allclose(a, b, atol=1e-12)
    # any solve(B) callable (here SciPy's SuperLU) gives the same subspace
    lu = spla.splu((L + 0.05 * sp.identity(L.shape[0])).tocsc())
    c = orthogonal_iteration(L, U0, factor=lu, n_iter=3)
    assert _max_angle(a, c) < 1e-8
    d = orthogonal_iteration(L, U0, factor=lu.solve, n_iter=3)
    assert _max_angle(a, d) < 1e-8


def test_shifted_factor_solves_and_falls_back_when_indefinite(fan):
    V, F, _, subs = fan
    L = submesh_laplacian(C := adjacency_matrix(F, V.shape[0]), subs.parts[2])
    assert C.shape[0] == V.shape[0]
    B = np.random.default_rng(3).standard_normal((L.shape[0], 4))
    fac = ShiftedFactor(L, delta=0.1)
    M = L.toarray() + 0.1 * np.eye(L.shape[0])
    np.testing.assert_allclose(fac.solve(B), np.linalg.solve(M, B), atol=1e-10)
    np.testing.assert_allclose(fac.solve(B[:, 0]), np.linalg.solve(M, B[:, 0]), atol=1e-10)
    # cotangent weights can be negative: L + delta I may be indefinite -> SuperLU
    A = sp.csr_matrix(np.array([[0.0, -3.0, 1.0], [-3.0, 0.0, 1.0], [1.0, 1.0, 0.0]]))
    Lneg = laplacian_from_adjacency(A)
    f2 = ShiftedFactor(Lneg, delta=0.01)
    assert f2.method == "superlu"
    M2 = Lneg.toarray() + 0.01 * np.eye(3)
    np.testing.assert_allclose(f2.solve(np.eye(3)), np.linalg.inv(M2), atol=1e-10)
    with pytest.raises(InvalidInputError, match="must have 3 rows"):
        f2.solve(np.ones(4))


@pytest.mark.slow
def test_submesh_eigenbases_exact_and_tracked(fan):
    _, _, C, subs = fan
    exact = list(submesh_eigenbases(C, subs, 0.1, method="exact"))
    assert [i for i, _, _ in exact] == list(range(len(subs)))
    for i, w, U in exact:
        L = submesh_laplacian(C, subs.parts[i])
        wd = np.linalg.eigvalsh(L.toarray())[: w.size]
        np.testing.assert_allclose(w, wd, atol=1e-9)
        assert U.shape == (700, 70)
        assert np.array_equal(fix_signs(U), U)
    # tracked OI run to convergence: same subspaces where the spectrum has a gap at k (a count of
    # 20 keeps the run short: the convergence factor at 70 columns is ~0.99 per iteration)
    k = 20
    opts = SubmeshOptions(n_iter=3000, tol=1e-11)
    sb = submesh_eigenbases_result(C, subs, k, method="oi", options=opts)
    info = sb.info
    tracked = list(zip(range(len(info)), sb.eigenvalues, sb.eigenvectors))
    assert all(r.converged for r in info[1:]) and info[0].n_iter == 0  # first one: exact (thesis)
    assert all(r.n_iter > 1 for r in info[1:])  # tracked, not recomputed exactly
    checked = 0
    for (i, we, Ue), (_, wo, Uo) in zip(exact, tracked):
        np.testing.assert_allclose(wo, we[:k], atol=1e-7)
        L = submesh_laplacian(C, subs.parts[i])
        lam = np.linalg.eigvalsh(L.toarray())
        if lam[k] - lam[k - 1] > 1e-3:
            assert _max_angle(Uo, Ue[:, :k]) < 1e-6
            checked += 1
    assert checked >= len(subs) // 2


def test_one_step_oi_lowpass_close_to_exact(fan):
    """Thesis claim (Fig. 5.55): one iteration of T^4 per submesh is almost as good as the exact basis."""
    V, F, _, _ = fan
    ex = lowpass(V, F, method="exact").signal
    oi = lowpass(V, F, method="oi", options=LowpassOptions(zeta=4, n_iter=1)).signal
    e_ex = np.linalg.norm(ex - V, axis=1).mean()
    e_oi = np.linalg.norm(oi - V, axis=1).mean()
    assert e_ex > 0
    assert e_oi <= 1.2 * e_ex
    # a single T^1 step is clearly worse: the power matters
    oi1 = lowpass(V, F, method="oi", options=LowpassOptions(zeta=1, n_iter=1)).signal
    assert np.linalg.norm(oi1 - V, axis=1).mean() > e_oi


@pytest.mark.slow
def test_doi_meets_thresholds_for_every_submesh(fan):
    V, F, C, subs = fan
    sb = submesh_eigenbases_result(C, subs, 0.1, method="doi", signal=V)
    info = sb.info
    out = list(zip(range(len(info)), sb.eigenvalues, sb.eigenvectors))
    assert len(info) == len(out) == len(subs)
    sizes = []
    for (i, w, U), r in zip(out, info):
        X = V[subs.parts[i]]
        rho = np.linalg.norm(X - U @ (U.T @ X)) / np.linalg.norm(X - X.mean(axis=0))
        assert rho == pytest.approx(r.residual, rel=1e-9)
        assert r.converged
        assert rho <= 0.03  # eps_high
        assert np.all(np.diff(w) >= 0) and U.shape[1] == w.size == r.size
        sizes.append(r.size)
    assert len(set(sizes)) > 1  # the subspace size adapts per submesh
    # tighter band -> more components
    info2 = submesh_eigenbases_result(
        C,
        subs,
        0.1,
        method="doi",
        signal=V,
        options=SubmeshOptions(eps_low=0.005, eps_high=0.008),
    ).info
    assert all(r.residual <= 0.008 and r.converged for r in info2)
    assert np.mean([r.size for r in info2]) > np.mean(sizes)


def test_doi_grows_and_shrinks_from_a_bad_start(fan):
    V, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[4])
    X = V[subs.parts[4]]
    _, U = np.linalg.eigh(L.toarray())
    small = dynamic_orthogonal_iteration(L, U[:, :5], X, eps_low=0.02, eps_high=0.03)
    big = dynamic_orthogonal_iteration(L, U[:, :200], X, eps_low=0.02, eps_high=0.03, t_max=300)
    for r in (small, big):
        # from too few and from too many columns alike, the iteration lands inside the band
        assert r.converged
        assert 0.02 <= r.residual <= 0.03
    assert small.size > 5 and big.size < 200
    # a band too narrow for one column: stops at the larger subspace, below eps_high
    narrow = dynamic_orthogonal_iteration(L, U[:, :30], X, eps_low=0.0200, eps_high=0.0201)
    assert narrow.converged and narrow.residual <= 0.0201
    # t_max exhausted -> not converged (reported), result still evaluated consistently
    with pytest.warns(
        ConvergenceWarning, match="Dynamic orthogonal iteration did not converge in 2"
    ):
        short = dynamic_orthogonal_iteration(L, U[:, :2], X, eps_low=0.02, eps_high=0.03, t_max=2)
    assert not short.converged and short.size == 3
    with pytest.raises(ConvergenceError) as err:
        dynamic_orthogonal_iteration(
            L, U[:, :2], X, eps_low=0.02, eps_high=0.03, t_max=2, on_nonconvergence="raise"
        )
    assert isinstance(err.value.partial, DOIResult) and err.value.partial.size == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet = dynamic_orthogonal_iteration(
            L, U[:, :2], X, eps_low=0.02, eps_high=0.03, t_max=2, on_nonconvergence="ignore"
        )
    assert not quiet.converged
    # partitioned: one warning naming the count of failed submeshes
    with pytest.warns(ConvergenceWarning, match=r"submeshes did not converge \(doi"):
        opts = SubmeshOptions(t_max=1)
        for _ in submesh_eigenbases(C, subs, 0.1, method="doi", signal=V, options=opts):
            pass


def test_oi_nonconvergence_is_reported(fan):
    _, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[0])
    U0 = np.random.default_rng(0).standard_normal((700, 30))
    with pytest.warns(ConvergenceWarning, match="Orthogonal iteration"):
        res = orthogonal_iteration_result(L, U0, n_iter=2, tol=1e-12)
    assert not res.converged and res.n_iter == 2 and res.residual > 1e-12
    with pytest.raises(ConvergenceError):
        orthogonal_iteration(L, U0, n_iter=2, tol=1e-12, on_nonconvergence="raise")
    with pytest.raises(InvalidInputError, match="`on_nonconvergence` must be one of"):
        orthogonal_iteration(L, U0, on_nonconvergence="loud")
    with pytest.warns(ConvergenceWarning, match=r"submeshes did not converge \(oi"):
        for _ in submesh_eigenbases(C, subs, 20, options=SubmeshOptions(n_iter=1, tol=1e-12)):
            pass


def test_lowpass_keep_all_reproduces_input(fan):
    V, F, _, _ = fan
    out = lowpass(V, F, keep=1.0, method="exact").signal
    np.testing.assert_allclose(out, V, atol=1e-9)
    # a count equal to the submesh size too, also for a 1-D and a 5-D signal
    rng = np.random.default_rng(0)
    X = rng.normal(size=(V.shape[0], 5))
    np.testing.assert_allclose(lowpass(X, F, keep=700, method="exact").signal, X, atol=1e-9)
    x = X[:, 0]
    y = lowpass(x, F, keep=1.0, method="exact").signal
    assert y.shape == x.shape
    np.testing.assert_allclose(y, x, atol=1e-9)


def test_partitioned_exact_close_to_whole_mesh():
    V, F = icosphere(4)  # 2562 vertices
    rng = np.random.default_rng(4)
    Vn = V * (1 + 0.05 * np.sin(4 * V[:, [0]]) * np.cos(3 * V[:, [1]])) + 0.01 * rng.normal(
        size=V.shape
    )
    whole = lowpass_whole(Vn, mesh_laplacian(Vn, F), keep=0.1)
    # the "whole" method is that reference (checked on a smaller sphere: one dense solve is enough)
    Vs, Fs = icosphere(2)
    np.testing.assert_allclose(
        lowpass(Vs, Fs, keep=0.1, method="whole").signal,
        lowpass_whole(Vs, mesh_laplacian(Vs, Fs), keep=0.1),
        atol=1e-10,
    )
    part = lowpass(Vn, F, keep=0.1, method="exact", options=LowpassOptions(submesh_size=500))
    part = part.signal
    e_whole = np.linalg.norm(whole - Vn, axis=1).mean()
    e_part = np.linalg.norm(part - Vn, axis=1).mean()
    assert 0.7 * e_whole < e_part < 1.3 * e_whole
    # both remove the same noise: results are much closer to each other than to the input
    assert np.linalg.norm(part - whole, axis=1).mean() < 0.6 * e_whole


def test_point_cloud_graph_and_weighted_laplacians(fan):
    V, F, C, _ = fan
    a = lowpass(V, F, method="oi", rng=1).signal
    b = lowpass(V, C=C, method="oi", rng=1).signal
    np.testing.assert_array_equal(a, b)
    W = knn_graph(V, 8)
    pc = lowpass(V, C=W, keep=0.1, method="exact").signal
    assert pc.shape == V.shape and np.isfinite(pc).all()
    assert np.linalg.norm(pc - V, axis=1).mean() < 0.1 * np.ptp(V, axis=0).max()

    def smoothed_a_little(out):
        # finite, moved (not the identity), by well under a tenth of the size, and the mean (the
        # DC component, in every low-pass band) is kept
        size = np.ptp(V, axis=0).max()
        d = np.linalg.norm(out - V, axis=1)
        assert np.isfinite(out).all()
        assert d.mean() > 1e-4 * size and d.max() < 0.05 * size
        np.testing.assert_allclose(out.mean(axis=0), V.mean(axis=0), atol=1e-4 * size)

    for kind in ("gaussian", "cotangent"):
        out = lowpass(V, F, laplacian=kind, method="oi").signal
        smoothed_a_little(out)
        full = lowpass(V, F, laplacian=kind, method="exact", keep=1.0).signal
        np.testing.assert_allclose(full, V, atol=1e-8)
    w = lowpass(V, C=W, laplacian="weighted", method="doi").signal
    smoothed_a_little(w)


def test_lowpass_result_diagnostics_and_legacy_keywords(fan):
    V, F, _, _ = fan
    plain = lowpass(V, F, rng=2)
    assert isinstance(plain, LowpassResult) and plain.submeshes == ()
    diag = lowpass(V, F, rng=2, options=LowpassOptions(diagnostics=True))
    assert len(diag.submeshes) > 1 and diag.submeshes[0].n_iter == 0
    np.testing.assert_allclose(diag.signal, plain.signal, atol=1e-9)
    info: list = []
    with pytest.warns(DeprecationWarning, match="`info` is deprecated"):
        old = lowpass(V, F, rng=2, info=info)
    np.testing.assert_array_equal(old.signal, diag.signal)
    assert [r.residual for r in info] == [r.residual for r in diag.submeshes]
    with pytest.warns(
        DeprecationWarning, match=r"LowpassOptions\(submesh_size=\.\.\., zeta=\.\.\.\)"
    ):
        legacy = lowpass(V, F, rng=2, zeta=2, submesh_size=600)
    new = lowpass(V, F, rng=2, options=LowpassOptions(zeta=2, submesh_size=600))
    np.testing.assert_array_equal(legacy.signal, new.signal)
    with pytest.raises(InvalidInputError, match="`zeta` must be > 0"):
        LowpassOptions(zeta=0)


def test_determinism_and_progress_free_iteration(fan):
    V, F, C, subs = fan
    for method in ("oi", "doi"):
        a = lowpass(V, F, method=method, rng=3).signal
        b = lowpass(V, F, method=method, rng=3).signal
        assert np.array_equal(a, b)
    cold = SubmeshOptions(warm_start=False)
    r1 = [U for _, _, U in submesh_eigenbases(C, subs, 20, options=cold, rng=5)]
    r2 = [U for _, _, U in submesh_eigenbases(C, subs, 20, options=cold, rng=5)]
    assert all(np.array_equal(x, y) for x, y in zip(r1, r2))
    # without Rayleigh-Ritz (Algorithm 6 as written) the subspace and the low-pass are the same
    with_rr = list(submesh_eigenbases(C, subs, 20))
    without = list(submesh_eigenbases(C, subs, 20, options=SubmeshOptions(ritz=False)))
    for (i, _, Ua), (_, w, Ub) in zip(with_rr[1:], without[1:]):
        assert np.isnan(w).all()
        x = V[subs.parts[i]]
        np.testing.assert_allclose(Ua @ (Ua.T @ x), Ub @ (Ub.T @ x), atol=1e-9)
    vals = [U @ (U.T @ V[subs.parts[i]]) for i, _, U in with_rr]
    assert reassemble(vals, subs).shape == V.shape


# ------------------------------------------------------------------------------- validation
def test_validation_orthogonal_iteration(fan):
    _, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[0])
    U0 = np.ones((700, 3))
    with pytest.raises(InvalidInputError, match="non-empty square"):
        orthogonal_iteration(sp.csr_matrix((3, 4)), U0)
    with pytest.raises(InvalidInputError, match="`L` contains NaN"):
        orthogonal_iteration(sp.csr_matrix(np.full((2, 2), np.nan)), np.ones((2, 1)))
    with pytest.raises(InvalidInputError, match=r"`U0` must have shape \(700, k\)"):
        orthogonal_iteration(L, np.ones((5, 2)))
    with pytest.raises(InvalidInputError, match="between 1 and 700 columns"):
        orthogonal_iteration(L, np.ones((700, 0)))
    with pytest.raises(InvalidInputError, match="`U0` contains NaN"):
        orthogonal_iteration(L, np.full((700, 2), np.nan))
    with pytest.raises(InvalidInputError, match="`zeta` must be an integer"):
        orthogonal_iteration(L, U0, zeta=1.5)
    with pytest.raises(InvalidInputError, match="`zeta` must be > 0"):
        orthogonal_iteration(L, U0, zeta=0)
    with pytest.raises(InvalidInputError, match="`n_iter` must be > 0"):
        orthogonal_iteration(L, U0, n_iter=0)
    with pytest.raises(InvalidInputError, match="`delta` must be > 0"):
        orthogonal_iteration(L, U0, delta=-1.0)
    with pytest.raises(InvalidInputError, match="`tol` must be >= 0"):
        orthogonal_iteration(L, U0, tol=-1.0)
    with pytest.raises(InvalidInputError, match="`factor` must be"):
        orthogonal_iteration(L, U0, factor=3)


def test_validation_doi(fan):
    V, _, C, subs = fan
    L = submesh_laplacian(C, subs.parts[0])
    U0 = np.eye(700)[:, :5]
    X = V[subs.parts[0]]
    with pytest.raises(InvalidInputError, match=r"`X` must have shape \(700,\)"):
        dynamic_orthogonal_iteration(L, U0, X[:5])
    with pytest.raises(InvalidInputError, match="`X` contains NaN"):
        dynamic_orthogonal_iteration(L, U0, np.full(700, np.nan))
    with pytest.raises(InvalidInputError, match="`eps_low` must be smaller"):
        dynamic_orthogonal_iteration(L, U0, X, eps_low=0.1, eps_high=0.05)
    with pytest.raises(InvalidInputError, match="`eps_high` must be >= 0"):
        dynamic_orthogonal_iteration(L, U0, X, eps_high=-1.0)
    with pytest.raises(InvalidInputError, match="`t_max` must be > 0"):
        dynamic_orthogonal_iteration(L, U0, X, t_max=0)
    with pytest.raises(InvalidInputError, match="`min_size`"):
        dynamic_orthogonal_iteration(L, U0, X, min_size=10, max_size=5)


def test_validation_submesh_eigenbases(fan):
    V, _, C, subs = fan
    with pytest.raises(InvalidInputError, match="`method` must be one of"):
        submesh_eigenbases(C, subs, 0.1, method="svd")
    with pytest.raises(InvalidInputError, match="`laplacian` must be one of"):
        submesh_eigenbases(C, subs, 0.1, laplacian="cotangent")
    with pytest.raises(InvalidInputError, match="`subs` must be a Submeshes"):
        submesh_eigenbases(C, [np.arange(3)], 0.1)
    with pytest.raises(InvalidInputError, match="`C` has 30 vertices"):
        submesh_eigenbases(adjacency_matrix(np.array([[0, 1, 2]]), 30), subs, 0.1)
    for bad in (0, 1.5, 0.0, True, "a"):
        with pytest.raises(InvalidInputError, match="`n_keep` must be"):
            submesh_eigenbases(C, subs, bad)
    with pytest.raises(InvalidInputError, match="`signal` is required"):
        submesh_eigenbases(C, subs, 0.1, method="doi")
    with pytest.raises(InvalidInputError, match="`signal` must have"):
        submesh_eigenbases(C, subs, 0.1, method="doi", signal=V[:10])
    with pytest.raises(InvalidInputError, match="`signal` contains NaN"):
        submesh_eigenbases(C, subs, 0.1, method="doi", signal=np.full_like(V, np.nan))
    with pytest.warns(DeprecationWarning, match="submesh_eigenbases_result"):
        with pytest.raises(InvalidInputError, match="`info` must be a list"):
            submesh_eigenbases(C, subs, 0.1, info=())
    with pytest.raises(InvalidInputError, match="`n_iter` must be > 0"):
        SubmeshOptions(n_iter=0)
    with pytest.raises(InvalidInputError, match="`delta` must be > 0"):
        SubmeshOptions(delta=0.0)
    with pytest.raises(InvalidInputError, match="`tol` must be >= 0"):
        SubmeshOptions(tol=-1.0)
    with pytest.raises(InvalidInputError, match="`eps_low` must be smaller"):
        SubmeshOptions(eps_low=0.1, eps_high=0.05)
    with pytest.raises(InvalidInputError, match="`options` must be a SubmeshOptions"):
        submesh_eigenbases(C, subs, 0.1, options=LowpassOptions())
    with pytest.warns(DeprecationWarning, match=r"SubmeshOptions\(n_iter=\.\.\.\)"):
        with pytest.raises(InvalidInputError, match="`n_iter` must be > 0"):
            submesh_eigenbases(C, subs, 0.1, n_iter=0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'zeta_'"):
        submesh_eigenbases(C, subs, 0.1, zeta_=2)


def test_validation_lowpass(fan):
    V, F, C, _ = fan
    with pytest.raises(InvalidInputError, match="`method` must be one of"):
        lowpass(V, F, method="svd")
    with pytest.raises(InvalidInputError, match="`laplacian` must be one of"):
        lowpass(V, F, laplacian="umbrella")
    with pytest.raises(InvalidInputError, match="give the faces `F`"):
        lowpass(V)
    with pytest.raises(InvalidInputError, match="either `F` or `C`"):
        lowpass(V, F, C=C)
    with pytest.raises(InvalidInputError, match="`C` must have shape"):
        lowpass(V[:10], C=C)
    with pytest.raises(InvalidInputError, match="`V` must have shape"):
        lowpass(np.zeros((2, 2, 2)), F)
    with pytest.raises(InvalidInputError, match="`V` contains NaN"):
        lowpass(np.full_like(V, np.nan), F)
    with pytest.raises(InvalidInputError, match="`F` has vertex indices out of range"):
        lowpass(V[:100], F)
    with pytest.raises(InvalidInputError, match="needs a mesh `F`"):
        lowpass(V, C=C, laplacian="cotangent")
    with pytest.raises(InvalidInputError, match="uses the values of `C`"):
        lowpass(V, F, laplacian="weighted")
    with pytest.raises(InvalidInputError, match="`points` must have shape"):
        lowpass(V[:, :2], F, laplacian="gaussian")
    with pytest.raises(InvalidInputError, match="`keep` must be"):
        lowpass(V, F, keep=1.5, method="whole")
    with pytest.raises(InvalidInputError, match="`n_keep` must be"):
        lowpass(V, F, keep=-3)


@pytest.mark.parametrize("cond_exp", [2, 12])
def test_onorm_cholesky_qr_and_householder_fallback(cond_exp, monkeypatch):
    """Well-conditioned tall blocks take Cholesky QR; ill-conditioned ones fall back to Householder.

    Either way the result is orthonormal and spans the columns of ``Y``.
    """
    from spectrageo.spectral import orthogonal

    rng = np.random.default_rng(cond_exp)
    U, _ = np.linalg.qr(rng.normal(size=(400, 30)))
    V, _ = np.linalg.qr(rng.normal(size=(30, 30)))
    Y = U @ np.diag(np.logspace(0, -cond_exp, 30)) @ V.T
    calls = []
    real_qr = orthogonal.sla.qr
    monkeypatch.setattr(orthogonal.sla, "qr", lambda *a, **k: calls.append(1) or real_qr(*a, **k))
    Q = orthogonal._onorm(Y.copy())
    assert bool(calls) == (cond_exp > 7)  # Householder only for the ill-conditioned block
    np.testing.assert_allclose(Q.T @ Q, np.eye(30), atol=1e-10)
    # same span: projecting Y onto span(Q) leaves it unchanged
    np.testing.assert_allclose(Q @ (Q.T @ Y), Y, atol=1e-9 * np.abs(Y).max())
