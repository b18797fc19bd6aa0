"""Scalable layered coding of mesh animations (``method="layered"``, thesis Section 5.2.4,
Algorithm 11): layer decomposition, coarse reconstruction, rate adaptation, streaming."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _layered, _layered_reconstruct
from spectrageo.metrics import kg_error

from conftest import icosphere


def _synthetic(T: int = 24, seed: int = 0):
    V, F = icosphere(3)
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi)
    t = np.linspace(0, 1, T)[:, None, None]
    bulge = 1 + 0.2 * np.sin(3 * V[None, :, :1] + 4 * t + phase)
    return V[None] * bulge + 0.3 * t * np.array([1.0, 0.5, 0.0]), F


@pytest.fixture(scope="module")
def anim():
    return _synthetic()


def _bfs_depth(F, n, known):
    C, _ = _layered_reconstruct._rings(F, n)
    reached = np.zeros(n, bool)
    reached[known] = True
    depth = 0
    while not reached.all():
        nb = (C @ reached.astype(float) > 0) & ~reached
        assert nb.any()
        reached |= nb
        depth += 1
    return depth


def test_layer_order_is_a_spread_permutation(anim):
    A, F = anim
    n = A.shape[1]
    order = _layered_reconstruct.layer_order(A, F)
    assert np.array_equal(np.sort(order), np.arange(n))
    assert np.array_equal(order, _layered_reconstruct.layer_order(A, F))  # deterministic
    # Eq. (5.57) spreads the layers: every vertex is within a few rings of layer n/10
    assert _bfs_depth(F, n, order[: n // 10]) <= 3
    # the temporal term (Eq. 5.58) keeps fast vertices longer: a vertex that moves a lot ranks
    # higher with the motion than without it
    fast = A.copy()
    fast[:, 5] += np.linspace(0, 1, A.shape[0])[:, None]
    rank_with = int(np.flatnonzero(_layered_reconstruct.layer_order(fast, F) == 5)[0])
    rank_without = int(np.flatnonzero(_layered_reconstruct.layer_order(A[:1], F) == 5)[0])
    assert rank_with < rank_without


def test_coarse_reconstruction_is_exact_for_a_translation(anim):
    A, F = anim
    n = A.shape[1]
    order = _layered_reconstruct.layer_order(A[:1], F)
    rec = _layered_reconstruct.Reconstructor(F, n, order)
    rec.first(A[0])
    known = order[: n // 10]
    shift = np.array([0.1, -0.2, 0.05])
    X = rec.coarse(known, np.tile(shift, (known.size, 1)))
    assert np.allclose(X, A[0] + shift, atol=1e-12)


def test_error_falls_as_the_layer_grows(anim):
    A, F = anim
    pts = []
    for layer in (0.05, 0.2, 1.0):
        data = compress.encode_animation(A, F, method="layered", layer=layer)
        R, F2 = compress.decode_animation(data)
        assert np.array_equal(F2, F) and R.shape == A.shape
        pts.append((len(data), kg_error(R, A)))
    sizes, errs = zip(*pts)
    assert sizes[0] < sizes[1] < sizes[2]
    assert errs[0] > errs[1] > errs[2]
    # every vertex sent: only the quantisation error remains (the step is a fraction of twice
    # the first frame's diagonal)
    R, _ = compress.decode_animation(compress.encode_animation(A, F, method="layered", layer=1.0))
    diag = np.linalg.norm(A[0].max(0) - A[0].min(0))
    assert np.abs(R - A).max() <= 0.5 * _layered.DEFAULT_STEP * 2 * diag * 1.0001


def test_refresh_frames_bound_the_drift(anim):
    A, F = anim
    errs = []
    for refresh in (0, 4):
        data = compress.encode_animation(A, F, method="layered", layer=0.05, refresh=refresh)
        errs.append(kg_error(compress.decode_animation(data)[0], A))
    assert errs[1] < errs[0]


def test_fine_reconstruction_runs_and_stays_close(anim):
    A, F = anim
    coarse = compress.encode_animation(A, F, method="layered", layer=0.1)
    fine = compress.encode_animation(A, F, method="layered", layer=0.1, fine=True)
    Rc = compress.decode_animation(coarse)[0]
    Rf = compress.decode_animation(fine)[0]
    assert compress.info_animation(fine)["method"] == "layered"
    # Eq. (5.66)-(5.76): RPCA for the first frames, then the incremental SVD; the result stays
    # within a small factor of the coarse one (it does not help on smooth motion)
    assert kg_error(Rf, A) < 2.0 * kg_error(Rc, A) + 0.05


def test_stream_first_packet_and_rate_adaptation(anim):
    A, F = anim
    n = A.shape[1]
    enc = compress.StreamEncoder(F, method="layered", bpvf=2.0, refresh=0)
    dec = compress.StreamDecoder()
    packets = [enc.push(f) for f in A] + [enc.close()]
    first = dec.feed(packets[0])
    assert len(first) == 1  # the first frame decodes from the first packet
    got = first + [f for p in packets[1:] for f in dec.feed(p)]
    R = np.stack(got)
    assert R.shape == A.shape and dec.n_frames == A.shape[0]
    R2, _ = compress.decode_animation(b"".join(packets))
    assert np.array_equal(R, R2)
    # per-frame rate adaptation (Algorithm 11 line 5): every later frame fits its budget
    for t0, _nf, _off, ln in enc._lay.entries[1:]:
        assert 8.0 * ln / n <= 2.0 * 1.05 + 8.0 * 120 / n, t0
    assert kg_error(R, A) < 5.0


def test_error_target_within_5_percent(anim):
    A, F = anim
    data = compress.encode_animation(A, F, method="layered", error=1.0)
    assert abs(kg_error(compress.decode_animation(data)[0], A) - 1.0) <= 0.05


def test_error_below_the_default_steps_floor_is_met_by_a_finer_step(anim):
    """With every vertex sent, the default step's rounding bounds the KG error from below;
    `error=` under that floor refused ("try a smaller `step`"), now the step is bisected."""
    A, F = anim
    floor = kg_error(
        compress.decode_animation(compress.encode_animation(A, F, method="layered", layer=1.0))[0],
        A,
    )
    target = floor / 8
    data = compress.encode_animation(A, F, method="layered", error=target)
    assert abs(kg_error(compress.decode_animation(data)[0], A) - target) <= 0.05 * target
    params = compress.info_animation(data)["parameters"]
    assert params["step"] < 1e-3 and params["mean_layer"] == 1.0


def test_bpvf_above_every_vertex_at_the_default_step_is_met_by_a_finer_step(anim):
    """A rate above what every vertex of every frame gives at the default step refused ("use
    a smaller `step`"); now the step is bisected with every vertex sent."""
    A, F = anim
    n_vf = A.shape[0] * A.shape[1]
    top = 8.0 * len(compress.encode_animation(A, F, method="layered", layer=1.0)) / n_vf
    data = compress.encode_animation(A, F, method="layered", bpvf=2.0 * top)
    assert abs(8.0 * len(data) / n_vf - 2.0 * top) <= 0.05 * 2.0 * top
    assert compress.info_animation(data)["parameters"]["step"] < 1e-3


def test_damaged_and_truncated_layered_streams(anim):
    A, F = anim
    data = compress.encode_animation(A, F, method="layered", layer=0.1)
    with pytest.raises(InvalidInputError, match="truncated"):
        compress.decode_animation(data[: len(data) // 2])
    part, _ = compress.decode_animation(data[: int(len(data) * 0.7)], partial=True)
    full, _ = compress.decode_animation(data)
    assert 1 <= part.shape[0] < A.shape[0]
    assert np.array_equal(part, full[: part.shape[0]])
    for pos in (12, 300, len(data) // 2):
        bad = bytearray(data)
        bad[pos] ^= 0x5A
        with pytest.raises(InvalidInputError):
            compress.decode_animation(bytes(bad))
    info = compress.info_animation(data)
    assert info["n_frames"] == A.shape[0] and info["frame_index"]
    assert abs(info["parameters"]["mean_layer"] - 0.1) < 0.01


def test_bad_layered_options(anim):
    A, F = anim
    with pytest.raises(InvalidInputError, match="unknown option"):
        compress.encode_animation(A, F, method="layered", block=8)
    with pytest.raises(InvalidInputError, match="`layer`"):
        compress.encode_animation(A, F, method="layered", layer=1.5)
    with pytest.raises(InvalidInputError, match="`refresh`"):
        compress.encode_animation(A, F, method="layered", refresh=-1)
    with pytest.raises(InvalidInputError, match="unknown option"):
        compress.StreamEncoder(F, method="layered", anchors=0.1)


def test_whole_file_bpvf_within_5_percent(anim):
    A, F = anim
    data = compress.encode_animation(A, F, method="layered", bpvf=7.0)
    assert abs(8.0 * len(data) / (A.shape[0] * A.shape[1]) - 7.0) <= 0.35
    with pytest.raises(InvalidInputError, match="header and the whole first frame"):
        compress.encode_animation(A, F, method="layered", bpvf=0.05)
    with pytest.raises(InvalidInputError, match="every vertex of every frame"):
        compress.encode_animation(A, F, method="layered", bpvf=500.0)


def test_still_animation_costs_little_and_stays_exact(anim):
    """A clean, motionless input: every frame after the first codes zero residuals, so the
    result is the first frame's quantisation and later frames cost a few bytes each."""
    A, F = anim
    still = np.repeat(A[:1], 10, axis=0)
    data = compress.encode_animation(still, F, method="layered")
    R, _ = compress.decode_animation(data)
    diag = np.linalg.norm(A[0].max(0) - A[0].min(0))
    assert np.abs(R - still).max() <= 0.5 * _layered.DEFAULT_STEP * 2 * diag * 1.0001
    assert np.array_equal(R[1:], np.repeat(R[:1], 9, axis=0))
    # the frames after the first hold their segment header (about 100 bytes: the container's
    # header is repeated per segment) and empty residuals: about half of a moving frame here
    first = len(compress.encode_animation(still[:1], F, method="layered"))
    moving = len(compress.encode_animation(A[:10], F, method="layered"))
    assert (len(data) - first) / 9 < 120
    assert len(data) - first < 0.6 * (moving - first)
