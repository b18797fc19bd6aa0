"""Denoisers applied to clean inputs must do no harm (issue #14), and Algorithm 1's learned sizes.

The gate of :func:`spectrageo.denoise.denoise` (curvature-robust noise level below
``MIN_NOISE`` -> unchanged, a residual identified as surface detail by Eqs. N2-N4 -> level 0)
and the trust region (no vertex moves farther than ``trust`` noise deviations) are documented in
:mod:`spectrageo.denoise._guard`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spectrageo import denoise, io, noise
from spectrageo._errors import InvalidInputError
from spectrageo.denoise._guard import (
    MIN_GROWTH,
    MIN_NOISE,
    MIN_SURVIVAL,
    MIN_TAIL,
    PLANAR_SHARE,
    SPIKE_SHARE,
    despike,
    noise_estimate,
    noise_sigma,
    planar_share,
)
from spectrageo.denoise.tsgsp import CoarseOptions, coarse
from spectrageo.metrics import theta_deg

from conftest import cube, grid

#: clean CAD tessellations and CAD-like meshes of the shared data (all of cad/, the mechanical
#: parts of meshes/): every filter must return them unchanged
CLEAN_CAD = [
    "cad/abc_00000050.stl",
    "cad/angle_block.STL",
    "cad/cycloidal.ply",
    "cad/featuretype.STL",
    "cad/joint.obj",
    "cad/octagonal_pocket.stl",
    "cad/partLp.obj",
    "cad/plate_holes.STL",
    "cad/screwdriver.obj",
    "meshes/fandisk.off",
    "meshes/cube-meshed.off",
    "meshes/turbine.off",
    "meshes/joint.off",
    "meshes/rotor.off",
    "meshes/anchor_dense.off",
]
FILTERS = ["tsgsp", "gnf", "bnf"]


def _read(shared_data, rel):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return io.read(shared_data / rel)


def test_flat_sheet_with_a_step_is_left_unchanged():
    V, F = grid(12, 12)
    V = V + np.array([0.0, 0.0, 1.0]) * (V[:, :1] > 0.5)  # a step: a sharp feature to blur
    V = V[:, [0, 2, 1]]
    assert denoise.noise_level(V) == 0.0
    for m in FILTERS:
        np.testing.assert_array_equal(denoise.denoise(V, F, method=m), V)


def _sphere(n, rng):
    P = rng.normal(size=(n, 3))
    return P / np.linalg.norm(P, axis=1, keepdims=True)


def test_noise_sigma_is_calibrated_on_curved_surfaces():
    """Zero on a clean sphere and cylinder (curvature is not noise); within 20 % of the true
    sigma under Gaussian noise along the normals."""
    rng = np.random.default_rng(1)
    S = _sphere(6000, rng)
    t = rng.uniform(0, 2 * np.pi, 6000)
    Cyl = np.c_[np.cos(t), np.sin(t), rng.uniform(0, 4, 6000)]
    assert noise_sigma(S)[1] < 1e-3 and noise_sigma(Cyl)[1] < 1e-3  # third-order terms only
    spacing = np.sqrt(4 * np.pi / 6000)
    for sigma in (0.05 * spacing, 0.2 * spacing):
        noisy = S * (1 + sigma * rng.standard_normal(6000))[:, None]
        est = noise_sigma(noisy)[0]
        assert 0.8 * sigma < est < 1.2 * sigma, (sigma, est)


def test_trust_region_bounds_every_displacement():
    V, F = cube(6)
    Vn = noise.apply(V, F, kind="gaussian", level=0.5, rng=3)
    sigma = noise_sigma(Vn)[0]
    for m in ("tsgsp", "gnf"):
        out = denoise.denoise(Vn, F, method=m, trust=2.0)
        assert np.linalg.norm(out - Vn, axis=1).max() <= 2.0 * sigma * (1 + 1e-9)
        free = denoise.denoise(Vn, F, method=m, trust=None)
        assert np.linalg.norm(free - Vn, axis=1).max() > 2.0 * sigma  # the bound was active


def test_meshes_under_seven_vertices_are_returned_unchanged():
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    for m in denoise.available():
        np.testing.assert_array_equal(denoise.denoise(tet, Ft, method=m), tet)


def test_gate_can_be_disabled():
    V, F = grid(10, 10)
    Vn = V.copy()
    Vn[:, 2] += 1e-4 * np.random.default_rng(0).standard_normal(V.shape[0])  # tiny noise
    assert denoise.noise_level(Vn) > 0
    gated = denoise.denoise(Vn, F, method="laplacian", min_noise=1.0)
    np.testing.assert_array_equal(gated, Vn)
    assert not np.array_equal(denoise.denoise(Vn, F, method="laplacian", min_noise=0), Vn)


@pytest.mark.parametrize("rel", CLEAN_CAD)
def test_clean_cad_is_returned_unchanged_by_every_filter(shared_data, rel):
    """Was 14-59 degrees of damage (cycloidal 45, featuretype 14.6); target <= 2 degrees and
    <= 0.5 % of the diagonal. The gate leaves them exactly as they are."""
    m = _read(shared_data, rel)
    assert denoise.noise_level(m.vertices) < MIN_NOISE
    for method in FILTERS:
        np.testing.assert_array_equal(
            denoise.denoise(m.vertices, m.faces, method=method), m.vertices
        )


@pytest.mark.parametrize(
    "rel,level,improves",
    [
        ("cad/featuretype.STL", 0.1, False),
        ("cad/plate_holes.STL", 0.1, False),
        ("cad/angle_block.STL", 0.1, False),
        ("cad/partLp.obj", 0.1, True),
        ("cad/abc_00000050.stl", 0.3, True),
        ("meshes/fandisk.off", 0.1, True),
    ],
)
def test_noisy_cad_is_not_mistaken_for_clean(shared_data, rel, level, improves):
    """The same parts with Gaussian noise along the normals pass the gate and are filtered.
    On partLp, abc and fandisk tsgsp gets closer to the clean part; on the STL parts with long
    thin triangles (featuretype, plate_holes, angle_block) it does not yet (theta 41 -> 45
    degrees on featuretype): the filters still assume near-uniform triangles (issue #14)."""
    m = _read(shared_data, rel)
    Vn = noise.apply(m.vertices, m.faces, kind="gaussian", level=level, rng=0)
    assert denoise.noise_level(Vn) > MIN_NOISE
    out = denoise.denoise(Vn, m.faces, method="tsgsp")
    assert not np.array_equal(out, Vn)
    if improves:
        assert theta_deg(out, m.vertices, m.faces) < theta_deg(Vn, m.vertices, m.faces)


def test_gate_threshold_separates_the_tuning_split(shared_data):
    """MIN_NOISE was chosen on the shared pairs: above every clean original, below every noisy
    input."""
    root = shared_data / "denoise"
    pairs = sorted(p for p in root.iterdir() if (p / "Noisy.obj").exists())
    assert len(pairs) >= 8
    for p in pairs:
        assert denoise.noise_level(_read(shared_data, p / "Noisy.obj").vertices) > MIN_NOISE, p
        assert denoise.noise_level(_read(shared_data, p / "Original.obj").vertices) < MIN_NOISE, p


def test_learned_subspace_sizes_settle_inside_the_band(shared_data):
    """Algorithm 1 as written (residual rule): on Fandisk0.3 most sizes lie strictly between 1
    and the bound; with the EM-variance rule of earlier versions most sit at the bound."""
    m = _read(shared_data, "denoise/Fandisk0.3/Noisy.obj")
    r = coarse(m.vertices, m.faces)
    at_bound = r.subspace_sizes == r.max_sizes[:, None]
    inside = (r.subspace_sizes > 1) & ~at_bound
    assert inside.mean() > 0.6 and at_bound.mean() < 0.4
    assert np.median(r.subspace_sizes / r.max_sizes[:, None]) < 0.95
    em = coarse(m.vertices, m.faces, options=CoarseOptions(rule="em"))
    assert (em.subspace_sizes == em.max_sizes[:, None]).mean() > 0.6


def test_evaluation_reports_learned_sizes(shared_data, tmp_path):
    from spectrageo.evaluate import denoise as ev

    rows = ev.evaluate_denoise(
        shared_data, methods=["tsgsp"], pairs=["Fandisk0.3"], out=tmp_path / "d",
        hausdorff_distance=False,
    )  # fmt: skip
    r = next(r for r in rows if r["method"] == "tsgsp")
    assert 0 < r["mbl_median_frac"] < 0.95 and r["mbl_at_bound_pct"] < 40 and r["mbl_n"] > 0
    assert "at the bound" in (tmp_path / "d.md").read_text()


# --------------------------------------------------------------------------- detail test (N2-N4)
def _bumpy_sphere(n, rng, *, freq=20.0, amp=0.03):
    """Unit sphere with smooth detail a few samples wide: r = 1 + amp sin(fx) sin(fy) sin(fz)."""
    S = _sphere(n, rng)
    r = 1 + amp * np.sin(freq * S[:, 0]) * np.sin(freq * S[:, 1]) * np.sin(freq * S[:, 2])
    return S * r[:, None]


def test_white_noise_statistics_take_their_known_values():
    """Under Gaussian noise along the normals G = 1, S ~ 1/10 or less and T = the chi-square
    ratio 0.72 (module notes): the detail test must not fire."""
    rng = np.random.default_rng(4)
    S = _sphere(8000, rng)
    spacing = np.sqrt(4 * np.pi / 8000)
    for sigma in (0.05 * spacing, 0.3 * spacing):
        e = noise_estimate(S * (1 + sigma * rng.standard_normal(8000))[:, None])
        assert 0.9 < e.growth < 1.15 and e.survival < 0.06 and 0.65 < e.tail < 0.8, e
        assert not e.detail and e.level == e.raw_level > MIN_NOISE


def test_sampled_detail_is_not_called_noise():
    """Smooth bumps about 8 samples wide: the quadric residual level is above the gate (the old
    decision called it noise), but it grows with the patch and survives smoothing: level 0."""
    V = _bumpy_sphere(8000, np.random.default_rng(5))
    e = noise_estimate(V)
    assert e.raw_level > MIN_NOISE
    assert e.growth >= MIN_GROWTH and e.survival >= MIN_SURVIVAL and e.tail >= MIN_TAIL
    assert e.detail and e.level == 0.0 and noise_sigma(V) == (e.sigma, 0.0)
    # the same surface with noise on it is noisy again, with the same sigma as before the test
    rng = np.random.default_rng(6)
    spacing = np.sqrt(4 * np.pi / 8000)
    Vn = V * (1 + 0.3 * spacing * rng.standard_normal(8000))[:, None]
    en = noise_estimate(Vn)
    assert not en.detail and en.level == en.raw_level > MIN_NOISE


def test_noise_estimate_validates_its_arguments():
    V = _sphere(100, np.random.default_rng(0))
    with pytest.raises(InvalidInputError, match="`patch` must be >= 7; got 6"):
        noise_estimate(V, patch=6)
    with pytest.raises(InvalidInputError, match=r"`quantile` must be in \(0, 1\); got 1.0"):
        noise_estimate(V, quantile=1.0)
    small = noise_estimate(V[:20])  # fewer than 1.5 * patch points: no detail test
    assert np.isnan(small.growth) and not small.detail and small.level == small.raw_level


#: clean organic meshes of the tuning half whose quadric level is above the gate (the old gate
#: smoothed them: cow 15.2, dino 13.6 degrees with tsgsp) and one of the validation half
CLEAN_ORGANIC = ["meshes/cow.off", "meshes/dino.off", "meshes/elephant.off"]


@pytest.mark.parametrize("rel", CLEAN_ORGANIC)
def test_clean_organic_mesh_is_left_within_target(shared_data, rel):
    """Issue 14's target on a clean organic mesh: <= 2 degrees of mean normal change and no
    vertex moved more than 0.5 % of the bounding-box diagonal, by every filter."""
    m = _read(shared_data, rel)
    V, F = m.vertices, m.faces
    e = noise_estimate(V)
    assert e.raw_level > MIN_NOISE  # the level alone calls it noisy: the detail test decides
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for method in FILTERS:
        out = denoise.denoise(V, F, method=method)
        assert theta_deg(out, V, F) <= 2.0, method
        assert np.linalg.norm(out - V, axis=1).max() <= 0.005 * diag, method


def test_noisy_version_of_clean_organic_mesh_is_still_denoised(shared_data):
    """The cow with Gaussian noise along the normals passes the gate. At level 0.1 (of the mean
    edge length) its noise is as strong as its detail and tsgsp is about neutral (15.8 degrees
    in and out; 15.6-16.0 with 250-500-vertex submeshes), so it must change the mesh and stay
    within 0.5 degrees of the input; at 0.3 it must halve the input's theta (36.5 -> 18.5)."""
    m = _read(shared_data, "meshes/cow.off")
    V, F = m.vertices, m.faces
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.1, rng=0).vertices
    e = noise_estimate(Vn)
    assert not e.detail and e.level > MIN_NOISE
    out = denoise.denoise(Vn, F, method="tsgsp")
    assert not np.array_equal(out, Vn)
    assert theta_deg(out, V, F) < theta_deg(Vn, V, F) + 0.5
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=0).vertices
    out = denoise.denoise(Vn, F, method="tsgsp")
    assert theta_deg(out, V, F) < 0.55 * theta_deg(Vn, V, F)


