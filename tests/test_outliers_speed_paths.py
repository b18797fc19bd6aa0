"""Compiled replacements of numpy steps in the RPCA outlier pipeline give the same bits
(docs/decisions.md#outliers-speed-exact-paths): Morton codes, row gathers, the span check and
the replay of step 5 with the first pass's normalised cloud."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.outliers import _rpca_solver as rp
from spectrageo.outliers._common import (
    SortedCloud,
    check_span,
    knn_grid,
    morton_codes,
    spacing_from,
    take_rows,
)
from spectrageo.outliers._grid import morton_encode


def _numpy_codes(P):
    """The former numpy path: quantise, clip, then interleave with ``morton_encode``."""
    lo = P.min(axis=0)
    ext = float(np.max(P.max(axis=0) - lo))
    scale = (2**21 - 1) / ext if ext > 0 else 0.0
    q = ((P - lo) * scale).astype(np.uint64)
    np.minimum(q, np.uint64(2**21 - 1), out=q)
    return morton_encode(q), lo, scale


@pytest.mark.parametrize("case", ["random", "offset", "flat", "single", "coincident", "f32"])
def test_morton_codes_equal_the_numpy_quantisation(case):
    rng = np.random.default_rng(1)
    P = rng.random((5000, 3))
    if case == "offset":
        P = P * [1e6, 3.0, 1e-3] - 1e5
    elif case == "flat":
        P[:, 2] = 0.25
    elif case == "single":
        P = P[:1]
    elif case == "coincident":
        P = np.tile(P[:1], (40, 1))
    elif case == "f32":
        P = P.astype(np.float32)
    codes, lo, scale = morton_codes(P)
    ref, lo_ref, scale_ref = _numpy_codes(P)
    np.testing.assert_array_equal(codes, ref)
    np.testing.assert_array_equal(lo, lo_ref)
    assert scale == scale_ref


def test_take_rows_equals_fancy_indexing():
    rng = np.random.default_rng(2)
    P = rng.random((1000, 3))
    rows = rng.integers(0, 1000, 2500)
    for A in (P, np.asfortranarray(P), P.astype(np.float32), rng.random((1000, 4))):
        out = take_rows(A, rows)
        np.testing.assert_array_equal(out, A[rows])
        assert out.flags.c_contiguous and out.dtype == A.dtype
    assert take_rows(P, rows[:0]).shape == (0, 3)
    sc = SortedCloud.of(P)
    np.testing.assert_array_equal(sc.points, P[sc.order])


def test_check_span_bounds_and_message():
    X = np.array([[0.0, -2.0, 5.0], [1e20, 3.0, -4.0]])
    check_span(X, 1e6, np.float32)  # spans 1e14 spacings: accepted
    with pytest.raises(InvalidInputError, match=r"spans 1e\+20 \(coordinates from -4 to 1e\+20\)"):
        check_span(X, 1.0, np.float32)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_replay_reuses_the_first_pass_cloud_bit_for_bit(dtype):
    """Step 5's replay with the normalised cloud kept by the one-block first pass equals the
    replay that normalises the cloud again."""
    rng = np.random.default_rng(4)
    xy = rng.random((4000, 2))
    P = np.column_stack([xy, 0.05 * np.sin(5 * xy[:, 0])])
    Q, _ = noise.corrupt_outliers(P, pattern="mixed", fraction=0.1, rng=4)
    sc = SortedCloud.of(Q)
    nb = knn_grid(sc, 10)
    h = spacing_from(nb.dmean)
    kw = dict(lam=None, rho=3.0, tol=1e-4, rank_tol=3e-3, max_iter=200, block_size=10**6)
    record: list = []
    scores, _, S, *_ = rp.solve_blocks(
        sc.points, h, nb.idx, smoothed=True, workers=1, dtype=np.dtype(dtype), vectors=True,
        record=record, **kw,
    )  # fmt: skip
    assert record[0].Pn is not None and record[0].Pn.dtype == np.dtype(dtype)
    rows = np.arange(5, Q.shape[0], 11)
    new_idx = nb.idx.copy()
    new_idx[rows] = np.roll(nb.idx[rows], 1, axis=0)  # other (valid) patches for the rows
    out = []
    for keep_cloud in (True, False):
        rec = [rp._BlockRecord(r) for r in record]
        if keep_cloud:
            rec[0].Pn, rec[0].centre = record[0].Pn, record[0].centre
        s2, S2, E2 = scores.copy(), S.copy(), np.zeros((Q.shape[0], 3))
        rp.replay_blocks(
            sc.points, h, new_idx, rows, nb.idx[rows].copy(), rec, dtype=np.dtype(dtype),
            scores_s=s2, E0_s=E2, S_s=S2,
        )  # fmt: skip
        out.append((s2, S2, E2))
    for a, b in zip(out[0], out[1], strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(out[0][0][rows], scores[rows])  # the rows were rescored
