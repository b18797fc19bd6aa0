"""Pinned output of :func:`register` on a small generated pair, and the point-to-plane step."""

from __future__ import annotations

import warnings

import numpy as np

from spectrageo.register import register
from spectrageo.register._common import apply_transform, make_transform, rotvec_to_matrix
from spectrageo.register._narrow import _plane_step

# the pose found on the pair below (agrees with the motion to 4e-4); speed-ups must keep it
PINNED = [
    [0.5184715951043111, 0.6694922331918591, 0.5319467593338346, -0.44639419112556356],
    [-0.8055250949396316, 0.5911318955898692, 0.041138831276854394, 0.41175387836521193],
    [-0.28690856817545324, -0.44982577928805423, 0.845777891526733, -0.5673069232811909],
    [0.0, 0.0, 0.0, 1.0],
]


def _pair():
    """Two overlapping halves of a bumpy torus sample, the source moved by a fixed motion."""
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0, 2 * np.pi, size=(2, 3000))
    r = 1.0 + 0.3 * np.cos(3 * u) * np.sin(2 * v)
    P = np.c_[r * np.cos(u) * (2 + np.cos(v)), r * np.sin(u) * (2 + np.cos(v)), 0.8 * r * np.sin(v)]
    M = make_transform(rotvec_to_matrix(np.array([0.3, -0.5, 0.9])), np.array([0.4, -0.2, 0.7]))
    return apply_transform(M, P[:2000]), P[1000:], np.linalg.inv(M)


def test_register_pose_is_pinned_on_a_generated_pair():
    S, T, T_gt = _pair()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = register(S, T, rng=0)
    np.testing.assert_allclose(res.transformation, PINNED, rtol=0, atol=1e-9)
    assert abs(res.fitness - 0.9813695871097684) < 1e-9
    assert res.converged and res.n_iter == 4
    assert np.abs(res.transformation - T_gt).max() < 1e-3


def test_plane_step_matches_the_textbook_formula():
    """Rows ``[(p - c) x n, n]`` (Eq. 6.39-6.40) written with np.cross give the same step bit for
    bit."""
    rng = np.random.default_rng(0)
    n = 700
    P = rng.normal(size=(n, 3))
    Q = P + 0.01 * rng.normal(size=(n, 3))
    N = rng.normal(size=(n, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    w = rng.random(n)
    scale = 3.0
    c = (w[:, None] * P).sum(0) / w.sum()
    J = np.c_[np.cross((P - c) / scale, N), N]
    r = np.einsum("ij,ij->i", (P - Q) / scale, N)
    A = (J * w[:, None]).T @ J
    b = -(J * w[:, None]).T @ r
    x = np.linalg.solve(A, b)
    R = rotvec_to_matrix(x[:3])
    ref = make_transform(R, c - R @ c + x[3:] * scale)
    np.testing.assert_array_equal(_plane_step(P, Q, N, w, scale), ref)
    # a degenerate system (all normals equal) has no step
    assert _plane_step(P, Q, np.tile([0.0, 0.0, 1.0], (n, 1)), w, scale) is None
