"""Face / vertex classification into corners, edges and flat areas (Eq. 4.14-4.15, 3-means)."""

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.geometry.features import (
    CORNER,
    EDGE,
    FLAT,
    classify_faces,
    classify_vertices,
    cluster_eigenvalues,
    patch_eigenvalues,
)

from conftest import cube, grid


def _cube_regions(P):
    """Per point: number of coordinates within 0.2 of the cube's faces |x| = 1."""
    return (np.abs(P) > 0.8).sum(axis=1)  # 1 = side, 2 = near an edge, 3 = near a corner


@pytest.fixture(scope="module")
def noisy_cube():
    V, F = cube(5)
    return noise.apply(V, F, kind="gaussian", level=0.1, rng=2), F


def test_noisy_cube_faces_corners_edges_flat(noisy_cube):
    V, F = noisy_cube
    fc = classify_faces(V, F, patch=15)
    reg = _cube_regions(V[F].mean(axis=1))
    # deep inside the sides: flat; the faces closest to the 8 corners: corner
    inner = (np.abs(V[F].mean(axis=1)) > 0.6).sum(axis=1) == 1
    assert np.mean(fc.labels[inner] == FLAT) > 0.95
    C = V[F].mean(axis=1)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    nearest = [int(np.argmin(np.linalg.norm(C - c, axis=1))) for c in corners]
    assert np.all(fc.labels[nearest] == CORNER)
    # faces touching an edge (two coordinates near +-1, away from corners): edge or corner
    edge = (np.sort(np.abs(C), axis=1)[:, 1] > 0.93) & (reg < 3)
    assert np.mean(fc.labels[edge] == EDGE) > 0.7
    assert np.mean(fc.labels[edge] != FLAT) > 0.95
    assert fc.counts["corner"] < fc.counts["edge"] < fc.counts["flat"]
    np.testing.assert_allclose(fc.eigenvalues.sum(axis=1), 1.0, atol=1e-12)
    assert fc.neighbors.shape == (len(F), 15) and np.all(fc.neighbors[:, 0] == np.arange(len(F)))


def test_noisy_cube_vertices(noisy_cube):
    V, F = noisy_cube
    fc = classify_vertices(V, F, patch=15)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    nearest = [int(np.argmin(np.linalg.norm(V - c, axis=1))) for c in corners]
    assert np.all(fc.labels[nearest] == CORNER)
    inner = (np.abs(V) > 0.6).sum(axis=1) == 1
    assert np.mean(fc.labels[inner] == FLAT) > 0.95
    assert fc.is_feature.sum() == fc.counts["edge"] + fc.counts["corner"]


def test_flat_plane_has_no_features():
    V, F = grid(20, 20)
    fc = classify_faces(V, F, patch=10)
    assert fc.counts == {"flat": len(F), "edge": 0, "corner": 0}


def test_patch_eigenvalues_match_dense():
    rng = np.random.default_rng(0)
    N = rng.normal(size=(30, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    nb = rng.integers(0, 30, size=(30, 6))
    nb[:, 0] = np.arange(30)
    nb = np.array(
        [np.r_[i, rng.choice(np.delete(np.arange(30), i), 5, replace=False)] for i in range(30)]
    )
    ev = patch_eigenvalues(N, nb)
    for i in (0, 7, 29):
        R = N[nb[i]].T @ N[nb[i]] / 6
        np.testing.assert_allclose(ev[i], np.linalg.eigvalsh(R), atol=1e-12)


def test_cluster_three_ideal_groups_and_min_feature():
    X = np.r_[
        np.tile([0.0, 0.0, 1.0], (50, 1)),
        np.tile([0.0, 0.5, 0.5], (20, 1)),
        np.tile([1 / 3] * 3, (5, 1)),
    ]
    labels, centers, n_iter, converged, resid = cluster_eigenvalues(X)
    np.testing.assert_array_equal(labels, np.r_[[FLAT] * 50, [EDGE] * 20, [CORNER] * 5])
    assert converged and resid == pytest.approx(0.0) and n_iter >= 1
    np.testing.assert_allclose(centers[EDGE], [0, 0.5, 0.5])
    # weak spread only (no crease anywhere): everything stays flat
    Y = np.c_[np.zeros(60), np.linspace(0, 0.01, 60), 1 - np.linspace(0, 0.01, 60)]
    assert (cluster_eigenvalues(Y)[0] == FLAT).all()


def test_deterministic(noisy_cube):
    V, F = noisy_cube
    np.testing.assert_array_equal(classify_faces(V, F).labels, classify_faces(V, F).labels)


def test_validation(noisy_cube):
    V, F = noisy_cube
    with pytest.raises(InvalidInputError, match="`patch` must be an integer"):
        classify_faces(V, F, patch=2.5)
    with pytest.raises(InvalidInputError, match="`patch` must be >= 3"):
        classify_faces(V, F, patch=2)
    with pytest.raises(InvalidInputError, match="exceeds the number of faces"):
        classify_faces(V, F, patch=10**7)
    with pytest.raises(InvalidInputError, match="min_feature"):
        classify_faces(V, F, min_feature=-0.1)
    with pytest.raises(InvalidInputError, match="`normals` must have shape"):
        classify_faces(V, F, normals=np.ones((3, 3)))
    bad = np.ones((len(F), 3))
    bad[0, 0] = np.nan
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        classify_faces(V, F, normals=bad)
    with pytest.raises(InvalidInputError, match="`normals` is required"):
        classify_vertices(V)
    with pytest.raises(InvalidInputError, match="exceeds the number of vertices"):
        classify_vertices(V, F, patch=10**7)


def test_mesh_without_any_face_area_is_refused():
    """Every vertex at one point: all normals are zero, and every patch would have been called
    flat; a clear error instead. One face with an area is enough to classify."""
    V = np.zeros((20, 3))
    F = np.array([(i, i + 1, i + 2) for i in range(18)])
    with pytest.raises(InvalidInputError, match="every face of the mesh is degenerate"):
        classify_faces(V, F)
    with pytest.raises(InvalidInputError, match="every face of the mesh is degenerate"):
        classify_vertices(V, F)
    V[19] = (1.0, 1.0, 0.0)
    V[18] = (1.0, 0.0, 0.0)
    assert classify_faces(V, F).labels.shape == (18,)
