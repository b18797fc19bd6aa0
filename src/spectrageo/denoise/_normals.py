"""Building blocks of the face-normal filters (thesis Sections 4.2 and 4.7), shared by
``bnf``, ``gnf`` and TSGSP's fine step. A *patch matrix* ``P`` is a binary (m, m) CSR matrix with
``P[j, l] = 1`` when face ``l`` belongs to the patch centred at face ``j``; the candidate patches
of face ``i`` are the non-zeros of column ``i``. Zero normal rows (degenerate faces) carry no
weight."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ..geometry._numba_kernels import max_sq_distance, vertex_update_kernel
from ..geometry.primitives import _normalize_rows
from ..graph import face_adjacency

#: Patch consistency measures understood by :func:`candidate_scores`.
MEASURES = ("thesis", "zhang2015")


# --------------------------------------------------------------------------- neighbourhoods
def face_neighbors(F, *, shared: str = "vertex", include_self: bool = True) -> sp.csr_matrix:
    """Binary (m, m) CSR matrix of faces sharing a vertex (``shared="vertex"``) or an edge."""
    check_choice(shared, "shared", ("vertex", "edge"))
    A = face_adjacency(F, shared=shared).tocsr()
    if include_self:
        A = (A + sp.identity(A.shape[0], format="csr")).tocsr()
        A.data[:] = 1.0
    A.sort_indices()
    return A


def face_radius_neighbors(
    centroids: np.ndarray,
    radius: float,
    *,
    adjacency: sp.spmatrix | None = None,
    include_self: bool = True,
) -> sp.csr_matrix:
    """Binary (m, m) CSR matrix of faces whose centroids lie within ``radius``; with ``adjacency``,
    only faces reachable through adjacent faces inside the ball."""
    C = np.asarray(centroids, dtype=np.float64)
    check_positive(radius, "radius")
    m = C.shape[0]
    pairs = cKDTree(C).query_pairs(r=float(radius), output_type="ndarray")
    rows = np.r_[pairs[:, 0], pairs[:, 1], np.arange(m)]
    cols = np.r_[pairs[:, 1], pairs[:, 0], np.arange(m)]
    B = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(m, m))
    B.sum_duplicates()
    B.data[:] = 1.0
    if adjacency is not None:
        Adj = sp.csr_matrix(adjacency, dtype=np.float64) + sp.identity(m, format="csr")
        Adj.data[:] = 1.0
        S = sp.identity(m, format="csr")
        for _ in range(m):  # breadth-first growth inside the ball; stops after a few rounds
            grown = (S @ Adj).multiply(B).tocsr()
            grown.data[:] = 1.0
            if grown.nnz == S.nnz:
                break
            S = grown
        B = S
    if not include_self:
        B = B.tolil()
        B.setdiag(0)
        B = B.tocsr()
        B.eliminate_zeros()
    B.sort_indices()
    return B


def edge_face_pairs(F) -> np.ndarray:
    A = sp.triu(face_adjacency(F, shared="edge"), k=1).tocoo()
    order = np.lexsort((A.col, A.row))
    return np.c_[A.row[order], A.col[order]].astype(np.int64)


def mean_centroid_distance(
    V: np.ndarray, F: np.ndarray, *, pairs: np.ndarray | None = None
) -> float:
    """Mean distance between the centroids of edge-adjacent faces (0.0 without any)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    pairs = edge_face_pairs(F) if pairs is None else pairs
    if len(pairs) == 0:
        return 0.0
    C = V[F].mean(axis=1)
    return float(np.linalg.norm(C[pairs[:, 0]] - C[pairs[:, 1]], axis=1).mean())


# --------------------------------------------------------------------------- patches
def patch_matrix(F) -> sp.csr_matrix:
    """Patch matrix of the 1-ring face patches (Section 4.2.1)."""
    return face_neighbors(F, shared="vertex", include_self=True)


