"""Guided mesh normal filtering (Zhang, Deng, Zhang & Liu 2015) with the guided normals of
Section 4.2 (Eqs. 4.8-4.11) and the vertex update of Section 4.7 (Eqs. 4.28-4.29)."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice, check_positive
from ..geometry import face_areas, face_centroids, face_normals, update_vertices
from ._guard import no_scale_message
from ._normals import (
    MEASURES,
    PatchSet,
    face_radius_neighbors,
    guided_normals,
    joint_bilateral_normals,
    mean_centroid_distance,
    spatial_weights,
)
from ._table import register

#: Parameter presets. ``"default"``: the defaults of Zhang et al. (2015) (radius neighbourhood of
#: twice the mean adjacent-centroid distance, sigma_r = 0.35, 20 normal and 10 vertex iterations).
#: ``"cad"``: models made of large flat regions and sharp features under strong noise; more normal
#: iterations and a narrower range kernel. ``"smooth"``: scanned / organic models with fine detail;
#: fewer normal iterations so that small features are not flattened. Notes:
#: docs/decisions.md#denoise-method-notes.
PRESETS: dict[str, dict[str, object]] = {
    "default": {"sigma_r": 0.35, "n_iter": 20, "vertex_iter": 10, "radius_factor": 2.0},
    "cad": {"sigma_r": 0.3, "n_iter": 40, "vertex_iter": 20, "radius_factor": 2.0},
    "smooth": {"sigma_r": 0.35, "n_iter": 5, "vertex_iter": 10, "radius_factor": 2.0},
}


_NO_SCALE = no_scale_message("guided normal filtering", "gnf(..., radius=..., sigma_s=...)")


def _pick(value, name: str, preset: dict):
    return preset[name] if value is None else value


@register(
    "gnf",
    summary="guided mesh normal filtering (joint bilateral filter guided by patch normals)",
    reference="Zhang, Deng, Zhang & Liu 2015, 'Guided mesh normal filtering', Pacific Graphics (CGF 34(7))",
    presets=tuple(PRESETS),
    trusted=True,
)
def gnf(
    V,
    F,
    *,
    preset: str = "default",
    sigma_r: float | None = None,
    sigma_s: float | None = None,
    radius: float | None = None,
    neighbors: str = "radius",
    n_iter: int | None = None,
    vertex_iter: int | None = None,
    measure: str = "zhang2015",
) -> np.ndarray:
    """Guided mesh normal filtering (Zhang et al. 2015), local iterative scheme.

    Each of ``n_iter`` passes takes every face's guided normal ``g_i`` (Eqs. 4.8-4.11, patch
    consistency ``measure``) and applies
    ``n_i <- normalize(sum_j A_j K_s(||c_i - c_j||) K_r(||g_i - g_j||) n_j)`` over the faces within
    ``radius`` (``neighbors="radius"``) or sharing a vertex; then ``vertex_iter`` vertex updates
    (Eqs. 4.28-4.29). Options left as None come from ``preset`` (:data:`PRESETS`)."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_choice(preset, "preset", tuple(PRESETS))
    check_choice(neighbors, "neighbors", ("radius", "vertex"))
    check_choice(measure, "measure", MEASURES)
    p = PRESETS[preset]
    sigma_r = float(check_positive(_pick(sigma_r, "sigma_r", p), "sigma_r"))
    n_iter = check_positive(_pick(n_iter, "n_iter", p), "n_iter", integer=True, allow_zero=True)
    vertex_iter = check_positive(
        _pick(vertex_iter, "vertex_iter", p), "vertex_iter", integer=True, allow_zero=True
    )
    if radius is not None:
        check_positive(radius, "radius")
    if sigma_s is not None:
        check_positive(sigma_s, "sigma_s")
    if neighbors == "vertex" and radius is not None:
        raise InvalidInputError('`radius` is only used with neighbors="radius".')

    ps = PatchSet.from_faces(F)
    pairs = ps.edge_pairs
    if neighbors == "radius":
        if radius is None:
            lc0 = mean_centroid_distance(V, F, pairs=pairs)
            if not lc0 > 0:
                raise InvalidInputError(_NO_SCALE)
            radius = float(p["radius_factor"]) * lc0
        nbr = face_radius_neighbors(face_centroids(V, F), radius, adjacency=ps.P)
    else:
        nbr = ps.P
    X = V.copy()
    for _ in range(n_iter):
        C = face_centroids(X, F)
        A = face_areas(X, F)
        N = face_normals(X, F)
        s = sigma_s if sigma_s is not None else mean_centroid_distance(X, F, pairs=pairs)
        if not s > 0:
            raise InvalidInputError(_NO_SCALE)
        g = guided_normals(N, A, ps, measure=measure)
        N = joint_bilateral_normals(N, g, spatial_weights(C, A, nbr, s), sigma_r)
        X = update_vertices(X, F, N, n_iter=vertex_iter)
    return X


__all__ = ["PRESETS", "gnf"]
