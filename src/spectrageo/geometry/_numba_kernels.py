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
