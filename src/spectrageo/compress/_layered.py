"""Scalable layered coding of mesh animations for low-latency streaming (Section 5.2.4,
Algorithm 11), method ``"layered"`` of the ``.sga`` container.

Encoder, offline (Eq. 5.55-5.59): one vertex is removed per layer, the one with the lowest
removal cost ``C(i, l) = C_s(i, l) + eta C_t(i)``, where the spatial term
``C_s = sum_{j=1..3} (|R_j(i)| - |R^_j(i, l)|) / |R_j(i)| rho^j`` (Eq. 5.57, ``rho = 0.6``)
counts the already removed j-ring neighbours and the temporal term ``C_t`` (Eq. 5.58) is the
mean motion of the vertex between consecutive frames (``eta = 0.1``). The removal order read
backwards is the layer order: layer ``l`` is ``M_l`` = its first ``l`` vertices (Eq. 5.55).
``C_t`` is divided by its largest value so that ``eta`` does not depend on the model's scale
or speed (the thesis leaves the unit open; measured in mean edge lengths instead, the temporal
term outweighed the spatial one on horse-gallop and the layers clustered on the legs, leaving
vertices 47 rings away from any received one at layer 0.1).

Encoder, online: frame 0 is sent whole (its quantised positions); frame ``t`` sends layer
``l_t`` -- the positions of the vertices of ``M_{l_t}`` as residuals against a constant-velocity
prediction from the two previous *decoded* frames (closed loop, so quantisation errors do not
accumulate on them; the thesis transmits the vertices without saying how they are coded; on
horse-gallop the prediction saves only about 2 % of their bits against the last frame alone),
uniformly quantised with the step ``s`` (a fraction of twice the first frame's bounding-box
diagonal) and entropy coded; the decoder turns them into the motion vectors of Eq. (5.64). The
layer of every frame is chosen for a target rate (``bpvf``: the largest layer whose frame fits
the budget), which is the per-frame rate adaptation of Algorithm 11 line 5 (for a whole file,
:func:`encode` searches the per-frame budget that brings the whole file -- header and first
frame included -- to ``bpvf``; ``error=`` bisects the layer fraction against the KG error).
When a whole-file request lies beyond what every vertex at the default step gives (a rate
above it, an error below it) and no ``step`` is given, the step is bisected instead with every
vertex sent. Every ``refresh`` frames (default 16; 0 = never) a refresh frame
also sends the quantised residual of every other vertex against the decoder's prediction, which
bounds the drift of the vertices that are never transmitted (the thesis streams without it; the
residuals are mostly zero and cheap).

Decoder (Algorithm 11 lines 7-15), frame by frame, needing only frames ``<= t``:

1. coarse reconstruction by weighted Laplacian interpolation of the motion vectors
   (Eq. 5.60-5.65): weights ``P_ij = 1 / (||v_i(t-1) - v_j(t-1)|| + eps)`` (Eq. 5.60) times
   ``O_ij = 4`` when the neighbour ``j`` was received and ``1 / (b_j + 1)`` otherwise, ``b_j``
   its topological distance to the received set (Eq. 5.61; the thesis writes the condition on
   ``v_i``, but the weight multiplies the neighbour's motion in Eq. 5.64, so it is read on
   ``j``); the "geometric" solver of Eq. 5.64 visits the unknown vertices ring by ring from the
   received ones (each takes the weighted mean motion of its already estimated neighbours) and
   then sweeps a few times over all unknown vertices with all neighbours, until
   ``|R^_1(i)| = |R_1(i)|``; ``v_u(t) = v_u(t-1) + B_u`` (Eq. 5.65);
2. fine reconstruction (``fine=True``; off by default: on the tuning animation, horse-gallop's
   first 48 frames at layer 0.1 and 0.05 and step 2.5e-4, it changed the KG error by less than
   0.3 % while making decoding 4-13 times slower): the face normals of the coarse frame are denoised by RPCA over the
   first ``n_t`` frames (Eq. 5.66-5.68, ``n_t = 8``) and afterwards by the incremental SVD of
   Eq. 5.69-5.71 with the shifting window of Eq. 5.72; the vertices that were not received and
   whose first-ring area changed by more than 1 % (``Phi``, Eq. 5.73) are moved towards the
   faces' planes (Eq. 5.74, 2 iterations) with face weights ``nu`` (Eq. 5.75) that favour
   received and slow vertices: ``nu`` = mean over the face's corners of ``(4 if received else 1)
   / (1 + C_t / mean C_t)`` (Eq. 5.75 prints ``4 C_t`` and ``C_t``, which favours *fast*
   vertices, against the text's "emphasizing the known and less moving points"; the text is
   followed).

Stream layout: a header segment (kind 0: frame count, step, refresh, fine; chunks:
connectivity, the temporal levels from which both sides compute the layer order), one segment
per frame (kind 1, ``nf = 1``; chunk: layer, coded residuals of the sent vertices and, on
refresh frames, of the others) and, for files, the frame index (kind 2).
Decoding is sequential: a frame needs the decoded frame before it (random access starts at
frame 0; the frame index still gives each frame's offset and length).
"""