def test_sparse_impulses_on_a_smooth_part_are_still_noise(shared_data):
    """Impulses on 10 % of fandisk's vertices raise G and S like detail, but leave patches
    without a hit (T near 0): still noisy, and tsgsp improves the normals (4.8 -> 2.1 degrees
    on the tuning case)."""
    m = _read(shared_data, "meshes/fandisk.off")
    V, F = m.vertices, m.faces
    Vn = noise.generate(V, F, kind="impulsive", level=0.3, rng=0).vertices
    e = noise_estimate(Vn)
    assert e.tail < MIN_TAIL and not e.detail and e.level > MIN_NOISE
    out = denoise.denoise(Vn, F, method="tsgsp")
    assert theta_deg(out, V, F) < theta_deg(Vn, V, F)


def _extruded_profile(n_profile=240, n_slices=9, gap=2.0):
    """A wavy sheet sampled every 0.05 along its profile z = sin(x) and every ``gap`` across:
    the 16 nearest vertices of every vertex lie on its own profile (like ``blade.off``)."""
    x = np.linspace(0.0, 12.0, n_profile)
    V = np.array([(xi, j * gap, np.sin(xi)) for j in range(n_slices) for xi in x])
    F = []
    for j in range(n_slices - 1):
        for i in range(n_profile - 1):
            a, b = j * n_profile + i, (j + 1) * n_profile + i
            F += [(a, a + 1, b), (a + 1, b + 1, b)]
    return V, np.array(F)


