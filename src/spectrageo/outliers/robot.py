"""Outlier removal and consolidation of depth-camera clouds (thesis Section 5.4.2): RPCA removal,
``k = 7`` connectivity and bilateral filtering along the normals (Eq. 5.100-5.101).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_points, check_choice, check_positive
from ..geometry import Mesh, PointCloud
from . import _kernels as _k
from ._common import check_k, knn_chunked
from .static import remove_outliers

__all__ = ["RobotResult", "bilateral_point_filter", "knn_triangles", "robot_pipeline"]


def knn_triangles(P: Any, k: int = 7) -> np.ndarray:
    """Triangles of the kNN graph: every 3-clique ``(i, j, l)`` of the symmetrised kNN graph.

    Section 5.4.2 connects each point with its ``k = 7`` nearest neighbours and makes a face of
    every three mutually connected vertices (overlapping faces: a connectivity, not a manifold).

    Returns
    -------
    (m, 3) int64 ndarray
        Faces ``i < j < l``, lexicographically sorted.
    """
    X = as_points(P, "P")
    k = check_k(k, X.shape[0])
    idx = knn_chunked(X, k).idx.astype(np.int64)
    n = X.shape[0]
    rows = np.repeat(np.arange(n), k)
    C = sp.csr_matrix((np.ones(rows.size, dtype=np.int8), (rows, idx.ravel())), shape=(n, n))
    C = ((C + C.T) > 0).astype(np.int8).tocsr()
    U = sp.triu(C, k=1).tocsr()  # edges i < j, rows sorted
    U.sort_indices()
    ei = np.repeat(np.arange(n, dtype=np.int64), np.diff(U.indptr))
    ej = U.indices.astype(np.int64)
    # candidates (i, j, l): edge (i, j), then every edge (j, l); a triangle when (i, l) is an edge
    deg = np.diff(U.indptr)[ej]
    ci = np.repeat(ei, deg)
    cj = np.repeat(ej, deg)
    starts = np.repeat(U.indptr[ej], deg)
    offs = np.arange(ci.size) - np.repeat(np.cumsum(deg) - deg, deg)
    cl = U.indices[starts + offs].astype(np.int64)
    codes = ei * n + ej  # sorted (CSR order)
    q = ci * n + cl
    pos = np.searchsorted(codes, q)
    pos[pos >= codes.size] = 0
    hit = codes[pos] == q
    F = np.column_stack([ci[hit], cj[hit], cl[hit]])
    return F[np.lexsort((F[:, 2], F[:, 1], F[:, 0]))]


def bilateral_point_filter(
    P: Any,
    k: int = 7,
    *,
    normals: Any = None,
    sigma1: float | None = None,
    sigma2: float | None = None,
    n_iter: int = 1,
) -> np.ndarray:
    """Bilateral filtering of points along their normals (Eq. 5.100-5.101).

    For every point with kNN cell ``Psi^k``: ``w_i = sum_j W1 W2 h_ij / sum_j W1 W2``,
    ``h_ij = <n_i, v_j - v_i>``, ``W1 = exp(-||v_i - v_j||^2 / (2 sigma1^2))``,
    ``W2 = exp(-h_ij^2 / (2 sigma2^2))``, then ``v_i <- v_i + w_i n_i``; ``n_i`` is the mean PCA
    normal over the cell. The sign of ``h_ij`` follows Fleishman et al. (towards the tangent plane;
    Eq. 5.100 prints the opposite).

    Parameters
    ----------
    P : (n, 3) array_like
    k : int
        Neighbours per cell.
    normals : (n, 3) array_like, optional
        Point normals; default PCA normals over the same ``k`` neighbours.
    sigma1, sigma2 : float, optional
        Spatial width (default the mean kNN distance) and range width (default per point, the
        standard deviation of ``h_ij`` over its cell).
    n_iter : int
        Filter passes (neighbourhoods recomputed each pass).

    Returns
    -------
    (n, 3) ndarray
    """
    X = as_points(P, "P").copy()
    k = check_k(k, X.shape[0])
    check_positive(n_iter, "n_iter", integer=True)
    if sigma1 is not None:
        check_positive(sigma1, "sigma1")
    if sigma2 is not None:
        check_positive(sigma2, "sigma2")
    N0 = None
    if normals is not None:
        N0 = np.asarray(normals, dtype=np.float64)
        if N0.shape != X.shape or not np.isfinite(N0).all():
            raise InvalidInputError(
                f"`normals` must be a finite array of shape {X.shape}; got {N0.shape}."
            )
    from ..geometry import pca_normals

    for _ in range(int(n_iter)):
        nb = knn_chunked(X, k)
        idx = nb.idx.astype(np.int64)
        N = pca_normals(X, k, orient="none") if N0 is None else N0
        # sign-consistent mean over the cell (align neighbours with n_i first)
        Nn = N[idx]
        sgn = np.sign(np.einsum("nkc,nc->nk", Nn, N))
        sgn[sgn == 0] = 1.0
        Nm = N + np.einsum("nk,nkc->nc", sgn, Nn)
        Nm /= np.maximum(np.linalg.norm(Nm, axis=1, keepdims=True), 1e-300)
        s1 = float(nb.dmean.mean()) if sigma1 is None else float(sigma1)
        if s1 <= 0:
            break  # all points coincide
        if sigma2 is None:
            H = np.einsum("nkc,nc->nk", X[idx] - X[:, None, :], Nm)
            s2 = H.std(axis=1)
        else:
            s2 = np.full(X.shape[0], float(sigma2))
        w = np.empty(X.shape[0])
        _k.bilateral_offsets(X, Nm, idx, s1, s2, w)
        X = X + w[:, None] * Nm
    return X


@dataclass(frozen=True)
class RobotResult:
    """Result of :func:`robot_pipeline`: ``keep`` (n,) and ``scores`` (n,) of the RPCA step (input
    order), ``points`` the filtered kept points, ``mesh`` their kNN triangulation (``output="mesh"``).
    """

    keep: np.ndarray = field(repr=False)
    scores: np.ndarray = field(repr=False)
    points: PointCloud | None = field(repr=False)
    mesh: Mesh | None = field(default=None, repr=False)
    threshold: float = 0.0


def robot_pipeline(
    cloud: Any,
    *,
    k: int = 7,
    threshold: float | None = None,
    rpca_k: int = 10,
    sigma1: float | None = None,
    sigma2: float | None = None,
    n_iter: int = 1,
    output: str = "cloud",
) -> RobotResult:
    """RPCA outlier removal, kNN connectivity and bilateral filtering (Section 5.4.2).

    1. :func:`remove_outliers` with ``method="rpca"``, ``k=rpca_k`` and ``threshold``.
    2. Connectivity of the kept points from their ``k = 7`` nearest neighbours.
    3. :func:`bilateral_point_filter` (Eq. 5.100-5.101) over those cells.
    4. ``output="mesh"``: faces from the 3-cliques of the kNN graph (:func:`knn_triangles`).

    Returns
    -------
    RobotResult
    """
    check_choice(output, "output", ("cloud", "mesh"))
    r = remove_outliers(cloud, method="rpca", k=rpca_k, threshold=threshold)
    kept = r.points
    if kept is None or kept.n_points < k + 1:
        raise InvalidInputError(
            f"only {int(r.keep.sum())} points are left after outlier removal; the filter needs "
            f"at least k + 1 = {k + 1}."
        )
    Y = bilateral_point_filter(kept.points, k, sigma1=sigma1, sigma2=sigma2, n_iter=n_iter)
    pts = PointCloud(Y, kept.normals, kept.colors, dict(kept.attributes))
    mesh = None
    if output == "mesh":
        F = knn_triangles(Y, k)
        mesh = Mesh(Y, F)
    return RobotResult(keep=r.keep, scores=r.scores, points=pts, mesh=mesh, threshold=r.threshold)