from __future__ import annotations

import heapq
import math
import struct

import numpy as np
import scipy.sparse as sp
from numba import njit

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames
from . import _connectivity, _container
from ._animation import KIND_BLOCK, KIND_HEADER, TAG_CONNECTIVITY
from ._container import Reader, varint
from ._entropy import decode_groups, encode_groups

METHOD = "layered"
#: removal-cost parameters of Eq. (5.57) and (5.59)
RHO = 0.6
ETA = 0.1
#: frames denoised by RPCA before the incremental SVD takes over (Eq. 5.66, "5-10 is enough")
NT_BAR = 8
#: default quantisation step of positions and motion vectors (fraction of twice the first
#: frame's diagonal); chosen on horse-gallop (tuning split): 1e-3 at layer 0.1 gave 2.72 bpvf /
#: KG 1.24, against 3.57 / 1.13 at 2.5e-4 and 3.22 / 1.21 at 2e-3 with layer 0.2
DEFAULT_STEP = 1e-3
#: smallest step the ``error=`` rate control tries (same unit as ``DEFAULT_STEP``)
_STEP_MIN = 1e-7
#: the rate controls stop within 3 % so that the 5 % contract holds
_AIM = 0.03
#: default layer (fraction of the vertices sent per frame) without a rate target
DEFAULT_LAYER = 0.1
DEFAULT_REFRESH = 16
#: iterations of the vertex update (Eq. 5.74, "only 1-2")
FINE_ITERS = 2
#: relative first-ring area change above which a vertex is refined (Eq. 5.73)
AREA_CHANGE = 0.01
#: sweeps of the geometric Laplacian interpolation after the ring-by-ring pass (Eq. 5.64)
SWEEPS = 4

# segment kinds and the connectivity tag are those of the other .sga streams (a frame is a block
# of one frame), so the shared parser (:func:`._animation.iter_segments`) reads both
KIND_FRAME = KIND_BLOCK
TAG_ORDER = 2  # the temporal levels from which the layer order is computed
TAG_FRAME = 7
_HEAD = struct.Struct("<BIdIB")  # kind, frame count, step, refresh, fine
_FRAME = struct.Struct("<BIIId")  # kind, frame number, frame number, 1, step (block layout)
_MAX_FRAMES = 1 << 24


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
    """Layer order of the vertices (Eq. 5.55-5.59): ``order[:l]`` is the layer ``M_l``.

    ``frames``: (T, n, 3) (T >= 1; the temporal term uses all of them, Eq. 5.58, quantised to
    :data:`CT_LEVELS` levels of its maximum) or (n, 3). Returns an (n,) permutation; the first
    vertices are the last to be removed, i.e. the hardest to predict.
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
    """Low-rank part ``E`` of the robust PCA ``M = E + S`` (principal component pursuit, Eq.
    4.18), by the inexact augmented Lagrangian method of Eq. 4.19-4.22 with the continuation of
    :func:`spectrageo.linalg.rpca` (``lam = 1 / sqrt(max(m, n))``, ``mu_0 = 1.25 / ||M||_2``,
    ``mu <- min(1.5 mu, 1e7 mu_0)``, stop at ``||M - E - S||_F <= tol ||M||_F``).

    The same iteration as ``rpca(M, max_iter=max_iter, tol=tol).low_rank`` (its row-chunked
    engine, whose element-wise kernels it shares), with every singular value thresholding
    ``D_{1/mu}(X) = X V diag((s - 1/mu)_+ / s) V^T`` taken from the thin SVD of
    :func:`._dense_fixed.svd_values` (Householder QR, one-sided Jacobi) instead of LAPACK, so
    that the decoder gets the same bits on every machine.
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


