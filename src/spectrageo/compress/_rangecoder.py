"""Adaptive binary range coder (LZMA's) and an adaptive symbol code built on it.

The coder state ``st`` is an int64 array ``(low, range, cache, cache_size, code, pos)``; ``buf``
a uint8 array the encoder writes into and the decoder reads from. A probability of a zero bit
is an integer of ``pb`` bits, updated by ``p += ((1 << pb) - p) >> 5`` after a zero and
``p -= p >> 5`` after a one. All integer arithmetic: both ends agree on every machine.
"""

from __future__ import annotations

import numba
import numpy as np

_TOP = 1 << 24
#: probability bits of :func:`code_symbol` (long runs of one symbol cost about 1e-3 bit each)
PB_SYM = 16
#: truncated-unary nodes of :func:`code_symbol` before its Elias-gamma escape
UNARY = 8
#: probabilities per adaptive symbol model
SYM_STRIDE = UNARY + 66
#: counted models (:func:`bit_counted`): the n-th update moves a probability by
#: ``1 / min(n + RATE0, RATE_MAX)`` of the way (docs/decisions.md#codec-conn-canonical)
RATE0 = 2
RATE_MAX = 32
#: trailing zero bytes :func:`finish` leaves out (the decoders' end checks allow four)
TRIM = 4


@numba.njit(cache=True, inline="always")
def bitlen(x):
    k = 0
    while x > 0:
        x >>= 1
        k += 1
    return k


@numba.njit(cache=True)
def start(enc, st, buf):
    """Initial state; the decoder reads its first five bytes."""
    st[:] = 0
    st[1] = 0xFFFFFFFF
    st[3] = 1
    if not enc:
        for _ in range(5):
            st[4] = ((st[4] << 8) | _next_byte(st, buf)) & 0xFFFFFFFF


@numba.njit(cache=True)
def round_low(st):
    """Encoder: move ``low`` to the value of ``[low, low + range)`` with the most trailing
    zero bits (32 or, as ``range >= 2**24``, at least 24), so that the flushed bytes end in
    zeros. Any value of the final interval decodes to the same symbols."""
    low = st[0]
    for sh in (32, 24):
        m = (np.int64(1) << sh) - 1
        v = (low + m) & ~m
        if v < low + st[1]:
            st[0] = v
            return


@numba.njit(cache=True)
def finish(st, buf):
    """Encoder: flush (:func:`round_low`, then the five bytes of ``low`` and the cache) and
    return the byte count without up to :data:`TRIM` trailing zero bytes, at least one byte.

    The decoder reads a byte past the end as zero (:func:`_next_byte`), and ends at most
    :data:`TRIM` bytes past it, which its end checks (``<= size + 4``) allow."""
    round_low(st)
    for _ in range(5):
        _shift_low(st, buf)
    nb = st[5]
    t = 0
    while t < TRIM and nb - t > 1 and nb - t - 1 < buf.size and buf[nb - t - 1] == 0:
        t += 1
    return nb - t


@numba.njit(cache=True)
def _shift_low(st, buf):
    low = st[0]
    if low < 0xFF000000 or low >= (1 << 32):
        carry = low >> 32
        temp = st[2]
        while True:
            p = st[5]
            if p < buf.size:
                buf[p] = (temp + carry) & 0xFF
            st[5] = p + 1
            temp = 0xFF
            st[3] -= 1
            if st[3] == 0:
                break
        st[2] = (low >> 24) & 0xFF
    st[3] += 1
    st[0] = (low & 0x00FFFFFF) << 8


@numba.njit(cache=True)
def _next_byte(st, buf):
    p = st[5]
    st[5] = p + 1
    return np.int64(buf[p]) if p < buf.size else np.int64(0)


@numba.njit(cache=True, inline="always")
def _dec_normalise(st, buf):
    """Decoder: shift in bytes until the range is back above ``_TOP``."""
    while st[1] < _TOP:
        st[1] <<= 8
        st[4] = ((st[4] << 8) | _next_byte(st, buf)) & 0xFFFFFFFF


@numba.njit(cache=True, inline="always")
def _bit_at(enc, st, buf, p, b, pb):
    """Code bit ``b`` (encoder) or return the decoded bit, probability ``p`` of a zero."""
    bound = (st[1] >> pb) * p
    if enc:
        if b == 0:
            st[1] = bound
        else:
            st[0] += bound
            st[1] -= bound
        while st[1] < _TOP:
            st[1] <<= 8
            _shift_low(st, buf)
        return b
    if st[4] < bound:
        st[1] = bound
        b = 0
    else:
        st[4] -= bound
        st[1] -= bound
        b = 1
    _dec_normalise(st, buf)
    return b


@numba.njit(cache=True)
def bit(enc, st, buf, probs, i, b, pb):
    """Code bit ``b`` (encoder) or return the decoded bit, with adaptive probability
    ``probs[i]`` of ``pb`` bits."""
    p = probs[i]
    b = _bit_at(enc, st, buf, p, b, pb)
    probs[i] = p + (((1 << pb) - p) >> 5) if b == 0 else p - (p >> 5)
    return b


