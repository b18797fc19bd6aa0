"""A pose must not enter a plane of the scene where it was observed, and a rejected segment
refines the best hypothesis of more rotation clusters (docs/decisions.md#identify3-planes,
docs/decisions.md#identify3-clusters)."""

from __future__ import annotations

import numpy as np

from spectrageo.register import _identify
from spectrageo.register._common import make_transform
from spectrageo.register._visibility import SceneRays


def _grid(a, b):
    A, B = np.meshgrid(a, b)
    return A.ravel(), B.ravel()


def _table():
    """The plane z = 0 observed over |x|, |y| <= 1 from a sensor above it."""
    x, y = _grid(np.arange(-1, 1.001, 0.02), np.arange(-1, 1.001, 0.02))
    return np.c_[x, y, np.zeros(x.size)]


def _cube(c, half=0.1):
    """Points of a cube's faces centred at ``c``, with their normals."""
    u, v = _grid(np.arange(-half, half + 1e-9, 0.02), np.arange(-half, half + 1e-9, 0.02))
    P, N = [], []
    for ax in range(3):
        for s in (-half, half):
            Q = np.zeros((u.size, 3))
            Q[:, ax] = s
            Q[:, (ax + 1) % 3], Q[:, (ax + 2) % 3] = u, v
            n = np.zeros((u.size, 3))
            n[:, ax] = 1.0
            P.append(Q)
            N.append(n)
    return np.vstack(P) + np.asarray(c), np.vstack(N)


def _views(T, P):
    """Rays of the table with the cube placed by ``T`` in the scan, without and with the plane."""
    table = _table()
    scan = np.vstack([table, P @ T[:3, :3].T + T[:3, 3]])
    e = np.array([0.3, 0.2, 3.0])
    plane = np.array([0.0, 0.0, 1.0, 0.0])
    return (SceneRays(scan, e, 0.02), SceneRays(scan, e, 0.02, [(plane, table)]),
            SceneRays(scan, e, 0.02, [(-plane, table)]))  # fmt: skip


def test_a_pose_inside_an_observed_plane_violates_one_on_it_does_not():
    P, N = _cube([0.0, 0.0, 0.0])
    # half of the cube inside the table: hidden by it, so the rays alone do not object
    T = np.eye(4)
    without, rays, flipped = _views(T, P)
    v0, v = without.violations(P, T, 3.0, N), rays.violations(P, T, 3.0, N)
    assert v0 < 0.05 and v > v0 + 0.1
    # the sensor's side is the front whatever the sign of the plane's equation
    assert flipped.violations(P, T, 3.0, N) == v
    # resting on the table: nothing enters it
    T = make_transform(np.eye(3), [0.0, 0.0, 0.1])
    without, rays, _ = _views(T, P)
    assert rays.violations(P, T, 3.0, N) == without.violations(P, T, 3.0, N) < 0.05
    # below the plane beyond its observed part (the plane's extension is no evidence)
    T = make_transform(np.eye(3), [3.0, 0.0, -0.05])
    without, rays, _ = _views(T, P)
    assert rays.violations(P, T, 3.0, N) == without.violations(P, T, 3.0, N)


def _rot_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


def test_cluster_heads_group_rotations_and_skip_the_refined_ones():
    angles = [0, 10, 60, 70, 130, 200, 250, 300]
    R = np.stack([_rot_z(a) for a in angles])
    t = np.zeros((len(angles), 3))
    order = np.arange(len(angles))
    out = _identify._cluster_heads(order, R, t, np.ones(len(angles)), [_rot_z(5)])
    assert len(out) == _identify.CLUSTER_EXTRA == 3
    # 0 and 10 join the refined pose; 60 heads a cluster that 70 joins; then 130 and 200
    heads = [np.degrees(np.arctan2(m[0][1, 0], m[0][0, 0])) % 360 for m in out]
    np.testing.assert_allclose(heads, [60, 130, 200], atol=1e-9)
    assert [len(m) for m in out] == [2, 1, 1]


def test_the_acceptance_band_applies_with_a_viewpoint_only():
    o = _identify._check_options({})
    assert _identify._accept_below(o) == 0.4
    o = _identify._check_options({"viewpoint": [0.0, 0.0, 3.0], "zeta": 0.5})
    assert _identify._accept_below(o) == 0.5 + _identify.ZETA_BAND
    assert 0.0 < _identify.ZETA_BAND < 0.1
