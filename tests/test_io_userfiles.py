"""Files as users have them: PLY triangle strips, OBJ texture coordinates and split normals, PCD with
georeferenced coordinates, XYZ with extra columns, glTF/GLB and 3MF scenes."""

from __future__ import annotations

import io as pyio
import json
import struct
import zipfile

import numpy as np
import pytest
import trimesh

from spectrageo import InvalidInputError, io
from spectrageo.geometry import Mesh, PointCloud

from conftest import icosphere, shared_file


def put(tmp_path, name, content):
    p = tmp_path / name
    p.write_bytes(content if isinstance(content, bytes) else content.encode())
    return p


def face_normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# ------------------------------------------------------------------------------ PLY tristrips
def _grid_strip(nx=5):
    """Two rows of vertices (y=0 and y=1) and one zig-zag strip over them: 2*(nx-1) triangles."""
    V = np.array([[i, j, 0.0] for i in range(nx) for j in (0, 1)])
    strip = np.arange(2 * nx)  # 0(0,0) 1(0,1) 2(1,0) 3(1,1) ...
    return V, strip


def _ply_strips(V, rows, fmt):
    head = (
        f"ply\nformat {fmt} 1.0\ncomment range scan\nelement vertex {len(V)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element tristrips {len(rows)}\nproperty list int int vertex_indices\nend_header\n"
    ).encode()
    if fmt == "ascii":
        body = "".join(f"{x:g} {y:g} {z:g}\n" for x, y, z in V)
        body += "".join(f"{len(r)} " + " ".join(map(str, r)) + "\n" for r in rows)
        return head + body.encode()
    body = np.asarray(V, "<f4").tobytes()
    for r in rows:
        body += struct.pack("<i", len(r)) + np.asarray(r, "<i4").tobytes()
    return head + body


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_tristrips_alternate_winding(tmp_path, fmt):
    V, strip = _grid_strip(5)
    m = io.read(put(tmp_path, "scan.ply", _ply_strips(V, [strip], fmt)))
    assert isinstance(m, Mesh) and m.n_faces == 8
    # alternate winding: every triangle of the strip faces the same way
    n = face_normals(m.vertices, m.faces)
    np.testing.assert_allclose(n, np.tile(n[0], (8, 1)))
    np.testing.assert_array_equal(m.faces[:3], [[0, 1, 2], [2, 1, 3], [2, 3, 4]])


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_tristrips_restart_and_degenerate(tmp_path, fmt):
    V, _ = _grid_strip(5)
    # -1 restarts; the repeated 3 (a parity swap) makes two degenerate triangles that are skipped;
    # a second row of another length is its own strip (variable-length lists: plyfile fallback)
    rows = [[0, 1, 2, 3, -1, 4, 5, 6, 7, 7, 8], [2, 3, 4]]
    m = io.read(put(tmp_path, "s.ply", _ply_strips(V, rows, fmt)))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [2, 1, 3], [4, 5, 6], [6, 5, 7], [2, 3, 4]])
    assert not any(len(set(f)) < 3 for f in m.faces.tolist())


def test_ply_tristrips_reads_like_faces(tmp_path):
    """Same triangles as the equivalent 'face' element file, through the public reader."""
    V, strip = _grid_strip(6)
    strips = io.read(put(tmp_path, "a.ply", _ply_strips(V, [strip], "binary_little_endian")))
    io.write(tmp_path / "b.ply", strips)
    back = io.read(tmp_path / "b.ply")
    np.testing.assert_array_equal(back.faces, strips.faces)
    np.testing.assert_array_equal(back.vertices, V)


def test_ply_tristrips_errors(tmp_path):
    head = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement tristrips 1\nproperty list int int idx\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    with pytest.raises(InvalidInputError, match=r"t.ply: PLY 'tristrips' element has no 'vertex_"):
        io.read(put(tmp_path, "t.ply", head))
    bad = _ply_strips(np.eye(3), [[0, 1, 5]], "ascii")
    with pytest.raises(InvalidInputError, match=r"o.ply: `faces` has vertex indices out of range"):
        io.read(put(tmp_path, "o.ply", bad))


