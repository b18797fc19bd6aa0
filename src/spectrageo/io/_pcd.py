"""Point Cloud Data (PCD v0.5-0.7): ``DATA ascii``, ``binary`` and ``binary_compressed``.

The header is parsed here and the body decoded with numpy: ``ascii`` by :func:`numpy.loadtxt`,
``binary`` by one structured :func:`numpy.frombuffer`, ``binary_compressed`` (compressed and
uncompressed sizes, then an LZF block holding the fields one after another) by python-lzf and
one ``frombuffer`` per field.

Fields (names case-insensitive): ``x y z`` -> points; ``normal_x normal_y normal_z`` -> normals;
``rgb`` (0x00RRGGBB) -> uint8 colours (n, 3); ``rgba`` -> (n, 4), or (n, 3) when every alpha is
0; padding ``_`` dropped; others -> attributes. ``VIEWPOINT`` is not applied to the points. NaN
points of organized clouds are dropped by default (``nan_points``), their indices kept in
``source_index``; :func:`read_pcd_header` gives the grid (``WIDTH``, ``HEIGHT``) and the
``VIEWPOINT`` without decoding the body.

Header and body must agree: POINTS = WIDTH*HEIGHT; exactly POINTS rows (ascii) or records
(binary, less than one record of trailing bytes tolerated); ``binary_compressed`` must declare
the implied uncompressed size, a compressed size present in the file and an expansion LZF can
produce (at most 88x). Declared sizes are checked against the memory cap.
"""

from __future__ import annotations

import gzip
import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ._common import check_alloc, exc_text
from ._raw import RawGeometry

_TYPES = {
    ("I", 1): np.int8,
    ("I", 2): np.int16,
    ("I", 4): np.int32,
    ("I", 8): np.int64,
    ("U", 1): np.uint8,
    ("U", 2): np.uint16,
    ("U", 4): np.uint32,
    ("U", 8): np.uint64,
    ("F", 4): np.float32,
    ("F", 8): np.float64,
}
_DATA = ("ascii", "binary", "binary_compressed")
_MAX_HEADER_LINES = 64
_MAX_COUNT = 1 << 20  # values per field (COUNT); PCL's largest descriptors have a few hundred
_LZF_MAX_RATIO = 88  # LZF's longest back-reference: 3 bytes for 264


def _parse_header(raw: bytes, name: str) -> tuple[dict[str, Any], int]:
    hdr: dict[str, Any] = {}
    pos = 0
    for _ in range(_MAX_HEADER_LINES):
        end = raw.find(b"\n", pos)
        if end < 0:
            raise InvalidInputError(f"{name}: truncated PCD header (no DATA line).")
        try:
            line = raw[pos:end].decode("ascii").strip()
        except UnicodeDecodeError as exc:
            raise InvalidInputError(f"{name}: not a PCD file (binary data in the header).") from exc
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, _, rest = line.partition(" ")
        key = key.upper()
        vals = rest.split()
        hdr[key] = vals
        if key == "DATA":
            return hdr, pos
        if key not in {
            "VERSION",
            "FIELDS",
            "COLUMNS",
            "SIZE",
            "TYPE",
            "COUNT",
            "WIDTH",
            "HEIGHT",
            "VIEWPOINT",
            "POINTS",
        }:
            raise InvalidInputError(
                f"{name}: not a PCD file (unexpected header line {line[:40]!r})."
            )
    raise InvalidInputError(f"{name}: not a PCD file (no DATA line in the header).")


