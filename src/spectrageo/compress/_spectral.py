"""Block spectral coding on overlapped submeshes (Section 5.2.1, Algorithms 6-8, Eq. 5.42-5.45).

Both ends build the dictionaries from the connectivity alone: seeded METIS parts grown to
overlapped submeshes of ``submesh_size`` vertices, each with the ``k`` lowest eigenvectors of its
binary Laplacian by orthogonal iterations (``"oi"``, Algorithm 6, Eq. 5.42), a dense
decomposition (``"exact"``) or per-submesh sizes (``"doi"``). With ``k`` at least the submesh
size (the default) the complete decomposition is computed directly and applied without forming
``U`` (:mod:`._spectral_fast`, flag :data:`DIRECT_FULL`; docs/decisions.md#compress-direct-bases).
``U^T v`` (Eq. 5.45) is quantised with one step and entropy coded per octave and coordinate; the
decoder averages the overlapping ``U c`` with the weights of Algorithm 8, all in the fixed-order
kernels of :mod:`._dense_fixed`. Frequency layers (``k/16``, ``k/4``, the rest) sit in separate
chunks, so a prefix decodes to a coarser mesh. ``"doi"``: Algorithm 7's added directions
(Eq. 5.44) are unknown to a decoder, so the OI dictionary is kept and each submesh's smallest
size with relative residual (Eq. 5.43) at most ``eps`` is sent.
"""

from __future__ import annotations

import struct

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice
from ._entropy import decode_groups, encode_groups, zstd_compress, zstd_decompress

BASES = ("oi", "exact", "doi")
TAG_SIZES = 2
TAG_LAYER = 3

_P = struct.Struct("<HfIBBBHdf")
#: flag in the basis byte of the parameters: the complete submesh eigenbases are computed directly
#: (:mod:`spectrageo.compress._spectral_fast`, columns signed by their first entry); without it,
#: by the orthogonal iterations of :func:`spectrageo.spectral.submesh_eigenbases` (columns signed
#: by :func:`spectrageo.spectral.gft.fix_signs`), as in the files written before the flag existed
DIRECT_FULL = 0x80


class SpectralParams:
    """Parameters of the spectral codec, stored in the ``.sgc`` header.

    ``direct`` records which computation of the complete bases (``k`` at least the submesh size)
    the file was coded with (:data:`DIRECT_FULL`); the encoder sets it whenever that case applies.
    """

    def __init__(
        self,
        *,
        submesh_size: int = 700,
        overlap: float = 0.15,
        seed: int = 0,
        basis: str = "oi",
        zeta: int = 4,
        n_iter: int = 1,
        k: int = 250,
        step: float = 1e-3,
        eps: float = 0.0,
        direct: bool = False,
    ) -> None:
        self.submesh_size = int(submesh_size)
        self.overlap = float(np.float32(overlap))
        self.seed = int(seed)
        self.basis = basis
        self.zeta = int(zeta)
        self.n_iter = int(n_iter)
        self.k = int(k)
        self.step = float(step)
        self.eps = float(np.float32(eps))
        self.direct = bool(direct)

    def to_bytes(self) -> bytes:
        return _P.pack(
            self.submesh_size,
            self.overlap,
            self.seed,
            BASES.index(self.basis) | (DIRECT_FULL if self.direct else 0),
            self.zeta,
            self.n_iter,
            self.k,
            self.step,
            self.eps,
        )

    @classmethod
    def from_bytes(cls, b: bytes) -> SpectralParams:
        if len(b) != _P.size:
            raise InvalidInputError(".sgc spectral parameters are malformed.")
        size, overlap, seed, basis, zeta, n_iter, k, step, eps = _P.unpack(b)
        direct = bool(basis & DIRECT_FULL)
        basis &= ~DIRECT_FULL
        if (
            basis >= len(BASES)
            or not 2 <= size <= 20000
            or not 0 <= overlap < 1
            or not 1 <= zeta <= 16
            or not 1 <= n_iter <= 64
            or not 1 <= k <= size
            or not (np.isfinite(step) and step > 0)
        ):
            raise InvalidInputError(".sgc spectral parameters are out of range.")
        return cls(
            submesh_size=size,
            overlap=overlap,
            seed=seed,
            basis=BASES[basis],
            zeta=zeta,
            n_iter=n_iter,
            k=k,
            step=step,
            eps=eps,
            direct=direct,
        )

    def as_dict(self) -> dict:
        return {
            "submesh_size": self.submesh_size,
            "overlap": round(self.overlap, 6),
            "basis": self.basis,
            "zeta": self.zeta,
            "n_iter": self.n_iter,
            "k": self.k,
            "step": self.step,
            **({"eps": round(self.eps, 6)} if self.basis == "doi" else {}),
            # complete bases computed directly (DIRECT_FULL): the limit of the iterations
            "direct": self.direct,
        }


