"""Container version 4 (the compact ``.sgc`` layout): size, exact frame, integrity, old versions."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.compress import _container
from spectrageo.datasets import fandisk

from conftest import icosphere

DATA = Path(__file__).parent / "data" / "sgc"
#: sha256 of the decoded vertices and faces of tests/data/sgc/predictive_v3.sgc (the embedded
#: fandisk at max_error 2e-3 with --reorder, written as container version 3)
PINNED_V3 = (
    "20842e263c7653510a9f628e0756e8d00f605a261d5c4ecd4b2bdc3e5e1d67ab",
    "4a5a4a31c59120425b9687679405f2fd135fc25b36ef58587a3f5b7a8e8f3695",
)


def _sha(X, dtype) -> str:
    return hashlib.sha256(np.ascontiguousarray(X, dtype=dtype).tobytes()).hexdigest()


@pytest.fixture(scope="module")
def mesh():
    m = fandisk()
    return m.V, m.F


@pytest.fixture(scope="module")
def small():
    V, F = icosphere(2)
    return V, F, compress.encode(V, F, method="predictive", max_error=1e-3, reorder=True)


def _overhead(data: bytes) -> int:
    return len(data) - sum(len(p) for _t, p in _container.parse(data).chunks)


def test_version_4_is_written_and_its_overhead_is_small(mesh):
    V, F = mesh
    data = compress.encode(V, F, method="predictive", max_error=2e-3, reorder=True)
    c = _container.parse(data)
    assert data[4] == c.version == 4 and c.reordered and not data[5] >> 6
    v3 = dataclasses.replace(c, version=3).to_bytes()
    # version 3 spends 54 bytes, the parameters and 9 per chunk outside its payloads; version
    # 4: magic, two bytes, three counts, a compact frame, the parameters and 6 per chunk
    assert _overhead(v3) == 72 + len(c.params) and _overhead(data) <= 34 + len(c.params)
    assert _container.parse(v3).chunks == c.chunks
    np.testing.assert_array_equal(compress.decode(v3)[0], compress.decode(data)[0])


def test_the_encoder_rounds_its_frame_to_what_the_header_stores(mesh):
    V, F = mesh
    c = _container.parse(compress.encode(V, F, method="predictive", step=1e-3))
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    assert float(np.float32(c.scale)) == c.scale <= diag and c.scale > diag * (1 - 1e-7)
    grid = c.scale * _container.ORIGIN_GRID
    assert all(float(round(o / grid)) * grid == o for o in c.origin)
    centre = 0.5 * (V.max(0) + V.min(0))
    assert np.abs(np.asarray(c.origin) - centre).max() <= grid / 2
    # a frame float32 cannot hold is stored wide (f64), exactly
    frames = [((1e300, 0.0, 0.0), 1.0), ((0.0, 0.0, 0.0), 1e-300), ((0.1,) * 3, 0.1)]
    frames += [_container.compact_frame((0.1, -3.7, 1e6), 0.1), ((0.0, 0.0, 0.0), 2.0**100)]
    for k, (origin, scale) in enumerate(frames):
        b = dataclasses.replace(c, origin=origin, scale=scale).to_bytes()
        p = _container.parse(b)
        assert p.origin == origin and p.scale == scale
        assert bool(b[5] >> 5 & _container.FLAG_WIDE) == (k < 3)


def test_version_3_files_still_decode_bit_identically():
    data = (DATA / "predictive_v3.sgc").read_bytes()
    assert data[4] == 3
    V, F = compress.decode(data)
    assert (_sha(V, np.float64), _sha(F, np.int64)) == PINNED_V3
    assert compress.info(data)["version"] == 3
    # the same content rewritten as version 4 (its f64 frame stored wide) decodes the same
    c = _container.parse(data)
    v4 = dataclasses.replace(c, version=None).to_bytes()
    assert v4[4] == 4 and v4[5] >> 5 & _container.FLAG_WIDE and len(v4) < len(data)
    V4, F4 = compress.decode(v4)
    assert (_sha(V4, np.float64), _sha(F4, np.int64)) == PINNED_V3


def test_every_header_byte_is_covered_by_chunk_0s_checksum(small):
    V, F, data = small
    _h, pos, _r = _container.layout(data)
    want = compress.decode(data)
    for i in range(4, pos):
        for bit in (0, 3, 7):
            bad = bytearray(data)
            bad[i] ^= 1 << bit
            with pytest.raises(InvalidInputError):
                compress.decode(bytes(bad))
    got = compress.decode(data)
    np.testing.assert_array_equal(got[0], want[0])


def test_a_damaged_count_is_refused_before_it_allocates(small, monkeypatch):
    V, F, data = small
    head, pos, records = _container.layout(data)
    forged = dataclasses.replace(head, n_vertices=1 << 28).pack() + data[pos:]  # crc not redone
    called = []
    real = compress._connectivity.decode_faces
    monkeypatch.setattr(
        compress._connectivity, "decode_faces", lambda *a: called.append(1) or real(*a)
    )
    with pytest.raises(InvalidInputError, match="header or chunk 0 is corrupted"):
        compress.decode(forged)
    assert not called


def test_cut_files_are_errors_or_their_complete_prefix(mesh):
    V, F = mesh
    data = compress.encode(V, F, submesh_size=300)  # spectral: connectivity + layers
    records = _container.layout(data)[2]
    assert data[4] == 4 and len(records) >= 3
    for cut in range(0, records[0].end):
        with pytest.raises(InvalidInputError):
            compress.decode(data[:cut], partial=True)
    for r in records[1:-1]:
        for end in (r.end, r.end + 1, r.end + 4):
            with pytest.raises(InvalidInputError, match="truncated"):
                compress.decode(data[:end])
            c = _container.parse(data[:end], partial=True)
            assert not c.complete and c.chunks[-1][1] == data[r.body : r.end]
    with pytest.raises(InvalidInputError, match="trailing"):
        compress.decode(data + b"\0")


def test_version_4_refuses_what_it_cannot_hold(small):
    c = _container.parse(small[2])
    with pytest.raises(InvalidInputError, match="tags"):
        dataclasses.replace(c, chunks=[(40, b"x")]).to_bytes()
    head, pos, _r = _container.layout(small[2])
    for field, value, match in [
        ("flags", head.flags | 4, "unknown method"),
        ("method_id", 9, "unknown method"),
        ("n_chunks", 0, "invalid counts"),
        ("scale", float("inf"), "invalid scale"),
        ("scale", -1.0, "invalid scale"),
        ("scale", float("nan"), "invalid scale"),
    ]:
        bad = dataclasses.replace(head, **{field: value}).pack() + small[2][pos:]
        with pytest.raises(InvalidInputError, match=match):
            compress.decode(bad)


def test_animations_keep_container_version_3():
    V, F = icosphere(1)
    frames = np.stack([V * (1 + 0.02 * t) for t in range(6)])
    data = compress.encode_animation(frames, F)
    assert data[4] == _container.ANIMATION_VERSION == 3
    assert compress.info_animation(data)["version"] == 3
    np.testing.assert_allclose(compress.decode_animation(data)[0], frames, atol=0.05)


def test_predictive_parameters_are_float32_and_keep_the_bound(mesh):
    V, F = mesh
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    for kw in ({"step": 1e-3}, {"max_error": 2e-3, "reorder": True}):
        data = compress.encode(V, F, method="predictive", **kw)
        c = _container.parse(data)
        assert len(c.params) == (8 if "max_error" in kw else 4)
        p = compress.info(data)["parameters"]
        if "max_error" in kw:
            assert p["max_vertex_error"] <= kw["max_error"]
            V2, F2 = compress.decode(data)
            from spectrageo.metrics import hausdorff

            hd = hausdorff(V2, F2, V, F, symmetric=True).hd_symmetric / diag
            assert hd <= kw["max_error"]
        else:
            assert p["step"] == float(np.float32(p["step"])) <= kw["step"]
