"""Do-no-harm guard of the static denoisers (not in the thesis): a curvature-robust noise level, a
white-noise test, the repair of sparse impulses and the trust region.

With ``s(k)`` the chi-square calibrated lower quartile of the per-vertex quadric-fit residual
variances ``RSS / (k - 6)`` over ``k``-vertex patches, ``r`` the median patch radius, ``V' = W V``
one step of the 10-neighbour mean, ``N(i)`` the one-ring and ``n_i`` the vertex normal::

    (N1)  sigma^2 = s(k), level = sigma / r         (N2)  G = s(1.5 k) / s(k)
    (N3)  S = s(k; V') / s(k; V)                    (N4)  T = q_0.10(res) / q_0.25(res)
    (N5)  r_i = n_i . (v_i - mean_{N(i)} v_j)       (N6)  s_i = r_i - median_{N(i)} r_j
    (N7)  spike: |s_i| > c sigma_s, a ring maximum, no same-sign neighbour above rho |s_i|,
          more than three distinct face normals around i
    (N8)  v_i <- v_i - s_i / (1 + 1/d_i) n_i
    (N9)  p = share of edge-sharing face pairs whose normals agree within PLANAR_DEG
    (N10) f = share of edge-sharing face pairs whose normals differ by more than FOLD_DEG
    (N11) u_i = n_i . (v_i - mean_{N(i)} v_j) / l_i
    (N12) c = sum_edges u_i u_j / (1/2 sum_edges (u_i^2 + u_j^2))
    (N13) o = median_i |(u_i + sum_{N(i)} u_j) / (1 + |N(i)|)|

A residual is detail, not noise, when ``G``, ``S`` and ``T`` all reach their thresholds; a mesh
is coarse when ``o`` and ``c`` do. Rules and measurements: docs/decisions.md#denoise-gate-notes
(also #denoise-gate-level, #denoise-gate-detail-test, #denoise-ring-patches,
#denoise-impulse-repair, #denoise-planar-rule, #denoise-fold-rule, #coarse-meshes)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.special import gammaincinv

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ..geometry import face_normals, mean_edge_length, vertex_face_matrix
from ..geometry._numba_kernels import (
    few_face_planes,
    isolated_spikes,
    neighbour_median_residual,
    patch_min_variance,
    patch_quadric_residual,
)
from ..geometry.primitives import _normalize_rows
from ..graph.adjacency import adjacency_matrix, face_adjacency, knn
from .smoothing import taubin

#: default gate (relative noise level below which a mesh counts as clean); chosen on the
#: tuning split, see docs/decisions.md#denoise-gate-level
MIN_NOISE = 0.015
#: default trust radius in noise standard deviations (Eq. 5.15)
TRUST = 6.0
#: detail test, growth: a residual whose lower-quartile variance grows by at least this factor
#: from ``patch`` to ``1.5 * patch`` neighbours is not white; chosen on the tuning split, see
#: docs/decisions.md#gate-constants
MIN_GROWTH = 1.57
#: detail test, smoothing: ... which keeps at least this fraction of its variance after one
#: step of the uniform kNN Laplacian; chosen on the tuning split, see
#: docs/decisions.md#gate-constants
MIN_SURVIVAL = 0.093
#: detail test, tail: ... and whose 10 %-quantile of per-patch residual variances is at least
#: this fraction of the 25 %-quantile (sparse impulses leave many exact patches); chosen on the
#: tuning split, see docs/decisions.md#gate-constants
MIN_TAIL = 0.25
#: lower-tail ratio (Eq. N4) below which a residual without impulses is left alone; see the
#: docs/decisions.md#denoise-sparse-tail
SPARSE_TAIL = 0.12
#: sparse impulses (Eq. N7): a spike's offset exceeds this many robust deviations of all offsets
SPIKE_THRESHOLD = 4.0
#: ... and no neighbour's offset of the same sign reaches this fraction of it
SPIKE_ISOLATION = 0.5
#: the repair runs when the first pass flags at least this share of the vertices
SPIKE_SHARE = 0.01
#: on a mesh the gate calls clean, the repair is kept when its first pass flags at least this
#: share (docs/decisions.md#denoise-quiet-impulses)
SPIKE_SHARE_QUIET = 0.02
#: ... and at least this many vertices (a small clean model's own sharp or irregular vertices
#: reach the share: the 12 valence-5 vertices of a 42-vertex icosphere)
SPIKE_COUNT_QUIET = 20
#: ... and never one smaller than this fraction of the mean edge length (regular samplings)
SPIKE_FLOOR = 0.02
#: faces whose unit normals agree within this angle (degrees) lie in one plane (Eq. N7); chosen
#: on the tuning split, see docs/decisions.md#gate-constants
SPIKE_PLANE_DEG = 0.5
#: passes of the repair (adjacent spikes hide each other)
SPIKE_PASSES = 3
#: planar tessellation test (Eq. N9): two faces sharing an edge whose unit normals agree within
#: this angle (degrees) are coplanar
PLANAR_DEG = 0.1
#: ... and a mesh in which at least this share of the face pairs are coplanar carries no dense
#: noise (docs/decisions.md#denoise-planar-rule)
PLANAR_SHARE = 0.11
#: folded-mesh test (Eq. N10): two faces sharing an edge whose unit normals differ by more than
#: this angle (degrees) fold over each other
FOLD_DEG = 120.0
#: ... and a mesh in which at least this share of the face pairs fold is too noisy for the
#: normal filters: it is smoothed by :func:`unfold` (docs/decisions.md#denoise-fold-rule)
FOLD_SHARE = 0.14
#: ... counted on meshes of at least this many vertices (a handful of faces turn sharply as
#: their shape: half the face pairs of a corner tetrahedron turn by 125 degrees)
FOLD_MIN_VERTICES = 50
#: :func:`unfold` stops once the share of folded pairs is below this
FOLD_STOP = 0.005
#: Taubin lambda|mu steps of the low-pass that :func:`unfold` and TSGSP's curved-surface finish
#: (reading choice (g) of :func:`spectrageo.denoise.tsgsp.fine`) apply: the setting the
#: protocol's tuning split chose for the Taubin peers (pass band 0.09)
LOWPASS_LAM = 0.33
LOWPASS_MU = -0.34
#: :func:`unfold`: Taubin lambda|mu pairs per block, at most ``FOLD_BLOCKS`` blocks
FOLD_PAIRS = 5
FOLD_BLOCKS = 10
#: neighbours averaged by the smoothing step of the detail test
SMOOTH_NEIGHBORS = 10
#: a Euclidean patch whose minimum-variance direction has a mean ``|cos|`` below this with the
#: vertex normals of its points lies across the surface (docs/decisions.md#denoise-ring-patches);
#: chosen on the tuning split, see docs/decisions.md#gate-constants
MISALIGNED_COS = 0.3
#: share of such patches from which the estimate uses graph-ring patches instead; chosen on the
#: tuning split, see docs/decisions.md#gate-constants
MISALIGNED_SHARE = 0.5

#: coarse-mesh test (Eq. N13): one-ring mean of the umbrella offsets per edge length at or above
#: this (median over the vertices) is shape, not noise; chosen on the tuning split, see
#: docs/decisions.md#coarse-meshes
COARSE_OFFSET = 0.12
#: ... together with an edge correlation of the offsets (Eq. N12) at or above this; chosen on the
#: tuning split, see docs/decisions.md#coarse-meshes
COARSE_CORR = 0.28


@dataclass(frozen=True)
class NoiseEstimate:
    """Result of :func:`noise_estimate` (Eqs. N1-N4); NaN where not computed."""

    sigma: float
    level: float
    raw_level: float
    growth: float
    survival: float
    tail: float
    detail: bool
    patches: str = "knn"


def ring_patches(V: np.ndarray, F: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest vertices of each vertex among its graph rings; ``(idx, dist)`` like ``knn``."""
    n = V.shape[0]
    A = adjacency_matrix(F, n).tocsr()
    A = (A + sp.identity(n, format="csr")).tocsr()
    A.data[:] = 1.0
    S = A
    for _ in range(5):
        if int(np.diff(S.indptr).min()) >= k:
            break
        S = (S @ A).tocsr()
        S.data[:] = 1.0
    counts = np.diff(S.indptr)
    rows = np.repeat(np.arange(n), counts)
    cols = S.indices
    dist = np.linalg.norm(V[cols] - V[rows], axis=1)
    order = np.lexsort((cols != rows, dist, rows))  # per row: by distance, the vertex itself first
    cols, dist = cols[order], dist[order]
    take = S.indptr[:-1, None] + np.arange(k)[None, :]
    short = counts < k
    take[short] = S.indptr[:-1][short, None]  # placeholder rows, replaced below
    idx = cols[take]
    d = dist[take]
    if short.any():
        i2, d2 = knn(V, k, include_self=True)
        idx[short], d[short] = i2[short], d2[short]
    return idx, d