#: threads for the direct complete bases (:class:`_Full`) and the products of :class:`_Explicit`;
#: None: every CPU this process may use. The result does not depend on it.
WORKERS: int | None = None


class _Explicit:
    """Dictionaries held as dense bases ``U_i`` (n_i, k_i): orthogonal iterations (``k`` below the
    submesh size, or a file without :data:`DIRECT_FULL`) or the trivial basis of a one-vertex mesh.

    The products are the fixed-order loops of :mod:`._dense_fixed` (the same on every machine).
    """

    def __init__(self, bases: list[np.ndarray]) -> None:
        self.bases = bases
        self.sizes = np.array([U.shape[1] for U in bases], dtype=np.int64)

    def analyse(self, X: np.ndarray, parts) -> list[np.ndarray]:
        from ._dense_fixed import matmul_tn

        X = np.ascontiguousarray(X, dtype=np.float64)
        return [matmul_tn(U, X[part]) for U, part in zip(self.bases, parts)]

    def synthesise(self, coefs) -> list[np.ndarray]:
        from .._threads import thread_map
        from ._dense_fixed import matmul
        from ._spectral_fast import CHUNK

        def job(a: int) -> list[np.ndarray]:
            return [
                matmul(np.ascontiguousarray(U[:, : c.shape[0]]), np.ascontiguousarray(c))
                for U, c in zip(self.bases[a : a + CHUNK], coefs[a : a + CHUNK])
            ]

        return [y for ys in thread_map(job, range(0, len(coefs), CHUNK), WORKERS) for y in ys]

    def explicit(self) -> _Explicit:
        return self


class _Full:
    """Complete eigenbases of every submesh Laplacian, applied without forming them; should the
    compiled decomposition fail on a submesh, every submesh uses :func:`_fixed_bases`.
    """

    def __init__(self, C, subs) -> None:
        from ._spectral_fast import FullBases

        self.C, self.subs = C, subs
        self.fb = FullBases(C, subs.parts, workers=WORKERS)
        self.sizes = self.fb.sizes.copy()
        self._explicit = None
        self._fallback = None

    def _dense(self) -> _Explicit:
        k = int(self.sizes.max())
        return _Explicit(_fixed_bases(self.C, self.subs, k, "exact", 4, 1, 0))

    def analyse(self, X: np.ndarray, parts) -> list[np.ndarray]:
        if self._fallback is None:
            try:
                return self.fb.analyse(X)
            except np.linalg.LinAlgError:
                self._fallback = self._dense()
        return self._fallback.analyse(X, parts)

    def analyse_explicit(self, X: np.ndarray, parts) -> list[np.ndarray]:
        """:meth:`analyse`, forming the bases of :meth:`explicit` in the same pass."""
        if self._fallback is None and self._explicit is None:
            try:
                coefs, bases = self.fb.analyse_explicit(X)
                self._explicit = _Explicit(bases)
                return coefs
            except np.linalg.LinAlgError:
                self._fallback = self._dense()
        return self.analyse(X, parts)

    def synthesise(self, coefs) -> list[np.ndarray]:
        if self._fallback is None:
            try:
                return self.fb.synthesise(coefs)
            except np.linalg.LinAlgError:
                self._fallback = self._dense()
        return self._fallback.synthesise(coefs)

    def explicit(self) -> _Explicit:
        """The bases as dense matrices (formed once, for repeated synthesis)."""
        if self._fallback is not None:
            return self._fallback
        if self._explicit is None:
            try:
                self._explicit = _Explicit(self.fb.explicit())
            except np.linalg.LinAlgError:
                self._fallback = self._dense()
                return self._fallback
        return self._explicit


