"""Out-of-core point-cloud processing: spatial tiles with halos, one Dask task per tile.

Three methods share one machinery (``docs/scaling.md``): outlier removal
(:func:`remove_outliers_tiled`), point-cloud saliency (:func:`saliency_tiled`) and the robot
pipeline's denoising (:func:`robot_denoise_tiled`).

1. *Stream* the input once (:mod:`._stream`): bounding box, count, and every ``s``-th point as a
   sample. A k-d split of the sample (median along the longest side, ``ceil(log2(n / tile))``
   levels) gives ``2^L`` axis-aligned boxes of at most about ``tile`` points each.
2. *Spill*: stream again and append every point (float64 coordinates and its input row) to its
   box's file in a scratch folder beside the output.
3. *Tiles on Dask* (:func:`_tile_job`): a task loads its box and the points of the other boxes
   within a halo of width ``w`` (only the files of boxes that meet the widened box), runs a
   per-tile function on that region and returns its values for the box's *own* points only
   (scores for outliers and saliency, new positions for denoising). ``w`` is chosen from the
   method's *reach* (below) so that every neighbourhood the own points' values read lies inside
   box + halo.
4. *Global steps* over the gathered values (thresholds, normalisations, global kernel widths),
   then *stream* the input a last time, writing the output rows in input order.

Halo. A method's reach is a list of kNN hops ``(k_1, k_2)``: the value of an own point ``p``
reads its ``k_1`` nearest neighbours and, with a second hop, the ``k_2`` nearest neighbours of
every point of ``{p} + kNN_{k_1}(p)``. The ``k``-th neighbour distance of a point within any
subset of the cloud bounds the true one from above, so the ball with that radius holds its true
``k`` neighbours. First hop: the radii ``r_p`` of the own points among themselves give
``w = max_p`` (protrusion of ``B(p, r_p)`` beyond the box); the region then holds every true
``k_1``-NN of every own point. Second hop: the ``k_2``-NN radii of those neighbours, measured in
that region, bound the true ones again; if their balls stick out further, the region is loaded
once more with the larger ``w`` -- it then holds every point any own value reads, so a per-tile
function that only reads these neighbourhoods gives the untiled values exactly. ``w`` covers the
balls of radius <= 3x the median radius; the few larger balls that stick out further (isolated
outliers, whose kNN balls reach far) are *stragglers*: the points inside them are loaded ball by
ball from the tiles they meet, rather than widening the halo of the whole box to the largest
ball (:func:`_reach`).

Reach and global steps of each method:

* ``outliers`` ``sor``/``radius``: one hop ``(k,)``; exact. The mean/std of SOR and the median of
  the radius rule are taken over all tiles' values after gathering.
* ``outliers`` ``rpca``: two hops ``(k, k)`` (the patches of ``p``'s neighbours enter its
  baseline, step 6 of :func:`spectrageo.outliers.rpca_scores`). That makes each patch exact, but
  the RPCA score is *not* a function of the patches alone: the ALM thresholds the singular values
  of the whole tile's patch matrix (one Gram matrix, ``lam = 1/sqrt(3m)`` from the region size,
  the stopping rules, the spacing and the refinement threshold are the region's). The untiled
  method therefore defines a cloud above ``block_size`` points (default 2^22) as exactly these
  tiles (``partition="tiles"`` of :func:`spectrageo.outliers.rpca_scores`, run in memory by
  :func:`rpca_tiles_in_memory`): the boxes of a k-d split of the same stride sample at
  ``ceil(log2(n / block_size))`` levels, the same halos, one RPCA per region with the own points'
  scores kept. The tiled run splits at ``ceil(log2(n / min(tile, block_size)))`` levels, the same
  whenever ``tile >= block_size`` (or ``tile`` gives the same number of levels), and then
  ``outliers --tile N`` equals the untiled run (bit for bit on the tests); smaller tiles split
  further and give an approximation. Scores are rescaled to the global point spacing (median of
  the own points' mean kNN distance over all tiles) before the global threshold, which is the
  automatic rule of :func:`spectrageo.outliers.remove_outliers` (``"valley"``) over all scores;
  the points flagged as small volumetric clusters (step 8 of
  :func:`spectrageo.outliers.rpca_scores`, per tile: a cluster of at most 150 points lies inside
  its tile's halo unless it straddles the region's outer edge) are removed whatever their score,
  as in the untiled run.
* ``saliency`` (:func:`spectrageo.saliency.pointcloud_saliency`, Eq. 6.30-6.33): ``s_p`` reads the
  normals of ``{p} + kNN_k(p)`` (Eq. 6.30) and each normal is the PCA of its point's
  ``normal_k``-NN (Eq. 6.31): two hops ``(k, normal_k)``; local, so exact. The tiles return the
  norms ``||lambda(C_p)||``; the two global steps -- the value given to degenerate patches (the
  largest finite saliency) and the min-max normalisation (Eq. 6.4) -- run after gathering, on
  all values, exactly as the untiled function does. Agreement: to rounding (<= 1e-12; the
  eigenvalue sums of Eq. 6.32 run over neighbours in index order, which differs between the
  region and the whole cloud).
* ``robot`` (:func:`spectrageo.outliers.robot_pipeline`): (a) RPCA outlier removal with
  ``rpca_k`` -- the ``rpca`` tiles above (equal to the untiled run when ``tile >= block_size``),
  but with the untiled rule after gathering: the automatic threshold rule of
  :func:`spectrageo.outliers.remove_outliers` over all scores, and the points flagged as small
  clusters (per tile) removed whatever their score; (b) per filter pass of :func:`spectrageo.outliers.bilateral_point_filter` (Eq. 5.100-5.101) the new
  ``v_p`` reads the kNN cell ``kNN_k(p)``, the cell-mean normal ``n_p`` (PCA normals of ``p`` and
  of its ``k`` neighbours, each over its own ``k``-NN) and ``sigma2_p`` from the same cell: two
  hops ``(k, k)`` among the kept points. Its global step is the default ``sigma1``, the mean
  kNN distance over the whole kept cloud: a one-hop pass ``(k,)`` gathers every kept point's mean
  distance first (summed in input order, as the untiled run does), then the filter pass runs with
  that ``sigma1``. Each of ``n_iter`` passes re-spills the moved points (tile membership kept,
  boxes grown to the moved points). Given the same keep mask the filtered points equal the untiled
  run to rounding (measured bitwise on the test clouds).
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ..io import atomic_write
from ..outliers.static import DEFAULT_THRESHOLD_RULE
from ._cluster import open_client, require_dask, show_progress, thread_budget
from ._stream import PointSource, open_source

__all__ = [
    "TiledResult",
    "TiledRobotResult",
    "TiledSaliencyResult",
    "remove_outliers_tiled",
    "robot_denoise_tiled",
    "saliency_tiled",
]

METHODS = ("rpca", "sor", "radius")
CHUNK = 1_000_000
SAMPLE = 200_000
SALIENCY_SUFFIXES = (".npy", ".csv", ".ply")


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


@dataclass
class _Tiles:
    """The spilled cloud: tile ``t``'s points are ``spill/tile{t}{tag}.xyz`` (float64) and their
    input rows ``.idx`` (int64); ``boxes`` (T, 2, 3) contain each tile's points, ``gbox`` (2, 3)
    all points."""

    spill: str
    boxes: np.ndarray
    gbox: np.ndarray
    n: int
    tag: str = ""
    time_read_s: float = 0.0
    time_spill_s: float = 0.0

    @property
    def n_tiles(self) -> int:
        return int(self.boxes.shape[0])

    def grow(self, t: int, xyz: np.ndarray) -> None:
        """Grow tile ``t``'s box and the global box to contain ``xyz`` (moved points)."""
        self.boxes[t, 0] = np.minimum(self.boxes[t, 0], xyz.min(axis=0))
        self.boxes[t, 1] = np.maximum(self.boxes[t, 1], xyz.max(axis=0))
        self.gbox[0] = np.minimum(self.gbox[0], self.boxes[t, 0])
        self.gbox[1] = np.maximum(self.gbox[1], self.boxes[t, 1])


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


