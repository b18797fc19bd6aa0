"""Feature-aware high-pass quantisation (Section 5.2.3, Algorithm 9, Eq. 5.53-5.54) and its
saliency-driven multiscale variant (Algorithm 10).

Encoder: delta coordinates ``delta = L v`` (``L = D - C``, Eq. 4.13); a mask of the deltas sent
finely (``feature``: the ``feature_fraction`` most salient vertices of the RPCA geometric
saliency, Algorithm 9 steps 1-2; ``saliency``: the fractions ``class_keep`` of ``n_classes``
classes, Algorithm 10 steps 2-5); anchors chosen from the connectivity alone (:func:`anchors`);
uniform quantisation (Eq. 5.53) of anchors and masked deltas with ``step``, the other deltas with
``ratio * step`` (0: zero) in a second layer. Under rate control the encoder also tries the
shares :data:`LEVELS` of sent deltas and keeps the best (docs/decisions.md#compress-levels,
docs/decisions.md#compress-feature-levels-why).

Decoder: ``[L; I_a] v = [delta; v_a]`` (Eq. 5.54) through its normal equations and the
fixed-order sparse Cholesky of :mod:`spectrageo.linalg._fixed`. ``feature_fraction=1`` is the
uniform baseline of Fig. 5.69-5.70.
"""

from __future__ import annotations

import heapq
import struct

import numba
import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from ._entropy import decode_groups, encode_groups, zstd_compress, zstd_decompress

TAG_MASK = 4
TAG_ANCHORS = 5
TAG_DELTA_FINE = 6
TAG_DELTA_COARSE = 7

_P = struct.Struct("<ffdI")  # files without the anchor-scheme byte (scheme 0)
_P1 = struct.Struct("<ffdIB")  # anchor_fraction, ratio, step, seed, anchor scheme
_MIN_FACES = 8  # below this the saliency patches are meaningless

#: shares of the vertices whose deltas are sent, tried by the rate control (see the module notes)
LEVELS = (0.1, 0.15, 0.2, 0.3, 0.5, 0.75, 1.0)

_DEFAULTS = {
    "feature": {"anchor_fraction": 0.01, "feature_fraction": 0.15, "ratio": 4.0},
    "saliency": {"anchor_fraction": 0.10, "ratio": 0.0},
}
_OPTIONS = {
    "feature": ("anchor_fraction", "feature_fraction", "ratio", "seed", "mask"),
    "saliency": ("anchor_fraction", "ratio", "seed", "n_classes", "class_keep", "mask"),
}


def _laplacian(F: np.ndarray, n: int) -> sp.csr_matrix:
    from ..graph import adjacency_matrix, laplacian_from_adjacency

    C = adjacency_matrix(F, n)
    C.data[:] = 1.0
    return laplacian_from_adjacency(C).tocsr()


#: anchor choice recorded in the parameters (a byte after them; files without it use scheme 0):
#: 0 = one METIS part per anchor, 1 = farthest-point sampling in hops (see :func:`anchors`)
ANCHOR_SCHEME = 1


