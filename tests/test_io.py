"""Round trips and layout guarantees of spectrageo.io (order and counts exact, values close)."""

from __future__ import annotations

import gzip
import io as pyio
import os
import stat

import numpy as np
import pytest

from spectrageo import InvalidInputError, io
from spectrageo.geometry import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from spectrageo.geometry.repair import merge_duplicate_vertices

from conftest import grid, icosphere


# ----------------------------------------------------------------------------------- fixtures
@pytest.fixture
def rich_mesh():
    """Icosphere with normals, RGBA colours, scalar/int/list vertex attributes and face attributes."""
    V, F = icosphere(2)
    rng = np.random.default_rng(1)
    n, m = len(V), len(F)
    return Mesh(
        V,
        F,
        vertex_normals=V / np.linalg.norm(V, axis=1, keepdims=True),
        vertex_colors=rng.integers(0, 256, (n, 4)).astype(np.uint8),
        vertex_attributes={
            "quality": rng.random(n),
            "label": rng.integers(-50, 50, n).astype(np.int32),
            "uv": rng.random((n, 2)).astype(np.float32),
            "flag": rng.random(n) > 0.5,
        },
        face_attributes={"saliency": rng.random(m).astype(np.float32), "id": np.arange(m)},
    )


@pytest.fixture
def rich_cloud():
    rng = np.random.default_rng(2)
    n = 500
    P = rng.normal(size=(n, 3)) * [3.0, 1.0, 0.5] + [10.0, -4.0, 2.0]
    N = rng.normal(size=(n, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    return PointCloud(
        P,
        N,
        rng.integers(0, 256, (n, 3)).astype(np.uint8),
        {
            "intensity": rng.random(n).astype(np.float32),
            "label": rng.integers(0, 7, n).astype(np.uint8),
            "feat": rng.random((n, 4)),
        },
    )


def _same_mesh_layout(a: Mesh, V, F):
    assert a.n_vertices == len(V) and a.n_faces == len(F)
    np.testing.assert_array_equal(a.faces, F)


# ------------------------------------------------------------------------------------------ PLY
@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("suffix", [".ply", ".ply.gz"])
def test_ply_mesh_roundtrip_keeps_everything(tmp_path, rich_mesh, binary, suffix):
    path = tmp_path / f"m{suffix}"
    io.write(path, rich_mesh, binary=binary)
    head = gzip.decompress(path.read_bytes()) if suffix.endswith(".gz") else path.read_bytes()
    assert head.startswith(b"ply\nformat " + (b"binary_little_endian" if binary else b"ascii"))
    m = io.read(path)
    assert isinstance(m, Mesh)
    _same_mesh_layout(m, rich_mesh.vertices, rich_mesh.faces)
    np.testing.assert_array_equal(m.vertices, rich_mesh.vertices)  # float64 by default: exact
    np.testing.assert_array_equal(m.vertex_normals, rich_mesh.vertex_normals)
    np.testing.assert_array_equal(m.vertex_colors, rich_mesh.vertex_colors)
    assert m.vertex_colors.dtype == np.uint8
    va, ref = m.vertex_attributes, rich_mesh.vertex_attributes
    assert set(va) == set(ref)
    np.testing.assert_array_equal(va["quality"], ref["quality"])
    np.testing.assert_array_equal(va["label"], ref["label"])
    assert va["label"].dtype == np.int32
    np.testing.assert_array_equal(va["uv"], ref["uv"])
    assert va["uv"].shape == (rich_mesh.n_vertices, 2) and va["uv"].dtype == np.float32
    np.testing.assert_array_equal(va["flag"].astype(bool), ref["flag"])
    np.testing.assert_array_equal(
        m.face_attributes["saliency"], rich_mesh.face_attributes["saliency"]
    )
    np.testing.assert_array_equal(m.face_attributes["id"], np.arange(rich_mesh.n_faces))


def test_ply_float32_option(tmp_path, rich_mesh):
    path = tmp_path / "m.ply"
    io.write(path, Mesh(rich_mesh.vertices, rich_mesh.faces), dtype=np.float32)
    assert b"property float x" in path.read_bytes()[:300]
    m = io.read_mesh(path)
    np.testing.assert_array_equal(m.vertices, rich_mesh.vertices.astype(np.float32))


def test_ply_binary_body_matches_plyfile_writer(rich_mesh):
    import plyfile

    from spectrageo.io import _ply

    ours = _ply.write_ply(
        rich_mesh.vertices,
        rich_mesh.faces,
        normals=rich_mesh.vertex_normals,
        vertex_attributes={"uv": rich_mesh.vertex_attributes["uv"]},
        binary=True,
    )
    # the same structured arrays written by plyfile's own (row-by-row) writer
    cols = _ply._vertex_columns(
        rich_mesh.vertices,
        rich_mesh.vertex_normals,
        None,
        {"uv": rich_mesh.vertex_attributes["uv"]},
        np.float64,
    )
    varr = _ply._element_table(cols, rich_mesh.n_vertices, {})
    farr = _ply._element_table(
        [("vertex_indices", rich_mesh.faces.astype(np.int32))], rich_mesh.n_faces, {}
    )
    buf = pyio.BytesIO()
    plyfile.PlyData(
        [plyfile.PlyElement.describe(varr, "vertex"), plyfile.PlyElement.describe(farr, "face")],
        text=False,
        byte_order="<",
        comments=["spectrageo"],
    ).write(buf)
    assert buf.getvalue() == ours


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_polygons_are_fanned_in_order(tmp_path, fmt):
    """Mixed triangle/quad/pentagon faces: fans in file order, face properties repeated."""
    V = np.random.default_rng(3).random((7, 3))
    polys = [[0, 1, 2, 3], [2, 3, 4], [0, 4, 5, 6, 1]]
    q = [1.5, 2.5, 3.5]
    header = (
        f"ply\nformat {fmt} 1.0\nelement vertex 7\nproperty double x\nproperty double y\n"
        "property double z\nelement face 3\nproperty list uchar int vertex_indices\n"
        "property float q\nend_header\n"
    ).encode()
    if fmt == "ascii":
        body = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in V)
        body += "".join(f"{len(p)} {' '.join(map(str, p))} {v}\n" for p, v in zip(polys, q))
        data = header + body.encode()
    else:  # written byte by byte (plyfile's own writer mixes byte orders for such rows)
        e = "<" if fmt == "binary_little_endian" else ">"
        data = header + V.astype(e + "f8").tobytes()
        for p, v in zip(polys, q):
            data += (
                bytes([len(p)])
                + np.array(p, e + "i4").tobytes()
                + np.array([v], e + "f4").tobytes()
            )
    path = tmp_path / "poly.ply"
    path.write_bytes(data)
    m = io.read_mesh(path)
    expected = [[0, 1, 2], [0, 2, 3], [2, 3, 4], [0, 4, 5], [0, 5, 6], [0, 6, 1]]
    np.testing.assert_array_equal(m.faces, expected)
    np.testing.assert_array_equal(m.face_attributes["q"], [1.5, 1.5, 2.5, 3.5, 3.5, 3.5])
    np.testing.assert_array_equal(m.vertices, V)


def test_ply_fast_paths_agree_with_plyfile(tmp_path, rich_mesh):
    """The vectorised decoders give exactly what plyfile's own reader gives."""
    from spectrageo.io import _ply

    for binary in (True, False):
        raw = _ply.write_ply(
            rich_mesh.vertices,
            rich_mesh.faces,
            colors=rich_mesh.vertex_colors,
            vertex_attributes=rich_mesh.vertex_attributes,
            face_attributes=rich_mesh.face_attributes,
            binary=binary,
        )
        header, offset = _ply._parse_header(raw, "x.ply")
        fast = (_ply._binary_elements if binary else _ply._ascii_elements)(
            raw, header, offset, "x.ply"
        )
        slow = _ply._read_full_plyfile(raw, "x.ply")
        assert fast is not None and fast.keys() == slow.keys()
        for el in fast:
            assert fast[el].keys() == slow[el].keys()
            for k in fast[el]:
                np.testing.assert_array_equal(fast[el][k], slow[el][k])


def test_ply_point_cloud_and_extra_elements(tmp_path, rich_cloud):
    path = tmp_path / "p.ply"
    io.write(path, rich_cloud)
    pc = io.read(path)
    assert isinstance(pc, PointCloud) and pc.n_points == rich_cloud.n_points
    np.testing.assert_array_equal(pc.points, rich_cloud.points)
    np.testing.assert_array_equal(pc.normals, rich_cloud.normals)
    np.testing.assert_array_equal(pc.colors, rich_cloud.colors)
    for k, v in rich_cloud.attributes.items():
        np.testing.assert_array_equal(pc.attributes[k], v)
    # an element the reader does not use (range grid with variable-length lists) is skipped
    text = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement range_grid 4\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n1 0\n0\n1 2\n0\n"
    )
    (tmp_path / "rg.ply").write_text(text)
    pc = io.read(tmp_path / "rg.ply")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_ply_zero_faces_is_point_cloud(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
        "1 2 3\n4 5 6\n"
    )
    (tmp_path / "pts.ply").write_text(text)
    pc = io.read(tmp_path / "pts.ply")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, [[1, 2, 3], [4, 5, 6]])


