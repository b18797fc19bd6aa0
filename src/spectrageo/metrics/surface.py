"""Exact point-to-surface distances, Hausdorff and Chamfer distances, F-score (model units).

A bounding-volume hierarchy (numba) finds the exact closest surface point; ties keep the smallest
triangle index. A mesh is sampled at its referenced vertices, edge midpoints and face centroids
with the weights of the 7-point degree-3 triangle quadrature rule (:func:`surface_samples`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive, deprecated_flag
from . import _kernels

_LEAF_SIZE = 4
_CHUNK = 1 << 18

#: Weights of the 7-point, degree-3 triangle quadrature rule (fractions of the face area).
_W_CORNER, _W_MIDPOINT, _W_CENTROID = 3.0 / 60.0, 8.0 / 60.0, 27.0 / 60.0

#: Keys returned by :func:`compare_surfaces`, in order.
SURFACE_KEYS = (
    "hd_mean",
    "hd_max",
    "chamfer",
    "fscore",
    "precision",
    "recall",
    "fscore_radius",
    "hd_mean_to_reference",
    "hd_max_to_reference",
    "hd_mean_to_result",
    "hd_max_to_result",
    "n_points_result",
    "n_points_reference",
)


@dataclass(frozen=True, eq=False)
class SurfaceDistance:
    """``distances`` (q,), ``face_index`` (q,) and ``closest_points`` (q, 3) or None."""

    distances: np.ndarray
    face_index: np.ndarray
    closest_points: np.ndarray | None = None


class _TriangleIndex:
    """BVH over the triangles of one mesh (module notes)."""

    def __init__(self, V: np.ndarray, F: np.ndarray) -> None:
        self.V = V
        self.keep = _distinct_triangles(V, F)  # None: every triangle is distinct
        self.F = F if self.keep is None else F[self.keep]
        tri = V[self.F]
        (
            self.order,
            nmin,
            nmax,
            left,
            right,
            start,
            count,
            n_nodes,
            self.depth,
        ) = _kernels.build_bvh(tri.min(axis=1), tri.max(axis=1), tri.mean(axis=1), _LEAF_SIZE)
        self.nmin, self.nmax = nmin[:n_nodes].copy(), nmax[:n_nodes].copy()
        self.left, self.right = left[:n_nodes].copy(), right[:n_nodes].copy()
        self.start, self.count = start[:n_nodes].copy(), count[:n_nodes].copy()

    def query(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances (q,) and closest triangle indices (q,) of the points ``Q``."""
        best_d2 = np.full(Q.shape[0], np.inf)
        best_t = np.full(Q.shape[0], -1, dtype=np.int64)
        _kernels.bvh_query(
            Q, self.V, self.F, self.order, self.nmin, self.nmax, self.left, self.right,
            self.start, self.count, self.depth, best_d2, best_t,
        )  # fmt: skip
        if self.keep is not None:
            best_t = self.keep[best_t]
        return np.sqrt(best_d2), best_t


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser, elementwise on uint64."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _distinct_triangles(V: np.ndarray, F: np.ndarray) -> np.ndarray | None:
    """Indices of the first of each group of triangles with the same three corner positions
    (in any order), or None when all are distinct. Coincident copies (instanced scenes, stacked
    soups) change no distance but make every query visit each copy. Groups are found by a hash
    and confirmed coordinate by coordinate, so only exact copies are left out."""
    if F.shape[0] < 2:
        return None
    bits = np.ascontiguousarray(V, dtype=np.float64).view(np.uint64)
    hv = _mix(_mix(_mix(bits[:, 0]) ^ bits[:, 1]) ^ bits[:, 2])
    hf = hv[F]
    corner = np.argsort(hf, axis=1, kind="stable")
    hs = np.take_along_axis(hf, corner, axis=1)
    key = _mix(_mix(_mix(hs[:, 0]) ^ hs[:, 1]) ^ hs[:, 2])
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    if first.all():
        return None
    rep = order[np.maximum.accumulate(np.where(first, np.arange(ks.size), 0))]
    canon = np.take_along_axis(F, corner, axis=1)
    same = np.all(V[canon[order]] == V[canon[rep]], axis=(1, 2))  # exact, not only the hash
    drop = np.zeros(F.shape[0], dtype=bool)
    drop[order] = same & ~first
    return None if not drop.any() else np.flatnonzero(~drop)