def anchors(F: np.ndarray, n: int, fraction: float, seed: int, scheme: int = ANCHOR_SCHEME):
    """Anchor vertices from the connectivity alone (sorted, unique): about ``fraction * n``
    vertices spread over the mesh, plus the smallest index of every connected component.

    ``scheme=1``: farthest-point sampling in hops (:func:`_farthest_points`): every component first
    gets its smallest index, then ``n_a`` more anchors follow, each the vertex farthest in hops
    from all anchors so far, ties to the smallest index (``seed`` unused; hops because the decoder
    does not know edge lengths). ``scheme=0`` (older files): one METIS part per anchor (seeded by
    ``seed``), each giving its smallest index. See docs/decisions.md#compress-anchors.
    """
    from ..graph import adjacency_matrix
    from ..spectral.partition import _metis, _split
    from ._animation import _component_anchors

    C = adjacency_matrix(F, n).tocsr()
    C.data[:] = 1.0
    n_a = max(1, int(np.ceil(fraction * n)))
    if n_a >= n:
        return np.arange(n, dtype=np.int64)
    if scheme == 0:
        from scipy.sparse.csgraph import connected_components

        if n_a >= 2:
            membership = _metis(C, n_a, int(seed))
            picks = np.array([int(p.min()) for p in _split(membership, n_a)], dtype=np.int64)
        else:
            picks = np.zeros(1, dtype=np.int64)
        ncomp, lab = connected_components(C, directed=False)
        first = np.full(ncomp, n, dtype=np.int64)
        np.minimum.at(first, lab, np.arange(n))
        have = np.zeros(ncomp, dtype=bool)
        have[lab[picks]] = True
        return np.unique(np.r_[picks, first[~have]])
    seeds = _component_anchors(C)  # the smallest index of every component, ascending
    out = np.empty(n_a, dtype=np.int64)
    k = _farthest_points(C.indptr.astype(np.int64), C.indices.astype(np.int64), seeds, n_a, out)
    return np.unique(np.r_[seeds, out[:k]])


