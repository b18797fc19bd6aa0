"""NumPy path of the patch RPCA (:func:`spectrageo.outliers.rpca_scores`, ``backend="numpy"``).

Steps 1-7 of one block without numba: exact kNN by a k-d tree, the inexact ALM of Eq. 4.22 on
the patch matrix of Eq. 5.98 as array operations over chunks of rows (``E = X W`` and the Gram
matrices as matrix products), the rebuilt patches and replayed second pass of steps 5-6, and the
tangent weighting of step 7 (batched 3 x 3 eigenproblems). The operators
(:func:`._svt.svt_operator`), the ``mu`` schedule and the stopping rules are those of the numba
kernels (:mod:`._rpca_solver`); the scores agree within rounding
(docs/decisions.md#register-numpy-rpca). It stores ``M`` and ``R`` (about 0.3 kB per point in
float32), so it suits clouds of up to some 10^5 points; steps 8-9 are not available.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, partial
from typing import Any, NamedTuple

import numpy as np

from .._errors import InvalidInputError
from . import _thresholds
from ._common import check_span, knn_chunked, spacing_from
from ._rpca_types import (
    BASELINE_QUANTILE,
    REFINE_MIN_TAU,
    PatchRPCAResult,
    RPCAOptions,
    report,
    scores_deduplicated,
)
from ._svt import RANK_BIN, RANK_FLOOR, svt_operator

__all__ = ["score_numpy"]

#: Points per chunk of the elementwise steps: bounds the temporaries and keeps one chunk's arrays
#: in cache (docs/decisions.md#reg-speed4-robust).
CHUNK = 4_096


def score_numpy(
    X: np.ndarray, k: int, opts: RPCAOptions, *, block_size: int, smoothed: bool = False
) -> PatchRPCAResult:
    """Steps 1-7 of :func:`spectrageo.outliers.rpca_scores` on ``X`` (n, 3) as one block.

    Raises
    ------
    InvalidInputError
        ``n > block_size``, ``clusters`` or a viewpoint (steps 8-9) asked for, or an extent
        the arithmetic cannot hold.
    """
    if opts.clusters or opts.sensor_origin is not None:
        raise InvalidInputError(
            "backend='numpy' computes steps 1-7 only: set clusters=False and give no viewpoint "
            "or grid."
        )
    n = X.shape[0]
    if n > block_size:
        raise InvalidInputError(
            f"backend='numpy' scores one block: at most block_size = {block_size} points; the "
            f"cloud has {n}."
        )
    with _blas_controller().limit(limits=1, user_api="blas"):
        return _score(X, k, opts, block_size, smoothed)


@cache
def _blas_controller() -> Any:
    """A ``threadpoolctl`` controller: the products run on one BLAS thread (their sizes gain
    nothing from threads, and the scores then do not depend on the thread count)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


class FirstPass(NamedTuple):
    """Steps 2-3 of the NumPy patch RPCA (:func:`first_pass`)."""

    Pn: np.ndarray  # (n, 3) centred points in spacings, ``opts.dtype``
    h: float  # the point spacing
    centre: np.ndarray  # (3,) the centroid subtracted
    S1: np.ndarray  # (n, 3) float32 residual vectors of the pass (0 rows without weighting)
    solve: Callable  # the inexact ALM with the options' parameters
    out: tuple  # ``solve``'s result on the patches: scores, E0, n_iter, converged, residual


def first_pass(X: np.ndarray, nb: Any, opts: RPCAOptions, record: list | None) -> FirstPass:
    """Steps 2-3 on the exact kNN ``nb`` (:func:`._common.knn_chunked`): the points centred and
    divided by the spacing, and the inexact ALM (Eq. 4.22) on the patch matrix (Eq. 5.98);
    ``record`` (a list, or None) receives what the replayed second pass needs."""
    h = spacing_from(nb.dmean)
    dt = np.dtype(opts.dtype)
    check_span(X, h, dt)
    centre = X.mean(axis=0)
    Pn = ((X - centre) * (1.0 / h)).astype(dt)
    S1 = np.empty((X.shape[0], 3) if opts.tangent_weight < 1 else (0, 3), dtype=np.float32)
    solve = partial(_ialm, lam=opts.lam, rho=opts.rho, tol=opts.tol, rank_tol=opts.rank_tol,
                    max_iter=opts.max_iter)  # fmt: skip
    return FirstPass(Pn, h, centre, S1, solve, solve(_patches(Pn, nb.idx), S1, record))


