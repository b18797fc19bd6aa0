"""A corpus of crafted hostile files (issue "Hardening against hostile input"), each read by the real
command line in a subprocess limited to 4 GiB of address space and 20 s: every one must end with
exit 2 and exactly one stderr line naming the problem (or exit 0 where the file is readable, e.g.
a NaN normal), never a signal, an internal error (exit 1) or a hang. Atomic-write cases and the
compiled-kernel guard are checked in process."""

from __future__ import annotations

import io as _io
import json
import os
import stat
import struct
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from _cli_limits import TIME_LIMIT, contract_violation, run_cli
from spectrageo import InvalidInputError, io
from spectrageo.geometry import Mesh, PointCloud
from spectrageo.io import _common

from conftest import icosphere, shared_file


def assert_error(path, *patterns: str, args=("info",), extra=("--json",)) -> str:
    """``spectrageo ARGS PATH`` exits 2 with one stderr line containing every pattern."""
    out = run_cli([*args, str(path), *extra])
    assert contract_violation(out, json_expected=False) is None, out.describe()
    assert out.code == 2, out.describe()
    line = out.lines[0]
    assert Path(path).name in line, line
    for pat in patterns:
        assert pat in line, f"{pat!r} not in {line!r}"
    assert out.seconds < TIME_LIMIT
    return line


def assert_errors(*cases, args=("info",), extra=("--json",)) -> list[str]:
    """:func:`assert_error` on several ``(path, *patterns)`` cases, two processes at a time."""
    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(lambda c: assert_error(*c, args=args, extra=extra), cases))


# ------------------------------------------------------------------------------------------ LAS
def las_header(
    *,
    minor: int = 2,
    n_vlrs: int = 0,
    fmt: int = 0,
    rec_len: int = 20,
    count: int = 0,
    scale: float = 0.01,
    offset_to_points: int | None = None,
) -> bytearray:
    """A LAS 1.0-1.3 public header block (227 bytes; 235 for 1.3), written field by field."""
    size = 235 if minor == 3 else 227
    h = bytearray(size)
    h[0:4] = b"LASF"
    h[24], h[25] = 1, minor
    struct.pack_into("<H", h, 94, size)
    struct.pack_into("<I", h, 96, size if offset_to_points is None else offset_to_points)
    struct.pack_into("<I", h, 100, n_vlrs)
    h[104] = fmt
    struct.pack_into("<H", h, 105, rec_len)
    struct.pack_into("<I", h, 107, count)
    struct.pack_into("<3d", h, 131, scale, scale, scale)
    return h


@pytest.fixture(scope="module")
def las_bytes(tmp_path_factory) -> tuple[bytes, int, int, int]:
    """A real-sized LAS written by spectrageo: (bytes, n points, offset, record length)."""
    pytest.importorskip("laspy")
    rng = np.random.default_rng(3)
    p = tmp_path_factory.mktemp("las") / "cloud.las"
    n = 110_000
    cloud = PointCloud(
        rng.random((n, 3)) * 100,
        colors=rng.integers(0, 256, (n, 3)).astype(np.uint8),
        attributes={"gps_time": np.arange(n, dtype=np.float64)},
    )
    io.write(p, cloud)  # point format 3: 34-byte records, 3.7 MB as in the issue
    raw = p.read_bytes()
    off = struct.unpack_from("<I", raw, 96)[0]
    rec = struct.unpack_from("<H", raw, 105)[0]
    n = struct.unpack_from("<I", raw, 107)[0]
    assert n == 110_000 and off + n * rec == len(raw)
    return raw, n, off, rec


def test_las_with_4294967295_vlrs_fails_fast(tmp_path):
    p = tmp_path / "vlrs.las"
    p.write_bytes(bytes(las_header(n_vlrs=2**32 - 1)))
    assert p.stat().st_size == 227
    assert_error(p, "4294967295 VLRs")