def test_patches_that_miss_the_surface_are_replaced_by_rings():
    """Profile-sampled sheet: every Euclidean patch is a planar curve, the quadric fits it
    exactly and the noise is invisible; with the faces, ring patches see it (module notes)."""
    from spectrageo.geometry import vertex_normals

    V, F = _extruded_profile()
    rng = np.random.default_rng(3)
    sigma = 0.06
    N = vertex_normals(V, F)
    Vn = V + sigma * rng.standard_normal(len(V))[:, None] * N
    blind = noise_estimate(Vn)
    assert blind.patches == "knn" and blind.level < MIN_NOISE  # the failure mode
    seen = noise_estimate(Vn, F=F)
    assert seen.patches == "rings" and seen.level > MIN_NOISE and not seen.detail
    assert 0.6 * sigma < seen.sigma < 1.5 * sigma
    clean = noise_estimate(V, F=F)
    assert clean.patches == "rings" and clean.level < MIN_NOISE
    # a well-sampled surface keeps its Euclidean patches when the faces are given
    G, GF = grid(40, 40)
    assert noise_estimate(G, F=GF).patches == "knn"


def test_profile_sampled_blade_is_denoised_and_left_alone_when_clean(shared_data):
    """``blade.off`` (cross-sections 1.87 apart, profiles sampled every 0.1-0.3): with Gaussian
    noise 0.3 along the normals the gate used to see no noise and return 61.6 degrees of error;
    now tsgsp halves it, and the clean blade still comes back unchanged."""
    m = _read(shared_data, "meshes/blade.off")
    V, F = m.vertices, m.faces
    for method in FILTERS:
        assert np.array_equal(denoise.denoise(V, F, method=method), V), method
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=0).vertices
    assert noise_estimate(Vn, F=F).patches == "rings"
    before = theta_deg(Vn, V, F)
    after = theta_deg(denoise.denoise(Vn, F, method="tsgsp"), V, F)
    assert after < 0.6 * before, (before, after)


