"""Compiled kernels of TSGSP's fine step (Eqs. 5.16-5.23)."""

from __future__ import annotations

import numba
import numpy as np

from .._errors import InvalidInputError
from ..geometry._numba_kernels import max_sq_distance
from ..geometry.features import patch_eigenvalues

_EPS = 1e-12


@numba.njit(cache=True)
def _select_kernel(N, nb, feature, psi, mean, indptr, cand):  # pragma: no cover - jitted
    """Eqs. (5.16)-(5.19) for every feature face over its candidate centres."""
    m = nb.shape[0]
    best = np.arange(m)
    for i in range(m):
        if not feature[i]:
            continue
        top = -np.inf
        for p in range(indptr[i], indptr[i + 1]):
            j = cand[p]
            xi = N[i, 0] * mean[j, 0] + N[i, 1] * mean[j, 1] + N[i, 2] * mean[j, 2]
            om = max_sq_distance(N, i, nb, j)
            score = psi[j] * xi / (np.sqrt(om) + 1e-12)
            if score > top:
                top = score
                best[i] = j
    return best


def select_neighborhoods(
    N: np.ndarray, nb: np.ndarray, feature: np.ndarray, *, eigenvalues: np.ndarray | None = None
) -> np.ndarray:
    """Ideal neighbourhood of every face (Eqs. 5.16-5.19): the centre of the chosen kNN patch.

    A flat face keeps its patch; a feature face takes, among the patches ``P_j`` containing it, the
    one maximising ``psi_j xi_ij / omega_ij`` (Eq. 5.17: ``psi_j = |l_j1 - l_j3| / l_j3``; Eq. 5.18:
    ``xi_ij = <n_i, mean normal of P_j>``; Eq. 5.19: ``omega_ij = max_g ||n_i - n_g||``); ties go
    to the lowest centre. ``N`` (m, 3) unit normals, ``nb`` (m, k) patches (row ``j``: members of
    ``P_j``), ``feature`` (m,) bool, ``eigenvalues`` the ascending patch eigenvalues if known."""
    N = np.ascontiguousarray(N, dtype=np.float64)
    nb = _check_patch_indices(nb)
    feature = np.ascontiguousarray(feature, dtype=np.bool_)
    m = nb.shape[0]
    if not feature.any():
        return np.arange(m, dtype=np.int64)
    lam = patch_eigenvalues(N, nb) if eigenvalues is None else np.asarray(eigenvalues)
    return _select(N, nb, feature, lam, *_inverse_patches(nb))


def _check_patch_indices(nb: np.ndarray) -> np.ndarray:
    """``nb`` as C-contiguous int64 with every entry in ``[0, m)``."""
    nb = np.ascontiguousarray(nb, dtype=np.int64)
    m = nb.shape[0]
    if nb.size and (nb.min() < 0 or nb.max() >= m):
        raise InvalidInputError(
            f"`nb` (kNN patches) must hold face indices in [0, {m}); got "
            f"{int(nb.min())}..{int(nb.max())} (non-finite or overflowing face centroids?)."
        )
    return nb


