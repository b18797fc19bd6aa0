"""``spectrageo complete``: missing vertices of meshes, animations and point-cloud sequences, and
hole filling (thesis Section 5.3).

- ``spectrageo complete IN OUT --known KNOWN.npy [--method mc|li|lsm]`` (meshes; the unknown rows
  of IN may hold anything, NaN included);
- ``spectrageo complete IN OUT --fill-holes [--method lsm|li|mc] [--max-hole N] [--density D]``
  (meshes with holes; ``lsm`` by default, see :func:`spectrageo.complete.fill_holes`);
- ``spectrageo complete IN.npz OUT.npz --known KNOWN.npy [--method motion|li|lia|mc|gmc]
  [--sweeps N]``
  (animations with ``vertices`` + ``faces``; point-cloud sequences with ``points`` (T, n, 3), where
  ``motion`` is Algorithm 13's WRLI).

``KNOWN.npy``: a boolean mask (n,) -- or (T, n) for animations -- or an integer index list.
OUT keeps the vertex order; known vertices are written unchanged. Writes are atomic.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError

MESH_METHODS = ("mc", "li", "lsm")
ANIM_METHODS = ("motion", "li", "lia", "mc", "gmc")


def _status(msg: str) -> None:
    from . import commands

    if not commands.QUIET:
        print(msg, file=sys.stderr, flush=True)


def _load_known(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"`--known`: file not found: {path}")
    try:
        arr = np.load(p, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise InvalidInputError(f"`--known`: {p.name} is not a .npy array ({exc}).") from exc
    if not isinstance(arr, np.ndarray):
        raise InvalidInputError(f"`--known`: {p.name} must hold one array, not an archive.")
    return arr


def _read_partial_mesh(path: str):
    """Vertices (NaN rows allowed) and faces of a mesh file; the regular reader refuses NaN."""
    from .. import io
    from ..io._api import _format_suffix, _read_raw

    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"file not found: {path}")
    suffix, gz = _format_suffix(p, None)
    if suffix in (".ply", ".obj", ".off"):
        rg = _read_raw(p, suffix, gz)
        if not rg.has_faces or rg.faces is None or not len(rg.faces):
            raise InvalidInputError(f"{p.name}: has no faces; `complete` needs a triangle mesh.")
        return np.asarray(rg.vertices, dtype=np.float64), np.asarray(rg.faces, dtype=np.int64)
    m = io.read_mesh(p)
    return m.vertices, m.faces


def _read_partial_frames(path: str):
    """``(frames, faces or None)`` of an ``.npz`` animation/sequence, NaN entries allowed."""
    import io as _bytes_io
    import zipfile

    from ..io._common import read_bytes

    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"file not found: {path}")
    try:
        # the same archives as every other command: optionally gzip-compressed, frames under
        # `vertices` or `frames`
        data = read_bytes(p, p.name.lower().endswith(".gz"))
        with np.load(_bytes_io.BytesIO(data), allow_pickle=False) as d:
            keys = set(d.files)
            vkey = "vertices" if "vertices" in keys else "frames" if "frames" in keys else None
            if vkey is not None:
                A = np.asarray(d[vkey], dtype=np.float64)
                F = np.asarray(d["faces"], dtype=np.int64) if "faces" in keys else None
                if F is None:
                    raise InvalidInputError(f"{p.name}: has `{vkey}` but no `faces`.")
            elif "points" in keys:
                if "counts" in keys:
                    raise InvalidInputError(
                        f"{p.name}: frames of different sizes have no point correspondence; "
                        "completion needs (T, n, 3) `points`."
                    )
                A, F = np.asarray(d["points"], dtype=np.float64), None
            else:
                raise InvalidInputError(
                    f"{p.name}: expected arrays `vertices` (or `frames`) + `faces` (animation) or "
                    f"`points` (sequence); got {', '.join(sorted(keys)) or 'none'}."
                )
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InvalidInputError(f"{p.name}: not a readable .npz archive ({exc}).") from exc
    if A.ndim != 3 or A.shape[2] != 3:
        raise InvalidInputError(f"{p.name}: frames must have shape (T, n, 3); got {A.shape}.")
    return A, F


def cmd_complete(args) -> int:
    from .. import complete, io
    from ..geometry import Mesh, MeshAnimation, PointCloudSequence

    src = str(args.input)
    is_npz = src.lower().endswith((".npz", ".npz.gz"))
    t0 = time.perf_counter()
    if args.fill_holes:
        if is_npz:
            raise InvalidInputError("`--fill-holes` works on a mesh file, not an .npz archive.")
        method = args.method or "lsm"
        if method not in MESH_METHODS:
            raise InvalidInputError(
                f"`--method` must be one of {', '.join(MESH_METHODS)} with --fill-holes."
            )
        m = io.read_mesh(src)
        V, F = complete.fill_holes(
            m.vertices,
            m.faces,
            method=method,
            max_hole=args.max_hole,
            density=1.0 if args.density is None else args.density,
        )
        io.write(args.output, Mesh(V, F))
        _status(
            f"wrote {args.output}: {V.shape[0] - m.n_vertices} implanted vertices, "
            f"{F.shape[0] - m.n_faces} faces added ({method}, {time.perf_counter() - t0:.2f} s)"
        )
        return 0
    for flag, value in (("--max-hole", args.max_hole), ("--density", args.density)):
        if value is not None:
            raise InvalidInputError(f"`{flag}` applies to --fill-holes.")
    if args.known is None:
        raise InvalidInputError("`--known` KNOWN.npy is required (or pass --fill-holes).")
    known = _load_known(args.known)
    if is_npz:
        method = args.method or "motion"
        if method not in ANIM_METHODS:
            raise InvalidInputError(
                f"`--method` must be one of {', '.join(ANIM_METHODS)} for animations; got {method!r}."
            )
        A, F = _read_partial_frames(src)
        if args.sweeps is not None and (F is None or method != "motion"):
            raise InvalidInputError("`--sweeps` applies to mesh animations with --method motion.")
        if F is not None:
            kw = {} if args.sweeps is None else {"sweeps": args.sweeps}
            X = complete.complete_animation(A, F, known, method=method, **kw)
            io.write(args.output, MeshAnimation(X, F))
        else:
            X = complete.complete_sequence(
                A, known, method="wrli" if method == "motion" else method
            )
            io.write(args.output, PointCloudSequence(list(X)))
        _status(
            f"wrote {args.output}: {X.shape[0]} frames of {X.shape[1]} vertices completed "
            f"({method}, {time.perf_counter() - t0:.2f} s)"
        )
        return 0
    method = args.method or "li"
    if method not in MESH_METHODS:
        raise InvalidInputError(
            f"`--method` must be one of {', '.join(MESH_METHODS)} for meshes; got {method!r}."
        )
    V, F = _read_partial_mesh(src)
    X = complete.inpaint(V, F, known, method=method)
    io.write(args.output, Mesh(X, F))
    _status(
        f"wrote {args.output}: {X.shape[0]} vertices ({method}, {time.perf_counter() - t0:.2f} s)"
    )
    return 0


def register(sub) -> None:
    """Add ``complete`` to the ``spectrageo`` sub-parsers."""
    p = sub.add_parser(
        "complete", help="recover missing vertices or fill holes (meshes, animations; Sec. 5.3)"
    )
    p.add_argument("input", help="mesh file, or .npz animation / point-cloud sequence")
    p.add_argument("output")
    p.add_argument(
        "--known", default=None, help="KNOWN.npy: bool mask (n,) or (T, n), or int vertex indices"
    )
    p.add_argument(
        "--method",
        default=None,
        choices=sorted(set(MESH_METHODS + ANIM_METHODS)),
        help="meshes: li (default) | lsm | mc, with --fill-holes lsm (default) | li | mc; "
        "animations: motion (default) | li | lia | mc",
    )
    p.add_argument(
        "--sweeps", type=int, default=None,
        help="animations, --method motion: filtering sweeps after the satellite generations "
        "(default 20; 0 = Algorithm 12 as printed)",
    )  # fmt: skip
    p.add_argument("--fill-holes", dest="fill_holes", action="store_true", help="close every hole")
    p.add_argument(
        "--max-hole", dest="max_hole", type=int, default=None,
        help="with --fill-holes: leave loops with more edges open",
    )  # fmt: skip
    p.add_argument(
        "--density", type=float, default=None,
        help="with --fill-holes: implanted points per loop edge length (default 1; lower for "
        "very large holes, whose fill grows with their area)",
    )  # fmt: skip
    p.set_defaults(func=cmd_complete)
    p.description = (
        "Recover missing vertices of a mesh with known connectivity (rows of IN not marked in\n"
        "--known may hold anything, NaN included), close the holes of a mesh (--fill-holes), or\n"
        "recover missing vertices of an animation / point-cloud sequence frame by frame (online:\n"
        "frame t uses frames <= t). Known vertices are returned unchanged, vertex order is kept."
    )
    p.epilog = (
        "example:\n  spectrageo complete scan.ply filled.ply --known known.npy --method li\n"
        "  spectrageo complete part_with_holes.off closed.off --fill-holes\n"
        "  spectrageo complete crane.npz crane_full.npz --known known.npy --method motion"
    )
