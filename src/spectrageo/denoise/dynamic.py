"""Denoising of mesh animations with fixed connectivity (thesis Section 5.1.2): Algorithm 3
(:func:`gft_rpca`, low-rank analysis of the high GFT frequencies of all frames), an RPCA of the
face normals (:func:`normals_rpca`), or any static method frame by frame
(:func:`denoise_frames`); :func:`denoise_animation` dispatches. Noise that repeats in every
frame is itself low rank and is kept (Fig. 5.29)."""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._plugins import load_plugins
from .._progress import progress
from .._validation import (
    as_faces,
    as_frames,
    as_rng,
    check_choice,
    check_positive,
    options_with_legacy,
)

__all__ = [
    "DYNAMIC_METHODS",
    "GFTRPCABlock",
    "GFTRPCAOptions",
    "GFTRPCAResult",
    "GFTRPCASetup",
    "NormalsRPCAResult",
    "denoise_animation",
    "denoise_frames",
    "dynamic_methods",
    "gft_rpca",
    "gft_rpca_block",
    "gft_rpca_setup",
    "normals_rpca",
    "register_animation_method",
]

#: Methods that treat the animation as one object (the others run frame by frame).
DYNAMIC_METHODS = ("gft-rpca", "normals-rpca")

#: Largest vertex count for which ``basis="exact"`` (a dense eigendecomposition of the whole
#: n x n Laplacian, O(n^3) time and 8 n^2 bytes) is allowed.
EXACT_LIMIT = 6000


# --------------------------------------------------------------------------- helpers
def _faces_of(frames, F):
    if F is None:
        F = getattr(frames, "faces", None)
    if F is None:
        raise InvalidInputError("`F` is required (the faces shared by all frames).")
    return F


def _check_energy(energy) -> float:
    if isinstance(energy, bool) or not isinstance(energy, (int, float, np.integer, np.floating)):
        raise InvalidInputError(f"`energy` must be a number in (0, 1]; got {energy!r}.")
    energy = float(energy)
    if not 0.0 < energy <= 1.0:
        raise InvalidInputError(f"`energy` must be in (0, 1]; got {energy!r}.")
    return energy


def _check_rank(rank) -> int | None:
    if rank is None:
        return None
    if isinstance(rank, bool) or not isinstance(rank, (int, np.integer)):
        raise InvalidInputError(f"`rank` must be a positive integer or None; got {rank!r}.")
    if rank < 1:
        raise InvalidInputError(f"`rank` must be >= 1; got {rank}.")
    return int(rank)


def _check_block_size(block_size, T: int) -> int:
    if block_size is None:
        return T
    if isinstance(block_size, bool) or not isinstance(block_size, (int, np.integer)):
        raise InvalidInputError(
            f"`block_size` must be a positive integer or None; got {block_size!r}."
        )
    if block_size < 1:
        raise InvalidInputError(f"`block_size` must be >= 1; got {block_size}.")
    return int(min(block_size, T))


@contextlib.contextmanager
def _blas_threads(limit: int | None):
    """Limit BLAS threads while many small matrices are processed (threads only add overhead
    there, and oversubscribe machines that run several jobs)."""
    if limit is None:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        yield
        return
    with threadpool_limits(limits=limit, user_api="blas"):
        yield


@dataclass
class _Stats:
    n_iter: int = 0
    converged: bool = True
    residual: float = 0.0
    n_rpca: int = 0

    def add(self, res) -> None:
        self.n_iter = max(self.n_iter, int(res.n_iter))
        self.converged = self.converged and bool(res.converged)
        self.residual = max(self.residual, float(res.residual))
        self.n_rpca += 1

    def merge(self, other) -> None:
        """Fold in the statistics of another block (max / all / max: order does not matter)."""
        self.n_iter = max(self.n_iter, int(other.n_iter))
        self.converged = self.converged and bool(other.converged)
        self.residual = max(self.residual, float(other.residual))


