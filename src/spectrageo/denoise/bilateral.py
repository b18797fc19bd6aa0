"""Bilateral denoisers: bilateral mesh denoising of vertices (Fleishman, Drori & Cohen-Or 2003) and
bilateral normal filtering (Zheng, Fu, Au & Tai 2011, local iterative scheme)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice, check_positive
from ..geometry import face_areas, face_centroids, face_normals, update_vertices, vertex_normals
from ..geometry.primitives import mean_edge_length
from ..graph import adjacency_matrix
from ._guard import no_scale_message
from ._normals import (
    face_neighbors,
    joint_bilateral_normals,
    mean_centroid_distance,
    spatial_weights,
)
from ._table import register


def _optional_positive(value, name: str) -> float | None:
    if value is None:
        return None
    return float(check_positive(value, name))


def _ring_pairs(F: np.ndarray, n: int, rings: int) -> tuple[np.ndarray, np.ndarray]:
    C = adjacency_matrix(F, n)
    R = C.copy()
    for _ in range(rings - 1):
        R = R + R @ C
        R.data[:] = 1.0
    R = sp.csr_matrix(R)
    R.setdiag(0)
    R.eliminate_zeros()
    R = R.tocoo()
    return R.row.astype(np.int64), R.col.astype(np.int64)


def _radius_pairs(X: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    pairs = cKDTree(X).query_pairs(r=radius, output_type="ndarray")
    return np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]


@register(
    "bilateral",
    summary="bilateral mesh denoising of vertices along their normals",
    reference="Fleishman, Drori & Cohen-Or 2003, 'Bilateral mesh denoising', SIGGRAPH",
    trusted=True,
)
def bilateral(
    V,
    F,
    *,
    sigma_c: float | None = None,
    sigma_s: float | None = None,
    radius: float | None = None,
    neighborhood: str = "radius",
    rings: int = 2,
    n_iter: int = 3,
) -> np.ndarray:
    """Bilateral mesh denoising (Fleishman et al. 2003): ``n_iter`` simultaneous moves
    ``v <- v + n sum_j w_j h_j / sum_j w_j`` along the vertex normal, ``h_j = <n, q_j - v>``,
    ``w_j = exp(-||v - q_j||^2 / 2 sigma_c^2) exp(-h_j^2 / 2 sigma_s^2)``, over the vertices within
    ``radius`` (default ``2 sigma_c``) or the ``rings``-ring. ``sigma_c`` defaults to the mean edge
    length, ``sigma_s`` to the median local deviation of ``h`` (the paper's rule)."""
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F")
    check_choice(neighborhood, "neighborhood", ("radius", "ring"))
    check_positive(rings, "rings", integer=True)
    check_positive(n_iter, "n_iter", integer=True, allow_zero=True)
    sigma_c = _optional_positive(sigma_c, "sigma_c")
    sigma_s = _optional_positive(sigma_s, "sigma_s")
    radius = _optional_positive(radius, "radius")
    if sigma_c is None:
        sigma_c = mean_edge_length(V, F)
        if not sigma_c > 0:
            raise InvalidInputError("`V` has only zero-length edges; pass `sigma_c` explicitly.")
    if radius is None:
        radius = 2.0 * sigma_c
    ring = _ring_pairs(F, n, rings) if neighborhood == "ring" else None
    X = V.copy()
    for _ in range(n_iter):
        Nv = vertex_normals(X, F, weighting="area")
        i, j = ring if ring is not None else _radius_pairs(X, radius)
        D = X[j] - X[i]
        t2 = np.einsum("ij,ij->i", D, D)
        h = np.einsum("ij,ij->i", Nv[i], D)
        if sigma_s is None:
            cnt = np.bincount(i, minlength=n)
            s1 = np.bincount(i, weights=h, minlength=n)
            s2 = np.bincount(i, weights=h * h, minlength=n)
            ok = cnt >= 2
            var = s2[ok] / cnt[ok] - (s1[ok] / cnt[ok]) ** 2
            sd = np.sqrt(np.maximum(var, 0.0))
            sigma_s = float(np.median(sd)) if sd.size else 0.0
            if not sigma_s > 0:
                return X  # no offsets at all: the surface is already flat everywhere
        w = np.exp(-t2 / (2.0 * sigma_c**2) - h * h / (2.0 * sigma_s**2))
        num = np.bincount(i, weights=w * h, minlength=n)
        den = np.bincount(i, weights=w, minlength=n)
        step = np.divide(num, den, out=np.zeros(n), where=den > 0)
        X = X + Nv * step[:, None]
    return X


@register(
    "bnf",
    summary="bilateral normal filtering (local iterative scheme) + vertex update",
    reference="Zheng, Fu, Au & Tai 2011, 'Bilateral normal filtering for mesh denoising', IEEE TVCG",
    trusted=True,
)
def bnf(
    V,
    F,
    *,
    sigma_s: float | None = None,
    sigma_r: float = 0.35,
    n_iter: int = 20,
    vertex_iter: int = 10,
    shared: str = "vertex",
) -> np.ndarray:
    """Bilateral normal filtering, local iterative scheme (Zheng et al. 2011): ``n_iter`` passes of
    ``n_i <- normalize(sum_j A_j W_s(||c_i - c_j||) W_r(||n_i - n_j||) n_j)`` over the faces sharing a
    vertex (or an edge, ``shared``), then ``vertex_iter`` vertex updates (Eqs. 4.28-4.29). ``sigma_s``
    defaults to the mean adjacent-centroid distance."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_choice(shared, "shared", ("vertex", "edge"))
    sigma_s = _optional_positive(sigma_s, "sigma_s")
    check_positive(sigma_r, "sigma_r")
    check_positive(n_iter, "n_iter", integer=True, allow_zero=True)
    check_positive(vertex_iter, "vertex_iter", integer=True, allow_zero=True)
    if sigma_s is None:
        sigma_s = mean_centroid_distance(V, F)
        if not sigma_s > 0:
            raise InvalidInputError(
                no_scale_message("the bilateral normal filter", "passing `sigma_s`")
            )
    N = face_normals(V, F)
    W = spatial_weights(
        face_centroids(V, F), face_areas(V, F), face_neighbors(F, shared=shared), sigma_s
    )
    for _ in range(n_iter):
        N = joint_bilateral_normals(N, N, W, sigma_r)
    return update_vertices(V, F, N, n_iter=vertex_iter)


__all__ = ["bilateral", "bnf"]
