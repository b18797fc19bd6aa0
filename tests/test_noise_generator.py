"""The corruption generator of the denoising generality protocol (spectrageo.noise.generate) and
the anisotropic noise it uses: determinism, and each kind at the requested level measured on the
output (relative to the clean mesh's mean edge length, Eq. 4.36)."""

import zlib

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.datasets import fandisk
from spectrageo.geometry.primitives import edges, vertex_normals
from spectrageo.noise._core import mean_spacing
from spectrageo.noise.generator import (
    ANISOTROPIC_RATIO,
    IMPULSIVE_FRACTION,
    REGION_RATIO,
    case_seed,
)


@pytest.fixture(scope="module")
def mesh():
    m = fandisk()
    return m.vertices, m.faces


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def test_kinds_and_levels_are_the_protocols():
    assert noise.GENERATOR_KINDS == (
        "gaussian-normal",
        "gaussian-random",
        "impulsive",
        "region-varying",
        "anisotropic",
    )
    assert noise.GENERATOR_LEVELS == (0.1, 0.3, 0.5)


@pytest.mark.parametrize("kind", noise.GENERATOR_KINDS)
def test_deterministic_for_a_seed_and_input_untouched(mesh, kind):
    V, F = mesh
    V_before = V.copy()
    a = noise.generate(V, F, kind=kind, level=0.3, rng=11)
    b = noise.generate(V, F, kind=kind, level=0.3, rng=11)
    c = noise.generate(V, F, kind=kind, level=0.3, rng=12)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.mask, b.mask)
    assert not np.array_equal(a.vertices, c.vertices)
    np.testing.assert_array_equal(V, V_before)
    np.testing.assert_allclose(a.vertices - V, a.displacement, atol=1e-12)
    assert a.kind == kind


@pytest.mark.parametrize("level", noise.GENERATOR_LEVELS)
def test_each_kind_reaches_the_requested_level(mesh, level):
    V, F = mesh
    l = mean_spacing(V, F)
    N = vertex_normals(V, F)
    n = V.shape[0]

    D = noise.generate(V, F, kind="gaussian-normal", level=level, rng=1).displacement
    dn = np.einsum("ij,ij->i", D, N)
    assert _rms(dn) / l == pytest.approx(level, rel=0.05)
    assert np.abs(D - dn[:, None] * N).max() < 1e-9 * l  # purely along the normals

    D = noise.generate(V, F, kind="gaussian-random", level=level, rng=2).displacement
    assert _rms(D) / l == pytest.approx(level, rel=0.05)  # per coordinate
    tang = D - np.einsum("ij,ij->i", D, N)[:, None] * N
    assert _rms(np.linalg.norm(tang, axis=1)) / l == pytest.approx(np.sqrt(2) * level, rel=0.05)

    r = noise.generate(V, F, kind="impulsive", level=level, rng=3)
    assert r.mask.sum() == round(IMPULSIVE_FRACTION * n)
    assert not r.displacement[~r.mask].any()
    dn = np.einsum("ij,ij->i", r.displacement, N)[r.mask]
    assert _rms(dn) / l == pytest.approx(level, rel=0.15)

    r = noise.generate(V, F, kind="region-varying", level=level, rng=4)
    dn = np.einsum("ij,ij->i", r.displacement, N)
    assert _rms(dn) / l == pytest.approx(level, rel=0.05)  # the level is the average power
    assert _rms(r.scale) / l == pytest.approx(level, rel=1e-9)
    lo, hi = np.quantile(r.scale, [0.2, 0.8])
    ratio = _rms(dn[r.scale >= hi]) / _rms(dn[r.scale <= lo])
    assert ratio > 1.8  # the level really varies over the surface (measured on the output) ...
    assert r.scale.max() / r.scale.min() == pytest.approx(REGION_RATIO)
    E = edges(F)
    jump = np.abs(r.scale[E[:, 0]] - r.scale[E[:, 1]]).max()
    assert jump < 0.1 * np.ptp(r.scale)  # ... and smoothly (no jump across an edge)

    D = noise.generate(V, F, kind="anisotropic", level=level, rng=5).displacement
    w, U = np.linalg.eigh(D.T @ D / n)
    assert np.sqrt(w[2]) / l == pytest.approx(level, rel=0.05)  # along the axis
    np.testing.assert_allclose(np.sqrt(w[:2]) / l, ANISOTROPIC_RATIO * level, rtol=0.1)


def test_anisotropic_normal_frame_and_given_axis(mesh):
    V, F = mesh
    l = mean_spacing(V, F)
    N = vertex_normals(V, F)
    r = noise.anisotropic(V, F, level=0.4, ratio=0.5, frame="normal", rng=0)
    dn = np.einsum("ij,ij->i", r.displacement, N)
    tang = r.displacement - dn[:, None] * N
    assert _rms(dn) / l == pytest.approx(0.4, rel=0.05)
    # two tangential directions, each with standard deviation 0.5 * 0.4 * l
    assert _rms(np.linalg.norm(tang, axis=1)) / l == pytest.approx(np.sqrt(2) * 0.2, rel=0.05)
    r = noise.anisotropic(V, F, level=0.3, ratio=0.0, axis=[0, 0, 2.0], rng=0)
    assert not r.displacement[:, :2].any()
    assert _rms(r.displacement[:, 2]) / l == pytest.approx(0.3, rel=0.05)
    np.testing.assert_allclose(r.scale, 0.3 * l)


def test_generator_validation(mesh):
    V, F = mesh
    with pytest.raises(InvalidInputError, match="`kind` must be one of"):
        noise.generate(V, F, kind="gaussian", level=0.3)
    with pytest.raises(InvalidInputError, match="`level` must be a finite number >= 0"):
        noise.generate(V, F, kind="impulsive", level=-1.0)
    with pytest.raises(InvalidInputError, match="`F` must"):
        noise.generate(V, F[:, :2], kind="gaussian-normal", level=0.3)
    with pytest.raises(InvalidInputError, match="`axis` must be a finite non-zero 3-vector"):
        noise.anisotropic(V, F, level=0.3, axis=[0, 0, 0])
    with pytest.raises(InvalidInputError, match="`axis` applies to frame='axis' only"):
        noise.anisotropic(V, F, level=0.3, frame="normal", axis=[0, 0, 1])
    with pytest.raises(InvalidInputError, match="`frame` must be one of"):
        noise.anisotropic(V, F, level=0.3, frame="tangent")
    with pytest.raises(InvalidInputError, match="`ratio` must be a finite number >= 0"):
        noise.anisotropic(V, F, level=0.3, ratio=-0.5)


def test_case_seed_is_stable_text_crc():
    assert case_seed("cad/partLp.obj", "impulsive", 0.3) == zlib.crc32(
        b"cad/partLp.obj|impulsive|0.3"
    )
    assert case_seed("a", 0.1, seed=5) == (zlib.crc32(b"a|0.1") + 5) % 2**32
    assert case_seed("a", 0.1) != case_seed("a", 0.3)
