"""Completion of mesh animations and point-cloud sequences (thesis Sections 5.3.2-5.3.3).

Readings and policies: docs/decisions.md#complete-motion-readings.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, check_choice, check_positive, coordinate_array
from ..graph import adjacency_matrix, knn_graph, laplacian_from_adjacency
from ..linalg import complete_matrix, laplacian_interpolation, lasso
from ._common import as_known
from .static import inpaint

__all__ = ["ANIMATION_METHODS", "SEQUENCE_METHODS", "complete_animation", "complete_sequence"]

ANIMATION_METHODS = ("motion", "li", "lia", "mc", "gmc")
SEQUENCE_METHODS = ("wrli", "li", "lia", "mc", "gmc")
#: GMC (graph-regularised matrix completion): final singular-value threshold, i.e. the weight
#: of the nuclear norm against the graph term (``lambda / (gamma lambda_max(L))``).
#: Chosen on the tuning split; see docs/decisions.md#complete-gmc-tau.
GMC_TAU = 1e-2
#: filtering sweeps of ``"motion"`` after the satellite generations of Algorithm 12.
#: Chosen on the tuning split; see docs/decisions.md#complete-sweeps.
MOTION_SWEEPS = 20
#: per-frame switch of ``"motion"``: below this leave-one-out ratio (:func:`_loo_ratio`) the
#: motion step is kept without testing static interpolation.
#: Chosen on the tuning split; see docs/decisions.md#completion-switch.
SWITCH_SCREEN = 0.3
#: per-frame switch: every ``SWITCH_STRIDE``-th anchor is held out (one fold per offset in
#: :data:`SWITCH_FOLDS`) to fit the blend weight of the two completions.
#: Chosen on the tuning split; see docs/decisions.md#completion-switch.
SWITCH_STRIDE = 5
#: per-frame switch: offsets of the held-out folds (``(0,)``: one fold, a fifth of the anchors).
#: Chosen on the tuning split; see docs/decisions.md#completion-switch.
SWITCH_FOLDS = (0,)


# --------------------------------------------------------------------------------- validation
def _as_partial_frames(frames: Any, name: str = "frames") -> np.ndarray:
    return coordinate_array(getattr(frames, "frames", frames), name, ndim=3, copy=True)


def _as_known_frames(known: Any, T: int, n: int) -> np.ndarray:
    """``known`` as a (T, n) bool mask; a per-vertex mask applies to every frame."""
    arr = np.asarray(known)
    if arr.dtype == bool and arr.ndim == 2:
        if arr.shape != (T, n):
            raise InvalidInputError(
                f"`known` must have shape ({n},) or ({T}, {n}); got {arr.shape}."
            )
        return arr.copy()
    if arr.dtype == bool and arr.shape != (n,):
        raise InvalidInputError(f"`known` must have shape ({n},) or ({T}, {n}); got {arr.shape}.")
    return np.broadcast_to(as_known(arr, n), (T, n)).copy()


def _check_known_rows(A: np.ndarray, K: np.ndarray) -> None:
    vals = A[K]
    if vals.size and not np.isfinite(vals).all():
        t, i = np.argwhere(K & ~np.isfinite(A).all(axis=2))[0]
        raise InvalidInputError(
            f"`frames` has NaN or inf coordinates at a known vertex (frame {t}, vertex {i}); "
            "known vertices must have finite coordinates."
        )


# ----------------------------------------------------------------------- Algorithm 12 (motion)
def _satellites(
    C: sp.csr_matrix,
    prev: np.ndarray,
    motion: np.ndarray,
    known: np.ndarray,
    sweeps: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Anchor-and-satellite motion (Eq. 5.91-5.92) and the reached mask, then ``sweeps``."""
    n = C.shape[0]
    Cc = C.tocoo()
    d2 = np.sum((prev[Cc.row] - prev[Cc.col]) ** 2, axis=1)
    # w_d = 1 / ||v_i - v_j||^2 on the previous, complete frame; Eq. 5.92 is a ratio, so the
    # weights are divided by their median (scale-free) and capped so that coincident vertices
    # neither overflow nor erase their other neighbours
    pos = d2[d2 > 0]
    ref = float(np.median(pos)) if pos.size else 1.0
    wd = np.minimum(ref / np.maximum(d2, ref * 1e-12), 1e12)
    W = sp.csr_matrix((wd, (Cc.row, Cc.col)), shape=(n, n))
    m = np.where(known[:, None], motion, 0.0)
    cur = known.copy()
    wp = cur.astype(np.float64)  # prioritisation: known vertices gain 1 per iteration
    while not cur.all():
        den = W @ wp
        sat = ~cur & (den > 0)
        if not sat.any():
            break
        num = W @ (wp[:, None] * m)
        m[sat] = num[sat] / den[sat][:, None]
        wp[cur] += 1.0
        cur |= sat
        wp[sat] = 1.0
    if sweeps > 0:
        m = _refine(W, wp, m, known, cur, sweeps)
    return m, cur