def _fixed_bases(C, subs, k: int, method: str, zeta: int, n_iter: int, seed) -> list[np.ndarray]:
    """The dictionaries of :func:`spectrageo.spectral.submesh_eigenbases` (``"oi"`` or ``"exact"``)
    with the fixed-order kernels of :mod:`._dense_fixed`, so every machine gets the same bases.

    ``"exact"`` and the first submesh of ``"oi"``: the ``k`` lowest eigenvectors of the dense
    submesh Laplacian. Later submeshes of ``"oi"``: ``n_iter`` orthogonal iterations (Algorithm 6,
    Eq. 5.42) from the previous basis, Householder QR (Eq. A.3-A.4), then the Ritz vectors.
    """
    from .._validation import as_rng
    from ..spectral.orthogonal import DELTA_REL, _nb_permuted_laplacian, _SubmeshSystems
    from . import _dense_fixed as D

    systems = _SubmeshSystems(C, True, False, None)
    gen = as_rng(seed)
    bases: list[np.ndarray] = []
    U_prev = None
    for part in subs.parts:
        ni = part.size
        ki = int(min(k, ni))
        L, (ptr, ind, val) = systems.laplacian(part)
        if method == "exact" or U_prev is None or ni <= 2:
            _w, U, _info = D.eigh_lowest(L.toarray(), ki)
            bases.append(U)
            U_prev = U
            continue
        U = _carry_over(U_prev, ni, ki, gen)
        # the shifted factor of spectrageo.spectral.orthogonal.ShiftedFactor, without fastmath
        dg = float(np.abs(L.diagonal()).mean())
        delta = DELTA_REL * dg if dg > 0 else DELTA_REL
        perm = D.reverse_cuthill_mckee(ptr.astype(np.int64), ind.astype(np.int64))
        Ap, Ai, Ax = _nb_permuted_laplacian(ptr, ind, val, perm, delta)
        Rp, Ri, Rx, ok = D.envelope_cholesky(Ap, Ai, Ax)
        if not ok:  # L + delta I is positive definite; kept for safety: the exact basis
            _w, U, _info = D.eigh_lowest(L.toarray(), ki)
            bases.append(U)
            U_prev = U
            continue
        Lp, Li, Lx = D.transpose_rows(Rp, Ri, Rx)
        for _ in range(n_iter):
            Z = np.ascontiguousarray(U[perm])
            D.solve_power(Lp, Li, Lx, Rp, Ri, Rx, Z, int(zeta))
            Y = np.empty_like(Z)
            Y[perm] = Z
            Q, _R = D.qr(Y)
            LQ = np.ascontiguousarray(L @ Q)  # scipy.sparse: one fixed loop over the nonzeros
            H = D.matmul_tn(Q, LQ)
            H = 0.5 * (H + H.T)
            _theta, W, _info = D.eigh(H)
            U = D.matmul(Q, W)
        D.fix_signs(U)
        bases.append(U)
        U_prev = U
    return bases


def _carry_over(U: np.ndarray, n: int, k: int, gen) -> np.ndarray:
    """The previous submesh's basis as the start of one of ``n`` vertices and ``k`` columns, cut or
    padded with random rows and columns as in :func:`spectrageo.spectral.submesh_eigenbases` (the
    codec's equal-sized submeshes pass it on unchanged).
    """
    from ._dense_fixed import qr

    if U.shape[0] > n:
        U = qr(np.ascontiguousarray(U[:n]))[0]
    elif U.shape[0] < n:
        pad = gen.standard_normal((n - U.shape[0], U.shape[1])) / np.sqrt(n)
        U = qr(np.vstack([U, pad]))[0]
    if U.shape[1] > k:
        U = U[:, :k]
    elif U.shape[1] < k:
        U = np.column_stack([U, gen.standard_normal((n, k - U.shape[1]))])
    return np.ascontiguousarray(U)


