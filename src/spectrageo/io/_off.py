"""Object File Format (OFF, COFF, NOFF, CNOFF, STOFF...), read with numpy, written with meshio.

Read here (meshio reads triangles only and rejects ``COFF``; trimesh drops colours and regroups
faces) with :func:`numpy.loadtxt` on the vertex and face blocks, keeping both orders. ``#``
comments; counts may sit on the keyword line; ``COFF`` colours -> ``vertex_colors``; ``NOFF``
normals -> vertex normals; polygons fan-triangulated; face colours ignored; ``OFF BINARY`` by
:func:`read_off_binary`; ``4OFF``/``nOFF`` rejected. Header and body must agree: non-negative
counts, exactly that many vertex and face lines and nothing after them; indices in range.
"""

from __future__ import annotations

import io
import os
import re
import tempfile

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ._common import check_alloc, fan_triangulate, text_colors
from ._raw import RawGeometry

_KEYWORD = re.compile(r"(ST)?(C)?(N)?(4)?(n)?OFF(BINARY)?")


def _table(lines: list[str]) -> np.ndarray | None:
    if not lines:
        return np.zeros((0, 0))
    try:
        return np.loadtxt(io.StringIO("\n".join(lines)), dtype=np.float64, ndmin=2)
    except ValueError:
        return None


def read_off(raw: bytes, name: str) -> RawGeometry:
    head = raw[: raw.find(b"\n") if b"\n" in raw else len(raw)].split(b"#", 1)[0].split()
    if head and (head[0].endswith(b"OFFBINARY") or head[1:2] == [b"BINARY"]):
        return read_off_binary(raw, name)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    lines = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            lines.append(line)
    if not lines:
        raise InvalidInputError(f"{name}: empty OFF file.")
    first = lines[0].split()
    m = _KEYWORD.fullmatch(first[0])
    if m is None:
        raise InvalidInputError(f"{name}: not an OFF file (first keyword {first[0][:20]!r}).")
    st, has_c, has_n, four, ndim, binary = m.groups()
    if four or ndim or binary:
        raise UnsupportedFormatError(
            f"{name}: OFF variant {first[0]!r} is not supported (3-D ascii OFF only)."
        )
    if len(first) > 1:
        counts, start = first[1:], 1
    else:
        if len(lines) < 2:
            raise InvalidInputError(f"{name}: OFF file has no counts line.")
        counts, start = lines[1].split(), 2
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (IndexError, ValueError) as exc:
        raise InvalidInputError(
            f"{name}: malformed OFF counts line {' '.join(counts)!r} (expected 'n_vertices n_faces n_edges')."
        ) from exc
    if nv < 0 or nf < 0:
        raise InvalidInputError(f"{name}: negative counts in OFF header ({nv}, {nf}).")
    if nv == 0:
        raise InvalidInputError(f"{name}: OFF file has no vertices.")
    vlines = lines[start : start + nv]
    if len(vlines) < nv:
        raise InvalidInputError(
            f"{name}: truncated OFF: {nv} vertices declared, {len(vlines)} vertex lines found."
        )
    vt = _table(vlines)
    if vt is None:
        raise InvalidInputError(
            f"{name}: malformed OFF vertex lines (non-numeric values or varying column counts)."
        )
    base = 3 + (3 if has_n else 0) + (2 if st else 0)
    ncol = vt.shape[1]
    n_color = ncol - base
    if ncol < base or (has_c and n_color not in (3, 4)) or (not has_c and n_color not in (0,)):
        if not has_c and n_color > 0 and ncol >= 3:
            n_color = 0  # extra values on plain OFF vertex lines are ignored
        else:
            raise InvalidInputError(
                f"{name}: OFF vertex lines have {ncol} values; {first[0]} expects {base}"
                + (" + 3 or 4 colour values." if has_c else ".")
            )
    V = vt[:, :3]
    c = 3
    normals = None
    if has_n:
        normals = vt[:, 3:6]
        c = 6
    colors = text_colors(vt[:, c : c + n_color]) if has_c and n_color else None
    flines = lines[start + nv : start + nv + nf]
    if len(flines) < nf:
        raise InvalidInputError(
            f"{name}: truncated OFF: {nf} faces declared, {len(flines)} face lines found."
        )
    rest = len(lines) - (start + nv + nf)
    if rest > 0:
        raise InvalidInputError(
            f"{name}: OFF counts line declares {nv} vertices and {nf} faces, but {rest} more "
            "line(s) follow them; the counts disagree with the body."
        )
    faces = _faces(flines, name, nv)
    return RawGeometry(V, faces, normals, colors)


