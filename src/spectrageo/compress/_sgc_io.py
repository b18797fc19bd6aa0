"""Compressed files as inputs of :mod:`spectrageo.io`: ``.sgc`` meshes and ``.sga`` animations.

:func:`register` is the ``spectrageo.formats`` entry point: io's format registry calls it the
first time it meets an extension it does not know, so ``io`` never imports this package.
Reading decodes the whole file; a file that was cut short is an error here
(``spectrageo decompress --partial`` decodes the complete part on purpose). Writing is not a
format conversion: the codecs are lossy and take a rate, so :func:`spectrageo.io.write` refuses
these extensions with :data:`WRITE_ADVICE`.
"""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from ..geometry.data import MeshAnimation, PointCloud, PointCloudSequence
from ..io import register_format
from ..io._raw import RawGeometry
from . import _sga, decode, decode_animation, info, info_animation
from ._container import check_memory

#: advice given when a .sgc / .sga output is asked of :func:`spectrageo.io.write`
WRITE_ADVICE = (
    "a compressed file is written by `spectrageo compress` (Python: spectrageo.compress.encode "
    "or encode_animation), which takes a method and a rate (--bpv / --error); mesh formats: "
    ".ply, .obj, .off, .stl; animations: .npz or a folder."
)


def register() -> None:
    """Register the ``.sgc`` and ``.sga`` readers with :func:`spectrageo.io.register_format`."""
    register_format(".sgc", read_sgc, write_advice=WRITE_ADVICE)
    register_format(".sga", read_sga, whole=True, write_advice=WRITE_ADVICE)


def _named(exc: InvalidInputError, name: str) -> InvalidInputError:
    text = str(exc)
    if "truncated" in text and "header" not in text and "--partial" not in text:
        text += " `spectrageo decompress --partial` decodes the complete part of a cut file."
    return InvalidInputError(f"{name}: {text}")


def read_sgc(data: bytes, name: str) -> RawGeometry:
    """A ``.sgc`` mesh, decoded (vertex and face order as coded)."""
    try:
        head = info(data)
    except InvalidInputError as exc:
        raise _named(exc, name) from exc
    check_memory(str(head["method"]), int(head["n_vertices"]), int(head["n_faces"]), name)
    try:
        V, F = decode(data)
    except InvalidInputError as exc:
        raise _named(exc, name) from exc
    return RawGeometry(vertices=np.asarray(V, np.float64), faces=np.asarray(F, np.int64))


def read_sga(data: bytes, name: str, *, kind: str | None) -> MeshAnimation | PointCloudSequence:
    """A ``.sga`` animation, decoded: a :class:`MeshAnimation`, or its frames as point clouds
    with ``kind="sequence"``."""
    if kind in ("mesh", "points"):
        raise InvalidInputError(f"{name}: a .sga file holds an animation, not a single {kind!r}.")
    _sga.check_memory(data, name)
    try:
        head = info_animation(data)
    except InvalidInputError as exc:
        raise _named(exc, name) from exc
    t, n, m = int(head["n_frames"]), int(head["n_vertices"]), int(head["n_faces"])
    check_memory(str(head["method"]), n, m, name, max(t, 1))
    try:
        frames, F = decode_animation(data)
    except InvalidInputError as exc:
        raise _named(exc, name) from exc
    frames = np.asarray(frames, np.float64)
    if kind == "sequence":
        return PointCloudSequence([PointCloud(f) for f in frames])
    return MeshAnimation(frames, np.asarray(F, np.int64))
