"""Integrity of ``.sgc`` / ``.sga`` files: chunks bound to their place, header fields validated,
declared counts checked against the memory cap, cut animations refused, errors naming the format.
"""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.cli.main import main
from spectrageo.compress import _container
from spectrageo.compress._sga_format import segment_end

from conftest import icosphere


@pytest.fixture(scope="module")
def sphere():
    V, F = icosphere(2)
    data = compress.encode(V, F, submesh_size=40)  # connectivity + 3 frequency layers
    return V, F, data


@pytest.fixture(scope="module")
def wave():
    V, F = icosphere(1)
    t = np.linspace(0.0, 1.0, 12)[:, None, None]
    frames = V[None] * (1.0 + 0.1 * np.sin(2 * np.pi * t + V[None, :, :1]))
    return compress.encode_animation(frames, F, method="blocks", block=4)


def _split(data: bytes) -> tuple[bytes, list[bytes]]:
    """Header and the raw chunks (record head + payload) of a container."""
    _container.parse(data)
    _h, pos, records = _container.layout(data)
    return data[:pos], [data[r.start : r.end] for r in records]


def _rebuilt(data: bytes, **changes) -> bytes:
    """``data`` with header fields changed and every checksum recomputed (a forged file)."""
    c = _container.parse(data)
    for k, v in changes.items():
        setattr(c, k, v)
    return c.to_bytes()


def _segments(data: bytes) -> list[bytes]:
    out, pos = [], 0
    while pos < len(data):
        end = segment_end(data, pos)
        out.append(data[pos:end])
        pos = end
    return out


def test_chunks_swapped_duplicated_dropped_or_foreign_are_refused(sphere):
    V, F, data = sphere
    head, ch = _split(data)
    assert data[4] == _container.FORMAT_VERSION == 4 and len(ch) == 4
    other = compress.encode(V * 1.001 + 0.002 * np.sin(7 * V), F, submesh_size=40)
    _oh, och = _split(other)
    assert other[:40] != data[:40] or och[2] != ch[2]
    hostile = {
        "swapped": [ch[0], ch[2], ch[1], ch[3]],
        "duplicated": [ch[0], ch[1], ch[1], ch[3]],
        "last duplicated": [ch[0], ch[1], ch[2], ch[2]],
        "dropped in the middle": [ch[0], ch[2], ch[3]],
        "taken from another file": [ch[0], ch[1], och[2], ch[3]],
    }
    for chunks in hostile.values():
        bad = head + b"".join(chunks)
        for partial in (False, True):
            with pytest.raises(InvalidInputError, match="out of place"):
                compress.decode(bad, partial=partial)
    # a file cut at the end: an error, or the coarser prefix with partial=True
    cut = head + b"".join(ch[:3])
    with pytest.raises(InvalidInputError, match=r"truncated \(chunk 3 of 4 missing\)"):
        compress.decode(cut)
    Vc, Fc = compress.decode(cut, partial=True)
    np.testing.assert_array_equal(Fc, F)
    assert not np.array_equal(Vc, compress.decode(data)[0])


def test_old_versions_decode_bit_identically_without_the_binding(sphere):
    V, F, data = sphere
    want = compress.decode(data)
    v3 = _rebuilt(data, version=3)
    for version in (1, 2, 3):
        old = _rebuilt(data, version=version)
        assert old[4] == version and len(old) == len(v3)
        assert old[:4] == v3[:4] and old[5:40] == v3[5:40]
        got = compress.decode(old)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        assert compress.info(old)["version"] == version
    assert compress.info(data)["version"] == 4 and len(v3) > len(data)


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("scale", 0.0, r"invalid scale; expected a finite number > 0, got 0\.0"),
        ("scale", -1.0, "invalid scale"),
        ("scale", float("nan"), "invalid scale"),
        ("scale", float("inf"), "invalid scale"),
        ("origin", (0.0, float("inf"), 0.0), "non-finite origin"),
        ("origin", (float("nan"), 0.0, 0.0), "non-finite origin"),
    ],
)
def test_forged_header_fields_are_refused(sphere, field, value, match):
    bad = _rebuilt(sphere[2], **{field: value})
    with pytest.raises(InvalidInputError, match=match):
        compress.decode(bad)


def test_a_complete_spectral_file_must_hold_every_layer(sphere):
    c = _container.parse(sphere[2])
    bad = _rebuilt(sphere[2], chunks=c.chunks[:-1])  # chunk count edited, checksums forged
    with pytest.raises(InvalidInputError, match="holds 2 of its 3 frequency layers"):
        compress.decode(bad)


def test_forged_vertex_count_is_refused_before_any_allocation(
    sphere, tmp_path, capsys, monkeypatch
):
    bad = _rebuilt(sphere[2], n_vertices=1 << 28)
    called = []
    real = compress._connectivity.decode_faces
    monkeypatch.setattr(
        compress._connectivity, "decode_faces", lambda *a: called.append(1) or real(*a)
    )
    with pytest.raises(InvalidInputError, match=r"decoding 268435456 vertices .*memory cap"):
        compress.decode(bad)
    assert not called
    monkeypatch.undo()
    p = tmp_path / "forged.sgc"
    p.write_bytes(bad)
    assert main(["decompress", str(p), str(tmp_path / "out.ply")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "memory cap" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "out.ply").exists()


def test_sga_without_its_frame_index_is_an_error_unless_partial(wave, tmp_path, capsys):
    segs = _segments(wave)
    assert segs[-1][:4] == _container.MAGIC
    cut = b"".join(segs[:-1])
    with pytest.raises(InvalidInputError, match="frame index segment is missing"):
        compress.decode_animation(cut)
    frames, _F = compress.decode_animation(cut, partial=True)
    np.testing.assert_array_equal(frames, compress.decode_animation(wave)[0])
    p = tmp_path / "cut.sga"
    p.write_bytes(cut)
    assert main(["decompress", str(p), str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "frame index" in err[0]
    assert main(["decompress", str(p), str(tmp_path / "b.npz"), "--partial"]) == 0


def test_corrupted_sga_names_the_sga_format(wave, tmp_path, capsys):
    segs = _segments(wave)
    block = bytearray(segs[1])
    block[-3] ^= 0x40  # inside the block's last chunk payload
    bad = b"".join([segs[0], bytes(block), *segs[2:]])
    with pytest.raises(InvalidInputError, match=r"^\.sga segment at byte \d+: chunk \d+ of"):
        compress.decode_animation(bad)
    p = tmp_path / "bad.sga"
    p.write_bytes(bad)
    assert main(["decompress", str(p), str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err
    assert ".sga" in err and ".sgc" not in err


def test_sga_forged_vertex_count_is_refused_before_decoding(wave):
    segs = _segments(wave)
    head = _rebuilt(segs[0], n_vertices=1 << 28)
    bad = b"".join([head, *segs[1:]])
    with pytest.raises(InvalidInputError, match=r"^\.sga header: decoding 12 frames .*memory cap"):
        compress.decode_animation(bad)
    with pytest.raises(InvalidInputError, match="memory cap"):
        compress.StreamDecoder().feed(bad)