# ----------------------------------------------------------------------------- segments
def _segment(n, m, origin, scale, params: bytes, chunks) -> bytes:
    return _container.Container(METHOD, n, m, origin, scale, params, False, chunks).to_bytes()


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    q = np.rint(x / step)
    if q.size and np.abs(q).max() > 2**39:
        raise InvalidInputError("motion too large for the quantisation step; use a larger step.")
    return q.astype(np.int64)


def _code_ints(q: np.ndarray) -> bytes:
    """(k, 3) ints: one Laplace group per coordinate."""
    if q.size == 0:
        return b""
    g = np.broadcast_to(np.arange(3), q.shape).ravel()
    return encode_groups(q.ravel(), g, 3)


def _decode_ints(buf: bytes, k: int, what: str) -> np.ndarray:
    if k == 0:
        return np.zeros((0, 3), dtype=np.int64)
    g = np.broadcast_to(np.arange(3), (k, 3)).ravel()
    return decode_groups(buf, g, 3, what).reshape(k, 3)


def _frame_payload(layer: int, q_known: np.ndarray, q_res: np.ndarray | None) -> bytes:
    a = _code_ints(q_known)
    body = varint(layer) + varint(len(a)) + a
    if q_res is not None:
        body += b"\x01" + _code_ints(q_res)
    else:
        body += b"\x00"
    return body


def _parse_payload(buf: bytes, n: int):
    r = Reader(buf, "layered frame")
    layer = r.varint()
    if not 0 <= layer <= n:
        raise InvalidInputError(".sga layered frame has an invalid layer.")
    la = r.varint()
    a = r.take(la)
    flag = r.take(1)[0]
    if flag not in (0, 1):
        raise InvalidInputError(".sga layered frame is malformed.")
    q_known = _decode_ints(a, layer, "layered motion vectors")
    q_res = _decode_ints(r.rest(), n - layer, "layered residuals") if flag else None
    return layer, q_known, q_res