# ------------------------------------------------------------------------------------------ OBJ
@pytest.mark.parametrize("suffix", [".obj", ".obj.gz"])
def test_obj_roundtrip(tmp_path, rich_mesh, suffix):
    path = tmp_path / f"m{suffix}"
    io.write(path, rich_mesh)
    m = io.read_mesh(path)
    _same_mesh_layout(m, rich_mesh.vertices, rich_mesh.faces)
    np.testing.assert_array_equal(m.vertices, rich_mesh.vertices)
    np.testing.assert_allclose(m.vertex_normals, rich_mesh.vertex_normals)


def test_obj_conventions(tmp_path):
    text = """# polygons, colours, texture coords and relative indices
v 0 0 0 1 0 0
v 1 0 0 0 1 0
v 1 1 0 0 0 1
v 0 1 0 1 1 1
v 2 0 0 0 0 0
vt 0 0
vt 1 0
vt 1 1
f 1/1 2/2 3/3 4/1
f -4 -1 -3
g second
usemtl stuff
f 2 5 3
v 9 9 9 0 0 0
"""
    (tmp_path / "c.obj").write_text(text)
    m = io.read_mesh(tmp_path / "c.obj")
    # 6 vertices in file order (the trailing one is unreferenced and kept)
    assert m.n_vertices == 6
    np.testing.assert_array_equal(m.vertices[5], [9, 9, 9])
    # quad fanned in place, relative face resolved against the vertex count, order kept
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [2, 5, 3], [1, 4, 2]])
    np.testing.assert_allclose(m.vertex_colors[:4], [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])


