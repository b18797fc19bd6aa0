"""PLY (ascii, binary little/big endian) through :mod:`plyfile`.

plyfile parses the header and writes it; bodies are read and written with vectorised numpy for
the common layouts (plyfile's row-by-row reader, about 50x slower, is the fallback for
variable-length lists; written bytes equal plyfile's, which a test checks).

Element ``vertex`` gives positions (``x y z``), normals (``nx ny nz``), colours (``red green blue
[alpha]``) and other properties as vertex attributes; ``face`` gives ``vertex_indices`` (or
``vertex_index``; polygons fan-triangulated in file order) and other properties as face
attributes; other elements are ignored. A fixed-length list becomes an (n, k) attribute; other
variable-length lists are skipped. Triangle strips (element ``tristrips``): triangle ``j`` of a
strip ``s`` is ``(s[j], s[j+1], s[j+2])``, swapped for odd ``j`` (one orientation, as MeshLab
reads them); ``-1`` restarts the strip; triangles with a repeated index are skipped; strip
triangles follow the ``face`` triangles, whose other properties are then dropped. MeshLab's
per-corner ``property list uchar float texcoord`` is the (m, 6) face attribute ``texcoord``.

Header and body must agree, checked before any array is sized: counts non-negative; in ascii
exactly the declared rows (missing lines: truncated; extra non-blank lines: an error); in binary
the counts must fit the bytes present, with less than one row left over; list lengths within
their type and non-negative. Errors name the element, the property and the value.
"""

from __future__ import annotations

import io
import warnings
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ._common import check_alloc, exc_text, fan_triangulate
from ._raw import RawGeometry

_NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
_COLOR_NAMES = (
    ("red", "green", "blue", "alpha"),
    ("r", "g", "b", "a"),
    ("diffuse_red", "diffuse_green", "diffuse_blue", "diffuse_alpha"),
)
_FACE_INDEX_NAMES = ("vertex_indices", "vertex_index")
_WANTED = frozenset({"vertex", "face", "tristrips"})
_PLY_SCALAR = {
    "i1": "i1",
    "u1": "u1",
    "i2": "i2",
    "u2": "u2",
    "i4": "i4",
    "u4": "u4",
    "f4": "f4",
    "f8": "f8",
}


def _plyfile():
    import plyfile

    return plyfile


# --------------------------------------------------------------------------------------- reading
def _parse_header(raw: bytes, name: str):
    plyfile = _plyfile()
    stream = io.BytesIO(raw)
    try:
        header = plyfile.PlyData._parse_header(stream)
    except plyfile.PlyParseError as exc:
        raise InvalidInputError(f"{name}: malformed PLY header ({exc_text(exc)}).") from exc
    except (UnicodeDecodeError, ValueError, TypeError) as exc:
        raise InvalidInputError(f"{name}: not a PLY file ({exc_text(exc)}).") from exc
    return header, stream.tell()


def _min_row_bytes(elt, bo: str) -> int:
    """Fewest bytes a binary row of ``elt`` can take: its scalars and its lists' length prefixes."""
    plyfile = _plyfile()
    size = 0
    for p in elt.properties:
        if isinstance(p, plyfile.PlyListProperty):
            size += np.dtype(p.list_dtype(bo)[0]).itemsize
        else:
            size += np.dtype(p.dtype(bo)).itemsize
    return size


def _line_starts(body) -> np.ndarray:
    """Start offsets of the lines of ``body`` (a last line without newline counts)."""
    nl = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    starts = np.r_[0, nl + 1]
    return starts[starts < len(body)] if len(body) else np.zeros(0, dtype=np.int64)


