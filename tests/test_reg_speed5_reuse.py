"""The robustification's k-d tree search reused by the narrow phase (spacing, target normals).

``spacing_from_search`` promises the value of ``spacing(P[keep])`` and ``neighbors_from_search``
the neighbour lists of a search of ``P[keep]`` (hence the same normals) wherever it answers;
both are checked for exact equality, and ``register`` for the same result with and without them.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spectrageo import io
from spectrageo.register import _api, register
from spectrageo.register._common import knn_normals_at, spacing
from spectrageo.register._narrow import (
    NORMAL_K,
    TargetIndex,
    neighbors_from_search,
    spacing_from_search,
)
from spectrageo.register._robust import exact_neighbors, outlier_result
from spectrageo.register._robust_fast import outlier_keep

from conftest import shared_file


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(5)
    sphere = rng.normal(size=(3000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    noisy = np.vstack([sphere, rng.uniform(-1.5, 1.5, size=(300, 3))])
    u, v = rng.random((2, 4000))
    plane = np.column_stack([u, v, 0.003 * rng.normal(size=4000)])
    g = np.arange(40, dtype=float)
    gx, gy = np.meshgrid(g, g)
    grid = np.column_stack([gx.ravel(), gy.ravel(), 0.01 * (gx.ravel() % 3)])  # many ties
    return {"noisy": noisy, "plane": plane, "grid": grid}


def _search(P: np.ndarray, k: int = 10):
    tree = cKDTree(P)
    d, i = tree.query(P, k=k + 1)
    assert np.array_equal(i[:, 0], np.arange(P.shape[0])) and np.all(d[:, 1] > 0)
    return d, i


def _masks(n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    few = rng.random(n) > 0.02
    many = rng.random(n) > 0.4
    return [np.ones(n, dtype=bool), few, many]


@pytest.mark.parametrize("name", ["noisy", "plane", "grid"])
def test_spacing_from_search_is_the_spacing_of_the_kept_points(name):
    P = _clouds()[name]
    d, i = _search(P)
    answered = 0
    for keep in _masks(P.shape[0]):
        h = spacing_from_search(keep, d, i)
        if h is not None:
            answered += 1
            assert h == spacing(P[keep])
    assert answered >= 2


def test_spacing_from_search_declines_without_a_kept_neighbour():
    P = _clouds()["plane"]
    d, i = _search(P)
    keep = np.zeros(P.shape[0], dtype=bool)
    keep[::40] = True  # every kept point's 10 nearest are removed
    assert spacing_from_search(keep, d, i) is None
    assert spacing_from_search(np.eye(1, P.shape[0], dtype=bool)[0], d, i) is None


@pytest.mark.parametrize("name", ["noisy", "plane", "grid"])
def test_neighbors_from_search_give_the_searched_normals(name):
    P = _clouds()[name]
    d, i = _search(P)
    for keep in _masks(P.shape[0]):
        T = P[keep]
        nb = neighbors_from_search(keep, d, i, NORMAL_K)
        known = nb[:, 0] >= 0
        _, ref = cKDTree(T).query(T[known], k=NORMAL_K)
        np.testing.assert_array_equal(nb[known], ref)
        assert np.all(nb[~known] == -1)
        if name != "grid" and keep.mean() > 0.9:
            assert known.mean() > 0.8
        rows = np.arange(T.shape[0])
        reused = TargetIndex(T, neighbors=nb)
        searched = TargetIndex(T)
        for j in (rows[::7], rows[::3], rows):  # lazily, in batches
            np.testing.assert_array_equal(reused.normals_at(j), searched.normals_at(j))
        expect = knn_normals_at(T, T, NORMAL_K, cKDTree(T))[0]
        np.testing.assert_array_equal(reused.normals_at(rows), expect)


def test_neighbors_from_search_needs_enough_columns():
    P = _clouds()["noisy"]
    d, i = _search(P, 5)
    assert neighbors_from_search(np.ones(P.shape[0], dtype=bool), d, i, NORMAL_K) is None
    # lists of the wrong shape are ignored (every normal searched)
    index = TargetIndex(P, neighbors=np.zeros((3, NORMAL_K), dtype=np.intp))
    rows = np.arange(0, P.shape[0], 5)
    np.testing.assert_array_equal(index.normals_at(rows), TargetIndex(P).normals_at(rows))


def test_outlier_keep_returns_its_search():
    P = _clouds()["noisy"]
    keep, nbrs, search = outlier_keep(P, 10, 0.6)
    full = outlier_result(P, 10)
    k2, n2 = full.scores <= 0.6, exact_neighbors(full)
    np.testing.assert_array_equal(keep, k2)
    np.testing.assert_array_equal(nbrs, n2)
    tree, d, i = search
    d0, i0 = _search(P)
    np.testing.assert_array_equal(d, d0)
    np.testing.assert_array_equal(i, i0)
    assert tree.n == P.shape[0]
    dup = np.vstack([P[:500], P[:20]])  # exact copies: no search to reuse
    assert outlier_keep(dup, 10, 0.6)[2] is None


def _pair():
    rng = np.random.default_rng(2)
    u, v = rng.random((2, 6000)) * 2 * np.pi
    tor = np.column_stack([(2 + np.cos(v)) * np.cos(u), (2 + np.cos(v)) * np.sin(u), np.sin(v)])
    A = tor[:3500] + 0.005 * rng.normal(size=(3500, 3))
    B = tor[2500:] + 0.005 * rng.normal(size=(3500, 3))
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return A @ R.T + [0.2, -0.1, 0.05], B


def _counting(monkeypatch) -> list:
    """Record what the reuse answers during the next registration."""
    got: list = []
    sp, nb = _api.spacing_from_search, _api.neighbors_from_search

    def spy_spacing(*a, **k):
        got.append(sp(*a, **k))
        return got[-1]

    def spy_neighbors(*a, **k):
        got.append(nb(*a, **k))
        return got[-1]

    monkeypatch.setattr(_api, "spacing_from_search", spy_spacing)
    monkeypatch.setattr(_api, "neighbors_from_search", spy_neighbors)
    return got


def _used(got: list) -> None:
    """Both spacings and the target's neighbour lists came from the search."""
    assert len(got) == 3 and all(g is not None for g in got)
    assert (got[1][:, 0] >= 0).mean() > 0.8


