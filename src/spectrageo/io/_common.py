"""Helpers shared by the format modules: paths, gzip, atomic writes, polygon fans, frame sorting,
and the memory cap that every reader applies to the sizes a file declares.

The cap (:func:`max_bytes`) is the environment variable ``SPECTRAGEO_MAX_BYTES`` (bytes, or with
a suffix ``K M G T``); by default the smallest of 8 GiB, half the physical memory and a quarter
of the address-space limit. A file whose decoding would exceed it is refused with
:class:`~spectrageo.InvalidInputError` naming the file, the field and the value.
"""

from __future__ import annotations

import contextlib
import contextvars
import gzip
import os
import re
import shutil
import stat
import tempfile
import time
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError

MAX_BYTES_ENV = "SPECTRAGEO_MAX_BYTES"
_DEFAULT_MAX = 8 * 1024**3
_UNITS = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}


def _default_max_bytes() -> int:
    cap = _DEFAULT_MAX
    try:
        phys = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        if phys > 0:
            cap = min(cap, phys // 2)
    except (ValueError, OSError, AttributeError):
        pass
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
            cap = min(cap, soft // 4)
    except (ImportError, ValueError, OSError):
        pass
    return int(cap)


_LOWERED: contextvars.ContextVar[tuple[int, str] | None] = contextvars.ContextVar(
    "spectrageo_lowered_cap", default=None
)


@contextlib.contextmanager
def lowered_cap(nbytes: int, advice: str) -> Iterator[None]:
    """In the block (this thread), :func:`max_bytes` is at most ``nbytes``; refusals then give
    ``advice`` instead of ``SPECTRAGEO_MAX_BYTES``."""
    token = _LOWERED.set((int(nbytes), advice))
    try:
        yield
    finally:
        _LOWERED.reset(token)


def _cap_advice() -> str:
    low = _LOWERED.get()
    if low is not None and low[0] < _env_max_bytes():
        return low[1]
    return f"set {MAX_BYTES_ENV} to raise it"


def max_bytes() -> int:
    """Memory cap (bytes) for what one file may ask to allocate (see the module docstring), at
    most the one of an enclosing :func:`lowered_cap`.

    Raises
    ------
    InvalidInputError
        When ``SPECTRAGEO_MAX_BYTES`` is set but is not a positive size.
    """
    low = _LOWERED.get()
    cap = _env_max_bytes()
    return cap if low is None else min(cap, low[0])


def _env_max_bytes() -> int:
    text = os.environ.get(MAX_BYTES_ENV, "").strip()
    if not text:
        return _default_max_bytes()
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMGT]?)(?:i?B)?", text, flags=re.IGNORECASE)
    if m is None or float(m.group(1)) <= 0:
        raise InvalidInputError(
            f"environment variable {MAX_BYTES_ENV} must be a positive size in bytes "
            f"(e.g. 8G, 500M, 1000000); got {text!r}."
        )
    return int(float(m.group(1)) * _UNITS[m.group(2).upper()])


def _fmt_bytes(n: int) -> str:
    for unit, k in (("TiB", 1024**4), ("GiB", 1024**3), ("MiB", 1024**2), ("KiB", 1024)):
        if n >= k:
            return f"{n / k:.1f} {unit}"
    return f"{n} bytes"


def check_alloc(need: int, name: str, what: str) -> None:
    """Refuse to allocate ``need`` bytes (an exact Python int) for ``what`` beyond :func:`max_bytes`."""
    cap = max_bytes()
    if need > cap:
        raise InvalidInputError(
            f"{name}: {what} needs {_fmt_bytes(need)}, more than the memory cap of "
            f"{_fmt_bytes(cap)} ({_cap_advice()})."
        )


