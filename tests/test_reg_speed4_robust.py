"""The registration's outlier and boundary tests (Eq. 6.42-6.44) computed with less work.

``outlier_keep`` promises the decision of the full NumPy patch RPCA (``outlier_result(P, k).scores
<= threshold``) for every point, and the neighbour lists it searched; the boundary test's
distances from known neighbours promise the values of the formula they replace. Both are checked
for exact equality.
"""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import io
from spectrageo.register._robust import boundary_mask, exact_neighbors, outlier_result
from spectrageo.register._robust_fast import _knn, _rebuild, outlier_keep

from conftest import shared_file


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(11)
    sphere = rng.normal(size=(3000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    noisy = np.vstack([sphere, rng.uniform(-1.5, 1.5, size=(300, 3))])  # patches rebuilt
    u, v = rng.random((2, 4000))
    plane = np.column_stack([u, v, 0.003 * rng.normal(size=4000)])
    clustered = np.vstack([plane, 0.5 + 0.02 * rng.normal(size=(120, 3))])
    g = np.arange(40, dtype=float)
    gx, gy = np.meshgrid(g, g)
    grid = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])  # equidistant neighbours
    grid = np.vstack([grid, [[10.5, 10.5, 3.0], [20.2, 5.1, -2.0], [30.0, 30.0, 1.5]]])
    dup = np.vstack([sphere[:1000], sphere[:50]])  # exact copies: the general path
    return {"noisy": noisy, "clustered": clustered, "grid": grid, "dup": dup}


@pytest.mark.parametrize("name", ["noisy", "clustered", "grid", "dup"])
def test_outlier_keep_is_the_full_decision(name):
    X = _clouds()[name]
    ref = outlier_result(X, 10)
    for thr in (0.0, 0.3, 0.6, 1.0, 5.0):
        keep, nbrs, _ = outlier_keep(X, 10, thr)
        np.testing.assert_array_equal(keep, ref.scores <= thr)
        np.testing.assert_array_equal(nbrs, exact_neighbors(ref))
    assert keep.dtype == bool and keep.shape == (X.shape[0],)


def test_outlier_keep_removes_the_scattered_points():
    X = _clouds()["noisy"]
    keep = outlier_keep(X, 10, 0.6)[0]
    assert keep[:3000].mean() > 0.95
    assert keep[3000:].mean() < 0.5


def test_knn_shortcut_matches_the_chunked_search():
    from spectrageo.outliers._common import knn_chunked

    X = _clouds()["noisy"]
    nb, tree = _knn(X, 10)[:2]
    ref = knn_chunked(X, 10)
    np.testing.assert_array_equal(nb.idx, ref.idx)
    np.testing.assert_array_equal(nb.dmean, ref.dmean)
    np.testing.assert_array_equal(nb.dlast, ref.dlast)
    assert nb.idx.dtype == ref.idx.dtype and nb.n_zero == 0 and tree.n == X.shape[0]
    assert _knn(_clouds()["dup"], 10) is None  # a point with a copy: the general path


@pytest.mark.parametrize("name", ["noisy", "clustered", "grid"])
def test_rebuild_from_the_whole_tree_matches(name):
    from spectrageo.outliers import _rpca_numpy as rn

    X = _clouds()[name]
    nb, tree = _knn(X, 10)[:2]
    s1 = np.zeros(X.shape[0])
    rng = np.random.default_rng(3)
    s1[rng.choice(X.shape[0], X.shape[0] // 8, replace=False)] = 5.0  # flagged points
    if name != "grid":  # the scattered points / the dense cluster: rows with no unflagged
        s1[X.shape[0] - {"noisy": 300, "clustered": 120}[name] :] = 5.0  # point among 2 (k + 1)
    a, b = nb.idx.copy(), nb.idx.copy()
    ra, oa = _rebuild(X, tree, a, s1, 10)
    rb, ob = rn._rebuild(X, b, s1, 10)
    assert ra.size > 0
    np.testing.assert_array_equal(ra, rb)
    np.testing.assert_array_equal(oa, ob)
    np.testing.assert_array_equal(a, b)


def test_boundary_distances_are_the_formula_they_replace():
    from spectrageo.register._robust import _neighbor_distances

    X = _clouds()["noisy"]
    nbrs = outlier_keep(X, 10, 0.6)[1]
    ref = np.sqrt(np.square(X[nbrs] - X[:, None, :]).sum(axis=2))
    np.testing.assert_array_equal(_neighbor_distances(X, nbrs), ref)
    np.testing.assert_array_equal(boundary_mask(X, 10, nbrs), boundary_mask(X, 10))


def test_outlier_keep_on_a_real_scan(shared_data):
    f = shared_file(shared_data, "scans", "bunny", "bun045.ply.gz")
    X = io.read_point_cloud(f).points
    ref = outlier_result(X, 10)
    keep, nbrs, _ = outlier_keep(X, 10, 0.6)
    np.testing.assert_array_equal(keep, ref.scores <= 0.6)
    np.testing.assert_array_equal(nbrs, exact_neighbors(ref))
    assert 0 < np.count_nonzero(~keep) < 0.05 * X.shape[0]


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("k", [3, 10])
def test_outlier_keep_on_random_clouds(seed, k):
    """Heavy tails, near-collinear points (the normals' ``eigh`` fallback) and Fortran-ordered
    input: the same decision as the full scores."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 1500))
    if seed % 3 == 0:
        X = rng.standard_cauchy(size=(n, 3))
    elif seed % 3 == 1:
        t = rng.random(n)
        X = np.column_stack([t, 2 * t, 3 * t]) + 1e-6 * rng.normal(size=(n, 3))
    else:
        X = np.asfortranarray(np.column_stack([rng.random((n, 2)), 0.01 * rng.normal(size=n)]))
    ref = outlier_result(X, k)
    for thr in (0.1, 0.6, 2.0):
        keep, nbrs, _ = outlier_keep(X, k, thr)
        np.testing.assert_array_equal(keep, ref.scores <= thr)
        np.testing.assert_array_equal(nbrs, exact_neighbors(ref))
