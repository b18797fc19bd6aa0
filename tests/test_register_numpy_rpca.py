"""The NumPy backend of the patch RPCA (``RPCAOptions(backend="numpy")``) against the numba one.

Same method (Eq. 5.98-5.99, Algorithm 14 and steps 5-7 of ``rpca_scores``), so equal scores within
rounding; the registration's robustification (Eq. 6.42) uses it.
"""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.outliers import RPCAOptions, rpca_scores

#: float32 state: the two paths round differently (BLAS products, summation order)
ATOL = {"float32": 1e-4, "float64": 1e-6}


def _clouds() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    sphere = rng.normal(size=(3000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    noisy = np.vstack([sphere, rng.uniform(-1.5, 1.5, size=(300, 3))])  # patches rebuilt
    u, v = rng.random((2, 4000))
    plane = np.column_stack([u, v, 0.003 * rng.normal(size=4000)])
    clustered = np.vstack([plane, 0.5 + 0.02 * rng.normal(size=(120, 3))])
    wave = np.column_stack([u, v, 0.1 * np.sin(6 * u)]) * 40.0 + 1000.0  # far from the origin
    dup = np.vstack([sphere[:1000], sphere[:50]])  # exact copies
    return {"noisy": noisy, "clustered": clustered, "wave": wave, "dup": dup}


@pytest.mark.parametrize("name", ["noisy", "clustered", "wave", "dup"])
@pytest.mark.parametrize(
    "extra",
    [{}, {"second_pass": "full"}, {"dtype": "float64"}, {"refine": False, "tangent_weight": 1.0}],
)
def test_numpy_backend_equals_numba(name, extra):
    X = _clouds()[name]
    base = dict(clusters=False, on_nonconvergence="ignore", **extra)
    a = rpca_scores(X, 10, RPCAOptions(**base))
    b = rpca_scores(X, 10, RPCAOptions(backend="numpy", **base), smoothed=True)
    atol = ATOL[np.dtype(RPCAOptions(**base).dtype).name]
    np.testing.assert_allclose(b.scores, a.scores, rtol=0, atol=atol)
    assert b.spacing == pytest.approx(a.spacing, rel=1e-12)
    assert (b.n_iter, b.n_refined, b.n_blocks) == (a.n_iter, a.n_refined, 1)
    a_sm = rpca_scores(X, 10, RPCAOptions(**base), smoothed=True).smoothed
    np.testing.assert_allclose(b.smoothed, a_sm, rtol=0, atol=atol * b.spacing)


def test_numpy_backend_rebuilds_patches():
    X = _clouds()["noisy"]
    r = rpca_scores(X, 10, RPCAOptions(backend="numpy", clusters=False))
    assert r.n_refined > 0
    assert np.all(r.scores >= 0)
    assert np.median(r.scores[3000:]) > 10 * np.median(r.scores[:3000])


def test_numpy_backend_refuses_what_it_does_not_compute():
    X = _clouds()["noisy"]
    with pytest.raises(InvalidInputError, match="clusters=False"):
        rpca_scores(X, 10, RPCAOptions(backend="numpy"))
    with pytest.raises(InvalidInputError, match="viewpoint"):
        rpca_scores(X, 10, RPCAOptions(backend="numpy", clusters=False, viewpoint=(0, 0, 0)))
    with pytest.raises(InvalidInputError, match="one block"):
        rpca_scores(X, 10, RPCAOptions(backend="numpy", clusters=False, block_size=1000))
    with pytest.raises(InvalidInputError, match="backend"):
        RPCAOptions(backend="cuda")