def _min_variance_dirs(V: np.ndarray, idx: np.ndarray) -> np.ndarray:
    n = V.shape[0]
    lam = np.empty(n)
    dirs = np.empty((n, 3))
    patch_min_variance(V, idx, lam, dirs)
    return dirs


def _misaligned_share(V: np.ndarray, F: np.ndarray, idx: np.ndarray, dirs: np.ndarray) -> float:
    from ..geometry import vertex_normals

    N = vertex_normals(V, F)
    a = np.abs(np.einsum("nkj,nj->nk", N[idx], dirs)).mean(axis=1)
    return float(np.mean(a < MISALIGNED_COS))


def _residuals(V: np.ndarray, idx: np.ndarray, dirs: np.ndarray | None = None) -> np.ndarray:
    """Per-vertex quadric residual variance ``RSS / (k - 6)`` over the patches ``idx``."""
    if dirs is None:
        dirs = _min_variance_dirs(V, idx)
    n = V.shape[0]
    res = np.empty(n)
    spread = np.empty(n)
    patch_quadric_residual(V, idx, dirs, res, spread)
    return res


def _calibrated(res: np.ndarray, quantile: float, dof: int) -> float:
    """Chi-square calibrated ``quantile`` of the finite residual variances (Eq. N1)."""
    ok = np.isfinite(res)
    if not ok.any():
        return 0.0
    q = float(np.quantile(np.maximum(res[ok], 0.0), quantile))
    # chi-square quantile: chi2.ppf(q, dof) = 2 gammaincinv(dof / 2, q) (scipy.stats costs 0.25 s
    # of import time for every command that denoises)
    return q / (2.0 * gammaincinv(0.5 * dof, quantile) / dof)


