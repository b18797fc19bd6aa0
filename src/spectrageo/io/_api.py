"""Public read/write functions: dispatch on the extension, validation, atomic output."""

from __future__ import annotations

import functools
import importlib
import io
import os
import re
import warnings
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import ConvergenceWarning, InvalidInputError, RepairWarning, UnsupportedFormatError
from ..geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from ..geometry.repair import WELD_TOL, Weld, is_soup
from ..geometry.repair import weld as weld_mesh
from ._common import (
    atomic_dir,
    atomic_write,
    check_alloc,
    exc_text,
    natural_key,
    read_bytes,
    split_suffix,
    write_bytes,
)
from ._raw import RawGeometry

Geometry = Mesh | PointCloud | MeshAnimation | PointCloudSequence

KINDS = ("mesh", "points", "animation", "sequence")
NAN_POLICIES = ("raise", "drop")


# ------------------------------------------------------------------------------ format registry
# extension -> (module of this package, reader function, extra keyword arguments); the modules are
# imported on first use so that reading a PLY never imports laspy
_READER_SPECS: dict[str, tuple[str, str, dict[str, Any]]] = {
    ".ply": ("_ply", "read_ply", {}),
    ".obj": ("_obj", "read_obj", {}),
    ".off": ("_off", "read_off", {}),
    ".stl": ("_simple", "read_stl", {}),
    ".pcd": ("_pcd", "read_pcd", {}),
    ".xyz": ("_simple", "read_xyz", {}),
    ".pts": ("_simple", "read_pts", {}),
    ".npy": ("_simple", "read_npy", {}),
    ".las": ("_las", "read_las", {"compressed": False}),
    ".laz": ("_las", "read_las", {"compressed": True}),
    ".glb": ("_trimesh_formats", "read_glb", {}),
    ".gltf": ("_trimesh_formats", "read_gltf", {}),
    ".3mf": ("_trimesh_formats", "read_3mf", {}),
    ".sgc": ("_sgc", "read_sgc", {}),
}


def _reader(suffix: str) -> Callable[[bytes, str], RawGeometry]:
    module, func, kwargs = _READER_SPECS[suffix]
    fn = getattr(importlib.import_module(f"{__package__}.{module}"), func)
    return functools.partial(fn, **kwargs) if kwargs else fn


_MESH_WRITE = (".ply", ".obj", ".off", ".stl")
_POINTS_WRITE = (".ply", ".pcd", ".xyz", ".npy", ".las", ".laz", ".obj", ".off")
_WRITE_OPTIONS = ("pcd_format", "dtype", "las_scale", "frame_format", "prefix", "compress")
PCD_FORMATS = ("ascii", "binary", "binary_compressed")


def supported_formats() -> dict[str, Any]:
    """Extensions spectrageo reads and writes.

    Returns
    -------
    dict
        ``"read"``: extensions of single files (each also readable gzip-compressed, ``.ply.gz``...;
        ``.sgc``: a compressed mesh, decoded) plus ``".npz"`` (animation or sequence), ``".sga"``
        (a compressed animation, decoded) and ``"<folder>/"`` (numbered frame files);
        ``"write"``: extensions per object type (``"mesh"``, ``"points"``, ``"animation"``,
        ``"sequence"``); ``"compression"``: ``[".gz"]``, appendable to every single-file format.
    """
    return {
        "read": [*_READER_SPECS, ".npz", ".sga", "<folder>/"],
        "write": {
            "mesh": list(_MESH_WRITE),
            "points": list(_POINTS_WRITE),
            "animation": [".npz", "<folder>/"],
            "sequence": [".npz", "<folder>/"],
        },
        "compression": [".gz"],
    }


def _unsupported(p: Path, suffix: str, allowed) -> UnsupportedFormatError:
    shown = suffix if suffix else "(none)"
    return UnsupportedFormatError(
        f"{p.name}: unsupported file extension {shown!r}; supported: {', '.join(allowed)} "
        "(each optionally gzip-compressed, e.g. .ply.gz)."
    )


# ------------------------------------------------------------------------------------- reading
def _check_kind(kind: str | None) -> None:
    if kind is not None and kind not in KINDS:
        raise InvalidInputError(
            f"`kind` must be one of {', '.join(map(repr, KINDS))} or None; got {kind!r}."
        )