# ----------------------------------------------------------------------------- encoder
class LayeredEncoder:
    """Online encoder: :meth:`push` one frame at a time (``StreamEncoder(method="layered")``)."""

    def __init__(
        self,
        F,
        *,
        step: float | None = None,
        bpvf: float | None = None,
        layer: float | None = None,
        refresh: int = DEFAULT_REFRESH,
        fine: bool = False,
        motion_frames=None,
        n_frames: int = 0,
    ) -> None:
        self.F_in = F
        self.step = DEFAULT_STEP if step is None else float(step)
        if not (math.isfinite(self.step) and 1e-7 <= self.step <= 1.0):
            raise InvalidInputError(f"`step` must be in [1e-7, 1]; got {step!r}.")
        self.bpvf = None if bpvf is None else float(bpvf)
        if self.bpvf is not None and not (math.isfinite(self.bpvf) and self.bpvf > 0):
            raise InvalidInputError(f"`bpvf` must be a positive number; got {bpvf!r}.")
        if layer is not None and (
            isinstance(layer, bool) or not isinstance(layer, int | float) or not 0 < layer <= 1
        ):
            raise InvalidInputError(f"`layer` must be a fraction in (0, 1]; got {layer!r}.")
        self.layer = DEFAULT_LAYER if layer is None else float(layer)
        if isinstance(refresh, bool) or not isinstance(refresh, int | np.integer) or refresh < 0:
            raise InvalidInputError(f"`refresh` must be a non-negative integer; got {refresh!r}.")
        self.refresh = int(refresh)
        self.fine = bool(fine)
        self.motion_frames = motion_frames
        self.n_frames = int(n_frames)
        self.t = 0
        self.offset = 0
        self.entries: list[tuple[int, int, int, int]] = []
        self.started = False
        self.closed = False
        self.layers: list[int] = []

    def _start(self, V0: np.ndarray) -> bytes:
        n = V0.shape[0]
        self.n = n
        self.F = as_faces(self.F_in, n, "F")
        if n > _container.MAX_COUNT or self.F.shape[0] > _container.MAX_COUNT:
            raise InvalidInputError("the animation is too large for the .sga format.")
        lo, hi = V0.min(axis=0), V0.max(axis=0)
        self.origin = 0.5 * (lo + hi)
        diag = float(np.linalg.norm(hi - lo))
        self.scale = 2.0 * diag if diag > 0 else 1.0  # room for motion beyond the first frame
        mf = V0[None] if self.motion_frames is None else np.asarray(self.motion_frames)
        levels = motion_levels(mf)
        self.order = order_from_levels(self.F, n, levels)
        self.rec = Reconstructor(self.F, n, self.order, fine=self.fine)
        head = _HEAD.pack(KIND_HEADER, self.n_frames, self.step, self.refresh, int(self.fine))
        chunks = [
            (TAG_CONNECTIVITY, _connectivity.encode_faces(self.F)),
            (TAG_ORDER, encode_groups(levels, np.zeros(n, dtype=np.int64), 1)),
        ]
        seg = _segment(n, self.F.shape[0], tuple(self.origin), self.scale, head, chunks)
        self.started = True
        self.offset = len(seg)
        return seg

    def _frame_segment(self, body: bytes) -> bytes:
        params = _FRAME.pack(KIND_FRAME, self.t, self.t, 1, self.step)
        return _segment(
            self.n, self.F.shape[0], tuple(self.origin), self.scale, params, [(TAG_FRAME, body)]
        )

    def push(self, frame) -> bytes:
        """Add one frame (n, 3); returns its bytes (the header too, with the first frame)."""
        if self.closed:
            raise InvalidInputError("the stream is closed.")
        V = np.asarray(frame, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or (self.started and V.shape[0] != self.n):
            raise InvalidInputError(f"`frame` must have shape (n, 3); got {V.shape}.")
        if not np.isfinite(V).all():
            raise InvalidInputError("`frame` contains NaN or inf coordinates.")
        out = b"" if self.started else self._start(V)
        X = (V - self.origin) / self.scale
        s = self.step
        if self.t == 0:  # the whole first frame (decodable from the first packet)
            q = _quantise(X[self.order], s)
            P0 = np.empty((self.n, 3))
            P0[self.order] = q * s
            self.rec.first(P0)
            body = _frame_payload(self.n, q, None)
            layer = self.n
        else:
            refresh = self.refresh > 0 and self.t % self.refresh == 0
            layer, body = self._choose_layer(X, refresh)
        seg = self._frame_segment(body)
        self.layers.append(layer)
        self.entries.append((self.t, 1, self.offset, len(seg)))
        self.offset += len(seg)
        self.t += 1
        return out + seg

    def _choose_layer(self, X: np.ndarray, refresh: bool) -> tuple[int, bytes]:
        n, s = self.n, self.step
        if self.bpvf is None:
            layer = max(1, int(round(self.layer * n)))
        else:  # Algorithm 11 line 5: the largest layer whose motion vectors fit the budget
            budget = self.bpvf * n / 8.0
            lo, hi = 1, n

            pred = self.rec.predict(self.order)

            def size(k):
                return len(_code_ints(_quantise(X[self.order[:k]] - pred[:k], s))) + 8

            if size(hi) <= budget:
                lo = hi
            while hi - lo > max(1, n // 200):
                mid = (lo + hi) // 2
                if size(mid) <= budget:
                    lo = mid
                else:
                    hi = mid
            layer = lo
        known = self.order[:layer]
        pk = self.rec.predict(known)
        q = _quantise(X[known] - pk, s)  # closed loop: against the decoder's prediction
        Xr = self.rec.step(known, pk + q * s - self.rec.prev[known])
        q_res = None
        if refresh:
            rest = self.order[layer:]
            q_res = _quantise(X[rest] - Xr[rest], s)
            res = np.zeros((n, 3))
            res[rest] = q_res * s
            self.rec.correct(res)
        return layer, _frame_payload(layer, q, q_res)

    def close(self) -> bytes:
        """The frame index; returns the final bytes."""
        if self.closed:
            return b""
        self.closed = True
        if not self.started:
            raise InvalidInputError("the stream has no frame.")
        from ._animation import index_segment

        return index_segment(
            METHOD, self.n, self.F.shape[0], tuple(self.origin), self.scale, self.entries
        )


def encode(frames, F, *, step=None, bpvf=None, error=None, **options) -> bytes:
    """Layered coding of a whole animation (the layer decomposition uses all its frames)."""
    A = as_frames(frames, "frames")
    F = as_faces(F, A.shape[1], "F")
    T = A.shape[0]
    if T > _MAX_FRAMES:
        raise InvalidInputError("the animation is too large for the .sga format.")
    bad = sorted(set(options) - {"layer", "refresh", "fine"})
    if bad:
        raise InvalidInputError(
            f"unknown option(s) {bad} for method 'layered'; use ['fine', 'layer', 'refresh']."
        )

    def build(step=step, **kw):
        enc = LayeredEncoder(F, motion_frames=A, n_frames=T, step=step, **options, **kw)
        return b"".join(enc.push(A[t]) for t in range(T)) + enc.close()

    if bpvf is not None:
        return _whole_file_rate(
            build, float(bpvf), A.shape[1] * T, "layer" in options, step_given=step is not None
        )
    if error is None:
        return build()
    if "layer" in options:
        raise InvalidInputError("`layer` cannot be combined with `error`.")
    from ..metrics import kg_error

    target = float(error)
    best = None
    if step is None:
        full = build(layer=1.0)
        e_full = kg_error(decode(full)[0], A)
        best = (abs(e_full - target) / target, full)  # a candidate for the layer search too
        if e_full > target * (1 + _AIM):
            # even sending every vertex of every frame, the default step's rounding is above
            # the request: every vertex is sent and the step is bisected instead
            return _error_by_step(build, A, target, best)
    # the KG error falls as the layer grows: bisection on the layer fraction, within 5 %
    return _bisect_log(
        lambda f: build(layer=f),
        lambda data: -kg_error(decode(data)[0], A),
        -target,
        1e-3,
        1.0,
        best,
        "error",
        iters=14,
        hint="; the step bounds the error from below, try a smaller `step`",
    )


def _bisect_log(make, measure, target, lo, hi, best, what, *, iters=40, hint=""):
    """Bisection (log scale) of a knob in ``[lo, hi]`` until ``measure(make(knob))`` is within 3 %
    of ``target`` (5 % is the contract). ``measure`` must grow with the knob (pass the negatives
    of a measure that falls, and of its target). ``best`` is ``None`` or the (relative gap,
    data) to beat; ``what`` names the request in the error raised when 5 % is not met."""
    for _ in range(iters):
        mid = math.sqrt(lo * hi)
        data = make(mid)
        value = measure(data)
        gap = abs(value - target) / abs(target)
        if best is None or gap < best[0]:
            best = (gap, data)
        if gap <= _AIM:
            break
        if value > target:
            hi = mid
        else:
            lo = mid
        if hi / lo < 1.0001:
            break
    if best[0] > 0.05:
        raise InvalidInputError(
            f"`{what}` = {abs(target):g} could not be met within 5 % with 'layered' (closest: "
            f"{best[0]:.1%} away){hint}."
        )
    return best[1]


def _error_by_step(build, A, target: float, best) -> bytes:
    """``error=`` below what the default step gives with every vertex sent: the step is
    bisected at layer 1, within 5 % of the KG error ``target``; ``best`` is the (relative gap,
    data) of the default step."""
    from ..metrics import kg_error

    return _bisect_log(
        lambda s: build(step=s, layer=1.0),
        lambda data: kg_error(decode(data)[0], A),
        target,
        _STEP_MIN,
        DEFAULT_STEP,
        best,
        "error",
    )


def _rate_by_step(build, target: float, nvf: int, budget: float, best) -> bytes:
    """``bpvf`` above what the default step gives with every vertex sent (a per-frame
    ``budget`` that sends them all): the step is bisected, within 5 %."""
    finest = build(step=_STEP_MIN, bpvf=budget)
    r_top = 8.0 * len(finest) / nvf
    if r_top < target * 0.95:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': every vertex of every frame "
            f"at the smallest step ({_STEP_MIN:g}) gives {r_top:.3g} bpvf here."
        )
    return _bisect_log(
        lambda s: build(step=s, bpvf=budget),
        lambda data: -8.0 * len(data) / nvf,  # the rate falls as the step grows
        -target,
        _STEP_MIN,
        DEFAULT_STEP,
        best,
        "bpvf",
    )


def _whole_file_rate(
    build, target: float, nvf: int, fixed_layer: bool, *, step_given: bool = True
) -> bytes:
    """``bpvf`` for a whole file: bisection on the per-frame budget of the rate adaptation so
    that the file -- header and whole first frame included -- is within 5 % of ``target``. A
    target above what every vertex of every frame gives at the default step (``step`` not
    given) is met by bisecting the step with every vertex sent."""
    if fixed_layer:
        raise InvalidInputError("`layer` cannot be combined with `bpvf`.")

    def rate(b):
        data = build(bpvf=b)
        return 8.0 * len(data) / nvf, data

    lo, hi = 1e-3 * target, 64.0 * target
    r_lo, d_lo = rate(lo)
    if r_lo > target * 1.05:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': the header and the whole "
            f"first frame alone give {r_lo:.3g} bpvf here (more frames amortise them)."
        )
    r_hi, d_hi = rate(hi)
    if r_hi < target * 0.95 and not step_given:
        return _rate_by_step(build, target, nvf, hi, (abs(r_hi - target) / target, d_hi))
    if r_hi < target * 0.95:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': sending every vertex of "
            f"every frame gives {r_hi:.3g} bpvf here (use a smaller `step`)."
        )
    best = min((abs(r_lo - target) / target, d_lo), (abs(r_hi - target) / target, d_hi))
    return _bisect_log(
        lambda b: build(bpvf=b),
        lambda data: 8.0 * len(data) / nvf,
        target,
        lo,
        hi,
        best,
        "bpvf",
        iters=30,
    )


