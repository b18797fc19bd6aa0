"""The ``.sgc`` container: magic, version, header, checksummed chunks.

Version 4 (written for meshes; little endian, ``varint``: LEB128)::

    magic      b"SGC\\x1a"                                  4 bytes
    version    u8 (4)
    method     u8: bits 0-4 method id (0 spectral, 1 feature, 2 saliency, 3 predictive),
               bit 5 reordered (vertices/faces renumbered by the codec), bit 6 wide, bit 7 zero
    n_chunks, n_vertices, n_faces                          3 varints
    origin, scale   wide: 4 x f64; else three zigzag varints k and an f32 scale s, the origin
                    being k * (s * 2**-24) (the encoder rounds its frame to these values before
                    normalising, see :func:`compact_frame`, so decoding is exact)
    params     varint length + bytes                       (method parameters, see each codec)
    chunks     n_chunks x (varint (length * 32 + tag), crc32 u32, payload)

Versions 1-3 (read; version 3 is also written for the segments of ``.sga`` animations, whose
:func:`._sga_format.segment_end` relies on the header checksum)::

    magic 4 bytes, version u8, method u8, flags u8 (bit 0: reordered), n_chunks u8,
    n_vertices u32, n_faces u32, origin 3 x f64, scale f64, params u16 length + bytes,
    crc32 u32 of everything above, chunks n_chunks x (tag u8, length u32, crc32 u32, payload)

Chunk 0 is the connectivity, then the geometry coarse to fine. From version 3 the checksums are
chained: chunk ``i``'s covers its place (``i`` and its tag and length), its payload and the
checksum before it, chunk 0's the header's (version 3: the header checksum; version 4: the
header bytes themselves, so chunk 0's checksum is the header's), so each chunk is bound to its
place and to everything before it and the last one covers the whole file; chunks swapped,
duplicated, dropped or taken from another file are refused. Versions 1 and 2 checksum each
payload alone and are read with those checks. Every length and checksum (chunk 0's, hence the
header's, included), the counts (:data:`MAX_COUNT`) and ``origin`` / ``scale`` (finite,
``scale > 0``) are verified before :func:`parse` returns, so before a payload is interpreted or
a count is used to allocate; damaged or foreign data raise :class:`~spectrageo.InvalidInputError`.
With ``partial=True`` a prefix decodes from its complete chunks (a file cut at the end).
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from .._errors import InvalidInputError
from ..io._common import check_alloc

MAGIC = b"SGC\x1a"
#: version written for meshes; 2 added the traversal connectivity code (:mod:`._conn_traverse`),
#: 3 the chained chunk checksums, 4 the compact header (docs/decisions.md#codec-container-v4)
FORMAT_VERSION = 4
#: version written for ``.sga`` animation segments (:mod:`._sga_format`)
ANIMATION_VERSION = 3
#: versions read (a version 1 file's connectivity is always the delta code)
READ_VERSIONS = (1, 2, 3, 4)
#: first version whose chunk checksums are chained (bound to their place and the file)
CHAINED_VERSION = 3
#: first version with the compact layout
COMPACT_VERSION = 4
METHOD_IDS = {
    "spectral": 0,
    "feature": 1,
    "saliency": 2,
    "predictive": 3,
    # mesh animations (.sga, :mod:`spectrageo.compress._animation`)
    "pca": 16,
    "pca-q": 17,
    "pca-qs": 18,
    "pca-qp": 19,
    "blocks": 20,
    "layered": 21,
    "pca-spectral": 22,
    "pca-pred": 23,
}
METHOD_NAMES = {v: k for k, v in METHOD_IDS.items()}
FLAG_REORDERED = 1
#: version 4: origin and scale stored as f64 (a frame :func:`compact_frame` could not round)
FLAG_WIDE = 2
#: largest vertex / face count a file may declare (guards allocations against hostile headers)
MAX_COUNT = 1 << 28
MAX_CHUNKS = 255
#: version 4 origin grid, a fraction of the scale (a power of two, so the grid step is exact; the
#: float32 resolution of a unit coordinate, as the scale's rounding)
ORIGIN_GRID = 2.0**-24
_ORIGIN_MAX = 1 << 52  # largest |k| of a compact origin (k * grid is then exact to recover)
_TAG_BITS = 5  # version 4 chunk tags are below 2**5

_FIXED = struct.Struct("<4sBBBBII4d")
_CHUNK = struct.Struct("<BII")
_PLACE = struct.Struct("<BBI")  # chunk index, tag, length: the chained checksum's prefix
_WIDE = struct.Struct("<4d")
_F32 = struct.Struct("<f")
_U32 = struct.Struct("<I")

#: decoder working memory per vertex, bytes (peak resident growth of a fresh process decoding the
#: 437,645-vertex dragon, with margin), checked against io's memory cap before decoding
_WORK_PER_VERTEX = {"spectral": 1500}
_WORK_DEFAULT = 5000


def check_memory(method: str, n: int, m: int, name: str, n_frames: int = 0) -> None:
    """Refuse to decode ``n`` vertices, ``m`` faces (and ``n_frames`` frames of an animation)
    when the decoder's memory would exceed :func:`spectrageo.io._common.max_bytes`."""
    work = _WORK_PER_VERTEX.get(method, _WORK_DEFAULT)
    need = n * work + 24 * m + 24 * n * max(1, 2 * n_frames)
    what = f"decoding {n_frames} frames of {n} vertices" if n_frames else f"decoding {n} vertices"
    check_alloc(need, name, f"{what} and {m} faces")


