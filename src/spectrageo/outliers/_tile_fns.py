"""Per-tile functions of the tiled outlier removal and robot filter (:func:`._halo.tile_job`).

Reach: ``sor``/``radius`` one hop ``(k,)`` (global z-scores and medians after gathering), ``rpca``
two hops ``(k, k)`` (:mod:`._rpca_tiled`), the bilateral filter two hops ``(k, k)`` per pass with
a global ``sigma1`` gathered by :func:`dmean_tile`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._common import knn_chunked
from ._rpca_tiled import rpca_tile_scores
from .robot import bilateral_point_filter
from .static import radius_scores

__all__ = ["bilateral_tile", "dmean_tile", "outlier_tile"]


def outlier_tile(R, m, dmean, *, workers, k, method, kw, knn=None) -> dict:
    """Outlier scores of the own points by ``method`` (``kw``: the RPCA pipeline's keyword
    arguments; ``knn``: the halo search's neighbours, reused by the RPCA's step 1)."""
    if method == "rpca":
        return rpca_tile_scores(R, m, dmean, workers=workers, k=k, kw=kw, knn=knn)
    out: dict[str, Any] = {"dmean": np.asarray(dmean, dtype=np.float64)}
    if method == "radius":
        s = radius_scores(R, k, workers=workers)[:m]
    else:  # sor: the z-scores are formed over all tiles' values
        s = out["dmean"]
    out["scores"] = np.asarray(s, dtype=np.float64)
    return out


outlier_tile.takes_knn = True  # type: ignore[attr-defined]


def dmean_tile(R, m, _dmean, *, workers, k) -> dict:
    """Mean ``k``-NN distance of the own points, as :func:`bilateral_point_filter` measures it."""
    nb = knn_chunked(R, k, query=R[:m], self_index=np.arange(m), workers=workers)
    return {"dmean": nb.dmean}


def bilateral_tile(R, m, _dmean, *, workers, k, sigma1, sigma2) -> dict:
    """One bilateral pass (Eq. 5.100-5.101) with the global ``sigma1``: own points' positions."""
    Y = bilateral_point_filter(R, k, sigma1=sigma1, sigma2=sigma2, n_iter=1)[:m]
    return {"xyz": Y}