def _format_suffix(p: Path, format: str | None) -> tuple[str, bool]:
    suffix, gz = split_suffix(p)
    if format is not None:
        f = str(format).lower().strip()
        gz = gz or f.endswith(".gz")
        f = f.removesuffix(".gz")
        suffix = f if f.startswith(".") else "." + f
    return suffix, gz


@dataclass(frozen=True)
class ReadReport:
    """What :func:`read_with_report` did to the file's data on the way in.

    Attributes
    ----------
    n_input_vertices : int
        Vertex/point rows in the file (frame 0 for animations and sequences).
    n_merged_vertices : int
        Vertices merged into an earlier one by welding (0 when not welded).
    n_dropped_faces : int
        Faces dropped because welding collapsed two of their corners.
    welded : bool
        Whether the mesh was welded.
    n_nonfinite_rows : int
        Rows with NaN/inf coordinates that were dropped (point clouds; see ``nan_points``).
    source_index : (k,) int64 or None
        Input row of every point kept, when rows were dropped; None otherwise.
    """

    n_input_vertices: int = 0
    n_merged_vertices: int = 0
    n_dropped_faces: int = 0
    welded: bool = False
    n_nonfinite_rows: int = 0
    source_index: np.ndarray | None = None


def read(
    path: str | os.PathLike,
    *,
    kind: str | None = None,
    weld: bool | None = None,
    weld_tol: float | None = None,
    format: str | None = None,
    nan_points: str | None = None,
) -> Geometry:
    """Read a mesh, point cloud, mesh animation or point-cloud sequence.

    Parameters
    ----------
    path : str or path-like
        A file (``.ply .obj .off .stl .pcd .xyz .pts .npy .las .laz .glb .gltf .3mf``, each optionally
        ``.gz``), a ``.npz`` animation/sequence, a compressed mesh (``.sgc``) or animation
        (``.sga``) of :mod:`spectrageo.compress` (decoded whole; a cut file is an error, see
        ``decode(..., partial=True)``), or a folder of numbered frame files.
    kind : {"mesh", "points", "animation", "sequence"} or None
        Force the interpretation. None: a file with faces gives a :class:`Mesh`, without faces a
        :class:`PointCloud`; ``.npz`` with ``faces`` a :class:`MeshAnimation`, with ``points`` a
        :class:`PointCloudSequence`; a folder gives an animation when every frame has faces, else a
        sequence. ``"points"`` reads a mesh file's vertices (with normals, colours, attributes) as a
        point cloud; ``"sequence"`` reads an animation's frames as point clouds.
    weld : bool or None
        Merge coincident vertices of a mesh (within ``weld_tol`` times the bounding-box diagonal; the
        first vertex of each group is kept, in input order, with its per-vertex data; faces whose
        corners collapse are dropped). None (default): weld triangle soups only, i.e. STL files and
        any mesh whose faces share no vertex; every other mesh keeps its vertex order and count
        exactly (seam copies included: the processing functions weld internally and write results
        back in the input's order, see :func:`spectrageo.geometry.weld`). False: never weld (the
        raw soup); True: always weld.
    weld_tol : float, optional
        Relative weld tolerance; default :data:`spectrageo.geometry.WELD_TOL` (1e-6).
    format : str, optional
        Format to use instead of the one the extension implies (``"xyz"``, ``"ply.gz"``...).
    nan_points : {"raise", "drop"} or None
        What to do with points whose coordinates are NaN/inf. None: ``"drop"`` for PCD (NaN marks
        "no measurement" in organized clouds; the kept points' original indices go to the attribute
        ``source_index``), ``"raise"`` elsewhere. Mesh vertices are never dropped (indices would move).
        Normals or colours with NaN/inf in some rows (of points that are kept) are not read at
        all, with a :class:`~spectrageo.RepairWarning` giving the count: the coordinates are
        kept, and no NaN normal reaches the result (processing recomputes normals when needed).

    Returns
    -------
    Mesh | PointCloud | MeshAnimation | PointCloudSequence

    Raises
    ------
    InvalidInputError
        Missing file ("file not found: ..."), malformed/truncated/empty file, NaN coordinates, face
        indices out of range, shape errors; the message names the file.
    UnsupportedFormatError
        Unknown extension (the message lists the supported ones) or unsupported variant.

    Notes
    -----
    Apart from welding soups (above), readers never repair: degenerate faces, duplicate and
    unreferenced vertices are kept as in the file (order and count preserved). Repairs are explicit,
    see :func:`spectrageo.geometry.clean_mesh`. Polygons are fan-triangulated in file order.
    :func:`read_with_report` also says how many vertices were merged and rows dropped.
    """
    return read_with_report(
        path, kind=kind, weld=weld, weld_tol=weld_tol, format=format, nan_points=nan_points
    )[0]