# ------------------------------------------------------------------------------ OBJ vt / vn
QUAD_OBJ = """# a textured quad and a triangle, vt shared unevenly
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
vt 0.0 0.0
vt 1.0 0.0
vt 1.0 1.0
vt 0.0 1.0
vt 0.5 0.25
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
f 2/5/1 5/2/1 3/3/1
"""


def test_obj_texcoords_follow_the_fan(tmp_path):
    m = io.read(put(tmp_path, "q.obj", QUAD_OBJ))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    tc = m.face_attributes["texcoord"]
    assert tc.shape == (3, 6) and tc.dtype == np.float64
    np.testing.assert_array_equal(
        tc, [[0, 0, 1, 0, 1, 1], [0, 0, 1, 1, 0, 1], [0.5, 0.25, 1, 0, 1, 1]]
    )
    # one normal per vertex (all corners point at vn 1): vertex normals, no corner normals
    np.testing.assert_array_equal(m.vertex_normals, np.tile([0, 0, 1.0], (5, 1)))
    assert "corner_normals" not in m.face_attributes


def test_obj_texcoords_roundtrip(tmp_path):
    m = io.read(put(tmp_path, "q.obj", QUAD_OBJ))
    io.write(tmp_path / "out.obj", m)
    text = (tmp_path / "out.obj").read_text()
    assert sum(line.startswith("vt ") for line in text.splitlines()) == 5  # deduplicated
    assert "f 1/1/1 2/2/2 3/3/3" in text
    back = io.read(tmp_path / "out.obj")
    np.testing.assert_array_equal(back.vertices, m.vertices)
    np.testing.assert_array_equal(back.faces, m.faces)
    np.testing.assert_array_equal(back.face_attributes["texcoord"], m.face_attributes["texcoord"])
    np.testing.assert_array_equal(back.vertex_normals, m.vertex_normals)


def test_obj_split_normals_become_corner_normals(tmp_path):
    # vertex 2 has two different normals (a crease): per-corner normals
    text = """v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
vn 0 0 1
vn 1 0 0
f 1//1 2//1 3//1
f 1//2 3//2 4//2
"""
    m = io.read(put(tmp_path, "c.obj", text))
    assert m.vertex_normals is None
    cn = m.face_attributes["corner_normals"]
    assert cn.shape == (2, 9)
    np.testing.assert_array_equal(cn, [[0, 0, 1] * 3, [1, 0, 0] * 3])
    io.write(tmp_path / "c2.obj", m)
    out = (tmp_path / "c2.obj").read_text()
    assert out.count("\nvn ") == 2 and "f 1//1 2//1 3//1" in out and "f 1//2 3//2 4//2" in out
    back = io.read(tmp_path / "c2.obj")
    np.testing.assert_array_equal(back.face_attributes["corner_normals"], cn)


def test_obj_vn_indices_equal_v_indices(tmp_path):
    V, F = icosphere(1)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()] + [
        f"vn {x!r} {y!r} {z!r}" for x, y, z in N.tolist()
    ]
    lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in F + 1]
    m = io.read(put(tmp_path, "s.obj", "\n".join(lines) + "\n"))
    np.testing.assert_array_equal(m.vertex_normals, N)
    assert m.face_attributes == {}