def _spiked_sphere(frac=0.08, height=0.05, seed=0):
    from conftest import icosphere

    V, F = icosphere(4)  # 2562 vertices, mean edge ~0.05
    g = np.random.default_rng(seed)
    hit = g.choice(len(V), int(frac * len(V)), replace=False)
    Vn = V.copy()
    Vn[hit] += (g.choice([-1.0, 1.0], hit.size) * height * g.uniform(0.5, 1.5, hit.size))[
        :, None
    ] * V[hit]  # unit sphere: the position is the normal
    return V, F, Vn, hit


def test_despike_pulls_isolated_spikes_back_and_leaves_the_rest():
    """Eqs. N5-N8: on a sphere with spikes on 8 % of the vertices, the spikes are pulled back
    (RMS position error down by > 2x; at spikes with no spiked neighbour by > 5x), vertices
    away from every spike (almost all) do not move or move little, and a clean sphere, a clean
    subdivided cube (creases, corners) and Gaussian noise flag (almost) nothing."""
    from spectrageo.denoise._guard import SPIKE_SHARE, despike
    from spectrageo.graph.adjacency import adjacency_matrix

    V, F, Vn, hit = _spiked_sphere()
    r = despike(Vn, F)
    assert r.share >= SPIKE_SHARE and r.n_moved >= 0.7 * hit.size
    err_in = np.linalg.norm(Vn - V, axis=1)
    err_out = np.linalg.norm(r.vertices - V, axis=1)
    assert np.sqrt(np.mean(err_out**2)) < 0.5 * np.sqrt(np.mean(err_in**2))
    C = adjacency_matrix(F, len(V))
    near = np.zeros(len(V), bool)
    near[hit] = True
    lone = hit[(C @ near.astype(float))[hit] == 0]  # spikes without a spiked neighbour
    assert lone.size > 50
    assert np.sqrt(np.mean(err_out[lone] ** 2)) < 0.2 * np.sqrt(np.mean(err_in[lone] ** 2))
    near |= (C @ near.astype(float)) > 0
    far_moves = np.linalg.norm(r.vertices[~near] - Vn[~near], axis=1)
    assert np.mean(far_moves == 0) > 0.95 and far_moves.max() < 0.2 * np.median(err_in[hit])
    for Vc, Fc in (_spiked_sphere()[:2], cube(4)):
        assert despike(Vc, Fc).n_moved == 0
    Vg = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    assert despike(Vg, F).share < SPIKE_SHARE
    with pytest.raises(InvalidInputError, match="isolation"):
        despike(Vn, F, isolation=0.0)