def padded_patches(P: sp.csr_matrix) -> np.ndarray:
    """Patch members as an (m, k_max) array, short rows padded with their first member."""
    P = sp.csr_matrix(P)
    counts = np.diff(P.indptr)
    if counts.size and counts.min() == 0:
        raise InvalidInputError("`P` has an empty patch (a row without members).")
    kmax = int(counts.max()) if counts.size else 0
    rows = np.repeat(np.arange(P.shape[0]), counts)
    pos = np.arange(P.indices.size) - np.repeat(P.indptr[:-1], counts)
    first = P.indices[P.indptr[:-1]] if counts.size else np.zeros(0, dtype=np.int64)
    out = np.repeat(first[:, None], kmax, axis=1).astype(np.int64)
    out[rows, pos] = P.indices
    return out


@dataclass(frozen=True)
class PatchSet:
    """Candidate patches with the topology that patch selection reuses."""

    P: sp.csr_matrix
    members: np.ndarray
    faces: np.ndarray
    centers: np.ndarray
    starts: np.ndarray
    edge_pairs: np.ndarray | None = None
    inner_edges: sp.csr_matrix | None = None

    @property
    def n_faces(self) -> int:
        return self.P.shape[0]

    @classmethod
    def from_matrix(cls, P: sp.spmatrix, F=None) -> PatchSet:
        P = sp.csr_matrix(P, dtype=np.float64)
        if P.shape[0] != P.shape[1]:
            raise InvalidInputError(f"`P` must be square (m, m); got {P.shape}.")
        P.sum_duplicates()
        P.data[:] = 1.0
        P.sort_indices()
        PT = P.T.tocsr()
        PT.sort_indices()
        faces = np.repeat(np.arange(PT.shape[0]), np.diff(PT.indptr)).astype(np.int64)
        edge_pairs = inner = None
        if F is not None:
            F = np.asarray(F, dtype=np.int64)
            if F.shape != (P.shape[0], 3):
                raise InvalidInputError(f"`F` must have shape ({P.shape[0]}, 3); got {F.shape}.")
            edge_pairs = edge_face_pairs(F)
            Pc = sp.csc_matrix(P)
            inner = Pc[:, edge_pairs[:, 0]].multiply(Pc[:, edge_pairs[:, 1]]).tocsr()
            inner.eliminate_zeros()
            inner.sort_indices()
        return cls(
            P=P,
            members=padded_patches(P),
            faces=faces,
            centers=PT.indices.astype(np.int64),
            starts=PT.indptr.astype(np.int64),
            edge_pairs=edge_pairs,
            inner_edges=inner,
        )

    @classmethod
    def from_faces(cls, F) -> PatchSet:
        return cls.from_matrix(patch_matrix(F), F)


def _as_patch_set(patches, F=None) -> PatchSet:
    if isinstance(patches, PatchSet):
        return patches
    return PatchSet.from_matrix(patches, F)


def _row_reduce(values: np.ndarray, indptr: np.ndarray, ufunc, empty: float) -> np.ndarray:
    n = indptr.size - 1
    out = np.full(n, empty)
    nonempty = np.diff(indptr) > 0
    if values.size:
        out[nonempty] = ufunc.reduceat(values, indptr[:-1][nonempty])
    return out


def _thesis_patch_term(N: np.ndarray, P: sp.csr_matrix) -> np.ndarray:
    """``a_j = |lambda_j1 - lambda_j2|`` of Eq. (4.9) for every patch."""
    from ..geometry._numba_kernels import sym3_eigenvalues

    i, j = (0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2)  # [xx, yy, zz, xy, xz, yz]
    outer = N[:, i] * N[:, j]
    R = np.asarray(P @ outer)  # R_j = N_j^T N_j (sum of n n^T over the patch), 6 entries
    lam = sym3_eigenvalues(np.ascontiguousarray(R))  # ascending
    return np.abs(lam[:, 0] - lam[:, 1])