def noise_estimate(V, *, F=None, patch: int = 16, quantile: float = 0.25) -> NoiseEstimate:
    """Curvature-robust noise estimate and white-noise test (Eqs. N1-N4) of the surface sampled by
    ``V``: ``patch`` (>= 7) is ``k``, ``quantile`` the residual quantile in (0, 1); with faces ``F``,
    graph-ring patches replace Euclidean ones that mostly lie across the surface. All zero below 7
    vertices; no detail test below ``round(1.5 k)`` vertices."""
    V = as_points(V, "V")
    check_positive(patch, "patch", integer=True)
    if patch < 7:
        raise InvalidInputError(f"`patch` must be >= 7; got {patch}.")
    if not 0 < quantile < 1:
        raise InvalidInputError(f"`quantile` must be in (0, 1); got {quantile!r}.")
    nan = float("nan")
    n = V.shape[0]
    k = min(int(patch), n)
    if k < 7:
        return NoiseEstimate(0.0, 0.0, 0.0, nan, nan, nan, False)
    big = int(round(1.5 * k))
    # one query serves both patch sizes (the growth test's patches are the first ``big``
    # neighbours; the level's the first ``k`` of them)
    idx_all, dist_all = knn(V, min(big, n), include_self=True)
    idx, dist = np.ascontiguousarray(idx_all[:, :k]), dist_all[:, :k]
    rings = False
    dirs = _min_variance_dirs(V, idx)
    if F is not None:
        F = as_faces(F, n, "F")
        if F.shape[0] and _misaligned_share(V, F, idx, dirs) >= MISALIGNED_SHARE:
            rings = True
            idx, dist = ring_patches(V, F, k)
            dirs = _min_variance_dirs(V, idx)
    kind = "rings" if rings else "knn"
    res = _residuals(V, idx, dirs)
    ok = np.isfinite(res)
    radius = float(np.median(dist[:, -1]))
    if not ok.any() or not radius > 0:
        # every patch degenerate (coincident or collinear points)
        return NoiseEstimate(0.0, 0.0, 0.0, nan, nan, nan, False, kind)
    var = _calibrated(res, quantile, k - 6)
    sigma = float(np.sqrt(var))
    level = sigma / radius
    if not var > 0 or big > n:
        return NoiseEstimate(sigma, level, level, nan, nan, nan, False, kind)
    # Eq. (N2): growth of the residual variance with the patch size
    if rings:
        idx_big = ring_patches(V, F, big)[0]
    else:
        idx_big = idx_all
    growth = float(_calibrated(_residuals(V, idx_big), quantile, big - 6) / var)
    # Eq. (N3): variance surviving one step of the uniform kNN Laplacian (lambda = 1)
    m = min(SMOOTH_NEIGHBORS, k - 1)
    smooth = V[idx[:, 1 : m + 1]].mean(axis=1)
    survival = float(_calibrated(_residuals(smooth, idx), quantile, k - 6) / var)
    # Eq. (N4): lower tail of the per-patch residual variances
    low = np.quantile(np.maximum(res[ok], 0.0), [0.1, 0.25])
    tail = float(low[0] / low[1]) if low[1] > 0 else 0.0
    detail = bool(growth >= MIN_GROWTH and survival >= MIN_SURVIVAL and tail >= MIN_TAIL)
    return NoiseEstimate(
        sigma, 0.0 if detail else level, level, growth, survival, tail, detail, kind
    )