def _loo_ratio(C: sp.csr_matrix, prev: np.ndarray, cur: np.ndarray, known: np.ndarray) -> float:
    """Leave-one-out error ratio motion / position at the anchors (inf if too few)."""
    Cc = C.tocoo()
    d2 = np.sum((prev[Cc.row] - prev[Cc.col]) ** 2, axis=1)
    pos = d2[d2 > 0]
    ref = float(np.median(pos)) if pos.size else 1.0
    w = np.minimum(ref / np.maximum(d2, ref * 1e-12), 1e12) * known[Cc.col]
    Wk = sp.csr_matrix((w, (Cc.row, Cc.col)), shape=C.shape)
    den = np.asarray(Wk.sum(axis=1)).ravel()
    ok = known & (den > 0)
    if ok.sum() < 3:
        return np.inf
    curk = np.where(known[:, None], cur, 0.0)
    m = np.where(known[:, None], cur - prev, 0.0)
    e_motion = float(np.sum((m[ok] - (Wk @ m)[ok] / den[ok, None]) ** 2))
    e_static = float(np.sum((curk[ok] - (Wk @ curk)[ok] / den[ok, None]) ** 2))
    return np.sqrt(e_motion / e_static) if e_static > 0 else np.inf


def _with_static_switch(step, C: sp.csr_matrix, L: sp.csr_matrix):
    """Wrap ``step(prev, cur, known_t)`` with the blend with static LI (``static_switch``).

    Below :data:`SWITCH_SCREEN` the step runs alone; otherwise the held-out folds fit
    ``a = clip(sum <v - s, m - s> / sum ||m - s||^2, 0, 1)`` (Eq. S1) and the frame is
    ``a * step + (1 - a) * interpolation``.
    """

    def static(cur, kt):
        idx = np.flatnonzero(kt)
        try:
            return laplacian_interpolation(L, idx, cur[idx])
        except InvalidInputError:  # a component without anchor: only the motion step works
            return None

    def switched(prev, cur, kt):
        if _loo_ratio(C, prev, cur, kt) < SWITCH_SCREEN:
            return step(prev, cur, kt)
        anchors = np.flatnonzero(kt)
        num = den = 0.0
        for off in SWITCH_FOLDS:
            held = anchors[off::SWITCH_STRIDE]
            if not held.size:
                continue
            kh = kt.copy()
            kh[held] = False
            xs = static(cur, kh)
            if xs is None:
                return step(prev, cur, kt)
            xm = step(prev, cur, kh)
            d = xm[held] - xs[held]
            num += float(np.sum((cur[held] - xs[held]) * d))
            den += float(np.sum(d * d))
        a = float(np.clip(num / den, 0.0, 1.0)) if den > 0 else 1.0
        if a >= 1.0:
            return step(prev, cur, kt)
        out = static(cur, kt)
        if out is None:
            return step(prev, cur, kt)
        if a <= 0.0:
            return out
        return a * step(prev, cur, kt) + (1.0 - a) * out

    return switched


