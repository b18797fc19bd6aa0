"""Sequential kernels that cannot be vectorised with numpy."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def propagate_signs(
    N: np.ndarray, child: np.ndarray, par: np.ndarray
) -> None:  # pragma: no cover - jitted
    """Flip ``N[child[t]]`` to agree with ``N[par[t]]``, in order (BFS order of a spanning tree)."""
    for t in range(child.shape[0]):
        c = child[t]
        p = par[t]
        d = N[c, 0] * N[p, 0] + N[c, 1] * N[p, 1] + N[c, 2] * N[p, 2]
        if d < 0:
            N[c, 0] = -N[c, 0]
            N[c, 1] = -N[c, 1]
            N[c, 2] = -N[c, 2]


@numba.njit(cache=True)
def vertex_update_kernel(V, F, N, inv_deg, n_iter):  # pragma: no cover - jitted
    """``n_iter`` in-place steps of Eq. (4.28) (one pass over the faces each); ``inv_deg`` 0 = fixed."""
    n = V.shape[0]
    m = F.shape[0]
    delta = np.empty((n, 3))
    for _ in range(n_iter):
        delta[:, :] = 0.0
        for j in range(m):
            a = F[j, 0]
            b = F[j, 1]
            c = F[j, 2]
            c0 = (V[a, 0] + V[b, 0] + V[c, 0]) / 3.0
            c1 = (V[a, 1] + V[b, 1] + V[c, 1]) / 3.0
            c2 = (V[a, 2] + V[b, 2] + V[c, 2]) / 3.0
            n0 = N[j, 0]
            n1 = N[j, 1]
            n2 = N[j, 2]
            for t in range(3):
                v = F[j, t]
                p = n0 * (c0 - V[v, 0]) + n1 * (c1 - V[v, 1]) + n2 * (c2 - V[v, 2])
                delta[v, 0] += p * n0
                delta[v, 1] += p * n1
                delta[v, 2] += p * n2
        for i in range(n):
            s = inv_deg[i]
            V[i, 0] += delta[i, 0] * s
            V[i, 1] += delta[i, 1] * s
            V[i, 2] += delta[i, 2] * s
    return V
