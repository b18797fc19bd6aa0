"""Wavefront OBJ through :mod:`meshio`.

meshio's OBJ reader keeps the file's order: ``v`` lines in order, ``f`` lines in order (its face
blocks follow the file), texture/normal indices of ``f a/b/c`` ignored. trimesh's OBJ loader was not
used because it may split vertices per texture coordinate and regroups faces by material/object.

Conventions
    * ``v x y z [w]``: w is ignored; ``v x y z r g b [a]`` (a common extension) gives vertex colours
      (floats in [0, 1], or uint8 when the file writes integers 0-255).
    * ``vn`` lines become vertex normals only when there are exactly as many as ``v`` lines (the
      per-vertex layout MeshLab and most exporters write); otherwise they are ignored.
    * Quads and polygons are fan-triangulated, ``(v0, v1, v2), (v0, v2, v3), ...``, in file order.
    * Negative (relative) indices are resolved against the total vertex count, which is exact when
      all ``v`` lines come before the faces (the usual layout).
    * Groups, materials, texture coordinates, lines (``l``) and points (``p``) are ignored.
"""

from __future__ import annotations

import io
import re

import numpy as np

from .._errors import InvalidInputError
from ._common import exc_text, fan_triangulate, text_colors
from ._raw import RawGeometry

_VT_LINE = re.compile(r"^[ \t]*vt[ \t].*$", re.MULTILINE)
_VN_LINE = re.compile(r"^[ \t]*vn[ \t].*$", re.MULTILINE)
_V_LINE = re.compile(r"^[ \t]*v[ \t]", re.MULTILINE)


def read_obj(raw: bytes, name: str) -> RawGeometry:
    import meshio

    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    if "\x00" in text:
        raise InvalidInputError(f"{name}: not a text OBJ file (binary content).")
    # meshio requires as many vt (and vn) lines as v lines; texture coordinates are not used here and
    # normals only in the per-vertex layout, so the other lines are dropped before parsing.
    text = _VT_LINE.sub("", text)
    if len(_VN_LINE.findall(text)) != len(_V_LINE.findall(text)):
        text = _VN_LINE.sub("", text)
    try:
        m = meshio.obj.read(io.StringIO(text))
    except (ValueError, TypeError, IndexError) as exc:
        raise InvalidInputError(f"{name}: malformed OBJ ({exc_text(exc)}).") from exc
    pts = np.asarray(m.points, dtype=np.float64)
    if pts.size == 0:
        raise InvalidInputError(f"{name}: OBJ file has no vertices ('v' lines).")
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise InvalidInputError(
            f"{name}: OBJ 'v' lines must have at least 3 coordinates; got shape {pts.shape}."
        )
    n = pts.shape[0]
    V = pts[:, :3]
    colors = None
    if pts.shape[1] in (6, 7):
        colors = text_colors(pts[:, 3:])
    normals = None
    vn = m.point_data.get("obj:vn")
    if vn is not None and vn.ndim == 2 and vn.shape == (n, 3):
        normals = np.asarray(vn, dtype=np.float64)
    faces = None
    if m.cells:
        blocks = []
        for cb in m.cells:
            data = np.asarray(cb.data, dtype=np.int64)
            # meshio subtracts 1 from every index: 0 (invalid in OBJ) -> -1, relative -k -> -k-1
            if (data == -1).any():
                raise InvalidInputError(
                    f"{name}: OBJ face index 0 is invalid (indices start at 1)."
                )
            neg = data < -1
            if neg.any():
                data = np.where(neg, n + data + 1, data)
            tris, _ = fan_triangulate(data, name)
            blocks.append(tris)
        faces = np.concatenate(blocks) if blocks else np.zeros((0, 3), dtype=np.int64)
    return RawGeometry(V, faces, normals, colors)


def write_obj(V: np.ndarray, faces: np.ndarray | None, *, normals=None) -> bytes:
    import meshio

    cells = [("triangle", np.asarray(faces, dtype=np.int64))] if faces is not None else []
    point_data = {"obj:vn": np.asarray(normals, dtype=np.float64)} if normals is not None else {}
    mesh = meshio.Mesh(np.asarray(V, dtype=np.float64), cells, point_data=point_data)
    buf = io.StringIO()
    meshio.obj.write(buf, mesh)
    return buf.getvalue().encode("utf-8")