def test_obj_partial_texcoords_are_nan(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0.25 0.5\nf 1/1 2/1 3/1\nf 2 4 3\n"
    m = io.read(put(tmp_path, "p.obj", text))
    tc = m.face_attributes["texcoord"]
    np.testing.assert_array_equal(tc[0], [0.25, 0.5] * 3)
    assert np.isnan(tc[1]).all()
    io.write(tmp_path / "p2.obj", m)
    out = (tmp_path / "p2.obj").read_text()
    assert "f 1/1 2/1 3/1\nf 2 4 3\n" in out


def test_obj_texcoord_ply_interop(tmp_path):
    """The face attribute ``texcoord`` is MeshLab's PLY face property, both ways."""
    m = io.read(put(tmp_path, "q.obj", QUAD_OBJ))
    for binary in (True, False):
        io.write(tmp_path / "q.ply", m, binary=binary)
        head = (tmp_path / "q.ply").read_bytes().split(b"end_header")[0]
        assert b"property list uchar float texcoord" in head
        ply = io.read(tmp_path / "q.ply")
        assert ply.face_attributes["texcoord"].dtype == np.float64
        np.testing.assert_allclose(
            ply.face_attributes["texcoord"], m.face_attributes["texcoord"], atol=1e-7
        )
        io.write(tmp_path / "back.obj", ply)
        back = io.read(tmp_path / "back.obj")
        np.testing.assert_allclose(
            back.face_attributes["texcoord"], m.face_attributes["texcoord"], atol=1e-7
        )


def test_ply_meshlab_quad_texcoord_follows_fan(tmp_path):
    head = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "property list uchar float texcoord\nend_header\n"
    )
    body = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 8 0 0 1 0 1 1 0 1\n"
    m = io.read(put(tmp_path, "mq.ply", head + body))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(
        m.face_attributes["texcoord"], [[0, 0, 1, 0, 1, 1], [0, 0, 1, 1, 0, 1]]
    )


def test_obj_corner_index_errors(tmp_path):
    cases = [
        (
            "n.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//0 3//1\n",
            r"n.obj: OBJ face normal index 0",
        ),
        ("s.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n", r"s.obj: malformed OBJ"),
        (
            "w.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 1\nf 1//1 2//1 3//1\n",
            r"w.obj: OBJ 'vn' lines",
        ),
    ]
    # an out-of-range texture index drops the texture coordinates (the geometry is intact)
    with pytest.warns(UserWarning, match=r"t.obj: OBJ face texture index 2 is out of range"):
        m = io.read(put(tmp_path, "t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n"))
    assert m.n_faces == 1 and "texcoord" not in m.face_attributes
    for name, text, match in cases:
        with pytest.raises(InvalidInputError, match=match):
            io.read(put(tmp_path, name, text))


def test_spot_convert_keeps_texcoords(tmp_path, shared_data):
    src = shared_file(shared_data, "meshes", "spot.obj")
    n_vt = sum(line.startswith("vt ") for line in src.read_text().splitlines())
    out = tmp_path / "spot_out.obj"
    from spectrageo.cli.main import main

    assert main(["convert", str(src), str(out)]) == 0
    assert sum(line.startswith("vt ") for line in out.read_text().splitlines()) == n_vt
    a, b = io.read(src), io.read(out)
    np.testing.assert_array_equal(a.face_attributes["texcoord"], b.face_attributes["texcoord"])
    io.write(tmp_path / "spot.ply", a)
    c = io.read(tmp_path / "spot.ply")
    np.testing.assert_allclose(
        c.face_attributes["texcoord"], a.face_attributes["texcoord"], atol=1e-7
    )


