"""TSGSP's fine step: feature-aware graph spectral filtering of face normals (thesis Section
5.1.1, Algorithm 2 lines 4-7, Eqs. 5.16-5.23)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice, check_positive, options_with_legacy
from ..geometry import face_centroids, face_normals
from ..geometry._numba_kernels import patch_bimodality, patch_moments, sym3_eigenvalues
from ..geometry.features import FLAT, cluster_eigenvalues
from ..geometry.primitives import _normalize_rows
from ..graph.adjacency import knn
from ._guard import LOWPASS_LAM, LOWPASS_MU, no_scale_message
from ._normals import fast_update_vertices, mean_centroid_distance
from ._tsgsp_kernels import _EPS, _filter_kernel, _inverse_patches, _select
from .smoothing import taubin

#: Parameter presets (Fig. 5.16): ``"scan"`` for scanned / organic models, ``"cad"`` for flat
#: regions and sharp features; ``"default"`` chosen on the shared pairs for both kinds.
PRESETS: dict[str, dict[str, float | int]] = {
    "default": {"sigma_s": 0.2, "zeta": 6, "vertex_iter": 7, "n_outer": 3, "patch": 18},
    "scan": {"sigma_s": 1.0, "zeta": 3, "vertex_iter": 5, "n_outer": 1, "patch": 15},
    "cad": {"sigma_s": 0.3, "zeta": 10, "vertex_iter": 15, "n_outer": 3, "patch": 15},
}

#: Sarle's coefficient a feature patch must reach; see docs/decisions.md#tsgsp-bimodality
BIMODALITY = 0.65
#: middle patch eigenvalue that keeps a feature whatever its bimodality (same entry)
WIDE_SPREAD = 0.3
#: Taubin pairs of the curved-surface finish; see docs/decisions.md#tsgsp-curved-finish
CURVED_FINISH = 10


@dataclass(frozen=True)
class FineOptions:
    """Options of :func:`fine`, validated on construction; None takes the preset's value. Reading
    choices (a)-(g): docs/decisions.md#denoise-tsgsp-notes."""

    #: ``k`` of the face kNN patches (>= 3)
    patch: int | None = None
    #: range width on normal differences (Eq. 5.22)
    sigma_s: float | None = None
    #: spatial width (Eq. 5.21); default the mean adjacent-centroid distance x sqrt(patch / 6)
    sigma_c: float | None = None
    #: power of the filter (Eq. 5.23)
    zeta: int | None = None
    #: vertex updates per round (Eqs. 4.28-4.29)
    vertex_iter: int | None = None
    #: rounds of classification, filtering and vertex update (reading choice (a))
    n_outer: int | None = None
    #: feature floor of the classification (Eqs. 4.14-4.15)
    min_feature: float = 0.02
    #: Eq. (5.22) on the selected patch's mean normal ("patch") or the face's own (b)
    range_guide: str = "patch"
    #: stop after round 1 when the flat faces keep more than this fraction of their smallest
    #: patch eigenvalue (c); None: every round
    curved_gate: float | None = 0.12
    #: Taubin pairs after that stop (g); 0: none
    curved_finish: int = CURVED_FINISH
    #: weight neighbours by area in Eq. (5.20) (d)
    area_weights: bool = True
    #: bimodality a feature patch must reach (f); None: Eqs. (4.14)-(4.15) alone
    bimodality: float | None = BIMODALITY

    def __post_init__(self):
        check_choice(self.range_guide, "range_guide", ("patch", "normal"))
        if self.sigma_s is not None:
            check_positive(self.sigma_s, "sigma_s")
        if self.zeta is not None:
            check_positive(self.zeta, "zeta", integer=True)
        if self.vertex_iter is not None:
            check_positive(self.vertex_iter, "vertex_iter", integer=True, allow_zero=True)
        if self.n_outer is not None:
            check_positive(self.n_outer, "n_outer", integer=True)
        if self.sigma_c is not None:
            check_positive(self.sigma_c, "sigma_c")
        check_positive(self.min_feature, "min_feature", allow_zero=True)
        if self.curved_gate is not None:
            check_positive(self.curved_gate, "curved_gate")
        check_positive(self.curved_finish, "curved_finish", integer=True, allow_zero=True)
        if not isinstance(self.area_weights, (bool, np.bool_)):
            raise InvalidInputError(
                f"`area_weights` must be True or False; got {self.area_weights!r}."
            )
        p = self.patch
        if p is not None and (isinstance(p, bool) or not isinstance(p, (int, np.integer)) or p < 3):
            raise InvalidInputError(f"`patch` must be an integer >= 3; got {p!r}.")


