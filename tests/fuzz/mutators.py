"""Mutations per fuzz format: the byte-level ones of :mod:`test_fuzz_io` (bit flips, overwritten
runs, truncation, duplicated ranges, header count edits) plus structure-aware ones for glTF/GLB
(accessor counts, types, primitive amplification), 3MF (XML index/count edits, zip method and size
fields, nested components) and ``.sgc`` / ``.sga`` (chunks or segments swapped, duplicated or
dropped, header fields forged with a recomputed checksum).

Each mutator returns ``(bytes, description, expect)``; ``expect`` is ``"seed"`` when a mutant that
is read at all must decode to the seed's result (checksummed codec files), ``"error"`` when it
must be refused, and ``""`` when only the generic invariants apply.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import struct
import zipfile
import zlib

import test_fuzz_io as _base

from . import seeds

_GENERIC = (_base._bitflip, _base._byterun, _base._truncate, _base._duplicate)
_BIG = (0, 1, 2**31, 2**32 - 1, 2**63, 10**12)


def _generic(data: bytes, fmt: str, suffix: str, rng) -> tuple[bytes, str]:
    if fmt in seeds.BASE_FORMATS or fmt == "pts":
        return _base.mutate(data, "xyz" if fmt == "pts" else fmt, suffix, rng)
    return _GENERIC[int(rng.integers(len(_GENERIC)))](data, rng)


# ------------------------------------------------------------------------------------ glTF / GLB
def _glb_split(data: bytes) -> tuple[dict, bytes]:
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + jlen])
    (blen,) = struct.unpack_from("<I", data, 20 + jlen)
    return doc, data[28 + jlen : 28 + jlen + blen]


def _gltf_split(data: bytes) -> tuple[dict, bytes]:
    import base64

    doc = json.loads(data)
    uri = doc["buffers"][0].pop("uri")
    return doc, base64.b64decode(uri.split(",", 1)[1])


def _edit_gltf_doc(doc: dict, rng) -> str:
    acc = doc["accessors"]
    k = int(rng.integers(8))
    a = acc[int(rng.integers(len(acc)))]
    if k == 0:
        a["count"] = int(rng.choice([0, -1, a["count"] + 1, a["count"] * 1000, 2**32, 2**64]))
        return f"accessor count -> {a['count']}"
    if k == 1:
        a["type"] = str(rng.choice(["VEC2", "SCALAR", "MAT4", "VEC4", "BOGUS"]))
        return f"accessor type -> {a['type']}"
    if k == 2:
        a["componentType"] = int(rng.choice([5120, 5121, 5123, 5125, 5126, 1, 9999]))
        return f"accessor componentType -> {a['componentType']}"
    if k == 3:
        v = doc["bufferViews"][int(rng.integers(2))]
        key = str(rng.choice(["byteOffset", "byteLength", "byteStride", "buffer"]))
        v[key] = int(rng.choice([-4, 1, 3, 2**31, 2**40, 10**6]))
        return f"bufferView {key} -> {v[key]}"
    if k == 4:
        prims = doc["meshes"][0]["primitives"]
        prims[0]["mode"] = int(rng.choice([0, 1, 2, 3, 5, 6, 7, -1, 99]))
        return f"primitive mode -> {prims[0]['mode']}"
    if k == 5:  # amplification: many primitives or many nodes sharing the mesh
        n = int(rng.choice([500, 2000, 8000]))
        if rng.random() < 0.5:
            doc["meshes"][0]["primitives"] = doc["meshes"][0]["primitives"][:1] * n
            return f"{n} copies of one primitive"
        doc["nodes"] = [{"mesh": 0} for _ in range(n)]
        doc["scenes"][0]["nodes"] = list(range(n))
        return f"{n} nodes sharing one mesh"
    if k == 6:
        doc["extensionsRequired"] = [str(rng.choice(["EXT_meshopt_compression", "KHR_x"]))]
        doc["extensionsUsed"] = doc["extensionsRequired"]
        return f"extensionsRequired {doc['extensionsRequired']}"
    # node graph: a cycle or a reference out of range
    if rng.random() < 0.5:
        doc["nodes"] = [{"mesh": 0, "children": [1]}, {"children": [0]}]
        return "node cycle"
    doc["nodes"][0]["mesh"] = int(rng.choice([1, -1, 2**40]))
    return f"node mesh -> {doc['nodes'][0]['mesh']}"


def _mutate_gltf(data: bytes, fmt: str, rng) -> tuple[bytes, str, str]:
    if rng.random() < 0.5:
        doc, blob = (_glb_split if fmt == "glb" else _gltf_split)(data)
        desc = _edit_gltf_doc(doc, rng)
        make = seeds.glb_bytes if fmt == "glb" else seeds.gltf_bytes
        return make(doc, blob), desc, ""
    if fmt == "glb" and rng.random() < 0.3:  # a chunk length or the total length
        buf = bytearray(data)
        off = int(rng.choice([8, 12]))
        val = int(rng.choice(_BIG)) % 2**32
        struct.pack_into("<I", buf, off, val)
        return bytes(buf), f"GLB length field at {off} -> {val}", ""
    m, d = _generic(data, fmt, "." + fmt, rng)
    return m, d, ""


# ------------------------------------------------------------------------------------------- 3MF
def _model_of(data: bytes) -> str:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return z.read("3D/3dmodel.model").decode()


def _edit_model(model: str, rng) -> tuple[str, str]:
    k = int(rng.integers(4))
    if k == 0:
        hits = list(re.finditer(r'v[123]="(\d+)"', model))
        m = hits[int(rng.integers(len(hits)))]
        new = str(rng.choice(["42", "-1", str(2**31), str(2**64), "1e3", "x"]))
        return model[: m.start(1)] + new + model[m.end(1) :], f"triangle index -> {new}"
    if k == 1:
        hits = list(re.finditer(r'[xyz]="([^"]+)"', model))
        m = hits[int(rng.integers(len(hits)))]
        new = str(rng.choice(["nan", "inf", "1e309", "-", "3e38"]))
        return model[: m.start(1)] + new + model[m.end(1) :], f"vertex coordinate -> {new}"
    if k == 2:  # nested components: fan-out ``w`` over ``d`` levels
        w, d = int(rng.choice([4, 10])), int(rng.choice([3, 6, 9]))
        objs = []
        for lvl in range(d):
            comps = "".join(f'<component objectid="{lvl + 1}"/>' for _ in range(w))
            objs.append(
                f'<object id="{lvl + 2}" type="model"><components>{comps}</components></object>'
            )
        model = model.replace("</resources>", "".join(objs) + "</resources>")
        model = model.replace('<item objectid="1"/>', f'<item objectid="{d + 1}"/>')
        return model, f"nested components {w} per level, {d} levels"
    cut = int(rng.integers(len(model)))
    return model[:cut], f"model XML cut at {cut}"


def _mutate_3mf(data: bytes, rng) -> tuple[bytes, str, str]:
    op = rng.random()
    if op < 0.45:
        model, desc = _edit_model(_model_of(data), rng)
        method = zipfile.ZIP_STORED if b"\x00\x00\x00\x00" in data[8:10] else zipfile.ZIP_DEFLATED
        return seeds.zip_3mf(model, method), desc, ""
    if op < 0.65:  # a field of a local or central zip header
        buf = bytearray(data)
        heads = [m.start() for m in re.finditer(b"PK\x03\x04|PK\x01\x02", data)]
        h = heads[int(rng.integers(len(heads)))]
        central = data[h + 2 : h + 4] == b"\x01\x02"
        fields = {"method": (10 if central else 8, "<H"), "csize": (20 if central else 18, "<I")}
        fields["usize"] = (24 if central else 22, "<I")
        name = str(rng.choice(sorted(fields)))
        off, f = fields[name]
        val = int(rng.choice([1, 9, 14, 99])) if name == "method" else int(rng.choice(_BIG)) % 2**32
        struct.pack_into(f, buf, h + off, val)
        return bytes(buf), f"zip {'central' if central else 'local'} {name} -> {val}", ""
    m, d = _generic(data, "3mf", ".3mf", rng)
    return m, d, ""


# -------------------------------------------------------------------------------- .sgc and .sga
def _segments(data: bytes) -> list[bytes]:
    from spectrageo.compress import _sga_format

    out, pos = [], 0
    while pos < len(data):
        end = _sga_format.segment_end(data, pos)
        out.append(data[pos:end])
        pos = end
    return out


def _split_container(data: bytes):
    """Header fields (:class:`spectrageo.compress._container.Header`, as stored) and ``(tag,
    payload)`` chunks of one container segment, read through the container's own layout."""
    from spectrageo.compress import _container

    head, _pos, records = _container.layout(data)
    return head, [(r.tag, data[r.body : r.end]) for r in records]


