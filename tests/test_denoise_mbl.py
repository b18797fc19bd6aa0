"""Model-based Bayesian learning of the subspace size and noise (Algorithm 1, Eq. 5.5-5.10)."""

import numpy as np
import pytest
import scipy.linalg as sla

from spectrageo._errors import InvalidInputError
from spectrageo.denoise._tsgsp_mbl import _em_fit, mbl_subspace


def _dense_em_step(c, rperp2, k, sigma, gamma, r):
    """One EM step written with dense matrices straight from Eq. (5.5)-(5.10) / (B.17)-(B.18)."""
    n_l = c.size
    Sigma = sla.toeplitz(r ** np.arange(n_l))
    Pi0 = gamma * Sigma
    Pi = np.linalg.inv(np.eye(n_l) / sigma + np.linalg.inv(Pi0))  # (B.5)
    H = Pi @ c / sigma  # (B.4) with U^T U = I
    resid2 = rperp2 + np.sum((c - H) ** 2)
    sigma_new = (resid2 + sigma * (n_l - np.trace(Pi @ np.linalg.inv(Pi0)))) / k  # (5.7)
    B = Pi + np.outer(H, H)
    q0, q1 = np.mean(np.diag(B)), np.mean(np.diag(B, -1))
    r_new = np.sign(q1 / q0) * min(abs(q1 / q0), 0.99)  # (5.10)
    Sig_new = sla.toeplitz(r_new ** np.arange(n_l))
    gamma_new = np.trace(np.linalg.solve(Sig_new, B)) / n_l  # (5.8)
    return H, sigma_new, gamma_new, r_new, np.trace(Pi)


@pytest.mark.parametrize("r0", [0.0, 0.4, -0.3])
def test_em_step_matches_dense_formulas(r0):
    rng = np.random.default_rng(1)
    n_l, k = 12, 80
    c = rng.normal(size=n_l) * np.linspace(3, 0.5, n_l)
    rperp2, sigma, gamma = 1.7, 0.2, 2.5
    work = [np.zeros(n_l) for _ in range(6)]
    s, g, r, resid2, trpi = _em_fit(c, n_l, rperp2, float(k), sigma, gamma, r0, 1, *work)
    H_ref, s_ref, g_ref, r_ref, tr_ref = _dense_em_step(c, rperp2, k, sigma, gamma, r0)
    np.testing.assert_allclose(work[0], H_ref, rtol=1e-10)
    np.testing.assert_allclose(trpi, tr_ref, rtol=1e-10)
    np.testing.assert_allclose(s, s_ref, rtol=1e-10)
    np.testing.assert_allclose(r, r_ref, rtol=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-9)
    np.testing.assert_allclose(resid2, rperp2 + np.sum((c - H_ref) ** 2), rtol=1e-12)


def test_mbl_recovers_subspace_size_and_noise():
    rng = np.random.default_rng(4)
    k, n_max, n_true, sigma = 400, 120, 15, 0.05
    U, _ = np.linalg.qr(rng.normal(size=(k, n_max)))
    v = U[:, :n_true] @ rng.normal(0, 2.0, n_true) + rng.normal(0, sigma, k)
    res = mbl_subspace(v, U, noise_var=sigma**2)
    assert n_true - 2 <= res.n_keep <= n_true + 12
    assert 0.6 * sigma**2 < res.noise_var < 1.6 * sigma**2
    assert res.converged and res.n_iter >= 2
    clean = U[:, :n_true] @ (U[:, :n_true].T @ v)
    est = U[:, : res.n_keep] @ res.coefficients
    # the estimate is closer to the clean signal than the noisy one
    noisy_err = np.linalg.norm(v - U[:, :n_true] @ (U[:, :n_true].T @ v))
    assert np.linalg.norm(est - clean) < 0.5 * noisy_err


def test_mbl_grows_when_reference_noise_is_tiny():
    rng = np.random.default_rng(0)
    k, n_max = 200, 40
    U, _ = np.linalg.qr(rng.normal(size=(k, n_max)))
    v = U @ rng.normal(0, 1.0, n_max) + rng.normal(0, 0.5, k)
    small = mbl_subspace(v, U, noise_var=1e-6)
    assert small.n_keep == n_max and not small.converged
    big = mbl_subspace(v, U, noise_var=10.0)
    assert big.n_keep == 1


def test_mbl_validation():
    U = np.linalg.qr(np.random.default_rng(0).normal(size=(20, 5)))[0]
    v = np.ones(20)
    with pytest.raises(InvalidInputError, match="1-D signal"):
        mbl_subspace(np.ones((20, 2)), U, noise_var=1.0)
    with pytest.raises(InvalidInputError, match="`U` must have shape"):
        mbl_subspace(v, U[:10], noise_var=1.0)
    with pytest.raises(InvalidInputError, match="`noise_var` must be > 0"):
        mbl_subspace(v, U, noise_var=0.0)
    with pytest.raises(InvalidInputError, match="`n_init` must be in"):
        mbl_subspace(v, U, noise_var=1.0, n_init=9)
    with pytest.raises(InvalidInputError, match="`n_min` must be in"):
        mbl_subspace(v, U, noise_var=1.0, n_min=0)
    with pytest.raises(InvalidInputError, match="`n_em` must be >= 1"):
        mbl_subspace(v, U, noise_var=1.0, n_em=0)
    with pytest.raises(InvalidInputError, match="`tol` must be >= 0"):
        mbl_subspace(v, U, noise_var=1.0, tol=-1.0)