def point_to_surface(
    P,
    V_ref,
    F_ref,
    *,
    return_closest: bool | None = None,
) -> SurfaceDistance:
    """Exact distance from each point of ``P`` (q, 3) to the triangle surface ``(V_ref, F_ref)``.

    Degenerate triangles count as the union of their edges. Returns a :class:`SurfaceDistance`
    without ``closest_points`` (:func:`point_to_surface_closest` adds them; ``return_closest``
    is deprecated).
    """
    if return_closest is not None:
        deprecated_flag("point_to_surface", "return_closest", "point_to_surface_closest()")
    return _point_to_surface(P, V_ref, F_ref, bool(return_closest))


def point_to_surface_closest(P, V_ref, F_ref) -> SurfaceDistance:
    """:func:`point_to_surface` with the closest surface points (q, 3) in ``closest_points``."""
    return _point_to_surface(P, V_ref, F_ref, True)


def _point_to_surface(P, V_ref, F_ref, closest: bool) -> SurfaceDistance:
    P = as_points(P, "P")
    V_ref = as_points(V_ref, "V_ref")
    F_ref = as_faces(F_ref, V_ref.shape[0], "F_ref")
    d, t = _TriangleIndex(V_ref, F_ref).query(P)
    cp = _kernels.closest_points(P, t, V_ref, F_ref) if closest else None
    return SurfaceDistance(d, t, cp)


def surface_distance_per_vertex(V, V_ref, F_ref) -> np.ndarray:
    """Exact distance (n,) from each vertex of ``V`` to the reference surface."""
    return point_to_surface(V, V_ref, F_ref).distances


@dataclass(frozen=True)
class HausdorffResult:
    """:func:`hausdorff`: ``hd_mean`` (the thesis's HD), ``hd_max``, their reverse and ``hd_symmetric``."""

    hd_mean: float
    hd_max: float
    hd_mean_reverse: float | None = None
    hd_max_reverse: float | None = None
    hd_symmetric: float | None = None

    def as_dict(self) -> dict[str, float | None]:
        return {
            "hd_mean": self.hd_mean,
            "hd_max": self.hd_max,
            "hd_mean_reverse": self.hd_mean_reverse,
            "hd_max_reverse": self.hd_max_reverse,
            "hd_symmetric": self.hd_symmetric,
        }


def hausdorff(V, F, V_ref, F_ref, *, symmetric: bool = True) -> HausdorffResult:
    """Vertex-to-surface Hausdorff distances between ``(V, F)`` and ``(V_ref, F_ref)`` (Section 4.9).

    The meshes need not correspond; vertices used by no face are left out. ``F`` None (a point
    cloud) or ``symmetric=False`` gives the one-sided values only. The ``hd_*`` keys of
    :func:`compare` and :func:`compare_surfaces` also sample edge midpoints and centroids.
    Returns a :class:`HausdorffResult`.
    """
    V = as_points(V, "V")
    V_ref = as_points(V_ref, "V_ref")
    F_ref = as_faces(F_ref, V_ref.shape[0], "F_ref")
    Q = V
    if F is not None:
        F = as_faces(F, V.shape[0], "F")
        Q = V[_referenced(F, V.shape[0])]
    d = _TriangleIndex(V_ref, F_ref).query(Q)[0]
    fwd_mean, fwd_max = float(d.mean()), float(d.max())
    if not symmetric or F is None:
        return HausdorffResult(fwd_mean, fwd_max)
    r = _TriangleIndex(V, F).query(V_ref[_referenced(F_ref, V_ref.shape[0])])[0]
    rev_mean, rev_max = float(r.mean()), float(r.max())
    return HausdorffResult(fwd_mean, fwd_max, rev_mean, rev_max, max(fwd_max, rev_max))


# --------------------------------------------------------------------------- symmetric comparison
def _referenced(F: np.ndarray, n: int) -> np.ndarray:
    """Indices of the vertices used by at least one face, ascending."""
    return np.flatnonzero(np.bincount(F.ravel(), minlength=n))


