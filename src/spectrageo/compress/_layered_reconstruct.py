"""Layer order and frame reconstruction of the layered animation codec (Section 5.2.4).

Layer order (Eq. 5.55-5.59): one vertex is removed per layer, the one with the lowest cost
``C_s(i, l) + eta C_t(i)``: the spatial term (Eq. 5.57, ``rho = 0.6``) counts the removed
j-ring neighbours, the temporal term (Eq. 5.58, ``eta = 0.1``) is the mean motion divided by
its largest value. The removal order read backwards gives ``M_l`` = its first ``l`` vertices.

:class:`Reconstructor` (Algorithm 11 lines 7-15), run by decoder and encoder alike: the coarse
frame by weighted Laplacian interpolation of the motion vectors (Eq. 5.60-5.65, ring by ring
from the received vertices, then a few sweeps), and with ``fine=True`` the face normals
denoised by RPCA over the first ``n_t = 8`` frames and then by incremental SVD (Eq. 5.66-5.72),
unreceived vertices whose first-ring area changed by over 1 % (Eq. 5.73) moved towards the
faces' planes (Eq. 5.74-5.75).
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import scipy.sparse as sp
from numba import njit

from .._validation import as_faces, as_frames

#: removal-cost parameters of Eq. (5.57) and (5.59)
RHO = 0.6
ETA = 0.1
#: frames denoised by RPCA before the incremental SVD takes over (Eq. 5.66, "5-10 is enough")
NT_BAR = 8
#: iterations of the vertex update (Eq. 5.74, "only 1-2")
FINE_ITERS = 2
#: relative first-ring area change above which a vertex is refined (Eq. 5.73)
AREA_CHANGE = 0.01
#: sweeps of the geometric Laplacian interpolation after the ring-by-ring pass (Eq. 5.64)
SWEEPS = 4


# ----------------------------------------------------------------------------- layers
def _adjacency(F: np.ndarray, n: int) -> sp.csr_matrix:
    """Binary vertex adjacency ``C`` (CSR, zero diagonal) of the faces."""
    i, j = F[:, [0, 1, 2, 1, 2, 0]].ravel(), F[:, [1, 2, 0, 0, 1, 2]].ravel()
    C = sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    C.data[:] = 1.0
    C.setdiag(0)
    C.eliminate_zeros()
    return C.tocsr()


def _rings(F: np.ndarray, n: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Binary adjacency ``C`` and the ring-level matrix ``R`` (entry j for j-ring, j = 1..3)."""
    C = _adjacency(F, n)
    reach = sp.identity(n, format="csr")
    level = sp.csr_matrix((n, n))
    for ring in (1, 2, 3):
        nxt = ((reach @ C) + reach).astype(bool).astype(np.float64)
        new = nxt - reach
        new.eliminate_zeros()
        level = level + ring * new
        reach = nxt
    level = level.tocsr()
    level.sort_indices()
    return C, level


@njit(cache=True)
def _greedy_removal(indptr, indices, levels, ct, rho, n):  # pragma: no cover - compiled
    """Removal order of Eq. (5.56): repeatedly the vertex of lowest cost (5.59); a binary heap
    with lazy deletion (an entry is stale when the vertex's version moved on)."""
    size = np.zeros((n, 4))
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            size[i, levels[p]] += 1.0
    removed_cnt = np.zeros((n, 4))
    w = np.array([0.0, rho, rho**2, rho**3])
    version = np.zeros(n, dtype=np.int64)
    alive = np.ones(n, dtype=np.bool_)
    heap = [(ct[i], np.int64(i), np.int64(0)) for i in range(n)]
    heapq.heapify(heap)
    order = np.empty(n, dtype=np.int64)
    k = 0
    while len(heap) > 0:
        c, i, ver = heapq.heappop(heap)
        if not alive[i] or ver != version[i]:
            continue
        alive[i] = False
        order[k] = i
        k += 1
        for p in range(indptr[i], indptr[i + 1]):
            nb = indices[p]
            if alive[nb]:
                removed_cnt[nb, levels[p]] += 1.0
                version[nb] += 1
                cost = ct[nb]
                for j in range(1, 4):
                    if size[nb, j] > 0:
                        cost += removed_cnt[nb, j] / size[nb, j] * w[j]
                heapq.heappush(heap, (cost, np.int64(nb), version[nb]))
    return order


