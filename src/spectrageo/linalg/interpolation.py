"""Least-squares Laplacian interpolation of values given on a subset of vertices (Section 4.6)."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._errors import InvalidInputError
from ._common import spd_factor

__all__ = ["laplacian_interpolation"]


def laplacian_interpolation(
    L: Any,
    known_idx: Any,
    known_values: Any,
    *,
    weights: Any = None,
) -> np.ndarray:
    """Fill unknown per-vertex values by minimising the Laplacian energy ``||L B||`` (Eq. 4.24-4.27).

    ``B_u`` solves ``[L_12; L_22] B_u = -[L_11; L_21] B_k`` (Eq. 4.26-4.27) through its sparse
    normal equations, one SuperLU factorisation for all columns. Row ``weights`` give
    ``min ||W^{1/2} L B||``; zero weight on the known rows is harmonic interpolation.

    Parameters
    ----------
    L : (n, n) sparse or array_like
        A Laplacian, e.g. ``L = D - C`` or ``L_w`` of Eq. 5.63/5.95.
    known_idx, known_values : (n_k,) int, (n_k,) or (n_k, d)
        Distinct known vertices and their values, kept exactly in the (n,) or (n, d) result.
    weights : (n,) array_like, optional
        Non-negative weights of the rows of ``L``.

    Raises
    ------
    InvalidInputError
        Bad shapes or indices, NaN, negative weights, or a component without a known vertex.
    """
    if sp.issparse(L):
        Ls = sp.csr_matrix(L, dtype=np.float64)
        data = Ls.data
    else:
        arr = np.asarray(L, dtype=np.float64)
        if arr.ndim != 2:
            raise InvalidInputError(f"`L` must be a square (n, n) matrix; got shape {arr.shape}.")
        Ls = sp.csr_matrix(arr)
        data = arr
    if Ls.shape[0] != Ls.shape[1] or Ls.shape[0] == 0:
        raise InvalidInputError(f"`L` must be a square (n, n) matrix; got shape {Ls.shape}.")
    if not np.isfinite(data).all():
        raise InvalidInputError("`L` contains NaN or inf values.")
    n = Ls.shape[0]

    idx = np.asarray(known_idx)
    if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
        raise InvalidInputError(
            f"`known_idx` must be a 1-D array of integer indices; got shape {idx.shape}, dtype {idx.dtype}."
        )
    idx = idx.astype(np.int64)
    if idx.size == 0:
        raise InvalidInputError("`known_idx` is empty; at least one known vertex is required.")
    if idx.min() < 0 or idx.max() >= n:
        raise InvalidInputError(
            f"`known_idx` has indices out of range: expected 0..{n - 1}; got {idx.min()}..{idx.max()}."
        )
    if np.unique(idx).size != idx.size:
        raise InvalidInputError("`known_idx` contains repeated indices.")

    vals = np.asarray(known_values, dtype=np.float64)
    vector = vals.ndim == 1
    Bk = vals[:, None] if vector else vals
    if Bk.ndim != 2 or Bk.shape[0] != idx.size:
        raise InvalidInputError(
            f"`known_values` must have shape ({idx.size},) or ({idx.size}, d); got {vals.shape}."
        )
    if not np.isfinite(Bk).all():
        raise InvalidInputError("`known_values` contains NaN or inf values.")

    if weights is None:
        w = None
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise InvalidInputError(f"`weights` must have shape ({n},); got {w.shape}.")
        if not np.isfinite(w).all() or (w < 0).any():
            raise InvalidInputError("`weights` must be finite and non-negative.")

    out = np.empty((n, Bk.shape[1]))
    known = np.zeros(n, dtype=bool)
    known[idx] = True
    unknown = np.flatnonzero(~known)
    out[idx] = Bk
    if unknown.size == 0:
        return out[:, 0] if vector else out

    Lw = Ls if w is None else sp.diags(w) @ Ls
    _check_determined(Lw, known)
    Lc = sp.csc_matrix(Ls)
    R = Lc[:, unknown]
    Q = Lc[:, idx]
    Rt_w = R.T if w is None else R.T @ sp.diags(w)
    K = sp.csc_matrix(Rt_w @ R)
    rhs = -(Rt_w @ (Q @ Bk))
    try:
        lu = spd_factor(K)
    except RuntimeError as exc:  # exactly singular
        raise InvalidInputError(
            "the interpolation system is singular: some unknown values are not determined by `L`."
        ) from exc
    Bu = lu.solve(np.asarray(rhs))
    if not np.isfinite(Bu).all():
        raise InvalidInputError(
            "the interpolation system is singular: some unknown values are not determined by `L`."
        )
    out[unknown] = Bu
    out[idx] = Bk  # exactly the input
    return out[:, 0] if vector else out


def _check_determined(Lw: sp.csr_matrix, known: np.ndarray) -> None:
    """Every connected component (graph of the non-zeros of ``Lw``) must hold a known vertex."""
    pattern = abs(Lw) + abs(Lw).T
    n_comp, labels = connected_components(pattern, directed=False)
    if n_comp == 1:
        return
    has_known = np.zeros(n_comp, dtype=bool)
    has_known[labels[known]] = True
    if not has_known.all():
        bad = np.flatnonzero(~has_known)
        first = int(np.flatnonzero(labels == bad[0])[0])
        raise InvalidInputError(
            f"{bad.size} connected component(s) of `L` contain no known vertex (e.g. vertex "
            f"{first}); their values are undetermined."
        )
