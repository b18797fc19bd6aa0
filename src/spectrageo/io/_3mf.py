"""3MF packages flattened into one mesh.

Read with :mod:`zipfile` and a streaming :mod:`xml.parsers.expat` parser (no element tree is
kept; DTDs are refused). Parts must be stored or deflated (bzip2 and lzma are accepted) and
their inflated size is checked against the memory cap before parsing. The root model part
comes from ``_rels/.rels``; build items are expanded in file order, components recursively
(``p:path`` references followed), ``transform`` matrices applied (``p' = p @ M[:3] + M[3]``,
a negative determinant reverses the winding). The expanded instances and geometry are counted
first: more than :data:`MAX_3MF_INSTANCES` instances, or geometry beyond the memory cap, is
refused before anything is built. Coordinates stay in the model's ``unit``; materials,
colours and beam lattices are ignored.
"""

from __future__ import annotations

import io
import re
import zipfile
import zlib

import numpy as np

from .._errors import InvalidInputError
from ._common import check_alloc, exc_text
from ._raw import RawGeometry

# ----------------------------------------------------------------------------------------- 3MF
_REL_3DMODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
_PATH_ATTR = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06}path"
#: zip methods read: stored, deflated (the two 3MF allows), bzip2 and lzma
_ZIP_METHODS = {0, 8, 12, 14}
#: most object instances (build items and components, counted through every level) expanded
MAX_3MF_INSTANCES = 100_000
_FLUSH = 3 * 65536  # values buffered as text before conversion to an array


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


_BLOCK_ATTR = "spectrageo-block"
_IDENTITY = np.vstack([np.eye(3), np.zeros(3)])
_NAME = rb"(?:[A-Za-z_][\w.-]*:)?"
_BLOCK = re.compile(rb"<(" + _NAME + rb")(vertices|triangles)\s*>")
_SEPS = {
    b"vertices": [
        re.compile(rb"\s*(?:/>\s*)?<" + _NAME + rb"vertex\s+x\s*=\s*"),
        re.compile(rb"\s+y\s*=\s*"),
        re.compile(rb"\s+z\s*=\s*"),
    ],
    b"triangles": [
        re.compile(rb"\s*(?:/>\s*)?<" + _NAME + rb"triangle\s+v1\s*=\s*"),
        re.compile(rb"\s+v2\s*=\s*"),
        re.compile(rb"\s+v3\s*=\s*"),
    ],
}
_TAIL = re.compile(rb"\s*/>\s*")


def _fast_block(data: bytes, lo: int, hi: int, kind: bytes) -> np.ndarray | None:
    """Values of the ``<vertices>`` / ``<triangles>`` content ``data[lo:hi]`` when every element
    is ``<vertex x="" y="" z=""/>`` (``<triangle v1="" v2="" v3=""/>``) with nothing else, read
    in slices of about 4 MiB; None for any other layout (then expat reads it)."""
    conv, dtype = (float, np.float64) if kind == b"vertices" else (int, np.int64)
    if hi - lo <= 4096 and not data[lo:hi].strip():
        return np.zeros(0, dtype)
    out = []
    while lo < hi:
        end = data.find(b"/>", min(lo + (1 << 22), hi), hi)
        end = hi if end < 0 else end + 2
        toks = data[lo:end].split(b'"')
        lo = end
        if len(toks) % 6 != 1 or not _TAIL.fullmatch(toks[-1]):
            return None
        for group, pat in zip((toks[0:-1:6], toks[2::6], toks[4::6]), _SEPS[kind]):
            seps = set(group)
            if len(seps) > 8 or not all(pat.fullmatch(sep) for sep in seps):
                return None
        vals = toks[1::2]
        try:
            out.append(np.fromiter(map(conv, vals), dtype, len(vals)))
        except (ValueError, OverflowError):
            return None
    return np.concatenate(out)


