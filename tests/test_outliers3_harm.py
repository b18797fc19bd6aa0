"""The do-no-harm rule of ``remove_outliers(method="rpca")`` on nearly clean clouds
(``static.HARM_*``, docs/decisions.md#outliers3-harm)."""

from __future__ import annotations

import numpy as np
import pytest

import spectrageo.outliers.static as st
from spectrageo import io
from spectrageo.outliers import detect_outliers
from spectrageo.outliers._support import within_spread


def _plane(n_side: int = 40, seed: int = 0) -> np.ndarray:
    g = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side)), -1).reshape(-1, 2)
    rng = np.random.default_rng(seed)
    return np.column_stack([g + rng.uniform(-0.1, 0.1, g.shape), np.zeros(g.shape[0])])


def test_within_spread_on_and_off_a_plane():
    from scipy.spatial import cKDTree

    P = _plane()
    P[:, 2] = np.random.default_rng(1).normal(0.0, 0.05, P.shape[0])
    i = 820  # an interior point
    Q = np.vstack([P, P[i] + [0.3, 0.3, 3.0]])
    _, nb = cKDTree(Q).query(Q, 11)
    knn = (np.arange(Q.shape[0]), nb[:, 1:])
    got = within_spread(Q, np.array([i, Q.shape[0] - 1]), knn, 3.0)
    assert got.tolist() == [True, False]
    assert within_spread(Q, np.array([], dtype=np.int64), knn, 3.0).shape == (0,)


@pytest.fixture
def rule_off(monkeypatch):
    def off():
        monkeypatch.setattr(st, "HARM_SCORE", 1.0)

    return off


def test_clean_lidar_tile_loses_under_one_percent(rule_off):
    from spectrageo.evaluate._outliers_scans import REPO_DATA

    path = REPO_DATA / "lidar" / "pdal_4_6_crop.las"
    if not path.is_file():
        pytest.skip("the repository's LiDAR tuning tiles are absent")
    P = io.read(path, kind="points").points
    r = detect_outliers(P)
    assert r.info["n_harmless_kept"] > 0
    assert np.mean(~r.keep) < 0.01
    rule_off()
    r0 = detect_outliers(P)
    assert r0.info["n_harmless_kept"] == 0
    assert np.mean(~r0.keep) > 0.015
    assert np.all(r0.keep <= r.keep)  # the rule only keeps points


def test_rule_off_above_the_share(rule_off):
    rng = np.random.default_rng(2)
    P = _plane(50)
    far = rng.uniform([0, 0, -20], [50, 50, 20], (200, 3))
    Q = np.vstack([P, far])
    r = detect_outliers(Q)
    assert np.mean(r.scores >= r.threshold) >= st.HARM_SHARE
    assert r.info["n_harmless_kept"] == 0
    rule_off()
    assert np.array_equal(detect_outliers(Q).keep, r.keep)
