"""Outlier removal (thesis Section 5.4): RPCA patch filter, SOR/radius baselines, robot pipeline,
sequence cleaning."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.geometry import PointCloud, PointCloudSequence
from spectrageo.outliers import (
    RPCAOptions,
    auto_threshold,
    bilateral_point_filter,
    clean_sequence,
    knn_patch_matrix,
    knn_triangles,
    radius_scores,
    remove_outliers,
    robot_pipeline,
    rpca_scores,
    sor_scores,
    weighted_laplacian,
)

from conftest import outlier_recall_precision, require_module


def _plane(n_side=40, noise_level=0.0, seed=0):
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n_side), np.linspace(0, 1, n_side))
    P = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    P[:, :2] += rng.uniform(-0.2, 0.2, (P.shape[0], 2)) / n_side  # irregular sampling
    P[:, 2] += noise_level * rng.standard_normal(P.shape[0]) / n_side
    return P


def _sphere(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.standard_normal((n, 3))
    return P / np.linalg.norm(P, axis=1, keepdims=True)


#: The reference path of rpca_scores: float64 state, ALM stopped by the residual only.
EXACT = dict(dtype="float64", rank_tol=0.0)


def _f1(keep, labels):
    pred = ~keep
    tp = np.count_nonzero(pred & labels)
    p = tp / max(np.count_nonzero(pred), 1)
    r = tp / max(np.count_nonzero(labels), 1)
    return 2 * p * r / max(p + r, 1e-12)


# ----------------------------------------------------------------------------- patch matrix
def test_knn_patch_matrix_layout():
    P = _plane(6)
    M = knn_patch_matrix(P, 4)
    assert M.shape == (3 * P.shape[0], 5)
    # column 0 holds the point itself, row triplets x, y, z
    np.testing.assert_array_equal(M[0::3, 0], P[:, 0])
    np.testing.assert_array_equal(M[2::3, 0], P[:, 2])
    # columns 1..k: the k nearest other points, nearest first
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    np.fill_diagonal(d, np.inf)
    i = 7
    nn = np.argsort(d[i], kind="stable")[:4]
    got = M[3 * i : 3 * i + 3, 1:].T
    np.testing.assert_allclose(np.sort(np.linalg.norm(got - P[i], axis=1)), d[i, nn])


def test_knn_patch_matrix_given_neighbours_and_errors():
    P = _plane(5)
    idx = np.tile(np.arange(1, 4), (P.shape[0], 1))
    M = knn_patch_matrix(P, neighbors=idx)
    np.testing.assert_array_equal(M[0::3, 1], np.full(P.shape[0], P[1, 0]))
    with pytest.raises(InvalidInputError, match="neighbors"):
        knn_patch_matrix(P, neighbors=idx[:3])
    with pytest.raises(InvalidInputError, match="integer"):
        knn_patch_matrix(P, neighbors=idx.astype(float))
    with pytest.raises(InvalidInputError, match="outside"):
        knn_patch_matrix(P, neighbors=idx + 100)


def test_rpca_scores_match_linalg_rpca():
    """The fused patch solver gives the decomposition of spectrageo.linalg.rpca on the explicit M."""
    from spectrageo.linalg import RPCASolverOptions as LinalgOptions
    from spectrageo.linalg import rpca

    P, _ = noise.add_outliers(_sphere(400), fraction=0.05, kind="far", rng=1)
    k = 6
    opts = RPCAOptions(
        rho=1.5, tol=1e-9, max_iter=500, block_size=10**6, refine=False, tangent_weight=1, **EXACT
    )
    r = rpca_scores(P, k, opts)
    # explicit reference on the same normalised coordinates
    M = knn_patch_matrix((P - P.mean(axis=0)) / r.spacing, k)
    ref = rpca(M, method="ialm", tol=1e-9, max_iter=500, options=LinalgOptions(rho=1.5))
    s_ref = np.linalg.norm(ref.sparse[:, 0].reshape(-1, 3), axis=1)
    np.testing.assert_allclose(r.scores, s_ref, atol=1e-5 * max(1.0, s_ref.max()))


def test_rpca_refinement_rebuilds_outlier_patches_and_subtracts_baseline():
    """Steps 5-6 of rpca_scores, recomputed independently from the plain scores of the pieces."""
    from spectrageo.graph import knn
    from spectrageo.linalg import RPCASolverOptions as LinalgOptions
    from spectrageo.linalg import rpca
    from spectrageo.outliers import rpca as rp

    # a plane with a cloud of far outliers above it, many of whose patches are made of each other
    rng = np.random.default_rng(7)
    P = np.concatenate([_plane(25), rng.uniform([-0.5, -0.5, 0.3], [1.5, 1.5, 0.8], (100, 3))])
    k = 6
    kw = dict(tangent_weight=1, tol=1e-9, rho=1.5, max_iter=500, **EXACT)
    plain = rpca_scores(P, k, RPCAOptions(refine=False, **kw))
    r = rpca_scores(P, k, RPCAOptions(second_pass="full", **kw))
    assert r.n_refined > 0 and plain.n_refined == 0
    # reference: flag, rebuild the patches made mostly of flagged points, rerun Algorithm 14
    s1 = plain.scores
    tau = max(auto_threshold(s1, minimum=0.5), rp.REFINE_MIN_TAU)
    flag = s1 >= tau
    idx = knn(P, k)[0]
    kept = np.flatnonzero(~flag)
    rebuild = np.flatnonzero(2 * flag[idx].sum(axis=1) > k)
    assert rebuild.size == r.n_refined
    for i in rebuild:
        d = np.linalg.norm(P[kept] - P[i], axis=1)
        d[kept == i] = np.inf
        idx[i] = kept[np.argsort(d, kind="stable")[:k]]
    M = knn_patch_matrix((P - P.mean(axis=0)) / plain.spacing, k, neighbors=idx)
    ref = rpca(M, method="ialm", tol=1e-9, max_iter=500, options=LinalgOptions(rho=1.5))
    s2 = np.linalg.norm(ref.sparse[:, 0].reshape(-1, 3), axis=1)
    from spectrageo.outliers._rpca_core import BASELINE_QUANTILE

    expect = np.maximum(s2 - np.quantile(s1[idx], BASELINE_QUANTILE, axis=1), 0.0)
    np.testing.assert_allclose(r.scores, expect, atol=1e-4 * max(1.0, expect.max()))
    # the refinement separates the outlier cloud better than the plain first column
    from spectrageo.evaluate.outliers import _oracle_threshold

    lab = np.arange(P.shape[0]) >= 625

    def best_f1(sc):
        return _f1(sc < _oracle_threshold(sc, lab), lab)

    assert best_f1(plain.scores) < 0.99 < best_f1(r.scores)
    # the default second pass (rebuilt rows replayed with Gram-corrected operators) agrees
    rep = rpca_scores(P, k, RPCAOptions(**kw))
    assert rep.n_refined == r.n_refined
    assert best_f1(rep.scores) > 0.99
    np.testing.assert_allclose(rep.scores, r.scores, atol=0.02 * max(1.0, r.scores.max()))


def _neighbour_normals(P, idx):
    """Smallest principal axis of each point's neighbours (the point itself left out)."""
    Q = P[idx]
    C = Q - Q.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", C, C))[1][:, :, 0]


