"""Denoising of mesh animations (dynamic 3D meshes with fixed connectivity), Section 5.1.2.

Two methods work on the whole animation at once and exploit its temporal coherence:

``"gft-rpca"`` -- :func:`gft_rpca`, Algorithm 3 ("Spectral denoising of dynamic 3D meshes"):
    the binary graph Laplacian of the shared connectivity is decomposed once (Eq. 4.3); every frame
    is transformed by the GFT (Eq. 4.4); the number of high-frequency components ``n_h`` follows
    from the energy rule of Eq. 5.25-5.27 (99.99 % of the energy is kept in the unchanged low
    frequencies); the ``n_h`` high-frequency coefficients of all frames form one coherent matrix per
    coordinate (Eq. 5.24), whose low-rank part is estimated by the bilateral-factorisation RPCA
    (Eq. 5.29-5.35, :func:`spectrageo.linalg.rpca` with ``method="godec"``); the denoised spectra
    (Eq. 5.36) are transformed back by the IGFT (Eq. 5.37).

``"normals-rpca"`` -- :func:`normals_rpca`, the spatio-temporal RPCA on face normals mentioned with
    Fig. 5.71: the face normals of all frames form one coherent matrix per coordinate; their low-rank
    part gives the denoised normals, and the vertices of every frame are moved to agree with them
    by the vertex update of Eq. 4.28-4.29.

Any static method of :mod:`spectrageo.denoise` can also be run frame by frame
(:func:`denoise_frames`); :func:`denoise_animation` dispatches between the two.

Known limitation (Section 5.1.2, Fig. 5.29): noise that repeats identically in every frame (a
*spatial mask*, :func:`spectrageo.noise.spatial_mask`) is itself temporally coherent, hence low rank,
and is kept by the RPCA; ``"gft-rpca"`` removes little of it. Time-varying connectivity is not
supported (one face array for all frames).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from .._validation import as_faces, as_frames, as_rng, check_choice, check_positive

__all__ = [
    "DYNAMIC_METHODS",
    "GFTRPCABlock",
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
    from ..linalg import rpca

    r = None if rank is None else min(rank, *M.shape)
    res = rpca(
        M,
        method="godec",
        rank=r,
        lam=lam,
        tol=tol,
        max_iter=max_iter,
        backend="dense",
        on_nonconvergence="ignore",
        rng=gen,
    )
    stats.add(res)
    return res.low_rank


# --------------------------------------------------------------------------- Algorithm 3
@dataclass(frozen=True, eq=False)
class GFTRPCAResult:
    """Result of :func:`gft_rpca`.

    Attributes
    ----------
    frames : (T, n, 3) float64
        Denoised animation (same frame count and vertex order as the input).
    n_high : (n_parts, n_blocks) int64
        ``n_h`` of Eq. 5.27 for every spectral part (the whole mesh, or each submesh) and frame block.
    basis : str
        ``"exact"`` or ``"partitioned"``.
    n_submeshes : int
        1 for the exact basis.
    n_iter : int
        Largest number of RPCA iterations over all coherent matrices.
    converged : bool
        Every RPCA met its tolerance.
    residual : float
        Largest final relative change of the RPCA iterations.
    seconds : float
        Wall time.
    """

    frames: np.ndarray
    n_high: np.ndarray
    basis: str
    n_submeshes: int
    n_iter: int
    converged: bool
    residual: float
    seconds: float


def _n_high(H: np.ndarray, energy: float) -> np.ndarray:
    """Per-frame ``n_hi`` of Eq. 5.25-5.26 for spectra ``H`` (T, k, 3) in ascending frequency.

    ``n_hi`` is the largest number of highest-frequency components whose cumulative energy does
    not exceed ``(1 - energy) E_s`` (``E_s`` the total energy of the frame's GFT, Eq. 5.25).
    """
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


def _check_options(energy, rank, lam, basis, submesh_size, overlap, submesh_solver, max_iter, tol):
    energy = _check_energy(energy)
    rank = _check_rank(rank)
    if lam is not None:
        check_positive(lam, "lam")
    check_choice(basis, "basis", ("auto", "exact", "partitioned"))
    check_choice(submesh_solver, "submesh_solver", ("exact", "oi"))
    check_positive(submesh_size, "submesh_size", integer=True)
    check_positive(max_iter, "max_iter", integer=True)
    check_positive(tol, "tol")
    return energy, rank


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
    """Algorithm 3 on the frame blocks ``A[s : s + bs]`` (global indices ``b0, b0 + 1, ...``) for
    every spectral part of ``items`` (``(i, part, w, U)``; ``part`` None: the whole mesh on the
    exact basis), the overlapping submesh results averaged with the weights of Algorithm 8.

    The RPCA of part ``i`` and block ``b`` draws from its own generator (:func:`_derived_rng`), and
    every output value is the same sum in the same submesh order whether the blocks are processed
    together or one by one: a block's result depends only on ``entropy``, its frames and ``b``.
    """
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
    """The spatial part of Algorithm 3, shared by all frame blocks (from :func:`gft_rpca_setup`).

    Attributes
    ----------
    basis : str
        ``"exact"`` or ``"partitioned"``.
    n_vertices : int
    parts : tuple of (n_i,) int64 arrays
        Sorted vertex indices of every submesh (``(None,)`` for the exact basis: the whole mesh).
    weights : tuple of (n_i,) float64 arrays
        Degree weights of Algorithm 8 (``(None,)`` for the exact basis).
    bases : tuple of (n_i, n_i) float64 arrays
        Full eigenbasis of every part's binary Laplacian, eigenvalues ascending.
    options : tuple
        ``(energy, rank, lam, max_iter, tol)`` of the RPCA, validated.
    single_thread : bool
    entropy : tuple of int
        Entropy of the :class:`numpy.random.SeedSequence` from which the generator of every
        (submesh, frame block) is derived.
    """

    basis: str
    n_vertices: int
    parts: tuple
    weights: tuple
    bases: tuple
    options: tuple
    single_thread: bool
    entropy: tuple

    @property
    def n_parts(self) -> int:
        """Number of spectral parts (1 for the exact basis)."""
        return len(self.bases)

    @property
    def nbytes(self) -> int:
        """Bytes of the index, weight and basis arrays (what is sent once to every worker)."""
        arrays = [*self.parts, *self.weights, *self.bases]
        return int(sum(a.nbytes for a in arrays if a is not None))

    def _items(self):
        return zip(range(self.n_parts), self.parts, self.weights, self.bases)


@dataclass(frozen=True, eq=False)
class GFTRPCABlock:
    """Result of :func:`gft_rpca_block` on one block of ``T_b`` frames.

    Attributes
    ----------
    frames : (T_b, n, 3) float64
        The block's denoised frames.
    n_high : (n_parts,) int64
        ``n_h`` of Eq. 5.27 of every spectral part for this block (a column of
        :attr:`GFTRPCAResult.n_high`).
    n_iter, converged, residual :
        RPCA statistics over this block (maximum / all / maximum).
    """

    frames: np.ndarray
    n_high: np.ndarray
    n_iter: int
    converged: bool
    residual: float


def gft_rpca_setup(
    F,
    n_vertices: int,
    *,
    energy: float = 0.9999,
    rank: int | None = None,
    lam: float | None = None,
    basis: str = "auto",
    submesh_size: int = 700,
    overlap: float = 0.15,
    submesh_solver: str = "exact",
    max_iter: int = 100,
    tol: float = 1e-5,
    single_thread: bool = True,
    rng=None,
) -> GFTRPCASetup:
    """Compute once what every frame block of :func:`gft_rpca` shares (Algorithm 3, line 1).

    The submeshes (METIS + ring growth) and the full eigenbasis of every submesh's binary Laplacian
    ``L = D - C``, or the exact eigenbasis of the whole mesh's, exactly as :func:`gft_rpca` computes
    them, plus the validated RPCA options and the seed entropy of the per-block generators. Unlike
    :func:`gft_rpca`, which holds one submesh basis at a time, all bases are kept:
    ``sum_i n_i^2`` doubles (about ``8 n (1 + overlap) submesh_size`` bytes; see
    :attr:`GFTRPCASetup.nbytes`). :func:`gft_rpca_block` then denoises any frame block with it, in
    any order or process, with the same result as the block's slice of ``gft_rpca(...,
    block_size=...)`` with the same ``rng``.

    Parameters
    ----------
    F : (m, 3) int
        Faces shared by all frames.
    n_vertices : int
        Vertices per frame.
    energy, rank, lam, basis, submesh_size, overlap, submesh_solver, max_iter, tol, single_thread, rng :
        As in :func:`gft_rpca`.

    Returns
    -------
    GFTRPCASetup
    """
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, (int, np.integer)):
        raise InvalidInputError(f"`n_vertices` must be a positive integer; got {n_vertices!r}.")
    check_positive(n_vertices, "n_vertices", integer=True)
    n = int(n_vertices)
    F = as_faces(F, n, "F")
    energy, rank = _check_options(
        energy, rank, lam, basis, submesh_size, overlap, submesh_solver, max_iter, tol
    )
    entropy = _seed_entropy(rng)
    basis = _resolve_basis(basis, n)
    C = _binary_adjacency(F, n)
    opts = (energy, rank, lam, int(max_iter), float(tol))
    if basis == "exact":
        U = _exact_basis(C)
        return GFTRPCASetup("exact", n, (None,), (None,), (U,), opts, bool(single_thread), entropy)
    gen = _derived_rng(entropy, _KEY_SPATIAL)
    subs = _partition(C, submesh_size, overlap, gen)
    with _blas_threads(1 if single_thread else None):
        items = list(_part_items(C, subs, submesh_solver, gen))
    parts, weights, bases = (tuple(x[k] for x in items) for k in (1, 2, 3))
    return GFTRPCASetup("partitioned", n, parts, weights, bases, opts, bool(single_thread), entropy)


def gft_rpca_block(setup: GFTRPCASetup, frames, block_index: int = 0) -> GFTRPCABlock:
    """Denoise one block of frames with a precomputed :class:`GFTRPCASetup` (Algorithm 3, lines 2-17).

    Parameters
    ----------
    setup : GFTRPCASetup
        From :func:`gft_rpca_setup`.
    frames : (T_b, n, 3) array_like
        The block's frames (consecutive frames of the animation).
    block_index : int
        Position of the block in the animation (0, 1, ...): it selects the block's random
        generators, so that the result equals the block's slice of :func:`gft_rpca` run with
        ``block_size=T_b`` (the last block may be shorter) and the same ``rng``.

    Returns
    -------
    GFTRPCABlock
    """
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
    energy: float = 0.9999,
    rank: int | None = None,
    lam: float | None = None,
    basis: str = "auto",
    submesh_size: int = 700,
    overlap: float = 0.15,
    submesh_solver: str = "exact",
    block_size: int | None = None,
    max_iter: int = 100,
    tol: float = 1e-5,
    single_thread: bool = True,
    rng=None,
) -> GFTRPCAResult:
    """Spectral denoising of a mesh animation by low-rank analysis of its GFT (Algorithm 3).

    The binary Laplacian ``L = D - C`` (positive semi-definite, Eq. 4.1 with unit weights) of the
    shared connectivity is decomposed once; for each block of frames the GFT of every frame is
    computed (Eq. 4.4), the per-frame number of high-frequency components ``n_hi`` is the largest
    number of highest-frequency components holding at most ``1 - energy`` of the frame's GFT energy
    (Eq. 5.25-5.26, energy summed over all ``n`` components of the uncentred coordinates, as
    written), ``n_h = max_i n_hi`` (Eq. 5.27), and for each coordinate the ``T x n_h`` coherent
    matrix of Eq. 5.24 is split by the bilateral-factorisation RPCA (Eq. 5.29-5.35, GoDec with
    soft thresholding) into a low-rank ``E`` and a sparse ``S``. Frame ``i`` gets its ``n_hi``
    highest components from ``E`` and keeps the rest (Eq. 5.36); the IGFT gives the vertices
    (Eq. 5.37).

    Bases
    -----
    ``basis="exact"``: the full eigendecomposition of the whole Laplacian (dense, O(n^3) time and
    O(n^2) memory; refused above ``EXACT_LIMIT`` = 6000 vertices).
    ``basis="partitioned"``: the mesh is split into overlapped submeshes of ``submesh_size``
    vertices (:func:`spectrageo.spectral.overlapped_submeshes`, METIS + ring growth, ``overlap``
    15 % as in Section 5.2.1); Algorithm 3 runs on every submesh with the full eigenbasis of its
    binary Laplacian (:func:`spectrageo.spectral.submesh_eigenbases`: ``submesh_solver="exact"`` is
    a dense LAPACK decomposition, ``"oi"`` the orthogonal iterations of Eq. 4.7 started from the
    previous submesh's basis), and the overlapping results are averaged with the degree weights of
    Algorithm 8. Memory is O(T n) for the animation plus O(submesh_size^2 + T submesh_size) per
    submesh (one accumulator of the animation's size; the crane animation, 10k vertices, played to
    400 frames: about 1.5x the animation's 92 MB above the input, under a minute on two cores), so
    10k-50k-vertex animations run in seconds to minutes. On the shared animations it is
    as good as the exact basis or better (the RPCA is then local: a low rank suffices for the
    nearly rigid motion of a small patch). ``basis="auto"`` is ``"partitioned"`` (which is exact for
    meshes with at most ``submesh_size`` vertices: a single submesh holds the whole mesh).

    Online mode
    -----------
    ``block_size``: frames are processed in consecutive blocks of that many frames, each with its
    own ``n_h`` and RPCA (the "online / groups of frames" mode of Section 5.1.2); the basis is
    computed once. A block's result depends only on the seed, its own frames and its position, so
    blocks can be denoised as they arrive, in any order or in parallel:
    :func:`gft_rpca_setup` computes the basis once and :func:`gft_rpca_block` denoises one block
    with it (:func:`spectrageo.distributed.gft_rpca_blocks` runs the blocks as Dask tasks, with
    the same result). Blocks should hold at least ~10 frames for the low-rank model to have
    something to work with.

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
        Noisy animation with shared connectivity.
    F : (m, 3) int, optional
        Shared faces (taken from ``frames.faces`` for a MeshAnimation).
    energy : float in (0, 1]
        Fraction of the GFT energy kept unchanged in the low frequencies (Eq. 5.26: 0.9999).
        ``1.0`` leaves the animation unchanged.
    rank : int or None
        Rank ``r`` of the bilateral factorisation (Eq. 5.30). ``None`` (default): the Gavish-Donoho
        estimate of :func:`~spectrageo.linalg.rpca` from the singular values of every coherent
        matrix. A fixed small rank (3) is slightly better on short clips (40-50 frames) but fails on
        long ones (chickenCrossing, 400 frames: KG 7 % against 0.5 % with the estimate), so the
        estimate is the default.
    lam : float or None
        Soft threshold of Eq. 5.32 (``None``: a robust three-sigma level of the rank-``r`` residual,
        the default of :func:`~spectrageo.linalg.rpca`).
    basis : {"auto", "exact", "partitioned"}
    submesh_size : int
        Vertices per submesh for the partitioned basis (500-800 recommended, Section 5.2.1).
    overlap : float in [0, 1)
        Overlap of the submeshes.
    submesh_solver : {"exact", "oi"}
        Eigensolver of the submesh Laplacians (partitioned basis only).
    block_size : int or None
        Frames per block (online mode); ``None``: all frames at once.
    max_iter, tol :
        RPCA iteration limit and tolerance (relative change of ``(E, S)``).
    single_thread : bool
        Run the many small matrix products with one BLAS thread (faster on shared machines).
    rng : int, Generator or None
        Seed (``None``: 0). 128 bits of entropy are drawn from it once; a
        :class:`numpy.random.SeedSequence` of that entropy gives one generator to METIS and the
        submesh eigensolver and an independent one to the RPCA random starts of every (submesh,
        frame block) pair (child keys ``(0,)`` and ``(1, i, b)``). A block's result therefore does
        not depend on which other blocks are processed, nor in which order.

    Returns
    -------
    GFTRPCAResult

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN, unknown option, ``basis="exact"`` on more than ``EXACT_LIMIT`` vertices.
    """
    t_start = time.perf_counter()
    F = _faces_of(frames, F)
    A = as_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    energy, rank = _check_options(
        energy, rank, lam, basis, submesh_size, overlap, submesh_solver, max_iter, tol
    )
    bs = _check_block_size(block_size, T)
    entropy = _seed_entropy(rng)
    basis = _resolve_basis(basis, n)
    C = _binary_adjacency(F, n)
    starts = list(range(0, T, bs))
    opts = (energy, rank, lam, int(max_iter), float(tol))
    # the same spatial setup and per-block code as gft_rpca_setup / gft_rpca_block, but the
    # submesh bases are computed and dropped one at a time (submesh outer loop, blocks inner)
    if basis == "exact":
        items = [(0, None, None, _exact_basis(C))]
        n_parts, threads = 1, None
    else:
        gen = _derived_rng(entropy, _KEY_SPATIAL)
        subs = _partition(C, submesh_size, overlap, gen)
        n_parts, threads = len(subs.parts), (1 if single_thread else None)
        items = _part_items(C, subs, submesh_solver, gen, progress_desc="gft-rpca submeshes")
    with _blas_threads(threads):
        out, n_high, stats = _denoise_parts(items, A, starts, bs, 0, n_parts, opts, entropy)
    return GFTRPCAResult(
        out, n_high, basis, n_parts, stats.n_iter, stats.converged, stats.residual,
        time.perf_counter() - t_start,
    )  # fmt: skip


# --------------------------------------------------------------------------- normals variant
@dataclass(frozen=True, eq=False)
class NormalsRPCAResult:
    """Result of :func:`normals_rpca`.

    Attributes
    ----------
    frames : (T, n, 3) float64
        Denoised animation.
    normals : (T, m, 3) float64
        Denoised unit face normals (the low-rank part, re-normalised).
    n_iter, converged, residual :
        RPCA statistics (maximum / all / maximum over the three coordinates).
    seconds : float
    """

    frames: np.ndarray
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
    """Spatio-temporal RPCA on face normals, then the vertex update (Fig. 5.71 context, Section 5.2.3).

    The unit face normals of all frames form, per coordinate, a ``T x m`` coherent matrix (frames
    as rows, as in Eq. 5.24); its low-rank part (bilateral-factorisation RPCA, Eq. 5.29-5.35) is the
    denoised normal field of every frame, the sparse part holds the noise spikes. The rows are
    re-normalised and every frame's vertices are moved to agree with them by ``n_update``
    iterations of the vertex update of Eq. 4.28-4.29 (:func:`spectrageo.geometry.update_vertices`)
    starting from the noisy positions. The individual normals are used rather than guided normals,
    which the thesis reports to smooth sharp features less.

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
    F : (m, 3) int, optional
    rank : int or None
        Rank of the factorisation; ``None``: Gavish-Donoho estimate from the singular values.
    lam : float or None
        Soft threshold of Eq. 5.32 (``None``: robust three-sigma level).
    n_update : int
        Iterations of the vertex update.
    max_iter, tol, single_thread, rng :
        As in :func:`gft_rpca`.

    Returns
    -------
    NormalsRPCAResult
    """
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
def dynamic_methods() -> list[str]:
    """Names of the methods that denoise an animation as a whole (``"gft-rpca"``, ``"normals-rpca"``)."""
    return list(DYNAMIC_METHODS)


def denoise_frames(frames, F=None, *, method: str = "bnf", **options) -> np.ndarray:
    """Run the static denoiser ``method`` (see :func:`spectrageo.denoise.available`) on every frame.

    Returns the denoised frames (T, n, 3); the per-frame baseline of Section 5.1.2.
    """
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


def denoise_animation(frames, F=None, *, method: str = "gft-rpca", **options) -> np.ndarray:
    """Denoise a mesh animation; returns the denoised frames (T, n, 3) in the input vertex order.

    ``method``: ``"gft-rpca"`` (:func:`gft_rpca`, Algorithm 3), ``"normals-rpca"``
    (:func:`normals_rpca`), ``"dae"`` (:func:`spectrageo.learn.dae_animation`, Section 5.1.3,
    option ``train_frames``), or any static method of :func:`spectrageo.denoise.available`, which is
    then run frame by frame (:func:`denoise_frames`). ``options`` go to that function.
    """
    if not isinstance(method, str):
        raise InvalidInputError(f"`method` must be a string; got {type(method).__name__}.")
    if method == "dae":  # content-wise DAEs, trained on the first frames (Section 5.1.3)
        from ..learn.dae import dae_animation

        return dae_animation(frames, F, **options)
    funcs = {"gft-rpca": gft_rpca, "normals-rpca": normals_rpca}
    if method in funcs:
        func = funcs[method]
        import inspect

        allowed = {
            p.name
            for p in inspect.signature(func).parameters.values()
            if p.kind is inspect.Parameter.KEYWORD_ONLY
        }
        unknown = sorted(set(options) - allowed)
        if unknown:
            raise InvalidInputError(
                f"unknown option(s) for method {method!r}: {', '.join(unknown)}; "
                f"accepted: {', '.join(sorted(allowed))}."
            )
        return func(frames, F, **options).frames
    return denoise_frames(frames, F, method=method, **options)
