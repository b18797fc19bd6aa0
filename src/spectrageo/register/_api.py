"""Public registration API (Section 6.2): broad phase, robustification, narrow phase, pipeline.

Inputs are (n, 3) arrays, point clouds or meshes; transforms are (4, 4) float64 mapping the
source into the target frame, ``x_t = R x_s + t`` (rows: ``P @ R.T + t``); results are
deterministic for a given ``rng``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import ConvergenceWarning, InvalidInputError
from .._validation import as_rng, check_choice, check_positive
from ._common import (
    RegistrationResult,
    apply_transform,
    as_transform,
    check_extent,
    downsample_to,
    points_of,
    spacing,
    thin,
)
from ._narrow import (
    NORMAL_K,
    TargetIndex,
    _within,
    check_icp_options,
    constraint,
    neighbors_from_search,
    run_narrow,
    spacing_from_search,
)
from ._robust import boundary_mask
from ._robust_fast import outlier_keep

#: :func:`register` keeps at most TARGET_POINTS * max_points target points for the narrow phase
#: (docs/decisions.md#register-speed, docs/decisions.md#reg-speed5-target)
TARGET_POINTS = 1.0
#: default source size of :func:`register`'s narrow phase (docs/decisions.md#register-speed,
#: docs/decisions.md#reg-speed4-verify)
MAX_POINTS = 8000
#: larger inputs are first thinned to a random subset of this size (every later step samples
#: far fewer points)
MAX_INPUT_POINTS = 1_000_000
#: a registration is reported ``converged`` only with at least these (docs/decisions.md#register-reliable)
MIN_CONSTRAINT = 1e-3
MIN_TIGHT_SHARE = 0.6
#: with rival poses, every start is first refined for at most this many iterations; the full
#: ``max_iter`` only when the leading one has not converged by then (docs/decisions.md#reg-speed4-verify)
RIVAL_ITER = 25


def narrow_phase(
    source: Any,
    target: Any,
    init: Any = None,
    *,
    max_iter: int = 60,
    tol: float = 1e-5,
    method: str = "point_to_plane",
    gamma: float | None = None,
    inlier_distance: float | None = None,
    max_points: int = 20000,
    coarse: bool = True,
) -> RegistrationResult:
    r"""Weighted ICP with Tukey's bi-weight (Section 6.2.4, Eq. 6.39-6.41).

    Minimises :math:`\sum_i \psi(D(R v_i + t, q_i))` (Eq. 6.39-6.40) by iteratively re-weighted
    least squares with nearest-neighbour pairs and weights :math:`(1 - r^2/\gamma^2)^2` for
    :math:`r \le \gamma`, the scale :math:`\gamma` annealed coarse to fine; choices in
    docs/decisions.md#register-narrow-details and docs/decisions.md#register-narrow-tol.

    Parameters
    ----------
    source, target : (n, 3) array_like, PointCloud or Mesh
    init : (4, 4) array_like, optional
        Initial transform (identity by default).
    max_iter, tol : int, float
        Iteration cap (a ConvergenceWarning when reached); step tolerance in source diagonals.
    method : {"point_to_plane", "point_to_point"}
    gamma, inlier_distance : float, optional
        Initial Tukey scale; distance of ``fitness`` (default 3 point spacings).
    max_points : int
        Source voxel down-sampled to at most this many points (target ``max(5 max_points, 1e5)``).
    coarse : bool
        Start on every 4th source point with approximate neighbours.

    Returns
    -------
    RegistrationResult
    """
    S = points_of(source, "source")
    Tg = points_of(target, "target")
    T0 = np.eye(4) if init is None else as_transform(init, "init")
    return run_narrow(
        S,
        Tg,
        T0,
        max_iter=max_iter,
        tol=tol,
        method=method,
        gamma=gamma,
        inlier_distance=inlier_distance,
        max_points=max_points,
        coarse=coarse,
    )


def robustify(
    points: Any,
    *,
    k_outliers: int = 10,
    outlier_threshold: float = 0.6,
    k_boundary: int = 10,
    remove_outliers: bool = True,
    remove_boundary: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Small-scale outlier and boundary removal (Section 6.2.5, Eq. 6.42-6.44).

    Removes points whose RPCA outlier score (Eq. 6.42, in point spacings) exceeds
    ``outlier_threshold`` (thesis 0.6) and points whose mean distance to their ``k_boundary``
    (``K_D = 10``) nearest neighbours is at least twice the mean (Eq. 6.43-6.44). Returns
    ``(kept (m, 3), keep (n,) bool)``.
    """
    P = points_of(points, "points")
    check_positive(k_outliers, "k_outliers", integer=True)
    check_positive(k_boundary, "k_boundary", integer=True)
    check_positive(outlier_threshold, "outlier_threshold")
    kept, keep, _ = _robustify(P, int(k_outliers), float(outlier_threshold), int(k_boundary),
                               remove_outliers, remove_boundary)  # fmt: skip
    return kept, keep


