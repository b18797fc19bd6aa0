"""The range coder's shorter flush and the inline connectivity format 0x44."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _conn_streams, _conn_traverse
from spectrageo.compress import _rangecoder as rc
from spectrageo.compress._connectivity import decode_faces, reorder_coded


def _hull(seed: int, n: int = 150):
    rng = np.random.default_rng(seed)
    h = trimesh.convex.convex_hull(rng.normal(size=(n, 3)))
    return np.asarray(h.vertices), np.asarray(h.faces, dtype=np.int64)


def _bits(bits: np.ndarray, pb: int = 11):
    """Encode ``bits`` with one adaptive model; returns the bytes and the byte count before
    the flush's trimming would apply (the stream as the earlier flush wrote it is 5 bytes of
    ``low`` plus the cache)."""
    buf = np.zeros(bits.size + 64, np.uint8)
    st = np.zeros(6, np.int64)
    rc.start(True, st, buf)
    probs = np.full(1, 1 << (pb - 1), np.int64)
    for b in bits:
        rc.bit(True, st, buf, probs, 0, int(b), pb)
    nb = rc.finish(st, buf)
    return buf[:nb].tobytes(), int(st[5])


def _unbits(data: bytes, n: int, pb: int = 11):
    buf = np.frombuffer(data, np.uint8).copy()
    st = np.zeros(6, np.int64)
    rc.start(False, st, buf)
    probs = np.full(1, 1 << (pb - 1), np.int64)
    out = np.array([rc.bit(False, st, buf, probs, 0, 0, pb) for _ in range(n)])
    return out, int(st[5]) - buf.size


@pytest.mark.parametrize("p1", [0.0, 0.02, 0.5, 0.97, 1.0])
def test_trimmed_streams_decode_within_the_end_checks(p1):
    rng = np.random.default_rng(int(100 * p1))
    for n in (0, 1, 2, 7, 50, 400):
        bits = (rng.random(n) < p1).astype(np.int64)
        data, full = _bits(bits)
        assert 1 <= len(data) <= full and full - len(data) <= rc.TRIM
        # what was left out are zero bytes only: the decoder reads them past the end
        out, past = _unbits(data, n)
        assert np.array_equal(out, bits)
        assert past <= rc.TRIM  # the decoders' checks allow ``size + 4``
        padded, _ = _unbits(data + bytes(full - len(data)), n)
        assert np.array_equal(padded, bits)


def test_flush_leaves_out_three_or_four_bytes_of_random_streams():
    rng = np.random.default_rng(3)
    saved = []
    for _ in range(50):
        data, full = _bits((rng.random(300) < 0.3).astype(np.int64))
        saved.append(full - len(data))
    assert min(saved) >= 3  # round_low leaves at least 24 zero bits in low's four bytes


def test_adaptive_streams_round_trip():
    rng = np.random.default_rng(9)
    for _ in range(30):
        alphas = [int(a) for a in rng.integers(2, 40, size=int(rng.integers(1, 5)))]
        streams = [rng.integers(0, a, size=int(rng.integers(0, 60))) for a in alphas]
        for counted in (False, True):
            blob = _conn_streams.adaptive_blob(streams, alphas, counted)
            back = _conn_streams.adaptive_read(blob, [s.size for s in streams], alphas, counted)
            for s, b in zip(streams, back, strict=True):
                assert np.array_equal(s, b)


@pytest.mark.parametrize("seed", range(4))
def test_inline_format_0x44_is_0x43_without_its_zero_byte(seed):
    V, F = _hull(seed)
    _, G, _, code = reorder_coded(V, F)
    assert code[0] == _conn_traverse.MARKER_INLINE2
    old = bytes([_conn_traverse.MARKER_INLINE, 0]) + code[1:]
    for c in (code, old):
        np.testing.assert_array_equal(decode_faces(c, len(V), len(G)), G)


def test_reorder_files_decode_within_the_bound():
    V, F = _hull(7, 400)
    data = compress.encode(V, F, method="predictive", max_error=1e-3, reorder=True)
    V2, F2 = compress.decode(data)
    assert F2.shape == F.shape
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    # decoded vertices stay within the bound (order: the codec's, compared as sets of faces)
    assert np.abs(np.sort(V2, axis=0) - np.sort(V, axis=0)).max() <= 1e-3 * diag
    for cut in (len(data) - 1, len(data) // 2):
        with pytest.raises(InvalidInputError):
            compress.decode(data[:cut])
