"""Outlier removal and consolidation of dynamic point-cloud sequences (thesis Section 5.4.3):
RPCA of the spatio-temporal matrix of each part (Eq. 5.102-5.103) and refill of removed points by
motion vectors interpolated with a weighted graph Laplacian (Eq. 5.104-5.109).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._errors import ConvergenceError, ConvergenceWarning, InvalidInputError
from .._validation import as_rng, check_choice, check_positive
from ..geometry import PointCloud, PointCloudSequence
from ._common import check_k, knn_chunked

__all__ = ["SequenceResult", "clean_sequence", "weighted_laplacian"]

#: Default RPCA weight ``lam = LAM_FACTOR / sqrt(max(3 n_m, T))`` (see :func:`clean_sequence`).
LAM_FACTOR = 2.0
#: Smallest motion-similarity weight ``W2`` (Eq. 5.105).
W2_FLOOR = 1e-3


@dataclass(frozen=True)
class SequenceResult:
    """Result of :func:`clean_sequence`.

    Attributes
    ----------
    frames : PointCloudSequence
        Consolidated frames, or the kept points of each frame.
    keep, scores : list of (n_t,) ndarrays
        Per frame: kept points and the scores ``||s||_2`` of Eq. 5.103 (input order).
    low_rank : (T, n, 3) ndarray or None
        The low-rank reconstruction of every frame (fixed-size sequences).
    n_iter, converged, residual, n_unconverged
        RPCA figures over the parts (frames).
    """

    frames: PointCloudSequence = field(repr=False)
    keep: list = field(repr=False)
    scores: list = field(repr=False)
    low_rank: np.ndarray | None = field(default=None, repr=False)
    n_iter: int = 0
    converged: bool = True
    residual: float = 0.0
    n_unconverged: int = 0


def _report(res: SequenceResult, policy: str, n_total: int, what: str) -> None:
    """One warning (or error) for all the parts or frames whose RPCA did not converge."""
    if res.converged or policy == "ignore":
        return
    msg = (
        f"RPCA did not converge on {res.n_unconverged} of {n_total} {what} of the sequence "
        f"(largest residual {res.residual:.3g}); their outlier flags may be unreliable: "
        "increase `max_iter` or relax `tol`."
    )
    if policy == "raise":
        raise ConvergenceError(msg, partial=res)
    warnings.warn(msg, ConvergenceWarning, stacklevel=3)


def _knn_adjacency(V: np.ndarray, k: int) -> sp.csr_matrix:
    n = V.shape[0]
    idx = knn_chunked(V, k).idx.astype(np.int64)
    rows = np.repeat(np.arange(n), k)
    C = sp.csr_matrix((np.ones(rows.size), (rows, idx.ravel())), shape=(n, n))
    C = ((C + C.T) > 0).astype(np.float64)
    return sp.csr_matrix(C)


def _hops_to_known(C: sp.csr_matrix, known: np.ndarray) -> np.ndarray:
    """Graph distance (in edges) from every vertex to the nearest known vertex (inf if none)."""
    n = C.shape[0]
    hops = np.full(n, np.inf)
    hops[known] = 0.0
    frontier = np.flatnonzero(known)
    d = 0
    while frontier.size:
        d += 1
        nb = np.unique(C[frontier].indices)
        nb = nb[~np.isfinite(hops[nb])]
        hops[nb] = d
        frontier = nb
    return hops


def weighted_laplacian(
    C: Any, prev: np.ndarray, motion: np.ndarray, known: np.ndarray
) -> sp.csr_matrix:
    """The weighted Laplacian ``L_w = D - C_w`` of Eq. (5.104)-(5.108).

    ``C_w = W1 o W2 o W3 o C`` with ``W1_ij = 1 / ||v_i(t-1) - v_j(t-1)||^2`` (Eq. 5.104, scaled by
    the median squared edge length), ``W2_ij = max(1 + cos(m_i, m_j), 1e-3)`` (Eq. 5.105) and
    ``W3_ij = 4`` for a known ``v_j``, else ``1 / (n_v + 1)`` with ``n_v`` the hops from ``v_j`` to the
    nearest known vertex (Eq. 5.106, applied to the neighbour whose motion is borrowed, so ``C_w`` is
    not symmetric); ``D_i = sum_j C_w[i, j]`` (Eq. 5.108).

    Parameters
    ----------
    C : (n, n) sparse
        Binary adjacency.
    prev : (n, 3) ndarray
        Positions at frame ``t - 1``.
    motion : (n, 3) ndarray
        Motion vectors ``m_i`` (zero rows where unknown).
    known : (n,) bool ndarray

    Returns
    -------
    (n, n) csr_matrix
    """
    C = sp.csr_matrix(C, dtype=np.float64)
    C.sort_indices()
    n = C.shape[0]
    r = np.repeat(np.arange(n), np.diff(C.indptr))
    c = C.indices
    d2 = np.einsum("ij,ij->i", prev[r] - prev[c], prev[r] - prev[c])
    pos = d2[d2 > 0]
    floor = float(pos.min()) if pos.size else 1.0
    scale = float(np.median(pos)) if pos.size else 1.0
    w1 = scale / np.maximum(d2, floor)  # Eq. 5.104 times a constant (no overflow)
    nm = np.linalg.norm(motion, axis=1)
    den = nm[r] * nm[c]
    cos = np.zeros_like(den)
    ok = den > 0
    cos[ok] = np.einsum("ij,ij->i", motion[r[ok]], motion[c[ok]]) / den[ok]
    w2 = np.maximum(1.0 + cos, W2_FLOOR)
    hops = _hops_to_known(C, known)
    w3 = np.where(known[c], 4.0, 1.0 / (np.where(np.isfinite(hops[c]), hops[c], 0.0) + 1.0))
    Cw = sp.csr_matrix((C.data * w1 * w2 * w3, (r, c)), shape=(n, n))
    return sp.csr_matrix(sp.diags(np.asarray(Cw.sum(axis=1)).ravel()) - Cw)


def clean_sequence(
    seq: Any,
    *,
    k: int = 10,
    tau: float | str = 1e-4,
    submesh_size: int = 700,
    overlap: float = 0.15,
    lam: float | None = None,
    tol: float = 1e-7,
    max_iter: int | None = None,
    refill: bool = True,
    rng: Any = 0,
    on_nonconvergence: str = "warn",
) -> SequenceResult:
    """Remove outliers from a point-cloud sequence and consolidate it (Section 5.4.3).

    For frames of ``n`` corresponding points: the ``k``-NN graph of the per-point temporal median
    is split into overlapped parts of ``submesh_size`` points
    (:func:`spectrageo.spectral.overlapped_submeshes`); per part, RPCA of the ``3 n_m x T`` matrix
    of Eq. 5.102 (unit-diagonal coordinates) gives ``E`` and ``S`` (Eq. 5.103); a (point, frame)
    is an outlier when the norm of its entries of ``S`` is at least ``tau``. With ``refill``,
    removed points take their low-rank position at the first frame and later move by the motion
    vectors of the kept points interpolated with :func:`weighted_laplacian` (Eq. 5.104-5.109;
    docs/decisions.md#outliers-sequence-lam). Sequences whose point count varies are cleaned
    frame by frame by :func:`remove_outliers` (``tau`` unused, nothing refilled).

    Parameters
    ----------
    seq : PointCloudSequence or (T, n, 3) array_like
    k : int
        Neighbours of the connectivity graph.
    tau : float or "auto"
        Threshold on the sparse-part scores; ``"auto"``: :func:`auto_threshold` over all scores.
    submesh_size, overlap : int, float
        Part size ``n_m`` and overlap of the partition.
    lam, tol, max_iter
        RPCA options; ``lam`` defaults to ``2 / sqrt(max(3 n_m, T))``. Varying-size sequences pass
        only ``max_iter`` on.
    refill : bool
        Consolidate, or return only the kept points of each frame.
    rng : int or Generator
        Seeds METIS.
    on_nonconvergence : {"warn", "raise", "ignore"}
        Policy, once per call, when some parts (frames) stop at ``max_iter``.

    Returns
    -------
    SequenceResult
    """
    from ..linalg import laplacian_interpolation, rpca
    from ..spectral import overlapped_submeshes
    from ._rpca_types import RPCAOptions
    from .static import remove_outliers

    if isinstance(seq, PointCloudSequence):
        pcs = seq
    elif seq is None:
        raise InvalidInputError(
            "`seq` must be a PointCloudSequence or a (T, n, 3) array; got None."
        )
    else:
        arr = np.asarray(seq, dtype=np.float64)
        if arr.ndim != 3 or arr.shape[2] != 3:
            raise InvalidInputError(
                f"`seq` must be a PointCloudSequence or have shape (T, n, 3); got {arr.shape}."
            )
        if arr.shape[0] == 0:
            raise InvalidInputError("`seq` is empty; a sequence needs at least one frame.")
        pcs = PointCloudSequence([PointCloud(f) for f in arr])
    if not (isinstance(tau, str) and tau == "auto"):
        check_positive(tau, "tau")
    check_positive(submesh_size, "submesh_size", integer=True)
    if not (0 <= overlap < 1):
        raise InvalidInputError(f"`overlap` must be in [0, 1); got {overlap!r}.")
    check_choice(on_nonconvergence, "on_nonconvergence", ("warn", "raise", "ignore"))

    if not pcs.is_fixed_size():
        frame_options = RPCAOptions(
            on_nonconvergence="ignore", **({} if max_iter is None else {"max_iter": max_iter})
        )
        keeps, scores, frames = [], [], []
        n_iter, residual, n_bad = 0, 0.0, 0
        for t, f in enumerate(pcs.frames):
            try:
                # convergence is collected over the frames and reported once below
                r = remove_outliers(f, method="rpca", k=k, options=frame_options)
            except InvalidInputError as exc:
                raise InvalidInputError(f"frame {t}: {exc}") from exc
            keeps.append(r.keep)
            scores.append(r.scores)
            frames.append(r.points)
            n_iter = max(n_iter, int(r.info["n_iter"]))
            residual = max(residual, float(r.info["residual"]))
            n_bad += not r.info["converged"]
        res = SequenceResult(
            PointCloudSequence(frames),
            keeps,
            scores,
            n_iter=n_iter,
            converged=n_bad == 0,
            residual=residual,
            n_unconverged=n_bad,
        )
        _report(res, on_nonconvergence, len(pcs.frames), "frames")
        return res

    X = pcs.as_array()  # (T, n, 3)
    T, n = X.shape[0], X.shape[1]
    k = check_k(k, n)
    ref = np.median(X, axis=0)
    lo, hi = X.min(axis=(0, 1)), X.max(axis=(0, 1))
    diag = float(np.linalg.norm(hi - lo))
    if diag == 0:
        raise InvalidInputError("`seq` has no spatial extent: all points of all frames coincide.")
    centre = 0.5 * (lo + hi)
    Xn = (X - centre) / diag
    C = _knn_adjacency(ref, k)
    if n <= submesh_size:
        parts, cores = [np.arange(n)], [np.arange(n)]
    else:
        sub = overlapped_submeshes(C, submesh_size=submesh_size, overlap=overlap, rng=as_rng(rng))
        parts, cores = sub.parts, sub.cores

    score = np.zeros((T, n))
    low = np.empty((T, n, 3))
    n_iter, residual, n_bad = 0, 0.0, 0
    for part, core in zip(parts, cores, strict=True):
        M = np.ascontiguousarray(Xn[:, part, :].transpose(1, 2, 0).reshape(3 * part.size, T))
        lam_p = LAM_FACTOR / np.sqrt(max(M.shape)) if lam is None else float(lam)
        # convergence is collected over the parts and reported once below
        r = rpca(
            M, method="ialm", lam=lam_p, tol=tol, max_iter=max_iter, on_nonconvergence="ignore"
        )
        n_iter = max(n_iter, r.n_iter)
        n_bad += not r.converged
        residual = max(residual, r.residual)
        at = np.searchsorted(part, core)
        S = r.sparse.reshape(part.size, 3, T)[at]  # (c, 3, T)
        E = r.low_rank.reshape(part.size, 3, T)[at]
        score[:, core] = np.sqrt((S**2).sum(axis=1)).T
        low[:, core, :] = E.transpose(2, 0, 1)
    low = low * diag + centre
    if isinstance(tau, str):
        from .static import auto_threshold

        tau = auto_threshold(score.ravel())
    keep = score < tau

    frames_out = []
    if refill:
        Y = np.empty_like(X)
        Y[0] = np.where(keep[0][:, None], X[0], low[0])
        prev_motion = np.zeros((n, 3))
        for t in range(1, T):
            kn = keep[t]
            if kn.all():
                Y[t] = X[t]
            elif not kn.any():
                Y[t] = Y[t - 1] + prev_motion
            else:
                motion = np.where(kn[:, None], X[t] - Y[t - 1], prev_motion)
                Lw = weighted_laplacian(C, Y[t - 1], motion, kn)
                Y[t] = _refill(Lw, C, kn, X[t], Y[t - 1], laplacian_interpolation)
            prev_motion = Y[t] - Y[t - 1]
        for t in range(T):
            f = pcs.frames[t]
            frames_out.append(PointCloud(Y[t], f.normals, f.colors, dict(f.attributes)))
    else:
        for t in range(T):
            if not keep[t].any():
                raise InvalidInputError(f"frame {t}: every point was flagged as an outlier.")
            frames_out.append(pcs.frames[t].select(keep[t]))
    res = SequenceResult(
        frames=PointCloudSequence(frames_out),
        keep=[keep[t] for t in range(T)],
        scores=[score[t] for t in range(T)],
        low_rank=low,
        n_iter=n_iter,
        converged=n_bad == 0,
        residual=residual,
        n_unconverged=n_bad,
    )
    _report(res, on_nonconvergence, len(parts), "parts")
    return res


def _refill(Lw, C, known, Xt, prev, interp) -> np.ndarray:
    """Eq. 5.109 per connected component; components without a known point keep ``prev``."""
    out = np.where(known[:, None], Xt, prev)
    n_comp, lab = connected_components(C, directed=False)
    has_known = np.zeros(n_comp, dtype=bool)
    has_known[lab[known]] = True
    solvable = has_known[lab]
    idx = np.flatnonzero(solvable)
    if idx.size == 0:
        return out
    sub_known = known[idx]
    if sub_known.all():
        return out
    L = Lw[idx][:, idx]
    kidx = np.flatnonzero(sub_known)
    # rows of the unknown points only (harmonic form): each B_u is a weighted mean of its
    # neighbours', so B_u stays within the range of the known motions
    B = interp(L, kidx, Xt[idx][kidx] - prev[idx][kidx], weights=(~sub_known).astype(np.float64))
    out[idx] = prev[idx] + B
    return out
