"""``pca-pred`` coder version 4: the mean and basis trajectories range coded row by row with a
per-row prediction order (round trips, the orders chosen, damaged chunks)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError
from spectrageo.compress import _pca_pred


def _rows(T: int, k: int, seed: int = 0):
    """Integer trajectories (3T,) per row: smooth, linear, noisy and a wide one."""
    rng = np.random.default_rng(seed)
    t = np.arange(3 * T)
    rows = []
    for j in range(k + 1):
        kind = j % 3
        if kind == 0:
            r = np.rint(4000 * np.sin(t / (5 + j)))
        elif kind == 1:
            r = np.rint(37 * t - 900)
        else:
            r = rng.integers(-6, 7, 3 * T).astype(float)
        rows.append(r.astype(np.int64))
    rows[-1][::7] = -(2**30)  # a value near the coder's range
    qB = np.stack(rows[1:], axis=1) if k else np.zeros((3 * T, 0), np.int64)
    return rows[0], qB


@pytest.mark.parametrize(("T", "k"), [(1, 0), (1, 2), (2, 3), (40, 9)])
def test_round_trip(T, k):
    qm, qB = _rows(T, k)
    sm, sb = 2.0**-12, np.geomspace(1e-3, 1e-5, k)
    chunk = _pca_pred.basis_chunk(qm, sm, qB, sb, T)
    mean, B = _pca_pred.read_basis(chunk, T)
    assert np.array_equal(mean, qm * float(np.float32(sm)))
    assert np.array_equal(B, qB * sb.astype(np.float32).astype(np.float64)[None, :])


def test_orders_follow_the_rows():
    qm, qB = _rows(60, 6)
    Z = np.concatenate([qm[None], qB.T]).reshape(7, 3, 60)
    orders = _pca_pred._orders(Z)
    assert orders[2] == 0 and orders[5] == 0  # the noisy rows: no prediction
    assert orders[1] == 2 and orders[4] == 2  # the linear rows: second order
    assert orders[0] >= 1 and orders[3] >= 1  # the smooth ones


def test_damaged_chunks_are_refused_or_decode_finite():
    T, k = 30, 8
    qm, qB = _rows(T, k, seed=3)
    chunk = _pca_pred.basis_chunk(qm, 1e-4, qB, np.full(k, 1e-4), T)
    head = 1 + 4 + 4 * k
    with pytest.raises(InvalidInputError, match="malformed"):
        _pca_pred.read_basis(chunk[: head + 4], T)
    bad = bytearray(chunk)
    bad[head] = 0xFF  # prediction orders 3
    with pytest.raises(InvalidInputError, match="prediction order"):
        _pca_pred.read_basis(bytes(bad), T)
    rng = np.random.default_rng(1)
    for _ in range(40):
        bad = bytearray(chunk)
        i = int(rng.integers(head + 3, len(bad)))
        bad[i] ^= 1 << int(rng.integers(8))
        try:
            mean, B = _pca_pred.read_basis(bytes(bad), T)
        except InvalidInputError:
            continue
        assert np.isfinite(mean).all() and np.isfinite(B).all()