def _join_container(head, chunks: list[tuple[int, bytes]], forge: bool) -> bytes:
    """Reassemble a container from its header fields; with ``forge`` the chunks' checksums are
    chained as a writer would (so only the semantic checks can refuse the file), else each is
    the checksum of its payload alone."""
    from spectrageo.compress import _container

    head = dataclasses.replace(head, n_chunks=len(chunks) % 256)
    out = head.pack()
    prev = _container.chain_seed(head.version, out)
    for i, (tag, payload) in enumerate(chunks):
        crc = (
            _container.chunk_crc(head.version, i, tag, payload, prev)
            if forge
            else zlib.crc32(payload)
        )
        out += _container.record_head(head.version, tag, len(payload), crc) + payload
        prev = crc
    return out


def _keep_crcs(data: bytes, head, order: list[int]) -> bytes:
    """The container with its chunk records (original bytes, checksums included) in ``order``
    and the header's chunk count edited (the chained checksums then fail)."""
    from spectrageo.compress import _container

    _h, pos, records = _container.layout(data)
    raw = [data[r.start : r.end] for r in records]
    packed = dataclasses.replace(head, n_chunks=len(order) % 256).pack()
    if head.version < _container.COMPACT_VERSION and len(order) != head.n_chunks:
        packed = packed[:-4] + data[pos - 4 : pos]  # the old header checksum kept
    return packed + b"".join(raw[i] for i in order)


