"""Small valid seed files per fuzz format, made in memory (``(suffix, bytes)`` pairs)."""

from __future__ import annotations

import base64
import io
import json
import struct
import zipfile
from pathlib import Path

import numpy as np

import test_fuzz_io as _base

from conftest import icosphere

#: formats of :func:`test_fuzz_io.build_seeds` reused as they are (``gz`` wraps another)
BASE_FORMATS = tuple(f for f in _base.FORMATS if f != "gz")
#: formats added here
EXTRA_FORMATS = ("pts", "gltf", "glb", "3mf", "sgc", "sga")
FORMATS = BASE_FORMATS + EXTRA_FORMATS
#: formats whose mutants are also compared with the seed's decoded result
CODEC_FORMATS = ("sgc", "sga")


def available(fmt: str) -> bool:
    """Whether the optional packages a format needs are installed."""
    import importlib.util

    if fmt == "las":
        return importlib.util.find_spec("laspy") is not None
    if fmt == "laz":
        return all(importlib.util.find_spec(m) is not None for m in ("laspy", "lazrs"))
    return True


def _pts(rng) -> list[tuple[str, bytes]]:
    P = rng.normal(size=(60, 3))
    rows = "".join(
        f"{p[0]:.5f} {p[1]:.5f} {p[2]:.5f} {i % 200} 10 20 30\n" for i, p in enumerate(P)
    )
    plain = "".join(f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n" for p in P)
    return [(".pts", f"{len(P)}\n{rows}".encode()), (".pts", plain.encode())]


def gltf_doc(V: np.ndarray, F: np.ndarray, n_prims: int = 1) -> tuple[dict, bytes]:
    """A glTF document (without its buffer URI) of ``n_prims`` copies of one triangle primitive,
    and the binary buffer."""
    pos = V.astype("<f4").tobytes()
    idx = F.astype("<u4").tobytes()
    blob = idx + pos
    lo, hi = V.min(axis=0).tolist(), V.max(axis=0).tolist()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 1}, "indices": 0, "mode": 4}] * n_prims}
        ],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(idx), "target": 34963},
            {"buffer": 0, "byteOffset": len(idx), "byteLength": len(pos), "target": 34962},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5125, "count": F.size, "type": "SCALAR"},
            {
                "bufferView": 1,
                "componentType": 5126,
                "count": len(V),
                "type": "VEC3",
                "min": lo,
                "max": hi,
            },
        ],
    }
    return doc, blob


def gltf_bytes(doc: dict, blob: bytes) -> bytes:
    """The ``.gltf`` text with the buffer embedded as a data URI."""
    doc = json.loads(json.dumps(doc))
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(
        blob
    ).decode("ascii")
    return json.dumps(doc).encode()


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    """The ``.glb`` container of ``doc`` and ``blob`` (JSON and BIN chunks, 4-byte aligned)."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942)
    body += blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def model_3mf(V: np.ndarray, F: np.ndarray) -> str:
    """The ``3D/3dmodel.model`` XML of one mesh object."""
    verts = "".join(f'<vertex x="{x:.6f}" y="{y:.6f}" z="{z:.6f}"/>' for x, y, z in V)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in F)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<model unit="millimeter" xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
        f'<resources><object id="1" type="model"><mesh><vertices>{verts}</vertices>'
        f"<triangles>{tris}</triangles></mesh></object></resources>"
        '<build><item objectid="1"/></build></model>'
    )


def zip_3mf(model: str, method: int = zipfile.ZIP_DEFLATED) -> bytes:
    """A 3MF package holding ``model``."""
    buf = io.BytesIO()

    def entry(name: str) -> zipfile.ZipInfo:  # a fixed timestamp: the same bytes on every run
        return zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))

    with zipfile.ZipFile(buf, "w", method) as z:
        z.writestr(
            entry("[Content_Types].xml"),
            '<?xml version="1.0" encoding="UTF-8"?><Types xmlns="http://schemas.openxmlformats.org/'
            'package/2006/content-types"><Default Extension="model" ContentType="application/'
            'vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>',
            compress_type=method,
        )
        z.writestr(entry("3D/3dmodel.model"), model, compress_type=method)
    return buf.getvalue()


def build_seeds(fmt: str, tmp: Path, shared: Path | None = None) -> list[tuple[str, bytes]]:
    """``(suffix, bytes)`` seed files of one fuzz format (real shared files only for the base
    formats, when ``shared`` is given)."""
    if fmt in BASE_FORMATS:
        return _base.build_seeds(fmt, tmp, shared)
    from spectrageo import compress

    rng = np.random.default_rng(11)
    V, F = icosphere(1)
    if fmt == "pts":
        return _pts(rng)
    if fmt in ("gltf", "glb"):
        make = gltf_bytes if fmt == "gltf" else glb_bytes
        suffix = "." + fmt
        return [(suffix, make(*gltf_doc(V, F))), (suffix, make(*gltf_doc(V, F, n_prims=3)))]
    if fmt == "3mf":
        model = model_3mf(V, F)
        return [(".3mf", zip_3mf(model)), (".3mf", zip_3mf(model, zipfile.ZIP_STORED))]
    if fmt == "sgc":
        return [(".sgc", compress.encode(V, F)), (".sgc", compress.encode(V, F, method="feature"))]
    if fmt == "sga":
        frames = np.stack([V * (1 + 0.02 * t) + 0.01 * t for t in range(8)])
        return [
            (".sga", compress.encode_animation(frames, F)),
            (".sga", compress.encode_animation(frames, F, method="layered")),
        ]
    raise ValueError(f"unknown fuzz format {fmt!r}")
