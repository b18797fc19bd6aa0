"""Issue 53, hostile and wrecked inputs: LAZ counts, zip methods of .npz, huge face indices,
linear-memory welding, outliers at the ends of float64, degenerate meshes in denoise, metrics of
a collapsed result, one policy for point rows without coordinates."""

from __future__ import annotations

import io as _io
import json
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

from spectrageo import InvalidInputError, denoise, io, outliers
from spectrageo.cli.main import main
from spectrageo.geometry import Mesh, merge_duplicate_vertices

from conftest import icosphere

BIG = 2**64


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ------------------------------------------------------------------------------------------ LAZ
def _laz(n: int, fmt: int, version: str) -> bytes:
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    P = np.random.default_rng(n).random((n, 3)) * 10
    header = laspy.LasHeader(point_format=fmt, version=version)
    header.scales, header.offsets = [0.001] * 3, [0.0] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = P.T
    buf = _io.BytesIO()
    las.write(buf, do_compress=True)
    return buf.getvalue()


def _with_count(raw: bytes, n: int) -> bytes:
    r = bytearray(raw)
    if r[25] >= 4:  # LAS 1.4: 64-bit count, legacy count 0 or equal
        struct.pack_into("<Q", r, 247, n)
        if struct.unpack_from("<I", r, 107)[0]:
            struct.pack_into("<I", r, 107, n)
    else:
        struct.pack_into("<I", r, 107, n)
    return bytes(r)


@pytest.mark.parametrize(("fmt", "version"), [(0, "1.2"), (3, "1.2"), (6, "1.4"), (7, "1.4")])
@pytest.mark.parametrize("n", [1, 2, 100, 50001])
def test_laz_header_count_below_the_points_stored_is_refused(tmp_path, fmt, version, n):
    """As for LAS: a LAZ header declaring fewer points than the file holds is an error."""
    raw = _laz(n, fmt, version)
    good = tmp_path / "good.laz"
    good.write_bytes(raw)
    assert io.read(good).n_points == n
    bad = tmp_path / "bad.laz"
    bad.write_bytes(_with_count(raw, n - 1))
    # (one chunk fewer than the table holds when a chunk boundary is crossed)
    with pytest.raises(InvalidInputError, match=rf"bad\.laz: LAZ (header declares {n - 1}|chunk)"):
        io.read(bad)


# ------------------------------------------------------------------------------------------ NPZ
def _npz(method: int) -> bytes:
    buf = _io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_LZMA) as z:
        arr = _io.BytesIO()
        np.save(arr, np.random.default_rng(0).random((2, 5, 3)))
        z.writestr("points.npy", arr.getvalue())
    raw = bytearray(buf.getvalue())
    for sig, at in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # local and central headers
        i = raw.find(sig)
        struct.pack_into("<H", raw, i + at, method)
    return bytes(raw)


def test_npz_lzma_members_read(tmp_path):
    p = tmp_path / "lzma.npz"
    p.write_bytes(_npz(14))
    assert io.read(p).n_frames == 2


@pytest.mark.parametrize("method", [1, 9, 99])
def test_npz_unsupported_zip_method_is_named(tmp_path, capsys, method):
    p = tmp_path / "m.npz"
    p.write_bytes(_npz(method))
    with pytest.raises(InvalidInputError, match=f"zip compression method {method} is not supp"):
        io.read(p)
    known = tmp_path / "known.npy"
    np.save(known, np.ones((2, 5), bool))
    code, _, err = run_cli(capsys, "complete", "--known", known, p, tmp_path / "o.npz")
    assert code == 2 and f"zip compression method {method}" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_npz_corrupted_lzma_data_is_a_clear_error(tmp_path, capsys):
    raw = bytearray(_npz(14))
    i = raw.find(b"PK\x03\x04")
    start = i + 30 + sum(struct.unpack_from("<HH", raw, i + 26))
    raw[start + 4 : start + 40] = bytes(range(36))  # past the LZMA properties: damaged stream
    p = tmp_path / "bad.npz"
    p.write_bytes(bytes(raw))
    with pytest.raises(InvalidInputError, match="bad.npz: cannot read array 'points'"):
        io.read(p)
    known = tmp_path / "known.npy"
    np.save(known, np.ones((2, 5), bool))
    code, _, err = run_cli(capsys, "complete", "--known", known, p, tmp_path / "o.npz")
    assert code == 2 and "bad.npz: cannot read array 'points'" in err and "Traceback" not in err


# --------------------------------------------------------------------------- huge face indices
@pytest.mark.parametrize("index", [BIG, -BIG])
@pytest.mark.parametrize(
    ("suffix", "text", "match"),
    [
        (".off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 {i}\n", r"expected 0\.\.2 .*got -?{a}"),
        (".obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {i}\n", r"index -?{a} is out of range"),
        (
            ".ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 {i}\n",
            r"'vertex_indices' of element 'face' is out of range for int32",
        ),
    ],
)
def test_face_index_beyond_int64_is_a_clear_error(tmp_path, suffix, text, match, index):
    p = tmp_path / f"f{suffix}"
    p.write_text(text.format(i=index))
    with pytest.raises(InvalidInputError, match=match.format(a=abs(index))):
        io.read(p)


