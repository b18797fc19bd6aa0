"""Outlier removal for static point clouds: the RPCA filter of Algorithm 14 (Section 5.4.1) and
the statistical (SOR) and radius filters, one contract (:func:`remove_outliers`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._threads import numba_threads
from .._validation import (
    check_choice,
    check_positive,
    coordinate_array,
    deprecated_flag,
    options_with_legacy,
)
from ..geometry import PointCloud
from . import _local_density
from ._common import SortedCloud, check_k, knn_grid
from ._organized import grid_labels
from ._support import sparse_surface, within_spread
from ._thresholds import (  # noqa: F401 - the VALLEY_* constants are re-exported
    DEFAULT_THRESHOLD_RULE,
    RPCA_MIN_TAU,
    THRESHOLD_RULES,
    VALLEY_BIN,
    VALLEY_RATIO,
    VALLEY_SMOOTH,
    VALLEY_Z,
    auto_threshold,
    valley_threshold,
)
from .rpca import RPCAOptions, rpca_scores

__all__ = [
    "OutlierResult",
    "auto_threshold",
    "detect_outliers",
    "radius_scores",
    "remove_outliers",
    "sor_scores",
    "valley_threshold",
]

METHODS = ("rpca", "sor", "radius")
#: Score gate of the sparse-point stage, a fraction of the threshold; chosen on the tuning split
#: (docs/decisions.md#outliers-sparse-stage).
SPARSE_GATE = 0.25
#: Largest ``Q_0.9 / Q_0.5`` of the kept points' ``k``-th neighbour distances at which the second
#: pass runs; chosen on the tuning split (docs/decisions.md#outliers-rescore).
RESCORE_SPREAD = 2.08
#: Above :data:`RESCORE_SPREAD`, the second pass removes only its outliers whose ``k``-th
#: neighbour distance is at least this many times the median of their neighbours'; chosen on the
#: tuning split (docs/decisions.md#outliers-lidar-local-rescore).
RESCORE_LOCAL = 2.0
#: After a second pass that removed at least ``RESCORE_FOUND`` of the cloud a further pass is
#: tried, whose removals stand only when they are at least ``RESCORE_FOUND`` of the cloud and
#: their median score is at least ``RESCORE_LIFT`` times the pass's threshold (a population above
#: it, not the tail of the clean scores), up to ``RESCORE_PASSES`` passes in all, the first
#: included (:func:`_rescore`); chosen on the tuning split
#: (docs/decisions.md#outliers4-rescore-passes).
RESCORE_FOUND = 0.01
RESCORE_LIFT = 1.2
RESCORE_PASSES = 4
#: When the first pass removed under ``rescore_share`` of the cloud, the locally sparse points
#: (:mod:`._local_density`) count towards that share: reaching it with them, the passes of
#: :func:`_rescore` run on the points still kept, followed by the locally sparse test again;
#: chosen on the tuning split (docs/decisions.md#outliers6-rescore-after-local).
RESCORE_AFTER_LOCAL = True
#: Do no harm on a nearly clean cloud (scores remove under ``HARM_SHARE`` of it): a point removed
#: by its score alone is kept when ``score < HARM_SCORE * tau``, its ``k``-th neighbour distance is
#: at most ``HARM_SPACING`` times the median and it lies within ``HARM_SPREAD`` standard
#: deviations of its neighbours' plane; chosen on the tuning split
#: (docs/decisions.md#outliers3-harm).
HARM_SHARE = 0.03
HARM_SCORE = 2.0
HARM_SPACING = 1.5
HARM_SPREAD = 8.0


@dataclass(frozen=True)
class OutlierResult:
    """Result of :func:`remove_outliers` (arrays in input order).

    Attributes
    ----------
    keep : (n,) bool ndarray
        ``True`` for kept points: ``score < threshold`` (``<=`` for ``"sor"`` and ``"radius"``).
    scores : (n,) float ndarray
        Outlier score per point (larger = more outlying); ``inf`` for non-finite input rows.
    threshold : float
    method : str
    points : PointCloud or None
        The kept points with their attributes (None when not requested or none kept).
    smoothed : (n, 3) ndarray or None
        ``"rpca"`` with ``smoothed=True``: the first column of the low-rank part (Eq. 5.99).
    info : dict
        Method details (spacing, iterations, convergence, ...).
    """

    keep: np.ndarray = field(repr=False)
    scores: np.ndarray = field(repr=False)
    threshold: float
    method: str
    points: PointCloud | None = field(default=None, repr=False)
    smoothed: np.ndarray | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)

    @property
    def n_removed(self) -> int:
        return int(self.keep.size - np.count_nonzero(self.keep))


def _finite_rows(P: Any, nonfinite: str) -> tuple[np.ndarray, np.ndarray | None, PointCloud | None]:
    """``(points, finite_mask_or_None, cloud_or_None)`` with the non-finite policy applied."""
    if isinstance(P, PointCloud):
        return P.points, None, P
    if P is None:
        raise InvalidInputError("`cloud` must be a PointCloud or an (n, 3) array; got None.")
    X = coordinate_array(P, "cloud")
    fin = np.isfinite(X)
    if fin.all():  # a contiguous pass; the per-row reduction only when some value is not finite
        return np.ascontiguousarray(X), None, None
    ok = fin.all(axis=1)
    if nonfinite == "raise":
        bad = np.flatnonzero(~ok)
        raise InvalidInputError(
            f"`cloud` contains NaN or inf coordinates at {bad.size} row(s), first at index "
            f"{int(bad[0])}; pass nonfinite='remove' to drop them as outliers."
        )
    return np.ascontiguousarray(X[ok]), ok, None


def sor_scores(P: Any, k: int = 10, *, workers: int = -1) -> np.ndarray:
    """Statistical outlier scores: the z-score of each point's mean distance to its ``k`` neighbours.

    Keeping ``score <= std_ratio`` is the statistical outlier removal of PCL and Open3D; exact
    duplicates count as neighbours at distance 0. All zeros when every distance is equal.
    """
    X = np.asarray(P, dtype=np.float64)
    k = check_k(k, X.shape[0])
    d = _knn_stat(X, k, "dmean", workers)
    sd = float(d.std())
    if sd == 0.0:
        return np.zeros_like(d)
    return (d - float(d.mean())) / sd


def radius_scores(P: Any, k: int = 10, *, workers: int = -1) -> np.ndarray:
    """Radius outlier scores: the distance from each point to its ``k``-th nearest neighbour.

    Keeping ``score <= r`` is radius outlier removal with ``min_pts = k`` (PCL, Open3D).
    """
    X = np.asarray(P, dtype=np.float64)
    k = check_k(k, X.shape[0])
    return _knn_stat(X, k, "dlast", workers)


def _knn_stat(X: np.ndarray, k: int, what: str, workers: int) -> np.ndarray:
    """``dmean`` or ``dlast`` of the exact kNN (grid/octree search on the Morton-sorted cloud)."""
    with numba_threads(workers):
        sc = SortedCloud.of(X)
        nb = knn_grid(sc, k)
    out = np.empty(X.shape[0])
    out[sc.order] = getattr(nb, what)
    return out


def _sparse_points(r, s: np.ndarray, tau: float, factor: float | None) -> np.ndarray:
    """The sparse-point stage: ``d_k > factor * median(d_k)`` and ``score >= SPARSE_GATE * tau``,
    ``d_k`` the (range-normalised) ``k``-th neighbour distance
    (docs/decisions.md#outliers-sparse-stage); none without ``factor`` or ``kth_distance``."""
    d = r.kth_distance
    if factor is None or d is None or d.size == 0:
        return np.zeros(s.size, dtype=bool)
    return (d > factor * float(np.median(d))) & (s >= SPARSE_GATE * tau)


def _harmless(X: np.ndarray, r, s: np.ndarray, tau: float) -> np.ndarray:
    """On a cloud whose scores remove under ``HARM_SHARE`` of it: ``tau <= s < HARM_SCORE tau``,
    ``d_k <= HARM_SPACING median(d_k)`` (``d_k`` the range-normalised ``k``-th neighbour
    distance) and within ``HARM_SPREAD`` standard deviations of the neighbours' plane
    (:func:`._support.within_spread`): a moderate score inside the local spread of a region that
    is not sparse (docs/decisions.md#outliers3-harm); none without ``kth_distance`` or the
    neighbour lists."""
    d = r.kth_distance
    out = np.zeros(s.size, dtype=bool)
    if d is None or r.knn is None or d.size == 0 or HARM_SCORE <= 1.0:
        return out
    high = s >= tau
    if np.count_nonzero(high) >= HARM_SHARE * s.size:
        return out
    rows = np.flatnonzero(high & (s < HARM_SCORE * tau) & (d <= HARM_SPACING * float(np.median(d))))
    out[rows] = within_spread(X, rows, r.knn, HARM_SPREAD)
    return out


def _rpca_pass(X, k, options, threshold, rule, smoothed, workers, device, info: dict, first=True):
    """One scoring pass of ``method="rpca"`` on ``X`` without the grid stage: ``(keep, result of
    rpca_scores, tau)``; ``rule`` None uses ``threshold``; the do-no-harm rule (:func:`_harmless`)
    in the ``first`` pass only. Counts go to ``info``."""
    r = rpca_scores(X, k, options, smoothed=smoothed, workers=workers, device=device)
    s = r.scores
    blob = r.clusters if r.clusters is not None else np.zeros(s.size, dtype=bool)
    if rule is None:
        tau = float(threshold)
    elif rule == "valley":
        tau, vinfo = valley_threshold(s, minimum=RPCA_MIN_TAU)
        info.update(vinfo)
    else:
        tau = auto_threshold(s, minimum=RPCA_MIN_TAU, rule=rule)
    sparse = _sparse_points(r, s, tau, options.sparse_factor)
    harmless = _harmless(X, r, s, tau) if first else np.zeros(s.size, dtype=bool)
    keep = ((s < tau) | harmless) & ~blob & ~sparse
    # large sparse surface regions are kept (docs/decisions.md#outliers-sparse-regions);
    # clouds scored on k-d tiles skip it, as the sparse stage
    if options.sparse_regions and r.kth_distance is not None and not keep.all():
        surface = sparse_surface(X, ~keep, k, r.knn)
        info["n_sparse_region_kept"] = int(np.count_nonzero(surface))
        keep |= surface
    info["n_cluster_outliers"] = int(np.count_nonzero(blob))
    info["n_harmless_kept"] = int(np.count_nonzero(harmless))
    info["n_sparse_outliers"] = int(np.count_nonzero(sparse & ~blob & (s < tau)))
    return keep, r, tau


def _rescore_due(options: RPCAOptions, r, keep: np.ndarray, k: int, info: dict) -> str | None:
    """The second pass due: None unless the first pass removed at least
    ``options.rescore_share`` of the cloud and kept more than ``k`` points; ``"all"`` when their
    (range-normalised) ``k``-th neighbour distances ``d`` are homogeneous,
    ``Q_0.9(d) <= RESCORE_SPREAD Q_0.5(d)`` (scores in global spacings compare), else
    ``"local"`` (:func:`_locally_sparse`)."""
    n_kept = int(np.count_nonzero(keep))
    share = 1.0 - n_kept / max(keep.size, 1)
    if options.rescore_share is None or share < options.rescore_share or n_kept <= k:
        return None
    if r.kth_distance is None:  # k-d tiles: no distances to judge the spread by
        return None
    q50, q90 = np.quantile(r.kth_distance[keep], [0.5, 0.9])
    info["rescore_spread"] = float(q90 / q50) if q50 > 0 else float("inf")
    return "all" if q90 <= RESCORE_SPREAD * q50 else "local"


def _rescore(X, k, options, threshold, rule, workers, device, keep, mode, info) -> None:
    """The passes after the first, on the kept points, ``keep`` updated in place: each scores
    the points still kept (the stages of :func:`_rpca_pass` without the do-no-harm rule; with
    ``mode == "local"`` only its locally sparse outliers, :func:`_locally_sparse`). The second
    pass stands; after a pass that removed at least :data:`RESCORE_FOUND` of the cloud a further
    pass is tried, which stands only when it removes at least that share and the median score
    of its removed points is at least :data:`RESCORE_LIFT` times its threshold, up to
    :data:`RESCORE_PASSES` passes in all. ``info["rescore"]``: the second pass's threshold, the
    points removed after the first pass, the passes that stood (``n_passes``, the first
    included); ``info["rescore_dropped"]``: the tried pass that was dropped (its count, ``lift``
    = median score of its removed points over its threshold)."""
    n, done, n_removed, tau2 = keep.size, 1, 0, None
    while done < RESCORE_PASSES:
        sub = np.flatnonzero(keep)
        if sub.size <= k:
            break
        keep2, r2, tau = _rpca_pass(
            X[sub], k, options, threshold, rule, False, workers, device, {}, first=False
        )
        if mode == "local":
            keep2 |= ~_locally_sparse(r2)
        found = int(sub.size - np.count_nonzero(keep2))
        lift = float(np.median(r2.scores[~keep2])) / tau if found else 0.0
        if done > 1 and (found < RESCORE_FOUND * n or lift < RESCORE_LIFT):
            info["rescore_dropped"] = {
                "threshold": tau,
                "n_removed": found,
                "lift": lift,
                "pass": done + 1,
            }
            break
        keep[sub[~keep2]] = False
        done, n_removed = done + 1, n_removed + found
        tau2 = tau if tau2 is None else tau2
        if found < RESCORE_FOUND * n:
            break
    info["rescore"] = {
        "threshold": tau2,
        "n_removed": n_removed,
        "local": mode == "local",
        "n_passes": done,
    }


def _locally_sparse(r) -> np.ndarray:
    """``d_i >= RESCORE_LOCAL median_{j in N_i} d_j``, ``d`` the ``k``-th neighbour distances and
    ``N_i`` the ``k`` neighbours of a pass (all False without its lists)."""
    d = r.kth_distance
    if r.knn is None or d is None:
        return np.zeros(r.scores.size, dtype=bool)
    order, idx = r.knn
    ds = d[order]  # sorted positions, as the lists
    return d >= RESCORE_LOCAL * _inverse(order, np.median(ds[idx], axis=1))


def _locally_sparse_stage(X: np.ndarray, k: int, r, keep: np.ndarray) -> int:
    """Remove the locally sparse kept points from ``keep`` in place (:mod:`._local_density`,
    flagged points on their neighbours' plane exempted); their count (0 on k-d tiles, which have
    no ``kth_distance``)."""
    if r.kth_distance is None:
        return 0
    order = None if r.knn is None else r.knn[0]
    local = _local_density.locally_sparse_kept(
        X, keep, r.kth_distance, k, factor=_local_density.LOCAL_FACTOR, order=order
    )
    local &= ~_local_density.on_surface(X, local, r.knn)
    keep &= ~local
    return int(np.count_nonzero(local))


def _inverse(order: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.empty_like(v)
    out[order] = v
    return out


def remove_outliers(
    cloud: Any,
    *,
    method: str = "rpca",
    k: int = 10,
    threshold: float | None = None,
    smoothed: bool = False,
    nonfinite: str = "raise",
    return_points: bool | None = None,
    workers: int = -1,
    threshold_rule: str = DEFAULT_THRESHOLD_RULE,
    device: Any = "cpu",
    options: RPCAOptions | None = None,
    **legacy: Any,
) -> OutlierResult:
    """Remove outliers from a point cloud (Algorithm 14 or a statistical baseline).

    ``method="rpca"`` (Section 5.4.1): the scores of :func:`rpca_scores` (Eq. 5.98-5.99, in units
    of the point spacing); points with ``score < tau`` are kept, except the small volumetric
    clusters of its step 8 (whatever their score) and the sparse points of
    ``options.sparse_factor`` (:func:`_sparse_points`), unless they lie in a large sparse
    surface region (``options.sparse_regions``: :func:`._support.sparse_surface`); with
    ``options.grid`` (an organized depth frame) the flying pixels are removed and the
    image-supported points kept (:func:`._organized.grid_labels`). On a nearly clean cloud
    (:data:`HARM_SHARE`) moderate scores inside their neighbours' spread are kept
    (:func:`_harmless`). When the stages before the
    grid remove at least ``options.rescore_share`` of the cloud, the kept points are scored again
    the same way and the second pass's outliers removed too: all of them when the kept points'
    spacing is homogeneous (:data:`RESCORE_SPREAD`), else those locally sparse
    (:data:`RESCORE_LOCAL`; ``scores`` and ``threshold`` stay the first pass's;
    ``info["rescore"]``); after a pass that removed at least :data:`RESCORE_FOUND` of the
    cloud a further pass is tried, which stands only when it removes that share with a median
    score of at least :data:`RESCORE_LIFT` times its threshold (else
    ``info["rescore_dropped"]``), up to :data:`RESCORE_PASSES` passes (:func:`_rescore`).
    Then the locally sparse kept points are removed (:mod:`._local_density`;
    ``info["n_locally_sparse"]``; not on k-d tiles); when no second pass ran and the first
    pass's removals with them reach ``options.rescore_share``, the passes run on the points
    still kept and the locally sparse test once more (:data:`RESCORE_AFTER_LOCAL`;
    ``info["rescore_after_local"]``).
    ``threshold=None`` uses
    ``threshold_rule`` (``"valley"``: :func:`valley_threshold`; ``"density"``, ``"otsu"``:
    :func:`auto_threshold`) with the floor :data:`RPCA_MIN_TAU` = 0.5 spacings (chosen on the tuning
    split; see docs/decisions.md#outlier-rpca-constants). ``method="sor"``: keep points whose mean
    kNN distance is within ``threshold`` (default 1) standard deviations above the mean
    (:func:`sor_scores`). ``method="radius"``: keep points with at least ``k`` neighbours within
    radius ``threshold`` (default twice the median ``k``-th-neighbour distance;
    :func:`radius_scores`).

    Parameters
    ----------
    cloud : PointCloud or (n, 3) array_like
        ``n >= k + 1`` points.
    method : {"rpca", "sor", "radius"}
    k : int
        Neighbours per point.
    threshold : float, optional
        ``tau`` (RPCA, spacing units), ``std_ratio`` (SOR) or the radius (radius).
    smoothed : bool
        RPCA only: also return the low-rank smoothed points.
    nonfinite : {"raise", "remove"}
        Array rows with NaN/inf coordinates: raise, or mark them as outliers (score ``inf``).
    return_points : bool, optional
        Deprecated: :func:`detect_outliers` skips ``result.points``.
    workers : int
        Threads of the neighbour search and of the RPCA solver (-1: all cores).
    threshold_rule : {"valley", "density", "otsu"}
        RPCA only: automatic threshold rule when ``threshold`` is None.
    device : {"cpu", "cuda", "auto"} or torch.device
        RPCA only: where its iterations run (``device`` of :func:`rpca_scores`).
    options : RPCAOptions, optional
        RPCA only: options of :func:`rpca_scores`.
    **legacy
        Deprecated: the fields of :class:`RPCAOptions` as keyword arguments.

    Returns
    -------
    OutlierResult

    Raises
    ------
    InvalidInputError
        Empty or malformed input, fewer than ``k + 1`` finite points, or options of another method.
    """
    if return_points is not None:
        deprecated_flag("remove_outliers", "return_points", "detect_outliers() (no `points`)")
    args = (method, k, threshold, smoothed, nonfinite, workers, threshold_rule, device, options)
    build = return_points is None or bool(return_points)
    return _outliers(cloud, *args, build, legacy, "remove_outliers")


def detect_outliers(
    cloud: Any,
    *,
    method: str = "rpca",
    k: int = 10,
    threshold: float | None = None,
    smoothed: bool = False,
    nonfinite: str = "raise",
    workers: int = -1,
    threshold_rule: str = DEFAULT_THRESHOLD_RULE,
    device: Any = "cpu",
    options: RPCAOptions | None = None,
    **legacy: Any,
) -> OutlierResult:
    """:func:`remove_outliers` without the kept cloud (``points`` None); parameters as there."""
    args = (method, k, threshold, smoothed, nonfinite, workers, threshold_rule, device, options)
    return _outliers(cloud, *args, False, legacy, "detect_outliers")


def _outliers(
    cloud, method, k, threshold, smoothed, nonfinite, workers, threshold_rule, device, options,
    build_points: bool, legacy: dict, name: str,
) -> OutlierResult:  # fmt: skip
    check_choice(method, "method", METHODS)
    check_choice(nonfinite, "nonfinite", ("raise", "remove"))
    check_choice(threshold_rule, "threshold_rule", THRESHOLD_RULES)
    if threshold is not None:
        check_positive(threshold, "threshold", allow_zero=method == "sor")
    if method != "rpca" and not (
        isinstance(device, str) and device.strip().lower() in ("cpu", "auto")
    ):
        raise InvalidInputError(
            f"`device={device!r}` applies to method='rpca' only (the GPU path of the patch "
            f"RPCA); method={method!r} runs on the CPU: use device 'cpu' or 'auto'."
        )
    if (legacy or options is not None) and method != "rpca":
        given = sorted(legacy) if legacy else ["options"]
        raise InvalidInputError(
            f"options {given} apply to method='rpca' only; got method={method!r}."
        )
    if method == "rpca":
        options = options_with_legacy(options, legacy, RPCAOptions, name)
    X, finite, pc = _finite_rows(cloud, nonfinite)
    k = check_k(k, X.shape[0])
    info: dict[str, Any] = {}
    sm = None
    if method == "rpca":
        rule = None if threshold is not None else threshold_rule
        keep_f, r, tau = _rpca_pass(X, k, options, threshold, rule, smoothed, workers, device, info)
        s = r.scores
        due = _rescore_due(options, r, keep_f, k, info)
        again = replace(options, grid=None, viewpoint=options.sensor_origin)
        if due is not None:
            # a second pass on the kept points (docs/decisions.md#outliers-rescore); of uneven
            # spacing, its locally sparse outliers only
            # (docs/decisions.md#outliers-lidar-local-rescore); further passes while they find
            # a contamination's worth (docs/decisions.md#outliers4-rescore-passes)
            _rescore(X, k, again, threshold, rule, workers, device, keep_f, due, info)
        if r.kth_distance is not None:  # (docs/decisions.md#outliers5-local-density)
            n_local = _locally_sparse_stage(X, k, r, keep_f)
            if due is None and n_local and RESCORE_AFTER_LOCAL:
                # the locally sparse points count towards the second pass's share
                # (docs/decisions.md#outliers6-rescore-after-local)
                due = _rescore_due(options, r, keep_f, k, info)
                if due is not None:
                    info["rescore_after_local"] = True
                    _rescore(X, k, again, threshold, rule, workers, device, keep_f, due, info)
                    n_local += _locally_sparse_stage(X, k, r, keep_f)
            info["n_locally_sparse"] = n_local
        if options.grid is not None:  # the grid stage (docs/decisions.md#outliers-organized-grid)
            pix = options.grid.pixels(X.shape[0] if finite is None else finite.size)
            pix = pix if finite is None else pix[finite]
            supported, flying = grid_labels(X, pix, options.grid.shape, options.sensor_origin)
            info["n_flying"] = int(np.count_nonzero(flying))
            info["n_supported_kept"] = int(np.count_nonzero(supported & ~keep_f))
            keep_f = (keep_f | supported) & ~flying
        info.setdefault("contamination", float(np.count_nonzero(~keep_f) / max(s.size, 1)))
        info["threshold_rule"] = "given" if threshold is not None else threshold_rule
        sm = r.smoothed
        info.update(
            spacing=r.spacing,
            n_refined=r.n_refined,
            n_iter=r.n_iter,
            converged=r.converged,
            residual=r.residual,
            n_blocks=r.n_blocks,
        )
    elif method == "sor":
        s = sor_scores(X, k, workers=workers)
        tau = 1.0 if threshold is None else float(threshold)
        keep_f = s <= tau
    else:
        s = radius_scores(X, k, workers=workers)
        tau = 2.0 * float(np.median(s)) if threshold is None else float(threshold)
        keep_f = s <= tau
    if finite is not None:
        n = finite.size
        keep = np.zeros(n, dtype=bool)
        keep[finite] = keep_f
        scores = np.full(n, np.inf)
        scores[finite] = s
        if sm is not None:
            full = np.full((n, 3), np.nan)
            full[finite] = sm
            sm = full
        info["n_nonfinite"] = int(n - np.count_nonzero(finite))
    else:
        keep, scores = keep_f, s
    points = None
    if build_points and keep.any():
        points = pc.select(keep) if pc is not None else PointCloud(X[keep_f])
    return OutlierResult(
        keep=keep,
        scores=scores,
        threshold=tau,
        method=method,
        points=points,
        smoothed=sm,
        info=info,
    )
