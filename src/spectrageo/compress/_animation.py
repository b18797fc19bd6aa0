"""Eigen-trajectory coding of mesh animations with fixed connectivity (Section 5.2.2).

For every coordinate ``x`` of a block of ``k_f`` frames with trajectories ``A_x`` (k_f, n), the
eigenvectors ``U_x`` of ``R_x = A_x A_x^T`` (Eq. 5.46) multiply the delta coordinates
``delta_x = L A_x^T`` (Eq. 5.47, ``L = D - C``) and ``U_x^T delta_x^T`` (Eq. 5.48) is coded. The
decoder solves ``[L; I_a] A~^T = [delta~; Q(A_a^T)]`` (Eq. 5.50-5.51) with one fixed-order
factorisation for all frames (:mod:`spectrageo.linalg._fixed`: the same bits on every machine).

Methods (Table 5.12): ``pca`` (one block, the first ``k_l`` rows of ``U^_x`` at 16-bit
precision, Eq. 5.49 and 5.52, one anchor per connected component), ``pca-q`` (rows quantised
with the step ``s``, entropy coded, a rate-distortion test dropping rows), ``pca-qs`` /
``pca-qp`` (``pca-q`` with 1 % farthest-point anchors, solved frame by frame or all at once) and
``blocks`` (blocks of ``k_f`` frames, default 16, each basis found by orthogonal iterations from
the previous block's). Dictionaries are quantised per column and re-orthonormalised on both
sides, so the coefficients are exact projections; every block is coded on its own (the thesis
codes dictionary differences) so the frame index can start at any block.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._progress import progress
from .._validation import as_faces, as_frames
from . import _connectivity, _container
from ._container import Reader, varint
from ._entropy import decode_groups, encode_groups, zstd_compress, zstd_decompress
from ._sga_format import (
    ALL_METHODS,
    KIND_INDEX,
    MAX_FRAMES,
    METHODS,
    TAG_ANCHOR_INDEX,
    TAG_ANCHOR_POS,
    TAG_BASIS,
    TAG_COEFF,
    TAG_CONNECTIVITY,
    Params,
    block_segment,
    header_segment,
    index_segment,
    iter_segments,
    parse_block_params,
)

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

    The fixed-order sparse Cholesky of :mod:`spectrageo.linalg._fixed`; right-hand sides are solved
    64 columns at a time, each independent of the others, so serial and parallel reconstructions
    agree bit for bit.
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
        idx = (np.arange(live.size)[:, None] * width + (q - off)).ravel()
        cnt = np.bincount(idx, minlength=live.size * width).reshape(live.size, width)
        cnt = cnt.astype(np.float64)
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


@dataclass
class BlockSymbols:
    """Quantised content of one block of the quantised methods (all but ``pca``): what the
    entropy coder codes, and the re-orthonormalised dictionaries both ends compute from it."""

    rows: list[np.ndarray]  # 3 x (k,) kept rows of U^_x
    st: list[np.ndarray]  # 3 x (k,) dictionary column steps
    qU: list[np.ndarray]  # 3 x (nf, k) int64 quantised dictionaries
    Q: list[np.ndarray]  # 3 x (nf, k) orthonormal dictionaries
    q: list[np.ndarray]  # 3 x (k, n) int64 quantised coefficients
    qa: np.ndarray  # (nf, n_a, 3) int64 quantised anchor positions


def quantise_block(plan: _BlockPlan, method: str, step: float, ratio: float, rd: float):
    """:class:`BlockSymbols` of one block at the quantisation ``step`` (not ``pca``)."""
    nf = plan.nf
    n = plan.P[0].shape[1]
    rows_l, st_l, qU_l, Q_l, q_l = [], [], [], [], []
    for c in range(3):
        rows = _select_rows(plan.P[c], step, n, nf, rd)
        st = _basis_steps(plan.P[c][rows], step, n, nf)
        qU = np.rint(plan.U[c][:, rows] / st).astype(np.int64)
        Q = _orthonormal(qU * st)
        Pk = Q.T @ plan.delta[c].T  # exact projection on the transmitted dictionary (k, n)
        rows_l.append(rows)
        st_l.append(st)
        qU_l.append(qU)
        Q_l.append(Q)
        q_l.append(np.rint(Pk / step).astype(np.int64))
    qa = np.rint(plan.anchor_pos / _anchor_step(method, step, ratio)).astype(np.int64)
    return BlockSymbols(rows_l, st_l, qU_l, Q_l, q_l, qa)


def _anchor_chunk(qa: np.ndarray) -> bytes:
    """Anchor trajectories (nf, n_a, 3): frame differences, coded per coordinate and first frame."""
    nf = qa.shape[0]
    d = np.diff(qa, axis=0, prepend=np.zeros((1,) + qa.shape[1:], np.int64))
    grp = np.broadcast_to(
        (np.minimum(np.arange(nf), 1)[:, None, None] * 3 + np.arange(3)[None, None, :]),
        d.shape,
    )
    return encode_groups(d.ravel(), grp.ravel(), 6)


def code_block(sym: BlockSymbols, nf: int, n: int) -> list:
    """Chunks of one block segment holding ``sym``."""
    head = bytearray()
    basis_syms, basis_groups, coef_syms, coef_groups = [], [], [], []
    g = 0
    for c in range(3):
        k = sym.rows[c].size
        head += varint(k) + sym.st[c].astype("<f4").tobytes() + sym.rows[c].astype("<u4").tobytes()
        basis_syms.append(sym.qU[c].T.ravel())
        basis_groups.append(np.repeat(np.arange(k) + g, nf))
        coef_syms.append(sym.q[c].ravel())
        coef_groups.append(np.repeat(np.arange(k) + g, n))
        g += k
    basis = bytes(head) + encode_groups(np.concatenate(basis_syms), np.concatenate(basis_groups), g)
    coef = encode_groups(np.concatenate(coef_syms), np.concatenate(coef_groups), g)
    return [(TAG_BASIS, basis), (TAG_COEFF, coef), (TAG_ANCHOR_POS, _anchor_chunk(sym.qa))]


def dequantise_block(sym: BlockSymbols, method: str, step: float, ratio: float) -> tuple:
    """``(delta~ list of (n, nf), anchor positions (nf, n_a, 3))`` of ``sym`` (Eq. 5.49-5.50),
    with the fixed-order product of :func:`spectrageo.linalg._fixed.matmul` (no BLAS)."""
    from ..linalg._fixed import matmul

    deltas = [matmul(sym.Q[c], sym.q[c].astype(np.float64) * step).T for c in range(3)]
    return deltas, sym.qa * _anchor_step(method, step, ratio)


def encode_block(plan: _BlockPlan, method: str, step: float, ratio: float, rd: float) -> list:
    """Chunks of one block segment for the quantisation ``step`` (or kept count for ``pca``)."""
    if method != "pca":
        return code_block(
            quantise_block(plan, method, step, ratio, rd), plan.nf, plan.P[0].shape[1]
        )
    nf = plan.nf
    n = plan.P[0].shape[1]
    basis_head = bytearray()
    basis_syms, basis_groups = [], []
    coef_head = bytearray()
    coef_syms = []
    g_basis = 0
    for c in range(3):
        U, D = plan.U[c], plan.delta[c]
        count = min(int(step), nf * n)
        k = -(-count // n)
        rows = np.arange(k)
        st = np.full(k, 2.0 ** (1 - PCA_BITS))
        qU = np.rint(U[:, rows] / st).astype(np.int64)
        Q = _orthonormal(qU * st)
        basis_head += varint(k) + st.astype("<f4").tobytes() + rows.astype("<u4").tobytes()
        basis_syms.append(qU.T.ravel())
        basis_groups.append(np.repeat(np.arange(k) + g_basis, nf))
        g_basis += k
        flat = (Q.T @ D.T).ravel()[:count]
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
    basis = bytes(basis_head) + encode_groups(
        np.concatenate(basis_syms), np.concatenate(basis_groups), g_basis
    )
    coef = bytes(coef_head) + zstd_compress(b"".join(coef_syms))
    qa = np.rint(plan.anchor_pos / _anchor_step(method, step, ratio)).astype(np.int64)
    return [(TAG_BASIS, basis), (TAG_COEFF, coef), (TAG_ANCHOR_POS, _anchor_chunk(qa))]


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
    qUs, Qs = [], []
    pos = 0
    for c in range(3):
        k = ks[c]
        qUs.append(qU[pos : pos + k * nf].reshape(k, nf).T)
        pos += k * nf
        Qs.append(_orthonormal(qUs[c] * steps[c]))
    na = anchors.size
    grp = np.broadcast_to(
        (np.minimum(np.arange(nf), 1)[:, None, None] * 3 + np.arange(3)[None, None, :]),
        (nf, na, 3),
    )
    d = decode_groups(chunks[2][1], grp.ravel(), 6, "anchor trajectories")
    qa = np.cumsum(d.reshape(nf, na, 3), axis=0)
    if p.method != "pca":
        q = decode_groups(chunks[1][1], np.repeat(np.arange(sum(ks)), n), sum(ks), "coefficients")
        qs = np.split(q, np.cumsum([k * n for k in ks])[:2])
        qs = [qs[c].reshape(ks[c], n) for c in range(3)]
        sym = BlockSymbols(rows_all, steps, qUs, Qs, qs, qa)
        return dequantise_block(sym, p.method, step, p.anchor_ratio)
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
    deltas = []
    pos = 0
    for c in range(3):
        count, lo, hi = heads[c]
        P = np.zeros(ks[c] * n)
        P[:count] = lo + vals[pos : pos + count] * ((hi - lo) / ((1 << PCA_BITS) - 1))
        pos += count
        deltas.append(matmul(Qs[c], P.reshape(ks[c], n)).T)
    return deltas, qa * _anchor_step(p.method, step, p.anchor_ratio)


# ----------------------------------------------------------------------------- decoding


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
    L: sp.csr_matrix | None
    solver: object  # _Solver, or the traversal plan of pca-pred


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
    if c.method == "pca-pred":  # no anchors, no solve: the traversal plan instead
        from ._pca_pred import CODER, make_plan

        if p.n_iter != CODER:
            raise InvalidInputError(f".sga pca-pred coder version {p.n_iter} is not read here.")
        pl = make_plan(F, c.n_vertices)
        e = np.zeros(0, np.int64)
        o = np.asarray(c.origin)
        return StreamState(c.method, c.n_vertices, c.n_faces, o, c.scale, p, F, e, None, pl)
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
    if st.method == "pca-pred":
        from . import _pca_pred

        X = _pca_pred.reconstruct(st.solver, st.n, chunks, nf, step)
    else:
        deltas, apos = decode_block(chunks, st.params, nf, st.n, st.anchors, step)
        X = solve_frames(st.solver, deltas, apos, serial)
    if not np.isfinite(X).all():
        raise InvalidInputError(".sga data decodes to non-finite coordinates (corrupted).")
    return X * st.scale + st.origin


def solve_frames(solver: _Solver, deltas: list, apos: np.ndarray, serial: bool) -> np.ndarray:
    """Normalised frames (nf, n, 3) from ``delta~`` and the anchor positions (Eq. 5.51)."""
    nf = apos.shape[0]
    X = np.empty((nf, deltas[0].shape[0], 3))
    D = np.concatenate(deltas, axis=1)  # (n, 3 nf): columns c*nf + t
    A = np.concatenate([apos[:, :, c].T for c in range(3)], axis=1)
    if serial:  # Eq. (5.51) once per frame
        for t in range(nf):
            cols = [c * nf + t for c in range(3)]
            X[t] = solver.solve(D[:, cols], A[:, cols])
    else:  # one multi-right-hand-side solve for the block
        S = solver.solve(D, A)
        for c in range(3):
            X[:, :, c] = S[:, c * nf : (c + 1) * nf].T
    return X


def iter_blocks(st: StreamState, segs, partial: bool, serial: bool | None):
    """Yield ``(t0, frames)`` for the block segments ``segs`` that follow the header ``st``."""
    serial = st.method == "pca-qs" if serial is None else serial
    expect = 0
    seen_index = False
    for _pos, _end, c in segs:
        if seen_index:
            raise InvalidInputError(".sga data continues after its frame index.")
        if c.params[:1] == bytes([KIND_INDEX]):
            seen_index = True
            continue
        _b, t0, nf, step = parse_block_params(c, st)
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


def decode(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Frames and faces of a complete ``.sga`` byte string of an eigen-trajectory method."""
    segs = iter_segments(data, False)
    st = read_header(next(segs)[2])
    parts = [X for _t0, X in iter_blocks(st, segs, False, None)]
    return np.concatenate(parts, axis=0), st.F


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
        starts = range(0, self.T, self.blk)
        for t0 in progress(starts, desc="compress: analysing blocks", total=len(starts)):
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

    def build(self, step: float, symbols: list | None = None) -> bytes:
        """The file at ``step``; ``symbols``: the blocks' :class:`BlockSymbols` at that step."""
        m = self.F.shape[0]
        p = self.params(step)
        out = [
            header_segment(
                self.method, self.n, m, tuple(self.origin), self.scale, p, self.F, self.anchors
            )
        ]
        off = len(out[0])
        entries = []
        blocks = enumerate(self.plans)
        for b, plan in progress(blocks, desc="compress: coding blocks", total=len(self.plans)):
            if symbols is None:
                chunks = encode_block(plan, self.method, step, self.ratio, self.rd)
            else:
                chunks = code_block(symbols[b], plan.nf, self.n)
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


# ----------------------------------------------------------------------------- options and rate control
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
    if method == "pca-pred":
        from ._pca_pred import PRED_BLOCK, PcaPredFileEncoder

        blk = int(o["block"]) if "block" in options else PRED_BLOCK
        return PcaPredFileEncoder(frames, F, blk, *frame_box(frames))
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
    if T > MAX_FRAMES or n > _container.MAX_COUNT or F.shape[0] > _container.MAX_COUNT:
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
    from ._rate import bisect_step

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
        rec, _F = decode(data)
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
        return bisect_step(m_rate, float(bpvf), increasing=False, what="bpvf")[1]
    return bisect_step(m_err, float(error), increasing=True, what="error")[1]
