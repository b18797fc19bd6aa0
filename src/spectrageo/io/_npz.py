"""``.npz`` archives of animations (``vertices``, ``faces``) and point-cloud sequences (``points``)."""

from __future__ import annotations

import io
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ..geometry.data import MeshAnimation, PointCloud, PointCloudSequence
from ._common import check_alloc, exc_text, read_bytes, write_bytes


def _keys(keys) -> str:
    """Archive member names for a message: printable, one line, at most 10 of them."""
    shown = [k if k.isprintable() else ascii(k) for k in sorted(keys)]
    return ", ".join(shown[:10]) + (f", ... ({len(shown)} in all)" if len(shown) > 10 else "")


#: Zip compression methods the standard library decodes: stored, deflate, bzip2, LZMA.
ZIP_METHODS = {0: "stored", 8: "deflate", 12: "bzip2", 14: "LZMA"}


def npz_array(d, key: str, name: str) -> np.ndarray:
    """Array ``key`` of the archive: the member's compression method and declared size (against
    the memory cap) are checked, the member read (zipfile stops at the declared size and checks
    the CRC), then parsed by :func:`._simple.parse_npy`, which checks the header's shape against
    the bytes."""
    import lzma

    from ._simple import parse_npy

    zf = d.zip
    member = key if key in zf.namelist() else key + ".npy"
    where = f"{name}: cannot read array {key!r}"
    try:
        info = zf.getinfo(member)
        if info.compress_type not in ZIP_METHODS:
            known = ", ".join(f"{k} ({v})" for k, v in ZIP_METHODS.items())
            raise InvalidInputError(
                f"{where}: zip compression method {info.compress_type} is not supported "
                f"(supported: {known})."
            )
        check_alloc(info.file_size, name, f"array {key!r}")
        raw = zf.read(member)
    except InvalidInputError:
        raise
    except (lzma.LZMAError, zlib.error, EOFError) as exc:
        raise InvalidInputError(
            f"{where}: its {ZIP_METHODS[info.compress_type]} data are corrupted or truncated."
        ) from exc
    except (
        ValueError,
        OSError,
        zipfile.BadZipFile,
        KeyError,
        NotImplementedError,
        RuntimeError,
        OverflowError,
    ) as exc:
        raise InvalidInputError(f"{where} ({exc_text(exc)}).") from exc
    return parse_npy(raw, where)


def open_npz(data: bytes, name: str):
    """``np.load`` of the archive bytes ``data`` (a ``NpzFile``), or a clear error."""
    try:
        d = np.load(io.BytesIO(data), allow_pickle=False)
    except (
        ValueError,
        OSError,
        EOFError,
        zipfile.BadZipFile,
        OverflowError,
        KeyError,
        NotImplementedError,  # "zip file version 24.3", unknown compression
        RuntimeError,  # encrypted members
        zlib.error,
    ) as exc:
        why = exc_text(exc)
        if not data.startswith(b"PK") and not data.startswith(b"\x93NUMPY"):
            why = "not a zip archive of .npy arrays"  # numpy would call it pickled data
        raise InvalidInputError(f"{name}: not a valid .npz archive ({why}).") from exc
    if not isinstance(d, np.lib.npyio.NpzFile):
        raise InvalidInputError(f"{name}: not a .npz archive (a single .npy array).")
    return d


