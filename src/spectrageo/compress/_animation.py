"""Compression of mesh animations with fixed connectivity into ``.sga`` files (Section 5.2.2).

Delta coordinates projected on eigen-trajectories (Eq. 5.46-5.52). For every coordinate ``x``
of a block of ``k_f`` frames, ``A_x`` (k_f, n) holds the trajectories; the eigenvectors ``U_x``
of ``R_x = A_x A_x^T`` (Eq. 5.46) are the eigen-trajectories, ``delta_x = L A_x^T`` (Eq. 5.47,
``L = D - C`` the binary, unnormalised mesh Laplacian) the delta coordinates and
``U_x^T delta_x^T`` (Eq. 5.48) what is coded. The decoder rebuilds ``delta~ = U_x U^_x`` and solves
the sparse least-squares system ``[L; I_a] A~^T = [delta~; Q(A_a^T)]`` (Eq. 5.50-5.51) with one
factorisation of ``L^T L + I_a^T I_a`` for all frames. Every floating-point step of the decoder
(dictionary QR, the product ``U_x U^_x``, the sparse Cholesky and its solves) runs in a fixed
order without BLAS or LAPACK (:mod:`spectrageo.linalg._fixed`), so a file decodes to the same
bits on every machine.

Methods (the thesis's variants, Section 5.2.2, Table 5.12):

* ``pca``: the whole sequence is one block; the first ``k_l`` rows of ``U^_x`` (Eq. 5.49) are
  stored at 16-bit fixed precision (the "lossless" quantisation Eq. 5.52 assumes), the rest
  dropped. The rate knob is the number of kept coefficients (rows in order, the last one possibly
  cut), so a rate target is met continuously. No anchors: one vertex per connected component
  fixes the translation that ``L`` cannot see (Eq. 5.50).
* ``pca-q``: as ``pca`` but every row is uniformly quantised with the step ``s`` and entropy coded
  (quantised Laplace model per row, :mod:`._entropy`); a rate-distortion test drops the rows (and
  their dictionary columns) that cost more bits than the error they remove.
* ``pca-qs``: ``pca-q`` with anchor points (1 % of the vertices, farthest-point sampled on the
  first frame), reconstructed *serially*: one least-squares solve per frame (Eq. 5.51).
* ``pca-qp``: the same stream as ``pca-qs`` reconstructed in *parallel*: one multi-right-hand-side
  solve for all frames (identical result up to rounding; faster).
* ``blocks``: ``n_b`` blocks of ``k_f`` consecutive frames (default 16), the eigen-trajectories of
  each block found by orthogonal iterations started from those of the previous block (the
  coherence of consecutive blocks, Section 5.2.2 "Speed-up Process using OI"), anchors, parallel
  reconstruction. Memory is bounded by the block size.

Dictionaries ``U_x`` are quantised column by column with a step tied to the energy of the row
they multiply, and orthonormalised again (QR) on both sides, so the coefficients are exact
projections. Every block is coded independently (the thesis codes the difference of consecutive
dictionaries; here every block stays decodable on its own, which the frame index needs).

File layout (``.sga``): a sequence of :mod:`._container` segments, each the ordinary container
(magic, version, header, checksummed chunks) with an animation method id:

1. the stream header: kind 0, frame count, block size, step, anchors; chunks: connectivity
   (:mod:`._connectivity`), anchor indices;
2. one segment per block: kind 1, block number, first frame, frame count; chunks: dictionaries,
   coefficients, anchor trajectories;
3. the frame index (files, not live streams): kind 2; one chunk with the first frame, frame count,
   byte offset and length of every block, so a decoder can start at any block.

A truncated file decodes every complete block with ``partial=True``; corrupted or foreign bytes
raise :class:`~spectrageo.InvalidInputError`.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames
from . import _connectivity, _container
from ._container import Reader, varint
from ._entropy import decode_groups, encode_groups, zstd_compress, zstd_decompress

METHODS = ("pca", "pca-q", "pca-qs", "pca-qp", "blocks", "pca-spectral")
#: with the scalable layered codec of Section 5.2.4 (:mod:`._layered`)
ALL_METHODS = (*METHODS, "layered")
#: method ids in the container's method byte; the animation ids start at 16, clear of the static
#: codecs' ids (0-2) that share the container.
METHOD_IDS = {m: _container.METHOD_IDS[m] for m in ALL_METHODS}

TAG_CONNECTIVITY = 1
TAG_ANCHOR_INDEX = 2
TAG_BASIS = 3
TAG_COEFF = 4
TAG_ANCHOR_POS = 5
TAG_INDEX = 6
KIND_HEADER, KIND_BLOCK, KIND_INDEX = 0, 1, 2

#: default quantisation step (fraction of the bounding-box diagonal, delta-coordinate domain)
DEFAULT_STEP = 2e-4
#: default block size of ``blocks`` (frames)
DEFAULT_BLOCK = 16
#: fraction of vertices used as anchors by pca-qs, pca-qp and blocks (the thesis's 1 %)
DEFAULT_ANCHORS = 0.01
#: anchor quantisation step relative to the coefficient step
DEFAULT_ANCHOR_RATIO = 0.5
#: fixed precision of ``pca`` coefficients and dictionaries (Eq. 5.52 counts 16 bits)
PCA_BITS = 16
_MAX_FRAMES = 1 << 24

_HEAD = struct.Struct("<BIIIdffBBH")  # kind, T, block, n_anchors, step, ratio, weight, basis, it, -
_BLOCK = struct.Struct("<BIIId")  # kind, block number, first frame, frame count, step
_KIND = struct.Struct("<B")


# ----------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class Params:
    """Stream parameters stored in the header segment."""

    method: str
    n_frames: int  # 0: unknown (a live stream)
    block: int
    n_anchors: int
    step: float  # pca: number of kept coefficients per coordinate (an integer)
    anchor_ratio: float
    weight: float
    basis: int  # 0 exact eigen-decomposition, 1 orthogonal iterations
    n_iter: int

    def to_bytes(self) -> bytes:
        return _HEAD.pack(
            KIND_HEADER,
            self.n_frames,
            self.block,
            self.n_anchors,
            self.step,
            self.anchor_ratio,
            self.weight,
            self.basis,
            self.n_iter,
            0,
        )

    @classmethod
    def from_bytes(cls, method: str, b: bytes) -> Params:
        if len(b) != _HEAD.size or b[0] != KIND_HEADER:
            raise InvalidInputError(".sga stream header is malformed.")
        _k, T, block, na, step, ratio, weight, basis, n_iter, _ = _HEAD.unpack(b)
        if not (
            1 <= block <= _MAX_FRAMES
            and T <= _MAX_FRAMES
            and math.isfinite(step)
            and step > 0
            and math.isfinite(ratio)
            and ratio > 0
            and math.isfinite(weight)
            and weight > 0
            and basis in (0, 1)
        ):
            raise InvalidInputError(".sga stream header has invalid parameters.")
        return cls(method, T, block, na, step, ratio, weight, basis, n_iter)


def _anchored(method: str) -> bool:
    """Methods with the 1 % anchor points of Eq. (5.51) (the others anchor one vertex per component)."""
    return method in ("pca-qs", "pca-qp", "blocks")


def _anchor_step(method: str, step: float, ratio: float) -> float:
    """Quantisation step of the anchor trajectories (``pca``: fixed 16-bit-like precision)."""
    return 2.0**-PCA_BITS if method == "pca" else step * ratio


# ----------------------------------------------------------------------------- geometry helpers
def _laplacian(F: np.ndarray, n: int) -> sp.csr_matrix:
    """Binary unnormalised ``L = D - C`` of the mesh edges (Eq. 4.1)."""
    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    C = sp.csr_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    C = ((C + C.T) > 0).astype(np.float64).tocsr()
    return (sp.diags(np.asarray(C.sum(axis=1)).ravel()) - C).tocsr()


def _component_anchors(L: sp.csr_matrix) -> np.ndarray:
    """One vertex per connected component (isolated vertices included): the first of each."""
    from scipy.sparse.csgraph import connected_components

    _k, lab = connected_components(L, directed=False)
    _u, first = np.unique(lab, return_index=True)
    return np.sort(first).astype(np.int64)


def _fps(V: np.ndarray, k: int) -> np.ndarray:
    """Farthest-point sampling of ``k`` vertices (deterministic: starts at vertex 0)."""
    n = V.shape[0]
    k = min(k, n)
    out = np.empty(k, dtype=np.int64)
    d = np.full(n, np.inf)
    i = 0
    for j in range(k):
        out[j] = i
        d = np.minimum(d, np.sum((V - V[i]) ** 2, axis=1))
        i = int(np.argmax(d))
    return out


def choose_anchors(V0: np.ndarray, L: sp.csr_matrix, fraction: float) -> np.ndarray:
    """Anchor vertices: farthest-point samples of the first frame plus one per component."""
    k = max(1, int(math.ceil(fraction * V0.shape[0]))) if fraction > 0 else 0
    a = _fps(V0, k) if k else np.zeros(0, dtype=np.int64)
    return np.unique(np.r_[a, _component_anchors(L)]).astype(np.int64)


class _Solver:
    """Factorisation of ``L^T L + w^2 I_a^T I_a`` for Eq. (5.51), reused for every frame.

    The fixed-order sparse Cholesky of :mod:`spectrageo.linalg._fixed` (minimum-degree order,
    supernodal factor, no BLAS or LAPACK), so that a file decodes to the same bits on every
    machine. ``L`` is the binary ``D - C``: the matrix is formed exactly. Right-hand sides
    are solved 64 columns at a time (each column's result does not depend on the others, so
    the serial and parallel reconstructions agree bit for bit).
    """

    def __init__(self, L: sp.csr_matrix, anchors: np.ndarray, weight: float) -> None:
        from ..linalg._fixed import SparseCholesky

        n = L.shape[0]
        self.L = L
        self.anchors = anchors
        self.w2 = weight * weight
        d = np.zeros(n)
        d[anchors] = self.w2
        try:
            self.chol = SparseCholesky(L.T @ L + sp.diags(d))
        except np.linalg.LinAlgError as exc:  # cannot happen with one anchor per component
            raise InvalidInputError(f".sga reconstruction system is singular ({exc}).") from None

    def solve(self, delta: np.ndarray, anchor_pos: np.ndarray) -> np.ndarray:
        """``delta`` (n, c) and ``anchor_pos`` (n_a, c) -> positions (n, c)."""
        rhs = np.asarray(self.L.T @ delta)
        rhs[self.anchors] += self.w2 * anchor_pos
        out = np.empty_like(rhs)
        for j in range(0, rhs.shape[1], 64):
            out[:, j : j + 64] = self.chol.solve(rhs[:, j : j + 64])
        return out


# ----------------------------------------------------------------------------- eigen-trajectories
def eigen_trajectories(A: np.ndarray, U0: np.ndarray | None = None, n_iter: int = 0) -> np.ndarray:
    """Eigenvectors of ``R = A A^T`` (Eq. 5.46), (k_f, k_f), by decreasing eigenvalue.

    With ``U0`` (the previous block's basis, same size) and ``n_iter > 0`` the basis is found by
    ``n_iter`` orthogonal iterations ``U <- qr(R U)`` started from ``U0`` (Section 5.2.2, OI in
    blocks); otherwise by a dense symmetric eigen-decomposition. Signs: largest entry positive
    (exact), or agreeing with ``U0`` (OI).
    """
    R = A @ A.T
    if U0 is not None and n_iter > 0 and U0.shape == R.shape:
        U = U0
        for _ in range(n_iter):
            U, _r = np.linalg.qr(R @ U)
        s = np.sign(np.sum(U * U0, axis=0))
        s[s == 0] = 1.0
        return U * s
    w, U = np.linalg.eigh(R)
    U = U[:, ::-1]
    idx = np.argmax(np.abs(U), axis=0)
    s = np.sign(U[idx, np.arange(U.shape[1])])
    s[s == 0] = 1.0
    return U * s


def _entropy_bits(q: np.ndarray) -> float:
    """Empirical zero-order entropy of integer symbols, in bits (an estimate of the coded size)."""
    if q.size == 0:
        return 0.0
    _u, c = np.unique(q, return_counts=True)
    p = c / q.size
    return float(-(c * np.log2(p)).sum())


def _orthonormal(Uq: np.ndarray) -> np.ndarray:
    """Deterministic re-orthonormalisation of dequantised dictionary columns: the ``Q`` of a
    Householder QR with ``R``'s diagonal made positive, summed in a fixed order
    (:func:`spectrageo.linalg._fixed.orthonormal_columns`, no LAPACK), the same at both ends."""
    from ..linalg._fixed import orthonormal_columns

    return orthonormal_columns(Uq)


# ----------------------------------------------------------------------------- block coding
@dataclass
class _BlockPlan:
    """Unquantised analysis of one block: dictionaries and projections per coordinate."""

    t0: int
    nf: int
    U: list[np.ndarray]  # 3 x (nf, nf)
    P: list[np.ndarray]  # 3 x (nf, n)  U^T delta^T
    delta: list[np.ndarray]  # 3 x (n, nf)
    anchor_pos: np.ndarray  # (nf, n_a, 3)


def analyse_block(
    X: np.ndarray, L: sp.csr_matrix, anchors: np.ndarray, t0: int, prev=None, n_iter: int = 0
) -> _BlockPlan:
    """Eq. (5.46)-(5.48) for the normalised frames ``X`` (nf, n, 3) of one block."""
    nf = X.shape[0]
    Us, Ps, Ds = [], [], []
    for c in range(3):
        A = np.ascontiguousarray(X[:, :, c])
        U = eigen_trajectories(A, None if prev is None else prev.U[c], n_iter)
        D = np.asarray(L @ A.T)  # (n, nf)
        Us.append(U)
        Ps.append(U.T @ D.T)
        Ds.append(D)
    return _BlockPlan(t0, nf, Us, Ps, Ds, X[:, anchors, :].copy())


def _select_rows(P: np.ndarray, s: float, n: int, nf: int, rd: float) -> np.ndarray:
    """Rows of ``U^_x`` worth their bits: error removed > lambda * (coefficient + column bits).

    ``lambda = rd * ln2/6 * s^2`` is the slope of the uniform quantiser's rate-distortion curve;
    the coefficient bits are the rows' empirical entropies, a column costs about 8 bits a frame.
    """
    lam = rd * math.log(2) / 6.0 * s * s
    Q = np.rint(P / s)
    gain = np.sum(P * P, axis=1) - np.sum((P - s * Q) ** 2, axis=1)
    live = np.flatnonzero(Q.any(axis=1))
    if live.size == 0:
        return live.astype(np.int64)
    q = Q[live].astype(np.int64)
    off = q.min()
    width = int(q.max() - off) + 1
    bits = np.empty(live.size)
    if width * live.size <= 1 << 24:
        cnt = np.zeros((live.size, width))
        np.add.at(cnt, (np.repeat(np.arange(live.size), q.shape[1]), (q - off).ravel()), 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            pl = np.where(cnt > 0, cnt * np.log2(cnt / q.shape[1]), 0.0)
        bits[:] = -pl.sum(axis=1)
    else:
        bits[:] = [_entropy_bits(r) for r in q]
    keep = gain[live] > lam * (bits + nf * 8.0)
    return live[keep].astype(np.int64)


def _basis_steps(P_rows: np.ndarray, s: float, n: int, nf: int) -> np.ndarray:
    """Quantisation step of every kept dictionary column: its error ~ half the coefficient error."""
    norms = np.sqrt(np.sum(P_rows * P_rows, axis=1))
    st = 0.5 * s * math.sqrt(n / max(nf, 1)) / np.maximum(norms, 1e-30)
    st = np.clip(st, 2.0**-20, 0.25)
    return st.astype(np.float32).astype(np.float64)


def encode_block(plan: _BlockPlan, method: str, step: float, ratio: float, rd: float) -> list:
    """Chunks of one block segment for the quantisation ``step`` (or kept count for ``pca``)."""
    nf = plan.nf
    n = plan.P[0].shape[1]
    basis_head = bytearray()
    basis_syms, basis_groups = [], []
    coef_head = bytearray()
    coef_syms, coef_groups = [], []
    g_basis = g_coef = 0
    fixed = method == "pca"
    for c in range(3):
        U, P, D = plan.U[c], plan.P[c], plan.delta[c]
        if fixed:
            count = min(int(step), nf * n)
            k = -(-count // n)
            rows = np.arange(k)
            st = np.full(k, 2.0 ** (1 - PCA_BITS))
        else:
            rows = _select_rows(P, step, n, nf, rd)
            k = rows.size
            st = _basis_steps(P[rows], step, n, nf)
        Uk = U[:, rows]
        qU = np.rint(Uk / st).astype(np.int64)
        Q = _orthonormal(qU * st)
        basis_head += varint(k) + st.astype("<f4").tobytes() + rows.astype("<u4").tobytes()
        basis_syms.append(qU.T.ravel())
        basis_groups.append(np.repeat(np.arange(k) + g_basis, nf))
        g_basis += k
        Pk = Q.T @ D.T  # exact projection on the transmitted dictionary (k, n)
        if fixed:
            flat = Pk.ravel()[:count]
            lo = np.float32(flat.min() if flat.size else 0.0)
            hi = np.float32(flat.max() if flat.size else 0.0)
            span = float(hi) - float(lo)
            qs = (
                np.rint((flat - float(lo)) / span * ((1 << PCA_BITS) - 1)).astype("<u2")
                if span > 0
                else np.zeros(flat.size, "<u2")
            )
            coef_head += varint(count) + np.array([lo, hi], "<f4").tobytes()
            coef_syms.append(qs.tobytes())
        else:
            q = np.rint(Pk / step).astype(np.int64)
            coef_syms.append(q.ravel())
            coef_groups.append(np.repeat(np.arange(k) + g_coef, n))
            g_coef += k
    basis = bytes(basis_head) + encode_groups(
        np.concatenate(basis_syms), np.concatenate(basis_groups), g_basis
    )
    if fixed:
        coef = bytes(coef_head) + zstd_compress(b"".join(coef_syms))
    else:
        coef = encode_groups(np.concatenate(coef_syms), np.concatenate(coef_groups), g_coef)
    chunks = [(TAG_BASIS, basis), (TAG_COEFF, coef)]
    sa = _anchor_step(method, step, ratio)
    qa = np.rint(plan.anchor_pos / sa).astype(np.int64)  # (nf, na, 3)
    d = np.diff(qa, axis=0, prepend=np.zeros((1,) + qa.shape[1:], np.int64))
    grp = np.broadcast_to(
        (np.minimum(np.arange(nf), 1)[:, None, None] * 3 + np.arange(3)[None, None, :]),
        d.shape,
    )
    chunks.append((TAG_ANCHOR_POS, encode_groups(d.ravel(), grp.ravel(), 6)))
    return chunks


def decode_block(chunks, p: Params, nf: int, n: int, anchors: np.ndarray, step: float) -> tuple:
    """Dequantised ``(delta~ list of (n, nf), anchor positions (nf, n_a, 3) or None)``.

    ``delta~ = U_x U^_x`` (Eq. 5.49-5.50) with the fixed-order product of
    :func:`spectrageo.linalg._fixed.matmul` (no BLAS), so that every machine gets the same bits.
    """
    from ..linalg._fixed import matmul

    tags = [t for t, _ in chunks]
    want = [TAG_BASIS, TAG_COEFF, TAG_ANCHOR_POS]
    if tags != want:
        raise InvalidInputError(f".sga block has chunks {tags}; expected {want}.")
    r = Reader(chunks[0][1], "dictionary")
    ks, steps, rows_all = [], [], []
    for _c in range(3):
        k = r.varint()
        if k > nf:
            raise InvalidInputError(".sga dictionary is malformed (too many columns).")
        st = np.frombuffer(r.take(4 * k), "<f4").astype(np.float64)
        rows = np.frombuffer(r.take(4 * k), "<u4").astype(np.int64)
        if not (np.isfinite(st).all() and (st > 0).all()) or (rows >= nf).any():
            raise InvalidInputError(".sga dictionary is malformed (bad steps or rows).")
        ks.append(k)
        steps.append(st)
        rows_all.append(rows)
    groups = np.concatenate([np.repeat(np.arange(sum(ks)), nf)]) if sum(ks) else np.zeros(0, int)
    qU = decode_groups(r.rest(), groups, sum(ks), "dictionary")
    Qs = []
    pos = 0
    for c in range(3):
        k = ks[c]
        Uq = qU[pos : pos + k * nf].reshape(k, nf).T * steps[c]
        pos += k * nf
        Qs.append(_orthonormal(Uq))
    deltas = []
    if p.method == "pca":
        r = Reader(chunks[1][1], "coefficients")
        heads = []
        for c in range(3):
            count = r.varint()
            lo, hi = np.frombuffer(r.take(8), "<f4").astype(np.float64)
            if count > ks[c] * n or count <= (ks[c] - 1) * n and ks[c] > 0 or not math.isfinite(hi):
                raise InvalidInputError(".sga coefficients are malformed (bad count).")
            heads.append((count, lo, hi))
        total = sum(h[0] for h in heads)
        raw = zstd_decompress(r.rest(), 2 * total, "coefficients")
        if len(raw) != 2 * total:
            raise InvalidInputError(".sga coefficients are malformed (wrong size).")
        vals = np.frombuffer(raw, "<u2").astype(np.float64)
        pos = 0
        for c in range(3):
            count, lo, hi = heads[c]
            P = np.zeros(ks[c] * n)
            P[:count] = lo + vals[pos : pos + count] * ((hi - lo) / ((1 << PCA_BITS) - 1))
            pos += count
            deltas.append(matmul(Qs[c], P.reshape(ks[c], n)).T)
    else:
        groups = np.repeat(np.arange(sum(ks)), n)
        q = decode_groups(chunks[1][1], groups, sum(ks), "coefficients").astype(np.float64)
        pos = 0
        for c in range(3):
            k = ks[c]
            P = q[pos : pos + k * n].reshape(k, n) * step
            pos += k * n
            deltas.append(matmul(Qs[c], P).T)
    na = anchors.size
    grp = np.broadcast_to(
        (np.minimum(np.arange(nf), 1)[:, None, None] * 3 + np.arange(3)[None, None, :]),
        (nf, na, 3),
    )
    d = decode_groups(chunks[2][1], grp.ravel(), 6, "anchor trajectories")
    apos = np.cumsum(d.reshape(nf, na, 3), axis=0) * _anchor_step(p.method, step, p.anchor_ratio)
    return deltas, apos


# ----------------------------------------------------------------------------- segments
def _segment_end(data: bytes, pos: int) -> int | None:
    """End offset of the container segment starting at ``pos``; None when it is cut short.

    The segment header's checksum is verified first, so a damaged length cannot pose as a cut.
    """
    fixed = _container._FIXED
    if len(data) < pos + 4:
        return None
    if data[pos : pos + 4] != _container.MAGIC:
        raise InvalidInputError(f".sga data is corrupted (no segment starts at byte {pos}).")
    if len(data) < pos + fixed.size + 2:
        return None
    (plen,) = struct.unpack_from("<H", data, pos + fixed.size)
    end = pos + fixed.size + 2 + plen
    if len(data) < end + 4:
        return None
    (crc,) = struct.unpack_from("<I", data, end)
    if zlib.crc32(data[pos:end]) != crc:
        raise InvalidInputError(f".sga segment header at byte {pos} is corrupted.")
    n_chunks = data[pos + 7]
    p = end + 4
    for _ in range(n_chunks):
        if len(data) < p + _container._CHUNK.size:
            return None
        _tag, length, _crc = _container._CHUNK.unpack_from(data, p)
        p += _container._CHUNK.size + length
        if p > len(data):
            return None
    return p


def _segment(method, n, m, origin, scale, params: bytes, chunks) -> bytes:
    return _container.Container(method, n, m, origin, scale, params, False, chunks).to_bytes()


def header_segment(method, n, m, origin, scale, p: Params, F, anchors) -> bytes:
    conn = _connectivity.encode_faces(F)
    a = np.diff(np.r_[-1, anchors]) - 1
    idx = varint(anchors.size) + zstd_compress(a.astype("<u4").tobytes())
    return _segment(
        method,
        n,
        m,
        origin,
        scale,
        p.to_bytes(),
        [(TAG_CONNECTIVITY, conn), (TAG_ANCHOR_INDEX, idx)],
    )


def block_segment(method, n, m, origin, scale, b: int, t0: int, nf: int, step, chunks) -> bytes:
    return _segment(method, n, m, origin, scale, _BLOCK.pack(KIND_BLOCK, b, t0, nf, step), chunks)


def index_segment(method, n, m, origin, scale, entries) -> bytes:
    body = varint(len(entries)) + b"".join(
        varint(t0) + varint(nf) + varint(off) + varint(ln) for t0, nf, off, ln in entries
    )
    return _segment(method, n, m, origin, scale, _KIND.pack(KIND_INDEX), [(TAG_INDEX, body)])


@dataclass
class StreamState:
    """What the decoder knows after the header segment."""

    method: str
    n: int
    m: int
    origin: np.ndarray
    scale: float
    params: Params
    F: np.ndarray
    anchors: np.ndarray
    L: sp.csr_matrix
    solver: _Solver


def read_header(c: _container.Container) -> StreamState:
    if c.method not in METHODS:
        raise InvalidInputError(
            f"this is a compressed static mesh or an unknown method ({c.method!r}), not an "
            "animation; use spectrageo.compress.decode."
        )
    p = Params.from_bytes(c.method, c.params)
    if [t for t, _ in c.chunks] != [TAG_CONNECTIVITY, TAG_ANCHOR_INDEX]:
        raise InvalidInputError(".sga stream header lacks its connectivity or anchors.")
    F = _connectivity.decode_faces(c.chunks[0][1], c.n_vertices, c.n_faces)
    r = Reader(c.chunks[1][1], "anchor index")
    na = r.varint()
    if na > c.n_vertices:
        raise InvalidInputError(".sga anchor index is malformed.")
    raw = zstd_decompress(r.rest(), 4 * na, "anchor index")
    if len(raw) != 4 * na:
        raise InvalidInputError(".sga anchor index is malformed.")
    anchors = np.cumsum(np.frombuffer(raw, "<u4").astype(np.int64) + 1) - 1
    if na and (anchors[-1] >= c.n_vertices):
        raise InvalidInputError(".sga anchor index is malformed (index out of range).")
    L = _laplacian(F, c.n_vertices)
    comp = _component_anchors(L)
    if not np.isin(comp, anchors).all():
        raise InvalidInputError(".sga anchor index is malformed (a component has no anchor).")
    solver = _Solver(L, anchors, p.weight)
    return StreamState(
        c.method, c.n_vertices, c.n_faces, np.asarray(c.origin), c.scale, p, F, anchors, L, solver
    )


def reconstruct_block(st: StreamState, chunks, nf: int, step: float, serial: bool) -> np.ndarray:
    """Frames (nf, n, 3) of one block segment, in original coordinates."""
    if st.method == "pca-spectral":
        from . import _pca_spectral

        X = _pca_spectral.reconstruct(st.F, st.n, chunks, nf, step)
        if not np.isfinite(X).all():
            raise InvalidInputError(".sga data decodes to non-finite coordinates (corrupted).")
        return X * st.scale + st.origin
    deltas, apos = decode_block(chunks, st.params, nf, st.n, st.anchors, step)
    X = np.empty((nf, st.n, 3))
    D = np.concatenate(deltas, axis=1)  # (n, 3 nf): columns c*nf + t
    A = np.concatenate([apos[:, :, c].T for c in range(3)], axis=1)
    if serial:  # Eq. (5.51) once per frame
        for t in range(nf):
            cols = [c * nf + t for c in range(3)]
            X[t] = st.solver.solve(D[:, cols], A[:, cols])
    else:  # one multi-right-hand-side solve for the block
        S = st.solver.solve(D, A)
        for c in range(3):
            X[:, :, c] = S[:, c * nf : (c + 1) * nf].T
    if not np.isfinite(X).all():
        raise InvalidInputError(".sga data decodes to non-finite coordinates (corrupted).")
    return X * st.scale + st.origin


def _parse_block_params(c: _container.Container, st: StreamState) -> tuple[int, int, int, float]:
    if len(c.params) != _BLOCK.size or c.params[0] != KIND_BLOCK:
        raise InvalidInputError(".sga block segment header is malformed.")
    _k, b, t0, nf, step = _BLOCK.unpack(c.params)
    if not (math.isfinite(step) and step > 0):
        raise InvalidInputError(".sga block segment has an invalid step.")
    if c.method != st.method or c.n_vertices != st.n or c.n_faces != st.m:
        raise InvalidInputError(".sga block segment does not belong to this stream.")
    if not 1 <= nf <= max(st.params.block, 1) or t0 > _MAX_FRAMES:
        raise InvalidInputError(".sga block segment has an invalid frame count.")
    return b, t0, nf, step


def iter_segments(data: bytes, partial: bool) -> Iterator[tuple[int, int, _container.Container]]:
    """Parse consecutive segments; yields ``(offset, end, container)``."""
    pos = 0
    while pos < len(data):
        end = _segment_end(data, pos)
        if end is None:
            if partial and pos > 0:
                return
            raise InvalidInputError(f".sga data is truncated (segment at byte {pos} is cut short).")
        yield pos, end, _container.parse(data[pos:end])
        pos = end


def is_animation(data) -> bool:
    """True when ``data`` starts with a container whose method is an animation method."""
    b = bytes(data[:6]) if isinstance(data, bytes | bytearray | memoryview) else b""
    return len(b) == 6 and b[:4] == _container.MAGIC and b[5] in METHOD_IDS.values()


# ----------------------------------------------------------------------------- encoder
def frame_box(frames: np.ndarray) -> tuple[np.ndarray, float]:
    """``(origin, scale)`` of the coordinate normalisation: the centre of the bounding box of
    all frames and its diagonal (1 when every vertex of every frame coincides)."""
    lo, hi = frames.min(axis=(0, 1)), frames.max(axis=(0, 1))
    diag = float(np.linalg.norm(hi - lo))
    return 0.5 * (lo + hi), diag if diag > 0 else 1.0


class AnimationEncoder:
    """Analysis of a whole animation (normalised) shared by all rate points of a rate search."""

    def __init__(
        self, frames, F, method, *, block, anchors, anchor_ratio, weight, basis, n_iter, rd
    ):
        self.method = method
        self.T, self.n = frames.shape[:2]
        self.F = F
        self.origin, self.scale = frame_box(frames)
        X = (frames - self.origin) / self.scale
        self.L = _laplacian(F, self.n)
        if _anchored(method):
            self.anchors = choose_anchors(X[0], self.L, anchors)
        else:  # Eq. (5.50): only what L cannot see, one vertex per connected component
            self.anchors = _component_anchors(self.L)
        self.blk = block if method == "blocks" else self.T
        self.ratio = anchor_ratio
        self.weight = weight
        self.basis = basis
        self.n_iter = n_iter
        self.rd = rd
        self.plans = []
        prev = None
        for t0 in range(0, self.T, self.blk):
            Xb = X[t0 : t0 + self.blk]
            plan = analyse_block(Xb, self.L, self.anchors, t0, prev, n_iter if basis else 0)
            self.plans.append(plan)
            prev = plan
        self.X = X

    def params(self, step: float) -> Params:
        return Params(
            self.method,
            self.T,
            self.blk,
            int(self.anchors.size),
            float(step),
            self.ratio,
            self.weight,
            self.basis,
            self.n_iter,
        )

    def build(self, step: float) -> bytes:
        m = self.F.shape[0]
        p = self.params(step)
        out = [
            header_segment(
                self.method, self.n, m, tuple(self.origin), self.scale, p, self.F, self.anchors
            )
        ]
        off = len(out[0])
        entries = []
        for b, plan in enumerate(self.plans):
            chunks = encode_block(plan, self.method, step, self.ratio, self.rd)
            seg = block_segment(
                self.method,
                self.n,
                m,
                tuple(self.origin),
                self.scale,
                b,
                plan.t0,
                plan.nf,
                step,
                chunks,
            )
            entries.append((plan.t0, plan.nf, off, len(seg)))
            off += len(seg)
            out.append(seg)
        out.append(index_segment(self.method, self.n, m, tuple(self.origin), self.scale, entries))
        return b"".join(out)


# ----------------------------------------------------------------------------- public functions
def _check_options(method: str, options: dict) -> dict:
    allowed = {
        "block": DEFAULT_BLOCK,
        "anchors": DEFAULT_ANCHORS,
        "anchor_ratio": DEFAULT_ANCHOR_RATIO,
        "weight": 1.0,
        "basis": "oi",
        "n_iter": 2,
        "rd": 1.0,
    }
    bad = sorted(set(options) - set(allowed))
    if bad:
        raise InvalidInputError(
            f"unknown option(s) {bad} for method {method!r}; use {sorted(allowed)}."
        )
    out = {**allowed, **options}
    if out["basis"] not in ("oi", "exact"):
        raise InvalidInputError(f"`basis` must be 'oi' or 'exact'; got {out['basis']!r}.")
    b = out["block"]
    if isinstance(b, bool) or not isinstance(b, int | np.integer) or not 2 <= b <= 4096:
        raise InvalidInputError(f"`block` must be an integer in [2, 4096]; got {b!r}.")
    for name, lo, hi in (
        ("anchors", 0.0, 0.5),
        ("anchor_ratio", 1e-3, 1e3),
        ("weight", 1e-3, 1e3),
        ("rd", 0.0, 1e3),
    ):
        v = out[name]
        if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= float(v) <= hi:
            raise InvalidInputError(f"`{name}` must be a number in [{lo:g}, {hi:g}]; got {v!r}.")
    it = out["n_iter"]
    if isinstance(it, bool) or not isinstance(it, int | np.integer) or not 1 <= it <= 50:
        raise InvalidInputError(f"`n_iter` must be an integer in [1, 50]; got {it!r}.")
    return out


class PcaSpectralFileEncoder(AnimationEncoder):
    """``pca-spectral`` (:mod:`._pca_spectral`): the whole sequence in one block segment."""

    def __init__(self, frames, F) -> None:  # the parent's per-block analysis is not used
        from ._pca_spectral import PcaSpectralEncoder

        self.method = "pca-spectral"
        self.T, self.n = frames.shape[:2]
        self.F = F
        self.origin, self.scale = frame_box(frames)
        X = (frames - self.origin) / self.scale
        self.L = _laplacian(F, self.n)
        self.anchors = _component_anchors(self.L)  # the header's; the decoder does not use them
        self.blk = self.T
        self.ratio, self.weight, self.basis, self.n_iter = DEFAULT_ANCHOR_RATIO, 1.0, 1, 1
        self.enc = PcaSpectralEncoder(X, F)

    def build(self, step: float) -> bytes:
        m = self.F.shape[0]
        o = tuple(self.origin)
        p = self.params(step)
        head = header_segment(self.method, self.n, m, o, self.scale, p, self.F, self.anchors)
        seg = block_segment(
            self.method, self.n, m, o, self.scale, 0, 0, self.T, step, self.enc.chunks(step)
        )
        index = index_segment(
            self.method, self.n, m, o, self.scale, [(0, self.T, len(head), len(seg))]
        )
        return head + seg + index


def make_encoder(frames, F, method: str, options: dict) -> AnimationEncoder:
    o = _check_options(method, options)
    if method == "pca-spectral":
        return PcaSpectralFileEncoder(frames, F)
    return AnimationEncoder(
        frames,
        F,
        method,
        block=int(o["block"]),
        anchors=float(o["anchors"]),
        anchor_ratio=float(o["anchor_ratio"]),
        weight=float(o["weight"]),
        basis=1 if o["basis"] == "oi" else 0,
        n_iter=int(o["n_iter"]),
        rd=float(o["rd"]),
    )


def _bisect_count(measure, target: float, hi: int, *, increasing: bool, what: str) -> bytes:
    """Integer bisection on the kept-coefficient count of ``pca`` (rate grows, error falls)."""
    lo = 1
    f_lo, d_lo = measure(lo)
    f_hi, d_hi = measure(hi)
    for f, d in ((f_lo, d_lo), (f_hi, d_hi)):
        if abs(f - target) <= 0.03 * target:
            return d
    small, large = (f_lo, f_hi) if increasing else (f_hi, f_lo)
    if not small * 0.95 <= target <= large * 1.05:
        raise InvalidInputError(
            f"`{what}` = {target:g} cannot be reached with method 'pca': it gives {small:.4g} "
            f"to {large:.4g} here."
        )
    best = None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        f, d = measure(mid)
        err = abs(f - target) / target
        if best is None or err < best[0]:
            best = (err, d)
        if err <= 0.03:
            break
        if (f < target) == increasing:
            lo = mid
        else:
            hi = mid
    if best is None or best[0] > 0.05:
        raise InvalidInputError(f"`{what}` = {target:g} could not be met within 5 % with 'pca'.")
    return best[1]


def check_encode_args(frames, F, method: str, step, bpvf, error) -> tuple[np.ndarray, np.ndarray]:
    """The argument checks of :func:`encode_animation` for the eigen-trajectory methods
    (``method`` in :data:`ALL_METHODS`, not ``layered``): ``(A, F)`` validated."""
    if method not in ALL_METHODS:
        raise InvalidInputError(f"`method` must be one of {list(ALL_METHODS)}; got {method!r}.")
    if bpvf is not None and error is not None:
        raise InvalidInputError("give at most one of `bpvf` and `error`.")
    for name, v in (("bpvf", bpvf), ("error", error)):
        ok = not isinstance(v, bool) and isinstance(v, int | float | np.integer | np.floating)
        if v is not None and not (ok and math.isfinite(float(v)) and float(v) > 0):
            raise InvalidInputError(f"`{name}` must be a positive number; got {v!r}.")
    if step is not None and (bpvf is not None or error is not None):
        raise InvalidInputError("`step` cannot be combined with `bpvf` or `error`.")
    A = as_frames(frames, "frames")
    F = as_faces(F, A.shape[1], "F")
    T, n = A.shape[:2]
    if T > _MAX_FRAMES or n > _container.MAX_COUNT or F.shape[0] > _container.MAX_COUNT:
        raise InvalidInputError("the animation is too large for the .sga format.")
    fixed = method == "pca"
    if step is not None:
        ok = (1 <= step <= T * n) if fixed else (1e-7 <= step <= 4.0)
        if isinstance(step, bool) or not isinstance(step, int | float) or not ok:
            raise InvalidInputError(
                "`step` must be "
                + ("a kept-coefficient count in [1, T*n]" if fixed else "in [1e-7, 4]")
                + f"; got {step!r}."
            )
    return A, F


def encode_at_rate(build, A: np.ndarray, method: str, step, bpvf, error) -> bytes:
    """The file of a fixed ``step`` (default when None), or of the step meeting ``bpvf`` /
    ``error`` by bisection; ``build(step) -> bytes`` codes the whole file at one step."""
    from . import _bisect

    T, n = A.shape[:2]
    fixed = method == "pca"
    if bpvf is None and error is None:
        if step is None:
            step = max(1, min(T, 12) * n) if fixed else DEFAULT_STEP
        return build(int(step) if fixed else float(step))
    nvf = float(n * T)

    def m_rate(s):
        data = build(s)
        return 8.0 * len(data) / nvf, data

    def m_err(s):
        from ..metrics import kg_error

        data = build(s)
        rec, _F = decode_animation(data)
        return kg_error(rec, A), data

    if fixed:
        return _bisect_count(
            m_rate if bpvf is not None else m_err,
            float(bpvf if bpvf is not None else error),
            T * n,
            increasing=bpvf is not None,
            what="bpvf" if bpvf is not None else "error",
        )
    if bpvf is not None:
        return _bisect(m_rate, float(bpvf), increasing=False, what="bpvf")[1]
    return _bisect(m_err, float(error), increasing=True, what="error")[1]


def encode_animation(
    frames, F, *, method: str = "blocks", bpvf=None, error=None, step=None, **options
) -> bytes:
    """See :func:`spectrageo.compress.encode_animation`."""
    if method == "layered":
        from . import _layered

        if bpvf is not None and error is not None:
            raise InvalidInputError("give at most one of `bpvf` and `error`.")
        return _layered.encode(frames, F, step=step, bpvf=bpvf, error=error, **options)
    A, F = check_encode_args(frames, F, method, step, bpvf, error)
    enc = make_encoder(A, F, method, options)
    return encode_at_rate(enc.build, A, method, step, bpvf, error)


def _parse_stream(data, partial: bool):
    segs = iter_segments(data, partial)
    try:
        _p, _e, head = next(segs)
    except StopIteration:
        raise InvalidInputError(".sga data is empty.") from None
    if head.method == "layered":
        from ._layered import LayeredState

        return LayeredState(head), segs
    st = read_header(head)
    return st, segs


def iter_decode(data, *, partial: bool = False, serial: bool | None = None, _state=None):
    """Yield ``(t0, frames_block)`` for every block of an ``.sga`` byte string, in order.

    ``_state``: a dict that receives the stream state under ``"st"`` (its faces, parameters).
    """
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise InvalidInputError(f"`data` must be bytes; got {type(data).__name__}.")
    if not is_animation(data):
        raise InvalidInputError("not a spectrageo compressed animation (.sga).")
    st, segs = _parse_stream(data, partial)
    if _state is not None:
        _state["st"] = st
    if st.method == "layered":
        yield from _iter_layered(st, segs, partial)
        return
    serial = st.method == "pca-qs" if serial is None else serial
    expect = 0
    seen_index = False
    for _pos, _end, c in segs:
        if seen_index:
            raise InvalidInputError(".sga data continues after its frame index.")
        if c.params[:1] == bytes([KIND_INDEX]):
            seen_index = True
            continue
        _b, t0, nf, step = _parse_block_params(c, st)
        if t0 != expect:
            raise InvalidInputError(
                f".sga blocks are out of order (frame {t0}, expected {expect})."
            )
        yield t0, reconstruct_block(st, c.chunks, nf, step, serial)
        expect += nf
    if st.params.n_frames and expect != st.params.n_frames and not partial:
        raise InvalidInputError(
            f".sga data is truncated: {expect} of {st.params.n_frames} frames present."
        )


def _iter_layered(st, segs, partial: bool):
    seen_index = False
    for _pos, _end, c in segs:
        if seen_index:
            raise InvalidInputError(".sga data continues after its frame index.")
        if c.params[:1] == bytes([KIND_INDEX]):
            seen_index = True
            continue
        t = st.expect
        yield t, st.frame(c)[None]
    if st.n_frames and st.expect != st.n_frames and not partial:
        raise InvalidInputError(
            f".sga data is truncated: {st.expect} of {st.n_frames} frames present."
        )


def decode_animation(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """See :func:`spectrageo.compress.decode_animation`."""
    state: dict = {}
    parts = [X for _t0, X in iter_decode(data, partial=partial, _state=state)]
    if not parts:
        raise InvalidInputError(".sga data holds no complete frame.")
    return np.concatenate(parts, axis=0), state["st"].F


def info_animation(data) -> dict:
    """Header summary of ``.sga`` bytes without decoding the geometry."""
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    st, segs = _parse_stream(data, False)
    if st.method == "layered":
        return _info_layered(data, st, segs)
    n_blocks = 0
    frames = 0
    conn = len(_container.parse(data[: _segment_end(data, 0)]).chunks[0][1])
    has_index = False
    for _p, _e, c in segs:
        if c.params[:1] == bytes([KIND_INDEX]):
            has_index = True
            continue
        _b, _t0, nf, _s = _parse_block_params(c, st)
        n_blocks += 1
        frames += nf
    p = st.params
    parameters = {
        ("kept_coefficients" if p.method == "pca" else "step"): p.step,
        "block": p.block,
        "n_anchors": p.n_anchors,
        "anchor_ratio": p.anchor_ratio,
        "basis": "oi" if p.basis else "exact",
    }
    return _info_dict(data, st, frames, conn, n_blocks, has_index, parameters)


def _info_layered(data: bytes, st, segs) -> dict:
    from ._layered import _parse_payload

    conn = len(_container.parse(data[: _segment_end(data, 0)]).chunks[0][1])
    layers = []
    has_index = False
    for _p, _e, c in segs:
        if c.params[:1] == bytes([KIND_INDEX]):
            has_index = True
            continue
        if not c.chunks:
            raise InvalidInputError(".sga layered frame segment is malformed.")
        layers.append(_parse_payload(c.chunks[0][1], st.n)[0])
    frames = len(layers)
    parameters = {
        "step": st.step,
        "refresh": st.refresh,
        "mean_layer": float(np.mean(layers[1:])) / st.n if frames > 1 else 1.0,
    }
    return _info_dict(data, st, frames, conn, frames, has_index, parameters)


def _info_dict(data, st, frames, conn, n_blocks, has_index, parameters) -> dict:
    nvf = max(1, st.n * max(frames, 1))
    return {
        "format": "sga",
        "version": _container.FORMAT_VERSION,
        "method": st.method,
        "n_frames": frames,
        "n_vertices": st.n,
        "n_faces": st.m,
        "bytes": len(data),
        "bpvf": 8.0 * len(data) / nvf,
        "connectivity_bpvf": 8.0 * conn / nvf,
        "n_blocks": n_blocks,
        "frame_index": has_index,
        "order_preserved": True,
        "parameters": parameters,
    }


# ----------------------------------------------------------------------------- streaming
class StreamEncoder:
    """See :class:`spectrageo.compress.StreamEncoder`."""

    def __init__(self, F, *, method="blocks", step=None, bpvf=None, **options) -> None:
        self._lay = None
        if method == "layered":
            from ._layered import LayeredEncoder

            bad = sorted(set(options) - {"layer", "refresh", "fine"})
            if bad:
                raise InvalidInputError(
                    f"unknown option(s) {bad} for method 'layered'; use ['fine', 'layer', "
                    "'refresh']."
                )
            self._lay = LayeredEncoder(F, step=step, bpvf=bpvf, **options)
            return
        if method != "blocks":
            raise InvalidInputError(
                f"streaming supports methods 'blocks' and 'layered' (the others need the whole "
                f"sequence); got {method!r}."
            )
        if step is not None and bpvf is not None:
            raise InvalidInputError("give at most one of `step` and `bpvf`.")
        for name, v in (("step", step), ("bpvf", bpvf)):
            ok = not isinstance(v, bool) and isinstance(v, int | float | np.integer | np.floating)
            if v is not None and not (ok and math.isfinite(float(v)) and float(v) > 0):
                raise InvalidInputError(f"`{name}` must be a positive number; got {v!r}.")
        self.o = _check_options(method, options)
        self.F_in = F
        self.step = DEFAULT_STEP if step is None else float(step)
        self.bpvf = None if bpvf is None else float(bpvf)
        self.method = method
        self.buf: list[np.ndarray] = []
        self.prev = None
        self.t = 0
        self.b = 0
        self.offset = 0
        self.entries: list[tuple[int, int, int, int]] = []
        self.started = False
        self.closed = False
        self.block_steps: list[float] = []

    def _start(self, V0: np.ndarray) -> bytes:
        n = V0.shape[0]
        self.F = as_faces(self.F_in, n, "F")
        self.n = n
        lo, hi = V0.min(axis=0), V0.max(axis=0)
        self.origin = 0.5 * (lo + hi)
        diag = float(np.linalg.norm(hi - lo))
        self.scale = 2.0 * diag if diag > 0 else 1.0  # room for motion beyond the first frame
        self.L = _laplacian(self.F, n)
        X0 = (V0 - self.origin) / self.scale
        self.anchors = choose_anchors(X0, self.L, float(self.o["anchors"]))
        self.p = Params(
            self.method,
            0,
            int(self.o["block"]),
            int(self.anchors.size),
            self.step,
            float(self.o["anchor_ratio"]),
            float(self.o["weight"]),
            1 if self.o["basis"] == "oi" else 0,
            int(self.o["n_iter"]),
        )
        # the header carries the nominal step; blocks coded at another step (rate adaptation)
        # carry theirs in their own segment parameters
        head = header_segment(
            self.method,
            n,
            self.F.shape[0],
            tuple(self.origin),
            self.scale,
            self.p,
            self.F,
            self.anchors,
        )
        self.started = True
        self.offset = len(head)
        return head

    def push(self, frame) -> bytes:
        """Add one frame (n, 3); returns the bytes ready to send (possibly empty)."""
        if self._lay is not None:
            return self._lay.push(frame)
        if self.closed:
            raise InvalidInputError("the stream is closed.")
        V = np.asarray(frame, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or (self.started and V.shape[0] != self.n):
            raise InvalidInputError(f"`frame` must have shape (n, 3); got {V.shape}.")
        if not np.isfinite(V).all():
            raise InvalidInputError("`frame` contains NaN or inf coordinates.")
        out = b"" if self.started else self._start(V)
        self.buf.append((V - self.origin) / self.scale)
        if len(self.buf) == self.p.block:
            out += self._flush()
        return out

    def _flush(self) -> bytes:
        if not self.buf:
            return b""
        X = np.stack(self.buf)
        self.buf = []
        o = self.o
        plan = analyse_block(
            X,
            self.L,
            self.anchors,
            self.t,
            self.prev,
            int(o["n_iter"]) if o["basis"] == "oi" else 0,
        )
        self.prev = plan
        m = self.F.shape[0]

        def seg(s):
            chunks = encode_block(plan, self.method, s, float(o["anchor_ratio"]), float(o["rd"]))
            return block_segment(
                self.method,
                self.n,
                m,
                tuple(self.origin),
                self.scale,
                self.b,
                self.t,
                plan.nf,
                s,
                chunks,
            )

        if self.bpvf is None:
            s, data = self.step, seg(self.step)
        else:  # per-block rate adaptation: the block alone meets the target
            from . import _bisect

            nvf = float(self.n * plan.nf)
            s, data = _bisect(
                lambda s: (8.0 * len(seg(s)) / nvf, seg(s)),
                self.bpvf,
                increasing=False,
                what="bpvf",
            )
        self.block_steps.append(s)
        self.entries.append((self.t, plan.nf, self.offset, len(data)))
        self.offset += len(data)
        self.t += plan.nf
        self.b += 1
        return data

    def close(self) -> bytes:
        """Flush the last (short) block and append the frame index; returns the final bytes."""
        if self._lay is not None:
            return self._lay.close()
        if self.closed:
            return b""
        self.closed = True
        if not self.started:
            raise InvalidInputError("the stream has no frame.")
        out = self._flush()
        return out + index_segment(
            self.method, self.n, self.F.shape[0], tuple(self.origin), self.scale, self.entries
        )


class StreamDecoder:
    """See :class:`spectrageo.compress.StreamDecoder`."""

    def __init__(self) -> None:
        self.buf = b""
        self.state: StreamState | None = None
        self.expect = 0
        self.done = False
        self.F: np.ndarray | None = None

    def feed(self, data) -> list[np.ndarray]:
        """Add received bytes; returns the frames (n, 3) completed by them, in order."""
        if self.done and data:
            raise InvalidInputError(".sga stream continues after its frame index.")
        self.buf += bytes(data)
        out: list[np.ndarray] = []
        while self.buf:
            end = _segment_end(self.buf, 0)
            if end is None:
                break
            c = _container.parse(self.buf[:end])
            self.buf = self.buf[end:]
            if self.state is None:
                if c.method == "layered":
                    from ._layered import LayeredState

                    self.state = LayeredState(c)
                else:
                    self.state = read_header(c)
                self.F = self.state.F
                continue
            if c.params[:1] == bytes([KIND_INDEX]):
                self.done = True
                continue
            if self.state.method == "layered":
                out.append(self.state.frame(c))
                self.expect += 1
                continue
            out.extend(self._block(c))
        return out

    def _block(self, c) -> list[np.ndarray]:
        _b, t0, nf, step = _parse_block_params(c, self.state)
        if t0 != self.expect:
            raise InvalidInputError(
                f".sga blocks are out of order (frame {t0}, expected {self.expect})."
            )
        X = reconstruct_block(self.state, c.chunks, nf, step, serial=False)
        self.expect += nf
        return list(X)

    @property
    def n_frames(self) -> int:
        """Frames decoded so far."""
        return self.expect

    @property
    def pending_bytes(self) -> int:
        """Bytes received that do not yet form a complete segment (a cut stream's remainder)."""
        return len(self.buf)
