"""Identification of known models in a cluttered single-view scan (Section 6.2.3-6.2.6).

Scene and models share one sampling step; planes are removed and adaptive DBSCAN gives segments
(Eq. 6.28-6.29); boundary points are left out (Eq. 6.43-6.44); point saliency and multi-scale
features (Eq. 6.30-6.36) give correspondences, RANSAC and Tukey ICP a pose, and the dissimilarity
``h`` of the salient pairs (Eq. 6.37-6.38) decides ``found`` (``h < zeta``). With a sensor
``viewpoint``, a pose must also respect free space (``_visibility``), half turns of a rejected
pose and more rotation clusters are tried, a pose must not enter the removed planes, and segments
wider than a model also give hypotheses from their pieces cut along concave creases; ``found``
then needs ``h < zeta + ZETA_BAND``. Departures from the thesis: docs/decisions.md#identify-pipeline,
#identify-visibility, #identify-screening, #identify-pieces, #identify3-clusters, #identify3-planes
and #identify3-band.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from ._common import WORKERS, apply_transform, knn_normals, make_transform, voxel_downsample
from ._identify_cover import ModelGrid
from ._kernels import compatible_lists, count_inliers
from ._segment import adaptive_dbscan, remove_planes, split_creases
from ._visibility import SceneRays

#: RANSAC inliers also need normals within ~37 degrees (unoriented), as in the re-ranking
INLIER_COS = 0.8
#: guided sampling: number of anchor correspondences (first pick of a triple)
N_ANCHORS = 500
#: hypotheses re-ranked by the explained fraction of the segment
N_RERANK = 64
#: more hypotheses re-ranked: the best by the grid-screened explained fraction (all are screened)
N_SCREEN = 64
#: segment points of the screen (a subset of the re-ranking's)
SCREEN_POINTS = 100
#: guided sampling: largest change of ``|n_i . n_j|`` between the model and the segment pair
PAIR_COS_TOL = 0.25
#: free-space verification (with a viewpoint): range tolerance in sampling steps
VIS_TOL = 3.0
#: largest fraction of the moved model's points that may violate free space
VIS_MAX = 0.03
#: flipped poses (half turns about the model's principal axes) are tried below this ``h``
FLIP_H = 0.8
#: with a viewpoint, segments wider than this many model diagonals are also searched in pieces
SPLIT_DIAG = 1.3
#: concavity (about radians between the normals) of the creases that cut a wide segment
CREASE = 0.2
#: RANSAC hypotheses drawn and poses refined on a piece
PIECE_HYPOTHESES = 5000
PIECE_REFINE = 1
#: with a viewpoint, a rejected segment also refines the best hypothesis of this many more
#: rotation clusters (hypotheses whose rotations differ by more than ``CLUSTER_DEG`` degrees)
CLUSTER_EXTRA = 3
CLUSTER_DEG = 45.0
#: with a viewpoint (free space and planes checked), ``found`` needs ``h < zeta + ZETA_BAND``
ZETA_BAND = 0.03

DEFAULTS: dict[str, Any] = {
    "zeta": 0.4,  # Table 6.7
    "k_a": 5,  # Eq. 6.29
    "k_d": 10,  # Eq. 6.43
    "k_s": 1000.0,  # Eq. 6.34
    "k_p": 200,  # Eq. 6.38
    "k_p_fraction": 0.5,
    "tau": 0.4,  # salient-point threshold (Section 6.2.6)
    "saliency_k": 20,  # Eq. 6.30
    "scale_k": 5,  # Eq. 6.35 (K)
    "n_scales": 5,
    "voxel": None,
    "voxel_fraction": 1.0 / 40.0,
    "remove_planes": True,
    "n_hypotheses": 20000,
    "desc_k": 48,
    "query_radius": 0.1,
    "min_fraction": 0.05,
    "n_refine": 3,
    "min_segment": 30,
    "viewpoint": None,
}


@dataclass(frozen=True)
class Match:
    """Result of :func:`identify` for one model: ``model`` key, ``found``, ``dissimilarity`` ``h``
    (Eq. 6.38), model-to-scene ``transformation``, ``n_points`` and scene indices ``segment``.
    """

    model: Any
    found: bool
    dissimilarity: float
    transformation: np.ndarray = field(repr=False)
    n_points: int
    segment: np.ndarray = field(repr=False)


# ----------------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class _VF:
    vertices: Any
    faces: Any


def _geometry_points(x, name: str, rng) -> tuple[np.ndarray, float]:
    """Points of an array, PointCloud, Mesh or file; meshes are sampled uniformly by area."""
    from .. import io
    from .._validation import as_points

    if isinstance(x, str | Path):
        p = Path(x)
        if not p.is_file():
            raise InvalidInputError(f"`{name}`: file not found: {x}")
        # point rows without coordinates (NaN) are left out, as in PCD files; segment indices
        # then count the kept rows
        x = io.read(p, nan_points="drop")
    if isinstance(x, tuple) and len(x) == 2:  # (V, F)
        x = _VF(*x)
    faces = getattr(x, "faces", None)
    if hasattr(x, "vertices") and faces is not None and len(faces):
        from .._validation import as_faces
        from .scenes import _sample_surface

        V = as_points(x.vertices, name)
        F = as_faces(faces, V.shape[0], f"{name} faces")
        a = V[F]
        area = 0.5 * np.linalg.norm(np.cross(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]), axis=1).sum()
        diag = float(np.linalg.norm(np.ptp(V, axis=0)))
        if area <= 0 or diag <= 0:
            raise InvalidInputError(f"`{name}` has zero surface area.")
        # about (diag / (voxel / 3))^2 samples per unit of area fraction; bounded
        count = int(np.clip(area / (diag / 150.0) ** 2, 20_000, 400_000))
        return _sample_surface(V, F, count, np.random.default_rng(rng)), diag
    if hasattr(x, "points") and not isinstance(x, np.ndarray):
        x = x.points
    elif hasattr(x, "vertices") and not isinstance(x, np.ndarray):
        x = x.vertices
    P = as_points(x, name)
    return P, float(np.linalg.norm(np.ptp(P, axis=0)))


def _key_seed(key) -> int:
    """A stable integer of a model's key: its random streams do not depend on its position."""
    import zlib

    return zlib.crc32(repr(key).encode("utf-8"))