def _score(X: np.ndarray, k: int, opts: RPCAOptions, block_size: int, smoothed: bool):
    """:func:`score_numpy` inside the BLAS limit."""
    n = X.shape[0]
    nb = knn_chunked(X, k)
    if nb.n_zero:  # score the distinct positions
        again = partial(score_numpy, opts=opts, block_size=block_size, smoothed=smoothed)
        return scores_deduplicated(X, k, again, {})
    idx = nb.idx
    weighted = opts.tangent_weight < 1
    record: list | None = [] if opts.refine and opts.second_pass == "replay" else None
    first = first_pass(X, nb, opts, record)
    Pn, h, centre, S1, solve = first.Pn, first.h, first.centre, first.S1, first.solve
    scores, E0, n_iter, converged, residual = first.out
    s1, S2, n_refined = scores, S1, 0
    if opts.refine:
        rebuilt, old_idx = _rebuild(X, idx, s1, k)
        n_refined = int(rebuilt.size)
        if n_refined and record is not None:
            scores, S2 = s1.copy(), S1.copy()
            vec = np.empty((n_refined, 3) if weighted else (0, 3), dtype=np.float32)
            sc, e0 = _replay(_patches(Pn, old_idx, rebuilt), _patches(Pn, idx[rebuilt], rebuilt),
                             record, vec)  # fmt: skip
            scores[rebuilt], E0[rebuilt] = sc, e0
            if weighted:
                S2[rebuilt] = vec
        elif n_refined:
            S2 = np.empty_like(S1)
            scores, E0, it2, conv2, res2 = solve(_patches(Pn, idx), S2, None)
            n_iter, converged, residual = max(n_iter, it2), converged and conv2, max(residual, res2)
        else:
            scores = s1.copy()
    if weighted:  # step 7 on the final patches
        w2 = float(opts.tangent_weight) ** 2
        N = _normals(X, idx)
        s1, scores = _tangent_weighted(S1, N, w2), _tangent_weighted(S2, N, w2)
    if opts.refine:
        _subtract_baseline(scores, s1, idx)
        if n_refined:
            idx[rebuilt] = old_idx
    res = PatchRPCAResult(
        scores=scores,
        spacing=h,
        smoothed=E0 * h + centre if smoothed else None,
        n_iter=n_iter,
        converged=converged,
        residual=residual,
        n_blocks=1,
        n_refined=n_refined,
        kth_distance=nb.dlast,
        knn=(np.arange(n), idx),
    )
    report(res, opts.on_nonconvergence, opts.max_iter)
    return res


def _patches(Pn: np.ndarray, nbrs: np.ndarray, centers: np.ndarray | None = None) -> np.ndarray:
    """Rows ``3r + c`` of ``M`` (Eq. 5.98): coordinate ``c`` of ``centers[r]`` (default ``r``)
    and of its neighbours ``nbrs[r]``; shape ``(3 m, k + 1)``."""
    c = np.arange(nbrs.shape[0]) if centers is None else centers
    cols = np.concatenate([c[:, None], nbrs], axis=1)
    return np.ascontiguousarray(Pn[cols].transpose(0, 2, 1).reshape(3 * cols.shape[0], -1))


def _gram(M: np.ndarray) -> np.ndarray:
    """``M^T M`` in float64, by chunks of rows."""
    G = np.zeros((M.shape[1], M.shape[1]))
    for a in range(0, M.shape[0], 3 * CHUNK):
        Md = M[a : a + 3 * CHUNK].astype(np.float64)
        G += Md.T @ Md
    return G


def _buffers(M: np.ndarray) -> tuple[np.ndarray, ...]:
    """Work arrays of :func:`_ialm_pass` for ``M`` (allocated once per solve)."""
    rows = min(M.shape[0], 3 * CHUNK)
    return (*(np.empty((rows, M.shape[1]), dtype=M.dtype) for _ in range(4)),
            np.empty((rows, M.shape[1])))  # fmt: skip


