"""Analytic and property tests of geometry primitives, graphs, Laplacians and the GFT."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from spectrageo import InvalidInputError
from spectrageo.geometry import (
    boundary_edges,
    boundary_loops,
    edges,
    face_areas,
    face_centroids,
    face_normals,
    mean_curvature,
    mean_edge_length,
    pca_normals,
    pca_normals_eigen,
    update_vertices,
    vertex_normals,
)
from spectrageo.graph import (
    adjacency_matrix,
    delta_coordinates,
    face_adjacency,
    k_ring,
    knn,
    knn_graph,
    mesh_laplacian,
    point_cloud_laplacian,
    radius_graph,
)
from spectrageo.spectral import Eigenbasis, fix_signs, lowpass_whole

from conftest import cube, grid, icosphere

TET_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_tetrahedron_normals_areas_centroids():
    n = face_normals(TET_V, TET_F)
    np.testing.assert_allclose(n[0], [0, 0, -1])
    np.testing.assert_allclose(n[3], np.ones(3) / np.sqrt(3))
    a = face_areas(TET_V, TET_F)
    np.testing.assert_allclose(a, [0.5, 0.5, 0.5, np.sqrt(3) / 2])
    np.testing.assert_allclose(face_centroids(TET_V, TET_F)[3], [1 / 3, 1 / 3, 1 / 3])
    # outward orientation: normals point away from the centroid of the solid
    c = TET_V.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", n, face_centroids(TET_V, TET_F) - c) > 0)


def test_degenerate_face_gets_zero_normal_not_nan():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2], [0, 1, 3]])
    n = face_normals(V, F)
    assert np.all(np.isfinite(n))
    np.testing.assert_array_equal(n[0], 0.0)
    vn = vertex_normals(V, F)
    assert np.all(np.isfinite(vn))
    # vertex 2 lies only on the degenerate face: zero; the others average 0 and n[1]: n[1]
    np.testing.assert_array_equal(vn[2], 0.0)
    np.testing.assert_allclose(vn[[0, 1, 3]], np.tile(n[1], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n[1]), 1.0)


@pytest.mark.parametrize("weighting", ["mean", "area"])
def test_vertex_normals_sphere_radial(weighting):
    V, F = icosphere(3)
    vn = vertex_normals(V, F, weighting=weighting)
    cos = np.einsum("ij,ij->i", vn, V / np.linalg.norm(V, axis=1, keepdims=True))
    assert cos.min() > 0.999


def test_normals_rotation_equivariant():
    V, F = icosphere(2)
    V = V * np.array([1.0, 0.7, 0.4])  # anisotropic so normals are not trivially radial
    R = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    np.testing.assert_allclose(face_normals(V @ R.T, F), face_normals(V, F) @ R.T, atol=1e-12)
    np.testing.assert_allclose(vertex_normals(V @ R.T, F), vertex_normals(V, F) @ R.T, atol=1e-12)
    rng = np.random.default_rng(0)
    P = rng.normal(size=(500, 3)) * [3, 2, 0.1]
    n1 = pca_normals(P @ R.T, 12, orient="none")
    n2 = pca_normals(P, 12, orient="none") @ R.T
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", n1, n2)), 1.0, atol=1e-8)


def test_edges_and_mean_edge_length_cube():
    V, F = cube(1)  # 8 vertices, 12 triangles, 18 edges
    E = edges(F)
    assert E.shape == (18, 2) and np.all(E[:, 0] < E[:, 1])
    lengths = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    assert np.isclose(mean_edge_length(V, F), lengths.mean())
    assert np.isclose(sorted(set(np.round(lengths, 9)))[0], 2.0)


def test_boundaries():
    V, F = grid(5, 4)
    B = boundary_edges(F)
    assert len(B) == 2 * (4 + 3)
    loops = boundary_loops(F)
    assert len(loops) == 1 and len(loops[0]) == 14
    Vs, Fs = icosphere(1)
    assert boundary_edges(Fs).size == 0 and boundary_loops(Fs) == []


def test_mean_curvature_sphere():
    V, F = icosphere(4)
    H = mean_curvature(V * 2.0, F)
    # unit-radius sphere scaled by 2: mean curvature 1/2 everywhere, positive (convex)
    assert np.median(H) == pytest.approx(0.5, rel=0.02)
    assert np.all(H > 0)


def test_pca_normals_sphere_orientation():
    V, _ = icosphere(4)
    n = pca_normals(V, 10)  # default MST propagation, root points to +z
    cos = np.einsum("ij,ij->i", n, V)
    assert np.all(np.abs(cos) > 0.99)
    assert (cos > 0).all() or (cos < 0).all()  # consistent
    r = pca_normals_eigen(V, 10, orient="centroid")
    n2, ev = r.normals, r.eigenvalues
    assert np.all(np.einsum("ij,ij->i", n2, V) > 0.99)
    assert np.all(np.diff(ev, axis=1) >= -1e-15)


def test_laplacians_symmetric_psd_nullspace(sphere_mesh):
    V, F = sphere_mesh
    ones = np.ones(len(V))
    for kind in ("binary", "gaussian", "cotangent"):
        L = mesh_laplacian(V, F, kind=kind)
        assert sp.isspmatrix_csr(L) and L.dtype == np.float64
        assert abs(L - L.T).max() < 1e-12
        np.testing.assert_allclose(L @ ones, 0.0, atol=1e-10)
        w = np.linalg.eigvalsh(L.toarray())
        assert w.min() > -1e-9
        assert np.sum(w < 1e-9) == 1  # connected mesh: one-dimensional null space
    Ln = mesh_laplacian(V, F, kind="binary", normalized=True)
    d = np.asarray(adjacency_matrix(F, len(V)).sum(axis=1)).ravel()
    np.testing.assert_allclose(Ln @ np.sqrt(d), 0.0, atol=1e-10)
    assert np.linalg.eigvalsh(Ln.toarray()).max() <= 2.0 + 1e-9


def test_binary_laplacian_matches_thesis_definition():
    V, F = cube(1)
    L = mesh_laplacian(V, F, kind="binary").toarray()
    C = adjacency_matrix(F, len(V)).toarray()
    np.testing.assert_array_equal(L, np.diag(C.sum(1)) - C)
    assert set(np.unique(C)) == {0.0, 1.0}


def test_ring_graph_spectrum_closed_form():
    # cycle graph C_n: eigenvalues 2 - 2 cos(2 pi k / n)
    n = 12
    i = np.arange(n)
    C = sp.csr_matrix(
        (np.ones(2 * n), (np.r_[i, (i + 1) % n], np.r_[(i + 1) % n, i])), shape=(n, n)
    )
    from spectrageo.graph import laplacian_from_adjacency

    L = laplacian_from_adjacency(C)
    basis = Eigenbasis.from_laplacian(L)
    expected = np.sort(2 - 2 * np.cos(2 * np.pi * i / n))
    np.testing.assert_allclose(basis.eigenvalues, expected, atol=1e-12)


def test_gft_round_trip_and_sign_convention(sphere_mesh):
    V, F = sphere_mesh
    L = mesh_laplacian(V, F)
    basis = Eigenbasis.from_laplacian(L)
    np.testing.assert_allclose(basis.igft(basis.gft(V)), V, atol=1e-10)
    U = basis.eigenvectors
    np.testing.assert_allclose(U.T @ U, np.eye(len(V)), atol=1e-10)
    big = U[np.argmax(np.abs(U), axis=0), np.arange(U.shape[1])]
    assert np.all(big > 0)
    np.testing.assert_array_equal(fix_signs(-U), U)
    assert np.all(np.diff(basis.eigenvalues) >= -1e-12)


def test_sparse_and_dense_eigenbasis_agree():
    V, F = icosphere(4)  # 2562 vertices
    L = mesh_laplacian(V, F)
    d = Eigenbasis.from_laplacian(L, 20, method="dense")
    s = Eigenbasis.from_laplacian(L, 20, method="sparse")
    np.testing.assert_allclose(s.eigenvalues, d.eigenvalues, atol=1e-8)
    # compare subspaces (degenerate eigenvalues on the sphere make single vectors ambiguous)
    from scipy.linalg import subspace_angles

    assert subspace_angles(s.eigenvectors[:, :16], d.eigenvectors[:, :16]).max() < 1e-5


def test_lowpass_whole_all_components_is_identity_and_smooths(sphere_mesh):
    V, F = sphere_mesh
    L = mesh_laplacian(V, F)
    np.testing.assert_allclose(lowpass_whole(V, L, keep=1.0), V, atol=1e-10)
    rng = np.random.default_rng(1)
    noisy = V + 0.02 * rng.normal(size=V.shape)
    smooth = lowpass_whole(noisy, L, keep=0.1)
    assert np.linalg.norm(smooth - V) < np.linalg.norm(noisy - V)


def test_delta_coordinates_flat_grid_interior_zero():
    V, F = grid(6, 6)
    d = delta_coordinates(V, F)
    interior = (V[:, 0] > 0) & (V[:, 0] < 1) & (V[:, 1] > 0) & (V[:, 1] < 1)
    np.testing.assert_allclose(d[interior], 0.0, atol=1e-12)
    C = adjacency_matrix(F, len(V)).toarray()
    i = 0
    np.testing.assert_allclose(d[i], V[i] - V[C[i] > 0].mean(axis=0))


def test_k_ring_nested(sphere_mesh):
    V, F = sphere_mesh
    C = adjacency_matrix(F, len(V))
    r1 = set(k_ring(C, 0, 1))
    r2 = set(k_ring(C, 0, 2))
    assert r1 < r2 and 0 in r1
    assert r1 - {0} == set(np.flatnonzero(C[0].toarray().ravel()))
    assert 0 not in set(k_ring(C, 0, 1, include_seeds=False))


def test_face_adjacency_cube():
    V, F = cube(1)
    A = face_adjacency(F)
    assert np.all(np.asarray(A.sum(axis=1)).ravel() == 3)
    Av = face_adjacency(F, shared="vertex")
    assert np.all(np.asarray(Av.sum(axis=1)).ravel() >= 3)


def test_knn_and_graphs_against_brute_force():
    rng = np.random.default_rng(3)
    P = rng.random((300, 3))
    idx, dist = knn(P, 5)
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    np.fill_diagonal(D, np.inf)
    np.testing.assert_allclose(dist, np.sort(D, axis=1)[:, :5], atol=1e-12)
    W = knn_graph(P, 5)
    assert abs(W - W.T).max() == 0
    R = radius_graph(P, 0.1)
    np.testing.assert_array_equal(R.toarray() > 0, D < 0.1)
    L = point_cloud_laplacian(P, 6, kind="gaussian")
    np.testing.assert_allclose(L @ np.ones(300), 0.0, atol=1e-12)


def test_knn_with_duplicates_excludes_self():
    P = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0]])
    idx, dist = knn(P, 1)
    assert idx[0, 0] == 1 and idx[1, 0] == 0 and dist[0, 0] == 0


def test_update_vertices_recovers_mesh_from_its_normals():
    V, F = icosphere(3)
    rng = np.random.default_rng(0)
    target = face_normals(V, F)
    noisy = V + 0.01 * rng.normal(size=V.shape)
    noisy_before, target_before = noisy.copy(), target.copy()
    out = update_vertices(noisy, F, target, n_iter=200)
    err_before = np.degrees(
        np.arccos(np.clip(np.einsum("ij,ij->i", face_normals(noisy, F), target), -1, 1))
    ).mean()
    err_after = np.degrees(
        np.arccos(np.clip(np.einsum("ij,ij->i", face_normals(out, F), target), -1, 1))
    ).mean()
    assert err_after < 0.1 * err_before
    # the caller's arrays are not mutated
    np.testing.assert_array_equal(noisy, noisy_before)
    np.testing.assert_array_equal(target, target_before)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: face_normals(np.zeros((4, 2)), TET_F), r"`V` must have shape \(n, 3\)"),
        (lambda: face_normals(TET_V, TET_F[:, :2]), r"`F` must have shape \(m, 3\)"),
        (lambda: face_normals(TET_V, TET_F + 1), "out of range"),
        (lambda: face_normals(TET_V * np.nan, TET_F), "NaN or inf"),
        (lambda: face_normals(TET_V, TET_F.astype(float) + 0.5), "integer"),
        (lambda: vertex_normals(TET_V, TET_F, weighting="angle"), "`weighting` must be one of"),
        (lambda: mesh_laplacian(TET_V, TET_F, kind="harmonic"), "`kind` must be one of"),
        (lambda: knn(TET_V, 4), "needs at least 5 points"),
        (lambda: knn(TET_V, 0), "`k` must be > 0"),
        (lambda: radius_graph(TET_V, -1.0), "`radius` must be > 0"),
        (lambda: Eigenbasis.from_laplacian(sp.eye(5), 9), "`k` must be in 1..5"),
        (lambda: lowpass_whole(TET_V, sp.eye(4), keep=1.5), "`keep` must be a fraction"),
        (
            lambda: update_vertices(TET_V, TET_F, np.ones((3, 3))),
            "`target_normals` must have shape",
        ),
        (lambda: k_ring(sp.eye(3), [5], 1), "`seeds` must be vertex indices"),
        (lambda: delta_coordinates(TET_V), "needs `F` or `L`"),
        (lambda: face_adjacency(TET_F, shared="corner"), "`shared` must be"),
        (
            lambda: knn_graph(np.random.default_rng(0).random((20, 3)), 3, weights="cosine"),
            "`weights` must be",
        ),
    ],
)
def test_validation_errors(call, match):
    with pytest.raises(InvalidInputError, match=match):
        call()