@numba.njit(cache=True, parallel=True)
def _max_distance_kernel(N, faces, centers, members):  # pragma: no cover - jitted
    out = np.empty(faces.shape[0])
    for t in numba.prange(faces.shape[0]):
        out[t] = np.sqrt(max_sq_distance(N, faces[t], members, centers[t]))
    return out


@numba.njit(cache=True)
def _patch_diameter_kernel(N, members):  # pragma: no cover - jitted
    m, k = members.shape
    out = np.empty(m)
    for j in range(m):
        best = 0.0
        for p in range(k):
            a = members[j, p]
            for q in range(p + 1, k):
                b = members[j, q]
                d0 = N[a, 0] - N[b, 0]
                d1 = N[a, 1] - N[b, 1]
                d2 = N[a, 2] - N[b, 2]
                d = d0 * d0 + d1 * d1 + d2 * d2
                if d > best:
                    best = d
        out[j] = np.sqrt(best)
    return out


def _max_distance_to_patch(
    N: np.ndarray, rows: np.ndarray, cols: np.ndarray, members: np.ndarray
) -> np.ndarray:
    """``b_ij = max_{l in P_j} ||n_i - n_l||`` (Eq. 4.10) for the pairs ``(rows, cols)``."""
    return _max_distance_kernel(np.ascontiguousarray(N), rows, cols, np.ascontiguousarray(members))


def _zhang_patch_scores(N: np.ndarray, ps: PatchSet) -> np.ndarray:
    """Patch consistency ``Phi(P) R(P)`` of Zhang et al. 2015."""
    phi = _patch_diameter_kernel(np.ascontiguousarray(N), ps.members)
    a, b = ps.edge_pairs[:, 0], ps.edge_pairs[:, 1]
    sal = np.linalg.norm(N[a] - N[b], axis=1)  # edge saliency
    vals = sal[ps.inner_edges.indices]
    ssum = _row_reduce(vals, ps.inner_edges.indptr, np.add, 0.0)
    smax = _row_reduce(vals, ps.inner_edges.indptr, np.maximum, 0.0)
    return phi * smax / (ssum + 1e-9)


