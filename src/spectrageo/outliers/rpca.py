"""Outlier scores of dense, unorganised point clouds by RPCA of the kNN patch matrix
(thesis Section 5.4.1, Eq. 5.98-5.99, Algorithm 14).

For every point ``v_i`` the patch ``[v_i, v_i1, ..., v_ik]`` (the point and its ``k`` nearest
neighbours) fills three rows of ``M`` (Eq. 5.98). Neighbouring points share their geometry, so the
columns of ``M`` are nearly equal and ``M`` is close to low rank; a point that does not belong to
the surface sampled by its neighbours shows up in the first column of the sparse part ``S`` of
``M = E + S`` (Eq. 5.99). The score of ``v_i`` is ``||s_i||_2``, the norm of the first-column
entries of its three rows; Algorithm 14 keeps the points with ``||s_i|| < tau``.

Implementation notes (deviations and choices, all documented in :func:`rpca_scores`):

* By default (``refine=True``) the plain score is refined in two documented steps: patches made
  mostly of flagged points are rebuilt from the unflagged ones and Algorithm 14 runs a second
  time, and each score is taken relative to the median first-pass score of its patch. Far
  outliers that only see other outliers then score by their distance to the surface, and points
  in sparse or noisy parts of a scan no longer stand out merely because their whole
  neighbourhood has large residuals. The residual is also weighted towards its component along
  the local normal (``tangent_weight=0.5``). ``refine=False, tangent_weight=1`` gives the
  thesis' score unchanged.

* ``M`` is never formed: a fused kernel gathers its rows from the points and runs the inexact ALM
  iteration of Eq. 4.22 (the same iterates as :func:`spectrageo.linalg.rpca` with ``method="ialm"``,
  checked in the tests with ``dtype="float64", rank_tol=0``) with a single ``3n x (k+1)`` state
  array. One pass per iteration works tile by tile (128 points, stored column by column): the
  elementwise shrinkage/residual steps and the two small products ``X W`` (in factored form
  while ``W`` has low rank) and ``X^T X`` are vectorised loops over contiguous columns, disjoint
  point ranges run on threads (the kernels release the GIL); the SVT itself is an
  eigendecomposition of the ``(k+1) x (k+1)`` Gram matrix, never an SVD of the tall matrix.
* Speed (issue 15): one exact kNN query on the Morton-sorted cloud (a uniform grid, then an
  implicit octree for the isolated points: :mod:`._grid`) serves both passes; the refinement only
  queries the rebuilt patches against the unflagged points on the same sorted cloud. The state
  is float32 by default (``dtype``; the Gram matrices, residuals and scores are accumulated in
  float64), and the ALM also stops when the ranking of the scores stops changing (``rank_tol``).
* Scale and translation invariance: the points are centred and divided by the point spacing ``h``
  (median over points of the mean kNN distance) before ``M`` is formed, so scores are in units of
  ``h`` and a threshold carries over between clouds of different scales.
* Memory: a cloud of more than ``block_size`` points is cut into the k-d tiles of
  ``spectrageo outliers --tile`` (``partition="tiles"``: each tile plus a halo scored alone, so
  the tiled command gives the same scores); within a region the ALM runs in blocks of at most
  ``block_size`` consecutive points along the Morton curve, each an independent RPCA whose rows
  are the block's patches (neighbours may lie outside the block). Peak memory is the points, one
  region's kNN indices and one block's state, whatever the cloud size.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._device import resolve_backend
from .._errors import ConvergenceError, ConvergenceWarning, InvalidInputError
from .._validation import check_choice, check_positive
from ..linalg._common import single_thread_blas
from . import _kernels as _k
from ._clusters import cluster_outliers
from ._common import (
    KNN_CHUNK,
    Neighbours,
    SortedCloud,
    as_cloud,
    check_k,
    knn_chunked,
    knn_grid,
    numba_threads,
    spacing_from,
)

__all__ = ["PatchRPCAResult", "knn_patch_matrix", "rpca_scores"]

#: Ranking stop rule of the ALM (see :func:`rpca_scores`): the scores are ranked by the levels
#: ``RANK_FLOOR * 2^j`` spacings (the smallest automatic threshold of ``remove_outliers`` and its
#: doublings; scores below the floor tie), and the ALM stops once the shrinkage level ``lam / mu``
#: is below the floor and at most ``rank_tol`` of the points changed level in one iteration.
RANK_FLOOR = 0.4
RANK_BIN = float(np.log10(2.0))  # decades per level
#: Default ``rank_tol``, chosen on the tuning split of :mod:`spectrageo.evaluate.outliers`.
RANK_TOL = 3e-3
#: Default number of points per independent RPCA block (and the largest tile of
#: ``partition="tiles"``): 2^22, so clouds of up to 4.2M points are one region (no halo work)
#: and the solver state of a block stays near 0.55 GB (float32, k = 10). Chosen for time and
#: memory on the 10^7-point clouds of ``benchmarks/outliers_large.py`` and
#: ``benchmarks/tiled_1e8.py`` (dragon prefix: 10^6 gave 16 tiles, 105 s, F1 0.975; 2^22 with a
#: faster halo search 4 tiles, 50 s, F1 0.998), so those clouds informed it and are not held out.
BLOCK_SIZE = 2**22
#: Fewest points per thread of the fused kernels (smaller blocks run on the calling thread).
_MIN_PER_THREAD = 10_000
#: Most point ranges per block of the fused kernels (see :class:`_Ranges`).
_MAX_PARTS = 16


@dataclass(frozen=True)
class PatchRPCAResult:
    """Result of :func:`rpca_scores`.

    Attributes
    ----------
    scores : (n,) ndarray
        ``||s_i||_2`` of Eq. 5.99 in units of the point spacing ``spacing`` (input order).
    spacing : float
        Point spacing ``h`` used to normalise the coordinates (input units).
    smoothed : (n, 3) ndarray or None
        First column of the low-rank part ``E`` mapped back to input coordinates (the point's own
        row of the smoothed patch), when requested.
    n_iter : int
        IALM iterations (the largest over blocks and passes).
    converged : bool
        Whether every block met ``tol`` or the ranking rule (``rank_tol``) before ``max_iter``.
    residual : float
        Largest final ``||M - E - S||_F / ||M||_F`` over blocks.
    n_blocks : int
        Number of independent RPCA blocks.
    n_refined : int
        Points whose patch was rebuilt by the refinement pass (0 without refinement).
    clusters : (n,) bool ndarray or None
        Points in small volumetric clusters (step 8 of :func:`rpca_scores`; None when
        ``clusters=False``).
    """

    scores: np.ndarray = field(repr=False)
    spacing: float
    smoothed: np.ndarray | None = field(default=None, repr=False)
    n_iter: int = 0
    converged: bool = True
    residual: float = 0.0
    n_blocks: int = 1
    n_refined: int = 0
    clusters: np.ndarray | None = field(default=None, repr=False)


def knn_patch_matrix(P: Any, k: int = 10, *, neighbors: Any = None) -> np.ndarray:
    """The spatial coherence matrix ``M`` of Eq. (5.98), shape ``(3n, k + 1)``.

    Rows ``3i, 3i+1, 3i+2`` hold the x, y and z coordinates of point ``v_i`` (column 0) and of its
    ``k`` nearest neighbours ``v_i1 ... v_ik`` (columns 1..k, nearest first, the point itself
    excluded).

    Parameters
    ----------
    P : (n, 3) array_like or PointCloud
    k : int
        Number of neighbours (``n >= k + 1``).
    neighbors : (n, k) array_like of int, optional
        Precomputed neighbour indices (e.g. from :func:`spectrageo.graph.knn`).

    Returns
    -------
    (3n, k + 1) ndarray of float64
        Dense; ``24 (k + 1)`` bytes per point. :func:`rpca_scores` never forms it.
    """
    X, _ = as_cloud(P)
    n = X.shape[0]
    if neighbors is None:
        k = check_k(k, n)
        idx = knn_chunked(X, k).idx
    else:
        idx = np.asarray(neighbors)
        if idx.ndim != 2 or idx.shape[0] != n:
            raise InvalidInputError(
                f"`neighbors` must have shape ({n}, k); got {tuple(idx.shape)}."
            )
        if idx.dtype.kind not in "iu":
            raise InvalidInputError(f"`neighbors` must hold integer indices; got {idx.dtype}.")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise InvalidInputError(f"`neighbors` has indices outside 0..{n - 1}.")
    cols = np.concatenate([np.arange(n)[:, None], idx], axis=1)
    return np.ascontiguousarray(np.transpose(X[cols], (0, 2, 1)).reshape(3 * n, cols.shape[1]))


def rpca_scores(
    P: Any,
    k: int = 10,
    *,
    lam: float | None = None,
    rho: float = 3.0,
    tol: float = 3e-4,
    max_iter: int = 200,
    block_size: int = BLOCK_SIZE,
    smoothed: bool = False,
    on_nonconvergence: str = "warn",
    workers: int = -1,
    refine: bool = True,
    tangent_weight: float = 0.5,
    rank_tol: float = RANK_TOL,
    dtype: Any = "float32",
    clusters: bool = True,
    device: Any = "cpu",
    second_pass: str = "replay",
    partition: str = "tiles",
    _knn: Any = None,
) -> PatchRPCAResult:
    r"""Per-point outlier scores ``||s_i||_2`` of Eq. (5.99) from RPCA of the patch matrix.

    Steps (Algorithm 14, step 1, and Eq. 5.98-5.99):

    1. ``k`` nearest neighbours of every point (self excluded), exact, by a grid and octree
       search over the Morton-sorted cloud (:mod:`spectrageo.outliers._grid`); the spacing ``h``
       = median over points of the mean distance to those neighbours.
    2. Coordinates centred (per block) and divided by ``h``.
    3. Principal component pursuit ``min ||E||_* + lam ||S||_1, E + S = M`` (Eq. 4.18) of the
       ``3m x (k+1)`` patch matrix of each block of ``m`` points by the inexact ALM of Eq. 4.22:
       ``E = D_{1/mu}(M - S + Y/mu)``, ``S = Q_{lam/mu}(M - E + Y/mu)``,
       ``Y += mu (M - E - S)``, ``mu <- rho mu`` from ``mu_0 = 1.25 / ||M||_2`` (Lin, Chen & Ma
       use ``rho = 1.5``), ``Y_0 = S_0 = 0``; stops when ``||M - E - S||_F <= tol ||M||_F`` or by
       the ranking rule below (``rank_tol``), whichever comes first. The singular value
       thresholding uses the ``(k+1) x (k+1)`` Gram matrix of its argument, accumulated in the same
       pass (the thesis' ``beta = 1e-7`` is reachable).
       Defaults ``rho = 3``, ``tol = 3e-4``: chosen on the tuning split; see
       docs/decisions.md#outlier-rpca-constants.

       *Ranking rule.* What the filter uses is the order of the scores relative to the
       threshold, not their last digits. After every iteration the first-column scores are
       ranked by the levels ``0.4 * 2^j`` spacings (``0.4`` is the smallest automatic threshold
       of :func:`spectrageo.outliers.remove_outliers`, :data:`RANK_FLOOR`; scores below it
       tie): ``b_i = floor(log2(s_i / 0.4))`` for ``s_i >= 0.4``, else ``-1``. The ALM stops
       once the shrinkage level ``lam / mu`` is below ``0.4`` spacings (scores at the floor are
       no longer hidden by the soft threshold) and at most ``rank_tol * m`` of the ``m`` points
       of the block changed level since the previous iteration. Default ``rank_tol = 3e-3``,
       chosen on the tuning split of :mod:`spectrageo.evaluate.outliers` (``uniform`` and
       ``halo`` at 5-30 % on four scans): mean iterations 8.44 -> 8.12 with the mean F1 of the
       valley rule unchanged to three digits (0.9005 -> 0.9004; density rule 0.8924 -> 0.8951).
       A single level at 0.4 spacings stops at 8.00 (``rank_tol = 3e-3``) and 7.50 (``1e-2``,
       F1 -0.0006) iterations but ignores the order above the smallest threshold, which
       decides when the automatic threshold lies higher; finer rankings (levels 0.05 decades
       apart from 0.1 spacings) never stopped before the residual rule, and ``rho = 4`` (7
       iterations) loses 0.03 F1. ``rank_tol=0`` disables the rule.
    4. ``score_i = sqrt(S[3i, 0]^2 + S[3i+1, 0]^2 + S[3i+2, 0]^2)`` (the first column only; the
       other ``k`` columns, the neighbours' entries, are ignored as in the thesis).

    With ``refine=True`` (default; ``refine=False`` skips steps 5-6) two
    documented additions make the score robust where the thesis' assumption that outliers are
    sparse in every patch fails:

    5. *Second pass over rebuilt patches.* The first column measures how far ``v_i`` lies from
       the consensus of its own patch. A far outlier whose neighbours are mostly other far
       outliers sits near the middle of its (widely spread) patch and scores low. Points scoring
       at least ``max(tau_1, 1)`` spacings (``tau_1`` the automatic threshold of
       :func:`spectrageo.outliers.auto_threshold` on the first-pass scores) are flagged; every
       patch in which more than half of the ``k`` neighbours are flagged is rebuilt from the
       ``k`` nearest unflagged points, and the rows of the rebuilt patches are scored again. A
       far outlier's rebuilt patch samples the nearest surface and its first-column residual
       becomes its distance to it. The floor of one spacing keeps points that stay within a
       spacing of their neighbourhood (noisy surface, near-surface outliers) from being
       flagged, which would open holes in the patches of their inlier neighbours.
       Floor of one spacing (:data:`REFINE_MIN_TAU`): chosen on the tuning split; see
       docs/decisions.md#outlier-rpca-constants.

       *How the rebuilt rows are scored* (``second_pass``). ``"full"`` runs Algorithm 14 again
       on the whole patch matrix with the rebuilt rows in place (every row, from ``S = Y = 0``).
       ``"replay"`` (default) gets nearly the same scores from the rebuilt rows alone: the ALM
       is row-separable except for the SVT, whose operator at iteration ``t`` depends on the
       rows only through the ``(k+1) x (k+1)`` Gram matrix ``G_t`` of its argument. The first
       pass records ``G_t`` and its ``mu`` schedule; the rebuilt rows are run on their old
       patches with the recorded operators (which reproduces their share ``G_t^old`` of
       ``G_t``) and on their new patches with the operators of ``G_t - G_t^old + G_t^new``,
       for the same iterations; every other row keeps its first-pass trajectory and score
       (in ``"full"`` they move a little because the operators change). A few percent of the
       rows are rerun instead of all of them. On the GPU path the first pass runs on the device
       and the replay on the CPU (few rows).
       Default ``"replay"``: chosen on the tuning split; see
       docs/decisions.md#outlier-rpca-constants.
    6. *Local baseline.* ``score_i = max(||s_i|| - median_j ||s_j^{(1)}||, 0)`` over the points
       ``j`` of the (final) patch of ``v_i``, with the first-pass scores ``s^{(1)}``: in sparse or
       noisy parts of a scan every point has a large residual, and a point is outlying only
       when its residual exceeds the level around it (the median is taken over a patch whose
       majority is unflagged, so it is at most about ``max(tau_1, 1)`` for any point).

    Default ``refine=True``: chosen on the tuning split; see
    docs/decisions.md#outlier-rpca-constants.

    7. *Residual measured along the surface normal* (``tangent_weight < 1``, default 0.5). The
       residual vector ``s_i`` (the first-column entries of the three rows of ``v_i``) is split
       into its component along the normal ``n_i`` of the patch (the smallest principal axis of
       the ``k`` neighbours, ``v_i`` itself left out) and the tangential rest, and the score is
       ``sqrt(<s_i, n_i>^2 + w^2 |s_i - <s_i, n_i> n_i|^2)`` with ``w = tangent_weight``, for
       both passes (so also in the baseline of step 6). An off-surface point is displaced along
       the normal, while the tangential part of the residual mostly reflects the irregular
       sampling inside the patch (a point is rarely at its neighbours' centroid).
       Default ``w = 0.5``: chosen on the tuning split; see
       docs/decisions.md#outlier-rpca-constants.
       ``tangent_weight = 1`` is the plain norm of Eq. (5.99).

    8. *Small volumetric clusters* (``clusters=True``, default; a documented addition). Outliers
       that gather into blobs have only other outliers in their patches, so neither the patch
       residual nor the local baseline sees them. The connected components of the kNN graph
       restricted to edges of at most 3 spacings are formed; components of at most 150 points
       (and at most a tenth of the cloud) that are volumetric (smallest covariance eigenvalue
       above 5 % of the trace) and have at least four points are returned in ``clusters``
       (:mod:`spectrageo.outliers._clusters`, with the constants and the split they were chosen
       on). The scores themselves are not changed; :func:`spectrageo.outliers.remove_outliers`
       removes these points whatever their score (the automatic threshold is still
       computed on all scores).

    Parameters
    ----------
    P : (n, 3) array_like or PointCloud
        Finite coordinates, ``n >= k + 1``. Exact duplicate points are scored once per position
        (all copies get the same score): a point with ``k`` copies would otherwise have a constant
        patch and a zero score whatever its position.
    k : int
        Neighbours per patch (``M`` has ``k + 1`` columns).
    lam : float, optional
        Weight of ``||S||_1``; default ``1 / sqrt(3 m)`` for a block of ``m`` points (the PCP choice
        ``1 / sqrt(max(rows, cols))``).
    rho : float
        Growth factor of ``mu`` (``> 1``); 1.5 reproduces the solution of
        :func:`spectrageo.linalg.rpca` more closely, at 2.5x the passes.
    tol : float
        Relative residual at which the ALM stops.
    max_iter : int
        Iteration cap per block.
    block_size : int
        Points per independent RPCA block (memory: ``12 (k + 1)`` bytes per block point for the
        float32 solver state, twice that for float64, plus about ``60 + 4 k`` bytes per cloud
        point for the sorted copy, the normalised points, the neighbour lists and the scores).
    smoothed : bool
        Also return the first column of ``E`` (the smoothed position of every point).
    on_nonconvergence : {"warn", "raise", "ignore"}
        Policy when a block reaches ``max_iter`` first.
    workers : int
        Threads of the neighbour search and the other numba kernels and of the solver (-1: all
        cores; blocks of fewer than ``2 * 10000`` points run the solver on one thread). The
        scores are bit for bit the same for every value (the solver's point ranges and the
        order of their partial sums follow the block size, not the threads).
    refine : bool
        Second pass over rebuilt patches and local baseline (steps 5-6).
    tangent_weight : float
        Weight ``w`` in ``[0, 1]`` of the tangential part of the residual (step 7);
        ``refine=False, tangent_weight=1`` gives the plain first-column scores of Eq. (5.99).
    rank_tol : float
        Fraction in ``[0, 1)`` of the points that may change rank level in one iteration when
        the ALM stops by the ranking rule (step 3); 0 stops by ``tol`` only.
    dtype : {"float32", "float64"}
        Precision of the solver state (the normalised points, ``R``, ``W``). float32 halves the
        memory of a block and moves scores by about ``1e-5`` spacings (measured on the shared
        scans; the tests bound it by ``1e-3``); the Gram matrices whose eigenvalues drive the
        thresholding, the residual and the scores are always accumulated in float64.
    clusters : bool
        Also flag the points of small volumetric clusters (step 8).
    device : {"cpu", "cuda", "auto"} or torch.device
        Where the ALM iterations of step 3 run (:func:`spectrageo._device.resolve_device`;
        ``"auto"`` = ``"cuda"`` when PyTorch sees a GPU). ``"cpu"`` (default) is the fused numba
        kernel; ``"cuda"`` runs the same iteration in PyTorch on the GPU
        (:mod:`spectrageo.outliers._torch`: same ``mu`` schedule, ``lam``, stopping rules and
        SVT through the eigendecomposition of the Gram matrix, float32 state with float64 Gram
        and residual accumulation); a ``torch.device`` selects that path on any torch device,
        ``torch.device("cpu")`` included. The neighbour search, the rebuilt patches, the normals
        of step 7, the baseline and the clusters stay on the CPU. Tolerance: both paths differ
        only by floating-point rounding (order of the sums, fused multiply-adds). Measured on
        the shared bunny scan, clean and with 10 % injected ``uniform``/``halo`` outliers (torch
        on the CPU against numba, both stopping at the same iteration): max ``|diff|`` of the
        scores ``5e-5`` spacings in float32 and ``3e-8`` in float64, identical refined patches
        and clusters; ``2.1e-4`` on a 1.1M-point cloud (``docs/scaling.md``). Stated tolerance: ``1e-3`` spacings (the tests' bound); keep masks then
        agree except for points whose score lies within ``1e-3`` of the threshold.
    second_pass : {"replay", "full"}
        How step 5 scores the rebuilt patches (see step 5): ``"replay"`` reruns the rebuilt
        rows alone with Gram-corrected operators of the first pass, ``"full"`` reruns every row.
    partition : {"tiles", "blocks"}
        How a cloud of more than ``block_size`` points is split (below that, both are one
        block). ``"tiles"`` (default): the k-d tiles of ``spectrageo outliers --tile``
        (:func:`spectrageo.distributed.remove_outliers_tiled`; boxes of a median split of a
        stride sample, ``ceil(log2(n / block_size))`` levels), each tile with a halo holding
        every neighbourhood its points' scores read, steps 1-8 run on each tile's region alone
        (its own spacing, refinement threshold and clusters), the own points' scores kept and
        rescaled to the global spacing. The tiled command then gives the same scores and keep
        mask (tested bit for bit) whenever its ``--tile`` is at least ``block_size`` and the
        cloud has no exactly repeated points (a cloud with copies is scored on its distinct
        positions first, as below ``block_size``, which the streamed tiles do not do), and memory
        is bounded by one region (a tile plus its halo: up to about ``1.6 x block_size``
        points on the benchmark clouds) besides the cloud.
        ``"blocks"``: one kNN search, spacing and refinement threshold over the whole cloud,
        the ALM in blocks of consecutive points along the Morton curve (rows: the block's
        patches, neighbours anywhere); the behaviour before issue 21's exact tiles. Choice: on
        the 10^7-point benchmark cloud of ``docs/scaling.md`` (1 % outliers) the tiles also
        flag fewer inliers (F1 in ``docs/scaling.md``).
    _knn : internal
        Used by the tile function of :mod:`spectrageo.distributed`: the region's sorted cloud
        and its own points' neighbours from the halo search (:func:`_complete_knn`); leave
        unset.

    Returns
    -------
    PatchRPCAResult
    """
    X, _ = as_cloud(P)
    n = X.shape[0]
    k = check_k(k, n)
    if lam is not None:
        check_positive(lam, "lam")
    check_positive(rho, "rho")
    if rho <= 1:
        raise InvalidInputError(f"`rho` must be > 1; got {rho!r}.")
    check_positive(tol, "tol")
    check_positive(max_iter, "max_iter", integer=True)
    check_positive(block_size, "block_size", integer=True)
    if block_size < k + 1:
        raise InvalidInputError(f"`block_size` must be >= k + 1 = {k + 1}; got {block_size}.")
    check_choice(on_nonconvergence, "on_nonconvergence", ("warn", "raise", "ignore"))
    check_choice(second_pass, "second_pass", ("replay", "full"))
    check_choice(partition, "partition", ("tiles", "blocks"))
    check_positive(tangent_weight, "tangent_weight", allow_zero=True)
    if tangent_weight > 1:
        raise InvalidInputError(f"`tangent_weight` must be in [0, 1]; got {tangent_weight!r}.")
    check_positive(rank_tol, "rank_tol", allow_zero=True)
    if rank_tol >= 1:
        raise InvalidInputError(f"`rank_tol` must be in [0, 1); got {rank_tol!r}.")
    try:
        dt = np.dtype(dtype)
    except TypeError as exc:
        raise InvalidInputError(f"`dtype` must be float32 or float64; got {dtype!r}.") from exc
    if dt not in (np.float32, np.float64):
        raise InvalidInputError(f"`dtype` must be float32 or float64; got {dtype!r}.")
    backend = resolve_backend(device)  # "cpu" (numba) or a torch.device
    opts = dict(
        device=backend,
        lam=lam,
        rho=rho,
        tol=tol,
        max_iter=max_iter,
        block_size=block_size,
        smoothed=smoothed,
        on_nonconvergence=on_nonconvergence,
        workers=workers,
        refine=refine,
        tangent_weight=tangent_weight,
        rank_tol=rank_tol,
        dtype=dt,
        clusters=bool(clusters),
        second_pass=second_pass,
        partition=partition,
        knn=_knn,
    )
    if partition == "tiles" and n > block_size:
        from ..distributed._tiled import rpca_tiles_in_memory

        if _has_duplicates(X):  # score the distinct positions (a tile of copies has no patch)
            return _scores_deduplicated(X, k, **{key: v for key, v in opts.items() if key != "knn"})
        for key in ("on_nonconvergence", "partition", "knn"):
            opts.pop(key)
        res = rpca_tiles_in_memory(X, k, **opts)
        _report(res, on_nonconvergence, max_iter)
        return res
    if isinstance(backend, str):
        with numba_threads(workers):
            return _rpca_scores(X, k, **opts)
    from ._torch import torch_threads

    with numba_threads(workers), torch_threads(backend, workers):
        return _rpca_scores(X, k, **opts)


def _rpca_scores(X: np.ndarray, k: int, **opts: Any) -> PatchRPCAResult:
    """:func:`rpca_scores` after validation (numba threads already limited to ``workers``)."""
    n = X.shape[0]
    smoothed, refine = opts["smoothed"], opts["refine"]
    tangent_weight = opts["tangent_weight"]
    weighted = tangent_weight < 1
    if opts.get("knn") is None:
        sc = SortedCloud.of(X)
        nb = knn_grid(sc, k)
    else:  # a tile region: the halo search's sorted cloud and own points' neighbours
        sc, nb = _complete_knn(opts["knn"], k)
    order, Xs = sc.order, sc.points
    if nb.n_zero:
        return _scores_deduplicated(X, k, **{key: v for key, v in opts.items() if key != "knn"})
    h = spacing_from(nb.dmean)
    idx = nb.idx
    del nb  # the distances are not needed any more
    clusters_s = cluster_outliers(Xs, idx, h) if opts["clusters"] else None  # step 8
    solve_kw = {
        key: opts[key]
        for key in ("lam", "rho", "tol", "rank_tol", "max_iter", "block_size", "workers", "dtype")
    }
    solve_kw["device"] = opts.get("device", "cpu")
    record: list | None = [] if refine and opts["second_pass"] == "replay" else None
    scores_s, E0_s, S1, n_iter, converged, residual, n_blocks = _solve_blocks(
        Xs, h, idx, smoothed=smoothed, vectors=weighted, record=record, **solve_kw
    )
    n_refined = 0
    S2 = S1
    if refine:
        s1 = scores_s
        rebuilt, old_idx = _rebuild_outlier_patches(sc, idx, s1, k)
        n_refined = int(rebuilt.size)
        if n_refined and record is not None:
            scores_s = s1.copy()
            S2 = None if S1 is None else S1.copy()
            _replay_blocks(
                Xs,
                h,
                idx,
                rebuilt,
                old_idx,
                record,
                dtype=solve_kw["dtype"],
                scores_s=scores_s,
                E0_s=E0_s,
                S_s=S2,
            )
        elif n_refined:  # otherwise the second pass would repeat the first
            scores_s, E0_s, S2, it2, conv2, res2, _ = _solve_blocks(
                Xs, h, idx, smoothed=smoothed, vectors=weighted, **solve_kw
            )
            n_iter, converged = max(n_iter, it2), converged and conv2
            residual = max(residual, res2)
        else:
            scores_s = s1.copy()
    if weighted:  # step 7: the residuals measured along the local normal (patches final)
        s1 = np.empty(n)
        _k.tangent_weighted_norms(Xs, idx, S1, S2, float(tangent_weight) ** 2, s1, scores_s)
        del S1, S2
    if refine:
        _subtract_local_baseline(scores_s, s1, idx)

    scores = np.empty(n)
    scores[order] = scores_s
    clusters = None
    if clusters_s is not None:
        clusters = np.empty(n, dtype=bool)
        clusters[order] = clusters_s
    sm = None
    if smoothed:
        sm = np.empty((n, 3))
        sm[order] = E0_s
    res = PatchRPCAResult(
        scores=scores,
        spacing=h,
        smoothed=sm,
        n_iter=n_iter,
        converged=converged,
        residual=residual,
        n_blocks=n_blocks,
        n_refined=n_refined,
        clusters=clusters,
    )
    _report(res, opts["on_nonconvergence"], opts["max_iter"])
    return res


def _complete_knn(knn: Any, k: int) -> tuple[SortedCloud, Neighbours]:
    """Step 1 on a tile region whose first ``m`` rows (the tile's own points) already have their
    exact ``k`` nearest neighbours from the halo search (``spectrageo.distributed``): ``knn`` is
    ``(sc, nbr, n_zero, dmean)`` with ``sc`` the region's sorted cloud, ``nbr`` (m, k) region
    rows, ``n_zero`` the own points with a duplicate, ``dmean`` (m,). The other rows are searched
    here; the result is what :func:`knn_grid` gives for every row, up to the order of exactly
    equidistant neighbours."""
    sc, nbr, n_zero, dmean = knn
    n, m = sc.points.shape[0], nbr.shape[0]
    if nbr.shape[1] != k:  # pragma: no cover - internal: the halo searched with another k
        raise ValueError("neighbour lists of another k")
    pos = np.empty(n, dtype=np.int64)
    pos[sc.order] = np.arange(n)
    idt = np.int32 if n < 2**31 else np.int64
    idx = np.empty((n, k), dtype=idt)
    dm = np.empty(n)
    own = pos[:m]
    idx[own] = pos[nbr]
    dm[own] = dmean
    dlast = np.full(n, np.nan)  # not used by the scores
    if n > m:
        q = np.sort(pos[m:])
        rest = knn_grid(sc, k, query=q, self_index=q)
        idx[q] = rest.idx
        dm[q] = rest.dmean
        n_zero += rest.n_zero
    return sc, Neighbours(idx, dm, dlast, int(n_zero))


#: Flagging floor of the refinement pass, in spacings (see :func:`rpca_scores`, step 5); chosen
#: on the tuning split; see docs/decisions.md#outlier-rpca-constants.
REFINE_MIN_TAU = 1.0


def _solve_blocks(
    Xs: np.ndarray,
    h: float,
    idx: np.ndarray,
    *,
    smoothed: bool,
    lam: float | None,
    rho: float,
    tol: float,
    rank_tol: float,
    max_iter: int,
    block_size: int,
    workers: int,
    dtype: np.dtype,
    vectors: bool = False,
    device: Any = "cpu",
    record: list | None = None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int, bool, float, int]:
    """First-column scores (and ``E`` first column, and the residual vectors ``S[3i:3i+3, 0]``
    when ``vectors``) of every block's patch matrix (sorted order).

    ``record`` (a list), when given, receives per block the list of its iterations' operators
    (:func:`_replay_blocks`)."""
    n = Xs.shape[0]
    scores_s = np.empty(n)
    E0_s = np.empty((n, 3)) if smoothed else None
    # the residual vectors of step 7 in float32 (their norms are formed in float64)
    S_s = np.empty((n, 3), dtype=np.float32) if vectors else np.empty((0, 3), dtype=np.float32)
    n_blocks = max(1, -(-n // int(block_size)))
    bounds = np.linspace(0, n, n_blocks + 1).astype(np.int64)
    n_iter, converged, residual = 0, True, 0.0
    n_threads = _n_threads(workers, min(n, int(block_size)))
    inv_h = 1.0 / h
    Pn = np.empty(Xs.shape, dtype=dtype)  # the cloud about each block's centroid, in spacings
    pool_cm = ThreadPoolExecutor(n_threads) if n_threads > 1 else contextlib.nullcontext()
    # LAPACK only sees (k+1)-square eigenproblems (the kernels use no BLAS): keep it on the
    # calling thread (OpenBLAS does not thread such sizes anyway; the limit guards other builds).
    with pool_cm as pool, single_thread_blas():
        for b in range(n_blocks):
            lo, hi = int(bounds[b]), int(bounds[b + 1])
            centre = _normalise(Xs, lo, hi, inv_h, Pn)
            centers = np.arange(lo, hi, dtype=idx.dtype)
            args = (Pn, centers, idx[lo:hi], lam, rho, tol, rank_tol, max_iter, smoothed)
            vec = S_s[lo:hi] if vectors else S_s
            steps: list | None = None
            if record is not None:
                steps = []
                record.append(steps)
            if not isinstance(device, str):  # the torch path (spectrageo.outliers._torch)
                from ._torch import patch_ialm_torch

                out = patch_ialm_torch(*args, vec, device, record=steps)
            else:
                out = _patch_ialm(*args, pool, n_threads, vec, record=steps)
            scores_s[lo:hi] = out[0]
            if smoothed:
                E0_s[lo:hi] = out[1] * h + centre
            n_iter = max(n_iter, out[2])
            converged = converged and out[3]
            residual = max(residual, out[4])
    return scores_s, E0_s, (S_s if vectors else None), n_iter, converged, residual, n_blocks


def _normalise(Xs: np.ndarray, lo: int, hi: int, inv_h: float, Pn: np.ndarray) -> np.ndarray:
    """``Pn = (Xs - c) / h`` for the whole cloud, ``c`` the centroid of the block ``lo .. hi``
    (returned); rounded once from float64 into ``Pn``'s dtype, in chunks. Shared by both passes
    of step 5, whose replay must see the first pass's coordinates bit for bit."""
    centre = Xs[lo:hi].mean(axis=0)
    n = Xs.shape[0]
    for c0 in range(0, n, KNN_CHUNK):
        c1 = min(n, c0 + KNN_CHUNK)
        Pn[c0:c1] = (Xs[c0:c1] - centre) * inv_h
    return centre


def _replay_blocks(
    Xs: np.ndarray,
    h: float,
    idx: np.ndarray,
    rows: np.ndarray,
    old_idx: np.ndarray,
    record: list,
    *,
    dtype: np.dtype,
    scores_s: np.ndarray,
    E0_s: np.ndarray | None,
    S_s: np.ndarray | None,
) -> None:
    """Step 5's second pass: the sorted rows ``rows`` (whose patches were rebuilt from
    ``old_idx`` to ``idx[rows]``) rescored, in place in ``scores_s``, ``E0_s`` and ``S_s``, by
    :func:`_replay_ialm` with the recorded iterations of their block (same blocks, centring and
    scaling as :func:`_solve_blocks`)."""
    n = Xs.shape[0]
    n_blocks = len(record)
    bounds = np.linspace(0, n, n_blocks + 1).astype(np.int64)
    inv_h = 1.0 / h
    Pn = np.empty(Xs.shape, dtype=dtype)
    with single_thread_blas():
        for b in range(n_blocks):
            lo, hi = int(bounds[b]), int(bounds[b + 1])
            inb = (rows >= lo) & (rows < hi)
            sel = rows[inb]
            if sel.size == 0:
                continue
            centre = _normalise(Xs, lo, hi, inv_h, Pn)
            centers = sel.astype(idx.dtype)
            vec = (
                np.empty((sel.size, 3), dtype=np.float32)
                if S_s is not None
                else np.empty((0, 3), dtype=np.float32)
            )
            sc, e0 = _replay_ialm(
                Pn,
                centers,
                np.ascontiguousarray(old_idx[inb]),
                np.ascontiguousarray(idx[sel]),
                record[b],
                vec,
            )
            scores_s[sel] = sc
            if E0_s is not None:
                E0_s[sel] = e0 * h + centre
            if S_s is not None:
                S_s[sel] = vec


def _rebuild_outlier_patches(
    sc: SortedCloud, idx: np.ndarray, s1: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Step 5 of :func:`rpca_scores`: rebuild, in place, the patches made mostly of flagged points.

    The ``k`` nearest unflagged points of each rebuilt patch's centre are found on the unflagged
    points of the same sorted cloud (:func:`._common.knn_grid` with a subset: far outliers then
    see empty space around them, which the octree search prunes). Returns the (sorted) rows
    whose patches were rebuilt and their former neighbour lists.
    """
    from .static import RPCA_MIN_TAU, auto_threshold

    tau = max(auto_threshold(s1, minimum=RPCA_MIN_TAU), REFINE_MIN_TAU)
    flagged = s1 >= tau
    n_kept = s1.size - int(np.count_nonzero(flagged))
    none = np.empty(0, dtype=np.int64), idx[:0].copy()
    if n_kept < k + 1 or n_kept == s1.size:
        return none
    rebuild = np.flatnonzero(_k.count_flagged(idx, flagged) * 2 > k)
    if rebuild.size == 0:
        return none
    kept = np.flatnonzero(~flagged)
    pos = np.minimum(np.searchsorted(kept, rebuild), kept.size - 1)
    own = np.where(kept[pos] == rebuild, pos, -1)  # an unflagged centre excludes itself
    nb = knn_grid(sc, k, subset=kept, query=rebuild, self_index=own)
    old = idx[rebuild]
    idx[rebuild] = nb.idx
    return rebuild, old


def _subtract_local_baseline(scores: np.ndarray, s1: np.ndarray, idx: np.ndarray) -> None:
    """Step 6 of :func:`rpca_scores`: ``scores -= median of s1 over each patch``, floored at 0."""
    _k.subtract_patch_median(scores, s1, idx)


def _n_threads(workers: int, m: int) -> int:
    """Threads of the fused kernels for blocks of ``m`` points (``workers`` as in cKDTree)."""
    cores = os.cpu_count() or 1
    w = cores if workers is None or workers < 0 else max(1, int(workers))
    return max(1, min(w, m // _MIN_PER_THREAD))


def _report(res: PatchRPCAResult, policy: str, max_iter: int) -> None:
    if res.converged or policy == "ignore":
        return
    msg = (
        f"RPCA of the kNN patch matrix did not converge in {max_iter} iterations "
        f"(residual {res.residual:.3g}); increase `max_iter` or relax `tol`."
    )
    if policy == "raise":
        raise ConvergenceError(msg, partial=res)
    warnings.warn(msg, ConvergenceWarning, stacklevel=3)


def _has_duplicates(X: np.ndarray) -> bool:
    """Whether two rows of ``X`` are equal (exact check only where Morton codes collide)."""
    from ._common import morton_codes, sort_codes

    codes = morton_codes(X)[0]
    sc = codes[sort_codes(codes)]
    if not np.any(sc[1:] == sc[:-1]):
        return False
    return int(np.unique(X, axis=0).shape[0]) < X.shape[0]


def _scores_deduplicated(X: np.ndarray, k: int, **kw: Any) -> PatchRPCAResult:
    """Score unique positions and give every copy the score of its position."""
    U, inverse = np.unique(X, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    if U.shape[0] < k + 1:
        raise InvalidInputError(
            f"`k` = {k} neighbours need at least {k + 1} distinct points; the cloud has "
            f"{U.shape[0]} distinct positions among {X.shape[0]} points."
        )
    r = rpca_scores(U, k, **kw)
    return PatchRPCAResult(
        scores=r.scores[inverse],
        spacing=r.spacing,
        smoothed=None if r.smoothed is None else r.smoothed[inverse],
        n_iter=r.n_iter,
        converged=r.converged,
        residual=r.residual,
        n_blocks=r.n_blocks,
        n_refined=r.n_refined,
        clusters=None if r.clusters is None else r.clusters[inverse],
    )


def _svt_operator(G: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``W`` (K, K) with ``X W = D_tau(X)`` (Eq. 4.21) from the Gram matrix ``G = X^T X``, and its
    factors ``W = A B`` (``A`` (K, r), ``B`` (r, K)).

    ``X = U diag(s) V^T`` gives ``D_tau(X) = X V_r diag(1 - tau / s_r) V_r^T`` over the ``r``
    singular values above ``tau`` (the eigenpairs of ``G``); never an SVD of the tall ``X``.
    """
    w, V = np.linalg.eigh(G)
    s = np.sqrt(np.maximum(w, 0.0))
    pos = s > tau
    K = G.shape[0]
    if not pos.any():  # everything thresholded away: E = 0
        return np.zeros_like(G), np.zeros((K, 1)), np.zeros((1, K))
    Vr = V[:, pos]
    A = np.ascontiguousarray(Vr * (1.0 - tau / s[pos]))
    return np.ascontiguousarray(A @ Vr.T), A, np.ascontiguousarray(Vr.T)


class _Ranges:
    """Disjoint point ranges of one block, run on a thread pool (the kernels release the GIL).

    The ranges depend on the block size only (a power of two, at most :data:`_MAX_PARTS`, of at
    least ``_MIN_PER_THREAD`` points each), never on the thread count: their partial Gram
    matrices are summed in a fixed order, so the scores are bit for bit the same whatever
    ``workers`` is (a tiled run on 1 or 2 Dask workers, a CLI run with ``--workers 1``).
    """

    def __init__(self, m: int, K: int, pool: ThreadPoolExecutor | None, n_threads: int):
        fit = max(1, m // _MIN_PER_THREAD)
        n_parts = min(_MAX_PARTS, 1 << (fit.bit_length() - 1))
        self.bounds = np.linspace(0, m, n_parts + 1).astype(np.int64)
        self.G = np.empty((n_parts, K, K))
        self.pool = pool if n_parts > 1 and n_threads > 1 else None

    def run(self, fn: Any, *args: Any) -> tuple[np.ndarray, float]:
        """``fn(*args, G_part, lo, hi)`` over the ranges; the summed ``G`` and return values."""
        b = self.bounds
        if self.pool is None:
            out = [fn(*args, self.G[p], int(b[p]), int(b[p + 1])) for p in range(len(b) - 1)]
        else:
            futs = [
                self.pool.submit(fn, *args, self.G[p], int(b[p]), int(b[p + 1]))
                for p in range(len(b) - 1)
            ]
            out = [f.result() for f in futs]
        return self.G.sum(axis=0), float(sum(x for x in out if x is not None))


def _patch_ialm(
    Pn: np.ndarray,
    centers: np.ndarray,
    nbrs: np.ndarray,
    lam: float | None,
    rho: float,
    tol: float,
    rank_tol: float,
    max_iter: int,
    want_e0: bool,
    pool: ThreadPoolExecutor | None,
    n_threads: int,
    vec: np.ndarray,
    record: list | None = None,
) -> tuple[np.ndarray, np.ndarray | None, int, bool, float]:
    """Inexact ALM (Eq. 4.22) on the implicit patch matrix of the rows ``centers``.

    Returns ``(scores, E0, n_iter, converged, residual)``; see :mod:`._kernels` for the state,
    kept in the dtype of ``Pn``. Stops at ``residual <= tol`` or when at most ``rank_tol * m``
    scores change their bin of the ranking rule (:func:`rpca_scores`) between two iterations.
    ``vec`` ((m, 3), or no rows) receives the first-column residual vectors of ``S``.
    ``record`` (a list), when given, receives the operators and scalars of every iteration
    (:func:`_replay_ialm`).
    """
    m = centers.shape[0]
    K = nbrs.shape[1] + 1
    dt = Pn.dtype.type
    ranges = _Ranges(m, K, pool, n_threads)
    G, _ = ranges.run(_k.patch_gram, Pn, centers, nbrs)
    fro = float(np.sqrt(max(np.trace(G), 0.0)))
    scores = np.zeros(m)
    E0 = np.empty((m, 3))
    if fro == 0.0:
        E0[:] = 0.0
        vec[:] = 0.0
        return scores, (E0 if want_e0 else None), 0, True, 0.0
    lam = 1.0 / np.sqrt(3.0 * m) if lam is None else float(lam)
    s_max = float(np.sqrt(max(np.linalg.eigvalsh(G)[-1], 0.0)))
    mu = 1.25 / s_max
    mu_max = mu * 1e7
    mu_prev = mu
    R = np.zeros(3 * m * K, dtype=Pn.dtype)  # column-major tiles, see :mod:`._kernels`
    bins = np.full(m, -2, dtype=np.int32)
    converged, residual, it = False, np.inf, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - `it` is returned
        W, A, B = (x.astype(Pn.dtype) for x in _svt_operator(G, 1.0 / mu))
        mu_next = min(mu * rho, mu_max)
        step = (
            W,
            A,
            B,
            dt(lam / mu_prev),
            dt(mu_prev / mu),
            dt(lam / mu),
            dt(1.0 + mu / mu_next),
        )
        if record is not None:
            record.append((G, mu, step))
        G, res2 = ranges.run(_k.patch_ialm_pass, Pn, centers, nbrs, R, *step, E0, scores, vec)
        residual = float(np.sqrt(res2)) / fro
        mu_prev, mu = mu, mu_next
        if residual <= tol:
            converged = True
            break
        if rank_tol > 0:
            changed = _k.rank_bins(scores, RANK_FLOOR, 1.0 / RANK_BIN, bins)
            if it > 1 and lam / mu_prev <= RANK_FLOOR and changed <= rank_tol * m:
                converged = True
                break
    return scores, (E0 if want_e0 else None), it, converged, residual


def _replay_ialm(
    Pn: np.ndarray,
    centers: np.ndarray,
    nbrs_old: np.ndarray,
    nbrs_new: np.ndarray,
    steps: list,
    vec: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Step 5's second pass on the rows ``centers`` whose patches changed from ``nbrs_old`` to
    ``nbrs_new``, from the iterations ``steps`` recorded by :func:`_patch_ialm` on all rows.

    Iteration ``t`` of the recorded pass thresholded the Gram matrix ``G_t`` of its SVT
    argument over all rows. The changed rows are run twice, from ``S = Y = 0`` and with the same
    ``mu`` schedule: on their old patches with the recorded operators (which reproduces their
    share ``G_t^old`` of ``G_t``) and on their new patches with the operators of
    ``G_t - G_t^old + G_t^new`` (the Gram matrix with their new rows in place of the old ones).
    The other rows keep their first-pass trajectories, so their scores are not recomputed.
    Returns the first-column scores and ``E`` first columns of the new rows; ``vec`` ((m, 3),
    or no rows) receives their first-column residual vectors. One thread (few rows).
    """
    m = centers.shape[0]
    K = nbrs_new.shape[1] + 1
    scores = np.zeros(m)
    E0 = np.zeros((m, 3))
    if m == 0 or not steps:
        vec[:] = 0.0
        return scores, E0
    R_old = np.zeros(3 * m * K, dtype=Pn.dtype)
    R_new = np.zeros(3 * m * K, dtype=Pn.dtype)
    G_old, G_new = np.empty((K, K)), np.empty((K, K))
    _k.patch_gram(Pn, centers, nbrs_old, G_old, 0, m)
    _k.patch_gram(Pn, centers, nbrs_new, G_new, 0, m)
    s_old, e_old = np.empty(m), np.empty((m, 3))
    no_vec = np.empty((0, 3), dtype=np.float32)
    for G, mu, (W, A, B, *scal) in steps:
        ops = tuple(x.astype(Pn.dtype) for x in _svt_operator(G - G_old + G_new, 1.0 / mu))
        # G_old / G_new are overwritten with the shares of the next iteration's Gram matrix
        _k.patch_ialm_pass(
            Pn, centers, nbrs_old, R_old, W, A, B, *scal, e_old, s_old, no_vec, G_old, 0, m
        )
        _k.patch_ialm_pass(Pn, centers, nbrs_new, R_new, *ops, *scal, E0, scores, vec, G_new, 0, m)
    return scores, E0