def test_obj_integer_colours_and_points_only(tmp_path):
    (tmp_path / "c.obj").write_text("v 0 0 0 255 0 10\nv 1 0 0 0 128 0\nv 0 1 0 1 2 3\nf 1 2 3\n")
    m = io.read_mesh(tmp_path / "c.obj")
    assert m.vertex_colors.dtype == np.uint8
    np.testing.assert_array_equal(m.vertex_colors[0], [255, 0, 10])
    (tmp_path / "p.obj").write_text("v 0 0 0\nv 1 2 3\n")
    pc = io.read(tmp_path / "p.obj")
    assert isinstance(pc, PointCloud) and pc.n_points == 2


def test_obj_one_normal_per_vertex_becomes_vertex_normals(tmp_path):
    # every vertex uses one normal (here the same one): per-vertex normals, not corner normals
    (tmp_path / "a.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n")
    m = io.read_mesh(tmp_path / "a.obj")
    assert m.n_vertices == 3 and "corner_normals" not in m.face_attributes
    np.testing.assert_array_equal(m.vertex_normals, [[0, 0, 1]] * 3)


# ------------------------------------------------------------------------------------------ OFF
@pytest.mark.parametrize("suffix", [".off", ".off.gz"])
def test_off_roundtrip(tmp_path, rich_mesh, suffix):
    path = tmp_path / f"m{suffix}"
    io.write(path, rich_mesh)
    m = io.read_mesh(path)
    _same_mesh_layout(m, rich_mesh.vertices, rich_mesh.faces)
    np.testing.assert_array_equal(m.vertices, rich_mesh.vertices)


def test_off_variants(tmp_path):
    coff = """COFF
# comment line
5 3 0
0 0 0 255 0 0 255
1 0 0 0 255 0 255
1 1 0 0 0 255 255
0 1 0 10 20 30 255
2 2 2 1 2 3 4
4 0 1 2 3
3 1 4 2  # trailing comment
5 0 1 4 2 3 0.5 0.5 0.5
"""
    (tmp_path / "c.off").write_text(coff)
    m = io.read_mesh(tmp_path / "c.off")
    np.testing.assert_array_equal(
        m.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2], [0, 1, 4], [0, 4, 2], [0, 2, 3]]
    )
    assert m.vertex_colors.dtype == np.uint8 and m.vertex_colors.shape == (5, 4)
    np.testing.assert_array_equal(m.vertex_colors[3], [10, 20, 30, 255])
    (tmp_path / "n.off").write_text("NOFF 3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n")
    m = io.read_mesh(tmp_path / "n.off")
    np.testing.assert_array_equal(m.vertex_normals, np.tile([0, 0, 1.0], (3, 1)))
    (tmp_path / "p.off").write_text("OFF\n2 0 0\n1 2 3\n4 5 6\n")
    assert isinstance(io.read(tmp_path / "p.off"), PointCloud)


