"""Out-of-core outlier removal: spatial tiles with halos, one Dask task per tile.

Pipeline (``docs/scaling.md``):

1. *Stream* the input once (:mod:`._stream`): bounding box, count, and every ``s``-th point as a
   sample. A k-d split of the sample (median along the longest side, ``ceil(log2(n / tile))``
   levels) gives ``2^L`` axis-aligned boxes of at most about ``tile`` points each.
2. *Spill*: stream again and append every point (float64 coordinates and its input row) to its
   box's file in a scratch folder beside the output.
3. *Tiles on Dask*: a task loads its box and the points of the other boxes within a halo of
   width ``w`` (only the files of boxes that meet the widened box), and scores its own points.
   ``w`` is chosen so that every neighbourhood the score reads lies inside box + halo (below);
   the task returns the scores of its own points only.
4. *Threshold* on all scores (the same automatic rule as the untiled run), then *stream* the
   input a third time, writing the kept rows (every PLY property / LAS field kept).

Halo. For ``sor``/``radius`` the score of ``p`` reads the distances to its ``k`` nearest
neighbours (self excluded). Its ``k``-th neighbour distance among the box's own points, ``r_p``,
bounds the true one, so a halo that contains the ball ``B(p, r_p)`` of every own point holds
every true neighbour: ``w = max_p`` (protrusion of ``B(p, r_p)`` beyond the box) -- the kNN, and
so the scores and the keep mask, are those of the untiled run (the mean/std of SOR and the median
of the radius rule are taken over all tiles' values). ``rpca`` reads two hops (the patches of
``p``'s neighbours enter its baseline, step 6 of :func:`spectrageo.outliers.rpca_scores`), so the
halo is widened until the kNN balls of those neighbours are inside as well. That makes each
patch exact, but the RPCA score is *not* a function of the patches alone: the ALM thresholds the
singular values of the whole block's patch matrix (one Gram matrix per block, ``lam = 1/sqrt(3m)``
from the block size, global stopping rules, and a global refinement threshold), so a tiled RPCA
equals the untiled run only when one tile holds the cloud; with several tiles it is an
approximation whose keep mask agrees on the tested clouds on >= 98 % of the points (the untiled
method itself splits clouds above ``block_size`` = 10^6 points into independent blocks the same
way). Scores are rescaled to the global point spacing before the global threshold.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ._cluster import open_client, require_dask, show_progress, thread_budget
from ._stream import open_source

__all__ = ["TiledResult", "remove_outliers_tiled"]

METHODS = ("rpca", "sor", "radius")
CHUNK = 1_000_000
SAMPLE = 200_000
MAX_HALO_ROUNDS = 6


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


# ----------------------------------------------------------------------------- partition
def _kd_split(sample: np.ndarray, levels: int, lo: np.ndarray, hi: np.ndarray):
    """Heap-ordered split axes/values and the ``2^levels`` leaf boxes of a k-d median split."""
    n_inner = 2**levels - 1
    axis = np.zeros(n_inner, dtype=np.int64)
    value = np.zeros(n_inner)
    boxes = np.zeros((2**levels, 2, 3))

    def rec(node, pts, blo, bhi, depth):
        if depth == levels:
            boxes[node - n_inner] = (blo, bhi)
            return
        ext = (pts.max(axis=0) - pts.min(axis=0)) if len(pts) else (bhi - blo)
        a = int(np.argmax(ext))
        v = float(np.median(pts[:, a])) if len(pts) else 0.5 * (blo[a] + bhi[a])
        axis[node], value[node] = a, v
        left = pts[:, a] < v
        lhi, rlo = bhi.copy(), blo.copy()
        lhi[a] = v
        rlo[a] = v
        rec(2 * node + 1, pts[left], blo, lhi, depth + 1)
        rec(2 * node + 2, pts[~left], rlo, bhi, depth + 1)

    rec(0, sample, lo.astype(float), hi.astype(float), 0)
    return axis, value, boxes


def _leaf_of(xyz: np.ndarray, axis: np.ndarray, value: np.ndarray, levels: int) -> np.ndarray:
    node = np.zeros(xyz.shape[0], dtype=np.int64)
    rows = np.arange(xyz.shape[0])
    for _ in range(levels):
        go_right = xyz[rows, axis[node]] >= value[node]
        node = 2 * node + 1 + go_right
    return node - (2**levels - 1)


# ----------------------------------------------------------------------------- the tile task
def _load(spill: str, t: int) -> tuple[np.ndarray, np.ndarray]:
    base = Path(spill) / f"tile{t:06d}"
    xyz = np.fromfile(f"{base}.xyz", dtype=np.float64).reshape(-1, 3)
    idx = np.fromfile(f"{base}.idx", dtype=np.int64)
    return xyz, idx


def _protrusion(P: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, glo, ghi) -> float:
    """How far the balls ``B(P_i, r_i)`` reach beyond the box ``[lo, hi]`` (sides on the global
    bounding box excepted: no point lies beyond them)."""
    if P.shape[0] == 0:
        return 0.0
    out_lo = np.where(lo > glo, lo - (P - r[:, None]), 0.0)
    out_hi = np.where(hi < ghi, (P + r[:, None]) - hi, 0.0)
    return float(max(out_lo.max(initial=0.0), out_hi.max(initial=0.0), 0.0))


def _region(spill, t, boxes, w, n_tiles):
    core, cidx = _load(spill, t)
    lo, hi = boxes[t, 0] - w, boxes[t, 1] + w
    parts = [core]
    for u in range(n_tiles):
        if u == t or w <= 0:
            continue
        blo, bhi = boxes[u]
        if np.any(blo > hi) or np.any(bhi < lo):
            continue
        xyz, _ = _load(spill, u)
        inside = np.all((xyz >= lo) & (xyz <= hi), axis=1)
        if inside.any():
            parts.append(xyz[inside])
    return core, cidx, np.concatenate(parts) if len(parts) > 1 else core


def tile_task(
    spill: str,
    t: int,
    boxes: np.ndarray,
    gbox: np.ndarray,
    k: int,
    method: str,
    rpca_options: dict,
    n_threads: int | None,
) -> dict:
    """Scores of tile ``t``'s own points (see the module docstring for the halo)."""
    from scipy.spatial import cKDTree

    from .. import outliers

    t0 = time.perf_counter()
    n_tiles = boxes.shape[0]
    glo, ghi = gbox
    lo, hi = boxes[t]
    core, cidx = _load(spill, t)
    m = core.shape[0]
    if m == 0:
        return {"idx": cidx, "scores": np.empty(0), "dmean": np.empty(0), "n_region": 0, "w": 0.0}
    workers = n_threads if n_threads is not None else -1
    kk = min(k, max(m - 1, 1))
    d0, _ = cKDTree(core).query(core, kk + 1, workers=workers)
    w = _protrusion(core, d0[:, -1], lo, hi, glo, ghi) * (1 + 1e-9)
    hops = 2 if method == "rpca" else 1
    for _ in range(MAX_HALO_ROUNDS):
        core, cidx, R = _region(spill, t, boxes, w, n_tiles)
        if R.shape[0] < k + 1:
            raise InvalidInputError(
                f"`k` = {k} neighbours need at least {k + 1} points; the cloud has fewer."
            )
        tree = cKDTree(R)
        d, nb = tree.query(core, k + 1, workers=workers)
        if hops == 1:
            break
        js = np.unique(nb[:, 1:])
        dj, _ = tree.query(R[js], k + 1, workers=workers)
        need = _protrusion(R[js], dj[:, -1], lo, hi, glo, ghi) * (1 + 1e-9)
        if need <= w:
            break
        w = need
    info = {"n_region": int(R.shape[0]), "w": float(w), "dmean": d[:, 1:].mean(axis=1)}
    if method == "radius":
        s = outliers.radius_scores(R, k, workers=workers)[:m]
    elif method == "sor":
        s = info["dmean"]
    else:
        r = outliers.rpca_scores(R, k, workers=workers, on_nonconvergence="ignore", **rpca_options)
        s = r.scores[:m]
        info["spacing"] = float(r.spacing)
    info.update(idx=cidx, scores=np.asarray(s, dtype=np.float64), time_s=time.perf_counter() - t0)
    return info