def test_las_truncated_at_a_record_boundary(tmp_path, las_bytes):
    raw, n, off, rec = las_bytes
    p = tmp_path / "cut.las"
    p.write_bytes(raw[: off + 1000 * rec])
    assert_error(p, "truncated LAS", "110000 points", "holds 1000")


def test_las_point_count_off_by_one(tmp_path, las_bytes):
    raw, n, off, rec = las_bytes
    plus, minus = bytearray(raw), bytearray(raw)
    struct.pack_into("<I", plus, 107, n + 1)
    struct.pack_into("<I", minus, 107, n - 1)
    (tmp_path / "plus.las").write_bytes(plus)
    (tmp_path / "minus.las").write_bytes(minus)
    assert_errors(
        (tmp_path / "plus.las", "truncated LAS", "110001 points"),
        (tmp_path / "minus.las", "declares 109999 points", "holds 110000"),
    )


def test_las_edited_header_count_does_not_allocate(tmp_path, las_bytes):
    # the 3.7 MB file whose edited count made laspy peak at 7.1 GB
    raw, n, off, rec = las_bytes
    assert 3_000_000 < len(raw) < 4_500_000
    cases = []
    for count in (2**31, 2**32 - 1, 200_000_000):
        b = bytearray(raw)
        struct.pack_into("<I", b, 107, count)
        p = tmp_path / f"count{count}.las"
        p.write_bytes(b)
        cases.append((p, f"{count}"))
    assert_errors(*cases)


def test_las_scale_zero_and_nan(tmp_path, las_bytes):
    raw, *_ = las_bytes
    cases = []
    for value, text in ((0.0, "x scale factor is 0.0"), (float("nan"), "x scale factor is nan")):
        b = bytearray(raw)
        struct.pack_into("<d", b, 131, value)
        p = tmp_path / f"scale{text[-3:]}.las"
        p.write_bytes(b)
        cases.append((p, text))
    assert_errors(*cases)


def test_las_version_fields(tmp_path, las_bytes):
    cases = []
    for major, minor in [(2, 0), (1, 9), (0, 0)]:
        b = bytearray(las_bytes[0])
        b[24], b[25] = major, minor
        p = tmp_path / f"v{major}{minor}.las"
        p.write_bytes(b)
        cases.append((p, f"version field {major}.{minor}"))
    assert_errors(*cases)


def test_las_bad_record_length_and_vlr_runs_past(tmp_path):
    p = tmp_path / "rec.las"
    p.write_bytes(bytes(las_header(rec_len=5, count=1)) + bytes(5))
    h = las_header(n_vlrs=1, offset_to_points=227 + 54)
    vlr = bytearray(54)
    struct.pack_into("<H", vlr, 20, 1000)  # 1000 bytes of record data that are not there
    q = tmp_path / "vlr.las"
    q.write_bytes(bytes(h) + bytes(vlr))
    assert_errors((p, "record length 5"), (q, "VLR 0", "record length 1000"))


def test_laz_duplicated_chunk_is_an_error_not_an_abort(tmp_path):
    pytest.importorskip("lazrs")
    rng = np.random.default_rng(5)
    p = tmp_path / "c.laz"
    io.write(p, PointCloud(rng.random((3000, 3))))
    raw = p.read_bytes()
    off = struct.unpack_from("<I", raw, 96)[0]
    cto = struct.unpack_from("<q", raw, off)[0]
    # a chunk of the compressed points repeated: the chunk-table offset now points into the data
    dup = raw[:cto] + raw[cto - 400 : cto] + raw[cto:]
    (tmp_path / "dup.laz").write_bytes(dup)
    bad = bytearray(raw)
    struct.pack_into("<q", bad, off, len(raw) + 10**9)
    (tmp_path / "cto.laz").write_bytes(bad)
    # a chunk size of 4278240080 points in the laszip VLR: lazrs allocated 135 GiB and aborted
    vlr = raw.index(b"laszip encoded") - 2 + 54
    big = bytearray(raw)
    struct.pack_into("<I", big, vlr + 12, 4278240080)
    (tmp_path / "chunk.laz").write_bytes(big)
    assert_errors(
        (tmp_path / "dup.laz", "LAZ chunk table"),
        (tmp_path / "cto.laz", "chunk table offset"),
        (tmp_path / "chunk.laz", "LAZ chunk of 4278240080 points"),
    )


