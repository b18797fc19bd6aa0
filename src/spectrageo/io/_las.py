"""LAS / LAZ point clouds through :mod:`laspy` (LAZ needs the ``lazrs`` backend); optional extra.

Reading: scaled ``x y z`` -> points; ``red green blue`` -> uint8 colours (shifted by 8 bits when a
value exceeds 255, else kept: 8-bit values in 16-bit fields); extra-bytes ``normal_x normal_y
normal_z`` -> normals; the standard dimensions (intensity, returns, classification, scan angle,
user data, point source id, gps time) and other extra-bytes dimensions -> attributes.

Writing: LAS 1.2, point format 0-3; int32 coordinates with offset = minimum and scale
``10**ceil(log10(extent / 2e9))`` or ``las_scale``; colours 16-bit (x 257); normals and other
attributes as extra-bytes dimensions (``name_0 ... name_k-1`` for (n, k)).

Hostile input: :func:`check_las` parses the public header before any byte reaches laspy or
lazrs, and checks every declared size against the bytes present and the memory cap: version,
header size, point offset, VLRs and EVLRs, point format and record length, counts (1.4: the
legacy count 0 or equal), finite non-zero scales. LAS records must all be present with no whole
record beyond the count; LAZ needs a well-formed ``laszip encoded`` VLR and a chunk table inside
the file whose chunks match the point count and the compressed bytes, so a damaged table cannot
make lazrs allocate gigabytes (a process abort, not an exception), and no point beyond the count
(layered chunks state theirs; arithmetic-coded ones must need every byte for their points).
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import struct
import sys
import tempfile

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ._common import check_alloc, exc_text
from ._raw import RawGeometry

_STANDARD = (
    "intensity",
    "return_number",
    "number_of_returns",
    "classification",
    "scan_angle_rank",
    "scan_angle",
    "user_data",
    "point_source_id",
    "gps_time",
)


def _laspy(compressed: bool):
    try:
        import laspy
    except ImportError as exc:
        raise UnsupportedFormatError(
            "LAS/LAZ support needs the optional dependency laspy "
            "(pip install 'spectrageo[las]', which also installs lazrs for .laz)."
        ) from exc
    if compressed and not laspy.LazBackend.detect_available():
        raise UnsupportedFormatError(
            "LAZ support needs a LAZ backend for laspy: pip install lazrs (or 'spectrageo[las]')."
        )
    return laspy


# point data format -> minimum record length (LAS 1.4 R15, table of point data record formats)
_POINT_SIZES = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
_MIN_HEADER = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
_VLR_HEADER = 54
_EVLR_HEADER = 60
_LASZIP_USER = b"laszip encoded"
_LASZIP_RECORD = 22204


class LasLayout:
    """What :func:`check_las` found in the header (all sizes in bytes, counts as Python ints)."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def _u(raw: bytes, fmt: str, off: int):
    return struct.unpack_from("<" + fmt, raw, off)[0]