def candidate_scores(
    N: np.ndarray, patches, *, measure: str = "thesis", F=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Consistency scores ``(faces, patches, scores)`` of every (face, candidate patch) pair, sorted
    by face, lower is more consistent: Eqs. (4.8)-(4.10) ``a_j b_ij`` (``measure="thesis"``) or
    Zhang et al.'s ``Phi(P) R(P)`` (needs the faces)."""
    check_choice(measure, "measure", MEASURES)
    ps = _as_patch_set(patches, F)
    N = np.asarray(N, dtype=np.float64)
    if N.shape != (ps.n_faces, 3):
        raise InvalidInputError(f"`N` must have shape ({ps.n_faces}, 3); got {N.shape}.")
    if measure == "thesis":
        a = _thesis_patch_term(N, ps.P)
        b = _max_distance_to_patch(N, ps.faces, ps.centers, ps.members)
        scores = a[ps.centers] * b
    else:
        if ps.inner_edges is None:
            raise InvalidInputError('measure="zhang2015" needs the faces: pass `F`.')
        scores = _zhang_patch_scores(N, ps)[ps.centers]
    return ps.faces, ps.centers, scores


def select_patches(N: np.ndarray, patches, *, measure: str = "thesis", F=None) -> np.ndarray:
    """Ideal patch of every face (Eq. 4.8): the centre of its lowest-scoring candidate (ties: the
    lowest centre)."""
    ps = _as_patch_set(patches, F)
    faces, centers, scores = candidate_scores(N, ps, measure=measure)
    best = np.arange(ps.n_faces, dtype=np.int64)
    if scores.size == 0:
        return best
    lo = _row_reduce(scores, ps.starts, np.minimum, np.inf)
    hit = np.flatnonzero(scores == lo[faces])  # centres are sorted within each face
    first = np.r_[True, faces[hit][1:] != faces[hit][:-1]]
    best[faces[hit[first]]] = centers[hit[first]]
    return best


def patch_mean_normals(N: np.ndarray, areas: np.ndarray, P: sp.spmatrix) -> np.ndarray:
    """Area-weighted mean unit normal of every patch (Eq. 4.11)."""
    if isinstance(P, PatchSet):
        P = P.P
    return _normalize_rows(np.asarray(sp.csr_matrix(P) @ (np.asarray(areas)[:, None] * N)))


def guided_normals(
    N: np.ndarray,
    areas: np.ndarray,
    patches,
    *,
    measure: str = "thesis",
    F=None,
    return_patches: bool = False,
):
    """Guided normals (Section 4.2): the mean normal (Eq. 4.11) of each face's ideal patch
    (Eqs. 4.8-4.10); with ``return_patches``, also the chosen centres."""
    ps = _as_patch_set(patches, F)
    best = select_patches(N, ps, measure=measure)
    g = patch_mean_normals(N, areas, ps.P)[best]
    return (g, best) if return_patches else g


# --------------------------------------------------------------------------- filtering
def spatial_weights(
    centroids: np.ndarray, areas: np.ndarray, nbr: sp.csr_matrix, sigma_s: float
) -> sp.csr_matrix:
    """``W[i, j] = A_j exp(-||c_i - c_j||^2 / (2 sigma_s^2))`` on the non-zeros of ``nbr``."""
    check_positive(sigma_s, "sigma_s")
    nbr = sp.csr_matrix(nbr)
    rows = np.repeat(np.arange(nbr.shape[0]), np.diff(nbr.indptr))
    cols = nbr.indices
    d2 = np.sum((centroids[rows] - centroids[cols]) ** 2, axis=1)
    w = np.asarray(areas)[cols] * np.exp(-d2 / (2.0 * sigma_s**2))
    return sp.csr_matrix((w, cols.copy(), nbr.indptr.copy()), shape=nbr.shape)


def joint_bilateral_normals(
    N: np.ndarray, guide: np.ndarray, W: sp.csr_matrix, sigma_r: float
) -> np.ndarray:
    """One (joint) bilateral pass over the normals, weights ``W`` times the range kernel on ``guide``."""
    check_positive(sigma_r, "sigma_r")
    rows = np.repeat(np.arange(W.shape[0]), np.diff(W.indptr))
    cols = W.indices
    d2 = np.sum((guide[rows] - guide[cols]) ** 2, axis=1)
    w = W.data * np.exp(-d2 / (2.0 * sigma_r**2))
    out = np.asarray(sp.csr_matrix((w, cols, W.indptr), shape=W.shape) @ N)
    out = _normalize_rows(out)
    empty = ~out.any(axis=1)
    out[empty] = N[empty]
    return out


# --------------------------------------------------------------------------- vertex update
def fast_update_vertices(V: np.ndarray, F: np.ndarray, N: np.ndarray, n_iter: int) -> np.ndarray:
    """Compiled vertex update of Eqs. (4.28)-(4.29), ``n_iter`` passes (inputs trusted)."""
    V = np.array(V, dtype=np.float64, order="C")
    F = np.ascontiguousarray(F, dtype=np.int64)
    N = _normalize_rows(np.asarray(N, dtype=np.float64))
    active = N.any(axis=1)
    deg = np.bincount(F[active].ravel(), minlength=V.shape[0]).astype(np.float64)
    inv_deg = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    return vertex_update_kernel(V, F, N, inv_deg, int(n_iter))


__all__ = [
    "MEASURES",
    "PatchSet",
    "edge_face_pairs",
    "candidate_scores",
    "face_neighbors",
    "face_radius_neighbors",
    "guided_normals",
    "joint_bilateral_normals",
    "mean_centroid_distance",
    "padded_patches",
    "patch_matrix",
    "patch_mean_normals",
    "select_patches",
    "spatial_weights",
]
