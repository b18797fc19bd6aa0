"""The format registry: which reader and which writer serve a file extension.

Built-in modules are imported on first use (reading a PLY never imports laspy). Higher layers
register their formats with :func:`register_format` through the entry points
``spectrageo.formats``, loaded when an extension is not found here, so ``io`` never imports them.
"""

from __future__ import annotations

import functools
import importlib
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._errors import InvalidInputError, UnsupportedFormatError
from .._plugins import load_plugins
from ..geometry.data import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from ._common import read_bytes, split_suffix
from ._raw import RawGeometry

Geometry = Mesh | PointCloud | MeshAnimation | PointCloudSequence

_GROUP = "spectrageo.formats"
_LOCK = threading.RLock()  # a second thread waits until the plugins have registered

#: extension -> (module of this package, reader function, extra keyword arguments)
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
    ".3mf": ("_3mf", "read_3mf", {}),
}

#: extension -> (reader, whole) registered by plugins (:func:`register_format`)
_PLUGINS: dict[str, tuple[Callable[..., Any], bool]] = {}
#: extension -> message given when writing a read-only plugin format is asked
_WRITE_ADVICE: dict[str, str] = {}

_MESH_WRITE = (".ply", ".obj", ".off", ".stl")
_POINTS_WRITE = (".ply", ".pcd", ".xyz", ".npy", ".las", ".laz", ".obj", ".off")


def register_format(
    suffix: str,
    reader: Callable[..., Any],
    *,
    whole: bool = False,
    write_advice: str | None = None,
) -> None:
    """Register the reader of a file extension (the hook of ``spectrageo.formats`` plugins).

    Parameters
    ----------
    suffix : str
        Lower-case extension with its dot, e.g. ``".sgc"``; not a built-in one.
    reader : callable
        ``reader(data, name)`` returning the file's ``RawGeometry`` (:mod:`spectrageo.io._raw`);
        with ``whole=True``, ``reader(data, name, *, kind)`` returning a ``MeshAnimation`` or
        ``PointCloudSequence``. ``data`` is the file's bytes (gzip inflated), ``name`` its name.
    whole : bool
        The format holds a whole animation or sequence.
    write_advice : str, optional
        Message of the :class:`~spectrageo.UnsupportedFormatError` that :func:`write` raises for
        this read-only extension.

    Raises
    ------
    InvalidInputError
        If ``suffix`` is not a lower-case extension or is built in.
    """
    if not (isinstance(suffix, str) and suffix.startswith(".") and suffix == suffix.lower()):
        raise InvalidInputError(
            f"`suffix` must be a lower-case extension such as '.sgc'; got {suffix!r}."
        )
    if suffix in _READER_SPECS or suffix == ".npz":
        raise InvalidInputError(f"{suffix!r} is a built-in format of spectrageo.io.")
    _PLUGINS[suffix] = (reader, bool(whole))
    if write_advice is not None:
        _WRITE_ADVICE[suffix] = str(write_advice)


def _load() -> None:
    with _LOCK:
        load_plugins(_GROUP)


def _plugin(suffix: str) -> tuple[Callable[..., Any], bool] | None:
    """The plugin reader of ``suffix``; plugins are loaded when the extension is not known."""
    if suffix not in _PLUGINS and suffix not in _READER_SPECS and suffix != ".npz":
        _load()
    return _PLUGINS.get(suffix)


def single_suffixes() -> list[str]:
    """Extensions of single meshes or point clouds, built-in ones first."""
    _load()
    return [*_READER_SPECS, *(s for s, (_r, whole) in _PLUGINS.items() if not whole)]


def whole_suffixes() -> list[str]:
    """Extensions of plugin formats that hold a whole animation or sequence."""
    _load()
    return [s for s, (_r, whole) in _PLUGINS.items() if whole]


def is_single(suffix: str) -> bool:
    """Whether ``suffix`` is read as one mesh or point cloud (a frame of a folder)."""
    if suffix in _READER_SPECS:
        return True
    found = _plugin(suffix)
    return found is not None and not found[1]


def whole_reader(suffix: str) -> Callable[..., Any] | None:
    """The reader of a plugin format holding a whole animation or sequence, or None."""
    found = _plugin(suffix)
    return found[0] if found is not None and found[1] else None


def write_advice(suffix: str) -> str | None:
    """The message for writing a read-only plugin format, or None."""
    _plugin(suffix)
    return _WRITE_ADVICE.get(suffix)


def _reader(suffix: str) -> Callable[[bytes, str], RawGeometry]:
    if suffix not in _READER_SPECS:
        return _PLUGINS[suffix][0]
    module, func, kwargs = _READER_SPECS[suffix]
    fn = getattr(importlib.import_module(f"{__package__}.{module}"), func)
    return functools.partial(fn, **kwargs) if kwargs else fn


def supported_formats() -> dict[str, Any]:
    """Extensions spectrageo reads and writes.

    Returns
    -------
    dict
        ``"read"``: single-file extensions (each also ``.gz``), ``".npz"``, plugin animation
        formats (``".sga"``) and ``"<folder>/"``; ``"write"``: extensions per object type
        (``"mesh"``, ``"points"``, ``"animation"``, ``"sequence"``); ``"compression"``: ``[".gz"]``.
    """
    return {
        "read": [*single_suffixes(), ".npz", *whole_suffixes(), "<folder>/"],
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


def _format_suffix(p: Path, format: str | None) -> tuple[str, bool]:
    suffix, gz = split_suffix(p)
    if format is not None:
        f = str(format).lower().strip()
        gz = gz or f.endswith(".gz")
        f = f.removesuffix(".gz")
        suffix = f if f.startswith(".") else "." + f
    return suffix, gz


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
