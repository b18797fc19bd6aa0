"""Range normalisation of outlier scores for sensor scans with a known viewpoint."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ._common import SortedCloud, knn_grid

__all__ = ["RANGE_POWER", "check_viewpoint", "range_ratio"]

#: Exponent ``p`` of the range normalisation ``s_i / max(rho_i, 1)^p``: chosen on the tuning
#: split (docs/decisions.md#outliers-range-model).
RANGE_POWER = 2.0


def check_viewpoint(viewpoint: Any) -> tuple[float, float, float] | None:
    """``viewpoint`` as a tuple of three finite floats (None passes through)."""
    if viewpoint is None:
        return None
    try:
        v = np.asarray(viewpoint, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"`viewpoint` must be 3 numbers; got {viewpoint!r}.") from exc
    if v.shape != (3,) or not np.isfinite(v).all():
        raise InvalidInputError(f"`viewpoint` must be 3 finite numbers; got {viewpoint!r}.")
    return (float(v[0]), float(v[1]), float(v[2]))


def range_ratio(X: np.ndarray, k: int, viewpoint: tuple[float, float, float]) -> np.ndarray:
    r"""Predicted spacing at each point's range, over the cloud's spacing: ``rho_i``.

    A sensor's spacing grows linearly with the range ``r_i = ||x_i - o||``:
    ``d_i \approx c\, r_i`` with ``c = median_i(d_i / r_i)`` (``d_i`` the mean distance to the
    ``k`` nearest neighbours) and ``rho_i = c\, r_i / h``, ``h = median_i d_i``. Medians keep
    ``c`` and ``h`` independent of a minority of outliers.

    Parameters
    ----------
    X : (n, 3) ndarray
        Finite points.
    k : int
        Neighbours of ``d_i``.
    viewpoint : (3,) tuple
        Sensor origin ``o``.

    Returns
    -------
    (n,) ndarray
        ``rho_i`` (1 when the cloud has no spread of ranges).
    """
    sc = SortedCloud.of(X)
    dm = np.empty(X.shape[0])
    dm[sc.order] = knn_grid(sc, k).dmean
    r = np.linalg.norm(X - np.asarray(viewpoint), axis=1)
    h = float(np.median(dm))
    ok = r > 0
    if h <= 0 or not ok.any():
        return np.ones(X.shape[0])
    c = float(np.median(dm[ok] / r[ok]))
    return c * r / h