def _ialm_pass(
    M: np.ndarray, R: np.ndarray, ops: tuple, scal: tuple, E0: np.ndarray, S0: np.ndarray,
    V0: np.ndarray, work: tuple,
) -> tuple[np.ndarray, float]:  # fmt: skip
    """One IALM iteration (Eq. 4.22; :func:`._kernels.patch_ialm_pass`): updates ``R`` and the
    first-column ``E0`` (m, 3), scores ``S0`` (m,) and residual vectors ``V0`` (m, 3, or no rows);
    returns the next Gram matrix and ``||M - E - S||_F^2``. ``work``: :func:`_buffers`."""
    W, A, B = ops
    tp, fp, t, f1 = scal
    K = M.shape[1]
    low = 2 * A.shape[1] < K
    G = np.zeros((K, K))
    res2 = 0.0
    cl, Y, X, E, X64 = work
    T = np.empty((X.shape[0], A.shape[1]), dtype=M.dtype) if low else None
    for a in range(0, M.shape[0], 3 * CHUNK):
        b = min(M.shape[0], a + 3 * CHUNK)
        Mc, Rc = M[a:b], R[a:b]
        c, y, x, e, x64 = cl[: b - a], Y[: b - a], X[: b - a], E[: b - a], X64[: b - a]
        np.clip(Rc, -tp, tp, out=c)
        np.multiply(c, fp, out=y)
        np.subtract(Mc, Rc, out=x)
        x += c
        x += y  # the SVT argument
        if low:  # E = X W = (X A) B
            np.matmul(np.matmul(x, A, out=T[: b - a]), B, out=e)
        else:
            np.matmul(x, W, out=e)
        np.subtract(Mc, e, out=Rc)
        Rc += y
        np.clip(Rc, -t, t, out=c)
        y -= c  # -(M - E - S)
        res2 += float(np.einsum("ij,ij->", y, y, dtype=np.float64))
        np.subtract(Mc, Rc, out=x)
        np.multiply(c, f1, out=y)
        x += y  # the next SVT argument
        np.copyto(x64, x)
        G += x64.T @ x64
        p0, p1 = a // 3, b // 3
        sv = (Rc[:, 0] - c[:, 0]).reshape(-1, 3)
        S0[p0:p1] = np.sqrt(np.einsum("ij,ij->i", sv, sv, dtype=np.float64))
        if V0.shape[0]:
            V0[p0:p1] = sv
        E0[p0:p1] = e[:, 0].reshape(-1, 3)
    return G, res2


def _ialm(
    M: np.ndarray, vec: np.ndarray, record: list | None, *, lam: float | None, rho: float,
    tol: float, rank_tol: float, max_iter: int,
) -> tuple[np.ndarray, np.ndarray, int, bool, float]:  # fmt: skip
    """Inexact ALM on the patch matrix ``M`` (:func:`._rpca_solver._patch_ialm`): ``(scores,
    E0, n_iter, converged, residual)``; ``vec`` receives the residual vectors, ``record`` the
    operators of every iteration."""
    m, dt = M.shape[0] // 3, M.dtype.type
    G = _gram(M)
    fro = float(np.sqrt(max(np.trace(G), 0.0)))
    scores, E0 = np.zeros(m), np.zeros((m, 3))
    if fro == 0.0:
        vec[:] = 0.0
        return scores, E0, 0, True, 0.0
    lam = 1.0 / np.sqrt(3.0 * m) if lam is None else float(lam)
    mu = 1.25 / float(np.sqrt(max(np.linalg.eigvalsh(G)[-1], 0.0)))
    mu_max, mu_prev = mu * 1e7, mu
    R = np.zeros_like(M)
    work = _buffers(M)
    bins = np.full(m, -2, dtype=np.int32)
    converged, residual, it = False, np.inf, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - `it` is returned
        ops = tuple(x.astype(dt) for x in svt_operator(G, 1.0 / mu))
        mu_next = min(mu * rho, mu_max)
        scal = (dt(lam / mu_prev), dt(mu_prev / mu), dt(lam / mu), dt(1.0 + mu / mu_next))
        if record is not None:
            record.append((G, mu, (*ops, *scal)))
        G, res2 = _ialm_pass(M, R, ops, scal, E0, scores, vec, work)
        residual = float(np.sqrt(res2)) / fro
        mu_prev, mu = mu, mu_next
        changed = _rank_levels(scores, bins) if rank_tol > 0 else m + 1
        ranked = it > 1 and lam / mu_prev <= RANK_FLOOR and changed <= rank_tol * m
        if residual <= tol or ranked:  # Eq. 4.22's tolerance, or the ranking rule
            converged = True
            break
    return scores, E0, it, converged, residual


