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


def adaptive_blob(streams, alphas, counted: bool = False) -> bytes:
    """The streams under adaptive models (:func:`._rangecoder.code_streams`)."""
    data = np.concatenate([np.zeros(0, np.int64), *(s.astype(np.int64) for s in streams)])
    offsets = np.r_[0, np.cumsum([s.size for s in streams])].astype(np.int64)
    buf = np.zeros(8 * data.size + 64, dtype=np.uint8)
    nb = rangecoder.code_streams(True, data, offsets, np.array(alphas, np.int64), buf, counted)
    return buf[:nb].tobytes()


def adaptive_read(blob: bytes, sizes, alphas, counted: bool = False) -> list[np.ndarray]:
    """Inverse of :func:`adaptive_blob` for streams of the given sizes."""
    buf = np.frombuffer(blob, dtype=np.uint8).copy()
    data = np.zeros(sum(sizes), dtype=np.int64)
    offsets = np.r_[0, np.cumsum(sizes)].astype(np.int64)
    a = np.array(alphas, np.int64)
    if rangecoder.code_streams(False, data, offsets, a, buf, counted) < 0:
        raise InvalidInputError(".sgc connectivity is malformed (adaptive streams).")
    return np.split(data, offsets[1:-1])


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
        streams = adaptive_read(r.take(r.varint()), sizes[:n_topo], alphas[:n_topo])
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


def canonical_sizes(topo) -> bytes:
    """Sizes of the stage-1 streams (gate, orient, seed, far, third vertex by context) in the
    canonical format, less what the face count implies: the orient stream has one symbol per
    face that is not a seed, every gate not in it closed a border edge, and the last context
    holds the third vertices the others do not."""
    gate, orient, seed, far, *w = (s.size for s in topo)
    return b"".join(varint(x) for x in (seed, gate - orient, far, *w[:-1]))


def read_canonical(r: Reader, alphas, m: int):
    """Stage-1 streams and raw bits of the canonical format; stages 2-3 are empty. Returns
    ``(sizes, streams, bits)`` as :func:`read_streams`."""
    seed, closed, far, *w = (r.varint() for _ in range(len(alphas) - 2))
    if seed % 3 or not 3 <= seed <= 3 * m:
        raise InvalidInputError(".sgc connectivity is malformed (stream lengths).")
    orient = m - seed // 3
    sizes = [orient + closed, orient, seed, far, *w, orient - sum(w)]
    if sizes[-1] < 0 or max(sizes) > 3 * m + 3 or sum(sizes) > 9 * m + 16:
        raise InvalidInputError(".sgc connectivity is malformed (stream too long).")
    nb = r.varint()
    if nb > 64 * (3 * m + 3):
        raise InvalidInputError(".sgc connectivity is malformed (bit stream too long).")
    raw = np.frombuffer(r.take((nb + 7) // 8), dtype=np.uint8)
    streams = adaptive_read(r.rest(), sizes, alphas, True)
    empty = (np.zeros(8, np.uint8), 0)
    return sizes, streams, [(np.r_[raw, np.zeros(8, np.uint8)], nb), empty, empty]
