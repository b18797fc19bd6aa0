"""Every validation branch of spectrageo.io: a clear InvalidInputError naming the file, never a raw
library traceback; atomic writes leave nothing behind on failure."""

from __future__ import annotations

import gzip
import os
import struct
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from spectrageo import InvalidInputError, UnsupportedFormatError, io
from spectrageo.geometry import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from spectrageo.io import _common, _write

from conftest import icosphere

PLY_HEAD = (
    "ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
    "property float z\n{extra}end_header\n"
)
FACE_PROP = "element face {m}\nproperty list uchar int vertex_indices\n"
PCD_HEAD = (
    "VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {type}\nCOUNT {count}\nWIDTH {w}\n"
    "HEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
)


def pcd_head(
    fields="x y z", size="4 4 4", type="F F F", count="1 1 1", w=2, h=1, n=None, data="ascii"
):
    return PCD_HEAD.format(
        fields=fields,
        size=size,
        type=type,
        count=count,
        w=w,
        h=h,
        n=w * h if n is None else n,
        data=data,
    )


def put(tmp_path: Path, name: str, content) -> Path:
    p = tmp_path / name
    if isinstance(content, str):
        content = content.encode()
    p.write_bytes(content)
    return p


@pytest.fixture
def mesh():
    V, F = icosphere(1)
    return Mesh(V, F)


# ------------------------------------------------------------------------------ generic read
def test_missing_file(tmp_path):
    with pytest.raises(InvalidInputError, match="file not found: .*nope.ply"):
        io.read(tmp_path / "nope.ply")


@pytest.mark.parametrize("name", ["x.abc", "x.ply.zip", "noext", "x.gz"])
def test_unknown_extension_lists_supported(tmp_path, name):
    p = put(tmp_path, name, "1 2 3\n")
    with pytest.raises(
        UnsupportedFormatError, match=r"unsupported file extension.*supported: .ply"
    ):
        io.read(p)


def test_bad_kind_and_nan_policy(tmp_path, mesh):
    io.write(tmp_path / "m.ply", mesh)
    with pytest.raises(InvalidInputError, match="`kind` must be one of"):
        io.read(tmp_path / "m.ply", kind="surface")
    with pytest.raises(InvalidInputError, match="`nan_points` must be one of"):
        io.read(tmp_path / "m.ply", nan_points="ignore")


@pytest.mark.parametrize("kind", ["animation", "sequence"])
def test_single_file_cannot_be_animation(tmp_path, mesh, kind):
    io.write(tmp_path / "m.ply", mesh)
    with pytest.raises(
        InvalidInputError, match=f"m.ply: a single .ply file cannot be read as '{kind}'"
    ):
        io.read(tmp_path / "m.ply", kind=kind)


@pytest.mark.parametrize(
    "ext", [".ply", ".obj", ".off", ".stl", ".pcd", ".xyz", ".npy", ".las", ".laz", ".npz"]
)
def test_empty_file(tmp_path, ext):
    p = put(tmp_path, f"e{ext}", b"" if ext == ".npz" else b"  \n")
    with pytest.raises(InvalidInputError, match=f"e{ext}: empty file"):
        io.read(p)


@pytest.mark.parametrize("ext", [".ply", ".stl", ".pcd", ".npy", ".las", ".laz", ".npz", ".off"])
def test_garbage_bytes(tmp_path, ext):
    pytest.importorskip("laspy")
    blob = np.random.default_rng(0).integers(1, 256, 3000, dtype=np.uint8).tobytes()
    p = put(tmp_path, f"g{ext}", blob)
    with pytest.raises(InvalidInputError, match=f"g{ext}"):
        io.read(p)


def test_garbage_obj_is_binary(tmp_path):
    p = put(tmp_path, "g.obj", b"v 1 2 3\x00\x01\x02")
    with pytest.raises(InvalidInputError, match="g.obj: not a text OBJ file"):
        io.read(p)


