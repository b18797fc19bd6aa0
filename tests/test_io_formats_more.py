"""More valid files users have: upper-case PCD fields, XYZ count lines, PTS, binary OFF, and
structured .npy point arrays (issue 53)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from spectrageo import InvalidInputError, io
from spectrageo.geometry.data import Mesh, PointCloud

P = np.array([[0.5, 1.25, -2.0], [3.0, 4.5, 5.75], [-1.0, 0.0, 2.5], [8.0, -7.25, 6.0]])


# ------------------------------------------------------------------------------- PCD X Y Z
def _pcd_header(fields: str, n: int, data: str, *, size="4 4 4", type_="F F F") -> bytes:
    return (
        f"VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {type_}\nCOUNT 1 1 1\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    ).encode()


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
def test_pcd_upper_case_fields(tmp_path, data):
    if data == "ascii":
        body = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P).encode()
    elif data == "binary":
        body = P.astype("<f4").tobytes()
    else:
        lzf = pytest.importorskip("lzf")
        soa = np.ascontiguousarray(P.T.astype("<f4")).tobytes()
        comp = lzf.compress(soa) or lzf.compress(soa, len(soa) + 64)
        body = struct.pack("<II", len(comp), len(soa)) + comp
    (tmp_path / "autzen.pcd").write_bytes(_pcd_header("X Y Z", len(P), data) + body)
    pc = io.read(tmp_path / "autzen.pcd")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, P)  # every value is exact in float32


def test_pcd_lower_case_spelling_wins_and_missing_field_is_named(tmp_path):
    body = "".join(f"{x:.17g} {y:.17g} {z:.17g} 7\n" for x, y, z in P).encode()
    head = _pcd_header("x y z X", len(P), "ascii", size="4 4 4 4", type_="F F F F")
    head = head.replace(b"COUNT 1 1 1", b"COUNT 1 1 1 1")
    (tmp_path / "both.pcd").write_bytes(head + body)
    pc = io.read(tmp_path / "both.pcd")
    np.testing.assert_array_equal(pc.points, P)
    np.testing.assert_array_equal(pc.attributes["X"], np.full(len(P), 7.0))
    (tmp_path / "noz.pcd").write_bytes(
        _pcd_header("X Y W", len(P), "binary") + P.astype("<f4").tobytes()
    )
    with pytest.raises(InvalidInputError, match=r"noz.pcd: PCD file lacks field 'z'"):
        io.read(tmp_path / "noz.pcd")


# ----------------------------------------------------------------------- XYZ with count line
def test_xyz_count_line_is_skipped(tmp_path):
    rows = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P)
    (tmp_path / "wave.xyz").write_text(f"{len(P)}\n{rows}")
    pc = io.read(tmp_path / "wave.xyz")
    np.testing.assert_array_equal(pc.points, P)
    # comment and blank lines between the count and the rows are fine
    (tmp_path / "c.xyz").write_text(f"# exported\n{len(P)}\n\n# x y z\n{rows}")
    np.testing.assert_array_equal(io.read(tmp_path / "c.xyz").points, P)


def test_xyz_count_line_must_match_rows(tmp_path):
    rows = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P)
    (tmp_path / "bad.xyz").write_text(f"{len(P) + 1}\n{rows}")
    with pytest.raises(
        InvalidInputError, match=r"bad.xyz: the XYZ count line declares 5 points, the file holds 4"
    ):
        io.read(tmp_path / "bad.xyz")


def test_xyz_single_value_first_line_is_not_a_point(tmp_path):
    rows = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P)
    (tmp_path / "f.xyz").write_text(f"2.5\n{rows}")
    with pytest.raises(InvalidInputError, match=r"f.xyz: line 1 holds the single value '2.5'"):
        io.read(tmp_path / "f.xyz")
    # a file of 1-column rows stays a width error, not a count line
    (tmp_path / "one.xyz").write_text("4\n1\n2\n3\n4\n")
    with pytest.raises(InvalidInputError, match=r"one.xyz: XYZ rows must have at least 3 values"):
        io.read(tmp_path / "one.xyz")


# --------------------------------------------------------------------------------------- PTS
def test_pts_with_count_intensity_and_colors(tmp_path):
    rgb = np.array([[255, 0, 10], [1, 2, 3], [0, 0, 0], [200, 100, 50]])
    inten = np.array([-2048, 0, 17, 2047])
    rows = "".join(
        f"{x:.17g} {y:.17g} {z:.17g} {i} {r} {g} {b}\n"
        for (x, y, z), i, (r, g, b) in zip(P, inten, rgb)
    )
    (tmp_path / "scan.pts").write_text(f"{len(P)}\n{rows}")
    pc = io.read(tmp_path / "scan.pts")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, P)
    np.testing.assert_array_equal(pc.attributes["intensity"], inten.astype(np.float64))
    assert pc.colors.dtype == np.uint8
    np.testing.assert_array_equal(pc.colors, rgb)
    assert ".pts" in io.supported_formats()["read"]


@pytest.mark.parametrize("with_count", [True, False])
def test_pts_xyz_only(tmp_path, with_count):
    rows = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P)
    (tmp_path / "p.pts").write_text((f"{len(P)}\n" if with_count else "") + rows)
    pc = io.read_point_cloud(tmp_path / "p.pts")
    np.testing.assert_array_equal(pc.points, P)
    assert pc.colors is None


def test_pts_malformed(tmp_path):
    rows = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in P)
    (tmp_path / "n.pts").write_text(f"3\n{rows}")
    with pytest.raises(
        InvalidInputError, match=r"n.pts: the PTS count line declares 3 points, the file holds 4"
    ):
        io.read(tmp_path / "n.pts")
    (tmp_path / "w.pts").write_text("1 2 3 4 5\n6 7 8 9 10\n")
    with pytest.raises(InvalidInputError, match=r"w.pts: PTS rows must have 3, 4, 6 or 7 values"):
        io.read(tmp_path / "w.pts")
    (tmp_path / "c.pts").write_text("1 2 3 0 300 0 0\n")
    with pytest.raises(InvalidInputError, match=r"c.pts: PTS colour values .* 0..255"):
        io.read(tmp_path / "c.pts")


# -------------------------------------------------------------------------------- binary OFF
V4 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.25, 1.0]])


def _off_binary(V, faces, *, colors=True, order=">", keyword=b"OFF BINARY") -> bytes:
    i4, f4 = f"{order}i4", f"{order}f4"
    out = [keyword + b"\n", np.array([len(V), len(faces), 0], i4).tobytes()]
    out.append(np.asarray(V, f4).tobytes())
    for f in faces:
        out.append(np.array([len(f), *f], i4).tobytes())
        if colors:
            out.append(np.array([3], i4).tobytes() + np.array([0.1, 0.2, 0.3], f4).tobytes())
    return b"".join(out)


@pytest.mark.parametrize(
    ("colors", "order"), [(True, ">"), (False, ">"), (False, "<")], ids=["geomview", "pmp", "le"]
)
def test_off_binary_triangles(tmp_path, colors, order):
    F = [[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]]
    (tmp_path / "beetle.off").write_bytes(_off_binary(V4, F, colors=colors, order=order))
    m = io.read(tmp_path / "beetle.off")
    assert isinstance(m, Mesh)
    np.testing.assert_array_equal(m.vertices, V4)
    np.testing.assert_array_equal(m.faces, F)


def test_off_binary_polygons_fanned_like_ascii(tmp_path):
    V = np.vstack([V4, [[1.0, 1.0, 0.0]]])
    polys = [[0, 1, 4, 2], [1, 4, 3]]
    (tmp_path / "q.off").write_bytes(_off_binary(V, polys))
    ascii_text = "OFF\n5 2 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in V)
    ascii_text += "4 0 1 4 2\n3 1 4 3\n"
    (tmp_path / "a.off").write_text(ascii_text)
    m, ref = io.read(tmp_path / "q.off"), io.read(tmp_path / "a.off")
    np.testing.assert_array_equal(m.faces, ref.faces)
    np.testing.assert_array_equal(m.faces, [[0, 1, 4], [0, 4, 2], [1, 4, 3]])
    np.testing.assert_array_equal(m.vertices, V)


def test_off_binary_malformed(tmp_path):
    raw = _off_binary(V4, [[0, 1, 2], [0, 1, 3]])
    (tmp_path / "t.off").write_bytes(raw[:-6])
    with pytest.raises(InvalidInputError, match=r"t.off: malformed binary OFF"):
        io.read(tmp_path / "t.off")
    (tmp_path / "v.off").write_bytes(raw[: len(b"OFF BINARY\n") + 12 + 20])
    with pytest.raises(InvalidInputError, match=r"v.off: truncated binary OFF: 4 vertices"):
        io.read(tmp_path / "v.off")
    (tmp_path / "r.off").write_bytes(_off_binary(V4, [[0, 1, 9]]))
    with pytest.raises(InvalidInputError, match=r"r.off: `faces` has vertex indices out of range"):
        io.read(tmp_path / "r.off")
    (tmp_path / "c.off").write_bytes(_off_binary(V4, [[0, 1, 2]], keyword=b"COFF BINARY"))
    with pytest.raises(
        InvalidInputError, match=r"c.off: binary OFF variant 'COFF' is not supported"
    ):
        io.read(tmp_path / "c.off")


# ------------------------------------------------------------------------- structured .npy
def test_npy_structured_xyz(tmp_path):
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("label", "<i4")])
    arr = np.zeros(len(P), dtype=dt)
    arr["x"], arr["y"], arr["z"] = P.T
    arr["red"] = [1, 2, 3, 4]
    arr["label"] = [7, 8, 9, 10]
    np.save(tmp_path / "diamond.npy", arr)
    pc = io.read(tmp_path / "diamond.npy")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, P)
    np.testing.assert_array_equal(pc.attributes["label"], [7.0, 8.0, 9.0, 10.0])


def test_npy_structured_without_z(tmp_path):
    arr = np.zeros(3, dtype=[("x", "<f8"), ("y", "<f8"), ("w", "<f8")])
    np.save(tmp_path / "s.npy", arr)
    with pytest.raises(InvalidInputError, match=r"s.npy: structured .npy lacks field 'z'"):
        io.read(tmp_path / "s.npy")
