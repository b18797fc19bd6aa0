"""Do-no-harm guard shared by the static denoisers: a curvature-robust noise level that decides
whether a mesh carries noise at all, and the trust region that bounds every displacement.

Why. Users run denoisers on files that are already clean (CAD exports, finished scans). The
filters of Sections 4.7 and 5.1.1 then blend normals across features and, on CAD tessellations
with long thin triangles, bend flat and cylindrical faces (trimesh's ``cycloidal.ply``: 45 degrees
of mean normal change). The thesis assumes a noisy input; this module is the documented
addition that lets a method recognise a clean one.

Noise level (:func:`noise_level`). Eq. (5.14) models the smallest patch variance as
``lambda_min(R_v) + sigma_z^2`` and Eq. (5.15) drops ``lambda_min(R_v)`` (flat patches). On a
clean curved surface that term is the curvature and does not vanish, so here the surface is
removed to second order instead: around every vertex the ``patch`` nearest vertices are fitted
with a least-squares quadric height field over the tangent plane of the patch (its
minimum-variance direction as height axis); the residual variance ``RSS / (k - 6)`` is zero on
planes, cylinders and spheres and ``sigma_z^2`` (chi-square distributed with ``k - 6`` degrees of
freedom) under Gaussian noise along the normals. Creases and patches straddling two parts fit
badly, so a low quantile ``q`` (0.25) of the per-vertex residuals is taken and divided by the
matching chi-square quantile ``chi2_q(k - 6) / (k - 6)``, which keeps the estimate unbiased under
Gaussian noise as long as fewer than 75 % of the patches straddle features. The level is
reported relative to the median patch radius (the distance to the ``patch``-th neighbour), a
length that follows the sampling the estimate sees (the mean edge length of a CAD tessellation
is dominated by a few long edges).

Gate. A mesh whose level is below ``min_noise`` is returned unchanged. ``0.015`` was chosen on the
tuning split (the shared denoising pairs): the largest level of a clean original there is 0.0126
(Bunny), the smallest of a noisy input 0.0365 (the real scans; the synthetic pairs are at 0.057
and above); 0.015 is the round value just above the clean originals.

Trust region. Displacements are capped at ``trust`` times the noise standard deviation of
:func:`noise_sigma` (see :func:`apply_trust`). Eq. (5.15)'s plane-fit estimate counts curvature
as noise and let the filters move clean curved parts by several triangle widths.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from .._errors import InvalidInputError
from .._validation import as_points, check_positive
from ..geometry._numba_kernels import patch_min_variance, patch_quadric_residual
from ..graph.adjacency import knn

#: default gate (relative noise level below which a mesh counts as clean); see the module notes
MIN_NOISE = 0.015
#: default trust radius in noise standard deviations (Eq. 5.15)
TRUST = 6.0


def noise_sigma(V, *, patch: int = 16, quantile: float = 0.25) -> tuple[float, float]:
    """Curvature-robust noise estimate of a surface sampled by ``V`` (module notes).

    Returns ``(sigma, level)``: ``sigma`` the estimated standard deviation of the noise along the
    normals (model units; 0 on sampled planes, cylinders and spheres) and ``level = sigma / r``
    with ``r`` the median distance of a vertex to its ``patch``-th nearest vertex. With fewer
    than 7 vertices no quadric can be fitted and noise cannot be told from shape:
    ``(0.0, 0.0)`` is returned, so such meshes are left unchanged by the gate.
    """
    V = as_points(V, "V")
    check_positive(patch, "patch", integer=True)
    if patch < 7:
        raise InvalidInputError(f"`patch` must be >= 7; got {patch}.")
    if not 0 < quantile < 1:
        raise InvalidInputError(f"`quantile` must be in (0, 1); got {quantile!r}.")
    k = min(int(patch), V.shape[0])
    if k < 7:
        return 0.0, 0.0
    idx, dist = knn(V, k, include_self=True)
    lam = np.empty(V.shape[0])
    dirs = np.empty((V.shape[0], 3))
    patch_min_variance(V, idx, lam, dirs)
    res = np.empty(V.shape[0])
    spread = np.empty(V.shape[0])
    patch_quadric_residual(V, idx, dirs, res, spread)
    ok = np.isfinite(res)
    radius = float(np.median(dist[:, -1]))
    if not ok.any() or not radius > 0:
        return 0.0, 0.0  # every patch degenerate (coincident or collinear points)
    dof = k - 6
    var = float(np.quantile(np.maximum(res[ok], 0.0), quantile)) / (chi2.ppf(quantile, dof) / dof)
    sigma = float(np.sqrt(var))
    return sigma, sigma / radius


def noise_level(V, *, patch: int = 16, quantile: float = 0.25) -> float:
    """Relative noise level ``sigma / r`` of :func:`noise_sigma` (dimensionless)."""
    return noise_sigma(V, patch=patch, quantile=quantile)[1]


def apply_trust(V: np.ndarray, X: np.ndarray, radius: float) -> np.ndarray:
    """``X`` with every displacement from ``V`` longer than ``radius`` shortened to it (direction
    kept)."""
    D = X - V
    length = np.linalg.norm(D, axis=1, keepdims=True)
    scale = np.minimum(1.0, radius / np.maximum(length, np.finfo(np.float64).tiny))
    return V + D * scale
