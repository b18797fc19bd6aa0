"""``pca-pred`` coder speed-ups keep the bits: the regression of the later components side by
side equals the one-at-a-time regression exactly, and the coded bytes of fixed coefficients are
those of the coder before the change (hashes pinned then, re-pinned for coder version 3:
docs/decisions.md#anim-pred3-contexts; no BLAS on this path)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from spectrageo.compress import _pca_pred

from conftest import icosphere


def test_side_by_side_regression_equals_one_at_a_time():
    rng = np.random.default_rng(0)
    n, k, q = 60, 30, 12
    Rb = rng.standard_normal((n, k)) * 5
    Rg = np.full((n, _pca_pred.MAXR), -1, np.int64)
    Rg[n - 1, :20] = rng.permutation(n - 1)[:20]
    X = np.zeros((_pca_pred.MAXR, q))
    L = np.zeros((q, q))
    m = _pca_pred._local_factor(Rg, Rb, n - 1, q, X, L)
    xs = np.zeros(k)
    Y, W = np.zeros((_pca_pred.MAXR, k)), np.zeros((q, k))
    _pca_pred._local_predict_rest(Rg, Rb, n - 1, q, q, m, X, L, Y, W, xs)
    w, y = np.zeros(q), np.zeros(_pca_pred.MAXR)
    one = [_pca_pred._local_predict(Rg, Rb, n - 1, j, q, m, X, L, w, y) for j in range(q, k)]
    assert m == 20
    assert np.array_equal(xs[: k - q], np.array(one))


@pytest.mark.parametrize(
    ("k", "size", "digest"),
    [
        # sizes with the flush that leaves out trailing zero bytes (docs/decisions.md#codec-rc-flush)
        (7, 2318, "fe2ba7eb7183041709053a40f12918dae694b93258b4e187253f2b559c5415a8"),
        (40, 13347, "582d4bb6bf77d58f947a980ce56e1040629c9e0a40a01f8a72aea11a64caac31"),
    ],
)
def test_coded_bytes_are_pinned(k, size, digest):
    V, F = icosphere(3)
    n = V.shape[0]
    pl = _pca_pred.make_plan(F, n)
    rng = np.random.default_rng(k)
    X = (V @ rng.standard_normal((3, k))) * np.linspace(40, 2, k)
    X += rng.standard_normal((n, k)) * 3
    chunk, Q = _pca_pred.encode_coefficients(X, pl, _pca_pred.RDO_LAMBDA)
    assert len(chunk) == size
    assert hashlib.sha256(chunk).hexdigest() == digest
    assert np.array_equal(_pca_pred.decode_coefficients(chunk, pl, n, k), Q)


def test_value_counts_match_unique():
    rng = np.random.default_rng(1)
    for q in (np.rint(rng.standard_normal(500) * 4), np.array([0.0, 1e9, -3.0, 1e9])):
        assert np.array_equal(_pca_pred._counts(q), np.unique(q, return_counts=True)[1])
