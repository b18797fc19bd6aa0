"""Small volumetric clusters (step 8 of :func:`spectrageo.outliers.rpca_scores`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spectrageo import io, noise
from spectrageo.outliers import RPCAOptions, detect_outliers, rpca_scores
from spectrageo.outliers._clusters import cluster_outliers

from conftest import shared_file


def _plane(n_side=60, seed=0):
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 1.0, n_side)
    X, Y = np.meshgrid(g, g)
    P = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    P[:, :2] += rng.normal(0.0, 1e-3, (P.shape[0], 2))
    return P


def _knn(P, k=10):
    d, nb = cKDTree(P).query(P, k + 1)
    return nb[:, 1:], float(np.median(d[:, 1:].mean(axis=1)))


def _f1(removed, labels):
    tp = np.count_nonzero(removed & labels)
    p = tp / max(np.count_nonzero(removed), 1)
    r = tp / max(np.count_nonzero(labels), 1)
    return 2 * p * r / (p + r) if p + r else 0.0


def test_blob_flagged_flat_fragment_kept():
    P = _plane()
    h = 1.0 / 59
    rng = np.random.default_rng(1)
    blob = np.array([0.5, 0.5, 0.6]) + 3 * h * rng.standard_normal((40, 3))
    g = np.linspace(0, 6 * h, 7)
    fx, fy = np.meshgrid(g, g)  # a flat 49-point piece of surface, apart from the plane
    frag = np.c_[fx.ravel() + 0.2, fy.ravel() + 0.2, np.full(fx.size, 0.4)]
    single = np.array([[0.9, 0.1, 0.8]])
    X = np.vstack([P, blob, frag, single])
    idx, hh = _knn(X)
    flag = cluster_outliers(X, idx, hh)
    n0 = P.shape[0]
    assert not flag[:n0].any()  # the surface
    assert flag[n0 : n0 + 40].sum() >= 36  # the volumetric blob (stragglers left to the score)
    assert not flag[n0 + 40 : n0 + 40 + frag.shape[0]].any()  # the flat fragment
    assert not flag[-1]  # an isolated point is left to the score


def test_limits_and_largest_component():
    rng = np.random.default_rng(2)
    X = rng.standard_normal((80, 3))  # one volumetric cloud of 80 points: the largest component
    idx, h = _knn(X)
    assert not cluster_outliers(X, idx, h).any()
    # nothing is flagged when no component may be (a tenth of 80 points is 8 < 40 per blob)
    Y = np.vstack([X, X + 100.0])
    idx, h = _knn(Y)
    assert not cluster_outliers(Y, idx, h).any()
    # max_size bounds the flagged components
    P = _plane(40)
    blob = np.array([0.5, 0.5, 0.7]) + 0.05 * rng.standard_normal((60, 3))
    Z = np.vstack([P, blob])
    idx, h = _knn(Z)
    assert cluster_outliers(Z, idx, h, max_size=150)[-60:].sum() >= 55
    assert not cluster_outliers(Z, idx, h, max_size=30)[-60:].any()


def test_rpca_scores_clusters_option_and_input_order():
    P = _plane(40)
    rng = np.random.default_rng(5)
    centres = np.array([[0.2, 0.3, 0.5], [0.7, 0.6, -0.4], [0.5, 0.5, 0.9]])
    blobs = np.vstack([c + 0.06 * rng.standard_normal((30, 3)) for c in centres])
    Q = np.vstack([P, blobs])
    lab = np.r_[np.zeros(P.shape[0], bool), np.ones(blobs.shape[0], bool)]
    perm = rng.permutation(Q.shape[0])
    Q, lab = Q[perm], lab[perm]
    r = rpca_scores(Q, 10)
    assert r.clusters is not None and r.clusters.shape == (Q.shape[0],)
    assert _f1(r.clusters, lab) >= 0.9  # input order: the flags match the labels
    assert rpca_scores(Q, 10, RPCAOptions(clusters=False)).clusters is None
    # duplicates: every copy gets the flag of its position
    D = np.vstack([Q, Q[:50]])
    rd = rpca_scores(D, 10)
    assert np.array_equal(rd.clusters[-50:], rd.clusters[:50])


@pytest.mark.slow
def test_blobs_on_a_real_scan(shared_data):
    """Tuning scan: the cluster rule lifts the F1 on blobs and flags almost nothing on the scan."""
    path = shared_file(shared_data, "scans", "bunny", "bun000.ply.gz")
    P = io.read(path, kind="points").points
    clean = detect_outliers(P)
    assert clean.info["n_cluster_outliers"] <= 0.002 * P.shape[0]
    Q, lab = noise.corrupt_outliers(P, pattern="blobs", fraction=0.1, rng=0)
    on = detect_outliers(Q)
    off = detect_outliers(Q, options=RPCAOptions(clusters=False))
    f_on, f_off = _f1(~on.keep, lab), _f1(~off.keep, lab)
    assert f_on >= 0.93 and f_on >= f_off + 0.1
    assert on.info["n_cluster_outliers"] > 0 and off.info["n_cluster_outliers"] == 0
    assert 0.05 <= on.info["contamination"] <= 0.15
