"""Partitioned spectral low-pass filtering (Section 4.1.3, Eq. 4.6; Section 5.2.1, Eq. 5.45)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, check_choice, options_with_legacy
from ..graph import laplacian_from_adjacency, weighted_adjacency
from .gft import _n_keep as _n_keep_whole
from .gft import lowpass_whole
from .orthogonal import (
    DOI_EPS_HIGH,
    DOI_EPS_LOW,
    SubmeshOptions,
    _check_iteration,
    _submesh_stream,
)
from .partition import as_adjacency, overlapped_submeshes, reassemble

__all__ = ["DEFAULT_KEEP", "LowpassOptions", "LowpassResult", "lowpass"]

#: default fraction of components kept per submesh: the thesis keeps 10 % per submesh of about 700
#: vertices and shows the shape is preserved with 90 % of the high frequencies removed (Fig. 5.22)
DEFAULT_KEEP = 0.1

METHODS = ("exact", "oi", "doi", "whole")
LAPLACIANS = ("binary", "gaussian", "cotangent", "weighted")


@dataclass(frozen=True)
class LowpassOptions:
    """Options of :func:`lowpass`: ``submesh_size``, ``overlap`` (:func:`overlapped_submeshes`),
    the OI / DOI fields of :class:`SubmeshOptions`, reassembly ``weights`` (:func:`reassemble`), and
    ``diagnostics``, which records one result per submesh (runs the Rayleigh-Ritz step).
    """

    submesh_size: int = 700
    overlap: float = 0.15
    delta: float | None = None
    zeta: int = 4
    n_iter: int = 1
    tol: float | None = None
    eps_low: float = DOI_EPS_LOW
    eps_high: float = DOI_EPS_HIGH
    t_max: int = 100
    weights: Any = None
    diagnostics: bool = False

    def __post_init__(self) -> None:
        _check_iteration(self)


@dataclass(frozen=True, eq=False)
class LowpassResult:
    """The low-passed ``signal`` (shaped like the input) and, with ``diagnostics``, one
    :class:`OIResult` / :class:`DOIResult` per submesh in ``submeshes``.
    """

    signal: np.ndarray
    submeshes: tuple = ()


def lowpass(
    V,
    F=None,
    *,
    keep: float | int = DEFAULT_KEEP,
    method: str = "oi",
    laplacian: str = "binary",
    C=None,
    points=None,
    options: LowpassOptions | None = None,
    rng=None,
    **legacy,
) -> LowpassResult:
    """Spectral low-pass of a signal on a mesh or graph in overlapped submeshes (Eq. 5.45).

    Each submesh signal is projected on the lowest eigenvectors of its own Laplacian,
    ``v~[i] = U_nl[i] U_nl[i]^T v[i]``, and the copies are merged with the weights of Algorithm 8.

    Parameters
    ----------
    V, F : (n,) or (n, d) float, (m, 3) int or None
        The signal, and the triangles of a mesh (or None with an adjacency ``C``).
    keep : float in (0, 1] or int
        Components kept per submesh (of ``n`` for ``"whole"``; the start size for ``"doi"``).
    method : {"oi", "exact", "doi", "whole"}
        Algorithm 6, dense per submesh, Algorithm 7, or the unpartitioned Laplacian (costly).
    laplacian, C, points
        Weights of ``L = D - C`` (Eq. 4.1-4.2: ``"binary"``, ``"gaussian"`` and ``"cotangent"``
        with positions ``points`` or ``V``, or ``"weighted"``: the values of the adjacency ``C``).
    options, rng
        :class:`LowpassOptions` (old keywords and ``info=list`` warn); METIS and start seed.

    Returns
    -------
    LowpassResult
    """
    info = legacy.pop("info", None)
    if info is not None:
        warnings.warn(
            "lowpass(): `info` is deprecated; use options=LowpassOptions(diagnostics=True) and "
            "LowpassResult.submeshes.",
            DeprecationWarning,
            stacklevel=2,
        )
        if not isinstance(info, list):
            raise InvalidInputError(f"`info` must be a list or None; got {type(info).__name__}.")
    o = options_with_legacy(options, legacy, LowpassOptions, "lowpass")
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
        Wk = W.copy()
        if kind == "binary":
            Wk.data[:] = 1.0
        _n_keep_whole(keep, n)
        L = laplacian_from_adjacency(Wk)
        out = lowpass_whole(X.reshape(n, -1), L, keep=keep)
        return LowpassResult(out.reshape(X.shape))

    # the partition only uses the sparsity pattern (cotangent weights may be negative)
    subs = overlapped_submeshes(abs(W), submesh_size=o.submesh_size, overlap=o.overlap, rng=rng)
    Xm = X.reshape(n, -1)
    values = [None] * len(subs.parts)
    record = info if info is not None else ([] if o.diagnostics else None)
    sub_opts = SubmeshOptions(
        delta=o.delta,
        zeta=o.zeta,
        n_iter=o.n_iter,
        tol=o.tol,
        eps_low=o.eps_low,
        eps_high=o.eps_high,
        t_max=o.t_max,
        ritz=False,
    )
    signal = Xm if method == "doi" else None
    for i, _w, U in _submesh_stream(W, subs, keep, method, kind, signal, sub_opts, rng, record, {}):
        xi = Xm[subs.parts[i]]
        values[i] = U @ (U.T @ xi)
    out = reassemble(values, subs, weights=o.weights)
    return LowpassResult(out.reshape(X.shape), tuple(record) if record is not None else ())


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
