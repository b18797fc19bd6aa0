"""Registration speed-ups: scores from the last ICP query, shorter verification, capped rivals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spectrageo.metrics import registration as rm
from spectrageo.register import _api, _broad, register
from spectrageo.register._common import apply_transform, make_transform, rotvec_to_matrix
from spectrageo.register._narrow import (
    TargetIndex,
    _score,
    _within,
    constraint,
    icp,
    run_narrow,
)

from conftest import shared_file

#: the keys of ``register(...).info`` after a broad phase (a contract of the public API)
INFO_KEYS = {
    "n_candidates", "voxel_size", "n_peaks", "peak_rank", "broad_fitness", "broad_time_s",
    "n_kept_source", "n_kept_target", "n_rivals", "gamma", "time_s", "n_source", "icp_converged",
    "constraint", "tight_share", "reliable",
}  # fmt: skip


def _surface(n: int, rng: np.random.Generator) -> np.ndarray:
    u, v = rng.uniform(0, 2 * np.pi, size=(2, n))
    r = 1.0 + 0.3 * np.cos(3 * u) * np.sin(2 * v)
    return np.c_[
        r * np.cos(u) * (2 + np.cos(v)), r * np.sin(u) * (2 + np.cos(v)), 0.8 * r * np.sin(v)
    ]


def _pair(seed: int = 3, n: int = 6000):
    rng = np.random.default_rng(seed)
    P = _surface(n, rng)
    M = make_transform(
        rotvec_to_matrix(np.array([0.05, -0.04, 0.03])), np.array([0.05, 0.0, -0.03])
    )
    return apply_transform(M, P[: 2 * n // 3]), P[n // 3 :]


def test_within_agrees_with_the_bounded_query():
    """A query bounded by ``dist`` finds exactly the rows that ``_within`` keeps from a query
    with a larger bound (the KD-tree keeps ``d < bound``)."""
    rng = np.random.default_rng(0)
    T = rng.normal(size=(3000, 3))
    X = rng.normal(size=(5000, 3))
    idx = TargetIndex(T, need_normals=False)
    for dist in (0.05, 0.1, 0.2):
        d_small, _ = idx.tree.query(X, k=1, distance_upper_bound=dist)
        d_big, _ = idx.tree.query(X, k=1, distance_upper_bound=3 * dist)
        np.testing.assert_array_equal(_within(d_big, dist), np.isfinite(d_small))
        np.testing.assert_array_equal(d_big[_within(d_big, dist)], d_small[np.isfinite(d_small)])


@pytest.mark.parametrize("max_iter", [2, 3, 60])
def test_icp_fitness_equals_a_fresh_score_of_its_pose(max_iter):
    """Whether the run stops at ``max_iter`` (scored from its last query) or converges earlier,
    fitness and rmse are those of a separate query at the final pose, bit for bit."""
    S, T = _pair()
    idx = TargetIndex(T)
    res = icp(S, idx, np.eye(4), max_iter=max_iter, tol=1e-5, method="point_to_plane",
              gamma0=None, gamma_min=0.02, inlier_distance=0.03, keep_query=True)  # fmt: skip
    assert (res.fitness, res.inlier_rmse) == _score(S, idx, res.transformation, 0.03)
    X, d, j = res.info["final_query"]
    np.testing.assert_array_equal(X, apply_transform(res.transformation, S))
    d2, j2 = idx.tree.query(X, k=1, distance_upper_bound=0.03)
    np.testing.assert_array_equal(d, d2)
    np.testing.assert_array_equal(j, np.where(np.isfinite(d2), j2, 0))
    assert constraint(S, idx, res.transformation, 0.03, (X, d, j)) == constraint(
        S, idx, res.transformation, 0.03
    )


def test_run_narrow_returns_the_query_only_on_request():
    S, T = _pair()
    assert "final_query" not in run_narrow(S, T, np.eye(4), warn=False).info
    assert "final_query" in run_narrow(S, T, np.eye(4), warn=False, keep_query=True).info


def test_target_normals_computed_by_mask_match_the_whole_computation():
    rng = np.random.default_rng(1)
    T = _surface(2000, rng)
    lazy, whole = TargetIndex(T), TargetIndex(T)
    lazy.normals_at(np.array([5, 3, 3, 1999, 5]))
    got = lazy.normals_at(np.arange(0, 2000, 7)[::-1])
    all_n = whole.normals_at(np.arange(2000))
    np.testing.assert_array_equal(got, all_n[np.arange(0, 2000, 7)[::-1]])


def test_apart_tells_the_same_pose_from_another():
    s = 0.01
    A = make_transform(rotvec_to_matrix(np.radians([0.0, 0.0, 30.0])), [0.2, 0.0, 0.0])
    near = make_transform(rotvec_to_matrix(np.radians([0.0, 0.0, 2.0])), [0.01, 0.0, 0.0]) @ A
    turned = make_transform(rotvec_to_matrix(np.radians([0.0, 180.0, 0.0])), [0.0, 0.0, 0.0]) @ A
    shifted = make_transform(np.eye(3), [0.05, 0.0, 0.0]) @ A
    assert not _broad._apart(near, A, s)
    assert _broad._apart(turned, A, s) and _broad._apart(shifted, A, s)


def test_verification_continues_one_run_per_pose(monkeypatch):
    """Peaks whose short runs end at the same pose are continued once; the chosen pose is the
    one found when every kept run is continued (to 0.01 degree)."""
    S, T = _pair(n=3000)
    real = _broad.icp

    def runs(same_pose_test: bool):
        calls = []

        def counting(*a, **k):
            calls.append(k["max_iter"])
            return real(*a, **k)

        monkeypatch.setattr(_broad, "icp", counting)
        if not same_pose_test:
            monkeypatch.setattr(_broad, "_apart", lambda A, B, s: True)
        T0, info = _broad.broad_phase_points(S, T, rng=np.random.default_rng(0))
        monkeypatch.undo()
        assert calls[: info["n_peaks"]] == [_broad.VERIFY_SHORT] * info["n_peaks"]
        return T0, len(calls) - info["n_peaks"]

    T_all, n_all = runs(False)
    T_one, n_one = runs(True)
    assert n_all == _broad.VERIFY_KEEP
    assert 1 <= n_one < n_all  # this pair's best peaks reach one pose
    assert rm.rotation_error_deg(T_one, T_all) < 0.01
    assert np.abs(T_one[:3, 3] - T_all[:3, 3]).max() < 1e-3


def test_register_info_keys_are_unchanged():
    S, T = _pair(n=3000)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = register(S, T, rng=0)
    assert set(res.info) == INFO_KEYS


def test_rivals_capped_at_rival_iter_choose_the_full_runs_pose(shared_data, monkeypatch):
    """On the tuning crop pair whose best voxel-scale pose is the room turned by 180 degrees,
    refining every start for RIVAL_ITER iterations gives the pose of full-length runs."""
    from spectrageo.evaluate.register import crop_pairs

    shared_file(shared_data, "scans", "registration", "open3d", "fragment.pcd")
    p = crop_pairs(shared_data, 1, 2)[1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        capped = register(p["source"], p["target"], rng=1)
        monkeypatch.setattr(_api, "RIVAL_ITER", 10**6)
        full = register(p["source"], p["target"], rng=1)
    assert capped.info["n_rivals"] >= 1
    np.testing.assert_array_equal(capped.transformation, full.transformation)
    assert capped.converged and full.converged
    assert rm.rotation_error_deg(capped.transformation, p["T_gt"]) < 2.0