def _low_rank(M: np.ndarray, rank: int | None, lam, max_iter: int, tol: float, gen, stats):
    """Low-rank part of ``M`` by the bilateral-factorisation RPCA (Eq. 5.29-5.35)."""
    from ..linalg import RPCASolverOptions, rpca

    r = None if rank is None else min(rank, *M.shape)
    res = rpca(
        M,
        method="godec",
        rank=r,
        lam=lam,
        tol=tol,
        max_iter=max_iter,
        on_nonconvergence="ignore",
        options=RPCASolverOptions(backend="dense"),
        rng=gen,
    )
    stats.add(res)
    return res.low_rank


# --------------------------------------------------------------------------- Algorithm 3
@dataclass(frozen=True, eq=False)
class GFTRPCAResult:
    """Result of :func:`gft_rpca`."""

    #: (T, n, 3) denoised animation
    frames: np.ndarray
    #: (n_parts, n_blocks) ``n_h`` of Eq. (5.27) per spectral part and frame block
    n_high: np.ndarray
    #: "exact" or "partitioned"
    basis: str
    n_submeshes: int
    #: RPCA statistics: largest iteration count, all converged, largest final change
    n_iter: int
    converged: bool
    residual: float
    #: wall time
    seconds: float


def _n_high(H: np.ndarray, energy: float) -> np.ndarray:
    """Per-frame ``n_hi`` of Eqs. (5.25)-(5.26) for spectra ``H`` (T, k, 3), ascending frequency."""
    e = np.einsum("tkc,tkc->tk", H, H)
    total = e.sum(axis=1, keepdims=True)
    cum = np.cumsum(e[:, ::-1], axis=1)
    return np.count_nonzero(cum <= (1.0 - energy) * total * (1.0 + 1e-12), axis=1)


