"""Small formats: XYZ and PTS text, ``.npy`` point arrays and STL (through trimesh)."""

from __future__ import annotations

import io
import re
import tokenize
import warnings

import numpy as np

from .._errors import InvalidInputError
from ._common import check_alloc, exc_text, quiet_trimesh, text_colors
from ._raw import RawGeometry

# ------------------------------------------------------------------------------------------ XYZ
_COMMENTS = ("#", "//")
_NORMAL_KEYS = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"), ("n_x", "n_y", "n_z"))
_COLOR_KEYS = (("r", "g", "b", "a"), ("red", "green", "blue", "alpha"))


def _is_comment(line: str) -> bool:
    return line.startswith(_COMMENTS)


def _split(line: str, sep: str | None) -> list[str]:
    return [t.strip() for t in line.split(sep)] if sep else line.split()


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _xyz_names(tokens: list[str]) -> list[str]:
    """Header column names, lower case, spaces replaced by ``_``, leading ``//`` or ``#`` dropped."""
    out = []
    for t in tokens:
        t = t.strip().lstrip("/#").strip()
        out.append("_".join(t.split()))
    return out


def _find_group(names: list[str], groups, width: int) -> list[int] | None:
    low = [n.lower() for n in names]
    for g in groups:
        if all(k in low for k in g[:width]):
            return [low.index(k) for k in g[:width]]
    return None


def read_xyz(raw: bytes, name: str) -> RawGeometry:
    """Delimited text of points, one per line: ``x y z`` and optional normals, colours, scalars.

    An optional first line with one integer is a point count and must equal the data rows.
    Separators: spaces/tabs, ``,`` or ``;`` (from the first data line; ``;`` allows a decimal
    comma); ``#`` and ``//`` lines are comments. A header of column names (a first line such as
    ``X Y Z R G B``, or CloudCompare's ``//X,Y,Z,R,G,B,A`` comment) decides the layout: ``nx ny nz``
    (``normal_x``...) normals, ``r g b [a]`` (``red``...) colours, other columns float64
    attributes. Without one, the columns after ``x y z`` are guessed left to right: 3 columns of
    unit-norm rows are normals, 3 columns of integers 0..255 colours (uint8) with an optional 4th
    as alpha (repeated once for ``x y z r g b nx ny nz``), the rest ``scalar_0``, ``scalar_1``...
    A header settles the guess's ambiguities (an 8-bit intensity after ``r g b`` reads as alpha;
    integer labels in 0..255 as colours; non-unit normals as scalars).

    Raises
    ------
    InvalidInputError
        Rows with a different number of values or non-numeric values (naming the line), fewer than
        3 columns, no data rows, a count line that disagrees with the rows.
    """
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    lines = text.splitlines()
    # first data line; the comment line right before it may name the columns
    first, last_comment = None, None
    for i, ln in enumerate(lines):
        s = ln.strip()
        if not s:
            continue
        if _is_comment(s):
            last_comment = s
            continue
        first = i
        break
    if first is None:
        raise InvalidInputError(f"{name}: XYZ file holds no points.")
    declared, first = _count_line(lines, first, name)
    if first is None:
        raise InvalidInputError(f"{name}: XYZ file holds no points (only a count line).")
    head = lines[first].strip()
    sep = ";" if ";" in head else "," if "," in head else None
    names: list[str] | None = None
    tokens = _split(head, sep)
    body_start = first
    if not all(_is_number(t.replace(",", ".") if sep == ";" else t) for t in tokens):
        # a line of column names
        names = _xyz_names(tokens)
        body_start = first + 1
        nxt = next((ln.strip() for ln in lines[body_start:] if ln.strip()), "")
        nxt = "" if _is_comment(nxt) else nxt
        if nxt:
            sep = ";" if ";" in nxt else "," if "," in nxt else None
    body = "\n".join(lines[body_start:])
    decimal_comma = sep == ";" and "," in body  # European CSV: "1,5;2,25;3"
    if decimal_comma:
        body = body.replace(",", ".")
    table = _load_table(body, lines, body_start, sep, decimal_comma, name, "XYZ", _COMMENTS)
    _check_count(declared, table.shape[0], name, "XYZ")
    k = table.shape[1]
    if k < 3:
        raise InvalidInputError(
            f"{name}: XYZ rows must have at least 3 values (x y z); got {k} (line {first + 1})."
        )
    if names is None and last_comment is not None:
        cand = _xyz_names(_split(last_comment.lstrip("/#").strip(), sep))
        if len(cand) == k and [c.lower() for c in cand[:3]] == ["x", "y", "z"]:
            names = cand
    if names is not None and len(names) != k:
        raise InvalidInputError(
            f"{name}: the XYZ header names {len(names)} columns ({' '.join(names)}), the data rows "
            f"have {k} values."
        )
    if names is not None:
        return _xyz_by_names(table, names, name)
    return _xyz_guess(table)


