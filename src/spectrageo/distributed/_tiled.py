"""Out-of-core point-cloud processing: spatial tiles with halos, one Dask task per tile.

Outlier removal, point-cloud saliency and the robot pipeline's denoising share one machinery
(``docs/scaling.md``): the input is streamed and spilled to the k-d tiles of
:mod:`spectrageo.outliers._tiles`; each Dask task runs a per-tile function on its tile plus halo
(:mod:`spectrageo.outliers._halo`) and returns the values of its own points; the global steps
(thresholds, normalisations, kernel widths) run on the gathered values and the output is streamed
in input order (:mod:`spectrageo.io._ply_stream`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive, options_with_legacy
from ..io._ply_stream import write_moved, write_values
from ..outliers import RPCAOptions
from ..outliers import rpca as _rpca
from ..outliers._halo import tile_job
from ..outliers._rpca_tiled import to_global_spacing
from ..outliers._thresholds import DEFAULT_THRESHOLD_RULE
from ..outliers._tile_fns import bilateral_tile, dmean_tile, outlier_tile
from ..outliers._tiles import CHUNK, Tiles, append, load, partition, tile_base
from ._cluster import open_client, require_dask, show_progress, thread_budget
from ._stream import open_source

__all__ = [
    "TileOptions",
    "TiledResult",
    "TiledRobotResult",
    "TiledSaliencyResult",
    "remove_outliers_tiled",
    "robot_denoise_tiled",
    "saliency_tiled",
]

METHODS = ("rpca", "sor", "radius")
SALIENCY_SUFFIXES = (".npy", ".csv", ".ply")


@dataclass(frozen=True)
class TileOptions:
    """How a tiled run cuts the cloud and where it runs (validated on creation).

    Parameters
    ----------
    tile : int
        Points per tile; memory per task is about ``(1 + halo) * tile`` points.
    chunk : int
        Points per streamed read.
    workers, scheduler, processes, progress
        Dask cluster (:func:`spectrageo.distributed.open_client`) and progress bar.
    scratch : path, optional
        Folder of the spill files (default beside ``dst``); workers must see it.
    """

    tile: int
    chunk: int = CHUNK
    workers: int | None = None
    scheduler: str | None = None
    processes: bool = True
    progress: bool = False
    scratch: str | os.PathLike | None = None

    def __post_init__(self) -> None:
        check_positive(self.tile, "tile", integer=True)
        check_positive(self.chunk, "chunk", integer=True)
        if self.workers is not None:
            check_positive(self.workers, "workers", integer=True)


def _options(tiling: TileOptions | None, legacy: dict, func: str) -> TileOptions:
    """``tiling`` with the deprecated keyword arguments of its fields (popped from ``legacy``)."""
    names = {f.name for f in dataclasses.fields(TileOptions)}
    old = {key: legacy.pop(key) for key in list(legacy) if key in names}
    if tiling is None:
        if "tile" not in old:
            raise InvalidInputError(f"{func}(): `tiling` (a TileOptions with `tile`) is required.")
        tiling = TileOptions(tile=old["tile"])
    return options_with_legacy(tiling, old, TileOptions, func)


def _client(tiling: TileOptions, n_tasks: int):
    return open_client(
        workers=tiling.workers,
        scheduler=tiling.scheduler,
        processes=tiling.processes,
        n_tasks=n_tasks,
        verbose=tiling.progress,
    )


@dataclass(frozen=True)
class TiledResult:
    """Result of :func:`remove_outliers_tiled` (arrays are input order; ``keep``/``scores`` are
    None when not requested)."""

    n_points: int
    n_kept: int
    threshold: float
    method: str
    n_tiles: int
    keep: np.ndarray | None = field(default=None, repr=False)
    scores: np.ndarray | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TiledSaliencyResult:
    """Result of :func:`saliency_tiled`: ``values`` (n,) saliency in input order, or None when not
    requested."""

    n_points: int
    n_tiles: int
    values: np.ndarray | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TiledRobotResult:
    """Result of :func:`robot_denoise_tiled` (input order): ``keep`` (n,) bool and ``scores`` (n,)
    of the RPCA step, ``points`` (n_kept, 3) the filtered kept points; arrays None when not
    requested."""

    n_points: int
    n_kept: int
    threshold: float
    n_tiles: int
    keep: np.ndarray | None = field(default=None, repr=False)
    scores: np.ndarray | None = field(default=None, repr=False)
    points: np.ndarray | None = field(default=None, repr=False)
    info: dict = field(default_factory=dict)


@contextmanager
def _scratch_dir(dst, scratch) -> Iterator[str]:
    if scratch is not None:
        parent = Path(scratch)
    elif dst is not None:
        parent = Path(dst).resolve().parent
    else:
        parent = Path(tempfile.gettempdir())
    name = Path(dst).name if dst is not None else "points"
    spill = tempfile.mkdtemp(prefix=f".{name}.tiles-", dir=parent)
    try:
        yield spill
    finally:
        shutil.rmtree(spill, ignore_errors=True)


def _rpca_tile(tile: int, options: RPCAOptions) -> tuple[int, int]:
    """``(tile, block_size)`` of the ``rpca`` passes: tiles of at most ``block_size`` points, the
    untiled method's (``partition="tiles"`` of :func:`spectrageo.outliers.rpca_scores`)."""
    bs = _rpca.BLOCK_SIZE if options.block_size is None else int(options.block_size)
    return min(int(tile), bs), bs