def dictionaries(F: np.ndarray, n: int, p: SpectralParams):
    """Submeshes and their low-frequency dictionaries from the connectivity (same on both sides).

    When ``k`` covers every submesh, ``p.direct`` selects the direct computation of the complete
    bases (:class:`_Full`); otherwise, and always when ``k`` is smaller, the orthogonal iterations
    (:func:`_fixed_bases`). Returns ``(subs, dic)``: ``dic.sizes`` is the number of basis vectors
    of every submesh, ``dic.analyse(X, subs.parts)`` the coefficients ``U_i^T X[part_i]`` and
    ``dic.synthesise(coefs)`` the per-submesh values ``U_i[:, :m_i] c_i``.
    """
    from ..graph import adjacency_matrix
    from ._spectral_fast import overlapped_submeshes

    C = adjacency_matrix(F, n)
    size = min(p.submesh_size, n) if n >= 2 else 2
    if n < 2:  # a single vertex: one trivial submesh
        from ..spectral import Submeshes

        allv = np.arange(n, dtype=np.int64)
        subs = Submeshes([allv], [allv.copy()], n, [np.zeros(n, dtype=np.int64)])
        return subs, _Explicit([np.ones((n, 1))])
    subs = overlapped_submeshes(C, submesh_size=size, overlap=p.overlap, rng=p.seed)
    k = min(p.k, size)
    if p.direct and all(part.size <= k for part in subs.parts):
        # the subspace is the whole space: the dictionary is the complete eigenbasis
        return subs, _Full(C, subs)
    method = "exact" if p.basis == "exact" else "oi"
    return subs, _Explicit(_fixed_bases(C, subs, k, method, p.zeta, p.n_iter, p.seed))


def _band(c: np.ndarray) -> np.ndarray:
    """Octave band of column index ``c`` (0 -> 0, 1 -> 1, 2-3 -> 2, 4-7 -> 3, ...)."""
    c = np.asarray(c, dtype=np.int64)
    out = np.zeros(c.shape, dtype=np.int64)
    nz = c > 0
    # floor(log2(c)) + 1 is the bit length of c: the exponent of frexp, exact (no logarithm)
    out[nz] = np.frexp(c[nz].astype(np.float64))[1]
    return out


