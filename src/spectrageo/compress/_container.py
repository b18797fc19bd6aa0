"""The ``.sgc`` container: magic, version, header, checksummed chunks.

Layout (little endian)::

    magic    b"SGC\\x1a"                                  4 bytes
    version  u8  (FORMAT_VERSION)
    method   u8  (0 spectral, 1 feature, 2 saliency, 3 predictive)
    flags    u8  (bit 0: vertices/faces were reordered by the codec)
    n_chunks u8
    n_vertices u32, n_faces u32
    origin   3 x f64, scale f64                            (normalisation of the coordinates)
    params   u16 length + bytes                            (method parameters, see each codec)
    crc32    u32 of everything above
    chunks   n_chunks x (tag u8, length u32, crc32 u32, payload)

Chunk 0 is the connectivity, then the geometry coarse to fine. From version 3 the checksums are
chained: chunk ``i``'s covers ``(i u8, tag u8, length u32)``, its payload and the checksum before
it (the header's for chunk 0), so each chunk is bound to its place and to everything before it
and the last one covers the whole file; chunks swapped, duplicated, dropped or taken from another
file are refused. Versions 1 and 2 checksum each payload alone and are read with those checks. Every length and
checksum, the counts (:data:`MAX_COUNT`) and ``origin`` / ``scale`` (finite, ``scale > 0``) are
verified before a payload is interpreted, so damaged or foreign data raise
:class:`~spectrageo.InvalidInputError`; with ``partial=True`` a prefix decodes from its complete
chunks (a file cut at the end).
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass, field

from .._errors import InvalidInputError
from ..io._common import check_alloc

MAGIC = b"SGC\x1a"
#: version written; 2 added the traversal connectivity code (:mod:`._conn_traverse`), 3 the
#: chained chunk checksums
FORMAT_VERSION = 3
#: versions read (a version 1 file's connectivity is always the delta code)
READ_VERSIONS = (1, 2, 3)
#: first version whose chunk checksums are chained (bound to their place and the file)
CHAINED_VERSION = 3
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
#: largest vertex / face count a file may declare (guards allocations against hostile headers)
MAX_COUNT = 1 << 28

_FIXED = struct.Struct("<4sBBBBII4d")
_CHUNK = struct.Struct("<BII")
_PLACE = struct.Struct("<BBI")  # chunk index, tag, length: the chained checksum's prefix

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


def _chunk_crc(version: int, i: int, tag: int, payload: bytes, prev: int) -> int:
    """Checksum of chunk ``i`` (chained to ``prev`` from :data:`CHAINED_VERSION` on)."""
    if version < CHAINED_VERSION:
        return zlib.crc32(payload)
    return zlib.crc32(payload, zlib.crc32(_PLACE.pack(i, tag, len(payload)), prev))


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
    version: int = FORMAT_VERSION

    def to_bytes(self) -> bytes:
        if len(self.chunks) > 255:
            raise InvalidInputError("too many chunks for the container (at most 255).")
        if self.version not in READ_VERSIONS:
            raise InvalidInputError(f"container version must be in {READ_VERSIONS}.")
        head = _FIXED.pack(
            MAGIC,
            self.version,
            METHOD_IDS[self.method],
            FLAG_REORDERED if self.reordered else 0,
            len(self.chunks),
            self.n_vertices,
            self.n_faces,
            *self.origin,
            self.scale,
        )
        head += struct.pack("<H", len(self.params)) + self.params
        crc = zlib.crc32(head)
        out = [head, struct.pack("<I", crc)]
        for i, (tag, payload) in enumerate(self.chunks):
            crc = _chunk_crc(self.version, i, tag, payload, crc)
            out.append(_CHUNK.pack(tag, len(payload), crc))
            out.append(payload)
        return b"".join(out)


def parse(data, *, partial: bool = False, fmt: str = ".sgc") -> Container:
    """Parse and verify a container; ``partial`` accepts a prefix (missing chunks are dropped).

    ``fmt`` names the data in error messages (a ``.sga`` segment passes its own).
    """
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise InvalidInputError(f"`data` must be bytes; got {type(data).__name__}.")
    if len(data) < 4 or data[:4] != MAGIC:
        raise InvalidInputError("not a spectrageo compressed mesh (.sgc): wrong magic bytes.")
    if len(data) < _FIXED.size + 2:
        raise InvalidInputError(f"{fmt} data is truncated inside the header.")
    magic, version, method, flags, n_chunks, n, m, ox, oy, oz, scale = _FIXED.unpack_from(data)
    if version not in READ_VERSIONS:
        raise InvalidInputError(
            f"{fmt} format version {version} is not supported (this spectrageo reads versions "
            f"{', '.join(map(str, READ_VERSIONS))})."
        )
    (plen,) = struct.unpack_from("<H", data, _FIXED.size)
    end = _FIXED.size + 2 + plen
    if len(data) < end + 4:
        raise InvalidInputError(f"{fmt} data is truncated inside the header.")
    (crc,) = struct.unpack_from("<I", data, end)
    if zlib.crc32(data[:end]) != crc:
        raise InvalidInputError(f"{fmt} header is corrupted (checksum mismatch).")
    if method not in METHOD_NAMES:
        raise InvalidInputError(f"{fmt} header names an unknown method id {method}.")
    if not (0 < n <= MAX_COUNT and 0 < m <= MAX_COUNT) or n_chunks < 1:
        raise InvalidInputError(
            f"{fmt} header has invalid counts (n={n}, m={m}, chunks={n_chunks})."
        )
    if not all(math.isfinite(x) for x in (ox, oy, oz)):
        raise InvalidInputError(
            f"{fmt} header has a non-finite origin; expected finite numbers, got "
            f"({ox}, {oy}, {oz})."
        )
    if not (math.isfinite(scale) and scale > 0):
        raise InvalidInputError(
            f"{fmt} header has an invalid scale; expected a finite number > 0, got {scale}."
        )
    c = Container(
        METHOD_NAMES[method],
        n,
        m,
        (ox, oy, oz),
        scale,
        data[_FIXED.size + 2 : end],
        bool(flags & FLAG_REORDERED),
        version=version,
    )
    pos = end + 4
    for i in range(n_chunks):
        if len(data) < pos + _CHUNK.size:
            if partial and i > 0:
                c.complete = False
                return c
            raise InvalidInputError(f"{fmt} data is truncated (chunk {i} of {n_chunks} missing).")
        tag, length, ccrc = _CHUNK.unpack_from(data, pos)
        pos += _CHUNK.size
        payload = data[pos : pos + length]
        if len(payload) != length:
            if partial and i > 0:
                c.complete = False
                return c
            raise InvalidInputError(
                f"{fmt} data is truncated (chunk {i} of {n_chunks} holds {len(payload)} of "
                f"{length} bytes)."
            )
        if _chunk_crc(version, i, tag, payload, crc) != ccrc:
            if version < CHAINED_VERSION:
                raise InvalidInputError(f"{fmt} chunk {i} is corrupted (checksum mismatch).")
            raise InvalidInputError(
                f"{fmt} chunk {i} of {n_chunks} is corrupted or out of place (its checksum "
                "binds it to its position and the chunks before it: chunks reordered, "
                "duplicated, dropped or taken from another file)."
            )
        crc = ccrc
        c.chunks.append((tag, payload))
        pos += length
    if pos != len(data):
        raise InvalidInputError(f"{fmt} data has {len(data) - pos} unexpected trailing bytes.")
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
