"""``pca-pred`` ``error=`` rate control guided by the error of the rounded coefficients: the KG
bound holds, and the coded trials are as few as the search promises."""

from __future__ import annotations

import math

import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _pca_pred
from spectrageo.compress import _rate_animation as ra
from spectrageo.compress._animation import frame_box
from spectrageo.metrics import kg_error
from test_anim_pca_pred import _animation


@pytest.fixture(scope="module")
def anim():
    return _animation(T=20)


def _encoder(A, F, block=512):
    return _pca_pred.PcaPredFileEncoder(A, F, block, *frame_box(A))


def _decoded_kg(enc, A, s):
    R, _F = compress.decode_animation(enc.build(s))
    return kg_error(R, A)


@pytest.mark.parametrize("block", [512, 7])
@pytest.mark.parametrize("error", [0.02, 0.1, 0.4])
def test_error_bound_holds_with_bounded_trials(anim, block, error):
    A, F = anim
    enc = _encoder(A, F, block)
    s, n = ra.pred_error_search(enc, A, error)
    assert abs(_decoded_kg(enc, A, s) / error - 1) <= ra.RATE_TOLERANCE
    assert 1 <= n["coded"] <= ra.PRED_CODED_TRIALS + ra.MAX_TRIALS
    assert n["rounded"] <= ra.PRED_CODED_TRIALS * (ra.PRED_ROUNDED_STEPS + 1)


def test_a_wrong_ratio_is_corrected_by_the_coded_trials(anim, monkeypatch):
    """With the coder's ratio guessed 1.6x too large, the first coded trial misses and measures
    it; the bound still holds."""
    A, F = anim
    monkeypatch.setattr(ra, "PRED_RDO_RATIO", 1.6 * ra.PRED_RDO_RATIO)
    enc = _encoder(A, F)
    s, n = ra.pred_error_search(enc, A, 0.1)
    assert abs(_decoded_kg(enc, A, s) / 0.1 - 1) <= ra.RATE_TOLERANCE
    assert 2 <= n["coded"] <= ra.PRED_CODED_TRIALS + ra.MAX_TRIALS


def test_rounded_error_is_the_coders_without_rate_distortion_rounding(anim, monkeypatch):
    A, F = anim
    enc = _encoder(A, F)
    s = 1e-3
    rounded = enc.sq_error(s, rounded=True)
    coded = enc.sq_error(s)
    assert 1.0 <= coded / rounded < 1.5
    monkeypatch.setattr(_pca_pred, "RDO_LAMBDA", 0.0)
    enc = _encoder(A, F)
    assert enc.sq_error(s) == pytest.approx(rounded, rel=1e-9)


def test_unreachable_error_is_refused(anim):
    A, F = anim
    with pytest.raises(InvalidInputError, match="cannot be reached"):
        compress.encode_animation(A, F, method="pca-pred", error=1e3)


def test_encode_animation_meets_the_error(anim):
    A, F = anim
    data = compress.encode_animation(A, F, method="pca-pred", error=0.07, reorder=False)
    R, _F = compress.decode_animation(data)
    assert math.isclose(kg_error(R, A), 0.07, rel_tol=ra.RATE_TOLERANCE)