@pytest.mark.parametrize("w", [0.0, 0.5])
def test_tangent_weighted_scores_match_reference(w):
    """Step 7 of rpca_scores against numpy: residual split along / across the neighbours' normal."""
    from spectrageo.graph import knn
    from spectrageo.linalg import RPCASolverOptions as LinalgOptions
    from spectrageo.linalg import rpca

    P, _ = noise.add_outliers(_sphere(400), fraction=0.05, kind="far", rng=3)
    k = 6
    kw = dict(rho=1.5, tol=1e-9, max_iter=500)
    r = rpca_scores(P, k, RPCAOptions(refine=False, tangent_weight=w, **kw, **EXACT))
    M = knn_patch_matrix((P - P.mean(axis=0)) / r.spacing, k)
    opts = LinalgOptions(rho=kw["rho"])
    res = rpca(M, method="ialm", tol=kw["tol"], max_iter=kw["max_iter"], options=opts)
    S = res.sparse[:, 0].reshape(-1, 3)
    nrm = _neighbour_normals(P, knn(P, k)[0])
    sn = np.einsum("ij,ij->i", S, nrm)
    st = np.linalg.norm(S - sn[:, None] * nrm, axis=1)
    expect = np.hypot(sn, w * st)
    np.testing.assert_allclose(r.scores, expect, atol=1e-5 * max(1.0, expect.max()))
    if w == 0.0:  # weighting can only shrink the plain norm
        plain = rpca_scores(P, k, RPCAOptions(refine=False, tangent_weight=1, **kw, **EXACT)).scores
        assert np.all(r.scores <= plain + 1e-9) and np.any(r.scores < 0.5 * plain)


