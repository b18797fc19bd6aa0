"""Registration on degenerate and bad input, and the prepared-target API (Section 6.2)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spectrageo import InvalidInputError
from spectrageo.metrics import registration as rm
from spectrageo.register import PreparedTarget, prepare_target, register
from spectrageo.register._common import apply_transform, make_transform, rotvec_to_matrix


def _bumpy(n: int, rng, lo=0.0, hi=1.0) -> np.ndarray:
    """Points of a surface with irregular bumps over ``[lo, hi] x [0, 1]``."""
    xy = np.c_[rng.uniform(lo, hi, n), rng.random(n)]
    z = 0.08 * np.sin(7.0 * xy[:, 0] + 1.0) * np.cos(5.0 * xy[:, 1]) + 0.05 * np.exp(
        -((xy[:, 0] - 0.3) ** 2 + (xy[:, 1] - 0.6) ** 2) / 0.01
    )
    return np.c_[xy, z]


def _motion(deg: float, t) -> np.ndarray:
    return make_transform(rotvec_to_matrix(np.radians(deg) * np.array([0.3, -0.5, 0.8])), t)


def _register(S, T, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return register(S, T, **kw)


def test_bumpy_surface_is_registered_and_reported_converged():
    rng = np.random.default_rng(0)
    P = _bumpy(20000, rng)
    M = _motion(40.0, [0.2, -0.1, 0.05])
    res = _register(P, apply_transform(M, _bumpy(20000, rng)))
    assert rm.rotation_error_deg(res.transformation, M) < 2.0
    assert res.converged and res.info["reliable"]
    assert {"constraint", "tight_share", "icp_converged"} <= set(res.info)


@pytest.mark.parametrize(
    "source, match",
    [
        (np.zeros((1, 3)), "at least 3 points"),
        (np.ones((50, 3)), "all equal"),
        (np.r_[np.random.default_rng(0).random((100, 3)), [[np.nan, 0.0, 0.0]]], "NaN"),
    ],
)
def test_bad_clouds_raise_clear_errors(source, match):
    T = np.random.default_rng(1).random((500, 3))
    with pytest.raises(InvalidInputError, match=match):
        register(source, T)
    with pytest.raises(InvalidInputError, match=match):
        register(T, source)


def test_all_equal_target_raises():
    with pytest.raises(InvalidInputError, match="`target` .* all equal"):
        register(np.random.default_rng(0).random((100, 3)), np.ones((50, 3)))


def test_plane_is_not_reported_converged():
    """A plane fixes only 3 of the 6 degrees of freedom: whatever pose comes out is a guess."""
    rng = np.random.default_rng(2)
    S = np.c_[rng.random((3000, 2)), np.zeros(3000)]
    T = np.c_[rng.random((3000, 2)), np.zeros(3000)] + [0.1, 0.2, 0.0]
    res = _register(S, T)
    assert not res.converged
    assert res.info["constraint"] < 1e-3


def test_line_is_not_reported_converged():
    rng = np.random.default_rng(3)
    S = np.c_[rng.random(3000), np.zeros((3000, 2))]
    T = np.c_[rng.random(3000), np.zeros((3000, 2))] + [0.3, 0.0, 0.0]
    res = _register(S, T)
    assert not res.converged


def test_clouds_without_overlap_are_not_reported_converged():
    """Two disjoint strips of one bumpy surface: no pose is right, none may be claimed."""
    rng = np.random.default_rng(4)
    S = _bumpy(15000, rng, 0.0, 0.35)
    T = apply_transform(_motion(25.0, [0.1, 0.0, 0.0]), _bumpy(15000, rng, 0.65, 1.0))
    res = _register(S, T)
    assert not res.converged and not res.info["reliable"]


@pytest.mark.slow
def test_ten_million_points():
    rng = np.random.default_rng(5)
    P = _bumpy(10_000_000, rng)
    M = _motion(20.0, [0.05, 0.0, 0.02])
    res = _register(P, apply_transform(M, P[::997]))
    del P
    ok = rm.rotation_error_deg(res.transformation, M) < 2.0
    assert ok or not res.converged
    assert ok and res.converged


# --------------------------------------------------------------------------- prepared target
def test_prepared_target_gives_the_same_pose_as_a_plain_call():
    from spectrageo.register._broad import default_voxel

    rng = np.random.default_rng(6)
    T = _bumpy(20000, rng)
    sources = [apply_transform(_motion(a, [0.1, 0.0, 0.0]), _bumpy(20000, rng)) for a in (30, 70)]
    pt = prepare_target(T, voxel_size=default_voxel(sources[0], T))
    assert isinstance(pt, PreparedTarget)
    a = _register(sources[0], T, rng=0)
    b = _register(sources[0], pt, rng=0)
    np.testing.assert_array_equal(a.transformation, b.transformation)
    assert a.fitness == b.fitness
    # one prepared target serves many sources
    c = _register(sources[1], pt, rng=0)
    assert rm.rotation_error_deg(c.transformation, np.linalg.inv(_motion(70, [0.1, 0, 0]))) < 2.0


def test_prepared_target_refuses_other_options():
    pt = prepare_target(_bumpy(5000, np.random.default_rng(7)))
    S = _bumpy(5000, np.random.default_rng(8))
    with pytest.raises(InvalidInputError, match="prepared target was made for"):
        register(S, pt, robust=False)
    with pytest.raises(InvalidInputError, match="voxel_size"):
        register(S, pt, broad_options={"voxel_size": 0.5})
    with pytest.raises(InvalidInputError, match="`method` must be one of"):
        prepare_target(S, method="nope")
