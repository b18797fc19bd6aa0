"""Wavefront OBJ: a vectorised reader and writer that keep the file's order and per-corner data.

Written here because meshio drops the ``vt``/``vn`` indices of corners and trimesh splits
vertices per texture coordinate and regroups faces, against the order guarantees of
:func:`spectrageo.io.read`.

Reading
    * ``v x y z [w]`` (w ignored); ``v x y z r g b [a]`` gives vertex colours (uint8 when written
      as integers 0-255). When only some ``v`` lines carry colours, the geometry is read and the
      colours dropped with a RepairWarning.
    * Faces ``f`` with corners ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``, fan-triangulated in file
      order; per-corner data follow the fan.
    * ``vt`` become the face attribute ``texcoord`` (m, 6), NaN for corners without one.
    * ``vn`` become vertex normals when every vertex has one normal (or, with no ``vn`` index,
      when there are as many ``vn`` as ``v`` lines), else the face attribute ``corner_normals``
      (m, 9), NaN for corners without one.
    * Negative indices count back from the total of ``v`` (``vt``, ``vn``) lines; groups,
      materials, lines and points are ignored; ``#`` comments; a trailing ``\\`` continues a line.
Writing
    ``v`` lines with the shortest exact repr, ``vn`` (vertex or deduplicated corner normals),
    ``vt`` (deduplicated corners, in order of first use) and ``f a[/b][/c]`` faces.
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from .._errors import InvalidInputError, RepairWarning
from ._common import exc_text, fan_triangulate, text_colors
from ._raw import RawGeometry

_COMMENT = re.compile(r"#[^\n]*")
_KEY_LINES = {
    key: re.compile(rf"^[ \t]*{key}[ \t]+([^\n]*)$", re.MULTILINE) for key in ("v", "vt", "vn", "f")
}


def _line_number(text: str, key: str, k: int) -> int:
    """1-based line number of the ``k``-th (0-based) ``key`` line of ``text`` (for error messages)."""
    pat = re.compile(rf"^[ \t]*{key}[ \t]", re.MULTILINE)
    for i, mt in enumerate(pat.finditer(text)):
        if i == k:
            return text.count("\n", 0, mt.start()) + 1
    return -1


def _table(
    text: str, key: str, name: str, min_cols: int, *, pad: bool = False, trim: bool = False
) -> np.ndarray:
    """Numbers of the ``key`` lines as a (count, width) float64 table (same width on every line;
    shorter lines padded with 0 when ``pad``; lines cut to ``min_cols`` values when ``trim`` and
    the widths differ, with a RepairWarning when values beyond a 4th are dropped)."""
    lines = _KEY_LINES[key].findall(text)
    if not lines:
        return np.zeros((0, min_cols), dtype=np.float64)
    rows = [ln.split() for ln in lines]
    lens = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    if trim and (lens != lens[0]).any() and lens.min() >= min_cols:
        extra = int((lens > min_cols + 1).sum())
        if extra:
            warnings.warn(
                f"{name}: only {extra} of {lens.size} OBJ '{key}' lines carry colours; the "
                "colours are ignored.",
                RepairWarning,
                stacklevel=3,
            )
        rows = [r[:min_cols] for r in rows]
        lens = np.full(len(rows), min_cols, dtype=np.int64)
    if pad and (lens != lens[0]).any():
        width = int(lens.max())
        rows = [r + ["0"] * (width - len(r)) for r in rows]
        lens = np.full(len(rows), width, dtype=np.int64)
    if (lens != lens[0]).any():
        k = int(np.flatnonzero(lens != lens[0])[0])
        raise InvalidInputError(
            f"{name}: malformed OBJ: '{key}' line {_line_number(text, key, k)} has {int(lens[k])} "
            f"values, the first '{key}' line {int(lens[0])}."
        )
    try:
        arr = np.array([x for r in rows for x in r], dtype=np.float64)
    except ValueError as exc:
        raise InvalidInputError(
            f"{name}: malformed OBJ: non-numeric value in a '{key}' line ({exc_text(exc)})."
        ) from exc
    return arr.reshape(len(rows), int(lens[0]))


_MISSING = np.iinfo(np.int64).min


def _fits_int64(tok: str) -> bool:
    try:
        return -(2**63) <= int(tok) < 2**63
    except ValueError:
        return True


def _indices(tokens: list[str], name: str, what: str) -> np.ndarray:
    """Integers of ``tokens``; empty tokens give ``_MISSING``."""
    present = np.fromiter((bool(t) for t in tokens), dtype=bool, count=len(tokens))
    try:
        if present.all():
            return np.array(tokens).astype(np.int64) if tokens else np.zeros(0, np.int64)
        out = np.full(len(tokens), _MISSING, dtype=np.int64)
        out[present] = np.array([t for t in tokens if t]).astype(np.int64)
    except OverflowError as exc:  # an index beyond int64: name it as written, never wrapped
        big = next((t for t in tokens if t and not _fits_int64(t)), "?")
        raise InvalidInputError(
            f"{name}: OBJ face {what} index {big} is out of range (larger than any file can hold)."
        ) from exc
    except ValueError as exc:
        raise InvalidInputError(
            f"{name}: malformed OBJ: non-integer {what} index in an 'f' line ({exc_text(exc)})."
        ) from exc
    return out


def _resolve(idx: np.ndarray, count: int, name: str, what: str, *, required: bool) -> np.ndarray:
    """1-based / relative OBJ indices -> 0-based; ``_MISSING`` stays -1 (missing)."""
    missing = idx == _MISSING
    if required and missing.any():
        raise InvalidInputError(f"{name}: malformed OBJ: a face corner has no vertex index.")
    if (idx == 0).any():
        which = "" if what == "vertex" else f"{what} "
        raise InvalidInputError(f"{name}: OBJ face {which}index 0 is invalid (indices start at 1).")
    out = np.where(idx > 0, idx - 1, count + idx)
    out[missing] = -1
    if not required:
        bad = ~missing & ((out < 0) | (out >= count))
        if bad.any():
            # the geometry is intact: drop the broken attribute, keep the mesh, and say so
            raw = int(idx[np.flatnonzero(bad)[0]])
            key = "vt" if what == "texture" else "vn"
            warnings.warn(
                f"{name}: OBJ face {what} index {raw} is out of range (the file has {count} "
                f"'{key}' lines); the {what} coordinates of the file are ignored.",
                RepairWarning,
                stacklevel=2,
            )
            return np.full(idx.shape, -1, dtype=np.int64)
    elif (out < 0).any():  # a relative index reaching before the first vertex
        raw = int(idx[np.flatnonzero(out < 0)[0]])
        raise InvalidInputError(
            f"{name}: OBJ face index {raw} is out of range: relative (negative) indices count "
            f"back from the last 'v' line (the file has {count}), so they go down to -{count}."
        )
    return out


def read_obj(raw: bytes, name: str) -> RawGeometry:
    """Parse OBJ bytes into a :class:`RawGeometry` (see the module docstring for the mapping)."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    if "\x00" in text:
        raise InvalidInputError(f"{name}: not a text OBJ file (binary content).")
    text = text.replace("\r\n", "\n").replace("\r", "\n").replace("\\\n", " ")
    text = _COMMENT.sub("", text)

    pts = _table(text, "v", name, 3, trim=True)
    if pts.shape[0] == 0:
        raise InvalidInputError(f"{name}: OBJ file has no vertices ('v' lines).")
    if pts.shape[1] < 3:
        raise InvalidInputError(
            f"{name}: OBJ 'v' lines must have at least 3 coordinates; got shape {pts.shape}."
        )
    n = pts.shape[0]
    V = np.ascontiguousarray(pts[:, :3])
    colors = text_colors(pts[:, 3:]) if pts.shape[1] in (6, 7) else None
    vt = _table(text, "vt", name, 2, pad=True)
    vn = _table(text, "vn", name, 3)
    if vn.shape[0] and vn.shape[1] != 3:
        raise InvalidInputError(f"{name}: OBJ 'vn' lines must have 3 values; got {vn.shape[1]}.")
    if vt.shape[0]:
        uv = np.zeros((vt.shape[0], 2))
        uv[:, : min(2, vt.shape[1])] = vt[:, :2]
        vt = uv

    face_lines = _KEY_LINES["f"].findall(text)
    normals = vn if (vn.shape[0] == n and vn.shape[0] > 0) else None
    if not face_lines:
        return RawGeometry(V, None, normals, colors)

    rows = [ln.split() for ln in face_lines]
    short = sum(1 for r in rows if len(r) < 3)
    if short:
        # 'f' lines with one or two corners are points or lines, not faces: skipped, and said
        warnings.warn(
            f"{name}: {short} OBJ 'f' line(s) with fewer than 3 corners skipped.",
            RepairWarning,
            stacklevel=2,
        )
        rows = [r for r in rows if len(r) >= 3]
        if not rows:
            return RawGeometry(V, None, normals, colors)
    lens = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    flat = [t for r in rows for t in r]
    if any("/" in t for t in flat):
        parts = [t.split("/") for t in flat]
        if max(len(p) for p in parts) > 3:
            raise InvalidInputError(
                f"{name}: malformed OBJ: face corners are 'v', 'v/vt', 'v//vn' or 'v/vt/vn'."
            )
        vi = _indices([p[0] for p in parts], name, "vertex")
        ti = _indices([p[1] if len(p) > 1 else "" for p in parts], name, "texture")
        ni = _indices([p[2] if len(p) > 2 else "" for p in parts], name, "normal")
    else:
        vi = _indices(flat, name, "vertex")
        ti = ni = None
    vi = _resolve(vi, n, name, "vertex", required=True)
    if ti is not None:
        ti = _resolve(ti, vt.shape[0], name, "texture", required=False)
        if (ti < 0).all():
            ti = None
    if ni is not None:
        ni = _resolve(ni, vn.shape[0], name, "normal", required=False)
        if (ni < 0).all():
            ni = None

    # fan over corner positions, then gather vertex / texture / normal indices through it
    if (lens == lens[0]).all():
        corner_polys = np.arange(lens.sum(), dtype=np.int64).reshape(lens.size, int(lens[0]))
    else:
        ends = np.cumsum(lens)
        corner_polys = [np.arange(e - k, e, dtype=np.int64) for e, k in zip(ends, lens)]
    corners, _ = fan_triangulate(corner_polys, name)
    faces = vi[corners]
    fattrs: dict[str, np.ndarray] = {}
    if ti is not None:
        t = ti[corners]
        tex = vt[np.maximum(t, 0)]  # (m, 3, 2)
        tex[t < 0] = np.nan
        fattrs["texcoord"] = tex.reshape(-1, 6)
    if ni is not None:
        normals, corner_normals = _split_normals(vi, ni, vn, n, corners)
        if corner_normals is not None:
            fattrs["corner_normals"] = corner_normals
    return RawGeometry(V, faces, normals, colors, {}, fattrs)


