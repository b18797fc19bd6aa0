"""Lossless connectivity coding that keeps the face order and the corner order of every face.

The encoder writes two schemes and keeps the smaller; the first byte tells them apart:

- the traversal code of :mod:`._conn_traverse` (first byte ``0x40``-``0x43``);
- the delta code (first byte 1-8, the index width): each face ``(a, b, c)`` becomes ``a`` minus
  the previous face's first corner, ``b - a`` and ``c - a`` (zigzag), split into byte planes and
  compressed with zstd; it wins on tiny meshes and some files ordered by one sweep.

:func:`reorder` is the ``--reorder`` option: vertices and faces in the traversal's own order,
each face rotated to start at its smallest index, or the input's order where that codes smaller.
"""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from . import _conn_traverse
from ._container import Reader, varint
from ._entropy import ZSTD_LEVEL, zstd_compress, zstd_decompress

#: bytes of index differences up to which the delta code uses zstd's strongest level (19);
#: above it level 12 (437k-vertex dragon: 1.4 s instead of 7.8 s, 3 % larger)
DELTA_STRONG_MAX = 1 << 20


def _zigzag(d: np.ndarray) -> np.ndarray:
    return ((d << 1) ^ (d >> 63)).astype(np.uint64)


def _unzigzag(u: np.ndarray) -> np.ndarray:
    u = u.astype(np.int64)
    return (u >> 1) ^ -(u & 1)


def encode_faces(F: np.ndarray, traversed=None) -> bytes:
    """The smaller of the traversal code and the delta code of ``F`` (``traversed``: its
    :func:`._conn_traverse.traverse`, when the caller has it)."""
    delta = _encode_delta(F)
    if len(F) == 0:
        return delta
    traversal = _conn_traverse.encode(F, traversed)
    return traversal if len(traversal) < len(delta) else delta


def _encode_delta(F: np.ndarray) -> bytes:
    F = np.asarray(F, dtype=np.int64)
    d = np.empty_like(F)
    d[:, 0] = np.diff(np.r_[0, F[:, 0]])
    d[:, 1] = F[:, 1] - F[:, 0]
    d[:, 2] = F[:, 2] - F[:, 0]
    u = _zigzag(d.ravel())
    nbytes = max(1, (int(u.max()).bit_length() + 7) // 8) if u.size else 1
    planes = b"".join(
        ((u >> np.uint64(8 * k)) & np.uint64(255)).astype(np.uint8).tobytes() for k in range(nbytes)
    )
    # zstd's strongest levels cost seconds on large face lists for a few percent
    level = ZSTD_LEVEL if len(planes) <= DELTA_STRONG_MAX else 12
    return varint(nbytes) + zstd_compress(planes, level)


def decode_faces(buf: bytes, n_vertices: int, n_faces: int) -> np.ndarray:
    if len(buf) and buf[0] in _conn_traverse.MARKERS and n_faces > 0:
        F = _conn_traverse.decode(buf, n_vertices, n_faces)
        if F.min() < 0 or F.max() >= n_vertices:  # pragma: no cover - decode checks the range
            raise InvalidInputError(".sgc connectivity is malformed (vertex index out of range).")
        return F
    r = Reader(buf, "connectivity")
    nbytes = r.varint()
    if not 1 <= nbytes <= 8:
        raise InvalidInputError(".sgc connectivity is malformed (bad index width).")
    size = 3 * n_faces * nbytes
    raw = zstd_decompress(r.rest(), size, "connectivity")
    if len(raw) != size:
        raise InvalidInputError(".sgc connectivity is malformed (wrong number of indices).")
    planes = np.frombuffer(raw, dtype=np.uint8).reshape(nbytes, 3 * n_faces)
    u = np.zeros(3 * n_faces, dtype=np.uint64)
    for k in range(nbytes):
        u |= planes[k].astype(np.uint64) << np.uint64(8 * k)
    d = _unzigzag(u).reshape(n_faces, 3)
    F = np.empty_like(d)
    F[:, 0] = np.cumsum(d[:, 0])
    F[:, 1] = F[:, 0] + d[:, 1]
    F[:, 2] = F[:, 0] + d[:, 2]
    if F.min() < 0 or F.max() >= n_vertices:
        raise InvalidInputError(".sgc connectivity is malformed (vertex index out of range).")
    return F


def reorder(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Codec-friendly order: returns ``(V', F', perm)`` with ``V' = V[perm]``.

    The traversal's order, unless the input's own order already codes smaller (files written
    along one sweep, e.g. range maps, can cost well under a bit per vertex); then the input is
    returned with the identity permutation.
    """
    return reorder_coded(V, F)[:3]


def reorder_coded(V: np.ndarray, F: np.ndarray):
    """:func:`reorder` and the connectivity code of its faces: ``(V', F', perm, code)``."""
    F = np.asarray(F, dtype=np.int64)
    identity = np.arange(V.shape[0], dtype=np.int64)
    if len(F) == 0:
        return V, F, identity, encode_faces(F)
    traversed = _conn_traverse.traverse(F)  # one traversal for both orders
    code = encode_faces(F, traversed)
    perm, G = _conn_traverse.canonical(F, V.shape[0], traversed)
    code_g = encode_faces(G)
    if len(code) <= len(code_g):
        return V, F, identity, code
    return V[perm], G, perm, code_g
