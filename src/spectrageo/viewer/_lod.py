"""Level of detail: a light proxy of a large model, drawn while the camera moves.

Vertex clustering (Rossignac and Borrel's uniform-grid simplification): every occupied cubic cell
keeps its original vertex nearest the cell's mean, faces map to those representatives, and collapsed
or repeated faces are dropped, so per-vertex data (any frame, colours) maps onto the proxy as
``values[reps]``. The finest grid within the face (point) budget is found by bisection. A display
aid, not a thesis method (the Appendix C viewer draws the full model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points


@dataclass(frozen=True)
class Proxy:
    """A vertex-clustered proxy.

    Attributes
    ----------
    reps : (k,) int64
        Ascending indices of the original vertices kept (one per occupied cell).
    faces : (m', 3) int64 or None
        Proxy faces indexing ``reps`` (``None`` for a point cloud).
    resolution : int
        Cells along the longest bounding-box side (0: the model fitted the budget).
    cell_size : float
        Edge length of the cubic cells.
    """

    reps: np.ndarray
    faces: np.ndarray | None
    resolution: int
    cell_size: float


def _cells(V: np.ndarray, lo: np.ndarray, h: float, res: np.ndarray) -> np.ndarray:
    """Linear cell id of every vertex for cubic cells of size ``h``."""
    ijk = np.floor((V - lo) / h).astype(np.int64)
    np.clip(ijk, 0, res - 1, out=ijk)
    return (ijk[:, 0] * res[1] + ijk[:, 1]) * res[2] + ijk[:, 2]


def _cluster(V, F, lo, ext, r):
    h = float(ext.max()) / r
    res = np.maximum(np.ceil(ext / h).astype(np.int64), 1)
    _, inv = np.unique(_cells(V, lo, h, res), return_inverse=True)
    inv = inv.ravel()
    if F is None:
        return inv, None, h
    C = inv[F]
    ok = (C[:, 0] != C[:, 1]) & (C[:, 1] != C[:, 2]) & (C[:, 0] != C[:, 2])
    C = C[ok]
    # one face per unordered triple of cells (keep the first one's orientation)
    S = np.sort(C, axis=1)
    k = int(inv.max()) + 1
    if k < 2_000_000:  # k**3 fits in int64: one integer key per triple
        key = (S[:, 0] * k + S[:, 1]) * k + S[:, 2]
        _, first = np.unique(key, return_index=True)
    else:  # pragma: no cover - more than 2M clusters only happens far above any display budget
        _, first = np.unique(S, axis=0, return_index=True)
    return inv, C[np.sort(first)], h


def _representatives(V: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """Per cluster, the index of the vertex nearest the cluster's mean."""
    k = int(inv.max()) + 1
    cnt = np.bincount(inv, minlength=k).astype(np.float64)
    mean = np.stack([np.bincount(inv, weights=V[:, j], minlength=k) for j in range(3)], axis=1)
    mean /= cnt[:, None]
    d = ((V - mean[inv]) ** 2).sum(axis=1)
    order = np.lexsort((np.arange(len(V)), d, inv))  # by cluster, then distance, then index
    starts = np.r_[0, np.flatnonzero(np.diff(inv[order])) + 1]
    return order[starts]


def vertex_clustering(
    V,
    F=None,
    *,
    max_faces: int = 100_000,
    max_points: int = 150_000,
) -> Proxy:
    """Vertex-clustering proxy of a mesh (or point cloud) within a face (point) budget.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int or None
        Faces; ``None`` for a point cloud.
    max_faces, max_points : int, keyword-only
        Largest number of proxy faces (meshes) or representatives (point clouds).

    Returns
    -------
    Proxy
        ``m' <= max_faces`` (meshes) or ``k <= max_points`` (point clouds); a model within the
        budget is its own proxy (every vertex, the input faces, ``resolution == 0``).

    Examples
    --------
    >>> from spectrageo.viewer._lod import vertex_clustering
    >>> p = vertex_clustering(V, F, max_faces=100_000)     # doctest: +SKIP
    >>> proxy_colors = colors[p.reps]                      # doctest: +SKIP
    """
    V = as_points(V, name="V")
    if F is not None:
        F = as_faces(F, n_vertices=len(V), name="F")
    for name, val in (("max_faces", max_faces), ("max_points", max_points)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise InvalidInputError(f"`{name}` must be a positive integer; got {val!r}.")
    n = len(V)
    lo = V.min(axis=0)
    ext = np.maximum(V.max(axis=0) - lo, 1e-12 * max(1.0, float(np.abs(V).max())))

    def fits(r):
        inv, C, h = _cluster(V, F, lo, ext, r)
        size = (int(inv.max()) + 1) if F is None else len(C)
        return size <= (max_points if F is None else max_faces), inv, C, h

    if (F is None and n <= max_points) or (F is not None and len(F) <= max_faces):
        return Proxy(reps=np.arange(n, dtype=np.int64), faces=F, resolution=0, cell_size=0.0)
    # bracket the largest fitting r, starting from a surface-like estimate (size ~ r**2), then
    # bisect; r = 1 (one cell along the longest side) always fits for any sensible budget
    budget = max_points if F is None else max_faces
    probe = fits(64)
    size64 = max(1, (int(probe[1].max()) + 1) if F is None else len(probe[2]))
    r = max(2, int(64 * np.sqrt(budget / size64)))
    lo_r, best, hi_r = 1, None, None
    if probe[0]:
        lo_r, best = 64, probe
    else:
        hi_r = 64
    for _ in range(40):
        if hi_r is not None and r >= hi_r or r <= lo_r:
            break
        cand = fits(r)
        if cand[0]:
            lo_r, best = r, cand
            r = int(r * 1.25) + 1
        else:
            hi_r = r
            r = max(lo_r + 1, int(r / 1.25))
        if r > 1 << 21:
            break
    if best is None:
        best = fits(1)
    hi_r = hi_r if hi_r is not None else lo_r + 1
    while hi_r - lo_r > max(1, lo_r // 64):  # 1.5 % resolution is plenty for a display proxy
        mid = (lo_r + hi_r) // 2
        cand = fits(mid)
        if cand[0]:
            lo_r, best = mid, cand
        else:
            hi_r = mid
    _, inv, C, h = best
    return _finish(V, inv, C, lo_r, h)


def _finish(V, inv, C, r, h) -> Proxy:
    reps = _representatives(V, inv)
    # clusters are numbered by ascending cell id; renumber so that reps ascend (stable, cache-friendly)
    order = np.argsort(reps, kind="stable")
    new_id = np.empty_like(order)
    new_id[order] = np.arange(len(order))
    faces = None if C is None else new_id[C].astype(np.int64)
    return Proxy(reps=reps[order].astype(np.int64), faces=faces, resolution=int(r), cell_size=h)


__all__ = ["Proxy", "vertex_clustering"]
