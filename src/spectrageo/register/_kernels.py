"""Compiled kernels of identification (thesis Section 6.2): RANSAC hypothesis scoring."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def count_inliers(R, t, A, B, thr2):  # pragma: no cover - compiled
    """Per hypothesis ``h``: how many correspondences ``(A[c], B[c])`` satisfy
    ``||R[h] A[c] + t[h] - B[c]||^2 <= thr2``. ``R`` (H, 3, 3), ``t`` (H, 3), ``A``/``B`` (C, 3).

    The same sum of squares as ``((R A + t - B) ** 2).sum()`` over the three coordinates, without
    the (H, C, 3) temporary; hypotheses run in parallel.
    """
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
                cnt += 1
        out[h] = cnt
    return out