def _check_options(options: dict) -> dict:
    unknown = set(options) - set(DEFAULTS)
    if unknown:
        raise InvalidInputError(
            f"unknown option(s) {', '.join(sorted(unknown))}; known: {', '.join(sorted(DEFAULTS))}."
        )
    o = {**DEFAULTS, **options}
    for k in (
        "zeta",
        "k_s",
        "tau",
        "voxel_fraction",
        "k_p_fraction",
        "query_radius",
        "min_fraction",
    ):
        v = o[k]
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or v <= 0:
            raise InvalidInputError(f"`{k}` must be a positive number; got {v!r}.")
    if o["voxel"] is not None:
        v = o["voxel"]
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or v <= 0:
            raise InvalidInputError(f"`voxel` must be a positive number or None; got {v!r}.")
    for k in ("k_a", "k_d", "k_p", "saliency_k", "scale_k", "n_scales", "n_hypotheses", "desc_k",
              "n_refine", "min_segment"):  # fmt: skip
        v = o[k]
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise InvalidInputError(f"`{k}` must be a positive integer; got {v!r}.")
    if o["viewpoint"] is not None:
        try:
            vp = np.asarray(o["viewpoint"], dtype=np.float64)
        except (TypeError, ValueError):
            vp = np.full(0, np.nan)
        if vp.shape != (3,) or not np.isfinite(vp).all():
            raise InvalidInputError(f"`viewpoint` must be 3 finite numbers or None; got {vp!r}.")
        o["viewpoint"] = vp
    if o["tau"] >= 1:
        raise InvalidInputError(f"`tau` must be in (0, 1); got {o['tau']!r}.")
    return o


# ------------------------------------------------------------------------------ descriptors


@dataclass
class _Cloud:
    P: np.ndarray  # (m, 3) down-sampled points
    N: np.ndarray  # unoriented normals
    s_raw: np.ndarray  # raw saliency (Eq. 6.33)
    desc: np.ndarray  # pose-free descriptor
    keep: np.ndarray  # non-boundary mask (Eq. 6.43)
    tree: cKDTree
    diag: float
    grid: ModelGrid | None = None  # built on first use as a model