def f32_below(x: float) -> float:
    """The largest float32 value ``<= x`` as a float (``x`` itself when that is not a positive
    normal float32)."""
    with np.errstate(over="ignore"):
        y = np.float32(x)
    if not np.isfinite(y):
        return float(x)
    if float(y) > x:
        y = np.nextafter(y, np.float32(0.0))
    return float(y) if _is_f32(float(y)) and y > 0 else float(x)


def _is_f32(x: float) -> bool:
    """Whether ``x`` is a normal float32 value (or zero)."""
    f = np.finfo(np.float32)
    return (x == 0.0 or float(f.tiny) <= abs(x) <= float(f.max)) and float(np.float32(x)) == x


def compact_frame(origin, diag: float) -> tuple[tuple[float, float, float], float]:
    """A normalisation frame near ``(origin, diag)`` that version 4 stores exactly: the scale
    rounded down to float32 (so ``max_error`` over the diagonal still holds) and the origin
    rounded to the grid of :data:`ORIGIN_GRID` times the scale. Returned unchanged when it
    cannot be (the file then stores it as f64)."""
    o, s = tuple(float(x) for x in origin), f32_below(float(diag))
    if not _is_f32(s) or not all(math.isfinite(x) for x in o):
        return o, float(diag)
    g = s * ORIGIN_GRID
    k = [x / g for x in o]
    if not all(abs(v) < _ORIGIN_MAX for v in k):
        return o, float(diag)
    return tuple(float(round(v)) * g for v in k), s


def _origin_steps(origin, scale: float) -> list[int] | None:
    """Grid steps of a compact origin, or None when ``(origin, scale)`` needs the wide layout."""
    if not (scale > 0 and _is_f32(scale)):
        return None
    if not all(math.isfinite(x) for x in origin):
        return None
    g = scale * ORIGIN_GRID
    if g == 0.0:
        return None
    k = [round(x / g) for x in origin]
    if not all(abs(v) < _ORIGIN_MAX and float(v) * g == x for v, x in zip(k, origin)):
        return None
    return k


def _zigzag(k: int) -> int:
    return 2 * k if k >= 0 else -2 * k - 1


def _unzigzag(z: int) -> int:
    return z >> 1 if not z & 1 else -((z + 1) >> 1)


