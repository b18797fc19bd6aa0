"""Exact speed-ups of the RPCA outlier pipeline at 100k points give the bits of the computations
they replace (docs/decisions.md#outliers7-speed-100k): the radix sort of the Morton codes, the
octree pass of few far queries on threads, the locally sparse stage on the pass's sorted cloud,
the replay's two passes on two threads, the cluster links known short from the kNN and the
density rule's bin counts without a sort."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import noise
from spectrageo.outliers import _common as common
from spectrageo.outliers import _rpca_solver as rp
from spectrageo.outliers import detect_outliers
from spectrageo.outliers._clusters import cluster_outliers
from spectrageo.outliers._common import SortedCloud, knn_grid, spacing_from
from spectrageo.outliers._grid import radix_argsort
from spectrageo.outliers._local_density import locally_sparse_kept


def _sheet(n, seed, frac=0.1):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    P = np.column_stack([xy, 0.05 * np.sin(5 * xy[:, 0])])
    return noise.corrupt_outliers(P, pattern="mixed", fraction=frac, rng=seed)[0]


@pytest.mark.parametrize("n", [0, 1, 2, 7, 1000, 50_000])
def test_radix_sort_is_the_stable_argsort(n):
    rng = np.random.default_rng(n)
    cases = [
        rng.integers(0, 2**63, n, dtype=np.uint64) * np.uint64(2) + np.uint64(1),  # top bit too
        rng.integers(0, 40, n).astype(np.uint64) << np.uint64(33),  # ties, shared low digits
        rng.integers(0, 3000, n).astype(np.uint64),
        np.full(n, 5, dtype=np.uint64),
    ]
    for keys in cases:
        assert np.array_equal(radix_argsort(keys), np.argsort(keys, kind="stable"))
    assert np.array_equal(common.sort_codes(cases[1]), np.argsort(cases[1], kind="stable"))


def test_far_queries_same_lists_on_one_or_all_threads(monkeypatch):
    """The step-5 search (far queries on a subset) gives the same lists whether its octree
    pass runs on the calling thread or on numba's threads."""
    P = _sheet(20_000, 1, frac=0.2)
    sc = SortedCloud.of(P)
    rng = np.random.default_rng(0)
    kept = np.sort(rng.choice(P.shape[0], 15_000, replace=False))
    query = np.setdiff1d(np.arange(P.shape[0]), kept)
    out = []
    for below in (10**9, 0):
        monkeypatch.setattr(common, "KNN_SERIAL_BELOW", below)
        nb = knn_grid(sc, 10, subset=kept, query=query, self_index=np.full(query.size, -1))
        out.append((nb.idx.copy(), nb.dmean.copy(), nb.dlast.copy()))
    for a, b in zip(*out):
        assert np.array_equal(a, b)


def test_locally_sparse_on_the_pass_order_equals_its_own_sort():
    P = _sheet(8_000, 2)
    sc = SortedCloud.of(P)
    kth = knn_grid(sc, 10).dlast
    d = np.empty_like(kth)
    d[sc.order] = kth
    rng = np.random.default_rng(1)
    for share in (1.0, 0.9, 0.6):
        keep = rng.random(P.shape[0]) < share
        a = locally_sparse_kept(P, keep, d, 10, order=sc.order)
        b = locally_sparse_kept(P, keep, d, 10)  # sorts the cloud itself
        c = locally_sparse_kept(P, keep, d, 10, order=np.arange(P.shape[0]))  # not Morton: sorts
        assert a.any() and np.array_equal(a, b) and np.array_equal(a, c)


def test_cluster_links_known_short_change_nothing():
    P = _sheet(20_000, 3)
    rng = np.random.default_rng(3)
    blobs = np.concatenate([c + 0.004 * rng.standard_normal((30, 3)) for c in rng.random((8, 3))])
    sc = SortedCloud.of(np.vstack([P, blobs]))
    nb = knn_grid(sc, 10)
    h = spacing_from(nb.dmean)
    a = cluster_outliers(sc.points, nb.idx, h)
    b = cluster_outliers(sc.points, nb.idx, h, kth=nb.dlast)
    assert a.sum() >= 30 and np.array_equal(a, b)


def test_replay_on_two_threads_gives_the_same_bits(monkeypatch):
    P = _sheet(30_000, 4, frac=0.15)
    runs = []
    for threaded_from in (10**9, 1):
        monkeypatch.setattr(rp, "_REPLAY_THREADED", threaded_from)
        r = detect_outliers(P, method="rpca")
        runs.append(r)
    a, b = runs
    assert a.info["n_refined"] > 500
    assert np.array_equal(a.scores, b.scores) and np.array_equal(a.keep, b.keep)


def test_density_rule_counts_equal_numpy_histogram():
    from spectrageo.outliers._thresholds import _bin_counts

    rng = np.random.default_rng(5)
    for _ in range(200):
        s = np.abs(rng.standard_normal(int(rng.integers(1, 3000)))) * rng.uniform(0.1, 10)
        w = rng.uniform(0.01, 1.0)
        edges = np.arange(0.0, rng.uniform(0.5, 5.0) + w, w)
        s[:3] = edges[rng.integers(0, edges.size, 3)]  # values on the edges, the last included
        assert np.array_equal(_bin_counts(s, edges), np.histogram(s, edges)[0])