def test_tangent_weight_separates_normal_from_tangential_offsets():
    """A point pushed along the normal outscores one pushed the same distance across the plane."""
    P = _plane(30)
    i_n, i_t = 200, 600
    h = 1.0 / 30
    Q = P.copy()
    Q[i_n, 2] += 1.5 * h
    Q[i_t, 0] += 0.45 * h  # stays inside the sampling, only irregularity
    plain = rpca_scores(Q, 8, RPCAOptions(tangent_weight=1)).scores
    weighted = rpca_scores(Q, 8).scores
    assert weighted[i_n] > 0.5
    # relative to the clean points' level, the weighted score singles out the normal offset more
    others = np.delete(np.arange(len(Q)), [i_n, i_t])
    assert weighted[i_n] / np.percentile(weighted[others], 99) > plain[i_n] / np.percentile(
        plain[others], 99
    )
    with pytest.raises(InvalidInputError, match="tangent_weight"):
        RPCAOptions(tangent_weight=1.5)
    with pytest.raises(InvalidInputError, match="tangent_weight"):
        RPCAOptions(tangent_weight=-0.1)


def test_rpca_scores_invariances():
    P, _ = noise.add_outliers(_sphere(800), fraction=0.1, kind="far", rng=2)
    a = rpca_scores(P, 8).scores
    rng = np.random.default_rng(3)
    perm = rng.permutation(P.shape[0])
    b = rpca_scores(P[perm] * 7.0 + [100.0, -5.0, 3.0], 8).scores
    np.testing.assert_allclose(b, a[perm], rtol=1e-5, atol=1e-6)


def test_rpca_blocks_bound_memory_and_agree():
    P, lab = noise.add_outliers(_sphere(3000), fraction=0.1, kind="far", rng=4)
    one = rpca_scores(P, 8)
    many = rpca_scores(P, 8, RPCAOptions(block_size=700, partition="blocks"))
    tiles = rpca_scores(P, 8, RPCAOptions(block_size=700))  # "tiles": 2^3 k-d tiles with halos
    assert many.n_blocks == 5 and one.n_blocks == 1 and tiles.n_blocks == 8
    # block-wise RPCA is a different (independent) decomposition but flags the same outliers
    for r in (one, many, tiles):
        tau = auto_threshold(r.scores, minimum=0.5, rule="density")
        assert _f1(r.scores < tau, lab) > 0.9
    assert abs(tiles.spacing - one.spacing) < 1e-12 * one.spacing  # global spacing, exact kNN


def test_rpca_tiles_with_many_copies():
    # a tile made of copies of one point has no patch: the tiled partition scores the distinct
    # positions (as the single-block path does) and gives every copy its position's score
    rng = np.random.default_rng(0)
    X = np.r_[np.zeros((3000, 3)) + 5.0, rng.random((200, 3))]
    r = rpca_scores(X, 10, RPCAOptions(block_size=1000))
    assert np.isfinite(r.scores).all()
    assert np.ptp(r.scores[:3000]) == 0.0
    one = rpca_scores(X, 10)  # one block: the same deduplicated problem
    np.testing.assert_array_equal(r.scores, one.scores)


def _plane_and_box(seed=0):
    """An elongated box of points and a dense plane across it: the k-d split of the tiles puts
    every sample point of one leaf on the plane's side, so that leaf is empty."""
    rng = np.random.default_rng(seed)
    A = rng.random((1000, 3)) * [10.0, 1.0, 1.0]
    B = np.c_[np.full(3000, 5.0), rng.random((3000, 2))]
    return np.r_[A, B]


def test_rpca_tiles_with_an_empty_tile():
    from spectrageo.outliers._tiles import memory_tiles

    X = _plane_and_box()
    assert min(len(r) for r in memory_tiles(X, 1000).spill.rows) == 0
    r = rpca_scores(X, 10, RPCAOptions(block_size=1000))
    assert r.n_blocks == 4 and np.isfinite(r.scores).all()