# ------------------------------------------------------------------------------------- welding
def _components(V: np.ndarray, tol: float) -> np.ndarray:
    """Reference: connected components of "distance <= tol" from all pairwise distances."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial.distance import cdist

    return connected_components(cdist(V, V) <= tol, directed=False)[1]


def test_weld_groups_equal_the_pairwise_components():
    """Clusters of copies, near-copies and chains: the same groups and first vertices as the
    components of the "closer than tol" graph."""
    rng = np.random.default_rng(7)
    for _ in range(60):
        n = int(rng.integers(2, 300))
        base = rng.random((max(1, n // 4), 3)) * rng.choice([1e-3, 1.0, 1e3])
        V = base[rng.integers(0, base.shape[0], n)]
        near = rng.random((n, 1)) < 0.5
        V = V + rng.normal(size=V.shape) * rng.choice([0.0, 1e-4, 1e-2]) * near
        tol = float(rng.choice([1e-3, 1e-2, 0.1])) * float(np.ptp(V, axis=0).max() + 1e-9)
        Vw, _, index_map = merge_duplicate_vertices(V, np.zeros((0, 3), int), tol=tol)
        ref = _components(V, tol)
        assert np.array_equal(np.unique(np.c_[index_map, ref], axis=0)[:, 0], np.arange(len(Vw)))
        assert len(Vw) == len(np.unique(ref))
        _, first = np.unique(ref, return_index=True)
        np.testing.assert_array_equal(Vw, V[np.sort(first)])


def test_weld_of_identical_triangles_needs_linear_memory(tmp_path):
    """10,000 copies of one triangle (a 500 KB STL): every corner coincides with 9,999 others.
    The pairs of coincident corners (4.5e8) are never formed: peak allocations stay small."""
    rec = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    p = tmp_path / "same.stl"
    p.write_bytes(b"\0" * 80 + struct.pack("<I", 10_000) + rec * 10_000)
    tracemalloc.start()
    try:
        m = io.read(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert m.n_vertices == 3 and m.n_faces == 10_000
    assert peak < 50e6, peak


# ------------------------------------------------------------------------------------ outliers
def test_outliers_coordinate_beyond_the_solver_range_is_named(tmp_path, capsys):
    P = np.vstack([np.random.default_rng(0).random((200, 3)), [[3e38, 0.0, 0.0]]])
    with pytest.raises(InvalidInputError, match=r"spans 3e\+38 \(coordinates from .* to 3e\+38\)"):
        outliers.remove_outliers(P)
    np.savetxt(tmp_path / "big.xyz", P)
    code, _, err = run_cli(capsys, "outliers", tmp_path / "big.xyz", tmp_path / "o.ply")
    assert code == 2 and "spans 3e+38" in err and "Traceback" not in err


def test_outliers_points_closer_than_float64_resolves_are_copies():
    """100 points 1e-312 apart (their squared distances underflow to 0) score as one position,
    with no endless deduplication."""
    P = np.random.default_rng(1).random((300, 3)) - 0.5
    P[:100] = 0.0
    P[:100, 0] = np.arange(100) * 1e-312  # distinct rows, unresolvable distances
    res = outliers.remove_outliers(P, method="rpca")
    scores = np.asarray(res.scores)
    assert np.isfinite(scores).all()
    assert np.ptp(scores[:100]) == 0.0


# -------------------------------------------------------------------------------------- denoise
def test_denoise_of_a_mesh_without_area_stops_before_the_gate(monkeypatch, tmp_path, capsys):
    """Every vertex at one point (and welding off): nothing to filter, returned unchanged before
    the gate, whose kernels would be compiled for it."""
    from spectrageo.denoise import _registry

    def never(*a, **k):
        raise AssertionError("the gate ran on a mesh without area")

    monkeypatch.setattr(_registry, "is_folded", never)
    monkeypatch.setattr(_registry, "noise_estimate", never)
    V = np.ones((20, 3))
    F = np.array([(i, i + 1, i + 2) for i in range(18)])
    for weld in (False, True):
        np.testing.assert_array_equal(denoise.denoise(V, F, weld=weld), V)
    io.write(tmp_path / "point.obj", Mesh(V, F))
    code, _, err = run_cli(
        capsys, "denoise", "--no-weld", tmp_path / "point.obj", tmp_path / "o.obj"
    )
    assert code == 0 and "no face of non-zero area" in err and "unchanged" in err


# -------------------------------------------------------------------------------------- metrics
def test_metrics_measure_a_result_whose_faces_all_collapsed(tmp_path, capsys):
    """Every corner moved to its face's centroid (a soup of points): welding would leave no face,
    yet the comparison with the original is measured (a large Hausdorff distance)."""
    V, F = icosphere(2)
    C = V[F].mean(axis=1)
    io.write(tmp_path / "ref.ply", Mesh(V, F))
    Vs = np.repeat(C, 3, axis=0)
    io.write(tmp_path / "wreck.ply", Mesh(Vs, np.arange(len(Vs)).reshape(-1, 3)))
    code, out, err = run_cli(
        capsys, "metrics", tmp_path / "wreck.ply", tmp_path / "ref.ply", "--json"
    )
    assert code == 0, err
    d = json.loads(out)
    edge = float(np.linalg.norm(V[F[0, 0]] - V[F[0, 1]]))
    assert d["hd_max"] > 0.3 * edge and d["correspondence"] is False


# ------------------------------------------------------------------- rows without coordinates
def test_convert_drops_rows_without_coordinates_like_info_and_outliers(tmp_path, capsys):
    P = np.random.default_rng(0).random((16, 3))
    P[[2, 5, 9]] = np.inf
    src = tmp_path / "inf.xyz"
    np.savetxt(src, P)
    code, _, err = run_cli(capsys, "convert", src, tmp_path / "o.ply")
    assert code == 0 and "3 of 16 rows" in err
    assert io.read(tmp_path / "o.ply").n_points == 13
    code, out, _ = run_cli(capsys, "info", src, "--json")
    assert code == 0 and json.loads(out)["n_vertices"] == 13