# ------------------------------------------------------------------------------------------ STL
@pytest.mark.parametrize("binary", [True, False])
def test_stl_roundtrip_unwelded_and_welded(tmp_path, binary):
    V, F = icosphere(2)
    path = tmp_path / "m.stl"
    io.write(path, Mesh(V, F), binary=binary)
    raw = io.read_mesh(path, weld=False)
    # weld=False: each triangle keeps its own 3 corners, in file order
    assert raw.n_vertices == 3 * len(F) and raw.n_faces == len(F)
    np.testing.assert_array_equal(raw.faces, np.arange(3 * len(F)).reshape(-1, 3))
    tol = 1e-6 if binary else 0.0
    np.testing.assert_allclose(raw.vertices.reshape(-1, 3, 3), V[F], atol=tol)
    welded = io.read_mesh(path)  # default: STL is welded
    assert welded.n_vertices == len(V) and welded.n_faces == len(F)
    np.testing.assert_allclose(welded.vertices[welded.faces], V[F], atol=tol)
    # weld keeps first occurrences in corner order, as merge_duplicate_vertices does
    Vw, Fw, _ = merge_duplicate_vertices(raw.vertices, raw.faces)
    np.testing.assert_array_equal(welded.vertices, Vw)
    np.testing.assert_array_equal(welded.faces, Fw)


def test_stl_gz(tmp_path):
    V, F = grid(4, 4)
    io.write(tmp_path / "g.stl.gz", Mesh(V, F))
    m = io.read_mesh(tmp_path / "g.stl.gz", weld=True)
    assert m.n_vertices == 16 and m.n_faces == len(F)


def test_weld_keeps_first_occurrence_attributes(tmp_path):
    # two coincident vertices (0 and 3) with different qualities: the first one's value is kept
    text = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
        "property double z\nproperty float quality\nelement face 2\n"
        "property list uchar int vertex_indices\nend_header\n"
        "0 0 0 1\n1 0 0 2\n0 1 0 3\n0 0 0 4\n3 0 1 2\n3 3 2 1\n"
    )
    (tmp_path / "d.ply").write_text(text)
    keep = io.read_mesh(tmp_path / "d.ply")
    assert keep.n_vertices == 4  # default: duplicates preserved
    w = io.read_mesh(tmp_path / "d.ply", weld=True)
    assert w.n_vertices == 3
    np.testing.assert_array_equal(w.faces, [[0, 1, 2], [0, 2, 1]])
    np.testing.assert_array_equal(w.vertex_attributes["quality"], [1, 2, 3])