def test_laz_layer_sizes_beyond_the_chunk(tmp_path):
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    header = laspy.LasHeader(point_format=6, version="1.4")
    las = laspy.LasData(header)
    P = np.random.default_rng(2).random((200, 3)) * 10
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    buf = _io.BytesIO()
    las.write(buf, do_compress=True)
    raw = bytearray(buf.getvalue())
    off = struct.unpack_from("<I", raw, 96)[0]
    # chunk 0 = first point (30 bytes raw), u32 point count, then 9 u32 layer sizes of Point14
    struct.pack_into("<9I", raw, off + 8 + 30 + 4, *([0xFFFFFFFF] * 9))
    (tmp_path / "layers.laz").write_bytes(raw)
    assert_error(tmp_path / "layers.laz", "corrupted LAZ chunk 0", "layer sizes")


def test_real_laz_with_duplicated_chunk(tmp_path, shared_data):
    pytest.importorskip("lazrs")
    src = shared_file(shared_data, "scans", "lidar", "autzen_trim.laz")
    raw = src.read_bytes()
    p = tmp_path / "autzen_dup.laz"
    p.write_bytes(raw[:5000] + raw[1500:5000] + raw[5000:])
    assert_error(p, "LAZ")


# ------------------------------------------------------------------------------------------ PCD
def test_pcd_binary_compressed_claiming_268m_points(tmp_path):
    n = 268_435_456
    head = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary_compressed\n"
    ).encode()
    payload = bytes(64)
    p = tmp_path / "huge.pcd"
    p.write_bytes(head + struct.pack("<II", len(payload), n * 12 % 2**32) + payload)
    (tmp_path / "huge2.pcd").write_bytes(
        head.replace(str(n).encode(), b"80000000") + struct.pack("<II", 64, 960_000_000) + payload
    )
    # refused before python-lzf allocates (it segfaulted when that allocation failed)
    assert_errors(
        (p, "cannot expand", "POINTS 268435456"),
        (tmp_path / "huge2.pcd", "cannot expand", "960000000"),
    )


def test_pcd_negative_and_huge_counts(tmp_path):
    base = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT {c}\nWIDTH {w}\nHEIGHT 1\n"
        "POINTS {w}\nDATA binary\n"
    )
    cases = []
    for i, (c, w, pat) in enumerate(
        [
            ("1 1 1", -1, "WIDTH must be >= 0; got -1"),
            ("1 1 1", 2**31, "truncated PCD"),
            ("1 99999999999999999999 1", 2, "COUNT of field 'y'"),
        ]
    ):
        p = tmp_path / f"c{i}.pcd"
        p.write_bytes(base.format(c=c, w=w).encode() + bytes(24))
        cases.append((p, pat))
    assert_errors(*cases)


def test_pcd_nan_normal_keeps_the_cloud(tmp_path):
    P = np.random.default_rng(1).random((10, 3))
    N = np.tile([0.0, 0.0, 1.0], (10, 1))
    N[3] = np.nan
    head = (
        "VERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\n"
        "TYPE F F F F F F\nCOUNT 1 1 1 1 1 1\nWIDTH 10\nHEIGHT 1\nPOINTS 10\nDATA binary\n"
    )
    p = tmp_path / "nan_normal.pcd"
    p.write_bytes(head.encode() + np.hstack([P, N]).astype("<f4").tobytes())
    out = run_cli(["info", str(p), "--json"])
    assert out.code == 0, out.describe()
    d = json.loads(out.stdout)
    assert d["n_vertices"] == 10 and d["has_normals"] is False
    assert len(out.lines) == 1 and "1 of 10 point normals are NaN" in out.lines[0]


