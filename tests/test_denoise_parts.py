"""The do-no-harm gate decides per part on files of several parts (docs/decisions.md#denoise-gate-parts)."""

from __future__ import annotations

import numpy as np
import trimesh

from spectrageo.denoise import denoise
from spectrageo.denoise._guard import PLANAR_SHARE, planar_share
from spectrageo.geometry import mean_edge_length


def _box(shift: float):
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0)).subdivide().subdivide()
    return np.asarray(m.vertices) + [shift, 0.0, 0.0], np.asarray(m.faces)


def _noisy_sphere(level: float, seed: int = 0):
    m = trimesh.creation.icosphere(subdivisions=4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(seed)
    h = mean_edge_length(V, F)
    return V + rng.normal(0.0, level * h, V.shape[0])[:, None] * V, F


def _join(a, b):
    return np.vstack([a[0], b[0]]), np.vstack([a[1], b[1] + a[0].shape[0]])


def test_clean_planar_part_beside_a_noisy_part_is_kept_bit_for_bit():
    box, sphere = _box(3.0), _noisy_sphere(0.3)
    V, F = _join(sphere, box)
    assert planar_share(*box) >= PLANAR_SHARE > planar_share(V, F)  # the whole file is not planar
    out = denoise(V, F)
    nb = box[0].shape[0]
    assert np.array_equal(out[-nb:], V[-nb:])  # the box part as it came
    moved = np.linalg.norm(out[:-nb] - V[:-nb], axis=1)
    assert moved.max() > 0.0  # the noisy part was filtered


def test_noisy_parts_are_filtered_as_one_mesh():
    a, b = _noisy_sphere(0.3, seed=1), _noisy_sphere(0.3, seed=2)
    b = (b[0] + [3.0, 0.0, 0.0], b[1])
    V, F = _join(a, b)
    out = denoise(V, F)
    n = a[0].shape[0]
    assert np.linalg.norm(out[:n] - V[:n], axis=1).max() > 0.0
    assert np.linalg.norm(out[n:] - V[n:], axis=1).max() > 0.0


def test_two_clean_parts_come_back_unchanged():
    m = trimesh.creation.icosphere(subdivisions=4)
    sphere = (np.asarray(m.vertices), np.asarray(m.faces))
    V, F = _join(sphere, _box(3.0))
    assert np.array_equal(denoise(V, F), V)
