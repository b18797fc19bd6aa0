"""Point-cloud normals by local PCA (Eq. 6.31) with consistent orientation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from .._validation import as_points, check_choice, check_positive, deprecated_flag
from .neighbors import knn

_CHUNK = 200_000


@dataclass(frozen=True, eq=False)
class PCANormals:
    """Result of :func:`pca_normals_eigen`: ``normals`` (n, 3) and ascending ``eigenvalues`` (n, 3)."""

    normals: np.ndarray
    eigenvalues: np.ndarray


def pca_normals(
    P, k: int = 10, *, orient: str = "mst", viewpoint=None, return_eigenvalues: bool | None = None
):
    """Unit normals (n, 3) of a point cloud from each point's kNN covariance (Eq. 6.31).

    The matrix ``(1/|Psi_i|) sum (v - v_i)(v - v_i)^T`` over the ``k`` neighbours and ``v_i``
    (centred on ``v_i`` as in Eq. 6.31) gives the normal as its smallest eigenvector. ``orient``:
    ``"mst"`` propagates signs along a minimum spanning tree weighted by ``1 - |n_i . n_j|``
    (Hoppe et al.), each component's highest point facing +z; ``"viewpoint"`` faces ``viewpoint``
    (default far above the bounding box); ``"centroid"`` points away from the centroid; ``"none"``
    keeps the largest-magnitude entry positive. ``return_eigenvalues`` is deprecated: use
    :func:`pca_normals_eigen`.
    """
    if return_eigenvalues is not None:
        deprecated_flag("pca_normals", "return_eigenvalues", "pca_normals_eigen() (a PCANormals)")
    r = pca_normals_eigen(P, k, orient=orient, viewpoint=viewpoint)
    return (r.normals, r.eigenvalues) if return_eigenvalues else r.normals


def pca_normals_eigen(P, k: int = 10, *, orient: str = "mst", viewpoint=None) -> PCANormals:
    """:func:`pca_normals` with the ascending covariance eigenvalues (n, 3); returns a :class:`PCANormals`."""
    P = as_points(P, "P")
    check_positive(k, "k", integer=True)
    check_choice(orient, "orient", ("mst", "viewpoint", "centroid", "none"))
    n = P.shape[0]
    k_eff = min(k, n - 1)
    normals = np.empty((n, 3))
    evals = np.empty((n, 3))
    if k_eff < 2:
        normals[:] = [0.0, 0.0, 1.0]
        evals[:] = 0.0
        idx = None
    else:
        idx, _ = knn(P, k_eff)
        for s in range(0, n, _CHUNK):
            sl = slice(s, s + _CHUNK)
            D = P[idx[sl]] - P[sl, None, :]
            cov = np.einsum("nki,nkj->nij", D, D) / (k_eff + 1)
            w, U = np.linalg.eigh(cov)
            normals[sl] = U[:, :, 0]
            evals[sl] = w
        big = np.argmax(np.abs(normals), axis=1)
        normals *= np.sign(normals[np.arange(n), big])[:, None]
    if orient == "centroid":
        out = P - P.mean(axis=0)
        normals *= np.where(np.einsum("ij,ij->i", normals, out) < 0, -1.0, 1.0)[:, None]
    elif orient == "viewpoint":
        if viewpoint is None:
            lo, hi = P.min(axis=0), P.max(axis=0)
            viewpoint = 0.5 * (lo + hi) + np.array([0.0, 0.0, 10.0 * float(np.max(hi - lo)) + 1.0])
        vp = np.asarray(viewpoint, dtype=np.float64).reshape(3)
        normals *= np.where(np.einsum("ij,ij->i", normals, vp - P) < 0, -1.0, 1.0)[:, None]
    elif orient == "mst" and idx is not None:
        normals = _orient_mst(P, normals, idx)
    return PCANormals(normals, evals)


def _orient_mst(P: np.ndarray, N: np.ndarray, idx: np.ndarray) -> np.ndarray:
    n, k = idx.shape
    rows = np.repeat(np.arange(n), k)
    cols = idx.ravel()
    w = 1.0 - np.abs(np.einsum("ij,ij->i", N[rows], N[cols])) + 1e-9
    G = sp.csr_matrix((w, (rows, cols)), shape=(n, n))
    G = G.maximum(G.T)
    T = minimum_spanning_tree(G)
    T = T.maximum(T.T).tocsr()
    ncomp, labels = connected_components(T, directed=False)
    out = N.copy()
    for c in range(ncomp):
        members = np.flatnonzero(labels == c)
        root = members[np.argmax(P[members, 2])]
        if out[root, 2] < 0:
            out[root] *= -1
        order, pred = breadth_first_order(T, root, directed=False, return_predecessors=True)
        # process in BFS order: a node's parent is always final before the node itself
        child = order[1:]
        par = pred[child]
        _propagate(out, child, par)
    return out


def _propagate(N: np.ndarray, child: np.ndarray, par: np.ndarray) -> None:
    from ._numba_kernels import propagate_signs

    propagate_signs(N, child, par)
