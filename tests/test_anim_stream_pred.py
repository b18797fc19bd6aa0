"""Streaming ``pca-pred``: one segment per ``block`` frames, decoded as it arrives, with the
vertex order kept or renumbered, at a fixed step or a per-block ``bpvf``."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.compress._connectivity import reorder_coded

from conftest import icosphere


def _animation(T: int = 40):
    V, F = icosphere(2)
    t = np.linspace(0, 1, T)[:, None, None]
    return V[None] * (1 + 0.15 * np.sin(3 * V[None, :, :1] + 4 * t)) + 0.2 * t, F


def _stream(A, F, **kw):
    enc = compress.StreamEncoder(F, method="pca-pred", **kw)
    parts = [enc.push(X) for X in A]
    parts.append(enc.close())
    return parts


def test_segments_per_block_decode_as_they_arrive():
    A, F = _animation()
    parts = _stream(A, F, block=16)
    # the header with the first frame, a block segment with frames 16 and 32, the rest at close
    assert [i for i, p in enumerate(parts) if p] == [0, 15, 31, 40]
    data = b"".join(parts)
    info = compress.info_animation(data)
    assert info["method"] == "pca-pred" and info["n_blocks"] == 3 and info["order_preserved"]
    R, F2 = compress.decode_animation(data)
    assert np.array_equal(F2, F)
    diag = float(np.linalg.norm(A.max(axis=(0, 1)) - A.min(axis=(0, 1))))
    assert np.abs(R - A).max() < 2e-3 * diag  # the default step on twice the first frame's box
    dec = compress.StreamDecoder()
    got = []
    for p in parts:
        got += dec.feed(p)
        assert len(got) in (0, 16, 32, 40)
    assert np.array_equal(np.stack(got), R)  # the same decoder, bit for bit


def test_smaller_than_blocks_at_the_same_step_scale():
    A, F = _animation()
    ours = b"".join(_stream(A, F, block=16))
    enc = compress.StreamEncoder(F, method="blocks", block=16)
    theirs = b"".join([enc.push(X) for X in A] + [enc.close()])
    err = [np.abs(compress.decode_animation(d)[0] - A).max() for d in (ours, theirs)]
    assert len(ours) < len(theirs)
    assert err[0] < 2 * err[1]


def test_reorder_renumbers_as_the_connectivity_coder_does():
    A, F = _animation(20)
    data = b"".join(_stream(A, F, block=8, reorder=True))
    assert not compress.info_animation(data)["order_preserved"]
    _V, F2, perm, _c = reorder_coded(A[0], F)
    R, F3 = compress.decode_animation(data)
    assert np.array_equal(F3, F2)
    assert np.abs(R - A[:, perm]).max() < 1e-2


def test_bpvf_per_block():
    A, F = _animation(32)
    parts = _stream(A, F, block=16, bpvf=6.0)
    for seg in (parts[15], parts[31]):  # the two block segments alone, within 5 %
        assert abs(8.0 * len(seg) / (16 * A.shape[1]) - 6.0) <= 0.3
    low = b"".join(_stream(A, F, block=16, bpvf=3.0))
    assert len(low) < len(b"".join(parts))


def test_bad_arguments():
    _A, F = _animation(4)
    with pytest.raises(InvalidInputError, match="'blocks', 'pca-pred' and 'layered'"):
        compress.StreamEncoder(F, method="pca-qp")
    with pytest.raises(InvalidInputError, match="needs method 'pca-pred'"):
        compress.StreamEncoder(F, method="blocks", reorder=True)
    with pytest.raises(InvalidInputError, match="`block` must be"):
        compress.StreamEncoder(F, method="pca-pred", block=1)