def _refine(
    W: sp.csr_matrix,
    wp: np.ndarray,
    m: np.ndarray,
    known: np.ndarray,
    reached: np.ndarray,
    sweeps: int,
) -> np.ndarray:
    """``sweeps`` Jacobi sweeps of Eq. 5.92 over the reached non-anchor vertices."""
    free = np.flatnonzero(reached & ~known)
    if free.size == 0:
        return m
    P = (W[free] @ sp.diags(wp)).tocsr()
    den = np.asarray(P.sum(axis=1)).ravel()
    ok = den > 0
    free, P, den = free[ok], P[ok], den[ok]
    inv = (1.0 / den)[:, None]
    for _ in range(sweeps):
        m[free] = (P @ m) * inv
    return m


def _lia_motion(L: sp.csr_matrix, motion: np.ndarray, known: np.ndarray) -> np.ndarray:
    idx = np.flatnonzero(known)
    return laplacian_interpolation(L, idx, motion[idx])


def _mc_offline(A: np.ndarray, K: np.ndarray, *, tol: float, max_iter: int, rng: Any) -> np.ndarray:
    """Matrix completion of the centred, scaled (3n, T) animation matrix (Eq. 5.90)."""
    T, n, _ = A.shape
    M = A.transpose(1, 2, 0).reshape(3 * n, T)
    obs = np.repeat(K.T, 3, axis=0)
    X = np.where(obs, M, 0.0)
    cnt = obs.sum(axis=1)
    mu = np.divide(X.sum(axis=1), cnt, out=np.zeros(3 * n), where=cnt > 0)
    pts = A[K]
    scale = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))) or 1.0
    Xc = np.where(obs, (X - mu[:, None]) / scale, 0.0)
    res = complete_matrix(Xc, obs, tol=tol, max_iter=max_iter, on_nonconvergence="ignore", rng=rng)
    out = res.completed * scale + mu[:, None]
    return out.reshape(n, 3, T).transpose(2, 0, 1)


def _gmc_offline(
    A: np.ndarray, K: np.ndarray, C: sp.csr_matrix, *, tol: float, max_iter: int
) -> np.ndarray:
    """Graph-regularised completion (GMC): docs/decisions.md#complete-motion-readings."""
    T, n, _ = A.shape
    M = A.transpose(1, 2, 0).reshape(3 * n, T)
    obs = np.repeat(K.T, 3, axis=0)
    cnt = obs.sum(axis=1)
    mu = np.divide(np.where(obs, M, 0.0).sum(axis=1), cnt, out=np.zeros(3 * n), where=cnt > 0)
    pts = A[K]
    scale = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))) or 1.0
    D = np.where(obs, (M - mu[:, None]) / scale, 0.0)
    L = laplacian_from_adjacency(C)
    lmax = float(np.abs(L).sum(axis=1).max()) or 1.0  # Gershgorin bound of lambda_max(L)

    def graph_grad(X):
        return (L @ X.reshape(n, 3 * T)).reshape(3 * n, T)

    X = D.copy()
    tau = max(float(np.linalg.norm(D, 2)) / 10.0, GMC_TAU)
    for _ in range(int(max_iter)):
        Y = X - graph_grad(X) / lmax
        Xn = _svt_thin(Y, tau)
        Xn[obs] = D[obs]
        change = float(np.linalg.norm(Xn - X)) / max(float(np.linalg.norm(Xn)), 1e-300)
        X = Xn
        if tau > GMC_TAU:
            tau = max(tau * 0.7, GMC_TAU)
        elif change < tol:
            break
    out = X * scale + mu[:, None]
    return out.reshape(n, 3, T).transpose(2, 0, 1)


