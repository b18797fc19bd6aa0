"""Options objects of the patch RPCA and the tiled runs: validation and the deprecated keywords."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.outliers import RPCAOptions, detect_outliers, rpca_scores


def _cloud(n=600, seed=0):
    rng = np.random.default_rng(seed)
    P = np.c_[rng.random((n, 2)), 0.01 * rng.standard_normal(n)]
    return np.r_[P, rng.uniform(-1, 2, (30, 3))]


def test_options_are_frozen_and_validated_once():
    opts = RPCAOptions(dtype=np.float64)
    assert opts.dtype == "float64"
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.rho = 2.0  # type: ignore[misc]
    for field, value in [
        ("rho", 1.0),
        ("tol", 0.0),
        ("rank_tol", 1.0),
        ("dtype", "float16"),
        ("partition", "grid"),
        ("block_size", 0),
        ("tangent_weight", 2.0),
    ]:
        with pytest.raises(InvalidInputError, match=field):
            RPCAOptions(**{field: value})


def test_legacy_keywords_warn_and_give_the_same_scores():
    P = _cloud()
    new = rpca_scores(P, 8, RPCAOptions(refine=False, max_iter=50), workers=1)
    with pytest.warns(DeprecationWarning, match=r"RPCAOptions\(max_iter=\.\.\., refine=\.\.\.\)"):
        old = rpca_scores(P, 8, refine=False, max_iter=50, workers=1)
    np.testing.assert_array_equal(old.scores, new.scores)
    with pytest.warns(DeprecationWarning, match="detect_outliers"):
        r_old = detect_outliers(P, k=8, clusters=False)
    r_new = detect_outliers(P, k=8, options=RPCAOptions(clusters=False))
    np.testing.assert_array_equal(r_old.keep, r_new.keep)
    with pytest.raises(TypeError, match="no_such_option"):
        rpca_scores(P, 8, no_such_option=1)


def test_tile_options():
    pytest.importorskip("dask")
    from spectrageo import distributed

    with pytest.raises(InvalidInputError, match="`tile`"):
        distributed.TileOptions(0)
    with pytest.raises(InvalidInputError, match="`workers`"):
        distributed.TileOptions(100, workers=0)
    with pytest.raises(InvalidInputError, match="tiling"):
        distributed.remove_outliers_tiled(_cloud(), None)