def read_off_binary(raw: bytes, name: str) -> RawGeometry:
    """Binary OFF (``OFF BINARY`` / ``NOFF BINARY`` / ``STOFF BINARY`` keyword line).

    int32 counts ``nv nf ne``, ``nv`` float32 vertex records (plus NOFF normals, STOFF ``s t``
    ignored), then per face ``k`` and ``k`` int32 indices, with (Geomview) or without (pmp-library)
    a colour count and its float32 values (ignored): the layout whose records fill the file
    exactly. Big-endian, or little-endian when the big-endian count does not fit the file.

    Raises
    ------
    InvalidInputError
        Truncated data, records that fill the file in neither layout, face sizes below 3, indices
        out of range, no vertices; :class:`~spectrageo.UnsupportedFormatError` for binary COFF,
        4OFF and nOFF.
    """
    end = raw.find(b"\n")
    if end < 0:
        raise InvalidInputError(f"{name}: truncated binary OFF (nothing after the keyword line).")
    keyword = raw[:end].split()[0].decode("latin-1")
    m = _KEYWORD.fullmatch(keyword.removesuffix("BINARY") + "BINARY")
    if m is None:
        raise InvalidInputError(f"{name}: not an OFF file (first keyword {keyword[:20]!r}).")
    st, has_c, has_n, four, ndim, _binary = m.groups()
    if has_c or four or ndim:
        raise UnsupportedFormatError(
            f"{name}: binary OFF variant {keyword!r} is not supported (OFF, NOFF and STOFF BINARY "
            "only; colours, 4-D and n-D vertices are not)."
        )
    body = raw[end + 1 :]
    if len(body) < 12:
        raise InvalidInputError(
            f"{name}: truncated binary OFF: {len(body)} bytes after the keyword line, the counts "
            "need 12."
        )
    stride = 3 + (3 if has_n else 0) + (2 if st else 0)
    order = ">"
    nv, nf, _ne = (int(v) for v in np.frombuffer(body, ">i4", 3))
    if not 0 <= nv * stride * 4 <= len(body) - 12:
        le = [int(v) for v in np.frombuffer(body, "<i4", 3)]
        if 0 < le[0] * stride * 4 <= len(body) - 12 and le[1] >= 0:
            order, (nv, nf, _ne) = "<", le
    if nv < 0 or nf < 0:
        raise InvalidInputError(f"{name}: negative counts in binary OFF header ({nv}, {nf}).")
    if nv == 0:
        raise InvalidInputError(f"{name}: OFF file has no vertices.")
    need = nv * stride * 4
    if need > len(body) - 12:
        raise InvalidInputError(
            f"{name}: truncated binary OFF: {nv} vertices declared need {need} bytes, "
            f"{len(body) - 12} bytes follow the counts."
        )
    check_alloc(nv * stride * 8, name, f"{nv} OFF vertices")
    vt = np.frombuffer(body, f"{order}f4", nv * stride, 12).reshape(nv, stride).astype(np.float64)
    V = np.ascontiguousarray(vt[:, :3])
    normals = np.ascontiguousarray(vt[:, 3:6]) if has_n else None
    rest = body[12 + need :]
    if len(rest) % 4:
        raise InvalidInputError(
            f"{name}: malformed binary OFF: the {len(rest)} bytes after the vertices are not whole "
            "int32 face records (truncated or trailing bytes)."
        )
    words = np.frombuffer(rest, f"{order}i4").astype(np.int64)
    faces = _binary_faces(words, nf, nv, name)
    return RawGeometry(V, faces, normals, None)