def check_las(raw: bytes, name: str, *, compressed: bool) -> LasLayout:
    """Parse and check the LAS/LAZ header of ``raw`` (rules in the module docstring); the header's
    point format, not ``compressed``, decides how the body is checked.

    Raises
    ------
    InvalidInputError
        Naming the file, the field and its value.
    """
    size = len(raw)
    if size < 4 or raw[:4] != b"LASF":
        raise InvalidInputError(f"{name}: not a LAS/LAZ file (no 'LASF' signature).")
    if size < 227:
        raise InvalidInputError(
            f"{name}: truncated LAS header ({size} bytes; a LAS header has at least 227)."
        )
    major, minor = raw[24], raw[25]
    if major != 1 or minor not in _MIN_HEADER:
        raise InvalidInputError(
            f"{name}: LAS version field {major}.{minor} is not supported (1.0 to 1.4)."
        )
    hsize = _u(raw, "H", 94)
    off = _u(raw, "I", 96)
    n_vlrs = _u(raw, "I", 100)
    fmt_id = raw[104]
    rec_len = _u(raw, "H", 105)
    legacy = _u(raw, "I", 107)
    if hsize < _MIN_HEADER[minor] or hsize > size:
        raise InvalidInputError(
            f"{name}: LAS header size {hsize} is invalid for version 1.{minor} (at least "
            f"{_MIN_HEADER[minor]}, at most the file size {size})."
        )
    if off < hsize or off > size:
        raise InvalidInputError(
            f"{name}: LAS offset to point data {off} is outside the file (header size {hsize}, "
            f"file size {size})."
        )
    # VLRs: each at least 54 bytes, all between the header and the point data
    if n_vlrs * _VLR_HEADER > off - hsize:
        raise InvalidInputError(
            f"{name}: LAS header declares {n_vlrs} VLRs, but only {off - hsize} bytes lie between "
            f"the header and the point data (a VLR needs at least {_VLR_HEADER})."
        )
    pos = hsize
    laszip = None
    for i in range(n_vlrs):
        rl = _u(raw, "H", pos + 20)
        if pos + _VLR_HEADER + rl > off:
            raise InvalidInputError(
                f"{name}: LAS VLR {i} (record length {rl}) runs past the offset to point data "
                f"{off}."
            )
        if raw[pos + 2 : pos + 18].rstrip(b"\0") == _LASZIP_USER and (
            _u(raw, "H", pos + 18) == _LASZIP_RECORD
        ):
            laszip = bytes(raw[pos + _VLR_HEADER : pos + _VLR_HEADER + rl])
        pos += _VLR_HEADER + rl
    is_compressed = bool(fmt_id & 0xC0)
    fmt = fmt_id & 0x3F
    if fmt not in _POINT_SIZES:
        raise InvalidInputError(f"{name}: LAS point data format {fmt_id} is not supported (0-10).")
    if rec_len < _POINT_SIZES[fmt]:
        raise InvalidInputError(
            f"{name}: LAS point record length {rec_len} is shorter than the {_POINT_SIZES[fmt]} "
            f"bytes of point format {fmt}."
        )
    if minor >= 4:
        n = _u(raw, "Q", 247)
        if legacy not in (0, n):
            raise InvalidInputError(
                f"{name}: LAS legacy point count {legacy} differs from the point count {n}."
            )
    else:
        n = legacy
    for axis, k in zip("xyz", range(3)):
        sc, of = _u(raw, "d", 131 + 8 * k), _u(raw, "d", 155 + 8 * k)
        if not math.isfinite(sc) or sc == 0.0:
            raise InvalidInputError(
                f"{name}: LAS {axis} scale factor is {sc!r}; it must be a finite non-zero number "
                "(a scale of 0 collapses every point)."
            )
        if not math.isfinite(of):
            raise InvalidInputError(f"{name}: LAS {axis} offset is {of!r}; it must be finite.")
    check_alloc(n * (2 * rec_len + 80), name, f"{n} LAS points of {rec_len} bytes")
    # EVLRs (1.4): bounded by the file, walked so that laspy's loop over them is bounded too
    evlr_start = n_evlrs = 0
    if minor >= 4:
        evlr_start, n_evlrs = _u(raw, "Q", 235), _u(raw, "I", 243)
        if n_evlrs:
            if evlr_start < off or evlr_start + n_evlrs * _EVLR_HEADER > size:
                raise InvalidInputError(
                    f"{name}: LAS header declares {n_evlrs} EVLRs starting at {evlr_start}, "
                    f"outside the file ({size} bytes; the point data start at {off})."
                )
            epos = evlr_start
            for i in range(n_evlrs):
                if epos + _EVLR_HEADER > size:
                    raise InvalidInputError(f"{name}: LAS EVLR {i} runs past the end of the file.")
                epos += _EVLR_HEADER + _u(raw, "Q", epos + 20)
                if epos > size:
                    raise InvalidInputError(f"{name}: LAS EVLR {i} runs past the end of the file.")
    layout = LasLayout(
        minor=minor, n=n, offset=off, record_length=rec_len, point_format=fmt, laszip=laszip
    )
    if not is_compressed:
        end = off + n * rec_len
        limit = size
        if n_evlrs and evlr_start >= off:
            limit = min(limit, evlr_start)
        if minor >= 3:
            wave = _u(raw, "Q", 227)
            if off < wave < limit:
                limit = wave
        if end > limit:
            have = max(limit - off, 0) // rec_len
            raise InvalidInputError(
                f"{name}: truncated LAS: the header declares {n} points of {rec_len} bytes, the "
                f"file holds {have} (point data of {max(limit - off, 0)} bytes at offset {off})."
            )
        extra = (limit - end) // rec_len
        if extra:
            raise InvalidInputError(
                f"{name}: LAS header declares {n} points, but the file holds {n + extra} whole "
                f"point records of {rec_len} bytes (header point count too small?)."
            )
        return layout
    _laspy(True)  # the header decides, whatever the extension says
    _check_laz_chunks(raw, name, layout)
    return layout


