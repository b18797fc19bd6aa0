"""Chunked point readers and streaming writers for the tiled (out-of-core) outlier removal.

Streamed: binary PLY point clouds (memory-mapped vertex records, every property kept), ``.npy``
``(n, 3+)`` arrays (memory-mapped) and LAS/LAZ (laspy chunk iterator; needs ``spectrageo[las]``).
Other readable formats are read whole through :func:`spectrageo.io.read_point_cloud` (not
out-of-core) and written through :func:`spectrageo.io.write`. In the Python API an ``(n, 3+)``
numpy array or ``dask.array`` is a source too (a dask array is computed one chunk of rows at a
time, once per pass; kept rows are written as ``.npy``).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ..io import atomic_write

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


class PointSource:
    """A point cloud read in chunks: ``n`` points, ``chunks(size)`` yields ``(start, xyz, rows)``
    (``xyz`` (m, 3) float64, ``rows`` the records to write back for kept points)."""

    kind = "memory"

    def __init__(self, path: Path, n: int):
        self.path, self.n = path, n

    def chunks(self, size: int) -> Iterator[tuple[int, np.ndarray, Any]]:  # pragma: no cover
        raise NotImplementedError

    def writer(self, path: Path, n_kept: int):  # pragma: no cover
        raise NotImplementedError


class _PlySource(PointSource):
    kind = "ply"

    def __init__(self, path: Path, header: bytes, dtype: np.dtype, n: int):
        super().__init__(path, n)
        self.header, self.dtype = header, dtype
        self.rec = np.memmap(path, dtype=dtype, mode="r", offset=len(header), shape=(n,))

    def chunks(self, size):
        for a in range(0, self.n, size):
            r = np.asarray(self.rec[a : a + size])
            xyz = np.stack([r["x"], r["y"], r["z"]], axis=1).astype(np.float64)
            yield a, xyz, r

    def writer(self, path, n_kept):
        text = self.header.decode("ascii")
        lines = [
            f"element vertex {n_kept}" if ln.startswith("element vertex ") else ln
            for ln in text.split("\n")
        ]
        return _RawWriter(path, "\n".join(lines).encode("ascii"))


class _RawWriter:
    def __init__(self, path, header: bytes):
        self.cm = atomic_write(path)
        self.fh = open(self.cm.__enter__(), "wb")  # noqa: SIM115 - closed in close()
        self.fh.write(header)

    def write(self, rows):
        self.fh.write(np.ascontiguousarray(rows).tobytes())

    def close(self, ok=True):
        self.fh.close()
        if ok:
            self.cm.__exit__(None, None, None)
        else:
            self.cm.__exit__(RuntimeError, RuntimeError("aborted"), None)


class _NpySource(PointSource):
    kind = "npy"

    def __init__(self, path: Path):
        self.arr = np.load(path, mmap_mode="r")
        if self.arr.ndim != 2 or self.arr.shape[1] < 3:
            raise InvalidInputError(f"{path.name}: expected an (n, 3) array; got {self.arr.shape}.")
        super().__init__(path, int(self.arr.shape[0]))

    def chunks(self, size):
        for a in range(0, self.n, size):
            r = np.asarray(self.arr[a : a + size])
            yield a, r[:, :3].astype(np.float64), r

    def writer(self, path, n_kept):
        return _NpyWriter(path, (n_kept, self.arr.shape[1]), self.arr.dtype)


class _NpyWriter:
    def __init__(self, path, shape, dtype):
        self.cm = atomic_write(path)
        tmp = self.cm.__enter__()
        self.out = np.lib.format.open_memmap(tmp, mode="w+", dtype=dtype, shape=shape)
        self.pos = 0

    def write(self, rows):
        self.out[self.pos : self.pos + len(rows)] = rows
        self.pos += len(rows)

    def close(self, ok=True):
        self.out.flush()
        del self.out
        self.cm.__exit__(None, None, None) if ok else self.cm.__exit__(
            RuntimeError, RuntimeError("aborted"), None
        )


class _LasSource(PointSource):
    kind = "las"

    def __init__(self, path: Path):
        try:
            import laspy
        except ImportError as exc:
            raise InvalidInputError(
                f"{path.name}: LAS/LAZ needs laspy: pip install 'spectrageo[las]'."
            ) from exc
        self.laspy = laspy
        with laspy.open(path) as f:
            self.header = copy.deepcopy(f.header)
            n = int(f.header.point_count)
        super().__init__(path, n)

    def chunks(self, size):
        with self.laspy.open(self.path) as f:
            a = 0
            for pts in f.chunk_iterator(size):
                xyz = np.stack(
                    [np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)], axis=1
                ).astype(np.float64)
                yield a, xyz, pts
                a += len(xyz)

    def writer(self, path, n_kept):
        return _LasWriter(self.laspy, path, self.header)


class _LasWriter:
    def __init__(self, laspy, path, header):
        self.cm = atomic_write(path)
        tmp = self.cm.__enter__()
        hdr = copy.deepcopy(header)
        hdr.point_count = 0
        self.w = laspy.open(
            tmp, mode="w", header=hdr, do_compress=str(path).lower().endswith(".laz")
        )

    def write(self, rows):
        if len(rows):
            self.w.write_points(rows)

    def close(self, ok=True):
        self.w.close()
        self.cm.__exit__(None, None, None) if ok else self.cm.__exit__(
            RuntimeError, RuntimeError("aborted"), None
        )


class _MemorySource(PointSource):
    """Any other readable format, read whole (not out-of-core)."""

    def __init__(self, path: Path):
        from .. import io

        self.cloud = io.read_point_cloud(path)
        super().__init__(path, self.cloud.n_points)

    def chunks(self, size):
        P = self.cloud.points
        for a in range(0, self.n, size):
            yield (
                a,
                np.asarray(P[a : a + size], dtype=np.float64),
                np.arange(a, min(a + size, self.n)),
            )

    def writer(self, path, n_kept):
        return _MemoryWriter(path, self.cloud)


class _MemoryWriter:
    def __init__(self, path, cloud):
        self.path, self.cloud, self.rows = path, cloud, []

    def write(self, rows):
        self.rows.append(rows)

    def close(self, ok=True):
        if ok:
            from .. import io

            keep = np.zeros(self.cloud.n_points, dtype=bool)
            if self.rows:
                keep[np.concatenate(self.rows)] = True
            io.write(self.path, self.cloud.select(keep))


class _ArraySource(PointSource):
    """An (n, 3+) array in memory or a ``dask.array`` (computed chunk by chunk, once per pass)."""

    kind = "array"

    def __init__(self, arr: Any):
        shape = tuple(getattr(arr, "shape", ()))
        if len(shape) != 2 or shape[1] < 3:
            raise InvalidInputError(f"points: expected an (n, 3) array; got shape {shape}.")
        if not np.issubdtype(np.dtype(arr.dtype), np.number):
            raise InvalidInputError(f"points: expected numbers; got dtype {arr.dtype}.")
        self.arr = arr
        super().__init__(Path("points"), int(shape[0]))

    def chunks(self, size):
        for a in range(0, self.n, size):
            r = np.asarray(self.arr[a : a + size])
            yield a, r[:, :3].astype(np.float64), r

    def writer(self, path, n_kept):
        if not Path(path).name.lower().endswith(".npy"):
            raise InvalidInputError(
                f"{Path(path).name}: the kept points of an array are written as .npy."
            )
        return _NpyWriter(path, (n_kept, int(self.arr.shape[1])), np.dtype(self.arr.dtype))


def open_source(path: Any) -> PointSource:
    """The chunked reader of ``path`` (see the module docstring for what is streamed); an (n, 3+)
    array (numpy, or ``dask.array`` read chunk by chunk) is taken as it is."""
    if hasattr(path, "shape") and hasattr(path, "dtype"):
        return _ArraySource(path)
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(2, "No such file or directory", str(p))
    low = p.name.lower()
    if low.endswith(".npy"):
        return _NpySource(p)
    if low.endswith((".las", ".laz")):
        return _LasSource(p)
    if low.endswith(".ply"):
        src = _ply_source(p)
        if src is not None:
            return src
    return _MemorySource(p)


def _ply_source(p: Path) -> PointSource | None:
    """Memory-mapped binary PLY point cloud, or None (ASCII, faces, lists: read whole)."""
    with open(p, "rb") as fh:
        head = fh.read(65536)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    nl = head.find(b"\n", end)
    header = head[: nl + 1]
    lines = header.decode("ascii", "replace").splitlines()
    fmt, n, fields, current, other = None, 0, [], None, False
    for ln in lines:
        t = ln.split()
        if not t:
            continue
        if t[0] == "format":
            fmt = t[1]
        elif t[0] == "element":
            current = t[1]
            if current == "vertex":
                n = int(t[2])
            elif int(t[2]) > 0:
                other = True
        elif t[0] == "property" and current == "vertex":
            if t[1] == "list" or t[1] not in _PLY_TYPES:
                return None
            fields.append((t[2], _PLY_TYPES[t[1]]))
    if other:
        raise InvalidInputError(
            f"{p.name} has faces; tiled outlier removal takes point clouds (run without --tile)."
        )
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        return None
    names = [f for f, _ in fields]
    if not {"x", "y", "z"} <= set(names):
        return None
    bo = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(f, bo + t) for f, t in fields])
    if p.stat().st_size < len(header) + n * dtype.itemsize:
        raise InvalidInputError(f"{p.name}: file shorter than its header says ({n} vertices).")
    return _PlySource(p, header, dtype, n)


def select_rows(rows: Any, keep: np.ndarray) -> Any:
    """The kept records of a chunk (numpy records, laspy points or indices)."""
    return rows[keep]
