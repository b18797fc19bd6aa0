"""Completion of mesh animations and point-cloud sequences (thesis Sections 5.3.2-5.3.3).

Online methods (frame ``t`` uses frames ``<= t`` only): ``"motion"`` (Algorithm 12, anchors and
satellites, followed by filtering sweeps), ``"wrli"`` (Algorithm 13, weighted regularised Laplacian interpolation of the motion),
and the baselines ``"li"`` (static Laplacian interpolation frame by frame) and ``"lia"``
(Laplacian interpolation of the motion vectors, the thesis's LIA). Offline baseline: ``"mc"``,
matrix completion of the whole animation matrix (Eq. 5.90, MC of the thesis's [359]), and
``"gmc"``, the same completion with the spatial graph of the geometry as a regulariser (GMC of
[359]).
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
#: of the nuclear norm against the graph term (``lambda / (gamma lambda_max(L))``), chosen on the
#: tuning animation (horse-gallop, 25 frames, 30 % known, seed 1: NMSVE 2.666e-4 / 2.671e-4 /
#: 2.672e-4 at 1e-2 / 1e-3 / 1e-4, the first the fastest)
GMC_TAU = 1e-2
#: filtering sweeps of ``"motion"`` after the satellite generations of Algorithm 12 (chosen on
#: the tuning animation, see :func:`complete_animation`)
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
    """``known`` as a (T, n) bool mask: a (n,) mask / index list applies to every frame."""
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
    """Anchors-and-satellites propagation of the motion vectors (Eq. 5.91-5.92).

    Returns the motion of every vertex and the mask of vertices reached (a component without an
    anchor is not reached). ``sweeps > 0`` then repeats the weighted filtering of Eq. 5.92 over
    every reached non-anchor vertex (see :func:`_refine`).
    """
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
    """Cheap screen of the per-frame switch of ``complete_animation(method="motion")``.

    Leave-one-out at the anchors of frame ``t``, from their known neighbours only, with the
    weights ``w_d`` of Eq. 5.92: RMS error of predicting an anchor's motion from its neighbours'
    motions, divided by the RMS error of predicting its position from its neighbours'
    positions. The second overstates what Laplacian interpolation does (with few known
    neighbours the mean position is off along the surface), so a small ratio says "motion" for
    sure while a ratio near 1 only says "test both". ``inf`` when too few anchors have a known
    neighbour.
    """
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
    r"""Wrap an online step ``step(prev, cur, known_t)`` with the per-frame blend with static
    Laplacian interpolation (``static_switch`` of :func:`complete_animation`).

    The screen :func:`_loo_ratio` keeps ``step`` alone below :data:`SWITCH_SCREEN`. Otherwise
    the frame is completed both ways with held-out anchors: for each fold ``f`` of
    :data:`SWITCH_FOLDS` (every :data:`SWITCH_STRIDE`-th anchor from offset ``f``) the held-out
    anchors ``H_f`` are predicted by the step (``m``) and by interpolation (``s``) from the other
    anchors, and the blend weight is the least-squares fit over all folds,

        (S1)  a = clip( sum_f sum_{i in H_f} <v_i - s_i, m_i - s_i>
                        / sum_f sum_{i in H_f} ||m_i - s_i||^2 , 0, 1 ),

    after which the frame is ``a * step + (1 - a) * interpolation``, both from all anchors (anchors
    are returned exactly by both, so by the blend). ``a = 1`` or ``0`` runs one way only.
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
    """Repeated weighted filtering of Eq. 5.92 after the generations of Algorithm 12.

    Algorithm 12 estimates every satellite once, from the neighbours known when its generation
    is reached (a first-generation satellite sees only its anchors). Here every reached
    non-anchor vertex is then re-estimated ``sweeps`` times (Jacobi sweeps) from all its
    neighbours with the same weights ``w_d w_p`` (anchors keep their measured motion and weigh
    most); the sweeps converge towards the ``w_d w_p``-weighted harmonic interpolation of the
    anchors' motion.
    """
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
    """Matrix completion of the (3n, T) animation matrix (Eq. 5.90); rows centred on the mean of
    their known entries, scaled by the bounding-box diagonal of the known data."""
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
    r"""Graph-regularised matrix completion of the animation matrix (GMC of the thesis's [359],
    Section 5.3.3's offline baseline; the thesis gives no equations for it).

    Reading: ``min_X lambda ||X||_* + (gamma / 2) tr(X^T (L (x) I_3) X)  s.t.  P_omega(X) =
    P_omega(M)`` on the (3n, T) animation matrix (rows: the coordinates of the vertices, ``L =
    D - C`` the binary Laplacian of the mesh or kNN graph), centred and scaled as for ``"mc"``,
    solved by proximal gradient in soft-impute form: a gradient step of length
    ``1 / (gamma lambda_max)`` on the graph term (``X - L X / lambda_max``, ``lambda_max``
    bounded by Gershgorin), singular-value thresholding (Eq. 4.21) at
    ``tau = lambda / (gamma lambda_max)`` and the known entries put back, with ``tau``
    decreasing geometrically from ``||X||_2 / 10`` to :data:`GMC_TAU` (continuation), until
    the relative change of the iterate is below ``tol``.
    """
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
    """Singular-value thresholding ``U S_tau[Lambda] V^T`` (Eq. 4.21) of a tall or wide matrix
    through the eigendecomposition of its small Gram matrix (an animation matrix has few
    columns; LAPACK's SVD of a 30000 x 25 matrix is ~40 times slower)."""
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
    """Frame 0 must be complete for the online methods (the thesis assumes it); a partial frame 0
    is completed statically (Laplacian interpolation)."""
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
    """Shared frame loop: ``step(prev, cur, known_t) -> frame``; frame 0 completed statically."""
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
    r"""Recover missing vertices of a mesh animation with fixed connectivity (Sec. 5.3.2).

    ``method="motion"`` (Algorithm 12, online: frame ``t`` uses frames ``<= t`` only): the known
    vertices of frame ``t`` are anchors with motion ``m_j = v_t,j - v_t-1,j``; the unknown vertices
    in the first ring of an anchor are first-generation satellites, those in the first ring of a
    satellite the next generation, and so on; a satellite moves by the weighted mean of the
    motions of its already known neighbours (Eq. 5.91-5.92),
    ``m_i = sum_j w_dij w_pj m_j / sum_j |w_dij w_pj|``, ``v_t,i = v_t-1,i + m_i``, with
    ``w_dij = 1 / ||v_i - v_j||^2`` on the previous (complete) frame and the prioritisation weight
    ``w_p`` (1 for a new satellite, +1 per iteration for every known vertex, so anchors weigh
    most). Reading: Eq. 5.92 prints ``w_{p_i}`` (of the satellite itself), which would cancel out
    of the ratio; the weight of the neighbour ``j`` is used, as the text describes ("more emphasis
    on the anchor points instead of the satellites"). Second reading: Algorithm 12 estimates a
    satellite once, from the neighbours known when its generation is reached, so a
    first-generation satellite follows its one or two anchors only; the text calls the step "a
    weighted filtering approach". After the generations, the same filter (Eq. 5.92, weights
    ``w_d w_p``, anchors fixed) is applied ``sweeps`` more times to every non-anchor vertex, now
    with all its neighbours. ``sweeps=0`` is Algorithm 12 as printed. The default,
    :data:`MOTION_SWEEPS` = 20, was chosen on the tuning animation (horse-gallop, 25 frames,
    30 % known, seed 1; mean NMSVE over frames 1-24): 0 sweeps 1.08e-5, 10 sweeps 1.08e-6, 20
    1.01e-6, 50 0.99e-6 at 1.4x the time of 20; LIA 1.68e-6. On pose sets, whose frames are
    unrelated poses (the shared cat-poses and lion-poses), every motion step is less accurate
    than ``"li"`` frame by frame; ``static_switch`` (default on) lets the anchors of each frame
    choose a blend of the two (see the parameter).

    Baselines: ``"li"`` Laplacian interpolation of every frame on its own (binary ``L = D - C``,
    Eq. 4.24-4.27), ``"lia"`` Laplacian interpolation of the motion vectors from the previous
    completed frame (online), ``"mc"`` matrix completion of the whole ``(3n, T)`` animation matrix
    (Eq. 5.90 with the ALM of Eq. 5.80-5.89; offline, every frame is used) and ``"gmc"`` the same
    with the mesh Laplacian as a regulariser (:func:`_gmc_offline`; offline).

    Policies: frame 0 is assumed complete (the thesis); a partly known frame 0 is completed by
    Laplacian interpolation first. A frame without any known vertex repeats the previous
    completed frame (zero motion); a connected component without anchor in frame ``t`` keeps its
    previous positions (``"motion"``, ``"lia"``) -- never NaN. ``"li"`` and ``"mc"`` raise
    :class:`~spectrageo.InvalidInputError` where their problem is undetermined.

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
        Unknown entries may hold anything (NaN included).
    F : (m, 3) array_like of int
    known : (n,) or (T, n) bool array, or (n_k,) int array
        Known vertices, the same in every frame or per frame.
    method : {"motion", "li", "lia", "mc", "gmc"}
    tol, max_iter : float, int
        Stopping rule of ``"mc"`` (ALM) and ``"gmc"`` (relative change of the iterate).
    sweeps : int
        Filtering sweeps of ``"motion"`` after the satellite generations (see above; 0 =
        Algorithm 12 as printed).
    static_switch : bool
        ``"motion"`` only, not in the thesis; it serves pose sets, whose frames are unrelated
        poses. Per frame, a cheap leave-one-out screen at the anchors (:func:`_loo_ratio`)
        keeps the motion step when it is clearly better (ratio below :data:`SWITCH_SCREEN`);
        otherwise the folds of held-out anchors (every :data:`SWITCH_STRIDE`-th anchor from each
        offset of :data:`SWITCH_FOLDS`) are held out in turn, the frame is
        completed both by the motion step and by static Laplacian interpolation, and the blend
        ``a * motion + (1 - a) * interpolation`` whose weight fits the held-out anchors best
        (least squares, clipped to [0, 1]; Eq. S1 of ``_with_static_switch``) completes the
        frame from all anchors. Online still. False: every frame by the motion step.
    rng : int, Generator or None

    Returns
    -------
    (T, n, 3) float64 ndarray
        Known entries exactly the input ones, vertex order kept.
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
    """One frame of Algorithm 13 (Eq. 5.94-5.97) as a closure over the fixed graph ``C``."""
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
    """``B-hat``: unweighted first-ring mean motion, generation by generation from the known
    points (the ``sum_{Psi_1} d`` of Eq. 5.96)."""
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
    r"""Recover missing points of a point-cloud sequence with point correspondence (Sec. 5.3.3).

    ``method="wrli"`` (Algorithm 13, online): the binary kNN graph ``C`` (Eq. 5.93,
    ``n_neighbors``, symmetrised) is built once on frame 0 and kept for every frame. For frame
    ``t``: prioritisation ``w_p`` (``N`` for known points, ``N - 1`` for their neighbours, ..., 1
    for the most remote), Gaussian weights on the previous frame ``C_w,ij = w_p,i
    exp(-||v_i - v_j||^2 / (2 sigma^2)) c_ij`` (Eq. 5.94; reading: the thesis's kernel has no
    width, ``sigma`` is the mean graph edge length of frame 0 so that it is scale-free),
    ``L_w = D - C_w`` (Eq. 5.95), the known motions ``B_k``, the first-ring mean motion
    ``B-hat`` (propagated generation by generation from the known points), then the LASSO of
    Eq. 5.96 ``min_z 0.5 ||P - R z||^2 + gamma' ||z||_1`` with ``R = L_w[:, u]``,
    ``P = -L_w[:, k] B_k - R B-hat_u`` (:func:`spectrageo.linalg.lasso`, ADMM), and
    ``v_u(t) = v_u(t-1) + B-hat_u + z`` (Eq. 5.97 with the corrected motion). ``gamma`` is
    relative: ``gamma' = gamma * alpha_max`` where ``alpha_max = ||R^T P||_inf / n`` is the
    smallest weight giving ``z = 0`` (so ``gamma >= 1`` returns ``B-hat`` and ``gamma = 0``
    plain weighted Laplacian interpolation of the motion).

    Baselines as in :func:`complete_animation` (``"li"``, ``"lia"``, ``"mc"``, ``"gmc"``), on the
    kNN graph. Same policies for frame 0, empty frames and unreached components.

    Parameters
    ----------
    clouds : (T, n, 3) array_like or a list of T (n, 3) arrays
        The same ``n`` in every frame (point ``i`` is the same point over time).
    known : (n,) or (T, n) bool array, or (n_k,) int array
    method : {"wrli", "li", "lia", "mc", "gmc"}
    n_neighbors : int
    gamma : float
        Relative LASSO weight (see above).
    max_iter, tol : int, float
        ADMM iterations of ``"wrli"``; ``tol`` and ``max_iter`` also drive ``"mc"`` and ``"gmc"``.
    static_switch : bool
        ``"wrli"`` only, not in the thesis: the per-frame screen and blend with static Laplacian
        interpolation of :func:`complete_animation` (for sequences of unrelated shapes).
    rng : int, Generator or None

    Returns
    -------
    (T, n, 3) float64 ndarray
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