def _check_counts(raw: bytes, header, offset: int, name: str) -> None:
    """Element counts against the body, before anything is sized by them (module docstring)."""
    elements = header.elements
    for elt in elements:
        if elt.count < 0:
            raise InvalidInputError(
                f"{name}: PLY element '{elt.name}' count must be >= 0; got {elt.count}."
            )
    body = memoryview(raw)[offset:]
    if header.text:
        starts = _line_starts(body)
        declared = sum(elt.count for elt in elements)
        if declared > starts.size:
            row = 0
            for elt in elements:
                if row + elt.count > starts.size:
                    raise InvalidInputError(
                        f"{name}: truncated PLY: element '{elt.name}' declares {elt.count} rows "
                        f"but only {max(starts.size - row, 0)} lines remain."
                    )
                row += elt.count
        if declared < starts.size and bytes(body[starts[declared] :]).strip():
            extra = sum(1 for ln in bytes(body[starts[declared] :]).split(b"\n") if ln.strip())
            raise InvalidInputError(
                f"{name}: PLY body holds {extra} more non-empty line(s) than the {declared} rows "
                f"the header declares ({', '.join(f'{e.name} {e.count}' for e in elements)})."
            )
        for elt in elements:
            check_alloc(16 * elt.count * max(len(elt.properties), 1), name, f"PLY '{elt.name}'")
        return
    bo = header.byte_order
    need = 0
    for elt in elements:
        row = max(_min_row_bytes(elt, bo), 1)
        if need + elt.count * row > len(body):
            raise InvalidInputError(
                f"{name}: truncated PLY: element '{elt.name}' needs {elt.count * row} bytes "
                f"({elt.count} rows of at least {row}) at offset {offset + need}, the file has "
                f"{max(len(body) - need, 0)}."
            )
        need += elt.count * row
        check_alloc(2 * elt.count * max(row, 8), name, f"PLY '{elt.name}'")


def _check_trailing(left: int, header, name: str) -> None:
    """Binary body: ``left`` bytes after the last element; one row's worth or more is an error."""
    if not header.elements or left <= 0:
        return
    last = header.elements[-1]
    row = max(_min_row_bytes(last, header.byte_order), 1)
    if left >= row:
        raise InvalidInputError(
            f"{name}: PLY body has {left} bytes after the declared elements "
            f"({', '.join(f'{e.name} {e.count}' for e in header.elements)}); an element count "
            "is too small or the file is corrupted."
        )


def _read_full_plyfile(raw: bytes, name: str, header=None) -> dict[str, dict[str, np.ndarray]]:
    """Fallback: plyfile's own reader for every element."""
    plyfile = _plyfile()
    stream = io.BytesIO(raw)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # plyfile's loadtxt on empty lists
            data = plyfile.PlyData.read(stream, mmap=False)
    except plyfile.PlyParseError as exc:
        raise InvalidInputError(f"{name}: malformed or truncated PLY ({exc_text(exc)}).") from exc
    except (ValueError, TypeError, UnicodeDecodeError, EOFError, OverflowError) as exc:
        raise InvalidInputError(f"{name}: malformed or truncated PLY ({exc_text(exc)}).") from exc
    if header is not None and not header.text:
        _check_trailing(len(raw) - stream.tell(), header, name)
    out: dict[str, dict[str, np.ndarray]] = {}
    for elt in data.elements:
        cols: dict[str, np.ndarray] = {}
        arr = elt.data
        for prop in elt.properties:
            col = arr[prop.name]
            if col.dtype == object:
                lens = {len(x) for x in col}
                if len(lens) == 1 and len(col):
                    col = np.stack([np.asarray(x) for x in col])
            cols[prop.name] = col
        if elt.name in _WANTED:
            out[elt.name] = cols
    return out


