"""Streaming writers of the tiled point-cloud commands (``spectrageo.distributed``): rows read
again chunk by chunk from a *source* (``n``, ``kind``, ``chunks(size)`` yielding ``(start, xyz,
rows)``, and per kind ``dtype``, ``arr``, ``cloud`` or ``writer(path, n)``), written atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .._colormap import jet
from ._common import atomic_write

__all__ = ["ply_header", "write_moved", "write_values"]

_PLY_NAMES = {
    "i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort",
    "i4": "int", "u4": "uint", "f4": "float", "f8": "double",
}  # fmt: skip


def ply_header(dtype: np.dtype, n: int) -> bytes:
    """Header of a binary little-endian PLY file of ``n`` vertex records of ``dtype``."""
    props = "".join(f"property {_PLY_NAMES[dtype[name].str[1:]]} {name}\n" for name in dtype.names)
    return f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n{props}end_header\n".encode(
        "ascii"
    )


def write_values(
    source: Any, dst: Path, suf: str, vals: Any, chunk: int, lo: float, hi: float
) -> None:
    """Per-point values ``vals`` (n,) (input order) to ``.npy`` ((n,) float64), ``.csv`` (one value
    per line) or ``.ply`` (the source's vertex properties, only x, y, z when it is not a PLY, with
    ``saliency`` (double) and jet colours over ``[lo, hi]`` replacing any colours)."""
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
    with atomic_write(dst) as tmp, open(tmp, "wb") as fh:
        fh.write(ply_header(dtype, n))
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
            fh.write(np.ascontiguousarray(rec).tobytes())


def write_moved(source: Any, dst: Path, keep: Any, pos: Any, n_kept: int, chunk: int) -> None:
    """The kept rows (``keep`` (n,) bool) of the source with new coordinates ``pos`` (n, 3), input
    order, in the source's format (PLY: every property, x, y, z as double; npy: float64 or wider;
    LAS/LAZ: scaled integer coordinates)."""
    if source.kind == "memory":
        from ..geometry import PointCloud
        from . import write

        c = source.cloud.select(keep)
        write(dst, PointCloud(np.asarray(pos)[keep], c.normals, c.colors, dict(c.attributes)))
        return
    if source.kind == "ply":
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
        with atomic_write(dst) as tmp, open(tmp, "wb") as fh:
            fh.write(ply_header(dtype, n_kept))
            for rows in _moved_rows(source, keep, pos, chunk):
                rec = np.empty(len(rows[0]), dtype=dtype)
                for f in dtype.names:
                    rec[f] = rows[0][f]
                new = rows[1]
                rec["x"], rec["y"], rec["z"] = new[:, 0], new[:, 1], new[:, 2]
                fh.write(np.ascontiguousarray(rec).tobytes())
        return
    if source.kind == "npy":
        dtype = np.result_type(source.arr.dtype, np.float64)
        with atomic_write(dst) as tmp:
            out = np.lib.format.open_memmap(
                tmp, mode="w+", dtype=dtype, shape=(n_kept, source.arr.shape[1])
            )
            at = 0
            for rows, new in _moved_rows(source, keep, pos, chunk):
                rows = rows.astype(dtype)
                rows[:, :3] = new
                out[at : at + len(rows)] = rows
                at += len(rows)
            out.flush()
            del out
        return
    writer = source.writer(dst, n_kept)
    ok = False
    try:
        for rows, new in _moved_rows(source, keep, pos, chunk):
            rows.x, rows.y, rows.z = new[:, 0], new[:, 1], new[:, 2]  # LAS/LAZ: scaled integers
            writer.write(rows)
        ok = True
    finally:
        writer.close(ok)


def _moved_rows(source: Any, keep: Any, pos: Any, chunk: int):
    """``(rows, new_xyz)`` of the kept rows of each chunk."""
    for a, xyz, rows in source.chunks(chunk):
        kc = keep[a : a + xyz.shape[0]]
        yield rows[kc], np.asarray(pos[a : a + xyz.shape[0]])[kc]
