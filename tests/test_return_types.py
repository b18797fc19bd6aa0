"""One return type per function: each companion equals the deprecated return-shape flag exactly."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spectrageo import geometry, metrics, noise, outliers, spectral
from spectrageo.graph import adjacency_matrix, mesh_laplacian

from conftest import cube, icosphere


def _same(a, b) -> None:
    """Field-by-field exact equality of two results (arrays bit-identical)."""
    assert type(a) is type(b)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y, f.name


def test_pca_normals_eigen_equals_return_eigenvalues():
    V, _ = icosphere(3)
    r = geometry.pca_normals_eigen(V, 10, orient="centroid")
    assert isinstance(r, geometry.PCANormals)
    with pytest.warns(DeprecationWarning, match="pca_normals_eigen"):
        n, ev = geometry.pca_normals(V, 10, orient="centroid", return_eigenvalues=True)
    np.testing.assert_array_equal(r.normals, n)
    np.testing.assert_array_equal(r.eigenvalues, ev)
    np.testing.assert_array_equal(
        geometry.pca_normals(V, 10), geometry.pca_normals_eigen(V).normals
    )


def test_point_to_surface_closest_equals_return_closest():
    V, F = cube(3)
    P = np.random.default_rng(0).normal(size=(50, 3))
    r = metrics.point_to_surface_closest(P, V, F)
    with pytest.warns(DeprecationWarning, match="point_to_surface_closest"):
        old = metrics.point_to_surface(P, V, F, return_closest=True)
    _same(r, old)
    plain = metrics.point_to_surface(P, V, F)
    assert plain.closest_points is None
    np.testing.assert_array_equal(plain.distances, r.distances)


@pytest.mark.parametrize("kind", ["gaussian", "impulsive", "quantization"])
def test_apply_result_equals_return_result(kind):
    V, F = icosphere(2)
    r = noise.apply_result(V, F, kind=kind, rng=3)
    with pytest.warns(DeprecationWarning, match="apply_result"):
        old = noise.apply(V, F, kind=kind, rng=3, return_result=True)
    _same(r, old)
    np.testing.assert_array_equal(noise.apply(V, F, kind=kind, rng=3), r.vertices)


@pytest.mark.parametrize("kind", ["gaussian", "impulsive", "spatial-mask"])
def test_animation_noise_result_equals_return_result(kind):
    V, F = icosphere(2)
    A = np.stack([V, 1.1 * V, 0.9 * V])
    r = noise.animation_noise_result(A, F, kind=kind, rng=5)
    with pytest.warns(DeprecationWarning, match="animation_noise_result"):
        old = noise.animation_noise(A, F, kind=kind, rng=5, return_result=True)
    _same(r, old)
    np.testing.assert_array_equal(noise.animation_noise(A, F, kind=kind, rng=5), r.vertices)


@pytest.mark.parametrize("method", ["rpca", "sor"])
def test_detect_outliers_equals_return_points_false(method):
    rng = np.random.default_rng(1)
    P = np.c_[rng.random((300, 2)), 0.01 * rng.random(300)]
    P[:10] += rng.normal(scale=0.5, size=(10, 3))
    r = outliers.detect_outliers(P, method=method, k=10, workers=1)
    assert r.points is None
    with pytest.warns(DeprecationWarning, match="detect_outliers"):
        old = outliers.remove_outliers(P, method=method, k=10, workers=1, return_points=False)
    # the RPCA solver's reported residual varies in its last bits from run to run (BLAS)
    res_r, res_old = r.info.pop("residual", 0.0), old.info.pop("residual", 0.0)
    assert res_r == pytest.approx(res_old, rel=1e-9)
    _same(r, old)
    with pytest.warns(DeprecationWarning, match="return_points"):
        kept = outliers.remove_outliers(P, method=method, k=10, return_points=True)
    default = outliers.remove_outliers(P, method=method, k=10)
    np.testing.assert_array_equal(kept.points.points, default.points.points)
    np.testing.assert_array_equal(default.keep, r.keep)


def test_orthogonal_iteration_result_equals_full_output():
    V, F = icosphere(3)
    L = mesh_laplacian(V, F)
    U0 = np.random.default_rng(2).standard_normal((V.shape[0], 6))
    r = spectral.orthogonal_iteration_result(L, U0, n_iter=5, tol=1e-14, on_nonconvergence="ignore")
    with pytest.warns(DeprecationWarning, match="orthogonal_iteration_result"):
        old = spectral.orthogonal_iteration(
            L, U0, n_iter=5, tol=1e-14, on_nonconvergence="ignore", full_output=True
        )
    _same(r, old)
    np.testing.assert_array_equal(
        spectral.orthogonal_iteration(L, U0, n_iter=3),
        spectral.orthogonal_iteration_result(L, U0, n_iter=3).eigenvectors,
    )


@pytest.mark.parametrize("method", ["oi", "doi"])
def test_submesh_eigenbases_result_equals_info_list(method):
    V, F = icosphere(3)
    C = adjacency_matrix(F, V.shape[0])
    subs = spectral.overlapped_submeshes(C, submesh_size=150, rng=0)
    opts = spectral.SubmeshOptions(n_iter=20)
    kw = dict(method=method, signal=V if method == "doi" else None, options=opts, rng=4)
    r = spectral.submesh_eigenbases_result(C, subs, 8, **kw)
    assert isinstance(r, spectral.SubmeshBases) and len(r.info) == len(subs.parts)
    info: list = []
    with pytest.warns(DeprecationWarning, match="submesh_eigenbases_result"):
        old = list(spectral.submesh_eigenbases(C, subs, 8, info=info, **kw))
    assert [i for i, _, _ in old] == list(range(len(subs.parts)))
    for (_, w, U), wr, Ur in zip(old, r.eigenvalues, r.eigenvectors, strict=True):
        np.testing.assert_array_equal(w, wr)
        np.testing.assert_array_equal(U, Ur)
    for a, b in zip(info, r.info, strict=True):
        _same(a, b)
