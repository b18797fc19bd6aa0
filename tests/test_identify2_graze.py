"""Free-space violations leave out model points seen nearly edge-on
(docs/decisions.md#identify2-grazing)."""

from __future__ import annotations

import numpy as np

from spectrageo.register._visibility import GRAZE_COS, SceneRays


def _grid(a, b):
    A, B = np.meshgrid(a, b)
    return A.ravel(), B.ravel()


def _wall(z=10.0):
    x, y = _grid(np.arange(-2, 2.001, 0.02), np.arange(-2, 2.001, 0.02))
    return np.c_[x, y, np.full(x.size, z)]


def test_edge_on_surface_is_not_counted_a_facing_one_is():
    rays = SceneRays(_wall(), np.zeros(3), 0.02)
    # a strip in the plane x = 0.1 (containing rays from the origin nearly): seen edge-on
    y, z = _grid(np.arange(-0.3, 0.301, 0.02), np.arange(5.0, 6.001, 0.02))
    strip = np.c_[np.full(y.size, 0.1), y, z]
    n_strip = np.tile([1.0, 0.0, 0.0], (strip.shape[0], 1))
    D = strip / np.linalg.norm(strip, axis=1)[:, None]
    assert np.abs(D @ [1.0, 0.0, 0.0]).max() < GRAZE_COS
    T = np.eye(4)
    assert rays.violations(strip, T, 3.0) == 1.0  # without normals: every point violates
    assert rays.violations(strip, T, 3.0, n_strip) == 0.0
    # a patch facing the sensor in front of the wall still violates
    x, y = _grid(np.arange(-0.3, 0.301, 0.02), np.arange(-0.3, 0.301, 0.02))
    patch = np.c_[x, y, np.full(x.size, 5.0)]
    n_patch = np.tile([0.0, 0.0, -1.0], (patch.shape[0], 1))
    assert rays.violations(patch, T, 3.0, n_patch) == 1.0
    # normals are turned with the pose: the strip turned by 90 degrees about y faces the sensor
    R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    c = strip.mean(axis=0)
    Tr = np.eye(4)
    Tr[:3, :3], Tr[:3, 3] = R, c - R @ c
    assert rays.violations(strip, Tr, 3.0, n_strip) == 1.0
