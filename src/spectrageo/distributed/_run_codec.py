"""Single-file runners of ``compress`` (thesis Section 5.2) and ``complete`` (Section 5.3).

``compress`` writes meshes to ``.sgc`` through :func:`spectrageo.compress.encode` and animations
(``.npz`` or a folder of frames) to ``.sga`` through
:func:`spectrageo.compress.encode_animation`. ``complete`` recovers missing vertices of meshes,
animations and point-cloud sequences from a ``--known`` mask or index list, or fills the holes of
a mesh; known vertices are written unchanged and vertex order is kept. Writes are atomic.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ._files import check_outputs, read_reported, status

MESH_METHODS = ("mc", "li", "lsm")
ANIM_METHODS = ("motion", "li", "lia", "mc", "gmc")


def _read_mesh(path: str, *, no_weld: bool = False):
    from ..geometry import Mesh

    obj, _rep = read_reported(
        path, kind="mesh", weld=False if no_weld else None, no_weld_option=True
    )
    if not isinstance(obj, Mesh):
        raise InvalidInputError(f"{path!r} is not a triangle mesh ({type(obj).__name__}).")
    return obj


def _is_animation_input(path: str) -> bool:
    """A folder of frames, a ``.npz`` or a ``.sga`` file (each optionally gzip-compressed)."""
    from ..io._common import split_suffix

    p = Path(path)
    return p.is_dir() or split_suffix(p)[0] in (".npz", ".sga")


def _compress_animation(args) -> int:
    from .. import compress
    from ..geometry import MeshAnimation

    method = args.method or "pca-pred"
    if method not in compress.ANIMATION_METHODS:
        raise InvalidInputError(
            f"--method {method!r} is a mesh codec; animations take one of "
            f"{list(compress.ANIMATION_METHODS)}."
        )
    if args.bpv is not None:
        raise InvalidInputError("animations take --bpvf (bits per vertex per frame), not --bpv.")
    if getattr(args, "max_error", None) is not None:
        raise InvalidInputError("--max-error is for meshes; animations take --error (KG).")
    if args.reorder and method != "pca-pred":
        raise InvalidInputError(
            "--reorder applies to meshes and to the animation method pca-pred; "
            f"{method!r} keeps vertex order."
        )
    anim, _rep = read_reported(args.input, kind="animation", weld=False)
    if not isinstance(anim, MeshAnimation):
        raise InvalidInputError(f"{args.input!r} is not a mesh animation.")
    d, dt = _encode_to(
        args.output,
        compress.encode_animation,
        compress.info_animation,
        anim.frames,
        anim.faces,
        method=method,
        bpvf=args.bpvf,
        error=args.error,
        step=args.step,
        **({"reorder": True} if args.reorder else {}),
    )
    order = (
        "vertices and faces REORDERED by the codec (--reorder)"
        if not d.get("order_preserved", True)
        else "vertex and face order kept"
    )
    status(
        f"wrote {args.output}: {d['bytes']} bytes, {d['bpvf']:.3f} bpvf, {method}, "
        f"{d['n_frames']} frames in {d['n_blocks']} block(s), {order}, "
        f"{dt:.2f} s ({1e3 * dt / d['n_frames']:.1f} ms/frame)"
    )
    return 0


def _encode_to(path, encode, info, *data, **options) -> tuple[dict, float]:
    """Run ``encode(*data, **options)``, write the bytes atomically to ``path``; returns
    ``(info(bytes), seconds spent encoding)``."""
    from ..io import atomic_write

    t0 = time.perf_counter()
    blob = encode(*data, **options)
    dt = time.perf_counter() - t0
    with atomic_write(path) as tmp:
        Path(tmp).write_bytes(blob)
    return info(blob), dt


def run_compress(args) -> int:
    from .. import compress

    out = str(args.output).lower()
    if not out.endswith((".sgc", ".sga")):
        raise InvalidInputError(
            f"the output must end with .sgc (mesh) or .sga (animation); got {args.output!r}."
        )
    check_outputs([args.input], [args.output])
    if out.endswith(".sga") or _is_animation_input(args.input):
        if not out.endswith(".sga"):
            raise InvalidInputError(
                f"{args.input!r} is an animation; its output must end with .sga."
            )
        return _compress_animation(args)
    if args.bpvf is not None:
        raise InvalidInputError("meshes take --bpv (bits per vertex), not --bpvf.")
    method = args.method or "auto"
    if method not in compress.ENCODE_METHODS:
        raise InvalidInputError(
            f"--method {method!r} is an animation codec; meshes take one of "
            f"{list(compress.ENCODE_METHODS)}."
        )
    mesh = _read_mesh(args.input, no_weld=args.no_weld)
    d, dt = _encode_to(
        args.output,
        compress.encode,
        compress.info,
        mesh.vertices,
        mesh.faces,
        method=method,
        bpv=args.bpv,
        error=args.error,
        max_error=getattr(args, "max_error", None),
        reorder=args.reorder,
        **({"step": args.step} if args.step is not None else {}),
    )
    order = (
        "vertices and faces REORDERED by the codec (--reorder)"
        if d["reordered"]
        else "vertex and face order kept"
    )
    chosen = d["method"] if method == d["method"] else f"{d['method']} (chosen by {method})"
    share = d["parameters"].get("sent_share")
    level = "" if share is None else f" (deltas of {100 * share:.0f} % of the vertices sent)"
    status(
        f"wrote {args.output}: {d['bytes']} bytes, {d['bpv']:.2f} bpv "
        f"(connectivity {d['connectivity_bpv']:.2f}), {chosen}{level}, {order}, {dt:.2f} s"
    )
    return 0


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
    import zipfile

    from ..io._common import read_bytes
    from ..io._npz import npz_array, open_npz

    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"file not found: {path}")
    try:
        # the same archives as every other command: optionally gzip-compressed, frames under
        # `vertices` or `frames`
        data = read_bytes(p, p.name.lower().endswith(".gz"))
        with open_npz(data, p.name) as d:
            keys = set(d.files)
            vkey = "vertices" if "vertices" in keys else "frames" if "frames" in keys else None
            if vkey is not None:
                A = np.asarray(npz_array(d, vkey, p.name), dtype=np.float64)
                F = None
                if "faces" in keys:
                    F = np.asarray(npz_array(d, "faces", p.name), dtype=np.int64)
                if F is None:
                    raise InvalidInputError(f"{p.name}: has `{vkey}` but no `faces`.")
            elif "points" in keys:
                if "counts" in keys:
                    raise InvalidInputError(
                        f"{p.name}: frames of different sizes have no point correspondence; "
                        "completion needs (T, n, 3) `points`."
                    )
                A, F = np.asarray(npz_array(d, "points", p.name), dtype=np.float64), None
            else:
                raise InvalidInputError(
                    f"{p.name}: expected arrays `vertices` (or `frames`) + `faces` (animation) or "
                    f"`points` (sequence); got {', '.join(sorted(keys)) or 'none'}."
                )
    except InvalidInputError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InvalidInputError(f"{p.name}: not a readable .npz archive ({exc}).") from exc
    if A.ndim != 3 or A.shape[2] != 3:
        raise InvalidInputError(f"{p.name}: frames must have shape (T, n, 3); got {A.shape}.")
    return A, F


def _open_note(open_loops) -> str:
    """``; N left open: k <reason>, ...`` for the status line of ``complete --fill-holes``."""
    if not open_loops:
        return ""
    why: dict[str, int] = {}
    for lp in open_loops:
        why[lp.reason] = why.get(lp.reason, 0) + 1
    reasons = "; ".join(f"{c} {k}" for k, c in why.items())
    return f"; {len(open_loops)} left open: {reasons}"


def run_complete(args) -> int:
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
        res = complete.fill_holes(
            m.vertices,
            m.faces,
            method=method,
            max_hole=args.max_hole,
            density=1.0 if args.density is None else args.density,
        )
        V, F = res
        io.write(args.output, Mesh(V, F))
        status(
            f"wrote {args.output}: {res.n_filled} of {res.n_loops} boundary loops closed, "
            f"{V.shape[0] - m.n_vertices} implanted vertices, {F.shape[0] - m.n_faces} faces "
            f"added ({method}, {time.perf_counter() - t0:.2f} s){_open_note(res.open_loops)}"
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
        status(
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
    status(
        f"wrote {args.output}: {X.shape[0]} vertices ({method}, {time.perf_counter() - t0:.2f} s)"
    )
    return 0
