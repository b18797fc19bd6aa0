"""The inline connectivity formats of canonical faces (first bytes 0x43, 0x44)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spectrageo import InvalidInputError
from spectrageo.compress import _conn_traverse
from spectrageo.compress._connectivity import decode_faces, reorder_coded


def _cylinder8():
    m = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=8)
    return np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)


def _irregular(seed=0, n=300):
    """Convex hull of random points: irregular valences."""
    rng = np.random.default_rng(seed)
    h = trimesh.convex.convex_hull(rng.normal(size=(n, 3)))
    return np.asarray(h.vertices), np.asarray(h.faces, dtype=np.int64)


def _stream_format(G):
    """The 0x42 code of canonical faces (the inline format switched off)."""
    mp = pytest.MonkeyPatch()
    mp.setattr(_conn_traverse, "_maybe_canonical", lambda F: False)
    try:
        return _conn_traverse.encode(G)
    finally:
        mp.undo()


#: the 8-section cylinder in canonical order as the 0x42 format wrote it before the shorter
#: range coder flush (docs/decisions.md#codec-rc-flush), and as it writes it now
_CANONICAL_FORMAT = bytes.fromhex("42120300000001020910000019beb554dcc38d00")
_CANONICAL_FORMAT_NOW = bytes.fromhex("42120300000001020910000019beb555")
#: the same faces in the inline format 0x43 (read only) and in 0x44, which leaves out the
#: coder's first byte and the flush's zero bytes (pinned: the formats and models must not drift)
_INLINE_FORMAT = bytes.fromhex("43003a735a4127ce161363")
_INLINE2_FORMAT = bytes.fromhex("443a735a4128")


def test_canonical_stream_format_files_still_decode():
    V, F = _cylinder8()
    _, G, _, code = reorder_coded(V, F)
    assert _CANONICAL_FORMAT[0] == _conn_traverse.MARKER_CANONICAL
    for old in (_CANONICAL_FORMAT, _INLINE_FORMAT):
        np.testing.assert_array_equal(decode_faces(old, len(V), len(G)), G)
    assert _stream_format(G) == _CANONICAL_FORMAT_NOW
    np.testing.assert_array_equal(decode_faces(_CANONICAL_FORMAT_NOW, len(V), len(G)), G)
    assert code == _INLINE2_FORMAT
    np.testing.assert_array_equal(decode_faces(code, len(V), len(G)), G)
    for cut in (2, 10):
        with pytest.raises(InvalidInputError):
            decode_faces(_CANONICAL_FORMAT[:cut], len(V), len(G))


def test_inline_format_is_smaller_on_irregular_meshes():
    for seed in range(3):
        V, F = _irregular(seed)
        _, G, _, code = reorder_coded(V, F)
        assert code[0] == _conn_traverse.MARKER_INLINE2
        old = _stream_format(G)
        assert old[0] == _conn_traverse.MARKER_CANONICAL
        assert len(code) < 0.95 * len(old)
        np.testing.assert_array_equal(decode_faces(code, len(V), len(G)), G)
        np.testing.assert_array_equal(decode_faces(old, len(V), len(G)), G)


def _odd_meshes():
    V, F = _irregular(3, 200)
    holed = F[np.random.default_rng(0).permutation(len(F))[: len(F) - 40]]
    two = np.r_[F, F + len(V)]
    flipped = F.copy()
    flipped[::7] = flipped[::7, ::-1]  # inconsistent orientation
    fin = np.r_[F, [[F[0, 0], F[0, 1], len(V)]]]  # three faces on one edge
    return {"holed": holed, "two components": two, "flipped": flipped, "non-manifold": fin}


@pytest.mark.parametrize("kind", ["holed", "two components", "flipped", "non-manifold"])
def test_odd_topologies_round_trip(kind):
    F = _odd_meshes()[kind]
    n = int(F.max()) + 1
    V = np.random.default_rng(1).normal(size=(n, 3))
    _, G, _, code = reorder_coded(V, F)
    assert code[0] in _conn_traverse.MARKERS
    np.testing.assert_array_equal(decode_faces(code, n, len(G)), G)


def test_faces_that_only_look_canonical_keep_the_general_formats():
    V, F = _irregular(4, 100)
    _, G, _, _ = reorder_coded(V, F)
    H = G.copy()
    H[[5, 6]] = H[[6, 5]]  # same vertex order, faces swapped: not the traversal's order
    assert _conn_traverse._maybe_canonical(H)
    code = _conn_traverse.encode(H)
    assert code[0] not in (_conn_traverse.MARKER_INLINE, _conn_traverse.MARKER_INLINE2)
    np.testing.assert_array_equal(_conn_traverse.decode(code, len(V), len(H)), H)


def test_cut_or_random_inline_streams_are_refused_or_decode_in_range():
    # bit flips of an inline stream: tests/test_conn_canonical.py
    V, F = _irregular(5, 200)
    _, G, _, code = reorder_coded(V, F)
    rng = np.random.default_rng(2)
    for cut in (1, 3, len(code) // 2):
        with pytest.raises(InvalidInputError):
            decode_faces(code[:cut], len(V), len(G))
    for i in range(40):
        junk = (
            bytes([0x43 if i % 2 else 0x44])
            + rng.integers(0, 256, size=int(rng.integers(0, 64))).astype(np.uint8).tobytes()
        )
        try:
            H = decode_faces(junk, len(V), len(G))
        except InvalidInputError:
            continue
        assert H.shape == G.shape and H.min() >= 0 and H.max() < len(V)