def _split_normals(
    vi: np.ndarray, ni: np.ndarray, vn: np.ndarray, n: int, corners: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Vertex normals when each vertex has one normal vector, else per-corner normals (m, 9)."""
    has = (ni >= 0) & (vi < n)
    per_vertex = np.full(n, -1, dtype=np.int64)
    per_vertex[vi[has]] = ni[has]
    if vn.shape[0] == n:
        unused = per_vertex < 0
        per_vertex[unused] = np.flatnonzero(unused)
    if (per_vertex >= 0).all() and np.array_equal(vn[per_vertex[vi[has]]], vn[ni[has]]):
        return vn[per_vertex], None
    c = ni[corners]
    out = vn[np.maximum(c, 0)]  # (m, 3, 3)
    out[c < 0] = np.nan
    return None, out.reshape(-1, 9)


# --------------------------------------------------------------------------------------- writing
def _fmt_rows(prefix: str, a: np.ndarray) -> str:
    """``prefix x y z`` lines with the shortest repr of each float (exact round trip)."""
    if a.size == 0:
        return ""
    line = prefix + " " + " ".join(["{!r}"] * a.shape[1]) + "\n"
    return "".join(line.format(*row) for row in np.asarray(a, dtype=np.float64).tolist())


def _dedup(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique rows of ``values`` (k, d) in order of first use and the 0-based index of each row;
    rows with NaN get index -1 and are not listed."""
    ok = np.isfinite(values).all(axis=1)
    idx = np.full(values.shape[0], -1, dtype=np.int64)
    if not ok.any():
        return np.zeros((0, values.shape[1])), idx
    uniq, first, inverse = np.unique(values[ok], axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # unique rows in order of first use
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    idx[ok] = rank[inverse.reshape(-1)]
    return uniq[order], idx


def _check_corner_attr(a, m: int, width: int, key: str) -> np.ndarray | None:
    if a is None:
        return None
    a = np.asarray(a)
    if a.shape != (m, width) or a.dtype.kind not in "fiu":
        raise InvalidInputError(
            f"face attribute `{key}` must have shape ({m}, {width}) (numbers) to be written as OBJ "
            f"per-corner data; got {a.shape} {a.dtype}."
        )
    return a.astype(np.float64)


def write_obj(
    V: np.ndarray,
    faces: np.ndarray | None,
    *,
    normals=None,
    texcoord=None,
    corner_normals=None,
) -> bytes:
    """Serialise to OBJ text: ``faces`` None writes only ``v`` (and ``vn``) lines; ``normals`` (n, 3)
    gives one ``vn`` per vertex; ``texcoord`` (m, 6) and ``corner_normals`` (m, 9, used without
    ``normals``) give deduplicated ``vt`` / ``vn`` lines (NaN corners get none).
    """
    V = np.asarray(V, dtype=np.float64)
    out = ["# written by spectrageo\n", _fmt_rows("v", V)]
    if faces is None:
        if normals is not None:
            out.append(_fmt_rows("vn", np.asarray(normals)))
        return "".join(out).encode("utf-8")
    F = np.asarray(faces, dtype=np.int64)
    m = F.shape[0]
    texcoord = _check_corner_attr(texcoord, m, 6, "texcoord")
    corner_normals = _check_corner_attr(corner_normals, m, 9, "corner_normals")
    cols = [F + 1]  # each (m, 3) 1-based, 0 = absent
    t_idx = n_idx = None
    if texcoord is not None:
        uv, idx = _dedup(texcoord.reshape(-1, 2))
        out.append(_fmt_rows("vt", uv))
        t_idx = (idx + 1).reshape(m, 3)
    if normals is not None:
        out.append(_fmt_rows("vn", np.asarray(normals)))
        n_idx = F + 1
    elif corner_normals is not None:
        nrm, idx = _dedup(corner_normals.reshape(-1, 3))
        out.append(_fmt_rows("vn", nrm))
        n_idx = (idx + 1).reshape(m, 3)
    if m == 0:
        return "".join(out).encode("utf-8")
    has_t = t_idx is not None and (t_idx > 0).any()
    has_n = n_idx is not None and (n_idx > 0).any()
    uniform = (not has_t or (t_idx > 0).all()) and (not has_n or (n_idx > 0).all())
    if uniform:
        if has_t and has_n:
            corner, table = "{}/{}/{}", np.stack([cols[0], t_idx, n_idx], axis=2)
        elif has_t:
            corner, table = "{}/{}", np.stack([cols[0], t_idx], axis=2)
        elif has_n:
            corner, table = "{}//{}", np.stack([cols[0], n_idx], axis=2)
        else:
            corner, table = "{}", cols[0][:, :, None]
        line = "f " + " ".join([corner] * 3) + "\n"
        out.append("".join(line.format(*r) for r in table.reshape(m, -1).tolist()))
        return "".join(out).encode("utf-8")
    lines = []
    tz = t_idx if has_t else np.zeros_like(F)
    nz = n_idx if has_n else np.zeros_like(F)
    for fv, ft, fn in zip(cols[0].tolist(), tz.tolist(), nz.tolist()):
        cs = []
        for a, b, c in zip(fv, ft, fn):
            cs.append(f"{a}/{b or ''}/{c}" if c else (f"{a}/{b}" if b else f"{a}"))
        lines.append("f " + " ".join(cs) + "\n")
    out.append("".join(lines))
    return "".join(out).encode("utf-8")
