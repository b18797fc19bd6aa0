"""Entropy coding of quantised integers with ``constriction`` (ANS) and bytes with ``zstandard``.

Integers are coded in *groups* (e.g. one frequency band of one coordinate): each group gets a
quantised Laplace model with its own scale, fitted by the encoder and stored as a float16, and a
symbol range ``[-R, R]`` stored as a varint. Large values are split into a high part (Laplace
coded, at most :data:`MAX_HIGH` in magnitude) and ``shift`` raw low bits (uniform model; in
16-bit pieces when there are more than 23), so that the model's alphabet stays small and every
symbol keeps a usable probability in the coder's 24-bit precision. The decoder needs the group
of every symbol (it derives it from the structure it already knows) and reads the parameters
from the stream.
"""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from ._container import Reader, varint

#: largest magnitude of the Laplace-coded high part of a symbol
MAX_HIGH = 4095
#: largest magnitude of any coded integer
MAX_ABS = (1 << 40) - 1


def _model(R: int, scale: float):
    import constriction

    return constriction.stream.model.QuantizedLaplace(-R, R, 0.0, float(scale))


def _uniform(shift: int):
    import constriction

    return constriction.stream.model.Uniform(1 << shift)


#: widest raw part the coder takes in one piece (its probabilities have 24 bits)
_MAX_RAW = 23


def _raw_widths(shift: int) -> list[int]:
    """Bit widths of the raw low part, lowest bits first: one piece up to :data:`_MAX_RAW` bits
    (the layout of every file written so far), 16-bit pieces beyond."""
    if shift <= _MAX_RAW:
        return [shift] if shift else []
    return [16] * (shift // 16) + ([shift % 16] if shift % 16 else [])


def encode_groups(symbols: np.ndarray, groups: np.ndarray, n_groups: int) -> bytes:
    """Code ``symbols`` (int64) whose group ids are ``groups`` (0..n_groups-1)."""
    from constriction import stream

    AnsCoder = stream.stack.AnsCoder  # noqa: N806 - the library's class name

    symbols = np.asarray(symbols, dtype=np.int64)
    groups = np.asarray(groups, dtype=np.int64)
    if symbols.size and np.abs(symbols).max() > MAX_ABS:
        raise InvalidInputError("quantised values are too large to code; use a coarser step.")
    order = np.argsort(groups, kind="stable")
    counts = np.bincount(groups, minlength=n_groups)
    starts = np.r_[0, np.cumsum(counts)]
    head = bytearray()
    plans = []
    for g in range(n_groups):
        s = symbols[order[starts[g] : starts[g + 1]]]
        R = int(np.abs(s).max()) if s.size else 0
        shift = max(0, int(R).bit_length() - MAX_HIGH.bit_length())
        hi = s >> shift
        Rh = int(np.abs(hi).max()) if hi.size else 0
        if Rh > MAX_HIGH:  # the shift floors negative values: -32767 >> 3 is -4096
            shift += 1
            hi = s >> shift
            Rh = int(np.abs(hi).max())
        scale = float(np.float16(max(np.abs(hi).mean() if hi.size else 0.0, 0.05)))
        if not np.isfinite(scale):  # float16 overflow cannot happen (|hi| <= MAX_HIGH)
            scale = float(MAX_HIGH)
        head += varint(Rh) + bytes([shift]) + np.float16(scale).tobytes()
        plans.append((hi, s - (hi << shift), Rh, shift, scale))
    coder = AnsCoder()
    for hi, lo, Rh, shift, scale in reversed(plans):
        if hi.size == 0:
            continue
        widths = _raw_widths(shift)
        offsets = np.cumsum([0, *widths])
        for w, off in zip(reversed(widths), reversed(offsets[:-1])):  # last decoded, first coded
            coder.encode_reverse(((lo >> int(off)) & ((1 << w) - 1)).astype(np.int32), _uniform(w))
        if Rh:
            coder.encode_reverse(hi.astype(np.int32), _model(Rh, scale))
    words = coder.get_compressed().astype("<u4").tobytes()
    return bytes(head) + words


def decode_groups(buf: bytes, groups: np.ndarray, n_groups: int, what: str) -> np.ndarray:
    """Inverse of :func:`encode_groups` given the same ``groups``."""
    from constriction import stream

    AnsCoder = stream.stack.AnsCoder  # noqa: N806 - the library's class name

    groups = np.asarray(groups, dtype=np.int64)
    r = Reader(buf, what)
    params = []
    for _ in range(n_groups):
        Rh = r.varint()
        (shift,) = r.take(1)
        scale = float(np.frombuffer(r.take(2), dtype="<f2")[0])
        if Rh > MAX_HIGH or shift > 40 or not (np.isfinite(scale) and scale > 0):
            raise InvalidInputError(f".sgc {what} has invalid entropy-model parameters.")
        params.append((Rh, shift, scale))
    words = r.rest()
    if len(words) % 4:
        raise InvalidInputError(f".sgc {what} is malformed (coder words misaligned).")
    w = np.frombuffer(words, dtype="<u4").astype(np.uint32)
    order = np.argsort(groups, kind="stable")
    counts = np.bincount(groups, minlength=n_groups)
    out_sorted = np.zeros(groups.size, dtype=np.int64)
    pos = 0
    try:
        # an empty word list is a valid coder state: constriction seals a state that holds
        # little information (one symbol -4 of a Laplace model of scale 4) into no words
        coder = AnsCoder(w)
        for g, (Rh, shift, scale) in enumerate(params):
            k = int(counts[g])
            if k == 0:
                continue
            hi = np.zeros(k, dtype=np.int64)
            lo = np.zeros(k, dtype=np.int64)
            if Rh:
                hi = coder.decode(_model(Rh, scale), k).astype(np.int64)
            off = 0
            for w in _raw_widths(shift):
                lo += coder.decode(_uniform(w), k).astype(np.int64) << off
                off += w
            out_sorted[pos : pos + k] = (hi << shift) + lo
            pos += k
    except (ValueError, RuntimeError, OverflowError) as exc:
        if isinstance(exc, InvalidInputError):
            raise
        raise InvalidInputError(f".sgc {what} is malformed ({exc}).") from None
    out = np.empty_like(out_sorted)
    out[order] = out_sorted
    return out


# ----------------------------------------------------------------------------- zstd
ZSTD_LEVEL = 19


def zstd_compress(b: bytes, level: int = ZSTD_LEVEL) -> bytes:
    import zstandard

    return zstandard.ZstdCompressor(level=level).compress(b)


def zstd_decompress(b: bytes, max_size: int, what: str) -> bytes:
    import zstandard

    try:
        declared = zstandard.get_frame_parameters(b).content_size
        if declared > max_size and declared != zstandard.CONTENTSIZE_UNKNOWN:
            raise InvalidInputError(f".sgc {what} declares {declared} bytes; at most {max_size}.")
        out = zstandard.ZstdDecompressor().decompress(b, max_output_size=max_size)
    except zstandard.ZstdError as exc:
        raise InvalidInputError(f".sgc {what} is malformed ({exc}).") from None
    if len(out) > max_size:
        raise InvalidInputError(f".sgc {what} is malformed (inflates beyond its declared size).")
    return out
