"""Saliency-aware multiscale simplification (Section 6.1.3, Algorithm 15, Tables 6.2-6.4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, as_rng, check_choice
from ..geometry.primitives import edges as mesh_edges
from ._common import check_int, minmax

CLASS_EDGES = ("uniform", "quantile")
WITHIN = ("random", "top")


@dataclass(frozen=True)
class Simplified:
    """Result of :func:`simplify`: ``vertices``, ``faces``, the input index ``kept`` of every output
    vertex, the ``classes`` of the input and the ``keep_fractions`` per class.
    """

    vertices: np.ndarray
    faces: np.ndarray
    kept: np.ndarray
    classes: np.ndarray
    keep_fractions: np.ndarray


def saliency_classes(saliency, n_classes: int, *, class_edges: str = "uniform") -> np.ndarray:
    """Class of every value, 0 (least salient) to ``n_classes - 1`` (Algorithm 15, step 2)."""
    check_choice(class_edges, "class_edges", CLASS_EDGES)
    s = minmax(np.asarray(saliency, dtype=np.float64))
    if class_edges == "uniform":
        return np.minimum(np.floor(s * n_classes), n_classes - 1).astype(np.int64)
    ranks = np.empty(s.size, dtype=np.int64)
    ranks[np.argsort(s, kind="stable")] = np.arange(s.size)
    return (ranks * n_classes // max(s.size, 1)).astype(np.int64)


def class_keep_fractions(counts, n_keep: int, *, weights=None) -> np.ndarray:
    """Keep fractions ``p_c = min(1, a w_c)`` (default ``w_c = 2**c``) keeping ``n_keep``."""
    counts = np.asarray(counts, dtype=np.float64)
    N = counts.size
    w = 2.0 ** np.arange(N) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (N,) or not np.isfinite(w).all() or (w <= 0).any():
        raise InvalidInputError(f"`weights` must be {N} positive numbers; got {weights!r}.")
    total = counts.sum()
    if n_keep >= total:
        return np.ones(N)

    def kept(a):
        return (np.minimum(1.0, a * w) * counts).sum()

    lo, hi = 0.0, 1.0 / w.min()
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if kept(mid) < n_keep:
            lo = mid
        else:
            hi = mid
    return np.minimum(1.0, hi * w)


def simplify(
    V,
    F,
    *,
    ratio: float = 0.8,
    saliency=None,
    n_classes: int = 4,
    keep_fractions=None,
    weights=None,
    class_edges: str = "uniform",
    within: str = "random",
    rng=None,
    **saliency_options,
) -> Simplified:
    """Saliency-aware multiscale simplification (Algorithm 15): removes ``ratio`` of the vertices
    (or per-class ``keep_fractions``), by default by :func:`saliency` with ``saliency_options``;
    options in docs/decisions.md#saliency-simplify-choices. Returns a valid :class:`Simplified`.
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    n = V.shape[0]
    n_classes = check_int(n_classes, "n_classes", minimum=1)
    check_choice(within, "within", WITHIN)
    if saliency is None:
        from .combined import saliency as _saliency

        s = _saliency(V, F, per="vertex", **saliency_options)
    else:
        if saliency_options:
            raise InvalidInputError(
                f"saliency options {sorted(saliency_options)} given together with `saliency`."
            )
        s = np.asarray(saliency, dtype=np.float64)
        if s.shape != (n,):
            raise InvalidInputError(f"`saliency` must have shape ({n},); got {s.shape}.")
        if not np.isfinite(s).all():
            raise InvalidInputError("`saliency` contains NaN or inf values.")
    cls = saliency_classes(s, n_classes, class_edges=class_edges)
    counts = np.bincount(cls, minlength=n_classes)
    if keep_fractions is not None:
        p = np.asarray(keep_fractions, dtype=np.float64)
        if p.shape != (n_classes,) or not np.isfinite(p).all() or (p < 0).any() or (p > 1).any():
            raise InvalidInputError(
                f"`keep_fractions` must be {n_classes} numbers in [0, 1]; got {keep_fractions!r}."
            )
    else:
        ratio = float(ratio)
        if not (0.0 <= ratio < 1.0):
            raise InvalidInputError(f"`ratio` must be in [0, 1); got {ratio}.")
        n_keep = max(3, int(round((1.0 - ratio) * n)))
        p = class_keep_fractions(counts, n_keep, weights=weights)
    gen = as_rng(rng)
    keep = np.zeros(n, dtype=bool)
    for c in range(n_classes):
        members = np.flatnonzero(cls == c)
        q = int(round(p[c] * members.size))
        if q == 0:
            continue
        if within == "top":
            chosen = members[np.argsort(-s[members], kind="stable")[:q]]
        else:
            chosen = gen.choice(members, q, replace=False)
        keep[chosen] = True
    if keep.sum() < 3:
        raise InvalidInputError("the simplification keeps fewer than 3 vertices; lower `ratio`.")
    # connectivity: every removed vertex takes the place of its nearest kept vertex along the edges
    E = mesh_edges(F)
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1) + 1e-300
    G = sp.coo_matrix((w, (E[:, 0], E[:, 1])), shape=(n, n)).tocsr()
    kept_idx = np.flatnonzero(keep)
    _, _, src = dijkstra(
        G, directed=False, indices=kept_idx, min_only=True, return_predecessors=True
    )
    src = np.asarray(src, dtype=np.int64)
    unreached = src < 0  # vertices of components without a kept vertex: keep the nearest in space
    if unreached.any():
        from scipy.spatial import cKDTree

        _, j = cKDTree(V[kept_idx]).query(V[unreached])
        src[unreached] = kept_idx[j]
    Fm = src[F]
    ok = (Fm[:, 0] != Fm[:, 1]) & (Fm[:, 1] != Fm[:, 2]) & (Fm[:, 0] != Fm[:, 2])
    Fm = Fm[ok]
    if Fm.shape[0] == 0:
        raise InvalidInputError(
            "no triangle survives the simplification (every face collapsed onto one or two kept "
            "vertices: a mesh of degenerate faces, or too few vertices kept); lower `ratio`."
        )
    if Fm.size:  # drop duplicate triangles (same vertex set), keep the first orientation seen
        _, first = np.unique(np.sort(Fm, axis=1), axis=0, return_index=True)
        Fm = Fm[np.sort(first)]
    used = np.unique(Fm)
    remap = np.full(n, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return Simplified(V[used].copy(), remap[Fm], used, cls, p)


__all__ = [
    "CLASS_EDGES",
    "Simplified",
    "class_keep_fractions",
    "saliency_classes",
    "simplify",
]