# ------------------------------------------------------------------------------------------ PCD
@pytest.mark.parametrize("pcd_format", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("suffix", [".pcd", ".pcd.gz"])
def test_pcd_roundtrip(tmp_path, rich_cloud, pcd_format, suffix):
    path = tmp_path / f"p{suffix}"
    io.write(path, rich_cloud, pcd_format=pcd_format)
    raw = gzip.decompress(path.read_bytes()) if suffix.endswith(".gz") else path.read_bytes()
    assert f"DATA {pcd_format}\n".encode() in raw[:600]
    pc = io.read(path)
    assert pc.n_points == rich_cloud.n_points
    # float64 coordinates kept by default (they do not round-trip through float32, PCL's type)
    np.testing.assert_array_equal(pc.points, rich_cloud.points)
    np.testing.assert_array_equal(pc.normals, rich_cloud.normals.astype(np.float32))
    np.testing.assert_array_equal(pc.colors, rich_cloud.colors)
    np.testing.assert_array_equal(pc.attributes["intensity"], rich_cloud.attributes["intensity"])
    np.testing.assert_array_equal(pc.attributes["label"], rich_cloud.attributes["label"])
    assert pc.attributes["label"].dtype == np.uint8
    np.testing.assert_array_equal(pc.attributes["feat"], rich_cloud.attributes["feat"])
    assert pc.attributes["feat"].shape == (rich_cloud.n_points, 4)


@pytest.mark.parametrize("pcd_format", ["ascii", "binary", "binary_compressed"])
def test_pcd_float64_and_rgba(tmp_path, pcd_format):
    rng = np.random.default_rng(4)
    P = rng.random((50, 3))
    C = rng.integers(0, 256, (50, 4)).astype(np.uint8)
    C[:, 3] = np.maximum(C[:, 3], 1)
    path = tmp_path / "p.pcd"
    io.write(path, PointCloud(P, colors=C), pcd_format=pcd_format, dtype=np.float64)
    pc = io.read(path)
    np.testing.assert_array_equal(pc.points, P)
    np.testing.assert_array_equal(pc.colors, C)


def test_pcd_binary_compressed_layout_is_structure_of_arrays(tmp_path):
    """Decode an LZF block built independently: all x, then all y, then all z, then intensity."""
    import struct

    import lzf

    P = np.arange(12, dtype=np.float32).reshape(4, 3)
    inten = np.array([5, 6, 7, 8], dtype=np.uint16)
    soa = P[:, 0].tobytes() + P[:, 1].tobytes() + P[:, 2].tobytes() + inten.tobytes()
    comp = lzf.compress(soa, len(soa) + 64)
    header = (
        "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        "WIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary_compressed\n"
    )
    path = tmp_path / "c.pcd"
    path.write_bytes(header.encode() + struct.pack("<II", len(comp), len(soa)) + comp)
    pc = io.read(path)
    np.testing.assert_array_equal(pc.points, P)
    np.testing.assert_array_equal(pc.attributes["intensity"], inten)


def test_pcd_organized_nan_points(tmp_path):
    P = np.arange(18, dtype=np.float64).reshape(6, 3)
    P[[1, 4]] = np.nan
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 2\n"
        "POINTS 6\nDATA binary\n"
    )
    path = tmp_path / "org.pcd"
    path.write_bytes(header.encode() + P.astype("<f4").tobytes())
    pc = io.read(path)  # PCD default: NaN marks "no measurement" -> dropped
    np.testing.assert_array_equal(pc.points, P[[0, 2, 3, 5]])
    np.testing.assert_array_equal(pc.attributes["source_index"], [0, 2, 3, 5])
    with pytest.raises(InvalidInputError, match="2 of 6 points have NaN"):
        io.read(path, nan_points="raise")


def test_pcd_ascii_packed_rgb_float_and_integer(tmp_path):
    """ascii rgb as an integer bit pattern (PCL >= 1.7) or as the float's value (older writers)."""
    packed = (10 << 16) | (20 << 8) | 30
    as_float = np.array([packed], dtype=np.uint32).view(np.float32)[0]
    body = f"0 0 0 {packed}\n1 1 1 {float(as_float)!r}\n"
    header = (
        "VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\n"
        "HEIGHT 1\nPOINTS 2\nDATA ascii\n"
    )
    (tmp_path / "c.pcd").write_text(header + body)
    pc = io.read(tmp_path / "c.pcd")
    np.testing.assert_array_equal(pc.colors, [[10, 20, 30], [10, 20, 30]])


