"""``pca-pred`` coder version 3: parallelogram corners found once per vertex, the local
regression through ring weights, residual bits under three mixed context models
(docs/decisions.md#anim-pred3-contexts)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo.compress import _pca_pred, _predictive_kernel

from conftest import icosphere


def test_parallelogram_corners_give_the_kernels_parallelograms():
    """The corners ``(a, b, c)`` reproduce ``_parallelograms_at``'s values and gate face at
    every vertex of a half-decoded sphere."""
    V, F = icosphere(2)
    n = V.shape[0]
    F = np.ascontiguousarray(F, dtype=np.int64)
    ptr, vf = _predictive_kernel._vertex_faces(F, n)
    order = _predictive_kernel.traversal_order(F, n)
    G = np.random.default_rng(0).integers(-1000, 1000, (n, 3)).astype(np.int64)
    vis = np.zeros(n, np.bool_)
    vis[order[: n // 2]] = True
    seen = 0
    for v in order[n // 2 :]:
        P = np.zeros((4, 3), np.int64)
        g1, g2 = np.full(1, -1, np.int64), np.full(1, -1, np.int64)
        k = _predictive_kernel._parallelograms_at(F, ptr, vf, G, vis, v, P, g1)
        abc = np.zeros((4, 3), np.int64)
        k2 = _predictive_kernel._parallelogram_corners(F, ptr, vf, vis, v, abc, g2)
        assert k == k2 and g1[0] == g2[0]
        assert np.array_equal(P[:k], G[abc[:k, 0]] + G[abc[:k, 1]] - G[abc[:k, 2]])
        seen += k
    assert seen > 0


def test_ring_weights_are_the_ridge_regression():
    """``u . y`` equals the ridge regression of ``y`` on the ring's first ``q`` base residuals
    applied to the vertex's own: ``r_v^T (X^T X + RIDGE I)^-1 X^T y``."""
    v, q, ring = 15, 9, np.arange(15)
    Rb = np.random.default_rng(2).standard_normal((v + 1, 20)) * 4
    Rg = np.full((v + 1, _pca_pred.MAXR), -1, np.int64)
    Rg[v, : ring.size] = ring[::-1]
    X, L = np.zeros((_pca_pred.MAXR, q)), np.zeros((q, q))
    m = _pca_pred._local_factor(Rg, Rb, v, q, X, L)
    Xm, Ym = Rb[ring[::-1], :q], Rb[ring[::-1]]
    want = Rb[v, :q] @ np.linalg.solve(Xm.T @ Xm + _pca_pred.RIDGE * np.eye(q), Xm.T @ Ym)
    scratch = (np.zeros(q), np.zeros(_pca_pred.MAXR))
    got = [_pca_pred._local_predict(Rg, Rb, v, j, q, m, X, L, *scratch) for j in range(20)]
    assert m == ring.size
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def test_noisy_coefficients_round_trip_with_mixed_contexts():
    """Many components (past the regression's ``PREG`` and the direct component contexts) of
    smooth fields plus noise and outliers decode to the encoder's integers."""
    V, F = icosphere(3)
    n = V.shape[0]
    plan = _pca_pred.make_plan(F, n)
    rng = np.random.default_rng(5)
    k = _pca_pred.PREG + 20
    X = (V @ rng.standard_normal((3, k))) * np.geomspace(400, 0.5, k)
    X += rng.laplace(0, 1.5, (n, k))
    X[rng.random(X.shape) < 0.005] *= 300
    chunk, Q = _pca_pred.encode_coefficients(X, plan, _pca_pred.RDO_LAMBDA)
    assert np.array_equal(_pca_pred.decode_coefficients(chunk, plan, n, k), Q)
    with pytest.raises(Exception, match="malformed"):
        _pca_pred.decode_coefficients(chunk[: len(chunk) // 3], plan, n, k)


def test_a_version_2_stream_is_refused(monkeypatch):
    from spectrageo import InvalidInputError, compress
    from spectrageo.compress._animation import frame_box

    V, F = icosphere(2)
    A = V[None] * (1 + 0.05 * np.arange(5)[:, None, None])
    origin, scale = frame_box(A)
    assert _pca_pred.CODER >= 3
    monkeypatch.setattr(_pca_pred, "CODER", 2)
    old = _pca_pred.PcaPredFileEncoder(A, F, 512, origin, scale).build(1e-3)
    monkeypatch.undo()
    with pytest.raises(InvalidInputError, match="coder version 2"):
        compress.decode_animation(old)