# ------------------------------------------------------------------------------------------- gz
def gzip_bomb(n_mib: int) -> bytes:
    """One gzip member inflating to ``n_mib`` MiB of zeros (about 1 KB per MiB), built without
    holding the zeros: after a full flush deflate's output for the next MiB repeats exactly."""
    z = bytes(1 << 20)
    c = zlib.compressobj(9, zlib.DEFLATED, 31)
    head = c.compress(z) + c.flush(zlib.Z_FULL_FLUSH)
    block = c.compress(z) + c.flush(zlib.Z_FULL_FLUSH)
    tail = c.flush()[:-8]  # final empty block; the trailer is written for the whole stream
    crc = 0
    for _ in range(n_mib):
        crc = zlib.crc32(z, crc)
    return head + block * (n_mib - 1) + tail + struct.pack("<II", crc, (n_mib << 20) % 2**32)


def test_gzip_bomb_stops_at_the_cap(tmp_path):
    bomb = gzip_bomb(1025)  # 1 GiB + 1 MiB of zeros in about 1 MB
    assert len(bomb) < 2_000_000
    assert zlib.decompressobj(31).decompress(bomb, 1 << 20) == bytes(1 << 20)
    p = tmp_path / "bomb.ply.gz"
    p.write_bytes(bomb)
    # under the 4 GiB address-space limit the default cap is at most 1 GiB
    assert_error(p, "expands to more than the memory cap")


def test_gzip_cap_is_configurable(tmp_path, monkeypatch):
    p = tmp_path / "bomb.xyz.gz"
    p.write_bytes(gzip_bomb(64))
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "16M")
    line = assert_error(p, "memory cap of 16.0 MiB", "SPECTRAGEO_MAX_BYTES")
    assert "16.0 MiB" in line
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "lots")
    out = run_cli(["info", str(p)])
    assert out.code == 2 and len(out.lines) == 1, out.describe()
    assert "SPECTRAGEO_MAX_BYTES must be a positive size" in out.lines[0]


def test_gzip_members_truncation_and_garbage(tmp_path):
    import gzip

    text = b"0 0 0\n1 0 0\n0 1 0\n"
    two = gzip.compress(text[:6]) + gzip.compress(text[6:])
    (tmp_path / "two.xyz.gz").write_bytes(two)
    assert io.read(tmp_path / "two.xyz.gz").n_points == 3  # concatenated members, as gunzip
    (tmp_path / "cut.xyz.gz").write_bytes(two[:-12])
    (tmp_path / "junk.xyz.gz").write_bytes(two + b"JUNK")
    assert_errors(
        (tmp_path / "cut.xyz.gz", "corrupted or truncated gzip"),
        (tmp_path / "junk.xyz.gz", "trailing garbage"),
    )


