"""k-d tiles of a point cloud: the partition, the spill files and in-memory tiles.

A median k-d split of a stride sample (``ceil(log2(n / tile))`` levels) gives ``2^L`` boxes of
about ``tile`` points (:func:`plan`); a streamed cloud is spilled to one file per box
(:func:`partition`), a cloud in memory keeps the rows of each box (:func:`memory_tiles`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ._common import column_bounds

__all__ = ["Tiles", "load", "memory_tiles", "partition"]

#: Points per streamed read.
CHUNK = 1_000_000
#: Size of the stride sample the k-d split is computed on.
SAMPLE = 200_000


def kd_split(sample: np.ndarray, levels: int, lo: np.ndarray, hi: np.ndarray):
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


def leaf_of(xyz: np.ndarray, axis: np.ndarray, value: np.ndarray, levels: int) -> np.ndarray:
    node = np.zeros(xyz.shape[0], dtype=np.int64)
    rows = np.arange(xyz.shape[0])
    for _ in range(levels):
        go_right = xyz[rows, axis[node]] >= value[node]
        node = 2 * node + 1 + go_right
    return node - (2**levels - 1)


@dataclass
class Tiles:
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


def tile_base(spill: str, t: int, tag: str = "") -> Path:
    return Path(spill) / f"tile{t:06d}{tag}"


def append(spill: str, t: int, tag: str, xyz: np.ndarray, rows: np.ndarray) -> None:
    base = tile_base(spill, t, tag)
    with open(f"{base}.xyz", "ab") as fh:
        fh.write(np.ascontiguousarray(xyz, dtype=np.float64).tobytes())
    with open(f"{base}.idx", "ab") as fh:
        fh.write(np.ascontiguousarray(rows, dtype=np.int64).tobytes())


def levels_for(n: int, tile: int) -> int:
    """Levels of the k-d split: ``2^L`` boxes of at most about ``tile`` points."""
    return max(0, math.ceil(math.log2(max(1.0, n / tile))))


def plan(sample: np.ndarray, levels: int, glo: np.ndarray, ghi: np.ndarray):
    """Split axes/values and leaf boxes (clipped to the bounding box ``glo .. ghi``)."""
    axis, value, boxes = kd_split(sample, levels, glo, ghi)
    boxes[:, 0] = np.maximum(boxes[:, 0], glo)
    boxes[:, 1] = np.minimum(boxes[:, 1], ghi)
    return axis, value, boxes


class MemorySpill:
    """The tiles of an in-memory cloud, in place of a spill folder: tile ``t`` is the rows
    ``rows[t]`` (input order) of ``X`` (what :func:`load` returns for a spill file)."""

    def __init__(self, X: np.ndarray, rows: list[np.ndarray]):
        self.X, self.rows = X, rows

    def load(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        r = self.rows[t]
        return self.X[r], r


def memory_tiles(X: np.ndarray, tile: int, chunk: int = CHUNK) -> Tiles:
    """:func:`partition` of an in-memory (n, 3) float64 cloud: the same sample, boxes and
    membership (rows in input order) as streaming it from a file."""
    n = X.shape[0]
    stride = max(1, n // SAMPLE)
    glo, ghi = column_bounds(X)
    levels = levels_for(n, tile)
    axis, value, boxes = plan(X[::stride], levels, glo, ghi)
    leaf = np.empty(n, dtype=np.int64)
    for a in range(0, n, chunk):
        leaf[a : a + chunk] = leaf_of(X[a : a + chunk], axis, value, levels)
    order = np.argsort(leaf, kind="stable")
    counts = np.bincount(leaf, minlength=boxes.shape[0])
    rows = np.split(order, np.cumsum(counts)[:-1])
    return Tiles(MemorySpill(X, rows), boxes, np.stack([glo, ghi]), n)  # type: ignore[arg-type]


def partition(source: Any, tile: int, chunk: int, spill: str) -> Tiles:
    """Passes 1 (bounding box, sample, k-d boxes) and 2 (spill every point to its box)."""
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
    levels = levels_for(n, tile)
    axis, value, boxes = plan(np.concatenate(samples), levels, glo, ghi)
    n_tiles = boxes.shape[0]
    t_read = time.perf_counter() - t0
    for a, xyz, _ in source.chunks(chunk):
        leaf = leaf_of(xyz, axis, value, levels)
        order = np.argsort(leaf, kind="stable")
        counts = np.bincount(leaf, minlength=n_tiles)
        starts = np.concatenate([[0], np.cumsum(counts)])
        rows = np.arange(a, a + xyz.shape[0], dtype=np.int64)
        for t in np.flatnonzero(counts):
            sel = order[starts[t] : starts[t + 1]]
            append(spill, int(t), "", xyz[sel], rows[sel])
    for t in range(n_tiles):  # empty tiles: empty files
        for ext in ("xyz", "idx"):
            Path(f"{tile_base(spill, t)}.{ext}").touch()
    return Tiles(
        spill,
        boxes,
        np.stack([glo, ghi]),
        n,
        time_read_s=t_read,
        time_spill_s=time.perf_counter() - t0 - t_read,
    )


def load(spill: str, t: int, tag: str = "") -> tuple[np.ndarray, np.ndarray]:
    if isinstance(spill, MemorySpill):
        return spill.load(t)
    base = tile_base(spill, t, tag)
    xyz = np.fromfile(f"{base}.xyz", dtype=np.float64).reshape(-1, 3)
    idx = np.fromfile(f"{base}.idx", dtype=np.int64)
    return xyz, idx