def _rank_levels(scores: np.ndarray, bins: np.ndarray) -> int:
    """The ranking rule's levels of ``scores`` (:func:`._kernels.rank_bins`) into ``bins``, in
    place; returns how many points changed level."""
    new = np.full(scores.shape, -1, dtype=np.int32)
    up = scores >= RANK_FLOOR
    new[up] = np.floor(np.log10(scores[up] / RANK_FLOOR) * (1.0 / RANK_BIN))
    changed = int(np.count_nonzero(new != bins))
    bins[:] = new
    return changed


def _replay(M_old: np.ndarray, M_new: np.ndarray, steps: list, vec: np.ndarray):
    """Step 5's second pass (:func:`._rpca_solver._replay_ialm`): the rows whose patches changed
    from ``M_old`` to ``M_new`` rerun the recorded ``mu`` schedule, on their old patches with the
    recorded operators and on the new ones with those of ``G_t - G_t^old + G_t^new``. Returns
    their scores and ``E`` first columns; ``vec`` receives their residual vectors."""
    m = M_old.shape[0] // 3
    dt = M_old.dtype
    scores, E0 = np.zeros(m), np.zeros((m, 3))
    R_old, R_new = np.zeros_like(M_old), np.zeros_like(M_new)
    G_old, G_new = _gram(M_old), _gram(M_new)
    s_old, e_old = np.empty(m), np.empty((m, 3))
    no_vec = np.empty((0, 3), dtype=np.float32)
    work = _buffers(M_old)
    for G, mu, (W, A, B, *scal) in steps:
        ops = tuple(x.astype(dt) for x in svt_operator(G - G_old + G_new, 1.0 / mu))
        G_old = _ialm_pass(M_old, R_old, (W, A, B), scal, e_old, s_old, no_vec, work)[0]
        G_new = _ialm_pass(M_new, R_new, ops, scal, E0, scores, vec, work)[0]
    return scores, E0