def _apply(B: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``B @ X[t]`` for every frame of ``X`` (T, k, 3) as one matrix product."""
    T, k, d = X.shape
    Y = B @ X.transpose(1, 0, 2).reshape(k, T * d)
    return Y.reshape(B.shape[0], T, d).transpose(1, 0, 2)


def _algorithm3_block(
    X: np.ndarray,
    U: np.ndarray,
    energy: float,
    rank: int | None,
    lam,
    max_iter: int,
    tol: float,
    gen,
    stats: _Stats,
) -> tuple[np.ndarray, int]:
    """Lines 2-17 of Algorithm 3 for one block of frames ``X`` (T, k, 3) on a full basis ``U`` (k, k)."""
    T, k, _ = X.shape
    H = _apply(U.T, X)  # GFT of every frame, Eq. 4.4
    nh_i = _n_high(H, energy)  # Eq. 5.25-5.26
    nh = int(nh_i.max())  # Eq. 5.27
    if nh == 0:
        return X.copy(), 0
    out = H  # updated in place: every coherent matrix is read before its columns are replaced
    lo = k - nh
    # Eq. 5.36 keeps the n_hi highest components of frame i from E (the last n_hi columns of M)
    col = np.arange(nh)[None, :]
    keep = col >= (nh - nh_i)[:, None]  # (T, nh) mask of the entries taken from E
    for c in range(3):
        M = H[:, lo:, c]  # coherent matrix, Eq. 5.24 (n_s x n_h)
        E = _low_rank(M, rank, lam, max_iter, tol, gen, stats)  # Eq. 5.29-5.35
        out[:, lo:, c] = np.where(keep, E, M)
    return _apply(U, out), nh  # IGFT, Eq. 5.37


# ---------------------------------------------------------------------- seeds, setup, one block
#: Spawn-key prefixes of the generators derived from the user's seed: one for the spatial setup
#: (METIS, the eigensolver's random starts), one per (submesh, frame block) for the RPCA.
_KEY_SPATIAL = 0
_KEY_BLOCK = 1


def _seed_entropy(rng) -> tuple[int, ...]:
    """128 bits of entropy drawn once from ``rng`` (seed, Generator or None: seed 0)."""
    gen = as_rng(rng)
    return tuple(int(x) for x in gen.integers(0, 2**32, size=4, dtype=np.uint64))


def _derived_rng(entropy: tuple[int, ...], *key: int) -> np.random.Generator:
    """The generator of ``key`` (``(_KEY_SPATIAL,)`` or ``(_KEY_BLOCK, i, b)``): a child
    :class:`numpy.random.SeedSequence` of ``entropy``, independent of every other key."""
    return np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key))


@dataclass(frozen=True)
class GFTRPCAOptions:
    """Options of :func:`gft_rpca` and :func:`gft_rpca_setup`, validated on construction."""

    #: GFT energy kept unchanged in the low frequencies (Eq. 5.26), in (0, 1]; 1: no change
    energy: float = 0.9999
    #: rank of the bilateral factorisation (Eq. 5.30); None: Gavish-Donoho estimate per matrix
    rank: int | None = None
    #: soft threshold of Eq. (5.32); None: a robust three-sigma level
    lam: float | None = None
    #: "exact" (whole mesh, at most ``EXACT_LIMIT`` vertices), "partitioned" (overlapped
    #: submeshes, Section 5.2.1, weights of Algorithm 8) or "auto" ("partitioned")
    basis: str = "auto"
    submesh_size: int = 700
    overlap: float = 0.15
    #: "exact" (dense) or "oi" (orthogonal iterations, Eq. 4.7) per submesh
    submesh_solver: str = "exact"
    #: RPCA iteration limit and tolerance
    max_iter: int = 100
    tol: float = 1e-5
    #: one BLAS thread for the many small products
    single_thread: bool = True

    def __post_init__(self):
        object.__setattr__(self, "energy", _check_energy(self.energy))
        object.__setattr__(self, "rank", _check_rank(self.rank))
        if self.lam is not None:
            check_positive(self.lam, "lam")
        check_choice(self.basis, "basis", ("auto", "exact", "partitioned"))
        check_choice(self.submesh_solver, "submesh_solver", ("exact", "oi"))
        check_positive(self.submesh_size, "submesh_size", integer=True)
        check_positive(self.max_iter, "max_iter", integer=True)
        check_positive(self.tol, "tol")

    @property
    def _rpca(self) -> tuple:
        return (self.energy, self.rank, self.lam, int(self.max_iter), float(self.tol))


def _resolve_basis(basis: str, n: int) -> str:
    if basis == "auto":
        basis = "partitioned"
    if basis == "exact" and n > EXACT_LIMIT:
        raise InvalidInputError(
            f"`basis`='exact' needs a dense {n} x {n} eigendecomposition; it is limited to "
            f"{EXACT_LIMIT} vertices. Use basis='partitioned'."
        )
    return basis


def _binary_adjacency(F: np.ndarray, n: int):
    from ..graph import adjacency_matrix

    C = adjacency_matrix(F, n)
    C.data[:] = 1.0
    return C


def _exact_basis(C) -> np.ndarray:
    from ..graph import laplacian_from_adjacency

    L = laplacian_from_adjacency(C).toarray()
    _, U = np.linalg.eigh(L)  # Algorithm 3, line 1 (Eq. 4.3)
    return U


def _partition(C, submesh_size, overlap, gen):
    from ..spectral import overlapped_submeshes

    return overlapped_submeshes(C, submesh_size=int(submesh_size), overlap=overlap, rng=gen)


def _part_items(C, subs, submesh_solver, gen, progress_desc=None):
    """``(i, part, w, U)`` for every submesh, bases computed one at a time (in submesh order: the
    ``"oi"`` solver starts each from the previous one)."""
    from ..spectral import submesh_eigenbases

    bases = submesh_eigenbases(C, subs, 1.0, method=submesh_solver, rng=gen)
    if progress_desc is not None:
        bases = progress(bases, desc=progress_desc, total=len(subs.parts))
    for i, _w, U in bases:
        # weights of Algorithm 8; the tiny offset gives the plain average to a vertex isolated in
        # all its submeshes
        yield i, subs.parts[i], subs.degrees[i].astype(np.float64) + 1e-9, U


def _denoise_parts(items, A, starts, bs, b0, n_parts, rpca_opts, entropy):
    """Algorithm 3 on the frame blocks of ``A`` for every spectral part, the overlapping submesh
    results averaged with the weights of Algorithm 8; a block depends only on ``entropy``, its
    frames and its index."""
    energy, rank, lam, max_iter, tol = rpca_opts
    stats = _Stats()
    n_high = np.zeros((n_parts, len(starts)), dtype=np.int64)
    out = den = None
    for i, part, w, U in items:
        if part is None:
            out = np.empty_like(A)
            for j, s in enumerate(starts):
                gen = _derived_rng(entropy, _KEY_BLOCK, i, b0 + j)
                out[s : s + bs], n_high[i, j] = _algorithm3_block(
                    A[s : s + bs], U, energy, rank, lam, max_iter, tol, gen, stats
                )
            continue
        if out is None:  # sum_j w_ij v_ij and sum_j w_ij of Algorithm 8
            out = np.zeros_like(A)
            den = np.zeros(A.shape[1])
        Xp = A[:, part]
        Y = np.empty_like(Xp)
        for j, s in enumerate(starts):
            gen = _derived_rng(entropy, _KEY_BLOCK, i, b0 + j)
            Y[s : s + bs], n_high[i, j] = _algorithm3_block(
                Xp[s : s + bs], U, energy, rank, lam, max_iter, tol, gen, stats
            )
        Y *= w[None, :, None]
        out[:, part] += Y
        den[part] += w
        del Xp, Y
    if den is not None:
        out /= den[None, :, None]
    return out, n_high, stats


@dataclass(frozen=True, eq=False)
class GFTRPCASetup:
    """The spatial part of Algorithm 3 shared by all frame blocks (:func:`gft_rpca_setup`)."""

    basis: str
    n_vertices: int
    #: sorted vertex indices of every submesh (``(None,)`` for the exact basis)
    parts: tuple
    #: degree weights of Algorithm 8 (``(None,)`` for the exact basis)
    weights: tuple
    #: full eigenbasis of every part's binary Laplacian, eigenvalues ascending
    bases: tuple
    #: ``(energy, rank, lam, max_iter, tol)`` of the RPCA
    options: tuple
    single_thread: bool
    #: entropy of the SeedSequence of the per-block generators
    entropy: tuple

    @property
    def n_parts(self) -> int:
        return len(self.bases)

    @property
    def nbytes(self) -> int:
        """Bytes of the index, weight and basis arrays."""
        arrays = [*self.parts, *self.weights, *self.bases]
        return int(sum(a.nbytes for a in arrays if a is not None))

    def _items(self):
        return zip(range(self.n_parts), self.parts, self.weights, self.bases)


@dataclass(frozen=True, eq=False)
class GFTRPCABlock:
    """Result of :func:`gft_rpca_block` on one block of frames."""

    #: (T_b, n, 3) denoised frames of the block
    frames: np.ndarray
    #: (n_parts,) ``n_h`` of every spectral part
    n_high: np.ndarray
    n_iter: int
    converged: bool
    residual: float


def gft_rpca_setup(
    F, n_vertices: int, *, options: GFTRPCAOptions | None = None, rng=None, **legacy
) -> GFTRPCASetup:
    """What every frame block of :func:`gft_rpca` shares (Algorithm 3, line 1), all submesh bases
    kept (:attr:`GFTRPCASetup.nbytes`); options and ``rng`` as in :func:`gft_rpca`."""
    o = options_with_legacy(options, legacy, GFTRPCAOptions, "gft_rpca_setup")
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, (int, np.integer)):
        raise InvalidInputError(f"`n_vertices` must be a positive integer; got {n_vertices!r}.")
    check_positive(n_vertices, "n_vertices", integer=True)
    n = int(n_vertices)
    F = as_faces(F, n, "F")
    entropy = _seed_entropy(rng)
    basis = _resolve_basis(o.basis, n)
    C = _binary_adjacency(F, n)
    opts = o._rpca
    single = bool(o.single_thread)
    if basis == "exact":
        U = _exact_basis(C)
        return GFTRPCASetup("exact", n, (None,), (None,), (U,), opts, single, entropy)
    gen = _derived_rng(entropy, _KEY_SPATIAL)
    subs = _partition(C, o.submesh_size, o.overlap, gen)
    with _blas_threads(1 if single else None):
        items = list(_part_items(C, subs, o.submesh_solver, gen))
    parts, weights, bases = (tuple(x[k] for x in items) for k in (1, 2, 3))
    return GFTRPCASetup("partitioned", n, parts, weights, bases, opts, single, entropy)


def gft_rpca_block(setup: GFTRPCASetup, frames, block_index: int = 0) -> GFTRPCABlock:
    """Denoise frame block number ``block_index`` with a :class:`GFTRPCASetup` (Algorithm 3, lines
    2-17): the block's slice of ``gft_rpca(..., block_size=T_b)`` with the same ``rng``."""
    if not isinstance(setup, GFTRPCASetup):
        raise InvalidInputError(f"`setup` must be a GFTRPCASetup; got {type(setup).__name__}.")
    X = as_frames(frames)
    if X.shape[1] != setup.n_vertices:
        raise InvalidInputError(
            f"`frames` must have {setup.n_vertices} vertices per frame (the setup's); "
            f"got {X.shape[1]}."
        )
    if isinstance(block_index, bool) or not isinstance(block_index, (int, np.integer)):
        raise InvalidInputError(f"`block_index` must be an integer >= 0; got {block_index!r}.")
    check_positive(block_index, "block_index", integer=True, allow_zero=True)
    threads = None if setup.basis == "exact" or not setup.single_thread else 1
    with _blas_threads(threads):
        out, n_high, stats = _denoise_parts(
            setup._items(), X, [0], X.shape[0], int(block_index), setup.n_parts,
            setup.options, setup.entropy,
        )  # fmt: skip
    return GFTRPCABlock(out, n_high[:, 0], stats.n_iter, stats.converged, stats.residual)


# --------------------------------------------------------------------------- Algorithm 3
def gft_rpca(
    frames,
    F=None,
    *,
    options: GFTRPCAOptions | None = None,
    block_size: int | None = None,
    rng=None,
    **legacy,
) -> GFTRPCAResult:
    """Spectral denoising of a mesh animation by low-rank analysis of its GFT (Algorithm 3).

    The binary Laplacian ``L = D - C`` is decomposed once (Eq. 4.3; per overlapped submesh by
    default). Per block of frames: GFT of every frame (Eq. 4.4); ``n_hi``, the most
    highest-frequency components holding at most ``1 - energy`` of the energy (Eqs. 5.25-5.26),
    ``n_h = max_i n_hi`` (Eq. 5.27); per coordinate the ``T x n_h`` coherent matrix (Eq. 5.24) is
    split by the bilateral-factorisation RPCA (Eqs. 5.29-5.35), frame ``i`` takes its ``n_hi``
    highest components from the low-rank part (Eq. 5.36), and the IGFT gives the vertices
    (Eq. 5.37). A block depends only on the seed, its frames and its index (:func:`gft_rpca_block`).

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
    F : (m, 3) int, optional
        Shared faces (default ``frames.faces``).
    options : GFTRPCAOptions, optional
    block_size : int, optional
        Frames per block (online mode); None: all at once.
    rng : int, Generator or None
        Seed (None: 0) of the SeedSequence whose children seed METIS and each block's RPCA.
    **legacy
        The fields of :class:`GFTRPCAOptions` as keywords: deprecated.
    """
    o = options_with_legacy(options, legacy, GFTRPCAOptions, "gft_rpca")
    t_start = time.perf_counter()
    F = _faces_of(frames, F)
    A = as_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    bs = _check_block_size(block_size, T)
    entropy = _seed_entropy(rng)
    basis = _resolve_basis(o.basis, n)
    C = _binary_adjacency(F, n)
    starts = list(range(0, T, bs))
    opts = o._rpca
    # the same spatial setup and per-block code as gft_rpca_setup / gft_rpca_block, but the
    # submesh bases are computed and dropped one at a time (submesh outer loop, blocks inner)
    if basis == "exact":
        items = [(0, None, None, _exact_basis(C))]
        n_parts, threads = 1, None
    else:
        gen = _derived_rng(entropy, _KEY_SPATIAL)
        subs = _partition(C, o.submesh_size, o.overlap, gen)
        n_parts, threads = len(subs.parts), (1 if o.single_thread else None)
        items = _part_items(C, subs, o.submesh_solver, gen, progress_desc="gft-rpca submeshes")
    with _blas_threads(threads):
        out, n_high, stats = _denoise_parts(items, A, starts, bs, 0, n_parts, opts, entropy)
    return GFTRPCAResult(
        out, n_high, basis, n_parts, stats.n_iter, stats.converged, stats.residual,
        time.perf_counter() - t_start,
    )  # fmt: skip


# --------------------------------------------------------------------------- normals variant
@dataclass(frozen=True, eq=False)
class NormalsRPCAResult:
    """Result of :func:`normals_rpca`."""

    frames: np.ndarray
    #: (T, m, 3) denoised unit face normals
    normals: np.ndarray
    n_iter: int
    converged: bool
    residual: float
    seconds: float


def normals_rpca(
    frames,
    F=None,
    *,
    rank: int | None = None,
    lam: float | None = None,
    n_update: int = 20,
    max_iter: int = 100,
    tol: float = 1e-5,
    single_thread: bool = True,
    rng=None,
) -> NormalsRPCAResult:
    """Spatio-temporal RPCA on face normals, then the vertex update (Section 5.2.3, Fig. 5.71).

    Per coordinate, the ``T x m`` matrix of unit face normals is split by the bilateral-factorisation
    RPCA (Eqs. 5.29-5.35) and every frame is fitted to its re-normalised low-rank part by
    ``n_update`` vertex updates (Eqs. 4.28-4.29). ``rank``, ``lam``, ``max_iter``, ``tol``,
    ``single_thread`` and ``rng`` as in :func:`gft_rpca`; returns a :class:`NormalsRPCAResult`."""
    from ..geometry import face_normals, update_vertices

    t_start = time.perf_counter()
    F = _faces_of(frames, F)
    A = as_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    rank = _check_rank(rank)
    if lam is not None:
        check_positive(lam, "lam")
    check_positive(n_update, "n_update", integer=True, allow_zero=True)
    check_positive(max_iter, "max_iter", integer=True)
    check_positive(tol, "tol")
    gen = as_rng(rng)
    stats = _Stats()
    N = np.stack([face_normals(A[t], F) for t in range(T)])  # (T, m, 3)
    with _blas_threads(1 if single_thread else None):
        Nd = np.stack(
            [_low_rank(N[:, :, c], rank, lam, max_iter, tol, gen, stats) for c in range(3)],
            axis=2,
        )
    norm = np.linalg.norm(Nd, axis=2, keepdims=True)
    Nd = np.divide(Nd, norm, out=np.zeros_like(Nd), where=norm > 1e-12)
    out = np.stack([update_vertices(A[t], F, Nd[t], n_iter=int(n_update)) for t in range(T)])
    return NormalsRPCAResult(
        out, Nd, stats.n_iter, stats.converged, stats.residual, time.perf_counter() - t_start
    )


# --------------------------------------------------------------------------- dispatch
#: animation methods registered by other packages (``dae`` by :mod:`spectrageo.learn`)
_ANIMATION_METHODS: dict[str, Callable[..., np.ndarray]] = {}


def register_animation_method(name: str, func: Callable[..., np.ndarray]) -> None:
    """Register ``func(frames, F, **options) -> (T, n, 3)`` as the animation method ``name``
    (plugins of the ``spectrageo.denoisers`` entry points; ``dae`` comes from :mod:`spectrageo.learn`)."""
    if not isinstance(name, str) or not name:
        raise InvalidInputError(f"`name` must be a non-empty string; got {name!r}.")
    if not callable(func):
        raise InvalidInputError(f"`func` must be callable; got {type(func).__name__}.")
    _ANIMATION_METHODS[name] = func


def _animation_method(name: str):
    """The registered animation method ``name`` (plugins loaded on a miss), or None."""
    if name not in _ANIMATION_METHODS:
        load_plugins("spectrageo.denoisers")
    return _ANIMATION_METHODS.get(name)


def dynamic_methods() -> list[str]:
    """Names of the methods that denoise an animation as a whole (``"gft-rpca"``, ``"normals-rpca"``)."""
    return list(DYNAMIC_METHODS)


def denoise_frames(frames, F=None, *, method: str = "bnf", **options) -> np.ndarray:
    """Run the static denoiser ``method`` (:func:`spectrageo.denoise.available`) on every frame,
    the per-frame baseline of Section 5.1.2; returns the (T, n, 3) denoised frames."""
    from ._registry import denoise, get

    F = _faces_of(frames, F)
    A = as_frames(frames)
    F = as_faces(F, A.shape[1], "F")
    get(method)  # validate the name before the loop
    return np.stack(
        [
            np.asarray(denoise(A[t], F, method=method, **options), dtype=np.float64)
            for t in progress(range(A.shape[0]), desc=f"{method} per frame", total=A.shape[0])
        ]
    )


def _keyword_options(func, method: str, options: dict) -> dict:
    """``options`` checked against ``func``'s keywords (for :func:`gft_rpca` its option fields)."""
    import inspect

    allowed = {
        p.name
        for p in inspect.signature(func).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    }
    fields = {f.name for f in dataclasses.fields(GFTRPCAOptions)} if func is gft_rpca else set()
    unknown = sorted(set(options) - allowed - fields)
    if unknown:
        raise InvalidInputError(
            f"unknown option(s) for method {method!r}: {', '.join(unknown)}; "
            f"accepted: {', '.join(sorted((allowed | fields) - {'options'}))}."
        )
    given = {k: options.pop(k) for k in list(options) if k in fields}
    if given:
        base = options.pop("options", None) or GFTRPCAOptions()
        options["options"] = dataclasses.replace(base, **given)
    return options


def denoise_animation(frames, F=None, *, method: str = "gft-rpca", **options) -> np.ndarray:
    """Denoise a mesh animation into (T, n, 3) frames: ``"gft-rpca"`` (:func:`gft_rpca`; the fields
    of :class:`GFTRPCAOptions` may be keywords), ``"normals-rpca"``, a method of
    :func:`register_animation_method` (``"dae"``, Section 5.1.3), or a static method frame by frame."""
    if not isinstance(method, str):
        raise InvalidInputError(f"`method` must be a string; got {type(method).__name__}.")
    funcs = {"gft-rpca": gft_rpca, "normals-rpca": normals_rpca}
    if method in funcs:
        func = funcs[method]
        return func(frames, F, **_keyword_options(func, method, dict(options))).frames
    plugin = _animation_method(method)
    if plugin is not None:
        return plugin(frames, F, **options)
    return denoise_frames(frames, F, method=method, **options)