def test_denoise_repairs_sparse_impulses_instead_of_smoothing(shared_data):
    """Through ``denoise``: impulses on 10 % of a smooth part's vertices (rocker-arm at level
    0.3, a tuning case) are repaired and the mesh is not smoothed (the level falls below the
    gate), so the normals end far better than the input's and than the filter's without the
    repair (1.8 vs 5.4 input and 8.9 degrees on the tuning run); Gaussian noise is untouched
    by the repair (same output with ``impulses=False``)."""
    m = _read(shared_data, "meshes/rocker-arm.obj")
    V, F = m.vertices, m.faces
    Vn = noise.generate(V, F, kind="impulsive", level=0.3, rng=0).vertices
    out = denoise.denoise(Vn, F, method="tsgsp")
    old = denoise.denoise(Vn, F, method="tsgsp", impulses=False)
    assert theta_deg(out, V, F) < 0.5 * theta_deg(Vn, V, F)
    assert theta_deg(out, V, F) < 0.5 * theta_deg(old, V, F)
    Vg = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=0).vertices
    np.testing.assert_array_equal(
        denoise.denoise(Vg, F, method="tsgsp"),
        denoise.denoise(Vg, F, method="tsgsp", impulses=False),
    )


def test_impulses_on_a_mesh_the_gate_calls_clean_are_repaired(shared_data):
    """Impulses on 10 % of spot's vertices (a tuning mesh) pass the detail test (level 0): the
    gate used to return the mesh unchanged with every spike in place (5.3 degrees). The repair
    now runs there and is kept when its first pass flags at least ``SPIKE_SHARE_QUIET`` of the
    vertices (5.2 % here); the clean spot, whose own sampling flags 1.8 %, still comes back
    bit for bit, and ``impulses=False`` keeps the old behaviour."""
    from spectrageo.denoise._guard import SPIKE_SHARE_QUIET

    m = _read(shared_data, "meshes/spot.obj")
    V, F = m.vertices, m.faces
    assert despike(V, F).share < SPIKE_SHARE_QUIET
    np.testing.assert_array_equal(denoise.denoise(V, F, method="tsgsp"), V)
    for level in (0.1, 0.3):
        Vn = noise.generate(V, F, kind="impulsive", level=level, rng=0).vertices
        assert noise_estimate(Vn, F=F).level < MIN_NOISE  # the gate alone would keep it
        out = denoise.denoise(Vn, F, method="tsgsp")
        assert theta_deg(out, V, F) < 0.5 * theta_deg(Vn, V, F), level
        np.testing.assert_array_equal(denoise.denoise(Vn, F, method="tsgsp", impulses=False), Vn)
        # only the repair moved vertices: gnf gives the same mesh
        np.testing.assert_array_equal(denoise.denoise(Vn, F, method="gnf"), out)
    # as a triangle soup (gated after welding, the repair on the welded mesh): every copy gets
    # its merged vertex's result
    Vs = Vn[F.ravel()]
    Fs = np.arange(Vs.shape[0]).reshape(-1, 3)
    np.testing.assert_allclose(denoise.denoise(Vs, Fs, method="tsgsp"), out[F.ravel()], atol=1e-12)