# ---------------------------------------------------------------------------------- XYZ / NPY
@pytest.mark.parametrize("suffix", [".xyz", ".xyz.gz"])
def test_xyz_roundtrip(tmp_path, rich_cloud, suffix):
    io.write(tmp_path / f"a{suffix}", rich_cloud)
    pc = io.read(tmp_path / f"a{suffix}")
    np.testing.assert_array_equal(pc.points, rich_cloud.points)
    np.testing.assert_array_equal(pc.normals, rich_cloud.normals)
    io.write(tmp_path / "b.xyz", PointCloud(rich_cloud.points))
    pc = io.read(tmp_path / "b.xyz")
    assert pc.normals is None
    np.testing.assert_array_equal(pc.points, rich_cloud.points)
    (tmp_path / "c.xyz").write_text("# header comment\n1 2 3\n\n4 5 6\n")
    np.testing.assert_array_equal(io.read(tmp_path / "c.xyz").points, [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("suffix", [".npy", ".npy.gz"])
def test_npy_roundtrip(tmp_path, rich_cloud, suffix):
    io.write(tmp_path / f"a{suffix}", rich_cloud)
    pc = io.read(tmp_path / f"a{suffix}")
    np.testing.assert_array_equal(pc.points, rich_cloud.points)
    np.save(tmp_path / "i.npy", np.arange(12, dtype=np.int32).reshape(4, 3))
    np.testing.assert_array_equal(io.read(tmp_path / "i.npy").points, np.arange(12).reshape(4, 3))
    io.write(tmp_path / "arr.npy", rich_cloud.points)  # plain arrays are point clouds
    np.testing.assert_array_equal(np.load(tmp_path / "arr.npy"), rich_cloud.points)


# ---------------------------------------------------------------------------------- LAS / LAZ
@pytest.mark.parametrize("suffix", [".las", ".laz", ".las.gz"])
def test_las_roundtrip(tmp_path, rich_cloud, suffix):
    pytest.importorskip("laspy")
    if suffix == ".laz":
        pytest.importorskip("lazrs")
    n = rich_cloud.n_points
    rng = np.random.default_rng(5)
    attrs = {
        "intensity": rng.integers(0, 60000, n).astype(np.uint16),
        "classification": rng.integers(0, 20, n).astype(np.uint8),
        "gps_time": rng.random(n) * 1e5,
        "score": rng.random(n).astype(np.float32),
    }
    pc = PointCloud(rich_cloud.points, rich_cloud.normals, rich_cloud.colors, attrs)
    io.write(tmp_path / f"p{suffix}", pc)
    back = io.read(tmp_path / f"p{suffix}")
    assert back.n_points == n
    extent = np.ptp(pc.points, axis=0).max()
    scale = 10.0 ** np.ceil(np.log10(extent / 2e9))
    np.testing.assert_allclose(back.points, pc.points, rtol=0, atol=scale)
    np.testing.assert_array_equal(back.colors, pc.colors)
    np.testing.assert_array_equal(back.normals, pc.normals)
    for k, v in attrs.items():
        np.testing.assert_array_equal(back.attributes[k], v)


def test_las_explicit_scale(tmp_path):
    pytest.importorskip("laspy")
    P = np.random.default_rng(6).random((20, 3)) * 100
    io.write(tmp_path / "p.las", PointCloud(P), las_scale=0.01)
    back = io.read(tmp_path / "p.las")
    np.testing.assert_allclose(back.points, P, atol=0.005 + 1e-9)
    assert not np.allclose(back.points, P, atol=1e-6)


# ---------------------------------------------------------------------------------- gz generic
@pytest.mark.parametrize("ext", [".ply", ".obj", ".off", ".stl"])
def test_gz_equals_plain(tmp_path, rich_mesh, ext):
    io.write(tmp_path / f"a{ext}", rich_mesh)
    io.write(tmp_path / f"a{ext}.gz", rich_mesh)
    gz = (tmp_path / f"a{ext}.gz").read_bytes()
    assert gz[:2] == b"\x1f\x8b"
    plain, unzipped = (tmp_path / f"a{ext}").read_bytes(), gzip.decompress(gz)
    if ext == ".obj":  # meshio writes a time stamp on the first line
        plain, unzipped = plain.split(b"\n", 1)[1], unzipped.split(b"\n", 1)[1]
    assert unzipped == plain
    a, b = io.read(tmp_path / f"a{ext}"), io.read(tmp_path / f"a{ext}.gz")
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)


# ------------------------------------------------------------------------------- kind forcing
def test_kind_points_reads_mesh_vertices(tmp_path, rich_mesh):
    io.write(tmp_path / "m.ply", rich_mesh)
    pc = io.read_point_cloud(tmp_path / "m.ply")
    assert isinstance(pc, PointCloud)
    np.testing.assert_array_equal(pc.points, rich_mesh.vertices)
    np.testing.assert_array_equal(pc.normals, rich_mesh.vertex_normals)
    np.testing.assert_array_equal(pc.colors, rich_mesh.vertex_colors)
    np.testing.assert_array_equal(pc.attributes["quality"], rich_mesh.vertex_attributes["quality"])
    assert isinstance(io.read(tmp_path / "m.ply", kind="mesh"), Mesh)


def test_format_override(tmp_path):
    (tmp_path / "pts.txt").write_text("1 2 3\n4 5 6\n")
    pc = io.read(tmp_path / "pts.txt", format="xyz")
    np.testing.assert_array_equal(pc.points, [[1, 2, 3], [4, 5, 6]])


def test_readers_preserve_degenerate_duplicate_unreferenced(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [5, 5, 5.0]])
    F = np.array([[0, 1, 2], [0, 1, 1], [3, 1, 2], [0, 1, 2]])  # degenerate + duplicate faces
    for ext in (".ply", ".obj", ".off"):
        io.write(tmp_path / f"d{ext}", Mesh(V, F))
        m = io.read_mesh(tmp_path / f"d{ext}")
        np.testing.assert_array_equal(m.vertices, V)
        np.testing.assert_array_equal(m.faces, F)


