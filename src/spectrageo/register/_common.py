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


def bbox_diagonal(P: np.ndarray) -> float:
    return float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))


def voxel_downsample(P: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, label)``: centroids of the occupied voxels by key and each point's voxel row."""
    if voxel <= 0 or P.shape[0] == 0:
        return P.copy(), np.arange(P.shape[0])
    key = np.floor((P - P.min(axis=0)) / voxel).astype(np.int64)
    span = key.max(axis=0) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) < 2.0**62:
        # mixed-radix code: same (lexicographic) order as unique rows, 1-D sort is much faster
        code = (key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2]
        _, label = np.unique(code, return_inverse=True)
    else:
        _, label = np.unique(key, axis=0, return_inverse=True)
    label = label.ravel()
    m = int(label.max()) + 1
    cnt = np.bincount(label, minlength=m).astype(np.float64)
    Q = np.empty((m, 3))
    for j in range(3):
        Q[:, j] = np.bincount(label, weights=P[:, j], minlength=m) / cnt
    return Q, label


def thin(P: np.ndarray, limit: int) -> np.ndarray:
    """At most ``limit`` points of ``P``: a fixed-seed random subset in the original order."""
    if P.shape[0] <= limit:
        return P
    keep = np.random.default_rng(0).choice(P.shape[0], size=int(limit), replace=False)
    return P[np.sort(keep)]


def downsample_to(P: np.ndarray, max_points: int) -> np.ndarray:
    """Voxel down-sampling grown until at most ``max_points`` remain."""
    if P.shape[0] <= max_points:
        return P
    diag = bbox_diagonal(P)
    # area-like scaling of a surface sample: m ~ (diag / voxel)^2
    voxel = diag / np.sqrt(max_points) * 0.35
    Q, _ = voxel_downsample(P, voxel)
    while Q.shape[0] > max_points:
        voxel *= 1.15 * np.sqrt(Q.shape[0] / max_points)
        Q, _ = voxel_downsample(P, voxel)
    return Q


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