def _check_laz_chunks(raw: bytes, name: str, lay: LasLayout) -> None:
    size, off, n = len(raw), lay.offset, lay.n
    vlr = lay.laszip
    if vlr is None or len(vlr) < 34:
        raise InvalidInputError(
            f"{name}: LAZ file without a valid 'laszip encoded' VLR (record 22204)."
        )
    chunk_size = _u(vlr, "I", 12)
    n_items = _u(vlr, "H", 32)
    if len(vlr) != 34 + 6 * n_items:
        raise InvalidInputError(
            f"{name}: LAZ 'laszip encoded' VLR of {len(vlr)} bytes does not match its "
            f"{n_items} items."
        )
    item_bytes = sum(_u(vlr, "H", 34 + 6 * i + 2) for i in range(n_items))
    if item_bytes != lay.record_length:
        raise InvalidInputError(
            f"{name}: LAZ items describe {item_bytes}-byte points, the header's point record "
            f"length is {lay.record_length}."
        )
    if chunk_size == 0:
        raise InvalidInputError(f"{name}: LAZ chunk size 0 in the 'laszip encoded' VLR.")
    if chunk_size != 0xFFFFFFFF:  # lazrs sizes a buffer for a whole chunk, whatever n is
        check_alloc(chunk_size * lay.record_length, name, f"a LAZ chunk of {chunk_size} points")
    if n == 0:
        cto = _u(raw, "q", off) if off + 8 <= size else -1
        if off + 8 <= cto <= size - 8 and _u(raw, "I", cto + 4):
            raise InvalidInputError(
                f"{name}: LAZ header declares 0 points, but its chunk table lists "
                f"{_u(raw, 'I', cto + 4)} chunks of compressed points (header point count wrong?)."
            )
        return
    if off + 8 > size:
        raise InvalidInputError(f"{name}: truncated LAZ: no chunk table offset after the header.")
    cto = _u(raw, "q", off)
    if cto == -1 and size >= 8:  # writer could not seek back: the offset is at the end
        cto = _u(raw, "q", size - 8)
    if not off + 8 <= cto <= size - 8:
        raise InvalidInputError(
            f"{name}: LAZ chunk table offset {cto} is outside the compressed data "
            f"({off + 8}..{size - 8}); the file is truncated or corrupted."
        )
    version, n_chunks = _u(raw, "I", cto), _u(raw, "I", cto + 4)
    variable = chunk_size == 0xFFFFFFFF
    expected = None if variable else -(-n // chunk_size)
    if (
        version != 0
        or n_chunks == 0
        or n_chunks > cto - off - 8
        or (expected is not None and n_chunks != expected)
        or (variable and n_chunks > n)
    ):
        want = f"{expected}" if expected is not None else f"1..{min(n, cto - off - 8)}"
        raise InvalidInputError(
            f"{name}: LAZ chunk table at {cto} declares {n_chunks} chunks (version {version}); "
            f"{n} points in chunks of {'variable size' if variable else chunk_size} need {want}. "
            "The file is truncated or corrupted."
        )
    import lazrs

    try:
        src = io.BytesIO(raw)
        src.seek(off)
        table = lazrs.read_chunk_table(src, lazrs.LazVlr(vlr))
    except (lazrs.LazrsError, ValueError, OSError, RuntimeError) as exc:
        raise InvalidInputError(f"{name}: corrupted LAZ chunk table ({exc_text(exc)}).") from exc
    total_bytes = sum(int(b) for _, b in table)
    total_points = sum(int(p) for p, _ in table)
    if len(table) != n_chunks or total_bytes != cto - off - 8:
        raise InvalidInputError(
            f"{name}: LAZ chunk table lists {len(table)} chunks of {total_bytes} bytes in all; the "
            f"compressed points occupy {cto - off - 8} bytes. The file is corrupted."
        )
    if variable and total_points != n:
        raise InvalidInputError(
            f"{name}: LAZ header declares {n} points, the chunk table {total_points}."
        )
    items = [_u(vlr, "H", 34 + 6 * i) for i in range(n_items)]
    items_sz = [_u(vlr, "H", 34 + 6 * i + 2) for i in range(n_items)]
    items_v = [_u(vlr, "H", 34 + 6 * i + 4) for i in range(n_items)]
    counts = [int(p) for p, _ in table]
    if not variable:
        counts = [chunk_size] * (n_chunks - 1) + [n - (n_chunks - 1) * chunk_size]
    if any(v >= 3 and t in _LAYERS for t, v in zip(items, items_v)):
        n_layers = sum(
            (sz if t == 14 else _LAYERS[t]) for t, sz in zip(items, items_sz) if t in _LAYERS
        )
        _check_layers(raw, name, off + 8, table, lay, n_layers, counts)
    else:
        _check_last_chunk(raw, name, lay, table, counts, cto)


class _Hidden(io.RawIOBase):
    """``raw`` as a stream that ends at ``limit`` for reads starting before ``resume``."""

    def __init__(self, raw: bytes, limit: int, resume: int):
        self.raw, self.limit, self.resume, self.pos = raw, limit, resume, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def tell(self) -> int:
        return self.pos

    def seek(self, pos: int, whence: int = 0) -> int:
        base = (0, self.pos, len(self.raw))[whence]
        self.pos = base + pos
        return self.pos

    def readinto(self, buf) -> int:
        end = len(self.raw) if self.pos >= self.resume else self.limit
        k = max(0, min(len(buf), end - self.pos))
        buf[:k] = self.raw[self.pos : self.pos + k]
        self.pos += k
        return k


def _check_last_chunk(raw: bytes, name: str, lay: LasLayout, table, counts, cto: int) -> None:
    """Refuse points stored beyond the header's count. An arithmetic-coded chunk (point formats
    0-5) is written so that decoding its points reads every byte of it: the last chunk's points
    must not decode with its final byte hidden."""
    import lazrs

    src = _Hidden(raw, cto - 1, cto)
    src.seek(lay.offset)
    out = bytearray(counts[-1] * lay.record_length)
    try:
        with _native_stderr_held():
            dec = lazrs.LasZipDecompressor(src, lay.laszip)
            dec.seek(sum(counts[:-1]))
            dec.decompress_many(out)
    except (lazrs.LazrsError, ValueError, OSError, RuntimeError):
        return  # every byte is needed (or the data are damaged: the reader reports that)
    except BaseException as exc:
        if type(exc).__name__ != "PanicException":
            raise
        return
    raise InvalidInputError(
        f"{name}: LAZ header declares {lay.n} points, but the compressed data of its last chunk "
        f"hold more than its {counts[-1]} (header point count too small?)."
    )


# layered (LAZ 1.4, item version 3) items -> number of layers per chunk: Point14 9, RGB14 1,
# RGBNIR14 2, Wavepacket14 1, Byte14 one per byte
_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1, 14: 0}