@pytest.mark.parametrize("damage", ["corrupt", "truncated"])
def test_gz_damaged(tmp_path, mesh, damage):
    io.write(tmp_path / "m.ply.gz", mesh)
    raw = (tmp_path / "m.ply.gz").read_bytes()
    if damage == "corrupt":
        raw = raw[:20] + bytes(b ^ 0xFF for b in raw[20:60]) + raw[60:]
    else:
        raw = raw[: len(raw) // 2]
    p = put(tmp_path, "bad.ply.gz", raw)
    with pytest.raises(InvalidInputError, match="bad.ply.gz: corrupted or truncated gzip"):
        io.read(p)
    p = put(tmp_path, "notgz.off.gz", b"OFF\n3 1 0\n")
    with pytest.raises(InvalidInputError, match="notgz.off.gz: corrupted or truncated gzip"):
        io.read(p)


# ----------------------------------------------------------------------------- geometry checks
def test_read_mesh_needs_faces(tmp_path):
    p = put(tmp_path, "p.xyz", "1 2 3\n4 5 6\n")
    with pytest.raises(InvalidInputError, match=r"p.xyz: has no faces \(2 points only\)"):
        io.read_mesh(p)


def test_nan_vertices_in_mesh(tmp_path):
    p = put(tmp_path, "n.obj", "v 0 0 0\nv nan 0 0\nv 0 1 inf\nf 1 2 3\n")
    with pytest.raises(
        InvalidInputError,
        match=r"n.obj: 2 vertices have NaN or inf coordinates \(first at index 1\)",
    ):
        io.read(p)


def test_nan_points(tmp_path):
    p = put(tmp_path, "n.xyz", "0 0 0\nnan 0 0\n1 1 1\n")
    with pytest.raises(
        InvalidInputError, match=r"n.xyz: 1 of 3 points have NaN or inf .*nan_points='drop'"
    ):
        io.read(p)
    pc = io.read(p, nan_points="drop")
    np.testing.assert_array_equal(pc.points, [[0, 0, 0], [1, 1, 1]])
    np.testing.assert_array_equal(pc.attributes["source_index"], [0, 2])
    p = put(tmp_path, "all.xyz", "nan 0 0\ninf 0 0\n")
    with pytest.raises(InvalidInputError, match="all.xyz: all 2 points have NaN or inf"):
        io.read(p, nan_points="drop")


def test_nan_normals(tmp_path):
    # one bad normal no longer rejects the cloud: the points are kept, the normals dropped
    from spectrageo import RepairWarning

    p = put(tmp_path, "n.xyz", "0 0 0 0 0 1\n1 1 1 nan 0 0\n")
    with pytest.warns(RepairWarning, match="n.xyz: 1 of 2 point normals are NaN or inf"):
        pc = io.read(p)
    assert pc.n_points == 2 and pc.normals is None


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("o.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"),
        ("o.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
        (
            "o.ply",
            PLY_HEAD.format(fmt="ascii", n=3, extra=FACE_PROP.format(m=1))
            + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
        ),
    ],
)
def test_face_index_out_of_range(tmp_path, name, content):
    p = put(tmp_path, name, content)
    with pytest.raises(
        InvalidInputError, match=rf"{name}: `faces` has vertex indices out of range"
    ):
        io.read(p)


def test_point_cloud_errors_are_wrapped(tmp_path):
    # colours of a bad width reach the PointCloud container: its message gets the file name
    text = PLY_HEAD.format(
        fmt="ascii", n=2, extra="property uchar red\nproperty uchar green\nproperty uchar blue\n"
    )
    p = put(tmp_path, "ok.ply", text + "0 0 0 1 2 3\n1 1 1 4 5 6\n")
    assert io.read(p).colors.shape == (2, 3)
    p = put(tmp_path, "e.ply", PLY_HEAD.format(fmt="ascii", n=0, extra=""))
    with pytest.raises(InvalidInputError, match="e.ply: the file contains no vertices"):
        io.read(p)


# ------------------------------------------------------------------------------------------ PLY
def test_ply_bad_header(tmp_path):
    p = put(tmp_path, "h.ply", "ply\nformat weird 1.0\nend_header\n")
    with pytest.raises(InvalidInputError, match="h.ply: malformed PLY header"):
        io.read(p)
    p = put(tmp_path, "u.ply", b"ply\nformat ascii 1.0\ncomment \xff\xfe\nend_header\n")
    with pytest.raises(InvalidInputError, match="u.ply: not a PLY file"):
        io.read(p)


def test_ply_truncated_binary_vertices(tmp_path):
    V = np.random.default_rng(0).random((10, 3)).astype("<f4")
    full = PLY_HEAD.format(fmt="binary_little_endian", n=10, extra="").encode() + V.tobytes()
    p = put(tmp_path, "t.ply", full[:-7])
    with pytest.raises(
        InvalidInputError, match="t.ply: truncated PLY: element 'vertex' needs 120 bytes"
    ):
        io.read(p)


def test_ply_truncated_binary_faces(tmp_path, mesh):
    io.write(tmp_path / "m.ply", mesh)
    raw = (tmp_path / "m.ply").read_bytes()
    p = put(tmp_path, "t.ply", raw[:-30])
    with pytest.raises(InvalidInputError, match="t.ply: malformed or truncated PLY"):
        io.read(p)


def test_ply_truncated_ascii(tmp_path, mesh):
    io.write(tmp_path / "m.ply", mesh, binary=False)
    lines = (tmp_path / "m.ply").read_text().splitlines(keepends=True)
    p = put(tmp_path, "t.ply", "".join(lines[:-5]))
    with pytest.raises(
        InvalidInputError, match="t.ply: truncated PLY: element 'face' declares 80 rows"
    ):
        io.read(p)