def _cut_blocks(data: bytes, blocks: dict) -> bytes:
    """``data`` with each vertex / triangle block that :func:`_fast_block` reads replaced by an
    empty element naming its entry in ``blocks`` (the skeleton left for expat)."""
    pieces, pos, last = [], 0, 0
    while (m := _BLOCK.search(data, pos)) is not None:
        prefix, kind = m.group(1), m.group(2)
        close = data.find(b"</" + prefix + kind, m.end())
        gt = data.find(b">", close)
        if close < 0 or gt < 0:
            break
        arr = _fast_block(data, m.end(), close, kind)
        pos = m.end()
        if arr is None:
            continue
        key = str(len(blocks))
        blocks[key] = arr
        pieces += [
            data[last : m.start()],
            b'<%s%s %s="%s"/>' % (prefix, kind, _BLOCK_ATTR.encode(), key.encode()),
        ]
        last = pos = gt + 1
    if not pieces:
        return data
    pieces.append(data[last:])
    return b"".join(pieces)


class _Object:
    """One 3MF ``<object>``: its mesh (vertex and triangle text converted in chunks) and its
    components ``(part path, object id, transform text)``."""

    def __init__(self, oid: str) -> None:
        self.oid = oid
        self.has_mesh = False
        self.V: np.ndarray = np.zeros((0, 3))
        self.F: np.ndarray = np.zeros((0, 3), dtype=np.int64)
        self.components: list[tuple[str, str, str | None]] = []
        self._v: list = []
        self._t: list = []
        self._vc: list[np.ndarray] = []
        self._tc: list[np.ndarray] = []

    def flush(self, name: str, final: bool = False) -> None:
        try:
            if self._v:
                if None in self._v:
                    raise ValueError("a <vertex> lacks x, y or z")
                self._vc.append(np.array(self._v, dtype=np.float64))
            if self._t:
                if None in self._t:
                    raise ValueError("a <triangle> lacks v1, v2 or v3")
                self._tc.append(np.array(self._t, dtype=np.int64))
        except OverflowError as exc:
            raise InvalidInputError(
                f"{name}: 3MF object {self.oid}: a triangle's vertex index is beyond the 64-bit "
                "integer range; indices must lie in [0, number of vertices)."
            ) from exc
        except (ValueError, TypeError) as exc:
            raise InvalidInputError(
                f"{name}: 3MF object {self.oid}: missing or malformed vertex/triangle attributes "
                f"({exc_text(exc)})."
            ) from exc
        self._v, self._t = [], []
        if final:
            self.V = np.concatenate([*self._vc, np.zeros(0)]).reshape(-1, 3)
            self.F = np.concatenate([*self._tc, np.zeros(0, np.int64)]).reshape(-1, 3)
            self._vc, self._tc = [], []
            F, n = self.F, self.V.shape[0]
            if F.size and (F.min() < 0 or F.max() >= n):
                raise InvalidInputError(
                    f"{name}: 3MF object {self.oid}: triangle indices out of range (0..{n - 1})."
                )