# ------------------------------------------------------------------------------- animations
@pytest.mark.parametrize("compress", [False, True])
def test_npz_animation_roundtrip(tmp_path, compress):
    V, F = icosphere(1)
    frames = np.stack([V, 1.5 * V, V + [0, 0, 1]])
    io.write(tmp_path / "a.npz", MeshAnimation(frames, F), compress=compress)
    a = io.read(tmp_path / "a.npz")
    assert isinstance(a, MeshAnimation)
    np.testing.assert_array_equal(a.frames, frames)
    np.testing.assert_array_equal(a.faces, F)
    with np.load(tmp_path / "a.npz") as d:
        assert set(d.files) == {"vertices", "faces"}


def test_npz_animation_shared_layout(tmp_path):
    """float32 vertices, int32 faces and extra keys (frame_names), as in the shared data."""
    V, F = icosphere(1)
    np.savez(
        tmp_path / "s.npz",
        vertices=np.stack([V, V]).astype(np.float32),
        faces=F.astype(np.int32),
        frame_names=np.array(["a", "b"]),
    )
    a = io.read_animation(tmp_path / "s.npz")
    assert a.n_frames == 2 and a.frames.dtype == np.float64
    np.testing.assert_array_equal(a.faces, F)
    seq = io.read_sequence(tmp_path / "s.npz")
    assert isinstance(seq, PointCloudSequence) and seq.n_points == [len(V)] * 2


def test_npz_sequences(tmp_path):
    rng = np.random.default_rng(7)
    fixed = PointCloudSequence([PointCloud(rng.random((10, 3))) for _ in range(3)])
    io.write(tmp_path / "f.npz", fixed)
    back = io.read(tmp_path / "f.npz")
    np.testing.assert_array_equal(back.as_array(), fixed.as_array())
    var = [PointCloud(rng.random((k, 3))) for k in (5, 9, 2)]
    io.write(tmp_path / "v.npz.gz", var)  # a list of clouds is a sequence
    back = io.read(tmp_path / "v.npz.gz")
    assert back.n_points == [5, 9, 2]
    for a, b in zip(back, var):
        np.testing.assert_array_equal(a.points, b.points)


@pytest.mark.parametrize("frame_format", [None, ".obj", "off", ".ply.gz"])
def test_frame_folder_animation_roundtrip(tmp_path, frame_format):
    V, F = icosphere(1)
    frames = np.stack([V * (1 + 0.1 * t) for t in range(12)])
    target = tmp_path / "anim"
    kw = {} if frame_format is None else {"frame_format": frame_format}
    io.write(target, MeshAnimation(frames, F), **kw)
    ext = "." + (frame_format or ".ply").lstrip(".")
    names = sorted(os.listdir(target))
    assert names == [f"frame_{t:03d}{ext}" for t in range(12)]
    a = io.read(target)
    assert isinstance(a, MeshAnimation) and a.n_frames == 12
    np.testing.assert_array_equal(a.frames, frames)
    np.testing.assert_array_equal(a.faces, F)
    # rewriting a shorter animation into the same folder removes the stale frames
    io.write(str(target) + "/", MeshAnimation(frames[:3], F), **kw)
    assert len(os.listdir(target)) == 3
    np.testing.assert_array_equal(io.read_animation(target).frames, frames[:3])


def test_frame_folder_natural_order(tmp_path):
    V, F = icosphere(0)
    d = tmp_path / "frames"
    d.mkdir()
    for t in (10, 2, 1, 33):
        io.write(d / f"frame_{t}.obj", Mesh(V + t, F))
    (d / "notes.txt").write_text("not a frame")
    a = io.read(d)
    np.testing.assert_array_equal(a.frames[:, 0, 0] - V[0, 0], [1, 2, 10, 33])


