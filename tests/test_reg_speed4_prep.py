"""Broad-phase preparation of registration: voxel down-sampling, shape properties, density.

The fast paths (occupancy table or one sort of an int64 code, count-only intermediate voxels,
one neighbour query for every scale, a sliding-midpoint tree for the density) must give what
their definitions give, exactly where the code promises it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spectrageo.register import _broad, _common


def _ref_voxel(P: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Definition: voxels by unique integer rows (lexicographic), centroids by bincount."""
    key = np.floor((P - P.min(axis=0)) / voxel).astype(np.int64)
    _, label = np.unique(key, axis=0, return_inverse=True)
    label = label.ravel()
    m = int(label.max()) + 1
    cnt = np.bincount(label, minlength=m).astype(np.float64)
    Q = np.stack([np.bincount(label, weights=P[:, j], minlength=m) / cnt for j in range(3)], 1)
    return Q, label


def _ref_downsample_to(P: np.ndarray, max_points: int) -> np.ndarray:
    if P.shape[0] <= max_points:
        return P
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    voxel = diag / np.sqrt(max_points) * 0.35
    Q, _ = _ref_voxel(P, voxel)
    while Q.shape[0] > max_points:
        voxel *= 1.15 * np.sqrt(Q.shape[0] / max_points)
        Q, _ = _ref_voxel(P, voxel)
    return Q