class _ModelParser:
    """Streaming (expat) reader of one 3MF model part: objects and build items, no tree kept."""

    def __init__(self, name: str, path: str) -> None:
        self.name, self.path = name, path
        self.objects: dict[str, _Object] = {}
        self.items: list[tuple[str, str, str | None]] = []
        self.depth = 0
        self.cur: _Object | None = None
        self.blocks: dict[str, np.ndarray] = {}

    def start(self, tag: str, attrs: dict) -> None:
        self.depth += 1
        tag = _local(tag)
        cur = self.cur
        if _BLOCK_ATTR in attrs and cur is not None and tag in ("vertices", "triangles"):
            block = self.blocks.get(attrs[_BLOCK_ATTR])
            if block is not None:
                (cur._vc if tag == "vertices" else cur._tc).append(block)
        elif tag == "vertex" and cur is not None:
            self._add(cur._v, attrs.get("x"), attrs.get("y"), attrs.get("z"))
        elif tag == "triangle" and cur is not None:
            self._add(cur._t, attrs.get("v1"), attrs.get("v2"), attrs.get("v3"))
        elif self.depth == 1 and tag != "model":
            raise InvalidInputError(f"{self.name}: 3MF part {self.path!r} is not a <model>.")
        elif tag == "object":
            self.cur = _Object(attrs.get("id", ""))
        elif tag == "mesh" and cur is not None:
            cur.has_mesh = True
        elif tag == "component" and cur is not None:
            sub = attrs.get(_PATH_ATTR) or self.path
            cur.components.append((sub, attrs.get("objectid", ""), attrs.get("transform")))
        elif tag == "item":
            sub = attrs.get(_PATH_ATTR) or self.path
            self.items.append((sub, attrs.get("objectid", ""), attrs.get("transform")))

    def _add(self, buf: list, a, b, c) -> None:
        buf += (a, b, c)
        if len(buf) >= _FLUSH:
            self.cur.flush(self.name)
            n = sum(x.size for x in self.cur._vc) + sum(x.size for x in self.cur._tc)
            check_alloc(
                8 * n, self.name, f"3MF object {self.cur.oid} ({n // 3} vertices/triangles)"
            )

    def end(self, tag: str) -> None:
        self.depth -= 1
        if _local(tag) == "object" and self.cur is not None:
            self.cur.flush(self.name, final=True)
            self.objects.setdefault(self.cur.oid, self.cur)
            self.cur = None


class _Package:
    def __init__(self, raw: bytes, name: str) -> None:
        self.name = name
        try:
            self.zip = zipfile.ZipFile(io.BytesIO(raw))
        except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
            raise InvalidInputError(
                f"{name}: not a 3MF file (not a zip package: {exc_text(exc)})."
            ) from exc
        self.members = {n.lstrip("/").lower(): n for n in self.zip.namelist()}
        self.parts: dict[str, _ModelParser] = {}

    def _open(self, path: str):
        key = path.lstrip("/").lower()
        if key not in self.members:
            raise InvalidInputError(f"{self.name}: the 3MF package lacks the part {path!r}.")
        info = self.zip.getinfo(self.members[key])
        if info.compress_type not in _ZIP_METHODS:
            raise InvalidInputError(
                f"{self.name}: 3MF part {path!r} uses zip compression method "
                f"{info.compress_type}; 3MF parts are stored (0) or deflated (8)."
            )
        if info.flag_bits & 0x1:
            raise InvalidInputError(f"{self.name}: 3MF part {path!r} is encrypted.")
        check_alloc(info.file_size, self.name, f"inflating 3MF part {path!r}")
        return self.zip.open(info), info.file_size

    def _parse(self, path: str, start, end, blocks: dict | None = None) -> None:
        """Parse part ``path`` with expat (DTDs refused); with ``blocks``, the vertex and triangle
        blocks of the common layout are converted first (:func:`_cut_blocks`)."""
        from xml.parsers import expat

        p = expat.ParserCreate(namespace_separator="}")
        p.StartElementHandler, p.EndElementHandler = start, end

        def no_dtd(*_args) -> None:
            raise InvalidInputError(f"{self.name}: 3MF part {path!r} declares a DTD; refused.")

        p.StartDoctypeDeclHandler = no_dtd
        try:
            fh, size = self._open(path)
            with fh:  # inflated up to the declared (checked) size, never beyond
                data = fh.read(size)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError) as exc:
            raise InvalidInputError(
                f"{self.name}: corrupt 3MF part {path!r} (damaged compressed data: "
                f"{exc_text(exc)})."
            ) from exc
        if blocks is not None:
            data = _cut_blocks(data, blocks)
        try:
            p.Parse(data, True)
        except expat.ExpatError as exc:
            if exc.code == expat.errors.codes[expat.errors.XML_ERROR_NO_MEMORY]:
                raise InvalidInputError(
                    f"{self.name}: not enough memory to parse 3MF part {path!r}."
                ) from None
            raise InvalidInputError(
                f"{self.name}: malformed XML in 3MF part {path!r} ({exc})."
            ) from exc

    def root_model(self) -> str:
        if "_rels/.rels" not in self.members:
            return "3D/3dmodel.model"
        found: list[str] = []

        def start(tag: str, attrs: dict) -> None:
            if _local(tag) == "Relationship" and attrs.get("Type") == _REL_3DMODEL:
                found.append(attrs.get("Target", "").lstrip("/"))

        self._parse("_rels/.rels", start, lambda tag: None)
        return found[0] if found else "3D/3dmodel.model"

    def model(self, path: str) -> _ModelParser:
        key = path.lstrip("/").lower()
        if key not in self.parts:
            mp = _ModelParser(self.name, path.lstrip("/"))
            self._parse(path, mp.start, mp.end, mp.blocks)
            self.parts[key] = mp
        return self.parts[key]

    def get(self, path: str, oid: str) -> _Object:
        obj = self.model(path).objects.get(oid)
        if obj is None:
            raise InvalidInputError(
                f"{self.name}: 3MF refers to object {oid!r}, which {path} lacks."
            )
        return obj


