"""Exact point-to-surface distances, Hausdorff distances, Chamfer distance and F-score.

The distance from a point ``q`` to a triangle mesh is the distance to the closest point of the
*surface* (any point of any triangle, not only the vertices). It is computed exactly with a
bounding-volume hierarchy (BVH) over the reference triangles, in numba:

* the tree splits triangles at the midpoint of the longest axis of their centroid bounds (leaves of
  at most 4 triangles), each node storing the axis-aligned box of its triangles;
* each query descends depth-first, nearer child first, testing leaf triangles with an exact
  point-triangle kernel (Voronoi regions of vertices, edges and interior) and skipping a node only
  when the distance to its box exceeds the best distance found so far. Since the box contains every
  point of its triangles, no closer triangle can be skipped: the result is exact (up to rounding),
  whatever the triangle sizes (a mix of tiny and huge triangles costs no correctness).

Memory is O(m) for the tree plus O(q) for the answers (no per-query candidate lists), so it scales to
meshes of millions of triangles; the 437,645-vertex dragon against itself takes a few seconds.

Exact ties between triangles keep the smallest triangle index, so results are deterministic.
Distances are in model units (no normalisation).

Symmetric surface distances (:func:`compare_surfaces`, and ``hd_*`` of
:func:`spectrageo.metrics.compare`) sample each side and measure the samples against the *other*
side exactly:

* a mesh is sampled by :func:`surface_samples`: its referenced vertices, the midpoint of every
  edge and the centroid of every face (deterministic; no random sampling). These are the nodes of
  the 7-point triangle quadrature rule exact for cubic polynomials (corner weight 3/60, edge
  midpoint 8/60, centroid 27/60 of the face area), so a weighted mean over them is the mean over the
  *surface* (area-weighted), and any surface point is within a third of its face's longest edge of
  a sample. Vertices used by no face are not part of the surface and are ignored on both sides.
* a point cloud is its points, each with the same weight.
* distances to a mesh are exact point-to-surface (the BVH above); to a point cloud, point-to-point
  (nearest neighbour, :class:`scipy.spatial.cKDTree`).

Queries run in chunks of at most ``2**18`` sample points, so memory beyond the two inputs is O(q)
floats for the distances.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
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
    """Closest-point query result.

    Attributes
    ----------
    distances : (q,) float64
        Euclidean distance from each query point to the surface.
    face_index : (q,) int64
        Index of a closest triangle (the smallest index among exact ties).
    closest_points : (q, 3) float64 or None
        The closest surface points (only when requested).
    """

    distances: np.ndarray
    face_index: np.ndarray
    closest_points: np.ndarray | None = None


class _TriangleIndex:
    """Reusable search structure over the triangles of one mesh (a BVH, see the module docstring)."""

    def __init__(self, V: np.ndarray, F: np.ndarray) -> None:
        self.V = V
        self.F = F
        tri = V[F]
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
        return np.sqrt(best_d2), best_t


def point_to_surface(
    P,
    V_ref,
    F_ref,
    *,
    return_closest: bool = False,
) -> SurfaceDistance:
    """Exact distance from each point of ``P`` to the triangle surface ``(V_ref, F_ref)``.

    Parameters
    ----------
    P : (q, 3) array_like
        Query points (e.g. the vertices of a result mesh).
    V_ref : (n, 3) array_like
    F_ref : (m, 3) array_like of int
        Reference triangle mesh. Degenerate triangles are treated as the union of their edges.
    return_closest : bool
        Also return the closest surface points.

    Returns
    -------
    SurfaceDistance
        ``distances`` (q,), ``face_index`` (q,), ``closest_points`` (q, 3) or None.

    Notes
    -----
    Exact up to floating-point rounding (BVH search, see the module docstring); model units.
    """
    P = as_points(P, "P")
    V_ref = as_points(V_ref, "V_ref")
    F_ref = as_faces(F_ref, V_ref.shape[0], "F_ref")
    d, t = _TriangleIndex(V_ref, F_ref).query(P)
    cp = _kernels.closest_points(P, t, V_ref, F_ref) if return_closest else None
    return SurfaceDistance(d, t, cp)


def surface_distance_per_vertex(V, V_ref, F_ref) -> np.ndarray:
    """Per-vertex exact distance from ``V`` to the reference surface, shape (n,) (heatmaps).

    The same values whose mean and max are ``hd_mean`` and ``hd_max`` of :func:`hausdorff`.
    """
    return point_to_surface(V, V_ref, F_ref).distances


@dataclass(frozen=True)
class HausdorffResult:
    """Hausdorff distances between a result mesh and a reference mesh (model units).

    Attributes
    ----------
    hd_mean, hd_max : float
        Mean and max over the result's vertices of the distance to the reference surface
        (one-sided, result -> reference; ``hd_mean`` is the thesis's HD, Section 4.9).
    hd_mean_reverse, hd_max_reverse : float or None
        The same from the reference's vertices to the result's surface (None when not computed).
    hd_symmetric : float or None
        ``max(hd_max, hd_max_reverse)``, the symmetric (vertex-sampled) Hausdorff distance.
    """

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
    """Exact vertex-to-surface Hausdorff distances between ``(V, F)`` and ``(V_ref, F_ref)``.

    The distance from every vertex of the result to the closest point of the reference *surface*
    (triangles), and, when ``symmetric`` and ``F`` is given, from every reference vertex to the result
    surface. The two meshes need not share connectivity or vertex count. Vertices used by no face
    are not part of a surface and are left out (of ``V`` only when ``F`` is given).

    This is the vertex-sampled variant (the thesis's HD is ``hd_mean``). The ``hd_mean`` / ``hd_max``
    of :func:`spectrageo.metrics.compare` and :func:`compare_surfaces` are symmetric and also sample
    edge midpoints and face centroids (see the module docstring).

    Parameters
    ----------
    V : (n, 3) array_like
        Result vertices.
    F : (m, 3) array_like of int or None
        Result faces; None (e.g. a point cloud) computes the one-sided values only.
    V_ref, F_ref : (n_ref, 3), (m_ref, 3)
        Reference mesh.
    symmetric : bool
        Also compute the reverse one-sided values and the symmetric maximum.

    Returns
    -------
    HausdorffResult
        ``hd_mean`` (thesis HD, Section 4.9), ``hd_max``, reverse values and ``hd_symmetric``.
        Model units (not normalised by the bounding box).
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
    """One side of a comparison: a mesh (sampled, see :func:`surface_samples`) or a point cloud.

    Holds the samples' weights (summing to 1; None for equal weights) and, lazily, the search
    structure of the side when it is the target of the other side's samples.
    """

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
        """Yield the sample points in order (vertices, edge midpoints, centroids), in chunks."""
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
        """Exact distance from the points ``Q`` to this side (surface or nearest point)."""
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
    """Distance from every sample of ``src`` to ``tgt``, shape (src.n_samples,)."""
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
    """The :data:`SURFACE_KEYS` statistics (F-score ones only when ``radius`` is given)."""
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
    """A Mesh, a PointCloud, a ``(V, F)`` pair (``F`` None for a point cloud) or an (n, 3) array."""
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

    Works between meshes of any resolution and connectivity, point clouds, and a mesh and a point
    cloud. Each side is sampled (a mesh: referenced vertices, edge midpoints and face centroids,
    area-weighted; a cloud: its points, equally weighted; see the module docstring) and the samples
    are measured against the other side: exactly to its surface when it is a mesh, to its nearest
    point when it is a point cloud.

    Parameters
    ----------
    result, reference : Mesh, PointCloud, ``(V, F)`` or ``(P, None)`` tuple, or (n, 3) array_like
        The two sides; a bare array is a point cloud.
    radius : float, optional
        F-score distance threshold in model units; default 1% of the diagonal of the reference's
        bounding box (of its referenced vertices or its points).

    Returns
    -------
    dict
        With ``d_res`` the distances of the result's samples to the reference, ``d_ref`` those of the
        reference's samples to the result, ``w`` the sample weights (summing to 1 per side) and
        ``mean_w`` the weighted mean (model units unless stated):

        * ``hd_max = max(max d_res, max d_ref)``: symmetric Hausdorff distance (over the samples).
        * ``hd_mean = (mean_w d_res + mean_w d_ref) / 2``: mean of the two one-sided means.
        * ``chamfer``: mean of the two mean nearest-neighbour (point-to-surface for meshes)
          distances, *not squared*; by these definitions it equals ``hd_mean``.
        * ``precision = sum of w over d_res <= radius``, ``recall`` the same for ``d_ref``,
          ``fscore = 2 P R / (P + R)`` (0 when both are 0), all in [0, 1] (Knapitsch et al. 2017,
          *Tanks and Temples*, with ``<=`` and area weights for meshes); ``fscore_radius``.
        * ``hd_mean_to_reference``, ``hd_max_to_reference`` (from ``d_res``),
          ``hd_mean_to_result``, ``hd_max_to_result`` (from ``d_ref``): the one-sided values.
        * ``n_points_result``, ``n_points_reference``: samples compared per side (int).

        Swapping ``result`` and ``reference`` leaves ``hd_*``, ``chamfer`` and (for a fixed
        ``radius``) ``fscore`` unchanged and swaps precision and recall.

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN, a mesh without faces, an animation or sequence, a non-positive radius, or
        no radius given for a reference of zero extent.
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
    """The sample points of a mesh surface used by :func:`compare_surfaces`, and their weights.

    Parameters
    ----------
    V : (n, 3) array_like
    F : (m, 3) array_like of int

    Returns
    -------
    points : (q, 3) float64
        The referenced vertices (ascending index), then the midpoints of the unique edges (sorted
        by ``(i, j)``, ``i <= j``), then the face centroids (face order);
        ``q = n_referenced + n_edges + m``.
    weights : (q,) float64
        Area weights of the 7-point degree-3 quadrature rule (corner 3/60, edge midpoint 8/60,
        centroid 27/60 of each face's area, summed over the faces sharing a sample), divided by the
        total area, so they sum to 1 and ``points``-weighted means are surface means. Equal weights
        when every face has zero area.
    """
    V = as_points(V, "V")
    side = _Side(V, as_faces(F, V.shape[0], "F"))
    return np.concatenate(list(side.sample_chunks())), side.weights.copy()