def test_ply_ascii_bad_values(tmp_path):
    head = PLY_HEAD.format(fmt="ascii", n=3, extra=FACE_PROP.format(m=1))
    p = put(tmp_path, "f.ply", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n")
    with pytest.raises(
        InvalidInputError,
        match="f.ply: property 'vertex_indices' of element 'face' must hold integers",
    ):
        io.read(p)
    head = PLY_HEAD.format(fmt="ascii", n=1, extra="property uchar red\n")
    p = put(tmp_path, "r.ply", head + "0 0 0 300\n")
    with pytest.raises(
        InvalidInputError, match="r.ply: property 'red' of element 'vertex' is out of range"
    ):
        io.read(p)
    head = PLY_HEAD.format(fmt="ascii", n=2, extra="")
    p = put(tmp_path, "x.ply", head + "0 0 0\n1 0 zero\n")
    with pytest.raises(InvalidInputError, match="x.ply: malformed or truncated PLY"):
        io.read(p)


def test_ply_structure_errors(tmp_path):
    p = put(
        tmp_path,
        "nv.ply",
        "ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n",
    )
    with pytest.raises(InvalidInputError, match="nv.ply: PLY file has no 'vertex' element"):
        io.read(p)
    p = put(
        tmp_path,
        "nx.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n1\n",
    )
    with pytest.raises(InvalidInputError, match="nx.ply: PLY 'vertex' element lacks property 'x'"):
        io.read(p)
    head = PLY_HEAD.format(fmt="ascii", n=3, extra="element face 1\nproperty list uchar int idx\n")
    p = put(tmp_path, "nf.ply", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(
        InvalidInputError, match="nf.ply: PLY 'face' element has no 'vertex_indices'"
    ):
        io.read(p)
    head = PLY_HEAD.format(fmt="ascii", n=3, extra=FACE_PROP.format(m=1))
    p = put(tmp_path, "two.ply", head + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n")
    with pytest.raises(
        InvalidInputError, match="two.ply: faces must have at least 3 vertices; got 2"
    ):
        io.read(p)


def test_ply_write_errors(tmp_path, mesh):
    n, m = mesh.n_vertices, mesh.n_faces
    cases = [
        (
            Mesh(mesh.vertices, mesh.faces, vertex_attributes={"a b": np.zeros(n)}),
            "cannot be a PLY property name",
        ),
        (
            Mesh(mesh.vertices, mesh.faces, vertex_attributes={"x": np.zeros(n)}),
            "clashes with another PLY property",
        ),
        (
            Mesh(mesh.vertices, mesh.faces, vertex_attributes={"t": np.zeros((n, 2, 2))}),
            r"attribute `t` has shape \(42, 2, 2\)",
        ),
        (
            Mesh(mesh.vertices, mesh.faces, face_attributes={"t": np.zeros((m, 2, 2))}),
            r"face attribute `t` has shape",
        ),
        (
            Mesh(mesh.vertices, mesh.faces, face_attributes={"vertex_indices": np.zeros(m)}),
            "clashes",
        ),
        (
            Mesh(mesh.vertices, mesh.faces, vertex_attributes={"s": np.array(["a"] * n)}),
            "PLY cannot store",
        ),
    ]
    for obj, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            io.write(tmp_path / "w.ply", obj)
    assert not (tmp_path / "w.ply").exists()
    # 64-bit integers are narrowed when they fit, stored as double otherwise
    big = Mesh(
        mesh.vertices, mesh.faces, vertex_attributes={"i": np.arange(n) + 2**40, "j": np.arange(n)}
    )
    io.write(tmp_path / "b.ply", big)
    back = io.read_mesh(tmp_path / "b.ply").vertex_attributes
    assert back["i"].dtype == np.float64 and back["j"].dtype == np.int32
    np.testing.assert_array_equal(back["i"], np.arange(n) + 2**40)


# ------------------------------------------------------------------------------------------ OBJ
def test_obj_errors(tmp_path):
    cases = [
        ("r.obj", "v 0 0 0\nv 1 0\nv 0 1 0\n", "r.obj: malformed OBJ"),
        ("t.obj", "v 0 0\nv 1 0\n", r"r?t.obj: OBJ 'v' lines must have at least 3 coordinates"),
        ("z.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "z.obj: OBJ face index 0 is invalid"),
        ("n.obj", "# nothing\nf 1 2 3\n", "n.obj: OBJ file has no vertices"),
        ("a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 b 3\n", "a.obj: malformed OBJ"),
    ]
    for name, text, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            io.read(put(tmp_path, name, text))
    # 'f' lines with fewer than 3 corners are skipped with a RepairWarning (points/lines, not faces)
    from spectrageo import RepairWarning

    with pytest.warns(RepairWarning, match="f.obj: 1 OBJ 'f' line"):
        pc = io.read(put(tmp_path, "f.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n"))
    assert isinstance(pc, PointCloud) and pc.n_points == 2


# ------------------------------------------------------------------------------------------ OFF
@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("# only a comment\n", "empty OFF file"),
        ("PLY\n3 1 0\n", "not an OFF file"),
        ("4OFF\n1 0 0\n0 0 0 0\n", "OFF variant '4OFF' is not supported"),
        ("OFF\n", "OFF file has no counts line"),
        ("OFF\nthree 1 0\n", "malformed OFF counts line"),
        ("OFF\n-3 1 0\n", "negative counts"),
        ("OFF\n0 0 0\n", "OFF file has no vertices"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n", "truncated OFF: 3 vertices declared, 2 vertex lines found"),
        ("OFF\n2 0 0\n0 0 0\n1 x 0\n", "malformed OFF vertex lines"),
        ("OFF\n2 0 0\n0 0\n1 0\n", "OFF vertex lines have 2 values; OFF expects 3"),
        (
            "COFF\n2 0 0\n0 0 0\n1 0 0\n",
            "OFF vertex lines have 3 values; COFF expects 3 \\+ 3 or 4 colour",
        ),
        (
            "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            "truncated OFF: 2 faces declared, 1 face lines found",
        ),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n", "OFF face indices must be integers"),
        (
            "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n4 0 1\n",
            "OFF face line 1 declares 4 vertices but lists 2",
        ),
        ("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 a b\n", "malformed OFF face line 1"),
    ],
)
def test_off_errors(tmp_path, text, match):
    with pytest.raises(InvalidInputError, match="o.off: " + match):
        io.read(put(tmp_path, "o.off", text))


def test_off_extra_vertex_values_ignored(tmp_path):
    m = io.read_mesh(put(tmp_path, "x.off", "OFF\n3 1 0\n0 0 0 9\n1 0 0 9\n0 1 0 9\n3 0 1 2\n"))
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


# ------------------------------------------------------------------------------------------ STL
def test_stl_errors(tmp_path, mesh):
    io.write(tmp_path / "m.stl", mesh)
    raw = (tmp_path / "m.stl").read_bytes()
    with pytest.raises(InvalidInputError, match="t.stl: not a valid STL file"):
        io.read(put(tmp_path, "t.stl", raw[:-25]))
    bad = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid x\n"
    with pytest.raises(InvalidInputError, match="a.stl: malformed or truncated STL"):
        io.read(put(tmp_path, "a.stl", bad))


# ---------------------------------------------------------------------------------- XYZ / NPY
def test_xyz_errors(tmp_path):
    with pytest.raises(InvalidInputError, match=r"c.xyz: .*line 2"):
        io.read(put(tmp_path, "c.xyz", "1 2 3 4\n5 6 7\n"))
    with pytest.raises(InvalidInputError, match="m.xyz: malformed XYZ text"):
        io.read(put(tmp_path, "m.xyz", "1 2 3\n4 5\n"))
    with pytest.raises(InvalidInputError, match="e.xyz: XYZ file holds no points"):
        io.read(put(tmp_path, "e.xyz", "# header only\n"))


def test_npy_errors(tmp_path):
    np.save(tmp_path / "s.npy", np.zeros((4, 2)))
    with pytest.raises(
        InvalidInputError, match=r"s.npy: .npy point arrays must have shape \(n, 3\); got \(4, 2\)"
    ):
        io.read(tmp_path / "s.npy")
    np.save(tmp_path / "t.npy", np.zeros((2, 4, 3)))
    with pytest.raises(
        InvalidInputError, match=r"t.npy: .*got \(2, 4, 3\).*sequences go in a .npz"
    ):
        io.read(tmp_path / "t.npy")
    np.save(tmp_path / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InvalidInputError, match="o.npy: not a valid .npy array"):
        io.read(tmp_path / "o.npy")
    np.save(tmp_path / "u.npy", np.array([["a", "b", "c"]]))
    with pytest.raises(InvalidInputError, match="u.npy: .npy must hold a numeric"):
        io.read(tmp_path / "u.npy")
    np.save(tmp_path / "n.npy", np.array([[0, 0, 0], [np.nan, 1, 1.0]]))
    with pytest.raises(InvalidInputError, match="n.npy: 1 of 2 points have NaN"):
        io.read(tmp_path / "n.npy")
    full = (tmp_path / "s.npy").read_bytes()
    with pytest.raises(InvalidInputError, match="cut.npy: not a valid .npy array"):
        io.read(put(tmp_path, "cut.npy", full[:-10]))


# ------------------------------------------------------------------------------------------ PCD
@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("VERSION 0.7\nFIELDS x y z", "truncated PCD header"),
        (b"VERSION 0.7\n\xff\xfe\n", "binary data in the header"),
        ("VERSION 0.7\nHELLO 1\n", "unexpected header line 'HELLO 1'"),
        ("# c\n" * 70, "no DATA line"),
        (pcd_head().replace("SIZE 4 4 4\n", ""), "PCD header lacks SIZE"),
        (pcd_head().replace("FIELDS x y z\n", "FIELDS\n"), "PCD header lacks FIELDS"),
        (pcd_head(size="4 4"), "FIELDS/SIZE/TYPE/COUNT have different lengths"),
        (pcd_head(w="two"), "malformed numbers in the PCD header"),
        (pcd_head(n=5), "POINTS=5 differs from WIDTH\\*HEIGHT=2"),
        (pcd_head(count="1 0 1"), "COUNT of field .y. must be in 1..1048576; got 0"),
        (pcd_head(fields="x y x"), "repeats a field name"),
        (pcd_head(fields="y z w"), "lacks field 'x'"),
        (pcd_head(count="2 1 1") + "0 0 0 0\n0 0 0 0\n", "field 'x' must have COUNT 1"),
        (pcd_head() + "0 0 0\n", "truncated PCD: 2 points declared, 1 rows found"),
        (pcd_head(), "truncated PCD: 2 points declared, no data rows"),
        (pcd_head() + "0 0 0 1\n0 0 0 1\n", "ascii rows have 4 values; the header declares 3"),
        (pcd_head() + "0 0 0\n0 a 0\n", "malformed PCD ascii data"),
        (
            pcd_head(fields="x y z l", size="4 4 4 4", type="F F F I", count="1 1 1 1")
            + "0 0 0 1.5\n0 0 0 1\n",
            "integer field 'l' holds non-integer",
        ),
        (pcd_head(data="binary") + "\x00" * 20, "truncated PCD: binary data needs 24 bytes"),
    ],
)
def test_pcd_invalid(tmp_path, content, match):
    with pytest.raises(InvalidInputError, match="c.pcd: .*" + match):
        io.read(put(tmp_path, "c.pcd", content))


@pytest.mark.parametrize(
    ("head", "match"),
    [
        (pcd_head(type="F F X"), "unsupported TYPE X with SIZE 4"),
        (pcd_head(size="4 4 2"), "unsupported TYPE F with SIZE 2"),
        (pcd_head(data="binary_scrambled"), "PCD DATA 'binary_scrambled' is not supported"),
    ],
)
def test_pcd_unsupported(tmp_path, head, match):
    with pytest.raises(UnsupportedFormatError, match="c.pcd: .*" + match):
        io.read(put(tmp_path, "c.pcd", head + "0 0 0\n0 0 0\n"))


def test_pcd_compressed_damage(tmp_path):
    import lzf

    soa = np.arange(6, dtype="<f4").tobytes()
    comp = lzf.compress(soa, 100)
    head = pcd_head(data="binary_compressed").encode()
    good = head + struct.pack("<II", len(comp), len(soa)) + comp
    assert io.read(put(tmp_path, "ok.pcd", good)).n_points == 2
    cases = [
        (head + b"\x01\x02", "missing the compressed block sizes"),
        (good[:-3], f"compressed block of {len(comp)} bytes"),
        (
            head + struct.pack("<II", len(comp), 99) + comp,
            "uncompressed size 99 differs from the 24 bytes",
        ),
        (head + struct.pack("<II", 8, 24) + b"\xff" * 8, "corrupt PCD LZF block"),
        (head + struct.pack("<II", len(comp) - 1, 24) + comp[:-1], "corrupt PCD LZF block"),
    ]
    for raw, match in cases:
        with pytest.raises(InvalidInputError, match="c.pcd: .*" + match):
            io.read(put(tmp_path, "c.pcd", raw))


def test_pcd_write_errors(tmp_path):
    P = np.zeros((3, 3))
    with pytest.raises(InvalidInputError, match="attribute name 'a b' cannot be a PCD field name"):
        io.write(tmp_path / "w.pcd", PointCloud(P, attributes={"a b": np.zeros(3)}))
    with pytest.raises(InvalidInputError, match="attribute name 'x' cannot be a PCD field name"):
        io.write(tmp_path / "w.pcd", PointCloud(P, attributes={"x": np.zeros(3)}))
    with pytest.raises(InvalidInputError, match=r"attribute `t` has shape \(3, 2, 2\)"):
        io.write(tmp_path / "w.pcd", PointCloud(P, attributes={"t": np.zeros((3, 2, 2))}))
    with pytest.raises(InvalidInputError, match="PCD cannot store values of dtype <U1"):
        io.write(tmp_path / "w.pcd", PointCloud(P, attributes={"s": np.array(["a"] * 3)}))
    with pytest.raises(InvalidInputError, match="`pcd_format` must be one of"):
        io.write(tmp_path / "w.pcd", PointCloud(P), pcd_format="zip")
    assert not (tmp_path / "w.pcd").exists()


# ---------------------------------------------------------------------------------- LAS / LAZ
def test_las_missing_dependency(tmp_path, monkeypatch):
    pytest.importorskip("laspy")
    io.write(tmp_path / "p.las", PointCloud(np.zeros((2, 3))))
    monkeypatch.setitem(sys.modules, "laspy", None)
    with pytest.raises(
        UnsupportedFormatError, match=r"optional dependency laspy .*spectrageo\[las\]"
    ):
        io.read(tmp_path / "p.las")
    with pytest.raises(UnsupportedFormatError, match="optional dependency laspy"):
        io.write(tmp_path / "q.las", PointCloud(np.zeros((2, 3))))


def test_laz_missing_backend(tmp_path, monkeypatch):
    laspy = pytest.importorskip("laspy")
    monkeypatch.setattr(laspy.LazBackend, "detect_available", staticmethod(lambda: ()))
    put(tmp_path, "p.laz", b"LASF" + b"\x00" * 400)
    with pytest.raises(UnsupportedFormatError, match="LAZ support needs a LAZ backend"):
        io.read(tmp_path / "p.laz")


def test_las_truncated_and_write_errors(tmp_path):
    pytest.importorskip("laspy")
    rng = np.random.default_rng(0)
    io.write(tmp_path / "p.las", PointCloud(rng.random((100, 3))))
    raw = (tmp_path / "p.las").read_bytes()
    # the header is checked before laspy sees the bytes: the message says what is missing
    with pytest.raises(
        InvalidInputError, match="t.las: truncated LAS: the header declares 100 points of 20 bytes"
    ):
        io.read(put(tmp_path, "t.las", raw[: len(raw) // 2]))
    P = rng.random((5, 3))
    cases = [
        ({"las_scale": -1.0}, PointCloud(P), "`las_scale` must be a positive number"),
        ({"las_scale": 1e-12}, PointCloud(P * 1e6), "too fine for the extent"),
        (
            {},
            PointCloud(P, attributes={"t": np.zeros((5, 2, 2))}),
            r"attribute `t` has shape \(5, 2, 2\)",
        ),
        ({}, PointCloud(P, attributes={"s": np.array(["a"] * 5)}), "attribute `s` has dtype <U1"),
        (
            {},
            PointCloud(P, attributes={"x": np.zeros(5)}),
            "attribute name `x` clashes with a LAS dimension",
        ),
        (
            {},
            PointCloud(P, attributes={"classification": np.array([1, 2, 3, 300, 4])}),
            "cannot store attributes in LAS",
        ),
        (
            {},
            PointCloud(P, attributes={"intensity": np.array([1.5, 2, 3, 4, 5])}),
            "attribute `intensity` cannot be stored exactly",
        ),
    ]
    for kw, pc, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            io.write(tmp_path / "w.las", pc, **kw)
    assert not (tmp_path / "w.las").exists()


# ------------------------------------------------------------------------------------------ NPZ
def _npz(tmp_path, name, **arrays):
    np.savez(tmp_path / name, **arrays)
    return tmp_path / name


def test_npz_errors(tmp_path):
    V, F = icosphere(0)
    fr = np.stack([V, V])
    bad_frames = fr.copy()
    bad_frames[1, 3] = np.nan
    bad_frames[0, 0] = np.inf
    cases = [
        (_npz(tmp_path, "a.npz", vertices=fr), {}, "a.npz: animation .npz lacks key 'faces'"),
        (_npz(tmp_path, "b.npz", faces=F), {}, "b.npz: animation .npz lacks key 'vertices'"),
        (
            _npz(tmp_path, "c.npz", vertices=V, faces=F),
            {},
            r"c.npz: 'vertices' must have shape \(T, n, 3\); got \(12, 3\)",
        ),
        (
            _npz(tmp_path, "d.npz", vertices=fr, faces=F[:, :2]),
            {},
            r"d.npz: 'faces' must have shape \(m, 3\)",
        ),
        (
            _npz(tmp_path, "e.npz", vertices=fr, faces=F + 100),
            {},
            "e.npz: `faces` has vertex indices out of range",
        ),
        (
            _npz(tmp_path, "f.npz", vertices=bad_frames, faces=F),
            {},
            r"f.npz: 2 vertex positions have NaN or inf coordinates \(first at frame 0, vertex 0\)",
        ),
        (
            _npz(tmp_path, "g.npz", vertices=fr, faces=F.astype(float)),
            {},
            "g.npz: 'faces' must hold integers",
        ),
        (_npz(tmp_path, "h.npz", vertices=fr[:, :0], faces=F), {}, "h.npz: 'vertices' is empty"),
        (
            _npz(tmp_path, "i.npz", vertices=np.array([[["a"] * 3]]), faces=F),
            {},
            "i.npz: 'vertices' must be numeric",
        ),
        (_npz(tmp_path, "j.npz", stuff=V), {}, "j.npz: .npz has keys stuff; expected 'vertices'"),
        (
            _npz(tmp_path, "k.npz", points=V),
            {},
            r"k.npz: 'points' must have shape \(T, n, 3\), or \(N, 3\) with 'counts'",
        ),
        (
            _npz(tmp_path, "l.npz", points=V, counts=np.array([5, 5])),
            {},
            "l.npz: 'counts' must be positive integers summing to the 12 rows",
        ),
        (
            _npz(tmp_path, "m.npz", points=V, counts=np.array([13, -1])),
            {},
            "m.npz: 'counts' must be positive",
        ),
        (
            _npz(tmp_path, "n.npz", vertices=fr, faces=F),
            {"kind": "points"},
            "n.npz: a .npz file holds an animation or a sequence, not a single 'points'",
        ),
    ]
    for path, kw, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            io.read(path, **kw)


def test_npz_not_an_archive(tmp_path):
    np.save(tmp_path / "arr.npy", np.zeros((3, 3)))
    p = put(tmp_path, "single.npz", (tmp_path / "arr.npy").read_bytes())
    with pytest.raises(InvalidInputError, match="single.npz: not a .npz archive"):
        io.read(p)
    with zipfile.ZipFile(tmp_path / "broken.npz", "w") as z:
        z.writestr("vertices.npy", b"not an array")
        z.writestr("faces.npy", b"nope")
    with pytest.raises(InvalidInputError, match="broken.npz: cannot read array 'vertices'"):
        io.read(tmp_path / "broken.npz")


# ------------------------------------------------------------------------------- frame folders
def test_folder_errors(tmp_path):
    V, F = icosphere(0)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.txt").write_text("x")
    with pytest.raises(
        InvalidInputError,
        match="empty: a folder is read as .* numbered frame files .* this one has none",
    ):
        io.read(empty)
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    io.write(mixed / "f_0.ply", Mesh(V, F))
    io.write(mixed / "f_1.obj", Mesh(V, F))
    with pytest.raises(
        InvalidInputError, match=r"mixed: folder mixes frame formats \(.obj, .ply\)"
    ):
        io.read(mixed)
    with pytest.raises(InvalidInputError, match="not a single 'mesh'"):
        io.read(empty, kind="mesh")
    count = tmp_path / "count"
    count.mkdir()
    io.write(count / "f_0.ply", Mesh(V, F))
    io.write(count / "f_1.ply", Mesh(np.vstack([V, [[9, 9, 9]]]), F))
    with pytest.raises(InvalidInputError, match="f_1.ply: 13 vertices, but f_0.ply has 12"):
        io.read(count)
    conn = tmp_path / "conn"
    conn.mkdir()
    io.write(conn / "f_0.ply", Mesh(V, F))
    io.write(conn / "f_1.ply", Mesh(V, F[:, [0, 2, 1]]))
    with pytest.raises(InvalidInputError, match="f_1.ply: faces differ from those of f_0.ply"):
        io.read(conn)
    assert io.read(conn, kind="sequence").n_points == [12, 12]
    half = tmp_path / "half"
    half.mkdir()
    io.write(half / "f_0.ply", Mesh(V, F))
    io.write(half / "f_1.ply", PointCloud(V))
    with pytest.raises(InvalidInputError, match="some frames have faces and others not"):
        io.read(half)
    pts = tmp_path / "pts"
    pts.mkdir()
    io.write(pts / "f_0.xyz", PointCloud(V))
    with pytest.raises(InvalidInputError, match="f_0.xyz: has no faces"):
        io.read_animation(pts)


# ------------------------------------------------------------------------------------- write
def test_write_argument_errors(tmp_path, mesh):
    anim = MeshAnimation(np.stack([mesh.vertices] * 2), mesh.faces)
    seq = PointCloudSequence([PointCloud(mesh.vertices)])
    cases = [
        (
            InvalidInputError,
            tmp_path / "a.ply",
            mesh,
            {"colour": 1},
            "unexpected option\\(s\\) colour for write",
        ),
        (InvalidInputError, tmp_path / "a.ply", "mesh", {}, "`obj` must be a Mesh, PointCloud"),
        (InvalidInputError, tmp_path / "a.ply", np.zeros((2, 3, 3)), {}, "`obj` must be a Mesh"),
        (
            UnsupportedFormatError,
            tmp_path / "a.ply",
            anim,
            {},
            "a.ply: unsupported file extension '.ply'; supported: .npz",
        ),
        (UnsupportedFormatError, tmp_path / "s.pcd", seq, {}, "unsupported file extension '.pcd'"),
        (
            InvalidInputError,
            tmp_path / "meshdir",
            mesh,
            {},
            "a Mesh is written to a file with an extension",
        ),
        (
            UnsupportedFormatError,
            tmp_path / "m.xyz",
            mesh,
            {},
            r"cannot write a Mesh as '.xyz'.*PointCloud\(mesh.vertices\)",
        ),
        (UnsupportedFormatError, tmp_path / "m.vtk", mesh, {}, "cannot write a Mesh as '.vtk'"),
        (
            UnsupportedFormatError,
            tmp_path / "p.stl",
            PointCloud(mesh.vertices),
            {},
            "p.stl: unsupported file extension '.stl'",
        ),
        (
            UnsupportedFormatError,
            tmp_path / "fr",
            anim,
            {"frame_format": ".pcd"},
            "`frame_format` '.pcd' cannot hold MeshAnimation frames",
        ),
        (
            InvalidInputError,
            tmp_path / "fr",
            anim,
            {"prefix": "a/b"},
            "`prefix` must be a plain file name prefix",
        ),
        (
            InvalidInputError,
            tmp_path / "missing" / "m.ply",
            mesh,
            {},
            "output folder does not exist",
        ),
        (
            InvalidInputError,
            tmp_path / "missing" / "anim",
            anim,
            {},
            "output folder does not exist",
        ),
    ]
    for exc, path, obj, kw, match in cases:
        with pytest.raises(exc, match=match):
            io.write(path, obj, **kw)
    assert sorted(os.listdir(tmp_path)) == []


def test_atomic_write_targets(tmp_path):
    (tmp_path / "d").mkdir()
    with pytest.raises(InvalidInputError, match="a folder with that name exists"):
        with io.atomic_write(tmp_path / "d"):
            pass
    put(tmp_path, "file", "x")
    with pytest.raises(
        InvalidInputError, match="cannot write frames to .*file: a file with that name exists"
    ):
        with _common.atomic_dir(tmp_path / "file"):
            pass


def test_atomic_write_failure_leaves_target_unchanged(tmp_path):
    target = put(tmp_path, "keep.bin", b"old content")
    with pytest.raises(RuntimeError, match="boom"):
        with io.atomic_write(target) as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("boom")
    assert target.read_bytes() == b"old content"
    assert sorted(os.listdir(tmp_path)) == ["keep.bin"]


@pytest.mark.parametrize("existing", [False, True])
def test_write_failure_midway_leaves_no_partial_file(tmp_path, mesh, monkeypatch, existing):
    target = tmp_path / "m.ply"
    if existing:
        target.write_bytes(b"previous")
    real = Path.write_bytes

    def half_then_fail(self, data):
        real(self, data[: len(data) // 2])
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_bytes", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        io.write(target, mesh)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == (["m.ply"] if existing else [])
    if existing:
        assert target.read_bytes() == b"previous"


def test_folder_write_failure_midway(tmp_path, mesh, monkeypatch):
    anim = MeshAnimation(np.stack([mesh.vertices] * 4), mesh.faces)
    calls = {"n": 0}
    real = _write._serialise

    def fail_third(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        return real(*args, **kw)

    monkeypatch.setattr(_write, "_serialise", fail_third)
    with pytest.raises(OSError, match="disk full"):
        io.write(tmp_path / "anim", anim)
    assert sorted(os.listdir(tmp_path)) == []  # neither the target nor the staging folder
    # an existing folder keeps its previous frames
    monkeypatch.undo()
    io.write(tmp_path / "anim", MeshAnimation(np.stack([mesh.vertices] * 2), mesh.faces))
    before = {f: (tmp_path / "anim" / f).read_bytes() for f in os.listdir(tmp_path / "anim")}
    calls["n"] = 0
    monkeypatch.setattr(_write, "_serialise", fail_third)
    with pytest.raises(OSError, match="disk full"):
        io.write(tmp_path / "anim", MeshAnimation(anim.frames * 2, anim.faces))
    after = {f: (tmp_path / "anim" / f).read_bytes() for f in os.listdir(tmp_path / "anim")}
    assert after == before and sorted(os.listdir(tmp_path)) == ["anim"]


def test_gz_write_is_gzip(tmp_path, mesh):
    io.write(tmp_path / "m.off.gz", mesh)
    assert gzip.decompress((tmp_path / "m.off.gz").read_bytes()).startswith(b"OFF")


def test_read_bytes_guards(tmp_path):
    with pytest.raises(InvalidInputError, match="file not found"):
        _common.read_bytes(tmp_path / "gone.ply", False)
    with pytest.raises(InvalidInputError, match="expected a file, got a folder"):
        _common.read_bytes(tmp_path, False)


def test_ragged_polygon_with_two_vertices(tmp_path):
    # ragged faces go through plyfile's reader; a 2-vertex face among them is reported by index
    head = PLY_HEAD.format(fmt="ascii", n=4, extra=FACE_PROP.format(m=2))
    p = put(tmp_path, "r.ply", head + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n4 0 1 3 2\n2 0 1\n")
    with pytest.raises(
        InvalidInputError, match="r.ply: face 1 has 2 vertices; faces need at least 3"
    ):
        io.read(p)


def test_obj_relative_index_before_the_first_vertex_is_named(tmp_path):
    """``f -1 -2 -9`` on three vertices: the message names -9 and the valid range (it used to
    report an index of 9223372036854775807)."""
    p = tmp_path / "neg.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n")
    with pytest.raises(InvalidInputError, match=r"index -9 is out of range.*down to -3"):
        io.read(p)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -3\n")
    assert io.read(p).faces.tolist() == [[2, 1, 0]]


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs Linux's /proc")
def test_a_folder_that_takes_no_new_file_is_named_not_the_temporary():
    """Writing into /proc failed with 'file not found' naming the hidden temporary file."""
    from spectrageo.geometry import Mesh

    V = np.eye(3)
    with pytest.raises(
        InvalidInputError, match=r"cannot write /proc/x\.ply: the folder /proc"
    ) as e:
        io.write("/proc/x.ply", Mesh(V, np.array([[0, 1, 2]])))
    assert "spectrageo-tmp" not in str(e.value)


def test_npz_that_is_not_a_zip_says_so(tmp_path):
    p = tmp_path / "garbage.npz"
    p.write_bytes(b"\x00\x01not an archive at all" * 10)
    with pytest.raises(InvalidInputError, match=r"not a zip archive of \.npy arrays") as e:
        io.read(p)
    assert "pickled" not in str(e.value)
