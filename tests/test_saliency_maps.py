"""Saliency maps of meshes: spectral, geometric, combined, fast (thesis Section 6.1.2)."""

import numpy as np
import pytest
from scipy.stats import pearsonr

from spectrageo._errors import InvalidInputError
from spectrageo.saliency import (
    SaliencyOptions,
    coherence_matrix,
    face_patches,
    fast_mask,
    geometric_face_values,
    geometric_saliency,
    saliency,
    saliency_components,
    spectral_face_values,
    spectral_saliency,
)

from conftest import cube, grid, icosphere


def _rotation(seed=0):
    Q, R = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def _fandisk(shared_data):
    from spectrageo.io import read_mesh

    m = read_mesh(shared_data / "saliency" / "fandisk.obj")
    gt = np.loadtxt(shared_data / "saliency" / "fandisk_saliencyValues_of_centroids.csv")
    return m.vertices, m.faces, gt


def test_spectral_face_values_flat_patch_is_analytic():
    V, F = grid(8, 8)
    N = np.tile([0.0, 0.0, 1.0], (len(F), 1))
    P = face_patches(V[F].mean(axis=1), 10)
    # R_i = M_i M_i^T has the single eigenvalue k + 1 = 11, so s = 1 / 11 everywhere
    np.testing.assert_allclose(spectral_face_values(N, P), 1.0 / 11.0, rtol=1e-12)
    np.testing.assert_array_equal(spectral_saliency(V, F, k=10, per="face"), 0.0)


