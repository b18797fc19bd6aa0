"""The ``.sga`` stream format shared by the animation codecs (:mod:`._animation`, :mod:`._layered`).

A ``.sga`` file is a sequence of :mod:`._container` segments with an animation method id: the
stream header (kind 0: :class:`Params` with the connectivity and anchor chunks, or the
``layered`` header), one segment per block (kind 1: block number, first frame, frame count,
step; a ``layered`` frame is a block of one frame) and, in files, the frame index (kind 2: first
frame, frame count, byte offset and length of every block, so a decoder can start at any block).
A file without its trailing index was cut short: decoding it needs ``partial=True``.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from . import _connectivity, _container
from ._container import varint
from ._entropy import zstd_compress

METHODS = ("pca", "pca-q", "pca-qs", "pca-qp", "blocks", "pca-spectral", "pca-pred")
#: with the scalable layered codec of Section 5.2.4 (:mod:`._layered`)
ALL_METHODS = (*METHODS, "layered")
#: method ids in the container's method byte; the animation ids start at 16, clear of the static
#: codecs' ids (0-2) that share the container.
METHOD_IDS = {m: _container.METHOD_IDS[m] for m in ALL_METHODS}

TAG_CONNECTIVITY = 1
TAG_ANCHOR_INDEX = 2
TAG_BASIS = 3
TAG_COEFF = 4
TAG_ANCHOR_POS = 5
TAG_INDEX = 6
KIND_HEADER, KIND_BLOCK, KIND_INDEX = 0, 1, 2
MAX_FRAMES = 1 << 24

_HEAD = struct.Struct("<BIIIdffBBH")  # kind, T, block, n_anchors, step, ratio, weight, basis, it, -
_BLOCK = struct.Struct("<BIIId")  # kind, block number, first frame, frame count, step
_KIND = struct.Struct("<B")


@dataclass(frozen=True)
class Params:
    """Stream parameters stored in the header segment."""

    method: str
    n_frames: int  # 0: unknown (a live stream)
    block: int
    n_anchors: int
    step: float  # pca: number of kept coefficients per coordinate (an integer)
    anchor_ratio: float
    weight: float
    basis: int  # 0 exact eigen-decomposition, 1 orthogonal iterations
    n_iter: int

    def to_bytes(self) -> bytes:
        return _HEAD.pack(
            KIND_HEADER,
            self.n_frames,
            self.block,
            self.n_anchors,
            self.step,
            self.anchor_ratio,
            self.weight,
            self.basis,
            self.n_iter,
            0,
        )

    @classmethod
    def from_bytes(cls, method: str, b: bytes) -> Params:
        if len(b) != _HEAD.size or b[0] != KIND_HEADER:
            raise InvalidInputError(".sga stream header is malformed.")
        _k, T, block, na, step, ratio, weight, basis, n_iter, _ = _HEAD.unpack(b)
        if not (
            1 <= block <= MAX_FRAMES
            and T <= MAX_FRAMES
            and math.isfinite(step)
            and step > 0
            and math.isfinite(ratio)
            and ratio > 0
            and math.isfinite(weight)
            and weight > 0
            and basis in (0, 1)
        ):
            raise InvalidInputError(".sga stream header has invalid parameters.")
        return cls(method, T, block, na, step, ratio, weight, basis, n_iter)


def segment_end(data: bytes, pos: int) -> int | None:
    """End offset of the container segment starting at ``pos``; None when it is cut short.

    The segment header's checksum is verified first, so a damaged length cannot pose as a cut.
    """
    fixed = _container._FIXED
    if len(data) < pos + 4:
        return None
    if data[pos : pos + 4] != _container.MAGIC:
        raise InvalidInputError(f".sga data is corrupted (no segment starts at byte {pos}).")
    if len(data) < pos + fixed.size + 2:
        return None
    (plen,) = struct.unpack_from("<H", data, pos + fixed.size)
    end = pos + fixed.size + 2 + plen
    if len(data) < end + 4:
        return None
    (crc,) = struct.unpack_from("<I", data, end)
    if zlib.crc32(data[pos:end]) != crc:
        raise InvalidInputError(f".sga segment header at byte {pos} is corrupted.")
    n_chunks = data[pos + 7]
    p = end + 4
    for _ in range(n_chunks):
        if len(data) < p + _container._CHUNK.size:
            return None
        _tag, length, _crc = _container._CHUNK.unpack_from(data, p)
        p += _container._CHUNK.size + length
        if p > len(data):
            return None
    return p


def _segment(method, n, m, origin, scale, params: bytes, chunks, reordered=False) -> bytes:
    c = _container.Container(method, n, m, origin, scale, params, reordered, chunks)
    return c.to_bytes()


def header_segment(method, n, m, origin, scale, p: Params, F, anchors, reordered=False) -> bytes:
    conn = _connectivity.encode_faces(F)
    a = np.diff(np.r_[-1, anchors]) - 1
    idx = varint(anchors.size) + zstd_compress(a.astype("<u4").tobytes())
    return _segment(
        method,
        n,
        m,
        origin,
        scale,
        p.to_bytes(),
        [(TAG_CONNECTIVITY, conn), (TAG_ANCHOR_INDEX, idx)],
        reordered,
    )


def block_segment(method, n, m, origin, scale, b: int, t0: int, nf: int, step, chunks) -> bytes:
    return _segment(method, n, m, origin, scale, _BLOCK.pack(KIND_BLOCK, b, t0, nf, step), chunks)


def index_segment(method, n, m, origin, scale, entries) -> bytes:
    body = varint(len(entries)) + b"".join(
        varint(t0) + varint(nf) + varint(off) + varint(ln) for t0, nf, off, ln in entries
    )
    return _segment(method, n, m, origin, scale, _KIND.pack(KIND_INDEX), [(TAG_INDEX, body)])


def parse_block_params(c: _container.Container, st) -> tuple[int, int, int, float]:
    if len(c.params) != _BLOCK.size or c.params[0] != KIND_BLOCK:
        raise InvalidInputError(".sga block segment header is malformed.")
    _k, b, t0, nf, step = _BLOCK.unpack(c.params)
    if not (math.isfinite(step) and step > 0):
        raise InvalidInputError(".sga block segment has an invalid step.")
    if c.method != st.method or c.n_vertices != st.n or c.n_faces != st.m:
        raise InvalidInputError(".sga block segment does not belong to this stream.")
    if not 1 <= nf <= max(st.params.block, 1) or t0 > MAX_FRAMES:
        raise InvalidInputError(".sga block segment has an invalid frame count.")
    return b, t0, nf, step


def iter_segments(data: bytes, partial: bool) -> Iterator[tuple[int, int, _container.Container]]:
    """Parse consecutive segments; yields ``(offset, end, container)``."""
    pos = 0
    while pos < len(data):
        end = segment_end(data, pos)
        if end is None:
            if partial and pos > 0:
                return
            raise InvalidInputError(f".sga data is truncated (segment at byte {pos} is cut short).")
        yield pos, end, _container.parse(data[pos:end], fmt=f".sga segment at byte {pos}:")
        pos = end


def declared_frames(head: _container.Container) -> int:
    """Frame count a stream header segment declares (0: unknown, a live stream); both header
    layouts (:class:`Params` and the ``layered`` one) start with ``(kind u8, frames u32)``."""
    if len(head.params) < 5:
        raise InvalidInputError(".sga stream header is malformed.")
    return int(struct.unpack_from("<I", head.params, 1)[0])


def is_animation(data) -> bool:
    """True when ``data`` starts with a container whose method is an animation method."""
    b = bytes(data[:6]) if isinstance(data, bytes | bytearray | memoryview) else b""
    return len(b) == 6 and b[:4] == _container.MAGIC and b[5] in METHOD_IDS.values()


def info_dict(data, st, frames, conn, n_blocks, has_index, parameters, reordered=False) -> dict:
    nvf = max(1, st.n * max(frames, 1))
    return {
        "format": "sga",
        "version": data[4],
        "method": st.method,
        "n_frames": frames,
        "n_vertices": st.n,
        "n_faces": st.m,
        "bytes": len(data),
        "bpvf": 8.0 * len(data) / nvf,
        "connectivity_bpvf": 8.0 * conn / nvf,
        "n_blocks": n_blocks,
        "frame_index": has_index,
        "order_preserved": not reordered,
        "parameters": parameters,
    }
