"""Scene formats flattened into one mesh or point cloud: glTF 2.0 (``.glb``, ``.gltf``) and 3MF.

glTF / GLB
    Read with :func:`trimesh.load_scene` (``process=False``: vertices as stored) and flattened in
    the order of ``scene.graph.nodes_geometry``: each instance moved by its world transform (a
    negative determinant reverses the winding), faces offset, pieces concatenated. Kept when
    every mesh has them: ``NORMAL`` (rotated by the inverse transpose), ``COLOR_0`` (uint8 RGBA)
    and ``TEXCOORD_0`` (face attribute ``texcoord`` (m, 6), v up). Point primitives give a point
    cloud, or are appended as unreferenced vertices next to triangles; materials, animations,
    skins and lines are ignored. A ``.gltf`` with separate buffer files is read from a path only.
3MF
    Read with :mod:`zipfile` and :mod:`xml.etree.ElementTree` (trimesh's loader needs ``lxml`` and
    ``networkx``). The root model part comes from ``_rels/.rels``; build items are expanded in
    file order, components recursively (``p:path`` references followed), ``transform`` matrices
    applied (``p' = p @ M[:3] + M[3]``, a negative determinant reverses the winding).
    Coordinates stay in the model's ``unit``; materials, colours and beam lattices are ignored.
"""

from __future__ import annotations

import io
import json
import struct
import xml.etree.ElementTree as ET
import zipfile

import numpy as np

from .._errors import InvalidInputError
from ._common import exc_text
from ._raw import RawGeometry


# ---------------------------------------------------------------------------------------- glTF
def read_glb(raw: bytes, name: str) -> RawGeometry:
    """Binary glTF 2.0 (``.glb``)."""
    if raw[:4] != b"glTF":
        raise InvalidInputError(f"{name}: not a binary glTF file (no 'glTF' magic).")
    _check_glb_buffers(raw, name)
    return _read_trimesh_scene(raw, name, "glb")


def read_gltf(raw: bytes, name: str, *, folder=None) -> RawGeometry:
    """Text glTF 2.0 (``.gltf``): buffers embedded (``data:`` URIs) or, when ``folder`` is given
    (reading from a path), separate files relative to it (plain relative names inside the folder
    only; each must exist and hold at least the ``byteLength`` the glTF declares)."""
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise InvalidInputError(
            f"{name}: not a glTF file (invalid JSON: {exc_text(exc)})."
        ) from exc
    if not isinstance(doc, dict):
        raise InvalidInputError(f"{name}: not a glTF file (the JSON is not an object).")
    if folder is None:
        _check_external(doc, name)
        return _read_trimesh_scene(raw, name, "gltf")
    _check_external_files(doc, name, folder)
    return _read_trimesh_scene(raw, name, "gltf", folder=folder)


def _check_external_files(doc: dict, name: str, folder) -> None:
    from pathlib import Path

    root = Path(folder).resolve()
    for b in doc.get("buffers", []) or []:
        if not isinstance(b, dict) or not isinstance(b.get("uri"), str):
            continue
        uri = b["uri"]
        if uri.startswith("data:"):
            continue
        from urllib.parse import unquote

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
        for b in doc.get("buffers", []) or []
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


