"""Seeded fuzzing of every reader: mutated files must give a result or one clear error line.

For each format a few hundred mutants of small seed files (synthetic ones, plus real files from the
shared data when present) are made with a fixed seed: bit flips, overwritten byte runs,
truncations, duplicated chunks and edits of the numbers of the header (counts set to 0, -1, 2^31,
2^32-1, n+1, n-1 or huge). Every mutant is read by ``spectrageo info FILE --json`` in a subprocess
limited to 4 GiB of address space; the run must end with exit 0 and valid JSON, or exit 2 with
exactly one line on stderr, within 20 s, never with exit 1 (internal error) or a signal.

To keep CI time low, one child process reads a batch of mutants in sequence through a small driver
that calls :func:`spectrageo.cli.main.main` per file and records the exit code and the stderr lines
(Python's and the file descriptor's, so native messages count). When a batch dies (signal, or a
native hang past the batch timeout), the file it was reading is run alone through the real command
line to name the culprit, and the rest of the batch goes on in a new process.

Environment: ``SPECTRAGEO_FUZZ_N`` (mutants per format, default 300), ``SPECTRAGEO_FUZZ_SEED``,
``SPECTRAGEO_FUZZ_REPORT`` (a path: append per-format outcome counts as JSON lines).
"""

from __future__ import annotations

import gzip
import io
import json
import os
import re
import struct
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from _cli_limits import (
    TIME_LIMIT,
    Outcome,
    child_env,
    contract_violation,
    limit_resources,
    run_cli,
)

from conftest import icosphere, optional_shared_data

N_MUTANTS = int(os.environ.get("SPECTRAGEO_FUZZ_N", "300"))
SEED = int(os.environ.get("SPECTRAGEO_FUZZ_SEED", "20240611"))
BATCH_TIMEOUT = 150.0
N_WORKERS = 2

FORMATS = (
    "ply_ascii",
    "ply_binary",
    "obj",
    "off",
    "stl",
    "pcd_ascii",
    "pcd_binary",
    "pcd_compressed",
    "xyz",
    "npy",
    "npz",
    "las",
    "laz",
    "gz",
)

# ----------------------------------------------------------------------------------- the driver
DRIVER = r"""
import contextlib, io, json, os, signal, sys, tempfile, time

class _Timeout(BaseException):
    pass

def _alarm(signum, frame):
    raise _Timeout()

signal.signal(signal.SIGALRM, _alarm)
from spectrageo.cli.main import main

log = open(sys.argv[1], "a", buffering=1)
files = open(sys.argv[2]).read().splitlines()
limit = int(sys.argv[3])
cap = tempfile.TemporaryFile()
for f in files:
    log.write(json.dumps({"start": f}) + "\n")
    log.flush()
    out, err = io.StringIO(), io.StringIO()
    cap.seek(0)
    cap.truncate()
    saved = os.dup(2)
    os.dup2(cap.fileno(), 2)  # native code writing to fd 2 counts as stderr too
    t0 = time.perf_counter()
    signal.alarm(limit)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["info", f, "--json"])
    except _Timeout:
        code = None
    except SystemExit as exc:
        code = exc.code
    except BaseException as exc:
        code = "raised " + type(exc).__name__ + ": " + str(exc)[:200]
    finally:
        signal.alarm(0)
        dt = time.perf_counter() - t0
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
    cap.seek(0)
    native = cap.read().decode("utf-8", "replace")
    lines = [ln for ln in (err.getvalue() + native).splitlines() if ln.strip()]
    log.write(json.dumps({"file": f, "code": code, "lines": lines[:5], "n_lines": len(lines),
                          "stdout": out.getvalue() if code == 0 else "", "seconds": dt}) + "\n")
    log.flush()
"""


