"""Input representations of the learned denoisers: guided pixels (Eqs. 5.38-5.39), rotations to
``[1 0 0]`` (Figs. 5.41, 5.43), the images of Fig. 5.40 and the flat / edge / corner classes.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..geometry import face_centroids, face_normals
from ..geometry._numba_kernels import max_sq_distance

#: default image width ``k`` (an odd number, Fig. 5.40); see :mod:`spectrageo.learn.bm3d_cnn`
IMAGE_COLS = 9


#: vertex rings around a face searched for its nearest centroids when the faces are known (the
#: candidate bound of :func:`_ring_knn` holds for at most 2)
FACE_RINGS = 2


def centroid_knn(C: np.ndarray, k: int, F: np.ndarray | None = None) -> np.ndarray:
    """Indices (m, k) of the ``k`` nearest centroids of every centroid, itself first (ties by index).

    Without ``F`` the Euclidean nearest (Fig. 5.40); with ``F`` the nearest among the faces within
    :data:`FACE_RINGS` vertex rings (docs/decisions.md#learn-ring-neighbours).
    """
    m = C.shape[0]
    if F is not None:
        return _ring_knn(np.ascontiguousarray(C, dtype=np.float64), np.asarray(F), k)
    kk = min(k, m)
    _, idx = cKDTree(C).query(C, k=kk, workers=-1)
    idx = np.asarray(idx, dtype=np.int64).reshape(m, kk)
    # the query point itself may not come first when centroids coincide: force it
    ar = np.arange(m)
    rows = np.flatnonzero(idx[:, 0] != ar)
    if rows.size:
        sub = idx[rows] == rows[:, None]
        self_pos = np.argmax(sub, axis=1)
        has = sub.any(axis=1)
        r, pos = rows[has], self_pos[has]
        idx[r, pos] = idx[r, 0]
        idx[:, 0] = ar
    if kk < k:
        idx = np.concatenate([idx, np.repeat(idx[:, -1:], k - kk, axis=1)], axis=1)
    return idx


def _ring_knn(C: np.ndarray, F: np.ndarray, k: int) -> np.ndarray:
    F = np.ascontiguousarray(F, dtype=np.int64)
    m = F.shape[0]
    if C.shape[0] != m:
        raise ValueError(f"{C.shape[0]} centroids for {m} faces.")
    n = int(F.max()) + 1 if m else 0
    vptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(F.ravel(), minlength=n), out=vptr[1:])
    vf = np.empty(3 * m, dtype=np.int64)  # faces around each vertex, CSR by vptr
    _vertex_faces(F, vptr, vf)
    out = np.empty((m, k), dtype=np.int64)
    if m == 0:
        return out
    # candidate buffer: a bound on the faces within two rings of any face (sum, over the face's
    # vertices, of the valences of the vertices of the faces around them), at most m
    deg = np.diff(vptr).astype(np.float64)
    around = np.bincount(F.ravel(), weights=np.repeat(deg[F].sum(axis=1), 3), minlength=n)
    cap = int(min(m, around[F].sum(axis=1).max() + 1))
    n_chunks = int(min(m, 4 * numba.get_num_threads()))
    _ring_knn_kernel(F, vptr, vf, C, FACE_RINGS, cap, n_chunks, out)
    return out


@numba.njit(cache=True)
def _vertex_faces(F, vptr, vf):  # pragma: no cover - numba
    """``vf[vptr[v]:vptr[v + 1]]``: the faces around vertex ``v``, ascending (counting sort)."""
    fill = vptr[:-1].copy()
    for f in range(F.shape[0]):
        for a in range(3):
            v = F[f, a]
            vf[fill[v]] = f
            fill[v] += 1


@numba.njit(cache=True, parallel=True)
def _ring_knn_kernel(F, vptr, vf, C, rings, cap, n_chunks, out):  # pragma: no cover - numba
    """``out[f]``: the ``k`` faces nearest to face ``f`` by centroid among the faces within
    ``rings`` (at most 2: ``cap`` bounds their number) vertex rings of it, ``f`` first, ties by
    index, padded with the farthest one. ``n_chunks`` blocks of faces, each with its own
    marks (memory ``n_chunks (m + n + cap)`` integers)."""
    m = F.shape[0]
    n = vptr.size - 1
    k = out.shape[1]
    for ch in numba.prange(n_chunks):
        mark = np.full(m, -1, dtype=np.int64)  # stamp: the face whose search saw it last
        vmark = np.full(n, -1, dtype=np.int64)  # ... and the vertex whose faces it listed
        cand = np.empty(cap, dtype=np.int64)
        bd = np.empty(k)
        bi = np.empty(k, dtype=np.int64)
        for f in range(ch * m // n_chunks, (ch + 1) * m // n_chunks):
            cand[0] = f
            mark[f] = f
            nc = 1
            start = 0
            for _ in range(rings):
                end = nc
                for c in range(start, end):
                    g = cand[c]
                    for a in range(3):
                        v = F[g, a]
                        if vmark[v] == f:
                            continue
                        vmark[v] = f
                        for t in range(vptr[v], vptr[v + 1]):
                            h = vf[t]
                            if mark[h] != f:
                                mark[h] = f
                                cand[nc] = h
                                nc += 1
                start = end
            # the k nearest by (distance, index); the face itself first (distance -1)
            cnt = 0
            for c in range(nc):
                h = cand[c]
                if h == f:
                    d = -1.0
                else:
                    d0 = C[h, 0] - C[f, 0]
                    d1 = C[h, 1] - C[f, 1]
                    d2 = C[h, 2] - C[f, 2]
                    d = d0 * d0 + d1 * d1 + d2 * d2
                if cnt == k and (d > bd[k - 1] or (d == bd[k - 1] and h > bi[k - 1])):
                    continue
                j = cnt if cnt < k else k - 1
                while j > 0 and (bd[j - 1] > d or (bd[j - 1] == d and bi[j - 1] > h)):
                    if j < k:
                        bd[j] = bd[j - 1]
                        bi[j] = bi[j - 1]
                    j -= 1
                bd[j] = d
                bi[j] = h
                if cnt < k:
                    cnt += 1
            for j in range(k):
                out[f, j] = bi[min(j, cnt - 1)]


def column_order(k: int) -> np.ndarray:
    """Image column of the ``j``-th nearest neighbour (Fig. 5.40): centre, right, left, right, ..."""
    c = k // 2
    j = np.arange(k)
    return np.where(j % 2 == 1, c + (j + 1) // 2, c - j // 2).astype(np.int64)


def guided_pixels(N: np.ndarray, knn_idx: np.ndarray) -> np.ndarray:
    """Guided pixels ``g_i`` (m, 3) of Eqs. (5.38)-(5.39): the normalised mean of the candidate row with the smallest ``s_ij h_ij``."""
    from ..geometry._numba_kernels import sym3_eigenvalues
    from ..geometry.primitives import _normalize_rows

    N = np.ascontiguousarray(N, dtype=np.float64)
    m, k = knn_idx.shape
    # patch j = the distinct faces of row j, ascending (the order of a CSR patch matrix's sums);
    # the candidates of face i = the rows that contain it, ascending
    members = np.sort(np.asarray(knn_idx, dtype=np.int64), axis=1)
    first = np.ones((m, k), dtype=np.bool_)
    first[:, 1:] = members[:, 1:] != members[:, :-1]
    cptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(members[first], minlength=m), out=cptr[1:])
    cand = np.empty(int(cptr[-1]), dtype=np.int64)
    _transpose_rows(members, first, cptr, cand)
    moments = np.empty((m, 6))
    sums = np.empty((m, 3))
    _patch_sums(N, members, first, moments, sums)
    lam = sym3_eigenvalues(moments)  # Eq. (4.9): a_j = |lambda_1 - lambda_2|
    best = np.empty(m, dtype=np.int64)
    _ideal_rows(N, members, np.abs(lam[:, 0] - lam[:, 1]), cptr, cand, best)
    g = _normalize_rows(sums)[best]
    bad = ~np.isfinite(g).all(axis=1) | (np.linalg.norm(g, axis=1) < 0.5)
    g[bad] = N[bad]
    return g


@numba.njit(cache=True)
def _transpose_rows(members, first, cptr, cand):  # pragma: no cover - numba
    """``cand[cptr[i]:cptr[i + 1]]``: the rows containing face ``i``, ascending (counting sort)."""
    fill = cptr[:-1].copy()
    m, k = members.shape
    for j in range(m):
        for q in range(k):
            if first[j, q]:
                l = members[j, q]
                cand[fill[l]] = j
                fill[l] += 1


@numba.njit(cache=True, parallel=True)
def _patch_sums(N, members, first, moments, sums):  # pragma: no cover - numba
    """Per patch: ``sum n n^T`` as [xx, yy, zz, xy, xz, yz] and ``sum n`` over its distinct
    members, added in ascending face order from zero."""
    m, k = members.shape
    for j in numba.prange(m):
        s0 = s1 = s2 = s3 = s4 = s5 = 0.0
        a0 = a1 = a2 = 0.0
        for q in range(k):
            if first[j, q]:
                l = members[j, q]
                x, y, z = N[l, 0], N[l, 1], N[l, 2]
                s0 += x * x
                s1 += y * y
                s2 += z * z
                s3 += x * y
                s4 += x * z
                s5 += y * z
                a0 += x
                a1 += y
                a2 += z
        moments[j, 0] = s0
        moments[j, 1] = s1
        moments[j, 2] = s2
        moments[j, 3] = s3
        moments[j, 4] = s4
        moments[j, 5] = s5
        sums[j, 0] = a0
        sums[j, 1] = a1
        sums[j, 2] = a2


@numba.njit(cache=True, parallel=True)
def _ideal_rows(N, members, a, cptr, cand, best):  # pragma: no cover - numba
    """Eq. (4.8)/(5.38): for face ``i`` the candidate row ``j`` with the least ``a_j b_ij``,
    ``b_ij = max_l ||n_i - n_l||`` (Eq. 4.10, a repeated member does not change the maximum);
    ties to the lowest ``j``; a row set with an undefined (NaN) score keeps the face's own row."""
    m = members.shape[0]
    for i in numba.prange(m):
        bi = -1
        bs = np.inf
        nan = False
        for t in range(cptr[i], cptr[i + 1]):
            j = cand[t]
            sc = a[j] * np.sqrt(max_sq_distance(N, i, members, j))
            if sc != sc:
                nan = True
            elif sc < bs:
                bs = sc
                bi = j
        best[i] = i if (nan or bi < 0) else bi


def rotations_to_axis(G: np.ndarray) -> np.ndarray:
    """Smallest rotations ``R_i`` (m, 3, 3) with ``R_i g_i = [1, 0, 0]`` (Figs. 5.41, 5.43)."""
    G = np.asarray(G, dtype=np.float64)
    m = G.shape[0]
    nrm = np.linalg.norm(G, axis=1)
    a = np.divide(G, nrm[:, None], out=np.zeros_like(G), where=nrm[:, None] > 0)
    a[nrm == 0] = (1.0, 0.0, 0.0)
    c = a[:, 0]  # a . e_x
    v = np.stack([np.zeros(m), a[:, 2], -a[:, 1]], axis=1)  # a x e_x
    K = np.zeros((m, 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -v[:, 2], v[:, 1]
    K[:, 1, 0], K[:, 1, 2] = v[:, 2], -v[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -v[:, 1], v[:, 0]
    opp = c < -1.0 + 1e-9
    denom = np.where(opp, 1.0, 1.0 + c)
    R = np.eye(3)[None] + K + (K @ K) / denom[:, None, None]
    R[opp] = np.diag([-1.0, -1.0, 1.0])
    return R


def normal_images(
    G: np.ndarray,
    knn_idx: np.ndarray,
    R: np.ndarray,
    *,
    rows: int | None = None,
    faces=None,
    out: np.ndarray | None = None,
    channel: int = 0,
) -> np.ndarray:
    """Images (b, 3, rows, k) float32 of Fig. 5.40 from the pixels ``G`` (m, 3), rotated by ``R`` (Fig. 5.43).

    Row ``r`` of face ``i``'s image is the kNN row (``knn_idx``) of its ``r``-th nearest centroid,
    nearest in the centre column; ``faces`` selects images, ``out`` receives them at ``channel``.
    """
    m, k = knn_idx.shape
    rows = k if rows is None else int(rows)
    faces = np.arange(m) if faces is None else np.asarray(faces, dtype=np.int64)
    order = column_order(k)
    lay = np.empty_like(knn_idx)
    lay[:, order] = knn_idx  # laid-out rows: lay[j, col] = face shown in column col
    centres = np.ascontiguousarray(knn_idx[faces, :rows])  # (b, rows)
    if out is None:
        out = np.empty((faces.size, 3, rows, k), dtype=np.float32)
        channel = 0
    elif (
        out.dtype != np.float32
        or not out.flags.c_contiguous
        or out.shape[0] != faces.size
        or out.shape[2:] != (rows, k)
        or not 0 <= channel <= out.shape[1] - 3
    ):
        raise ValueError(f"`out` of shape {out.shape} cannot take these images at {channel}.")
    _images_kernel(
        np.ascontiguousarray(R, dtype=np.float64),
        np.ascontiguousarray(G, dtype=np.float64),
        np.ascontiguousarray(lay),
        centres,
        faces,
        out,
        channel,
    )
    return out


@numba.njit(cache=True, parallel=True)
def _images_kernel(R, G, lay, centres, faces, out, ch0):  # pragma: no cover - numba
    """``out[b, ch0 + i, r, c] = sum_j R[faces[b], i, j] G[lay[centres[b, r], c], j]`` in
    float64, stored as float32 (one gather and rotation, no (b, rows, k, 3) temporary)."""
    nb, rows = centres.shape
    k = lay.shape[1]
    for b in numba.prange(nb):
        f = faces[b]
        for r in range(rows):
            row = lay[centres[b, r]]
            for c in range(k):
                g = row[c]
                g0, g1, g2 = G[g, 0], G[g, 1], G[g, 2]
                for i in range(3):
                    out[b, ch0 + i, r, c] = R[f, i, 0] * g0 + R[f, i, 1] * g1 + R[f, i, 2] * g2


def row_eigenvalues(first_row: np.ndarray) -> np.ndarray:
    """Ascending eigenvalues (b, 3) of ``C = I^T I / k`` for first rows ``(b, 3, k)`` (Sec. 5.1.4),
    by the compiled 3x3 Jacobi kernel shared with TSGSP (LAPACK's accuracy; about 1.5x faster
    than a batched ``numpy.linalg.eigvalsh`` on 70k rows)."""
    from ..geometry._numba_kernels import patch_moments, sym3_eigenvalues

    X = np.asarray(first_row)
    if X.dtype not in (np.float32, np.float64):
        X = X.astype(np.float64)
    b, _, k = X.shape
    P = np.ascontiguousarray(X.transpose(0, 2, 1)).reshape(-1, 3)  # the pixels as rows
    return sym3_eigenvalues(patch_moments(P, np.arange(b * k).reshape(b, k)))


def kmeans(X: np.ndarray, n_clusters: int, *, rng=0, n_iter: int = 50) -> np.ndarray:
    """Lloyd's kappa-means with k-means++ seeding; returns the centres (n_clusters, d), sorted by
    their first coordinate's descending value then second (a deterministic order for a seed)."""
    gen = np.random.default_rng(rng)
    X = np.asarray(X, dtype=np.float64)
    n = X.shape[0]
    n_clusters = min(n_clusters, n)
    centres = [X[gen.integers(n)]]
    d2 = np.sum((X - centres[0]) ** 2, axis=1)
    for _ in range(1, n_clusters):
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(n, 1.0 / n)
        centres.append(X[gen.choice(n, p=p)])
        d2 = np.minimum(d2, np.sum((X - centres[-1]) ** 2, axis=1))
    Cc = np.array(centres)
    for _ in range(n_iter):
        lab = assign_classes(X, Cc)
        new = np.array(
            [X[lab == j].mean(axis=0) if (lab == j).any() else Cc[j] for j in range(len(Cc))]
        )
        if np.allclose(new, Cc):
            break
        Cc = new
    order = np.lexsort(tuple(-Cc[:, j] for j in reversed(range(Cc.shape[1]))))
    return Cc[order]


def assign_classes(X: np.ndarray, centres: np.ndarray, *, chunk: int = 65536) -> np.ndarray:
    """Index of the nearest centre for every row of ``X`` (Algorithm 4, line 16)."""
    X = np.asarray(X, dtype=np.float64)
    centres = np.asarray(centres, dtype=np.float64)
    out = np.empty(X.shape[0], dtype=np.int64)
    cc = np.sum(centres**2, axis=1)
    for s in range(0, X.shape[0], chunk):
        x = X[s : s + chunk]
        d = cc[None, :] - 2.0 * x @ centres.T
        out[s : s + chunk] = np.argmin(d, axis=1)
    return out


def filtered_pixels(N, G, knn_idx, C, A, *, sigma_r: float = 0.35) -> np.ndarray:
    """Algorithm 5's filtered image: one joint bilateral pass of the normals over each kNN row (``sigma_r = 0.35``)."""
    from ..denoise._normals import joint_bilateral_normals, spatial_weights

    m, k = knn_idx.shape
    P = sp.csr_matrix((np.ones(m * k), knn_idx.ravel(), np.arange(0, m * k + 1, k)), shape=(m, m))
    P.sum_duplicates()
    d1 = np.linalg.norm(C[knn_idx[:, min(1, k - 1)]] - C, axis=1)
    sigma_s = float(np.mean(d1)) if np.mean(d1) > 0 else 1.0
    W = spatial_weights(C, A, P, sigma_s)
    return joint_bilateral_normals(N, G, W, sigma_r)


def image_parts(V, F, *, k: int = IMAGE_COLS, channels: int = 9):
    """Neighbour rows, rotations and pixel sets of :func:`build_images`, for imaging in chunks."""
    from ..geometry import face_areas

    N = face_normals(V, F)
    C = face_centroids(V, F)
    idx = centroid_knn(C, k, F)
    G = guided_pixels(N, idx)
    if channels == 9:
        Fp = filtered_pixels(N, G, idx, C, face_areas(V, F))
        return idx, rotations_to_axis(Fp), [Fp, G, N]
    return idx, rotations_to_axis(G), [G, N][: channels // 3]


def images_of(idx, R, parts, *, rows: int = 5, faces=None) -> np.ndarray:
    """Images (b, 3 len(parts), rows, k) float32 of ``faces`` (default all) from
    :func:`image_parts`' output."""
    m, k = idx.shape
    b = m if faces is None else np.asarray(faces).size
    img = np.empty((b, 3 * len(parts), rows, k), dtype=np.float32)
    for j, P in enumerate(parts):
        normal_images(P, idx, R, rows=rows, faces=faces, out=img, channel=3 * j)
    return img


def build_images(V, F, *, k: int = IMAGE_COLS, rows: int = 5, channels: int = 9, faces=None):
    """Network input: images (b, channels, rows, k) float32 and rotations (m, 3, 3) (``channels`` 3, 6 or 9)."""
    idx, R, parts = image_parts(V, F, k=k, channels=channels)
    return images_of(idx, R, parts, rows=rows, faces=faces), R


def mesh_inputs(V, F, k: int = IMAGE_COLS):
    """Face normals, kNN rows, guided pixels and rotations of a mesh (the common first steps of
    Algorithms 4 and 5)."""
    N = face_normals(V, F)
    C = face_centroids(V, F)
    idx = centroid_knn(C, k, F)
    G = guided_pixels(N, idx)
    R = rotations_to_axis(G)
    return N, idx, G, R


__all__ = [
    "IMAGE_COLS",
    "assign_classes",
    "centroid_knn",
    "column_order",
    "guided_pixels",
    "image_parts",
    "images_of",
    "kmeans",
    "mesh_inputs",
    "normal_images",
    "rotations_to_axis",
    "row_eigenvalues",
]