# ------------------------------------------------------------------------------------- npy, npz
def npy_bytes(header_shape: str, data: bytes, descr: str = "<f8") -> bytes:
    hdr = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {header_shape}, }}"
    hdr = hdr + " " * (63 - (len(hdr) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(hdr)) + hdr.encode() + data


def test_npy_header_lies(tmp_path):
    data = np.zeros((4, 3)).tobytes()
    # (2**40, 3) float64 = 24 TiB
    (tmp_path / "tib.npy").write_bytes(npy_bytes("(1099511627776, 3)", data))
    (tmp_path / "neg.npy").write_bytes(npy_bytes("(-1, 3)", data))
    (tmp_path / "big.npy").write_bytes(npy_bytes("(99999999999999999999, 3)", data))
    (tmp_path / "few.npy").write_bytes(npy_bytes("(3, 3)", data))
    assert_errors(
        (tmp_path / "tib.npy", "(1099511627776, 3)", "truncated"),
        (tmp_path / "neg.npy", "not a valid .npy array"),
        (tmp_path / "big.npy", "not a valid .npy array"),
        (tmp_path / "few.npy", "disagrees with the data"),
    )


def test_npz_member_header_lies(tmp_path):
    import zipfile

    V, F = icosphere(0)
    frames = np.stack([V, V])
    buf = _io.BytesIO()
    np.save(buf, F.astype(np.int32))
    with zipfile.ZipFile(tmp_path / "lie.npz", "w") as z:
        z.writestr("vertices.npy", npy_bytes("(2, 1099511627776, 3)", frames.tobytes()))
        z.writestr("faces.npy", buf.getvalue())
    with zipfile.ZipFile(tmp_path / "names.npz", "w") as z:  # names inside the file: one line
        z.writestr("line\nbreak.npy", buf.getvalue())
    assert_errors(
        (tmp_path / "lie.npz", "cannot read array 'vertices'", "truncated"),
        (tmp_path / "names.npz", ".npz has keys", "line\\nbreak"),
    )


def test_face_index_beyond_int64_is_named_as_written(tmp_path):
    big = "9223372036854775808"
    (tmp_path / "i.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {big}\n")
    (tmp_path / "i.off").write_text(f"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 {big}\n")
    V, F = icosphere(0)
    Fu = F.astype(np.uint64)
    Fu[0, 0] = 2**63
    np.savez(tmp_path / "u.npz", vertices=np.stack([V, V]), faces=Fu)
    lines = assert_errors(*((tmp_path / name, big) for name in ("i.obj", "i.off", "u.npz")))
    assert not any("-9223372036854775808" in line for line in lines)


# --------------------------------------------------------------------------------- OFF and PLY
def test_off_zero_faces_with_face_lines(tmp_path):
    V, F = icosphere(3)
    body = "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V)
    faces = "".join(f"3 {a} {b} {c}\n" for a, b, c in F[:446])
    (tmp_path / "zero.off").write_text(f"OFF\n{len(V)} 0 0\n{body}{faces}")
    assert_error(tmp_path / "zero.off", "0 faces", "446 more line(s)")


def _ascii_ply(n_decl: int, V, F, list_type="uchar") -> str:
    head = (
        f"ply\nformat ascii 1.0\nelement vertex {n_decl}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(F)}\nproperty list {list_type} int vertex_indices\n"
        "end_header\n"
    )
    return (
        head
        + "".join(f"{x} {y} {z}\n" for x, y, z in V)
        + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in F)
    )


def test_ply_vertex_count_minus_one(tmp_path):
    V, F = icosphere(1)
    (tmp_path / "nm1.ply").write_text(_ascii_ply(len(V) - 1, V, F))
    assert_error(tmp_path / "nm1.ply", "1 more non-empty line(s)", f"vertex {len(V) - 1}")


def test_ply_list_length_overflows_uchar(tmp_path):
    V = np.random.default_rng(0).random((300, 3))
    big_face = [list(range(300))]
    (tmp_path / "len300.ply").write_text(_ascii_ply(300, V, big_face))
    text = _ascii_ply(3, V[:3], [[0, 1, 2]]).replace("\n3 0 1 2\n", "\n-1 0 1 2\n")
    (tmp_path / "lenneg.ply").write_text(text)
    assert_errors(
        (tmp_path / "len300.ply", "list length 300", "vertex_indices", "uint8"),
        (tmp_path / "lenneg.ply", "list length -1"),
    )


def test_ply_face_property_not_a_list_and_bad_counts(tmp_path):
    head = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n0\n"
    )
    (tmp_path / "scalar.ply").write_text(head)
    cases = [(tmp_path / "scalar.ply", "'vertex_indices' must be a list")]
    V, F = icosphere(0)
    for count, pat in ((-1, "count must be >= 0; got -1"), (2**31, "truncated PLY")):
        text = _ascii_ply(len(V), V, F).replace(f"element face {len(F)}", f"element face {count}")
        (tmp_path / f"c{count}.ply").write_text(text)
        cases.append((tmp_path / f"c{count}.ply", pat))
    binary = _binary_ply_header(2**31) + np.zeros(9, "<f4").tobytes()
    (tmp_path / "b.ply").write_bytes(binary)
    cases.append((tmp_path / "b.ply", "truncated PLY", "2147483648 rows"))
    assert_errors(*cases)


