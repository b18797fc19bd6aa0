"""Writing: :func:`write` dispatches on the extension; every write is atomic."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ..geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from ._api import _MESH_WRITE, _POINTS_WRITE, Geometry, _unsupported, is_single, write_advice
from ._common import atomic_dir, split_suffix, write_bytes
from ._npz import write_npz

_WRITE_OPTIONS = ("pcd_format", "dtype", "las_scale", "frame_format", "prefix", "compress")
PCD_FORMATS = ("ascii", "binary", "binary_compressed")


def _is_folder_target(path: str | os.PathLike) -> bool:
    s = os.fspath(path)
    p = Path(s)
    return s.endswith(("/", os.sep)) or p.is_dir() or p.suffix == ""


def _as_geometry(obj: Any) -> Geometry:
    if isinstance(obj, Mesh | PointCloud | MeshAnimation | PointCloudSequence):
        return obj
    if isinstance(obj, list | tuple) and obj and all(isinstance(o, PointCloud) for o in obj):
        return PointCloudSequence(list(obj))
    if isinstance(obj, np.ndarray) and obj.ndim == 2:
        return PointCloud(obj)
    raise InvalidInputError(
        "`obj` must be a Mesh, PointCloud, MeshAnimation, PointCloudSequence, a list of "
        f"PointCloud or an (n, 3) array; got {type(obj).__name__}."
    )


def write(path: str | os.PathLike, obj: Any, *, binary: bool = True, **kw: Any) -> None:
    """Write geometry atomically (temporary file in the same folder, then :func:`os.replace`).

    Parameters
    ----------
    path : str or path-like
        Target. Mesh: ``.ply .obj .off .stl``; PointCloud: ``.ply .pcd .xyz .npy .las .laz .obj
        .off``; both optionally ``.gz``. MeshAnimation / PointCloudSequence: ``.npz`` or a folder (a
        path without suffix, ending with ``/``, or an existing folder) that receives numbered frames
        ``frame_000.ply, frame_001.ply, ...``.
    obj : Mesh | PointCloud | MeshAnimation | PointCloudSequence | list[PointCloud] | (n, 3) array
    binary : bool
        Binary PLY/STL/PCD (default) or ascii. Text formats (OBJ, OFF, XYZ) ignore it.
    **kw
        Format options (any other name is an error):

        ``pcd_format`` : {"ascii", "binary", "binary_compressed"}, optional
            PCD encoding; default ``"binary"`` (``"ascii"`` when ``binary=False``).
        ``dtype`` : numpy float dtype, optional
            Coordinate type for PLY (default float64) and PCD (default float32 when every
            coordinate survives the float32 round trip exactly, else float64, so georeferenced
            clouds are not altered); always obeyed when given.
        ``las_scale`` : float, optional
            LAS/LAZ coordinate resolution (default: chosen from the extent of the points).
        ``frame_format`` : str, optional
            Frame file format of folder outputs (default ``".ply"``; e.g. ``".obj"``, ``".ply.gz"``).
        ``prefix`` : str, optional
            Frame file name prefix of folder outputs (default ``"frame_"``).
        ``compress`` : bool, optional
            ``.npz`` outputs: zip-deflate the arrays (default False).

    Notes
    -----
    Each format stores what it can hold: PLY and PCD normals, colours and attributes (PLY writes a
    (m, 6) ``texcoord`` as MeshLab's list property); OBJ vertex normals and the per-corner
    ``texcoord`` / ``corner_normals``; XYZ normals; LAS colours, normals and attributes. Writing a
    folder stages the frames in a temporary folder; stale ``<prefix><number>.*`` frames of an
    earlier, longer sequence are removed.
    """
    unknown = set(kw) - set(_WRITE_OPTIONS)
    if unknown:
        raise InvalidInputError(
            f"unexpected option(s) {', '.join(sorted(unknown))} for write; accepted: "
            f"binary, {', '.join(_WRITE_OPTIONS)}."
        )
    geom = _as_geometry(obj)
    if kw.get("pcd_format") is not None and kw["pcd_format"] not in PCD_FORMATS:
        raise InvalidInputError(
            f"`pcd_format` must be one of {', '.join(map(repr, PCD_FORMATS))}; got {kw['pcd_format']!r}."
        )
    p = Path(path)
    if isinstance(geom, MeshAnimation | PointCloudSequence):
        if _is_folder_target(path):
            _write_folder(p, geom, binary=binary, **kw)
            return
        suffix, gz = split_suffix(p)
        if suffix != ".npz":
            advice = write_advice(suffix)
            if advice is not None:
                raise UnsupportedFormatError(f"{p.name}: {advice}")
            raise _unsupported(p, suffix, [".npz", "<folder>/"])
        write_npz(p, geom, gz=gz, compress=bool(kw.get("compress", False)))
        return
    if _is_folder_target(path):
        raise InvalidInputError(
            f"{p}: a {type(geom).__name__} is written to a file with an extension "
            f"(one of {', '.join(_MESH_WRITE if isinstance(geom, Mesh) else _POINTS_WRITE)})."
        )
    suffix, gz = split_suffix(p)
    data = _serialise(p, geom, suffix, binary=binary, **kw)
    write_bytes(p, data, gz)


def _serialise(p: Path, geom: Mesh | PointCloud, suffix: str, *, binary: bool, **kw: Any) -> bytes:
    dtype = kw.get("dtype")
    advice = write_advice(suffix)
    if advice is not None:
        raise UnsupportedFormatError(f"{p.name}: {advice}")
    if isinstance(geom, Mesh):
        if suffix not in _MESH_WRITE:
            extra = (
                " To save only the vertices, write PointCloud(mesh.vertices) instead."
                if suffix in _POINTS_WRITE
                else ""
            )
            raise UnsupportedFormatError(
                f"{p.name}: cannot write a Mesh as {suffix or '(no extension)'!r}; mesh formats: "
                f"{', '.join(_MESH_WRITE)} (optionally .gz).{extra}"
            )
        V, F = geom.vertices, geom.faces
        if suffix == ".ply":
            from ._ply import write_ply

            return write_ply(
                V,
                F,
                normals=geom.vertex_normals,
                colors=geom.vertex_colors,
                vertex_attributes=geom.vertex_attributes,
                face_attributes=geom.face_attributes,
                binary=binary,
                dtype=dtype if dtype is not None else np.float64,
            )
        if suffix == ".obj":
            from ._obj import write_obj

            return write_obj(
                V,
                F,
                normals=geom.vertex_normals,
                texcoord=geom.face_attributes.get("texcoord"),
                corner_normals=geom.face_attributes.get("corner_normals"),
            )
        if suffix == ".off":
            from ._off import write_off

            return write_off(V, F)
        from ._simple import write_stl

        return write_stl(V, F, binary=binary)
    if suffix not in _POINTS_WRITE:
        raise _unsupported(p, suffix, _POINTS_WRITE)
    P = geom.points
    if suffix == ".ply":
        from ._ply import write_ply

        return write_ply(
            P,
            None,
            normals=geom.normals,
            colors=geom.colors,
            vertex_attributes=geom.attributes,
            binary=binary,
            dtype=dtype if dtype is not None else np.float64,
        )
    if suffix == ".pcd":
        from ._pcd import write_pcd

        fmt = kw.get("pcd_format") or ("binary" if binary else "ascii")
        return write_pcd(
            P,
            normals=geom.normals,
            colors=geom.colors,
            attributes=geom.attributes,
            pcd_format=fmt,
            dtype=dtype,
        )
    if suffix == ".xyz":
        from ._simple import write_xyz

        return write_xyz(P, geom.normals)
    if suffix == ".npy":
        from ._simple import write_npy

        return write_npy(P)
    if suffix in (".las", ".laz"):
        from ._las import write_las

        return write_las(
            P,
            normals=geom.normals,
            colors=geom.colors,
            attributes=geom.attributes,
            compressed=suffix == ".laz",
            las_scale=kw.get("las_scale"),
        )
    if suffix == ".obj":
        from ._obj import write_obj

        return write_obj(P, None, normals=geom.normals)
    from ._off import write_off

    return write_off(P, None)


def _write_folder(
    folder: Path, geom: MeshAnimation | PointCloudSequence, *, binary: bool, **kw: Any
) -> None:
    fmt = str(kw.get("frame_format") or ".ply").lower()
    if not fmt.startswith("."):
        fmt = "." + fmt
    prefix = str(kw.get("prefix", "frame_"))
    if os.sep in prefix or "/" in prefix:
        raise InvalidInputError(f"`prefix` must be a plain file name prefix; got {prefix!r}.")
    suffix, _gz = split_suffix(Path("x" + fmt))
    allowed = _MESH_WRITE if isinstance(geom, MeshAnimation) else _POINTS_WRITE
    if suffix not in allowed:
        raise UnsupportedFormatError(
            f"`frame_format` {fmt!r} cannot hold {type(geom).__name__} frames; use one of "
            f"{', '.join(allowed)} (optionally .gz)."
        )
    frames = list(geom) if isinstance(geom, MeshAnimation) else list(geom.frames)
    width = max(3, len(str(len(frames) - 1)))
    names = [f"{prefix}{t:0{width}d}{fmt}" for t in range(len(frames))]
    opts = {k: v for k, v in kw.items() if k not in ("frame_format", "prefix", "compress")}
    with atomic_dir(folder) as stage:
        for name, fr in zip(names, frames):
            sfx, gz = split_suffix(stage / name)
            data = _serialise(stage / name, fr, sfx, binary=binary, **opts)
            write_bytes(stage / name, data, gz)
    # frames of an earlier, longer (or other-format) sequence with the same prefix would be read back
    keep = set(names)
    pattern = re.compile(re.escape(prefix) + r"\d+\.")
    for f in folder.iterdir():
        if f.name in keep or not f.is_file() or not pattern.match(f.name):
            continue
        if is_single(split_suffix(f)[0]):
            f.unlink()