def _tile_base(spill: str, t: int, tag: str = "") -> Path:
    return Path(spill) / f"tile{t:06d}{tag}"


def _append(spill: str, t: int, tag: str, xyz: np.ndarray, rows: np.ndarray) -> None:
    base = _tile_base(spill, t, tag)
    with open(f"{base}.xyz", "ab") as fh:
        fh.write(np.ascontiguousarray(xyz, dtype=np.float64).tobytes())
    with open(f"{base}.idx", "ab") as fh:
        fh.write(np.ascontiguousarray(rows, dtype=np.int64).tobytes())


def _levels(n: int, tile: int) -> int:
    """Levels of the k-d split: ``2^L`` boxes of at most about ``tile`` points."""
    return max(0, math.ceil(math.log2(max(1.0, n / tile))))


def _plan(sample: np.ndarray, levels: int, glo: np.ndarray, ghi: np.ndarray):
    """Split axes/values and leaf boxes (clipped to the bounding box ``glo .. ghi``)."""
    axis, value, boxes = _kd_split(sample, levels, glo, ghi)
    boxes[:, 0] = np.maximum(boxes[:, 0], glo)
    boxes[:, 1] = np.minimum(boxes[:, 1], ghi)
    return axis, value, boxes


def _rpca_tile(tile: int, rpca_options: dict) -> int:
    """Points per tile of the ``rpca`` passes: at most ``block_size``, so that the tiles are the
    untiled method's (``partition="tiles"`` of :func:`spectrageo.outliers.rpca_scores`)."""
    from ..outliers.rpca import BLOCK_SIZE

    return min(int(tile), int(rpca_options.get("block_size", BLOCK_SIZE)))


