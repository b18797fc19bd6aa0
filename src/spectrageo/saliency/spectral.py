"""Spectral saliency ``1 / ||lambda(M_i M_i^T)||_2`` of face patches (Eq. 6.1-6.4, 6.10-6.11)."""

from __future__ import annotations

import numpy as np

from .._validation import check_choice
from ..geometry.features import patch_eigenvalues
from ._common import PER, check_k, check_mesh, face_patches, face_to_vertex, mesh_normals, minmax


def spectral_face_values(normals: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Raw ``s_i = 1 / ||lambda_i||_2`` per patch row (Eq. 6.1-6.3), (q,) float64; a patch
    of zero normals gets the largest finite value.
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
    """Normalised spectral saliency (Eq. 6.1-6.4) per vertex or face (Eq. 6.14); ``k``,
    ``normals`` as in :class:`SaliencyOptions`, or precomputed ``patches``.
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