def test_sequence_folder(tmp_path):
    rng = np.random.default_rng(8)
    seq = PointCloudSequence(
        [
            PointCloud(rng.random((k, 3)), colors=rng.integers(0, 256, (k, 3)).astype(np.uint8))
            for k in (7, 4, 9)
        ]
    )
    for fmt in (".ply", ".pcd", ".xyz", ".npy"):
        target = tmp_path / f"seq{fmt.replace('.', '_')}"
        io.write(target, seq, frame_format=fmt, prefix="scan")
        back = io.read(target)
        assert isinstance(back, PointCloudSequence) and back.n_points == [7, 4, 9]
        for a, b in zip(back, seq):
            np.testing.assert_allclose(a.points, b.points, atol=1e-6)
    # a folder of mesh frames read as a sequence of vertex clouds
    V, F = icosphere(0)
    io.write(tmp_path / "anim", MeshAnimation(np.stack([V, V]), F))
    s = io.read_sequence(tmp_path / "anim")
    assert isinstance(s, PointCloudSequence) and s.n_points == [len(V), len(V)]


# ------------------------------------------------------------------------------- atomic write
def test_atomic_write_replaces_and_cleans(tmp_path):
    target = tmp_path / "out.npy"
    target.write_bytes(b"old")
    with io.atomic_write(target) as tmp:
        assert tmp.parent == tmp_path and tmp.name.endswith(".npy") and tmp != target
        np.save(tmp, np.arange(3))
        assert target.read_bytes() == b"old"  # untouched until the block ends
    np.testing.assert_array_equal(np.load(target), np.arange(3))
    assert sorted(os.listdir(tmp_path)) == ["out.npy"]
    mode = stat.S_IMODE(target.stat().st_mode)
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask


def test_supported_formats():
    f = io.supported_formats()
    for ext in (".ply", ".obj", ".off", ".stl", ".pcd", ".xyz", ".npy", ".las", ".laz", ".npz"):
        assert ext in f["read"]
    assert set(f["write"]["mesh"]) == {".ply", ".obj", ".off", ".stl"}
    assert {".ply", ".pcd", ".xyz", ".npy", ".las", ".laz"} <= set(f["write"]["points"])
    assert ".npz" in f["write"]["animation"] and f["compression"] == [".gz"]


def test_embedded_fandisk_reads():
    from spectrageo.datasets import fandisk

    m = fandisk()
    assert m.n_vertices == 6475 and m.n_faces == 12946


def test_float_colours_are_quantised_for_pcd_and_las(tmp_path):
    rng = np.random.default_rng(9)
    P = rng.random((30, 3))
    C = rng.random((30, 3))
    io.write(tmp_path / "c.pcd", PointCloud(P, colors=C))
    np.testing.assert_array_equal(io.read(tmp_path / "c.pcd").colors, np.round(C * 255))
    pytest.importorskip("laspy")
    io.write(tmp_path / "c.las", PointCloud(P, colors=C))
    # 16-bit in the file, back to 8 bits on reading
    np.testing.assert_array_equal(io.read(tmp_path / "c.las").colors, np.round(C * 65535) // 256)


def test_ply_alternative_property_names(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nproperty float normal_x\nproperty float normal_y\nproperty float normal_z\n"
        "property uchar diffuse_red\nproperty uchar diffuse_green\nproperty uchar diffuse_blue\n"
        "end_header\n0 0 0 0 0 1 10 20 30\n1 1 1 0 1 0 40 50 60\n"
    )
    (tmp_path / "alt.ply").write_text(text)
    pc = io.read(tmp_path / "alt.ply")
    np.testing.assert_array_equal(pc.normals, [[0, 0, 1], [0, 1, 0]])
    np.testing.assert_array_equal(pc.colors, [[10, 20, 30], [40, 50, 60]])
    assert pc.attributes == {}


def test_pcd_padding_and_unset_alpha(tmp_path):
    """'_' padding fields are dropped; rgba whose alpha bytes are all 0 gives 3 channels."""
    rec = np.zeros(
        2, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_", "<u4"), ("rgba", "<u4")]
    )
    rec["x"] = [1, 2]
    rec["_"] = 0xDEADBEEF
    rec["rgba"] = [(1 << 16) | (2 << 8) | 3, (4 << 16) | (5 << 8) | 6]
    header = (
        "VERSION 0.7\nFIELDS x y z _ rgba\nSIZE 4 4 4 4 4\nTYPE F F F U U\nCOUNT 1 1 1 1 1\n"
        "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n"
    )
    (tmp_path / "p.pcd").write_bytes(header.encode() + rec.tobytes())
    pc = io.read(tmp_path / "p.pcd")
    np.testing.assert_array_equal(pc.points[:, 0], [1, 2])
    np.testing.assert_array_equal(pc.colors, [[1, 2, 3], [4, 5, 6]])
    assert pc.attributes == {}