@dataclass
class Header:
    """A container header's fields as stored (no checks; :func:`layout` reads one).

    ``origin`` holds three floats (versions 1-3, or version 4 with :data:`FLAG_WIDE`) or the
    three integer grid steps of a compact version 4 origin; ``flags`` holds
    :data:`FLAG_REORDERED` and :data:`FLAG_WIDE`.
    """

    version: int
    method_id: int
    flags: int
    n_chunks: int
    n_vertices: int
    n_faces: int
    origin: tuple
    scale: float
    params: bytes

    def pack(self) -> bytes:
        """The header bytes (versions 1-3 with their header checksum)."""
        if self.version < COMPACT_VERSION:
            head = _FIXED.pack(
                MAGIC,
                self.version,
                self.method_id,
                self.flags & FLAG_REORDERED,
                self.n_chunks,
                self.n_vertices,
                self.n_faces,
                *self.origin,
                self.scale,
            )
            head += struct.pack("<H", len(self.params)) + self.params
            return head + _U32.pack(zlib.crc32(head))
        out = [MAGIC, bytes([self.version, (self.method_id | self.flags << 5) & 0xFF])]
        out += [varint(self.n_chunks), varint(self.n_vertices), varint(self.n_faces)]
        if self.flags & FLAG_WIDE:
            out.append(_WIDE.pack(*self.origin, self.scale))
        else:
            out += [varint(_zigzag(int(k))) for k in self.origin] + [_F32.pack(self.scale)]
        out += [varint(len(self.params)), self.params]
        return b"".join(out)

    def frame(self) -> tuple[tuple[float, float, float], float]:
        """``(origin, scale)`` as floats."""
        if self.version < COMPACT_VERSION or self.flags & FLAG_WIDE:
            return tuple(float(x) for x in self.origin), float(self.scale)
        g = self.scale * ORIGIN_GRID
        return tuple(float(k) * g for k in self.origin), float(self.scale)


def chain_seed(version: int, head: bytes) -> int:
    """The value chunk 0's checksum chains from: the header checksum (versions 1-3, the last 4
    bytes of ``head``), the checksum of the header bytes (version 4)."""
    if version < COMPACT_VERSION:
        return _U32.unpack_from(head, len(head) - 4)[0]
    return zlib.crc32(head)


def record_head(version: int, tag: int, length: int, crc: int) -> bytes:
    """The bytes a chunk's payload follows (tag, length, checksum)."""
    if version < COMPACT_VERSION:
        return _CHUNK.pack(tag, length, crc)
    return varint(length << _TAG_BITS | tag) + _U32.pack(crc)


def chunk_crc(version: int, i: int, tag: int, payload: bytes, prev: int) -> int:
    """Checksum of chunk ``i`` (chained to ``prev`` from :data:`CHAINED_VERSION` on)."""
    if version < CHAINED_VERSION:
        return zlib.crc32(payload)
    if version < COMPACT_VERSION:
        place = _PLACE.pack(i, tag, len(payload))
    else:
        place = bytes([i]) + varint(len(payload) << _TAG_BITS | tag)
    return zlib.crc32(payload, zlib.crc32(place, prev))


@dataclass
class Container:
    method: str
    n_vertices: int
    n_faces: int
    origin: tuple[float, float, float]
    scale: float
    params: bytes
    reordered: bool = False
    chunks: list[tuple[int, bytes]] = field(default_factory=list)
    complete: bool = True  # False when a prefix was read with partial=True
    #: None: :data:`FORMAT_VERSION` for meshes, :data:`ANIMATION_VERSION` for animations
    version: int | None = None

    def header(self) -> Header:
        """The :class:`Header` this container is written with (f64 origin and scale unless
        version 4 stores them exactly in its compact form)."""
        version = self.version
        if version is None:
            anim = METHOD_IDS[self.method] >= 16
            version = ANIMATION_VERSION if anim else FORMAT_VERSION
        if version not in READ_VERSIONS:
            raise InvalidInputError(f"container version must be in {READ_VERSIONS}.")
        if len(self.chunks) > MAX_CHUNKS:
            raise InvalidInputError(f"too many chunks for the container (at most {MAX_CHUNKS}).")
        flags = FLAG_REORDERED if self.reordered else 0
        origin, scale = tuple(float(x) for x in self.origin), float(self.scale)
        if version >= COMPACT_VERSION:
            if any(t >> _TAG_BITS for t, _ in self.chunks):
                raise InvalidInputError(f"chunk tags must be below {1 << _TAG_BITS}.")
            steps = _origin_steps(origin, scale)
            if steps is None:
                flags |= FLAG_WIDE
            else:
                origin = tuple(steps)
        return Header(
            version,
            METHOD_IDS[self.method],
            flags,
            len(self.chunks),
            self.n_vertices,
            self.n_faces,
            origin,
            scale,
            self.params,
        )

    def to_bytes(self) -> bytes:
        h = self.header()
        head = h.pack()
        out, crc = [head], chain_seed(h.version, head)
        for i, (tag, payload) in enumerate(self.chunks):
            crc = chunk_crc(h.version, i, tag, payload, crc)
            out += [record_head(h.version, tag, len(payload), crc), payload]
        return b"".join(out)


