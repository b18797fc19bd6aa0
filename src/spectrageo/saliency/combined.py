"""Mesh saliency maps (Section 6.1.2, Eq. 6.8-6.14) and the fast variant (Table 6.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import check_choice, options_with_legacy
from ._common import PER, check_k, check_mesh, face_patches, face_to_vertex, minmax
from ._common import mesh_normals as _mesh_normals
from ._options import SaliencyOptions
from .geometric import PatchRPCA, geometric_face_values
from .spectral import spectral_face_values

METHODS = ("combined", "spectral", "geometric")
#: Number of saliency classes of the fast variant (the 64 colours of the jet colormap).
FAST_CLASSES = 64


@dataclass(frozen=True)
class SaliencyComponents:
    """Per-face maps of :func:`saliency_components`: ``spectral``, ``geometric``, ``combined``,
    ``patches``, ``analysed`` rows, ``rpca`` report, ``spectral_raw`` and ``geometric_raw``.
    """

    spectral: np.ndarray
    geometric: np.ndarray | None
    combined: np.ndarray
    patches: np.ndarray
    analysed: np.ndarray
    rpca: PatchRPCA | None
    spectral_raw: np.ndarray
    geometric_raw: np.ndarray | None


def fast_mask(spectral: np.ndarray, *, n_classes: int = FAST_CLASSES) -> np.ndarray:
    """Faces outside the least salient of ``n_classes`` spectral classes (Table 6.1); see
    docs/decisions.md#saliency-fast-faces.
    """
    s = np.asarray(spectral, dtype=np.float64)
    cls = np.minimum(np.floor(s * n_classes), n_classes - 1)
    return cls > 0


def saliency_components(
    V, F, options: SaliencyOptions | None = None, *, method: str = "combined", **legacy
) -> SaliencyComponents:
    """Per-face spectral, geometric and combined saliency (Eq. 6.8-6.13); see :func:`saliency`."""
    check_choice(method, "method", METHODS)
    opts = options_with_legacy(options, legacy, SaliencyOptions, "saliency_components")
    V, F = check_mesh(V, F)
    k = check_k(opts.k, F.shape[0])
    w1, w2 = opts.weights
    N = _mesh_normals(V, F, opts.normals)
    patches = face_patches(V[F].mean(axis=1), k)
    s2_raw = spectral_face_values(N, patches)
    s2 = minmax(s2_raw)
    m = F.shape[0]
    analysed = np.ones(m, dtype=bool)
    s1 = s1_raw = None
    info = None
    if method != "spectral":
        if opts.fast:
            analysed = fast_mask(s2)
        rows = np.flatnonzero(analysed)
        info = geometric_face_values(N, patches[rows], **opts.geometric())
        s1_raw = np.zeros(m)
        s1_raw[rows] = info.values
        s1 = minmax(s1_raw)
    if method == "spectral":
        comb = s2
    elif method == "geometric":
        comb = s1
    else:
        comb = (w1 * s1 + w2 * s2) / (w1 + w2)
    return SaliencyComponents(s2, s1, comb, patches, analysed, info, s2_raw, s1_raw)


def saliency(
    V,
    F,
    options: SaliencyOptions | None = None,
    *,
    method: str = "combined",
    per: str = "vertex",
    **legacy,
) -> np.ndarray:
    """Saliency map of a triangle mesh (Section 6.1.2, Eq. 6.1-6.14).

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int
    options : SaliencyOptions, optional
        Patch size, fast variant, weights, normals and RPCA settings (thesis defaults).
    method : {"combined", "spectral", "geometric"}
        Spectral (Eq. 6.10-6.11), geometric (Eq. 6.8-6.9) or weighted mean (Eq. 6.13).
    per : {"vertex", "face"}
        Per-face map, or its first-ring mean per vertex (Eq. 6.14).
    **legacy
        Deprecated: fields of :class:`SaliencyOptions` as keywords.

    Returns
    -------
    (n,) or (m,) float64 in [0, 1], invariant to rotation, translation and uniform scaling.

    Raises
    ------
    InvalidInputError
        Bad mesh arrays or options, ``k + 1`` larger than the number of faces.

    Examples
    --------
    >>> s = saliency(V, F, SaliencyOptions(fast=True), per="face")  # doctest: +SKIP
    """
    check_choice(per, "per", PER)
    opts = options_with_legacy(options, legacy, SaliencyOptions, "saliency")
    comp = saliency_components(V, F, opts, method=method)
    if per == "face":
        return comp.combined
    V = np.asarray(V)
    return face_to_vertex(comp.combined, np.asarray(F, dtype=np.int64), V.shape[0])


__all__ = [
    "FAST_CLASSES",
    "METHODS",
    "SaliencyComponents",
    "SaliencyOptions",
    "fast_mask",
    "saliency",
    "saliency_components",
]
