"""``canonical`` faces re-traverse to themselves, so ``--reorder`` files get the inline format."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from spectrageo import compress
from spectrageo.compress import _conn_traverse
from spectrageo.compress._connectivity import decode_faces, reorder_coded


def _sphere():
    s = trimesh.creation.icosphere(subdivisions=2)
    return np.asarray(s.vertices), np.asarray(s.faces, dtype=np.int64)


def _odd(kind: str):
    """Face arrays the codec accepts whose traversal seeds faces with numbered vertices."""
    V, F = _sphere()
    n = len(V)
    if kind == "bowtie":  # two triangles sharing one vertex: the second seed starts new-old-new
        return 5, np.array([[0, 1, 2], [3, 0, 4]], dtype=np.int64)
    if kind == "touching_spheres":  # a second sphere through one vertex of the first
        F2 = F + n
        F2[F2 == n + F[0, 1]] = F[0, 1]
        return 2 * n, np.r_[F, np.roll(F2, 1, axis=0)]
    if kind == "four_faces_on_edges":  # non-manifold edges: flaps seeded after the sphere
        a, b = F[:6, 0], F[:6, 1]
        flaps = np.c_[n + np.arange(6), a, b]
        return n + 6, np.r_[F, flaps]
    if kind == "duplicates_and_degenerate":
        degenerate = np.c_[F[:4, 2], F[:4, 1], F[:4, 2]]
        flipped = F[5:7, ::-1]
        return n + 3, np.r_[F, F[3:9], degenerate, flipped][::-1]
    rng = np.random.default_rng(int(kind.split("_")[1]))
    nv = int(rng.integers(3, 40))
    return nv + 2, rng.integers(0, nv, size=(int(rng.integers(1, 120)), 3))


KINDS = ["bowtie", "touching_spheres", "four_faces_on_edges", "duplicates_and_degenerate"] + [
    f"soup_{k}" for k in range(12)
]


@pytest.mark.parametrize("kind", KINDS)
def test_canonical_faces_are_a_fixed_point(kind):
    n, F = _odd(kind)
    perm, G = _conn_traverse.canonical(F, n)
    np.testing.assert_array_equal(np.sort(perm), np.arange(n))
    perm2, G2 = _conn_traverse.canonical(G, n)
    np.testing.assert_array_equal(G2, G)
    np.testing.assert_array_equal(perm2, np.arange(n))
    code = _conn_traverse._encode_inline(G)
    assert code is not None and code[0] == _conn_traverse.MARKER_INLINE2
    np.testing.assert_array_equal(_conn_traverse.decode(code, n, len(G)), G)


def test_bowtie_seed_starts_at_its_numbered_vertex():
    _, G = _conn_traverse.canonical(np.array([[0, 1, 2], [3, 0, 4]]), 5)
    np.testing.assert_array_equal(G, [[0, 1, 2], [0, 3, 4]])


def test_general_formats_keep_file_order_with_odd_seeds():
    n, F = _odd("touching_spheres")
    H = F[np.random.default_rng(2).permutation(len(F))]
    buf = _conn_traverse.encode(H)
    assert buf[0] in (_conn_traverse.MARKER, _conn_traverse.MARKER_ADAPTIVE)
    np.testing.assert_array_equal(_conn_traverse.decode(buf, n, len(H)), H)


def test_reorder_of_non_manifold_mesh_writes_inline_and_decodes_to_it():
    V, F = _sphere()
    n, F = _odd("four_faces_on_edges")
    V = np.r_[V, V[:6] * 1.2]
    Vr, G, perm, code = reorder_coded(V, F)
    assert code[0] == _conn_traverse.MARKER_INLINE2
    np.testing.assert_array_equal(decode_faces(code, n, len(G)), G)
    data = compress.encode(V, F, method="predictive", reorder=True, max_error=1e-3)
    V2, F2 = compress.decode(data)
    np.testing.assert_array_equal(F2, G)
    assert np.abs(V2 - Vr).max() < 1e-2