@dataclass(frozen=True)
class Record:
    """One stored chunk: its tag, the offsets of its record, payload and end, its checksum."""

    tag: int
    start: int
    body: int
    end: int
    crc: int


def _read_header(data: bytes, fmt: str) -> tuple[Header, int]:
    """The raw header and the offset where the chunks start (truncation is an error)."""
    if len(data) < 4 or data[:4] != MAGIC:
        raise InvalidInputError("not a spectrageo compressed mesh (.sgc): wrong magic bytes.")
    if len(data) < 6:
        raise InvalidInputError(f"{fmt} data is truncated inside the header.")
    version = data[4]
    if version not in READ_VERSIONS and len(data) < _FIXED.size + 2:
        raise InvalidInputError(f"{fmt} data is truncated inside the header.")
    if version not in READ_VERSIONS:
        raise InvalidInputError(
            f"{fmt} format version {version} is not supported (this spectrageo reads versions "
            f"{', '.join(map(str, READ_VERSIONS))})."
        )
    if version < COMPACT_VERSION:
        if len(data) < _FIXED.size + 2:
            raise InvalidInputError(f"{fmt} data is truncated inside the header.")
        _m, _v, method, flags, n_chunks, n, m, ox, oy, oz, scale = _FIXED.unpack_from(data)
        (plen,) = struct.unpack_from("<H", data, _FIXED.size)
        end = _FIXED.size + 2 + plen
        if len(data) < end + 4:
            raise InvalidInputError(f"{fmt} data is truncated inside the header.")
        if zlib.crc32(data[:end]) != _U32.unpack_from(data, end)[0]:
            raise InvalidInputError(f"{fmt} header is corrupted (checksum mismatch).")
        flags &= FLAG_REORDERED
        params = data[_FIXED.size + 2 : end]
        return Header(version, method, flags, n_chunks, n, m, (ox, oy, oz), scale, params), end + 4
    r = Reader(data, "header")
    r.pos = 6
    try:
        n_chunks, n, m = r.varint(), r.varint(), r.varint()
        if data[5] >> 5 & FLAG_WIDE:
            *origin, scale = r.unpack("<4d")
        else:
            origin = [_unzigzag(r.varint()) for _ in range(3)]
            (scale,) = r.unpack("<f")
        params = r.take(r.varint())
    except InvalidInputError:
        raise InvalidInputError(f"{fmt} data is truncated inside the header.") from None
    flags = data[5] >> 5
    return Header(version, data[5] & 31, flags, n_chunks, n, m, tuple(origin), scale, params), r.pos


def _walk(data: bytes, pos: int, h: Header) -> tuple[list[Record], tuple | None]:
    """The complete chunk records from ``pos`` and, when the data end inside chunk ``i``,
    ``(i, bytes present, length)`` (``length`` None when its record head is cut)."""
    out = []
    for i in range(h.n_chunks):
        start = pos
        if h.version < COMPACT_VERSION:
            if len(data) < pos + _CHUNK.size:
                return out, (i, 0, None)
            tag, length, crc = _CHUNK.unpack_from(data, pos)
            pos += _CHUNK.size
        else:
            r = Reader(data, "chunk")
            r.pos = pos
            try:
                word = r.varint()
                (crc,) = r.unpack("<I")
            except InvalidInputError:
                return out, (i, 0, None)
            tag, length, pos = word & (1 << _TAG_BITS) - 1, word >> _TAG_BITS, r.pos
        if len(data) < pos + length:
            return out, (i, len(data) - pos, length)
        out.append(Record(tag, start, pos, pos + length, crc))
        pos += length
    return out, None


def layout(data: bytes, fmt: str = ".sgc") -> tuple[Header, int, list[Record]]:
    """Header, offset of the first chunk and the chunk records of a container, read without
    verifying checksums or values (for tools that edit files; :func:`parse` reads files)."""
    h, pos = _read_header(bytes(data), fmt)
    return h, pos, _walk(bytes(data), pos, h)[0]