def fine(
    V,
    F,
    *,
    preset: str = "default",
    options: FineOptions | None = None,
    source=None,
    return_features: bool = False,
    **legacy,
):
    """Fine denoising: feature-aware graph spectral filtering of face normals (Eqs. 5.16-5.23).

    On face kNN patches found once, each round classifies faces by 3-means on the patch eigenvalues
    (Eqs. 4.14-4.15, reading choice (f)), selects every feature face's ideal patch
    (:func:`select_neighborhoods`, Eqs. 5.16-5.19), weights it with ``C_w = W_c o W_s o C``
    (Eqs. 5.20-5.22), filters the normals with ``(D^-1 C_w)^zeta`` (Eq. 5.23) and moves the
    vertices to them (Eqs. 4.28-4.29). Reading choices (a)-(g):
    docs/decisions.md#denoise-tsgsp-notes, #tsgsp-fine-weights.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    preset : {"default", "scan", "cad"}
        Supplies the options left as None (:data:`PRESETS`, Fig. 5.16).
    options : FineOptions, optional
    source : (n, 3) float, optional
        Positions whose normals the first round filters and from which it updates (reading
        choice (e)); None: ``V``.
    return_features : bool
        Also return the (m,) bool feature mask of the last round.
    **legacy
        The fields of :class:`FineOptions` as keywords: deprecated.

    Returns
    -------
    (n, 3) float64, or ``(vertices, feature_mask)``
    """
    o = options_with_legacy(options, legacy, FineOptions, "fine")
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_choice(preset, "preset", tuple(PRESETS))
    p = PRESETS[preset]
    sigma_s = float(p["sigma_s"] if o.sigma_s is None else o.sigma_s)
    zeta = int(p["zeta"] if o.zeta is None else o.zeta)
    vertex_iter = int(p["vertex_iter"] if o.vertex_iter is None else o.vertex_iter)
    n_outer = int(p["n_outer"] if o.n_outer is None else o.n_outer)
    if source is not None:
        source = as_points(source, "source")
        if source.shape != V.shape:
            raise InvalidInputError(
                f"`source` must have the shape of `V` {V.shape}; got {source.shape}."
            )
    m = F.shape[0]
    patch = o.patch
    if patch is None:
        # the preset's patch, capped by the face count (a 12-face cube has no 18-face patches)
        patch = min(int(p["patch"]), m)
        if patch < 3:  # one or two faces: no patch to filter over
            return V.copy()
    if patch > m:
        raise InvalidInputError(f"`patch` = {patch} exceeds the number of faces ({m}).")
    patch = int(patch)
    sigma_c = o.sigma_c
    if sigma_c is None:
        lc = mean_centroid_distance(V, F)
        if not lc > 0:
            raise InvalidInputError(no_scale_message("TSGSP's fine step", "passing `sigma_c`"))
        sigma_c = lc * float(np.sqrt(patch / 6.0))
    X = V.copy()
    Cc = face_centroids(X, F)
    nb, _ = knn(Cc, patch, include_self=True)
    # topology of the patches is fixed over the rounds: sort / invert the lists once
    nb_sorted = np.sort(nb, axis=1)
    indptr, cand = _inverse_patches(nb)
    den_c = 2 * sigma_c**2
    den_s = 2 * sigma_s**2
    feature = np.zeros(m, dtype=bool)
    l1_first = 0.0
    for r in range(n_outer):
        cr = face_normals(X, F, unit=False)
        N = _normalize_rows(cr)
        dbl_area = np.linalg.norm(cr, axis=1)
        active = dbl_area > 0  # zero-area faces carry no weight
        if o.area_weights:
            wa = dbl_area / max(float(dbl_area.mean()), _EPS)
        else:
            wa = np.ones(m)
        moments = patch_moments(N, nb_sorted)
        ev = sym3_eigenvalues(moments)  # Eq. (4.14)-(4.15)
        labels = cluster_eigenvalues(ev, min_feature=o.min_feature)[0]
        new_feature = labels != FLAT
        if o.bimodality is not None:  # reading choice (f): curvature is not a crease
            new_feature &= (patch_bimodality(N, nb_sorted, moments) >= o.bimodality) | (
                ev[:, 1] >= WIDE_SPREAD
            )
        if o.curved_gate is not None:
            flat_l1 = ev[~new_feature, 0]
            l1 = float(np.median(flat_l1)) if flat_l1.size else 0.0
            if r == 0:
                l1_first = l1
            elif r == 1 and l1 > o.curved_gate * l1_first:
                # curved surface: further rounds would facet it (reading choice (c)); the
                # low-pass of reading choice (g) takes off what one round left
                if o.curved_finish:
                    X = taubin(X, F, lam=LOWPASS_LAM, mu=LOWPASS_MU, n_iter=o.curved_finish)
                break
        feature = new_feature
        best = _select(N, nb, feature, ev, indptr, cand)  # Eq. (5.16)-(5.19)
        if r > 0:
            Cc = face_centroids(X, F)
        values = N
        if r == 0 and source is not None:  # reading choice (e)
            X = source.copy()
            values = face_normals(X, F)
        Nf = _filter_kernel(
            N, Cc, nb, best, active, den_c, den_s, zeta, o.range_guide == "patch", wa, values
        )  # Eq. (5.20)-(5.23)
        X = fast_update_vertices(X, F, Nf, vertex_iter)  # Eq. (4.28)-(4.29)
    return (X, feature) if return_features else X