# ---------------------------------------------------------------------------------------- PCD
@pytest.mark.parametrize("pcd_format", ["ascii", "binary", "binary_compressed"])
def test_pcd_utm_coordinates_are_kept(tmp_path, pcd_format):
    rng = np.random.default_rng(0)
    P = np.round(rng.random((200, 3)) * [1000, 1000, 50] + [512345.678, 5401234.567, 250.0], 3)
    N = rng.normal(size=(200, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    io.write(tmp_path / "utm.pcd", PointCloud(P, N), pcd_format=pcd_format)
    head = (tmp_path / "utm.pcd").read_bytes()[:400]
    assert b"SIZE 8 8 8 4 4 4" in head and b"TYPE F F F F F F" in head
    back = io.read(tmp_path / "utm.pcd")
    np.testing.assert_array_equal(back.points, P)
    np.testing.assert_array_equal(back.normals, N.astype(np.float32))
    # the old float32 default moved such points by up to a few centimetres
    assert np.abs(P.astype(np.float32) - P).max() > 0.01


def test_pcd_float32_when_exact_and_explicit_dtype(tmp_path):
    P = np.arange(30, dtype=np.float64).reshape(10, 3) * 0.5
    io.write(tmp_path / "a.pcd", PointCloud(P))
    assert b"SIZE 4 4 4" in (tmp_path / "a.pcd").read_bytes()[:300]
    np.testing.assert_array_equal(io.read(tmp_path / "a.pcd").points, P)
    Q = P + 512345.678
    io.write(tmp_path / "b.pcd", PointCloud(Q), dtype=np.float32)  # explicit: obeyed
    assert b"SIZE 4 4 4" in (tmp_path / "b.pcd").read_bytes()[:300]
    np.testing.assert_array_equal(io.read(tmp_path / "b.pcd").points, Q.astype(np.float32))
    io.write(tmp_path / "c.pcd", PointCloud(P), dtype=np.float64)
    assert b"SIZE 8 8 8" in (tmp_path / "c.pcd").read_bytes()[:300]


# ---------------------------------------------------------------------------------------- XYZ
XYZ = np.array([[1.5, 2.25, -3.0], [4.0, 5.0, 6.125], [-7.0, 8.5, 9.0]])
NRM = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0], [0.0, -1.0, 0.0]])
RGB = np.array([[255, 0, 10], [0, 128, 0], [1, 2, 3]])
ALPHA = np.array([[255], [200], [0]])
SCALAR = np.array([[0.5], [7.25], [300.0]])


def _rows(*blocks, sep=" "):
    table = np.hstack(blocks)
    return "".join(sep.join(f"{v:g}" for v in row) + "\n" for row in table)


@pytest.mark.parametrize("sep", [" ", ",", ";", "\t"])
@pytest.mark.parametrize(
    ("layout", "blocks", "has_n", "color_w", "n_scalars"),
    [
        ("xyz", (XYZ,), False, 0, 0),
        ("xyz_n", (XYZ, NRM), True, 0, 0),
        ("xyz_rgb", (XYZ, RGB), False, 3, 0),
        ("xyz_rgba", (XYZ, RGB, ALPHA), False, 4, 0),
        ("xyz_n_rgb", (XYZ, NRM, RGB), True, 3, 0),
        ("xyz_i", (XYZ, SCALAR), False, 0, 1),
        ("xyz_rgb_i", (XYZ, RGB, SCALAR), False, 3, 1),
        ("xyz_rgb_n", (XYZ, RGB, NRM), True, 3, 0),
    ],
)
def test_xyz_layouts(tmp_path, sep, layout, blocks, has_n, color_w, n_scalars):
    pc = io.read(put(tmp_path, f"{layout}.xyz", _rows(*blocks, sep=sep)))
    np.testing.assert_array_equal(pc.points, XYZ)
    if has_n:
        np.testing.assert_array_equal(pc.normals, NRM)
    else:
        assert pc.normals is None
    if color_w:
        assert pc.colors.dtype == np.uint8 and pc.colors.shape == (3, color_w)
        np.testing.assert_array_equal(pc.colors[:, :3], RGB)
    else:
        assert pc.colors is None
    assert sorted(pc.attributes) == [f"scalar_{i}" for i in range(n_scalars)]
    if n_scalars:
        np.testing.assert_array_equal(pc.attributes["scalar_0"], SCALAR[:, 0])