def _run_batch(files: list[str], workdir: Path, tag: str) -> dict[str, Outcome]:
    """Outcomes of ``info --json`` on ``files``; batches that die are continued in new processes."""
    driver = workdir / "driver.py"
    if not driver.exists():
        driver.write_text(DRIVER)
    results: dict[str, Outcome] = {}
    todo = list(files)
    k = 0
    while todo:
        k += 1
        log = workdir / f"{tag}-{k}.log"
        lst = workdir / f"{tag}-{k}.txt"
        lst.write_text("\n".join(todo))
        try:
            subprocess.run(
                [sys.executable, str(driver), str(log), str(lst), str(int(TIME_LIMIT))],
                capture_output=True,
                timeout=BATCH_TIMEOUT,
                preexec_fn=limit_resources,
                env=child_env(),
            )
        except subprocess.TimeoutExpired:
            pass
        started = None
        for line in log.read_text().splitlines() if log.exists() else []:
            rec = json.loads(line)
            if "start" in rec:
                started = rec["start"]
                continue
            started = None
            out = Outcome(rec["code"], rec["lines"], rec["stdout"], rec["seconds"])
            if rec["n_lines"] != len(rec["lines"]):
                out.lines = out.lines + ["..."] * (rec["n_lines"] - len(rec["lines"]))
            results[rec["file"]] = out
        todo = [f for f in todo if f not in results]
        if started is not None:
            # the batch died on this file: run it alone through the real command line
            results[started] = run_cli(["info", started, "--json"])
            todo = [f for f in todo if f != started]
        elif todo:  # died before starting any further file (e.g. at import): run one alone
            results[todo[0]] = run_cli(["info", todo[0], "--json"])
            todo = todo[1:]
    return results


# ---------------------------------------------------------------------------------------- seeds
def _mesh_parts():
    V, F = icosphere(1)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    C = (np.abs(N) * 255).astype(np.uint8)
    return V, F, N, C


def _written(tmp: Path, name: str, obj, **kw) -> bytes:
    from spectrageo import io as sio

    p = tmp / name
    sio.write(p, obj, **kw)
    return p.read_bytes()


_CUBE_V = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n"
_CUBE_QUADS = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]


def _ply_mixed_ascii() -> bytes:
    faces = [f"4 {a} {b} {c} {d}" for a, b, c, d in _CUBE_QUADS[:4]]
    faces += ["3 2 3 7", "3 2 7 6", "3 3 0 4", "3 3 4 7"]
    head = (
        "ply\nformat ascii 1.0\ncomment mixed polygons\nelement vertex 8\nproperty float x\n"
        "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
        "property uchar blue\nelement face 8\nproperty list uchar int vertex_indices\n"
        "property float quality\nend_header\n"
    )
    verts = "".join(f"{ln} 10 200 30\n" for ln in _CUBE_V.splitlines())
    return (head + verts + "".join(f"{f} 0.5\n" for f in faces)).encode()