def noise_sigma(V, *, F=None, patch: int = 16, quantile: float = 0.25) -> tuple[float, float]:
    """``(sigma, level)`` of :func:`noise_estimate` (model units; 0 level for surface detail)."""
    est = noise_estimate(V, F=F, patch=patch, quantile=quantile)
    return est.sigma, est.level


def noise_level(V, *, F=None, patch: int = 16, quantile: float = 0.25) -> float:
    """Relative noise level ``sigma / r`` of :func:`noise_estimate` (Eq. N1; 0.0 for surface detail,
    Eqs. N2-N4), e.g. ``noise_level(V, F=F)``."""
    return noise_sigma(V, F=F, patch=patch, quantile=quantile)[1]


def _pair_share(V, F, angle: float, *, turned: bool) -> float:
    check_positive(angle, "angle")
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    if F.shape[0] < 2:
        return 0.0
    A = sp.triu(face_adjacency(F), k=1).tocoo()
    if A.nnz == 0:
        return 0.0
    N = face_normals(V, F)
    ok = np.linalg.norm(N, axis=1) > 0.5
    c = np.einsum("ij,ij->i", N[A.row], N[A.col])
    t = np.cos(np.radians(angle))
    return float(np.mean(((c < t) if turned else (c >= t)) & ok[A.row] & ok[A.col]))


def planar_share(V, F, *, angle: float = PLANAR_DEG) -> float:
    """Eq. (N9): share of the edge-sharing face pairs coplanar within ``angle`` degrees."""
    return _pair_share(V, F, angle, turned=False)


def fold_share(V, F, *, angle: float = FOLD_DEG) -> float:
    """Eq. (N10): share of the edge-sharing face pairs turned by more than ``angle`` degrees."""
    return _pair_share(V, F, angle, turned=True)


def is_folded(V, F) -> bool:
    """At least ``FOLD_MIN_VERTICES`` vertices and :func:`fold_share` at least ``FOLD_SHARE``."""
    V = as_points(V, "V")
    return V.shape[0] >= FOLD_MIN_VERTICES and fold_share(V, F) >= FOLD_SHARE


@dataclass(frozen=True)
class CoarseShape:
    """Result of :func:`coarse_shape`: ``o`` (Eq. N13), ``c`` (Eq. N12), both above threshold."""

    offset: float
    corr: float
    coarse: bool


def coarse_shape(V, F) -> CoarseShape:
    """Coarse-mesh test (Eqs. N11-N13); a mesh without edges gives ``(0.0, 1.0, False)``."""
    from ..geometry import vertex_normals

    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    n = V.shape[0]
    if n == 0 or F.shape[0] == 0:
        return CoarseShape(0.0, 1.0, False)
    C = adjacency_matrix(F, n).tocsr()
    C.data[:] = 1.0
    deg = np.asarray(C.sum(axis=1)).ravel()
    has = deg > 0
    if not has.any():
        return CoarseShape(0.0, 1.0, False)
    U = sp.triu(C, k=1).tocoo()
    length = np.linalg.norm(V[U.row] - V[U.col], axis=1)
    ell = (np.bincount(U.row, length, n) + np.bincount(U.col, length, n)) / np.maximum(deg, 1.0)
    mean = (C @ V) / np.maximum(deg, 1.0)[:, None]
    u = np.einsum("ij,ij->i", V - mean, vertex_normals(V, F))  # Eq. (N11)
    u = np.divide(u, ell, out=np.zeros(n), where=has & (ell > 0))
    a, b = u[U.row], u[U.col]
    den = 0.5 * float(np.sum(a * a + b * b))
    corr = float(np.sum(a * b)) / den if den > 0 else 1.0  # Eq. (N12)
    ring = (u + C @ u) / (deg + 1.0)  # Eq. (N13)
    offset = float(np.median(np.abs(ring[has])))
    return CoarseShape(offset, corr, bool(offset >= COARSE_OFFSET and corr >= COARSE_CORR))


def has_shared_edge(F) -> bool:
    """True when some edge is shared by two faces."""
    F = np.asarray(F, dtype=np.int64)
    if F.shape[0] < 2:
        return False
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    E = E[E[:, 0] != E[:, 1]]
    if E.shape[0] < 2:
        return False
    key = np.sort(E[:, 0] * (int(F.max()) + 1) + E[:, 1])
    return bool(np.any(key[1:] == key[:-1]))