def test_nearly_empty_lower_tail_without_impulses_is_left_unchanged(shared_data):
    """knot2, a swept tube, has a residual above the gate whose lower tail is near 0 (its rings
    make some patches exact) and no spikes the repair flags: clean, and with impulses on 10 %
    of its vertices at 0.1 (the tuning case the rule was chosen on: tsgsp 1.8 -> 21.5 degrees
    before), it comes back bit for bit from every filter; ``impulses=False`` skips the rule.
    (Dense noise on CAD tessellations, whose tail is low but not empty, is still filtered:
    :func:`test_noisy_cad_is_not_mistaken_for_clean`.)"""
    from spectrageo.denoise._guard import SPARSE_TAIL, SPIKE_SHARE

    m = _read(shared_data, "meshes/knot2.off")
    V, F = m.vertices, m.faces
    Vn = noise.generate(V, F, kind="impulsive", level=0.1, rng=0).vertices
    for X in (V, Vn):
        e = noise_estimate(X, F=F)
        assert e.level > MIN_NOISE and e.tail < SPARSE_TAIL  # the gate calls it noisy
        assert despike(X, F).share < SPIKE_SHARE
        for method in FILTERS:
            np.testing.assert_array_equal(denoise.denoise(X, F, method=method), X)
    assert theta_deg(denoise.denoise(V, F, method="tsgsp", impulses=False), V, F) > 5.0


def test_small_clean_models_are_not_repaired_as_impulses():
    """The quiet-mesh repair needs 2 % *and* 20 flagged vertices: on a clean 42-vertex icosphere
    the 12 valence-5 vertices stand out (29 %), on a clean cone its apex (3 %)."""
    import trimesh

    from spectrageo.denoise._guard import SPIKE_SHARE_QUIET

    for m in (trimesh.creation.icosphere(1), trimesh.creation.cone(1.0, 2.0, sections=32)):
        V, F = np.asarray(m.vertices, float), np.asarray(m.faces)
        assert despike(V, F).share >= SPIKE_SHARE_QUIET  # the share alone would repair them
        for method in FILTERS:
            np.testing.assert_array_equal(denoise.denoise(V, F, method=method), V)


def test_mesh_whose_faces_all_collapse_is_returned_unchanged():
    """Every vertex at one point: welding leaves no face, so there is nothing to denoise and the
    mesh comes back unchanged (the impulse repair on quiet meshes and the gate of a soup must
    not fail on the empty welded mesh)."""
    V = np.zeros((20, 3))
    F = np.array([(i, i + 1, i + 2) for i in range(18)])
    for method in FILTERS:
        np.testing.assert_array_equal(denoise.denoise(V, F, method=method), V)
    # the same as a triangle soup (gated after welding)
    V, F = np.zeros((54, 3)), np.arange(54).reshape(18, 3)
    np.testing.assert_array_equal(denoise.denoise(V, F, method="tsgsp"), V)


def test_impulse_repair_hands_creased_parts_to_the_filter():
    """A subdivided cube with impulses (six seeds): spikes on creases are not isolated (N7), the
    repaired mesh is still noisy for the gate, and tsgsp finishes it; the mean theta is below
    the filter's alone (1.38 vs 1.71 degrees when written)."""
    V, F = cube(4)
    new, old = [], []
    for seed in range(6):
        Vn = noise.generate(V, F, kind="impulsive", level=0.3, rng=seed).vertices
        new.append(theta_deg(denoise.denoise(Vn, F), V, F))
        old.append(theta_deg(denoise.denoise(Vn, F, impulses=False), V, F))
    assert np.mean(new) < 0.9 * np.mean(old), (new, old)


