"""Umbrella-operator smoothing (Taubin 1995, Eq. 2 with uniform weights):
``U(v_i) = mean_{N_i} v_j - v_i = -(D^-1 L v)_i`` for the binary Laplacian ``L = D - C``
(Eq. 4.1). Isolated vertices and components without an interior vertex do not move."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ..graph import adjacency_matrix
from ._table import register


def _umbrella(V: np.ndarray, F: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """``D^-1 C`` and the mask of the vertices that move."""
    n = V.shape[0]
    C = adjacency_matrix(F, n)
    d = np.asarray(C.sum(axis=1)).ravel()
    inv = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)
    move = d > 0
    if F.shape[0]:
        E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        E = E[E[:, 0] != E[:, 1]]
        key, counts = np.unique(E[:, 0] * n + E[:, 1], return_counts=True)
        b = key[counts == 1]
        boundary = np.zeros(n, dtype=bool)
        boundary[b // n] = True
        boundary[b % n] = True
        _, label = connected_components(C, directed=False)
        interior = move & ~boundary
        move &= np.isin(label, label[interior])
    return (sp.diags(inv) @ C).tocsr(), move


def _check_finite_number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidInputError(f"`{name}` must be a number; got {value!r}.")
    if not np.isfinite(value):
        raise InvalidInputError(f"`{name}` must be finite; got {value!r}.")
    return float(value)


@register(
    "laplacian",
    summary="uniform (umbrella) Laplacian smoothing",
    reference="Taubin 1995, Eq. 2 with uniform weights (Vollmer et al. 1999 'umbrella')",
)
def laplacian(V, F, *, lam: float = 0.5, n_iter: int = 5) -> np.ndarray:
    """Uniform Laplacian smoothing ``v_i <- v_i + lam U(v_i)``, ``n_iter`` times (``lam`` in
    (0, 1]); returns the (n, 3) positions."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    lam = _check_finite_number(lam, "lam")
    if not 0 < lam <= 1:
        raise InvalidInputError(f"`lam` must be in (0, 1]; got {lam!r}.")
    check_positive(n_iter, "n_iter", integer=True, allow_zero=True)
    A, has_nb = _umbrella(V, F)
    mask = has_nb[:, None]
    X = V.copy()
    for _ in range(n_iter):
        X = X + lam * (A @ X - X) * mask
    return X


@register(
    "taubin",
    summary="Taubin lambda|mu non-shrinking smoothing",
    reference="Taubin 1995, 'A signal processing approach to fair surface design', SIGGRAPH",
)
def taubin(V, F, *, lam: float = 0.5, mu: float = -0.53, n_iter: int = 10) -> np.ndarray:
    """Taubin's lambda|mu smoothing, ``n_iter`` pairs of ``v += lam U(v)`` (``lam`` in (0, 1]) and
    ``v += mu U(v)`` (``mu < -lam``): a low-pass with pass band ``1/lam + 1/mu``."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    lam = _check_finite_number(lam, "lam")
    mu = _check_finite_number(mu, "mu")
    if not 0 < lam <= 1:
        raise InvalidInputError(f"`lam` must be in (0, 1]; got {lam!r}.")
    if not mu < -lam:
        raise InvalidInputError(f"`mu` must be negative with mu < -lam = {-lam!r}; got {mu!r}.")
    check_positive(n_iter, "n_iter", integer=True, allow_zero=True)
    A, has_nb = _umbrella(V, F)
    mask = has_nb[:, None]
    X = V.copy()
    for _ in range(n_iter):
        X = X + lam * (A @ X - X) * mask
        X = X + mu * (A @ X - X) * mask
    return X


__all__ = ["laplacian", "taubin"]
