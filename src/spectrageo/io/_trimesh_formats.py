"""glTF 2.0 (``.glb``, ``.gltf``) scenes flattened into one mesh or point cloud.

Parsed here (JSON, buffers, accessors with strides, sparse data and normalized integers).
The default scene is walked depth first in file order (without scenes every root node,
without nodes every mesh); each mesh instance is moved by its world transform (a negative
determinant reverses the winding) and the pieces are concatenated, so a file always reads to
the same arrays. Primitives: TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN become triangles
(degenerate strip joins dropped); POINTS give a point cloud, or unreferenced vertices after
the triangles; a scene of line primitives only is refused. Kept when every piece has them:
``NORMAL`` (rotated by the inverse transpose), ``COLOR_0`` (uint8 RGBA) and ``TEXCOORD_0``
(face attribute ``texcoord`` (m, 6), v up; dropped when ``KHR_texture_transform`` is used).
Materials, animations and skins are ignored; a required extension that changes the geometry
storage (Draco, meshopt) is refused by name. The declared sizes are checked against the
memory cap before any array is built. A ``.gltf`` with separate buffer files is read from a
path only.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ._common import check_alloc, exc_text, fan_triangulate
from ._ply import strips_to_triangles
from ._raw import RawGeometry

# ---------------------------------------------------------------------------------------- glTF
_MODES = {
    0: "POINTS",
    1: "LINES",
    2: "LINE_LOOP",
    3: "LINE_STRIP",
    4: "TRIANGLES",
    5: "TRIANGLE_STRIP",
    6: "TRIANGLE_FAN",
}
_COMPONENTS = {
    5120: np.dtype("i1"),
    5121: np.dtype("u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: required extensions that leave the geometry read here unchanged (materials, textures, lights)
_NEUTRAL_PREFIXES = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_")
_NEUTRAL = {"KHR_mesh_quantization"}
_EXT_WHAT = {
    "EXT_meshopt_compression": "meshoptimizer-compressed buffers",
    "KHR_meshopt_compression": "meshoptimizer-compressed buffers",
    "KHR_draco_mesh_compression": "Draco-compressed meshes",
}
#: bytes per vertex and per face while flattening (positions, normals, colours, texcoords)
_BYTES_PER_VERTEX = 8 * 3 + 8 * 3 + 4 + 8 * 2
_BYTES_PER_FACE = 8 * 3 + 8 * 6


def read_glb(raw: bytes, name: str) -> RawGeometry:
    """Binary glTF 2.0 (``.glb``): a JSON chunk and an optional binary chunk (buffer 0)."""
    if raw[:4] != b"glTF":
        raise InvalidInputError(f"{name}: not a binary glTF file (no 'glTF' magic).")
    if len(raw) < 20:
        raise InvalidInputError(f"{name}: truncated GLB file ({len(raw)} bytes).")
    clen, ctype = struct.unpack("<II", raw[12:20])
    if ctype != 0x4E4F534A or 20 + clen > len(raw):  # "JSON"
        raise InvalidInputError(f"{name}: malformed or truncated GLB (no JSON chunk).")
    try:
        doc = json.loads(raw[20 : 20 + clen].decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InvalidInputError(f"{name}: malformed GLB JSON chunk ({exc_text(exc)}).") from exc
    if not isinstance(doc, dict):
        raise InvalidInputError(f"{name}: malformed GLB (the JSON chunk is not an object).")
    _check_external(doc, name)
    pos = 20 + clen + (-clen % 4 if 20 + clen + (-clen % 4) <= len(raw) else 0)
    blob = None
    if pos + 8 <= len(raw):
        blen, btype = struct.unpack("<II", raw[pos : pos + 8])
        if btype == 0x004E4942:  # "BIN"
            if pos + 8 + blen > len(raw):
                raise InvalidInputError(
                    f"{name}: truncated GLB: the binary chunk declares {blen} bytes, "
                    f"{len(raw) - pos - 8} are present."
                )
            blob = memoryview(raw)[pos + 8 : pos + 8 + blen]
    return _Gltf(doc, name, blob, None).flatten()


def read_gltf(raw: bytes, name: str, *, folder=None) -> RawGeometry:
    """Text glTF 2.0 (``.gltf``): buffers embedded (``data:`` URIs) or, when ``folder`` is given
    (reading from a path), separate files relative to it (plain relative names inside the folder
    only; each must exist and hold at least the ``byteLength`` the glTF declares)."""
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InvalidInputError(
            f"{name}: not a glTF file (invalid JSON: {exc_text(exc)})."
        ) from exc
    if not isinstance(doc, dict):
        raise InvalidInputError(f"{name}: not a glTF file (the JSON is not an object).")
    if folder is None:
        _check_external(doc, name)
    else:
        _check_external_files(doc, name, folder)
    return _Gltf(doc, name, None, folder).flatten()


def _check_external_files(doc: dict, name: str, folder) -> None:
    from pathlib import Path
    from urllib.parse import unquote

    root = Path(folder).resolve()
    for b in _items(doc, "buffers", name):
        if not isinstance(b, dict) or not isinstance(b.get("uri"), str):
            continue
        uri = b["uri"]
        if uri.startswith("data:"):
            continue
        target = (root / unquote(uri)).resolve()
        if root not in target.parents:
            raise InvalidInputError(
                f"{name}: glTF buffer {uri!r} is outside the file's folder; refused."
            )
        if not target.is_file():
            raise InvalidInputError(f"{name}: glTF buffer file {uri!r} not found next to it.")
        declared = b.get("byteLength")
        if isinstance(declared, int) and target.stat().st_size < declared:
            raise InvalidInputError(
                f"{name}: glTF buffer {uri!r} holds {target.stat().st_size} bytes, fewer than "
                f"the {declared} its byteLength declares."
            )


def _check_external(doc: dict, name: str) -> None:
    external = [
        b["uri"]
        for b in _items(doc, "buffers", name)
        if isinstance(b, dict)
        and isinstance(b.get("uri"), str)
        and not b["uri"].startswith("data:")
    ]
    if external:
        shown = ", ".join(repr(u) for u in external[:3])
        raise InvalidInputError(
            f"{name}: the glTF buffers are separate files ({shown}); spectrageo reads glTF with "
            "embedded buffers only. Convert it to .glb (e.g. `gltf-pipeline -i in.gltf -o out.glb` "
            "or Blender) or embed the buffers as data: URIs."
        )


def _items(doc: dict, key: str, name: str) -> list:
    value = doc.get(key, [])
    if not isinstance(value, list):
        raise InvalidInputError(f"{name}: malformed glTF: `{key}` must be a list.")
    return value


def _check_required(doc: dict, name: str) -> None:
    """Refuse extensions the file requires that change how its geometry is stored."""
    for ext in _items(doc, "extensionsRequired", name):
        ext = str(ext)
        if ext in _NEUTRAL or ext.startswith(_NEUTRAL_PREFIXES):
            continue
        what = _EXT_WHAT.get(ext, "a feature spectrageo does not decode")
        raise UnsupportedFormatError(
            f"{name}: the glTF file requires the extension {ext} ({what}), which spectrageo "
            "cannot read; export it without that extension (e.g. with gltf-transform or Blender)."
        )


def _index(value, n: int, name: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise InvalidInputError(
            f"{name}: malformed glTF: {what} must be an index in 0..{n - 1}; got {value!r}."
        )
    return value


def _natural(d: dict, key: str, name: str, what: str, default: int | None = None) -> int:
    value = d.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InvalidInputError(
            f"{name}: malformed glTF: {what} `{key}` must be an integer >= 0; got {value!r}."
        )
    return value


def _node_matrix(node: dict, name: str, k: int) -> np.ndarray:
    """Local (4, 4) transform of a node: ``matrix`` (column-major) or translation/rotation/scale."""

    def numbers(key: str, size: int, default: list[float]) -> np.ndarray:
        v = node.get(key, default)
        try:
            a = np.array(v, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (size,) or not np.isfinite(a).all():
            raise InvalidInputError(
                f"{name}: malformed glTF: node {k} `{key}` must be {size} finite numbers."
            )
        return a

    if "matrix" in node:
        return numbers("matrix", 16, []).reshape(4, 4).T
    t = numbers("translation", 3, [0.0, 0.0, 0.0])
    x, y, z, w = numbers("rotation", 4, [0.0, 0.0, 0.0, 1.0])
    s = numbers("scale", 3, [1.0, 1.0, 1.0])
    q = np.hypot(np.hypot(x, y), np.hypot(z, w))
    if q > 0:
        x, y, z, w = x / q, y / q, z / q, w / q
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    M = np.eye(4)
    M[:3, :3] = R * s
    M[:3, 3] = t
    return M


class _Gltf:
    """Accessors, primitives and the scene graph of one glTF document."""

    def __init__(self, doc: dict, name: str, blob, folder) -> None:
        self.doc, self.name, self.blob, self.folder = doc, name, blob, folder
        _check_required(doc, name)
        self.accessors = _items(doc, "accessors", name)
        self.views = _items(doc, "bufferViews", name)
        self.meshes = _items(doc, "meshes", name)
        self.nodes = _items(doc, "nodes", name)
        self._buffers: dict[int, bytes] = {}
        self._cache: dict[int, np.ndarray] = {}
        self.texture_transform = "KHR_texture_transform" in (doc.get("extensionsUsed") or [])

    # -- buffers and accessors
    def buffer(self, i: int) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        bufs = _items(self.doc, "buffers", self.name)
        b = bufs[_index(i, len(bufs), self.name, "bufferView `buffer`")]
        if not isinstance(b, dict):
            raise InvalidInputError(f"{self.name}: malformed glTF: buffer {i} is not an object.")
        uri = b.get("uri")
        if uri is None:
            if i != 0 or self.blob is None:
                exts = [e for e in (b.get("extensions") or {}) if e in _EXT_WHAT]
                _check_required({"extensionsRequired": exts}, self.name)
                raise InvalidInputError(f"{self.name}: glTF buffer {i} has no data (no uri).")
            data = self.blob
        elif isinstance(uri, str) and uri.startswith("data:"):
            head, _, body = uri.partition(",")
            if not head.endswith(";base64"):
                raise InvalidInputError(
                    f"{self.name}: glTF buffer {i}: only base64 data: URIs are read."
                )
            try:
                data = base64.b64decode(body, validate=False)
            except (ValueError, binascii.Error) as exc:
                raise InvalidInputError(
                    f"{self.name}: glTF buffer {i}: malformed base64 data ({exc_text(exc)})."
                ) from exc
        elif isinstance(uri, str) and self.folder is not None:
            from pathlib import Path
            from urllib.parse import unquote

            data = (Path(self.folder) / unquote(uri)).read_bytes()
        else:
            raise InvalidInputError(f"{self.name}: glTF buffer {i} has an unreadable uri.")
        declared = _natural(b, "byteLength", self.name, f"buffer {i}", 0)
        if len(data) < declared:
            raise InvalidInputError(
                f"{self.name}: truncated glTF buffer {i}: it holds {len(data)} bytes, its "
                f"byteLength declares {declared}."
            )
        self._buffers[i] = data
        return data

    def _view(self, v: int, what: str) -> tuple[memoryview, int | None]:
        view = self.views[_index(v, len(self.views), self.name, f"{what} `bufferView`")]
        if not isinstance(view, dict):
            raise InvalidInputError(
                f"{self.name}: malformed glTF: bufferView {v} is not an object."
            )
        data = self.buffer(view.get("buffer"))
        off = _natural(view, "byteOffset", self.name, f"bufferView {v}", 0)
        length = _natural(view, "byteLength", self.name, f"bufferView {v}")
        if off + length > len(data):
            raise InvalidInputError(
                f"{self.name}: glTF bufferView {v} (bytes {off}..{off + length}) lies beyond its "
                f"buffer ({len(data)} bytes)."
            )
        stride = view.get("byteStride")
        if stride is not None:
            stride = _natural(view, "byteStride", self.name, f"bufferView {v}")
        return memoryview(data)[off : off + length], stride

    def _read(self, v: int, off: int, count: int, dtype, width: int, what: str) -> np.ndarray:
        data, stride = self._view(v, what)
        elem = dtype.itemsize * width
        stride = stride or elem
        if stride < elem:
            raise InvalidInputError(
                f"{self.name}: glTF {what}: byteStride {stride} is smaller than an element "
                f"({elem} bytes)."
            )
        if count and off + stride * (count - 1) + elem > len(data):
            raise InvalidInputError(
                f"{self.name}: glTF {what} ({count} elements) reaches beyond its bufferView "
                f"({len(data)} bytes)."
            )
        if not count:
            return np.zeros((0, width), dtype=dtype)
        return np.ndarray(
            (count, width), dtype=dtype, buffer=data, offset=off, strides=(stride, dtype.itemsize)
        ).copy()

    def count(self, i: int, what: str) -> int:
        a = self.accessors[_index(i, len(self.accessors), self.name, f"{what} accessor")]
        if not isinstance(a, dict):
            raise InvalidInputError(f"{self.name}: malformed glTF: accessor {i} is not an object.")
        return _natural(a, "count", self.name, f"accessor {i}")

    def accessor(self, i: int, what: str) -> np.ndarray:
        """Accessor ``i`` as a (count, width) array: stored dtype, float64 when normalized."""
        if i in self._cache:
            return self._cache[i]
        count = self.count(i, what)
        a = self.accessors[i]
        dtype = _COMPONENTS.get(a.get("componentType"))
        width = _WIDTHS.get(a.get("type"))
        if dtype is None or width is None:
            raise InvalidInputError(
                f"{self.name}: malformed glTF: accessor {i} ({what}) has componentType "
                f"{a.get('componentType')!r} and type {a.get('type')!r}."
            )
        check_alloc(count * width * 8, self.name, f"glTF accessor {i} ({count} elements)")
        where = f"accessor {i} ({what})"
        if "bufferView" in a:
            off = _natural(a, "byteOffset", self.name, f"accessor {i}", 0)
            arr = self._read(a["bufferView"], off, count, dtype, width, where)
        else:
            arr = np.zeros((count, width), dtype=dtype)
        sparse = a.get("sparse")
        if isinstance(sparse, dict):
            arr = self._sparse(arr, sparse, i, dtype, width, where)
        if a.get("normalized") and dtype.kind in "iu":
            scale = float(np.iinfo(dtype).max)
            arr = np.maximum(arr / scale, -1.0)
        self._cache[i] = arr
        return arr

    def _sparse(self, arr, sparse: dict, i: int, dtype, width: int, where: str) -> np.ndarray:
        n = _natural(sparse, "count", self.name, f"accessor {i} sparse")
        ind, val = sparse.get("indices"), sparse.get("values")
        if not isinstance(ind, dict) or not isinstance(val, dict):
            raise InvalidInputError(f"{self.name}: malformed glTF: {where} sparse data.")
        itype = _COMPONENTS.get(ind.get("componentType"))
        if itype is None or itype.kind != "u":
            raise InvalidInputError(f"{self.name}: malformed glTF: {where} sparse index type.")
        ioff = _natural(ind, "byteOffset", self.name, f"{where} sparse indices", 0)
        voff = _natural(val, "byteOffset", self.name, f"{where} sparse values", 0)
        idx = self._read(ind.get("bufferView"), ioff, n, itype, 1, where)[:, 0].astype(np.int64)
        vals = self._read(val.get("bufferView"), voff, n, dtype, width, where)
        if idx.size and idx.max() >= arr.shape[0]:
            raise InvalidInputError(f"{self.name}: glTF {where}: sparse index out of range.")
        arr = arr.copy()
        arr[idx] = vals
        return arr

    # -- primitives
    def _prims(self, m: int) -> list[dict]:
        mesh = self.meshes[_index(m, len(self.meshes), self.name, "node `mesh`")]
        prims = mesh.get("primitives", []) if isinstance(mesh, dict) else None
        if not isinstance(prims, list) or not all(isinstance(p, dict) for p in prims):
            raise InvalidInputError(f"{self.name}: malformed glTF: mesh {m} `primitives`.")
        return prims

    def cost(self, m: int) -> tuple[int, int]:
        """(vertices, faces) that one instance of mesh ``m`` adds, from the declared counts."""
        nv = nf = 0
        for p in self._prims(m):
            attrs = p.get("attributes")
            if not isinstance(attrs, dict) or "POSITION" not in attrs:
                continue
            mode = p.get("mode", 4)
            n = self.count(attrs["POSITION"], "POSITION")
            k = self.count(p["indices"], "indices") if "indices" in p else n
            if mode == 0:
                nv += k
            elif mode in (4, 5, 6):
                nv += n
                nf += k // 3 if mode == 4 else max(k - 2, 0)
        return nv, nf

    def primitive(self, m: int, j: int, p: dict) -> dict | None:
        """Arrays of one primitive: ``V`` and ``F`` (None for points), ``N``, ``C``, ``UV``."""
        mode = p.get("mode", 4)
        if mode not in _MODES:
            raise InvalidInputError(
                f"{self.name}: glTF mesh {m} primitive {j}: mode must be 0..6; got {mode!r}."
            )
        attrs = p.get("attributes")
        if mode in (1, 2, 3) or not isinstance(attrs, dict) or "POSITION" not in attrs:
            return None
        where = f"mesh {m} primitive {j}"
        if "KHR_draco_mesh_compression" in (p.get("extensions") or {}):
            a = self.accessors[_index(attrs["POSITION"], len(self.accessors), self.name, where)]
            if isinstance(a, dict) and "bufferView" not in a:
                _check_required({"extensionsRequired": ["KHR_draco_mesh_compression"]}, self.name)
        pos = self.accessor(attrs["POSITION"], f"{where} POSITION")
        if pos.shape[1] != 3:
            t = self.accessors[attrs["POSITION"]].get("type")
            raise InvalidInputError(
                f"{self.name}: glTF {where}: POSITION must be a VEC3 accessor; got {t}."
            )
        V = pos.astype(np.float64)
        n = V.shape[0]
        idx = None
        if "indices" in p:
            a = self.accessor(p["indices"], f"{where} indices")
            if a.shape[1] != 1 or a.dtype.kind != "u":
                raise InvalidInputError(
                    f"{self.name}: glTF {where}: indices must be unsigned integers (SCALAR)."
                )
            idx = a[:, 0].astype(np.int64)
            if idx.size and idx.max() >= n:
                raise InvalidInputError(
                    f"{self.name}: glTF {where}: index {int(idx.max())} is out of range "
                    f"(POSITION holds {n} vertices)."
                )
        out = {"V": V, "F": None, "N": None, "C": None, "UV": None}
        nrm = self._attr(attrs, "NORMAL", (3,), where)
        col = self._attr(attrs, "COLOR_0", (3, 4), where)
        uv = None if self.texture_transform else self._attr(attrs, "TEXCOORD_0", (2,), where)
        if nrm is not None and nrm.shape[0] == n:
            out["N"] = nrm.astype(np.float64)
        if col is not None and col.shape[0] == n:
            out["C"] = _rgba(col)
        if uv is not None and uv.shape[0] == n:
            uv = uv.astype(np.float64)
            uv[:, 1] = 1.0 - uv[:, 1]
            out["UV"] = uv
        if mode == 0:
            if idx is not None:
                out = {k: (None if v is None else v[idx]) for k, v in out.items()}
            return out
        if idx is None:
            idx = np.arange(n, dtype=np.int64)
        if mode == 4:
            if idx.size % 3:
                raise InvalidInputError(
                    f"{self.name}: glTF {where}: TRIANGLES need a multiple of 3 indices; got "
                    f"{idx.size}."
                )
            out["F"] = idx.reshape(-1, 3)
        else:
            # strips: odd triangles swapped to one orientation, degenerate joins dropped
            if mode == 5:
                out["F"] = strips_to_triangles([idx], self.name)
            elif idx.size >= 3:
                out["F"] = fan_triangulate(idx[None, :], self.name)[0]
            else:
                out["F"] = np.zeros((0, 3), dtype=np.int64)
        return out

    def _attr(self, attrs: dict, key: str, widths: tuple, where: str) -> np.ndarray | None:
        if key not in attrs:
            return None
        a = self.accessor(attrs[key], f"{where} {key}")
        return a if a.shape[1] in widths else None

    # -- scene graph
    def instances(self) -> list[tuple[np.ndarray, int]]:
        """(world transform, mesh index) of every mesh instance of the default scene, depth
        first in file order; without scenes, every root node; without nodes, every mesh."""
        name, nodes = self.name, self.nodes
        scenes = _items(self.doc, "scenes", name)
        if scenes:
            s = _index(self.doc.get("scene", 0), len(scenes), name, "`scene`")
            roots = scenes[s].get("nodes", []) if isinstance(scenes[s], dict) else None
        elif nodes:
            children = {c for n in nodes if isinstance(n, dict) for c in n.get("children", [])}
            roots = [k for k in range(len(nodes)) if k not in children]
        else:
            return [(np.eye(4), m) for m in range(len(self.meshes))]
        if not isinstance(roots, list):
            raise InvalidInputError(f"{name}: malformed glTF: scene `nodes` must be a list.")
        out: list[tuple[np.ndarray, int]] = []
        seen: set[int] = set()
        stack = [(r, np.eye(4)) for r in reversed(roots)]
        while stack:
            k, parent = stack.pop()
            k = _index(k, len(nodes), name, "a scene or `children` node")
            if k in seen:
                raise InvalidInputError(
                    f"{name}: malformed glTF: node {k} is reached twice in the scene graph (a "
                    "node has one parent and the graph no cycle)."
                )
            seen.add(k)
            node = nodes[k]
            if not isinstance(node, dict):
                raise InvalidInputError(f"{name}: malformed glTF: node {k} is not an object.")
            T = parent @ _node_matrix(node, name, k)
            if "mesh" in node:
                out.append((T, _index(node["mesh"], len(self.meshes), name, f"node {k} `mesh`")))
            kids = node.get("children", [])
            if not isinstance(kids, list):
                raise InvalidInputError(f"{name}: malformed glTF: node {k} `children`.")
            stack.extend((c, T) for c in reversed(kids))
        return out

    def flatten(self) -> RawGeometry:
        try:
            return self._flatten()
        except InvalidInputError:
            raise
        except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
            raise InvalidInputError(
                f"{self.name}: malformed or unsupported glTF file ({exc_text(exc)})."
            ) from exc

    def _flatten(self) -> RawGeometry:
        name = self.name
        inst = self.instances()
        costs = {m: self.cost(m) for m in {m for _, m in inst}}
        nv = sum(costs[m][0] for _, m in inst)
        nf = sum(costs[m][1] for _, m in inst)
        check_alloc(
            nv * _BYTES_PER_VERTEX + nf * _BYTES_PER_FACE,
            name,
            f"flattening the glTF scene ({len(inst)} mesh instances, {nv} vertices, {nf} faces)",
        )
        prims: dict[int, list] = {}
        meshes, clouds, modes = [], [], set()
        for T, m in inst:
            if m not in prims:
                plist = self._prims(m)
                modes.update(p.get("mode", 4) for p in plist)
                prims[m] = [self.primitive(m, j, p) for j, p in enumerate(plist)]
            for pr in prims[m]:
                if pr is not None:
                    (clouds if pr["F"] is None else meshes).append((T, pr))
        if not meshes and not clouds:
            lines = sorted(_MODES[k] for k in modes & {1, 2, 3})
            if lines:
                raise UnsupportedFormatError(
                    f"{name}: the glTF scene holds only line primitives ({', '.join(lines)}); "
                    "spectrageo reads TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN and POINTS."
                )
            raise InvalidInputError(f"{name}: the glTF scene holds no meshes or points.")
        return _concat(meshes, clouds)


def _rgba(c: np.ndarray) -> np.ndarray:
    """COLOR_0 (VEC3 or VEC4; float in [0, 1] or normalized) as uint8 RGBA."""
    if c.dtype.kind == "f":
        c = np.rint(np.clip(c, 0.0, 1.0) * 255.0)
    out = np.full((c.shape[0], 4), 255, dtype=np.uint8)
    out[:, : c.shape[1]] = np.clip(c, 0, 255).astype(np.uint8)
    return out


def _concat(meshes: list, clouds: list) -> RawGeometry:
    """Instances moved by their world transform (a negative determinant reverses the winding),
    faces offset, triangles first, then points."""
    Vs, Fs, Ns, Cs, UVs = [], [], [], [], []
    offset = 0
    for T, pr in meshes + clouds:
        A = T[:3, :3]
        Vs.append(pr["V"] @ A.T + T[:3, 3])
        F = pr["F"]
        if F is not None:
            if np.linalg.det(A) < 0:
                F = F[:, ::-1]
            Fs.append(F + offset)
            UVs.append(None if pr["UV"] is None else pr["UV"][F].reshape(-1, 6))
        offset += pr["V"].shape[0]
        n = pr["N"]
        if n is not None:
            n = n @ np.linalg.pinv(A)  # rows times the inverse transpose
            lens = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.divide(n, lens, out=np.zeros_like(n), where=lens > 0)
        Ns.append(n)
        Cs.append(pr["C"])
    V = np.concatenate(Vs)
    normals = np.concatenate(Ns) if all(n is not None for n in Ns) else None
    colors = np.concatenate(Cs) if all(c is not None for c in Cs) else None
    if not meshes:
        return RawGeometry(V, None, normals, colors)
    fattrs = {}
    if all(u is not None for u in UVs):
        fattrs["texcoord"] = np.concatenate(UVs)
    return RawGeometry(V, np.concatenate(Fs), normals, colors, {}, fattrs)
