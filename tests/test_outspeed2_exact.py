"""Exact speed-ups of the RPCA outlier pipeline give the bits of the computations they replace
(docs/decisions.md#outliers-speed-exact-paths-2): the hashed cell lookup and the precomputed
octree boxes of the kNN search, the block normalisation, the patch quantile of step 6, the flag
counts, and the bounds that skip rows of the sparse-region stage."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import noise
from spectrageo.outliers import _grid as grid
from spectrageo.outliers import _kernels as kern
from spectrageo.outliers import _rpca_solver as rp
from spectrageo.outliers import _support as sup
from spectrageo.outliers._common import KNN_SERIAL_BELOW, SortedCloud, knn_chunked, knn_grid


def _sheet(n, seed, frac=0.1, offset=0.0):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    P = np.column_stack([xy, 0.05 * np.sin(5 * xy[:, 0])]) + offset
    return noise.corrupt_outliers(P, pattern="mixed", fraction=frac, rng=seed)[0]


def test_cell_table_finds_the_sorted_positions():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 100, 5000):
        keys = np.unique(rng.integers(0, 2**40, n).astype(np.uint64))
        table, shift = grid._cell_table(keys)
        assert table.size >= 2 * keys.size and (table >= 0).sum() == keys.size
        probe = np.concatenate([keys, rng.integers(0, 2**40, 300).astype(np.uint64)])
        for key in probe:
            p = int(np.searchsorted(keys, key))
            want = p if p < keys.size and keys[p] == key else -1
            assert grid._find_cell(table, shift, keys, key) == want


def test_cell_boxes_equal_the_former_box_distance():
    """Precomputed boxes give the squared distances of the former inline formula bit for bit."""
    rng = np.random.default_rng(1)
    lo = np.array([-3.25, 1e5, 0.125])
    wl = np.array([2.0**-7, 2.0**-6, 2.0**-5]) * 1.37
    ckey = rng.integers(0, 2**30, 400).astype(np.uint64)
    clev = rng.integers(0, 3, 400).astype(np.int64)
    box = grid._cell_boxes(ckey, clev, wl, lo)
    for f in range(ckey.size):
        w = wl[clev[f]]
        e = 1e-9 * w
        c = [float(grid._compact3(ckey[f] >> np.uint64(a))) for a in range(3)]
        q = lo + rng.random(3) * 2.0**10 * w
        acc = 0.0
        for a in range(3):
            x0 = lo[a] + c[a] * w - e
            g = max(x0 - q[a], 0.0, q[a] - (x0 + (w + 2 * e)))
            acc += g * g  # gx * gx + gy * gy + gz * gz, in that order
        assert grid._box_dist2(box, f, q[0], q[1], q[2]) == acc


@pytest.mark.parametrize("case", ["sheet", "offset", "lattice"])
def test_grid_knn_matches_the_kd_tree_and_thread_counts(case):
    import numba

    if case == "lattice":  # equidistant neighbours everywhere: the order is the search's own
        g = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0)), -1).reshape(-1, 2)
        P = np.column_stack([g, np.zeros(len(g))])
    else:
        P = _sheet(20000, 3, offset=1e5 if case == "offset" else 0.0)
    sc = SortedCloud.of(P)
    runs = []
    for threads in (1, numba.config.NUMBA_NUM_THREADS):
        old = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            runs.append(knn_grid(sc, 10))
        finally:
            numba.set_num_threads(old)
    for a, b in zip(runs[0].__dict__.values(), runs[1].__dict__.values(), strict=True):
        np.testing.assert_array_equal(a, b)
    ref = knn_chunked(sc.points, 10)
    np.testing.assert_allclose(runs[0].dmean, ref.dmean, rtol=1e-12)
    if case != "lattice":
        np.testing.assert_array_equal(runs[0].idx, ref.idx)


def test_small_query_sets_run_on_the_calling_thread_with_the_same_lists():
    P = _sheet(30000, 4)
    sc = SortedCloud.of(P)
    full = knn_grid(sc, 8)
    q = np.arange(0, P.shape[0], 7)
    assert q.size < KNN_SERIAL_BELOW
    part = knn_grid(sc, 8, query=q, self_index=q)
    np.testing.assert_array_equal(part.idx, full.idx[q])
    np.testing.assert_array_equal(part.dmean, full.dmean[q])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_block_normalisation_equals_numpy(dtype):
    rng = np.random.default_rng(5)
    for t in range(12):
        n = int(rng.integers(1, 40000))
        X = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3) + rng.normal(size=3) * 1e4
        if t % 3 == 0:
            X[:, 2] = -0.0  # numpy's sum starts at +0.0
        lo = int(rng.integers(0, max(n // 2, 1)))
        hi = int(rng.integers(lo + 1, n + 1))
        inv_h = 1.0 / rng.uniform(0.01, 10.0)
        Pn = np.empty(X.shape, dtype)
        centre = rp._normalise(X, lo, hi, inv_h, Pn)
        ref_c = X[lo:hi].mean(axis=0)
        ref = ((X - ref_c) * inv_h).astype(dtype)
        assert centre.tobytes() == ref_c.tobytes()
        assert Pn.tobytes() == ref.tobytes()


@pytest.mark.parametrize("k, q", [(10, 0.3), (10, 0.0), (10, 1.0), (7, 0.5), (1, 0.3), (16, 0.77)])
def test_patch_quantile_equals_the_sorted_order_statistics(k, q):
    rng = np.random.default_rng(k)
    n = 3000
    s1 = np.round(rng.exponential(size=n), 1)  # many ties
    idx = rng.integers(0, n, (n, k)).astype(np.int32)
    scores = rng.exponential(size=n)
    out = scores.copy()
    kern.subtract_patch_quantile(out, s1, idx, q)
    pos = q * (k - 1)
    lo = min(int(np.floor(pos)), k - 1)
    hi = min(lo + 1, k - 1)
    v = np.sort(s1[idx], axis=1)
    base = v[:, lo] + (pos - lo) * (v[:, hi] - v[:, lo])
    ref = np.maximum(scores - base, 0.0)
    assert out.tobytes() == ref.tobytes()


def test_count_flagged_equals_numpy():
    rng = np.random.default_rng(6)
    idx = rng.integers(0, 5000, (5000, 10)).astype(np.int32)
    flagged = rng.random(5000) < 0.2
    np.testing.assert_array_equal(kern.count_flagged(idx, flagged), flagged[idx].sum(axis=1))


def _support_cases():
    rng = np.random.default_rng(7)
    yield "sheet", _sheet(6000, 8), 0.3
    yield "offset", _sheet(6000, 9, offset=1e5), 0.3
    g = np.stack(np.meshgrid(np.arange(50.0), np.arange(50.0)), -1).reshape(-1, 2)
    L = np.column_stack([g, np.zeros(len(g))])
    yield "lattice", np.vstack([L, rng.uniform(-5, 55, (200, 3))]), 0.4
    S = rng.normal(size=(5000, 3))
    S /= np.linalg.norm(S, axis=1)[:, None]
    yield "sphere", np.vstack([S, 0.05 * rng.normal(size=(300, 3)) + [2, 0, 0]]), 0.5
    line = np.column_stack([np.linspace(0, 1, 3000), 1e-9 * rng.normal(size=(3000, 2))])
    yield "line", line, 0.5


@pytest.mark.parametrize("case", ["sheet", "offset", "lattice", "sphere", "line"])
def test_support_bounds_exclude_no_candidate(case, monkeypatch):
    """Rows skipped by the bounds are never candidates, and the stage keeps the same points as
    with every row tested exactly."""
    X, share = next((P, s) for name, P, s in _support_cases() if name == case)
    rng = np.random.default_rng(10)
    removed = rng.random(X.shape[0]) < share
    sc = SortedCloud.of(X)
    knn = (sc.order, knn_grid(sc, 10).idx)
    rows = np.flatnonzero(removed)
    inv = np.empty(X.shape[0], dtype=np.int64)
    inv[sc.order] = np.arange(X.shape[0])
    nb = sc.order[knn[1][inv[rows]]]
    out = np.empty(rows.size, dtype=bool)
    kern.surely_not_surface(X, rows, nb, sup.SUPPORT_BETA, sup.SUPPORT_FLAT, out)
    cand = sup._candidates(X, rows, nb, sup.SUPPORT_BETA, sup.SUPPORT_FLAT)
    assert not np.any(out & cand)
    fast = sup.sparse_surface(X, removed, 10, knn)
    monkeypatch.setattr(kern, "surely_not_surface", lambda X, r, n, b, f, o: o.fill(False))
    slow = sup.sparse_surface(X, removed, 10, knn)
    np.testing.assert_array_equal(fast, slow)
    if case in ("sheet", "sphere"):
        assert out.any()  # the bounds do skip rows
