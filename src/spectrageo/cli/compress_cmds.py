"""``spectrageo compress | decompress`` and ``spectrageo info FILE.sgc`` (thesis Section 5.2).

Thin layer over :func:`spectrageo.compress.encode`, :func:`~spectrageo.compress.decode` and
:func:`~spectrageo.compress.info` for meshes (``.sgc``), and over
:func:`~spectrageo.compress.encode_animation` / :func:`~spectrageo.compress.decode_animation`
for animations (``.sga``: input ``.npz`` or a folder of frames, Section 5.2.2); every output is
written atomically.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from .._errors import InvalidInputError

HELP = {
    "compress": (
        "Compress a triangle mesh into a .sgc file: spectral (block spectral coding on\n"
        "overlapped submeshes, Sec. 5.2.1, progressive), feature (feature-aware delta\n"
        "coordinates, Algorithm 9) or saliency (Algorithm 10). Vertex and face order are kept\n"
        "unless --reorder. --bpv counts the whole file; --error is the RMS vertex error as a\n"
        "fraction of the bounding-box diagonal; both are met within 5 %.\n"
        "Animations (.npz or a folder of frames) go to a .sga file: eigen-trajectory coding of\n"
        "delta coordinates (Sec. 5.2.2: pca, pca-q, pca-qs, pca-qp, blocks [default]),\n"
        "eigen-trajectories in the partitioned GFT basis (pca-spectral: Sec. 5.2.1 + 5.2.2) or\n"
        "the scalable layered streaming codec (Sec. 5.2.4: layered, one segment per frame); --bpvf\n"
        "is the whole file in bits per vertex per frame, --error the KG error in percent.",
        "spectrageo compress fandisk.off fandisk.sgc --bpv 20\n"
        "spectrageo compress part.obj part.sgc --method feature --error 0.002\n"
        "spectrageo compress crane.npz crane.sga --method pca-qp --bpvf 4\n"
        "spectrageo compress frames/ anim.sga --error 0.1   # KG error in percent",
    ),
    "decompress": (
        "Decompress a .sgc file into any mesh format (.ply, .obj, .off, .stl). --partial decodes\n"
        "a file that was cut short (a progressive prefix) to a coarser mesh. A .sga animation\n"
        "decompresses into a .npz or a folder of frames; --partial keeps every complete block.",
        "spectrageo decompress fandisk.sgc fandisk.ply\nspectrageo decompress crane.sga crane.npz",
    ),
}


def _status(msg: str) -> None:
    from . import commands

    commands._status(msg)


def _read_mesh(path: str, *, no_weld: bool = False):
    from ..geometry import Mesh
    from .commands import _read

    obj, _rep = _read(path, kind="mesh", weld=False if no_weld else None, no_weld_option=True)
    if not isinstance(obj, Mesh):
        raise InvalidInputError(f"{path!r} is not a triangle mesh ({type(obj).__name__}).")
    return obj


def _read_sgc(path: str) -> bytes:
    """The bytes of a .sgc / .sga file, gunzipped when its name ends with .gz."""
    from ..io._common import read_bytes, split_suffix

    p = Path(path)
    if p.is_dir():
        raise InvalidInputError(f"{path!r} is a folder, not a .sgc file.")
    if not p.exists():
        raise InvalidInputError(f"file not found: {p}")
    return read_bytes(p, split_suffix(p)[1])


def _is_animation_input(path: str) -> bool:
    """A folder of frames, a ``.npz`` or a ``.sga`` file (each optionally gzip-compressed)."""
    from ..io._common import split_suffix

    p = Path(path)
    return p.is_dir() or split_suffix(p)[0] in (".npz", ".sga")


def cmd_compress_animation(args) -> int:
    from .. import compress
    from ..geometry import MeshAnimation
    from .commands import _read

    method = args.method or "blocks"
    if method not in compress.ANIMATION_METHODS:
        raise InvalidInputError(
            f"--method {method!r} is a mesh codec; animations take one of "
            f"{list(compress.ANIMATION_METHODS)}."
        )
    if args.bpv is not None:
        raise InvalidInputError("animations take --bpvf (bits per vertex per frame), not --bpv.")
    if args.reorder:
        raise InvalidInputError("--reorder is for meshes; animations always keep vertex order.")
    anim, _rep = _read(args.input, kind="animation", weld=False)
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
    )
    _status(
        f"wrote {args.output}: {d['bytes']} bytes, {d['bpvf']:.3f} bpvf, {method}, "
        f"{d['n_frames']} frames in {d['n_blocks']} block(s), vertex and face order kept, "
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


def cmd_compress(args) -> int:
    from .. import compress
    from .commands import _check_outputs

    out = str(args.output).lower()
    if not out.endswith((".sgc", ".sga")):
        raise InvalidInputError(
            f"the output must end with .sgc (mesh) or .sga (animation); got {args.output!r}."
        )
    _check_outputs([args.input], [args.output])
    if out.endswith(".sga") or _is_animation_input(args.input):
        if not out.endswith(".sga"):
            raise InvalidInputError(
                f"{args.input!r} is an animation; its output must end with .sga."
            )
        return cmd_compress_animation(args)
    if args.bpvf is not None:
        raise InvalidInputError("meshes take --bpv (bits per vertex), not --bpvf.")
    method = args.method or "spectral"
    if method not in compress.METHODS:
        raise InvalidInputError(
            f"--method {method!r} is an animation codec; meshes take one of "
            f"{list(compress.METHODS)}."
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
        reorder=args.reorder,
        **({"step": args.step} if args.step is not None else {}),
    )
    order = (
        "vertices and faces REORDERED by the codec (--reorder)"
        if d["reordered"]
        else "vertex and face order kept"
    )
    share = d["parameters"].get("sent_share")
    level = "" if share is None else f" (deltas of {100 * share:.0f} % of the vertices sent)"
    _status(
        f"wrote {args.output}: {d['bytes']} bytes, {d['bpv']:.2f} bpv "
        f"(connectivity {d['connectivity_bpv']:.2f}), {method}{level}, {order}, {dt:.2f} s"
    )
    return 0


def cmd_decompress(args) -> int:
    from .. import compress, io
    from ..geometry import Mesh
    from .commands import _check_outputs

    _check_outputs([args.input], [args.output])
    data = _read_sgc(args.input)
    if compress._animation.is_animation(data):
        return _decompress_animation(args, data)
    t0 = time.perf_counter()
    V, F = compress.decode(data, partial=args.partial)
    dt = time.perf_counter() - t0
    io.write(args.output, Mesh(V, F))
    _status(f"wrote {args.output}: {V.shape[0]} vertices, {F.shape[0]} faces, {dt:.2f} s")
    return 0


def _decompress_animation(args, data: bytes) -> int:
    from .. import compress, io
    from ..geometry import MeshAnimation

    t0 = time.perf_counter()
    frames, F = compress.decode_animation(data, partial=args.partial)
    dt = time.perf_counter() - t0
    msg = f"wrote {args.output}: {frames.shape[0]} frames of {frames.shape[1]} vertices"
    if args.partial:
        # the frame count the header announces (every stream kind's state carries it: the
        # layered one as ``n_frames``, the others in their ``params``)
        dec = compress.StreamDecoder()
        dec.feed(data)
        st = dec.state
        total = 0
        if st is not None:
            total = getattr(st, "n_frames", None)
            if total is None:
                total = st.params.n_frames
        if total and total > frames.shape[0]:
            msg += f" ({total - frames.shape[0]} of {total} frames missing: the file is cut short)"
    io.write(args.output, MeshAnimation(frames, F))
    _status(f"{msg}, {dt:.2f} s ({1e3 * dt / frames.shape[0]:.1f} ms/frame)")
    return 0


def cmd_info_sgc(args) -> int:
    """``spectrageo info FILE.sgc [--json]`` (called by ``info`` for .sgc files)."""
    from .. import compress

    data = _read_sgc(args.file)
    try:
        d = {"file": str(args.file), **compress.info(data)}
    except InvalidInputError as mesh_err:  # an animation file (.sga): its own header
        try:
            d = {"file": str(args.file), **compress.info_animation(data)}
        except InvalidInputError:
            if compress._animation.is_animation(data) or str(args.file).lower().endswith(".sga"):
                raise
            raise mesh_err from None  # neither: report it as the mesh file it is named
    if args.json:
        print(json.dumps(d, indent=2))
    else:
        for k, v in d.items():
            if isinstance(v, dict):
                v = ", ".join(f"{a}={b}" for a, b in v.items())
            elif isinstance(v, float):
                v = f"{v:.4g}"
            print(f"{k:>24}: {v}")
    return 0


def register(sub) -> None:
    from .. import compress

    p = sub.add_parser(
        "compress", help="compress a mesh (.sgc) or an animation (.sga) (Sec. 5.2.1-5.2.3)"
    )
    p.add_argument("input", help="mesh file, or animation (.npz or a folder of frames)")
    p.add_argument("output", help="OUT.sgc (mesh) or OUT.sga (animation)")
    p.add_argument(
        "--method",
        choices=list(compress.METHODS) + list(compress.ANIMATION_METHODS),
        default=None,
        help="default: spectral (meshes), blocks (animations)",
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument("--bpv", type=float, default=None, metavar="X", help="target bits per vertex")
    g.add_argument(
        "--bpvf",
        type=float,
        default=None,
        metavar="X",
        help="animations: target bits per vertex per frame (whole file)",
    )
    g.add_argument(
        "--error",
        type=float,
        default=None,
        metavar="E",
        help="target RMS vertex error as a fraction of the bounding-box diagonal; "
        "animations: KG error in percent",
    )
    g.add_argument(
        "--step",
        type=float,
        default=None,
        help="quantisation step (fraction of the diagonal) instead of a target",
    )
    p.add_argument(
        "--reorder",
        action="store_true",
        help="let the codec renumber vertices and faces for a smaller file",
    )
    p.add_argument(
        "--no-weld",
        action="store_true",
        help="meshes: code the vertices as stored; by default STL files and triangle soups are "
        "welded on reading (their corners merged), as every command reads them",
    )
    p.set_defaults(func=cmd_compress)

    p = sub.add_parser("decompress", help="decompress a .sgc file into a mesh file")
    p.add_argument("input", help="IN.sgc or IN.sga")
    p.add_argument(
        "output", help="mesh file (.ply, .obj, .off, .stl); animations: .npz or a folder"
    )
    p.add_argument(
        "--partial",
        action="store_true",
        help="decode a truncated file (progressive prefix; complete animation blocks)",
    )
    p.set_defaults(func=cmd_decompress)

    for name, (desc, example) in HELP.items():
        sp = sub.choices[name]
        sp.description = desc
        sp.epilog = "example:\n  " + "\n  ".join(example.strip().splitlines())


__all__ = ["register"]