def check_count(value: Any, name: str, field: str, *, minimum: int = 0) -> int:
    """A count read from a header as a Python int >= ``minimum`` (error names the field)."""
    try:
        v = int(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InvalidInputError(f"{name}: {field} must be an integer; got {value!r}.") from exc
    if v < minimum:
        raise InvalidInputError(f"{name}: {field} must be >= {minimum}; got {v}.")
    return v


def split_suffix(path: Path) -> tuple[str, bool]:
    """``(format_suffix, gzipped)`` of ``path``: ``'x.ply.gz' -> ('.ply', True)`` (lower case)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return (suffixes[-2] if len(suffixes) >= 2 else ""), True
    return (suffixes[-1] if suffixes else ""), False


def read_bytes(path: Path, gzipped: bool) -> bytes:
    """Whole content of ``path``, gunzipped when ``gzipped`` in a bounded stream (16 MiB chunks, stopping
    beyond :func:`max_bytes`; concatenated members read as one); errors become InvalidInputError.
    """
    try:
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            if stat.S_ISDIR(st.st_mode):
                raise InvalidInputError(f"{path.name}: expected a file, got a folder.")
            raise InvalidInputError(f"{path.name}: not a regular file (a pipe or device).")
        check_alloc(st.st_size, path.name, "reading the file")
        raw = path.read_bytes()
    except IsADirectoryError as exc:
        raise InvalidInputError(f"{path.name}: expected a file, got a folder.") from exc
    except FileNotFoundError as exc:
        raise InvalidInputError(f"file not found: {path}") from exc
    if not gzipped:
        return raw
    return gunzip(raw, path.name)


_GZ_CHUNK = 16 * 1024**2


def gunzip(raw: bytes, name: str) -> bytes:
    """Inflate gzip ``raw`` (one or more members) with the output bounded by :func:`max_bytes`."""
    cap = max_bytes()
    parts: list[bytes] = []
    total = 0
    data = memoryview(raw)
    try:
        if len(raw) < 2 or raw[:2] != b"\x1f\x8b":
            raise InvalidInputError(f"{name}: corrupted or truncated gzip data (not a gzip file).")
        while True:
            d = zlib.decompressobj(16 + zlib.MAX_WBITS)
            buf = data
            while True:
                out = d.decompress(buf, _GZ_CHUNK)
                total += len(out)
                if total > cap:
                    raise InvalidInputError(
                        f"{name}: gzip data expands to more than the memory cap of "
                        f"{_fmt_bytes(cap)} ({_cap_advice()})."
                    )
                parts.append(out)
                if d.eof:
                    break
                buf = d.unconsumed_tail
                if not buf and not out:
                    out = d.flush(_GZ_CHUNK)
                    total += len(out)
                    parts.append(out)
                    if not d.eof:
                        raise InvalidInputError(
                            f"{name}: corrupted or truncated gzip data (the stream ends early)."
                        )
            rest = d.unused_data
            if not rest.strip(b"\x00"):
                break
            if rest[:2] != b"\x1f\x8b":
                raise InvalidInputError(
                    f"{name}: corrupted gzip data ({len(rest)} bytes of trailing garbage)."
                )
            data = memoryview(rest)
    except zlib.error as exc:
        raise InvalidInputError(
            f"{name}: corrupted or truncated gzip data ({type(exc).__name__}: {exc})."
        ) from exc
    return b"".join(parts)


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


TMP_TAG = ".spectrageo-tmp-"
STALE_SECONDS = 3600.0


def _remove_stale_temporaries(parent: Path, name: str) -> None:
    """Remove ``.NAME.spectrageo-tmp-*`` left next to ``NAME`` by a killed write (older than 1 h)."""
    prefix = f".{name}{TMP_TAG}"
    now = time.time()
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return
    for e in entries:
        if not e.name.startswith(prefix):
            continue
        try:
            st = e.stat(follow_symlinks=False)
            if now - st.st_mtime < STALE_SECONDS:
                continue
            if stat.S_ISDIR(st.st_mode):
                shutil.rmtree(e.path, ignore_errors=True)
            elif stat.S_ISREG(st.st_mode):
                os.unlink(e.path)
        except OSError:
            continue


def _resolve_target(path: str | os.PathLike) -> tuple[Path, os.stat_result | None]:
    """The file an atomic write replaces: symlinks are followed (the link is kept and its target
    gets the new content); FIFOs, devices and sockets are refused, as are read-only files."""
    target = Path(path)
    if target.is_symlink():
        resolved = Path(os.path.realpath(target))
        if resolved.is_dir():
            raise InvalidInputError(
                f"cannot write {target}: it is a link to a folder ({resolved})."
            )
        target = resolved
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise InvalidInputError(f"output folder does not exist: {parent}")
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return target, None
    except OSError as exc:
        raise InvalidInputError(f"cannot write {target}: {exc.strerror or exc}.") from exc
    if stat.S_ISDIR(st.st_mode):
        raise InvalidInputError(f"cannot write {target}: a folder with that name exists.")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(st.st_mode) else "not a regular file"
        raise InvalidInputError(
            f"cannot write {target}: it is {kind}; refusing to replace it with a regular file."
        )
    if not (st.st_mode & 0o222) or not os.access(target, os.W_OK):
        raise InvalidInputError(
            f"cannot write {target}: the file is read-only (mode "
            f"{stat.S_IMODE(st.st_mode):o}); make it writable or choose another name."
        )
    return target, st


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike) -> Iterator[Path]:
    """Context manager for an atomic file write.

    Yields a temporary ``.NAME.spectrageo-tmp-XXXXXXXX.SUFFIX`` next to ``path`` that replaces it
    with :func:`os.replace` when the block exits normally; when it raises, the temporary is removed
    and ``path`` left untouched. An existing target keeps its permission bits; a symbolic link is
    written through; a FIFO, device, socket or read-only target is refused with
    :class:`InvalidInputError`; temporaries of killed writes older than an hour are removed first.

    Examples
    --------
    >>> with atomic_write("out.npy") as tmp:  # doctest: +SKIP
    ...     np.save(tmp, arr)
    """
    target, st = _resolve_target(path)
    parent = target.parent if str(target.parent) else Path(".")
    _remove_stale_temporaries(parent, target.name)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{target.name}{TMP_TAG}", suffix=target.suffix, dir=parent
        )
    except OSError as exc:  # a read-only or special folder (/proc, a full disk...)
        raise InvalidInputError(
            f"cannot write {target}: the folder {parent} does not accept new files "
            f"({exc.strerror or exc})."
        ) from exc
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~_UMASK)
        try:
            os.replace(tmp, target)
        except OSError as exc:
            raise InvalidInputError(f"cannot write {target}: {exc.strerror or exc}.") from exc
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_dir(path: Path) -> Iterator[Path]:
    """Stage a folder's content in a temporary sibling ``.NAME.spectrageo-tmp-XXXXXXXX`` and move it
    to ``path`` on success (a rename, or one :func:`os.replace` per file into an existing folder);
    on failure ``path`` is untouched. Stale staging folders older than an hour are removed first.
    """
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InvalidInputError(f"output folder does not exist: {parent}")
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"cannot write frames to {path}: a file with that name exists.")
    _remove_stale_temporaries(parent, path.name)
    stage = Path(tempfile.mkdtemp(prefix=f".{path.name}{TMP_TAG}", dir=parent))
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


_I64 = np.iinfo(np.int64)


def _check_int64(a: np.ndarray, where: str) -> None:
    """Face indices must be representable as int64 (unsigned or float values beyond it would wrap
    to a negative index)."""
    if a.size == 0 or a.dtype.kind not in "uf" or (a.dtype.kind == "u" and a.dtype.itemsize < 8):
        return
    lo, hi = a.min(), a.max()
    if hi > _I64.max or lo < _I64.min or (a.dtype.kind == "f" and not np.isfinite([lo, hi]).all()):
        bad = hi if hi > _I64.max or not np.isfinite(hi) else lo
        text = str(int(bad)) if a.dtype.kind == "u" else f"{float(bad):.17g}"
        raise InvalidInputError(f"{where}: face vertex index {text} is out of range.")


def fan_triangulate(polygons: Any, where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Triangulate polygons as fans ``(v0, vk, vk+1)`` in the file's face order.

    ``polygons``: (m, k) int array or ragged sequences; ``where``: file name for messages. Returns
    ``(faces (t, 3) int64, source)``, ``source`` (t,) the polygon of each triangle, or None when
    every polygon was a triangle.
    """
    if isinstance(polygons, np.ndarray) and polygons.dtype != object and polygons.ndim == 2:
        arr = polygons
        _check_int64(arr, where)
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
        for p in seq:
            _check_int64(np.asarray(p), where)
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


@contextlib.contextmanager
def quiet_trimesh() -> Iterator[None]:
    """Keep trimesh's log records (tracebacks of input it recovers from) off stderr in the block."""
    import logging

    log = logging.getLogger("trimesh")
    sink = logging.NullHandler()
    before = log.propagate
    log.addHandler(sink)
    log.propagate = False
    try:
        yield
    finally:
        log.propagate = before
        log.removeHandler(sink)