def _clouds(rng: np.random.Generator) -> list[np.ndarray]:
    grid = np.stack(np.meshgrid(*[np.arange(12.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    sphere = rng.normal(size=(6000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    return [
        rng.normal(size=(4000, 3)),
        sphere * 3.0 + 10.0,
        grid * 0.5,  # points exactly on voxel boundaries
        np.r_[grid[:40], grid[:40]],  # duplicates
        rng.uniform(-1.0, 1.0, size=(2, 3)),
    ]


@pytest.mark.parametrize("seed", [0, 1])
def test_voxel_downsample_matches_definition(seed):
    rng = np.random.default_rng(seed)
    for P in _clouds(rng):
        diag = np.linalg.norm(np.ptp(P, axis=0))
        # coarse (occupancy table), fine (sort of the code), finer than the spacing
        for voxel in (diag / 10, diag / 45, diag / 400, diag / 1e6, 0.5):
            Q, label = _common.voxel_downsample(P, voxel)
            Qr, lr = _ref_voxel(P, voxel)
            np.testing.assert_array_equal(label, lr)
            np.testing.assert_array_equal(Q, Qr)
            assert Q.shape[0] == label.max() + 1


def test_voxel_downsample_wide_span_uses_rows():
    # integer span beyond 2**62: the code falls back to unique rows, same answer
    P = np.array([[0.0, 0.0, 0.0], [1e7, 1e7, 1e7], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]])
    Q, label = _common.voxel_downsample(P, 1e-6)
    Qr, lr = _ref_voxel(P, 1e-6)
    np.testing.assert_array_equal(label, lr)
    np.testing.assert_array_equal(Q, Qr)
    assert Q.shape == (3, 3)


def test_voxel_downsample_degenerate_voxel_and_empty():
    P = np.random.default_rng(0).normal(size=(10, 3))
    Q, label = _common.voxel_downsample(P, 0.0)
    np.testing.assert_array_equal(Q, P)
    np.testing.assert_array_equal(label, np.arange(10))
    assert Q is not P
    Q, label = _common.voxel_downsample(np.empty((0, 3)), 1.0)
    assert Q.shape == (0, 3) and label.shape == (0,)


@pytest.mark.parametrize("max_points", [50, 400, 3000])
def test_downsample_to_matches_definition(max_points):
    for P in _clouds(np.random.default_rng(2)):
        Q = _common.downsample_to(P, max_points)
        np.testing.assert_array_equal(Q, _ref_downsample_to(P, max_points))
        assert Q.shape[0] <= max_points or Q is P


def test_downsample_to_small_and_single_point_clouds():
    P = np.random.default_rng(3).normal(size=(30, 3))
    assert _common.downsample_to(P, 30) is P
    # every point equal: no grid merges them; a copy comes back instead of an endless search
    Z = np.ones((50, 3))
    out = _common.downsample_to(Z, 10)
    np.testing.assert_array_equal(out, Z)
    assert out is not Z


def test_bounds_and_diagonal_exact():
    rng = np.random.default_rng(4)
    P = rng.normal(size=(5000, 3))
    P[7] = [-0.0, 0.0, np.inf]
    lo, hi = _common.column_bounds(P)
    np.testing.assert_array_equal(lo, P.min(axis=0))
    np.testing.assert_array_equal(hi, P.max(axis=0))
    Q = P[:-1][np.isfinite(P[:-1]).all(1)]
    assert _common.bbox_diagonal(Q) == float(np.linalg.norm(Q.max(axis=0) - Q.min(axis=0)))
    with pytest.raises(ValueError):
        _common.column_bounds(np.empty((0, 3)))


def _sphere(n: int, radius: float, seed: int) -> np.ndarray:
    X = np.random.default_rng(seed).normal(size=(n, 3))
    return radius * X / np.linalg.norm(X, axis=1, keepdims=True)


def test_shape_properties_one_query_serves_every_scale():
    rng = np.random.default_rng(5)
    P = rng.normal(size=(1500, 3)) * [1.0, 2.0, 0.3]
    tree = cKDTree(P)
    both, F = _broad.shape_properties(P, tree, ks=(16, 40))
    small, _ = _broad.shape_properties(P, tree, ks=(16,))
    large, F40 = _broad.shape_properties(P, tree, ks=(40,))
    # the k nearest are the first k of the larger query: the same numbers bit for bit
    np.testing.assert_array_equal(both[:, :2], small)
    np.testing.assert_array_equal(both[:, 2:], large)
    np.testing.assert_array_equal(F, F40)
    # chunks give the same rows
    chunked = _broad.shape_properties(P, tree, chunk=400)
    np.testing.assert_array_equal(chunked[0], both)
    np.testing.assert_array_equal(chunked[1], F)


def test_shape_properties_sphere_curvature_and_frames():
    R = 2.0
    P = _sphere(20000, R, 6)
    desc, F = _broad.shape_properties(P, cKDTree(P))
    # both principal curvatures of a sphere are 1/R at both scales (k nearest span ~0.05 R)
    np.testing.assert_allclose(np.median(desc, axis=0), 1.0 / R, rtol=0.03)
    # frames: orthonormal, third column the (inward, positive mean curvature) normal
    np.testing.assert_allclose(np.einsum("nij,nik->njk", F, F), np.broadcast_to(np.eye(3), F.shape),
                               atol=1e-9)  # fmt: skip
    inward = -P / R
    assert np.median(np.einsum("ni,ni->n", F[:, :, 2], inward)) > 0.99


@pytest.mark.parametrize("k", [None, 5])
def test_density_matches_brute_force(k):
    rng = np.random.default_rng(7)
    centres = rng.normal(size=(20, 12)) * 3.0
    Phi = centres[rng.integers(0, 20, 1500)] + 0.3 * rng.normal(size=(1500, 12))
    radius = 0.8
    rho = _broad.density(Phi, radius, k)
    kk = _broad.DENSITY_NEIGHBORS if k is None else k
    b = np.sqrt(-np.log(_broad.PHI)) / radius
    d = np.sqrt(((Phi[:, None, :] - Phi[None, :, :]) ** 2).sum(-1))
    d = np.sort(np.where(d < radius, d, np.inf), axis=1)[:, :kk]
    ref = np.where(np.isfinite(d), np.exp(-((b * d) ** 2)), 0.0).sum(1)
    # same neighbours, distances summed in another order: equal to rounding
    np.testing.assert_allclose(rho, ref, rtol=1e-12, atol=0)
    assert np.all(rho >= 1.0)  # every candidate counts itself
