"""glTF primitive modes, required extensions, large scenes and 3MF bombs; OBJ and STL oddities."""

from __future__ import annotations

import base64
import io as pyio
import json
import struct
import subprocess
import sys
import time
import zipfile

import numpy as np
import pytest

from spectrageo import InvalidInputError, RepairWarning, UnsupportedFormatError, io
from spectrageo.geometry import Mesh, PointCloud

SQUARE = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0, 0]]


# ---------------------------------------------------------------------------------- glTF builders
def _gltf(arrays, prims, *, nodes=None, **extra) -> dict:
    """glTF document with one embedded buffer: ``arrays`` are (values, componentType, type), each
    given a bufferView and an accessor of the same index; ``prims`` a list of primitive lists
    (one mesh each); ``nodes`` default to one node per mesh."""
    fmt = {5126: "<f4", 5125: "<u4", 5123: "<u2", 5121: "u1"}
    blob, views, accessors = b"", [], []
    for values, ctype, atype in arrays:
        data = np.asarray(values, dtype=fmt[ctype])
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes})
        accessors.append(
            {
                "bufferView": len(views) - 1,
                "componentType": ctype,
                "type": atype,
                "count": data.shape[0],
            }
        )
        blob += data.tobytes() + b"\0" * (-data.nbytes % 4)
    if nodes is None:
        nodes = [{"mesh": k} for k in range(len(prims))]
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [
            {
                "byteLength": len(blob),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
            }
        ],
        "bufferViews": views,
        "accessors": accessors,
        "meshes": [{"primitives": p} for p in prims],
        "nodes": nodes,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "scene": 0,
    }
    doc.update(extra)
    return doc


def _one(pos, *, mode: int, nodes=None) -> dict:
    """glTF document of one primitive of ``mode`` over the positions ``pos``."""
    return _gltf([pos], [[{"attributes": {"POSITION": 0}, "mode": mode}]], nodes=nodes)


def _put_gltf(tmp_path, name, doc):
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _glb(doc: dict) -> bytes:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


# ---------------------------------------------------------------------------------- glTF modes
def test_triangle_strip_and_fan_are_read_as_triangles(tmp_path):
    pos = (SQUARE[:4], 5126, "VEC3")
    m = io.read(_put_gltf(tmp_path, "s.gltf", _one(pos, mode=5)))
    assert isinstance(m, Mesh)
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [2, 1, 3]])  # odd ones flipped: one side
    # indexed strip with a repeated index joining two strips: the degenerate joins are dropped
    idx = ([0, 1, 2, 3, 3, 4, 4, 5], 5123, "SCALAR")
    pos6 = ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 0, 0], [6, 0, 0]], 5126, "VEC3")
    doc = _gltf([pos6, idx], [[{"attributes": {"POSITION": 0}, "indices": 1, "mode": 5}]])
    m = io.read(_put_gltf(tmp_path, "j.gltf", doc), weld=False)
    assert m.n_faces == 2 and (np.ptp(m.faces, axis=1) > 0).all()
    fan = ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 0.5, 0]], 5126, "VEC3")
    m = io.read(_put_gltf(tmp_path, "f.gltf", _one(fan, mode=6)))
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [0, 3, 4]])


def test_points_primitive_is_a_point_cloud_and_lines_are_refused(tmp_path):
    pos = (SQUARE, 5126, "VEC3")
    pc = io.read(_put_gltf(tmp_path, "p.gltf", _one(pos, mode=0)))
    assert isinstance(pc, PointCloud) and pc.n_points == 5
    np.testing.assert_array_equal(pc.points, SQUARE)
    doc = _one(pos, mode=1)
    with pytest.raises(UnsupportedFormatError, match=r"l.gltf: .*only line primitives \(LINES\)"):
        io.read(_put_gltf(tmp_path, "l.gltf", doc))


@pytest.mark.parametrize("ext", ["EXT_meshopt_compression", "KHR_draco_mesh_compression"])
def test_required_extension_is_named(tmp_path, ext):
    doc = _gltf([(SQUARE[:3], 5126, "VEC3")], [[{"attributes": {"POSITION": 0}}]])
    doc["extensionsUsed"] = doc["extensionsRequired"] = [ext]
    (tmp_path / "c.glb").write_bytes(_glb(doc))
    with pytest.raises(UnsupportedFormatError, match=rf"c.glb: .*requires the extension {ext}"):
        io.read(tmp_path / "c.glb")
    doc["extensionsRequired"] = ["KHR_materials_unlit"]  # does not change the geometry: read
    assert io.read(_put_gltf(tmp_path, "u.gltf", doc)).n_faces == 1


def test_position_must_be_vec3(tmp_path):
    doc = _gltf([([[0, 0], [1, 0], [0, 1]], 5126, "VEC2")], [[{"attributes": {"POSITION": 0}}]])
    with pytest.raises(InvalidInputError, match=r"v.gltf: .*POSITION must be a VEC3 .*VEC2"):
        io.read(_put_gltf(tmp_path, "v.gltf", doc))