def test_xyz_cloudcompare_header_and_names(tmp_path):
    text = "//X,Y,Z,R,G,B,A,Intensity\n" + _rows(XYZ, RGB, ALPHA, SCALAR, sep=",")
    pc = io.read(put(tmp_path, "cc.xyz", text))
    np.testing.assert_array_equal(pc.colors, np.hstack([RGB, ALPHA]))
    np.testing.assert_array_equal(pc.attributes["Intensity"], SCALAR[:, 0])
    # a plain first line of names; the header settles the "r g b i" vs "r g b a" ambiguity
    text = "X Y Z R G B Reflectance\n" + _rows(XYZ, RGB, ALPHA)
    pc = io.read(put(tmp_path, "h.xyz", text))
    np.testing.assert_array_equal(pc.colors, RGB)
    np.testing.assert_array_equal(pc.attributes["Reflectance"], ALPHA[:, 0])
    # without the header the 8-bit column is read as alpha (documented ambiguity)
    pc = io.read(put(tmp_path, "g.xyz", _rows(XYZ, RGB, ALPHA)))
    assert pc.colors.shape == (3, 4)
    # '#' comments and a comment header naming normals
    text = "# scanner export\n# x y z nx ny nz\n" + _rows(XYZ, NRM * 2)
    pc = io.read(put(tmp_path, "n.xyz", text))
    np.testing.assert_array_equal(pc.normals, NRM * 2)  # named: kept even if not unit


def test_xyz_decimal_comma_and_non_unit_normals(tmp_path):
    text = _rows(XYZ, NRM, sep=";").replace(".", ",")
    pc = io.read(put(tmp_path, "eu.xyz", text))
    np.testing.assert_array_equal(pc.points, XYZ)
    np.testing.assert_array_equal(pc.normals, NRM)
    pc = io.read(put(tmp_path, "nn.xyz", _rows(XYZ, NRM * 3)))
    assert pc.normals is None and sorted(pc.attributes) == ["scalar_0", "scalar_1", "scalar_2"]


def test_xyz_roundtrip_with_normals(tmp_path):
    io.write(tmp_path / "w.xyz", PointCloud(XYZ, NRM))
    pc = io.read(tmp_path / "w.xyz")
    np.testing.assert_array_equal(pc.normals, NRM)


def test_xyz_misshaped_rows(tmp_path):
    with pytest.raises(InvalidInputError, match=r"m.xyz: malformed XYZ text: line 4 has 2 values"):
        io.read(put(tmp_path, "m.xyz", "# c\n1 2 3\n4 5 6\n7 8\n"))
    with pytest.raises(InvalidInputError, match=r"a.xyz: malformed XYZ text: line 2 .*'x'"):
        io.read(put(tmp_path, "a.xyz", "1,2,3\n4,x,6\n"))
    with pytest.raises(InvalidInputError, match=r"s.xyz: XYZ rows must have at least 3 values"):
        io.read(put(tmp_path, "s.xyz", "1 2\n3 4\n"))
    with pytest.raises(InvalidInputError, match=r"h.xyz: the XYZ header names 4 columns"):
        io.read(put(tmp_path, "h.xyz", "X Y Z I\n1 2 3\n"))
    with pytest.raises(InvalidInputError, match=r"e.xyz: XYZ file holds no points"):
        io.read(put(tmp_path, "e.xyz", "// nothing\n"))


# ---------------------------------------------------------------------------------- GLB / glTF


def test_glb_box(tmp_path):
    box = trimesh.creation.box(extents=(1, 2, 3))
    (tmp_path / "box.glb").write_bytes(box.export(file_type="glb"))
    m = io.read(tmp_path / "box.glb")
    assert isinstance(m, Mesh) and m.n_vertices == 8 and m.n_faces == 12
    np.testing.assert_allclose(m.vertices, box.vertices)
    np.testing.assert_array_equal(m.faces, box.faces)