def _ascii_elements(raw: bytes, header, offset: int, name: str) -> dict | None:
    """Vectorised ascii body; None when a layout needs the row-by-row fallback."""
    plyfile = _plyfile()
    body = memoryview(raw)[offset:]
    nl = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    # line k spans [start_k, nl[k]); a last line without newline is accepted
    ends = nl
    if len(body) and (nl.size == 0 or nl[-1] != len(body) - 1):
        ends = np.r_[nl, len(body)]
    starts = np.r_[0, ends[:-1] + 1] if ends.size else np.zeros(0, dtype=np.int64)
    out: dict[str, dict[str, np.ndarray]] = {}
    row = 0
    for elt in header.elements:
        count = elt.count
        if row + count > ends.size:
            raise InvalidInputError(
                f"{name}: truncated PLY: element '{elt.name}' declares {count} rows but only "
                f"{max(ends.size - row, 0)} lines remain."
            )
        if elt.name not in _WANTED:
            row += count  # one line per row in ascii PLY: unused elements are skipped unparsed
            continue
        props = elt.properties
        cols: dict[str, np.ndarray] = {}
        if count == 0:
            for p in props:
                if isinstance(p, plyfile.PlyListProperty):
                    cols[p.name] = np.zeros((0, 0), dtype=p.list_dtype()[1])
                else:
                    cols[p.name] = np.zeros(0, dtype=p.dtype())
            out[elt.name] = cols
            continue
        chunk = bytes(body[starts[row] : ends[row + count - 1]])
        row += count
        try:
            table = np.loadtxt(io.BytesIO(chunk), dtype=np.float64, ndmin=2)
        except ValueError:
            return None
        if table.shape[0] != count:
            return None
        c = 0
        for p in props:
            if isinstance(p, plyfile.PlyListProperty):
                if c >= table.shape[1]:
                    return None
                lens = table[:, c]
                L = lens[0]
                len_info = np.iinfo(np.dtype(p.list_dtype()[0]))
                if lens.min() < 0 or lens.max() > len_info.max:
                    bad = lens.min() if lens.min() < 0 else lens.max()
                    raise InvalidInputError(
                        f"{name}: PLY list length {bad:.17g} of property '{p.name}' of element "
                        f"'{elt.name}' is out of range for its length type "
                        f"{np.dtype(p.list_dtype()[0])} (0..{len_info.max})."
                    )
                if not (lens == L).all() or L != int(L):
                    return None
                L = int(L)
                vals = table[:, c + 1 : c + 1 + L]
                if vals.shape[1] != L:
                    return None
                cols[p.name] = _cast(vals, p.list_dtype()[1], name, elt.name, p.name)
                c += 1 + L
            else:
                if c >= table.shape[1]:
                    return None
                cols[p.name] = _cast(table[:, c], p.dtype(), name, elt.name, p.name)
                c += 1
        if c != table.shape[1]:
            return None
        out[elt.name] = cols
    return out


def _cast(values: np.ndarray, dtype: Any, name: str, element: str, prop: str) -> np.ndarray:
    dt = np.dtype(dtype)
    if dt.kind in "iu":
        if not np.isfinite(values).all() or (values != np.round(values)).any():
            raise InvalidInputError(
                f"{name}: property '{prop}' of element '{element}' must hold integers."
            )
        info = np.iinfo(dt)
        if values.size and (values.min() < info.min or values.max() > info.max):
            raise InvalidInputError(
                f"{name}: property '{prop}' of element '{element}' is out of range for {dt}."
            )
    return values.astype(dt)


