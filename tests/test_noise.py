"""Noise and corruption with ground truth (Sections 3.4, 4.10): statistics, seeding, masks, errors."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.geometry import mean_edge_length, vertex_normals

from conftest import icosphere


@pytest.fixture(scope="module")
def sphere():
    return icosphere(4)  # 2562 vertices


def test_gaussian_along_normals_has_requested_sigma(sphere):
    V, F = sphere
    r = noise.gaussian(V, F, level=0.3, rng=0)
    sigma = 0.3 * mean_edge_length(V, F)
    np.testing.assert_allclose(r.vertices - V, r.displacement)
    # displacement is parallel to the unit vertex normal
    N = vertex_normals(V, F)
    c = np.einsum("ij,ij->i", r.displacement, N)
    np.testing.assert_allclose(r.displacement, c[:, None] * N, atol=1e-12)
    assert np.std(c) == pytest.approx(sigma, rel=0.06)
    assert abs(np.mean(c)) < 4 * sigma / np.sqrt(len(V))
    assert np.allclose(r.scale, sigma) and r.mask.all()


def test_uniform_has_same_sigma_and_bounded_support(sphere):
    V, F = sphere
    r = noise.uniform(V, F, level=0.5, rng=1, direction="random")
    sigma = 0.5 * mean_edge_length(V, F)
    assert np.abs(r.displacement).max() <= np.sqrt(3) * sigma + 1e-12
    assert np.std(r.displacement) == pytest.approx(sigma, rel=0.05)


def test_impulsive_moves_only_the_mask(sphere):
    V, F = sphere
    r = noise.impulsive(V, F, fraction=0.1, level=1.0, rng=2)
    assert r.mask.sum() == round(0.1 * len(V))
    moved = np.linalg.norm(r.displacement, axis=1) > 0
    assert not moved[~r.mask].any()
    assert moved[r.mask].mean() > 0.99


def test_seeded_and_input_untouched(sphere):
    V, F = sphere
    V0 = V.copy()
    a = noise.apply(V, F, kind="gaussian", level=0.3, rng=7)
    b = noise.apply(V, F, kind="gaussian", level=0.3, rng=7)
    c = noise.apply(V, F, kind="gaussian", level=0.3, rng=8)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    np.testing.assert_array_equal(V, V0)


def test_region_varying_labels_and_levels(sphere):
    V, F = sphere
    r = noise.region_varying(V, F, levels=(0.1, 0.8), rng=3)
    assert r.labels is not None and set(np.unique(r.labels)) == {0, 1}
    s = [np.std(np.linalg.norm(r.displacement[r.labels == k], axis=1)) for k in (0, 1)]
    assert s[1] > 3 * s[0]


def test_quantize_is_within_half_step(sphere):
    V, F = sphere
    r = noise.quantize(V, F, level=0.5)
    step = r.scale.max()
    assert np.abs(r.displacement).max() <= step / 2 + 1e-12


def test_point_cloud_noise_uses_nn_spacing():
    rng = np.random.default_rng(0)
    P = rng.uniform(size=(2000, 3)) * np.array([1, 1, 0.0])  # a planar patch
    r = noise.gaussian(P, None, level=0.2, rng=0)
    # PCA normals of a plane are +-z: the noise is along z only
    assert np.abs(r.displacement[:, :2]).max() < 1e-9
    assert np.abs(r.displacement[:, 2]).max() > 0


def test_animation_spatial_mask_is_same_vertices_every_frame(sphere):
    V, F = sphere
    frames = np.stack([V * (1 + 0.05 * t) for t in range(6)])
    r = noise.spatial_mask(frames, F, fraction=0.2, level=0.5, rng=0)
    moved = np.linalg.norm(r.displacement, axis=2) > 0
    m0 = moved[0]
    assert 0.1 < m0.mean() < 0.3
    for t in range(1, 6):
        np.testing.assert_array_equal(moved[t], m0)


def test_animation_noise_kinds(sphere):
    V, F = sphere
    frames = np.stack([V, 1.1 * V, 0.9 * V])
    for kind in noise.ANIMATION_KINDS:
        out = noise.animation_noise(frames, F, kind=kind, level=0.2, rng=0)
        assert out.shape == frames.shape and np.isfinite(out).all(), kind
        assert not np.allclose(out, frames), kind


def test_add_outliers_labels_and_far_bbox():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(1000, 3))
    Q, labels = noise.add_outliers(P, fraction=0.1, kind="far", rng=0)
    assert Q.shape == (1100, 3) and labels.sum() == 100 and not labels[:1000].any()
    np.testing.assert_array_equal(Q[:1000], P)
    Qn, ln = noise.add_outliers(P, fraction=0.2, kind="near", rng=0, shuffle=True)
    assert ln.sum() == 200 and ln[:1000].sum() < 200  # shuffled


def test_remove_vertices_and_holes_keep_index_map(sphere):
    V, F = sphere
    r = noise.remove_vertices(V, F, fraction=0.1, rng=0)
    assert r.removed.sum() == round(0.1 * len(V))
    np.testing.assert_array_equal(r.vertices, V[~r.removed])
    h = noise.make_holes(V, F, n_holes=2, size=0.1, rng=0)
    assert h.removed.any() and h.faces.max() < len(h.vertices)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda V, F: noise.apply(V, F, kind="pink", level=0.1), "kind"),
        (lambda V, F: noise.gaussian(V, F, level=-1), "level"),
        (lambda V, F: noise.gaussian(V, F, level=float("nan")), "level"),
        (lambda V, F: noise.impulsive(V, F, fraction=1.5, level=0.1), "fraction"),
        (lambda V, F: noise.gaussian(V, F, level=0.1, direction="up"), "direction"),
        (lambda V, F: noise.gaussian(V[:, :2], F, level=0.1), "V"),
        (lambda V, F: noise.gaussian(V, F + len(V), level=0.1), "F"),
        (lambda V, F: noise.add_outliers(V, fraction=0.1, kind="mid"), "kind"),
    ],
)
def test_errors(sphere, call, match):
    V, F = sphere
    with pytest.raises(InvalidInputError, match=match):
        call(V, F)
