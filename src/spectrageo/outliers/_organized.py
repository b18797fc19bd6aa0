r"""Organized (image) clouds: flying pixels and image-supported points (the grid stage of
:func:`spectrageo.outliers.remove_outliers`).

With the range image ``r_p = ||x_p - o||`` of a depth camera (``o`` the viewpoint, the origin by
default), let ``theta`` be the angular pitch (median of ``||x_p - x_q|| / r_p`` over horizontal
and vertical neighbours ``p, q`` on one surface, ``|r_p - r_q| < 0.05 r_p``) and ``sigma(r)`` the
range noise at range ``r``: the 0.9 quantile of those neighbours' ``|r_p - r_q|`` in 16 range
bins of equal counts, interpolated linearly (it holds the depth quantisation of structured-light
sensors, whose step grows as ``r^2``). The depth tolerance is

.. math::

    T_p = \alpha \max(\sigma(r_p), \theta r_p).

A point is

* *supported* when at least ``S`` of its 8 image neighbours exist and lie within ``T_p`` in
  range: it samples a smooth surface seen by the sensor and is kept whatever its score;
* *flying* when, along one of the 4 image directions ``d``, the pixels ``p - a d`` and
  ``p + b d`` (``(a, b)`` in ``(1, 1), (1, 2), (2, 1)``: runs of 1 or 2 mixed pixels) both exist
  and ``r_p`` lies between their ranges, more than ``T_p`` from each: a mixed pixel between two
  depth layers, removed.

Points off the grid (index ``-1``) get neither label. Constants chosen on the tuning split; see
docs/decisions.md#outliers-organized-grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import InvalidInputError

__all__ = ["GRID_ALPHA", "GRID_SUPPORT", "OrganizedGrid", "grid_labels"]

#: Depth tolerance ``alpha``, in range noise or spacings (module notes).
GRID_ALPHA = 4.0
#: Image neighbours within the tolerance that make a point supported.
GRID_SUPPORT = 7
#: Quantile of the neighbours' range differences that measures the range noise, per range bin.
NOISE_QUANTILE = 0.9
NOISE_BINS = 16
_SAME_SURFACE = 0.05
_DIRS = ((0, 1), (1, 0), (1, 1), (1, -1))
_RUNS = ((1, 1), (1, 2), (2, 1))


@dataclass(frozen=True, eq=False)
class OrganizedGrid:
    """The image grid of an organized cloud (a depth camera's ``HEIGHT x WIDTH`` frame).

    Parameters
    ----------
    shape : (2,) tuple of int
        ``(height, width)`` of the image.
    index : (n,) array_like of int, optional
        Row-major pixel ``row * width + col`` of every point (``-1``: not on the grid, e.g. points
        added later); None: point ``i`` is pixel ``i`` (``n = height * width``). A PCD file read
        with its NaN pixels dropped gives it as the attribute ``source_index``.

    Raises
    ------
    InvalidInputError
        A shape that is not two positive integers or an index outside the image.
    """

    shape: tuple[int, int]
    index: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        try:
            h, w = (int(v) for v in self.shape)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(
                f"`shape` must be (height, width); got {self.shape!r}."
            ) from exc
        if h < 1 or w < 1:
            raise InvalidInputError(f"`shape` must be positive; got {self.shape!r}.")
        object.__setattr__(self, "shape", (h, w))
        if self.index is not None:
            idx = np.asarray(self.index)
            if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
                raise InvalidInputError("`index` must be a 1-D array of integer pixel indices.")
            idx = idx.astype(np.int64)
            if idx.size and (idx.min() < -1 or idx.max() >= h * w):
                raise InvalidInputError(
                    f"`index` holds pixels outside the {h} x {w} image (or below -1)."
                )
            on = idx[idx >= 0]
            if np.unique(on).size != on.size:
                raise InvalidInputError("`index` gives two points the same pixel.")
            object.__setattr__(self, "index", idx)

    def pixels(self, n: int) -> np.ndarray:
        """The pixel of each of ``n`` points (``-1`` off the grid)."""
        if self.index is None:
            if n != self.shape[0] * self.shape[1]:
                raise InvalidInputError(
                    f"an OrganizedGrid without `index` needs height * width = "
                    f"{self.shape[0] * self.shape[1]} points; got {n}."
                )
            return np.arange(n, dtype=np.int64)
        if self.index.size != n:
            raise InvalidInputError(f"`grid.index` has {self.index.size} entries for {n} points.")
        return self.index


def grid_labels(
    X: np.ndarray,
    pix: np.ndarray,
    shape: tuple[int, int],
    viewpoint: Any = None,
    *,
    alpha: float = GRID_ALPHA,
    support: int = GRID_SUPPORT,
) -> tuple[np.ndarray, np.ndarray]:
    """``(supported, flying)`` boolean masks of the points ``X`` (module notes).

    Parameters
    ----------
    X : (n, 3) ndarray
        Finite points.
    pix : (n,) int ndarray
        Pixel of each point, ``-1`` off the grid.
    shape : (height, width)
    viewpoint : (3,) array_like, optional
        Sensor origin (default the origin of the coordinates).
    """
    n = X.shape[0]
    supported = np.zeros(n, dtype=bool)
    flying = np.zeros(n, dtype=bool)
    on = np.flatnonzero(pix >= 0)
    H, W = shape
    if on.size < 9:
        return supported, flying
    o = np.zeros(3) if viewpoint is None else np.asarray(viewpoint, dtype=np.float64)
    r_on = np.linalg.norm(X[on] - o, axis=1)
    R = np.full(H * W, np.nan)
    R[pix[on]] = r_on
    R = R.reshape(H, W)
    Xi = np.full((H * W, 3), np.nan)
    Xi[pix[on]] = X[on]
    Xi = Xi.reshape(H, W, 3)
    theta, pairs = _pitch(Xi, R)
    if not theta > 0:
        return supported, flying
    T = alpha * np.maximum(_noise_at(R, pairs), theta * R)
    Rp = np.pad(R, 2, constant_values=np.nan)

    def shifted(dy: int, dx: int) -> np.ndarray:
        return Rp[2 + dy : 2 + dy + H, 2 + dx : 2 + dx + W]

    count = np.zeros((H, W), dtype=np.int64)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                count += np.abs(shifted(dy, dx) - R) <= T  # NaN compares False
    fly = np.zeros((H, W), dtype=bool)
    for dy, dx in _DIRS:
        for a, b in _RUNS:
            lo, hi = shifted(-a * dy, -a * dx), shifted(b * dy, b * dx)
            fly |= ((lo < R - T) & (hi > R + T)) | ((lo > R + T) & (hi < R - T))
    flat = pix[on]
    supported[on] = count.reshape(-1)[flat] >= support
    flying[on] = fly.reshape(-1)[flat] & ~supported[on]
    return supported, flying


def _pitch(Xi: np.ndarray, R: np.ndarray) -> tuple[float, np.ndarray]:
    """``theta`` (median ``||x_p - x_q|| / r_p`` over horizontal and vertical neighbours on one
    surface) and those pairs' ``(r_p, |r_p - r_q|)``, shape (m, 2)."""
    vals, pairs = [], []
    for sl_a, sl_b in (
        ((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
        ((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
    ):
        ra, rb = R[sl_a], R[sl_b]
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.linalg.norm(Xi[sl_a] - Xi[sl_b], axis=-1) / ra
        dr = np.abs(ra - rb)
        ok = np.isfinite(d) & (dr < _SAME_SURFACE * ra) & (ra > 0)
        vals.append(d[ok])
        pairs.append(np.stack([ra[ok], dr[ok]], axis=1))
    v = np.concatenate(vals)
    return (float(np.median(v)) if v.size else 0.0), np.concatenate(pairs)


def _noise_at(R: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """The range noise at each pixel's range: the ``NOISE_QUANTILE`` of ``|r_p - r_q|`` over the
    neighbour pairs in each of ``NOISE_BINS`` range bins (equal counts), interpolated linearly."""
    out = np.zeros(R.shape)
    if pairs.shape[0] < NOISE_BINS:
        return out
    order = np.argsort(pairs[:, 0], kind="stable")
    parts = np.array_split(pairs[order], NOISE_BINS)
    centres = np.array([np.median(p[:, 0]) for p in parts])
    noise = np.array([np.quantile(p[:, 1], NOISE_QUANTILE) for p in parts])
    ok = np.isfinite(R)
    out[ok] = np.interp(R[ok], centres, noise)
    return out