def _pair_histograms(P, N, idx, n_bins: int = 6) -> np.ndarray:
    """Sign-invariant point-pair histograms over each point's neighbours, FPFH-style averaged."""
    m, k = idx.shape
    D = P[idx] - P[:, None, :]
    L = np.linalg.norm(D, axis=2)
    D = D / np.maximum(L, 1e-300)[:, :, None]
    Nj = N[idx]
    f1 = np.abs(np.einsum("mkc,mc->mk", Nj, N))
    a = np.abs(np.einsum("mkc,mc->mk", D, N))
    b = np.abs(np.einsum("mkc,mkc->mk", D, Nj))
    f2, f3 = np.minimum(a, b), np.maximum(a, b)
    valid = L > 0
    H = np.zeros((m, 3 * n_bins))
    rows = np.repeat(np.arange(m), k).reshape(m, k)[valid]
    for c, f in enumerate((f1, f2, f3)):
        bins = np.minimum((f[valid] * n_bins).astype(np.int64), n_bins - 1)
        np.add.at(H, (rows, c * n_bins + bins), 1.0)
    H /= np.maximum(valid.sum(axis=1), 1)[:, None]
    # FPFH-like widening: own histogram plus the mean of the neighbours'
    return 0.5 * (H + H[idx].mean(axis=1))


def _prepare(P: np.ndarray, voxel: float, o: dict) -> _Cloud | None:
    from ..saliency.pointcloud import pointcloud_saliency

    Q, _ = voxel_downsample(P, voxel)
    m = Q.shape[0]
    if m < max(o["saliency_k"] + 2, o["scale_k"] * o["n_scales"], 30):
        return None
    tree = cKDTree(Q)
    N, idx = knn_normals(Q, 10, tree)
    s_raw = pointcloud_saliency(Q, k=o["saliency_k"], normals=N, normalize=False)
    kk = min(o["desc_k"], m - 1)
    _, nb = tree.query(Q, k=kk + 1, workers=WORKERS)
    nb = nb[:, 1:]
    hist = _pair_histograms(Q, N, nb)
    # multi-scale raw saliency (Eq. 6.35 on s * (k + 1), which lies in [1, sqrt 3])
    sr = s_raw * (o["saliency_k"] + 1)
    kmax = min(o["scale_k"] * o["n_scales"], m)
    _, nb2 = tree.query(Q, k=kmax, workers=WORKERS)
    cs = np.cumsum(sr[nb2], axis=1)
    sizes = np.minimum(o["scale_k"] * np.arange(1, o["n_scales"] + 1), kmax)
    a = cs[:, sizes - 1] / sizes
    desc = np.c_[hist, 2.0 * (a - 1.0)]
    # boundary points (Eq. 6.43-6.44): mean distance to K_D neighbours >= 2 x its average
    kd = min(o["k_d"], m - 1)
    dd, _ = tree.query(Q, k=kd + 1, workers=WORKERS)
    dpsi = dd[:, 1:].mean(axis=1)
    keep = dpsi < 2.0 * dpsi.mean()
    diag = float(np.linalg.norm(np.ptp(Q, axis=0)))
    return _Cloud(Q, N, s_raw, desc, keep, tree, diag)


# ------------------------------------------------------------------------------- pose search


