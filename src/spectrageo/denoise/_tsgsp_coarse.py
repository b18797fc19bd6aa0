"""TSGSP's coarse step: per-submesh spectral subspaces learned by MBL (thesis Section 5.1.1,
Algorithm 1, Algorithm 2 lines 1-3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import (
    as_faces,
    as_points,
    as_rng,
    check_choice,
    check_positive,
    options_with_legacy,
)
from ..geometry._numba_kernels import patch_min_variance
from ..graph import adjacency_matrix
from ..graph.adjacency import knn
from ..linalg._common import single_thread_blas
from ..spectral import SubmeshOptions, overlapped_submeshes, reassemble, submesh_eigenbases
from ._tsgsp_mbl import RULES, _mbl_search


@dataclass(frozen=True)
class CoarseOptions:
    """Options of :func:`coarse`, validated on construction."""

    #: vertices per submesh (>= 8); chosen on the tuning split, see
    #: docs/decisions.md#tsgsp-submesh-size
    submesh_size: int = 300
    #: overlap fraction of neighbouring submeshes
    overlap: float = 0.15
    #: largest subspace as a fraction of the submesh size, in (0, 1]; chosen on the tuning
    #: split, see docs/decisions.md#denoise-tsgsp-notes
    max_keep: float = 0.3
    #: "oi" (orthogonal iterations, Eq. 4.7) or "exact" (dense eigendecomposition)
    method: str = "oi"
    #: power of ``(L + delta I)^-1`` and orthogonal iterations per submesh
    zeta: int = 4
    oi_iter: int = 1
    #: EM iterations per subspace size (``b`` of Algorithm 1)
    n_em: int = 10
    #: relative half-width of Algorithm 1's noise band; chosen on the tuning split, see
    #: docs/decisions.md#tsgsp-residual-rule
    tol: float = 0.0
    #: statistic of the size walk: "residual" (Algorithm 1) or "em" (Eq. 5.7)
    rule: str = "residual"
    #: known noise variance ``sigma_z^2``; None: estimated (Eq. 5.15)
    noise_var: float | None = None
    #: patch size of the noise estimate (Eqs. 5.13-5.15); chosen on the tuning split, see
    #: docs/decisions.md#denoise-tsgsp-notes
    noise_patch: int = 12
    #: Laplacian edge weights: "scale" (:func:`scale_weights`, chosen on the tuning split, see
    #: docs/decisions.md#tsgsp-scale-weights) or the thesis's "binary"
    weights: str = "scale"

    def __post_init__(self):
        check_positive(self.submesh_size, "submesh_size", integer=True)
        if self.submesh_size < 8:
            raise InvalidInputError(f"`submesh_size` must be >= 8; got {self.submesh_size}.")
        if not (isinstance(self.max_keep, (int, float)) and 0 < self.max_keep <= 1):
            raise InvalidInputError(f"`max_keep` must be in (0, 1]; got {self.max_keep!r}.")
        check_choice(self.method, "method", ("oi", "exact"))
        check_positive(self.n_em, "n_em", integer=True)
        check_positive(self.tol, "tol", allow_zero=True)
        check_choice(self.rule, "rule", RULES)
        check_choice(self.weights, "weights", ("scale", "binary"))
        if self.noise_var is not None:
            check_positive(self.noise_var, "noise_var")


@dataclass(frozen=True)
class CoarseResult:
    """Result of :func:`coarse`."""

    #: (n, 3) coarse-denoised positions
    vertices: np.ndarray
    #: ``sigma_z^2`` of Eq. (5.15)
    noise_var: float
    #: (n_submeshes, 3) learned ``n_l`` (Algorithm 1)
    subspace_sizes: np.ndarray
    #: (n_submeshes, 3) learned noise variances (Eq. 5.7)
    submesh_noise: np.ndarray
    #: (n_submeshes,) largest size considered
    max_sizes: np.ndarray
    n_submeshes: int
    #: subspace sizes visited by Algorithm 1 in all
    n_iter: int
    #: every signal met the noise band
    converged: bool
    #: RMS displacement ``||V_coarse - V|| / sqrt(n)``
    residual: float


def estimate_noise(V, *, patch: int = 24, F=None, return_directions: bool = False):
    """Noise variance from the minimum-variance direction of local patches (Eqs. 5.13-5.15): the
    median over the vertices of the smallest covariance eigenvalue of each ``patch``-vertex patch,
    times ``k / (k - 3)``; with ``return_directions``, also the (n, 3) unit directions."""
    V = as_points(V, "V")
    check_positive(patch, "patch", integer=True)
    if patch < 4:
        raise InvalidInputError(f"`patch` must be >= 4; got {patch}.")
    k = min(int(patch), V.shape[0])
    if k < 4:
        raise InvalidInputError(
            f"`V` needs at least 4 vertices to estimate noise; got {V.shape[0]}."
        )
    idx, _ = knn(V, k, include_self=True)
    lam = np.empty(V.shape[0])
    dirs = np.empty((V.shape[0], 3))
    patch_min_variance(V, idx, lam, dirs)
    var = float(np.median(np.maximum(lam, 0.0))) * k / (k - 3)
    return (var, dirs) if return_directions else var


def _initial_fractions(e: np.ndarray) -> np.ndarray:
    """Eq. (5.11) as a fraction of the largest subspace, ``exp(-|e~|)`` with ``e~`` the smoothing
    factor of Eq. (5.12) over its median across the submeshes."""
    med = np.median(e, axis=0, keepdims=True)
    et = np.divide(e, med, out=np.ones_like(e), where=med > 0)
    return np.exp(-np.abs(et))


def coarse(V, F, *, options: CoarseOptions | None = None, rng=0, **legacy) -> CoarseResult:
    """Coarse denoising: per-submesh spectral subspaces learned by MBL (Algorithm 1).

    Each coordinate of an overlapped submesh is modelled as ``U_nl h + z`` (Eqs. 5.2-5.3), ``U_nl``
    the lowest-frequency eigenvectors of the submesh Laplacian ``L = D - C`` (Eq. 4.7). EM learns
    ``H``, the noise and the Toeplitz prior (Eqs. 5.5-5.10); ``n_l`` is walked from Eq. (5.11) until
    the residual reaches ``sigma_z^2 mean(u_v^2)`` (Eq. 5.15); the estimates are merged with the
    degree weights of Fig. 5.4. ``V`` needs 8 vertices; ``rng`` seeds METIS and the subspace
    starts; the fields of :class:`CoarseOptions` as keywords and ``full_output`` are deprecated.
    Returns a :class:`CoarseResult`."""
    full_output = legacy.pop("full_output", None)
    options = options_with_legacy(options, legacy, CoarseOptions, "coarse")
    res = _coarse(V, F, options, rng)
    if full_output is None:
        return res
    import warnings

    warnings.warn(
        "coarse(..., full_output=...) is deprecated; coarse returns a CoarseResult (use "
        "`.vertices` for the positions).",
        DeprecationWarning,
        stacklevel=2,
    )
    return res if full_output else res.vertices


def _coarse(V, F, o: CoarseOptions, rng) -> CoarseResult:
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F")
    gen = as_rng(rng)
    if n < 8:
        raise InvalidInputError(
            f"the mesh has {n} vertices; the TSGSP coarse step needs at least 8 vertices "
            "(method 'gnf' or 'bnf' works on smaller meshes)."
        )
    sig2, dirs = estimate_noise(V, patch=o.noise_patch, return_directions=True)
    if o.noise_var is not None:
        sig2 = float(o.noise_var)
    C = adjacency_matrix(F, n)
    if o.weights == "scale":
        C = scale_weights(V, C)
    subs = overlapped_submeshes(C, submesh_size=o.submesh_size, overlap=o.overlap, rng=gen)
    n_sub = len(subs.parts)
    if not sig2 > 0:
        zeros = np.zeros((n_sub, 3))
        none = np.zeros(n_sub, dtype=np.int64)
        return CoarseResult(V.copy(), 0.0, zeros.astype(np.int64), zeros, none, n_sub, 0, True, 0.0)
    Cb = C.copy()
    Cb.data[:] = 1.0
    E = np.empty((n_sub, 3))
    for i, part in enumerate(subs.parts):
        A = Cb[part][:, part]
        X = V[part]
        LX = np.asarray(A.sum(axis=1)).ravel()[:, None] * X - A @ X
        E[i] = np.einsum("ij,ij->j", X, LX)  # smoothing factor e = v^T L v (Eq. 5.12)
    frac0 = _initial_fractions(E)
    # small dense matrices per submesh: one BLAS thread is fastest
    with single_thread_blas():
        values, sizes, noise, maxs, visits, all_conv = _coarse_loop(
            V, C, subs, frac0, sig2, dirs, o, gen,
            "weighted" if o.weights == "scale" else "binary",
        )  # fmt: skip
    out = reassemble(values, subs)
    resid = float(np.linalg.norm(out - V) / np.sqrt(n))
    return CoarseResult(out, sig2, sizes, noise, maxs, n_sub, visits, all_conv, resid)


def scale_weights(V: np.ndarray, C) -> sp.csr_matrix:
    """``C`` reweighted to ``h / ((h_i + h_j) / 2)``, ``h_i`` the median edge length at vertex ``i``
    and ``h`` the median of the ``h_i``."""
    C = sp.csr_matrix(C, dtype=np.float64, copy=True)
    C.sort_indices()
    n = C.shape[0]
    if C.nnz == 0:
        return C
    rows = np.repeat(np.arange(n), np.diff(C.indptr))
    length = np.linalg.norm(V[rows] - V[C.indices], axis=1)
    order = np.lexsort((length, rows))  # lengths sorted within each row
    srt = length[order]
    deg = np.diff(C.indptr)
    has = deg > 0
    lo = C.indptr[:-1] + (deg - 1) // 2
    hi = C.indptr[:-1] + deg // 2
    h = np.zeros(n)
    h[has] = 0.5 * (srt[lo[has]] + srt[hi[has]])
    pos = h[h > 0]
    if pos.size == 0:
        C.data[:] = 1.0
        return C
    h = np.maximum(h, pos.min())
    C.data = float(np.median(h[has])) / (0.5 * (h[rows] + h[C.indices]))
    return C


def _coarse_loop(V, C, subs, frac0, sig2, dirs, o: CoarseOptions, gen, laplacian):
    """Algorithm 1 on every submesh basis."""
    n_sub = len(subs.parts)
    sizes = np.zeros((n_sub, 3), dtype=np.int64)
    maxs = np.zeros(n_sub, dtype=np.int64)
    noise = np.zeros((n_sub, 3))
    values: list[np.ndarray] = [None] * n_sub  # type: ignore[list-item]
    visits = 0
    all_conv = True
    rule_code = RULES.index(o.rule)
    bases = submesh_eigenbases(
        C, subs, o.max_keep, method=o.method, laplacian=laplacian,
        options=SubmeshOptions(zeta=o.zeta, n_iter=o.oi_iter), rng=gen,
    )  # fmt: skip
    for i, _w, U in bases:
        part = subs.parts[i]
        X = V[part]
        k = part.size
        n_max = U.shape[1]
        maxs[i] = n_max
        coef = U.T @ X  # (n_max, 3)
        ref = sig2 * np.mean(dirs[part] ** 2, axis=0)
        n0 = np.clip(np.rint(n_max * frac0[i]).astype(np.int64), 1, n_max)
        Y = np.empty_like(X)
        for j in range(3):
            r = max(float(ref[j]), sig2 * 1e-3)
            nl, s_hat, _g, _r, _res, vis, conv, H = _mbl_search(
                np.ascontiguousarray(coef[:, j]), float(X[:, j] @ X[:, j]), float(k), r,
                int(n0[j]), int(o.n_em), float(o.tol), 1, rule_code,
            )  # fmt: skip
            sizes[i, j] = nl
            noise[i, j] = s_hat
            visits += int(vis)
            all_conv &= bool(conv)
            Y[:, j] = U[:, :nl] @ H
        values[i] = Y
    return values, sizes, noise, maxs, visits, all_conv
