"""The canonical-order connectivity formats (first bytes 0x42, 0x43) and counted adaptive models."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _conn_traverse, _rangecoder
from spectrageo.compress._conn_streams import adaptive_blob, adaptive_read
from spectrageo.compress._connectivity import decode_faces, reorder_coded


def _cylinder():
    m = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=24)
    return np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)


@pytest.mark.parametrize("mesh", ["cylinder", "sphere"])
def test_canonical_faces_use_the_short_format_and_round_trip(mesh):
    if mesh == "cylinder":
        V, F = _cylinder()
    else:
        s = trimesh.creation.icosphere(subdivisions=2)
        V, F = np.asarray(s.vertices), np.asarray(s.faces, dtype=np.int64)
    _, G, _, code = reorder_coded(V, F)
    assert code[0] == _conn_traverse.MARKER_INLINE2
    np.testing.assert_array_equal(decode_faces(code, len(V), len(G)), G)


def test_canonical_format_is_smaller_than_the_adaptive_one():
    V, F = _cylinder()
    _, G, _, code = reorder_coded(V, F)
    H = G.copy()
    H[-1] = np.roll(H[-1], 1)  # one rotation off: the general (adaptive) format
    general = _conn_traverse.encode(H)
    assert general[0] == _conn_traverse.MARKER_ADAPTIVE
    # stages 2-3 implied: their sizes, tables and ANS words are not written
    assert len(code) + 20 <= len(general)


def test_faces_out_of_canonical_order_keep_the_general_formats():
    V, F = _cylinder()
    _, G, _, _ = reorder_coded(V, F)
    rng = np.random.default_rng(0)
    for H in (G[rng.permutation(len(G))], np.roll(G, 1, axis=1)):
        buf = _conn_traverse.encode(H)
        assert buf[0] in (_conn_traverse.MARKER, _conn_traverse.MARKER_ADAPTIVE)
        np.testing.assert_array_equal(_conn_traverse.decode(buf, len(V), len(H)), H)


def test_damaged_canonical_streams_are_refused_or_decode_in_range():
    V, F = _cylinder()
    _, G, _, code = reorder_coded(V, F)
    rng = np.random.default_rng(1)
    for cut in (2, len(code) // 2):
        with pytest.raises(InvalidInputError):
            decode_faces(code[:cut], len(V), len(G))
    for _ in range(40):
        bad = bytearray(code)
        bad[int(rng.integers(1, len(bad)))] ^= 1 << int(rng.integers(8))
        try:
            H = decode_faces(bytes(bad), len(V), len(G))
        except InvalidInputError:
            continue
        assert H.shape == G.shape and H.min() >= 0 and H.max() < len(V)


def test_counted_models_learn_a_constant_stream_faster():
    s = [np.full(500, 3, np.int64), np.zeros(500, np.int64)]
    fixed = adaptive_blob(s, [8, 2])
    counted = adaptive_blob(s, [8, 2], counted=True)
    assert len(counted) < len(fixed) - 10
    for blob, c in ((fixed, False), (counted, True)):
        out = adaptive_read(blob, [500, 500], [8, 2], counted=c)
        np.testing.assert_array_equal(out[0], s[0])
        np.testing.assert_array_equal(out[1], s[1])


def test_counted_rates_never_make_a_certainty():
    # a first update of the whole way would give a symbol probability 1 and its rival 0
    assert 2 <= _rangecoder.RATE0 <= _rangecoder.RATE_MAX
    s = [np.r_[np.zeros(300, np.int64), 1, np.zeros(5, np.int64)]]
    out = adaptive_read(adaptive_blob(s, [2], counted=True), [306], [2], counted=True)
    np.testing.assert_array_equal(out[0], s[0])


def test_reorder_file_with_canonical_connectivity_decodes():
    V, F = _cylinder()
    Vr, G, _, code = reorder_coded(V, F)
    assert code[0] == _conn_traverse.MARKER_INLINE2
    data = compress.encode(V, F, method="predictive", reorder=True, max_error=1e-3)
    V2, F2 = compress.decode(data)
    np.testing.assert_array_equal(F2, G)
    assert np.abs(V2 - Vr).max() < 1e-2


#: an 8-section cylinder in canonical order as the adaptive format (0x41) wrote it before the
#: canonical format existed
_ADAPTIVE_FORMAT = bytes.fromhex(
    "4112121f1f030000010209100312200020011204000000200120100000004425b0eed06ab604bde036510000"
    "000060000000"
)


def test_adaptive_format_files_still_decode():
    m = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=8)
    V, F = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)
    _, G, _, code = reorder_coded(V, F)
    assert _ADAPTIVE_FORMAT[0] == _conn_traverse.MARKER_ADAPTIVE
    np.testing.assert_array_equal(decode_faces(_ADAPTIVE_FORMAT, len(V), len(G)), G)
    assert code[0] == _conn_traverse.MARKER_INLINE2 and len(code) < len(_ADAPTIVE_FORMAT)


def test_one_traversal_serves_both_orders():
    from spectrageo import datasets

    m = datasets.fandisk()
    F = np.ascontiguousarray(m.faces[::-1], dtype=np.int64)  # out of canonical order
    t = _conn_traverse.traverse(F)
    assert _conn_traverse.encode(F, t) == _conn_traverse.encode(F)
    perm_a, G_a = _conn_traverse.canonical(F, len(m.vertices), t)
    perm_b, G_b = _conn_traverse.canonical(F, len(m.vertices))
    assert np.array_equal(perm_a, perm_b) and np.array_equal(G_a, G_b)