def _binary_elements(raw: bytes, header, offset: int, name: str) -> dict | None:
    """Vectorised binary body; None when a layout needs the row-by-row fallback."""
    plyfile = _plyfile()
    bo = header.byte_order
    out: dict[str, dict[str, np.ndarray]] = {}
    pos = offset
    complete = True
    for i_elt, elt in enumerate(header.elements):
        if _WANTED <= out.keys() or not any(e.name in _WANTED for e in header.elements[i_elt:]):
            complete = False
            break
        count = elt.count
        props = elt.properties
        has_list = any(isinstance(p, plyfile.PlyListProperty) for p in props)
        fields: list[tuple] = []
        list_lens: dict[str, int] = {}
        if has_list and count > 0:
            # lengths of the lists in the first row; assumed fixed and verified below
            p0 = pos
            for p in props:
                if isinstance(p, plyfile.PlyListProperty):
                    len_t, val_t = (np.dtype(t) for t in p.list_dtype(bo))
                    if p0 + len_t.itemsize > len(raw):
                        return None
                    L = int(np.frombuffer(raw, len_t, 1, p0)[0])
                    if L < 0:
                        raise InvalidInputError(
                            f"{name}: PLY list length {L} of property '{p.name}' of element "
                            f"'{elt.name}' is negative."
                        )
                    list_lens[p.name] = L
                    p0 += len_t.itemsize + L * val_t.itemsize
                    if p0 > len(raw):  # the first row alone runs past the end: not fixed-size
                        return None
                else:
                    p0 += np.dtype(p.dtype(bo)).itemsize
        for p in props:
            if isinstance(p, plyfile.PlyListProperty):
                len_t, val_t = p.list_dtype(bo)
                L = list_lens.get(p.name, 0)
                fields.append((p.name + "\nlen", len_t))
                fields.append((p.name, val_t, (L,)))
            else:
                fields.append((p.name, p.dtype(bo)))
        dt = np.dtype(fields)
        need = count * dt.itemsize
        if pos + need > len(raw):
            if has_list:
                return None  # maybe variable lengths; the fallback decides
            raise InvalidInputError(
                f"{name}: truncated PLY: element '{elt.name}' needs {need} bytes at offset {pos}, "
                f"the file has {len(raw) - pos}."
            )
        arr = np.frombuffer(raw, dtype=dt, count=count, offset=pos)
        for p in props:
            if isinstance(p, plyfile.PlyListProperty) and count > 0:
                if not (arr[p.name + "\nlen"] == list_lens[p.name]).all():
                    return None
        cols = {}
        for p in props:
            col = arr[p.name]
            cols[p.name] = col.astype(col.dtype.newbyteorder("="), copy=True)
        if elt.name in _WANTED:
            out[elt.name] = cols
        pos += need
    if complete:
        _check_trailing(len(raw) - pos, header, name)
    return out


def _check_face_lists(header, name: str) -> None:
    """The vertex indices of ``face`` / ``tristrips`` must be a list property."""
    plyfile = _plyfile()
    for elt in header.elements:
        if elt.name not in ("face", "tristrips"):
            continue
        for p in elt.properties:
            if p.name not in _FACE_INDEX_NAMES:
                continue
            if not isinstance(p, plyfile.PlyListProperty):
                raise InvalidInputError(
                    f"{name}: PLY '{elt.name}' property '{p.name}' must be a list "
                    f"('property list uchar int {p.name}'); got a scalar {p.val_dtype}."
                )


def _pick(cols: dict, candidates: tuple[tuple[str, ...], ...], width: int) -> tuple | None:
    for names in candidates:
        if all(n in cols for n in names[:width]):
            return names
    return None


