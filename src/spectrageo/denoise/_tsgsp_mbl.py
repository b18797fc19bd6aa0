"""Model-based Bayesian learning of the spectral subspace size and the noise variance
(thesis Section 5.1.1, Proposition 1, Eqs. 5.4-5.10, Algorithm 1, Appendix B).

One coordinate ``v = U h + z`` of a submesh (Eqs. 5.2-5.3), prior ``h ~ N(0, gamma Sigma)`` with
Toeplitz ``Sigma_qw = r^|q-w|`` (Eq. 5.10). ``U`` is orthonormal and ``Sigma^-1`` tridiagonal,
so one EM iteration (Eqs. 5.5-5.9, B.17-B.18) costs O(n_l) on ``c = U^T v``. The walk over
``n_l`` ends at the smallest size whose residual ``||v - U H||^2 / n_m`` reaches the reference
(Algorithm 1; found by galloping and bisection, the same size as unit steps).
Notes: docs/decisions.md#denoise-mbl-notes."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .._errors import InvalidInputError

_R_MAX = 0.99
#: statistics the size walk can compare with the reference noise (index = kernel code)
RULES = ("em", "residual")
_TINY = 1e-300


@numba.njit(cache=True)
def _em_fit(c, n_l, rperp2, k, sigma, gamma, r, n_em, H, pdiag, poff, D, lsub, y):
    """``n_em`` EM iterations at size ``n_l``: ``(sigma, gamma, r, resid2, trPi)``."""  # pragma: no cover - jitted
    resid2 = 0.0
    trpi = 0.0
    for _ in range(n_em):
        sig = max(sigma, _TINY)
        gam = max(gamma, _TINY)
        one_r2 = 1.0 - r * r
        # tridiagonal precision A = I/sigma + Sigma^-1/gamma
        off = -r / (gam * one_r2)
        for q in range(n_l):
            if n_l == 1:
                a = 1.0 / gam
            elif q == 0 or q == n_l - 1:
                a = 1.0 / (gam * one_r2)
            else:
                a = (1.0 + r * r) / (gam * one_r2)
            pdiag[q] = 1.0 / sig + a  # temporarily the diagonal of A
        # LDL^T
        D[0] = pdiag[0]
        for q in range(n_l - 1):
            lsub[q] = off / D[q]
            D[q + 1] = pdiag[q + 1] - lsub[q] * off
        # H = A^-1 c / sigma
        y[0] = c[0] / sig
        for q in range(1, n_l):
            y[q] = c[q] / sig - lsub[q - 1] * y[q - 1]
        H[n_l - 1] = y[n_l - 1] / D[n_l - 1]
        for q in range(n_l - 2, -1, -1):
            H[q] = y[q] / D[q] - lsub[q] * H[q + 1]
        # diagonal and first off-diagonal of Pi = A^-1 (Takahashi recursion)
        pdiag[n_l - 1] = 1.0 / D[n_l - 1]
        for q in range(n_l - 2, -1, -1):
            poff[q] = -lsub[q] * pdiag[q + 1]
            pdiag[q] = 1.0 / D[q] - lsub[q] * poff[q]
        # residual ||v - U H||^2 = ||v - U c||^2 + ||c - H||^2
        resid2 = rperp2
        trpi = 0.0
        for q in range(n_l):
            dq = c[q] - H[q]
            resid2 += dq * dq
            trpi += pdiag[q]
        # Eq. (5.7)
        sigma = (resid2 + trpi) / k
        # B = Pi + H H^T: Toeplitz fit (Eq. 5.9-5.10)
        q0 = 0.0
        for q in range(n_l):
            q0 += pdiag[q] + H[q] * H[q]
        q0 /= n_l
        if n_l > 1:
            q1 = 0.0
            for q in range(n_l - 1):
                q1 += poff[q] + H[q] * H[q + 1]
            q1 /= n_l - 1
            ratio = q1 / q0 if q0 > 0 else 0.0
            r = min(abs(ratio), _R_MAX)
            if ratio < 0:
                r = -r
        else:
            r = 0.0
        # Eq. (5.8): gamma = Tr(Sigma^-1 B) / n_l
        one_r2 = 1.0 - r * r
        acc = 0.0
        for q in range(n_l):
            if n_l == 1:
                a = 1.0
            elif q == 0 or q == n_l - 1:
                a = 1.0
            else:
                a = 1.0 + r * r
            acc += a * (pdiag[q] + H[q] * H[q])
        for q in range(n_l - 1):
            acc -= 2.0 * r * (poff[q] + H[q] * H[q + 1])
        gamma = max(acc / (one_r2 * n_l), _TINY)
    return sigma, gamma, r, resid2, trpi


@numba.njit(cache=True)
def _fit_size(c, csum, vnorm2, k, n_l, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, stat):
    """EM at size ``n_l`` from the standard start: ``(statistic, gamma, r, resid2, trPi)``."""  # pragma: no cover
    sigma = max(sigma_ref, _TINY)
    mean_c2 = csum[n_l] / n_l
    gamma = max(mean_c2 - sigma, 1e-3 * max(mean_c2, _TINY))
    rperp2 = max(vnorm2 - csum[n_l], 0.0)
    out = _em_fit(c, n_l, rperp2, k, sigma, gamma, 0.0, n_em, H, pdiag, poff, D, lsub, y)
    if stat == 1:  # Algorithm 1 as written: ||v - U H||^2 / n_m
        return out[3] / k, out[1], out[2], out[3], out[4]
    return out  # the EM noise variance of Eq. (5.7)


@numba.njit(cache=True)
def _mbl_search(c, vnorm2, k, sigma_ref, n_init, n_em, tol, n_min, stat):
    """Algorithm 1 for one signal: ``(n_l, sigma, gamma, r, resid2, visits, converged, H)``."""  # pragma: no cover - jitted
    n_max = c.shape[0]
    csum = np.zeros(n_max + 1)
    for q in range(n_max):
        csum[q + 1] = csum[q] + c[q] * c[q]
    H = np.zeros(n_max)
    pdiag = np.zeros(n_max)
    poff = np.zeros(n_max)
    D = np.zeros(n_max)
    lsub = np.zeros(n_max)
    y = np.zeros(n_max)
    upper = sigma_ref * (1.0 + tol)
    n0 = min(max(n_init, n_min), n_max)
    visits = 1
    s0 = _fit_size(c, csum, vnorm2, k, n0, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, stat)[0]
    converged = True
    if s0 <= upper:
        # n0 meets the noise level: gallop down to a size that does not
        hi = n0
        lo = n_min - 1
        step = 1
        while True:
            cand = hi - step
            if cand < n_min:
                break
            visits += 1
            s = _fit_size(
                c, csum, vnorm2, k, cand, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, stat
            )[0]
            if s <= upper:
                hi = cand
                step *= 2
            else:
                lo = cand
                break
    else:
        # too much signal counted as noise: gallop up
        lo = n0
        hi = -1
        step = 1
        while True:
            cand = lo + step
            if cand >= n_max:
                cand = n_max
            visits += 1
            s = _fit_size(
                c, csum, vnorm2, k, cand, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, stat
            )[0]
            if s <= upper:
                hi = cand
                break
            lo = cand
            if cand == n_max:
                break
            step *= 2
        if hi < 0:
            hi = n_max
            converged = False
    # bisection: lo fails (or is below n_min), hi meets the noise level
    while hi - lo > 1:
        mid = (lo + hi) // 2
        visits += 1
        s = _fit_size(c, csum, vnorm2, k, mid, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, stat)[0]
        if s <= upper:
            hi = mid
        else:
            lo = mid
    sigma, gamma, r, resid2, _ = _fit_size(
        c, csum, vnorm2, k, hi, sigma_ref, n_em, H, pdiag, poff, D, lsub, y, 0
    )
    return hi, sigma, gamma, r, resid2, visits, converged, H[:hi].copy()


@dataclass(frozen=True)
class MBLResult:
    """Result of :func:`mbl_subspace` (``coefficients``: the posterior mean ``H`` of Eq. 5.5)."""

    n_keep: int
    noise_var: float
    coefficients: np.ndarray
    gamma: float
    r: float
    n_iter: int
    converged: bool
    residual: float


def mbl_subspace(
    v,
    U,
    *,
    noise_var: float,
    n_init: int | None = None,
    n_em: int = 10,
    tol: float = 0.1,
    n_min: int = 1,
    rule: str = "residual",
) -> MBLResult:
    """Learn the subspace size and noise variance of one signal ``v`` (k,) on the orthonormal basis
    ``U`` (k, n_max), lowest frequency first (Algorithm 1), against the reference ``noise_var``
    (Eq. 5.15); ``n_init``, ``n_em``, ``tol``, ``n_min`` and ``rule`` as in Algorithm 1."""
    v = np.asarray(v, dtype=np.float64)
    U = np.asarray(U, dtype=np.float64)
    if v.ndim != 1:
        raise InvalidInputError(f"`v` must be a 1-D signal; got shape {v.shape}.")
    if U.ndim != 2 or U.shape[0] != v.shape[0] or U.shape[1] < 1:
        raise InvalidInputError(f"`U` must have shape ({v.shape[0]}, n_max); got {U.shape}.")
    if not (np.isfinite(noise_var) and noise_var > 0):
        raise InvalidInputError(f"`noise_var` must be > 0; got {noise_var!r}.")
    n_max = U.shape[1]
    n_init = n_max // 2 if n_init is None else int(n_init)
    if not 1 <= n_init <= n_max:
        raise InvalidInputError(f"`n_init` must be in 1..{n_max}; got {n_init}.")
    if not 1 <= n_min <= n_max:
        raise InvalidInputError(f"`n_min` must be in 1..{n_max}; got {n_min}.")
    if n_em < 1:
        raise InvalidInputError(f"`n_em` must be >= 1; got {n_em}.")
    if not tol >= 0:
        raise InvalidInputError(f"`tol` must be >= 0; got {tol!r}.")
    if rule not in RULES:
        raise InvalidInputError(f"`rule` must be one of {', '.join(RULES)}; got {rule!r}.")
    c = U.T @ v
    out = _mbl_search(
        c,
        float(v @ v),
        float(v.shape[0]),
        float(noise_var),
        n_init,
        int(n_em),
        float(tol),
        int(n_min),
        RULES.index(rule),
    )
    n_l, sigma, gamma, r, resid2, steps, conv, H = out
    return MBLResult(
        int(n_l), float(sigma), H, float(gamma), float(r), int(steps), bool(conv), float(resid2)
    )