def _inverse_patches(nb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidates of face ``i``: ``cand[indptr[i]:indptr[i + 1]]``, the centres of its patches."""
    nb = _check_patch_indices(nb)
    m = nb.shape[0]
    indptr, cand, ok = _inverse_kernel(nb)
    if not ok:  # pragma: no cover - guarded above; the kernel's own check is the last line
        raise InvalidInputError(f"patch member indices must be in [0, {m}).")
    return indptr, cand


@numba.njit(cache=True)
def _inverse_kernel(nb):  # pragma: no cover - jitted
    """Counting sort of (centre, member) pairs by member; ``ok`` False for an index out of range."""
    m, k = nb.shape
    indptr = np.zeros(m + 1, dtype=np.int64)
    for j in range(m):
        for q in range(k):
            g = nb[j, q]
            if g < 0 or g >= m:
                return indptr, np.empty(0, dtype=np.int64), False
            indptr[g + 1] += 1
    for i in range(m):
        indptr[i + 1] += indptr[i]
    fill = indptr[:-1].copy()
    cand = np.empty(m * k, dtype=np.int64)
    for j in range(m):
        for q in range(k):
            g = nb[j, q]
            cand[fill[g]] = j
            fill[g] += 1
    return indptr, cand, True


@numba.njit(cache=True)
def _patch_means(N, nb):  # pragma: no cover - jitted
    """Mean normal of every kNN patch."""
    m, k = nb.shape
    out = np.zeros((m, 3))
    for j in range(m):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for q in range(k):
            g = nb[j, q]
            s0 += N[g, 0]
            s1 += N[g, 1]
            s2 += N[g, 2]
        out[j, 0] = s0 / k
        out[j, 1] = s1 / k
        out[j, 2] = s2 / k
    return out


def _select(N, nb, feature, lam, indptr, cand) -> np.ndarray:
    if not feature.any():
        return np.arange(nb.shape[0], dtype=np.int64)
    lam = np.asarray(lam)
    psi = np.abs(lam[:, 0] - lam[:, 2]) / np.maximum(lam[:, 2], _EPS)
    mean = _patch_means(N, nb)
    return _select_kernel(N, nb, feature, np.ascontiguousarray(psi), mean, indptr, cand).astype(
        np.int64
    )


@numba.njit(cache=True)
def _filter_kernel(
    N, Cc, nb, best, active, den_c, den_s, zeta, patch_guide, wa, values
):  # pragma: no cover
    """Eqs. (5.20)-(5.23): bilateral weights (``wa`` the per-face weights, from ``N``) on the
    selected neighbourhoods, ``zeta`` steps of ``D^-1 C_w`` applied to ``values``, unit rows."""
    m, k = nb.shape
    G = np.zeros((m, 3))
    if patch_guide:
        for i in range(m):
            j = best[i]
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for q in range(k):
                g = nb[j, q]
                s0 += wa[g] * N[g, 0]
                s1 += wa[g] * N[g, 1]
                s2 += wa[g] * N[g, 2]
            nrm = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            if nrm > 0:
                G[i, 0] = s0 / nrm
                G[i, 1] = s1 / nrm
                G[i, 2] = s2 / nrm
    else:
        G[:, :] = N
    P = np.empty((m, k))
    for i in range(m):
        j = best[i]
        d = 0.0
        for q in range(k):
            g = nb[j, q]
            e0 = Cc[i, 0] - Cc[g, 0]
            e1 = Cc[i, 1] - Cc[g, 1]
            e2 = Cc[i, 2] - Cc[g, 2]
            dc = e0 * e0 + e1 * e1 + e2 * e2
            e0 = G[i, 0] - G[g, 0]
            e1 = G[i, 1] - G[g, 1]
            e2 = G[i, 2] - G[g, 2]
            dn = e0 * e0 + e1 * e1 + e2 * e2
            w = wa[g] * np.exp(-dc / den_c - dn / den_s) if active[g] else 0.0
            P[i, q] = w
            d += w
        inv = 1.0 / d if d > 0 else 0.0
        for q in range(k):
            P[i, q] *= inv
    A = values.copy()
    B = np.empty((m, 3))
    for _ in range(zeta):
        for i in range(m):
            j = best[i]
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for q in range(k):
                g = nb[j, q]
                p = P[i, q]
                s0 += p * A[g, 0]
                s1 += p * A[g, 1]
                s2 += p * A[g, 2]
            B[i, 0] = s0
            B[i, 1] = s1
            B[i, 2] = s2
        A, B = B, A
    for i in range(m):
        nrm = np.sqrt(A[i, 0] * A[i, 0] + A[i, 1] * A[i, 1] + A[i, 2] * A[i, 2])
        if nrm > 0:
            A[i, 0] /= nrm
            A[i, 1] /= nrm
            A[i, 2] /= nrm
        else:
            A[i, 0] = N[i, 0]
            A[i, 1] = N[i, 1]
            A[i, 2] = N[i, 2]
    return A
