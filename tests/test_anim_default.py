"""The default animation method (``pca-pred``) through the API, the CLI and the streaming
encoder, and the sides named by unreachable ``pca-pred`` targets."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.cli.main import main

from conftest import icosphere


def _animation(T: int = 12):
    V, F = icosphere(2)
    t = np.linspace(0, 1, T)[:, None, None]
    return V[None] * (1 + 0.15 * np.sin(3 * V[None, :, :1] + 4 * t)) + 0.2 * t, F


def test_default_is_pca_pred_in_the_api_and_the_cli(tmp_path):
    A, F = _animation()
    data = compress.encode_animation(A, F)
    info = compress.info_animation(data)
    assert info["method"] == "pca-pred"
    assert info["order_preserved"]
    assert data == compress.encode_animation(A, F, method="pca-pred")
    path = tmp_path / "a.npz"
    np.savez(path, vertices=A, faces=F)
    out = tmp_path / "a.sga"
    assert main(["compress", str(path), str(out), "--quiet"]) == 0
    assert out.read_bytes() == data
    R, F2 = compress.decode_animation(data)
    assert np.array_equal(F2, F)
    # the default step's error, relative to the bounding box: well under a thousandth
    diag = float(np.linalg.norm(A.max(axis=(0, 1)) - A.min(axis=(0, 1))))
    assert np.abs(R - A).max() < 1e-3 * diag


def test_streaming_default_is_pca_pred_in_blocks_of_16():
    A, F = _animation(20)
    enc = compress.StreamEncoder(F)
    parts = [enc.push(X) for X in A]
    data = b"".join(parts) + enc.close()
    info = compress.info_animation(data)
    assert info["method"] == "pca-pred" and info["n_blocks"] == 2


@pytest.mark.parametrize(
    ("kw", "side"),
    [({"bpvf": 1e-4}, "smallest"), ({"bpvf": 1e4}, "largest"), ({"error": 1e4}, "largest")],
)
def test_unreachable_pca_pred_targets_name_their_side(kw, side):
    A, F = _animation()
    with pytest.raises(InvalidInputError, match=f"cannot be reached: the {side} value"):
        compress.encode_animation(A, F, **kw)


@pytest.mark.parametrize("method", ["pca-pred", "blocks", "pca-qp"])
def test_error_target_on_frames_collapsed_to_a_point_is_refused(method):
    _A, F = _animation()
    A = np.zeros((6, int(F.max()) + 1, 3))
    A[:, :, 0] = np.arange(6)[:, None]  # each frame one point, moving
    with pytest.raises(InvalidInputError, match="KG\\) is undefined"):
        compress.encode_animation(A, F, method=method, error=0.5)
    data = compress.encode_animation(A, F, method=method, step=1e-3)
    assert np.allclose(compress.decode_animation(data)[0], A, atol=1e-6)