def _binary_faces(words: np.ndarray, nf: int, nv: int, name: str) -> np.ndarray:
    """Faces of binary OFF from the int32 words after the vertices (both layouts, see above)."""
    if nf == 0:
        if len(words):
            raise InvalidInputError(
                f"{name}: binary OFF declares 0 faces, but {4 * len(words)} bytes follow the "
                "vertices; the counts disagree with the body."
            )
        return np.zeros((0, 3), dtype=np.int64)
    if not len(words):
        raise InvalidInputError(f"{name}: truncated binary OFF: {nf} faces declared, none present.")
    k = int(words[0])
    if k < 3:
        raise InvalidInputError(f"{name}: binary OFF face 0 has {k} vertices; at least 3 needed.")
    polys = None
    for with_colors in (True, False):
        # uniform records (all faces of one size, one colour count): one reshape, no loop
        ncol = int(words[k + 1]) if with_colors and len(words) > k + 1 else 0
        width = 1 + k + (1 + ncol if with_colors else 0)
        if ncol >= 0 and len(words) == nf * width:
            rec = words.reshape(nf, width)
            if (rec[:, 0] == k).all() and (not with_colors or (rec[:, k + 1] == ncol).all()):
                polys = rec[:, 1 : 1 + k]
                break
        polys = _walk_faces(words, nf, with_colors)
        if polys is not None:
            break
    if polys is None:
        raise InvalidInputError(
            f"{name}: malformed or truncated binary OFF: the {4 * len(words)} bytes after the "
            f"vertices do not hold the {nf} declared face records."
        )
    if isinstance(polys, np.ndarray):
        idx = polys
    else:
        idx = np.concatenate([np.asarray(p, dtype=np.int64) for p in polys])
        small = next((i for i, p in enumerate(polys) if len(p) < 3), None)
        if small is not None:
            raise InvalidInputError(
                f"{name}: binary OFF face {small} has {len(polys[small])} vertices; at least 3 "
                "needed."
            )
    if idx.size and (idx.min() < 0 or idx.max() >= nv):
        raise _out_of_range(name, int(idx[(idx < 0) | (idx >= nv)][0]), nv)
    return fan_triangulate(polys, name)[0]


def _walk_faces(words: np.ndarray, nf: int, with_colors: bool) -> list[np.ndarray] | None:
    """Variable-size face records, read one after another (each record's start depends on the
    sizes before it, so this is a sequential walk); None when they do not fill ``words`` exactly."""
    polys = []
    pos, n = 0, len(words)
    for _ in range(nf):
        if pos >= n:
            return None
        k = int(words[pos])
        if k < 0 or pos + 1 + k > n:
            return None
        polys.append(words[pos + 1 : pos + 1 + k])
        pos += 1 + k
        if with_colors:
            if pos >= n:
                return None
            ncol = int(words[pos])
            if ncol < 0:
                return None
            pos += 1 + ncol
    return polys if pos == n else None


def _out_of_range(name: str, value, nv: int) -> InvalidInputError:
    return InvalidInputError(
        f"{name}: `faces` has vertex indices out of range: expected 0..{nv - 1} (the file declares "
        f"{nv} vertices); got {value}."
    )


def _faces(flines: list[str], name: str, nv: int) -> np.ndarray:
    if not flines:
        return np.zeros((0, 3), dtype=np.int64)
    ft = _table(flines)
    if ft is not None and ft.shape[1] >= 1:
        k = ft[:, 0]
        if (
            (k == k[0]).all()
            and np.isfinite(k[0])
            and k[0] == int(k[0])
            and 3 <= int(k[0]) <= ft.shape[1] - 1
        ):
            kk = int(k[0])
            idx = ft[:, 1 : 1 + kk]
            if (idx != np.round(idx)).any() or not np.isfinite(idx).all():
                raise InvalidInputError(f"{name}: OFF face indices must be integers.")
            if idx.min() < 0 or idx.max() >= nv:  # checked as floats: no int64 wrap-around
                row = int(np.flatnonzero(((idx < 0) | (idx >= nv)).any(axis=1))[0])
                toks = flines[row].split()[1 : 1 + kk]  # the index as written, exact
                bad = next(t for t, v in zip(toks, idx[row]) if v < 0 or v >= nv)
                raise _out_of_range(name, bad, nv)
            return fan_triangulate(idx.astype(np.int64), name)[0]
    polys = []
    for i, line in enumerate(flines):
        tok = line.split()
        try:
            k = int(tok[0])
            idx = [int(t) for t in tok[1 : 1 + max(k, 0)]]
        except (ValueError, IndexError) as exc:
            raise InvalidInputError(f"{name}: malformed OFF face line {i}: {line[:60]!r}.") from exc
        if len(idx) != k:
            raise InvalidInputError(
                f"{name}: OFF face line {i} declares {k} vertices but lists {len(idx)}."
            )
        for v in idx:
            if not 0 <= v < nv:
                raise _out_of_range(name, v, nv)
        polys.append(idx)
    return fan_triangulate(polys, name)[0]


def write_off(V: np.ndarray, faces: np.ndarray | None) -> bytes:
    import meshio

    cells = [("triangle", np.asarray(faces, dtype=np.int64))] if faces is not None else []
    mesh = meshio.Mesh(np.asarray(V, dtype=np.float64), cells)
    # meshio's OFF writer opens a path itself; write to a private temporary file and return its bytes
    with tempfile.TemporaryDirectory(prefix="spectrageo-off-") as d:
        tmp = os.path.join(d, "mesh.off")
        meshio.off.write(tmp, mesh)
        with open(tmp, "rb") as fh:
            return fh.read()