def _binary_ply_header(n: int) -> bytes:
    return (
        "ply\nformat binary_little_endian 1.0\nelement vertex "
        f"{n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()


# ---------------------------------------------------------------------- denoise: 1e300 vertex
def test_denoise_tsgsp_rejects_a_1e300_vertex(tmp_path):
    V, F = icosphere(3)
    V = V.copy()
    V[0] = [1e300, 0.0, 0.0]
    src = tmp_path / "far.off"
    src.write_text(
        f"OFF\n{len(V)} {len(F)} 0\n"
        + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in V.tolist())
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in F.tolist())
    )
    out_file = tmp_path / "out.off"
    for extra in ([], ["--no-weld"]):
        line = assert_error(
            src,
            "`vertices`",
            "1e+150",
            args=("denoise", "--method", "tsgsp"),
            extra=(str(out_file), *extra),
        )
        assert "1e+300" in line
        assert not out_file.exists()


def test_kernel_and_validation_guards():
    from spectrageo._validation import as_points
    from spectrageo.denoise import _tsgsp_kernels as tsgsp

    with pytest.raises(InvalidInputError, match=r"`V` has coordinates of magnitude above 1e\+150"):
        as_points(np.array([[1e300, 0, 0], [0, 0, 0]]))
    as_points(np.array([[1e149, -1e150, 0.0]]))  # the bound itself is accepted
    nb = np.array([[0, 1], [1, 2], [2, 0]])
    indptr, cand = tsgsp._inverse_patches(nb)
    assert indptr.tolist() == [0, 2, 4, 6]
    bad = np.array([[0, 3], [1, 2], [2, 0]])  # 3 = the kNN "missing neighbour" sentinel
    with pytest.raises(InvalidInputError, match=r"`nb` .* must hold face indices in \[0, 3\)"):
        tsgsp._inverse_patches(bad)
    _, _, ok = tsgsp._inverse_kernel(bad)  # the compiled kernel refuses it too, writes nothing
    assert not ok
    _, _, ok = tsgsp._inverse_kernel(np.array([[0, -1], [1, 2], [2, 0]]))
    assert not ok


# ------------------------------------------------------------------------------ error handling
def test_memory_error_becomes_invalid_input(tmp_path, monkeypatch):
    from spectrageo.io import _simple

    p = tmp_path / "m.xyz"
    p.write_text("0 0 0\n")

    def boom(raw, name):
        raise MemoryError("Unable to allocate 24.0 TiB")

    monkeypatch.setattr(_simple, "read_xyz", boom)
    with pytest.raises(InvalidInputError, match="m.xyz: not enough memory to read this file"):
        io.read(p)


def test_max_bytes_setting(monkeypatch):
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "16G")
    assert _common.max_bytes() == 16 * 1024**3
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "1000")
    assert _common.max_bytes() == 1000
    with pytest.raises(InvalidInputError, match="x.ply: PLY 'vertex' needs 2.0 KiB, more than"):
        _common.check_alloc(2048, "x.ply", "PLY 'vertex'")
    for bad in ("-5", "0", "8 apples"):
        monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", bad)
        with pytest.raises(InvalidInputError, match="SPECTRAGEO_MAX_BYTES must be a positive"):
            _common.max_bytes()
    monkeypatch.delenv("SPECTRAGEO_MAX_BYTES")
    assert 0 < _common.max_bytes() <= 8 * 1024**3


def test_library_warnings_do_not_leak_and_repairs_follow_success(tmp_path, recwarn):
    # a float colour cast and loadtxt's "no data" warning used to reach stderr before the error
    (tmp_path / "w.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nend_header\n0 0 1e999 300\n"
    )
    with pytest.raises(InvalidInputError):
        io.read(tmp_path / "w.ply")
    assert not [w for w in recwarn if not issubclass(w.category, DeprecationWarning)]


def test_fifo_input_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "pipe.ply"
    os.mkfifo(fifo)
    assert_error(fifo, "not a regular file")


# -------------------------------------------------------------------------------- atomic writes
@pytest.fixture
def small_mesh():
    V, F = icosphere(0)
    return Mesh(V, F)