def _without_reuse(monkeypatch):
    monkeypatch.setattr(_api, "spacing_from_search", lambda *a, **k: None)
    monkeypatch.setattr(_api, "neighbors_from_search", lambda *a, **k: None)


def _same(a, b):
    np.testing.assert_array_equal(a.transformation, b.transformation)
    assert (a.fitness, a.inlier_rmse, a.n_iter, a.converged) == (
        b.fitness,
        b.inlier_rmse,
        b.n_iter,
        b.converged,
    )
    assert a.info["constraint"] == b.info["constraint"]
    assert a.info["tight_share"] == b.info["tight_share"]


def test_register_gives_the_same_result_without_the_reuse(monkeypatch):
    S, T = _pair()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = _counting(monkeypatch)
        fast = register(S, T, rng=0, max_points=2000)
        _used(got)
        _without_reuse(monkeypatch)
        slow = register(S, T, rng=0, max_points=2000)
    _same(fast, slow)


def test_register_same_result_without_the_reuse_on_a_scan_pair(shared_data, monkeypatch):
    f0 = shared_file(shared_data, "scans", "bunny", "bun000.ply.gz")
    f1 = shared_file(shared_data, "scans", "bunny", "bun045.ply.gz")
    S, T = io.read_point_cloud(f0).points, io.read_point_cloud(f1).points
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = _counting(monkeypatch)
        fast = register(S, T, rng=0)
        _used(got)
        _without_reuse(monkeypatch)
        slow = register(S, T, rng=0)
    _same(fast, slow)
    assert fast.converged


def test_prepared_target_reuses_the_tree_when_every_point_is_kept(monkeypatch):
    n = 4000  # a Fibonacci sphere: even spacing, no outlier or boundary point
    z = 1.0 - (2.0 * np.arange(n) + 1.0) / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * np.arange(n)
    r = np.sqrt(1.0 - z * z)
    P = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    seen: list = []
    robustify = _api._robustify

    def spy(*a, **k):
        seen.append(robustify(*a, **k))
        return seen[-1]

    monkeypatch.setattr(_api, "_robustify", spy)
    pt = _api.prepare_target(P, max_points=n)
    assert pt.n_kept == n
    assert pt.index.tree is seen[0][2][0]
    searched = TargetIndex(pt.narrow_points)
    assert pt.index.spacing == searched.spacing
    rows = np.arange(n)
    np.testing.assert_array_equal(pt.index.normals_at(rows), searched.normals_at(rows))
    X = P[::7] * 1.01
    np.testing.assert_array_equal(pt.index.tree.query(X)[1], searched.tree.query(X)[1])