def _ply_mixed_binary(big_endian: bool) -> bytes:
    bo = ">" if big_endian else "<"
    head = (
        f"ply\nformat binary_{'big' if big_endian else 'little'}_endian 1.0\nelement vertex 8\n"
        "property float x\nproperty float y\nproperty float z\nelement face 8\n"
        "property list uchar int vertex_indices\nelement tristrips 1\n"
        "property list int int vertex_indices\nend_header\n"
    ).encode()
    V = np.array([[float(t) for t in ln.split()] for ln in _CUBE_V.splitlines()])
    body = V.astype(bo + "f4").tobytes()
    faces = [list(q) for q in _CUBE_QUADS[:4]] + [[2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    for f in faces:
        body += struct.pack(bo + "B", len(f)) + np.asarray(f, dtype=bo + "i4").tobytes()
    strip = [0, 1, 3, 2, -1, 4, 5, 7, 6]
    body += struct.pack(bo + "i", len(strip)) + np.asarray(strip, dtype=bo + "i4").tobytes()
    return head + body


def _obj_rich() -> bytes:
    lines = [
        "# cube with texture coordinates and normals",
        "mtllib none.mtl",
        "o cube",
    ]
    lines += [f"v {ln}" for ln in _CUBE_V.splitlines()]
    lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1"]
    lines += ["vn 0 0 -1", "vn 0 0 1", "vn 0 -1 0", "vn 1 0 0", "vn 0 1 0", "vn -1 0 0"]
    lines.append("g sides\ns 1")
    for i, q in enumerate(_CUBE_QUADS):
        lines.append("f " + " ".join(f"{a + 1}/{j + 1}/{i + 1}" for j, a in enumerate(q)))
    lines.append("l 1 2")
    lines.append("f -1 -2 -3")
    return ("\n".join(lines) + "\n").encode()


def _off_color() -> bytes:
    verts = "".join(f"{ln} 255 0 0\n" for ln in _CUBE_V.splitlines())
    faces = "".join(f"4 {a} {b} {c} {d}\n" for a, b, c, d in _CUBE_QUADS)
    return f"COFF\n# colored cube\n8 6 12\n{verts}{faces}".encode()


def _cloud(rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    P = rng.normal(size=(150, 3)) * [1.0, 2.0, 0.5]
    N = rng.normal(size=(150, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    C = rng.integers(0, 256, size=(150, 3)).astype(np.uint8)
    return P, N, C


def _xyz_seeds(rng) -> list[tuple[str, bytes]]:
    P, N, C = _cloud(rng)
    buf = io.StringIO()
    buf.write("X Y Z R G B Intensity\n")
    for p, c in zip(P, C):
        buf.write(f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {c[0]} {c[1]} {c[2]} {rng.random():.3f}\n")
    plain = "".join(
        f"{p[0]:.9g} {p[1]:.9g} {p[2]:.9g} {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}\n" for p, n in zip(P, N)
    )
    csv = "//X,Y,Z\n" + "".join(f"{p[0]:.5f},{p[1]:.5f},{p[2]:.5f}\n" for p in P)
    return [(".xyz", buf.getvalue().encode()), (".xyz", plain.encode()), (".xyz", csv.encode())]


def _las_bytes(P, C, *, version: str, point_format: int, compressed: bool) -> bytes:
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(P.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    if C is not None and "red" in las.point_format.dimension_names:
        c16 = C.astype(np.uint16) * 257
        las.red, las.green, las.blue = c16[:, 0], c16[:, 1], c16[:, 2]
    las.intensity = np.arange(P.shape[0], dtype=np.uint16)
    buf = io.BytesIO()
    las.write(buf, do_compress=compressed)
    return buf.getvalue()


def _real_las_subset(shared: Path | None, n: int, compressed: bool) -> list[tuple[str, bytes]]:
    laspy = pytest.importorskip("laspy")
    if shared is None:
        return []
    src = shared / "scans" / "lidar" / "autzen_trim.laz"
    if not src.exists():
        return []
    las = laspy.read(src)
    sub = laspy.LasData(las.header)
    sub.points = las.points[:n].copy()
    buf = io.BytesIO()
    sub.write(buf, do_compress=compressed)
    return [(".laz" if compressed else ".las", buf.getvalue())]


def build_seeds(fmt: str, tmp: Path, shared: Path | None) -> list[tuple[str, bytes]]:
    """``(suffix, bytes)`` seed files of one fuzz format."""
    from spectrageo.geometry import Mesh, PointCloud

    rng = np.random.default_rng(7)
    V, F, N, C = _mesh_parts()
    mesh = Mesh(V, F, vertex_normals=N, vertex_colors=C)
    P, PN, PC = _cloud(rng)
    cloud = PointCloud(P, PN, PC, {"intensity": rng.random(P.shape[0]).astype(np.float32)})
    real = (lambda *parts: shared.joinpath(*parts)) if shared is not None else None

    def real_file(*parts) -> list[tuple[str, bytes]]:
        if real is None or not real(*parts).exists():
            return []
        p = real(*parts)
        return [(p.suffix.lower(), p.read_bytes())]

    if fmt == "ply_ascii":
        return [(".ply", _written(tmp, "a.ply", mesh, binary=False)), (".ply", _ply_mixed_ascii())]
    if fmt == "ply_binary":
        return [
            (".ply", _written(tmp, "b.ply", mesh)),
            (".ply", _written(tmp, "c.ply", cloud)),
            (".ply", _ply_mixed_binary(False)),
            (".ply", _ply_mixed_binary(True)),
        ]
    if fmt == "obj":
        return [(".obj", _written(tmp, "a.obj", mesh)), (".obj", _obj_rich())]
    if fmt == "off":
        return [
            (".off", _written(tmp, "a.off", mesh)),
            (".off", _off_color()),
            *real_file("meshes", "joint.off"),
        ]
    if fmt == "stl":
        return [
            (".stl", _written(tmp, "a.stl", mesh)),
            (".stl", _written(tmp, "b.stl", mesh, binary=False)),
            *real_file("cad", "angle_block.STL"),
        ]
    if fmt.startswith("pcd"):
        enc = {"pcd_ascii": "ascii", "pcd_binary": "binary", "pcd_compressed": "binary_compressed"}
        seeds = [(".pcd", _written(tmp, "a.pcd", cloud, pcd_format=enc[fmt]))]
        if fmt == "pcd_compressed":
            seeds += real_file("scans", "pcl", "noisy_slice_displaced.pcd")
        return seeds
    if fmt == "xyz":
        return _xyz_seeds(rng)
    if fmt == "npy":
        out = []
        for a in (P, P.astype(np.float32), np.round(P * 100).astype(np.int32)):
            b = io.BytesIO()
            np.save(b, a)
            out.append((".npy", b.getvalue()))
        return out
    if fmt == "npz":
        frames = np.stack([V, V * 1.1, V * 0.9])
        a, b = io.BytesIO(), io.BytesIO()
        np.savez(a, vertices=frames, faces=F.astype(np.int32))
        np.savez_compressed(b, points=P, counts=np.array([50, 100]))
        return [(".npz", a.getvalue()), (".npz", b.getvalue())]
    if fmt == "las":
        return [
            (".las", _las_bytes(P * 10, PC, version="1.2", point_format=3, compressed=False)),
            (".las", _las_bytes(P * 10, PC, version="1.4", point_format=7, compressed=False)),
            *_real_las_subset(shared, 1500, compressed=False),
        ]
    if fmt == "laz":
        return [
            (".laz", _las_bytes(P * 10, PC, version="1.2", point_format=3, compressed=True)),
            (".laz", _las_bytes(P * 10, None, version="1.4", point_format=6, compressed=True)),
            *_real_las_subset(shared, 3000, compressed=True),
            *real_file("scans", "lidar", "autzen_trim.laz"),
        ]
    if fmt == "gz":
        return [
            (".ply.gz", gzip.compress(_written(tmp, "g.ply", mesh), mtime=0)),
            (".xyz.gz", gzip.compress(_xyz_seeds(rng)[1][1], mtime=0)),
            (".off.gz", gzip.compress(_off_color(), mtime=0)),
            (".pcd.gz", gzip.compress(_written(tmp, "g.pcd", cloud), mtime=0)),
        ]
    raise AssertionError(fmt)


# ------------------------------------------------------------------------------------ mutations
_INTERESTING = ("0", "-1", str(2**31), str(2**32 - 1), str(2**63), "99999999999999999999")


def _count_values(n: int) -> list[str]:
    return [*_INTERESTING, str(n + 1), str(max(n - 1, 0)), str(n * 1000 + 7)]


def _text_header_end(data: bytes, fmt: str) -> int:
    if fmt.startswith("ply"):
        i = data.find(b"end_header")
        return i if i >= 0 else min(len(data), 512)
    if fmt.startswith("pcd"):
        i = data.find(b"DATA")
        return i if i >= 0 else min(len(data), 512)
    if fmt == "npy":
        return min(len(data), 128)
    return min(len(data), 2048)


def _edit_text_number(data: bytes, fmt: str, rng) -> tuple[bytes, str]:
    end = _text_header_end(data, fmt)
    nums = list(re.finditer(rb"-?\d+(\.\d+)?(e[-+]?\d+)?", data[:end]))
    if not nums:
        return _bitflip(data, rng)
    m = nums[int(rng.integers(len(nums)))]
    try:
        n = int(float(m.group()))
    except (ValueError, OverflowError):
        n = 1
    if "." in m.group().decode() and rng.random() < 0.5:
        new = str(rng.choice(["0", "1e300", "nan", "inf", "-1e-300"]))
    else:
        new = str(rng.choice(_count_values(n)))
    desc = f"header number {m.group().decode()!r} at {m.start()} -> {new}"
    return data[: m.start()] + new.encode() + data[m.end() :], desc


# LAS header fields: (offset, struct format, name); LAS 1.4 adds the 64-bit counts
_LAS_FIELDS = (
    (24, "B", "version_major"),
    (25, "B", "version_minor"),
    (94, "H", "header_size"),
    (96, "I", "offset_to_points"),
    (100, "I", "n_vlrs"),
    (104, "B", "point_format"),
    (105, "H", "record_length"),
    (107, "I", "legacy_point_count"),
    (111, "I", "legacy_count_return_1"),
    (131, "d", "x_scale"),
    (139, "d", "y_scale"),
    (155, "d", "x_offset"),
    (179, "d", "max_x"),
    (235, "Q", "evlr_start"),
    (243, "I", "n_evlrs"),
    (247, "Q", "point_count_14"),
)


def _edit_las(data: bytes, rng) -> tuple[bytes, str]:
    fields = list(_LAS_FIELDS)
    minor = data[25] if len(data) > 25 else 2
    hsize = struct.unpack_from("<H", data, 94)[0] if len(data) >= 96 else 227
    if minor < 4:
        fields = [f for f in fields if f[0] < 227]
    if len(data) >= hsize + 54 and rng.random() < 0.2:  # the first VLR's record length
        off = hsize + 20
        val = int(rng.choice([0, 1, 54, 65535, 1000]))
        buf = bytearray(data)
        struct.pack_into("<H", buf, off, val)
        return bytes(buf), f"first VLR record_length -> {val}"
    off, fmtc, name = fields[int(rng.integers(len(fields)))]
    if off + struct.calcsize(fmtc) > len(data):
        return _truncate(data, rng)
    old = struct.unpack_from("<" + fmtc, data, off)[0]
    if fmtc == "d":
        val = float(rng.choice([0.0, -1.0, 1e300, np.nan, np.inf, 1e-300, 2 * old if old else 1.0]))
    else:
        bits = 8 * struct.calcsize(fmtc)
        cands = [0, 1, 2**bits - 1, 2 ** (bits - 1), old + 1, max(old - 1, 0), old * 2, old + 100]
        val = int(rng.choice(cands)) % (2**bits)
    buf = bytearray(data)
    struct.pack_into("<" + fmtc, buf, off, val)
    return bytes(buf), f"LAS {name} {old} -> {val}"


def _edit_binary_count(data: bytes, fmt: str, suffix: str, rng) -> tuple[bytes, str] | None:
    buf = bytearray(data)
    if fmt == "stl" and len(data) >= 84 and not data.startswith(b"solid"):
        old = struct.unpack_from("<I", data, 80)[0]
        val = int(rng.choice([0, 2**32 - 1, 2**31, old + 1, old - 1, old * 100]))
        struct.pack_into("<I", buf, 80, val % 2**32)
        return bytes(buf), f"STL triangle count {old} -> {val}"
    if fmt == "pcd_compressed":
        i = data.find(b"DATA binary_compressed")
        j = data.find(b"\n", i) + 1
        if i >= 0 and j + 8 <= len(data):
            k = int(rng.integers(2))
            old = struct.unpack_from("<I", data, j + 4 * k)[0]
            val = int(rng.choice([0, 2**32 - 1, 2**31, old + 1, old - 1, old * 1000]))
            struct.pack_into("<I", buf, j + 4 * k, val % 2**32)
            return bytes(buf), f"PCD {'usize' if k else 'csize'} {old} -> {val}"
    if fmt in ("las", "laz"):
        return _edit_las(data, rng)
    if fmt == "gz" and len(data) > 18:
        old = struct.unpack_from("<I", data, len(data) - 4)[0]
        val = int(rng.choice([0, 2**32 - 1, old + 1, old - 1]))
        struct.pack_into("<I", buf, len(data) - 4, val % 2**32)
        return bytes(buf), f"gzip ISIZE {old} -> {val}"
    if fmt == "npz":
        hits = [m.start() for m in re.finditer(rb"'shape': \(", data)]
        if hits:
            pos = hits[int(rng.integers(len(hits)))]
            m = re.compile(rb"\d+").search(data, pos)
            new = str(rng.choice(_count_values(int(m.group())))).encode()
            return data[: m.start()] + new + data[m.end() :], f"npz member shape -> {new.decode()}"
    return None


def _bitflip(data: bytes, rng) -> tuple[bytes, str]:
    buf = bytearray(data)
    k = int(rng.integers(1, 9))
    where = []
    for _ in range(k):
        hi = min(len(buf), 1024) if rng.random() < 0.5 else len(buf)
        i = int(rng.integers(hi))
        buf[i] ^= 1 << int(rng.integers(8))
        where.append(i)
    return bytes(buf), f"{k} bit flips at {sorted(where)[:4]}"


def _byterun(data: bytes, rng) -> tuple[bytes, str]:
    buf = bytearray(data)
    L = int(min(len(buf), 2 ** rng.uniform(0, 8)))
    i = int(rng.integers(len(buf) - L + 1))
    kind = int(rng.integers(3))
    fill = bytes(L) if kind == 0 else b"\xff" * L if kind == 1 else rng.bytes(L)
    buf[i : i + L] = fill
    return bytes(buf), f"{L} bytes {('zero', 'ff', 'random')[kind]} at {i}"


def _truncate(data: bytes, rng) -> tuple[bytes, str]:
    hi = min(len(data), 1024) if rng.random() < 0.4 else len(data)
    n = int(rng.integers(1, max(hi, 2)))
    return data[:n], f"truncated to {n} of {len(data)} bytes"


def _duplicate(data: bytes, rng) -> tuple[bytes, str]:
    L = int(max(1, min(len(data) // 2, 2 ** rng.uniform(0, 16))))
    a = int(rng.integers(len(data) - L + 1))
    b = a + L if rng.random() < 0.5 else int(rng.integers(len(data) + 1))
    return data[:b] + data[a : a + L] + data[b:], f"chunk [{a}, {a + L}) duplicated at {b}"


_TEXT_HEADERS = (
    "ply_ascii",
    "ply_binary",
    "obj",
    "off",
    "pcd_ascii",
    "pcd_binary",
    "pcd_compressed",
    "xyz",
    "npy",
)


def mutate(data: bytes, fmt: str, suffix: str, rng) -> tuple[bytes, str]:
    """One mutant of ``data`` and a description of the mutation."""
    if fmt == "gz" and rng.random() < 0.4:  # mutate the content, then compress it again
        inner, desc = mutate(gzip.decompress(data), suffix.split(".")[1], suffix[:-3], rng)
        return gzip.compress(inner, mtime=0), "content: " + desc
    op = rng.random()
    if op < 0.3:
        edited = _edit_binary_count(data, fmt, suffix, rng)
        if edited is None or (fmt in _TEXT_HEADERS and rng.random() < 0.5):
            return _edit_text_number(data, fmt, rng)
        return edited
    if op < 0.5:
        return _bitflip(data, rng)
    if op < 0.65:
        return _byterun(data, rng)
    if op < 0.82:
        return _truncate(data, rng)
    return _duplicate(data, rng)


# ---------------------------------------------------------------------------------------- tests
def _summary(fmt: str, outcomes: dict[str, Outcome], descs: dict[str, str]) -> dict:
    counts = {"ok": 0, "error": 0}
    bad = []
    for f, out in outcomes.items():
        v = contract_violation(out)
        if v is None:
            counts["ok" if out.code == 0 else "error"] += 1
        else:
            counts[v] = counts.get(v, 0) + 1
            bad.append(f"{Path(f).name} [{descs[f]}]: {v}; {out.describe()}")
    return {"format": fmt, "n": len(outcomes), "counts": counts, "violations": sorted(bad)}


@pytest.mark.parametrize("fmt", FORMATS)
def test_fuzz_reader(fmt, tmp_path):
    if fmt in ("las", "laz"):
        pytest.importorskip("laspy")
        if fmt == "laz":
            pytest.importorskip("lazrs")
    shared = optional_shared_data()  # real seed files when present (always under CI=true)
    seeds = build_seeds(fmt, tmp_path, shared)
    rng = np.random.default_rng([SEED, FORMATS.index(fmt)])
    files, descs = [], {}
    for i in range(N_MUTANTS):
        k = int(rng.integers(len(seeds)))
        suffix, data = seeds[k]
        mutant, desc = mutate(data, fmt, suffix, rng)
        p = tmp_path / f"m{i:04d}_s{k}{suffix}"
        p.write_bytes(mutant)
        files.append(str(p))
        descs[str(p)] = f"seed {k}: {desc}"
    chunks = [files[w::N_WORKERS] for w in range(N_WORKERS)]
    with ThreadPoolExecutor(N_WORKERS) as pool:
        parts = list(
            pool.map(lambda wc: _run_batch(wc[1], tmp_path, f"w{wc[0]}"), enumerate(chunks))
        )
    outcomes = {k: v for part in parts for k, v in part.items()}
    assert len(outcomes) == len(files)
    summary = _summary(fmt, outcomes, descs)
    report = os.environ.get("SPECTRAGEO_FUZZ_REPORT")
    if report:
        with open(report, "a") as fh:
            fh.write(json.dumps(summary) + "\n")
    assert not summary["violations"], (
        f"{len(summary['violations'])} of {len(files)} {fmt} mutants broke the contract "
        f"({summary['counts']}):\n" + "\n".join(summary["violations"][:25])
    )
    # the mutants are not all rejected: the reader still reads near-intact files
    assert summary["counts"]["ok"] > 0 or fmt in ("gz",)


def test_mutations_are_deterministic():
    rng1, rng2 = np.random.default_rng([SEED, 0]), np.random.default_rng([SEED, 0])
    data = bytes(range(256)) * 8
    assert [mutate(data, "stl", ".stl", rng1) for _ in range(20)] == [
        mutate(data, "stl", ".stl", rng2) for _ in range(20)
    ]


def test_driver_names_a_crashing_file(tmp_path):
    """A batch whose process dies is continued, and the culprit is run alone."""
    good = tmp_path / "ok.xyz"
    good.write_text("0 0 0\n1 0 0\n0 1 0\n")
    sentinel = tmp_path / "crash.xyz"
    sentinel.write_text("0 0 0\n")
    driver = tmp_path / "driver.py"
    # a driver that kills itself on the sentinel, as a native crash would
    driver.write_text(
        DRIVER.replace(
            "    t0 = time.perf_counter()\n",
            "    if f.endswith('crash.xyz'):\n        os.kill(os.getpid(), signal.SIGSEGV)\n"
            "    t0 = time.perf_counter()\n",
            1,
        )
    )
    res = _run_batch([str(good), str(sentinel), str(good) + ".missing.xyz"], tmp_path, "t")
    assert set(res) == {str(good), str(sentinel), str(good) + ".missing.xyz"}
    assert res[str(good)].code == 0
    assert res[str(sentinel)].code == 0  # the real command line reads it fine
    assert res[str(good) + ".missing.xyz"].code == 2