def read_ply(raw: bytes, name: str) -> RawGeometry:
    """Parse PLY bytes into a :class:`RawGeometry` (see module docstring for the mapping)."""
    header, offset = _parse_header(raw, name)
    _check_counts(raw, header, offset, name)
    _check_face_lists(header, name)
    if header.text:
        elements = _ascii_elements(raw, header, offset, name)
    else:
        elements = _binary_elements(raw, header, offset, name)
    if elements is None:
        elements = _read_full_plyfile(raw, name, header)
    if "vertex" not in elements:
        raise InvalidInputError(f"{name}: PLY file has no 'vertex' element.")
    vcols = dict(elements["vertex"])
    for c in ("x", "y", "z"):
        if c not in vcols:
            raise InvalidInputError(
                f"{name}: PLY 'vertex' element lacks property '{c}' (has {', '.join(vcols)})."
            )
    V = np.stack([vcols.pop("x"), vcols.pop("y"), vcols.pop("z")], axis=1).astype(np.float64)
    normals = None
    nn = _pick(vcols, _NORMAL_NAMES, 3)
    if nn is not None:
        normals = np.stack([vcols.pop(k) for k in nn], axis=1).astype(np.float64)
    colors = None
    cn = _pick(vcols, _COLOR_NAMES, 3)
    if cn is not None:
        keys = list(cn[:4]) if cn[3] in vcols else list(cn[:3])
        cols = [vcols.pop(k) for k in keys]
        dt = np.result_type(*cols)
        colors = np.stack(cols, axis=1).astype(dt)
    vattrs = {k: v for k, v in vcols.items() if v.dtype != object}
    faces = None
    fattrs: dict[str, np.ndarray] = {}
    if "face" in elements:
        fcols = dict(elements["face"])
        key = next((k for k in _FACE_INDEX_NAMES if k in fcols), None)
        if key is None:
            raise InvalidInputError(
                f"{name}: PLY 'face' element has no 'vertex_indices' list (has {', '.join(fcols)})."
            )
        polys = fcols.pop(key)
        if polys.dtype != object and polys.ndim == 2 and polys.shape[0] == 0:
            faces = np.zeros((0, 3), dtype=np.int64)
            source = None
        else:
            faces, source = fan_triangulate(polys, name)
        tex = fcols.pop("texcoord", None)
        if tex is not None:
            tc = _fan_texcoords(polys, tex, name)
            if tc is not None:
                fattrs["texcoord"] = tc
        for k, v in fcols.items():
            if v.dtype == object:
                continue
            fattrs[k] = v if source is None else v[source]
    if "tristrips" in elements:
        scols = elements["tristrips"]
        key = next((k for k in _FACE_INDEX_NAMES if k in scols), None)
        if key is None:
            raise InvalidInputError(
                f"{name}: PLY 'tristrips' element has no 'vertex_indices' list "
                f"(has {', '.join(scols)})."
            )
        strips = strips_to_triangles(scols[key], name)
        if faces is None or len(faces) == 0:
            faces = strips
        else:
            faces = np.concatenate([faces, strips])
            fattrs = {}  # per-face properties of the 'face' element do not cover the strips
    return RawGeometry(V, faces, normals, colors, vattrs, fattrs)


def strips_to_triangles(strips: Any, name: str) -> np.ndarray:
    """Triangles (t, 3) int64 of PLY triangle strips (rules in the module docstring): ``strips`` one
    int sequence per ``tristrips`` row, ``name`` the file name for messages.
    """
    if isinstance(strips, np.ndarray) and strips.dtype != object:
        rows = [np.asarray(r) for r in strips.reshape(strips.shape[0], -1)]
    else:
        rows = [np.asarray(r) for r in strips]
    for r in rows:
        if r.size and r.dtype.kind not in "iu":
            raise InvalidInputError(f"{name}: PLY 'tristrips' indices must be integers.")
    if not rows:
        return np.zeros((0, 3), dtype=np.int64)
    # one flat sequence, each row closed by a restart marker
    sep = np.array([-1], dtype=np.int64)
    s = np.concatenate([np.concatenate([r.astype(np.int64).ravel(), sep]) for r in rows])
    if s.size < 3:
        return np.zeros((0, 3), dtype=np.int64)
    pos = np.arange(s.size, dtype=np.int64)
    start = np.maximum.accumulate(np.where(s < 0, pos + 1, 0))  # first index of the current strip
    a, b, c = s[:-2], s[1:-1], s[2:]
    odd = ((pos[:-2] - start[:-2]) % 2).astype(bool)
    ok = (a >= 0) & (b >= 0) & (c >= 0) & (a != b) & (b != c) & (a != c)
    tris = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    return tris[ok]


