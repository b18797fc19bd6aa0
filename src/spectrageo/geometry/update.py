"""Vertex positions from target face normals (Section 4.7, Eq. 4.28-4.29)."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ._numba_kernels import vertex_update_kernel


def update_vertices(V, F, target_normals, *, n_iter: int = 20, fixed=None) -> np.ndarray:
    """Move vertices so that faces become orthogonal to ``target_normals`` (Eq. 4.28-4.29).

    Each of ``n_iter`` iterations applies ``v_i <- v_i + (1 / |Psi_i|) sum_j n_j <n_j, c_j - v_i>``
    over the incident faces and recomputes the centroids ``c_j``, a gradient step on
    ``sum_j sum_{i in f_j} <n_j, c_j - v_i>^2``.

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int
    target_normals : (m, 3) float
        Re-normalised; zero rows leave their face inactive.
    n_iter, fixed : int, (n,) bool, optional
        Iterations (GNF uses 10-20) and vertices that must not move.

    Returns
    -------
    (n, 3) float64
    """
    V = as_points(V, "V", copy=True)
    n = V.shape[0]
    F = as_faces(F, n, "F")
    N = np.asarray(target_normals, dtype=np.float64)
    if N.shape != F.shape:
        raise InvalidInputError(f"`target_normals` must have shape {F.shape}; got {N.shape}.")
    if not np.isfinite(N).all():
        raise InvalidInputError("`target_normals` contains NaN or inf values.")
    check_positive(n_iter, "n_iter", integer=True, allow_zero=True)
    norm = np.linalg.norm(N, axis=1, keepdims=True)
    N = np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)
    active = norm.ravel() > 0
    deg = np.bincount(F[active].ravel(), minlength=n).astype(np.float64)
    inv_deg = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    if fixed is not None:
        fixed = np.asarray(fixed, dtype=bool)
        if fixed.shape != (n,):
            raise InvalidInputError(f"`fixed` must have shape ({n},); got {fixed.shape}.")
        inv_deg[fixed] = 0.0
    V = vertex_update_kernel(V, F, N, inv_deg, int(n_iter))
    return V
