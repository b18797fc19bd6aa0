"""Narrow-phase registration: Tukey-weighted ICP (Section 6.2.4, Eq. 6.39-6.41)."""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._errors import ConvergenceWarning
from .._validation import check_choice, check_positive
from ._common import (
    RegistrationResult,
    apply_transform,
    bbox_diagonal,
    downsample_to,
    knn_normals_at,
    make_transform,
    orthonormalize,
    rotvec_to_matrix,
    spacing,
    workers_for,
)

#: Tukey constant: gamma = 4.685 sigma gives 95 % efficiency under Gaussian residuals.
TUKEY_C = 4.685
#: per-iteration annealing factor of the Tukey scale (coarse-to-fine down to ``gamma_min``)
SHRINK = 0.85
#: coarse iterations use every COARSE_STRIDE-th source point (at least COARSE_MIN of them) while
#: the Tukey scale is above COARSE_UNTIL times its floor: the strided subset of a surface sample
#: has about sqrt(stride) times its spacing, and the floor is two spacings
COARSE_STRIDE = 4
COARSE_MIN = 2000
COARSE_UNTIL = COARSE_STRIDE**0.5
#: approximate nearest neighbours in the coarse iterations (KD-tree ``eps``)
COARSE_EPS = 1.0
#: neighbours (the point itself included) of a target normal (Eq. 6.31)
NORMAL_K = 10


class TargetIndex:
    """KD-tree, spacing and lazily computed unoriented normals of a target cloud.

    Parameters
    ----------
    T : (n, 3) float64
        The target points.
    normal_k : int
        Neighbours (the point itself included) of each normal (Eq. 6.31).
    need_normals : bool
        Whether :meth:`normals_at` is available.
    neighbors : (n, normal_k) int, optional
        Rows of ``T`` known to be the ``normal_k`` nearest points of each point in the order of
        ``tree.query(T[r], normal_k)`` (the point itself first), -1 where unknown; the normals of
        the known rows are computed from them instead of a search (the same values).
    point_spacing : float, optional
        ``spacing(T)`` when already known (e.g. from :func:`spacing_from_search`).
    tree : cKDTree, optional
        ``cKDTree(T)`` when already built (with its default options).
    """

    def __init__(
        self,
        T: np.ndarray,
        *,
        normal_k: int = NORMAL_K,
        need_normals: bool = True,
        neighbors: np.ndarray | None = None,
        point_spacing: float | None = None,
        tree: cKDTree | None = None,
    ):
        self.points = T
        self.tree = cKDTree(T) if tree is None else tree
        self.spacing = spacing(T, self.tree) if point_spacing is None else float(point_spacing)
        self.normal_k = int(normal_k)
        self._normals = np.zeros((T.shape[0], 3)) if need_normals else None
        self._known = np.zeros(T.shape[0], dtype=bool) if need_normals else None
        ok = neighbors is not None and need_normals and neighbors.shape == (T.shape[0], normal_k)
        self._neighbors = neighbors if ok else None

    def normals_at(self, j: np.ndarray) -> np.ndarray:
        """Unit normals (unoriented) of the target points ``j``."""
        if self._normals is None:
            raise RuntimeError("this TargetIndex was built without normals")
        # the sorted distinct unknown rows (np.unique's answer) by a mask instead of a sort
        mask = np.zeros(self._known.shape[0], dtype=bool)
        mask[j[~self._known[j]]] = True
        new = np.flatnonzero(mask)
        if new.size:
            if self._neighbors is None or self.normal_k > self.points.shape[0]:
                N = knn_normals_at(self.points, self.points[new], self.normal_k, self.tree)[0]
            else:
                N = self._normals_of(new)
            self._normals[new] = N
            self._known[new] = True
        return self._normals[j]

    def _normals_of(self, rows: np.ndarray) -> np.ndarray:
        """:func:`knn_normals_at` of the target at its points ``rows`` (sorted, distinct), the
        neighbour lists taken from ``neighbors`` where known and searched elsewhere, all rows
        in one batch as :func:`knn_normals_at` computes them."""
        idx = self._neighbors[rows].astype(np.intp)
        miss = np.flatnonzero(idx[:, 0] < 0)
        if miss.size:
            k = self.normal_k
            _, found = self.tree.query(self.points[rows[miss]], k=k,
                                       workers=workers_for(miss.size))  # fmt: skip
            idx[miss] = np.asarray(found).reshape(miss.size, k)
        return _normals_from(self.points, idx)


