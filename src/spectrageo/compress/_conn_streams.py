"""Symbol streams of the traversal connectivity code: static tables, ANS words, adaptive blob."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from . import _rangecoder as rangecoder
from ._container import Reader, varint


def categorical(counts: np.ndarray):
    import constriction

    p = counts.astype(np.float64) / float(counts.sum())
    return constriction.stream.model.Categorical(p, perfect=False)


def static_tables(streams, alphas) -> bytes:
    """Symbol counts of the non-empty streams (varints up to the last symbol used)."""
    head = bytearray()
    for s, alpha in zip(streams, alphas, strict=True):
        if s.size:
            counts = np.bincount(s, minlength=alpha)
            top = int(np.flatnonzero(counts).max()) + 1
            head += varint(top) + b"".join(varint(int(x)) for x in counts[:top])
    return bytes(head)


def static_words(streams, alphas) -> bytes:
    """The streams under static categorical models of their counts (constriction's ANS)."""
    from constriction import stream

    coder = stream.stack.AnsCoder()
    for s, alpha in reversed(list(zip(streams, alphas, strict=True))):
        if s.size:
            counts = np.bincount(s, minlength=alpha)
            coder.encode_reverse(s.astype(np.int32), categorical(counts))
    return coder.get_compressed().astype("<u4").tobytes()


def _read_table(r: Reader, size: int, alpha: int):
    if not size:
        return None
    top = r.varint()
    if not 1 <= top <= alpha:
        raise InvalidInputError(".sgc connectivity is malformed (bad symbol table).")
    counts = np.zeros(alpha, dtype=np.int64)
    counts[:top] = [r.varint() for _ in range(top)]
    if counts.sum() != size:
        raise InvalidInputError(".sgc connectivity is malformed (bad symbol table).")
    return counts


def read_streams(r: Reader, adaptive: bool, n_topo: int, alphas, m: int, nv: int):
    """Every symbol stream of a traversal code: sizes, stage 1 (``n_topo`` streams) adaptive
    or static, the rest static; then the three raw bit buffers. Returns
    ``(sizes, streams, bits)``."""
    from constriction import stream

    limits = (3 * m + 3,) * n_topo + (nv, m, m, m)
    sizes, tables = [], []
    for alpha, lim in zip(alphas, limits, strict=True):
        size = r.varint()
        if size > lim:
            raise InvalidInputError(".sgc connectivity is malformed (stream too long).")
        sizes.append(size)
        if not adaptive:
            tables.append(_read_table(r, size, alpha))
    if sizes[n_topo] != nv or sizes[n_topo + 1] != m or sizes[n_topo + 3] != m:
        raise InvalidInputError(".sgc connectivity is malformed (stream lengths).")
    if sum(sizes[:n_topo]) > 9 * m + 16:
        raise InvalidInputError(".sgc connectivity is malformed (stream too long).")
    first = 0
    streams = []
    if adaptive:
        tables = [None] * n_topo + [
            _read_table(r, z, a) for z, a in zip(sizes[n_topo:], alphas[n_topo:])
        ]
        blob = np.frombuffer(r.take(r.varint()), dtype=np.uint8).copy()
        data = np.zeros(sum(sizes[:n_topo]), dtype=np.int64)
        offsets = np.r_[0, np.cumsum(sizes[:n_topo])].astype(np.int64)
        if rangecoder.code_streams(False, data, offsets, np.array(alphas[:n_topo]), blob) < 0:
            raise InvalidInputError(".sgc connectivity is malformed (adaptive streams).")
        streams = np.split(data, offsets[1:-1])
        first = n_topo
    bits = []
    for _ in range(3):
        nb = r.varint()
        if nb > 64 * (3 * m + 3):
            raise InvalidInputError(".sgc connectivity is malformed (bit stream too long).")
        raw = np.frombuffer(r.take((nb + 7) // 8), dtype=np.uint8)
        bits.append((np.r_[raw, np.zeros(8, np.uint8)], nb))
    words = r.rest()
    if len(words) % 4:
        raise InvalidInputError(".sgc connectivity is malformed (coder words misaligned).")
    w = np.frombuffer(words, dtype="<u4").astype(np.uint32)
    try:
        coder = stream.stack.AnsCoder(w)
        for size, counts in zip(sizes[first:], tables[first:], strict=True):
            if size:
                streams.append(coder.decode(categorical(counts), size).astype(np.int64))
            else:
                streams.append(np.zeros(0, dtype=np.int64))
    except (ValueError, RuntimeError, OverflowError) as exc:
        raise InvalidInputError(f".sgc connectivity is malformed ({exc}).") from None
    return sizes, streams, bits