# ----------------------------------------------------------------------------- the driver
def remove_outliers_tiled(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    tile: int,
    method: str = "rpca",
    k: int = 10,
    threshold: float | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    processes: bool = True,
    chunk: int = CHUNK,
    return_arrays: bool = False,
    progress: bool = False,
    scratch: str | os.PathLike | None = None,
    **rpca_options: Any,
) -> TiledResult:
    """Outlier removal of a cloud too large for memory: streamed, tiled, scored on Dask, written
    streaming (``spectrageo outliers IN OUT --tile N``).

    Parameters
    ----------
    src, dst : path
        Point cloud in, kept points out. Binary PLY, ``.npy`` and LAS/LAZ are streamed (the
        output keeps every PLY property / LAS field and the input's format); other formats are
        read whole.
    tile : int
        Points per tile (>= 2 k); memory per task is about ``(1 + halo) * tile`` points.
    method, k, threshold, **rpca_options
        As :func:`spectrageo.outliers.remove_outliers`; ``sor``/``radius`` give the untiled keep
        mask exactly; ``rpca`` with one tile gives it exactly, with several an approximation
        (module docstring).
    workers, scheduler, processes
        Dask cluster (:func:`spectrageo.distributed.open_client`).
    chunk : int
        Points per streamed read.
    return_arrays : bool
        Also return the ``keep`` mask and ``scores`` (n values each, in memory).
    scratch : path, optional
        Folder for the per-tile spill files (default: beside ``dst``; with a remote scheduler it
        must be on a file system the workers see).
    """
    check_choice(method, "method", METHODS)
    check_positive(tile, "tile", integer=True)
    check_positive(k, "k", integer=True)
    check_positive(chunk, "chunk", integer=True)
    if tile < 2 * k:
        raise InvalidInputError(f"`tile` must be >= 2 k = {2 * k} points; got {tile}.")
    if rpca_options and method != "rpca":
        raise InvalidInputError(f"options {sorted(rpca_options)} apply to method='rpca' only.")
    if threshold is not None:
        check_positive(threshold, "threshold", allow_zero=method == "sor")
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < k + 1:
        raise InvalidInputError(f"`k` = {k} neighbours need at least {k + 1} points; got {n}.")
    # pass 1: bounding box and a stride sample
    stride = max(1, n // SAMPLE)
    glo, ghi = np.full(3, np.inf), np.full(3, -np.inf)
    samples = []
    for a, xyz, _ in source.chunks(chunk):
        if not np.isfinite(xyz).all():
            raise InvalidInputError(
                f"{Path(src).name}: NaN/inf coordinates near row {a}; tiled processing needs "
                "finite points (run without --tile to drop them)."
            )
        glo, ghi = np.minimum(glo, xyz.min(axis=0)), np.maximum(ghi, xyz.max(axis=0))
        first = (-a) % stride
        samples.append(xyz[first::stride])
    levels = max(0, math.ceil(math.log2(max(1.0, n / tile))))
    axis, value, boxes = _kd_split(np.concatenate(samples), levels, glo, ghi)
    boxes[:, 0] = np.maximum(boxes[:, 0], glo)
    boxes[:, 1] = np.minimum(boxes[:, 1], ghi)
    n_tiles = boxes.shape[0]
    parent = Path(scratch) if scratch is not None else Path(dst).resolve().parent
    spill = tempfile.mkdtemp(prefix=f".{Path(dst).name}.tiles-", dir=parent)
    t_read = time.perf_counter() - t_start
    try:
        # pass 2: spill every point to its tile's files
        for a, xyz, _ in source.chunks(chunk):
            leaf = _leaf_of(xyz, axis, value, levels)
            order = np.argsort(leaf, kind="stable")
            counts = np.bincount(leaf, minlength=n_tiles)
            starts = np.concatenate([[0], np.cumsum(counts)])
            rows = np.arange(a, a + xyz.shape[0], dtype=np.int64)
            for t in np.flatnonzero(counts):
                sel = order[starts[t] : starts[t + 1]]
                base = Path(spill) / f"tile{t:06d}"
                with open(f"{base}.xyz", "ab") as fh:
                    fh.write(np.ascontiguousarray(xyz[sel]).tobytes())
                with open(f"{base}.idx", "ab") as fh:
                    fh.write(rows[sel].tobytes())
        for t in range(n_tiles):  # empty tiles: empty files
            for ext in ("xyz", "idx"):
                Path(spill, f"tile{t:06d}.{ext}").touch()
        t_spill = time.perf_counter() - t_start - t_read
        # tiles on Dask
        scores = np.empty(n)
        dmean = np.empty(n)
        tile_of = np.empty(n, dtype=np.int32) if method == "rpca" else None
        spacing = np.empty(n_tiles)
        sizes = np.zeros(n_tiles, dtype=np.int64)
        region = np.zeros(n_tiles, dtype=np.int64)
        with open_client(
            workers=workers,
            scheduler=scheduler,
            processes=processes,
            n_tasks=n_tiles,
            verbose=progress,
        ) as client:
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, scheduler)
            boxes_f = client.scatter(boxes, broadcast=True)
            futs = [
                client.submit(
                    tile_task,
                    spill,
                    t,
                    boxes_f,
                    np.stack([glo, ghi]),
                    k,
                    method,
                    rpca_options,
                    budget,
                    key=f"spectrageo-tile-{t}",
                    pure=False,
                )  # fmt: skip
                for t in range(n_tiles)
            ]
            show_progress(futs, progress)
            distributed = require_dask()
            for fut in distributed.as_completed(futs):
                r = fut.result()
                t = int(fut.key.rsplit("-", 1)[1])
                scores[r["idx"]] = r["scores"]
                dmean[r["idx"]] = r["dmean"]
                if tile_of is not None:
                    tile_of[r["idx"]] = t
                spacing[t] = r.get("spacing", np.nan)
                sizes[t] = r["idx"].size
                region[t] = r["n_region"]
                fut.release()
        t_tiles = time.perf_counter() - t_start - t_read - t_spill
    finally:
        shutil.rmtree(spill, ignore_errors=True)
    from .. import outliers
    from ..outliers.static import RPCA_MIN_TAU

    info: dict[str, Any] = {}
    if method == "rpca":
        if n_tiles > 1:  # scores to units of the global spacing (median of the mean kNN distance)
            h = float(np.median(dmean))
            info["spacing"] = h
            scores *= (spacing / h)[tile_of]
        tau = (
            float(threshold)
            if threshold is not None
            else outliers.auto_threshold(scores, minimum=RPCA_MIN_TAU, rule="density")
        )
        keep = scores < tau
    elif method == "sor":
        sd = float(dmean.std())
        scores = np.zeros_like(dmean) if sd == 0.0 else (dmean - float(dmean.mean())) / sd
        tau = 1.0 if threshold is None else float(threshold)
        keep = scores <= tau
    else:
        tau = 2.0 * float(np.median(scores)) if threshold is None else float(threshold)
        keep = scores <= tau
    n_kept = int(keep.sum())
    # pass 3: write the kept rows
    writer = source.writer(Path(dst), n_kept)
    ok = False
    try:
        for a, _xyz, rows in source.chunks(chunk):
            writer.write(rows[keep[a : a + len(_xyz)]])
        ok = True
    finally:
        writer.close(ok)
    info.update(
        n_workers=n_workers,
        tile_points_max=int(sizes.max()),
        region_points_max=int(region.max()),
        halo_fraction_mean=float(region.sum() / max(sizes.sum(), 1) - 1.0),
        time_read_s=round(t_read, 3),
        time_spill_s=round(t_spill, 3),
        time_tiles_s=round(t_tiles, 3),
        time_total_s=round(time.perf_counter() - t_start, 3),
        streamed=source.kind != "memory",
    )
    return TiledResult(
        n_points=n,
        n_kept=n_kept,
        threshold=tau,
        method=method,
        n_tiles=n_tiles,
        keep=keep if return_arrays else None,
        scores=scores if return_arrays else None,
        info=info,
    )