def _svt_thin(Y: np.ndarray, tau: float) -> np.ndarray:
    """Singular-value thresholding (Eq. 4.21) through the small Gram matrix."""
    wide = Y.shape[1] > Y.shape[0]
    Z = Y.T if wide else Y
    w, V = np.linalg.eigh(Z.T @ Z)
    sv = np.sqrt(np.maximum(w, 0.0))
    keep = sv > tau
    if not keep.any():
        return np.zeros_like(Y)
    Vk = V[:, keep]
    R = (Z @ (Vk * ((sv[keep] - tau) / sv[keep]))) @ Vk.T
    return R.T if wide else R


def _first_frame(A0, K0, C, F, name):
    """Frame 0, a partial one completed by Laplacian interpolation."""
    if K0.all():
        return A0.copy()
    if not K0.any():
        raise InvalidInputError(
            f"frame 0 of `{name}` has no known vertex; the online methods need a (partly) known "
            "first frame."
        )
    idx = np.flatnonzero(K0)
    return laplacian_interpolation(laplacian_from_adjacency(C), idx, A0[idx])


def _run_online(A, K, C, method, step):
    """Frame loop ``step(prev, cur, known_t) -> frame`` after :func:`_first_frame`."""
    T = A.shape[0]
    out = np.empty_like(A)
    out[0] = _first_frame(A[0], K[0], C, None, "frames")
    out[0][K[0]] = A[0][K[0]]
    for t in range(1, T):
        kt = K[t]
        if not kt.any():  # all-unknown frame: documented fallback, zero motion
            out[t] = out[t - 1]
            continue
        out[t] = step(out[t - 1], A[t], kt)
        out[t][kt] = A[t][kt]
    return out


def complete_animation(
    frames: Any,
    F: Any,
    known: Any,
    *,
    method: str = "motion",
    tol: float = 1e-4,
    max_iter: int = 200,
    sweeps: int = MOTION_SWEEPS,
    static_switch: bool = True,
    rng: Any = None,
) -> np.ndarray:
    """Recover missing vertices of a mesh animation with fixed connectivity (Section 5.3.2).

    ``"motion"`` (Algorithm 12, online) moves satellites by
    ``m_i = sum_j w_dij w_pj m_j / sum_j |w_dij w_pj|`` over known neighbours (Eq. 5.91-5.92),
    generation by generation from the anchors, then ``sweeps`` more filter passes
    (docs/decisions.md#complete-sweeps; 0 is Algorithm 12 as printed). ``static_switch`` blends each
    frame with static Laplacian interpolation (docs/decisions.md#complete-pose-sets). Baselines:
    ``"li"`` per frame, ``"lia"`` (LI of the motion), offline ``"mc"`` (Eq. 5.90) and ``"gmc"``.

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
    F : (m, 3) array_like of int
    known : (n,) or (T, n) bool, or (n_k,) int
    method : {"motion", "li", "lia", "mc", "gmc"}
    tol, max_iter, sweeps, static_switch, rng
        Settings of the methods above.

    Returns
    -------
    (T, n, 3) float64 ndarray, known entries exactly the input ones.
    """
    check_choice(method, "method", ANIMATION_METHODS)
    if isinstance(sweeps, bool) or not isinstance(sweeps, (int, np.integer)) or sweeps < 0:
        raise InvalidInputError(f"`sweeps` must be a non-negative integer; got {sweeps!r}.")
    A = _as_partial_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    K = _as_known_frames(known, T, n)
    _check_known_rows(A, K)
    C = adjacency_matrix(F, n)
    return _complete_frames(
        A,
        K,
        C,
        method,
        tol=tol,
        max_iter=max_iter,
        rng=rng,
        F=F,
        sweeps=int(sweeps),
        switch=bool(static_switch),
    )