@numba.njit(cache=True)
def bit_counted(enc, st, buf, probs, cnts, i, b, pb):
    """:func:`bit` whose first updates are larger: the n-th (``cnts[i]``) moves the
    probability ``1 / min(n + RATE0, RATE_MAX)`` of the way to the bit seen."""
    p = probs[i]
    b = _bit_at(enc, st, buf, p, b, pb)
    d = min(cnts[i] + RATE0, RATE_MAX)
    cnts[i] = min(cnts[i] + 1, RATE_MAX)
    probs[i] = p + ((1 << pb) - p) // d if b == 0 else p - p // d
    return b


@numba.njit(cache=True)
def bit_mixed(enc, st, buf, probs, cnts, i, j, k, b):
    """:func:`bit_counted` under the mean of the probabilities ``probs[i]``, ``probs[j]`` and
    ``probs[k]`` (of :data:`PB_SYM` bits); all three are updated."""
    p = (probs[i] + probs[j] + probs[k]) // 3
    b = _bit_at(enc, st, buf, p, b, PB_SYM)
    for x in (i, j, k):
        d = min(cnts[x] + RATE0, RATE_MAX)
        cnts[x] = min(cnts[x] + 1, RATE_MAX)
        q = probs[x]
        probs[x] = q + ((1 << PB_SYM) - q) // d if b == 0 else q - q // d
    return b


@numba.njit(cache=True, inline="always")
def _sym_bit(enc, st, buf, probs, cnts, i, j, k, b):
    if j >= 0:
        return bit_mixed(enc, st, buf, probs, cnts, i, j, k, b)
    if cnts.size:
        return bit_counted(enc, st, buf, probs, cnts, i, b, PB_SYM)
    return bit(enc, st, buf, probs, i, b, PB_SYM)


@numba.njit(cache=True)
def direct(enc, st, buf, b):
    """Code one equiprobable bit."""
    st[1] >>= 1
    if enc:
        if b:
            st[0] += st[1]
        while st[1] < _TOP:
            st[1] <<= 8
            _shift_low(st, buf)
        return b
    b = 0
    if st[4] >= st[1]:
        st[4] -= st[1]
        b = 1
    _dec_normalise(st, buf)
    return b


@numba.njit(cache=True)
def code_symbol(enc, st, buf, probs, cnts, base, s, alpha, base2=-1, base3=-1):
    """Symbol ``s`` of ``range(alpha)`` with the adaptive model at ``probs[base:base +
    SYM_STRIDE]``: truncated unary over the first :data:`UNARY` values, then the Elias-gamma
    code of the rest (adaptive length, equiprobable mantissa). ``cnts``: update counts of
    :func:`bit_counted`, or empty for :func:`bit`; with ``base2, base3 >= 0`` every binary
    decision is coded under the mean of three counted models (:func:`bit_mixed`). Returns the
    symbol (decoder: may be ``>= alpha`` on damaged data)."""
    top = min(alpha - 1, UNARY)
    for k in range(top):
        j2, j3 = (base2 + k, base3 + k) if base2 >= 0 else (-1, -1)
        if _sym_bit(enc, st, buf, probs, cnts, base + k, j2, j3, 1 if s == k else 0) == 1:
            return np.int64(k)
    if top == alpha - 1:
        return np.int64(top)
    z = s - top + 1 if enc else 0
    nb = bitlen(z)
    length = 1
    while length < 64:
        o = UNARY + length
        j2, j3 = (base2 + o, base3 + o) if base2 >= 0 else (-1, -1)
        if not _sym_bit(enc, st, buf, probs, cnts, base + o, j2, j3, 1 if length < nb else 0):
            break
        length += 1
    m = np.int64(1)
    for j in range(length - 2, -1, -1):
        m = (m << 1) | direct(enc, st, buf, (z >> j) & 1 if enc else 0)
    return m - 1 + top


@numba.njit(cache=True)
def code_streams(enc, data, offsets, alphas, buf, counted):
    """Code the streams ``data[offsets[k]:offsets[k + 1]]`` (symbols of ``range(alphas[k])``),
    each with its own adaptive model (``counted``: :func:`bit_counted` updates). Encoder:
    returns the byte count; decoder: fills ``data`` and returns the bytes read, or -1 on
    damaged data."""
    st = np.zeros(6, np.int64)
    start(enc, st, buf)
    probs = np.full(alphas.size * SYM_STRIDE, 1 << (PB_SYM - 1), np.int64)
    cnts = np.zeros(probs.size if counted else 0, np.int64)
    for k in range(alphas.size):
        for i in range(offsets[k], offsets[k + 1]):
            s = code_symbol(enc, st, buf, probs, cnts, k * SYM_STRIDE, data[i], alphas[k])
            if not enc:
                if s < 0 or s >= alphas[k] or st[5] > buf.size + 8:
                    return -1
                data[i] = s
    if enc:
        return finish(st, buf)
    return st[5] if st[5] <= buf.size + 4 else -1