def test_glb_scene_transforms_flattened(tmp_path):
    V, F = icosphere(1)
    scene = trimesh.Scene()
    T1 = np.eye(4)
    T1[:3, 3] = [10, 0, 0]
    T2 = np.diag([1.0, 1.0, -1.0, 1.0])  # mirror: winding must be reversed
    T2[:3, 3] = [0, 5, 0]
    scene.add_geometry(trimesh.Trimesh(V, F, process=False), node_name="a", transform=T1)
    scene.add_geometry(trimesh.Trimesh(V, F, process=False), node_name="b", transform=T2)
    (tmp_path / "s.glb").write_bytes(scene.export(file_type="glb"))
    m = io.read(tmp_path / "s.glb")
    n = len(V)
    assert m.n_vertices == 2 * n and m.n_faces == 2 * len(F)
    # each instance: the same vertex order, moved by its node transform
    parts = {tuple(np.round(m.vertices[i * n : (i + 1) * n].mean(0), 6)) for i in range(2)}
    assert parts == {(10.0, 0.0, 0.0), (0.0, 5.0, 0.0)}
    for i in range(2):
        Vi = m.vertices[i * n : (i + 1) * n]
        Fi = m.faces[i * len(F) : (i + 1) * len(F)] - i * n
        c = Vi.mean(0)
        fc = Vi[Fi].mean(1) - c
        assert (np.einsum("ij,ij->i", face_normals(Vi, Fi), fc) > 0).all()  # outward


def test_glb_normals_and_texcoords(tmp_path):
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * 0.5 + 0.25
    tm = trimesh.Trimesh(
        V, F, visual=TextureVisuals(uv=uv, material=PBRMaterial(name="m")), process=False
    )
    tm.vertex_normals = np.tile([0, 0, 1.0], (4, 1))
    (tmp_path / "t.glb").write_bytes(tm.export(file_type="glb", include_normals=True))
    m = io.read(tmp_path / "t.glb")
    np.testing.assert_allclose(m.vertex_normals, np.tile([0, 0, 1.0], (4, 1)))
    np.testing.assert_allclose(m.face_attributes["texcoord"], uv[F].reshape(-1, 6), atol=1e-7)
    io.write(tmp_path / "t.obj", m)
    assert (tmp_path / "t.obj").read_text().count("\nvt ") == 4


def test_glb_point_cloud(tmp_path):
    rng = np.random.default_rng(3)
    P = rng.random((50, 3))
    C = rng.integers(0, 256, (50, 4)).astype(np.uint8)
    (tmp_path / "p.glb").write_bytes(trimesh.PointCloud(P, colors=C).export(file_type="glb"))
    pc = io.read(tmp_path / "p.glb")
    assert isinstance(pc, PointCloud) and pc.n_points == 50
    np.testing.assert_allclose(pc.points, P, atol=1e-6)
    np.testing.assert_array_equal(pc.colors, C)


def test_gltf_embedded_and_external_buffers(tmp_path):
    box = trimesh.creation.box()
    files = box.export(file_type="gltf", embed_buffers=True)
    (tmp_path / "e.gltf").write_bytes(files["model.gltf"])
    m = io.read(tmp_path / "e.gltf")
    np.testing.assert_allclose(m.vertices, box.vertices)
    files = box.export(file_type="gltf")
    for key, data in files.items():
        (tmp_path / key).write_bytes(data)
    # separate buffer files next to the .gltf are read (from a path), refused from bytes alone
    m = io.read(tmp_path / "model.gltf")
    np.testing.assert_allclose(m.vertices, box.vertices)
    from spectrageo.io._trimesh_formats import read_gltf

    with pytest.raises(InvalidInputError, match=r"model.gltf: the glTF buffers are separate files"):
        read_gltf(files["model.gltf"], "model.gltf")


def test_gltf_glb_errors(tmp_path):
    with pytest.raises(InvalidInputError, match=r"x.glb: not a binary glTF"):
        io.read(put(tmp_path, "x.glb", b"PK\x03\x04 not glb"))
    glb = trimesh.creation.box().export(file_type="glb")
    with pytest.raises(InvalidInputError, match=r"t.glb: "):
        io.read(put(tmp_path, "t.glb", glb[: len(glb) // 2]))
    with pytest.raises(InvalidInputError, match=r"j.gltf: not a glTF file"):
        io.read(put(tmp_path, "j.gltf", "{nope"))
    empty = {"asset": {"version": "2.0"}, "scenes": [{"nodes": []}], "scene": 0}
    with pytest.raises(InvalidInputError, match=r"n.gltf: "):
        io.read(put(tmp_path, "n.gltf", json.dumps(empty)))


# ---------------------------------------------------------------------------------------- 3MF
_CT = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    "</Types>"
)
_RELS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>'
)


def _model_xml(V, F, items, components=""):
    verts = "".join(
        f'<vertex x="{x!r}" y="{y!r}" z="{z!r}"/>' for x, y, z in np.asarray(V).tolist()
    )
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in F)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<model unit="millimeter" xml:lang="en-US" '
        'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
        f'<resources><object id="1" type="model"><mesh><vertices>{verts}</vertices>'
        f"<triangles>{tris}</triangles></mesh></object>{components}</resources>"
        f"<build>{items}</build></model>"
    )


