"""Small formats: XYZ text, ``.npy`` point arrays and STL (through trimesh)."""

from __future__ import annotations

import io
import warnings

import numpy as np

from .._errors import InvalidInputError
from ._common import exc_text
from ._raw import RawGeometry


# ------------------------------------------------------------------------------------------ XYZ
def read_xyz(raw: bytes, name: str) -> RawGeometry:
    """Whitespace-separated text, ``#`` comments; 3 columns (x y z) or 6 (x y z nx ny nz)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            table = np.loadtxt(io.BytesIO(raw), dtype=np.float64, ndmin=2, comments="#")
    except ValueError as exc:
        raise InvalidInputError(f"{name}: malformed XYZ text ({exc_text(exc)}).") from exc
    if table.size == 0:
        raise InvalidInputError(f"{name}: XYZ file holds no points.")
    if table.shape[1] not in (3, 6):
        raise InvalidInputError(
            f"{name}: XYZ rows must have 3 (x y z) or 6 (x y z nx ny nz) values; got {table.shape[1]}."
        )
    normals = table[:, 3:6] if table.shape[1] == 6 else None
    return RawGeometry(table[:, :3].copy(), None, normals)


def write_xyz(P: np.ndarray, normals=None) -> bytes:
    table = P if normals is None else np.hstack([P, np.asarray(normals, dtype=np.float64)])
    buf = io.BytesIO()
    np.savetxt(buf, table, fmt="%.17g", delimiter=" ")
    return buf.getvalue()


# ------------------------------------------------------------------------------------------ NPY
def read_npy(raw: bytes, name: str) -> RawGeometry:
    """A (n, 3) numeric array saved with :func:`numpy.save` (pickles are refused)."""
    try:
        arr = np.load(io.BytesIO(raw), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise InvalidInputError(f"{name}: not a valid .npy array ({exc_text(exc)}).") from exc
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "iuf":
        raise InvalidInputError(
            f"{name}: .npy must hold a numeric (n, 3) array; got dtype {getattr(arr, 'dtype', type(arr))}."
        )
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidInputError(
            f"{name}: .npy point arrays must have shape (n, 3); got {arr.shape} "
            "(sequences go in a .npz file or a folder of frames)."
        )
    return RawGeometry(arr.astype(np.float64))


def write_npy(P: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(P, dtype=np.float64), allow_pickle=False)
    return buf.getvalue()


# ------------------------------------------------------------------------------------------ STL
def read_stl(raw: bytes, name: str) -> RawGeometry:
    """Binary or ascii STL through :func:`trimesh.exchange.stl.load_stl`.

    Every triangle keeps its own three corners (3 m vertices, faces ``[[0,1,2],[3,4,5],...]``), in file
    order; the public reader merges coincident corners only when asked (``weld=True``). Multiple
    ``solid`` blocks of an ascii file are concatenated in file order.
    """
    from trimesh.exchange import stl

    is_binary = len(raw) >= 84 and 84 + 50 * int(np.frombuffer(raw, "<u4", 1, 80)[0]) == len(raw)
    if not is_binary:
        try:
            text_ok = raw[:5].lower() == b"solid" and raw.decode("ascii") is not None
        except UnicodeDecodeError:
            text_ok = False
        if not text_ok:
            raise InvalidInputError(
                f"{name}: not a valid STL file (neither a binary STL whose size matches its "
                "triangle count nor ascii 'solid' text; truncated or not STL)."
            )
    try:
        d = stl.load_stl_binary(io.BytesIO(raw)) if is_binary else stl.load_stl(io.BytesIO(raw))
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types (even ImportError) on garbage
        raise InvalidInputError(f"{name}: malformed or truncated STL ({exc_text(exc)}).") from exc
    parts = list(d["geometry"].values()) if "geometry" in d else [d]
    parts = [p for p in parts if isinstance(p, dict) and "vertices" in p and len(p["vertices"])]
    if not parts:
        raise InvalidInputError(
            f"{name}: not a valid STL file (no triangles found; truncated or not STL)."
        )
    V = np.concatenate([np.asarray(p["vertices"], dtype=np.float64).reshape(-1, 3) for p in parts])
    F = np.arange(V.shape[0], dtype=np.int64).reshape(-1, 3)
    return RawGeometry(V, F)


def write_stl(V: np.ndarray, F: np.ndarray, *, binary: bool) -> bytes:
    import trimesh
    from trimesh.exchange import stl

    tm = trimesh.Trimesh(vertices=V, faces=F, process=False, validate=False)
    if binary:
        return stl.export_stl(tm)
    return stl.export_stl_ascii(tm).encode("ascii")