def _complete_frames(
    A, K, C, method, *, tol, max_iter, rng, F=None, wrli=None, sweeps=0, switch=False
):
    T, n, _ = A.shape
    if method in ("mc", "gmc"):
        if not K.any(axis=0).all():
            bad = int(np.flatnonzero(~K.any(axis=0))[0])
            raise InvalidInputError(
                f"vertex {bad} is unknown in every frame; matrix completion cannot recover it."
            )
        if method == "mc":
            out = _mc_offline(A, K, tol=tol, max_iter=max_iter, rng=rng)
        else:
            out = _gmc_offline(A, K, C, tol=tol, max_iter=max_iter)
        out[K] = A[K]
        return out
    L = laplacian_from_adjacency(C)
    if method == "li":
        out = np.empty_like(A)
        for t in range(T):
            if F is not None:
                out[t] = inpaint(A[t], F, K[t], method="li")
            else:
                idx = np.flatnonzero(K[t])
                if idx.size == 0:
                    raise InvalidInputError(f"frame {t} has no known point.")
                out[t] = laplacian_interpolation(L, idx, A[t][idx])
        return out

    def step_motion(prev, cur, kt):
        m, reached = _satellites(C, prev, cur - np.where(kt[:, None], prev, 0.0), kt, sweeps=sweeps)
        m[~reached] = 0.0
        return prev + m

    def step_lia(prev, cur, kt):
        motion = np.where(kt[:, None], cur - prev, 0.0)
        m, reached = _satellites(C, prev, motion, kt)  # components without anchor: zero motion
        sub = reached
        if sub.all():
            mv = _lia_motion(L, motion, kt)
        else:
            mv = np.zeros_like(prev)
            idx = np.flatnonzero(sub)
            Ls = laplacian_from_adjacency(C[idx][:, idx])
            mv[idx] = _lia_motion(Ls, motion[idx], kt[idx])
        return prev + mv

    step = {"motion": step_motion, "lia": step_lia, "wrli": wrli}[method]
    if switch and method in ("motion", "wrli"):
        step = _with_static_switch(step, C, L)
    return _run_online(A, K, C, method, step)


# ------------------------------------------------------------------- Algorithm 13 (WRLI)
def _wrli_step(C: sp.csr_matrix, sigma: float, gamma: float, max_iter: int):
    """One frame of Algorithm 13 (Eq. 5.94-5.97) over the fixed graph ``C``."""
    Cc = C.tocoo()
    n = C.shape[0]

    def step(prev, cur, kt):
        motion = np.where(kt[:, None], cur - prev, 0.0)
        # prioritisation (Sec. 5.3.3): N for known points, N - 1 for their neighbours, ..., 1
        gen = np.full(n, -1, dtype=np.int64)
        gen[kt] = 0
        reach = kt.copy()
        g = 0
        while True:
            nb = (C @ reach.astype(np.float64) > 0) & ~reach
            if not nb.any():
                break
            g += 1
            gen[nb] = g
            reach |= nb
        N = g + 1
        wp = np.where(gen >= 0, N - gen, 0).astype(np.float64)  # unreached components: 0
        # Eq. 5.94-5.95: C_w,ij = w_p,i exp(-||v_i - v_j||^2 / (2 sigma^2)) c_ij (previous frame)
        d2 = np.sum((prev[Cc.row] - prev[Cc.col]) ** 2, axis=1)
        w = wp[Cc.row] * np.exp(-d2 / (2.0 * sigma * sigma))
        Cw = sp.csr_matrix((w, (Cc.row, Cc.col)), shape=(n, n))
        Lw = (sp.diags(np.asarray(Cw.sum(axis=1)).ravel()) - Cw).tocsc()
        # B-hat: mean motion of the first ring, propagated generation by generation
        Bh, reached = _satellites_mean(C, motion, kt)
        u = np.flatnonzero(~kt & reached)
        k = np.flatnonzero(kt)
        if u.size == 0:
            return prev + np.where(reached[:, None], Bh, 0.0)
        R = Lw[:, u]
        Q = Lw[:, k]
        P = -(Q @ motion[k]) - R @ Bh[u]  # Eq. 5.96 (sign: L B = Q B_k + R B_u, Eq. 4.26)
        n_s = R.shape[0]
        amax = float(np.abs(R.T @ P).max()) / n_s
        if amax > 0 and gamma > 0:
            res = lasso(R, P, alpha=gamma * amax, max_iter=max_iter, on_nonconvergence="ignore")
            z = res.coef
        else:
            z = np.zeros((u.size, 3))
        B = np.where(reached[:, None], Bh, 0.0)
        B[u] = Bh[u] + z
        return prev + B  # Eq. 5.97

    return step


