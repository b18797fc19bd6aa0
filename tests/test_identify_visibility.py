"""Free-space verification of identification poses (docs/decisions.md#identify-visibility)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.register import identify, make_scene
from spectrageo.register._visibility import SceneRays
from test_identify import _library


def _wall(step=0.02, z=10.0, half=2.0):
    u = np.arange(-half, half + 1e-9, step)
    X, Y = np.meshgrid(u, u)
    return np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]


def _patch(z, step=0.02, half=0.3):
    u = np.arange(-half, half + 1e-9, step)
    X, Y = np.meshgrid(u, u)
    return np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]


def test_free_space_violations_in_front_on_and_behind_a_wall():
    rays = SceneRays(_wall(), np.zeros(3), 0.02)
    T = np.eye(4)
    assert rays.violations(_patch(5.0), T, 3.0) == 1.0  # in front: the wall would be hidden
    assert rays.violations(_patch(10.0), T, 3.0) == 0.0  # on the observed surface
    assert rays.violations(_patch(12.0), T, 3.0) == 0.0  # behind it: hidden, not contradicted
    # moved by T: the patch at z = 12 brought to z = 6
    T[2, 3] = -6.0
    assert rays.violations(_patch(12.0), T, 3.0) == 1.0
    # rays the sensor did not observe carry no evidence
    off = _patch(5.0) + [10.0, 0.0, 0.0]
    assert rays.violations(off, np.eye(4), 3.0) == 0.0


def test_free_space_violations_count_the_protruding_share():
    rays = SceneRays(_wall(), np.zeros(3), 0.02)
    P = np.r_[_patch(10.0), _patch(4.0)[:100]]
    v = rays.violations(P, np.eye(4), 3.0)
    assert v == pytest.approx(100 / P.shape[0])


@pytest.fixture(scope="module")
def vis_case(shared_data):
    lib = _library(shared_data)
    scene_lib = {k: lib[k] for k in ("bunny", "cow")}
    sc = make_scene(scene_lib, n_objects=2, clutter=1, image_size=(480, 360), rng=3)
    return lib, sc


def test_identify_with_viewpoint_keeps_the_right_answers(vis_case):
    from spectrageo.metrics.registration import rotation_error_deg

    lib, sc = vis_case
    res = identify(sc.points, lib, rng=0, viewpoint=sc.viewpoint)
    for m in res:
        present = m.model in sc.names
        assert m.found == present, (m.model, m.dissimilarity)
        if present:
            j = sc.names.index(m.model)
            assert rotation_error_deg(m.transformation[:3, :3], sc.poses[j][:3, :3]) < 5.0


def test_visibility_rejects_a_pose_that_h_accepts(vis_case):
    """Seen from the opposite side, the right poses put the objects in front of what was observed:
    ``h`` accepts them, the free-space check does not."""
    lib, sc = vis_case
    present = {k: lib[k] for k in sc.names}
    plain = identify(sc.points, present, rng=0)
    assert all(m.found and m.dissimilarity < 0.4 for m in plain)
    centre = sc.points.mean(axis=0)
    mirrored = 2.0 * centre - sc.viewpoint
    seen = identify(sc.points, present, rng=0, viewpoint=mirrored)
    assert not any(m.found for m in seen)


@pytest.mark.parametrize("vp", [(0.0, 1.0), (0.0, np.nan, 1.0), "abc"])
def test_identify_viewpoint_validation(vp):
    P = np.random.default_rng(0).normal(size=(200, 3))
    with pytest.raises(InvalidInputError, match="`viewpoint` must be 3 finite numbers"):
        identify(P, [P], viewpoint=vp)


def test_flips_are_half_turns_about_the_principal_axes():
    from types import SimpleNamespace

    from spectrageo.register._identify import _flips

    g = np.random.default_rng(0)
    P = g.normal(size=(500, 3)) * [3.0, 2.0, 1.0] + [1.0, -2.0, 0.5]
    T = np.eye(4)
    T[:3, 3] = [0.3, 0.1, -0.2]
    flips = _flips(SimpleNamespace(P=P), T)
    assert len(flips) == 3
    c = P.mean(axis=0)
    for F in flips:
        R = F[:3, :3]
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
        assert np.isclose(np.trace(R), -1.0)  # a rotation by pi
        assert np.allclose(F[:3, :3] @ c + F[:3, 3], c + T[:3, 3])  # the centroid stays put
    # the three axes are those of the cloud: each half turn keeps one axis, reverses two
    axes = np.linalg.svd(P - c, full_matrices=False)[2]
    for F, a in zip(flips, axes):
        assert np.allclose(F[:3, :3] @ a, a)