def _check_layers(
    raw: bytes, name: str, start: int, table, lay: LasLayout, n_layers: int, counts
) -> None:
    """Each layered chunk: the first point raw, a u32 point count (``counts[k]`` from the header),
    ``n_layers`` u32 layer sizes, then the layers. The sizes are checked against the chunk's bytes:
    lazrs allocates a buffer per layer from them."""
    pos, rec_len = start, lay.record_length
    for k, (_count, nbytes) in enumerate(table):
        head = rec_len + 4 + 4 * n_layers
        held = _u(raw, "I", pos + rec_len) if nbytes >= rec_len + 4 else counts[k]
        if held != counts[k]:
            raise InvalidInputError(
                f"{name}: LAZ header declares {lay.n} points, so chunk {k} holds {counts[k]}; "
                f"the chunk says {held} (header point count wrong?)."
            )
        sizes = (
            struct.unpack_from(f"<{n_layers}I", raw, pos + rec_len + 4) if nbytes >= head else ()
        )
        if nbytes < head or sum(sizes) > nbytes - head:
            raise InvalidInputError(
                f"{name}: corrupted LAZ chunk {k}: its layer sizes ({sum(sizes)} bytes in all) do "
                f"not fit in the chunk's {nbytes} bytes."
            )
        pos += int(nbytes)


