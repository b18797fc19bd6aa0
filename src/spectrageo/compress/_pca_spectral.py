"""``pca-spectral``: eigen-trajectories coded in the partitioned graph Fourier basis.

Not a method of the thesis: Section 5.2.2's temporal PCA with Section 5.2.1's spatial transform,

    (P1)  X_t = M + sum_j U_tj G_j,   G_j = S_j v_j reshaped to (n, 3)

with ``M`` the mean frame and ``[X_t - M]_t = U S V^T``. ``M`` and each ``G_j`` are analysed in
the dictionaries of :func:`._spectral.dictionaries` and quantised with one step ``s``; ``U_tj``
with ``c s sqrt(n) / ||G~_j||`` (``c`` = :data:`U_FACTOR`). One block segment holds the whole
sequence: chunks ``TAG_BASIS`` (``k``, the steps and the quantised ``U``) and ``TAG_COEFF``.
See docs/decisions.md#compress-pca-spectral and docs/decisions.md#compress-pca-spectral-results.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from .._errors import InvalidInputError
from ._container import Reader, varint
from ._entropy import decode_groups, encode_groups

TAG_BASIS = 3
TAG_COEFF = 4
#: step of the temporal coefficients relative to ``s sqrt(n) / ||G_j||``
U_FACTOR = 0.1
_SUBMESH = 300
#: coefficients held per call of the dictionaries when signals are transformed together
_BATCH_BYTES = 64 << 20
_CACHE: dict = {}


def _params(n: int):
    from ._spectral import SpectralParams

    p = SpectralParams(
        submesh_size=_SUBMESH, overlap=0.1, seed=0, basis="oi", zeta=4, n_iter=1, k=_SUBMESH
    )
    p.direct = n >= 2
    return p


def _dictionaries(F: np.ndarray, n: int):
    """``(subs, dic, layout, band, sizes)`` for the connectivity, cached for repeated decodes
    of the same mesh (the rate control decodes many times)."""
    from ._spectral import _band, _layout, dictionaries, layer_cutoffs

    key = (n, hashlib.sha1(np.ascontiguousarray(F, dtype=np.int64).tobytes()).hexdigest())
    if key not in _CACHE:
        subs, dic = dictionaries(F, n, _params(n))
        sizes = dic.sizes.copy()
        layout = _layout(sizes, layer_cutoffs(int(sizes.max())))
        col = np.concatenate([c for _s, c in layout])
        band = _band(col) if col.size else np.zeros(0, np.int64)
        band = band - (int(band.min()) if band.size else 0)
        _CACHE.clear()  # one mesh at a time
        _CACHE[key] = (subs, dic, layout, band, sizes)
    return _CACHE[key]


def _rows(coef: list[np.ndarray], layout, n_sub: int) -> np.ndarray:
    """Coefficient rows of every layer, concatenated in layer order: (R, d)."""
    out = []
    for sub, col in layout:
        bounds = np.searchsorted(sub, np.arange(n_sub + 1))
        out += [coef[i][col[bounds[i] : bounds[i + 1]]] for i in np.flatnonzero(np.diff(bounds))]
    d = coef[0].shape[1] if coef else 3
    return np.concatenate(out) if out else np.zeros((0, d))


def _batch(n_rows: int, n_signals: int) -> int:
    """Signals transformed per call: the submesh decompositions are recomputed at every call of
    the dictionary, so the signals share calls, as many as :data:`_BATCH_BYTES` of coefficients
    allow (at least one)."""
    return max(1, min(n_signals, _BATCH_BYTES // max(1, 8 * 3 * n_rows)))


def _analyse_many(signals: np.ndarray, subs, dic, layout) -> np.ndarray:
    """Coefficient rows (J, R, 3) of the signals (J, n, 3), in layer order."""
    J, n = signals.shape[:2]
    n_sub = len(subs.parts)
    rows = int(sum(sub.size for sub, _c in layout))
    out = np.empty((J, rows, 3))
    step = _batch(max(rows, n), J)
    for a in range(0, J, step):
        b = min(J, a + step)
        X = np.ascontiguousarray(signals[a:b].transpose(1, 0, 2).reshape(n, 3 * (b - a)))
        R = _rows(dic.analyse(X, subs.parts), layout, n_sub)
        out[a:b] = R.reshape(rows, b - a, 3).transpose(1, 0, 2)
    return out


def _synthesise_many(rows: np.ndarray, n: int, subs, dic, layout, sizes) -> np.ndarray:
    """Signals (J, n, 3) from their coefficient rows (J, R, 3) in layer order (the inverse of
    :func:`_analyse_many`, with the degree-weighted reassembly of Algorithm 8)."""
    from ..spectral import reassemble
    from ._spectral import _scatter

    J, R = rows.shape[:2]
    out = np.empty((J, n, 3))
    step = _batch(max(R, n), J)
    for a in range(0, J, step):
        b = min(J, a + step)
        flat = rows[a:b].transpose(1, 0, 2).reshape(R, 3 * (b - a))
        vals, pos = [], 0
        for sub, _col in layout:
            vals.append(flat[pos : pos + sub.size])
            pos += sub.size
        X = reassemble(dic.synthesise(_scatter(layout, vals, sizes)), subs)
        out[a:b] = X.reshape(n, b - a, 3).transpose(1, 0, 2)
    return out


def _groups(band: np.ndarray, n_signals: int) -> tuple[np.ndarray, int]:
    nb = int(band.max()) + 1 if band.size else 1
    per = np.repeat(band, 3)  # row-major (R, 3)
    g = (np.arange(n_signals)[:, None] * nb + per[None, :]).ravel()
    return g, n_signals * nb


class PcaSpectralEncoder:
    """Analysis of a normalised animation ``X`` (T, n, 3); :meth:`chunks` codes it at a step."""

    def __init__(self, X: np.ndarray, F: np.ndarray) -> None:
        T, n = X.shape[:2]
        self.T, self.n = T, n
        subs, dic, layout, band, sizes = _dictionaries(F, n)
        self.band = band
        M = X.mean(axis=0)
        D = (X - M).reshape(T, 3 * n)
        U, S, Vt = np.linalg.svd(D, full_matrices=False)
        live = np.flatnonzero(S > S[0] * 1e-12) if S.size and S[0] > 0 else np.zeros(0, int)
        self.U = U[:, live]
        signals = np.concatenate([M[None], (S[live, None] * Vt[live]).reshape(-1, n, 3)])
        self.values = list(_analyse_many(signals, subs, dic, layout))

    def chunks(self, step: float) -> list[tuple[int, bytes]]:
        q = [np.rint(v / step).astype(np.int64) for v in self.values]
        kept = [j for j in range(1, len(q)) if q[j].any()]
        su = np.empty(len(kept), dtype=np.float32)
        qU = []
        for i, j in enumerate(kept):
            norm = float(np.linalg.norm(q[j])) * step
            su[i] = np.float32(min(U_FACTOR * step * math.sqrt(self.n) / norm, 0.25))
            qU.append(np.rint(self.U[:, j - 1] / float(su[i])).astype(np.int64))
        k = len(kept)
        ug = np.repeat(np.arange(k), self.T)
        basis = (
            varint(k)
            + su.astype("<f4").tobytes()
            + encode_groups(np.concatenate(qU) if qU else np.zeros(0, np.int64), ug, max(k, 1))
        )
        sig = [q[0]] + [q[j] for j in kept]
        g, ng = _groups(self.band, len(sig))
        coef = encode_groups(np.concatenate([s.ravel() for s in sig]), g, ng)
        return [(TAG_BASIS, basis), (TAG_COEFF, coef)]


def reconstruct(F: np.ndarray, n: int, chunks, nf: int, step: float) -> np.ndarray:
    """Normalised frames (nf, n, 3) of a ``pca-spectral`` block segment."""
    tags = [t for t, _ in chunks]
    if tags != [TAG_BASIS, TAG_COEFF]:
        raise InvalidInputError(f".sga block has chunks {tags}; expected [3, 4].")
    subs, dic, layout, band, sizes = _dictionaries(F, n)
    r = Reader(chunks[0][1], "temporal coefficients")
    k = r.varint()
    if k > nf:
        raise InvalidInputError(".sga temporal coefficients are malformed (too many components).")
    su = np.frombuffer(r.take(4 * k), "<f4").astype(np.float64)
    if not (np.isfinite(su).all() and (su > 0).all()):
        raise InvalidInputError(".sga temporal coefficients are malformed (bad steps).")
    qU = decode_groups(r.rest(), np.repeat(np.arange(k), nf), max(k, 1), "temporal coefficients")
    U = qU.reshape(k, nf).T * su[None, :]
    g, ng = _groups(band, k + 1)
    q = decode_groups(chunks[1][1], g, ng, "spectral coefficients").astype(np.float64) * step
    G = _synthesise_many(q.reshape(k + 1, band.size, 3), n, subs, dic, layout, sizes)
    X = np.repeat(G[0][None], nf, axis=0)  # every frame, also when no component was sent
    if k:
        from ._dense_fixed import matmul

        # fixed summation order over the components (no BLAS: the same bits on every machine)
        Gk = np.ascontiguousarray(G[1:].reshape(k, 3 * n))
        X += matmul(np.ascontiguousarray(U), Gk).reshape(nf, n, 3)
    return X
