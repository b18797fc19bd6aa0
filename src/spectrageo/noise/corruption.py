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
    """Outlier fractions may exceed 1 (they are relative to the clean point count)."""
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
    """Append ``round(fraction * n)`` outliers to a point cloud; returns the points and the outlier labels.

    ``kind="far"``: uniform in the bounding box enlarged by ``margin`` diagonals; ``"near"``: a random
    inlier moved by ``distance`` point spacings along a random direction (or its ``normals``).
    Outliers follow ``P`` unless ``shuffle``.
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
    """A mesh with missing vertices and its ground truth.

    ``vertices`` and ``faces``: the kept vertices in order and the faces among them, re-indexed;
    ``removed`` (n,) bool; ``index_map`` (n,): new index of every vertex, -1 where removed; ``kept``:
    original indices of the kept vertices; ``labels``: the hole of every removed vertex, -1 elsewhere.
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
    """Remove ``round(fraction * n)`` random vertices and the faces touching them."""
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
    """Cut ``n_holes`` holes of ``round(size * n)`` vertices, each the graph-geodesic nearest to a random seed."""
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
    """Append ``round(fraction * n)`` labelled outliers of one :data:`OUTLIER_PATTERNS` ``pattern``.

    With ``s`` the mean point spacing: ``"uniform"`` in the bounding box enlarged by ``margin``
    diagonals; ``"halo"`` an inlier moved ``U(2, 20) s``; ``"blobs"`` Gaussian clusters of 10-50
    points of deviation ``U(2, 5) s``; ``"flying"`` inliers near depth edges moved ``+-U(2, 30) s``
    along the ray from ``viewpoint``; ``"lidar"`` half multipath (``U(5, 50) s`` behind), half
    scatter towards the sensor; ``"mixed"`` half uniform, half a ``U(5, 15) s`` halo. ``viewpoint``
    defaults to two diagonals along the thinnest principal axis. Returns ``(P_out, labels)``,
    shuffled unless ``shuffle=False``.
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