def test_spectral_face_values_match_explicit_eigendecomposition():
    V, F = cube(4)
    rng = np.random.default_rng(3)
    N = rng.standard_normal((len(F), 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    P = face_patches(V[F].mean(axis=1), 7)
    s = spectral_face_values(N, P)
    for i in (0, 5, 17, len(F) - 1):
        Mi = N[P[i]].T  # (3, k + 1), Eq. 6.10
        lam = np.linalg.eigvalsh(Mi @ Mi.T)  # Eq. 6.11, 6.1-6.2
        assert s[i] == pytest.approx(1.0 / np.linalg.norm(lam), rel=1e-10)  # Eq. 6.3


def test_face_patches_start_with_the_face_and_are_nearest():
    V, F = icosphere(2)
    C = V[F].mean(axis=1)
    P = face_patches(C, 6)
    assert P.shape == (len(F), 7)
    np.testing.assert_array_equal(P[:, 0], np.arange(len(F)))
    d = np.linalg.norm(C[:, None, :] - C[None, :, :], axis=2)
    for i in (0, 11, 40):
        ref = np.sort(d[i])[1:7]
        np.testing.assert_allclose(np.sort(d[i, P[i, 1:]]), ref, rtol=1e-12)


@pytest.mark.parametrize("method", ["spectral", "geometric", "combined"])
def test_cube_edges_are_more_salient_than_face_centres(method):
    V, F = cube(5)
    s = saliency(V, F, SaliencyOptions(k=15), method=method, per="face")
    assert s.min() >= 0.0 and s.max() <= 1.0 + 1e-12
    if method != "combined":
        assert s.max() == pytest.approx(1.0)
    C = V[F].mean(axis=1)
    # distance of each face centroid to the nearest cube edge (two coordinates at +-1)
    a = np.sort(1.0 - np.abs(C), axis=1)
    dist_edge = np.hypot(a[:, 0], a[:, 1])
    near, far = dist_edge < 0.2, dist_edge > 0.7
    assert near.any() and far.any()
    assert s[near].mean() > s[far].mean() + 0.3
    assert s[far].max() < 0.1


@pytest.mark.parametrize("method", ["spectral", "geometric", "combined"])
def test_map_is_invariant_to_rotation_scale_translation(method):
    V, F = cube(4)
    V = V + 0.02 * np.random.default_rng(0).standard_normal(V.shape)  # break symmetric ties
    s = saliency(V, F, method=method)
    V2 = 3.5 * V @ _rotation(1).T + np.array([10.0, -4.0, 2.0])
    s2 = saliency(V2, F, method=method)
    assert pearsonr(s, s2)[0] >= 0.999
    np.testing.assert_allclose(s, s2, atol=1e-4)


def test_vertex_map_is_first_ring_mean_of_face_map():
    V, F = cube(3)
    sf = saliency(V, F, SaliencyOptions(k=8), per="face", method="spectral")
    sv = saliency(V, F, SaliencyOptions(k=8), per="vertex", method="spectral")
    for i in (0, 7, len(V) - 1):
        ring = np.flatnonzero((F == i).any(axis=1))
        assert sv[i] == pytest.approx(sf[ring].mean())  # Eq. 6.14


def test_combined_is_weighted_mean_of_normalised_parts():
    V, F = cube(4)
    c = saliency_components(V, F, SaliencyOptions(k=12, weights=(1.0, 3.0)))
    np.testing.assert_allclose(c.combined, (c.geometric + 3.0 * c.spectral) / 4.0)
    for x in (c.spectral, c.geometric):
        assert x.min() == pytest.approx(0.0) and x.max() == pytest.approx(1.0)  # Eq. 6.12
    assert c.rpca.converged and c.rpca.residual <= 1e-4


def test_geometric_rpca_decomposes_the_coherence_matrix():
    V, F = cube(4)
    from spectrageo.geometry import face_normals

    N = face_normals(V, F)
    P = face_patches(V[F].mean(axis=1), 10)
    M = coherence_matrix(N, P)
    assert M.shape == (len(F), 33)
    np.testing.assert_array_equal(M[3, 3:6], N[P[3, 1]])
    res = geometric_face_values(N, P, sparse_norm="center", tol=1e-7, max_iter=1000)
    assert res.converged and res.residual <= 1e-7
    assert res.values.shape == (len(F),) and (res.values >= 0).all()
    # flat-area faces (all patch normals equal) have (almost) no sparse part
    flat = np.all(np.abs(M - np.tile(M[:, :3], 11)) < 1e-12, axis=1)
    assert flat.any()
    assert res.values[flat].max() < 0.2 * res.values.max()


def _reference_ialm(M, lam, tol, max_iter, group):
    """Textbook inexact ALM (full SVD, explicit L and S), same parameters as the internal solver."""
    m = M.shape[0]
    norm_fro = np.linalg.norm(M)
    two = np.linalg.norm(M, 2)
    if group:
        dual = np.sqrt((M.reshape(m, -1, 3) ** 2).sum(axis=2)).max() / lam
    else:
        dual = np.abs(M).max() / lam
    Y = M / max(two, dual)
    mu, mu_bar, S = 1.25 / two, 1.25e7 / two, np.zeros_like(M)
    for it in range(1, max_iter + 1):
        U, sv, Vt = np.linalg.svd(M - S + Y / mu, full_matrices=False)
        L = (U * np.maximum(sv - 1.0 / mu, 0.0)) @ Vt
        T = M - L + Y / mu
        thr = lam / mu
        if group:
            G = T.reshape(m, -1, 3)
            n = np.linalg.norm(G, axis=2, keepdims=True)
            S = (G * np.maximum(1.0 - thr / np.maximum(n, 1e-300), 0.0)).reshape(M.shape)
        else:
            S = np.sign(T) * np.maximum(np.abs(T) - thr, 0.0)
        Z = M - L - S
        Y = Y + mu * Z
        mu = min(1.5 * mu, mu_bar)
        if np.linalg.norm(Z) / norm_fro <= tol:
            return S, it
    return S, max_iter


@pytest.mark.parametrize("group", [True, False])
def test_fused_internal_solver_matches_textbook_ialm(group):
    from spectrageo.geometry import face_normals
    from spectrageo.saliency.geometric import _ialm_tall

    V, F = cube(4)
    V = V + 0.02 * np.random.default_rng(5).standard_normal(V.shape)
    M = coherence_matrix(face_normals(V, F), face_patches(V[F].mean(axis=1), 10))
    lam = 1.0 / np.sqrt(M.shape[0])
    S_ref, it_ref = _reference_ialm(M, lam, 1e-6, 500, group)
    S, it, conv, resid, _ = _ialm_tall(M, lam=lam, tol=1e-6, max_iter=500, group=group)
    assert conv and resid <= 1e-6 and it == it_ref
    np.testing.assert_allclose(S, S_ref, atol=1e-9)


def test_internal_solver_rows_in_blocks_give_the_same_decomposition(monkeypatch):
    # rows are independent; the Gram matrix and the residual are summed per block, so blocks
    # change the decomposition by rounding only
    from spectrageo.geometry import face_normals
    from spectrageo.saliency import geometric

    V, F = cube(4)
    V = V + 0.02 * np.random.default_rng(6).standard_normal(V.shape)
    M = coherence_matrix(face_normals(V, F), face_patches(V[F].mean(axis=1), 10))
    lam = 1.0 / np.sqrt(M.shape[0])
    S, it, _, resid, _ = geometric._ialm_tall(M, lam=lam, tol=1e-6, max_iter=500, group=True)
    monkeypatch.setattr(geometric, "ROWS", 7)
    S7, it7, _, resid7, _ = geometric._ialm_tall(M, lam=lam, tol=1e-6, max_iter=500, group=True)
    assert it7 == it
    np.testing.assert_allclose(S7, S, rtol=0, atol=1e-10)
    assert resid7 == pytest.approx(resid, rel=1e-6)


def test_group_shrinkage_is_rotation_invariant_elementwise_is_close():
    V, F = cube(4)
    V = V + 0.01 * np.random.default_rng(2).standard_normal(V.shape)
    R = _rotation(4)
    g1 = geometric_saliency(V, F, k=12, per="face", normals="face")
    g2 = geometric_saliency(V @ R.T, F, k=12, per="face", normals="face")
    np.testing.assert_allclose(g1, g2, atol=1e-5)
    e1 = geometric_saliency(V, F, k=12, per="face", normals="face", shrinkage="elementwise")
    e2 = geometric_saliency(V @ R.T, F, k=12, per="face", normals="face", shrinkage="elementwise")
    assert pearsonr(e1, e2)[0] > 0.95


def test_library_rpca_solver_agrees_with_internal():
    V, F = cube(4)
    a = geometric_saliency(V, F, k=10, per="face", shrinkage="elementwise", tol=1e-6)
    b = geometric_saliency(
        V, F, k=10, per="face", shrinkage="elementwise", solver="ialm", tol=1e-6, max_iter=500
    )
    assert pearsonr(a, b)[0] > 0.95


def test_fast_mask_drops_lowest_of_64_classes():
    s = np.array([0.0, 0.01, 1 / 64 - 1e-9, 1 / 64, 0.5, 1.0])
    np.testing.assert_array_equal(fast_mask(s), [False, False, False, True, True, True])


def test_fast_variant_analyses_fewer_rows_and_matches_original(shared_data):
    V, F, _ = _fandisk(shared_data)
    full = saliency_components(V, F)
    fast = saliency_components(V, F, SaliencyOptions(fast=True))
    assert 0.2 < fast.analysed.mean() < 0.9
    assert full.analysed.all()
    assert (fast.geometric_raw[~fast.analysed] == 0).all()
    assert pearsonr(full.combined, fast.combined)[0] >= 0.95


def test_fandisk_correlates_with_reference_map(shared_data):
    V, F, gt = _fandisk(shared_data)
    s = saliency(V, F, per="face")
    assert len(gt) == len(F)
    assert pearsonr(s, gt)[0] >= 0.85


def test_validation_errors():
    V, F = cube(2)
    with pytest.raises(InvalidInputError, match="`method` must be one of"):
        saliency(V, F, method="nope")
    with pytest.raises(InvalidInputError, match="`per` must be one of"):
        saliency(V, F, per="edge")
    with pytest.raises(InvalidInputError, match="needs at least"):
        saliency(V, F, SaliencyOptions(k=len(F)))
    with pytest.raises(InvalidInputError, match="`k` must be >= 2"):
        SaliencyOptions(k=1)
    with pytest.raises(InvalidInputError, match="`k` must be an integer"):
        SaliencyOptions(k=2.5)
    with pytest.raises(InvalidInputError, match="`weights` must be non-negative"):
        SaliencyOptions(weights=(0, 0))
    with pytest.raises(InvalidInputError, match="`weights` must be two"):
        SaliencyOptions(weights=(1,))
    with pytest.raises(InvalidInputError, match="`fast` must be True or False"):
        SaliencyOptions(fast="yes")
    with pytest.raises(InvalidInputError, match="`normals` must have shape"):
        saliency(V, F, SaliencyOptions(normals=np.zeros((3, 3))))
    with pytest.raises(InvalidInputError, match="`normals` contains NaN"):
        SaliencyOptions(normals=np.full(F.shape, np.nan))
    with pytest.raises(InvalidInputError, match="`normals` must be one of"):
        SaliencyOptions(normals="vertex")
    with pytest.raises(InvalidInputError, match="supports only shrinkage"):
        geometric_saliency(V, F, k=5, solver="ialm")
    with pytest.raises(InvalidInputError, match="`sparse_norm` must be one of"):
        geometric_saliency(V, F, k=5, sparse_norm="x")
    with pytest.raises(InvalidInputError, match="`max_iter` must be >= 1"):
        geometric_saliency(V, F, k=5, max_iter=0)
    with pytest.raises(InvalidInputError, match="`F` must have shape"):
        saliency(V, F[:, :2])


def test_options_object_and_deprecated_keywords_agree():
    V, F = cube(3)
    opts = SaliencyOptions(k=8, fast=True, weights=(1, 2))
    new = saliency(V, F, opts, per="face")
    with pytest.warns(DeprecationWarning, match="SaliencyOptions"):
        old = saliency(V, F, per="face", k=8, fast=True, weights=(1, 2))
    np.testing.assert_array_equal(new, old)
    with pytest.warns(DeprecationWarning, match="k="):
        comp = saliency_components(V, F, k=8)
    np.testing.assert_array_equal(
        comp.combined, saliency_components(V, F, SaliencyOptions(k=8)).combined
    )
    with pytest.raises(TypeError, match="unexpected keyword argument 'nope'"):
        saliency(V, F, nope=1)
    with pytest.raises(InvalidInputError, match="`options` must be a SaliencyOptions"):
        saliency(V, F, {"k": 8})
    with pytest.raises(InvalidInputError, match="supports only shrinkage"):
        SaliencyOptions(solver="godec")