def test_many_primitives_read_completely_and_identically(tmp_path):
    """1,000 nodes with clashing names, each an instance of a mesh of 8 primitives: all 8,000
    pieces are read, in scene order, and a second read gives the same arrays."""
    n, k = 1000, 8
    tri = ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], 5126, "VEC3")
    nodes = [{"mesh": 0, "name": "node", "translation": [j, 0, 0]} for j in range(n)]
    doc = _gltf([tri], [[{"attributes": {"POSITION": 0}}] * k], nodes=nodes)
    path = _put_gltf(tmp_path, "many.gltf", doc)
    a = io.read(path, weld=False)
    b = io.read(path, weld=False)
    assert a.n_vertices == 3 * k * n and a.n_faces == k * n
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.vertices[:: 3 * k, 0], np.arange(n))  # scene order


def test_amplified_scene_refused_before_building(tmp_path, monkeypatch):
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "50M")
    pos = (np.zeros((20000, 3)), 5126, "VEC3")
    nodes = [{"mesh": 0}] * 2000  # 40 M vertices from a 240 KB buffer
    path = _put_gltf(tmp_path, "amp.gltf", _one(pos, mode=0, nodes=nodes))
    with pytest.raises(InvalidInputError, match=r"amp.gltf: flattening the glTF scene \(2000 mesh"):
        io.read(path)
    doc = _gltf([pos], [[{"attributes": {"POSITION": 0}}]], nodes=[{"children": [1]}, {"mesh": 0}])
    doc["scenes"] = [{"nodes": [0, 1]}]  # node 1 reached twice
    with pytest.raises(InvalidInputError, match=r"d.gltf: .*node 1 is reached twice"):
        io.read(_put_gltf(tmp_path, "d.gltf", doc))


# ----------------------------------------------------------------------------------- OBJ / STL
def test_obj_with_colours_on_some_vertices(tmp_path):
    (tmp_path / "p.obj").write_text(
        "v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n"
    )
    with pytest.warns(RepairWarning, match=r"only 2 of 4 OBJ 'v' lines carry colours"):
        m = io.read(tmp_path / "p.obj")
    assert m.n_vertices == 4 and m.n_faces == 2 and m.vertex_colors is None