@njit(cache=True)
def _coarse_kernel(indptr, indices, prev, O, b, B, n_levels, sweeps):  # pragma: no cover
    """Eq. (5.60)-(5.64) in place on ``B`` (n, 3): edge weights ``P O`` from the previous frame,
    the unknown vertices ring by ring (``b`` = 1, 2, ...: the weighted mean motion of their
    neighbours of lower ``b``), then ``sweeps`` Jacobi sweeps over every unknown vertex with its
    whole first ring; vertices no received vertex reaches (``b < 0``) keep a zero motion."""
    n = prev.shape[0]
    nnz = indices.shape[0]
    w = np.empty(nnz)
    total = 0.0
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            d = np.sqrt(
                (prev[i, 0] - prev[j, 0]) ** 2
                + (prev[i, 1] - prev[j, 1]) ** 2
                + (prev[i, 2] - prev[j, 2]) ** 2
            )
            w[p] = d
            total += d
    eps = 1e-12 * (1.0 + total / max(nnz, 1))
    for p in range(nnz):
        w[p] = O[p] / (w[p] + eps)  # Eq. (5.60) x Eq. (5.61)
    for level in range(1, n_levels + 1):
        for i in range(n):
            if b[i] != level:
                continue
            s0 = 0.0
            acc = np.zeros(3)
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                if 0 <= b[j] < level:
                    s0 += w[p]
                    for c in range(3):
                        acc[c] += w[p] * B[j, c]
            if s0 > 0:
                for c in range(3):
                    B[i, c] = acc[c] / s0
    Bn = B.copy()
    for _ in range(sweeps):
        for i in range(n):
            if b[i] <= 0:
                continue
            s0 = 0.0
            acc = np.zeros(3)
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                s0 += w[p]
                for c in range(3):
                    acc[c] += w[p] * B[j, c]
            if s0 > 0:
                for c in range(3):
                    Bn[i, c] = acc[c] / s0
        for i in range(n):
            if b[i] > 0:
                for c in range(3):
                    B[i, c] = Bn[i, c]


#: levels of the temporal term: ``C_t / max C_t`` is rounded to ``k / CT_LEVELS`` and the
#: levels are sent, so the decoder recomputes the same order from the connectivity (Eq. 5.57
#: needs nothing else) instead of receiving a permutation (about 18 bits per vertex)
CT_LEVELS = 15


def motion_levels(frames) -> np.ndarray:
    """Quantised temporal term of Eq. (5.58): ``round(CT_LEVELS C_t / max C_t)`` per vertex."""
    A = np.asarray(frames, dtype=np.float64)
    if A.shape[0] < 2:
        return np.zeros(A.shape[1], dtype=np.int64)
    ct = np.linalg.norm(np.diff(A, axis=0), axis=2).mean(axis=0)
    top = float(ct.max())
    if not top > 0:
        return np.zeros(A.shape[1], dtype=np.int64)
    return np.rint(CT_LEVELS * ct / top).astype(np.int64)


def order_from_levels(F: np.ndarray, n: int, levels: np.ndarray, *, rho=RHO, eta=ETA):
    """Layer order from the connectivity and the temporal levels (Eq. 5.56-5.59)."""
    _C, level = _rings(F, n)
    removal = _greedy_removal(
        level.indptr,
        level.indices,
        level.data.astype(np.int64),
        eta * np.asarray(levels, dtype=np.float64) / CT_LEVELS,
        float(rho),
        n,
    )
    return removal[::-1].copy()


def layer_order(frames, F, *, rho: float = RHO, eta: float = ETA) -> np.ndarray:
    """Layer order (Eq. 5.55-5.59) of ``frames`` (T, n, 3) or (n, 3): an (n,) permutation whose first
    ``l`` vertices are the layer ``M_l`` (the last removed, the hardest to predict).
    """
    A = np.asarray(frames, dtype=np.float64)
    if A.ndim == 2:
        A = A[None]
    A = as_frames(A, "frames")
    n = A.shape[1]
    F = as_faces(F, n, "F")
    return order_from_levels(F, n, motion_levels(A), rho=rho, eta=eta)


