"""Partitioned spectral low-pass filtering (Section 4.1.3, Eq. 4.6; Section 5.2.1, Eq. 5.45).

The graph is split into overlapped equal-sized submeshes, each submesh signal is projected on the
``n_l`` lowest-frequency eigenvectors of its own Laplacian, ``v~[i] = U_nl[i] U_nl[i]^T v[i]``
(Eq. 5.45), and the overlapping copies are merged with the degree weights of Algorithm 8.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, check_choice
from .gft import _n_keep as _n_keep_whole
from .gft import lowpass_whole
from .orthogonal import DOI_EPS_HIGH, DOI_EPS_LOW, submesh_eigenbases
from .partition import as_adjacency, overlapped_submeshes, reassemble

__all__ = ["DEFAULT_KEEP", "lowpass"]

#: default fraction of components kept per submesh: 10 % (the thesis shows the shape is preserved
#: with 90 % of the high frequencies removed, Fig. 5.22, and its OI experiments keep 10 % per
#: submesh of about 700 vertices)
DEFAULT_KEEP = 0.1

METHODS = ("exact", "oi", "doi", "whole")
LAPLACIANS = ("binary", "gaussian", "cotangent", "weighted")


def lowpass(
    V,
    F=None,
    *,
    keep: float | int = DEFAULT_KEEP,
    submesh_size: int = 700,
    overlap: float = 0.15,
    method: str = "oi",
    laplacian: str = "binary",
    C=None,
    points=None,
    delta: float | None = None,
    zeta: int = 4,
    n_iter: int = 1,
    tol: float | None = None,
    eps_low: float = DOI_EPS_LOW,
    eps_high: float = DOI_EPS_HIGH,
    t_max: int = 100,
    weights=None,
    rng=None,
    info: list | None = None,
) -> np.ndarray:
    """Spectral low-pass of a signal on a mesh or graph, processed in overlapped submeshes (Eq. 5.45).

    Parameters
    ----------
    V : (n,) or (n, d) float
        The signal: vertex coordinates (n, 3) for mesh smoothing/compression, or any per-vertex signal.
    F : (m, 3) int, optional
        Triangles. Give ``F`` for a mesh, or ``F=None`` and ``C`` for a point cloud or any graph.
    keep : float in (0, 1] or int
        Components kept per submesh: a fraction of the submesh size, or a count (default 10 %).
        For ``method="whole"`` the fraction refers to the whole graph's ``n``. For ``"doi"`` it is the
        starting subspace size of the first submesh.
    submesh_size, overlap : see :func:`~spectrageo.spectral.partition.overlapped_submeshes`
    method : {"oi", "exact", "doi", "whole"}
        ``"oi"``: subspace tracking with orthogonal iterations (Eq. 4.7, Algorithm 6; ``n_iter``
        iterations of ``T^zeta``); ``"exact"``: dense eigendecomposition of every submesh;
        ``"doi"``: dynamic OI (Algorithm 7), adapting the kept size per submesh to the residual band
        ``[eps_low, eps_high]``; ``"whole"``: no partitioning, the ``keep * n`` lowest eigenvectors of
        the whole Laplacian from SciPy's sparse eigensolver (the reference of Section 4.1.3; costly).
    laplacian : {"binary", "gaussian", "cotangent", "weighted"}
        ``"binary"`` ``L = D - C`` on the connectivity (Eq. 4.1, default, the thesis's choice for
        compression); ``"gaussian"``/``"cotangent"`` weights (Eq. 4.2) need a mesh and coordinates
        (``points``, or ``V`` itself when it has shape (n, 3)); ``"weighted"`` uses the values of ``C``.
    C : sparse (n, n), optional
        Symmetric adjacency (e.g. :func:`spectrageo.graph.knn_graph`), used when ``F`` is None.
    points : (n, 3), optional
        Vertex positions for the Gaussian/cotangent weights when ``V`` is not the coordinates.
    delta, zeta, n_iter, tol : OI parameters, see :func:`~spectrageo.spectral.orthogonal.orthogonal_iteration`
    eps_low, eps_high, t_max : DOI parameters, see
        :func:`~spectrageo.spectral.orthogonal.dynamic_orthogonal_iteration`
    weights : None or "uniform" or "core"
        Reassembly weights (:func:`~spectrageo.spectral.partition.reassemble`); default: Algorithm 8.
    rng : seed for METIS and random starts.
    info : list, optional
        Receives one result object per submesh (see ``submesh_eigenbases``).

    Returns
    -------
    (n,) or (n, d) float64, the low-passed signal.
    """
    check_choice(method, "method", METHODS)
    check_choice(laplacian, "laplacian", LAPLACIANS)
    X = np.asarray(V, dtype=np.float64)
    if X.ndim not in (1, 2) or X.shape[0] == 0:
        raise InvalidInputError(f"`V` must have shape (n,) or (n, d) with n >= 1; got {X.shape}.")
    if not np.isfinite(X).all():
        raise InvalidInputError("`V` contains NaN or inf values.")
    n = X.shape[0]
    W = _adjacency(X, F, C, points, laplacian, n)
    kind = "binary" if laplacian == "binary" else "weighted"

    if method == "whole":
        from ..graph import laplacian_from_adjacency

        Wk = W.copy()
        if kind == "binary":
            Wk.data[:] = 1.0
        _n_keep_whole(keep, n)
        L = laplacian_from_adjacency(Wk)
        out = lowpass_whole(X.reshape(n, -1), L, keep=keep)
        return out.reshape(X.shape)

    # the partition only uses the sparsity pattern (cotangent weights may be negative)
    subs = overlapped_submeshes(abs(W), submesh_size=submesh_size, overlap=overlap, rng=rng)
    Xm = X.reshape(n, -1)
    values = [None] * len(subs.parts)
    for i, _w, U in submesh_eigenbases(
        W,
        subs,
        keep,
        method=method,
        delta=delta,
        zeta=zeta,
        n_iter=n_iter,
        tol=tol,
        signal=Xm if method == "doi" else None,
        eps_low=eps_low,
        eps_high=eps_high,
        t_max=t_max,
        laplacian=kind,
        ritz=False,
        rng=rng,
        info=info,
    ):
        xi = Xm[subs.parts[i]]
        values[i] = U @ (U.T @ xi)
    out = reassemble(values, subs, weights=weights)
    return out.reshape(X.shape)


def _adjacency(X, F, C, points, laplacian: str, n: int) -> sp.csr_matrix:
    if F is None and C is None:
        raise InvalidInputError("give the faces `F` of a mesh, or an adjacency `C` for a graph.")
    if F is not None and C is not None:
        raise InvalidInputError("give either `F` or `C`, not both.")
    if C is not None:
        W = as_adjacency(C)
        if W.shape[0] != n:
            raise InvalidInputError(f"`C` must have shape ({n}, {n}) to match `V`; got {W.shape}.")
        if laplacian in ("gaussian", "cotangent"):
            raise InvalidInputError(
                f"`laplacian`={laplacian!r} needs a mesh `F`; with `C` use 'binary' or 'weighted'."
            )
        return W
    Fa = as_faces(F, n, "F")
    if laplacian == "weighted":
        raise InvalidInputError("`laplacian`='weighted' uses the values of `C`; pass `C`, not `F`.")
    if laplacian == "binary":
        return _binary_adjacency(Fa, n)
    from ..graph import weighted_adjacency

    P = X if points is None else np.asarray(points, dtype=np.float64)
    if P.shape != (n, 3):
        raise InvalidInputError(
            f"`points` must have shape ({n}, 3) for {laplacian!r} weights; got {P.shape}."
        )
    W = weighted_adjacency(P, Fa, kind=laplacian).tocsr()
    W.eliminate_zeros()
    return as_adjacency(W, allow_negative=laplacian == "cotangent")


def _binary_adjacency(F: np.ndarray, n: int) -> sp.csr_matrix:
    """Binary vertex adjacency of a triangle list (Eq. 3.6) without sorting the edge list."""
    i = F.ravel()
    j = F[:, [1, 2, 0]].ravel()
    keep = i != j
    i, j = i[keep], j[keep]
    W = sp.csr_matrix((np.ones(2 * i.size), (np.r_[i, j], np.r_[j, i])), shape=(n, n))
    W.sum_duplicates()
    W.data[:] = 1.0
    return W
