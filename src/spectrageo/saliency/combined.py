"""Saliency maps of meshes: spectral, geometric and combined, with the fast variant (Section 6.1.2).

Pipeline (Fig. 6.6): overlapping kNN face patches -> spectral saliency ``s_2`` (Eq. 6.10-6.11 with
6.1-6.3) and geometric saliency ``s_1`` (RPCA, Eq. 6.8-6.9) per face -> min-max normalisation
(Eq. 6.12) -> weighted combination ``s_c = (w1 s_1 + w2 s_2) / (w1 + w2)`` (Eq. 6.13, w1 = w2 = 1)
-> per-vertex mean over the first ring (Eq. 6.14).

Fast variant (Table 6.1): the faces are split into 64 classes by their normalised spectral saliency
(the 64 colours of the jet map); the least salient class (``s_2 < 1/64``, mostly flat areas) is
left out of the RPCA matrix, which shrinks to ``M'`` with ``n_f' < n_f`` rows, and gets geometric
saliency 0. The thesis classifies vertices; the same rule is applied here to the faces, whose rows
form ``M`` (the share of faces dropped is within 1-2 points of the share of faces with a class-1
vertex under the per-vertex rule). The guided normals, the patches and the spectral map are needed
for every face before the classes are known, so only the RPCA shrinks; its cost is linear in the
rows, so the saving is at most the dropped share of the RPCA time (28-38 % of the whole map's CPU
time on the reference models, see ``benchmarks/saliency.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice
from ._common import PER, check_k, check_mesh, face_patches, face_to_vertex, minmax
from ._common import mesh_normals as _mesh_normals
from .geometric import PatchRPCA, geometric_face_values
from .spectral import spectral_face_values

METHODS = ("combined", "spectral", "geometric")
#: Number of saliency classes of the fast variant (the 64 colours of the jet colormap).
FAST_CLASSES = 64


@dataclass(frozen=True)
class SaliencyComponents:
    """Per-face pieces of a saliency computation (:func:`saliency_components`).

    Attributes
    ----------
    spectral : (m,) float64
        Normalised spectral saliency ``s_2`` (Eq. 6.4/6.12).
    geometric : (m,) float64 or None
        Normalised geometric saliency ``s_1`` (Eq. 6.12); None when not computed.
    combined : (m,) float64
        The face map of the requested method (Eq. 6.13 for ``"combined"``).
    patches : (m, k + 1) int64
        Face patches (face first).
    analysed : (m,) bool
        Faces whose rows entered the RPCA matrix (all unless ``fast``).
    rpca : PatchRPCA or None
        Solver report of the geometric part.
    spectral_raw, geometric_raw : (m,) float64 or None
        Values before normalisation (``1 / ||lambda||`` and the sparse-row norm).
    """

    spectral: np.ndarray
    geometric: np.ndarray | None
    combined: np.ndarray
    patches: np.ndarray
    analysed: np.ndarray
    rpca: PatchRPCA | None
    spectral_raw: np.ndarray
    geometric_raw: np.ndarray | None


def _check_weights(weights) -> tuple[float, float]:
    try:
        w1, w2 = (float(w) for w in weights)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"`weights` must be two non-negative numbers (w1, w2); got {weights!r}."
        ) from exc
    if not (np.isfinite(w1) and np.isfinite(w2)) or w1 < 0 or w2 < 0 or w1 + w2 == 0:
        raise InvalidInputError(
            f"`weights` must be non-negative with a positive sum; got {weights!r}."
        )
    return w1, w2


def fast_mask(spectral: np.ndarray, *, n_classes: int = FAST_CLASSES) -> np.ndarray:
    """Faces kept by the fast variant: not in the least salient of ``n_classes`` classes (Table 6.1).

    ``spectral`` is the normalised spectral map in [0, 1]; class 1 is ``[0, 1 / n_classes)``.
    """
    s = np.asarray(spectral, dtype=np.float64)
    cls = np.minimum(np.floor(s * n_classes), n_classes - 1)
    return cls > 0


def saliency_components(
    V,
    F,
    *,
    method: str = "combined",
    k: int = 25,
    fast: bool = False,
    weights=(1.0, 1.0),
    normals="guided",
    sparse_norm: str = "patch",
    shrinkage: str = "group",
    solver: str = "internal",
    tol: float = 1e-4,
    max_iter: int = 300,
    rng=None,
) -> SaliencyComponents:
    """Per-face spectral, geometric and combined saliency (Eq. 6.8-6.13); see :func:`saliency`."""
    check_choice(method, "method", METHODS)
    V, F = check_mesh(V, F)
    k = check_k(k, F.shape[0])
    w1, w2 = _check_weights(weights)
    if not isinstance(fast, bool | np.bool_):
        raise InvalidInputError(f"`fast` must be True or False; got {fast!r}.")
    N = _mesh_normals(V, F, normals)
    patches = face_patches(V[F].mean(axis=1), k)
    s2_raw = spectral_face_values(N, patches)
    s2 = minmax(s2_raw)
    m = F.shape[0]
    analysed = np.ones(m, dtype=bool)
    s1 = s1_raw = None
    info = None
    if method != "spectral":
        if fast:
            analysed = fast_mask(s2)
        rows = np.flatnonzero(analysed)
        info = geometric_face_values(
            N,
            patches[rows],
            sparse_norm=sparse_norm,
            shrinkage=shrinkage,
            solver=solver,
            tol=tol,
            max_iter=max_iter,
            rng=rng,
        )
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
    *,
    method: str = "combined",
    per: str = "vertex",
    k: int = 25,
    fast: bool = False,
    weights=(1.0, 1.0),
    normals="guided",
    sparse_norm: str = "patch",
    shrinkage: str = "group",
    solver: str = "internal",
    tol: float = 1e-4,
    max_iter: int = 300,
    rng=None,
) -> np.ndarray:
    """Saliency map of a triangle mesh (Section 6.1.2, Eq. 6.1-6.14).

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    method : {"combined", "spectral", "geometric"}
        Spectral saliency (Eq. 6.10-6.11, 6.1-6.3), geometric saliency (RPCA of the patch normals,
        Eq. 6.8-6.9) or their weighted mean (Eq. 6.13).
    per : {"vertex", "face"}
        Per-face map, or its mean over each vertex's first ring (Eq. 6.14).
    k : int
        Neighbours per patch besides the face (thesis: 25; range 15-35 recommended).
    fast : bool
        Leave the least salient of 64 spectral classes out of the RPCA (Table 6.1); their geometric
        saliency is 0.
    weights : (w1, w2)
        Weights of the geometric and spectral maps in Eq. (6.13) (thesis: 1, 1).
    normals : {"guided", "face"} or (m, 3) array
        Normals analysed (guided normals by default, Section 6.1.2).
    sparse_norm, shrinkage, solver, tol, max_iter, rng
        Options of the geometric part, see :func:`spectrageo.saliency.geometric_face_values`.

    Returns
    -------
    (n,) or (m,) float64 in [0, 1]: 0 on flat areas, high on edges, corners and defects. The map is
    invariant to rotation, translation and uniform scaling of the mesh.

    Raises
    ------
    InvalidInputError
        Bad mesh arrays, unknown option, ``k + 1`` larger than the number of faces.

    Examples
    --------
    >>> s = saliency(V, F)                          # doctest: +SKIP
    >>> s_face = saliency(V, F, per="face", fast=True)  # doctest: +SKIP
    """
    check_choice(per, "per", PER)
    comp = saliency_components(
        V,
        F,
        method=method,
        k=k,
        fast=fast,
        weights=weights,
        normals=normals,
        sparse_norm=sparse_norm,
        shrinkage=shrinkage,
        solver=solver,
        tol=tol,
        max_iter=max_iter,
        rng=rng,
    )
    if per == "face":
        return comp.combined
    V = np.asarray(V)
    return face_to_vertex(comp.combined, np.asarray(F, dtype=np.int64), V.shape[0])


__all__ = [
    "FAST_CLASSES",
    "METHODS",
    "SaliencyComponents",
    "fast_mask",
    "saliency",
    "saliency_components",
]
