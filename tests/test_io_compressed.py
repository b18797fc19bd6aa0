"""Compressed files (.sgc meshes, .sga animations) as inputs of io.read, the commands and batch."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest

from spectrageo import InvalidInputError, UnsupportedFormatError, compress, io
from spectrageo.cli.main import main
from spectrageo.geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence

from conftest import icosphere


def _saved(tmp_path_factory, name: str, data: bytes):
    p = tmp_path_factory.mktemp("compressed") / name
    p.write_bytes(data)
    return data, p


@pytest.fixture(scope="module")
def sphere_sgc(tmp_path_factory):
    V, F = icosphere(3)
    return V, F, *_saved(tmp_path_factory, "sphere.sgc", compress.encode(V, F))


@pytest.fixture(scope="module")
def wave_sga(tmp_path_factory):
    V, F = icosphere(2)
    t = np.linspace(0.0, 1.0, 12)[:, None, None]
    frames = V[None] * (1.0 + 0.1 * np.sin(2 * np.pi * t + V[None, :, :1]))
    data = compress.encode_animation(frames, F, method="pca-qp")
    return frames, F, *_saved(tmp_path_factory, "wave.sga", data)


def test_sgc_reads_as_the_decoded_mesh(sphere_sgc):
    V, F, data, p = sphere_sgc
    m = io.read(p)
    V2, F2 = compress.decode(data)
    assert isinstance(m, Mesh)
    assert np.array_equal(m.vertices, V2) and np.array_equal(m.faces, F2)
    assert np.array_equal(m.faces, F)  # order kept by default
    assert np.sqrt(np.mean(np.sum((m.vertices - V) ** 2, axis=1))) < 0.01
    pts = io.read(p, kind="points")
    assert isinstance(pts, PointCloud) and np.array_equal(pts.points, V2)


def test_sgc_gzip_and_frame_folder(sphere_sgc, tmp_path):
    V, F, data, p = sphere_sgc
    gz = tmp_path / "sphere.sgc.gz"
    gz.write_bytes(gzip.compress(data))
    assert np.array_equal(io.read(gz).vertices, io.read(p).vertices)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        (folder / f"frame_{i:03d}.sgc").write_bytes(data)
    anim = io.read(folder)
    assert isinstance(anim, MeshAnimation) and anim.n_frames == 3
    assert np.array_equal(anim.frames[2], io.read(p).vertices)


def test_sga_reads_as_an_animation_or_a_sequence(wave_sga):
    frames, F, data, p = wave_sga
    a = io.read(p)
    f2, F2 = compress.decode_animation(data)
    assert isinstance(a, MeshAnimation)
    assert np.array_equal(a.frames, f2) and np.array_equal(a.faces, F)
    s = io.read(p, kind="sequence")
    assert isinstance(s, PointCloudSequence) and len(s) == frames.shape[0]
    with pytest.raises(InvalidInputError, match=r"wave\.sga: .*animation, not a single 'mesh'"):
        io.read(p, kind="mesh")


def test_cut_and_foreign_files_are_clear_errors(sphere_sgc, wave_sga, tmp_path):
    data, sga = sphere_sgc[2], wave_sga[2]
    cut = tmp_path / "cut.sgc"
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InvalidInputError, match=r"cut\.sgc: .*truncated.*--partial"):
        io.read(cut)
    head = tmp_path / "head.sgc"
    head.write_bytes(data[:10])
    with pytest.raises(InvalidInputError, match=r"head\.sgc: .*truncated inside the header\.$"):
        io.read(head)
    swapped = tmp_path / "anim.sgc"  # an animation under a mesh extension
    swapped.write_bytes(sga)
    with pytest.raises(InvalidInputError, match=r"anim\.sgc: "):
        io.read(swapped)
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0xFF
    bad = tmp_path / "bad.sgc"
    bad.write_bytes(bytes(flipped))
    with pytest.raises(InvalidInputError, match=r"bad\.sgc: .*checksum"):
        io.read(bad)
    empty = tmp_path / "empty.sga"
    empty.write_bytes(b"")
    with pytest.raises(InvalidInputError, match="empty file"):
        io.read(empty)
    with pytest.raises(InvalidInputError, match="cannot be read as 'animation'"):
        io.read(sphere_sgc[3], kind="animation")


def test_writing_a_compressed_extension_points_to_compress(tmp_path):
    V, F = icosphere(1)
    with pytest.raises(UnsupportedFormatError, match=r"x\.sgc: .*spectrageo compress"):
        io.write(tmp_path / "x.sgc", Mesh(V, F))
    anim = MeshAnimation(np.stack([V, V]), F)
    with pytest.raises(UnsupportedFormatError, match=r"x\.sga: .*spectrageo compress"):
        io.write(tmp_path / "x.sga", anim)
    assert not list(tmp_path.iterdir())
    f = io.supported_formats()
    assert ".sgc" in f["read"] and ".sga" in f["read"]
    assert ".sgc" not in f["write"]["mesh"] and ".sga" not in f["write"]["animation"]


def test_commands_take_compressed_inputs(sphere_sgc, wave_sga, tmp_path, capsys):
    V, F, data, p = sphere_sgc
    ref = tmp_path / "ref.ply"
    io.write(ref, Mesh(V, F))
    capsys.readouterr()
    assert main(["metrics", str(p), str(ref), "--json"]) == 0
    theta = json.loads(capsys.readouterr().out)["theta_deg"]
    V2, F2 = compress.decode(data)
    from spectrageo.metrics import theta_deg

    assert theta == pytest.approx(theta_deg(V2, V, F), rel=1e-9)
    ply = tmp_path / "s.ply"
    assert main(["convert", str(p), str(ply)]) == 0
    assert np.allclose(io.read(ply).vertices, V2)
    npz = tmp_path / "w.npz"
    assert main(["convert", str(wave_sga[3]), str(npz)]) == 0
    assert np.allclose(io.read(npz).frames, compress.decode_animation(wave_sga[2])[0])
    assert main(["convert", str(ply), str(tmp_path / "back.sgc")]) == 2
    assert "spectrageo compress" in capsys.readouterr().err


def test_declared_size_beyond_the_memory_cap_is_refused_before_decoding(
    sphere_sgc, wave_sga, monkeypatch
):
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "100K")
    called = []
    monkeypatch.setattr(compress, "decode", lambda *a, **k: called.append(1))
    monkeypatch.setattr(compress, "decode_animation", lambda *a, **k: called.append(1))
    with pytest.raises(InvalidInputError, match=r"sphere\.sgc: decoding 642 vertices .*memory cap"):
        io.read(sphere_sgc[3])
    with pytest.raises(InvalidInputError, match=r"wave\.sga: decoding 12 frames .*memory cap"):
        io.read(wave_sga[3])
    assert not called


def test_viewer_session_opens_compressed_uploads(sphere_sgc, wave_sga):
    from spectrageo.viewer.server import ViewerSession

    s = ViewerSession()
    m = s.load_bytes(sphere_sgc[2], "sphere.sgc")
    assert np.array_equal(m.obj.vertices, compress.decode(sphere_sgc[2])[0])
    a = s.load_bytes(wave_sga[2], "wave.sga")
    assert isinstance(a.obj, MeshAnimation) and a.obj.n_frames == 12
    with pytest.raises(InvalidInputError, match=r"could not read cut\.sgc: .*truncated"):
        s.load_bytes(sphere_sgc[2][:-40], "cut.sgc")


def test_compress_no_weld_keeps_a_soup_and_hints_name_real_options(tmp_path, capsys):
    V, F = icosphere(1)
    soup = Mesh(V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3))
    src = tmp_path / "soup.obj"
    io.write(src, soup)
    capsys.readouterr()
    assert main(["compress", str(src), str(tmp_path / "w.sgc")]) == 0
    err = capsys.readouterr().err
    assert "welded 240 vertices into 42 (triangle soup; --no-weld keeps them apart)" in err
    assert io.read(tmp_path / "w.sgc", weld=False).n_vertices == 42
    assert main(["compress", str(src), str(tmp_path / "s.sgc"), "--no-weld"]) == 0
    assert "welded" not in capsys.readouterr().err
    raw = io.read(tmp_path / "s.sgc", weld=False)
    assert raw.n_vertices == 240 and np.array_equal(raw.faces, soup.faces)
    # metrics has no --no-weld: the message does not offer it
    assert main(["metrics", str(src), str(src)]) == 0
    err = capsys.readouterr().err
    assert "(triangle soup)" in err and "--no-weld" not in err


def test_compress_takes_sga_and_gzipped_npz_animations(wave_sga, tmp_path):
    frames, F, data, p = wave_sga
    out = tmp_path / "again.sga"
    assert main(["compress", str(p), str(out), "--method", "pca", "--bpvf", "12"]) == 0
    a = io.read(out)
    assert isinstance(a, MeshAnimation) and a.n_frames == frames.shape[0]
    npz = tmp_path / "w.npz.gz"
    io.write(npz, MeshAnimation(frames, F))
    assert main(["compress", str(npz), str(tmp_path / "w.sga")]) == 0
    assert io.read(tmp_path / "w.sga").n_frames == frames.shape[0]


def test_decompress_and_info_take_gzipped_files(sphere_sgc, tmp_path, capsys):
    V, F, data, p = sphere_sgc
    gz = tmp_path / "s.sgc.gz"
    gz.write_bytes(gzip.compress(data))
    assert main(["decompress", str(gz), str(tmp_path / "s.ply")]) == 0
    assert np.allclose(io.read(tmp_path / "s.ply").vertices, compress.decode(data)[0])
    capsys.readouterr()
    assert main(["info", str(gz), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "spectral"
    assert main(["decompress", str(tmp_path / "missing.sgc"), str(tmp_path / "m.ply")]) == 2
    assert "file not found" in capsys.readouterr().err