def _robustify(
    P: np.ndarray,
    k_outliers: int = 10,
    outlier_threshold: float = 0.6,
    k_boundary: int = 10,
    remove_outliers: bool = True,
    remove_boundary: bool = True,
) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """:func:`robustify` on validated points and options; also returns the outlier test's k-d
    tree search of ``P`` on itself, ``(tree, d, i)`` as
    `._robust_fast.outlier_keep` returns it, or None."""
    keep = np.ones(P.shape[0], dtype=bool)
    nbrs = search = None  # the RPCA's exact kNN, reused by the boundary test
    if remove_outliers and P.shape[0] > k_outliers + 1:
        ok, nbrs, search = outlier_keep(P, k_outliers, outlier_threshold)
        keep &= ok
    if remove_boundary and P.shape[0] > k_boundary + 1:
        keep &= ~boundary_mask(P, k_boundary, nbrs)
    if keep.sum() < 3:  # never leave less than a registrable cloud
        keep[:] = True
    return P[keep], keep, search


def broad_phase(source: Any, target: Any, *, rng: Any = 0, **options: Any) -> np.ndarray:
    """Global registration (Section 6.2.2, Eq. 6.24-6.27): the (4, 4) source-to-target transform.

    ``options`` (``voxel_size``, ``n_samples``, ``n_matches``, ``kernel_radius``, ``n_peaks``, ...)
    as in :func:`spectrageo.register._broad.broad_phase_points`.
    """
    from ._broad import broad_phase_points

    S = points_of(source, "source")
    Tg = points_of(target, "target")
    return broad_phase_points(S, Tg, rng=as_rng(rng), **options)[0]


@dataclass(frozen=True, eq=False)
class PreparedTarget:
    """A target made ready for many :func:`register` calls (see :func:`prepare_target`).

    Attributes
    ----------
    points : (n, 3) float64
        The target as given.
    voxel_size : float
        Broad-phase voxel.
    robust, method, max_points
        The :func:`register` options it was prepared for.
    """

    points: np.ndarray = field(repr=False)
    voxel_size: float
    robust: bool
    method: str
    max_points: int
    broad: Any = field(repr=False, default=None)
    narrow_points: np.ndarray = field(repr=False, default=None)
    index: TargetIndex = field(repr=False, default=None)
    n_kept: int = 0


def prepare_target(
    target: Any,
    *,
    voxel_size: float | None = None,
    robust: bool = True,
    method: str = "point_to_plane",
    max_points: int = MAX_POINTS,
) -> PreparedTarget:
    """Target descriptors, KD-trees and robustified narrow-phase cloud, for reuse by :func:`register`.

    Parameters
    ----------
    target : (n, 3) array_like, PointCloud or Mesh
    voxel_size : float, optional
        Broad-phase voxel (default: the target's bounding-box diagonal / 45).
    robust, method, max_points
        As in :func:`register`; a call with other values raises.

    Returns
    -------
    PreparedTarget

    Examples
    --------
    >>> pt = prepare_target(scan0)                      # doctest: +SKIP
    >>> [register(s, pt).transformation for s in scans]  # doctest: +SKIP
    """
    from ._broad import broad_target, default_voxel

    Tg = thin(points_of(target, "target"), MAX_INPUT_POINTS)
    check_extent(Tg, "target")
    check_choice(method, "method", ("point_to_plane", "point_to_point"))
    check_positive(max_points, "max_points", integer=True)
    s = float(voxel_size) if voxel_size is not None else default_voxel(Tg, Tg)
    check_positive(s, "voxel_size")
    Td = downsample_to(Tg, int(TARGET_POINTS * max_points))
    n_kept = Td.shape[0]
    nbrs = h = tree = None
    need_normals = method == "point_to_plane"
    if robust:
        Td, kt, search = _robustify(Td)
        n_kept = int(kt.sum())
        if search is not None:
            # the outlier test's search gives the spacing, most normals' neighbour lists and,
            # when every point is kept, the tree (the same values as searching the kept points)
            h = spacing_from_search(kt, search[1], search[2])
            if need_normals:
                nbrs = neighbors_from_search(kt, search[1], search[2], NORMAL_K)
            tree = search[0] if kt.all() else None
    index = TargetIndex(Td, need_normals=need_normals, neighbors=nbrs, point_spacing=h, tree=tree)
    return PreparedTarget(Tg, s, bool(robust), method, int(max_points), broad_target(Tg, s), Td,
                          index, n_kept)  # fmt: skip