def _map_tiles(client, tiles: Tiles, hops, fn, params, budget, progress, name) -> Iterator:
    """Run ``fn`` on every tile; yields ``(t, result)`` as tasks finish."""
    distributed = require_dask()
    boxes_f = client.scatter(tiles.boxes, broadcast=True, hash=False)
    token = uuid.uuid4().hex[:8]
    futs = [
        client.submit(
            tile_job,
            tiles.spill,
            t,
            boxes_f,
            tiles.gbox,
            tuple(hops),
            fn,
            params,
            budget,
            tiles.tag,
            key=f"spectrageo-{name}-{token}-{t}",
            pure=False,
        )  # fmt: skip
        for t in range(tiles.n_tiles)
    ]
    show_progress(futs, progress)
    for fut in distributed.as_completed(futs):
        r = fut.result()
        t = int(fut.key.rsplit("-", 1)[1])
        fut.release()
        yield t, r


class _Stats:
    """Tile sizes and region sizes over a run (for ``info``)."""

    def __init__(self, n_tiles: int):
        self.sizes = np.zeros(n_tiles, dtype=np.int64)
        self.region = np.zeros(n_tiles, dtype=np.int64)

    def add(self, t: int, r: dict) -> None:
        self.sizes[t] = r["idx"].size
        self.region[t] = max(self.region[t], r["n_region"])

    def info(self) -> dict:
        return {
            "tile_points_max": int(self.sizes.max()),
            "region_points_max": int(self.region.max()),
            "halo_fraction_mean": float(self.region.sum() / max(self.sizes.sum(), 1) - 1.0),
        }


def _saliency_fn(R, m, _dmean, *, workers, k, normal_k) -> dict:
    """``||lambda(C_p)||`` of the own points (Eq. 6.30-6.32, as
    :func:`spectrageo.saliency.pointcloud_saliency` computes it)."""
    from ..geometry.features import patch_eigenvalues
    from ..geometry.pointcloud import pca_normals
    from ..graph.adjacency import knn

    N = pca_normals(R, k=normal_k, orient="none")
    nb, _ = knn(R, k + 1, include_self=True, query=R[:m], workers=workers)
    ev = patch_eigenvalues(N, nb) * (k + 1)
    return {"norm": np.linalg.norm(ev, axis=1)}


def _check_tile(tile: int, need: int, what: str) -> None:
    if tile < need:
        raise InvalidInputError(f"`tile` must be >= {what} = {need} points; got {tile}.")