def _satellites_mean(C: sp.csr_matrix, motion: np.ndarray, known: np.ndarray):
    """``B-hat`` of Eq. 5.96: first-ring mean motion, generation by generation."""
    m = np.where(known[:, None], motion, 0.0)
    cur = known.copy()
    while not cur.all():
        f = cur.astype(np.float64)
        den = C @ f
        sat = ~cur & (den > 0)
        if not sat.any():
            break
        num = C @ (f[:, None] * m)
        m[sat] = num[sat] / den[sat][:, None]
        cur |= sat
    return m, cur


def complete_sequence(
    clouds: Any,
    known: Any,
    *,
    method: str = "wrli",
    n_neighbors: int = 8,
    gamma: float = 0.01,
    max_iter: int = 500,
    tol: float = 1e-4,
    static_switch: bool = True,
    rng: Any = None,
) -> np.ndarray:
    """Recover missing points of a point-cloud sequence with correspondence (Section 5.3.3).

    ``"wrli"`` (Algorithm 13, online): on the kNN graph of frame 0 (Eq. 5.93), the weighted
    Laplacian ``L_w`` (Eq. 5.94-5.95) and the LASSO ``min_z 0.5 ||P - R z||^2 + gamma' ||z||_1``
    (Eq. 5.96) correct the mean motion, ``v_u(t) = v_u(t-1) + B-hat_u + z`` (Eq. 5.97); ``gamma`` is
    relative to the smallest weight giving ``z = 0``. Baselines and ``static_switch`` as in
    :func:`complete_animation`. ``clouds`` (T, n, 3); ``known`` as there. Returns (T, n, 3) float64.
    """
    check_choice(method, "method", SEQUENCE_METHODS)
    check_positive(n_neighbors, "n_neighbors", integer=True)
    check_positive(gamma, "gamma", allow_zero=True)
    if isinstance(clouds, list | tuple):
        sizes = {np.shape(c) for c in clouds}
        if len(sizes) > 1:
            raise InvalidInputError(
                "`clouds` must all have the same number of points (point i is the same point in "
                f"every frame); got shapes {sorted(sizes)[:3]}."
            )
    A = _as_partial_frames(
        np.asarray(clouds, dtype=np.float64) if isinstance(clouds, list | tuple) else clouds,
        "clouds",
    )
    T, n, _ = A.shape
    K = _as_known_frames(known, T, n)
    _check_known_rows(A, K)
    if n <= n_neighbors:
        raise InvalidInputError(
            f"`n_neighbors` must be < the number of points {n}; got {n_neighbors}."
        )
    A0 = A[0]
    if not K[0].all():
        # graph on the known points of frame 0 only would leave the unknown ones out: the
        # online methods need frame 0 complete to build the graph (Algorithm 13, line 1)
        raise InvalidInputError(
            "frame 0 of `clouds` must be complete: the graph of Algorithm 13 is built on it."
        )
    C = knn_graph(A0, n_neighbors)
    C = sp.csr_matrix(C, dtype=np.float64)
    C.data[:] = 1.0
    Cc = C.tocoo()
    sigma = float(np.sqrt(np.sum((A0[Cc.row] - A0[Cc.col]) ** 2, axis=1)).mean()) or 1.0
    step = _wrli_step(C, sigma, gamma, max_iter) if method == "wrli" else None
    return _complete_frames(
        A, K, C, method, tol=tol, max_iter=max_iter, rng=rng, wrli=step, switch=bool(static_switch)
    )
