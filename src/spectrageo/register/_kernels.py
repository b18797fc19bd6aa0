"""Compiled kernels of identification (thesis Section 6.2): RANSAC hypothesis scoring."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def count_inliers(R, t, A, B, thr2, NA, NB, cos_min):  # pragma: no cover - compiled
    """Per hypothesis, correspondences within ``thr2`` (squared) whose unoriented normals agree."""
    H = R.shape[0]
    C = A.shape[0]
    out = np.zeros(H, dtype=np.int64)
    for h in prange(H):
        r00, r01, r02 = R[h, 0, 0], R[h, 0, 1], R[h, 0, 2]
        r10, r11, r12 = R[h, 1, 0], R[h, 1, 1], R[h, 1, 2]
        r20, r21, r22 = R[h, 2, 0], R[h, 2, 1], R[h, 2, 2]
        t0, t1, t2 = t[h, 0], t[h, 1], t[h, 2]
        cnt = 0
        for c in range(C):
            a0, a1, a2 = A[c, 0], A[c, 1], A[c, 2]
            d0 = r00 * a0 + r01 * a1 + r02 * a2 + t0 - B[c, 0]
            d1 = r10 * a0 + r11 * a1 + r12 * a2 + t1 - B[c, 1]
            d2 = r20 * a0 + r21 * a1 + r22 * a2 + t2 - B[c, 2]
            if d0 * d0 + d1 * d1 + d2 * d2 <= thr2:
                if cos_min <= 0.0:
                    cnt += 1
                else:
                    n0, n1, n2 = NA[c, 0], NA[c, 1], NA[c, 2]
                    dot = (
                        (r00 * n0 + r01 * n1 + r02 * n2) * NB[c, 0]
                        + (r10 * n0 + r11 * n1 + r12 * n2) * NB[c, 1]
                        + (r20 * n0 + r21 * n1 + r22 * n2) * NB[c, 2]
                    )
                    if abs(dot) >= cos_min:
                        cnt += 1
        out[h] = cnt
    return out


@njit(cache=True, nogil=True)
def _compatible(A, B, NA, NB, a, c, voxel, max_d, sep, cos_tol):  # pragma: no cover - compiled
    dA = np.sqrt((A[c, 0] - A[a, 0]) ** 2 + (A[c, 1] - A[a, 1]) ** 2 + (A[c, 2] - A[a, 2]) ** 2)
    dB = np.sqrt((B[c, 0] - B[a, 0]) ** 2 + (B[c, 1] - B[a, 1]) ** 2 + (B[c, 2] - B[a, 2]) ** 2)
    if dB > max_d or dB < sep or abs(dA - dB) > 0.1 * max(dA, dB) + voxel:
        return False
    cA = abs(NA[c, 0] * NA[a, 0] + NA[c, 1] * NA[a, 1] + NA[c, 2] * NA[a, 2])
    cB = abs(NB[c, 0] * NB[a, 0] + NB[c, 1] * NB[a, 1] + NB[c, 2] * NB[a, 2])
    return abs(cA - cB) <= cos_tol


@njit(cache=True, nogil=True, parallel=True)
def compatible_lists(A, B, NA, NB, anchors, voxel, max_d, sep, cos_tol):  # pragma: no cover
    """``(counts, flat)``: per anchor, the correspondences whose distances and normal angles
    agree with it.
    """
    n1 = anchors.shape[0]
    C = A.shape[0]
    counts = np.zeros(n1, dtype=np.int64)
    for i in prange(n1):
        a = anchors[i]
        k = 0
        for c in range(C):
            if _compatible(A, B, NA, NB, a, c, voxel, max_d, sep, cos_tol):
                k += 1
        counts[i] = k
    off = np.zeros(n1 + 1, dtype=np.int64)
    for i in range(n1):
        off[i + 1] = off[i] + counts[i]
    flat = np.empty(off[n1], dtype=np.int64)
    for i in prange(n1):
        a = anchors[i]
        k = off[i]
        for c in range(C):
            if _compatible(A, B, NA, NB, a, c, voxel, max_d, sep, cos_tol):
                flat[k] = c
                k += 1
    return counts, flat