def _outlier_pass(client, tiles, method, k, kw, budget, progress, stats):
    """Scores (input order) of every point, its mean kNN distance, and for ``rpca`` its tile,
    the tiles' spacings and the small-cluster flags (step 8 of
    :func:`spectrageo.outliers.rpca_scores`, measured per tile)."""
    n = tiles.n
    scores = np.empty(n)
    dmean = np.empty(n)
    tile_of = np.empty(n, dtype=np.int32) if method == "rpca" else None
    blob = np.zeros(n, dtype=bool) if method == "rpca" else None
    spacing = np.full(tiles.n_tiles, np.nan)
    hops = (k, k) if method == "rpca" else (k,)
    params = {"k": k, "method": method, "kw": kw}
    for t, r in _map_tiles(client, tiles, hops, outlier_tile, params, budget, progress, "tile"):
        stats.add(t, r)
        if r["idx"].size == 0:
            continue
        scores[r["idx"]] = r["scores"]
        dmean[r["idx"]] = r["dmean"]
        if tile_of is not None:
            tile_of[r["idx"]] = t
        if blob is not None and "clusters" in r:
            blob[r["idx"]] = r["clusters"]
        spacing[t] = r.get("spacing", np.nan)
    return scores, dmean, tile_of, spacing, blob


def _outlier_keep(
    method, threshold, scores, dmean, tile_of, spacing, n_tiles, blob=None, rule="density"
):
    """The untiled threshold rule over all gathered scores: ``(keep, scores, tau, info)``.

    ``rpca``: automatic threshold by ``rule`` (``"valley"``: :func:`valley_threshold`, else
    :func:`auto_threshold`); ``blob`` (small-cluster flags), when given, are removed whatever
    their score, as :func:`spectrageo.outliers.remove_outliers` does.
    """
    from .. import outliers
    from ..outliers.static import RPCA_MIN_TAU

    info: dict[str, Any] = {}
    if method == "rpca":
        if n_tiles > 1:
            info["spacing"] = to_global_spacing(scores, dmean, tile_of, spacing)
        if threshold is not None:
            tau = float(threshold)
        elif rule == "valley":
            tau = float(outliers.valley_threshold(scores, minimum=RPCA_MIN_TAU)[0])
        else:
            tau = outliers.auto_threshold(scores, minimum=RPCA_MIN_TAU, rule=rule)
        keep = scores < tau if blob is None else (scores < tau) & ~blob
        if blob is not None:
            info["n_cluster_outliers"] = int(np.count_nonzero(blob))
    elif method == "sor":
        sd = float(dmean.std())
        scores = np.zeros_like(dmean) if sd == 0.0 else (dmean - float(dmean.mean())) / sd
        tau = 1.0 if threshold is None else float(threshold)
        keep = scores <= tau
    else:
        tau = 2.0 * float(np.median(scores)) if threshold is None else float(threshold)
        keep = scores <= tau
    return keep, scores, tau, info


def _timing(info: dict, tiles: Tiles, t_start: float, t_tiles: float, source) -> dict:
    info.update(
        time_read_s=round(tiles.time_read_s, 3),
        time_spill_s=round(tiles.time_spill_s, 3),
        time_tiles_s=round(t_tiles, 3),
        time_total_s=round(time.perf_counter() - t_start, 3),
        streamed=source.kind != "memory",
    )
    return info


