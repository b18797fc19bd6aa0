"""Correspondence-free screening of identification pose hypotheses.

Each hypothesis ``(R, t)`` (model -> segment) is scored by the share of segment points that land,
moved into model coordinates, in a grid cell near a model point whose unoriented normal agrees.
A cell stores the index of the model point nearest its centre (or -1 beyond the radius), so one
look-up replaces a nearest-neighbour query (docs/decisions.md#identify-screening).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from ._common import WORKERS

#: at most this many cells along one axis (memory stays bounded for any sampling step)
MAX_CELLS_AXIS = 128


class ModelGrid:
    """Nearest model point per cell of a grid around the model.

    Parameters
    ----------
    P : (m, 3) array
        Model points.
    tree : cKDTree
        KD-tree of ``P``.
    radius : float
        A cell refers to a model point when its centre lies within ``radius`` of it.
    cell : float
        Requested cell size; enlarged so that no axis exceeds :data:`MAX_CELLS_AXIS` cells.
    """

    def __init__(self, P: np.ndarray, tree: cKDTree, radius: float, cell: float):
        lo = P.min(axis=0) - radius
        ext = P.max(axis=0) + radius - lo
        cell = max(float(cell), float(ext.max()) / MAX_CELLS_AXIS)
        dims = np.maximum(np.ceil(ext / cell).astype(np.int64), 1)
        axes = [lo[a] + (np.arange(dims[a]) + 0.5) * cell for a in range(3)]
        C = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        d, j = tree.query(C, k=1, distance_upper_bound=radius, workers=WORKERS)
        self.index = np.where(np.isfinite(d), j, -1).astype(np.int32)
        self.lo, self.cell, self.dims = lo, cell, dims

    def coverage(self, R, t, Q, NQ, NM, cos_min: float) -> np.ndarray:
        """Share of ``Q`` (q, 3) with normals ``NQ`` explained by each pose ``(R[h], t[h])``."""
        return _coverage(
            np.ascontiguousarray(R), np.ascontiguousarray(t), np.ascontiguousarray(Q),
            np.ascontiguousarray(NQ), np.ascontiguousarray(NM), self.index, self.lo,
            float(self.cell), self.dims, float(cos_min),
        )  # fmt: skip


@njit(cache=True, nogil=True, parallel=True)
def _coverage(R, t, Q, NQ, NM, index, lo, cell, dims, cos_min):  # pragma: no cover - compiled
    H = R.shape[0]
    n = Q.shape[0]
    out = np.zeros(H)
    d0, d1, d2 = dims[0], dims[1], dims[2]
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    inv = 1.0 / cell
    for h in prange(H):
        r00, r01, r02 = R[h, 0, 0], R[h, 0, 1], R[h, 0, 2]
        r10, r11, r12 = R[h, 1, 0], R[h, 1, 1], R[h, 1, 2]
        r20, r21, r22 = R[h, 2, 0], R[h, 2, 1], R[h, 2, 2]
        t0, t1, t2 = t[h, 0], t[h, 1], t[h, 2]
        cnt = 0
        for i in range(n):
            x0 = Q[i, 0] - t0
            x1 = Q[i, 1] - t1
            x2 = Q[i, 2] - t2
            # R^T (q - t): the segment point in model coordinates
            u0 = (r00 * x0 + r10 * x1 + r20 * x2 - lo0) * inv
            u1 = (r01 * x0 + r11 * x1 + r21 * x2 - lo1) * inv
            u2 = (r02 * x0 + r12 * x1 + r22 * x2 - lo2) * inv
            if not (u0 >= 0.0 and u1 >= 0.0 and u2 >= 0.0 and u0 < d0 and u1 < d1 and u2 < d2):
                continue
            j = index[(int(u0) * d1 + int(u1)) * d2 + int(u2)]
            if j < 0:
                continue
            m0 = r00 * NQ[i, 0] + r10 * NQ[i, 1] + r20 * NQ[i, 2]
            m1 = r01 * NQ[i, 0] + r11 * NQ[i, 1] + r21 * NQ[i, 2]
            m2 = r02 * NQ[i, 0] + r12 * NQ[i, 1] + r22 * NQ[i, 2]
            if abs(m0 * NM[j, 0] + m1 * NM[j, 1] + m2 * NM[j, 2]) >= cos_min:
                cnt += 1
        out[h] = cnt / max(n, 1)
    return out


__all__ = ["MAX_CELLS_AXIS", "ModelGrid"]
