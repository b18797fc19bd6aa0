"""Outliers for point clouds and missing data (removed vertices, holes) for meshes, with ground truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, as_rng, check_choice, check_positive
from ._core import check_fraction, mean_spacing, unique_edges


def _check_fraction(fraction) -> None:
    """Outlier fractions are relative to the clean point count and may exceed 1 (unlike
    :func:`._core.check_fraction`)."""
    if isinstance(fraction, bool) or not isinstance(
        fraction, int | float | np.integer | np.floating
    ):
        raise InvalidInputError(f"`fraction` must be a number >= 0; got {fraction!r}.")
    if not np.isfinite(fraction) or fraction < 0:
        raise InvalidInputError(f"`fraction` must be a finite number >= 0; got {fraction!r}.")


def add_outliers(
    P,
    *,
    fraction: float = 0.1,
    kind: str = "far",
    rng=None,
    normals=None,
    margin: float = 0.1,
    distance: tuple[float, float] = (1.0, 3.0),
    shuffle: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Append ``round(fraction * n)`` synthetic outliers to a point cloud.

    Parameters
    ----------
    P : (n, 3) array_like
        Clean points (the inliers).
    fraction : float
        Number of outliers relative to the number of inliers, >= 0 (so ``labels.sum() ==
        round(fraction * n)``; values above 1 are allowed).
    kind : {"far", "near"}
        ``"far"``: uniform in the bounding box of ``P`` enlarged on every side by ``margin`` times its
        diagonal. ``"near"``: near-surface outliers -- a random inlier (with replacement) displaced by
        ``U(distance[0], distance[1])`` times the mean nearest-neighbour spacing, along a random unit
        direction, or along ``+-normals`` of that inlier (random sign) when ``normals`` is given.
    rng : int, Generator or None
    normals : (n, 3) array_like, optional
        Inlier normals for ``kind="near"``.
    margin : float
        Bounding-box enlargement for ``kind="far"`` (fraction of the diagonal, >= 0).
    distance : (float, float)
        Range of near-outlier offsets in units of the mean nearest-neighbour spacing.
    shuffle : bool
        False (default): the outliers are appended, so the first n rows are ``P`` in order and
        ``labels[:n]`` is all False. True: all rows are permuted with ``rng``; ``labels`` follows.

    Returns
    -------
    P_out : (n + k, 3) float64
    labels : (n + k,) bool
        True for outliers.

    Notes
    -----
    A "far" outlier may by chance land close to the surface; the labels record how points were
    generated, not their distance to the surface.
    """
    P = as_points(P, "P")
    check_choice(kind, "kind", ("far", "near"))
    _check_fraction(fraction)
    check_positive(margin, "margin", allow_zero=True)
    lo_d, hi_d = (float(x) for x in distance)
    if not (np.isfinite(lo_d) and np.isfinite(hi_d)) or lo_d < 0 or hi_d < lo_d:
        raise InvalidInputError(
            f"`distance` must be (low, high) with 0 <= low <= high; got {tuple(distance)!r}."
        )
    rng = as_rng(rng)
    n = P.shape[0]
    k = int(round(float(fraction) * n))
    if kind == "far":
        lo, hi = P.min(axis=0), P.max(axis=0)
        pad = margin * float(np.linalg.norm(hi - lo))
        Q = rng.uniform(lo - pad, hi + pad, size=(k, 3))
    else:
        if n < 2:
            raise InvalidInputError(
                "near-surface outliers need at least 2 points to define a spacing."
            )
        s = mean_spacing(P, None)
        base = rng.integers(0, n, size=k)
        mag = rng.uniform(lo_d, hi_d, size=k) * s
        if normals is not None:
            N = np.asarray(normals, dtype=np.float64)
            if N.shape != P.shape:
                raise InvalidInputError(f"`normals` must have shape {P.shape}; got {N.shape}.")
            nrm = np.linalg.norm(N, axis=1, keepdims=True)
            if not np.isfinite(N).all() or np.any(nrm[base] == 0):
                raise InvalidInputError("`normals` must be finite and non-zero.")
            d = N[base] / nrm[base] * rng.choice([-1.0, 1.0], size=k)[:, None]
        else:
            d = rng.standard_normal((k, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
        Q = P[base] + mag[:, None] * d
    out = np.concatenate([P, Q])
    labels = np.r_[np.zeros(n, dtype=bool), np.ones(k, dtype=bool)]
    if shuffle:
        perm = rng.permutation(n + k)
        out, labels = out[perm], labels[perm]
    return out, labels


@dataclass(frozen=True, eq=False)
class CorruptionResult:
    """A mesh with missing vertices and the ground truth needed to evaluate a completion.

    Attributes
    ----------
    vertices : (n_kept, 3) float64
        The kept vertices, in their original order.
    faces : (m_kept, 3) int64 or None
        The faces whose three vertices were kept, re-indexed into ``vertices``.
    removed : (n,) bool
        True for removed vertices (original indexing).
    index_map : (n,) int64
        New index of every original vertex, -1 where removed (``vertices[index_map[i]] == V[i]``).
    kept : (n_kept,) int64
        Original index of every kept vertex (``vertices == V[kept]``).
    labels : (n,) int64 or None
        For holes: the hole number of every removed vertex, -1 for kept vertices.
    """

    vertices: np.ndarray
    faces: np.ndarray | None
    removed: np.ndarray
    index_map: np.ndarray
    kept: np.ndarray
    labels: np.ndarray | None = None


def _apply_removal(V, F, removed, labels=None) -> CorruptionResult:
    kept = np.flatnonzero(~removed)
    index_map = np.full(V.shape[0], -1, dtype=np.int64)
    index_map[kept] = np.arange(kept.size)
    faces = None
    if F is not None:
        keep_f = ~removed[F].any(axis=1)
        faces = index_map[F[keep_f]]
    return CorruptionResult(V[kept].copy(), faces, removed, index_map, kept, labels)


def remove_vertices(V, F=None, *, fraction: float, rng=None) -> CorruptionResult:
    """Remove a uniformly random subset of ``round(fraction * n)`` vertices (without replacement).

    Faces that touch a removed vertex are dropped; the other faces are re-indexed. Works on point
    clouds too (``F`` None). See :class:`CorruptionResult` for the ground truth returned.
    """
    V = as_points(V, "V")
    if F is not None:
        F = as_faces(F, V.shape[0], "F")
    fraction = check_fraction(fraction)
    rng = as_rng(rng)
    n = V.shape[0]
    removed = np.zeros(n, dtype=bool)
    removed[rng.choice(n, size=int(round(fraction * n)), replace=False)] = True
    return _apply_removal(V, F, removed)


def make_holes(V, F, *, n_holes: int = 1, size: float = 0.05, rng=None) -> CorruptionResult:
    """Cut ``n_holes`` holes, each removing ``round(size * n)`` vertices around a random seed.

    Each hole is grown from a random (not yet removed) seed vertex and takes the vertices nearest to
    it in graph-geodesic distance (Dijkstra on the edge graph weighted by edge lengths), so it is
    one connected patch on the surface; holes may touch or merge. ``labels`` gives the hole of every
    removed vertex (-1 for kept ones).

    Parameters
    ----------
    V : (n, 3) array_like
    F : (m, 3) array_like of int
    n_holes : int
        Number of holes, >= 1.
    size : float
        Fraction of the vertices removed per hole, in (0, 1]; ``n_holes * size`` must not exceed 1.
    rng : int, Generator or None
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_positive(n_holes, "n_holes", integer=True)
    if isinstance(size, bool) or not isinstance(size, int | float | np.integer | np.floating):
        raise InvalidInputError(f"`size` must be a number in (0, 1]; got {size!r}.")
    if not np.isfinite(size) or size <= 0 or size > 1:
        raise InvalidInputError(f"`size` must be in (0, 1]; got {size!r}.")
    if n_holes * size > 1:
        raise InvalidInputError(
            f"`n_holes` * `size` must be <= 1 (the holes would remove more than every vertex); "
            f"got {n_holes} * {size}."
        )
    rng = as_rng(rng)
    n = V.shape[0]
    per_hole = max(1, int(round(size * n)))
    E = unique_edges(F, n)
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    w = np.maximum(w, 1e-300)  # zero-length edges still connect
    G = sp.csr_matrix(
        (np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
    )
    labels = np.full(n, -1, dtype=np.int64)
    for h in range(n_holes):
        free = np.flatnonzero(labels < 0)
        seed = int(free[rng.integers(free.size)])
        dist = dijkstra(G, directed=False, indices=seed)
        dist[labels >= 0] = np.inf
        order = np.argsort(dist, kind="stable")
        take = order[:per_hole]
        take = take[np.isfinite(dist[take])]  # stay in the seed's connected component
        labels[take] = h
    return _apply_removal(V, F, labels >= 0, labels)


#: Outlier patterns of :func:`corrupt_outliers`.
OUTLIER_PATTERNS = ("uniform", "halo", "blobs", "flying", "lidar", "mixed")


def corrupt_outliers(
    P,
    *,
    pattern: str = "uniform",
    fraction: float = 0.1,
    rng=None,
    viewpoint=None,
    margin: float = 0.1,
    shuffle: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Append ``round(fraction * n)`` labelled outliers of a given spatial pattern to a cloud.

    Distances are in units of the point spacing ``s`` (the mean nearest-neighbour distance of
    ``P``, as in :func:`add_outliers`); ``diag`` is the bounding-box diagonal of ``P``.

    Parameters
    ----------
    P : (n, 3) array_like
        Clean points (the inliers), ``n >= 11`` for the patterns that use neighbourhoods.
    pattern : str
        One of :data:`OUTLIER_PATTERNS`.
    fraction : float
        Outliers relative to the number of inliers, >= 0 (``labels.sum() == round(fraction * n)``).
    rng : int, Generator or None
    viewpoint : (3,) array_like, optional
        Sensor position for ``"flying"`` and ``"lidar"``. Default: ``centroid + 2 diag u`` with
        ``u`` the smallest principal axis of ``P`` (sign fixed: largest-magnitude entry positive),
        i.e. a sensor looking at the cloud across its thinnest extent.
    margin : float
        Bounding-box enlargement (fraction of ``diag``) of ``"uniform"``, ``"blobs"``, ``"mixed"``.
    shuffle : bool
        True (default): all rows permuted with ``rng``; False: outliers appended after ``P``.

    Returns
    -------
    P_out : (n + m, 3) float64
    labels : (n + m,) bool
        True for the injected outliers.

    Notes
    -----
    Patterns:

    ``"uniform"``
        Uniform in the bounding box of ``P`` enlarged on every side by ``margin * diag``.
    ``"halo"``
        A random inlier (with replacement) displaced by ``U(2, 20) s`` along a uniformly random
        unit direction (so within 2-20 spacings of its inlier, possibly nearer the surface).
    ``"blobs"``
        Clustered outliers: clusters of 10-50 points (the last one smaller), each an isotropic
        Gaussian of standard deviation ``U(2, 5) s`` around a centre uniform in the enlarged
        bounding box.
    ``"flying"``
        Flying pixels of range sensors: a random inlier, drawn with probability proportional to
        its local depth range (the spread of the depths of its 10 nearest neighbours seen from
        ``viewpoint``, plus a floor of ``s``), so depth edges give most of them, moved along its
        sensor ray (the line from ``viewpoint``) by ``+-U(2, 30) s`` (random sign).
    ``"lidar"``
        Structured LiDAR artefacts, half each: *multipath* returns -- a random inlier moved
        *behind* its surface along its sensor ray by ``U(5, 50) s``; *vegetation-like scatter* --
        a random inlier moved ``U(2, 10) s`` along a random direction in the hemisphere of its
        PCA normal that faces ``viewpoint``.
    ``"mixed"``
        Half ``"uniform"``, half a halo at ``U(5, 15) s`` (the case of the outlier issue).
    """
    P = as_points(P, "P")
    check_choice(pattern, "pattern", OUTLIER_PATTERNS)
    _check_fraction(fraction)
    check_positive(margin, "margin", allow_zero=True)
    rng = as_rng(rng)
    n = P.shape[0]
    if n < 11:
        raise InvalidInputError(f"`P` needs at least 11 points for outlier patterns; got {n}.")
    m = int(round(float(fraction) * n))
    s = mean_spacing(P, None)
    lo, hi = P.min(axis=0), P.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    pad = margin * diag

    def uniform(c: int) -> np.ndarray:
        return rng.uniform(lo - pad, hi + pad, size=(c, 3))

    def halo(c: int, a: float, b: float) -> np.ndarray:
        return P[rng.integers(0, n, size=c)] + rng.uniform(a, b, (c, 1)) * s * _unit(rng, c)

    if pattern in ("flying", "lidar"):
        vp = _viewpoint(P, diag) if viewpoint is None else np.asarray(viewpoint, dtype=np.float64)
        if vp.shape != (3,) or not np.isfinite(vp).all():
            raise InvalidInputError(f"`viewpoint` must be 3 finite numbers; got {viewpoint!r}.")
    if pattern == "uniform":
        Q = uniform(m)
    elif pattern == "halo":
        Q = halo(m, 2.0, 20.0)
    elif pattern == "mixed":
        Q = np.concatenate([uniform(m // 2), halo(m - m // 2, 5.0, 15.0)])
    elif pattern == "blobs":
        parts, left = [], m
        while left > 0:
            c = min(left, int(rng.integers(10, 51)))
            centre = uniform(1)
            parts.append(centre + rng.uniform(2.0, 5.0) * s * rng.standard_normal((c, 3)))
            left -= c
        Q = np.concatenate(parts) if parts else np.empty((0, 3))
    elif pattern == "flying":
        from scipy.spatial import cKDTree

        ray = P - vp
        depth = np.linalg.norm(ray, axis=1)
        _, nb = cKDTree(P).query(P, k=11)
        w = np.ptp(depth[nb], axis=1) + s
        base = rng.choice(n, size=m, p=w / w.sum())
        sign = rng.choice([-1.0, 1.0], size=(m, 1))
        u = ray[base] / np.maximum(depth[base], 1e-300)[:, None]
        Q = P[base] + sign * rng.uniform(2.0, 30.0, (m, 1)) * s * u
    else:  # lidar
        from scipy.spatial import cKDTree

        half = m // 2
        base = rng.integers(0, n, size=half)
        ray = P[base] - vp
        u = ray / np.maximum(np.linalg.norm(ray, axis=1), 1e-300)[:, None]
        multi = P[base] + rng.uniform(5.0, 50.0, (half, 1)) * s * u
        base = rng.integers(0, n, size=m - half)
        _, nb = cKDTree(P).query(P[base], k=11)
        Y = P[nb] - P[nb].mean(axis=1, keepdims=True)
        _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", Y, Y))
        nrm = vec[:, :, 0]
        nrm *= np.where(np.einsum("ij,ij->i", nrm, vp - P[base]) < 0, -1.0, 1.0)[:, None]
        d = _unit(rng, m - half)
        d *= np.where(np.einsum("ij,ij->i", d, nrm) < 0, -1.0, 1.0)[:, None]
        veg = P[base] + rng.uniform(2.0, 10.0, (m - half, 1)) * s * d
        Q = np.concatenate([multi, veg])
    out = np.concatenate([P, Q])
    labels = np.r_[np.zeros(n, dtype=bool), np.ones(Q.shape[0], dtype=bool)]
    if shuffle:
        perm = rng.permutation(out.shape[0])
        out, labels = out[perm], labels[perm]
    return out, labels


def _unit(rng: np.random.Generator, c: int) -> np.ndarray:
    d = rng.standard_normal((c, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _viewpoint(P: np.ndarray, diag: float) -> np.ndarray:
    c = P.mean(axis=0)
    _, vec = np.linalg.eigh(np.cov((P - c).T))
    u = vec[:, 0]
    if u[np.argmax(np.abs(u))] < 0:
        u = -u
    return c + 2.0 * max(diag, 1e-300) * u
