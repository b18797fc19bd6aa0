"""Helpers shared by the format modules: paths, gzip, atomic writes, polygon fans, frame sorting."""

from __future__ import annotations

import contextlib
import gzip
import os
import re
import shutil
import tempfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError


def split_suffix(path: Path) -> tuple[str, bool]:
    """``(format_suffix, gzipped)`` of ``path``: ``'x.ply.gz' -> ('.ply', True)`` (lower case)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return (suffixes[-2] if len(suffixes) >= 2 else ""), True
    return (suffixes[-1] if suffixes else ""), False


def read_bytes(path: Path, gzipped: bool) -> bytes:
    """Whole content of ``path``, gunzipped when ``gzipped``; errors become InvalidInputError."""
    try:
        raw = path.read_bytes()
    except IsADirectoryError as exc:
        raise InvalidInputError(f"{path.name}: expected a file, got a folder.") from exc
    except FileNotFoundError as exc:
        raise InvalidInputError(f"file not found: {path}") from exc
    if not gzipped:
        return raw
    try:
        return gzip.decompress(raw)
    except (gzip.BadGzipFile, EOFError, zlib.error, OSError) as exc:
        raise InvalidInputError(
            f"{path.name}: corrupted or truncated gzip data ({type(exc).__name__}: {exc})."
        ) from exc


def write_bytes(target: Path, data: bytes, gzipped: bool) -> None:
    """Write ``data`` (gzip-compressed when ``gzipped``) to ``target`` atomically."""
    if gzipped:
        data = gzip.compress(data, compresslevel=6, mtime=0)
    with atomic_write(target) as tmp:
        tmp.write_bytes(data)


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# read once at import: os.umask can only be queried by setting it, which is not thread-safe
_UMASK = _read_umask()


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Context manager for an atomic file write.

    Yields the path of a temporary file in the same folder as ``path`` (same final suffix, so that
    libraries choosing a format from the name still do); when the block exits normally the temporary
    file replaces ``path`` with :func:`os.replace` (atomic on POSIX and Windows). When the block raises,
    the temporary file is removed and ``path`` is left untouched (absent or with its old content).

    Examples
    --------
    >>> with atomic_write("out.npy") as tmp:  # doctest: +SKIP
    ...     np.save(tmp, arr)
    """
    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise InvalidInputError(f"output folder does not exist: {parent}")
    if target.is_dir():
        raise InvalidInputError(f"cannot write {target}: a folder with that name exists.")
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=".tmp" + target.suffix, dir=parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_dir(path: Path) -> Iterator[Path]:
    """Stage a folder's content in a temporary sibling folder and move it to ``path`` on success.

    When ``path`` does not exist, the staged folder is renamed to it (atomic). When it exists, the
    staged files are moved into it one by one with :func:`os.replace` (each atomic). On failure the
    staging folder is removed and ``path`` is untouched.
    """
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InvalidInputError(f"output folder does not exist: {parent}")
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"cannot write frames to {path}: a file with that name exists.")
    stage = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent))
    try:
        yield stage
        if not path.exists():
            os.chmod(stage, 0o777 & ~_UMASK)
            os.replace(stage, path)
        else:
            for f in sorted(stage.iterdir()):
                os.replace(f, path / f.name)
            stage.rmdir()
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


_NUM = re.compile(r"(\d+)")


def natural_key(name: str) -> tuple:
    """Sort key comparing the digit runs of ``name`` as numbers: ``f2 < f10``."""
    parts = _NUM.split(name)
    return tuple((0, int(p), p) if p.isdigit() else (1, 0, p.lower()) for p in parts)


def fan_triangulate(polygons: Any, where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Triangulate polygons as fans ``(v0, vk, vk+1)``, keeping the file's face order.

    Parameters
    ----------
    polygons : (m, k) int array or sequence of int sequences (ragged)
    where : str
        File name for error messages.

    Returns
    -------
    faces : (t, 3) int64
        Triangles; the fan of polygon ``i`` comes right after the fan of polygon ``i - 1``.
    source : (t,) int64 or None
        Index of the polygon each triangle comes from (None when every polygon was a triangle).
    """
    if isinstance(polygons, np.ndarray) and polygons.dtype != object and polygons.ndim == 2:
        arr = polygons
        m, k = arr.shape
        if k == 3:
            return arr.astype(np.int64, copy=False), None
        if k < 3:
            raise InvalidInputError(f"{where}: faces must have at least 3 vertices; got {k}.")
        lens = np.full(m, k, dtype=np.int64)
        flat = arr.reshape(-1).astype(np.int64, copy=False)
    else:
        seq = list(polygons)
        if not seq:
            return np.zeros((0, 3), dtype=np.int64), None
        lens = np.fromiter((len(p) for p in seq), dtype=np.int64, count=len(seq))
        if lens.min() < 3:
            bad = int(np.flatnonzero(lens < 3)[0])
            raise InvalidInputError(
                f"{where}: face {bad} has {int(lens[bad])} vertices; faces need at least 3."
            )
        if (lens == 3).all():
            return np.asarray(seq, dtype=np.int64).reshape(-1, 3), None
        flat = np.concatenate([np.asarray(p, dtype=np.int64).ravel() for p in seq])
    starts = np.cumsum(lens) - lens
    ntri = lens - 2
    source = np.repeat(np.arange(lens.size, dtype=np.int64), ntri)
    k = np.arange(source.size, dtype=np.int64) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    s = starts[source]
    faces = np.stack([flat[s], flat[s + k + 1], flat[s + k + 2]], axis=1)
    return faces, source


def exc_text(exc: BaseException) -> str:
    """``'TypeName: message'`` of a library exception, for wrapping into InvalidInputError."""
    msg = str(exc).strip()
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def text_colors(c: np.ndarray) -> np.ndarray:
    """Colours read from text: integers above 1 mean 0-255 (uint8), otherwise floats in [0, 1]."""
    c = np.asarray(c, dtype=np.float64)
    if c.size and (c == np.round(c)).all() and c.max() > 1.0 and c.min() >= 0 and c.max() <= 255:
        return c.astype(np.uint8)
    return c