def test_ascii_stl_with_bad_normal_is_quiet(tmp_path):
    (tmp_path / "n.stl").write_text(
        "solid t\nfacet normal 0 0 x\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
        "endloop\nendfacet\nendsolid t\n"
    )
    r = subprocess.run(
        [sys.executable, "-m", "spectrageo.cli.main", "info", str(tmp_path / "n.stl")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0 and "n_faces: 1" in r.stdout
    assert r.stderr.strip() == ""


# ----------------------------------------------------------------------------------------- 3MF
_RELS = (
    '<?xml version="1.0"?><Relationships xmlns="http://schemas.openxmlformats.org/package/2006/'
    'relationships"><Relationship Target="/3D/3dmodel.model" Id="r0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>'
)
_HEAD = '<model xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02"><resources>'
_TRI = (
    '<object id="1"><mesh><vertices><vertex x="0" y="0" z="0"/><vertex x="1" y="0" z="0"/>'
    '<vertex x="0" y="1" z="0"/></vertices><triangles><triangle v1="0" v2="1" v3="2"/>'
    "</triangles></mesh></object>"
)


def _3mf(path, model, method=zipfile.ZIP_DEFLATED):
    buf = pyio.BytesIO()
    with zipfile.ZipFile(buf, "w", method) as z:
        z.writestr("_rels/.rels", _RELS)
        z.writestr("3D/3dmodel.model", model)
    path.write_bytes(buf.getvalue())
    return path


def test_3mf_nested_components_refused_early(tmp_path):
    objs = [_TRI]
    for level in range(2, 9):  # 10 components per level, 7 levels: 10^7 instances
        comps = "".join(f'<component objectid="{level - 1}"/>' for _ in range(10))
        objs.append(f'<object id="{level}"><components>{comps}</components></object>')
    model = _HEAD + "".join(objs) + '</resources><build><item objectid="8"/></build></model>'
    t0 = time.perf_counter()
    with pytest.raises(InvalidInputError, match=r"n.3mf: .*11111111 object instances.*limit of"):
        io.read(_3mf(tmp_path / "n.3mf", model))
    assert time.perf_counter() - t0 < 10
    # two levels: expanded (100 triangles)
    model = model.replace('objectid="8"', 'objectid="3"')
    assert io.read(_3mf(tmp_path / "ok.3mf", model), weld=False).n_faces == 100


def test_3mf_inflated_size_capped(tmp_path, monkeypatch):
    verts = "".join(f'<vertex x="{k}" y="0" z="0"/>' for k in range(200_000))  # 6 MB inflated
    tris = '<triangles><triangle v1="0" v2="1" v3="2"/></triangles>'
    model = _HEAD + f'<object id="1"><mesh><vertices>{verts}</vertices>{tris}</mesh></object>'
    path = _3mf(
        tmp_path / "b.3mf", model + '</resources><build><item objectid="1"/></build></model>'
    )
    assert path.stat().st_size < 2_000_000
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "1M")
    with pytest.raises(InvalidInputError, match=r"b.3mf: inflating 3MF part .*memory cap"):
        io.read(path)
    monkeypatch.setenv("SPECTRAGEO_MAX_BYTES", "100M")
    m = io.read(path, weld=False)  # streamed: the vertices are read, no element tree is kept
    assert m.n_vertices == 200_000 and m.n_faces == 1
    np.testing.assert_array_equal(m.vertices[:, 0], np.arange(200_000))


def test_3mf_damaged_deflate_and_other_zip_methods(tmp_path):
    model = _HEAD + _TRI + '</resources><build><item objectid="1"/></build></model>'
    model += "<!--" + "x" * 5000 + "-->"
    raw = bytearray(_3mf(tmp_path / "ok.3mf", model).read_bytes())
    start = raw.index(b"3D/3dmodel.model") + len("3D/3dmodel.model") + 40
    raw[start : start + 20] = b"\xff" * 20
    (tmp_path / "d.3mf").write_bytes(bytes(raw))
    with pytest.raises(InvalidInputError, match=r"d.3mf: corrupt 3MF part '3D/3dmodel.model'"):
        io.read(tmp_path / "d.3mf")
    stored = _3mf(tmp_path / "s.3mf", model, zipfile.ZIP_STORED).read_bytes()
    for method in (1, 9, 99):
        raw = bytearray(stored)
        for sig, off in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # local and central headers
            pos = raw.find(sig)
            while pos >= 0:
                raw[pos + off : pos + off + 2] = struct.pack("<H", method)
                pos = raw.find(sig, pos + 4)
        (tmp_path / "m.3mf").write_bytes(bytes(raw))
        with pytest.raises(InvalidInputError, match=rf"m.3mf: .*compression method {method}"):
            io.read(tmp_path / "m.3mf")


def test_3mf_dtd_refused(tmp_path):
    model = (
        '<?xml version="1.0"?><!DOCTYPE model [<!ENTITY a "aaaaaaaaaa">]>'
        + _HEAD
        + _TRI
        + '</resources><build><item objectid="1"/></build></model>'
    )
    with pytest.raises(InvalidInputError, match=r"x.3mf: 3MF part .* declares a DTD"):
        io.read(_3mf(tmp_path / "x.3mf", model))


def test_3mf_index_beyond_int64_is_a_clear_error(tmp_path):
    model = _HEAD + _TRI.replace('v3="2"', 'v3="18446744073709551616"')
    model += '</resources><build><item objectid="1"/></build></model>'
    with pytest.raises(InvalidInputError, match=r"vertex index is beyond the 64-bit") as err:
        io.read(_3mf(tmp_path / "x.3mf", model))
    assert "OverflowError" not in str(err.value)


def test_3mf_any_attribute_layout_reads_the_same(tmp_path):
    """Vertices with attributes in another order and triangles with property attributes are read
    like the common layout."""
    build = '</resources><build><item objectid="1"/></build></model>'
    common = io.read(_3mf(tmp_path / "c.3mf", _HEAD + _TRI + build), weld=False)
    other = (
        _TRI.replace('x="1" y="0" z="0"', 'z="0" y="0" x="1"')
        .replace('v3="2"/>', 'v3="2" pid="1" p1="0"/>')
        .replace("<vertex ", "\n  <vertex ")
    )
    m = io.read(_3mf(tmp_path / "o.3mf", _HEAD + other + build), weld=False)
    np.testing.assert_array_equal(m.vertices, common.vertices)
    np.testing.assert_array_equal(m.faces, common.faces)
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_3mf_part_larger_than_declared_is_corrupt(tmp_path):
    """A part that inflates beyond the size its zip entry declares is refused (and inflated only
    up to that size)."""
    model = _HEAD + _TRI + '</resources><build><item objectid="1"/></build></model>'
    raw = bytearray(_3mf(tmp_path / "ok.3mf", model + " " * 1_000_000).read_bytes())
    pos = raw.rfind(b"PK\x01\x02")  # central directory entry of the model part
    assert raw[pos + 46 : pos + 62] == b"3D/3dmodel.model"
    raw[pos + 24 : pos + 28] = struct.pack("<I", 1000)
    (tmp_path / "f.3mf").write_bytes(bytes(raw))
    with pytest.raises(InvalidInputError, match=r"f.3mf: corrupt 3MF part '3D/3dmodel.model'"):
        io.read(tmp_path / "f.3mf")
