"""Per-vertex or per-face values written to ``.npy``, ``.csv`` or ``.ply``.

A ``.ply`` holds the input geometry with the values as a vertex or face property and jet colours
quantised to 64 classes, as the thesis visualises them; per-face values are coloured through
their first-ring mean at the vertices, since PLY viewers colour vertices.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InvalidInputError

VALUE_SUFFIXES = (".npy", ".csv", ".ply")


def value_suffix(path: str) -> str:
    p = Path(path)
    suf = p.suffix.lower()
    if suf == ".gz":
        suf = Path(p.stem).suffix.lower()
    if suf not in VALUE_SUFFIXES:
        raise InvalidInputError(
            f"`--out` must end with one of {', '.join(VALUE_SUFFIXES)}; got {path!r}."
        )
    return suf


def write_values(path: str, values: np.ndarray, *, geometry=None, per: str = "vertex", name: str):
    """Write values to .npy/.csv, or as a property + jet colours of ``geometry`` to .ply."""
    from .. import io
    from .._colormap import jet
    from ..geometry import Mesh, PointCloud
    from ..io import atomic_write

    suf = value_suffix(path)
    values = np.asarray(values)
    if suf == ".npy":
        with atomic_write(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, values)
        return
    if suf == ".csv":
        fmt = "%d" if np.issubdtype(values.dtype, np.integer) else "%.9g"
        with atomic_write(path) as tmp:
            np.savetxt(tmp, values if values.ndim > 1 else values[:, None], fmt=fmt, delimiter=",")
        return
    if geometry is None:
        raise InvalidInputError("a .ply output needs geometry; use .npy or .csv.")
    vals = values.astype(np.float64)
    if isinstance(geometry, PointCloud):
        out = PointCloud(
            geometry.points,
            normals=geometry.normals,
            colors=jet(vals),
            attributes={**geometry.attributes, name: vals},
        )
    else:
        if per == "face":
            from ..saliency._common import face_to_vertex

            shown = face_to_vertex(vals, geometry.faces, geometry.n_vertices)
            out = Mesh(
                geometry.vertices,
                geometry.faces,
                vertex_colors=jet(shown),
                face_attributes={name: vals},
            )
        else:
            out = Mesh(
                geometry.vertices,
                geometry.faces,
                vertex_colors=jet(vals),
                vertex_attributes={name: vals},
            )
    io.write(path, out)