def _kabsch_batch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid fits taking A[h] (h, p, 3) onto B[h]: rotations (h, 3, 3), translations (h, 3)."""
    ca, cb = A.mean(axis=1), B.mean(axis=1)
    Hm = np.einsum("hpi,hpj->hij", A - ca[:, None], B - cb[:, None])
    U, _, Vt = np.linalg.svd(Hm)
    d = np.sign(
        np.linalg.det(np.einsum("hij,hjk->hik", Vt.transpose(0, 2, 1), U.transpose(0, 2, 1)))
    )
    d[d == 0] = 1.0
    Dm = np.zeros((A.shape[0], 3, 3))
    Dm[:, 0, 0] = 1
    Dm[:, 1, 1] = 1
    Dm[:, 2, 2] = d
    R = np.einsum("hji,hjk,hlk->hil", Vt, Dm, U)
    t = cb - np.einsum("hij,hj->hi", R, ca)
    return R, t


def _ransac_poses(
    model: _Cloud, seg: _Cloud, voxel: float, o: dict, g, heads: list | None = None
) -> list[tuple[float, np.ndarray]]:
    """Candidate model->segment poses from descriptor correspondences, best first. ``heads``
    (a list) receives up to ``CLUSTER_EXTRA`` rotation clusters not represented among those
    returned, each as its poses, best first."""
    qi = np.flatnonzero(seg.keep)
    if qi.size < 10:
        qi = np.arange(seg.P.shape[0])
    mi = np.flatnonzero(model.keep)
    if mi.size < 10:
        mi = np.arange(model.P.shape[0])
    dtree = cKDTree(model.desc[mi])
    kc = 3
    _, j = dtree.query(seg.desc[qi], k=kc, workers=WORKERS)
    cq = np.repeat(qi, kc)
    cm = mi[j.ravel()]
    A, B = model.P[cm], seg.P[cq]  # correspondence: model point -> segment point
    nc = cm.size
    nh = o["n_hypotheses"]
    A, B = np.ascontiguousarray(A), np.ascontiguousarray(B)
    NA, NB = np.ascontiguousarray(model.N[cm]), np.ascontiguousarray(seg.N[cq])
    # guided sampling: the first correspondence of a triple among n1 anchors, the other two among
    # the correspondences compatible with it -- pairwise distance kept (as in the triple check
    # below), segment distance between `sep` and 0.6 model diagonals (a segment may hold several
    # objects), unoriented angle between the two normals kept -- so that a triple needs only its
    # first pick right, not all three
    n1 = min(nc, N_ANCHORS)
    anchors = g.choice(nc, n1, replace=False)
    sep = max(0.1 * min(model.diag, seg.diag), 2 * voxel)
    cnt, flat = compatible_lists(
        A, B, NA, NB, anchors.astype(np.int64), float(voxel), 0.6 * model.diag, float(sep),
        PAIR_COS_TOL,
    )  # fmt: skip
    usable = np.flatnonzero(cnt >= 2)
    if usable.size == 0:
        return []
    off = np.r_[0, np.cumsum(cnt)[:-1]]
    ai = usable[g.integers(0, usable.size, size=nh)]
    pick = off[ai, None] + (g.random((nh, 2)) * cnt[ai, None]).astype(np.int64)
    s = np.c_[anchors[ai], flat[pick]]
    a, b = A[s], B[s]
    da = np.linalg.norm(a[:, [0, 1, 2]] - a[:, [1, 2, 0]], axis=2)
    db = np.linalg.norm(b[:, [0, 1, 2]] - b[:, [1, 2, 0]], axis=2)
    ok = (np.abs(da - db) <= 0.1 * np.maximum(da, db) + voxel).all(axis=1)
    ok &= db.min(axis=1) >= sep
    if not ok.any():
        return []
    R, t = _kabsch_batch(a[ok], b[ok])
    thr2 = (2.0 * voxel) ** 2
    score = count_inliers(
        np.ascontiguousarray(R), np.ascontiguousarray(t), A, B, thr2, NA, NB, INLIER_COS
    ).astype(np.float64)
    # re-rank the best hypotheses by the fraction of segment points the moved model explains;
    # candidates: the most inliers, and the most explained points on a grid screen of all
    step = max(1, seg.P.shape[0] // 400)
    Qs, Ns = seg.P[::step], seg.N[::step]
    top = np.argsort(-score, kind="stable")[:N_RERANK]
    if N_SCREEN > 0:
        if model.grid is None:
            model.grid = ModelGrid(model.P, model.tree, 1.5 * voxel, voxel)
        sk = max(1, Qs.shape[0] // SCREEN_POINTS)
        gcov = model.grid.coverage(R, t, Qs[::sk], Ns[::sk], model.N, 0.8)
        extra = np.argsort(-gcov, kind="stable")[:N_SCREEN]
        top = np.r_[top, extra[~np.isin(extra, top)]]
    cover = np.empty(top.size)
    for c, h in enumerate(top):
        Pm = (Qs - t[h]) @ R[h]  # segment points in model coordinates
        d, jn = model.tree.query(Pm, k=1, distance_upper_bound=1.5 * voxel, workers=WORKERS)
        ok = np.isfinite(d)
        # explained: close to the moved model and with a similar (unoriented) normal
        agree = np.abs(np.einsum("ij,ij->i", Ns[ok] @ R[h], model.N[jn[ok]])) >= 0.8
        cover[c] = agree.sum() / Qs.shape[0]
    order = top[np.argsort(-cover, kind="stable")]
    score = np.zeros(R.shape[0])
    score[top] = cover
    out: list[tuple[float, np.ndarray]] = []
    for h in order:
        T = make_transform(R[h], t[h])
        # skip near-duplicates of an already kept pose
        if any(np.linalg.norm(T[:3, 3] - U[:3, 3]) < 3 * voxel
               and np.linalg.norm(T[:3, :3] - U[:3, :3]) < 0.3 for _, U in out):  # fmt: skip
            continue
        out.append((float(score[h]), T))
        if len(out) >= o["n_refine"]:
            break
    if heads is not None:
        heads.extend(_cluster_heads(order, R, t, score, [T[:3, :3] for _, T in out]))
    return out


def _cluster_heads(order, R, t, score, reps: list) -> list[list[np.ndarray]]:
    """Rotation clusters of the hypotheses in ``order`` not represented by ``reps``: a hypothesis
    turned more than ``CLUSTER_DEG`` from ``reps`` and every earlier head starts a cluster, the
    others join the first head within the angle; the first ``CLUSTER_EXTRA`` clusters, each as
    its member poses in ``order`` (docs/decisions.md#identify3-clusters)."""
    lim = 1.0 + 2.0 * np.cos(np.radians(CLUSTER_DEG))  # trace(Ra^T Rb) above: within the angle
    heads = [(U, None) for U in reps]
    out: list[list[np.ndarray]] = []
    for h in order:
        k = next((c for c, (U, _) in enumerate(heads) if np.einsum("ij,ij->", U, R[h]) > lim), -1)
        if k < 0:
            if len(out) >= CLUSTER_EXTRA:
                continue
            out.append([])
            heads.append((R[h], len(out) - 1))
            k = len(heads) - 1
        if heads[k][1] is not None:
            out[heads[k][1]].append(make_transform(R[h], t[h]))
    return out


def _refine(model: _Cloud, seg: _Cloud, T0: np.ndarray, o: dict) -> np.ndarray:
    """Tukey ICP of the nearby segment points onto the model from ``inv(T0)``; model->scene."""
    import warnings

    from ._api import narrow_phase

    d, _ = cKDTree(apply_transform(T0, model.P)).query(seg.P, k=1, workers=WORKERS)
    near = d <= o["query_radius"] * model.diag
    src = seg.P[near] if near.sum() >= 10 else seg.P
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = narrow_phase(
            src, model.P, init=np.linalg.inv(T0), max_iter=30, tol=1e-4, coarse=False
        )
    return np.linalg.inv(res.transformation)


def _flips(model: _Cloud, T: np.ndarray) -> list[np.ndarray]:
    """``T`` composed with half turns about the model's principal axes through its centroid."""
    c = model.P.mean(axis=0)
    _, _, Vt = np.linalg.svd(model.P - c, full_matrices=False)
    out = []
    for a in Vt:
        F = 2.0 * np.outer(a, a) - np.eye(3)  # rotation by pi about a
        out.append(T @ make_transform(F, c - F @ c))
    return out


def _search_segment(
    model, seg, voxel, o, g, rays, hyp=None
) -> list[tuple[float, float, np.ndarray]]:
    """Refined poses of ``model`` on ``seg`` as ``(h, violation, T)``; flips of the best pose,
    then the least violating pose of more rotation clusters, are tried when no pose is accepted
    (docs/decisions.md#identify-visibility, #identify3-clusters). The hypotheses come from
    ``hyp`` (a piece of ``seg``) when given."""
    out: list[tuple[float, float, np.ndarray]] = []
    zeta = o["zeta"]

    def run(T0):
        T = _refine(model, seg, T0, o)
        h = dissimilarity(model, seg, T, voxel, o)
        v = 0.0 if rays is None else rays.violations(model.P, T, VIS_TOL, model.N)
        out.append((h, v, T))
        return h < 0.75 * zeta and v <= VIS_MAX  # a clear match: no need for the other poses

    if hyp is not None:  # a piece: its best hypothesis only
        po = {**o, "n_refine": PIECE_REFINE, "n_hypotheses": PIECE_HYPOTHESES}
        for _score, T0 in _ransac_poses(model, hyp, voxel, po, g):
            run(T0)
        return out
    heads: list = []
    for _score, T0 in _ransac_poses(model, seg, voxel, o, g, heads if rays is not None else None):
        if run(T0):
            return out
    if rays is None or not out or any(h < zeta and v <= VIS_MAX for h, v, _ in out):
        return out
    h0, _, T0 = min(out, key=lambda x: x[0])
    if h0 >= FLIP_H:
        return out
    # a plausible but rejected pose: the pose search often turns a mostly hidden object by a
    # half turn about one of its principal axes
    for Tf in _flips(model, T0):
        if run(Tf):
            return out
    if any(h < zeta and v <= VIS_MAX for h, v, _ in out):
        return out
    # the best hypotheses of other rotation clusters (the re-ranking may rank the right one low)
    sub = slice(None, None, 8)
    for members in heads:
        vs = [rays.violations(model.P[sub], Tc, VIS_TOL, model.N[sub]) for Tc in members]
        if run(members[int(np.argmin(vs))]):
            break
    return out


# ---------------------------------------------------------------------------- dissimilarity


def dissimilarity(model: _Cloud, seg: _Cloud, T: np.ndarray, voxel: float, o: dict) -> float:
    """``h`` of Eq. 6.38 between the model moved by ``T`` and the segment (see module notes)."""
    from ..saliency.pointcloud import normalize_saliency_pair

    st, sq = normalize_saliency_pair(model.s_raw, seg.s_raw, K_s=o["k_s"])

    def feats(P, s, tree):
        kmax = min(o["scale_k"] * o["n_scales"], P.shape[0])
        _, nb = tree.query(P, k=kmax, workers=WORKERS)
        cs = np.cumsum(s[nb], axis=1)
        sizes = np.minimum(o["scale_k"] * np.arange(1, o["n_scales"] + 1), kmax)
        return cs[:, sizes - 1] / sizes  # Eq. 6.35

    at = feats(model.P, st, model.tree)
    aq = feats(seg.P, sq, seg.tree)
    Pt = apply_transform(T, model.P)
    # the query object: segment points near the moved model (Section 6.2.3 merges the clusters
    # close to the registered model); others belong to neighbouring objects of the segment
    dn, _ = cKDTree(Pt).query(seg.P, k=1, workers=WORKERS)
    near = dn <= o["query_radius"] * model.diag
    ft = np.c_[Pt / voxel, at]  # Eq. 6.36
    fq = np.c_[seg.P / voxel, aq]
    sal_t = st > o["tau"]
    sal_q = (sq > o["tau"]) & seg.keep & near
    if sal_q.sum() < 3 or sal_t.sum() < 3:
        sal_q = near if near.sum() >= 3 else np.ones(seg.P.shape[0], bool)
        sal_t = np.ones(model.P.shape[0], bool)
    ti = np.flatnonzero(sal_t)
    d, j = cKDTree(ft[ti]).query(fq[sal_q], k=1, workers=WORKERS)  # Eq. 6.37
    # unique pairs: each model point keeps its closest query point
    order = np.argsort(d, kind="stable")
    _, first = np.unique(j[order], return_index=True)
    du = np.sort(d[order][first])
    # a query point that lost its model point to another counts with its own distance
    rest = np.setdiff1d(np.arange(d.size), order[first])
    dall = np.sort(np.r_[du, d[rest]])
    kp = int(max(o["k_p"], o["k_p_fraction"] * d.size))
    kp = min(kp, dall.size)
    return float(dall[:kp].mean())


def _accept_below(o: dict) -> float:
    """The ``h`` below which an admissible pose is found: ``zeta``, plus ``ZETA_BAND`` with a
    viewpoint (docs/decisions.md#identify3-band)."""
    return o["zeta"] + (0.0 if o["viewpoint"] is None else ZETA_BAND)


def _pieces(S, segs, o, voxel, diag) -> list[tuple[int, _Cloud]]:
    """Model-sized pieces of the segments wider than ``SPLIT_DIAG`` model diagonals, cut along
    concave creases (an object touching clutter; docs/decisions.md#identify-pieces)."""
    out = []
    for c, (idx, cl) in enumerate(segs):
        if cl.diag <= SPLIT_DIAG * diag:
            continue
        lab = split_creases(cl.P, cl.N, o["viewpoint"], crease=CREASE, min_size=o["min_segment"])
        if lab.max() < 1:
            continue
        _, j = cl.tree.query(S[idx], k=1, workers=WORKERS)
        full = lab[j]
        for p in range(int(lab.max()) + 1):
            sub = idx[full == p]
            pc = _prepare(S[sub], voxel, o)
            if pc is not None and pc.diag <= SPLIT_DIAG * diag:
                out.append((c, pc))
    return out


# ------------------------------------------------------------------------------------- API


def identify(scene, models, *, rng=0, **options) -> list[Match]:
    """Find which ``models`` are in the single-view ``scene`` and where (Section 6.2.3-6.2.6).

    Parameters
    ----------
    scene : (n, 3) array, PointCloud, Mesh or file path
        NaN rows of a file are left out; segment indices count the kept rows.
    models : list or dict of arrays, PointClouds, Meshes or paths
        Meshes are sampled uniformly by area.
    rng : int or Generator
    **options
        Overrides of :data:`DEFAULTS` (``zeta``, ``k_a``, ``k_d``, ``k_s``, ``k_p``, ``tau``, ...);
        unknown names raise InvalidInputError. ``viewpoint`` (3,): the sensor position; a found
        pose then leaves at most :data:`VIS_MAX` of the model in observed free space (``h`` may
        reach ``zeta`` + :data:`ZETA_BAND`), and segments wider than :data:`SPLIT_DIAG` model
        diagonals are also searched in pieces.

    Returns
    -------
    list of Match
        One per model, in the given order.
    """
    o = _check_options(options)
    if isinstance(models, dict):
        items = list(models.items())
    elif isinstance(models, list | tuple):
        items = [(m if isinstance(m, str | Path) else i, m) for i, m in enumerate(models)]
    else:
        raise InvalidInputError(
            f"`models` must be a list or a dict of geometries; got {type(models).__name__}."
        )
    if not items:
        raise InvalidInputError("`models` is empty; give at least one model.")
    seed = np.random.default_rng(rng).integers(2**63 - 1)
    S, _ = _geometry_points(scene, "scene", seed)
    if S.shape[0] < 50:
        raise InvalidInputError(f"`scene` must have at least 50 points; got {S.shape[0]}.")
    mpts, diag_list = [], []
    for i, (key, m) in enumerate(items):
        P, dg = _geometry_points(m, f"models[{key!r}]" if isinstance(models, dict) else f"models[{i}]",
                                [int(seed), _key_seed(key)])  # fmt: skip
        if P.shape[0] < 30:
            raise InvalidInputError(
                f"`models[{i}]` must have at least 30 points; got {P.shape[0]}."
            )
        mpts.append(P)
        diag_list.append(dg)
    # the input geometry's extent (not the samples'), so the sampling step does not vary
    diags = np.array(diag_list)
    if not (diags > 0).all():
        raise InvalidInputError("every model must have a non-zero extent.")
    st = cKDTree(S)
    sub = np.arange(0, S.shape[0], max(1, S.shape[0] // 4000))
    dsc, _ = st.query(S[sub], k=2, workers=WORKERS)
    spacing = float(np.median(dsc[:, 1]))
    voxel = o["voxel"] or max(spacing, float(np.median(diags)) * o["voxel_fraction"])
    # --- segmentation on the down-sampled scene
    Sd, vlab = voxel_downsample(S, voxel)
    keep = np.ones(Sd.shape[0], dtype=bool)
    planes: list = []
    if o["remove_planes"] and Sd.shape[0] >= 100:
        keep, planes = remove_planes(Sd, threshold=1.0 * voxel, rng=[int(seed), 0])
    labels_d = np.full(Sd.shape[0], -1, dtype=np.int64)
    ki = np.flatnonzero(keep)
    if ki.size > o["k_a"] + 1:
        labels_d[ki] = adaptive_dbscan(Sd[ki], k_a=o["k_a"], min_cluster_size=o["min_segment"])
    labels = labels_d[vlab]
    n_seg = int(labels_d.max()) + 1
    segs: list[tuple[np.ndarray, _Cloud]] = []
    for c in range(n_seg):
        idx = np.flatnonzero(labels == c)
        cl = _prepare(S[idx], voxel, o)
        if cl is not None:
            segs.append((idx, cl))
    # (segment, cloud giving the hypotheses): the segments, then pieces of the wide ones
    jobs = [(c, sc) for c, (_, sc) in enumerate(segs)]
    if o["viewpoint"] is not None:
        jobs += _pieces(S, segs, o, voxel, float(np.median(diags)))
    # --- every model against every segment
    rays = None
    if o["viewpoint"] is not None:
        # the removed planes with their points: a pose must not enter them
        pl = [(nc, Sd[~keep][np.abs(Sd[~keep] @ nc[:3] - nc[3]) <= voxel]) for nc in planes]
        rays = SceneRays(Sd, o["viewpoint"], voxel, pl)
    cands, admissible = [], []
    for mi_, P in enumerate(mpts):
        mc = _prepare(P, voxel, o)
        best = (np.inf, np.eye(4), np.zeros(0, dtype=np.int64))
        best_key = (True, np.inf)
        if mc is not None:
            for c, (si, hc) in enumerate(jobs):
                idx, sc = segs[si]
                # one stream per (model, job): a model's answer does not depend on the others
                g = np.random.default_rng([int(seed), 1, _key_seed(items[mi_][0]), c])
                # too small to decide (a few dozen points fit anywhere on any model)
                if hc.diag < 0.15 * mc.diag or hc.P.shape[0] < o["min_fraction"] * mc.P.shape[0]:
                    continue
                if hc is not sc and not best_key[0] and best_key[1] < 0.75 * o["zeta"]:
                    continue  # a piece, for a model already clearly found
                tried = _search_segment(mc, sc, voxel, o, g, rays, None if hc is sc else hc)
                for h, v, T in tried:
                    key = (v > VIS_MAX, h)
                    if np.isfinite(h) and key < best_key:
                        best_key, best = key, (h, T, idx)
        if mc is not None:
            mc.grid = None  # up to MAX_CELLS_AXIS^3 cells; not needed after the search
        cands.append((mi_, *best, mc))
        admissible.append(not best_key[0])
    # --- decisions, conflicts resolved by h
    zeta = _accept_below(o)
    found = [np.isfinite(c[1]) and c[1] < zeta and a for c, a in zip(cands, admissible)]
    explained = []
    for _mi, h, T, idx, mc in cands:
        if not np.isfinite(h) or mc is None:
            explained.append(np.zeros(0, dtype=np.int64))
            continue
        d, _ = cKDTree(apply_transform(T, mc.P)).query(S[idx], k=1, workers=WORKERS)
        explained.append(idx[d <= 2.0 * voxel])
    order = sorted(range(len(cands)), key=lambda i: cands[i][1])
    taken: list[int] = []
    for i in order:
        if not found[i]:
            continue
        for j in taken:
            inter = np.intersect1d(explained[i], explained[j]).size
            if inter > 0.5 * max(1, min(explained[i].size, explained[j].size)):
                found[i] = False
                break
        if found[i]:
            taken.append(i)
    out = []
    for (key, _), (_, h, T, idx, _), f in zip(items, cands, found):
        out.append(Match(model=key, found=bool(f), dissimilarity=float(h), transformation=T,
                         n_points=int(idx.size), segment=idx.astype(np.int64)))  # fmt: skip
    return out


__all__ = ["DEFAULTS", "Match", "dissimilarity", "identify"]
