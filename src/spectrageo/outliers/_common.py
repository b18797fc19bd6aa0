"""Shared machinery of the outlier filters: input coercion, the Morton-sorted cloud and its exact
grid/octree kNN queries (:mod:`._grid`), chunked kd-tree kNN queries (the reference, and for
callers without a sorted cloud), the point spacing used to make scores scale-invariant, and
duplicate handling."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_points, check_positive
from ..geometry import PointCloud

#: Query points per kNN chunk: bounds the temporaries of a query to O(chunk * k).
KNN_CHUNK = 131_072
#: Below this many query points the kd-tree and the grid/octree kernels are queried on the
#: calling thread (starting the query threads costs more than it saves).
KNN_SERIAL_BELOW = 16_384


def as_cloud(P: Any, name: str = "P") -> tuple[np.ndarray, PointCloud | None]:
    """``(points, cloud)`` from an (n, 3) array or a :class:`PointCloud` (``cloud`` is None for arrays).

    Raises :class:`InvalidInputError` for wrong shapes, NaN/inf coordinates and empty input.
    """
    if isinstance(P, PointCloud):
        return P.points, P
    if P is None:
        raise InvalidInputError(f"`{name}` must be an (n, 3) array or a PointCloud; got None.")
    return as_points(P, name), None


def check_k(k: Any, n: int, name: str = "k") -> int:
    """``k`` must be a positive integer smaller than the number of points ``n``."""
    check_positive(k, name, integer=True)
    k = int(k)
    if n < k + 1:
        raise InvalidInputError(
            f"`{name}` = {k} neighbours need at least {k + 1} points; the cloud has {n}."
        )
    return k


def column_bounds(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P.min(axis=0), P.max(axis=0))`` of an (n, 3) array, column by column (a reduction over
    axis 0 of an (n, 3) array is strided and ~20x slower)."""
    lo = np.array([P[:, j].min() for j in range(3)])
    hi = np.array([P[:, j].max() for j in range(3)])
    return lo, hi