def remove_outliers_tiled(
    src: Any,
    dst: str | os.PathLike | None,
    tiling: TileOptions | None = None,
    *,
    method: str = "rpca",
    k: int = 10,
    threshold: float | None = None,
    options: RPCAOptions | None = None,
    device: Any = "cpu",
    return_arrays: bool = False,
    **legacy: Any,
) -> TiledResult:
    """Outlier removal of a cloud too large for memory, scored in tiles on Dask, written streaming.

    ``sor`` and ``radius`` give the untiled keep mask exactly. ``rpca`` gives the keep mask of
    the first scoring pass of :func:`~spectrageo.outliers.remove_outliers` (threshold rule and
    cluster flags) when ``tile >= block_size`` (docs/decisions.md#outliers-tiles); smaller tiles
    approximate it. The stages that need a whole-cloud neighbourhood are not applied: sparse
    points and sparse surface regions, the organized grid, the do-no-harm rule of a nearly clean
    cloud (docs/decisions.md#outliers3-harm) and the second pass at high contamination
    (docs/decisions.md#outliers-rescore).

    Parameters
    ----------
    src : path or array
        Binary PLY, ``.npy``, LAS/LAZ (streamed; output in the same format), other formats (read
        whole), or an ``(n, 3+)`` numpy / dask array (kept rows written as ``.npy``).
    dst : path or None
        Kept points out; None writes nothing and returns ``keep`` and ``scores``.
    tiling : TileOptions
        Tile size (>= 2 k), chunk and cluster.
    method, k, threshold, options, device
        As :func:`spectrageo.outliers.remove_outliers`.
    return_arrays : bool
        Also return ``keep`` and ``scores``.
    **legacy
        Deprecated: fields of :class:`TileOptions` and :class:`RPCAOptions` as keywords.

    Returns
    -------
    TiledResult
    """
    func = "remove_outliers_tiled"
    tiling = _options(tiling, legacy, func)
    if (legacy or options is not None) and method != "rpca":
        given = sorted(legacy) if legacy else ["options"]
        raise InvalidInputError(f"options {given} apply to method='rpca' only.")
    if "partition" in legacy or (options is not None and options.partition != "tiles"):
        raise InvalidInputError("`partition` does not apply to tiled runs (they are the tiles).")
    options = options_with_legacy(options, legacy, RPCAOptions, func)
    tile, chunk = tiling.tile, tiling.chunk
    check_choice(method, "method", METHODS)
    check_positive(k, "k", integer=True)
    if tile < 2 * k:
        raise InvalidInputError(f"`tile` must be >= 2 k = {2 * k} points; got {tile}.")
    if threshold is not None:
        check_positive(threshold, "threshold", allow_zero=method == "sor")
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < k + 1:
        raise InvalidInputError(f"`k` = {k} neighbours need at least {k + 1} points; got {n}.")
    if dst is not None and source.kind == "array" and not str(dst).lower().endswith(".npy"):
        raise InvalidInputError(
            f"{Path(dst).name}: the kept points of an array are written as .npy."
        )
    kw: dict[str, Any] = {}
    if method == "rpca":
        tile, block_size = _rpca_tile(tile, options)
        if block_size < k + 1:
            raise InvalidInputError(f"`block_size` must be >= k + 1 = {k + 1}; got {block_size}.")
        kw = options.solver_kwargs(block_size=block_size, smoothed=False, workers=-1, device=device)
    with _scratch_dir(dst, tiling.scratch) as spill:
        tiles = partition(source, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        t0 = time.perf_counter()
        with _client(tiling, tiles.n_tiles) as client:
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, tiling.scheduler)
            scores, dmean, tile_of, spacing, blob = _outlier_pass(
                client, tiles, method, k, kw, budget, tiling.progress, stats
            )
        t_tiles = time.perf_counter() - t0
    keep, scores, tau, info = _outlier_keep(
        method, threshold, scores, dmean, tile_of, spacing, tiles.n_tiles, blob,
        rule=DEFAULT_THRESHOLD_RULE,
    )  # fmt: skip
    n_kept = int(keep.sum())
    # last pass: the kept rows
    if dst is not None:
        writer = source.writer(Path(dst), n_kept)
        ok = False
        try:
            for a, _xyz, rows in source.chunks(chunk):
                writer.write(rows[keep[a : a + len(_xyz)]])
            ok = True
        finally:
            writer.close(ok)
    else:
        return_arrays = True
    info.update(n_workers=n_workers, **stats.info())
    _timing(info, tiles, t_start, t_tiles, source)
    return TiledResult(
        n_points=n,
        n_kept=n_kept,
        threshold=tau,
        method=method,
        n_tiles=tiles.n_tiles,
        keep=keep if return_arrays else None,
        scores=scores if return_arrays else None,
        info=info,
    )


