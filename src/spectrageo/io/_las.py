"""LAS / LAZ point clouds through :mod:`laspy` (LAZ needs the ``lazrs`` backend); optional extra.

Reading: scaled ``x y z`` -> points (float64); ``red green blue`` -> uint8 colours (LAS stores 16-bit
channels; values above 255 are taken as 16-bit and shifted by 8 bits, otherwise the file holds 8-bit
values in 16-bit fields, as many do, and they are kept); extra-bytes dimensions ``normal_x normal_y
normal_z`` -> normals; the standard dimensions ``intensity, return_number, number_of_returns,
classification, scan_angle_rank / scan_angle, user_data, point_source_id, gps_time`` (when the point
format has them) and every other extra-bytes dimension -> attributes.

Writing: LAS 1.2, point format 0 / 1 (with ``gps_time``) / 2 / 3 (with colours). Coordinates are
stored as int32 with offset = minimum and a power-of-ten scale chosen so that the extent fits
(resolution ``scale`` = 10**ceil(log10(extent / 2e9)), e.g. 1e-9 for a unit-size cloud), or the
``las_scale`` given. Colours are written 16-bit (8-bit value x 257). Normals and attributes that are
not standard dimensions go to extra-bytes dimensions ((n, k) attributes as ``name_0 ... name_k-1``).
"""

from __future__ import annotations

import io

import numpy as np

from .._errors import InvalidInputError, UnsupportedFormatError
from ._common import exc_text
from ._raw import RawGeometry

_STANDARD = (
    "intensity",
    "return_number",
    "number_of_returns",
    "classification",
    "scan_angle_rank",
    "scan_angle",
    "user_data",
    "point_source_id",
    "gps_time",
)


def _laspy(compressed: bool):
    try:
        import laspy
    except ImportError as exc:
        raise UnsupportedFormatError(
            "LAS/LAZ support needs the optional dependency laspy "
            "(pip install 'spectrageo[las]', which also installs lazrs for .laz)."
        ) from exc
    if compressed and not laspy.LazBackend.detect_available():
        raise UnsupportedFormatError(
            "LAZ support needs a LAZ backend for laspy: pip install lazrs (or 'spectrageo[las]')."
        )
    return laspy


def read_las(raw: bytes, name: str, *, compressed: bool) -> RawGeometry:
    laspy = _laspy(compressed)
    try:
        las = laspy.read(io.BytesIO(raw))
    except (laspy.errors.LaspyException, ValueError, OSError, EOFError, RuntimeError) as exc:
        raise InvalidInputError(
            f"{name}: malformed or truncated LAS/LAZ ({exc_text(exc)})."
        ) from exc
    V = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1).astype(
        np.float64
    )
    dims = set(las.point_format.dimension_names)
    colors = None
    if {"red", "green", "blue"} <= dims:
        c = np.stack([np.asarray(las[k]) for k in ("red", "green", "blue")], axis=1)
        if c.size and c.max() > 255:
            c = c >> 8
        colors = c.astype(np.uint8)
    extra = list(las.point_format.extra_dimension_names)
    normals = None
    if all(k in extra for k in ("normal_x", "normal_y", "normal_z")):
        normals = np.stack(
            [np.asarray(las[k], dtype=np.float64) for k in ("normal_x", "normal_y", "normal_z")],
            axis=1,
        )
        extra = [k for k in extra if k not in ("normal_x", "normal_y", "normal_z")]
    attrs: dict[str, np.ndarray] = {}
    for k in _STANDARD:
        if k in dims:
            attrs[k] = np.array(las[k])
    for k in extra:
        attrs[k] = np.array(las[k])
    return RawGeometry(V, None, normals, colors, attrs, {})


def _scale(P: np.ndarray, las_scale: float | None) -> np.ndarray:
    if las_scale is not None:
        s = float(las_scale)
        if not np.isfinite(s) or s <= 0:
            raise InvalidInputError(f"`las_scale` must be a positive number; got {las_scale!r}.")
        return np.full(3, s)
    extent = float(np.ptp(P, axis=0).max()) if P.size else 0.0
    extent = max(extent, 1e-12)
    return np.full(3, 10.0 ** np.ceil(np.log10(extent / 2e9)))


