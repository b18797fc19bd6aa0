"""Inexact ALM of the patch RPCA (Eq. 4.22 on the patch matrix of Eq. 5.98), block by block.

Blocks are at most ``block_size`` consecutive points along the Morton curve, each an independent
RPCA whose rows are its patches; the fused kernels of :mod:`._kernels` run one iteration per pass
on disjoint point ranges (fixed by the block size, so results do not depend on the threads).
"""

from __future__ import annotations

import contextlib
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from ..linalg._common import single_thread_blas
from . import _kernels as _k
from ._common import KNN_CHUNK
from ._svt import RANK_BIN, RANK_FLOOR, svt_operator

#: Fewest points per thread of the fused kernels (smaller blocks run on the calling thread).
_MIN_PER_THREAD = 10_000
#: Most point ranges per block of the fused kernels (see :class:`_Ranges`).
_MAX_PARTS = 16
#: Fewest replayed rows whose two passes per iteration run on two threads.
_REPLAY_THREADED = 2048


def solve_blocks(
    Xs: np.ndarray,
    h: float,
    idx: np.ndarray,
    *,
    smoothed: bool,
    lam: float | None,
    rho: float,
    tol: float,
    rank_tol: float,
    max_iter: int,
    block_size: int,
    workers: int,
    dtype: np.dtype,
    vectors: bool = False,
    device: Any = "cpu",
    record: list | None = None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int, bool, float, int]:
    """First-column scores (and ``E`` first column, and the residual vectors ``S[3i:3i+3, 0]``
    when ``vectors``) of every block's patch matrix (sorted order).

    ``record`` (a list), when given, receives per block the list of its iterations' operators
    (:func:`replay_blocks`)."""
    n = Xs.shape[0]
    scores_s = np.empty(n)
    E0_s = np.empty((n, 3)) if smoothed else None
    # the residual vectors of step 7 in float32 (their norms are formed in float64)
    S_s = np.empty((n, 3), dtype=np.float32) if vectors else np.empty((0, 3), dtype=np.float32)
    n_blocks = max(1, -(-n // int(block_size)))
    bounds = np.linspace(0, n, n_blocks + 1).astype(np.int64)
    n_iter, converged, residual = 0, True, 0.0
    n_threads = _n_threads(workers, min(n, int(block_size)))
    inv_h = 1.0 / h
    Pn = np.empty(Xs.shape, dtype=dtype)  # the cloud about each block's centroid, in spacings
    pool_cm = ThreadPoolExecutor(n_threads) if n_threads > 1 else contextlib.nullcontext()
    # LAPACK only sees (k+1)-square eigenproblems (the kernels use no BLAS): keep it on the
    # calling thread (OpenBLAS does not thread such sizes anyway; the limit guards other builds).
    with pool_cm as pool, single_thread_blas():
        for b in range(n_blocks):
            lo, hi = int(bounds[b]), int(bounds[b + 1])
            centre = _normalise(Xs, lo, hi, inv_h, Pn)
            centers = np.arange(lo, hi, dtype=idx.dtype)
            args = (Pn, centers, idx[lo:hi], lam, rho, tol, rank_tol, max_iter, smoothed)
            vec = S_s[lo:hi] if vectors else S_s
            steps: list | None = None
            if record is not None:
                steps = _BlockRecord()
                # one block: its normalised cloud serves the replay as it is
                if n_blocks == 1 and isinstance(device, str):
                    steps.Pn, steps.centre = Pn, centre
                record.append(steps)
            if not isinstance(device, str):  # the torch path (spectrageo.outliers._torch)
                from ._torch import patch_ialm_torch

                out = patch_ialm_torch(*args, vec, device, record=steps)
            else:
                out = _patch_ialm(*args, pool, n_threads, vec, record=steps)
            scores_s[lo:hi] = out[0]
            if smoothed:
                E0_s[lo:hi] = out[1] * h + centre
            n_iter = max(n_iter, out[2])
            converged = converged and out[3]
            residual = max(residual, out[4])
    return scores_s, E0_s, (S_s if vectors else None), n_iter, converged, residual, n_blocks


class _BlockRecord(list):
    """The recorded iterations of one block (:func:`replay_blocks`); when it is the only block,
    also its normalised cloud ``Pn`` and centre (:func:`_normalise`), else None."""

    Pn: np.ndarray | None = None
    centre: np.ndarray | None = None


def _normalise(Xs: np.ndarray, lo: int, hi: int, inv_h: float, Pn: np.ndarray) -> np.ndarray:
    """``Pn = (Xs - c) / h`` for the whole cloud, ``c`` the centroid of the block ``lo .. hi``
    (returned); rounded once from float64 into ``Pn``'s dtype. Shared by both passes
    of step 5, whose replay must see the first pass's coordinates bit for bit."""
    if Xs.dtype != np.float64 or not (Xs.flags.c_contiguous and Pn.flags.c_contiguous):
        centre = Xs[lo:hi].mean(axis=0)
        for c0 in range(0, Xs.shape[0], KNN_CHUNK):
            c1 = min(Xs.shape[0], c0 + KNN_CHUNK)
            Pn[c0:c1] = (Xs[c0:c1] - centre) * inv_h
        return centre
    # compiled, same operations in the same order as above (the mean is numpy's row-by-row sum
    # over axis 0 of an (m, 3) array); docs/decisions.md#outliers-speed-normalise
    centre = np.empty(3)
    _k.centre_and_scale(Xs, lo, hi, inv_h, centre, Pn)
    return centre


def replay_blocks(
    Xs: np.ndarray,
    h: float,
    idx: np.ndarray,
    rows: np.ndarray,
    old_idx: np.ndarray,
    record: list,
    *,
    dtype: np.dtype,
    scores_s: np.ndarray,
    E0_s: np.ndarray | None,
    S_s: np.ndarray | None,
    workers: int = 1,
) -> None:
    """Step 5's second pass: the sorted rows ``rows`` (whose patches were rebuilt from
    ``old_idx`` to ``idx[rows]``) rescored, in place in ``scores_s``, ``E0_s`` and ``S_s``, by
    :func:`_replay_ialm` with the recorded iterations of their block (same blocks, centring and
    scaling as :func:`solve_blocks`); ``workers`` as there."""
    n = Xs.shape[0]
    n_blocks = len(record)
    bounds = np.linspace(0, n, n_blocks + 1).astype(np.int64)
    inv_h = 1.0 / h
    Pn = None
    with single_thread_blas():
        for b in range(n_blocks):
            lo, hi = int(bounds[b]), int(bounds[b + 1])
            inb = (rows >= lo) & (rows < hi)
            sel = rows[inb]
            if sel.size == 0:
                continue
            kept = getattr(record[b], "Pn", None)
            if kept is not None and kept.dtype == dtype:
                Pn, centre = kept, record[b].centre
            else:
                Pn = np.empty(Xs.shape, dtype=dtype) if Pn is None else Pn
                centre = _normalise(Xs, lo, hi, inv_h, Pn)
            centers = sel.astype(idx.dtype)
            vec = (
                np.empty((sel.size, 3), dtype=np.float32)
                if S_s is not None
                else np.empty((0, 3), dtype=np.float32)
            )
            sc, e0 = _replay_ialm(
                Pn,
                centers,
                np.ascontiguousarray(old_idx[inb]),
                np.ascontiguousarray(idx[sel]),
                record[b],
                vec,
                sel.size >= _REPLAY_THREADED and _n_threads(workers, 2 * _MIN_PER_THREAD) > 1,
            )
            scores_s[sel] = sc
            if E0_s is not None:
                E0_s[sel] = e0 * h + centre
            if S_s is not None:
                S_s[sel] = vec


def _n_threads(workers: int, m: int) -> int:
    """Threads of the fused kernels for blocks of ``m`` points (``workers`` as in cKDTree)."""
    cores = os.cpu_count() or 1
    w = cores if workers is None or workers < 0 else max(1, int(workers))
    return max(1, min(w, m // _MIN_PER_THREAD))


class _Ranges:
    """Disjoint point ranges of one block, run on a thread pool (the kernels release the GIL).

    The ranges depend on the block size only (a power of two, at most :data:`_MAX_PARTS`, of at
    least ``_MIN_PER_THREAD`` points each), never on the thread count: their partial Gram
    matrices are summed in a fixed order, so the scores are bit for bit the same whatever
    ``workers`` is (a tiled run on 1 or 2 Dask workers, a CLI run with ``--workers 1``).
    """

    def __init__(self, m: int, K: int, pool: ThreadPoolExecutor | None, n_threads: int):
        fit = max(1, m // _MIN_PER_THREAD)
        n_parts = min(_MAX_PARTS, 1 << (fit.bit_length() - 1))
        self.bounds = np.linspace(0, m, n_parts + 1).astype(np.int64)
        self.G = np.empty((n_parts, K, K))
        self.pool = pool if n_parts > 1 and n_threads > 1 else None

    def run(self, fn: Any, *args: Any) -> tuple[np.ndarray, float]:
        """``fn(*args, G_part, lo, hi)`` over the ranges; the summed ``G`` and return values."""
        b = self.bounds
        if self.pool is None:
            out = [fn(*args, self.G[p], int(b[p]), int(b[p + 1])) for p in range(len(b) - 1)]
        else:
            futs = [
                self.pool.submit(fn, *args, self.G[p], int(b[p]), int(b[p + 1]))
                for p in range(len(b) - 1)
            ]
            out = [f.result() for f in futs]
        return self.G.sum(axis=0), float(sum(x for x in out if x is not None))


def _patch_ialm(
    Pn: np.ndarray,
    centers: np.ndarray,
    nbrs: np.ndarray,
    lam: float | None,
    rho: float,
    tol: float,
    rank_tol: float,
    max_iter: int,
    want_e0: bool,
    pool: ThreadPoolExecutor | None,
    n_threads: int,
    vec: np.ndarray,
    record: list | None = None,
) -> tuple[np.ndarray, np.ndarray | None, int, bool, float]:
    """Inexact ALM (Eq. 4.22) on the implicit patch matrix of the rows ``centers``.

    Returns ``(scores, E0, n_iter, converged, residual)``; stops at ``residual <= tol`` or by the
    ranking rule; ``vec`` ((m, 3), or no rows) receives the first-column residual vectors and
    ``record`` (a list) the operators of every iteration (:func:`_replay_ialm`).
    """
    m = centers.shape[0]
    K = nbrs.shape[1] + 1
    dt = Pn.dtype.type
    ranges = _Ranges(m, K, pool, n_threads)
    G, _ = ranges.run(_k.patch_gram, Pn, centers, nbrs)
    fro = float(np.sqrt(max(np.trace(G), 0.0)))
    scores = np.zeros(m)
    E0 = np.empty((m, 3))
    if fro == 0.0:
        E0[:] = 0.0
        vec[:] = 0.0
        return scores, (E0 if want_e0 else None), 0, True, 0.0
    lam = 1.0 / np.sqrt(3.0 * m) if lam is None else float(lam)
    s_max = float(np.sqrt(max(np.linalg.eigvalsh(G)[-1], 0.0)))
    mu = 1.25 / s_max
    mu_max = mu * 1e7
    mu_prev = mu
    R = np.zeros(3 * m * K, dtype=Pn.dtype)  # column-major tiles, see :mod:`._kernels`
    bins = np.full(m, -2, dtype=np.int32)
    converged, residual, it = False, np.inf, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - `it` is returned
        W, A, B = (x.astype(Pn.dtype) for x in svt_operator(G, 1.0 / mu))
        mu_next = min(mu * rho, mu_max)
        step = (
            W,
            A,
            B,
            dt(lam / mu_prev),
            dt(mu_prev / mu),
            dt(lam / mu),
            dt(1.0 + mu / mu_next),
        )
        if record is not None:
            record.append((G, mu, step))
        G, res2 = ranges.run(_k.patch_ialm_pass, Pn, centers, nbrs, R, *step, E0, scores, vec)
        residual = float(np.sqrt(res2)) / fro
        mu_prev, mu = mu, mu_next
        if residual <= tol:
            converged = True
            break
        if rank_tol > 0:
            changed = _k.rank_bins(scores, RANK_FLOOR, 1.0 / RANK_BIN, bins)
            if it > 1 and lam / mu_prev <= RANK_FLOOR and changed <= rank_tol * m:
                converged = True
                break
    return scores, (E0 if want_e0 else None), it, converged, residual


def _replay_ialm(
    Pn: np.ndarray,
    centers: np.ndarray,
    nbrs_old: np.ndarray,
    nbrs_new: np.ndarray,
    steps: list,
    vec: np.ndarray,
    threaded: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Step 5's second pass on the rows ``centers`` whose patches changed from ``nbrs_old`` to
    ``nbrs_new``, from the iterations ``steps`` recorded by :func:`_patch_ialm` on all rows.

    The changed rows run twice with the recorded ``mu`` schedule: on their old patches with the
    recorded operators (reproducing their share ``G_t^old`` of each Gram matrix ``G_t``) and on
    their new patches with the operators of ``G_t - G_t^old + G_t^new``; other rows keep their
    first-pass scores. Returns the new rows' scores and ``E`` first columns; ``vec`` receives their
    residual vectors. ``threaded``: the two passes of an iteration run on two threads.
    """
    m = centers.shape[0]
    K = nbrs_new.shape[1] + 1
    scores = np.zeros(m)
    E0 = np.zeros((m, 3))
    if m == 0 or not steps:
        vec[:] = 0.0
        return scores, E0
    R_old = np.zeros(3 * m * K, dtype=Pn.dtype)
    R_new = np.zeros(3 * m * K, dtype=Pn.dtype)
    G_old, G_new = np.empty((K, K)), np.empty((K, K))
    _k.patch_gram(Pn, centers, nbrs_old, G_old, 0, m)
    _k.patch_gram(Pn, centers, nbrs_new, G_new, 0, m)
    s_old, e_old = np.empty(m), np.empty((m, 3))
    no_vec = np.empty((0, 3), dtype=np.float32)
    with ThreadPoolExecutor(1) if threaded else contextlib.nullcontext() as pool:
        for G, mu, (W, A, B, *scal) in steps:
            ops = tuple(x.astype(Pn.dtype) for x in svt_operator(G - G_old + G_new, 1.0 / mu))
            # G_old / G_new are overwritten with the shares of the next iteration's Gram matrix
            old = (Pn, centers, nbrs_old, R_old, W, A, B, *scal, e_old, s_old, no_vec, G_old, 0, m)
            fut = None if pool is None else pool.submit(_k.patch_ialm_pass, *old)
            if fut is None:
                _k.patch_ialm_pass(*old)
            new = (Pn, centers, nbrs_new, R_new, *ops, *scal, E0, scores, vec, G_new, 0, m)
            _k.patch_ialm_pass(*new)
            if fut is not None:
                fut.result()
    return scores, E0