def saliency_tiled(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    tiling: TileOptions | None = None,
    *,
    k: int = 20,
    normal_k: int = 10,
    normalize: bool = True,
    return_values: bool = False,
    **legacy: Any,
) -> TiledSaliencyResult:
    """Point-cloud saliency (Eq. 6.30-6.33) of a cloud too large for memory, in tiles on Dask.

    Equals :func:`spectrageo.saliency.pointcloud_saliency` to rounding (reach ``(k, normal_k)``;
    degenerate patches and the min-max normalisation are handled over all values).

    Parameters
    ----------
    src : path
        Point cloud (binary PLY, ``.npy``, LAS/LAZ streamed; other formats read whole).
    dst : path
        ``.npy``, ``.csv`` or ``.ply`` (with ``saliency`` and jet colours), input order.
    tiling : TileOptions
        Tile size (>= 2 (max(k, normal_k) + 1)), chunk and cluster.
    k, normal_k, normalize
        As :func:`spectrageo.saliency.pointcloud_saliency`.
    return_values : bool
        Also return the (n,) values.
    **legacy
        Deprecated: fields of :class:`TileOptions` as keywords.

    Returns
    -------
    TiledSaliencyResult
    """
    tiling = _options(tiling, legacy, "saliency_tiled")
    if legacy:
        raise TypeError(
            f"saliency_tiled() got an unexpected keyword argument {sorted(legacy)[0]!r}"
        )
    tile, chunk = tiling.tile, tiling.chunk
    from ..saliency._common import check_int

    k = check_int(k, "k", minimum=2)
    normal_k = check_int(normal_k, "normal_k", minimum=2)
    need = 2 * (max(k, normal_k) + 1)
    _check_tile(tile, need, "2 (max(k, normal_k) + 1)")
    suf = _value_suffix(dst)
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < k + 1:
        raise InvalidInputError(f"`k` = {k} neighbours need at least {k + 1} points; got {n}.")
    with _scratch_dir(dst, tiling.scratch) as spill:
        tiles = partition(source, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        vals = np.memmap(Path(spill) / "values.f8", dtype=np.float64, mode="w+", shape=(n,))
        t0 = time.perf_counter()
        with _client(tiling, tiles.n_tiles) as client:
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, tiling.scheduler)
            params = {"k": k, "normal_k": normal_k}
            for t, r in _map_tiles(
                client, tiles, (k, normal_k), _saliency_fn, params, budget, tiling.progress,
                "saliency",
            ):  # fmt: skip
                stats.add(t, r)
                if r["idx"].size:
                    vals[r["idx"]] = r["norm"]
        t_tiles = time.perf_counter() - t0
        lo, hi = _saliency_globals(vals, chunk, normalize)
        write_values(source, Path(dst), suf, vals, chunk, lo, hi)
        values = np.array(vals) if return_values else None
        del vals
    info: dict[str, Any] = {"n_workers": n_workers, **stats.info()}
    _timing(info, tiles, t_start, t_tiles, source)
    return TiledSaliencyResult(n_points=n, n_tiles=tiles.n_tiles, values=values, info=info)


def _saliency_globals(vals: np.ndarray, chunk: int, normalize: bool) -> tuple[float, float]:
    """In place, chunk by chunk: norms -> ``1 / ||lambda||`` with the untiled degenerate-patch
    value, then min-max (:func:`spectrageo.saliency.pointcloud_saliency`). Returns the colour
    range (min, max) of the final values."""
    n = vals.shape[0]
    smax, degenerate = -np.inf, False
    for a in range(0, n, chunk):
        nr = np.array(vals[a : a + chunk])
        s = np.divide(1.0, nr, out=np.zeros_like(nr), where=nr > 0)
        if (nr > 0).any():
            smax = max(smax, float(s[nr > 0].max()))
        if (nr <= 0).any():
            degenerate = True
            s[nr <= 0] = np.nan  # marked; filled below
        vals[a : a + chunk] = s
    fill = smax if np.isfinite(smax) else 0.0
    lo, hi = np.inf, -np.inf
    for a in range(0, n, chunk):
        s = np.array(vals[a : a + chunk])
        if degenerate:
            s[np.isnan(s)] = fill
            vals[a : a + chunk] = s
        lo, hi = min(lo, float(s.min())), max(hi, float(s.max()))
    if not normalize:
        return lo, hi
    scale = max(abs(lo), abs(hi), np.finfo(float).tiny)
    flat = hi - lo <= 1e-9 * scale  # as saliency._common.minmax
    for a in range(0, n, chunk):
        s = np.array(vals[a : a + chunk])
        vals[a : a + chunk] = np.zeros_like(s) if flat else (s - lo) / (hi - lo)
    return (0.0, 0.0) if flat else (0.0, 1.0)