class _Side:
    """A mesh (sampled as in :func:`surface_samples`) or a point cloud, with its sample weights."""

    def __init__(self, V: np.ndarray, F: np.ndarray | None, *, like: _Side | None = None) -> None:
        """``like``: a side with the same ``F`` whose vertex and edge lists are reused."""
        self.V, self.F = V, F
        self._index: Any = None
        if F is None:
            self.used = None
            self.n_samples = V.shape[0]
            self.weights = None  # equal weights
            return
        n, m = V.shape[0], F.shape[0]
        if like is not None:
            self.used, self.E, inv = like.used, like.E, like._inv
        else:
            self.used = _referenced(F, n)
            a = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
            key = a[:, 0] * np.int64(n) + a[:, 1]  # (3m,): all faces' edge 0, then 1, then 2
            ukey, inv = np.unique(key, return_inverse=True)
            self.E = np.stack([ukey // n, ukey % n], axis=1)
        self._inv = inv
        area = 0.5 * np.linalg.norm(
            np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1
        )
        total = float(area.sum())
        self.n_samples = self.used.size + self.E.shape[0] + m
        if total > 0.0 and np.isfinite(total):
            wv = np.bincount(F.ravel(), weights=np.repeat(area * _W_CORNER, 3), minlength=n)
            we = np.bincount(inv, weights=np.tile(area * _W_MIDPOINT, 3), minlength=len(self.E))
            self.weights = np.concatenate([wv[self.used], we, area * _W_CENTROID]) / total
        else:  # every face degenerate: no area to weight by, plain mean over the samples
            self.weights = np.full(self.n_samples, 1.0 / self.n_samples)

    def bbox_diagonal(self) -> float:
        P = self.V if self.used is None else self.V[self.used]
        return float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))

    def sample_chunks(self):
        """The sample points in order (vertices, edge midpoints, centroids), in chunks."""
        V = self.V
        if self.F is None:
            for s in range(0, V.shape[0], _CHUNK):
                yield V[s : s + _CHUNK]
            return
        for s in range(0, self.used.size, _CHUNK):
            yield V[self.used[s : s + _CHUNK]]
        for s in range(0, self.E.shape[0], _CHUNK):
            e = self.E[s : s + _CHUNK]
            yield 0.5 * (V[e[:, 0]] + V[e[:, 1]])
        for s in range(0, self.F.shape[0], _CHUNK):
            f = self.F[s : s + _CHUNK]
            yield (V[f[:, 0]] + V[f[:, 1]] + V[f[:, 2]]) / 3.0

    def distances_to(self, Q: np.ndarray) -> np.ndarray:
        """Exact distance from the points ``Q`` to this side."""
        if self._index is None:
            if self.F is None:
                from scipy.spatial import cKDTree

                self._index = cKDTree(self.V)
            else:
                self._index = _TriangleIndex(self.V, self.F)
        if self.F is None:
            return self._index.query(Q, k=1, workers=-1)[0]
        return self._index.query(Q)[0]


def _one_sided(src: _Side, tgt: _Side) -> np.ndarray:
    """Distance from every sample of ``src`` to ``tgt``."""
    d = np.empty(src.n_samples)
    pos = 0
    for Q in src.sample_chunks():
        d[pos : pos + Q.shape[0]] = tgt.distances_to(np.ascontiguousarray(Q))
        pos += Q.shape[0]
    return d


def _mean(d: np.ndarray, w: np.ndarray | None) -> float:
    return float(d.mean() if w is None else d @ w)


def _fraction_within(d: np.ndarray, w: np.ndarray | None, radius: float) -> float:
    """Weighted fraction of ``d <= radius``; exactly 0 or 1 when none or all are within."""
    inside = d <= radius
    n_in = int(inside.sum())
    if n_in == 0 or n_in == d.size:
        return float(n_in > 0)
    return float(n_in / d.size if w is None else min(w[inside].sum(), 1.0))