def read_with_report(
    path: str | os.PathLike,
    *,
    kind: str | None = None,
    weld: bool | None = None,
    weld_tol: float | None = None,
    format: str | None = None,
    nan_points: str | None = None,
) -> tuple[Geometry, ReadReport]:
    """:func:`read`, also returning a :class:`ReadReport` (vertices merged, rows dropped).

    Hostile input: the readers check every size a file declares against the bytes present and the
    memory cap (``SPECTRAGEO_MAX_BYTES``, see :mod:`spectrageo.io._common`) before allocating;
    an allocation that still fails (``MemoryError``) becomes :class:`InvalidInputError` naming the
    file. Warnings of the libraries underneath (numpy casts, trimesh, plyfile) are silenced while
    reading; spectrageo's own :class:`~spectrageo.RepairWarning` s are emitted after a successful
    read only, so that a failed read reports one error and nothing else.
    """
    with warnings.catch_warnings(record=True) as caught, np.errstate(all="ignore"):
        warnings.simplefilter("always")
        try:
            out = _read_with_report(
                path, kind=kind, weld=weld, weld_tol=weld_tol, format=format, nan_points=nan_points
            )
        except MemoryError as exc:
            raise InvalidInputError(
                f"{Path(path).name}: not enough memory to read this file (the sizes it declares "
                f"need more than is available{': ' + str(exc) if str(exc) else ''})."
            ) from None
        except RecursionError as exc:
            raise InvalidInputError(f"{Path(path).name}: malformed file ({exc}).") from None
        except InvalidInputError as exc:
            # one line, whatever a library message or a name inside the file contains
            msg = str(exc)
            if not msg.isprintable():
                flat = " ".join(msg.split())
                flat = "".join(c if c.isprintable() else ascii(c)[1:-1] for c in flat)
                raise type(exc)(flat) from exc
            raise
    for w in caught:
        if issubclass(w.category, RepairWarning | ConvergenceWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out


def _read_with_report(
    path: str | os.PathLike,
    *,
    kind: str | None,
    weld: bool | None,
    weld_tol: float | None,
    format: str | None,
    nan_points: str | None,
) -> tuple[Geometry, ReadReport]:
    _check_kind(kind)
    if nan_points is not None and nan_points not in NAN_POLICIES:
        raise InvalidInputError(
            f"`nan_points` must be one of {', '.join(map(repr, NAN_POLICIES))} or None; got {nan_points!r}."
        )
    p = Path(path)
    if not p.exists():
        raise InvalidInputError(f"file not found: {p}")
    if weld_tol is not None and (not np.isfinite(weld_tol) or weld_tol < 0):
        raise InvalidInputError(f"`weld_tol` must be a finite number >= 0; got {weld_tol!r}.")
    if p.is_dir():
        geom = _read_folder(p, kind=kind, weld=weld, nan_points=nan_points, format=format)
        return geom, ReadReport(n_input_vertices=_n_rows(geom))
    suffix, gz = _format_suffix(p, format)
    if suffix == ".npz":
        geom = _read_npz(p, gz, kind=kind)
        return geom, ReadReport(n_input_vertices=_n_rows(geom))
    if suffix == ".sga":
        geom = _read_sga(p, gz, kind=kind)
        return geom, ReadReport(n_input_vertices=_n_rows(geom))
    if suffix not in _READER_SPECS:
        raise _unsupported(p, suffix, [*_READER_SPECS, ".npz", ".sga"])
    if kind in ("animation", "sequence"):
        raise InvalidInputError(
            f"{p.name}: a single {suffix} file cannot be read as {kind!r}; "
            "use a .npz file or a folder of numbered frames."
        )
    raw = _read_raw(p, suffix, gz)
    if weld is None:
        weld = suffix == ".stl" or (raw.has_faces and is_soup(raw.faces, raw.vertices.shape[0]))
    return _build_with_report(
        raw, p.name, kind=kind, weld=weld, weld_tol=weld_tol, nan_points=nan_points
    )


def _n_rows(geom: Geometry) -> int:
    if isinstance(geom, Mesh | MeshAnimation):
        return geom.n_vertices
    if isinstance(geom, PointCloud):
        return geom.n_points
    return int(geom.n_points[0])


def _read_raw(p: Path, suffix: str, gz: bool) -> RawGeometry:
    data = read_bytes(p, gz)
    if not data.strip():
        raise InvalidInputError(f"{p.name}: empty file.")
    if suffix == ".gltf":  # separate buffer files are found next to the .gltf
        rg = _reader(suffix)(data, p.name, folder=p.parent)
    else:
        rg = _reader(suffix)(data, p.name)
    _check_face_range(rg, p.name)
    return rg


def _check_face_range(rg: RawGeometry, name: str) -> None:
    """Face indices within ``[0, n_vertices)``, checked before anything sizes arrays by them."""
    F = rg.faces
    if F is None or not len(F):
        return
    n = rg.vertices.shape[0]
    lo, hi = int(F.min()), int(F.max())
    if lo < 0 or hi >= n:
        raise InvalidInputError(
            f"{name}: `faces` has vertex indices out of range: expected 0..{n - 1} (the file has "
            f"{n} vertices); got {lo}..{hi}."
        )


def _drop_nonfinite(a, n: int, name: str, what: str):
    """Per-vertex normals/colours with NaN/inf rows are not kept (the geometry is): a RepairWarning
    says how many rows were bad. Returns ``a`` or None."""
    if a is None:
        return None
    a = np.asarray(a)
    if a.dtype.kind != "f" or np.isfinite(a).all():
        return a
    cnt = _nonfinite_rows(a.reshape(a.shape[0], -1)).size
    warnings.warn(
        f"{name}: {cnt} of {n} {what} are NaN or inf; the file's {what} are not read "
        "(coordinates kept).",
        RepairWarning,
        stacklevel=3,
    )
    return None


def _nonfinite_rows(a: np.ndarray) -> np.ndarray:
    return np.flatnonzero(~np.isfinite(a).all(axis=1))


def _weld(rg: RawGeometry, tol: float | None) -> tuple[RawGeometry, Weld]:
    w = weld_mesh(rg.vertices, rg.faces, tol=WELD_TOL if tol is None else tol)
    first = np.empty(w.vertices.shape[0], dtype=np.int64)
    first[w.index_map[::-1]] = np.arange(w.index_map.size - 1, -1, -1)

    def pick(a):
        return None if a is None else np.asarray(a)[first]

    return RawGeometry(
        w.vertices,
        w.faces,
        pick(rg.normals),
        pick(rg.colors),
        {k: np.asarray(v)[first] for k, v in rg.vertex_attributes.items()},
        {k: np.asarray(v)[w.face_kept] for k, v in rg.face_attributes.items()},
    ), w


def _build(
    rg: RawGeometry, name: str, *, kind: str | None, weld: bool | None, nan_points: str | None
) -> Mesh | PointCloud:
    if weld is None:
        weld = rg.has_faces and is_soup(rg.faces, rg.vertices.shape[0])
    geom, _report = _build_with_report(
        rg, name, kind=kind, weld=weld, weld_tol=None, nan_points=nan_points
    )
    return geom


def _build_with_report(
    rg: RawGeometry,
    name: str,
    *,
    kind: str | None,
    weld: bool,
    weld_tol: float | None,
    nan_points: str | None,
) -> tuple[Mesh | PointCloud, ReadReport]:
    n = rg.vertices.shape[0]
    if n == 0:
        raise InvalidInputError(f"{name}: the file contains no vertices/points.")
    as_mesh = kind == "mesh" or (kind is None and rg.has_faces)
    if kind == "mesh" and not rg.has_faces:
        raise InvalidInputError(
            f"{name}: has no faces ({n} points only); read it as a point cloud (kind='points')."
        )
    bad = _nonfinite_rows(rg.vertices)
    if as_mesh:
        if bad.size:
            raise InvalidInputError(
                f"{name}: {bad.size} vertices have NaN or inf coordinates (first at index "
                f"{int(bad[0])}); mesh vertices cannot be dropped without renumbering faces."
            )
        report = ReadReport(n_input_vertices=n)
        if weld:
            if rg.faces is None or not len(rg.faces):
                raise InvalidInputError(f"{name}: has no faces to weld.")
            try:
                rg, w = _weld(rg, weld_tol)
            except InvalidInputError as exc:
                raise InvalidInputError(f"{name}: {exc}") from exc
            if not len(rg.faces):
                raise InvalidInputError(
                    f"{name}: every face collapsed when welding coincident vertices (all "
                    f"{w.face_kept.size} faces are degenerate); read it with weld=False."
                )
            report = ReadReport(
                n_input_vertices=n,
                n_merged_vertices=w.n_merged,
                n_dropped_faces=w.n_dropped_faces,
                welded=True,
            )
        try:
            return Mesh(
                rg.vertices,
                rg.faces,
                vertex_normals=_drop_nonfinite(rg.normals, n, name, "vertex normals"),
                vertex_colors=_drop_nonfinite(rg.colors, n, name, "vertex colours"),
                vertex_attributes=rg.vertex_attributes,
                face_attributes=rg.face_attributes,
            ), report
        except InvalidInputError as exc:
            raise InvalidInputError(f"{name}: {exc}") from exc
    policy = nan_points or rg.nan_policy_default
    normals, colors, attrs = rg.normals, rg.colors, dict(rg.vertex_attributes)
    P = rg.vertices
    if bad.size:
        if policy == "raise":
            raise InvalidInputError(
                f"{name}: {bad.size} of {n} points have NaN or inf coordinates (first at index "
                f"{int(bad[0])}); pass nan_points='drop' to drop them."
            )
        keep = np.ones(n, dtype=bool)
        keep[bad] = False
        if not keep.any():
            raise InvalidInputError(f"{name}: all {n} points have NaN or inf coordinates.")
        P = P[keep]
        normals = None if normals is None else normals[keep]
        colors = None if colors is None else colors[keep]
        attrs = {k: v[keep] for k, v in attrs.items()}
        attrs.setdefault("source_index", np.flatnonzero(keep))
    # one bad normal must not cost the whole cloud: the normals are dropped, the points kept
    normals = _drop_nonfinite(normals, P.shape[0], name, "point normals")
    colors = _drop_nonfinite(colors, P.shape[0], name, "point colours")
    report = ReadReport(
        n_input_vertices=n,
        n_nonfinite_rows=int(bad.size),
        source_index=np.flatnonzero(np.isfinite(rg.vertices).all(axis=1)) if bad.size else None,
    )
    try:
        return PointCloud(P, normals, colors, attrs), report
    except InvalidInputError as exc:
        raise InvalidInputError(f"{name}: {exc}") from exc


def _keys(keys) -> str:
    """Archive member names for a message: printable, one line, at most 10 of them."""
    shown = [k if k.isprintable() else ascii(k) for k in sorted(keys)]
    return ", ".join(shown[:10]) + (f", ... ({len(shown)} in all)" if len(shown) > 10 else "")


def _npz_array(d, key: str, name: str) -> np.ndarray:
    """Array ``key`` of the archive: the member's declared size is checked against the memory cap,
    the member read (zipfile stops at the declared size and checks the CRC), then parsed by
    :func:`._simple.parse_npy`, which checks the header's shape against the bytes."""
    from ._simple import parse_npy

    zf = d.zip
    member = key if key in zf.namelist() else key + ".npy"
    try:
        info = zf.getinfo(member)
        check_alloc(info.file_size, name, f"array {key!r}")
        raw = zf.read(member)
    except InvalidInputError:
        raise
    except (
        ValueError,
        OSError,
        EOFError,
        zipfile.BadZipFile,
        zlib.error,
        KeyError,
        NotImplementedError,
        RuntimeError,
        OverflowError,
    ) as exc:
        raise InvalidInputError(f"{name}: cannot read array {key!r} ({exc_text(exc)}).") from exc
    return parse_npy(raw, f"{name}: cannot read array {key!r}")


def _read_sga(p: Path, gz: bool, *, kind: str | None) -> MeshAnimation | PointCloudSequence:
    data = read_bytes(p, gz)
    if not data:
        raise InvalidInputError(f"{p.name}: empty file.")
    from ._sgc import read_sga

    return read_sga(data, p.name, kind=kind)


def _read_npz(p: Path, gz: bool, *, kind: str | None) -> MeshAnimation | PointCloudSequence:
    data = read_bytes(p, gz)
    if not data:
        raise InvalidInputError(f"{p.name}: empty file.")
    name = p.name
    try:
        d = np.load(io.BytesIO(data), allow_pickle=False)
    except (
        ValueError,
        OSError,
        EOFError,
        zipfile.BadZipFile,
        OverflowError,
        KeyError,
        NotImplementedError,  # "zip file version 24.3", unknown compression
        RuntimeError,  # encrypted members
        zlib.error,
    ) as exc:
        why = exc_text(exc)
        if not data.startswith(b"PK") and not data.startswith(b"\x93NUMPY"):
            why = "not a zip archive of .npy arrays"  # numpy would call it pickled data
        raise InvalidInputError(f"{name}: not a valid .npz archive ({why}).") from exc
    if not isinstance(d, np.lib.npyio.NpzFile):
        raise InvalidInputError(f"{name}: not a .npz archive (a single .npy array).")
    with d:
        keys = set(d.files)
        if kind in ("mesh", "points"):
            raise InvalidInputError(
                f"{name}: a .npz file holds an animation or a sequence, not a single {kind!r}."
            )
        vkey = "vertices" if "vertices" in keys else "frames" if "frames" in keys else None
        if "faces" in keys or kind == "animation" or (vkey is not None and "points" not in keys):
            if "faces" not in keys and kind != "sequence":
                raise InvalidInputError(
                    f"{name}: animation .npz lacks key 'faces' (has {_keys(keys)})."
                )
            if vkey is None:
                raise InvalidInputError(
                    f"{name}: animation .npz lacks key 'vertices' (has {_keys(keys)})."
                )
            frames = _npz_array(d, vkey, name)
            _check_frames(frames, name, vkey)
            if kind == "sequence":
                return PointCloudSequence([PointCloud(f) for f in frames.astype(np.float64)])
            faces = _npz_array(d, "faces", name)
            if faces.ndim != 2 or faces.shape[1] != 3:
                raise InvalidInputError(
                    f"{name}: 'faces' must have shape (m, 3); got {faces.shape}."
                )
            if faces.dtype.kind not in "iu":
                raise InvalidInputError(f"{name}: 'faces' must hold integers; got {faces.dtype}.")
            try:
                return MeshAnimation(frames, faces)
            except InvalidInputError as exc:
                raise InvalidInputError(f"{name}: {exc}") from exc
        if "points" in keys:
            pts = _npz_array(d, "points", name)
            if pts.ndim == 3:
                _check_frames(pts, name, "points")
                return PointCloudSequence([PointCloud(f) for f in pts.astype(np.float64)])
            if pts.ndim == 2 and "counts" in keys:
                counts = _npz_array(d, "counts", name)
                if (
                    counts.ndim != 1
                    or counts.dtype.kind not in "iu"
                    or (counts <= 0).any()
                    or counts.sum() != pts.shape[0]
                    or pts.shape[1] != 3
                ):
                    raise InvalidInputError(
                        f"{name}: 'counts' must be positive integers summing to the {pts.shape[0]} "
                        f"rows of 'points' (n, 3); got counts {counts.shape} summing to "
                        f"{int(counts.sum()) if counts.dtype.kind in 'iu' else '?'}, points {pts.shape}."
                    )
                _check_frames(pts[None], name, "points")
                parts = np.split(pts.astype(np.float64), np.cumsum(counts)[:-1])
                return PointCloudSequence([PointCloud(f) for f in parts])
            raise InvalidInputError(
                f"{name}: 'points' must have shape (T, n, 3), or (N, 3) with 'counts' (T,); got {pts.shape}."
            )
        raise InvalidInputError(
            f"{name}: .npz has keys {_keys(keys) or '(none)'}; expected 'vertices' and "
            "'faces' (animation) or 'points' [+ 'counts'] (sequence)."
        )


def _check_frames(frames: np.ndarray, name: str, key: str) -> None:
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise InvalidInputError(f"{name}: {key!r} must have shape (T, n, 3); got {frames.shape}.")
    if frames.dtype.kind not in "iuf":
        raise InvalidInputError(f"{name}: {key!r} must be numeric; got {frames.dtype}.")
    if frames.shape[0] == 0 or frames.shape[1] == 0:
        raise InvalidInputError(f"{name}: {key!r} is empty; got shape {frames.shape}.")
    if frames.dtype.kind == "f":
        finite = np.isfinite(frames).all(axis=2)
        if not finite.all():
            t, i = np.argwhere(~finite)[0]
            raise InvalidInputError(
                f"{name}: {int((~finite).sum())} vertex positions have NaN or inf coordinates "
                f"(first at frame {t}, vertex {i})."
            )


def _frame_files(folder: Path, format: str | None) -> list[Path]:
    files = []
    for f in folder.iterdir():
        if not f.is_file() or f.name.startswith("."):
            continue
        if _format_suffix(f, format)[0] in _READER_SPECS:
            files.append(f)
    if not files:
        others = sorted(
            f.name for f in folder.iterdir() if not f.name.startswith(".") and f.is_file()
        )
        npz = [n for n in others if n.lower().endswith((".npz", ".npz.gz"))]
        hint = (
            f"; it holds {len(npz)} .npz file(s) ({', '.join(npz[:3])}{', ...' if len(npz) > 3 else ''}): "
            "pass one of them"
            if npz
            else f"; it holds {len(others)} other file(s)"
            if others
            else "; it is empty"
        )
        raise InvalidInputError(
            f"{folder}: a folder is read as an animation or sequence of numbered frame files "
            f"({', '.join(_READER_SPECS)}), and this one has none{hint}."
        )
    kinds = sorted({_format_suffix(f, format)[0] for f in files})
    if len(kinds) > 1:
        raise InvalidInputError(
            f"{folder}: folder mixes frame formats ({', '.join(kinds)}); keep one format per sequence."
        )
    return sorted(files, key=lambda f: natural_key(f.name))


def _read_folder(
    folder: Path, *, kind: str | None, weld: bool, nan_points: str | None, format: str | None
) -> MeshAnimation | PointCloudSequence:
    if kind in ("mesh", "points"):
        raise InvalidInputError(
            f"{folder}: a folder holds an animation or a sequence, not a single {kind!r}."
        )
    files = _frame_files(folder, format)
    raws = []
    for f in files:
        suffix, gz = _format_suffix(f, format)
        raws.append((f, _read_raw(f, suffix, gz)))
    with_faces = [rg.has_faces for _, rg in raws]
    if kind is None:
        if all(with_faces):
            kind = "animation"
        elif not any(with_faces):
            kind = "sequence"
        else:
            first = raws[with_faces.index(False)][0].name
            raise InvalidInputError(
                f"{folder}: some frames have faces and others not (e.g. {first}); "
                "read it with kind='sequence' to get point clouds."
            )
    if kind == "sequence":
        return PointCloudSequence(
            [_build(rg, f.name, kind="points", weld=False, nan_points=nan_points) for f, rg in raws]
        )
    meshes = [_build(rg, f.name, kind="mesh", weld=weld, nan_points=None) for f, rg in raws]
    ref, ref_name = meshes[0], files[0].name
    for f, m in zip(files[1:], meshes[1:]):
        if m.n_vertices != ref.n_vertices:
            raise InvalidInputError(
                f"{f.name}: {m.n_vertices} vertices, but {ref_name} has {ref.n_vertices}; "
                "animation frames must share one connectivity."
            )
        if m.faces.shape != ref.faces.shape or not np.array_equal(m.faces, ref.faces):
            raise InvalidInputError(
                f"{f.name}: faces differ from those of {ref_name}; animation frames must share "
                "one connectivity (use kind='sequence' to read them as point clouds)."
            )
    return MeshAnimation(np.stack([m.vertices for m in meshes]), ref.faces)


def read_mesh(path: str | os.PathLike, **kw: Any) -> Mesh:
    """Read a triangle mesh (error when the file has no faces). Options as in :func:`read`."""
    return read(path, kind="mesh", **kw)


def read_point_cloud(path: str | os.PathLike, **kw: Any) -> PointCloud:
    """Read a point cloud; a mesh file gives its vertices with normals, colours and attributes."""
    return read(path, kind="points", **kw)


def read_animation(path: str | os.PathLike, **kw: Any) -> MeshAnimation:
    """Read a mesh animation from a ``.npz`` (``vertices`` (T, n, 3), ``faces`` (m, 3)) or a folder."""
    return read(path, kind="animation", **kw)


def read_sequence(path: str | os.PathLike, **kw: Any) -> PointCloudSequence:
    """Read a point-cloud sequence from a folder of frames or a ``.npz`` (``points``...)."""
    return read(path, kind="sequence", **kw)


# ------------------------------------------------------------------------------------- writing
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
        Target. Mesh: ``.ply .obj .off .stl``; PointCloud: ``.ply .pcd .xyz .npy .las .laz .obj .off``;
        both optionally ``.gz``-compressed (``mesh.ply.gz``). MeshAnimation / PointCloudSequence:
        ``.npz`` or a folder (a path without suffix, ending with ``/``, or an existing folder) that
        receives numbered frames ``frame_000.ply, frame_001.ply, ...``.
    obj : Mesh | PointCloud | MeshAnimation | PointCloudSequence | list[PointCloud] | (n, 3) array
    binary : bool
        Binary PLY/STL/PCD (default) or ascii. Text formats (OBJ, OFF, XYZ) ignore it.
    **kw
        Format options (any other name is an error):

        ``pcd_format`` : {"ascii", "binary", "binary_compressed"}, optional
            PCD encoding; default ``"binary"`` (``"ascii"`` when ``binary=False``).
        ``dtype`` : numpy float dtype, optional
            Coordinate type for PLY (default float64, lossless) and PCD. PCD default (None): float32,
            PCL's usual type, when every coordinate survives the float32 round trip exactly
            (``np.array_equal(P.astype(np.float32).astype(np.float64), P)``), else float64, so that
            georeferenced clouds are not altered (float32 moves UTM coordinates such as
            x=512345.678 by up to 3 cm, northings near 5.4e6 by up to 0.25 m); PCD normals are float32
            unless ``dtype`` is given. An explicit ``dtype`` is always obeyed.
        ``las_scale`` : float, optional
            LAS/LAZ coordinate resolution (default: chosen from the extent of the points).
        ``frame_format`` : str, optional
            Frame file format of folder outputs (default ``".ply"``; e.g. ``".obj"``, ``".pcd"``,
            ``".ply.gz"``).
        ``prefix`` : str, optional
            Frame file name prefix of folder outputs (default ``"frame_"``).
        ``compress`` : bool, optional
            ``.npz`` outputs: zip-deflate the arrays (default False).

    Notes
    -----
    PLY keeps vertex normals, colours and vertex/face attributes ((n,) scalars or (n, k) fixed-length
    lists; a (m, 6) face attribute ``texcoord`` is written as MeshLab's ``property list uchar float
    texcoord``); PCD keeps normals, colours and attributes; OBJ keeps vertex normals and the per-corner
    face attributes ``texcoord`` (m, 6) and ``corner_normals`` (m, 9) as deduplicated ``vt``/``vn``
    lines with ``f v/vt/vn`` corners; OFF, STL, XYZ (normals kept), NPY and LAS (colours, normals and
    attributes kept) store what the format can hold.
    Writing a folder stages the frames in a temporary folder; frames named ``<prefix><number>.*``
    left in an existing target folder from an earlier, longer sequence are removed.
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
        if suffix in (".sga", ".sgc"):
            from ._sgc import WRITE_ADVICE

            raise UnsupportedFormatError(f"{p.name}: {WRITE_ADVICE}")
        if suffix != ".npz":
            raise _unsupported(p, suffix, [".npz", "<folder>/"])
        _write_npz(p, geom, gz=gz, compress=bool(kw.get("compress", False)))
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
    if suffix in (".sgc", ".sga"):
        from ._sgc import WRITE_ADVICE

        raise UnsupportedFormatError(f"{p.name}: {WRITE_ADVICE}")
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


def _write_npz(
    p: Path, geom: MeshAnimation | PointCloudSequence, *, gz: bool, compress: bool
) -> None:
    buf = io.BytesIO()
    save = np.savez_compressed if compress else np.savez
    if isinstance(geom, MeshAnimation):
        save(buf, vertices=geom.frames, faces=geom.faces)
    elif geom.is_fixed_size():
        save(buf, points=geom.as_array())
    else:
        save(
            buf,
            points=np.concatenate([f.points for f in geom.frames]),
            counts=np.asarray(geom.n_points, dtype=np.int64),
        )
    write_bytes(p, buf.getvalue(), gz)


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
        if split_suffix(f)[0] in _READER_SPECS:
            f.unlink()


__all__ = [
    "atomic_write",
    "read",
    "read_animation",
    "read_mesh",
    "read_point_cloud",
    "read_sequence",
    "read_with_report",
    "ReadReport",
    "supported_formats",
    "write",
]
