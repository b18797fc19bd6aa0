"""Public registration API (Section 6.2): broad phase, robustification, narrow phase, pipeline.

Inputs are (n, 3) arrays, point clouds or meshes; transforms are (4, 4) float64 mapping the
source into the target frame, ``x_t = R x_s + t`` (rows: ``P @ R.T + t``); results are
deterministic for a given ``rng``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_rng, check_positive
from ._common import (
    RegistrationResult,
    apply_transform,
    as_transform,
    downsample_to,
    points_of,
)
from ._narrow import TargetIndex, check_icp_options, run_narrow
from ._robust import boundary_mask, outlier_scores


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
    keep = np.ones(P.shape[0], dtype=bool)
    if remove_outliers and P.shape[0] > k_outliers + 1:
        keep &= outlier_scores(P, int(k_outliers)) <= outlier_threshold
    if remove_boundary and P.shape[0] > k_boundary + 1:
        keep &= ~boundary_mask(P, int(k_boundary))
    if keep.sum() < 3:  # never leave less than a registrable cloud
        keep[:] = True
    return P[keep], keep


def broad_phase(source: Any, target: Any, *, rng: Any = 0, **options: Any) -> np.ndarray:
    """Global registration (Section 6.2.2, Eq. 6.24-6.27): the (4, 4) source-to-target transform.

    ``options`` (``voxel_size``, ``n_samples``, ``n_matches``, ``kernel_radius``, ``n_peaks``, ...)
    as in :func:`spectrageo.register._broad.broad_phase_points`.
    """
    from ._broad import broad_phase_points

    S = points_of(source, "source")
    Tg = points_of(target, "target")
    return broad_phase_points(S, Tg, rng=as_rng(rng), **options)[0]


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
    max_points: int = 20000,
    broad_options: dict | None = None,
) -> RegistrationResult:
    """Broad-to-narrow registration (Section 6.2.1): broad phase unless ``init``, robustify, ICP.

    ``rng`` seeds the broad phase; ``robust`` applies :func:`robustify`; ``max_iter``, ``tol``,
    ``method``, ``max_points`` go to :func:`narrow_phase` and ``broad_options`` to
    :func:`broad_phase`. Returns a :class:`RegistrationResult` whose ``info`` holds ``time_s``,
    ``broad_time_s``, ``n_candidates``, ``n_kept_source`` and ``n_kept_target``.
    """
    t0 = time.perf_counter()
    S = points_of(source, "source")
    Tg = points_of(target, "target")
    check_icp_options(max_iter, tol, method)
    check_positive(max_points, "max_points", integer=True)
    g = as_rng(rng)
    if broad_options is not None and not isinstance(broad_options, dict):
        raise InvalidInputError(
            f"`broad_options` must be a dict; got {type(broad_options).__name__}."
        )
    info: dict[str, Any] = {}
    if init is None:
        from ._broad import broad_phase_points

        T0, binfo = broad_phase_points(S, Tg, rng=g, **(broad_options or {}))
        info.update(binfo)
    else:
        T0 = as_transform(init, "init")
        info["broad_time_s"] = 0.0
    # robustification on the clouds the narrow phase will use (down-sampled first: the RPCA
    # patch problem then costs ~0.05 s instead of ~0.5 s on a 40k-point scan)
    Sd = downsample_to(S, max_points)
    Td = downsample_to(Tg, max(5 * max_points, 100000))
    if robust:
        Sd, ks = robustify(Sd)
        Td, kt = robustify(Td)
        info["n_kept_source"], info["n_kept_target"] = int(ks.sum()), int(kt.sum())
    index = TargetIndex(Td, need_normals=method == "point_to_plane")
    # after the broad phase (already refined at the voxel scale) the Tukey scale starts at two
    # voxels instead of the median distance, which at low overlap is dominated by points without
    # a counterpart and would drag the alignment off
    gamma0 = 2.0 * info["voxel_size"] if init is None else None
    res = run_narrow(
        Sd,
        Td,
        T0,
        max_iter=max_iter,
        tol=tol,
        method=method,
        gamma=gamma0,
        max_points=max_points,
        index=index,
    )
    info.update(res.info)
    info["time_s"] = time.perf_counter() - t0
    return RegistrationResult(
        transformation=res.transformation,
        fitness=res.fitness,
        inlier_rmse=res.inlier_rmse,
        n_iter=res.n_iter,
        converged=res.converged,
        inlier_distance=res.inlier_distance,
        info=info,
    )


__all__ = [
    "RegistrationResult",
    "apply_transform",
    "broad_phase",
    "narrow_phase",
    "register",
    "robustify",
]
