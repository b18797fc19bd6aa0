"""Shared helpers of the registration steps: inputs, down-sampling, normals, rigid transforms."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_points

#: Threads used by the kNN queries (-1: all cores, as Open3D's searches do; the answers do not
#: depend on the thread count).
WORKERS = -1
#: queries with fewer points run on one thread (starting the threads costs more than they save)
SMALL_QUERY = 8192


def workers_for(n: int) -> int:
    """kNN query threads for ``n`` query points."""
    return 1 if n < SMALL_QUERY else WORKERS


def points_of(x: Any, name: str) -> np.ndarray:
    """(n, 3) float64 points of an array, a PointCloud or a Mesh, validated."""
    if x is None:
        raise InvalidInputError(
            f"`{name}` must be an (n, 3) array, a PointCloud or a Mesh; got None."
        )
    for attr in ("points", "vertices"):
        if hasattr(x, attr) and not isinstance(x, np.ndarray):
            x = getattr(x, attr)
            break
    P = as_points(x, name)
    if P.shape[0] < 3:
        raise InvalidInputError(
            f"`{name}` must have at least 3 points for a rigid registration; got {P.shape[0]}."
        )
    return P


def check_extent(P: np.ndarray, name: str) -> None:
    """Raise when every point of ``P`` is the same (nothing fixes a rigid motion)."""
    if not np.any(P.max(axis=0) > P.min(axis=0)):
        raise InvalidInputError(
            f"`{name}` has {P.shape[0]} points that are all equal (zero extent); a rigid "
            "registration needs a cloud with extent."
        )


def as_transform(T: Any, name: str) -> np.ndarray:
    """A validated rigid (4, 4) transform (tolerance 1e-4), rotation re-orthonormalised."""
    try:
        A = np.array(T, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"`{name}` must be a numeric (4, 4) matrix.") from exc
    if A.shape != (4, 4):
        raise InvalidInputError(f"`{name}` must have shape (4, 4); got {A.shape}.")
    if not np.isfinite(A).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    if not np.allclose(A[3], [0.0, 0.0, 0.0, 1.0], atol=1e-8):
        raise InvalidInputError(f"`{name}` must have last row [0, 0, 0, 1]; got {A[3].tolist()}.")
    R = A[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise InvalidInputError(
            f"`{name}` must be a rigid transform (orthonormal rotation block with det +1)."
        )
    A[:3, :3] = orthonormalize(R)
    return A


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Closest rotation (det +1) to ``R`` in the Frobenius norm (SVD)."""
    U, _, Vt = np.linalg.svd(R)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ D @ Vt


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def apply_transform(T: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Points ``P`` (n, 3) moved by ``T``: ``P @ R.T + t``."""
    return P @ T[:3, :3].T + T[:3, 3]


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation by ``|w|`` radians about ``w / |w|``."""
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    k = w / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Uniformly distributed rotation (from a normalised Gaussian quaternion)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def column_bounds(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column minimum and maximum of ``P`` (n, d), exactly ``P.min(axis=0)`` and
    ``P.max(axis=0)``, one contiguous pass per column (a reduction along axis 0 of an (n, 3)
    array is much slower)."""
    cols = range(P.shape[1])
    return np.array([P[:, j].min() for j in cols]), np.array([P[:, j].max() for j in cols])


def bbox_diagonal(P: np.ndarray) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``P`` (n, 3)."""
    lo, hi = column_bounds(P)
    return float(np.linalg.norm(hi - lo))


def _voxel_keys(D: np.ndarray, voxel: float) -> np.ndarray:
    """Integer voxel coordinates ``floor(D / voxel)`` (n, 3) int64 of points ``D >= 0``."""
    buf = np.divide(D, voxel)
    np.floor(buf, out=buf)
    return buf.astype(np.int64)


def _voxel_code(key: np.ndarray) -> tuple[np.ndarray | None, int]:
    """Mixed-radix code ``(k0 span1 + k1) span2 + k2`` (n,) int64 of voxel keys, ordered like
    the rows of ``key`` lexicographically, and the number of codes; ``(None, 0)`` when the
    code would not fit in 62 bits."""
    span = column_bounds(key)[1] + 1
    size = float(span[0]) * float(span[1]) * float(span[2])
    if size >= 2.0**62:
        return None, 0
    return (key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2], int(size)


def _dense(size: int, n: int) -> bool:
    """Whether an occupancy table of ``size`` codes is cheaper than sorting ``n`` codes."""
    return size <= max(4 * n, 65536)


def _n_voxels(D: np.ndarray, voxel: float) -> int:
    """Number of voxels of size ``voxel`` occupied by the points ``D >= 0`` (n, 3)."""
    if voxel <= 0:
        return D.shape[0]
    key = _voxel_keys(D, voxel)
    code, size = _voxel_code(key)
    if code is None:
        return int(np.unique(key, axis=0).shape[0])
    if _dense(size, code.size):
        occupied = np.zeros(size, dtype=bool)
        occupied[code] = True
        return int(np.count_nonzero(occupied))
    sc = np.sort(code, kind="stable")
    return int(np.count_nonzero(sc[1:] != sc[:-1])) + 1


def _voxel_labels(key: np.ndarray) -> np.ndarray:
    """Each row's rank among the distinct rows of ``key`` in lexicographic order (the inverse
    of ``np.unique(key, axis=0)``), (n,) intp."""
    code, size = _voxel_code(key)
    if code is None:
        return np.unique(key, axis=0, return_inverse=True)[1].ravel()
    if _dense(size, code.size):
        occupied = np.zeros(size, dtype=bool)
        occupied[code] = True
        rank = np.cumsum(occupied, dtype=np.intp)
        return rank[code] - 1
    order = np.argsort(code, kind="stable")
    sc = code[order]
    first = np.empty(sc.size, dtype=bool)
    first[0] = True
    np.not_equal(sc[1:], sc[:-1], out=first[1:])
    label = np.empty(sc.size, dtype=np.intp)
    label[order] = np.cumsum(first, dtype=np.intp) - 1
    return label


def _centroids(P: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Mean (m, 3) of the points ``P`` of every label ``0 .. m - 1``."""
    m = int(label.max()) + 1
    cnt = np.bincount(label, minlength=m).astype(np.float64)
    Q = np.empty((m, 3))
    for j in range(3):
        Q[:, j] = np.bincount(label, weights=P[:, j], minlength=m) / cnt
    return Q


def voxel_downsample(P: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Voxel-grid down-sampling of ``P`` (n, 3).

    The voxel of a point is ``floor((p - min P) / voxel)`` per coordinate; returns ``(Q, label)``
    with ``Q`` (m, 3) the centroids of the occupied voxels in lexicographic order of their
    integer coordinates and ``label`` (n,) the row of ``Q`` of each point. ``voxel <= 0`` or an
    empty ``P`` returns a copy of ``P`` and ``arange(n)``.
    """
    if voxel <= 0 or P.shape[0] == 0:
        return P.copy(), np.arange(P.shape[0])
    label = _voxel_labels(_voxel_keys(P - column_bounds(P)[0], voxel))
    return _centroids(P, label), label


def thin(P: np.ndarray, limit: int) -> np.ndarray:
    """At most ``limit`` points of ``P``: a fixed-seed random subset in the original order."""
    if P.shape[0] <= limit:
        return P
    keep = np.random.default_rng(0).choice(P.shape[0], size=int(limit), replace=False)
    return P[np.sort(keep)]


def downsample_to(P: np.ndarray, max_points: int) -> np.ndarray:
    """Voxel down-sampling (:func:`voxel_downsample`) grown until at most ``max_points`` remain.

    The first voxel is ``0.35 diag / sqrt(max_points)`` (area-like scaling of a surface sample,
    ``m ~ (diag / voxel)^2``; ``diag`` the bounding-box diagonal); while ``m`` voxels are
    occupied, ``m > max_points``, the voxel grows by ``1.15 sqrt(m / max_points)``. The
    intermediate voxels are only counted; the centroids are formed once, at the last voxel.
    ``P`` with at most ``max_points`` points is returned as is, and a copy of ``P`` when its
    bounding box is a single point.
    """
    if P.shape[0] <= max_points:
        return P
    lo, hi = column_bounds(P)
    diag = float(np.linalg.norm(hi - lo))
    D = P - lo
    voxel = diag / np.sqrt(max_points) * 0.35
    m = _n_voxels(D, voxel)
    while m > max_points and voxel > 0:
        voxel *= 1.15 * np.sqrt(m / max_points)
        m = _n_voxels(D, voxel)
    if not voxel > 0:  # all points equal: nothing to merge by a grid
        return P.copy()
    return _centroids(P, _voxel_labels(_voxel_keys(D, voxel)))


def spacing(P: np.ndarray, tree: cKDTree | None = None, *, n_sample: int = 2000) -> float:
    """Median distance to the nearest other point (estimated on a fixed strided subset)."""
    n = P.shape[0]
    if n < 2:
        return 0.0
    tree = tree if tree is not None else cKDTree(P)
    idx = np.arange(0, n, max(1, n // n_sample))
    d, _ = tree.query(P[idx], k=2, workers=workers_for(idx.size))
    s = float(np.median(d[:, 1]))
    if s <= 0:
        pos = d[:, 1][d[:, 1] > 0]
        s = float(np.median(pos)) if pos.size else 0.0
    return s


def knn_normals(
    P: np.ndarray, k: int = 10, tree: cKDTree | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented normals (n, 3) and neighbour indices (n, k) from kNN covariances (Eq. 6.31)."""
    tree = tree if tree is not None else cKDTree(P)
    return knn_normals_at(P, P, k, tree)


def knn_normals_at(
    P: np.ndarray, X: np.ndarray, k: int, tree: cKDTree
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`knn_normals` of the cloud ``P`` at its points ``X``."""
    n = X.shape[0]
    k = int(min(k, P.shape[0]))
    _, idx = tree.query(X, k=k, workers=workers_for(n))
    idx = np.asarray(idx).reshape(n, k)
    Q = P[idx]
    Q = Q - Q.mean(axis=1, keepdims=True)
    C = np.einsum("nki,nkj->nij", Q, Q)
    _, vec = np.linalg.eigh(C)
    N = vec[:, :, 0]
    return N, idx


@dataclass(frozen=True)
class RegistrationResult:
    """Result of :func:`register` and :func:`narrow_phase`.

    Attributes
    ----------
    transformation : (4, 4) float64
        Source-to-target transform.
    fitness, inlier_rmse : float
        Share of down-sampled source points within ``inlier_distance`` of the target; their RMS.
    n_iter, converged : int, bool
        Narrow-phase iterations and whether it met its tolerance (:func:`register`: and the
        pose is pinned down, ``info["reliable"]``).
    inlier_distance : float
    info : dict
        Diagnostics (``gamma``, ``time_s``, ...).
    """

    transformation: np.ndarray = field(repr=False)
    fitness: float
    inlier_rmse: float
    n_iter: int
    converged: bool
    inlier_distance: float = 0.0
    info: dict = field(default_factory=dict, repr=False)
