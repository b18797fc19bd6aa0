"""Spectral saliency of faces and vertices (Section 6.1.1, Eq. 6.1-6.4; Section 6.1.2, Eq. 6.10-6.11).

For every face ``f_i`` the normals of its patch ``P_i`` (the face and its ``k`` nearest faces by
centroid distance) are stacked into ``M_i`` (3, k + 1) (Eq. 6.10) and ``R_i = M_i M_i^T`` (Eq. 6.11,
the covariance of Section 4.4) is decomposed, ``R_i U_i = U_i Lambda_i`` (Eq. 6.1-6.2). The saliency
is the inverse 2-norm of the eigenvalues (Eq. 6.3),

    s_i = 1 / sqrt(lambda_i1^2 + lambda_i2^2 + lambda_i3^2),

and is min-max normalised to [0, 1] (Eq. 6.4). Since the normals are unit, ``trace R_i = k + 1`` and
``s_i`` lies between ``1 / (k + 1)`` (flat patch, one eigenvalue) and ``sqrt(3) / (k + 1)`` (corner,
three equal eigenvalues); the measure depends only on the normals, so it is invariant to rotation,
translation and uniform scaling of the mesh.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_choice
from ..geometry.features import patch_eigenvalues
from ._common import PER, check_k, check_mesh, face_patches, face_to_vertex, mesh_normals, minmax


def spectral_face_values(normals: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Raw spectral saliency ``s_i = 1 / ||lambda_i||_2`` of every patch (Eq. 6.1-6.3), shape (m,).

    Parameters
    ----------
    normals : (m, 3) float
        Unit face normals (zero rows of degenerate faces carry no weight).
    patches : (q, k + 1) int
        Patch member indices, one row per analysed face (see :func:`face_patches`).

    Returns
    -------
    (q,) float64, not normalised. A patch whose normals are all zero gets the largest finite value
    of the others (no inf in the output).
    """
    patches = np.asarray(patches, dtype=np.int64)
    ev = patch_eigenvalues(normals, patches) * patches.shape[1]  # eigenvalues of R_i = M_i M_i^T
    nrm = np.linalg.norm(ev, axis=1)
    s = np.divide(1.0, nrm, out=np.full_like(nrm, np.nan), where=nrm > 0)
    bad = ~np.isfinite(s)
    if bad.any():
        s[bad] = np.max(s[~bad]) if (~bad).any() else 0.0
    return s


def spectral_saliency(
    V, F, *, k: int = 25, per: str = "vertex", normals="guided", patches=None
) -> np.ndarray:
    """Normalised spectral saliency of a mesh (Eq. 6.1-6.4), per vertex or per face.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    k : int
        Neighbours per patch besides the face itself (Eq. 6.8 has ``k + 1`` columns; thesis default
        25, useful range 15-35).
    per : {"vertex", "face"}
        Per-face values (Eq. 6.4) or their first-ring mean at each vertex (Eq. 6.14).
    normals : {"guided", "face"} or (m, 3) array
        Normals analysed: guided normals (Section 6.1.2, robust to scanning noise), plain face
        normals, or given ones.
    patches : (m, k + 1) int, optional
        Precomputed patches (:func:`spectrageo.saliency.face_patches`); ``k`` is then ignored.

    Returns
    -------
    (n,) or (m,) float64 in [0, 1]; high on corners and edges, 0 on flat areas.
    """
    check_choice(per, "per", PER)
    V, F = check_mesh(V, F)
    N = mesh_normals(V, F, normals)
    if patches is None:
        k = check_k(k, F.shape[0])
        patches = face_patches(V[F].mean(axis=1), k)
    s = minmax(spectral_face_values(N, patches))
    return s if per == "face" else face_to_vertex(s, F, V.shape[0])


__all__ = ["spectral_face_values", "spectral_saliency"]