# ----------------------------------------------------------------------------- reconstruction
def _norm3(X: np.ndarray) -> np.ndarray:
    """Euclidean norms along the last axis (length 3), summed in the order x, y, z."""
    return np.sqrt(X[..., 0] * X[..., 0] + X[..., 1] * X[..., 1] + X[..., 2] * X[..., 2])


def _face_normals(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cr = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    a = _norm3(cr)
    N = cr / np.where(a > 0, a, 1.0)[:, None]
    return N, 0.5 * a


def _unit_blocks(E: np.ndarray) -> np.ndarray:
    """Re-normalise every normal (3 consecutive columns) of a (m, 3k) matrix (Eq. 5.68)."""
    m, c = E.shape
    X = E.reshape(m, c // 3, 3)
    nrm = _norm3(X)[..., None]
    return (X / np.where(nrm > 0, nrm, 1.0)).reshape(m, c)


def _rpca_low_rank(M: np.ndarray, *, max_iter: int = 100, tol: float = 1e-5) -> np.ndarray:
    """Low-rank part ``E`` of the robust PCA ``M = E + S`` (Eq. 4.18) by the inexact ALM of
    Eq. 4.19-4.22 with the continuation of :func:`spectrageo.linalg.rpca`: the same iteration,
    with every singular value thresholding taken from :func:`._dense_fixed.svd_values` instead of
    LAPACK, so the decoder gets the same bits on every machine.
    """
    from ..linalg._kernels import ialm_prepare, ialm_update
    from ._dense_fixed import matmul, svd_values

    M = np.asarray(M, dtype=np.float64)
    transposed = M.shape[0] < M.shape[1]
    A = np.ascontiguousarray(M.T if transposed else M)
    m, n = A.shape
    lam = 1.0 / math.sqrt(m)
    fro = math.sqrt(float(_sum_squares(A)))
    E = np.zeros((m, n))
    if fro == 0:
        return E.T if transposed else E
    s, V, _info = svd_values(A)
    mu = 1.25 / s[0]
    mu_max = mu * 1e7
    R = np.zeros((m, n))
    X = np.empty((m, n))
    Ymu = np.empty((m, n))
    Xn = np.empty((m, n))
    mu_prev = mu
    eps = np.finfo(np.float64).eps
    for _ in range(max_iter):
        # D_{1/mu}: numerically non-zero singular values above the threshold
        p = int(np.count_nonzero(s > s[0] * max(m, n) * eps)) if s[0] > 0 else 0
        shr = np.maximum(s[:p] - 1.0 / mu, 0.0)
        k = int(np.count_nonzero(shr > 0))
        mu_next = min(mu * 1.5, mu_max)
        ialm_prepare(A, R, lam / mu_prev, mu_prev / mu, X, Ymu)
        if k:
            Pa = np.ascontiguousarray(V[:, :k] * (shr[:k] / s[:k]))
            Pb = np.ascontiguousarray(V[:, :k].T)
            Ec = matmul(matmul(X, Pa), Pb)
        else:
            Ec = np.zeros((m, n))
        res2 = ialm_update(A, Ec, Ymu, lam / mu, mu / mu_next, R, E, Xn)
        mu_prev, mu = mu, mu_next
        if math.sqrt(res2) / fro <= tol:
            break
        s, V, _info = svd_values(Xn)
    return np.ascontiguousarray(E.T) if transposed else E


def _svd_wide(E: np.ndarray):
    """Thin SVD ``(U, s, V, info)`` of a matrix with fewer rows than columns, from that of its
    transpose (:func:`._dense_fixed.svd`)."""
    from ._dense_fixed import svd

    U, s, V, info = svd(np.ascontiguousarray(E.T))
    return V, s, U, info


@njit(cache=True)
def _mean(x):  # pragma: no cover - compiled
    """Mean of a 1-D array summed in index order."""
    acc = 0.0
    for i in range(x.size):
        acc += x[i]
    return acc / max(x.size, 1)


@njit(cache=True)
def _sum_squares(A):  # pragma: no cover - compiled
    """``sum A^2`` over the rows in order (fixed summation order)."""
    m, n = A.shape
    acc = 0.0
    for i in range(m):
        for j in range(n):
            acc += A[i, j] * A[i, j]
    return acc


class Reconstructor:
    """Decoder state (Algorithm 11 lines 7-15); the encoder runs the same one (closed loop)."""

    def __init__(self, F: np.ndarray, n: int, order: np.ndarray, *, fine: bool = True) -> None:
        self.F = F
        self.n = n
        self.order = order
        self.fine = fine
        C = _adjacency(F, n)
        self.C = C
        self.rows = np.repeat(np.arange(n), np.diff(C.indptr))
        self.cols = C.indices
        self._plans: dict = {}
        self.prev: np.ndarray | None = None
        self.prev2: np.ndarray | None = None
        self.prev_area: np.ndarray | None = None
        self.history: list[np.ndarray] = []  # face normals of the first NT_BAR frames
        self.svd: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.motion_sum = np.zeros(n)
        self.t = 0
        # vertex -> incident faces
        m = F.shape[0]
        self.VF = sp.csr_matrix(
            (np.ones(3 * m), (F.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m)
        )

    # -- frame 0
    def first(self, V0: np.ndarray) -> np.ndarray:
        self.prev = V0.copy()
        N, a = _face_normals(V0, self.F)
        self.prev_area = self.VF @ a
        self.t = 1
        if self.fine:
            self.history = [N]
        return self.prev

    # -- Eq. (5.60)-(5.65)
    def _plan(self, known: np.ndarray):
        """What depends only on the received set: the rings ``b`` around it (BFS) and ``O``
        (Eq. 5.61); cached, since a stream sends few distinct layers."""
        key = known.tobytes()
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        n = self.n
        is_known = np.zeros(n, dtype=bool)
        is_known[known] = True
        b = np.full(n, -1, dtype=np.int64)
        b[is_known] = 0
        reached = is_known.copy()
        fronts = []
        level = 0
        while True:
            nb = (self.C @ reached.astype(np.float64) > 0) & ~reached
            if not nb.any():
                break
            level += 1
            b[nb] = level
            fronts.append(nb)
            reached |= nb
        bc = b[self.cols]
        O = np.where(bc == 0, 4.0, 1.0 / (np.maximum(bc, 0) + 1.0))  # Eq. (5.61), read on j
        plan = (is_known, fronts, O, reached & ~is_known, reached, b)
        if len(self._plans) > 64:
            self._plans.clear()
        self._plans[key] = plan
        return plan

    def coarse(self, known: np.ndarray, motion_known: np.ndarray) -> np.ndarray:
        n, prev = self.n, self.prev
        B = np.zeros((n, 3))
        B[known] = motion_known
        if known.size == n:
            return prev + B
        _k, fronts, O, _u, _r, b = self._plan(np.asarray(known, dtype=np.int64))
        _coarse_kernel(self.C.indptr, self.cols, prev, O, b, B, len(fronts), SWEEPS)
        return prev + B  # Eq. (5.65)

    # -- Eq. (5.66)-(5.72)
    def _denoised_normals(self, N: np.ndarray) -> np.ndarray:
        """Denoised face normals of the new frame (Eq. 5.66-5.72); every factorisation and
        product is a fixed-order kernel of :mod:`._dense_fixed` (the same bits everywhere)."""
        from ._dense_fixed import matmul, matmul_tn, qr, svd

        if self.svd is None:
            self.history.append(N)
            M = np.concatenate(self.history, axis=1)  # Eq. (5.66)
            E = _unit_blocks(_rpca_low_rank(M, max_iter=100, tol=1e-5))  # Eq. (5.67)-(5.68)
            if len(self.history) >= NT_BAR:
                U, s, V, _info = svd(E) if E.shape[0] >= E.shape[1] else _svd_wide(E)
                keep = s > 1e-6 * s[0]
                self.svd = (
                    np.ascontiguousarray(U[:, keep]),
                    s[keep],
                    np.ascontiguousarray(V[:, keep]),
                )
                self.history = []
            return E[:, -3:]
        U, s, V = self.svd
        q = s.size
        N = np.ascontiguousarray(N)
        P = matmul_tn(U, N)
        Rm = N - matmul(U, P)
        Q, R = qr(Rm)  # Eq. (5.69)
        K = np.block([[np.diag(s), P], [np.zeros((3, q)), R]])  # Eq. (5.70)
        Uk, sk, Vk, _info = svd(K)
        Uk, sk, Vk = np.ascontiguousarray(Uk[:, :q]), sk[:q], Vk[:, :q]
        U2 = matmul(np.concatenate([U, Q], axis=1), Uk)  # Eq. (5.71)
        Vn = np.ascontiguousarray(Vk[q:])  # the new frame's rows of the right factor
        Fd = _unit_blocks(matmul(U2 * sk, np.ascontiguousarray(Vn.T)))
        # Eq. (5.72): shift the window -- drop the oldest frame, keep the denoised new one
        Vold = matmul(np.ascontiguousarray(V[3:]), np.ascontiguousarray(Uk[:q]))
        Vstack = np.concatenate([Vold, Vn], axis=0)
        Qv, Rv = qr(Vstack)
        u2, s2, v2, _info = svd(np.ascontiguousarray(sk[:, None] * Rv.T))
        self.svd = (matmul(U2, u2), s2, matmul(Qv, v2))
        return Fd

    # -- Eq. (5.73)-(5.76)
    def refine(self, X: np.ndarray, is_known: np.ndarray) -> np.ndarray:
        N, a = _face_normals(X, self.F)
        Nd = self._denoised_normals(N)
        area = self.VF @ a
        change = np.abs(area - self.prev_area) / np.maximum(
            np.maximum(area, self.prev_area), 1e-300
        )
        move = (change > AREA_CHANGE) & ~is_known  # Eq. (5.73), received vertices stay
        self.prev_area = area
        if not move.any():
            return X
        ct = self.motion_sum / max(self.t, 1)
        mean_ct = float(_mean(ct))
        kappa = np.where(is_known, 4.0, 1.0) / (1.0 + ct / mean_ct if mean_ct > 0 else 1.0)
        F0, F1, F2 = self.F[:, 0], self.F[:, 1], self.F[:, 2]
        nu = (kappa[F0] + kappa[F1] + kappa[F2]) / 3.0  # Eq. (5.75), per face
        X = X.copy()
        F = self.F
        wsum = self.VF @ nu
        wsum = np.where(wsum > 0, wsum, 1.0)
        for _ in range(FINE_ITERS):  # Eq. (5.74) with the centroids of Eq. (5.76)
            c = (X[F[:, 0]] + X[F[:, 1]] + X[F[:, 2]]) / 3.0
            acc = np.zeros_like(X)
            for k in range(3):
                g = c - X[F[:, k]]
                d = Nd[:, 0] * g[:, 0] + Nd[:, 1] * g[:, 1] + Nd[:, 2] * g[:, 2]
                np.add.at(acc, F[:, k], (nu * d)[:, None] * Nd)
            X[move] += acc[move] / wsum[move, None]
        return X

    def predict(self, idx: np.ndarray) -> np.ndarray:
        """Predicted positions of the vertices ``idx`` in the next frame: constant velocity
        from the last two decoded frames (the last frame alone after the first)."""
        if self.prev2 is None:
            return self.prev[idx]
        return 2.0 * self.prev[idx] - self.prev2[idx]

    def step(self, known: np.ndarray, motion_known: np.ndarray) -> np.ndarray:
        """Frame ``t`` from the received vertices ``known`` and their motion vectors."""
        X = self.coarse(known, motion_known)
        is_known = np.zeros(self.n, dtype=bool)
        is_known[known] = True
        if self.fine:
            X = self.refine(X, is_known)
        self.motion_sum += np.linalg.norm(X - self.prev, axis=1)
        self.prev2 = self.prev
        self.prev = X
        self.t += 1
        return X

    def correct(self, residual: np.ndarray) -> np.ndarray:
        """Add a refresh frame's residuals to the last frame."""
        self.prev = self.prev + residual
        return self.prev