def _value_suffix(dst) -> str:
    suf = Path(dst).suffix.lower()
    if suf not in SALIENCY_SUFFIXES:
        raise InvalidInputError(
            f"`dst` must end with one of {', '.join(SALIENCY_SUFFIXES)}; got {str(dst)!r}."
        )
    return suf


def robot_denoise_tiled(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    tiling: TileOptions | None = None,
    *,
    k: int = 7,
    threshold: float | None = None,
    rpca_k: int = 10,
    sigma1: float | None = None,
    sigma2: float | None = None,
    n_iter: int = 1,
    outlier_removal: bool = True,
    return_arrays: bool = False,
    **legacy: Any,
) -> TiledRobotResult:
    """The robot pipeline's cloud output (Section 5.4.2) of a cloud too large for memory.

    RPCA outlier removal as the ``rpca`` tiles of :func:`remove_outliers_tiled`, then bilateral
    filtering (Eq. 5.100-5.101; reach ``(k, k)`` per pass, the global ``sigma1`` gathered first);
    given the keep mask, equal to :func:`spectrageo.outliers.robot_pipeline` to rounding.

    Parameters
    ----------
    src, dst : path
        Point cloud in, filtered kept points out (same format; PLY, ``.npy``, LAS/LAZ streamed).
    tiling : TileOptions
        Tile size (>= 2 (max(k, rpca_k) + 1)), chunk and cluster.
    k, threshold, rpca_k, sigma1, sigma2, n_iter
        As :func:`spectrageo.outliers.robot_pipeline`.
    outlier_removal : bool
        False: filter every point (``keep`` all True, ``scores`` None, ``threshold`` NaN).
    return_arrays : bool
        Also return ``keep``, ``scores`` and the filtered ``points``.
    **legacy
        Deprecated: fields of :class:`TileOptions` as keywords.

    Returns
    -------
    TiledRobotResult
    """
    tiling = _options(tiling, legacy, "robot_denoise_tiled")
    if legacy:
        raise TypeError(
            f"robot_denoise_tiled() got an unexpected keyword argument {sorted(legacy)[0]!r}"
        )
    chunk = tiling.chunk
    check_positive(k, "k", integer=True)
    check_positive(rpca_k, "rpca_k", integer=True)
    check_positive(n_iter, "n_iter", integer=True)
    for name, v in (("sigma1", sigma1), ("sigma2", sigma2)):
        if v is not None:
            check_positive(v, name)
    if threshold is not None:
        check_positive(threshold, "threshold")
    need = 2 * (max(k, rpca_k) + 1)
    _check_tile(tiling.tile, need, "2 (max(k, rpca_k) + 1)")
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < rpca_k + 1:
        raise InvalidInputError(
            f"`rpca_k` = {rpca_k} neighbours need at least {rpca_k + 1} points; got {n}."
        )
    _check_same_format(source, dst)
    rpca = RPCAOptions()
    tile, block_size = _rpca_tile(tiling.tile, rpca)  # the RPCA step's tiles: the untiled run's
    kw = rpca.solver_kwargs(block_size=block_size, smoothed=False, workers=-1, device="cpu")
    progress = tiling.progress
    with _scratch_dir(dst, tiling.scratch) as spill:
        tiles = partition(source, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        t0 = time.perf_counter()
        sigmas = []
        with _client(tiling, tiles.n_tiles) as client:
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, tiling.scheduler)
            if outlier_removal:
                scores, dmean, tile_of, spacing, blob = _outlier_pass(
                    client, tiles, "rpca", rpca_k, kw, budget, progress, stats
                )
                keep, scores, tau, info = _outlier_keep(
                    "rpca", threshold, scores, dmean, tile_of, spacing, tiles.n_tiles, blob,
                    rule=DEFAULT_THRESHOLD_RULE,
                )  # fmt: skip
                del dmean, tile_of, blob
            else:
                keep, scores, tau, info = np.ones(n, dtype=bool), None, math.nan, {}
            n_kept = int(keep.sum())
            if n_kept < k + 1:
                raise InvalidInputError(
                    f"only {n_kept} points are left after outlier removal; the filter needs "
                    f"at least k + 1 = {k + 1}."
                )
            cur = _respill(tiles, ".p0", lambda xyz, idx: keep[idx])
            dm = np.memmap(Path(spill) / "dmean.f8", dtype=np.float64, mode="w+", shape=(n,))
            for it in range(int(n_iter)):
                if sigma1 is None:  # global step: mean kNN distance over the kept cloud
                    for _t, r in _map_tiles(
                        client, cur, (k,), dmean_tile, {"k": k}, budget, progress, "dmean"
                    ):
                        if r["idx"].size:
                            dm[r["idx"]] = r["dmean"]
                    s1 = float(np.asarray(dm)[keep].mean())
                else:
                    s1 = float(sigma1)
                sigmas.append(s1)
                if s1 <= 0:
                    break  # all points coincide (as the untiled filter)
                params = {"k": k, "sigma1": s1, "sigma2": sigma2}
                nxt = _respill(cur, f".p{it + 1}", None)  # empty files, filled below
                for t, r in _map_tiles(
                    client, cur, (k, k), bilateral_tile, params, budget, progress, "bilateral"
                ):  # each tile's moved points go straight to the next pass's files
                    stats.add(t, r)
                    if r["idx"].size:
                        append(spill, t, nxt.tag, r["xyz"], r["idx"])
                        nxt.grow(t, r["xyz"])
                _drop(cur)
                cur = nxt
            del dm
        t_tiles = time.perf_counter() - t0
        pos = np.memmap(Path(spill) / "pos.f8", dtype=np.float64, mode="w+", shape=(n, 3))
        for t in range(cur.n_tiles):
            xyz, idx = load(spill, t, cur.tag)
            pos[idx] = xyz
        write_moved(source, Path(dst), keep, pos, n_kept, chunk)
        points = np.asarray(pos)[keep] if return_arrays else None
        del pos
    info.update(n_workers=n_workers, sigma1=sigmas, n_kept=n_kept, **stats.info())
    _timing(info, tiles, t_start, t_tiles, source)
    return TiledRobotResult(
        n_points=n,
        n_kept=n_kept,
        threshold=tau,
        n_tiles=tiles.n_tiles,
        keep=keep if return_arrays else None,
        scores=scores if return_arrays else None,
        points=points,
        info=info,
    )