@contextlib.contextmanager
def _native_stderr_held():
    """Hold what native code writes to fd 2 while laspy/lazrs decode (a lazrs panic prints a report
    before becoming an exception): written back on success, dropped on failure.
    """
    try:
        fd = sys.stderr.fileno() if sys.stderr is not None else 2
    except (AttributeError, OSError, ValueError):
        fd = 2
    try:
        saved = os.dup(fd)
    except OSError:  # no usable stderr: nothing to hold
        yield
        return
    with tempfile.TemporaryFile() as hold:
        with contextlib.suppress(AttributeError, OSError, ValueError):
            sys.stderr.flush()
        os.dup2(hold.fileno(), fd)
        ok = False
        try:
            yield
            ok = True
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            if ok:
                hold.seek(0)
                text = hold.read()
                if text:
                    os.write(fd, text)


def read_las(raw: bytes, name: str, *, compressed: bool) -> RawGeometry:
    """LAS/LAZ bytes -> points (see the module docstring: the header is checked first)."""
    laspy = _laspy(compressed)
    check_las(raw, name, compressed=compressed)
    errors: tuple[type[BaseException], ...] = (
        laspy.errors.LaspyException,
        ValueError,
        OSError,
        EOFError,
        RuntimeError,
        KeyError,
        IndexError,
        TypeError,
        ArithmeticError,
        struct.error,
    )
    if compressed:
        import lazrs

        errors = (*errors, lazrs.LazrsError)
    try:
        with _native_stderr_held():
            las = laspy.read(io.BytesIO(raw))
    except errors as exc:
        raise InvalidInputError(
            f"{name}: malformed or truncated LAS/LAZ ({exc_text(exc)})."
        ) from exc
    except BaseException as exc:
        # lazrs turns a Rust panic on corrupted chunk data into pyo3's PanicException, which
        # derives from BaseException; anything else (KeyboardInterrupt...) goes on unchanged
        if type(exc).__name__ != "PanicException":
            raise
        raise InvalidInputError(
            f"{name}: corrupted LAZ point data (the decoder failed: {exc_text(exc)})."
        ) from None
    V = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1).astype(
        np.float64
    )
    dims = set(las.point_format.dimension_names)
    colors = None
    if {"red", "green", "blue"} <= dims:
        c = np.stack([np.asarray(las[k]) for k in ("red", "green", "blue")], axis=1)
        if c.size and c.max() > 255:
            c = c >> 8
        colors = c.astype(np.uint8)
    extra = list(las.point_format.extra_dimension_names)
    normals = None
    if all(k in extra for k in ("normal_x", "normal_y", "normal_z")):
        normals = np.stack(
            [np.asarray(las[k], dtype=np.float64) for k in ("normal_x", "normal_y", "normal_z")],
            axis=1,
        )
        extra = [k for k in extra if k not in ("normal_x", "normal_y", "normal_z")]
    attrs: dict[str, np.ndarray] = {}
    for k in _STANDARD:
        if k in dims:
            attrs[k] = np.array(las[k])
    for k in extra:
        attrs[k] = np.array(las[k])
    return RawGeometry(V, None, normals, colors, attrs, {})