def rebuild_rows(idx: np.ndarray, s1: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Step 5's choice: ``(flagged (n,) bool, rows (r,) int64)``, the points whose first-pass
    score reaches the automatic threshold (floored at ``REFINE_MIN_TAU``) and the rows whose
    patch ``idx[i]`` holds more than ``k / 2`` of them; no rows when fewer than ``k + 1`` points
    or all of them are unflagged."""
    tau = max(_thresholds.auto_threshold(s1, minimum=_thresholds.RPCA_MIN_TAU), REFINE_MIN_TAU)
    flagged = s1 >= tau
    n_kept = s1.size - int(np.count_nonzero(flagged))
    if n_kept < k + 1 or n_kept == s1.size:
        return flagged, np.empty(0, dtype=np.int64)
    return flagged, np.flatnonzero(np.count_nonzero(flagged[idx], axis=1) * 2 > k)


def _rebuild(X: np.ndarray, idx: np.ndarray, s1: np.ndarray, k: int) -> tuple[np.ndarray, Any]:
    """Step 5 (:func:`._rpca_core._rebuild_outlier_patches`): the patches with more than ``k / 2``
    flagged points get the ``k`` nearest unflagged points of their centre, in place in ``idx``;
    returns the rebuilt rows and their former neighbour lists."""
    flagged, rebuild = rebuild_rows(idx, s1, k)
    if rebuild.size == 0:
        return rebuild, idx[:0].copy()
    kept = np.flatnonzero(~flagged)
    pos = np.minimum(np.searchsorted(kept, rebuild), kept.size - 1)
    own = np.where(kept[pos] == rebuild, pos, -1)  # an unflagged centre excludes itself
    nb = knn_chunked(X[kept], k, query=X[rebuild], self_index=own)
    old = idx[rebuild]
    idx[rebuild] = kept[nb.idx]
    return rebuild, old


def _normals(X: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Unit normals (n, 3) of the neighbours ``X[idx[i]]`` of every point: the eigenvector of the
    smallest eigenvalue of their covariance (:func:`._kernels.normal_of`: the trigonometric
    eigenvalues, the largest cross product of two rows of ``C - lambda_min I``; ``eigh`` where
    the two smallest eigenvalues are within ``1e-4`` of the largest)."""
    Q = X[idx].transpose(2, 0, 1)  # (3, n, k)
    Q = Q - Q.mean(axis=2, keepdims=True)
    xx, yy, zz, xy, xz, yz = (
        np.einsum("nk,nk->n", Q[a], Q[b])
        for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    )
    q = (xx + yy + zz) / 3.0
    bx, by, bz = xx - q, yy - q, zz - q
    p2 = (bx * bx + by * by + bz * bz + 2.0 * (xy * xy + xz * xz + yz * yz)) / 6.0
    p = np.sqrt(p2)
    det = bx * (by * bz - yz * yz) - xy * (xy * bz - yz * xz) + xz * (xy * yz - by * xz)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.clip(np.nan_to_num(det / (2.0 * p2 * p)), -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    l_max = q + 2.0 * p * np.cos(phi)
    l_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    l_mid = 3.0 * q - l_max - l_min
    rows = (np.stack([xx - l_min, xy, xz]), np.stack([xy, yy - l_min, yz]),
            np.stack([xz, yz, zz - l_min]))  # fmt: skip
    V = np.stack([np.cross(rows[a], rows[b], axis=0) for a, b in ((0, 1), (0, 2), (1, 2))])
    nv = np.square(V).sum(axis=1)  # (3, n)
    best = np.argmax(nv, axis=0)  # the first of equal norms, as the kernel
    cols = np.arange(idx.shape[0])
    N = V[best, :, cols]
    n1 = nv[best, cols]
    ok = (p2 > 0) & (l_mid - l_min > 1e-4 * np.maximum(np.abs(l_max), 1e-300)) & (n1 > 0)
    N[ok] /= np.sqrt(n1[ok])[:, None]
    if not ok.all():
        C = np.stack([xx, xy, xz, xy, yy, yz, xz, yz, zz], axis=1)[~ok].reshape(-1, 3, 3)
        N[~ok] = np.linalg.eigh(C)[1][:, :, 0]
    return N


def _tangent_weighted(S: np.ndarray, N: np.ndarray, w2: float) -> np.ndarray:
    """Step 7 (:func:`._kernels.tangent_weighted_norms`): ``sqrt(<s, n>^2 + w2 |s - <s, n> n|^2)``
    for the residual vectors ``S`` (n, 3) and unit normals ``N`` (n, 3)."""
    s = S.astype(np.float64)
    pn = np.einsum("ni,ni->n", s, N)
    ss = np.einsum("ni,ni->n", s, s)
    return np.sqrt(np.maximum(w2 * ss + (1.0 - w2) * pn * pn, 0.0))


def _subtract_baseline(scores: np.ndarray, s1: np.ndarray, idx: np.ndarray) -> None:
    """Step 6 (:func:`._kernels.subtract_patch_quantile`): ``scores -= Q_q(s1[idx[i]])`` (linear
    interpolation between order statistics, ``q = BASELINE_QUANTILE``), floored at 0, in place."""
    k = idx.shape[1]
    pos = BASELINE_QUANTILE * (k - 1)
    lo = min(int(np.floor(pos)), k - 1)
    hi, g = min(lo + 1, k - 1), pos - lo
    v = np.sort(s1[idx], axis=1)
    np.maximum(scores - (v[:, lo] + g * (v[:, hi] - v[:, lo])), 0.0, out=scores)