def test_write_keeps_the_mode_of_an_existing_target(tmp_path, small_mesh):
    target = tmp_path / "m.ply"
    target.write_bytes(b"old")
    os.chmod(target, 0o640)
    io.write(target, small_mesh)
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert io.read(target).n_vertices == small_mesh.n_vertices


def test_write_refuses_a_fifo(tmp_path, small_mesh):
    fifo = tmp_path / "out.ply"
    os.mkfifo(fifo)
    with pytest.raises(InvalidInputError, match="is a FIFO"):
        io.write(fifo, small_mesh)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    src = tmp_path / "in.ply"
    io.write(src, small_mesh)
    out = run_cli(["convert", str(src), str(fifo)])
    assert out.code == 2 and len(out.lines) == 1 and "FIFO" in out.lines[0], out.describe()


def test_write_through_a_symlink(tmp_path, small_mesh):
    real = tmp_path / "data" / "real.ply"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.ply"
    link.symlink_to(real)
    io.write(link, small_mesh)
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert io.read(real).n_vertices == small_mesh.n_vertices
    assert sorted(os.listdir(real.parent)) == ["real.ply"]


def test_write_to_a_read_only_target_is_an_error(tmp_path, small_mesh):
    target = tmp_path / "ro.ply"
    target.write_bytes(b"keep")
    os.chmod(target, 0o444)
    with pytest.raises(InvalidInputError, match="ro.ply: the file is read-only"):
        io.write(target, small_mesh)
    assert target.read_bytes() == b"keep"
    src = tmp_path / "in.ply"
    io.write(src, small_mesh)
    out = run_cli(["convert", str(src), str(target)])
    assert out.code == 2 and len(out.lines) == 1 and "read-only" in out.lines[0], out.describe()


def test_temporaries_are_named_and_stale_ones_removed(tmp_path, small_mesh):
    target = tmp_path / "m.ply"
    seen = []
    with pytest.raises(RuntimeError):
        with io.atomic_write(target) as tmp:
            seen.append(tmp.name)
            raise RuntimeError("killed")
    assert seen[0].startswith(".m.ply.spectrageo-tmp-") and seen[0].endswith(".ply")
    # leftovers of killed writes: an old one is removed on the next write, a fresh one is kept
    old = tmp_path / ".m.ply.spectrageo-tmp-deadbeef.ply"
    fresh = tmp_path / ".m.ply.spectrageo-tmp-cafe.ply"
    other = tmp_path / ".other.ply.spectrageo-tmp-0000.ply"
    for f in (old, fresh, other):
        f.write_bytes(b"partial")
    past = time.time() - 2 * 3600
    os.utime(old, (past, past))
    os.utime(other, (past, past))
    io.write(target, small_mesh)
    assert not old.exists() and fresh.exists() and other.exists()


def test_coordinates_too_small_to_measure_are_refused(tmp_path):
    """A model at 1e-300 scale: its squared lengths underflow, so `info` reported a mean edge
    length of 0 and `noise` returned it unchanged. It is refused like coordinates above 1e150;
    a single point or coincident points (extent 0) and small real scales are accepted."""
    from spectrageo._validation import MIN_EXTENT, as_points

    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="spans only 2e-300"):
        as_points(V * 1e-300)
    as_points(V * 1e-60)  # well above MIN_EXTENT: accepted
    as_points(np.zeros((5, 3)))
    as_points(np.ones((1, 3)) * 1e-300)
    assert MIN_EXTENT == 1e-70
    with pytest.raises(InvalidInputError, match="Rescale"):  # nor written
        io.write(tmp_path / "t.off", Mesh(V * 1e-300, F))
    lines = ["OFF", f"{len(V)} {len(F)} 0"]
    lines += [" ".join(f"{x:.17g}" for x in v) for v in V * 1e-300]
    lines += ["3 " + " ".join(str(i) for i in f) for f in F]
    (tmp_path / "tiny.off").write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidInputError, match="Rescale"):
        io.read(tmp_path / "tiny.off")
