"""Reading: :func:`read` and its variants, turning a file's raw arrays into geometry."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import ConvergenceWarning, InvalidInputError, RepairWarning
from ..geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from ..geometry.repair import WELD_TOL, Weld, is_soup
from ..geometry.repair import weld as weld_mesh
from ._api import (
    Geometry,
    _format_suffix,
    _read_raw,
    _unsupported,
    is_single,
    single_suffixes,
    whole_reader,
    whole_suffixes,
)
from ._common import natural_key, read_bytes
from ._npz import read_npz
from ._raw import RawGeometry

KINDS = ("mesh", "points", "animation", "sequence")
NAN_POLICIES = ("raise", "drop")


def _check_kind(kind: str | None) -> None:
    if kind is not None and kind not in KINDS:
        raise InvalidInputError(
            f"`kind` must be one of {', '.join(map(repr, KINDS))} or None; got {kind!r}."
        )


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
        A file (``.ply .obj .off .stl .pcd .xyz .pts .npy .las .laz .glb .gltf .3mf``, each
        optionally ``.gz``), a ``.npz`` animation/sequence, a compressed mesh (``.sgc``) or
        animation (``.sga``) of :mod:`spectrageo.compress` (decoded whole; a cut file is an error),
        or a folder of numbered frame files.
    kind : {"mesh", "points", "animation", "sequence"} or None
        Force the interpretation. None: a file with faces gives a :class:`Mesh`, without faces a
        :class:`PointCloud`; ``.npz`` with ``faces`` a :class:`MeshAnimation`, with ``points`` a
        :class:`PointCloudSequence`; a folder an animation when every frame has faces, else a
        sequence. ``"points"`` reads a mesh's vertices (with their data) as a point cloud;
        ``"sequence"`` an animation's frames as point clouds.
    weld : bool or None
        Merge coincident vertices of a mesh (within ``weld_tol`` times the bounding-box diagonal,
        keeping the first of each group and dropping collapsed faces). None (default): weld
        triangle soups only (STL files, meshes whose faces share no vertex); every other mesh keeps
        its vertex order and count exactly (see :func:`spectrageo.geometry.weld`).
    weld_tol : float, optional
        Relative weld tolerance; default :data:`spectrageo.geometry.WELD_TOL` (1e-6).
    format : str, optional
        Format to use instead of the one the extension implies (``"xyz"``, ``"ply.gz"``...).
    nan_points : {"raise", "drop"} or None
        Points with NaN/inf coordinates. None: ``"drop"`` for PCD (the kept points' indices go to
        the attribute ``source_index``), ``"raise"`` elsewhere; mesh vertices are never dropped.
        Normals or colours with NaN/inf rows are not read (a :class:`~spectrageo.RepairWarning`
        gives the count).

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
    Apart from welding soups, readers never repair: degenerate faces, duplicate and unreferenced
    vertices are kept (see :func:`spectrageo.geometry.clean_mesh`).
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

    Warnings of the libraries underneath are silenced while reading; spectrageo's own
    :class:`~spectrageo.RepairWarning` s are emitted after a successful read only, so a failed read
    reports one error and nothing else.
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
        geom = read_npz(p, gz, kind=kind)
        return geom, ReadReport(n_input_vertices=_n_rows(geom))
    whole = whole_reader(suffix)
    if whole is not None:
        geom = _read_whole(p, gz, whole, kind=kind)
        return geom, ReadReport(n_input_vertices=_n_rows(geom))
    if not is_single(suffix):
        raise _unsupported(p, suffix, [*single_suffixes(), ".npz", *whole_suffixes()])
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


def _read_whole(
    p: Path, gz: bool, reader, *, kind: str | None
) -> MeshAnimation | PointCloudSequence:
    data = read_bytes(p, gz)
    if not data:
        raise InvalidInputError(f"{p.name}: empty file.")
    return reader(data, p.name, kind=kind)


def _frame_files(folder: Path, format: str | None) -> list[Path]:
    files = []
    for f in folder.iterdir():
        if not f.is_file() or f.name.startswith("."):
            continue
        if is_single(_format_suffix(f, format)[0]):
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
            f"({', '.join(single_suffixes())}), and this one has none{hint}."
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