def no_scale_message(filter_name: str, call: str) -> str:
    """Refusal of a mesh without two adjacent faces with distinct centroids."""
    return (
        "the mesh has no two adjacent faces with distinct centroids (separate or duplicated "
        f"triangles, e.g. a triangle soup that welding did not join), so {filter_name} has no "
        "neighbourhood to filter over. `spectrageo denoise` writes such a file unchanged (with "
        "welding on, i.e. without --no-weld, seam copies are joined first); from Python, "
        f"{call} gives the filter a scale."
    )


def unfold(V, F, *, stop: float = FOLD_STOP, return_share: bool = False):
    """Taubin lambda|mu blocks of ``FOLD_PAIRS`` pairs until :func:`fold_share` < ``stop`` (at most
    ``FOLD_BLOCKS``); with ``return_share``, also the final share."""
    X = as_points(V, "V")
    share = float("nan")  # FOLD_BLOCKS >= 1: set by the first block
    for _ in range(FOLD_BLOCKS):
        X = taubin(X, F, lam=LOWPASS_LAM, mu=LOWPASS_MU, n_iter=FOLD_PAIRS)
        share = fold_share(X, F)
        if share < stop:
            break
    return (X, share) if return_share else X


def apply_trust(V: np.ndarray, X: np.ndarray, radius: float) -> np.ndarray:
    """``X`` with every displacement from ``V`` longer than ``radius`` shortened to it."""
    D = X - V
    length = np.linalg.norm(D, axis=1, keepdims=True)
    scale = np.minimum(1.0, radius / np.maximum(length, np.finfo(np.float64).tiny))
    return V + D * scale


@dataclass(frozen=True)
class DespikeResult:
    """Result of :func:`despike`: positions, share flagged by the first pass, moves."""

    vertices: np.ndarray
    share: float
    n_moved: int


def _spike_offsets(
    V: np.ndarray, FN: np.ndarray, VF: sp.csr_matrix, C: sp.csr_matrix, deg: np.ndarray
) -> tuple:
    """Eqs. (N5)-(N6): ring-median-corrected umbrella offsets and the vertex normals."""
    N = _normalize_rows(np.asarray(VF @ FN))
    mean = (C @ V) / np.maximum(deg, 1.0)[:, None]
    r = np.einsum("ij,ij->i", V - mean, N)
    s = np.empty_like(r)
    neighbour_median_residual(C.indptr, C.indices, r, s)
    return s, N


def despike(V, F, *, threshold: float = SPIKE_THRESHOLD, isolation: float = SPIKE_ISOLATION,
            passes: int = SPIKE_PASSES) -> DespikeResult:  # fmt: skip
    """Detect and pull back isolated spikes (Eqs. N5-N8): ``threshold`` is ``c`` and ``isolation``
    ``rho`` of Eq. (N7); ``passes`` repair passes."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_positive(threshold, "threshold")
    check_positive(passes, "passes", integer=True)
    if not 0 < isolation <= 1:
        raise InvalidInputError(f"`isolation` must be in (0, 1]; got {isolation!r}.")
    X = V.copy()
    n = X.shape[0]
    if n == 0 or F.shape[0] == 0:
        return DespikeResult(X, 0.0, 0)
    C = adjacency_matrix(F, n)
    C.sort_indices()
    deg = np.diff(C.indptr).astype(np.float64)
    VF = vertex_face_matrix(F, n)
    flag = np.zeros(n, dtype=np.bool_)
    plane_cos = float(np.cos(np.radians(SPIKE_PLANE_DEG)))
    edge = mean_edge_length(X, F)
    share = 0.0
    moved = 0
    for p in range(int(passes)):
        FN = face_normals(X, F)
        s, N = _spike_offsets(X, FN, VF, C, deg)
        sig = 1.4826 * float(np.median(np.abs(s)))
        thr = max(threshold * sig, SPIKE_FLOOR * edge)
        if not thr > 0:
            break
        if isolated_spikes(C.indptr, C.indices, s, thr, isolation, flag) == 0:
            break
        sel = np.flatnonzero(flag)
        # vertices exactly on a crease or corner of planar parts are features, not spikes
        ex = np.zeros(sel.size, dtype=np.bool_)
        few_face_planes(VF.indptr, VF.indices, FN, sel, plane_cos, 3, ex)
        sel = sel[~ex]
        if p == 0:
            share = sel.size / n
        if sel.size == 0:
            break
        h = s[sel] / (1.0 + 1.0 / deg[sel])
        moved += sel.size
        X[sel] -= h[:, None] * N[sel]
    return DespikeResult(X, share, moved)