def _write_3mf(path, model, rels=True):
    buf = pyio.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", _CT)
        if rels:
            z.writestr("_rels/.rels", _RELS)
        z.writestr("3D/3dmodel.model", model)
    path.write_bytes(buf.getvalue())


def test_3mf_items_and_components(tmp_path):
    box = trimesh.creation.box()
    V, F = np.asarray(box.vertices), np.asarray(box.faces)
    comp = (
        '<object id="2" type="model"><components>'
        '<component objectid="1" transform="1 0 0 0 1 0 0 0 1 0 0 5"/></components></object>'
    )
    items = '<item objectid="1" transform="2 0 0 0 2 0 0 0 2 10 0 0"/><item objectid="2"/>'
    _write_3mf(tmp_path / "b.3mf", _model_xml(V, F, items, comp))
    m = io.read(tmp_path / "b.3mf")
    assert m.n_vertices == 16 and m.n_faces == 24
    np.testing.assert_allclose(m.vertices[:8], V * 2 + [10, 0, 0])
    np.testing.assert_allclose(m.vertices[8:], V + [0, 0, 5])
    np.testing.assert_array_equal(m.faces, np.vstack([F, F + 8]))
    _write_3mf(tmp_path / "n.3mf", _model_xml(V, F, '<item objectid="1"/>'), rels=False)
    np.testing.assert_allclose(io.read(tmp_path / "n.3mf").vertices, V)


def test_3mf_trimesh_export_if_available(tmp_path):
    box = trimesh.creation.box()
    try:
        data = box.export(file_type="3mf")
    except (ImportError, ModuleNotFoundError) as exc:  # needs lxml and networkx
        pytest.skip(f"trimesh cannot export 3MF here ({exc})")
    (tmp_path / "t.3mf").write_bytes(data)
    m = io.read(tmp_path / "t.3mf")
    assert m.n_faces == 12


def test_3mf_errors(tmp_path):
    with pytest.raises(InvalidInputError, match=r"z.3mf: not a 3MF file"):
        io.read(put(tmp_path, "z.3mf", b"solid nonsense" * 10))
    buf = pyio.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("other.txt", "x")
    with pytest.raises(InvalidInputError, match=r"m.3mf: the 3MF package lacks the part"):
        io.read(put(tmp_path, "m.3mf", buf.getvalue()))
    V, F = np.eye(3), np.array([[0, 1, 7]])
    _write_3mf(tmp_path / "o.3mf", _model_xml(V, F, '<item objectid="1"/>'))
    with pytest.raises(InvalidInputError, match=r"o.3mf: 3MF object 1: triangle indices out of"):
        io.read(tmp_path / "o.3mf")
    _write_3mf(tmp_path / "r.3mf", _model_xml(V, [[0, 1, 2]], '<item objectid="9"/>'))
    with pytest.raises(InvalidInputError, match=r"r.3mf: 3MF refers to object '9'"):
        io.read(tmp_path / "r.3mf")
    _write_3mf(tmp_path / "x.3mf", "<model><oops></model>")
    with pytest.raises(InvalidInputError, match=r"x.3mf: malformed XML"):
        io.read(tmp_path / "x.3mf")


def test_new_formats_listed():
    assert {".glb", ".gltf", ".3mf"} <= set(io.supported_formats()["read"])