def _fan_texcoords(polys: np.ndarray, tex: np.ndarray, name: str) -> np.ndarray | None:
    """MeshLab's per-corner ``texcoord`` list (2 values per corner) following the polygon fans.

    Returns (t, 6) float64 aligned with the triangles of :func:`fan_triangulate`, or None when the
    list lengths do not match the polygons' corner counts (then the property is not kept).
    """
    if polys.dtype != object and tex.dtype != object and polys.ndim == 2 and tex.ndim == 2:
        m, k = polys.shape
        if tex.shape != (m, 2 * k):
            return None
        corner_ids = np.arange(m * k, dtype=np.int64).reshape(m, k)
        flat_uv = tex.reshape(m * k, 2)
    else:
        plist = list(polys)
        tlist = list(tex) if tex.dtype == object else list(tex.reshape(len(tex), -1))
        lens = np.fromiter((len(p) for p in plist), dtype=np.int64, count=len(plist))
        tlens = np.fromiter((len(t) for t in tlist), dtype=np.int64, count=len(tlist))
        if lens.shape != tlens.shape or (tlens != 2 * lens).any():
            return None
        ends = np.cumsum(lens)
        corner_ids = [np.arange(e - n, e, dtype=np.int64) for e, n in zip(ends, lens)]
        flat_uv = (
            np.concatenate([np.asarray(t, dtype=np.float64) for t in tlist]).reshape(-1, 2)
            if tlist
            else np.zeros((0, 2))
        )
    tri_corners, _ = fan_triangulate(corner_ids, name)
    if tri_corners.size == 0:
        return np.zeros((0, 6), dtype=np.float64)
    return flat_uv.astype(np.float64)[tri_corners].reshape(-1, 6)


# --------------------------------------------------------------------------------------- writing
def _ply_dtype(a: np.ndarray, what: str) -> np.dtype:
    dt = a.dtype
    if dt == np.bool_:
        return np.dtype("u1")
    if dt.kind == "f":
        return np.dtype("f4") if dt.itemsize <= 4 else np.dtype("f8")
    if dt.kind in "iu":
        key = f"{dt.kind}{dt.itemsize}"
        if key in _PLY_SCALAR:
            return np.dtype(key)
        # 64-bit integers: PLY has none; use 32 bits when the values fit, else double
        t = np.dtype("i4") if dt.kind == "i" else np.dtype("u4")
        info = np.iinfo(t)
        if a.size == 0 or (a.min() >= info.min and a.max() <= info.max):
            return t
        return np.dtype("f8")
    raise InvalidInputError(f"{what} has dtype {dt}, which PLY cannot store (numbers only).")


def _element_table(
    columns: list[tuple[str, np.ndarray]], n: int, list_cols: dict[str, np.ndarray]
) -> np.ndarray:
    """Structured array with scalar fields and fixed-length list fields (subarrays)."""
    fields = []
    for key, col in columns:
        if col.ndim == 1:
            fields.append((key, _ply_dtype(col, f"property '{key}'")))
        else:
            fields.append((key, _ply_dtype(col, f"property '{key}'"), (col.shape[1],)))
    arr = np.empty(n, dtype=fields)
    for key, col in columns:
        arr[key] = col
    return arr


def _check_name(key: str, used: set[str], where: str) -> None:
    if not key or any(ch.isspace() for ch in key) or not key.isascii():
        raise InvalidInputError(
            f"{where} name {key!r} cannot be a PLY property name (ascii, no spaces)."
        )
    if key in used:
        raise InvalidInputError(f"{where} name {key!r} clashes with another PLY property.")
    used.add(key)


def _vertex_columns(V, normals, colors, attrs, dtype) -> list[tuple[str, np.ndarray]]:
    cols: list[tuple[str, np.ndarray]] = []
    used: set[str] = set()
    for i, k in enumerate("xyz"):
        cols.append((k, V[:, i].astype(dtype)))
        used.add(k)
    if normals is not None:
        for i, k in enumerate(("nx", "ny", "nz")):
            cols.append((k, np.asarray(normals)[:, i].astype(dtype)))
            used.add(k)
    if colors is not None:
        c = np.asarray(colors)
        for i, k in enumerate(("red", "green", "blue", "alpha")[: c.shape[1]]):
            cols.append((k, c[:, i]))
            used.add(k)
    for k, a in attrs.items():
        _check_name(k, used, "attribute")
        a = np.asarray(a)
        if a.ndim > 2:
            raise InvalidInputError(
                f"attribute `{k}` has shape {a.shape}; PLY stores (n,) or (n, k) attributes."
            )
        cols.append((k, a))
    return cols