def morton_codes(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(codes, lo, scale)``: Z-order (Morton) codes of ``P`` at 21 bits per axis.

    Each coordinate is quantised as ``floor((P - lo) * scale)`` with ``lo`` the bounding-box
    corner and ``scale = (2^21 - 1) / extent`` (``extent`` the largest side of the box; 0 when all
    points coincide), and the three 21-bit integers are interleaved (x in bit 0).
    """
    from ._grid import morton_encode
    from ._kernels import morton_quantised

    n = P.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.uint64), np.zeros(3), 0.0
    lo, hi = column_bounds(P)
    ext = float(np.max(hi - lo))
    scale = (2**21 - 1) / ext if ext > 0 else 0.0
    codes = np.empty(n, dtype=np.uint64)
    if P.dtype == np.float64:  # same codes (docs/decisions.md#outliers-speed-exact-paths)
        morton_quantised(P, lo, scale, codes)
        return codes, lo, scale
    step = 1 << 20
    for s in range(0, n, step):
        q = ((P[s : s + step] - lo) * scale).astype(np.uint64)
        np.minimum(q, np.uint64(2**21 - 1), out=q)
        codes[s : s + step] = morton_encode(q)
    return codes, lo, scale


def take_rows(P: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``P[rows]`` as a new C-contiguous array (an (n, 3) float64 ``P``: a compiled gather)."""
    if P.ndim != 2 or P.shape[1] != 3 or P.dtype != np.float64:
        return np.ascontiguousarray(P[rows])
    from ._kernels import gather_rows

    out = np.empty((rows.shape[0], 3))
    gather_rows(P, np.asarray(rows), out)
    return out


def morton_order(P: np.ndarray) -> np.ndarray:
    """Permutation sorting ``P`` along a Z-order (Morton) curve of 21 bits per axis.

    Visiting points in this order keeps spatial neighbours close in memory, which makes kd-tree
    queries and the gathers of the patch matrix cache-friendly.
    """
    if P.shape[0] < 2:
        return np.arange(P.shape[0])
    return sort_codes(morton_codes(P)[0])


def sort_codes(codes: np.ndarray) -> np.ndarray:
    """``np.argsort(codes, kind="stable")`` of uint64 ``codes``, faster (a compiled radix sort:
    the same permutation on every machine)."""
    from ._grid import radix_argsort

    return radix_argsort(np.ascontiguousarray(codes, dtype=np.uint64))


@dataclass(frozen=True)
class Neighbours:
    """kNN of every point of a (spatially sorted) cloud, self excluded.

    ``idx`` (n, k) int32/int64 neighbour indices, nearest first; ``dmean`` (n,) mean distance to
    the k neighbours; ``dlast`` (n,) distance to the k-th neighbour; ``n_zero`` number of points
    with at least one neighbour at distance 0 (an exact duplicate).
    """

    idx: np.ndarray
    dmean: np.ndarray
    dlast: np.ndarray
    n_zero: int


def knn_chunked(
    P: np.ndarray,
    k: int,
    *,
    tree: cKDTree | None = None,
    query: np.ndarray | None = None,
    self_index: np.ndarray | None = None,
    workers: int = -1,
) -> Neighbours:
    """k nearest neighbours in chunks, excluding each query point itself.

    With ``query=None`` the points of ``P`` query themselves; otherwise ``query`` points are looked
    up in ``P`` and ``self_index[i]`` (or -1) names the entry of ``P`` that is query ``i`` itself,
    to be excluded. When a point has exact duplicates the copy removed is the point itself, never a
    duplicate (as :func:`spectrageo.graph.knn`). Memory is O(n k) for the result plus O(chunk k).
    """
    tree = cKDTree(P) if tree is None else tree
    Q = P if query is None else query
    nq = Q.shape[0]
    if query is None:
        self_index = np.arange(nq)
    if nq < KNN_SERIAL_BELOW:
        workers = 1
    kk = k + 1
    itype = np.int32 if P.shape[0] < 2**31 - 1 else np.int64
    idx = np.empty((nq, k), dtype=itype)
    dmean = np.empty(nq)
    dlast = np.empty(nq)
    n_zero = 0
    for s in range(0, nq, KNN_CHUNK):
        e = min(nq, s + KNN_CHUNK)
        d, i = tree.query(Q[s:e], k=kk, workers=workers)
        d = d.reshape(e - s, kk)
        i = i.reshape(e - s, kk)
        own = self_index[s:e]
        is_self = i == own[:, None]
        has_self = is_self.any(axis=1)
        drop = np.where(has_self, np.argmax(is_self, axis=1), kk - 1)
        keep = np.ones(i.shape, dtype=bool)
        keep[np.arange(e - s), drop] = False
        i = i[keep].reshape(e - s, k)
        d = d[keep].reshape(e - s, k)
        idx[s:e] = i
        dmean[s:e] = d.mean(axis=1)
        dlast[s:e] = d[:, -1]
        n_zero += int(np.count_nonzero(d[:, 0] == 0.0))
    return Neighbours(idx, dmean, dlast, n_zero)


def spacing_from(dmean: np.ndarray) -> float:
    """Typical point spacing: the median over points of the mean distance to their k neighbours.

    The median keeps it independent of the outliers (which have large kNN distances) as long as
    they are fewer than half of the points. Falls back to the mean of the positive values when more
    than half of the points sit on exact duplicates; raises when every point coincides.
    """
    h = float(np.median(dmean))
    if h > 0:
        return h
    pos = dmean[dmean > 0]
    if pos.size == 0:
        raise InvalidInputError("`P` has no spatial extent: all points coincide.")
    return float(pos.mean())


@dataclass(frozen=True)
class SortedCloud:
    """A cloud sorted along its Morton curve: ``points[i] = P[order[i]]`` with ``codes`` (sorted),
    and the quantisation ``lo``, ``scale`` of :func:`morton_codes`."""

    points: np.ndarray
    order: np.ndarray
    codes: np.ndarray
    lo: np.ndarray
    scale: float

    @classmethod
    def of(cls, P: np.ndarray, order: np.ndarray | None = None) -> SortedCloud:
        """The sorted cloud of ``P``; a given ``order`` that sorts the codes saves the sort."""
        codes, lo, scale = morton_codes(P)
        if order is not None:
            c = codes[order]
            if c.size == P.shape[0] and bool(np.all(c[1:] >= c[:-1])):
                return cls(take_rows(P, order), order, c, lo, scale)
        order = sort_codes(codes)
        return cls(take_rows(P, order), order, codes[order], lo, scale)


def knn_grid(
    sc: SortedCloud,
    k: int,
    *,
    subset: np.ndarray | None = None,
    query: np.ndarray | None = None,
    self_index: np.ndarray | None = None,
) -> Neighbours:
    """Exact kNN on a Morton-sorted cloud (:func:`spectrageo.outliers._grid.knn_sorted`).

    Default: every point of ``sc`` queries the others. ``subset`` (sorted row indices of ``sc``)
    restricts the *data* to those rows (copied, still sorted, with grid levels of their own;
    returned indices are rows of ``sc``); ``query`` (sorted row indices of ``sc``) restricts the
    queries, and ``self_index[i]`` (a position in ``subset``, or in ``sc`` without a subset, or
    -1) excludes query ``i`` itself. Same result as :func:`knn_chunked` up to the order of
    exactly equidistant neighbours; runs on numba's threads; memory is the ``n k`` indices plus
    24 bytes per query (the distances are reduced on the fly to their mean, the ``k``-th and the
    nearest).
    """
    from ._grid import knn_sorted

    X, codes = sc.points, sc.codes
    if subset is not None:
        X, codes = take_rows(X, subset), codes[subset]
    # few queries: on the calling thread (docs/decisions.md#outliers-speed-serial-regions)
    few = KNN_SERIAL_BELOW
    if query is None and subset is None:
        idx, dmean, dlast, dzero = knn_sorted(X, codes, k, sc.lo, sc.scale, serial_below=few)
    else:
        qi = np.arange(sc.points.shape[0]) if query is None else query
        if query is None and self_index is None:
            self_index = qi
        idx, dmean, dlast, dzero = knn_sorted(
            X,
            codes,
            k,
            sc.lo,
            sc.scale,
            query=take_rows(sc.points, qi),
            qcodes=sc.codes[qi],
            self_index=self_index,
            serial_below=few,
        )
    if subset is not None:
        idx = subset.astype(idx.dtype, copy=False)[idx]
    return Neighbours(idx, dmean, dlast, int(np.count_nonzero(dzero)))


#: Grid of :func:`resolvable`: the square of any non-zero multiple is a normal float64.
RESOLUTION = 1e-150


def resolvable(X: np.ndarray) -> np.ndarray:
    """``X`` (n, 3) with the coordinates below ``2**52 * RESOLUTION`` in magnitude rounded to
    multiples of :data:`RESOLUTION`, so that distinct rows lie at a non-zero squared distance:
    points the search finds at distance 0 (their squared distance underflows) become copies.
    """
    small = np.abs(X) < RESOLUTION * 2.0**52
    if not small.any():
        return X
    return np.where(small, np.round(X / RESOLUTION) * RESOLUTION, X)


def check_span(X: np.ndarray, spacing: float, dtype) -> None:
    """Refuse a cloud whose extent in point spacings overflows the products of ``dtype``
    (squares of coordinates in spacings, summed over a patch)."""
    limit = 1e15 if np.dtype(dtype) == np.float32 else 1e100
    cmin, cmax = column_bounds(X)  # contiguous column passes, not a strided np.ptp(axis=0)
    lo, hi = float(cmin.min()), float(cmax.max())
    span = float(np.max(cmax - cmin))
    if not span <= limit * spacing:
        raise InvalidInputError(
            f"the point cloud spans {span:.3g} (coordinates from {lo:.3g} to {hi:.3g}), "
            f"{span / spacing:.3g} times its point spacing {spacing:.3g}; the RPCA arithmetic "
            f"({np.dtype(dtype).name}) overflows beyond {limit:.0e} spacings. Remove the distant "
            "points or rescale the cloud."
        )
