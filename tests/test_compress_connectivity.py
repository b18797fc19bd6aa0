"""Order-preserving connectivity coding: exact round trips on real and awkward face lists."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spectrageo import InvalidInputError
from spectrageo.compress import _conn_traverse
from spectrageo.compress._connectivity import (
    _encode_delta,
    decode_faces,
    encode_faces,
    reorder,
)
from spectrageo.datasets import data_dir, fandisk


def load_fandisk():
    mesh = fandisk()
    return mesh.vertices, np.asarray(mesh.faces, dtype=np.int64)


def _roundtrip(F, n):
    F = np.asarray(F, dtype=np.int64)
    buf = encode_faces(F)
    G = decode_faces(buf, n, len(F))
    np.testing.assert_array_equal(G, F)
    return buf


def _traversal_roundtrip(F, n):
    F = np.asarray(F, dtype=np.int64)
    buf = _conn_traverse.encode(F)
    np.testing.assert_array_equal(_conn_traverse.decode(buf, n, len(F)), F)
    return buf


def _grid(k):
    """A (k x k)-vertex grid, two triangles per cell, consistently oriented."""
    idx = np.arange(k * k).reshape(k, k)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    return np.r_[np.c_[a.ravel(), b.ravel(), d.ravel()], np.c_[a.ravel(), d.ravel(), c.ravel()]]


def _bound_bits(n, m):
    return (math.lgamma(n + 1) + math.lgamma(m + 1)) / math.log(2)


def test_fandisk_roundtrip_and_never_larger_than_delta_code():
    V, F = load_fandisk()
    buf = _roundtrip(F, len(V))
    assert len(buf) <= len(_encode_delta(F))


def test_random_orders_cost_close_to_the_permutation_bound():
    rng = np.random.default_rng(0)
    F = _grid(60)
    n, m = 3600, len(F)
    lab = rng.permutation(n)
    G = lab[F][rng.permutation(m)]
    G = np.take_along_axis(G, (rng.integers(0, 3, m)[:, None] + np.arange(3)) % 3, axis=1)
    buf = _traversal_roundtrip(G, n)
    bits = 8 * len(buf)
    bound = _bound_bits(n, m)
    # the two orders cannot cost less than the bound; topology and rotations (log2 3 per face)
    # come on top, and the delta code spends about 3 log2(n) bits per face
    assert bits < bound + 6 * n + 1.6 * m
    assert bits < 0.65 * 8 * len(_encode_delta(G))


def test_traversal_ordered_file_costs_a_few_bits_per_vertex():
    V, F = load_fandisk()
    V2, G, perm = reorder(V, F)
    np.testing.assert_array_equal(V2, V[perm])
    np.testing.assert_array_equal(np.sort(perm), np.arange(len(V)))
    assert _same_oriented_faces(perm[G], F)  # same faces, same orientation, new labels
    buf = _roundtrip(G, len(V))
    assert 8 * len(buf) / len(V) < 5.0


def _same_oriented_faces(A, B):
    def canon(X):
        r = np.argmin(X, axis=1)
        idx = (r[:, None] + np.arange(3)) % 3
        Y = np.take_along_axis(X, idx, axis=1)
        return Y[np.lexsort(Y.T[::-1])]

    return np.array_equal(canon(A), canon(B))


def test_reorder_keeps_the_oriented_face_set():
    rng = np.random.default_rng(3)
    F = _grid(20)
    lab = rng.permutation(400)
    F = lab[F][rng.permutation(len(F))]
    V = rng.normal(size=(400, 3))
    V2, G, perm = reorder(V, F)
    assert _same_oriented_faces(perm[G], F)
    np.testing.assert_array_equal(G.min(axis=1), G[:, 0])


@pytest.mark.parametrize(
    "name",
    [
        "soup",
        "nonmanifold",
        "degenerate",
        "duplicate",
        "flipped",
        "gaps",
        "single",
        "components",
        "fan",
    ],
)
def test_awkward_face_lists_roundtrip(name):
    rng = np.random.default_rng(1)
    if name == "soup":  # every face its own vertices (unwelded STL)
        F = np.arange(300).reshape(100, 3)[rng.permutation(100)]
    elif name == "nonmanifold":  # five triangles on one edge, plus a grid
        F = np.r_[_grid(8), np.c_[np.zeros(5, int), np.ones(5, int), 64 + np.arange(5)]]
    elif name == "degenerate":
        F = np.r_[_grid(6), [[3, 3, 4], [5, 5, 5], [7, 8, 7]]]
    elif name == "duplicate":
        G = _grid(6)
        F = np.r_[G, G[:10], G[5:8, ::-1]]
    elif name == "flipped":
        G = _grid(10)
        flip = rng.random(len(G)) < 0.5
        G[flip] = G[flip][:, ::-1]
        F = G
    elif name == "gaps":  # unreferenced labels, largest label well below n
        F = 3 * _grid(7) + 5
    elif name == "single":
        F = np.array([[2, 0, 1]])
    elif name == "components":
        F = np.r_[_grid(5), 25 + _grid(4), 41 + _grid(3)][rng.permutation(32 + 18 + 8)]
    else:  # a vertex of degree 5000 (a cone of a fine circle)
        k = 5000
        F = np.c_[np.zeros(k, int), 1 + np.arange(k), 1 + (np.arange(k) + 1) % k]
    n = int(F.max()) + 4
    _traversal_roundtrip(F, n)
    _roundtrip(F, n)
    V = rng.normal(size=(n, 3))
    V2, G, perm = reorder(V, F)
    assert _same_oriented_faces(perm[G], F)
    _roundtrip(G, n)


def test_old_delta_streams_still_decode():
    V, F = load_fandisk()
    np.testing.assert_array_equal(decode_faces(_encode_delta(F), len(V), len(F)), F)


def test_corrupted_traversal_streams_are_refused_or_stay_in_range():
    rng = np.random.default_rng(7)
    F = _grid(12)
    lab = rng.permutation(144)
    F = lab[F][rng.permutation(len(F))]
    buf = _conn_traverse.encode(F)
    refused = 0
    for trial in range(300):
        b = bytearray(buf)
        if trial % 3 == 0:
            b = b[: rng.integers(1, len(b))]
        else:
            for _ in range(rng.integers(1, 4)):
                i = rng.integers(1, len(b))
                b[i] ^= 1 << int(rng.integers(0, 8))
        try:
            G = decode_faces(bytes(b), 144, len(F))
        except InvalidInputError:
            refused += 1
            continue
        assert G.shape == F.shape and G.min() >= 0 and G.max() < 144
    assert refused > 150


def test_wrong_counts_are_refused():
    F = _grid(5)
    buf = _conn_traverse.encode(F)
    with pytest.raises(InvalidInputError):
        decode_faces(buf, 10, len(F))  # fewer vertices than the labels need
    with pytest.raises(InvalidInputError):
        decode_faces(buf, 25, len(F) + 7)


def _shared_meshes():
    root = data_dir()
    if root is None:
        return []
    pats = ("meshes/*.off", "meshes/*.obj", "cad/*.obj", "cad/*.STL", "cad/*.ply", "holes/*.off")
    return sorted(p for pat in pats for p in Path(root).glob(pat))


@pytest.mark.parametrize("path", _shared_meshes(), ids=lambda p: p.name)
def test_every_shared_mesh_roundtrips(path):
    from spectrageo.io import read_mesh

    mesh = read_mesh(path)
    F = np.asarray(mesh.faces, dtype=np.int64)
    n = len(mesh.vertices)
    buf = _roundtrip(F, n)
    assert len(buf) <= len(_encode_delta(F))
    V2, G, perm = reorder(mesh.vertices, F)
    assert _same_oriented_faces(perm[G], F)
    rbuf = _roundtrip(G, n)
    assert len(rbuf) <= len(buf)  # reorder keeps the input's order when that codes smaller


def test_version_1_files_still_read():
    from spectrageo import compress
    from spectrageo.compress import _container

    V, F = load_fandisk()
    data = compress.encode(V, F)
    assert data[4] == 4  # version 4: compact header, chained chunk checksums
    V2, F2 = compress.decode(data)
    # the same content as version 1 writes it (version byte, checksums of each payload alone)
    c = _container.parse(data)
    c.version = 1
    old = c.to_bytes()
    assert old[4] == 1 and len(old) > len(data)
    V1, F1 = compress.decode(old)
    np.testing.assert_array_equal(F1, F)
    np.testing.assert_array_equal(V1, V2)


#: a 5 x 5 grid, labels and face order shuffled (seed 3), coded by the static-model traversal
#: format (first byte 0x40) before the adaptive one replaced it
_STATIC_FORMAT = bytes.fromhex(
    "4019192c020d1f1f011f03010300140e1100020000000000000000000001020102000106000000000001020102"
    "010101010a00000000000000000001000000000103000001000204000001010001030000011906060303030703"
    "200b00000001180204000000011807010202060308022003060a10002aeb0ed3410f4041d1afa06063514a8c80"
    "0000d085830a89cc5713ac05fcfa086406f2343b20341bc7a8ee7bda2ff766beb878f64b"
)


def test_static_format_streams_still_decode():
    rng = np.random.default_rng(3)
    F = rng.permutation(25)[_grid(5)][rng.permutation(32)]
    assert _STATIC_FORMAT[0] == _conn_traverse.MARKER
    np.testing.assert_array_equal(decode_faces(_STATIC_FORMAT, 25, 32), F)
    assert _conn_traverse.encode(F)[0] == _conn_traverse.MARKER_ADAPTIVE


def test_adaptive_contexts_make_canonical_connectivity_cheap():
    # a closed, regular mesh in its own traversal order: Draco's edgebreaker spends about 1.5
    # bits per vertex on such meshes; the gate-valence contexts bring ours below that
    V, F = load_fandisk()
    _, G, _ = reorder(V, F)
    buf = _roundtrip(G, len(V))
    assert 8 * len(buf) / len(V) < 1.45