def _scale(P: np.ndarray, las_scale: float | None) -> np.ndarray:
    if las_scale is not None:
        s = float(las_scale)
        if not np.isfinite(s) or s <= 0:
            raise InvalidInputError(f"`las_scale` must be a positive number; got {las_scale!r}.")
        return np.full(3, s)
    extent = float(np.ptp(P, axis=0).max()) if P.size else 0.0
    extent = max(extent, 1e-12)
    return np.full(3, 10.0 ** np.ceil(np.log10(extent / 2e9)))


def write_las(
    P: np.ndarray,
    *,
    normals=None,
    colors=None,
    attributes=None,
    compressed: bool,
    las_scale: float | None = None,
) -> bytes:
    laspy = _laspy(compressed)
    attributes = dict(attributes or {})
    has_gps = "gps_time" in attributes
    fmt = (3 if has_gps else 2) if colors is not None else (1 if has_gps else 0)
    header = laspy.LasHeader(point_format=fmt, version="1.2")
    scale = _scale(P, las_scale)
    offset = np.floor(P.min(axis=0) / scale) * scale if P.size else np.zeros(3)
    span = (P.max(axis=0) - offset) / scale if P.size else np.zeros(3)
    if (span > 2**31 - 1).any():
        raise InvalidInputError(
            f"`las_scale` {scale[0]:g} is too fine for the extent of the cloud (int32 overflow)."
        )
    header.offsets = offset
    header.scales = scale
    std_dims = set(laspy.PointFormat(fmt).dimension_names)
    extras: list[tuple[str, np.ndarray]] = []
    if normals is not None:
        nrm = np.asarray(normals, dtype=np.float64)
        extras += [(k, nrm[:, i]) for i, k in enumerate(("normal_x", "normal_y", "normal_z"))]
    standard: list[tuple[str, np.ndarray]] = []
    flat: list[tuple[str, np.ndarray]] = []
    for k, a in attributes.items():
        a = np.asarray(a)
        if a.ndim == 2:  # one extra-bytes dimension per column: name_0, name_1, ...
            flat.extend((f"{k}_{j}", a[:, j]) for j in range(a.shape[1]))
        elif a.ndim == 1:
            flat.append((k, a))
        else:
            raise InvalidInputError(
                f"attribute `{k}` has shape {a.shape}; LAS stores (n,) or (n, k) attributes."
            )
    for k, a in flat:
        if a.dtype.kind not in "biuf":
            raise InvalidInputError(f"attribute `{k}` has dtype {a.dtype}; LAS stores numbers.")
        if k in std_dims and k not in ("X", "Y", "Z", "red", "green", "blue"):
            standard.append((k, a))
        elif k.lower() in {d.lower() for d in std_dims}:
            raise InvalidInputError(f"attribute name `{k}` clashes with a LAS dimension.")
        else:
            extras.append((k, a.astype(np.uint8) if a.dtype == np.bool_ else a))
    if extras:
        header.add_extra_dims(
            [laspy.ExtraBytesParams(name=k, type=a.dtype.newbyteorder("=")) for k, a in extras]
        )
    las = laspy.LasData(header)
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    if colors is not None:
        c = np.asarray(colors)
        if c.dtype.kind == "f":
            c16 = np.clip(np.round(c[:, :3] * 65535.0), 0, 65535).astype(np.uint16)
        else:
            c16 = c[:, :3].astype(np.uint16) * 257
        las.red, las.green, las.blue = c16[:, 0], c16[:, 1], c16[:, 2]
    try:
        for k, a in standard:
            las[k] = a
        for k, a in extras:
            las[k] = a
    except (ValueError, TypeError, OverflowError) as exc:
        raise InvalidInputError(f"cannot store attributes in LAS ({exc_text(exc)}).") from exc
    for k, a in standard:
        if not np.array_equal(np.asarray(las[k]).astype(np.float64), a.astype(np.float64)):
            raise InvalidInputError(
                f"attribute `{k}` cannot be stored exactly in the LAS dimension of that name "
                "(non-integer or out-of-range values)."
            )
    buf = io.BytesIO()
    try:
        las.write(buf, do_compress=compressed)
    except (laspy.errors.LaspyException, ValueError, OverflowError) as exc:
        raise InvalidInputError(f"cannot write LAS/LAZ ({exc_text(exc)}).") from exc
    return buf.getvalue()