def test_rpca_threaded_ranges_match_single_thread(monkeypatch):
    """Splitting a block into point ranges on threads sums the same Gram matrices and residuals."""
    import spectrageo.outliers._rpca_solver as rp

    P, _ = noise.add_outliers(_sphere(2500), fraction=0.1, kind="far", rng=6)
    one = rpca_scores(P, 8, workers=1, smoothed=True)
    monkeypatch.setattr(rp, "_MIN_PER_THREAD", 500)
    many = rpca_scores(P, 8, workers=3, smoothed=True)
    assert rp._n_threads(3, P.shape[0]) == 3
    assert many.n_iter == one.n_iter
    np.testing.assert_allclose(many.scores, one.scores, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(many.smoothed, one.smoothed, rtol=1e-9, atol=1e-9)


def test_oracle_threshold_is_best_cut():
    from spectrageo.evaluate.outliers import _oracle_threshold

    s = np.array([0.1, 0.2, 5.0, 3.0, 0.3, 4.0, 0.25, 3.0])
    lab = np.array([0, 0, 1, 1, 0, 1, 1, 0], bool)
    tau = _oracle_threshold(s, lab)
    best = max(_f1(s < t, lab) for t in np.unique(s))
    assert _f1(s < tau, lab) == best and tau == 0.25


def test_rpca_smoothed_is_close_to_points():
    P = _plane(30, noise_level=0.3)
    r = rpca_scores(P, 8, smoothed=True)
    assert r.smoothed.shape == P.shape
    h = r.spacing
    assert np.median(np.linalg.norm(r.smoothed - P, axis=1)) < 0.5 * h
    # the low-rank copy is flatter than the noisy input
    assert np.std(r.smoothed[:, 2]) < np.std(P[:, 2])


def test_rpca_nonconvergence_policies():
    P, _ = noise.add_outliers(_sphere(300), fraction=0.1, kind="far", rng=5)
    with pytest.warns(Warning, match="did not converge"):
        rpca_scores(P, 8, RPCAOptions(max_iter=1))
    from spectrageo._errors import ConvergenceError

    with pytest.raises(ConvergenceError):
        rpca_scores(P, 8, RPCAOptions(max_iter=1, on_nonconvergence="raise"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = rpca_scores(P, 8, RPCAOptions(max_iter=1, on_nonconvergence="ignore"))
    assert not r.converged and r.n_iter == 1


# ----------------------------------------------------------------------------- remove_outliers
@pytest.mark.parametrize("method", ["rpca", "sor", "radius"])
def test_remove_far_outliers_synthetic(method):
    P, lab = noise.add_outliers(_sphere(4000), fraction=0.1, kind="far", rng=6, shuffle=True)
    r = remove_outliers(P, method=method, k=10)
    assert r.keep.dtype == bool and r.keep.shape == lab.shape
    assert r.scores.shape == lab.shape and np.isfinite(r.scores).all()
    assert _f1(r.keep, lab) > (0.9 if method == "rpca" else 0.8)
    np.testing.assert_array_equal(r.points.points, P[r.keep])
    # the threshold reproduces the mask (rpca: points of small volumetric clusters removed too)
    if method == "rpca":
        from spectrageo.outliers._local_density import locally_sparse_kept, on_surface
        from spectrageo.outliers._rpca_types import SPARSE_FACTOR
        from spectrageo.outliers.static import SPARSE_GATE

        rs = rpca_scores(P, 10)
        d = rs.kth_distance
        sparse = (d > SPARSE_FACTOR * np.median(d)) & (r.scores >= SPARSE_GATE * r.threshold)
        cmp = (r.scores < r.threshold) & ~rs.clusters & ~sparse
        local = locally_sparse_kept(P, cmp, d, 10)
        cmp &= ~(local & ~on_surface(P, local, rs.knn))
        n_extra = r.info["n_cluster_outliers"] + r.info["n_sparse_outliers"]
        n_extra += r.info["n_locally_sparse"]
        assert n_extra >= np.count_nonzero(~r.keep & (r.scores < r.threshold))
    else:
        cmp = r.scores <= r.threshold
    np.testing.assert_array_equal(r.keep, cmp)


def test_remove_outliers_carries_attributes():
    P, lab = noise.add_outliers(_sphere(1500), fraction=0.1, kind="far", rng=7)
    n = P.shape[0]
    rng = np.random.default_rng(0)
    cloud = PointCloud(
        P,
        normals=P / np.linalg.norm(P, axis=1, keepdims=True),
        colors=rng.integers(0, 255, (n, 3)).astype(np.uint8),
        attributes={"source_index": np.arange(n)},
    )
    r = remove_outliers(cloud, method="rpca")
    kept = r.points
    np.testing.assert_array_equal(kept.attributes["source_index"], np.flatnonzero(r.keep))
    np.testing.assert_array_equal(kept.colors, cloud.colors[r.keep])
    np.testing.assert_array_equal(kept.normals, cloud.normals[r.keep])


def test_threshold_monotone_and_explicit():
    P, _ = noise.add_outliers(_sphere(1500), fraction=0.1, kind="far", rng=8)
    a = remove_outliers(P, threshold=0.5)
    b = remove_outliers(P, threshold=2.0)
    assert a.threshold == 0.5 and b.threshold == 2.0
    assert np.all(b.keep[a.keep])  # a higher tau keeps a superset (Algorithm 14)
    assert b.keep.sum() > a.keep.sum()


def test_sor_matches_definition():
    from scipy.spatial import cKDTree

    P, _ = noise.add_outliers(_sphere(500), fraction=0.1, kind="far", rng=9)
    d, _ = cKDTree(P).query(P, k=6)
    dm = d[:, 1:].mean(axis=1)
    np.testing.assert_allclose(sor_scores(P, 5), (dm - dm.mean()) / dm.std(), rtol=1e-10)
    np.testing.assert_allclose(radius_scores(P, 5), d[:, 5], rtol=1e-12)
    r = remove_outliers(P, method="sor", k=5, threshold=2.0)
    np.testing.assert_array_equal(r.keep, dm <= dm.mean() + 2.0 * dm.std())
    rr = remove_outliers(P, method="radius", k=5, threshold=0.2)
    counts = np.array([len(x) - 1 for x in cKDTree(P).query_ball_point(P, 0.2)])
    np.testing.assert_array_equal(rr.keep, counts >= 5)


def test_sor_against_open3d():
    """Open3D's ``remove_statistical_outlier`` is SOR with the query point among its
    ``nb_neighbors`` (distance 0: a mean over k + 1 distances, k / (k + 1) times ours, the same
    z-scores), the sample standard deviation (ddof 1) and a strict ``<``. With
    ``nb_neighbors = k + 1`` and ``std_ratio = threshold * sqrt((n - 1) / n)`` it is our rule: the
    same keep mask, point for point (a point within rounding of the threshold could fall on
    either side; none does on 50 seeds)."""
    o3d = require_module("open3d")
    P, lab = noise.add_outliers(_sphere(2000), fraction=0.1, kind="far", rng=10)
    n, k, t = P.shape[0], 10, 1.5
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    _, ind = pc.remove_statistical_outlier(nb_neighbors=k + 1, std_ratio=t * np.sqrt((n - 1) / n))
    keep = np.zeros(n, bool)
    keep[np.asarray(ind)] = True
    r = remove_outliers(P, method="sor", k=k, threshold=t)
    np.testing.assert_array_equal(r.keep, keep)
    # not vacuous: SOR at 1.5 std removes 63-75 % of these far outliers and nothing else
    # (measured on seeds 10-59, precision 1.0); keeping every outlier gives recall 0
    recall, precision = outlier_recall_precision(r.keep, lab)
    assert recall >= 0.55 and precision >= 0.95, (recall, precision)


def test_rpca_beats_sor_on_near_surface_outliers():
    P = _sphere(4000)
    Q, lab = noise.add_outliers(P, fraction=0.1, kind="near", normals=P, rng=11, distance=(1.5, 3))
    rp = remove_outliers(Q, method="rpca")
    best_sor = max(
        _f1(remove_outliers(Q, method="sor", k=k, threshold=t).keep, lab)
        for k in (10, 20)
        for t in (0.5, 1.0, 2.0)
    )
    assert _f1(rp.keep, lab) > best_sor


def test_clean_cloud_keeps_almost_everything():
    r = remove_outliers(_plane(40), method="rpca")
    assert r.keep.mean() > 0.97


# ----------------------------------------------------------------------------- malformed input
def test_malformed_inputs():
    with pytest.raises(InvalidInputError, match="empty"):
        remove_outliers(np.zeros((0, 3)))
    with pytest.raises(InvalidInputError, match="shape"):
        remove_outliers(np.zeros((10, 2)))
    with pytest.raises(InvalidInputError, match="None"):
        remove_outliers(None)
    with pytest.raises(InvalidInputError, match="numeric"):
        remove_outliers([["a", "b", "c"]] * 20)
    with pytest.raises(InvalidInputError, match="need at least 11 points"):
        remove_outliers(np.random.default_rng(0).random((8, 3)), k=10)
    with pytest.raises(InvalidInputError, match="method"):
        remove_outliers(_plane(5), method="lof")
    with pytest.raises(InvalidInputError, match="threshold"):
        remove_outliers(_plane(5), threshold=-1.0)
    with pytest.raises(InvalidInputError, match="apply to method='rpca' only"):
        remove_outliers(_plane(5), method="sor", options=RPCAOptions(rho=2.0))
    with pytest.raises(InvalidInputError, match="`k`"):
        remove_outliers(_plane(5), k=0)
    with pytest.raises(InvalidInputError, match="rho"):
        RPCAOptions(rho=1.0)
    with pytest.raises(InvalidInputError, match="block_size"):
        rpca_scores(_plane(5), 4, RPCAOptions(block_size=3))
    with pytest.raises(InvalidInputError, match="nonfinite"):
        remove_outliers(_plane(5), nonfinite="keep")


def test_nonfinite_rows_policy():
    P, lab = noise.add_outliers(_sphere(1000), fraction=0.1, kind="far", rng=12)
    P[[3, 50]] = [np.nan, 0.0, 0.0]
    P[70, 2] = np.inf
    with pytest.raises(
        InvalidInputError, match=r"NaN or inf coordinates at 3 row\(s\), first at index 3"
    ):
        remove_outliers(P)
    r = remove_outliers(P, nonfinite="remove", smoothed=True)
    assert not r.keep[[3, 50, 70]].any()
    assert np.isinf(r.scores[[3, 50, 70]]).all()
    assert r.info["n_nonfinite"] == 3
    assert np.isfinite(r.points.points).all()
    assert r.points.n_points == r.keep.sum()


def test_duplicates_scored_once_per_position():
    P, lab = noise.add_outliers(_sphere(1000), fraction=0.1, kind="far", rng=13)
    D = np.concatenate([P, P[:200], P[:200]])  # many exact duplicates, in-place copies
    r = remove_outliers(D, method="rpca", threshold=1.0)
    ref = remove_outliers(P, method="rpca", threshold=1.0)
    n = P.shape[0]
    np.testing.assert_allclose(r.scores[:n], ref.scores, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(r.scores[n : n + 200], ref.scores[:200], rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(r.keep[n + 200 :], ref.keep[:200])
    with pytest.raises(InvalidInputError, match="distinct"):
        remove_outliers(np.repeat(_plane(3), 5, axis=0), k=10)


def test_auto_threshold_splits_two_modes():
    rng = np.random.default_rng(0)
    s = np.concatenate([rng.uniform(0, 0.3, 900), rng.uniform(5, 10, 100)])
    t = auto_threshold(s)
    assert 0.3 <= t < 5
    assert auto_threshold(np.full(10, 2.0)) == pytest.approx(2.0)
    assert auto_threshold(s[:900], minimum=1.0) >= 1.0
    assert auto_threshold(np.array([np.inf])) == 0.0
    # density rule: the split moves down to where the (flat) outlier density takes over
    inl = np.abs(rng.standard_normal(9000)) * 0.3
    out = rng.uniform(0.0, 40.0, 1000)
    s = np.concatenate([inl, out])
    t_otsu = auto_threshold(s, minimum=0.5)
    t_dens = auto_threshold(s, minimum=0.5, rule="density")
    assert 0.5 <= t_dens < t_otsu

    def errors(t):
        return np.count_nonzero(inl >= t) + np.count_nonzero(out < t)

    assert errors(t_dens) < errors(t_otsu)
    assert auto_threshold(s, minimum=5.0, rule="density") >= 5.0
    with pytest.raises(InvalidInputError, match="rule"):
        auto_threshold(s, rule="median")


# ----------------------------------------------------------------------------- robot pipeline
def test_bilateral_filter_flattens_noisy_plane():
    P = _plane(30, noise_level=0.5, seed=1)
    Y = bilateral_point_filter(P, 7, n_iter=2)
    assert np.std(Y[:, 2]) < 0.6 * np.std(P[:, 2])
    # motion is along the (nearly vertical) normals: mostly in z
    dxy = np.linalg.norm(Y[:, :2] - P[:, :2], axis=1)
    assert np.median(dxy) < 0.2 * np.median(np.abs(Y[:, 2] - P[:, 2]))
    # an exact plane is a fixed point
    Q = _plane(20)
    np.testing.assert_allclose(bilateral_point_filter(Q, 7), Q, atol=1e-12)
    with pytest.raises(InvalidInputError, match="normals"):
        bilateral_point_filter(Q, 7, normals=np.zeros((3, 3)))
    with pytest.raises(InvalidInputError, match="sigma1"):
        bilateral_point_filter(Q, 7, sigma1=0.0)


def test_knn_triangles_are_cliques():
    P = _plane(12)
    F = knn_triangles(P, 7)
    assert F.shape[1] == 3 and F.shape[0] > P.shape[0]  # n_f > n as in Section 5.4.2
    assert np.all(F[:, 0] < F[:, 1]) and np.all(F[:, 1] < F[:, 2])
    assert np.unique(F, axis=0).shape[0] == F.shape[0]
    from scipy.spatial import cKDTree

    _, idx = cKDTree(P).query(P, k=8)
    E = {(i, j) for i in range(P.shape[0]) for j in idx[i, 1:]}
    E |= {(j, i) for i, j in E}
    assert all((a, b) in E and (b, c) in E and (a, c) in E for a, b, c in F)
    # and every clique is found (brute force on a small cloud)
    n = P.shape[0]
    brute = {
        (a, b, c)
        for a in range(n)
        for b in range(a + 1, n)
        if (a, b) in E
        for c in range(b + 1, n)
        if (b, c) in E and (a, c) in E
    }
    assert brute == {tuple(f) for f in F}


def test_robot_pipeline_mesh_and_cloud():
    P = _plane(30, noise_level=0.3, seed=2)
    Q, lab = noise.add_outliers(P, fraction=0.1, kind="far", rng=14)
    cols = np.tile(np.arange(Q.shape[0])[:, None] % 255, (1, 3)).astype(np.uint8)
    r = robot_pipeline(PointCloud(Q, colors=cols), output="mesh")
    assert _f1(r.keep, lab) > 0.8
    assert r.points.n_points == r.keep.sum()
    np.testing.assert_array_equal(r.points.colors, cols[r.keep])
    assert r.mesh.faces.shape[0] > r.points.n_points
    assert np.std(r.points.points[~lab[r.keep], 2]) < np.std(P[:, 2])
    with pytest.raises(InvalidInputError, match="output"):
        robot_pipeline(Q, output="ply")


# ----------------------------------------------------------------------------- sequences
def _moving_sequence(T=12, n_side=25, frac=0.1, seed=0):
    rng = np.random.default_rng(seed)
    P = _plane(n_side)
    frames = []
    for t in range(T):
        a = 0.05 * t
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        V = P @ R.T + [0.02 * t, 0, 0]
        V[:, 2] += 0.1 * np.sin(3 * V[:, 0] + 0.3 * t)  # non-rigid bending
        frames.append(V)
    clean = np.stack(frames)
    noisy = clean.copy()
    lab = np.zeros(clean.shape[:2], bool)
    n = clean.shape[1]
    for t in range(T):
        idx = rng.choice(n, int(frac * n), replace=False)
        lab[t, idx] = True
        d = rng.standard_normal((idx.size, 3))
        noisy[t, idx] += 0.1 * d / np.linalg.norm(d, axis=1, keepdims=True)
    return clean, noisy, lab


def test_clean_sequence_detects_and_refills():
    clean, noisy, lab = _moving_sequence()
    r = clean_sequence(PointCloudSequence(list(noisy)), k=8, tau="auto")
    keep = np.stack(r.keep)
    assert keep.shape == lab.shape
    assert _f1(keep, lab) > 0.9
    Y = np.stack([f.points for f in r.frames])
    err = np.linalg.norm(Y - clean, axis=2)
    err0 = np.linalg.norm(noisy - clean, axis=2)
    assert err.mean() < 0.2 * err0.mean()
    assert r.low_rank.shape == clean.shape


def test_clean_sequence_default_tau_and_no_refill():
    clean, noisy, lab = _moving_sequence(T=8, n_side=20)
    r = clean_sequence(noisy, k=8)  # thesis tau = 1e-4
    keep = np.stack(r.keep)
    assert np.mean(~keep[lab]) > 0.95
    r2 = clean_sequence(noisy, k=8, tau="auto", refill=False)
    assert [f.n_points for f in r2.frames] == [int(k.sum()) for k in r2.keep]


def test_clean_sequence_partitioned_matches_quality():
    clean, noisy, lab = _moving_sequence(T=10, n_side=30, seed=1)
    r = clean_sequence(noisy, k=8, tau="auto", submesh_size=300)
    assert _f1(np.stack(r.keep), lab) > 0.85


def test_clean_sequence_variable_size_falls_back_per_frame():
    frames = []
    labs = []
    for t in range(3):
        Q, lab = noise.add_outliers(_sphere(800 + 50 * t, seed=t), fraction=0.1, rng=t)
        frames.append(PointCloud(Q))
        labs.append(lab)
    r = clean_sequence(PointCloudSequence(frames), k=10)
    assert [k.size for k in r.keep] == [f.n_points for f in frames]
    assert [f.n_points for f in r.frames] == [int(k.sum()) for k in r.keep]
    for k_, lab in zip(r.keep, labs, strict=True):
        assert _f1(k_, lab) > 0.8


def test_clean_sequence_surfaces_nonconvergence():
    """Parts whose RPCA stops at max_iter are counted and reported once, by the policy."""
    from spectrageo._errors import ConvergenceError, ConvergenceWarning
    from spectrageo.outliers import SequenceResult

    clean, noisy, lab = _moving_sequence(T=12, n_side=20)  # 400 points, 3 parts of 200
    kw = dict(k=8, max_iter=1, submesh_size=200)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        r = clean_sequence(noisy, **kw)
    msgs = [str(w.message) for w in rec if issubclass(w.category, ConvergenceWarning)]
    assert len(msgs) == 1, msgs
    assert not r.converged and r.n_iter == 1 and r.residual > 0
    assert f"did not converge on {r.n_unconverged} of " in msgs[0] and r.n_unconverged >= 2
    with pytest.raises(ConvergenceError, match="did not converge") as exc:
        clean_sequence(noisy, on_nonconvergence="raise", **kw)
    assert isinstance(exc.value.partial, SequenceResult)
    assert exc.value.partial.n_unconverged == r.n_unconverged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        quiet = clean_sequence(noisy, on_nonconvergence="ignore", **kw)
        ok = clean_sequence(noisy, k=8, submesh_size=200)  # default iterations: converges
    assert quiet.n_unconverged == r.n_unconverged and not quiet.converged
    assert ok.converged and ok.n_unconverged == 0
    with pytest.raises(InvalidInputError, match="on_nonconvergence"):
        clean_sequence(noisy, on_nonconvergence="loud")


def test_clean_sequence_variable_size_surfaces_nonconvergence():
    from spectrageo._errors import ConvergenceWarning

    frames = [PointCloud(_sphere(300 + 40 * t, seed=t)) for t in range(3)]
    with pytest.warns(ConvergenceWarning, match="on 3 of 3 frames") as rec:
        r = clean_sequence(PointCloudSequence(frames), k=8, max_iter=1)
    assert sum(issubclass(w.category, ConvergenceWarning) for w in rec) == 1
    assert r.n_unconverged == 3 and not r.converged and r.n_iter == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = clean_sequence(PointCloudSequence(frames), k=8)
    assert ok.converged and ok.n_unconverged == 0 and ok.n_iter > 1


def test_clean_sequence_errors():
    with pytest.raises(InvalidInputError, match="None"):
        clean_sequence(None)
    with pytest.raises(InvalidInputError, match=r"\(T, n, 3\)"):
        clean_sequence(np.zeros((4, 3)))
    with pytest.raises(InvalidInputError, match="empty"):
        clean_sequence(np.zeros((0, 5, 3)))
    with pytest.raises(InvalidInputError, match="tau"):
        clean_sequence(np.random.default_rng(0).random((3, 20, 3)), tau=0.0)
    with pytest.raises(InvalidInputError, match="overlap"):
        clean_sequence(np.random.default_rng(0).random((3, 20, 3)), overlap=1.0)
    with pytest.raises(InvalidInputError, match="need at least"):
        clean_sequence(np.random.default_rng(0).random((3, 5, 3)), k=10)
    with pytest.raises(InvalidInputError, match="no spatial extent"):
        clean_sequence(np.zeros((3, 20, 3)))


def test_weighted_laplacian_rows():
    import scipy.sparse as sp

    # path graph 0-1-2, vertex 1 unknown
    C = sp.csr_matrix(np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], float))
    prev = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
    motion = np.array([[1.0, 0, 0], [0, 0, 0], [1, 0, 0]])
    known = np.array([True, False, True])
    L = weighted_laplacian(C, prev, motion, known).toarray()
    np.testing.assert_allclose(L.sum(axis=1), 0.0, atol=1e-12)  # L = D - C_w
    # row 1: W1 = 1/d^2 (scaled by the median d^2 = 2.5), W2 = 1 (zero motion), W3 = 4 (known)
    np.testing.assert_allclose(-L[1, [0, 2]], [4 * 2.5 / 1.0, 4 * 2.5 / 4.0])
    # row 0: neighbour 1 unknown at 1 hop -> W3 = 1/2; motions (1,0,0)/(0) -> W2 = 1
    np.testing.assert_allclose(-L[0, 1], 0.5 * 2.5 / 1.0)