def write_ply(
    obj_vertices: np.ndarray,
    faces: np.ndarray | None,
    *,
    normals=None,
    colors=None,
    vertex_attributes=None,
    face_attributes=None,
    binary: bool = True,
    dtype: Any = np.float64,
) -> bytes:
    """Serialise to PLY bytes (binary little endian or ascii)."""
    plyfile = _plyfile()
    dtype = np.dtype(dtype)
    n = obj_vertices.shape[0]
    vcols = _vertex_columns(obj_vertices, normals, colors, vertex_attributes or {}, dtype)
    varr = _element_table(vcols, n, {})
    elements = [plyfile.PlyElement.describe(varr, "vertex")]
    farr = None
    if faces is not None:
        F = np.asarray(faces)
        fcols: list[tuple[str, np.ndarray]] = [("vertex_indices", F.astype(np.int32))]
        used = {"vertex_indices"}
        for k, a in (face_attributes or {}).items():
            _check_name(k, used, "face attribute")
            a = np.asarray(a)
            if a.ndim > 2:
                raise InvalidInputError(
                    f"face attribute `{k}` has shape {a.shape}; PLY stores (m,) or (m, k)."
                )
            if k == "texcoord" and a.ndim == 2 and a.shape[1] == 6 and a.dtype.kind == "f":
                a = a.astype(np.float32)  # MeshLab's `property list uchar float texcoord`
            fcols.append((k, a))
        farr = _element_table(fcols, F.shape[0], {})
        elements.append(plyfile.PlyElement.describe(farr, "face"))
    data = plyfile.PlyData(elements, text=not binary, byte_order="<", comments=["spectrageo"])
    buf = io.BytesIO()
    buf.write(data.header.encode("ascii") + b"\n")
    if binary:
        for arr in (varr, farr):
            if arr is not None:
                buf.write(_binary_body(arr))
        return buf.getvalue()
    for arr in (varr, farr):
        if arr is None or arr.size == 0:
            continue
        table, fmts = _ascii_table(arr)
        np.savetxt(buf, table, fmt=fmts, delimiter=" ")
    return buf.getvalue()


def _binary_body(arr: np.ndarray) -> bytes:
    """Little-endian PLY rows of ``arr``; fixed-length list fields get their uchar length prefix.

    Same bytes as plyfile's writer (which handles list properties row by row in Python).
    """
    fields, fill = [], []
    for key in arr.dtype.names:
        sub = arr.dtype.fields[key][0]
        base = sub.base.newbyteorder("<")
        if sub.shape:
            fields.append((key + "\nlen", "u1"))
            fields.append((key, base, sub.shape))
            fill.append((key + "\nlen", sub.shape[0]))
        else:
            fields.append((key, base))
    out = np.empty(arr.size, dtype=fields)
    for key in arr.dtype.names:
        out[key] = arr[key]
    for key, k in fill:
        out[key] = k
    return out.tobytes()


def _ascii_table(arr: np.ndarray) -> tuple[np.ndarray, list[str]]:
    parts = []
    fmts: list[str] = []
    for key in arr.dtype.names:
        sub = arr.dtype.fields[key][0]
        base = sub.base
        fmt = "%.9g" if base == np.float32 else "%.17g" if base.kind == "f" else "%d"
        col = arr[key]
        if sub.shape:  # list property: length then values
            k = sub.shape[0]
            parts.append(np.full((arr.size, 1), k, dtype=np.float64))
            fmts.append("%d")
            parts.append(col.reshape(arr.size, k).astype(np.float64))
            fmts.extend([fmt] * k)
        else:
            parts.append(col.astype(np.float64).reshape(-1, 1))
            fmts.append(fmt)
    return np.hstack(parts), fmts