def _sizes(pkg: _Package, path: str, oid: str, memo: dict, stack: set) -> tuple[int, int, int]:
    """(vertices, triangles, instances) that one instance of object ``oid`` expands to."""
    key = (path.lstrip("/").lower(), oid)
    if key in memo:
        return memo[key]
    if key in stack or len(stack) > 32:
        raise InvalidInputError(
            f"{pkg.name}: 3MF components nest too deep or form a cycle (object {oid!r})."
        )
    stack.add(key)
    obj = pkg.get(path, oid)
    nv, nf, ni = obj.V.shape[0], obj.F.shape[0], 1
    for sub, cid, _t in obj.components:
        v, f, i = _sizes(pkg, sub.lstrip("/"), cid, memo, stack)
        nv, nf, ni = nv + v, nf + f, ni + i
    stack.discard(key)
    memo[key] = (nv, nf, ni)
    return memo[key]


def read_3mf(raw: bytes, name: str) -> RawGeometry:
    """3MF package (see the module docstring)."""
    pkg = _Package(raw, name)
    root_path = pkg.root_model()
    root = pkg.model(root_path)
    items = [(p.lstrip("/"), oid, _matrix(t, name)) for p, oid, t in root.items]
    if not items:  # no build section: every mesh object of the root part, untransformed
        items = [
            (root_path, o.oid, _matrix(None, name)) for o in root.objects.values() if o.has_mesh
        ]
    memo: dict = {}
    nv = nf = ni = 0
    for p, oid, _M in items:
        v, f, i = _sizes(pkg, p, oid, memo, set())
        nv, nf, ni = nv + v, nf + f, ni + i
    if ni > MAX_3MF_INSTANCES:
        raise InvalidInputError(
            f"{name}: the 3MF build expands to {ni} object instances (components nested in "
            f"components), more than the limit of {MAX_3MF_INSTANCES}."
        )
    check_alloc(24 * (nv + nf), name, f"expanding the 3MF build ({nv} vertices, {nf} triangles)")
    Vs: list[np.ndarray] = []
    Fs: list[np.ndarray] = []
    count = 0

    def emit(path: str, oid: str, M: np.ndarray) -> None:
        nonlocal count
        obj = pkg.get(path, oid)
        if obj.V.shape[0] or obj.F.shape[0]:
            Vs.append(obj.V if (M == _IDENTITY).all() else obj.V @ M[:3] + M[3])
            F = obj.F[:, ::-1] if np.linalg.det(M[:3]) < 0 else obj.F
            Fs.append(F + count)
            count += obj.V.shape[0]
        for sub, cid, t in obj.components:
            emit(sub.lstrip("/"), cid, _compose(_matrix(t, name), M))

    for p, oid, M in items:
        emit(p, oid, M)
    if not Vs or count == 0:
        raise InvalidInputError(f"{name}: the 3MF package holds no mesh vertices.")
    if len(Vs) == 1:  # one piece: its arrays as they are (no copy)
        return RawGeometry(Vs[0], Fs[0])
    return RawGeometry(np.concatenate(Vs), np.concatenate(Fs))