def _symmetric(res: _Side, ref: _Side, radius: float | None = None) -> dict[str, Any]:
    """The :data:`SURFACE_KEYS` statistics (the F-score ones only with ``radius``)."""
    d_fwd = _one_sided(res, ref)  # result samples -> reference
    d_bwd = _one_sided(ref, res)  # reference samples -> result
    m_fwd, m_bwd = _mean(d_fwd, res.weights), _mean(d_bwd, ref.weights)
    x_fwd, x_bwd = float(d_fwd.max()), float(d_bwd.max())
    out: dict[str, Any] = {
        "hd_mean": 0.5 * (m_fwd + m_bwd),
        "hd_max": max(x_fwd, x_bwd),
        "chamfer": 0.5 * (m_fwd + m_bwd),
    }
    if radius is not None:
        precision = _fraction_within(d_fwd, res.weights, radius)
        recall = _fraction_within(d_bwd, ref.weights, radius)
        den = precision + recall
        out["fscore"] = 2.0 * precision * recall / den if den > 0 else 0.0
        out["precision"], out["recall"] = precision, recall
        out["fscore_radius"] = float(radius)
    out.update(
        hd_mean_to_reference=m_fwd,
        hd_max_to_reference=x_fwd,
        hd_mean_to_result=m_bwd,
        hd_max_to_result=x_bwd,
        n_points_result=int(res.n_samples),
        n_points_reference=int(ref.n_samples),
    )
    return out


def _as_side(obj: Any, name: str) -> _Side:
    """A Mesh, a PointCloud, a ``(V, F)`` pair (``F`` None: a cloud) or an (n, 3) array."""
    from ..geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence

    if isinstance(obj, MeshAnimation | PointCloudSequence):
        raise InvalidInputError(
            f"`{name}` must be a mesh or a point cloud; got a {type(obj).__name__} (compare "
            "animations with `compare_animation`, or frame by frame)."
        )
    if isinstance(obj, Mesh):
        V, F = obj.vertices, obj.faces
    elif isinstance(obj, PointCloud):
        V, F = obj.points, None
    elif (
        isinstance(obj, tuple | list) and len(obj) == 2 and (obj[1] is None or np.ndim(obj[0]) == 2)
    ):
        V, F = obj
    else:
        V, F = obj, None
    V = as_points(V, name if F is None else f"{name} vertices")
    if F is not None:
        F = as_faces(F, V.shape[0], f"{name} faces", allow_empty=True)
        if F.shape[0] == 0:
            raise InvalidInputError(
                f"`{name}` has no faces, so no surface; pass `(V, None)` to compare its vertices "
                "as a point cloud."
            )
    return _Side(V, F)


def compare_surfaces(result, reference, *, radius: float | None = None) -> dict[str, Any]:
    """Symmetric distances between two surfaces or point clouds that need not correspond.

    With ``d_res`` the distances of the result's samples to the reference, ``d_ref`` the reverse and
    ``w`` the sample weights: ``hd_max = max(max d_res, max d_ref)``; ``hd_mean`` and ``chamfer``
    (not squared) the mean of the two weighted means; ``precision`` / ``recall`` the weight within
    ``radius`` and ``fscore = 2 P R / (P + R)`` (Knapitsch et al. 2017); the one-sided
    ``hd_{mean,max}_to_{reference,result}`` and ``n_points_{result,reference}``.

    Parameters
    ----------
    result, reference : Mesh, PointCloud, ``(V, F)``, ``(P, None)`` or (n, 3) array_like
    radius : float, optional
        F-score threshold; default 1 % of the reference's bounding-box diagonal.

    Returns
    -------
    dict
        The :data:`SURFACE_KEYS`.
    """
    res = _as_side(result, "result")
    ref = _as_side(reference, "reference")
    if radius is None:
        diag = ref.bbox_diagonal()
        if diag == 0.0:
            raise InvalidInputError(
                "`radius` is required: the reference has zero extent (all its points coincide), so "
                "1% of its bounding-box diagonal is 0."
            )
        radius = 0.01 * diag
    else:
        check_positive(radius, "radius")
    return _symmetric(res, ref, float(radius))


def surface_samples(V, F) -> tuple[np.ndarray, np.ndarray]:
    """Sample points (q, 3) of a mesh surface and their weights (q,) summing to 1 (:func:`compare_surfaces`).

    Referenced vertices, sorted unique edges' midpoints, face centroids; weights 3/60, 8/60 and 27/60
    of each face's area.
    """
    V = as_points(V, "V")
    side = _Side(V, as_faces(F, V.shape[0], "F"))
    return np.concatenate(list(side.sample_chunks())), side.weights.copy()