def _reorder(n: int, rng) -> tuple[list[int], str]:
    k = int(rng.integers(3))
    if k == 0 and n >= 2:
        i, j = sorted(int(x) for x in rng.choice(n, 2, replace=False))
        order = list(range(n))
        order[i], order[j] = order[j], order[i]
        return order, f"chunks {i} and {j} swapped"
    if k == 1:
        i = int(rng.integers(n))
        order = list(range(n))
        order.insert(int(rng.integers(n + 1)), i)
        return order, f"chunk {i} duplicated"
    i = int(rng.integers(n))
    return [j for j in range(n) if j != i], f"chunk {i} dropped"


def _forge_header(head, rng):
    """A header field edited (the layout's fields, whatever the version); a file whose counts
    or method no longer match its coded streams (checksums recomputed) must be refused or
    decode to the seed's mesh."""
    from spectrageo.compress import _container

    compact = head.version >= _container.COMPACT_VERSION and not head.flags & _container.FLAG_WIDE
    k = int(rng.integers(5 if compact else 4))
    expect = "seed" if k in (1, 3) else ""
    if k == 0:
        scale = float(rng.choice([0.0, -1.0, float("nan"), float("inf"), 1e-300, 1e300]))
        if abs(scale) in (1e-300, 1e300):  # beyond float32: the wide layout
            head = _widen(head)
        head = dataclasses.replace(head, scale=scale)
        desc = f"scale -> {scale}"
    elif k == 1:
        name = str(rng.choice(["n_vertices", "n_faces"]))
        v = getattr(head, name)
        head = dataclasses.replace(head, **{name: int(rng.choice([0, 1, v + 1, 2**28, 2**32 - 1]))})
        desc = f"{name} -> {getattr(head, name)}"
    elif k == 2:
        x = float(rng.choice([float("nan"), 1e308, -float("inf")]))
        head = _widen(head)
        head = dataclasses.replace(head, origin=(x, *head.origin[1:]))
        desc = f"origin x -> {x}"
    elif k == 3:
        limit = 32 if head.version >= _container.COMPACT_VERSION else 256
        ids = [m for m in (0, 1, 2, 5, 16, 21, 31, 200) if m != head.method_id and m < limit]
        head = dataclasses.replace(head, method_id=int(rng.choice(ids)))
        desc = f"method -> {head.method_id}"
    else:  # compact origin grid steps far out of range (a finite origin far away)
        k0 = int(rng.choice([2**52, 2**62, -(2**62)]))
        head = dataclasses.replace(head, origin=(k0, *head.origin[1:]))
        desc = f"origin grid steps x -> {k0}"
    return head, desc, expect