def read_npz(p: Path, gz: bool, *, kind: str | None) -> MeshAnimation | PointCloudSequence:
    data = read_bytes(p, gz)
    if not data:
        raise InvalidInputError(f"{p.name}: empty file.")
    name = p.name
    with open_npz(data, name) as d:
        keys = set(d.files)
        if kind in ("mesh", "points"):
            raise InvalidInputError(
                f"{name}: a .npz file holds an animation or a sequence, not a single {kind!r}."
            )
        vkey = "vertices" if "vertices" in keys else "frames" if "frames" in keys else None
        if "faces" in keys or kind == "animation" or (vkey is not None and "points" not in keys):
            if "faces" not in keys and kind != "sequence":
                raise InvalidInputError(
                    f"{name}: animation .npz lacks key 'faces' (has {_keys(keys)})."
                )
            if vkey is None:
                raise InvalidInputError(
                    f"{name}: animation .npz lacks key 'vertices' (has {_keys(keys)})."
                )
            frames = npz_array(d, vkey, name)
            _check_frames(frames, name, vkey)
            if kind == "sequence":
                return PointCloudSequence([PointCloud(f) for f in frames.astype(np.float64)])
            faces = npz_array(d, "faces", name)
            if faces.ndim != 2 or faces.shape[1] != 3:
                raise InvalidInputError(
                    f"{name}: 'faces' must have shape (m, 3); got {faces.shape}."
                )
            if faces.dtype.kind not in "iu":
                raise InvalidInputError(f"{name}: 'faces' must hold integers; got {faces.dtype}.")
            try:
                return MeshAnimation(frames, faces)
            except InvalidInputError as exc:
                raise InvalidInputError(f"{name}: {exc}") from exc
        if "points" in keys:
            pts = npz_array(d, "points", name)
            if pts.ndim == 3:
                _check_frames(pts, name, "points")
                return PointCloudSequence([PointCloud(f) for f in pts.astype(np.float64)])
            if pts.ndim == 2 and "counts" in keys:
                counts = npz_array(d, "counts", name)
                if (
                    counts.ndim != 1
                    or counts.dtype.kind not in "iu"
                    or (counts <= 0).any()
                    or counts.sum() != pts.shape[0]
                    or pts.shape[1] != 3
                ):
                    raise InvalidInputError(
                        f"{name}: 'counts' must be positive integers summing to the {pts.shape[0]} "
                        f"rows of 'points' (n, 3); got counts {counts.shape} summing to "
                        f"{int(counts.sum()) if counts.dtype.kind in 'iu' else '?'}, points {pts.shape}."
                    )
                _check_frames(pts[None], name, "points")
                parts = np.split(pts.astype(np.float64), np.cumsum(counts)[:-1])
                return PointCloudSequence([PointCloud(f) for f in parts])
            raise InvalidInputError(
                f"{name}: 'points' must have shape (T, n, 3), or (N, 3) with 'counts' (T,); got {pts.shape}."
            )
        raise InvalidInputError(
            f"{name}: .npz has keys {_keys(keys) or '(none)'}; expected 'vertices' and "
            "'faces' (animation) or 'points' [+ 'counts'] (sequence)."
        )


def _check_frames(frames: np.ndarray, name: str, key: str) -> None:
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise InvalidInputError(f"{name}: {key!r} must have shape (T, n, 3); got {frames.shape}.")
    if frames.dtype.kind not in "iuf":
        raise InvalidInputError(f"{name}: {key!r} must be numeric; got {frames.dtype}.")
    if frames.shape[0] == 0 or frames.shape[1] == 0:
        raise InvalidInputError(f"{name}: {key!r} is empty; got shape {frames.shape}.")
    if frames.dtype.kind == "f":
        finite = np.isfinite(frames).all(axis=2)
        if not finite.all():
            t, i = np.argwhere(~finite)[0]
            raise InvalidInputError(
                f"{name}: {int((~finite).sum())} vertex positions have NaN or inf coordinates "
                f"(first at frame {t}, vertex {i})."
            )


def write_npz(
    p: Path, geom: MeshAnimation | PointCloudSequence, *, gz: bool, compress: bool
) -> None:
    buf = io.BytesIO()
    save = np.savez_compressed if compress else np.savez
    if isinstance(geom, MeshAnimation):
        save(buf, vertices=geom.frames, faces=geom.faces)
    elif geom.is_fixed_size():
        save(buf, points=geom.as_array())
    else:
        save(
            buf,
            points=np.concatenate([f.points for f in geom.frames]),
            counts=np.asarray(geom.n_points, dtype=np.int64),
        )
    write_bytes(p, buf.getvalue(), gz)