class _MemorySpill:
    """The tiles of an in-memory cloud, in place of a spill folder: tile ``t`` is the rows
    ``rows[t]`` (input order) of ``X`` (what :func:`_load` returns for a spill file)."""

    def __init__(self, X: np.ndarray, rows: list[np.ndarray]):
        self.X, self.rows = X, rows

    def load(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        r = self.rows[t]
        return self.X[r], r


def _memory_tiles(X: np.ndarray, tile: int, chunk: int = CHUNK) -> _Tiles:
    """:func:`_partition` of an in-memory (n, 3) float64 cloud: the same sample, boxes and
    membership (rows in input order) as streaming it from a file."""
    from ..outliers._common import column_bounds

    n = X.shape[0]
    stride = max(1, n // SAMPLE)
    glo, ghi = column_bounds(X)
    levels = _levels(n, tile)
    axis, value, boxes = _plan(X[::stride], levels, glo, ghi)
    leaf = np.empty(n, dtype=np.int64)
    for a in range(0, n, chunk):
        leaf[a : a + chunk] = _leaf_of(X[a : a + chunk], axis, value, levels)
    order = np.argsort(leaf, kind="stable")
    counts = np.bincount(leaf, minlength=boxes.shape[0])
    rows = np.split(order, np.cumsum(counts)[:-1])
    return _Tiles(_MemorySpill(X, rows), boxes, np.stack([glo, ghi]), n)  # type: ignore[arg-type]


def _partition(source: PointSource, src, tile: int, chunk: int, spill: str) -> _Tiles:
    """Passes 1 (bounding box, sample, k-d boxes) and 2 (spill every point to its box)."""
    from ..outliers._common import column_bounds

    t0 = time.perf_counter()
    n = source.n
    stride = max(1, n // SAMPLE)
    glo, ghi = np.full(3, np.inf), np.full(3, -np.inf)
    samples = []
    for a, xyz, _ in source.chunks(chunk):
        if not np.isfinite(xyz).all():
            raise InvalidInputError(
                f"{source.path.name}: NaN/inf coordinates near row {a}; tiled processing needs "
                "finite points (run without --tile to drop them)."
            )
        lo_c, hi_c = column_bounds(xyz)
        glo, ghi = np.minimum(glo, lo_c), np.maximum(ghi, hi_c)
        first = (-a) % stride
        samples.append(xyz[first::stride])
    levels = _levels(n, tile)
    axis, value, boxes = _plan(np.concatenate(samples), levels, glo, ghi)
    n_tiles = boxes.shape[0]
    t_read = time.perf_counter() - t0
    for a, xyz, _ in source.chunks(chunk):
        leaf = _leaf_of(xyz, axis, value, levels)
        order = np.argsort(leaf, kind="stable")
        counts = np.bincount(leaf, minlength=n_tiles)
        starts = np.concatenate([[0], np.cumsum(counts)])
        rows = np.arange(a, a + xyz.shape[0], dtype=np.int64)
        for t in np.flatnonzero(counts):
            sel = order[starts[t] : starts[t + 1]]
            _append(spill, int(t), "", xyz[sel], rows[sel])
    for t in range(n_tiles):  # empty tiles: empty files
        for ext in ("xyz", "idx"):
            Path(f"{_tile_base(spill, t)}.{ext}").touch()
    return _Tiles(
        spill,
        boxes,
        np.stack([glo, ghi]),
        n,
        time_read_s=t_read,
        time_spill_s=time.perf_counter() - t0 - t_read,
    )


# ----------------------------------------------------------------------------- the tile task
def _load(spill: str, t: int, tag: str = "") -> tuple[np.ndarray, np.ndarray]:
    if isinstance(spill, _MemorySpill):
        return spill.load(t)
    base = _tile_base(spill, t, tag)
    xyz = np.fromfile(f"{base}.xyz", dtype=np.float64).reshape(-1, 3)
    idx = np.fromfile(f"{base}.idx", dtype=np.int64)
    return xyz, idx


def _protrusion(P: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, glo, ghi):
    """Per point, how far the ball ``B(P_i, r_i)`` reaches beyond the box ``[lo, hi]`` (sides on
    the global bounding box excepted: no point lies beyond them); (n,) >= 0."""
    out = np.zeros(P.shape[0])
    for a in range(3):  # one column at a time (a few 1-D passes instead of (n, 3) temporaries)
        if lo[a] > glo[a]:
            np.maximum(out, lo[a] - (P[:, a] - r), out=out)
        if hi[a] < ghi[a]:
            np.maximum(out, (P[:, a] + r) - hi[a], out=out)
    return out


def _reach(P, r, lo, hi, glo, ghi, w_min: float = 0.0):
    """Halo width ``w`` and the *stragglers* for the balls ``B(P_i, r_i)``: ``w`` covers the balls
    of the regular points (radius <= 3x the median radius), the stragglers (a few points with far
    larger balls, e.g. isolated outliers) are returned as balls ``(centres, radii)`` to load
    one by one, instead of widening the whole halo to the largest ball. Also returns which balls
    stick out of the box at all."""
    r = r * (1 + 1e-9)
    prot = _protrusion(P, r, lo, hi, glo, ghi) * (1 + 1e-9)
    if P.shape[0] == 0:
        return w_min, P[:0], r[:0], prot > 0
    med = float(np.median(r))
    regular = r <= 3.0 * med if med > 0 else np.ones(r.shape, dtype=bool)
    w = max(w_min, float(prot[regular].max(initial=0.0)))
    far = prot > w
    return w, P[far], r[far], prot > 0


def _region(spill, t, boxes, w, n_tiles, tag="", balls=None):
    """Tile ``t``'s own points first, then every other tile's points within ``w`` of its box or
    inside one of the ``balls`` ``(centres (s, 3), radii (s,))``."""
    from scipy.spatial import cKDTree

    core, cidx = _load(spill, t, tag)
    lo, hi = boxes[t, 0] - w, boxes[t, 1] + w
    c, rad = balls if balls is not None else (np.zeros((0, 3)), np.zeros(0))
    parts = [core]
    for u in range(n_tiles):
        if u == t:
            continue
        blo, bhi = boxes[u]
        in_box = w > 0 and not (np.any(blo > hi) or np.any(bhi < lo))
        hit = np.all((c + rad[:, None] >= blo) & (c - rad[:, None] <= bhi), axis=1)
        if not in_box and not hit.any():
            continue
        xyz, _ = _load(spill, u, tag)
        inside = np.all((xyz >= lo) & (xyz <= hi), axis=1) if in_box else np.zeros(len(xyz), bool)
        if hit.any() and len(xyz):
            # candidates: outside the widened box, inside the bounding box of the hitting balls
            ch, rh = c[hit], rad[hit]
            blo_b, bhi_b = (ch - rh[:, None]).min(axis=0), (ch + rh[:, None]).max(axis=0)
            rest = np.flatnonzero(~inside & np.all((xyz >= blo_b) & (xyz <= bhi_b), axis=1))
            if rest.size:
                tree = cKDTree(xyz[rest], balanced_tree=False, compact_nodes=False)
                found = tree.query_ball_point(ch, rh)
                sel = [np.asarray(f, dtype=np.int64) for f in found if len(f)]
                if sel:
                    inside[rest[np.concatenate(sel)]] = True
        if inside.any():
            parts.append(xyz[inside])
    return core, cidx, np.concatenate(parts) if len(parts) > 1 else core


def _own_knn(P: np.ndarray, m: int, k: int, workers, known=None):
    """Exact ``k``-NN (self excluded) of the first ``m`` points of ``P`` among all of ``P``, by the
    compiled grid search of the untiled filters: ``dmean`` and ``dlast`` of the ``m`` points
    (input order) and ``(radii, used)``: a function ``(rows, k2) -> dlast`` of any rows, and one
    giving the sorted rows of the ``m`` points and of all their neighbours.

    ``known``, when given, is ``(dmean, dlast, nbr, n_zero, edge)`` from a search among ``P[:m]``
    (the own points) where every point not flagged in ``edge`` has its whole ``k``-NN ball
    inside the own box, so its neighbours are own points and final; only the ``edge`` points
    are searched again. Also returns ``(sc, nbr, n_zero)``: the sorted cloud of ``P``, the own
    points' neighbours (``(m, k)`` rows of ``P``, nearest first) and how many own points have
    a neighbour at distance 0."""
    from ..outliers._common import SortedCloud, knn_grid, numba_threads

    sc = SortedCloud.of(P)
    pos = np.empty(P.shape[0], dtype=np.int64)
    pos[sc.order] = np.arange(P.shape[0])

    def query(rows: np.ndarray, kk: int):
        # queries in Morton order (3-5x faster than scattered ones); results back in rows' order
        p = pos[rows]
        o = np.argsort(p)
        q = p[o]
        back = np.empty_like(o)
        back[o] = np.arange(o.size)
        with numba_threads(workers):
            nb = knn_grid(sc, kk, query=q, self_index=q)
        return nb, back

    idt = np.int32 if P.shape[0] < 2**31 else np.int64
    if known is None:
        if m == P.shape[0]:  # every point queries: the plain search (as rpca_scores runs it)
            with numba_threads(workers):
                nb = knn_grid(sc, k)
            back = pos
        else:
            nb, back = query(np.arange(m), k)
        dmean, dlast = nb.dmean[back], nb.dlast[back]
        nbr = sc.order[nb.idx[back]].astype(idt)
        n_zero = nb.n_zero
    else:
        dmean, dlast, nbr, n_zero, edge = known
        dmean, dlast, nbr = dmean.copy(), dlast.copy(), nbr.copy()
        rows = np.flatnonzero(edge)
        nb = None
        if rows.size:
            nb, back = query(rows, k)
            dmean[rows], dlast[rows] = nb.dmean[back], nb.dlast[back]
            nbr[rows] = sc.order[nb.idx[back]]

    def radii(rows: np.ndarray, k2: int) -> np.ndarray:
        r, at = query(rows, k2)
        return r.dlast[at]

    def used() -> np.ndarray:
        # (with ``known``, the other points' neighbours are own points, marked already)
        mark = np.zeros(P.shape[0], dtype=bool)
        mark[:m] = True
        if nb is not None:
            mark[sc.order[nb.idx.ravel()]] = True
        return np.flatnonzero(mark)

    return dmean, dlast, (radii, used), (sc, nbr, n_zero)


def _halo_region(spill, t, boxes, gbox, hops, workers, tag=""):
    """Own points, their rows, the region (own points first), ``dmean`` (m,): the mean distance
    of the own points to their ``hops[0]`` nearest region points (self excluded), the halo
    width, with a halo wide enough for the reach ``hops`` (module docstring), and ``knn``: the
    region's sorted cloud, the own points' ``hops[0]`` nearest neighbours (rows of the region)
    and the number of own points with a duplicate (see :func:`_own_knn`). The neighbour
    searches are the compiled exact grid search of the untiled filters."""
    from scipy.spatial import cKDTree

    n_tiles = boxes.shape[0]
    glo, ghi = gbox
    lo, hi = boxes[t]
    k1 = int(hops[0])
    core, cidx = _load(spill, t, tag)
    m = core.shape[0]
    if m == 0:
        return core, cidx, core, np.empty(0), 0.0, None
    known = None
    if m > k1:  # k1-NN radii among the own points
        d0, r0, _, (_, nbr0, nz0) = _own_knn(core, m, k1, workers)
    else:  # too few own points: widen until the region has k1 + 1 points, radii in it
        w = max(float(np.max(ghi - glo)) / 64.0, np.finfo(float).tiny)
        while True:
            _, _, R = _region(spill, t, boxes, w, n_tiles, tag)
            if R.shape[0] > k1 or w > 4.0 * float(np.max(ghi - glo)):
                break
            w *= 2.0
        d0, _ = cKDTree(R).query(core, min(k1 + 1, R.shape[0]), workers=workers)
        r0 = d0.reshape(m, -1)[:, -1]
    w, bc, br, edge = _reach(core, r0, lo, hi, glo, ghi)
    if m > k1:  # balls inside the box hold only own points: those neighbours are final
        known = (d0, r0, nbr0, nz0, edge)
    core, cidx, R = _region(spill, t, boxes, w, n_tiles, tag, (bc, br))
    if R.shape[0] < k1 + 1:
        raise InvalidInputError(
            f"`k` = {k1} neighbours need at least {k1 + 1} points; the cloud has fewer."
        )
    dmean, dlast, (radii, used), knn = _own_knn(R, m, k1, workers, known)
    if len(hops) > 2:  # pragma: no cover - internal: reaches of at most two hops
        raise ValueError("reach of at most two hops")
    if len(hops) == 2:
        k2 = int(hops[1])
        # second hop: the k2-NN balls of the own points and their neighbours, measured in this
        # region (an upper bound of the true radii); reload once if some stick out
        js = used()
        if R.shape[0] < k2 + 1:
            w2, c2, r2 = math.inf, R[:0], np.zeros(0)
        else:
            if k2 == k1:  # the own points' k2-NN radii are their k1-NN radii, known already
                own = js < m
                rj = np.empty(js.size)
                rj[own] = dlast[js[own]]
                rj[~own] = radii(js[~own], k2)
            else:
                rj = radii(js, k2)
            w2, c2, r2, _ = _reach(R[js], rj, lo, hi, glo, ghi, w_min=w)
        if w2 > w or len(r2):
            w = w2
            balls = (np.concatenate([bc, c2]), np.concatenate([br, r2]))
            # the own points' k1-NN were exact already: ``dmean`` stands
            core, cidx, R = _region(spill, t, boxes, w, n_tiles, tag, balls)
            bc, br = balls
            # own points whose neighbours may lie in the halo are searched again in the new R
            knn = _own_knn(R, m, k1, workers, known)[3]
    return core, cidx, R, dmean, float(w), knn


def _tile_job(
    spill: str,
    t: int,
    boxes: np.ndarray,
    gbox: np.ndarray,
    hops: tuple[int, ...],
    fn: Callable[..., dict],
    params: dict,
    n_threads: int | None,
    tag: str = "",
) -> dict:
    """One Dask task: ``fn(R, m, dmean, workers=..., **params)`` on tile ``t``'s region ``R`` (own
    points first, ``m`` of them; ``dmean`` their mean kNN distance), halo from ``hops``.
    ``fn`` returns per-own-point arrays (and scalars); ``idx`` (the own points' input rows),
    ``n_region``, ``w`` and ``time_s`` are added."""
    t0 = time.perf_counter()
    workers = n_threads if n_threads is not None else -1
    core, cidx, R, dmean, w, knn = _halo_region(spill, t, boxes, gbox, hops, workers, tag)
    m = core.shape[0]
    out: dict = {}
    if m:
        kw = {"knn": (*knn, dmean)} if getattr(fn, "takes_knn", False) else {}
        out = fn(R, m, dmean, workers=workers, **kw, **params)
    out.update(
        idx=cidx,
        n_region=int(R.shape[0]) if m else 0,
        w=w,
        time_s=time.perf_counter() - t0,
    )
    return out


def _map_tiles(client, tiles: _Tiles, hops, fn, params, budget, progress, name) -> Iterator:
    """Run ``fn`` on every tile; yields ``(t, result)`` as tasks finish."""
    distributed = require_dask()
    boxes_f = client.scatter(tiles.boxes, broadcast=True, hash=False)
    token = uuid.uuid4().hex[:8]
    futs = [
        client.submit(
            _tile_job,
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


# ----------------------------------------------------------------------------- per-tile functions
def _outlier_fn(R, m, dmean, *, workers, k, method, rpca_options, knn=None) -> dict:
    """Outlier scores of the own points (``dmean``: their mean ``k``-NN distance; ``knn``: the
    region's sorted cloud and the own points' neighbours from the halo search, reused by the
    RPCA's kNN step)."""
    from .. import outliers

    out: dict[str, Any] = {"dmean": np.asarray(dmean, dtype=np.float64)}
    if method == "radius":
        s = outliers.radius_scores(R, k, workers=workers)[:m]
    elif method == "sor":
        s = out["dmean"]
    else:  # one RPCA over the region (no further tiling: it is the untiled method's tile)
        r = outliers.rpca_scores(
            R, k, workers=workers, on_nonconvergence="ignore", partition="blocks",
            _knn=knn, **rpca_options,
        )  # fmt: skip
        s = r.scores[:m]
        out.update(
            spacing=float(r.spacing),
            n_iter=r.n_iter,
            converged=r.converged,
            residual=r.residual,
            n_blocks=r.n_blocks,
            n_refined=r.n_refined,
        )
        if r.clusters is not None:
            out["clusters"] = np.asarray(r.clusters[:m], dtype=bool)
        if r.smoothed is not None:
            out["smoothed"] = r.smoothed[:m]
    out["scores"] = np.asarray(s, dtype=np.float64)
    return out


_outlier_fn.takes_knn = True  # type: ignore[attr-defined]


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


def _dmean_fn(R, m, _dmean, *, workers, k) -> dict:
    """Mean ``k``-NN distance of the own points, as :func:`bilateral_point_filter` measures it."""
    from ..outliers._common import knn_chunked

    nb = knn_chunked(R, k, query=R[:m], self_index=np.arange(m), workers=workers)
    return {"dmean": nb.dmean}


def _bilateral_fn(R, m, _dmean, *, workers, k, sigma1, sigma2) -> dict:
    """One bilateral pass (Eq. 5.100-5.101) with the global ``sigma1``; own points' new positions."""
    from ..outliers.robot import bilateral_point_filter

    Y = bilateral_point_filter(R, k, sigma1=sigma1, sigma2=sigma2, n_iter=1)[:m]
    return {"xyz": Y}


# ----------------------------------------------------------------------------- shared driver steps
def _check_common(tile, chunk, workers, need: int, what: str) -> None:
    check_positive(tile, "tile", integer=True)
    check_positive(chunk, "chunk", integer=True)
    if workers is not None:
        check_positive(workers, "workers", integer=True)
    if tile < need:
        raise InvalidInputError(f"`tile` must be >= {what} = {need} points; got {tile}.")


def _outlier_pass(client, tiles, method, k, rpca_options, budget, progress, stats):
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
    params = {"k": k, "method": method, "rpca_options": rpca_options}
    for t, r in _map_tiles(client, tiles, hops, _outlier_fn, params, budget, progress, "tile"):
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


def _to_global_spacing(scores, dmean, tile_of, spacing) -> float:
    """Scores of the tiles (each in units of its own spacing) to units of the global spacing
    ``h`` (median over all points of the mean kNN distance), in place; returns ``h``."""
    h = float(np.median(dmean))
    if not h > 0:  # the untiled run scores distinct positions; tiles cannot (copies span tiles)
        raise InvalidInputError(
            "more than half of the points are exact copies of others (median kNN distance 0); "
            "tiled RPCA needs distinct points: remove the copies or run without --tile."
        )
    scores *= (spacing / h)[tile_of]
    return h


def rpca_tiles_in_memory(X: np.ndarray, k: int, *, block_size: int, workers: int, **opts: Any):
    """``rpca_scores(X, k, partition="tiles")`` for a cloud above ``block_size`` points: the tiles
    of :func:`remove_outliers_tiled` (same boxes, halos and per-region RPCA), run one after the
    other in this process, scores rescaled to the global spacing (:func:`_to_global_spacing`).
    Returns a :class:`spectrageo.outliers.PatchRPCAResult` (``n_blocks`` = the tiles)."""
    from .._progress import progress
    from ..outliers.rpca import PatchRPCAResult

    n = X.shape[0]
    tiles = _memory_tiles(X, block_size)
    T = tiles.n_tiles
    scores, dmean = np.empty(n), np.empty(n)
    tile_of = np.empty(n, dtype=np.int32)
    spacing = np.full(T, np.nan)
    clusters = np.zeros(n, dtype=bool) if opts.get("clusters", True) else None
    smoothed = np.empty((n, 3)) if opts.get("smoothed", False) else None
    params = {"k": k, "method": "rpca", "rpca_options": dict(opts, block_size=block_size)}
    n_iter, converged, residual, n_refined = 0, True, 0.0, 0
    for t in progress(range(T), desc=f"RPCA outlier scores, {T} tiles", total=T):
        r = _tile_job(tiles.spill, t, tiles.boxes, tiles.gbox, (k, k), _outlier_fn, params, workers)
        rows = r["idx"]
        if rows.size == 0:
            continue
        scores[rows], dmean[rows], tile_of[rows] = r["scores"], r["dmean"], t
        spacing[t] = r["spacing"]
        if clusters is not None and "clusters" in r:
            clusters[rows] = r["clusters"]
        if smoothed is not None:
            smoothed[rows] = r["smoothed"]
        n_iter, converged = max(n_iter, r["n_iter"]), converged and r["converged"]
        residual, n_refined = max(residual, r["residual"]), n_refined + r["n_refined"]
    h = _to_global_spacing(scores, dmean, tile_of, spacing)
    return PatchRPCAResult(
        scores=scores,
        spacing=h,
        smoothed=smoothed,
        n_iter=n_iter,
        converged=converged,
        residual=residual,
        n_blocks=T,
        n_refined=n_refined,
        clusters=clusters,
    )


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
            info["spacing"] = _to_global_spacing(scores, dmean, tile_of, spacing)
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


def _timing(info: dict, tiles: _Tiles, t_start: float, t_tiles: float, source) -> dict:
    info.update(
        time_read_s=round(tiles.time_read_s, 3),
        time_spill_s=round(tiles.time_spill_s, 3),
        time_tiles_s=round(t_tiles, 3),
        time_total_s=round(time.perf_counter() - t_start, 3),
        streamed=source.kind != "memory",
    )
    return info


# ----------------------------------------------------------------------------- outliers
def remove_outliers_tiled(
    src: Any,
    dst: str | os.PathLike | None,
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
    src : path or array
        Point cloud in. Binary PLY, ``.npy`` and LAS/LAZ are streamed (the output keeps every
        PLY property / LAS field and the input's format); other formats are read whole. An
        ``(n, 3+)`` numpy array or ``dask.array`` (for instance ``dask.array.from_zarr`` of a
        cloud larger than memory) is read one chunk of rows at a time, once per pass; its kept
        rows are written as ``.npy``.
    dst : path or None
        Kept points out (written atomically, streaming). None writes nothing and returns the
        ``keep`` mask and ``scores`` (``return_arrays`` implied).
    tile : int
        Points per tile (>= 2 k); memory per task is about ``(1 + halo) * tile`` points. With
        ``rpca``, tiles hold at most ``block_size`` points (default 2^22).
    method, k, threshold, **rpca_options
        As :func:`spectrageo.outliers.remove_outliers`; ``sor``/``radius`` give the untiled keep
        mask exactly; so does ``rpca`` when ``tile >= block_size`` (tiles are then cut at
        ``block_size`` points, the untiled method's own tiles); smaller tiles give an
        approximation (module docstring).
    workers, scheduler, processes
        Dask cluster (:func:`spectrageo.distributed.open_client`).
    chunk : int
        Points per streamed read.
    return_arrays : bool
        Also return the ``keep`` mask and ``scores`` (n values each, in memory).
    scratch : path, optional
        Folder for the per-tile spill files (default: beside ``dst``, or the temporary folder
        when ``dst`` is None; with a remote scheduler it
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
    if "partition" in rpca_options:
        raise InvalidInputError("`partition` does not apply to tiled runs (they are the tiles).")
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
    if method == "rpca":
        tile = _rpca_tile(tile, rpca_options)
    with _scratch_dir(dst, scratch) as spill:
        tiles = _partition(source, src, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        t0 = time.perf_counter()
        with open_client(
            workers=workers, scheduler=scheduler, processes=processes,
            n_tasks=tiles.n_tiles, verbose=progress,
        ) as client:  # fmt: skip
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, scheduler)
            scores, dmean, tile_of, spacing, blob = _outlier_pass(
                client, tiles, method, k, rpca_options, budget, progress, stats
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


# ----------------------------------------------------------------------------- saliency
def saliency_tiled(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    tile: int,
    k: int = 20,
    normal_k: int = 10,
    normalize: bool = True,
    workers: int | None = None,
    scheduler: str | None = None,
    processes: bool = True,
    chunk: int = CHUNK,
    return_values: bool = False,
    progress: bool = False,
    scratch: str | os.PathLike | None = None,
) -> TiledSaliencyResult:
    """Point-cloud saliency (Eq. 6.30-6.33) of a cloud too large for memory: streamed, tiled,
    computed on Dask, written streaming (``spectrageo saliency IN --out OUT --tile N``).

    Equals :func:`spectrageo.saliency.pointcloud_saliency` to rounding (reach ``(k, normal_k)``;
    the degenerate-patch value and the min-max normalisation run over all gathered values; module
    docstring).

    Parameters
    ----------
    src : path
        Point cloud: binary PLY, ``.npy``, LAS/LAZ streamed; other formats read whole.
    dst : path
        ``.npy`` ((n,) float64), ``.csv`` (one value per line) or ``.ply`` (the input's vertex
        properties -- only x, y, z when the input is not a PLY -- with ``saliency`` (double) and
        jet colours ``red/green/blue`` replacing any input colours), rows in input order.
    tile : int
        Points per tile (>= 2 (max(k, normal_k) + 1)).
    k, normal_k, normalize
        As :func:`spectrageo.saliency.pointcloud_saliency`.
    workers, scheduler, processes, chunk
        As :func:`remove_outliers_tiled`.
    return_values : bool
        Also return the (n,) values in memory.
    progress, scratch
        As :func:`remove_outliers_tiled`.
    """
    from ..saliency._common import check_int

    k = check_int(k, "k", minimum=2)
    normal_k = check_int(normal_k, "normal_k", minimum=2)
    need = 2 * (max(k, normal_k) + 1)
    _check_common(tile, chunk, workers, need, "2 (max(k, normal_k) + 1)")
    suf = _value_suffix(dst)
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < k + 1:
        raise InvalidInputError(f"`k` = {k} neighbours need at least {k + 1} points; got {n}.")
    with _scratch_dir(dst, scratch) as spill:
        tiles = _partition(source, src, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        vals = np.memmap(Path(spill) / "values.f8", dtype=np.float64, mode="w+", shape=(n,))
        t0 = time.perf_counter()
        with open_client(
            workers=workers, scheduler=scheduler, processes=processes,
            n_tasks=tiles.n_tiles, verbose=progress,
        ) as client:  # fmt: skip
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, scheduler)
            params = {"k": k, "normal_k": normal_k}
            for t, r in _map_tiles(
                client, tiles, (k, normal_k), _saliency_fn, params, budget, progress, "saliency"
            ):
                stats.add(t, r)
                if r["idx"].size:
                    vals[r["idx"]] = r["norm"]
        t_tiles = time.perf_counter() - t0
        lo, hi = _saliency_globals(vals, chunk, normalize)
        _write_values(source, Path(dst), suf, vals, chunk, lo, hi)
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


_PLY_NAMES = {
    "i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort",
    "i4": "int", "u4": "uint", "f4": "float", "f8": "double",
}  # fmt: skip


def _ply_header(dtype: np.dtype, n: int) -> bytes:
    props = "".join(f"property {_PLY_NAMES[dtype[name].str[1:]]} {name}\n" for name in dtype.names)
    return f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n{props}end_header\n".encode(
        "ascii"
    )


def _write_values(source, dst: Path, suf: str, vals, chunk: int, lo: float, hi: float) -> None:
    """Stream the values (input order) to ``.npy``, ``.csv`` or ``.ply`` (module docstring of
    :func:`saliency_tiled`), atomically."""
    from .._colormap import jet
    from ._stream import _RawWriter

    n = vals.shape[0]
    if suf == ".npy":
        with atomic_write(dst) as tmp:
            out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float64, shape=(n,))
            for a in range(0, n, chunk):
                out[a : a + chunk] = vals[a : a + chunk]
            out.flush()
            del out
        return
    if suf == ".csv":
        with atomic_write(dst) as tmp, open(tmp, "wb") as fh:
            for a in range(0, n, chunk):
                np.savetxt(fh, np.asarray(vals[a : a + chunk])[:, None], fmt="%.9g")
        return
    drop = {"red", "green", "blue", "alpha", "saliency"}
    in_dtype = source.dtype if source.kind == "ply" else None
    base = (
        [(f, in_dtype[f].newbyteorder("<")) for f in in_dtype.names if f not in drop]
        if in_dtype is not None
        else [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    )
    dtype = np.dtype(base + [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("saliency", "<f8")])
    writer = _RawWriter(dst, _ply_header(dtype, n))
    ok = False
    try:
        for a, xyz, rows in source.chunks(chunk):
            s = np.asarray(vals[a : a + xyz.shape[0]])
            rec = np.empty(xyz.shape[0], dtype=dtype)
            if in_dtype is not None:
                for f, _ in base:
                    rec[f] = rows[f]
            else:
                rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            rgb = jet(s, vmin=lo, vmax=hi)
            rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
            rec["saliency"] = s
            writer.write(rec)
        ok = True
    finally:
        writer.close(ok)


# ----------------------------------------------------------------------------- robot denoising
def robot_denoise_tiled(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    tile: int,
    k: int = 7,
    threshold: float | None = None,
    rpca_k: int = 10,
    sigma1: float | None = None,
    sigma2: float | None = None,
    n_iter: int = 1,
    outlier_removal: bool = True,
    workers: int | None = None,
    scheduler: str | None = None,
    processes: bool = True,
    chunk: int = CHUNK,
    return_arrays: bool = False,
    progress: bool = False,
    scratch: str | os.PathLike | None = None,
) -> TiledRobotResult:
    """The robot pipeline's cloud output (Section 5.4.2) for a cloud too large for memory: RPCA
    outlier removal and bilateral filtering (Eq. 5.100-5.101) in tiles on Dask, written streaming
    (``spectrageo robot IN OUT --tile N``).

    As :func:`spectrageo.outliers.robot_pipeline` with ``output="cloud"``: the RPCA step is the
    tiled ``rpca`` of :func:`remove_outliers_tiled` (tiles of at most ``min(tile, 2^22)`` points,
    the untiled run's own, so the keep mask equals the untiled one when ``tile >= block_size``;
    with smaller tiles it is an approximation); given its keep mask, the
    filter equals the untiled one to rounding (reach ``(k, k)`` per pass, the global default
    ``sigma1`` gathered first; module docstring).

    Parameters
    ----------
    src, dst : path
        Point cloud in, filtered kept points out, in input order. Binary PLY (every property
        kept; x, y, z written as double), ``.npy`` (float64) and LAS/LAZ (coordinates quantised
        to the file's scale) are streamed; other formats are read whole.
    tile : int
        Points per tile (>= 2 (max(k, rpca_k) + 1)); at most 2^22 (the RPCA step's tiles).
    k, threshold, rpca_k, sigma1, sigma2, n_iter
        As :func:`spectrageo.outliers.robot_pipeline`.
    outlier_removal : bool
        False: skip the RPCA step and filter every point (then equal to
        :func:`spectrageo.outliers.bilateral_point_filter` to rounding); ``keep`` is all True,
        ``scores`` None and ``threshold`` NaN.
    workers, scheduler, processes, chunk
        As :func:`remove_outliers_tiled`.
    return_arrays : bool
        Also return ``keep``, ``scores`` (n each) and the filtered ``points`` (n_kept, 3).
    progress, scratch
        As :func:`remove_outliers_tiled`.
    """
    check_positive(k, "k", integer=True)
    check_positive(rpca_k, "rpca_k", integer=True)
    check_positive(n_iter, "n_iter", integer=True)
    for name, v in (("sigma1", sigma1), ("sigma2", sigma2)):
        if v is not None:
            check_positive(v, name)
    if threshold is not None:
        check_positive(threshold, "threshold")
    need = 2 * (max(k, rpca_k) + 1)
    _check_common(tile, chunk, workers, need, "2 (max(k, rpca_k) + 1)")
    require_dask()
    t_start = time.perf_counter()
    source = open_source(src)
    n = source.n
    if n < rpca_k + 1:
        raise InvalidInputError(
            f"`rpca_k` = {rpca_k} neighbours need at least {rpca_k + 1} points; got {n}."
        )
    _check_same_format(source, dst)
    tile = _rpca_tile(tile, {})  # the RPCA step's tiles: those of the untiled run
    with _scratch_dir(dst, scratch) as spill:
        tiles = _partition(source, src, tile, chunk, spill)
        stats = _Stats(tiles.n_tiles)
        t0 = time.perf_counter()
        sigmas = []
        with open_client(
            workers=workers, scheduler=scheduler, processes=processes,
            n_tasks=tiles.n_tiles, verbose=progress,
        ) as client:  # fmt: skip
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, scheduler)
            if outlier_removal:
                scores, dmean, tile_of, spacing, blob = _outlier_pass(
                    client, tiles, "rpca", rpca_k, {}, budget, progress, stats
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
                        client, cur, (k,), _dmean_fn, {"k": k}, budget, progress, "dmean"
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
                    client, cur, (k, k), _bilateral_fn, params, budget, progress, "bilateral"
                ):  # each tile's moved points go straight to the next pass's files
                    stats.add(t, r)
                    if r["idx"].size:
                        _append(spill, t, nxt.tag, r["xyz"], r["idx"])
                        nxt.grow(t, r["xyz"])
                _drop(cur)
                cur = nxt
            del dm
        t_tiles = time.perf_counter() - t0
        pos = np.memmap(Path(spill) / "pos.f8", dtype=np.float64, mode="w+", shape=(n, 3))
        for t in range(cur.n_tiles):
            xyz, idx = _load(spill, t, cur.tag)
            pos[idx] = xyz
        _write_moved(source, Path(dst), keep, pos, n_kept, chunk)
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


def _respill(tiles: _Tiles, tag: str, select) -> _Tiles:
    """A new point set with the same tiles: each tile's points filtered by ``select(xyz, idx)``
    (boxes and global box kept: they still contain the points), or empty files when ``select``
    is None."""
    for t in range(tiles.n_tiles):
        for ext in ("xyz", "idx"):
            Path(f"{_tile_base(tiles.spill, t, tag)}.{ext}").write_bytes(b"")
        if select is None:
            continue
        xyz, idx = _load(tiles.spill, t, tiles.tag)
        sel = select(xyz, idx)
        if sel.any():
            _append(tiles.spill, t, tag, xyz[sel], idx[sel])
    return _Tiles(tiles.spill, tiles.boxes.copy(), tiles.gbox.copy(), tiles.n, tag=tag)


def _drop(tiles: _Tiles) -> None:
    for t in range(tiles.n_tiles):
        for ext in ("xyz", "idx"):
            Path(f"{_tile_base(tiles.spill, t, tiles.tag)}.{ext}").unlink(missing_ok=True)


def _write_moved(source, dst: Path, keep, pos, n_kept: int, chunk: int) -> None:
    """Stream the kept rows with new coordinates ``pos`` (input order), atomically."""
    if source.kind == "memory":
        from .. import io
        from ..geometry import PointCloud

        c = source.cloud.select(keep)
        io.write(dst, PointCloud(np.asarray(pos)[keep], c.normals, c.colors, dict(c.attributes)))
        return
    if source.kind == "ply":
        from ._stream import _RawWriter

        dtype = np.dtype(
            [
                (
                    f,
                    source.dtype[f].newbyteorder("<")
                    if f not in ("x", "y", "z")
                    else np.dtype("<f8"),
                )
                for f in source.dtype.names
            ]
        )
        writer: Any = _RawWriter(dst, _ply_header(dtype, n_kept))
    elif source.kind == "npy":
        from ._stream import _NpyWriter

        dtype = np.result_type(source.arr.dtype, np.float64)
        writer = _NpyWriter(dst, (n_kept, source.arr.shape[1]), dtype)
    else:
        writer = source.writer(dst, n_kept)
    ok = False
    try:
        for a, xyz, rows in source.chunks(chunk):
            kc = keep[a : a + xyz.shape[0]]
            new = np.asarray(pos[a : a + xyz.shape[0]])[kc]
            rows = rows[kc]
            if source.kind == "ply":
                rec = np.empty(len(rows), dtype=dtype)
                for f in dtype.names:
                    rec[f] = rows[f]
                rec["x"], rec["y"], rec["z"] = new[:, 0], new[:, 1], new[:, 2]
                rows = rec
            elif source.kind == "npy":
                rows = rows.astype(dtype)
                rows[:, :3] = new
            else:  # LAS/LAZ: scaled integer coordinates
                rows.x, rows.y, rows.z = new[:, 0], new[:, 1], new[:, 2]
            writer.write(rows)
        ok = True
    finally:
        writer.close(ok)