def _widen(head):
    """A compact version 4 header turned into its wide (f64 origin and scale) form."""
    from spectrageo.compress import _container

    if head.version < _container.COMPACT_VERSION or head.flags & _container.FLAG_WIDE:
        return head
    origin, scale = head.frame()
    return dataclasses.replace(
        head, flags=head.flags | _container.FLAG_WIDE, origin=origin, scale=scale
    )


def _mutate_container(data: bytes, rng) -> tuple[bytes, str, str]:
    head, chunks = _split_container(data)
    op = rng.random()
    if op < 0.35:  # chunks reordered, checksums kept: must be refused or read as the seed
        order, desc = _reorder(len(chunks), rng)
        if rng.random() < 0.5:
            return _keep_crcs(data, head, order), desc, "seed"
        # and the whole chain forged: a writer's file with its chunks out of place
        return _join_container(head, [chunks[i] for i in order], True), desc + ", forged", "seed"
    if op < 0.6:
        forged, desc, expect = _forge_header(head, rng)
        return _join_container(forged, chunks, True), "header " + desc + ", forged", expect
    if op < 0.75:  # a payload byte changed and every checksum recomputed
        i = int(rng.integers(len(chunks)))
        tag, payload = chunks[i]
        if payload:
            b = bytearray(payload)
            b[int(rng.integers(len(b)))] ^= 1 << int(rng.integers(8))
            chunks[i] = (tag, bytes(b))
        return _join_container(head, chunks, True), f"chunk {i} byte flipped, forged", ""
    m, d = _generic(data, "sgc", ".sgc", rng)
    return m, d, "seed"


def _mutate_sga(data: bytes, rng) -> tuple[bytes, str, str]:
    segs = _segments(data)
    op = rng.random()
    if op < 0.4:
        n = len(segs)
        if rng.random() < 0.25:
            return b"".join(segs[:-1]), "trailing index segment dropped", "error"
        order, desc = _reorder(n, rng)
        return b"".join(segs[i] for i in order), desc.replace("chunk", "segment"), "seed"
    if op < 0.6:
        i = int(rng.integers(len(segs)))
        m, desc, expect = _mutate_container(segs[i], rng)
        segs[i] = m
        return b"".join(segs), f"segment {i}: {desc}", expect
    m, d = _generic(data, "sga", ".sga", rng)
    return m, d, "seed"


def mutate(data: bytes, fmt: str, suffix: str, rng) -> tuple[bytes, str, str]:
    """One mutant of ``data``: ``(bytes, description, expect)`` (see the module docstring)."""
    if fmt in ("gltf", "glb"):
        return _mutate_gltf(data, fmt, rng)
    if fmt == "3mf":
        return _mutate_3mf(data, rng)
    if fmt == "sgc":
        return _mutate_container(data, rng)
    if fmt == "sga":
        return _mutate_sga(data, rng)
    m, d = _generic(data, fmt, suffix, rng)
    return m, d, ""