def _prepared(target: Any, S: np.ndarray, robust: bool, method: str, max_points: int, bo: dict):
    if not isinstance(target, PreparedTarget):
        from ._broad import default_voxel

        Tg = thin(points_of(target, "target"), MAX_INPUT_POINTS)
        vs = bo.get("voxel_size")
        s = float(vs) if vs is not None else default_voxel(S, Tg)
        check_positive(s, "voxel_size")
        return prepare_target(Tg, voxel_size=s, robust=robust, method=method, max_points=max_points)
    got = (target.robust, target.method, target.max_points)
    if got != (bool(robust), method, int(max_points)):
        raise InvalidInputError(
            f"the prepared target was made for robust, method, max_points = {got}; this call "
            f"asks for {(bool(robust), method, int(max_points))}."
        )
    if bo.get("voxel_size") is not None and float(bo["voxel_size"]) != target.voxel_size:
        raise InvalidInputError(
            "`broad_options['voxel_size']` differs from the prepared target's; prepare it with "
            "that voxel."
        )
    return target


def _reliable(
    Sd: np.ndarray,
    index: TargetIndex,
    res: RegistrationResult,
    info: dict,
    near: float,
    query: tuple | None = None,
) -> bool:
    """Whether the final pose is pinned down: the inliers constrain every rigid motion
    (:func:`constraint` at least ``MIN_CONSTRAINT``) and concentrate near zero residual (the
    share of the inliers within a third of ``inlier_distance``, one spacing, at least
    ``MIN_TIGHT_SHARE``; ``near``: the share of ``Sd`` within a third of ``inlier_distance``,
    already scored; ``query``: the final pose's nearest-target query within
    ``inlier_distance``, when known); docs/decisions.md#register-reliable."""
    d = res.inlier_distance
    c = constraint(Sd, index, res.transformation, d, query)
    tight = near / max(res.fitness, 1e-300)
    info.update(icp_converged=bool(res.converged), constraint=c, tight_share=tight)
    info["reliable"] = bool(c >= MIN_CONSTRAINT and tight >= MIN_TIGHT_SHARE)
    return info["reliable"]