def _layout(hdr: dict[str, Any], name: str):
    fields = hdr.get("FIELDS") or hdr.get("COLUMNS")
    for key in ("SIZE", "TYPE", "WIDTH", "HEIGHT"):
        if key not in hdr:
            raise InvalidInputError(f"{name}: PCD header lacks {key}.")
    if not fields:
        raise InvalidInputError(f"{name}: PCD header lacks FIELDS.")
    sizes, types = hdr["SIZE"], hdr["TYPE"]
    counts = hdr.get("COUNT", ["1"] * len(fields))
    if not (len(sizes) == len(types) == len(counts) == len(fields)):
        raise InvalidInputError(
            f"{name}: PCD header FIELDS/SIZE/TYPE/COUNT have different lengths "
            f"({len(fields)}, {len(sizes)}, {len(types)}, {len(counts)})."
        )
    try:
        sizes = [int(s) for s in sizes]
        counts = [int(c) for c in counts]
        width, height = int(hdr["WIDTH"][0]), int(hdr["HEIGHT"][0])
        n = int(hdr["POINTS"][0]) if "POINTS" in hdr else width * height
    except (ValueError, IndexError) as exc:
        raise InvalidInputError(f"{name}: malformed numbers in the PCD header.") from exc
    for key, v in (("WIDTH", width), ("HEIGHT", height), ("POINTS", n)):
        if v < 0:
            raise InvalidInputError(f"{name}: PCD header {key} must be >= 0; got {v}.")
    if n != width * height:
        raise InvalidInputError(
            f"{name}: PCD header POINTS={n} differs from WIDTH*HEIGHT={width * height}."
        )
    for f, c in zip(fields, counts):
        if not 1 <= c <= _MAX_COUNT:
            raise InvalidInputError(
                f"{name}: PCD header COUNT of field '{f}' must be in 1..{_MAX_COUNT}; got {c}."
            )
    dts = []
    for f, s, t, c in zip(fields, sizes, types, counts):
        key = (t.upper(), s)
        if key not in _TYPES:
            raise UnsupportedFormatError(
                f"{name}: PCD field '{f}' has unsupported TYPE {t} with SIZE {s} "
                "(supported: I/U with 1, 2, 4, 8 bytes; F with 4, 8)."
            )
        dts.append((f, np.dtype(_TYPES[key]).newbyteorder("<"), c))
    data = hdr["DATA"][0].lower() if hdr["DATA"] else ""
    if data not in _DATA:
        raise UnsupportedFormatError(
            f"{name}: PCD DATA {data!r} is not supported (ascii, binary, binary_compressed)."
        )
    names = [f for f, _, _ in dts if f != "_"]
    if len(set(names)) != len(names):
        raise InvalidInputError(f"{name}: PCD header repeats a field name.")
    return dts, n, height, data


def _unique_names(dts):
    """Structured-dtype field names (padding fields '_' renamed to be unique)."""
    out = []
    for i, (f, dt, c) in enumerate(dts):
        key = f if f != "_" else f"_pad{i}"
        out.append((key, dt, c))
    return out


