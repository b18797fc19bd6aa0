"""The second pass on clouds of uneven spacing (``static.RESCORE_LOCAL``,
docs/decisions.md#outliers-lidar-local-rescore): only locally sparse points of the second pass
are removed, so a sparse region of the surface keeps its points."""

from __future__ import annotations

import numpy as np

from spectrageo.outliers import RPCAOptions, detect_outliers
from spectrageo.outliers.static import RESCORE_SPREAD
from test_outliers_rescore import _contaminate  # noqa: E402


def _two_densities(seed: int = 3) -> np.ndarray:
    """A ground plane sampled at spacing 1 next to one at spacing 3 (an aerial tile where flight
    strips overlap), jittered."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(70.0), np.arange(70.0))
    dense = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    u, v = np.meshgrid(np.arange(0.0, 150.0, 3.0), np.arange(0.0, 90.0, 3.0))
    sparse = np.stack([u.ravel() + 72.0, v.ravel(), np.full(u.size, 0.5)], axis=1)
    P = np.concatenate([dense, sparse])
    return P + rng.uniform(-0.1, 0.1, P.shape)


def test_local_second_pass_on_uneven_spacing():
    P = _two_densities()
    Q, lab = _contaminate(P, np.tile([0.0, 0.0, 1.0], (P.shape[0], 1)), 0.3)
    r = detect_outliers(Q)
    off = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
    assert r.info["rescore_spread"] > RESCORE_SPREAD and r.info["rescore"]["local"]
    # more outliers found, no surface point lost, scores and threshold the first pass's
    assert not (r.keep & ~off.keep).any()
    np.testing.assert_array_equal(r.keep[~lab], off.keep[~lab])
    assert np.count_nonzero(~r.keep & lab) > np.count_nonzero(~off.keep & lab)
    np.testing.assert_array_equal(r.scores, off.scores)
    assert r.threshold == off.threshold


def test_locally_sparse_points():
    """A point whose k-th neighbour is 3x farther than its neighbours' is locally sparse; the
    points of an evenly sampled plane are not."""
    from spectrageo.outliers import rpca_scores
    from spectrageo.outliers.static import _locally_sparse

    u, v = np.meshgrid(np.arange(30.0), np.arange(30.0))
    P = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    P = np.concatenate([P, [[15.2, 15.3, 6.0]]])
    r = rpca_scores(P, 10)
    sparse = _locally_sparse(r)
    assert sparse[-1] and not sparse[:-1].any()