_KIND_SUFFIXES = {"ply": (".ply",), "npy": (".npy",), "las": (".las", ".laz")}


def _check_same_format(source, dst) -> None:
    """Streamed inputs are written back in their own format (records copied)."""
    want = _KIND_SUFFIXES.get(source.kind)
    if want is not None and Path(dst).suffix.lower() not in want:
        raise InvalidInputError(
            f"the tiled output keeps the input's format: `dst` must end with "
            f"{' or '.join(want)}; got {Path(dst).name!r}."
        )


def _respill(tiles: Tiles, tag: str, select) -> Tiles:
    """A new point set with the same tiles: each tile's points filtered by ``select(xyz, idx)``
    (boxes and global box kept: they still contain the points), or empty files when ``select``
    is None."""
    for t in range(tiles.n_tiles):
        for ext in ("xyz", "idx"):
            Path(f"{tile_base(tiles.spill, t, tag)}.{ext}").write_bytes(b"")
        if select is None:
            continue
        xyz, idx = load(tiles.spill, t, tiles.tag)
        sel = select(xyz, idx)
        if sel.any():
            append(tiles.spill, t, tag, xyz[sel], idx[sel])
    return Tiles(tiles.spill, tiles.boxes.copy(), tiles.gbox.copy(), tiles.n, tag=tag)


def _drop(tiles: Tiles) -> None:
    for t in range(tiles.n_tiles):
        for ext in ("xyz", "idx"):
            Path(f"{tile_base(tiles.spill, t, tiles.tag)}.{ext}").unlink(missing_ok=True)