def test_creases_of_planar_parts_are_not_spikes():
    """Eq. N7's last condition: on a clean cube meshed irregularly (Delaunay faces, irregular
    crease rings) the offsets of neighbouring crease vertices differ, and without the planar
    test a few crease vertices would be taken for spikes; with it nothing moves, and with
    impulses the moved vertices are mostly hit ones."""
    from spectrageo.denoise._guard import despike

    from conftest import irregular_cube

    for seed in range(3):
        V, F = irregular_cube(seed=seed)
        assert despike(V, F).n_moved == 0
    V, F = irregular_cube(seed=0)
    Vn = noise.generate(V, F, kind="impulsive", level=0.3, rng=0).vertices
    r = despike(Vn, F)
    hit = np.linalg.norm(Vn - V, axis=1) > 0
    moved = np.linalg.norm(r.vertices - Vn, axis=1) > 0
    assert moved.any() and np.mean(hit[moved]) > 0.5


# ---------------------------------------------------------------- planar tessellations (Eq. N9)
#: clean CAD exports from outside the shared data (tests/data/trimesh, MIT): the quadric level
#: calls each of them noisy and every filter used to destroy them (tsgsp: 50.8, 34.0 and 31.2
#: degrees of mean normal change)
TRIMESH_CAD = ["20mm-xyz-cube.stl", "7_8ths_cube.stl", "box.STL"]


@pytest.mark.parametrize("name", TRIMESH_CAD)
def test_clean_cad_outside_the_shared_data_is_returned_unchanged(name):
    from pathlib import Path

    m = io.read(Path(__file__).parent / "data" / "trimesh" / name)
    V, F = m.vertices, m.faces
    assert noise_estimate(V, F=F).level >= MIN_NOISE  # the level alone would denoise it
    assert planar_share(V, F) >= PLANAR_SHARE
    for method in FILTERS:
        np.testing.assert_array_equal(denoise.denoise(V, F, method=method), V)


def test_planar_share_counts_coplanar_face_pairs():
    V, F = grid(20, 20)
    assert planar_share(V, F) == 1.0
    Vn = V.copy()  # noise of 0.2 edge lengths along the normal
    Vn[:, 2] += 0.01 * np.random.default_rng(0).standard_normal(V.shape[0])
    assert planar_share(Vn, F) < 0.01
    Vc, Fc = cube(4)
    # 768 faces, 1152 face pairs; the 12 edges of the cube, 8 segments each, carry 96 of them
    assert Fc.shape[0] == 768
    assert planar_share(Vc, Fc) == pytest.approx(1056 / 1152)
    assert planar_share(V, F[:1]) == 0.0  # no shared edge
    with pytest.raises(InvalidInputError):
        planar_share(V, F, angle=-1.0)


def test_planar_tessellation_with_impulses_is_repaired_not_filtered():
    """Impulses on a sampled cube leave most face pairs coplanar: the impulse repair alone
    runs and is kept because it makes more of them coplanar."""
    V, F = cube(8)
    Vn = noise.generate(V, F, kind="impulsive", level=0.5, rng=2).vertices
    assert planar_share(Vn, F) >= PLANAR_SHARE
    before = theta_deg(Vn, V, F)
    for method in FILTERS:
        out = denoise.denoise(Vn, F, method=method)
        assert theta_deg(out, V, F) < 0.5 * before, method
    # without the repair a planar tessellation is returned as given
    np.testing.assert_array_equal(denoise.denoise(Vn, F, method="tsgsp", impulses=False), Vn)


def test_planar_repair_that_moves_a_cone_apex_is_refused():
    """A clean cone: the repair's first pass flags its apex (2 % of the vertices) and would
    flatten it; the repaired mesh has no more coplanar face pairs, so the input is kept."""
    import trimesh

    m = trimesh.creation.cone(radius=1.0, height=2.0, sections=48)
    V, F = np.asarray(m.vertices, float), np.asarray(m.faces)
    assert despike(V, F).share >= SPIKE_SHARE  # the repair would run
    for method in FILTERS:
        np.testing.assert_array_equal(denoise.denoise(V, F, method=method), V)
