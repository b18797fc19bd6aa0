"""Do-no-harm on clean coarse meshes (issue 53): low-poly shapes, separate triangles and
multi-part files come back from every denoiser within the targets, and their noisy versions at a
resolution where noise can be told from shape are still denoised.

The coarse-mesh test (Eqs. N11-N13) and the rule for separate triangles are documented in
:mod:`spectrageo.denoise._guard` ("Coarse meshes"); the measurements on fetched low-poly files are
``benchmarks/lowpoly/clean_coarse.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import denoise, noise
from spectrageo._errors import InvalidInputError
from spectrageo.denoise._guard import COARSE_CORR, COARSE_OFFSET, coarse_shape, has_shared_edge
from spectrageo.denoise.gnf import gnf
from spectrageo.denoise.smoothing import taubin
from spectrageo.geometry import face_areas
from spectrageo.metrics import theta_deg

from conftest import cube, icosphere

#: issue 53's do-no-harm targets: relative area change, largest move over the bounding-box
#: diagonal, mean face-normal change (degrees)
AREA, MOVE, DEG = 0.01, 0.005, 2.0
METHODS = ("tsgsp", "gnf", "taubin")


def tube(segments: int = 8, rings: int = 3, radius: float = 1.0, height: float = 2.0):
    """Closed low-poly cylinder: ``rings`` rings of ``segments`` vertices, each turned by half a
    segment against the previous one (no two side triangles coplanar), capped by fans around a
    centre vertex raised a little (no coplanar cap triangles either). Outward faces."""
    V, F = [], []
    for r in range(rings):
        a = 2 * np.pi * (np.arange(segments) + 0.5 * r) / segments
        z = height * r / (rings - 1)
        V += [(radius * np.cos(t), radius * np.sin(t), z) for t in a]
    for r in range(rings - 1):
        for i in range(segments):
            a, b = r * segments + i, r * segments + (i + 1) % segments
            c, d = a + segments, b + segments
            F += [(a, b, c), (b, d, c)]
    bottom, top = len(V), len(V) + 1
    V += [(0.0, 0.0, -0.15 * height), (0.0, 0.0, 1.15 * height)]
    last = (rings - 1) * segments
    for i in range(segments):
        F.append((bottom, (i + 1) % segments, i))
        F.append((top, last + i, last + (i + 1) % segments))
    return np.array(V, dtype=np.float64), np.array(F, dtype=np.int64)


def soup(n: int = 30, seed: int = 0):
    """``n`` separate triangles (no shared vertex) at random places and orientations."""
    g = np.random.default_rng(seed)
    V = (g.normal(size=(n, 1, 3)) * 3.0 + g.normal(size=(n, 3, 3))).reshape(-1, 3)
    return V, np.arange(3 * n, dtype=np.int64).reshape(n, 3)


def two_parts():
    """An icosahedron and a coarse icosphere beside it: one file, two connected components."""
    V1, F1 = icosphere(0)
    V2, F2 = icosphere(1)
    V2 = 0.7 * V2 + np.array([3.0, 0.5, 0.0])
    return np.vstack([V1, V2]), np.vstack([F1, F2 + V1.shape[0]])


COARSE = {
    "icosahedron": lambda: icosphere(0),
    "icosphere-42": lambda: icosphere(1),
    "tube": tube,
    "box": lambda: cube(1),
    "soup": soup,
    "two-parts": two_parts,
}


def _harm(V, F, X):
    a0, a1 = face_areas(V, F).sum(), face_areas(X, F).sum()
    diag = np.linalg.norm(V.max(axis=0) - V.min(axis=0))
    return abs(a1 / a0 - 1.0), np.linalg.norm(X - V, axis=1).max() / diag, theta_deg(X, V, F)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shape", list(COARSE))
def test_clean_coarse_meshes_are_not_harmed(shape, method):
    V, F = COARSE[shape]()
    X = denoise.denoise(V, F, method=method)
    area, move, deg = _harm(V, F, X)
    assert area <= AREA, (shape, method, area)
    assert move <= MOVE, (shape, method, move)
    assert deg <= DEG, (shape, method, deg)


@pytest.mark.parametrize("shape", ["icosahedron", "icosphere-42", "tube", "two-parts"])
def test_coarse_shape_flags_low_poly_models(shape):
    V, F = COARSE[shape]()
    c = coarse_shape(V, F)
    assert c.offset >= COARSE_OFFSET and c.corr >= COARSE_CORR and c.coarse, c


def test_coarse_shape_leaves_noise_on_fine_meshes_to_the_filter():
    # a fine icosphere with Gaussian noise: anti-correlated offsets, small ring-mean offset
    V, F = icosphere(4)
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    c = coarse_shape(Vn, F)
    assert not c.coarse and c.corr < 0 and c.offset < COARSE_OFFSET, c
    # and the clean fine sphere is smooth at its resolution (the level gate keeps it, not this)
    assert coarse_shape(V, F).offset < COARSE_OFFSET


def test_coarse_shape_degenerate_inputs():
    V, F = soup(4)
    assert not coarse_shape(V, F).coarse  # in-plane offsets only
    with pytest.raises(InvalidInputError, match="F"):
        coarse_shape(V, np.zeros((2, 4), dtype=np.int64))


def test_has_shared_edge():
    V, F = soup(5)
    assert not has_shared_edge(F)
    assert not has_shared_edge(F[:1])
    assert has_shared_edge(icosphere(0)[1])


def test_taubin_leaves_separate_triangles_alone():
    # the filter itself, without the gate: a component without an interior vertex would shrink
    V, F = soup(10)
    np.testing.assert_array_equal(taubin(V, F, n_iter=50), V)
    # a closed part next to the triangles is still smoothed
    Vi, Fi = icosphere(2)
    V2, F2 = np.vstack([V, Vi]), np.vstack([F, Fi + V.shape[0]])
    X = taubin(V2, F2)
    np.testing.assert_array_equal(X[: V.shape[0]], V)
    assert not np.allclose(X[V.shape[0] :], Vi)


def test_gnf_refusal_speaks_in_cli_terms():
    V, F = soup(6)
    with pytest.raises(InvalidInputError, match="--no-weld") as exc:
        gnf(V, F)
    assert "pass `radius`" not in str(exc.value)
    # through denoise (what the CLI calls) the file comes back unchanged instead
    np.testing.assert_array_equal(denoise.denoise(V, F, method="gnf"), V)


def _fine(shape: str):
    """The shapes above at a resolution where noise can be told from shape."""
    if shape == "sphere":
        return icosphere(4)
    if shape == "tube":
        return tube(segments=64, rings=24, height=3.0)
    if shape == "box":
        return cube(5)
    V1, F1 = icosphere(3)
    V2, F2 = icosphere(3)
    return np.vstack([V1, 0.7 * V2 + 3.0]), np.vstack([F1, F2 + V1.shape[0]])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shape", ["sphere", "tube", "box", "two-parts"])
def test_noisy_fine_versions_are_still_denoised(shape, method):
    V, F = _fine(shape)
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=3).vertices
    assert not coarse_shape(Vn, F).coarse
    X = denoise.denoise(Vn, F, method=method)
    assert theta_deg(X, V, F) < 0.8 * theta_deg(Vn, V, F)