def _decode(raw: bytes, pos: int, dts, n: int, data: str, name: str) -> dict[str, np.ndarray]:
    dts = _unique_names(dts)
    cols: dict[str, np.ndarray] = {}
    if n == 0:
        return {f: np.zeros((0, c) if c > 1 else 0, dtype=dt) for f, dt, c in dts}
    if data == "ascii":
        if not raw[pos:].strip():
            raise InvalidInputError(f"{name}: truncated PCD: {n} points declared, no data rows.")
        # at least 2 bytes ("0\n") per declared row, and the table's float64 copy within the cap
        rows_max = (len(raw) - pos + 1) // 2
        if n > rows_max:
            raise InvalidInputError(
                f"{name}: truncated PCD: {n} points declared, the {len(raw) - pos} bytes of ascii "
                f"data hold at most {rows_max} rows."
            )
        check_alloc(8 * n * sum(c for _, _, c in dts), name, f"{n} PCD points")
        try:
            table = np.loadtxt(io.BytesIO(raw[pos:]), dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise InvalidInputError(f"{name}: malformed PCD ascii data ({exc_text(exc)}).") from exc
        width = sum(c for _, _, c in dts)
        if table.shape[0] < n:
            raise InvalidInputError(
                f"{name}: truncated PCD: {n} points declared, {table.shape[0]} rows found."
            )
        if table.shape[0] > n:
            raise InvalidInputError(
                f"{name}: PCD header declares POINTS {n}, the file holds {table.shape[0]} data rows."
            )
        if table.shape[1] != width:
            raise InvalidInputError(
                f"{name}: PCD ascii rows have {table.shape[1]} values; the header declares {width}."
            )
        table = table[:n]
        k = 0
        for f, dt, c in dts:
            block = table[:, k : k + c]
            k += c
            if f in ("rgb", "rgba"):
                vals = _ascii_packed_color(block[:, 0])
            else:
                if dt.kind in "iu" and (
                    not np.isfinite(block).all() or (block != np.round(block)).any()
                ):
                    raise InvalidInputError(
                        f"{name}: PCD integer field '{f}' holds non-integer values."
                    )
                info = np.iinfo(dt) if dt.kind in "iu" else None
                if info is not None and (block.min() < info.min or block.max() > info.max):
                    bad = block.min() if block.min() < info.min else block.max()
                    raise InvalidInputError(
                        f"{name}: PCD field '{f}' value {bad:.17g} is out of range for its TYPE "
                        f"{dt.kind.upper()} SIZE {dt.itemsize}."
                    )
                vals = block.astype(dt.newbyteorder("="))
                vals = vals[:, 0] if c == 1 else vals
            cols[f] = vals
        return cols
    rec_size = sum(dt.itemsize * c for _, dt, c in dts)
    if data == "binary":
        need = n * rec_size
        if len(raw) - pos < need:
            raise InvalidInputError(
                f"{name}: truncated PCD: binary data needs {need} bytes (POINTS {n} of "
                f"{rec_size} bytes), the file has {len(raw) - pos}."
            )
        extra = (len(raw) - pos - need) // rec_size
        if extra:
            raise InvalidInputError(
                f"{name}: PCD header declares POINTS {n}, the binary data hold {n + extra} records "
                f"of {rec_size} bytes."
            )
        check_alloc(2 * need, name, f"{n} PCD points")
        rec = np.dtype([(f, dt, (c,)) if c > 1 else (f, dt) for f, dt, c in dts])
        arr = np.frombuffer(raw, dtype=rec, count=n, offset=pos)
        for f, dt, _c in dts:
            cols[f] = arr[f].astype(dt.newbyteorder("="))
        return cols
    # binary_compressed
    import lzf

    if len(raw) - pos < 8:
        raise InvalidInputError(f"{name}: truncated PCD: missing the compressed block sizes.")
    csize, usize = struct.unpack("<II", raw[pos : pos + 8])
    payload = raw[pos + 8 : pos + 8 + csize]
    if len(payload) < csize:
        raise InvalidInputError(
            f"{name}: truncated PCD: compressed block of {csize} bytes, {len(payload)} present."
        )
    expected = n * rec_size
    if usize != expected:
        raise InvalidInputError(
            f"{name}: corrupt PCD: uncompressed size {usize} differs from the {expected} bytes "
            f"the header implies (POINTS {n} of {rec_size} bytes)."
        )
    if usize > _LZF_MAX_RATIO * csize + 64:
        raise InvalidInputError(
            f"{name}: corrupt PCD: a compressed block of {csize} bytes cannot expand to the "
            f"{usize} bytes that POINTS {n} needs (LZF expands at most {_LZF_MAX_RATIO}x)."
        )
    check_alloc(2 * usize, name, f"{n} PCD points")
    try:
        buf = lzf.decompress(payload, usize) if usize else b""
    except ValueError as exc:
        raise InvalidInputError(f"{name}: corrupt PCD LZF block ({exc_text(exc)}).") from exc
    if buf is None or len(buf) != usize:
        raise InvalidInputError(f"{name}: corrupt PCD LZF block (wrong decompressed size).")
    off = 0
    for f, dt, c in dts:
        v = np.frombuffer(buf, dtype=dt, count=n * c, offset=off).astype(dt.newbyteorder("="))
        off += n * c * dt.itemsize
        cols[f] = v if c == 1 else v.reshape(n, c)
    return cols


def _ascii_packed_color(v: np.ndarray) -> np.ndarray:
    """Packed colours written in ascii: PCL >= 1.7 writes the uint32 bit pattern as an integer, older
    writers the float32 value; integers in [0, 2**32) are taken as bit patterns, the rest as floats."""
    as_int = np.isfinite(v) & (v == np.round(v)) & (v >= 0) & (v < 2.0**32)
    out = np.where(as_int, 0, v).astype(np.float32).view(np.uint32)
    out[as_int] = v[as_int].astype(np.uint32)
    return out


def _unpack_colors(col: np.ndarray, with_alpha: bool) -> np.ndarray:
    if col.dtype.kind == "f":
        u = np.ascontiguousarray(col, dtype=np.float32).view(np.uint32)
    else:
        u = col.astype(np.uint32)
    r = ((u >> 16) & 0xFF).astype(np.uint8)
    g = ((u >> 8) & 0xFF).astype(np.uint8)
    b = (u & 0xFF).astype(np.uint8)
    if with_alpha:
        a = ((u >> 24) & 0xFF).astype(np.uint8)
        if a.any():
            return np.stack([r, g, b, a], axis=1)
    return np.stack([r, g, b], axis=1)


_KNOWN_FIELDS = ("x", "y", "z", "normal_x", "normal_y", "normal_z", "rgb", "rgba")


def _canonical_names(dts):
    """Rename the known fields (``x y z``, ``normal_*``, ``rgb``, ``rgba``) written in another case
    (``X Y Z`` as PDAL writes them) to their lower-case names; a field already spelled in lower case
    keeps the role and the other spelling stays an attribute."""
    present = {f for f, _, _ in dts}
    out = []
    for f, dt, c in dts:
        low = f.lower()
        if low in _KNOWN_FIELDS and f != low and low not in present:
            present.add(low)
            f = low
        out.append((f, dt, c))
    return out


def read_pcd(raw: bytes, name: str) -> RawGeometry:
    hdr, pos = _parse_header(raw, name)
    dts, n, _height, data = _layout(hdr, name)
    dts = _canonical_names(dts)
    fields = [f for f, _, _ in dts]
    for c in ("x", "y", "z"):
        if c not in fields:
            raise InvalidInputError(
                f"{name}: PCD file lacks field '{c}' (fields: {' '.join(fields)})."
            )
    for f, _dt, c in dts:
        if f in ("x", "y", "z", "normal_x", "normal_y", "normal_z", "rgb", "rgba") and c != 1:
            raise InvalidInputError(f"{name}: PCD field '{f}' must have COUNT 1; got {c}.")
    cols = _decode(raw, pos, dts, n, data, name)
    cols = {k: v for k, v in cols.items() if not k.startswith("_pad")}
    V = np.stack([cols.pop("x"), cols.pop("y"), cols.pop("z")], axis=1).astype(np.float64)
    normals = None
    if all(k in cols for k in ("normal_x", "normal_y", "normal_z")):
        normals = np.stack(
            [cols.pop("normal_x"), cols.pop("normal_y"), cols.pop("normal_z")], axis=1
        ).astype(np.float64)
    colors = None
    if "rgba" in cols:
        colors = _unpack_colors(cols.pop("rgba"), with_alpha=True)
    elif "rgb" in cols:
        colors = _unpack_colors(cols.pop("rgb"), with_alpha=False)
    raw_geom = RawGeometry(V, None, normals, colors, cols, {})
    raw_geom.nan_policy_default = "drop"
    return raw_geom


#: ``VIEWPOINT`` of a PCD header without one (PCL's default: origin, identity rotation)
DEFAULT_VIEWPOINT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
_HEADER_BYTES = 1 << 16


@dataclass(frozen=True)
class PCDHeader:
    """Grid and sensor pose of a PCD file (:func:`read_pcd_header`).

    Attributes
    ----------
    width, height : int
        ``WIDTH`` and ``HEIGHT``; ``height > 1`` is an organized (image) cloud of ``height`` rows.
    viewpoint : (7,) tuple of float
        ``VIEWPOINT``: sensor origin ``tx ty tz`` and orientation quaternion ``qw qx qy qz``.
    """

    width: int
    height: int
    viewpoint: tuple[float, ...] = DEFAULT_VIEWPOINT

    @property
    def organized(self) -> bool:
        """Whether the points are an image of ``height > 1`` rows of ``width`` pixels."""
        return self.height > 1 and self.width > 1

    @property
    def origin(self) -> tuple[float, float, float]:
        """The sensor origin ``(tx, ty, tz)``."""
        return (self.viewpoint[0], self.viewpoint[1], self.viewpoint[2])

    @property
    def default_viewpoint(self) -> bool:
        """Whether ``VIEWPOINT`` is absent or PCL's default ``0 0 0 1 0 0 0``."""
        return self.viewpoint == DEFAULT_VIEWPOINT


def read_pcd_header(path: Any) -> PCDHeader:
    """The header of a ``.pcd`` (or ``.pcd.gz``) file, without decoding its body.

    Raises
    ------
    InvalidInputError
        Missing file, or a header that is not PCD or has malformed ``WIDTH``, ``HEIGHT`` or
        ``VIEWPOINT`` values.
    """
    p = Path(path)
    try:
        opener = gzip.open if p.name.lower().endswith(".gz") else open
        with opener(p, "rb") as fh:
            raw = fh.read(_HEADER_BYTES)
    except FileNotFoundError as exc:
        raise InvalidInputError(f"file not found: {p}") from exc
    except (OSError, EOFError) as exc:
        raise InvalidInputError(f"{p.name}: cannot read the PCD header ({exc_text(exc)}).") from exc
    hdr, _ = _parse_header(raw, p.name)
    try:
        width, height = int(hdr["WIDTH"][0]), int(hdr["HEIGHT"][0])
        vp = tuple(float(v) for v in hdr.get("VIEWPOINT", DEFAULT_VIEWPOINT))
    except (KeyError, IndexError, ValueError) as exc:
        raise InvalidInputError(
            f"{p.name}: malformed WIDTH, HEIGHT or VIEWPOINT in the PCD header."
        ) from exc
    if width < 0 or height < 0:
        raise InvalidInputError(f"{p.name}: PCD header WIDTH and HEIGHT must be >= 0.")
    if len(vp) != 7 or not np.isfinite(vp).all():
        raise InvalidInputError(
            f"{p.name}: PCD header VIEWPOINT must be 7 finite numbers; got {vp}."
        )
    return PCDHeader(width, height, vp)


# --------------------------------------------------------------------------------------- writing
def _pcd_type(dt: np.dtype) -> tuple[str, int]:
    if dt == np.bool_:
        return "U", 1
    if dt.kind == "f":
        return ("F", 4) if dt.itemsize <= 4 else ("F", 8)
    if dt.kind in "iu" and dt.itemsize in (1, 2, 4, 8):
        return ("I" if dt.kind == "i" else "U"), dt.itemsize
    raise InvalidInputError(f"PCD cannot store values of dtype {dt} (numbers only).")


def write_pcd(
    P: np.ndarray,
    *,
    normals=None,
    colors=None,
    attributes=None,
    pcd_format: str = "binary",
    dtype: Any = None,
) -> bytes:
    """Serialise a point cloud to PCD v0.7 bytes (``pcd_format`` in ascii/binary/binary_compressed).

    ``dtype`` None writes float32 coordinates when every coordinate round-trips through float32
    exactly, else float64 (UTM-sized coordinates would move by up to 0.25 m); normals then float32.
    Colours: (n, 3) or (n, 4) uint8 or floats in [0, 1]; attributes (n,) or (n, k).
    """
    P = np.asarray(P)
    if dtype is None:
        p64 = P.astype(np.float64)
        exact = np.array_equal(p64.astype(np.float32).astype(np.float64), p64)
        coord_dtype = np.dtype(np.float32 if exact else np.float64)
        normal_dtype = np.dtype(np.float32)
    else:
        coord_dtype = normal_dtype = np.dtype(dtype)
    n = P.shape[0]
    columns: list[tuple[str, np.ndarray]] = []  # (name, (n, c) array)
    for i, k in enumerate("xyz"):
        columns.append((k, P[:, i : i + 1].astype(coord_dtype)))
    if normals is not None:
        nrm = np.asarray(normals)
        for i, k in enumerate(("normal_x", "normal_y", "normal_z")):
            columns.append((k, nrm[:, i : i + 1].astype(normal_dtype)))
    if colors is not None:
        c = np.asarray(colors)
        if c.dtype.kind == "f":
            c = np.clip(np.round(c * 255.0), 0, 255)
        c = c.astype(np.uint32)
        packed = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
        if c.shape[1] == 4:
            packed = packed | (c[:, 3] << 24)
            columns.append(("rgba", packed.astype(np.uint32).reshape(-1, 1)))
        else:
            columns.append(("rgb", packed.astype(np.uint32).view(np.float32).reshape(-1, 1)))
    used = {k for k, _ in columns}
    for k, a in (attributes or {}).items():
        a = np.asarray(a)
        if not k or any(ch.isspace() for ch in k) or not k.isascii() or k in used:
            raise InvalidInputError(f"attribute name {k!r} cannot be a PCD field name.")
        used.add(k)
        if a.ndim == 1:
            a = a.reshape(-1, 1)
        elif a.ndim != 2:
            raise InvalidInputError(
                f"attribute `{k}` has shape {a.shape}; PCD stores (n,) or (n, k)."
            )
        if a.dtype == np.bool_:
            a = a.astype(np.uint8)
        columns.append((k, a))
    tys = [_pcd_type(a.dtype) for _, a in columns]
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        "FIELDS " + " ".join(k for k, _ in columns),
        "SIZE " + " ".join(str(s) for _, s in tys),
        "TYPE " + " ".join(t for t, _ in tys),
        "COUNT " + " ".join(str(a.shape[1]) for _, a in columns),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        f"DATA {pcd_format}",
    ]
    out = io.BytesIO()
    out.write(("\n".join(header) + "\n").encode("ascii"))
    le = [(k, np.dtype(f"<{t.lower()}{s}"), a) for (k, a), (t, s) in zip(columns, tys)]
    if pcd_format == "ascii":
        flat, fmts = [], []
        for i, (k, dt, a) in enumerate(le):
            if k == "rgb":  # written as the uint32 bit pattern, as PCL does
                a = a.view(np.uint32)
                dt = np.dtype("<u4")
            for j in range(a.shape[1]):
                flat.append((f"f{i}_{j}", dt.newbyteorder("="), a[:, j]))
                fmts.append("%d" if dt.kind in "iu" else "%.9g" if dt.itemsize == 4 else "%.17g")
        rec = np.empty(n, dtype=[(key, dt) for key, dt, _ in flat])
        for key, _dt, col in flat:
            rec[key] = col
        np.savetxt(out, rec, fmt=fmts, delimiter=" ")
    elif pcd_format == "binary":
        rec = np.dtype([(f"f{i}", dt, (a.shape[1],)) for i, (_, dt, a) in enumerate(le)])
        arr = np.empty(n, dtype=rec)
        for i, (_, dt, a) in enumerate(le):
            arr[f"f{i}"] = a.astype(dt)
        out.write(arr.tobytes())
    else:
        import lzf

        soa = b"".join(np.ascontiguousarray(a.astype(dt)).tobytes() for _, dt, a in le)
        if len(soa):
            comp = lzf.compress(soa)
            if comp is None:  # incompressible data: give LZF an output bound above the input size
                comp = lzf.compress(soa, len(soa) + len(soa) // 16 + 64)
        else:
            comp = b""
        out.write(struct.pack("<II", len(comp), len(soa)))
        out.write(comp)
    return out.getvalue()
