"""``spectrageo compress | decompress`` and ``spectrageo info FILE.sgc`` (thesis Sections 5.2.1, 5.2.3).

Thin layer over :func:`spectrageo.compress.encode`, :func:`~spectrageo.compress.decode` and
:func:`~spectrageo.compress.info`; every output is written atomically.
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
        "fraction of the bounding-box diagonal; both are met within 5 %.",
        "spectrageo compress fandisk.off fandisk.sgc --bpv 20\n"
        "spectrageo compress part.obj part.sgc --method feature --error 0.002",
    ),
    "decompress": (
        "Decompress a .sgc file into any mesh format (.ply, .obj, .off, .stl). --partial decodes\n"
        "a file that was cut short (a progressive prefix) to a coarser mesh.",
        "spectrageo decompress fandisk.sgc fandisk.ply",
    ),
}


def _status(msg: str) -> None:
    from . import commands

    commands._status(msg)


def _read_mesh(path: str):
    from ..geometry import Mesh
    from .commands import _read

    obj, _rep = _read(path, kind="mesh")
    if not isinstance(obj, Mesh):
        raise InvalidInputError(f"{path!r} is not a triangle mesh ({type(obj).__name__}).")
    return obj


def _read_sgc(path: str) -> bytes:
    p = Path(path)
    if p.is_dir():
        raise InvalidInputError(f"{path!r} is a folder, not a .sgc file.")
    return p.read_bytes()


def cmd_compress(args) -> int:
    from .. import compress
    from ..io import atomic_write
    from .commands import _check_outputs

    if not str(args.output).lower().endswith(".sgc"):
        raise InvalidInputError(f"the output must end with .sgc; got {args.output!r}.")
    _check_outputs([args.input], [args.output])
    mesh = _read_mesh(args.input)
    t0 = time.perf_counter()
    data = compress.encode(
        mesh.vertices,
        mesh.faces,
        method=args.method,
        bpv=args.bpv,
        error=args.error,
        reorder=args.reorder,
        **({"step": args.step} if args.step is not None else {}),
    )
    dt = time.perf_counter() - t0
    with atomic_write(args.output) as tmp:
        Path(tmp).write_bytes(data)
    d = compress.info(data)
    order = (
        "vertices and faces REORDERED by the codec (--reorder)"
        if d["reordered"]
        else "vertex and face order kept"
    )
    _status(
        f"wrote {args.output}: {d['bytes']} bytes, {d['bpv']:.2f} bpv "
        f"(connectivity {d['connectivity_bpv']:.2f}), {args.method}, {order}, {dt:.2f} s"
    )
    return 0


def cmd_decompress(args) -> int:
    from .. import compress, io
    from ..geometry import Mesh
    from .commands import _check_outputs

    _check_outputs([args.input], [args.output])
    data = _read_sgc(args.input)
    t0 = time.perf_counter()
    V, F = compress.decode(data, partial=args.partial)
    dt = time.perf_counter() - t0
    io.write(args.output, Mesh(V, F))
    _status(f"wrote {args.output}: {V.shape[0]} vertices, {F.shape[0]} faces, {dt:.2f} s")
    return 0


def cmd_info_sgc(args) -> int:
    """``spectrageo info FILE.sgc [--json]`` (called by ``info`` for .sgc files)."""
    from .. import compress

    d = {"file": str(args.file), **compress.info(_read_sgc(args.file))}
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

    p = sub.add_parser("compress", help="compress a mesh into a .sgc file (Sec. 5.2.1, 5.2.3)")
    p.add_argument("input", help="mesh file")
    p.add_argument("output", help="OUT.sgc")
    p.add_argument("--method", choices=list(compress.METHODS), default="spectral")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--bpv", type=float, default=None, metavar="X", help="target bits per vertex")
    g.add_argument(
        "--error",
        type=float,
        default=None,
        metavar="E",
        help="target RMS vertex error as a fraction of the bounding-box diagonal",
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
    p.set_defaults(func=cmd_compress)

    p = sub.add_parser("decompress", help="decompress a .sgc file into a mesh file")
    p.add_argument("input", help="IN.sgc")
    p.add_argument("output", help="mesh file (.ply, .obj, .off, .stl)")
    p.add_argument("--partial", action="store_true", help="decode a truncated (progressive) file")
    p.set_defaults(func=cmd_decompress)

    for name, (desc, example) in HELP.items():
        sp = sub.choices[name]
        sp.description = desc
        sp.epilog = "example:\n  " + "\n  ".join(example.strip().splitlines())


__all__ = ["register"]
