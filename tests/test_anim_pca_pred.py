"""``pca-pred``: trajectory PCA with coefficients predicted along the mesh (round trip, the rate
control's targets, reordering, damaged data, degenerate animations)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _pca_pred
from spectrageo.compress._animation import frame_box
from spectrageo.compress._connectivity import reorder_coded
from spectrageo.metrics import kg_error

from conftest import icosphere


def _animation(T: int = 16, level: int = 3):
    """A deforming icosphere: a travelling bulge, a twist and a drift."""
    V, F = icosphere(level)
    t = np.linspace(0, 1, T)[:, None, None]
    A = V[None] * (1 + 0.2 * np.sin(3 * V[None, :, :1] + 4 * t)) + 0.3 * t
    ang = 0.5 * t[..., 0] * V[None, :, 2]
    x = A[..., 0] * np.cos(ang) - A[..., 1] * np.sin(ang)
    y = A[..., 0] * np.sin(ang) + A[..., 1] * np.cos(ang)
    return np.stack([x, y, A[..., 2]], axis=-1), F


@pytest.fixture(scope="module")
def anim():
    return _animation()


def test_decoded_frames_are_the_encoders_own_prediction(anim):
    """The decoder rebuilds exactly the integers the encoder coded, and its frames equal the
    ones the rate control predicts (BLAS products there) to rounding."""
    A, F = anim
    origin, scale = frame_box(A)
    enc = _pca_pred.PcaPredFileEncoder(A, F, 512, origin, scale)
    data = enc.build(1e-3)
    R, F2 = compress.decode_animation(data)
    assert np.array_equal(F2, F)
    assert np.abs(R - enc.frames(1e-3)).max() < 1e-12 * scale
    part = enc.parts[0][1]
    Q = part.quantise(1e-3)[4]
    coef = part.quantise(1e-3)[7]
    assert Q.shape[1] > 0
    assert np.array_equal(_pca_pred.decode_coefficients(coef, part.plan, A.shape[1], Q.shape[1]), Q)
    err2 = float(np.sum((R - A) ** 2))
    assert err2 == pytest.approx(enc.sq_error(1e-3), rel=1e-9)
    d = compress.info_animation(data)
    assert d["method"] == "pca-pred" and d["order_preserved"] and d["n_blocks"] == 1


@pytest.mark.parametrize("kw", [{"error": 0.3}, {"error": 0.05}, {"bpvf": 3.0}])
def test_rate_targets_are_met_within_5_percent(anim, kw):
    A, F = anim
    data = compress.encode_animation(A, F, method="pca-pred", **kw)
    R, _F = compress.decode_animation(data)
    got = kg_error(R, A) if "error" in kw else 8.0 * len(data) / (A.shape[0] * A.shape[1])
    want = kw.get("error", kw.get("bpvf"))
    assert abs(got / want - 1) <= 0.05


def test_smaller_than_pca_qp_at_the_same_error(anim):
    A, F = anim
    sizes = {
        m: len(compress.encode_animation(A, F, method=m, error=0.1)) for m in ("pca-qp", "pca-pred")
    }
    assert sizes["pca-pred"] < 0.8 * sizes["pca-qp"]


def test_blocks_and_degenerate_animations(anim):
    A, F = anim
    data = compress.encode_animation(A, F, method="pca-pred", block=5, step=1e-3)
    R, _F = compress.decode_animation(data)
    assert compress.info_animation(data)["n_blocks"] == 4
    assert kg_error(R, A) < 1.0
    for B in (A[:1], np.repeat(A[:1], 4, axis=0), np.zeros((3,) + A.shape[1:])):
        R, _F = compress.decode_animation(compress.encode_animation(B, F, method="pca-pred"))
        assert R.shape == B.shape and np.abs(R - B).max() < 1e-3 * max(np.ptp(B), 1.0)


def test_reorder_permutes_vertices_and_says_so(anim):
    A, F = anim
    plain = compress.encode_animation(A, F, method="pca-pred", step=1e-3)
    data = compress.encode_animation(A, F, method="pca-pred", step=1e-3, reorder=True)
    R, G = compress.decode_animation(data)
    _V, G2, perm, _c = reorder_coded(A[0], F)
    assert np.array_equal(G, G2)
    assert not compress.info_animation(data)["order_preserved"]
    assert kg_error(R, A[:, perm]) < 0.5
    assert len(data) < len(plain)
    with pytest.raises(InvalidInputError, match="reorder"):
        compress.encode_animation(A, F, method="pca-qp", reorder=True)
    with pytest.raises(InvalidInputError, match="reorder"):
        compress.encode_animation(A, F, method="pca-pred", reorder="yes")


def test_damaged_coefficients_are_refused_or_decode_finite(anim):
    A, F = anim
    origin, scale = frame_box(A)
    part = _pca_pred.PcaPredFileEncoder(A, F, 512, origin, scale).parts[0][1]
    Q = part.quantise(1e-3)[4]
    coef = part.quantise(1e-3)[7]
    n, k = Q.shape
    with pytest.raises(InvalidInputError):
        _pca_pred.decode_coefficients(coef[: len(coef) // 3], part.plan, n, k)
    with pytest.raises(InvalidInputError):
        _pca_pred.decode_coefficients(b"", part.plan, n, k)
    rng = np.random.default_rng(0)
    for _ in range(20):
        b = bytearray(coef)
        b[int(rng.integers(len(b)))] ^= 1 << int(rng.integers(8))
        try:
            got = _pca_pred.decode_coefficients(bytes(b), part.plan, n, k)
        except InvalidInputError:
            continue
        assert got.shape == (n, k)
    with pytest.raises(InvalidInputError):
        _pca_pred.read_basis(b"\x05\x00", A.shape[0])