def _check_glb_buffers(raw: bytes, name: str) -> None:
    """Refuse a GLB whose JSON chunk refers to external buffer files (rare)."""
    if len(raw) < 20:
        raise InvalidInputError(f"{name}: truncated GLB file ({len(raw)} bytes).")
    clen, ctype = struct.unpack("<II", raw[12:20])
    if ctype != 0x4E4F534A or 20 + clen > len(raw):  # "JSON"
        raise InvalidInputError(f"{name}: malformed or truncated GLB (no JSON chunk).")
    try:
        doc = json.loads(raw[20 : 20 + clen].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise InvalidInputError(f"{name}: malformed GLB JSON chunk ({exc_text(exc)}).") from exc
    if isinstance(doc, dict):
        _check_external(doc, name)


def _stored_vertex_normals(geom) -> np.ndarray | None:
    """Vertex normals the file stored (trimesh computes them on access otherwise)."""
    cache = getattr(getattr(geom, "_cache", None), "cache", {})
    vn = cache.get("vertex_normals") if isinstance(cache, dict) else None
    if vn is None or np.shape(vn) != np.shape(geom.vertices):
        return None
    return np.asarray(vn, dtype=np.float64)


def _read_trimesh_scene(raw: bytes, name: str, file_type: str, *, folder=None) -> RawGeometry:
    import trimesh

    kw = {}
    if folder is not None:
        from trimesh.resolvers import FilePathResolver

        kw["resolver"] = FilePathResolver(str(folder))
    try:
        scene = trimesh.load_scene(io.BytesIO(raw), file_type=file_type, process=False, **kw)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types on malformed input
        raise InvalidInputError(
            f"{name}: malformed or unsupported {file_type.upper()} file ({exc_text(exc)})."
        ) from exc
    meshes, clouds = [], []
    for node in scene.graph.nodes_geometry:
        transform, geom_name = scene.graph[node]
        geom = scene.geometry.get(geom_name)
        if isinstance(geom, trimesh.Trimesh):
            meshes.append((np.asarray(transform, dtype=np.float64), geom))
        elif isinstance(geom, trimesh.PointCloud):
            clouds.append((np.asarray(transform, dtype=np.float64), geom))
    if not meshes and not clouds:
        raise InvalidInputError(f"{name}: the {file_type.upper()} scene holds no meshes or points.")
    Vs, Fs, Ns, Cs, UVs = [], [], [], [], []
    offset = 0
    for T, g in meshes:
        V = np.asarray(g.vertices, dtype=np.float64)
        F = np.asarray(g.faces, dtype=np.int64)
        A = T[:3, :3]
        Vs.append(V @ A.T + T[:3, 3])
        if np.linalg.det(A) < 0:
            F = F[:, ::-1]
        Fs.append(F + offset)
        offset += V.shape[0]
        vn = _stored_vertex_normals(g)
        if vn is not None:
            n = vn @ np.linalg.inv(A)  # rows times inverse-transpose
            lens = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.divide(n, lens, out=np.zeros_like(n), where=lens > 0)
        Ns.append(n if vn is not None else None)
        vis = g.visual
        uv = getattr(vis, "uv", None) if getattr(vis, "kind", None) == "texture" else None
        UVs.append(None if uv is None else np.asarray(uv, dtype=np.float64)[F].reshape(-1, 6))
        vc = None
        if getattr(vis, "kind", None) == "vertex":
            vc = np.asarray(vis.vertex_colors, dtype=np.uint8)
        Cs.append(vc)
    for T, pc in clouds:
        P = np.asarray(pc.vertices, dtype=np.float64)
        Vs.append(P @ T[:3, :3].T + T[:3, 3])
        Ns.append(None)
        c = np.asarray(pc.colors) if len(getattr(pc, "colors", [])) else None
        Cs.append(c.astype(np.uint8) if c is not None and c.shape == (P.shape[0], 4) else None)
    V = np.concatenate(Vs)
    normals = np.concatenate(Ns) if all(n is not None for n in Ns) else None
    colors = np.concatenate(Cs) if all(c is not None for c in Cs) else None
    if not meshes:
        return RawGeometry(V, None, normals, colors)
    F = np.concatenate(Fs)
    fattrs = {}
    if all(u is not None for u in UVs):
        fattrs["texcoord"] = np.concatenate(UVs)
    return RawGeometry(V, F, normals, colors, {}, fattrs)


# ----------------------------------------------------------------------------------------- 3MF
_REL_3DMODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
_PROD_NS = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _matrix(text: str | None, name: str) -> np.ndarray:
    """3MF transform (12 numbers, row-major 4x3) as a (4, 3) array; identity when absent."""
    if not text:
        return np.vstack([np.eye(3), np.zeros(3)])
    try:
        m = np.array(text.split(), dtype=np.float64)
    except ValueError as exc:
        raise InvalidInputError(f"{name}: malformed 3MF transform {text!r}.") from exc
    if m.size != 12 or not np.isfinite(m).all():
        raise InvalidInputError(f"{name}: 3MF transform must have 12 numbers; got {text!r}.")
    return m.reshape(4, 3)


def _compose(inner: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """Transform applying ``inner`` then ``outer`` (both (4, 3) row-vector matrices)."""
    out = np.empty((4, 3))
    out[:3] = inner[:3] @ outer[:3]
    out[3] = inner[3] @ outer[:3] + outer[3]
    return out


class _Package:
    def __init__(self, raw: bytes, name: str) -> None:
        self.name = name
        try:
            self.zip = zipfile.ZipFile(io.BytesIO(raw))
        except (zipfile.BadZipFile, ValueError, OSError) as exc:
            raise InvalidInputError(
                f"{name}: not a 3MF file (not a zip package: {exc_text(exc)})."
            ) from exc
        self.members = {n.lstrip("/").lower(): n for n in self.zip.namelist()}
        self.parts: dict[str, dict[str, ET.Element]] = {}

    def read(self, path: str) -> bytes:
        key = path.lstrip("/").lower()
        if key not in self.members:
            raise InvalidInputError(f"{self.name}: the 3MF package lacks the part {path!r}.")
        try:
            return self.zip.read(self.members[key])
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            raise InvalidInputError(
                f"{self.name}: corrupt 3MF part {path!r} ({exc_text(exc)})."
            ) from exc

    def xml(self, path: str) -> ET.Element:
        try:
            return ET.fromstring(self.read(path))
        except ET.ParseError as exc:
            raise InvalidInputError(
                f"{self.name}: malformed XML in 3MF part {path!r} ({exc})."
            ) from exc

    def root_model(self) -> str:
        if "_rels/.rels" in self.members:
            rels = self.xml("_rels/.rels")
            for rel in rels.iter():
                if _local(rel.tag) == "Relationship" and rel.get("Type") == _REL_3DMODEL:
                    return rel.get("Target", "").lstrip("/")
        return "3D/3dmodel.model"

    def objects(self, path: str) -> dict[str, ET.Element]:
        key = path.lstrip("/").lower()
        if key not in self.parts:
            root = self.xml(path)
            if _local(root.tag) != "model":
                raise InvalidInputError(f"{self.name}: 3MF part {path!r} is not a <model>.")
            self.parts[key] = {o.get("id", ""): o for o in root.iter() if _local(o.tag) == "object"}
        return self.parts[key]


def _mesh_arrays(mesh: ET.Element, name: str, oid: str) -> tuple[np.ndarray, np.ndarray]:
    verts, tris = [], []
    for child in mesh:
        tag = _local(child.tag)
        if tag == "vertices":
            verts = [
                (v.get("x"), v.get("y"), v.get("z")) for v in child if _local(v.tag) == "vertex"
            ]
        elif tag == "triangles":
            tris = [
                (t.get("v1"), t.get("v2"), t.get("v3"))
                for t in child
                if _local(t.tag) == "triangle"
            ]
    try:
        V = np.array(verts, dtype=np.float64).reshape(-1, 3)
        F = np.array(tris, dtype=np.int64).reshape(-1, 3)
    except (ValueError, TypeError) as exc:
        raise InvalidInputError(
            f"{name}: 3MF object {oid}: missing or malformed vertex/triangle attributes "
            f"({exc_text(exc)})."
        ) from exc
    if F.size and (F.min() < 0 or F.max() >= V.shape[0]):
        raise InvalidInputError(
            f"{name}: 3MF object {oid}: triangle indices out of range (0..{V.shape[0] - 1})."
        )
    return V, F


def read_3mf(raw: bytes, name: str) -> RawGeometry:
    """3MF package (see the module docstring)."""
    pkg = _Package(raw, name)
    root_path = pkg.root_model()
    root = pkg.xml(root_path)
    if _local(root.tag) != "model":
        raise InvalidInputError(f"{name}: 3MF root part {root_path!r} is not a <model>.")
    pkg.objects(root_path)
    Vs: list[np.ndarray] = []
    Fs: list[np.ndarray] = []
    count = [0]

    def emit(path: str, oid: str, M: np.ndarray, depth: int) -> None:
        if depth > 32:
            raise InvalidInputError(f"{name}: 3MF components nest too deep (a cycle?).")
        obj = pkg.objects(path).get(oid)
        if obj is None:
            raise InvalidInputError(f"{name}: 3MF refers to object {oid!r}, which {path} lacks.")
        for child in obj:
            tag = _local(child.tag)
            if tag == "mesh":
                V, F = _mesh_arrays(child, name, oid)
                Vs.append(V @ M[:3] + M[3])
                if np.linalg.det(M[:3]) < 0:
                    F = F[:, ::-1]
                Fs.append(F + count[0])
                count[0] += V.shape[0]
            elif tag == "components":
                for comp in child:
                    if _local(comp.tag) != "component":
                        continue
                    sub = comp.get(f"{{{_PROD_NS}}}path") or path
                    emit(
                        sub.lstrip("/"),
                        comp.get("objectid", ""),
                        _compose(_matrix(comp.get("transform"), name), M),
                        depth + 1,
                    )

    items = [e for e in root.iter() if _local(e.tag) == "item"]
    if items:
        for it in items:
            sub = it.get(f"{{{_PROD_NS}}}path") or root_path
            emit(sub.lstrip("/"), it.get("objectid", ""), _matrix(it.get("transform"), name), 0)
    else:  # no build section: every mesh object of the root part, untransformed
        for oid, obj in pkg.objects(root_path).items():
            if any(_local(c.tag) == "mesh" for c in obj):
                emit(root_path, oid, _matrix(None, name), 0)
    if not Vs or sum(v.shape[0] for v in Vs) == 0:
        raise InvalidInputError(f"{name}: the 3MF package holds no mesh vertices.")
    return RawGeometry(np.concatenate(Vs), np.concatenate(Fs))