def write_las(
    P: np.ndarray,
    *,
    normals=None,
    colors=None,
    attributes=None,
    compressed: bool,
    las_scale: float | None = None,
) -> bytes:
    laspy = _laspy(compressed)
    attributes = dict(attributes or {})
    has_gps = "gps_time" in attributes
    fmt = (3 if has_gps else 2) if colors is not None else (1 if has_gps else 0)
    header = laspy.LasHeader(point_format=fmt, version="1.2")
    scale = _scale(P, las_scale)
    offset = np.floor(P.min(axis=0) / scale) * scale if P.size else np.zeros(3)
    span = (P.max(axis=0) - offset) / scale if P.size else np.zeros(3)
    if (span > 2**31 - 1).any():
        raise InvalidInputError(
            f"`las_scale` {scale[0]:g} is too fine for the extent of the cloud (int32 overflow)."
        )
    header.offsets = offset
    header.scales = scale
    std_dims = set(laspy.PointFormat(fmt).dimension_names)
    extras: list[tuple[str, np.ndarray]] = []
    if normals is not None:
        nrm = np.asarray(normals, dtype=np.float64)
        extras += [(k, nrm[:, i]) for i, k in enumerate(("normal_x", "normal_y", "normal_z"))]
    standard: list[tuple[str, np.ndarray]] = []
    flat: list[tuple[str, np.ndarray]] = []
    for k, a in attributes.items():
        a = np.asarray(a)
        if a.ndim == 2:  # one extra-bytes dimension per column: name_0, name_1, ...
            flat.extend((f"{k}_{j}", a[:, j]) for j in range(a.shape[1]))
        elif a.ndim == 1:
            flat.append((k, a))
        else:
            raise InvalidInputError(
                f"attribute `{k}` has shape {a.shape}; LAS stores (n,) or (n, k) attributes."
            )
    for k, a in flat:
        if a.dtype.kind not in "biuf":
            raise InvalidInputError(f"attribute `{k}` has dtype {a.dtype}; LAS stores numbers.")
        if k in std_dims and k not in ("X", "Y", "Z", "red", "green", "blue"):
            standard.append((k, a))
        elif k.lower() in {d.lower() for d in std_dims}:
            raise InvalidInputError(f"attribute name `{k}` clashes with a LAS dimension.")
        else:
            extras.append((k, a.astype(np.uint8) if a.dtype == np.bool_ else a))
    if extras:
        header.add_extra_dims(
            [laspy.ExtraBytesParams(name=k, type=a.dtype.newbyteorder("=")) for k, a in extras]
        )
    las = laspy.LasData(header)
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    if colors is not None:
        c = np.asarray(colors)
        if c.dtype.kind == "f":
            c16 = np.clip(np.round(c[:, :3] * 65535.0), 0, 65535).astype(np.uint16)
        else:
            c16 = c[:, :3].astype(np.uint16) * 257
        las.red, las.green, las.blue = c16[:, 0], c16[:, 1], c16[:, 2]
    try:
        for k, a in standard:
            las[k] = a
        for k, a in extras:
            las[k] = a
    except (ValueError, TypeError, OverflowError) as exc:
        raise InvalidInputError(f"cannot store attributes in LAS ({exc_text(exc)}).") from exc
    for k, a in standard:
        if not np.array_equal(np.asarray(las[k]).astype(np.float64), a.astype(np.float64)):
            raise InvalidInputError(
                f"attribute `{k}` cannot be stored exactly in the LAS dimension of that name "
                "(non-integer or out-of-range values)."
            )
    buf = io.BytesIO()
    try:
        las.write(buf, do_compress=compressed)
    except (laspy.errors.LaspyException, ValueError, OverflowError) as exc:
        raise InvalidInputError(f"cannot write LAS/LAZ ({exc_text(exc)}).") from exc
    return buf.getvalue()