def _check_header(h: Header, fmt: str) -> tuple[tuple[float, float, float], float]:
    n, m, n_chunks = h.n_vertices, h.n_faces, h.n_chunks
    if h.method_id not in METHOD_NAMES or h.flags >> 2:
        raise InvalidInputError(f"{fmt} header names an unknown method id {h.method_id}.")
    if not (0 < n <= MAX_COUNT and 0 < m <= MAX_COUNT and 1 <= n_chunks <= MAX_CHUNKS):
        raise InvalidInputError(
            f"{fmt} header has invalid counts (n={n}, m={m}, chunks={n_chunks})."
        )
    origin, scale = h.frame()
    if not (math.isfinite(scale) and scale > 0):
        raise InvalidInputError(
            f"{fmt} header has an invalid scale; expected a finite number > 0, got {scale}."
        )
    if not all(math.isfinite(x) for x in origin):
        raise InvalidInputError(
            f"{fmt} header has a non-finite origin; expected finite numbers, got "
            f"({origin[0]}, {origin[1]}, {origin[2]})."
        )
    return origin, scale


def parse(data, *, partial: bool = False, fmt: str = ".sgc") -> Container:
    """Parse and verify a container; ``partial`` accepts a prefix (missing chunks are dropped).

    ``fmt`` names the data in error messages (a ``.sga`` segment passes its own).
    """
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise InvalidInputError(f"`data` must be bytes; got {type(data).__name__}.")
    h, pos = _read_header(data, fmt)
    origin, scale = _check_header(h, fmt)
    records, cut = _walk(data, pos, h)
    crc = chain_seed(h.version, data[:pos])
    c = Container(
        METHOD_NAMES[h.method_id],
        h.n_vertices,
        h.n_faces,
        origin,
        scale,
        h.params,
        bool(h.flags & FLAG_REORDERED),
        version=h.version,
    )
    n_chunks = h.n_chunks
    for i, rec in enumerate(records):
        payload = data[rec.body : rec.end]
        if chunk_crc(h.version, i, rec.tag, payload, crc) != rec.crc:
            if h.version < CHAINED_VERSION:
                raise InvalidInputError(f"{fmt} chunk {i} is corrupted (checksum mismatch).")
            if i == 0 and h.version >= COMPACT_VERSION:
                raise InvalidInputError(
                    f"{fmt} header or chunk 0 is corrupted (checksum mismatch; chunk 0's "
                    "checksum covers the header)."
                )
            raise InvalidInputError(
                f"{fmt} chunk {i} of {n_chunks} is corrupted or out of place (its checksum "
                "binds it to its position and the chunks before it: chunks reordered, "
                "duplicated, dropped or taken from another file)."
            )
        crc = rec.crc
        c.chunks.append((rec.tag, payload))
    if cut is not None:
        i, have, length = cut
        if partial and i > 0:
            c.complete = False
            return c
        if length is None:
            raise InvalidInputError(f"{fmt} data is truncated (chunk {i} of {n_chunks} missing).")
        raise InvalidInputError(
            f"{fmt} data is truncated (chunk {i} of {n_chunks} holds {have} of {length} bytes)."
        )
    end = records[-1].end
    if end != len(data):
        raise InvalidInputError(f"{fmt} data has {len(data) - end} unexpected trailing bytes.")
    return c


# ----------------------------------------------------------------------------- small codecs
class Reader:
    """Bounds-checked reader over a payload (every overrun is an InvalidInputError)."""

    def __init__(self, buf: bytes, what: str) -> None:
        self.buf = buf
        self.pos = 0
        self.what = what

    def take(self, k: int) -> bytes:
        if k < 0 or self.pos + k > len(self.buf):
            raise InvalidInputError(f".sgc {self.what} is malformed (read past its end).")
        out = self.buf[self.pos : self.pos + k]
        self.pos += k
        return out

    def unpack(self, fmt: str):
        s = struct.Struct(fmt)
        return s.unpack(self.take(s.size))

    def varint(self) -> int:
        shift = out = 0
        while True:
            (b,) = self.take(1)
            out |= (b & 0x7F) << shift
            if not b & 0x80:
                return out
            shift += 7
            if shift > 63:
                raise InvalidInputError(f".sgc {self.what} is malformed (bad varint).")

    def rest(self) -> bytes:
        out = self.buf[self.pos :]
        self.pos = len(self.buf)
        return out


def varint(x: int) -> bytes:
    x = int(x)
    if x < 0:
        raise ValueError("varint of a negative number")
    out = bytearray()
    while True:
        b = x & 0x7F
        x >>= 7
        if x:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)
