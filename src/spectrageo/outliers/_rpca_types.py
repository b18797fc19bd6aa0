"""Options and result of the patch RPCA (:func:`spectrageo.outliers.rpca_scores`)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import ConvergenceError, ConvergenceWarning, InvalidInputError
from .._validation import check_choice, check_positive
from ._common import resolvable
from ._organized import OrganizedGrid
from ._range import RANGE_POWER, check_viewpoint

__all__ = ["PatchRPCAResult", "RPCAOptions", "scan_options", "viewpoint_options"]

#: Default ``sparse_factor``: chosen on the tuning split; see docs/decisions.md#outliers-sparse-stage.
SPARSE_FACTOR = 3.0
#: Default ``rank_tol``: chosen on the tuning split; see docs/decisions.md#outliers-rank-tol.
RANK_TOL = 3e-3
#: Default ``rescore_share``: chosen on the tuning split; see docs/decisions.md#outliers-rescore.
RESCORE_SHARE = 0.11
#: Flagging floor of the refinement pass, in spacings (step 5); chosen on the tuning split; see
#: docs/decisions.md#outlier-rpca-constants.
REFINE_MIN_TAU = 1.0
#: Quantile of the first-pass patch scores subtracted in step 6 (the local baseline); chosen on
#: the tuning split; see docs/decisions.md#outliers-baseline-quantile.
BASELINE_QUANTILE = 0.3


@dataclass(frozen=True)
class RPCAOptions:
    """Options of the patch RPCA (:func:`spectrageo.outliers.rpca_scores`), validated on creation.

    Parameters
    ----------
    lam : float, optional
        Weight of ``||S||_1``; default ``1 / sqrt(3 m)`` for a block of ``m`` points.
    rho, tol, max_iter
        Growth factor of ``mu`` (``> 1``), relative residual at which the ALM stops, iteration cap.
    block_size : int, optional
        Points per RPCA block and largest tile; None is ``rpca.BLOCK_SIZE`` (2^22).
    refine : bool
        Steps 5-6 (rebuilt patches, local baseline).
    tangent_weight : float
        Weight in ``[0, 1]`` of the tangential residual (step 7).
    rank_tol : float
        Ranking stop rule, in ``[0, 1)``; 0 stops by ``tol`` only.
    dtype : {"float32", "float64"}
        Precision of the solver state.
    clusters : bool
        Step 8 (small volumetric clusters).
    second_pass : {"replay", "full"}
        How step 5 rescores the rebuilt patches.
    partition : {"tiles", "blocks"}
        A cloud above ``block_size``: k-d tiles with halos, or Morton blocks of one problem.
    on_nonconvergence : {"warn", "raise", "ignore"}
        Policy when a block reaches ``max_iter`` first.
    viewpoint : (3,) tuple of float, optional
        Sensor origin of a single-view scan (step 9: scores over ``max(rho_i, 1)^range_power``).
    range_power : float
        Exponent of step 9 (``>= 0``).
    sparse_factor : float, optional
        :func:`remove_outliers` also removes points whose ``k``-th neighbour is farther than
        ``sparse_factor`` times the median (range-normalised with a viewpoint); None: off.
    sparse_regions : bool
        :func:`remove_outliers` keeps the removed points that form large sparse surface regions
        (:mod:`._support`).
    rescore_share : float, optional
        :func:`remove_outliers` scores the kept points again (a second pass) when the first
        removed at least this share of the cloud (all its outliers removed when their spacing is
        homogeneous, ``static.RESCORE_SPREAD``, else the locally sparse ones,
        ``static.RESCORE_LOCAL``), and tries a further pass after any pass that removed
        ``static.RESCORE_FOUND`` of the cloud, keeping its removals when they reach that share
        and score well above its threshold (``static.RESCORE_LIFT``); None: off.
    grid : OrganizedGrid, optional
        Image grid of an organized depth frame: :func:`remove_outliers` removes its flying pixels
        and keeps its image-supported points (:mod:`._organized`); the viewpoint defaults to the
        origin (camera coordinates).
    backend : {"numba", "numpy"}
        Steps 1-7 by the numba kernels, or by NumPy/SciPy without numba (:mod:`._rpca_numpy`:
        one block, no steps 8-9, scores equal within rounding; docs/decisions.md#register-numpy-rpca).
    """

    lam: float | None = None
    rho: float = 3.0
    tol: float = 3e-4
    max_iter: int = 200
    block_size: int | None = None
    refine: bool = True
    tangent_weight: float = 0.5
    rank_tol: float = RANK_TOL
    dtype: str = "float32"
    clusters: bool = True
    second_pass: str = "replay"
    partition: str = "tiles"
    on_nonconvergence: str = "warn"
    viewpoint: tuple[float, float, float] | None = None
    range_power: float = RANGE_POWER
    sparse_factor: float | None = SPARSE_FACTOR
    sparse_regions: bool = True
    rescore_share: float | None = RESCORE_SHARE
    grid: OrganizedGrid | None = None
    backend: str = "numba"

    def __post_init__(self) -> None:
        check_choice(self.backend, "backend", ("numba", "numpy"))
        if self.grid is not None and not isinstance(self.grid, OrganizedGrid):
            raise InvalidInputError(f"`grid` must be an OrganizedGrid; got {type(self.grid)}.")
        object.__setattr__(self, "viewpoint", check_viewpoint(self.viewpoint))
        check_positive(self.range_power, "range_power", allow_zero=True)
        if self.sparse_factor is not None:
            check_positive(self.sparse_factor, "sparse_factor")
        if self.rescore_share is not None:
            check_positive(self.rescore_share, "rescore_share")
        if self.rescore_share is not None and self.rescore_share > 1:
            raise InvalidInputError(
                f"`rescore_share` must be in (0, 1] or None; got {self.rescore_share!r}."
            )
        if self.lam is not None:
            check_positive(self.lam, "lam")
        check_positive(self.rho, "rho")
        if self.rho <= 1:
            raise InvalidInputError(f"`rho` must be > 1; got {self.rho!r}.")
        check_positive(self.tol, "tol")
        check_positive(self.max_iter, "max_iter", integer=True)
        if self.block_size is not None:
            check_positive(self.block_size, "block_size", integer=True)
        check_choice(self.on_nonconvergence, "on_nonconvergence", ("warn", "raise", "ignore"))
        check_choice(self.second_pass, "second_pass", ("replay", "full"))
        check_choice(self.partition, "partition", ("tiles", "blocks"))
        check_positive(self.tangent_weight, "tangent_weight", allow_zero=True)
        if self.tangent_weight > 1:
            raise InvalidInputError(
                f"`tangent_weight` must be in [0, 1]; got {self.tangent_weight!r}."
            )
        check_positive(self.rank_tol, "rank_tol", allow_zero=True)
        if self.rank_tol >= 1:
            raise InvalidInputError(f"`rank_tol` must be in [0, 1); got {self.rank_tol!r}.")
        try:
            dt = np.dtype(self.dtype)
        except TypeError as exc:
            raise InvalidInputError(
                f"`dtype` must be float32 or float64; got {self.dtype!r}."
            ) from exc
        if dt not in (np.float32, np.float64):
            raise InvalidInputError(f"`dtype` must be float32 or float64; got {self.dtype!r}.")
        object.__setattr__(self, "dtype", dt.name)

    @property
    def sensor_origin(self) -> tuple[float, float, float] | None:
        """``viewpoint``, or the origin for an organized grid without one."""
        if self.viewpoint is None and self.grid is not None:
            return (0.0, 0.0, 0.0)
        return self.viewpoint

    def solver_kwargs(
        self, *, block_size: int, smoothed: bool, workers: int, device: Any
    ) -> dict[str, Any]:
        """The keyword arguments of the scoring pipeline (:mod:`._rpca_core`); ``device`` is
        resolved where the scores are computed (:func:`spectrageo._device.resolve_backend`)."""
        return dict(
            device=device,
            lam=self.lam,
            rho=self.rho,
            tol=self.tol,
            max_iter=self.max_iter,
            block_size=int(block_size),
            smoothed=smoothed,
            on_nonconvergence=self.on_nonconvergence,
            workers=workers,
            refine=self.refine,
            tangent_weight=self.tangent_weight,
            rank_tol=self.rank_tol,
            dtype=np.dtype(self.dtype),
            clusters=bool(self.clusters),
            second_pass=self.second_pass,
            partition=self.partition,
            knn=None,
        )


def viewpoint_options(text: str, method: str = "rpca") -> Any:
    """:class:`RPCAOptions` with the viewpoint ``"X,Y,Z"`` (the ``--viewpoint`` option).

    Raises
    ------
    InvalidInputError
        Not three comma-separated numbers, or ``method`` is not ``"rpca"``.
    """
    if method != "rpca":
        raise InvalidInputError(f"--viewpoint applies to --method rpca only; got {method!r}.")
    try:
        v = tuple(float(x) for x in str(text).split(","))
    except ValueError as exc:
        raise InvalidInputError(f"--viewpoint must be X,Y,Z (3 numbers); got {text!r}.") from exc
    if len(v) != 3:
        raise InvalidInputError(f"--viewpoint must be X,Y,Z (3 numbers); got {text!r}.")
    return RPCAOptions(viewpoint=v)


def scan_options(
    path: Any, cloud: Any = None, viewpoint: str | None = None, method: str = "rpca"
) -> Any:
    """:class:`RPCAOptions` of a scan file as ``spectrageo outliers`` builds them, or None.

    ``viewpoint`` (``"X,Y,Z"``, the ``--viewpoint`` option) wins; otherwise a PCD file's header
    gives it (``VIEWPOINT``'s origin) when the cloud is organized or the ``VIEWPOINT`` differs
    from PCL's default ``0 0 0 1 0 0 0``. An organized PCD (``HEIGHT > 1``) read as ``cloud``
    (a PointCloud; NaN pixels dropped, their rows in the attribute ``source_index``) also gives
    :class:`OrganizedGrid`. See docs/decisions.md#outliers-organized-grid.

    Raises
    ------
    InvalidInputError
        A malformed ``viewpoint`` or header, or ``viewpoint`` with a ``method`` other than rpca.
    """
    opts = None if viewpoint is None else viewpoint_options(viewpoint, method)
    name = str(path).lower()
    if method != "rpca" or not name.endswith((".pcd", ".pcd.gz")):
        return opts
    from ..io._pcd import read_pcd_header

    hdr = read_pcd_header(path)
    vp = opts.viewpoint if opts is not None else None
    if vp is None and (hdr.organized or not hdr.default_viewpoint):
        vp = hdr.origin
    grid = None
    points = getattr(cloud, "points", None)
    if hdr.organized and points is not None:
        index = getattr(cloud, "attributes", {}).get("source_index")
        if index is not None or points.shape[0] == hdr.width * hdr.height:
            grid = OrganizedGrid((hdr.height, hdr.width), index)
    if vp is None and grid is None:
        return opts
    return RPCAOptions(viewpoint=vp, grid=grid)


@dataclass(frozen=True)
class PatchRPCAResult:
    """Result of :func:`spectrageo.outliers.rpca_scores` (arrays in input order).

    Attributes
    ----------
    scores : (n,) ndarray
        ``||s_i||_2`` of Eq. 5.99 in units of ``spacing``.
    spacing : float
        Point spacing ``h`` (input units).
    smoothed : (n, 3) ndarray or None
        First column of ``E`` in input coordinates, when requested.
    n_iter, converged, residual, n_blocks, n_refined
        Largest iteration count, whether all blocks converged, largest relative residual, number of
        blocks (tiles), rebuilt patches.
    clusters : (n,) bool ndarray or None
        Points in small volumetric clusters (step 8).
    kth_distance : (n,) ndarray or None
        Distance to the ``k``-th neighbour (over ``max(rho_i, 1)`` with a viewpoint); None for
        clouds scored on tiles.
    knn : tuple or None
        ``(order, idx)``: the sorting permutation of the scored cloud and its neighbour lists in
        sorted positions (after step 5); None for tiles and deduplicated clouds.
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
    kth_distance: np.ndarray | None = field(default=None, repr=False)
    knn: tuple | None = field(default=None, repr=False)


def report(res: PatchRPCAResult, policy: str, max_iter: int) -> None:
    """Apply the ``on_nonconvergence`` policy to a result."""
    if res.converged or policy == "ignore":
        return
    msg = (
        f"RPCA of the kNN patch matrix did not converge in {max_iter} iterations "
        f"(residual {res.residual:.3g}); increase `max_iter` or relax `tol`."
    )
    if policy == "raise":
        raise ConvergenceError(msg, partial=res)
    warnings.warn(msg, ConvergenceWarning, stacklevel=3)


def scores_deduplicated(
    X: np.ndarray, k: int, score: Callable[..., PatchRPCAResult], kw: dict
) -> PatchRPCAResult:
    """``score(U, k, **kw)`` on the unique positions ``U`` (points closer than float64 resolves
    count as copies: :func:`~._common.resolvable`); every copy gets its position's score."""
    U, inverse = np.unique(resolvable(X), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    if U.shape[0] == X.shape[0]:  # nothing merged: the search met no copy to remove
        raise InvalidInputError("the point cloud has points the neighbour search cannot separate.")
    if U.shape[0] < k + 1:
        raise InvalidInputError(
            f"`k` = {k} neighbours need at least {k + 1} distinct points; the cloud has "
            f"{U.shape[0]} distinct positions among {X.shape[0]} points."
        )
    r = score(U, k, **kw)
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
        kth_distance=None if r.kth_distance is None else r.kth_distance[inverse],
    )
