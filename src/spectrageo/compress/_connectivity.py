"""Lossless connectivity coding that keeps the face order and the corner order of every face.

Every face ``(a, b, c)`` becomes three integers: ``a`` minus the first corner of the previous face,
``b - a`` and ``c - a`` (zigzag mapped to unsigned), split into byte planes (all low bytes, then
the next bytes, ...) and compressed with zstd. Meshes whose faces follow a traversal (most exported
files) give small differences and compress well; a random face order costs close to the
``log2(m!)`` bits that any order-preserving code must spend.

:func:`reorder` is the ``--reorder`` option: vertices in reverse Cuthill-McKee order (a
breadth-first order over the edges), each face rotated to start at its smallest index (orientation
kept) and the faces sorted, which makes the differences small on every mesh.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .._errors import InvalidInputError
from ._container import Reader, varint
from ._entropy import zstd_compress, zstd_decompress


def _zigzag(d: np.ndarray) -> np.ndarray:
    return ((d << 1) ^ (d >> 63)).astype(np.uint64)


def _unzigzag(u: np.ndarray) -> np.ndarray:
    u = u.astype(np.int64)
    return (u >> 1) ^ -(u & 1)


def encode_faces(F: np.ndarray) -> bytes:
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
    return varint(nbytes) + zstd_compress(planes)


def decode_faces(buf: bytes, n_vertices: int, n_faces: int) -> np.ndarray:
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
    """Codec-friendly order: returns ``(V', F', perm)`` with ``V' = V[perm]``."""
    n = V.shape[0]
    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    C = sp.csr_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    C = ((C + C.T) > 0).astype(np.float64).tocsr()
    perm = reverse_cuthill_mckee(C, symmetric_mode=True).astype(np.int64)[::-1].copy()
    inv = np.empty(n, dtype=np.int64)
    inv[perm] = np.arange(n)
    G = inv[F]
    rot = np.argmin(G, axis=1)
    idx = (rot[:, None] + np.arange(3)[None, :]) % 3
    G = np.take_along_axis(G, idx, axis=1)
    G = G[np.lexsort((G[:, 2], G[:, 1], G[:, 0]))]
    return V[perm], G, perm