# ----------------------------------------------------------------------------- decoder
class LayeredState:
    """What the decoder knows after the header segment, and its running state."""

    def __init__(self, c: _container.Container) -> None:
        if len(c.params) != _HEAD.size or c.params[0] != KIND_HEADER:
            raise InvalidInputError(".sga layered stream header is malformed.")
        _k, T, step, refresh, fine = _HEAD.unpack(c.params)
        if not (math.isfinite(step) and step > 0 and T <= _MAX_FRAMES and fine in (0, 1)):
            raise InvalidInputError(".sga layered stream header has invalid parameters.")
        if [t for t, _ in c.chunks] != [TAG_CONNECTIVITY, TAG_ORDER]:
            raise InvalidInputError(".sga layered stream header lacks connectivity or order.")
        n, m = c.n_vertices, c.n_faces
        self.method = METHOD
        self.n, self.m = n, m
        self.n_frames = T
        self.step = step
        self.refresh = refresh
        self.origin = np.asarray(c.origin)
        self.scale = c.scale
        self.F = _connectivity.decode_faces(c.chunks[0][1], n, m)
        levels = decode_groups(c.chunks[1][1], np.zeros(n, dtype=np.int64), 1, "layer levels")
        if levels.size and (levels.min() < 0 or levels.max() > CT_LEVELS):
            raise InvalidInputError(".sga layer levels are malformed.")
        self.order = order_from_levels(self.F, n, levels)
        self.rec = Reconstructor(self.F, n, self.order, fine=bool(fine))
        self.expect = 0

    def frame(self, c: _container.Container) -> np.ndarray:
        if len(c.params) != _FRAME.size or c.params[0] != KIND_FRAME:
            raise InvalidInputError(".sga layered frame segment header is malformed.")
        _k, t0, _t, nf, step = _FRAME.unpack(c.params)
        if c.method != METHOD or c.n_vertices != self.n or c.n_faces != self.m or nf != 1:
            raise InvalidInputError(".sga layered frame does not belong to this stream.")
        if t0 != self.expect:
            raise InvalidInputError(
                f".sga frames are out of order (frame {t0}, expected {self.expect})."
            )
        if step != self.step or [t for t, _ in c.chunks] != [TAG_FRAME]:
            raise InvalidInputError(".sga layered frame segment is malformed.")
        layer, q, q_res = _parse_payload(c.chunks[0][1], self.n)
        s = self.step
        if t0 == 0:
            if layer != self.n:
                raise InvalidInputError(".sga layered stream must start with a whole frame.")
            P0 = np.empty((self.n, 3))
            P0[self.order] = q * s
            X = self.rec.first(P0)
        else:
            known = self.order[:layer]
            pk = self.rec.predict(known)
            X = self.rec.step(known, pk + q * s - self.rec.prev[known])
            if q_res is not None:
                res = np.zeros((self.n, 3))
                res[self.order[layer:]] = q_res * s
                X = self.rec.correct(res)
        if not np.isfinite(X).all():
            raise InvalidInputError(".sga data decodes to non-finite coordinates (corrupted).")
        self.expect += 1
        return X * self.scale + self.origin


def decode(data) -> tuple[np.ndarray, np.ndarray]:
    """Frames and faces of a complete layered ``.sga`` byte string."""
    from ._animation import iter_decode

    parts = [X for _t, X in iter_decode(data)]
    from ._animation import _parse_stream

    st, _ = _parse_stream(bytes(data), True)
    return np.concatenate(parts, axis=0), st.F