def _normals_from(P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Unoriented unit normals (m, 3) of the neighbourhoods ``P[idx]`` (``idx`` (m, k)): the
    eigenvector of the smallest eigenvalue of each neighbourhood's covariance (Eq. 6.31), the
    computation of :func:`knn_normals_at` after its search."""
    Q = P[idx]
    Q = Q - Q.mean(axis=1, keepdims=True)
    C = np.einsum("nki,nkj->nij", Q, Q)
    _, vec = np.linalg.eigh(C)
    return vec[:, :, 0]


def neighbors_from_search(
    keep: np.ndarray, d: np.ndarray, i: np.ndarray, normal_k: int
) -> np.ndarray | None:
    """The neighbour lists of :class:`TargetIndex` for the cloud ``P[keep]``, from a search of
    ``P`` on itself.

    ``d``, ``i`` (n, K) are the distances and rows of ``cKDTree(P).query(P, K)`` with every
    point first in its own row and no two points equal. A kept row whose first ``normal_k``
    entries are all kept and whose first ``normal_k + 1`` distances strictly increase has
    those entries as its ``normal_k`` nearest points in ``P[keep]``, in the one order any
    search returns them (no ties; every other point is farther); its entry is that list (rows
    of ``P[keep]``), other rows are -1. Returns None when ``K < normal_k + 1``.
    """
    n, K = d.shape
    if K < normal_k + 1:
        return None
    dd = d[:, : normal_k + 1]
    ok = np.all(dd[:, 1:] > dd[:, :-1], axis=1)
    rows = i[:, :normal_k]
    if not keep.all():
        ok &= keep[rows].all(axis=1)
        rows = (np.cumsum(keep) - 1)[rows]
    out = np.where(ok[:, None], rows, -1)
    return out[keep] if not keep.all() else out


def spacing_from_search(
    keep: np.ndarray, d: np.ndarray, i: np.ndarray, *, n_sample: int = 2000
) -> float | None:
    """:func:`spacing` of ``P[keep]`` from a search of ``P`` on itself, or None.

    ``d``, ``i`` (n, K) are the distances and rows of ``cKDTree(P).query(P, K)`` with every
    point first in its own row and no two points equal. The nearest other point of ``P[keep]``
    to a kept point is the first kept entry after the point itself, at that entry's distance
    (the same value a search of ``P[keep]`` computes); :func:`spacing`'s median is taken over
    its strided subset of ``P[keep]``. None when a point of the subset has no kept entry or the
    median is not positive (then :func:`spacing` decides).
    """
    rows = np.flatnonzero(keep)
    m = rows.size
    if m < 2:
        return None
    sub = rows[np.arange(0, m, max(1, m // n_sample))]
    kept = keep[i[sub, 1:]]
    first = np.argmax(kept, axis=1)
    if not kept[np.arange(sub.size), first].all():
        return None
    s = float(np.median(d[sub, 1 + first]))
    return s if s > 0 else None


def tukey_weights(r: np.ndarray, gamma: float) -> np.ndarray:
    """IRLS weights ``psi'(r) / r = (1 - r^2 / gamma^2)^2`` for ``|r| <= gamma`` (Eq. 6.41)."""
    u = 1.0 - (r / gamma) ** 2
    return np.where(np.abs(r) <= gamma, u * u, 0.0)


def _kabsch(P: np.ndarray, Q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares rigid transform taking ``P`` onto ``Q`` (Kabsch/Umeyama, no scale)."""
    sw = w.sum()
    cp = (w[:, None] * P).sum(0) / sw
    cq = (w[:, None] * Q).sum(0) / sw
    H = ((P - cp) * w[:, None]).T @ (Q - cq)
    U, _, Vt = np.linalg.svd(H)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ D @ U.T
    return make_transform(R, cq - R @ cp)


def _plane_step(P: np.ndarray, Q: np.ndarray, N: np.ndarray, w: np.ndarray, scale: float):
    """Linearised weighted point-to-plane increment, or None when singular."""
    c = (w[:, None] * P).sum(0) / w.sum()
    Pc = (P - c) / scale
    J = np.empty((P.shape[0], 6))
    J[:, 3:] = N
    # rows [Pc x N, N]: np.cross's component formulas without its set-up cost, the same bits
    # (docs/decisions.md#reg-speed3-overhead)
    for a, (i, k) in enumerate(((1, 2), (2, 0), (0, 1))):
        np.subtract(Pc[:, i] * N[:, k], Pc[:, k] * N[:, i], out=J[:, a])
    r = np.einsum("ij,ij->i", (P - Q) / scale, N)
    Jw = J * w[:, None]
    A = Jw.T @ J
    b = -Jw.T @ r
    ev = np.linalg.eigvalsh(A)
    if ev[0] <= 1e-9 * max(ev[-1], 1e-300):
        return None
    x = np.linalg.solve(A, b)
    R = rotvec_to_matrix(x[:3])
    # p -> R (p - c) + c + t
    return make_transform(R, c - R @ c + x[3:] * scale)


def _query(
    index: TargetIndex, P: np.ndarray, bound: float, eps: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest target within ``bound`` (inf beyond); ``eps > 0`` approximate."""
    d, j = index.tree.query(
        P, k=1, eps=eps, distance_upper_bound=bound, workers=workers_for(P.shape[0])
    )
    j = np.where(np.isfinite(d), j, 0)
    return d, j


def _score(P: np.ndarray, index: TargetIndex, T: np.ndarray, dist: float) -> tuple[float, float]:
    """``(fitness, rmse)``: share of ``T P`` within ``dist`` of the target, their RMS distance."""
    d, _ = index.tree.query(
        apply_transform(T, P), k=1, distance_upper_bound=dist, workers=workers_for(P.shape[0])
    )
    return _fit_rmse(d, np.isfinite(d))


def _fit_rmse(d: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    fit = float(ok.mean())
    rmse = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("inf")
    return fit, rmse


def _within(d: np.ndarray, dist: float) -> np.ndarray:
    """Rows of nearest distances ``d`` (from a query bounded by ``dist`` or more) that a query
    bounded by ``dist`` finds: ``d < dist``, compared on squares as the KD-tree does."""
    return d * d < dist * dist


def constraint(
    P: np.ndarray, index: TargetIndex, T: np.ndarray, dist: float, query: tuple | None = None
) -> float:
    """Smallest over largest eigenvalue of the point-to-plane information matrix ``J^T J`` of
    the inliers within ``dist`` (rows ``[(p - c) x n / l, n]``, ``l`` the source diagonal): near
    0 when a motion slides the source along the target (plane, line, sphere, no overlap).

    ``query``: ``(X, d, j)``, the moved source ``T P`` and its nearest target distances and rows
    within ``dist`` (as :func:`icp` returns with ``keep_query``), used instead of searching.
    """
    if query is not None:
        X, d, j = query
    else:
        X = apply_transform(T, P)
        d, j = index.tree.query(X, k=1, distance_upper_bound=dist, workers=workers_for(P.shape[0]))
    ok = np.isfinite(d)
    if ok.sum() < 6:
        return 0.0
    X, j = X[ok], j[ok]
    if index._normals is not None:
        N = index.normals_at(j)
    else:
        N = knn_normals_at(index.points, index.points[j], index.normal_k, index.tree)[0]
    scale = max(bbox_diagonal(P), 1e-300)
    J = np.c_[np.cross((X - X.mean(axis=0)) / scale, N), N]
    ev = np.linalg.eigvalsh(J.T @ J / X.shape[0])
    return float(max(ev[0], 0.0) / max(ev[-1], 1e-300))


def icp(
    S: np.ndarray,
    index: TargetIndex,
    T0: np.ndarray,
    *,
    max_iter: int,
    tol: float,
    method: str,
    gamma0: float | None,
    gamma_min: float,
    inlier_distance: float,
    coarse: bool = False,
    keep_query: bool = False,
) -> RegistrationResult:
    """Tukey-weighted ICP on prepared data (see :func:`narrow_phase`).

    ``keep_query``: also return, as ``info["final_query"]``, the moved full source ``X`` (n, 3)
    and its nearest target distances ``d`` (n,) and rows ``j`` (n,) within ``inlier_distance``
    (``inf`` and 0 beyond), the query that scored the final pose.
    """
    t0 = time.perf_counter()
    scale = max(bbox_diagonal(S), 1e-300)
    T = T0.copy()
    S_full = S
    # coarse to fine: while the Tukey window is wide the pose is far from its final value, and a
    # strided quarter of the source (at least COARSE_MIN points) determines the step as well
    coarse = coarse and S.shape[0] >= 2 * COARSE_MIN
    if coarse:
        S = S_full[:: max(2, min(COARSE_STRIDE, S.shape[0] // COARSE_MIN))]
    P = apply_transform(T, S)
    if gamma0 is None:
        # robust scale of the initial distances, on a strided subset (a nearest-neighbour query
        # far from the target is slow; later queries are bounded by gamma)
        sub = P[:: max(1, P.shape[0] // 2000)]
        gamma = TUKEY_C * 1.4826 * float(np.median(index.tree.query(sub, k=1, workers=1)[0]))
    else:
        gamma = float(gamma0)
    gamma = max(gamma, gamma_min)
    d, j = _query(index, P, gamma, COARSE_EPS if coarse else 0.0)
    converged = last = False
    it = 0
    while it < max_iter:
        it += 1
        w = tukey_weights(d, gamma)
        if np.count_nonzero(w) < 6:
            gamma *= 2.0
            if gamma > scale:
                break
            d, j = _query(index, P, gamma, COARSE_EPS if coarse else 0.0)
            continue
        Q = index.points[j]
        inc = None
        if method == "point_to_plane":
            inc = _plane_step(P, Q, index.normals_at(j), w, scale)
        if inc is None:
            inc = _kabsch(P, Q, w)
        T = inc @ T
        T[:3, :3] = orthonormalize(T[:3, :3])
        if coarse and gamma <= COARSE_UNTIL * gamma_min:
            S, coarse = S_full, False
        P = apply_transform(T, S)
        # the last allowed iteration also bounds its query by the inlier distance, so that the
        # final pose is scored from it (the rows within gamma are the same either way)
        last = it == max_iter and not coarse
        d, j = _query(index, P, max(gamma, inlier_distance) if last else gamma,
                      COARSE_EPS if coarse else 0.0)  # fmt: skip
        # robust scale of the current inliers; gamma only shrinks (annealing towards the noise)
        inl = d[d < gamma]
        new_gamma = gamma
        if inl.size >= 6:
            robust = TUKEY_C * 1.4826 * float(np.median(inl))
            new_gamma = max(gamma_min, min(robust, SHRINK * gamma))
        ang = np.arccos(min(max((np.trace(inc[:3, :3]) - 1) / 2, -1.0), 1.0))
        step = max(ang * scale, float(np.linalg.norm(inc[:3, 3])))
        gamma_stable = new_gamma > 0.99 * gamma
        gamma = new_gamma
        if step < tol * scale and gamma_stable and not coarse:
            converged = True
            break
    if last:
        X = P  # scored from the last query (its bound reached inlier_distance)
        ok = _within(d, inlier_distance)
    else:
        X = apply_transform(T, S_full)
        d, j = _query(index, X, inlier_distance)
        ok = np.isfinite(d)
    fit, rmse = _fit_rmse(d, ok)
    info = {"gamma": gamma, "time_s": time.perf_counter() - t0, "n_source": S_full.shape[0]}
    if keep_query:
        info["final_query"] = (X, np.where(ok, d, np.inf), np.where(ok, j, 0))
    return RegistrationResult(
        transformation=T,
        fitness=fit,
        inlier_rmse=rmse,
        n_iter=it,
        converged=converged,
        inlier_distance=inlier_distance,
        info=info,
    )


def check_icp_options(max_iter: Any, tol: Any, method: Any) -> None:
    check_positive(max_iter, "max_iter", integer=True)
    check_positive(tol, "tol")
    check_choice(method, "method", ("point_to_plane", "point_to_point"))


def run_narrow(
    S: np.ndarray,
    Tg: np.ndarray,
    T0: np.ndarray,
    *,
    max_iter: int = 60,
    tol: float = 1e-5,
    method: str = "point_to_plane",
    gamma: float | None = None,
    inlier_distance: float | None = None,
    max_points: int = 20000,
    index: TargetIndex | None = None,
    warn: bool = True,
    coarse: bool = True,
    keep_query: bool = False,
    source_spacing: float | None = None,
) -> RegistrationResult:
    """:func:`icp` on validated arrays: ``S`` down-sampled to ``max_points``, the target index
    built unless given, the scale floor two spacings and the inlier distance three
    (``source_spacing``: :func:`spacing` of the down-sampled ``S`` when already known)."""
    check_icp_options(max_iter, tol, method)
    check_positive(max_points, "max_points", integer=True)
    if gamma is not None:
        check_positive(gamma, "gamma")
    if inlier_distance is not None:
        check_positive(inlier_distance, "inlier_distance")
    Sd = downsample_to(S, max_points)
    if index is None:
        index = TargetIndex(
            downsample_to(Tg, max(5 * max_points, 100000)),
            need_normals=method == "point_to_plane",
        )
    hs = spacing(Sd) if source_spacing is None else float(source_spacing)
    h = max(index.spacing, hs, 1e-12 * max(bbox_diagonal(Tg), 1.0))
    dist = float(inlier_distance) if inlier_distance is not None else 3.0 * h
    res = icp(
        Sd,
        index,
        T0,
        max_iter=int(max_iter),
        tol=float(tol),
        method=method,
        gamma0=gamma,
        gamma_min=2.0 * h,
        inlier_distance=dist,
        coarse=bool(coarse),
        keep_query=keep_query,
    )
    if warn and not res.converged:
        warnings.warn(
            f"narrow phase stopped at max_iter={max_iter} before meeting tol={tol:g}.",
            ConvergenceWarning,
            stacklevel=3,
        )
    return res