def layer_cutoffs(k: int) -> list[int]:
    cuts = sorted({max(1, k // 16), max(1, k // 4), k})
    return [c for c in cuts if c <= k]


def _layout(sizes: np.ndarray, cuts: list[int]):
    """For every layer: (submesh id, column) of each coefficient row, in a fixed order."""
    out = []
    lo = 0
    for hi in cuts:
        sub, col = [], []
        for i, s in enumerate(sizes):
            a, b = lo, min(hi, int(s))
            if b > a:
                sub.append(np.full(b - a, i, dtype=np.int64))
                col.append(np.arange(a, b, dtype=np.int64))
        sub = np.concatenate(sub) if sub else np.zeros(0, np.int64)
        col = np.concatenate(col) if col else np.zeros(0, np.int64)
        out.append((sub, col))
        lo = hi
    return out


def _groups(col: np.ndarray) -> tuple[np.ndarray, int]:
    """Group of each of the 3 coordinates of each row: (octave band - first band) * 3 + j."""
    if col.size == 0:
        return np.zeros(0, np.int64), 0
    band = _band(col)
    b0 = int(band.min())
    g = ((band - b0)[:, None] * 3 + np.arange(3)[None, :]).ravel()
    return g, (int(band.max()) - b0 + 1) * 3


class SpectralPlan:
    """Encoder state: dictionaries and unquantised coefficients; quantise at any step."""

    def __init__(self, X: np.ndarray, F: np.ndarray, p: SpectralParams) -> None:
        self.p = p
        self.n = X.shape[0]
        size = min(p.submesh_size, self.n) if self.n >= 2 else 2
        # new files take the direct computation whenever the bases are complete
        p.direct = self.n >= 2 and min(p.k, size) >= size
        self.subs, self.dic = dictionaries(F, self.n, p)
        self._X = X
        self.values = None

    def _analyse(self, explicit: bool) -> None:
        """The coefficients, once (with the explicit bases when ``explicit``)."""
        if self.values is not None:
            return
        X, p, parts = self._X, self.p, self.subs.parts
        if explicit and isinstance(self.dic, _Full):
            self.coef = self.dic.analyse_explicit(X, parts)
        else:
            self.coef = self.dic.analyse(X, parts)
        ks = self.dic.sizes.copy()
        if p.basis == "doi":
            ks = np.array([self._doi_size(c, X[part]) for c, part in zip(self.coef, parts)])
        self.sizes = ks
        self.cuts = layer_cutoffs(int(self.dic.sizes.max()))
        self.layout = _layout(self.sizes, self.cuts)
        values = []
        for sub, col in self.layout:
            bounds = np.searchsorted(sub, np.arange(len(self.sizes) + 1))
            rows = [
                self.coef[i][col[bounds[i] : bounds[i + 1]]]
                for i in np.flatnonzero(np.diff(bounds))
            ]
            values.append(np.concatenate(rows) if rows else np.zeros((0, 3)))
        self.values = values
        self._X = None

    def _doi_size(self, c: np.ndarray, Xi: np.ndarray) -> int:
        total = float(np.sum((Xi - Xi.mean(axis=0)) ** 2))
        if total <= 0:
            return 1
        e = np.sum(c**2, axis=1)
        resid = np.maximum(np.sum(Xi**2) - np.cumsum(e), 0.0)
        ok = np.flatnonzero(np.sqrt(resid / total) <= self.p.eps)
        return int(ok[0] + 1) if ok.size else c.shape[0]

    def params(self, step: float) -> bytes:
        self.p.step = float(step)
        return self.p.to_bytes()

    def chunks(self, step: float) -> list[tuple[int, bytes]]:
        self._analyse(False)
        out = []
        if self.p.basis == "doi":
            out.append((TAG_SIZES, zstd_compress(self.sizes.astype("<u2").tobytes())))
        for (_sub, col), vals in zip(self.layout, self.values):
            q = np.rint(vals / step).astype(np.int64).ravel()
            g, ng = _groups(col)
            out.append((TAG_LAYER, encode_groups(q, g, ng)))
        return out

    def reconstruct(self, step: float | None) -> np.ndarray:
        from ..spectral import reassemble

        self._analyse(True)
        vals = [v if step is None else np.rint(v / step) * step for v in self.values]
        coefs = _scatter(self.layout, vals, self.sizes)
        return reassemble(self.dic.explicit().synthesise(coefs), self.subs)


_OPTIONS = ("submesh_size", "overlap", "seed", "basis", "zeta", "n_iter", "k", "eps")


def make_plan(X: np.ndarray, F: np.ndarray, method: str, options: dict) -> SpectralPlan:
    """Validate the ``spectral`` options and prepare the encoder."""
    from .._validation import check_positive

    bad = sorted(set(options) - set(_OPTIONS))
    if bad:
        raise InvalidInputError(
            f"unknown option(s) {bad} for method 'spectral'; choose from {list(_OPTIONS)}."
        )
    o = dict(options)
    basis = o.get("basis", "oi")
    check_choice(basis, "basis", BASES)
    for name in ("submesh_size", "k", "zeta", "n_iter"):
        if name in o:
            check_positive(o[name], name, integer=True)
    size = int(o.get("submesh_size", 300))
    if not 16 <= size <= 20000:
        raise InvalidInputError(f"`submesh_size` must be in 16..20000; got {size}.")
    k = int(o.get("k", size))
    if k > size:
        raise InvalidInputError(f"`k` must be at most `submesh_size` = {size}; got {k}.")
    overlap = o.get("overlap", 0.1)
    if not isinstance(overlap, int | float) or not 0 <= overlap < 0.9:
        raise InvalidInputError(f"`overlap` must be in [0, 0.9); got {overlap!r}.")
    eps = o.get("eps", 0.002)
    if not isinstance(eps, int | float) or not 0 <= eps < 1:
        raise InvalidInputError(f"`eps` must be in [0, 1); got {eps!r}.")
    if int(o.get("zeta", 4)) > 16 or int(o.get("n_iter", 1)) > 64:
        raise InvalidInputError("`zeta` must be at most 16 and `n_iter` at most 64.")
    seed = o.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise InvalidInputError(f"`seed` must be an integer in [0, 2**32); got {seed!r}.")
    p = SpectralParams(
        submesh_size=size,
        overlap=overlap,
        seed=seed,
        basis=basis,
        zeta=int(o.get("zeta", 4)),
        n_iter=int(o.get("n_iter", 1)),
        k=k,
        eps=eps if basis == "doi" else 0.0,
    )
    return SpectralPlan(X, F, p)


def describe(params: bytes, method: str) -> dict:
    return SpectralParams.from_bytes(params).as_dict()


def decode(
    params: bytes,
    chunks: list[tuple[int, bytes]],
    F: np.ndarray,
    n: int,
    method: str = "spectral",
    *,
    complete: bool = True,
) -> np.ndarray:
    """Normalised coordinates (n, 3) from the geometry chunks; a ``complete`` file (not a prefix
    read with ``partial=True``) must hold every frequency layer."""
    from ..spectral import reassemble

    p = SpectralParams.from_bytes(params)
    subs, dic = dictionaries(F, n, p)
    sizes = dic.sizes.copy()
    rest = list(chunks)
    if p.basis == "doi":
        if not rest or rest[0][0] != TAG_SIZES:
            raise InvalidInputError(".sgc spectral stream lacks its subspace sizes.")
        raw = zstd_decompress(rest.pop(0)[1], 2 * sizes.size, "subspace sizes")
        got = np.frombuffer(raw, dtype="<u2").astype(np.int64)
        if got.size != sizes.size or (got < 1).any() or (got > sizes).any():
            raise InvalidInputError(".sgc subspace sizes do not match the connectivity.")
        sizes = got
    layout = _layout(sizes, layer_cutoffs(int(dic.sizes.max())))
    if len(rest) > len(layout) or any(t != TAG_LAYER for t, _ in rest):
        raise InvalidInputError(".sgc spectral stream has unexpected chunks.")
    if complete and len(rest) < len(layout):
        raise InvalidInputError(
            f".sgc spectral stream holds {len(rest)} of its {len(layout)} frequency layers "
            "(the header's chunk count does not match the parameters)."
        )
    vals = []
    for (_sub, col), (_t, payload) in zip(layout, rest):
        g, ng = _groups(col)
        vals.append(decode_groups(payload, g, ng, "spectral layer").reshape(-1, 3) * p.step)
    coefs = _scatter(layout[: len(vals)], vals, sizes)
    return reassemble(dic.synthesise(coefs), subs)


def _scatter(layout, vals, sizes) -> list[np.ndarray]:
    """Per-submesh coefficient matrices from the per-layer rows (missing rows stay zero); as many
    columns as the rows have (3 for one signal, more when signals are batched)."""
    d = vals[0].shape[1] if len(vals) else 3
    coefs = [np.zeros((int(s), d)) for s in sizes]
    for (sub, col), v in zip(layout, vals):
        bounds = np.searchsorted(sub, np.arange(len(sizes) + 1))  # rows are submesh-major
        for i in np.flatnonzero(np.diff(bounds)):
            a, b = bounds[i], bounds[i + 1]
            coefs[i][col[a:b]] = v[a:b]
    return coefs