def _next_data_line(lines: list[str], start: int) -> int | None:
    for i in range(start, len(lines)):
        s = lines[i].strip()
        if s and not _is_comment(s):
            return i
    return None


def _count_line(lines: list[str], first: int, name: str) -> tuple[int | None, int | None]:
    """``(declared_count, first_data_line)``: a first line with a single value followed by a line of
    3 or more values is a count line (an error unless it is a non-negative integer)."""
    toks = lines[first].split()
    if len(toks) != 1 or "," in toks[0] or ";" in toks[0]:
        return None, first
    nxt = _next_data_line(lines, first + 1)
    if nxt is None:
        return None, first
    ntoks = lines[nxt].strip()
    sep = ";" if ";" in ntoks else "," if "," in ntoks else None
    if len(_split(ntoks, sep)) < 3:
        return None, first
    if re.fullmatch(r"[+-]?[0-9]+", toks[0]) is None:
        raise InvalidInputError(
            f"{name}: line {first + 1} holds the single value {toks[0][:30]!r} above rows of "
            f"{len(_split(ntoks, sep))} values; expected a point count (a non-negative integer)."
        )
    count = int(toks[0])
    if count < 0:
        raise InvalidInputError(
            f"{name}: the point count on line {first + 1} is negative ({count})."
        )
    return count, nxt


def _check_count(declared: int | None, n_rows: int, name: str, fmt: str) -> None:
    if declared is not None and declared != n_rows:
        raise InvalidInputError(
            f"{name}: the {fmt} count line declares {declared} points, the file holds {n_rows} "
            "data rows."
        )


def _bad_line(lines: list[str], start: int, sep, decimal_comma: bool, exc: Exception) -> str:
    """Describe the first malformed data line (1-based line number) for the error message."""
    width = None
    for i in range(start, len(lines)):
        s = lines[i].strip()
        for c in _COMMENTS:
            s = s.split(c, 1)[0].strip() if c in s else s
        if not s:
            continue
        if decimal_comma:
            s = s.replace(",", ".")
        toks = _split(s, sep)
        bad = next((t for t in toks if not _is_number(t)), None)
        if bad is not None:
            return f"line {i + 1} has a non-numeric value {bad!r}"
        if width is None:
            width, first = len(toks), i
        elif len(toks) != width:
            return f"line {i + 1} has {len(toks)} values, line {first + 1} has {width}"
    return exc_text(exc)