@numba.njit(cache=True)
def _farthest_points(indptr, indices, seeds, n_a, out):  # pragma: no cover - jitted
    """Farthest-point sampling in hops from the anchors ``seeds``: ``n_a`` more anchors, ties to
    the smallest index, by a heap of ``(-distance, vertex)`` and breadth-first updates that stop
    where they improve nothing. Returns the number of anchors written to ``out``.
    """
    n = indptr.size - 1
    far = n + 1
    dist = np.full(n, far, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    heap = [(0, 0)]
    heap.pop()
    k = -seeds.size  # the seeds are not written to ``out``
    while k < n_a:
        if k < 0:
            a = seeds[seeds.size + k]
        else:
            if len(heap) == 0:
                break
            negd, a = heapq.heappop(heap)
            if -negd != dist[a]:
                continue  # stale entry
            if dist[a] == 0:
                break
            out[k] = a
        k += 1
        dist[a] = 0
        head = 0
        tail = 1
        queue[0] = a
        while head < tail:
            u = queue[head]
            head += 1
            nd = dist[u] + 1
            for j in range(indptr[u], indptr[u + 1]):
                w = indices[j]
                if nd < dist[w]:
                    dist[w] = nd
                    queue[tail] = w
                    tail += 1
                    if k >= 0:
                        heapq.heappush(heap, (-nd, w))
        if k == 0:  # every component reached: start the heap from the distances
            heap = [(-dist[v], v) for v in range(n)]
            heapq.heapify(heap)
    return max(k, 0)


class _Solver:
    """Normal equations of ``[L; I_a] v = [delta; v_a]`` (Eq. 5.54), formed exactly (``L`` is the
    binary ``D - C``) and factorised by the fixed-order sparse Cholesky of
    :mod:`spectrageo.linalg._fixed`; SPD because every component holds an anchor.
    """

    def __init__(self, L: sp.csr_matrix, a: np.ndarray) -> None:
        from ..linalg._fixed import SparseCholesky

        n = L.shape[0]
        P = sp.csr_matrix((np.ones(a.size), (np.arange(a.size), a)), shape=(a.size, n))
        self.L, self.P = L, P
        self.chol = SparseCholesky(L.T @ L + P.T @ P)

    def solve(self, delta: np.ndarray, va: np.ndarray) -> np.ndarray:
        return self.chol.solve(np.asarray(self.L.T @ delta + self.P.T @ va))


def _feature_rank(V, F, seed: int) -> np.ndarray | None:
    """Vertices by decreasing RPCA geometric saliency (Algorithm 9 steps 1-2); ``None`` on meshes
    too small for patches (every delta is then sent)."""
    if F.shape[0] < _MIN_FACES:
        return None
    from ..saliency import geometric_saliency

    s = geometric_saliency(V, F, k=min(25, F.shape[0] - 1), rng=seed)
    return np.argsort(-s, kind="stable")


def _mask_from_rank(rank: np.ndarray | None, n: int, fraction: float) -> np.ndarray:
    if fraction >= 1.0 or rank is None:
        return np.ones(n, dtype=bool)
    mask = np.zeros(n, dtype=bool)
    mask[rank[: int(round(fraction * n))]] = True
    return mask


def _saliency_classes(V, F, n_classes: int, seed: int):
    """Combined saliency and its quantile classes (Algorithm 10 steps 2-3); ``None`` on meshes
    too small for patches."""
    from ..saliency import SaliencyOptions, saliency, saliency_classes

    if F.shape[0] < _MIN_FACES:
        return None
    s = saliency(V, F, SaliencyOptions(k=min(25, F.shape[0] - 1), rng=seed))
    return s, saliency_classes(s, n_classes, class_edges="quantile")


def _mask_from_classes(sal, n: int, keep) -> np.ndarray:
    """The fractions ``keep`` of every class, most salient first (Algorithm 10 steps 4-5)."""
    if sal is None:
        return np.ones(n, dtype=bool)
    s, cls = sal
    mask = np.zeros(n, dtype=bool)
    for c in range(len(keep)):
        idx = np.flatnonzero(cls == c)
        k = int(round(keep[c] * idx.size))
        mask[idx[np.argsort(-s[idx], kind="stable")[:k]]] = True
    return mask


class FeaturePlan:
    def __init__(self, X, F, method: str, o: dict) -> None:
        self.n = n = X.shape[0]
        self.method = method
        self.anchor_fraction = float(np.float32(o["anchor_fraction"]))
        self.ratio = float(np.float32(o["ratio"]))
        self.seed = int(o.get("seed", 0))
        self._rank: np.ndarray | None | bool = None  # saliency ranking (feature method)
        self.scheme = ANCHOR_SCHEME
        self.a = anchors(F, n, self.anchor_fraction, self.seed, self.scheme)
        self.L = _laplacian(F, n)
        self.delta = np.asarray(self.L @ X)
        self.va = X[self.a]
        if "mask" in o and o["mask"] is not None:
            mask = np.asarray(o["mask"])
            if mask.dtype != bool or mask.shape != (n,):
                raise InvalidInputError(f"`mask` must be a boolean array of shape ({n},).")
            self.mask = mask.copy()
        elif method == "feature":
            fraction = float(o["feature_fraction"])
            self._x, self._f = X, F
            self._rank = _feature_rank(X, F, self.seed) if fraction < 1.0 else False
            self.mask = _mask_from_rank(None if fraction >= 1.0 else self._rank, n, fraction)
        else:
            self._sal = _saliency_classes(X, F, int(o["n_classes"]), self.seed)
            self._profile = np.asarray(o["class_keep"], dtype=np.float64)
            self.mask = _mask_from_classes(self._sal, n, self._profile)
        # the factorisation of Eq. (5.54) is made when a reconstruction is first asked for (rate
        # control); a file coded at a given step never needs it. The box is shared by the level
        # plans of :meth:`levels` (shallow copies), so it is factorised once.
        self._solver_box: list[_Solver] = []

    @property
    def solver(self) -> _Solver:
        if not self._solver_box:
            self._solver_box.append(_Solver(self.L, self.a))
        return self._solver_box[0]

    def levels(self) -> list[FeaturePlan]:
        """The plans of :data:`LEVELS` for the rate control, sharing anchors, Laplacian and
        factorisation; ``saliency`` keeps ``min(1, a * class_keep[c])`` of every class, ``a`` giving the
        level's share (Algorithm 10 steps 4-5).
        """
        import copy

        from ..saliency.simplify import class_keep_fractions

        if self.method == "feature":
            if self._rank is False:  # not ranked yet (the plan was made for uniform quantisation)
                self._rank = _feature_rank(self._x, self._f, self.seed)
            if self._rank is None:  # too small for patches: every delta is sent at every level
                return [self]
        elif getattr(self, "_sal", None) is None:  # a given mask, or too small for patches
            return [self]
        out = []
        for f in LEVELS:
            p = copy.copy(self)
            if self.method == "feature":
                p.mask = _mask_from_rank(self._rank, self.n, f)
            elif f >= 1.0:
                p.mask = np.ones(self.n, dtype=bool)
            else:
                counts = np.bincount(self._sal[1], minlength=self._profile.size)
                weights = np.maximum(self._profile, 1e-3)
                keep = class_keep_fractions(counts, int(round(f * self.n)), weights=weights)
                p.mask = _mask_from_classes(self._sal, self.n, keep)
            p.ratio = 0.0 if f < 1.0 else 1.0
            out.append(p)
        return out

    def params(self, step: float) -> bytes:
        return _P1.pack(self.anchor_fraction, self.ratio, float(step), self.seed, self.scheme)

    def _quant(self, step: float):
        qa = np.rint(self.va / step).astype(np.int64)
        qf = np.rint(self.delta[self.mask] / step).astype(np.int64)
        if self.ratio > 0:
            qc = np.rint(self.delta[~self.mask] / (self.ratio * step)).astype(np.int64)
        else:
            qc = np.zeros((0, 3), dtype=np.int64)
        return qa, qf, qc

    def chunks(self, step: float):
        qa, qf, qc = self._quant(step)
        out = [
            (TAG_MASK, zstd_compress(np.packbits(self.mask).tobytes())),
            (TAG_ANCHORS, _enc3(qa)),
            (TAG_DELTA_FINE, _enc3(qf)),
        ]
        if self.ratio > 0:
            out.append((TAG_DELTA_COARSE, _enc3(qc)))
        return out

    def reconstruct(self, step: float | None) -> np.ndarray:
        if step is None:  # the floor: exact anchors, exact masked deltas
            d = self.delta.copy()
            if self.ratio == 0:
                d[~self.mask] = 0.0
            return self.solver.solve(d, self.va)
        qa, qf, qc = self._quant(step)
        d = np.zeros_like(self.delta)
        d[self.mask] = qf * step
        if self.ratio > 0:
            d[~self.mask] = qc * (self.ratio * step)
        return self.solver.solve(d, qa * step)


def _enc3(q: np.ndarray) -> bytes:
    g = np.tile(np.arange(3), q.shape[0])
    return encode_groups(q.ravel(), g, 3)


def _dec3(buf: bytes, rows: int, what: str) -> np.ndarray:
    g = np.tile(np.arange(3), rows)
    return decode_groups(buf, g, 3, what).reshape(rows, 3)


def _check_fraction(v, name: str, *, lo_open: bool = True) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
        raise InvalidInputError(f"`{name}` must be a number in (0, 1]; got {v!r}.")
    if not 0 < float(v) <= 1:
        raise InvalidInputError(f"`{name}` must be in (0, 1]; got {v!r}.")
    return float(v)


def make_plan(X, F, method: str, options: dict) -> FeaturePlan:
    bad = sorted(set(options) - set(_OPTIONS[method]))
    if bad:
        raise InvalidInputError(
            f"unknown option(s) {bad} for method {method!r}; choose from {list(_OPTIONS[method])}."
        )
    o = {**_DEFAULTS[method], **options}
    _check_fraction(o["anchor_fraction"], "anchor_fraction")
    r = o["ratio"]
    if isinstance(r, bool) or not isinstance(r, int | float) or not (r == 0 or 1 <= r <= 1e4):
        raise InvalidInputError(f"`ratio` must be 0 or in [1, 10000]; got {r!r}.")
    seed = o.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise InvalidInputError(f"`seed` must be an integer in [0, 2**32); got {seed!r}.")
    if method == "feature":
        _check_fraction(o["feature_fraction"], "feature_fraction")
    else:
        nc = o.get("n_classes", 4)
        if isinstance(nc, bool) or not isinstance(nc, int) or not 1 <= nc <= 64:
            raise InvalidInputError(f"`n_classes` must be an integer in 1..64; got {nc!r}.")
        keep = o.get("class_keep")
        if keep is None:  # least salient class first
            keep = np.linspace(0.1, 1.0, nc) if nc > 1 else np.ones(1)
        keep = np.asarray(keep, dtype=np.float64)
        if keep.shape != (nc,) or not ((keep >= 0) & (keep <= 1)).all():
            raise InvalidInputError(f"`class_keep` must hold {nc} fractions in [0, 1].")
        o["n_classes"], o["class_keep"] = nc, keep
    return FeaturePlan(X, F, method, o)


def describe(params: bytes, method: str) -> dict:
    af, ratio, step, _seed, scheme = _unpack(params)
    return {
        "anchor_fraction": round(af, 6),
        "ratio": round(ratio, 6),
        "step": step,
        "anchor_scheme": scheme,
    }


def _read_mask(body: dict, n: int) -> np.ndarray:
    if TAG_MASK not in body:
        raise InvalidInputError(".sgc feature stream lacks its mask.")
    raw = zstd_decompress(body[TAG_MASK], (n + 7) // 8, "feature mask")
    if len(raw) != (n + 7) // 8:
        raise InvalidInputError(".sgc feature mask has the wrong size.")
    return np.unpackbits(np.frombuffer(raw, dtype=np.uint8))[:n].astype(bool)


def sent_share(chunks, n: int) -> float:
    """Share of the vertices whose deltas are sent at the fine step (the mask's ones)."""
    return float(_read_mask(dict(chunks), n).sum()) / max(n, 1)


def _unpack(params: bytes):
    if len(params) == _P.size:
        af, ratio, step, seed = _P.unpack(params)
        scheme = 0
    elif len(params) == _P1.size:
        af, ratio, step, seed, scheme = _P1.unpack(params)
        if scheme > ANCHOR_SCHEME:
            raise InvalidInputError(
                f".sgc feature stream uses anchor scheme {scheme}, newer than this version of "
                f"spectrageo reads (up to {ANCHOR_SCHEME})."
            )
    else:
        raise InvalidInputError(
            f".sgc {_P.size}- or {_P1.size}-byte parameters expected; got {len(params)}."
        )
    if not (0 < af <= 1 and (ratio == 0 or 1 <= ratio <= 1e4) and np.isfinite(step) and step > 0):
        raise InvalidInputError(".sgc feature parameters are out of range.")
    return af, ratio, step, seed, scheme


def decode(
    params: bytes, chunks, F: np.ndarray, n: int, method: str, *, complete: bool = True
) -> np.ndarray:
    """Coordinates (n, 3) from the feature stream; a ``complete`` file (not a prefix read with
    ``partial=True``) must hold its fine deltas, and its coarse deltas exactly when the ratio
    is not zero."""
    af, ratio, step, seed, scheme = _unpack(params)
    tags = [t for t, _ in chunks]
    if complete and (TAG_DELTA_FINE not in tags or (ratio > 0) != (TAG_DELTA_COARSE in tags)):
        raise InvalidInputError(".sgc feature stream lacks delta chunks its parameters call for.")
    need = [TAG_MASK, TAG_ANCHORS]
    allowed = {TAG_MASK, TAG_ANCHORS, TAG_DELTA_FINE, TAG_DELTA_COARSE}
    if any(t not in allowed for t in tags) or len(set(tags)) != len(tags):
        raise InvalidInputError(".sgc feature stream has unexpected chunks.")
    if tags[:2] != need:
        raise InvalidInputError(".sgc feature stream lacks its mask or anchors.")
    body = dict(chunks)
    mask = _read_mask(body, n)
    a = anchors(F, n, af, seed, scheme)
    va = _dec3(body[TAG_ANCHORS], a.size, "anchors") * step
    L = _laplacian(F, n)
    d = np.zeros((n, 3))
    if TAG_DELTA_FINE in body:
        d[mask] = _dec3(body[TAG_DELTA_FINE], int(mask.sum()), "feature deltas") * step
    if TAG_DELTA_COARSE in body:
        if ratio == 0:
            raise InvalidInputError(".sgc feature stream has an unexpected chunk.")
        d[~mask] = _dec3(body[TAG_DELTA_COARSE], int((~mask).sum()), "deltas") * (ratio * step)
    return _Solver(L, a).solve(d, va)