def register(
    source: Any,
    target: Any,
    *,
    init: Any = None,
    rng: Any = 0,
    robust: bool = True,
    max_iter: int = 60,
    tol: float = 1e-5,
    method: str = "point_to_plane",
    max_points: int = MAX_POINTS,
    broad_options: dict | None = None,
) -> RegistrationResult:
    """Broad-to-narrow registration (Section 6.2.1): broad phase unless ``init``, robustify, ICP.

    ``target`` may be a :class:`PreparedTarget` (:func:`prepare_target`), reused across calls.
    ``rng`` seeds the broad phase; ``robust`` applies :func:`robustify`; ``max_iter``, ``tol``,
    ``method``, ``max_points`` go to :func:`narrow_phase` and ``broad_options`` to
    :func:`broad_phase`. The broad phase's pose and its rivals (other verified poses nearly as
    fit) are refined, each first for at most ``RIVAL_ITER`` iterations (all ``max_iter`` for
    every unconverged one when the leader has not converged by then); the largest share of
    source points within a third of the inlier distance wins, then the fitness.
    ``converged`` is the narrow phase's convergence and the pose being
    pinned down (no sliding along a plane, line or sphere, inliers near zero residual; else the
    pose is a guess, e.g. without overlap). Returns a :class:`RegistrationResult` whose ``info``
    holds ``time_s``, ``broad_time_s``, ``n_candidates``, ``n_kept_source``, ``n_kept_target``,
    ``icp_converged``, ``constraint``, ``tight_share`` and ``reliable``.
    """
    t0 = time.perf_counter()
    S = thin(points_of(source, "source"), MAX_INPUT_POINTS)
    check_extent(S, "source")
    check_icp_options(max_iter, tol, method)
    check_positive(max_points, "max_points", integer=True)
    g = as_rng(rng)
    if broad_options is not None and not isinstance(broad_options, dict):
        raise InvalidInputError(
            f"`broad_options` must be a dict; got {type(broad_options).__name__}."
        )
    bo = dict(broad_options or {})
    pt = _prepared(target, S, robust, method, max_points, bo)
    bo.pop("voxel_size", None)
    info: dict[str, Any] = {}
    if init is None:
        from ._broad import broad_phase_points

        T0, binfo = broad_phase_points(S, None, rng=g, target=pt.broad, **bo)
        info.update(binfo)
    else:
        T0 = as_transform(init, "init")
        info["broad_time_s"] = 0.0
    # robustification on the clouds the narrow phase will use (down-sampled first: the RPCA
    # patch problem then costs ~0.05 s instead of ~0.5 s on a 40k-point scan)
    Sd = downsample_to(S, max_points)
    hs = None  # the spacing of Sd, from the outlier test's search when there is one
    if robust:
        Sd, ks, search = _robustify(Sd)
        info["n_kept_source"], info["n_kept_target"] = int(ks.sum()), pt.n_kept
        if search is not None:
            hs = spacing_from_search(ks, search[1], search[2])
    if hs is None:
        hs = spacing(Sd)
    # after the broad phase (already refined at the voxel scale) the Tukey scale starts at two
    # voxels instead of the median distance, which at low overlap is dominated by points without
    # a counterpart and would drag the alignment off
    gamma0 = 2.0 * info["voxel_size"] if init is None else None
    # the broad phase's best and its close rivals (other poses nearly as fit at the voxel scale,
    # e.g. a room turned by 180 degrees) are refined; the share of source points within one
    # spacing (a third of the inlier distance) decides, then the fitness
    rivals = info.pop("rivals", [])
    info["n_rivals"] = len(rivals)
    starts = [T0, *rivals]

    def refine(T_start: np.ndarray, iters: int) -> RegistrationResult:
        return run_narrow(Sd, pt.points, T_start, max_iter=iters, tol=tol, method=method,
                          gamma=gamma0, max_points=max_points, index=pt.index, warn=False,
                          keep_query=True, source_spacing=hs)  # fmt: skip

    def key(r: RegistrationResult) -> tuple[float, float]:
        d = r.info["final_query"][1]
        return float(_within(d, r.inlier_distance / 3.0).mean()), r.fitness

    # with rivals every start is first given RIVAL_ITER iterations (a run converged by then is
    # the full run); only when the leader has not converged, every unconverged start gets all
    cap = min(max_iter, RIVAL_ITER) if rivals else max_iter
    runs = [refine(T, cap) for T in starts]
    keys = [key(r) for r in runs]
    k = max(range(len(runs)), key=keys.__getitem__)
    if cap < max_iter and not runs[k].converged:
        runs = [r if r.converged else refine(T, max_iter) for r, T in zip(runs, starts)]
        keys = [key(r) for r in runs]
        k = max(range(len(runs)), key=keys.__getitem__)
    res, best = runs[k], keys[k]
    query = res.info.pop("final_query")
    if not res.converged:
        warnings.warn(
            f"narrow phase stopped at max_iter={max_iter} before meeting tol={tol:g}.",
            ConvergenceWarning,
            stacklevel=2,
        )
    info.update(res.info)
    reliable = _reliable(Sd, pt.index, res, info, best[0], query)
    info["time_s"] = time.perf_counter() - t0
    return RegistrationResult(
        transformation=res.transformation,
        fitness=res.fitness,
        inlier_rmse=res.inlier_rmse,
        n_iter=res.n_iter,
        converged=res.converged and reliable,
        inlier_distance=res.inlier_distance,
        info=info,
    )


__all__ = [
    "PreparedTarget",
    "RegistrationResult",
    "apply_transform",
    "broad_phase",
    "narrow_phase",
    "prepare_target",
    "register",
    "robustify",
]
