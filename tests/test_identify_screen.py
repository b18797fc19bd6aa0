"""Grid screening of identification pose hypotheses (docs/decisions.md#identify-screening)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from spectrageo.register._common import knn_normals, make_transform
from spectrageo.register._identify_cover import MAX_CELLS_AXIS, ModelGrid
from spectrageo.register.scenes import random_rotation


def _sphere(n=3000, seed=0):
    X = np.random.default_rng(seed).normal(size=(n, 3))
    return X / np.linalg.norm(X, axis=1, keepdims=True)


def _exact(P, N, T, Q, NQ, radius, cos_min):
    R, t = T[:3, :3], T[:3, 3]
    Pm = (Q - t) @ R
    d, j = cKDTree(P).query(Pm, k=1, distance_upper_bound=radius)
    ok = np.isfinite(d)
    agree = np.abs(np.einsum("ij,ij->i", NQ[ok] @ R, N[j[ok]])) >= cos_min
    return agree.sum() / Q.shape[0]


def test_grid_coverage_scores_right_and_wrong_poses():
    P = _sphere() * [1.0, 0.6, 0.3]  # an ellipsoid: no rotational symmetry
    tree = cKDTree(P)
    N, _ = knn_normals(P, 10, tree)
    grid = ModelGrid(P, tree, 0.05, 0.033)
    T = make_transform(random_rotation(np.random.default_rng(1)), np.array([2.0, -1.0, 0.5]))
    part = P[:, 0] > 0.2  # the visible part, moved into the scene
    Q, NQ = P[part] @ T[:3, :3].T + T[:3, 3], N[part] @ T[:3, :3].T
    far = T.copy()
    far[:3, 3] += 5.0
    turned = T @ make_transform(random_rotation(np.random.default_rng(2)), np.zeros(3))
    Rs = np.stack([T[:3, :3], far[:3, :3], turned[:3, :3]])
    ts = np.stack([T[:3, 3], far[:3, 3], turned[:3, 3]])
    cov = grid.coverage(Rs, ts, Q, NQ, N, 0.8)
    assert cov[0] == 1.0
    assert cov[1] == 0.0
    assert cov[2] < 0.5
    # a screen, not the exact measure: within a cell's reach of the exact share
    for k, U in enumerate((T, turned)):
        assert abs(cov[2 * k] - _exact(P, N, U, Q, NQ, 0.05, 0.8)) < 0.25


def test_grid_size_is_bounded():
    P = _sphere(500)
    grid = ModelGrid(P, cKDTree(P), 0.01, 1e-6)  # a tiny requested cell
    assert (grid.dims <= MAX_CELLS_AXIS + 1).all()
    assert grid.index.size == int(np.prod(grid.dims))


def test_screened_hypotheses_explain_at_least_as_much(shared_data, monkeypatch):
    """The screen adds candidates to the re-ranking: the best explained share cannot drop."""
    from spectrageo.metrics.registration import rotation_error_deg
    from spectrageo.register import _identify
    from spectrageo.register.scenes import _sample_surface
    from test_identify import _library

    lib = _library(shared_data)
    o, voxel = dict(_identify.DEFAULTS), 0.025
    for name, k in (("cow", 2), ("bunny", 2)):
        P = _sample_surface(*lib[name], 60000, np.random.default_rng(0))
        model = _identify._prepare(P, voxel, o)
        g = np.random.default_rng(k)
        T = make_transform(random_rotation(g), g.normal(size=3))
        d = g.normal(size=3)
        part = P[P @ d > np.quantile(P @ d, 0.8)]  # one side, 20 % of the surface
        seg = _identify._prepare(part @ T[:3, :3].T + T[:3, 3], voxel, o)
        best = []
        for n in (0, _identify.N_SCREEN):
            monkeypatch.setattr(_identify, "N_SCREEN", n)
            out = _identify._ransac_poses(model, seg, voxel, o, np.random.default_rng(5))
            best.append(out[0])
        assert best[1][0] >= best[0][0]
        assert rotation_error_deg(best[1][1][:3, :3], T[:3, :3]) < 10.0