def _load_table(body, lines, start, sep, decimal_comma, name, fmt, comments) -> np.ndarray:
    """The numbers of the text ``body`` (the lines of ``lines`` from ``start`` on) as an
    (n_rows, n_cols) float64 array; a malformed or empty table is an ``InvalidInputError``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            table = np.loadtxt(
                io.StringIO(body),
                dtype=np.float64,
                ndmin=2,
                comments=list(comments) or None,
                delimiter=sep,
            )
    except ValueError as exc:
        raise InvalidInputError(
            f"{name}: malformed {fmt} text: {_bad_line(lines, start, sep, decimal_comma, exc)}."
        ) from exc
    if table.size == 0:
        raise InvalidInputError(f"{name}: {fmt} file holds no points.")
    return table


def _unit_rows(block: np.ndarray) -> bool:
    finite = np.isfinite(block).all(axis=1)
    if not finite.any():
        return False
    return bool((np.abs(np.linalg.norm(block[finite], axis=1) - 1.0) <= 1e-3).all())


def _byte_column(col: np.ndarray) -> bool:
    return bool(
        np.isfinite(col).all()
        and (col == np.round(col)).all()
        and col.min() >= 0
        and col.max() <= 255
    )


def _xyz_guess(table: np.ndarray) -> RawGeometry:
    k = table.shape[1]
    normals = colors = None
    c = 3
    for _ in range(2):
        if normals is None and k - c >= 3 and _unit_rows(table[:, c : c + 3]):
            normals = table[:, c : c + 3].copy()
            c += 3
        if (
            colors is None
            and k - c >= 3
            and all(_byte_column(table[:, j]) for j in range(c, c + 3))
        ):
            w = 4 if k - c >= 4 and _byte_column(table[:, c + 3]) else 3
            colors = table[:, c : c + w].astype(np.uint8)
            c += w
    attrs = {f"scalar_{i}": table[:, j].copy() for i, j in enumerate(range(c, k))}
    return RawGeometry(table[:, :3].copy(), None, normals, colors, attrs)


def _xyz_by_names(table: np.ndarray, names: list[str], name: str) -> RawGeometry:
    used: set[int] = set()
    xyz = _find_group(names, (("x", "y", "z"),), 3) or [0, 1, 2]
    used.update(xyz)
    normals = colors = None
    nidx = _find_group(names, _NORMAL_KEYS, 3)
    if nidx is not None and not used & set(nidx):
        normals = table[:, nidx].copy()
        used.update(nidx)
    cidx = _find_group(names, _COLOR_KEYS, 3)
    if cidx is not None and not used & set(cidx):
        aidx = _find_group(names, _COLOR_KEYS, 4)
        if aidx is not None and aidx[3] not in used:
            cidx = aidx
        colors = text_colors(table[:, cidx])
        used.update(cidx)
    attrs: dict[str, np.ndarray] = {}
    for j, key in enumerate(names):
        if j in used:
            continue
        key = key or f"scalar_{j}"
        if key in attrs:
            raise InvalidInputError(f"{name}: the XYZ header repeats the column name {key!r}.")
        attrs[key] = table[:, j].copy()
    return RawGeometry(table[:, xyz].copy(), None, normals, colors, attrs)


def read_pts(raw: bytes, name: str) -> RawGeometry:
    """Leica/PDAL point text (``.pts``): an optional point count line, then ``x y z [i] [r g b]``.

    Rows of 3, 4 (``intensity``, a float64 attribute), 6 or 7 values (colours integers 0..255),
    separated by spaces, tabs or commas; a count line must equal the number of rows.

    Raises
    ------
    InvalidInputError
        Count mismatch, rows of another or varying width, non-numeric values, colours outside
        0..255, no data rows.
    """
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise InvalidInputError(f"{name}: PTS file holds no points.")
    declared, first = _count_line(lines, first, name)
    if first is None:
        raise InvalidInputError(f"{name}: PTS file holds no points (only a count line).")
    sep = "," if "," in lines[first] else None
    table = _load_table("\n".join(lines[first:]), lines, first, sep, False, name, "PTS", ("#",))
    _check_count(declared, table.shape[0], name, "PTS")
    k = table.shape[1]
    if k not in (3, 4, 6, 7):
        raise InvalidInputError(
            f"{name}: PTS rows must have 3, 4, 6 or 7 values (x y z [intensity] [r g b]); got {k}."
        )
    attrs = {"intensity": table[:, 3].copy()} if k in (4, 7) else {}
    colors = None
    if k >= 6:
        rgb = table[:, k - 3 :]
        if not all(_byte_column(rgb[:, j]) for j in range(3)):
            raise InvalidInputError(
                f"{name}: PTS colour values (last 3 columns) must be integers in 0..255."
            )
        colors = rgb.astype(np.uint8)
    return RawGeometry(table[:, :3].copy(), None, None, colors, attrs)


def write_xyz(P: np.ndarray, normals=None) -> bytes:
    table = P if normals is None else np.hstack([P, np.asarray(normals, dtype=np.float64)])
    buf = io.BytesIO()
    np.savetxt(buf, table, fmt="%.17g", delimiter=" ")
    return buf.getvalue()


# ------------------------------------------------------------------------------------------ NPY
def parse_npy(raw: bytes, name: str) -> np.ndarray:
    """The array of ``.npy`` bytes (a read-only view of ``raw``), its header checked first: shape
    times item size must equal the bytes that follow and stay within the memory cap; object arrays
    (pickles) are refused.
    """
    from numpy.lib import format as npf

    f = io.BytesIO(raw)
    try:
        version = npf.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = npf.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran, dtype = npf.read_array_header_2_0(f)
        elif version == (3, 0):  # utf-8 header; numpy has no public reader for it
            try:
                from numpy.lib import _format_impl as impl
            except ImportError:  # numpy < 2
                impl = npf
            shape, fortran, dtype = impl._read_array_header(f, version)
        else:
            raise ValueError(f"unsupported .npy format version {version[0]}.{version[1]}")
    except (
        ValueError,
        OSError,
        EOFError,
        OverflowError,
        SyntaxError,
        TypeError,
        KeyError,
        tokenize.TokenError,  # numpy re-tokenizes old-style headers
    ) as exc:
        raise InvalidInputError(f"{name}: not a valid .npy array ({exc_text(exc)}).") from exc
    if dtype.hasobject:
        raise InvalidInputError(
            f"{name}: not a valid .npy array (it holds Python objects, a pickle; refused)."
        )
    count = 1
    for d in shape:
        count *= int(d)
    need = count * dtype.itemsize
    have = len(raw) - f.tell()
    if need != have:
        what = "truncated" if need > have else "the header's shape disagrees with the data"
        raise InvalidInputError(
            f"{name}: not a valid .npy array ({what}: the header declares shape {tuple(shape)} "
            f"of {dtype}, {need} bytes; the file holds {have} bytes of data)."
        )
    check_alloc(2 * need, name, f"a .npy array of shape {tuple(shape)}")
    arr = np.frombuffer(raw, dtype=dtype, count=count, offset=f.tell())
    return arr.reshape(shape, order="F" if fortran else "C")


def read_npy(raw: bytes, name: str) -> RawGeometry:
    """An (n, 3) numeric array, or a 1-D structured array with fields ``x y z`` (any case; other
    numeric scalar fields become float64 attributes); pickles refused (:func:`parse_npy`).
    """
    arr = parse_npy(raw, name)
    if arr.dtype.names is not None:
        return _npy_structured(arr, name)
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "iuf":
        raise InvalidInputError(
            f"{name}: .npy must hold a numeric (n, 3) array; got dtype {getattr(arr, 'dtype', type(arr))}."
        )
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidInputError(
            f"{name}: .npy point arrays must have shape (n, 3); got {arr.shape} "
            "(sequences go in a .npz file or a folder of frames)."
        )
    return RawGeometry(arr.astype(np.float64))


def _npy_structured(arr: np.ndarray, name: str) -> RawGeometry:
    fields = list(arr.dtype.names)
    low = {f.lower(): f for f in reversed(fields)}  # the first spelling wins
    if arr.ndim != 1:
        raise InvalidInputError(
            f"{name}: a structured .npy point array must be 1-D (one record per point); got shape "
            f"{arr.shape}."
        )
    xyz = []
    for c in "xyz":
        f = low.get(c)
        if f is None:
            raise InvalidInputError(
                f"{name}: structured .npy lacks field '{c}' (fields: {' '.join(fields)})."
            )
        if arr.dtype[f].kind not in "iuf" or arr.dtype[f].shape != ():
            raise InvalidInputError(
                f"{name}: structured .npy field '{f}' must be a numeric scalar; got {arr.dtype[f]}."
            )
        xyz.append(f)
    V = np.stack([arr[f].astype(np.float64) for f in xyz], axis=1)
    attrs = {
        f: arr[f].astype(np.float64)
        for f in fields
        if f not in xyz and arr.dtype[f].kind in "iuf" and arr.dtype[f].shape == ()
    }
    return RawGeometry(V, None, None, None, attrs)


def write_npy(P: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(P, dtype=np.float64), allow_pickle=False)
    return buf.getvalue()


# ------------------------------------------------------------------------------------------ STL
def read_stl(raw: bytes, name: str) -> RawGeometry:
    """Binary or ascii STL through :func:`trimesh.exchange.stl.load_stl`: every triangle keeps its
    own corners (3 m vertices) in file order, ascii ``solid`` blocks concatenated.
    """
    from trimesh.exchange import stl

    is_binary = len(raw) >= 84 and 84 + 50 * int(np.frombuffer(raw, "<u4", 1, 80)[0]) == len(raw)
    if not is_binary:
        try:
            text_ok = raw[:5].lower() == b"solid" and raw.decode("ascii") is not None
        except UnicodeDecodeError:
            text_ok = False
        if not text_ok:
            raise InvalidInputError(
                f"{name}: not a valid STL file (neither a binary STL whose size matches its "
                "triangle count nor ascii 'solid' text; truncated or not STL)."
            )
    try:
        with quiet_trimesh():  # a bad ascii normal is logged with a traceback; normals are unused
            d = stl.load_stl_binary(io.BytesIO(raw)) if is_binary else stl.load_stl(io.BytesIO(raw))
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types (even ImportError) on garbage
        raise InvalidInputError(f"{name}: malformed or truncated STL ({exc_text(exc)}).") from exc
    parts = list(d["geometry"].values()) if "geometry" in d else [d]
    parts = [p for p in parts if isinstance(p, dict) and "vertices" in p and len(p["vertices"])]
    if not parts:
        raise InvalidInputError(
            f"{name}: not a valid STL file (no triangles found; truncated or not STL)."
        )
    V = np.concatenate([np.asarray(p["vertices"], dtype=np.float64).reshape(-1, 3) for p in parts])
    F = np.arange(V.shape[0], dtype=np.int64).reshape(-1, 3)
    return RawGeometry(V, F)


def write_stl(V: np.ndarray, F: np.ndarray, *, binary: bool) -> bytes:
    import trimesh
    from trimesh.exchange import stl

    tm = trimesh.Trimesh(vertices=V, faces=F, process=False, validate=False)
    if binary:
        return stl.export_stl(tm)
    return stl.export_stl_ascii(tm).encode("ascii")
