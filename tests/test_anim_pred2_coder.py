"""``pca-pred``'s coefficient coder: rational base predictions, rounding-remainder sign contexts
(docs/decisions.md#anim-pred2-rational)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo.compress import _pca_pred

from conftest import icosphere


def test_base_prediction_is_the_exact_mean():
    """``out + fr`` is the exact mean of the parallelograms (flag 0) or of the decoded 1-ring
    (flag 1), ``fr`` in [0, 1)."""
    V, F = icosphere(2)
    n = V.shape[0]
    F, order, ptr, vf, Rg, n1 = _pca_pred.make_plan(F, n)
    rng = np.random.default_rng(3)
    Q = rng.integers(-50, 50, (n, 3)).astype(np.int64)
    vis = np.zeros(n, np.bool_)
    vis[order[: n // 2]] = True
    v = order[n // 2]
    nn = min(n1[v], _pca_pred.MAXN)
    abc = np.zeros((_pca_pred.MAXP, 3), np.int64)
    for flag in (0, 1):
        out = np.zeros(3, np.int64)
        fr = np.zeros(3)
        flags = np.full(3, flag, np.int64)
        cnt = _pca_pred._base(F, ptr, vf, vis, Rg, nn, v, Q, flags, abc, out, fr)
        P = Q[abc[:, 0]] + Q[abc[:, 1]] - Q[abc[:, 2]]
        assert cnt > 0 and nn > 0
        exact = P[:cnt].mean(axis=0) if flag == 0 else Q[Rg[v, :nn]].mean(axis=0)
        assert np.all((fr >= 0) & (fr < 1))
        np.testing.assert_allclose(out + fr, exact, rtol=0, atol=1e-12)


def test_heavy_tailed_coefficients_round_trip_exactly():
    """Integers of every size and sign (zeros, +-1, large outliers) decode to themselves."""
    V, F = icosphere(3)
    n = V.shape[0]
    plan = _pca_pred.make_plan(F, n)
    rng = np.random.default_rng(7)
    X = rng.laplace(0, 3, (n, 14)) * np.linspace(40, 0.3, 14)
    X[rng.random(X.shape) < 0.01] *= 1e4
    chunk, Q = _pca_pred.encode_coefficients(X, plan, 0.15)
    assert np.abs(Q - X).max() <= 1.0
    assert np.array_equal(_pca_pred.decode_coefficients(chunk, plan, n, 14), Q)
    chunk0, Q0 = _pca_pred.encode_coefficients(X, plan, 0.0)
    assert np.array_equal(Q0, np.rint(X))
    assert np.array_equal(_pca_pred.decode_coefficients(chunk0, plan, n, 14), Q0)


def test_a_stream_of_another_coder_version_is_refused(monkeypatch):
    """The coder version sits in the stream header; another version is a clear error, not
    frames decoded by the wrong coder."""
    from spectrageo import InvalidInputError, compress
    from spectrageo.compress._animation import frame_box

    V, F = icosphere(2)
    A = V[None] * (1 + 0.1 * np.arange(6)[:, None, None])
    origin, scale = frame_box(A)
    data = _pca_pred.PcaPredFileEncoder(A, F, 512, origin, scale).build(1e-3)
    R, _F = compress.decode_animation(data)
    assert np.abs(R - A).max() < 1e-2 * scale
    monkeypatch.setattr(_pca_pred, "CODER", 1)
    old = _pca_pred.PcaPredFileEncoder(A, F, 512, origin, scale).build(1e-3)
    monkeypatch.undo()
    with pytest.raises(InvalidInputError, match="coder version 1"):
        compress.decode_animation(old)
